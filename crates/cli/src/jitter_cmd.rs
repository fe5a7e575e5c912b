//! `hcc jitter [CONFIG] [--duration S] [--out DIR] [--wait event|hybrid] [--load]`:
//! how late is each cycle, and how much of that is the machine and how much
//! the software?
//!
//! 1. **Floor.** Half of it before the pair and half after it (one
//!    measurement of the machine around the pair): a bare periodic thread at
//!    the control rate on each of the two cores (pinned, `SCHED_FIFO` when permitted, timer slack 1 ns, the
//!    same wait strategy as the daemons: `event` sleeps to each deadline with
//!    `clock_nanosleep(TIMER_ABSTIME)`, `hybrid` sleeps until
//!    [`rt::HYBRID_LEAD_NS`] before it and spins) — no IPC, no work. Its
//!    lateness is what the machine alone costs.
//! 2. **Pair.** `hcc-sim` (real time) pinned to one core and `hcc-controller`
//!    to the other, both `SCHED_FIFO` and `mlockall` when permitted, for the
//!    duration. Each records HDR histograms in its loop (fixed bounds, no
//!    allocation) and writes them when it stops (`--stats`): the simulator's
//!    tick lateness and the state → command latency (state published → its
//!    answer received at the simulator), the controller's wake-up latency
//!    (state published → start of the computation) and compute time, and the
//!    counters (missed commands, fallbacks, …).
//!
//! It prints a table (min, p50, p90, p99, p99.9, p99.99, max of each figure,
//! the floor beside it and the ratio) and writes `DIR/jitter.json` (the same
//! numbers, the quantile curves and the run's settings: kernel, CPU, the
//! scheduling actually obtained, wait strategy, durations, steal time) and
//! `DIR/jitter.png` (latency vs percentile, floor dashed). While it measures,
//! `/dev/cpu_dma_latency` is held at 0 µs when the process may open it (as
//! cyclictest does). `--load` runs a busy thread at normal priority on each
//! core during both measurements.
//!
//! On a small virtual machine the maximum belongs to the host (stalls of
//! several ms, visible as steal time); judge by p99 and p99.9, and by misses
//! beyond those the floor shows. A miss of a state the simulator published
//! late — less than its command window before the tick that judged it, as
//! when it catches up after a stall of its own core — is the simulator's
//! lateness: counted apart (`missed_after_late_tick`) and not charged to the
//! controller in the verdict.

use anyhow::{Context, bail};
use hcc_config::Scenario;
use hcc_control::Controller;
use hcc_msgs::ipc;
use hcc_msgs::{Namespace, ServiceNames, monotonic_now_ns};
use hcc_report::{PercentileCurve, plot_percentiles};
use hcc_rt::{self as rt, RtSettings};
use hcc_timing::machine::{CpuDmaLatency, CpuTimes, MachineInfo};
use hcc_timing::{DaemonTimings, Figure, LatencyHistogram, LatencySummary, RtObtained};
use iceoryx2::prelude::SignalHandlingMode;
use serde_json::{Value, json};
use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, Instant};
use tracing::warn;

use crate::daemons::{
    Daemon, TERMINATE_GRACE, daemon_path, describe_status, install_signal_handlers, interrupted,
    wait_until_controller_listens,
};
use crate::run_cmd::DEFAULT_CONFIG;

/// The floor thread and the simulator count a cycle as late when it wakes
/// later than this part of the period (the simulator's command window).
const LATE_FRACTION: f64 = 0.8;

/// Default floor measurement, s (at most the pair's duration).
const DEFAULT_FLOOR_S: f64 = 10.0;

/// Wait strategy of both daemons and of the floor threads.
type Wait = hcc_rt::WaitStrategy;

#[derive(clap::Args, Debug)]
pub struct JitterArgs {
    /// Scenario TOML (default: the paper's simulation #1; after convergence
    /// the controller holds the goal).
    #[arg(default_value = DEFAULT_CONFIG)]
    pub config: PathBuf,
    /// Duration of the measurement of the pair, s.
    #[arg(long, default_value_t = 60.0)]
    pub duration: f64,
    /// Duration of the floor measurement, s, half of it before the pair and
    /// half after it (default: 10 s, at most --duration).
    #[arg(long)]
    pub floor_duration: Option<f64>,
    /// Output directory.
    #[arg(long, default_value = "out/jitter")]
    pub out: PathBuf,
    /// Wait strategy of the daemons and of the floor threads.
    #[arg(long, value_enum, default_value_t = Wait::Hybrid)]
    pub wait: Wait,
    /// Run a CPU load at normal priority on both cores during the measurements.
    #[arg(long)]
    pub load: bool,
    /// Core of the simulator (and of the first floor thread).
    #[arg(long, default_value_t = 0)]
    pub sim_core: usize,
    /// Core of the controller (and of the second floor thread).
    #[arg(long, default_value_t = 1)]
    pub controller_core: usize,
    /// SCHED_FIFO priority of the daemons and floor threads (when permitted).
    #[arg(long, default_value_t = 80, value_parser = clap::value_parser!(i32).range(1..=99))]
    pub priority: i32,
    /// Normal scheduling instead of SCHED_FIFO.
    #[arg(long)]
    pub no_fifo: bool,
    /// IPC namespace (default: a unique one).
    #[arg(long)]
    pub namespace: Option<String>,
    /// iceoryx2 file prefix shared with the daemons (default: HCC_IPC_FILE_PREFIX, else iceoryx2's).
    #[arg(long)]
    pub file_prefix: Option<String>,
    /// The simulator polls for its answers and flags its states so
    /// (`STATE_FLAG_DRIVER_POLLS_COMMANDS`): the controller sends no
    /// `command_ready` notification.
    #[arg(long)]
    pub poll_commands: bool,
    /// The controller publishes telemetry for every N-th answered state.
    #[arg(long, default_value_t = 1, value_parser = clap::value_parser!(u32).range(1..=1000))]
    pub telemetry_every: u32,
    /// The controller does not warm its caches with a copy of the law while
    /// it spins before each state (`hcc-controller --no-warm-up`; the
    /// scenario's `[controller_daemon] warm_up` otherwise).
    #[arg(long)]
    pub no_warm_up: bool,
    /// Skip the PNG plot.
    #[arg(long)]
    pub no_plot: bool,
    /// No progress lines on stderr.
    #[arg(long)]
    pub quiet: bool,
}

