//! The driver's FCI cycle against a fake torque motion (the robot's states
//! made here, the written torques recorded) and an in-test controller,
//! through real iceoryx2 shared memory (own namespace and file prefix per
//! test), with hcc-rtalloc's allocator installed.
//!
//! Covered: the state published per FCI state (seq = message_id, the gravity
//! flag), commands applied in the same cycle, the guard (rate, limits), hold
//! → fallback → ramp → `motion_finished`, a Stop command, a refused
//! gravity-including command, a robot error ending the cycle, and no system
//! allocation in the cycle body after warm-up. Not covered here: franka-rs's
//! own socket I/O (the fake replaces it); the driver counts the allocations
//! of its real loop too (`loop_system_allocs` in `--stats`), which the
//! franka-sim tests (python/tests/test_franka.py) check against the simulated robot.

use franka::{ControlException, Errors, FrankaError, FrankaResult, MoveStatus, RobotState};
use hcc_franka::cycle::{FrankaCycle, FrankaSettings, Step};
use hcc_franka::guard::JOINTS;
use hcc_franka::motion::TorqueMotion;
use hcc_msgs::driver::StopReason;
use hcc_msgs::ipc::{self, CommandPublisher, DriverPorts, Services, StateSubscriber};
use hcc_msgs::{
    COMMAND_FLAG_GRAVITY_INCLUDED, CommandMode, DriverStatus, JointState, Namespace, ServiceNames,
    TorqueCommand,
};
use hcc_rtalloc::RtAllocator;
use iceoryx2::prelude::SignalHandlingMode;

#[global_allocator]
static ALLOCATOR: RtAllocator = RtAllocator::new();

/// The robot's side: states numbered from `next_id`, the torques written.
struct FakeMotion {
    next_id: u64,
    q: [f64; JOINTS],
    dq: [f64; JOINTS],
    written: Vec<[f64; JOINTS]>,
    finished: Option<[f64; JOINTS]>,
    /// Return this error at the next read.
    fail: Option<FrankaError>,
}

impl FakeMotion {
    fn new(capacity: usize) -> FakeMotion {
        FakeMotion {
            next_id: 1000,
            q: [0.0, 0.0, 0.0, -1.57, 0.0, 1.57, 0.785],
            dq: [0.1, -0.2, 0.0, 0.0, 0.0, 0.3, 1.0],
            written: Vec::with_capacity(capacity),
            finished: None,
            fail: None,
        }
    }
}

impl TorqueMotion for FakeMotion {
    fn read_once(&mut self) -> FrankaResult<RobotState> {
        if let Some(e) = self.fail.take() {
            return Err(e);
        }
        let s = RobotState {
            time: franka::Duration::from_millis(self.next_id),
            q: self.q,
            dq: self.dq,
            tau_J: [0.5; JOINTS],
            control_command_success_rate: 1.0,
            ..RobotState::default()
        };
        self.next_id += 1;
        Ok(s)
    }

    fn write_once(&mut self, tau: &[f64; JOINTS]) -> FrankaResult<()> {
        self.written.push(*tau);
        Ok(())
    }

    fn finish(&mut self, tau: &[f64; JOINTS]) -> FrankaResult<()> {
        self.finished = Some(*tau);
        Ok(())
    }
}

/// The driver's ports, the in-test controller's ports, and the prefix.
struct Rig {
    ports: DriverPorts,
    commands: CommandPublisher,
    states: StateSubscriber,
    prefix: String,
    seq: std::cell::Cell<u64>,
    _services: Services,
    _node: ipc::IpcNode,
}

impl Rig {
    fn new(tag: &str) -> Rig {
        let prefix = format!("hccfr{}{}_", tag, std::process::id());
        let names = ServiceNames::for_namespace(Namespace::unique(tag).unwrap());
        let node = ipc::create_node(tag, SignalHandlingMode::Disabled, Some(&prefix)).unwrap();
        let services = Services::open(&node, &names).unwrap();
        Rig {
            ports: DriverPorts::open(&services).unwrap(),
            commands: services.torque_command_publisher().unwrap(),
            states: services.joint_state_subscriber(4).unwrap(),
            prefix,
            seq: std::cell::Cell::new(0),
            _services: services,
            _node: node,
        }
    }

    /// The controller answers the state with `message_id` (sent ahead: the
    /// fake robot's ids are known).
    fn answer(&self, message_id: u64, tau: [f64; JOINTS], mode: CommandMode, flags: u32) {
        let mut c = TorqueCommand::zeroed();
        c.set_n_joints(JOINTS).unwrap();
        c.header.seq = self.seq.get();
        self.seq.set(self.seq.get() + 1);
        c.state_seq = message_id;
        c.state_stamp_ns = 1;
        c.mode = mode.code();
        c.flags = flags;
        c.set_tau(&tau).unwrap();
        self.commands.send_copy(c).unwrap();
    }

