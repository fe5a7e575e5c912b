//! Tests of the `driver` module.

use super::*;
use crate::COMMAND_FLAG_GRAVITY_INCLUDED;

const N: usize = 2;

fn settings(compensates_gravity: bool) -> DriverSettings {
    let mut d = [0.0; MAX_JOINTS];
    d[..N].copy_from_slice(&[2.0, 3.0]);
    DriverSettings {
        n: N,
        late_tolerance: 0,
        check_sequence: true,
        hold_cycles: 2,
        fallback_timeout_cycles: Some(5),
        wait_for_first_command: false,
        fallback_damping: d,
        gravity: if compensates_gravity {
            Gravity::RobotAdds
        } else {
            Gravity::ControllerSends
        },
        stop_mode: StopMode::SafeStop,
    }
}

/// The gravity torque g(q) = `g` for [`DriverLogic::decide`].
fn given(g: &[f64]) -> impl FnOnce(&mut [f64]) + '_ {
    move |out| out.copy_from_slice(g)
}

fn publish(logic: &mut DriverLogic) -> JointState {
    let mut s = JointState::zeroed();
    logic
        .fill_state(&mut s, &[0.1, 0.2], &[1.0, -1.0], &[0.0, 0.0], 1000)
        .unwrap();
    s
}

fn command(seq: u64, state: &JointState, tau: [f64; N], mode: CommandMode) -> TorqueCommand {
    let mut c = TorqueCommand::zeroed();
    c.set_n_joints(N).unwrap();
    c.header.seq = seq;
    c.answer(state);
    c.mode = mode.code();
    c.flags = if state.driver_compensates_gravity() {
        0
    } else {
        COMMAND_FLAG_GRAVITY_INCLUDED
    };
    c.set_tau(&tau).unwrap();
    c
}

#[test]
fn states_carry_seq_status_flag_and_counters() {
    let mut logic = DriverLogic::new(settings(true));
    let s0 = publish(&mut logic);
    let s1 = publish(&mut logic);
    assert_eq!((s0.header.seq, s1.header.seq), (0, 1));
    assert!(s1.driver_compensates_gravity());
    assert_eq!(s1.status(), Ok(DriverStatus::Ok));
    assert!(s1.validate(N).is_ok());
    let mut logic = DriverLogic::new(settings(false));
    assert!(!publish(&mut logic).driver_compensates_gravity());
    // A non-finite sensor value is refused.
    let mut s = JointState::zeroed();
    assert!(
        logic
            .fill_state(&mut s, &[f64::NAN, 0.0], &[0.0; 2], &[0.0; 2], 0)
            .is_err()
    );
}

#[test]
fn current_command_is_applied_and_echo_is_checked() {
    let mut logic = DriverLogic::new(settings(false));
    let s0 = publish(&mut logic);
    let c = command(0, &s0, [1.0, 2.0], CommandMode::Normal);
    assert_eq!(
        logic.offer(&c, s0.header.seq),
        Offer::Applicable { current: true }
    );
    let mut tau = [0.0; N];
    assert_eq!(
        logic.decide(Some(&c), &[0.0; N], given(&[0.0; N]), &mut tau),
        Action::Apply
    );
    assert_eq!(tau, [1.0, 2.0]);
    // The same command again is old.
    assert_eq!(
        logic.offer(&c, s0.header.seq),
        Offer::Rejected(CommandRejection::Old)
    );
    // A command answering an older state is late (tolerance 0).
    let s1 = publish(&mut logic);
    let late = command(1, &s0, [0.0; N], CommandMode::Normal);
    assert_eq!(
        logic.offer(&late, s1.header.seq),
        Offer::Rejected(CommandRejection::TooLate { cycles: 1 })
    );
    // A command answering a state never published is refused.
    let mut future = command(2, &s1, [0.0; N], CommandMode::Normal);
    future.state_seq = 99;
    assert_eq!(
        logic.offer(&future, s1.header.seq),
        Offer::Rejected(CommandRejection::Future)
    );
    let r = logic.rejections();
    assert_eq!((r.old, r.too_late, r.future), (1, 1, 1));
}

