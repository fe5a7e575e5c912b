//! The discrete-time velocity limit on the torque that is sent
//! ([`hcc_control::velocity_limit`]): after the saturation, each joint's speed
//! one period ahead is held to 0.94 of its URDF limit (0.95 with a margin for
//! the model's drift within the period) by the smallest
//! correction in the kinetic-energy metric, a torque on the limited joints
//! against their motion. It runs where no torque-rate limit follows (a
//! correction the filter would delay does not hold within the period; there
//! the velocity barrier of the law's safety layer plans for the rate limit),
//! with the safety layer on; off, the torque is the law's bit for bit.
//! After the correction the torque is clipped to the effort limits again.

use hcc_control::velocity_limit::PeriodModel;
use hcc_control::{Controller, VelocityLimitOutcome, VelocityLimitWork, limit_velocity};
use hcc_model::linalg::products::gemv_slices;
use nalgebra::DVector;

/// The limit's state: on or off, the URDF velocity limits, its workspace.
pub(crate) struct VelocityLimit {
    on: bool,
    v_max: Vec<f64>,
    /// h = C q̇ (+ g where τ contains it).
    h: DVector<f64>,
    work: VelocityLimitWork,
}

impl VelocityLimit {
    /// For `controller`'s robot; `rate_limited`: a torque-rate limit follows
    /// the law (the limit is then off). Allocates.
    pub(crate) fn new(controller: &Controller, rate_limited: bool) -> VelocityLimit {
        let n = controller.nq();
        VelocityLimit {
            on: controller.spec().safety.enabled && !rate_limited,
            v_max: controller
                .model()
                .joints
                .iter()
                .map(|j| j.velocity_limit)
                .collect(),
            h: DVector::zeros(n),
            work: VelocityLimitWork::new(n),
        }
    }

    /// Corrects `tau` (length n, saturated, to be sent) at the state with
    /// velocity `qd` the law just ran on; `gravity_in_tau`: τ contains g(q);
    /// `limits`: the effort limits. `None` where the limit is off.
    /// Allocation-free.
    pub(crate) fn apply(
        &mut self,
        controller: &Controller,
        qd: &[f64],
        gravity_in_tau: bool,
        limits: &[f64],
        period_s: f64,
        tau: &mut [f64],
    ) -> Option<VelocityLimitOutcome> {
        if !self.on {
            return None;
        }
        let terms = controller.model_terms();
        gemv_slices(self.h.as_mut_slice(), 1.0, &terms.c, qd, 0.0);
        if gravity_in_tau {
            self.h += &terms.g;
        }
        let model = PeriodModel {
            m: &terms.m,
            chol: controller.mass_factor(),
            h: &self.h,
            qd,
            v_max: &self.v_max,
            period_s,
        };
        let out = limit_velocity(&model, tau, &mut self.work);
        if out.acted {
            for (t, l) in tau.iter_mut().zip(limits) {
                *t = t.clamp(-l, *l);
            }
        }
        Some(out)
    }
}
