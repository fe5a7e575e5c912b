"""hcc-franka against the franka-sim FCI server (an FR3 or a Panda simulated
with MuJoCo), with hcc-controller, as a user runs them.

The server runs in its own virtual environment (``$HCC_FRANKA_SIM_PYTHON``,
made by ``python/test.sh`` from ``requirements-franka-sim.txt``: franka-sim
pins numpy 1.x), started by ``franka_sim_launcher.py`` on 127.0.0.1 and a
free port of its own, with its motion limits and communication constraints
enforced: it aborts a motion as a real robot would. Its physics model is
``config/robots/fr3/fr3-nomesh.xml`` (no download).

The tests of this module run one after the other (pytest runs them in
order in one process): each starts its own server, and the comparison with
Franka's own client (pylibfranka, which always uses the FCI port 1337)
takes a lock file as well. Durations are the simulated robot's: the state's
sequence number is the robot's ``message_id`` (ms), so a slow host does not
change them.
"""

from __future__ import annotations

import contextlib
import fcntl
import json
import os
import pathlib
import re
import signal
import socket
import subprocess
import tempfile
import time
from typing import Iterator

import pytest

from conftest import ROOT, binary, unique
from hcc import Client, Telemetry
from procs import remove_ipc_files, started

FR3 = ROOT / "config" / "fr3-pose-posture.toml"
PANDA = ROOT / "config" / "panda-fer-pose-posture.toml"
MJCF = ROOT / "config" / "robots" / "fr3" / "fr3-nomesh.xml"
LAUNCHER = pathlib.Path(__file__).with_name("franka_sim_launcher.py")
PEER = pathlib.Path(__file__).with_name("libfranka_peer.py")
#: The pylibfranka comparison needs the fixed FCI port: one test at a time.
PORT_1337_LOCK = pathlib.Path(tempfile.gettempdir()) / "hcc-franka-sim-1337.lock"

#: The flange goals of the runs (m): the first, then one sent mid-run.
GOAL_1 = [0.50, 0.10, 0.56]
GOAL_2 = [0.56, -0.08, 0.50]
#: The robot's error names the server reports when it aborts a motion.
ABORTS = re.compile(r"(violation|discontinuity|reflex)", re.IGNORECASE)


def sim_python() -> str:
    path = os.environ.get("HCC_FRANKA_SIM_PYTHON")
    if not path or not pathlib.Path(path).exists():
        pytest.fail(
            "HCC_FRANKA_SIM_PYTHON is not set: run the tests with python/test.sh, which "
            "installs franka-sim (requirements-franka-sim.txt) in an environment of its own"
        )
    return path


def free_port() -> int:
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def wait_for_line(log: pathlib.Path, pattern: str, proc: subprocess.Popen, timeout: float) -> str:
    """Waits until ``log`` has a line matching ``pattern``; returns the log."""
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        text = log.read_text() if log.exists() else ""
        if re.search(pattern, text):
            return text
        if proc.poll() is not None:
            break
        time.sleep(0.1)
    raise AssertionError(f"no {pattern!r} in {log.name}:\n{log.read_text()[-4000:]}")


@contextlib.contextmanager
def franka_sim(tmp: pathlib.Path, port: int, protocol: int = 10) -> Iterator[pathlib.Path]:
    """The franka-sim server on 127.0.0.1:``port``; yields its log."""
    log = tmp / f"franka-sim-{port}.log"
    cmd = [sim_python(), str(LAUNCHER), "--port", str(port), "--protocol", str(protocol)]
    cmd += ["--enforce-motion-limits", "--enforce-comm-constraints"]
    env = dict(os.environ, FR3_MJCF=str(MJCF))
    with started(cmd, env, log) as server:
        wait_for_line(log, "Server ready for new client connection", server, 120)
        yield log


