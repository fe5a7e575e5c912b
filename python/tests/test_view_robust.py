"""``hcc view`` survives what clients and peers do to it.

A standalone ``hcc view`` watches a controller and a simulator. It keeps
serving through 100 clients that connect and drop at random (closing
cleanly, vanishing mid-stream, or leaving without a handshake), through
malformed client messages, and through the controller and simulator being
stopped and started again in the same namespace (their sequence numbers
restart: counted on ``/view``, and the new run is served). It serves the
URDF as an asset and nothing outside the URDF's directory. A recording
played back through it (``hcc view FILE.mcap``) serves the recorded
joint states unchanged.
"""

from __future__ import annotations

import contextlib
import json
import os
import pathlib
import random
import re
import socket
import subprocess
import time
from typing import Any, Iterator

import foxglove_ws as fx
from conftest import ROOT, binary, unique
from procs import remove_ipc_files, started

CONFIG = ROOT / "config" / "paper-sim1.toml"
URDF = ROOT / "config" / "planar4.urdf"


@contextlib.contextmanager
def daemons(ns: str, env: dict[str, str], tmp: pathlib.Path, tag: str) -> Iterator[None]:
    """hcc-controller and a real-time hcc-sim (60 s) in ``ns``; stopped (SIGTERM) on exit."""
    controller = [str(binary("hcc-controller")), str(CONFIG), "--namespace", ns]
    sim = [str(binary("hcc-sim")), str(CONFIG), "--namespace", ns, "--realtime", "--duration", "60"]
    with started(controller, env, tmp / f"controller-{tag}.log"):
        time.sleep(0.5)
        with started(sim, env, tmp / f"sim-{tag}.log"):
            yield


def joint_states(port: int, seconds: float) -> list[dict]:
    """The joint states a fresh client receives in ``seconds``."""
    with fx.client(port) as c:
        c.wait_for_channels(["/joint_state"])
        c.subscribe("/joint_state")
        return [m.json() for m in c.messages(seconds) if m.topic == "/joint_state"]


def view_counts(port: int) -> dict:
    """The next ``/view`` message."""
    with fx.client(port) as c:
        c.wait_for_channels(["/view"])
        c.subscribe("/view")
        for m in c.messages(5.0):
            return m.json()
    raise AssertionError("no /view message within 5 s")


def random_client(port: int, rng: random.Random) -> None:
    """Connects and leaves in one of several ways."""
    how = rng.randrange(4)
    if how == 0:
        # TCP only, no handshake, or half a handshake.
        with socket.create_connection(("127.0.0.1", port)) as s:
            if rng.random() < 0.5:
                s.sendall(b"GET / HTTP/1.1\r\nHost: x\r\nUpgrade: websocket\r\n")
        return
    with fx.client(port, close_timeout=0.2) as c:
        c.wait_for_channels(["/joint_state", "/telemetry", "/tf"])
        if how >= 2:
            c.subscribe(*rng.sample(sorted(c.channels), k=rng.randrange(1, len(c.channels))))
            for _ in range(rng.randrange(20)):
                c.recv(0.05)
        if how == 3:
            # Vanish without a close frame.
            c.ws.socket.shutdown(socket.SHUT_RDWR)


MALFORMED: list[str | bytes] = [
    "not json",
    "{}",
    '{"op": "subscribe"}',
    '{"op": "subscribe", "subscriptions": [{"id": 1, "channelId": 999999}]}',
    '{"op": "subscribe", "subscriptions": [{"id": "x", "channelId": -1}]}',
    '{"op": "unsubscribe", "subscriptionIds": [424242]}',
    '{"op": "advertise", "channels": [{"id": 1, "topic": "/joint_state", "encoding": "json", "schemaName": "x"}]}',
    '{"op": "getParameters", "parameterNames": ["a"]}',
    '{"op": "fetchAsset", "uri": 7, "requestId": "no"}',
    '{"op": "no such op"}',
    json.dumps({"op": "subscribe", "subscriptions": [{"id": k, "channelId": 1} for k in range(1000)]}),
    b"",
    b"\x01",
    b"\x02\xff\xff\xff\xff" + os.urandom(64),
    os.urandom(4096),
    "[" * 10000,
]


