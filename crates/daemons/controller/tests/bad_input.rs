//! Bad input to the controller loop, through real iceoryx2 services (own
//! namespace and file prefix): every kind of malformed joint state is
//! rejected with the defined safe command (mode SafeHold, τ = g at the last
//! valid configuration, or 0 when the driver adds gravity itself) and
//! counted, the next valid state is answered normally, a stale peer is
//! declared lost no earlier than the timeout, and thousands of random states
//! never make the loop panic or command a non-finite or over-limit torque.

use std::path::PathBuf;
use std::sync::atomic::Ordering;

use hcc_config::Scenario;
use hcc_control::Controller;
use hcc_controller::{ControlLoop, LoopSettings, Outcome, Ports};
use hcc_msgs::ipc::{
    self, CommandSubscriber, MAX_SUBSCRIBER_BUFFER, Services, StatePublisher, TelemetrySubscriber,
};
use hcc_msgs::{
    CommandMode, JointState, MAX_JOINTS, Namespace, STATE_FLAG_DRIVER_GRAVITY_COMPENSATION,
    ServiceNames, TelemetryCounters, TorqueCommand,
};
use hcc_rt::WaitStrategy;
use iceoryx2::prelude::SignalHandlingMode;

fn scenario() -> Scenario {
    let path = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../../config/paper-sim1.toml");
    Scenario::load(&path).unwrap()
}

fn cleanup(prefix: &str) {
    let files = ipc::leftover_files(prefix).unwrap();
    for f in files.iter().filter(|f| f.global_mgmt) {
        std::fs::remove_file(&f.path).unwrap();
    }
    let rest: Vec<_> = files.iter().filter(|f| !f.global_mgmt).collect();
    assert!(rest.is_empty(), "files left behind: {rest:?}");
}

/// A controller loop and an in-test driver on one namespace.
struct Rig {
    cycle: ControlLoop,
    ports: Ports,
    state_pub: StatePublisher,
    commands: CommandSubscriber,
    telemetry: TelemetrySubscriber,
    n: usize,
    q0: Vec<f64>,
    seq: u64,
    // Keep the services and the node alive (dropped last).
    _services: Services,
    _node: ipc::IpcNode,
}

impl Rig {
    fn new(prefix: &str, tag: &str, limits: Option<f64>) -> Rig {
        let scenario = scenario();
        let n = scenario.model.nq();
        let names = ServiceNames::for_namespace(Namespace::unique(tag).unwrap());
        let node = ipc::create_node(tag, SignalHandlingMode::Disabled, Some(prefix)).unwrap();
        let services = Services::open(&node, &names).unwrap();
        let ports = Ports::open(&services).unwrap();
        let controller =
            Controller::new(&scenario.model, scenario.spec.clone(), &scenario.q0).unwrap();
        let mut settings = LoopSettings::from_scenario(&scenario).unwrap();
        settings.wait = WaitStrategy::Event;
        if let Some(l) = limits {
            settings.cycle.torque_limits = vec![l; n];
        }
        Rig {
            cycle: ControlLoop::new(controller, settings).unwrap(),
            state_pub: services.joint_state_publisher().unwrap(),
            commands: services
                .torque_command_subscriber(MAX_SUBSCRIBER_BUFFER)
                .unwrap(),
            telemetry: services
                .telemetry_subscriber(MAX_SUBSCRIBER_BUFFER)
                .unwrap(),
            ports,
            n,
            q0: scenario.q0.iter().copied().collect(),
            seq: 100,
            _services: services,
            _node: node,
        }
    }

    /// A valid state with the next sequence number.
    fn valid(&mut self) -> JointState {
        self.seq += 1;
        let mut s = JointState::zeroed();
        s.set_joints(&self.q0, &vec![0.0; self.n], &vec![0.0; self.n])
            .unwrap();
        s.header.seq = self.seq;
        s.header.stamp_ns = hcc_msgs::monotonic_now_ns();
        s
    }

