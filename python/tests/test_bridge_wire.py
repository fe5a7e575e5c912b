"""hcc bridge on the wire, read as a ROS 2 node on rmw_zenoh would read it.

A Zenoh router (its own process, a loopback port of this test) and the
bridge (a peer of it) beside hcc-controller + hcc-sim (the Panda, real
time); this test is a second Zenoh session that subscribes to ``0/**`` and
asks for the liveliness tokens of domain 0. It decodes every sample with
``rosbags`` (an independent pure-Python CDR and RIHS01 implementation, with
ROS 2 Jazzy's message definitions and this repository's
``ros/hcc_msgs/msg/*.msg``) and compares the values with what the
iceoryx2 side published, read at the same time through ``hcc.Client``:
equal to the bit, except the decimation to the bridge's rate.
"""

from __future__ import annotations

import math
import pathlib
import statistics
import threading
import time
from typing import Any

import numpy as np
import zenoh
from rosbags.typesys import Stores, get_types_from_msg, get_typestore

from hcc import Client
from hcc.remote import read_attachment, session_config, unique_ros_names

from bridge_procs import bridge, router, wait_for, zenoh_config
from conftest import ROOT
from procs import sim_pair

SCENARIO = ROOT / "config" / "panda-pose-posture.toml"
MSG_DIR = ROOT / "ros" / "hcc_msgs" / "msg"
PANDA_JOINTS = [f"panda_joint{i}" for i in range(1, 8)]


def typestore() -> Any:
    """ROS 2 Jazzy's types plus hcc_msgs from the shipped .msg files."""
    ts = get_typestore(Stores.ROS2_JAZZY)
    types: dict[str, Any] = {}
    for name in ("Level", "SetpointAnswer", "RemoteAnswer", "Telemetry"):
        types.update(get_types_from_msg((MSG_DIR / f"{name}.msg").read_text(), f"hcc_msgs/msg/{name}"))
    ts.register(types)
    return ts


def dds(type_name: str) -> str:
    pkg, _, ty = type_name.rpartition("/")
    return f"{pkg.replace('/', '::')}::dds_::{ty}_"


def bits(values: Any) -> bytes:
    """The IEEE-754 bytes of a float sequence (numpy array or list)."""
    return np.asarray(values, dtype="<f8").tobytes()


class Collector:
    """Every sample of the bridge's topics, as (key, payload, attachment)."""

    def __init__(self) -> None:
        self.samples: list[tuple[str, bytes, bytes | None]] = []
        self.lock = threading.Lock()

    def __call__(self, s: zenoh.Sample) -> None:
        att = s.attachment.to_bytes() if s.attachment is not None else None
        with self.lock:
            self.samples.append((str(s.key_expr), s.payload.to_bytes(), att))

    def by_key(self) -> dict[str, list[tuple[bytes, bytes | None]]]:
        out: dict[str, list[tuple[bytes, bytes | None]]] = {}
        with self.lock:
            for k, p, a in self.samples:
                out.setdefault(k, []).append((p, a))
        return out


def collect_iceoryx(client: Client, seconds: float) -> tuple[dict[int, Any], dict[int, Any]]:
    """Joint states and telemetry by sequence number, read for ``seconds``."""
    states: dict[int, Any] = {}
    telemetry: dict[int, Any] = {}
    end = time.monotonic() + seconds
    from hcc import ipc
    from hcc.msgs import JointState, Telemetry
    while time.monotonic() < end:
        for s in ipc.receive_all(client._states, JointState):
            states[s.header.seq] = s
        for t in ipc.receive_all(client._telemetry, Telemetry):
            telemetry[t.header.seq] = t
        time.sleep(0.002)
    return states, telemetry


