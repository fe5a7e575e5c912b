//! The `hcc-controller` process: start-up, the real-time loop, the logging
//! thread and shutdown.
//!
//! Start-up builds the robot model, the controller and every buffer from the
//! scenario TOML, opens the iceoryx2 services ([`hcc_msgs::ipc`]), prepares
//! the thread ([`hcc_rt`]) and waits for the first joint state. The loop
//! then runs [`ControlLoop::run_once`] inside an [`hcc_rtalloc::RtSection`] until
//! SIGINT/SIGTERM. A second, non-real-time thread logs the loop's counters
//! every 100 ms when they change.
//!
//! Logging is `hcc_rt::init_logging`'s: stderr, filtered by `RUST_LOG`
//! (default `info`), one line per event prefixed `hcc-controller:` (and
//! `warning:` / `error:` by level). Only start-up, shutdown and the logging thread log;
//! the real-time loop never does.

use std::ffi::OsString;
use std::path::{Path, PathBuf};
use std::process::ExitCode;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::time::{Duration, Instant};

use anyhow::{Context, Result};
use clap::Parser;
use hcc_config::Scenario;
use hcc_msgs::ServiceNames;
use hcc_msgs::ipc::{self, IpcNode, ScenarioPublisher, Services};
use iceoryx2::prelude::{LogLevel, SignalHandlingMode, set_log_level_from_env_or};
use tracing::{error, info, warn};

use crate::control_loop::{ControlLoop, LoopSettings, Outcome, Ports};
use crate::status::LoopStatus;
use hcc_cycle::CycleCounters;
use hcc_rt::{self as rt, RtReport, WaitStrategy};

/// Cycles after which the allocator counters are taken as the baseline.
const WARM_UP_CYCLES: u64 = 1_000;

/// Stack pre-faulted for the loop.
const PREFAULT_STACK_BYTES: usize = 512 * 1024;

/// Counters the log of changes leaves out: `cycles` changes every cycle,
/// `stale_events` every timeout while the peer is lost (logged as a loss).
const NOT_LOGGED: [&str; 2] = ["cycles", "stale_events"];

/// Command line of `hcc-controller`.
#[derive(Debug, Parser)]
#[command(
    name = "hcc-controller",
    version,
    about = "Hierarchical compliance controller daemon: answers every joint state with a torque command over iceoryx2."
)]
// The help texts name the scenario's TOML tables as [table] and placeholders as
// <name>: neither an intra-doc link nor HTML.
#[allow(rustdoc::broken_intra_doc_links, rustdoc::invalid_html_tags)]
pub struct Args {
    /// Scenario TOML (robot, hierarchy, gains, goals, [ipc], [controller_daemon]).
    pub config: PathBuf,
    /// IPC namespace and file prefix.
    #[command(flatten)]
    pub ipc: hcc_rt::IpcArgs,
    /// Wait strategy (overrides [controller_daemon].wait_strategy).
    #[arg(long, value_enum)]
    pub wait: Option<WaitStrategy>,
    /// The control thread's real-time set-up (over [controller_daemon]).
    #[command(flatten)]
    pub rt: hcc_rt::RtArgs,
    /// When stopping, write the loop's timing report (wake-up latency and
    /// compute time histograms, counters, real-time set-up obtained) as JSON here.
    #[arg(long)]
    pub stats: Option<PathBuf>,
    /// Publish telemetry for every N-th answered state only (default 1: every
    /// cycle). Setpoint answers and counters reach clients with the next
    /// sample; `hcc run`'s recorder needs every cycle.
    #[arg(long, default_value_t = 1, value_parser = clap::value_parser!(u32).range(1..=1000))]
    pub telemetry_every: u32,
    /// No cache warm-up (overrides [controller_daemon].warm_up): the hybrid
    /// wait no longer steps a copy of the law on the last state while it
    /// spins before the next one.
    #[arg(long)]
    pub no_warm_up: bool,
    /// No state for this long (ms) is a lost driver, reported in telemetry
    /// once per timeout (overrides [controller_daemon].stale_timeout_ms).
    /// `hcc run --lockstep` sets the simulator's lockstep timeout: there a
    /// driver waiting for the recorder is not lost.
    #[arg(long)]
    pub stale_timeout_ms: Option<f64>,
}

/// Parses `args` (program name first), runs the daemon, maps the result to
/// an exit code: 0 after a clean stop, 2 for a start-up error.
pub fn main_with_args(args: impl IntoIterator<Item = impl Into<OsString> + Clone>) -> ExitCode {
    hcc_rt::init_logging("hcc-controller");
    hcc_rt::run_main(args, run, |e| error!("{e:#}"))
}

