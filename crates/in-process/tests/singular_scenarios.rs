//! Singularities in closed loop (plant RK4 at 0.1 ms, controller at 1 kHz,
//! torque held): the scenarios `config/planar-singular-stretch.toml` (level 1
//! driven into a kinematic singularity: the arm pulled out straight towards a
//! goal out of reach) and `config/planar-algorithmic-singularity.toml` (level
//! 2 conflicting with level 1). In each, the controller never produces a
//! NaN, the torque applied (saturated to the scenario's limits, as the
//! controller daemon does) stays bounded, the singularity is flagged while
//! the arm is in the singular region, and after the goal is moved to where the
//! arm can leave that region, the flag clears and the tasks converge. The
//! control law's own torque stays of the order of its value at the start (the
//! lower levels and τ_μ fade out near the singularity, and the saturation
//! scales the torque as a whole instead of clipping joints, so the arm does not
//! whip round; see the README, Faults and safety).

use std::path::PathBuf;

use hcc_config::Scenario;
use hcc_control::Controller;
use hcc_plant::SimError;
use hcc_plant::{LoopTiming, run_zoh};
use nalgebra::DVector;

fn load(name: &str) -> Scenario {
    let path = PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("../../config")
        .join(name);
    Scenario::load(&path).unwrap_or_else(|e| panic!("{e}"))
}

/// Per cycle: time, singular flags, largest |τ|, all finite, ‖x̃_i‖.
#[derive(Debug, Clone)]
struct Sample {
    t: f64,
    singular: Vec<bool>,
    max_tau: f64,
    /// Largest |τ| applied (after saturation).
    applied: f64,
    finite: bool,
    errors: Vec<f64>,
    conditioning: Vec<f64>,
}

/// The hierarchical controller, with one level's goal moved at `switch_s`.
struct SwitchingLaw {
    controller: Controller,
    /// τ saturated to the scenario's torque limits, as the controller daemon does.
    tau: DVector<f64>,
    limits: DVector<f64>,
    gravity: bool,
    period_s: f64,
    k: u64,
    switch_s: f64,
    level: usize,
    new_goal: Vec<f64>,
    log: Vec<Sample>,
}

impl SwitchingLaw {
    fn compute(&mut self, q: &DVector<f64>, qd: &DVector<f64>) -> Result<(), SimError> {
        let t = self.k as f64 * self.period_s;
        self.k += 1;
        if (t - self.switch_s).abs() < 0.5 * self.period_s {
            self.controller
                .set_goal(self.level, &self.new_goal)
                .map_err(|e| SimError::Invalid(e.to_string()))?;
        }
        let out = self
            .controller
            .step(q.as_slice(), qd.as_slice())
            .map_err(|e| SimError::Invalid(format!("controller at t = {t}: {e}")))?;
        // Saturated as the controller daemon does it (the control part scaled).
        self.tau.copy_from(&out.tau);
        let gravity = self.gravity.then_some(out.gravity.as_slice());
        hcc_control::saturate(self.tau.as_mut_slice(), gravity, self.limits.as_slice());
        self.log.push(Sample {
            t,
            singular: out.singular.clone(),
            max_tau: out.tau.amax(),
            applied: self.tau.amax(),
            finite: out.tau.iter().all(|x| x.is_finite())
                && out.tau_level.iter().flatten().all(|x| x.is_finite()),
            errors: out.task_error.iter().map(|e| e.norm()).collect(),
            conditioning: out.conditioning.clone(),
        });
        Ok(())
    }
}

/// Runs `scenario` for `switch_s + after_s`, moving `level`'s goal to `new_goal` at `switch_s`.
fn run(
    mut scenario: Scenario,
    level: usize,
    new_goal: &[f64],
    switch_s: f64,
    after_s: f64,
) -> Vec<Sample> {
    scenario.set_duration(switch_s + after_s).unwrap();
    let mut law = SwitchingLaw {
        controller: Controller::new(&scenario.model, scenario.spec.clone(), &scenario.q0).unwrap(),
        tau: DVector::zeros(scenario.model.nq()),
        limits: scenario.controller_daemon.torque_limits.clone(),
        gravity: scenario.spec.gravity_compensation,
        period_s: scenario.period_s(),
        k: 0,
        switch_s,
        level,
        new_goal: new_goal.to_vec(),
        log: Vec::new(),
    };
    let mut plant = hcc_plant::plant_for(&scenario).unwrap();
    let timing = LoopTiming {
        control_period_s: law.period_s,
        substeps: scenario.simulation.substeps,
        cycles: scenario.cycles() as usize,
    };
    let result = run_zoh(&mut plant, timing, |_, _, q, qd, tau| {
        law.compute(q, qd)?;
        tau.copy_from(&law.tau);
        Ok(())
    });
    if let Err(e) = result {
        for s in law.log.iter().rev().take(10).rev() {
            println!("{s:?}");
        }
        panic!("the closed loop failed: {e}");
    }
    law.log
}

