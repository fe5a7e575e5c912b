//! The scenario service (`hcc/<ns>/scenario`): the controller publishes the
//! [`ScenarioDoc`] it runs once, as a JSON byte slice; the service keeps the
//! last sample (history 1), which iceoryx2 hands to a subscriber that
//! connects later when the publisher updates its connections — the
//! controller's connection upkeep does, off the torque path. Publish-subscribe
//! rather than request-response: the document is written once and read by
//! any number of tools, from one sample in shared memory, with no server
//! loop to answer them; a blackboard holds only fixed-size values.

use std::time::{Duration, Instant};

use iceoryx2::port::publisher::Publisher;
use iceoryx2::port::update_connections::{ConnectionFailure, UpdateConnections};
use iceoryx2::prelude::*;
use iceoryx2::service::builder::publish_subscribe::PublishSubscribeOpenError;

use super::error::IpcError;
use super::node::{Ipc, IpcNode};
use super::settings::MAX_NODES;
use crate::scenario::{MAX_SCENARIO_DOC_BYTES, ScenarioDoc, ScenarioDocError};
use crate::service::ServiceNames;

/// Tools that may read the scenario at once.
pub const MAX_SCENARIO_SUBSCRIBERS: usize = 8;

fn builder<'a>(
    node: &'a IpcNode,
    name: &'a ServiceName,
) -> iceoryx2::service::builder::publish_subscribe::Builder<[u8], (), Ipc> {
    node.service_builder(name)
        .publish_subscribe::<[u8]>()
        .max_publishers(1)
        .max_subscribers(MAX_SCENARIO_SUBSCRIBERS)
        .max_nodes(MAX_NODES)
        .history_size(1)
        .subscriber_max_buffer_size(1)
}

/// The controller's side: publishes its document once and hands it to tools
/// that connect later on every [`UpdateConnections::update_connections`].
pub struct ScenarioPublisher {
    publisher: Publisher<Ipc, [u8], ()>,
    // Keeps the service while the publisher lives.
    _service: iceoryx2::service::port_factory::publish_subscribe::PortFactory<Ipc, [u8], ()>,
}

impl std::fmt::Debug for ScenarioPublisher {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("ScenarioPublisher").finish_non_exhaustive()
    }
}

impl ScenarioPublisher {
    /// Creates the service of `names` and publishes `doc` (at start-up; allocates).
    pub fn publish(
        node: &IpcNode,
        names: &ServiceNames,
        doc: &ScenarioDoc,
    ) -> Result<ScenarioPublisher, IpcError> {
        let service = names.scenario();
        let err = |reason: String| IpcError::Service {
            service: service.to_owned(),
            reason,
        };
        let bytes = doc.to_json();
        if bytes.len() > MAX_SCENARIO_DOC_BYTES {
            return Err(err(format!(
                "the scenario document has {} bytes, more than {MAX_SCENARIO_DOC_BYTES}",
                bytes.len()
            )));
        }
        let name = ServiceName::new(service).map_err(|e| err(format!("invalid name ({e:?})")))?;
        let factory = builder(node, &name)
            .open_or_create()
            .map_err(|e| err(format!("{e:?}")))?;
        let publisher = factory
            .publisher_builder()
            .initial_max_slice_len(bytes.len().max(1))
            .create()
            .map_err(|e| IpcError::Port {
                service: service.to_owned(),
                port: "publisher",
                reason: format!("{e:?} (is another controller running in this namespace?)"),
            })?;
        let sample = publisher
            .loan_slice_uninit(bytes.len())
            .map_err(|e| err(format!("loan: {e:?}")))?;
        sample
            .write_from_slice(&bytes)
            .send()
            .map_err(|e| err(format!("send: {e:?}")))?;
        Ok(ScenarioPublisher {
            publisher,
            _service: factory,
        })
    }
}

impl UpdateConnections for ScenarioPublisher {
    fn update_connections(&self) -> Result<(), ConnectionFailure> {
        self.publisher.update_connections()
    }
}

