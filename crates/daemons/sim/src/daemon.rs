//! The `hcc-sim` process: the simulated robot driver ([`SimDriver`]) on the
//! hcc services, paced by an absolute 1 kHz clock (real-time mode) or by the
//! controller's answers (lockstep mode).
//!
//! **Real-time mode.** At tick k+1 (`clock_nanosleep(CLOCK_MONOTONIC,
//! TIMER_ABSTIME)` on t_0 + (k+1) T) the driver takes the newest command,
//! integrates [t_k, t_{k+1}] with the command that answered state k (or holds /
//! falls back, see [`hcc_plant::driver`]), then publishes state k+1 and notifies
//! `state_ready`. A tick more than 10 periods late re-anchors the clock
//! (counted as an overrun) instead of bursting. A late tick is caught up with
//! ticks back to back; a state published in one of them has less than its
//! command window before the next, and its miss, if it is missed, is counted
//! apart as well (`short_window_misses`): the simulator's lateness, not the
//! controller's.
//!
//! **Lockstep mode.** After publishing state k the driver waits (on
//! `command_ready`) for the command answering it, then integrates at once:
//! deterministic and faster than real time. Before the first command it
//! waits indefinitely, republishing state k every 20 ms so that a controller
//! that starts later receives it. Once commands flow, a command missing for
//! `--lockstep-timeout-ms` is a miss (dead controller): the driver holds and
//! then falls back like in real time, advancing one period per period of wall
//! time, until commands return. With `--lockstep-recorder` (as `hcc run`
//! starts it) state k also waits for the recorder to have taken state
//! k − 32 ([`crate::recorder_wait`]): nothing is lost when the recorder
//! stalls.
//!
//! With `--duration S` the state at t = S is published with status `Stopped`
//! and the process exits 0; SIGINT/SIGTERM do the same at the current state.
//!
//! The waits, sleeps, thread set-up and stop signal are those of `hcc-rt`
//! (`--wait event|hybrid` is [`WaitStrategy`]). Logging goes through
//! `tracing` to stderr (`RUST_LOG`, default `info`): the real-time thread only
//! stores counters into atomics ([`LoopStatus`]); a logging thread reports their
//! changes every 100 ms, and the summary is logged after the loop.

use std::ffi::OsString;
use std::path::PathBuf;
use std::process::ExitCode;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};

use anyhow::{Context, Result};
use clap::Parser;
use hcc_config::{Scenario, SimMode};
use hcc_msgs::ServiceNames;
use hcc_msgs::ipc::{self, Services};
use hcc_rt::{self as rt, WaitStrategy};
use iceoryx2::prelude::{LogLevel, SignalHandlingMode, set_log_level_from_env_or};

use hcc_plant::SimDriver;

use crate::recorder_wait::RecorderWait;
use crate::sim_loop::{Ports, SimLoop};
use crate::status::{LoopStatus, log_loop};

/// Command line of `hcc-sim`.
#[derive(Debug, Parser)]
#[command(
    name = "hcc-sim",
    version,
    about = "Plant-simulator daemon: publishes joint states of the simulated robot and applies the controller's torque commands over iceoryx2."
)]
// The help texts name the scenario's TOML tables as [table] and placeholders as
// <name>: neither an intra-doc link nor HTML.
#[allow(rustdoc::broken_intra_doc_links, rustdoc::invalid_html_tags)]
pub struct Args {
    /// Scenario TOML (robot, initial state, [simulation], [ipc], [sim_daemon]).
    pub config: PathBuf,
    /// IPC namespace and file prefix.
    #[command(flatten)]
    pub ipc: hcc_rt::IpcArgs,
    /// Lockstep mode (overrides [sim_daemon].mode).
    #[arg(long, conflicts_with = "realtime")]
    pub lockstep: bool,
    /// Real-time mode (overrides [sim_daemon].mode).
    #[arg(long)]
    pub realtime: bool,
    /// Stop after this much simulated time (s); default: run until SIGINT/SIGTERM.
    #[arg(long)]
    pub duration: Option<f64>,
    /// Lockstep: a command missing this long (ms) counts as a miss.
    #[arg(long, default_value_t = 100.0)]
    pub lockstep_timeout_ms: f64,
    /// Lockstep: run at most this many times faster than real time (a state
    /// at most every control period / this); default: as fast as the
    /// controller answers. Subscribers that are not in the lockstep (a
    /// recorder) then have their queues' length in real time divided by it
    /// to drain them, however the host stalls them.
    #[arg(long)]
    pub lockstep_max_speed: Option<f64>,
    /// Lockstep: wait for the recorder of `hcc run` (its progress service):
    /// state k is published once the recorder has taken state k − 32, so
    /// that a stalled recorder delays the run instead of losing samples. A
    /// recorder silent for --lockstep-timeout-ms is no longer waited for.
    #[arg(long)]
    pub lockstep_recorder: bool,
    /// The simulator thread's real-time set-up (over [sim_daemon]).
    #[command(flatten)]
    pub rt: hcc_rt::RtArgs,
    /// Real time: how the loop waits — `event`: sleep until each tick
    /// (clock_nanosleep) and block on `command_ready` for the answer;
    /// `hybrid`: sleep until shortly before the tick and spin to it, poll for
    /// the answer for a while before blocking.
    #[arg(long, value_enum, default_value_t = WaitStrategy::Event)]
    pub wait: WaitStrategy,
    /// Real time: wait for each answer by polling the `torque_command`
    /// service only (never blocking on `command_ready`), and say so in every
    /// state (`STATE_FLAG_DRIVER_POLLS_COMMANDS`), so that the controller
    /// skips the notification. Spins up to the answer's deadline: for a
    /// simulator on a core of its own.
    #[arg(long)]
    pub poll_commands: bool,
    /// When stopping, write the loop's timing report (tick lateness and
    /// state → command latency histograms, counters, real-time set-up
    /// obtained) as JSON here.
    #[arg(long)]
    pub stats: Option<PathBuf>,
}

