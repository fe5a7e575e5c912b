//! The `hcc-controller` process: start-up, the real-time loop, the logging
//! thread and shutdown.
//!
//! Start-up builds the robot model, the controller and every buffer from the
//! scenario TOML, opens the iceoryx2 services ([`hcc_msgs::ipc`]), prepares
//! the thread ([`crate::rt`]) and waits for the first joint state. The loop
//! then runs [`Cycle::run_once`] inside an [`hcc_rtalloc::RtSection`] until
//! SIGINT/SIGTERM. A second, non-real-time thread logs the loop's counters
//! every 100 ms when they change.

use std::ffi::OsString;
use std::path::PathBuf;
use std::process::ExitCode;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::time::Duration;

use anyhow::{Context, Result};
use clap::{Parser, ValueEnum};
use hcc_config::{Scenario, WaitStrategy};
use hcc_control::Controller;
use hcc_msgs::ServiceNames;
use hcc_msgs::ipc::{self, Services};
use iceoryx2::prelude::{LogLevel, SignalHandlingMode, set_log_level_from_env_or};

use crate::cycle::{Cycle, CycleSettings, Outcome, Ports, Status};
use crate::rt::{self, RtSettings};

/// Cycles after which the allocator counters are taken as the baseline.
const WARM_UP_CYCLES: u64 = 1_000;

/// Stack pre-faulted for the loop.
const PREFAULT_STACK_BYTES: usize = 512 * 1024;

/// Wait strategy on the command line.
#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum WaitArg {
    /// Block on the state_ready event.
    Event,
    /// Sleep until shortly before the expected state, then poll.
    Hybrid,
}

/// Command line of `hcc-controller`.
#[derive(Debug, Parser)]
#[command(
    name = "hcc-controller",
    version,
    about = "Hierarchical compliance controller daemon: answers every joint state with a torque command over iceoryx2."
)]
pub struct Args {
    /// Scenario TOML (robot, hierarchy, gains, goals, [ipc], [controller_daemon]).
    pub config: PathBuf,
    /// IPC namespace (overrides [ipc].namespace).
    #[arg(long)]
    pub namespace: Option<String>,
    /// Prefix of the shared-memory files (default: the HCC_IPC_FILE_PREFIX
    /// environment variable, else iceoryx2's default). All peers must agree.
    #[arg(long)]
    pub file_prefix: Option<String>,
    /// Wait strategy (overrides [controller_daemon].wait_strategy).
    #[arg(long, value_enum)]
    pub wait: Option<WaitArg>,
    /// CPU core of the control thread (overrides [controller_daemon].cpu_core).
    #[arg(long)]
    pub cpu_core: Option<usize>,
    /// SCHED_FIFO priority 1..=99 of the control thread (overrides
    /// [controller_daemon].sched_priority).
    #[arg(long, value_parser = clap::value_parser!(i32).range(1..=99))]
    pub sched_priority: Option<i32>,
    /// Lock memory (mlockall), as [controller_daemon].mlock = true.
    #[arg(long)]
    pub mlock: bool,
    /// When stopping, write the loop's timing report (wake-up latency and
    /// compute time histograms, counters, real-time set-up obtained) as JSON here.
    #[arg(long)]
    pub stats: Option<PathBuf>,
}

/// Parses `args` (program name first), runs the daemon, maps the result to
/// an exit code: 0 after a clean stop, 2 for a start-up error.
pub fn main_with_args<I, T>(args: I) -> ExitCode
where
    I: IntoIterator<Item = T>,
    T: Into<OsString> + Clone,
{
    let args = match Args::try_parse_from(args) {
        Ok(a) => a,
        Err(e) => {
            let _ = e.print();
            return if e.use_stderr() {
                ExitCode::from(2)
            } else {
                ExitCode::SUCCESS
            };
        }
    };
    match run(args) {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("hcc-controller: error: {e:#}");
            ExitCode::from(2)
        }
    }
}

/// Everything built at start-up.
struct Setup {
    scenario: Scenario,
    names: ServiceNames,
    file_prefix: Option<String>,
    settings: CycleSettings,
}

