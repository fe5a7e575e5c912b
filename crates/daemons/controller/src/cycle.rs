//! One cycle of the torque loop, the I/O shell around [`Decider`]: wait for
//! a joint state (per the wait strategy), take the newest sample, let the
//! [`Decider`] answer it (validate → sequence → law τ = Σ τ_i + τ_μ + g,
//! paper Eq. (19) → safe command → saturate), send the command and notify
//! `command_ready`, publish telemetry, and record the timing histograms.
//!
//! [`Cycle`] owns every buffer; [`Cycle::run_once`] allocates nothing, takes
//! no lock, does no logging or formatting. Events (invalid input, saturation,
//! peer lost, …) go to atomic counters in [`Status`], which a non-real-time
//! thread reads and logs.
//!
//! When no state arrives for `stale_timeout` (by default three control
//! periods: the third missing state), the cycle counts a stale event, marks
//! the peer lost (once per loss), publishes a telemetry sample flagged
//! [`hcc_msgs::TELEMETRY_FLAG_PEER_LOST`] carrying the counters (one per
//! further timeout while the peer stays away), and keeps waiting; it never
//! exits because a driver died. How a returning or restarted peer is told
//! apart: see [`crate::decide`].

use std::sync::Arc;
use std::sync::atomic::Ordering;

use hcc_config::WaitStrategy;
use hcc_control::Controller;
use hcc_msgs::ipc::{
    self, CommandPublisher, EventListener, EventNotifier, IpcError, LATEST_BUFFER, PreLoan,
    SETPOINT_BUFFER, Services, SetpointSubscriber, StateSubscriber, TelemetryPublisher,
    UpdateConnections,
};
use hcc_msgs::{
    CommandMode, JointState, STATE_FLAG_DRIVER_POLLS_COMMANDS, TelemetryCounters, TelemetryTimings,
    TorqueCommand, monotonic_now_ns,
};

use crate::decide::{Answer, Decider};
use crate::status::Status;
use hcc_rt as rt;
use hcc_timing::LatencyHistogram;

/// Longest single blocking wait, so that a stop request is seen promptly.
const MAX_WAIT_NS: u64 = 20_000_000;

/// What the cache warm-up's lead before the expected state is made of.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct WarmUpLead {
    /// The law's last step, ns.
    pub step_ns: u64,
    /// The warm-ups' recent peak duration ([`DecayingPeak`]; 0 before the first), ns.
    pub warm_up_ns: u64,
    /// How much earlier than expected states came lately ([`DecayingPeak`]), ns.
    pub early_ns: u64,
}

impl WarmUpLead {
    /// How long before the expected state the warm-up starts: 1.5 times its
    /// recent peak duration (a warm-up's step is slower than the answering
    /// one, its caches being the cold ones: 1.5–1.8 times here) but at least
    /// three steps (before the first warm-up) and at least 25 µs (the
    /// Panda's step is 3–4 µs), plus how much earlier than expected states
    /// came lately (a driver's stamps move with what it computes before
    /// them) — so that the warm-up is over when the state comes. Not earlier
    /// than needed: at the start of the 150 µs spin the law in the loop
    /// still took 5.2–5.6 µs at the median against 3.5–3.7 µs when warmed
    /// 15–30 µs before the state (README, timing section).
    pub fn ns(&self) -> u64 {
        let own = self.warm_up_ns + self.warm_up_ns / 2;
        (3 * self.step_ns)
            .max(WARM_UP_MIN_LEAD_NS)
            .max(own)
            .saturating_add(self.early_ns)
    }
}

/// A recent peak: follows a larger value at once and decays by 1/64 per
/// value noted (to half in about 44), so that it sits near the top of what
/// the last few hundred values were.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct DecayingPeak(u64);

impl DecayingPeak {
    /// Notes `value`, counted as at most `cap` (one value far out, such as
    /// a step stalled by the host, must not hold the peak up for long).
    pub fn note(&mut self, value: u64, cap: u64) {
        self.0 = value.min(cap).max(self.0 - self.0 / 64);
    }

    /// The peak (0 before the first value).
    pub fn get(self) -> u64 {
        self.0
    }
}

/// The shortest lead of the cache warm-up before the expected state, ns.
pub const WARM_UP_MIN_LEAD_NS: u64 = 25_000;

