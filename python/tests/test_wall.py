"""The Panda pressed into a MuJoCo wall: compliance without force sensing.

config/panda-wall.toml puts the TCP's goal 5 cm behind the wall of
config/panda-wall.mujoco.toml. The controller never sees the wall; the arm
presses with the force its level-1 stiffness implies, F = K1 (x_d − x)
along the wall's normal, stays stable, and the lower levels (orientation,
posture) keep converging in the remaining redundancy.

The release in the same run: a client (hcc.Client) sets level 1's goal 5 cm
in front of the wall, to apply at the state of t = 3 s, and the arm leaves the
wall and comes to it.

Felt without a sensor, in the same run (recorded by ``hcc record``): the
controller's momentum observer flags the contact when the tool meets the wall
and clears it after the release, and its wrench estimate F̂ at the TCP agrees
with MuJoCo's contact force along the wall's normal.
"""

from __future__ import annotations

import math
import pathlib
import re
import subprocess
import tomllib

import numpy as np

from hcc import Client, SetpointAnswer, Telemetry

from conftest import ROOT, binary
from procs import read_csv, run_pair

SCENARIO = ROOT / "config" / "panda-wall.toml"
SCENE = ROOT / "config" / "panda-wall.mujoco.toml"


#: The state at which the client's release applies (t = 3 s at 1 kHz).
RELEASE_SEQ = 3000


def release_and_collect(goal: list[float], out: list[Telemetry], answers: list[SetpointAnswer]):
    """An on_started callback: a Client sends level 1's goal ``goal`` to apply at
    :data:`RELEASE_SEQ` and gathers telemetry until the driver ends; the
    controller's last answer to that setpoint goes to ``answers``."""

    def attach(namespace: str, prefix: str, driver: subprocess.Popen) -> None:
        with Client(namespace, file_prefix=prefix) as client:
            # The controller's setpoint subscriber exists once it answers states
            # (a setpoint sent before that reaches nobody).
            first = client.latest_telemetry(timeout=30.0)
            assert first is not None, "no telemetry within 30 s"
            out.append(first)
            sp = client.setpoint(0, 3).with_goal(goal).with_duration(0.0)
            seq = client.send(sp.with_apply_at(RELEASE_SEQ))
            while driver.poll() is None:
                for sample in client.telemetry(timeout=0.05):
                    out.append(sample)
                    if driver.poll() is not None:
                        break
            for sample in reversed(out):
                answer = sample.answer_for(client.client_id)
                if answer is not None and answer.seq >= seq:
                    answers.append(SetpointAnswer.from_buffer_copy(answer))
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
    free_goal = wall_point + 0.05 * normal
    free_goal[2] = goal[2]
    telemetry: list[Telemetry] = []
    answers: list[SetpointAnswer] = []
    paths = run_pair(
        SCENARIO, tmp_path, lockstep=True, duration=6.0,
        extra=["--scene", str(SCENE)],
        on_started=release_and_collect(list(map(float, free_goal)), telemetry, answers),
        record=True,
    )
    assert answers and answers[0].accepted(), "the release was not accepted"
    assert answers[0].late == 0, (
        f"the release arrived after the state {RELEASE_SEQ} it was meant for (the client "
        "attached too slowly)"
    )
    _, rows = read_csv(paths["contact"])
    c = np.array(rows)
    assert np.all(np.isfinite(c)), "NaN in the contact record"
    t, f_normal, tip = c[:, 0], c[:, 4], c[:, 5:8]
    t_release = RELEASE_SEQ * 1e-3

    # Pressing (t < 3 s): K·Δx along the normal, Δx = (x_d − x)·(−n) being how far
    # the goal lies behind the TCP.
    expected = k1 * ((goal - tip) @ -normal)
    settled = (t >= t_release - 1.0) & (t < t_release - 0.01)
    rel = np.abs(f_normal[settled] - expected[settled]) / expected[settled]
    last_pressed = np.flatnonzero(settled)[-1]
    print(
        f"wall: contact force {f_normal[last_pressed]:.3f} N, K1·Δx {expected[last_pressed]:.3f} N "
        f"(largest relative difference over the last second {rel.max():.2e}); TCP "
        f"{1e3 * ((tip[last_pressed] - wall_point) @ normal):.2f} mm in front of the wall surface"
    )
    assert f_normal[last_pressed] > 10.0, "the TCP does not press against the wall"
    assert rel.max() < 0.10
    # Stable: the TCP rests (no oscillation) in the last second before the release.
    assert np.ptp(tip[settled], axis=0).max() < 1e-4

    # The hierarchy below keeps converging; telemetry came through the Client.
    pressed = [x for x in telemetry if x.state_seq < RELEASE_SEQ]
    assert pressed, "no telemetry received before the release"
    assert all(math.isfinite(x.error_norm(lvl)) for x in telemetry for lvl in range(3))
    orientation = [x.error_norm(1) for x in pressed]
    print(
        f"wall: orientation error {orientation[0]:.3e} → {orientation[-1]:.3e} rad "
        f"({len(pressed)} samples before the release, {len(telemetry)} in all)"
    )
    assert orientation[-1] < 1e-3
    # The posture (7 joints) cannot be met under the levels above; it settles at its best.
    last = [x.error_norm(2) for x in pressed if x.state_seq >= RELEASE_SEQ - 500]
    assert last and np.ptp(last) < 1e-3

    # The release: the goal moves at the state of t = 3 s (telemetry shows the
    # level's goal leaving the pressed one there), the TCP leaves the wall and
    # comes to the new goal.
    moved = [x.state_seq for x in telemetry if np.linalg.norm(np.array(x.goal[0][:3]) - goal) > 1e-9]
    assert moved and min(moved) >= RELEASE_SEQ, "the goal moved before its state"
    tip_end = tip[-1]
    print(
        f"release: goal moving from state {min(moved)}, contact force {f_normal[-1]:.2e} N at "
        f"t = {t[-1]:.2f} s, TCP {1e3 * np.linalg.norm(tip_end - free_goal):.3f} mm from the goal "
        "in front of the wall"
    )
    assert f_normal[-1] == 0.0
    assert np.linalg.norm(tip_end - free_goal) < 1e-3

    check_contact_estimate(paths, c, normal)

    # A client's setpoint, a driver in another language that stops and leaves:
    # the controller's torque path made no system allocation after warm-up.
    log = paths["controller_log"].read_text()
    m = re.search(r"rt system allocations on the torque path after warm-up (\d+)", log)
    assert m is not None, log[-2000:]
    assert m.group(1) == "0", log[-2000:]


