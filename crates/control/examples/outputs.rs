//! The controller's outputs over a few hundred steps, for comparing two builds of the
//! law: τ, τ_i, τ_μ, v_i, S_i, the conditioning and P_μ of every step of the planar
//! arm, the Panda (three levels, and the 6-D pose over a posture) and the 4–32-joint
//! chains of the scaling benchmark, in eq. (21) and in the classical projector form.
//!
//! `cargo run --release -p hcc-control --example outputs -- write FILE` stores them
//! (every value as its bits); `-- compare FILE` runs the law again and prints, per
//! case and quantity, the largest absolute deviation and the largest one relative to
//! the norm of the vector it belongs to (τ_μ and P_μ, zero in theory: to ‖τ‖ and
//! ‖τ‖ ‖q̇‖), 0 when the bits are the same. `-- steps CASE
//! [N]` runs N steps of one case (planar, panda, chain32, …) for an instruction count;
//! run under valgrind's lackey (`--tool=lackey --trace-mem=yes --log-file=TRACE`) it
//! prints where `Controller::step` sits, and `-- footprint TRACE ADDRESS` then counts
//! the code and data one step touches (64-byte lines and 4 KiB pages of the fourth
//! step in the trace: the caches' and TLBs' working set of the law).

#[path = "../benches/support/chain.rs"]
mod chain;
#[path = "../tests/common/mod.rs"]
mod common;

use common::*;
use hcc_control::{Controller, ControllerSpec, Form};
use hcc_model::Model;
use nalgebra::DVector;
use std::collections::{BTreeMap, HashSet};

const STEPS: usize = 400;
/// The quantities compared (one vector per step each).
const NAMES: [&str; 7] = ["tau", "tau_level", "tau_mu", "v", "storage", "cond", "p_mu"];

/// Every quantity of every step of one case: `values[q][step]`.
type Run = Vec<Vec<Vec<f64>>>;

fn cases() -> Vec<(String, Model, ControllerSpec, Vec<f64>)> {
    let planar = planar();
    let panda = panda();
    let mut v = vec![
        (
            "planar".to_string(),
            planar.clone(),
            planar_spec(&planar, "sim1"),
            vec_of(&reference()["initial_configuration"]["q0"]),
        ),
        (
            "panda".to_string(),
            panda.clone(),
            panda_spec(&panda),
            vec![0.0, -0.3, 0.0, -2.2, 0.0, 2.0, 0.8],
        ),
        (
            "panda-pose".to_string(),
            panda.clone(),
            panda_pose_spec(&panda, true),
            vec![0.0, -0.3, 0.0, -2.2, 0.0, 2.0, 0.8],
        ),
    ];
    for n in [4, 7, 12, 20, 32] {
        let model = Model::from_urdf_str(&chain::chain_urdf(n), None, "tcp", None).expect("chain");
        let q0 = chain::start_configuration(n);
        let spec = chain::chain_spec(&model, &q0);
        v.push((format!("chain{n}"), model, spec, q0));
    }
    v
}

/// q̇ of the compared path.
fn path_velocity(n: usize) -> Vec<f64> {
    (0..n).map(|i| 0.3 * (i as f64 + 1.0).sin()).collect()
}

/// `STEPS` steps along q(t) = q0 + t q̇ (1 ms apart) with a fixed q̇.
fn run(model: &Model, spec: ControllerSpec, q0: &[f64]) -> Run {
    let n = model.nq();
    let mut c = Controller::new(model, spec, &DVector::from_column_slice(q0)).expect("controller");
    let qd = path_velocity(n);
    let mut q = q0.to_vec();
    let mut values: Run = vec![Vec::new(); NAMES.len()];
    for _ in 0..STEPS {
        for (qi, vi) in q.iter_mut().zip(&qd) {
            *qi += 1e-3 * vi;
        }
        let o = c.step(&q, &qd).expect("step");
        let cat = |v: &[DVector<f64>]| v.iter().flat_map(|x| x.iter().copied()).collect();
        let step = [
            o.tau.as_slice().to_vec(),
            cat(&o.tau_level),
            o.tau_mu.as_slice().to_vec(),
            cat(&o.v),
            o.storage.clone(),
            o.conditioning.clone(),
            vec![o.p_mu],
        ];
        for (dst, x) in values.iter_mut().zip(step) {
            dst.push(x);
        }
    }
    values
}

fn all_runs() -> BTreeMap<String, Run> {
    let mut runs = BTreeMap::new();
    for (name, model, spec, q0) in cases() {
        for form in [Form::Extended, Form::ClassicalProjector] {
            let mut spec = spec.clone();
            spec.form = form;
            let tag = if form == Form::Extended {
                "eq21"
            } else {
                "proj"
            };
            runs.insert(format!("{name}/{tag}"), run(&model, spec, &q0));
        }
    }
    runs
}

fn write(path: &str) {
    let mut text = String::new();
    for (case, run) in all_runs() {
        for (q, steps) in NAMES.iter().zip(&run) {
            for (k, v) in steps.iter().enumerate() {
                let bits: Vec<String> = v.iter().map(|x| format!("{:x}", x.to_bits())).collect();
                text.push_str(&format!("{case} {q} {k} {}\n", bits.join(" ")));
            }
        }
    }
    std::fs::write(path, text).expect("write");
}

