//! The control cycle: one joint state in, the torque command that answers it
//! and a telemetry sample out, without any I/O (see the crate docs).
//!
//! The law is the hierarchical compliance controller, paper Eq. (19):
//! τ = Σ τ_i + τ_μ + g, with τ_i of Eqs. (20), (21) and τ_μ of Eq. (22).
//! [`ControlCycle::step`] allocates nothing, takes no lock, does no logging
//! or formatting; events go to counters ([`CycleCounters`]).
//!
//! # Safe command
//!
//! A state the stream checks reject ([`crate::stream`]: malformed, a gravity
//! conflict, out of sequence) is answered with mode
//! [`CommandMode::SafeHold`] and τ = g(q_v), the gravity torque at the last
//! valid configuration q_v, when the controller includes gravity (and τ = 0
//! otherwise, or before any valid state, or on a gravity conflict, where the
//! driver adds g itself). No damping term is added: the velocity of the last
//! valid state is stale, and a torque −D q̇_v held over several cycles would not
//! be dissipative; damping is the driver's fallback (see the hcc-msgs timing
//! contract). A numerical failure of the control law (which its damped
//! inversions should prevent), including a non-finite τ, is answered the same
//! way. The safe command is saturated like any other, never filtered (a
//! safety stop must not be delayed). A duplicate state is not answered
//! again. Every rejection is counted (`invalid_states`, `sequence_errors`,
//! `numerical_failures`).
//!
//! # Stale state and peer restart
//!
//! When no state arrives for the stale timeout, the caller calls
//! [`ControlCycle::stale`]: a stale event is counted, the peer marked lost
//! (once per loss) and a telemetry sample flagged
//! [`TELEMETRY_FLAG_PEER_LOST`] carrying the counters is prepared. A new
//! peer ([`crate::stream`]) resets the controller's null-space basis memory
//! (`Controller::reset`) and control resumes with it. (The torque does not
//! depend on the basis, only its last bits do: a state that merely comes late
//! changes nothing, so a lockstep run over IPC stays bit-identical to the
//! in-process one on a loaded machine.)
//!
//! # Order within a cycle
//!
//! [`ControlCycle::take_setpoints`] (the setpoints waiting for this state,
//! then those that arrived with it, in arrival order), then
//! [`ControlCycle::decide`] (stream checks → transitions and paths advance one period →
//! law → saturation → torque filter → the output stages' energy tank (module
//! `output_tank`) → velocity limit → command, then telemetry).
//! [`ControlCycle::step`] is both. The controller daemon calls the parts
//! itself to time them, and fills the telemetry once the command is out
//! ([`ControlCycle::decide_command`], [`ControlCycle::fill_telemetry`]).

use hcc_control::Controller;
use hcc_msgs::ipc::SETPOINT_BUFFER;
use hcc_msgs::{
    COMMAND_FLAG_GRAVITY_INCLUDED, CommandMode, JointState, MAX_JOINTS, NO_KNOT, Setpoint,
    SetpointRejection, TELEMETRY_FLAG_CONTACT, TELEMETRY_FLAG_CONTACT_HOLD,
    TELEMETRY_FLAG_PEER_LOST, Telemetry, TelemetryTimings, TorqueCommand, monotonic_now_ns,
};

use crate::contact::ContactWatch;
use crate::counters::CycleCounters;
use crate::load_ramp::LoadRamp;
use crate::output_tank::OutputTank;
use crate::path_gate::PathGate;
use crate::paths::Paths;
use crate::reaction::ContactReaction;
use crate::setpoints::SetpointHandler;
use crate::settings::{CycleError, CycleSettings};
use crate::stream::{StreamCheck, Verdict};
use crate::telemetry;
use crate::torque_filter::TorqueFilter;
use crate::velocity_limit::VelocityLimit;
use crate::wrench::WrenchEstimate;

mod load_messages;
mod path_messages;