#: MuJoCo's contact force above which the tool is taken to touch the wall, N.
TOUCH_N = 0.5
#: How long after the touch the flag may come (the impact builds up the
#: estimate within a few observer time constants, 1/K_O = 20 ms by default), s.
DETECTION_WINDOW_S = 0.05
#: How long after the tool leaves the wall the flag may stay (the estimate's
#: decay to the hysteresis' release level), s.
RELEASE_WINDOW_S = 0.1


def check_contact_estimate(
    paths: dict[str, pathlib.Path], contact: np.ndarray, normal: np.ndarray
) -> None:
    """The controller's own view of the wall (from the run's recording) against
    MuJoCo's: contact flagged when the tool meets the wall and only then, F̂ at
    the TCP along the wall's normal within 10 % of MuJoCo's contact force."""
    table = paths["recording"].with_suffix(".csv")
    subprocess.run(
        [str(binary("hcc")), "export", str(paths["recording"]), "--csv", str(table)],
        cwd=ROOT, check=True, capture_output=True,
    )
    header, rows = read_csv(table)
    traj = np.array(rows)
    col = {name: k for k, name in enumerate(header)}
    f_cols = sorted((n for n in header if n.startswith("f_ext_")), key=lambda n: int(n[6:]))
    assert len(f_cols) == 3, f"expected F̂ of the TCP position level, got {f_cols}"
    t_ctl = traj[:, col["t"]]
    flagged = traj[:, col["contact"]] > 0.5
    f_hat = traj[:, [col[n] for n in f_cols]]
    # Both tables are on the driver's clock, t = k·T: match rows by time.
    t_sim, f_sim = contact[:, 0], contact[:, 4]
    f_true = np.interp(t_ctl, t_sim, f_sim)
    touching = f_true > TOUCH_N
    assert touching.any(), "the tool never touched the wall"
    t_touch = t_ctl[np.argmax(touching)]
    t_leave = t_ctl[np.flatnonzero(touching)[-1]]
    assert flagged.any(), "the controller never flagged the contact"
    t_flag = t_ctl[np.argmax(flagged)]
    t_clear = t_ctl[np.flatnonzero(flagged)[-1]]
    # The estimate along the normal into the wall: the wall pushes the robot
    # along +normal, so F̂·n is the pressing force.
    f_hat_n = f_hat @ normal
    pressed = (t_ctl >= RELEASE_SEQ * 1e-3 - 1.0) & (t_ctl < RELEASE_SEQ * 1e-3 - 0.01)
    rel = np.abs(f_hat_n[pressed] - f_true[pressed]) / f_true[pressed]
    free = ~touching & ((t_ctl < t_touch) | (t_ctl > t_leave + RELEASE_WINDOW_S))
    tau_cols = [col[n] for n in header if n.startswith("tau_ext_")]
    free_peak = np.abs(traj[free][:, tau_cols]).max(axis=0)
    print(
        f"contact: tool on the wall {t_touch:.3f}–{t_leave:.3f} s, flagged {t_flag:.3f}–"
        f"{t_clear:.3f} s; pressed: F̂·n {f_hat_n[pressed][-1]:.3f} N vs MuJoCo "
        f"{f_true[pressed][-1]:.3f} N (largest relative difference over the last second "
        f"{rel.max():.2e}); MuJoCo's force when the flag cleared {f_true[t_ctl == t_clear][0]:.3f} N; "
        f"largest |r| in free motion {[float(f'{x:.2e}') for x in free_peak]} N·m"
    )
    assert 0.0 <= t_flag - t_touch <= DETECTION_WINDOW_S
    # The flag clears as the pressing force fades (below the release level
    # before the tool has quite left), never later than the window after.
    assert t_clear <= t_leave + RELEASE_WINDOW_S
    assert f_true[t_ctl == t_clear][0] < 0.25 * f_true[pressed][-1]
    assert not flagged[free].any(), "contact flagged in free motion"
    assert rel.max() < 0.10
