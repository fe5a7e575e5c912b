"""Reading a running controller from Python: telemetry and joint states.

:class:`Client` opens the services of one namespace with the contract's
settings and subscribes to the controller's :class:`~hcc.msgs.Telemetry`
and the driver's :class:`~hcc.msgs.JointState`.

Not here yet: setting goals and gains, streaming setpoints and waiting until
a new goal is accepted. Those need a run-time setpoint service in the
contract, which does not exist yet; the client does not imitate it. Until
then, goals and gains come from the scenario file the controller was
started with.
"""

from __future__ import annotations

import time
from typing import Any, Iterator

from . import ipc
from .msgs import JointState, Telemetry

#: Polling interval of the iterators, s.
POLL_S: float = 0.0005


class Client:
    """Telemetry and joint states of the robot in ``namespace``.

    ``file_prefix``: the shared-memory file prefix of the peers (default:
    $HCC_IPC_FILE_PREFIX, else iceoryx2's default). ``buffer``: queue length
    of the subscribers (samples older than that are lost when not read in
    time). Use as a context manager or call :meth:`close`.
    """

    def __init__(
        self,
        namespace: str,
        *,
        file_prefix: str | None = None,
        buffer: int = ipc.MAX_SUBSCRIBER_BUFFER,
    ) -> None:
        self.names = ipc.ServiceNames(namespace)
        self._node = ipc.create_node("hcc-py-client", file_prefix)
        self._services = ipc.Services(self._node, self.names)
        self._telemetry = self._services.subscriber("telemetry", buffer)
        self._states = self._services.subscriber("joint_state", buffer)
        self._last_telemetry: Telemetry | None = None
        self._last_state: JointState | None = None

    def __enter__(self) -> "Client":
        return self

    def __exit__(self, *exc: Any) -> None:
        self.close()

    def close(self) -> None:
        """Releases the subscribers and the node."""
        for port in (self._telemetry, self._states):
            if port is not None:
                port.delete()
        self._telemetry = self._states = None
        self._services = None
        self._node = None

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

    def wait_converged(
        self, level: int, tolerance: float, timeout: float = 10.0, settle_samples: int = 1
    ) -> Telemetry:
        """Waits until the task error norm ‖x̃‖ of ``level`` (0-based) is below ``tolerance``.

        The error comes from the controller's telemetry; ``settle_samples``
        samples in a row must be below the tolerance. Returns the sample that
        completed the wait; raises TimeoutError after ``timeout`` s.
        """
        deadline = time.monotonic() + timeout
        below = 0
        last: Telemetry | None = None
        for t in self.telemetry(timeout=timeout):
            last = t
            if level >= t.levels():
                raise ValueError(f"level {level} does not exist (the controller has {t.levels()})")
            below = below + 1 if t.error_norm(level) < tolerance else 0
            if below >= settle_samples:
                return t
            if time.monotonic() >= deadline:
                break
        error = "no telemetry" if last is None else f"error norm {last.error_norm(level):.3g}"
        raise TimeoutError(
            f"level {level} not converged to {tolerance} within {timeout} s ({error})"
        )
