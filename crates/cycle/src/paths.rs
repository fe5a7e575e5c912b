//! The levels' desired paths (a scenario level's `trajectory`;
//! docs/tracking.md): every used state moves each path one nominal period on,
//! as transitions do; the law is handed x_{i,d}, ẋ_{i,d} and, for a level with
//! the feed-forward, ẍ_{i,d}. The setpoint handler's equilibrium follows the
//! path, so a goal setpoint for the level starts from where the path is —
//! and ends the path (the newest command wins). Allocation-free after
//! [`Paths::new`].

use hcc_control::Controller;
use hcc_spec::tracking::Tracking;
use hcc_trajectory::{PathSample, Trajectory};

use crate::setpoints::SetpointHandler;

/// One level's path and its sample buffers.
struct LevelPath {
    trajectory: Trajectory,
    sample: PathSample,
    feed_forward: bool,
    /// Hand the law ẋ_{i,d} (with the feed-forward always; without it as a
    /// transition does, `[setpoint_limits] relative_damping`).
    velocity: bool,
    /// Still driving the level (no goal setpoint has taken it over).
    driving: bool,
}

/// The paths of a cycle's levels and their clock.
pub(crate) struct Paths {
    levels: Vec<Option<LevelPath>>,
    /// Time since the first used state, s.
    elapsed_s: f64,
}

impl Paths {
    /// The paths of `tracking`; every level with the feed-forward tracks
    /// (its fixed goal a constant path) while any level follows a path. A
    /// level without it is pulled along as a transition pulls it: the damping
    /// relative to the path's velocity with `relative_damping`.
    pub(crate) fn new(
        tracking: &Tracking,
        relative_damping: bool,
        controller: &mut Controller,
    ) -> Paths {
        let any = tracking.any();
        let mut levels = Vec::with_capacity(tracking.paths.len());
        for (i, p) in tracking.paths.iter().enumerate() {
            let feed_forward = tracking.feed_forward.get(i).copied().unwrap_or(true);
            if any && feed_forward {
                let zeros = vec![0.0; controller.task_dim(i)];
                // The level exists and the values are finite: this cannot fail.
                let _ = controller.set_goal_acceleration(i, Some(&zeros));
            }
            levels.push(p.as_ref().map(|p| LevelPath {
                sample: p.trajectory.sample_buffer(),
                trajectory: p.trajectory.clone(),
                feed_forward,
                velocity: feed_forward || relative_damping,
                driving: true,
            }));
        }
        Paths {
            levels,
            elapsed_s: 0.0,
        }
    }

    /// Hands every driving path's value at this state's time to the law and
    /// to the setpoint handler's equilibrium, then moves the clock `dt` s on.
    /// A level whose goal a setpoint has taken is left to it (the
    /// feed-forward ends there).
    pub(crate) fn advance(
        &mut self,
        dt: f64,
        controller: &mut Controller,
        setpoints: &mut SetpointHandler,
    ) {
        let t = self.elapsed_s;
        for (i, level) in self.levels.iter_mut().enumerate() {
            let Some(p) = level.as_mut().filter(|p| p.driving) else {
                continue;
            };
            if setpoints.goal_taken(i) {
                p.driving = false;
                let _ = controller.set_goal_acceleration(i, None);
                continue;
            }
            p.trajectory.sample(t, &mut p.sample);
            let s = &p.sample;
            // Checked paths of the level's dimension: these calls cannot fail.
            let _ = controller.set_goal(i, &s.goal);
            if p.velocity {
                let _ = controller.set_goal_velocity(i, &s.velocity);
            }
            if p.feed_forward {
                let _ = controller.set_goal_acceleration(i, Some(&s.acceleration));
            }
            setpoints.follow(i, &s.goal);
        }
        if dt.is_finite() && dt > 0.0 {
            self.elapsed_s += dt;
        }
    }
}
