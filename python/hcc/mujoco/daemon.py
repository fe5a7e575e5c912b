"""The MuJoCo driver process: :class:`MujocoDriver` on the hcc services.

Paced like ``hcc-sim``:

* **real time**: an absolute clock at the control rate. At tick k+1
  (t_0 + (k+1) T; sleep, then spin the last ``SPIN_LEAD_S``) the driver
  takes the newest command, integrates [t_k, t_{k+1}] with the one that
  answered state k (or holds / falls back), publishes state k+1 and
  notifies ``state_ready``. A tick more than 10 periods late re-anchors the
  clock (an overrun) instead of bursting.
* **lockstep**: after publishing state k the driver waits (on
  ``command_ready``) for the command answering it, then integrates at once.
  Before the first command it waits indefinitely, republishing state k
  every 20 ms; once commands flow, a command missing for
  ``lockstep_timeout_s`` is a miss (hold, then fall back), advancing one
  period per period of wall time until commands return.

With a duration, the state at t = duration is published with status
STOPPED and the process exits 0; SIGINT/SIGTERM do the same at the current
state.
"""

from __future__ import annotations

import json
import pathlib
import signal
import sys
import time
from dataclasses import dataclass, field
from typing import Any, TextIO

import iceoryx2 as iox2
import numpy as np

from .. import ipc
from ..msgs import DriverStatus, JointState, TorqueCommand
from .driver import Applied, MujocoDriver

#: Republish period of the current state while waiting for the first command (lockstep), s.
REPUBLISH_S: float = 0.020
#: Real time: part of the period after publishing during which the answer is awaited.
COMMAND_WINDOW_FRACTION: float = 0.8
#: Real time: the last part of the wait to a tick is spun, s.
SPIN_LEAD_S: float = 0.000050
#: Real time: poll interval while waiting for the answer, s.
POLL_S: float = 0.0001


@dataclass
class RunStats:
    """What the loop measured."""

    mode: str
    periods: int = 0
    waiting: int = 0
    stopped_periods: int = 0
    late_commands: int = 0
    #: Misses of states whose command window was cut short by a late tick
    #: (caught up back to back): the driver's lateness, not the controller's.
    short_window_misses: int = 0
    overruns: int = 0
    connection_updates: int = 0
    connection_update_failures: int = 0
    lateness_ns: list[int] = field(default_factory=list)
    state_to_command_ns: list[int] = field(default_factory=list)

    def summary(self, driver: MujocoDriver, period_ns: int) -> dict[str, Any]:
        """Counters and latency percentiles as a JSON-ready dict."""
        c = driver.counters

        def pct(values: list[int]) -> dict[str, float]:
            if not values:
                return {"count": 0}
            a = np.array(values, dtype=float) * 1e-3
            return {
                "count": len(values),
                "p50_us": float(np.percentile(a, 50)),
                "p99_us": float(np.percentile(a, 99)),
                "p999_us": float(np.percentile(a, 99.9)),
                "max_us": float(a.max()),
            }

        late_ticks = sum(1 for x in self.lateness_ns if x > period_ns * COMMAND_WINDOW_FRACTION)
        return {
            "driver": "hcc.mujoco",
            "mode": self.mode,
            "t_s": driver.plant.t,
            "k": driver.k,
            "periods": self.periods,
            "waiting_for_controller": self.waiting,
            "stopped_periods": self.stopped_periods,
            "applied_commands": c.applied_commands,
            "missed_commands": c.missed_commands,
            "fallback_cycles": c.fallback_cycles,
            "rejected_commands": c.rejected_commands,
            "late_commands": self.late_commands,
            "short_window_misses": self.short_window_misses,
            "ticks_late": late_ticks,
            "overruns": self.overruns,
            "connection_updates": self.connection_updates,
            "connection_update_failures": self.connection_update_failures,
            "tick_lateness": pct(self.lateness_ns),
            "state_to_command": pct(self.state_to_command_ns),
        }


def is_short_window_miss(
    missed_before: int, missed_after: int, tick_ns: int, published_ns: int, window_ns: int
) -> bool:
    """Whether the tick at ``tick_ns`` counted a miss of a state published at
    ``published_ns`` that had less than its command window ``window_ns``.

    A late tick is caught up with ticks back to back, so the state published
    in it has less than its window before the next tick; its miss is the
    driver's lateness, not the controller's (as ``hcc-sim`` counts it).
    """
    return missed_after > missed_before and tick_ns < published_ns + window_ns