fn compare(path: &str) {
    let text = std::fs::read_to_string(path).expect("read");
    let mut old: BTreeMap<(String, String, usize), Vec<f64>> = BTreeMap::new();
    for line in text.lines() {
        let mut it = line.split(' ');
        let (case, q, k) = (it.next().unwrap(), it.next().unwrap(), it.next().unwrap());
        let v = it
            .map(|b| f64::from_bits(u64::from_str_radix(b, 16).expect("bits")))
            .collect();
        old.insert((case.into(), q.into(), k.parse().unwrap()), v);
    }
    let mut worst_rel: BTreeMap<&str, f64> = BTreeMap::new();
    for (case, run) in all_runs() {
        let n = run[0][0].len();
        let speed = path_velocity(n).iter().map(|x| x * x).sum::<f64>().sqrt();
        let mut line = format!("{case:<18}");
        for (q, steps) in NAMES.iter().zip(&run) {
            let (mut abs, mut rel) = (0.0f64, 0.0f64);
            for (k, v) in steps.iter().enumerate() {
                let w = &old[&(case.clone(), q.to_string(), k)];
                assert_eq!(v.len(), w.len());
                let norm_of = |w: &[f64]| w.iter().map(|x| x * x).sum::<f64>().sqrt();
                // τ_μ and P_μ (zero in theory) against ‖τ‖ and ‖τ‖ ‖q̇‖ of the step.
                let tau = norm_of(&old[&(case.clone(), "tau".to_string(), k)]);
                let norm = match *q {
                    "tau_mu" => tau,
                    "p_mu" => tau * speed,
                    _ => norm_of(w),
                };
                for (a, b) in v.iter().zip(w) {
                    if a.to_bits() != b.to_bits() {
                        let d = (a - b).abs();
                        abs = abs.max(d);
                        rel = rel.max(d / norm.max(f64::MIN_POSITIVE));
                    }
                }
            }
            line.push_str(&format!(" {q} {abs:.1e}/{rel:.1e}"));
            let e = worst_rel.entry(q).or_insert(0.0);
            *e = e.max(rel);
        }
        println!("{line}");
    }
    println!(
        "largest relative deviation per quantity (|Δ| / ‖vector‖; τ_μ: / ‖τ‖, P_μ: / ‖τ‖ ‖q̇‖):"
    );
    for (q, r) in worst_rel {
        println!("  {q:<10} {r:.2e}");
    }
}

/// N steps of one case along the benchmarks' path (for an instruction count of
/// `Controller::step` under callgrind: `--toggle-collect='*Controller::step*'`).
fn steps(case: &str, count: usize) {
    let (_, model, spec, q0) = cases()
        .into_iter()
        .find(|c| c.0 == case)
        .expect("no such case");
    let n = model.nq();
    let mut c =
        Controller::new(&model, spec, &DVector::from_column_slice(&q0)).expect("controller");
    let qd: Vec<f64> = (0..n).map(|i| 0.1 * (i as f64 + 1.0).sin()).collect();
    let mut q = q0.clone();
    // Where the step's code starts, for `footprint` (valgrind runs the code at
    // the addresses it prints).
    eprintln!(
        "Controller::step at {:#x}",
        Controller::step as *const () as usize
    );
    for _ in 0..count {
        for (qi, vi) in q.iter_mut().zip(&qd) {
            *qi += 1e-5 * vi;
        }
        std::hint::black_box(c.step(&q, &qd).expect("step").tau[0]);
    }
}

/// The working set of one `Controller::step` in a lackey trace (`I`, `L`, `S`, `M`
/// records of `ADDR,SIZE`): the records from the fourth entry at `entry` to the
/// fifth, counted as distinct 64-byte lines and 4 KiB pages of code and of data.
fn footprint(trace: &str, entry: &str) {
    let entry = u64::from_str_radix(entry.trim_start_matches("0x"), 16).expect("hex address");
    let text = std::fs::read_to_string(trace).expect("trace");
    let (mut code, mut data) = (HashSet::new(), HashSet::new());
    let (mut entries, mut instructions, mut accesses) = (0, 0usize, 0usize);
    for line in text.lines() {
        let mut f = line.split_whitespace();
        let (Some(kind), Some(rest)) = (f.next(), f.next()) else {
            continue;
        };
        let Some(addr) = rest
            .split(',')
            .next()
            .and_then(|a| u64::from_str_radix(a, 16).ok())
        else {
            continue;
        };
        if kind == "I" && addr == entry {
            entries += 1;
        }
        if entries != 4 {
            continue;
        }
        if kind == "I" {
            instructions += 1;
            code.insert(addr >> 6);
        } else if matches!(kind, "L" | "S" | "M") {
            accesses += 1;
            data.insert(addr >> 6);
        }
    }
    if entries < 5 {
        eprintln!(
            "footprint: the trace holds {entries} entries at {entry:#x}, needs 5 (steps CASE 6)"
        );
        return;
    }
    let pages = |lines: &HashSet<u64>| lines.iter().map(|l| l >> 6).collect::<HashSet<_>>().len();
    println!(
        "one step: {instructions} instructions over {} lines ({:.1} KiB) in {} pages of code; \
         {accesses} data accesses over {} lines ({:.1} KiB) in {} pages",
        code.len(),
        code.len() as f64 / 16.0,
        pages(&code),
        data.len(),
        data.len() as f64 / 16.0,
        pages(&data)
    );
}

fn main() {
    let args: Vec<String> = std::env::args().collect();
    match (args.get(1).map(String::as_str), args.get(2)) {
        (Some("write"), Some(p)) => write(p),
        (Some("compare"), Some(p)) => compare(p),
        (Some("steps"), Some(case)) => {
            steps(case, args.get(3).map_or(1000, |s| s.parse().unwrap()))
        }
        (Some("footprint"), Some(trace)) => match args.get(3) {
            Some(entry) => footprint(trace, entry),
            None => eprintln!("usage: outputs footprint TRACE ADDRESS"),
        },
        _ => eprintln!(
            "usage: outputs write FILE | outputs compare FILE | outputs steps CASE [N] | \
             outputs footprint TRACE ADDRESS"
        ),
    }
}
