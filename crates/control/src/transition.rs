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

use nalgebra::{DMatrix, DVector, UnitQuaternion, Vector3};

use crate::ControlError;

/// The minimum-jerk profile at σ (clamped to [0, 1]): (s, ds/dσ, d²s/dσ²).
#[inline]
pub fn quintic(sigma: f64) -> (f64, f64, f64) {
    let x = sigma.clamp(0.0, 1.0);
    let x2 = x * x;
    let s = x2 * x * (10.0 + x * (-15.0 + 6.0 * x));
    let ds = 30.0 * x2 * (1.0 - x) * (1.0 - x);
    let dds = 60.0 * x * (1.0 - x) * (1.0 - 2.0 * x);
    (s, ds, dds)
}

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

/// One level's equilibrium and gains, moving from where they are to a new
/// target over a transition. The goal and the gains have clocks of their
/// own: a setpoint that sets only one of them restarts only its clock, so a
/// stiffness change sent while the goal moves leaves the goal's motion as it
/// was (and a new goal leaves a running gain transition on its way).
#[derive(Debug, Clone)]
pub struct Transition {
    kind: GoalKind,
    /// The goal's transition: duration and time elapsed, s.
    duration: f64,
    elapsed: f64,
    /// The gains' transition: duration and time elapsed, s.
    gain_duration: f64,
    gain_elapsed: f64,
    goal_from: DVector<f64>,
    goal_to: DVector<f64>,
    rot_from: UnitQuaternion<f64>,
    rot_to: UnitQuaternion<f64>,
    k_from: DMatrix<f64>,
    k_to: DMatrix<f64>,
    d_from: DMatrix<f64>,
    d_to: DMatrix<f64>,
    goal: DVector<f64>,
    goal_velocity: DVector<f64>,
    /// Velocity feed-forward that replaces the profile's ẋ_d (from a
    /// setpoint stream), held until the next goal.
    feed_forward: DVector<f64>,
    stiffness: DMatrix<f64>,
    damping: DMatrix<f64>,
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

#[cfg(test)]
fn rpy(v: &DVector<f64>) -> UnitQuaternion<f64> {
    rpy_at(v.as_slice(), 0)
}

/// σ = t / T clamped to [0, 1]; 1 for T = 0.
fn sigma(elapsed: f64, duration: f64) -> f64 {
    if duration > 0.0 {
        (elapsed / duration).clamp(0.0, 1.0)
    } else {
        1.0
    }
}

/// The rotation of the roll, pitch, yaw values at `v[o..o + 3]`.
fn rpy_at(v: &[f64], o: usize) -> UnitQuaternion<f64> {
    UnitQuaternion::from_euler_angles(v[o], v[o + 1], v[o + 2])
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

    fn update(&mut self) {
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

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn profile_endpoints_rest_and_clamp() {
        assert_eq!(quintic(0.0), (0.0, 0.0, 0.0));
        let (s, ds, dds) = quintic(1.0);
        assert_eq!((s, ds, dds), (1.0, 0.0, 0.0));
        assert_eq!(quintic(-3.0), (0.0, 0.0, 0.0));
        assert_eq!(quintic(7.0), (1.0, 0.0, 0.0));
        // Symmetric: s(½) = ½, peak speed 15/8 there, no acceleration.
        let (s, ds, dds) = quintic(0.5);
        assert!((s - 0.5).abs() < 1e-15 && (ds - 1.875).abs() < 1e-15 && dds.abs() < 1e-15);
        // Monotone.
        let mut last = 0.0;
        for k in 1..=1000 {
            let (s, ds, _) = quintic(k as f64 / 1000.0);
            assert!(s >= last && ds >= 0.0);
            last = s;
        }
    }

    #[test]
    fn profile_is_c2() {
        // The derivatives are those of s (central differences), and s, s′, s″
        // are continuous across σ = 0 and σ = 1 (zero on the outside).
        let h = 1e-6;
        for k in 0..=200 {
            let x = k as f64 / 200.0;
            let (_, ds, dds) = quintic(x);
            if (h..=1.0 - h).contains(&x) {
                let num_ds = (quintic(x + h).0 - quintic(x - h).0) / (2.0 * h);
                let num_dds = (quintic(x + h).1 - quintic(x - h).1) / (2.0 * h);
                assert!((num_ds - ds).abs() < 1e-8, "s′ at {x}");
                assert!((num_dds - dds).abs() < 1e-6, "s″ at {x}");
            }
        }
        for edge in [0.0, 1.0] {
            let (a, b) = (quintic(edge - 1e-9), quintic(edge + 1e-9));
            assert!((a.0 - b.0).abs() < 1e-12);
            assert!((a.1 - b.1).abs() < 1e-12);
            assert!((a.2 - b.2).abs() < 1e-7);
        }
    }

    fn diag(v: &[f64]) -> DMatrix<f64> {
        DMatrix::from_diagonal(&DVector::from_column_slice(v))
    }

    /// A stiffness change sent while the goal moves leaves the goal's
    /// motion exactly as it was; the gains reach their target on their own
    /// clock, and a later goal leaves the gain transition on its way.
    #[test]
    fn goal_and_gains_move_on_clocks_of_their_own() {
        let k = diag(&[500.0, 500.0]);
        let d = diag(&[40.0, 40.0]);
        let goal = Target {
            goal: Some(&[0.2, 0.0]),
            ..Target::default()
        };
        let mut plain = Transition::new(GoalKind::Vector, &[0.0, 1.0], &k, &d).unwrap();
        let mut t = plain.clone();
        plain.start(goal, 1.0);
        t.start(goal, 1.0);
        let dt = 1e-3;
        for _ in 0..500 {
            plain.advance(dt);
            t.advance(dt);
        }
        let stiff = diag(&[800.0, 800.0]);
        t.start(
            Target {
                stiffness: Some(&stiff),
                ..Target::default()
            },
            0.2,
        );
        assert_eq!(t.stiffness(), &k, "no jump of K at the start");
        for step in 0..500 {
            plain.advance(dt);
            t.advance(dt);
            assert_eq!(t.goal(), plain.goal(), "goal unchanged at step {step}");
            assert_eq!(t.goal_velocity(), plain.goal_velocity());
            if step == 99 {
                let mid = t.stiffness()[(0, 0)];
                assert!((mid - 650.0).abs() < 1e-9, "K half way at σ = ½: {mid}");
                assert!(t.is_moving());
            }
        }
        assert_eq!(t.goal(), &[0.2, 0.0]);
        assert_eq!(t.stiffness(), &stiff);
        assert_eq!(t.damping(), &d);
        assert!(!t.is_moving());
        // A new goal during a gain transition: the gains go on to their target.
        let soft = diag(&[300.0, 300.0]);
        t.start(
            Target {
                stiffness: Some(&soft),
                ..Target::default()
            },
            1.0,
        );
        for _ in 0..250 {
            t.advance(dt);
        }
        let k_quarter = t.stiffness()[(0, 0)];
        t.start(
            Target {
                goal: Some(&[0.0, 0.0]),
                ..Target::default()
            },
            0.1,
        );
        assert_eq!(
            t.stiffness()[(0, 0)],
            k_quarter,
            "the gains go on from where they are"
        );
        for _ in 0..750 {
            t.advance(dt);
        }
        assert_eq!(t.stiffness(), &soft);
        assert_eq!(t.goal(), &[0.0, 0.0]);
    }

    #[test]
    fn vector_goal_moves_smoothly_and_arrives() {
        let k = diag(&[500.0, 500.0]);
        let d = diag(&[40.0, 40.0]);
        let mut t = Transition::new(GoalKind::Vector, &[0.0, 1.0], &k, &d).unwrap();
        assert!(!t.is_moving());
        t.start(
            Target {
                goal: Some(&[0.2, 0.0]),
                ..Target::default()
            },
            2.0,
        );
        assert_eq!(t.goal(), &[0.0, 1.0], "no jump at the start");
        assert_eq!(t.goal_velocity(), &[0.0, 0.0]);
        let dt = 1e-3;
        let mut travelled = 0.0;
        let mut prev = t.goal()[0];
        for _ in 0..1000 {
            t.advance(dt);
            travelled += (t.goal()[0] - prev).abs();
            prev = t.goal()[0];
        }
        assert!((t.progress() - 0.5).abs() < 1e-12);
        assert!((t.goal()[0] - 0.1).abs() < 1e-12, "half way at σ = ½");
        // Peak speed 15/8 · Δ / T.
        assert!((t.goal_velocity()[0] - 1.875 * 0.2 / 2.0).abs() < 1e-9);
        assert!((t.goal_velocity()[1] + 1.875 * 1.0 / 2.0).abs() < 1e-9);
        for _ in 0..1500 {
            t.advance(dt);
        }
        assert!(!t.is_moving());
        assert_eq!(t.goal(), &[0.2, 0.0]);
        assert_eq!(t.goal_velocity(), &[0.0, 0.0]);
        assert!(travelled <= 0.1 + 1e-12, "monotone");
        // Zero duration: the target at once.
        t.start(
            Target {
                goal: Some(&[1.0, 1.0]),
                ..Target::default()
            },
            0.0,
        );
        assert_eq!(t.goal(), &[1.0, 1.0]);
        assert_eq!(t.progress(), 1.0);
    }

    #[test]
    fn a_new_target_starts_from_where_the_equilibrium_is() {
        let k = diag(&[1.0]);
        let mut t = Transition::new(GoalKind::Vector, &[0.0], &k, &k).unwrap();
        t.start(
            Target {
                goal: Some(&[1.0]),
                ..Target::default()
            },
            1.0,
        );
        for _ in 0..500 {
            t.advance(1e-3);
        }
        let here = t.goal()[0];
        t.start(
            Target {
                goal: Some(&[-1.0]),
                ..Target::default()
            },
            1.0,
        );
        assert_eq!(t.goal()[0], here);
        assert_eq!(t.target_goal(), &[-1.0]);
        t.advance(1.0);
        assert_eq!(t.goal(), &[-1.0]);
    }

    #[test]
    fn orientation_follows_the_geodesic() {
        let k = diag(&[10.0; 3]);
        let mut t = Transition::new(GoalKind::RollPitchYaw, &[0.0, 0.0, 0.0], &k, &k).unwrap();
        let yaw = std::f64::consts::FRAC_PI_2;
        t.start(
            Target {
                goal: Some(&[0.0, 0.0, yaw]),
                ..Target::default()
            },
            1.0,
        );
        t.advance(0.5);
        let g = t.goal();
        assert!(g[0].abs() < 1e-12 && g[1].abs() < 1e-12);
        assert!((g[2] - yaw / 2.0).abs() < 1e-12, "{g:?}");
        let w = t.goal_velocity();
        assert!(
            (w[2] - 1.875 * yaw).abs() < 1e-9 && w[0].abs() < 1e-12,
            "{w:?}"
        );

        // A general pair: the angle to the start grows as s·θ, on the geodesic.
        let (a, b) = ([0.3, -0.4, 1.0], [-1.2, 0.5, -2.5]);
        let mut t = Transition::new(GoalKind::RollPitchYaw, &a, &k, &k).unwrap();
        t.start(
            Target {
                goal: Some(&b),
                ..Target::default()
            },
            1.0,
        );
        let (ra, rb) = (
            rpy(&DVector::from_column_slice(&a)),
            rpy(&DVector::from_column_slice(&b)),
        );
        let theta = ra.angle_to(&rb);
        for k in 1..=10 {
            t.advance(0.1);
            let (s, _, _) = quintic(k as f64 / 10.0);
            let r = rpy(&DVector::from_column_slice(t.goal()));
            assert!((ra.angle_to(&r) - s * theta).abs() < 1e-9);
            assert!((r.angle_to(&rb) - (1.0 - s) * theta).abs() < 1e-9);
        }
        assert!(t.current_rotation().angle_to(&rb) < 1e-12);
    }

    #[test]
    fn a_pose_moves_its_position_linearly_and_its_orientation_on_the_geodesic() {
        let k = diag(&[100.0; 6]);
        let from = [0.4, 0.0, 0.5, 3.0, -0.2, 0.1];
        let to = [0.5, 0.1, 0.3, -2.0, 0.6, -1.2];
        let mut t = Transition::new(GoalKind::Pose, &from, &k, &k).unwrap();
        t.start(
            Target {
                goal: Some(&to),
                ..Target::default()
            },
            1.0,
        );
        let (ra, rb) = (rpy_at(&from, 3), rpy_at(&to, 3));
        let theta = ra.angle_to(&rb);
        let axis = (ra.inverse() * rb).axis().unwrap();
        assert!(theta > 1.0, "a large rotation: {theta}");
        let mut last_angle = 0.0;
        let steps = 200;
        for k in 1..=steps {
            t.advance(1.0 / steps as f64);
            let (s, ds, _) = quintic(k as f64 / steps as f64);
            let g = t.goal();
            // Position rows: the straight line, at s.
            for a in 0..3 {
                assert!((g[a] - (from[a] + s * (to[a] - from[a]))).abs() < 1e-12);
                assert!((t.goal_velocity()[a] - ds * (to[a] - from[a])).abs() < 1e-9);
            }
            // Orientation rows: on the geodesic — the angle to the start grows
            // monotonically (as s·θ), the axis of R_0ᵀ R(t) stays that of R_0ᵀ R_1.
            let r = rpy_at(g, 3);
            let angle = ra.angle_to(&r);
            assert!(angle >= last_angle - 1e-12, "monotone at step {k}");
            assert!((angle - s * theta).abs() < 1e-9, "s·θ at step {k}");
            if angle > 1e-6 {
                let ax = (ra.inverse() * r).axis().unwrap();
                assert!(
                    (ax.into_inner() - axis.into_inner()).norm() < 1e-9,
                    "axis at step {k}"
                );
            }
            // ω_d along the world-frame axis R_0 n, of size ṡ θ.
            let w = Vector3::new(
                t.goal_velocity()[3],
                t.goal_velocity()[4],
                t.goal_velocity()[5],
            );
            let expected = ra * axis.into_inner() * (ds * theta);
            if k < steps {
                assert!((w - expected).norm() < 1e-9, "ω at step {k}: {w:?}");
            }
            last_angle = angle;
        }
        assert!(!t.is_moving());
        assert_eq!(t.goal(), &to, "at rest on the target as sent");
        assert_eq!(t.goal_velocity(), &[0.0; 6]);
        // The distance for the speed limit: √(|Δp|² + θ²).
        let back = t.distance_to(&from);
        let dp: f64 = (0..3).map(|a| (to[a] - from[a]).powi(2)).sum();
        assert!((back - (dp + theta * theta).sqrt()).abs() < 1e-9);
        let e = Transition::new(
            GoalKind::Pose,
            &[0.0; 3],
            &diag(&[1.0; 3]),
            &diag(&[1.0; 3]),
        )
        .unwrap_err();
        assert!(e.to_string().contains("6 values"), "{e}");
    }

    #[test]
    fn bad_sizes_are_errors() {
        let k = diag(&[1.0; 2]);
        let e = Transition::new(GoalKind::RollPitchYaw, &[0.0; 2], &k, &k).unwrap_err();
        assert!(e.to_string().contains("3 values"), "{e}");
        let e = Transition::new(GoalKind::Vector, &[0.0; 3], &k, &k).unwrap_err();
        assert!(e.to_string().contains("2×2"), "{e}");
        let e = Transition::new(GoalKind::Vector, &[f64::NAN; 2], &k, &k).unwrap_err();
        assert!(e.to_string().contains("non-finite"), "{e}");
    }

    #[test]
    fn gains_stay_symmetric_positive_definite() {
        // Two SPD matrices with very different eigenvectors.
        let k0 = DMatrix::from_row_slice(3, 3, &[900.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0]);
        let k1 = DMatrix::from_row_slice(3, 3, &[2.0, 1.9, 0.0, 1.9, 2.0, 0.0, 0.0, 0.0, 500.0]);
        let d = diag(&[1.0; 3]);
        let mut t = Transition::new(GoalKind::Vector, &[0.0; 3], &k0, &d).unwrap();
        t.start(
            Target {
                stiffness: Some(&k1),
                ..Target::default()
            },
            1.0,
        );
        for _ in 0..=100 {
            let k = t.stiffness();
            assert!((k - k.transpose()).amax() == 0.0, "symmetric");
            let min = k.clone().symmetric_eigenvalues().min();
            assert!(min > 0.0, "SPD, λ_min = {min}");
            assert_eq!(t.goal(), &[0.0; 3], "the goal stays");
            t.advance(0.01);
        }
        assert_eq!(t.stiffness(), &k1);
        assert_eq!(t.damping(), &d);
    }
}
