//! `[setpoint_limits]`: limits on the setpoints a client may send to a
//! running controller, and how a moving goal is damped.
//!
//! ```toml
//! [setpoint_limits]
//! relative_damping = true        # damp ẋ_i − ẋ_{i,d} while a goal moves (default true)
//! path_knots = 256               # knots a level's run-time path holds ahead (docs/tracking.md)
//! path_check_timeout_ms = 100.0  # a path message waits this long for its feasibility check at most
//!
//! [[setpoint_limits.level]]          # one per [[level]], in order; all optional
//! max_stiffness = 3000.0         # largest eigenvalue of K_i a setpoint may ask for
//! max_speed = 0.25               # peak speed of the equilibrium (m/s or rad/s)
//! workspace_min = [0.1, -0.6, 0.0]   # position tasks: a box on the selected axes (m)
//! workspace_max = [0.8, 0.6, 1.0]
//! ```
//!
//! Defaults: `max_stiffness` 4 × the largest eigenvalue of the level's K in
//! the file, `max_speed` 0.25 m/s for position tasks and 1 rad/s otherwise,
//! no box (the controller then uses the ball the chain reaches from its
//! root). None of this changes a run that receives no setpoint.

use std::path::Path;

use hcc_spec::{LevelSpec, TaskUnit};
use serde::Deserialize;

use crate::error::{ConfigError, invalid};
use hcc_spec::setpoint_limits::{
    DEFAULT_MAX_ANGULAR_SPEED, DEFAULT_MAX_LINEAR_SPEED, DEFAULT_PATH_CHECK_TIMEOUT_MS,
    DEFAULT_PATH_KNOTS, DEFAULT_STIFFNESS_FACTOR, LevelSetpointLimits, MAX_PATH_KNOTS,
    SetpointLimits,
};

/// `[setpoint_limits]` as written.
#[derive(Clone, Debug, Default, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SetpointLimitsSection {
    /// Damp the velocity relative to a moving equilibrium (default true).
    pub relative_damping: Option<bool>,
    /// Knots a level's run-time path holds ahead at most (default 256).
    pub path_knots: Option<usize>,
    /// How long a path message waits for its feasibility check (default 100 ms).
    pub path_check_timeout_ms: Option<f64>,
    /// Per-level limits, in level order.
    #[serde(default, rename = "level")]
    pub levels: Vec<LevelSetpointLimitsSection>,
}

/// `[[setpoint_limits.level]]` as written.
#[derive(Clone, Debug, Default, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct LevelSetpointLimitsSection {
    pub max_stiffness: Option<f64>,
    pub max_speed: Option<f64>,
    pub workspace_min: Option<Vec<f64>>,
    pub workspace_max: Option<Vec<f64>>,
}

fn positive(file: &Path, text: &str, path: &str, v: f64) -> Result<f64, ConfigError> {
    if v.is_finite() && v > 0.0 {
        Ok(v)
    } else {
        Err(invalid(
            file,
            text,
            path,
            format!("{v} must be positive and finite"),
        ))
    }
}

/// Checks `[setpoint_limits]` against the resolved levels.
pub(crate) fn resolve(
    file: &Path,
    text: &str,
    section: &SetpointLimitsSection,
    levels: &[LevelSpec],
    n: usize,
) -> Result<SetpointLimits, ConfigError> {
    if section.levels.len() > levels.len() {
        return Err(invalid(
            file,
            text,
            "setpoint_limits.level",
            format!(
                "{} entries, but the scenario has {} levels",
                section.levels.len(),
                levels.len()
            ),
        ));
    }
    let mut out = Vec::with_capacity(levels.len());
    for (i, level) in levels.iter().enumerate() {
        let s = section.levels.get(i).cloned().unwrap_or_default();
        let path = |f: &str| format!("setpoint_limits.level[{i}].{f}");
        let k_max = level
            .stiffness
            .clone()
            .symmetric_eigenvalues()
            .iter()
            .fold(0.0_f64, |a, &b| a.max(b));
        let max_stiffness = match s.max_stiffness {
            Some(v) => positive(file, text, &path("max_stiffness"), v)?,
            None => DEFAULT_STIFFNESS_FACTOR * k_max,
        };
        // A level that mixes units (a pose) limits the norm of its stacked
        // step with the linear default unless the scenario says otherwise.
        let max_speed = match (s.max_speed, level.unit(n)) {
            (Some(v), _) => positive(file, text, &path("max_speed"), v)?,
            (None, Some(TaskUnit::Length) | None) => DEFAULT_MAX_LINEAR_SPEED,
            (None, Some(TaskUnit::Angle)) => DEFAULT_MAX_ANGULAR_SPEED,
        };
        let workspace = match (s.workspace_min, s.workspace_max) {
            (None, None) => None,
            (Some(lo), Some(hi)) => {
                let m = level.dim(n);
                let bad = lo.len() != m
                    || hi.len() != m
                    || lo
                        .iter()
                        .zip(&hi)
                        .any(|(a, b)| !(a.is_finite() && b.is_finite() && a < b));
                if bad || level.unit(n) != Some(TaskUnit::Length) {
                    return Err(invalid(
                        file,
                        text,
                        &path("workspace_min"),
                        format!(
                            "a workspace box is for position tasks: {m} finite values each, min < max"
                        ),
                    ));
                }
                Some((lo, hi))
            }
            _ => {
                return Err(invalid(
                    file,
                    text,
                    &path("workspace_min"),
                    "give both workspace_min and workspace_max",
                ));
            }
        };
        out.push(LevelSetpointLimits {
            max_stiffness,
            max_speed,
            workspace,
        });
    }
    let path_knots = section.path_knots.unwrap_or(DEFAULT_PATH_KNOTS);
    if !(3..=MAX_PATH_KNOTS).contains(&path_knots) {
        return Err(invalid(
            file,
            text,
            "setpoint_limits.path_knots",
            format!("{path_knots} must be from 3 to {MAX_PATH_KNOTS}"),
        ));
    }
    let path_check_timeout_ms = match section.path_check_timeout_ms {
        Some(ms) => positive(file, text, "setpoint_limits.path_check_timeout_ms", ms)?,
        None => DEFAULT_PATH_CHECK_TIMEOUT_MS,
    };
    Ok(SetpointLimits {
        relative_damping: section.relative_damping.unwrap_or(true),
        path_knots,
        path_check_timeout_ms,
        levels: out,
    })
}
