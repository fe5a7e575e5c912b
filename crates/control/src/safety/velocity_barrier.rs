//! **Velocity limits: the barrier.** Governor and damping act on the speed; the
//! barrier on what the law's torque is about to do to it. With the acceleration
//! the law's torque τ produces on the model, q̈ = M⁻¹ (τ − C q̇ − g), a joint k in the
//! band (x_k > 0) may accelerate away from rest (sign(q̇_k) q̈_k) at most at
//!
//! a_k = min(α h_k, √(2 (R/m_k) h_k)),  h_k = f_full v_k − |q̇_k|,
//!
//! (α = `velocity_barrier_rate`; R the torque filter's rate limit when there is
//! one: the applied torque, and with it the acceleration, changes at most at R/m_k
//! per second, and braking from a_k at that jerk gains a_k² m_k/(2R) ≤ h_k of speed).
//! The excess Δ_k is removed by −s(x_k) m_k Δ_k sign(q̇_k): it only ever opposes the
//! motion (power ≤ 0), scaled in by the smoothstep (no torque jump), zero below
//! f_on (bit for bit).
//!
//! **Towards a position limit** the same rule holds with the speed from which
//! the joint can still stop before its URDF limit, d away:
//!
//! v_d = a_b (√(t_b² + 2 d / a_b) − t_b),  a_b = τ_b / M_kk,  t_b = τ_b / R + T
//!
//! (the distance v t_b + v² / (2 a_b): the brake τ_b = [`APPROACH_BRAKE_SHARE`]
//! of the guard's torque at half its margin — the effort limit — built at the
//! rate limit R within t_b, then held; M_kk ≥ m_k: a lower deceleration than
//! the joint has). A joint that enters the guard's margin at a speed its spring
//! cannot meet behind the rate limit (stiffness 2 k p, i.e. a torque rate
//! 2 k p |q̇|) lags it, and a lagging spring feeds the arm energy; braked to
//! v_d on the way, it arrives slowly enough. f_on v_d and f_full v_d bound its
//! band as they bound the speed's.

use super::{Safety, SafetyOutput, diagonal_of_llt, smoothstep};
use nalgebra::{DMatrix, DVector};

/// The share of a joint's guard torque at half the margin (its effort limit by
/// default) the approach bound brakes with.
pub const APPROACH_BRAKE_SHARE: f64 = 0.25;

impl Safety {
    /// Whether the velocity barrier needs the acceleration of this cycle: it is
    /// on and a joint is above f_on of its velocity limit or of its approach
    /// bound v_d, or a torque rate limit follows (then a hard acceleration
    /// below the band counts too).
    pub(crate) fn barrier_needs_acceleration(
        &self,
        q: &DVector<f64>,
        qd: &DVector<f64>,
        chol: &DMatrix<f64>,
    ) -> bool {
        self.spec.enabled
            && self.spec.velocity_barrier
            && (self.spec.torque_rate_limit.is_some()
                || (0..qd.len()).any(|k| {
                    self.speed_band(k) > 0.0 || self.approach_band(k, q[k], qd[k], chol).0 > 0.0
                }))
    }

    /// Joint `k` at `q` moving at `qd` towards a position limit: its place in
    /// the approach band (0 at f_on v_d, 1 at f_full v_d; ≤ 0 below it or
    /// moving away) and the speed left to f_full v_d (module docs).
    fn approach_band(&self, k: usize, q: f64, qd: f64, chol: &DMatrix<f64>) -> (f64, f64) {
        let d = if qd > 0.0 {
            self.upper[k] - q
        } else if qd < 0.0 {
            q - self.lower[k]
        } else {
            return (0.0, f64::INFINITY);
        };
        if !d.is_finite() {
            return (0.0, f64::INFINITY);
        }
        let half = 0.5 * self.spec.joint_limit_margin;
        let brake = APPROACH_BRAKE_SHARE * self.k_guard[k] * half * half;
        let a = brake / diagonal_of_llt(chol, k);
        let t = self.spec.torque_rate_limit.map_or(0.0, |r| brake / r) + self.spec.control_period_s;
        let v = a * ((t * t + 2.0 * d.max(0.0) / a).sqrt() - t);
        let (on, full) = (
            self.spec.velocity_limit_fraction,
            self.spec.velocity_limit_full_fraction,
        );
        let speed = qd.abs();
        if v.is_nan() || v <= 0.0 {
            // At or past the limit: any motion towards it is above the band.
            return (if speed > 0.0 { 1.0 } else { 0.0 }, -speed);
        }
        ((speed - on * v) / ((full - on) * v), full * v - speed)
    }

