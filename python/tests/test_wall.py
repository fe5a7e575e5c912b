"""The Panda pressed into a MuJoCo wall: compliance without force sensing.

config/panda-wall.toml puts the TCP's goal 5 cm behind the wall of
config/panda-wall.mujoco.toml. The controller never sees the wall; the arm
presses with the force its level-1 stiffness implies, F = K1 (x_d − x)
along the wall's normal, stays stable, and the lower levels (orientation,
posture) keep converging in the remaining redundancy.

The release is a second run: it starts from the pressed state with the
goal in front of the wall, and the arm comes back to it (this also checks a
start from a pressed state; Client.set_goal could move the goal in one run).
"""

from __future__ import annotations

import math
import pathlib
import re
import subprocess
import tomllib

import numpy as np

from hcc import Client, Telemetry

from conftest import ROOT
from procs import read_csv, run_pair

SCENARIO = ROOT / "config" / "panda-wall.toml"
SCENE = ROOT / "config" / "panda-wall.mujoco.toml"


def collect_telemetry(out: list[Telemetry]):
    """An on_started callback: a Client gathers telemetry until the driver ends."""

    def attach(namespace: str, prefix: str, driver: subprocess.Popen) -> None:
        with Client(namespace, file_prefix=prefix) as client:
            while driver.poll() is None:
                for sample in client.telemetry(timeout=0.05):
                    out.append(sample)
                    if driver.poll() is not None:
                        break

    return attach


def test_wall_force_is_stiffness_times_penetration_and_the_arm_comes_back(
    tmp_path: pathlib.Path,
) -> None:
    doc = tomllib.loads(SCENARIO.read_text())
    scene = tomllib.loads(SCENE.read_text())["mujoco"]["wall"]
    k1 = doc["level"][0]["stiffness"]
    goal = np.array(doc["level"][0]["goal"])
    normal = np.array(scene["normal"])
    wall_point = np.array(scene["point"])
    telemetry: list[Telemetry] = []
    press = tmp_path / "press"
    press.mkdir()
    paths = run_pair(
        SCENARIO, press, lockstep=True, duration=3.0,
        extra=["--scene", str(SCENE)], on_started=collect_telemetry(telemetry),
    )
    _, rows = read_csv(paths["contact"])
    c = np.array(rows)
    assert np.all(np.isfinite(c)), "NaN in the contact record"
    t, f_normal, tip = c[:, 0], c[:, 4], c[:, 5:8]
    # K·Δx along the normal: Δx = (x_d − x)·(−n) is how far the goal lies behind the TCP.
    expected = k1 * ((goal - tip) @ -normal)
    settled = t >= 2.0
    rel = np.abs(f_normal[settled] - expected[settled]) / expected[settled]
    print(
        f"wall: contact force {f_normal[-1]:.3f} N, K1·Δx {expected[-1]:.3f} N "
        f"(largest relative difference over the last second {rel.max():.2e}); "
        f"TCP {1e3 * ((tip[-1] - wall_point) @ normal):.2f} mm in front of the wall surface"
    )
    assert f_normal[-1] > 10.0, "the TCP does not press against the wall"
    assert rel.max() < 0.10
    # Stable: the TCP rests (no oscillation) in the last second.
    assert np.ptp(tip[settled], axis=0).max() < 1e-4

    # The hierarchy below keeps converging; telemetry came through the Client.
    assert telemetry, "no telemetry received"
    assert all(math.isfinite(x.error_norm(lvl)) for x in telemetry for lvl in range(3))
    orientation = [x.error_norm(1) for x in telemetry]
    posture = [x.error_norm(2) for x in telemetry]
    print(
        f"wall: orientation error {orientation[0]:.3e} → {orientation[-1]:.3e} rad, "
        f"posture error {posture[0]:.3e} → {posture[-1]:.3e} rad ({len(telemetry)} samples)"
    )
    assert orientation[-1] < 1e-3
    # The posture (7 joints) cannot be met under the levels above; it settles at its best.
    last = [x.error_norm(2) for x in telemetry if x.header.stamp_ns >= telemetry[-1].header.stamp_ns - 5e8]
    assert np.ptp(last) < 1e-3

    # The release: from the pressed state, the goal 5 cm in front of the wall.
    states = read_csv(paths["record"])[1]
    n = 7
    q, qd = states[-1][1 : 1 + n], states[-1][1 + n : 1 + 2 * n]
    free_goal = wall_point + 0.05 * normal
    free_goal[2] = goal[2]
    text = SCENARIO.read_text()
    text = text.replace('urdf = "', f'urdf = "{(ROOT / "config").as_posix()}/', 1)
    text = re.sub(r"goal = \[0\.60, 0\.0, 0\.413\]", f"goal = {list(map(float, free_goal))}", text)
    text = re.sub(r"(\[initial\]\n)q0 = \[[^\]]*\]", lambda m: f"{m.group(1)}q0 = {q}\nqd0 = {qd}", text)
    release = tmp_path / "panda-wall-release.toml"
    release.write_text(text)
    back = tmp_path / "release"
    back.mkdir()
    paths = run_pair(release, back, lockstep=True, duration=3.0, extra=["--scene", str(SCENE)])
    c = np.array(read_csv(paths["contact"])[1])
    assert np.all(np.isfinite(c))
    gap0 = (c[0, 5:8] - wall_point) @ normal
    assert gap0 < scene["tool_radius"] + 1e-3, "the release run does not start at the wall"
    tip_end = c[-1, 5:8]
    print(
        f"release: TCP {1e3 * gap0:.2f} mm from the wall after the first period, contact force "
        f"{c[-1, 4]:.2e} N at the end, TCP "
        f"{1e3 * np.linalg.norm(tip_end - free_goal):.3f} mm from the goal in front of the wall"
    )
    assert c[-1, 4] == 0.0
    assert np.linalg.norm(tip_end - free_goal) < 1e-3