class _Stop:
    """SIGINT/SIGTERM set a flag the loops check."""

    requested = False

    @classmethod
    def install(cls) -> None:
        def handler(signum: int, frame: Any) -> None:
            cls.requested = True

        signal.signal(signal.SIGINT, handler)
        signal.signal(signal.SIGTERM, handler)


class ContactLog:
    """Rows t, contact force (world, on the robot), tip position; written beside the run."""

    def __init__(self, out: TextIO | None) -> None:
        self.out = out
        if out is not None:
            out.write("t,fx,fy,fz,f_normal,tip_x,tip_y,tip_z\n")

    def record(self, driver: MujocoDriver) -> None:
        """Appends the current state's contact force."""
        if self.out is None:
            return
        p = driver.plant
        f = p.contact_force()
        wall = p.wall
        fn = float(np.dot(f, wall.normal)) if wall is not None else 0.0
        x = p.tip_position()
        values = [p.t, *f, fn, *x]
        self.out.write(",".join(repr(float(v)) for v in values) + "\n")


class StateLog:
    """Rows t, q, q̇ of every state k (the plant's exact values)."""

    def __init__(self, out: TextIO | None, n: int) -> None:
        self.out = out
        if out is not None:
            cols = [f"q{j + 1}" for j in range(n)] + [f"qd{j + 1}" for j in range(n)]
            out.write(",".join(["t", *cols]) + "\n")

    def record(self, driver: MujocoDriver) -> None:
        """Appends the current state."""
        if self.out is None:
            return
        p = driver.plant
        values = [p.t, *p.q, *p.qd]
        self.out.write(",".join(repr(float(v)) for v in values) + "\n")


class Loop:
    """The driver on its ports."""

    def __init__(
        self,
        driver: MujocoDriver,
        services: ipc.Services,
        contact: ContactLog,
        states: StateLog,
        mode: str,
    ) -> None:
        self.driver = driver
        self.states = services.publisher("joint_state")
        self.state_ready = services.notifier("state_ready", ipc.EVENT_STATE_PUBLISHED)
        self.commands = services.subscriber("torque_command", ipc.LATEST_BUFFER)
        self.command_ready = services.listener("command_ready")
        self.newest: TorqueCommand | None = None
        self.msg = JointState.zeroed()
        self.published_ns = 0
        self.answered = False
        self.contact = contact
        self.state_log = states
        states.record(driver)
        self.stats = RunStats(mode)
        self.period_ns = round(driver.period_s * 1e9)

    def close(self) -> None:
        """Releases the ports."""
        for port in (self.states, self.state_ready, self.commands, self.command_ready):
            port.delete()

    def publish(self) -> None:
        """Publishes state k (stamped now) and notifies state_ready."""
        self.published_ns = time.monotonic_ns()
        self.answered = False
        self.driver.write_state(self.msg, self.published_ns)
        self.states.send_copy(self.msg)
        self.state_ready.notify()

    def _receive(self) -> bool:
        newest = ipc.receive_latest(self.commands, TorqueCommand)
        if newest is not None:
            self.newest = newest
        c = self.newest
        return c is not None and c.state_seq == self.driver.k and c.state_stamp_ns != 0

    def _take_answer(self, drain_events: bool = True) -> bool:
        got = self._receive()
        if got and not self.answered:
            self.answered = True
            self.stats.state_to_command_ns.append(time.monotonic_ns() - self.published_ns)
        if drain_events:
            self.command_ready.try_wait()
        return got

    def _upkeep(self) -> None:
        """Connects the state publisher to subscribers that appeared (a recorder,
        a monitor) while the loop waits, so that the next ``send_copy`` does not
        (iceoryx2 otherwise connects them inside the send, between a tick and
        its state)."""
        try:
            self.states.update_connections()
            self.stats.connection_updates += 1
        except Exception:  # an iceoryx2 error: counted, the send retries it
            self.stats.connection_update_failures += 1

    def _advance(self) -> None:
        applied = self.driver.advance(self.newest)
        self.stats.periods += 1
        if applied == Applied.WAITING_FOR_CONTROLLER:
            self.stats.waiting += 1
        elif applied == Applied.STOPPED:
            self.stats.stopped_periods += 1
        self.contact.record(self.driver)
        self.state_log.record(self.driver)

    def run_realtime(self) -> None:
        """The absolute-clock loop at the control rate."""
        period = self.period_ns
        window = int(period * COMMAND_WINDOW_FRACTION)
        self.publish()
        next_tick = time.monotonic_ns() + period
        while True:
            deadline = min(self.published_ns + window, next_tick)
            # Polled (a blocking wait's timeout is too coarse inside a period);
            # the command_ready notifications are drained at the tick.
            while not self._take_answer(drain_events=False) and not _Stop.requested:
                if time.monotonic_ns() >= deadline:
                    break
                time.sleep(POLL_S)
            self._upkeep()
            rest = next_tick - time.monotonic_ns()
            if rest > SPIN_LEAD_S * 1e9:
                time.sleep((rest - SPIN_LEAD_S * 1e9) * 1e-9)
            while time.monotonic_ns() < next_tick:
                pass
            now = time.monotonic_ns()
            self.stats.lateness_ns.append(now - next_tick)
            if _Stop.requested:
                break
            was_answered = self.answered
            if self._take_answer() and not was_answered:
                self.stats.late_commands += 1
            missed = self.driver.counters.missed_commands
            self._advance()
            if is_short_window_miss(
                missed, self.driver.counters.missed_commands, now, self.published_ns, window
            ):
                self.stats.short_window_misses += 1
            if self.driver.finished():
                break
            self.publish()
            next_tick += period
            if now > next_tick + 10 * period:
                next_tick = now + period
                self.stats.overruns += 1

    def run_lockstep(self, timeout_s: float) -> None:
        """Advance once per answer; misses after ``timeout_s`` once commands flow."""
        period_ns = self.period_ns
        while not self.driver.finished():
            self.publish()
            published = time.monotonic_ns()
            if not self.driver.have_command:
                deadline = None
            elif self.driver.in_fallback():
                deadline = published + period_ns
            else:
                deadline = published + int(timeout_s * 1e9)
            while True:
                if self._take_answer() or _Stop.requested:
                    break
                now = time.monotonic_ns()
                if deadline is not None and now >= deadline:
                    break
                if not self.driver.have_command and now >= published + REPUBLISH_S * 1e9:
                    self.publish()
                    published = now
                wait_ns = (published + int(REPUBLISH_S * 1e9)) - now
                if deadline is not None:
                    wait_ns = min(wait_ns, deadline - now)
                wait_ns = max(1_000, min(wait_ns, 20_000_000))
                self._upkeep()
                self.command_ready.timed_wait(iox2.Duration.from_nanos(wait_ns))
            if _Stop.requested:
                break
            self._advance()


