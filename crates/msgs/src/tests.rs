//! Unit tests: layout, validation, schema, gravity agreement.

use core::mem::{align_of, offset_of, size_of};

use iceoryx2::prelude::ZeroCopySend;

use super::*;

#[test]
fn layout_has_no_hidden_padding() {
    assert_eq!(size_of::<Header>(), 24);
    assert_eq!(align_of::<Header>(), 8);
    // Header, status, flags, 2 counters, 3 joint vectors.
    assert_eq!(
        size_of::<JointState>(),
        24 + 4 + 4 + 8 + 8 + 3 * 8 * MAX_JOINTS
    );
    assert_eq!(size_of::<JointState>(), 816);
    assert_eq!(offset_of!(JointState, q), 48);
    // Header, two echoes, mode, flags, tau.
    assert_eq!(
        size_of::<TorqueCommand>(),
        24 + 8 + 8 + 4 + 4 + 8 * MAX_JOINTS
    );
    assert_eq!(size_of::<TorqueCommand>(), 304);
    assert_eq!(offset_of!(TorqueCommand, tau), 48);
    let telemetry_fields = 24
        + 8
        + 8
        + 4
        + 4
        + 4 * MAX_LEVELS
        + 4
        + 4
        + 8 * MAX_JOINTS * (3 + MAX_LEVELS)
        + 8 * MAX_TASK_DIM * MAX_LEVELS
        + 8 * MAX_LEVELS * 2
        + 8
        + size_of::<TelemetryCounters>()
        + size_of::<TelemetryTimings>()
        + 3 * 8 * MAX_TASK_DIM * MAX_LEVELS
        + 8 * MAX_LEVELS
        + size_of::<SetpointAnswer>() * MAX_SETPOINT_CLIENTS
        + 8 * MAX_JOINTS
        + 8
        + 3 * 8 * MAX_LEVELS
        + 5 * 8;
    assert_eq!(size_of::<Telemetry>(), telemetry_fields);
    // Client schemas 4, 6 and 8 appended tau_ext, then h, potential, tank and
    // tank_valve, then the load: every older field kept its offset.
    let appended_8 = 5 * 8;
    assert_eq!(
        offset_of!(Telemetry, load_mass),
        telemetry_fields - appended_8
    );
    let appended_6 = 8 + 3 * 8 * MAX_LEVELS + appended_8;
    assert_eq!(
        offset_of!(Telemetry, tau_ext),
        telemetry_fields - appended_6 - 8 * MAX_JOINTS
    );
    assert_eq!(offset_of!(Telemetry, h), telemetry_fields - appended_6);
    assert_eq!(size_of::<TelemetryCounters>(), 14 * 8);
    assert_eq!(size_of::<TelemetryTimings>(), 4 * 8);
    assert_eq!(size_of::<SetpointAnswer>(), 3 * 8 + 2 * 4 + 8 + 4 * 4);
    for a in [
        align_of::<JointState>(),
        align_of::<TorqueCommand>(),
        align_of::<Telemetry>(),
    ] {
        assert_eq!(a, 8);
    }
    // Header, client id, level, fields, dim, layout, duration, apply-at,
    // goal, velocity, two full gain matrices.
    assert_eq!(
        size_of::<Setpoint>(),
        24 + 8 + 4 * 4 + 8 + 8 + 8 * MAX_TASK_DIM * 2 + 8 * MAX_GAIN_ENTRIES * 2
    );
    assert_eq!(size_of::<Setpoint>(), 16_960);
    assert_eq!(offset_of!(Setpoint, goal), 64);
    assert_eq!(align_of::<Setpoint>(), 8);
    // The torque path fits in a page each.
    assert!(size_of::<JointState>() <= 4096 && size_of::<TorqueCommand>() <= 4096);
    const { assert!(MAX_JOINTS >= 32) };
}

#[test]
fn each_part_s_version_is_encoded_in_its_type_names() {
    // SAFETY: type_name only returns a static string.
    let names = unsafe {
        [
            (
                SchemaPart::Driver,
                <JointState as ZeroCopySend>::type_name(),
            ),
            (
                SchemaPart::Driver,
                <TorqueCommand as ZeroCopySend>::type_name(),
            ),
            (SchemaPart::Client, <Telemetry as ZeroCopySend>::type_name()),
            (
                SchemaPart::Client,
                <TelemetryCounters as ZeroCopySend>::type_name(),
            ),
            (
                SchemaPart::Client,
                <TelemetryTimings as ZeroCopySend>::type_name(),
            ),
            (SchemaPart::Client, <Setpoint as ZeroCopySend>::type_name()),
            (
                SchemaPart::Client,
                <SetpointAnswer as ZeroCopySend>::type_name(),
            ),
        ]
    };
    for (part, name) in names {
        let suffix = format!("@{}{}", part.name(), part.version());
        assert!(name.starts_with("hcc_msgs::"), "{name}");
        assert!(name.ends_with(&suffix), "{name} lacks {suffix}");
        assert_eq!(name.matches('@').count(), 1, "{name}: one part only");
    }
    // The header is in both parts: its name carries both versions.
    // SAFETY: as above.
    let header = unsafe { <Header as ZeroCopySend>::type_name() };
    assert_eq!(
        header,
        format!("hcc_msgs::Header@driver{DRIVER_SCHEMA_VERSION}@client{CLIENT_SCHEMA_VERSION}")
    );
}

