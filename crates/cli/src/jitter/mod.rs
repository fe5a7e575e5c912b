//! `hcc jitter [CONFIG] [--duration S] [--out DIR] [--wait event|hybrid] [--load]`:
//! how late is each cycle, and how much of that is the machine and how much
//! the software?
//!
//! 1. **Floor.** Half of it before the pair and half after it (one
//!    measurement of the machine around the pair): a bare periodic thread at
//!    the control rate on each of the two cores (pinned, `SCHED_FIFO` when permitted, timer slack 1 ns, the
//!    same wait strategy as the daemons: `event` sleeps to each deadline with
//!    `clock_nanosleep(TIMER_ABSTIME)`, `hybrid` sleeps until
//!    [`hcc_rt::HYBRID_LEAD_NS`] before it and spins) — no IPC, no work. Its
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

use crate::daemons::install_signal_handlers;

mod figures;
mod floor;
mod law;
mod pair;
mod plan;
mod report;
mod table;

use figures::{Figures, targets};
use floor::{Load, cpu_times, floor_phase, join_floors, steal_since};
use law::law_phase;
use pair::{Counts, run_pair};
use report::Measured;

pub use plan::JitterArgs;
use plan::{Environment, Plan};

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

    let figures = Figures::new(&args, &pair, &floor, Some(&law));
    let counts = Counts::new(
        &pair.sim,
        floor.iter().find(|f| f.core == args.controller_core),
    );
    let measured = Measured {
        targets: targets(&args, &figures, &counts),
        args: &args,
        scenario: &scenario,
        plan: &plan,
        env: &env,
        floor: &floor,
        pair: &pair,
        figures: &figures,
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
