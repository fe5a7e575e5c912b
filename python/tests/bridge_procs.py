"""Starting a Zenoh router and ``hcc bridge`` beside a controller pair, on
the test's own loopback port, and cleaning up."""

from __future__ import annotations

import contextlib
import os
import pathlib
import subprocess
import sys
import time
from typing import Iterator

from conftest import binary
from procs import free_port, started

HERE = pathlib.Path(__file__).resolve().parent


@contextlib.contextmanager
def router(tmp: pathlib.Path) -> Iterator[int]:
    """A Zenoh router process on a free loopback port; yields the port."""
    port = free_port()
    log = tmp / "router.log"
    with started([sys.executable, str(HERE / "zenoh_router.py"), str(port)], dict(os.environ), log):
        wait_for(lambda: "ready" in log.read_text(), 30.0, f"the Zenoh router on port {port}")
        yield port


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


def bridge_cmd(
    ns: str, scenario: pathlib.Path | None, config: pathlib.Path, *extra: str
) -> list[str]:
    """The command line of ``hcc bridge`` (``scenario`` None: the namespace
    alone, the scenario from the controller's scenario service)."""
    given = ["--config", str(scenario)] if scenario is not None else []
    return [str(binary("hcc")), "bridge", "--namespace", ns, *given,
            "--zenoh-config", str(config), *extra]


@contextlib.contextmanager
def bridge(ns: str, prefix: str, scenario: pathlib.Path | None, config: pathlib.Path,
           log: pathlib.Path, *extra: str) -> Iterator[subprocess.Popen]:
    """``hcc bridge`` on ``ns``; stopped with SIGTERM (then SIGKILL) on exit."""
    env = dict(os.environ, HCC_IPC_FILE_PREFIX=prefix)
    with started(bridge_cmd(ns, scenario, config, *extra), env, log) as p:
        yield p


def wait_for(predicate, timeout: float, what: str) -> None:  # type: ignore[no-untyped-def]
    """Polls ``predicate`` until true; AssertionError naming ``what`` after ``timeout`` s."""
    deadline = time.monotonic() + timeout
    while not predicate():
        if time.monotonic() >= deadline:
            raise AssertionError(f"timed out waiting for {what}")
        time.sleep(0.01)
