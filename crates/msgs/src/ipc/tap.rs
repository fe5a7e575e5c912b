//! The tap: one listener of a namespace's streams for every tool that reads
//! them without taking part in the loop (the recorder, the live view, the
//! bridge). It subscribes with the largest queues the services allow
//! ([`MAX_SUBSCRIBER_BUFFER`] samples of each loop stream, [`SETPOINT_BUFFER`]
//! of each client stream), empties them on each [`Tap::drain`] and hands every
//! sample on in the contract's order: the client's messages first (a client
//! numbers its setpoints, path and load messages together, so they go on in
//! that order across the three queues), then the joint states, the torque
//! commands and the telemetry (a command or telemetry sample always follows
//! the state and the messages its cycle took). It checks each loop stream's
//! sequence numbers as it goes: the samples a full queue lost before the tap
//! read them are counted as gaps, and a source that numbers from the start
//! again (a restarted driver or controller) is counted and followed
//! ([`TapCounts`]).
//!
//! A tap never makes a publisher wait (the services' overflow is safe), so a
//! slow tool loses samples, counted, and never slows the loop. It copies the
//! client messages out while it orders them (a subscriber may hold only a
//! few samples at once), so it allocates: it is not for a real-time loop.

use super::{
    CommandSubscriber, IpcError, IpcNode, LoadSubscriber, MAX_SUBSCRIBER_BUFFER, PathSubscriber,
    SETPOINT_BUFFER, Services, SetpointSubscriber, StateSubscriber, TelemetrySubscriber,
};
use crate::{
    ClientMessage, JointState, LoadSetpoint, PathKnots, SeqEvent, SequenceChecker, Setpoint,
    Telemetry, TorqueCommand,
};

/// A drain that found this many samples in one queue should be followed by
/// another at once (the queue may have overflowed meanwhile).
pub const TAP_BURST: usize = MAX_SUBSCRIBER_BUFFER / 2;