def check_joint_states(ts: Any, samples: list[tuple[bytes, bytes | None]], states: dict[int, Any]) -> None:
    """Every bridged state equals an iceoryx2 state to the bit; its stamp is
    the state's monotonic stamp plus one constant offset; the decimation
    keeps every tenth state (1 kHz → 100 Hz)."""
    # Several states share a position while the arm rests (before the first
    # command, with different efforts): every state of a position is a candidate.
    by_q: dict[bytes, list[Any]] = {}
    for s in states.values():
        by_q.setdefault(bits(s.q_list()), []).append(s)
    offsets, seqs = set(), []
    for payload, _ in samples:
        msg = ts.deserialize_cdr(payload, "sensor_msgs/msg/JointState")
        assert list(msg.name) == PANDA_JOINTS
        assert msg.header.frame_id == ""
        candidates = by_q.get(bits(msg.position), [])
        if not candidates:
            continue  # published before or after the iceoryx2 window
        same = [
            s for s in candidates
            if bits(msg.velocity) == bits(s.qd_list()) and bits(msg.effort) == bits(s.tau_measured_list())
        ]
        assert same, f"position of state {candidates[0].header.seq} bridged with another velocity or effort"
        if len(same) > 1:
            continue  # alike to the bit: no single stamp to compare
        s = same[0]
        stamp = msg.header.stamp.sec * 1_000_000_000 + msg.header.stamp.nanosec
        offsets.add(stamp - s.header.stamp_ns)
        seqs.append(s.header.seq)
    assert len(seqs) >= 50, f"only {len(seqs)} bridged states matched the iceoryx2 window"
    assert len(offsets) == 1, f"the monotonic → ROS time offset changed: {sorted(offsets)[:5]}"
    gaps = [b - a for a, b in zip(seqs, seqs[1:])]
    assert statistics.median(gaps) == 10, gaps[:20]
    wall = time.time_ns() - time.monotonic_ns()
    assert abs(offsets.pop() - wall) < 1_000_000_000, "ROS stamps are CLOCK_REALTIME"


def check_telemetry(ts: Any, samples: list[tuple[bytes, bytes | None]], telemetry: dict[int, Any]) -> None:
    """Every bridged telemetry sample equals the controller's of the same cycle."""
    matched = 0
    for payload, _ in samples:
        m = ts.deserialize_cdr(payload, "hcc_msgs/msg/Telemetry")
        t = telemetry.get(m.cycle)
        if t is None:
            continue
        matched += 1
        assert (m.state_seq, m.command_seq, m.stamp_monotonic_ns, m.mode, m.flags) == (
            t.state_seq, t.command_seq, t.header.stamp_ns, t.mode, t.flags)
        assert bits(m.tau) == bits(t.tau_list())
        assert bits([m.p_mu]) == bits([t.p_mu])
        assert bits(m.tau_ext) == bits(t.tau_ext_list())
        assert bits([m.h]) == bits([t.h])
        assert bits(m.potential) == bits(t.potential_list())
        assert bits(m.tank) == bits(t.tank_list())
        assert bits(m.tank_valve) == bits(t.tank_valve_list())
        assert bits([m.load_mass, *m.load_com, m.load_progress]) == bits(
            [t.load_mass, *t.load_com_list(), t.load_progress])
        assert [lv.name for lv in m.levels] == ["TCP position", "TCP orientation", "posture"]
        for i, lv in enumerate(m.levels):
            assert lv.dim == t.task_dims[i]
            assert bits(lv.error) == bits(t.task_error_list(i))
            assert bits(lv.goal) == bits(t.goal_list(i))
            assert bits(lv.stiffness_diag) == bits(t.stiffness_diag_list(i))
            assert bits(lv.damping_diag) == bits(t.damping_diag_list(i))
            assert bits([lv.storage, lv.min_singular_value, lv.transition_progress]) == bits(
                [t.storage[i], t.min_singular_value[i], t.transition_progress[i]])
            assert lv.singular == t.is_singular(i)
        counters = dict(zip(m.counter_names, m.counter_values.tolist()))
        for name, _ in t.counters._fields_:
            assert counters[name] == getattr(t.counters, name), name
        assert counters["bridge_published"] > 0
        assert m.bridge_client_id == 0 and len(m.remote_answers) == 0, "read-only bridge"
    assert matched >= 50, f"only {matched} bridged telemetry samples matched"


def check_attachments(samples: list[tuple[bytes, bytes | None]]) -> bytes:
    """rmw_zenoh attachments: +1 per sample, one GID per publisher."""
    seqs, gids = [], set()
    for _, att in samples:
        assert att is not None
        seq, stamp, gid = read_attachment(att)
        seqs.append(seq)
        gids.add(gid)
        assert abs(stamp - time.time_ns()) < 60_000_000_000
    assert len(gids) == 1
    assert seqs == list(range(seqs[0], seqs[0] + len(seqs))), "sequence numbers +1 per sample"
    return gids.pop()


