//! The unreachable sweep: seeded Panda goals the hierarchy cannot meet, and
//! what the arm does once nobody commands anything — the measurement of the
//! passivity of the hierarchy where its higher levels cannot converge (the
//! paper's Sec. IV proves stability only once they have).
//!
//! Each goal is the scenario's own (`config/panda-pose-posture.toml` with its
//! torque filter, the safety layer's defaults), final from t = 0: no setpoint,
//! no transition, no external force, the plant the controller's model — so
//! nothing but the controller can raise the storage
//!
//! H = ½ q̇ᵀ M q̇ + V_1 + Σ_{i≥2} β_i V_i + the joint-limit guard's potential
//!     + the fade's tank + the levels' energy tanks + the output stages' tank
//!
//! (`ControlCycle::storage`, the telemetry's `h`; β_i the fades). The TCP goals, a
//! quarter each:
//! within 0.2 m of the base axis; below the base; behind it; 0.95–1.6 m from
//! the shoulder (beyond reach). Every goal: the hand turned to a random
//! roll-pitch-yaw (often one the wrist cannot reach with the position held),
//! a posture goal up to 0.5 rad beyond the limits of every joint.
//!
//! Printed over all goals: the largest rise of H from one cycle to the next,
//! within 10 ms, and over the run (each: which goal, when); the goals that move again
//! (above 0.05 rad/s) after resting (max |q̇| < 0.01 rad/s over 0.1 s); the
//! time to rest — first and for good — as median, p95, max and the share at
//! rest by 4, 12 and 30 s; the largest |q̇_k|/q̇_max,k and the deepest beyond a
//! position limit. `UNREACHABLE_GOALS` goals (default 24) of
//! `UNREACHABLE_SECONDS` each (default 30 s); `UNREACHABLE_GOALS=200 cargo
//! test --release -p hcc-in-process --test unreachable_sweep -- --nocapture`
//! is the full sweep of docs/limits-and-singularities.md
//! (`UNREACHABLE_THREADS=2`: on two threads, one per core, reported
//! together, with a line per goal). `UNREACHABLE_SHARD=i/n` runs the goals g
//! with g mod n = i (one process per core) and prints a line per goal; `UNREACHABLE_ONLY=g` runs goal g alone
//! and prints its course every 0.25 s (`UNREACHABLE_EVERY=k`: every k
//! cycles; with q, q̇, the torque sent and which safety parts act)
//! (`UNREACHABLE_PLOT=<dir>`: and draws
//! it, H, the potentials, the tanks and their valves, as
//! `<dir>/unreachable-goal-<g>.png`); `UNREACHABLE_FILTER=0` runs without the
//! torque filter; `SWEEP_SAFETY=field=value,…` changes `[safety]` fields for
//! a comparison, as in the 500-goal sweep.
//!
//! Asserted on every goal (30 s each), with the energy tanks
//! (`hcc_control::energy_tank`): no NaN, inside the position limits, at most
//! 0.95 of a velocity limit, at rest by 30 s, never moving again after rest,
//! and H rising by at most 5 mJ from one cycle to the next, 0.01 J within
//! 10 ms and 0.2 J over a run without the torque filter — with it, where the
//! rate limit cannot build a torque the law changes faster and every tank is
//! empty its lag still feeds energy in (up to 0.25 J, 2.5 J and 12 J) — but
//! the known exceptions of the 200 goals (`Known`; the figures in
//! docs/limits-and-singularities.md).

mod safety_overrides;
mod seeded;
use safety_overrides::sweep_safety_overrides;
use seeded::{Rng, on_threads, quantile};
use std::collections::VecDeque;
use std::path::PathBuf;

use hcc_config::Scenario;
use hcc_in_process::run_observed;
use nalgebra::DVector;

fn load(name: &str) -> Scenario {
    let path = PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("../../config")
        .join(name);
    Scenario::load(&path).unwrap_or_else(|e| panic!("{e}"))
}

/// Where a goal's TCP is.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Region {
    /// Within 0.2 m of the base axis, 0.2 m below the base to 1.2 m above it.
    NearAxis,
    /// Below the base: 0.05–0.6 m under it, up to 0.8 m from its axis.
    BelowBase,
    /// Behind the base, low: x from −0.8 to −0.1 m, |y| ≤ 0.4 m, z from −0.3
    /// to 0.3 m.
    Behind,
    /// 0.95–1.6 m from the shoulder, in any direction from 0.8 rad below the
    /// shoulder's horizon to 1.2 rad above it.
    BeyondReach,
}