    /// The newest state published.
    fn latest_state(&self) -> Option<JointState> {
        let mut newest = None;
        while let Ok(Some(s)) = self.states.receive() {
            newest = Some(*s);
        }
        newest
    }
}

fn settings() -> FrankaSettings {
    let mut s = FrankaSettings::from_config(&hcc_config::franka::Franka::default());
    s.window_ns = 300_000;
    s
}

/// Drops the ports and removes the test's shared-memory files.
fn clean_up(rig: Rig) {
    let prefix = rig.prefix.clone();
    drop(rig);
    let files = ipc::leftover_files(&prefix).unwrap();
    for f in files.iter().filter(|f| f.global_mgmt) {
        std::fs::remove_file(&f.path).unwrap();
    }
    assert!(files.iter().all(|f| f.global_mgmt), "{files:?}");
}

#[test]
fn commands_are_applied_in_the_cycle_without_system_allocation() {
    let rig = Rig::new("frapply");
    let cycles = 3_000;
    let mut motion = FakeMotion::new(cycles + 10);
    {
        let mut cycle = FrankaCycle::new(settings(), &rig.ports);
        cycle.begin_motion();
        let _rt = hcc_rtalloc::RtSection::enter();
        let mut measured = 0;
        for k in 0..cycles {
            // A smooth torque: steps of 0.3 N·m at most.
            let t = (k as f64 * 0.01).sin() * 30.0;
            let tau = [t, -t, 0.1, 0.0, 0.0, 0.0, t / 10.0];
            rig.answer(motion.next_id, tau, CommandMode::Normal, 0);
            let before = hcc_rtalloc::thread_stats();
            assert!(matches!(cycle.step(&mut motion, false), Ok(Step::Running)));
            if k >= 200 {
                measured += hcc_rtalloc::thread_stats().since(before).system_allocs;
            }
            let written = motion.written.last().unwrap();
            if k > 100 {
                assert_eq!(*written, tau, "cycle {k}");
            }
        }
        assert_eq!(measured, 0, "system allocations in the cycle after warm-up");
        assert_eq!(cycle.counts().loop_system_allocs, 0);
        assert_eq!(cycle.counts().applied, cycles as u64);
        assert_eq!(cycle.missed_commands(), 0);
        assert!(cycle.guard_counts().max_step_written <= 1.0);
        assert_eq!(cycle.timings().named()[0].1.count(), cycles as u64);
        assert_eq!(cycle.counts().min_success_permille, 1000);
    }
    // The state carries the robot's message id, the gravity flag, q, q̇, τ_J.
    let s = rig.latest_state().expect("a published state");
    s.validate(JOINTS).unwrap();
    assert_eq!(s.header.seq, motion.next_id - 1);
    assert!(s.driver_compensates_gravity());
    assert_eq!(s.q(), motion.q);
    assert_eq!(s.qd(), motion.dq);
    assert_eq!(s.tau_measured(), [0.5; JOINTS]);
    assert_eq!(s.status(), Ok(DriverStatus::Ok));
    clean_up(rig);
}

#[test]
fn jumps_are_ramped_within_the_rate_and_limits() {
    let rig = Rig::new("frjump");
    let mut motion = FakeMotion::new(64);
    {
        let mut cycle = FrankaCycle::new(settings(), &rig.ports);
        cycle.begin_motion();
        for _ in 0..20 {
            let tau = [50.0, -50.0, 0.0, 0.0, 20.0, 0.0, 0.0];
            rig.answer(motion.next_id, tau, CommandMode::Normal, 0);
            cycle.step(&mut motion, false).unwrap();
        }
        let mut last = [0.0; JOINTS];
        for w in &motion.written {
            for (a, b) in w.iter().zip(&last) {
                assert!((a - b).abs() <= 1.0, "{w:?} after {last:?}");
            }
            last = *w;
        }
        // Joint 5 stops at its 12 N·m limit.
        assert_eq!(motion.written.last().unwrap()[4], 12.0);
        let g = cycle.guard_counts();
        assert!(g.rate_limited >= 12 && g.limited >= 1, "{g:?}");
    }
    clean_up(rig);
}

