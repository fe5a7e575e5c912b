"""The MuJoCo driver reproduces hcc-sim in lockstep: same controller, same trajectory.

``hcc-controller`` runs once against ``python -m hcc.mujoco --lockstep`` and
once (inside ``hcc run --lockstep``) against ``hcc-sim``. Both plants (with their loads in the hand, ``[robot.load]`` and
``[[simulation.load]]``)
integrate Eq. (1) with RK4 at the scenario's step and a zero-order hold per
control period, so the trajectories agree to round-off; the largest joint
difference over the run is printed.
"""

from __future__ import annotations

import math
import os
import pathlib
import subprocess

import pytest

from conftest import ROOT, binary, unique
from procs import read_csv, remove_ipc_files, run_pair

#: Largest joint difference accepted, rad, where the loop is smooth (measured:
#: about 1e-11).
TOLERANCE_RAD = 1e-9

#: Largest joint difference accepted, rad, where the controller's velocity
#: limits act (in the shipped Panda scenario the spring saturation, the
#: velocity governor and the joint damping; a damping of 500 1/s amplifies the
#: plants' round-off differences most, measured: 3e-8).
TOLERANCE_VELOCITY_DAMPING_RAD = 1e-7

SAFETY_OFF = """
[safety]
enabled = false
"""

VELOCITY_DAMPING = """
[safety]
velocity_damping = 500.0
"""

PUSH = """
[[simulation.wrench]]
start_s = 1.0
duration_s = 0.5
link = "tcp"
force = [10.0, 0.0, 0.0]
torque = [0.0, 0.0, 1.0]
"""

#: A load in the hand from the start (told to the controller too) and another
#: the hand takes at 1 s, unannounced (docs/load.md).
LOADS = """
[robot.load]
mass = 0.5
com = [0.0, 0.02, 0.08]
inertia = [1e-3, 0.0, 0.0, 1.2e-3, 0.0, 8e-4]

[[simulation.load]]
start_s = 1.0
mass = 1.0
com = [0.0, 0.0, 0.1]
"""


def hcc_sim_trajectory(scenario: pathlib.Path, out: pathlib.Path) -> pathlib.Path:
    """``hcc run --lockstep`` of ``scenario`` (unique namespace and file prefix)."""
    prefix = f"{unique('hccpyr')}_"
    try:
        subprocess.run(
            [str(binary("hcc")), "run", str(scenario), "--lockstep", "--no-plots", "--quiet",
             "--namespace", unique("pyrun"), "--out", str(out)],
            cwd=ROOT, check=True, capture_output=True, text=True, timeout=600,
            env={**os.environ, "HCC_IPC_FILE_PREFIX": prefix},
        )
    finally:
        remove_ipc_files(prefix)
    return out / "trajectory.csv"


def largest_joint_difference(mujoco_csv: pathlib.Path, sim_csv: pathlib.Path) -> tuple[float, int]:
    """max |q_mujoco − q_sim| over every common time step, and the number of steps."""
    h1, r1 = read_csv(mujoco_csv)
    h2, r2 = read_csv(sim_csv)
    n = sum(1 for c in h1 if c.startswith("q") and not c.startswith("qd"))
    cols = [h2.index(f"q{j + 1}") for j in range(n)]
    sim = {round(r[0] * 1e6): r for r in r2}
    worst, common = 0.0, 0
    for row in r1:
        other = sim.get(round(row[0] * 1e6))
        if other is None:
            continue
        common += 1
        for j in range(n):
            d = abs(row[1 + j] - other[cols[j]])
            assert math.isfinite(d)
            worst = max(worst, d)
    return worst, common


@pytest.mark.parametrize(
    "name,extra,tolerance",
    [
        ("paper-sim1.toml", "", TOLERANCE_RAD),
        ("panda-pose-posture.toml", "", TOLERANCE_VELOCITY_DAMPING_RAD),
        ("panda-pose-posture.toml", SAFETY_OFF, TOLERANCE_RAD),
        ("panda-pose-posture.toml", VELOCITY_DAMPING, TOLERANCE_VELOCITY_DAMPING_RAD),
        ("paper-sim1.toml", PUSH, TOLERANCE_RAD),
        ("panda-pose-posture.toml", SAFETY_OFF + LOADS, TOLERANCE_RAD),
    ],
    ids=["paper-sim1", "panda", "panda-no-safety-layer", "panda-velocity-damping", "paper-sim1-push",
         "panda-loads"],
)
def test_lockstep_matches_hcc_sim(
    name: str, extra: str, tolerance: float, tmp_path: pathlib.Path
) -> None:
    scenario = ROOT / "config" / name
    if extra:
        text = scenario.read_text().replace(
            'urdf = "', f'urdf = "{(ROOT / "config").as_posix()}/', 1
        )
        scenario = tmp_path / name
        scenario.write_text(text + extra)
    sim_csv = hcc_sim_trajectory(scenario, tmp_path / "hcc-sim")
    paths = run_pair(scenario, tmp_path, lockstep=True, duration=3.0)
    worst, common = largest_joint_difference(paths["record"], sim_csv)
    print(f"{scenario.stem}{' + ' + extra.split()[0] if extra else ''}: largest joint "
          f"difference MuJoCo vs hcc-sim over {common} states: {worst:.3e} rad")
    _, r1 = read_csv(paths["record"])
    _, r2 = read_csv(sim_csv)
    # Every state of both runs (hcc run's simulator waits for its recorder).
    assert len(r1) == 3001 and r1[0][0] == 0.0 and r1[-1][0] == 3.0, (len(r1), r1[0][0], r1[-1][0])
    assert common == 3001 and r2[0][0] == 0.0 and r2[-1][0] == 3.0, (common, len(r2), r2[0][0], r2[-1][0])
    assert worst < tolerance
