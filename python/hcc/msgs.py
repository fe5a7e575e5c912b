"""ctypes mirrors of the hcc message contract (the Rust crate ``hcc-msgs``).

Every wire type has the same size, alignment and field offsets as its
``#[repr(C)]`` Rust definition (``tests/test_layout.py`` compares them with
the Rust compiler's own figures), and its ``type_name()`` returns the
iceoryx2 type name of the Rust type including the schema version, so
iceoryx2 connects a Python peer to the Rust peers and refuses one built
against another schema (``IncompatibleTypes``).

Joint vectors hold :data:`MAX_JOINTS` entries of which the first
``header.n_joints`` are meaningful; writers keep the tail zero.
"""

from __future__ import annotations

import ctypes
import enum
import math
from typing import Sequence

#: Version of the message schema; part of every type name.
SCHEMA_VERSION: int = 1
#: Joint capacity of every joint vector.
MAX_JOINTS: int = 32
#: Capacity of hierarchy levels r in :class:`Telemetry`.
MAX_LEVELS: int = 8
#: Capacity of one level's task dimension m_i in :class:`Telemetry`.
MAX_TASK_DIM: int = MAX_JOINTS

#: :attr:`JointState.flags` bit: the driver adds gravity compensation g(q) itself.
STATE_FLAG_DRIVER_GRAVITY_COMPENSATION: int = 1 << 0
#: All :attr:`JointState.flags` bits of this schema.
STATE_FLAGS_KNOWN: int = STATE_FLAG_DRIVER_GRAVITY_COMPENSATION
#: :attr:`TorqueCommand.flags` bit: τ contains the gravity torque g(q) (paper Eq. (19)).
COMMAND_FLAG_GRAVITY_INCLUDED: int = 1 << 0
#: All :attr:`TorqueCommand.flags` bits of this schema.
COMMAND_FLAGS_KNOWN: int = COMMAND_FLAG_GRAVITY_INCLUDED
#: :attr:`Telemetry.flags` bit: the controller lost the driver (no state within its timeout).
TELEMETRY_FLAG_PEER_LOST: int = 1 << 16

_Joints = ctypes.c_double * MAX_JOINTS


def _type_name(name: str) -> str:
    return f"hcc_msgs::{name}@schema{SCHEMA_VERSION}"


class MsgError(ValueError):
    """A message that fails the contract's checks (the reason is the text)."""


class DriverStatus(enum.IntEnum):
    """Status of the driver, in :attr:`JointState.status`."""

    #: Commands are applied normally.
    OK = 0
    #: No applicable command recently; the driver runs its own fallback.
    FALLBACK_ACTIVE = 1
    #: The driver is stopping; it no longer applies commands.
    STOPPING = 2
    #: The driver has stopped; no further commands are applied.
    STOPPED = 3


class CommandMode(enum.IntEnum):
    """Mode of a :class:`TorqueCommand`, in :attr:`TorqueCommand.mode`."""

    #: τ is the regular control law, paper Eq. (19).
    NORMAL = 0
    #: The controller's defined safe command after invalid input; applied.
    SAFE_HOLD = 1
    #: τ is valid but a task Jacobian is (near) singular; applied.
    SINGULAR = 2
    #: The controller requests a stop: τ is not applied, the driver stops.
    STOP = 3


def _check_finite(msg: str, field: str, values: Sequence[float], n: int) -> None:
    for index in range(n):
        value = values[index]
        if not math.isfinite(value):
            raise MsgError(f"{msg}.{field}[{index}] is not finite ({value})")


def _check_n(msg: str, n_joints: int, expected_n: int) -> int:
    if n_joints > MAX_JOINTS:
        raise MsgError(f"{msg}: {n_joints} joints exceed the capacity of {MAX_JOINTS}")
    if n_joints != expected_n:
        raise MsgError(f"{msg}: {n_joints} joints, the robot has {expected_n}")
    return n_joints


class Header(ctypes.Structure):
    """Header shared by all messages (mirror of ``hcc_msgs::Header``)."""

    _fields_ = [
        ("schema_version", ctypes.c_uint32),
        ("n_joints", ctypes.c_uint32),
        ("seq", ctypes.c_uint64),
        ("stamp_ns", ctypes.c_uint64),
    ]
    schema_version: int
    n_joints: int
    seq: int
    stamp_ns: int

    @staticmethod
    def type_name() -> str:
        """The iceoryx2 type name of the Rust type."""
        return _type_name("Header")

    def check(self, msg: str, expected_n: int) -> int:
        """Checks the schema version and the joint count; returns n."""
        if self.schema_version != SCHEMA_VERSION:
            raise MsgError(
                f"{msg}: schema version {self.schema_version}, expected {SCHEMA_VERSION}"
            )
        return _check_n(msg, self.n_joints, expected_n)

    def n(self) -> int:
        """``n_joints`` clamped to the capacity."""
        return min(self.n_joints, MAX_JOINTS)