#[test]
fn late_commands_within_the_tolerance_are_applied() {
    let mut s = settings(false);
    s.late_tolerance = 1;
    let mut logic = DriverLogic::new(s);
    let s0 = publish(&mut logic);
    let s1 = publish(&mut logic);
    let c = command(0, &s0, [1.0, 1.0], CommandMode::Normal);
    assert_eq!(
        logic.offer(&c, s1.header.seq),
        Offer::Applicable { current: false }
    );
}

#[test]
fn invalid_and_gravity_conflicting_commands_are_refused() {
    let mut logic = DriverLogic::new(settings(true));
    let s0 = publish(&mut logic);
    // The driver compensates gravity, but the command includes it.
    let mut c = command(0, &s0, [1.0, 2.0], CommandMode::Normal);
    c.flags = COMMAND_FLAG_GRAVITY_INCLUDED;
    assert!(matches!(
        logic.offer(&c, s0.header.seq),
        Offer::Rejected(CommandRejection::GravityConflict(_))
    ));
    let mut c = command(1, &s0, [1.0, 2.0], CommandMode::Normal);
    c.tau[1] = f64::INFINITY;
    assert!(matches!(
        logic.offer(&c, s0.header.seq),
        Offer::Rejected(CommandRejection::Invalid(_))
    ));
    let mut c = command(2, &s0, [1.0, 2.0], CommandMode::Normal);
    c.mode = 77;
    assert!(matches!(
        logic.offer(&c, s0.header.seq),
        Offer::Rejected(CommandRejection::Invalid(_))
    ));
    let mut c = command(3, &s0, [1.0, 2.0], CommandMode::Normal);
    c.header.n_joints = 3;
    assert!(matches!(
        logic.offer(&c, s0.header.seq),
        Offer::Rejected(CommandRejection::Invalid(_))
    ));
}

#[test]
fn misses_hold_then_fall_back_then_stop() {
    let mut logic = DriverLogic::new(settings(false));
    let s0 = publish(&mut logic);
    let c = command(0, &s0, [5.0, 6.0], CommandMode::Normal);
    let mut tau = [0.0; N];
    let qd = [1.0, -1.0];
    let g = [10.0, 20.0];
    logic.decide(Some(&c), &qd, given(&g), &mut tau);
    // hold_cycles = 2: the last τ twice.
    for _ in 0..2 {
        assert_eq!(logic.decide(None, &qd, given(&g), &mut tau), Action::Hold);
        assert_eq!(tau, [5.0, 6.0]);
        assert_eq!(logic.status(), DriverStatus::FallbackActive);
    }
    // Then g − D q̇ (the robot does not compensate gravity).
    assert_eq!(
        logic.decide(None, &qd, given(&g), &mut tau),
        Action::Fallback
    );
    assert_eq!(tau, [10.0 - 2.0, 20.0 + 3.0]);
    assert_eq!(logic.missed_commands(), 3);
    assert_eq!(logic.fallback_cycles(), 3);
    let s = publish(&mut logic);
    assert_eq!(s.status(), Ok(DriverStatus::FallbackActive));
    assert_eq!((s.missed_commands, s.fallback_cycles), (3, 3));
    // An applicable command ends the fallback.
    let c = command(1, &s, [1.0, 1.0], CommandMode::Singular);
    assert_eq!(
        logic.offer(&c, s.header.seq),
        Offer::Applicable { current: true }
    );
    assert_eq!(
        logic.decide(Some(&c), &qd, given(&g), &mut tau),
        Action::Apply
    );
    assert_eq!(logic.status(), DriverStatus::Ok);
    // Timeout (5 periods in a row) stops the driver.
    for _ in 0..5 {
        assert_ne!(
            logic.decide(None, &qd, given(&g), &mut tau),
            Action::Stop { first: true }
        );
    }
    assert_eq!(
        logic.decide(None, &qd, given(&g), &mut tau),
        Action::Stop { first: true }
    );
    assert_eq!(logic.stop_reason(), Some(StopReason::FallbackTimeout));
}

