//! Run metrics (`metrics.json`): per-level convergence figures, torque and
//! power extrema, and the settings of the run.
//!
//! Everything is computed from a [`Trajectory`] and a [`RunDescription`] only,
//! so the same code serves runs from the in-process simulator and from the
//! daemons.

use crate::columns;
use crate::{ReportError, Trajectory};
use serde::{Deserialize, Serialize};
use std::collections::BTreeMap;
use std::path::Path;

/// Physical unit of a level's task error, which decides the absolute
/// convergence threshold (1 mm for lengths, 1 mrad for angles).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub enum ErrorUnit {
    /// Metres (Cartesian position).
    #[serde(rename = "m")]
    Meter,
    /// Radians (orientation, joint angles).
    #[serde(rename = "rad")]
    Radian,
    /// Mixed or other units: no absolute threshold.
    #[serde(rename = "mixed")]
    Mixed,
}

impl ErrorUnit {
    /// Absolute convergence threshold: 1 mm or 1 mrad; `None` for mixed units.
    pub fn abs_threshold(self) -> Option<f64> {
        match self {
            ErrorUnit::Meter | ErrorUnit::Radian => Some(1e-3),
            ErrorUnit::Mixed => None,
        }
    }

    /// Unit label for plots.
    pub fn label(self) -> &'static str {
        match self {
            ErrorUnit::Meter => "m",
            ErrorUnit::Radian => "rad",
            ErrorUnit::Mixed => "",
        }
    }
}

/// One level of the hierarchy as the report sees it.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct LevelDescription {
    /// Human-readable name, e.g. "TCP position".
    pub name: String,
    /// Task dimension m_i (number of `e<level>_<k>` columns).
    pub dim: usize,
    /// Unit of the task error.
    pub unit: ErrorUnit,
    /// Unit of every error row of a level that mixes units (e.g. a 6-D pose: three
    /// metres, three radians; `unit` is then `Mixed`). Empty when all rows share
    /// `unit`. The metrics then also report each group of rows of one unit.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub row_units: Vec<ErrorUnit>,
}

impl LevelDescription {
    /// Unit label for plots: that of `unit`, or the distinct row units of a mixed
    /// level ("m, rad").
    pub fn unit_label(&self) -> String {
        let mut labels: Vec<&str> = Vec::new();
        for u in &self.row_units {
            if !labels.contains(&u.label()) {
                labels.push(u.label());
            }
        }
        if self.unit == ErrorUnit::Mixed && !labels.is_empty() {
            labels.join(", ")
        } else {
            self.unit.label().to_string()
        }
    }
}

/// Convergence figures of the error rows of one unit within a mixed level.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct UnitGroupMetrics {
    pub unit: ErrorUnit,
    /// 0-based error rows of the group.
    pub rows: Vec<usize>,
    /// max over the run of the group's error norm.
    pub max_error_norm: f64,
    /// The group's error norm at the last sample.
    pub final_error_norm: f64,
    /// First time after which the group's error norm stays below 1 mm or 1 mrad.
    pub time_below_abs_s: Option<f64>,
}

/// What the report needs to know about a run besides its trajectory.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RunDescription {
    /// Scenario name (usually the configuration file name).
    pub scenario: String,
    /// Number of joints n.
    pub n_joints: usize,
    /// Levels in priority order (level 1 first).
    pub levels: Vec<LevelDescription>,
    /// Free-form settings of the run (rates, durations, options), copied to metrics.json.
    #[serde(default)]
    pub settings: BTreeMap<String, serde_json::Value>,
}

/// Convergence figures of one level.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct LevelMetrics {
    /// 1-based level index.
    pub level: usize,
    pub name: String,
    pub unit: ErrorUnit,
    /// ‖e_i(0)‖.
    pub initial_error_norm: f64,
    /// First time after which ‖e_i‖ ≤ 5 % of ‖e_i(0)‖ until the end; null if never.
    pub time_below_5_percent_s: Option<f64>,
    /// Same with 1 %.
    pub time_below_1_percent_s: Option<f64>,
    /// Absolute threshold used below (1 mm or 1 mrad), null for mixed units.
    pub abs_threshold: Option<f64>,
    /// Same with the absolute threshold; null if never or if there is no threshold.
    pub time_below_abs_s: Option<f64>,
    /// ‖e_i‖ at the last sample.
    pub final_error_norm: f64,
    /// e_i at the last sample.
    pub final_error: Vec<f64>,
    /// max ‖e_i‖ over the run.
    pub max_error_norm: f64,
    /// Earliest time from which the level energy S_i never increases again
    /// (up to a relative tolerance of 1e-9 of max S_i); null if S_i is not recorded.
    pub energy_non_increasing_from_s: Option<f64>,
    /// For a level of mixed units: the figures of each group of rows of one unit.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub by_unit: Vec<UnitGroupMetrics>,
}

