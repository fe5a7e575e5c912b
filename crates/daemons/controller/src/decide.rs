//! The controller's decision for one joint state, without any I/O:
//! validate → sequence → law → safe command → saturate, leaving the
//! [`TorqueCommand`] that answers the state and the telemetry sample in the
//! [`Decider`]'s buffers. [`crate::cycle::Cycle`] is the shell that waits,
//! receives, sends and publishes around it; a test drives [`Decider::decide`]
//! directly, without iceoryx2.
//!
//! The law is the hierarchical compliance controller, paper Eq. (19):
//! τ = Σ τ_i + τ_μ + g, with τ_i of Eqs. (20), (21) and τ_μ of Eq. (22).
//! [`Decider::decide`] allocates nothing, takes no lock, does no logging or
//! formatting; events go to counters ([`LoopCounters`]).
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
//! When no state arrives for the stale timeout, the shell calls
//! [`Decider::stale`]: a stale event is counted, the peer marked lost (once
//! per loss) and a telemetry sample flagged [`TELEMETRY_FLAG_PEER_LOST`]
//! carrying the counters is prepared. When states come back, the stream
//! tells a new peer from the old one: a state that continues the old
//! sequence (the same driver after a stall) is used as is, while one that
//! does not (a restarted driver counts from 0), or [`RESYNC_RUN`] consecutive
//! rejected states that follow each other (a driver restarted without an
//! outage), reset the [`SequenceChecker`] and the controller's null-space
//! basis memory (`Controller::reset`), and control resumes with that peer.
//! (The torque does not depend on the basis, only its last bits do: a state
//! that merely comes late changes nothing, so a lockstep run over IPC stays
//! bit-identical to the in-process one on a loaded machine.)

use hcc_control::Controller;
use hcc_msgs::{
    COMMAND_FLAG_GRAVITY_INCLUDED, CommandMode, JointState, MAX_JOINTS, MAX_LEVELS, MAX_TASK_DIM,
    SeqEvent, SequenceChecker, Setpoint, TELEMETRY_FLAG_PEER_LOST, Telemetry, TelemetryTimings,
    TorqueCommand, monotonic_now_ns,
};

use crate::commander::Commander;
use crate::cycle::{CycleError, CycleSettings};
use crate::output::OutputPipeline;
use crate::status::LoopCounters;

/// Consecutive rejected sequence numbers (backwards or implausible jumps)
/// that follow each other, taken as a restarted peer.
pub const RESYNC_RUN: u32 = 3;

/// Slack of [`max_plausible_gap`], in states.
pub const GAP_SLACK: u64 = 16;

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

/// What [`Decider::decide`] made of a state.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Answer {
    /// Answer with [`Decider::command`], of this mode.
    Command(CommandMode),
    /// A duplicate state: not answered.
    Duplicate,
}

/// How a state is used (validation and sequence).
enum Verdict {
    /// Run the law on it.
    Use,
    /// Answer with the safe command.
    Reject { gravity_conflict: bool },
    /// Do not answer.
    Duplicate,
}

/// The decision state: the control law, the sequence checker, the counters,
/// g(q_v) of the last valid state, and the command and telemetry buffers.
pub struct Decider {
    controller: Controller,
    n: usize,
    r: usize,
    limits: [f64; MAX_JOINTS],
    /// Whether τ includes g(q) (the command's gravity flag).
    gravity_compensation: bool,
    /// Nominal period of the driver's states, ns.
    period_ns: u64,
    command: TorqueCommand,
    telemetry: Box<Telemetry>,
    checker: SequenceChecker,
    counters: LoopCounters,
    command_seq: u64,
    telemetry_seq: u64,
    /// g(q_v) at the last valid state.
    gravity_last: [f64; MAX_JOINTS],
    have_valid: bool,
    /// Consecutive rejected sequence numbers that follow each other.
    resync_run: u32,
    /// Sequence number of the last rejected state of that run.
    resync_last: u64,
    /// Wake-up time of the last state whose sequence number was accepted.
    last_accepted_ns: u64,
    peer_lost: bool,
    /// Duration of `Controller::step` in the last decision, ns.
    step_ns: Option<u64>,
    /// The telemetry of the last command not yet filled: (state's sequence
    /// number, mode, whether the law ran) — [`Decider::fill_telemetry`].
    pending_telemetry: Option<(u64, CommandMode, bool)>,
    /// Setpoints: checks, transitions, answers.
    commander: Commander,
    /// State sequence number of the last well-formed state (setpoint timing).
    clock_seq: u64,
    /// Rate limit and low-pass between the law and the saturation.
    output: OutputPipeline,
    /// Cache warm-up: a copy of the law, stepped on the last decided state while
    /// the loop waits ([`Decider::warm_up`]); its output is discarded.
    warm: Option<Box<Controller>>,
}

