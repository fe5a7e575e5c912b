"""Commanding a live hcc-controller + hcc-sim pair (the Panda, real time) from Python.

hcc.Client moves the TCP with set_goal (accepted, then within 1 mm of the
new goal once the transition is over), and the controller rejects bad
setpoints with its reason while the targets stay; a setpoint that fails the
model-free checks is refused before it is sent.
"""

from __future__ import annotations

import math
import pathlib
import time

import pytest

from hcc import Client, LoadRejection, SetpointError, SetpointRejected, SetpointRejection

from hcc import ipc
from circle import circle_knots, circle_sample
from conftest import ROOT, unique
from procs import remove_ipc_files, sim_pair

SCENARIO = ROOT / "config" / "panda-pose-posture.toml"
GOAL = [0.55, 0.10, 0.30]


def test_set_goal_converges_and_bad_setpoints_are_rejected(tmp_path: pathlib.Path) -> None:
    with (
        sim_pair(SCENARIO, tmp_path) as (ns, prefix, ctl, plant),
        Client(ns, file_prefix=prefix) as client,
    ):
        # The controller's scenario, from its service: the levels by name.
        assert client.level_names() == ["TCP position", "TCP orientation", "posture"]
        assert client.level("posture") == 2
        doc = client.scenario()
        assert doc["rate_hz"] == 1000.0 and doc["toml"] == SCENARIO.read_text()
        assert [j["name"] for j in doc["joints"]][0] == "panda_joint1" and len(doc["joints"]) == 7
        assert doc["levels"][0]["tasks"] == ["position"] and doc["levels"][0]["dim"] == 3
        with pytest.raises(ValueError, match="no level 'elbow'"):
            client.level("elbow")
        # The arm settles at the scenario's goal first.
        client.wait_until_converged(0, 1e-3, timeout=30.0)
        start = client.latest_telemetry()
        assert start is not None and start.levels() == 3

        t0 = time.monotonic()
        seq = client.set_goal(0, GOAL, duration=1.0)
        assert seq == client.last_seq == 1
        answer = client.wait_until_accepted(seq, timeout=5.0)
        assert answer.seq == seq and answer.client_id == client.client_id
        assert answer.accepted() and answer.level == 0 and answer.duration_s >= 1.0
        error = client.wait_until_converged(0, 1e-3, timeout=10.0)
        reached = time.monotonic() - t0
        t = client.latest_telemetry()
        assert t is not None
        moved = math.dist(start.goal_list(0), GOAL)
        print(
            f"set_goal: TCP goal moved {1e3 * moved:.1f} mm over {answer.duration_s:.2f} s, "
            f"within {1e3 * error:.3f} mm of it after {reached:.2f} s"
        )
        assert moved > 0.05
        assert t.goal_list(0) == pytest.approx(GOAL, abs=1e-12)
        assert error < 1e-3

        # Rejected by the controller, with its reason; nothing changes.
        seq = client.set_goal(0, [3.0, 0.0, 0.3], duration=1.0)
        with pytest.raises(SetpointRejected) as e:
            client.wait_until_accepted(seq, timeout=5.0)
        assert e.value.rejection is SetpointRejection.OUTSIDE_WORKSPACE is SetpointRejection(16)
        assert e.value.answer.seq == seq and "outside_workspace" in str(e.value)
        assert "workspace" in e.value.rejection.reason
        print(f"rejected: {e.value}")
        seq = client.set_gains(0, stiffness=[1e6, 1e6, 1e6])
        with pytest.raises(SetpointRejected) as e:
            client.wait_until_accepted(seq, timeout=5.0)
        assert e.value.rejection is SetpointRejection.STIFFNESS_ABOVE_LIMIT

        # Refused before sending (no sequence number used, nothing sent).
        before = client.last_seq
        with pytest.raises(SetpointError) as e:
            client.set_gains(0, damping=[[1.0, 2.0, 0.0], [2.0, 1.0, 0.0], [0.0, 0.0, 1.0]])
        assert e.value.rejection is SetpointRejection.NOT_POSITIVE_DEFINITE
        with pytest.raises(SetpointError) as e:
            client.set_goal(0, [0.5, math.nan, 0.3])
        assert e.value.rejection is SetpointRejection.NON_FINITE
        assert client.last_seq == before + 2, "each setpoint built takes a number"

        # A valid full stiffness and diagonal damping are accepted.
        k = [[400.0, 0.0, 0.0], [0.0, 400.0, 0.0], [0.0, 0.0, 300.0]]
        seq = client.set_gains(0, stiffness=k, damping=[40.0, 40.0, 35.0], duration=0.5)
        client.wait_until_accepted(seq, timeout=5.0)
        client.wait_until_converged(0, 1e-3, timeout=10.0)
        t = client.latest_telemetry()
        assert t is not None
        assert t.stiffness_diag_list(0) == pytest.approx([400.0, 400.0, 300.0])
        assert t.damping_diag_list(0) == pytest.approx([40.0, 40.0, 35.0])
        assert t.goal_list(0) == pytest.approx(GOAL, abs=1e-12), "targets kept"

        # The load in the hand (docs/load.md): refused with its reason, or
        # taken; the plant does not carry it, so the TCP moves by the weight
        # the model now compensates, and comes back when the hand is empty.
        with pytest.raises(SetpointRejected) as e:
            client.set_load(5.0, timeout=5.0)
        assert e.value.load_rejection is LoadRejection.ABOVE_PAYLOAD and "above_payload" in str(e.value)
        with pytest.raises(SetpointRejected) as e:
            client.set_load(1.0, inertia=[0.1, 0.0, 0.0, 0.1, 0.0, 0.3], timeout=5.0)
        assert e.value.load_rejection is LoadRejection.NOT_PHYSICAL
        with pytest.raises(SetpointError) as e:
            client.set_load(-1.0)
        assert e.value.rejection is LoadRejection.NEGATIVE_MASS
        assert client.set_load(0.5, (0.0, 0.0, 0.1), ramp_s=0.1, timeout=5.0).accepted()
        time.sleep(1.0)
        t = client.latest_telemetry()
        assert t is not None
        moved = t.error_norm(0)
        assert (t.load_mass, t.load_com_list(), t.load_progress) == (0.5, [0.0, 0.0, 0.1], 1.0)
        assert client.set_load(0.0, timeout=5.0).accepted()
        back = client.wait_until_converged(0, 1e-3, timeout=10.0)
        print(f"set_load: 0.5 kg told but not carried moves the TCP {1e3 * moved:.1f} mm; unloaded {1e3 * back:.3f} mm")
        assert moved > 1e-3 and back < 1e-3
        assert ctl.poll() is None and plant.poll() is None, "the pair keeps running"