def run(
    driver: MujocoDriver,
    namespace: str,
    *,
    lockstep: bool,
    lockstep_timeout_s: float = 0.1,
    file_prefix: str | None = None,
    contact_csv: pathlib.Path | None = None,
    record_csv: pathlib.Path | None = None,
    stats_path: pathlib.Path | None = None,
    log: TextIO = sys.stderr,
) -> dict[str, Any]:
    """Runs the driver until its duration ends or a signal arrives; returns the stats."""
    _Stop.install()
    node = ipc.create_node("hcc-mujoco", file_prefix)
    services = ipc.Services(node, ipc.ServiceNames(namespace))
    out = open(contact_csv, "w") if contact_csv is not None else None
    rec = open(record_csv, "w") if record_csv is not None else None
    loop = Loop(
        driver,
        services,
        ContactLog(out),
        StateLog(rec, driver.n),
        "lockstep" if lockstep else "realtime",
    )
    try:
        if lockstep:
            loop.run_lockstep(lockstep_timeout_s)
        else:
            loop.run_realtime()
        driver.status = DriverStatus.STOPPED
        loop.publish()
    finally:
        for f in (out, rec):
            if f is not None:
                f.close()
        driver.plant.close()
        loop.close()
    stats = loop.stats.summary(driver, loop.period_ns)
    c = driver.counters
    print(
        f"hcc.mujoco: stopped at t = {driver.plant.t:.3f} s (k = {driver.k}): "
        f"{c.applied_commands} commands applied, {c.missed_commands} missed, "
        f"{c.fallback_cycles} fallback cycles, {c.rejected_commands} rejected, "
        f"{loop.stats.overruns} overruns",
        file=log,
    )
    if not lockstep:
        t = stats["tick_lateness"]
        if t["count"]:
            print(
                f"hcc.mujoco: tick lateness: p50 {t['p50_us']:.1f} µs, p99 {t['p99_us']:.1f} µs, "
                f"max {t['max_us']:.1f} µs ({t['count']} ticks, {stats['ticks_late']} later than "
                f"{COMMAND_WINDOW_FRACTION:.0%} of a period, {stats['late_commands']} late commands, "
                f"{stats['short_window_misses']} of the misses after a late tick)",
                file=log,
            )
    if stats_path is not None:
        stats_path.write_text(json.dumps(stats, indent=1) + "\n")
    return stats