/// The figures of the rows of each unit of a mixed level (`comps`: the error columns).
fn unit_groups(t: &[f64], level: &LevelDescription, comps: &[Vec<f64>]) -> Vec<UnitGroupMetrics> {
    let mut units: Vec<ErrorUnit> = Vec::new();
    for u in &level.row_units {
        if !units.contains(u) {
            units.push(*u);
        }
    }
    units
        .into_iter()
        .map(|unit| {
            let rows: Vec<usize> = (0..level.row_units.len().min(comps.len()))
                .filter(|&k| level.row_units[k] == unit)
                .collect();
            let norms: Vec<f64> = (0..t.len())
                .map(|r| {
                    rows.iter()
                        .map(|&k| comps[k][r] * comps[k][r])
                        .sum::<f64>()
                        .sqrt()
                })
                .collect();
            UnitGroupMetrics {
                unit,
                max_error_norm: norms.iter().fold(0.0, |a: f64, b| a.max(*b)),
                final_error_norm: norms.last().copied().unwrap_or(0.0),
                time_below_abs_s: unit
                    .abs_threshold()
                    .and_then(|thr| time_to_stay_below(t, &norms, thr)),
                rows,
            }
        })
        .collect()
}

/// Contents of `metrics.json`.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Metrics {
    pub run: RunDescription,
    /// Number of recorded samples (controller cycles).
    pub samples: usize,
    /// Time of the last sample.
    pub duration_s: f64,
    pub levels: Vec<LevelMetrics>,
    /// max_t |τ_k| per joint (applied torque, gravity included).
    pub max_abs_torque: Vec<f64>,
    /// max_t |P_μ| (power of the Coriolis cancellation, ideally 0); null if not recorded.
    pub max_abs_p_mu: Option<f64>,
    /// max_t of every disturbing-acceleration column (`acc<i>_<j>`, `accv<i>_<j>`).
    pub max_disturbing_acceleration: BTreeMap<String, f64>,
    /// ‖q̇‖ at the last sample (rad/s): whether the run came to rest.
    pub final_joint_speed: f64,
}

/// First time from which `values[k] ≤ thr` for every later sample; `None` if the
/// last sample is above.
pub fn time_to_stay_below(t: &[f64], values: &[f64], thr: f64) -> Option<f64> {
    // NaN counts as above the threshold.
    match values.iter().rposition(|v| v.is_nan() || *v > thr) {
        None => t.first().copied(),
        Some(k) if k + 1 < values.len() => Some(t[k + 1]),
        Some(_) => None,
    }
}

/// Earliest time from which `values` is non-increasing (each step may rise by at most `tol`).
pub fn non_increasing_from(t: &[f64], values: &[f64], tol: f64) -> Option<f64> {
    if values.is_empty() {
        return None;
    }
    let mut k = values.len() - 1;
    while k > 0 && values[k] <= values[k - 1] + tol {
        k -= 1;
    }
    Some(t[k])
}

