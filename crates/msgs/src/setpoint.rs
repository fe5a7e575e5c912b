//! The [`Setpoint`] message: a client commands a running controller.
//!
//! A setpoint changes one hierarchy level's goal x_{i,d} (with an optional
//! velocity feed-forward ẋ_{i,d}), its stiffness K_i and/or its damping D_i
//! (paper Eqs. (20), (21)), over a transition of a given duration. Values are
//! in the task's own coordinates, exactly as in the scenario TOML:
//!
//! * position tasks: metres on the task's selected axes, in the task's order;
//! * orientation tasks: roll, pitch, yaw in rad (the controller interpolates
//!   on SO(3), not per angle);
//! * joint (posture) tasks: rad (m for prismatic joints), one per joint.
//!
//! K and D are m_i×m_i: either diagonal (`dim` values) or full (`dim²` values,
//! row-major), chosen per matrix by [`Setpoint::gain_layout`].
//!
//! [`Setpoint::validate`] checks everything that needs no robot model and no
//! control law: schema, known bits, level and dimension within the
//! capacities, finite values, a usable duration, and that K and D are
//! symmetric positive definite. The controller checks the rest (the level
//! exists, `dim` equals m_i, the level's stiffness limit, joint limits, the
//! workspace) and answers every setpoint with an [`ANSWER_ACCEPTED`] code or a
//! [`SetpointRejection`] code in its telemetry. Nothing here allocates.

use iceoryx2::prelude::ZeroCopySend;

use crate::types::Header;
use crate::{CLIENT_SCHEMA_VERSION, MAX_LEVELS, MAX_TASK_DIM};

/// Name of [`Setpoint`] in error messages.
pub const SETPOINT: &str = "setpoint";

/// [`Setpoint::fields`] bit: set the goal x_{i,d} (`goal`).
pub const SETPOINT_GOAL: u32 = 1 << 0;
/// [`Setpoint::fields`] bit: set the goal's velocity feed-forward ẋ_{i,d}
/// (`velocity`); only together with [`SETPOINT_GOAL`].
pub const SETPOINT_VELOCITY: u32 = 1 << 1;
/// [`Setpoint::fields`] bit: set the stiffness K_i (`stiffness`).
pub const SETPOINT_STIFFNESS: u32 = 1 << 2;
/// [`Setpoint::fields`] bit: set the damping D_i (`damping`).
pub const SETPOINT_DAMPING: u32 = 1 << 3;
/// All [`Setpoint::fields`] bits defined by this schema.
pub const SETPOINT_FIELDS_KNOWN: u32 =
    SETPOINT_GOAL | SETPOINT_VELOCITY | SETPOINT_STIFFNESS | SETPOINT_DAMPING;

/// [`Setpoint::gain_layout`] bit: `stiffness` holds the full m×m matrix
/// row-major (`dim²` values); otherwise its diagonal (`dim` values).
pub const GAIN_STIFFNESS_FULL: u32 = 1 << 0;
/// [`Setpoint::gain_layout`] bit: `damping` holds the full m×m matrix
/// row-major; otherwise its diagonal.
pub const GAIN_DAMPING_FULL: u32 = 1 << 1;
/// All [`Setpoint::gain_layout`] bits defined by this schema.
pub const GAIN_LAYOUT_KNOWN: u32 = GAIN_STIFFNESS_FULL | GAIN_DAMPING_FULL;

/// Capacity of one full gain matrix (m×m with m ≤ [`MAX_TASK_DIM`]).
pub const MAX_GAIN_ENTRIES: usize = MAX_TASK_DIM * MAX_TASK_DIM;

/// Setpoints the controller keeps waiting for their application point
/// ([`Setpoint::apply_at_state_seq`] ahead of the current state), over all
/// clients. A setpoint that finds them all taken is rejected
/// ([`SetpointRejection::PendingFull`]).
pub const MAX_PENDING_SETPOINTS: usize = 32;

/// Longest transition a setpoint may ask for, in s (one hour). Longer ones
/// are almost certainly a unit error (ms or ns sent as s).
pub const MAX_TRANSITION_S: f64 = 3600.0;

/// Relative tolerance of the symmetry check of a full K or D:
/// |A_jk − A_kj| ≤ `SYMMETRY_TOLERANCE` · max_jk |A_jk|. Values written from
/// a symmetric matrix are exactly symmetric; the tolerance only forgives
/// rounding in a client's own computation of the matrix.
pub const SYMMETRY_TOLERANCE: f64 = 1e-9;

