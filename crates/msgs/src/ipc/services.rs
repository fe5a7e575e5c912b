//! Service set-up: the six services of a namespace, opened (or created) with
//! the contract's settings, and the ports each peer takes from them.

use std::fmt::Debug;

use iceoryx2::prelude::*;
use iceoryx2::service::builder::event::{EventCreateError, EventOpenError, EventOpenOrCreateError};
use iceoryx2::service::builder::publish_subscribe::{
    PublishSubscribeCreateError, PublishSubscribeOpenError, PublishSubscribeOpenOrCreateError,
};
use iceoryx2::service::port_factory::{event, publish_subscribe};

use super::error::IpcError;
use super::events::{EventListener, EventNotifier, listener, notifier};
use super::node::{Ipc, IpcNode};
use super::pubsub::{
    CommandPublisher, CommandSubscriber, LoadPublisher, LoadSubscriber, PathPublisher,
    PathSubscriber, SetpointPublisher, SetpointSubscriber, StatePublisher, StateSubscriber,
    TelemetryPublisher, TelemetrySubscriber, publisher, subscriber,
};
use super::settings::{
    EVENT_ID_MAX, MAX_BORROWED_SAMPLES, MAX_COMMAND_SUBSCRIBERS, MAX_LISTENERS, MAX_NODES,
    MAX_NOTIFIERS, MAX_SETPOINT_PUBLISHERS, MAX_SETPOINT_SUBSCRIBERS, MAX_STATE_SUBSCRIBERS,
    MAX_SUBSCRIBER_BUFFER, MAX_TELEMETRY_SUBSCRIBERS,
};
use crate::service::{EVENT_COMMAND_PUBLISHED, EVENT_STATE_PUBLISHED, ServiceNames};
use crate::setpoint::Setpoint;
use crate::types::{JointState, TorqueCommand};
use crate::{LoadSetpoint, PathKnots, Telemetry};

fn pubsub_open_reason(e: PublishSubscribeOpenError) -> String {
    use PublishSubscribeOpenError as E;
    match e {
        E::VersionMismatch => "peer built with a different iceoryx2 version".into(),
        E::IncompatibleTypes => {
            "schema mismatch: the peer uses a different message type or hcc-msgs schema version"
                .into()
        }
        E::IncompatibleMessagingPattern => {
            "a service of another kind (not publish-subscribe) uses this name".into()
        }
        E::IncompatibleOverflowBehavior => {
            "the peer created it without safe overflow (not an hcc peer?)".into()
        }
        E::DoesNotSupportRequestedAmountOfPublishers
        | E::DoesNotSupportRequestedAmountOfSubscribers
        | E::DoesNotSupportRequestedAmountOfNodes
        | E::DoesNotSupportRequestedMinBufferSize
        | E::DoesNotSupportRequestedMinHistorySize
        | E::DoesNotSupportRequestedMinSubscriberBorrowedSamples => format!(
            "the peer created it with smaller capacities ({e:?}); peers must open the services through hcc_msgs::ipc"
        ),
        E::ExceedsMaxNumberOfNodes => "too many processes have opened it".into(),
        E::InsufficientPermissions => {
            "insufficient permissions (peers must run as the same user)".into()
        }
        E::IsMarkedForDestruction => "it is being removed; retry".into(),
        E::DoesNotExist => "it does not exist".into(),
        other => format!("iceoryx2 failure {other:?}"),
    }
}

fn pubsub_reason(e: PublishSubscribeOpenOrCreateError) -> String {
    match e {
        PublishSubscribeOpenOrCreateError::PublishSubscribeOpenError(e) => pubsub_open_reason(e),
        PublishSubscribeOpenOrCreateError::PublishSubscribeCreateError(e) => match e {
            PublishSubscribeCreateError::InsufficientPermissions => {
                "insufficient permissions to create it".into()
            }
            other => format!("cannot create it: iceoryx2 failure {other:?}"),
        },
        PublishSubscribeOpenOrCreateError::SystemInFlux => {
            "it is being created and removed repeatedly by another process".into()
        }
    }
}

fn event_reason(e: EventOpenOrCreateError) -> String {
    match e {
        EventOpenOrCreateError::EventOpenError(e) => match e {
            EventOpenError::VersionMismatch => {
                "peer built with a different iceoryx2 version".into()
            }
            EventOpenError::IncompatibleMessagingPattern => {
                "a service of another kind (not an event) uses this name".into()
            }
            EventOpenError::InsufficientPermissions => {
                "insufficient permissions (peers must run as the same user)".into()
            }
            other => format!("iceoryx2 failure {other:?}"),
        },
        EventOpenOrCreateError::EventCreateError(e) => match e {
            EventCreateError::InsufficientPermissions => {
                "insufficient permissions to create it".into()
            }
            other => format!("cannot create it: iceoryx2 failure {other:?}"),
        },
        EventOpenOrCreateError::SystemInFlux => {
            "it is being created and removed repeatedly by another process".into()
        }
    }
}

