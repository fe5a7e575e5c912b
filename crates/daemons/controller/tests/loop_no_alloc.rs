//! The acceptance check of the torque loop: 10 000 cycles of receive →
//! compute → publish command → publish telemetry against an in-test driver,
//! through real iceoryx2 shared memory (own namespace and file prefix), with
//! `RtAllocator` installed as this test binary's global allocator.
//!
//! After warm-up the real-time thread makes no call into the system
//! allocator, the pool occupancy is bounded and constant from cycle to cycle,
//! and the thread takes no page fault (`hcc_rtalloc::LoopAudit`). The cache
//! warm-up's test is `warm_up.rs`, the control cycle's own is in `hcc-cycle`.

use std::path::PathBuf;

use hcc_config::Scenario;
use hcc_control::Controller;
use hcc_controller::{ControlLoop, LoopSettings, Outcome, Ports};
use hcc_msgs::ipc::{self, MAX_SUBSCRIBER_BUFFER, Services};
use hcc_msgs::{
    CommandMode, JointState, MAX_JOINTS, MAX_KNOTS_PER_MESSAGE, Namespace, PATH_EXTEND, PATH_NEW,
    PathKnots, ServiceNames, Setpoint,
};
use hcc_rt::WaitStrategy;
use hcc_rtalloc::{LoopAudit, RtAllocator, RtSection, thread_stats};
use iceoryx2::prelude::SignalHandlingMode;

#[global_allocator]
static ALLOCATOR: RtAllocator = RtAllocator::new();

const WARM_UP: u64 = 3_000;
const CYCLES: u64 = 10_000;

/// The allocator's counters are process-wide: the loops through iceoryx2 run
/// one at a time.
static SERIAL: std::sync::Mutex<()> = std::sync::Mutex::new(());

fn scenario() -> Scenario {
    let path = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../../config/paper-sim1.toml");
    Scenario::load(&path).unwrap()
}