#[test]
fn zeroed_messages_carry_their_part_s_version() {
    assert_eq!(
        JointState::zeroed().header.schema_version,
        DRIVER_SCHEMA_VERSION
    );
    assert_eq!(
        TorqueCommand::zeroed().header.schema_version,
        DRIVER_SCHEMA_VERSION
    );
    assert_eq!(
        Telemetry::zeroed().header.schema_version,
        CLIENT_SCHEMA_VERSION
    );
    assert_eq!(
        Setpoint::zeroed().header.schema_version,
        CLIENT_SCHEMA_VERSION
    );
    assert_eq!(Header::new(), Header::driver());
}

#[test]
fn schema_check() {
    let d = SchemaPart::Driver;
    assert_eq!(check_schema(d, JOINT_STATE, DRIVER_SCHEMA_VERSION), Ok(()));
    let e = check_schema(d, JOINT_STATE, DRIVER_SCHEMA_VERSION + 1).unwrap_err();
    assert_eq!(
        e,
        MsgError::SchemaMismatch {
            msg: JOINT_STATE,
            part: "driver",
            found: DRIVER_SCHEMA_VERSION + 1,
            expected: DRIVER_SCHEMA_VERSION
        }
    );
    assert!(e.to_string().contains("joint_state.header.schema_version"));
    assert!(e.to_string().contains("driver schema"), "{e}");
    let mut s = valid_state(7);
    s.header.schema_version = 0;
    assert!(matches!(
        s.validate(7),
        Err(MsgError::SchemaMismatch { found: 0, .. })
    ));
    // Each message is checked against its own part.
    let mut t = Telemetry::zeroed();
    t.header.schema_version = CLIENT_SCHEMA_VERSION + 1;
    assert!(matches!(
        t.validate(0),
        Err(MsgError::SchemaMismatch { part: "client", .. })
    ));
}

fn valid_state(n: usize) -> JointState {
    let mut s = JointState::zeroed();
    let q: Vec<f64> = (0..n).map(|i| 0.1 * i as f64).collect();
    let qd: Vec<f64> = (0..n).map(|i| -0.01 * i as f64).collect();
    let tau = vec![1.5; n];
    s.set_joints(&q, &qd, &tau).unwrap();
    s
}

#[test]
fn zeroed_messages_are_valid_and_empty() {
    let s = JointState::zeroed();
    assert_eq!(s.header.schema_version, DRIVER_SCHEMA_VERSION);
    assert_eq!(s.q().len(), 0);
    assert_eq!(s.validate(0), Ok(()));
    assert_eq!(TorqueCommand::zeroed().validate(0), Ok(()));
    assert_eq!(Telemetry::zeroed().validate(0), Ok(()));
    assert_eq!(JointState::default(), s);
}

#[test]
fn state_setters_and_accessors() {
    let s = valid_state(7);
    assert_eq!(s.n(), 7);
    assert_eq!(s.q().len(), 7);
    assert_eq!(s.qd()[3], -0.03);
    assert_eq!(s.tau_measured(), &[1.5; 7]);
    assert_eq!(s.validate(7), Ok(()));
    assert_eq!(s.status(), Ok(DriverStatus::Ok));

    // Shrinking n zeroes the tail.
    let mut t = s;
    t.set_n_joints(3).unwrap();
    assert!(t.q[3..].iter().all(|&x| x == 0.0));
    assert_eq!(t.q(), &s.q()[..3]);

    // A setter with the wrong length or a non-finite value leaves q unchanged.
    let mut u = s;
    assert_eq!(
        u.set_q(&[0.0; 6]),
        Err(MsgError::LengthMismatch {
            msg: JOINT_STATE,
            field: "q",
            len: 6,
            expected: 7
        })
    );
    let mut bad = [0.0; 7];
    bad[4] = f64::NAN;
    assert!(matches!(
        u.set_qd(&bad),
        Err(MsgError::NonFinite {
            field: "qd",
            index: 4,
            ..
        })
    ));
    assert_eq!(u, s);
    assert!(matches!(
        u.set_joints(&[0.0; 33], &[0.0; 33], &[0.0; 33]),
        Err(MsgError::TooManyJoints { n: 33, .. })
    ));
    assert!(matches!(
        u.set_n_joints(MAX_JOINTS + 1),
        Err(MsgError::TooManyJoints { .. })
    ));
    assert_eq!(u, s);
}

