"""A test client of ``hcc view``: the ``websockets`` package speaks WebSocket,
this module reads the Foxglove SDK's framing on top of it (subprotocol
``foxglove.sdk.v1``: JSON text messages with an ``op``, binary messages with
an opcode byte), and starts ``hcc view`` beside a run.
"""

from __future__ import annotations

import contextlib
import json
import os
import pathlib
import socket
import struct
import subprocess
import time
from dataclasses import dataclass, field
from typing import Any, Iterator

from websockets.sync.client import ClientConnection, connect

from procs import free_port, started

SUBPROTOCOL = "foxglove.sdk.v1"
#: Binary opcodes of the server.
MESSAGE_DATA = 1
FETCH_ASSET_RESPONSE = 4


def wait_for_port(port: int, timeout: float = 60.0, proc: subprocess.Popen | None = None) -> None:
    """Waits until something accepts TCP connections on 127.0.0.1:``port``."""
    deadline = time.monotonic() + timeout
    while True:
        try:
            with socket.create_connection(("127.0.0.1", port), timeout=1.0):
                return
        except OSError:
            if proc is not None and proc.poll() is not None:
                raise AssertionError(f"the server process ended ({proc.returncode})") from None
            if time.monotonic() > deadline:
                raise AssertionError(f"nothing listens on port {port} after {timeout} s") from None
            time.sleep(0.05)


@dataclass
class Message:
    """One MessageData frame."""

    topic: str
    log_time: int
    data: bytes

    def json(self) -> Any:
        return json.loads(self.data)


@dataclass
class Client:
    """A connected client: the server's info and advertised channels."""

    ws: ClientConnection
    server_info: dict = field(default_factory=dict)
    channels: dict[str, dict] = field(default_factory=dict)
    subscriptions: dict[int, str] = field(default_factory=dict)
    next_sub: int = 1

    def _handle_text(self, msg: dict) -> None:
        if msg.get("op") == "serverInfo":
            self.server_info = msg
        elif msg.get("op") == "advertise":
            for ch in msg["channels"]:
                self.channels[ch["topic"]] = ch

    def wait_for_channels(self, topics: list[str], timeout: float = 10.0) -> None:
        """Reads until every topic in ``topics`` is advertised."""
        deadline = time.monotonic() + timeout
        while not all(t in self.channels for t in topics):
            left = deadline - time.monotonic()
            assert left > 0, f"not advertised within {timeout} s: {topics}; have {list(self.channels)}"
            frame = self.ws.recv(timeout=left)
            if isinstance(frame, str):
                self._handle_text(json.loads(frame))

    def subscribe(self, *topics: str) -> None:
        """Subscribes to ``topics`` (advertised already)."""
        subs = []
        for t in topics:
            sid = self.next_sub
            self.next_sub += 1
            self.subscriptions[sid] = t
            subs.append({"id": sid, "channelId": self.channels[t]["id"]})
        self.ws.send(json.dumps({"op": "subscribe", "subscriptions": subs}))

    def recv(self, timeout: float) -> Message | dict | bytes | None:
        """The next frame: a Message, a JSON dict, other binary bytes, or None on timeout."""
        try:
            frame = self.ws.recv(timeout=timeout)
        except TimeoutError:
            return None
        if isinstance(frame, str):
            msg = json.loads(frame)
            self._handle_text(msg)
            return msg
        if frame and frame[0] == MESSAGE_DATA:
            sid, log_time = struct.unpack_from("<IQ", frame, 1)
            return Message(self.subscriptions.get(sid, f"?{sid}"), log_time, frame[13:])
        return frame

    def messages(self, seconds: float) -> Iterator[Message]:
        """Every message received during ``seconds``."""
        end = time.monotonic() + seconds
        while (left := end - time.monotonic()) > 0:
            m = self.recv(min(left, 0.5))
            if isinstance(m, Message):
                yield m

    def fetch_asset(self, uri: str, request_id: int, timeout: float = 10.0) -> tuple[int, bytes]:
        """(status, data or error text) of a fetchAsset request (status 0 = success)."""
        self.ws.send(json.dumps({"op": "fetchAsset", "uri": uri, "requestId": request_id}))
        end = time.monotonic() + timeout
        while (left := end - time.monotonic()) > 0:
            frame = self.recv(left)
            if isinstance(frame, bytes) and frame[0] == FETCH_ASSET_RESPONSE:
                rid, status, err_len = struct.unpack_from("<IBI", frame, 1)
                if rid == request_id:
                    body = frame[10:]
                    return status, body[:err_len] if status else body
        raise AssertionError(f"no answer to fetchAsset {uri} within {timeout} s")


@contextlib.contextmanager
def client(port: int, **kw: Any) -> Iterator[Client]:
    """A client connected to ``hcc view`` on ``port`` with the SDK's subprotocol."""
    with connect(f"ws://127.0.0.1:{port}", subprotocols=[SUBPROTOCOL], open_timeout=20, **kw) as ws:
        assert ws.subprotocol == SUBPROTOCOL
        yield Client(ws)


@contextlib.contextmanager
def view_process(args: list[str], env: dict[str, str], log: pathlib.Path, binary: pathlib.Path) -> Iterator[tuple[subprocess.Popen, int]]:
    """``hcc view ARGS --port 0``; yields the process and the port it printed."""
    with started([str(binary), "view", *args, "--port", "0"], env, log) as p:
        deadline = time.monotonic() + 60
        while "hcc view: ws://127.0.0.1:" not in (text := log.read_text()):
            assert p.poll() is None and time.monotonic() < deadline, f"hcc view said: {text}"
            time.sleep(0.05)
        yield p, int(text.split("hcc view: ws://127.0.0.1:")[1].split()[0])


def env_with_prefix(prefix: str) -> dict[str, str]:
    return dict(os.environ, HCC_IPC_FILE_PREFIX=prefix)
