"""The MuJoCo driver in real time at 1 kHz against hcc-controller, watched by hcc.Client.

Prints the driver's tick lateness and miss rate (the figures of a soft
real-time Python plant; they depend on the machine's load) and checks what
must hold regardless: the run completes, commands are applied, the client
sees consecutive joint states and telemetry, and the TCP converges.
"""

from __future__ import annotations

import json
import pathlib
import subprocess

from hcc import Client, JointState

from conftest import ROOT
from procs import run_pair


def test_realtime_run_with_a_client(tmp_path: pathlib.Path) -> None:
    seen: dict[str, object] = {}

    def watch(namespace: str, prefix: str, driver: subprocess.Popen) -> None:
        with Client(namespace, file_prefix=prefix) as client:
            state = client.latest_joint_state(timeout=10.0)
            assert state is not None, "no joint state within 10 s"
            seen["n"] = state.n()
            states: list[JointState] = []
            for s in client.joint_states(timeout=1.0):
                states.append(s)
                if len(states) == 50:
                    break
            seen["seqs"] = [s.header.seq for s in states]
            seen["converged_error"] = client.wait_until_converged(0, 1e-3, timeout=5.5)
            t = client.latest_telemetry()
            seen["levels"] = t.levels() if t is not None else 0
            seen["latest_cycles"] = t.counters.cycles if t is not None else 0

    paths = run_pair(
        ROOT / "config" / "paper-sim1.toml", tmp_path, lockstep=False, duration=6.0,
        on_started=watch,
    )
    stats = json.loads(paths["stats"].read_text())
    lateness = stats["tick_lateness"]
    miss_rate = stats["missed_commands"] / stats["periods"]
    print(
        f"real time 1 kHz: tick lateness p50 {lateness['p50_us']:.1f} µs, p99 "
        f"{lateness['p99_us']:.1f} µs, max {lateness['max_us']:.1f} µs; missed commands "
        f"{stats['missed_commands']} of {stats['periods']} periods ({100 * miss_rate:.2f} %, "
        f"{stats['short_window_misses']} after a late tick), {stats['overruns']} overruns; state → command p50 {stats['state_to_command']['p50_us']:.1f} µs"
    )
    assert stats["periods"] == 6000
    assert stats["applied_commands"] > 0
    # The misses after a late tick (the driver's lateness) are a part of all misses.
    assert 0 <= stats["short_window_misses"] <= stats["missed_commands"]
    # The client attached mid-run: the state publisher's connections were kept
    # up while the loop waited, once per period, without an error.
    assert stats["connection_updates"] >= 6000
    assert stats["connection_update_failures"] == 0
    assert seen["n"] == 4 and seen["levels"] == 3
    seqs = seen["seqs"]
    assert seqs == sorted(seqs) and len(set(seqs)) == len(seqs)
    assert seen["converged_error"] < 1e-3
    assert seen["latest_cycles"] > 0
