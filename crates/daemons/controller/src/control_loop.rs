//! The controller's torque loop: the I/O shell around the control cycle
//! ([`hcc_cycle::ControlCycle`]) — wait for a joint state (per the wait
//! strategy), take the newest sample and the setpoints that came with it,
//! let the cycle answer it (stream checks → law τ = Σ τ_i + τ_μ + g, paper
//! Eq. (19) → saturation → torque filter, or the safe command), send the
//! command and notify `command_ready`, publish telemetry, and record the
//! timing histograms.
//!
//! [`ControlLoop`] owns every buffer; [`ControlLoop::run_once`] allocates
//! nothing, takes no lock, does no logging or formatting. Events (invalid
//! input, saturation, peer lost, …) go to atomic counters in [`LoopStatus`],
//! which a non-real-time thread reads and logs.
//!
//! When no state arrives for `stale_timeout` (by default three control
//! periods: the third missing state), the loop counts a stale event, marks
//! the peer lost (once per loss), publishes a telemetry sample flagged
//! [`hcc_msgs::TELEMETRY_FLAG_PEER_LOST`] carrying the counters (one per
//! further timeout while the peer stays away), and keeps waiting; it never
//! exits because a driver died. How a returning or restarted peer is told
//! apart: see [`hcc_cycle::stream`].

use std::sync::Arc;
use std::sync::atomic::Ordering;

use hcc_config::ConfigError;
use hcc_control::Controller;
use hcc_cycle::{Answer, ControlCycle, CycleError, CycleSettings};
use hcc_msgs::ipc::{
    self, CommandPublisher, ConnectionFailure, EventListener, EventNotifier, IpcError,
    LATEST_BUFFER, LoadSubscriber, PathSubscriber, PreLoan, SETPOINT_BUFFER, ScenarioPublisher,
    Services, SetpointSubscriber, StateSubscriber, TelemetryPublisher, UpdateConnections,
};
use hcc_msgs::{
    CommandMode, JointState, STATE_FLAG_DRIVER_POLLS_COMMANDS, TelemetryTimings, monotonic_now_ns,
};

use crate::status::LoopStatus;
use crate::warm_up::{WarmUp, WarmUpOverlaps};
use hcc_rt::{self as rt, WaitStrategy};
use hcc_timing::LatencyHistogram;

/// Longest single blocking wait, so that a stop request is seen promptly.
const MAX_WAIT_NS: u64 = 20_000_000;

/// The ports the loop uses.
pub struct Ports {
    /// Joint states (buffer [`LATEST_BUFFER`]: the newest wins).
    pub states: StateSubscriber,
    /// `state_ready` events from the driver.
    pub state_ready: EventListener,
    /// Torque commands (this process is the single publisher).
    pub commands: CommandPublisher,
    /// `command_ready` events to the driver.
    pub command_ready: EventNotifier,
    /// Telemetry (single publisher; never blocks).
    pub telemetry: TelemetryPublisher,
    /// Setpoints from clients (buffer [`SETPOINT_BUFFER`]; all taken each cycle).
    pub setpoints: SetpointSubscriber,
    /// Path knots from clients (buffer [`SETPOINT_BUFFER`]; all taken each
    /// cycle after the setpoints; docs/tracking.md).
    pub paths: PathSubscriber,
    /// Loads the robot's hand holds (clients → controller).
    pub loads: LoadSubscriber,
    /// The scenario the controller runs, for tools that know only the
    /// namespace (none in a test rig that does not publish one).
    pub scenario: Option<ScenarioPublisher>,
}

/// A port with no connections (the scenario's place when none is published).
struct NoPort;

impl UpdateConnections for NoPort {
    fn update_connections(&self) -> Result<(), ConnectionFailure> {
        Ok(())
    }
}