/// What [`ControlCycle::decide`] made of a state.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Answer {
    /// Answer with [`ControlCycle::command`], of this mode.
    Command(CommandMode),
    /// A duplicate state: not answered.
    Duplicate,
}

/// The cycle's state: the law, the stream checks, the setpoints, the torque
/// filter, the counters, g(q_v) of the last valid state, and the command and
/// telemetry buffers.
pub struct ControlCycle {
    controller: Controller,
    n: usize,
    limits: [f64; MAX_JOINTS],
    /// Whether τ includes g(q) (the command's gravity flag).
    gravity_compensation: bool,
    /// Nominal period, s (transitions advance by it per used state).
    period_s: f64,
    stream: StreamCheck,
    setpoints: SetpointHandler,
    /// The levels' desired paths (module `paths`).
    paths: Paths,
    /// A load being announced (module `load_ramp`).
    load_ramp: LoadRamp,
    /// Run-time path messages waiting for their feasibility check (module
    /// `path_gate`); `None`: taken at once.
    gate: Option<PathGate>,
    /// `[setpoint_limits]` path_knots and path_check_timeout_ms (the gate's).
    path_knots: usize,
    path_check_timeout_s: f64,
    filter: TorqueFilter,
    /// The discrete-time velocity limit on the torque sent (module
    /// `velocity_limit`; behind a rate limit, the brake certificate).
    velocity_limit: VelocityLimit,
    /// The largest correction it made so far (N·m).
    velocity_limit_largest: f64,
    /// The energy tank of the stages after the law (module `output_tank`).
    output_tank: OutputTank,
    /// The external-torque observer and the contact detection (module
    /// `contact`).
    contact: ContactWatch,
    /// What a contact does to the torque (module `reaction`).
    reaction: ContactReaction,
    /// F̂, the external wrench at the wrench level's frame (module `wrench`).
    wrench: WrenchEstimate,
    command: TorqueCommand,
    telemetry: Box<Telemetry>,
    counters: CycleCounters,
    command_seq: u64,
    telemetry_seq: u64,
    /// The gravity torque the commands carry at the last valid state: g(q_v)
    /// with gravity compensation; the load's alone when the driver
    /// compensates the arm's and the model carries a load
    /// (hcc_control::StepOutput::gravity_load; docs/load.md).
    gravity_last: [f64; MAX_JOINTS],
    /// Whether the commands carry `gravity_last`.
    gravity_carried: bool,
    have_valid: bool,
    peer_lost: bool,
    /// Duration of `Controller::step` in the last decision, ns.
    step_ns: Option<u64>,
    /// The telemetry of the last command not yet filled: (state's sequence
    /// number, mode, whether the law ran) — [`ControlCycle::fill_telemetry`].
    pending_telemetry: Option<(u64, CommandMode, bool)>,
    /// State sequence number of the last well-formed state (setpoint timing).
    clock_seq: u64,
    zeros: [f64; MAX_JOINTS],
}