#[test]
fn misses_hold_fall_back_then_ramp_down_and_finish() {
    let rig = Rig::new("frmiss");
    let mut motion = FakeMotion::new(256);
    let tau = [2.5, 0.0, 0.0, 0.0, 0.0, 0.0, -0.5];
    {
        let mut cycle = FrankaCycle::new(settings(), &rig.ports);
        cycle.begin_motion();
        // Before the first command: the fallback, no miss counted.
        cycle.step(&mut motion, false).unwrap();
        assert_eq!((cycle.counts().waiting, cycle.missed_commands()), (1, 0));
        for _ in 0..10 {
            rig.answer(motion.next_id, tau, CommandMode::Normal, 0);
            cycle.step(&mut motion, false).unwrap();
        }
        assert_eq!(*motion.written.last().unwrap(), tau);
        // The controller is gone: 3 cycles held, then −D q̇ (ramped).
        for _ in 0..3 {
            cycle.step(&mut motion, false).unwrap();
            assert_eq!(*motion.written.last().unwrap(), tau);
        }
        let s = rig.latest_state().unwrap();
        assert_eq!(s.status(), Ok(DriverStatus::FallbackActive));
        for _ in 0..20 {
            cycle.step(&mut motion, false).unwrap();
        }
        let d = settings().fallback_damping;
        let fallback: Vec<f64> = (0..JOINTS).map(|k| -d[k] * motion.dq[k]).collect();
        assert_eq!(motion.written.last().unwrap().as_slice(), fallback);
        // The fallback timeout (100 ms): ramp to zero, motion_finished.
        let mut end = Step::Running;
        for _ in 0..200 {
            end = cycle.step(&mut motion, false).unwrap();
            if end != Step::Running {
                break;
            }
        }
        assert_eq!(end, Step::Finished(StopReason::FallbackTimeout));
        assert_eq!(motion.finished, Some([0.0; JOINTS]));
        assert!(cycle.counts().stopping >= 2, "{:?}", cycle.counts());
        assert_eq!(cycle.logic().status(), DriverStatus::Stopped);
        // Between motions the robot's states go out with status Stopped; a
        // controller answering them is noticed.
        let state = motion.read_once().unwrap();
        assert!(!cycle.idle_step(&state));
        let next = motion.read_once().unwrap();
        rig.answer(next.time.as_millis(), tau, CommandMode::Normal, 0);
        assert!(cycle.idle_step(&next));
        assert_eq!(
            rig.latest_state().unwrap().status(),
            Ok(DriverStatus::Stopped)
        );
    }
    clean_up(rig);
}

#[test]
fn a_stop_command_ends_the_motion_and_a_gravity_command_is_refused() {
    let rig = Rig::new("frstop");
    let mut motion = FakeMotion::new(64);
    {
        let mut cycle = FrankaCycle::new(settings(), &rig.ports);
        cycle.begin_motion();
        rig.answer(motion.next_id, [0.5; JOINTS], CommandMode::Normal, 0);
        cycle.step(&mut motion, false).unwrap();
        // g(q) included: the robot adds it too, so the command is refused.
        let id = motion.next_id;
        rig.answer(
            id,
            [0.5; JOINTS],
            CommandMode::Normal,
            COMMAND_FLAG_GRAVITY_INCLUDED,
        );
        cycle.step(&mut motion, false).unwrap();
        assert_eq!(cycle.rejections().gravity_conflict, 1);
        assert_eq!(cycle.counts().held, 1);
        rig.answer(motion.next_id, [0.0; JOINTS], CommandMode::Stop, 0);
        let end = cycle.step(&mut motion, false).unwrap();
        assert_eq!(end, Step::Finished(StopReason::Commanded));
        assert_eq!(motion.finished, Some([0.0; JOINTS]));
    }
    clean_up(rig);
}

#[test]
fn a_robot_error_ends_the_cycle_with_its_names() {
    let rig = Rig::new("frerr");
    let mut motion = FakeMotion::new(16);
    {
        let mut cycle = FrankaCycle::new(settings(), &rig.ports);
        cycle.begin_motion();
        let mut errors = Errors::default();
        errors.0[Errors::index_of("joint_velocity_violation").unwrap()] = true;
        motion.fail = Some(FrankaError::Control(ControlException {
            message: "libfranka: Move command aborted: motion aborted by reflex!".into(),
            move_status: Some(MoveStatus::ReflexAborted),
            last_motion_errors: errors,
            log: Vec::new(),
        }));
        let e = cycle.step(&mut motion, false).unwrap_err();
        let fault = hcc_franka::faults::Fault::from_error(&e);
        assert_eq!(fault.names(), "joint_velocity_violation");
        cycle.abort_motion();
        assert_eq!(cycle.logic().status(), DriverStatus::Stopped);
        assert!(motion.written.is_empty());
        // A recovered robot starts a new motion with fresh logic.
        cycle.begin_motion();
        rig.answer(motion.next_id, [0.2; JOINTS], CommandMode::Normal, 0);
        assert!(matches!(cycle.step(&mut motion, false), Ok(Step::Running)));
        assert_eq!(cycle.counts().motions, 2);
        rig.answer(motion.next_id, [0.2; JOINTS], CommandMode::Normal, 0);
        cycle.step(&mut motion, true).unwrap();
        // A signal: ramp down from 0.2 N·m in one cycle, then finish.
        let mut end = Step::Running;
        for _ in 0..3 {
            end = cycle.step(&mut motion, false).unwrap();
            if end != Step::Running {
                break;
            }
        }
        assert_eq!(end, Step::Finished(StopReason::Requested));
    }
    clean_up(rig);
}
