//! The levels' desired paths (docs/tracking.md): a scenario level's
//! `trajectory`, and paths a client sends while the controller runs
//! ([`PathKnots`] on `hcc/<ns>/path`). Every used state moves each path one
//! nominal period on, as transitions do; the law is handed x_{i,d}, ẋ_{i,d}
//! and, for a level with the feed-forward, ẍ_{i,d}. The setpoint handler's
//! equilibrium follows the path, so a goal setpoint for the level starts from
//! where the path is — and ends the path (the newest command wins); a new
//! path replaces the running one from where it is.
//!
//! A path sent at run time is a [`PathStream`]: its knots are checked (the
//! level's columns, joint limits and workspace of every knot, unit
//! quaternions, a first knot at the level's equilibrium) and answered in the
//! client's answer slot; a path that runs out of knots stops on its last at
//! rest (counted: `paths_stopped`). Allocation-free after [`Paths::new`]; the
//! spare stream a new path is built in is swapped in whole, so a refused
//! message changes nothing.

use hcc_control::Controller;
use hcc_msgs::{
    ANSWER_ACCEPTED, KnotsRefusal, NO_KNOT, PathKnots, PathRejection, SetpointRejection,
};
use hcc_spec::TaskUnit;
use hcc_spec::setpoint_limits::SetpointLimits;
use hcc_spec::tracking::{Tracking, blocks};
use hcc_trajectory::{Block, KnotError, PathSample, PathStream, StreamState, Trajectory};

use crate::setpoints::SetpointHandler;

/// How a run-time path that runs out of knots decelerates at most (m/s² or
/// rad/s² on its coordinates).
pub const PATH_STOP_DECELERATION: f64 = 1.0;
/// How far a new path's first knot may be from the level's equilibrium.
const START_OFFSET_M: f64 = 0.05;
const START_OFFSET_RAD: f64 = 0.2;

/// What drives a level.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Driver {
    /// Its goal (and the setpoints).
    Goal,
    /// The scenario's path.
    Scenario,
    /// A path sent at run time.
    Stream,
}

/// One level's paths and buffers.
struct LevelPath {
    scenario: Option<Trajectory>,
    stream: PathStream,
    /// A new path is built here, then swapped in.
    spare: PathStream,
    blocks: Vec<Block>,
    units: Vec<TaskUnit>,
    sample: PathSample,
    /// A knot in the goal format (checks), the one before it, and the
    /// running path's last knot and its time (the speed check).
    goal: Vec<f64>,
    previous: Vec<f64>,
    last: Vec<f64>,
    last_t: f64,
    feed_forward: bool,
    /// Hand the law ẋ_{i,d} (with the feed-forward always; without it as a
    /// transition does, `[setpoint_limits] relative_damping`).
    velocity: bool,
    driver: Driver,
    /// The run-time path's own time, s (negative before it starts).
    stream_t: f64,
    /// The setpoint handler's goal count when the path began.
    goals_at_start: u64,
    stopping: bool,
}

/// The paths of a cycle's levels and their clocks.
pub(crate) struct Paths {
    levels: Vec<LevelPath>,
    /// Time since the first used state, s (the scenario's paths).
    elapsed_s: f64,
    period_s: f64,
    /// The feed-forward is on for the levels that have it.
    tracking: bool,
    /// Run-time paths that reached their last knot.
    pub(crate) stopped: u64,
}

impl Paths {
    /// The paths of `tracking` for `controller`'s levels; every level with
    /// the feed-forward tracks (its fixed goal a constant path) once any
    /// level follows a path. A level without it is pulled along as a
    /// transition pulls it: the damping relative to the path's velocity with
    /// `relative_damping`; each run-time path holds `path_knots` knots ahead
    /// (`[setpoint_limits]`).
    pub(crate) fn new(
        tracking: &Tracking,
        limits: &SetpointLimits,
        period_s: f64,
        controller: &mut Controller,
    ) -> Paths {
        let relative_damping = limits.relative_damping;
        let n = controller.nq();
        let mut levels = Vec::with_capacity(controller.levels());
        for i in 0..controller.levels() {
            let spec = &controller.spec().levels[i];
            let feed_forward = tracking.feed_forward.get(i).copied().unwrap_or(true);
            let blocks = blocks(&spec.tasks, n);
            let scenario = tracking
                .paths
                .get(i)
                .cloned()
                .flatten()
                .map(|p| p.trajectory);
            let stream = PathStream::new(&blocks, limits.path_knots, PATH_STOP_DECELERATION);
            levels.push(LevelPath {
                sample: stream.sample_buffer(),
                goal: vec![0.0; controller.task_dim(i)],
                previous: vec![0.0; controller.task_dim(i)],
                last: vec![0.0; controller.task_dim(i)],
                last_t: 0.0,
                spare: stream.clone(),
                stream,
                units: spec.units(n),
                blocks,
                driver: if scenario.is_some() {
                    Driver::Scenario
                } else {
                    Driver::Goal
                },
                scenario,
                feed_forward,
                velocity: feed_forward || relative_damping,
                stream_t: 0.0,
                goals_at_start: 0,
                stopping: false,
            });
        }
        let mut paths = Paths {
            levels,
            elapsed_s: 0.0,
            period_s,
            tracking: false,
            stopped: 0,
        };
        if tracking.any() {
            paths.track(controller);
        }
        paths
    }