/// What the hybrid spin does about the cache warm-up at one of its turns.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum WarmUpTurn {
    /// Too early: look again at the next turn of the spin.
    NotYet,
    /// Warm up now (once in this wait).
    Run,
    /// No warm-up in this wait: the state is due or overdue (a step now would
    /// delay its answer), or the law's step is too long for the spin.
    Skip,
}

/// The cache warm-up's timing in a hybrid wait ([`CycleSettings::warm_up`]):
/// at `now` (ns), with the next state expected at `expected` and a spin of
/// `hybrid_lead_ns` before it. It runs [`WarmUpLead::ns`] before the state
/// (from the spin's start when that is longer than the spin), not earlier
/// (what is warmed at the spin's start has cooled when the state comes) and
/// not once the state is due; never when three of the law's steps do not
/// fit in the spin.
pub fn warm_up_turn(now: u64, expected: u64, lead: WarmUpLead, hybrid_lead_ns: u64) -> WarmUpTurn {
    if 3 * lead.step_ns > hybrid_lead_ns || now >= expected {
        WarmUpTurn::Skip
    } else if now < expected.saturating_sub(lead.ns()) {
        WarmUpTurn::NotYet
    } else {
        WarmUpTurn::Run
    }
}

/// The cache warm-ups that were still running when the state they prepared
/// for was published: that state waited for them (its wake-up latency holds
/// the wait).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct WarmUpOverlaps {
    /// How many.
    pub count: u64,
    /// The longest wait they caused, ns.
    pub max_ns: u64,
}

impl WarmUpOverlaps {
    /// Notes a warm-up that ended at `end_ns` before a state stamped `stamp_ns`
    /// (the same clock); an overlap when the state came first.
    pub fn note(&mut self, end_ns: u64, stamp_ns: u64) {
        if stamp_ns != 0 && stamp_ns < end_ns {
            self.count += 1;
            self.max_ns = self.max_ns.max(end_ns - stamp_ns);
        }
    }
}

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
}

impl Ports {
    /// Creates the controller's ports on the opened services.
    pub fn open(services: &Services) -> Result<Ports, IpcError> {
        // The setpoint subscriber before the state subscriber: a launcher
        // that sees the controller listening for states can already send it
        // setpoints (a schedule due at the first state).
        let setpoints = services.setpoint_subscriber(SETPOINT_BUFFER)?;
        let commands = services.torque_command_publisher()?;
        let telemetry = services.telemetry_publisher()?;
        let command_ready = services.command_ready_notifier()?;
        let states = services.joint_state_subscriber(LATEST_BUFFER)?;
        let state_ready = services.state_ready_listener()?;
        Ok(Ports {
            setpoints,
            commands,
            telemetry,
            command_ready,
            states,
            state_ready,
        })
    }

    /// The ports whose connections to new or departed peers the loop updates
    /// while it waits ([`rt::ConnectionUpkeep`]): the publishers, the
    /// notifier and the subscribers (a listener has no connections).
    pub fn connections(&self) -> [&dyn UpdateConnections; 5] {
        [
            &self.commands,
            &self.telemetry,
            &self.command_ready,
            &self.states,
            &self.setpoints,
        ]
    }
}

/// Settings of the loop.
#[derive(Debug, Clone, PartialEq)]
pub struct CycleSettings {
    /// How to wait for the next state.
    pub wait: WaitStrategy,
    /// Nominal period of the driver's states, ns.
    pub period_ns: u64,
    /// No state for this long: the peer is stale, ns.
    pub stale_timeout_ns: u64,
    /// |τ_k| ≤ limit_k (may be +inf).
    pub torque_limits: Vec<f64>,
    /// Whether τ includes g(q) (the command's gravity flag).
    pub gravity_compensation: bool,
    /// Hybrid wait: wake this long before the expected next state, ns.
    pub hybrid_lead_ns: u64,
    /// Hybrid wait: poll this long after the expected time before blocking on the event, ns.
    pub hybrid_spin_ns: u64,
    /// Limits of setpoints (`[commanding]`).
    pub commanding: hcc_config::commanding::Commanding,
    /// The torque output pipeline (`[output]`).
    pub output: hcc_config::output::Output,
    /// Publish telemetry for every this many answered states (1: every
    /// cycle; a peer-lost sample is always published).
    pub telemetry_every: u32,
    /// Hybrid wait: step a copy of the law on the last state once per cycle,
    /// [`WarmUpLead::ns`] before the next state is expected, if the last
    /// step took at most a third of `hybrid_lead_ns` (cache warm-up;
    /// [`Decider::warm_up`]).
    pub warm_up: bool,
}

