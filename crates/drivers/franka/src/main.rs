//! `hcc-franka CONFIG --robot-ip IP [--namespace NS]`: drives a Franka FR3 or
//! Panda for the hcc controller over the Franka Control Interface (see the
//! library docs and `docs/franka.md`).
//!
//! `hcc-franka --robot-ip IP --save-urdf FILE` writes the URDF the robot
//! serves (FCI protocol 10, `GetRobotModel`) and exits.
//!
//! Exit codes: 0 after a clean stop (SIGINT/SIGTERM, `--duration`, a Stop
//! command), 3 when the motion ended on its own (no applicable command within
//! the fallback timeout, or a robot error) and `--recover` was not given, 2
//! for an error (start-up, a lost connection, a failed recovery).

use std::path::PathBuf;
use std::process::ExitCode;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::time::Duration;

use anyhow::{Context, Result, anyhow, bail};
use clap::Parser;
use franka::{RealtimeConfig, Robot};
use hcc_config::Scenario;
use hcc_franka::cycle::{FrankaCycle, FrankaSettings, Step};
use hcc_franka::faults::{Fault, FaultCounts, FaultKind};
use hcc_msgs::ServiceNames;
use hcc_msgs::driver::StopReason;
use hcc_msgs::ipc::{self, DriverPorts, Services};
use iceoryx2::prelude::{LogLevel, SignalHandlingMode, set_log_level_from_env_or};

#[global_allocator]
static ALLOCATOR: hcc_rtalloc::RtAllocator = hcc_rtalloc::RtAllocator::new();

/// Command line of `hcc-franka`.
#[derive(Debug, Parser)]
#[command(
    name = "hcc-franka",
    version,
    about = "Drives a Franka FR3 or Panda for the hcc controller over the Franka Control Interface (torque control at 1 kHz)."
)]
// The help texts name the scenario's TOML tables as [table].
#[allow(rustdoc::broken_intra_doc_links)]
struct Args {
    /// Scenario TOML (7 joints, [robot] gravity_compensation = false, [franka], [ipc]).
    #[arg(required_unless_present = "save_urdf")]
    config: Option<PathBuf>,
    /// The robot's FCI address (its control box), optionally with ":port".
    #[arg(long)]
    robot_ip: String,
    /// IPC namespace and file prefix.
    #[command(flatten)]
    ipc: hcc_rt::IpcArgs,
    /// The loop thread's real-time set-up (memory is always locked;
    /// franka-rs raises the thread to its highest SCHED_FIFO priority
    /// itself, `--sched-priority` sets another).
    #[command(flatten)]
    rt: hcc_rt::RtArgs,
    /// Write the URDF the robot serves (FCI protocol 10) to this file and exit.
    #[arg(long, conflicts_with = "config")]
    save_urdf: Option<PathBuf>,
    /// After a robot error: run automatic error recovery; after any end of a
    /// motion: wait for a controller's answer and start a new motion.
    #[arg(long)]
    recover: bool,
    /// Do not require a real-time kernel and SCHED_FIFO (simulated robots).
    #[arg(long)]
    no_realtime: bool,
    /// Stop (ramp down, finish the motion) after this many seconds.
    #[arg(long)]
    duration: Option<f64>,
    /// When stopping, write the timing report (latency histograms, counters) as JSON here.
    #[arg(long)]
    stats: Option<PathBuf>,
}

/// How the run ended.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Outcome {
    /// A signal, `--duration` or a Stop command.
    Clean,
    /// The motion ended on its own and `--recover` was not given.
    Stopped,
}

fn main() -> ExitCode {
    hcc_rt::init_logging("hcc-franka");
    let args = match hcc_rt::parse_args::<Args, _, _>(std::env::args_os()) {
        Ok(a) => a,
        Err(code) => return code,
    };
    match run(&args) {
        Ok(Outcome::Clean) => ExitCode::SUCCESS,
        Ok(Outcome::Stopped) => ExitCode::from(3),
        Err(e) => {
            tracing::error!("{e:#}");
            ExitCode::from(2)
        }
    }
}

/// Connects to the robot (FCI protocol 10, else 5) from the calling thread.
fn connect(args: &Args) -> Result<Robot> {
    let realtime = if args.no_realtime {
        RealtimeConfig::Ignore
    } else {
        RealtimeConfig::Enforce
    };
    let robot = Robot::new(&args.robot_ip, realtime).map_err(|e| {
        anyhow!("connecting to the robot at {}: {e}", args.robot_ip).context(match e {
            franka::FrankaError::Realtime(_) => {
                "a real robot needs a real-time kernel and SCHED_FIFO; --no-realtime for simulators"
            }
            _ => "is FCI enabled in Desk, the brakes open and the address right?",
        })
    })?;
    let (protocol, arm) = match robot.fci_version() {
        franka::FciVersion::V10 => (10, "FR3"),
        franka::FciVersion::V5 => (5, "Panda/FER"),
    };
    tracing::info!(
        "connected to {} (FCI protocol {protocol}: {arm}, server version {})",
        args.robot_ip,
        robot.server_version()
    );
    Ok(robot)
}

