"""Starting a Zenoh router and ``hcc bridge`` beside a controller pair, on
the test's own loopback port, and cleaning up."""

from __future__ import annotations

import contextlib
import os
import pathlib
import signal
import socket
import subprocess
import sys
import time
from typing import Iterator

from conftest import ROOT, binary

HERE = pathlib.Path(__file__).resolve().parent


def free_port() -> int:
    """A TCP port on 127.0.0.1 that is free now (bound to port 0 and released)."""
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


@contextlib.contextmanager
def router(tmp: pathlib.Path) -> Iterator[int]:
    """A Zenoh router process on a free loopback port; yields the port."""
    port = free_port()
    log = open(tmp / "router.log", "w")
    p = subprocess.Popen([sys.executable, str(HERE / "zenoh_router.py"), str(port)],
                         stdout=subprocess.PIPE, stderr=log, text=True)
    try:
        assert p.stdout is not None
        line = p.stdout.readline()
        assert line.strip() == "ready", f"router did not start: {(tmp / 'router.log').read_text()}"
        yield port
    finally:
        p.send_signal(signal.SIGTERM)
        try:
            p.wait(timeout=10)
        except subprocess.TimeoutExpired:
            p.kill()
            p.wait()
        log.close()


def zenoh_config(tmp: pathlib.Path, port: int) -> pathlib.Path:
    """A bridge's Zenoh configuration: a peer of the router on ``port``, loopback only."""
    path = tmp / "zenoh.json5"
    path.write_text(
        "{\n"
        '  mode: "peer",\n'
        f'  connect: {{ endpoints: ["tcp/127.0.0.1:{port}"] }},\n'
        '  listen: { endpoints: ["tcp/127.0.0.1:0"] },\n'
        "  scouting: { multicast: { enabled: false }, gossip: { enabled: true } },\n"
        "}\n"
    )
    return path


def bridge_cmd(ns: str, scenario: pathlib.Path, config: pathlib.Path, *extra: str) -> list[str]:
    """The command line of ``hcc bridge``."""
    return [str(binary("hcc")), "bridge", "--namespace", ns, "--config", str(scenario),
            "--zenoh-config", str(config), *extra]


@contextlib.contextmanager
def bridge(ns: str, prefix: str, scenario: pathlib.Path, config: pathlib.Path,
           log: pathlib.Path, *extra: str) -> Iterator[subprocess.Popen]:
    """``hcc bridge`` on ``ns``; stopped with SIGTERM (then SIGKILL) on exit."""
    env = dict(os.environ, HCC_IPC_FILE_PREFIX=prefix)
    out = open(log, "w")
    p = subprocess.Popen(bridge_cmd(ns, scenario, config, *extra), cwd=ROOT, env=env,
                         stdout=out, stderr=subprocess.STDOUT)
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


def wait_for(predicate, timeout: float, what: str) -> None:  # type: ignore[no-untyped-def]
    """Polls ``predicate`` until true; AssertionError naming ``what`` after ``timeout`` s."""
    deadline = time.monotonic() + timeout
    while not predicate():
        if time.monotonic() >= deadline:
            raise AssertionError(f"timed out waiting for {what}")
        time.sleep(0.01)
