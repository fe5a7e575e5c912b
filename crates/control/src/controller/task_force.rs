//! A level's task terms of one cycle: x̃_i, J_i, J̇_i, the potential V_i and its
//! gradient, ẋ_i and the spring–damper force F_i = ∂V_i/∂x_iᵀ + D_i ẋ_i of
//! eqs. (20), (21) — with the safety layer's spring saturation and velocity
//! governor, and a contact reaction's softening κ, applied to the spring.

use super::Controller;
use hcc_linalg::products::{copy, gemv, gemv_t};
use nalgebra::DVector;

impl Controller {
    /// x̃_i, J_i, J̇_i, the potential V_i and its gradient, ẋ_i and F_i; the
    /// spring part scaled by the velocity governor (gain `governor`, `speed` = ‖q̇‖;
    /// crate::safety) where it drives the motion near a velocity limit.
    pub(super) fn evaluate_task(
        &mut self,
        i: usize,
        q: &DVector<f64>,
        qd: &DVector<f64>,
        governor: f64,
        speed: f64,
    ) {
        let l = &mut self.levels[i];
        let tasks = &self.spec.levels[i].tasks;
        let (model, data) = (&self.model, &self.data);
        crate::task::jacobian(
            model,
            data,
            tasks,
            &mut self.frames,
            &mut l.j,
            Some(&mut l.jdot),
        );
        l.potential = crate::task::potential(
            model,
            data,
            tasks,
            &mut self.frames,
            q,
            &l.stiffness,
            &l.goal,
            l.tank.spring_shift(),
            &mut l.pot,
            &mut l.err,
            &mut l.grad,
        );
        // Safety layer: the spring saturation (crate::safety): beyond r_0 the
        // gradient of the saturated potential, which replaces V_i.
        let (v_sat, scale) = self.safety.saturate_spring(i, l.potential, &mut l.grad);
        l.potential = v_sat;
        if scale < 1.0 {
            self.out.safety.spring_saturated = true;
        }
        // A contact reaction's softening: κ V_i, a potential still.
        let kappa = self.stiffness_scale;
        if kappa != 1.0 {
            l.potential *= kappa;
            l.grad *= kappa;
        }
        gemv(&mut l.xdot, 1.0, &l.j, qd, 0.0);
        // The rate of V_i at the spring point; the energy tank takes its
        // shift's rate off (crate::energy_tank).
        l.spring_rate = l.grad.dot(&l.xdot);
        if l.goal_moving {
            // A moving equilibrium: damp the velocity relative to it.
            l.xdot -= &l.goal_velocity;
        }
        // F_i = (∂V_i/∂x_i)ᵀ + D_i (ẋ_i − ẋ_{i,d}), ẋ_{i,d} = 0 for a fixed goal.
        copy(&mut l.f, &l.grad);
        let mut sigma = 1.0;
        if governor > 0.0 {
            // Velocity governor: σ_i from the spring's power and the cosine between
            // q̇ and −J_iᵀ ∂V_i/∂x_i (crate::safety).
            gemv_t(&mut self.tmp_n, 1.0, &l.j, &l.grad, 0.0);
            let power = self.tmp_n.dot(qd);
            sigma = crate::safety::spring_scale(governor, power, self.tmp_n.norm(), speed);
            if sigma < 1.0 {
                l.f *= sigma;
            }
        }
        self.out.safety.spring_scale[i] = sigma;
        gemv(&mut l.f, 1.0, &l.damping, &l.xdot, 1.0);
    }
}