    /// Turns the feed-forward on for every level that has it.
    fn track(&mut self, controller: &mut Controller) {
        if self.tracking {
            return;
        }
        for (i, l) in self.levels.iter().enumerate() {
            if l.feed_forward {
                // The level exists and the values are finite: this cannot fail.
                let zeros = [0.0; hcc_msgs::MAX_TASK_DIM];
                let _ = controller.set_goal_acceleration(i, Some(&zeros[..l.goal.len()]));
            }
        }
        self.tracking = true;
    }

    /// Takes a client's knots in the cycle of the state `state_seq`: checks
    /// them against the level, starts or extends its path, and answers in
    /// the client's slot. Returns the answer code. Allocation-free.
    pub(crate) fn take(
        &mut self,
        knots: &PathKnots,
        state_seq: u64,
        controller: &mut Controller,
        setpoints: &mut SetpointHandler,
    ) -> u32 {
        let result = self.check_and_take(knots, state_seq, setpoints);
        let (code, knot) = match result {
            Ok(()) => {
                self.track(controller);
                // A new path is a command, as a setpoint is: the tanks and
                // the passivity budget are refilled once (its samples and
                // its extensions — a device streaming knots — are not).
                if knots.is_new() {
                    controller.command_taken();
                }
                (ANSWER_ACCEPTED, NO_KNOT)
            }
            Err(r) => (r.code(), r.knot_field()),
        };
        setpoints.record_answer(knots.client_id, knots.header.seq, knots.level, (code, knot));
        code
    }

    fn check_and_take(
        &mut self,
        knots: &PathKnots,
        state_seq: u64,
        setpoints: &SetpointHandler,
    ) -> Result<(), KnotsRefusal> {
        let goals_now = setpoints.goals_taken(knots.level as usize);
        let period_s = self.period_s;
        let (i, l) = self.level_of(knots)?;
        let max_speed = setpoints
            .max_speed(i)
            .ok_or(SetpointRejection::UnknownLevel)?;
        // Every knot against the level's limits, in its goal format, and
        // against its speed limit from the knot before (an extension's
        // first from the running path's last).
        let running = l.driver == Driver::Stream && l.goals_at_start == goals_now;
        let mut before = (!knots.is_new() && running && !l.stream.is_empty()).then_some(l.last_t);
        l.previous.copy_from_slice(&l.last);
        for k in 0..knots.count() {
            l.check_knot(knots, k, i, setpoints)?;
            let t = knots.knot(k).0;
            let chord = before
                .filter(|t0| t > *t0)
                .map(|t0| distance(&l.blocks, &l.previous, &l.goal) / (t - t0));
            if chord.is_some_and(|v| v > max_speed * SPEED_TOLERANCE) {
                return Err(KnotsRefusal::at(PathRejection::TooFast, k));
            }
            std::mem::swap(&mut l.previous, &mut l.goal);
            before = Some(t);
        }
        // Taken from here on: the last knot, for the next extension's check.
        let last_t = knots.knot(knots.count() - 1).0;
        if knots.is_new() {
            // Its first knot at the level's equilibrium.
            let (_, first) = knots.knot(0);
            hcc_trajectory::goal_of(&l.blocks, first, &mut l.goal);
            let here = setpoints
                .equilibrium(i)
                .ok_or(SetpointRejection::UnknownLevel)?;
            if !starts_at(&l.blocks, &l.units, &l.goal, here) {
                return Err(KnotsRefusal::at(PathRejection::StartsAway, 0));
            }
            l.spare.clear();
            push_all(&mut l.spare, knots)?;
            std::mem::swap(&mut l.stream, &mut l.spare);
            l.last.copy_from_slice(&l.previous);
            l.last_t = last_t;
            l.driver = Driver::Stream;
            let start = knots.apply_at_state_seq.max(state_seq);
            l.stream_t = -((start - state_seq) as f64) * period_s;
            l.goals_at_start = goals_now;
            l.stopping = false;
            return Ok(());
        }
        if !running || l.stream.is_empty() {
            return Err(PathRejection::NoPath.into());
        }
        if l.stream.state(l.stream_t) != StreamState::Running {
            return Err(PathRejection::PathEnded.into());
        }
        if knots.count() > l.stream.room() {
            return Err(PathRejection::PathFull.into());
        }
        let held = l.stream.len();
        push_all(&mut l.stream, knots).inspect_err(|_| l.stream.truncate(held))?;
        l.last.copy_from_slice(&l.previous);
        l.last_t = last_t;
        Ok(())
    }

