"""The driver side of the hcc contract, without any transport.

Mirror of the Rust ``DriverLogic`` (hcc-driver-example): which received
command may be applied, what to do when none may (hold, then fallback, then
stop) and what the published state says about it. Both implementations run
the same cases (``tests/data/driver_cases.json``).

Per control period the driver

1. samples the joints and publishes a :class:`~hcc.msgs.JointState` filled by
   :meth:`Driver.fill_state` (seq +1, stamp, status, gravity flag, counters);
2. passes every received :class:`~hcc.msgs.TorqueCommand` to
   :meth:`Driver.offer`, which checks its sequence number, its validity, the
   gravity agreement (exactly one side adds g(q), paper Eq. (19)) and the echo
   of the state it answers (current, or late up to the tolerance; never a
   state not yet published);
3. calls :meth:`Driver.decide` with the newest applicable command, which
   yields the torque to write:

   * an applicable command in mode NORMAL, SINGULAR or SAFE_HOLD: its τ;
   * mode STOP: nothing; the driver stops (status STOPPING, then STOPPED,
     and never resumes);
   * no applicable command (a miss): ``missed_commands`` +1, status
     FALLBACK_ACTIVE, ``fallback_cycles`` +1; the last applied τ is held for
     ``hold_cycles`` periods, then τ = g(q) − D q̇ (g only when the robot does
     not compensate gravity itself); after ``fallback_timeout_cycles``
     periods in a row in fallback the driver stops.
"""

from __future__ import annotations

import enum
from dataclasses import dataclass, field
from typing import Sequence

from .msgs import (
    STATE_FLAG_DRIVER_GRAVITY_COMPENSATION,
    CommandMode,
    DriverStatus,
    JointState,
    MsgError,
    TorqueCommand,
)


@dataclass
class DriverSettings:
    """Settings of the contract logic."""

    #: Number of joints n.
    n: int
    #: Commands answering a state up to this many periods older than the latest are applied.
    late_tolerance: int = 0
    #: Periods the last applied τ is held after a miss before the fallback torque.
    hold_cycles: int = 3
    #: Periods in a row in fallback after which the driver stops.
    fallback_timeout_cycles: int = 100
    #: Joint damping D of the fallback torque −D q̇ (n entries).
    fallback_damping: list[float] = field(default_factory=list)
    #: Whether the robot adds gravity compensation itself.
    compensates_gravity: bool = False

    def __post_init__(self) -> None:
        if not self.fallback_damping:
            self.fallback_damping = [2.0] * self.n
        if len(self.fallback_damping) != self.n:
            raise ValueError(
                f"fallback_damping has {len(self.fallback_damping)} entries, expected {self.n}"
            )


class CommandRejection(enum.Enum):
    """Why a received command was not applied."""

    #: Its sequence number repeats or goes back.
    OLD = "old"
    #: It fails validation (schema, joint count, unknown mode/flags, non-finite τ).
    INVALID = "invalid"
    #: Its gravity flag disagrees with the driver's gravity handling.
    GRAVITY_CONFLICT = "gravity_conflict"
    #: It answers a state that was never published.
    FUTURE = "future"
    #: It answers a state older than the tolerance allows.
    TOO_LATE = "too_late"


@dataclass(frozen=True)
class Offer:
    """What :meth:`Driver.offer` found."""

    #: Whether the command may be applied.
    applicable: bool
    #: Applicable: whether it answers the latest published state.
    current: bool = False
    #: Not applicable: why.
    rejection: CommandRejection | None = None
    #: TOO_LATE: by how many periods.
    cycles: int = 0
    #: INVALID / GRAVITY_CONFLICT: the reason.
    reason: str = ""


class Action(enum.Enum):
    """What the driver does this period."""

    #: Write the command's τ.
    APPLY = "apply"
    #: A miss: write the last applied τ again (within hold_cycles).
    HOLD = "hold"
    #: A miss: write the fallback torque g(q) − D q̇.
    FALLBACK = "fallback"
    #: Do not write; engage the safe stop (the first time).
    STOP_FIRST = "stop_first"
    #: Do not write; already stopping or stopped.
    STOP = "stop"


class StopReason(enum.Enum):
    """Why the driver stopped."""

    #: The controller sent a command in mode STOP.
    COMMANDED = "commanded"
    #: No applicable command for fallback_timeout_cycles periods.
    FALLBACK_TIMEOUT = "fallback_timeout"
    #: The driver itself was asked to stop.
    REQUESTED = "requested"


