//! Writing a run's results as its rows are produced: `trajectory.csv` line by
//! line ([`CsvWriter`]), `metrics.json` from an online accumulator and the
//! plots from a bounded decimation ([`RunWriter`]). Memory does not grow with
//! the run's length, and the outputs are those of the in-memory table: the
//! same CSV bytes, the same metrics; plots from every row up to
//! [`crate::decimate::PLOT_POINTS`] rows, from each bucket's extremes beyond.

use crate::decimate::Decimator;
use crate::online::MetricsAccumulator;
use crate::plots::plot_all;
use crate::trajectory::{push_csv_row, validate_columns};
use crate::{METRICS_FILE, ReportError, RunDescription, RunOutputs, TRAJECTORY_FILE};
use std::fs::File;
use std::io::{BufWriter, Write};
use std::path::{Path, PathBuf};

/// A CSV table written row by row, in the format of
/// [`crate::Trajectory::write_csv`] (same header, same number formatting).
pub struct CsvWriter {
    path: PathBuf,
    out: BufWriter<File>,
    n_columns: usize,
    rows: u64,
    line: String,
}

impl CsvWriter {
    /// Creates (or truncates) `path` and writes the header of `columns`.
    pub fn create(path: &Path, columns: &[String]) -> Result<CsvWriter, ReportError> {
        validate_columns(columns)?;
        let io = |e| ReportError::Io {
            path: path.to_path_buf(),
            error: e,
        };
        let mut out = BufWriter::with_capacity(1 << 20, File::create(path).map_err(io)?);
        writeln!(out, "{}", columns.join(",")).map_err(io)?;
        Ok(CsvWriter {
            path: path.to_path_buf(),
            out,
            n_columns: columns.len(),
            rows: 0,
            line: String::new(),
        })
    }

    /// Rows written so far.
    pub fn rows(&self) -> u64 {
        self.rows
    }

    /// Appends one row (as many values as columns).
    pub fn push_row(&mut self, row: &[f64]) -> Result<(), ReportError> {
        ReportError::check_row(self.rows, row, self.n_columns)?;
        self.line.clear();
        push_csv_row(&mut self.line, row);
        self.out
            .write_all(self.line.as_bytes())
            .map_err(|e| self.io(e))?;
        self.rows += 1;
        Ok(())
    }

    /// Flushes the file; the error names it.
    pub fn finish(mut self) -> Result<PathBuf, ReportError> {
        self.out.flush().map_err(|e| self.io(e))?;
        Ok(self.path)
    }

    fn io(&self, error: std::io::Error) -> ReportError {
        ReportError::Io {
            path: self.path.clone(),
            error,
        }
    }
}

/// The results of a run written into a directory as its rows come:
/// `trajectory.csv`, then at [`RunWriter::finish`] `metrics.json` and the
/// plots. Nothing is written before the first row (the directory and the CSV
/// are created then), so a run without rows leaves no files.
pub struct RunWriter {
    dir: PathBuf,
    columns: Vec<String>,
    csv: Option<CsvWriter>,
    metrics: MetricsAccumulator,
    plots: Option<Decimator>,
}

impl RunWriter {
    /// A writer of rows with `columns` into `dir` for a run of the shape of
    /// `run` (joints, levels; its settings are taken at the end); with
    /// `plots`, the PNG plots too.
    pub fn new(
        dir: &Path,
        columns: Vec<String>,
        run: &RunDescription,
        plots: bool,
    ) -> Result<RunWriter, ReportError> {
        validate_columns(&columns)?;
        Ok(RunWriter {
            dir: dir.to_path_buf(),
            metrics: MetricsAccumulator::new(&columns, run)?,
            plots: if plots {
                Some(Decimator::for_plots(columns.clone())?)
            } else {
                None
            },
            columns,
            csv: None,
        })
    }

    /// Rows taken so far.
    pub fn rows(&self) -> usize {
        self.metrics.samples()
    }

    /// Takes the next row: written to the CSV, folded into the metrics and
    /// the plots' decimation.
    pub fn push_row(&mut self, row: &[f64]) -> Result<(), ReportError> {
        let csv = match &mut self.csv {
            Some(csv) => csv,
            None => {
                std::fs::create_dir_all(&self.dir).map_err(|e| ReportError::Io {
                    path: self.dir.clone(),
                    error: e,
                })?;
                let path = self.dir.join(TRAJECTORY_FILE);
                self.csv.insert(CsvWriter::create(&path, &self.columns)?)
            }
        };
        csv.push_row(row)?;
        self.metrics.push_row(row)?;
        if let Some(d) = &mut self.plots {
            d.push_row(row)?;
        }
        Ok(())
    }

    /// Completes the CSV, writes `metrics.json` (with `run`, the description
    /// of [`RunWriter::new`] and its final settings) and the plots.
    pub fn finish(self, run: &RunDescription) -> Result<RunOutputs, ReportError> {
        let Some(csv) = self.csv else {
            return Err(ReportError::Table("the trajectory has no rows".into()));
        };
        let mut files = vec![csv.finish()?];
        let metrics = self.metrics.finish(run)?;
        let json = self.dir.join(METRICS_FILE);
        metrics.write_json(&json)?;
        files.push(json);
        if let Some(d) = self.plots {
            files.extend(plot_all(&self.dir, &d.finish()?, &metrics)?);
        }
        Ok(RunOutputs { metrics, files })
    }
}