impl Ports {
    /// Creates the controller's ports on the opened services.
    pub fn open(services: &Services) -> Result<Ports, IpcError> {
        // The setpoint subscriber before the state subscriber: a launcher
        // that sees the controller listening for states can already send it
        // setpoints (a schedule due at the first state).
        let setpoints = services.setpoint_subscriber(SETPOINT_BUFFER)?;
        let paths = services.path_subscriber(SETPOINT_BUFFER)?;
        let loads = services.load_subscriber(SETPOINT_BUFFER)?;
        let commands = services.torque_command_publisher()?;
        let telemetry = services.telemetry_publisher()?;
        let command_ready = services.command_ready_notifier()?;
        let states = services.joint_state_subscriber(LATEST_BUFFER)?;
        let state_ready = services.state_ready_listener()?;
        Ok(Ports {
            setpoints,
            paths,
            loads,
            commands,
            telemetry,
            command_ready,
            states,
            state_ready,
            scenario: None,
        })
    }

    /// The ports whose connections to new or departed peers the loop updates
    /// while it waits ([`rt::ConnectionUpkeep`]): the publishers, the
    /// notifier and the subscribers (a listener has no connections), and the
    /// scenario's publisher, which hands its document to tools that connect.
    pub fn connections(&self) -> [&dyn UpdateConnections; 8] {
        [
            &self.commands,
            &self.telemetry,
            &self.command_ready,
            &self.states,
            &self.setpoints,
            &self.paths,
            &self.loads,
            match &self.scenario {
                Some(p) => p,
                None => &NoPort,
            },
        ]
    }
}

/// Settings of the loop: the cycle's, and how the loop waits and publishes.
#[derive(Debug, Clone, PartialEq)]
pub struct LoopSettings {
    /// The control cycle's settings (period, torque limits, gravity,
    /// setpoint limits, torque filter).
    pub cycle: CycleSettings,
    /// How to wait for the next state.
    pub wait: WaitStrategy,
    /// No state for this long: the peer is stale, ns.
    pub stale_timeout_ns: u64,
    /// Hybrid wait: wake this long before the expected next state, ns.
    pub hybrid_lead_ns: u64,
    /// Hybrid wait: poll this long after the expected time before blocking on the event, ns.
    pub hybrid_spin_ns: u64,
    /// Publish telemetry for every this many answered states (1: every
    /// cycle; a peer-lost sample is always published).
    pub telemetry_every: u32,
    /// Hybrid wait: step a twin of the law on the last state once per cycle
    /// shortly before the next state is expected (the cache warm-up, module
    /// [`crate::warm_up`]).
    pub warm_up: bool,
}

impl LoopSettings {
    /// Settings for a scenario (its cycle, `[controller_daemon]`); the
    /// runtime checks the wait strategy's name (an error names the field and
    /// its line).
    pub fn from_scenario(scenario: &hcc_config::Scenario) -> Result<LoopSettings, ConfigError> {
        let d = &scenario.controller_daemon;
        let wait = match &d.wait_strategy {
            None => WaitStrategy::default(),
            Some(name) => name.parse().map_err(|e: rt::UnknownWaitStrategy| {
                scenario.error_at("controller_daemon.wait_strategy", e.to_string())
            })?,
        };
        Ok(LoopSettings {
            cycle: CycleSettings::from_scenario(scenario),
            wait,
            stale_timeout_ns: (d.stale_timeout_ms * 1e6).round() as u64,
            hybrid_lead_ns: rt::HYBRID_LEAD_NS,
            hybrid_spin_ns: 200_000,
            telemetry_every: 1,
            warm_up: d.warm_up,
        })
    }
}

/// What one [`ControlLoop::run_once`] did.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Outcome {
    /// A state was answered with a command of this mode.
    Answered(CommandMode),
    /// A duplicate state was dropped (not answered).
    Duplicate,
    /// No state within the stale timeout (peer lost); still waiting.
    Stale,
    /// A stop was requested (SIGINT/SIGTERM).
    Stop,
}

