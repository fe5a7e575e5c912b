//! The `hcc-sim` process: the simulated robot driver ([`SimDriver`]) on the
//! hcc services, paced by an absolute 1 kHz clock (real-time mode) or by the
//! controller's answers (lockstep mode).
//!
//! **Real-time mode.** At tick k+1 (`clock_nanosleep(CLOCK_MONOTONIC,
//! TIMER_ABSTIME)` on t_0 + (k+1) T) the driver takes the newest command,
//! integrates [t_k, t_{k+1}] with the command that answered state k (or holds /
//! falls back, see [`crate::driver`]), then publishes state k+1 and notifies
//! `state_ready`. A tick more than 10 periods late re-anchors the clock
//! (counted as an overrun) instead of bursting.
//!
//! **Lockstep mode.** After publishing state k the driver waits (on
//! `command_ready`) for the command answering it, then integrates at once:
//! deterministic and faster than real time. Before the first command it
//! waits indefinitely, republishing state k every 20 ms so that a controller
//! that starts later receives it. Once commands flow, a command missing for
//! `--lockstep-timeout-ms` is a miss (dead controller): the driver holds and
//! then falls back like in real time, advancing one period per period of wall
//! time, until commands return.
//!
//! With `--duration S` the state at t = S is published with status `Stopped`
//! and the process exits 0; SIGINT/SIGTERM do the same at the current state.

use std::ffi::OsString;
use std::path::PathBuf;
use std::process::ExitCode;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::time::Duration;

use anyhow::{Context, Result};
use clap::Parser;
use hcc_config::{Scenario, SimMode};
use hcc_controller::rt::{self, RtSettings};
use hcc_msgs::ipc::{
    self, CommandSubscriber, EventListener, EventNotifier, LATEST_BUFFER, Services, StatePublisher,
};
use hcc_msgs::{JointState, ServiceNames, TorqueCommand, monotonic_now_ns};
use iceoryx2::prelude::{LogLevel, SignalHandlingMode, set_log_level_from_env_or};

use crate::driver::{Applied, SimDriver};

/// Republish period of the current state while waiting for the first command (lockstep).
const REPUBLISH_NS: u64 = 20_000_000;

/// Command line of `hcc-sim`.
#[derive(Debug, Parser)]
#[command(
    name = "hcc-sim",
    version,
    about = "Plant-simulator daemon: publishes joint states of the simulated robot and applies the controller's torque commands over iceoryx2."
)]
pub struct Args {
    /// Scenario TOML (robot, initial state, [simulation], [ipc], [sim_daemon]).
    pub config: PathBuf,
    /// IPC namespace (overrides [ipc].namespace).
    #[arg(long)]
    pub namespace: Option<String>,
    /// Prefix of the shared-memory files (default: the HCC_IPC_FILE_PREFIX
    /// environment variable, else iceoryx2's default). All peers must agree.
    #[arg(long)]
    pub file_prefix: Option<String>,
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
    /// SCHED_FIFO priority of the simulator thread (1..=99); default: normal scheduling.
    #[arg(long)]
    pub sched_priority: Option<i32>,
    /// Lock memory (mlockall).
    #[arg(long)]
    pub mlock: bool,
}

/// Parses `args` (program name first) and runs the daemon; 0 after a clean
/// stop, 2 for a start-up error, 1 for a failure while running.
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
            eprintln!("hcc-sim: error: {e:#}");
            ExitCode::from(2)
        }
    }
}

/// Counts of durations in 10 µs buckets up to 5 ms (allocation-free after construction).
struct Histogram {
    buckets: Vec<u64>,
    count: u64,
    max_ns: u64,
}

impl Histogram {
    const BUCKET_NS: u64 = 10_000;

    fn new() -> Histogram {
        Histogram {
            buckets: vec![0; 501],
            count: 0,
            max_ns: 0,
        }
    }

    fn record(&mut self, ns: u64) {
        let i = ((ns / Self::BUCKET_NS) as usize).min(self.buckets.len() - 1);
        self.buckets[i] += 1;
        self.count += 1;
        self.max_ns = self.max_ns.max(ns);
    }

    /// Upper bucket edge below which a fraction `p` of the samples lie, µs.
    fn percentile_us(&self, p: f64) -> f64 {
        let target = (p * self.count as f64).ceil() as u64;
        let mut seen = 0;
        for (i, c) in self.buckets.iter().enumerate() {
            seen += c;
            if seen >= target.max(1) {
                return ((i as u64 + 1) * Self::BUCKET_NS) as f64 / 1e3;
            }
        }
        self.max_ns as f64 / 1e3
    }

    fn summary(&self) -> String {
        if self.count == 0 {
            return "no samples".into();
        }
        format!(
            "p50 < {:.0} µs, p99 < {:.0} µs, p99.9 < {:.0} µs, max {:.1} µs ({} samples)",
            self.percentile_us(0.5),
            self.percentile_us(0.99),
            self.percentile_us(0.999),
            self.max_ns as f64 / 1e3,
            self.count
        )
    }
}

