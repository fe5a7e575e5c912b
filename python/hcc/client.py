"""Commanding and reading a running controller from Python.

:class:`Client` opens the services of one namespace with the contract's
settings, reads the controller's :class:`~hcc.msgs.Telemetry` and the
driver's :class:`~hcc.msgs.JointState`, and commands the controller with
:class:`~hcc.msgs.Setpoint`\ s on ``hcc/<ns>/setpoint`` (the semantics of
the Rust ``hcc-client``): :meth:`Client.set_goal`, :meth:`Client.set_gains`
and :meth:`Client.send` return the setpoint's sequence number, and
:meth:`Client.wait_until_accepted` waits for the controller's answer in its
telemetry (accepted, or the controller's :class:`~hcc.msgs.SetpointRejection`).
Levels are 0-based, in the order of the scenario's ``[[level]]``\ s.

Example::

    with hcc.Client("panda") as client:
        seq = client.set_goal(0, [0.5, 0.1, 0.4], duration=2.0)
        answer = client.wait_until_accepted(seq, timeout=1.0)
        print(f"moving over {answer.duration_s:.2f} s")
        client.wait_until_converged(0, tolerance=1e-3, timeout=5.0)
"""

from __future__ import annotations

import os
import time
from typing import Any, Iterator, Sequence

from . import ipc
from .msgs import (
    ANSWER_ACCEPTED,
    MAX_KNOTS_PER_MESSAGE,
    PATH_EXTEND,
    PATH_NEW,
    JointState,
    LoadRejection,
    LoadSetpoint,
    PathKnots,
    PathRejection,
    SetpointRejection,
    Setpoint,
    SetpointAnswer,
    SetpointError,
    Telemetry,
)

#: Polling interval of the iterators, s.
POLL_S: float = 0.0005


class SetpointRejected(SetpointError):
    """The controller rejected a setpoint (it changed nothing).

    :attr:`rejection` is the controller's reason (None for a code this
    schema does not know, then see :attr:`code`); :attr:`answer` the answer
    as it came in telemetry.
    """

    def __init__(self, answer: SetpointAnswer) -> None:
        rejection = SetpointRejection.from_code(answer.code)
        path = PathRejection.from_code(answer.code)
        load = LoadRejection.from_code(answer.code)
        what = (
            str(rejection) if rejection is not None
            else str(path) if path is not None
            else str(load) if load is not None
            else f"unknown code {answer.code}"
        )
        super().__init__(
            rejection, f"setpoint {answer.seq} rejected by the controller: {what}"
        )
        #: A path's own reason (codes from 201; :attr:`rejection` is None then).
        self.path_rejection: PathRejection | None = path
        #: A load's own reason (codes from 301; :attr:`rejection` is None then).
        self.load_rejection: LoadRejection | None = load
        #: The answer code (a :class:`~hcc.msgs.SetpointRejection` value).
        self.code: int = answer.code
        #: The controller's answer.
        self.answer: SetpointAnswer = answer


class KnotsRefused(SetpointError):
    """The controller (or the checks before sending) refused a message of a
    path: :attr:`first`, :attr:`last` are its knots (0-based in what was
    sent), :attr:`knot` the knot refused when the refusal is one knot's (its
    limits, workspace, order, quaternion, the start), :attr:`cause` the
    refusal (:class:`SetpointRejected` or :class:`~hcc.msgs.SetpointError`)."""

    def __init__(
        self,
        first: int,
        last: int,
        times: Sequence[float],
        cause: Exception,
        knot: int | None = None,
    ) -> None:
        rejection = getattr(cause, "rejection", None)
        where = (
            f"knot {knot} (t = {times[knot]} s)"
            if knot is not None and 0 <= knot < len(times)
            else f"knots {first}..={last} (t = {times[first]} s … {times[last]} s)"
        )
        super().__init__(rejection, f"{where}: {cause}")
        self.first: int = first
        self.last: int = last
        self.knot: int | None = knot
        self.cause: Exception = cause


