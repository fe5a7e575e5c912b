//! `hcc plot DIR` redraws the plots of a run directory from its
//! `trajectory.csv` and `metrics.json`; `hcc plot FILE.mcap [--out DIR]`
//! derives trajectory.csv, metrics.json and the plots from a recording (the
//! code `hcc run` uses for its own results); `hcc export FILE.mcap --csv
//! FILE.csv [--from S] [--to S]` writes the derived table only.

use anyhow::{Context, bail};
use hcc_report::Trajectory;
use std::path::{Path, PathBuf};

use crate::derive;
use crate::simulate_cmd::write_results;

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
    let d = derive::derive(&args.path, &scenario)?;
    if d.rows.traj.n_rows() == 0 {
        bail!(
            "{} holds no complete controller cycle (joint state and telemetry)",
            args.path.display()
        );
    }
    let out = args.out.clone().unwrap_or_else(|| {
        args.path
            .parent()
            .map(Path::to_path_buf)
            .unwrap_or_else(|| PathBuf::from("."))
    });
    let m = write_results(&out, &d.rows.traj, &d.description, args.no_plots)?;
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
    let d = derive::derive(&args.recording, &scenario)?;
    let traj = &d.rows.traj;
    let from = args.from.unwrap_or(f64::NEG_INFINITY);
    let to = args.to.unwrap_or(f64::INFINITY);
    let mut table = Trajectory::new(traj.columns().to_vec())?;
    for row in traj.rows().filter(|r| r[0] >= from && r[0] <= to) {
        table.push_row(row)?;
    }
    if let Some(dir) = args.csv.parent().filter(|d| !d.as_os_str().is_empty()) {
        std::fs::create_dir_all(dir).with_context(|| format!("cannot create {}", dir.display()))?;
    }
    table.write_csv(&args.csv)?;
    println!(
        "{} rows x {} columns into {}",
        table.n_rows(),
        table.columns().len(),
        args.csv.display()
    );
    Ok(())
}