    /// Sends `s` (any bit pattern) and runs one cycle.
    fn handle(&mut self, s: JointState) -> Outcome {
        self.state_pub.send_copy(s).unwrap();
        self.cycle.run_once(&self.ports)
    }

    fn newest_command(&self) -> Option<TorqueCommand> {
        let mut last = None;
        while let Some(c) = self.commands.receive().unwrap() {
            last = Some(*c);
        }
        last
    }

    fn counters(&self) -> TelemetryCounters {
        self.cycle.cycle().counters().telemetry
    }
}

#[test]
fn every_kind_of_bad_joint_state_gets_the_safe_command_and_is_counted() {
    let prefix = format!("hcctbi{}_", std::process::id());
    {
        let mut rig = Rig::new(&prefix, "bad_input", None);
        let n = rig.n;
        // A valid state first: its g(q) is the safe command's torque.
        let s = rig.valid();
        assert_eq!(rig.handle(s), Outcome::Answered(CommandMode::Normal));
        let c = rig.newest_command().unwrap();
        let gravity: Vec<f64> = rig
            .cycle
            .cycle()
            .controller()
            .output()
            .gravity
            .iter()
            .copied()
            .collect();
        assert!(gravity.iter().any(|g| g.abs() > 1.0));
        assert!(c.tau().iter().all(|t| t.is_finite()));

        type Corrupt = fn(&mut JointState);
        let invalid: Vec<(&str, Corrupt)> = vec![
            ("q NaN", |s| s.q[1] = f64::NAN),
            ("q +Inf", |s| s.q[0] = f64::INFINITY),
            ("qd -Inf", |s| s.qd[3] = f64::NEG_INFINITY),
            ("qd NaN", |s| s.qd[2] = f64::NAN),
            ("tau_measured NaN", |s| s.tau_measured[0] = f64::NAN),
            ("one joint too few", |s| s.header.n_joints -= 1),
            ("one joint too many", |s| s.header.n_joints += 1),
            ("more joints than the capacity", |s| {
                s.header.n_joints = 1000
            }),
            ("zero joints", |s| s.header.n_joints = 0),
            ("schema 4", |s| s.header.schema_version = 4),
            ("schema 2", |s| s.header.schema_version = 2),
            ("schema 0", |s| s.header.schema_version = 0),
            ("unknown status", |s| s.status = 99),
            ("unknown flag", |s| s.flags = 1 << 7),
        ];
        for (what, corrupt) in &invalid {
            let before = rig.counters();
            let mut s = rig.valid();
            corrupt(&mut s);
            assert_eq!(
                rig.handle(s),
                Outcome::Answered(CommandMode::SafeHold),
                "{what}"
            );
            let c = rig.newest_command().unwrap();
            assert_eq!(c.state_seq, s.header.seq, "{what}: the echo");
            assert_eq!(c.mode, CommandMode::SafeHold.code(), "{what}");
            assert_eq!(c.tau(), gravity.as_slice(), "{what}: τ = g(q_v)");
            assert_eq!(
                rig.counters().invalid_states,
                before.invalid_states + 1,
                "{what}"
            );
            // Control resumes with the next valid state.
            let s = rig.valid();
            assert_eq!(
                rig.handle(s),
                Outcome::Answered(CommandMode::Normal),
                "after {what}"
            );
        }

        // The driver adds gravity too (both would): safe command without g.
        let before = rig.counters();
        let mut s = rig.valid();
        s.flags = STATE_FLAG_DRIVER_GRAVITY_COMPENSATION;
        assert_eq!(rig.handle(s), Outcome::Answered(CommandMode::SafeHold));
        let c = rig.newest_command().unwrap();
        assert!(c.tau().iter().all(|&t| t == 0.0), "{:?}", c.tau());
        assert_eq!(c.flags, 0, "the command must not claim to include gravity");
        assert_eq!(rig.counters().invalid_states, before.invalid_states + 1);

        // Sequence: backwards once, an implausible jump, a duplicate.
        let s = rig.valid();
        assert_eq!(rig.handle(s), Outcome::Answered(CommandMode::Normal));
        let last = rig.seq;
        for (what, seq) in [
            ("backwards", last - 10),
            ("jump", last + 1_000_000),
            ("far jump", u64::MAX),
        ] {
            let before = rig.counters();
            let mut s = rig.valid();
            rig.seq -= 1;
            s.header.seq = seq;
            assert_eq!(
                rig.handle(s),
                Outcome::Answered(CommandMode::SafeHold),
                "{what}"
            );
            let c = rig.newest_command().unwrap();
            assert_eq!(c.tau(), gravity.as_slice(), "{what}");
            assert_eq!(
                rig.counters().sequence_errors,
                before.sequence_errors + 1,
                "{what}"
            );
        }
        // The rejected numbers did not move the checker: the stream continues.
        let s = rig.valid();
        assert_eq!(s.header.seq, last + 1);
        assert_eq!(rig.handle(s), Outcome::Answered(CommandMode::Normal));
        let before = rig.counters();
        assert_eq!(
            rig.handle(s),
            Outcome::Duplicate,
            "a duplicate is not answered"
        );
        assert!(rig.newest_command().is_some());
        assert!(rig.newest_command().is_none());
        assert_eq!(rig.counters().sequence_errors, before.sequence_errors + 1);
        // A small gap (the loop missed states) is normal operation: used, counted.
        rig.seq += 5;
        let s = rig.valid();
        assert_eq!(rig.handle(s), Outcome::Answered(CommandMode::Normal));
        assert_eq!(rig.counters().missed_states, before.missed_states + 5);

        // A driver restarted without an outage (counting from 0 again):
        // two states are rejected, the third that follows them is accepted.
        let mut outcomes = Vec::new();
        for k in 0..4 {
            let mut s = rig.valid();
            s.header.seq = k;
            outcomes.push(rig.handle(s));
        }
        rig.seq = 3;
        assert_eq!(
            outcomes,
            [
                Outcome::Answered(CommandMode::SafeHold),
                Outcome::Answered(CommandMode::SafeHold),
                Outcome::Answered(CommandMode::Normal),
                Outcome::Answered(CommandMode::Normal)
            ]
        );

        // Telemetry carries the same counters.
        let mut last_t = None;
        while let Some(t) = rig.telemetry.receive().unwrap() {
            last_t = Some(t.counters);
        }
        assert_eq!(last_t.unwrap(), rig.counters());
        println!("counters after the bad inputs: {:?}", rig.counters());
        let _ = n;
    }
    cleanup(&prefix);
}