impl Decider {
    /// Builds the decision state around `controller` (already constructed
    /// for the robot); checks the sizes and torque limits of `settings`.
    pub fn new(controller: Controller, settings: &CycleSettings) -> Result<Decider, CycleError> {
        let n = controller.nq();
        let r = controller.levels();
        check_shape(n, r, &settings.torque_limits)?;
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
        let commander = Commander::new(&controller, &settings.commanding)?;
        commander.fill(&mut telemetry);
        let warm = settings.warm_up.then(|| Box::new(controller.clone()));
        Ok(Decider {
            warm,
            commander,
            output: OutputPipeline::new(&settings.output, settings.period_ns as f64 * 1e-9),
            controller,
            n,
            r,
            limits,
            gravity_compensation: settings.gravity_compensation,
            period_ns: settings.period_ns,
            command,
            telemetry,
            checker: SequenceChecker::new(),
            counters: LoopCounters::default(),
            command_seq: 0,
            telemetry_seq: 0,
            gravity_last: [0.0; MAX_JOINTS],
            have_valid: false,
            resync_run: 0,
            resync_last: 0,
            last_accepted_ns: 0,
            peer_lost: false,
            step_ns: None,
            pending_telemetry: None,
            clock_seq: 0,
        })
    }

    /// The command answering the last decided state (its `header.stamp_ns`
    /// is set by [`Decider::stamp_command`]).
    pub fn command(&self) -> &TorqueCommand {
        &self.command
    }

    /// The telemetry sample of the last decision (or stale timeout).
    pub fn telemetry(&self) -> &Telemetry {
        &self.telemetry
    }

    /// Every counter so far.
    pub fn counters(&self) -> LoopCounters {
        self.counters
    }

    /// The control law.
    pub fn controller(&self) -> &Controller {
        &self.controller
    }

    /// How long `Controller::step` took in the last decision, ns (`None` if
    /// the law did not run).
    pub fn step_ns(&self) -> Option<u64> {
        self.step_ns
    }

    /// Cache warm-up (`CycleSettings::warm_up`): steps a copy of the law on
    /// `state`, the state of the last decision, if the law ran on it (a valid
    /// state), so that the law's code is in the caches and its branches in the
    /// predictors when the next state comes (the copy's data is its own).
    /// Nothing of it reaches a command; allocation-free. Does nothing when off,
    /// before the first valid state and after a state the law did not run on.
    /// Returns whether the copy was stepped.
    pub fn warm_up(&mut self, state: &JointState) -> bool {
        match self.warm.as_deref_mut() {
            Some(twin) if self.step_ns.is_some() => {
                let _ = twin.step(state.q(), state.qd());
                true
            }
            _ => false,
        }
    }

    /// Whether the peer is lost (a stale timeout since the last state).
    pub fn peer_lost(&self) -> bool {
        self.peer_lost
    }

    /// Takes a client's setpoint now, whatever its application point
    /// (checked against the law, applied through its transition from the
    /// next decision on); the answer goes into the next telemetry sample.
    /// Returns the answer code. Allocation-free.
    pub fn take_setpoint(&mut self, setpoint: &Setpoint) -> u32 {
        let code = self.commander.take(setpoint);
        self.commander.fill(&mut self.telemetry);
        code
    }

    /// The state sequence number that setpoints are timed against in the
    /// cycle of `state` ([`Setpoint::apply_at_state_seq`]): its own when it
    /// is well-formed, else that of the last well-formed state.
    pub fn setpoint_clock(&mut self, state: &JointState) -> u64 {
        if state.validate(self.n).is_ok() {
            self.clock_seq = state.header.seq;
        }
        self.clock_seq
    }