impl ControlCycle {
    /// Builds the cycle around `controller` (already constructed for the
    /// robot); checks the sizes and torque limits of `settings`. Allocates
    /// every buffer.
    pub fn new(
        mut controller: Controller,
        settings: &CycleSettings,
    ) -> Result<ControlCycle, CycleError> {
        let n = controller.nq();
        let r = controller.levels();
        settings.check(n, r)?;
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
        let setpoints = SetpointHandler::new(&controller, &settings.setpoint_limits)?;
        if settings.tracking.paths.len() > r || settings.tracking.feed_forward.len() > r {
            return Err(CycleError::Shape(format!(
                "paths for {} levels, the controller has {r}",
                settings.tracking.paths.len()
            )));
        }
        let paths = Paths::new(
            &settings.tracking,
            &settings.setpoint_limits,
            settings.period_s(),
            &mut controller,
        );
        let spec = controller.spec();
        let wrench_level = spec.wrench_level();
        let wrench = WrenchEstimate::new(
            wrench_level,
            wrench_level.map_or(0, |i| dims[i]),
            spec.singular_ratio,
        );
        setpoints.fill(&mut telemetry);
        Ok(ControlCycle {
            stream: StreamCheck::new(n, settings.gravity_compensation, settings.period_ns),
            setpoints,
            paths,
            gate: None,
            load_ramp: LoadRamp::new(),
            path_knots: settings.setpoint_limits.path_knots,
            path_check_timeout_s: settings.setpoint_limits.path_check_timeout_ms * 1e-3,
            filter: TorqueFilter::new(&settings.torque_filter, settings.period_s()),
            velocity_limit: VelocityLimit::new(&controller, &limits, settings.period_s()),
            velocity_limit_largest: 0.0,
            output_tank: OutputTank::new(
                spec.safety.enabled && spec.safety.energy_tanks,
                spec.safety.tank_initial,
                spec.safety.tank_max,
                settings.period_s(),
            ),
            contact: ContactWatch::new(&settings.contact),
            reaction: ContactReaction::new(&settings.contact),
            wrench,
            controller,
            n,
            limits,
            gravity_compensation: settings.gravity_compensation,
            period_s: settings.period_s(),
            command,
            telemetry,
            counters: CycleCounters::default(),
            command_seq: 0,
            telemetry_seq: 0,
            gravity_last: [0.0; MAX_JOINTS],
            gravity_carried: settings.gravity_compensation,
            have_valid: false,
            peer_lost: false,
            step_ns: None,
            pending_telemetry: None,
            clock_seq: 0,
            zeros: [0.0; MAX_JOINTS],
        })
    }

    /// The command answering the last decided state (its `header.stamp_ns`
    /// is set by [`ControlCycle::stamp_command`]).
    pub fn command(&self) -> &TorqueCommand {
        &self.command
    }

    /// The telemetry sample of the last decision (or stale timeout).
    pub fn telemetry(&self) -> &Telemetry {
        &self.telemetry
    }

    /// Every counter so far.
    pub fn counters(&self) -> CycleCounters {
        self.counters
    }

    /// The control law (after the last decision: its output and terms at that state).
    pub fn controller(&self) -> &Controller {
        &self.controller
    }

    /// The storage H of the last decision (J): the law's
    /// (`hcc_control::SafetyOutput::h`) and the tank of the stages after it
    /// (module `output_tank`).
    pub fn storage(&self) -> f64 {
        self.controller.output().safety.h + self.output_tank.energy_at_sample()
    }

    /// How long `Controller::step` took in the last decision, ns (`None` if
    /// the law did not run).
    pub fn step_ns(&self) -> Option<u64> {
        self.step_ns
    }

    /// r, the estimate of the external joint torque τ_ext at the last used
    /// state (N·m, length n; the generalized-momentum observer, module
    /// `contact`).
    pub fn external_torque(&self) -> &[f64] {
        self.contact.residual()
    }

    /// F̂ = pinv(J_iᵀ) r, the estimate of the external wrench at the frame
    /// of level [`ControlCycle::wrench_level`] at the last used state (its
    /// task rows: N along world axes, then N·m for a pose; empty without such
    /// a level; module `wrench`).
    pub fn external_wrench(&self) -> &[f64] {
        self.wrench.wrench()
    }

    /// The level (0-based) whose frame [`ControlCycle::external_wrench`] is
    /// at: the first position or pose level
    /// (`hcc_control::ControllerSpec::wrench_level`).
    pub fn wrench_level(&self) -> Option<usize> {
        self.wrench.level()
    }

    /// Whether the contact detection flags a contact.
    pub fn in_contact(&self) -> bool {
        self.contact.in_contact()
    }

    /// How far the contact reaction acts, in [0, 1] (0: the law as
    /// configured; module `reaction`), and the law's stiffness factor κ.
    pub fn reaction_level(&self) -> (f64, f64) {
        (self.reaction.level(), self.controller.stiffness_scale())
    }

