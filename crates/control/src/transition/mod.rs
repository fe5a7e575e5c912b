//! Smooth transitions of a level's virtual equilibrium x_{i,d} and of its
//! gains K_i, D_i (the spring–damper of paper Eqs. (20), (21)) when a new
//! setpoint arrives while the controller runs.
//!
//! A new goal never jumps: over a transition of duration T the equilibrium
//! follows the minimum-jerk (quintic) profile
//!
//! s(σ) = 10σ³ − 15σ⁴ + 6σ⁵,  σ = t / T ∈ [0, 1],
//!
//! which starts and ends at rest with zero acceleration (s′ = s″ = 0 at both
//! ends), so x_{i,d}(t), ẋ_{i,d}(t) and ẍ_{i,d}(t) are continuous (C²) across
//! the start and the end of the transition.
//!
//! * Vector goals (positions in m, joint angles in rad):
//!   x_d(t) = x_0 + s (x_1 − x_0), ẋ_d = (ds/dt) (x_1 − x_0).
//! * Orientation goals (roll, pitch, yaw as in the scenario): interpolated on
//!   SO(3) by slerp, R_d(t) = R_0 exp(s log(R_0ᵀ R_1)) — the geodesic, not
//!   per angle — with the world-frame angular velocity
//!   ω_d = (ds/dt) R_0 log(R_0ᵀ R_1). At the end of the transition the
//!   equilibrium is the target's roll, pitch, yaw exactly as sent.
//! * 6-D pose goals (x, y, z, roll, pitch, yaw): the position rows as vector
//!   goals, the orientation rows by slerp as above, on the same profile s(t)
//!   (ẋ_d = [ṡ Δp; ω_d]).
//! * Gains: K(t) = (1 − s) K_0 + s K_1 and the same for D. A convex
//!   combination of symmetric positive definite matrices is symmetric
//!   positive definite (xᵀ K x = (1 − s) xᵀ K_0 x + s xᵀ K_1 x > 0), so the
//!   gains stay SPD all along.
//!
//! A transition started while another one runs starts from where the
//! equilibrium and the gains are at that instant (its velocity then restarts
//! from zero, as the profile does).
//!
//! [`Transition::new`] allocates every buffer; [`Transition::start`] and
//! [`Transition::advance`] allocate nothing.
//!
//! The clocks and the state are here; `profile.rs` has s(σ), `shape.rs` the
//! interpolation of each kind of goal and of the gains.

mod profile;
mod shape;
#[cfg(test)]
mod tests;

pub use profile::quintic;
pub use shape::GoalKind;

use crate::ControlError;
use nalgebra::{DMatrix, DVector, UnitQuaternion};
use profile::sigma;
use shape::rpy_at;

/// One level's equilibrium and gains, moving from where they are to a new
/// target over a transition. The goal and the gains have clocks of their
/// own: a setpoint that sets only one of them restarts only its clock, so a
/// stiffness change sent while the goal moves leaves the goal's motion as it
/// was (and a new goal leaves a running gain transition on its way).
#[derive(Debug, Clone)]
pub struct Transition {
    pub(super) kind: GoalKind,
    /// The goal's transition: duration and time elapsed, s.
    pub(super) duration: f64,
    pub(super) elapsed: f64,
    /// The gains' transition: duration and time elapsed, s.
    pub(super) gain_duration: f64,
    pub(super) gain_elapsed: f64,
    pub(super) goal_from: DVector<f64>,
    pub(super) goal_to: DVector<f64>,
    pub(super) rot_from: UnitQuaternion<f64>,
    pub(super) rot_to: UnitQuaternion<f64>,
    pub(super) k_from: DMatrix<f64>,
    pub(super) k_to: DMatrix<f64>,
    pub(super) d_from: DMatrix<f64>,
    pub(super) d_to: DMatrix<f64>,
    pub(super) goal: DVector<f64>,
    pub(super) goal_velocity: DVector<f64>,
    /// Velocity feed-forward that replaces the profile's ẋ_d (from a
    /// setpoint stream), held until the next goal.
    pub(super) feed_forward: DVector<f64>,
    pub(super) stiffness: DMatrix<f64>,
    pub(super) damping: DMatrix<f64>,
}

