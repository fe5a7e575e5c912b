//! Plant simulator for the hierarchical compliance controller of Dietrich, Ott
//! & Albu-Schäffer (IROS 2013): the robot dynamics of the paper's eq. (1)
//! integrated with RK4 ([`Plant`]), and the in-process closed loop with the
//! controller sampled at the control rate and its torque held between samples
//! ([`closed_loop`]).

pub mod closed_loop;
pub mod end_stops;
pub mod plant;
pub mod zoh;

pub use end_stops::EndStops;
pub use plant::{ExternalWrench, Plant, PlantEnergy};
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
