//! # hcc-msgs — the message contract between the hcc controller and a robot driver
//!
//! This crate is the complete interface between the hcc controller (the
//! hierarchical compliance controller of Dietrich, Ott & Albu-Schäffer,
//! "Multi-Objective Compliance Control of Redundant Manipulators: Hierarchy,
//! Control, and Stability", IROS 2013) and whatever moves the joints: the
//! hcc plant simulator or a real robot driver. A driver can be written
//! against this crate alone.
//!
//! ## Transport
//!
//! Messages travel zero-copy over iceoryx2 publish-subscribe services
//! (`ipc::Service`). All payload types are `#[repr(C)]`, fixed-size, `Copy`,
//! pointer-free and derive `ZeroCopySend`.
//!
//! | service (see [`ServiceNames`])   | payload           | publisher        | subscribers            |
//! |----------------------------------|-------------------|------------------|------------------------|
//! | `hcc/<ns>/joint_state`           | [`JointState`]    | driver/simulator | controller, loggers    |
//! | `hcc/<ns>/torque_command`        | [`TorqueCommand`] | controller       | driver/simulator, loggers |
//! | `hcc/<ns>/telemetry`             | [`Telemetry`]     | controller       | loggers, `hcc` tools   |
//! | `hcc/<ns>/setpoint`              | [`Setpoint`]      | clients (up to [`ipc::MAX_SETPOINT_PUBLISHERS`]) | controller, loggers |
//! | `hcc/<ns>/state_ready` (event)   | —                 | driver notifies [`EVENT_STATE_PUBLISHED`] | controller (optional wake-up) |
//! | `hcc/<ns>/command_ready` (event) | —                 | controller notifies [`EVENT_COMMAND_PUBLISHED`] | driver (optional wake-up) |
//!
//! `<ns>` is a per-robot namespace ([`validate_namespace`]: 1–64 characters
//! of `[A-Za-z0-9_-]`), so two robots or two tests never share a service.
//! Exactly one publisher per service, except `setpoint`, which several
//! clients may command at once (each with its own client id). Subscribers should use a small buffer
//! with safe overflow (the newest sample wins) and read until empty each
//! cycle, keeping the newest sample.
//!
//! Peers open these services through [`ipc`] ([`ipc::create_node`],
//! [`ipc::Services::open`]), which fixes their capacities, overflow
//! behaviour and the single publisher per service.
//!
//! ## Rates and sequence/echo semantics
//!
//! * The driver publishes one [`JointState`] per control period (nominally
//!   1 kHz), `header.seq` +1 per state, `header.stamp_ns` = sampling instant.
//! * The controller answers every state it accepts with exactly one
//!   [`TorqueCommand`]: its own `header.seq` (+1 per command), and the echo
//!   `state_seq`/`state_stamp_ns` of the state it answers
//!   ([`TorqueCommand::answer`]). It publishes one [`Telemetry`] per cycle.
//! * Receivers check the stream with a [`SequenceChecker`]: `Next` or
//!   `Gap { missed }` are used, `Duplicate`/`Backwards` are dropped (a
//!   restarted peer shows up as repeated `Backwards`; reset the checker then).
//!
//! ## Timing contract of a driver
//!
//! Per period, the driver: (1) samples the joints and publishes a
//! [`JointState`] (optionally notifies `state_ready`); (2) before applying a
//! torque it takes the newest received [`TorqueCommand`] and applies it only
//! if [`TorqueCommand::validate`] passes, its gravity flag agrees
//! ([`check_gravity_agreement`]), and it answers the latest published state
//! ([`command_freshness`] = `Current`), or — per the driver's documented
//! timing tolerance — a state at most `L` periods older (`Late { cycles ≤ L }`;
//! a driver that applies at the start of the next period uses `L = 1`).
//! `Future` commands are never applied.
//!
//! **Missed command** (none applicable this period): increment
//! `missed_commands`; the driver runs its fallback (e.g. hold/gravity
//! compensation plus joint damping −D q̇; never an extrapolated controller
//! torque), sets status `FallbackActive`, increments `fallback_cycles` per
//! period in fallback; it returns to `Ok` with the next applicable command.
//! After a driver-specific timeout in fallback (e.g. 100 ms) it stops.
//!
//! **Mode** ([`CommandMode`]): `Normal` and `Singular` (valid τ, degraded
//! hierarchy) and `SafeHold` (the controller's defined safe command after
//! invalid input) are applied. `Stop`: the driver must not apply τ, performs
//! its own safe stop (brakes / stop category of the robot), publishes status
//! `Stopping` then `Stopped` and does not resume within this session.
//!
//! ## Units, order, time
//!
//! * Revolute joints: q in rad, q̇ in rad/s, τ in N·m. Prismatic joints: m,
//!   m/s, N.
//! * Joint order: the order of the actuated joints along the URDF chain from
//!   the root link to the tip link (fixed joints skipped). `header.n_joints`
//!   must equal the robot model's joint count.
//! * Timestamps: `CLOCK_MONOTONIC` in ns ([`monotonic_now_ns`]), valid
//!   between processes on the same host.
//!
//! ## Gravity
//!
//! The control law τ = Σ τ_i + τ_μ + g (paper Eq. (19)) contains the gravity
//! torque g(q). Whether the controller sends it is a per-robot setting:
//! [`COMMAND_FLAG_GRAVITY_INCLUDED`] in [`TorqueCommand::flags`] says it did.
//! A driver that adds gravity compensation itself (many commercial arms do)
//! sets [`STATE_FLAG_DRIVER_GRAVITY_COMPENSATION`] in [`JointState::flags`].
//! Exactly one side adds g; a driver rejects commands that disagree
//! ([`check_gravity_agreement`]).
//!
//! ## The driver side
//!
//! [`driver::DriverLogic`] implements the driver's half of this contract once
//! (sequence numbers, freshness, gravity agreement, hold → fallback → stop),
//! transport-free and allocation-free; the simulated robot of `hcc-sim` and
//! the example real-robot driver both run it, with their policies as
//! [`driver::DriverSettings`].
//!
//! ## Versions
//!
//! The contract has two parts, versioned apart ([`SchemaPart`]), so that a
//! change on one side of the controller does not break the peers of the
//! other side:
//!
//! | part | version | messages and events |
//! |------|---------|---------------------|
//! | driver-facing | [`DRIVER_SCHEMA_VERSION`] | [`JointState`], [`TorqueCommand`], the `state_ready` and `command_ready` events ([`EVENT_STATE_PUBLISHED`], [`EVENT_COMMAND_PUBLISHED`]), the `STATE_FLAG_*` and `COMMAND_FLAG_*` bits, [`DriverStatus`], [`CommandMode`] |
//! | client-facing | [`CLIENT_SCHEMA_VERSION`] | [`Setpoint`], [`Telemetry`] (with [`TelemetryCounters`], [`TelemetryTimings`], [`SetpointAnswer`]), [`SetpointRejection`] codes, `TELEMETRY_FLAG_*` |
//!
//! **The rule.** A change of the layout or the meaning of anything in a
//! part's row bumps that part's version, and only that part's: a new
//! telemetry field bumps [`CLIENT_SCHEMA_VERSION`] and every driver keeps
//! working unchanged; a new state flag bumps [`DRIVER_SCHEMA_VERSION`] and
//! clients keep working. [`Header`] is in both parts: a change of its
//! layout bumps both. The version sits in every header
//! (`header.schema_version`, checked by [`check_schema`]) and, as
//! `@driver<N>` / `@client<N>`, in the iceoryx2 type name of every payload
//! (`hcc_msgs::JointState@driver3`, `hcc_msgs::Telemetry@client8`), so
//! iceoryx2 itself refuses to connect peers of different versions of one
//! part when a service is opened (`IncompatibleTypes`; size and alignment
//! are compared too). Both parts started at 3, the single schema they were
//! split from (schema 3 defined their present contents), so no number was
//! ever used for two meanings.
//!
//! iceoryx2's own version must match exactly between peers as well: every
//! service records the iceoryx2 version that created it, and opening it from
//! another version fails (`VersionMismatch`). Build all peers of one robot
//! against the same iceoryx2 version.
//!
//! ## Commanding a running controller
//!
//! Clients send [`Setpoint`]s (a level's goal, velocity feed-forward,
//! stiffness and/or damping, and a transition duration) on
//! `hcc/<ns>/setpoint`. [`Setpoint::validate`] does the model-free checks;
//! the controller checks the rest against its law and model. Every setpoint
//! is answered with [`ANSWER_ACCEPTED`] or a [`SetpointRejection`] code (stable
//! numbers) in [`Telemetry::setpoint_answers`]; that extension of
//! the telemetry layout was schema 2. Schema 3 added the setpoint's
//! application point ([`Setpoint::apply_at_state_seq`]: the controller keeps
//! the setpoint until the cycle of that joint-state sequence number, which
//! makes scheduled setpoints over IPC exact) and per-client counts of
//! rejected and late setpoints in [`SetpointAnswer`] (both now the
//! client-facing part, [`CLIENT_SCHEMA_VERSION`]).
//!
//! ## Real-time use
//!
//! Nothing in this crate allocates except building service names and
//! formatting errors. Validation, setters, accessors and the sequence checker
//! are meant for the control loop. Entries beyond `n_joints` are kept zero by
//! writers and ignored by readers.