/// One goal: where its TCP is asked to be, the TCP roll-pitch-yaw, the posture.
struct Goal {
    region: Region,
    tcp: [f64; 3],
    rpy: [f64; 3],
    posture: Vec<f64>,
}

/// The shoulder's height above the base (m): joint 2's axis.
const SHOULDER: f64 = 0.333;

/// The first `n` goals (seeded); the regions take turns.
fn goals(joints: &[hcc_model::Joint], n: usize) -> Vec<Goal> {
    use std::f64::consts::{FRAC_PI_2, PI};
    let mut rng = Rng(0x0bad_5eed_0047_0001);
    let regions = [
        Region::NearAxis,
        Region::BelowBase,
        Region::Behind,
        Region::BeyondReach,
    ];
    (0..n)
        .map(|g| {
            let region = regions[g % regions.len()];
            let az = rng.range(-PI, PI);
            let tcp = match region {
                Region::NearAxis => {
                    let rho = rng.range(0.0, 0.2);
                    [rho * az.cos(), rho * az.sin(), rng.range(-0.2, 1.2)]
                }
                Region::BelowBase => {
                    let rho = rng.range(0.0, 0.8);
                    [rho * az.cos(), rho * az.sin(), rng.range(-0.6, -0.05)]
                }
                Region::Behind => [
                    rng.range(-0.8, -0.1),
                    rng.range(-0.4, 0.4),
                    rng.range(-0.3, 0.3),
                ],
                Region::BeyondReach => {
                    let (radius, el) = (rng.range(0.95, 1.6), rng.range(-0.8, 1.2));
                    [
                        radius * el.cos() * az.cos(),
                        radius * el.cos() * az.sin(),
                        SHOULDER + radius * el.sin(),
                    ]
                }
            };
            let rpy = [
                rng.range(-PI, PI),
                rng.range(-FRAC_PI_2, FRAC_PI_2),
                rng.range(-PI, PI),
            ];
            let posture = joints
                .iter()
                .map(|j| rng.range(j.lower - 0.5, j.upper + 0.5))
                .collect();
            Goal {
                region,
                tcp,
                rpy,
                posture,
            }
        })
        .collect()
}

/// At rest: max |q̇| below this (rad/s) over [`REST_WINDOW`] cycles.
const REST_SPEED: f64 = 0.01;
const REST_WINDOW: usize = 100;
/// Moving again after rest: max |q̇| above this (rad/s).
const MOVING_AGAIN: f64 = 0.05;
/// The window of the short-term rise of H, in cycles (10 ms at 1 kHz).
const RISE_WINDOW: usize = 10;

/// What one goal did.
#[derive(Clone, Debug)]
struct GoalRun {
    g: usize,
    region: Region,
    /// Largest rise of H from one cycle to the next (J) and when (s).
    rise_cycle: (f64, f64),
    /// Largest rise of H within [`RISE_WINDOW`] cycles (J) and when it ended (s).
    rise_10ms: (f64, f64),
    /// Largest rise of H over the run, H_k − min_{j≤k} H_j (J), and when.
    rise: (f64, f64),
    /// H at t = 0 and at the end (J).
    h_start: f64,
    h_end: f64,
    /// The first time at rest (s; infinity: never).
    first_rest: f64,
    /// At rest for good from (s; infinity: not by the end).
    rest: f64,
    /// The first time above [`MOVING_AGAIN`] after the first rest, and the
    /// largest speed after it (rad/s).
    moved_again: Option<f64>,
    speed_after_rest: f64,
    /// Largest |q̇_k| / q̇_max,k and deepest beyond a position limit (rad; ≤ 0:
    /// inside).
    speed_ratio: f64,
    beyond: f64,
    /// Every torque finite.
    finite: bool,
}

/// A goal's course every cycle, for its figure (`UNREACHABLE_PLOT`).
#[derive(Default)]
struct Course {
    t: Vec<f64>,
    h: Vec<f64>,
    /// Per level: V_i as H counts it, the tank E_i, the valve β_i.
    potential: Vec<Vec<f64>>,
    tank: Vec<Vec<f64>>,
    valve: Vec<Vec<f64>>,
    speed: Vec<f64>,
}