/// `--save-urdf`: the robot's own model.
fn save_urdf(args: &Args, path: &PathBuf) -> Result<()> {
    let robot = connect(args)?;
    let urdf = robot.robot_model().map_err(|e| {
        anyhow!("{e} (only an FR3, FCI protocol 10, serves its URDF; a Panda's model is config/robots/panda)")
    })?;
    std::fs::write(path, &urdf).with_context(|| format!("writing {}", path.display()))?;
    tracing::info!(
        "wrote the robot's URDF ({} bytes) to {}",
        urdf.len(),
        path.display()
    );
    Ok(())
}

/// The scenario must describe a Franka the way the driver drives it.
fn check_scenario(s: &Scenario) -> Result<()> {
    if s.model.nq() != hcc_franka::guard::JOINTS {
        bail!(
            "{}: the robot model has {} joints; a Franka arm has 7",
            s.path.display(),
            s.model.nq()
        );
    }
    if s.spec.gravity_compensation {
        bail!(
            "{}: a Franka adds the gravity torque itself; set [robot] gravity_compensation = false",
            s.path.display()
        );
    }
    Ok(())
}

/// The collision thresholds of `[franka]`.
fn set_collision_behavior(robot: &Robot, f: &hcc_config::franka::Franka) -> Result<()> {
    let c = &f.collision;
    robot
        .set_collision_behavior(
            c.lower_torque_thresholds_acceleration,
            c.upper_torque_thresholds_acceleration,
            c.lower_torque_thresholds_nominal,
            c.upper_torque_thresholds_nominal,
            c.lower_force_thresholds_acceleration,
            c.upper_force_thresholds_acceleration,
            c.lower_force_thresholds_nominal,
            c.upper_force_thresholds_nominal,
        )
        .map_err(|e| anyhow!("the robot refused the collision thresholds of [franka]: {e}"))
}

fn run(args: &Args) -> Result<Outcome> {
    if let Some(path) = &args.save_urdf {
        save_urdf(args, path)?;
        return Ok(Outcome::Clean);
    }
    let config = args.config.as_ref().context("a scenario is required")?;
    let scenario = Scenario::load(config)?;
    check_scenario(&scenario)?;
    if let Some(d) = args.duration
        && !(d.is_finite() && d > 0.0)
    {
        bail!("--duration {d} must be positive");
    }
    let names =
        ServiceNames::new(args.ipc.namespace_or(&scenario.ipc.namespace)).context("--namespace")?;
    let file_prefix = args.ipc.file_prefix();
    hcc_rt::install_stop_handler().context("installing the SIGINT/SIGTERM handlers")?;
    set_log_level_from_env_or(LogLevel::Warn);
    let node = ipc::create_node(
        "hcc-franka",
        SignalHandlingMode::Disabled,
        file_prefix.as_deref(),
    )?;
    let services = Services::open(&node, &names)?;
    let ports = DriverPorts::open(&services)?;

    let robot = connect(args)?;
    set_collision_behavior(&robot, &scenario.franka)?;
    // On the thread that runs the loop (the one franka-rs connected from).
    let report = hcc_rt::prepare_rt_thread(&args.rt.settings(None, None, true, 512 * 1024));
    for w in &report.warnings {
        tracing::warn!("{w}");
    }
    let memory_locked = report.memory_locked;
    tracing::info!("{}: publishing on {:?}", scenario.name, names.joint_state());
    let mut cycle = FrankaCycle::new(FrankaSettings::from_config(&scenario.franka), &ports);
    let started = std::time::Instant::now();
    let deadline = args
        .duration
        .map(|d| hcc_msgs::monotonic_now_ns() + (d * 1e9) as u64);
    let mut faults = FaultCounts::default();
    let shared = Arc::new(Shared::default());
    let done = Arc::new(AtomicBool::new(false));
    let logger = spawn_logger(&shared, &done)?;
    let result = session(&robot, &mut cycle, args, deadline, &mut faults, &shared);
    done.store(true, Ordering::Relaxed);
    let _ = logger.join();
    log_summary(&cycle, &faults);
    if let Some(path) = &args.stats {
        stats(
            &cycle,
            &faults,
            memory_locked,
            started.elapsed().as_secs_f64(),
        )
        .write_json(path)
        .context("--stats: writing the timing report")?;
    }
    result
}

