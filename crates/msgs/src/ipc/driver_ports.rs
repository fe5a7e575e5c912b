//! The ports of a robot driver, and the ports whose connections its loop keeps
//! up to date.

use iceoryx2::port::update_connections::UpdateConnections;

use super::error::IpcError;
use super::events::{EventListener, EventNotifier};
use super::pubsub::{CommandSubscriber, StatePublisher};
use super::services::Services;
use super::settings::LATEST_BUFFER;

/// The ports of a robot driver (the simulated robot of `hcc-sim`, a real
/// driver): it publishes joint states and notifies `state_ready`, it receives
/// torque commands (newest kept, [`LATEST_BUFFER`]) and listens to `command_ready`.
pub struct DriverPorts {
    /// Publisher of the joint states.
    pub states: StatePublisher,
    /// Notifier of `state_ready`.
    pub state_ready: EventNotifier,
    /// Subscriber of the torque commands.
    pub commands: CommandSubscriber,
    /// Listener of `command_ready`.
    pub command_ready: EventListener,
}

impl DriverPorts {
    /// Creates the driver's ports on the opened services (keep `services`
    /// alive while the ports are used).
    pub fn open(services: &Services) -> Result<DriverPorts, IpcError> {
        Ok(DriverPorts {
            states: services.joint_state_publisher()?,
            state_ready: services.state_ready_notifier()?,
            commands: services.torque_command_subscriber(LATEST_BUFFER)?,
            command_ready: services.command_ready_listener()?,
        })
    }

    /// The ports whose connections to new or departed peers a driver's loop
    /// updates while it waits (`hcc_rt::ConnectionUpkeep`): the publisher,
    /// the notifier and the subscriber (a listener has no connections).
    pub fn connections(&self) -> [&dyn UpdateConnections; 3] {
        [&self.states, &self.state_ready, &self.commands]
    }
}
