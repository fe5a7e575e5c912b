//! Behaviour of the controller loop against an in-test driver over real
//! iceoryx2 services (own namespace and file prefix): normal answers echo the
//! state's sequence number, invalid input gets the defined safe command, a
//! silent peer is detected and a restarted one accepted, and a second
//! controller cannot take over the torque channel.

use std::path::PathBuf;

use hcc_config::Scenario;
use hcc_control::Controller;
use hcc_controller::{ControlLoop, LoopSettings, Outcome, Ports};
use hcc_msgs::ipc::{self, CommandSubscriber, Services, StatePublisher};
use hcc_msgs::{COMMAND_FLAG_GRAVITY_INCLUDED, CommandMode, JointState, Namespace, ServiceNames};
use hcc_rt::WaitStrategy;
use iceoryx2::prelude::SignalHandlingMode;

fn scenario() -> Scenario {
    let path = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../../config/paper-sim1.toml");
    Scenario::load(&path).unwrap()
}

fn send(publisher: &StatePublisher, seq: u64, q: &[f64], qd: &[f64]) {
    let mut s = JointState::zeroed();
    s.header.seq = seq;
    s.header.stamp_ns = hcc_msgs::monotonic_now_ns();
    s.set_n_joints(q.len()).unwrap();
    // Raw writes, so that tests can send NaN.
    s.q[..q.len()].copy_from_slice(q);
    s.qd[..qd.len()].copy_from_slice(qd);
    publisher.send_copy(s).unwrap();
}

fn newest(sub: &CommandSubscriber) -> hcc_msgs::TorqueCommand {
    let mut last = None;
    while let Some(c) = sub.receive().unwrap() {
        last = Some(*c);
    }
    last.expect("a command was published")
}

fn cleanup(prefix: &str) {
    let files = ipc::leftover_files(prefix).unwrap();
    for f in files.iter().filter(|f| f.global_mgmt) {
        std::fs::remove_file(&f.path).unwrap();
    }
    let rest: Vec<_> = files.iter().filter(|f| !f.global_mgmt).collect();
    assert!(rest.is_empty(), "files left behind: {rest:?}");
}