fn summary(name: &str, log: &[Sample], level: usize, switch_s: f64) {
    let flagged: Vec<&Sample> = log.iter().filter(|s| s.singular[level]).collect();
    let first = flagged.first().map(|s| s.t);
    let last = flagged.last().map(|s| s.t);
    let worst_cond = log
        .iter()
        .map(|s| s.conditioning[level])
        .fold(f64::INFINITY, f64::min);
    let max_tau = log.iter().map(|s| s.max_tau).fold(0.0, f64::max);
    println!(
        "{name}: level {} flagged in {} cycles, first at {first:?} s, last at {last:?} s (goal moved at {switch_s} s); smallest eigenvalue ratio {worst_cond:.2e}; max |τ| {max_tau:.1} N·m; final errors {:?}",
        level + 1,
        flagged.len(),
        log.last().unwrap().errors
    );
}

#[test]
fn kinematic_singularity_arm_stretched_out_then_back() {
    let scenario = load("planar-singular-stretch.toml");
    let switch_s = 1.5;
    let log = run(scenario, 0, &[0.90, 1.30], switch_s, 1.5);
    summary("stretch", &log, 0, switch_s);
    assert!(log.iter().all(|s| s.finite), "a non-finite torque");
    // The law's own torque: at most its initial K_1 x̃_1 pull (262 N·m) — no
    // whipping through the singular region. What reaches the joints is
    // saturated to the scenario's limits, as in the controller daemon.
    let max_tau = log.iter().map(|s| s.max_tau).fold(0.0, f64::max);
    assert!(max_tau < 500.0, "torque {max_tau} N·m");
    assert!(
        log.iter().all(|s| s.applied <= 100.0 + 1e-9),
        "applied torque above the limit"
    );
    let before: Vec<&Sample> = log.iter().filter(|s| s.t < switch_s).collect();
    let after: Vec<&Sample> = log.iter().filter(|s| s.t >= switch_s + 0.5).collect();
    assert!(
        before.iter().any(|s| s.singular[0]),
        "level 1 never flagged while stretched out"
    );
    assert!(
        after.iter().all(|s| !s.singular.iter().any(|&f| f)),
        "still flagged 0.5 s after the goal came back within reach"
    );
    assert!(
        log.last().unwrap().errors[0] < 1e-3,
        "level 1 converged back"
    );
}

#[test]
fn algorithmic_singularity_conflicting_levels_then_compatible_goal() {
    let scenario = load("planar-algorithmic-singularity.toml");
    let switch_s = 1.5;
    // Level 2 starts towards its compatible goal 0.3–0.4 s after it is set
    // (0.1 s later with the energy tanks: 1.6 mm left after 1.5 s, 0.8 mm
    // without them; why it starts later was not looked into) and converges
    // with a time constant of about 0.2 s: 2 s to be within 1 mm.
    let log = run(scenario, 1, &[0.6], switch_s, 2.0);
    // The rank loss of levels 1 and 2 together is flagged on level 3 (the
    // inversion of J_aug J_augᵀ for its null-space basis).
    summary("algorithmic", &log, 2, switch_s);
    assert!(log.iter().all(|s| s.finite), "a non-finite torque");
    let max_tau = log.iter().map(|s| s.max_tau).fold(0.0, f64::max);
    assert!(max_tau < 500.0, "torque {max_tau} N·m");
    assert!(
        log.iter().all(|s| s.applied <= 100.0 + 1e-9),
        "applied torque above the limit"
    );
    let before: Vec<&Sample> = log.iter().filter(|s| s.t < switch_s).collect();
    let after: Vec<&Sample> = log.iter().filter(|s| s.t >= switch_s + 0.5).collect();
    assert!(
        before.iter().any(|s| s.singular[2]),
        "the conflict never flagged"
    );
    // Level 1 keeps its TCP through the conflict to within about a cm: the
    // damped inversion gives up a little of the strict hierarchy there.
    let tcp_worst = before
        .iter()
        .filter(|s| s.t > 0.9)
        .map(|s| s.errors[0])
        .fold(0.0, f64::max);
    println!("algorithmic: worst TCP error in the conflict after 0.9 s: {tcp_worst:.2e} m");
    assert!(tcp_worst < 2.5e-2, "level 1 pushed off by {tcp_worst} m");
    assert!(
        after.iter().all(|s| !s.singular.iter().any(|&f| f)),
        "still flagged 0.5 s after the compatible goal"
    );
    let last = log.last().unwrap();
    assert!(
        last.errors[0] < 1e-3 && last.errors[1] < 1e-3,
        "{:?}",
        last.errors
    );
}
