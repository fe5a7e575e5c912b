//! What a [`crate::ControlCycle`] is built with, and what can refuse it.

use hcc_config::Scenario;
use hcc_msgs::{MAX_JOINTS, MAX_LEVELS};
use hcc_spec::contact::Contact;
use hcc_spec::setpoint_limits::SetpointLimits;
use hcc_spec::torque_filter::TorqueFilterSpec;
use hcc_spec::tracking::Tracking;

/// Settings of the control cycle (everything but the law itself, which is
/// the `hcc_control::Controller` it is built around).
#[derive(Debug, Clone, PartialEq)]
pub struct CycleSettings {
    /// Nominal period of the driver's states, ns (transitions advance by it;
    /// the sequence plausibility judges gaps by it).
    pub period_ns: u64,
    /// |τ_k| ≤ limit_k, one per joint (may be +inf).
    pub torque_limits: Vec<f64>,
    /// Whether τ includes g(q) (the command's gravity flag; the driver adds
    /// it otherwise).
    pub gravity_compensation: bool,
    /// Limits of setpoints (`[setpoint_limits]`).
    pub setpoint_limits: SetpointLimits,
    /// The rate limit and low-pass after the law (`[torque_filter]`).
    pub torque_filter: TorqueFilterSpec,
    /// The external-torque observer and contact detection (`[contact]`).
    pub contact: Contact,
    /// The levels' desired paths and feed-forward flags (docs/tracking.md).
    pub tracking: Tracking,
}

impl CycleSettings {
    /// The settings of `scenario`: its control rate, `[controller_daemon]
    /// torque_limits`, `[robot] gravity_compensation`, `[setpoint_limits]`,
    /// `[torque_filter]`, `[contact]` and the levels' paths.
    pub fn from_scenario(scenario: &Scenario) -> CycleSettings {
        CycleSettings {
            period_ns: scenario.period_ns(),
            torque_limits: scenario
                .controller_daemon
                .torque_limits
                .iter()
                .copied()
                .collect(),
            gravity_compensation: scenario.spec.gravity_compensation,
            setpoint_limits: scenario.setpoint_limits.clone(),
            torque_filter: scenario.torque_filter.clone(),
            contact: scenario.contact.clone(),
            tracking: scenario.tracking.clone(),
        }
    }

    /// The nominal period, s.
    pub fn period_s(&self) -> f64 {
        self.period_ns as f64 * 1e-9
    }

    /// Checks the sizes of a law of `n` joints and `r` levels against the
    /// message capacities and the torque limits.
    pub fn check(&self, n: usize, r: usize) -> Result<(), CycleError> {
        if n > MAX_JOINTS {
            return Err(CycleError::Shape(format!(
                "the robot has {n} joints; the messages hold at most {MAX_JOINTS}"
            )));
        }
        if r > MAX_LEVELS {
            return Err(CycleError::Shape(format!(
                "the hierarchy has {r} levels; telemetry holds at most {MAX_LEVELS}"
            )));
        }
        let limits = &self.torque_limits;
        if limits.len() != n {
            return Err(CycleError::Shape(format!(
                "controller_daemon.torque_limits has {} entries, the robot {n} joints",
                limits.len()
            )));
        }
        if let Some(k) = limits.iter().position(|l| l.is_nan() || *l <= 0.0) {
            return Err(CycleError::Shape(format!(
                "controller_daemon.torque_limits[{k}] = {} must be positive",
                limits[k]
            )));
        }
        let c = &self.contact;
        if c.observer_gain.len() != n || c.threshold.len() != n {
            return Err(CycleError::Shape(format!(
                "contact: {} observer gains and {} thresholds for {n} joints",
                c.observer_gain.len(),
                c.threshold.len()
            )));
        }
        if self.period_ns == 0 {
            return Err(CycleError::Shape("the control period is 0 ns".into()));
        }
        Ok(())
    }
}

/// Why a [`crate::ControlCycle`] (or a part of it) cannot be built.
#[derive(Debug, thiserror::Error)]
pub enum CycleError {
    /// A size does not fit the message capacities or the law.
    #[error("{0}")]
    Shape(String),
}