class Run:
    """hcc-controller and hcc-franka on one scenario, one server, one namespace."""

    def __init__(self, tmp: pathlib.Path, scenario: pathlib.Path, port: int) -> None:
        self.tmp, self.scenario, self.port = tmp, scenario, port
        self.ns = unique("fr")
        self.prefix = f"{unique('hccfr')}_"[:32]
        self.env = dict(os.environ, HCC_IPC_FILE_PREFIX=self.prefix)
        self.driver_log = tmp / "hcc-franka.log"
        self.stats = tmp / "hcc-franka.json"
        self.controllers = 0

    def controller(self) -> contextlib.AbstractContextManager[subprocess.Popen]:
        self.controllers += 1
        cmd = [str(binary("hcc-controller")), str(self.scenario), "--namespace", self.ns]
        return started(cmd, self.env, self.tmp / f"controller-{self.controllers}.log")

    def driver(self, *extra: str) -> contextlib.AbstractContextManager[subprocess.Popen]:
        cmd = [str(binary("hcc-franka")), str(self.scenario), "--namespace", self.ns]
        cmd += ["--robot-ip", f"127.0.0.1:{self.port}", "--no-realtime"]
        cmd += ["--stats", str(self.stats), *extra]
        return started(cmd, self.env, self.driver_log)

    def goal(self, level: int, values: list[float], duration: float) -> None:
        cmd = [str(binary("hcc")), "goal", "--namespace", self.ns, "--level", str(level)]
        cmd += ["--duration", repr(duration), "--timeout", "10", "--", *map(repr, values)]
        out = subprocess.run(cmd, cwd=ROOT, env=self.env, capture_output=True, text=True)
        assert out.returncode == 0, out.stdout + out.stderr

    def reach(self, goal: list[float]) -> int:
        """Sends the flange ``goal`` (2 s transition) with ``hcc goal``; returns
        the robot time (ms) until it was reached, at most 5 s."""
        with Client(self.ns, file_prefix=self.prefix) as client:
            start = latest_seq(client)
            self.goal(1, goal, 2.0)
            ms = robot_ms_to_converge(client, start)
        assert ms <= 5000, f"{goal}: {ms} ms of robot time"
        return ms

    def stop_driver(self, driver: subprocess.Popen) -> dict:
        """SIGTERM: the driver ramps down, finishes the motion, writes its stats."""
        driver.send_signal(signal.SIGTERM)
        rc = driver.wait(timeout=30)
        log = self.driver_log.read_text()
        assert rc == 0, log
        return json.loads(self.stats.read_text())


def converged(t: Telemetry, position: float = 1e-3, orientation: float = 1e-2) -> bool:
    return (
        t.transition_progress[0] >= 1.0
        and t.error_norm(0) < position
        and t.error_norm(1) < orientation
    )


def robot_ms_to_converge(client: Client, start_seq: int, timeout: float = 60.0) -> int:
    """Robot time (ms, the states' message ids) from ``start_seq`` until the
    flange is within 1 mm and 10 mrad of its goal, its transition over."""
    deadline = time.monotonic() + timeout
    last: Telemetry | None = None
    while time.monotonic() < deadline:
        t = client.latest_telemetry(timeout=0.5)
        if t is not None:
            last = t
            if t.state_seq > start_seq and converged(t):
                return t.state_seq - start_seq
        time.sleep(0.01)
    errors = "no telemetry" if last is None else f"{last.error_norm(0):.3g} m, {last.error_norm(1):.3g} rad"
    raise AssertionError(f"the flange did not converge ({errors})")


def latest_seq(client: Client) -> int:
    t = client.latest_telemetry(timeout=5.0)
    assert t is not None, "no telemetry"
    return t.state_seq


def assert_clean(stats: dict, sim_log: pathlib.Path) -> None:
    """No abort, no communication violation, steps within 1 N·m, no allocation."""
    c = stats["counters"]
    assert c["aborted_motions"] == 0, c
    assert not [k for k in c if k.startswith("robot_error.")], c
    assert c["max_torque_step_written_mnm"] <= 1000, c
    assert c["loop_system_allocs"] == 0, c
    assert c["guard_non_finite"] == 0 and c["guard_limited"] == 0, c
    aborts = [line for line in sim_log.read_text().splitlines() if ABORTS.search(line)]
    assert not aborts, "\n".join(aborts)