fn open_pubsub<T: Debug + ZeroCopySend>(
    node: &IpcNode,
    name: &str,
    max_publishers: usize,
    max_subscribers: usize,
) -> Result<publish_subscribe::PortFactory<Ipc, T, ()>, IpcError> {
    let err = |reason: String| IpcError::Service {
        service: name.to_owned(),
        reason,
    };
    let service_name = ServiceName::new(name).map_err(|e| err(format!("invalid name ({e:?})")))?;
    node.service_builder(&service_name)
        .publish_subscribe::<T>()
        .max_publishers(max_publishers)
        .max_subscribers(max_subscribers)
        .max_nodes(MAX_NODES)
        .history_size(0)
        .subscriber_max_buffer_size(MAX_SUBSCRIBER_BUFFER)
        .subscriber_max_borrowed_samples(MAX_BORROWED_SAMPLES)
        .enable_safe_overflow(true)
        .open_or_create()
        .map_err(|e| err(pubsub_reason(e)))
}

fn open_event(
    node: &IpcNode,
    name: &str,
    default_event: usize,
) -> Result<event::PortFactory<Ipc>, IpcError> {
    let err = |reason: String| IpcError::Service {
        service: name.to_owned(),
        reason,
    };
    let service_name = ServiceName::new(name).map_err(|e| err(format!("invalid name ({e:?})")))?;
    debug_assert!(default_event <= EVENT_ID_MAX);
    node.service_builder(&service_name)
        .event()
        .max_notifiers(MAX_NOTIFIERS)
        .max_listeners(MAX_LISTENERS)
        .max_nodes(MAX_NODES)
        .event_id_max_value(EVENT_ID_MAX)
        .open_or_create()
        .map_err(|e| err(event_reason(e)))
}

/// The seven services of one namespace, opened (or created) with the contract's settings.
pub struct Services {
    names: ServiceNames,
    joint_state: publish_subscribe::PortFactory<Ipc, JointState, ()>,
    torque_command: publish_subscribe::PortFactory<Ipc, TorqueCommand, ()>,
    telemetry: publish_subscribe::PortFactory<Ipc, Telemetry, ()>,
    setpoint: publish_subscribe::PortFactory<Ipc, Setpoint, ()>,
    path: publish_subscribe::PortFactory<Ipc, PathKnots, ()>,
    load: publish_subscribe::PortFactory<Ipc, LoadSetpoint, ()>,
    state_ready: event::PortFactory<Ipc>,
    command_ready: event::PortFactory<Ipc>,
}

impl Debug for Services {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Services")
            .field("names", &self.names)
            .finish_non_exhaustive()
    }
}

impl Services {
    /// Opens (or creates) all services of `names` on `node`.
    pub fn open(node: &IpcNode, names: &ServiceNames) -> Result<Services, IpcError> {
        Ok(Services {
            joint_state: open_pubsub(node, names.joint_state(), 1, MAX_STATE_SUBSCRIBERS)?,
            torque_command: open_pubsub(node, names.torque_command(), 1, MAX_COMMAND_SUBSCRIBERS)?,
            telemetry: open_pubsub(node, names.telemetry(), 1, MAX_TELEMETRY_SUBSCRIBERS)?,
            setpoint: open_pubsub(
                node,
                names.setpoint(),
                MAX_SETPOINT_PUBLISHERS,
                MAX_SETPOINT_SUBSCRIBERS,
            )?,
            path: open_pubsub(
                node,
                names.path(),
                MAX_SETPOINT_PUBLISHERS,
                MAX_SETPOINT_SUBSCRIBERS,
            )?,
            load: open_pubsub(
                node,
                names.load(),
                MAX_SETPOINT_PUBLISHERS,
                MAX_SETPOINT_SUBSCRIBERS,
            )?,
            state_ready: open_event(node, names.state_ready(), EVENT_STATE_PUBLISHED)?,
            command_ready: open_event(node, names.command_ready(), EVENT_COMMAND_PUBLISHED)?,
            names: names.clone(),
        })
    }

    /// The service names.
    pub fn names(&self) -> &ServiceNames {
        &self.names
    }

    /// The single publisher of joint states (the driver or simulator).
    pub fn joint_state_publisher(&self) -> Result<StatePublisher, IpcError> {
        publisher(&self.joint_state, self.names.joint_state(), "driver")
    }