/// Parses `args` (program name first) and runs the daemon; 0 after a clean
/// stop, 2 for an error (at start-up or while running).
pub fn main_with_args(args: impl IntoIterator<Item = impl Into<OsString> + Clone>) -> ExitCode {
    rt::init_logging("hcc-sim");
    hcc_rt::run_main(args, run, |e| tracing::error!("{e:#}"))
}

/// The pacing: `--lockstep` / `--realtime` over `[sim_daemon].mode`.
fn mode(args: &Args, scenario: &Scenario) -> SimMode {
    if args.lockstep {
        SimMode::Lockstep
    } else if args.realtime {
        SimMode::Realtime
    } else {
        scenario.sim_daemon.mode
    }
}

/// Refuses out-of-range options.
fn check_args(args: &Args) -> Result<()> {
    if !(args.lockstep_timeout_ms.is_finite() && args.lockstep_timeout_ms > 0.0) {
        anyhow::bail!(
            "--lockstep-timeout-ms {} must be positive",
            args.lockstep_timeout_ms
        );
    }
    if let Some(x) = args.lockstep_max_speed
        && !(x.is_finite() && x > 0.0)
    {
        anyhow::bail!("--lockstep-max-speed {x} must be positive");
    }
    Ok(())
}

/// Runs the daemon.
pub fn run(args: Args) -> Result<()> {
    let scenario = Scenario::load(&args.config)?;
    scenario.check_cpu_core("sim_daemon", &rt::available_cores())?;
    let names =
        ServiceNames::new(args.ipc.namespace_or(&scenario.ipc.namespace)).context("--namespace")?;
    let mode = mode(&args, &scenario);
    if args.lockstep_recorder && mode != SimMode::Lockstep {
        anyhow::bail!("--lockstep-recorder needs lockstep mode (--lockstep)");
    }
    let file_prefix = args.ipc.file_prefix();
    check_args(&args)?;
    let mut driver = SimDriver::new(&scenario)
        .map_err(|e| anyhow::anyhow!("{}: {e}", scenario.path.display()))?;
    if let Some(d) = args.duration {
        driver.set_duration(d)?;
    }
    rt::install_stop_handler().context("installing the SIGINT/SIGTERM handlers")?;
    set_log_level_from_env_or(LogLevel::Warn);

    if let Some(line) = rt::cleanup_stale_resources(file_prefix.as_deref()) {
        tracing::info!("{line}");
    }
    let node = ipc::create_node(
        "hcc-sim",
        SignalHandlingMode::Disabled,
        file_prefix.as_deref(),
    )?;
    let services = Services::open(&node, &names)?;
    let ports = Ports::open(&services)?;

    let rt_settings = args
        .rt
        .settings(scenario.sim_daemon.cpu_core, None, false, 512 * 1024);
    let report = rt::prepare_rt_thread(&rt_settings);
    for w in &report.warnings {
        tracing::warn!("{w}");
    }
    tracing::info!(
        "{} ({} joints), {:?} mode, wait {}, namespace {:?}, {}; publishing on {:?}",
        scenario.name,
        driver.model().nq(),
        mode,
        args.wait,
        names.namespace().as_str(),
        match args.duration {
            Some(d) => format!("{d} s of simulated time"),
            None => "until SIGINT/SIGTERM".into(),
        },
        names.joint_state(),
    );

    let status = Arc::new(LoopStatus::default());
    let done = Arc::new(AtomicBool::new(false));
    let logger = {
        let (status, done) = (status.clone(), done.clone());
        std::thread::Builder::new()
            .name("hcc-sim-log".into())
            .spawn(move || log_loop(&status, &done))
            .context("starting the logging thread")?
    };

    let recorder = if args.lockstep_recorder {
        Some(RecorderWait::open(&node, &names)?)
    } else {
        None
    };
    let mut lp = SimLoop::new(driver, &ports, &status, args.wait)
        .with_recorder(recorder)
        // Lockstep blocks on `command_ready` (it has no deadline to spin to).
        .with_polling(args.poll_commands && mode == SimMode::Realtime);
    let started = std::time::Instant::now();
    let result = {
        let _rt = hcc_rtalloc::RtSection::enter();
        let timeout_ns = (args.lockstep_timeout_ms * 1e6) as u64;
        match mode {
            SimMode::Realtime => lp.run_realtime(),
            SimMode::Lockstep => lp.run_lockstep(timeout_ns, args.lockstep_max_speed),
        }
    };
    // The final state, status Stopped.
    lp.driver.set_stopped();
    lp.publish();
    done.store(true, Ordering::Relaxed);
    let _ = logger.join();
    lp.log_summary(mode);
    if let Some(path) = &args.stats {
        lp.timings(
            args.wait,
            report.obtained(&rt_settings),
            started.elapsed().as_secs_f64(),
        )
        .write_json(path)
        .context("--stats: writing the timing report")?;
    }
    drop(lp);
    drop(ports);
    drop(services);
    drop(node);
    result
}
