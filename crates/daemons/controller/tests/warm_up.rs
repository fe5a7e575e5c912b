//! The cache warm-up steps a twin of the law on the last valid state between
//! decisions: the commands are bit for bit those of a cycle without it (the
//! twin shares no state with the law that answers), on the Panda with its
//! safety layer and null-space basis memory, through a NaN state, and before
//! any valid state (nothing to warm on).

use std::path::PathBuf;

use hcc_config::Scenario;
use hcc_control::Controller;
use hcc_controller::LoopSettings;
use hcc_controller::warm_up::WarmUp;
use hcc_cycle::{ControlCycle, CycleSettings};
use hcc_msgs::JointState;
use hcc_timing::LatencyHistogram;

const PERIOD: u64 = 1_000_000;
const SPIN: u64 = 150_000;

fn scenario() -> Scenario {
    let path =
        PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../../config/panda-pose-posture.toml");
    Scenario::load(&path).unwrap()
}

/// The Panda's k-th state of a smooth motion around q0; state 150 has a NaN in q.
fn panda_state(scenario: &Scenario, k: u64) -> JointState {
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
    s.header.seq = k;
    if k == 150 {
        s.q[2] = f64::NAN;
    }
    s
}

#[test]
fn the_cache_warm_up_changes_no_command() {
    let scenario = scenario();
    assert!(
        LoopSettings::from_scenario(&scenario).warm_up,
        "on by default"
    );
    let settings = CycleSettings::from_scenario(&scenario);
    let make = || {
        let c = Controller::new(&scenario.model, scenario.spec.clone(), &scenario.q0).unwrap();
        ControlCycle::new(c, &settings).unwrap()
    };
    let (mut warm, mut plain) = (make(), make());
    let mut warm_up = WarmUp::new(warm.controller(), true);
    let mut timing = LatencyHistogram::new();
    // A turn 10 µs before the state expected one period after `k`'s.
    let mut turn = |w: &mut WarmUp, cycle: &ControlCycle, s: &JointState, k: u64| {
        let expected = (k + 1) * PERIOD;
        w.turn(
            expected - 10_000,
            expected,
            SPIN,
            (s, cycle.step_ns()),
            &mut timing,
        );
    };
    turn(&mut warm_up, &warm, &JointState::zeroed(), 0);
    assert_eq!(warm_up.count(), 0, "nothing to warm on yet");
    for k in 1..=300u64 {
        let s = panda_state(&scenario, k);
        let (a, b) = (warm.decide(&s, k * PERIOD), plain.decide(&s, k * PERIOD));
        assert_eq!(a, b, "state {k}");
        assert_eq!(warm.command().tau(), plain.command().tau(), "state {k}");
        assert_eq!(warm.telemetry().tau(), plain.telemetry().tau(), "state {k}");
        // Warm on the last state (twice: the second turn of a wait does not
        // run it again); not on the NaN state, which the law did not run on.
        // (A warm-up is also skipped when the law's last step took more than
        // a third of the spin, as on a loaded machine.)
        let before = warm_up.count();
        turn(&mut warm_up, &warm, &s, k);
        turn(&mut warm_up, &warm, &s, k);
        assert!(warm_up.count() - before <= u64::from(k != 150), "state {k}");
        warm_up.arrival((k + 1) * PERIOD, SPIN);
    }
    assert!(warm_up.count() > 0, "the warm-up never ran");
    assert_eq!(timing.count(), warm_up.count());
}