/// The [`Telemetry`](crate::Telemetry) answer code of an accepted setpoint.
/// Every other answer is a [`SetpointRejection::code`].
pub const ANSWER_ACCEPTED: u32 = 0;

/// Why a setpoint was rejected. A rejected setpoint changes nothing. The
/// codes are stable: they travel in telemetry and are never renumbered
/// (new reasons get new codes).
///
/// Checked by [`Setpoint::validate`] (no model needed): `SchemaMismatch`,
/// `UnknownFields`, `NothingSet`, `VelocityWithoutGoal`, `UnknownLayout`,
/// `LevelCapacity`, `DimensionCapacity`, `NonFinite`, `BadDuration`,
/// `NotSymmetric`, `NotPositiveDefinite` of a diagonal gain. Checked by the
/// controller against its law and model: `NotPositiveDefinite` of a full
/// gain matrix (a Cholesky factorisation, hcc-cycle), `UnknownLevel`, `DimensionMismatch`,
/// `StiffnessAboveLimit`, `JointLimit`, `OutsideWorkspace`, `GainsAboveRate`;
/// and by its queue of setpoints that wait for their state: `PendingFull`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
#[repr(u32)]
pub enum SetpointRejection {
    /// `header.schema_version` differs from [`CLIENT_SCHEMA_VERSION`].
    SchemaMismatch = 1,
    /// `fields` has bits this schema does not define.
    UnknownFields = 2,
    /// `fields` is zero: the setpoint sets nothing.
    NothingSet = 3,
    /// [`SETPOINT_VELOCITY`] without [`SETPOINT_GOAL`].
    VelocityWithoutGoal = 4,
    /// `gain_layout` has bits this schema does not define.
    UnknownLayout = 5,
    /// `level` ≥ [`MAX_LEVELS`].
    LevelCapacity = 6,
    /// `dim` is 0 or above [`MAX_TASK_DIM`].
    DimensionCapacity = 7,
    /// A value that is used is NaN or infinite.
    NonFinite = 8,
    /// `duration_s` is negative or above [`MAX_TRANSITION_S`].
    BadDuration = 9,
    /// A full K or D is not symmetric (beyond [`SYMMETRY_TOLERANCE`]).
    NotSymmetric = 10,
    /// K or D is not positive definite (a diagonal entry ≤ 0, or a full
    /// matrix whose Cholesky factorisation fails).
    NotPositiveDefinite = 11,
    /// The controller has no level `level` (it has fewer levels).
    UnknownLevel = 12,
    /// `dim` differs from the level's task dimension m_i.
    DimensionMismatch = 13,
    /// K exceeds the level's `max_stiffness` (an eigenvalue above it).
    StiffnessAboveLimit = 14,
    /// A joint goal lies outside the joint's URDF limits.
    JointLimit = 15,
    /// A position goal lies outside the level's workspace.
    OutsideWorkspace = 16,
    /// The setpoint is due at a later state, but
    /// [`MAX_PENDING_SETPOINTS`] setpoints already wait for theirs.
    PendingFull = 17,
    /// K or D is more than the control rate carries at the arm's current
    /// configuration (T·λmax(J M⁻¹ Jᵀ D) or T²·λmax(J M⁻¹ Jᵀ K) above its bound:
    /// the sampled spring–damper would oscillate).
    GainsAboveRate = 18,
}

impl SetpointRejection {
    /// Every rejection, in code order.
    pub const ALL: [SetpointRejection; 18] = [
        Self::SchemaMismatch,
        Self::UnknownFields,
        Self::NothingSet,
        Self::VelocityWithoutGoal,
        Self::UnknownLayout,
        Self::LevelCapacity,
        Self::DimensionCapacity,
        Self::NonFinite,
        Self::BadDuration,
        Self::NotSymmetric,
        Self::NotPositiveDefinite,
        Self::UnknownLevel,
        Self::DimensionMismatch,
        Self::StiffnessAboveLimit,
        Self::JointLimit,
        Self::OutsideWorkspace,
        Self::PendingFull,
        Self::GainsAboveRate,
    ];

    /// The stable code (never [`ANSWER_ACCEPTED`]).
    pub const fn code(self) -> u32 {
        self as u32
    }