def test_the_server_survives_clients_garbage_and_restarts(tmp_path: pathlib.Path) -> None:
    ns = unique("pyviewr")
    prefix = f"{unique('hccvr')}_"[:32]
    env = fx.env_with_prefix(prefix)
    rng = random.Random(20131103)
    try:
        with fx.view_process(
            ["--namespace", ns, "--config", str(CONFIG), "--rate", "50"],
            env, tmp_path / "view.log", binary("hcc"),
        ) as (view, port):
            with daemons(ns, env, tmp_path, "1"):
                first = joint_states(port, 1.5)
                assert len(first) > 30, (tmp_path / "view.log").read_text()

                for _ in range(100):
                    random_client(port, rng)
                assert view.poll() is None, (tmp_path / "view.log").read_text()

                for bad in MALFORMED:
                    with contextlib.suppress(Exception), fx.client(port, close_timeout=0.2) as c:
                        c.ws.send(bad)
                        for _ in range(5):
                            c.recv(0.05)
                assert view.poll() is None, (tmp_path / "view.log").read_text()

                with fx.client(port) as c:
                    c.wait_for_channels(["/joint_state"])
                    status, urdf = c.fetch_asset("package://hcc/robot.urdf", 1)
                    assert (status, urdf) == (0, URDF.read_bytes())
                    for k, uri in enumerate(["package://hcc/../paper-sim1.toml", "/etc/passwd",
                                             "file:///etc/passwd", "package://x/missing.dae"]):
                        status, err = c.fetch_asset(uri, 10 + k)
                        assert status == 1, f"{uri} was served"

                after_garbage = joint_states(port, 1.5)
                assert len(after_garbage) > 30
                assert after_garbage[0]["seq"] > first[-1]["seq"]

            # The controller and the simulator stop and start again.
            time.sleep(0.5)
            with daemons(ns, env, tmp_path, "2"):
                time.sleep(1.0)
                second = joint_states(port, 1.5)
                counts = view_counts(port)
            assert view.poll() is None, (tmp_path / "view.log").read_text()
    finally:
        remove_ipc_files(prefix)
    print(f"\nafter the restart: {len(second)} joint states, /view: {counts}")
    assert len(second) > 30
    assert second[0]["seq"] < after_garbage[-1]["seq"], "the restarted simulator counts from 0"
    assert counts["joint_state"]["restarts"] >= 1
    assert counts["telemetry"]["restarts"] >= 1


def test_a_recording_plays_back_unchanged(tmp_path: pathlib.Path) -> None:
    """``hcc run --lockstep`` records run.mcap; ``hcc view run.mcap --rate 0``
    serves every recorded joint state, equal in value, and a transform set
    with each."""
    from mcap.reader import make_reader

    ns = unique("pyviewp")
    prefix = f"{unique('hccvp')}_"[:32]
    env = fx.env_with_prefix(prefix)
    out = tmp_path / "out"
    try:
        r = subprocess.run(
            [str(binary("hcc")), "run", str(CONFIG), "--lockstep", "--duration", "0.5",
             "--namespace", ns, "--out", str(out), "--no-plots", "--quiet"],
            cwd=ROOT, env=env, capture_output=True, text=True, timeout=300,
        )
        assert r.returncode == 0, r.stderr
    finally:
        remove_ipc_files(prefix)
    recording = out / "run.mcap"
    with open(recording, "rb") as f:
        recorded = [
            json.loads(m.data)
            for _s, ch, m in make_reader(f).iter_messages()
            if ch.topic == "/joint_state"
        ]
    assert len(recorded) > 400
    paths = layout_paths()
    topics = sorted({p.split(".")[0] for p in paths} | {"/joint_state", "/tf"})
    with fx.view_process(
        [str(recording), "--rate", "0", "--speed", "0.25"], env, tmp_path / "view.log", binary("hcc")
    ) as (view, port):
        with fx.client(port) as c:
            c.wait_for_channels(topics)
            c.subscribe(*topics)
            got, tf, last = [], 0, {}
            for m in c.messages(4.0):
                if m.topic == "/joint_state":
                    got.append(m.json())
                if m.topic == "/tf":
                    tf += 1
                else:
                    last[m.topic] = m.json()
    # A lockstep simulator republishes its first state every 20 ms until the
    # first command: a controller slower to start than that leaves it twice
    # in the recording, and the view serves each state once (a duplicate
    # sequence number is not a new state).
    served: list[dict[str, Any]] = []
    for m in recorded:
        if not served or m["seq"] != served[-1]["seq"]:
            served.append(m)
    by_seq = {m["seq"]: m for m in served}
    print(
        f"\nplayback: {len(got)} of {len(recorded)} recorded joint states "
        f"({len(recorded) - len(served)} republished), {tf} transform sets"
    )
    # The playback waits for the first subscriber: it sees the whole run.
    assert got == served
    assert tf == len(served)
    assert len(by_seq) == len(served)
    # The layouts' message paths find their fields in the served messages
    # (null where the URDF gives no limit; joint indices beyond the planar
    # arm's 4 joints, and task rows beyond a level's dimension, excepted).
    n_joints = len(recorded[0]["q"])
    for p in paths:
        topic, *fields = p.split(".")
        v = value_at(last[topic], fields)
        beyond = max_index(p) >= n_joints or beyond_level_rows(last[topic], p)
        assert v is not MISSING or beyond, f"{p} has no value"


