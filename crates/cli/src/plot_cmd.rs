//! `hcc plot DIR`: regenerate the plots of a run directory from its
//! `trajectory.csv` and `metrics.json`.

use anyhow::Context;
use std::path::PathBuf;

#[derive(clap::Args, Debug)]
pub struct PlotArgs {
    /// Run directory containing trajectory.csv and metrics.json (as written by
    /// `hcc simulate` or `hcc run`).
    pub dir: PathBuf,
}

pub fn run(args: PlotArgs) -> anyhow::Result<()> {
    let files = hcc_report::replot(&args.dir)
        .with_context(|| format!("cannot plot the run in {}", args.dir.display()))?;
    for f in files {
        println!("{}", f.display());
    }
    Ok(())
}
