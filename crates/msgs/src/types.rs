//! The driver-facing wire types: [`Header`] (shared), [`JointState`],
//! [`TorqueCommand`]; the client-facing [`crate::Telemetry`] is in
//! `telemetry.rs`.
//!
//! All types are `#[repr(C)]`, `Copy`, contain no pointers and derive
//! iceoryx2's `ZeroCopySend`, so they live directly in shared memory. Their
//! iceoryx2 type names carry the version of their part of the contract
//! (`…@driver<N>` for the joint state and the torque command, `…@client<N>`
//! for the telemetry; see the crate docs, "Versions"), which makes iceoryx2
//! refuse to connect peers built against different versions of that part.
//!
//! Status and mode fields are raw `u32` codes, not Rust enums: a peer (possibly
//! written in another language) may put any bit pattern there, and reading an
//! invalid discriminant of a Rust enum would be undefined behaviour. Decode
//! them with [`DriverStatus::from_code`] / [`CommandMode::from_code`].
//!
//! Joint vectors hold [`MAX_JOINTS`] entries of which the first
//! `header.n_joints` are meaningful. Writers keep the tail zero; readers ignore it.

use iceoryx2::prelude::ZeroCopySend;

use crate::error::MsgError;
use crate::{MAX_JOINTS, SchemaPart};

/// Name of [`JointState`] in error messages.
pub const JOINT_STATE: &str = "joint_state";
/// Name of [`TorqueCommand`] in error messages.
pub const TORQUE_COMMAND: &str = "torque_command";

/// [`JointState::flags`] bit: the driver itself adds gravity compensation
/// g(q) to every commanded torque, so commands must NOT contain it.
pub const STATE_FLAG_DRIVER_GRAVITY_COMPENSATION: u32 = 1 << 0;
/// [`JointState::flags`] bit: the driver polls the `torque_command` service
/// for its answer and never waits on `command_ready`, so the controller skips
/// that notification (a system call, and a wake-up of the other core) for
/// this state. A driver that blocks on `command_ready` must leave it clear.
pub const STATE_FLAG_DRIVER_POLLS_COMMANDS: u32 = 1 << 1;
/// All [`JointState::flags`] bits defined by this schema.
pub const STATE_FLAGS_KNOWN: u32 =
    STATE_FLAG_DRIVER_GRAVITY_COMPENSATION | STATE_FLAG_DRIVER_POLLS_COMMANDS;

/// [`TorqueCommand::flags`] bit: τ already contains the gravity torque g(q)
/// (term g of the control law, paper Eq. (19)).
pub const COMMAND_FLAG_GRAVITY_INCLUDED: u32 = 1 << 0;
/// All [`TorqueCommand::flags`] bits defined by this schema.
pub const COMMAND_FLAGS_KNOWN: u32 = COMMAND_FLAG_GRAVITY_INCLUDED;

/// Header shared by all messages. It belongs to both parts of the contract:
/// a change of its layout bumps both versions (its type name carries both).
#[derive(Debug, Clone, Copy, PartialEq, Eq, ZeroCopySend)]
#[type_name("hcc_msgs::Header@driver3@client8")]
#[repr(C)]
pub struct Header {
    /// The writer's version of the message's part of the contract
    /// ([`crate::DRIVER_SCHEMA_VERSION`] or [`crate::CLIENT_SCHEMA_VERSION`]).
    pub schema_version: u32,
    /// Number of valid joints `n` (≤ [`MAX_JOINTS`]).
    pub n_joints: u32,
    /// Sequence number of this message stream; +1 per message.
    pub seq: u64,
    /// CLOCK_MONOTONIC time in ns when the content was produced
    /// (state: sampling instant; command: computation end).
    pub stamp_ns: u64,
}

impl Header {
    /// A header of `part` (its current version), `n = 0`, `seq = 0`, `stamp_ns = 0`.
    pub const fn of(part: SchemaPart) -> Self {
        Self {
            schema_version: part.version(),
            n_joints: 0,
            seq: 0,
            stamp_ns: 0,
        }
    }

    /// A header of the driver-facing part ([`JointState`], [`TorqueCommand`]):
    /// [`crate::DRIVER_SCHEMA_VERSION`].
    pub const fn driver() -> Self {
        Self::of(SchemaPart::Driver)
    }

    /// A header of the client-facing part ([`crate::Setpoint`], [`crate::Telemetry`]):
    /// [`crate::CLIENT_SCHEMA_VERSION`].
    pub const fn client() -> Self {
        Self::of(SchemaPart::Client)
    }

    /// [`Header::driver`]: the header drivers build their states with (the
    /// name it had before the contract was versioned in two parts).
    pub const fn new() -> Self {
        Self::driver()
    }

