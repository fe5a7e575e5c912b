//! A level that follows a path (a scenario's `trajectory`) and a goal
//! setpoint for it: the newest command wins. The setpoint's transition
//! starts from where the path is (no jump of the equilibrium), the path
//! stops driving the level, and the level ends at the setpoint's goal.

use std::path::PathBuf;

use hcc_config::Scenario;
use hcc_cycle::{ControlCycle, CycleSettings};
use hcc_msgs::{ANSWER_ACCEPTED, JointState, Setpoint};
use hcc_plant::zoh::{LoopTiming, run_zoh};

#[test]
fn a_goal_setpoint_takes_a_path_level_over_from_where_the_path_is() {
    let path =
        PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../config/panda-figure-eight.toml");
    let sc = Scenario::load(&path).unwrap();
    let c = hcc_cycle::controller_for(&sc).unwrap();
    let mut d = ControlCycle::new(c, &CycleSettings::from_scenario(&sc)).unwrap();
    let mut plant = hcc_plant::plant_for(&sc).unwrap();
    let n = sc.model.nq();
    let period_ns = sc.period_ns();
    let timing = LoopTiming {
        control_period_s: sc.period_s(),
        substeps: 10,
        cycles: 3000,
    };
    let (take_at, target) = (1500, [0.50, 0.02, 0.42]);
    let mut goals: Vec<[f64; 3]> = Vec::new();
    run_zoh(&mut plant, timing, |k, _t, q, qd, tau| {
        if k == take_at {
            let sp = Setpoint::for_level(5, 1, 0, 3)
                .with_goal(&target)
                .unwrap()
                .with_duration(0.5);
            assert_eq!(d.take_setpoint_now(&sp), ANSWER_ACCEPTED);
        }
        let mut s = JointState::zeroed();
        s.set_joints(q.as_slice(), qd.as_slice(), &vec![0.0; n])
            .unwrap();
        s.header.seq = k as u64 + 1;
        d.decide(&s, (k as u64 + 1) * period_ns);
        let g = &d.telemetry().goal[0];
        goals.push([g[0], g[1], g[2]]);
        tau.as_mut_slice().copy_from_slice(d.command().tau());
        Ok(())
    })
    .unwrap();
    let step = |k: usize| {
        (0..3)
            .map(|a| (goals[k + 1][a] - goals[k][a]).powi(2))
            .sum::<f64>()
            .sqrt()
    };
    // On the path the equilibrium moves at most ~0.16 m/s (0.16 mm per
    // cycle); the handover keeps that order: no jump.
    let largest = (1..goals.len() - 1).map(step).fold(0.0, f64::max);
    println!(
        "largest step of level 1's equilibrium per cycle: {largest:.3e} m; at the handover {:.3e} m",
        step(take_at - 1)
    );
    assert!(largest < 5e-4, "{largest:.3e} m");
    // The path no longer drives the level: it ends at the setpoint's goal.
    let last = goals[goals.len() - 1];
    assert!(
        (0..3).all(|a| (last[a] - target[a]).abs() < 1e-12),
        "{last:?}"
    );
}