impl Metrics {
    /// Computes the metrics of `traj` (columns per [`crate::columns`]).
    pub fn compute(traj: &Trajectory, run: &RunDescription) -> Result<Metrics, ReportError> {
        let t = traj.require(columns::TIME)?;
        if t.is_empty() {
            return Err(ReportError::Table("the trajectory has no rows".into()));
        }
        let mut levels = Vec::with_capacity(run.levels.len());
        for (i, level) in run.levels.iter().enumerate() {
            let comps: Vec<Vec<f64>> = (0..level.dim)
                .map(|k| traj.require(&columns::error(i + 1, k + 1)))
                .collect::<Result<_, _>>()?;
            let norms: Vec<f64> = (0..t.len())
                .map(|r| comps.iter().map(|c| c[r] * c[r]).sum::<f64>().sqrt())
                .collect();
            let e0 = norms[0];
            let last = t.len() - 1;
            let abs_threshold = level.unit.abs_threshold();
            let energy_non_increasing_from_s = match traj.column(&columns::energy(i + 1)) {
                Some(s) => {
                    let smax = s.iter().fold(0.0_f64, |a, b| a.max(b.abs()));
                    non_increasing_from(&t, &s, 1e-9 * smax)
                }
                None => None,
            };
            levels.push(LevelMetrics {
                level: i + 1,
                name: level.name.clone(),
                unit: level.unit,
                initial_error_norm: e0,
                time_below_5_percent_s: time_to_stay_below(&t, &norms, 0.05 * e0),
                time_below_1_percent_s: time_to_stay_below(&t, &norms, 0.01 * e0),
                abs_threshold,
                time_below_abs_s: abs_threshold.and_then(|thr| time_to_stay_below(&t, &norms, thr)),
                final_error_norm: norms[last],
                final_error: comps.iter().map(|c| c[last]).collect(),
                max_error_norm: norms.iter().fold(0.0, |a: f64, b| a.max(*b)),
                energy_non_increasing_from_s,
                by_unit: unit_groups(&t, level, &comps),
            });
        }
        let max_abs = |v: Vec<f64>| v.iter().fold(0.0_f64, |a, b| a.max(b.abs()));
        let max_abs_torque = (0..run.n_joints)
            .map(|k| traj.require(&columns::torque(k + 1)).map(max_abs))
            .collect::<Result<_, _>>()?;
        let max_abs_p_mu = traj.column(columns::P_MU).map(max_abs);
        let max_disturbing_acceleration = traj
            .columns()
            .iter()
            .filter(|c| columns::is_disturbing_acceleration(c))
            .filter_map(|c| traj.column(c).map(|v| (c.clone(), max_abs(v))))
            .collect();
        let last = t.len() - 1;
        let final_joint_speed = (0..run.n_joints)
            .map(|k| {
                traj.require(&columns::velocity(k + 1))
                    .map(|v| v[last] * v[last])
            })
            .sum::<Result<f64, _>>()?
            .sqrt();
        Ok(Metrics {
            run: run.clone(),
            final_joint_speed,
            samples: t.len(),
            duration_s: t[t.len() - 1],
            levels,
            max_abs_torque,
            max_abs_p_mu,
            max_disturbing_acceleration,
        })
    }

    /// Writes pretty JSON to `path`.
    pub fn write_json(&self, path: &Path) -> Result<(), ReportError> {
        let text = serde_json::to_string_pretty(self).map_err(|e| ReportError::Json {
            path: path.to_path_buf(),
            error: e,
        })?;
        std::fs::write(path, text + "\n").map_err(|e| ReportError::Io {
            path: path.to_path_buf(),
            error: e,
        })
    }

    /// Reads a `metrics.json` written by [`Metrics::write_json`].
    pub fn read_json(path: &Path) -> Result<Metrics, ReportError> {
        let text = std::fs::read_to_string(path).map_err(|e| ReportError::Io {
            path: path.to_path_buf(),
            error: e,
        })?;
        serde_json::from_str(&text).map_err(|e| ReportError::Json {
            path: path.to_path_buf(),
            error: e,
        })
    }

