"""A Zenoh router on one loopback TCP port, as a process of its own (the
"router" host of the bridge tests): ``python zenoh_router.py PORT``. Runs
until SIGTERM/SIGINT; prints ``ready`` once it listens."""

from __future__ import annotations

import signal
import sys
import threading

import zenoh


def main() -> None:
    port = int(sys.argv[1])
    conf = zenoh.Config()
    conf.insert_json5("mode", '"router"')
    conf.insert_json5("listen/endpoints", f'["tcp/127.0.0.1:{port}"]')
    conf.insert_json5("scouting/multicast/enabled", "false")
    stop = threading.Event()
    signal.signal(signal.SIGTERM, lambda *_: stop.set())
    signal.signal(signal.SIGINT, lambda *_: stop.set())
    session = zenoh.open(conf)
    print("ready", flush=True)
    stop.wait()
    session.close()


if __name__ == "__main__":
    main()
