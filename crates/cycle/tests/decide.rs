//! The controller's decision step driven directly, without iceoryx2: a valid
//! state gets the control law's torque (paper Eq. (19)), a bad one the safe
//! command τ = g(q_v), a duplicate no answer, a restarted peer is recognised,
//! and a gravity conflict is answered with τ = 0.

use std::path::PathBuf;

use hcc_config::Scenario;
use hcc_control::Controller;
use hcc_cycle::{Answer, ControlCycle, CycleSettings, RESYNC_RUN};
use hcc_msgs::{
    COMMAND_FLAG_GRAVITY_INCLUDED, CommandMode, JointState, STATE_FLAG_DRIVER_GRAVITY_COMPENSATION,
};

/// One control period at 1 kHz, ns.
const PERIOD: u64 = 1_000_000;

/// A shipped scenario of `config/`.
fn load(name: &str) -> Scenario {
    let path = PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("../../config")
        .join(name);
    Scenario::load(&path).unwrap()
}

fn scenario() -> Scenario {
    load("paper-sim1.toml")
}

fn controller(scenario: &Scenario) -> Controller {
    Controller::new(&scenario.model, scenario.spec.clone(), &scenario.q0).unwrap()
}

/// A decider without torque limits (τ is the law's), and the scenario.
fn decider() -> (ControlCycle, Scenario) {
    let scenario = scenario();
    let mut settings = CycleSettings::from_scenario(&scenario);
    assert!(settings.gravity_compensation, "paper-sim1 includes g(q)");
    settings.torque_limits = vec![f64::INFINITY; scenario.model.nq()];
    (
        ControlCycle::new(controller(&scenario), &settings).unwrap(),
        scenario,
    )
}

/// A valid state at q0 + offset, at rest, with sequence number `seq`.
fn state(scenario: &Scenario, seq: u64, offset: f64) -> JointState {
    let n = scenario.model.nq();
    let q: Vec<f64> = scenario.q0.iter().map(|q| q + offset).collect();
    let mut s = JointState::zeroed();
    s.set_joints(&q, &vec![0.1; n], &vec![0.0; n]).unwrap();
    s.header.seq = seq;
    s
}

#[test]
fn a_valid_state_is_answered_normally_with_the_torque_of_the_law() {
    let (mut d, scenario) = decider();
    let mut reference = controller(&scenario);
    for k in 1..=3u64 {
        let s = state(&scenario, k, 0.01 * k as f64);
        assert_eq!(
            d.decide(&s, k * PERIOD),
            Answer::Command(CommandMode::Normal)
        );
        let tau = reference.step(s.q(), s.qd()).unwrap().tau.clone();
        let c = d.command();
        assert_eq!(c.tau(), tau.as_slice(), "state {k}: τ of Eq. (19)");
        assert_eq!((c.state_seq, c.header.seq), (k, k));
        assert_eq!(c.mode, CommandMode::Normal.code());
        assert_eq!(c.flags, COMMAND_FLAG_GRAVITY_INCLUDED);
        assert!(c.validate(s.n()).is_ok());
        let t = d.telemetry();
        assert_eq!((t.state_seq, t.command_seq), (k, k));
        assert_eq!(t.tau(), tau.as_slice());
        assert!(d.step_ns().is_some(), "the law ran");
    }
    let c = d.counters();
    assert_eq!(c.telemetry.cycles, 3);
    assert_eq!(c.telemetry.invalid_states + c.telemetry.sequence_errors, 0);
    assert_eq!(c.core.numerical_failures + c.core.peer_restarts, 0);
}

#[test]
fn a_nan_state_gets_the_safe_hold_with_gravity_at_the_last_valid_state() {
    let (mut d, scenario) = decider();
    // Before any valid state there is no q_v: τ = 0.
    let mut bad = state(&scenario, 1, 0.0);
    bad.q[1] = f64::NAN;
    assert_eq!(
        d.decide(&bad, PERIOD),
        Answer::Command(CommandMode::SafeHold)
    );
    assert!(d.command().tau().iter().all(|&t| t == 0.0));

    let s = state(&scenario, 2, 0.02);
    assert_eq!(
        d.decide(&s, 2 * PERIOD),
        Answer::Command(CommandMode::Normal)
    );
    let gravity: Vec<f64> = d.controller().output().gravity.iter().copied().collect();
    assert!(gravity.iter().any(|g| g.abs() > 1.0), "{gravity:?}");
    let levels = d.telemetry().tau_level(0).to_vec();

    let mut bad = state(&scenario, 3, 0.5);
    bad.qd[2] = f64::NAN;
    assert_eq!(
        d.decide(&bad, 3 * PERIOD),
        Answer::Command(CommandMode::SafeHold)
    );
    assert!(d.step_ns().is_none(), "the law did not run");
    let c = d.command();
    assert_eq!(c.tau(), gravity.as_slice(), "τ = g(q_v)");
    assert_eq!(c.state_seq, 3);
    assert_eq!(c.mode, CommandMode::SafeHold.code());
    assert_eq!(c.flags, COMMAND_FLAG_GRAVITY_INCLUDED);
    let t = d.telemetry();
    assert_eq!(t.mode, CommandMode::SafeHold.code());
    assert_eq!(
        t.tau_level(0),
        levels.as_slice(),
        "the last valid diagnostics"
    );
    assert_eq!(d.counters().telemetry.invalid_states, 2);
}

