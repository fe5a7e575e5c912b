//! The fast-goal sweep: seeded Panda goals that step at t = 0 (the scenario's
//! own goals, no transition), with and without the shipped torque filter, and
//! how fast they drive the joints against their URDF velocity limits.
//!
//! Each goal (`config/panda-pose-posture.toml`, the safety layer's defaults): a
//! TCP goal 0.4–1.0 m from the start TCP in any direction, the hand turned by
//! up to π/2 about a random axis, a posture goal up to 0.5 rad beyond the
//! limits of every joint. `FAST_GOALS` goals (default 100) of `FAST_SECONDS`
//! each (default 2 s; the peaks come within the first 0.3 s). Printed per
//! configuration: the largest |q̇_k| / q̇_max,k over every goal, its goal, joint
//! and time, the share of goals above 0.95, and the largest torque step;
//! `FAST_DETAIL` prints every goal above 0.95.
//!
//! The discrete-time velocity limit of the cycle holds every joint at ≤ 0.95 ×
//! its limit, asserted in both configurations: without a torque filter by the
//! one-period limit (`hcc_control::velocity_limit`; 0.9401 over the default
//! 100 goals, 1.166 × before it), with the shipped filter by the brake
//! certificate (`hcc_control::brake_certificate`; 0.9368, 1.836 × before it,
//! when 24 goals went past 0.95) — docs/limits-and-singularities.md.

mod seeded;
use seeded::Rng;
use std::path::PathBuf;

use hcc_config::Scenario;
use hcc_in_process::run_observed;
use nalgebra::{DVector, UnitQuaternion};

fn load(name: &str) -> Scenario {
    let path = PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("../../config")
        .join(name);
    Scenario::load(&path).unwrap_or_else(|e| panic!("{e}"))
}

/// One goal: TCP position, TCP roll-pitch-yaw, posture.
struct Goal {
    tcp: [f64; 3],
    rpy: [f64; 3],
    posture: Vec<f64>,
}

/// The first `n` goals (seeded) from the TCP placement of `base` at its q0.
fn goals(base: &Scenario, n: usize) -> Vec<Goal> {
    let model = &base.model;
    let tip = model.frame_id("panda_hand_tcp").expect("the TCP frame");
    let mut data = hcc_model::Data::new(model);
    hcc_model::forward_kinematics(model, &mut data, &base.q0);
    let start = hcc_model::frame_placement(model, &data, tip);
    let mut rng = Rng(0xfa57_60a1_5eed_0046);
    (0..n)
        .map(|_| {
            let p = start.translation.vector + rng.range(0.4, 1.0) * rng.direction();
            let turn = UnitQuaternion::from_scaled_axis(
                rng.direction() * rng.range(0.0, std::f64::consts::FRAC_PI_2),
            );
            let (roll, pitch, yaw) = (turn * start.rotation).euler_angles();
            let posture = model
                .joints
                .iter()
                .map(|j| rng.range(j.lower - 0.5, j.upper + 0.5))
                .collect();
            Goal {
                tcp: [p.x, p.y, p.z],
                rpy: [roll, pitch, yaw],
                posture,
            }
        })
        .collect()
}

/// What one goal did: the largest |q̇_k| / q̇_max,k with its joint and time,
/// the largest torque step (N·m), and whether every torque was finite.
#[derive(Clone, Copy, Debug)]
struct Peak {
    ratio: f64,
    joint: usize,
    t: f64,
    tau_step: f64,
    finite: bool,
    /// Telemetry's velocity-limit counters at the end: cycles corrected,
    /// fall-backs, the largest correction (mN·m).
    corrected: [u64; 3],
}

