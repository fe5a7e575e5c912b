//! Results of a run of the hierarchical compliance controller: the trajectory
//! table (`trajectory.csv`), metrics (`metrics.json`) and PNG plots in the
//! spirit of Figs. 3–7 of Dietrich, Ott & Albu-Schäffer (IROS 2013).
//!
//! The crate knows nothing about how a run was produced (in-process simulation
//! or the daemons): its inputs are rows with the columns described in
//! [`columns`] and a [`RunDescription`]. The rows are taken one at a time
//! ([`RunWriter`]: the CSV streamed, the metrics accumulated online, the plots
//! from a bounded decimation), so memory does not grow with the run; an
//! in-memory [`Trajectory`] goes through the same writer ([`write_run`]).
//!
//! ```no_run
//! # use hcc_report::*;
//! # fn f(traj: Trajectory, run: RunDescription) -> Result<(), ReportError> {
//! let out = write_run(std::path::Path::new("out/sim1"), &traj, &run)?;
//! print!("{}", out.metrics.summary());
//! # Ok(()) }
//! ```

pub mod columns;
pub mod decimate;
pub mod metrics;
mod online;
pub mod percentiles;
pub mod plots;
pub mod stream;
pub mod trajectory;

pub use decimate::{Decimator, PLOT_POINTS};
pub use metrics::{ErrorUnit, LevelDescription, LevelMetrics, Metrics, RunDescription};
pub use online::MetricsAccumulator;
pub use percentiles::{PercentileCurve, plot_percentiles};
pub use plots::{TimePanel, plot_all, plot_time_series};
pub use stream::{CsvWriter, RunWriter};
pub use trajectory::Trajectory;

use std::path::{Path, PathBuf};

/// File name of the trajectory table in a run directory.
pub const TRAJECTORY_FILE: &str = "trajectory.csv";
/// File name of the metrics in a run directory.
pub const METRICS_FILE: &str = "metrics.json";

/// Errors of this crate; each names the file or column concerned.
#[derive(Debug, thiserror::Error)]
pub enum ReportError {
    #[error("{}: {error}", path.display())]
    Io {
        path: PathBuf,
        error: std::io::Error,
    },
    #[error("{}: invalid JSON: {error}", path.display())]
    Json {
        path: PathBuf,
        error: serde_json::Error,
    },
    #[error("{origin}: line {line}: {message}")]
    Parse {
        origin: String,
        line: usize,
        message: String,
    },
    #[error("trajectory: {0}")]
    Table(String),
    #[error("{}: plotting failed: {message}", path.display())]
    Plot { path: PathBuf, message: String },
}

impl ReportError {
    /// Checks that row number `index` has `columns` values (every table and
    /// writer of this crate takes rows of a fixed width).
    pub(crate) fn check_row(
        index: impl std::fmt::Display,
        row: &[f64],
        columns: usize,
    ) -> Result<(), ReportError> {
        if row.len() == columns {
            return Ok(());
        }
        Err(ReportError::Table(format!(
            "row {index} has {} values, the table has {columns} columns",
            row.len()
        )))
    }
}

/// What [`write_run`] produced.
#[derive(Clone, Debug)]
pub struct RunOutputs {
    pub metrics: Metrics,
    /// Every file written (CSV, JSON, PNGs).
    pub files: Vec<PathBuf>,
}

/// Writes `trajectory.csv`, `metrics.json` and the plots of an in-memory table
/// into `dir` (created if missing), through the streaming [`RunWriter`].
pub fn write_run(
    dir: &Path,
    traj: &Trajectory,
    run: &RunDescription,
) -> Result<RunOutputs, ReportError> {
    let mut w = RunWriter::new(dir, traj.columns().to_vec(), run, true)?;
    for row in traj.rows() {
        w.push_row(row)?;
    }
    w.finish(run)
}

/// Regenerates the plots of a run directory from its `trajectory.csv` and
/// `metrics.json`; the CSV is read line by line into the plots' bounded
/// decimation, as the rows of a run are when it is written.
pub fn replot(dir: &Path) -> Result<Vec<PathBuf>, ReportError> {
    use std::io::BufRead as _;
    let path = dir.join(TRAJECTORY_FILE);
    let io = |error| ReportError::Io {
        path: path.clone(),
        error,
    };
    let file = std::fs::File::open(&path).map_err(io)?;
    let lines = std::io::BufReader::new(file).lines().map(|l| l.map_err(io));
    let origin = path.display().to_string();
    let mut csv = trajectory::CsvLines::new(lines, &origin);
    let mut plot = Decimator::for_plots(csv.header()?)?;
    let mut row = Vec::new();
    while csv.next_row(&mut row)? {
        plot.push_row(&row)?;
    }
    let metrics = Metrics::read_json(&dir.join(METRICS_FILE))?;
    plot_all(dir, &plot.finish()?, &metrics)
}
