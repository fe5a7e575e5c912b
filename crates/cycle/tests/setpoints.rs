//! Setpoints through the decision step, without iceoryx2: accepted ones move
//! the law's equilibrium smoothly to the target (stretched to the level's
//! speed limit), every bad kind is rejected with its code and changes
//! nothing, and every setpoint is answered in telemetry.

mod common;

use std::path::PathBuf;

use hcc_config::Scenario;
use hcc_control::Controller;
use hcc_cycle::{ControlCycle, CycleSettings};
use hcc_msgs::{ANSWER_ACCEPTED, JointState, Setpoint, SetpointRejection};

const PERIOD: u64 = 1_000_000;

fn scenario() -> Scenario {
    let path =
        PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../config/panda-pose-posture.toml");
    Scenario::load(&path).unwrap()
}

fn decider(scenario: &Scenario) -> ControlCycle {
    let settings = CycleSettings::from_scenario(scenario);
    let c = Controller::new(&scenario.model, scenario.spec.clone(), &scenario.q0).unwrap();
    ControlCycle::new(c, &settings).unwrap()
}

use common::state_at_start as state;

#[test]
fn a_goal_moves_the_equilibrium_smoothly_and_is_answered() {
    let sc = scenario();
    let mut d = decider(&sc);
    let mut seq = 1;
    d.decide(&state(&sc, seq), PERIOD);
    let start = d.controller().level_target(0).unwrap().goal.to_vec();
    assert_eq!(start, [0.55, 0.20, 0.30]);
    // 0.1 m in 0.2 s would peak at 0.94 m/s: stretched to 15/8 · 0.1 / 0.25 = 0.75 s.
    let sp = Setpoint::for_level(42, 7, 0, 3)
        .with_goal(&[0.55, 0.30, 0.30])
        .unwrap()
        .with_duration(0.2);
    assert_eq!(d.take_setpoint_now(&sp), ANSWER_ACCEPTED);
    let a = *d.telemetry().answer_for(42).expect("answered");
    assert_eq!((a.seq, a.code, a.level), (7, ANSWER_ACCEPTED, 0));
    assert!((a.duration_s - 0.75).abs() < 1e-12, "{}", a.duration_s);
    let mut last = start[1];
    for k in 0..750 {
        seq += 1;
        d.decide(&state(&sc, seq), (k + 2) * PERIOD);
        let y = d.controller().level_target(0).unwrap().goal[1];
        assert!(
            y >= last && y - last < 0.25e-3 + 1e-12,
            "smooth and within the speed limit"
        );
        last = y;
    }
    let t = d.telemetry();
    assert!((t.goal(0)[1] - 0.30).abs() < 1e-12);
    assert_eq!(t.transition_progress[0], 1.0);
    assert_eq!(t.stiffness_diag[0][..3], [350.0; 3]);
    assert_eq!(
        d.controller().level_target(0).unwrap().goal,
        [0.55, 0.30, 0.30]
    );
    // The other levels were not touched.
    assert_eq!(
        d.controller().level_target(2).unwrap().goal,
        sc.q0.as_slice()
    );
}