#[test]
fn a_silent_driver_is_declared_lost_after_the_timeout_not_before() {
    let prefix = format!("hcctst{}_", std::process::id());
    {
        let mut rig = Rig::new(&prefix, "stale_timing", None);
        let timeout_ns = LoopSettings::from_scenario(&scenario())
            .unwrap()
            .stale_timeout_ns;
        assert_eq!(timeout_ns, 3_000_000, "three periods at 1 kHz");
        let mut waits = Vec::new();
        for _ in 0..10 {
            let s = rig.valid();
            rig.state_pub.send_copy(s).unwrap();
            assert!(matches!(
                rig.cycle.run_once(&rig.ports),
                Outcome::Answered(_)
            ));
            // The timeout counts from the state's arrival (the loop's wake-up),
            // not from the end of its answer: a slow answer (a preempted test
            // thread) leaves less of the timeout to wait.
            let arrived = rig.cycle.status().last_state_ns.load(Ordering::Relaxed);
            assert_eq!(rig.cycle.run_once(&rig.ports), Outcome::Stale);
            let lost = rig.cycle.status().peer_lost_at_ns.load(Ordering::Relaxed);
            waits.push(lost.saturating_sub(arrived) as f64 / 1e6);
        }
        waits.sort_by(f64::total_cmp);
        println!(
            "stale detection after the last state: min {:.3} ms, median {:.3} ms, max {:.3} ms (timeout 3 ms)",
            waits[0], waits[5], waits[9]
        );
        // Measured from the arrival the deadline counts from: never below it.
        assert!(waits[0] >= 3.0, "declared lost early: {waits:?}");
        assert!(waits[9] < 1000.0, "{waits:?}");
        let c = rig.counters();
        assert_eq!(c.peer_lost_events, 10);
        let mut flagged = 0;
        while let Some(t) = rig.telemetry.receive().unwrap() {
            flagged += usize::from(t.peer_lost());
        }
        assert_eq!(
            flagged, 10,
            "one flagged telemetry sample per stale timeout"
        );
    }
    cleanup(&prefix);
}

