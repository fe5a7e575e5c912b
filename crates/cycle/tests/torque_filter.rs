//! The torque-rate limit in closed loop with the plant (RK4, zero-order hold):
//! off, scaling Δτ as a whole, and per joint, at 1000 N·m/s on the paper's
//! Sim #1 and the Panda scenario. Prints the figures the docs quote; checks
//! that the limit holds, that off is the law's run, and that the limiter does
//! not act on the Panda scenario.

use std::path::PathBuf;

use hcc_config::Scenario;
use hcc_control::Controller;
use hcc_cycle::{ControlCycle, CycleSettings};
use hcc_msgs::JointState;
use hcc_plant::zoh::{LoopTiming, run_zoh};
use hcc_spec::torque_filter::RateLimitMode;

struct Figures {
    rate_limited: u64,
    max_step: f64,
    final_error: f64,
    max_error_dev: f64,
}

fn run(file: &str, mode: Option<RateLimitMode>, reference: Option<&[f64]>) -> (Figures, Vec<f64>) {
    let path = PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("../../config")
        .join(file);
    let sc = Scenario::load(&path).unwrap();
    let mut settings = CycleSettings::from_scenario(&sc);
    settings.torque_filter.torque_rate_limit = mode.map(|_| 1000.0);
    settings.torque_filter.rate_limit_mode = mode.unwrap_or_default();
    let c = Controller::new(&sc.model, sc.spec.clone(), &sc.q0).unwrap();
    let mut d = ControlCycle::new(c, &settings).unwrap();
    let mut plant = hcc_plant::plant_for(&sc).unwrap();
    let n = sc.model.nq();
    let timing = LoopTiming {
        control_period_s: 1e-3,
        substeps: sc.simulation.substeps,
        cycles: (sc.simulation.duration_s * 1e3).round() as usize,
    };
    let mut prev = vec![0.0; n];
    let mut errors = Vec::new();
    let mut max_step = 0.0_f64;
    run_zoh(&mut plant, timing, |k, _t, q, qd, tau| {
        let mut s = JointState::zeroed();
        s.set_joints(q.as_slice(), qd.as_slice(), &vec![0.0; n])
            .unwrap();
        s.header.seq = k as u64 + 1;
        d.decide(&s, (k as u64 + 1) * 1_000_000);
        let out = d.command().tau();
        if k > 0 {
            let step = out
                .iter()
                .zip(&prev)
                .fold(0.0_f64, |m, (a, b)| m.max((a - b).abs()));
            max_step = max_step.max(step);
        }
        prev.copy_from_slice(out);
        tau.as_mut_slice().copy_from_slice(out);
        let e = d.telemetry().task_error(0);
        errors.push(e.iter().map(|x| x * x).sum::<f64>().sqrt());
        Ok(())
    })
    .unwrap();
    let max_error_dev = reference.map_or(0.0, |r| {
        r.iter()
            .zip(&errors)
            .fold(0.0_f64, |m, (a, b)| m.max((a - b).abs()))
    });
    let f = Figures {
        rate_limited: d.counters().telemetry.rate_limited,
        max_step,
        final_error: *errors.last().unwrap(),
        max_error_dev,
    };
    (f, errors)
}

#[test]
fn rate_limit_whole_and_per_joint_in_closed_loop() {
    for file in ["paper-sim1.toml", "panda-pose-posture.toml"] {
        let (off, reference) = run(file, None, None);
        assert_eq!(off.rate_limited, 0);
        for mode in [RateLimitMode::Whole, RateLimitMode::PerJoint] {
            let (f, _) = run(file, Some(mode), Some(&reference));
            println!(
                "{file} {mode:?}: rate-limited cycles {}, max |Δτ| per cycle {:.3} N·m (off: {:.3}), \
                 final level-1 error {:.3e} m (off: {:.3e}), max deviation of the level-1 error from off {:.3e} m",
                f.rate_limited,
                f.max_step,
                off.max_step,
                f.final_error,
                off.final_error,
                f.max_error_dev
            );
            // The limit holds (saturation only lowers |τ|, never raises a step here).
            assert!(
                f.max_step <= 1.0 + 1e-9 || f.rate_limited == 0,
                "{}",
                f.max_step
            );
            if file.starts_with("panda") {
                // The law's first torque comes in from the held g(q0) at the
                // rate limit; after that the Panda's motion stays below 1000
                // N·m/s, and it converges as without the limit.
                assert!(
                    f.rate_limited > 0 && f.rate_limited < 150,
                    "only while the first torque ramps in: {}",
                    f.rate_limited
                );
                assert!(f.final_error < 1e-5, "{}", f.final_error);
            } else {
                assert!(f.rate_limited > 0);
            }
        }
    }
}
