"""The simulated robot driver on MuJoCo: the contract exactly as ``hcc-sim``.

Per control period k the driver publishes the state (q_k, q̇_k) as the
plant holds it, then applies a torque over [t_k, t_{k+1}] (zero-order hold)
chosen from the newest received command:

* the newest command, if it passes validation, agrees on gravity (exactly
  one side adds g(q), paper Eq. (19)), answers state k and its mode applies
  torque (NORMAL, SINGULAR, SAFE_HOLD);
* otherwise a miss: status FALLBACK_ACTIVE from that period on (counted in
  ``missed_commands`` and ``fallback_cycles``); the last applied torque is
  held for ``hold_cycles`` periods, then τ = g(q_k) − D q̇_k (gravity held,
  joint damping: a braking robot) until applicable commands come back;
* before the first command ever, the fallback without counting misses (the
  arm does not fall while the controller starts);
* a STOP command ends control for the session: status STOPPED, braking from
  then on.

When the scenario's controller does not add gravity
(``gravity_compensation = false``) the driver compensates it itself, like
many commercial arms: it sets the driver-gravity flag and adds g(q_k).
"""

from __future__ import annotations

import enum
from dataclasses import dataclass

import numpy as np

from ..msgs import (
    DRIVER_SCHEMA_VERSION,
    STATE_FLAG_DRIVER_GRAVITY_COMPENSATION,
    CommandMode,
    DriverStatus,
    Header,
    JointState,
    MsgError,
    TorqueCommand,
)
from ..scenario import Scenario
from .plant import Plant, SceneFile


class Applied(enum.Enum):
    """How the torque of one period was chosen."""

    COMMAND = "command"
    HELD = "held"
    FALLBACK = "fallback"
    WAITING_FOR_CONTROLLER = "waiting_for_controller"
    STOPPED = "stopped"


@dataclass
class Counters:
    """Counters of the driver."""

    missed_commands: int = 0
    fallback_cycles: int = 0
    applied_commands: int = 0
    rejected_commands: int = 0


def _per_joint(v: float | list[float], n: int) -> np.ndarray:
    return np.array(v if isinstance(v, list) else [v] * n, dtype=float)


class MujocoDriver:
    """The MuJoCo plant plus the driver's command handling."""

    def __init__(self, scenario: Scenario, scene: SceneFile | None = None) -> None:
        self.plant = Plant(scenario, scene)
        self.n = self.plant.n
        self.period_s = scenario.period_s
        self.hold_cycles = scenario.hold_cycles
        self.fallback_damping = _per_joint(scenario.fallback_damping, self.n)
        if len(self.fallback_damping) != self.n:
            raise ValueError(f"sim_daemon.fallback_damping needs {self.n} entries")
        self.driver_gravity = not scenario.gravity_compensation
        self.state_flags = STATE_FLAG_DRIVER_GRAVITY_COMPENSATION if self.driver_gravity else 0
        self.cycles_total: int | None = None
        self.tau = np.zeros(self.n)
        self.last_command_tau = np.zeros(self.n)
        self.have_command = False
        self.consecutive_misses = 0
        self.status = DriverStatus.FALLBACK_ACTIVE
        self.counters = Counters()

    @property
    def k(self) -> int:
        """Index k of the current state."""
        return self.plant.k

    def set_duration(self, duration_s: float) -> None:
        """Stop after ``duration_s`` of simulated time (whole periods)."""
        cycles = round(duration_s / self.period_s)
        if not (np.isfinite(duration_s) and 1 <= cycles <= 1e12):
            raise ValueError(
                f"--duration {duration_s} s must be finite and cover at least one period of {self.period_s} s"
            )
        self.cycles_total = cycles

    def finished(self) -> bool:
        """Whether the final state (of the duration) has been reached."""
        return self.cycles_total is not None and self.k >= self.cycles_total

    def in_fallback(self) -> bool:
        """In the fallback after misses (not while waiting for the first command)."""
        return self.have_command and self.status == DriverStatus.FALLBACK_ACTIVE

    def write_state(self, msg: JointState, stamp_ns: int) -> None:
        """Writes state k (exact plant values) into ``msg``, stamped ``stamp_ns``."""
        n = self.n
        msg.header = Header(schema_version=DRIVER_SCHEMA_VERSION, n_joints=n, seq=self.k, stamp_ns=stamp_ns)
        msg.status = int(self.status)
        msg.flags = self.state_flags
        msg.missed_commands = self.counters.missed_commands
        msg.fallback_cycles = self.counters.fallback_cycles
        # The torque applied over the last period is the "motor" torque.
        for field, values in ((msg.q, self.plant.q), (msg.qd, self.plant.qd), (msg.tau_measured, self.tau)):
            view = np.ctypeslib.as_array(field)
            view[:n] = values
            view[n:] = 0.0

    def _applicable(self, command: TorqueCommand) -> CommandMode | None:
        try:
            command.validate(self.n)
        except MsgError:
            self.counters.rejected_commands += 1
            return None
        if command.gravity_included() == self.driver_gravity:
            self.counters.rejected_commands += 1
            return None
        if command.state_seq != self.k:
            return None
        return command.mode_or_none()

    def _fallback_torque(self) -> None:
        # The robot holds its own g(q), which knows no load (as hcc-sim's driver).
        self.tau = self.plant.robot_gravity() - self.fallback_damping * self.plant.qd

    def advance(self, newest: TorqueCommand | None) -> Applied:
        """Chooses the torque for [t_k, t_{k+1}], integrates the period and advances k."""
        mode = self._applicable(newest) if newest is not None else None
        if self.status == DriverStatus.STOPPED:
            applied = Applied.STOPPED
        elif mode == CommandMode.STOP:
            self.status = DriverStatus.STOPPED
            applied = Applied.STOPPED
        elif mode is not None and newest is not None:
            self.tau = np.array(newest.tau[: self.n])
            if self.driver_gravity:
                self.tau = self.tau + self.plant.robot_gravity()
            self.last_command_tau = self.tau.copy()
            self.have_command = True
            self.consecutive_misses = 0
            self.status = DriverStatus.OK
            self.counters.applied_commands += 1
            applied = Applied.COMMAND
        elif not self.have_command:
            applied = Applied.WAITING_FOR_CONTROLLER
        else:
            self.counters.missed_commands += 1
            self.consecutive_misses += 1
            self.status = DriverStatus.FALLBACK_ACTIVE
            self.counters.fallback_cycles += 1
            if self.consecutive_misses <= self.hold_cycles:
                self.tau = self.last_command_tau.copy()
                applied = Applied.HELD
            else:
                applied = Applied.FALLBACK
        if applied == Applied.FALLBACK:
            self._fallback_torque()
        elif applied in (Applied.WAITING_FOR_CONTROLLER, Applied.STOPPED):
            self._fallback_torque()
            self.counters.fallback_cycles += 1
        self.plant.advance(self.tau)
        return applied