impl Course {
    fn push(&mut self, t: f64, h: f64, out: &hcc_control::StepOutput, speed: f64) {
        let r = out.tank.len();
        if self.potential.is_empty() {
            self.potential = vec![Vec::new(); r];
            self.tank = vec![Vec::new(); r];
            self.valve = vec![Vec::new(); r];
        }
        self.t.push(t);
        self.h.push(h);
        for i in 0..r {
            self.potential[i].push(out.safety.level_potential[i]);
            self.tank[i].push(out.tank[i]);
            self.valve[i].push(out.tank_valve[i]);
        }
        self.speed.push(speed);
    }

    /// H, the levels' potentials, the tanks and the valves, and the largest
    /// joint speed, as `<dir>/unreachable-goal-<g>.png`.
    fn plot(&self, dir: &std::path::Path, g: usize, goal: &Goal, filtered: bool) {
        use hcc_report::TimePanel;
        std::fs::create_dir_all(dir).unwrap();
        let per_level = |name: &str, v: &[Vec<f64>], from: usize| -> Vec<(String, Vec<f64>)> {
            v.iter()
                .enumerate()
                .skip(from)
                .map(|(i, x)| (format!("{name}_{}", i + 1), x.clone()))
                .collect()
        };
        let panels = [
            TimePanel {
                title: "Storage H = kinetic + sum V_i + guard potential + tanks".into(),
                y_label: "H [J]".into(),
                series: vec![("H".into(), self.h.clone())],
            },
            TimePanel {
                title: "Each level's potential in H".into(),
                y_label: "V [J]".into(),
                series: per_level("V", &self.potential, 0),
            },
            TimePanel {
                title: "Energy tanks of levels 2 and 3".into(),
                y_label: "E [J]".into(),
                series: per_level("tank", &self.tank, 1),
            },
            TimePanel {
                title: "Tank valves (1: the paper's law)".into(),
                y_label: "valve".into(),
                series: per_level("valve", &self.valve, 1),
            },
            TimePanel {
                title: "Largest joint speed".into(),
                y_label: "max |qd| [rad/s]".into(),
                series: vec![("max |qd|".into(), self.speed.clone())],
            },
        ];
        let path = dir.join(format!("unreachable-goal-{g}.png"));
        let title = format!(
            "Unreachable sweep, goal {g} ({:?}, TCP {:.2?} m), {} torque filter",
            goal.region,
            goal.tcp,
            if filtered { "with the" } else { "without a" }
        );
        hcc_report::plot_time_series(&path, &title, &self.t, &panels).unwrap();
        println!("wrote {}", path.display());
    }
}

