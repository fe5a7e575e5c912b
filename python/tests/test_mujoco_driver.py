"""The MuJoCo driver's command handling without IPC: hcc-sim's rules, period by period."""

from __future__ import annotations

import pathlib

import numpy as np
import pytest

from hcc import COMMAND_FLAG_GRAVITY_INCLUDED, CommandMode, DriverStatus, JointState, TorqueCommand
from hcc.mujoco import Applied, MujocoDriver, Plant, SceneFile
from hcc.scenario import Scenario, ScenarioError

from conftest import ROOT

SIM1 = ROOT / "config" / "paper-sim1.toml"


def command(driver: MujocoDriver, tau: list[float], mode: CommandMode = CommandMode.NORMAL,
            gravity: bool = True) -> TorqueCommand:
    c = TorqueCommand.zeroed()
    c.header.n_joints = driver.n
    c.header.seq = driver.k
    c.state_seq = driver.k
    c.state_stamp_ns = 1
    c.mode = int(mode)
    c.flags = COMMAND_FLAG_GRAVITY_INCLUDED if gravity else 0
    for j, t in enumerate(tau):
        c.tau[j] = t
    return c


def test_waiting_apply_hold_fallback_stop() -> None:
    s = Scenario.load(SIM1)
    s.hold_cycles = 2
    d = MujocoDriver(s)
    g0 = d.plant.gravity()
    assert d.advance(None) == Applied.WAITING_FOR_CONTROLLER
    assert np.allclose(d.tau, g0)  # the arm is held, misses are not counted yet
    assert d.counters.missed_commands == 0 and d.status == DriverStatus.FALLBACK_ACTIVE
    tau = [1.0, 2.0, 3.0, 4.0]
    assert d.advance(command(d, tau)) == Applied.COMMAND
    assert d.status == DriverStatus.OK and list(d.tau) == tau
    stale = command(d, tau)
    stale.state_seq = d.k - 1
    assert d.advance(stale) == Applied.HELD
    assert d.advance(None) == Applied.HELD and list(d.tau) == tau
    expected = d.plant.gravity() - 2.0 * d.plant.qd  # g(q_k) − D q̇_k, default D = 2
    assert d.advance(None) == Applied.FALLBACK
    assert np.allclose(d.tau, expected)
    assert d.counters.missed_commands == 3 and d.in_fallback()
    msg = JointState.zeroed()
    d.write_state(msg, 5)
    msg.validate(4)
    assert msg.status == DriverStatus.FALLBACK_ACTIVE and msg.missed_commands == 3
    assert msg.header.seq == d.k == 5
    # Invalid or gravity-conflicting commands are misses, counted as rejected.
    bad = command(d, [float("nan"), 0.0, 0.0, 0.0])
    assert d.advance(bad) == Applied.FALLBACK
    assert d.advance(command(d, tau, gravity=False)) == Applied.FALLBACK
    assert d.counters.rejected_commands == 2
    assert d.advance(command(d, tau, CommandMode.SINGULAR)) == Applied.COMMAND
    assert d.advance(command(d, tau, CommandMode.STOP)) == Applied.STOPPED
    assert d.status == DriverStatus.STOPPED
    assert d.advance(command(d, tau)) == Applied.STOPPED  # no resume within the session


def test_driver_adds_gravity_when_the_controller_does_not(tmp_path: pathlib.Path) -> None:
    s = Scenario.load(SIM1)
    s.gravity_compensation = False
    d = MujocoDriver(s)
    msg = JointState.zeroed()
    d.write_state(msg, 1)
    assert msg.driver_compensates_gravity()
    g = d.plant.gravity()
    assert d.advance(command(d, [1.0, 0.0, 0.0, 0.0], gravity=False)) == Applied.COMMAND
    assert np.allclose(d.tau, g + np.array([1.0, 0.0, 0.0, 0.0]))


def test_bad_input_gets_clear_errors(tmp_path: pathlib.Path) -> None:
    bad = tmp_path / "bad.toml"
    bad.write_text(SIM1.read_text().replace("integrator_dt_s = 1e-4", "integrator_dt_s = 3e-4"))
    with pytest.raises(ScenarioError, match="must divide the control period"):
        Scenario.load(bad)
    bad.write_text(SIM1.read_text().replace("duration_s = 3.0", "duration_s = 3.0\ncontrol_rate_hz = 1000.0", 1))
    with pytest.raises(ScenarioError, match=r"simulation.control_rate_hz: .*\[controller\] rate_hz"):
        Scenario.load(bad)
    bad.write_text(SIM1.read_text().replace("rate_hz = 1000.0", "rate_hz = 500.0"))
    assert Scenario.load(bad).period_s == 0.002
    text = SIM1.read_text().replace('urdf = "', f'urdf = "{(ROOT / "config").as_posix()}/', 1)
    bad.write_text(text.replace('tip_link = "tcp"', 'tip_link = "nowhere"'))
    with pytest.raises(ScenarioError, match="tip link 'nowhere'"):
        Plant(Scenario.load(bad))
    bad.write_text("[mujoco]\nscene = \"table\"\n")
    with pytest.raises(ScenarioError, match="mujoco.scene"):
        SceneFile.load(bad)
    bad.write_text("[mujoco]\nscene = \"wall\"\n[mujoco.wall]\npoint = [0, 0]\nnormal = [1, 0, 0]\n")
    with pytest.raises(ScenarioError, match="point/normal"):
        SceneFile.load(bad)
    with pytest.raises(ScenarioError, match="cannot read"):
        Scenario.load(tmp_path / "missing.toml")
    d = MujocoDriver(Scenario.load(SIM1))
    with pytest.raises(ValueError, match="--duration"):
        d.set_duration(0.0)


