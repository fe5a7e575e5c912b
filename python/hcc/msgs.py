"""ctypes mirrors of the hcc message contract (the Rust crate ``hcc-msgs``).

Every wire type has the same size, alignment and field offsets as its
``#[repr(C)]`` Rust definition (``tests/test_layout.py`` compares them with
the Rust compiler's own figures), and its ``type_name()`` returns the
iceoryx2 type name of the Rust type including the version of its part of
the contract (``@driver<N>``: joint state and torque command; ``@client<N>``:
setpoints and telemetry), so iceoryx2 connects a Python peer to the Rust
peers and refuses one built against another version of that part
(``IncompatibleTypes``). The two parts are versioned apart: a telemetry
change bumps :data:`CLIENT_SCHEMA_VERSION` only, and drivers keep working.

Joint vectors hold :data:`MAX_JOINTS` entries of which the first
``header.n_joints`` are meaningful; writers keep the tail zero.
"""

from __future__ import annotations

import ctypes
import enum
import math
from typing import Any, Sequence

#: Version of the driver-facing part of the contract (joint state, torque
#: command, their events and flags); part of their type names (``@driver<N>``).
DRIVER_SCHEMA_VERSION: int = 3
#: Version of the client-facing part (setpoints, telemetry, rejection codes);
#: part of their type names (``@client<N>``).
CLIENT_SCHEMA_VERSION: int = 8
#: Joint capacity of every joint vector.
MAX_JOINTS: int = 32
#: Capacity of hierarchy levels r in :class:`Telemetry`.
MAX_LEVELS: int = 8
#: Capacity of one level's task dimension m_i in :class:`Telemetry`.
MAX_TASK_DIM: int = MAX_JOINTS

#: :attr:`JointState.flags` bit: the driver adds gravity compensation g(q) itself.
STATE_FLAG_DRIVER_GRAVITY_COMPENSATION: int = 1 << 0
#: :attr:`JointState.flags` bit: the driver polls for its commands and never waits on
#: ``command_ready``, so the controller skips that notification.
STATE_FLAG_DRIVER_POLLS_COMMANDS: int = 1 << 1
#: All :attr:`JointState.flags` bits of this schema.
STATE_FLAGS_KNOWN: int = STATE_FLAG_DRIVER_GRAVITY_COMPENSATION | STATE_FLAG_DRIVER_POLLS_COMMANDS
#: :attr:`TorqueCommand.flags` bit: τ contains the gravity torque g(q) (paper Eq. (19)).
COMMAND_FLAG_GRAVITY_INCLUDED: int = 1 << 0
#: All :attr:`TorqueCommand.flags` bits of this schema.
COMMAND_FLAGS_KNOWN: int = COMMAND_FLAG_GRAVITY_INCLUDED
#: :attr:`Telemetry.flags` bit: the controller lost the driver (no state within its timeout).
TELEMETRY_FLAG_PEER_LOST: int = 1 << 16
#: :attr:`Telemetry.flags` bit: the controller's contact detection flags a contact
#: (some ``|tau_ext[j]|`` above its threshold, not yet all below the release level).
TELEMETRY_FLAG_CONTACT: int = 1 << 17
#: :attr:`Telemetry.flags` bit: the contact reaction ``hold`` is latched (gravity and a
#: joint damper until a client's accepted setpoint releases it).
TELEMETRY_FLAG_CONTACT_HOLD: int = 1 << 18
#: Clients whose last answer :class:`Telemetry` carries (the most recent ones).
MAX_SETPOINT_CLIENTS: int = 8
#: Setpoints the controller keeps waiting for their application point
#: (:attr:`Setpoint.apply_at_state_seq`), over all clients; one more is
#: rejected with :attr:`SetpointRejection.PENDING_FULL`.
MAX_PENDING_SETPOINTS: int = 32

_Joints = ctypes.c_double * MAX_JOINTS


def _driver_type_name(name: str) -> str:
    return f"hcc_msgs::{name}@driver{DRIVER_SCHEMA_VERSION}"


def _client_type_name(name: str) -> str:
    return f"hcc_msgs::{name}@client{CLIENT_SCHEMA_VERSION}"


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
        return f"hcc_msgs::Header@driver{DRIVER_SCHEMA_VERSION}@client{CLIENT_SCHEMA_VERSION}"

    def check(self, msg: str, expected_n: int, version: int = DRIVER_SCHEMA_VERSION) -> int:
        """Checks the schema version (of the message's part: ``version``) and
        the joint count; returns n."""
        if self.schema_version != version:
            raise MsgError(f"{msg}: schema version {self.schema_version}, expected {version}")
        return _check_n(msg, self.n_joints, expected_n)

    def n(self) -> int:
        """``n_joints`` clamped to the capacity."""
        return min(self.n_joints, MAX_JOINTS)


def _driver_header() -> Header:
    return Header(schema_version=DRIVER_SCHEMA_VERSION)


def _client_header() -> Header:
    return Header(schema_version=CLIENT_SCHEMA_VERSION)


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
        return _driver_type_name("JointState")

    @classmethod
    def zeroed(cls) -> "JointState":
        """All-zero state with the current schema and status OK."""
        return cls(header=_driver_header())

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
        return _driver_type_name("TorqueCommand")

    @classmethod
    def zeroed(cls) -> "TorqueCommand":
        """All-zero command with the current schema and mode NORMAL."""
        return cls(header=_driver_header())

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
        ("rate_limited", ctypes.c_uint64),
        ("low_passed", ctypes.c_uint64),
        ("velocity_limited", ctypes.c_uint64),
        ("velocity_limit_fallbacks", ctypes.c_uint64),
        ("velocity_limit_max_correction_mnm", ctypes.c_uint64),
    ]
    cycles: int
    invalid_states: int
    saturations: int
    singular_cycles: int
    stale_events: int
    peer_lost_events: int
    missed_states: int
    sequence_errors: int
    send_failures: int
    #: Cycles whose torque change was limited by the torque-rate limit.
    rate_limited: int
    #: Cycles whose torque went through the output low-pass filter.
    low_passed: int
    #: Cycles whose torque the discrete-time velocity limit corrected.
    velocity_limited: int
    #: Of those, cycles without a certified brake (the fall-back was sent).
    velocity_limit_fallbacks: int
    #: The largest correction of the velocity limit so far, mN·m (a maximum).
    velocity_limit_max_correction_mnm: int

    @staticmethod
    def type_name() -> str:
        """The iceoryx2 type name of the Rust type."""
        return _client_type_name("TelemetryCounters")


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
        return _client_type_name("TelemetryTimings")