/// What one floor thread measured.
struct FloorCore {
    core: usize,
    rt: RtObtained,
    lateness: LatencyHistogram,
    late_cycles: u64,
}

/// The real-time settings of a measuring thread of `hcc jitter` (a floor
/// thread, the law's reference): pinned to `core`, SCHED_FIFO `fifo` when
/// permitted, its stack prefaulted, memory not locked (the daemons lock
/// theirs).
fn measuring_thread(core: usize, fifo: Option<i32>) -> RtSettings {
    RtSettings {
        cpu_core: Some(core),
        sched_priority: fifo,
        lock_memory: false,
        prefault_stack_bytes: 256 * 1024,
    }
}

/// Bare periodic threads, one per core, all with the same deadlines.
fn measure_floor(
    cores: &[usize],
    fifo: Option<i32>,
    wait: Wait,
    period_ns: u64,
    duration_s: f64,
) -> anyhow::Result<Vec<FloorCore>> {
    let cycles = (duration_s * 1e9 / period_ns as f64).round().max(1.0) as u64;
    let late_ns = (period_ns as f64 * LATE_FRACTION) as u64;
    let start_ns = monotonic_now_ns() + 50_000_000;
    let handles: Vec<_> = cores
        .iter()
        .map(|&core| {
            std::thread::Builder::new()
                .name(format!("hcc-floor-{core}"))
                .spawn(move || {
                    let settings = measuring_thread(core, fifo);
                    let report = rt::prepare_rt_thread(&settings);
                    let mut lateness = LatencyHistogram::new();
                    let mut late_cycles = 0;
                    rt::sleep_until_ns(start_ns);
                    for k in 1..=cycles {
                        let deadline = start_ns + k * period_ns;
                        wait.sleep_until(deadline);
                        let late = monotonic_now_ns().saturating_sub(deadline);
                        lateness.record(late);
                        late_cycles += u64::from(late > late_ns);
                        if interrupted() {
                            break;
                        }
                    }
                    FloorCore {
                        core,
                        rt: report.obtained(&settings),
                        lateness,
                        late_cycles,
                    }
                })
        })
        .collect::<Result<_, _>>()
        .context("starting the floor threads")?;
    handles
        .into_iter()
        .map(|h| {
            h.join()
                .map_err(|_| anyhow::anyhow!("a floor thread panicked"))
        })
        .collect()
}

/// Untimed steps before the law's back-to-back reference is timed.
const LAW_WARM_UP_STEPS: usize = 200;
/// Timed steps of the law's back-to-back reference, per floor half.
const LAW_STEPS: usize = 2_000;

/// The scenario's control law stepped back to back on the controller's core:
/// what one step costs on this machine at this moment with its caches warm
/// (the step benchmark's "back to back", measured in the same run as the
/// pair). The law's time in the loop is read against it: their ratio is
/// what the idle between two states and the machine's neighbours add.
struct LawReference {
    core: usize,
    steps: LatencyHistogram,
}

/// Steps the scenario's law [`LAW_WARM_UP_STEPS`] + [`LAW_STEPS`] times back
/// to back in a thread pinned to `core` (SCHED_FIFO `fifo` when permitted),
/// along a small joint trajectory around the scenario's q0, timing each of the
/// last [`LAW_STEPS`] (a step that fails is not timed).
fn measure_law(
    scenario: &Scenario,
    core: usize,
    fifo: Option<i32>,
) -> anyhow::Result<LawReference> {
    let mut controller = Controller::new(&scenario.model, scenario.spec.clone(), &scenario.q0)
        .map_err(|e| anyhow::anyhow!("{}: controller: {e}", scenario.path.display()))?;
    let q0: Vec<f64> = scenario.q0.iter().copied().collect();
    let steps = std::thread::scope(|scope| {
        std::thread::Builder::new()
            .name(format!("hcc-law-{core}"))
            .spawn_scoped(scope, move || {
                let _ = rt::prepare_rt_thread(&measuring_thread(core, fifo));
                let mut steps = LatencyHistogram::new();
                let mut q = q0.clone();
                let mut qd = vec![0.0; q0.len()];
                for k in 0..LAW_WARM_UP_STEPS + LAW_STEPS {
                    let t = k as f64 * 1e-3;
                    for (j, (qj, qdj)) in q.iter_mut().zip(qd.iter_mut()).enumerate() {
                        let phase = t + j as f64;
                        *qj = q0[j] + 0.05 * phase.sin();
                        *qdj = 0.05 * phase.cos();
                    }
                    let start = monotonic_now_ns();
                    let ok = controller.step(&q, &qd).is_ok();
                    let took = monotonic_now_ns().saturating_sub(start);
                    if ok && k >= LAW_WARM_UP_STEPS {
                        steps.record(took);
                    }
                }
                steps
            })
            .map(|h| h.join())
    })
    .context("starting the law's reference thread")?
    .map_err(|_| anyhow::anyhow!("the law's reference thread panicked"))?;
    Ok(LawReference { core, steps })
}