def test_fr3_reaches_two_goals_without_a_reflex(tmp_path: pathlib.Path) -> None:
    port = free_port()
    run = Run(tmp_path, FR3, port)
    try:
        with franka_sim(tmp_path, port) as sim_log:
            # The robot's own model: the server serves franka_description's
            # hand-less FR3, the URDF shipped in config/robots/fr3.
            urdf = tmp_path / "served.urdf"
            cmd = [str(binary("hcc-franka")), "--robot-ip", f"127.0.0.1:{port}"]
            cmd += ["--no-realtime", "--save-urdf", str(urdf)]
            out = subprocess.run(cmd, cwd=ROOT, capture_output=True, text=True, timeout=60)
            assert out.returncode == 0, out.stderr
            shipped = ROOT / "config" / "robots" / "fr3" / "fr3.urdf"
            assert urdf.read_text() == shipped.read_text()
            reach_two_goals(run, sim_log)
    finally:
        remove_ipc_files(run.prefix)


def test_fr3_without_the_torque_filter_reaches_two_goals_without_a_reflex(
    tmp_path: pathlib.Path,
) -> None:
    """The FR3 scenario with its `[torque_filter]` removed: the cycle's
    one-period velocity limit is then the one that acts, and what is sent
    reaches the server without a reflex or a torque step the robot refuses."""
    section = "[torque_filter]\ntorque_rate_limit = 500.0  # N·m/s\n"
    text = FR3.read_text()
    assert section in text
    text = text.replace(section, "")
    text = text.replace('urdf = "robots/', f'urdf = "{ROOT}/config/robots/')
    scenario = tmp_path / "fr3-no-filter.toml"
    scenario.write_text(text)
    port = free_port()
    run = Run(tmp_path, scenario, port)
    try:
        with franka_sim(tmp_path, port) as sim_log:
            reach_two_goals(run, sim_log)
    finally:
        remove_ipc_files(run.prefix)


def reach_two_goals(run: Run, sim_log: pathlib.Path) -> None:
    """Controller and driver on the server: two goals by `hcc goal`, then a
    clean stop; nothing the robot would refuse."""
    with run.controller(), run.driver() as driver:
        wait_for_line(run.driver_log, "applying torque commands", driver, 60)
        for goal in (GOAL_1, GOAL_2):
            run.reach(goal)
        stats = run.stop_driver(driver)
    assert_clean(stats, sim_log)
    c = stats["counters"]
    assert c["applied_commands"] > 0 and c["motions"] == 1, c
    for name in ("state_to_joint_state", "command_to_torque", "driver_added"):
        assert stats["figures"][name]["summary"]["count"] > 1000, name


def test_controller_killed_then_restarted(tmp_path: pathlib.Path) -> None:
    port = free_port()
    run = Run(tmp_path, FR3, port)
    try:
        with franka_sim(tmp_path, port) as sim_log, run.driver("--recover") as driver:
            with run.controller() as first:
                wait_for_line(run.driver_log, "applying torque commands", driver, 60)
                time.sleep(1.0)
                first.kill()
                first.wait()
            wait_for_line(run.driver_log, "motion finished", driver, 30)
            wait_for_line(run.driver_log, "waiting for a controller", driver, 30)
            with run.controller():
                wait_for_line(run.driver_log, "starting a new motion", driver, 60)
                run.reach(GOAL_1)
                stats = run.stop_driver(driver)
        assert_clean(stats, sim_log)
        c = stats["counters"]
        # Held, then the fallback, then the stop's ramp: a second motion.
        assert c["held_cycles"] >= 3 and c["fallback_torque_cycles"] > 0, c
        assert c["stopping_cycles"] >= 1 and c["motions"] == 2, c
        assert c["idle_states"] > 0, c
    finally:
        remove_ipc_files(run.prefix)


