//! **Velocity limits: the spring saturation.** A large task error pulls hard, and
//! the damper D_i lets a level settle at the task speed D_i⁻¹ ∂V_i/∂x_i. Each level's
//! potential is therefore replaced beyond the radius r_0,i by its linear extension
//! (a Huber function of r = √(2 V_i)):
//!
//! V_i,sat = V_i for r ≤ r_0,  r_0 r − r_0²/2 beyond,  ∂V_i,sat/∂x_i = min(1, r_0/r) ∂V_i/∂x_i,
//!
//! with r_0,i = d_min(D_i) v_i / √λ_max(K_i), so that ‖∂V_i,sat/∂x_i‖ ≤ d_min v_i:
//! the speed the damper settles at is at most v_i, the task speed whose
//! least-squares joint velocity J_i⁺ ẋ_i keeps every joint within f_full of its
//! velocity limit at the initial configuration (computed at construction).
//! V_i,sat is a potential (the force keeps its direction and is its gradient), so
//! the paper's passivity argument holds unchanged with S_i (eqs. 26, 28) built on V_i,sat, and
//! the equilibria are the law's. V_i,sat is C¹ and its force continuous in the
//! state (no torque jump; crossing r_0 only bends the torque's rate; at t = 0 it
//! only lowers the initial torque). Without a finite velocity limit (the
//! paper's planar arm) r_0 = ∞ and nothing changes.

use super::Safety;
use nalgebra::{DMatrix, DVector};

impl Safety {
    /// The spring saturation's task speed of each level from its Jacobian `j` at the
    /// initial configuration: v_i = f_full · min_k v_k / ‖(J_i⁺)_k‖, the largest task
    /// speed whose least-squares joint velocity J_i⁺ ẋ_i keeps every joint k within
    /// f_full of its velocity limit v_k, whatever the direction of ẋ_i (∞ without a
    /// finite velocity limit or with the saturation off). Allocates (construction).
    pub(crate) fn set_task_speeds(&mut self, jacobians: &[&DMatrix<f64>]) {
        for (i, &j) in jacobians.iter().enumerate() {
            let mut v = f64::INFINITY;
            if self.spec.enabled
                && self.spec.spring_saturation
                && let Ok(pinv) = j.clone().pseudo_inverse(1e-9)
            {
                for (k, &vk) in self.velocity_limit.iter().enumerate() {
                    let row = pinv.row(k).norm();
                    if vk.is_finite() && row > 0.0 {
                        v = v.min(self.spec.velocity_limit_full_fraction * vk / row);
                    }
                }
            }
            self.task_speed[i] = v;
        }
    }

    /// Sets level `i`'s r_0,i for the gains `stiffness`, `damping`
    /// ([`Safety::spring_radius_for`]). Allocation-free (also for `set_gains`).
    pub(crate) fn set_spring_radius(
        &mut self,
        i: usize,
        stiffness: &DMatrix<f64>,
        damping: &DMatrix<f64>,
    ) {
        self.spring_radius[i] = self.spring_radius_for(i, stiffness, damping);
    }

    /// Level `i`'s r_0,i now (∞: not saturated).
    pub(crate) fn spring_radius(&self, i: usize) -> f64 {
        self.spring_radius[i]
    }

    /// r_0,i = F_max,i / √λ_max(K_i) with F_max,i = d_min(D_i) · v_i, for the gains
    /// `stiffness`, `damping` of level `i` (λ_max bounded by the largest absolute row
    /// sum, d_min the smallest diagonal entry; ∞ without a task speed).
    /// Allocation-free.
    pub(crate) fn spring_radius_for(
        &self,
        i: usize,
        stiffness: &DMatrix<f64>,
        damping: &DMatrix<f64>,
    ) -> f64 {
        let v = self.task_speed[i];
        if !v.is_finite() {
            return f64::INFINITY;
        }
        let m = stiffness.nrows();
        let mut kmax: f64 = 0.0;
        for a in 0..m {
            let mut row = 0.0;
            for b in 0..m {
                row += stiffness[(a, b)].abs();
            }
            kmax = kmax.max(row);
        }
        let dmin = (0..damping.nrows())
            .map(|a| damping[(a, a)])
            .fold(f64::INFINITY, f64::min);
        if kmax > 0.0 && dmin > 0.0 {
            dmin * v / kmax.sqrt()
        } else {
            f64::INFINITY
        }
    }

    /// The spring saturation of level `i` (module docs): with r = √(2 V_i) beyond
    /// r_0,i, the gradient `grad` is scaled by r_0/r in place and the saturated
    /// potential r_0 r − r_0²/2 returned; else V_i unchanged. Returns (V, scale).
    pub(crate) fn saturate_spring(
        &self,
        i: usize,
        potential: f64,
        grad: &mut DVector<f64>,
    ) -> (f64, f64) {
        let r0 = self.spring_radius[i];
        if !r0.is_finite() {
            return (potential, 1.0);
        }
        let r = (2.0 * potential.max(0.0)).sqrt();
        if r <= r0 {
            return (potential, 1.0);
        }
        let scale = r0 / r;
        *grad *= scale;
        (saturated_potential(potential, r0), scale)
    }
}

/// V_sat of the potential V and the radius r_0 (module docs): V for
/// r = √(2V) ≤ r_0 (and for r_0 = ∞), r_0 r − r_0²/2 beyond.
pub(crate) fn saturated_potential(potential: f64, r0: f64) -> f64 {
    let r = (2.0 * potential.max(0.0)).sqrt();
    if !r0.is_finite() || r <= r0 {
        potential
    } else {
        r0 * r - 0.5 * r0 * r0
    }
}
