//! Where a level's goals may lie: a box from `[[setpoint_limits.level]]`, or
//! by default the ball the chain reaches from its root.

use hcc_control::{Controller, LevelSpec, TaskSpec};
use hcc_msgs::MAX_TASK_DIM;

/// Where a level's position goals may lie.
#[derive(Debug, Clone)]
pub(super) enum Workspace {
    /// Not a position task.
    None,
    /// A box (min, max) on the task's coordinates.
    Box(Box<([f64; MAX_TASK_DIM], [f64; MAX_TASK_DIM])>),
    /// The ball of `radius` around `center`, on the selected axes.
    Ball {
        center: [f64; 3],
        radius: f64,
        axes: [usize; 3],
    },
}

/// Radius and centre of the ball the chain reaches, for `frame`.
fn reach(controller: &Controller, frame: hcc_model::FrameId) -> ([f64; 3], f64) {
    let model = controller.model();
    let center = model
        .joints
        .first()
        .map(|j| j.placement.translation.vector)
        .unwrap_or_default();
    let mut radius: f64 = model
        .joints
        .iter()
        .skip(1)
        .map(|j| j.placement.translation.vector.norm())
        .sum();
    radius += model
        .joints
        .iter()
        .filter(|j| j.kind == hcc_model::JointKind::Prismatic)
        .map(|j| j.upper.abs().max(j.lower.abs()))
        .sum::<f64>();
    if let Some(f) = model.frames.get(frame) {
        radius += f.placement.translation.vector.norm();
    }
    ([center.x, center.y, center.z], radius)
}

impl Workspace {
    /// The workspace of a level of `controller` described by `spec`, with
    /// the box `limits` of its `[[setpoint_limits.level]]` (position tasks).
    pub(super) fn of_level(
        controller: &Controller,
        spec: &LevelSpec,
        limits: Option<&(Vec<f64>, Vec<f64>)>,
    ) -> Workspace {
        match (spec.tasks.as_slice(), limits) {
            ([TaskSpec::Position { .. }], Some((lo, hi))) => {
                let mut a = [0.0; MAX_TASK_DIM];
                let mut b = [0.0; MAX_TASK_DIM];
                a[..lo.len()].copy_from_slice(lo);
                b[..hi.len()].copy_from_slice(hi);
                Workspace::Box(Box::new((a, b)))
            }
            ([TaskSpec::Position { frame, axes }], None) => {
                let (center, radius) = reach(controller, *frame);
                let mut ax = [3; 3];
                ax[..axes.len()].copy_from_slice(axes);
                Workspace::Ball {
                    center,
                    radius,
                    axes: ax,
                }
            }
            // The position rows (the first three) of a pose level.
            ([TaskSpec::Pose { frame }], None) => {
                let (center, radius) = reach(controller, *frame);
                Workspace::Ball {
                    center,
                    radius,
                    axes: [0, 1, 2],
                }
            }
            _ => Workspace::None,
        }
    }

    /// Whether `goal` (the level's m coordinates) lies inside.
    pub(super) fn contains(&self, goal: &[f64]) -> bool {
        let m = goal.len();
        match self {
            Workspace::None => true,
            Workspace::Box(b) => (0..m).all(|a| (b.0[a]..=b.1[a]).contains(&goal[a])),
            Workspace::Ball {
                center,
                radius,
                axes,
            } => {
                // The position rows only (a pose level's first three).
                let d2: f64 = (0..m.min(3))
                    .map(|a| (goal[a] - center[axes[a].min(2)]).powi(2))
                    .sum();
                d2 <= radius * radius
            }
        }
    }
}