    /// Checks the schema version against `part` and that `n_joints` fits the
    /// capacity and equals `expected_n` (the robot model's joint count).
    pub fn check(
        &self,
        part: SchemaPart,
        msg: &'static str,
        expected_n: usize,
    ) -> Result<usize, MsgError> {
        crate::check_schema(part, msg, self.schema_version)?;
        let n = self.n_joints as usize;
        if n > MAX_JOINTS {
            return Err(MsgError::TooManyJoints {
                msg,
                n,
                capacity: MAX_JOINTS,
            });
        }
        if n != expected_n {
            return Err(MsgError::JointCountMismatch {
                msg,
                n,
                expected: expected_n,
            });
        }
        Ok(n)
    }

    /// `n_joints` clamped to the capacity (never panics on a corrupt value).
    #[inline]
    pub fn n(&self) -> usize {
        (self.n_joints as usize).min(MAX_JOINTS)
    }
}

impl Default for Header {
    fn default() -> Self {
        Self::new()
    }
}

/// Status of the robot driver (or simulator), published in [`JointState::status`].
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
#[repr(u32)]
pub enum DriverStatus {
    /// Commands are applied normally.
    Ok = 0,
    /// No valid command answered recent states; the driver runs its own
    /// fallback (holding torque / damping) and counts `fallback_cycles`.
    FallbackActive = 1,
    /// The driver is stopping (Stop command received, or shutdown): it no
    /// longer applies commands.
    Stopping = 2,
    /// The driver has stopped; no further commands are applied.
    Stopped = 3,
}

impl DriverStatus {
    /// Decodes a raw code; unknown codes are an error naming the field.
    pub const fn from_code(code: u32) -> Result<Self, MsgError> {
        match code {
            0 => Ok(Self::Ok),
            1 => Ok(Self::FallbackActive),
            2 => Ok(Self::Stopping),
            3 => Ok(Self::Stopped),
            value => Err(MsgError::UnknownCode {
                msg: JOINT_STATE,
                field: "status",
                value,
            }),
        }
    }

    /// The raw code.
    pub const fn code(self) -> u32 {
        self as u32
    }
}

/// Mode of a [`TorqueCommand`], in [`TorqueCommand::mode`].
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
#[repr(u32)]
pub enum CommandMode {
    /// τ is the regular control law, paper Eq. (19).
    Normal = 0,
    /// The controller received invalid input (non-finite state, wrong joint
    /// count, stale data) and sends its defined safe command instead
    /// (gravity compensation if included, plus joint damping). Drivers apply it.
    SafeHold = 1,
    /// τ is valid but at least one task Jacobian is (near) singular, so the
    /// hierarchy is degraded (see telemetry). Drivers apply it like Normal.
    Singular = 2,
    /// The controller requests a stop: the driver must not apply τ and must
    /// enter its own stop behaviour (brakes / its safe stop), then publish
    /// status Stopping/Stopped.
    Stop = 3,
}

impl CommandMode {
    /// Decodes a raw code; unknown codes are an error naming the field.
    pub const fn from_code(code: u32) -> Result<Self, MsgError> {
        match code {
            0 => Ok(Self::Normal),
            1 => Ok(Self::SafeHold),
            2 => Ok(Self::Singular),
            3 => Ok(Self::Stop),
            value => Err(MsgError::UnknownCode {
                msg: TORQUE_COMMAND,
                field: "mode",
                value,
            }),
        }
    }

    /// The raw code.
    pub const fn code(self) -> u32 {
        self as u32
    }

    /// Whether a driver applies τ in this mode (all but [`CommandMode::Stop`]).
    pub const fn applies_torque(self) -> bool {
        !matches!(self, Self::Stop)
    }
}

/// Checks that every one of the first `n` entries is finite.
#[inline]
fn check_finite(
    msg: &'static str,
    field: &'static str,
    values: &[f64],
    n: usize,
) -> Result<(), MsgError> {
    for (index, &value) in values.iter().take(n).enumerate() {
        if !value.is_finite() {
            return Err(MsgError::NonFinite {
                msg,
                field,
                index,
                value,
            });
        }
    }
    Ok(())
}

/// Copies `src` into the first `n` entries of `dst` after checking its length
/// and finiteness; on error `dst` is unchanged.
#[inline]
fn set_checked(
    msg: &'static str,
    field: &'static str,
    dst: &mut [f64],
    n: usize,
    src: &[f64],
) -> Result<(), MsgError> {
    if src.len() != n {
        return Err(MsgError::LengthMismatch {
            msg,
            field,
            len: src.len(),
            expected: n,
        });
    }
    check_finite(msg, field, src, n)?;
    dst[..n].copy_from_slice(src);
    Ok(())
}

