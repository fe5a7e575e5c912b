"""Opening the contract's iceoryx2 services exactly as the Rust peers do.

The creator of an iceoryx2 service fixes its capacities and an opener's
values are minimum requirements, so every peer of one robot opens the
services with the same settings (mirror of ``hcc_msgs::ipc``):

================  ===============  ===========  ===========================  ======
service           payload          publishers   subscribers                  buffer
================  ===============  ===========  ===========================  ======
joint_state       JointState       1            MAX_STATE_SUBSCRIBERS        128
torque_command    TorqueCommand    1            MAX_COMMAND_SUBSCRIBERS      128
telemetry         Telemetry        1            MAX_TELEMETRY_SUBSCRIBERS    128
setpoint          Setpoint         4 (clients)  MAX_SETPOINT_SUBSCRIBERS     128
path              PathKnots        4 (clients)  MAX_SETPOINT_SUBSCRIBERS     128
load              LoadSetpoint     4 (clients)  MAX_SETPOINT_SUBSCRIBERS     128
state_ready       event            2 notifiers  4 listeners
command_ready     event            2 notifiers  4 listeners
scenario          bytes (JSON)     1            MAX_SCENARIO_SUBSCRIBERS     1
================  ===============  ===========  ===========================  ======

``scenario`` keeps its one sample (history 1): the controller publishes the
scenario it runs once, and a tool that connects later reads it
(:func:`read_scenario`). The others: history 0, safe overflow (the newest sample wins), publishers discard data
instead of blocking. ``setpoint``, ``path`` and ``load`` are the services with several
publishers: up to :data:`MAX_SETPOINT_PUBLISHERS` clients may command one
controller at once; the controller reads every queued setpoint and path
message each cycle.
"""

from __future__ import annotations

import ctypes
import json
import os
import re
import time
from dataclasses import dataclass
from typing import Any

import iceoryx2 as iox2

from .msgs import JointState, LoadSetpoint, PathKnots, Setpoint, Telemetry, TorqueCommand

#: Prefix of all hcc service names.
SERVICE_PREFIX: str = "hcc"
#: Maximum namespace length.
MAX_NAMESPACE_LEN: int = 64
#: Subscribers of joint_state: controller, recorder, two spare.
MAX_STATE_SUBSCRIBERS: int = 4
#: Subscribers of torque_command: driver, recorder, two spare.
MAX_COMMAND_SUBSCRIBERS: int = 4
#: Subscribers of telemetry.
MAX_TELEMETRY_SUBSCRIBERS: int = 4
#: Clients that may publish setpoints to one controller at once.
MAX_SETPOINT_PUBLISHERS: int = 4
#: Subscribers of setpoint: the controller, a recorder, two spare.
MAX_SETPOINT_SUBSCRIBERS: int = 4
#: Queue of the controller's setpoint subscriber.
SETPOINT_BUFFER: int = 16
#: Largest subscriber queue a service supports.
MAX_SUBSCRIBER_BUFFER: int = 128
#: Queue of a control-loop subscriber (drains every cycle, keeps the newest).
LATEST_BUFFER: int = 2
#: Samples a subscriber may hold at once.
MAX_BORROWED_SAMPLES: int = 2
#: Samples a publisher may have loaned at once.
MAX_LOANED_SAMPLES: int = 2
#: Nodes that may open one service.
MAX_NODES: int = 16
#: Notifiers per event service.
MAX_NOTIFIERS: int = 2
#: Listeners per event service.
MAX_LISTENERS: int = 4
#: Largest event id of the event services.
EVENT_ID_MAX: int = 4
#: Event id the driver notifies on state_ready after publishing a state.
EVENT_STATE_PUBLISHED: int = 1
#: Event id the controller notifies on command_ready after publishing a command.
EVENT_COMMAND_PUBLISHED: int = 2
#: Tools that may read the scenario service at once.
MAX_SCENARIO_SUBSCRIBERS: int = 8
#: Version of the scenario document (``hcc_msgs::scenario::SCENARIO_SCHEMA_VERSION``).
SCENARIO_SCHEMA_VERSION: int = 1
#: Environment variable carrying the shared-memory file prefix to peers.
FILE_PREFIX_ENV: str = "HCC_IPC_FILE_PREFIX"