def check_tokens(session: zenoh.Session, ns: str, ts: Any) -> None:
    """The node, its publishers and its goal and path subscriptions in the ROS graph."""
    expected = 1 + 3 + 3 + 3 + 1
    keys: list[str] = []
    mine: list[list[str]] = []
    # Asked again while the reply is short: on a loaded host the router may
    # not have every token yet when the first query reaches it.
    for _ in range(5):
        keys = [str(r.ok.key_expr)
                for r in session.liveliness().get("@ros2_lv/0/**", timeout=5.0)
                if r.ok is not None]
        mine = [k.split("/") for k in keys if k.split("/")[7:9] == [f"%{ns}", "hcc_bridge"]]
        if len(mine) >= expected:
            break
        time.sleep(0.5)
    assert len(mine) == expected, keys
    assert sum(p[5] == "NN" and len(p) == 9 and p[6] == "%" for p in mine) == 1
    topics = {(p[5], p[9], p[10], p[11], p[12]) for p in mine if len(p) == 13}
    goal = unique_ros_names(["TCP position", "TCP orientation", "posture"])
    assert goal == ["tcp_position", "tcp_orientation", "posture"]
    want = {
        ("MP", "joint_states", "sensor_msgs/msg/JointState"),
        ("MP", "torque_command", "sensor_msgs/msg/JointState"),
        ("MP", "telemetry", "hcc_msgs/msg/Telemetry"),
        ("MS", "tcp_position/goal", "geometry_msgs/msg/PointStamped"),
        ("MS", "tcp_orientation/goal", "geometry_msgs/msg/QuaternionStamped"),
        ("MS", "posture/goal", "std_msgs/msg/Float64MultiArray"),
        ("MS", "tcp_position/path", "trajectory_msgs/msg/MultiDOFJointTrajectory"),
        ("MS", "tcp_orientation/path", "trajectory_msgs/msg/MultiDOFJointTrajectory"),
        ("MS", "posture/path", "trajectory_msgs/msg/JointTrajectory"),
        ("MS", "load", "geometry_msgs/msg/InertiaStamped"),
    }
    assert topics == {(kind, f"%{ns}%{name}".replace("/", "%"), dds(ty), ts.hash_rihs01(ty), "::,10:,:,:,,")
                      for kind, name, ty in want}
    zids = {p[2] for p in mine}
    assert len(zids) == 1 and all(p[3] == "0" for p in mine)
    assert len({p[4] for p in mine}) == len(mine), "one entity id each"


def test_bridge_speaks_rmw_zenoh(tmp_path: pathlib.Path) -> None:
    ts = typestore()
    assert ts.hash_rihs01("sensor_msgs/msg/JointState") == (
        "RIHS01_a13ee3a330e346c9d87b5aa18d24e11690752bd33a0350f11c5882bc9179260e")
    collector = Collector()
    with (
        router(tmp_path) as port,
        sim_pair(SCENARIO, tmp_path) as (ns, prefix, ctl, plant),
        bridge(ns, prefix, SCENARIO, zenoh_config(tmp_path, port), tmp_path / "bridge.log", "--rate", "100"),
        Client(ns, file_prefix=prefix) as client,
    ):
        session = zenoh.open(session_config([f"tcp/127.0.0.1:{port}"]))
        try:
            sub = session.declare_subscriber("0/**", collector)
            wait_for(lambda: len(collector.samples) > 30, 30.0, "the bridge's samples")
            states, telemetry = collect_iceoryx(client, 2.0)
            time.sleep(0.2)
            check_tokens(session, ns, ts)
            sub.undeclare()
        finally:
            session.close()
        assert ctl.poll() is None and plant.poll() is None
    keys = collector.by_key()
    expect = {
        f"0/{ns}/joint_states/sensor_msgs::msg::dds_::JointState_/{ts.hash_rihs01('sensor_msgs/msg/JointState')}",
        f"0/{ns}/torque_command/sensor_msgs::msg::dds_::JointState_/{ts.hash_rihs01('sensor_msgs/msg/JointState')}",
        f"0/{ns}/telemetry/hcc_msgs::msg::dds_::Telemetry_/{ts.hash_rihs01('hcc_msgs/msg/Telemetry')}",
    }
    assert set(keys) == expect, sorted(keys)
    state_key, command_key, telemetry_key = (
        next(k for k in expect if f"/{name}/" in k) for name in ("joint_states", "torque_command", "telemetry"))
    gids = {check_attachments(keys[k]) for k in expect}
    assert len(gids) == 3, "one GID per publisher"
    check_joint_states(ts, keys[state_key], states)
    check_telemetry(ts, keys[telemetry_key], telemetry)
    for payload, _ in keys[command_key]:
        m = ts.deserialize_cdr(payload, "sensor_msgs/msg/JointState")
        assert list(m.name) == PANDA_JOINTS and len(m.position) == 0 and len(m.effort) == 7
    for payload, _ in keys[state_key][:1]:
        assert payload[:4] == b"\x00\x01\x00\x00", "CDR little endian"
    n = sum(len(v) for v in keys.values())
    print(f"bridge wire: {n} samples on {len(keys)} keys, decoded by rosbags, equal to iceoryx2's")
    summary = (tmp_path / "bridge.log").read_text()
    assert '"bridge_published"' in summary, summary


