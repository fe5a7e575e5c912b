//! The velocity barrier towards a position limit (hcc_control::safety,
//! "the barrier"): a joint moving towards its URDF limit faster than a
//! rate-limited brake could stop it from is braked with a torque against its
//! motion; the same speed away from the limit, or slowly towards it, is left
//! alone.

mod common;

use common::{panda, panda_spec};
use hcc_control::Controller;

/// Panda joint 4's lower limit (rad) and its velocity limit (rad/s).
const LOWER_4: f64 = -3.0718;
const SPEED_LIMIT_4: f64 = 2.175;

/// The barrier's torque on joint 4 at `q4` moving at `qd4` (every other
/// joint at rest), behind a rate limit of 1000 N·m/s.
fn barrier_on_joint_4(q4: f64, qd4: f64) -> (f64, f64) {
    let model = panda();
    let mut spec = panda_spec(&model);
    spec.safety.torque_rate_limit = Some(1000.0);
    let mut q = [0.0, -0.3, 0.0, -2.2, 0.0, 2.0, 0.8];
    let mut qd = [0.0; 7];
    q[3] = q4;
    let q0 = nalgebra::DVector::from_column_slice(&q);
    // The posture alone, lightly damped, its goal 1 rad beyond the limit:
    // its spring drives joint 4 into it (as in the unreachable sweep).
    let mut posture = spec.levels.pop().expect("the posture level");
    posture.goal = q0.clone();
    posture.goal[3] = LOWER_4 - 1.0;
    posture.damping *= 0.01;
    spec.levels = vec![posture];
    let mut c = Controller::new(&model, spec, &q0).expect("controller");
    qd[3] = qd4;
    let out = c.step(&q, &qd).expect("step");
    let tau = &out.safety.barrier_tau;
    let power: f64 = tau.iter().zip(&qd).map(|(t, v)| t * v).sum();
    (tau[3], power)
}

#[test]
fn a_joint_fast_towards_its_limit_is_braked_before_the_guard_and_not_away_from_it() {
    // 0.55 of the velocity limit: below the velocity band (f_on = 0.6), where
    // governor, damping and barrier leave the speed alone.
    let speed = 0.55 * SPEED_LIMIT_4;
    // 0.12 rad from the limit (the guard's margin is 0.1), moving towards it
    // with the posture's spring pushing on: above f_on v_d (v_d ≈ 1.8 rad/s
    // there behind 1000 N·m/s), braked against the motion.
    let (towards, power) = barrier_on_joint_4(LOWER_4 + 0.12, -speed);
    assert!(towards > 0.5, "braking torque {towards} N·m");
    assert!(power < 0.0, "the barrier's power {power} W");
    // The same speed away from the limit: nothing on joint 4.
    let (away, _) = barrier_on_joint_4(LOWER_4 + 0.12, speed);
    assert_eq!(away, 0.0);
}

#[test]
fn slowly_towards_the_limit_is_left_alone() {
    // 0.1 rad/s, 0.12 rad away: v_d is far above it.
    let (slow, _) = barrier_on_joint_4(LOWER_4 + 0.12, -0.1);
    assert_eq!(slow, 0.0);
}