/// Busy threads at normal priority, one per core, until dropped.
struct Load {
    stop: Arc<AtomicBool>,
    threads: Vec<std::thread::JoinHandle<()>>,
}

impl Load {
    fn start(cores: &[usize]) -> anyhow::Result<Load> {
        let stop = Arc::new(AtomicBool::new(false));
        let mut threads = Vec::new();
        for &core in cores {
            let stop = stop.clone();
            threads.push(
                std::thread::Builder::new()
                    .name(format!("hcc-load-{core}"))
                    .spawn(move || {
                        core_affinity::set_for_current(core_affinity::CoreId { id: core });
                        // Arithmetic and a 4 MiB working set (evicts the caches
                        // the real-time threads share with it).
                        let mut buffer = vec![1u64; 512 * 1024];
                        let mut x = 0x9e37_79b9_7f4a_7c15u64;
                        let mut i = 0usize;
                        while !stop.load(Ordering::Relaxed) {
                            for _ in 0..4096 {
                                x ^= x << 13;
                                x ^= x >> 7;
                                x ^= x << 17;
                                let j = (x as usize) % buffer.len();
                                buffer[j] = buffer[j].wrapping_add(x);
                                i = i.wrapping_add(1);
                            }
                        }
                        std::hint::black_box((&buffer, i));
                    })
                    .context("starting a load thread")?,
            );
        }
        Ok(Load { stop, threads })
    }
}

impl Drop for Load {
    fn drop(&mut self) {
        self.stop.store(true, Ordering::Relaxed);
        for t in self.threads.drain(..) {
            let _ = t.join();
        }
    }
}

/// CPU time counters of the measured cores, to report the steal time.
fn cpu_times(cores: &[usize]) -> Vec<Option<CpuTimes>> {
    cores.iter().map(|&c| CpuTimes::read(Some(c))).collect()
}

fn steal_since(cores: &[usize], before: &[Option<CpuTimes>]) -> Value {
    let after = cpu_times(cores);
    let mut v = serde_json::Map::new();
    for ((core, b), a) in cores.iter().zip(before).zip(&after) {
        let f = match (b, a) {
            (Some(b), Some(a)) => json!(a.steal_fraction_since(b)),
            _ => Value::Null,
        };
        v.insert(format!("core{core}"), f);
    }
    Value::Object(v)
}

/// The pair's figures, read from the daemons' timing reports.
struct Pair {
    sim: DaemonTimings,
    controller: DaemonTimings,
    run_s: f64,
}