class Driver:
    """State of the driver's contract logic (status OK, nothing published)."""

    def __init__(self, settings: DriverSettings) -> None:
        self.settings = settings
        self.status = DriverStatus.OK
        self.stop_reason: StopReason | None = None
        self.missed_commands = 0
        self.fallback_cycles = 0
        self.applied = 0
        self.rejections: dict[CommandRejection, int] = {r: 0 for r in CommandRejection}
        self._next_state_seq = 0
        self._last_command_seq: int | None = None
        self._misses_in_a_row = 0
        self._last_tau: list[float] | None = None

    def fill_state(
        self,
        msg: JointState,
        q: Sequence[float],
        qd: Sequence[float],
        tau_measured: Sequence[float],
        stamp_ns: int,
    ) -> int:
        """Fills the next state (joints, seq, stamp, status, flags, counters); returns its seq.

        Raises :class:`~hcc.msgs.MsgError` for wrong lengths or non-finite
        values (nothing is published then and the caller stops).
        """
        msg.set_joints(q, qd, tau_measured)
        seq = self._next_state_seq
        self._next_state_seq += 1
        msg.header.seq = seq
        msg.header.stamp_ns = stamp_ns
        msg.status = int(self.status)
        msg.flags = STATE_FLAG_DRIVER_GRAVITY_COMPENSATION if self.settings.compensates_gravity else 0
        msg.missed_commands = self.missed_commands
        msg.fallback_cycles = self.fallback_cycles
        return seq

    def _observe_command_seq(self, seq: int, current: bool) -> bool:
        """Sequence check of the command stream; False for a repeated or backwards number."""
        last = self._last_command_seq
        if last is None or seq > last:
            self._last_command_seq = seq
            return True
        if seq < last and current:
            # A restarted controller answering our latest state: resynchronise.
            self._last_command_seq = seq
            return True
        return False

    def _reject(self, rejection: CommandRejection, cycles: int = 0, reason: str = "") -> Offer:
        self.rejections[rejection] += 1
        return Offer(False, rejection=rejection, cycles=cycles, reason=reason)

    def offer(self, command: TorqueCommand, latest: JointState) -> Offer:
        """Classifies a received command against the latest published state."""
        latest_seq = latest.header.seq
        current = command.state_seq == latest_seq
        if not self._observe_command_seq(command.header.seq, current):
            return self._reject(CommandRejection.OLD)
        try:
            command.validate(self.settings.n)
        except MsgError as e:
            return self._reject(CommandRejection.INVALID, reason=str(e))
        if command.gravity_included() == latest.driver_compensates_gravity():
            return self._reject(
                CommandRejection.GRAVITY_CONFLICT,
                reason=f"command includes gravity: {command.gravity_included()}, "
                f"driver compensates gravity: {latest.driver_compensates_gravity()}",
            )
        if current:
            return Offer(True, current=True)
        if command.state_seq > latest_seq:
            return self._reject(CommandRejection.FUTURE)
        cycles = latest_seq - command.state_seq
        if cycles <= self.settings.late_tolerance:
            return Offer(True, current=False)
        return self._reject(CommandRejection.TOO_LATE, cycles=cycles)

    def decide(
        self,
        command: TorqueCommand | None,
        qd: Sequence[float],
        gravity: Sequence[float],
        tau: list[float],
    ) -> Action:
        """Decides this period's torque into ``tau`` (length n).

        ``command``: the newest command :meth:`offer` found applicable this
        period, if any; ``gravity`` is g(q) (ignored when the robot
        compensates gravity itself).
        """
        n = self.settings.n
        if self.status in (DriverStatus.STOPPING, DriverStatus.STOPPED):
            tau[:] = [0.0] * n
            self.status = DriverStatus.STOPPED
            return Action.STOP
        if command is not None:
            if command.mode == CommandMode.STOP:
                tau[:] = [0.0] * n
                return self._begin_stop(StopReason.COMMANDED)
            tau[:] = command.tau_list()
            self._last_tau = list(tau)
            self._misses_in_a_row = 0
            self.applied += 1
            self.status = DriverStatus.OK
            return Action.APPLY
        self.missed_commands += 1
        self._misses_in_a_row += 1
        if self._misses_in_a_row > self.settings.fallback_timeout_cycles:
            tau[:] = [0.0] * n
            return self._begin_stop(StopReason.FALLBACK_TIMEOUT)
        self.status = DriverStatus.FALLBACK_ACTIVE
        self.fallback_cycles += 1
        if self._last_tau is not None and self._misses_in_a_row <= self.settings.hold_cycles:
            tau[:] = self._last_tau
            return Action.HOLD
        d = self.settings.fallback_damping
        g = [0.0] * n if self.settings.compensates_gravity else gravity
        tau[:] = [g[k] - d[k] * qd[k] for k in range(n)]
        return Action.FALLBACK

    def request_stop(self) -> Action:
        """The driver stops on its own (signal, end of the run, hardware fault)."""
        if self.status in (DriverStatus.STOPPING, DriverStatus.STOPPED):
            return Action.STOP
        return self._begin_stop(StopReason.REQUESTED)

    def stop_completed(self) -> None:
        """The safe stop has completed: the next state says STOPPED."""
        if self.status == DriverStatus.STOPPING:
            self.status = DriverStatus.STOPPED

    def _begin_stop(self, reason: StopReason) -> Action:
        self.status = DriverStatus.STOPPING
        self.stop_reason = reason
        return Action.STOP_FIRST
