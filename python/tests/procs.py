"""Starting the MuJoCo driver, hcc-sim and the Rust controller as a user would, and cleaning up."""

from __future__ import annotations

import contextlib
import csv
import os
import pathlib
import signal
import socket
import subprocess
import sys
from typing import Callable, Iterator

import iceoryx2 as iox2

from conftest import ROOT, binary, unique

#: Directory of POSIX shared memory on Linux.
SHM_DIR = "/dev/shm"


def free_port() -> int:
    """A TCP port on 127.0.0.1 that is free now (bound to port 0 and released)."""
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def read_csv(path: pathlib.Path) -> tuple[list[str], list[list[float]]]:
    """Header and rows of a numeric CSV."""
    with open(path) as f:
        rows = list(csv.reader(f))
    return rows[0], [[float(x) for x in r] for r in rows[1:]]


@contextlib.contextmanager
def started(cmd: list[str], env: dict[str, str], log: pathlib.Path) -> Iterator[subprocess.Popen]:
    """Runs ``cmd``; on exit stops it (SIGTERM, then SIGKILL) if it still runs."""
    out = open(log, "w")
    p = subprocess.Popen(cmd, cwd=ROOT, env=env, stdout=out, stderr=subprocess.STDOUT)
    try:
        yield p
    finally:
        if p.poll() is None:
            p.send_signal(signal.SIGTERM)
            try:
                p.wait(timeout=10)
            except subprocess.TimeoutExpired:
                p.kill()
                p.wait()
        out.close()


def run_pair(
    scenario: pathlib.Path,
    tmp: pathlib.Path,
    *,
    lockstep: bool = True,
    duration: float | None = None,
    extra: list[str] | None = None,
    timeout: float = 600.0,
    controller_extra: list[str] | None = None,
    on_started: Callable[[str, str, subprocess.Popen], None] | None = None,
    record: bool = False,
) -> dict[str, pathlib.Path]:
    """Runs the MuJoCo driver against hcc-controller on ``scenario`` until the driver ends.

    Unique namespace and file prefix; both processes are stopped afterwards.
    ``on_started(namespace, file_prefix, driver_process)`` is called once
    both run (e.g. to attach a client until the driver ends). With ``record``,
    ``hcc record`` subscribes before the controller starts and writes the whole
    run to ``paths["recording"]`` (stopped by SIGINT once the driver ends). Returns the paths of the driver's records and the logs.
    """
    ns = unique("pyt")
    prefix = f"{unique('hccpy')}_"[:32]
    env = dict(os.environ, HCC_IPC_FILE_PREFIX=prefix)
    paths = {
        "record": tmp / "mujoco_states.csv",
        "stats": tmp / "mujoco_stats.json",
        "driver_log": tmp / "mujoco.log",
        "controller_log": tmp / "controller.log",
        "contact": tmp / "contact.csv",
        "recording": tmp / "run.mcap",
        "recorder_log": tmp / "recorder.log",
    }
    driver = [sys.executable, "-m", "hcc.mujoco", str(scenario), "--namespace", ns]
    driver += ["--lockstep"] if lockstep else ["--realtime"]
    if duration is not None:
        driver += ["--duration", repr(duration)]
    driver += ["--record", str(paths["record"]), "--stats", str(paths["stats"])]
    driver += ["--contact-csv", str(paths["contact"]), *(extra or [])]
    controller = [str(binary("hcc-controller")), str(scenario), "--namespace", ns]
    controller += controller_extra or []
    recorder = [str(binary("hcc")), "record", "--namespace", ns, "--file-prefix", prefix]
    recorder += ["--config", str(scenario), "--out", str(paths["recording"]), "--quiet"]
    try:
        with contextlib.ExitStack() as stack:
            d = stack.enter_context(started(driver, env, paths["driver_log"]))
            r = stack.enter_context(started(recorder, env, paths["recorder_log"])) if record else None
            c = stack.enter_context(started(controller, env, paths["controller_log"]))
            if on_started is not None:
                on_started(ns, prefix, d)
            try:
                rc = d.wait(timeout=timeout)
            except subprocess.TimeoutExpired:
                raise AssertionError(
                    f"the MuJoCo driver did not finish: {paths['driver_log'].read_text()}"
                ) from None
            assert rc == 0, paths["driver_log"].read_text()
            assert c.poll() is None, f"controller exited: {paths['controller_log'].read_text()}"
            if r is not None:
                # The controller goes on publishing (peer-lost telemetry): the
                # recorder stops on Ctrl-C, draining its queues and closing the file.
                r.send_signal(signal.SIGINT)
                try:
                    rc = r.wait(timeout=60.0)
                except subprocess.TimeoutExpired:
                    raise AssertionError(
                        f"hcc record did not finish: {paths['recorder_log'].read_text()}"
                    ) from None
                assert rc == 0, paths["recorder_log"].read_text()
    finally:
        remove_ipc_files(prefix)
    return paths


def remove_ipc_files(prefix: str) -> None:
    """Deletes the shared-memory and bookkeeping files of a test's own file prefix."""
    iceoryx2_root = iox2.config.default().global_cfg.root_path.to_string()
    for root in (pathlib.Path(SHM_DIR), pathlib.Path(iceoryx2_root)):
        if not root.is_dir():
            continue
        for path in root.rglob(f"{prefix}*"):
            if path.is_file():
                path.unlink(missing_ok=True)


@contextlib.contextmanager
def sim_pair(
    scenario: pathlib.Path, tmp: pathlib.Path, duration: float = 60.0
) -> Iterator[tuple[str, str, subprocess.Popen, subprocess.Popen]]:
    """hcc-controller and hcc-sim (real time, ``duration`` s) on ``scenario``.

    Unique namespace and file prefix; yields (namespace, file prefix,
    controller, simulator); both are stopped and the prefix's files removed
    afterwards.
    """
    ns = unique("pycmd")
    prefix = f"{unique('hccpy')}_"[:32]
    env = dict(os.environ, HCC_IPC_FILE_PREFIX=prefix)
    controller = [str(binary("hcc-controller")), str(scenario), "--namespace", ns]
    sim = [str(binary("hcc-sim")), str(scenario), "--namespace", ns, "--realtime"]
    sim += ["--duration", repr(duration)]
    try:
        with (
            started(controller, env, tmp / "controller.log") as ctl,
            started(sim, env, tmp / "sim.log") as plant,
        ):
            yield ns, prefix, ctl, plant
    finally:
        remove_ipc_files(prefix)