    /// Before the decision of the state `state_seq` (see
    /// [`Decider::setpoint_clock`]): takes the queued setpoints that are due,
    /// in arrival order. Allocation-free.
    pub fn apply_due_setpoints(&mut self, state_seq: u64) {
        if self.commander.apply_due(state_seq) > 0 {
            self.commander.fill(&mut self.telemetry);
        }
    }

    /// A setpoint received in the cycle of the state `state_seq`: taken now
    /// when due, else queued until its state (then answered); see
    /// [`crate::commander::Commander::receive`]. `Some(code)` when answered
    /// now. Allocation-free.
    pub fn receive_setpoint(&mut self, setpoint: &Setpoint, state_seq: u64) -> Option<u32> {
        let code = self.commander.receive(setpoint, state_seq);
        self.commander.fill(&mut self.telemetry);
        code
    }

    /// Setpoints waiting for their state.
    pub fn pending_setpoints(&self) -> usize {
        self.commander.pending()
    }

    /// Decides the answer to `state`, received at `wake_ns` (CLOCK_MONOTONIC,
    /// used only to judge sequence gaps): validate → sequence → law → safe
    /// command → saturate. For [`Answer::Command`], the command and the
    /// telemetry content are left in the buffers. Allocation-free.
    pub fn decide(&mut self, state: &JointState, wake_ns: u64) -> Answer {
        let answer = self.decide_command(state, wake_ns);
        self.fill_telemetry();
        answer
    }

    /// [`Decider::decide`] without the telemetry: only the command is left in
    /// its buffer, the telemetry is filled by [`Decider::fill_telemetry`]
    /// (the loop calls it once the command is out, so that copying the
    /// diagnostics is not on the path from a state to its command; a sample
    /// finished with [`Decider::finish_telemetry`] is complete either way).
    /// Allocation-free.
    pub fn decide_command(&mut self, state: &JointState, wake_ns: u64) -> Answer {
        self.pending_telemetry = None;
        self.step_ns = None;
        let resumed = std::mem::replace(&mut self.peer_lost, false);
        self.counters.telemetry.cycles += 1;
        let mut tau = [0.0; MAX_JOINTS];
        let (law_mode, gravity_conflict) = match self.classify(state, wake_ns, resumed) {
            Verdict::Duplicate => return Answer::Duplicate,
            Verdict::Use => (self.law(state, &mut tau), false),
            Verdict::Reject { gravity_conflict } => (None, gravity_conflict),
        };
        // Whether tau contains g(q_v) = gravity_last (for the saturation).
        let gravity_in_tau = match law_mode {
            Some(_) => {
                self.output_stages(&mut tau);
                self.gravity_compensation
            }
            None => {
                self.output.interrupt();
                self.safe_command(&mut tau, gravity_conflict)
            }
        };
        // Saturation to the torque limits: the control part is scaled as a
        // whole, which keeps the hierarchy (hcc_control::saturate).
        let n = self.n;
        let gravity = gravity_in_tau.then_some(&self.gravity_last[..n]);
        if hcc_control::saturate(&mut tau[..n], gravity, &self.limits[..n]) {
            self.counters.telemetry.saturations += 1;
        }
        let mode = law_mode.unwrap_or(CommandMode::SafeHold);
        self.fill_command(state, mode, gravity_conflict, &tau);
        self.pending_telemetry = Some((state.header.seq, mode, law_mode.is_some()));
        Answer::Command(mode)
    }

    /// Fills the telemetry of the last command decided by
    /// [`Decider::decide_command`] (nothing if it is filled already or the
    /// last state was a duplicate). Allocation-free.
    pub fn fill_telemetry(&mut self) {
        if let Some((state_seq, mode, fresh)) = self.pending_telemetry.take() {
            self.fill_telemetry_of(state_seq, mode, fresh);
        }
    }

    /// Sets the command's stamp (the end of the computation) and returns it, to send.
    pub fn stamp_command(&mut self, now_ns: u64) -> &TorqueCommand {
        self.command.header.stamp_ns = now_ns;
        &self.command
    }

    /// Completes the telemetry sample of an answered state once the command
    /// is out: counts `send_failures`, sets the timings and the publication
    /// stamp, and returns it, to publish.
    pub fn finish_telemetry(
        &mut self,
        send_failures: u64,
        timings: TelemetryTimings,
        now_ns: u64,
    ) -> &Telemetry {
        self.fill_telemetry();
        self.counters.telemetry.send_failures += send_failures;
        let t = &mut *self.telemetry;
        t.counters = self.counters.telemetry;
        t.timings = timings;
        t.header.stamp_ns = now_ns;
        &self.telemetry
    }