/// One sample as the tap read it (borrowed from shared memory until the
/// callback returns).
#[derive(Debug, Clone, Copy)]
pub enum Tapped<'a> {
    /// A joint state (driver → controller).
    State(&'a JointState),
    /// A torque command (controller → driver).
    Command(&'a TorqueCommand),
    /// A telemetry sample (controller → tools).
    Telemetry(&'a Telemetry),
    /// A client's setpoint.
    Setpoint(&'a Setpoint),
    /// A client's path message.
    Path(&'a PathKnots),
    /// A client's load message.
    Load(&'a LoadSetpoint),
}

/// Which streams a tap subscribes to.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum TapStreams {
    /// The loop's: joint states, torque commands, telemetry.
    Loop,
    /// The loop's and the clients' (setpoints, paths, loads).
    All,
}

/// One loop stream's counts.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct StreamCounts {
    /// Samples read.
    pub received: u64,
    /// Samples lost before the tap read them (sequence gaps).
    pub missed: u64,
    /// Times the source numbered from the start again (a restart).
    pub restarts: u64,
}

/// What a tap has read and lost so far.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct TapCounts {
    /// The joint states.
    pub joint_state: StreamCounts,
    /// The torque commands.
    pub torque_command: StreamCounts,
    /// The telemetry.
    pub telemetry: StreamCounts,
    /// The clients' messages read (setpoints, paths, loads).
    pub client_messages: u64,
}

impl TapCounts {
    /// Samples lost on the three loop streams.
    pub fn missed(&self) -> u64 {
        self.joint_state.missed + self.torque_command.missed + self.telemetry.missed
    }
}

/// The clients' subscribers.
struct ClientPorts {
    setpoints: SetpointSubscriber,
    paths: PathSubscriber,
    loads: LoadSubscriber,
}

/// A client's message as a tapped sample.
fn tapped(m: &ClientMessage) -> Tapped<'_> {
    match m {
        ClientMessage::Setpoint(s) => Tapped::Setpoint(s),
        ClientMessage::Path(p) => Tapped::Path(p),
        ClientMessage::Load(l) => Tapped::Load(l),
    }
}

/// A namespace's streams, subscribed (module docs).
pub struct Tap {
    states: StateSubscriber,
    commands: CommandSubscriber,
    telemetry: TelemetrySubscriber,
    client: Option<ClientPorts>,
    /// The sequence checks of the states, commands and telemetry.
    checkers: [SequenceChecker; 3],
    counts: TapCounts,
    /// The last joint state's sequence number + 1 (0 before any).
    states_taken: u64,
}

/// Why a queue could not be read.
fn receive_error(service: &str, e: impl std::fmt::Debug) -> IpcError {
    IpcError::Receive {
        service: service.into(),
        reason: format!("{e:?}"),
    }
}

/// Empties one loop stream's queue (`service`): checks each sample's
/// sequence number into `counts` and hands it to `each` (`tapped`: its
/// number and the sample as tapped). Returns how many it read and the last
/// one's number.
fn drain_loop<T: std::fmt::Debug + iceoryx2::prelude::ZeroCopySend>(
    port: &iceoryx2::port::subscriber::Subscriber<super::Ipc, T, ()>,
    service: &str,
    (checker, counts): (&mut SequenceChecker, &mut StreamCounts),
    each: &mut dyn FnMut(Tapped<'_>),
    tapped: impl for<'a> Fn(&'a T) -> (u64, Tapped<'a>),
) -> Result<(usize, Option<u64>), IpcError> {
    let (mut k, mut last) = (0, None);
    while let Some(sample) = port.receive().map_err(|e| receive_error(service, e))? {
        let (seq, m) = tapped(&sample);
        check(checker, counts, seq);
        each(m);
        k += 1;
        last = Some(seq);
    }
    Ok((k, last))
}

/// Counts one loop sample's sequence number into `counts`.
fn check(checker: &mut SequenceChecker, counts: &mut StreamCounts, seq: u64) {
    counts.received += 1;
    let restarts = checker.restarts();
    if let SeqEvent::Gap { missed } = checker.observe_restarting(seq) {
        counts.missed += missed;
    }
    counts.restarts += checker.restarts() - restarts;
}

impl Tap {
    /// Subscribes to `streams` of the services `services` opened.
    pub fn open(services: &Services, streams: TapStreams) -> Result<Tap, IpcError> {
        let client = match streams {
            TapStreams::Loop => None,
            TapStreams::All => Some(ClientPorts {
                setpoints: services.setpoint_subscriber(SETPOINT_BUFFER)?,
                paths: services.path_subscriber(SETPOINT_BUFFER)?,
                loads: services.load_subscriber(SETPOINT_BUFFER)?,
            }),
        };
        Ok(Tap {
            states: services.joint_state_subscriber(MAX_SUBSCRIBER_BUFFER)?,
            commands: services.torque_command_subscriber(MAX_SUBSCRIBER_BUFFER)?,
            telemetry: services.telemetry_subscriber(MAX_SUBSCRIBER_BUFFER)?,
            client,
            checkers: Default::default(),
            counts: TapCounts::default(),
            states_taken: 0,
        })
    }

    /// Empties every queue once and hands each sample to `each` in the
    /// contract's order (module docs). Returns the most samples one queue
    /// held: at [`TAP_BURST`] or more, drain again at once.
    pub fn drain(&mut self, each: &mut dyn FnMut(Tapped<'_>)) -> Result<usize, IpcError> {
        let mut most = 0;
        if let Some(c) = &self.client {
            let mut held = Vec::new();
            while let Some(s) = c
                .setpoints
                .receive()
                .map_err(|e| receive_error("setpoint", e))?
            {
                held.push(ClientMessage::Setpoint(Box::new(*s)));
            }
            while let Some(p) = c.paths.receive().map_err(|e| receive_error("path", e))? {
                held.push(ClientMessage::Path(Box::new(*p)));
            }
            while let Some(l) = c.loads.receive().map_err(|e| receive_error("load", e))? {
                held.push(ClientMessage::Load(Box::new(*l)));
            }
            // Copies (a subscriber may hold only a few samples out of shared
            // memory at once), ordered by the client's common sequence.
            held.sort_by_key(ClientMessage::seq);
            for m in &held {
                each(tapped(m));
            }
            self.counts.client_messages += held.len() as u64;
            most = held.len();
        }
        let [states, commands, telemetry] = &mut self.checkers;
        let c = &mut self.counts;
        let (s, last_state) = drain_loop(
            &self.states,
            "joint_state",
            (states, &mut c.joint_state),
            each,
            |s| (s.header.seq, Tapped::State(s)),
        )?;
        let (k, _) = drain_loop(
            &self.commands,
            "torque_command",
            (commands, &mut c.torque_command),
            each,
            |c| (c.header.seq, Tapped::Command(c)),
        )?;
        let (t, _) = drain_loop(
            &self.telemetry,
            "telemetry",
            (telemetry, &mut c.telemetry),
            each,
            |t| (t.header.seq, Tapped::Telemetry(t)),
        )?;
        if let Some(seq) = last_state {
            self.states_taken = seq + 1;
        }
        Ok(most.max(s).max(k).max(t))
    }

    /// The last joint state's sequence number + 1, as of the last drain (0
    /// before any): with every queue emptied by that drain, what a lockstep
    /// recorder publishes ([`super::RecorderProgressPublisher`]).
    pub fn states_taken(&self) -> u64 {
        self.states_taken
    }

    /// What the tap has read and lost so far.
    pub fn counts(&self) -> TapCounts {
        self.counts
    }
}

/// A tap with the node and the services it reads through: what a tool's
/// listening thread opens (the node is the thread's own; iceoryx2 ports stay
/// on the thread that made them). Dropped in order: the tap, the services,
/// the node.
pub struct TapNode {
    tap: Tap,
    /// The lockstep recorder's progress, once enabled.
    progress: Option<super::RecorderProgressPublisher>,
    names: crate::ServiceNames,
    _services: Services,
    node: IpcNode,
}

impl TapNode {
    /// Creates node `node_name` (file prefix `file_prefix`, no signal
    /// handling: the tool handles its signals), opens the services of
    /// `names` and taps `streams`.
    pub fn open(
        node_name: &str,
        file_prefix: Option<&str>,
        names: &crate::ServiceNames,
        streams: TapStreams,
    ) -> Result<TapNode, IpcError> {
        let node = super::create_node(
            node_name,
            iceoryx2::prelude::SignalHandlingMode::Disabled,
            file_prefix,
        )?;
        let services = Services::open(&node, names)?;
        let tap = Tap::open(&services, streams)?;
        Ok(TapNode {
            tap,
            progress: None,
            names: names.clone(),
            _services: services,
            node,
        })
    }

    /// The tap.
    pub fn tap(&mut self) -> &mut Tap {
        &mut self.tap
    }

    /// Publishes the tap's progress from now on ([`Self::publish_progress`]):
    /// the recorder of a lockstep run, which the simulator waits for
    /// ([`super::RecorderProgressPublisher`]).
    pub fn enable_progress(&mut self) -> Result<(), IpcError> {
        if self.progress.is_none() {
            self.progress = Some(super::RecorderProgressPublisher::open(
                &self.node,
                &self.names,
            )?);
        }
        Ok(())
    }

    /// Publishes [`Tap::states_taken`] when enabled: call it once the
    /// samples of a drain have been handed on.
    pub fn publish_progress(&mut self) -> Result<(), IpcError> {
        match &mut self.progress {
            Some(p) => p.publish(self.tap.states_taken()),
            None => Ok(()),
        }
    }
}
