//! Bounded, peak-preserving decimation of a run's rows for the plots.
//!
//! A plot is 1200 pixels wide, so it cannot show more than a few thousand
//! points per line; holding every row of a long run only to draw it would make
//! the memory of `hcc plot` grow with the run. The [`Decimator`] keeps every
//! row up to a bound (`max_points`, so the plots of short runs are drawn from
//! all rows as before); beyond it, it keeps buckets of consecutive rows and, per
//! bucket and column, the minimum and the maximum in the order they occurred.
//! A line through those points passes through every extreme of the run (a
//! one-cycle spike stays visible). When the buckets fill up, neighbours are
//! merged in pairs (the bucket width doubles), so memory stays bounded
//! whatever the run's length.
//!
//! Non-finite values are skipped, as the plots skip them.

use crate::{ReportError, Trajectory};

/// Rows kept exactly (and points per line at most) by [`Decimator::for_plots`]:
/// more than every shipped scenario has (14.5 s at 1 kHz), and about ten points
/// per pixel of a plot's width.
pub const PLOT_POINTS: usize = 16_384;

/// Min and max of every column over consecutive rows, in time order.
#[derive(Clone, Debug)]
struct Bucket {
    t_first: f64,
    t_last: f64,
    min: Vec<f64>,
    max: Vec<f64>,
    /// Per column: whether the minimum came first (at or before the maximum).
    min_first: Vec<bool>,
}

/// Whether `later` replaces `current` as the extreme (`better`: strictly less
/// for a minimum, strictly greater for a maximum); NaN stands for "no finite
/// value yet" and is replaced by any finite value.
fn takes_over(current: f64, later: f64, better: fn(f64, f64) -> bool) -> bool {
    !later.is_nan() && (current.is_nan() || better(later, current))
}

/// A finite value, or NaN for an infinity or NaN (the plots skip both).
fn finite_or_nan(v: f64) -> f64 {
    if v.is_finite() { v } else { f64::NAN }
}

impl Bucket {
    /// The bucket of one row at time `t`.
    fn of_row(t: f64, row: &[f64]) -> Bucket {
        let values: Vec<f64> = row.iter().map(|v| finite_or_nan(*v)).collect();
        Bucket {
            t_first: t,
            t_last: t,
            min: values.clone(),
            max: values,
            min_first: vec![true; row.len()],
        }
    }

    /// Extends the bucket with `later`, which follows it in time.
    fn absorb(&mut self, later: &Bucket) {
        for j in 0..self.min.len() {
            let new_min = takes_over(self.min[j], later.min[j], |a, b| a < b);
            let new_max = takes_over(self.max[j], later.max[j], |a, b| a > b);
            self.min_first[j] = match (new_min, new_max) {
                (false, false) => self.min_first[j],
                (true, true) => later.min_first[j],
                // Min from this bucket, max from the later one: min first.
                (false, true) => true,
                (true, false) => false,
            };
            if new_min {
                self.min[j] = later.min[j];
            }
            if new_max {
                self.max[j] = later.max[j];
            }
        }
        self.t_last = later.t_last;
    }

    /// The rows that represent the bucket: one for a single instant, else
    /// two (at its first and last time) carrying each column's extremes in
    /// the order they occurred.
    fn emit(&self, t_col: usize, out: &mut Trajectory) -> Result<(), ReportError> {
        if self.t_first == self.t_last {
            let mut row = self.min.clone();
            row[t_col] = self.t_first;
            return out.push_row(&row);
        }
        let pick = |first: bool| -> Vec<f64> {
            (0..self.min.len())
                .map(|j| {
                    if self.min_first[j] == first {
                        self.min[j]
                    } else {
                        self.max[j]
                    }
                })
                .collect()
        };
        let (mut a, mut b) = (pick(true), pick(false));
        a[t_col] = self.t_first;
        b[t_col] = self.t_last;
        out.push_row(&a)?;
        out.push_row(&b)
    }
}

/// Buckets of `width` rows each (the last one possibly partial).
#[derive(Debug)]
struct Buckets {
    width: u64,
    done: Vec<Bucket>,
    partial: Option<(Bucket, u64)>,
    /// Complete buckets at which neighbours are merged in pairs.
    capacity: usize,
}

impl Buckets {
    fn push(&mut self, t: f64, row: &[f64]) {
        let one = Bucket::of_row(t, row);
        let (bucket, count) = match self.partial.take() {
            Some((mut b, c)) => {
                b.absorb(&one);
                (b, c + 1)
            }
            None => (one, 1),
        };
        if count < self.width {
            self.partial = Some((bucket, count));
            return;
        }
        self.done.push(bucket);
        if self.done.len() >= self.capacity {
            let merged = self
                .done
                .chunks(2)
                .map(|pair| {
                    let mut b = pair[0].clone();
                    if let Some(later) = pair.get(1) {
                        b.absorb(later);
                    }
                    b
                })
                .collect();
            self.done = merged;
            self.width *= 2;
        }
    }
}

/// Keeps at most about `max_points` rows of a run for its plots (see the
/// module documentation).
#[derive(Debug)]
pub struct Decimator {
    columns: Vec<String>,
    t_col: usize,
    max_points: usize,
    /// Every row, while there are at most `max_points`.
    exact: Trajectory,
    buckets: Option<Buckets>,
}