#[test]
fn state_validation_cases() {
    let s = valid_state(7);

    let mut nan = s;
    nan.q[2] = f64::NAN;
    let e = nan.validate(7).unwrap_err();
    assert!(matches!(
        e,
        MsgError::NonFinite {
            field: "q",
            index: 2,
            ..
        }
    ));
    assert!(e.to_string().contains("joint_state.q[2]"), "{e}");

    let mut inf = s;
    inf.tau_measured[6] = f64::NEG_INFINITY;
    assert!(matches!(
        inf.validate(7),
        Err(MsgError::NonFinite {
            field: "tau_measured",
            index: 6,
            ..
        })
    ));

    // Non-finite values beyond n are ignored.
    let mut tail = s;
    tail.qd[20] = f64::INFINITY;
    assert_eq!(tail.validate(7), Ok(()));

    assert_eq!(
        s.validate(6),
        Err(MsgError::JointCountMismatch {
            msg: JOINT_STATE,
            n: 7,
            expected: 6
        })
    );

    // A corrupt n beyond the capacity is an error, and accessors stay in bounds.
    let mut big = s;
    big.header.n_joints = 1000;
    assert_eq!(
        big.validate(7),
        Err(MsgError::TooManyJoints {
            msg: JOINT_STATE,
            n: 1000,
            capacity: MAX_JOINTS
        })
    );
    assert_eq!(big.q().len(), MAX_JOINTS);

    let mut status = s;
    status.status = 99;
    assert!(matches!(
        status.validate(7),
        Err(MsgError::UnknownCode {
            field: "status",
            value: 99,
            ..
        })
    ));
    let mut flags = s;
    flags.flags = 0x80;
    assert!(matches!(
        flags.validate(7),
        Err(MsgError::UnknownCode { field: "flags", .. })
    ));
}

#[test]
fn command_roundtrip_and_validation() {
    let state = {
        let mut s = valid_state(7);
        s.header.seq = 41;
        s.header.stamp_ns = 123;
        s
    };
    let mut c = TorqueCommand::zeroed();
    c.set_n_joints(7).unwrap();
    c.set_tau(&[2.0; 7]).unwrap();
    c.answer(&state);
    c.flags = COMMAND_FLAG_GRAVITY_INCLUDED;
    assert_eq!((c.state_seq, c.state_stamp_ns), (41, 123));
    assert_eq!(c.validate(7), Ok(()));
    assert_eq!(c.tau(), &[2.0; 7]);
    assert_eq!(c.mode(), Ok(CommandMode::Normal));
    assert_eq!(
        command_freshness(c.state_seq, state.header.seq),
        CommandFreshness::Current
    );

    let mut nan = c;
    nan.tau[0] = f64::NAN;
    assert!(matches!(
        nan.validate(7),
        Err(MsgError::NonFinite { field: "tau", .. })
    ));
    assert!(nan.set_tau(&[f64::INFINITY; 7]).is_err());
    let mut mode = c;
    mode.mode = 7;
    assert!(matches!(
        mode.validate(7),
        Err(MsgError::UnknownCode { field: "mode", .. })
    ));
    assert!(c.validate(8).is_err());
    for (code, mode) in [
        (0, CommandMode::Normal),
        (1, CommandMode::SafeHold),
        (2, CommandMode::Singular),
        (3, CommandMode::Stop),
    ] {
        assert_eq!(CommandMode::from_code(code), Ok(mode));
        assert_eq!(mode.code(), code);
        assert_eq!(mode.applies_torque(), mode != CommandMode::Stop);
    }
    for code in 0..4 {
        assert_eq!(DriverStatus::from_code(code).map(|s| s.code()), Ok(code));
    }
    assert!(DriverStatus::from_code(4).is_err());
}