/// Counters shared with the logging thread.
#[derive(Default)]
struct Shared {
    missed: AtomicU64,
    fallback_cycles: AtomicU64,
    in_fallback: AtomicBool,
    has_command: AtomicBool,
    overruns: AtomicU64,
    rejected: AtomicU64,
}

/// The simulator's ports.
struct Ports {
    states: StatePublisher,
    state_ready: EventNotifier,
    commands: CommandSubscriber,
    command_ready: EventListener,
}

struct Loop<'a> {
    driver: SimDriver,
    ports: &'a Ports,
    newest: Option<TorqueCommand>,
    state: JointState,
    shared: &'a Shared,
    lateness: Histogram,
    round_trip: Histogram,
    overruns: u64,
}

impl Loop<'_> {
    fn publish(&mut self) {
        self.driver.write_state(&mut self.state, monotonic_now_ns());
        let _ = self.ports.states.send_copy(self.state);
        let _ = self.ports.state_ready.notify();
    }

    /// Drains the command queue into `newest`; true if the newest answers state k.
    fn drain(&mut self) -> bool {
        while let Ok(Some(c)) = self.ports.commands.receive() {
            self.newest = Some(*c);
        }
        let _ = self.ports.command_ready.try_wait(|_| {});
        self.newest
            .is_some_and(|c| c.state_seq == self.driver.k() && c.state_stamp_ns != 0)
    }

    fn advance(&mut self) -> Result<()> {
        let answered = self
            .newest
            .filter(|c| c.state_seq == self.driver.k())
            .map(|c| c.header.stamp_ns.saturating_sub(c.state_stamp_ns));
        let applied = self.driver.advance(self.newest.as_ref())?;
        if applied == Applied::Command
            && let Some(rtt) = answered
        {
            self.round_trip.record(rtt);
        }
        let c = self.driver.counters();
        self.shared
            .missed
            .store(c.missed_commands, Ordering::Relaxed);
        self.shared
            .fallback_cycles
            .store(c.fallback_cycles, Ordering::Relaxed);
        self.shared
            .rejected
            .store(c.rejected_commands, Ordering::Relaxed);
        self.shared
            .in_fallback
            .store(self.driver.in_fallback(), Ordering::Relaxed);
        self.shared
            .has_command
            .store(self.driver.has_command(), Ordering::Relaxed);
        Ok(())
    }

    fn run_realtime(&mut self) -> Result<()> {
        let period_ns = (self.driver.period_s() * 1e9).round() as u64;
        self.publish();
        let mut next = monotonic_now_ns() + period_ns;
        loop {
            rt::sleep_until_ns(next);
            let now = monotonic_now_ns();
            self.lateness.record(now.saturating_sub(next));
            if rt::stop_requested() {
                break;
            }
            self.drain();
            self.advance()?;
            if self.driver.finished() {
                break;
            }
            self.publish();
            next += period_ns;
            if now > next + 10 * period_ns {
                next = now + period_ns;
                self.overruns += 1;
                self.shared.overruns.store(self.overruns, Ordering::Relaxed);
            }
        }
        Ok(())
    }

    fn run_lockstep(&mut self, timeout_ns: u64) -> Result<()> {
        let period_ns = (self.driver.period_s() * 1e9).round() as u64;
        loop {
            if self.driver.finished() {
                break;
            }
            self.publish();
            let mut published = monotonic_now_ns();
            let deadline = if !self.driver.has_command() {
                u64::MAX
            } else if self.driver.in_fallback() {
                published + period_ns
            } else {
                published + timeout_ns
            };
            loop {
                if self.drain() || rt::stop_requested() {
                    break;
                }
                let now = monotonic_now_ns();
                if now >= deadline {
                    break;
                }
                if !self.driver.has_command() && now >= published + REPUBLISH_NS {
                    self.publish();
                    published = now;
                }
                let wait = deadline.min(published + REPUBLISH_NS).saturating_sub(now);
                let _ = self
                    .ports
                    .command_ready
                    .timed_wait(|_| {}, Duration::from_nanos(wait.clamp(1_000, 20_000_000)));
            }
            if rt::stop_requested() {
                break;
            }
            self.advance()?;
        }
        Ok(())
    }
}

fn log_loop(shared: &Shared, done: &AtomicBool) {
    let (mut missed, mut fallback, mut overruns, mut rejected) = (0, false, 0, 0);
    let mut connected = false;
    while !done.load(Ordering::Relaxed) {
        std::thread::sleep(Duration::from_millis(100));
        if !connected && shared.has_command.load(Ordering::Relaxed) {
            connected = true;
            eprintln!("hcc-sim: receiving torque commands");
        }
        let f = shared.in_fallback.load(Ordering::Relaxed);
        if f != fallback {
            fallback = f;
            if f {
                eprintln!(
                    "hcc-sim: no applicable torque command: fallback active (gravity held, joint damping)"
                );
            } else {
                eprintln!("hcc-sim: torque commands are back; fallback ended");
            }
        }
        let m = shared.missed.load(Ordering::Relaxed);
        if m != missed {
            eprintln!("hcc-sim: missed commands: {m} (+{})", m - missed);
            missed = m;
        }
        let o = shared.overruns.load(Ordering::Relaxed);
        if o != overruns {
            eprintln!("hcc-sim: clock overruns (re-anchored): {o}");
            overruns = o;
        }
        let r = shared.rejected.load(Ordering::Relaxed);
        if r != rejected {
            eprintln!("hcc-sim: rejected commands (invalid or gravity conflict): {r}");
            rejected = r;
        }
    }
}