class SetpointAnswer(ctypes.Structure):
    """The controller's answer to the last setpoint of one client (in :class:`Telemetry`)."""

    _fields_ = [
        ("client_id", ctypes.c_uint64),
        ("seq", ctypes.c_uint64),
        ("answered", ctypes.c_uint64),
        ("code", ctypes.c_uint32),
        ("level", ctypes.c_uint32),
        ("duration_s", ctypes.c_double),
        ("rejected", ctypes.c_uint32),
        ("late", ctypes.c_uint32),
        ("knot", ctypes.c_uint32),
        ("reserved", ctypes.c_uint32),
    ]
    #: The client's :attr:`Setpoint.client_id`.
    client_id: int
    #: ``header.seq`` of the client's last setpoint.
    seq: int
    #: Setpoints answered for this client so far (0: an empty slot).
    answered: int
    #: :data:`ANSWER_ACCEPTED` or a :class:`SetpointRejection` code.
    code: int
    #: The level it addressed (0-based, as sent).
    level: int
    #: The transition duration in force, s (stretched to the level's speed
    #: limit if needed; 0 when rejected).
    duration_s: float
    #: Setpoints of this client rejected so far (of ``answered``).
    rejected: int
    #: Setpoints of this client applied late so far (they arrived after the
    #: state of their :attr:`Setpoint.apply_at_state_seq`).
    late: int
    #: The knot a refused :class:`PathKnots` message was refused for, 0-based
    #: in the message; :data:`NO_KNOT` when the answer names no knot.
    knot: int
    #: Zero.
    reserved: int

    @staticmethod
    def type_name() -> str:
        """The iceoryx2 type name of the Rust type."""
        return _client_type_name("SetpointAnswer")

    def accepted(self) -> bool:
        """Whether the setpoint was accepted."""
        return self.code == ANSWER_ACCEPTED

    def refused_knot(self) -> "int | None":
        """The refused knot (0-based in its message), if the answer names one."""
        return None if self.knot == NO_KNOT else int(self.knot)

    def rejection(self) -> "SetpointRejection | None":
        """The rejection, None when accepted or for an unknown code."""
        return SetpointRejection.from_code(self.code)

    def __repr__(self) -> str:
        return (
            f"SetpointAnswer(client_id={self.client_id:#x}, seq={self.seq}, "
            f"answered={self.answered}, code={self.code}, level={self.level}, "
            f"duration_s={self.duration_s}, rejected={self.rejected}, late={self.late})"
        )


