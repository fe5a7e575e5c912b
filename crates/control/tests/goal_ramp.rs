//! A goal transition booked through the command tank (`Controller::grant_goal_step`,
//! `Controller::ramp_goal`): a goal setpoint grants the energy the step to its
//! target would store; each step of the goal is paid from it (its work on the
//! spring), so that H rises by the grant and by nothing else; a step nothing
//! can pay is refused.

mod common;
use common::*;
use hcc_control::Controller;
use nalgebra::DVector;

const Q0: [f64; 7] = [0.1, -0.2, 0.05, -2.0, 0.1, 1.9, 0.7];
const REST: [f64; 7] = [0.0; 7];

/// The Panda's controller at rest at `Q0`, every level at its goal (H = the
/// tanks' content), with `tank_initial` J in its tanks; the TCP's position.
fn panda_at_goal(tank_initial: f64) -> (Controller, [f64; 3]) {
    panda_tcp_offset(&Q0, [0.0; 3], tank_initial)
}

/// Grants a 5 cm step of the TCP goal along x and moves the goal there on
/// the minimum-jerk profile in 0.4 s (as a transition moves it: peak
/// 0.23 m/s), the arm held still; `relative`: the damper is told the goal's
/// velocity. Returns the largest rise of H from one cycle to the next.
fn move_5cm(c: &mut Controller, p: [f64; 3], relative: bool) -> f64 {
    c.grant_goal_step(0, &[p[0] + 0.05, p[1], p[2]])
        .expect("grant");
    c.set_commands_active(true);
    let mut h = c.step(&Q0, &REST).expect("step").safety.h;
    let (period, duration) = (1e-3, 0.4);
    let cycles = (duration / period) as usize;
    let mut rise: f64 = 0.0;
    for k in 1..=cycles {
        let (s, ds, _) = hcc_control::transition::quintic(k as f64 / cycles as f64);
        let goal = [p[0] + 0.05 * s, p[1], p[2]];
        let rate = [0.05 * ds / duration, 0.0, 0.0];
        assert!(c.ramp_goal(0, &goal, &rate).expect("goal"));
        if relative {
            c.set_goal_velocity(0, &rate).expect("velocity");
        }
        let out = c.step(&Q0, &REST).expect("step");
        assert!(out.command_input.paid);
        assert!(out.command_input.goal_power >= 0.0, "the goal leads");
        rise = rise.max(out.safety.h - h);
        h = out.safety.h;
    }
    rise
}

#[test]
fn a_goal_setpoint_grants_what_its_step_would_store() {
    let (mut c, p) = panda_at_goal(2.0);
    let before = c.step(&Q0, &REST).expect("step").safety.h;
    // ½ · 800 N/m · (5 cm)² = 1 J, and half of it for each of the two
    // levels' tanks.
    let grant = c
        .grant_goal_step(0, &[p[0] + 0.05, p[1], p[2]])
        .expect("grant");
    assert!((grant - 2.0).abs() < 1e-9, "{grant}");
    // A target where the goal is stores nothing.
    assert_eq!(c.grant_goal_step(0, &p).expect("grant"), 0.0);
    let out = c.step(&Q0, &REST).expect("step");
    assert!((out.command_input.granted - 2.0).abs() < 1e-9);
    assert!((out.command_input.tank - 2.0).abs() < 1e-9);
    assert!(
        (out.safety.h - before - 2.0).abs() < 1e-9,
        "H rises by the grant: {before} → {}",
        out.safety.h
    );
    assert!(c.grant_goal_step(0, &[0.0; 2]).is_err());
    assert!(c.grant_goal_step(0, &[f64::NAN; 3]).is_err());
    assert!(c.grant_goal_step(7, &p).is_err());
}

#[test]
fn the_goals_steps_are_paid_from_the_grant_and_h_never_rises() {
    let (mut c, p) = panda_at_goal(2.0);
    let rise = move_5cm(&mut c, p, true);
    // Booked from one cycle's F for the coming period, the work differs from
    // the spring's rise by second-order terms; the fade's tank books level
    // 1's damper ahead (at the sample that starts the period), the command
    // tank its payment at the next: while the goal speeds up, H rises by the
    // damper power's change over one period (here the arm does not move, so
    // the whole damper power ẋ_dᵀDẋ_d is the goal's). The sweep's tolerance.
    assert!(rise < 1e-4, "H rose by {rise} J from one cycle to the next");
    let out = c.step(&Q0, &REST).expect("step");
    assert!((out.potential[0] - 1.0).abs() < 1e-9, "{:?}", out.potential);
    // The grant paid the spring's 1 J, the damper's work (which filled the
    // fade's tank) and the levels' tanks' top-ups (half the storage) as far
    // as it went; the spare paid the rest.
    let (tank, unpaid) = c.command_tank();
    assert!(tank < 1e-9, "{tank}");
    assert_eq!(unpaid, 0.0);
    c.set_commands_active(false);
    c.step(&Q0, &REST).expect("step");
    assert_eq!(c.command_tank().0, 0.0);
}

#[test]
fn a_goal_step_nothing_can_pay_waits() {
    // No tank holds anything at the goal: no spare, no grant.
    let (mut c, p) = panda_at_goal(0.0);
    c.step(&Q0, &REST).expect("step");
    assert_eq!(c.tank_spare(), 0.0);
    let goal = [p[0] + 0.001, p[1], p[2]];
    assert!(
        !c.ramp_goal(0, &goal, &[0.0; 3]).expect("goal"),
        "nothing pays"
    );
    assert_eq!(c.level_target(0).expect("level").goal, &p);
    c.grant_goal_step(0, &[p[0] + 0.05, p[1], p[2]])
        .expect("grant");
    c.set_commands_active(true);
    c.step(&Q0, &REST).expect("step");
    assert!(
        c.ramp_goal(0, &goal, &[0.0; 3]).expect("goal"),
        "the grant pays"
    );
    assert_eq!(c.level_target(0).expect("level").goal, &goal);
}

#[test]
fn with_the_tanks_off_a_goal_step_is_a_goal() {
    let model = panda();
    let mut spec = panda_spec(&model);
    spec.safety.energy_tanks = false;
    let q0 = DVector::from_vec(Q0.to_vec());
    let mut c = Controller::new(&model, spec, &q0).expect("ctl");
    c.step(&Q0, &REST).expect("step");
    let goal = [0.4, 0.1, 0.5];
    assert_eq!(c.grant_goal_step(0, &goal).expect("grant"), 0.0);
    assert!(c.ramp_goal(0, &goal, &[0.0; 3]).expect("goal"));
    assert_eq!(c.level_target(0).expect("level").goal, &goal);
}

#[test]
fn a_goal_the_damper_is_not_told_is_booked_at_its_rate() {
    // `relative_damping = false`: the damper acts on ẋ_i, the goal still
    // moves; its work on the spring is booked at the transition's rate.
    let (mut c, p) = panda_at_goal(2.0);
    let rise = move_5cm(&mut c, p, false);
    // The arm held still: no damper acts, the spring's work is the whole of
    // it, booked at the rate at the period's start — below its mean while
    // the goal speeds up (K |x̃| ẍ_d T² / 2 ≈ 2e-5 J here). The sweep's
    // tolerance.
    assert!(rise < 1e-4, "H rose by {rise} J from one cycle to the next");
    let out = c.step(&Q0, &REST).expect("step");
    assert!((out.potential[0] - 1.0).abs() < 1e-9);
    let (tank, unpaid) = c.command_tank();
    assert!(tank > 0.0 && unpaid == 0.0, "{tank} {unpaid}");
}