    /// No state within the stale timeout: counts a stale event, marks the
    /// peer lost, and prepares a telemetry sample flagged
    /// [`TELEMETRY_FLAG_PEER_LOST`] stamped `now_ns`. Returns whether this
    /// is a new loss.
    pub fn stale(&mut self, now_ns: u64) -> bool {
        self.counters.telemetry.stale_events += 1;
        let new_loss = !self.peer_lost;
        if new_loss {
            self.peer_lost = true;
            self.counters.telemetry.peer_lost_events += 1;
        }
        self.telemetry_seq += 1;
        let t = &mut *self.telemetry;
        t.header.seq = self.telemetry_seq;
        t.header.stamp_ns = now_ns;
        t.flags = self.command.flags | TELEMETRY_FLAG_PEER_LOST;
        t.counters = self.counters.telemetry;
        new_loss
    }

    /// The law's τ through the rate limit and the low-pass (module
    /// [`crate::output`]), counted; nothing when both are off.
    fn output_stages(&mut self, tau: &mut [f64; MAX_JOINTS]) {
        if !self.output.is_active() {
            return;
        }
        let stages = self.output.apply(&mut tau[..self.n]);
        let c = &mut self.counters.telemetry;
        c.rate_limited += u64::from(stages.rate_limited);
        c.low_passed += u64::from(stages.low_passed);
    }

    /// Validation and sequence of `state`, counted.
    fn classify(&mut self, state: &JointState, wake: u64, resumed: bool) -> Verdict {
        let well_formed = state.validate(self.n).is_ok();
        // Exactly one side adds g(q) (hcc_msgs::check_gravity_agreement).
        let gravity_conflict =
            well_formed && state.driver_compensates_gravity() == self.gravity_compensation;
        if !well_formed || gravity_conflict {
            self.counters.telemetry.invalid_states += 1;
            return Verdict::Reject { gravity_conflict };
        }
        match self.check_sequence(state.header.seq, wake, resumed) {
            Ok(Some(missed)) => {
                self.counters.telemetry.missed_states += missed;
                Verdict::Use
            }
            Ok(None) => {
                self.counters.telemetry.sequence_errors += 1;
                Verdict::Duplicate
            }
            Err(()) => {
                self.counters.telemetry.sequence_errors += 1;
                Verdict::Reject {
                    gravity_conflict: false,
                }
            }
        }
    }

    /// Forgets the peer's sequence and the controller's basis memory (a new peer).
    fn restart_peer(&mut self) {
        self.checker.reset();
        self.controller.reset();
        self.resync_run = 0;
        self.counters.daemon.peer_restarts += 1;
    }