#[test]
fn a_duplicate_is_not_answered() {
    let (mut d, scenario) = decider();
    let s = state(&scenario, 7, 0.0);
    assert_eq!(d.decide(&s, PERIOD), Answer::Command(CommandMode::Normal));
    let answered = *d.command();
    assert_eq!(d.decide(&s, 2 * PERIOD), Answer::Duplicate);
    assert_eq!(*d.command(), answered, "the command buffer is unchanged");
    let c = d.counters().telemetry;
    assert_eq!((c.cycles, c.sequence_errors), (2, 1));
    // The stream continues.
    let s = state(&scenario, 8, 0.0);
    assert_eq!(
        d.decide(&s, 3 * PERIOD),
        Answer::Command(CommandMode::Normal)
    );
    assert_eq!(d.command().header.seq, 2);
}

#[test]
fn states_going_backwards_three_times_in_a_row_are_a_restarted_peer() {
    let (mut d, scenario) = decider();
    let mut wake = 0;
    let mut decide = |d: &mut ControlCycle, seq: u64| {
        wake += PERIOD;
        d.decide(&state(&scenario, seq, 0.0), wake)
    };
    for seq in 100..110 {
        assert_eq!(decide(&mut d, seq), Answer::Command(CommandMode::Normal));
    }
    // A single backwards state is rejected; the stream then continues.
    assert_eq!(decide(&mut d, 50), Answer::Command(CommandMode::SafeHold));
    assert_eq!(decide(&mut d, 110), Answer::Command(CommandMode::Normal));
    // A driver restarted without an outage counts from 0: the third state
    // that follows the rejected ones resets the checker.
    let mut answers = Vec::new();
    for seq in 0..u64::from(RESYNC_RUN) + 1 {
        answers.push(decide(&mut d, seq));
    }
    assert_eq!(
        answers,
        [
            Answer::Command(CommandMode::SafeHold),
            Answer::Command(CommandMode::SafeHold),
            Answer::Command(CommandMode::Normal),
            Answer::Command(CommandMode::Normal),
        ]
    );
    let c = d.counters();
    assert_eq!(c.core.peer_restarts, 1);
    assert_eq!(c.telemetry.sequence_errors, 3);
    // An implausible jump ahead is rejected like a backwards step.
    assert_eq!(
        decide(&mut d, 1_000_000),
        Answer::Command(CommandMode::SafeHold)
    );
    assert_eq!(decide(&mut d, 4), Answer::Command(CommandMode::Normal));
}

#[test]
fn a_new_peer_after_a_stale_timeout_is_accepted_at_once() {
    let (mut d, scenario) = decider();
    let s = state(&scenario, 500, 0.0);
    assert_eq!(d.decide(&s, PERIOD), Answer::Command(CommandMode::Normal));
    assert!(d.stale(5 * PERIOD), "a new loss");
    assert!(!d.stale(8 * PERIOD), "the same loss");
    assert!(d.peer_lost() && d.telemetry().peer_lost());
    let c = d.counters().telemetry;
    assert_eq!((c.stale_events, c.peer_lost_events), (2, 1));
    assert_eq!(d.telemetry().counters, c);
    let s = state(&scenario, 0, 0.0);
    assert_eq!(
        d.decide(&s, 9 * PERIOD),
        Answer::Command(CommandMode::Normal)
    );
    assert!(!d.peer_lost() && !d.telemetry().peer_lost());
    assert_eq!(d.counters().core.peer_restarts, 1);
}

