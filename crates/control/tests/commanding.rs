//! The law's commanding API: gains and a goal velocity changed while the
//! controller runs (`set_gains`, `set_goal_velocity`, `level_target`).

mod common;
use common::*;
use hcc_control::Controller;
use nalgebra::{DMatrix, DVector};

const Q0: [f64; 7] = [0.1, -0.2, 0.05, -2.0, 0.1, 1.9, 0.7];
const QD: [f64; 7] = [0.1, -0.2, 0.15, 0.1, -0.3, 0.2, 0.25];

/// The law of eqs. (20)/(21) as the paper states it: without the safety layer's
/// spring saturation, which caps the doubled spring below.
fn controller() -> Controller {
    let model = panda();
    let mut spec = panda_spec(&model);
    spec.safety.spring_saturation = false;
    Controller::new(&model, spec, &DVector::from_vec(Q0.to_vec())).expect("controller")
}

#[test]
fn unchanged_gains_and_a_zero_goal_velocity_change_nothing() {
    let mut a = controller();
    let mut b = controller();
    let target = b.level_target(0).expect("level");
    let (k, d) = (target.stiffness.clone(), target.damping.clone());
    b.set_gains(0, Some(&k), Some(&d)).expect("gains");
    b.set_goal_velocity(0, &[0.0; 3]).expect("velocity");
    b.set_goal_velocity(2, &[0.0; 7]).expect("velocity");
    for _ in 0..3 {
        let ta = a.step(&Q0, &QD).expect("step").tau.clone();
        let tb = b.step(&Q0, &QD).expect("step").tau.clone();
        assert_eq!(ta, tb, "bit-identical");
    }
}

#[test]
fn stiffness_scales_the_spring_and_damping_acts_on_the_relative_velocity() {
    let mut c = controller();
    let t0 = c.step(&Q0, &QD).expect("step").tau_level[0].clone();
    let j1 = c.task_jacobian(0).clone();
    let xdot = &j1 * DVector::from_column_slice(&QD);
    let err = c.output().task_error[0].clone();

    // τ_1 = −J_1ᵀ (K_1 x̃_1 + D_1 (ẋ_1 − ẋ_{1,d})), eq. (20): doubling K adds −J_1ᵀ K_1 x̃_1.
    let k1 = DMatrix::from_diagonal_element(3, 3, 1600.0);
    c.set_gains(0, Some(&k1), None).expect("gains");
    let t1 = c.step(&Q0, &QD).expect("step").tau_level[0].clone();
    let expected = -j1.transpose() * (DMatrix::from_diagonal_element(3, 3, 800.0) * &err);
    assert!((&t1 - &t0 - expected).amax() < 1e-9);
    assert_eq!(c.level_target(0).expect("level").stiffness, &k1);

    // A goal velocity equal to ẋ_1 cancels the damping term of level 1.
    c.set_goal_velocity(0, xdot.as_slice()).expect("velocity");
    let t2 = c.step(&Q0, &QD).expect("step").tau_level[0].clone();
    let spring_only = -j1.transpose() * (&k1 * &err);
    assert!((&t2 - spring_only).amax() < 1e-9);
    assert_eq!(
        c.level_target(0).expect("level").goal_velocity,
        xdot.as_slice()
    );
}

#[test]
fn bad_gains_and_velocities_are_errors_and_change_nothing() {
    let mut c = controller();
    let before = c.level_target(0).expect("level").stiffness.clone();
    let wrong_size = DMatrix::from_diagonal_element(2, 2, 1.0);
    let mut asym = DMatrix::from_diagonal_element(3, 3, 100.0);
    asym[(0, 1)] = 1.0;
    let negative = DMatrix::from_diagonal_element(3, 3, -1.0);
    let mut nan = DMatrix::from_diagonal_element(3, 3, 1.0);
    nan[(2, 2)] = f64::NAN;
    for bad in [&wrong_size, &asym, &negative, &nan] {
        assert!(c.set_gains(0, Some(bad), None).is_err());
        assert!(c.set_gains(0, None, Some(bad)).is_err());
    }
    assert!(c.set_gains(9, None, None).is_err());
    assert_eq!(c.level_target(0).expect("level").stiffness, &before);
    assert!(c.set_goal_velocity(0, &[0.0; 2]).is_err());
    assert!(c.set_goal_velocity(0, &[f64::NAN, 0.0, 0.0]).is_err());
    assert!(c.set_goal_velocity(7, &[0.0; 3]).is_err());
    assert!(c.level_target(3).is_none());
}

#[test]
fn the_same_gains_again_refill_no_tank() {
    // A transition that moves only a goal hands the law the same gains in
    // every cycle: that is no command, and must not refill the energy tanks
    // (a gain change does: the tanks pay what the new gains do).
    let mut a = controller();
    let mut b = controller();
    let mut c = controller();
    for _ in 0..300 {
        for x in [&mut a, &mut b, &mut c] {
            x.step(&Q0, &QD).expect("step");
        }
    }
    let drained = a.output().tank.clone();
    for i in 1..3 {
        let target = b.level_target(i).expect("level");
        let (k, d) = (target.stiffness.clone(), target.damping.clone());
        b.set_gains(i, Some(&k), Some(&d)).expect("gains");
        c.set_gains(i, Some(&(k * 1.01)), Some(&d)).expect("gains");
    }
    let (ta, tb, tc) = (
        a.step(&Q0, &QD).expect("step").clone(),
        b.step(&Q0, &QD).expect("step").clone(),
        c.step(&Q0, &QD).expect("step").clone(),
    );
    assert_eq!(ta.tank, tb.tank, "the same gains refilled a tank");
    assert_eq!(ta.tau, tb.tau, "bit-identical");
    // Changed gains refill: the tanks were below what a refill gives.
    assert!(
        (1..3).any(|i| tc.tank[i] > ta.tank[i] + 1e-3),
        "no refill after a gain change: {:?} → {:?} (drained {drained:?})",
        ta.tank,
        tc.tank
    );
}