fn load(args: &Args) -> Result<Setup> {
    let scenario = Scenario::load(&args.config)?;
    scenario.check_cpu_core("controller_daemon", &rt::available_cores())?;
    let namespace = args
        .namespace
        .clone()
        .unwrap_or_else(|| scenario.ipc.namespace.clone());
    let names = ServiceNames::new(&namespace).context("--namespace")?;
    let file_prefix = args.file_prefix.clone().or_else(ipc::file_prefix_from_env);
    let mut settings = CycleSettings::from_scenario(&scenario);
    if let Some(w) = args.wait {
        settings.wait = match w {
            WaitArg::Event => WaitStrategy::Event,
            WaitArg::Hybrid => WaitStrategy::Hybrid,
        };
    }
    Ok(Setup {
        scenario,
        names,
        file_prefix,
        settings,
    })
}

/// Runs the daemon until SIGINT/SIGTERM.
pub fn run(args: Args) -> Result<()> {
    let setup = load(&args)?;
    let scenario = &setup.scenario;
    let controller = Controller::new(&scenario.model, scenario.spec.clone(), &scenario.q0)
        .map_err(|e| anyhow::anyhow!("{}: controller: {e}", scenario.path.display()))?;
    let mut cycle = Cycle::new(controller, setup.settings.clone())?;
    rt::install_stop_handler().context("installing the SIGINT/SIGTERM handlers")?;
    set_log_level_from_env_or(LogLevel::Warn);

    if let Some(line) = rt::cleanup_stale_resources(setup.file_prefix.as_deref()) {
        eprintln!("hcc-controller: {line}");
    }
    let node = ipc::create_node(
        "hcc-controller",
        SignalHandlingMode::Disabled,
        setup.file_prefix.as_deref(),
    )?;
    let services = Services::open(&node, &setup.names)?;
    let ports = Ports::open(&services)?;

    let d = &scenario.controller_daemon;
    let rt_settings = RtSettings {
        cpu_core: args.cpu_core.or(d.cpu_core),
        sched_priority: args.sched_priority.or(d.sched_priority),
        lock_memory: args.mlock || d.mlock,
        prefault_stack_bytes: PREFAULT_STACK_BYTES,
    };
    let report = rt::prepare_rt_thread(&rt_settings);
    for w in &report.warnings {
        eprintln!("hcc-controller: warning: {w}");
    }
    if !hcc_rtalloc::pool_active() {
        eprintln!(
            "hcc-controller: warning: the real-time allocator is not installed; loop allocations go to the system allocator"
        );
    }
    eprintln!(
        "hcc-controller: {} ({} joints, {} levels), namespace {:?}, wait {:?}, pinned {}, SCHED_FIFO {}, mlock {}; waiting for the first joint state on {:?}",
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

    let status = cycle.status();
    let baseline = Arc::new(AtomicU64::new(u64::MAX));
    let done = Arc::new(AtomicBool::new(false));
    let logger = {
        let (status, baseline, done) = (status.clone(), baseline.clone(), done.clone());
        std::thread::Builder::new()
            .name("hcc-controller-log".into())
            .spawn(move || log_loop(&status, &baseline, &done))
            .context("starting the logging thread")?
    };

    let mut cycles = 0u64;
    let started = std::time::Instant::now();
    {
        let _rt = hcc_rtalloc::RtSection::enter();
        loop {
            match cycle.run_once(&ports) {
                Outcome::Stop => break,
                Outcome::Answered(_) => {
                    cycles += 1;
                    if cycles == WARM_UP_CYCLES {
                        baseline.store(hcc_rtalloc::stats().rt_system_allocs, Ordering::Relaxed);
                    }
                }
                Outcome::Duplicate | Outcome::Stale => {}
            }
        }
    }
    done.store(true, Ordering::Relaxed);
    let _ = logger.join();
    let c = status.counters();
    let s = hcc_rtalloc::stats();
    let base = baseline.load(Ordering::Relaxed);
    eprintln!(
        "hcc-controller: stopped after {} cycles: invalid {}, saturated {}, singular {}, stale {}, peer lost {}, missed states {}, sequence errors {}, send failures {}, max compute {:.1} µs; rt system allocations after warm-up {}, pool high-water {}",
        c.cycles,
        c.invalid_states,
        c.saturations,
        c.singular_cycles,
        c.stale_events,
        c.peer_lost_events,
        c.missed_states,
        c.sequence_errors,
        c.send_failures,
        status.max_compute_ns.load(Ordering::Relaxed) as f64 / 1e3,
        if base == u64::MAX {
            "n/a (no warm-up)".to_string()
        } else {
            s.rt_system_allocs.saturating_sub(base).to_string()
        },
        s.pool_high_water,
    );
    if let Some(path) = &args.stats {
        let t = cycle.timings();
        let mut stats = hcc_timing::DaemonTimings {
            daemon: "hcc-controller".into(),
            wait: wait_name(setup.settings.wait).into(),
            rt: report.obtained(&rt_settings),
            run_s: started.elapsed().as_secs_f64(),
            ..Default::default()
        };
        stats
            .figures
            .insert("wakeup_latency".into(), (&t.wakeup).into());
        stats
            .figures
            .insert("compute_time".into(), (&t.compute).into());
        stats
            .figures
            .insert("control_law_time".into(), (&t.step).into());
        for (name, value) in [
            ("cycles", c.cycles),
            ("invalid_states", c.invalid_states),
            ("saturations", c.saturations),
            ("singular_cycles", c.singular_cycles),
            ("stale_events", c.stale_events),
            ("peer_lost_events", c.peer_lost_events),
            ("missed_states", c.missed_states),
            ("sequence_errors", c.sequence_errors),
            ("send_failures", c.send_failures),
        ] {
            stats.counters.insert(name.into(), value);
        }
        stats
            .write_json(path)
            .context("--stats: writing the timing report")?;
    }
    drop(ports);
    drop(services);
    drop(node);
    Ok(())
}

/// The wait strategy's name on the command line.
pub fn wait_name(w: WaitStrategy) -> &'static str {
    match w {
        WaitStrategy::Event => "event",
        WaitStrategy::Hybrid => "hybrid",
    }
}