    /// The checks of `knots` that do not depend on the level's running
    /// path: the message, the level's columns, and each knot on its own
    /// ([`LevelPath::check_knot`]). What the feasibility check's gate asks
    /// before it hands a message to the worker. Allocation-free.
    pub(crate) fn precheck(
        &mut self,
        knots: &PathKnots,
        setpoints: &SetpointHandler,
    ) -> Result<(), KnotsRefusal> {
        let (i, l) = self.level_of(knots)?;
        (0..knots.count()).try_for_each(|k| l.check_knot(knots, k, i, setpoints))
    }

    /// The message's level, once the message is well-formed and has the
    /// level's columns.
    fn level_of(&mut self, knots: &PathKnots) -> Result<(usize, &mut LevelPath), KnotsRefusal> {
        knots.validate()?;
        let i = knots.level as usize;
        let l = self
            .levels
            .get_mut(i)
            .ok_or(SetpointRejection::UnknownLevel)?;
        if knots.columns() != l.stream.columns() {
            return Err(PathRejection::ColumnMismatch.into());
        }
        Ok((i, l))
    }

    /// Hands every driving path's value at this state's time to the law and
    /// to the setpoint handler's equilibrium, then moves the clocks `dt` s
    /// on. A level whose goal a setpoint has taken is left to it.
    pub(crate) fn advance(
        &mut self,
        dt: f64,
        controller: &mut Controller,
        setpoints: &mut SetpointHandler,
    ) {
        let t = self.elapsed_s;
        for (i, p) in self.levels.iter_mut().enumerate() {
            let goals = setpoints.goals_taken(i);
            match p.driver {
                Driver::Goal => continue,
                Driver::Scenario if goals > 0 => {
                    p.driver = Driver::Goal;
                    continue;
                }
                Driver::Stream if goals != p.goals_at_start => {
                    p.driver = Driver::Goal;
                    continue;
                }
                Driver::Scenario => match &p.scenario {
                    Some(s) => s.sample(t, &mut p.sample),
                    None => continue,
                },
                Driver::Stream => {
                    p.stream.sample(p.stream_t, &mut p.sample);
                    let stopping = p.stream.state(p.stream_t) != StreamState::Running;
                    if stopping && !p.stopping {
                        self.stopped += 1;
                    }
                    p.stopping = stopping;
                    if dt.is_finite() && dt > 0.0 {
                        p.stream_t += dt;
                    }
                }
            }
            let s = &p.sample;
            // Checked paths of the level's dimension: these calls cannot fail.
            // The sample's work is booked with its velocity (an input; the
            // path's message refilled the tanks when it was taken).
            let _ = controller.follow_goal(i, &s.goal, &s.velocity);
            if p.velocity {
                let _ = controller.set_goal_velocity(i, &s.velocity);
            }
            if p.feed_forward && self.tracking {
                let _ = controller.set_goal_acceleration(i, Some(&s.acceleration));
            }
            setpoints.follow(i, &s.goal);
        }
        if dt.is_finite() && dt > 0.0 {
            self.elapsed_s += dt;
        }
    }
}

