//! The capacities and queues every peer opens the services with (the table of
//! the module documentation): an opener's values are minimum requirements, so
//! all peers must use these.

/// Subscribers of `joint_state`: controller, recorder, two spare (monitors).
pub const MAX_STATE_SUBSCRIBERS: usize = 4;
/// Subscribers of `torque_command`: driver, recorder, two spare.
pub const MAX_COMMAND_SUBSCRIBERS: usize = 4;
/// Subscribers of `telemetry`: recorders and monitors.
pub const MAX_TELEMETRY_SUBSCRIBERS: usize = 4;
/// Clients that may publish setpoints to one controller at once (a user's
/// application, a scheduler and two command-line tools). A further client
/// gets "it already has the maximum number of publishers".
pub const MAX_SETPOINT_PUBLISHERS: usize = 4;
/// Subscribers of `setpoint`: the controller, a recorder, two spare.
pub const MAX_SETPOINT_SUBSCRIBERS: usize = 4;
/// Queue of the controller's setpoint subscriber: enough for every client to
/// send a few setpoints per cycle; with safe overflow a flood loses its
/// oldest setpoints (never answered), never stalls a client.
pub const SETPOINT_BUFFER: usize = 16;
/// Largest subscriber queue a service supports (a recorder's buffer).
pub const MAX_SUBSCRIBER_BUFFER: usize = 128;
/// Queue of a control-loop subscriber: it drains the queue every cycle and
/// keeps the newest sample.
pub const LATEST_BUFFER: usize = 2;
/// Samples a subscriber may hold at once (drop them promptly).
pub const MAX_BORROWED_SAMPLES: usize = 2;
/// Samples a publisher may have loaned at once.
pub const MAX_LOANED_SAMPLES: usize = 2;
/// Nodes that may open one service.
pub const MAX_NODES: usize = 16;
/// Notifiers per event service.
pub const MAX_NOTIFIERS: usize = 2;
/// Listeners per event service.
pub const MAX_LISTENERS: usize = 4;
/// Largest event id of the event services.
pub const EVENT_ID_MAX: usize = 4;
