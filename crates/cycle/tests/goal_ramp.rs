//! A goal setpoint's transition paid from its command tank: the setpoint is
//! granted the energy its step would store (and the tanks' share of it) when
//! it is taken; its steps are paid from that grant, so that H rises when it
//! is taken and not while the goal moves; nothing is held or unpaid; once the
//! transition is over the rest of the grant is dropped.

mod common;

use std::path::PathBuf;

use hcc_config::Scenario;
use hcc_control::Controller;
use hcc_cycle::{ControlCycle, CycleSettings};
use hcc_msgs::{ANSWER_ACCEPTED, Setpoint};

const PERIOD: u64 = 1_000_000;

use common::state_at_start as state;

#[test]
fn a_goal_transition_is_paid_from_its_grant() {
    let path =
        PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../config/panda-pose-posture.toml");
    let sc = Scenario::load(&path).unwrap();
    let settings = CycleSettings::from_scenario(&sc);
    let c = Controller::new(&sc.model, sc.spec.clone(), &sc.q0).unwrap();
    let mut d = ControlCycle::new(c, &settings).unwrap();
    d.decide(&state(&sc, 1), PERIOD);
    let goal = d.controller().level_target(0).unwrap().goal.to_vec();
    // 5 cm along y; the arm held where it is (the state never changes).
    let sp = Setpoint::for_level(7, 1, 0, 3)
        .with_goal(&[goal[0], goal[1] + 0.05, goal[2]])
        .unwrap()
        .with_duration(0.5);
    let before = d.storage();
    assert_eq!(d.take_setpoint_now(&sp), ANSWER_ACCEPTED);
    let mut seq = 2;
    d.decide(&state(&sc, seq), seq * PERIOD);
    seq += 1;
    let input = d.controller().output().command_input;
    let v1 = d.controller().output().potential[0];
    assert!(input.granted > 0.0, "{input:?}");
    assert!(input.tank > 0.0 && input.paid, "{input:?}");
    let mut h = d.storage();
    assert!(h > before, "the grant is an input: {before} → {h}");
    let mut rise: f64 = 0.0;
    let mut cycles = 0;
    while d.telemetry().transition_progress[0] < 1.0 && cycles < 2000 {
        d.decide(&state(&sc, seq), seq * PERIOD);
        seq += 1;
        cycles += 1;
        rise = rise.max(d.storage() - h);
        h = d.storage();
    }
    println!(
        "grant {:.4} J, V_1 {v1:.2e} → {:.4} J over {cycles} cycles, largest rise of H {rise:.2e} J",
        input.granted,
        d.controller().output().potential[0]
    );
    assert!(cycles < 2000, "the transition ends");
    assert!(rise < 1e-4, "H rose by {rise} J while the goal moved");
    assert_eq!(d.counters().core.goal_ramp_held, 0);
    assert_eq!(d.counters().core.command_unpaid_mj, 0);
    // The goal is where it was sent; what was left of the grant is dropped.
    let now = d.controller().level_target(0).unwrap().goal.to_vec();
    assert!((now[1] - goal[1] - 0.05).abs() < 1e-12);
    d.decide(&state(&sc, seq), seq * PERIOD);
    assert_eq!(d.controller().command_tank().0, 0.0);
}
