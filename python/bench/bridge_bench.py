"""Measures hcc bridge: state → remote subscriber latency, bytes per second
and drops at 100 Hz and 1 kHz on loopback, and the controller's state →
command latency with and without the bridge (the same run, alternating).

    python/.venv/bin/python python/bench/bridge_bench.py [--seconds 10] [--phases 3]

Starts hcc-controller and hcc-sim (the Panda, real time) in a namespace of
its own; this process is the Zenoh router (a loopback port of its own) and
the remote subscriber; ``hcc bridge`` runs as a peer of it. Latency of a
joint state = the subscriber's CLOCK_REALTIME at reception − the state's
sampling instant (the bridge stamps ROS messages with the daemons'
CLOCK_MONOTONIC moved to CLOCK_REALTIME by one offset): driver → iceoryx2
→ bridge (≤ 1 ms poll) → CDR → Zenoh TCP → Python callback. The
controller's latency = telemetry's wake-up latency + compute time of each
cycle (state stamp → command sent). Prints figures; asserts nothing.
"""

from __future__ import annotations

import argparse
import json
import os
import pathlib
import signal
import socket
import subprocess
import sys
import tempfile
import threading
import time

import iceoryx2 as iox2
import zenoh

from hcc import Client, ipc
from hcc.msgs import JointState, Telemetry
from hcc.remote import read_attachment, topic_key, JOINT_STATE

ROOT = pathlib.Path(__file__).resolve().parents[2]
SCENARIO = ROOT / "config" / "panda-pose-posture.toml"


def binary(name: str) -> str:
    found = [ROOT / "target" / p / name for p in ("release", "debug")]
    found = [p for p in found if p.exists()]
    if not found:
        sys.exit(f"{name} is not built: cargo build --release --workspace --bins")
    return str(max(found, key=lambda p: p.stat().st_mtime))


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def pct(values: list[float], q: float) -> float:
    if not values:
        return float("nan")
    v = sorted(values)
    return v[min(len(v) - 1, int(q * len(v)))]


class Receiver:
    """Every sample of the bridge: latency of joint states, bytes, sequence gaps."""

    def __init__(self, state_key: str) -> None:
        self.state_key = state_key
        self.lock = threading.Lock()
        self.reset()

    def reset(self) -> None:
        with getattr(self, "lock", threading.Lock()):
            self.latency_us: list[float] = []
            self.bytes = 0
            self.count = 0
            self.last_seq: dict[str, int] = {}
            self.gaps = 0

    def __call__(self, s: zenoh.Sample) -> None:
        now = time.time_ns()
        key = str(s.key_expr)
        payload = s.payload.to_bytes()
        att = s.attachment.to_bytes() if s.attachment is not None else b""
        with self.lock:
            self.count += 1
            self.bytes += len(payload) + len(att)
            seq, _, _ = read_attachment(att)
            last = self.last_seq.get(key)
            if last is not None and seq > last + 1:
                self.gaps += seq - last - 1
            self.last_seq[key] = seq
            if key == self.state_key:
                sec, nsec = int.from_bytes(payload[4:8], "little", signed=True), int.from_bytes(payload[8:12], "little")
                self.latency_us.append((now - (sec * 1_000_000_000 + nsec)) / 1e3)


def start_bridge(ns: str, env: dict[str, str], config: pathlib.Path, rate: float) -> subprocess.Popen:
    cmd = [binary("hcc"), "bridge", "--namespace", ns, "--config", str(SCENARIO),
           "--zenoh-config", str(config), "--rate", str(rate), "--quiet"]
    return subprocess.Popen(cmd, env=env, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)


def stop_bridge(p: subprocess.Popen) -> dict[str, float]:
    p.send_signal(signal.SIGTERM)
    out, _ = p.communicate(timeout=20)
    line = next((x for x in out.splitlines() if x.startswith("{")), "{}")
    return json.loads(line)


