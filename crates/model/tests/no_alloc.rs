//! After `Data::new`, no algorithm allocates: a counting global allocator (in
//! this test binary only) must see zero allocations while every algorithm and
//! every linalg routine runs 1000 times on each robot.

mod common;

use common::*;
use hcc_model::linalg::spd::spd_inverse;
use hcc_model::linalg::{
    cholesky_in_place, cholesky_solve_in_place, cholesky_solve_matrix_in_place,
};
use hcc_model::*;
use nalgebra::{DMatrix, DVector};
use std::hint::black_box;

/// Counts the allocations of each thread (`hcc_rtalloc::thread_stats`), so the
/// test harness's own threads never disturb the count.
#[global_allocator]
static GLOBAL: hcc_rtalloc::RtAllocator = hcc_rtalloc::RtAllocator::new();

const ITERATIONS: usize = 1000;

fn run_all(model: &Model) {
    let n = model.nq();
    let mut data = Data::new(model);
    let tip = model.tip_frame();
    let other = model.frames.len() / 2;
    let q = DVector::from_fn(n, |i, _| 0.1 * i as f64 - 0.2);
    let qd = DVector::from_fn(n, |i, _| 0.3 - 0.05 * i as f64);
    let qdd = DVector::from_fn(n, |i, _| 0.5 - 0.1 * i as f64);
    let tau = DVector::from_fn(n, |i, _| 1.0 + i as f64);
    let mut j = DMatrix::zeros(6, n);
    let mut jdot = DMatrix::zeros(6, n);
    let mut factor = DMatrix::zeros(n, n);
    let mut inverse = DMatrix::zeros(n, n);
    let mut x = DVector::zeros(n);
    let mut xm = DMatrix::zeros(n, 3);
    let short = DVector::zeros(n + 1);
    let mut loaded = model.clone();
    let load = hcc_model::Load::point(1.5, [0.0, 0.02, 0.1]);

    let before = hcc_rtalloc::thread_stats().allocs;
    for _ in 0..ITERATIONS {
        forward_kinematics(model, &mut data, &q);
        black_box(frame_placement(model, &data, tip));
        frame_jacobian(model, &data, other, &mut j);
        forward_kinematics_vel(model, &mut data, &q, &qd);
        frame_jacobian(model, &data, tip, &mut j);
        frame_jacobian_time_variation(model, &data, tip, &mut jdot);
        black_box(frame_classical_acceleration(model, &data, tip));
        crba(model, &mut data, &q);
        coriolis_matrix(model, &mut data, &q, &qd);
        gravity(model, &mut data, &q);
        nle(model, &mut data, &q, &qd);
        rnea(model, &mut data, &q, &qd, &qdd);
        black_box(forward_dynamics(model, &mut data, &q, &qd, &tau).is_ok());
        compute_all_terms(model, &mut data, &q, &qd);
        black_box(model.energy(&data, &qd));
        black_box(model.check_state(&q, Some(&qd), Some(&tau)).is_ok());
        // Bad sizes take the NaN / error path, also without allocating.
        crba(model, &mut data, &short);
        black_box(forward_dynamics(model, &mut data, &short, &qd, &tau).is_err());
        // linalg
        factor.copy_from(&data.m);
        black_box(cholesky_in_place(&mut factor).is_ok());
        x.copy_from(&tau);
        black_box(cholesky_solve_in_place(&factor, &mut x).is_ok());
        xm.fill(1.0);
        black_box(cholesky_solve_matrix_in_place(&factor, &mut xm).is_ok());
        black_box(spd_inverse(&data.m, &mut factor, &mut inverse));
        // A load changed at run time.
        hcc_model::set_load(&mut loaded, &load);
        black_box(load.check(3.0).is_ok());
    }
    let after = hcc_rtalloc::thread_stats().allocs;
    assert_eq!(
        after - before,
        0,
        "{}: {} allocations in the loop",
        model.name,
        after - before
    );
    assert!(data.qdd.iter().all(|v| v.is_finite()));
}

#[test]
fn algorithms_do_not_allocate() {
    // The counter works: a heap allocation is seen.
    let before = hcc_rtalloc::thread_stats().allocs;
    black_box(DVector::<f64>::zeros(black_box(8)));
    assert!(hcc_rtalloc::thread_stats().allocs > before);

    run_all(&panda());
    run_all(&planar());
}
