"""Starts the franka-sim FCI server (an FR3 or, with ``--protocol 5``, an
FER/Panda simulated with MuJoCo) bound to one address of this machine.

franka-sim's own command, ``run-franka-sim-server``, binds every interface
(0.0.0.0) and accepts ``--bind`` only together with ``--mobile-duo``; its
server class takes the address, so this launcher passes 127.0.0.1 (and a
port of the test's choosing, so that tests never collide). The gripper
server (a fixed port) is not started. The physics model comes from
``$FR3_MJCF`` (the tests point it at ``config/robots/fr3/fr3-nomesh.xml``,
so nothing is downloaded).

Usage: python franka_sim_launcher.py --port P [--protocol 10|5]
[--enforce-motion-limits] [--enforce-comm-constraints]. SIGTERM and SIGINT
stop the server cleanly.
"""

from __future__ import annotations

import argparse
import logging
import signal
import sys
from types import FrameType


def _interrupt(_signum: int, _frame: FrameType | None) -> None:
    raise KeyboardInterrupt


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--host", default="127.0.0.1")
    parser.add_argument("--port", type=int, required=True)
    parser.add_argument("--protocol", type=int, choices=(10, 5), default=10)
    parser.add_argument("--enforce-motion-limits", action="store_true")
    parser.add_argument("--enforce-comm-constraints", action="store_true")
    args = parser.parse_args()
    if not args.host.startswith("127."):
        parser.error("the test server binds a loopback address only")
    logging.basicConfig(
        level=logging.INFO,
        format="%(asctime)s %(levelname)s %(name)s: %(message)s",
        stream=sys.stdout,
    )
    from franka_sim import FrankaSimServer

    server = FrankaSimServer(
        host=args.host,
        port=args.port,
        enable_vis=False,
        enable_gripper=False,
        protocol_version=args.protocol,
        enforce_comm_constraints=args.enforce_comm_constraints,
        enforce_motion_limits=args.enforce_motion_limits,
    )
    signal.signal(signal.SIGTERM, _interrupt)
    signal.signal(signal.SIGINT, _interrupt)
    try:
        server.start()
    except KeyboardInterrupt:
        pass
    finally:
        server.stop()
    return 0


if __name__ == "__main__":
    sys.exit(main())
