//! `[[setpoint]]`: setpoints scheduled in the scenario, applied by `hcc
//! simulate` in-process and by `hcc run` through the setpoint service.
//!
//! ```toml
//! [[setpoint]]
//! t = 2.0                    # s from the start; the first cycle with t_k ≥ t takes it
//! level = 1                  # 1-based, in the order of the [[level]] tables
//! goal = [0.4, 0.1, 0.5]     # optional: x_{i,d} in the task's coordinates
//! velocity = [0.0, 0.0, 0.0] # optional (with goal): feed-forward ẋ_{i,d}
//! stiffness = [800, 800, 800]  # optional: K_i, m diagonal or m×m row-major values
//! damping = [60, 60, 60]     # optional: D_i, the same layouts
//! duration = 1.5             # optional transition time, s (default 0: the speed limit)
//! ```
//!
//! Each entry is checked at load with the model-free checks of a setpoint
//! message ([`hcc_msgs::Setpoint::validate`], on the message built from it)
//! and against the hierarchy (the level exists, the values have its m_i).
//! The controller's own checks (stiffness limit, workspace, joint limits)
//! apply when it takes the setpoint. Entries are sorted by time (stable).

use std::path::Path;

use hcc_msgs::{Setpoint, SetpointRejection};
use hcc_spec::LevelSpec;
use serde::Deserialize;

use crate::error::{ConfigError, invalid};

/// The client id scheduled setpoints carry (in-process and over IPC alike).
pub const SCHEDULE_CLIENT_ID: u64 = 0x5343_4845_4455_4c45;

/// `[[setpoint]]` as written.
#[derive(Clone, Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SetpointSection {
    pub t: f64,
    pub level: usize,
    pub goal: Option<Vec<f64>>,
    pub velocity: Option<Vec<f64>>,
    pub stiffness: Option<Vec<f64>>,
    pub damping: Option<Vec<f64>>,
    pub duration: Option<f64>,
}

/// A checked scheduled setpoint.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ScheduledSetpoint {
    /// Time in s from the start of the run.
    pub t_s: f64,
    /// The message (level 0-based, client [`SCHEDULE_CLIENT_ID`], sequence
    /// number = 1 + the entry's index after sorting).
    pub setpoint: Setpoint,
}

/// A `Setpoint::with_*` builder.
type Builder = fn(Setpoint, &[f64]) -> Result<Setpoint, SetpointRejection>;

/// One field into the message, its model-free checks naming the field.
fn with_field(
    base: Setpoint,
    name: &str,
    values: &[f64],
    build: Builder,
) -> Result<Setpoint, (String, SetpointRejection)> {
    let fail = |r: SetpointRejection| (name.to_string(), r);
    let sp = build(base, values).map_err(fail)?;
    // Alone (a velocity with a zero goal), so a failure is this field's.
    let mut alone = build(
        Setpoint::for_level(0, 0, base.level as usize, base.dim()),
        values,
    )
    .map_err(fail)?;
    if name == "velocity" {
        alone = alone.with_goal(&vec![0.0; base.dim()]).map_err(fail)?;
    }
    alone.validate().map_err(fail)?;
    // A full K or D: positive definite (Setpoint::validate checks the shape
    // only; the controller factorises it when it takes the setpoint).
    let full = match name {
        "stiffness" => alone.stiffness_full().then(|| alone.stiffness()),
        "damping" => alone.damping_full().then(|| alone.damping()),
        _ => None,
    };
    if let Some(values) = full {
        let m = alone.dim();
        let mut l = nalgebra::DMatrix::from_row_slice(m, m, values);
        if hcc_model::linalg::cholesky_in_place(&mut l).is_err() {
            return Err(fail(SetpointRejection::NotPositiveDefinite));
        }
    }
    Ok(sp)
}