#[test]
fn ten_thousand_cycles_without_system_allocation_or_page_fault() {
    let _serial = SERIAL.lock().unwrap_or_else(|e| e.into_inner());
    assert!(hcc_rtalloc::pool_active());
    let prefix = format!("hcctc{}_", std::process::id());
    {
        let scenario = scenario();
        let n = scenario.model.nq();
        let names = ServiceNames::for_namespace(Namespace::unique("ctl_noalloc").unwrap());
        let node =
            ipc::create_node("loop-test", SignalHandlingMode::Disabled, Some(&prefix)).unwrap();
        let services = Services::open(&node, &names).unwrap();
        let ports = Ports::open(&services).unwrap();
        // The in-test driver and a recorder.
        let state_pub = services.joint_state_publisher().unwrap();
        let state_ready = services.state_ready_notifier().unwrap();
        let command_sub = services.torque_command_subscriber(2).unwrap();
        let command_ready = services.command_ready_listener().unwrap();
        let telemetry_sub = services
            .telemetry_subscriber(MAX_SUBSCRIBER_BUFFER)
            .unwrap();
        // A client streaming a setpoint every cycle (a small circle of goals,
        // stiffness changes; every third one due three states later, so the
        // queue of waiting setpoints fills and drains), prepared beforehand.
        let setpoint_pub = services.setpoint_publisher().unwrap();
        let setpoints: Vec<Setpoint> = (0..2 * WARM_UP)
            .map(|k| {
                let phase = k as f64 * 1e-3;
                let goal = [0.90 + 0.01 * phase.sin(), 0.80 + 0.01 * phase.cos()];
                let at = if k.is_multiple_of(3) { k + 3 } else { 0 };
                let sp = Setpoint::for_level(9, k, 0, 2)
                    .with_goal(&goal)
                    .unwrap()
                    .with_duration(0.005)
                    .with_apply_at(at);
                if k.is_multiple_of(2) {
                    sp.with_stiffness(&[1000.0 + (k % 100) as f64; 2]).unwrap()
                } else {
                    sp
                }
            })
            .collect();

        // A second client streams samples to level 2 (joint 1) through the
        // feasibility check, LEAD samples ahead of the path: its messages
        // wait in the gate while the worker, on a thread of its own, checks
        // them.
        let path_pub = services.path_publisher().unwrap();
        const LEAD: u64 = 200;
        let joint = |j: u64| {
            let t = j as f64 * 1e-3;
            let w = 2.0 * std::f64::consts::PI * 0.5;
            let x = 0.35 + 0.02 * (1.0 - (w * t).cos());
            (t, x, 0.02 * w * (w * t).sin(), 0.02 * w * w * (w * t).cos())
        };
        let mut next_sample = 0u64;
        let mut path_sent = 0u64;

        let controller =
            Controller::new(&scenario.model, scenario.spec.clone(), &scenario.q0).unwrap();
        let mut settings = LoopSettings::from_scenario(&scenario).unwrap();
        settings.wait = WaitStrategy::Event;
        let mut cycle = ControlLoop::new(controller, settings).unwrap();
        let done = std::sync::Arc::new(std::sync::atomic::AtomicBool::new(false));
        let checker = {
            let worker = cycle.check_paths_at_run_time();
            let done = done.clone();
            std::thread::spawn(move || worker.run(&done))
        };

        let q0: Vec<f64> = scenario.q0.iter().copied().collect();
        let mut q = [0.0; MAX_JOINTS];
        let mut qd = [0.0; MAX_JOINTS];
        let zero = [0.0; MAX_JOINTS];

        // One driver period + one controller cycle; returns (ok, occupancy).
        let mut one = |k: u64| -> bool {
            let s = (k as f64 * 1e-3).sin();
            for j in 0..n {
                q[j] = q0[j] + 0.05 * s;
                qd[j] = 0.05 * (k as f64 * 1e-3).cos();
            }
            let mut ok = setpoint_pub
                .send_copy(setpoints[k as usize % setpoints.len()])
                .is_ok();
            if next_sample <= k + LEAD {
                let mut msg = PathKnots::zeroed();
                (msg.client_id, msg.level) = (11, 2);
                msg.flags = if next_sample == 0 {
                    PATH_NEW
                } else {
                    PATH_EXTEND
                };
                while next_sample <= k + LEAD && msg.count() < MAX_KNOTS_PER_MESSAGE {
                    let (t, x, v, a) = joint(next_sample);
                    ok &= msg.push_sample(t, &[x], &[v], &[a]).is_ok();
                    next_sample += 1;
                }
                path_sent += 1;
                msg.header.seq = path_sent;
                ok &= path_pub.send_copy(msg).is_ok();
            }
            // Every other cycle as after a wait (the command's sample loaned
            // before the state comes), else as a state already waiting.
            if k.is_multiple_of(2) {
                cycle.prepare_send(&ports);
            }
            let Ok(sample) = state_pub.loan_uninit() else {
                return false;
            };
            let mut sample = sample.write_payload(JointState::zeroed());
            let st = sample.payload_mut();
            st.header.seq = k;
            st.header.stamp_ns = hcc_msgs::monotonic_now_ns();
            ok &= st.set_joints(&q[..n], &qd[..n], &zero[..n]).is_ok();
            ok &= sample.send().is_ok();
            ok &= state_ready.notify().is_ok();
            ok &= cycle.run_once(&ports) == Outcome::Answered(CommandMode::Normal);
            let _ = command_ready.try_wait(|_| {});
            match command_sub.receive() {
                Ok(Some(c)) => ok &= c.state_seq == k && c.tau().iter().all(|t| t.is_finite()),
                _ => ok = false,
            }
            // The last answer: this cycle's setpoint, or — when it waits for
            // a later state — the one that waited for this state (after the
            // first pass the indices run behind the states: applied at once).
            let expected = if k < 2 * WARM_UP && k.is_multiple_of(3) {
                k.checked_sub(3)
            } else {
                Some(k % (2 * WARM_UP))
            };
            while let Ok(Some(t)) = telemetry_sub.receive() {
                ok &= t.state_seq == k;
                let answer = t.answer_for(9);
                ok &= match expected {
                    Some(seq) => answer.is_some_and(|a| a.seq == seq && a.code == 0),
                    None => answer.is_none(),
                };
            }
            ok
        };

        // As the daemon does at start-up: memory locked when permitted, pool
        // and stack pre-faulted, the real-time section entered.
        let mut audit = LoopAudit::prepare(512 * 1024);
        let mut failures = 0u64;
        for k in 0..WARM_UP {
            failures += u64::from(!one(k));
        }
        audit.start();
        for k in WARM_UP..WARM_UP + CYCLES {
            failures += u64::from(!one(k));
            audit.note();
        }
        let report = audit.finish();
        done.store(true, std::sync::atomic::Ordering::Relaxed);
        checker.join().unwrap();
        let counters = cycle.cycle().counters().telemetry;
        let core = cycle.cycle().counters().core;
        let path_answers = *cycle.cycle().telemetry().answer_for(11).unwrap();
        println!(
            "path messages: {path_sent} sent, {} answered (last: seq {}, code {}), {} still in \
             the check; {} infeasible, {} unchecked",
            path_answers.answered,
            path_answers.seq,
            path_answers.code,
            cycle.cycle().paths_in_check(),
            core.paths_infeasible,
            core.paths_unchecked
        );

        println!(
            "{}; counters {counters:?}",
            report.line("controller loop", CYCLES)
        );
        assert_eq!(failures, 0, "cycles that did not round-trip correctly");
        // Both ways of sending ran: in a sample loaned while waiting, and
        // loaned on the spot.
        let (preloaned, loan_failures) = cycle.preloaned_sends();
        assert_eq!(loan_failures, 0);
        let total = WARM_UP + CYCLES;
        assert!(
            preloaned >= total / 2 && preloaned < total,
            "{preloaned} of {total}"
        );
        assert_eq!(counters.invalid_states, 0);
        assert_eq!(counters.missed_states, 0);
        assert_eq!(counters.send_failures, 0);
        // The messages went through the gate: answered in order as their
        // verdicts came (a busy machine may leave some unchecked; nothing is
        // infeasible on this path).
        assert_eq!(core.paths_infeasible, 0);
        assert!(
            path_answers.answered + cycle.cycle().paths_in_check() as u64 >= path_sent - 1,
            "{path_answers:?} of {path_sent}"
        );
        assert!(path_answers.answered > path_sent / 2, "{path_answers:?}");
        report.check().unwrap();
        assert!(
            report.during.pool_allocs > 0,
            "iceoryx2 loans are served by the pool"
        );
    }
    // Everything dropped: only the per-prefix global management segment remains.
    let files = ipc::leftover_files(&prefix).unwrap();
    for f in files.iter().filter(|f| f.global_mgmt) {
        std::fs::remove_file(&f.path).unwrap();
    }
    let rest: Vec<_> = files.iter().filter(|f| !f.global_mgmt).collect();
    assert!(rest.is_empty(), "shared-memory files left behind: {rest:?}");
}

