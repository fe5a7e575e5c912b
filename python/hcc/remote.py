"""Watching and commanding an hcc controller from another host, over Zenoh.

``hcc bridge`` (a process beside the controller) publishes a namespace's
joint states, torque commands and telemetry on Zenoh in the wire format of
ROS 2's ``rmw_zenoh`` and takes goals and paths on topics per level and the
load in the hand on one topic (:meth:`Client.follow`, :meth:`Client.set_load`).
:class:`Client` here reads those topics and sends goals with the surface of
:class:`hcc.Client` (which needs the controller's shared memory, i.e. the
same host): :meth:`Client.telemetry`, :meth:`Client.joint_states`,
:meth:`Client.latest_telemetry`, :meth:`Client.set_goal`,
:meth:`Client.wait_until_accepted`, :meth:`Client.wait_until_converged`.
Levels are 0-based; goals are in the task's coordinates, as in the
scenario TOML (x, y, z, roll, pitch, yaw for a pose level).

Example (a router on the robot's host at 192.0.2.10)::

    from hcc.remote import Client
    with Client("panda", connect=["tcp/192.0.2.10:7447"]) as arm:
        seq = arm.set_goal(0, [0.5, 0.1, 0.4, 3.14159, 0.0, 0.0])
        answer = arm.wait_until_accepted(seq, timeout=2.0)
        arm.wait_until_converged(0, tolerance=1e-3, timeout=10.0)

The bridge forwards goals only when started with ``--allow-setpoints``;
otherwise :meth:`Client.wait_until_accepted` raises :class:`GoalRefused`
(code 100). Everything here is plain Python on ``eclipse-zenoh``: its own
CDR reader and writer for the few message types involved.
"""

from __future__ import annotations

import collections
import dataclasses
import math
import os
import struct
import threading
import time
from typing import Any, Callable, Iterator, Sequence

import zenoh

from .msgs import TELEMETRY_FLAG_CONTACT, TELEMETRY_FLAG_CONTACT_HOLD, TELEMETRY_FLAG_PEER_LOST

#: Polling interval of the waits, s.
POLL_S: float = 0.001

JOINT_STATE = ("sensor_msgs/msg/JointState",
               "RIHS01_a13ee3a330e346c9d87b5aa18d24e11690752bd33a0350f11c5882bc9179260e")
POSE_STAMPED = ("geometry_msgs/msg/PoseStamped",
                "RIHS01_10f3786d7d40fd2b54367835614bff85d4ad3b5dab62bf8bca0cc232d73b4cd8")
POINT_STAMPED = ("geometry_msgs/msg/PointStamped",
                 "RIHS01_4c0296af86e01e562e9e0405d138a01537247580076c58ea38d7923ac1045897")
QUATERNION_STAMPED = ("geometry_msgs/msg/QuaternionStamped",
                      "RIHS01_381add86c6c3160644d228ca342182c7fd6c7fab11c7a85ad817a9cc22dbac6e")
FLOAT64_MULTI_ARRAY = ("std_msgs/msg/Float64MultiArray",
                       "RIHS01_1025ddc6b9552d191f89ef1a8d2f60f3d373e28b283d8891ddcc974e8c55397f")
TELEMETRY = ("hcc_msgs/msg/Telemetry",
             "RIHS01_715655cde20dd09c5cfa090561ba9bf36da8a823b27019ce59c04d3a2f3bba40")
GOAL_TYPES = (POSE_STAMPED, POINT_STAMPED, QUATERNION_STAMPED, FLOAT64_MULTI_ARRAY)
JOINT_TRAJECTORY = ("trajectory_msgs/msg/JointTrajectory",
                    "RIHS01_179b33eba59d676f6d967ac71fe35e7ca2f64b2f3928f4a018cec115e213796e")
MULTI_DOF_JOINT_TRAJECTORY = ("trajectory_msgs/msg/MultiDOFJointTrajectory",
                              "RIHS01_3a18fd095292a65cfde8833c72985a30af981f3ec44494655c6267262b443a4a")
#: The types of the levels' path topics (joint levels; Cartesian levels).
PATH_TYPES = (JOINT_TRAJECTORY, MULTI_DOF_JOINT_TRAJECTORY)
#: The load topic's type (``/<ns>/load``, docs/load.md).
INERTIA_STAMPED = ("geometry_msgs/msg/InertiaStamped",
                   "RIHS01_766be45976252babf7f9d8ac4ae7c912a7ceccf71035622529f27518b695aa09")