class Telemetry(ctypes.Structure):
    """Per-cycle diagnostics of the controller.

    Paper quantities: τ_i per level (Eqs. (20), (21)), τ_μ (Eq. (22)), g and
    the total τ (Eq. (19)), task errors x̃_i, storage functions S_i (Eqs.
    (26), (28)), P_μ = τ_μᵀ q̇. Since schema 2 also the active goal
    x_{i,d}(t) and the diagonals of K_i(t) and D_i(t) of every level
    (Eqs. (20), (21)), each level's transition progress, and the answer to
    the last setpoint of each recent client. Since client schema 4 also
    ``tau_ext``, the estimate of the external joint torque (appended last),
    and the contact flag :data:`TELEMETRY_FLAG_CONTACT`. Since client schema
    6 also ``h``, the storage H of the arm and the controller together (J:
    kinetic energy, the levels' potentials as faded, the joint-limit guard's
    potential, the controller's energy tanks), ``potential``, each level's
    potential as H counts it, ``tank``, the energy in each level's energy tank
    (J), and ``tank_valve``, its valve in [0, 1] (1: the paper's law).
    Since client schema 8 also the load the controller's model carries
    (``load_mass``, ``load_com``, ``load_progress``; docs/load.md) — each
    appended after every older field.
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
        ("goal", (ctypes.c_double * MAX_TASK_DIM) * MAX_LEVELS),
        ("stiffness_diag", (ctypes.c_double * MAX_TASK_DIM) * MAX_LEVELS),
        ("damping_diag", (ctypes.c_double * MAX_TASK_DIM) * MAX_LEVELS),
        ("transition_progress", ctypes.c_double * MAX_LEVELS),
        ("setpoint_answers", SetpointAnswer * MAX_SETPOINT_CLIENTS),
        ("tau_ext", _Joints),
        ("h", ctypes.c_double),
        ("potential", ctypes.c_double * MAX_LEVELS),
        ("tank", ctypes.c_double * MAX_LEVELS),
        ("tank_valve", ctypes.c_double * MAX_LEVELS),
        ("load_mass", ctypes.c_double),
        ("load_com", ctypes.c_double * 3),
        ("load_progress", ctypes.c_double),
    ]
    header: Header
    state_seq: int
    command_seq: int
    mode: int
    n_levels: int
    singular_levels: int
    flags: int
    p_mu: float
    h: float
    counters: TelemetryCounters
    timings: TelemetryTimings

    @staticmethod
    def type_name() -> str:
        """The iceoryx2 type name of the Rust type."""
        return _client_type_name("Telemetry")

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

    def _per_level(self, rows: ctypes.Array, level: int) -> list[float]:
        if not 0 <= level < self.levels():
            return []
        return list(rows[level][: min(self.task_dims[level], MAX_TASK_DIM)])

    def goal_list(self, level: int) -> list[float]:
        """Active goal x_{i,d}(t) of ``level`` (0-based), length m_i (roll,
        pitch, yaw for orientation); moves during a transition. Empty if out
        of range."""
        return self._per_level(self.goal, level)

    def stiffness_diag_list(self, level: int) -> list[float]:
        """Diagonal of the active stiffness K_i(t) of ``level``, length m_i."""
        return self._per_level(self.stiffness_diag, level)

    def damping_diag_list(self, level: int) -> list[float]:
        """Diagonal of the active damping D_i(t) of ``level``, length m_i."""
        return self._per_level(self.damping_diag, level)

    def progress(self, level: int) -> float:
        """Progress t/T of ``level``'s transition in [0, 1] (1: at rest); NaN if out of range."""
        if not 0 <= level < self.levels():
            return math.nan
        return self.transition_progress[level]

    def answer_for(self, client_id: int) -> SetpointAnswer | None:
        """The answer to the last setpoint of ``client_id``, if this sample has one."""
        for a in self.setpoint_answers:
            if a.answered > 0 and a.client_id == client_id:
                return a
        return None

    def tau_list(self) -> list[float]:
        """Total commanded τ (Eq. (19)), length n."""
        return list(self.tau[: self.n()])

    def peer_lost(self) -> bool:
        """Whether this sample reports a lost driver."""
        return bool(self.flags & TELEMETRY_FLAG_PEER_LOST)

    def tau_ext_list(self) -> list[float]:
        """r, the controller's estimate of the external joint torque τ_ext
        (N·m; generalized-momentum observer, client schema 4), length n."""
        return list(self.tau_ext[: self.n()])

    def tank_list(self) -> list[float]:
        """The energy in each level's energy tank (J; 0 for level 1, which has
        none; client schema 6), length r."""
        return list(self.tank[: self.levels()])

    def tank_valve_list(self) -> list[float]:
        """Each level's tank valve in [0, 1] (1: the paper's law; 0: the
        level's spring point follows what the levels above do to it; client
        schema 6), length r."""
        return list(self.tank_valve[: self.levels()])

    def load_com_list(self) -> list[float]:
        """The centre of mass of the load the controller's model carries, in
        the tip frame (m; client schema 8; ``load_mass`` its mass in kg,
        ``load_progress`` the announced load's ramp in [0, 1], 1: none runs;
        docs/load.md)."""
        return list(self.load_com)

    def potential_list(self) -> list[float]:
        """Each level's potential as H counts it (J; V_1, then β_i V_i with
        the level's fade β_i; client schema 6), length r."""
        return list(self.potential[: self.levels()])

    def contact(self) -> bool:
        """Whether this sample flags a contact."""
        return bool(self.flags & TELEMETRY_FLAG_CONTACT)

    def contact_hold(self) -> bool:
        """Whether the contact reaction ``hold`` is latched (a setpoint releases it)."""
        return bool(self.flags & TELEMETRY_FLAG_CONTACT_HOLD)

    def is_singular(self, level: int) -> bool:
        """Whether level ``level`` (0-based) is flagged singular."""
        return 0 <= level < 32 and bool(self.singular_levels & (1 << level))


# --- Setpoints (mirror of hcc_msgs::Setpoint, SetpointRejection and their constants) ---

#: :attr:`Setpoint.fields` bit: set the goal x_{i,d} (``goal``).
SETPOINT_GOAL: int = 1 << 0
#: :attr:`Setpoint.fields` bit: set the goal's velocity feed-forward ẋ_{i,d}
#: (``velocity``); only together with :data:`SETPOINT_GOAL`.
SETPOINT_VELOCITY: int = 1 << 1
#: :attr:`Setpoint.fields` bit: set the stiffness K_i (``stiffness``).
SETPOINT_STIFFNESS: int = 1 << 2
#: :attr:`Setpoint.fields` bit: set the damping D_i (``damping``).
SETPOINT_DAMPING: int = 1 << 3
#: All :attr:`Setpoint.fields` bits of this schema.
SETPOINT_FIELDS_KNOWN: int = (
    SETPOINT_GOAL | SETPOINT_VELOCITY | SETPOINT_STIFFNESS | SETPOINT_DAMPING
)
#: :attr:`Setpoint.gain_layout` bit: ``stiffness`` holds the full m×m matrix
#: row-major (m² values); otherwise its diagonal (m values).
GAIN_STIFFNESS_FULL: int = 1 << 0
#: :attr:`Setpoint.gain_layout` bit: ``damping`` holds the full m×m matrix row-major.
GAIN_DAMPING_FULL: int = 1 << 1
#: All :attr:`Setpoint.gain_layout` bits of this schema.
GAIN_LAYOUT_KNOWN: int = GAIN_STIFFNESS_FULL | GAIN_DAMPING_FULL
#: Capacity of one full gain matrix (m×m with m ≤ :data:`MAX_TASK_DIM`).
MAX_GAIN_ENTRIES: int = MAX_TASK_DIM * MAX_TASK_DIM
#: Longest transition a setpoint may ask for, s (one hour).
MAX_TRANSITION_S: float = 3600.0
#: Relative tolerance of the symmetry check of a full K or D:
#: |A_jk − A_kj| ≤ tolerance · max |A_jk|.
SYMMETRY_TOLERANCE: float = 1e-9
#: The answer code of an accepted setpoint; every other code is a :class:`SetpointRejection`.
ANSWER_ACCEPTED: int = 0

_REJECTION_TEXT: dict[int, str] = {}


