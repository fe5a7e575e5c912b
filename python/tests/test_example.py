"""The example of docs/python.md runs against a live controller and prints the Panda's error."""

from __future__ import annotations

import os
import pathlib
import re
import subprocess
import sys

from conftest import ROOT
from procs import run_pair

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
