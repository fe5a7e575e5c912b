//! `hcc simulate CONFIG --out DIR`: the closed loop in one process (controller
//! sampled at the control rate, torque held, plant integrated with RK4), then
//! trajectory.csv, metrics.json and plots in DIR and a short summary on stdout.
//! The scenario's `[[setpoint]]` entries are applied at their cycles.

use anyhow::Context;
use hcc_config::Scenario;
use hcc_control::Controller;
use hcc_controller::schedule::Schedule;
use hcc_plant::SimError;
use hcc_plant::closed_loop::{self, Commands, HierarchicalLaw};
use hcc_report::{Metrics, RunDescription, Trajectory};
use std::path::{Path, PathBuf};

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
    let run = closed_loop::simulate_law(&scenario, scheduled_law(&scenario)?)
        .with_context(|| format!("simulation of {} failed", args.config.display()))?;
    let metrics = write_results(&args.out, &run.trajectory, &run.description, args.no_plots)?;
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

/// Writes trajectory.csv, metrics.json and (unless `no_plots`) the plots into
/// `out` (created if missing); the metrics.
pub fn write_results(
    out: &Path,
    traj: &Trajectory,
    description: &RunDescription,
    no_plots: bool,
) -> anyhow::Result<Metrics> {
    if no_plots {
        std::fs::create_dir_all(out).with_context(|| format!("cannot create {}", out.display()))?;
        traj.write_csv(&out.join(hcc_report::TRAJECTORY_FILE))?;
        let m = Metrics::compute(traj, description)?;
        m.write_json(&out.join(hcc_report::METRICS_FILE))?;
        return Ok(m);
    }
    Ok(hcc_report::write_run(out, traj, description)?.metrics)
}

/// The scenario's `[[setpoint]]` schedule as [`Commands`] of the in-process law.
struct ScheduledCommands(Schedule);

impl Commands for ScheduledCommands {
    fn before_step(&mut self, k: u64, controller: &mut Controller) -> Result<(), SimError> {
        self.0.before_step(k, controller).map_err(SimError::Invalid)
    }
}

/// The in-process law of `scenario`, its `[[setpoint]]` entries (if any)
/// applied through the controller daemon's commander
/// ([`hcc_controller::schedule::Schedule`]).
pub(crate) fn scheduled_law(scenario: &Scenario) -> anyhow::Result<HierarchicalLaw> {
    let law = HierarchicalLaw::new(scenario)?;
    if scenario.setpoints.is_empty() {
        return Ok(law);
    }
    let schedule = Schedule::new(law.controller(), scenario)?;
    Ok(law.with_commands(Box::new(ScheduledCommands(schedule))))
}