def test_remote_goal_messages_are_ros_messages() -> None:
    """hcc.remote's goal messages decode with rosbags as ROS 2 would."""
    from hcc import remote

    ts = typestore()
    stamp = 1_700_000_000_123_456_789
    m = ts.deserialize_cdr(remote.encode_goal(remote.POSE_STAMPED, [0.5, 0.1, 0.4, 3.0, -0.2, 1.0], stamp),
                           "geometry_msgs/msg/PoseStamped")
    assert (m.header.stamp.sec, m.header.stamp.nanosec) == (1_700_000_000, 123_456_789)
    assert (m.pose.position.x, m.pose.position.y, m.pose.position.z) == (0.5, 0.1, 0.4)
    q = (m.pose.orientation.x, m.pose.orientation.y, m.pose.orientation.z, m.pose.orientation.w)
    assert q == remote.rpy_to_quaternion(3.0, -0.2, 1.0)
    assert abs(sum(x * x for x in q) - 1.0) < 1e-15
    m = ts.deserialize_cdr(remote.encode_goal(remote.POINT_STAMPED, [1.0, 2.0, 3.0]), "geometry_msgs/msg/PointStamped")
    assert (m.point.x, m.point.y, m.point.z) == (1.0, 2.0, 3.0)
    m = ts.deserialize_cdr(remote.encode_goal(remote.QUATERNION_STAMPED, [0.0, 0.0, 0.5]),
                           "geometry_msgs/msg/QuaternionStamped")
    assert m.quaternion.z == math.sin(0.25) and m.quaternion.w == math.cos(0.25)
    m = ts.deserialize_cdr(remote.encode_goal(remote.FLOAT64_MULTI_ARRAY, [0.1, -0.2, 0.3]),
                           "std_msgs/msg/Float64MultiArray")
    assert m.data.tolist() == [0.1, -0.2, 0.3] and m.layout.data_offset == 0
    # Types and hashes of hcc.remote are ROS 2's.
    for ty in (*remote.GOAL_TYPES, *remote.PATH_TYPES, remote.INERTIA_STAMPED, remote.JOINT_STATE,
               remote.TELEMETRY):
        assert ts.hash_rihs01(ty[0]) == ty[1], ty[0]
    # The path messages decode with rosbags too.
    m = ts.deserialize_cdr(remote.encode_trajectory(remote.JOINT_TRAJECTORY, [0.0, 1.5], [[0.1, 0.2], [0.3, 0.4]],
                                                    ["a", "b"], stamp), "trajectory_msgs/msg/JointTrajectory")
    assert m.joint_names == ["a", "b"] and m.points[1].positions.tolist() == [0.3, 0.4]
    assert (m.points[1].time_from_start.sec, m.points[1].time_from_start.nanosec) == (1, 500_000_000)
    m = ts.deserialize_cdr(remote.encode_trajectory(remote.MULTI_DOF_JOINT_TRAJECTORY, [0.25],
                                                    [[0.5, 0.1, 0.3, 0.0, 0.0, 0.0, 1.0]]),
                           "trajectory_msgs/msg/MultiDOFJointTrajectory")
    tf = m.points[0].transforms[0]
    assert (tf.translation.x, tf.rotation.w, m.points[0].time_from_start.nanosec) == (0.5, 1.0, 250_000_000)
    att = remote.attachment(5, stamp, bytes(range(16)))
    assert remote.read_attachment(att) == (5, stamp, bytes(range(16))) and len(att) == 33
    # The load message decodes with rosbags too, field for field.
    m = ts.deserialize_cdr(remote.encode_load(1.5, (0.01, -0.02, 0.1), (4e-3, 1e-4, 2e-4, 5e-3, 3e-4, 6e-3), stamp,
                                              "tcp"), "geometry_msgs/msg/InertiaStamped")
    i = m.inertia
    assert m.header.frame_id == "tcp" and (i.m, i.com.x, i.com.y, i.com.z) == (1.5, 0.01, -0.02, 0.1)
    assert (i.ixx, i.ixy, i.ixz, i.iyy, i.iyz, i.izz) == (4e-3, 1e-4, 2e-4, 5e-3, 3e-4, 6e-3)