#[test]
fn fallback_without_gravity_when_the_robot_compensates_it() {
    let mut s = settings(true);
    s.hold_cycles = 0;
    let mut logic = DriverLogic::new(s);
    let mut tau = [0.0; N];
    assert_eq!(
        logic.decide(None, &[1.0, 1.0], given(&[10.0, 20.0]), &mut tau),
        Action::Fallback
    );
    assert_eq!(tau, [-2.0, -3.0]);
}

#[test]
fn stop_command_stops_for_good() {
    let mut logic = DriverLogic::new(settings(false));
    let s0 = publish(&mut logic);
    let stop = command(0, &s0, [9.0, 9.0], CommandMode::Stop);
    assert_eq!(
        logic.offer(&stop, s0.header.seq),
        Offer::Applicable { current: true }
    );
    let mut tau = [1.0; N];
    assert_eq!(
        logic.decide(Some(&stop), &[0.0; N], given(&[0.0; N]), &mut tau),
        Action::Stop { first: true }
    );
    assert_eq!(tau, [0.0; N]);
    assert_eq!(logic.stop_reason(), Some(StopReason::Commanded));
    let s1 = publish(&mut logic);
    assert_eq!(s1.status(), Ok(DriverStatus::Stopping));
    logic.stop_completed();
    let s2 = publish(&mut logic);
    assert_eq!(s2.status(), Ok(DriverStatus::Stopped));
    // A later normal command is not applied: no resume within the session.
    let c = command(1, &s2, [1.0, 1.0], CommandMode::Normal);
    logic.offer(&c, s2.header.seq);
    assert_eq!(
        logic.decide(Some(&c), &[0.0; N], given(&[0.0; N]), &mut tau),
        Action::Stop { first: false }
    );
    assert_eq!(tau, [0.0; N]);
    assert_eq!(logic.applied(), 0);
}

#[test]
fn restarted_controller_is_resynchronised() {
    let mut logic = DriverLogic::new(settings(false));
    let s0 = publish(&mut logic);
    let c = command(500, &s0, [1.0, 1.0], CommandMode::Normal);
    assert_eq!(
        logic.offer(&c, s0.header.seq),
        Offer::Applicable { current: true }
    );
    let s1 = publish(&mut logic);
    // The controller restarted: its seq starts again at 0, answering s1.
    let c = command(0, &s1, [1.0, 1.0], CommandMode::Normal);
    assert_eq!(
        logic.offer(&c, s1.header.seq),
        Offer::Applicable { current: true }
    );
    let c = command(1, &s1, [1.0, 1.0], CommandMode::Normal);
    assert_eq!(
        logic.offer(&c, s1.header.seq),
        Offer::Applicable { current: true }
    );
}

/// The simulated robot's settings: only current commands, no sequence
/// check, wait for the first command, no timeout, the driver adds gravity.
fn sim_settings(gravity: Gravity) -> DriverSettings {
    DriverSettings {
        check_sequence: false,
        fallback_timeout_cycles: None,
        wait_for_first_command: true,
        gravity,
        stop_mode: StopMode::Brake,
        ..settings(false)
    }
}