mod client_message;
pub mod driver;
mod error;
pub mod ipc;
mod load;
mod path;
pub mod scenario;
mod sequence;
mod service;
mod setpoint;
mod telemetry;
mod types;

pub use client_message::ClientMessage;
pub use error::{MsgError, NamespaceError};
pub use load::{DEFAULT_LOAD_RAMP_S, LoadRefusal, LoadRejection, LoadSetpoint};
pub use path::{
    KnotsRefusal, KnotsRejection, MAX_KNOTS_PER_MESSAGE, MAX_PATH_COLUMNS, PATH_DERIVATIVES,
    PATH_EXTEND, PATH_FLAGS_KNOWN, PATH_NEW, PathKnots, PathRejection,
};
pub use sequence::{CommandFreshness, SeqEvent, SequenceChecker, command_freshness};
pub use service::{
    EVENT_COMMAND_PUBLISHED, EVENT_STATE_PUBLISHED, MAX_NAMESPACE_LEN, Namespace, SERVICE_PREFIX,
    ServiceNames, validate_namespace,
};
pub use setpoint::{
    ANSWER_ACCEPTED, GAIN_DAMPING_FULL, GAIN_LAYOUT_KNOWN, GAIN_STIFFNESS_FULL, MAX_GAIN_ENTRIES,
    MAX_PENDING_SETPOINTS, MAX_TRANSITION_S, SETPOINT, SETPOINT_DAMPING, SETPOINT_FIELDS_KNOWN,
    SETPOINT_GOAL, SETPOINT_STIFFNESS, SETPOINT_VELOCITY, SYMMETRY_TOLERANCE, Setpoint,
    SetpointRejection, answer_code,
};
pub use telemetry::{
    MAX_SETPOINT_CLIENTS, NO_KNOT, SetpointAnswer, TELEMETRY, TELEMETRY_FLAG_CONTACT,
    TELEMETRY_FLAG_CONTACT_HOLD, TELEMETRY_FLAG_PEER_LOST, Telemetry, TelemetryCounters,
    TelemetryTimings,
};
pub use types::{
    COMMAND_FLAG_GRAVITY_INCLUDED, COMMAND_FLAGS_KNOWN, CommandMode, DriverStatus, Header,
    JOINT_STATE, JointState, STATE_FLAG_DRIVER_GRAVITY_COMPENSATION,
    STATE_FLAG_DRIVER_POLLS_COMMANDS, STATE_FLAGS_KNOWN, TORQUE_COMMAND, TorqueCommand,
};

