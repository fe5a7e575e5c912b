//! Timing of the dynamics algorithms for the Panda (7 DOF, tip `panda_hand_tcp`).
//!
//! Plain `Instant` loop: for each algorithm, `SAMPLES` samples of `BATCH` calls
//! each on pseudo-random states; prints the median and the 99th percentile of the
//! time per call. Run with `cargo bench -p hcc-model`.

use hcc_model::*;
use nalgebra::{DMatrix, DVector};
use std::hint::black_box;
use std::time::Instant;

const SAMPLES: usize = 20_000;
const BATCH: usize = 10;

/// One benchmark state: q, q̇, τ (also used as q̈ for RNEA).
type State = (DVector<f64>, DVector<f64>, DVector<f64>);

fn main() {
    let urdf = concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/../../config/robots/panda/panda.urdf"
    );
    let model = match Model::from_urdf_file(urdf, None, "panda_hand_tcp", None) {
        Ok(m) => m,
        Err(e) => {
            eprintln!("cannot load the Panda: {e}");
            std::process::exit(1);
        }
    };
    let n = model.nq();
    let tip = model.tip_frame();
    let mut data = Data::new(&model);
    let mut j = DMatrix::zeros(6, n);
    // A fixed set of states (deterministic pseudo-random numbers).
    let mut seed = 0x2545_f491_4f6c_dd1d_u64;
    let mut next = move || {
        seed ^= seed << 13;
        seed ^= seed >> 7;
        seed ^= seed << 17;
        (seed >> 11) as f64 / (1u64 << 53) as f64 * 2.0 - 1.0
    };
    let states: Vec<State> = (0..64)
        .map(|_| {
            (
                DVector::from_fn(n, |_, _| next()),
                DVector::from_fn(n, |_, _| next()),
                DVector::from_fn(n, |_, _| 20.0 * next()),
            )
        })
        .collect();

    println!(
        "hcc-model dynamics, Panda (n = {n}), {SAMPLES} samples x {BATCH} calls, time per call"
    );
    println!("{:<28} {:>10} {:>10}", "algorithm", "median", "p99");
    let mut run = |name: &str, f: &mut dyn FnMut(&mut Data, &State)| {
        let mut samples = Vec::with_capacity(SAMPLES);
        for s in 0..SAMPLES {
            let st = &states[s % states.len()];
            let t0 = Instant::now();
            for _ in 0..BATCH {
                f(&mut data, black_box(st));
            }
            samples.push(t0.elapsed().as_nanos() as f64 / BATCH as f64);
        }
        samples.sort_by(|a, b| a.total_cmp(b));
        let median = samples[samples.len() / 2];
        let p99 = samples[samples.len() * 99 / 100];
        println!("{name:<28} {:>8.0} ns {:>8.0} ns", median, p99);
    };
    run("forward_kinematics", &mut |d, (q, _, _)| {
        forward_kinematics(&model, d, q)
    });
    run("crba (M)", &mut |d, (q, _, _)| crba(&model, d, q));
    run("coriolis_matrix (C)", &mut |d, (q, qd, _)| {
        coriolis_matrix(&model, d, q, qd)
    });
    run("gravity (g)", &mut |d, (q, _, _)| gravity(&model, d, q));
    run("frame_jacobian (J, +FK)", &mut |d, (q, _, _)| {
        forward_kinematics(&model, d, q);
        frame_jacobian(&model, d, tip, &mut j);
    });
    run("nle (C qd + g)", &mut |d, (q, qd, _)| nle(&model, d, q, qd));
    run("rnea", &mut |d, (q, qd, tau)| rnea(&model, d, q, qd, tau));
    run("forward_dynamics", &mut |d, (q, qd, tau)| {
        black_box(forward_dynamics(&model, d, q, qd, tau).is_ok());
    });
    run("compute_all_terms", &mut |d, (q, qd, _)| {
        compute_all_terms(&model, d, q, qd)
    });
}
