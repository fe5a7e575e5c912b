//! The shapes a transition moves along: a vector goal componentwise, roll,
//! pitch, yaw on the SO(3) geodesic (slerp) with its world-frame angular
//! velocity, a 6-D pose as both, and the gains as the convex combination
//! K(t) = (1 − s) K_0 + s K_1 (SPD all along).

use super::Transition;
use super::profile::quintic;
use nalgebra::{UnitQuaternion, Vector3};

/// How a level's goal is interpolated.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum GoalKind {
    /// Componentwise (positions, joint angles).
    Vector,
    /// Roll, pitch, yaw (3 values), interpolated on SO(3) by slerp.
    RollPitchYaw,
    /// A 6-D pose: x, y, z componentwise, then roll, pitch, yaw by slerp.
    Pose,
}

impl GoalKind {
    /// The number of values a goal of this kind has, if fixed.
    pub fn fixed_dim(self) -> Option<usize> {
        match self {
            GoalKind::Vector => None,
            GoalKind::RollPitchYaw => Some(3),
            GoalKind::Pose => Some(6),
        }
    }

    /// The first of the three roll, pitch, yaw rows, if any.
    pub fn rotation_rows(self) -> Option<usize> {
        match self {
            GoalKind::Vector => None,
            GoalKind::RollPitchYaw => Some(0),
            GoalKind::Pose => Some(3),
        }
    }
}

/// The rotation of the roll, pitch, yaw values at `v[o..o + 3]`.
pub(super) fn rpy_at(v: &[f64], o: usize) -> UnitQuaternion<f64> {
    UnitQuaternion::from_euler_angles(v[o], v[o + 1], v[o + 2])
}

impl Transition {
    /// Distance from the current equilibrium to `goal`: Euclidean for
    /// vector goals, the rotation angle for roll, pitch, yaw, and for a pose
    /// √(|Δp|² + θ²) (θ the rotation angle).
    pub fn distance_to(&self, goal: &[f64]) -> f64 {
        if goal.len() != self.dim() {
            return f64::INFINITY;
        }
        let vector_rows = match self.kind.rotation_rows() {
            Some(o) => o,
            None => self.dim(),
        };
        let d2: f64 = goal[..vector_rows]
            .iter()
            .zip(self.goal.iter())
            .map(|(a, b)| (a - b) * (a - b))
            .sum();
        let theta = match self.kind.rotation_rows() {
            Some(o) => self.current_rotation().angle_to(&rpy_at(goal, o)),
            None => 0.0,
        };
        (d2 + theta * theta).sqrt()
    }

    /// The rotation of the current orientation equilibrium (identity for
    /// vector goals).
    pub fn current_rotation(&self) -> UnitQuaternion<f64> {
        match self.kind {
            GoalKind::Vector => UnitQuaternion::identity(),
            GoalKind::RollPitchYaw | GoalKind::Pose => {
                let (s, _, _) = quintic(self.goal_progress());
                self.rot_from.slerp(&self.rot_to, s)
            }
        }
    }

    /// The equilibrium, its velocity and the gains at the clocks' progress.
    pub(super) fn update(&mut self) {
        let sigma = self.goal_progress();
        let (s, ds_dsigma, _) = quintic(sigma);
        // ds/dt = (ds/dσ) / T; zero once the transition is over.
        let ds_dt = if self.duration > 0.0 && sigma < 1.0 {
            ds_dsigma / self.duration
        } else {
            0.0
        };
        let rotation_rows = self.kind.rotation_rows();
        for j in 0..self.dim() {
            if rotation_rows.is_some_and(|o| (o..o + 3).contains(&j)) {
                continue;
            }
            let delta = self.goal_to[j] - self.goal_from[j];
            self.goal[j] = self.goal_from[j] + s * delta;
            self.goal_velocity[j] = ds_dt * delta;
        }
        if let Some(o) = rotation_rows {
            if sigma >= 1.0 {
                // At rest on the target: its roll, pitch, yaw as sent.
                for j in o..o + 3 {
                    self.goal[j] = self.goal_to[j];
                    self.goal_velocity[j] = 0.0;
                }
            } else {
                let r = self.rot_from.slerp(&self.rot_to, s);
                let (roll, pitch, yaw) = r.euler_angles();
                self.goal[o] = roll;
                self.goal[o + 1] = pitch;
                self.goal[o + 2] = yaw;
                // ω = ṡ R_0 log(R_0ᵀ R_1), constant direction along the geodesic.
                let log: Vector3<f64> = (self.rot_from.inverse() * self.rot_to).scaled_axis();
                let omega = self.rot_from * log * ds_dt;
                for a in 0..3 {
                    self.goal_velocity[o + a] = omega[a];
                }
            }
        }
        if self.feed_forward.iter().any(|&v| v != 0.0) {
            // The client's trajectory velocity replaces the profile's: a
            // stream restarts a short transition every cycle, whose own
            // velocity only approximates the trajectory's (adding both
            // would count the motion twice).
            self.goal_velocity.copy_from(&self.feed_forward);
        }
        let (s, _, _) = quintic(self.gain_progress());
        let s1 = 1.0 - s;
        for (dst, (a, b)) in self
            .stiffness
            .iter_mut()
            .zip(self.k_from.iter().zip(self.k_to.iter()))
        {
            *dst = s1 * a + s * b;
        }
        for (dst, (a, b)) in self
            .damping
            .iter_mut()
            .zip(self.d_from.iter().zip(self.d_to.iter()))
        {
            *dst = s1 * a + s * b;
        }
    }
}