    /// Whether a contact hold is latched (`[contact] reaction = "hold"`; an
    /// accepted setpoint releases it).
    pub fn holding(&self) -> bool {
        self.reaction.held()
    }

    /// The telemetry flags of the contact watch: a contact flagged, a hold
    /// latched.
    fn contact_flags(&self) -> u32 {
        let mut flags = 0;
        if self.contact.in_contact() {
            flags |= TELEMETRY_FLAG_CONTACT;
        }
        if self.reaction.held() {
            flags |= TELEMETRY_FLAG_CONTACT_HOLD;
        }
        flags
    }

    /// Whether the peer is lost (a stale timeout since the last state).
    pub fn peer_lost(&self) -> bool {
        self.peer_lost
    }

    /// One cycle (libfranka's shape: one call from state to command): takes
    /// the setpoints `next_setpoint` yields (those that arrived with the
    /// state, at most [`SETPOINT_BUFFER`]), then decides the answer to
    /// `state`, received at `wake_ns` (CLOCK_MONOTONIC, used only to judge
    /// sequence gaps). For [`Answer::Command`] the command and the telemetry
    /// content are left in the buffers. Allocation-free.
    pub fn step(
        &mut self,
        state: &JointState,
        wake_ns: u64,
        next_setpoint: impl FnMut() -> Option<Setpoint>,
    ) -> Answer {
        self.take_setpoints(state, next_setpoint);
        self.decide(state, wake_ns)
    }

    /// Before the decision of `state`: takes the queued setpoints that are
    /// due at it, then every setpoint `next_setpoint` yields (at most
    /// [`SETPOINT_BUFFER`]: bounded work), in arrival order — each taken at
    /// once when due, else queued until its state
    /// ([`SetpointHandler::receive`]). Setpoints are timed against the
    /// state's sequence number when it is well-formed, else against the last
    /// well-formed state's. Allocation-free.
    pub fn take_setpoints(
        &mut self,
        state: &JointState,
        mut next_setpoint: impl FnMut() -> Option<Setpoint>,
    ) {
        if self.stream.well_formed(state) {
            self.clock_seq = state.header.seq;
        }
        let clock = self.clock_seq;
        let mut changed = self.setpoints.apply_due(clock, &mut self.controller) > 0;
        for _ in 0..SETPOINT_BUFFER {
            let Some(setpoint) = next_setpoint() else {
                break;
            };
            match self.gate.as_mut() {
                // Behind its client's path messages (module `path_gate`).
                Some(gate) if gate.holds_client(setpoint.client_id) => {
                    if !gate.defer(&setpoint) {
                        let code = (SetpointRejection::PendingFull.code(), NO_KNOT);
                        let (client, seq) = (setpoint.client_id, setpoint.header.seq);
                        self.setpoints
                            .record_answer(client, seq, setpoint.level, code);
                    }
                }
                _ => {
                    self.setpoints
                        .receive(&setpoint, clock, &mut self.controller);
                }
            }
            changed = true;
        }
        if changed {
            self.setpoints.fill(&mut self.telemetry);
        }
    }

    /// Takes a client's setpoint now, whatever its application point
    /// (checked against the law, applied through its transition from the
    /// next decision on); the answer goes into the next telemetry sample.
    /// Returns the answer code. What a replay does with the setpoints a
    /// recording says were taken in a cycle. Allocation-free.
    pub fn take_setpoint_now(&mut self, setpoint: &Setpoint) -> u32 {
        let code = self.setpoints.take(setpoint, &mut self.controller);
        self.setpoints.fill(&mut self.telemetry);
        code
    }

    /// Setpoints waiting for their state.
    pub fn pending_setpoints(&self) -> usize {
        self.setpoints.pending()
    }

    /// Decides the answer to `state`, received at `wake_ns`: stream checks →
    /// law → saturation → torque filter, then the telemetry. For
    /// [`Answer::Command`], the command and the telemetry content are left in
    /// the buffers. Allocation-free.
    pub fn decide(&mut self, state: &JointState, wake_ns: u64) -> Answer {
        let answer = self.decide_command(state, wake_ns);
        self.fill_telemetry();
        answer
    }