/// Everything built at start-up.
struct Setup {
    scenario: Scenario,
    names: ServiceNames,
    file_prefix: Option<String>,
    settings: LoopSettings,
}

fn load(args: &Args) -> Result<Setup> {
    let scenario = Scenario::load(&args.config)?;
    scenario.check_cpu_core("controller_daemon", &rt::available_cores())?;
    let names =
        ServiceNames::new(args.ipc.namespace_or(&scenario.ipc.namespace)).context("--namespace")?;
    let file_prefix = args.ipc.file_prefix();
    let mut settings = LoopSettings::from_scenario(&scenario)?;
    if let Some(w) = args.wait {
        settings.wait = w;
    }
    settings.telemetry_every = args.telemetry_every;
    settings.warm_up &= !args.no_warm_up;
    if let Some(ms) = args.stale_timeout_ms {
        if !(ms.is_finite() && ms > 0.0) {
            anyhow::bail!("--stale-timeout-ms {ms} must be a positive number of milliseconds");
        }
        settings.stale_timeout_ns = (ms * 1e6).round() as u64;
    }
    Ok(Setup {
        scenario,
        names,
        file_prefix,
        settings,
    })
}

/// The iceoryx2 node, services and ports, dropped in that reverse order.
struct Ipc {
    ports: Ports,
    _services: Services,
    _node: IpcNode,
}

impl Ipc {
    /// Removes what dead processes left behind, then opens everything.
    fn open(setup: &Setup) -> Result<Ipc> {
        if let Some(line) = rt::cleanup_stale_resources(setup.file_prefix.as_deref()) {
            info!("{line}");
        }
        let node = ipc::create_node(
            ipc::CONTROLLER_NODE,
            SignalHandlingMode::Disabled,
            setup.file_prefix.as_deref(),
        )?;
        let services = Services::open(&node, &setup.names)?;
        let mut ports = Ports::open(&services)?;
        let doc = setup.scenario.document(setup.names.namespace().as_str());
        ports.scenario = Some(ScenarioPublisher::publish(&node, &setup.names, &doc)?);
        Ok(Ipc {
            ports,
            _services: services,
            _node: node,
        })
    }
}

/// The path-check thread's nice value: its rollouts give way to the
/// processes around the loop (a driver, a simulator, the recorder).
const PATH_CHECK_NICE: i32 = 10;

/// Runs the daemon until SIGINT/SIGTERM.
pub fn run(args: Args) -> Result<()> {
    let setup = load(&args)?;
    let scenario = &setup.scenario;
    let controller = hcc_cycle::controller_for(scenario)?;
    let mut control = ControlLoop::new(controller, setup.settings.clone())?;
    rt::install_stop_handler().context("installing the SIGINT/SIGTERM handlers")?;
    set_log_level_from_env_or(LogLevel::Warn);
    let ipc = Ipc::open(&setup)?;

    // The run-time paths' feasibility check, on a thread of its own started
    // before this thread turns real-time (it inherits no pinning or
    // priority), below everything else (nice PATH_CHECK_NICE).
    let done = Arc::new(AtomicBool::new(false));
    let checker = {
        let worker = control.check_paths_at_run_time();
        let done = done.clone();
        std::thread::Builder::new()
            .name("hcc-path-check".into())
            .spawn(move || {
                if let Err(e) = rt::lower_priority(PATH_CHECK_NICE) {
                    warn!("the path-check thread keeps its priority: {e}");
                }
                worker.run(&done)
            })
            .context("starting the path-check thread")?
    };

    let d = &scenario.controller_daemon;
    let rt_settings = args
        .rt
        .settings(d.cpu_core, d.sched_priority, d.mlock, PREFAULT_STACK_BYTES);
    let report = rt::prepare_rt_thread(&rt_settings);
    log_start(&setup, &report);

    let status = control.status();
    let baseline = Arc::new(AtomicU64::new(u64::MAX));
    let logger = {
        let (status, baseline, done) = (status.clone(), baseline.clone(), done.clone());
        std::thread::Builder::new()
            .name("hcc-controller-log".into())
            .spawn(move || log_loop(&status, &baseline, &done))
            .context("starting the logging thread")?
    };
    let started = Instant::now();
    control_loop(&mut control, &ipc.ports, &baseline);
    done.store(true, Ordering::Relaxed);
    let _ = logger.join();
    let _ = checker.join();
    let baseline = baseline.load(Ordering::Relaxed);
    log_stop(&status, baseline);
    if let Some(path) = &args.stats {
        let rt = report.obtained(&rt_settings);
        let allocs =
            (baseline != u64::MAX).then(|| torque_path_allocs(&status).saturating_sub(baseline));
        write_stats(
            path,
            &control,
            setup.settings.wait,
            rt,
            started.elapsed(),
            allocs,
        )?;
    }
    // The loop's loaned sample goes back before its publisher and node go.
    drop(control);
    drop(ipc);
    Ok(())
}