    /// Decodes a code; `None` for [`ANSWER_ACCEPTED`] and unknown codes.
    pub const fn from_code(code: u32) -> Option<Self> {
        if code == 0 || code as usize > Self::ALL.len() {
            None
        } else {
            Some(Self::ALL[code as usize - 1])
        }
    }

    /// A short machine-friendly name (`snake_case`), for JSON and scripts.
    pub const fn name(self) -> &'static str {
        match self {
            Self::SchemaMismatch => "schema_mismatch",
            Self::UnknownFields => "unknown_fields",
            Self::NothingSet => "nothing_set",
            Self::VelocityWithoutGoal => "velocity_without_goal",
            Self::UnknownLayout => "unknown_layout",
            Self::LevelCapacity => "level_capacity",
            Self::DimensionCapacity => "dimension_capacity",
            Self::NonFinite => "non_finite",
            Self::BadDuration => "bad_duration",
            Self::NotSymmetric => "not_symmetric",
            Self::NotPositiveDefinite => "not_positive_definite",
            Self::UnknownLevel => "unknown_level",
            Self::DimensionMismatch => "dimension_mismatch",
            Self::StiffnessAboveLimit => "stiffness_above_limit",
            Self::JointLimit => "joint_limit",
            Self::OutsideWorkspace => "outside_workspace",
            Self::PendingFull => "pending_full",
            Self::GainsAboveRate => "gains_above_rate",
        }
    }

    /// The reason in plain words, for a person.
    pub const fn reason(self) -> &'static str {
        match self {
            Self::SchemaMismatch => "the client speaks another hcc-msgs schema version",
            Self::UnknownFields => "the setpoint sets fields this schema does not define",
            Self::NothingSet => {
                "the setpoint sets nothing (no goal, velocity, stiffness or damping)"
            }
            Self::VelocityWithoutGoal => {
                "a velocity feed-forward needs a goal in the same setpoint"
            }
            Self::UnknownLayout => "the gain layout has bits this schema does not define",
            Self::LevelCapacity => "the level index exceeds the message capacity",
            Self::DimensionCapacity => "the dimension is 0 or exceeds the message capacity",
            Self::NonFinite => "a value is NaN or infinite",
            Self::BadDuration => "the transition duration is negative or longer than one hour",
            Self::NotSymmetric => "a stiffness or damping matrix is not symmetric",
            Self::NotPositiveDefinite => "a stiffness or damping matrix is not positive definite",
            Self::UnknownLevel => "the controller has no such level",
            Self::DimensionMismatch => "the dimension differs from the level's task dimension",
            Self::StiffnessAboveLimit => "the stiffness exceeds the level's max_stiffness",
            Self::JointLimit => "a joint goal lies outside the joint's limits",
            Self::OutsideWorkspace => "a position goal lies outside the level's workspace",
            Self::PendingFull => "too many setpoints wait for their state sequence number",
            Self::GainsAboveRate => {
                "K or D is more than the control rate carries at the arm's configuration (the sampled spring-damper would oscillate)"
            }
        }
    }
}

impl std::fmt::Display for SetpointRejection {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(
            f,
            "{} (code {}): {}",
            self.name(),
            self.code(),
            self.reason()
        )
    }
}

impl std::error::Error for SetpointRejection {}

/// The answer code of a validation result: [`ANSWER_ACCEPTED`] or the
/// rejection's code.
pub const fn answer_code(result: Result<(), SetpointRejection>) -> u32 {
    match result {
        Ok(()) => ANSWER_ACCEPTED,
        Err(r) => r.code(),
    }
}

