//! The pair: `hcc-sim` (real time) on one core and `hcc-controller` on the
//! other, each writing its loop's HDR histograms and counters (`--stats`),
//! and the simulator's counts of answered and missed cycles.

use anyhow::{Context, bail};
use hcc_msgs::ipc;
use hcc_msgs::{Namespace, ServiceNames};
use hcc_timing::DaemonTimings;
use iceoryx2::prelude::SignalHandlingMode;
use std::path::Path;
use std::time::{Duration, Instant};

use super::floor::FloorCore;
use super::plan::JitterArgs;
use crate::daemons::{
    Daemon, TERMINATE_GRACE, daemon_path, describe_status, interrupted,
    wait_until_controller_listens,
};

/// The pair's figures, read from the daemons' timing reports.
pub(super) struct Pair {
    pub(super) sim: DaemonTimings,
    pub(super) controller: DaemonTimings,
    pub(super) run_s: f64,
}

/// The command lines of the pair: (simulator, controller).
pub(super) fn pair_args(
    args: &JitterArgs,
    fifo: Option<i32>,
    namespace: &Namespace,
    sim_stats: &Path,
    controller_stats: &Path,
) -> (Vec<String>, Vec<String>) {
    let config = args.config.display().to_string();
    let mut common = vec![
        "--namespace".to_string(),
        namespace.to_string(),
        "--wait".into(),
        args.wait.name().into(),
        "--mlock".into(),
    ];
    if let Some(p) = fifo {
        common.extend(["--sched-priority".into(), p.to_string()]);
    }
    let mut controller_args = vec![config.clone()];
    controller_args.extend(common.iter().cloned());
    controller_args.extend([
        "--cpu-core".into(),
        args.controller_core.to_string(),
        "--stats".into(),
        controller_stats.display().to_string(),
        "--telemetry-every".into(),
        args.telemetry_every.to_string(),
    ]);
    if args.no_warm_up {
        controller_args.push("--no-warm-up".into());
    }
    let mut sim_args = vec![config];
    sim_args.extend(common);
    sim_args.extend([
        "--realtime".into(),
        "--duration".into(),
        format!("{:?}", args.duration),
        "--cpu-core".into(),
        args.sim_core.to_string(),
        "--stats".into(),
        sim_stats.display().to_string(),
    ]);
    if args.poll_commands {
        sim_args.push("--poll-commands".into());
    }
    (sim_args, controller_args)
}

/// Waits until the simulator has finished its run; returns the wall time, s.
pub(super) fn await_pair(
    args: &JitterArgs,
    sim: &mut Daemon,
    controller: &mut Daemon,
) -> anyhow::Result<f64> {
    let started = Instant::now();
    let mut next_progress = started + Duration::from_secs(5);
    // The simulated time runs with the wall clock; allow for start-up and overruns.
    let limit = Duration::from_secs_f64(args.duration * 1.5 + 30.0);
    loop {
        if let Some(s) = sim.poll() {
            if s.success() {
                return Ok(started.elapsed().as_secs_f64());
            }
            bail!(
                "hcc-sim (pid {}) failed with {}; its stderr ends with:\n{}",
                sim.pid(),
                describe_status(s),
                sim.stderr_tail()
            );
        }
        if let Some(s) = controller.poll() {
            bail!(
                "hcc-controller (pid {}) exited with {} during the measurement; its stderr ends with:\n{}",
                controller.pid(),
                describe_status(s),
                controller.stderr_tail()
            );
        }
        if interrupted() {
            sim.terminate(TERMINATE_GRACE);
            controller.terminate(TERMINATE_GRACE);
            bail!("interrupted; both daemons stopped");
        }
        if started.elapsed() > limit {
            bail!(
                "hcc-sim did not finish its {} s within {} s; its stderr ends with:\n{}",
                args.duration,
                limit.as_secs(),
                sim.stderr_tail()
            );
        }
        let now = Instant::now();
        if now >= next_progress {
            if !args.quiet {
                eprintln!(
                    "hcc jitter: pair {:.0} / {} s",
                    started.elapsed().as_secs_f64(),
                    args.duration
                );
            }
            next_progress += Duration::from_secs(5);
        }
        std::thread::sleep(Duration::from_millis(50));
    }
}