class SetpointRejection(enum.IntEnum):
    """Why a setpoint was rejected (a rejected setpoint changes nothing).

    The codes are stable (they travel in telemetry). :meth:`Setpoint.validate`
    checks codes 1-11 (no model needed); the controller checks 12-16 and 18 against
    its law and model, and 17 against its queue of setpoints waiting for
    their state. :attr:`label` is the Rust ``SetpointRejection::name()``
    (snake_case, as in ``hcc goal`` and ``hcc monitor --json``), :attr:`reason`
    the text for a person.
    """

    #: ``header.schema_version`` differs from :data:`CLIENT_SCHEMA_VERSION`.
    SCHEMA_MISMATCH = 1
    #: ``fields`` has bits this schema does not define.
    UNKNOWN_FIELDS = 2
    #: ``fields`` is zero: the setpoint sets nothing.
    NOTHING_SET = 3
    #: :data:`SETPOINT_VELOCITY` without :data:`SETPOINT_GOAL`.
    VELOCITY_WITHOUT_GOAL = 4
    #: ``gain_layout`` has bits this schema does not define.
    UNKNOWN_LAYOUT = 5
    #: ``level`` ≥ :data:`MAX_LEVELS`.
    LEVEL_CAPACITY = 6
    #: ``dim`` is 0 or above :data:`MAX_TASK_DIM`.
    DIMENSION_CAPACITY = 7
    #: A value that is used is NaN or infinite.
    NON_FINITE = 8
    #: ``duration_s`` is negative or above :data:`MAX_TRANSITION_S`.
    BAD_DURATION = 9
    #: A full K or D is not symmetric (beyond :data:`SYMMETRY_TOLERANCE`).
    NOT_SYMMETRIC = 10
    #: K or D is not positive definite.
    NOT_POSITIVE_DEFINITE = 11
    #: The controller has no level ``level``.
    UNKNOWN_LEVEL = 12
    #: ``dim`` differs from the level's task dimension m_i.
    DIMENSION_MISMATCH = 13
    #: K exceeds the level's ``max_stiffness`` (an eigenvalue above it).
    STIFFNESS_ABOVE_LIMIT = 14
    #: A joint goal lies outside the joint's URDF limits.
    JOINT_LIMIT = 15
    #: A position goal lies outside the level's workspace.
    OUTSIDE_WORKSPACE = 16
    #: The setpoint is due at a later state, but :data:`MAX_PENDING_SETPOINTS`
    #: setpoints already wait for theirs.
    PENDING_FULL = 17
    #: K or D is more than the control rate carries at the arm's configuration.
    GAINS_ABOVE_RATE = 18

    @property
    def label(self) -> str:
        """The short machine-friendly name (``outside_workspace``), as in Rust."""
        return self.name.lower()

    @property
    def reason(self) -> str:
        """The reason in plain words."""
        return _REJECTION_TEXT[self.value]

    @classmethod
    def from_code(cls, code: int) -> "SetpointRejection | None":
        """Decodes a code; None for :data:`ANSWER_ACCEPTED` and unknown codes."""
        try:
            return cls(code)
        except ValueError:
            return None

    def __str__(self) -> str:
        return f"{self.label} (code {self.value}): {self.reason}"


_REJECTION_TEXT.update({
    1: "the client speaks another hcc-msgs schema version",
    2: "the setpoint sets fields this schema does not define",
    3: "the setpoint sets nothing (no goal, velocity, stiffness or damping)",
    4: "a velocity feed-forward needs a goal in the same setpoint",
    5: "the gain layout has bits this schema does not define",
    6: "the level index exceeds the message capacity",
    7: "the dimension is 0 or exceeds the message capacity",
    8: "a value is NaN or infinite",
    9: "the transition duration is negative or longer than one hour",
    10: "a stiffness or damping matrix is not symmetric",
    11: "a stiffness or damping matrix is not positive definite",
    12: "the controller has no such level",
    13: "the dimension differs from the level's task dimension",
    14: "the stiffness exceeds the level's max_stiffness",
    15: "a joint goal lies outside the joint's limits",
    16: "a position goal lies outside the level's workspace",
    17: "too many setpoints wait for their state sequence number",
    18: "K or D is more than the control rate carries at the arm's configuration (the sampled spring-damper would oscillate)",
})


class SetpointError(MsgError):
    """A setpoint that fails a check; :attr:`rejection` names the reason.

    Raised before sending by :meth:`Setpoint.validate` and the ``with_*``
    builders (the controller's codes for the same faults).
    """

    def __init__(
        self,
        rejection: "SetpointRejection | PathRejection | LoadRejection | None",
        message: str | None = None,
    ) -> None:
        super().__init__(message or f"setpoint not sent: {rejection}")
        #: The rejection (None only for an answer code this schema does not know;
        #: a :class:`PathRejection` for a path's knots checked before sending).
        self.rejection = rejection


_U32_MAX = 0xFFFF_FFFF
_Task = ctypes.c_double * MAX_TASK_DIM
_Gains = ctypes.c_double * MAX_GAIN_ENTRIES


def _floats(values: Any) -> list[float]:
    """A flat list of floats from a sequence, a nested m×m sequence or an array."""
    out: list[float] = []
    for v in values:
        if isinstance(v, (int, float)) or not hasattr(v, "__iter__"):
            out.append(float(v))
        else:
            out.extend(float(x) for x in v)
    return out


def _copy_values(dst: ctypes.Array, values: Sequence[float], dim: int) -> None:
    if dim == 0 or dim > MAX_TASK_DIM:
        raise SetpointError(SetpointRejection.DIMENSION_CAPACITY)
    if len(values) != dim:
        raise SetpointError(
            SetpointRejection.DIMENSION_MISMATCH,
            f"setpoint not sent: {len(values)} values for dimension {dim}",
        )
    ctypes.memset(dst, 0, ctypes.sizeof(dst))
    for k, v in enumerate(values):
        dst[k] = v


