//! The JSON Schema of each channel (and the helpers that build them, for
//! the other JSON channels of hcc's tools) (what Foxglove and PlotJuggler show as
//! the message's fields). Numbers may be `null` where the value was NaN or ±∞.

use serde_json::{Value, json};

/// A number (or `null` for NaN and ±∞) property.
pub fn number(description: &str) -> Value {
    json!({"type": ["number", "null"], "description": description})
}

/// An array-of-numbers property.
pub fn numbers(description: &str) -> Value {
    json!({"type": "array", "items": {"type": ["number", "null"]}, "description": description})
}

/// An integer property.
pub fn integer(description: &str) -> Value {
    json!({"type": "integer", "description": description})
}

fn text(description: &str) -> Value {
    json!({"type": "string", "description": description})
}

/// A message's JSON Schema: an object of `properties`, all required.
pub fn object(title: &str, description: &str, properties: Value) -> Value {
    let required: Vec<String> = properties
        .as_object()
        .map(|o| o.keys().cloned().collect())
        .unwrap_or_default();
    json!({
        "$schema": "https://json-schema.org/draft/2020-12/schema",
        "title": title,
        "description": description,
        "type": "object",
        "properties": properties,
        "required": required,
    })
}

/// A client message's properties: its header and client id (every client
/// message has them, in this order), then `fields`.
fn client_message(fields: Value) -> Value {
    let mut m = json!({
        "seq": integer("the client's sequence number"),
        "stamp_ns": integer("send time, CLOCK_MONOTONIC ns"),
        "schema_version": integer("hcc-msgs schema"),
        "n_joints": integer("header n_joints"),
        "client_id": integer("the client"),
    });
    if let (Some(m), Value::Object(f)) = (m.as_object_mut(), fields) {
        m.extend(f);
    }
    m
}

fn stream_stats() -> Value {
    json!({
        "type": "object",
        "properties": {
            "received": integer("samples received"),
            "recorded": integer("samples written to this file"),
            "gaps": integer("samples lost (sum of the sequence gaps)"),
            "gap_events": integer("sequence gaps"),
            "duplicates": integer("duplicate sequence numbers"),
            "backwards": integer("sequence numbers that went backwards (not restarts)"),
            "restarts": integer("times the stream was numbered again from below (a restarted publisher)"),
        }
    })
}

fn joint_state() -> Value {
    object(
        "hcc.JointState",
        "A joint state of the driver (hcc-msgs JointState)",
        json!({
            "seq": integer("sequence number, +1 per state"),
            "stamp_ns": integer("sampling instant, CLOCK_MONOTONIC ns"),
            "schema_version": integer("hcc-msgs schema"),
            "status": text("driver status: ok, fallback_active, stopping, stopped"),
            "status_code": integer("driver status code"),
            "flags": integer("STATE_FLAG_* bits"),
            "missed_commands": integer("periods without an applicable command (total)"),
            "fallback_cycles": integer("periods in the driver's fallback (total)"),
            "q": numbers("joint positions q, rad (m for prismatic joints)"),
            "qd": numbers("joint velocities q̇, rad/s"),
            "tau_measured": numbers("measured joint torques, N·m"),
        }),
    )
}

fn torque_command() -> Value {
    object(
        "hcc.TorqueCommand",
        "A torque command of the controller (hcc-msgs TorqueCommand)",
        json!({
            "seq": integer("sequence number, +1 per command"),
            "stamp_ns": integer("end of the computation, CLOCK_MONOTONIC ns"),
            "state_seq": integer("seq of the joint state it answers"),
            "state_stamp_ns": integer("stamp of the joint state it answers"),
            "mode": text("normal, safe_hold, singular, stop"),
            "mode_code": integer("command mode code"),
            "flags": integer("COMMAND_FLAG_* bits (1: gravity included)"),
            "tau": numbers("commanded torque τ, eq. (19), N·m"),
        }),
    )
}

