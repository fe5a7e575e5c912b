//! The typed publishers and subscribers of the contract's messages, and how a
//! port is created: publishers that never block, subscribers with a bounded
//! queue.

use std::fmt::Debug;

use iceoryx2::port::publisher::{Publisher, PublisherCreateError};
use iceoryx2::port::subscriber::{Subscriber, SubscriberCreateError};
use iceoryx2::prelude::*;
use iceoryx2::service::port_factory::publish_subscribe;

use super::error::IpcError;
use super::node::Ipc;
use super::settings::{MAX_LOANED_SAMPLES, MAX_SUBSCRIBER_BUFFER};
use crate::setpoint::Setpoint;
use crate::types::{JointState, TorqueCommand};
use crate::{LoadSetpoint, PathKnots, Telemetry};

/// Publisher of [`JointState`] (driver/simulator).
pub type StatePublisher = Publisher<Ipc, JointState, ()>;
/// Subscriber of [`JointState`].
pub type StateSubscriber = Subscriber<Ipc, JointState, ()>;
/// A received [`JointState`], read in place in shared memory (released on drop).
pub type StateSample = iceoryx2::sample::Sample<Ipc, JointState, ()>;
/// Publisher of [`TorqueCommand`] (controller).
pub type CommandPublisher = Publisher<Ipc, TorqueCommand, ()>;
/// Subscriber of [`TorqueCommand`].
pub type CommandSubscriber = Subscriber<Ipc, TorqueCommand, ()>;
/// Publisher of [`Setpoint`] (a client).
pub type SetpointPublisher = Publisher<Ipc, Setpoint, ()>;
/// Subscriber of [`Setpoint`] (the controller).
pub type SetpointSubscriber = Subscriber<Ipc, Setpoint, ()>;
/// Publisher of [`PathKnots`] (a client).
pub type PathPublisher = Publisher<Ipc, PathKnots, ()>;
/// Subscriber of [`PathKnots`] (the controller).
pub type PathSubscriber = Subscriber<Ipc, PathKnots, ()>;
/// Publisher of [`LoadSetpoint`] (a client).
pub type LoadPublisher = Publisher<Ipc, LoadSetpoint, ()>;
/// Subscriber of [`LoadSetpoint`] (the controller).
pub type LoadSubscriber = Subscriber<Ipc, LoadSetpoint, ()>;
/// Publisher of [`Telemetry`] (controller).
pub type TelemetryPublisher = Publisher<Ipc, Telemetry, ()>;
/// Subscriber of [`Telemetry`].
pub type TelemetrySubscriber = Subscriber<Ipc, Telemetry, ()>;

/// A publisher of `service` (`role` names its kind of peer in errors) that never
/// blocks: a slow subscriber loses its oldest samples.
pub(super) fn publisher<T: Debug + ZeroCopySend>(
    factory: &publish_subscribe::PortFactory<Ipc, T, ()>,
    service: &str,
    role: &str,
) -> Result<Publisher<Ipc, T, ()>, IpcError> {
    factory
        .publisher_builder()
        .max_loaned_samples(MAX_LOANED_SAMPLES)
        .backpressure_strategy(BackpressureStrategy::DiscardData)
        .create()
        .map_err(|e| IpcError::Port {
            service: service.to_owned(),
            port: "publisher",
            reason: match e {
                PublisherCreateError::ExceedsMaxSupportedPublishers => {
                    let short = service.rsplit('/').next().unwrap_or(service);
                    match factory.static_config().max_publishers() {
                        1 => format!(
                            "{short} already has a publisher (is another {role} running in this namespace?)"
                        ),
                        max => format!(
                            "{short} already has {max} publishers, the most it allows (too many {role}s in this namespace)"
                        ),
                    }
                }
                other => format!("iceoryx2 failure {other:?}"),
            },
        })
}

/// A subscriber of `service` with a queue of `buffer` samples (clamped to
/// 1..=[`MAX_SUBSCRIBER_BUFFER`]).
pub(super) fn subscriber<T: Debug + ZeroCopySend>(
    factory: &publish_subscribe::PortFactory<Ipc, T, ()>,
    service: &str,
    buffer: usize,
) -> Result<Subscriber<Ipc, T, ()>, IpcError> {
    factory
        .subscriber_builder()
        .buffer_size(buffer.clamp(1, MAX_SUBSCRIBER_BUFFER))
        .create()
        .map_err(|e| IpcError::Port {
            service: service.to_owned(),
            port: "subscriber",
            reason: match e {
                SubscriberCreateError::ExceedsMaxSupportedSubscribers => {
                    "it already has the maximum number of subscribers".to_owned()
                }
                other => format!("iceoryx2 failure {other:?}"),
            },
        })
}