def _copy_gain(dst: ctypes.Array, values: Sequence[float], dim: int) -> bool:
    if dim == 0 or dim > MAX_TASK_DIM:
        raise SetpointError(SetpointRejection.DIMENSION_CAPACITY)
    full = len(values) == dim * dim and dim > 1
    if not full and len(values) != dim:
        raise SetpointError(
            SetpointRejection.DIMENSION_MISMATCH,
            f"setpoint not sent: {len(values)} gain values for dimension {dim} "
            f"(give {dim} diagonal values or {dim * dim} row-major)",
        )
    ctypes.memset(dst, 0, ctypes.sizeof(dst))
    for k, v in enumerate(values):
        dst[k] = v
    return full


def _cholesky_ok(a: Sequence[float], m: int) -> bool:
    """Whether the symmetric m×m matrix (row-major, lower triangle used) is
    positive definite: A = L Lᵀ finds every pivot > 0."""
    low = [0.0] * (m * m)
    for j in range(m):
        for k in range(j + 1):
            s = a[j * m + k]
            for p in range(k):
                s -= low[j * m + p] * low[k * m + p]
            if j == k:
                if math.isnan(s) or s <= 0.0:
                    return False
                low[j * m + j] = math.sqrt(s)
            else:
                low[j * m + k] = s / low[k * m + k]
    return True


def _check_spd(values: Sequence[float], full: bool, m: int) -> SetpointRejection | None:
    if not full:
        return None if all(v > 0.0 for v in values) else SetpointRejection.NOT_POSITIVE_DEFINITE
    scale = max((abs(v) for v in values), default=0.0)
    for j in range(m):
        for k in range(j):
            if abs(values[j * m + k] - values[k * m + j]) > SYMMETRY_TOLERANCE * scale:
                return SetpointRejection.NOT_SYMMETRIC
    return None if _cholesky_ok(values, m) else SetpointRejection.NOT_POSITIVE_DEFINITE