/// The command lines of the pair: (simulator, controller).
fn pair_args(
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
fn await_pair(args: &JitterArgs, sim: &mut Daemon, controller: &mut Daemon) -> anyhow::Result<f64> {
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

fn run_pair(
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

/// One row group of the table: a figure of the pair and the floor it is compared with.
struct Row<'a> {
    key: &'static str,
    label: &'static str,
    pair: Figure,
    floor: Option<&'a FloorCore>,
    /// The law's back-to-back reference (the control law's row only).
    reference: Option<&'a LawReference>,
}

fn us(ns: u64) -> String {
    let v = ns as f64 * 1e-3;
    if v >= 100.0 {
        format!("{v:.0}")
    } else {
        format!("{v:.1}")
    }
}

fn ratio(a: u64, b: u64) -> Option<f64> {
    (b > 0).then(|| a as f64 / b as f64)
}

fn table(rows: &[Row]) -> String {
    let mut out = format!("  {:<34}", "[µs]");
    for l in LatencySummary::LABELS {
        out.push_str(&format!("{l:>9}"));
    }
    out.push('\n');
    for row in rows {
        let s = row.pair.summary;
        out.push_str(&format!("  {:<34}", row.label));
        for v in s.values_ns() {
            out.push_str(&format!("{:>9}", us(v)));
        }
        out.push('\n');
        if let Some(f) = row.floor {
            let fs = f.lateness.summary();
            out.push_str(&format!("  {:<34}", format!("  floor, core {}", f.core)));
            for v in fs.values_ns() {
                out.push_str(&format!("{:>9}", us(v)));
            }
            out.push('\n');
            push_ratio(&mut out, &s, &fs);
        }
        if let Some(r) = row.reference {
            let rs = r.steps.summary();
            out.push_str(&format!(
                "  {:<34}",
                format!("  back to back, core {}", r.core)
            ));
            for v in rs.values_ns() {
                out.push_str(&format!("{:>9}", us(v)));
            }
            out.push('\n');
            push_ratio(&mut out, &s, &rs);
        }
    }
    out
}

/// The ratio line of a figure `s` to its reference `reference`, per quantile.
fn push_ratio(out: &mut String, s: &LatencySummary, reference: &LatencySummary) {
    out.push_str(&format!("  {:<34}", "  ratio"));
    for (a, b) in s.values_ns().iter().zip(reference.values_ns()) {
        out.push_str(&match ratio(*a, b) {
            Some(r) => format!("{r:>9.2}"),
            None => format!("{:>9}", "-"),
        });
    }
    out.push('\n');
}

fn summary_json(s: &LatencySummary) -> Value {
    serde_json::to_value(s).unwrap_or(Value::Null)
}

fn ratios_json(a: &LatencySummary, b: &LatencySummary) -> Value {
    let mut m = serde_json::Map::new();
    for ((l, x), y) in LatencySummary::LABELS
        .iter()
        .zip(a.values_ns())
        .zip(b.values_ns())
    {
        m.insert((*l).to_string(), json!(ratio(x, y)));
    }
    Value::Object(m)
}

fn curve_us(f: &Figure) -> Vec<(f64, f64)> {
    f.curve
        .iter()
        .map(|p| (p.percentile, p.value_ns as f64 * 1e-3))
        .collect()
}

/// What the measurement runs with, checked against the arguments and the machine.
struct Plan {
    floor_s: f64,
    period_ns: u64,
    /// The measured cores (one if both daemons share a core).
    cores: Vec<usize>,
    fifo: Option<i32>,
}

impl Plan {
    fn new(args: &JitterArgs, scenario: &Scenario) -> anyhow::Result<Plan> {
        if !(args.duration.is_finite() && args.duration >= 0.5) {
            bail!("--duration {} must be at least 0.5 s", args.duration);
        }
        let floor_s = args
            .floor_duration
            .unwrap_or(DEFAULT_FLOOR_S.min(args.duration));
        if !(floor_s.is_finite() && floor_s > 0.0) {
            bail!("--floor-duration {floor_s} must be positive");
        }
        let available: Vec<usize> = core_affinity::get_core_ids()
            .unwrap_or_default()
            .iter()
            .map(|c| c.id)
            .collect();
        for (what, core) in [
            ("--sim-core", args.sim_core),
            ("--controller-core", args.controller_core),
        ] {
            if !available.contains(&core) {
                bail!("{what} {core}: this process may run on cores {available:?} only");
            }
        }
        if args.sim_core == args.controller_core {
            warn!(
                "the simulator and the controller share core {}",
                args.sim_core
            );
        }
        let cores = if args.sim_core == args.controller_core {
            vec![args.sim_core]
        } else {
            vec![args.sim_core, args.controller_core]
        };
        Ok(Plan {
            floor_s,
            period_ns: (1e9 / scenario.simulation.control_rate_hz).round() as u64,
            cores,
            fifo: (!args.no_fifo).then_some(args.priority),
        })
    }

    /// Cycles later than this count as late.
    fn late_ns(&self) -> u64 {
        (self.period_ns as f64 * LATE_FRACTION) as u64
    }
}

/// The process-wide settings held during the measurements.
struct Environment {
    machine: MachineInfo,
    /// Held until dropped.
    dma: Option<CpuDmaLatency>,
    dma_note: String,
    memory_locked: bool,
}

impl Environment {
    fn set_up() -> Environment {
        let machine = MachineInfo::read();
        let (dma, dma_note) = match CpuDmaLatency::request(0) {
            Ok(d) => {
                let note = format!("held at {} µs", d.us);
                (Some(d), note)
            }
            Err(e) => (None, format!("not held ({e})")),
        };
        // The floor threads run in this process: lock its memory like the daemons'.
        let memory_locked = hcc_rtalloc::lock_memory().is_ok();
        Environment {
            machine,
            dma,
            dma_note,
            memory_locked,
        }
    }
}

/// One half of the floor measurement (`when`: before or after the pair), with
/// its warnings and (unless `quiet`) its result lines.
fn floor_phase(
    args: &JitterArgs,
    plan: &Plan,
    duration_s: f64,
    when: &str,
) -> anyhow::Result<(Vec<FloorCore>, Value)> {
    let before = cpu_times(&plan.cores);
    let floor = measure_floor(
        &plan.cores,
        plan.fifo,
        args.wait,
        plan.period_ns,
        duration_s,
    )?;
    let steal = steal_since(&plan.cores, &before);
    if interrupted() {
        bail!("interrupted during the floor measurement");
    }
    for f in &floor {
        for w in &f.rt.warnings {
            warn!("floor core {}: {w}", f.core);
        }
    }
    if !args.quiet {
        for f in &floor {
            eprintln!(
                "hcc jitter: floor core {} ({when}): {}",
                f.core,
                f.lateness.summary().line_us()
            );
        }
    }
    Ok((floor, steal))
}

/// The law's back-to-back reference on the controller's core, next to one
/// half of the floor (`when`), with its result line unless `quiet`.
fn law_phase(
    args: &JitterArgs,
    scenario: &Scenario,
    plan: &Plan,
    when: &str,
) -> anyhow::Result<LawReference> {
    let law = measure_law(scenario, args.controller_core, plan.fifo)?;
    if interrupted() {
        bail!("interrupted during the law's reference");
    }
    if !args.quiet {
        eprintln!(
            "hcc jitter: control law back to back, core {} ({when}): {}",
            law.core,
            law.steps.summary().line_us()
        );
    }
    Ok(law)
}

/// The two halves of the floor as one measurement: per core, the lateness
/// histograms merged and the late cycles summed; the steal fraction the mean
/// of the halves' (equal durations).
fn join_floors(
    (mut floor, steal): (Vec<FloorCore>, Value),
    (after, steal_after): (Vec<FloorCore>, Value),
) -> (Vec<FloorCore>, Value) {
    for f in &mut floor {
        if let Some(a) = after.iter().find(|a| a.core == f.core) {
            f.lateness.merge(&a.lateness);
            f.late_cycles += a.late_cycles;
        }
    }
    let mut mean = serde_json::Map::new();
    if let (Some(b), Some(a)) = (steal.as_object(), steal_after.as_object()) {
        for (core, x) in b {
            let m = match (x.as_f64(), a.get(core).and_then(Value::as_f64)) {
                (Some(x), Some(y)) => json!((x + y) / 2.0),
                _ => Value::Null,
            };
            mean.insert(core.clone(), m);
        }
    }
    (floor, Value::Object(mean))
}

/// The figures of the table, each with the floor of its core.
fn figure_rows<'a>(
    args: &JitterArgs,
    pair: &Pair,
    floor: &'a [FloorCore],
    law: Option<&'a LawReference>,
) -> Vec<Row<'a>> {
    let floor_of = |core: usize| floor.iter().find(|f| f.core == core);
    let stage = |key, label, name| Row {
        key,
        label,
        pair: pair.controller.figure(name),
        floor: None,
        reference: None,
    };
    vec![
        Row {
            key: "sim_tick_lateness",
            label: "simulator tick lateness",
            pair: pair.sim.figure("tick_lateness"),
            floor: floor_of(args.sim_core),
            reference: None,
        },
        Row {
            key: "state_to_command_latency",
            label: "state -> command latency",
            pair: pair.sim.figure("state_to_command"),
            floor: floor_of(args.controller_core),
            reference: None,
        },
        Row {
            key: "controller_wakeup_latency",
            label: "controller wake-up latency",
            pair: pair.controller.figure("wakeup_latency"),
            floor: floor_of(args.controller_core),
            reference: None,
        },
        Row {
            key: "controller_compute_time",
            label: "controller compute time",
            pair: pair.controller.figure("compute_time"),
            floor: None,
            reference: None,
        },
        Row {
            key: "controller_control_law_time",
            label: "  of which the control law",
            pair: pair.controller.figure("control_law_time"),
            floor: None,
            reference: law,
        },
        // The stages of the controller's cycle, from its wake-up: they add
        // up to the compute time (the telemetry comes after the command).
        stage(
            "controller_stage_setpoints",
            "  stage: setpoints taken",
            "stage_setpoints",
        ),
        stage(
            "controller_stage_decide",
            "  stage: decide (law, pipeline)",
            "stage_decide",
        ),
        stage(
            "controller_stage_send",
            "  stage: command send",
            "stage_send",
        ),
        stage(
            "controller_stage_notify",
            "  stage: command_ready notify",
            "stage_notify",
        ),
        stage(
            "controller_stage_telemetry",
            "  after: telemetry",
            "stage_telemetry",
        ),
        // Before the state: the law's twin stepped while waiting.
        stage(
            "controller_warm_up",
            "  before: cache warm-up step",
            "warm_up",
        ),
        // The driver's part of the path: from the state's stamp until its
        // send returned (the controller may take the sample before that).
        Row {
            key: "sim_state_publish",
            label: "simulator: state stamp -> sent",
            pair: pair.sim.figure("state_publish"),
            floor: None,
            reference: None,
        },
    ]
}

