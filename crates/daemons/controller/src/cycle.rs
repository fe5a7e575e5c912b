//! One cycle of the torque loop: wait for a joint state, validate it, compute
//! the hierarchical compliance control law (paper Eq. (19): τ = Σ τ_i + τ_μ + g),
//! saturate, answer with a torque command, publish telemetry.
//!
//! [`Cycle`] owns every buffer; [`Cycle::run_once`] allocates nothing, takes
//! no lock, does no logging or formatting. Events (invalid input, saturation,
//! peer lost, …) go to atomic counters in [`Status`], which a non-real-time
//! thread reads and logs.
//!
//! # Safe command
//!
//! A state that fails validation (schema, joint count, NaN/Inf, unknown
//! status or flags), goes backwards in sequence, jumps further ahead than the
//! driver can have advanced in the elapsed time ([`max_plausible_gap`]), or
//! disagrees with the controller about who adds gravity, is answered with mode
//! [`CommandMode::SafeHold`] and τ = g(q_v), the gravity torque at the last
//! valid configuration q_v, when the controller includes gravity (and τ = 0
//! otherwise, or before any valid state, or on a gravity conflict, where the
//! driver adds g itself). No damping term is added: the velocity of the last
//! valid state is stale, and a torque −D q̇_v held over several cycles would not
//! be dissipative; damping is the driver's fallback (see the hcc-msgs timing
//! contract). A numerical failure of the control law (which its damped
//! inversions should prevent), including a non-finite τ, is answered the same
//! way. The safe command is saturated like any other. A duplicate state is not
//! answered again. Every rejection is counted (`invalid_states`,
//! `sequence_errors`, `numerical_failures`) and logged by the non-real-time
//! thread.
//!
//! # Stale state and peer restart
//!
//! When no state arrives for `stale_timeout` (by default three control
//! periods: the third missing state), the cycle counts a stale event, marks
//! the peer lost (once per loss), publishes a telemetry sample flagged
//! [`TELEMETRY_FLAG_PEER_LOST`] carrying the counters (one per further timeout while the peer stays away), and keeps
//! waiting; it never exits because a driver died. When states come back, the
//! stream tells a new peer from the old one: a state that continues the old
//! sequence (the same driver after a stall) is used as is, while one that
//! does not (a restarted driver counts from 0), or three consecutive
//! rejected states that follow each other (a driver restarted without an
//! outage), reset the [`SequenceChecker`] and the controller's null-space
//! basis memory (`Controller::reset`), and control resumes with that peer.
//! (The torque does not depend on the basis, only its last bits do: a state
//! that merely comes late changes nothing, so a lockstep run over IPC stays
//! bit-identical to the in-process one on a loaded machine.)

use std::sync::Arc;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};

use hcc_config::WaitStrategy;
use hcc_control::Controller;
use hcc_msgs::ipc::{
    self, CommandPublisher, EventListener, EventNotifier, IpcError, LATEST_BUFFER, Services,
    StateSubscriber, TelemetryPublisher,
};
use hcc_msgs::{
    COMMAND_FLAG_GRAVITY_INCLUDED, CommandMode, JointState, MAX_JOINTS, MAX_LEVELS, MAX_TASK_DIM,
    SeqEvent, SequenceChecker, TELEMETRY_FLAG_PEER_LOST, Telemetry, TelemetryCounters,
    TorqueCommand, monotonic_now_ns,
};

use crate::rt;
use hcc_timing::LatencyHistogram;

/// Longest single blocking wait, so that a stop request is seen promptly.
const MAX_WAIT_NS: u64 = 20_000_000;

/// Consecutive rejected sequence numbers (backwards or implausible jumps)
/// that follow each other, taken as a restarted peer.
const RESYNC_RUN: u32 = 3;

/// Slack of [`max_plausible_gap`], in states.
const GAP_SLACK: u64 = 16;