    /// [`ControlCycle::decide`] without the telemetry: only the command is
    /// left in its buffer, the telemetry is filled by
    /// [`ControlCycle::fill_telemetry`] (the daemon calls it once the command
    /// is out, so that copying the diagnostics is not on the path from a
    /// state to its command; a sample finished with
    /// [`ControlCycle::finish_telemetry`] is complete either way).
    /// Allocation-free.
    pub fn decide_command(&mut self, state: &JointState, wake_ns: u64) -> Answer {
        self.pending_telemetry = None;
        self.step_ns = None;
        let resumed = std::mem::replace(&mut self.peer_lost, false);
        self.counters.telemetry.cycles += 1;
        let mut tau = [0.0; MAX_JOINTS];
        let (law_mode, gravity_conflict) = match self.classify(state, wake_ns, resumed) {
            None => return Answer::Duplicate,
            Some(Ok(())) => (self.law(state, &mut tau), false),
            Some(Err(gravity_conflict)) => (None, gravity_conflict),
        };
        if law_mode.is_none() {
            // A fault: the observer starts again (module `contact`).
            self.contact.reset();
            self.wrench.clear();
        }
        // Whether tau contains gravity_last (for the saturation).
        let gravity_in_tau = match law_mode {
            Some(_) => self.gravity_carried,
            None => self.safe_command(&mut tau, gravity_conflict),
        };
        // Saturation to the torque limits: the control part is scaled as a
        // whole, which keeps the hierarchy (hcc_control::saturate).
        let n = self.n;
        let gravity = gravity_in_tau.then_some(&self.gravity_last[..n]);
        if hcc_control::saturate(&mut tau[..n], gravity, &self.limits[..n]) {
            self.counters.telemetry.saturations += 1;
        }
        // Then the torque filter, on what is commanded: its rate limit bounds
        // the step from the previous command itself, and a step between two
        // torques within the limits stays within them. The safe command is
        // never filtered (a safety stop must not be delayed).
        match law_mode {
            Some(_) => self.filter_torque(&mut tau),
            None => self.filter.bypass(&tau[..n]),
        }
        if law_mode.is_some() {
            self.hold_energy(state, &mut tau);
            self.limit_velocity(state, gravity_in_tau, &mut tau);
            let controller = &mut self.controller;
            let draw = |e| controller.draw_tank_spare(e);
            self.output_tank.book(&state.qd()[..n], &tau[..n], draw);
            // mJ, rounded up: energy fed in is never shown as 0.
            self.counters.core.energy_unpaid_mj = (self.output_tank.unpaid() * 1e3).ceil() as u64;
        }
        let mode = law_mode.unwrap_or(CommandMode::SafeHold);
        self.fill_command(state, mode, gravity_conflict, &tau);
        self.pending_telemetry = Some((state.header.seq, mode, law_mode.is_some()));
        Answer::Command(mode)
    }