/// xorshift64*: a deterministic generator, enough for fuzzing.
struct Rng(u64);

impl Rng {
    fn next(&mut self) -> u64 {
        self.0 ^= self.0 >> 12;
        self.0 ^= self.0 << 25;
        self.0 ^= self.0 >> 27;
        self.0.wrapping_mul(0x2545_f491_4f6c_dd1d)
    }
    fn pick<T: Copy>(&mut self, v: &[T]) -> T {
        v[(self.next() % v.len() as u64) as usize]
    }
}

#[test]
fn random_states_never_panic_or_command_a_torque_spike() {
    let prefix = format!("hcctfz{}_", std::process::id());
    const LIMIT: f64 = 150.0;
    {
        let mut rig = Rig::new(&prefix, "fuzz", Some(LIMIT));
        let n = rig.n;
        let mut rng = Rng(0x9e37_79b9_7f4a_7c15);
        let values = [
            f64::NAN,
            f64::INFINITY,
            f64::NEG_INFINITY,
            1e300,
            -1e300,
            f64::MIN_POSITIVE / 2.0,
            -0.0,
            1e3,
            -50.0,
        ];
        let (mut answered, mut duplicates, mut safe, mut handled) = (0u64, 0u64, 0u64, 0u64);
        let mut worst = 0.0f64;
        const CASES: usize = 3000;
        for _ in 0..CASES {
            let mut s = rig.valid();
            for _ in 0..1 + rng.next() % 3 {
                match rng.next() % 10 {
                    0 => s.header.schema_version = rng.pick(&[0, 1, 2, u32::MAX]),
                    1 => s.header.n_joints = rng.pick(&[0, 1, 3, 5, 32, 33, u32::MAX]),
                    2 => s.header.seq = rng.next(),
                    3 => s.header.seq = s.header.seq.saturating_sub(rng.next() % 4),
                    4 => s.status = rng.pick(&[1, 2, 3, 4, u32::MAX]),
                    5 => s.flags = rng.pick(&[1, 2, 1 << 31, u32::MAX]),
                    6 => s.q[(rng.next() % MAX_JOINTS as u64) as usize] = rng.pick(&values),
                    7 => s.qd[(rng.next() % MAX_JOINTS as u64) as usize] = rng.pick(&values),
                    8 => s.tau_measured[(rng.next() % n as u64) as usize] = rng.pick(&values),
                    _ => {
                        // Raw garbage in every joint entry.
                        for k in 0..n {
                            s.q[k] = f64::from_bits(rng.next());
                            s.qd[k] = f64::from_bits(rng.next());
                        }
                    }
                }
            }
            handled += 1;
            match rig.handle(s) {
                Outcome::Answered(mode) => {
                    answered += 1;
                    safe += u64::from(mode == CommandMode::SafeHold);
                    let c = rig.newest_command().expect("an answer is published");
                    assert_eq!(c.state_seq, s.header.seq);
                    assert!(c.validate(n).is_ok(), "the command itself is valid: {c:?}");
                    for t in c.tau() {
                        assert!(
                            t.is_finite() && t.abs() <= LIMIT,
                            "τ = {:?} for {s:?}",
                            c.tau()
                        );
                        worst = worst.max(t.abs());
                    }
                    if s.validate(n).is_err() {
                        assert_eq!(mode, CommandMode::SafeHold, "{s:?}");
                    }
                }
                Outcome::Duplicate => duplicates += 1,
                other => panic!("unexpected outcome {other:?}"),
            }
            // Back to the stream of the in-test driver now and then.
            if rng.next().is_multiple_of(4) {
                let s = rig.valid();
                handled += 1;
                assert!(matches!(rig.handle(s), Outcome::Answered(_)));
                let _ = rig.newest_command();
            }
        }
        let c = rig.counters();
        println!(
            "{CASES} random states: {answered} answered ({safe} SafeHold), {duplicates} duplicates; counters {c:?}; largest |τ| {worst:.1} N·m (limit {LIMIT})"
        );
        assert!(safe > CASES as u64 / 3, "most random states are invalid");
        assert!(c.invalid_states > 0 && c.sequence_errors > 0 && c.saturations > 0);
        assert_eq!(c.cycles, handled, "every state is handled once");
    }
    cleanup(&prefix);
}