#[test]
fn every_bad_setpoint_is_rejected_with_its_code_and_changes_nothing() {
    let sc = scenario();
    let mut d = decider(&sc);
    d.decide(&state(&sc, 1), PERIOD);
    let goal = |level: usize, g: &[f64]| {
        Setpoint::for_level(1, 1, level, g.len())
            .with_goal(g)
            .unwrap()
    };
    let mut nan = goal(0, &[0.5, 0.1, 0.3]);
    nan.goal[1] = f64::NAN;
    let not_spd = Setpoint::for_level(1, 1, 0, 3)
        .with_stiffness(&[100.0, 0.0, -5.0])
        .unwrap();
    // Symmetric (the message's shape is right), indefinite: the cycle's
    // factorisation rejects it.
    let not_spd_full = Setpoint::for_level(1, 1, 0, 3)
        .with_damping(&[10.0, 20.0, 0.0, 20.0, 10.0, 0.0, 0.0, 0.0, 10.0])
        .unwrap();
    assert_eq!(not_spd_full.validate(), Ok(()));
    let too_stiff = Setpoint::for_level(1, 1, 0, 3)
        .with_stiffness(&[100.0, 100.0, 4.0 * 350.0 + 1.0])
        .unwrap();
    let mut joint = sc.q0.as_slice().to_vec();
    joint[3] = 1.0; // the Panda's joint 4 is limited to [-3.07, -0.07] rad
    // The hand's rotation about joint 7 is light: 100 N·m·s/rad of posture
    // damping is far more than 1 kHz carries (hcc_control::rate).
    let too_damped = Setpoint::for_level(1, 1, 2, 7)
        .with_damping(&[100.0; 7])
        .unwrap();
    let cases = [
        (goal(5, &[0.5, 0.1, 0.3]), SetpointRejection::UnknownLevel),
        (goal(0, &[0.5, 0.1]), SetpointRejection::DimensionMismatch),
        (nan, SetpointRejection::NonFinite),
        (not_spd, SetpointRejection::NotPositiveDefinite),
        (not_spd_full, SetpointRejection::NotPositiveDefinite),
        (too_stiff, SetpointRejection::StiffnessAboveLimit),
        (goal(2, &joint), SetpointRejection::JointLimit),
        (
            goal(0, &[3.0, 0.0, 0.3]),
            SetpointRejection::OutsideWorkspace,
        ),
        (
            goal(0, &[0.5, 0.1, 0.3]).with_duration(-1.0),
            SetpointRejection::BadDuration,
        ),
        (too_damped, SetpointRejection::GainsAboveRate),
    ];
    for (k, (mut sp, reason)) in cases.into_iter().enumerate() {
        sp.header.seq = k as u64 + 10;
        assert_eq!(d.take_setpoint_now(&sp), reason.code(), "{reason}");
        let a = *d.telemetry().answer_for(1).unwrap();
        assert_eq!((a.seq, a.code), (k as u64 + 10, reason.code()));
        d.decide(&state(&sc, k as u64 + 2), (k as u64 + 2) * PERIOD);
        let target = d.controller().level_target(0).unwrap();
        assert_eq!(target.goal, [0.55, 0.20, 0.30], "unchanged after {reason}");
        assert_eq!(target.stiffness[(2, 2)], 350.0);
        assert_eq!(d.telemetry().transition_progress[0], 1.0);
    }
    assert_eq!(d.telemetry().answer_for(1).unwrap().answered, 10);
    assert_eq!(d.controller().level_target(2).unwrap().damping[(6, 6)], 1.5);
}

/// Gains setpoints against the control rate (hcc_control::rate): the
/// refusal names nothing but its code; the bound scales with the gain, so
/// the damping at the largest accepted scale passes and twice it does not.
#[test]
fn gains_the_control_rate_cannot_carry_are_rejected() {
    let sc = scenario();
    let mut d = decider(&sc);
    d.decide(&state(&sc, 1), PERIOD);
    let mut c = Controller::new(&sc.model, sc.spec.clone(), &sc.q0).unwrap();
    let big = nalgebra::DMatrix::from_diagonal_element(7, 7, 100.0);
    let e = c.check_gain_rate(2, None, Some(&big)).unwrap_err();
    println!("posture damping 100: {e}");
    assert!(e.damping && e.value > hcc_control::rate::B_MAX, "{e:?}");
    let carried = 0.99 * 100.0 * e.scale();
    let damping = |seq: u64, v: f64| {
        let mut sp = Setpoint::for_level(5, seq, 2, 7)
            .with_damping(&[v; 7])
            .unwrap();
        sp.header.seq = seq;
        sp
    };
    assert_eq!(
        d.take_setpoint_now(&damping(1, 2.0 * carried)),
        SetpointRejection::GainsAboveRate.code()
    );
    assert_eq!(d.take_setpoint_now(&damping(2, carried)), ANSWER_ACCEPTED);
}

