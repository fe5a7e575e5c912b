//! **Velocity limits: the governor.** The dynamics can still carry a joint faster
//! (inertia shifting between joints, several levels adding up): near a velocity
//! limit the springs stop driving the motion. With x_k = (|q̇_k| − f_on v_k) / ((f_full − f_on) v_k) (f_on =
//! `velocity_limit_fraction`, f_full = `velocity_limit_full_fraction`, v_k the URDF
//! velocity limit), the gain g = 1 − Π_k (1 − s(x_k)) ∈ [0, 1] (0 below f_on, 1 as
//! soon as one joint is at f_full) scales the spring force of each level,
//!
//! F_i = σ_i ∂V_i/∂x_i + D_i ẋ_i (in τ_i of eqs. 20, 21),  σ_i = 1 − g · s(c_i / c_0),
//!
//! where c_i = −q̇ᵀ J_iᵀ ∂V_i/∂x_i / (‖J_iᵀ ∂V_i/∂x_i‖ ‖q̇‖) is the cosine between the
//! motion and the spring's torque ([`GOVERNOR_COSINE`] = c_0): only a spring that
//! drives the motion (its potential falls, ẋ_iᵀ ∂V_i/∂x_i < 0) is scaled, one that
//! brakes or acts across the motion is kept. What the spring no longer puts into
//! motion, (1 − σ_i) ẋ_iᵀ ∂V_i/∂x_i ≤ 0, leaves the storage Σ S_i (for level 1
//! exactly: d/dt (½ q̇ᵀMq̇ + V_1) gains (1 − σ_1) ẋ_1ᵀ ∂V_1/∂x_1 ≤ 0); it goes to the
//! fade's tank with the dampers' dissipation. The dampers D_i are untouched and
//! brake. s is the smoothstep, so σ_i is C¹ in q̇ with σ_i = 1, σ̇_i = 0 at the onset:
//! no torque jump and no torque-rate jump. The equilibria are the law's (σ_i = 1 at
//! rest), and below f_on of every limit nothing changes (bit for bit).

use super::{GOVERNOR_COSINE, GOVERNOR_RELEASE_RATE, Safety, smoothstep};
use nalgebra::DVector;

/// The velocity governor's factor σ_i = 1 − g · s(c_i / [`GOVERNOR_COSINE`]) of a
/// level's spring force (module docs): `g` the governor's gain, `power` =
/// ẋ_iᵀ ∂V_i/∂x_i = q̇ᵀ J_iᵀ ∂V_i/∂x_i (the rate of V_i), `torque_norm` =
/// ‖J_iᵀ ∂V_i/∂x_i‖, `speed` = ‖q̇‖, c_i = −power / (torque_norm · speed).
/// 1 exactly when g = 0 or the spring does not drive the motion (power ≥ 0).
pub(crate) fn spring_scale(g: f64, power: f64, torque_norm: f64, speed: f64) -> f64 {
    // `!(power < 0.0)` also catches a NaN power.
    if g <= 0.0 || power >= 0.0 || power.is_nan() {
        return 1.0;
    }
    let denom = torque_norm * speed;
    if denom.is_nan() || denom <= 0.0 {
        return 1.0;
    }
    1.0 - g * smoothstep(-power / denom / GOVERNOR_COSINE)
}

impl Safety {
    /// The velocity governor's gain g = 1 − Π_k (1 − s(x_k)) of this cycle (module
    /// docs): 0 while every joint is below f_on of its velocity limit (or the
    /// governor is off), 1 once one is at f_full; C¹ in q̇.
    pub(crate) fn governor_gain(&mut self, qd: &DVector<f64>) -> f64 {
        if !self.spec.enabled || !self.spec.velocity_governor {
            return 0.0;
        }
        let mut keep = 1.0;
        for k in 0..qd.len() {
            let x = self.speed_band(k);
            if x > 0.0 {
                keep *= 1.0 - smoothstep(x);
            }
        }
        // It follows a rise at once and falls at most at GOVERNOR_RELEASE_RATE:
        // an arm swinging through the band keeps its springs held back
        // instead of switching them on and off every few cycles.
        let release = GOVERNOR_RELEASE_RATE * self.spec.control_period_s;
        let g = (1.0 - keep).max(self.governor_prev - release).max(0.0);
        self.governor_prev = g;
        g
    }
}
