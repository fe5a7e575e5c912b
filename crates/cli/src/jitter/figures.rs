//! The figures of `hcc jitter` by name — each a latency of the pair with
//! the floor of its core or the law's back-to-back reference — and the
//! targets: figures against limits, printed, never asserted.

use hcc_timing::Figure;

use super::floor::FloorCore;
use super::law::LawReference;
use super::pair::{Counts, Pair};
use super::plan::{JitterArgs, Wait};

/// One row group of the table: a figure of the pair and the floor it is compared with.
pub(super) struct Row<'a> {
    pub(super) key: &'static str,
    pub(super) label: &'static str,
    pub(super) pair: Figure,
    pub(super) floor: Option<&'a FloorCore>,
    /// The law's back-to-back reference (the control law's row only).
    pub(super) reference: Option<&'a LawReference>,
}

/// The figures of the table, each with the floor of its core (or the law's
/// back-to-back reference), by name.
pub(super) struct Figures<'a> {
    /// The simulator's tick lateness, beside the floor of its core.
    pub tick: Row<'a>,
    /// State published → its answer received at the simulator, beside the
    /// floor of the controller's core.
    pub state_to_command: Row<'a>,
    /// The controller's wake-up latency, beside the floor of its core.
    pub wakeup: Row<'a>,
    /// The controller's compute time (wake-up → command sent).
    pub compute: Row<'a>,
    /// Of which the control law, beside its back-to-back reference.
    pub law: Row<'a>,
    /// The stages of the controller's cycle, from its wake-up (they add up
    /// to the compute time), then what follows the command and precedes the
    /// state: the telemetry and the cache warm-up.
    pub stages: [Row<'a>; 6],
    /// The driver's part of the path: from the state's stamp until its send
    /// returned (the controller may take the sample before that).
    pub publish: Row<'a>,
}

impl<'a> Figures<'a> {
    pub(super) fn new(
        args: &JitterArgs,
        pair: &Pair,
        floor: &'a [FloorCore],
        law: Option<&'a LawReference>,
    ) -> Figures<'a> {
        let floor_of = |core: usize| floor.iter().find(|f| f.core == core);
        let row = |key, label, figure: Figure| Row {
            key,
            label,
            pair: figure,
            floor: None,
            reference: None,
        };
        let ctl = |key, label, name| row(key, label, pair.controller.figure(name));
        Figures {
            tick: Row {
                floor: floor_of(args.sim_core),
                ..row(
                    "sim_tick_lateness",
                    "simulator tick lateness",
                    pair.sim.figure("tick_lateness"),
                )
            },
            state_to_command: Row {
                floor: floor_of(args.controller_core),
                ..row(
                    "state_to_command_latency",
                    "state -> command latency",
                    pair.sim.figure("state_to_command"),
                )
            },
            wakeup: Row {
                floor: floor_of(args.controller_core),
                ..ctl(
                    "controller_wakeup_latency",
                    "controller wake-up latency",
                    "wakeup_latency",
                )
            },
            compute: ctl(
                "controller_compute_time",
                "controller compute time",
                "compute_time",
            ),
            law: Row {
                reference: law,
                ..ctl(
                    "controller_control_law_time",
                    "  of which the control law",
                    "control_law_time",
                )
            },
            stages: [
                ctl(
                    "controller_stage_setpoints",
                    "  stage: setpoints taken",
                    "stage_setpoints",
                ),
                ctl(
                    "controller_stage_decide",
                    "  stage: decide (law, filter)",
                    "stage_decide",
                ),
                ctl(
                    "controller_stage_send",
                    "  stage: command send",
                    "stage_send",
                ),
                ctl(
                    "controller_stage_notify",
                    "  stage: command_ready notify",
                    "stage_notify",
                ),
                ctl(
                    "controller_stage_telemetry",
                    "  after: telemetry",
                    "stage_telemetry",
                ),
                ctl(
                    "controller_warm_up",
                    "  before: cache warm-up step",
                    "warm_up",
                ),
            ],
            publish: row(
                "sim_state_publish",
                "simulator: state stamp -> sent",
                pair.sim.figure("state_publish"),
            ),
        }
    }

    /// The rows in the order of the table.
    pub(super) fn rows(&self) -> impl Iterator<Item = &Row<'a>> {
        [
            &self.tick,
            &self.state_to_command,
            &self.wakeup,
            &self.compute,
            &self.law,
        ]
        .into_iter()
        .chain(&self.stages)
        .chain([&self.publish])
    }

    /// The rows drawn in jitter.png (the stages are in the table and the JSON).
    pub(super) fn plotted(&self) -> [&Row<'a>; 5] {
        [
            &self.tick,
            &self.state_to_command,
            &self.wakeup,
            &self.compute,
            &self.law,
        ]
    }
}

/// A target: what, the measured value, the limit (figures, not assertions).
pub(super) type Target = (&'static str, f64, f64);

pub(super) fn targets(args: &JitterArgs, figures: &Figures, counts: &Counts) -> Vec<Target> {
    let per_million = |n: u64, of: u64| {
        if of == 0 {
            0.0
        } else {
            n as f64 * 1e6 / of as f64
        }
    };
    let s2c = figures.state_to_command.pair.summary;
    let tick = figures.tick.pair.summary;
    let tick_floor = figures.tick.floor.map(|f| f.lateness.summary());
    let compute = figures.compute.pair.summary;
    let mut targets = Vec::new();
    if args.wait == Wait::Hybrid {
        targets.push((
            "state -> command latency p50 <= 5 us",
            s2c.p50_ns as f64 * 1e-3,
            5.0,
        ));
        if let (Some(a), Some(b)) = (figures.tick.floor, figures.state_to_command.floor) {
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

/// a / b, when b is not 0.
pub(super) fn ratio(a: u64, b: u64) -> Option<f64> {
    (b > 0).then(|| a as f64 / b as f64)
}
