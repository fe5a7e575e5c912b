//! Setpoints applied to the running law, allocation-free.
//!
//! [`SetpointHandler::take`] checks a [`Setpoint`] — first the model-free checks of
//! [`Setpoint::validate`], then against the law: a full K and D positive
//! definite, the level exists, `dim` equals m_i, every eigenvalue of K ≤ the
//! level's `max_stiffness`, joint goals
//! inside the URDF limits, position goals inside the level's workspace (the
//! `[[setpoint_limits.level]]` box, by default the ball the chain reaches from its
//! root) — and, if accepted, starts the level's transition
//! ([`hcc_control::transition::Transition`]: minimum-jerk equilibrium, slerp
//! for orientation tasks and a pose level's orientation rows, convex gains).
//! A transition shorter than the level's speed limit allows is
//! **stretched** to it: the equilibrium's peak speed 15/8 · |Δx| / T stays
//! ≤ `max_speed` (|Δx| the Euclidean distance, the rotation angle for
//! orientation, √(|Δp|² + θ²) for a pose). The answer (accepted, or a
//! rejection code, with the duration in force) is kept per client for
//! telemetry.
//!
//! [`SetpointHandler::receive`] is the cycle's entry: a setpoint whose
//! application point ([`Setpoint::apply_at_state_seq`]) the current state has
//! reached is taken at once; one due later waits in a preallocated queue of
//! [`MAX_PENDING_SETPOINTS`](hcc_msgs::MAX_PENDING_SETPOINTS) (arrival order) until [`SetpointHandler::apply_due`]
//! finds its state, and is answered then. The model-free checks reject at
//! receipt; a full queue rejects with [`SetpointRejection::PendingFull`]. A setpoint
//! that arrives after its state is taken at once and counted late.
//!
//! [`SetpointHandler::advance`] moves every transition by one period and hands
//! x_{i,d}(t), K_i(t), D_i(t) and — with `relative_damping` — ẋ_{i,d}(t) to
//! the law (`ramp_goal`, `ramp_gains`, `set_goal_velocity`). A taken setpoint
//! is a command: the law refills its energy tanks (`command_taken`), and a
//! goal setpoint grants its command tank the energy the step to its target
//! would store (`grant_goal_step`). The goal's steps are paid from the command
//! tank (its work on the level's spring and damper); a step neither it nor
//! the tanks' spare can pay holds the goal's clock (counted,
//! `goal_ramp_held`). Each step of the gains is booked against the tanks, and
//! a stiffening they cannot pay holds the gains' clock until they can
//! (counted, `gain_ramp_held`). Nothing
//! changes for a level that never received a setpoint, so a run without
//! setpoints is bit-identical to one without this module.

use hcc_control::transition::{GoalKind, Target, Transition};
use hcc_control::{Controller, TaskSpec};
use hcc_msgs::{
    ANSWER_ACCEPTED, MAX_LEVELS, MAX_SETPOINT_CLIENTS, MAX_TASK_DIM, NO_KNOT, SETPOINT_DAMPING,
    SETPOINT_GOAL, SETPOINT_STIFFNESS, SETPOINT_VELOCITY, Setpoint, SetpointAnswer,
    SetpointRejection, Telemetry, answer_code,
};
use hcc_spec::setpoint_limits::SetpointLimits;
use nalgebra::DMatrix;

use crate::settings::CycleError;

mod gain_check;
mod pending;
mod workspace;

use pending::Pending;
use workspace::Workspace;

/// One level's limits and state.
struct LevelState {
    transition: Transition,
    max_stiffness: f64,
    max_speed: f64,
    workspace: Workspace,
    /// Joint indices of a joint task (goal entry a ↔ joint `joints[a]`).
    joints: Option<Vec<usize>>,
    /// Whether the law must be updated this cycle (a transition runs or just ended).
    active: bool,
    /// Goal setpoints taken for the level so far (a path stops driving it
    /// when one is taken after it began).
    goals_taken: u64,
    /// The velocity feed-forward of the last setpoint that set one, and the
    /// time since (a stream that stops: [`STREAM_TIMEOUT_S`]).
    feed_forward: [f64; MAX_TASK_DIM],
    feed_forward_age_s: f64,
    k: DMatrix<f64>,
    d: DMatrix<f64>,
}