/// Sets `header.n_joints`, zeroing all joint entries at index ≥ `n` in `vectors`.
fn set_n(
    msg: &'static str,
    header: &mut Header,
    vectors: &mut [&mut [f64; MAX_JOINTS]],
    n: usize,
) -> Result<(), MsgError> {
    if n > MAX_JOINTS {
        return Err(MsgError::TooManyJoints {
            msg,
            n,
            capacity: MAX_JOINTS,
        });
    }
    header.n_joints = n as u32;
    for v in vectors.iter_mut() {
        v[n..].fill(0.0);
    }
    Ok(())
}

/// Joint state, published by the driver/simulator once per cycle (1 kHz).
///
/// Units: q in rad (prismatic: m), q̇ in rad/s (m/s), τ in N·m (N).
/// Joint order: the URDF chain order from root to tip (actuated joints only).
#[derive(Debug, Clone, Copy, PartialEq, ZeroCopySend)]
#[type_name("hcc_msgs::JointState@driver3")]
#[repr(C)]
pub struct JointState {
    /// `seq`: state counter (+1 per cycle); `stamp_ns`: sampling instant.
    pub header: Header,
    /// [`DriverStatus`] code.
    pub status: u32,
    /// `STATE_FLAG_*` bits.
    pub flags: u32,
    /// Total cycles in which no applicable command was available.
    pub missed_commands: u64,
    /// Total cycles spent in the driver's fallback.
    pub fallback_cycles: u64,
    /// Joint positions q.
    pub q: [f64; MAX_JOINTS],
    /// Joint velocities q̇.
    pub qd: [f64; MAX_JOINTS],
    /// Measured joint torques (zero if the driver has no torque sensing).
    pub tau_measured: [f64; MAX_JOINTS],
}

impl JointState {
    /// All-zero state with the current driver schema, `n = 0` and status Ok.
    pub const fn zeroed() -> Self {
        Self {
            header: Header::driver(),
            status: DriverStatus::Ok as u32,
            flags: 0,
            missed_commands: 0,
            fallback_cycles: 0,
            q: [0.0; MAX_JOINTS],
            qd: [0.0; MAX_JOINTS],
            tau_measured: [0.0; MAX_JOINTS],
        }
    }

    /// Number of valid joints (clamped to the capacity).
    #[inline]
    pub fn n(&self) -> usize {
        self.header.n()
    }

    /// Joint positions, length `n`.
    #[inline]
    pub fn q(&self) -> &[f64] {
        &self.q[..self.n()]
    }

    /// Joint velocities, length `n`.
    #[inline]
    pub fn qd(&self) -> &[f64] {
        &self.qd[..self.n()]
    }

    /// Measured torques, length `n`.
    #[inline]
    pub fn tau_measured(&self) -> &[f64] {
        &self.tau_measured[..self.n()]
    }

    /// Decoded driver status.
    pub fn status(&self) -> Result<DriverStatus, MsgError> {
        DriverStatus::from_code(self.status)
    }

    /// Sets `n` and zeroes all entries at index ≥ `n`.
    pub fn set_n_joints(&mut self, n: usize) -> Result<(), MsgError> {
        set_n(
            JOINT_STATE,
            &mut self.header,
            &mut [&mut self.q, &mut self.qd, &mut self.tau_measured],
            n,
        )
    }

    /// Sets q (length must equal `n`, values finite).
    pub fn set_q(&mut self, q: &[f64]) -> Result<(), MsgError> {
        let n = self.n();
        set_checked(JOINT_STATE, "q", &mut self.q, n, q)
    }

    /// Sets q̇ (length must equal `n`, values finite).
    pub fn set_qd(&mut self, qd: &[f64]) -> Result<(), MsgError> {
        let n = self.n();
        set_checked(JOINT_STATE, "qd", &mut self.qd, n, qd)
    }

    /// Sets `n = q.len()` and q, q̇, τ_measured at once (tail zeroed).
    /// Everything is checked first, so on error the message is unchanged.
    pub fn set_joints(&mut self, q: &[f64], qd: &[f64], tau: &[f64]) -> Result<(), MsgError> {
        let n = q.len();
        if n > MAX_JOINTS {
            return Err(MsgError::TooManyJoints {
                msg: JOINT_STATE,
                n,
                capacity: MAX_JOINTS,
            });
        }
        for (field, v) in [("q", q), ("qd", qd), ("tau_measured", tau)] {
            if v.len() != n {
                return Err(MsgError::LengthMismatch {
                    msg: JOINT_STATE,
                    field,
                    len: v.len(),
                    expected: n,
                });
            }
            check_finite(JOINT_STATE, field, v, n)?;
        }
        self.set_n_joints(n)?;
        self.q[..n].copy_from_slice(q);
        self.qd[..n].copy_from_slice(qd);
        self.tau_measured[..n].copy_from_slice(tau);
        Ok(())
    }

