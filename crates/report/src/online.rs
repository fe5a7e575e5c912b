//! The run metrics computed row by row ([`MetricsAccumulator`]), in memory
//! independent of the run's length, with exactly the figures of
//! [`Metrics::compute`] on the whole table (same expressions, same order of
//! operations, so the same bits).
//!
//! Each figure of `metrics.json` is a fold that needs no look-back, except:
//! - "time to stay below a threshold" (the thresholds 5 % and 1 % of ‖e_i(0)‖
//!   are known after the first row): the start of the current run of rows
//!   below the threshold, forgotten at each row above;
//! - "non-increasing from" with a tolerance of 1e-9 · max |S_i| known only at
//!   the end: the answer is the last rise larger than the final tolerance, so
//!   the accumulator keeps the rises that no later, larger rise supersedes and
//!   that exceed the tolerance so far (it only grows). A decaying energy leaves
//!   none; each setpoint change or push leaves at most a few.

use crate::columns;
use crate::metrics::{LevelMetrics, Metrics, RunDescription, UnitGroupMetrics};
use crate::{ErrorUnit, ReportError};
use std::collections::BTreeMap;

/// Index of a required column, or the error [`crate::Trajectory::require`] gives.
fn require(columns: &[String], name: &str) -> Result<usize, ReportError> {
    columns
        .iter()
        .position(|c| c == name)
        .ok_or_else(|| ReportError::Table(format!("the trajectory has no column {name:?}")))
}

/// ‖row[cols]‖, summed in the order of `cols` like the batch computation.
fn norm(row: &[f64], cols: &[usize]) -> f64 {
    cols.iter().map(|&j| row[j] * row[j]).sum::<f64>().sqrt()
}

/// "First time from which the value stays ≤ thr" ([`crate::metrics::time_to_stay_below`]).
#[derive(Clone, Debug)]
struct StayBelow {
    thr: f64,
    since: Option<f64>,
}

impl StayBelow {
    fn new(thr: f64) -> StayBelow {
        StayBelow { thr, since: None }
    }

    fn observe(&mut self, t: f64, v: f64) {
        // NaN counts as above the threshold.
        if v.is_nan() || v > self.thr {
            self.since = None;
        } else if self.since.is_none() {
            self.since = Some(t);
        }
    }
}

/// Whether `cur` is a rise over `prev` for the tolerance `tol`: the step the
/// backward scan of [`crate::metrics::non_increasing_from`] stops at.
fn is_rise(prev: f64, cur: f64, tol: f64) -> bool {
    // `!(cur <= prev + tol)`, spelled out: NaN on either side is a rise.
    !matches!(
        cur.partial_cmp(&(prev + tol)),
        Some(std::cmp::Ordering::Less | std::cmp::Ordering::Equal)
    )
}

/// The smallest tolerance ≥ 0 (as f64 bits, which order non-negative floats)
/// for which `cur` over `prev` is no rise; `u64::MAX` if none is (NaN).
fn rise_until(prev: f64, cur: f64) -> u64 {
    let inf = f64::INFINITY.to_bits();
    if is_rise(prev, cur, f64::INFINITY) {
        return u64::MAX;
    }
    let (mut lo, mut hi) = (0_u64, inf);
    while lo < hi {
        let mid = lo + (hi - lo) / 2;
        if is_rise(prev, cur, f64::from_bits(mid)) {
            lo = mid + 1;
        } else {
            hi = mid;
        }
    }
    lo
}

/// "Non-increasing from" of a level energy S_i with the tolerance 1e-9 · max |S_i|.
#[derive(Clone, Debug)]
struct EnergyTrend {
    col: usize,
    smax: f64,
    prev: Option<f64>,
    /// (time, prev, cur, tolerance bits up to which it is a rise) of the
    /// candidate rises, later ones with smaller bounds.
    rises: Vec<(f64, f64, f64, u64)>,
}

impl EnergyTrend {
    fn tol(&self) -> f64 {
        1e-9 * self.smax
    }

    fn observe(&mut self, t: f64, row: &[f64]) {
        let s = row[self.col];
        self.smax = self.smax.max(s.abs());
        let tol = self.tol();
        // Rises not larger than the tolerance so far never count again.
        while self.rises.last().is_some_and(|r| !is_rise(r.1, r.2, tol)) {
            self.rises.pop();
        }
        if let Some(prev) = self.prev.replace(s)
            && is_rise(prev, s, tol)
        {
            let until = rise_until(prev, s);
            while self.rises.last().is_some_and(|r| r.3 <= until) {
                self.rises.pop();
            }
            self.rises.push((t, prev, s, until));
        }
    }