/// The driver side of the in-test loop: publishes state `k`, runs one cycle
/// and takes its command; whether the answer came.
struct TestDriver {
    state_pub: ipc::StatePublisher,
    state_ready: ipc::EventNotifier,
    command_sub: ipc::CommandSubscriber,
    command_ready: ipc::EventListener,
    q: Vec<f64>,
}

impl TestDriver {
    fn round_trip(&self, cycle: &mut ControlLoop, ports: &Ports, k: u64) -> bool {
        let n = self.q.len();
        let q: Vec<f64> = self
            .q
            .iter()
            .map(|q| q + 0.05 * (k as f64 * 1e-3).sin())
            .collect();
        let zero = [0.0; MAX_JOINTS];
        let mut s = JointState::zeroed();
        s.header.seq = k;
        s.header.stamp_ns = hcc_msgs::monotonic_now_ns();
        let mut ok = s.set_joints(&q, &zero[..n], &zero[..n]).is_ok();
        ok &= self.state_pub.send_copy(s).is_ok();
        ok &= self.state_ready.notify().is_ok();
        ok &= cycle.run_once(ports) == Outcome::Answered(CommandMode::Normal);
        let _ = self.command_ready.try_wait(|_| {});
        ok & matches!(self.command_sub.receive(), Ok(Some(c)) if c.state_seq == k)
    }
}

