//! **Joint-limit guard.** A dissipative safety layer below the hierarchy (not a task of
//! it): within `joint_limit_margin` of a URDF position limit, with penetration
//! p = q − (upper − margin) (resp. (lower + margin) − q) ≥ 0, the joint gets the
//! spring torque k p² (k = torque / (margin/2)², `torque` = `joint_limit_torque` or the
//! URDF effort limit, i.e. the effort limit at half the margin and four times it at the
//! limit) and the damping −s(p/(0.1 margin)) · min(2ζ √(2 k p · m_k), m_k / T) q̇ — the
//! damping ratio ζ against the spring's local stiffness 2 k p, brought in over the
//! first tenth of the margin ([`GUARD_RAMP`]) — with s the smoothstep,
//! m_k = 1/(M⁻¹)_kk the joint's effective inertia and T the control period (a damping
//! above m_k / T is more than the sampled loop carries, crate::rate). Both vanish with
//! their first derivative at p = 0: no torque jump and no torque-rate jump at
//! activation. The spring has the potential k p³/3 (in [`SafetyOutput::guard_potential`]).

use super::{GUARD_RAMP, Safety, SafetyOutput, smoothstep};

impl Safety {
    /// Joint `k`'s penetration p ≥ 0 into the margin at position `q`, and the
    /// side: 1 towards the upper limit, −1 towards the lower (0 outside).
    pub(super) fn penetration(&self, k: usize, q: f64) -> (f64, f64) {
        let margin = self.spec.joint_limit_margin;
        // Penetration into the margin (positive: towards the upper limit).
        let up = q - (self.upper[k] - margin);
        let lo = (self.lower[k] + margin) - q;
        if up > 0.0 {
            (up, 1.0)
        } else if lo > 0.0 {
            (lo, -1.0)
        } else {
            (0.0, 0.0)
        }
    }

    /// The guard's spring and damping on joint `k` (penetration `p` > 0 on
    /// side `sign`, effective inertia `m_k`, speed `qd`) added to `out.tau`.
    pub(super) fn guard(
        &self,
        k: usize,
        (p, sign): (f64, f64),
        m_k: f64,
        qd: f64,
        out: &mut SafetyOutput,
    ) {
        let margin = self.spec.joint_limit_margin;
        let kg = self.k_guard[k];
        // At most m_k / T: a heavier damping than the joint's own inertia
        // carries at the control period would drive an oscillation
        // (crate::rate, b ≤ 1).
        // The damping ratio ζ against the spring's local stiffness 2 k p
        // wherever it is deeper than GUARD_RAMP · margin (a joint resting
        // shallow in the margin is damped as well as a deep one).
        let d = (self.spec.joint_limit_damping_ratio * 2.0 * (2.0 * kg * p * m_k).sqrt())
            .min(m_k / self.spec.control_period_s);
        out.tau[k] += -sign * kg * p * p - smoothstep(p / (GUARD_RAMP * margin)) * d * qd;
        out.guard_potential += kg * p * p * p / 3.0;
        out.joint_limit_active = true;
    }
}