def test_a_reflex_is_named_and_recovered(tmp_path: pathlib.Path) -> None:
    # The controller starts with a flange yaw goal 2.5 rad from the pose the
    # robot stands in (goals are absolute) and without the safety layer: it
    # spins joint 7 past its velocity limit and the robot aborts the motion.
    # The goal is then set back to the robot's pose (at the commanding
    # limits' speed); the driver recovers (--recover) until the arm is calm.
    orientation = [-3.141592653589793, 0.0, -0.785]
    goal = "goal = [-3.141592653589793, 0.0, -0.785]"
    text = FR3.read_text()
    assert goal in text and "spring_saturation = false" in text
    text = text.replace(goal, "goal = [-3.141592653589793, 0.0, 1.715]")
    text = text.replace("spring_saturation = false", "enabled = false")
    text = text.replace('urdf = "robots/', f'urdf = "{ROOT}/config/robots/')
    scenario = tmp_path / "fr3-far-yaw-goal.toml"
    scenario.write_text(text)
    port = free_port()
    run = Run(tmp_path, scenario, port)
    try:
        with franka_sim(tmp_path, port) as sim_log, run.driver("--recover") as driver:
            with run.controller():
                log = wait_for_line(run.driver_log, r"robot error \w+", driver, 60)
                run.goal(2, orientation, 0.0)
                wait_for_line(run.driver_log, "automatic error recovery done", driver, 30)
                wait_for_line(run.driver_log, "starting a new motion", driver, 30)
                time.sleep(4.0)
                stats = run.stop_driver(driver)
        names = re.findall(r"robot error ([a-z_+]+)", log)
        assert names and all(n != "-" for n in names), log
        c = stats["counters"]
        assert c["aborted_motions"] >= 1 and c["motions"] >= 2, c
        reported = [k.removeprefix("robot_error.") for k in c if k.startswith("robot_error.")]
        assert set(names[0].split("+")) <= set(reported), (names, reported)
        assert all(n in sim_log.read_text() for n in names[0].split("+")), names
        assert c["max_torque_step_written_mnm"] <= 1000, c
    finally:
        remove_ipc_files(run.prefix)


def test_panda_against_franka_sim_fer_mode(tmp_path: pathlib.Path) -> None:
    """The Panda scenario against franka-sim's FER mode (its Panda limit
    tables). franka-sim 1.1.7 speaks FCI protocol 10 on the wire in that mode
    too (its Connect answers version 10, its states have the FR3 layout), so
    the protocol 5 exchange itself is franka-rs's, not tested here."""
    port = free_port()
    run = Run(tmp_path, PANDA, port)
    try:
        with franka_sim(tmp_path, port, protocol=5) as sim_log, run.controller(), run.driver() as driver:
            log = wait_for_line(run.driver_log, "applying torque commands", driver, 60)
            assert "connected to 127.0.0.1" in log
            run.reach(GOAL_1)
            stats = run.stop_driver(driver)
        assert_clean(stats, sim_log)
    finally:
        remove_ipc_files(run.prefix)


def test_the_server_aborts_a_torque_jump_of_libfranka_that_hcc_franka_ramps(
    tmp_path: pathlib.Path,
) -> None:
    """Franka's own client on the same server: a rate-limited hold runs
    clean, an unlimited 5 N·m step is aborted with the robot's
    ``controller_torque_discontinuity`` — the step hcc-franka's guard ramps
    (tests/cycle.rs: jumps are ramped within the rate)."""
    with open(PORT_1337_LOCK, "w") as lock:
        fcntl.flock(lock, fcntl.LOCK_EX)
        with franka_sim(tmp_path, 1337):
            results = []
            for extra in ([], ["--jump", "5.0"]):
                cmd = [sim_python(), str(PEER), "--cycles", "1500", *extra]
                out = subprocess.run(cmd, capture_output=True, text=True, timeout=120)
                assert out.returncode == 0, out.stdout + out.stderr
                results.append(json.loads(out.stdout.strip().splitlines()[-1]))
    clean, jump = results
    assert clean == {"cycles": 1500, "errors": [], "message": ""}, clean
    assert jump["errors"] == ["controller_torque_discontinuity"], jump
    # Aborted at the step (cycle 750) or at the read after it.
    assert jump["cycles"] in (750, 751), jump