#[test]
fn a_workspace_box_and_the_velocity_feed_forward() {
    let sc = scenario();
    let mut settings = CycleSettings::from_scenario(&sc);
    settings.setpoint_limits.levels[0].workspace =
        Some((vec![0.3, -0.3, 0.2], vec![0.7, 0.3, 0.6]));
    let c = Controller::new(&sc.model, sc.spec.clone(), &sc.q0).unwrap();
    let mut d = ControlCycle::new(c, &settings).unwrap();
    d.decide(&state(&sc, 1), PERIOD);
    let outside = Setpoint::for_level(3, 1, 0, 3)
        .with_goal(&[0.55, 0.20, 0.65])
        .unwrap();
    assert_eq!(
        d.take_setpoint_now(&outside),
        SetpointRejection::OutsideWorkspace.code()
    );
    // Inside the box, with a feed-forward: the law damps ẋ − ẋ_d.
    let inside = Setpoint::for_level(3, 2, 0, 3)
        .with_goal(&[0.55, 0.20, 0.30])
        .unwrap()
        .with_velocity(&[0.0, 0.05, 0.0])
        .unwrap();
    assert_eq!(d.take_setpoint_now(&inside), ANSWER_ACCEPTED);
    d.decide(&state(&sc, 2), 2 * PERIOD);
    let v = d.controller().level_target(0).unwrap().goal_velocity;
    assert_eq!(v, [0.0, 0.05, 0.0]);

    // With relative damping off, the law keeps D ẋ (ẋ_d = 0).
    settings.setpoint_limits.relative_damping = false;
    let c = Controller::new(&sc.model, sc.spec.clone(), &sc.q0).unwrap();
    let mut d = ControlCycle::new(c, &settings).unwrap();
    d.decide(&state(&sc, 1), PERIOD);
    assert_eq!(d.take_setpoint_now(&inside), ANSWER_ACCEPTED);
    d.decide(&state(&sc, 2), 2 * PERIOD);
    let v = d.controller().level_target(0).unwrap().goal_velocity;
    assert_eq!(v, [0.0; 3]);
}

/// Hands `setpoints` to the cycle with `state` (as the daemon does with
/// those that arrived in the state's cycle); the answer of client `id`
/// after it, if any.
fn deliver(
    d: &mut ControlCycle,
    state: &JointState,
    setpoints: &[Setpoint],
    id: u64,
) -> Option<hcc_msgs::SetpointAnswer> {
    let mut next = setpoints.iter().copied();
    d.take_setpoints(state, || next.next());
    d.telemetry().answer_for(id).copied()
}

/// The application point: a setpoint due at a later state waits in the
/// queue (unanswered) and is applied in that state's cycle, before its
/// transition advances; arrival order is kept for setpoints due together; a
/// late one is applied on receipt and counted; a full queue rejects; a
/// malformed one is rejected at receipt.
#[test]
fn setpoints_wait_for_their_state() {
    let sc = scenario();
    let mut d = decider(&sc);
    let id = 77;
    let goal = |seq: u64, y: f64, at: u64| {
        Setpoint::for_level(id, seq, 0, 3)
            .with_goal(&[0.55, y, 0.30])
            .unwrap()
            .with_duration(1.0)
            .with_apply_at(at)
    };
    // Cycle of state 0: a stiffness change and two goals, all for state 5
    // (applied in arrival order: the last goal wins).
    let k = Setpoint::for_level(id, 1, 0, 3)
        .with_stiffness(&[300.0, 300.0, 300.0])
        .unwrap()
        .with_duration(0.0)
        .with_apply_at(5);
    let s0 = state(&sc, 0);
    let answer = deliver(&mut d, &s0, &[k, goal(2, 0.25, 5), goal(3, 0.30, 5)], id);
    assert!(answer.is_none(), "queued, not answered yet");
    assert_eq!(d.pending_setpoints(), 3);
    d.decide(&s0, PERIOD);
    assert!(d.telemetry().answer_for(id).is_none(), "not answered yet");
    for seq in 1..5 {
        assert!(deliver(&mut d, &state(&sc, seq), &[], id).is_none());
        d.decide(&state(&sc, seq), (seq + 1) * PERIOD);
        let g = d.controller().level_target(0).unwrap().goal.to_vec();
        assert_eq!(g, [0.55, 0.20, 0.30], "nothing before state 5");
    }
    let a = deliver(&mut d, &state(&sc, 5), &[], id).expect("answered in the cycle of state 5");
    assert_eq!(d.pending_setpoints(), 0);
    assert_eq!(
        (a.seq, a.answered, a.code, a.rejected, a.late),
        (3, 3, 0, 0, 0)
    );
    d.decide(&state(&sc, 5), 6 * PERIOD);
    let target = d.controller().level_target(0).unwrap();
    // The equilibrium moved one period towards 0.30 (the last goal), and
    // the stiffness is the new one (at once, then held).
    assert!(
        target.goal[1] > 0.20 && target.goal[1] < 0.2001,
        "{}",
        target.goal[1]
    );
    assert_eq!(d.telemetry().goal[0][1], target.goal[1]);
    assert_eq!(target.stiffness[(0, 0)], 300.0);

    // Late: state 3 is past; applied on receipt and counted.
    let s6 = state(&sc, 6);
    let a = deliver(&mut d, &s6, &[goal(4, 0.25, 3)], id).unwrap();
    assert_eq!(
        (a.seq, a.answered, a.code, a.late),
        (4, 4, ANSWER_ACCEPTED, 1)
    );
    // Malformed: rejected at receipt, not queued.
    let mut bad = goal(5, 0.25, 100);
    bad.goal[0] = f64::NAN;
    let a = deliver(&mut d, &s6, &[bad], id).unwrap();
    assert_eq!((a.seq, a.code), (5, SetpointRejection::NonFinite.code()));
    assert_eq!(d.pending_setpoints(), 0);
    // A full queue rejects with pending_full and changes nothing (the cycle
    // takes at most SETPOINT_BUFFER setpoints per state).
    let mut queued = 0;
    while queued < hcc_msgs::MAX_PENDING_SETPOINTS as u64 {
        let batch: Vec<Setpoint> = (queued..hcc_msgs::MAX_PENDING_SETPOINTS as u64)
            .take(hcc_msgs::ipc::SETPOINT_BUFFER)
            .map(|k| goal(6 + k, 0.25, 1000 + k))
            .collect();
        queued += batch.len() as u64;
        let a = deliver(&mut d, &s6, &batch, id).unwrap();
        assert_eq!(a.seq, 5, "queued setpoints are not answered yet");
    }
    assert_eq!(d.pending_setpoints(), hcc_msgs::MAX_PENDING_SETPOINTS);
    let a = deliver(&mut d, &s6, &[goal(99, 0.25, 5000)], id).unwrap();
    assert_eq!(
        (a.seq, a.code, a.rejected),
        (99, SetpointRejection::PendingFull.code(), 2)
    );
    // They drain in order as their states come.
    deliver(&mut d, &state(&sc, 1000 + 9), &[], id);
    assert_eq!(d.pending_setpoints(), hcc_msgs::MAX_PENDING_SETPOINTS - 10);
    assert_eq!(d.telemetry().answer_for(id).unwrap().seq, 6 + 9);
    // A malformed state does not move the setpoint clock: a setpoint due at
    // state 1010 still waits, although the broken state is numbered beyond.
    let mut broken = state(&sc, 1_000_000);
    broken.q[0] = f64::NAN;
    deliver(&mut d, &broken, &[], id);
    assert_eq!(d.pending_setpoints(), hcc_msgs::MAX_PENDING_SETPOINTS - 10);
    deliver(&mut d, &state(&sc, u64::MAX / 2), &[], id);
    assert_eq!(d.pending_setpoints(), 0);
}