/// The wait strategy is the runtime's to check: a name it does not know is
/// refused when the daemon's settings are made, naming the field and its
/// line as the scenario's own errors do.
#[test]
fn an_unknown_wait_strategy_is_refused_with_its_field_and_line() {
    let path = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../../config/panda-wall.toml");
    let text = std::fs::read_to_string(&path).unwrap();
    assert!(text.contains("wait_strategy = \"hybrid\""));
    let line = text
        .lines()
        .position(|l| l.starts_with("wait_strategy"))
        .unwrap()
        + 1;
    let bad = text.replace("wait_strategy = \"hybrid\"", "wait_strategy = \"spin\"");
    let scenario = Scenario::from_toml_str(&bad, &path).unwrap();
    let e = LoopSettings::from_scenario(&scenario).unwrap_err();
    let msg = e.to_string();
    assert!(msg.contains("controller_daemon.wait_strategy"), "{msg}");
    assert!(msg.contains("unknown wait strategy \"spin\""), "{msg}");
    assert!(msg.contains("panda-wall.toml"), "{msg}");
    assert_eq!(e.line(), Some(line), "{msg}");
    // The names the runtime knows, and none given: its default.
    let event = text.replace("wait_strategy = \"hybrid\"", "wait_strategy = \"event\"");
    let s = Scenario::from_toml_str(&event, &path).unwrap();
    assert_eq!(
        LoopSettings::from_scenario(&s).unwrap().wait,
        WaitStrategy::Event
    );
    let none = text.replace("wait_strategy = \"hybrid\"\n", "");
    let s = Scenario::from_toml_str(&none, &path).unwrap();
    assert_eq!(
        LoopSettings::from_scenario(&s).unwrap().wait,
        WaitStrategy::Hybrid
    );
}

#[test]
fn torque_limits_default_to_the_urdf_effort_limits_and_saturation_shows_in_telemetry() {
    let path =
        PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../../config/panda-pose-posture.toml");
    let panda = Scenario::load(&path).unwrap();
    let limits: Vec<f64> = panda
        .controller_daemon
        .torque_limits
        .iter()
        .copied()
        .collect();
    assert_eq!(limits, [87.0, 87.0, 87.0, 87.0, 12.0, 12.0, 12.0]);
    assert_eq!(
        LoopSettings::from_scenario(&panda)
            .unwrap()
            .cycle
            .torque_limits,
        limits
    );

    let prefix = format!("hcctsa{}_", std::process::id());
    {
        let mut rig = Rig::new(&prefix, "saturation", Some(2.0));
        let s = rig.valid();
        assert_eq!(rig.handle(s), Outcome::Answered(CommandMode::Normal));
        let c = rig.newest_command().unwrap();
        assert!(c.tau().iter().all(|t| t.abs() <= 2.0), "{:?}", c.tau());
        let t = rig.telemetry.receive().unwrap().expect("telemetry");
        assert_eq!(t.counters.saturations, 1);
        assert_eq!(t.tau(), c.tau(), "telemetry shows the saturated τ");
        let unsaturated: f64 = t.tau_level(0).iter().fold(0.0, |m, x| m.max(x.abs()));
        assert!(
            unsaturated > 2.0,
            "the level torques show what was asked for"
        );
    }
    cleanup(&prefix);
}