def test_the_scenario_of_a_namespace_without_a_controller_says_which(tmp_path: pathlib.Path) -> None:
    """No controller: the client says none runs; a controller's node without
    the scenario service (an older one): the client says it is older. Both
    name the scenario file as the way out."""
    ns = unique("pyscn")
    prefix = f"{unique('hccscn')}_"[:32]
    try:
        with Client(ns, file_prefix=prefix) as client:
            with pytest.raises(ipc.ScenarioUnavailable, match="no controller runs") as e:
                client.scenario(timeout=0.05)
            assert "scenario file" in str(e.value)
            older = ipc.create_node(ipc.CONTROLLER_NODE, prefix)
            services = ipc.Services(older, ipc.ServiceNames(ns))
            with pytest.raises(ipc.ScenarioUnavailable, match="older than this client"):
                client.scenario(timeout=0.05)
            del services, older
    finally:
        remove_ipc_files(prefix)


def test_follow_sends_a_path_that_the_tcp_tracks(tmp_path: pathlib.Path) -> None:
    """Client.follow (docs/tracking.md): a circle the TCP follows within 1 mm
    from 3 s on; a path that starts away from the level is refused, naming
    its first knots and the reason."""
    from hcc import KnotsRefused, PathRejection

    with (
        sim_pair(SCENARIO, tmp_path) as (ns, prefix, ctl, plant),
        Client(ns, file_prefix=prefix) as client,
    ):
        client.wait_until_converged(0, 1e-3, timeout=30.0)
        t = client.latest_telemetry()
        assert t is not None
        start = t.goal_list(0)
        times, points = circle_knots(start, 5.0)
        answer = client.follow(0, times, points, timeout=5.0)
        assert answer.accepted()
        began = time.monotonic()
        worst = 0.0
        for t in client.telemetry(timeout=1.0):
            elapsed = time.monotonic() - began
            if elapsed > 5.0:
                break
            if elapsed > 3.0:
                worst = max(worst, math.hypot(*t.task_error_list(0)))
        print(f"follow: largest TCP error from 3 s {worst:.3e} m")
        assert 0.0 < worst < 1e-3

        far = [start[0] + 0.15, start[1], start[2]]
        with pytest.raises(KnotsRefused) as e:
            client.follow(0, [0.0, 0.5], [far, far], timeout=5.0)
        assert (e.value.first, e.value.last, e.value.knot) == (0, 1, 0)
        assert e.value.cause.path_rejection is PathRejection.STARTS_AWAY, e.value


