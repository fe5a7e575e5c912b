//! At the edge of the workspace and in conflicting hierarchies the arm comes to
//! rest (the safety layer of hcc-control, hcc_control::safety, and the plant's end
//! stops): the shipped singular scenarios run for 8 s, the Panda with a TCP goal
//! out of reach and a posture beyond its limits, and a seeded sweep of Panda goals.
//! The figures are printed (`--nocapture`) and quoted in docs/limits-and-singularities.md.

use std::path::PathBuf;

use hcc_config::Scenario;
use hcc_simulation::{CycleView, simulate_observed};
use nalgebra::{DMatrix, DVector};

fn load(name: &str) -> Scenario {
    let path = PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("../../config")
        .join(name);
    Scenario::load(&path).unwrap_or_else(|e| panic!("{e}"))
}

/// One cycle of a run.
#[derive(Clone, Debug)]
struct Sample {
    t: f64,
    q: Vec<f64>,
    qd: Vec<f64>,
    energy: f64,
    errors: Vec<f64>,
    finite: bool,
    guard: bool,
    velocity: bool,
    max_tau_rate: f64,
    /// A level faded, or the null-space damping acted.
    faded: bool,
    /// The velocity governor's gain g.
    governor: f64,
    /// The spring saturation capped a level's spring.
    saturated: bool,
    /// The conflict fade acted.
    conflict: bool,
    /// |τ − τ_twin| (largest joint): the torque a part of the safety layer changed,
    /// against a twin controller without it stepped on the same states (0 without a
    /// twin).
    twin_tau: f64,
    /// Largest |d(τ − τ_twin)/dt| over the joints (N·m/s).
    twin_rate: f64,
    /// Per level: its conditioning (`StepOutput::conditioning`).
    conditioning: Vec<f64>,
}

/// The log of a run of the control cycle (the daemon's), per cycle.
struct Logged {
    period_s: f64,
    prev_safety: DVector<f64>,
    /// The same controller without a part of the safety layer, stepped on the same states.
    twin: Option<hcc_control::Controller>,
    prev_twin: DVector<f64>,
    log: Vec<Sample>,
}

impl Logged {
    /// Logs the cycle `v` (its law's output after the step at its state).
    fn observe(&mut self, v: &CycleView<'_>) {
        let (q, qd) = (v.state.q(), v.state.qd());
        let out = v.cycle.controller().output();
        let rate = (&out.safety.tau - &self.prev_safety).amax() / self.period_s;
        self.prev_safety.copy_from(&out.safety.tau);
        let (mut twin_tau, mut twin_rate) = (0.0, 0.0);
        if let Some(twin) = &mut self.twin {
            let t = twin.step(q, qd).unwrap();
            let d = &out.tau - &t.tau;
            twin_tau = d.amax();
            twin_rate = (&d - &self.prev_twin).amax() / self.period_s;
            self.prev_twin.copy_from(&d);
        }
        self.log.push(Sample {
            t: v.t,
            q: q.to_vec(),
            qd: qd.to_vec(),
            energy: out.safety.energy,
            errors: out.task_error.iter().map(|e| e.norm()).collect(),
            finite: out.tau.iter().all(|x| x.is_finite()),
            guard: out.safety.joint_limit_active,
            velocity: out.safety.velocity_limit_active,
            max_tau_rate: rate,
            faded: out.safety.null_space_damping_active || out.fade.iter().any(|&b| b < 1.0),
            governor: out.safety.velocity_governor,
            saturated: out.safety.spring_saturated,
            conflict: out.safety.conflict_fade_active,
            twin_tau,
            twin_rate,
            conditioning: out.conditioning.clone(),
        });
    }
}

fn run(scenario: Scenario, duration_s: f64) -> Vec<Sample> {
    run_logged(scenario, duration_s, None)
}

/// The twin of the velocity limits: without the governor and the velocity damping.
fn without_velocity_limits(s: &mut hcc_control::SafetySpec) {
    s.velocity_governor = false;
    s.velocity_damping = 0.0;
}

/// The twin of the conflict fade: without it.
fn without_conflict_fade(s: &mut hcc_control::SafetySpec) {
    s.conflict_fade_ratio = 0.0;
}

/// [`run`]; `twin`: also step a controller whose safety layer `twin` changed on
/// the same states (for the torque of what it removed and its rate).
fn run_logged(
    mut scenario: Scenario,
    duration_s: f64,
    twin: Option<fn(&mut hcc_control::SafetySpec)>,
) -> Vec<Sample> {
    scenario.set_duration(duration_s).unwrap();
    let n = scenario.model.nq();
    let twin = twin.map(|change| {
        let mut spec = scenario.spec.clone();
        change(&mut spec.safety);
        hcc_control::Controller::new(&scenario.model, spec, &scenario.q0).unwrap()
    });
    let mut logged = Logged {
        period_s: 1.0 / scenario.simulation.control_rate_hz,
        prev_safety: DVector::zeros(n),
        twin,
        prev_twin: DVector::zeros(n),
        log: Vec::new(),
    };
    simulate_observed(&scenario, &mut |v| {
        logged.observe(v);
        Ok(())
    })
    .unwrap_or_else(|e| panic!("closed loop: {e}"));
    logged.log
}