/// Whether the driver stops now (a signal, or `--duration` over).
fn stop_now(deadline: Option<u64>) -> bool {
    hcc_rt::stop_requested() || deadline.is_some_and(|d| hcc_msgs::monotonic_now_ns() >= d)
}

/// Motions until a clean stop, the end without `--recover`, or an error.
fn session(
    robot: &Robot,
    cycle: &mut FrankaCycle,
    args: &Args,
    deadline: Option<u64>,
    faults: &mut FaultCounts,
    shared: &Shared,
) -> Result<Outcome> {
    loop {
        cycle.begin_motion();
        shared.motions.fetch_add(1, Ordering::Relaxed);
        let end = {
            let _rt = hcc_rtalloc::RtSection::enter();
            run_motion(robot, cycle, deadline, shared)
        };
        let aborted = match end {
            Ok(StopReason::Requested) => return Ok(Outcome::Clean),
            Ok(StopReason::Commanded) => {
                tracing::info!("the controller commanded a stop: motion finished");
                return Ok(Outcome::Clean);
            }
            Ok(StopReason::FallbackTimeout) => {
                tracing::warn!(
                    "no applicable command within the fallback timeout: torque ramped down, motion finished"
                );
                false
            }
            Err(e) => {
                let fault = Fault::from_error(&e);
                cycle.abort_motion();
                faults.add(&fault);
                tracing::error!("{}", fault.line());
                if fault.kind != FaultKind::Aborted {
                    return Err(anyhow!("{}", fault.line()));
                }
                true
            }
        };
        if !args.recover {
            return Ok(Outcome::Stopped);
        }
        if aborted {
            robot
                .automatic_error_recovery()
                .map_err(|e| anyhow!("automatic error recovery failed: {e}"))?;
            tracing::info!("automatic error recovery done");
        }
        if !wait_for_controller(robot, cycle, deadline)? {
            return Ok(Outcome::Clean);
        }
        tracing::info!("a controller answers: starting a new motion");
    }
}

/// One torque motion, cycle after cycle, until it ends.
fn run_motion(
    robot: &Robot,
    cycle: &mut FrankaCycle,
    deadline: Option<u64>,
    shared: &Shared,
) -> franka::FrankaResult<StopReason> {
    let mut control = robot.start_torque_control()?;
    loop {
        match cycle.step(&mut control, stop_now(deadline))? {
            Step::Running => shared.update(cycle),
            Step::Finished(reason) => return Ok(reason),
        }
    }
}

/// Between motions: publishes the robot's states (status Stopped) until a
/// controller answers one; false on a stop.
fn wait_for_controller(
    robot: &Robot,
    cycle: &mut FrankaCycle,
    deadline: Option<u64>,
) -> Result<bool> {
    tracing::info!("waiting for a controller to answer the robot's states");
    while !stop_now(deadline) {
        let state = robot
            .read_once()
            .map_err(|e| anyhow!("reading the robot's state: {e}"))?;
        if cycle.idle_step(&state) {
            return Ok(true);
        }
    }
    Ok(false)
}

/// What the logging thread reports, stored by the loop.
#[derive(Default)]
struct Shared {
    motions: AtomicU64,
    status: AtomicU64,
    missed: AtomicU64,
    rejected: AtomicU64,
    guard_limited: AtomicU64,
    guard_rate_limited: AtomicU64,
    applied: AtomicU64,
}

impl Shared {
    fn update(&self, c: &FrankaCycle) {
        let r = c.rejections();
        let g = c.guard_counts();
        let store = |a: &AtomicU64, v: u64| a.store(v, Ordering::Relaxed);
        store(&self.status, u64::from(c.in_fallback()));
        store(&self.missed, c.missed_commands());
        store(
            &self.rejected,
            r.invalid + r.gravity_conflict + r.future + r.too_late,
        );
        store(&self.guard_limited, g.limited);
        store(&self.guard_rate_limited, g.rate_limited);
        store(&self.applied, c.counts().applied);
    }
}

fn spawn_logger(
    shared: &Arc<Shared>,
    done: &Arc<AtomicBool>,
) -> Result<std::thread::JoinHandle<()>> {
    let (shared, done) = (shared.clone(), done.clone());
    std::thread::Builder::new()
        .name("hcc-franka-log".into())
        .spawn(move || log_loop(&shared, &done))
        .context("starting the logging thread")
}