fn run(base: &Scenario, goal: &Goal, filter: bool, seconds: f64) -> Peak {
    let mut s = base.clone();
    s.spec.levels[0].goal = DVector::from_row_slice(&goal.tcp);
    s.spec.levels[1].goal = DVector::from_row_slice(&goal.rpy);
    s.spec.levels[2].goal = DVector::from_row_slice(&goal.posture);
    if !filter {
        // The filter and what the safety layer knows of it, both off.
        s.torque_filter.torque_rate_limit = None;
        s.spec.safety.torque_rate_limit = None;
    }
    s.set_duration(seconds).unwrap();
    let limits: Vec<f64> = s.model.joints.iter().map(|j| j.velocity_limit).collect();
    let mut peak = Peak {
        ratio: 0.0,
        joint: 0,
        t: 0.0,
        tau_step: 0.0,
        finite: true,
        corrected: [0; 3],
    };
    let mut prev: Option<Vec<f64>> = None;
    run_observed(&s, &mut |v| {
        for (k, (w, lim)) in v.state.qd().iter().zip(&limits).enumerate() {
            let r = w.abs() / lim;
            if r > peak.ratio {
                (peak.ratio, peak.joint, peak.t) = (r, k, v.t);
            }
        }
        let tau = v.cycle.command().tau();
        peak.finite &= tau.iter().all(|x| x.is_finite());
        if let Some(p) = &prev {
            let step = p
                .iter()
                .zip(tau)
                .fold(0.0_f64, |m, (a, b)| m.max((a - b).abs()));
            peak.tau_step = peak.tau_step.max(step);
        }
        prev = Some(tau.to_vec());
        let c = v.cycle.telemetry().counters;
        peak.corrected = [
            c.velocity_limited,
            c.velocity_limit_fallbacks,
            c.velocity_limit_max_correction_mnm,
        ];
        Ok(())
    })
    .unwrap_or_else(|e| panic!("closed loop: {e}"));
    peak
}

/// Runs every goal in one configuration and prints its figures; returns the
/// worst peak and the largest torque step.
fn sweep(base: &Scenario, goals: &[Goal], filter: bool, seconds: f64) -> (Peak, f64) {
    let name = if filter {
        "with the shipped torque filter"
    } else {
        "without a torque filter"
    };
    let detail = std::env::var("FAST_DETAIL").is_ok();
    let peaks: Vec<Peak> = goals
        .iter()
        .map(|g| run(base, g, filter, seconds))
        .collect();
    for (g, p) in peaks.iter().enumerate() {
        assert!(p.finite, "goal {g} ({name}): a non-finite torque");
        if detail && p.ratio > 0.95 {
            println!(
                "fast goal {g} ({name}): {:.3} × on joint {} at {:.3} s; tcp {:.3?} rpy {:.3?}",
                p.ratio,
                p.joint + 1,
                p.t,
                goals[g].tcp,
                goals[g].rpy
            );
        }
    }
    let (g, worst) = peaks
        .iter()
        .enumerate()
        .max_by(|a, b| a.1.ratio.total_cmp(&b.1.ratio))
        .map(|(g, p)| (g, *p))
        .expect("goals");
    let above = peaks.iter().filter(|p| p.ratio > 0.95).count();
    let step = peaks.iter().map(|p| p.tau_step).fold(0.0, f64::max);
    let corrected: u64 = peaks.iter().map(|p| p.corrected[0]).sum();
    let fallbacks: u64 = peaks.iter().map(|p| p.corrected[1]).sum();
    let largest = peaks.iter().map(|p| p.corrected[2]).max().unwrap_or(0);
    println!(
        "fast goals, {name}: {} goals of {seconds} s; largest |q̇_k|/q̇_max,k {:.4} (goal {g}, joint {}, t {:.3} s); above 0.95: {above} ({:.1} %); largest torque step {step:.3} N·m; velocity limit (telemetry): {corrected} cycles corrected, {fallbacks} fall-backs, largest correction {:.3} N·m",
        goals.len(),
        worst.ratio,
        worst.joint + 1,
        worst.t,
        100.0 * above as f64 / goals.len() as f64,
        largest as f64 * 1e-3
    );
    // Telemetry counts what the limit did.
    assert!(
        corrected > 0 && largest > 0,
        "{name}: the limit never acted"
    );
    (worst, step)
}

#[test]
fn fast_goals_against_the_velocity_limits() {
    let env = |k: &str| std::env::var(k).ok();
    let n: usize = env("FAST_GOALS")
        .and_then(|s| s.parse().ok())
        .unwrap_or(100);
    let seconds: f64 = env("FAST_SECONDS")
        .and_then(|s| s.parse().ok())
        .unwrap_or(2.0);
    let base = load("panda-pose-posture.toml");
    assert_eq!(
        base.torque_filter.torque_rate_limit,
        Some(1000.0),
        "the Panda scenario ships the 1 N·m per cycle filter"
    );
    let goals = goals(&base, n);
    let (bare, _) = sweep(&base, &goals, false, seconds);
    let (filtered, step) = sweep(&base, &goals, true, seconds);
    // What the robot sees through the filter: 1 N·m per cycle at most.
    assert!(step <= 1.0 + 1e-9, "a torque step of {step} N·m");
    assert!(bare.ratio <= 0.95, "without the filter: {bare:?}");
    assert!(filtered.ratio <= 0.95, "with the filter: {filtered:?}");
}
