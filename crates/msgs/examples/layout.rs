//! Prints the memory layout of every contract type as JSON: size, alignment
//! and the offset of each field, plus the versions of the contract's two
//! parts (driver-facing, client-facing), the iceoryx2 type
//! names, the service names and settings, the flag bits, the setpoint
//! constants and the rejection codes with their names and reasons. Bindings
//! in other languages compare their mirrors of the types with this output so
//! that the two never drift apart.
//!
//! Run with `cargo run -q -p hcc-msgs --example layout`.

use std::mem::{align_of, offset_of, size_of};

use hcc_msgs::{
    ANSWER_ACCEPTED, CLIENT_SCHEMA_VERSION, COMMAND_FLAG_GRAVITY_INCLUDED, DRIVER_SCHEMA_VERSION,
    EVENT_COMMAND_PUBLISHED, EVENT_STATE_PUBLISHED, GAIN_DAMPING_FULL, GAIN_LAYOUT_KNOWN,
    GAIN_STIFFNESS_FULL, Header, JointState, LoadRejection, LoadSetpoint, MAX_GAIN_ENTRIES,
    MAX_JOINTS, MAX_KNOTS_PER_MESSAGE, MAX_LEVELS, MAX_NAMESPACE_LEN, MAX_PATH_COLUMNS,
    MAX_PENDING_SETPOINTS, MAX_SETPOINT_CLIENTS, MAX_TASK_DIM, MAX_TRANSITION_S, PATH_EXTEND,
    PATH_FLAGS_KNOWN, PATH_NEW, PathKnots, PathRejection, SETPOINT_DAMPING, SETPOINT_FIELDS_KNOWN,
    SETPOINT_GOAL, SETPOINT_STIFFNESS, SETPOINT_VELOCITY, STATE_FLAG_DRIVER_GRAVITY_COMPENSATION,
    STATE_FLAG_DRIVER_POLLS_COMMANDS, STATE_FLAGS_KNOWN, SYMMETRY_TOLERANCE, ServiceNames,
    Setpoint, SetpointAnswer, SetpointRejection, TELEMETRY_FLAG_CONTACT,
    TELEMETRY_FLAG_CONTACT_HOLD, TELEMETRY_FLAG_PEER_LOST, Telemetry, TelemetryCounters,
    TelemetryTimings, TorqueCommand, ipc,
};
use iceoryx2::prelude::ZeroCopySend;

/// One struct's layout as a JSON object.
fn layout<T: ZeroCopySend>(fields: &[(&str, usize)]) -> String {
    // SAFETY: type_name only returns the name given by the derive.
    let name = unsafe { <T as ZeroCopySend>::type_name() };
    let fields: Vec<String> = fields
        .iter()
        .map(|(f, o)| format!("{{\"name\": \"{f}\", \"offset\": {o}}}"))
        .collect();
    format!(
        "{{\"type_name\": \"{name}\", \"size\": {}, \"align\": {}, \"fields\": [{}]}}",
        size_of::<T>(),
        align_of::<T>(),
        fields.join(", ")
    )
}

macro_rules! fields {
    ($t:ty: $($f:ident),+) => {
        layout::<$t>(&[$((stringify!($f), offset_of!($t, $f))),+])
    };
}

/// `"key": value` pairs joined into the body of a JSON object.
fn object<V: std::fmt::Display>(entries: &[(&str, V)]) -> String {
    let entries: Vec<String> = entries
        .iter()
        .map(|(k, v)| format!("\"{k}\": {v}"))
        .collect();
    entries.join(", ")
}

