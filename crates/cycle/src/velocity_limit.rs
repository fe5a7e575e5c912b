//! The discrete-time velocity limit on the torque that is sent, after the
//! saturation and the torque filter, with the safety layer on (off, the
//! torque is the law's bit for bit):
//!
//! * no torque-rate limit: [`hcc_control::velocity_limit`] holds each joint's
//!   speed one period ahead to 0.94 of its URDF limit by the smallest
//!   correction in the kinetic-energy metric; the torque is then clipped to
//!   the effort limits again;
//! * a torque-rate limit: a correction cannot arrive within the period, so
//!   [`hcc_control::brake_certificate`] sends the law's torque only when a
//!   brake the rate limit allows still holds every joint below 0.92 of its
//!   limit, else the law's torque blended towards that brake — within one
//!   rate step of the previous command and within the effort limits, so the
//!   filter's promise (no step larger than r·Δt) holds for what is sent.
//!
//! Where it acted, the filter is told what was sent (its next step starts
//! from it).

use hcc_control::velocity_limit::PeriodModel;
use hcc_control::{
    BrakeModel, BrakeWork, Controller, VelocityLimitOutcome, VelocityLimitWork, limit_velocity,
    limit_velocity_rate_limited,
};
use hcc_model::linalg::products::gemv_slices;
use nalgebra::DVector;

use crate::torque_filter::RateLimit;

/// The limit's state: on or off, the URDF velocity and effort limits, the
/// nominal period, the workspaces.
pub(crate) struct VelocityLimit {
    on: bool,
    v_max: Vec<f64>,
    effort: Vec<f64>,
    period_s: f64,
    /// h = C q̇ (+ g where τ contains it).
    h: DVector<f64>,
    /// g where τ contains it, else 0.
    g: DVector<f64>,
    work: VelocityLimitWork,
    brake: BrakeWork,
}

impl VelocityLimit {
    /// For `controller`'s robot with the effort limits `effort` (those the
    /// cycle saturates to) at the nominal period `period_s`. Allocates.
    pub(crate) fn new(controller: &Controller, effort: &[f64], period_s: f64) -> VelocityLimit {
        let n = controller.nq();
        VelocityLimit {
            on: controller.spec().safety.enabled,
            v_max: controller
                .model()
                .joints
                .iter()
                .map(|j| j.velocity_limit)
                .collect(),
            effort: effort[..n].to_vec(),
            period_s,
            h: DVector::zeros(n),
            g: DVector::zeros(n),
            work: VelocityLimitWork::new(n),
            brake: BrakeWork::new(n),
        }
    }

    /// Corrects `tau` (length n, saturated and filtered, to be sent) at the
    /// state with velocity `qd` the law just ran on; `gravity_in_tau`: the
    /// gravity torque τ contains (g(q), or the load's alone); `rate`: the rate limit in force, if any. `None` where
    /// the limit is off. Allocation-free.
    pub(crate) fn apply(
        &mut self,
        controller: &Controller,
        qd: &[f64],
        gravity_in_tau: Option<&[f64]>,
        rate: Option<RateLimit<'_>>,
        tau: &mut [f64],
    ) -> Option<VelocityLimitOutcome> {
        if !self.on {
            return None;
        }
        let terms = controller.model_terms();
        match gravity_in_tau {
            Some(g) => self.g.as_mut_slice().copy_from_slice(g),
            None => self.g.fill(0.0),
        }
        if let Some(rate) = rate {
            let model = BrakeModel {
                m: &terms.m,
                chol: controller.mass_factor(),
                c: &terms.c,
                g: &self.g,
                qd,
                v_max: &self.v_max,
                period_s: self.period_s,
                previous: rate.previous,
                max_step: rate.max_step,
                effort: &self.effort,
            };
            return Some(limit_velocity_rate_limited(&model, tau, &mut self.brake));
        }
        gemv_slices(self.h.as_mut_slice(), 1.0, &terms.c, qd, 0.0);
        self.h += &self.g;
        let model = PeriodModel {
            m: &terms.m,
            chol: controller.mass_factor(),
            h: &self.h,
            qd,
            v_max: &self.v_max,
            period_s: self.period_s,
        };
        let out = limit_velocity(&model, tau, &mut self.work);
        if out.acted {
            for (t, l) in tau.iter_mut().zip(&self.effort) {
                *t = t.clamp(-l, *l);
            }
        }
        Some(out)
    }
}
