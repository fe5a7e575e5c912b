//! The simulated robot of hcc: the robot dynamics of the paper's eq. (1)
//! integrated with RK4 ([`Plant`], with end stops and external wrenches), the
//! zero-order-hold period step ([`PeriodStep`], [`run_zoh`]) and the
//! simulated driver ([`SimDriver`]: the plant behind the driver side of the
//! message contract). The `hcc-sim` daemon runs the driver over iceoryx2;
//! `hcc simulate` (crate `hcc-in-process`) runs it in process against the
//! control cycle.

pub mod driver;
pub mod end_stops;
pub mod plant;
pub mod zoh;

use hcc_config::Scenario;

pub use driver::{Applied, DriverCounters, SimDriver};
pub use end_stops::EndStops;
pub use plant::{ExternalWrench, Plant, PlantEnergy, TimedLoad};
pub use zoh::{LoopTiming, PeriodStep, run_zoh};

/// Errors of the simulator, naming the offending quantity.
#[derive(Debug, thiserror::Error)]
pub enum SimError {
    #[error("{what} has length {got}, expected {expected}")]
    Dimension {
        what: &'static str,
        expected: usize,
        got: usize,
    },
    #[error("{what}[{index}] is not finite")]
    NonFinite { what: &'static str, index: usize },
    #[error("{0}")]
    Invalid(String),
    #[error("the simulation diverged at t = {t} s (non-finite acceleration)")]
    Diverged { t: f64 },
    #[error("model: {0}")]
    Model(#[from] hcc_model::ModelError),
}

/// Builds the plant of a scenario (model, initial state, friction, wrenches,
/// the loads its tip takes at a time).
pub fn plant_for(scenario: &Scenario) -> Result<Plant, SimError> {
    let s = &scenario.simulation;
    let mut plant = Plant::new(
        scenario.model.clone(),
        &scenario.q0,
        &scenario.qd0,
        &s.joint_friction,
    )?;
    plant.set_wrenches(
        s.wrenches
            .iter()
            .map(|w| ExternalWrench {
                start_s: w.start_s,
                duration_s: w.duration_s,
                frame: w.frame_id,
                force: w.force,
                torque: w.torque,
            })
            .collect(),
    )?;
    plant.set_loads(
        s.loads
            .iter()
            .map(|l| TimedLoad {
                start_s: l.start_s,
                load: l.load,
            })
            .collect(),
    )?;
    Ok(plant)
}
