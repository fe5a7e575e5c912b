//! What the discrete-time velocity limit costs next to the law's step, on the
//! Panda (median, p99, p99.9, max; the ratio of medians to the step's in the
//! same run): the one-period limit (`hcc_control::velocity_limit`, no torque
//! filter) and the brake certificate behind a rate limit
//! (`hcc_control::brake_certificate`), each where it lets the law's torque
//! through and where it acts. `cargo bench -p hcc-control --bench velocity_limit`.

#[path = "../tests/common/mod.rs"]
mod common;
mod support;
use common::*;

use hcc_control::velocity_limit::PeriodModel;
use hcc_control::{
    BrakeModel, BrakeWork, Controller, VelocityLimitWork, limit_velocity,
    limit_velocity_rate_limited,
};
use hcc_linalg::products::gemv_slices;
use nalgebra::DVector;
use std::time::Instant;

const SAMPLES: usize = 20_000;
const WARMUP: usize = 2_000;

/// The state of a case: a velocity and the torque the law would send, as an
/// offset from g(q) (plus, for the certificate, the previous command's).
struct Case {
    name: &'static str,
    qd: [f64; 7],
    push: [f64; 7],
    previous: [f64; 7],
}

fn main() {
    let model = panda();
    let q0 = [0.0, -0.3, 0.0, -2.2, 0.0, 2.0, 0.8];
    let v_max: Vec<f64> = model.joints.iter().map(|j| j.velocity_limit).collect();
    let effort: Vec<f64> = model.joints.iter().map(|j| j.effort_limit).collect();
    let slow = [0.1, -0.1, 0.05, 0.1, -0.1, 0.1, 0.2];
    let fast = [0.4, -0.2, 0.3, 0.1, -0.5, 0.2, 2.3];
    let cases = [
        Case {
            name: "slow, law let through",
            qd: slow,
            push: [1.0, -1.0, 0.5, 0.5, -0.2, 0.2, 0.1],
            previous: [0.5, -0.5, 0.2, 0.2, -0.1, 0.1, 0.05],
        },
        Case {
            name: "wrist at 0.9, pushed on",
            qd: fast,
            push: [30.0, -20.0, 10.0, 5.0, -4.0, 3.0, 6.0],
            previous: [29.5, -19.5, 9.5, 4.5, -3.5, 2.5, 5.0],
        },
    ];
    let mut c = Controller::new(&model, panda_spec(&model), &DVector::from_column_slice(&q0))
        .expect("controller");
    let mut period = VelocityLimitWork::new(7);
    let mut brake = BrakeWork::new(7);
    let mut h = DVector::zeros(7);
    for case in &cases {
        let (mut step, mut one, mut cert) = (Vec::new(), Vec::new(), Vec::new());
        let (mut acted_one, mut acted_cert) = (0, 0);
        let mut q = q0;
        for k in 0..WARMUP + SAMPLES {
            for (qi, vi) in q.iter_mut().zip(&case.qd) {
                *qi += 1e-6 * vi;
            }
            let t0 = Instant::now();
            let out = c.step(&q, &case.qd).expect("step");
            std::hint::black_box(out.tau[0]);
            let t_step = t0.elapsed().as_nanos() as f64;
            let terms = c.model_terms();
            let mut tau = [0.0; 7];
            let mut previous = [0.0; 7];
            for i in 0..7 {
                tau[i] = terms.g[i] + case.push[i];
                previous[i] = terms.g[i] + case.previous[i];
            }
            // The one-period limit: h = C q̇ + g, then the limit.
            let t1 = Instant::now();
            h.copy_from(&terms.g);
            gemv_slices(h.as_mut_slice(), 1.0, &terms.c, &case.qd, 1.0);
            let p = PeriodModel {
                m: &terms.m,
                chol: c.mass_factor(),
                h: &h,
                qd: &case.qd,
                v_max: &v_max,
                period_s: 1e-3,
            };
            let mut t_one_tau = tau;
            let a1 = limit_velocity(&p, &mut t_one_tau, &mut period).acted;
            let t_one = t1.elapsed().as_nanos() as f64;
            // The certificate behind a 1 N·m per period rate limit.
            let t2 = Instant::now();
            let b = BrakeModel {
                m: &terms.m,
                chol: c.mass_factor(),
                c: &terms.c,
                g: &terms.g,
                qd: &case.qd,
                v_max: &v_max,
                period_s: 1e-3,
                previous: &previous,
                max_step: 1.0,
                effort: &effort,
            };
            let a2 = limit_velocity_rate_limited(&b, &mut tau, &mut brake).acted;
            let t_cert = t2.elapsed().as_nanos() as f64;
            std::hint::black_box(tau[6] + t_one_tau[6]);
            if k >= WARMUP {
                step.push(t_step);
                one.push(t_one);
                cert.push(t_cert);
                acted_one += usize::from(a1);
                acted_cert += usize::from(a2);
            }
        }
        let step = support::stats(step);
        let one = support::stats(one);
        let cert = support::stats(cert);
        println!("Panda, {}:", case.name);
        print("law step", &step, step.median, None);
        print("one-period limit", &one, step.median, Some(acted_one));
        print("brake certificate", &cert, step.median, Some(acted_cert));
    }
}

fn print(what: &str, s: &support::Stats, step_median: f64, acted: Option<usize>) {
    let acted = acted.map_or(String::new(), |a| {
        format!("  acted {:.0} %", 100.0 * a as f64 / SAMPLES as f64)
    });
    println!(
        "  {what:<18} median {:>7.2} µs  p99 {:>7.2} µs  p99.9 {:>7.2} µs  max {:>8.2} µs  median / step {:>5.2}{acted}",
        s.median,
        s.p99,
        s.p999,
        s.max,
        s.median / step_median
    );
}