/// A setpoint for one hierarchy level, published by a client on
/// `hcc/<ns>/setpoint` (see [`crate::ServiceNames::setpoint`]).
///
/// `header.seq` is the client's own sequence number (+1 per setpoint; the
/// controller echoes it with its answer), `header.stamp_ns` the send time,
/// `header.n_joints` is unused (writers set 0).
///
/// `apply_at_state_seq` = k defines when the setpoint takes effect: in the
/// controller cycle that answers the first joint state whose sequence number
/// is ≥ k (taken before that cycle's transitions advance and its law steps).
/// 0, or any k the current state has reached, means at once (the cycle that
/// receives it). A setpoint that arrives after its state is applied on
/// receipt and counted late ([`crate::SetpointAnswer::late`]). The
/// controller answers a setpoint when it applies it; the model-free checks
/// ([`Setpoint::validate`]) reject at receipt. With a driver that numbers its
/// states k = 0, 1, … per control period (hcc-sim), k is the cycle index
/// of t_k = k · T, so a schedule sent ahead is applied exactly as
/// `hcc simulate` applies it in-process. Entries beyond what
/// `fields`, `dim` and `gain_layout` select are ignored (writers keep them
/// zero).
#[derive(Debug, Clone, Copy, PartialEq, ZeroCopySend)]
#[type_name("hcc_msgs::Setpoint@client8")]
#[repr(C)]
pub struct Setpoint {
    /// `seq`: the client's sequence number; `stamp_ns`: send time.
    pub header: Header,
    /// The client's identity (any value the client chooses, unique among
    /// the clients of one controller; e.g. from [`crate::monotonic_now_ns`]
    /// and the process id). Answers are kept per client id.
    pub client_id: u64,
    /// Target level, 0-based in the order of the scenario's tasks.
    pub level: u32,
    /// `SETPOINT_*` bits: what this setpoint sets.
    pub fields: u32,
    /// Task dimension m of the values (must equal the level's m_i).
    pub dim: u32,
    /// `GAIN_*_FULL` bits: full or diagonal K and D.
    pub gain_layout: u32,
    /// Transition duration in s (0: as fast as the level's speed limit
    /// allows; shorter transitions are stretched to that limit).
    pub duration_s: f64,
    /// Apply in the cycle of the first joint state with sequence number ≥
    /// this (0: on receipt); see the type's docs.
    pub apply_at_state_seq: u64,
    /// Goal x_{i,d}, first `dim` entries (with [`SETPOINT_GOAL`]).
    pub goal: [f64; MAX_TASK_DIM],
    /// Velocity feed-forward ẋ_{i,d} at the goal, first `dim` entries (with
    /// [`SETPOINT_VELOCITY`]); units of the goal per second.
    pub velocity: [f64; MAX_TASK_DIM],
    /// K_i: `dim` diagonal values, or `dim²` row-major with [`GAIN_STIFFNESS_FULL`].
    pub stiffness: [f64; MAX_GAIN_ENTRIES],
    /// D_i: `dim` diagonal values, or `dim²` row-major with [`GAIN_DAMPING_FULL`].
    pub damping: [f64; MAX_GAIN_ENTRIES],
}

impl Setpoint {
    /// An all-zero setpoint with the current schema (sets nothing).
    pub const fn zeroed() -> Self {
        Self {
            header: Header::client(),
            client_id: 0,
            level: 0,
            fields: 0,
            dim: 0,
            gain_layout: 0,
            duration_s: 0.0,
            apply_at_state_seq: 0,
            goal: [0.0; MAX_TASK_DIM],
            velocity: [0.0; MAX_TASK_DIM],
            stiffness: [0.0; MAX_GAIN_ENTRIES],
            damping: [0.0; MAX_GAIN_ENTRIES],
        }
    }

    /// `dim` clamped to the capacity (never panics on a corrupt value).
    #[inline]
    pub fn dim(&self) -> usize {
        (self.dim as usize).min(MAX_TASK_DIM)
    }

    /// Whether every bit of `field` (`SETPOINT_*`) is set.
    #[inline]
    pub fn sets(&self, field: u32) -> bool {
        self.fields & field == field
    }

    /// The goal, length `dim`.
    pub fn goal(&self) -> &[f64] {
        &self.goal[..self.dim()]
    }

    /// The velocity feed-forward, length `dim`.
    pub fn velocity(&self) -> &[f64] {
        &self.velocity[..self.dim()]
    }

    /// Whether K is sent as a full matrix.
    pub fn stiffness_full(&self) -> bool {
        self.gain_layout & GAIN_STIFFNESS_FULL != 0
    }

    /// Whether D is sent as a full matrix.
    pub fn damping_full(&self) -> bool {
        self.gain_layout & GAIN_DAMPING_FULL != 0
    }

    /// The K values sent: `dim` (diagonal) or `dim²` (full, row-major).
    pub fn stiffness(&self) -> &[f64] {
        let m = self.dim();
        &self.stiffness[..if self.stiffness_full() { m * m } else { m }]
    }

    /// The D values sent: `dim` (diagonal) or `dim²` (full, row-major).
    pub fn damping(&self) -> &[f64] {
        let m = self.dim();
        &self.damping[..if self.damping_full() { m * m } else { m }]
    }