/// A velocity feed-forward is held this long after the setpoint that set it
/// (a stream of goal and velocity refreshes it every cycle); then it fades
/// linearly to zero over [`STREAM_FADE_S`]: a stream that stops leaves the
/// equilibrium at its last goal at rest, without a step in the damping's
/// reference. Counted (`streams_stopped`).
pub const STREAM_TIMEOUT_S: f64 = 0.05;
/// How long the feed-forward of a stream that stopped fades, s.
pub const STREAM_FADE_S: f64 = 0.05;

/// The setpoint side of the control cycle (see the module docs).
pub struct SetpointHandler {
    levels: Vec<LevelState>,
    relative_damping: bool,
    lower: Vec<f64>,
    upper: Vec<f64>,
    answers: [SetpointAnswer; MAX_SETPOINT_CLIENTS],
    /// Per answer slot: when the client was last heard (a running count).
    heard: [u64; MAX_SETPOINT_CLIENTS],
    count: u64,
    zeros: [f64; MAX_TASK_DIM],
    pending: Pending,
    /// Setpoints accepted so far (a contact hold's release).
    accepted: u64,
    /// Setpoint streams whose feed-forward faded because they stopped.
    pub(crate) streams_stopped: u64,
    /// Cycles in which a level's gains transition held: the energy tanks
    /// could not pay its stiffening (`Controller::ramp_gains`).
    pub(crate) gains_held: u64,
    /// Level-cycles in which a goal's step was held: neither the command
    /// tank nor the tanks' spare could pay its work (`Controller::ramp_goal`).
    pub(crate) goals_held: u64,
}

impl SetpointHandler {
    /// Limits from `settings` (one entry per level) for `controller`'s levels.
    /// Allocates.
    pub fn new(
        controller: &Controller,
        settings: &SetpointLimits,
    ) -> Result<SetpointHandler, CycleError> {
        let r = controller.levels();
        if settings.levels.len() != r {
            return Err(CycleError::Shape(format!(
                "setpoint_limits has limits for {} levels, the controller {r}",
                settings.levels.len()
            )));
        }
        let model = controller.model();
        let lower = model.joints.iter().map(|j| j.lower).collect();
        let upper = model.joints.iter().map(|j| j.upper).collect();
        let mut levels = Vec::with_capacity(r);
        for (i, limits) in settings.levels.iter().enumerate() {
            let spec = &controller.spec().levels[i];
            let target = controller
                .level_target(i)
                .ok_or_else(|| CycleError::Shape(format!("no level {i}")))?;
            // An orientation task and a pose level's roll, pitch, yaw rows
            // move on SO(3) (slerp); every other level, stacked ones
            // included, row by row.
            let kind = match spec.tasks.as_slice() {
                [TaskSpec::Orientation { .. }] => GoalKind::RollPitchYaw,
                [TaskSpec::Pose { .. }] => GoalKind::Pose,
                _ => GoalKind::Vector,
            };
            let transition = Transition::new(kind, target.goal, target.stiffness, target.damping)
                .map_err(|e| CycleError::Shape(e.to_string()))?;
            let workspace = Workspace::of_level(controller, spec, limits.workspace.as_ref());
            let joints = match spec.tasks.as_slice() {
                [TaskSpec::Joints { indices }] => Some(indices.clone()),
                [TaskSpec::Posture] => Some((0..controller.nq()).collect()),
                _ => None,
            };
            let m = controller.task_dim(i);
            levels.push(LevelState {
                transition,
                max_stiffness: limits.max_stiffness,
                max_speed: limits.max_speed,
                workspace,
                joints,
                active: false,
                goals_taken: 0,
                feed_forward: [0.0; MAX_TASK_DIM],
                feed_forward_age_s: 0.0,
                k: DMatrix::zeros(m, m),
                d: DMatrix::zeros(m, m),
            });
        }
        Ok(SetpointHandler {
            levels,
            relative_damping: settings.relative_damping,
            lower,
            upper,
            answers: [SetpointAnswer::default(); MAX_SETPOINT_CLIENTS],
            heard: [0; MAX_SETPOINT_CLIENTS],
            count: 0,
            zeros: [0.0; MAX_TASK_DIM],
            pending: Pending::new(),
            accepted: 0,
            streams_stopped: 0,
            gains_held: 0,
            goals_held: 0,
        })
    }

    /// Checks `setpoint`, starts its transition if accepted, and records the
    /// answer for its client, now (whatever its application point). Returns
    /// the answer code. Allocation-free.
    pub fn take(&mut self, setpoint: &Setpoint, controller: &mut Controller) -> u32 {
        self.take_counted(setpoint, false, controller)
    }

