//! `[output]`: the controller's torque output pipeline after the law.
//!
//! ```toml
//! [output]
//! torque_rate_limit = 1000.0     # N·m/s per joint (off when absent)
//! rate_limit_mode = "whole"      # "whole": scale Δτ as a whole; "per_joint": clip each joint
//! low_pass_hz = 100.0            # first-order low-pass cut-off (off when absent)
//! ```
//!
//! Both stages are off by default, so every scenario without `[output]`
//! runs exactly as before.

use std::path::Path;

use serde::Deserialize;

use crate::error::{ConfigError, invalid};

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

/// `[output]` as written.
#[derive(Clone, Debug, Default, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct OutputSection {
    pub torque_rate_limit: Option<f64>,
    #[serde(default)]
    pub rate_limit_mode: RateLimitMode,
    pub low_pass_hz: Option<f64>,
}

/// Resolved `[output]`.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Output {
    /// Largest |dτ/dt| per joint, N·m/s (`None`: off).
    pub torque_rate_limit: Option<f64>,
    /// How the limit acts.
    pub rate_limit_mode: RateLimitMode,
    /// Cut-off of the first-order low-pass, Hz (`None`: off).
    pub low_pass_hz: Option<f64>,
}

/// Checks `[output]`: both values positive and finite when given.
pub(crate) fn resolve(file: &Path, text: &str, s: &OutputSection) -> Result<Output, ConfigError> {
    for (name, v) in [
        ("output.torque_rate_limit", s.torque_rate_limit),
        ("output.low_pass_hz", s.low_pass_hz),
    ] {
        if let Some(v) = v.filter(|v| !(v.is_finite() && *v > 0.0)) {
            return Err(invalid(
                file,
                text,
                name,
                format!("{v} must be positive and finite"),
            ));
        }
    }
    Ok(Output {
        torque_rate_limit: s.torque_rate_limit,
        rate_limit_mode: s.rate_limit_mode,
        low_pass_hz: s.low_pass_hz,
    })
}