#[test]
fn a_gravity_conflict_is_answered_with_zero_torque() {
    let (mut d, scenario) = decider();
    let s = state(&scenario, 1, 0.0);
    assert_eq!(d.decide(&s, PERIOD), Answer::Command(CommandMode::Normal));
    // The driver adds g(q) too: both would.
    let mut s = state(&scenario, 2, 0.0);
    s.flags = STATE_FLAG_DRIVER_GRAVITY_COMPENSATION;
    assert_eq!(
        d.decide(&s, 2 * PERIOD),
        Answer::Command(CommandMode::SafeHold)
    );
    let c = d.command();
    assert!(c.tau().iter().all(|&t| t == 0.0), "{:?}", c.tau());
    assert_eq!(c.flags, 0, "the command must not claim to include gravity");
    assert_eq!(d.counters().telemetry.invalid_states, 1);
}

#[test]
fn torque_limits_scale_the_law_and_are_counted() {
    let scenario = scenario();
    let n = scenario.model.nq();
    let mut settings = CycleSettings::from_scenario(&scenario);
    settings.torque_limits = vec![1.0; n];
    let mut d = ControlCycle::new(controller(&scenario), &settings).unwrap();
    let s = state(&scenario, 1, 0.0);
    assert_eq!(d.decide(&s, PERIOD), Answer::Command(CommandMode::Normal));
    let tau = d.command().tau();
    assert!(tau.iter().all(|t| t.abs() <= 1.0), "{tau:?}");
    assert!(tau.iter().any(|t| t.abs() == 1.0), "{tau:?}");
    assert_eq!(d.counters().telemetry.saturations, 1);
    // Bad settings are an error, not a panic.
    settings.torque_limits = vec![1.0; n - 1];
    assert!(ControlCycle::new(controller(&scenario), &settings).is_err());
    settings.torque_limits = vec![-1.0; n];
    assert!(ControlCycle::new(controller(&scenario), &settings).is_err());
}

/// The Panda's k-th state of a smooth motion around q0, numbered `seq`; state 150
/// has a NaN in q.
fn panda_state(scenario: &Scenario, k: u64, seq: u64) -> JointState {
    let n = scenario.model.nq();
    let t = k as f64 * 1e-3;
    let q: Vec<f64> = scenario
        .q0
        .iter()
        .enumerate()
        .map(|(j, q)| q + 0.3 * (t * (1.0 + j as f64)).sin())
        .collect();
    let qd: Vec<f64> = (0..n).map(|j| 0.3 * (t * (1.0 + j as f64)).cos()).collect();
    let mut s = JointState::zeroed();
    s.set_joints(&q, &qd, &vec![0.0; n]).unwrap();
    s.header.seq = seq;
    if k == 150 {
        s.q[2] = f64::NAN;
    }
    s
}

/// The loop decides the command first and fills the telemetry once the
/// command is out (`decide_command`, then `fill_telemetry`): the command and
/// the telemetry sample are byte for byte those of `decide`, through a NaN
/// state and a duplicate, and a sample finished without the explicit fill is
/// complete as well.
#[test]
fn the_telemetry_filled_after_the_command_is_the_same() {
    let scenario = load("panda-pose-posture.toml");
    let settings = CycleSettings::from_scenario(&scenario);
    let make = || ControlCycle::new(controller(&scenario), &settings).unwrap();
    let (mut whole, mut split, mut lazy) = (make(), make(), make());
    fn bytes<T>(x: &T) -> &[u8] {
        // SAFETY: plain-old-data message types, read as bytes for comparison.
        unsafe { std::slice::from_raw_parts((x as *const T).cast::<u8>(), size_of::<T>()) }
    }
    let timings = hcc_msgs::TelemetryTimings::default();
    for k in 1..=300u64 {
        // State 200 repeats 199's sequence number (a duplicate).
        let s = panda_state(&scenario, k, if k == 200 { 199 } else { k });
        let a = whole.decide(&s, k * PERIOD);
        let b = split.decide_command(&s, k * PERIOD);
        let c = lazy.decide_command(&s, k * PERIOD);
        assert_eq!((a, a), (b, c), "state {k}");
        assert_eq!(bytes(whole.command()), bytes(split.command()), "state {k}");
        split.fill_telemetry();
        split.fill_telemetry(); // a second call changes nothing
        assert_eq!(
            bytes(whole.telemetry()),
            bytes(split.telemetry()),
            "state {k}"
        );
        let (x, y) = (
            *whole.finish_telemetry(0, timings, k),
            *lazy.finish_telemetry(0, timings, k),
        );
        assert_eq!(bytes(&x), bytes(&y), "state {k}");
        split.finish_telemetry(0, timings, k);
    }
}