/// What a [`Transition::start`] changes; `None` keeps the current value.
#[derive(Debug, Clone, Copy, Default)]
pub struct Target<'a> {
    /// New goal, m values (roll, pitch, yaw for [`GoalKind::RollPitchYaw`]).
    pub goal: Option<&'a [f64]>,
    /// New stiffness K (m×m, SPD).
    pub stiffness: Option<&'a DMatrix<f64>>,
    /// New damping D (m×m, SPD).
    pub damping: Option<&'a DMatrix<f64>>,
}

impl Transition {
    /// At rest at `goal` with gains `stiffness`, `damping` (m×m each, m =
    /// `goal.len()`; 3 for [`GoalKind::RollPitchYaw`], 6 for
    /// [`GoalKind::Pose`]). Allocates. An error names a wrong size or a
    /// non-finite value.
    pub fn new(
        kind: GoalKind,
        goal: &[f64],
        stiffness: &DMatrix<f64>,
        damping: &DMatrix<f64>,
    ) -> Result<Self, ControlError> {
        let m = goal.len();
        if kind == GoalKind::RollPitchYaw && m != 3 {
            return Err(ControlError::Spec(format!(
                "an orientation goal has 3 values (roll, pitch, yaw), not {m}"
            )));
        }
        if kind == GoalKind::Pose && m != 6 {
            return Err(ControlError::Spec(format!(
                "a pose goal has 6 values (x, y, z, roll, pitch, yaw), not {m}"
            )));
        }
        for (name, g) in [("stiffness", stiffness), ("damping", damping)] {
            if g.shape() != (m, m) {
                return Err(ControlError::Spec(format!(
                    "the {name} is {}×{}, the goal has {m} values",
                    g.nrows(),
                    g.ncols()
                )));
            }
        }
        let all = goal.iter().chain(stiffness.iter()).chain(damping.iter());
        if all.into_iter().any(|x| !x.is_finite()) {
            return Err(ControlError::Spec(
                "a transition's goal or gains have a non-finite value".into(),
            ));
        }
        let g = DVector::from_column_slice(goal);
        let r = match kind.rotation_rows() {
            Some(o) => rpy_at(goal, o),
            None => UnitQuaternion::identity(),
        };
        Ok(Self {
            kind,
            duration: 0.0,
            elapsed: 0.0,
            gain_duration: 0.0,
            gain_elapsed: 0.0,
            goal_from: g.clone(),
            goal_to: g.clone(),
            rot_from: r,
            rot_to: r,
            k_from: stiffness.clone(),
            k_to: stiffness.clone(),
            d_from: damping.clone(),
            d_to: damping.clone(),
            goal: g,
            goal_velocity: DVector::zeros(m),
            feed_forward: DVector::zeros(m),
            stiffness: stiffness.clone(),
            damping: damping.clone(),
        })
    }

    /// Task dimension m.
    pub fn dim(&self) -> usize {
        self.goal.len()
    }

    /// How the goal is interpolated.
    pub fn kind(&self) -> GoalKind {
        self.kind
    }

    /// Sets a velocity feed-forward v (m values): ẋ_d = v from now on
    /// (instead of the profile's velocity), held until the next
    /// [`Transition::start`] with a goal (a setpoint stream sends the goal and
    /// its velocity together). Wrong lengths are ignored.
    pub fn set_feed_forward(&mut self, velocity: &[f64]) {
        if velocity.len() == self.dim() {
            self.feed_forward.as_mut_slice().copy_from_slice(velocity);
            self.update();
        }
    }

    /// Whether a nonzero velocity feed-forward is held.
    pub fn has_feed_forward(&self) -> bool {
        self.feed_forward.iter().any(|&v| v != 0.0)
    }

