//! Opening the contract's iceoryx2 services exactly as every peer must.
//!
//! The creator of an iceoryx2 service fixes its capacities, and an opener's
//! values are minimum requirements; a peer that asks for more fails to
//! connect. So every peer of one robot — the controller daemon, the plant
//! simulator, a real robot driver, the `hcc run` recorder — opens the services
//! through this module, with the same settings:
//!
//! | service          | payload           | publishers | subscribers | buffer (max) | history | overflow |
//! |------------------|-------------------|-----------:|------------:|-------------:|--------:|----------|
//! | `joint_state`    | [`JointState`]    | 1          | [`MAX_STATE_SUBSCRIBERS`] | [`MAX_SUBSCRIBER_BUFFER`] | 0 | safe (newest wins) |
//! | `torque_command` | [`TorqueCommand`] | 1          | [`MAX_COMMAND_SUBSCRIBERS`] | [`MAX_SUBSCRIBER_BUFFER`] | 0 | safe |
//! | `telemetry`      | [`Telemetry`]     | 1          | [`MAX_TELEMETRY_SUBSCRIBERS`] | [`MAX_SUBSCRIBER_BUFFER`] | 0 | safe |
//! | `setpoint`       | [`Setpoint`]      | [`MAX_SETPOINT_PUBLISHERS`] | [`MAX_SETPOINT_SUBSCRIBERS`] | [`MAX_SUBSCRIBER_BUFFER`] | 0 | safe |
//! | `state_ready`, `command_ready` (events) | — | [`MAX_NOTIFIERS`] notifiers | [`MAX_LISTENERS`] listeners | | | |
//!
//! `max_publishers(1)` on `torque_command` is the guard of the torque channel:
//! a second controller in the same namespace cannot create a publisher
//! ("torque_command already has a publisher"). The same holds for
//! `joint_state` (one robot per namespace) and `telemetry`. `setpoint` is
//! the one service with several publishers: up to [`MAX_SETPOINT_PUBLISHERS`]
//! clients (an application, `hcc goal`, a scheduler) may command one
//! controller at once; the controller subscribes with a queue of
//! [`SETPOINT_BUFFER`] and takes every queued setpoint each cycle.
//!
//! Publishers never block ([`BackpressureStrategy::DiscardData`] with safe
//! overflow): a slow or absent subscriber loses its oldest samples and never
//! stalls the control loop. Control-loop subscribers use a buffer of
//! [`LATEST_BUFFER`] and keep the newest sample; recorders use
//! [`MAX_SUBSCRIBER_BUFFER`] and read often enough not to lose samples.
//!
//! # Files
//!
//! With the `ipc` service type iceoryx2 creates shared-memory segments and
//! small bookkeeping files. Their names start with a file prefix (iceoryx2's
//! default `iox2_`); [`create_node`] takes an optional own prefix so that
//! tests, or two independent systems on one host, never see each other's
//! files. All peers of one robot must use the same prefix (and namespace).
//! [`FILE_PREFIX_ENV`] carries it to child processes. iceoryx2 removes a node's
//! files when the node is dropped, and those of crashed processes when the
//! next node is created or with [`cleanup_dead_nodes`]; only one small
//! `*global_mgmt` segment per prefix stays by design ([`leftover_files`]).
//!
//! Everything here runs at start-up and allocates; the ports it returns are
//! used in the loop (`receive`, `notify`, `timed_wait` do not allocate;
//! `loan` allocates one small block in iceoryx2 0.10, which the daemons serve
//! from a real-time pool).
//!
//! # Layout
//!
//! One job per file, each building on those above it:
//! - `settings`: the capacities and queues of the table above;
//! - `error`: [`IpcError`];
//! - `node`: the iceoryx2 configuration with the file prefix, and the node;
//! - `pubsub`: the typed publishers and subscribers, and how they are created;
//! - `events`: the event ports and the precise wait [`wait_for_event_until`];
//! - `preloan`: samples loaned ahead of time, [`PreLoan`];
//! - `cleanup`: what crashed processes leave behind, [`leftover_files`];
//! - `services`: the six services of a namespace, [`Services`];
//! - `driver_ports`: the ports of a robot driver, [`DriverPorts`];
//! - `tap`: a namespace's streams for a tool that listens, [`Tap`].
//!
//! [`JointState`]: crate::JointState
//! [`TorqueCommand`]: crate::TorqueCommand
//! [`Telemetry`]: crate::Telemetry
//! [`Setpoint`]: crate::Setpoint
//! [`BackpressureStrategy::DiscardData`]: iceoryx2::prelude::BackpressureStrategy::DiscardData

mod cleanup;
mod driver_ports;
mod error;
mod events;
mod node;
mod preloan;
mod pubsub;
mod recorder_progress;
mod scenario;
mod services;
mod settings;
mod tap;
#[cfg(test)]
mod testing;

pub use cleanup::{CleanupReport, LeftoverFile, cleanup_dead_nodes, leftover_files};
pub use driver_ports::DriverPorts;
pub use error::IpcError;
pub use events::{EventListener, EventNotifier, wait_for_event_until};
pub use node::{FILE_PREFIX_ENV, Ipc, IpcNode, config, create_node, file_prefix_from_env};
pub use preloan::PreLoan;
pub use pubsub::{
    CommandPublisher, CommandSubscriber, LoadPublisher, LoadSubscriber, PathPublisher,
    PathSubscriber, SetpointPublisher, SetpointSubscriber, StatePublisher, StateSample,
    StateSubscriber, TelemetryPublisher, TelemetrySubscriber,
};
pub use recorder_progress::{RECORDER_LEAD, RecorderProgressPublisher, RecorderProgressSubscriber};
pub use scenario::{
    CONTROLLER_NODE, MAX_SCENARIO_SUBSCRIBERS, ScenarioPublisher, ScenarioReadError, read_scenario,
    read_scenario_as,
};
pub use services::Services;
pub use settings::{
    EVENT_ID_MAX, LATEST_BUFFER, MAX_BORROWED_SAMPLES, MAX_COMMAND_SUBSCRIBERS, MAX_LISTENERS,
    MAX_LOANED_SAMPLES, MAX_NODES, MAX_NOTIFIERS, MAX_SETPOINT_PUBLISHERS,
    MAX_SETPOINT_SUBSCRIBERS, MAX_STATE_SUBSCRIBERS, MAX_SUBSCRIBER_BUFFER,
    MAX_TELEMETRY_SUBSCRIBERS, SETPOINT_BUFFER,
};
pub use tap::{StreamCounts, TAP_BURST, Tap, TapCounts, TapNode, TapStreams, Tapped};

/// `update_connections` of iceoryx2's ports (see `hcc_rt::ConnectionUpkeep`).
pub use iceoryx2::port::update_connections::{ConnectionFailure, UpdateConnections};
