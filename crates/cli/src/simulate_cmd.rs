//! `hcc simulate CONFIG --out DIR`: hcc in one process — the simulated
//! robot's driver and the control cycle the controller daemon runs,
//! exchanging their messages by function call (`hcc_in_process`): the same
//! torques as a lockstep `hcc run` of the scenario, by construction. Then
//! trajectory.csv, metrics.json and plots in DIR and a short summary on
//! stdout. The scenario's `[[setpoint]]` entries reach the cycle with the
//! state of their cycle, as a client's do.
//!
//! Each cycle's messages — the joint state numbered k and stamped t_k = k T,
//! the command and the telemetry — are written into `DIR/run.mcap` in the
//! layout of `hcc run` and `hcc record`, so that one reader (`hcc plot
//! FILE.mcap`, `hcc export`, `hcc replay`, Foxglove, PlotJuggler) handles
//! simulated and recorded runs alike.

use anyhow::Context;
use hcc_config::Scenario;
use hcc_in_process::{CycleView, SimError};
use hcc_record::mcap_log::{McapWriter, RecorderMsg, RunInfo};
use hcc_report::{Metrics, RunDescription, RunWriter, Trajectory};
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

// The help texts name the scenario's TOML tables as [table] and placeholders as
// <name>: neither an intra-doc link nor HTML.
#[allow(rustdoc::broken_intra_doc_links, rustdoc::invalid_html_tags)]
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
    // What the law refuses at q0, named by field and line.
    hcc_cycle::controller_for(&scenario)?;
    let recording = args.out.join(hcc_record::capture::RECORDING_FILE);
    let mut log = SimLog::create(&recording, &scenario)?;
    let result = hcc_in_process::simulate_observed(&scenario, &mut |cycle| {
        log.cycle(cycle)
            .map_err(|e| SimError::Invalid(format!("{}: {e:#}", recording.display())))
    });
    let run = result.with_context(|| format!("simulation of {} failed", args.config.display()))?;
    log.finish()?;
    let metrics = write_results(&args.out, &run.trajectory, &run.description, args.no_plots)?;
    print!("{}", metrics.summary());
    let counted = |key: &str| {
        run.description
            .settings
            .get(key)
            .and_then(|v| v.as_u64())
            .filter(|n| *n > 0)
    };
    if let Some(n) = counted("saturated_cycles") {
        println!("  torque saturated to the limits in {n} cycles");
    }
    if let Some(n) = counted("rate_limited_cycles") {
        println!("  torque rate-limited in {n} cycles");
    }
    if let Some(n) = counted("velocity_corrected_cycles") {
        println!("  torque corrected by the discrete-time velocity limit in {n} cycles");
    }
    if let Some(n) = counted("numerical_failures") {
        println!(
            "  warning: the law failed numerically in {n} cycles (answered with the safe command)"
        );
    }
    println!("results in {}", args.out.display());
    Ok(())
}

/// Writes trajectory.csv, metrics.json and (unless `no_plots`) the plots into
/// `out` (created if missing); the metrics.
fn write_results(
    out: &Path,
    traj: &Trajectory,
    description: &RunDescription,
    no_plots: bool,
) -> anyhow::Result<Metrics> {
    let mut w = RunWriter::new(out, traj.columns().to_vec(), description, !no_plots)?;
    for row in traj.rows() {
        w.push_row(row)?;
    }
    Ok(w.finish(description)?.metrics)
}

/// The recording of an in-process run: the messages the driver and the
/// control cycle exchanged, cycle by cycle.
struct SimLog {
    writer: Option<McapWriter>,
    cycles: u64,
}

impl SimLog {
    fn create(path: &Path, scenario: &Scenario) -> anyhow::Result<SimLog> {
        let s = &scenario.simulation;
        let (unix, _) = hcc_record::mcap_log::clock_pair();
        let mut run =
            hcc_record::capture::run_metadata("hcc simulate", &scenario.ipc.namespace, (unix, 0));
        run.insert("mode".into(), "in-process".into());
        run.insert("duration_s".into(), format!("{:?}", s.duration_s));
        run.insert("control_rate_hz".into(), scenario.rate_hz.to_string());
        let info = RunInfo {
            run,
            scenario: RunInfo::describe_scenario(scenario),
            machine: hcc_record::capture::machine_metadata(),
        };
        // Stamps are simulated time (t_k = k T from 0), shown from the start's Unix time.
        let writer = McapWriter::create(path, &info, (unix, 0))?;
        Ok(SimLog {
            writer: Some(writer),
            cycles: 0,
        })
    }

    /// Records one cycle: its state, command and telemetry.
    fn cycle(&mut self, view: &CycleView<'_>) -> anyhow::Result<()> {
        let Some(w) = self.writer.as_mut() else {
            return Ok(());
        };
        w.joint_state(view.state)?;
        w.torque_command(view.cycle.command())?;
        w.telemetry(view.cycle.telemetry())?;
        self.cycles += 1;
        Ok(())
    }

    fn finish(mut self) -> anyhow::Result<()> {
        let Some(w) = self.writer.take() else {
            return Ok(());
        };
        let mut stats = RecorderMsg::default();
        for s in [
            &mut stats.joint_state,
            &mut stats.torque_command,
            &mut stats.telemetry,
        ] {
            s.received = self.cycles;
            s.recorded = self.cycles;
        }
        let mut end = BTreeMap::new();
        end.insert("end".into(), "finished".into());
        w.finish(&stats, end)?;
        Ok(())
    }
}