#[test]
fn a_stream_that_stops_fades_its_feed_forward_to_rest() {
    use hcc_cycle::setpoints::{STREAM_FADE_S, STREAM_TIMEOUT_S};
    let sc = scenario();
    let c = Controller::new(&sc.model, sc.spec.clone(), &sc.q0).unwrap();
    let mut d = ControlCycle::new(c, &CycleSettings::from_scenario(&sc)).unwrap();
    d.decide(&state(&sc, 1), PERIOD);
    let sample = Setpoint::for_level(3, 1, 0, 3)
        .with_goal(&[0.55, 0.20, 0.30])
        .unwrap()
        .with_velocity(&[0.0, 0.05, 0.0])
        .unwrap();
    assert_eq!(d.take_setpoint_now(&sample), ANSWER_ACCEPTED);
    // The last sample of the stream: ẋ_d held, then fading, then zero.
    let mut seen = Vec::new();
    for k in 2..=120u64 {
        d.decide(&state(&sc, k), k * PERIOD);
        seen.push(d.controller().level_target(0).unwrap().goal_velocity[1]);
    }
    let at = |s: f64| seen[(s * 1000.0).round() as usize - 1];
    assert_eq!(at(STREAM_TIMEOUT_S - 0.002), 0.05);
    let mid = at(STREAM_TIMEOUT_S + 0.5 * STREAM_FADE_S);
    assert!((mid - 0.025).abs() < 2e-3, "{mid}");
    assert_eq!(at(STREAM_TIMEOUT_S + STREAM_FADE_S + 0.005), 0.0);
    // Linear: no step above one period's share of the fade.
    let step = seen
        .windows(2)
        .map(|w| (w[1] - w[0]).abs())
        .fold(0.0, f64::max);
    assert!(step <= 0.05 * 1e-3 / STREAM_FADE_S + 1e-12, "{step}");
    assert_eq!(d.counters().core.streams_stopped, 1);
    assert_eq!(d.telemetry().goal[0][..3], [0.55, 0.20, 0.30]);
}