_NAMESPACE = re.compile(r"^[A-Za-z0-9_][A-Za-z0-9_-]{0,63}$")


class IpcError(RuntimeError):
    """A service or port could not be opened (the text names it and why)."""


def validate_namespace(namespace: str) -> None:
    """Checks a namespace: 1-64 characters of ``[A-Za-z0-9_-]``, no leading '-'."""
    if not _NAMESPACE.match(namespace):
        raise ValueError(
            f"namespace {namespace!r} is invalid: use 1 to {MAX_NAMESPACE_LEN} "
            "characters of [A-Za-z0-9_-], not starting with '-'"
        )


@dataclass(frozen=True)
class ServiceNames:
    """The names of all services of one namespace."""

    namespace: str

    def __post_init__(self) -> None:
        validate_namespace(self.namespace)

    def _name(self, leaf: str) -> str:
        return f"{SERVICE_PREFIX}/{self.namespace}/{leaf}"

    @property
    def joint_state(self) -> str:
        """Publish-subscribe service of JointState (driver → controller)."""
        return self._name("joint_state")

    @property
    def torque_command(self) -> str:
        """Publish-subscribe service of TorqueCommand (controller → driver)."""
        return self._name("torque_command")

    @property
    def telemetry(self) -> str:
        """Publish-subscribe service of Telemetry (controller → loggers)."""
        return self._name("telemetry")

    @property
    def setpoint(self) -> str:
        """Publish-subscribe service of Setpoint (clients → controller)."""
        return self._name("setpoint")

    @property
    def path(self) -> str:
        """Publish-subscribe service of :class:`~hcc.msgs.PathKnots` (clients → controller)."""
        return self._name("path")

    @property
    def load(self) -> str:
        """Publish-subscribe service of :class:`~hcc.msgs.LoadSetpoint` (clients → controller)."""
        return self._name("load")

    @property
    def state_ready(self) -> str:
        """Event service the driver notifies with EVENT_STATE_PUBLISHED."""
        return self._name("state_ready")

    @property
    def command_ready(self) -> str:
        """Event service the controller notifies with EVENT_COMMAND_PUBLISHED."""
        return self._name("command_ready")

    @property
    def scenario(self) -> str:
        """Publish-subscribe service of the controller's scenario document (JSON bytes)."""
        return self._name("scenario")


def create_node(name: str, file_prefix: str | None = None) -> Any:
    """Creates an iceoryx2 node; ``file_prefix`` defaults to $HCC_IPC_FILE_PREFIX.

    Signal handling is disabled (the process handles SIGINT/SIGTERM itself).
    """
    prefix = file_prefix if file_prefix is not None else os.environ.get(FILE_PREFIX_ENV) or None
    config = iox2.config.default()
    if prefix is not None:
        if not re.fullmatch(r"[A-Za-z0-9_-]{1,32}", prefix):
            raise IpcError(
                f"ipc file prefix {prefix!r} is invalid: use 1 to 32 characters of [A-Za-z0-9_-]"
            )
        config.global_cfg.prefix = iox2.FileName.new(prefix)
    try:
        return (
            iox2.NodeBuilder.new()
            .name(iox2.NodeName.new(name))
            .config(config)
            .signal_handling_mode(iox2.SignalHandlingMode.Disabled)
            .create(iox2.ServiceType.Ipc)
        )
    except Exception as e:  # iceoryx2 raises its own exception types
        raise IpcError(f"ipc node {name!r}: {e!r}") from e


def _pubsub(
    node: Any, name: str, payload: type, max_subscribers: int, max_publishers: int = 1
) -> Any:
    try:
        return (
            node.service_builder(iox2.ServiceName.new(name))
            .publish_subscribe(payload)
            .max_publishers(max_publishers)
            .max_subscribers(max_subscribers)
            .max_nodes(MAX_NODES)
            .history_size(0)
            .subscriber_max_buffer_size(MAX_SUBSCRIBER_BUFFER)
            .subscriber_max_borrowed_samples(MAX_BORROWED_SAMPLES)
            .enable_safe_overflow(True)
            .open_or_create()
        )
    except Exception as e:
        raise IpcError(f"service {name!r}: {e!r}") from e