/// Latency distributions of the loop (recorded every answered state,
/// allocation-free; read by the daemon when it stops).
#[derive(Debug, Default)]
pub struct LoopTimings {
    /// Wake-up latency: from the state's stamp (its publication by the driver)
    /// to the start of the computation, ns.
    pub wakeup: LatencyHistogram,
    /// Compute time: from the start of the computation to the command sent
    /// (`command_ready` notified), ns.
    pub compute: LatencyHistogram,
    /// The control law alone (`Controller::step`, eqs. 3–22), ns.
    pub step: LatencyHistogram,
    /// Stage: the setpoints taken before the decision (from the start of
    /// the computation), ns.
    pub stage_setpoints: LatencyHistogram,
    /// Stage: the decision (validation, sequence, law, output pipeline), ns.
    pub stage_decide: LatencyHistogram,
    /// Stage: the command's publication (write and delivery; the loan is taken while waiting), ns.
    pub stage_send: LatencyHistogram,
    /// Stage: the `command_ready` notification (0 for a polling driver), ns.
    pub stage_notify: LatencyHistogram,
    /// Stage: the telemetry (filled and published; after the command), ns.
    pub stage_telemetry: LatencyHistogram,
    /// The cache warm-up's step (the law's twin, while waiting), ns.
    pub warm_up: LatencyHistogram,
}

impl LoopTimings {
    /// Every histogram with its name in the `--stats` report.
    pub fn named(&self) -> [(&'static str, &LatencyHistogram); 9] {
        [
            ("wakeup_latency", &self.wakeup),
            ("compute_time", &self.compute),
            ("control_law_time", &self.step),
            ("stage_setpoints", &self.stage_setpoints),
            ("stage_decide", &self.stage_decide),
            ("stage_send", &self.stage_send),
            ("stage_notify", &self.stage_notify),
            ("stage_telemetry", &self.stage_telemetry),
            ("warm_up", &self.warm_up),
        ]
    }
}

/// Where the loop stands between states: the last one, when it came, and
/// when the peer turns stale.
struct Arrivals {
    /// The newest joint state answered (its copy, once the command is out).
    state: JointState,
    /// Wake-up time of the last state received (`None` before the first), ns.
    last_ns: Option<u64>,
    /// No state by then: the peer is stale, ns.
    stale_deadline_ns: u64,
}

/// The controller's loop: the control cycle, the last state, the wait and
/// stale-timeout state, the warm-up, the timings and the shared status.
pub struct ControlLoop {
    cycle: ControlCycle,
    settings: LoopSettings,
    arrivals: Arrivals,
    max_compute_ns: u64,
    /// Answered states since the last telemetry sample.
    since_telemetry: u32,
    /// Send failures not yet counted in telemetry.
    pending_send_failures: u64,
    /// `command_ready` notifications skipped for polling drivers.
    notifications_skipped: u64,
    timings: LoopTimings,
    /// Connections to peers that appeared or left, made while waiting.
    upkeep: rt::ConnectionUpkeep,
    status: Arc<LoopStatus>,
    warm_up: WarmUp,
    /// The next command's sample, loaned while waiting (off the path).
    command_loan: PreLoan<hcc_msgs::TorqueCommand>,
}

impl ControlLoop {
    /// Builds the loop around `controller` (already constructed for the robot).
    pub fn new(controller: Controller, settings: LoopSettings) -> Result<ControlLoop, CycleError> {
        let warm_up = WarmUp::new(&controller, settings.warm_up);
        Ok(ControlLoop {
            cycle: ControlCycle::new(controller, &settings.cycle)?,
            settings,
            arrivals: Arrivals {
                state: JointState::zeroed(),
                last_ns: None,
                stale_deadline_ns: u64::MAX,
            },
            max_compute_ns: 0,
            since_telemetry: 0,
            pending_send_failures: 0,
            notifications_skipped: 0,
            timings: LoopTimings::default(),
            upkeep: rt::ConnectionUpkeep::new(),
            status: Arc::new(LoopStatus::default()),
            warm_up,
            command_loan: PreLoan::new(),
        })
    }

    /// The counters and flags, for a logging thread.
    pub fn status(&self) -> Arc<LoopStatus> {
        Arc::clone(&self.status)
    }

    /// From now on, run-time path messages wait for their feasibility
    /// check: the worker to run on a thread of its own
    /// ([`hcc_cycle::ControlCycle::check_paths_at_run_time`]). Start-up only.
    pub fn check_paths_at_run_time(&mut self) -> hcc_cycle::PathCheckWorker {
        self.cycle.check_paths_at_run_time()
    }