#[test]
fn gravity_agreement() {
    let mut s = valid_state(7);
    let mut c = TorqueCommand::zeroed();
    c.flags = COMMAND_FLAG_GRAVITY_INCLUDED;
    assert_eq!(check_gravity_agreement(&s, &c), Ok(()));
    s.flags = STATE_FLAG_DRIVER_GRAVITY_COMPENSATION;
    assert!(matches!(
        check_gravity_agreement(&s, &c),
        Err(MsgError::GravityConflict {
            command_includes: true,
            driver_compensates: true
        })
    ));
    c.flags = 0;
    assert_eq!(check_gravity_agreement(&s, &c), Ok(()));
    s.flags = 0;
    assert!(check_gravity_agreement(&s, &c).is_err());
}

#[test]
fn telemetry_shape() {
    let mut t = Telemetry::zeroed();
    t.tau_level[5][0] = 9.0;
    t.task_error[0][5] = 9.0;
    t.set_shape(7, &[3, 3, 7]).unwrap();
    assert_eq!(t.levels(), 3);
    assert_eq!(t.tau_level(0).len(), 7);
    assert_eq!(t.task_error(2).len(), 7);
    assert_eq!(t.task_error(0), &[0.0; 3]);
    assert_eq!(t.tau_level(5), &[] as &[f64]);
    assert_eq!(t.tau_level[5][0], 0.0);
    assert_eq!(t.task_error[0][5], 0.0);
    assert_eq!(t.validate(7), Ok(()));
    t.singular_levels = 0b100;
    assert!(t.is_singular(2) && !t.is_singular(1) && !t.is_singular(40));
    assert!(matches!(
        t.set_shape(7, &[1; 9]),
        Err(MsgError::CapacityExceeded {
            field: "n_levels",
            ..
        })
    ));
    assert!(matches!(
        t.set_shape(7, &[MAX_TASK_DIM + 1]),
        Err(MsgError::CapacityExceeded {
            field: "task_dims",
            ..
        })
    ));
    assert!(t.set_shape(MAX_JOINTS + 1, &[1]).is_err());
    let mut bad = t;
    bad.n_levels = 9;
    assert!(bad.validate(7).is_err());
}

#[test]
fn monotonic_clock_advances() {
    let a = monotonic_now_ns();
    let b = monotonic_now_ns();
    assert!(a > 0 && b >= a);
}

#[test]
fn telemetry_counters_are_listed_once_in_field_order() {
    assert_eq!(TelemetryCounters::COUNT, 14);
    assert_eq!(
        TelemetryCounters::NAMES,
        [
            "cycles",
            "invalid_states",
            "saturations",
            "singular_cycles",
            "stale_events",
            "peer_lost_events",
            "missed_states",
            "sequence_errors",
            "send_failures",
            "rate_limited",
            "low_passed",
            "velocity_limited",
            "velocity_limit_fallbacks",
            "velocity_limit_max_correction_mnm",
        ]
    );
    // The wire layout: one u64 each, in the order of NAMES.
    let offsets = [
        offset_of!(TelemetryCounters, cycles),
        offset_of!(TelemetryCounters, invalid_states),
        offset_of!(TelemetryCounters, saturations),
        offset_of!(TelemetryCounters, singular_cycles),
        offset_of!(TelemetryCounters, stale_events),
        offset_of!(TelemetryCounters, peer_lost_events),
        offset_of!(TelemetryCounters, missed_states),
        offset_of!(TelemetryCounters, sequence_errors),
        offset_of!(TelemetryCounters, send_failures),
        offset_of!(TelemetryCounters, rate_limited),
        offset_of!(TelemetryCounters, low_passed),
        offset_of!(TelemetryCounters, velocity_limited),
        offset_of!(TelemetryCounters, velocity_limit_fallbacks),
        offset_of!(TelemetryCounters, velocity_limit_max_correction_mnm),
    ];
    assert_eq!(
        offsets,
        [0, 8, 16, 24, 32, 40, 48, 56, 64, 72, 80, 88, 96, 104]
    );
    let c = TelemetryCounters {
        cycles: 1,
        invalid_states: 2,
        saturations: 3,
        singular_cycles: 4,
        stale_events: 5,
        peer_lost_events: 6,
        missed_states: 7,
        sequence_errors: 8,
        send_failures: 9,
        rate_limited: 10,
        low_passed: 11,
        velocity_limited: 12,
        velocity_limit_fallbacks: 13,
        velocity_limit_max_correction_mnm: 14,
    };
    assert_eq!(c.values(), [1, 2, 3, 4, 5, 6, 7, 8, 9, 10, 11, 12, 13, 14]);
    assert_eq!(TelemetryCounters::from_values(c.values()), c);
    assert_eq!(c.entries()[5], ("peer_lost_events", 6));
    assert_eq!(TelemetryCounters::ZERO, TelemetryCounters::default());
    assert!(TelemetryCounters::LABELS.iter().all(|l| !l.is_empty()));
}
