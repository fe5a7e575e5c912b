//! Helpers the cycle's integration tests share (each test file uses some).
#![allow(dead_code)]

use hcc_config::Scenario;
use hcc_msgs::JointState;

/// The joint state number `seq` at `q`, `qd` (no measured torque).
pub fn state_of(q: &[f64], qd: &[f64], seq: u64) -> JointState {
    let mut s = JointState::zeroed();
    s.set_joints(q, qd, &vec![0.0; q.len()]).unwrap();
    s.header.seq = seq;
    s
}

/// The arm held at `scenario`'s start: its joint state number `seq`, at rest.
pub fn state_at_start(scenario: &Scenario, seq: u64) -> JointState {
    let n = scenario.model.nq();
    let q: Vec<f64> = scenario.q0.iter().copied().collect();
    let mut s = JointState::zeroed();
    s.set_joints(&q, &vec![0.0; n], &vec![0.0; n]).unwrap();
    s.header.seq = seq;
    s
}

/// The shipped Panda scenario (`config/panda-pose-posture.toml`) and its
/// control cycle after one state at the start (number 1, at rest).
pub fn panda_cycle() -> (Scenario, hcc_cycle::ControlCycle) {
    let path = std::path::PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("../../config/panda-pose-posture.toml");
    let sc = Scenario::load(&path).unwrap();
    let settings = hcc_cycle::CycleSettings::from_scenario(&sc);
    let c = hcc_control::Controller::new(&sc.model, sc.spec.clone(), &sc.q0).unwrap();
    let mut d = hcc_cycle::ControlCycle::new(c, &settings).unwrap();
    d.decide(&state_at_start(&sc, 1), 1_000_000);
    (sc, d)
}

/// The largest change of a joint torque from one cycle to the next in
/// `tau` (one command per cycle), N·m.
pub fn largest_torque_step(tau: &[Vec<f64>]) -> f64 {
    tau.windows(2)
        .map(|w| {
            w[0].iter()
                .zip(&w[1])
                .map(|(a, b)| (a - b).abs())
                .fold(0.0, f64::max)
        })
        .fold(0.0_f64, f64::max)
}