impl LevelPath {
    /// Knot `k` of `knots` for level `i` on its own, into `self.goal` (the
    /// goal format): a unit quaternion per orientation, the level's joint
    /// limits and workspace, a sample's own velocity within `max_speed`.
    fn check_knot(
        &mut self,
        knots: &PathKnots,
        k: usize,
        i: usize,
        setpoints: &SetpointHandler,
    ) -> Result<(), KnotsRefusal> {
        let columns = knots.knot(k).1;
        if !hcc_trajectory::goal_of(&self.blocks, columns, &mut self.goal) {
            return Err(KnotsRefusal::at(PathRejection::NotUnitQuaternion, k));
        }
        setpoints
            .check_goal(i, &self.goal)
            .map_err(|r| KnotsRefusal::at(r, k))?;
        let max_speed = setpoints
            .max_speed(i)
            .ok_or(SetpointRejection::UnknownLevel)?;
        let own = knots
            .has_derivatives()
            .then(|| norm(knots.derivatives(k, self.goal.len()).0));
        if own.is_some_and(|v| v > max_speed * SPEED_TOLERANCE) {
            return Err(KnotsRefusal::at(PathRejection::TooFast, k));
        }
        Ok(())
    }
}

/// Appends every knot of `knots` to `stream` (with their derivatives when
/// the message carries them); a refusal names the knot.
pub(crate) fn push_all(stream: &mut PathStream, knots: &PathKnots) -> Result<(), KnotsRefusal> {
    let dim = stream.sample_dim();
    for k in 0..knots.count() {
        let (t, columns) = knots.knot(k);
        let pushed = if knots.has_derivatives() {
            let (velocity, acceleration) = knots.derivatives(k, dim);
            stream.push_sample(t, columns, velocity, acceleration)
        } else {
            stream.push(t, columns)
        };
        pushed.map_err(|e| {
            let reason = match e {
                KnotError::NotIncreasing => PathRejection::NotIncreasing,
                KnotError::NotUnit => PathRejection::NotUnitQuaternion,
                KnotError::Turn => PathRejection::TurnTooFar,
                KnotError::Full => PathRejection::PathFull,
                KnotError::Ended => PathRejection::PathEnded,
                KnotError::Malformed => PathRejection::ColumnMismatch,
            };
            KnotsRefusal::at(reason, k)
        })?;
    }
    Ok(())
}

/// A path's speed may exceed the level's `max_speed` by this factor (the
/// rounding of a chord computed from knots sent at that speed).
const SPEED_TOLERANCE: f64 = 1.0 + 1e-9;

fn norm(v: &[f64]) -> f64 {
    v.iter().map(|x| x * x).sum::<f64>().sqrt()
}

/// The distance between two knots `a`, `b` (goal format) as a transition
/// measures it: √(|Δx|² + θ²), θ the angle between their orientations.
fn distance(blocks: &[Block], a: &[f64], b: &[f64]) -> f64 {
    let (mut g, mut d2) = (0, 0.0);
    for block in blocks {
        match block {
            Block::Vector(n) => {
                d2 += (g..g + n).map(|r| (a[r] - b[r]).powi(2)).sum::<f64>();
            }
            Block::Rotation => {
                let rpy = |v: &[f64]| {
                    nalgebra::UnitQuaternion::from_euler_angles(v[g], v[g + 1], v[g + 2])
                };
                d2 += rpy(a).angle_to(&rpy(b)).powi(2);
            }
        }
        g += block.dim();
    }
    d2.sqrt()
}

/// Whether a path's first knot `first` (goal format) is within the start
/// offsets of the equilibrium `here`: per row by its unit, an orientation by
/// the angle between the two rotations.
fn starts_at(blocks: &[Block], units: &[TaskUnit], first: &[f64], here: &[f64]) -> bool {
    let mut g = 0;
    for b in blocks {
        match b {
            Block::Vector(n) => {
                for a in g..g + n {
                    let limit = match units[a] {
                        TaskUnit::Length => START_OFFSET_M,
                        TaskUnit::Angle => START_OFFSET_RAD,
                    };
                    if (first[a] - here[a]).abs() > limit {
                        return false;
                    }
                }
            }
            Block::Rotation => {
                let rpy = |v: &[f64]| {
                    nalgebra::UnitQuaternion::from_euler_angles(v[g], v[g + 1], v[g + 2])
                };
                if rpy(first).angle_to(&rpy(here)) > START_OFFSET_RAD {
                    return false;
                }
            }
        }
        g += b.dim();
    }
    true
}