/// The real-time loop: [`ControlLoop::run_once`] until a stop is requested, inside
/// an [`hcc_rtalloc::RtSection`]; after [`WARM_UP_CYCLES`] answers, the
/// allocator's count of the torque path becomes the `baseline` of the
/// logging thread.
fn control_loop(control: &mut ControlLoop, ports: &Ports, baseline: &AtomicU64) {
    let _rt = hcc_rtalloc::RtSection::enter();
    let mut answered = 0u64;
    loop {
        match control.run_once(ports) {
            Outcome::Stop => break,
            Outcome::Answered(_) => {
                answered += 1;
                if answered == WARM_UP_CYCLES {
                    baseline.store(
                        torque_path_allocs(control.status().as_ref()),
                        Ordering::Relaxed,
                    );
                }
            }
            Outcome::Duplicate | Outcome::Stale => {}
        }
    }
}

/// The start-up report: what was obtained of the real-time set-up, and what runs.
fn log_start(setup: &Setup, report: &RtReport) {
    for w in &report.warnings {
        warn!("{w}");
    }
    if !hcc_rtalloc::pool_active() {
        warn!(
            "the real-time allocator is not installed; loop allocations go to the system allocator"
        );
    }
    let scenario = &setup.scenario;
    info!(
        "{} ({} joints, {} levels), namespace {:?}, wait {:?}, pinned {}, SCHED_FIFO {}, mlock {}; waiting for the first joint state on {:?}",
        scenario.name,
        scenario.model.nq(),
        scenario.levels().len(),
        setup.names.namespace().as_str(),
        setup.settings.wait,
        report.pinned,
        report.fifo,
        report.memory_locked,
        setup.names.joint_state(),
    );
}

/// System allocations of the real-time thread so far, less those of the
/// connection upkeep (made while waiting, not on the torque path).
fn torque_path_allocs(status: &LoopStatus) -> u64 {
    hcc_rtalloc::stats()
        .rt_system_allocs
        .saturating_sub(status.upkeep_system_allocs.load(Ordering::Relaxed))
}

/// The shutdown summary: every counter, the worst compute time, the
/// real-time thread's system allocations on the torque path after warm-up
/// and the connection upkeep.
fn log_stop(status: &LoopStatus, baseline: u64) {
    let c = status.loop_counters();
    let counters: Vec<String> = c
        .entries()
        .iter()
        .filter(|(name, _, _)| *name != "cycles")
        .map(|(name, _, value)| format!("{name} {value}"))
        .collect();
    let s = hcc_rtalloc::stats();
    let allocs = if baseline == u64::MAX {
        "n/a (no warm-up)".to_string()
    } else {
        torque_path_allocs(status)
            .saturating_sub(baseline)
            .to_string()
    };
    info!(
        "stopped after {} cycles: {}; max compute {:.1} µs; rt system allocations on the torque path after warm-up {allocs}, pool high-water {}; {}",
        c.telemetry.cycles,
        counters.join(", "),
        status.max_compute_ns.load(Ordering::Relaxed) as f64 / 1e3,
        s.pool_high_water,
        upkeep_line(status),
    );
}

/// `--stats`: the loop's timing report (histograms, every counter, the
/// real-time set-up obtained) as JSON.
fn write_stats(
    path: &Path,
    control: &ControlLoop,
    wait: WaitStrategy,
    rt: hcc_timing::RtObtained,
    run: Duration,
    torque_path_allocs: Option<u64>,
) -> Result<()> {
    let t = control.timings();
    let mut stats = hcc_timing::DaemonTimings {
        daemon: "hcc-controller".into(),
        wait: wait.name().into(),
        rt,
        run_s: run.as_secs_f64(),
        ..Default::default()
    };
    for (name, histogram) in t.named() {
        stats.figures.insert(name.into(), histogram.into());
    }
    for (name, _, value) in control.cycle().counters().entries() {
        stats.counters.insert(name.into(), value);
    }
    stats.counters.insert(
        "notifications_skipped".into(),
        control.notifications_skipped(),
    );
    stats.counters.insert("warm_ups".into(), control.warm_ups());
    let overlaps = control.warm_up_overlaps();
    stats
        .counters
        .insert("warm_up_overlaps".into(), overlaps.count);
    stats
        .counters
        .insert("warm_up_overlap_max_ns".into(), overlaps.max_ns);
    stats.counters.insert(
        "warm_up_last_lead_ns".into(),
        control.last_warm_up_lead_ns(),
    );
    let (preloaned, loan_failures) = control.preloaned_sends();
    stats
        .counters
        .insert("commands_in_preloaned_samples".into(), preloaned);
    stats
        .counters
        .insert("command_preloan_failures".into(), loan_failures);
    if let Some(allocs) = torque_path_allocs {
        stats
            .counters
            .insert("torque_path_system_allocs_after_warm_up".into(), allocs);
    }
    let upkeep = control.upkeep();
    for (name, value) in [
        ("connection_updates", upkeep.updates),
        ("connection_update_system_allocs", upkeep.system_allocs),
        ("connection_update_failures", upkeep.failures),
        ("connection_update_max_ns", upkeep.max_ns),
    ] {
        stats.counters.insert(name.into(), value);
    }
    stats
        .write_json(path)
        .context("--stats: writing the timing report")
}