def _new_header() -> Header:
    return Header(schema_version=SCHEMA_VERSION)


class JointState(ctypes.Structure):
    """Joint state, published by the driver once per control period.

    Units: q in rad (prismatic m), q̇ in rad/s, τ in N·m. Joint order: the
    URDF chain from root to tip (actuated joints only).
    """

    _fields_ = [
        ("header", Header),
        ("status", ctypes.c_uint32),
        ("flags", ctypes.c_uint32),
        ("missed_commands", ctypes.c_uint64),
        ("fallback_cycles", ctypes.c_uint64),
        ("q", _Joints),
        ("qd", _Joints),
        ("tau_measured", _Joints),
    ]
    header: Header
    status: int
    flags: int
    missed_commands: int
    fallback_cycles: int

    @staticmethod
    def type_name() -> str:
        """The iceoryx2 type name of the Rust type."""
        return _type_name("JointState")

    @classmethod
    def zeroed(cls) -> "JointState":
        """All-zero state with the current schema and status OK."""
        return cls(header=_new_header())

    def n(self) -> int:
        """Number of valid joints (clamped to the capacity)."""
        return self.header.n()

    def q_list(self) -> list[float]:
        """Joint positions, length n."""
        return list(self.q[: self.n()])

    def qd_list(self) -> list[float]:
        """Joint velocities, length n."""
        return list(self.qd[: self.n()])

    def tau_measured_list(self) -> list[float]:
        """Measured torques, length n."""
        return list(self.tau_measured[: self.n()])

    def set_joints(
        self, q: Sequence[float], qd: Sequence[float], tau: Sequence[float]
    ) -> None:
        """Sets n = len(q) and q, q̇, τ_measured (checked first; tail zeroed)."""
        n = len(q)
        if n > MAX_JOINTS:
            raise MsgError(f"joint_state: {n} joints exceed the capacity of {MAX_JOINTS}")
        for field, values in (("q", q), ("qd", qd), ("tau_measured", tau)):
            if len(values) != n:
                raise MsgError(f"joint_state.{field} has {len(values)} entries, expected {n}")
            _check_finite("joint_state", field, values, n)
        self.header.n_joints = n
        for field, values in (("q", q), ("qd", qd), ("tau_measured", tau)):
            dst = getattr(self, field)
            for k in range(MAX_JOINTS):
                dst[k] = float(values[k]) if k < n else 0.0

    def driver_compensates_gravity(self) -> bool:
        """Whether the driver adds gravity compensation itself."""
        return bool(self.flags & STATE_FLAG_DRIVER_GRAVITY_COMPENSATION)

    def validate(self, expected_n: int) -> None:
        """Receiver-side check: schema, n, status, flags, finite values."""
        n = self.header.check("joint_state", expected_n)
        if self.status not in DriverStatus._value2member_map_:
            raise MsgError(f"joint_state.status: unknown code {self.status}")
        if self.flags & ~STATE_FLAGS_KNOWN:
            raise MsgError(f"joint_state.flags: unknown bits {self.flags:#x}")
        for field in ("q", "qd", "tau_measured"):
            _check_finite("joint_state", field, getattr(self, field), n)


class TorqueCommand(ctypes.Structure):
    """Torque command, published by the controller once per received state."""

    _fields_ = [
        ("header", Header),
        ("state_seq", ctypes.c_uint64),
        ("state_stamp_ns", ctypes.c_uint64),
        ("mode", ctypes.c_uint32),
        ("flags", ctypes.c_uint32),
        ("tau", _Joints),
    ]
    header: Header
    state_seq: int
    state_stamp_ns: int
    mode: int
    flags: int

    @staticmethod
    def type_name() -> str:
        """The iceoryx2 type name of the Rust type."""
        return _type_name("TorqueCommand")

    @classmethod
    def zeroed(cls) -> "TorqueCommand":
        """All-zero command with the current schema and mode NORMAL."""
        return cls(header=_new_header())

    def n(self) -> int:
        """Number of valid joints (clamped to the capacity)."""
        return self.header.n()

    def tau_list(self) -> list[float]:
        """Commanded torques, length n."""
        return list(self.tau[: self.n()])

    def gravity_included(self) -> bool:
        """Whether τ contains the gravity torque g(q)."""
        return bool(self.flags & COMMAND_FLAG_GRAVITY_INCLUDED)

    def mode_or_none(self) -> CommandMode | None:
        """The decoded mode, None for an unknown code."""
        try:
            return CommandMode(self.mode)
        except ValueError:
            return None

    def validate(self, expected_n: int) -> None:
        """Receiver-side check: schema, n, known mode and flags, finite τ."""
        n = self.header.check("torque_command", expected_n)
        if self.mode_or_none() is None:
            raise MsgError(f"torque_command.mode: unknown code {self.mode}")
        if self.flags & ~COMMAND_FLAGS_KNOWN:
            raise MsgError(f"torque_command.flags: unknown bits {self.flags:#x}")
        _check_finite("torque_command", "tau", self.tau, n)