/// The largest number of states a driver publishing one state per period can
/// have skipped in `elapsed_ns`: twice the periods elapsed plus
/// [`GAP_SLACK`] (wake-up jitter, a driver running slightly fast). A larger
/// jump of the sequence number is a corrupt or foreign stream and is rejected.
pub const fn max_plausible_gap(elapsed_ns: u64, period_ns: u64) -> u64 {
    let periods = match elapsed_ns.checked_div(period_ns) {
        Some(p) => p,
        None => 0,
    };
    periods.saturating_mul(2).saturating_add(GAP_SLACK)
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
}

impl Ports {
    /// Creates the controller's ports on the opened services.
    pub fn open(services: &Services) -> Result<Ports, IpcError> {
        let commands = services.torque_command_publisher()?;
        let telemetry = services.telemetry_publisher()?;
        let command_ready = services.command_ready_notifier()?;
        let states = services.joint_state_subscriber(LATEST_BUFFER)?;
        let state_ready = services.state_ready_listener()?;
        Ok(Ports {
            commands,
            telemetry,
            command_ready,
            states,
            state_ready,
        })
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

/// Counters and flags shared with the logging thread (all relaxed atomics).
#[derive(Debug, Default)]
pub struct Status {
    pub cycles: AtomicU64,
    pub invalid_states: AtomicU64,
    pub saturations: AtomicU64,
    pub singular_cycles: AtomicU64,
    pub stale_events: AtomicU64,
    pub peer_lost_events: AtomicU64,
    pub missed_states: AtomicU64,
    pub sequence_errors: AtomicU64,
    pub send_failures: AtomicU64,
    /// Cycles in which the control law reported a numerical failure.
    pub numerical_failures: AtomicU64,
    /// Peer restarts detected (stale then back, or repeated backwards).
    pub peer_restarts: AtomicU64,
    /// The peer is currently lost (no state within the stale timeout).
    pub peer_lost: AtomicBool,
    /// When the current (or last) loss was detected, CLOCK_MONOTONIC ns.
    pub peer_lost_at_ns: AtomicU64,
    /// Wake-up time of the last state received, CLOCK_MONOTONIC ns.
    pub last_state_ns: AtomicU64,
    /// `header.seq` of the last state received.
    pub last_state_seq: AtomicU64,
    /// At least one state was received.
    pub connected: AtomicBool,
    /// Worst compute time so far, ns.
    pub max_compute_ns: AtomicU64,
    /// Worst wake-up latency (wake − state stamp) so far, ns.
    pub max_latency_ns: AtomicU64,
}

impl Status {
    fn publish(&self, c: &TelemetryCounters, numerical_failures: u64, restarts: u64) {
        let set = |a: &AtomicU64, v: u64| a.store(v, Ordering::Relaxed);
        set(&self.cycles, c.cycles);
        set(&self.invalid_states, c.invalid_states);
        set(&self.saturations, c.saturations);
        set(&self.singular_cycles, c.singular_cycles);
        set(&self.stale_events, c.stale_events);
        set(&self.peer_lost_events, c.peer_lost_events);
        set(&self.missed_states, c.missed_states);
        set(&self.sequence_errors, c.sequence_errors);
        set(&self.send_failures, c.send_failures);
        set(&self.numerical_failures, numerical_failures);
        set(&self.peer_restarts, restarts);
    }

    /// The counters as in telemetry.
    pub fn counters(&self) -> TelemetryCounters {
        let get = |a: &AtomicU64| a.load(Ordering::Relaxed);
        TelemetryCounters {
            cycles: get(&self.cycles),
            invalid_states: get(&self.invalid_states),
            saturations: get(&self.saturations),
            singular_cycles: get(&self.singular_cycles),
            stale_events: get(&self.stale_events),
            peer_lost_events: get(&self.peer_lost_events),
            missed_states: get(&self.missed_states),
            sequence_errors: get(&self.sequence_errors),
            send_failures: get(&self.send_failures),
        }
    }
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
}

/// The controller's loop state: the control law, all message buffers and counters.
pub struct Cycle {
    controller: Controller,
    settings: CycleSettings,
    n: usize,
    r: usize,
    limits: [f64; MAX_JOINTS],
    state: JointState,
    command: TorqueCommand,
    telemetry: Box<Telemetry>,
    checker: SequenceChecker,
    counters: TelemetryCounters,
    numerical_failures: u64,
    restarts: u64,
    command_seq: u64,
    telemetry_seq: u64,
    /// g(q) at the last valid state.
    gravity_last: [f64; MAX_JOINTS],
    have_valid: bool,
    /// Consecutive rejected sequence numbers that follow each other.
    resync_run: u32,
    /// Sequence number of the last rejected state of that run.
    resync_last: u64,
    /// Wake-up time of the last state whose sequence number was accepted.
    last_accepted_ns: u64,
    last_state_ns: Option<u64>,
    stale_deadline_ns: u64,
    last_wake_ns: u64,
    peer_lost: bool,
    max_compute_ns: u64,
    timings: CycleTimings,
    status: Arc<Status>,
}

impl Cycle {
    /// Builds the loop state around `controller` (already constructed for the robot).
    pub fn new(controller: Controller, settings: CycleSettings) -> Result<Cycle, CycleError> {
        let n = controller.nq();
        let r = controller.levels();
        if n > MAX_JOINTS {
            return Err(CycleError::Shape(format!(
                "the robot has {n} joints; the messages hold at most {MAX_JOINTS}"
            )));
        }
        if r > MAX_LEVELS {
            return Err(CycleError::Shape(format!(
                "the hierarchy has {r} levels; telemetry holds at most {MAX_LEVELS}"
            )));
        }
        if settings.torque_limits.len() != n {
            return Err(CycleError::Shape(format!(
                "controller_daemon.torque_limits has {} entries, the robot {n} joints",
                settings.torque_limits.len()
            )));
        }
        if let Some(k) = settings
            .torque_limits
            .iter()
            .position(|l| l.is_nan() || *l <= 0.0)
        {
            return Err(CycleError::Shape(format!(
                "controller_daemon.torque_limits[{k}] = {} must be positive",
                settings.torque_limits[k]
            )));
        }
        let dims: Vec<usize> = (0..r).map(|i| controller.task_dim(i)).collect();
        let mut telemetry = Box::new(Telemetry::zeroed());
        telemetry
            .set_shape(n, &dims)
            .map_err(|e| CycleError::Shape(e.to_string()))?;
        let mut command = TorqueCommand::zeroed();
        command
            .set_n_joints(n)
            .map_err(|e| CycleError::Shape(e.to_string()))?;
        if settings.gravity_compensation {
            command.flags = COMMAND_FLAG_GRAVITY_INCLUDED;
        }
        let mut limits = [f64::INFINITY; MAX_JOINTS];
        limits[..n].copy_from_slice(&settings.torque_limits);
        Ok(Cycle {
            controller,
            n,
            r,
            limits,
            state: JointState::zeroed(),
            command,
            telemetry,
            checker: SequenceChecker::new(),
            counters: TelemetryCounters::default(),
            numerical_failures: 0,
            restarts: 0,
            command_seq: 0,
            telemetry_seq: 0,
            gravity_last: [0.0; MAX_JOINTS],
            have_valid: false,
            resync_run: 0,
            resync_last: 0,
            last_accepted_ns: 0,
            last_state_ns: None,
            stale_deadline_ns: u64::MAX,
            last_wake_ns: 0,
            peer_lost: false,
            max_compute_ns: 0,
            timings: CycleTimings::default(),
            status: Arc::new(Status::default()),
            settings,
        })
    }

    /// The counters and flags, for a logging thread.
    pub fn status(&self) -> Arc<Status> {
        Arc::clone(&self.status)
    }

    /// The counters of the last cycle.
    pub fn counters(&self) -> TelemetryCounters {
        self.counters
    }

    /// The last command sent.
    pub fn last_command(&self) -> &TorqueCommand {
        &self.command
    }

    /// Latency distributions of the answered states so far.
    pub fn timings(&self) -> &CycleTimings {
        &self.timings
    }

    /// The control law.
    pub fn controller(&self) -> &Controller {
        &self.controller
    }

    /// Waits for the next joint state (per the wait strategy), then handles
    /// it: validate → compute → saturate → command (+ `command_ready`) →
    /// telemetry. Returns after one state was handled, after a stale timeout,
    /// or when a stop was requested. Allocation-free.
    pub fn run_once(&mut self, ports: &Ports) -> Outcome {
        let mut notified = false;
        loop {
            if self.take_newest(ports) {
                let wake = monotonic_now_ns();
                return self.process(ports, wake);
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

    /// Drains the state queue; keeps the newest sample in `self.state`.
    fn take_newest(&mut self, ports: &Ports) -> bool {
        let mut got = false;
        while let Ok(Some(sample)) = ports.states.receive() {
            self.state = *sample;
            got = true;
        }
        got
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

    /// One step of the wait strategy; whether a notification is pending.
    fn wait_step(&self, ports: &Ports, now: u64) -> bool {
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
                let wake_at = expected.saturating_sub(self.settings.hybrid_lead_ns);
                if now < wake_at {
                    rt::sleep_until_ns(wake_at.min(self.stale_deadline_ns));
                    false
                } else if now < expected.saturating_add(self.settings.hybrid_spin_ns) {
                    std::hint::spin_loop();
                    false
                } else {
                    self.event_wait(ports, now)
                }
            }
        }
    }

    fn on_stale(&mut self, ports: &Ports, now: u64) {
        self.counters.stale_events += 1;
        if !self.peer_lost {
            self.peer_lost = true;
            self.counters.peer_lost_events += 1;
            self.status.peer_lost_at_ns.store(now, Ordering::Relaxed);
            self.status.peer_lost.store(true, Ordering::Relaxed);
        }
        self.stale_deadline_ns = now.saturating_add(self.settings.stale_timeout_ns);
        self.telemetry_seq += 1;
        let t = &mut *self.telemetry;
        t.header.seq = self.telemetry_seq;
        t.header.stamp_ns = now;
        t.flags = self.command.flags | TELEMETRY_FLAG_PEER_LOST;
        t.counters = self.counters;
        let _ = ports.telemetry.send_copy(*t);
        self.status
            .publish(&self.counters, self.numerical_failures, self.restarts);
    }

    /// Forgets the peer's sequence and the controller's basis memory (a new peer).
    fn restart_peer(&mut self) {
        self.checker.reset();
        self.controller.reset();
        self.resync_run = 0;
        self.restarts += 1;
    }

    /// Classifies the sequence number of the (well-formed) state in
    /// `self.state`: `Ok(Some(missed))` to use it, `Ok(None)` for a duplicate
    /// (not answered), `Err(())` to reject it with the safe command.
    /// `resumed`: the first state after a peer loss.
    fn check_sequence(&mut self, wake: u64, resumed: bool) -> Result<Option<u64>, ()> {
        let seq = self.state.header.seq;
        let mut probe = self.checker;
        let event = probe.observe(seq);
        let plausible = match event {
            SeqEvent::First | SeqEvent::Next => true,
            SeqEvent::Gap { missed } => {
                missed
                    <= max_plausible_gap(
                        wake.saturating_sub(self.last_accepted_ns),
                        self.settings.period_ns,
                    )
            }
            SeqEvent::Duplicate | SeqEvent::Backwards { .. } => false,
        };
        if plausible {
            self.checker = probe;
            self.resync_run = 0;
            self.last_accepted_ns = wake;
            return Ok(Some(match event {
                SeqEvent::Gap { missed } => missed,
                _ => 0,
            }));
        }
        if event == SeqEvent::Duplicate && !resumed {
            return Ok(None);
        }
        // A stream that does not continue the old one: after an outage it is
        // a new peer; otherwise only once RESYNC_RUN rejected states follow
        // each other (a restarted driver), never for a single corrupt one.
        self.resync_run = if self.resync_run > 0 && seq == self.resync_last.wrapping_add(1) {
            self.resync_run + 1
        } else {
            1
        };
        self.resync_last = seq;
        if resumed || self.resync_run >= RESYNC_RUN {
            self.restart_peer();
            self.checker.observe(seq);
            self.last_accepted_ns = wake;
            return Ok(Some(0));
        }
        Err(())
    }

    /// Handles the state in `self.state`, received at `wake` (ns).
    fn process(&mut self, ports: &Ports, wake: u64) -> Outcome {
        let n = self.n;
        let period = wake.saturating_sub(self.last_wake_ns);
        let first_wake = self.last_state_ns.is_none();
        self.last_state_ns = Some(wake);
        self.last_wake_ns = wake;
        self.stale_deadline_ns = wake.saturating_add(self.settings.stale_timeout_ns);
        self.status.connected.store(true, Ordering::Relaxed);
        self.status.last_state_ns.store(wake, Ordering::Relaxed);
        self.status
            .last_state_seq
            .store(self.state.header.seq, Ordering::Relaxed);
        let resumed = self.peer_lost;
        if resumed {
            self.peer_lost = false;
            self.status.peer_lost.store(false, Ordering::Relaxed);
        }
        self.counters.cycles += 1;

        let well_formed = self.state.validate(n).is_ok();
        // Exactly one side adds g(q) (hcc_msgs::check_gravity_agreement).
        let gravity_conflict = well_formed
            && self.state.driver_compensates_gravity() == self.settings.gravity_compensation;
        let mut valid = well_formed && !gravity_conflict;
        if valid {
            match self.check_sequence(wake, resumed) {
                Ok(Some(missed)) => self.counters.missed_states += missed,
                Ok(None) => {
                    self.counters.sequence_errors += 1;
                    self.status
                        .publish(&self.counters, self.numerical_failures, self.restarts);
                    return Outcome::Duplicate;
                }
                Err(()) => {
                    self.counters.sequence_errors += 1;
                    valid = false;
                }
            }
        } else {
            self.counters.invalid_states += 1;
        }

        let mut tau = [0.0; MAX_JOINTS];
        let mut mode = CommandMode::SafeHold;
        // Whether tau contains g(q_v) = gravity_last (for the saturation).
        let mut gravity_in_tau = false;
        if valid {
            let step_start = monotonic_now_ns();
            let result = self.controller.step(self.state.q(), self.state.qd());
            self.timings
                .step
                .record(monotonic_now_ns().saturating_sub(step_start));
            match result {
                // A non-finite τ is an Err of the step itself (hcc-control checks it).
                Ok(out) => {
                    tau[..n].copy_from_slice(out.tau.as_slice());
                    self.gravity_last[..n].copy_from_slice(out.gravity.as_slice());
                    self.have_valid = true;
                    gravity_in_tau = self.settings.gravity_compensation;
                    mode = if out.any_singular {
                        self.counters.singular_cycles += 1;
                        CommandMode::Singular
                    } else {
                        CommandMode::Normal
                    };
                }
                _ => {
                    self.numerical_failures += 1;
                    valid = false;
                }
            }
        }
        if !valid {
            // The defined safe command (module docs).
            let hold_gravity =
                self.settings.gravity_compensation && self.have_valid && !gravity_conflict;
            if hold_gravity {
                tau[..n].copy_from_slice(&self.gravity_last[..n]);
                gravity_in_tau = true;
            } else {
                tau[..n].fill(0.0);
            }
        }

        // Saturation to the torque limits: the control part is scaled as a whole,
        // which keeps the hierarchy (hcc_control::saturate).
        let gravity = gravity_in_tau.then_some(&self.gravity_last[..n]);
        if hcc_control::saturate(&mut tau[..n], gravity, &self.limits[..n]) {
            self.counters.saturations += 1;
        }

        // Command, echoing the state's sequence number.
        self.command_seq += 1;
        let c = &mut self.command;
        c.header.seq = self.command_seq;
        c.header.stamp_ns = monotonic_now_ns();
        c.answer(&self.state);
        c.mode = mode.code();
        c.flags = if self.settings.gravity_compensation && !gravity_conflict {
            COMMAND_FLAG_GRAVITY_INCLUDED
        } else {
            0
        };
        c.tau[..n].copy_from_slice(&tau[..n]);
        if ports.commands.send_copy(*c).is_err() {
            self.counters.send_failures += 1;
        }
        if ports.command_ready.notify().is_err() {
            self.counters.send_failures += 1;
        }
        let sent = monotonic_now_ns();
        // The state's notification, consumed now that it is answered.
        let _ = ports.state_ready.try_wait(|_| {});
        let compute_ns = sent.saturating_sub(wake);
        self.max_compute_ns = self.max_compute_ns.max(compute_ns);
        let latency = wake as i64 - self.state.header.stamp_ns as i64;
        self.timings.compute.record(compute_ns);
        self.timings.wakeup.record_signed(latency);

        // Telemetry (never blocks: safe overflow, discard on a full queue).
        self.fill_telemetry(mode, &tau, valid);
        let t = &mut *self.telemetry;
        t.timings.wakeup_latency_ns = latency;
        t.timings.compute_ns = compute_ns;
        t.timings.period_ns = if first_wake { 0 } else { period };
        t.timings.max_compute_ns = self.max_compute_ns;
        t.header.stamp_ns = monotonic_now_ns();
        let _ = ports.telemetry.send_copy(*t);

        self.status
            .publish(&self.counters, self.numerical_failures, self.restarts);
        self.status
            .max_compute_ns
            .store(self.max_compute_ns, Ordering::Relaxed);
        if latency > 0 {
            self.status
                .max_latency_ns
                .fetch_max(latency as u64, Ordering::Relaxed);
        }
        Outcome::Answered(mode)
    }

    fn fill_telemetry(&mut self, mode: CommandMode, tau: &[f64; MAX_JOINTS], fresh: bool) {
        let n = self.n;
        self.telemetry_seq += 1;
        let t = &mut *self.telemetry;
        t.header.seq = self.telemetry_seq;
        t.state_seq = self.state.header.seq;
        t.command_seq = self.command_seq;
        t.mode = mode.code();
        t.flags = self.command.flags;
        t.tau[..n].copy_from_slice(&tau[..n]);
        t.counters = self.counters;
        if !fresh {
            // Keep the last valid cycle's diagnostics.
            return;
        }
        let out = self.controller.output();
        let mut singular = 0u32;
        for i in 0..self.r {
            if out.singular[i] {
                singular |= 1 << i;
            }
            t.tau_level[i][..n].copy_from_slice(out.tau_level[i].as_slice());
            let m = out.task_error[i].len().min(MAX_TASK_DIM);
            t.task_error[i][..m].copy_from_slice(&out.task_error[i].as_slice()[..m]);
            t.storage[i] = out.storage[i];
            // σ_min/σ_max of the level's Gram factor (square root of the
            // smallest eigenvalue ratio of the inverted Gram matrices).
            t.min_singular_value[i] = out.conditioning[i].max(0.0).sqrt();
        }
        t.singular_levels = singular;
        t.tau_mu[..n].copy_from_slice(out.tau_mu.as_slice());
        if self.settings.gravity_compensation {
            t.tau_gravity[..n].copy_from_slice(out.gravity.as_slice());
        }
        t.p_mu = out.p_mu;
    }
}
