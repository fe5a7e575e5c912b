"""Franka's own client (pylibfranka, which bundles libfranka) as a test peer:
a torque loop against the franka-sim server, to compare what the simulated
robot does under libfranka with what it does under hcc-franka.

Usage: python libfranka_peer.py --cycles N [--jump NM]. It connects to
127.0.0.1 (libfranka always uses the FCI port 1337), holds the arm with a
joint damping torque −D q̇ for N cycles, rate limited like libfranka's
``limit_rate`` (≤ 1 N·m per cycle), and, with ``--jump``, commands one
unlimited step of NM N·m on joint 7 halfway. It prints one JSON line:
``{"cycles": run, "errors": [robot error names], "message": text}``.
"""

from __future__ import annotations

import argparse
import json
import sys

import pylibfranka as franka

#: The fallback damping of hcc-franka's [franka] defaults, N·m·s/rad.
DAMPING = [10.0, 10.0, 10.0, 10.0, 4.0, 4.0, 1.0]


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--cycles", type=int, default=2000)
    parser.add_argument("--jump", type=float, default=0.0)
    args = parser.parse_args()
    robot = franka.Robot("127.0.0.1", franka.RealtimeConfig.kIgnore)
    control = robot.start_torque_control()
    last = [0.0] * 7
    run = 0
    result: dict[str, object] = {"cycles": 0, "errors": [], "message": ""}
    try:
        for k in range(args.cycles):
            state, _ = control.readOnce()
            tau = [-d * v for d, v in zip(DAMPING, state.dq)]
            tau = [min(max(t, l - 0.999), l + 0.999) for t, l in zip(tau, last)]
            if args.jump and k == args.cycles // 2:
                tau[6] = last[6] + args.jump
            torques = franka.Torques(tau)
            if k == args.cycles - 1:
                torques.motion_finished = True
            control.writeOnce(torques)
            last = tau
            run = k + 1
    except franka.ControlException as e:
        state = robot.read_once()
        result["errors"] = _names(state.last_motion_errors)
        result["message"] = str(e)
    result["cycles"] = run
    print(json.dumps(result), flush=True)
    return 0


def _names(errors: object) -> list[str]:
    """The set flags of a libfranka ``Errors``, by name."""
    text = str(errors)
    return [n.strip(' "') for n in text.strip("[]").split(",") if n.strip(' "')]


if __name__ == "__main__":
    sys.exit(main())