class TelemetryCounters(ctypes.Structure):
    """Event counters of the controller (totals since start)."""

    _fields_ = [
        ("cycles", ctypes.c_uint64),
        ("invalid_states", ctypes.c_uint64),
        ("saturations", ctypes.c_uint64),
        ("singular_cycles", ctypes.c_uint64),
        ("stale_events", ctypes.c_uint64),
        ("peer_lost_events", ctypes.c_uint64),
        ("missed_states", ctypes.c_uint64),
        ("sequence_errors", ctypes.c_uint64),
        ("send_failures", ctypes.c_uint64),
    ]

    @staticmethod
    def type_name() -> str:
        """The iceoryx2 type name of the Rust type."""
        return _type_name("TelemetryCounters")


class TelemetryTimings(ctypes.Structure):
    """Timing of one controller cycle, in ns."""

    _fields_ = [
        ("wakeup_latency_ns", ctypes.c_int64),
        ("compute_ns", ctypes.c_uint64),
        ("period_ns", ctypes.c_uint64),
        ("max_compute_ns", ctypes.c_uint64),
    ]

    @staticmethod
    def type_name() -> str:
        """The iceoryx2 type name of the Rust type."""
        return _type_name("TelemetryTimings")


class Telemetry(ctypes.Structure):
    """Per-cycle diagnostics of the controller.

    Paper quantities: τ_i per level (Eqs. (20), (21)), τ_μ (Eq. (22)), g and
    the total τ (Eq. (19)), task errors x̃_i, storage functions S_i (Eqs.
    (26), (28)), P_μ = τ_μᵀ q̇.
    """

    _fields_ = [
        ("header", Header),
        ("state_seq", ctypes.c_uint64),
        ("command_seq", ctypes.c_uint64),
        ("mode", ctypes.c_uint32),
        ("n_levels", ctypes.c_uint32),
        ("task_dims", ctypes.c_uint32 * MAX_LEVELS),
        ("singular_levels", ctypes.c_uint32),
        ("flags", ctypes.c_uint32),
        ("tau", _Joints),
        ("tau_level", _Joints * MAX_LEVELS),
        ("tau_mu", _Joints),
        ("tau_gravity", _Joints),
        ("task_error", (ctypes.c_double * MAX_TASK_DIM) * MAX_LEVELS),
        ("storage", ctypes.c_double * MAX_LEVELS),
        ("min_singular_value", ctypes.c_double * MAX_LEVELS),
        ("p_mu", ctypes.c_double),
        ("counters", TelemetryCounters),
        ("timings", TelemetryTimings),
    ]
    header: Header
    state_seq: int
    command_seq: int
    mode: int
    n_levels: int
    singular_levels: int
    flags: int
    p_mu: float
    counters: TelemetryCounters
    timings: TelemetryTimings

    @staticmethod
    def type_name() -> str:
        """The iceoryx2 type name of the Rust type."""
        return _type_name("Telemetry")

    def n(self) -> int:
        """Number of valid joints (clamped to the capacity)."""
        return self.header.n()

    def levels(self) -> int:
        """Number of valid levels (clamped to the capacity)."""
        return min(self.n_levels, MAX_LEVELS)

    def task_error_list(self, level: int) -> list[float]:
        """Task error x̃ of ``level`` (0-based), length m_i; empty if out of range."""
        if not 0 <= level < self.levels():
            return []
        m = min(self.task_dims[level], MAX_TASK_DIM)
        return list(self.task_error[level][:m])

    def error_norm(self, level: int) -> float:
        """Euclidean norm of the task error of ``level`` (0-based)."""
        return math.sqrt(sum(e * e for e in self.task_error_list(level)))

    def tau_list(self) -> list[float]:
        """Total commanded τ (Eq. (19)), length n."""
        return list(self.tau[: self.n()])

    def peer_lost(self) -> bool:
        """Whether this sample reports a lost driver."""
        return bool(self.flags & TELEMETRY_FLAG_PEER_LOST)

    def is_singular(self, level: int) -> bool:
        """Whether level ``level`` (0-based) is flagged singular."""
        return 0 <= level < 32 and bool(self.singular_levels & (1 << level))


#: Every wire type by its Rust name.
WIRE_TYPES: dict[str, type[ctypes.Structure]] = {
    "Header": Header,
    "JointState": JointState,
    "TorqueCommand": TorqueCommand,
    "TelemetryCounters": TelemetryCounters,
    "TelemetryTimings": TelemetryTimings,
    "Telemetry": Telemetry,
}
