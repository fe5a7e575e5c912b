//! Error types of the message contract.
//!
//! [`MsgError`] is produced on the hot path (validation of received samples,
//! setters, sequence checks). It is `Copy` and carries only numbers and
//! `&'static str` names, so creating one never allocates; formatting it (e.g.
//! for a log line outside the real-time loop) does.
//!
//! [`NamespaceError`] is produced at start-up when service names are built.

use thiserror::Error;

/// A received or locally built message violates the contract.
///
/// `msg` names the message type (`"joint_state"`, `"torque_command"`,
/// `"telemetry"`), `field` the offending field.
#[derive(Debug, Clone, Copy, PartialEq, Error)]
pub enum MsgError {
    /// The header's schema version differs from the version of the
    /// message's part of the contract ([`crate::SchemaPart`]).
    #[error(
        "{msg}.header.schema_version = {found}, but this build speaks {part} schema {expected}; \
         rebuild both peers against the same hcc-msgs"
    )]
    SchemaMismatch {
        msg: &'static str,
        /// `"driver"` or `"client"` ([`crate::SchemaPart::name`]).
        part: &'static str,
        found: u32,
        expected: u32,
    },
    /// `n_joints` exceeds [`crate::MAX_JOINTS`].
    #[error("{msg}.header.n_joints = {n} exceeds the capacity MAX_JOINTS = {capacity}")]
    TooManyJoints {
        msg: &'static str,
        n: usize,
        capacity: usize,
    },
    /// `n_joints` differs from the robot model's joint count.
    #[error("{msg}.header.n_joints = {n}, but the robot model has {expected} joints")]
    JointCountMismatch {
        msg: &'static str,
        n: usize,
        expected: usize,
    },
    /// A value is NaN or infinite.
    #[error("{msg}.{field}[{index}] = {value} is not finite")]
    NonFinite {
        msg: &'static str,
        field: &'static str,
        index: usize,
        value: f64,
    },
    /// A slice handed to a setter does not have `n_joints` (or `task_dims[level]`) elements.
    #[error("{msg}.{field}: a slice of length {len} was given, but the message holds {expected}")]
    LengthMismatch {
        msg: &'static str,
        field: &'static str,
        len: usize,
        expected: usize,
    },
    /// A status/mode code or flag bit is not defined by this schema.
    #[error("{msg}.{field} = {value:#x} is not a code defined by this schema")]
    UnknownCode {
        msg: &'static str,
        field: &'static str,
        value: u32,
    },
    /// `n_levels` exceeds [`crate::MAX_LEVELS`] or a level index is out of range.
    #[error("{msg}.{field} = {value} exceeds the capacity {capacity}")]
    CapacityExceeded {
        msg: &'static str,
        field: &'static str,
        value: usize,
        capacity: usize,
    },
    /// The command's gravity flag does not match the driver's gravity handling
    /// (exactly one side must add g(q)).
    #[error(
        "torque_command.flags says gravity included = {command_includes}, but \
         joint_state.flags says the driver compensates gravity = {driver_compensates}; \
         exactly one of them must add g(q)"
    )]
    GravityConflict {
        command_includes: bool,
        driver_compensates: bool,
    },
    /// The sequence number repeats the previous one.
    #[error("{msg}.header.seq = {seq} repeats the previous sequence number")]
    DuplicateSequence { msg: &'static str, seq: u64 },
    /// The sequence number is smaller than the previous one.
    #[error("{msg}.header.seq = {seq} goes backwards (previous was {last})")]
    SequenceBackwards {
        msg: &'static str,
        seq: u64,
        last: u64,
    },
}

/// An invalid service namespace.
#[derive(Debug, Clone, PartialEq, Eq, Error)]
pub enum NamespaceError {
    /// The namespace is the empty string.
    #[error("ipc namespace is empty; use 1 to {max} characters of [A-Za-z0-9_-]")]
    Empty { max: usize },
    /// The namespace is longer than [`crate::MAX_NAMESPACE_LEN`].
    #[error("ipc namespace {namespace:?} has {len} characters; at most {max} are allowed")]
    TooLong {
        namespace: String,
        len: usize,
        max: usize,
    },
    /// The namespace contains a character outside `[A-Za-z0-9_-]`.
    #[error(
        "ipc namespace {namespace:?} contains {ch:?} at byte {index}; \
         only ASCII letters, digits, '_' and '-' are allowed"
    )]
    InvalidChar {
        namespace: String,
        ch: char,
        index: usize,
    },
    /// The namespace starts with '-' (reserved; it also looks like a command-line flag).
    #[error("ipc namespace {namespace:?} must not start with '-'")]
    LeadingDash { namespace: String },
}
