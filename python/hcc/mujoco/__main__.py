"""``python -m hcc.mujoco``: the MuJoCo plant driver (see :mod:`hcc.mujoco.daemon`)."""

from __future__ import annotations

import argparse
import math
import os
import pathlib
import sys

from .. import ipc
from ..scenario import Scenario, ScenarioError
from .daemon import run
from .driver import MujocoDriver
from .plant import SceneFile


def parse_args(argv: list[str]) -> argparse.Namespace:
    """The command line."""
    p = argparse.ArgumentParser(
        prog="python -m hcc.mujoco",
        description="Plant driver on MuJoCo: publishes joint states of the simulated robot "
        "and applies the controller's torque commands over iceoryx2, as hcc-sim does.",
    )
    p.add_argument("config", type=pathlib.Path, help="scenario TOML (the same file as hcc-sim's)")
    p.add_argument("--namespace", help="IPC namespace (overrides [ipc].namespace)")
    p.add_argument("--file-prefix", help="shared-memory file prefix (default: $HCC_IPC_FILE_PREFIX)")
    mode = p.add_mutually_exclusive_group()
    mode.add_argument("--lockstep", action="store_true", help="wait for each command (deterministic)")
    mode.add_argument("--realtime", action="store_true", help="absolute clock at the control rate")
    p.add_argument("--duration", type=float, help="stop after this much simulated time, s")
    p.add_argument(
        "--lockstep-timeout-ms", type=float, default=100.0,
        help="lockstep: a command missing this long counts as a miss (default 100)",
    )
    p.add_argument(
        "--scene", type=pathlib.Path,
        help="MuJoCo scene TOML ([mujoco] scene = \"wall\", [mujoco.wall] point, normal)",
    )
    p.add_argument("--contact-csv", type=pathlib.Path, help="write the contact force per period here")
    p.add_argument(
        "--sched-priority", type=int,
        help="SCHED_FIFO priority 1..=99 of the driver (default: normal scheduling)",
    )
    p.add_argument("--record", type=pathlib.Path, help="write t, q, qd of every state (CSV) here")
    p.add_argument("--stats", type=pathlib.Path, help="write counters and timing figures (JSON) here")
    return p.parse_args(argv)


def set_fifo_priority(priority: int) -> None:
    """Runs this process under SCHED_FIFO at ``priority``; a clear error if not permitted."""
    if not 1 <= priority <= 99:
        raise ValueError(f"--sched-priority {priority} must be in 1..=99")
    try:
        os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(priority))
    except PermissionError as e:
        raise ValueError(
            f"--sched-priority {priority}: not permitted ({e.strerror}); it needs CAP_SYS_NICE "
            "or an rtprio limit"
        ) from e


def main(argv: list[str] | None = None) -> int:
    """Runs the driver; 0 after a clean stop, 2 for a start-up error, 1 for a failure."""
    args = parse_args(sys.argv[1:] if argv is None else argv)
    try:
        scenario = Scenario.load(args.config)
        scene = SceneFile.load(args.scene) if args.scene is not None else None
        namespace = args.namespace or scenario.namespace
        ipc.validate_namespace(namespace)
        if not (math.isfinite(args.lockstep_timeout_ms) and args.lockstep_timeout_ms > 0):
            raise ValueError(f"--lockstep-timeout-ms {args.lockstep_timeout_ms} must be positive")
        driver = MujocoDriver(scenario, scene)
        if args.duration is not None:
            driver.set_duration(args.duration)
        lockstep = args.lockstep or (not args.realtime and scenario.mode == "lockstep")
        if args.sched_priority is not None:
            set_fifo_priority(args.sched_priority)
    except (ScenarioError, ValueError, ipc.IpcError) as e:
        print(f"hcc.mujoco: error: {e}", file=sys.stderr)
        return 2
    print(
        f"hcc.mujoco: {scenario.name} ({driver.n} joints), "
        f"{'lockstep' if lockstep else 'realtime'} mode, namespace {namespace!r}, "
        f"MuJoCo RK4 dt {scenario.integrator_dt_s} s x {scenario.substeps}",
        file=sys.stderr,
    )
    try:
        run(
            driver,
            namespace,
            lockstep=lockstep,
            lockstep_timeout_s=args.lockstep_timeout_ms * 1e-3,
            file_prefix=args.file_prefix,
            contact_csv=args.contact_csv,
            record_csv=args.record,
            stats_path=args.stats,
        )
    except (ipc.IpcError, FloatingPointError, OSError) as e:
        print(f"hcc.mujoco: error: {e}", file=sys.stderr)
        return 1
    return 0


if __name__ == "__main__":
    sys.exit(main())