#[test]
fn waiting_for_the_first_command_brakes_without_counting_misses() {
    let mut logic = DriverLogic::new(sim_settings(Gravity::ControllerSends));
    assert_eq!(logic.status(), DriverStatus::FallbackActive);
    let mut tau = [0.0; N];
    for _ in 0..10 {
        assert_eq!(
            logic.decide(None, &[1.0, -1.0], given(&[10.0, 20.0]), &mut tau),
            Action::Waiting
        );
    }
    assert_eq!(tau, [10.0 - 2.0, 20.0 + 3.0]);
    assert_eq!((logic.missed_commands(), logic.fallback_cycles()), (0, 10));
    assert!(!logic.has_command() && !logic.in_fallback());
    // No timeout: misses after a command hold, then fall back for ever.
    let s = publish(&mut logic);
    let c = command(0, &s, [1.0, 1.0], CommandMode::Normal);
    assert_eq!(
        logic.offer(&c, s.header.seq),
        Offer::Applicable { current: true }
    );
    assert_eq!(
        logic.decide(Some(&c), &[0.0; N], given(&[0.0; N]), &mut tau),
        Action::Apply
    );
    for _ in 0..1000 {
        assert_ne!(
            logic.decide(None, &[0.0; N], given(&[0.0; N]), &mut tau),
            Action::Stop { first: true }
        );
    }
    assert!(logic.in_fallback());
    // The same command offered again is not old without the sequence check.
    assert_eq!(
        logic.offer(&c, s.header.seq),
        Offer::Applicable { current: true }
    );
}

#[test]
fn a_driver_adding_gravity_adds_it_to_commands_and_holds_the_sum() {
    let mut logic = DriverLogic::new(sim_settings(Gravity::DriverAdds));
    let s = publish(&mut logic);
    assert!(s.driver_compensates_gravity());
    // A command including gravity conflicts.
    let mut c = command(0, &s, [1.0, 2.0], CommandMode::Normal);
    assert!(!c.gravity_included());
    let mut tau = [0.0; N];
    let g = [10.0, 20.0];
    assert_eq!(
        logic.decide(Some(&c), &[0.0; N], given(&g), &mut tau),
        Action::Apply
    );
    assert_eq!(tau, [11.0, 22.0]);
    // Held as applied (with the gravity of its period), not recomputed.
    assert_eq!(
        logic.decide(None, &[0.0; N], given(&[0.0; N]), &mut tau),
        Action::Hold
    );
    assert_eq!(tau, [11.0, 22.0]);
    c.flags = COMMAND_FLAG_GRAVITY_INCLUDED;
    assert!(matches!(
        logic.offer(&c, s.header.seq),
        Offer::Rejected(CommandRejection::GravityConflict(_))
    ));
    // The fallback torque includes g: the actuators do not add it.
    for _ in 0..2 {
        logic.decide(None, &[0.0; N], given(&[0.0; N]), &mut tau);
    }
    assert_eq!(
        logic.decide(None, &[1.0, 1.0], given(&g), &mut tau),
        Action::Fallback
    );
    assert_eq!(tau, [8.0, 17.0]);
}

#[test]
fn a_braking_stop_is_immediate_and_keeps_braking() {
    let mut logic = DriverLogic::new(sim_settings(Gravity::ControllerSends));
    let s = publish(&mut logic);
    let stop = command(0, &s, [9.0, 9.0], CommandMode::Stop);
    let mut tau = [0.0; N];
    let g = [10.0, 20.0];
    assert_eq!(
        logic.decide(Some(&stop), &[0.0; N], given(&g), &mut tau),
        Action::Stop { first: true }
    );
    assert_eq!(logic.status(), DriverStatus::Stopped);
    assert_eq!(tau, g);
    let c = command(1, &s, [1.0, 1.0], CommandMode::Normal);
    assert_eq!(
        logic.decide(Some(&c), &[0.0; N], given(&g), &mut tau),
        Action::Stop { first: false }
    );
    assert_eq!((logic.applied(), logic.fallback_cycles()), (0, 2));
    assert_eq!(logic.request_stop(), Action::Stop { first: false });
    // A requested stop of a braking driver is immediate too.
    let mut logic = DriverLogic::new(sim_settings(Gravity::ControllerSends));
    assert_eq!(logic.request_stop(), Action::Stop { first: true });
    assert_eq!(logic.status(), DriverStatus::Stopped);
    assert_eq!(logic.stop_reason(), Some(StopReason::Requested));
}

#[test]
fn gravity_agreement_needs_exactly_one_side() {
    assert!(gravity_agreement(true, false).is_ok());
    assert!(gravity_agreement(false, true).is_ok());
    assert!(gravity_agreement(true, true).is_err());
    assert!(gravity_agreement(false, false).is_err());
}
