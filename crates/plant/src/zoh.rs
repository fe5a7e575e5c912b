//! Sampled-data loop with a zero-order hold: the control law reads the plant
//! state at t_k = k T, its torque is held constant over [t_k, t_{k+1}) while the
//! plant is integrated with `substeps` RK4 steps of T / substeps.

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

/// Runs the loop. For each cycle k = 0..=cycles, `control(k, t_k, q(t_k), q̇(t_k), τ)`
/// writes the torque τ_k, which is then held over the next control period
/// (not applied after the last sample). The control law only ever sees sampled
/// states; wrenches configured in the plant act on it but are not visible here.
pub fn run_zoh<F>(plant: &mut Plant, timing: LoopTiming, mut control: F) -> Result<(), SimError>
where
    F: FnMut(usize, f64, &DVector<f64>, &DVector<f64>, &mut DVector<f64>) -> Result<(), SimError>,
{
    if timing.substeps == 0
        || !(timing.control_period_s > 0.0 && timing.control_period_s.is_finite())
    {
        return Err(SimError::Invalid(format!(
            "invalid loop timing: period {} s, {} substeps",
            timing.control_period_s, timing.substeps
        )));
    }
    let n = plant.model().nq();
    let mut tau = DVector::zeros(n);
    let h = timing.control_period_s / timing.substeps as f64;
    let t_start = plant.t();
    for k in 0..=timing.cycles {
        // Sample time from the cycle index (no accumulated rounding).
        let t = t_start + k as f64 * timing.control_period_s;
        control(k, t, plant.q(), plant.qd(), &mut tau)?;
        if k == timing.cycles {
            break;
        }
        for _ in 0..timing.substeps {
            plant.step(&tau, h)?;
        }
        // Re-anchor the plant clock to the exact sample time (no drift from
        // summing substeps).
        plant.set_time(t_start + (k + 1) as f64 * timing.control_period_s);
    }
    Ok(())
}