    /// A joint-state subscriber with a queue of `buffer` samples (clamped to
    /// 1..=[`MAX_SUBSCRIBER_BUFFER`]).
    pub fn joint_state_subscriber(&self, buffer: usize) -> Result<StateSubscriber, IpcError> {
        subscriber(&self.joint_state, self.names.joint_state(), buffer)
    }

    /// The single publisher of torque commands (the controller).
    pub fn torque_command_publisher(&self) -> Result<CommandPublisher, IpcError> {
        publisher(
            &self.torque_command,
            self.names.torque_command(),
            "controller",
        )
    }

    /// A torque-command subscriber with a queue of `buffer` samples.
    pub fn torque_command_subscriber(&self, buffer: usize) -> Result<CommandSubscriber, IpcError> {
        subscriber(&self.torque_command, self.names.torque_command(), buffer)
    }

    /// The single publisher of telemetry (the controller).
    pub fn telemetry_publisher(&self) -> Result<TelemetryPublisher, IpcError> {
        publisher(&self.telemetry, self.names.telemetry(), "controller")
    }

    /// A telemetry subscriber with a queue of `buffer` samples.
    pub fn telemetry_subscriber(&self, buffer: usize) -> Result<TelemetrySubscriber, IpcError> {
        subscriber(&self.telemetry, self.names.telemetry(), buffer)
    }

    /// A setpoint publisher (a client; up to [`MAX_SETPOINT_PUBLISHERS`] at once).
    pub fn setpoint_publisher(&self) -> Result<SetpointPublisher, IpcError> {
        publisher(&self.setpoint, self.names.setpoint(), "client")
    }

    /// A setpoint subscriber with a queue of `buffer` samples (the controller
    /// uses [`SETPOINT_BUFFER`]).
    ///
    /// [`SETPOINT_BUFFER`]: super::SETPOINT_BUFFER
    pub fn setpoint_subscriber(&self, buffer: usize) -> Result<SetpointSubscriber, IpcError> {
        subscriber(&self.setpoint, self.names.setpoint(), buffer)
    }

    /// A path publisher (a client; up to [`MAX_SETPOINT_PUBLISHERS`] at once).
    pub fn path_publisher(&self) -> Result<PathPublisher, IpcError> {
        publisher(&self.path, self.names.path(), "client")
    }

    /// A load publisher (a client; up to [`MAX_SETPOINT_PUBLISHERS`] at once).
    pub fn load_publisher(&self) -> Result<LoadPublisher, IpcError> {
        publisher(&self.load, self.names.load(), "client")
    }

    /// A load subscriber with a queue of `buffer` samples (the controller).
    pub fn load_subscriber(&self, buffer: usize) -> Result<LoadSubscriber, IpcError> {
        subscriber(&self.load, self.names.load(), buffer)
    }

    /// A path subscriber with a queue of `buffer` samples (the controller
    /// uses [`SETPOINT_BUFFER`]).
    ///
    /// [`SETPOINT_BUFFER`]: super::SETPOINT_BUFFER
    pub fn path_subscriber(&self, buffer: usize) -> Result<PathSubscriber, IpcError> {
        subscriber(&self.path, self.names.path(), buffer)
    }

    /// Notifier of `state_ready` (default event [`EVENT_STATE_PUBLISHED`]).
    pub fn state_ready_notifier(&self) -> Result<EventNotifier, IpcError> {
        notifier(
            &self.state_ready,
            self.names.state_ready(),
            EVENT_STATE_PUBLISHED,
        )
    }

    /// Listener of `state_ready`.
    pub fn state_ready_listener(&self) -> Result<EventListener, IpcError> {
        listener(&self.state_ready, self.names.state_ready())
    }

    /// Notifier of `command_ready` (default event [`EVENT_COMMAND_PUBLISHED`]).
    pub fn command_ready_notifier(&self) -> Result<EventNotifier, IpcError> {
        notifier(
            &self.command_ready,
            self.names.command_ready(),
            EVENT_COMMAND_PUBLISHED,
        )
    }

