//! Timing of `Controller::step` shared by the benchmarks: one `Instant` pair around
//! every call, warm-up cycles dropped, order statistics of the rest.
#![allow(dead_code)]

pub mod chain;

use hcc_control::{Controller, ControllerSpec};
use hcc_model::Model;
use nalgebra::DVector;
use std::time::{Duration, Instant};

/// Order statistics of the step time, µs.
#[derive(Clone, Copy, Debug)]
pub struct Stats {
    pub samples: usize,
    pub median: f64,
    pub p99: f64,
    pub p999: f64,
    pub max: f64,
}

/// Times `samples` steps (after `warmup` untimed ones) along q(t) = q0 + t q̇ with a
/// fixed q̇ (the null-space basis is continued from cycle to cycle, as in a loop).
/// `pace`: one step per period on an absolute clock, the core idle in between
/// (slept until 150 µs before each tick, then spun), as in the controller's loop;
/// `None`: back to back.
pub fn time_steps(
    model: &Model,
    spec: ControllerSpec,
    q0: &[f64],
    warmup: usize,
    samples: usize,
    pace: Option<Duration>,
) -> Stats {
    let n = model.nq();
    let mut c = Controller::new(model, spec, &DVector::from_column_slice(q0)).expect("controller");
    let qd: Vec<f64> = (0..n).map(|i| 0.1 * (i as f64 + 1.0).sin()).collect();
    let mut q = q0.to_vec();
    let mut t = Vec::with_capacity(samples);
    let start = Instant::now();
    for k in 0..warmup + samples {
        for (qi, vi) in q.iter_mut().zip(&qd) {
            *qi += 1e-5 * vi;
        }
        if let Some(period) = pace {
            // As in the controller's loop with the hybrid wait: the core idles
            // until 150 µs before the step's tick, then spins up to it.
            let due = start + period * k as u32;
            let lead = Duration::from_micros(150);
            if let Some(idle) = due
                .checked_sub(lead)
                .and_then(|w| w.checked_duration_since(Instant::now()))
            {
                std::thread::sleep(idle);
            }
            while Instant::now() < due {
                std::hint::spin_loop();
            }
        }
        let t0 = Instant::now();
        let out = c.step(&q, &qd).expect("step");
        std::hint::black_box(out.tau[0]);
        let dt = t0.elapsed().as_nanos() as f64;
        if k >= warmup {
            t.push(dt);
        }
    }
    stats(t)
}

/// Median, p99, p99.9 and max of samples in ns, reported in µs.
pub fn stats(mut samples: Vec<f64>) -> Stats {
    samples.sort_by(|a, b| a.partial_cmp(b).unwrap());
    let p = |f: f64| samples[((samples.len() as f64 - 1.0) * f) as usize] / 1000.0;
    Stats {
        samples: samples.len(),
        median: p(0.5),
        p99: p(0.99),
        p999: p(0.999),
        max: samples[samples.len() - 1] / 1000.0,
    }
}