/// A loop against the in-test driver on its own services (namespace `tag`,
/// the caller's file prefix), with the event wait.
struct Rig {
    services: Services,
    ports: Ports,
    driver: TestDriver,
    cycle: ControlLoop,
    k: u64,
    failures: u64,
    _node: ipc::IpcNode,
}

impl Rig {
    fn new(tag: &str, prefix: &str) -> Rig {
        let scenario = scenario();
        let names = ServiceNames::for_namespace(Namespace::unique(tag).unwrap());
        let node = ipc::create_node(tag, SignalHandlingMode::Disabled, Some(prefix)).unwrap();
        let services = Services::open(&node, &names).unwrap();
        let ports = Ports::open(&services).unwrap();
        let driver = TestDriver {
            state_pub: services.joint_state_publisher().unwrap(),
            state_ready: services.state_ready_notifier().unwrap(),
            command_sub: services.torque_command_subscriber(2).unwrap(),
            command_ready: services.command_ready_listener().unwrap(),
            q: scenario.q0.iter().copied().collect(),
        };
        let controller =
            Controller::new(&scenario.model, scenario.spec.clone(), &scenario.q0).unwrap();
        let mut settings = LoopSettings::from_scenario(&scenario).unwrap();
        settings.wait = WaitStrategy::Event;
        let cycle = ControlLoop::new(controller, settings).unwrap();
        Rig {
            services,
            ports,
            driver,
            cycle,
            k: 0,
            failures: 0,
            _node: node,
        }
    }

    /// `count` round trips (each state already there: no wait, no upkeep);
    /// what the calling thread allocated meanwhile.
    fn cycles(&mut self, count: u64) -> hcc_rtalloc::ThreadStats {
        let before = thread_stats();
        for _ in 0..count {
            let ok = self.driver.round_trip(&mut self.cycle, &self.ports, self.k);
            self.failures += u64::from(!ok);
            self.k += 1;
        }
        thread_stats().since(before)
    }

    /// The loop's connection upkeep, as a wait runs it.
    fn upkeep(&mut self) {
        self.cycle.upkeep_connections(&self.ports);
    }
}

/// Removes what the test's node left under `prefix` (the global management
/// files only: anything else is a leak).
fn clean_up(prefix: &str) {
    let files = ipc::leftover_files(prefix).unwrap();
    for f in files.iter().filter(|f| f.global_mgmt) {
        std::fs::remove_file(&f.path).unwrap();
    }
    assert!(files.iter().all(|f| f.global_mgmt), "{files:?}");
}