fn max_speed(log: &[Sample], from: f64) -> f64 {
    log.iter()
        .filter(|s| s.t >= from)
        .flat_map(|s| s.qd.iter().map(|x| x.abs()))
        .fold(0.0, f64::max)
}

/// Largest rise of E over any window after `from` (0 if E never grows).
fn energy_rise(log: &[Sample], from: f64) -> f64 {
    let mut low = f64::INFINITY;
    let mut rise: f64 = 0.0;
    for s in log.iter().filter(|s| s.t >= from) {
        low = low.min(s.energy);
        rise = rise.max(s.energy - low);
    }
    rise
}

fn report_singular(name: &str, log: &[Sample], reach_gap: f64) {
    let speeds: Vec<String> = [1.0, 2.0, 4.0, 6.0, 8.0]
        .iter()
        .map(|&t| {
            let s = log
                .iter()
                .min_by(|a, b| (a.t - t).abs().total_cmp(&(b.t - t).abs()))
                .unwrap();
            format!("{:.2e}", s.qd.iter().map(|x| x.abs()).fold(0.0, f64::max))
        })
        .collect();
    let last = log.last().unwrap();
    println!(
        "{name}: max |q̇| at 1/2/4/6/8 s: {}; max |q̇| from 4 s {:.2e} rad/s; E at 1/8 s {:.4}/{:.4} J, largest rise of E after 2 s {:.2e} J (after 1 s {:.2e} J); level-1 error at 8 s {:.5} m (closest reachable {reach_gap:.5} m)",
        speeds.join(" / "),
        max_speed(log, 4.0),
        log.iter().find(|s| s.t >= 1.0).unwrap().energy,
        last.energy,
        energy_rise(log, 2.0),
        energy_rise(log, 1.0),
        last.errors[0],
    );
}

/// With `HCC_ENERGY_PLOTS=<dir>` set: the total energy E of a run (and the same
/// from 2 s on, and the largest joint speed) as `<dir>/energy-<name>.png` (the
/// figures of docs/limits-and-singularities.md).
fn energy_plot(name: &str, title: &str, log: &[Sample]) {
    let Some(dir) = std::env::var_os("HCC_ENERGY_PLOTS") else {
        return;
    };
    let dir = PathBuf::from(dir);
    std::fs::create_dir_all(&dir).unwrap();
    let t: Vec<f64> = log.iter().map(|s| s.t).collect();
    let e: Vec<f64> = log.iter().map(|s| s.energy).collect();
    let end = log.last().map_or(0.0, |s| s.energy);
    let late: Vec<f64> = log
        .iter()
        .map(|s| {
            if s.t >= 2.0 {
                1e3 * (s.energy - end)
            } else {
                f64::NAN
            }
        })
        .collect();
    let speed: Vec<f64> = log
        .iter()
        .map(|s| s.qd.iter().map(|x| x.abs()).fold(0.0, f64::max).log10())
        .collect();
    let panel = |title: &str, y: &str, label: &str, v: Vec<f64>| hcc_report::TimePanel {
        title: title.into(),
        y_label: y.into(),
        series: vec![(label.into(), v)],
    };
    let path = dir.join(format!("energy-{name}.png"));
    hcc_report::plot_time_series(
        &path,
        title,
        &t,
        &[
            panel(
                "Total energy E = kinetic + V_1 + sum beta_i V_i (+ guard potential)",
                "E [J]",
                "E",
                e,
            ),
            panel(
                &format!("E from t = 2 s, relative to its final value {end:.4} J"),
                "E - E(end) [mJ]",
                "E - E(end)",
                late,
            ),
            panel(
                "Largest joint speed",
                "log10 max |qd| [rad/s]",
                "log10 max |qd|",
                speed,
            ),
        ],
    )
    .unwrap();
    println!("wrote {}", path.display());
}

#[test]
fn stretched_out_towards_a_goal_out_of_reach_the_arm_comes_to_rest() {
    let log = run(load("planar-singular-stretch.toml"), 8.0);
    // The goal (1.25, 1.625) is 2.0500 m from the base, the arm 2.0 m long.
    let gap = (1.25f64.hypot(1.625)) - 2.0;
    report_singular("stretch", &log, gap);
    energy_plot(
        "planar-singular-stretch",
        "planar-singular-stretch.toml, 8 s: TCP goal 5 cm out of reach",
        &log,
    );
    assert!(log.iter().all(|s| s.finite));
    assert!(max_speed(&log, 4.0) < 0.01);
    assert!((log.last().unwrap().errors[0] - gap).abs() < 1e-3);
    assert!(energy_rise(&log, 2.0) < 1e-3);
}