fn telemetry() -> Value {
    let level = json!({
        "type": "object",
        "properties": {
            "level": integer("level i, 1-based (1 = highest priority)"),
            "error": numbers("task error x̃_i = x_i − x_i,d"),
            "error_norm": number("‖x̃_i‖"),
            "S": number("storage function S_i, eqs. (26)/(28), J"),
            "tau": numbers("torque τ_i of the level, eqs. (20)/(21), N·m"),
            "sigma_min": number("smallest singular value of the level's projected Jacobian"),
            "singular": {"type": "boolean", "description": "σ_min below the threshold"},
            "goal": numbers("active goal x_i,d(t)"),
            "stiffness": numbers("diagonal of the active stiffness K_i(t)"),
            "damping": numbers("diagonal of the active damping D_i(t)"),
            "transition_progress": number("progress of the goal transition, 0..1"),
        }
    });
    let answer = json!({
        "type": "object",
        "properties": {
            "slot": integer("answer slot"),
            "client_id": integer("the client"),
            "seq": integer("seq of its last setpoint"),
            "answered": integer("setpoints answered for it"),
            "code": integer("0: accepted, else the rejection code"),
            "level": integer("level addressed, 0-based"),
            "duration_s": number("transition duration in force, s"),
            "rejected": integer("setpoints of this client rejected so far"),
            "late": integer("setpoints of this client applied after their state"),
            "knot": integer("the knot a path message was refused for, 0-based in it; 4294967295: none"),
        }
    });
    object(
        "hcc.Telemetry",
        "One cycle of the hierarchical compliance controller (hcc-msgs Telemetry)",
        json!({
            "seq": integer("controller cycle counter"),
            "stamp_ns": integer("publication time, CLOCK_MONOTONIC ns"),
            "state_seq": integer("seq of the joint state of this cycle"),
            "command_seq": integer("seq of the command of this cycle"),
            "mode": text("mode of the command sent"),
            "mode_code": integer("command mode code"),
            "flags": integer("COMMAND_FLAG_* bits; 65536: peer lost; 131072: contact"),
            "singular_levels": integer("bit i: level i+1 singular"),
            "tau": numbers("total torque τ = Σ τ_i + τ_μ + g, eq. (19), N·m"),
            "tau_mu": numbers("coupling compensation τ_μ, eq. (22), N·m"),
            "tau_gravity": numbers("the gravity torque the command carries: g(q), or the load's alone where the driver adds the arm's, N·m"),
            "tau_ext": numbers("estimate r of the external joint torque (momentum observer), N·m"),
            "P_mu": number("power of τ_μ, P_μ = τ_μᵀ q̇ (≈ 0), W"),
            "H": number("storage H of the arm and the controller, J"),
            "load": {
                "type": "object",
                "properties": {
                    "mass": number("mass of the load the controller's model carries, kg"),
                    "com": numbers("its centre of mass in the tip frame, m"),
                    "progress": number("the announced load's ramp, 0 to 1 (1: none runs)"),
                },
                "description": "the load in the hand as the controller's model has it"
            },
            "levels": {"type": "array", "items": level, "description": "per hierarchy level"},
            "counters": {
                "type": "object",
                "additionalProperties": {"type": "integer"},
                "description": "event counters of the controller since its start"
            },
            "timings": {
                "type": "object",
                "properties": {
                    "wakeup_latency_ns": integer("wake-up minus state stamp"),
                    "compute_ns": integer("state read → command sent"),
                    "period_ns": integer("time since the previous wake-up"),
                    "max_compute_ns": integer("worst compute_ns so far"),
                }
            },
            "setpoint_answers": {"type": "array", "items": answer},
        }),
    )
}

fn setpoint() -> Value {
    object(
        "hcc.Setpoint",
        "A client's setpoint to the controller (hcc-msgs Setpoint)",
        client_message(json!({
            "level": integer("target level, 0-based"),
            "fields": integer("SETPOINT_* bits: 1 goal, 2 velocity, 4 stiffness, 8 damping"),
            "dim": integer("task dimension of the values"),
            "gain_layout": integer("GAIN_*_FULL bits"),
            "duration_s": number("transition duration, s"),
            "apply_at_state_seq": integer("applied in the cycle of the first state with seq ≥ this (0: on receipt)"),
            "goal": numbers("goal x_i,d"),
            "velocity": numbers("velocity feed-forward"),
            "stiffness": numbers("K_i: diagonal, or full row-major"),
            "damping": numbers("D_i: diagonal, or full row-major"),
        })),
    )
}

fn path() -> Value {
    object(
        "hcc.PathKnots",
        "A client's path knots to the controller (hcc-msgs PathKnots)",
        client_message(json!({
            "level": integer("target level, 0-based"),
            "flags": integer("PATH_* bits: 1 new, 2 extend, 4 derivatives"),
            "columns": integer("columns per knot"),
            "count": integer("knots in the message"),
            "apply_at_state_seq": integer("a new path starts in the cycle of the first state with seq ≥ this (0: on receipt)"),
            "t": numbers("the knots' times, s of the path's own time"),
            "values": {"type": "array", "items": numbers("a knot's columns"), "description": "the knots' values"},
            "velocity": {"type": "array", "items": numbers("a sample's velocity"), "description": "with PATH_DERIVATIVES: the knots' velocities"},
            "acceleration": {"type": "array", "items": numbers("a sample's acceleration"), "description": "with PATH_DERIVATIVES: the knots' accelerations"},
        })),
    )
}

fn load() -> Value {
    object(
        "hcc.LoadSetpoint",
        "A client's load in the hand to the controller (hcc-msgs LoadSetpoint)",
        client_message(json!({
            "mass": number("kg"),
            "com": numbers("centre of mass in the tip frame, m"),
            "inertia": numbers("about the centre of mass, tip axes, kg·m²: ixx ixy ixz iyy iyz izz"),
            "ramp_s": number("the ramp as sent, s (0: the controller's default)"),
        })),
    )
}

fn recorder() -> Value {
    object(
        "hcc.Recorder",
        "What the recorder received and lost so far",
        json!({
            "elapsed_s": number("wall time since the recording started, s"),
            "joint_state": stream_stats(),
            "torque_command": stream_stats(),
            "telemetry": stream_stats(),
            "setpoint": stream_stats(),
            "path": stream_stats(),
            "load": stream_stats(),
            "total_gaps": integer("samples lost on all streams"),
            "last": {"type": "boolean", "description": "the final count of a clean end"},
        }),
    )
}

/// Schema name and JSON Schema text of a topic's channel (the recording's,
/// and `hcc view`'s live channels of the same topics).
pub fn schema(topic: &str) -> (&'static str, String) {
    let (name, value) = match topic {
        super::TOPIC_JOINT_STATE => ("hcc.JointState", joint_state()),
        super::TOPIC_TORQUE_COMMAND => ("hcc.TorqueCommand", torque_command()),
        super::TOPIC_TELEMETRY => ("hcc.Telemetry", telemetry()),
        super::TOPIC_SETPOINT => ("hcc.Setpoint", setpoint()),
        super::TOPIC_PATH => ("hcc.PathKnots", path()),
        super::TOPIC_LOAD => ("hcc.LoadSetpoint", load()),
        _ => ("hcc.Recorder", recorder()),
    };
    (name, value.to_string())
}