pub(super) fn run_pair(
    args: &JitterArgs,
    fifo: Option<i32>,
    sim_stats: &Path,
    controller_stats: &Path,
) -> anyhow::Result<Pair> {
    let namespace = match &args.namespace {
        Some(ns) => Namespace::new(ns).context("--namespace")?,
        None => Namespace::unique("hcc_jitter")?,
    };
    let file_prefix = args.file_prefix.clone().or_else(ipc::file_prefix_from_env);
    ipc::config(file_prefix.as_deref()).context("--file-prefix")?;
    let names = ServiceNames::for_namespace(namespace.clone());
    let (sim_args, controller_args) =
        pair_args(args, fifo, &namespace, sim_stats, controller_stats);
    let _ = std::fs::remove_file(sim_stats);
    let _ = std::fs::remove_file(controller_stats);

    let node = ipc::create_node(
        "hcc-jitter-probe",
        SignalHandlingMode::Disabled,
        file_prefix.as_deref(),
    )?;
    let mut controller = Daemon::spawn(
        "hcc-controller",
        &daemon_path("hcc-controller")?,
        &controller_args,
        file_prefix.as_deref(),
    )?;
    wait_until_controller_listens(&mut controller, &node, &names, 0)?;
    drop(node);
    let mut sim = Daemon::spawn(
        "hcc-sim",
        &daemon_path("hcc-sim")?,
        &sim_args,
        file_prefix.as_deref(),
    )?;
    let run_s = await_pair(args, &mut sim, &mut controller)?;
    // The controller answers the simulator's last state, then stops on SIGTERM
    // and writes its report.
    std::thread::sleep(Duration::from_millis(100));
    let status = controller.terminate(TERMINATE_GRACE);
    let clean = status.is_some_and(|s| s.success());
    if !clean {
        bail!(
            "hcc-controller did not stop cleanly ({}); its stderr ends with:\n{}",
            status.map_or("still running".into(), describe_status),
            controller.stderr_tail()
        );
    }
    let sim = DaemonTimings::read_json(sim_stats).context("the simulator's timing report")?;
    let controller =
        DaemonTimings::read_json(controller_stats).context("the controller's timing report")?;
    Ok(Pair {
        sim,
        controller,
        run_s,
    })
}

/// The simulator's counts: every period after the first command is answered or missed.
pub(super) struct Counts {
    pub(super) periods: u64,
    pub(super) waiting: u64,
    pub(super) stopped: u64,
    pub(super) received: u64,
    pub(super) missed: u64,
    /// Missed commands of states the simulator gave less than their command
    /// window (its own tick was late: the machine's lateness on its core).
    pub(super) short_window: u64,
    pub(super) cycles: u64,
    pub(super) consistent: bool,
    /// Late cycles and cycles of the floor on the controller's core.
    pub(super) floor_late: u64,
    pub(super) floor_cycles: u64,
}

impl Counts {
    pub(super) fn new(sim: &DaemonTimings, controller_floor: Option<&FloorCore>) -> Counts {
        let periods = sim.counter("periods");
        let waiting = sim.counter("waiting_for_controller");
        let stopped = sim.counter("stopped_periods");
        let received = sim.counter("applied_commands");
        let missed = sim.counter("missed_commands");
        let cycles = periods.saturating_sub(waiting + stopped);
        Counts {
            periods,
            waiting,
            stopped,
            received,
            missed,
            short_window: sim.counter("short_window_misses").min(missed),
            cycles,
            consistent: cycles == received + missed,
            floor_late: controller_floor.map_or(0, |f| f.late_cycles),
            floor_cycles: controller_floor.map_or(0, |f| f.lateness.count()),
        }
    }
}