/// The rows drawn in jitter.png (the stages are in the table and the JSON).
const PLOTTED_ROWS: usize = 5;

/// The simulator's counts: every period after the first command is answered or missed.
struct Counts {
    periods: u64,
    waiting: u64,
    stopped: u64,
    received: u64,
    missed: u64,
    /// Missed commands of states the simulator gave less than their command
    /// window (its own tick was late: the machine's lateness on its core).
    short_window: u64,
    cycles: u64,
    consistent: bool,
    /// Late cycles and cycles of the floor on the controller's core.
    floor_late: u64,
    floor_cycles: u64,
}

impl Counts {
    fn new(sim: &DaemonTimings, controller_floor: Option<&FloorCore>) -> Counts {
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

/// A target: what, the measured value, the limit (figures, not assertions).
type Target = (&'static str, f64, f64);

fn targets(args: &JitterArgs, rows: &[Row], counts: &Counts) -> Vec<Target> {
    let per_million = |n: u64, of: u64| {
        if of == 0 {
            0.0
        } else {
            n as f64 * 1e6 / of as f64
        }
    };
    let s2c = rows[1].pair.summary;
    let tick = rows[0].pair.summary;
    let tick_floor = rows[0].floor.map(|f| f.lateness.summary());
    let compute = rows[3].pair.summary;
    let mut targets = Vec::new();
    if args.wait == Wait::Hybrid {
        targets.push((
            "state -> command latency p50 <= 5 us",
            s2c.p50_ns as f64 * 1e-3,
            5.0,
        ));
        if let (Some(a), Some(b)) = (rows[0].floor, rows[1].floor) {
            targets.push((
                "state -> command latency p99 <= both floors' p99 + 10 us",
                s2c.p99_ns as f64 * 1e-3,
                (a.lateness.summary().p99_ns + b.lateness.summary().p99_ns) as f64 * 1e-3 + 10.0,
            ));
        }
        targets.push((
            "state -> command latency p99.9 <= 50 us",
            s2c.p999_ns as f64 * 1e-3,
            50.0,
        ));
        if let Some(f) = tick_floor {
            targets.push((
                "tick lateness p99.9 <= 1.2 x floor p99.9 (us)",
                tick.p999_ns as f64 * 1e-3,
                1.2 * f.p999_ns as f64 * 1e-3,
            ));
        }
    }
    targets.push((
        "controller compute time p99 <= 2 x its p50 (us)",
        compute.p99_ns as f64 * 1e-3,
        2.0 * compute.p50_ns as f64 * 1e-3,
    ));
    // A state the simulator published late, with less than its command
    // window before the next tick, is the simulator core's lateness (its
    // floor), not the controller's: the misses charged to the controller are
    // those of states that had their full window.
    targets.push((
        "missed commands (full window) per million cycles <= floor late cycles per million",
        per_million(counts.missed - counts.short_window, counts.cycles),
        per_million(counts.floor_late, counts.floor_cycles),
    ));
    targets
}

/// Everything measured, for the report, the plot and the table.
struct Measured<'a> {
    args: &'a JitterArgs,
    scenario: &'a Scenario,
    plan: &'a Plan,
    env: &'a Environment,
    floor: &'a [FloorCore],
    pair: &'a Pair,
    rows: &'a [Row<'a>],
    counts: Counts,
    targets: Vec<Target>,
    floor_steal: Value,
    pair_steal: Value,
}

impl Measured<'_> {
    /// The contents of jitter.json.
    fn report(&self) -> Value {
        let (args, plan, pair, floor, c) =
            (self.args, self.plan, self.pair, self.floor, &self.counts);
        let sim = &pair.sim;
        let mut figures = serde_json::Map::new();
        for row in self.rows {
            let mut v = json!({
                "pair": summary_json(&row.pair.summary),
                "curve": row.pair.curve,
            });
            if let Some(f) = row.floor {
                let fs = f.lateness.summary();
                v["floor_core"] = json!(f.core);
                v["floor"] = summary_json(&fs);
                v["ratio"] = ratios_json(&row.pair.summary, &fs);
            }
            if let Some(r) = row.reference {
                let rs = r.steps.summary();
                v["back_to_back_core"] = json!(r.core);
                v["back_to_back"] = summary_json(&rs);
                v["ratio_to_back_to_back"] = ratios_json(&row.pair.summary, &rs);
            }
            figures.insert(row.key.to_string(), v);
        }
        json!({
            "settings": {
                "scenario": self.scenario.name,
                "config": args.config.display().to_string(),
                "wait": args.wait.name(),
                "duration_s": args.duration,
                "floor_duration_s": plan.floor_s,
                "pair_wall_time_s": pair.run_s,
                "period_ns": plan.period_ns,
                "late_threshold_ns": plan.late_ns(),
                "load": args.load,
                "poll_commands": args.poll_commands,
                "telemetry_every": args.telemetry_every,
                "controller_warm_up": self.warm_up(),
                "controller_warm_ups": pair.controller.counter("warm_ups"),
                "controller_warm_up_overlaps": pair.controller.counter("warm_up_overlaps"),
                "controller_warm_up_overlap_max_ns": pair.controller.counter("warm_up_overlap_max_ns"),
                "controller_warm_up_last_lead_ns": pair.controller.counter("warm_up_last_lead_ns"),
                "notifications_skipped": pair.controller.counter("notifications_skipped"),
                "controller_commands_in_preloaned_samples": pair.controller.counter("commands_in_preloaned_samples"),
                "controller_torque_path_system_allocs": pair.controller.counter("torque_path_system_allocs_after_warm_up"),
                "controller_connection_updates": pair.controller.counter("connection_updates"),
                "cores": {"sim": args.sim_core, "controller": args.controller_core},
                "sched_fifo_requested": plan.fifo,
                "memory_locked_launcher": self.env.memory_locked,
                "cpu_dma_latency": self.env.dma_note,
                "machine": self.env.machine,
                "obtained": {
                    "sim": sim.rt,
                    "controller": pair.controller.rt,
                    "floor": floor.iter().map(|f| json!({"core": f.core, "rt": f.rt})).collect::<Vec<_>>(),
                },
            },
            "figures": figures,
            "counts": {
                "cycles": c.cycles,
                "received_commands": c.received,
                "missed_commands": c.missed,
                "missed_after_late_tick": c.short_window,
                "consistent": c.consistent,
                "periods": c.periods,
                "waiting_for_controller": c.waiting,
                "stopped_periods": c.stopped,
                "fallback_cycles": sim.counter("fallback_cycles"),
                "late_commands": sim.counter("late_commands"),
                "rejected_commands": sim.counter("rejected_commands"),
                "overruns": sim.counter("overruns"),
                "ticks_late": sim.counter("ticks_late"),
                "controller_cycles": pair.controller.counter("cycles"),
                "controller_missed_states": pair.controller.counter("missed_states"),
                "controller_stale_events": pair.controller.counter("stale_events"),
                "floor": floor.iter().map(|f| json!({
                    "core": f.core, "cycles": f.lateness.count(), "late_cycles": f.late_cycles,
                })).collect::<Vec<_>>(),
            },
            "steal_fraction": {"floor": self.floor_steal, "pair": self.pair_steal},
            "targets": self.targets.iter().map(|(what, value, limit)| json!({
                "target": what, "value": value, "limit": limit, "met": value <= limit,
            })).collect::<Vec<_>>(),
        })
    }

