"""The examples of docs/python.md run against a live controller: the Panda's error, a run-time goal."""

from __future__ import annotations

import os
import pathlib
import re
import subprocess
import sys

from hcc import Client

from conftest import ROOT
from procs import run_pair, sim_pair

EXAMPLE = ROOT / "python" / "examples" / "panda_error.py"


def test_panda_error_example(tmp_path: pathlib.Path) -> None:
    out: dict[str, str] = {}

    def run_example(namespace: str, prefix: str, driver: subprocess.Popen) -> None:
        env = dict(os.environ, HCC_IPC_FILE_PREFIX=prefix)
        done = subprocess.run(
            [sys.executable, str(EXAMPLE), namespace],
            env=env, capture_output=True, text=True, timeout=300,
        )
        assert done.returncode == 0, done.stderr
        out["stdout"] = done.stdout

    run_pair(
        ROOT / "config" / "panda-pose-posture.toml", tmp_path, lockstep=True, duration=3.0,
        on_started=run_example,
    )
    errors = [float(m) for m in re.findall(r"TCP error +([0-9.]+) mm", out["stdout"])]
    print(out["stdout"])
    assert len(errors) >= 3, out["stdout"]
    assert errors[0] > 10 * errors[-1] and errors[-1] < 1.0, "the TCP did not move to its goal"
    assert "settled" in out["stdout"].splitlines()[-1]


GOAL_EXAMPLE = ROOT / "python" / "examples" / "panda_goal.py"


def test_panda_goal_example(tmp_path: pathlib.Path) -> None:
    """The set_goal example of docs/python.md against hcc-controller + hcc-sim:
    accepted and converged; a goal outside the workspace exits with the reason."""
    with sim_pair(ROOT / "config" / "panda-pose-posture.toml", tmp_path) as (ns, prefix, _, _):
        env = dict(os.environ, HCC_IPC_FILE_PREFIX=prefix)
        with Client(ns, file_prefix=prefix) as client:
            assert client.latest_telemetry(timeout=20.0) is not None, "no controller"

        def run(*goal: str) -> subprocess.CompletedProcess:
            return subprocess.run(
                [sys.executable, str(GOAL_EXAMPLE), ns, *goal],
                env=env, capture_output=True, text=True, timeout=60,
            )

        done = run()
        print(done.stdout)
        assert done.returncode == 0, done.stderr
        assert "accepted" in done.stdout
        m = re.search(r"TCP within ([0-9.]+) mm", done.stdout)
        assert m is not None and float(m.group(1)) <= 1.0, done.stdout
        bad = run("3.0", "0.0", "0.3")
        assert bad.returncode != 0 and "outside_workspace" in bad.stderr, bad.stderr
