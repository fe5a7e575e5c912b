//! Controller step time (median, p99, p99.9, max) for the paper's planar arm and the
//! Panda's three-level hierarchy: back to back; regulation and the tracking form
//! interleaved (their ratios); paced at 1 kHz (the core idle between
//! steps, as in the controller's loop); and paced with the loop's cache warm-up, with
//! what sets its slower cycles apart. `cargo bench -p hcc-control --bench step`.

#[path = "../tests/common/mod.rs"]
mod common;
mod support;
use common::*;

fn main() {
    let planar = planar();
    let panda = panda();
    let cases = [
        (
            "planar arm, 3 levels",
            &planar,
            planar_spec(&planar, "sim1"),
            vec_of(&reference()["initial_configuration"]["q0"]),
        ),
        (
            "Panda pos/orient/posture",
            &panda,
            panda_spec(&panda),
            vec![0.0, -0.3, 0.0, -2.2, 0.0, 2.0, 0.8],
        ),
    ];
    for (name, model, spec, q0) in cases {
        let s = support::time_steps(model, spec.clone(), &q0, 5_000, 50_000, None);
        print_stats(name, model.nq(), "back to back", &s);
        // The tracking form beside regulation, interleaved (docs/tracking.md).
        let (reg, trk) =
            support::time_regulation_and_tracking(model, spec.clone(), &q0, 5_000, 50_000);
        print_stats(name, model.nq(), "regulation", &reg);
        print_stats(name, model.nq(), "tracking", &trk);
        println!(
            "{:<28} {:<17} tracking / regulation: median x{:.2}, p99 x{:.2}, p99.9 x{:.2}",
            "",
            "",
            trk.median / reg.median,
            trk.p99 / reg.p99,
            trk.p999 / reg.p999
        );
        // The same steps once per millisecond, the core idle in between as in the
        // controller's loop: what the machine's idle costs the next step.
        let s = support::time_steps(model, spec.clone(), &q0, 500, 5_000, Some(PERIOD));
        print_stats(name, model.nq(), "paced 1 kHz", &s);
        // Paced with the loop's cache warm-up (a twin's step 25 µs before the
        // tick), and what sets its slower cycles apart.
        let w = support::time_paced_warmed(model, spec, &q0, 500, 5_000, PERIOD, LEAD);
        print_stats(name, model.nq(), "paced+warmed", &w.step);
        println!(
            "{:<28} {:<17} warm-up step median {:>6.2} µs; slower / faster half of the cycles: \
             step x{:.2}, its warm-up x{:.2}, register-only kernel x{:.2}",
            "",
            "",
            w.warm_up.median,
            w.slow_over_fast_step,
            w.slow_over_fast_warm_up,
            w.slow_over_fast_kernel
        );
    }
}

/// How long before the tick the paced+warmed run's warm-up step starts (the
/// controller loop's shortest lead, `WARM_UP_MIN_LEAD_NS`).
const LEAD: std::time::Duration = std::time::Duration::from_micros(25);

/// The paced run's period (the control period of the shipped scenarios).
const PERIOD: std::time::Duration = std::time::Duration::from_millis(1);

fn print_stats(name: &str, n: usize, how: &str, s: &support::Stats) {
    println!(
        "{name:<28} n={n:<2} {how:<12} median {:>7.2} µs  p99 {:>7.2} µs  p99.9 {:>7.2} µs  max {:>8.2} µs",
        s.median, s.p99, s.p999, s.max
    );
}
