//! The table and the lines `hcc jitter` prints.

use hcc_timing::{LatencySummary, RtObtained};
use serde_json::Value;

use super::figures::{Figures, ratio};
use super::report::Measured;

pub(super) fn us(ns: u64) -> String {
    let v = ns as f64 * 1e-3;
    if v >= 100.0 {
        format!("{v:.0}")
    } else {
        format!("{v:.1}")
    }
}

pub(super) fn table(figures: &Figures) -> String {
    let mut out = format!("  {:<34}", "[µs]");
    for l in LatencySummary::LABELS {
        out.push_str(&format!("{l:>9}"));
    }
    out.push('\n');
    for row in figures.rows() {
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
pub(super) fn push_ratio(out: &mut String, s: &LatencySummary, reference: &LatencySummary) {
    out.push_str(&format!("  {:<34}", "  ratio"));
    for (a, b) in s.values_ns().iter().zip(reference.values_ns()) {
        out.push_str(&match ratio(*a, b) {
            Some(r) => format!("{r:>9.2}"),
            None => format!("{:>9}", "-"),
        });
    }
    out.push('\n');
}

impl Measured<'_> {
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
    pub(super) fn print(&self) {
        let (args, sim, c) = (self.args, &self.pair.sim, &self.counts);
        self.print_heading();
        print!("{}", table(self.figures));
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
            self.figures.tick.pair.summary.count,
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

pub(super) fn steal_text(v: &Value) -> String {
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