class Setpoint(ctypes.Structure):
    """A setpoint for one hierarchy level (mirror of ``hcc_msgs::Setpoint``).

    Changes the level's goal x_{i,d} (with an optional velocity feed-forward
    ẋ_{i,d}), its stiffness K_i and/or its damping D_i (paper Eqs. (20),
    (21)) over a transition of ``duration_s`` seconds. Values are in the
    task's own coordinates, as in the scenario TOML: metres on a position
    task's axes, roll/pitch/yaw in rad for orientation, rad (m) per joint for
    a posture. K and D are m×m: diagonal (m values) or full (m² row-major).

    ``header.seq`` is the client's sequence number (echoed in the answer),
    ``header.stamp_ns`` the send time, ``header.n_joints`` unused (0).
    Build one with :meth:`for_level` and the chainable ``with_*`` methods.
    """

    _fields_ = [
        ("header", Header),
        ("client_id", ctypes.c_uint64),
        ("level", ctypes.c_uint32),
        ("fields", ctypes.c_uint32),
        ("dim", ctypes.c_uint32),
        ("gain_layout", ctypes.c_uint32),
        ("duration_s", ctypes.c_double),
        ("apply_at_state_seq", ctypes.c_uint64),
        ("goal", _Task),
        ("velocity", _Task),
        ("stiffness", _Gains),
        ("damping", _Gains),
    ]
    header: Header
    #: The client's identity (answers are kept per client id).
    client_id: int
    #: Target level, 0-based in the order of the scenario's levels.
    level: int
    #: ``SETPOINT_*`` bits: what this setpoint sets.
    fields: int
    #: Task dimension m of the values (must equal the level's m_i).
    dim: int
    #: ``GAIN_*_FULL`` bits: full or diagonal K and D.
    gain_layout: int
    #: Transition duration, s (0: as fast as the level's speed limit allows).
    duration_s: float
    #: Apply in the controller cycle of the first joint state whose sequence
    #: number is ≥ this (0: on receipt); a setpoint arriving later is applied
    #: on receipt and counted late (:attr:`SetpointAnswer.late`).
    apply_at_state_seq: int

    @staticmethod
    def type_name() -> str:
        """The iceoryx2 type name of the Rust type."""
        return _client_type_name("Setpoint")

    @classmethod
    def zeroed(cls) -> "Setpoint":
        """An all-zero setpoint with the current schema (sets nothing)."""
        return cls(header=_client_header())

    @classmethod
    def for_level(cls, client_id: int, seq: int, level: int, dim: int) -> "Setpoint":
        """A setpoint of ``level`` (0-based) and dimension ``dim`` that sets nothing yet.

        Sizes beyond the capacities are kept (clamped to 32 bits) so that
        :meth:`validate` names them; negative ones raise ValueError.
        """
        if level < 0 or dim < 0:
            raise ValueError(f"level ({level}) and dimension ({dim}) must not be negative")
        s = cls.zeroed()
        s.client_id = client_id
        s.header.seq = seq
        s.level = min(level, _U32_MAX)
        s.dim = min(dim, _U32_MAX)
        return s

    def n_dim(self) -> int:
        """``dim`` clamped to the capacity."""
        return min(self.dim, MAX_TASK_DIM)

    def sets(self, field: int) -> bool:
        """Whether every bit of ``field`` (``SETPOINT_*``) is set."""
        return self.fields & field == field

    def stiffness_full(self) -> bool:
        """Whether K is sent as a full matrix."""
        return bool(self.gain_layout & GAIN_STIFFNESS_FULL)

    def damping_full(self) -> bool:
        """Whether D is sent as a full matrix."""
        return bool(self.gain_layout & GAIN_DAMPING_FULL)

    def goal_list(self) -> list[float]:
        """The goal, length ``dim``."""
        return list(self.goal[: self.n_dim()])

    def velocity_list(self) -> list[float]:
        """The velocity feed-forward, length ``dim``."""
        return list(self.velocity[: self.n_dim()])

    def stiffness_list(self) -> list[float]:
        """The K values sent: ``dim`` (diagonal) or ``dim²`` (full, row-major)."""
        m = self.n_dim()
        return list(self.stiffness[: m * m if self.stiffness_full() else m])

    def damping_list(self) -> list[float]:
        """The D values sent: ``dim`` (diagonal) or ``dim²`` (full, row-major)."""
        m = self.n_dim()
        return list(self.damping[: m * m if self.damping_full() else m])

    def with_goal(self, goal: Sequence[float]) -> "Setpoint":
        """Sets the goal (``dim`` values) and :data:`SETPOINT_GOAL`; returns self."""
        _copy_values(self.goal, _floats(goal), self.dim)
        self.fields |= SETPOINT_GOAL
        return self

    def with_velocity(self, velocity: Sequence[float]) -> "Setpoint":
        """Sets the velocity feed-forward (``dim`` values, goal units per s)."""
        _copy_values(self.velocity, _floats(velocity), self.dim)
        self.fields |= SETPOINT_VELOCITY
        return self

    def _with_gain(self, which: str, values: Any, bit: int, layout: int) -> "Setpoint":
        full = _copy_gain(getattr(self, which), _floats(values), self.dim)
        self.gain_layout = self.gain_layout | layout if full else self.gain_layout & ~layout
        self.fields |= bit
        return self

    def with_stiffness(self, values: Any) -> "Setpoint":
        """Sets K: ``dim`` diagonal values, or the full m×m matrix (nested or
        ``dim²`` row-major; the layout follows the length)."""
        return self._with_gain("stiffness", values, SETPOINT_STIFFNESS, GAIN_STIFFNESS_FULL)

    def with_damping(self, values: Any) -> "Setpoint":
        """Sets D like :meth:`with_stiffness`."""
        return self._with_gain("damping", values, SETPOINT_DAMPING, GAIN_DAMPING_FULL)

    def with_duration(self, duration_s: float) -> "Setpoint":
        """Sets the transition duration in s."""
        self.duration_s = float(duration_s)
        return self

    def with_apply_at(self, state_seq: int) -> "Setpoint":
        """Sets the application point: the cycle of the first joint state with
        sequence number ≥ ``state_seq`` (0: on receipt); returns self."""
        self.apply_at_state_seq = int(state_seq)
        return self

    def check(self) -> SetpointRejection | None:
        """The model-free checks of ``Setpoint::validate``, in its order, and
        the positive definiteness of a full K or D that the controller checks
        next (so the client refuses it before sending); the first failure or
        None."""
        if self.header.schema_version != CLIENT_SCHEMA_VERSION:
            return SetpointRejection.SCHEMA_MISMATCH
        if self.fields & ~SETPOINT_FIELDS_KNOWN:
            return SetpointRejection.UNKNOWN_FIELDS
        if self.fields == 0:
            return SetpointRejection.NOTHING_SET
        if self.sets(SETPOINT_VELOCITY) and not self.sets(SETPOINT_GOAL):
            return SetpointRejection.VELOCITY_WITHOUT_GOAL
        if self.gain_layout & ~GAIN_LAYOUT_KNOWN:
            return SetpointRejection.UNKNOWN_LAYOUT
        if self.level >= MAX_LEVELS:
            return SetpointRejection.LEVEL_CAPACITY
        if self.dim == 0 or self.dim > MAX_TASK_DIM:
            return SetpointRejection.DIMENSION_CAPACITY
        used = (
            (SETPOINT_GOAL, self.goal_list),
            (SETPOINT_VELOCITY, self.velocity_list),
            (SETPOINT_STIFFNESS, self.stiffness_list),
            (SETPOINT_DAMPING, self.damping_list),
        )
        for bit, values in used:
            if self.sets(bit) and not all(math.isfinite(v) for v in values()):
                return SetpointRejection.NON_FINITE
        if not math.isfinite(self.duration_s):
            return SetpointRejection.NON_FINITE
        if not 0.0 <= self.duration_s <= MAX_TRANSITION_S:
            return SetpointRejection.BAD_DURATION
        m = self.n_dim()
        if self.sets(SETPOINT_STIFFNESS):
            found = _check_spd(self.stiffness_list(), self.stiffness_full(), m)
            if found is not None:
                return found
        if self.sets(SETPOINT_DAMPING):
            return _check_spd(self.damping_list(), self.damping_full(), m)
        return None

    def validate(self) -> None:
        """Raises :class:`SetpointError` if :meth:`check` finds a fault."""
        found = self.check()
        if found is not None:
            raise SetpointError(found)


#: Knots one :class:`PathKnots` message carries at most.
MAX_KNOTS_PER_MESSAGE: int = 16
#: Columns of one knot at most.
MAX_PATH_COLUMNS: int = MAX_TASK_DIM
#: :attr:`PathKnots.flags`: the knots begin a new path.
PATH_NEW: int = 1 << 0
#: :attr:`PathKnots.flags`: the knots extend the level's running path.
PATH_EXTEND: int = 1 << 1
#: :attr:`PathKnots.flags`, with :data:`PATH_NEW` or :data:`PATH_EXTEND`:
#: the knots carry their velocity and acceleration (samples).
PATH_DERIVATIVES: int = 1 << 2
#: Every :attr:`PathKnots.flags` bit of this schema.
PATH_FLAGS_KNOWN: int = PATH_NEW | PATH_EXTEND | PATH_DERIVATIVES
#: :attr:`SetpointAnswer.knot` of an answer that names no knot.
NO_KNOT: int = 0xFFFF_FFFF

