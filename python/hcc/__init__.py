"""Python side of the hcc controller's message contract.

* :mod:`hcc.msgs`: ctypes mirrors of the wire types (same layout and
  iceoryx2 type names as the Rust crate ``hcc-msgs``).
* :mod:`hcc.ipc`: the services and their settings.
* :class:`hcc.Driver`: the driver side of the contract (which command may be
  applied; hold, fallback, stop) for drivers written in Python.
* :class:`hcc.Client`: reads the controller's telemetry and the joint states,
  sets goals and gains at run time (setpoints) and waits for their answers.
* :mod:`hcc.remote`: the same from another host, over Zenoh through
  ``hcc bridge`` (``from hcc.remote import Client``).
* :mod:`hcc.mujoco`: a plant driver on the MuJoCo physics engine
  (``python -m hcc.mujoco``).
"""

from .client import Client, KnotsRefused, SampleStream, SetpointRejected, new_client_id
from .driver import Action, CommandRejection, Driver, DriverSettings, Offer, StopReason
from .msgs import (
    ANSWER_ACCEPTED,
    CLIENT_SCHEMA_VERSION,
    COMMAND_FLAG_GRAVITY_INCLUDED,
    DRIVER_SCHEMA_VERSION,
    MAX_JOINTS,
    MAX_LEVELS,
    MAX_PENDING_SETPOINTS,
    MAX_SETPOINT_CLIENTS,
    MAX_KNOTS_PER_MESSAGE,
    MAX_TASK_DIM,
    NO_KNOT,
    PATH_DERIVATIVES,
    PATH_EXTEND,
    PATH_NEW,
    SETPOINT_DAMPING,
    SETPOINT_GOAL,
    SETPOINT_STIFFNESS,
    SETPOINT_VELOCITY,
    STATE_FLAG_DRIVER_GRAVITY_COMPENSATION,
    STATE_FLAG_DRIVER_POLLS_COMMANDS,
    TELEMETRY_FLAG_CONTACT,
    TELEMETRY_FLAG_CONTACT_HOLD,
    TELEMETRY_FLAG_PEER_LOST,
    CommandMode,
    DriverStatus,
    Header,
    JointState,
    MsgError,
    PathKnots,
    PathRejection,
    Setpoint,
    SetpointAnswer,
    SetpointError,
    SetpointRejection,
    Telemetry,
    TelemetryCounters,
    TelemetryTimings,
    TorqueCommand,
)

__all__ = [
    "ANSWER_ACCEPTED",
    "Action",
    "Client",
    "CLIENT_SCHEMA_VERSION",
    "COMMAND_FLAG_GRAVITY_INCLUDED",
    "DRIVER_SCHEMA_VERSION",
    "CommandMode",
    "Driver",
    "DriverSettings",
    "DriverStatus",
    "Header",
    "JointState",
    "MAX_JOINTS",
    "MAX_LEVELS",
    "MAX_PENDING_SETPOINTS",
    "MAX_SETPOINT_CLIENTS",
    "MAX_KNOTS_PER_MESSAGE",
    "MAX_TASK_DIM",
    "KnotsRefused",
    "SampleStream",
    "MsgError",
    "NO_KNOT",
    "PATH_DERIVATIVES",
    "PATH_EXTEND",
    "PATH_NEW",
    "PathKnots",
    "PathRejection",
    "Offer",
    "CommandRejection",
    "SETPOINT_DAMPING",
    "SETPOINT_GOAL",
    "SETPOINT_STIFFNESS",
    "SETPOINT_VELOCITY",
    "Setpoint",
    "SetpointAnswer",
    "SetpointError",
    "SetpointRejected",
    "SetpointRejection",
    "STATE_FLAG_DRIVER_GRAVITY_COMPENSATION",
    "STATE_FLAG_DRIVER_POLLS_COMMANDS",
    "StopReason",
    "TELEMETRY_FLAG_CONTACT",
    "TELEMETRY_FLAG_CONTACT_HOLD",
    "TELEMETRY_FLAG_PEER_LOST",
    "Telemetry",
    "TelemetryCounters",
    "TelemetryTimings",
    "TorqueCommand",
    "new_client_id",
]