    /// Fills the telemetry of the last command decided by
    /// [`ControlCycle::decide_command`] (nothing if it is filled already or
    /// the last state was a duplicate). Allocation-free.
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
        let flags = self.command.flags | TELEMETRY_FLAG_PEER_LOST | self.contact_flags();
        let t = &mut *self.telemetry;
        t.header.seq = self.telemetry_seq;
        t.header.stamp_ns = now_ns;
        t.flags = flags;
        t.counters = self.counters.telemetry;
        new_loss
    }

    /// The stream checks of `state`, counted: `None` for a duplicate (no
    /// answer), `Some(Ok(()))` to run the law, `Some(Err(gravity_conflict))`
    /// to answer with the safe command. A new peer resets the law's basis
    /// memory.
    fn classify(
        &mut self,
        state: &JointState,
        wake: u64,
        resumed: bool,
    ) -> Option<Result<(), bool>> {
        let c = &mut self.counters;
        match self.stream.classify(state, wake, resumed) {
            Verdict::Use { missed, new_peer } => {
                c.telemetry.missed_states += missed;
                if new_peer {
                    c.core.peer_restarts += 1;
                    self.controller.reset();
                    self.output_tank.reset();
                    self.contact.reset();
                    self.wrench.clear();
                }
                Some(Ok(()))
            }
            Verdict::Invalid { gravity_conflict } => {
                c.telemetry.invalid_states += 1;
                Some(Err(gravity_conflict))
            }
            Verdict::OutOfSequence => {
                c.telemetry.sequence_errors += 1;
                Some(Err(false))
            }
            Verdict::Duplicate => {
                c.telemetry.sequence_errors += 1;
                None
            }
        }
    }

    /// The law's τ through the torque filter (module
    /// [`crate::torque_filter`]), counted; nothing when it is off.
    fn filter_torque(&mut self, tau: &mut [f64; MAX_JOINTS]) {
        if !self.filter.is_active() {
            return;
        }
        let n = self.n;
        // Before any command the driver holds g(q) (or nothing, when it adds
        // gravity itself).
        let hold = if self.gravity_compensation {
            &self.gravity_last[..n]
        } else {
            &self.zeros[..n]
        };
        let stages = self.filter.apply(&mut tau[..n], hold);
        let c = &mut self.counters.telemetry;
        c.rate_limited += u64::from(stages.rate_limited);
        c.low_passed += u64::from(stages.low_passed);
    }

    /// What the stages after the law feed in beyond what their tank pays is
    /// held back (module `output_tank`), counted; the filter's next step
    /// starts from what is sent.
    fn hold_energy(&mut self, state: &JointState, tau: &mut [f64; MAX_JOINTS]) {
        let n = self.n;
        if self.output_tank.hold(
            &state.qd()[..n],
            &self.controller.model_terms().m,
            self.controller.tank_spare(),
            &mut tau[..n],
            &self.limits[..n],
            self.filter.rate_limit(n),
        ) {
            self.counters.core.energy_held += 1;
            if self.filter.is_active() {
                self.filter.bypass(&tau[..n]);
            }
        }
    }

    /// The discrete-time velocity limit on the law's torque about to be sent
    /// (module `velocity_limit`), counted.
    fn limit_velocity(
        &mut self,
        state: &JointState,
        gravity_in_tau: bool,
        tau: &mut [f64; MAX_JOINTS],
    ) {
        let n = self.n;
        let rate = self.filter.rate_limit(n);
        let gravity = gravity_in_tau.then_some(&self.gravity_last[..n]);
        let out = self.velocity_limit.apply(
            &self.controller,
            &state.qd()[..n],
            gravity,
            rate,
            &mut tau[..n],
        );
        if let Some(out) = out.filter(|o| o.acted) {
            let c = &mut self.counters.telemetry;
            c.velocity_limited += 1;
            c.velocity_limit_fallbacks += u64::from(out.fallback);
            self.velocity_limit_largest = self.velocity_limit_largest.max(out.largest_correction);
            // mN·m, rounded up: a correction is never shown as 0.
            c.velocity_limit_max_correction_mnm = (self.velocity_limit_largest * 1e3).ceil() as u64;
            // The filter's next step starts from what is sent.
            if self.filter.is_active() {
                self.filter.bypass(&tau[..n]);
            }
        }
    }

    /// The largest correction the discrete-time velocity limit made so far
    /// (N·m; 0 while it has not acted).
    pub fn velocity_limit_largest_correction(&self) -> f64 {
        self.velocity_limit_largest
    }

    /// The control law, paper Eq. (19), into `tau`; remembers g(q) as
    /// g(q_v). `None` on a numerical failure (counted).
    fn law(&mut self, state: &JointState, tau: &mut [f64; MAX_JOINTS]) -> Option<CommandMode> {
        let n = self.n;
        // Transitions move by one nominal period per used state (deterministic).
        self.setpoints.advance(self.period_s, &mut self.controller);
        // The levels' paths, after the transitions: a path drives its level
        // until a goal setpoint takes it (module `paths`).
        self.paths
            .advance(self.period_s, &mut self.controller, &mut self.setpoints);
        self.counters.core.paths_stopped = self.paths.stopped;
        self.counters.core.streams_stopped = self.setpoints.streams_stopped;
        self.counters.core.gain_ramp_held = self.setpoints.gains_held;
        self.counters.core.goal_ramp_held = self.setpoints.goals_held;
        self.counters.core.command_unpaid_mj =
            (1e3 * self.controller.command_tank().1).round() as u64;
        // A load being announced moves the model on (module `load_ramp`).
        let announcing = self.load_ramp.active();
        if !self
            .load_ramp
            .advance(self.period_s, &mut self.controller, state.q(), state.qd())
        {
            self.counters.core.load_ramp_held += 1;
        }
        // The contact reaction, from the flag of the previous state (module `reaction`).
        self.reaction.before_law(
            self.contact.in_contact(),
            self.contact.began(),
            self.setpoints.accepted(),
            self.period_s,
            &mut self.controller,
        );
        self.counters.core.reaction_restore_held = self.reaction.restore_held;
        // With a rate limit the robot's torque lags the law's: the law's
        // velocity barrier is told what is applied (hcc_control::safety).
        let applied = self.filter.rate_limited_previous().map(|p| &p[..n]);
        self.controller.set_applied_torque(applied);
        let start = monotonic_now_ns();
        let result = self.controller.step(state.q(), state.qd());
        self.step_ns = Some(monotonic_now_ns().saturating_sub(start));
        // A non-finite τ is an Err of the step itself (hcc-control checks it).
        let Ok(out) = result else {
            self.counters.core.numerical_failures += 1;
            return None;
        };
        tau[..n].copy_from_slice(out.tau.as_slice());
        let carried = if self.gravity_compensation {
            &out.gravity
        } else {
            &out.gravity_load
        };
        self.gravity_last[..n].copy_from_slice(carried.as_slice());
        self.gravity_carried = self.gravity_compensation || out.load_gravity_in_tau;
        let gravity = self.gravity_carried.then_some(&self.gravity_last[..n]);
        self.reaction.blend(&mut tau[..n], gravity, state.qd());
        self.output_tank.set_law(&tau[..n]);
        self.have_valid = true;
        let singular = out.any_singular;
        // The observer reads the model terms the law computed at this state
        // and the previous command, still in its buffer (module `contact`).
        self.contact.update(
            state,
            self.controller.model_terms(),
            &self.command,
            self.gravity_carried.then_some(&self.gravity_last[..n]),
            (self.period_s, announcing),
            &mut self.counters.core,
        );
        if let Some(i) = self.wrench.level() {
            let r = self.contact.residual();
            self.wrench.update(self.controller.task_jacobian(i), r);
        }
        if singular {
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
        let hold_gravity = self.gravity_carried && self.have_valid && !gravity_conflict;
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
        let flags = self.command.flags | self.contact_flags();
        let t = &mut *self.telemetry;
        t.header.seq = self.telemetry_seq;
        t.state_seq = state_seq;
        t.command_seq = self.command_seq;
        t.mode = mode.code();
        t.flags = flags;
        t.tau[..n].copy_from_slice(&self.command.tau[..n]);
        t.tau_ext[..n].copy_from_slice(self.contact.residual());
        t.counters = self.counters.telemetry;
        self.setpoints.fill(t);
        let load = &self.controller.model().load;
        t.load_mass = load.mass;
        t.load_com = load.com.into();
        t.load_progress = self.load_ramp.progress();
        if fresh {
            let gravity = self.gravity_carried.then_some(&self.gravity_last[..n]);
            telemetry::write_law_terms(t, self.controller.output(), gravity);
            t.h += self.output_tank.energy_at_sample();
        }
    }
}