    /// The velocity barrier (module docs): for every joint above f_on of its
    /// velocity limit whose predicted acceleration `qdd` (the law's torque on
    /// the model, M⁻¹ (τ − C q̇ − g)) drives it faster than α (f_full v_k −
    /// |q̇_k|), the torque m_k Δ_k sign(q̇_k) that removes the excess Δ_k
    /// (scaled in by the smoothstep of the band) into `out.barrier_tau`, and
    /// added to `out.tau`. Returns whether it acted. Allocation-free.
    pub(crate) fn velocity_barrier(
        &mut self,
        q: &DVector<f64>,
        qd: &DVector<f64>,
        qdd: &DVector<f64>,
        applied_qdd: Option<&DVector<f64>>,
        chol: &DMatrix<f64>,
        out: &mut SafetyOutput,
    ) -> bool {
        if out.barrier_active {
            out.barrier_tau.fill(0.0);
        }
        out.barrier_active = false;
        if !(self.spec.enabled && self.spec.velocity_barrier) {
            return false;
        }
        let (alpha, full) = (
            self.spec.velocity_barrier_rate,
            self.spec.velocity_limit_full_fraction,
        );
        for k in 0..qd.len() {
            if !self.velocity_limit[k].is_finite() {
                continue;
            }
            let sign = qd[k].signum();
            // Acceleration away from rest, and the speed left below f_full v_k.
            let a = sign * qdd[k];
            let mut headroom = full * self.velocity_limit[k] - qd[k].abs();
            let x = self.speed_band(k);
            let mut m_k = None;
            let mut excess: f64 = 0.0;
            if x > 0.0 {
                let m = self.effective_inertia(chol, k);
                m_k = Some(m);
                excess = smoothstep(x) * (a - alpha * headroom);
            }
            // Towards a position limit: the speed it can still stop from.
            let (x_d, headroom_d) = self.approach_band(k, q[k], qd[k], chol);
            if x_d > 0.0 {
                if m_k.is_none() {
                    m_k = Some(self.effective_inertia(chol, k));
                }
                excess = excess.max(smoothstep(x_d) * (a - alpha * headroom_d));
            }
            headroom = headroom.min(headroom_d);
            // The applied torque lags the law's behind the rate limit: brake for
            // the faster of the two.
            let a_jerk = applied_qdd.map_or(a, |qa| a.max(sign * qa[k]));
            if let Some(rate) = self.spec.torque_rate_limit
                && a_jerk > 0.0
                && a_jerk * a_jerk * diagonal_of_llt(chol, k) > 2.0 * rate * headroom
            {
                // m_k ≤ M_kk: only a joint that might not stop in time gets its m_k.
                let m = *m_k.get_or_insert_with(|| self.effective_inertia(chol, k));
                excess = excess.max(a_jerk - (2.0 * rate / m * headroom.max(0.0)).sqrt());
            }
            if excess.is_nan() || excess <= 0.0 {
                continue;
            }
            let t = -sign * m_k.unwrap_or(0.0) * excess;
            out.barrier_tau[k] = t;
            out.tau[k] += t;
            out.barrier_active = true;
        }
        if out.barrier_active {
            out.active = true;
            out.velocity_limit_active = true;
            out.barrier_cycles += 1;
            out.power += out.barrier_tau.dot(qd);
        }
        out.barrier_active
    }
}