/// Reports the loop's transitions and counters every 100 ms, until `done`.
fn log_loop(shared: &Shared, done: &AtomicBool) {
    let mut last = [0u64; 6];
    let mut connected = false;
    while !done.load(Ordering::Relaxed) {
        std::thread::sleep(Duration::from_millis(100));
        let get = |a: &AtomicU64| a.load(Ordering::Relaxed);
        let now = [
            get(&shared.status),
            get(&shared.missed),
            get(&shared.rejected),
            get(&shared.guard_limited),
            get(&shared.guard_rate_limited),
            get(&shared.motions),
        ];
        if !connected && get(&shared.applied) > 0 {
            connected = true;
            tracing::info!("applying torque commands");
        }
        if now[0] != last[0] {
            if now[0] == 1 {
                tracing::warn!("no applicable torque command: holding, then damping (fallback)");
            } else {
                tracing::info!("torque commands are back; fallback ended");
            }
        }
        let labels = [
            "",
            "missed commands",
            "rejected commands",
            "torque-limited cycles (guard)",
            "rate-limited cycles (guard)",
            "motions started",
        ];
        for k in 1..5 {
            if now[k] != last[k] {
                tracing::warn!("{}: {} (+{})", labels[k], now[k], now[k] - last[k]);
            }
        }
        last = now;
    }
}

fn log_summary(cycle: &FrankaCycle, faults: &FaultCounts) {
    let c = cycle.counts();
    let g = cycle.guard_counts();
    let r = cycle.rejections();
    tracing::info!(
        "{} cycles: {} applied, {} held, {} fallback, {} waiting, {} stopping; missed {}, rejected {} invalid {} gravity {} future {} too late; guard: {} limited, {} rate-limited (largest clip {:.3} N·m), {} non-finite; {} robot states skipped; {} motions aborted by the robot; system allocations in the loop after warm-up: {}",
        c.cycles,
        c.applied,
        c.held,
        c.fallback,
        c.waiting,
        c.stopping,
        cycle.missed_commands(),
        r.invalid,
        r.gravity_conflict,
        r.future,
        r.too_late,
        g.limited,
        g.rate_limited,
        g.max_clipped_step,
        g.non_finite,
        c.states_skipped,
        faults.aborted_motions(),
        c.loop_system_allocs,
    );
    for (name, h) in cycle.timings().named() {
        tracing::info!("{name}: {}", h.summary().line_us());
    }
}

/// The `--stats` report.
fn stats(
    cycle: &FrankaCycle,
    faults: &FaultCounts,
    memory_locked: bool,
    run_s: f64,
) -> hcc_timing::DaemonTimings {
    let c = cycle.counts();
    let g = cycle.guard_counts();
    let r = cycle.rejections();
    let mut stats = hcc_timing::DaemonTimings {
        daemon: "hcc-franka".into(),
        wait: "event".into(),
        rt: hcc_timing::RtObtained {
            memory_locked,
            ..Default::default()
        },
        run_s,
        ..Default::default()
    };
    for (name, h) in cycle.timings().named() {
        stats.figures.insert(name.into(), h.into());
    }
    let upkeep = cycle.upkeep();
    for (name, value) in [
        ("motions", c.motions),
        ("cycles", c.cycles),
        ("applied_commands", c.applied),
        ("held_cycles", c.held),
        ("fallback_torque_cycles", c.fallback),
        ("waiting_cycles", c.waiting),
        ("stopping_cycles", c.stopping),
        ("missed_commands", cycle.missed_commands()),
        ("fallback_cycles", cycle.fallback_cycles()),
        ("rejected_old", r.old),
        ("rejected_invalid", r.invalid),
        ("rejected_gravity_conflict", r.gravity_conflict),
        ("rejected_future", r.future),
        ("rejected_too_late", r.too_late),
        ("guard_non_finite", g.non_finite),
        ("guard_limited", g.limited),
        ("guard_rate_limited", g.rate_limited),
        (
            "guard_max_clipped_step_mnm",
            (g.max_clipped_step * 1e3).round() as u64,
        ),
        (
            "max_torque_step_written_mnm",
            (g.max_step_written * 1e3).ceil() as u64,
        ),
        ("states_skipped", c.states_skipped),
        ("bad_states", c.bad_states),
        ("idle_states", c.idle_states),
        ("min_success_permille", c.min_success_permille),
        ("aborted_motions", faults.aborted_motions()),
        ("loop_system_allocs", c.loop_system_allocs),
        ("upkeep_allocs", upkeep.allocs),
    ] {
        stats.counters.insert(name.into(), value);
    }
    for (name, count) in faults.entries() {
        stats.counters.insert(format!("robot_error.{name}"), count);
    }
    stats
}