    /// Starts a transition of `duration` s (≤ 0: the target is reached at
    /// once) from the current equilibrium and gains to `target`. The caller
    /// has checked the target (lengths m, finite, SPD); a wrong length is
    /// ignored for that part. Allocation-free.
    pub fn start(&mut self, target: Target<'_>, duration: f64) {
        let m = self.dim();
        let duration = if duration.is_finite() {
            duration.max(0.0)
        } else {
            0.0
        };
        let rotation_rows = self.kind.rotation_rows();
        if let Some(goal) = target.goal.filter(|g| g.len() == m) {
            // From where the equilibrium is now.
            if rotation_rows.is_some() {
                self.rot_from = self.current_rotation();
            }
            self.goal_from.copy_from(&self.goal);
            self.feed_forward.fill(0.0);
            self.goal_to.as_mut_slice().copy_from_slice(goal);
            if let Some(o) = rotation_rows {
                self.rot_to = rpy_at(goal, o);
            }
            self.duration = duration;
            self.elapsed = 0.0;
        }
        let k = target.stiffness.filter(|k| k.shape() == (m, m));
        let d = target.damping.filter(|d| d.shape() == (m, m));
        if k.is_some() || d.is_some() {
            // From the gains in force now; a gain not set keeps the target
            // of a transition still under way.
            self.k_from.copy_from(&self.stiffness);
            self.d_from.copy_from(&self.damping);
            if let Some(k) = k {
                self.k_to.copy_from(k);
            }
            if let Some(d) = d {
                self.d_to.copy_from(d);
            }
            self.gain_duration = duration;
            self.gain_elapsed = 0.0;
        }
        self.update();
    }

    /// Advances the transition by `dt` s and updates the equilibrium, its
    /// velocity and the gains. Allocation-free.
    pub fn advance(&mut self, dt: f64) {
        if dt.is_finite() && dt > 0.0 {
            self.elapsed = (self.elapsed + dt).min(self.duration);
            self.gain_elapsed = (self.gain_elapsed + dt).min(self.gain_duration);
        }
        self.update();
    }

    /// Time elapsed on the gains' clock (s).
    pub fn gain_elapsed(&self) -> f64 {
        self.gain_elapsed
    }

    /// Sets the gains' clock back to `elapsed` (s, clamped to the gains'
    /// transition) and updates the gains: a step the law could not take
    /// (its energy tanks could not pay a stiffening) is taken again later.
    /// Allocation-free.
    pub fn rewind_gains(&mut self, elapsed: f64) {
        if elapsed.is_finite() {
            self.gain_elapsed = elapsed.clamp(0.0, self.gain_duration);
            self.update();
        }
    }

    /// Time elapsed on the goal's clock (s).
    pub fn goal_elapsed(&self) -> f64 {
        self.elapsed
    }

    /// Sets the goal's clock back to `elapsed` (s, clamped to the goal's
    /// transition) and updates the equilibrium: a step the law could not
    /// take (its command tank and the tanks' spare could not pay the goal's
    /// work) is taken again later. Allocation-free.
    pub fn rewind_goal(&mut self, elapsed: f64) {
        if elapsed.is_finite() {
            self.elapsed = elapsed.clamp(0.0, self.duration);
            self.update();
        }
    }

    /// Progress σ = t / T in [0, 1] of the goal's transition (1 when none runs).
    pub fn goal_progress(&self) -> f64 {
        sigma(self.elapsed, self.duration)
    }

    /// Progress σ = t / T in [0, 1] of the gains' transition (1 when none runs).
    pub fn gain_progress(&self) -> f64 {
        sigma(self.gain_elapsed, self.gain_duration)
    }

    /// Progress σ in [0, 1] of the slower of the goal's and the gains'
    /// transitions (1 when neither runs).
    pub fn progress(&self) -> f64 {
        self.goal_progress().min(self.gain_progress())
    }

    /// Whether a transition is under way.
    pub fn is_moving(&self) -> bool {
        self.progress() < 1.0
    }

    /// The equilibrium x_{i,d}(t) (roll, pitch, yaw for orientation).
    pub fn goal(&self) -> &[f64] {
        self.goal.as_slice()
    }

    /// The target the transition moves to.
    pub fn target_goal(&self) -> &[f64] {
        self.goal_to.as_slice()
    }

    /// ẋ_{i,d}(t): the profile's velocity, or the feed-forward when one is
    /// held (world-frame angular velocity for orientation).
    pub fn goal_velocity(&self) -> &[f64] {
        self.goal_velocity.as_slice()
    }

    /// K_i(t).
    pub fn stiffness(&self) -> &DMatrix<f64> {
        &self.stiffness
    }

    /// D_i(t).
    pub fn damping(&self) -> &DMatrix<f64> {
        &self.damping
    }
}