def new_client_id() -> int:
    """A client id unique among the clients of one host (as the Rust
    ``hcc-client``): the process id in the high 32 bits, the monotonic clock
    in the low ones."""
    return ((os.getpid() << 32) ^ (time.monotonic_ns() & 0xFFFF_FFFF)) & 0xFFFF_FFFF_FFFF_FFFF


class Client:
    """Telemetry, joint states and setpoints of the robot in ``namespace``.

    ``file_prefix``: the shared-memory file prefix of the peers (default:
    $HCC_IPC_FILE_PREFIX, else iceoryx2's default). ``buffer``: queue length
    of the subscribers (samples older than that are lost when not read in
    time). ``client_id``: this client's identity in its setpoints (default
    :func:`new_client_id`); the controller keeps its answers per client id,
    so two clients of one controller must not share one. Use as a context
    manager or call :meth:`close`.

    The setpoint publisher is created with the first setpoint sent (a client
    that only reads takes none of the
    :data:`~hcc.ipc.MAX_SETPOINT_PUBLISHERS` client slots). The waiting
    methods read the same telemetry queue as :meth:`telemetry`. Not for a
    real-time loop: every call allocates and the waits sleep.
    """

    def __init__(
        self,
        namespace: str,
        *,
        file_prefix: str | None = None,
        buffer: int = ipc.MAX_SUBSCRIBER_BUFFER,
        client_id: int | None = None,
    ) -> None:
        if client_id is not None and not 0 <= client_id <= 0xFFFF_FFFF_FFFF_FFFF:
            raise ValueError(f"client_id {client_id} does not fit in 64 unsigned bits")
        self.names = ipc.ServiceNames(namespace)
        self._node = ipc.create_node("hcc-py-client", file_prefix)
        self._services = ipc.Services(self._node, self.names)
        self._telemetry = self._services.subscriber("telemetry", buffer)
        self._states = self._services.subscriber("joint_state", buffer)
        self._publisher: Any = None
        self._paths: Any = None
        self._loads: Any = None
        self._last_telemetry: Telemetry | None = None
        self._last_state: JointState | None = None
        self._client_id = new_client_id() if client_id is None else client_id
        self._seq = 0
        self._scenario: dict[str, Any] | None = None

    def __enter__(self) -> "Client":
        return self

    def __exit__(self, *exc: Any) -> None:
        self.close()

    def close(self) -> None:
        """Releases the ports and the node."""
        for port in (self._telemetry, self._states, self._publisher, self._paths, self._loads):
            if port is not None:
                port.delete()
        self._telemetry = self._states = self._publisher = self._paths = self._loads = None
        self._services = None
        self._node = None

    def scenario(self, timeout: float = 2.0) -> dict[str, Any]:
        """The scenario the controller runs, from its scenario service
        (:func:`hcc.ipc.read_scenario`: the file's text, the URDF, the levels
        and joints, the control rate); read once and kept."""
        if self._scenario is None:
            self._scenario = ipc.read_scenario(self._node, self.names, timeout)
        return self._scenario

    def level_names(self, timeout: float = 2.0) -> list[str]:
        """The controller's levels by name, in priority order (index = the
        0-based level of :meth:`set_goal`)."""
        return [str(level["name"]) for level in self.scenario(timeout)["levels"]]

    def level(self, name: str, timeout: float = 2.0) -> int:
        """The 0-based index of the level called ``name`` (ValueError if none is)."""
        names = self.level_names(timeout)
        if name not in names:
            raise ValueError(f"the controller has no level {name!r} (its levels: {names})")
        return names.index(name)

    def _iterate(self, port: Any, payload: type, timeout: float | None) -> Iterator[Any]:
        deadline = None if timeout is None else time.monotonic() + timeout
        while True:
            got = ipc.receive_all(port, payload)
            for sample in got:
                self._remember(sample)
                yield sample
            if not got:
                if deadline is not None and time.monotonic() >= deadline:
                    return
                time.sleep(POLL_S)
            elif deadline is not None:
                deadline = time.monotonic() + timeout  # type: ignore[operator]

    def _remember(self, sample: Any) -> None:
        if isinstance(sample, Telemetry):
            self._last_telemetry = sample
        else:
            self._last_state = sample

    def telemetry(self, timeout: float | None = 1.0) -> Iterator[Telemetry]:
        """Every telemetry sample in order; ends after ``timeout`` s without one (None: never)."""
        return self._iterate(self._telemetry, Telemetry, timeout)

    def joint_states(self, timeout: float | None = 1.0) -> Iterator[JointState]:
        """Every joint state in order; ends after ``timeout`` s without one (None: never)."""
        return self._iterate(self._states, JointState, timeout)

    def latest_telemetry(self, timeout: float = 1.0) -> Telemetry | None:
        """The newest telemetry sample, waiting up to ``timeout`` s for a first one."""
        return self._latest(self._telemetry, Telemetry, timeout, "_last_telemetry")

    def latest_joint_state(self, timeout: float = 1.0) -> JointState | None:
        """The newest joint state, waiting up to ``timeout`` s for a first one."""
        return self._latest(self._states, JointState, timeout, "_last_state")

    def _latest(self, port: Any, payload: type, timeout: float, attr: str) -> Any:
        deadline = time.monotonic() + timeout
        while True:
            newest = ipc.receive_latest(port, payload)
            if newest is not None:
                setattr(self, attr, newest)
            if getattr(self, attr) is not None or time.monotonic() >= deadline:
                return getattr(self, attr)
            time.sleep(POLL_S)

    # --- Commanding -----------------------------------------------------------

    @property
    def client_id(self) -> int:
        """This client's id (the controller keeps its answers under it)."""
        return self._client_id

    @property
    def last_seq(self) -> int:
        """Sequence number of the last setpoint built (0: none yet)."""
        return self._seq

    def setpoint(self, level: int, dim: int) -> Setpoint:
        """A setpoint of this client for ``level`` (0-based) and dimension
        ``dim`` with the next sequence number (+1 per setpoint); fill it with
        the ``with_*`` methods and hand it to :meth:`send`."""
        self._seq += 1
        return Setpoint.for_level(self._client_id, self._seq, level, dim)

    def send(self, setpoint: Setpoint) -> int:
        """Checks ``setpoint`` (the model-free checks), stamps it with the
        monotonic clock and publishes it; returns its sequence number.

        Raises :class:`~hcc.msgs.SetpointError` (nothing sent) when a check
        fails, :class:`~hcc.ipc.IpcError` when no publisher can be created
        (all client slots taken). Use it for streams (e.g. goal and velocity
        every cycle); the controller answers only the newest setpoint of a
        client that it read in a cycle.
        """
        setpoint.validate()
        msg = Setpoint.from_buffer_copy(setpoint)
        msg.header.stamp_ns = time.monotonic_ns()
        if self._publisher is None:
            self._publisher = self._services.publisher("setpoint")
        try:
            self._publisher.send_copy(msg)
        except Exception as e:  # iceoryx2 raises its own exception types
            raise ipc.IpcError(f"cannot send the setpoint: {e!r}") from e
        return msg.header.seq

    def set_goal(
        self,
        level: int,
        values: Sequence[float],
        duration: float | None = None,
        velocity: Sequence[float] | None = None,
    ) -> int:
        """Sets ``level``'s goal x_{i,d} (its task coordinates, as in the
        scenario TOML: m on a position task's axes, roll/pitch/yaw in rad,
        rad per joint) over a transition of ``duration`` s (None or 0: as
        fast as the level's speed limit allows; shorter transitions are
        stretched to it), with an optional velocity feed-forward ẋ_{i,d}.
        Returns the sequence number for :meth:`wait_until_accepted`."""
        values = list(values)
        sp = self.setpoint(level, len(values)).with_goal(values)
        if velocity is not None:
            sp.with_velocity(velocity)
        return self.send(sp.with_duration(0.0 if duration is None else duration))

    def set_gains(
        self,
        level: int,
        stiffness: Any = None,
        damping: Any = None,
        duration: float | None = None,
    ) -> int:
        """Sets ``level``'s stiffness K_i and/or damping D_i (paper Eqs.
        (20), (21)) over ``duration`` s (None or 0: at once, within the
        level's limits). Each is m diagonal values (a flat sequence) or the
        full symmetric positive definite m×m matrix (nested rows or a 2-D
        array); None keeps it. Returns the sequence number."""
        dims = {name: _gain_dim(v) for name, v in (("stiffness", stiffness), ("damping", damping))
                if v is not None}
        if len(set(dims.values())) > 1:
            raise SetpointError(
                SetpointRejection.DIMENSION_MISMATCH,
                f"setpoint not sent: stiffness is {dims['stiffness']}-dimensional, "
                f"damping {dims['damping']}-dimensional",
            )
        sp = self.setpoint(level, next(iter(dims.values()), 0))
        if stiffness is not None:
            sp.with_stiffness(stiffness)
        if damping is not None:
            sp.with_damping(damping)
        return self.send(sp.with_duration(0.0 if duration is None else duration))

    def follow(
        self,
        level: int,
        times: Sequence[float],
        points: Sequence[Sequence[float]],
        *,
        extend: bool = False,
        start_at_state_seq: int = 0,
        timeout: float = 2.0,
    ) -> SetpointAnswer:
        """Sends ``level`` a path (docs/tracking.md): knots at ``times`` (s of
        the path's own time, from 0) with ``points`` in a path file's columns
        (a position's x y z, an orientation's quaternion w x y z, a joint
        level's values). A new path (``extend`` False) must start at the
        level's equilibrium and starts in the cycle of joint state
        ``start_at_state_seq`` (0: on receipt); ``extend`` True appends
        knots to the running path (later than its last). Sent in messages
        of :data:`~hcc.msgs.MAX_KNOTS_PER_MESSAGE`, each after the answer to
        the one before (within ``timeout`` s); returns the last answer.
        Raises :class:`KnotsRefused` naming the refused message's knots."""
        times = [float(t) for t in times]
        points = [list(p) for p in points]
        if not times or len(times) != len(points):
            raise ValueError("give as many points as times, at least one")
        answer: SetpointAnswer | None = None
        for first in range(0, len(times), MAX_KNOTS_PER_MESSAGE):
            last = min(first + MAX_KNOTS_PER_MESSAGE, len(times)) - 1
            msg = PathKnots.zeroed()
            msg.level = level
            msg.flags = PATH_NEW if (first == 0 and not extend) else PATH_EXTEND
            msg.apply_at_state_seq = start_at_state_seq
            for k in range(first, last + 1):
                try:
                    msg.push(times[k], points[k])
                except Exception as e:
                    raise KnotsRefused(first, last, times, e, k) from e
            found, knot = msg.check_knot()
            if found is not None:
                at = None if knot is None else first + knot
                raise KnotsRefused(first, last, times, SetpointError(found, str(found)), at)
            self._send_path(msg)
            try:
                answer = self.wait_until_accepted(self._seq, timeout)
            except SetpointRejected as e:
                knot = e.answer.refused_knot()
                at = None if knot is None else first + knot
                raise KnotsRefused(first, last, times, e, at) from e
            except TimeoutError as e:
                raise KnotsRefused(first, last, times, e) from e
        assert answer is not None
        return answer

    def stream_samples(self, level: int, *, start_at_state_seq: int = 0, timeout: float = 2.0) -> "SampleStream":
        """A :class:`SampleStream` for ``level``: its path sent sample by
        sample (teleoperation, a policy)."""
        return SampleStream(self, level, start_at_state_seq, timeout)

    def _send_path(self, msg: PathKnots) -> int:
        """Sends one path message as this client's next; returns its seq."""
        if self._paths is None:
            self._paths = self._services.publisher("path")
        msg.client_id = self._client_id
        self._seq += 1
        msg.header.seq = self._seq
        msg.header.stamp_ns = time.monotonic_ns()
        try:
            self._paths.send_copy(msg)
        except Exception as e:  # iceoryx2 raises its own exception types
            raise ipc.IpcError(f"cannot send the path: {e!r}") from e
        return self._seq

    def set_load(
        self,
        mass: float,
        com: Sequence[float] = (0.0, 0.0, 0.0),
        inertia: Sequence[float] | None = None,
        *,
        ramp_s: float = 0.0,
        timeout: float = 1.0,
    ) -> SetpointAnswer:
        """Tells the controller the load the robot's hand holds from now on
        (docs/load.md): ``mass`` kg, ``com`` in the tip frame (m), ``inertia``
        about it (kg·m², ixx ixy ixz iyy iyz izz; None: a point mass), ramped
        in over ``ramp_s`` (0: the default). Waits for the answer: raises
        :class:`~hcc.msgs.SetpointError` when the checks before sending
        refuse it (nothing sent), :class:`SetpointRejected` with
        :attr:`~SetpointRejected.load_rejection` when the controller does."""
        msg = LoadSetpoint.of(mass, com, inertia, ramp_s)
        refusal = msg.check()
        if refusal is not None:
            raise SetpointError(refusal, f"load not sent: {refusal}")
        if self._loads is None:
            self._loads = self._services.publisher("load")
        msg.client_id = self._client_id
        self._seq += 1
        msg.header.seq = self._seq
        msg.header.stamp_ns = time.monotonic_ns()
        try:
            self._loads.send_copy(msg)
        except Exception as e:  # iceoryx2 raises its own exception types
            raise ipc.IpcError(f"cannot send the load: {e!r}") from e
        return self.wait_until_accepted(self._seq, timeout)

    def wait_until_accepted(self, seq: int, timeout: float = 1.0) -> SetpointAnswer:
        """Waits for the controller's answer to this client's setpoint ``seq``
        (or a later one of this client: telemetry keeps only a client's last
        answer) and returns it when accepted.

        Raises :class:`SetpointRejected` with the controller's reason, or
        TimeoutError when no controller answers within ``timeout`` s.
        """
        deadline = time.monotonic() + timeout
        while True:
            t = self._poll_telemetry()
            answer = t.answer_for(self._client_id) if t is not None else None
            if answer is not None and answer.seq >= seq:
                if answer.code == ANSWER_ACCEPTED:
                    return SetpointAnswer.from_buffer_copy(answer)
                raise SetpointRejected(SetpointAnswer.from_buffer_copy(answer))
            if time.monotonic() >= deadline:
                raise TimeoutError(
                    f"no controller answered setpoint {seq} within {timeout:.1f} s "
                    f"(is hcc-controller running in namespace {self.names.namespace!r}?)"
                )
            time.sleep(POLL_S)

    def wait_until_converged(
        self, level: int, tolerance: float, timeout: float = 10.0, settle_samples: int = 1
    ) -> float:
        """Waits until ``level``'s (0-based) transition is over and its task
        error norm ‖x̃‖ is ≤ ``tolerance`` in ``settle_samples`` telemetry
        samples in a row; returns the last norm. Call it after
        :meth:`wait_until_accepted` (before, the old goal may count). Raises
        ValueError for a level the controller does not have, TimeoutError
        after ``timeout`` s."""
        deadline = time.monotonic() + timeout
        last = float("nan")
        below = 0
        seen: int | None = None
        while True:
            t = self._poll_telemetry()
            if t is not None and t.header.seq != seen:
                seen = t.header.seq
                if level >= t.levels():
                    raise ValueError(
                        f"level {level} does not exist (the controller has {t.levels()})"
                    )
                last = t.error_norm(level)
                done = t.transition_progress[level] >= 1.0 and last <= tolerance
                below = below + 1 if done else 0
                if below >= settle_samples:
                    return last
            if time.monotonic() >= deadline:
                raise TimeoutError(
                    f"level {level} did not converge to {tolerance} within {timeout:.1f} s "
                    f"(error {last:.3e})"
                )
            time.sleep(POLL_S)

    def _poll_telemetry(self) -> Telemetry | None:
        newest = ipc.receive_latest(self._telemetry, Telemetry)
        if newest is not None:
            self._last_telemetry = newest
        return self._last_telemetry