    /// Entry (j, k) of K as an m×m matrix (zero off the diagonal when
    /// diagonal). Requires j, k < `dim`.
    #[inline]
    pub fn stiffness_at(&self, j: usize, k: usize) -> f64 {
        gain_at(&self.stiffness, self.stiffness_full(), self.dim(), j, k)
    }

    /// Entry (j, k) of D as an m×m matrix.
    #[inline]
    pub fn damping_at(&self, j: usize, k: usize) -> f64 {
        gain_at(&self.damping, self.damping_full(), self.dim(), j, k)
    }

    /// A setpoint of level `level` (0-based) and dimension `dim` that sets
    /// nothing yet; add parts with the `with_*` builders. Sizes beyond the
    /// capacities are kept as given, so [`Setpoint::validate`] names them.
    pub fn for_level(client_id: u64, seq: u64, level: usize, dim: usize) -> Self {
        let mut s = Self::zeroed();
        s.client_id = client_id;
        s.header.seq = seq;
        s.level = level.min(u32::MAX as usize) as u32;
        s.dim = dim.min(u32::MAX as usize) as u32;
        s
    }

    /// Sets the goal (`dim` values) and [`SETPOINT_GOAL`].
    pub fn with_goal(mut self, goal: &[f64]) -> Result<Self, SetpointRejection> {
        let dim = self.dim as usize;
        copy_values(&mut self.goal, goal, dim)?;
        self.fields |= SETPOINT_GOAL;
        Ok(self)
    }

    /// Sets the velocity feed-forward (`dim` values) and [`SETPOINT_VELOCITY`].
    pub fn with_velocity(mut self, velocity: &[f64]) -> Result<Self, SetpointRejection> {
        let dim = self.dim as usize;
        copy_values(&mut self.velocity, velocity, dim)?;
        self.fields |= SETPOINT_VELOCITY;
        Ok(self)
    }

    /// Sets K from `dim` diagonal values or `dim²` row-major values (the
    /// layout follows the length) and [`SETPOINT_STIFFNESS`].
    pub fn with_stiffness(mut self, values: &[f64]) -> Result<Self, SetpointRejection> {
        let dim = self.dim as usize;
        let full = copy_gain(&mut self.stiffness, values, dim)?;
        self.set_layout(GAIN_STIFFNESS_FULL, full);
        self.fields |= SETPOINT_STIFFNESS;
        Ok(self)
    }

    /// Sets D like [`Setpoint::with_stiffness`] and [`SETPOINT_DAMPING`].
    pub fn with_damping(mut self, values: &[f64]) -> Result<Self, SetpointRejection> {
        let dim = self.dim as usize;
        let full = copy_gain(&mut self.damping, values, dim)?;
        self.set_layout(GAIN_DAMPING_FULL, full);
        self.fields |= SETPOINT_DAMPING;
        Ok(self)
    }

    /// Sets the transition duration in s.
    pub fn with_duration(mut self, duration_s: f64) -> Self {
        self.duration_s = duration_s;
        self
    }

    /// Sets the application point: the cycle of the first joint state with
    /// sequence number ≥ `state_seq` (0: on receipt).
    pub fn with_apply_at(mut self, state_seq: u64) -> Self {
        self.apply_at_state_seq = state_seq;
        self
    }

    fn set_layout(&mut self, bit: u32, full: bool) {
        if full {
            self.gain_layout |= bit;
        } else {
            self.gain_layout &= !bit;
        }
    }