#: The level of a load's :class:`RemoteAnswer` (no level's index).
LOAD_LEVEL = 0xFFFF_FFFF

#: Codes of the bridge's own refusals (RemoteAnswer.code).
REFUSED_READ_ONLY = 100
REFUSED_RATE = 101
REFUSED_BAD_MESSAGE = 102
REFUSED_UNREACHABLE = 103

CDR_LE = b"\x00\x01\x00\x00"
NODE_NAME = "hcc_remote"
QOS = "::,10:,:,:,,"


# --- Names (as hcc bridge and rmw_zenoh build them) --------------------------

def ros_name(raw: str, prefix: str) -> str:
    """``raw`` made a ROS name token: lower case, other characters one ``_``."""
    out = ""
    for c in raw:
        if c.isascii() and c.isalnum():
            out += c.lower()
        elif out and not out.endswith("_"):
            out += "_"
    out = out.rstrip("_")
    if not out or out[0].isdigit():
        out = prefix + out
    return out


def unique_ros_names(raw: Sequence[str], prefix: str = "level") -> list[str]:
    """:func:`ros_name` of every level name, unique by ``_2``, ``_3``, … in order."""
    out: list[str] = []
    for i, r in enumerate(raw):
        base = ros_name(r, f"{prefix}{i + 1}_")
        name, k = base, 2
        while name in out:
            name, k = f"{base}_{k}", k + 1
        out.append(name)
    return out


def dds_name(type_name: str) -> str:
    """``pkg/msg/T`` → ``pkg::msg::dds_::T_``."""
    pkg, _, ty = type_name.rpartition("/")
    return f"{pkg.replace('/', '::')}::dds_::{ty}_"


def topic_key(domain: int, topic: str, ros_type: tuple[str, str]) -> str:
    """The data key expression of ``topic`` (absolute) in ``domain``."""
    return f"{domain}/{topic.strip('/')}/{dds_name(ros_type[0])}/{ros_type[1]}"


# --- CDR (plain, XCDR1) ------------------------------------------------------

class CdrReader:
    """Reads a plain-CDR message field by field (little endian only)."""

    def __init__(self, data: bytes) -> None:
        if data[:4] != CDR_LE:
            raise ValueError(f"not little-endian plain CDR: header {data[:4]!r}")
        self.data, self.pos = data, 4

    def _take(self, fmt: str, size: int) -> Any:
        self.pos += (-(self.pos - 4)) % size
        (v,) = struct.unpack_from("<" + fmt, self.data, self.pos)
        self.pos += size
        return v

    def u8(self) -> int:
        return self._take("B", 1)

    def i32(self) -> int:
        return self._take("i", 4)

    def u32(self) -> int:
        return self._take("I", 4)

    def i64(self) -> int:
        return self._take("q", 8)

    def u64(self) -> int:
        return self._take("Q", 8)

    def f64(self) -> float:
        return self._take("d", 8)

    def string(self) -> str:
        n = self.u32()
        raw = self.data[self.pos:self.pos + n]
        self.pos += n
        return raw[:-1].decode() if n else ""

    def seq(self, item: Callable[[], Any]) -> list[Any]:
        return [item() for _ in range(self.u32())]