/// The logging thread: every 100 ms, report what changed.
fn log_loop(status: &Status, baseline: &AtomicU64, done: &AtomicBool) {
    let mut last = status.counters();
    let mut last_lost = false;
    let mut connected = false;
    let mut last_rt_allocs = 0u64;
    let mut last_numerical = 0u64;
    let mut last_restarts = 0u64;
    while !done.load(Ordering::Relaxed) {
        std::thread::sleep(Duration::from_millis(100));
        if !connected && status.connected.load(Ordering::Relaxed) {
            connected = true;
            eprintln!("hcc-controller: receiving joint states; control running");
        }
        let lost = status.peer_lost.load(Ordering::Relaxed);
        if lost != last_lost {
            last_lost = lost;
            if lost {
                let last = status.last_state_ns.load(Ordering::Relaxed);
                let at = status.peer_lost_at_ns.load(Ordering::Relaxed);
                eprintln!(
                    "hcc-controller: peer lost: no joint state for {:.1} ms after state seq {} (detected at {at} ns); still running, waiting for a driver",
                    at.saturating_sub(last) as f64 / 1e6,
                    status.last_state_seq.load(Ordering::Relaxed),
                );
            } else {
                eprintln!(
                    "hcc-controller: joint states are back (state seq {}); control resumed",
                    status.last_state_seq.load(Ordering::Relaxed)
                );
            }
        }
        let c = status.counters();
        let changes = [
            (
                "invalid states (answered with SafeHold)",
                last.invalid_states,
                c.invalid_states,
            ),
            ("saturated cycles", last.saturations, c.saturations),
            ("peer losses", last.peer_lost_events, c.peer_lost_events),
            ("singular cycles", last.singular_cycles, c.singular_cycles),
            ("missed states", last.missed_states, c.missed_states),
            ("sequence errors", last.sequence_errors, c.sequence_errors),
            ("send failures", last.send_failures, c.send_failures),
        ];
        for (what, before, now) in changes {
            if now != before {
                eprintln!("hcc-controller: {what}: {now} (+{})", now - before);
            }
        }
        last = c;
        let numerical = status.numerical_failures.load(Ordering::Relaxed);
        if numerical != last_numerical {
            eprintln!(
                "hcc-controller: numerical failures of the control law (answered with SafeHold): {numerical}"
            );
            last_numerical = numerical;
        }
        let restarts = status.peer_restarts.load(Ordering::Relaxed);
        if restarts != last_restarts {
            eprintln!("hcc-controller: new peer detected; sequence checker reset ({restarts})");
            last_restarts = restarts;
        }
        let base = baseline.load(Ordering::Relaxed);
        if base != u64::MAX {
            let allocs = hcc_rtalloc::stats().rt_system_allocs.saturating_sub(base);
            if allocs != last_rt_allocs {
                eprintln!(
                    "hcc-controller: warning: {allocs} system allocations on the real-time thread after warm-up"
                );
                last_rt_allocs = allocs;
            }
        }
    }
}