    /// The model-free checks (see [`SetpointRejection`]), in this order: schema,
    /// fields, layout, capacities, finiteness of everything used, duration,
    /// the symmetry of a full K and D and the positivity of a diagonal one.
    /// A full matrix's positive definiteness is the controller's to check
    /// (it factorises it; this crate holds no linear algebra).
    /// Allocation-free.
    pub fn validate(&self) -> Result<(), SetpointRejection> {
        if self.header.schema_version != CLIENT_SCHEMA_VERSION {
            return Err(SetpointRejection::SchemaMismatch);
        }
        if self.fields & !SETPOINT_FIELDS_KNOWN != 0 {
            return Err(SetpointRejection::UnknownFields);
        }
        if self.fields == 0 {
            return Err(SetpointRejection::NothingSet);
        }
        if self.sets(SETPOINT_VELOCITY) && !self.sets(SETPOINT_GOAL) {
            return Err(SetpointRejection::VelocityWithoutGoal);
        }
        if self.gain_layout & !GAIN_LAYOUT_KNOWN != 0 {
            return Err(SetpointRejection::UnknownLayout);
        }
        if self.level as usize >= MAX_LEVELS {
            return Err(SetpointRejection::LevelCapacity);
        }
        if self.dim == 0 || self.dim as usize > MAX_TASK_DIM {
            return Err(SetpointRejection::DimensionCapacity);
        }
        let used: [(u32, &[f64]); 4] = [
            (SETPOINT_GOAL, self.goal()),
            (SETPOINT_VELOCITY, self.velocity()),
            (SETPOINT_STIFFNESS, self.stiffness()),
            (SETPOINT_DAMPING, self.damping()),
        ];
        for (bit, values) in used {
            if self.sets(bit) && values.iter().any(|v| !v.is_finite()) {
                return Err(SetpointRejection::NonFinite);
            }
        }
        if !self.duration_s.is_finite() {
            return Err(SetpointRejection::NonFinite);
        }
        if !(0.0..=MAX_TRANSITION_S).contains(&self.duration_s) {
            return Err(SetpointRejection::BadDuration);
        }
        let m = self.dim();
        if self.sets(SETPOINT_STIFFNESS) {
            check_gain_shape(self.stiffness(), self.stiffness_full(), m)?;
        }
        if self.sets(SETPOINT_DAMPING) {
            check_gain_shape(self.damping(), self.damping_full(), m)?;
        }
        Ok(())
    }
}

impl Default for Setpoint {
    fn default() -> Self {
        Self::zeroed()
    }
}

/// Copies `values` (length `dim`) into the front of `dst`, the rest zero.
fn copy_values(dst: &mut [f64], values: &[f64], dim: usize) -> Result<(), SetpointRejection> {
    if dim == 0 || dim > dst.len() || values.len() != dim {
        return Err(if dim == 0 || dim > MAX_TASK_DIM {
            SetpointRejection::DimensionCapacity
        } else {
            SetpointRejection::DimensionMismatch
        });
    }
    dst.fill(0.0);
    dst[..dim].copy_from_slice(values);
    Ok(())
}

/// Copies a diagonal (`dim` values) or full (`dim²`) gain; true if full.
fn copy_gain(dst: &mut [f64], values: &[f64], dim: usize) -> Result<bool, SetpointRejection> {
    if dim == 0 || dim > MAX_TASK_DIM {
        return Err(SetpointRejection::DimensionCapacity);
    }
    let full = values.len() == dim * dim && dim > 1;
    if !full && values.len() != dim {
        return Err(SetpointRejection::DimensionMismatch);
    }
    dst.fill(0.0);
    dst[..values.len()].copy_from_slice(values);
    Ok(full)
}

#[inline]
fn gain_at(values: &[f64], full: bool, m: usize, j: usize, k: usize) -> f64 {
    if full {
        values[j * m + k]
    } else if j == k {
        values[j]
    } else {
        0.0
    }
}

