//! `hcc plot DIR` redraws the plots of a run directory from its
//! `trajectory.csv` and `metrics.json`; `hcc plot FILE.mcap [--out DIR]`
//! derives trajectory.csv, metrics.json and the plots from a recording (the
//! code `hcc run` uses for its own results); `hcc export FILE.mcap --csv
//! FILE.csv [--from S] [--to S]` writes the derived table only.

use anyhow::{Context, bail};
use hcc_record::{RecordError, RowSink};
use hcc_report::CsvWriter;
use std::path::{Path, PathBuf};

use hcc_replay::derive;

#[derive(clap::Args, Debug)]
pub struct PlotArgs {
    /// A recording (FILE.mcap, from `hcc run`, `hcc record` or `hcc simulate`), or a
    /// results directory containing trajectory.csv and metrics.json.
    pub path: PathBuf,
    /// Output directory for a recording's results (default: the recording's directory).
    #[arg(long)]
    pub out: Option<PathBuf>,
    /// The scenario of a recording (default: the one it names).
    #[arg(long)]
    pub config: Option<PathBuf>,
    /// Only trajectory.csv and metrics.json (no PNG plots).
    #[arg(long)]
    pub no_plots: bool,
}

#[derive(clap::Args, Debug)]
pub struct ExportArgs {
    /// The recording (FILE.mcap).
    pub recording: PathBuf,
    /// The table to write (the columns of trajectory.csv).
    #[arg(long)]
    pub csv: PathBuf,
    /// First time to include, s (the driver's time t = k · T).
    #[arg(long, allow_negative_numbers = true)]
    pub from: Option<f64>,
    /// Last time to include, s.
    #[arg(long, allow_negative_numbers = true)]
    pub to: Option<f64>,
    /// The scenario of the recording (default: the one it names).
    #[arg(long)]
    pub config: Option<PathBuf>,
}

fn is_recording(path: &Path) -> bool {
    path.is_file()
}

pub fn run(args: PlotArgs) -> anyhow::Result<()> {
    if !is_recording(&args.path) {
        let files = hcc_report::replot(&args.path)
            .with_context(|| format!("cannot plot the run in {}", args.path.display()))?;
        for f in files {
            println!("{}", f.display());
        }
        return Ok(());
    }
    let scenario = derive::scenario_of(&args.path, args.config.as_deref())?;
    let out = args.out.clone().unwrap_or_else(|| {
        args.path
            .parent()
            .map(Path::to_path_buf)
            .unwrap_or_else(|| PathBuf::from("."))
    });
    // The results are written as the rows are derived (nothing before the first).
    let mut writer = derive::results_writer(&scenario, &out, args.no_plots)?;
    let d = derive::derive(&args.path, &scenario, &mut writer)?;
    if d.rows.rows == 0 {
        bail!(
            "{} holds no complete controller cycle (joint state and telemetry)",
            args.path.display()
        );
    }
    let m = writer.finish(&d.description)?.metrics;
    print!("{}", m.summary());
    d.print();
    if let Some(reason) = &d.read.truncated {
        println!("  the recording is truncated ({reason}); read up to its last complete chunk");
    }
    println!("results in {}", out.display());
    Ok(())
}

pub fn export(args: ExportArgs) -> anyhow::Result<()> {
    for (what, v) in [("--from", args.from), ("--to", args.to)] {
        if v.is_some_and(|v| !v.is_finite()) {
            bail!("{what} must be a finite time in s");
        }
    }
    let scenario = derive::scenario_of(&args.recording, args.config.as_deref())?;
    if let Some(dir) = args.csv.parent().filter(|d| !d.as_os_str().is_empty()) {
        std::fs::create_dir_all(dir).with_context(|| format!("cannot create {}", dir.display()))?;
    }
    let columns = hcc_in_process::column_names(&scenario, true);
    let mut window = TimeWindow {
        csv: CsvWriter::create(&args.csv, &columns)?,
        from: args.from.unwrap_or(f64::NEG_INFINITY),
        to: args.to.unwrap_or(f64::INFINITY),
    };
    derive::derive(&args.recording, &scenario, &mut window)?;
    let rows = window.csv.rows();
    window.csv.finish()?;
    println!(
        "{rows} rows x {} columns into {}",
        columns.len(),
        args.csv.display()
    );
    Ok(())
}

/// The rows of `hcc export` whose time `t` (the first column) lies in
/// [from, to], written to the CSV as they are derived.
struct TimeWindow {
    csv: CsvWriter,
    from: f64,
    to: f64,
}

impl RowSink for TimeWindow {
    fn push_row(&mut self, row: &[f64]) -> Result<(), RecordError> {
        if row[0] >= self.from && row[0] <= self.to {
            self.csv.push_row(row)?;
        }
        Ok(())
    }
}
