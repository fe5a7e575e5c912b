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
            let due = start + period * k as u32;
            idle_until_lead(due);
            spin_until(due);
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

/// The regulation law's step and the tracking form's (every level tracks,
/// level 1's goal moves: `controller/tracking.rs`) at the same states,
/// interleaved back to back so that both see the same machine; µs.
pub fn time_regulation_and_tracking(
    model: &Model,
    spec: ControllerSpec,
    q0: &[f64],
    warmup: usize,
    samples: usize,
) -> (Stats, Stats) {
    let n = model.nq();
    let q0v = DVector::from_column_slice(q0);
    let mut reg = Controller::new(model, spec.clone(), &q0v).expect("controller");
    let mut trk = Controller::new(model, spec, &q0v).expect("controller");
    for i in 0..trk.levels() {
        let m = trk.task_dim(i);
        let a: Vec<f64> = (0..m).map(|k| 0.01 * (k as f64 + 1.0)).collect();
        trk.set_goal_velocity(i, &a).expect("velocity");
        trk.set_goal_acceleration(i, Some(&a))
            .expect("acceleration");
    }
    let qd: Vec<f64> = (0..n).map(|i| 0.1 * (i as f64 + 1.0).sin()).collect();
    let mut q = q0.to_vec();
    let (mut tr, mut tt) = (Vec::with_capacity(samples), Vec::with_capacity(samples));
    for k in 0..warmup + samples {
        for (qi, vi) in q.iter_mut().zip(&qd) {
            *qi += 1e-5 * vi;
        }
        for (c, t) in [(&mut reg, &mut tr), (&mut trk, &mut tt)] {
            let t0 = Instant::now();
            let out = c.step(&q, &qd).expect("step");
            std::hint::black_box(out.tau[0]);
            let dt = t0.elapsed().as_nanos() as f64;
            if k >= warmup {
                t.push(dt);
            }
        }
    }
    (stats(tr), stats(tt))
}

/// [`time_paced_warmed`]'s figures: the step's, its warm-up's, and how the
/// slower half of the cycles differs from the faster half.
#[derive(Clone, Copy, Debug)]
pub struct WarmedStats {
    /// The timed step (after the warm-up), µs.
    pub step: Stats,
    /// The warm-up step of the same cycles, µs.
    pub warm_up: Stats,
    /// Medians over the cycles whose step took longer than the step's median,
    /// divided by those over the rest: the step, its warm-up, and a
    /// register-only arithmetic kernel timed in the same spin.
    pub slow_over_fast_step: f64,
    pub slow_over_fast_warm_up: f64,
    pub slow_over_fast_kernel: f64,
}

/// As the paced mode of [`time_steps`] with the controller loop's cache
/// warm-up: `lead` before each tick a second controller (the same spec and
/// inputs) takes one step, and shortly before that a register-only chain of
/// multiply-adds is timed (what the core's own speed did in that cycle). The
/// split of the cycles by the step's median tells a cycle of a slower core
/// (every ratio above 1) from one whose memory was slower (the steps' ratios
/// above 1, the kernel's at 1).
pub fn time_paced_warmed(
    model: &Model,
    spec: ControllerSpec,
    q0: &[f64],
    warmup: usize,
    samples: usize,
    period: Duration,
    lead: Duration,
) -> WarmedStats {
    let n = model.nq();
    let q0v = DVector::from_column_slice(q0);
    let mut c = Controller::new(model, spec.clone(), &q0v).expect("controller");
    let mut twin = Controller::new(model, spec, &q0v).expect("controller");
    let qd: Vec<f64> = (0..n).map(|i| 0.1 * (i as f64 + 1.0).sin()).collect();
    let mut q = q0.to_vec();
    // (step, warm-up, kernel) per cycle, ns.
    let mut t: Vec<[f64; 3]> = Vec::with_capacity(samples);
    let start = Instant::now();
    for k in 0..warmup + samples {
        for (qi, vi) in q.iter_mut().zip(&qd) {
            *qi += 1e-5 * vi;
        }
        let due = start + period * k as u32;
        idle_until_lead(due);
        spin_until(due - lead - Duration::from_micros(5));
        let t0 = Instant::now();
        let mut x = std::hint::black_box(1.0 + 1e-7);
        for _ in 0..KERNEL_ROUNDS {
            x = x * (1.0 + 1e-7) + 1e-9;
        }
        std::hint::black_box(x);
        let kernel = t0.elapsed().as_nanos() as f64;
        spin_until(due - lead);
        let t0 = Instant::now();
        std::hint::black_box(twin.step(&q, &qd).map(|o| o.tau[0]).ok());
        let warm = t0.elapsed().as_nanos() as f64;
        spin_until(due);
        let t0 = Instant::now();
        let out = c.step(&q, &qd).expect("step");
        std::hint::black_box(out.tau[0]);
        let step = t0.elapsed().as_nanos() as f64;
        if k >= warmup {
            t.push([step, warm, kernel]);
        }
    }
    let median_step = stats(t.iter().map(|r| r[0]).collect()).median * 1000.0;
    let (slow, fast): (Vec<[f64; 3]>, Vec<[f64; 3]>) = t.iter().partition(|r| r[0] > median_step);
    let ratio = |i: usize| {
        let m = |v: &[[f64; 3]]| stats(v.iter().map(|r| r[i]).collect()).median;
        if slow.is_empty() || fast.is_empty() {
            1.0
        } else {
            m(&slow) / m(&fast)
        }
    };
    WarmedStats {
        step: stats(t.iter().map(|r| r[0]).collect()),
        warm_up: stats(t.iter().map(|r| r[1]).collect()),
        slow_over_fast_step: ratio(0),
        slow_over_fast_warm_up: ratio(1),
        slow_over_fast_kernel: ratio(2),
    }
}

/// As the controller's loop with the hybrid wait: the core idles (sleeps)
/// until 150 µs before the tick at `due`; the caller spins from there.
fn idle_until_lead(due: Instant) {
    if let Some(idle) = due
        .checked_sub(Duration::from_micros(150))
        .and_then(|w| w.checked_duration_since(Instant::now()))
    {
        std::thread::sleep(idle);
    }
}

/// Spins (with the `pause` hint) until `at`.
fn spin_until(at: Instant) {
    while Instant::now() < at {
        std::hint::spin_loop();
    }
}

/// Rounds of [`time_paced_warmed`]'s register-only kernel (a dependent chain of
/// multiply-adds, about 0.7 µs).
const KERNEL_ROUNDS: usize = 400;

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