#: The node name of the controller daemon (``hcc_msgs::ipc::CONTROLLER_NODE``).
CONTROLLER_NODE: str = "hcc-controller"


def _controller_attached(node: Any, names: ServiceNames) -> bool:
    """Whether a live node named ``hcc-controller`` is attached to the
    namespace's telemetry service (a controller runs there; a client that
    opened the services itself is not one)."""
    details = iox2.Service.details(
        iox2.ServiceName.new(names.telemetry),
        node.config,
        iox2.MessagingPattern.PublishSubscribe,
        iox2.ServiceType.Ipc,
    )
    if details is None:
        return False
    for state in details.nodes():
        if isinstance(state, iox2.NodeState.Alive):
            view = state[0]
            if view.details is not None and view.details.name.as_str() == CONTROLLER_NODE:
                return True
    return False


class ScenarioUnavailable(IpcError):
    """No scenario could be read from the namespace (the text says why)."""


def read_scenario(node: Any, names: ServiceNames, timeout: float = 2.0) -> dict[str, Any]:
    """The scenario the controller of ``names`` runs, from its scenario service
    (``hcc_msgs::ipc::read_scenario``): a dict with ``version``, ``name``,
    ``namespace``, ``rate_hz``, ``path``, ``toml``, ``urdf_path``, ``urdf``,
    ``levels`` (each ``name``, ``tasks``, ``dim``) and ``joints`` (each
    ``name``, ``lower``, ``upper``, ``velocity``, ``effort``; None where the
    URDF sets no limit). Raises :class:`ScenarioUnavailable` when no
    controller publishes one (not running, or older than this client), when
    none comes within ``timeout`` s, or for another document version."""
    ns = names.namespace
    deadline = time.monotonic() + timeout
    # A controller that is starting may not have created the service yet.
    while True:
        try:
            service = (
                node.service_builder(iox2.ServiceName.new(names.scenario))
                .publish_subscribe(iox2.Slice[ctypes.c_uint8])
                .max_publishers(1)
                .max_subscribers(MAX_SCENARIO_SUBSCRIBERS)
                .max_nodes(MAX_NODES)
                .history_size(1)
                .subscriber_max_buffer_size(1)
                .open()
            )
            break
        except Exception as e:
            if "DoesNotExist" not in repr(e):
                raise ScenarioUnavailable(f"scenario service of {ns!r}: {e!r}") from e
            if time.monotonic() < deadline:
                time.sleep(0.01)
                continue
            if _controller_attached(node, names):
                raise ScenarioUnavailable(
                    f"the controller in namespace {ns!r} publishes no scenario: it is older "
                    "than this client (it has no scenario service); pass the scenario file"
                ) from e
            raise ScenarioUnavailable(
                f"no controller runs in namespace {ns!r} (no telemetry service, no scenario "
                "service): start hcc run or hcc-controller there, or pass the scenario file"
            ) from e
    subscriber = service.subscriber_builder().create()
    try:
        while True:
            sample = subscriber.receive()
            if sample is not None:
                data = bytes(sample.payload().as_memory_view())
                sample.delete()
                break
            if time.monotonic() >= deadline:
                raise ScenarioUnavailable(
                    f"the controller in namespace {ns!r} did not hand over its scenario "
                    f"within {timeout} s"
                )
            time.sleep(0.002)
    finally:
        subscriber.delete()
    doc: dict[str, Any] = json.loads(data)
    if doc.get("version") != SCENARIO_SCHEMA_VERSION:
        raise ScenarioUnavailable(
            f"the controller publishes scenario document version {doc.get('version')}, "
            f"this client reads version {SCENARIO_SCHEMA_VERSION}: use the client of the "
            "controller's release, or pass the scenario file"
        )
    return doc