/// The connection upkeep in words.
fn upkeep_line(status: &LoopStatus) -> String {
    format!(
        "peer connections made or dropped while waiting: {} (system allocations {}, longest {:.1} µs)",
        status.upkeep_updates.load(Ordering::Relaxed),
        status.upkeep_system_allocs.load(Ordering::Relaxed),
        status.upkeep_max_ns.load(Ordering::Relaxed) as f64 / 1e3,
    )
}

/// What the logging thread has reported so far.
struct Reported {
    connected: bool,
    peer_lost: bool,
    counters: CycleCounters,
    rt_allocs: u64,
    upkeep_updates: u64,
}

/// The logging thread: every 100 ms, report what changed.
fn log_loop(status: &LoopStatus, baseline: &AtomicU64, done: &AtomicBool) {
    let mut reported = Reported {
        connected: false,
        peer_lost: false,
        counters: status.loop_counters(),
        rt_allocs: 0,
        upkeep_updates: 0,
    };
    while !done.load(Ordering::Relaxed) {
        std::thread::sleep(Duration::from_millis(100));
        reported.peer(status);
        reported.counters(status.loop_counters());
        reported.rt_allocations(status, baseline.load(Ordering::Relaxed));
        reported.upkeep(status);
    }
}

impl Reported {
    /// The first state, a peer lost, a peer back.
    fn peer(&mut self, status: &LoopStatus) {
        if !self.connected && status.connected.load(Ordering::Relaxed) {
            self.connected = true;
            info!("receiving joint states; control running");
        }
        let lost = status.peer_lost.load(Ordering::Relaxed);
        if lost == self.peer_lost {
            return;
        }
        self.peer_lost = lost;
        let seq = status.last_state_seq.load(Ordering::Relaxed);
        if lost {
            let last = status.last_state_ns.load(Ordering::Relaxed);
            let at = status.peer_lost_at_ns.load(Ordering::Relaxed);
            warn!(
                "peer lost: no joint state for {:.1} ms after state seq {seq} (detected at {at} ns); still running, waiting for a driver",
                at.saturating_sub(last) as f64 / 1e6,
            );
        } else {
            info!("joint states are back (state seq {seq}); control resumed");
        }
    }

    /// Every counter that changed (but [`NOT_LOGGED`]): its total and the increase.
    fn counters(&mut self, now: CycleCounters) {
        let before = self.counters.values();
        for ((name, label, value), before) in now.entries().into_iter().zip(before) {
            if value != before && !NOT_LOGGED.contains(&name) {
                warn!("{label}: {value} (+{})", value.saturating_sub(before));
            }
        }
        self.counters = now;
    }

    /// System allocations of the real-time thread on the torque path after
    /// warm-up (`baseline`).
    fn rt_allocations(&mut self, status: &LoopStatus, baseline: u64) {
        if baseline == u64::MAX {
            return;
        }
        let allocs = torque_path_allocs(status).saturating_sub(baseline);
        if allocs != self.rt_allocs {
            warn!(
                "{allocs} system allocations on the real-time thread's torque path after warm-up"
            );
            self.rt_allocs = allocs;
        }
    }

    /// A peer connected or left (made while waiting, off the torque path).
    fn upkeep(&mut self, status: &LoopStatus) {
        let updates = status.upkeep_updates.load(Ordering::Relaxed);
        if updates != self.upkeep_updates {
            info!("{}", upkeep_line(status));
            self.upkeep_updates = updates;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_counters_left_out_of_the_log_exist() {
        let names = CycleCounters::default().entries().map(|e| e.0);
        for name in NOT_LOGGED {
            assert!(names.contains(&name), "{name} is not a counter: {names:?}");
        }
    }
}