    fn finish(mut self, t0: f64) -> Option<f64> {
        let tol = self.tol();
        while self.rises.last().is_some_and(|r| !is_rise(r.1, r.2, tol)) {
            self.rises.pop();
        }
        Some(self.rises.last().map_or(t0, |r| r.0))
    }
}

/// The figures of the rows of one unit of a mixed level.
#[derive(Clone, Debug)]
struct GroupAcc {
    unit: ErrorUnit,
    rows: Vec<usize>,
    cols: Vec<usize>,
    max: f64,
    last: f64,
    below_abs: Option<StayBelow>,
}

/// The figures of one level.
#[derive(Clone, Debug)]
struct LevelAcc {
    error_cols: Vec<usize>,
    e0: f64,
    below: Vec<StayBelow>,
    below_abs: Option<StayBelow>,
    max: f64,
    last: f64,
    energy: Option<EnergyTrend>,
    groups: Vec<GroupAcc>,
}

impl LevelAcc {
    fn new(
        i: usize,
        level: &crate::LevelDescription,
        cols: &[String],
    ) -> Result<Self, ReportError> {
        let error_cols: Vec<usize> = (0..level.dim)
            .map(|k| require(cols, &columns::error(i + 1, k + 1)))
            .collect::<Result<_, _>>()?;
        let mut units: Vec<ErrorUnit> = Vec::new();
        for u in &level.row_units {
            if !units.contains(u) {
                units.push(*u);
            }
        }
        let groups = units
            .into_iter()
            .map(|unit| {
                let rows: Vec<usize> = (0..level.row_units.len().min(level.dim))
                    .filter(|&k| level.row_units[k] == unit)
                    .collect();
                GroupAcc {
                    unit,
                    cols: rows.iter().map(|&k| error_cols[k]).collect(),
                    rows,
                    max: 0.0,
                    last: 0.0,
                    below_abs: unit.abs_threshold().map(StayBelow::new),
                }
            })
            .collect();
        Ok(LevelAcc {
            energy: cols
                .iter()
                .position(|c| *c == columns::energy(i + 1))
                .map(|col| EnergyTrend {
                    col,
                    smax: 0.0,
                    prev: None,
                    rises: Vec::new(),
                }),
            below_abs: level.unit.abs_threshold().map(StayBelow::new),
            error_cols,
            e0: 0.0,
            below: Vec::new(),
            max: 0.0,
            last: 0.0,
            groups,
        })
    }

    fn observe(&mut self, first: bool, t: f64, row: &[f64]) {
        let e = norm(row, &self.error_cols);
        if first {
            self.e0 = e;
            self.below = vec![StayBelow::new(0.05 * e), StayBelow::new(0.01 * e)];
        }
        for b in self.below.iter_mut().chain(&mut self.below_abs) {
            b.observe(t, e);
        }
        self.max = self.max.max(e);
        self.last = e;
        if let Some(s) = &mut self.energy {
            s.observe(t, row);
        }
        for g in &mut self.groups {
            let e = norm(row, &g.cols);
            g.max = g.max.max(e);
            g.last = e;
            if let Some(b) = &mut g.below_abs {
                b.observe(t, e);
            }
        }
    }

    fn finish(
        self,
        i: usize,
        level: &crate::LevelDescription,
        t0: f64,
        last: &[f64],
    ) -> LevelMetrics {
        let since = |b: &StayBelow| b.since;
        LevelMetrics {
            level: i + 1,
            name: level.name.clone(),
            unit: level.unit,
            initial_error_norm: self.e0,
            time_below_5_percent_s: self.below.first().and_then(since),
            time_below_1_percent_s: self.below.get(1).and_then(since),
            abs_threshold: level.unit.abs_threshold(),
            time_below_abs_s: self.below_abs.as_ref().and_then(since),
            final_error_norm: self.last,
            final_error: self.error_cols.iter().map(|&j| last[j]).collect(),
            max_error_norm: self.max,
            energy_non_increasing_from_s: self.energy.and_then(|s| s.finish(t0)),
            by_unit: self
                .groups
                .into_iter()
                .map(|g| UnitGroupMetrics {
                    unit: g.unit,
                    rows: g.rows,
                    max_error_norm: g.max,
                    final_error_norm: g.last,
                    time_below_abs_s: g.below_abs.as_ref().and_then(since),
                })
                .collect(),
        }
    }
}

