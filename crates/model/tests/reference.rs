//! Agreement with the reference values: Pinocchio for the Panda
//! (tests/data/panda_dynamics.json) and an independent implementation for
//! the paper's planar 4-DOF arm (tests/data/paper_planar4.json).
//!
//! "Relative error" is ‖a − b‖ ≤ 1e-9 · max(1, ‖b‖) with the Frobenius norm for
//! matrices and the Euclidean norm for vectors (b = reference).

mod common;

use common::*;
use hcc_model::*;
use nalgebra::{DMatrix, DVector};

const TOL: f64 = 1e-9;

fn check(name: &str, state: usize, err: f64, worst: &mut f64) {
    assert!(err <= TOL, "state {state}: {name} relative error {err:e}");
    *worst = worst.max(err);
}

#[test]
fn panda_matches_pinocchio() {
    let model = panda();
    let reference = load_json(PANDA_JSON);
    assert_eq!(model.nq(), 7);
    assert_eq!(model.locked_joints.len(), 2);
    let gravity_ref = vec_of(&reference["gravity"]);
    assert!((model.gravity - gravity_ref.fixed_rows::<3>(0)).norm() == 0.0);
    let tip = model.tip_frame();
    let mut data = Data::new(&model);
    let mut j = DMatrix::zeros(6, 7);
    let mut worst = 0.0_f64;
    let states = reference["states"].as_array().unwrap();
    assert!(!states.is_empty());
    for (k, s) in states.iter().enumerate() {
        let q = vec_of(&s["q"]);
        let qd = vec_of(&s["qd"]);
        let tau = vec_of(&s["tau"]);
        let w = &mut worst;

        compute_all_terms(&model, &mut data, &q, &qd);
        check("M", k, rel(&data.m, &mat_of(&s["M"])), w);
        check("C", k, rel(&data.c, &mat_of(&s["C"])), w);
        check("g", k, relv(&data.g, &vec_of(&s["g"])), w);
        check("nle", k, relv(&data.nle, &vec_of(&s["nle"])), w);

        let o_m = frame_placement(&model, &data, tip);
        let p = DVector::from_column_slice(o_m.translation.vector.as_slice());
        check("tip_position", k, relv(&p, &vec_of(&s["tip_position"])), w);
        let r = o_m.rotation.to_rotation_matrix();
        let r = DMatrix::from_column_slice(3, 3, r.matrix().as_slice());
        check("tip_rotation", k, rel(&r, &mat_of(&s["tip_rotation"])), w);
        frame_jacobian(&model, &data, tip, &mut j);
        check("tip_jacobian", k, rel(&j, &mat_of(&s["tip_jacobian"])), w);
        let a = frame_classical_acceleration(&model, &data, tip);
        let a = DVector::from_column_slice(a.as_slice());
        check("tip_jdot_qd", k, relv(&a, &vec_of(&s["tip_jdot_qd"])), w);

        // Each algorithm on its own gives the same.
        crba(&model, &mut data, &q);
        check("M (crba)", k, rel(&data.m, &mat_of(&s["M"])), w);
        coriolis_matrix(&model, &mut data, &q, &qd);
        check("C (coriolis_matrix)", k, rel(&data.c, &mat_of(&s["C"])), w);
        gravity(&model, &mut data, &q);
        check("g (gravity)", k, relv(&data.g, &vec_of(&s["g"])), w);
        nle(&model, &mut data, &q, &qd);
        check("nle (rnea)", k, relv(&data.nle, &vec_of(&s["nle"])), w);
        forward_dynamics(&model, &mut data, &q, &qd, &tau).unwrap();
        check(
            "qdd",
            k,
            relv(&data.qdd, &vec_of(&s["qdd_forward_dynamics"])),
            w,
        );
    }
    println!(
        "panda: worst relative error {worst:e} over {} states",
        states.len()
    );
}

#[test]
fn planar4_matches_paper_reference() {
    let model = planar();
    let reference = load_json(PLANAR_JSON);
    assert_eq!(model.nq(), 4);
    let tcp = model.frame_id("tcp").unwrap();
    let mut data = Data::new(&model);
    let mut j = DMatrix::zeros(6, 4);
    let mut worst = 0.0_f64;
    let states = reference["states"].as_object().unwrap();
    for (k, (name, s)) in states.iter().enumerate() {
        let q = vec_of(&s["q"]);
        let qd = vec_of(&s["qd"]);
        compute_all_terms(&model, &mut data, &q, &qd);
        let w = &mut worst;
        check(&format!("{name} M"), k, rel(&data.m, &mat_of(&s["M"])), w);
        check(&format!("{name} C"), k, rel(&data.c, &mat_of(&s["C"])), w);
        let p = frame_placement(&model, &data, tcp).translation.vector;
        let p = DVector::from_column_slice(&p.as_slice()[..2]);
        check(&format!("{name} tcp"), k, relv(&p, &vec_of(&s["tcp"])), w);
        frame_jacobian(&model, &data, tcp, &mut j);
        let j1 = j.rows(0, 2).into_owned();
        check(&format!("{name} J1"), k, rel(&j1, &mat_of(&s["J1"])), w);
    }
    println!(
        "planar4: worst relative error {worst:e} over {} states",
        states.len()
    );
}
