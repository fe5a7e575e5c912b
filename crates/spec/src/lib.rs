//! The specification of a compliance hierarchy (Dietrich, Ott &
//! Albu-Schäffer, IROS 2013): what a scenario file describes and the law
//! (`hcc_control::Controller::new`) runs — the levels in priority order, each
//! stacking its tasks with stiffness K_i, damping D_i and equilibrium x_{i,d}
//! (eqs. 20–21) ([`ControllerSpec`], [`LevelSpec`], [`TaskSpec`]), the law's
//! options ([`Form`], the Coriolis cancellation τ_μ of eq. 22, the singular
//! ratio) and the safety layer's settings ([`SafetySpec`]); and the control
//! cycle's settings around the law ([`contact`], [`setpoint_limits`],
//! [`torque_filter`], the levels' desired paths [`tracking`]).
//!
//! Plain data with the checks that need no configuration
//! ([`ControllerSpec::validate`], [`SafetySpec::validate`]); the checks at a
//! configuration (ranks, algorithmic singularities, gains the control rate
//! carries) are the law's. This crate sits beside the robot model so that
//! the scenario reader (`hcc-config`) fills it without depending on the law.

pub mod contact;
mod hierarchy;
mod safety;
pub mod setpoint_limits;
pub mod torque_filter;
pub mod tracking;

pub use hierarchy::{ControllerSpec, Form, LevelSpec, TaskSpec, TaskUnit};
pub use safety::SafetySpec;

/// The scenario file's field of the level an error names (`level` as
/// [`SpecError::Level`] and the law's level errors give it: "k (name)",
/// 1-based): `level[k−1]`, or `level` when it names none.
pub fn level_field(level: &str) -> String {
    level
        .split_whitespace()
        .next()
        .and_then(|k| k.parse::<usize>().ok())
        .map(|k| format!("level[{}]", k.saturating_sub(1)))
        .unwrap_or_else(|| "level".to_string())
}

/// A specification the checks refuse.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum SpecError {
    /// A level of the hierarchy is invalid (which level and why).
    #[error("level {level}: {why}")]
    Level { level: String, why: String },
    /// The hierarchy as a whole, or a setting, is invalid.
    #[error("{0}")]
    Spec(String),
}
