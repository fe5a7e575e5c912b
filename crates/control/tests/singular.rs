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
        task: TaskSpec::Position {
            frame: tcp,
            axes: vec![0],
        },
        stiffness: DMatrix::from_element(1, 1, 100.0),
        damping: DMatrix::from_element(1, 1, 10.0),
        goal: DVector::from_element(1, 0.9),
    };
    let err = Controller::new(&model, spec, &q0).unwrap_err().to_string();
    assert!(err.contains("level 2"), "{err}");
    // Too many dimensions above the lowest level.
    let mut spec = planar_spec(&model, "sim1");
    spec.levels[1].task = TaskSpec::Posture;
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
