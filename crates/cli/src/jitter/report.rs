//! What `hcc jitter` writes: `jitter.json` (every figure, its floor and
//! ratios, the counts, the settings and the targets) and `jitter.png`.

use hcc_config::Scenario;
use hcc_report::{PercentileCurve, plot_percentiles};
use hcc_timing::{Figure, LatencySummary};
use serde_json::{Value, json};
use std::path::Path;

use super::figures::{Figures, Target, ratio};
use super::floor::FloorCore;
use super::pair::{Counts, Pair};
use super::plan::{Environment, JitterArgs, Plan, Wait};

pub(super) fn summary_json(s: &LatencySummary) -> Value {
    serde_json::to_value(s).unwrap_or(Value::Null)
}

pub(super) fn ratios_json(a: &LatencySummary, b: &LatencySummary) -> Value {
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

pub(super) fn curve_us(f: &Figure) -> Vec<(f64, f64)> {
    f.curve
        .iter()
        .map(|p| (p.percentile, p.value_ns as f64 * 1e-3))
        .collect()
}

/// Everything measured, for the report, the plot and the table.
pub(super) struct Measured<'a> {
    pub(super) args: &'a JitterArgs,
    pub(super) scenario: &'a Scenario,
    pub(super) plan: &'a Plan,
    pub(super) env: &'a Environment,
    pub(super) floor: &'a [FloorCore],
    pub(super) pair: &'a Pair,
    pub figures: &'a Figures<'a>,
    pub(super) counts: Counts,
    pub(super) targets: Vec<Target>,
    pub(super) floor_steal: Value,
    pub(super) pair_steal: Value,
}

impl Measured<'_> {
    /// The contents of jitter.json.
    pub(super) fn report(&self) -> Value {
        let (args, plan, pair, floor, c) =
            (self.args, self.plan, self.pair, self.floor, &self.counts);
        let sim = &pair.sim;
        let mut figures = serde_json::Map::new();
        for row in self.figures.rows() {
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
    pub(super) fn plot(&self, path: &Path) -> anyhow::Result<()> {
        let (args, pair) = (self.args, self.pair);
        let mut curves = Vec::new();
        for (k, row) in self.figures.plotted().into_iter().enumerate() {
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
    pub(super) fn warm_up(&self) -> bool {
        matches!(self.args.wait, Wait::Hybrid)
            && self.scenario.controller_daemon.warm_up
            && !self.args.no_warm_up
    }
}