    /// Classifies the sequence number `seq` of a well-formed state:
    /// `Ok(Some(missed))` to use it, `Ok(None)` for a duplicate (not
    /// answered), `Err(())` to reject it with the safe command.
    /// `resumed`: the first state after a peer loss.
    fn check_sequence(&mut self, seq: u64, wake: u64, resumed: bool) -> Result<Option<u64>, ()> {
        let mut probe = self.checker;
        let event = probe.observe(seq);
        let plausible = match event {
            SeqEvent::First | SeqEvent::Next => true,
            SeqEvent::Gap { missed } => {
                missed
                    <= max_plausible_gap(wake.saturating_sub(self.last_accepted_ns), self.period_ns)
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

    /// The control law, paper Eq. (19), into `tau`; remembers g(q) as
    /// g(q_v). `None` on a numerical failure (counted).
    fn law(&mut self, state: &JointState, tau: &mut [f64; MAX_JOINTS]) -> Option<CommandMode> {
        let n = self.n;
        // Transitions move by one nominal period per used state (deterministic).
        self.commander
            .advance(self.period_ns as f64 * 1e-9, &mut self.controller);
        let start = monotonic_now_ns();
        let result = self.controller.step(state.q(), state.qd());
        self.step_ns = Some(monotonic_now_ns().saturating_sub(start));
        // A non-finite τ is an Err of the step itself (hcc-control checks it).
        let Ok(out) = result else {
            self.counters.daemon.numerical_failures += 1;
            return None;
        };
        tau[..n].copy_from_slice(out.tau.as_slice());
        self.gravity_last[..n].copy_from_slice(out.gravity.as_slice());
        self.have_valid = true;
        if out.any_singular {
            self.counters.telemetry.singular_cycles += 1;
            Some(CommandMode::Singular)
        } else {
            Some(CommandMode::Normal)
        }
    }

    /// The defined safe command (module docs) into `tau`: g(q_v) when the
    /// controller includes gravity, has a valid state and the driver does
    /// not add g itself, else 0. Returns whether `tau` contains g(q_v).
    fn safe_command(&self, tau: &mut [f64; MAX_JOINTS], gravity_conflict: bool) -> bool {
        let n = self.n;
        let hold_gravity = self.gravity_compensation && self.have_valid && !gravity_conflict;
        if hold_gravity {
            tau[..n].copy_from_slice(&self.gravity_last[..n]);
        } else {
            tau[..n].fill(0.0);
        }
        hold_gravity
    }

    /// The command answering `state` (its sequence number echoed).
    fn fill_command(
        &mut self,
        state: &JointState,
        mode: CommandMode,
        gravity_conflict: bool,
        tau: &[f64; MAX_JOINTS],
    ) {
        let n = self.n;
        self.command_seq += 1;
        let c = &mut self.command;
        c.header.seq = self.command_seq;
        c.answer(state);
        c.mode = mode.code();
        c.flags = if self.gravity_compensation && !gravity_conflict {
            COMMAND_FLAG_GRAVITY_INCLUDED
        } else {
            0
        };
        c.tau[..n].copy_from_slice(&tau[..n]);
    }

    /// The telemetry content of the decision answering state `state_seq`
    /// (its command in `self.command`); with `fresh` false (no law output
    /// this cycle) the last valid cycle's diagnostics are kept.
    fn fill_telemetry_of(&mut self, state_seq: u64, mode: CommandMode, fresh: bool) {
        let n = self.n;
        self.telemetry_seq += 1;
        let t = &mut *self.telemetry;
        t.header.seq = self.telemetry_seq;
        t.state_seq = state_seq;
        t.command_seq = self.command_seq;
        t.mode = mode.code();
        t.flags = self.command.flags;
        t.tau[..n].copy_from_slice(&self.command.tau[..n]);
        t.counters = self.counters.telemetry;
        self.commander.fill(t);
        if !fresh {
            return;
        }
        let out = self.controller.output();
        let mut singular = 0u32;
        for i in 0..self.r {
            if out.singular[i] {
                singular |= 1 << i;
            }
            // τ_i, Eqs. (20), (21); task error x̃_i; storage S_i, Eqs. (26), (28).
            t.tau_level[i][..n].copy_from_slice(out.tau_level[i].as_slice());
            let m = out.task_error[i].len().min(MAX_TASK_DIM);
            t.task_error[i][..m].copy_from_slice(&out.task_error[i].as_slice()[..m]);
            t.storage[i] = out.storage[i];
            // σ_min/σ_max of the level's Gram factor (square root of the
            // smallest eigenvalue ratio of the inverted Gram matrices).
            t.min_singular_value[i] = out.conditioning[i].max(0.0).sqrt();
        }
        t.singular_levels = singular;
        // τ_μ, Eq. (22); P_μ = τ_μᵀ q̇ (Sec. IV-C).
        t.tau_mu[..n].copy_from_slice(out.tau_mu.as_slice());
        if self.gravity_compensation {
            t.tau_gravity[..n].copy_from_slice(out.gravity.as_slice());
        }
        t.p_mu = out.p_mu;
    }
}

/// Checks the sizes against the message capacities and the torque limits.
fn check_shape(n: usize, r: usize, torque_limits: &[f64]) -> Result<(), CycleError> {
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
    if torque_limits.len() != n {
        return Err(CycleError::Shape(format!(
            "controller_daemon.torque_limits has {} entries, the robot {n} joints",
            torque_limits.len()
        )));
    }
    if let Some(k) = torque_limits.iter().position(|l| l.is_nan() || *l <= 0.0) {
        return Err(CycleError::Shape(format!(
            "controller_daemon.torque_limits[{k}] = {} must be positive",
            torque_limits[k]
        )));
    }
    Ok(())
}
