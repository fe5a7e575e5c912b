//! The strict hierarchy holds while a lower level's goal moves: a posture
//! goal change (level 3 of the Panda scenario) leaves the TCP (level 1)
//! where it is. Closed loop with the plant (RK4, zero-order hold at 1 kHz),
//! the same run with and without the change; the level-1 deviation between
//! them is printed and bounded. It is not zero only through the sampled
//! loop (the law's J_1 M⁻¹ τ_3 = 0 holds at the sampling instants, the held
//! torque acts on a moving state in between).

use std::path::PathBuf;

use hcc_config::Scenario;
use hcc_control::Controller;
use hcc_controller::{CycleSettings, Decider};
use hcc_msgs::{ANSWER_ACCEPTED, JointState, Setpoint};
use hcc_plant::zoh::{LoopTiming, run_zoh};

/// The TCP position error (level 1) per cycle, with or without a posture change at 1 s.
fn run(change: bool) -> Vec<[f64; 3]> {
    let path =
        PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../../config/panda-pose-posture.toml");
    let sc = Scenario::load(&path).unwrap();
    let settings = CycleSettings::from_scenario(&sc);
    let c = Controller::new(&sc.model, sc.spec.clone(), &sc.q0).unwrap();
    let mut d = Decider::new(c, &settings).unwrap();
    let mut plant = hcc_plant::closed_loop::plant_for(&sc).unwrap();
    let n = sc.model.nq();
    let mut posture: Vec<f64> = sc.q0.iter().copied().collect();
    posture[0] += 0.3;
    posture[2] -= 0.3;
    let mut out = Vec::new();
    let timing = LoopTiming {
        control_period_s: 1e-3,
        substeps: sc.simulation.substeps,
        cycles: 4000,
    };
    run_zoh(&mut plant, timing, |k, _t, q, qd, tau| {
        if change && k == 1000 {
            let sp = Setpoint::for_level(5, 1, 2, n)
                .with_goal(&posture)
                .unwrap()
                .with_duration(1.0);
            assert_eq!(d.take_setpoint(&sp), ANSWER_ACCEPTED);
        }
        let mut s = JointState::zeroed();
        s.set_joints(q.as_slice(), qd.as_slice(), &vec![0.0; n])
            .unwrap();
        s.header.seq = k as u64 + 1;
        d.decide(&s, (k as u64 + 1) * 1_000_000);
        let e = d.telemetry().task_error(0);
        out.push([e[0], e[1], e[2]]);
        tau.as_mut_slice().copy_from_slice(d.command().tau());
        Ok(())
    })
    .unwrap();
    out
}

#[test]
fn a_posture_goal_change_leaves_the_tcp_where_it_is() {
    let plain = run(false);
    let changed = run(true);
    let deviation = plain.iter().zip(&changed).fold(0.0_f64, |m, (a, b)| {
        let d2: f64 = (0..3).map(|j| (a[j] - b[j]).powi(2)).sum();
        m.max(d2.sqrt())
    });
    println!(
        "largest level-1 (TCP) deviation caused by a 0.3 rad posture goal change over 1 s: {deviation:.3e} m"
    );
    assert_eq!(
        plain[..1000],
        changed[..1000],
        "identical before the change"
    );
    assert!(deviation < 1e-5, "{deviation:e}");
}
