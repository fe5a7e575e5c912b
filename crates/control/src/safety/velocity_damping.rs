//! **Velocity limits: the damping.** A joint in the band is also damped,
//! −s(x_k) · `velocity_damping` · m_k q̇_k (default 100 1/s, 0 switches it off):
//! dissipative and C¹ at the onset.

use super::{Safety, SafetyOutput, smoothstep};

impl Safety {
    /// Joint `k`'s place x_k in the velocity band for the damping (0 when the
    /// damping is off: it acts only with a rate > 0).
    pub(super) fn velocity_damping_band(&self, k: usize) -> f64 {
        if self.spec.velocity_damping > 0.0 {
            self.speed_band(k)
        } else {
            0.0
        }
    }

    /// −s(x_k) · `velocity_damping` · m_k q̇_k on joint `k` (x_k = `x` > 0)
    /// added to `out.tau`.
    pub(super) fn velocity_damping(
        &self,
        k: usize,
        x: f64,
        m_k: f64,
        qd: f64,
        out: &mut SafetyOutput,
    ) {
        out.tau[k] -= smoothstep(x) * self.spec.velocity_damping * m_k * qd;
        out.velocity_limit_active = true;
    }
}