#[test]
fn conflicting_levels_the_arm_comes_to_rest() {
    let log = run(load("planar-algorithmic-singularity.toml"), 8.0);
    report_singular("algorithmic", &log, 0.0);
    energy_plot(
        "planar-algorithmic-singularity",
        "planar-algorithmic-singularity.toml, 8 s: level 2 in conflict with level 1",
        &log,
    );
    assert!(log.iter().all(|s| s.finite));
    assert!(max_speed(&log, 4.0) < 0.01);
    assert!(log.last().unwrap().errors[0] < 1e-3);
    assert!(energy_rise(&log, 2.0) < 1e-3);
}

/// The Panda scenario with the TCP goal `tcp` and the posture goal `posture`
/// (the safety layer's defaults).
fn panda(tcp: [f64; 3], posture: &[f64]) -> Scenario {
    let mut s = load("panda-pose-posture.toml");
    s.spec.levels[0].goal = DVector::from_row_slice(&tcp);
    s.spec.levels[2].goal = DVector::from_row_slice(posture);
    s
}

/// The onset of what the twin lacks (the first cycle in which `acts`): |dτ/dt| of
/// the torque it changed in its first five cycles, the largest |dτ/dt| and the
/// largest torque change of the run.
fn twin_figures(log: &[Sample], acts: fn(&Sample) -> bool) -> (Vec<f64>, f64, f64) {
    let first = log.iter().position(acts);
    let onset = first
        .map(|k| log[k..].iter().take(5).map(|s| s.twin_rate).collect())
        .unwrap_or_default();
    let rate = log.iter().map(|s| s.twin_rate).fold(0.0, f64::max);
    let tau = log.iter().map(|s| s.twin_tau).fold(0.0, f64::max);
    (onset, rate, tau)
}

/// Joint limit violations and the largest |q̇_k| / velocity limit of a run.
fn limit_figures(scenario: &Scenario, log: &[Sample]) -> (f64, f64) {
    let joints = &scenario.model.joints;
    let mut beyond: f64 = 0.0;
    let mut speed: f64 = 0.0;
    for s in log {
        for (k, j) in joints.iter().enumerate() {
            beyond = beyond.max(s.q[k] - j.upper).max(j.lower - s.q[k]);
            speed = speed.max(s.qd[k].abs() / j.velocity_limit);
        }
    }
    (beyond, speed)
}

#[test]
fn panda_out_of_reach_and_posture_beyond_limits_comes_to_rest_inside_the_limits() {
    // 1.3 m from the base; joints 4 and 6 asked beyond their upper limits
    // (−0.0698 and 3.7525 rad).
    let tcp = [1.2, 0.3, 0.4];
    let posture = [0.0, -0.3, 0.0, 0.3, 0.0, 4.0, 0.8];
    let scenario = panda(tcp, &posture);
    let log = run_logged(scenario.clone(), 6.0, Some(without_velocity_limits));
    let (beyond, speed) = limit_figures(&scenario, &log);
    let guard = log.iter().filter(|s| s.guard).count();
    let vel = log.iter().filter(|s| s.velocity).count();
    let sat = log.iter().filter(|s| s.saturated).count();
    let rate = log.iter().map(|s| s.max_tau_rate).fold(0.0, f64::max);
    let (onset, gov_rate, gov_tau) = twin_figures(&log, |s| s.governor > 0.0);
    let last = log.last().unwrap();
    println!(
        "panda 1.3 m: max |q̇| from 4 s {:.2e} rad/s; deepest beyond a limit {beyond:.2e} rad; largest |q̇|/limit {speed:.3}; guard cycles {guard}, spring-saturation cycles {sat}, velocity-limit cycles {vel}; largest |dτ_safety/dt| {rate:.0} N·m/s; governor: |dτ/dt| in its first 5 cycles {onset:.3?} N·m/s, largest {gov_rate:.0} N·m/s, largest torque change {gov_tau:.2} N·m; final q {:.3?}; final TCP error {:.3} m",
        max_speed(&log, 4.0),
        last.q,
        last.errors[0]
    );
    assert!(log.iter().all(|s| s.finite));
    assert!(max_speed(&log, 4.0) < 0.01);
    assert!(beyond <= 0.0, "a joint beyond its limit by {beyond} rad");
    assert!(speed < 1.0, "a joint at {speed} × its velocity limit");
    // Smooth onset: the first cycle's rate a small part of the largest, and the
    // largest under the output pipeline's usual rate limit (1000 N·m/s).
    assert!(onset[0] < 0.1 * gov_rate, "a torque jump at the onset");
    assert!(gov_rate < 1000.0, "velocity limits: {gov_rate} N·m/s");
}

