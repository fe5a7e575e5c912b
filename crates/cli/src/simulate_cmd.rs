//! `hcc simulate CONFIG --out DIR`: the closed loop in one process (controller
//! sampled at the control rate, torque held, plant integrated with RK4), then
//! trajectory.csv, metrics.json and plots in DIR and a short summary on stdout.

use anyhow::Context;
use std::path::PathBuf;

#[derive(clap::Args, Debug)]
pub struct SimulateArgs {
    /// Scenario TOML file (e.g. config/paper-sim1.toml).
    pub config: PathBuf,
    /// Output directory (created if missing).
    #[arg(long)]
    pub out: PathBuf,
    /// Simulated duration in s (overrides [simulation] duration_s).
    #[arg(long, allow_negative_numbers = true)]
    pub duration: Option<f64>,
    /// Run without the Coriolis cancellation τ_μ (eq. 22), for the ablation.
    #[arg(long)]
    pub no_coriolis_cancellation: bool,
    /// Skip the PNG plots (CSV and metrics only).
    #[arg(long)]
    pub no_plots: bool,
}

pub fn run(args: SimulateArgs) -> anyhow::Result<()> {
    let mut scenario = hcc_config::Scenario::load(&args.config)?;
    if let Some(d) = args.duration {
        scenario
            .set_duration(d)
            .with_context(|| format!("--duration {d}"))?;
    }
    if args.no_coriolis_cancellation {
        scenario.set_coriolis_cancellation(false)?;
    }
    let run = hcc_plant::closed_loop::simulate(&scenario)
        .with_context(|| format!("simulation of {} failed", args.config.display()))?;
    let metrics = if args.no_plots {
        std::fs::create_dir_all(&args.out)
            .with_context(|| format!("cannot create {}", args.out.display()))?;
        run.trajectory
            .write_csv(&args.out.join(hcc_report::TRAJECTORY_FILE))?;
        let m = hcc_report::Metrics::compute(&run.trajectory, &run.description)?;
        m.write_json(&args.out.join(hcc_report::METRICS_FILE))?;
        m
    } else {
        hcc_report::write_run(&args.out, &run.trajectory, &run.description)?.metrics
    };
    print!("{}", metrics.summary());
    if let Some(n) = run
        .description
        .settings
        .get("saturated_cycles")
        .and_then(|v| v.as_u64())
        && n > 0
    {
        println!("  torque saturated to the limits in {n} cycles");
    }
    println!("results in {}", args.out.display());
    Ok(())
}