    /// jitter.png: latency vs percentile, the floor dashed.
    fn plot(&self, path: &Path) -> anyhow::Result<()> {
        let (args, pair) = (self.args, self.pair);
        let mut curves = Vec::new();
        for (k, row) in self.rows.iter().take(PLOTTED_ROWS).enumerate() {
            curves.push(PercentileCurve {
                label: row.label.trim().to_string(),
                points: curve_us(&row.pair),
                reference: false,
                color: k,
            });
        }
        for f in self.floor {
            // The colour of the figure measured on the same core.
            let color = if f.core == args.sim_core { 0 } else { 2 };
            curves.push(PercentileCurve {
                label: format!("floor, core {} ({} wait)", f.core, args.wait.name()),
                points: curve_us(&Figure::from(&f.lateness)),
                reference: true,
                color,
            });
        }
        let title = format!(
            "{}: {} wait, {} s, {}{}",
            self.scenario.name,
            args.wait.name(),
            args.duration,
            match (pair.sim.rt.fifo_priority, pair.controller.rt.fifo_priority) {
                (Some(_), Some(_)) => "SCHED_FIFO",
                _ => "normal scheduling",
            },
            if args.load { ", with load" } else { "" }
        );
        plot_percentiles(path, &title, &curves)?;
        Ok(())
    }