#[test]
fn answers_safe_holds_detects_stale_peers_and_guards_the_torque_channel() {
    let prefix = format!("hcctb{}_", std::process::id());
    {
        let scenario = scenario();
        let n = scenario.model.nq();
        let names = ServiceNames::for_namespace(Namespace::unique("ctl_behaviour").unwrap());
        let node = ipc::create_node(
            "behaviour-test",
            SignalHandlingMode::Disabled,
            Some(&prefix),
        )
        .unwrap();
        let services = Services::open(&node, &names).unwrap();
        let ports = Ports::open(&services).unwrap();
        let state_pub = services.joint_state_publisher().unwrap();
        let commands = services.torque_command_subscriber(8).unwrap();

        let controller =
            Controller::new(&scenario.model, scenario.spec.clone(), &scenario.q0).unwrap();
        let mut settings = LoopSettings::from_scenario(&scenario).unwrap();
        settings.wait = WaitStrategy::Event;
        settings.stale_timeout_ns = 20_000_000;
        let mut cycle = ControlLoop::new(controller, settings).unwrap();

        // A second controller in the same namespace is refused.
        let second = Ports::open(&services)
            .err()
            .expect("second controller refused");
        assert!(
            second
                .to_string()
                .contains("torque_command already has a publisher"),
            "{second}"
        );

        let q0: Vec<f64> = scenario.q0.iter().copied().collect();
        let zero = vec![0.0; n];

        // Normal cycle: answers the state, gravity included (paper-sim1 compensates gravity).
        send(&state_pub, 10, &q0, &zero);
        assert_eq!(
            cycle.run_once(&ports),
            Outcome::Answered(CommandMode::Normal)
        );
        let c = newest(&commands);
        assert_eq!(c.state_seq, 10);
        assert_eq!(c.mode, CommandMode::Normal.code());
        assert_eq!(c.flags, COMMAND_FLAG_GRAVITY_INCLUDED);
        let gravity: Vec<f64> = cycle
            .cycle()
            .controller()
            .output()
            .gravity
            .iter()
            .copied()
            .collect();
        assert!(gravity.iter().any(|g| g.abs() > 1.0), "{gravity:?}");

        // NaN: SafeHold with τ = g(q) of the last valid state.
        let mut bad = q0.clone();
        bad[2] = f64::NAN;
        send(&state_pub, 11, &bad, &zero);
        assert_eq!(
            cycle.run_once(&ports),
            Outcome::Answered(CommandMode::SafeHold)
        );
        let c = newest(&commands);
        assert_eq!(c.state_seq, 11);
        assert_eq!(c.tau(), gravity.as_slice());

        // Wrong joint count: SafeHold as well.
        send(&state_pub, 12, &q0[..n - 1], &zero[..n - 1]);
        assert_eq!(
            cycle.run_once(&ports),
            Outcome::Answered(CommandMode::SafeHold)
        );
        assert_eq!(newest(&commands).tau(), gravity.as_slice());
        assert_eq!(cycle.cycle().counters().telemetry.invalid_states, 2);

        // Valid again; a duplicate is not answered; a backwards step is a SafeHold.
        send(&state_pub, 13, &q0, &zero);
        assert_eq!(
            cycle.run_once(&ports),
            Outcome::Answered(CommandMode::Normal)
        );
        send(&state_pub, 13, &q0, &zero);
        assert_eq!(cycle.run_once(&ports), Outcome::Duplicate);
        send(&state_pub, 5, &q0, &zero);
        assert_eq!(
            cycle.run_once(&ports),
            Outcome::Answered(CommandMode::SafeHold)
        );
        assert_eq!(cycle.cycle().counters().telemetry.sequence_errors, 2);
        let _ = newest(&commands);

        // Silence: stale, peer lost, still waiting.
        assert_eq!(cycle.run_once(&ports), Outcome::Stale);
        assert_eq!(cycle.run_once(&ports), Outcome::Stale);
        let counters = cycle.cycle().counters().telemetry;
        assert_eq!(counters.stale_events, 2);
        assert_eq!(counters.peer_lost_events, 1);
        assert!(
            cycle
                .status()
                .peer_lost
                .load(std::sync::atomic::Ordering::Relaxed)
        );

        // A restarted driver counts from 0 again: accepted, control resumes.
        for k in 0..3 {
            send(&state_pub, k, &q0, &zero);
            assert_eq!(
                cycle.run_once(&ports),
                Outcome::Answered(CommandMode::Normal),
                "state {k} of the new peer"
            );
            assert_eq!(newest(&commands).state_seq, k);
        }
        assert!(
            !cycle
                .status()
                .peer_lost
                .load(std::sync::atomic::Ordering::Relaxed)
        );
        assert_eq!(cycle.cycle().counters().telemetry.peer_lost_events, 1);
    }
    cleanup(&prefix);
}

#[test]
fn torque_limits_saturate_and_are_counted() {
    let prefix = format!("hcctl{}_", std::process::id());
    {
        let scenario = scenario();
        let n = scenario.model.nq();
        let names = ServiceNames::for_namespace(Namespace::unique("ctl_limits").unwrap());
        let node =
            ipc::create_node("limits-test", SignalHandlingMode::Disabled, Some(&prefix)).unwrap();
        let services = Services::open(&node, &names).unwrap();
        let ports = Ports::open(&services).unwrap();
        let state_pub = services.joint_state_publisher().unwrap();
        let commands = services.torque_command_subscriber(2).unwrap();
        let controller =
            Controller::new(&scenario.model, scenario.spec.clone(), &scenario.q0).unwrap();
        let mut settings = LoopSettings::from_scenario(&scenario).unwrap();
        settings.wait = WaitStrategy::Event;
        settings.cycle.torque_limits = vec![1.0; n];
        let mut cycle = ControlLoop::new(controller, settings).unwrap();
        let q0: Vec<f64> = scenario.q0.iter().copied().collect();
        send(&state_pub, 0, &q0, &vec![0.0; n]);
        assert_eq!(
            cycle.run_once(&ports),
            Outcome::Answered(CommandMode::Normal)
        );
        let c = newest(&commands);
        assert!(c.tau().iter().all(|t| t.abs() <= 1.0), "{:?}", c.tau());
        assert!(c.tau().iter().any(|t| t.abs() == 1.0));
        assert_eq!(cycle.cycle().counters().telemetry.saturations, 1);
    }
    cleanup(&prefix);
}