/// A TCP goal the Panda reaches only with its elbow stretched, and the hand asked to
/// point down: the orientation level loses a direction to the TCP level (its own Λ_2
/// near-singular, an algorithmic conflict). The conflict fade takes its spring out
/// (the null-space damping in its place): the arm comes to rest, without a torque
/// jump (against a twin controller without the conflict fade on the same states).
#[test]
fn a_level_in_conflict_fades_out_and_the_arm_comes_to_rest() {
    let tcp = [-0.15, 0.68, 0.78];
    let posture = [1.01, 0.98, -2.99, -1.89, -2.49, 0.78, -3.09];
    let scenario = panda(tcp, &posture);
    let log = run_logged(scenario.clone(), 4.0, Some(without_conflict_fade));
    let (beyond, speed) = limit_figures(&scenario, &log);
    let conflict = log.iter().filter(|s| s.conflict).count();
    let first = log.iter().find(|s| s.conflict).map_or(f64::NAN, |s| s.t);
    let (onset, rate, tau) = twin_figures(&log, |s| s.conflict);
    let last = log.last().unwrap();
    let mut without = scenario.clone();
    without_conflict_fade(&mut without.spec.safety);
    let without = run(without, 4.0);
    println!(
        "conflict: without the conflict fade max |q̇| over the last 0.1 s {:.2e} rad/s, orientation error {:.4} rad",
        max_speed(&without, 3.9),
        without.last().unwrap().errors[1]
    );
    println!(
        "conflict: the conflict fade from t = {first:.3} s, in {conflict} cycles; |dτ/dt| in its first 5 cycles {onset:.3?} N·m/s, largest {rate:.0} N·m/s, largest torque change {tau:.2} N·m; max |q̇| over the last 0.1 s {:.2e} rad/s (from 3 s {:.2e}); largest rise of E after 2 s {:.2e} J; errors at the end {:.4?}; conditioning {:?}; largest |q̇|/limit {speed:.2}",
        max_speed(&log, 3.9),
        max_speed(&log, 3.0),
        energy_rise(&log, 2.0),
        last.errors,
        last.conditioning
            .iter()
            .map(|c| format!("{c:.2e}"))
            .collect::<Vec<_>>(),
    );
    assert!(log.iter().all(|s| s.finite));
    assert!(conflict > 0, "the conflict fade never acted");
    assert!(beyond <= 0.0);
    assert!(max_speed(&log, 3.9) < 0.01, "not at rest");
    assert!(onset[0] < 0.1 * rate, "a torque jump at the onset");
}

/// A small deterministic generator (xorshift64*), uniform in [0, 1).
struct Rng(u64);

impl Rng {
    fn next(&mut self) -> f64 {
        self.0 ^= self.0 >> 12;
        self.0 ^= self.0 << 25;
        self.0 ^= self.0 >> 27;
        (self.0.wrapping_mul(0x2545_f491_4f6c_dd1d) >> 11) as f64 / (1u64 << 53) as f64
    }
    fn range(&mut self, lo: f64, hi: f64) -> f64 {
        lo + (hi - lo) * self.next()
    }
}

/// Why a sweep goal is not settled (at rest or converged) at the end of its run.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord)]
enum Unsettled {
    /// Still moving (≥ 0.1 rad/s over the last 0.1 s), levels 1 and 2 not yet at
    /// their goals (or their closest points): the move itself is not over.
    Travelling,
    /// Moving, levels 1 and 2 converged (TCP within 5 mm, orientation within
    /// 50 mrad): the posture level still swings in their null space.
    PostureSwinging,
    /// A joint within the guard's margin of a limit (the guard acting at the end).
    AtJointLimit,
    /// Slower than 0.1 rad/s with level 1 singular (TCP goal at or beyond the reach
    /// boundary).
    CreepReachBoundary,
    /// Slower than 0.1 rad/s with level 2 in an algorithmic conflict (its own Λ_2
    /// singular, level 1 regular).
    CreepConflict,
    /// Slower than 0.1 rad/s, no singularity, no limit.
    CreepOther,
}

/// The class of an unsettled run (see [`Unsettled`]); `eps` the singular ratio ε
/// (the fade region is ε … 100 ε).
fn classify(log: &[Sample], seconds: f64, eps: f64) -> Unsettled {
    let last = log.last().unwrap();
    let speed = max_speed(log, seconds - 0.1);
    let singular = |i: usize| last.conditioning[i] < 100.0 * eps;
    if last.guard {
        Unsettled::AtJointLimit
    } else if speed >= 0.1 {
        if last.errors[0] < 5e-3 && last.errors[1] < 5e-2 {
            Unsettled::PostureSwinging
        } else {
            Unsettled::Travelling
        }
    } else if singular(0) {
        Unsettled::CreepReachBoundary
    } else if singular(1) {
        Unsettled::CreepConflict
    } else {
        Unsettled::CreepOther
    }
}