/// Version of the driver-facing part of the contract: [`JointState`],
/// [`TorqueCommand`], their events, flags, status and mode codes (see the
/// crate docs, "Versions"). Bump it on any change of their layout or
/// meaning, together with the `@driver<N>` suffix of their `type_name`s (a
/// unit test checks they agree); nothing client-facing bumps it.
/// History (of the single schema it was split from): schema 3 added
/// [`STATE_FLAG_DRIVER_POLLS_COMMANDS`].
pub const DRIVER_SCHEMA_VERSION: u32 = 3;

/// Version of the client-facing part of the contract: [`Setpoint`],
/// [`Telemetry`] and the types inside it, the rejection codes (see the crate
/// docs, "Versions"). Bump it on any change of their layout or meaning,
/// together with the `@client<N>` suffix of their `type_name`s; nothing
/// driver-facing bumps it. History (of the single schema it was split from):
/// schema 2: [`Telemetry`] answers setpoints (active goals and gains,
/// transition progress, per-client answers); schema 3:
/// [`Setpoint::apply_at_state_seq`], [`SetpointAnswer::rejected`] and
/// [`SetpointAnswer::late`]; client schema 4: [`Telemetry::tau_ext`] (the
/// estimate of the external joint torque, appended after every older field,
/// whose offsets are unchanged) and [`TELEMETRY_FLAG_CONTACT`]; client
/// schema 5: the velocity limit's counters in [`TelemetryCounters`]
/// (`velocity_limited`, `velocity_limit_fallbacks`,
/// `velocity_limit_max_correction_mnm`, appended: every later field of
/// [`Telemetry`] moves by 24 bytes); client schema 6: [`Telemetry::h`],
/// [`Telemetry::potential`], [`Telemetry::tank`] and [`Telemetry::tank_valve`]
/// (the storage H, each level's potential in it, its energy tank and the
/// tank's valve; appended after every older field); client schema 7:
/// [`SetpointAnswer::knot`] (the knot a path message was refused for; the
/// slot grows by 8 bytes) and a path's knots with their derivatives
/// ([`PATH_DERIVATIVES`], [`PathKnots::velocity`],
/// [`PathKnots::acceleration`]), and [`LoadSetpoint`] (a new service);
/// client schema 8: [`Telemetry::load_mass`], [`Telemetry::load_com`] and
/// [`Telemetry::load_progress`] (the load the model carries; appended after
/// every older field).
pub const CLIENT_SCHEMA_VERSION: u32 = 8;