def test_a_device_streams_samples_that_the_tcp_tracks_and_rests_on_the_last(
    tmp_path: pathlib.Path,
) -> None:
    """Client.stream_samples (docs/tracking.md, "Samples"): a device's samples
    at 100 Hz with their velocity and acceleration, each sent 50 ms ahead of
    the path; the TCP follows within 1 mm, and when the device stops sending
    the arm comes to rest on its last sample. A sample out of reach is
    refused naming it."""
    from hcc import KnotsRefused

    period, lead, sampled = 0.01, 0.05, 3.0
    with (
        sim_pair(SCENARIO, tmp_path) as (ns, prefix, ctl, plant),
        Client(ns, file_prefix=prefix) as client,
    ):
        client.wait_until_converged(0, 1e-3, timeout=30.0)
        t = client.latest_telemetry()
        assert t is not None
        start = t.goal_list(0)
        stream = client.stream_samples(0, timeout=5.0)
        n = int(round(sampled / period)) + 1
        worst = 0.0
        began = time.monotonic()
        for k in range(n):
            tk = k * period
            wait = began + tk - lead - time.monotonic()
            if wait > 0:
                time.sleep(wait)
            stream.send(tk, *circle_sample(start, tk))
            if k == 1:
                # The path begins with the first two samples.
                began = time.monotonic()
            latest = client.latest_telemetry()
            if latest is not None and 1.0 < time.monotonic() - began < sampled - 0.1:
                worst = max(worst, math.hypot(*latest.task_error_list(0)))
        stream.check()
        assert stream.sent == n
        time.sleep(1.5)
        last, _, _ = circle_sample(start, (n - 1) * period)
        t = client.latest_telemetry()
        assert t is not None
        rest = math.dist(t.goal_list(0)[:3], last)
        settled = math.hypot(*t.task_error_list(0))
        print(
            f"samples: largest TCP error from 1 s {worst:.3e} m; the goal {rest:.1e} m from the "
            f"last sample, the TCP {settled:.1e} m from it"
        )
        assert 0.0 < worst < 1e-3
        assert rest < 1e-9 and settled < 1e-3

        # A new stream whose second sample is out of reach: the two begin the
        # path together, refused naming the second.
        here = t.goal_list(0)[:3]
        bad = client.stream_samples(0, timeout=5.0)
        bad.send(0.0, here, [0.0] * 3, [0.0] * 3)
        with pytest.raises(KnotsRefused) as e:
            bad.send(0.05, [3.0, 0.0, 0.3], [0.0] * 3, [0.0] * 3)
        assert e.value.knot == 1, e.value
        assert e.value.rejection is SetpointRejection.OUTSIDE_WORKSPACE, e.value
