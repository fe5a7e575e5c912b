//! The feasibility of paths sent at run time (docs/tracking.md,
//! "Feasibility"): the worker side. A path message that passes the cycle's
//! cheap checks waits in the cycle's path gate (crate `path_gate`) while a
//! [`PathChecker`] on a thread of its own (ros2_control's lesson: the
//! real-time thread hands the slow work on) rolls the hierarchy out along it
//! ([`crate::feasibility::Rollout`]) and answers with a [`Verdict`].
//!
//! Each level keeps its own rollout: a new path starts one from the
//! configuration and the levels' goals of the cycle that received it (the
//! other levels hold those goals); an extension continues it from where the
//! previous message's knots left it. The rollout follows the checker's own
//! copy of the level's [`PathStream`], stepped every
//! [`crate::feasibility::ROLLOUT_STEP_S`] as far as the knots received fix the path
//! (up to the last knot but one for knots, the last for samples: later knots
//! change nothing before); the rest, up to the last knot, is rolled out on a
//! copy, so that every message is checked to its end. A refused message
//! names the first of its knots at or after the step that failed; the level
//! then takes no extension until a new path begins.

use hcc_control::Controller;
use hcc_msgs::{KnotsRefusal, MAX_JOINTS, MAX_LEVELS, MAX_TASK_DIM, PathKnots, PathRejection};
use hcc_spec::tracking::blocks;
use hcc_trajectory::{PathSample, PathStream};

use crate::feasibility::{Infeasible, Rollout, Target};
use crate::paths::{PATH_STOP_DECELERATION, push_all};

/// What the cycle hands the checker: a path message, with the configuration
/// and the levels' goals (their goal format) of the cycle that received it.
#[derive(Clone, Copy)]
pub struct CheckRequest {
    /// The gate's number for the message (its verdict carries it back).
    pub token: u64,
    pub knots: PathKnots,
    pub q: [f64; MAX_JOINTS],
    pub goals: [[f64; MAX_TASK_DIM]; MAX_LEVELS],
}

impl CheckRequest {
    /// An empty request (the gate fills one in place).
    pub fn zeroed() -> CheckRequest {
        CheckRequest {
            token: 0,
            knots: PathKnots::zeroed(),
            q: [0.0; MAX_JOINTS],
            goals: [[0.0; MAX_TASK_DIM]; MAX_LEVELS],
        }
    }
}

/// The checker's answer to a [`CheckRequest`].
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Verdict {
    pub token: u64,
    /// `None`: the hierarchy can follow the message's knots.
    pub refusal: Option<KnotsRefusal>,
}

/// One level's rollout along its run-time path.
struct LevelCheck {
    stream: PathStream,
    sample: PathSample,
    rollout: Option<Rollout>,
    /// The next step's path time, s.
    t: f64,
    /// A message of the path was refused: extensions are too.
    refused: bool,
}

/// The worker's state: one rollout per level (module docs). Its checks
/// allocate; it runs off the real-time thread.
pub struct PathChecker {
    controller: Controller,
    levels: Vec<LevelCheck>,
    n: usize,
    dt: f64,
}

impl PathChecker {
    /// A checker of `controller`'s hierarchy, its levels' paths holding
    /// `path_knots` knots as the cycle's do (`[setpoint_limits]`), stepped
    /// every `dt` s.
    pub fn new(controller: &Controller, path_knots: usize, dt: f64) -> PathChecker {
        let n = controller.nq();
        let levels = controller
            .spec()
            .levels
            .iter()
            .map(|level| {
                let stream =
                    PathStream::new(&blocks(&level.tasks, n), path_knots, PATH_STOP_DECELERATION);
                LevelCheck {
                    sample: stream.sample_buffer(),
                    stream,
                    rollout: None,
                    t: 0.0,
                    refused: false,
                }
            })
            .collect();
        PathChecker {
            controller: controller.clone(),
            levels,
            n,
            dt,
        }
    }

    /// Checks one message (module docs). A message the cycle's own checks
    /// will refuse (malformed, an extension of no path) passes here: the
    /// cycle names its reason.
    pub fn check(&mut self, request: &CheckRequest) -> Verdict {
        let refusal = self.refusal(request);
        Verdict {
            token: request.token,
            refusal,
        }
    }

    fn refusal(&mut self, request: &CheckRequest) -> Option<KnotsRefusal> {
        let knots = &request.knots;
        let i = knots.level as usize;
        if knots.validate().is_err() || i >= self.levels.len() {
            return None;
        }
        let (dt, n, levels) = (self.dt, self.n, self.levels.len());
        let l = &mut self.levels[i];
        if knots.columns() != l.stream.columns() {
            return None;
        }
        if knots.is_new() {
            l.stream.clear();
            l.refused = false;
            l.t = 0.0;
            let mut rollout = Rollout::new(&self.controller, &request.q[..n]);
            for (level, goal) in request.goals.iter().enumerate().take(levels) {
                let dim = self.controller.task_dim(level);
                // The goals are the cycle's own: valid for their level.
                let _ = rollout.hold(level, &goal[..dim]);
            }
            l.rollout = Some(rollout);
        } else if l.refused {
            return Some(KnotsRefusal::at(PathRejection::Infeasible, 0));
        }
        let Some(rollout) = l.rollout.as_mut() else {
            // An extension of a path this checker has not seen begin.
            return None;
        };
        // The last knot before this message's (a knot extension's first
        // segment runs from it).
        let before = l.stream.last_time();
        if push_all(&mut l.stream, knots).is_err() {
            // The cycle refuses it for the same reason; what this level's
            // rollout follows is no longer the cycle's path.
            l.rollout = None;
            return None;
        }
        let last = knots.count() - 1;
        let t_last = knots.knot(last).0;
        // As far as the knots received fix the path: to the last sample, or
        // to the last knot but one (the segment into the last knot waits
        // for the next; entering it now would stop this copy of the path).
        let fixed = if knots.has_derivatives() {
            t_last
        } else if last > 0 {
            knots.knot(last - 1).0
        } else {
            before.unwrap_or(0.0)
        };
        let failed = roll(
            rollout,
            &mut l.stream,
            &mut l.sample,
            i,
            &mut l.t,
            fixed,
            dt,
        )
        .err()
        .or_else(|| {
            if l.t >= t_last {
                return None;
            }
            // The rest, to the last knot, on copies.
            let (mut stream, mut rollout, mut t) = (l.stream.clone(), rollout.clone(), l.t);
            roll(
                &mut rollout,
                &mut stream,
                &mut l.sample,
                i,
                &mut t,
                t_last,
                dt,
            )
            .err()
        });
        let failed = failed?;
        l.refused = true;
        let knot = (0..knots.count())
            .find(|&k| knots.knot(k).0 >= failed.t)
            .unwrap_or(last);
        Some(KnotsRefusal::at(PathRejection::Infeasible, knot))
    }
}

/// Steps `rollout` along `stream` (level `i`) at `*t`, `*t + dt`, … while
/// before `until` (its last step may reach `until` itself only when the
/// path's time `until` is where it ends: the last knot).
fn roll(
    rollout: &mut Rollout,
    stream: &mut PathStream,
    sample: &mut PathSample,
    i: usize,
    t: &mut f64,
    until: f64,
    dt: f64,
) -> Result<(), Infeasible> {
    while *t < until {
        stream.sample(*t, sample);
        let mut targets: [Option<Target<'_>>; MAX_LEVELS] = [None; MAX_LEVELS];
        targets[i] = Some((&sample.goal[..], &sample.velocity[..]));
        rollout.step(*t, &targets[..=i], dt)?;
        *t += dt;
    }
    Ok(())
}