/// The message of `entry` (level already checked), or the failing field and why.
fn build(entry: &SetpointSection, dim: usize) -> Result<Setpoint, (String, SetpointRejection)> {
    let mut sp = Setpoint::for_level(SCHEDULE_CLIENT_ID, 0, entry.level - 1, dim);
    let fields: [(&str, &Option<Vec<f64>>, Builder); 4] = [
        ("goal", &entry.goal, Setpoint::with_goal),
        ("velocity", &entry.velocity, Setpoint::with_velocity),
        ("stiffness", &entry.stiffness, Setpoint::with_stiffness),
        ("damping", &entry.damping, Setpoint::with_damping),
    ];
    for (name, values, f) in fields {
        if let Some(v) = values {
            sp = with_field(sp, name, v, f)?;
        }
    }
    sp = sp.with_duration(entry.duration.unwrap_or(0.0));
    sp.validate().map_err(|r| {
        let field = match r {
            SetpointRejection::NonFinite | SetpointRejection::BadDuration => "duration",
            SetpointRejection::VelocityWithoutGoal => "velocity",
            SetpointRejection::LevelCapacity => "level",
            _ => "",
        };
        (field.to_string(), r)
    })?;
    Ok(sp)
}

/// Checks the `[[setpoint]]` entries against the levels; sorted by time.
pub(crate) fn resolve(
    file: &Path,
    text: &str,
    entries: &[SetpointSection],
    levels: &[LevelSpec],
    n: usize,
) -> Result<Vec<ScheduledSetpoint>, ConfigError> {
    let mut out = Vec::with_capacity(entries.len());
    for (k, entry) in entries.iter().enumerate() {
        let path = |f: &str| format!("setpoint[{k}].{f}");
        if !(entry.t.is_finite() && entry.t >= 0.0) {
            return Err(invalid(
                file,
                text,
                &path("t"),
                format!("{} must be finite and ≥ 0 (s)", entry.t),
            ));
        }
        if entry.level == 0 || entry.level > levels.len() {
            return Err(invalid(
                file,
                text,
                &path("level"),
                format!(
                    "{} is not a level: 1 … {} (1-based, in the order of [[level]])",
                    entry.level,
                    levels.len()
                ),
            ));
        }
        let dim = levels[entry.level - 1].dim(n);
        let setpoint = build(entry, dim).map_err(|(field, r)| {
            let detail = match r {
                SetpointRejection::DimensionMismatch | SetpointRejection::DimensionCapacity => {
                    format!(
                        "level {} has m = {dim}: give {dim} values ({} for a full gain matrix)",
                        entry.level,
                        dim * dim
                    )
                }
                _ => r.reason().to_string(),
            };
            let at = if field.is_empty() {
                format!("setpoint[{k}]")
            } else {
                path(&field)
            };
            invalid(file, text, &at, detail)
        })?;
        out.push(ScheduledSetpoint {
            t_s: entry.t,
            setpoint,
        });
    }
    out.sort_by(|a, b| a.t_s.total_cmp(&b.t_s));
    for (k, s) in out.iter_mut().enumerate() {
        s.setpoint.header.seq = k as u64 + 1;
    }
    Ok(out)
}

impl ScheduledSetpoint {
    /// The cycle that takes it: the first k with t_k = k · T ≥ t (T the
    /// control period in whole ns, as the controller daemon counts it).
    pub fn cycle(&self, control_rate_hz: f64) -> u64 {
        let period_ns = ((1e9 / control_rate_hz).round() as u64).max(1);
        let t_ns = (self.t_s * 1e9).round() as u64;
        t_ns.div_ceil(period_ns)
    }

    /// The message as a client sends it: applied at the state of its cycle
    /// ([`hcc_msgs::Setpoint::apply_at_state_seq`] = [`ScheduledSetpoint::cycle`];
    /// the drivers number their states k = 0, 1, … per period).
    pub fn message(&self, control_rate_hz: f64) -> Setpoint {
        self.setpoint.with_apply_at(self.cycle(control_rate_hz))
    }
}