    /// The control cycle (last command, telemetry, every counter, the law).
    pub fn cycle(&self) -> &ControlCycle {
        &self.cycle
    }

    /// Latency distributions of the answered states so far.
    pub fn timings(&self) -> &LoopTimings {
        &self.timings
    }

    /// `command_ready` notifications skipped because the state's driver polls
    /// (`STATE_FLAG_DRIVER_POLLS_COMMANDS`).
    pub fn notifications_skipped(&self) -> u64 {
        self.notifications_skipped
    }

    /// Cache warm-ups run so far.
    pub fn warm_ups(&self) -> u64 {
        self.warm_up.count()
    }

    /// The warm-ups that ran into their state's publication (the state then
    /// waited for them).
    pub fn warm_up_overlaps(&self) -> WarmUpOverlaps {
        self.warm_up.overlaps()
    }

    /// How long before its state the last warm-up was due to start, ns.
    pub fn last_warm_up_lead_ns(&self) -> u64 {
        self.warm_up.last_lead_ns()
    }

    /// Commands sent in a sample loaned while waiting, and loans while
    /// waiting that failed (that cycle's send then loaned on the path).
    pub fn preloaned_sends(&self) -> (u64, u64) {
        (
            self.command_loan.preloaned_sends(),
            self.command_loan.loan_failures(),
        )
    }

    /// What the connection upkeep did so far (off the torque path).
    pub fn upkeep(&self) -> rt::UpkeepCounts {
        self.upkeep.counts()
    }

    /// Connects the ports to peers that appeared or left since the last
    /// check (a recorder, a monitor, a client, a restarted driver), so that
    /// the next command's send does not. Called by every step of the wait;
    /// one atomic load per port when nothing changed.
    pub fn upkeep_connections(&mut self, ports: &Ports) {
        if self.upkeep.run(&ports.connections()) {
            self.status.publish_upkeep(&self.upkeep.counts());
        }
    }

    /// Loans the next command's sample now, off the path from a state to its
    /// command (called by every step of the wait; nothing to do while a
    /// sample is in hand). Allocation-free.
    pub fn prepare_send(&mut self, ports: &Ports) {
        self.command_loan.refill(&ports.commands);
    }

    /// Waits for the next joint state (per the wait strategy), then handles
    /// it: cycle → command (+ `command_ready`) → telemetry. Returns after
    /// one state was handled, after a stale timeout, or when a stop was
    /// requested. Allocation-free.
    pub fn run_once(&mut self, ports: &Ports) -> Outcome {
        let mut notified = false;
        loop {
            if let Some(sample) = Self::take_newest(ports) {
                let wake = monotonic_now_ns();
                return self.answer(ports, wake, &sample);
            }
            if notified {
                // A notification without a new sample: consume it, or the
                // next wait would return at once.
                let _ = ports.state_ready.try_wait(|_| {});
            }
            if rt::stop_requested() {
                return Outcome::Stop;
            }
            let now = monotonic_now_ns();
            if self.arrivals.last_ns.is_some() && now >= self.arrivals.stale_deadline_ns {
                self.on_stale(ports, now);
                return Outcome::Stale;
            }
            notified = self.wait_step(ports, now);
        }
    }

    /// Drains the state queue; returns the newest sample (older ones are
    /// released as newer ones come). The sample is read in place, in shared
    /// memory: it is copied only once its command is out.
    fn take_newest(ports: &Ports) -> Option<hcc_msgs::ipc::StateSample> {
        let mut newest = None;
        while let Ok(Some(sample)) = ports.states.receive() {
            newest = Some(sample);
        }
        newest
    }

    /// Blocks on `state_ready` until a notification or the stale deadline
    /// (at most [`MAX_WAIT_NS`]), precisely (`ipc::wait_for_event_until`;
    /// iceoryx2's own timed wait rounds its timeout up to a scheduler tick).
    /// Returns whether a notification is pending (it is consumed after the
    /// state has been answered, off the path from wake-up to command).
    fn event_wait(&self, ports: &Ports, now: u64) -> bool {
        let deadline = self
            .arrivals
            .stale_deadline_ns
            .min(now.saturating_add(MAX_WAIT_NS))
            .max(now + 1_000);
        ipc::wait_for_event_until(&ports.state_ready, deadline)
    }