impl CycleSettings {
    /// Settings for a scenario's `[controller_daemon]` and control rate.
    pub fn from_scenario(scenario: &hcc_config::Scenario) -> CycleSettings {
        let d = &scenario.controller_daemon;
        CycleSettings {
            wait: d.wait_strategy,
            period_ns: (1e9 / scenario.simulation.control_rate_hz).round() as u64,
            stale_timeout_ns: (d.stale_timeout_ms * 1e6).round() as u64,
            torque_limits: d.torque_limits.iter().copied().collect(),
            gravity_compensation: scenario.spec.gravity_compensation,
            hybrid_lead_ns: rt::HYBRID_LEAD_NS,
            hybrid_spin_ns: 200_000,
            commanding: scenario.commanding.clone(),
            output: scenario.output.clone(),
            telemetry_every: 1,
            warm_up: d.warm_up,
        }
    }
}

/// Errors of [`Cycle::new`].
#[derive(Debug, thiserror::Error)]
pub enum CycleError {
    /// A size does not fit the message capacities or the controller.
    #[error("{0}")]
    Shape(String),
}

/// What one [`Cycle::run_once`] did.
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
pub struct CycleTimings {
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

impl CycleTimings {
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

/// The controller's loop: the [`Decider`], the receive buffer, the wait
/// and stale-timeout state, the timings and the shared [`Status`].
pub struct Cycle {
    decider: Decider,
    settings: CycleSettings,
    /// The newest joint state received.
    state: JointState,
    last_state_ns: Option<u64>,
    stale_deadline_ns: u64,
    last_wake_ns: u64,
    max_compute_ns: u64,
    /// Answered states since the last telemetry sample.
    since_telemetry: u32,
    /// Send failures not yet counted in telemetry.
    pending_send_failures: u64,
    /// `command_ready` notifications skipped for polling drivers.
    notifications_skipped: u64,
    timings: CycleTimings,
    /// Connections to peers that appeared or left, made while waiting.
    upkeep: rt::ConnectionUpkeep,
    status: Arc<Status>,
    /// The cache warm-up ran in this wait.
    warmed: bool,
    /// Cache warm-ups run since start-up.
    warm_ups: u64,
    /// The warm-ups' recent peak duration (their lead follows it), ns.
    warm_up_peak: DecayingPeak,
    /// How much earlier than expected the states came lately, ns.
    early_peak: DecayingPeak,
    /// When the hybrid wait expects the next state (0: no expectation), ns.
    expected_ns: u64,
    /// The lead of the last warm-up, ns.
    last_lead_ns: u64,
    /// When this wait's warm-up ended (0: none in this wait), ns.
    warm_up_end_ns: u64,
    /// Warm-ups that were still running when their state was published.
    warm_up_overlaps: WarmUpOverlaps,
    /// The next command's sample, loaned while waiting (off the path).
    command_loan: PreLoan<TorqueCommand>,
}

impl Cycle {
    /// Builds the loop state around `controller` (already constructed for the robot).
    pub fn new(controller: Controller, settings: CycleSettings) -> Result<Cycle, CycleError> {
        Ok(Cycle {
            decider: Decider::new(controller, &settings)?,
            settings,
            state: JointState::zeroed(),
            last_state_ns: None,
            stale_deadline_ns: u64::MAX,
            last_wake_ns: 0,
            max_compute_ns: 0,
            since_telemetry: 0,
            pending_send_failures: 0,
            notifications_skipped: 0,
            timings: CycleTimings::default(),
            upkeep: rt::ConnectionUpkeep::new(),
            status: Arc::new(Status::default()),
            warmed: false,
            warm_ups: 0,
            warm_up_peak: DecayingPeak::default(),
            early_peak: DecayingPeak::default(),
            expected_ns: 0,
            last_lead_ns: 0,
            warm_up_end_ns: 0,
            warm_up_overlaps: WarmUpOverlaps::default(),
            command_loan: PreLoan::new(),
        })
    }