/// The two parts of the contract, each with its own version.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum SchemaPart {
    /// Joint state, torque command and their events: what a driver reads and writes.
    Driver,
    /// Setpoints and telemetry: what clients and tools read and write.
    Client,
}

impl SchemaPart {
    /// The part's version ([`DRIVER_SCHEMA_VERSION`] or [`CLIENT_SCHEMA_VERSION`]).
    pub const fn version(self) -> u32 {
        match self {
            SchemaPart::Driver => DRIVER_SCHEMA_VERSION,
            SchemaPart::Client => CLIENT_SCHEMA_VERSION,
        }
    }

    /// `"driver"` or `"client"`, as in the type-name suffix `@driver<N>`.
    pub const fn name(self) -> &'static str {
        match self {
            SchemaPart::Driver => "driver",
            SchemaPart::Client => "client",
        }
    }
}

/// Joint capacity. 32 covers single and dual 7-DOF arms, mobile manipulators
/// and humanoid upper bodies, and keeps [`JointState`] (816 B) and
/// [`TorqueCommand`] (304 B) well inside one 4 KiB page.
pub const MAX_JOINTS: usize = 32;

/// Capacity of hierarchy levels r in [`Telemetry`].
pub const MAX_LEVELS: usize = 8;

/// Capacity of one level's task dimension m_i in [`Telemetry`]. Equal to
/// [`MAX_JOINTS`] because a joint-space (posture) task has dimension n.
pub const MAX_TASK_DIM: usize = MAX_JOINTS;

/// Checks a received schema version against the version of `part`.
pub const fn check_schema(part: SchemaPart, msg: &'static str, found: u32) -> Result<(), MsgError> {
    if found == part.version() {
        Ok(())
    } else {
        Err(MsgError::SchemaMismatch {
            msg,
            part: part.name(),
            found,
            expected: part.version(),
        })
    }
}

/// Checks that exactly one side adds gravity: the command includes g(q)
/// (`command_includes`, [`COMMAND_FLAG_GRAVITY_INCLUDED`]) iff the driver does
/// not compensate gravity itself (`driver_compensates`,
/// [`STATE_FLAG_DRIVER_GRAVITY_COMPENSATION`]). Callable by either side from
/// its own settings, without a message at hand.
pub fn gravity_agreement(driver_compensates: bool, command_includes: bool) -> Result<(), MsgError> {
    if command_includes != driver_compensates {
        Ok(())
    } else {
        Err(MsgError::GravityConflict {
            command_includes,
            driver_compensates,
        })
    }
}

/// [`gravity_agreement`] of the flags of a received state and command.
pub fn check_gravity_agreement(
    state: &JointState,
    command: &TorqueCommand,
) -> Result<(), MsgError> {
    gravity_agreement(
        state.driver_compensates_gravity(),
        command.gravity_included(),
    )
}

/// Current `CLOCK_MONOTONIC` time in ns (0 if the clock cannot be read,
/// which Linux never does for this clock). Allocation-free.
pub fn monotonic_now_ns() -> u64 {
    let mut ts = libc::timespec {
        tv_sec: 0,
        tv_nsec: 0,
    };
    // SAFETY: `ts` is a valid, writable timespec.
    let rc = unsafe { libc::clock_gettime(libc::CLOCK_MONOTONIC, &mut ts) };
    if rc != 0 {
        return 0;
    }
    (ts.tv_sec as u64)
        .saturating_mul(1_000_000_000)
        .saturating_add(ts.tv_nsec as u64)
}

#[cfg(test)]
mod tests;
