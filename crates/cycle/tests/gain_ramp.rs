//! A gains setpoint's transition booked through the energy tanks: each step
//! of the stiffness stores ½ eᵀ ΔK e more in the stretched spring, paid from
//! the tanks that the command refilled; where they run out the transition
//! holds (counted, `gain_ramp_held`) instead of putting energy in.

mod common;

use hcc_config::Scenario;
use hcc_cycle::ControlCycle;
use hcc_msgs::{ANSWER_ACCEPTED, Setpoint};

const PERIOD: u64 = 1_000_000;

use common::state_at_start as state;

/// A cycle whose TCP goal has been moved 20 cm away from the held arm and
/// reached (the spring stretched, V_1 = ½ · 350 · 0.2² = 7 J), and the
/// next state's number.
fn stretched() -> (Scenario, ControlCycle, u64) {
    let (sc, mut d) = common::panda_cycle();
    let goal = d.controller().level_target(0).unwrap().goal.to_vec();
    let sp = Setpoint::for_level(7, 1, 0, 3)
        .with_goal(&[goal[0], goal[1] + 0.2, goal[2]])
        .unwrap()
        .with_duration(0.1);
    assert_eq!(d.take_setpoint_now(&sp), ANSWER_ACCEPTED);
    // Stretched to the level's speed limit: 15/8 · 0.2 / 0.25 = 1.5 s.
    let mut seq = 2;
    for _ in 0..2500 {
        d.decide(&state(&sc, seq), seq * PERIOD);
        seq += 1;
    }
    (sc, d, seq)
}

fn stiffen(d: &mut ControlCycle, k: f64) {
    let sp = Setpoint::for_level(7, 2, 0, 3)
        .with_stiffness(&[k; 3])
        .unwrap()
        .with_duration(0.5);
    assert_eq!(d.take_setpoint_now(&sp), ANSWER_ACCEPTED);
}

#[test]
fn a_stiffening_the_tanks_pay_runs_its_course() {
    let (sc, mut d, mut seq) = stretched();
    stiffen(&mut d, 450.0);
    // The command refilled the tanks; the stiffening is paid from them.
    d.decide(&state(&sc, seq), seq * PERIOD);
    seq += 1;
    let spare = d.controller().tank_spare();
    for _ in 1..600 {
        d.decide(&state(&sc, seq), seq * PERIOD);
        seq += 1;
    }
    let k = d.controller().level_target(0).unwrap().stiffness.clone();
    assert_eq!(k[(0, 0)], 450.0);
    assert_eq!(d.counters().core.gain_ramp_held, 0);
    let left = d.controller().tank_spare();
    println!("spare {spare:.3} J → {left:.3} J");
    assert!(left < spare, "the stiffening was paid: {spare} → {left}");
}

#[test]
fn a_stiffening_beyond_the_tanks_holds_where_they_run_out() {
    let (sc, mut d, mut seq) = stretched();
    // ½ · 1050 N/m · (0.2 m)² = 21 J: more than the refilled tanks hold.
    stiffen(&mut d, 1400.0);
    for _ in 0..1000 {
        d.decide(&state(&sc, seq), seq * PERIOD);
        seq += 1;
    }
    let k = d.controller().level_target(0).unwrap().stiffness[(0, 0)];
    let held = d.counters().core.gain_ramp_held;
    let progress = d.telemetry().transition_progress[0];
    println!(
        "K {k:.1} N/m, held {held} cycles, progress {progress:.3}, spare {:.4} J",
        d.controller().tank_spare()
    );
    assert!(k > 350.0 && k < 1400.0, "part of the way: {k}");
    assert!(held > 100, "{held}");
    assert!(progress < 1.0, "the transition waits: {progress}");
    // The telemetry's gains are the law's.
    assert!((d.telemetry().stiffness_diag[0][0] - k).abs() < 1e-9);
}