fn run(base: &Scenario, g: usize, goal: &Goal, seconds: f64, trace: bool) -> GoalRun {
    let mut s = base.clone();
    s.spec.levels[0].goal = DVector::from_row_slice(&goal.tcp);
    s.spec.levels[1].goal = DVector::from_row_slice(&goal.rpy);
    s.spec.levels[2].goal = DVector::from_row_slice(&goal.posture);
    if std::env::var("UNREACHABLE_FILTER").is_ok_and(|v| v == "0") {
        // The filter and what the safety layer knows of it, both off.
        s.torque_filter.torque_rate_limit = None;
        s.spec.safety.torque_rate_limit = None;
    }
    sweep_safety_overrides(&mut s);
    s.set_duration(seconds).unwrap();
    let joints = s.model.joints.clone();
    let mut r = GoalRun {
        g,
        region: goal.region,
        rise_cycle: (0.0, 0.0),
        rise_10ms: (0.0, 0.0),
        rise: (0.0, 0.0),
        h_start: f64::NAN,
        h_end: f64::NAN,
        first_rest: f64::INFINITY,
        rest: 0.0,
        moved_again: None,
        speed_after_rest: 0.0,
        speed_ratio: 0.0,
        beyond: f64::NEG_INFINITY,
        finite: true,
    };
    let mut recent: VecDeque<f64> = VecDeque::with_capacity(RISE_WINDOW + 1);
    let mut low = f64::INFINITY;
    let mut still = 0usize;
    let mut last_t = 0.0;
    let plot = std::env::var_os("UNREACHABLE_PLOT").filter(|_| trace);
    // The trace's spacing in cycles (`UNREACHABLE_EVERY`, 250 by default).
    let every: u64 = std::env::var("UNREACHABLE_EVERY")
        .ok()
        .and_then(|s| s.parse().ok())
        .unwrap_or(250)
        .max(1);
    let mut course = Course::default();
    run_observed(&s, &mut |v| {
        let (q, qd) = (v.state.q(), v.state.qd());
        let out = v.cycle.controller().output();
        let h = v.cycle.storage();
        r.finite &= v.cycle.command().tau().iter().all(|x| x.is_finite()) && h.is_finite();
        if v.k == 0 {
            r.h_start = h;
        }
        r.h_end = h;
        last_t = v.t;
        // The rise within the window: H now against the lowest of the window.
        recent.push_back(h);
        if recent.len() > RISE_WINDOW + 1 {
            recent.pop_front();
        }
        let window_low = recent.iter().copied().fold(f64::INFINITY, f64::min);
        if let Some(&before) = recent.iter().rev().nth(1)
            && h - before > r.rise_cycle.0
        {
            r.rise_cycle = (h - before, v.t);
        }
        if h - window_low > r.rise_10ms.0 {
            r.rise_10ms = (h - window_low, v.t);
        }
        low = low.min(h);
        if h - low > r.rise.0 {
            r.rise = (h - low, v.t);
        }
        let speed = qd.iter().fold(0.0_f64, |m, x| m.max(x.abs()));
        if plot.is_some() {
            course.push(v.t, h, out, speed);
        }
        if speed < REST_SPEED {
            still += 1;
        } else {
            still = 0;
            // Not at rest at t: at rest for good from 0.1 s after it at the earliest.
            r.rest = v.t + REST_WINDOW as f64 * 1e-3;
        }
        if still >= REST_WINDOW && r.first_rest.is_infinite() {
            r.first_rest = v.t;
        }
        if r.first_rest < v.t {
            r.speed_after_rest = r.speed_after_rest.max(speed);
            if speed > MOVING_AGAIN && r.moved_again.is_none() {
                r.moved_again = Some(v.t);
            }
        }
        for (k, j) in joints.iter().enumerate() {
            r.speed_ratio = r.speed_ratio.max(qd[k].abs() / j.velocity_limit);
            r.beyond = r.beyond.max(q[k] - j.upper).max(j.lower - q[k]);
        }
        if trace && v.k % every == 0 {
            println!(
                "goal {g} t {:6.3}: H {h:9.4} J V {:.4?} fade {:.3?} tank {:.3?} valve {:.3?} guard {:.4} |q̇| {speed:.4} errors {:.4?} q {:.3?} q̇ {:.3?} τ {:.2?} spring scale {:.3?} barrier {} velocity {} passivity {} unpaid {} mJ held {}",
                v.t,
                out.potential,
                out.fade,
                out.tank,
                out.tank_valve,
                out.safety.guard_potential,
                out.task_error.iter().map(|e| e.norm()).collect::<Vec<_>>(),
                q,
                qd,
                v.cycle.command().tau(),
                out.safety.spring_scale,
                out.safety.barrier_active,
                out.safety.velocity_limit_active,
                out.safety.passivity_active,
                v.cycle.counters().core.energy_unpaid_mj,
                v.cycle.counters().core.energy_held,
            );
        }
        Ok(())
    })
    .unwrap_or_else(|e| panic!("closed loop: {e}"));
    if r.rest > last_t {
        r.rest = f64::INFINITY;
    }
    if let Some(dir) = plot {
        let filtered = s.torque_filter.torque_rate_limit.is_some();
        course.plot(std::path::Path::new(&dir), g, goal, filtered);
    }
    r
}