    /// One step of the wait strategy (after the connection upkeep); whether
    /// a notification is pending.
    fn wait_step(&mut self, ports: &Ports, now: u64) -> bool {
        self.upkeep_connections(ports);
        self.prepare_send(ports);
        let Some(last_wake) = self.arrivals.last_ns else {
            return self.event_wait(ports, now);
        };
        if self.settings.wait == WaitStrategy::Event {
            return self.event_wait(ports, now);
        }
        // Hybrid: the next state is due one period after the last one was
        // published (its stamp, same clock), not after this thread woke: a
        // late wake-up must not push the next one later.
        let stamp = self.arrivals.state.header.stamp_ns;
        let anchor = if stamp != 0 && stamp <= last_wake {
            stamp
        } else {
            last_wake
        };
        let expected = anchor.saturating_add(self.settings.cycle.period_ns);
        self.warm_up.expect(expected);
        let wake_at = expected.saturating_sub(self.settings.hybrid_lead_ns);
        if now < wake_at {
            rt::sleep_until_ns(wake_at.min(self.arrivals.stale_deadline_ns));
            false
        } else if now < expected.saturating_add(self.settings.hybrid_spin_ns) {
            let last = (&self.arrivals.state, self.cycle.step_ns());
            let spin = self.settings.hybrid_lead_ns;
            self.warm_up
                .turn(now, expected, spin, last, &mut self.timings.warm_up);
            std::hint::spin_loop();
            false
        } else {
            self.event_wait(ports, now)
        }
    }

    /// No state within the stale timeout: report the peer lost in telemetry.
    fn on_stale(&mut self, ports: &Ports, now: u64) {
        if self.cycle.stale(now) {
            self.status.peer_lost_at_ns.store(now, Ordering::Relaxed);
            self.status.peer_lost.store(true, Ordering::Relaxed);
        }
        self.arrivals.stale_deadline_ns = now.saturating_add(self.settings.stale_timeout_ns);
        let _ = ports.telemetry.send_copy(*self.cycle.telemetry());
        self.status.publish(&self.cycle.counters());
    }

    /// Notes the arrival of `state` at `wake` (ns); returns the period since
    /// the last arrival (`None` for the first).
    fn note_state(&mut self, state: &JointState, wake: u64) -> Option<u64> {
        let period = self.arrivals.last_ns.map(|l| wake.saturating_sub(l));
        self.arrivals.last_ns = Some(wake);
        self.arrivals.stale_deadline_ns = wake.saturating_add(self.settings.stale_timeout_ns);
        let status = &self.status;
        status.connected.store(true, Ordering::Relaxed);
        status.last_state_ns.store(wake, Ordering::Relaxed);
        status
            .last_state_seq
            .store(state.header.seq, Ordering::Relaxed);
        if self.cycle.peer_lost() {
            status.peer_lost.store(false, Ordering::Relaxed);
        }
        self.warm_up
            .arrival(state.header.stamp_ns, self.settings.hybrid_lead_ns);
        period
    }

