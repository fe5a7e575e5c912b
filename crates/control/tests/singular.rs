//! Singular configurations: finite, bounded torques and a raised flag; invalid
//! hierarchies are refused at construction with the level and the reason.

mod common;
use common::*;
use hcc_control::{ControlError, Controller, LevelSpec, TaskSpec};
use nalgebra::{DMatrix, DVector};

#[test]
fn planar_arm_stretched_out_is_flagged_and_bounded() {
    let model = planar();
    let spec = planar_spec(&model, "sim1");
    let q0 = DVector::from_vec(vec_of(&reference()["initial_configuration"]["q0"]));
    let mut c = Controller::new(&model, spec, &q0).expect("controller");
    // Stretched upright (all angles 0) and just around it: the TCP Jacobian loses rank.
    let mut max_tau: f64 = 0.0;
    let mut norms = Vec::new();
    for eps in [0.0, 1e-9, 1e-6, 1e-4, -1e-4] {
        let q = [eps, 0.0, -eps, 0.0];
        let qd = [0.3, -0.2, 0.1, 0.4];
        c.reset();
        let out = c.step(&q, &qd).expect("step stays finite");
        assert!(out.tau.iter().all(|x| x.is_finite()));
        assert!(out.singular[0], "level 1 not flagged at eps {eps}");
        assert!(out.any_singular);
        max_tau = max_tau.max(out.tau.amax());
        norms.push(out.tau.norm());
    }
    // Bounded: of the order of the springs' forces times the arm's length (1500 N at
    // 2 m, 1256 N·m, 120 N·m), not growing like 1/σ as the singularity is approached.
    assert!(
        max_tau < 10_000.0,
        "torque {max_tau} N·m at the singularity"
    );
    assert!(
        norms[1] <= 1.05 * norms[3],
        "‖τ‖ grows towards the singularity: {norms:?}"
    );
    // And away from it again, unflagged.
    let q = vec_of(&reference()["initial_configuration"]["q0"]);
    c.reset();
    let out = c.step(&q, &[0.0; 4]).expect("step");
    assert!(!out.any_singular);
}

#[test]
fn invalid_hierarchies_are_refused_with_the_level() {
    let model = planar();
    let q0 = DVector::from_vec(vec_of(&reference()["initial_configuration"]["q0"]));
    let tcp = model.frame_id("tcp").unwrap();
    // Level 2 repeats level 1: algorithmic singularity everywhere.
    let mut spec = planar_spec(&model, "sim1");
    spec.levels[1] = LevelSpec {
        name: "tcp x again".into(),
        tasks: vec![TaskSpec::Position {
            frame: tcp,
            axes: vec![0],
        }],
        stiffness: DMatrix::from_element(1, 1, 100.0),
        damping: DMatrix::from_element(1, 1, 10.0),
        goal: DVector::from_element(1, 0.9),
    };
    let err = Controller::new(&model, spec, &q0).unwrap_err().to_string();
    assert!(err.contains("level 2"), "{err}");
    // Too many dimensions above the lowest level.
    let mut spec = planar_spec(&model, "sim1");
    spec.levels[1].tasks = vec![TaskSpec::Posture];
    spec.levels[1].stiffness = DMatrix::identity(4, 4);
    spec.levels[1].damping = DMatrix::identity(4, 4);
    spec.levels[1].goal = DVector::zeros(4);
    let err = Controller::new(&model, spec, &q0).unwrap_err().to_string();
    assert!(err.contains("fewer than the 4 joints"), "{err}");
    // Non-symmetric and indefinite gains.
    let mut spec = planar_spec(&model, "sim1");
    spec.levels[0].stiffness = DMatrix::from_row_slice(2, 2, &[1000.0, 1.0, 0.0, 1000.0]);
    let err = Controller::new(&model, spec, &q0).unwrap_err();
    assert!(
        matches!(err, ControlError::Level { .. }) && err.to_string().contains("symmetric"),
        "{err}"
    );
    let mut spec = planar_spec(&model, "sim1");
    spec.levels[2].damping = DMatrix::from_element(1, 1, -1.0);
    let err = Controller::new(&model, spec, &q0).unwrap_err().to_string();
    assert!(
        err.contains("level 3") && err.contains("positive definite"),
        "{err}"
    );
    // Wrong goal length.
    let mut spec = planar_spec(&model, "sim1");
    spec.levels[0].goal = DVector::zeros(3);
    let err = Controller::new(&model, spec, &q0).unwrap_err().to_string();
    assert!(err.contains("level 1") && err.contains("goal"), "{err}");
    // Joint index out of range, found without a configuration by `validate`.
    let mut spec = planar_spec(&model, "sim1");
    spec.levels[2].tasks = vec![TaskSpec::Joints { indices: vec![4] }];
    let err = spec.validate(&model).unwrap_err().to_string();
    assert!(
        err.contains("level 3") && err.contains("joint indices"),
        "{err}"
    );
    assert!(planar_spec(&model, "sim1").validate(&model).is_ok());
    // Singular at the initial configuration.
    let spec = planar_spec(&model, "sim1");
    let err = Controller::new(&model, spec, &DVector::zeros(4))
        .unwrap_err()
        .to_string();
    assert!(err.contains("level 1") && err.contains("singular"), "{err}");
}