/// Prints the sweep's figures (module docs).
fn report(runs: &[GoalRun], seconds: f64) {
    let n = runs.len().max(1) as f64;
    let worst = |f: fn(&GoalRun) -> (f64, f64)| {
        runs.iter()
            .map(|r| (f(r), r.g))
            .max_by(|a, b| a.0.0.total_cmp(&b.0.0))
            .unwrap_or(((0.0, 0.0), 0))
    };
    let ((r1, t1), g1) = worst(|r| r.rise_cycle);
    let ((r10, t10), g10) = worst(|r| r.rise_10ms);
    let ((rise, trise), grise) = worst(|r| r.rise);
    let above = |x: f64| runs.iter().filter(|r| r.rise.0 > x).count();
    println!(
        "unreachable: {} goals of {seconds} s; largest rise of H from one cycle to the next {r1:.3e} J (goal {g1}, t {t1:.3} s); largest rise of H within 10 ms {r10:.3e} J (goal {g10}, t {t10:.3} s); largest rise of H over a run {rise:.3e} J (goal {grise}, t {trise:.3} s); goals whose H rose by > 1 mJ: {}, > 0.1 J: {}, > 1 J: {}",
        runs.len(),
        above(1e-3),
        above(0.1),
        above(1.0),
    );
    let again: Vec<String> = runs
        .iter()
        .filter_map(|r| {
            r.moved_again.map(|t| {
                format!(
                    "{} ({:?}, at {t:.2} s, up to {:.2} rad/s)",
                    r.g, r.region, r.speed_after_rest
                )
            })
        })
        .collect();
    println!(
        "unreachable: moved again (> {MOVING_AGAIN} rad/s) after resting: {} goals {again:?}",
        again.len()
    );
    for (name, f) in [
        (
            "first at rest",
            (|r: &GoalRun| r.first_rest) as fn(&GoalRun) -> f64,
        ),
        ("at rest for good", |r: &GoalRun| r.rest),
    ] {
        let mut v: Vec<f64> = runs.iter().map(f).collect();
        v.sort_by(f64::total_cmp);
        let share = |t: f64| 100.0 * v.iter().filter(|&&x| x <= t).count() as f64 / n;
        println!(
            "unreachable: {name} after median {:.2} s, p95 {:.2} s, max {:.2} s; by 4 s {:.1} %, 12 s {:.1} %, {seconds} s {:.1} %",
            quantile(&v, 0.5),
            quantile(&v, 0.95),
            quantile(&v, 1.0),
            share(4.0),
            share(12.0),
            share(seconds),
        );
    }
    let not_at_rest: Vec<usize> = runs
        .iter()
        .filter(|r| r.rest.is_infinite())
        .map(|r| r.g)
        .collect();
    println!("unreachable: not at rest at the end: {not_at_rest:?}");
    println!(
        "unreachable: largest |q̇_k|/q̇_max,k {:.3}; deepest beyond a position limit {:.2e} rad (≤ 0: inside)",
        runs.iter().map(|r| r.speed_ratio).fold(0.0, f64::max),
        runs.iter()
            .map(|r| r.beyond)
            .fold(f64::NEG_INFINITY, f64::max),
    );
}

/// One goal's run, printed as an `unreachable-goal` line when `line`.
fn run_goal(
    base: &Scenario,
    g: usize,
    goal: &Goal,
    seconds: f64,
    only: bool,
    line: bool,
) -> GoalRun {
    let r = run(base, g, goal, seconds, only);
    if line {
        println!(
            "unreachable-goal {g} {:?} tcp {:.3?} rpy {:.3?} posture {:.2?}: H {:.4} → {:.4} J; rise per cycle {:.3e} J at {:.3} s; rise 10 ms {:.3e} J at {:.3} s; rise {:.3e} J at {:.3} s; first rest {:.2} s; rest {:.2} s; moved again {:?} (up to {:.3} rad/s); |q̇|/limit {:.3}; beyond {:.2e} rad",
            r.region,
            goal.tcp,
            goal.rpy,
            goal.posture,
            r.h_start,
            r.h_end,
            r.rise_cycle.0,
            r.rise_cycle.1,
            r.rise_10ms.0,
            r.rise_10ms.1,
            r.rise.0,
            r.rise.1,
            r.first_rest,
            r.rest,
            r.moved_again,
            r.speed_after_rest,
            r.speed_ratio,
            r.beyond,
        );
    }
    r
}