def _event(node: Any, name: str) -> Any:
    try:
        return (
            node.service_builder(iox2.ServiceName.new(name))
            .event()
            .max_notifiers(MAX_NOTIFIERS)
            .max_listeners(MAX_LISTENERS)
            .max_nodes(MAX_NODES)
            .event_id_max_value(EVENT_ID_MAX)
            .open_or_create()
        )
    except Exception as e:
        raise IpcError(f"service {name!r}: {e!r}") from e


class Services:
    """The six services of one namespace, opened with the contract's settings."""

    def __init__(self, node: Any, names: ServiceNames) -> None:
        self.names = names
        self.joint_state = _pubsub(node, names.joint_state, JointState, MAX_STATE_SUBSCRIBERS)
        self.torque_command = _pubsub(
            node, names.torque_command, TorqueCommand, MAX_COMMAND_SUBSCRIBERS
        )
        self.telemetry = _pubsub(node, names.telemetry, Telemetry, MAX_TELEMETRY_SUBSCRIBERS)
        self.setpoint = _pubsub(
            node, names.setpoint, Setpoint, MAX_SETPOINT_SUBSCRIBERS, MAX_SETPOINT_PUBLISHERS
        )
        self.path = _pubsub(
            node, names.path, PathKnots, MAX_SETPOINT_SUBSCRIBERS, MAX_SETPOINT_PUBLISHERS
        )
        self.load = _pubsub(
            node, names.load, LoadSetpoint, MAX_SETPOINT_SUBSCRIBERS, MAX_SETPOINT_PUBLISHERS
        )
        self.state_ready = _event(node, names.state_ready)
        self.command_ready = _event(node, names.command_ready)

    @staticmethod
    def _port(what: str, service: str, build: Any) -> Any:
        try:
            return build()
        except Exception as e:
            raise IpcError(f"service {service!r}: cannot create a {what}: {e!r}") from e

    def publisher(self, which: str) -> Any:
        """A publisher of ``which``: the single one of joint_state,
        torque_command or telemetry, or one of the setpoint clients."""
        factory = getattr(self, which)
        limit = (
            f"({which} allows {MAX_SETPOINT_PUBLISHERS} clients at once)"
            if which in ("setpoint", "path", "load")
            else "(is another peer publishing in this namespace?)"
        )
        return self._port(
            f"publisher {limit}",
            getattr(self.names, which),
            lambda: factory.publisher_builder()
            .max_loaned_samples(MAX_LOANED_SAMPLES)
            .backpressure_strategy(iox2.BackpressureStrategy.DiscardData)
            .create(),
        )

    def subscriber(self, which: str, buffer: int) -> Any:
        """A subscriber of ``which`` with a queue of ``buffer`` samples (clamped)."""
        factory = getattr(self, which)
        size = max(1, min(buffer, MAX_SUBSCRIBER_BUFFER))
        return self._port(
            "subscriber",
            getattr(self.names, which),
            lambda: factory.subscriber_builder().buffer_size(size).create(),
        )

    def notifier(self, which: str, event_id: int) -> Any:
        """A notifier of ``which`` (state_ready or command_ready)."""
        factory = getattr(self, which)
        return self._port(
            "notifier",
            getattr(self.names, which),
            lambda: factory.notifier_builder()
            .default_event_id(iox2.EventId.new(event_id))
            .create(),
        )

    def listener(self, which: str) -> Any:
        """A listener of ``which`` (state_ready or command_ready)."""
        factory = getattr(self, which)
        return self._port(
            "listener", getattr(self.names, which), lambda: factory.listener_builder().create()
        )


def receive_latest(subscriber: Any, payload: type) -> Any | None:
    """Drains ``subscriber`` and returns a copy of its newest sample (or None)."""
    newest = None
    while True:
        sample = subscriber.receive()
        if sample is None:
            return newest
        newest = payload.from_buffer_copy(sample.payload().contents)
        sample.delete()


def receive_all(subscriber: Any, payload: type) -> list[Any]:
    """Drains ``subscriber``, returning copies of all queued samples, oldest first."""
    out = []
    while True:
        sample = subscriber.receive()
        if sample is None:
            return out
        out.append(payload.from_buffer_copy(sample.payload().contents))
        sample.delete()