/// Runs the daemon.
pub fn run(args: Args) -> Result<()> {
    let scenario = Scenario::load(&args.config)?;
    scenario.check_cpu_core("sim_daemon", &rt::available_cores())?;
    let namespace = args
        .namespace
        .clone()
        .unwrap_or_else(|| scenario.ipc.namespace.clone());
    let names = ServiceNames::new(&namespace).context("--namespace")?;
    let file_prefix = args.file_prefix.clone().or_else(ipc::file_prefix_from_env);
    let mode = if args.lockstep {
        SimMode::Lockstep
    } else if args.realtime {
        SimMode::Realtime
    } else {
        scenario.sim_daemon.mode
    };
    if !(args.lockstep_timeout_ms.is_finite() && args.lockstep_timeout_ms > 0.0) {
        anyhow::bail!(
            "--lockstep-timeout-ms {} must be positive",
            args.lockstep_timeout_ms
        );
    }
    if let Some(p) = args.sched_priority
        && !(1..=99).contains(&p)
    {
        anyhow::bail!("--sched-priority {p} must be in 1..=99");
    }
    let mut driver = SimDriver::new(&scenario)
        .map_err(|e| anyhow::anyhow!("{}: {e}", scenario.path.display()))?;
    if let Some(d) = args.duration {
        driver.set_duration(d)?;
    }
    rt::install_stop_handler().context("installing the SIGINT/SIGTERM handlers")?;
    set_log_level_from_env_or(LogLevel::Warn);

    if let Some(line) = rt::cleanup_stale_resources(file_prefix.as_deref()) {
        eprintln!("hcc-sim: {line}");
    }
    let node = ipc::create_node(
        "hcc-sim",
        SignalHandlingMode::Disabled,
        file_prefix.as_deref(),
    )?;
    let services = Services::open(&node, &names)?;
    let ports = Ports {
        states: services.joint_state_publisher()?,
        state_ready: services.state_ready_notifier()?,
        commands: services.torque_command_subscriber(LATEST_BUFFER)?,
        command_ready: services.command_ready_listener()?,
    };

    let report = rt::prepare_rt_thread(&RtSettings {
        cpu_core: scenario.sim_daemon.cpu_core,
        sched_priority: args.sched_priority,
        lock_memory: args.mlock,
        prefault_stack_bytes: 512 * 1024,
    });
    for w in &report.warnings {
        eprintln!("hcc-sim: warning: {w}");
    }
    eprintln!(
        "hcc-sim: {} ({} joints), {:?} mode, namespace {:?}, {}; publishing on {:?}",
        scenario.name,
        driver.model().nq(),
        mode,
        names.namespace().as_str(),
        match args.duration {
            Some(d) => format!("{d} s of simulated time"),
            None => "until SIGINT/SIGTERM".into(),
        },
        names.joint_state(),
    );

    let shared = Arc::new(Shared::default());
    let done = Arc::new(AtomicBool::new(false));
    let logger = {
        let (shared, done) = (shared.clone(), done.clone());
        std::thread::Builder::new()
            .name("hcc-sim-log".into())
            .spawn(move || log_loop(&shared, &done))
            .context("starting the logging thread")?
    };

    let mut lp = Loop {
        driver,
        ports: &ports,
        newest: None,
        state: JointState::zeroed(),
        shared: &shared,
        lateness: Histogram::new(),
        round_trip: Histogram::new(),
        overruns: 0,
    };
    let result = {
        let _rt = hcc_rtalloc::RtSection::enter();
        let timeout_ns = (args.lockstep_timeout_ms * 1e6) as u64;
        match mode {
            SimMode::Realtime => lp.run_realtime(),
            SimMode::Lockstep => lp.run_lockstep(timeout_ns),
        }
    };
    // The final state, status Stopped.
    lp.driver.set_stopped();
    lp.publish();
    done.store(true, Ordering::Relaxed);
    let _ = logger.join();
    let c = lp.driver.counters();
    eprintln!(
        "hcc-sim: stopped at t = {:.3} s (k = {}): {} commands applied, {} missed, {} fallback cycles, {} rejected, {} overruns",
        lp.driver.t(),
        lp.driver.k(),
        c.applied_commands,
        c.missed_commands,
        c.fallback_cycles,
        c.rejected_commands,
        lp.overruns
    );
    if mode == SimMode::Realtime {
        eprintln!("hcc-sim: tick lateness: {}", lp.lateness.summary());
    }
    eprintln!(
        "hcc-sim: state → command (controller stamp − state stamp): {}",
        lp.round_trip.summary()
    );
    drop(lp);
    drop(ports);
    drop(services);
    drop(node);
    result
}
