//! `hcc simulate CONFIG --out DIR`: the closed loop in one process (controller
//! sampled at the control rate, torque held, plant integrated with RK4), then
//! trajectory.csv, metrics.json and plots in DIR and a short summary on stdout.
//! The scenario's `[[setpoint]]` entries are applied at their cycles.
//!
//! Each cycle is also written into `DIR/run.mcap` in the layout of `hcc run`
//! and `hcc record` (a joint state numbered k and stamped t_k = k T, the
//! command and the telemetry of the law), so that one reader (`hcc plot
//! FILE.mcap`, `hcc export`, Foxglove, PlotJuggler) handles simulated and
//! recorded runs alike. The tables of `hcc simulate` are computed in process,
//! as the reference the derivation from a recording is tested against.

use anyhow::Context;
use hcc_config::Scenario;
use hcc_control::Controller;
use hcc_controller::schedule::Schedule;
use hcc_msgs::{
    COMMAND_FLAG_GRAVITY_INCLUDED, CommandMode, DriverStatus, JointState, MAX_LEVELS, MAX_TASK_DIM,
    Telemetry, TorqueCommand,
};
use hcc_plant::SimError;
use hcc_plant::closed_loop::{self, Commands, ControlLaw, HierarchicalLaw};
use hcc_record::mcap_log::{McapWriter, RecorderMsg, RunInfo};
use hcc_report::{Metrics, RunDescription, RunWriter, Trajectory};
use nalgebra::DVector;
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
    let recording = args.out.join(crate::run_cmd::RECORDING_FILE);
    let mut log = SimLog::create(&recording, &scenario)?;
    let result = closed_loop::simulate_law_observed(
        &scenario,
        scheduled_law(&scenario)?,
        &mut |k, _t, q, qd, law| {
            log.cycle(k, q, qd, law)
                .map_err(|e| SimError::Invalid(format!("{}: {e:#}", recording.display())))
        },
    );
    let run = result.with_context(|| format!("simulation of {} failed", args.config.display()))?;
    log.finish()?;
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

/// The recording of an in-process run: the messages the daemons would have
/// exchanged, cycle by cycle.
struct SimLog {
    writer: Option<McapWriter>,
    period_ns: u64,
    cycles: u64,
    n: usize,
    dims: Vec<usize>,
    gravity: bool,
    last_k: usize,
    state: JointState,
    command: TorqueCommand,
    telemetry: Box<Telemetry>,
}

impl SimLog {
    fn create(path: &Path, scenario: &Scenario) -> anyhow::Result<SimLog> {
        let s = &scenario.simulation;
        let (unix, _) = hcc_record::mcap_log::clock_pair();
        let mut run =
            crate::capture::run_metadata("hcc simulate", &scenario.ipc.namespace, (unix, 0));
        run.insert("mode".into(), "in-process".into());
        run.insert("duration_s".into(), format!("{:?}", s.duration_s));
        run.insert("control_rate_hz".into(), s.control_rate_hz.to_string());
        let info = RunInfo {
            run,
            scenario: RunInfo::describe_scenario(scenario),
            machine: crate::capture::machine_metadata(),
        };
        // Stamps are simulated time (t_k = k T from 0), shown from the start's Unix time.
        let writer = McapWriter::create(path, &info, (unix, 0))?;
        let n = scenario.model.nq();
        let dims = scenario.task_dims();
        let mut telemetry = Box::new(Telemetry::zeroed());
        telemetry.set_shape(n, &dims)?;
        let mut state = JointState::zeroed();
        state.set_n_joints(n)?;
        let mut command = TorqueCommand::zeroed();
        command.set_n_joints(n)?;
        let gravity = scenario.spec.gravity_compensation;
        if gravity {
            command.flags = COMMAND_FLAG_GRAVITY_INCLUDED;
        }
        telemetry.flags = command.flags;
        Ok(SimLog {
            writer: Some(writer),
            period_ns: (1e9 / s.control_rate_hz).round() as u64,
            cycles: (s.duration_s * s.control_rate_hz).round() as u64,
            n,
            dims,
            gravity,
            last_k: 0,
            state,
            command,
            telemetry,
        })
    }

