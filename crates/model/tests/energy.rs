//! Energy conservation: with τ = 0 and no damping, a free swing integrated
//! with classical RK4 (step 0.1 ms, 2 s) from seeded random states keeps the
//! total energy ½ q̇ᵀ M q̇ + V constant up to the integration error. The
//! tolerance is |E(t) − E(0)| ≤ 1e-7 · max(1, |E(0)|) over the whole run. For the
//! planar arm the test also checks that the drift shrinks like dt⁴.

mod common;

use common::*;
use hcc_model::*;
use nalgebra::DVector;
use rand::rngs::StdRng;
use rand::{RngExt, SeedableRng};

const DT: f64 = 1e-4;
const DURATION: f64 = 2.0;
const TOL: f64 = 1e-7;

fn qdd(
    model: &Model,
    data: &mut Data,
    q: &DVector<f64>,
    qd: &DVector<f64>,
    tau: &DVector<f64>,
) -> DVector<f64> {
    forward_dynamics(model, data, q, qd, tau).unwrap();
    data.qdd.clone()
}

/// One classical Runge–Kutta step of q̈ = f(q, q̇).
fn rk4(
    model: &Model,
    data: &mut Data,
    q: &mut DVector<f64>,
    qd: &mut DVector<f64>,
    tau: &DVector<f64>,
    dt: f64,
) {
    let k1q = qd.clone();
    let k1v = qdd(model, data, q, qd, tau);
    let q2 = &*q + 0.5 * dt * &k1q;
    let v2 = &*qd + 0.5 * dt * &k1v;
    let k2v = qdd(model, data, &q2, &v2, tau);
    let q3 = &*q + 0.5 * dt * &v2;
    let v3 = &*qd + 0.5 * dt * &k2v;
    let k3v = qdd(model, data, &q3, &v3, tau);
    let q4 = &*q + dt * &v3;
    let v4 = &*qd + dt * &k3v;
    let k4v = qdd(model, data, &q4, &v4, tau);
    *q += dt / 6.0 * (k1q + 2.0 * v2 + 2.0 * v3 + v4);
    *qd += dt / 6.0 * (k1v + 2.0 * k2v + 2.0 * k3v + k4v);
}

fn energy(model: &Model, data: &mut Data, q: &DVector<f64>, qd: &DVector<f64>) -> f64 {
    crba(model, data, q);
    model.energy(data, qd)
}

/// Integrates 2 s from a seeded random state with step `dt`; returns
/// (E0, max kinetic energy, max |E − E0|).
fn free_swing(model: &Model, seed: u64, dt: f64) -> (f64, f64, f64) {
    let n = model.nq();
    let mut rng = StdRng::seed_from_u64(seed);
    let mut q = DVector::from_fn(n, |_, _| rng.random_range(-1.0..1.0));
    let mut qd = DVector::from_fn(n, |_, _| rng.random_range(-1.0..1.0));
    let tau = DVector::zeros(n);
    let mut data = Data::new(model);
    let e0 = energy(model, &mut data, &q, &qd);
    let steps = (DURATION / dt).round() as usize;
    let mut drift = 0.0_f64;
    let mut kinetic_max = 0.0_f64;
    for _ in 0..steps {
        rk4(model, &mut data, &mut q, &mut qd, &tau, dt);
        let e = energy(model, &mut data, &q, &qd);
        drift = drift.max((e - e0).abs());
        kinetic_max = kinetic_max.max(0.5 * qd.dot(&(&data.m * &qd)));
    }
    (e0, kinetic_max, drift)
}

fn check(name: &str, model: &Model, seed: u64) -> f64 {
    let (e0, kinetic_max, drift) = free_swing(model, seed, DT);
    println!(
        "{name}: E0 = {e0:.6} J, max kinetic energy {kinetic_max:.3} J, max |E - E0| = {drift:e} J over {DURATION} s"
    );
    assert!(kinetic_max > 1.0, "{name}: the arm did not swing");
    assert!(
        drift <= TOL * e0.abs().max(1.0),
        "{name}: energy drift {drift:e} J"
    );
    drift
}

#[test]
fn panda_free_swing_conserves_energy() {
    check("panda", &panda(), 11);
}

#[test]
fn planar4_free_swing_conserves_energy() {
    let model = planar();
    let drift = check("planar4", &model, 12);
    // The drift is RK4's O(dt⁴) truncation error, not a modelling error: doubling
    // the step multiplies it by about 2⁴ = 16.
    let (_, _, drift2) = free_swing(&model, 12, 2.0 * DT);
    let ratio = drift2 / drift;
    println!("planar4: drift at 2 dt / drift at dt = {ratio:.2}");
    assert!((10.0..25.0).contains(&ratio), "drift ratio {ratio}");
}