impl Decimator {
    /// A decimator of rows with `columns`, time in column `t_col`, that keeps
    /// every row up to `max_points` rows and at most `max_points` after
    /// (`max_points` ≥ 4).
    pub fn new(
        columns: Vec<String>,
        t_col: usize,
        max_points: usize,
    ) -> Result<Decimator, ReportError> {
        if t_col >= columns.len() || max_points < 4 {
            return Err(ReportError::Table(format!(
                "decimation of {} columns with time column {t_col} to {max_points} points",
                columns.len()
            )));
        }
        Ok(Decimator {
            exact: Trajectory::new(columns.clone())?,
            columns,
            t_col,
            max_points,
            buckets: None,
        })
    }

    /// A decimator for the run plots: time in column `t`, [`PLOT_POINTS`] points.
    pub fn for_plots(columns: Vec<String>) -> Result<Decimator, ReportError> {
        let t_col = columns
            .iter()
            .position(|c| c == crate::columns::TIME)
            .ok_or_else(|| ReportError::Table("the trajectory has no column \"t\"".into()))?;
        Decimator::new(columns, t_col, PLOT_POINTS)
    }

    /// Takes the next row (time order).
    pub fn push_row(&mut self, row: &[f64]) -> Result<(), ReportError> {
        if let Some(b) = &mut self.buckets {
            ReportError::check_row("in the decimation", row, self.columns.len())?;
            b.push(row[self.t_col], row);
            return Ok(());
        }
        if self.exact.n_rows() < self.max_points {
            return self.exact.push_row(row);
        }
        // One row too many: from now on, buckets (the rows so far replayed).
        let mut b = Buckets {
            width: 1,
            done: Vec::new(),
            partial: None,
            capacity: self.max_points / 2,
        };
        for r in self.exact.rows() {
            b.push(r[self.t_col], r);
        }
        self.exact = Trajectory::new(self.columns.clone())?;
        self.buckets = Some(b);
        self.push_row(row)
    }

    /// The rows to plot: every row if there were at most `max_points`, else
    /// the extremes of each bucket.
    pub fn finish(self) -> Result<Trajectory, ReportError> {
        let Some(b) = self.buckets else {
            return Ok(self.exact);
        };
        let mut out = Trajectory::with_capacity(self.columns, self.max_points)?;
        for bucket in b.done.iter().chain(b.partial.as_ref().map(|(p, _)| p)) {
            bucket.emit(self.t_col, &mut out)?;
        }
        Ok(out)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn table(rows: usize, f: impl Fn(usize) -> f64) -> Vec<[f64; 2]> {
        (0..rows).map(|k| [k as f64 * 1e-3, f(k)]).collect()
    }

    fn decimate(rows: &[[f64; 2]], max_points: usize) -> Trajectory {
        let mut d = Decimator::new(vec!["t".into(), "x".into()], 0, max_points).unwrap();
        for r in rows {
            d.push_row(r).unwrap();
        }
        d.finish().unwrap()
    }

    #[test]
    fn short_runs_are_kept_exactly() {
        let rows = table(100, |k| (k as f64).sin());
        let out = decimate(&rows, 100);
        assert_eq!(out.n_rows(), 100);
        for (a, b) in out.rows().zip(&rows) {
            assert_eq!(a, b);
        }
    }

    #[test]
    fn decimation_keeps_extremes_in_order_and_is_bounded() {
        // A slow wave with one-cycle spikes up and down, and a NaN.
        let n = 1_000_003;
        let rows = table(n, |k| match k {
            123_457 => 50.0,
            765_432 => -40.0,
            500_000 => f64::NAN,
            _ => (k as f64 * 1e-4).sin(),
        });
        let out = decimate(&rows, 1000);
        assert!(
            out.n_rows() <= 1000 && out.n_rows() >= 500,
            "{}",
            out.n_rows()
        );
        let t = out.column("t").unwrap();
        let x = out.column("x").unwrap();
        assert!(t.windows(2).all(|w| w[0] < w[1]), "time is increasing");
        assert_eq!(t[0], 0.0);
        assert_eq!(*t.last().unwrap(), (n - 1) as f64 * 1e-3);
        let max = x.iter().fold(f64::MIN, |a, b| a.max(*b));
        let min = x.iter().fold(f64::MAX, |a, b| a.min(*b));
        assert_eq!((max, min), (50.0, -40.0));
        assert!(x.iter().all(|v| v.is_finite()));
        // The spikes are drawn near their time (within one bucket).
        let width = (n as f64 * 1e-3) / (out.n_rows() as f64 / 2.0);
        let at = |v: f64| t[x.iter().position(|x| *x == v).unwrap()];
        assert!((at(50.0) - 123.457).abs() <= 2.0 * width);
        assert!((at(-40.0) - 765.432).abs() <= 2.0 * width);
        // Between the spikes, the wave's own extremes are kept.
        let wave_max = rows
            .iter()
            .filter(|r| r[1] < 2.0)
            .fold(f64::MIN, |a, r| a.max(r[1]));
        assert!(x.contains(&wave_max));
    }

    #[test]
    fn order_of_min_and_max_is_kept() {
        // Falling then rising inside each bucket: the min is emitted first
        // for a rise, last for a fall.
        let rows = table(64, |k| if k < 32 { -(k as f64) } else { k as f64 });
        let x = decimate(&rows, 8).column("x").unwrap();
        assert_eq!(x.first(), Some(&0.0));
        assert_eq!(x.last(), Some(&63.0));
        let lo = x.iter().position(|v| *v == -31.0).unwrap();
        assert!(x[..lo].iter().all(|v| *v > -31.0));
    }
}