def beyond_level_rows(msg: object, path: str) -> bool:
    """Whether ``path`` is a task row ``levels[i].goal[k]`` or ``levels[i].error[k]`` beyond
    level i's dimension (the length of its ``error`` in ``msg``)."""
    m = re.fullmatch(r"/telemetry\.levels\[(\d+)\]\.(goal|error)\[(\d+)\]", path)
    if m is None or not isinstance(msg, dict):
        return False
    levels = msg.get("levels", [])
    i, k = int(m.group(1)), int(m.group(3))
    return i < len(levels) and k >= len(levels[i].get("error", []))


def layout_paths() -> list[str]:
    """Every message path of the layouts in docs/foxglove."""
    out = []
    for f in sorted((ROOT / "docs" / "foxglove").glob("*.json")):
        for panel in json.loads(f.read_text())["configById"].values():
            out += [p["value"] for p in panel.get("paths", [])]
            if "topicPath" in panel:
                out.append(panel["topicPath"])
    assert out
    return out


MISSING = object()


def value_at(msg: object, fields: list[str]) -> object:
    """The value at ``a[0].b`` (as split at the dots) in a decoded message, or MISSING."""
    for f in fields:
        name, *idx = f.replace("]", "").split("[")
        if not isinstance(msg, dict) or name not in msg:
            return MISSING
        msg = msg[name]
        for k in idx:
            if not isinstance(msg, list) or int(k) >= len(msg):
                return MISSING
            msg = msg[int(k)]
    return msg


def max_index(path: str) -> int:
    """The largest index in a message path (-1 without one)."""
    return max((int(k.split("]")[0]) for k in path.split("[")[1:]), default=-1)


def test_the_view_needs_only_the_namespace(tmp_path: pathlib.Path) -> None:
    """``hcc view --namespace NS`` without ``--config``: the scenario comes from
    the controller's scenario service, so the view serves the robot (its
    URDF as an asset) and the joint states."""
    ns = unique("pyviewns")
    prefix = f"{unique('hccvn')}_"[:32]
    env = fx.env_with_prefix(prefix)
    try:
        with daemons(ns, env, tmp_path, "1"):
            with fx.view_process(
                ["--namespace", ns, "--rate", "50"], env, tmp_path / "view.log", binary("hcc"),
            ) as (view, port):
                states = joint_states(port, 1.0)
                assert len(states) > 20, (tmp_path / "view.log").read_text()
                with fx.client(port) as c:
                    c.wait_for_channels(["/joint_state"])
                    status, urdf = c.fetch_asset("package://hcc/robot.urdf", 1)
                    assert (status, urdf) == (0, URDF.read_bytes()), (
                        tmp_path / "view.log"
                    ).read_text()
                assert view.poll() is None
        log = (tmp_path / "view.log").read_text()
        assert "no transform tree" not in log, log
    finally:
        remove_ipc_files(prefix)