/// A recorder (or monitor, or client) that subscribes while the loop runs:
/// left to iceoryx2, the next command's send connects it — allocations and
/// the mapping of its queue on the real-time thread between a state and its
/// answer. The loop's connection
/// upkeep, which runs while the loop waits, connects it instead (and
/// disconnects it when it leaves): the cycles after it allocate nothing from
/// the system, and the recorder receives every command.
#[test]
fn a_subscriber_attached_mid_run_is_connected_while_the_loop_waits() {
    let _serial = SERIAL.lock().unwrap_or_else(|e| e.into_inner());
    assert!(hcc_rtalloc::pool_active());
    let prefix = format!("hcctu{}_", std::process::id());
    {
        let mut rig = Rig::new("ctl_upkeep", &prefix);
        let rt = RtSection::enter();
        rig.cycles(500);
        // What the upkeep costs a spin pass when nothing changed (printed:
        // the machine is shared; the loop's stage figures are `hcc jitter`'s).
        let t0 = std::time::Instant::now();
        for _ in 0..10_000 {
            rig.upkeep();
        }
        println!(
            "upkeep without a change: {:.0} ns per call",
            t0.elapsed().as_nanos() as f64 / 10_000.0
        );
        assert_eq!(rig.cycle.upkeep().updates, 0);

        // Without upkeep (the state is already there: no wait), the send of
        // the next command makes the new connections.
        let recorder = rig
            .services
            .torque_command_subscriber(MAX_SUBSCRIBER_BUFFER)
            .unwrap();
        let during = rig.cycles(1);
        println!("the cycle whose send connected a recorder: {during:?}");
        // (The real-time pool's 512-byte blocks serve these allocations; with
        // 128-byte blocks some went to the system allocator. The segment's
        // mapping is done on the torque path all the same.)
        assert!(
            during.allocs > 0,
            "connecting inside the send allocates on the torque path: {during:?}"
        );
        assert!(matches!(recorder.receive(), Ok(Some(_))));
        drop(recorder);
        rig.cycles(10);

        // With the upkeep of a wait between the attach and the next state.
        let updates_before = rig.cycle.upkeep().updates;
        let recorder = rig
            .services
            .torque_command_subscriber(MAX_SUBSCRIBER_BUFFER)
            .unwrap();
        let monitor = rig
            .services
            .telemetry_subscriber(MAX_SUBSCRIBER_BUFFER)
            .unwrap();
        let upkeep_stats = thread_stats();
        rig.upkeep();
        let upkeep_stats = thread_stats().since(upkeep_stats);
        let u = rig.cycle.upkeep();
        println!("upkeep: {u:?}, allocator {upkeep_stats:?}");
        assert_eq!(u.updates, updates_before + 1, "{u:?}");
        assert!(u.allocs > 0 && u.failures == 0, "{u:?}");
        // (Fewer cycles than the recorder's queue holds: it reads them after.)
        let during = rig.cycles(100);
        println!("100 cycles after the upkeep connected a recorder: {during:?}");
        assert_eq!(during.system_allocs, 0, "{during:?}");
        assert_eq!(during.fallbacks, 0, "{during:?}");
        let mut received = 0;
        while let Ok(Some(_)) = recorder.receive() {
            received += 1;
        }
        let mut telemetry = 0;
        while let Ok(Some(_)) = monitor.receive() {
            telemetry += 1;
        }
        assert_eq!((received, telemetry), (100, 100));

        // Leaving: the cycles stay clean.
        drop(recorder);
        drop(monitor);
        rig.upkeep();
        let during = rig.cycles(200);
        println!(
            "after the recorder left: upkeep {:?}, cycles {during:?}",
            rig.cycle.upkeep()
        );
        assert_eq!(during.system_allocs, 0, "{during:?}");
        assert_eq!(during.system_frees, 0, "{during:?}");
        assert_eq!(rig.failures, 0, "cycles that did not round-trip");
        drop(rt);
    }
    clean_up(&prefix);
}

/// A driver that stops leaves between its last state and the command that
/// answers it (its `command_ready` listener dropped before the notification):
/// the notification finds the listener set changed and rebuilds its list of
/// listeners (iceoryx2 collects them in a vector of 4 × 120 bytes) on the
/// real-time thread, between the state and its answer — no wait in between
/// for the upkeep to do it. The real-time pool's blocks hold that vector:
/// no system allocation, the cycle answers, and the next cycles are clean.
#[test]
fn a_listener_that_leaves_before_the_answer_costs_no_system_allocation() {
    let _serial = SERIAL.lock().unwrap_or_else(|e| e.into_inner());
    assert!(hcc_rtalloc::pool_active());
    let prefix = format!("hcctl{}_", std::process::id());
    {
        let mut rig = Rig::new("ctl_leave", &prefix);
        let rt = RtSection::enter();
        rig.cycles(500);
        // A second listener (a driver's, about to stop), connected by the
        // upkeep of a wait; then it leaves, and the next state is already there.
        let leaving = rig.services.command_ready_listener().unwrap();
        rig.upkeep();
        rig.cycles(10);
        let updates_before = rig.cycle.upkeep().updates;
        drop(leaving);
        let during = rig.cycles(1);
        println!("the cycle whose notification found a listener gone: {during:?}");
        assert_eq!(
            rig.cycle.upkeep().updates,
            updates_before,
            "no upkeep ran in between"
        );
        assert!(
            during.allocs > 0,
            "the notification rebuilt its listener list: {during:?}"
        );
        assert_eq!(during.system_allocs, 0, "{during:?}");
        assert_eq!(during.fallbacks, 0, "{during:?}");
        let during = rig.cycles(100);
        assert_eq!(during.allocs, during.frees, "{during:?}");
        assert_eq!(during.system_allocs, 0, "{during:?}");
        assert_eq!(rig.failures, 0, "cycles that did not round-trip");
        drop(rt);
    }
    clean_up(&prefix);
}
