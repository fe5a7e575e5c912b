//! The speed each joint reaches this cycle and its place in the velocity band
//! between f_on and f_full of its URDF velocity limit: the input of the
//! governor, the velocity damping and the velocity barrier.

use super::{Safety, diagonal_of_llt};
use nalgebra::{DMatrix, DVector};

impl Safety {
    /// The speed each joint reaches (`reach`, module docs) at this cycle's
    /// state: |q̇_k|, plus, with a torque rate limit R and the applied torque's
    /// acceleration q̈_a driving it away from rest, the a² M_kk / (2R) it gains
    /// while the applied torque brakes at the rate limit (M_kk ≥ m_k: an
    /// upper bound). Call once per cycle before the other parts. Allocation-free.
    pub(crate) fn set_reach(
        &mut self,
        qd: &DVector<f64>,
        applied_qdd: Option<&DVector<f64>>,
        chol: &DMatrix<f64>,
    ) {
        for k in 0..qd.len() {
            let mut v = qd[k].abs();
            if let (Some(rate), Some(qa)) = (self.spec.torque_rate_limit, applied_qdd)
                && self.spec.enabled
            {
                let a = qd[k].signum() * qa[k];
                if a > 0.0 {
                    v += a * a * diagonal_of_llt(chol, k) / (2.0 * rate);
                }
            }
            self.reach[k] = v;
        }
    }

    /// Position of the joint's reach (`set_reach`) in the velocity band: 0 at
    /// f_on · v_max, 1 at f_full · v_max (not clamped; 0 for a joint without a
    /// velocity limit).
    pub(super) fn speed_band(&self, k: usize) -> f64 {
        let qd = self.reach[k];
        let vmax = self.velocity_limit[k];
        if !vmax.is_finite() {
            return 0.0;
        }
        let (on, full) = (
            self.spec.velocity_limit_fraction,
            self.spec.velocity_limit_full_fraction,
        );
        (qd.abs() - on * vmax) / ((full - on) * vmax)
    }
}