    fn take_counted(
        &mut self,
        setpoint: &Setpoint,
        late: bool,
        controller: &mut Controller,
    ) -> u32 {
        let result = self
            .check(setpoint)
            .and_then(|()| self.check_gain_rate(setpoint, controller));
        let duration = match result {
            Ok(()) => self.start(setpoint, controller),
            Err(_) => 0.0,
        };
        let code = answer_code(result);
        self.accepted += u64::from(code == ANSWER_ACCEPTED);
        self.record(setpoint, (code, NO_KNOT), duration, late);
        code
    }

    /// A setpoint received in the cycle of the state with sequence number
    /// `state_seq` (module docs): taken now when due (`Some(code)`), or
    /// queued until [`SetpointHandler::apply_due`] reaches its state (`None`).
    /// Rejected at once by the model-free checks or a full queue.
    /// Allocation-free.
    pub fn receive(
        &mut self,
        setpoint: &Setpoint,
        state_seq: u64,
        controller: &mut Controller,
    ) -> Option<u32> {
        if let Err(r) = setpoint.validate() {
            self.record(setpoint, (r.code(), NO_KNOT), 0.0, false);
            return Some(r.code());
        }
        let at = setpoint.apply_at_state_seq;
        if at <= state_seq {
            // Late: its state has already been answered.
            return Some(self.take_counted(setpoint, at < state_seq, controller));
        }
        if self.pending.push(setpoint) {
            return None;
        }
        let code = SetpointRejection::PendingFull.code();
        self.record(setpoint, (code, NO_KNOT), 0.0, false);
        Some(code)
    }

    /// Takes, in arrival order, every queued setpoint whose application
    /// point the state `state_seq` has reached. Bounded by
    /// [`MAX_PENDING_SETPOINTS`](hcc_msgs::MAX_PENDING_SETPOINTS); allocation-free. Returns how many it took.
    pub fn apply_due(&mut self, state_seq: u64, controller: &mut Controller) -> usize {
        let mut taken = 0;
        let mut k = 0;
        while k < self.pending.len {
            let slot = self.pending.order[k];
            if self.pending.slots[slot].apply_at_state_seq > state_seq {
                k += 1;
                continue;
            }
            let sp = self.pending.slots[slot];
            self.pending.remove(k);
            self.take_counted(&sp, false, controller);
            taken += 1;
        }
        taken
    }

    /// Setpoints accepted so far.
    pub fn accepted(&self) -> u64 {
        self.accepted
    }

    /// Setpoints waiting for their state.
    pub fn pending(&self) -> usize {
        self.pending.len
    }

    /// The law-side checks (module docs), after the model-free ones.
    fn check(&self, sp: &Setpoint) -> Result<(), SetpointRejection> {
        sp.validate()?;
        gain_check::check_positive_definite(sp)?;
        let level = self
            .levels
            .get(sp.level as usize)
            .ok_or(SetpointRejection::UnknownLevel)?;
        let m = level.transition.dim();
        if sp.dim() != m {
            return Err(SetpointRejection::DimensionMismatch);
        }
        if sp.sets(SETPOINT_STIFFNESS) && !gain_check::stiffness_within(sp, level.max_stiffness) {
            return Err(SetpointRejection::StiffnessAboveLimit);
        }
        if !sp.sets(SETPOINT_GOAL) {
            return Ok(());
        }
        self.check_goal(sp.level as usize, &sp.goal()[..m])
    }

    /// The gains of a checked setpoint against the control rate at the
    /// state of the last cycle (hcc_control::rate): K or D more than the
    /// period carries is refused with [`SetpointRejection::GainsAboveRate`]. Leaves the
    /// symmetrised gains in the level's buffers for [`SetpointHandler::start`].
    fn check_gain_rate(
        &mut self,
        sp: &Setpoint,
        controller: &mut Controller,
    ) -> Result<(), SetpointRejection> {
        let i = sp.level as usize;
        let level = &mut self.levels[i];
        let m = level.transition.dim();
        for a in 0..m {
            for b in 0..m {
                // Symmetrised, so the law's exact symmetry check holds.
                level.k[(a, b)] = 0.5 * (sp.stiffness_at(a, b) + sp.stiffness_at(b, a));
                level.d[(a, b)] = 0.5 * (sp.damping_at(a, b) + sp.damping_at(b, a));
            }
        }
        let (k, d) = (
            sp.sets(SETPOINT_STIFFNESS).then_some(&level.k),
            sp.sets(SETPOINT_DAMPING).then_some(&level.d),
        );
        if k.is_none() && d.is_none() {
            return Ok(());
        }
        controller
            .check_gain_rate(i, k, d)
            .map_err(|_| SetpointRejection::GainsAboveRate)
    }