    /// Whether the controller warmed its caches before each state (hybrid wait,
    /// `[controller_daemon] warm_up`, no `--no-warm-up`).
    fn warm_up(&self) -> bool {
        matches!(self.args.wait, Wait::Hybrid)
            && self.scenario.controller_daemon.warm_up
            && !self.args.no_warm_up
    }

    /// The heading of the table: the run, the machine, the scheduling obtained.
    fn print_heading(&self) {
        let (args, env, pair) = (self.args, self.env, self.pair);
        let machine = &env.machine;
        println!(
            "hcc jitter: {} — {} wait, pair {} s (floor {} s, half before and half after it), simulator core {} / controller core {}, load {}, command_ready {}, telemetry every {} cycle(s), cache warm-up {}",
            self.scenario.name,
            args.wait.name(),
            args.duration,
            self.plan.floor_s,
            args.sim_core,
            args.controller_core,
            if args.load { "on" } else { "off" },
            if args.poll_commands {
                "skipped (polling simulator)"
            } else {
                "notified"
            },
            args.telemetry_every,
            if self.warm_up() { "on" } else { "off" },
        );
        println!(
            "  {} ({} CPUs{}), kernel {}, rt throttling {} of {} µs",
            machine.cpu_model,
            machine.cpus,
            if machine.virtual_machine {
                ", virtual machine"
            } else {
                ""
            },
            machine.kernel,
            machine
                .rt_throttling
                .runtime_us
                .map_or("?".into(), |v| v.to_string()),
            machine
                .rt_throttling
                .period_us
                .map_or("?".into(), |v| v.to_string()),
        );
        let sched = |r: &RtObtained| {
            format!(
                "{}{}{}",
                r.fifo_priority
                    .map_or("normal".into(), |p| format!("SCHED_FIFO {p}")),
                r.pinned_core
                    .map_or(", unpinned".into(), |c| format!(", core {c}")),
                if r.memory_locked { ", mlocked" } else { "" }
            )
        };
        println!(
            "  obtained: simulator {}; controller {}; floor {}; /dev/cpu_dma_latency {}",
            sched(&pair.sim.rt),
            sched(&pair.controller.rt),
            self.floor
                .iter()
                .map(|f| sched(&f.rt))
                .collect::<Vec<_>>()
                .join(" / "),
            env.dma_note,
        );
    }

