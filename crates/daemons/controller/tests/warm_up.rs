//! The cache warm-up steps a twin of the law on the last valid state between
//! cycles: the commands are bit for bit those of a cycle without it (the
//! twin shares no state with the law that answers), on the Panda with its
//! safety layer and null-space basis memory, through a NaN state and before
//! any valid state (nothing to warm on) — and it allocates nothing.
//!
//! The states are those of an in-process run of the scenario (its first
//! 0.3 s), so the law sees a real motion.

use std::path::PathBuf;

use hcc_config::Scenario;
use hcc_control::Controller;
use hcc_controller::LoopSettings;
use hcc_controller::warm_up::WarmUp;
use hcc_cycle::{ControlCycle, CycleSettings};
use hcc_msgs::JointState;
use hcc_rtalloc::{RtAllocator, RtSection, thread_stats};
use hcc_timing::LatencyHistogram;

#[global_allocator]
static ALLOCATOR: RtAllocator = RtAllocator::new();

const PERIOD: u64 = 1_000_000;
const SPIN: u64 = 150_000;
/// The state replaced by one with a NaN.
const BROKEN: usize = 150;

fn scenario() -> Scenario {
    let path =
        PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../../config/panda-pose-posture.toml");
    Scenario::load(&path).unwrap()
}

/// The states of the scenario's first 0.3 s in process; one has a NaN in q.
fn states(scenario: &Scenario) -> Vec<JointState> {
    let mut short = scenario.clone();
    short.set_duration(0.3).unwrap();
    let mut states = Vec::new();
    hcc_in_process::simulate_observed(&short, &mut |v| {
        states.push(*v.state);
        Ok(())
    })
    .unwrap();
    states[BROKEN].q[2] = f64::NAN;
    states
}

fn cycle(scenario: &Scenario) -> ControlCycle {
    let c = Controller::new(&scenario.model, scenario.spec.clone(), &scenario.q0).unwrap();
    ControlCycle::new(c, &CycleSettings::from_scenario(scenario)).unwrap()
}

/// A turn of the hybrid spin 10 µs before the state expected one period
/// after the state of cycle `k`.
fn turn(w: &mut WarmUp, c: &ControlCycle, s: &JointState, k: u64, timing: &mut LatencyHistogram) {
    let expected = (k + 1) * PERIOD;
    w.turn(expected - 10_000, expected, SPIN, (s, c.step_ns()), timing);
}

#[test]
fn the_cache_warm_up_changes_no_command() {
    let scenario = scenario();
    assert!(
        LoopSettings::from_scenario(&scenario).unwrap().warm_up,
        "on by default"
    );
    let states = states(&scenario);
    let (mut warm, mut plain) = (cycle(&scenario), cycle(&scenario));
    let mut warm_up = WarmUp::new(warm.controller(), true);
    let mut timing = LatencyHistogram::new();
    turn(&mut warm_up, &warm, &JointState::zeroed(), 0, &mut timing);
    assert_eq!(warm_up.count(), 0, "nothing to warm on yet");
    for (k, s) in states.iter().enumerate() {
        let k = k as u64;
        let (a, b) = (warm.decide(s, k * PERIOD), plain.decide(s, k * PERIOD));
        assert_eq!(a, b, "state {k}");
        assert_eq!(warm.command().tau(), plain.command().tau(), "state {k}");
        assert_eq!(warm.telemetry().tau(), plain.telemetry().tau(), "state {k}");
        // Warm on the last state (twice: the second turn of a wait does not
        // run it again); not on the NaN state, which the law did not run on.
        // (A warm-up is also skipped when the law's last step took more than
        // a third of the spin, as on a loaded machine.)
        let before = warm_up.count();
        turn(&mut warm_up, &warm, s, k, &mut timing);
        turn(&mut warm_up, &warm, s, k, &mut timing);
        let ran = warm_up.count() - before;
        assert!(ran <= u64::from(k as usize != BROKEN), "state {k}: {ran}");
        warm_up.arrival((k + 1) * PERIOD, SPIN);
    }
    assert!(warm_up.count() > 0, "the warm-up never ran");
    assert_eq!(timing.count(), warm_up.count());
}

#[test]
fn the_cache_warm_up_allocates_nothing() {
    let scenario = scenario();
    let states = states(&scenario);
    let mut c = cycle(&scenario);
    let mut warm_up = WarmUp::new(c.controller(), true);
    let mut timing = LatencyHistogram::new();
    let mut run = |c: &mut ControlCycle, w: &mut WarmUp, k: usize| {
        let s = &states[k % states.len()];
        let k = k as u64;
        w.arrival(k * PERIOD, SPIN);
        c.decide(s, k * PERIOD);
        turn(w, c, s, k, &mut timing);
    };
    let rt = RtSection::enter();
    for k in 0..states.len() {
        run(&mut c, &mut warm_up, k);
    }
    let (before, warmed) = (thread_stats(), warm_up.count());
    for k in states.len()..4 * states.len() {
        run(&mut c, &mut warm_up, k);
    }
    let during = thread_stats().since(before);
    drop(rt);
    // (A warm-up is skipped when the law's last step took more than a third
    // of the spin: on a loaded machine some are.)
    assert!(warm_up.count() > warmed, "the warm-up never ran");
    assert_eq!(during.allocs, 0, "{during:?}");
}