/// Checks the shape of the m×m gain given by `values`: a diagonal's entries
/// positive (it is then positive definite), a full row-major matrix
/// symmetric to [`SYMMETRY_TOLERANCE`] (its positive definiteness is checked
/// by the controller, which factorises it).
fn check_gain_shape(values: &[f64], full: bool, m: usize) -> Result<(), SetpointRejection> {
    if !full {
        return if values.iter().all(|&v| v > 0.0) {
            Ok(())
        } else {
            Err(SetpointRejection::NotPositiveDefinite)
        };
    }
    let scale = values.iter().fold(0.0_f64, |s, v| s.max(v.abs()));
    for j in 0..m {
        for k in 0..j {
            if (values[j * m + k] - values[k * m + j]).abs() > SYMMETRY_TOLERANCE * scale {
                return Err(SetpointRejection::NotSymmetric);
            }
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn goal(level: u32, values: &[f64]) -> Setpoint {
        let mut s = Setpoint::zeroed();
        s.level = level;
        s.fields = SETPOINT_GOAL;
        s.dim = values.len() as u32;
        s.goal[..values.len()].copy_from_slice(values);
        s
    }

    fn full_stiffness(m: usize, a: &[f64]) -> Setpoint {
        let mut s = Setpoint::zeroed();
        s.fields = SETPOINT_STIFFNESS;
        s.gain_layout = GAIN_STIFFNESS_FULL;
        s.dim = m as u32;
        s.stiffness[..m * m].copy_from_slice(a);
        s
    }

    #[test]
    fn codes_are_stable_and_round_trip() {
        for (k, r) in SetpointRejection::ALL.iter().enumerate() {
            assert_eq!(r.code() as usize, k + 1);
            assert_eq!(SetpointRejection::from_code(r.code()), Some(*r));
            assert!(!r.reason().is_empty());
            assert!(r.to_string().contains(r.name()));
        }
        assert_eq!(SetpointRejection::from_code(ANSWER_ACCEPTED), None);
        assert_eq!(SetpointRejection::from_code(19), None);
        assert_eq!(SetpointRejection::from_code(u32::MAX), None);
        // The published numbers (docs and other-language clients rely on them).
        assert_eq!(SetpointRejection::SchemaMismatch.code(), 1);
        assert_eq!(SetpointRejection::NonFinite.code(), 8);
        assert_eq!(SetpointRejection::NotPositiveDefinite.code(), 11);
        assert_eq!(SetpointRejection::OutsideWorkspace.code(), 16);
        assert_eq!(SetpointRejection::PendingFull.code(), 17);
        assert_eq!(SetpointRejection::GainsAboveRate.code(), 18);
        assert_eq!(answer_code(Ok(())), 0);
        assert_eq!(answer_code(Err(SetpointRejection::JointLimit)), 15);
    }

    #[test]
    fn a_plain_goal_is_valid() {
        assert_eq!(goal(1, &[0.4, 0.1, 0.5]).validate(), Ok(()));
        let mut s = goal(0, &[0.1; MAX_TASK_DIM]);
        s.fields |= SETPOINT_VELOCITY;
        s.duration_s = 2.0;
        assert_eq!(s.validate(), Ok(()));
    }

    #[test]
    fn header_fields_and_capacities_are_checked() {
        let mut s = goal(0, &[1.0]);
        s.header.schema_version = CLIENT_SCHEMA_VERSION + 1;
        assert_eq!(s.validate(), Err(SetpointRejection::SchemaMismatch));
        let mut s = goal(0, &[1.0]);
        s.fields |= 1 << 7;
        assert_eq!(s.validate(), Err(SetpointRejection::UnknownFields));
        let mut s = goal(0, &[1.0]);
        s.fields = 0;
        assert_eq!(s.validate(), Err(SetpointRejection::NothingSet));
        let mut s = goal(0, &[1.0]);
        s.fields = SETPOINT_VELOCITY;
        assert_eq!(s.validate(), Err(SetpointRejection::VelocityWithoutGoal));
        let mut s = goal(0, &[1.0]);
        s.gain_layout = 1 << 5;
        assert_eq!(s.validate(), Err(SetpointRejection::UnknownLayout));
        assert_eq!(
            goal(MAX_LEVELS as u32, &[1.0]).validate(),
            Err(SetpointRejection::LevelCapacity)
        );
        assert_eq!(
            goal(0, &[]).validate(),
            Err(SetpointRejection::DimensionCapacity)
        );
        let mut s = goal(0, &[1.0]);
        s.dim = MAX_TASK_DIM as u32 + 1;
        assert_eq!(s.validate(), Err(SetpointRejection::DimensionCapacity));
        s.dim = u32::MAX;
        assert_eq!(s.validate(), Err(SetpointRejection::DimensionCapacity));
        assert_eq!(s.goal().len(), MAX_TASK_DIM, "accessors clamp");
    }

    #[test]
    fn only_used_values_must_be_finite() {
        let mut s = goal(0, &[1.0, f64::NAN]);
        assert_eq!(s.validate(), Err(SetpointRejection::NonFinite));
        s.goal[1] = 0.0;
        s.goal[5] = f64::NAN; // beyond dim: ignored
        s.velocity[0] = f64::INFINITY; // velocity not set: ignored
        s.stiffness[0] = f64::NAN; // stiffness not set: ignored
        assert_eq!(s.validate(), Ok(()));
        s.fields |= SETPOINT_VELOCITY;
        assert_eq!(s.validate(), Err(SetpointRejection::NonFinite));
        let mut s = goal(0, &[1.0]);
        s.duration_s = f64::NAN;
        assert_eq!(s.validate(), Err(SetpointRejection::NonFinite));
        s.duration_s = -0.1;
        assert_eq!(s.validate(), Err(SetpointRejection::BadDuration));
        s.duration_s = MAX_TRANSITION_S * 2.0;
        assert_eq!(s.validate(), Err(SetpointRejection::BadDuration));
        s.duration_s = MAX_TRANSITION_S;
        assert_eq!(s.validate(), Ok(()));
    }

    #[test]
    fn builders_fill_and_size_check() {
        let s = Setpoint::for_level(7, 3, 1, 2)
            .with_goal(&[0.4, 0.5])
            .unwrap()
            .with_velocity(&[0.1, 0.0])
            .unwrap()
            .with_stiffness(&[400.0, 10.0, 10.0, 300.0])
            .unwrap()
            .with_damping(&[30.0, 20.0])
            .unwrap()
            .with_duration(1.5);
        assert_eq!(s.validate(), Ok(()));
        assert_eq!((s.client_id, s.header.seq, s.level), (7, 3, 1));
        assert_eq!(s.fields, SETPOINT_FIELDS_KNOWN);
        assert!(s.stiffness_full() && !s.damping_full());
        assert_eq!(s.stiffness_at(1, 0), 10.0);
        assert_eq!(s.damping_at(1, 1), 20.0);
        assert_eq!(s.duration_s, 1.5);
        // Sizes: wrong lengths and dimensions are the contract's codes.
        let base = Setpoint::for_level(1, 1, 0, 3);
        assert_eq!(
            base.with_goal(&[1.0]).unwrap_err(),
            SetpointRejection::DimensionMismatch
        );
        assert_eq!(
            base.with_stiffness(&[1.0; 4]).unwrap_err(),
            SetpointRejection::DimensionMismatch
        );
        assert_eq!(
            Setpoint::for_level(1, 1, 0, 0).with_goal(&[]).unwrap_err(),
            SetpointRejection::DimensionCapacity
        );
        assert_eq!(
            Setpoint::for_level(1, 1, 0, 33)
                .with_damping(&[1.0; 33])
                .unwrap_err(),
            SetpointRejection::DimensionCapacity
        );
        // Too many levels is left for validate to name.
        let far = Setpoint::for_level(1, 1, 99, 1).with_goal(&[0.0]).unwrap();
        assert_eq!(far.validate(), Err(SetpointRejection::LevelCapacity));
    }

    #[test]
    fn diagonal_gains_must_be_positive() {
        let mut s = Setpoint::zeroed();
        s.fields = SETPOINT_STIFFNESS | SETPOINT_DAMPING;
        s.dim = 3;
        s.stiffness[..3].copy_from_slice(&[500.0, 500.0, 200.0]);
        s.damping[..3].copy_from_slice(&[40.0, 40.0, 20.0]);
        assert_eq!(s.validate(), Ok(()));
        assert_eq!(s.stiffness_at(2, 2), 200.0);
        assert_eq!(s.stiffness_at(0, 2), 0.0);
        s.damping[1] = 0.0;
        assert_eq!(s.validate(), Err(SetpointRejection::NotPositiveDefinite));
        s.damping[1] = 40.0;
        s.stiffness[0] = -1.0;
        assert_eq!(s.validate(), Err(SetpointRejection::NotPositiveDefinite));
    }

    #[test]
    fn full_gains_must_be_symmetric() {
        let s = full_stiffness(2, &[4.0, 1.0, 1.0, 3.0]);
        assert_eq!(s.validate(), Ok(()));
        assert_eq!(s.stiffness_at(0, 1), 1.0);
        assert_eq!(s.stiffness().len(), 4);
        // Not symmetric.
        let s = full_stiffness(2, &[4.0, 1.0, 0.0, 3.0]);
        assert_eq!(s.validate(), Err(SetpointRejection::NotSymmetric));
        // Rounding-level asymmetry is forgiven.
        let s = full_stiffness(2, &[4.0, 1.0, 1.0 + 1e-12, 3.0]);
        assert_eq!(s.validate(), Ok(()));
        // Symmetric and indefinite: the shape is right; the controller's
        // factorisation rejects it (hcc-cycle).
        let s = full_stiffness(2, &[1.0, 2.0, 2.0, 1.0]);
        assert_eq!(s.validate(), Ok(()));
    }
}
