//! The recorder's progress (`hcc/<ns>/recorder_progress`), the flow control
//! of a lockstep run that is recorded: [`RecorderProgressPublisher`].

use iceoryx2::port::publisher::Publisher;
use iceoryx2::port::subscriber::Subscriber;
use iceoryx2::prelude::*;

use super::error::IpcError;
use super::node::{Ipc, IpcNode};
use super::settings::{MAX_NODES, MAX_SUBSCRIBER_BUFFER};
use crate::service::ServiceNames;

/// How many states the simulator of a lockstep run may publish beyond those
/// the recorder has taken: a quarter of the recorder's queues, leaving the
/// rest for the controller's stale-peer reports while the simulator waits.
pub const RECORDER_LEAD: u64 = MAX_SUBSCRIBER_BUFFER as u64 / 4;

type Factory = iceoryx2::service::port_factory::publish_subscribe::PortFactory<Ipc, u64, ()>;

fn open(node: &IpcNode, names: &ServiceNames) -> Result<Factory, IpcError> {
    let service = names.recorder_progress();
    let err = |reason: String| IpcError::Service {
        service: service.to_owned(),
        reason,
    };
    let name = ServiceName::new(service).map_err(|e| err(format!("invalid name ({e:?})")))?;
    node.service_builder(&name)
        .publish_subscribe::<u64>()
        .max_publishers(1)
        .max_subscribers(2)
        .max_nodes(MAX_NODES)
        .history_size(1)
        .subscriber_max_buffer_size(1)
        .enable_safe_overflow(true)
        .open_or_create()
        .map_err(|e| err(format!("{e:?}")))
}

fn port_error(service: &str, port: &'static str, e: impl std::fmt::Debug) -> IpcError {
    IpcError::Port {
        service: service.to_owned(),
        port,
        reason: format!("{e:?}"),
    }
}

/// The recorder's side of the flow control of a recorded lockstep run.
///
/// A tap never makes a publisher wait ([`super::Tap`]): a tool that
/// falls behind loses samples, counted. In a lockstep run the daemons turn
/// several times faster than real time, so the recorder's queues
/// ([`MAX_SUBSCRIBER_BUFFER`] samples) last a few tens of milliseconds, and a
/// stall of the recorder's thread that long on a loaded machine lost
/// samples — the oldest first, so the run's first cycle went missing
/// without a gap to show for it. A lockstep run is not bound to the clock,
/// so it waits instead: after each drain the recorder publishes how many
/// states it has taken (the newest state's sequence number + 1), and the
/// simulator does not publish state k while the recorder has taken fewer
/// than k − [`RECORDER_LEAD`] (`hcc-sim --lockstep-recorder`). Everything
/// the recorder has not taken then fits its queues: at most
/// [`RECORDER_LEAD`] + 1 states, commands and telemetry samples, plus the
/// controller's stale-peer reports while the simulator waits.
///
/// One value, the last one kept (history 1, a queue of one): the simulator
/// reads the newest on every wait.
pub struct RecorderProgressPublisher {
    publisher: Publisher<Ipc, u64, ()>,
    /// The last value published.
    published: Option<u64>,
    /// The service's name, for errors.
    service: String,
    _service: Factory,
}

impl RecorderProgressPublisher {
    /// Opens (or creates) the service of `names` and its publisher.
    pub fn open(node: &IpcNode, names: &ServiceNames) -> Result<Self, IpcError> {
        let service = open(node, names)?;
        let publisher = service
            .publisher_builder()
            .create()
            .map_err(|e| port_error(names.recorder_progress(), "publisher", e))?;
        Ok(RecorderProgressPublisher {
            publisher,
            published: None,
            service: names.recorder_progress().to_owned(),
            _service: service,
        })
    }

    /// Publishes `states_taken` (the newest state's seq + 1) if it changed.
    pub fn publish(&mut self, states_taken: u64) -> Result<(), IpcError> {
        if self.published == Some(states_taken) {
            return Ok(());
        }
        self.publisher
            .send_copy(states_taken)
            .map_err(|e| IpcError::Send {
                service: self.service.clone(),
                reason: format!("{e:?}"),
            })?;
        self.published = Some(states_taken);
        Ok(())
    }
}

/// The simulator's side ([`RecorderProgressPublisher`]).
pub struct RecorderProgressSubscriber {
    subscriber: Subscriber<Ipc, u64, ()>,
    /// The newest value read (0 before any).
    states_taken: u64,
    _service: Factory,
}

impl RecorderProgressSubscriber {
    /// Opens (or creates) the service of `names` and subscribes (at
    /// start-up; allocates).
    pub fn open(node: &IpcNode, names: &ServiceNames) -> Result<Self, IpcError> {
        let service = open(node, names)?;
        let subscriber = service
            .subscriber_builder()
            .buffer_size(1)
            .create()
            .map_err(|e| port_error(names.recorder_progress(), "subscriber", e))?;
        Ok(RecorderProgressSubscriber {
            subscriber,
            states_taken: 0,
            _service: service,
        })
    }

    /// The states the recorder has taken, as it last said (0 before it said
    /// anything). Allocation-free.
    pub fn states_taken(&mut self) -> u64 {
        while let Ok(Some(sample)) = self.subscriber.receive() {
            self.states_taken = *sample;
        }
        self.states_taken
    }
}

impl super::UpdateConnections for RecorderProgressPublisher {
    fn update_connections(&self) -> Result<(), super::ConnectionFailure> {
        self.publisher.update_connections()
    }
}