/// When a run settles for good: the first time t from which every later sample
/// is at rest (max abs(q̇) < 0.01 rad/s over the preceding 0.1 s) or converged
/// (TCP < 1 mm, orientation < 10 mrad); infinity if the last one is neither.
fn settle_time(log: &[Sample]) -> f64 {
    let ok = |i: usize| {
        let s = &log[i];
        let recent = log[..=i]
            .iter()
            .rev()
            .take_while(|p| p.t > s.t - 0.1)
            .flat_map(|p| p.qd.iter().map(|x| x.abs()))
            .fold(0.0, f64::max);
        recent < 0.01 || (s.errors[0] < 1e-3 && s.errors[1] < 1e-2)
    };
    let mut t = f64::INFINITY;
    for i in (0..log.len()).rev() {
        if !ok(i) {
            break;
        }
        t = log[i].t;
    }
    t
}

/// The shortest time in which the joints can cover the distance from `q0` to `q`
/// with every joint at `fraction` of its URDF velocity limit (max_k |Δq_k| / (f v_k)).
fn shortest_move(joints: &[hcc_model::Joint], q0: &[f64], q: &[f64], fraction: f64) -> f64 {
    joints
        .iter()
        .enumerate()
        .map(|(k, j)| (q[k] - q0[k]).abs() / (fraction * j.velocity_limit))
        .fold(0.0, f64::max)
}