fn main() {
    let structs = [
        (
            "Header",
            fields!(Header: schema_version, n_joints, seq, stamp_ns),
        ),
        (
            "JointState",
            fields!(JointState: header, status, flags, missed_commands, fallback_cycles, q, qd, tau_measured),
        ),
        (
            "TorqueCommand",
            fields!(TorqueCommand: header, state_seq, state_stamp_ns, mode, flags, tau),
        ),
        (
            "TelemetryCounters",
            fields!(TelemetryCounters: cycles, invalid_states, saturations, singular_cycles,
                stale_events, peer_lost_events, missed_states, sequence_errors, send_failures,
                rate_limited, low_passed, velocity_limited, velocity_limit_fallbacks,
                velocity_limit_max_correction_mnm),
        ),
        (
            "TelemetryTimings",
            fields!(TelemetryTimings: wakeup_latency_ns, compute_ns, period_ns, max_compute_ns),
        ),
        (
            "SetpointAnswer",
            fields!(SetpointAnswer: client_id, seq, answered, code, level, duration_s, rejected, late,
                knot, reserved),
        ),
        (
            "Telemetry",
            fields!(Telemetry: header, state_seq, command_seq, mode, n_levels, task_dims,
                singular_levels, flags, tau, tau_level, tau_mu, tau_gravity, task_error,
                storage, min_singular_value, p_mu, counters, timings, goal, stiffness_diag,
                damping_diag, transition_progress, setpoint_answers, tau_ext, h, potential, tank,
                tank_valve, load_mass, load_com, load_progress),
        ),
        (
            "Setpoint",
            fields!(Setpoint: header, client_id, level, fields, dim, gain_layout, duration_s,
                apply_at_state_seq, goal, velocity, stiffness, damping),
        ),
        (
            "PathKnots",
            fields!(PathKnots: header, client_id, level, flags, columns, count,
                apply_at_state_seq, t, values, velocity, acceleration),
        ),
        (
            "LoadSetpoint",
            fields!(LoadSetpoint: header, client_id, mass, com, inertia, ramp_s),
        ),
    ];
    let body: Vec<String> = structs
        .iter()
        .map(|(name, json)| format!("    \"{name}\": {json}"))
        .collect();
    let names = ServiceNames::new("NS").expect("a valid namespace");
    let services: Vec<(&str, String)> = [
        ("joint_state", names.joint_state()),
        ("torque_command", names.torque_command()),
        ("telemetry", names.telemetry()),
        ("setpoint", names.setpoint()),
        ("path", names.path()),
        ("load", names.load()),
        ("state_ready", names.state_ready()),
        ("command_ready", names.command_ready()),
    ]
    .iter()
    .map(|(k, v)| (*k, format!("\"{v}\"")))
    .collect();
    let settings = object(&[
        ("max_state_subscribers", ipc::MAX_STATE_SUBSCRIBERS),
        ("max_command_subscribers", ipc::MAX_COMMAND_SUBSCRIBERS),
        ("max_telemetry_subscribers", ipc::MAX_TELEMETRY_SUBSCRIBERS),
        ("max_setpoint_publishers", ipc::MAX_SETPOINT_PUBLISHERS),
        ("max_setpoint_subscribers", ipc::MAX_SETPOINT_SUBSCRIBERS),
        ("setpoint_buffer", ipc::SETPOINT_BUFFER),
        ("max_subscriber_buffer", ipc::MAX_SUBSCRIBER_BUFFER),
        ("latest_buffer", ipc::LATEST_BUFFER),
        ("max_borrowed_samples", ipc::MAX_BORROWED_SAMPLES),
        ("max_loaned_samples", ipc::MAX_LOANED_SAMPLES),
        ("max_nodes", ipc::MAX_NODES),
        ("max_notifiers", ipc::MAX_NOTIFIERS),
        ("max_listeners", ipc::MAX_LISTENERS),
        ("event_id_max", ipc::EVENT_ID_MAX),
        ("event_state_published", EVENT_STATE_PUBLISHED),
        ("event_command_published", EVENT_COMMAND_PUBLISHED),
        ("max_namespace_len", MAX_NAMESPACE_LEN),
    ]);
    let flags = object(&[
        (
            "state_driver_gravity_compensation",
            STATE_FLAG_DRIVER_GRAVITY_COMPENSATION,
        ),
        (
            "state_driver_polls_commands",
            STATE_FLAG_DRIVER_POLLS_COMMANDS,
        ),
        ("state_flags_known", STATE_FLAGS_KNOWN),
        ("command_gravity_included", COMMAND_FLAG_GRAVITY_INCLUDED),
        ("telemetry_peer_lost", TELEMETRY_FLAG_PEER_LOST),
        ("telemetry_contact", TELEMETRY_FLAG_CONTACT),
        ("telemetry_contact_hold", TELEMETRY_FLAG_CONTACT_HOLD),
        ("setpoint_goal", SETPOINT_GOAL),
        ("setpoint_velocity", SETPOINT_VELOCITY),
        ("setpoint_stiffness", SETPOINT_STIFFNESS),
        ("setpoint_damping", SETPOINT_DAMPING),
        ("setpoint_fields_known", SETPOINT_FIELDS_KNOWN),
        ("gain_stiffness_full", GAIN_STIFFNESS_FULL),
        ("gain_damping_full", GAIN_DAMPING_FULL),
        ("gain_layout_known", GAIN_LAYOUT_KNOWN),
        ("path_new", PATH_NEW),
        ("path_extend", PATH_EXTEND),
        ("path_flags_known", PATH_FLAGS_KNOWN),
    ]);
    let setpoint = object(&[
        ("max_setpoint_clients", MAX_SETPOINT_CLIENTS.to_string()),
        ("max_pending_setpoints", MAX_PENDING_SETPOINTS.to_string()),
        ("max_gain_entries", MAX_GAIN_ENTRIES.to_string()),
        ("max_transition_s", format!("{MAX_TRANSITION_S:?}")),
        ("symmetry_tolerance", format!("{SYMMETRY_TOLERANCE:?}")),
        ("answer_accepted", ANSWER_ACCEPTED.to_string()),
        ("max_knots_per_message", MAX_KNOTS_PER_MESSAGE.to_string()),
        ("max_path_columns", MAX_PATH_COLUMNS.to_string()),
    ]);
    // Names and reasons are plain text without quotes or backslashes.
    let entry = |(code, name, reason): (u32, &str, &str)| {
        format!("{{\"code\": {code}, \"name\": \"{name}\", \"reason\": \"{reason}\"}}")
    };
    let rejections: Vec<String> = SetpointRejection::ALL
        .iter()
        .map(|r| entry((r.code(), r.name(), r.reason())))
        .collect();
    let path_rejections: Vec<String> = PathRejection::ALL
        .iter()
        .map(|r| entry((r.code(), r.name(), r.reason())))
        .collect();
    let load_rejections: Vec<String> = LoadRejection::ALL
        .iter()
        .map(|r| entry((r.code(), r.name(), r.reason())))
        .collect();
    println!(
        "{{\n  \"driver_schema_version\": {DRIVER_SCHEMA_VERSION},\n  \"client_schema_version\": {CLIENT_SCHEMA_VERSION},\n  \"max_joints\": {MAX_JOINTS},\n  \"max_levels\": {MAX_LEVELS},\n  \"max_task_dim\": {MAX_TASK_DIM},\n  \"ipc_file_prefix_env\": \"{}\",\n  \"services\": {{{}}},\n  \"settings\": {{{settings}}},\n  \"flags\": {{{flags}}},\n  \"setpoint\": {{{setpoint}}},\n  \"rejections\": [{}],\n  \"path_rejections\": [{}],\n  \"load_rejections\": [{}],\n  \"structs\": {{\n{}\n  }}\n}}",
        ipc::FILE_PREFIX_ENV,
        object(&services),
        rejections.join(", "),
        path_rejections.join(", "),
        load_rejections.join(", "),
        body.join(",\n")
    );
}