class CdrWriter:
    """Writes a plain-CDR little-endian message."""

    def __init__(self) -> None:
        self.buf = bytearray(CDR_LE)

    def _put(self, fmt: str, size: int, v: Any) -> "CdrWriter":
        self.buf += b"\x00" * ((-(len(self.buf) - 4)) % size)
        self.buf += struct.pack("<" + fmt, v)
        return self

    def i32(self, v: int) -> "CdrWriter":
        return self._put("i", 4, v)

    def u32(self, v: int) -> "CdrWriter":
        return self._put("I", 4, v)

    def f64(self, v: float) -> "CdrWriter":
        return self._put("d", 8, v)

    def string(self, s: str) -> "CdrWriter":
        raw = s.encode() + b"\x00"
        self.u32(len(raw))
        self.buf += raw
        return self

    def header(self, stamp_ns: int, frame_id: str = "") -> "CdrWriter":
        return self.i32(stamp_ns // 1_000_000_000).u32(stamp_ns % 1_000_000_000).string(frame_id)


def rpy_to_quaternion(roll: float, pitch: float, yaw: float) -> tuple[float, float, float, float]:
    """(x, y, z, w) of R = Rz(yaw) Ry(pitch) Rx(roll), the controller's convention."""
    cr, sr = math.cos(roll / 2), math.sin(roll / 2)
    cp, sp = math.cos(pitch / 2), math.sin(pitch / 2)
    cy, sy = math.cos(yaw / 2), math.sin(yaw / 2)
    return (sr * cp * cy - cr * sp * sy, cr * sp * cy + sr * cp * sy,
            cr * cp * sy - sr * sp * cy, cr * cp * cy + sr * sp * sy)


def encode_goal(ros_type: tuple[str, str], values: Sequence[float], stamp_ns: int = 0) -> bytes:
    """A goal message of ``ros_type`` from task coordinates ``values``:
    pose x, y, z, roll, pitch, yaw; point x, y, z; orientation roll,
    pitch, yaw; array: the values."""
    w = CdrWriter()
    v = [float(x) for x in values]
    if ros_type == FLOAT64_MULTI_ARRAY:
        w.u32(0).u32(0).u32(len(v))  # no layout dims, data_offset 0, data
        for x in v:
            w.f64(x)
        return bytes(w.buf)
    w.header(stamp_ns)
    if ros_type == POSE_STAMPED:
        if len(v) != 6:
            raise ValueError(f"a pose goal is x, y, z, roll, pitch, yaw, not {len(v)} values")
        coords = [*v[:3], *rpy_to_quaternion(*v[3:])]
    elif ros_type == POINT_STAMPED:
        if len(v) != 3:
            raise ValueError("a position goal needs x, y, z (the level's axes are taken)")
        coords = v
    else:
        if len(v) != 3:
            raise ValueError(f"an orientation goal is roll, pitch, yaw, not {len(v)} values")
        coords = list(rpy_to_quaternion(*v))
    for x in coords:
        w.f64(x)
    return bytes(w.buf)


def encode_trajectory(
    ros_type: tuple[str, str],
    times: Sequence[float],
    points: Sequence[Sequence[float]],
    joint_names: Sequence[str] = (),
    stamp_ns: int = 0,
    velocities: Sequence[Sequence[float]] | None = None,
    accelerations: Sequence[Sequence[float]] | None = None,
) -> bytes:
    """A path message of ``ros_type`` (docs/tracking.md): a
    ``JointTrajectory`` of positions, or a ``MultiDOFJointTrajectory`` of one
    transform per point, each point x, y, z, qx, qy, qz, qw; ``times`` are the
    points' ``time_from_start`` (s). ``velocities`` and ``accelerations``,
    one per point when given: a joint trajectory's values, a multi-DOF
    point's twist (linear x y z, angular x y z)."""
    if (velocities is None) != (accelerations is None):
        raise ValueError("give both velocities and accelerations, or neither")
    w = CdrWriter().header(stamp_ns)
    w.u32(len(joint_names))
    for n in joint_names:
        w.string(n)
    w.u32(len(points))
    for k, (t, p) in enumerate(zip(times, points)):
        v = [float(x) for x in p]
        rates = [] if velocities is None or accelerations is None else [
            [float(x) for x in velocities[k]],
            [float(x) for x in accelerations[k]],
        ]
        if ros_type == JOINT_TRAJECTORY:
            w.u32(len(v))
            for x in v:
                w.f64(x)
            for r in rates or [[], []]:  # velocities, accelerations
                w.u32(len(r))
                for x in r:
                    w.f64(x)
            w.u32(0)  # effort
        else:
            if len(v) != 7:
                raise ValueError(f"a multi-DOF point is x, y, z, qx, qy, qz, qw, not {len(v)} values")
            w.u32(1)
            for x in v:
                w.f64(x)
            for r in rates or [[], []]:  # one twist each, or none
                if r and len(r) != 6:
                    raise ValueError(f"a twist is linear x y z, angular x y z, not {len(r)} values")
                w.u32(1 if r else 0)
                for x in r:
                    w.f64(x)
        sec = math.floor(t)
        w.i32(int(sec)).u32(int(round((t - sec) * 1e9)) % 1_000_000_000)
    return bytes(w.buf)


def encode_load(
    mass: float,
    com: Sequence[float] = (0.0, 0.0, 0.0),
    inertia: Sequence[float] | None = None,
    stamp_ns: int = 0,
    frame_id: str = "",
) -> bytes:
    """A ``geometry_msgs/msg/InertiaStamped`` telling the load in the hand
    (docs/load.md): ``mass`` kg, ``com`` in the tip frame (m), ``inertia``
    about it (kg·m², ixx ixy ixz iyy iyz izz; None: a point mass);
    ``frame_id`` empty or the robot's tip link."""
    i = [0.0] * 6 if inertia is None else [float(x) for x in inertia]
    if len(com) != 3 or len(i) != 6:
        raise ValueError("a load is a mass, a centre of mass x y z and ixx ixy ixz iyy iyz izz")
    w = CdrWriter().header(stamp_ns, frame_id)
    for x in (float(mass), *(float(c) for c in com), *i):
        w.f64(x)
    return bytes(w.buf)


def attachment(seq: int, stamp_ns: int, gid: bytes) -> bytes:
    """rmw_zenoh's attachment: int64 sequence number, int64 source
    timestamp, the GID as a LEB128 length (16) and 16 bytes."""
    return struct.pack("<qqB", seq, stamp_ns, len(gid)) + gid


def read_attachment(raw: bytes) -> tuple[int, int, bytes]:
    """(sequence number, source timestamp ns, GID) of an rmw_zenoh attachment."""
    if len(raw) != 33 or raw[16] != 16:
        raise ValueError(f"not an rmw_zenoh attachment ({len(raw)} bytes)")
    seq, stamp = struct.unpack_from("<qq", raw)
    return seq, stamp, bytes(raw[17:])


# --- Messages -----------------------------------------------------------------

@dataclasses.dataclass
class RemoteJointState:
    """A ``sensor_msgs/msg/JointState`` from the bridge (joint states or,
    effort only, torque commands)."""

    stamp_ns: int
    name: list[str]
    position: list[float]
    velocity: list[float]
    effort: list[float]

    @classmethod
    def decode(cls, data: bytes) -> "RemoteJointState":
        r = CdrReader(data)
        stamp = r.i32() * 1_000_000_000 + r.u32()
        r.string()
        return cls(stamp, r.seq(r.string), r.seq(r.f64), r.seq(r.f64), r.seq(r.f64))

    def q_list(self) -> list[float]:
        return list(self.position)

    def qd_list(self) -> list[float]:
        return list(self.velocity)

    def tau_measured_list(self) -> list[float]:
        return list(self.effort)


@dataclasses.dataclass
class LevelTelemetry:
    """One level of an ``hcc_msgs/msg/Telemetry``."""

    name: str
    dim: int
    error: list[float]
    goal: list[float]
    stiffness_diag: list[float]
    damping_diag: list[float]
    storage: float
    min_singular_value: float
    transition_progress: float
    singular: bool


@dataclasses.dataclass
class Answer:
    """A controller answer (``hcc_msgs/msg/SetpointAnswer``)."""

    client_id: int
    seq: int
    answered: int
    code: int
    reason: str
    level: int
    duration_s: float
    rejected: int
    late: int

    def accepted(self) -> bool:
        return self.code == 0


@dataclasses.dataclass
class RemoteAnswer:
    """The answer to one remote goal (``hcc_msgs/msg/RemoteAnswer``)."""

    source_gid: bytes
    source_seq: int
    level: int
    code: int
    reason: str
    duration_s: float

    def accepted(self) -> bool:
        return self.code == 0


@dataclasses.dataclass
class RemoteTelemetry:
    """An ``hcc_msgs/msg/Telemetry`` sample (methods as :class:`hcc.Telemetry`'s)."""

    stamp_ns: int
    cycle: int
    state_seq: int
    command_seq: int
    stamp_monotonic_ns: int
    mode: int
    flags: int
    tau: list[float]
    p_mu: float
    level_list: list[LevelTelemetry]
    counters: dict[str, int]
    answers: list[Answer]
    bridge_client_id: int
    remote_answers: list[RemoteAnswer]
    #: The controller's estimate of the external joint torque (N·m per joint).
    tau_ext: list[float]
    #: The storage H of the arm and the controller (J).
    h: float
    #: Per level: its potential as H counts it, its energy tank (J) and the
    #: tank's valve in [0, 1] (1: the paper's law).
    potential: list[float]
    tank: list[float]
    tank_valve: list[float]
    #: The load the controller's model carries (docs/load.md): mass (kg),
    #: centre of mass in the tip frame (m), the announced load's ramp in
    #: [0, 1] (1: none runs).
    load_mass: float
    load_com: list[float]
    load_progress: float

    @classmethod
    def decode(cls, data: bytes) -> "RemoteTelemetry":
        r = CdrReader(data)
        stamp = r.i32() * 1_000_000_000 + r.u32()
        r.string()
        head = [r.u64(), r.u64(), r.u64(), r.u64(), r.u32(), r.u32()]
        tau, p_mu = r.seq(r.f64), r.f64()
        levels = r.seq(lambda: LevelTelemetry(
            r.string(), r.u32(), r.seq(r.f64), r.seq(r.f64), r.seq(r.f64), r.seq(r.f64),
            r.f64(), r.f64(), r.f64(), bool(r.u8())))
        counters = dict(zip(r.seq(r.string), r.seq(r.u64)))
        answers = r.seq(lambda: Answer(r.u64(), r.u64(), r.u64(), r.u32(), r.string(), r.u32(),
                                       r.f64(), r.u32(), r.u32()))
        bridge_id = r.u64()
        remote = r.seq(lambda: RemoteAnswer(bytes(r.u8() for _ in range(16)), r.i64(), r.u32(),
                                            r.u32(), r.string(), r.f64()))
        tau_ext = r.seq(r.f64)
        h = r.f64()
        potential, tank, tank_valve = r.seq(r.f64), r.seq(r.f64), r.seq(r.f64)
        load_mass, load_com, load_progress = r.f64(), [r.f64(), r.f64(), r.f64()], r.f64()
        return cls(stamp, *head, tau, p_mu, levels, counters, answers, bridge_id, remote, tau_ext,
                   h, potential, tank, tank_valve, load_mass, load_com, load_progress)

    def levels(self) -> int:
        return len(self.level_list)

    def task_error_list(self, level: int) -> list[float]:
        return list(self.level_list[level].error)

    def error_norm(self, level: int) -> float:
        return math.sqrt(sum(x * x for x in self.level_list[level].error))

    def goal_list(self, level: int) -> list[float]:
        return list(self.level_list[level].goal)

    def stiffness_diag_list(self, level: int) -> list[float]:
        return list(self.level_list[level].stiffness_diag)

    def damping_diag_list(self, level: int) -> list[float]:
        return list(self.level_list[level].damping_diag)

    def progress(self, level: int) -> float:
        return self.level_list[level].transition_progress

    def tau_list(self) -> list[float]:
        return list(self.tau)

    def is_singular(self, level: int) -> bool:
        return self.level_list[level].singular

    def peer_lost(self) -> bool:
        return bool(self.flags & TELEMETRY_FLAG_PEER_LOST)

    def tau_ext_list(self) -> list[float]:
        return list(self.tau_ext)

    def potential_list(self) -> list[float]:
        return list(self.potential)

    def tank_list(self) -> list[float]:
        return list(self.tank)

    def tank_valve_list(self) -> list[float]:
        return list(self.tank_valve)

    def contact(self) -> bool:
        return bool(self.flags & TELEMETRY_FLAG_CONTACT)

    def contact_hold(self) -> bool:
        return bool(self.flags & TELEMETRY_FLAG_CONTACT_HOLD)

    def answer_for(self, client_id: int) -> Answer | None:
        return next((a for a in self.answers if a.client_id == client_id), None)


class GoalRefused(Exception):
    """A remote goal was refused: by the controller (its rejection code and
    name) or by the bridge (codes 100–103: read-only, rate cap, unreadable
    message, controller unreachable)."""

    def __init__(self, answer: RemoteAnswer) -> None:
        what = ("load" if answer.level == LOAD_LEVEL
                else f"goal for level {answer.level}")
        super().__init__(f"{what} (message {answer.source_seq}) refused: "
                         f"{answer.reason} (code {answer.code})")
        self.answer = answer
        self.code = answer.code


# --- The client ----------------------------------------------------------------

class _Queue:
    """A bounded queue fed by a Zenoh callback (the oldest is dropped when full)."""

    def __init__(self, maxlen: int, decode: Callable[[bytes], Any]) -> None:
        self.items: collections.deque[Any] = collections.deque(maxlen=maxlen)
        self.decode = decode
        self.latest: Any = None
        self.lock = threading.Lock()

    def __call__(self, sample: zenoh.Sample) -> None:
        try:
            msg = self.decode(sample.payload.to_bytes())
        except (ValueError, struct.error, UnicodeDecodeError):
            return
        with self.lock:
            self.items.append(msg)
            self.latest = msg

    def pop(self) -> Any:
        with self.lock:
            return self.items.popleft() if self.items else None


def session_config(connect: Sequence[str] | None = None, config_file: str | None = None) -> zenoh.Config:
    """A Zenoh configuration: the file, or a peer connecting to ``connect``
    (default rmw_zenoh's router ``tcp/localhost:7447``), no multicast scouting."""
    if config_file is not None:
        return zenoh.Config.from_file(config_file)
    conf = zenoh.Config()
    conf.insert_json5("mode", '"peer"')
    conf.insert_json5("connect/endpoints", repr(list(connect or ["tcp/localhost:7447"])).replace("'", '"'))
    conf.insert_json5("listen/endpoints", '["tcp/127.0.0.1:0"]')
    conf.insert_json5("scouting/multicast/enabled", "false")
    return conf


class Client:
    """Joint states, telemetry and goals of the robot in ``namespace``,
    through ``hcc bridge`` over Zenoh.

    ``connect``: Zenoh endpoints (default ``tcp/localhost:7447``, rmw_zenoh's
    router); or ``config_file``: a Zenoh configuration (TLS, user/password).
    ``domain``: the ROS domain id of the bridge. ``buffer``: samples kept per
    stream for the iterators (older ones are dropped). Use as a context
    manager or call :meth:`close`. Goals need a bridge started with
    ``--allow-setpoints``; the goal topics are declared on first use, with
    the level names from telemetry (wait for it first: the methods do).
    """

    def __init__(self, namespace: str, *, connect: Sequence[str] | None = None,
                 config_file: str | None = None, domain: int = 0, buffer: int = 1024) -> None:
        self.namespace = ros_name(namespace, "hcc_")
        self.domain = domain
        self._session = zenoh.open(session_config(connect, config_file))
        self._zid = str(self._session.zid())
        self._telemetry = _Queue(buffer, RemoteTelemetry.decode)
        self._states = _Queue(buffer, RemoteJointState.decode)
        self._commands = _Queue(buffer, RemoteJointState.decode)
        self._entity = 0
        self._tokens = [self._token("NN", None)]
        self._subs = [
            self._subscribe("joint_states", JOINT_STATE, self._states),
            self._subscribe("torque_command", JOINT_STATE, self._commands),
            self._subscribe("telemetry", TELEMETRY, self._telemetry),
        ]
        self._publishers: dict[Any, tuple[Any, bytes, tuple[str, str]]] = {}
        self._sent: dict[int, bytes] = {}
        self._seq = 0

    def __enter__(self) -> "Client":
        return self

    def __exit__(self, *exc: Any) -> None:
        self.close()

    def close(self) -> None:
        """Undeclares everything and closes the session."""
        if self._session is not None:
            self._session.close()
        self._session = None

    def _token(self, kind: str, topic: tuple[str, tuple[str, str]] | None) -> Any:
        key = (f"@ros2_lv/{self.domain}/{self._zid}/0/{self._entity}/{kind}/%/"
               f"%{self.namespace}/{NODE_NAME}")
        self._entity += 1
        if topic is not None:
            name, ty = topic
            key += f"/{name.replace('/', '%')}/{dds_name(ty[0])}/{ty[1]}/{QOS}"
        return self._session.liveliness().declare_token(key)

    def _subscribe(self, name: str, ty: tuple[str, str], queue: _Queue) -> Any:
        topic = f"/{self.namespace}/{name}"
        self._tokens.append(self._token("MS", (topic, ty)))
        return self._session.declare_subscriber(topic_key(self.domain, topic, ty), queue)

    # --- Reading ----------------------------------------------------------------

    def _iterate(self, queue: _Queue, timeout: float | None) -> Iterator[Any]:
        deadline = None if timeout is None else time.monotonic() + timeout
        while True:
            msg = queue.pop()
            if msg is not None:
                if timeout is not None:
                    deadline = time.monotonic() + timeout
                yield msg
            elif deadline is not None and time.monotonic() >= deadline:
                return
            else:
                time.sleep(POLL_S)

    def telemetry(self, timeout: float | None = 1.0) -> Iterator[RemoteTelemetry]:
        """Every telemetry sample in order; ends after ``timeout`` s without one."""
        return self._iterate(self._telemetry, timeout)

    def joint_states(self, timeout: float | None = 1.0) -> Iterator[RemoteJointState]:
        """Every joint state in order; ends after ``timeout`` s without one."""
        return self._iterate(self._states, timeout)

    def torque_commands(self, timeout: float | None = 1.0) -> Iterator[RemoteJointState]:
        """Every torque command (effort only) in order."""
        return self._iterate(self._commands, timeout)

    def _latest(self, queue: _Queue, timeout: float) -> Any:
        deadline = time.monotonic() + timeout
        while queue.latest is None and time.monotonic() < deadline:
            time.sleep(POLL_S)
        return queue.latest

    def latest_telemetry(self, timeout: float = 1.0) -> RemoteTelemetry | None:
        """The newest telemetry sample, waiting up to ``timeout`` s for a first one."""
        return self._latest(self._telemetry, timeout)

    def latest_joint_state(self, timeout: float = 1.0) -> RemoteJointState | None:
        """The newest joint state, waiting up to ``timeout`` s for a first one."""
        return self._latest(self._states, timeout)

    # --- Commanding -------------------------------------------------------------

    @property
    def last_seq(self) -> int:
        """Sequence number of the last goal sent (0: none yet)."""
        return self._seq

    def _goal_topic(self, level: int, timeout: float) -> tuple[Any, bytes, tuple[str, str]]:
        if level in self._publishers:
            return self._publishers[level]
        t = self.latest_telemetry(timeout)
        if t is None:
            raise TimeoutError(f"no telemetry from namespace {self.namespace!r} within {timeout} s "
                               "(is hcc bridge running and connected?)")
        if not 0 <= level < t.levels():
            raise ValueError(f"level {level} does not exist (the controller has {t.levels()})")
        names = unique_ros_names([lv.name for lv in t.level_list])
        topic = f"/{self.namespace}/{names[level]}/goal"
        ty = self._goal_type(topic, timeout)
        token = self._token("MP", (topic, ty))
        pub = self._session.declare_publisher(topic_key(self.domain, topic, ty))
        gid = os.urandom(16)
        self._tokens.append(token)
        self._publishers[level] = (pub, gid, ty)
        return self._publishers[level]

    def _goal_type(
        self, topic: str, timeout: float, types: Sequence[tuple[str, str]] = GOAL_TYPES
    ) -> tuple[str, str]:
        """The goal type the bridge subscribes ``topic`` with (its liveliness
        token; asked again until ``timeout``, as tokens travel apart from data)."""
        mangled = topic.replace("/", "%")
        deadline = time.monotonic() + timeout
        while True:
            left = max(0.1, deadline - time.monotonic())
            for reply in self._session.liveliness().get(f"@ros2_lv/{self.domain}/**", timeout=left):
                if reply.ok is None:
                    continue
                parts = str(reply.ok.key_expr).split("/")
                if len(parts) == 13 and parts[5] == "MS" and parts[9] == mangled:
                    for ty in types:
                        if parts[10] == dds_name(ty[0]) and parts[11] == ty[1]:
                            return ty
            if time.monotonic() >= deadline:
                raise TimeoutError(f"no bridge subscribes {topic} (is hcc bridge running?)")
            time.sleep(0.05)

    def send_values(self, level: int, values: Sequence[float], timeout: float = 2.0) -> int:
        """Sends ``values`` to ``level``'s goal topic as its message type
        (pose: x, y, z, roll, pitch, yaw; position: x, y, z; orientation:
        roll, pitch, yaw; others: the level's m values); returns the sequence
        number to wait for."""
        pub, gid, ty = self._goal_topic(level, timeout)
        self._seq += 1
        now = time.time_ns()
        pub.put(encode_goal(ty, values, now), attachment=attachment(self._seq, now, gid))
        self._sent[self._seq] = gid
        return self._seq

    def follow(
        self,
        level: int,
        times: Sequence[float],
        points: Sequence[Sequence[float]],
        joint_names: Sequence[str] = (),
        timeout: float = 2.0,
        velocities: Sequence[Sequence[float]] | None = None,
        accelerations: Sequence[Sequence[float]] | None = None,
    ) -> int:
        """Sends ``level`` a path on its path topic (docs/tracking.md): a
        ``MultiDOFJointTrajectory`` for a Cartesian level (each point x, y, z,
        qx, qy, qz, qw), a ``JointTrajectory`` for the others (the level's
        values); ``times`` from when the controller accepts it. With
        ``velocities`` and ``accelerations`` (one per point: a twist, linear
        then angular, for a Cartesian level) the bridge sends the points as
        samples with those rates. Returns the sequence number for
        :meth:`wait_until_accepted`."""
        key = ("path", level)
        if key not in self._publishers:
            t = self.latest_telemetry(timeout)
            if t is None or not 0 <= level < t.levels():
                raise ValueError(f"level {level} does not exist or no telemetry")
            names = unique_ros_names([lv.name for lv in t.level_list])
            topic = f"/{self.namespace}/{names[level]}/path"
            ty = self._goal_type(topic, timeout, PATH_TYPES)
            self._tokens.append(self._token("MP", (topic, ty)))
            pub = self._session.declare_publisher(topic_key(self.domain, topic, ty))
            self._publishers[key] = (pub, os.urandom(16), ty)
        pub, gid, ty = self._publishers[key]
        self._seq += 1
        now = time.time_ns()
        pub.put(encode_trajectory(ty, times, points, joint_names, now, velocities, accelerations),
                attachment=attachment(self._seq, now, gid))
        self._sent[self._seq] = gid
        return self._seq

    def set_load(
        self,
        mass: float,
        com: Sequence[float] = (0.0, 0.0, 0.0),
        inertia: Sequence[float] | None = None,
        timeout: float = 2.0,
    ) -> int:
        """Tells the controller the load the robot's hand holds from now on,
        on the load topic (as :meth:`hcc.Client.set_load`; the ramp is the
        bridge's ``--load-ramp``). Returns the sequence number for
        :meth:`wait_until_accepted`; the answer's level is :data:`LOAD_LEVEL`."""
        key = "load"
        if key not in self._publishers:
            topic = f"/{self.namespace}/load"
            ty = self._goal_type(topic, timeout, (INERTIA_STAMPED,))
            self._tokens.append(self._token("MP", (topic, ty)))
            pub = self._session.declare_publisher(topic_key(self.domain, topic, ty))
            self._publishers[key] = (pub, os.urandom(16), ty)
        pub, gid, _ = self._publishers[key]
        self._seq += 1
        now = time.time_ns()
        pub.put(encode_load(mass, com, inertia, now), attachment=attachment(self._seq, now, gid))
        self._sent[self._seq] = gid
        return self._seq

    def set_goal(self, level: int, values: Sequence[float], duration: float | None = None) -> int:
        """Sets ``level``'s goal in its task coordinates (as :meth:`hcc.Client.set_goal`;
        the transition duration is the bridge's ``--goal-duration``, so
        ``duration`` must be None). Returns the sequence number."""
        if duration is not None:
            raise ValueError("remote goals take the bridge's --goal-duration; pass duration=None")
        return self.send_values(level, values)

    def wait_until_accepted(self, seq: int, timeout: float = 2.0) -> RemoteAnswer:
        """Waits for the answer to goal ``seq`` (or a later goal of the same
        level's publisher) and returns it when accepted; raises
        :class:`GoalRefused` with the reason, TimeoutError without answer."""
        gid = self._sent.get(seq)
        if gid is None:
            raise ValueError(f"goal {seq} was not sent by this client")
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            t = self._telemetry.latest
            for a in (t.remote_answers if t is not None else []):
                if a.source_gid == gid and a.source_seq >= seq:
                    if a.accepted():
                        return a
                    raise GoalRefused(a)
            time.sleep(POLL_S)
        raise TimeoutError(f"no answer to goal {seq} within {timeout:.1f} s")

    def wait_until_converged(self, level: int, tolerance: float, timeout: float = 10.0) -> float:
        """Waits until ``level``'s transition is over and its error norm is
        ≤ ``tolerance``; returns that norm (TimeoutError otherwise)."""
        deadline = time.monotonic() + timeout
        last = float("nan")
        while time.monotonic() < deadline:
            t = self._telemetry.latest
            if t is not None and level < t.levels():
                last = t.error_norm(level)
                if t.progress(level) >= 1.0 and last <= tolerance:
                    return last
            time.sleep(POLL_S)
        raise TimeoutError(f"level {level} did not converge to {tolerance} within {timeout:.1f} s "
                           f"(error {last:.3e})")