    /// The counters and flags, for a logging thread.
    pub fn status(&self) -> Arc<Status> {
        Arc::clone(&self.status)
    }

    /// The telemetry counters of the last cycle.
    pub fn counters(&self) -> TelemetryCounters {
        self.decider.counters().telemetry
    }

    /// The decision state (last command, telemetry, every counter).
    pub fn decider(&self) -> &Decider {
        &self.decider
    }

    /// Latency distributions of the answered states so far.
    pub fn timings(&self) -> &CycleTimings {
        &self.timings
    }

    /// `command_ready` notifications skipped because the state's driver polls
    /// (`STATE_FLAG_DRIVER_POLLS_COMMANDS`).
    pub fn notifications_skipped(&self) -> u64 {
        self.notifications_skipped
    }

    /// Cache warm-ups run so far ([`CycleSettings::warm_up`]).
    pub fn warm_ups(&self) -> u64 {
        self.warm_ups
    }

    /// The warm-ups that ran into their state's publication (the state then
    /// waited for them).
    pub fn warm_up_overlaps(&self) -> WarmUpOverlaps {
        self.warm_up_overlaps
    }

    /// How long before its state the last warm-up was due to start
    /// ([`WarmUpLead::ns`]; 0 before the first), ns.
    pub fn last_warm_up_lead_ns(&self) -> u64 {
        self.last_lead_ns
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

    /// The control law.
    pub fn controller(&self) -> &Controller {
        self.decider.controller()
    }

    /// Waits for the next joint state (per the wait strategy), then handles
    /// it: decide → command (+ `command_ready`) → telemetry. Returns after
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
            if self.last_state_ns.is_some() && now >= self.stale_deadline_ns {
                self.on_stale(ports, now);
                return Outcome::Stale;
            }
            notified = self.wait_step(ports, now);
        }
    }

    /// Drains the state queue; returns the newest sample (older ones are
    /// released as newer ones come). The sample is read in place, in shared
    /// memory: it is copied into `self.state` only once its command is out.
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
        match self.settings.wait {
            WaitStrategy::Event => self.event_wait(ports, now),
            WaitStrategy::Hybrid => {
                if self.last_state_ns.is_none() {
                    return self.event_wait(ports, now);
                }
                // The next state is due one period after the last one was
                // published (its stamp, same clock), not after this thread
                // woke: a late wake-up must not push the next one later.
                let stamp = self.state.header.stamp_ns;
                let anchor = if stamp != 0 && stamp <= self.last_wake_ns {
                    stamp
                } else {
                    self.last_wake_ns
                };
                let expected = anchor.saturating_add(self.settings.period_ns);
                self.expected_ns = expected;
                let wake_at = expected.saturating_sub(self.settings.hybrid_lead_ns);
                if now < wake_at {
                    rt::sleep_until_ns(wake_at.min(self.stale_deadline_ns));
                    false
                } else if now < expected.saturating_add(self.settings.hybrid_spin_ns) {
                    self.warm_up_before(now, expected);
                    std::hint::spin_loop();
                    false
                } else {
                    self.event_wait(ports, now)
                }
            }
        }
    }

    /// The cache warm-up ([`CycleSettings::warm_up`]) in the hybrid spin
    /// before the state expected at `expected` (ns): once per wait, when `now`
    /// is [`WarmUpLead::ns`] before it — late enough that nothing cools the
    /// caches again before the state, early enough that the step is over
    /// when it comes. Skipped when the spin starts after that point has
    /// passed the expected time, and for a law whose step takes more than a
    /// third of the spin's lead (a large robot's step would still run when
    /// its state comes).
    fn warm_up_before(&mut self, now: u64, expected: u64) {
        if self.warmed || !self.settings.warm_up {
            return;
        }
        let Some(step) = self.decider.step_ns() else {
            return;
        };
        let lead = WarmUpLead {
            step_ns: step,
            warm_up_ns: self.warm_up_peak.get(),
            early_ns: self.early_peak.get(),
        };
        let spin = self.settings.hybrid_lead_ns;
        match warm_up_turn(now, expected, lead, spin) {
            WarmUpTurn::NotYet => {}
            WarmUpTurn::Skip => self.warmed = true,
            WarmUpTurn::Run => {
                self.warmed = true;
                if self.decider.warm_up(&self.state) {
                    self.warm_ups += 1;
                    let end = monotonic_now_ns();
                    let took = end.saturating_sub(now);
                    self.timings.warm_up.record(took);
                    self.warm_up_peak.note(took, spin);
                    self.last_lead_ns = lead.ns();
                    self.warm_up_end_ns = end;
                }
            }
        }
    }

