"""Starting the MuJoCo driver and the Rust controller as a user would, and cleaning up."""

from __future__ import annotations

import contextlib
import csv
import os
import pathlib
import signal
import subprocess
import sys
from typing import Iterator

from conftest import ROOT, binary, unique


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
) -> dict[str, pathlib.Path]:
    """Runs the MuJoCo driver against hcc-controller on ``scenario`` until the driver ends.

    Unique namespace and file prefix; both processes are stopped afterwards.
    Returns the paths of the driver's records and the logs.
    """
    ns = unique("pyt")
    env = dict(os.environ, HCC_IPC_FILE_PREFIX=unique("hccpy")[:32])
    paths = {
        "record": tmp / "mujoco_states.csv",
        "stats": tmp / "mujoco_stats.json",
        "driver_log": tmp / "mujoco.log",
        "controller_log": tmp / "controller.log",
        "contact": tmp / "contact.csv",
    }
    driver = [sys.executable, "-m", "hcc.mujoco", str(scenario), "--namespace", ns]
    driver += ["--lockstep"] if lockstep else ["--realtime"]
    if duration is not None:
        driver += ["--duration", repr(duration)]
    driver += ["--record", str(paths["record"]), "--stats", str(paths["stats"])]
    driver += ["--contact-csv", str(paths["contact"]), *(extra or [])]
    controller = [str(binary("hcc-controller")), str(scenario), "--namespace", ns]
    with started(driver, env, paths["driver_log"]) as d:
        with started(controller, env, paths["controller_log"]) as c:
            try:
                rc = d.wait(timeout=timeout)
            except subprocess.TimeoutExpired:
                raise AssertionError(f"the MuJoCo driver did not finish: {paths['driver_log'].read_text()}")
            assert rc == 0, paths["driver_log"].read_text()
            assert c.poll() is None, f"controller exited: {paths['controller_log'].read_text()}"
    return paths