/// Seeded random Panda goals, 3 s each from the scenario's start: TCP goals from
/// 0.3 m to 1.4 m from the shoulder (within and beyond reach), posture goals up
/// to 0.5 rad beyond the limits of every joint. `SWEEP_GOALS` goals (default 100
/// here; `SWEEP_GOALS=500 cargo test --release -p hcc-plant --test
/// limits_and_singularities sweep -- --nocapture` runs the full sweep;
/// `SWEEP_SECONDS` sets the time per goal, `SWEEP_DETAIL` prints every goal not
/// settled and every one over a velocity limit, `SWEEP_SAFETY` changes `[safety]`
/// fields for a comparison, e.g. `conflict_fade_ratio=0,null_space_damping=50`,
/// `SWEEP_DAMPING` the levels' damping, e.g. `60,4,6`: D_i = that × I;
/// `SWEEP_GAIN_SCALE=s` every level s times faster, K_i × s², D_i × s;
/// `SWEEP_SINGULAR_RATIO` the singular ratio ε of `[controller.singularity]`;
/// `SWEEP_ONLY=g` runs goal g alone and prints its course every 0.5 s;
/// `SWEEP_HORIZON=T` runs each goal for T s as well and prints, for the goals
/// not settled in time, when they settle for good and how far their end
/// configuration is from the start at the URDF velocity limits).
/// Every goal not settled is classified ([`Unsettled`]). With the defaults (3 s,
/// at least 100 goals, no `SWEEP_SAFETY`) at least 35 % must settle: 43 % of the
/// first 100 goals and 42.8 % of 500 do with the conflict fade (31 % and 31.6 %
/// without it, with the joint damping at 50 1/s), so the floor catches a loss of
/// the conflict fade, with 8 goals in 100 of margin for numerical differences of a
/// chaotic sweep.
#[test]
fn sweep_of_random_panda_goals_no_nan_no_joint_beyond_its_limits() {
    let goals: usize = std::env::var("SWEEP_GOALS")
        .ok()
        .and_then(|s| s.parse().ok())
        .unwrap_or(100);
    // `SWEEP_SECONDS`: the time each goal has (default 3 s).
    let seconds: f64 = std::env::var("SWEEP_SECONDS")
        .ok()
        .and_then(|s| s.parse().ok())
        .unwrap_or(3.0);
    let base = load("panda-pose-posture.toml");
    let joints = base.model.joints.clone();
    let mut rng = Rng(0x5eed_1234_abcd_0001);
    let (mut settled, mut worst_beyond, mut worst_speed) = (0, f64::NEG_INFINITY, 0.0f64);
    let mut unsettled = Vec::new();
    let eps = base.spec.singular_ratio;
    let mut classes = std::collections::BTreeMap::new();
    let mut travel_min = Vec::new();
    let mut overridden = false;
    // `SWEEP_HORIZON`: also run each goal this long (s) and report, for the goals
    // not settled by `seconds`, whether they settle by then and how far their end
    // configuration is from the start at the URDF velocity limits.
    let horizon: f64 = std::env::var("SWEEP_HORIZON")
        .ok()
        .and_then(|s| s.parse().ok())
        .unwrap_or(0.0);
    let mut late = Vec::new();
    // `SWEEP_ONLY=g`: run goal g alone (the others drawn, not run) and print its
    // course once a second.
    let only: Option<usize> = std::env::var("SWEEP_ONLY")
        .ok()
        .and_then(|s| s.parse().ok());
    for g in 0..goals {
        let radius = rng.range(0.3, 1.4);
        let (az, el) = (rng.range(-3.1, 3.1), rng.range(-0.8, 1.2));
        let tcp = [
            radius * el.cos() * az.cos(),
            radius * el.cos() * az.sin(),
            0.333 + radius * el.sin(),
        ];
        let posture: Vec<f64> = joints
            .iter()
            .map(|j| rng.range(j.lower - 0.5, j.upper + 0.5))
            .collect();
        if only.is_some_and(|o| o != g) {
            continue;
        }
        let mut scenario = panda(tcp, &posture);
        overridden = sweep_safety_overrides(&mut scenario);
        if let Ok(v) = std::env::var("SWEEP_DAMPING") {
            for (l, x) in v.split(',').enumerate() {
                let x: f64 = x.parse().unwrap();
                let m = scenario.spec.levels[l].damping.nrows();
                scenario.spec.levels[l].damping = DMatrix::identity(m, m) * x;
            }
            overridden = true;
        }
        if let Ok(v) = std::env::var("SWEEP_SINGULAR_RATIO") {
            // The singular ratio ε of `[controller.singularity]` (fade region ε … 100 ε).
            scenario.spec.singular_ratio = v.parse().unwrap();
            overridden = true;
        }
        if let Ok(v) = std::env::var("SWEEP_GAIN_SCALE") {
            // Every level s times faster: K_i × s², D_i × s (the damping ratios kept).
            let x: f64 = v.parse().unwrap();
            for l in &mut scenario.spec.levels {
                l.stiffness *= x * x;
                l.damping *= x;
            }
            overridden = true;
        }
        let full = run(scenario.clone(), seconds.max(horizon));
        // The run up to `seconds` (the simulation is deterministic: a longer run
        // has the shorter one as its prefix).
        let cut = if horizon > seconds {
            full.partition_point(|s| s.t < seconds - 1e-9)
        } else {
            full.len()
        };
        let log = &full[..cut];
        assert!(full.iter().all(|s| s.finite), "goal {g}: a NaN");
        if only.is_some() {
            for smp in full.iter().step_by(500) {
                println!(
                    "goal {g} t {:5.1}: |q̇| {:.3?} E {:.3} errors {:.4?} conditioning {:?} faded {} guard {} governor {:.2} q {:.2?}",
                    smp.t,
                    smp.qd.iter().map(|x| x.abs()).collect::<Vec<_>>(),
                    smp.energy,
                    smp.errors,
                    smp.conditioning
                        .iter()
                        .map(|c| format!("{c:.1e}"))
                        .collect::<Vec<_>>(),
                    smp.faded,
                    smp.guard,
                    smp.governor,
                    smp.q
                );
            }
        }
        let (beyond, speed) = limit_figures(&scenario, &full);
        worst_beyond = worst_beyond.max(beyond);
        worst_speed = worst_speed.max(speed);
        // With the safety layer switched off (`SWEEP_SAFETY=enabled=0`, the paper's
        // law alone) nothing keeps the joints inside: the end stops are counted, not asserted.
        assert!(
            beyond <= 0.0 || !scenario.spec.safety.enabled,
            "goal {g}: a joint {beyond} rad beyond its limit"
        );
        if std::env::var_os("SWEEP_DETAIL").is_some() && speed > 1.0 {
            let (mut best, mut at) = (0.0, (0, 0));
            for (c, smp) in full.iter().enumerate() {
                for (k, j) in joints.iter().enumerate() {
                    let r = smp.qd[k].abs() / j.velocity_limit;
                    if r > best {
                        best = r;
                        at = (c, k);
                    }
                }
            }
            let smp = &full[at.0];
            println!(
                "goal {g}: speed {best:.2} × limit at joint {} t = {:.3} s; guard {} faded {} governor {:.2} saturated {}; q {:.2?}",
                at.1 + 1,
                smp.t,
                smp.guard,
                smp.faded,
                smp.governor,
                smp.saturated,
                smp.q
            );
        }
        let rest = max_speed(log, seconds - 0.1) < 0.01;
        let last = log.last().unwrap();
        let converged = last.errors[0] < 1e-3 && last.errors[1] < 1e-2;
        if rest || converged {
            settled += 1;
        } else {
            let class = classify(log, seconds, eps);
            let q0: Vec<f64> = scenario.q0.iter().copied().collect();
            let t_min = shortest_move(&joints, &q0, &last.q, 0.9);
            if horizon > seconds {
                // Where the goal settles given the horizon, and whether any motion
                // within the URDF velocity limits could have got there by `seconds`.
                let end = full.last().unwrap();
                let settled_late = max_speed(&full, horizon - 0.1) < 0.01
                    || (end.errors[0] < 1e-3 && end.errors[1] < 1e-2);
                let reach = shortest_move(&joints, &q0, &end.q, 1.0);
                late.push((g, class, settled_late, reach, settle_time(&full)));
            }
            *classes.entry(class).or_insert(0usize) += 1;
            if class == Unsettled::Travelling {
                travel_min.push(t_min);
            }
            unsettled.push((
                g,
                class,
                max_speed(log, seconds - 0.1),
                last.errors[0],
                last.errors[1],
                radius,
            ));
            if std::env::var_os("SWEEP_DETAIL").is_some() {
                let at = |t: f64| log.iter().find(|s| s.t >= t).unwrap_or(last);
                println!(
                    "goal {g}: tcp {tcp:.3?} posture {posture:.2?}; |q̇| at 1/2/3 s {:.3}/{:.3}/{:.3}; errors {:.4?}; conditioning {:?}; faded {} guard {} governor {:.2}; q {:.3?}; q̇ {:.3?}",
                    at(1.0).qd.iter().map(|x| x.abs()).fold(0.0, f64::max),
                    at(2.0).qd.iter().map(|x| x.abs()).fold(0.0, f64::max),
                    last.qd.iter().map(|x| x.abs()).fold(0.0, f64::max),
                    last.errors,
                    last.conditioning
                        .iter()
                        .map(|c| format!("{c:.2e}"))
                        .collect::<Vec<_>>(),
                    last.faded,
                    last.guard,
                    last.governor,
                    last.q,
                    last.qd,
                );
            }
        }
    }
    println!(
        "sweep: {goals} goals, {settled} at rest or converged by {seconds} s ({:.1} %); deepest beyond a limit {worst_beyond:.3e} rad (≤ 0: inside); largest |q̇|/limit {worst_speed:.2}; not settled (goal, class, max |q̇| over the last 0.1 s, TCP and orientation errors, TCP goal radius): {unsettled:.3?}",
        100.0 * settled as f64 / goals as f64
    );
    travel_min.sort_by(f64::total_cmp);
    println!(
        "sweep: not settled by class {classes:?}; travelling: shortest time from the start to where they are at 0.9 of the velocity limits {travel_min:.2?} s"
    );
    if horizon > seconds {
        let settled_late: Vec<_> = late.iter().filter(|l| l.2).collect();
        let out_of_time = settled_late.iter().filter(|l| l.3 > seconds).count();
        let mut by_class = std::collections::BTreeMap::new();
        for l in &settled_late {
            let e = by_class.entry(l.1).or_insert((0usize, 0usize));
            e.0 += 1;
            if l.3 > seconds {
                e.1 += 1;
            }
        }
        let mut reach: Vec<f64> = settled_late.iter().map(|l| l.3).collect();
        reach.sort_by(f64::total_cmp);
        let mut times = std::collections::BTreeMap::new();
        for l in &late {
            times.entry(l.1).or_insert_with(Vec::new).push(l.4);
        }
        let never: Vec<_> = late.iter().filter(|l| !l.2).map(|l| (l.0, l.1)).collect();
        println!("sweep: not settled by {horizon} s (goal, class at {seconds} s): {never:?}");
        for (class, t) in &mut times {
            t.sort_by(f64::total_cmp);
            println!("sweep: {class:?}: settled at {t:.1?} s (inf: not by {horizon} s)");
        }
        println!(
            "sweep: of the {} goals not settled by {seconds} s, {} settle by {horizon} s; of those, {out_of_time} end where no motion within the URDF velocity limits gets by {seconds} s (max_k |Δq_k|/v_k > {seconds} s); by class (settled by {horizon} s, of which out of time): {by_class:?}; max_k |Δq_k|/v_k of those settled: {reach:.2?} s",
            late.len(),
            settled_late.len()
        );
    }
    if seconds == 3.0 && goals >= 100 && !overridden {
        assert!(
            settled as f64 >= 0.35 * goals as f64,
            "only {settled} of {goals} goals settled by 3 s"
        );
    }
}