    /// No state within the stale timeout: report the peer lost in telemetry.
    fn on_stale(&mut self, ports: &Ports, now: u64) {
        if self.decider.stale(now) {
            self.status.peer_lost_at_ns.store(now, Ordering::Relaxed);
            self.status.peer_lost.store(true, Ordering::Relaxed);
        }
        self.stale_deadline_ns = now.saturating_add(self.settings.stale_timeout_ns);
        let _ = ports.telemetry.send_copy(*self.decider.telemetry());
        self.status.publish(&self.decider.counters());
    }

    /// Notes the arrival of `state` at `wake` (ns).
    fn note_state(&mut self, state: &JointState, wake: u64) {
        self.last_state_ns = Some(wake);
        self.last_wake_ns = wake;
        self.stale_deadline_ns = wake.saturating_add(self.settings.stale_timeout_ns);
        let status = &self.status;
        status.connected.store(true, Ordering::Relaxed);
        status.last_state_ns.store(wake, Ordering::Relaxed);
        status
            .last_state_seq
            .store(state.header.seq, Ordering::Relaxed);
        if self.decider.peer_lost() {
            status.peer_lost.store(false, Ordering::Relaxed);
        }
    }

    /// Notes when the state stamped `stamp_ns` came against the hybrid
    /// wait's expectation (the warm-up's lead follows how early states come)
    /// and whether this wait's warm-up was still running then.
    fn note_arrival(&mut self, stamp_ns: u64) {
        if self.expected_ns != 0 && stamp_ns != 0 {
            let early = self.expected_ns.saturating_sub(stamp_ns);
            self.early_peak.note(early, self.settings.hybrid_lead_ns);
        }
        if self.warm_up_end_ns != 0 {
            self.warm_up_overlaps.note(self.warm_up_end_ns, stamp_ns);
        }
        self.expected_ns = 0;
        self.warm_up_end_ns = 0;
    }

