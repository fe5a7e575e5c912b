//! Controller step time (median, p99, p99.9, max) for the paper's planar arm and the
//! Panda's three-level hierarchy. `cargo bench -p hcc-control`.

#[path = "../tests/common/mod.rs"]
mod common;
use common::*;
use hcc_control::Controller;
use hcc_model::Model;
use nalgebra::DVector;
use std::time::Instant;

fn bench(name: &str, model: &Model, spec: hcc_control::ControllerSpec, q0: Vec<f64>) {
    let n = model.nq();
    let mut c = Controller::new(model, spec, &DVector::from_vec(q0.clone())).expect("controller");
    let qd: Vec<f64> = (0..n).map(|i| 0.1 * (i as f64 + 1.0).sin()).collect();
    let mut q = q0;
    let mut samples = Vec::with_capacity(50_000);
    for k in 0..55_000 {
        for (qi, vi) in q.iter_mut().zip(&qd) {
            *qi += 1e-5 * vi;
        }
        let t = Instant::now();
        let out = c.step(&q, &qd).expect("step");
        std::hint::black_box(out.tau[0]);
        let dt = t.elapsed().as_nanos() as f64;
        if k >= 5_000 {
            samples.push(dt);
        }
    }
    samples.sort_by(|a, b| a.partial_cmp(b).unwrap());
    let p = |f: f64| samples[((samples.len() as f64 - 1.0) * f) as usize] / 1000.0;
    println!(
        "{name:<28} n={n:<2} median {:>7.2} µs  p99 {:>7.2} µs  p99.9 {:>7.2} µs  max {:>8.2} µs",
        p(0.5),
        p(0.99),
        p(0.999),
        samples[samples.len() - 1] / 1000.0
    );
}

fn main() {
    let planar = planar();
    let q0 = vec_of(&reference()["initial_configuration"]["q0"]);
    bench(
        "planar arm, 3 levels",
        &planar,
        planar_spec(&planar, "sim1"),
        q0,
    );
    let panda = panda();
    bench(
        "Panda pos/orient/posture",
        &panda,
        panda_spec(&panda),
        vec![0.0, -0.3, 0.0, -2.2, 0.0, 2.0, 0.8],
    );
}
