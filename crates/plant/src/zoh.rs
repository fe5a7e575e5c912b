//! Sampled-data loop with a zero-order hold: the control law reads the plant
//! state at t_k = k T, its torque is held constant over [t_k, t_{k+1}) while the
//! plant (the robot dynamics of paper Eq. (1)) is integrated with `substeps`
//! RK4 steps of T / substeps.
//!
//! [`PeriodStep`] is that one period; both zero-order-hold paths use it — the
//! in-process loop [`run_zoh`] (`hcc simulate`) and the simulated robot driver
//! of the `hcc-sim` daemon — so that a lockstep run over IPC reproduces the
//! in-process closed loop bit for bit.

use crate::{Plant, SimError};
use nalgebra::DVector;

/// Timing of a sampled-data loop.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct LoopTiming {
    /// Control period T in s.
    pub control_period_s: f64,
    /// Plant steps per control period.
    pub substeps: usize,
    /// Number of control cycles to integrate over (the loop visits cycles 0..=cycles,
    /// i.e. it also samples the final state at t = cycles·T without integrating further).
    pub cycles: usize,
}

/// One control period of the zero-order hold: `substeps` RK4 steps of
/// h = T / substeps with the torque held, then the plant clock re-anchored to
/// the exact next sample time (no drift from summing the sub-steps).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PeriodStep {
    substeps: usize,
    h: f64,
}

impl PeriodStep {
    /// The step of a loop with control period `control_period_s` (T > 0,
    /// finite) and `substeps` (≥ 1) RK4 steps per period.
    pub fn new(control_period_s: f64, substeps: usize) -> Result<PeriodStep, SimError> {
        if substeps == 0 || !(control_period_s > 0.0 && control_period_s.is_finite()) {
            return Err(SimError::Invalid(format!(
                "invalid loop timing: period {control_period_s} s, {substeps} substeps"
            )));
        }
        Ok(PeriodStep {
            substeps,
            h: control_period_s / substeps as f64,
        })
    }

    /// The RK4 step size h = T / substeps, s.
    pub fn h(&self) -> f64 {
        self.h
    }

    /// Integrates `plant` over one period with `tau` held, then sets its clock
    /// to `t_next` (the next sample time, computed by the caller from the
    /// cycle index). Allocation-free.
    pub fn advance(
        &self,
        plant: &mut Plant,
        tau: &DVector<f64>,
        t_next: f64,
    ) -> Result<(), SimError> {
        for _ in 0..self.substeps {
            plant.step(tau, self.h)?;
        }
        plant.set_time(t_next);
        Ok(())
    }
}

/// Runs the loop. For each cycle k = 0..=cycles, `control(k, t_k, q(t_k), q̇(t_k), τ)`
/// writes the torque τ_k, which is then held over the next control period
/// ([`PeriodStep`]; not applied after the last sample). The control law only
/// ever sees sampled states; wrenches configured in the plant act on it but
/// are not visible here.
pub fn run_zoh<F>(plant: &mut Plant, timing: LoopTiming, mut control: F) -> Result<(), SimError>
where
    F: FnMut(usize, f64, &DVector<f64>, &DVector<f64>, &mut DVector<f64>) -> Result<(), SimError>,
{
    let step = PeriodStep::new(timing.control_period_s, timing.substeps)?;
    let n = plant.model().nq();
    let mut tau = DVector::zeros(n);
    let t_start = plant.t();
    for k in 0..=timing.cycles {
        // Sample time from the cycle index (no accumulated rounding).
        let t = t_start + k as f64 * timing.control_period_s;
        control(k, t, plant.q(), plant.qd(), &mut tau)?;
        if k == timing.cycles {
            break;
        }
        step.advance(
            plant,
            &tau,
            t_start + (k + 1) as f64 * timing.control_period_s,
        )?;
    }
    Ok(())
}