/// The metrics of a run fed one row at a time; [`MetricsAccumulator::finish`]
/// gives what [`Metrics::compute`] gives on the table of the same rows.
#[derive(Clone, Debug)]
pub struct MetricsAccumulator {
    run: RunDescription,
    n_columns: usize,
    t_col: usize,
    levels: Vec<LevelAcc>,
    torque_cols: Vec<usize>,
    velocity_cols: Vec<usize>,
    p_mu_col: Option<usize>,
    /// max |x| of the torque columns, then P_μ (if any), then the disturbing accelerations.
    max_abs: Vec<f64>,
    acc_cols: Vec<(String, usize)>,
    samples: usize,
    t0: f64,
    last_row: Vec<f64>,
}

impl MetricsAccumulator {
    /// An accumulator of rows with `columns` for a run of the shape of `run`
    /// (joints and levels); fails like [`Metrics::compute`] on a missing column.
    pub fn new(columns: &[String], run: &RunDescription) -> Result<Self, ReportError> {
        let levels = run
            .levels
            .iter()
            .enumerate()
            .map(|(i, l)| LevelAcc::new(i, l, columns))
            .collect::<Result<_, _>>()?;
        let joint_cols = |name: fn(usize) -> String| -> Result<Vec<usize>, ReportError> {
            (1..=run.n_joints)
                .map(|k| require(columns, &name(k)))
                .collect()
        };
        let torque_cols = joint_cols(columns::torque)?;
        let p_mu_col = columns.iter().position(|c| c == columns::P_MU);
        let acc_cols: Vec<(String, usize)> = (0..columns.len())
            .filter(|&j| columns::is_disturbing_acceleration(&columns[j]))
            .map(|j| (columns[j].clone(), j))
            .collect();
        Ok(MetricsAccumulator {
            run: run.clone(),
            n_columns: columns.len(),
            t_col: require(columns, columns::TIME)?,
            levels,
            max_abs: vec![
                0.0;
                torque_cols.len() + usize::from(p_mu_col.is_some()) + acc_cols.len()
            ],
            velocity_cols: joint_cols(columns::velocity)?,
            torque_cols,
            p_mu_col,
            acc_cols,
            samples: 0,
            t0: 0.0,
            last_row: Vec::new(),
        })
    }

    /// Number of rows taken.
    pub fn samples(&self) -> usize {
        self.samples
    }

    /// Takes the next row.
    pub fn push_row(&mut self, row: &[f64]) -> Result<(), ReportError> {
        ReportError::check_row(self.samples, row, self.n_columns)?;
        let first = self.samples == 0;
        let t = row[self.t_col];
        if first {
            self.t0 = t;
        }
        for l in &mut self.levels {
            l.observe(first, t, row);
        }
        let cols = self
            .torque_cols
            .iter()
            .chain(&self.p_mu_col)
            .chain(self.acc_cols.iter().map(|(_, j)| j));
        for (m, &j) in self.max_abs.iter_mut().zip(cols) {
            *m = m.max(row[j].abs());
        }
        self.last_row.clear();
        self.last_row.extend_from_slice(row);
        self.samples += 1;
        Ok(())
    }

    /// The metrics of the rows taken, described by `run` (the run of
    /// [`MetricsAccumulator::new`] with its final settings).
    pub fn finish(self, run: &RunDescription) -> Result<Metrics, ReportError> {
        if self.samples == 0 {
            return Err(ReportError::Table("the trajectory has no rows".into()));
        }
        if run.n_joints != self.run.n_joints || run.levels != self.run.levels {
            return Err(ReportError::Table(
                "the run's joints or levels changed while its rows were taken".into(),
            ));
        }
        let last = &self.last_row;
        let n_torques = self.torque_cols.len();
        let n_p_mu = usize::from(self.p_mu_col.is_some());
        let levels = self
            .levels
            .into_iter()
            .zip(&run.levels)
            .enumerate()
            .map(|(i, (acc, l))| acc.finish(i, l, self.t0, last))
            .collect();
        Ok(Metrics {
            run: run.clone(),
            samples: self.samples,
            duration_s: last[self.t_col],
            levels,
            max_abs_torque: self.max_abs[..n_torques].to_vec(),
            max_abs_p_mu: self.p_mu_col.map(|_| self.max_abs[n_torques]),
            max_disturbing_acceleration: self
                .acc_cols
                .into_iter()
                .map(|(c, _)| c)
                .zip(self.max_abs[n_torques + n_p_mu..].iter().copied())
                .collect::<BTreeMap<_, _>>(),
            final_joint_speed: norm(last, &self.velocity_cols),
        })
    }
}
