//! The per-cycle helpers (validation, setters, sequence checks) do not
//! allocate: a counting global allocator must see zero allocations.

use hcc_msgs::{
    GAIN_STIFFNESS_FULL, JointState, MsgError, SETPOINT_DAMPING, SETPOINT_GOAL, SETPOINT_STIFFNESS,
    SETPOINT_VELOCITY, SequenceChecker, Setpoint, SetpointRejection, Telemetry, TorqueCommand,
    answer_code, check_gravity_agreement, command_freshness, monotonic_now_ns,
};

/// Counts the allocations of each thread (`hcc_rtalloc::thread_stats`), so the
/// test harness's own threads never disturb the count.
#[global_allocator]
static GLOBAL: hcc_rtalloc::RtAllocator = hcc_rtalloc::RtAllocator::new();

#[test]
fn hot_path_helpers_do_not_allocate() {
    let q = [0.3; 7];
    let mut state = JointState::zeroed();
    let mut command = TorqueCommand::zeroed();
    let mut telemetry = Telemetry::zeroed();
    let mut checker = SequenceChecker::new();
    let mut errors = 0usize;

    let before = hcc_rtalloc::thread_stats().allocs;
    for k in 0..1000u64 {
        state.header.seq = k;
        state.header.stamp_ns = monotonic_now_ns();
        state.set_joints(&q, &q, &q).unwrap_or_else(|_| errors += 1);
        let mut bad = state;
        bad.qd[3] = f64::NAN;
        if let Err(MsgError::NonFinite { .. }) = bad.validate(7) {
        } else {
            errors += 1;
        }
        state.validate(7).unwrap_or_else(|_| errors += 1);
        let event = checker.observe(k);
        if !event.is_accepted() || event.to_result("joint_state", k).is_err() {
            errors += 1;
        }
        if checker.observe(k).to_result("joint_state", k).is_ok() {
            errors += 1;
        }
        command.set_n_joints(7).unwrap_or_else(|_| errors += 1);
        command.set_tau(state.q()).unwrap_or_else(|_| errors += 1);
        command.answer(&state);
        command.flags = hcc_msgs::COMMAND_FLAG_GRAVITY_INCLUDED;
        command.validate(7).unwrap_or_else(|_| errors += 1);
        check_gravity_agreement(&state, &command).unwrap_or_else(|_| errors += 1);
        let _ = command_freshness(command.state_seq, k);
        telemetry
            .set_shape(7, &[3, 3, 7])
            .unwrap_or_else(|_| errors += 1);
        telemetry.validate(7).unwrap_or_else(|_| errors += 1);
    }
    let after = hcc_rtalloc::thread_stats().allocs;
    assert_eq!(errors, 0);
    assert_eq!(after - before, 0, "allocations in the hot path");
}

/// The driver side of the contract (`hcc_msgs::driver`), through every
/// branch — apply, hold, fallback, rejections, stop — allocates nothing.
#[test]
fn driver_logic_does_not_allocate() {
    use hcc_msgs::driver::{Action, DriverLogic, DriverSettings, Gravity, Offer, StopMode};
    use hcc_msgs::{CommandMode, DriverStatus, MAX_JOINTS};
    const N: usize = 7;
    let settings = |gravity, stop_mode, wait| DriverSettings {
        n: N,
        late_tolerance: 1,
        check_sequence: true,
        hold_cycles: 3,
        fallback_timeout_cycles: Some(50),
        wait_for_first_command: wait,
        fallback_damping: [2.0; MAX_JOINTS],
        gravity,
        stop_mode,
    };
    let mut errors = 0usize;
    let (q, g) = ([0.3; N], [1.5; N]);
    let mut tau = [0.0; N];
    let mut state = JointState::zeroed();
    let mut command = TorqueCommand::zeroed();
    let before = hcc_rtalloc::thread_stats().allocs;
    for (gravity, stop_mode, wait) in [
        (Gravity::ControllerSends, StopMode::SafeStop, false),
        (Gravity::RobotAdds, StopMode::SafeStop, false),
        (Gravity::DriverAdds, StopMode::Brake, true),
    ] {
        let mut logic = DriverLogic::new(settings(gravity, stop_mode, wait));
        for k in 0..200u64 {
            let seq = logic
                .fill_state(&mut state, &q, &q, &q, monotonic_now_ns())
                .unwrap_or_else(|_| {
                    errors += 1;
                    0
                });
            command.set_n_joints(N).unwrap_or_else(|_| errors += 1);
            command.header.seq = k;
            command.answer(&state);
            command.mode = CommandMode::Normal.code();
            command.flags = if state.driver_compensates_gravity() {
                0
            } else {
                hcc_msgs::COMMAND_FLAG_GRAVITY_INCLUDED
            };
            command.set_tau(&q).unwrap_or_else(|_| errors += 1);
            // Every third period the command is missing, every seventh invalid.
            if k % 7 == 0 {
                command.tau[0] = f64::NAN;
            }
            let offered = (k % 3 != 0).then(|| logic.offer(&command, seq));
            let applicable = matches!(offered, Some(Offer::Applicable { .. }));
            let c = applicable.then_some(&command);
            let _ = logic.decide(c, &q, |out| out.copy_from_slice(&g), &mut tau);
            let _ = logic.offer(&command, seq);
        }
        if logic.request_stop() == (Action::Stop { first: true }) {
            logic.stop_completed();
        }
        if logic.status() != DriverStatus::Stopped {
            errors += 1;
        }
        let _ = logic.decide(None, &q, |out| out.copy_from_slice(&g), &mut tau);
    }
    let after = hcc_rtalloc::thread_stats().allocs;
    assert_eq!(errors, 0);
    assert_eq!(after - before, 0, "allocations in the driver logic");
}

#[test]
fn setpoint_validation_does_not_allocate() {
    // A full 32×32 SPD stiffness (the largest factorisation) and a diagonal damping.
    let m = hcc_msgs::MAX_TASK_DIM;
    let mut setpoint = Box::new(Setpoint::zeroed());
    setpoint.fields = SETPOINT_GOAL | SETPOINT_VELOCITY | SETPOINT_STIFFNESS | SETPOINT_DAMPING;
    setpoint.gain_layout = GAIN_STIFFNESS_FULL;
    setpoint.dim = m as u32;
    for j in 0..m {
        setpoint.damping[j] = 10.0;
        for k in 0..m {
            setpoint.stiffness[j * m + k] = if j == k { 100.0 } else { 0.5 };
        }
    }
    let mut bad = setpoint.clone();
    bad.stiffness[1] = -50.0; // asymmetric
    let mut errors = 0usize;

    let before = hcc_rtalloc::thread_stats().allocs;
    for k in 0..200u64 {
        setpoint.header.seq = k;
        if setpoint.validate().is_err() {
            errors += 1;
        }
        if bad.validate() != Err(SetpointRejection::NotSymmetric) {
            errors += 1;
        }
        let code = answer_code(bad.validate());
        if SetpointRejection::from_code(code).map(SetpointRejection::name) != Some("not_symmetric")
        {
            errors += 1;
        }
    }
    let after = hcc_rtalloc::thread_stats().allocs;
    assert_eq!(errors, 0);
    assert_eq!(after - before, 0, "allocations in setpoint validation");
}