_PATH_REJECTION_TEXT: dict[int, str] = {
    201: "the message must either begin a path or extend one",
    202: "the message holds no knot or more than it can",
    203: "the knots' times are negative or do not increase past the path's last knot",
    204: "the knots have a number of columns the level does not have",
    205: "an orientation is not a unit quaternion w x y z",
    206: "an orientation turns more than 0.9π from the path's first",
    207: "there is no path running on the level to extend",
    208: "the path ran out of knots and stopped: send a new path",
    209: "the level's path holds as many knots ahead as it can",
    210: "the path's first knot is too far from the level's equilibrium",
    211: "the path moves faster than the level's max_speed",
    212: "the hierarchy cannot follow the path from where the arm is (singular, or out of reach)",
    213: "the feasibility check did not answer in time: nothing was taken",
}


class PathRejection(enum.IntEnum):
    """Why the controller refused a path's knots (codes from 201, apart from
    :class:`SetpointRejection`'s, sharing the answer slots; mirror of
    ``hcc_msgs::PathRejection``)."""

    BAD_FLAGS = 201
    KNOT_COUNT = 202
    NOT_INCREASING = 203
    COLUMN_MISMATCH = 204
    NOT_UNIT_QUATERNION = 205
    TURN_TOO_FAR = 206
    NO_PATH = 207
    PATH_ENDED = 208
    PATH_FULL = 209
    STARTS_AWAY = 210
    TOO_FAST = 211
    INFEASIBLE = 212
    UNCHECKED = 213

    @property
    def label(self) -> str:
        """The Rust ``PathRejection::name()`` (snake_case)."""
        return self.name.lower()

    @property
    def reason(self) -> str:
        """The reason in plain words."""
        return _PATH_REJECTION_TEXT[self.value]

    @classmethod
    def from_code(cls, code: int) -> "PathRejection | None":
        """Decodes a code; None for codes that are not a path's."""
        try:
            return cls(code)
        except ValueError:
            return None

    def __str__(self) -> str:
        return f"{self.label} (code {self.value}): {self.reason}"


class PathKnots(ctypes.Structure):
    """Up to :data:`MAX_KNOTS_PER_MESSAGE` knots of one level's path (mirror of
    ``hcc_msgs::PathKnots``; docs/tracking.md): t in s of the path's own time
    and the values in a path file's columns (a position's x y z, an
    orientation's quaternion w x y z, a joint level's values). ``flags`` is
    :data:`PATH_NEW` (begin a path, at the level's equilibrium) or
    :data:`PATH_EXTEND` (knots later than the running path's last), with
    :data:`PATH_DERIVATIVES` when the knots are samples carrying their
    velocity and acceleration in the level's goal-velocity coordinates (an
    orientation's ω and ω̇ in the base frame, 3 entries)."""

    _fields_ = [
        ("header", Header),
        ("client_id", ctypes.c_uint64),
        ("level", ctypes.c_uint32),
        ("flags", ctypes.c_uint32),
        ("columns", ctypes.c_uint32),
        ("count", ctypes.c_uint32),
        ("apply_at_state_seq", ctypes.c_uint64),
        ("t", ctypes.c_double * MAX_KNOTS_PER_MESSAGE),
        ("values", (ctypes.c_double * MAX_PATH_COLUMNS) * MAX_KNOTS_PER_MESSAGE),
        ("velocity", (ctypes.c_double * MAX_TASK_DIM) * MAX_KNOTS_PER_MESSAGE),
        ("acceleration", (ctypes.c_double * MAX_TASK_DIM) * MAX_KNOTS_PER_MESSAGE),
    ]
    header: Header
    client_id: int
    level: int
    flags: int
    columns: int
    count: int
    apply_at_state_seq: int

    @staticmethod
    def type_name() -> str:
        """The iceoryx2 type name of the Rust type."""
        return _client_type_name("PathKnots")

    @classmethod
    def zeroed(cls) -> "PathKnots":
        """An empty message of the current schema."""
        m = cls()
        m.header = _client_header()
        return m

    def push(self, t: float, values: Sequence[float]) -> None:
        """Appends a knot; :class:`MsgError` when the message is full or the
        values do not fit its columns (set by the first knot)."""
        values = _floats(values)
        if self.count >= MAX_KNOTS_PER_MESSAGE:
            raise MsgError("path knots: the message is full")
        if self.columns == 0:
            self.columns = min(len(values), MAX_PATH_COLUMNS)
        if len(values) != self.columns:
            raise MsgError(f"path knots: {len(values)} values, the message has {self.columns} columns")
        self.t[self.count] = float(t)
        for a, v in enumerate(values):
            self.values[self.count][a] = v
        self.count += 1

    def push_sample(
        self,
        t: float,
        values: Sequence[float],
        velocity: Sequence[float],
        acceleration: Sequence[float],
    ) -> None:
        """Appends a sample: a knot with its velocity and acceleration (the
        level's dimension each) and sets :data:`PATH_DERIVATIVES`."""
        velocity = _floats(velocity)
        acceleration = _floats(acceleration)
        if len(velocity) != len(acceleration) or len(velocity) > min(len(values), MAX_TASK_DIM):
            raise MsgError(
                f"path sample: {len(velocity)} rates and {len(acceleration)} accelerations "
                f"for {len(values)} values"
            )
        k = int(self.count)
        self.push(t, values)
        self.flags |= PATH_DERIVATIVES
        for a in range(len(velocity)):
            self.velocity[k][a] = velocity[a]
            self.acceleration[k][a] = acceleration[a]

    def check(self) -> "SetpointRejection | PathRejection | None":
        """The model-free checks of ``PathKnots::validate``; None when it passes."""
        return self.check_knot()[0]

    def check_knot(self) -> "tuple[SetpointRejection | PathRejection | None, int | None]":
        """:meth:`check` and the knot (0-based) its refusal is about, if one."""
        found = self._check_message()
        if found is not None:
            return found, None
        for k in range(self.count):
            t = self.t[k]
            values = list(self.values[k])[: self.columns]
            values += list(self.velocity[k])[: self.columns] + list(self.acceleration[k])[: self.columns]
            if not math.isfinite(t) or not all(math.isfinite(v) for v in values):
                return SetpointRejection.NON_FINITE, k
            if t < 0.0 or (k > 0 and t <= self.t[k - 1]):
                return PathRejection.NOT_INCREASING, k
        return None, None

    def _check_message(self) -> "SetpointRejection | PathRejection | None":
        if self.header.schema_version != CLIENT_SCHEMA_VERSION:
            return SetpointRejection.SCHEMA_MISMATCH
        if self.flags & ~PATH_DERIVATIVES not in (PATH_NEW, PATH_EXTEND):
            return PathRejection.BAD_FLAGS
        if self.level >= MAX_LEVELS:
            return SetpointRejection.LEVEL_CAPACITY
        if not 0 < self.columns <= MAX_PATH_COLUMNS:
            return PathRejection.COLUMN_MISMATCH
        if not 0 < self.count <= MAX_KNOTS_PER_MESSAGE:
            return PathRejection.KNOT_COUNT
        return None