/// `SWEEP_SAFETY=field=value,…`: the `[safety]` fields of a comparison run (numeric
/// fields, and `enabled=0` for the paper's law alone). Returns whether anything was
/// changed.
fn sweep_safety_overrides(s: &mut Scenario) -> bool {
    let Ok(v) = std::env::var("SWEEP_SAFETY") else {
        return false;
    };
    for kv in v.split(',').filter(|kv| !kv.is_empty()) {
        let (k, x) = kv
            .split_once('=')
            .unwrap_or_else(|| panic!("SWEEP_SAFETY: {kv:?} is not field=value"));
        let x: f64 = x
            .parse()
            .unwrap_or_else(|e| panic!("SWEEP_SAFETY: {kv:?}: {e}"));
        let sp = &mut s.spec.safety;
        match k {
            "null_space_damping" => sp.null_space_damping = x,
            "conflict_fade_ratio" => sp.conflict_fade_ratio = x,
            "velocity_damping" => sp.velocity_damping = x,
            "fade_tank_max" => sp.fade_tank_max = x,
            "velocity_limit_fraction" => sp.velocity_limit_fraction = x,
            "velocity_limit_full_fraction" => sp.velocity_limit_full_fraction = x,
            "joint_limit_margin" => sp.joint_limit_margin = x,
            "joint_limit_damping_ratio" => sp.joint_limit_damping_ratio = x,
            "enabled" => sp.enabled = x != 0.0,
            _ => panic!("SWEEP_SAFETY: unknown field {k:?}"),
        }
    }
    s.spec
        .safety
        .validate()
        .unwrap_or_else(|e| panic!("SWEEP_SAFETY: {e}"));
    true
}