    /// Records cycle `k`: its state, and the law's command and telemetry.
    fn cycle(
        &mut self,
        k: usize,
        q: &DVector<f64>,
        qd: &DVector<f64>,
        law: &HierarchicalLaw,
    ) -> anyhow::Result<()> {
        let Some(w) = self.writer.as_mut() else {
            return Ok(());
        };
        self.last_k = k;
        let stamp = k as u64 * self.period_ns;
        let (s, c, t) = (&mut self.state, &mut self.command, &mut *self.telemetry);
        s.header.seq = k as u64;
        s.header.stamp_ns = stamp;
        s.status = if k as u64 == self.cycles {
            DriverStatus::Stopped.code()
        } else {
            DriverStatus::Ok.code()
        };
        s.set_q(q.as_slice())?;
        s.set_qd(qd.as_slice())?;
        if !self.gravity {
            s.flags = hcc_msgs::STATE_FLAG_DRIVER_GRAVITY_COMPENSATION;
        }
        w.joint_state(s)?;

        let out = law.controller().output();
        let mode = if out.any_singular {
            CommandMode::Singular
        } else {
            CommandMode::Normal
        };
        c.header.seq = k as u64 + 1;
        c.header.stamp_ns = stamp;
        c.state_seq = k as u64;
        c.state_stamp_ns = stamp;
        c.mode = mode.code();
        c.set_tau(law.tau().as_slice())?;
        w.torque_command(c)?;

        let n = self.n;
        t.header.seq = k as u64 + 1;
        t.header.stamp_ns = stamp;
        t.state_seq = k as u64;
        t.command_seq = c.header.seq;
        t.mode = mode.code();
        t.tau[..n].copy_from_slice(law.tau().as_slice());
        t.tau_mu[..n].copy_from_slice(law.tau_mu().as_slice());
        if self.gravity {
            t.tau_gravity[..n].copy_from_slice(out.gravity.as_slice());
        }
        t.p_mu = law.p_mu();
        t.singular_levels = 0;
        for (i, &m) in self.dims.iter().enumerate().take(MAX_LEVELS) {
            t.tau_level[i][..n].copy_from_slice(law.level_torque(i).as_slice());
            t.task_error[i][..m].copy_from_slice(law.task_error(i).as_slice());
            t.storage[i] = law.level_energy(i);
            t.min_singular_value[i] = out
                .conditioning
                .get(i)
                .map_or(f64::NAN, |c| c.max(0.0).sqrt());
            if out.singular.get(i).copied().unwrap_or(false) {
                t.singular_levels |= 1 << i;
            }
            if let Some(target) = law.controller().level_target(i) {
                let m = m.min(MAX_TASK_DIM);
                t.goal[i][..m].copy_from_slice(&target.goal[..m]);
                for a in 0..m {
                    t.stiffness_diag[i][a] = target.stiffness[(a, a)];
                    t.damping_diag[i][a] = target.damping[(a, a)];
                }
                t.transition_progress[i] = 1.0;
            }
        }
        t.counters.cycles = k as u64 + 1;
        w.telemetry(t)?;
        Ok(())
    }

    fn finish(mut self) -> anyhow::Result<()> {
        let Some(w) = self.writer.take() else {
            return Ok(());
        };
        let cycles = self.last_k as u64 + 1;
        let mut stats = RecorderMsg::default();
        for s in [
            &mut stats.joint_state,
            &mut stats.torque_command,
            &mut stats.telemetry,
        ] {
            s.received = cycles;
            s.recorded = cycles;
        }
        let mut end = BTreeMap::new();
        end.insert("end".into(), "finished".into());
        w.finish(&stats, end)?;
        Ok(())
    }
}