_LOAD_REJECTION_TEXT: dict[int, str] = {
    301: "the load's mass is negative",
    302: "the load is heavier than the robot's payload limit",
    303: "the load's inertia is not a physical one (positive semidefinite, triangle inequalities)",
    304: "the ramp is negative or too long",
}

#: The ramp of a load whose message gives none, s.
DEFAULT_LOAD_RAMP_S: float = 0.2


class LoadRejection(enum.IntEnum):
    """Why the controller refused a load (codes from 301, sharing the answer
    slots with :class:`SetpointRejection` and :class:`PathRejection`; mirror
    of ``hcc_msgs::LoadRejection``; docs/load.md)."""

    NEGATIVE_MASS = 301
    ABOVE_PAYLOAD = 302
    NOT_PHYSICAL = 303
    BAD_RAMP = 304

    @property
    def label(self) -> str:
        """The Rust ``LoadRejection::name()`` (snake_case)."""
        return self.name.lower()

    @property
    def reason(self) -> str:
        """The reason in plain words."""
        return _LOAD_REJECTION_TEXT[self.value]

    def __str__(self) -> str:
        return f"{self.label} (code {self.value}): {self.reason}"

    @classmethod
    def from_code(cls, code: int) -> "LoadRejection | None":
        """The rejection of an answer code, None for codes that are not a load's."""
        try:
            return cls(code)
        except ValueError:
            return None


class LoadSetpoint(ctypes.Structure):
    """The load the robot's hand holds from now on (mirror of
    ``hcc_msgs::LoadSetpoint``; docs/load.md): mass (kg), centre of mass in
    the tip frame (m), rotational inertia about it in the tip frame's axes
    (kg·m², ixx ixy ixz iyy iyz izz), and the ramp (s; 0:
    :data:`DEFAULT_LOAD_RAMP_S`)."""

    _fields_ = [
        ("header", Header),
        ("client_id", ctypes.c_uint64),
        ("mass", ctypes.c_double),
        ("com", ctypes.c_double * 3),
        ("inertia", ctypes.c_double * 6),
        ("ramp_s", ctypes.c_double),
    ]
    header: Header
    client_id: int
    mass: float
    ramp_s: float

    @staticmethod
    def type_name() -> str:
        """The iceoryx2 type name of the Rust type."""
        return _client_type_name("LoadSetpoint")

    @classmethod
    def zeroed(cls) -> "LoadSetpoint":
        """An empty message of the current schema (no load)."""
        m = cls()
        m.header = _client_header()
        return m

    @classmethod
    def of(
        cls,
        mass: float,
        com: Sequence[float] = (0.0, 0.0, 0.0),
        inertia: Sequence[float] | None = None,
        ramp_s: float = 0.0,
    ) -> "LoadSetpoint":
        """A load; :class:`MsgError` when ``com`` is not 3 values or
        ``inertia`` not 6."""
        com = _floats(com)
        values = _floats(inertia) if inertia is not None else [0.0] * 6
        if len(com) != 3 or len(values) != 6:
            raise MsgError(f"load: {len(com)} values for com (3), {len(values)} for inertia (6)")
        m = cls.zeroed()
        m.mass = float(mass)
        for a, v in enumerate(com):
            m.com[a] = v
        for a, v in enumerate(values):
            m.inertia[a] = v
        m.ramp_s = float(ramp_s)
        return m

    def check(self) -> "SetpointRejection | LoadRejection | None":
        """The model-free checks of ``LoadSetpoint::validate``; None when it passes."""
        if self.header.schema_version != CLIENT_SCHEMA_VERSION:
            return SetpointRejection.SCHEMA_MISMATCH
        values = [self.mass, self.ramp_s, *self.com, *self.inertia]
        if not all(math.isfinite(v) for v in values):
            return SetpointRejection.NON_FINITE
        if self.mass < 0.0:
            return LoadRejection.NEGATIVE_MASS
        if not 0.0 <= self.ramp_s <= MAX_TRANSITION_S:
            return LoadRejection.BAD_RAMP
        return None


#: Every wire type by its Rust name.
WIRE_TYPES: dict[str, type[ctypes.Structure]] = {
    "Header": Header,
    "JointState": JointState,
    "TorqueCommand": TorqueCommand,
    "TelemetryCounters": TelemetryCounters,
    "TelemetryTimings": TelemetryTimings,
    "SetpointAnswer": SetpointAnswer,
    "Telemetry": Telemetry,
    "Setpoint": Setpoint,
    "PathKnots": PathKnots,
    "LoadSetpoint": LoadSetpoint,
}