def collect_controller(client: Client, seconds: float) -> tuple[list[float], int]:
    """State → command latencies (µs) of the controller over ``seconds``, and driver misses."""
    lat: list[float] = []
    first = last = None
    end = time.monotonic() + seconds
    while time.monotonic() < end:
        for t in ipc.receive_all(client._telemetry, Telemetry):
            lat.append((t.timings.wakeup_latency_ns + t.timings.compute_ns) / 1e3)
        for s in ipc.receive_all(client._states, JointState):
            first = s.missed_commands if first is None else first
            last = s.missed_commands
        time.sleep(0.002)
    return lat, (last or 0) - (first or 0)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seconds", type=float, default=10.0, help="measuring time per rate")
    ap.add_argument("--phases", type=int, default=3, help="on/off pairs for the controller's latency")
    ap.add_argument("--phase-seconds", type=float, default=5.0)
    args = ap.parse_args()
    ns = f"bench_{os.getpid()}"
    prefix = f"hccbench{os.getpid()}_"
    env = dict(os.environ, HCC_IPC_FILE_PREFIX=prefix)
    tmp = pathlib.Path(tempfile.mkdtemp(prefix="hcc-bridge-bench-"))
    port = free_port()
    config = tmp / "zenoh.json5"
    config.write_text('{ mode: "peer", connect: { endpoints: ["tcp/127.0.0.1:%d"] }, '
                      'listen: { endpoints: ["tcp/127.0.0.1:0"] }, '
                      "scouting: { multicast: { enabled: false } } }" % port)
    conf = zenoh.Config()
    conf.insert_json5("mode", '"router"')
    conf.insert_json5("listen/endpoints", f'["tcp/127.0.0.1:{port}"]')
    conf.insert_json5("scouting/multicast/enabled", "false")
    duration = 2 * args.seconds + 2 * args.phases * args.phase_seconds + 60
    daemons = [
        subprocess.Popen([binary("hcc-controller"), str(SCENARIO), "--namespace", ns], env=env,
                         stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL),
        subprocess.Popen([binary("hcc-sim"), str(SCENARIO), "--namespace", ns, "--realtime",
                          "--duration", str(duration)], env=env,
                         stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL),
    ]
    session = zenoh.open(conf)
    try:
        time.sleep(2.0)
        recv = Receiver(topic_key(0, f"/{ns}/joint_states", JOINT_STATE))
        session.declare_subscriber("0/**", recv)
        print(f"state → remote subscriber, loopback TCP, {args.seconds:.0f} s per rate")
        print("rate    samples  p50 µs  p99 µs  p99.9 µs  max µs   kB/s    zenoh gaps  ipc lost  dropped behind")
        for rate in (100.0, 1000.0):
            b = start_bridge(ns, env, config, rate)
            time.sleep(2.0)
            recv.reset()
            time.sleep(args.seconds)
            with recv.lock:
                lat, nbytes, gaps = list(recv.latency_us), recv.bytes, recv.gaps
            summary = stop_bridge(b)
            print(f"{rate:6.0f}  {len(lat):7d}  {pct(lat, .5):6.0f}  {pct(lat, .99):6.0f}  {pct(lat, .999):8.0f}  "
                  f"{max(lat, default=float('nan')):6.0f}  {nbytes / args.seconds / 1e3:6.1f}  {gaps:10d}  "
                  f"{summary.get('bridge_ipc_lost', -1):8.0f}  {summary.get('bridge_dropped_behind', -1):14.0f}")
        with Client(ns, file_prefix=prefix) as client:
            on: list[float] = []
            off: list[float] = []
            misses = {"on": 0, "off": 0}
            for _ in range(args.phases):
                b = start_bridge(ns, env, config, 1000.0)
                time.sleep(1.0)
                lat, m = collect_controller(client, args.phase_seconds)
                on += lat
                misses["on"] += m
                stop_bridge(b)
                time.sleep(0.5)
                lat, m = collect_controller(client, args.phase_seconds)
                off += lat
                misses["off"] += m
        print(f"\ncontroller state → command latency, {args.phases} × {args.phase_seconds:.0f} s each, alternating")
        print("bridge (1 kHz)  cycles   p50 µs  p99 µs  p99.9 µs  max µs  driver misses")
        for name, lat in (("running", on), ("stopped", off)):
            key = "on" if name == "running" else "off"
            print(f"{name:14s}  {len(lat):6d}  {pct(lat, .5):6.1f}  {pct(lat, .99):6.1f}  {pct(lat, .999):8.1f}  "
                  f"{max(lat, default=float('nan')):6.1f}  {misses[key]:13d}")
    finally:
        session.close()
        for p in daemons:
            p.send_signal(signal.SIGTERM)
        for p in daemons:
            try:
                p.wait(timeout=10)
            except subprocess.TimeoutExpired:
                p.kill()
        iox_root = iox2.config.default().global_cfg.root_path.to_string()
        for root in (pathlib.Path("/dev/shm"), pathlib.Path(iox_root)):
            if root.is_dir():
                for f in root.rglob(f"{prefix}*"):
                    if f.is_file():
                        f.unlink(missing_ok=True)
        for f in tmp.iterdir():
            f.unlink()
        tmp.rmdir()


if __name__ == "__main__":
    main()