/// The paper's scenarios never reach a limit or a singularity: the safety layer never
/// acts there (their torques are the paper's law bit for bit) and the plant's end stops
/// are never touched. The Panda scenario as shipped reaches no position limit and no
/// singularity either, but without the velocity limits its wrist went over its URDF
/// velocity limit: there the velocity limits act (spring saturation, governor,
/// damping — and nothing else), the plant sees no joint over its velocity limit, and
/// the governor's and damping's torque rate stays under 1000 N·m/s.
#[test]
fn the_shipped_regular_scenarios_are_untouched_by_the_safety_layer() {
    for name in [
        "paper-sim1.toml",
        "paper-sim2.toml",
        "panda-pose-posture.toml",
    ] {
        let scenario = load(name);
        let panda = name.starts_with("panda");
        let duration = scenario.simulation.duration_s;
        let twin = panda.then_some(without_velocity_limits as fn(&mut _));
        let log = run_logged(scenario.clone(), duration, twin);
        let faded = log.iter().filter(|s| s.faded).count();
        let guard = log.iter().filter(|s| s.guard).count();
        let vel = log.iter().filter(|s| s.velocity).count();
        let sat = log.iter().filter(|s| s.saturated).count();
        let (beyond, speed) = limit_figures(&scenario, &log);
        let (onset, gov_rate, gov_tau) = twin_figures(&log, |s| s.governor > 0.0);
        println!(
            "{name}: fade / null-space damping in {faded} cycles, guard in {guard}, spring saturation in {sat}, velocity governor or damping in {vel}; largest |q̇|/limit {speed:.3}; governor: |dτ/dt| in its first 5 cycles {onset:.3?} N·m/s, largest {gov_rate:.0} N·m/s, largest torque change {gov_tau:.2} N·m; errors at the end {:.3?}",
            log.last().unwrap().errors
        );
        assert_eq!(faded + guard, 0, "{name}: the safety layer acted");
        assert!(beyond <= 0.0);
        if panda {
            assert!(vel + sat > 0, "{name}: the velocity limits never acted");
            assert!(
                speed < 1.0,
                "{name}: a joint at {speed} × its velocity limit"
            );
            if let Some(&first) = onset.first() {
                assert!(first < 0.1 * gov_rate, "a torque jump at the onset");
            }
            assert!(gov_rate < 1000.0, "velocity limits: {gov_rate} N·m/s");
        } else {
            assert_eq!(vel + sat, 0, "{name}: the velocity limits acted");
        }
        let run = hcc_simulation::simulate(&scenario).unwrap();
        for key in [
            "end_stop_contacts",
            "joint_limit_guard_cycles",
            "velocity_limit_violation_steps",
        ] {
            assert!(!run.description.settings.contains_key(key), "{name}: {key}");
        }
    }
}

/// The guard comes in without a torque jump: joint 4 of the Panda driven into the
/// margin of its upper limit (−0.0698 rad, margin 0.1 rad) at 0.5 rad/s.
#[test]
fn the_joint_limit_guard_comes_in_without_a_torque_jump() {
    let scenario = load("panda-pose-posture.toml");
    let mut c =
        hcc_control::Controller::new(&scenario.model, scenario.spec.clone(), &scenario.q0).unwrap();
    let (speed, dt) = (0.5, 1e-3);
    let mut q: Vec<f64> = scenario.q0.iter().copied().collect();
    let mut qd = vec![0.0; q.len()];
    qd[3] = speed;
    q[3] = -0.3;
    let mut prev = 0.0;
    let mut first: Option<usize> = None;
    let mut rates = Vec::new();
    for k in 0..400 {
        let out = c.step(&q, &qd).unwrap();
        let tau = out.safety.tau[3];
        if out.safety.joint_limit_active && first.is_none() {
            first = Some(k);
        }
        if first.is_some() {
            rates.push((tau - prev).abs() / dt);
        }
        prev = tau;
        q[3] += speed * dt;
        if q[3] > -0.0698 {
            break;
        }
    }
    let max_rate = rates.iter().copied().fold(0.0, f64::max);
    println!(
        "guard onset: |dτ/dt| in the first 5 cycles {:.3?} N·m/s; largest over the margin {max_rate:.0} N·m/s (joint at {speed} rad/s)",
        &rates[..5]
    );
    assert!(first.is_some(), "the guard never acted");
    // The rate grows from ~0 with the penetration (k p² and smoothstep(p/margin)).
    assert!(rates[0] < 1e-2 * max_rate, "a torque jump at activation");
}