    /// Starts the accepted setpoint's transition (its gains symmetrised by
    /// [`SetpointHandler::check_gain_rate`]); returns its duration (s),
    /// stretched to the level's speed limit.
    fn start(&mut self, sp: &Setpoint, controller: &mut Controller) -> f64 {
        let level = &mut self.levels[sp.level as usize];
        let mut duration = sp.duration_s;
        if sp.sets(SETPOINT_GOAL) {
            level.goals_taken += 1;
            let distance = level.transition.distance_to(sp.goal());
            // Peak speed of the quintic profile: 15/8 · distance / T.
            duration = duration.max(1.875 * distance / level.max_speed);
        }
        let target = Target {
            goal: sp.sets(SETPOINT_GOAL).then(|| sp.goal()),
            stiffness: sp.sets(SETPOINT_STIFFNESS).then_some(&level.k),
            damping: sp.sets(SETPOINT_DAMPING).then_some(&level.d),
        };
        level.transition.start(target, duration);
        controller.command_taken();
        if sp.sets(SETPOINT_GOAL) {
            // Checked above: the grant cannot fail.
            let _ = controller.grant_goal_step(sp.level as usize, sp.goal());
        }
        if sp.sets(SETPOINT_VELOCITY) {
            level.transition.set_feed_forward(sp.velocity());
            let m = sp.velocity().len();
            level.feed_forward[..m].copy_from_slice(sp.velocity());
            level.feed_forward_age_s = 0.0;
        }
        level.active = true;
        duration
    }

    /// Keeps the answer (its code and the knot refused, `NO_KNOT` for a
    /// setpoint) in the client's slot (or the least recently heard one).
    fn record(&mut self, sp: &Setpoint, (code, knot): (u32, u32), duration_s: f64, late: bool) {
        self.count += 1;
        let slot = self
            .answers
            .iter()
            .position(|a| a.answered > 0 && a.client_id == sp.client_id)
            .unwrap_or_else(|| {
                (0..MAX_SETPOINT_CLIENTS)
                    .min_by_key(|&k| self.heard[k])
                    .unwrap_or(0)
            });
        let (answered, rejected, late_count) =
            if self.answers[slot].answered > 0 && self.answers[slot].client_id == sp.client_id {
                let a = &self.answers[slot];
                (a.answered, a.rejected, a.late)
            } else {
                (0, 0, 0)
            };
        self.answers[slot] = SetpointAnswer {
            client_id: sp.client_id,
            seq: sp.header.seq,
            answered: answered + 1,
            code,
            level: sp.level,
            duration_s,
            rejected: rejected.saturating_add(u32::from(code != ANSWER_ACCEPTED)),
            late: late_count.saturating_add(u32::from(late)),
            knot,
            reserved: 0,
        };
        self.heard[slot] = self.count;
    }

    /// Advances every active transition by `dt` s and hands the equilibrium,
    /// the gains and (with relative damping) the equilibrium's velocity to
    /// the law; a gains step the law's tanks cannot pay is held (module
    /// docs). Levels without a setpoint are not touched. Allocation-free.
    pub fn advance(&mut self, dt: f64, controller: &mut Controller) {
        let mut any = false;
        for (i, level) in self.levels.iter_mut().enumerate() {
            if !level.active {
                continue;
            }
            any = true;
            let gain_clock = level.transition.gain_elapsed();
            let goal_clock = level.transition.goal_elapsed();
            level.transition.advance(dt);
            if level.transition.has_feed_forward() {
                // A stream that stopped: its feed-forward fades to zero.
                level.feed_forward_age_s += dt;
                let late = level.feed_forward_age_s - STREAM_TIMEOUT_S;
                if late > 0.0 {
                    let scale = (1.0 - late / STREAM_FADE_S).max(0.0);
                    let m = level.transition.dim();
                    let mut v = [0.0; MAX_TASK_DIM];
                    for (a, x) in v[..m].iter_mut().enumerate() {
                        *x = scale * level.feed_forward[a];
                    }
                    level.transition.set_feed_forward(&v[..m]);
                    if scale == 0.0 {
                        self.streams_stopped += 1;
                    }
                }
            }
            // The values come from checked setpoints: these calls cannot fail.
            // The goal's step is paid from the command tank: one it and the
            // tanks' spare cannot pay holds the goal's clock (counted).
            let t = &level.transition;
            let goal_held = !controller
                .ramp_goal(i, t.goal(), t.goal_velocity())
                .unwrap_or(true);
            if goal_held {
                level.transition.rewind_goal(goal_clock);
                self.goals_held += 1;
            }
            let t = &level.transition;
            // The gains' step is booked through the energy tanks: a
            // stiffening they cannot pay holds the gains' clock (counted)
            // and is taken again in the next cycle.
            let held = !controller
                .ramp_gains(i, Some(t.stiffness()), Some(t.damping()))
                .unwrap_or(true);
            if held {
                level.transition.rewind_gains(gain_clock);
                self.gains_held += 1;
            }
            let t = &level.transition;
            // A held goal stands still.
            let velocity = if self.relative_damping && !goal_held {
                t.goal_velocity()
            } else {
                &self.zeros[..t.dim()]
            };
            let _ = controller.set_goal_velocity(i, velocity);
            level.active = t.is_moving() || t.has_feed_forward() || held || goal_held;
        }
        controller.set_commands_active(any);
    }

