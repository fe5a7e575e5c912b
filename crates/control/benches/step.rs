//! Controller step time (median, p99, p99.9, max) for the paper's planar arm and the
//! Panda's three-level hierarchy. `cargo bench -p hcc-control --bench step`.

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
        let s = support::time_steps(model, spec, &q0, 5_000, 50_000);
        println!(
            "{name:<28} n={:<2} median {:>7.2} µs  p99 {:>7.2} µs  p99.9 {:>7.2} µs  max {:>8.2} µs",
            model.nq(),
            s.median,
            s.p99,
            s.p999,
            s.max
        );
    }
}