    /// Full receiver-side check: schema, `n` within capacity and equal to
    /// `expected_n`, known status and flags, all n entries of q, q̇, τ finite.
    pub fn validate(&self, expected_n: usize) -> Result<(), MsgError> {
        let n = self
            .header
            .check(SchemaPart::Driver, JOINT_STATE, expected_n)?;
        self.status()?;
        if self.flags & !STATE_FLAGS_KNOWN != 0 {
            return Err(MsgError::UnknownCode {
                msg: JOINT_STATE,
                field: "flags",
                value: self.flags,
            });
        }
        check_finite(JOINT_STATE, "q", &self.q, n)?;
        check_finite(JOINT_STATE, "qd", &self.qd, n)?;
        check_finite(JOINT_STATE, "tau_measured", &self.tau_measured, n)
    }

    /// Whether the driver adds gravity compensation itself.
    pub fn driver_compensates_gravity(&self) -> bool {
        self.flags & STATE_FLAG_DRIVER_GRAVITY_COMPENSATION != 0
    }
}

impl Default for JointState {
    fn default() -> Self {
        Self::zeroed()
    }
}

/// Torque command, published by the controller once per received state.
#[derive(Debug, Clone, Copy, PartialEq, ZeroCopySend)]
#[type_name("hcc_msgs::TorqueCommand@driver3")]
#[repr(C)]
pub struct TorqueCommand {
    /// `seq`: command counter (+1 per command); `stamp_ns`: when τ was computed.
    pub header: Header,
    /// Echo of the `header.seq` of the [`JointState`] this command answers.
    pub state_seq: u64,
    /// Echo of the `header.stamp_ns` of that state (round-trip latency).
    pub state_stamp_ns: u64,
    /// [`CommandMode`] code.
    pub mode: u32,
    /// `COMMAND_FLAG_*` bits.
    pub flags: u32,
    /// Commanded joint torques τ (N·m; prismatic N).
    pub tau: [f64; MAX_JOINTS],
}

impl TorqueCommand {
    /// All-zero command with the current driver schema, `n = 0` and mode Normal.
    pub const fn zeroed() -> Self {
        Self {
            header: Header::driver(),
            state_seq: 0,
            state_stamp_ns: 0,
            mode: CommandMode::Normal as u32,
            flags: 0,
            tau: [0.0; MAX_JOINTS],
        }
    }

    /// Number of valid joints (clamped to the capacity).
    #[inline]
    pub fn n(&self) -> usize {
        self.header.n()
    }

    /// Commanded torques, length `n`.
    #[inline]
    pub fn tau(&self) -> &[f64] {
        &self.tau[..self.n()]
    }

    /// Decoded mode.
    pub fn mode(&self) -> Result<CommandMode, MsgError> {
        CommandMode::from_code(self.mode)
    }

    /// Sets `n` and zeroes τ at index ≥ `n`.
    pub fn set_n_joints(&mut self, n: usize) -> Result<(), MsgError> {
        set_n(TORQUE_COMMAND, &mut self.header, &mut [&mut self.tau], n)
    }

    /// Sets τ (length must equal `n`, values finite).
    pub fn set_tau(&mut self, tau: &[f64]) -> Result<(), MsgError> {
        let n = self.n();
        set_checked(TORQUE_COMMAND, "tau", &mut self.tau, n, tau)
    }

    /// Fills the echo fields from the state this command answers.
    pub fn answer(&mut self, state: &JointState) {
        self.state_seq = state.header.seq;
        self.state_stamp_ns = state.header.stamp_ns;
    }

    /// Whether τ contains the gravity torque g(q).
    pub fn gravity_included(&self) -> bool {
        self.flags & COMMAND_FLAG_GRAVITY_INCLUDED != 0
    }

    /// Full receiver-side check: schema, `n`, known mode and flags, τ finite.
    pub fn validate(&self, expected_n: usize) -> Result<(), MsgError> {
        let n = self
            .header
            .check(SchemaPart::Driver, TORQUE_COMMAND, expected_n)?;
        self.mode()?;
        if self.flags & !COMMAND_FLAGS_KNOWN != 0 {
            return Err(MsgError::UnknownCode {
                msg: TORQUE_COMMAND,
                field: "flags",
                value: self.flags,
            });
        }
        check_finite(TORQUE_COMMAND, "tau", &self.tau, n)
    }
}

impl Default for TorqueCommand {
    fn default() -> Self {
        Self::zeroed()
    }
}