def test_command_line_errors_exit_2(tmp_path: pathlib.Path) -> None:
    import subprocess
    import sys

    for args, text in [
        ([str(tmp_path / "missing.toml")], "cannot read"),
        ([str(SIM1), "--namespace", "a/b"], "namespace 'a/b' is invalid"),
        ([str(SIM1), "--duration", "-1"], "--duration"),
        ([str(SIM1), "--sched-priority", "0"], "--sched-priority 0"),
    ]:
        done = subprocess.run(
            [sys.executable, "-m", "hcc.mujoco", *args], capture_output=True, text=True, timeout=60
        )
        assert done.returncode == 2, (args, done.stderr)
        assert "hcc.mujoco: error:" in done.stderr and text in done.stderr, done.stderr
        assert "Traceback" not in done.stderr


def test_short_window_misses_are_told_apart() -> None:
    """A miss counts as the driver's own when its tick came before the state's window ended.

    The real-time loop catches a late tick up with ticks back to back; the state
    published in the late tick then has less than its window (0.8 ms at 1 kHz).
    """
    from hcc.mujoco.daemon import is_short_window_miss

    window = 800_000
    published = 10_000_000
    # A tick a period after the state (the window elapsed): the controller's miss.
    assert not is_short_window_miss(3, 4, published + 1_000_000, published, window)
    # A caught-up tick 0.1 ms after the state: the driver's lateness.
    assert is_short_window_miss(3, 4, published + 100_000, published, window)
    assert not is_short_window_miss(3, 4, published + window, published, window)
    # No miss in this tick: nothing to tell apart.
    assert not is_short_window_miss(4, 4, published + 100_000, published, window)


PANDA = ROOT / "config" / "panda-pose-posture.toml"


def test_a_load_in_the_hand_adds_its_weight_and_the_robot_s_own_gravity_knows_none(
    tmp_path: pathlib.Path,
) -> None:
    """docs/load.md: the plant's g gains −J_cᵀ m g₀ of the load (J_c at its centre
    of mass, placed by the tip body's pose), the robot's own g stays the bare arm's,
    and a ``[[simulation.load]]`` is taken at its time."""
    from hcc.scenario import Load
    import mujoco

    text = PANDA.read_text().replace('urdf = "', f'urdf = "{(ROOT / "config").as_posix()}/', 1)
    scenario = tmp_path / "loaded.toml"
    scenario.write_text(text + "\n[[simulation.load]]\nstart_s = 0.005\nmass = 1.0\ncom = [0.0, 0.0, 0.1]\n")
    s = Scenario.load(scenario)
    assert [(tl.start_s, tl.load.mass) for tl in s.loads] == [(0.005, 1.0)]
    plant = Plant(s)
    bare = plant.gravity()
    load = Load(1.5, [0.04, -0.03, 0.12], [2e-3, 0.0, 0.0, 3e-3, 0.0, 4e-3])
    plant.set_load(load)
    loaded = plant.gravity()
    # Independently: the point c = p_tip + R_tip com, its Jacobian, −J_cᵀ m g₀.
    d = plant._scratch
    tip = plant.robot.link_bodies[s.tip_link]
    point = d.xpos[tip] + d.xmat[tip].reshape(3, 3) @ np.array(load.com)
    jacp = np.zeros((3, plant.model.nv))
    mujoco.mj_jac(plant.model, d, jacp, None, point, tip)
    want = -(jacp.T @ (load.mass * np.array(s.gravity)))[plant.robot.dof_adr]
    off = np.max(np.abs(loaded - bare - want)) / np.max(np.abs(want))
    print(f"MuJoCo plant: the load's gravity torque off −J_cᵀ m g₀ by {off:.1e} (relative)")
    assert off < 1e-10
    assert np.max(np.abs(plant.robot_gravity() - bare)) < 1e-12
    # The timed load: taken at 5 ms.
    plant.set_load(Load(0.0, [0.0] * 3, [0.0] * 6))
    for _ in range(4):
        plant.advance(bare)
    assert plant.load.mass == 0.0
    for _ in range(2):
        plant.advance(bare)
    assert plant.load.mass == 1.0