    /// How many goal setpoints have been taken for level `i` (a path that
    /// began at another count has been taken over).
    pub(crate) fn goals_taken(&self, i: usize) -> u64 {
        self.levels.get(i).map_or(0, |l| l.goals_taken)
    }

    /// Level `i`'s equilibrium now (the transition's goal; a path's value
    /// while one drives the level).
    pub(crate) fn equilibrium(&self, i: usize) -> Option<&[f64]> {
        self.levels.get(i).map(|l| l.transition.goal())
    }

    /// Level `i`'s speed limit (`[setpoint_limits] max_speed`: m/s, rad/s).
    pub(crate) fn max_speed(&self, i: usize) -> Option<f64> {
        self.levels.get(i).map(|l| l.max_speed)
    }

    /// A goal `goal` (m_i values, the level's goal format) for level `i`
    /// against the joint limits of a joint level and the level's workspace
    /// (a path's knots; [`SetpointHandler::check`] for a setpoint's goal).
    pub(crate) fn check_goal(&self, i: usize, goal: &[f64]) -> Result<(), SetpointRejection> {
        let level = self.levels.get(i).ok_or(SetpointRejection::UnknownLevel)?;
        let m = level.transition.dim();
        if goal.len() != m {
            return Err(SetpointRejection::DimensionMismatch);
        }
        if let Some(joints) = &level.joints {
            for (a, &j) in joints.iter().enumerate() {
                let (lo, hi) = (self.lower[j], self.upper[j]);
                // A joint without limits (continuous) has lower ≥ upper in the model.
                if lo < hi && !(lo..=hi).contains(&goal[a]) {
                    return Err(SetpointRejection::JointLimit);
                }
            }
        }
        if level.workspace.contains(goal) {
            Ok(())
        } else {
            Err(SetpointRejection::OutsideWorkspace)
        }
    }

    /// Records an answer for a client's message that is not a setpoint (a
    /// path's knots) in the client's answer slot.
    pub(crate) fn record_answer(
        &mut self,
        client_id: u64,
        seq: u64,
        level: u32,
        (code, knot): (u32, u32),
    ) {
        let mut sp = Setpoint::zeroed();
        sp.client_id = client_id;
        sp.header.seq = seq;
        sp.level = level;
        self.record(&sp, (code, knot), 0.0, false);
    }

    /// Level `i`'s equilibrium is at `goal` now (a path moves it; crate
    /// `paths`): a later goal setpoint starts from here. Allocation-free.
    pub(crate) fn follow(&mut self, i: usize, goal: &[f64]) {
        if let Some(l) = self.levels.get_mut(i) {
            let target = Target {
                goal: Some(goal),
                stiffness: None,
                damping: None,
            };
            l.transition.start(target, 0.0);
        }
    }

    /// Writes the active goals, gain diagonals, progress and answers into `t`.
    pub fn fill(&self, t: &mut Telemetry) {
        for (i, level) in self.levels.iter().enumerate().take(MAX_LEVELS) {
            let tr = &level.transition;
            let m = tr.dim().min(MAX_TASK_DIM);
            t.goal[i][..m].copy_from_slice(&tr.goal()[..m]);
            for a in 0..m {
                t.stiffness_diag[i][a] = tr.stiffness()[(a, a)];
                t.damping_diag[i][a] = tr.damping()[(a, a)];
            }
            t.transition_progress[i] = tr.progress();
        }
        t.setpoint_answers = self.answers;
    }
}
