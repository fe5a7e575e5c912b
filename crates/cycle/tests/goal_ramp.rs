//! A goal setpoint's transition paid from its command tank: the setpoint is
//! granted the energy its step would store (and the tanks' share of it) when
//! it is taken; its steps are paid from that grant, so that H rises when it
//! is taken and not while the goal moves; nothing is held or unpaid; once the
//! transition is over the rest of the grant is dropped.

mod common;

use hcc_msgs::{ANSWER_ACCEPTED, Setpoint};

const PERIOD: u64 = 1_000_000;

use common::state_at_start as state;

#[test]
fn a_goal_transition_is_paid_from_its_grant() {
    let (sc, mut d) = common::panda_cycle();
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

#[test]
fn a_stream_of_setpoints_refills_the_tanks_once() {
    // A client streaming its goal with its velocity, a setpoint every cycle
    // (as `hcc teleop` does): the first one refills the tanks, the others
    // arrive while its transition runs and add their grants to the command
    // tank — no refill per message.
    let (sc, mut d) = common::panda_cycle();
    let goal = d.controller().level_target(0).unwrap().goal.to_vec();
    let (mut refills, mut grants) = (Vec::new(), 0.0);
    for k in 0..300u64 {
        // 0.05 m/s along y.
        let y = goal[1] + 0.05 * 1e-3 * (k + 1) as f64;
        let sp = Setpoint::for_level(7, k + 1, 0, 3)
            .with_goal(&[goal[0], y, goal[2]])
            .unwrap()
            .with_velocity(&[0.0, 0.05, 0.0])
            .unwrap();
        assert_eq!(d.take_setpoint_now(&sp), ANSWER_ACCEPTED);
        let seq = k + 2;
        d.decide(&state(&sc, seq), seq * PERIOD);
        let input = d.controller().output().command_input;
        refills.push(input.refill);
        grants += input.granted;
    }
    println!(
        "refills {:.4} J at the first message, {:.2e} J after; grants {grants:.4} J",
        refills[0],
        refills[1..].iter().sum::<f64>()
    );
    assert!(refills[1..].iter().all(|&r| r == 0.0), "{refills:?}");
    assert!(grants > 0.0);
    assert_eq!(d.counters().core.goal_ramp_held, 0);
    assert_eq!(d.counters().core.command_unpaid_mj, 0);
}