    /// Answers `state` (read in place in its sample), received at `wake`
    /// (ns); keeps a copy in `self.state` once the command is out.
    fn answer(&mut self, ports: &Ports, wake: u64, state: &JointState) -> Outcome {
        let period = self
            .last_state_ns
            .is_some()
            .then(|| wake.saturating_sub(self.last_wake_ns));
        self.note_state(state, wake);
        self.warmed = false;
        self.note_arrival(state.header.stamp_ns);
        // Setpoints waiting for this state first (they arrived earlier), then
        // every newly queued one (at most the queue's length: bounded work),
        // in arrival order: the order in which a client sent them.
        let clock = self.decider.setpoint_clock(state);
        self.decider.apply_due_setpoints(clock);
        for _ in 0..SETPOINT_BUFFER {
            let Ok(Some(setpoint)) = ports.setpoints.receive() else {
                break;
            };
            self.decider.receive_setpoint(&setpoint, clock);
        }
        let taken = monotonic_now_ns();
        let answer = self.decider.decide_command(state, wake);
        if let Some(step_ns) = self.decider.step_ns() {
            self.timings.step.record(step_ns);
        }
        let Answer::Command(mode) = answer else {
            self.state = *state;
            self.status.publish(&self.decider.counters());
            return Outcome::Duplicate;
        };
        let decided = monotonic_now_ns();
        let command = self.decider.stamp_command(decided);
        let mut send_failures =
            u64::from(self.command_loan.send(&ports.commands, *command).is_err());
        let published = monotonic_now_ns();
        if state.flags & STATE_FLAG_DRIVER_POLLS_COMMANDS == 0 {
            send_failures += u64::from(ports.command_ready.notify().is_err());
        } else {
            self.notifications_skipped += 1;
        }
        let sent = monotonic_now_ns();
        // The command is out: keep the state (the hybrid wait's anchor, the
        // warm-up's input) and fill the telemetry of this decision.
        self.state = *state;
        self.decider.fill_telemetry();
        // The state's notification, consumed now that it is answered.
        let _ = ports.state_ready.try_wait(|_| {});
        let compute_ns = sent.saturating_sub(wake);
        self.max_compute_ns = self.max_compute_ns.max(compute_ns);
        let latency = wake as i64 - state.header.stamp_ns as i64;
        let t = &mut self.timings;
        t.compute.record(compute_ns);
        t.wakeup.record_signed(latency);
        t.stage_setpoints.record(taken.saturating_sub(wake));
        t.stage_decide.record(decided.saturating_sub(taken));
        t.stage_send.record(published.saturating_sub(decided));
        t.stage_notify.record(sent.saturating_sub(published));

        // Telemetry (never blocks: safe overflow, discard on a full queue),
        // for every `telemetry_every`-th answer; the answers to setpoints
        // and the counters are carried by the next sample.
        self.since_telemetry += 1;
        self.pending_send_failures += send_failures;
        if self.since_telemetry >= self.settings.telemetry_every.max(1) {
            self.since_telemetry = 0;
            let timings = TelemetryTimings {
                wakeup_latency_ns: latency,
                compute_ns,
                period_ns: period.unwrap_or(0),
                max_compute_ns: self.max_compute_ns,
            };
            let t = self.decider.finish_telemetry(
                self.pending_send_failures,
                timings,
                monotonic_now_ns(),
            );
            self.pending_send_failures = 0;
            let _ = ports.telemetry.send_copy(*t);
            let done = monotonic_now_ns();
            self.timings
                .stage_telemetry
                .record(done.saturating_sub(sent));
        }
        self.status.publish(&self.decider.counters());
        self.status
            .max_compute_ns
            .store(self.max_compute_ns, Ordering::Relaxed);
        Outcome::Answered(mode)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const LEAD: u64 = 150_000;

    /// The lead of a law whose last step took `step_ns`, before any warm-up.
    fn first(step_ns: u64) -> WarmUpLead {
        WarmUpLead {
            step_ns,
            ..WarmUpLead::default()
        }
    }

    #[test]
    fn warm_up_lead_is_three_steps_and_at_least_25_us_before_the_first_warm_up() {
        assert_eq!(first(3_500).ns(), WARM_UP_MIN_LEAD_NS);
        assert_eq!(first(8_333).ns(), WARM_UP_MIN_LEAD_NS);
        assert_eq!(first(10_000).ns(), 30_000);
        assert_eq!(first(50_000).ns(), 150_000);
    }

    #[test]
    fn warm_up_lead_covers_its_own_duration_and_early_states() {
        // Warm-ups of up to 22 µs lately: 33 µs (1.5 times), more than 25 µs.
        let slow = WarmUpLead {
            step_ns: 3_500,
            warm_up_ns: 22_000,
            early_ns: 0,
        };
        assert_eq!(slow.ns(), 33_000);
        // Short warm-ups: the 25 µs floor, or three steps when longer.
        let quick = WarmUpLead {
            warm_up_ns: 6_000,
            ..slow
        };
        assert_eq!(quick.ns(), WARM_UP_MIN_LEAD_NS);
        assert_eq!(
            WarmUpLead {
                step_ns: 12_000,
                ..quick
            }
            .ns(),
            36_000
        );
        // States that came up to 9 µs before their expected time: that much earlier.
        assert_eq!(
            WarmUpLead {
                early_ns: 9_000,
                ..slow
            }
            .ns(),
            42_000
        );
        assert_eq!(
            WarmUpLead {
                early_ns: 9_000,
                ..quick
            }
            .ns(),
            34_000
        );
    }

    #[test]
    fn decaying_peak_follows_a_rise_at_once_and_a_fall_slowly() {
        let mut p = DecayingPeak::default();
        assert_eq!(p.get(), 0);
        p.note(20_000, LEAD);
        assert_eq!(p.get(), 20_000);
        p.note(5_000, LEAD);
        assert_eq!(p.get(), 20_000 - 20_000 / 64);
        // About 44 smaller values halve it; it never falls below the values.
        for _ in 0..43 {
            p.note(5_000, LEAD);
        }
        assert!((9_500..=10_500).contains(&p.get()), "{}", p.get());
        for _ in 0..1_000 {
            p.note(5_000, LEAD);
        }
        assert_eq!(p.get(), 5_000);
        // A value far out counts as the cap, and is forgotten like any other.
        p.note(900_000, LEAD);
        assert_eq!(p.get(), LEAD);
        for _ in 0..200 {
            p.note(5_000, LEAD);
        }
        assert!(p.get() < 10_000, "{}", p.get());
    }

    #[test]
    fn a_warm_up_overlaps_a_state_published_before_it_ended() {
        let mut o = WarmUpOverlaps::default();
        o.note(1_000_000, 1_000_001);
        o.note(1_000_000, 1_000_000);
        assert_eq!(
            o,
            WarmUpOverlaps::default(),
            "ended before or as the state came"
        );
        o.note(1_000_000, 996_000);
        o.note(2_000_000, 1_999_000);
        assert_eq!(
            o,
            WarmUpOverlaps {
                count: 2,
                max_ns: 4_000
            }
        );
        // A state without a stamp says nothing.
        o.note(3_000_000, 0);
        assert_eq!(o.count, 2);
    }

    /// Checks [`warm_up_turn`] with a state expected at 10 ms, at each
    /// offset from it (ns), against the turn wanted there.
    fn check(lead: WarmUpLead, cases: &[(i64, WarmUpTurn)]) {
        let expected = 10_000_000u64;
        for &(offset, want) in cases {
            let now = expected.checked_add_signed(offset).unwrap();
            assert_eq!(
                warm_up_turn(now, expected, lead, LEAD),
                want,
                "{offset} ns from the state, {lead:?}"
            );
        }
    }

    use WarmUpTurn::{NotYet, Run, Skip};

    #[test]
    fn warm_up_runs_in_the_last_lead_before_the_state_only() {
        let lead = LEAD as i64;
        check(
            first(3_500),
            &[
                // The spin starts 150 µs before the state: too early to warm.
                (-lead, NotYet),
                (-25_001, NotYet),
                // From 25 µs before the state until it is due.
                (-25_000, Run),
                (-1, Run),
                // Due or overdue: a step now would delay the answer.
                (0, Skip),
                (40_000, Skip),
            ],
        );
    }

    #[test]
    fn warm_up_moves_earlier_with_slow_warm_ups_and_early_states() {
        let lead = WarmUpLead {
            step_ns: 3_500,
            warm_up_ns: 20_000,
            early_ns: 10_000,
        };
        check(lead, &[(-40_001, NotYet), (-40_000, Run)]);
        // A lead longer than the spin: from the spin's start, never skipped
        // for it (only a long step of the law skips the warm-up).
        let stalled = WarmUpLead {
            warm_up_ns: LEAD,
            ..lead
        };
        check(stalled, &[(-(LEAD as i64), Run)]);
    }

    #[test]
    fn warm_up_of_a_long_step_starts_three_steps_before_or_not_at_all() {
        let spin = LEAD as i64;
        // 20 µs steps: 60 µs before the state.
        check(first(20_000), &[(-60_001, NotYet), (-60_000, Run)]);
        // Three steps fill the spin exactly: still warmed, from its start.
        check(first(50_000), &[(-spin, Run)]);
        // Longer: never (the step would still run when the state comes).
        check(first(50_001), &[(-spin, Skip), (-1_000, Skip)]);
    }

    #[test]
    fn warm_up_near_the_clock_origin_does_not_underflow() {
        assert_eq!(warm_up_turn(0, 10_000, first(3_500), LEAD), WarmUpTurn::Run);
        assert_eq!(
            warm_up_turn(10_000, 10_000, first(3_500), LEAD),
            WarmUpTurn::Skip
        );
        let far = WarmUpLead {
            step_ns: 3_500,
            warm_up_ns: u64::MAX / 2,
            early_ns: u64::MAX,
        };
        assert_eq!(far.ns(), u64::MAX);
        assert_eq!(warm_up_turn(0, 10_000, far, LEAD), WarmUpTurn::Run);
    }
}