    /// The table, the counts, the steal time and the targets.
    fn print(&self) {
        let (args, sim, c) = (self.args, &self.pair.sim, &self.counts);
        self.print_heading();
        print!("{}", table(self.rows));
        println!(
            "  cycles {} = received commands {} + missed {} ({}; {} of them after a late simulator tick); fallback cycles {}, late answers {}, rejected {}, clock overruns {}",
            c.cycles,
            c.received,
            c.missed,
            if c.consistent {
                "consistent"
            } else {
                "INCONSISTENT"
            },
            c.short_window,
            sim.counter("fallback_cycles"),
            sim.counter("late_commands"),
            sim.counter("rejected_commands"),
            sim.counter("overruns"),
        );
        println!(
            "  late cycles (> {} µs): floor {} of {} on core {}, simulator ticks {} of {}",
            us(self.plan.late_ns()),
            c.floor_late,
            c.floor_cycles,
            args.controller_core,
            sim.counter("ticks_late"),
            self.rows[0].pair.summary.count,
        );
        println!(
            "  steal time: floor {}, pair {}",
            steal_text(&self.floor_steal),
            steal_text(&self.pair_steal)
        );
        let ctl = &self.pair.controller;
        println!(
            "  controller: system allocations on the torque path after warm-up {}; peer connections made while waiting {} ({} system allocations, longest {:.1} µs)",
            ctl.counter("torque_path_system_allocs_after_warm_up"),
            ctl.counter("connection_updates"),
            ctl.counter("connection_update_system_allocs"),
            ctl.counter("connection_update_max_ns") as f64 / 1e3,
        );
        if self.warm_up() {
            println!(
                "  controller: cache warm-ups {}, of which still running when their state came {} (longest wait {:.1} µs); the last one's lead {:.1} µs",
                ctl.counter("warm_ups"),
                ctl.counter("warm_up_overlaps"),
                ctl.counter("warm_up_overlap_max_ns") as f64 / 1e3,
                ctl.counter("warm_up_last_lead_ns") as f64 / 1e3,
            );
        }
        for (what, value, limit) in &self.targets {
            println!(
                "  target {what}: {value:.2} vs {limit:.2} — {}",
                if value <= limit { "met" } else { "missed" }
            );
        }
        println!("results in {}", args.out.display());
    }
}

/// The line that says what is about to be measured.
fn announce(args: &JitterArgs, scenario: &Scenario, plan: &Plan, env: &Environment) {
    eprintln!(
        "hcc jitter: {} — {} wait, floor {} s, pair {} s, floor {} s, simulator on core {}, controller on core {}, {}, /dev/cpu_dma_latency {}, load {}",
        scenario.name,
        args.wait.name(),
        plan.floor_s / 2.0,
        args.duration,
        plan.floor_s / 2.0,
        args.sim_core,
        args.controller_core,
        match plan.fifo {
            Some(p) => format!("SCHED_FIFO {p} requested"),
            None => "normal scheduling".into(),
        },
        env.dma_note,
        if args.load { "on" } else { "off" },
    );
}

pub fn run(args: JitterArgs) -> anyhow::Result<()> {
    let scenario = Scenario::load(&args.config)?;
    let plan = Plan::new(&args, &scenario)?;
    std::fs::create_dir_all(&args.out)
        .with_context(|| format!("cannot create {}", args.out.display()))?;
    install_signal_handlers()?;
    let mut env = Environment::set_up();
    if !args.quiet {
        announce(&args, &scenario, &plan, &env);
    }
    let load = if args.load {
        Some(Load::start(&plan.cores)?)
    } else {
        None
    };

    // 1. The floor's first half.
    let half_s = plan.floor_s / 2.0;
    let floor_before = floor_phase(&args, &plan, half_s, "before the pair")?;
    let law_before = law_phase(&args, &scenario, &plan, "before the pair")?;

    // 2. The pair.
    let sim_stats = args.out.join("sim-timings.json");
    let controller_stats = args.out.join("controller-timings.json");
    let before = cpu_times(&plan.cores);
    let pair = run_pair(&args, plan.fifo, &sim_stats, &controller_stats)?;
    let pair_steal = steal_since(&plan.cores, &before);

    // 3. The floor's second half: the machine around the pair, not only
    // before it (its stalls come and go from minute to minute).
    let floor_after = floor_phase(&args, &plan, half_s, "after the pair")?;
    let law_after = law_phase(&args, &scenario, &plan, "after the pair")?;
    let (floor, floor_steal) = join_floors(floor_before, floor_after);
    let mut law = law_before;
    law.steps.merge(&law_after.steps);
    drop(load);
    drop(env.dma.take());

    let rows = figure_rows(&args, &pair, &floor, Some(&law));
    let counts = Counts::new(
        &pair.sim,
        floor.iter().find(|f| f.core == args.controller_core),
    );
    let measured = Measured {
        targets: targets(&args, &rows, &counts),
        args: &args,
        scenario: &scenario,
        plan: &plan,
        env: &env,
        floor: &floor,
        pair: &pair,
        rows: &rows,
        counts,
        floor_steal,
        pair_steal,
    };
    let json_path = args.out.join("jitter.json");
    std::fs::write(
        &json_path,
        serde_json::to_string_pretty(&measured.report())? + "\n",
    )
    .with_context(|| format!("cannot write {}", json_path.display()))?;
    if !args.no_plot {
        measured.plot(&args.out.join("jitter.png"))?;
    }
    measured.print();
    let c = &measured.counts;
    if !c.consistent {
        bail!(
            "the simulator's counts do not add up: {} cycles, {} received, {} missed",
            c.cycles,
            c.received,
            c.missed
        );
    }
    Ok(())
}

fn steal_text(v: &Value) -> String {
    match v.as_object() {
        Some(m) => m
            .iter()
            .map(|(k, f)| match f.as_f64() {
                Some(x) => format!("{k} {:.2} %", 100.0 * x),
                None => format!("{k} ?"),
            })
            .collect::<Vec<_>>()
            .join(", "),
        None => "?".into(),
    }
}