/// Why the scenario of a namespace could not be read.
#[derive(Debug, thiserror::Error)]
pub enum ScenarioReadError {
    /// No controller runs in the namespace (none publishes telemetry).
    #[error(
        "no controller runs in namespace {namespace:?} (no telemetry service, no scenario service): start `hcc run` or `hcc-controller` there, or pass --config"
    )]
    NoController { namespace: String },
    /// A controller runs (its telemetry service exists) but publishes no
    /// scenario: one older than the service.
    #[error(
        "the controller in namespace {namespace:?} publishes no scenario: it is older than this tool (it has no scenario service); pass --config"
    )]
    OlderController { namespace: String },
    /// The service exists but nothing came within the timeout.
    #[error(
        "the controller in namespace {namespace:?} did not hand over its scenario within {timeout:?}; pass --config"
    )]
    Timeout {
        namespace: String,
        timeout: Duration,
    },
    /// The document is of another version or unreadable.
    #[error(transparent)]
    Doc(#[from] ScenarioDocError),
    /// An iceoryx2 failure.
    #[error("{0}")]
    Ipc(String),
}

/// Reads the scenario the controller of `names` publishes, waiting up to
/// `timeout` for a starting controller to create the service and hand the
/// document over (at start-up; allocates).
pub fn read_scenario(
    node: &IpcNode,
    names: &ServiceNames,
    timeout: Duration,
) -> Result<ScenarioDoc, ScenarioReadError> {
    let namespace = names.namespace().to_string();
    let name =
        ServiceName::new(names.scenario()).map_err(|e| ScenarioReadError::Ipc(format!("{e:?}")))?;
    let deadline = Instant::now() + timeout;
    // A controller that is starting may not have created the service yet.
    let factory = loop {
        match builder(node, &name).open() {
            Ok(f) => break f,
            Err(PublishSubscribeOpenError::DoesNotExist) if Instant::now() < deadline => {
                std::thread::sleep(Duration::from_millis(10));
            }
            Err(PublishSubscribeOpenError::DoesNotExist) => {
                return Err(if controller_attached(node, names) {
                    ScenarioReadError::OlderController { namespace }
                } else {
                    ScenarioReadError::NoController { namespace }
                });
            }
            Err(e) => {
                return Err(ScenarioReadError::Ipc(format!(
                    "{}: {e:?}",
                    names.scenario()
                )));
            }
        }
    };
    let subscriber = factory
        .subscriber_builder()
        .create()
        .map_err(|e| ScenarioReadError::Ipc(format!("{}: {e:?}", names.scenario())))?;
    loop {
        match subscriber.receive() {
            Ok(Some(sample)) => return Ok(ScenarioDoc::from_json(sample.payload())?),
            Ok(None) => {}
            Err(e) => return Err(ScenarioReadError::Ipc(format!("{e:?}"))),
        }
        if Instant::now() >= deadline {
            return Err(ScenarioReadError::Timeout { namespace, timeout });
        }
        std::thread::sleep(Duration::from_millis(2));
    }
}

/// Whether a live node named `hcc-controller` is attached to the
/// namespace's telemetry service (a controller runs there; a tool that
/// opened the services itself is not one).
fn controller_attached(node: &IpcNode, names: &ServiceNames) -> bool {
    use iceoryx2::node::{NodeState, NodeView};
    let Ok(telemetry) = ServiceName::new(names.telemetry()) else {
        return false;
    };
    let Ok(Some(details)) = <Ipc as iceoryx2::service::Service>::details(
        &telemetry,
        node.config(),
        MessagingPattern::PublishSubscribe,
    ) else {
        return false;
    };
    details.dynamic_details.is_some_and(|d| {
        d.nodes.iter().any(|n| match n {
            NodeState::Alive(view) => view
                .details()
                .as_ref()
                .is_some_and(|d| d.name().as_str() == CONTROLLER_NODE),
            _ => false,
        })
    })
}

/// The node name of the controller daemon (`hcc-controller`).
pub const CONTROLLER_NODE: &str = "hcc-controller";

/// [`read_scenario`] through a node of its own (named `tool`, with the
/// peers' `file_prefix`), for a tool that has none.
pub fn read_scenario_as(
    tool: &str,
    names: &ServiceNames,
    file_prefix: Option<&str>,
    timeout: Duration,
) -> Result<ScenarioDoc, ScenarioReadError> {
    let node = super::node::create_node(tool, SignalHandlingMode::Disabled, file_prefix)
        .map_err(|e| ScenarioReadError::Ipc(e.to_string()))?;
    read_scenario(&node, names, timeout)
}