    /// Listener of `command_ready`.
    pub fn command_ready_listener(&self) -> Result<EventListener, IpcError> {
        listener(&self.command_ready, self.names.command_ready())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::Namespace;
    use crate::ipc::cleanup::{cleanup_dead_nodes, leftover_files};
    use crate::ipc::node::create_node;
    use crate::ipc::settings::{LATEST_BUFFER, SETPOINT_BUFFER};
    use crate::ipc::testing::{remove_global_mgmt, unique_prefix};

    #[test]
    fn services_round_trip_and_guard_the_torque_channel() {
        let prefix = unique_prefix("ipc");
        {
            let names = ServiceNames::for_namespace(Namespace::unique("ipc_test").unwrap());
            let node =
                create_node("hcc-msgs-test", SignalHandlingMode::Disabled, Some(&prefix)).unwrap();
            let services = Services::open(&node, &names).unwrap();
            // A second opener (another process in practice) gets the same services.
            let other = Services::open(&node, &names).unwrap();

            let state_pub = services.joint_state_publisher().unwrap();
            let state_sub = other.joint_state_subscriber(LATEST_BUFFER).unwrap();
            let notifier = services.state_ready_notifier().unwrap();
            let listener = other.state_ready_listener().unwrap();
            let command_pub = services.torque_command_publisher().unwrap();
            let command_sub = other
                .torque_command_subscriber(MAX_SUBSCRIBER_BUFFER)
                .unwrap();
            let _telemetry_pub = services.telemetry_publisher().unwrap();
            let _t1 = other.telemetry_subscriber(16).unwrap();
            let _t2 = other.telemetry_subscriber(16).unwrap();

            // The guarded torque channel: a second publisher is refused.
            let second = other.torque_command_publisher().unwrap_err();
            assert!(
                second
                    .to_string()
                    .contains("torque_command already has a publisher"),
                "{second}"
            );
            let second = other.joint_state_publisher().unwrap_err();
            assert!(
                second
                    .to_string()
                    .contains("joint_state already has a publisher"),
                "{second}"
            );

            let mut s = JointState::zeroed();
            s.header.seq = 7;
            s.set_joints(&[0.5, 1.0], &[0.0; 2], &[0.0; 2]).unwrap();
            state_pub.send_copy(s).unwrap();
            notifier.notify().unwrap();
            let mut events = 0;
            listener
                .timed_wait(
                    |a| {
                        assert_eq!(a.id, EventId::new(EVENT_STATE_PUBLISHED));
                        events += 1;
                    },
                    std::time::Duration::from_secs(1),
                )
                .unwrap();
            assert_eq!(events, 1);
            let got = *state_sub.receive().unwrap().unwrap();
            assert_eq!(got.q(), &[0.5, 1.0]);

            // Safe overflow: a slow subscriber keeps the newest samples, the publisher never blocks.
            for k in 0..10u64 {
                let mut c = TorqueCommand::zeroed();
                c.header.seq = k;
                command_pub.send_copy(c).unwrap();
            }
            let mut seqs = Vec::new();
            while let Some(c) = command_sub.receive().unwrap() {
                seqs.push(c.header.seq);
            }
            assert_eq!(seqs, (0..10).collect::<Vec<_>>());

            // Setpoints: several clients publish, the controller receives all of them.
            let setpoint_sub = services.setpoint_subscriber(SETPOINT_BUFFER).unwrap();
            let clients: Vec<_> = (0..MAX_SETPOINT_PUBLISHERS)
                .map(|_| other.setpoint_publisher().unwrap())
                .collect();
            let extra = services.setpoint_publisher().unwrap_err();
            assert!(
                extra
                    .to_string()
                    .contains("setpoint already has 4 publishers, the most it allows"),
                "{extra}"
            );
            for (id, client) in clients.iter().enumerate() {
                let mut sp = crate::Setpoint::zeroed();
                sp.client_id = id as u64 + 100;
                sp.header.seq = 1;
                sp.fields = crate::SETPOINT_GOAL;
                sp.dim = 1;
                client.send_copy(sp).unwrap();
            }
            let mut ids = Vec::new();
            while let Some(sp) = setpoint_sub.receive().unwrap() {
                assert_eq!(sp.validate(), Ok(()));
                ids.push(sp.client_id);
            }
            ids.sort_unstable();
            assert_eq!(ids, [100, 101, 102, 103]);
            drop(clients);
            // A client that leaves frees its place.
            let _again = services.setpoint_publisher().unwrap();

            let report = cleanup_dead_nodes(Some(&prefix)).unwrap();
            assert_eq!(report.alive, 1, "{report:?}");
            assert_eq!(report.dead, 0, "{report:?}");
            assert!(!leftover_files(&prefix).unwrap().is_empty());

            // A peer with another payload type under the same name: schema mismatch.
            let wrong = open_pubsub::<TorqueCommand>(&node, names.joint_state(), 1, 4).unwrap_err();
            assert!(wrong.to_string().contains("schema mismatch"), "{wrong}");
            assert!(wrong.to_string().contains("joint_state"), "{wrong}");
        }
        let rest = remove_global_mgmt(&prefix);
        assert!(rest.is_empty(), "files left behind: {rest:?}");
    }
}
