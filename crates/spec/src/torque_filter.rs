//! The torque filter's settings (`[torque_filter]`, read by `hcc-config`,
//! used by the control cycle): a torque-rate limit and a first-order
//! low-pass between the law and the saturation.

use serde::Deserialize;

/// How the torque-rate limit acts.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum RateLimitMode {
    /// Δτ scaled as a whole so that no joint exceeds the limit (keeps the
    /// direction of the change, like the saturation).
    #[default]
    Whole,
    /// Each joint's Δτ clipped on its own.
    PerJoint,
}

/// Resolved `[torque_filter]`.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct TorqueFilterSpec {
    /// Largest |dτ/dt| per joint, N·m/s (`None`: off).
    pub torque_rate_limit: Option<f64>,
    /// How the limit acts.
    pub rate_limit_mode: RateLimitMode,
    /// Cut-off of the first-order low-pass, Hz (`None`: off).
    pub low_pass_hz: Option<f64>,
}
