//! `[torque_filter]`: the filter between the law and the saturation — a
//! torque-rate limit and a first-order low-pass.
//!
//! ```toml
//! [torque_filter]
//! torque_rate_limit = 1000.0     # N·m/s per joint (off when absent)
//! rate_limit_mode = "whole"      # "whole": scale Δτ as a whole; "per_joint": clip each joint
//! low_pass_hz = 100.0            # first-order low-pass cut-off (off when absent)
//! ```
//!
//! Both stages are off by default: a scenario without `[torque_filter]`
//! commands the law's torque (saturated) as it is.

use std::path::Path;

use serde::Deserialize;

use crate::error::{ConfigError, invalid};
use hcc_spec::torque_filter::{RateLimitMode, TorqueFilterSpec};

/// `[torque_filter]` as written.
#[derive(Clone, Debug, Default, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct TorqueFilterSection {
    pub torque_rate_limit: Option<f64>,
    #[serde(default)]
    pub rate_limit_mode: RateLimitMode,
    pub low_pass_hz: Option<f64>,
}

/// Checks `[torque_filter]`: both values positive and finite when given.
pub(crate) fn resolve(
    file: &Path,
    text: &str,
    s: &TorqueFilterSection,
) -> Result<TorqueFilterSpec, ConfigError> {
    for (name, v) in [
        ("torque_filter.torque_rate_limit", s.torque_rate_limit),
        ("torque_filter.low_pass_hz", s.low_pass_hz),
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
    Ok(TorqueFilterSpec {
        torque_rate_limit: s.torque_rate_limit,
        rate_limit_mode: s.rate_limit_mode,
        low_pass_hz: s.low_pass_hz,
    })
}