#[test]
fn unreachable_goals_energy_and_rest() {
    let env = |k: &str| std::env::var(k).ok();
    let n: usize = env("UNREACHABLE_GOALS")
        .and_then(|s| s.parse().ok())
        .unwrap_or(24);
    let seconds: f64 = env("UNREACHABLE_SECONDS")
        .and_then(|s| s.parse().ok())
        .unwrap_or(30.0);
    let only: Option<usize> = env("UNREACHABLE_ONLY").and_then(|s| s.parse().ok());
    let shard: Option<(usize, usize)> = env("UNREACHABLE_SHARD").and_then(|s| {
        let (i, n) = s.split_once('/')?;
        Some((i.parse().ok()?, n.parse().ok()?))
    });
    // `UNREACHABLE_THREADS=k`: the goals on k threads (one per core), merged here.
    let threads: usize = env("UNREACHABLE_THREADS")
        .and_then(|s| s.parse().ok())
        .unwrap_or(1)
        .max(1);
    let base = load("panda-pose-posture.toml");
    let goals = goals(&base.model.joints, n.max(only.map_or(0, |g| g + 1)));
    let todo: Vec<(usize, &Goal)> = goals
        .iter()
        .enumerate()
        .filter(|(g, _)| only.is_none_or(|o| o == *g) && shard.is_none_or(|(i, n)| g % n == i))
        .collect();
    let lines = shard.is_some() || only.is_some() || threads > 1;
    let runs = on_threads(&todo, threads, |&(g, goal)| {
        run_goal(&base, g, goal, seconds, only.is_some(), lines)
    });
    report(&runs, seconds);

    let filtered = !std::env::var("UNREACHABLE_FILTER").is_ok_and(|v| v == "0");
    let known = if filtered {
        &WITH_FILTER
    } else {
        &WITHOUT_FILTER
    };
    for r in &runs {
        let g = r.g;
        assert!(r.finite, "goal {g}: a non-finite torque or H");
        // Inside the position limits, at most at 0.95 of a velocity limit
        // (but the known exceptions: at 0.951, up to 0.01 rad beyond).
        let ratio = if known.past_a_limit.contains(&g) {
            0.952
        } else {
            0.95
        };
        let beyond = if known.beyond_a_limit.contains(&g) {
            0.01
        } else {
            0.0
        };
        assert!(
            r.beyond <= beyond,
            "goal {g}: {} rad beyond a limit",
            r.beyond
        );
        assert!(
            r.speed_ratio <= ratio,
            "goal {g}: a joint at {:.3} × its velocity limit",
            r.speed_ratio
        );
        // The storage H rises by no more than what is not booked yet (the
        // velocity limits, the guard; with a filter, its lag).
        let (within_10ms, over_a_run) = known.rise;
        assert!(
            r.rise_cycle.0 <= known.rise_per_cycle,
            "goal {g}: H rose by {} J from one cycle to the next at {} s",
            r.rise_cycle.0,
            r.rise_cycle.1
        );
        assert!(
            r.rise_10ms.0 <= within_10ms,
            "goal {g}: H rose by {} J within 10 ms at {} s",
            r.rise_10ms.0,
            r.rise_10ms.1
        );
        assert!(
            r.rise.0 <= over_a_run,
            "goal {g}: H rose by {} J at {} s",
            r.rise.0,
            r.rise.1
        );
        if seconds >= 30.0 {
            assert!(
                r.rest <= 30.0 || known.not_at_rest.contains(&g),
                "goal {g}: not at rest by 30 s"
            );
            assert!(
                r.moved_again.is_none() || known.moves_again.contains(&g),
                "goal {g}: moved again after resting, at {:?} s",
                r.moved_again
            );
        }
    }
}

/// What the 200 goals do that the targets do not allow yet, with
/// the energy tanks: the exceptions and the largest rises of H.
struct Known {
    /// Goals at up to 0.951 of a velocity limit.
    past_a_limit: &'static [usize],
    /// Goals up to 0.01 rad beyond a position limit.
    beyond_a_limit: &'static [usize],
    /// Goals not at rest by 30 s.
    not_at_rest: &'static [usize],
    /// Goals that move again after resting.
    moves_again: &'static [usize],
    /// The largest rise of H within 10 ms and over a run (J).
    rise: (f64, f64),
    /// The largest rise of H from one cycle to the next (J).
    rise_per_cycle: f64,
}

/// With the shipped torque filter: what its lag feeds in is paid from the
/// output stages' tank, then from what the fade's and the levels' tanks hold
/// to spare (hcc-cycle's `output_tank`), and held back when all are empty;
/// but where the rate limit cannot build a torque the law changes faster than
/// 1000 N·m/s (the joint-limit guard's spring at speed, the governor's scale)
/// the lag still feeds energy in while every tank is empty: H rises by up to
/// 2.0 J within 10 ms, 10.7 J over a run and 0.20 J from one cycle to the
/// next (goal 58, swinging between joint 1's and joint 2's guards), and 103
/// reaches 0.951 of a velocity limit. No
/// goal past a position limit, none moves again, every goal at rest by 14 s.
const WITH_FILTER: Known = Known {
    past_a_limit: &[103],
    beyond_a_limit: &[],
    not_at_rest: &[],
    moves_again: &[],
    rise: (2.5, 12.0),
    rise_per_cycle: 0.25,
};

/// Without a filter: every goal at rest by 15 s, none moves again; H rises
/// by at most 0.15 J over a run (goal 186) and 4.5 mJ from one cycle to the
/// next (goal 4: the explicit integration of the sampled loop).
const WITHOUT_FILTER: Known = Known {
    past_a_limit: &[],
    beyond_a_limit: &[],
    not_at_rest: &[],
    moves_again: &[],
    rise: (0.01, 0.2),
    rise_per_cycle: 0.005,
};