def _gain_dim(values: Any) -> int:
    """m of a gain given as m diagonal values or an m×m matrix (nested rows)."""
    shape = getattr(values, "shape", None)
    if shape is not None:
        return int(shape[0])
    values = list(values)
    return len(values)


class SampleStream:
    """One level's path sent sample by sample as it is produced — a
    teleoperation device, a learned policy (docs/tracking.md, "Samples"). A
    sample is a knot with its velocity and acceleration in the level's
    goal-velocity coordinates (a position's rates; an orientation's ω and ω̇
    in the base frame); t is in s of the path's own time, from 0 at the first
    sample, which must be at the level's equilibrium.

    The controller interpolates with exactly these derivatives and needs one
    sample ahead of where the path is: stamp each sample a lead (a few
    control periods, more on a loaded host) ahead of the path. A stream that
    stops comes to rest on its last sample and is over (counted as a stopped
    path); begin a new stream then.

    The first sample is held and goes with the second, which begins the
    path (a path of one knot would be over as soon as its time passed) and
    waits for the answer; later samples are sent one message each without
    waiting, and a refusal of any of them raises :class:`KnotsRefused` at the
    next :meth:`send` or :meth:`check`."""

    def __init__(self, client: "Client", level: int, start_at_state_seq: int = 0, timeout: float = 2.0) -> None:
        self._client = client
        self.level: int = level
        self._start_at = start_at_state_seq
        self._timeout = timeout
        self._times: list[float] = []
        self._seqs: dict[int, int] = {}
        self._rejected_before = 0
        self._first: PathKnots | None = None

    @property
    def sent(self) -> int:
        """Samples handed to :meth:`send` so far (the first is sent with the second)."""
        return len(self._times)

    def send(
        self,
        t: float,
        values: Sequence[float],
        velocity: Sequence[float],
        acceleration: Sequence[float],
    ) -> None:
        """Sends one sample (the first with the second, which begins the
        path and waits for its answer)."""
        self.check()
        k = len(self._times)
        times = self._times + [float(t)]
        # The first sample waits in the message that begins the path.
        msg = self._first if k == 1 and self._first is not None else PathKnots.zeroed()
        msg.level = self.level
        msg.flags = PATH_NEW if k <= 1 else PATH_EXTEND
        msg.apply_at_state_seq = self._start_at
        try:
            msg.push_sample(t, values, velocity, acceleration)
        except Exception as e:
            raise KnotsRefused(k, k, times, e, k) from e
        found, at = msg.check_knot()
        if found is not None:
            knot = k if at is None else k - (msg.count - 1) + at
            raise KnotsRefused(k, k, times, SetpointError(found, str(found)), knot)
        self._times.append(float(t))
        if k == 0:
            self._first = msg
            return
        seq = self._client._send_path(msg)
        self._seqs[seq] = k
        if k == 1:
            self._first = None
            try:
                answer = self._client.wait_until_accepted(seq, self._timeout)
            except SetpointRejected as e:
                self._times.clear()
                knot = e.answer.refused_knot()
                raise KnotsRefused(0, 1, times, e, knot) from e
            self._rejected_before = answer.rejected

    def check(self) -> None:
        """Raises :class:`KnotsRefused` if the controller refused a sample sent so far."""
        if not self._seqs:
            return
        t = self._client._poll_telemetry()
        answer = t.answer_for(self._client._client_id) if t is not None else None
        if answer is None or answer.rejected <= self._rejected_before:
            return
        self._rejected_before = answer.rejected
        copy = SetpointAnswer.from_buffer_copy(answer)
        k = self._seqs.get(int(answer.seq)) if answer.code != ANSWER_ACCEPTED else None
        if k is None:
            # A later sample was answered since: the refused one is not known.
            last = len(self._times) - 1
            raise KnotsRefused(0, last, self._times, SetpointError(None, "a sample was refused"))
        raise KnotsRefused(k, k, self._times, SetpointRejected(copy), k)