    /// A short human-readable summary (one block per level, torque and P_μ extrema).
    pub fn summary(&self) -> String {
        use std::fmt::Write as _;
        let fmt_t = |x: Option<f64>| match x {
            Some(v) => format!("{v:.3} s"),
            None => "never".to_string(),
        };
        let fmt_rel = |x: Option<f64>, e0: f64| {
            if e0 > 0.0 { fmt_t(x) } else { "-".to_string() }
        };
        let mut s = String::new();
        let _ = writeln!(
            s,
            "{}: {} samples, {:.3} s",
            self.run.scenario, self.samples, self.duration_s
        );
        for l in &self.levels {
            // A level of mixed units (a 6-D pose: m and rad rows) has a
            // norm of no single unit: say so, and give each group's figures.
            let u = match l.unit {
                ErrorUnit::Mixed => "(mixed units)",
                unit => unit.label(),
            };
            let _ = write!(
                s,
                "  level {} ({}): |e0| = {:.4e} {u}, 5 %: {}, 1 %: {}, abs {}: {}, final |e| = {:.3e} {u}",
                l.level,
                l.name,
                l.initial_error_norm,
                fmt_rel(l.time_below_5_percent_s, l.initial_error_norm),
                fmt_rel(l.time_below_1_percent_s, l.initial_error_norm),
                match (l.abs_threshold, l.unit) {
                    (Some(_), ErrorUnit::Meter) => "1 mm",
                    (Some(_), _) => "1 mrad",
                    (None, _) => "-",
                },
                fmt_t(l.time_below_abs_s),
                l.final_error_norm,
            );
            for g in &l.by_unit {
                let (what, threshold) = match g.unit {
                    ErrorUnit::Meter => ("position", "1 mm"),
                    ErrorUnit::Radian => ("angle", "1 mrad"),
                    ErrorUnit::Mixed => ("other", "-"),
                };
                let _ = write!(
                    s,
                    "; {what} rows: final {:.3e} {}, abs {threshold}: {}",
                    g.final_error_norm,
                    g.unit.label(),
                    fmt_t(g.time_below_abs_s)
                );
            }
            let _ = writeln!(s);
        }
        let torques: Vec<String> = self
            .max_abs_torque
            .iter()
            .map(|v| format!("{v:.2}"))
            .collect();
        let _ = writeln!(s, "  max |tau| per joint [Nm]: {}", torques.join(", "));
        let _ = writeln!(s, "  final |qd| = {:.3e} rad/s", self.final_joint_speed);
        if let Some(p) = self.max_abs_p_mu {
            let _ = writeln!(s, "  max |P_mu| = {p:.3e} W");
        }
        s
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn stay_below_semantics() {
        let t = [0.0, 1.0, 2.0, 3.0, 4.0];
        assert_eq!(
            time_to_stay_below(&t, &[5.0, 0.5, 2.0, 0.5, 0.1], 1.0),
            Some(3.0)
        );
        assert_eq!(
            time_to_stay_below(&t, &[0.5, 0.5, 0.2, 0.5, 0.1], 1.0),
            Some(0.0)
        );
        assert_eq!(
            time_to_stay_below(&t, &[5.0, 0.5, 0.2, 0.5, 2.0], 1.0),
            None
        );
        assert_eq!(
            time_to_stay_below(&t, &[f64::NAN, 0.5, 0.2, 0.5, 0.1], 1.0),
            Some(1.0)
        );
    }

    #[test]
    fn non_increasing_semantics() {
        let t = [0.0, 1.0, 2.0, 3.0, 4.0];
        assert_eq!(
            non_increasing_from(&t, &[1.0, 2.0, 3.0, 2.0, 1.0], 0.0),
            Some(2.0)
        );
        assert_eq!(
            non_increasing_from(&t, &[5.0, 4.0, 3.0, 2.0, 1.0], 0.0),
            Some(0.0)
        );
        assert_eq!(
            non_increasing_from(&t, &[5.0, 4.0, 3.0, 2.0, 3.0], 0.0),
            Some(4.0)
        );
    }

    #[test]
    fn metrics_of_a_decaying_error() {
        let run = RunDescription {
            scenario: "test".into(),
            n_joints: 1,
            levels: vec![LevelDescription {
                name: "joint".into(),
                dim: 1,
                unit: ErrorUnit::Radian,
                row_units: Vec::new(),
            }],
            settings: BTreeMap::new(),
        };
        let cols = columns::required(1, &[1]);
        let mut traj = Trajectory::new(cols).unwrap();
        for k in 0..=1000 {
            let t = k as f64 * 1e-3;
            let e = 0.1 * (-10.0 * t).exp();
            // t, q1, qd1, tau1, e1_1, S1, P_mu
            traj.push_row(&[t, e, -e, -10.0 * e, e, e * e, 0.0])
                .unwrap();
        }
        let m = Metrics::compute(&traj, &run).unwrap();
        let l = &m.levels[0];
        assert!((l.initial_error_norm - 0.1).abs() < 1e-15);
        // e ≤ 5 % at t = ln(20)/10 = 0.2996 → first sample 0.300
        assert!((l.time_below_5_percent_s.unwrap() - 0.300).abs() < 1e-9);
        assert!((l.time_below_1_percent_s.unwrap() - 0.461).abs() < 1e-9);
        // 1 mrad = 1 % of 0.1 rad
        assert!((l.time_below_abs_s.unwrap() - 0.461).abs() < 1e-9);
        assert_eq!(l.energy_non_increasing_from_s, Some(0.0));
        assert!((m.max_abs_torque[0] - 1.0).abs() < 1e-12);
        assert_eq!(m.max_abs_p_mu, Some(0.0));
        let dir = std::env::temp_dir().join(format!("hcc-report-metrics-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let p = dir.join("metrics.json");
        m.write_json(&p).unwrap();
        assert_eq!(Metrics::read_json(&p).unwrap(), m);
        let _ = std::fs::remove_dir_all(&dir);
        assert!(m.summary().contains("level 1 (joint)"));
    }
}