#[test]
fn non_finite_state_is_rejected_without_touching_the_output() {
    let model = planar();
    let q0 = vec_of(&reference()["initial_configuration"]["q0"]);
    let mut c = Controller::new(
        &model,
        planar_spec(&model, "sim1"),
        &DVector::from_vec(q0.clone()),
    )
    .unwrap();
    let tau = c.step(&q0, &[0.0; 4]).unwrap().tau.clone();
    let mut bad = q0.clone();
    bad[2] = f64::INFINITY;
    assert!(matches!(
        c.step(&bad, &[0.0; 4]),
        Err(ControlError::BadInput(_))
    ));
    assert!(matches!(
        c.step(&q0, &[0.0, f64::NAN, 0.0, 0.0]),
        Err(ControlError::BadInput(_))
    ));
    assert!(matches!(
        c.step(&q0[..3], &[0.0; 4]),
        Err(ControlError::BadInput(_))
    ));
    assert_eq!(c.output().tau, tau);
}

/// Smallest singular value of the Panda's 6×7 TCP Jacobian at `q`.
fn panda_sigma_min(model: &hcc_model::Model, q: &[f64]) -> f64 {
    let mut data = hcc_model::Data::new(model);
    let n = model.nq();
    hcc_model::compute_all_terms(
        model,
        &mut data,
        &DVector::from_column_slice(q),
        &DVector::zeros(n),
    );
    let mut j = DMatrix::zeros(6, n);
    let tcp = model.frame_id("panda_hand_tcp").expect("tcp frame");
    hcc_model::frame_jacobian(model, &data, tcp, &mut j);
    j.svd(false, false).singular_values.min()
}

#[test]
fn panda_wrist_singularity_is_flagged_and_bounded() {
    let model = panda();
    // With q5 = π/2 the wrist joints 5–7 can no longer produce an independent rotation
    // at one value of q6 (for these q1–q4): the 6×7 TCP Jacobian loses rank while its
    // position rows stay regular. Find that q6 by a ternary search on σ_min.
    let at = |q6: f64| [0.2, -0.3, 0.1, -2.2, std::f64::consts::FRAC_PI_2, q6, 0.8];
    let (mut a, mut b) = (3.2, 3.5);
    for _ in 0..200 {
        let (m1, m2) = (a + (b - a) / 3.0, b - (b - a) / 3.0);
        if panda_sigma_min(&model, &at(m1)) < panda_sigma_min(&model, &at(m2)) {
            b = m2;
        } else {
            a = m1;
        }
    }
    let q6s = 0.5 * (a + b);
    let sigma = panda_sigma_min(&model, &at(q6s));
    assert!(
        sigma < 1e-9,
        "no wrist singularity found: σ_min {sigma:e} at q6 {q6s}"
    );

    let q0 = DVector::from_vec(at(2.0).to_vec());
    let mut spec = panda_spec(&model);
    // The joints are moved at prescribed speeds, not by the law: the passivity
    // damping and the energy tanks would answer the energy that motion feeds
    // the levels with.
    spec.safety.passivity_damping = false;
    spec.safety.energy_tanks = false;
    let mut c = Controller::new(&model, spec, &q0).expect("controller");
    let qd = [0.1, -0.2, 0.15, 0.1, -0.3, 0.2, 0.25];
    let far = c.step(&at(q6s + 0.1), &qd).expect("step").tau.norm();
    for d in [1e-4, 1e-6, 1e-9, 0.0, -1e-9, -1e-6, -1e-4] {
        c.reset();
        let out = c.step(&at(q6s + d), &qd).expect("step stays finite");
        assert!(out.tau.iter().all(|x| x.is_finite()));
        assert!(
            !out.singular[0],
            "the position level is regular here (d {d:e})"
        );
        assert!(out.singular[1], "orientation level not flagged at d {d:e}");
        assert!(out.any_singular);
        assert!(
            out.tau.norm() <= 1.5 * far,
            "‖τ‖ {} at d {d:e} vs {far} 0.1 rad away",
            out.tau.norm()
        );
    }
    // Driving q6 through the singularity: the command stays continuous (the per-cycle
    // change is of the order of the regular one; no jump of the null-space basis).
    let qd = [0.0, 0.0, 0.0, 0.0, 0.0, 0.5, 0.0];
    c.reset();
    let mut prev: Option<DVector<f64>> = None;
    let mut regular_change = 0.0;
    let mut max_change: f64 = 0.0;
    for k in 0..=2000 {
        let d = -0.05 + 0.1 * k as f64 / 2000.0;
        let out = c.step(&at(q6s + d), &qd).expect("step");
        assert!(out.tau.iter().all(|x| x.is_finite()));
        if let Some(p) = &prev {
            let change = (&out.tau - p).norm();
            if k == 1 {
                regular_change = change;
            }
            max_change = max_change.max(change);
        }
        prev = Some(out.tau.clone());
    }
    println!(
        "through the wrist singularity: largest per-cycle change of τ {max_change:.2e} N·m (regular {regular_change:.2e})"
    );
    assert!(
        max_change <= 3.0 * regular_change,
        "τ jumps by {max_change} N·m in one cycle through the singularity (regular {regular_change})"
    );
}
