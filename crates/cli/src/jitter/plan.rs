//! What `hcc jitter` measures with: its arguments, the plan checked against
//! them and the machine (durations, cores, scheduling), and the process-wide
//! settings held while it measures.

use anyhow::bail;
use hcc_config::Scenario;
use hcc_timing::machine::{CpuDmaLatency, MachineInfo};
use std::path::PathBuf;
use tracing::warn;

use crate::run_cmd::DEFAULT_CONFIG;

/// The floor thread and the simulator count a cycle as late when it wakes
/// later than this part of the period (the simulator's command window).
pub(super) const LATE_FRACTION: f64 = 0.8;

/// Default floor measurement, s (at most the pair's duration).
pub(super) const DEFAULT_FLOOR_S: f64 = 10.0;

/// Wait strategy of both daemons and of the floor threads.
pub(super) type Wait = hcc_rt::WaitStrategy;

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

/// What the measurement runs with, checked against the arguments and the machine.
pub(super) struct Plan {
    pub(super) floor_s: f64,
    pub(super) period_ns: u64,
    /// The measured cores (one if both daemons share a core).
    pub(super) cores: Vec<usize>,
    pub(super) fifo: Option<i32>,
}

impl Plan {
    pub(super) fn new(args: &JitterArgs, scenario: &Scenario) -> anyhow::Result<Plan> {
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
            period_ns: (1e9 / scenario.rate_hz).round() as u64,
            cores,
            fifo: (!args.no_fifo).then_some(args.priority),
        })
    }

    /// Cycles later than this count as late.
    pub(super) fn late_ns(&self) -> u64 {
        (self.period_ns as f64 * LATE_FRACTION) as u64
    }
}

/// The process-wide settings held during the measurements.
pub(super) struct Environment {
    pub(super) machine: MachineInfo,
    /// Held until dropped.
    pub(super) dma: Option<CpuDmaLatency>,
    pub(super) dma_note: String,
    pub(super) memory_locked: bool,
}

impl Environment {
    pub(super) fn set_up() -> Environment {
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