    /// Answers `state` (read in place in its sample), received at `wake`
    /// (ns); keeps a copy once the command is out.
    fn answer(&mut self, ports: &Ports, wake: u64, state: &JointState) -> Outcome {
        let period = self.note_state(state, wake);
        // Setpoints waiting for this state first (they arrived earlier), then
        // every newly queued one (bounded by the queue's length), in arrival
        // order: the order in which a client sent them.
        self.cycle.take_setpoints(state, || {
            ports
                .setpoints
                .receive()
                .ok()
                .flatten()
                .map(|sample| *sample)
        });
        // Then the paths' knots, in arrival order (bounded by the queue),
        // through the feasibility check when it runs.
        self.cycle.take_paths_at(state, || {
            ports.paths.receive().ok().flatten().map(|sample| *sample)
        });
        // Then the loads the hand holds (bounded by the queue).
        for _ in 0..SETPOINT_BUFFER {
            let Ok(Some(sample)) = ports.loads.receive() else {
                break;
            };
            self.cycle.take_load(&sample);
        }
        let taken = monotonic_now_ns();
        let answer = self.cycle.decide_command(state, wake);
        if let Some(step_ns) = self.cycle.step_ns() {
            self.timings.step.record(step_ns);
        }
        let Answer::Command(mode) = answer else {
            self.arrivals.state = *state;
            self.status.publish(&self.cycle.counters());
            return Outcome::Duplicate;
        };
        let stamps = self.send(ports, state, [wake, taken, monotonic_now_ns()]);
        // The command is out: keep the state (the hybrid wait's anchor, the
        // warm-up's input) and fill the telemetry of this decision.
        self.arrivals.state = *state;
        self.cycle.fill_telemetry();
        // The state's notification, consumed now that it is answered.
        let _ = ports.state_ready.try_wait(|_| {});
        let latency = wake as i64 - state.header.stamp_ns as i64;
        self.record_stages(latency, stamps);
        self.publish_telemetry(ports, latency, period, stamps);
        self.status.publish(&self.cycle.counters());
        self.status
            .max_compute_ns
            .store(self.max_compute_ns, Ordering::Relaxed);
        Outcome::Answered(mode)
    }

    /// Stamps and sends the command, notifies `command_ready` (unless the
    /// driver polls); counts the failures for the next telemetry sample.
    /// `stamps` are [wake, setpoints taken, decided]; returns them with the
    /// command published and the notification sent.
    fn send(&mut self, ports: &Ports, state: &JointState, stamps: [u64; 3]) -> [u64; 5] {
        let [wake, taken, decided] = stamps;
        let command = self.cycle.stamp_command(decided);
        let mut failures = u64::from(self.command_loan.send(&ports.commands, *command).is_err());
        let published = monotonic_now_ns();
        if state.flags & STATE_FLAG_DRIVER_POLLS_COMMANDS == 0 {
            failures += u64::from(ports.command_ready.notify().is_err());
        } else {
            self.notifications_skipped += 1;
        }
        self.pending_send_failures += failures;
        [wake, taken, decided, published, monotonic_now_ns()]
    }

    /// The timing histograms of an answered state: wake-up latency, compute
    /// time and each stage, from `stamps` = [wake, setpoints taken, decided,
    /// published, notified].
    fn record_stages(&mut self, latency: i64, stamps: [u64; 5]) {
        let [wake, taken, decided, published, sent] = stamps;
        let compute_ns = sent.saturating_sub(wake);
        self.max_compute_ns = self.max_compute_ns.max(compute_ns);
        let t = &mut self.timings;
        t.compute.record(compute_ns);
        t.wakeup.record_signed(latency);
        t.stage_setpoints.record(taken.saturating_sub(wake));
        t.stage_decide.record(decided.saturating_sub(taken));
        t.stage_send.record(published.saturating_sub(decided));
        t.stage_notify.record(sent.saturating_sub(published));
    }

    /// Telemetry (never blocks: safe overflow, discard on a full queue), for
    /// every `telemetry_every`-th answer; the answers to setpoints and the
    /// counters are carried by the next sample.
    fn publish_telemetry(
        &mut self,
        ports: &Ports,
        latency: i64,
        period: Option<u64>,
        stamps: [u64; 5],
    ) {
        self.since_telemetry += 1;
        if self.since_telemetry < self.settings.telemetry_every.max(1) {
            return;
        }
        self.since_telemetry = 0;
        let [wake, .., sent] = stamps;
        let timings = TelemetryTimings {
            wakeup_latency_ns: latency,
            compute_ns: sent.saturating_sub(wake),
            period_ns: period.unwrap_or(0),
            max_compute_ns: self.max_compute_ns,
        };
        let failures = std::mem::take(&mut self.pending_send_failures);
        let t = self
            .cycle
            .finish_telemetry(failures, timings, monotonic_now_ns());
        let _ = ports.telemetry.send_copy(*t);
        self.timings
            .stage_telemetry
            .record(monotonic_now_ns().saturating_sub(sent));
    }
}
