//! The [`PathKnots`] message: a client sends a level a path while the
//! controller runs (docs/tracking.md, "Paths at run time").
//!
//! A path is a sequence of knots (t, values) in the columns of a scenario's
//! path file (`hcc_trajectory`): a position's x y z (m), an orientation's unit
//! quaternion w x y z, a pose's x y z w x y z, a joint level's values (rad).
//! t is the path's own time in s, from 0 at the knot the path starts with.
//! One message carries up to [`MAX_KNOTS_PER_MESSAGE`] knots: a path
//! ([`PATH_NEW`]) begins with the first message and is extended by further
//! messages ([`PATH_EXTEND`]) while it runs, their knots later than every
//! knot before. The controller interpolates C² from local data (a knot's
//! derivatives from its neighbours), so a path streamed knot by knot keeps
//! two knots ahead of where it is; a path that runs out of knots stops on its
//! last knot, at rest, and is over.
//!
//! **Samples.** With [`PATH_DERIVATIVES`] the knots carry their velocity and
//! acceleration ([`PathKnots::velocity`], [`PathKnots::acceleration`]) in
//! the level's goal-velocity coordinates (a vector's rates; an
//! orientation's angular velocity and acceleration in the base frame, 3
//! entries for its 4 columns): a teleoperation device's or a policy's
//! samples, at up to the control rate. The controller interpolates between
//! them with exactly these derivatives, and a stream of samples needs only
//! one sample ahead of where the path is.
//!
//! [`PathKnots::validate`] checks what needs no model: schema, bits, the
//! capacities, finite values, t from ≥ 0 strictly increasing. The controller
//! checks the rest against the level (its columns, joint limits, the
//! workspace, unit quaternions, where the path starts) and answers in the
//! client's answer slot like a setpoint ([`crate::SetpointAnswer`]), with
//! [`crate::ANSWER_ACCEPTED`], a [`crate::SetpointRejection`] code for what the two
//! share, or a [`PathRejection`] code (from 201), and the knot refused
//! ([`crate::SetpointAnswer::knot`], a [`KnotsRefusal`]'s). Nothing here
//! allocates.

use iceoryx2::prelude::ZeroCopySend;

use crate::setpoint::SetpointRejection;
use crate::types::Header;
use crate::{CLIENT_SCHEMA_VERSION, MAX_LEVELS, MAX_TASK_DIM};

/// Knots one [`PathKnots`] message carries at most.
pub const MAX_KNOTS_PER_MESSAGE: usize = 16;

/// Columns of one knot at most (a level of [`MAX_TASK_DIM`] coordinates
/// without orientations).
pub const MAX_PATH_COLUMNS: usize = MAX_TASK_DIM;

/// [`PathKnots::flags`] bit: the knots begin a new path (the level's running
/// path, if any, is replaced from where it is).
pub const PATH_NEW: u32 = 1 << 0;
/// [`PathKnots::flags`] bit: the knots extend the level's running path.
pub const PATH_EXTEND: u32 = 1 << 1;
/// [`PathKnots::flags`] bit, with [`PATH_NEW`] or [`PATH_EXTEND`]: the knots
/// carry their velocity and acceleration (module docs, "Samples").
pub const PATH_DERIVATIVES: u32 = 1 << 2;
/// All [`PathKnots::flags`] bits defined by this schema.
pub const PATH_FLAGS_KNOWN: u32 = PATH_NEW | PATH_EXTEND | PATH_DERIVATIVES;

/// Why the controller refused a path's knots (codes from 201, apart from
/// [`SetpointRejection`]'s, with which they share the answer slots, and from
/// the bridge's own refusals, 100–103). A refused
/// message changes nothing. The codes are stable.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
#[repr(u32)]
pub enum PathRejection {
    /// `flags` is neither [`PATH_NEW`] nor [`PATH_EXTEND`] alone (with
    /// [`PATH_DERIVATIVES`] or without).
    BadFlags = 201,
    /// `count` is 0 or above [`MAX_KNOTS_PER_MESSAGE`].
    KnotCount = 202,
    /// The knots' times are negative, do not increase, or do not come after
    /// the running path's last knot.
    NotIncreasing = 203,
    /// `columns` is not the level's (its values, 4 per orientation).
    ColumnMismatch = 204,
    /// An orientation's columns are not a unit quaternion w x y z.
    NotUnitQuaternion = 205,
    /// An orientation turns more than 0.9π from the path's first knot.
    TurnTooFar = 206,
    /// [`PATH_EXTEND`] with no path running on the level.
    NoPath = 207,
    /// The running path has stopped (it ran out of knots): send a new path.
    PathEnded = 208,
    /// The level's path holds as many knots ahead as it can
    /// (`[setpoint_limits] path_knots`).
    PathFull = 209,
    /// A new path's first knot is farther from the level's equilibrium than
    /// a path may start (5 cm, 0.2 rad).
    StartsAway = 210,
    /// The path moves faster than the level's `max_speed` between a knot and
    /// the one before (√(|Δp|² + θ²) / Δt, as a transition's), or a sample's
    /// own velocity does.
    TooFast = 211,
    /// The hierarchy cannot follow the path from where the arm is: the
    /// feasibility check's rollout finds the stacked Jacobian singular at a
    /// knot's segment, or the level falling behind its path (out of reach,
    /// or blocked by the levels above). Once a message is refused for this,
    /// the path takes no more extensions: send a new path.
    Infeasible = 212,
    /// The feasibility check did not answer in time (`[setpoint_limits]
    /// path_check_timeout_ms`), or its queue was full: nothing was taken.
    Unchecked = 213,
}

impl PathRejection {
    /// Every rejection, in code order.
    pub const ALL: [PathRejection; 13] = [
        Self::BadFlags,
        Self::KnotCount,
        Self::NotIncreasing,
        Self::ColumnMismatch,
        Self::NotUnitQuaternion,
        Self::TurnTooFar,
        Self::NoPath,
        Self::PathEnded,
        Self::PathFull,
        Self::StartsAway,
        Self::TooFast,
        Self::Infeasible,
        Self::Unchecked,
    ];

    /// The stable code.
    pub const fn code(self) -> u32 {
        self as u32
    }

    /// Decodes a code; `None` for codes that are not a path's.
    pub const fn from_code(code: u32) -> Option<Self> {
        if code < 201 || code as usize > 200 + Self::ALL.len() {
            None
        } else {
            Some(Self::ALL[code as usize - 201])
        }
    }

    /// A short machine-friendly name (`snake_case`).
    pub const fn name(self) -> &'static str {
        match self {
            Self::BadFlags => "bad_flags",
            Self::KnotCount => "knot_count",
            Self::NotIncreasing => "not_increasing",
            Self::ColumnMismatch => "column_mismatch",
            Self::NotUnitQuaternion => "not_unit_quaternion",
            Self::TurnTooFar => "turn_too_far",
            Self::NoPath => "no_path",
            Self::PathEnded => "path_ended",
            Self::PathFull => "path_full",
            Self::StartsAway => "starts_away",
            Self::TooFast => "too_fast",
            Self::Infeasible => "infeasible",
            Self::Unchecked => "unchecked",
        }
    }

    /// The reason in plain words.
    pub const fn reason(self) -> &'static str {
        match self {
            Self::BadFlags => "the message must either begin a path or extend one",
            Self::KnotCount => "the message holds no knot or more than it can",
            Self::NotIncreasing => {
                "the knots' times are negative or do not increase past the path's last knot"
            }
            Self::ColumnMismatch => "the knots have a number of columns the level does not have",
            Self::NotUnitQuaternion => "an orientation is not a unit quaternion w x y z",
            Self::TurnTooFar => "an orientation turns more than 0.9π from the path's first",
            Self::NoPath => "there is no path running on the level to extend",
            Self::PathEnded => "the path ran out of knots and stopped: send a new path",
            Self::PathFull => "the level's path holds as many knots ahead as it can",
            Self::StartsAway => "the path's first knot is too far from the level's equilibrium",
            Self::TooFast => "the path moves faster than the level's max_speed",
            Self::Infeasible => {
                "the hierarchy cannot follow the path from where the arm is (singular, or out of reach)"
            }
            Self::Unchecked => "the feasibility check did not answer in time: nothing was taken",
        }
    }
}

impl std::fmt::Display for PathRejection {
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

impl std::error::Error for PathRejection {}

/// Why a path's knots were refused: a reason the two messages share, or the
/// path's own.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum KnotsRejection {
    /// A reason a setpoint has as well (schema, level, values, joint limits,
    /// workspace, the pending queue).
    Setpoint(SetpointRejection),
    /// The path's own.
    Path(PathRejection),
}

impl KnotsRejection {
    /// The answer code.
    pub const fn code(self) -> u32 {
        match self {
            Self::Setpoint(r) => r.code(),
            Self::Path(r) => r.code(),
        }
    }
}

impl std::fmt::Display for KnotsRejection {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Self::Setpoint(r) => r.fmt(f),
            Self::Path(r) => r.fmt(f),
        }
    }
}

impl From<SetpointRejection> for KnotsRejection {
    fn from(r: SetpointRejection) -> Self {
        Self::Setpoint(r)
    }
}

impl From<PathRejection> for KnotsRejection {
    fn from(r: PathRejection) -> Self {
        Self::Path(r)
    }
}

/// A refused path message: why, and the knot it was refused for (0-based
/// in the message) when the reason is one knot's.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct KnotsRefusal {
    /// Why.
    pub rejection: KnotsRejection,
    /// The knot, 0-based in the message (`None`: the message as a whole).
    pub knot: Option<usize>,
}

impl KnotsRefusal {
    /// A refusal of knot `knot`.
    pub fn at(rejection: impl Into<KnotsRejection>, knot: usize) -> Self {
        Self {
            rejection: rejection.into(),
            knot: Some(knot),
        }
    }

    /// The answer code.
    pub const fn code(&self) -> u32 {
        self.rejection.code()
    }

    /// The knot as [`crate::SetpointAnswer::knot`] carries it.
    pub fn knot_field(&self) -> u32 {
        self.knot.map_or(crate::NO_KNOT, |k| k as u32)
    }
}

impl<R: Into<KnotsRejection>> From<R> for KnotsRefusal {
    fn from(r: R) -> Self {
        Self {
            rejection: r.into(),
            knot: None,
        }
    }
}

impl std::fmt::Display for KnotsRefusal {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self.knot {
            Some(k) => write!(f, "knot {k}: {}", self.rejection),
            None => self.rejection.fmt(f),
        }
    }
}

impl std::error::Error for KnotsRefusal {}

/// Up to [`MAX_KNOTS_PER_MESSAGE`] knots of one level's path, published by a
/// client on `hcc/<ns>/path` (see [`crate::ServiceNames::path`]). `header.seq`
/// is the client's sequence number (shared with its setpoints: the answer
/// slot is the client's), `apply_at_state_seq` as a setpoint's: a new path's
/// t = 0 is the cycle of that state (0: on receipt).
#[derive(Debug, Clone, Copy, PartialEq, ZeroCopySend)]
#[type_name("hcc_msgs::PathKnots@client8")]
#[repr(C)]
pub struct PathKnots {
    /// `seq`: the client's sequence number; `stamp_ns`: send time.
    pub header: Header,
    /// The client's identity (as a setpoint's).
    pub client_id: u64,
    /// Target level, 0-based.
    pub level: u32,
    /// [`PATH_NEW`] or [`PATH_EXTEND`].
    pub flags: u32,
    /// Columns per knot (the level's values, 4 per orientation).
    pub columns: u32,
    /// Knots in this message.
    pub count: u32,
    /// A new path starts in the cycle of the first joint state with a
    /// sequence number ≥ this (0: on receipt).
    pub apply_at_state_seq: u64,
    /// The knots' times (s, the path's own time), first `count`.
    pub t: [f64; MAX_KNOTS_PER_MESSAGE],
    /// The knots' values, first `count` rows of `columns` entries.
    pub values: [[f64; MAX_PATH_COLUMNS]; MAX_KNOTS_PER_MESSAGE],
    /// With [`PATH_DERIVATIVES`]: the knots' velocities, first `count` rows
    /// of the level's dimension (module docs, "Samples"); zero otherwise.
    /// Client schema 7.
    pub velocity: [[f64; MAX_TASK_DIM]; MAX_KNOTS_PER_MESSAGE],
    /// With [`PATH_DERIVATIVES`]: the knots' accelerations, as `velocity`.
    pub acceleration: [[f64; MAX_TASK_DIM]; MAX_KNOTS_PER_MESSAGE],
}

impl PathKnots {
    /// An empty message of the current schema.
    pub const fn zeroed() -> Self {
        Self {
            header: Header::client(),
            client_id: 0,
            level: 0,
            flags: 0,
            columns: 0,
            count: 0,
            apply_at_state_seq: 0,
            t: [0.0; MAX_KNOTS_PER_MESSAGE],
            values: [[0.0; MAX_PATH_COLUMNS]; MAX_KNOTS_PER_MESSAGE],
            velocity: [[0.0; MAX_TASK_DIM]; MAX_KNOTS_PER_MESSAGE],
            acceleration: [[0.0; MAX_TASK_DIM]; MAX_KNOTS_PER_MESSAGE],
        }
    }

    /// Whether the knots carry their derivatives ([`PATH_DERIVATIVES`]).
    pub fn has_derivatives(&self) -> bool {
        self.flags & PATH_DERIVATIVES != 0
    }

    /// Whether the message begins a new path ([`PATH_NEW`]).
    pub fn is_new(&self) -> bool {
        self.flags & !PATH_DERIVATIVES == PATH_NEW
    }

    /// `count` clamped to the capacity.
    pub fn count(&self) -> usize {
        (self.count as usize).min(MAX_KNOTS_PER_MESSAGE)
    }

    /// `columns` clamped to the capacity.
    pub fn columns(&self) -> usize {
        (self.columns as usize).min(MAX_PATH_COLUMNS)
    }

    /// Knot `k`'s time and values.
    pub fn knot(&self, k: usize) -> (f64, &[f64]) {
        (self.t[k], &self.values[k][..self.columns()])
    }

    /// Appends a knot; an error when the message is full or the values do
    /// not fit its columns (set `columns` first, or by the first knot).
    pub fn push(&mut self, t: f64, values: &[f64]) -> Result<(), PathRejection> {
        let k = self.count();
        if k == MAX_KNOTS_PER_MESSAGE {
            return Err(PathRejection::KnotCount);
        }
        if self.columns == 0 {
            self.columns = values.len().min(MAX_PATH_COLUMNS) as u32;
        }
        if values.len() != self.columns() {
            return Err(PathRejection::ColumnMismatch);
        }
        self.t[k] = t;
        self.values[k][..values.len()].copy_from_slice(values);
        self.count += 1;
        Ok(())
    }

    /// Appends a sample: a knot with its velocity and acceleration (`dim`
    /// entries each, the level's dimension) and sets [`PATH_DERIVATIVES`].
    pub fn push_sample(
        &mut self,
        t: f64,
        values: &[f64],
        velocity: &[f64],
        acceleration: &[f64],
    ) -> Result<(), PathRejection> {
        let k = self.count();
        if velocity.len() != acceleration.len()
            || velocity.len() > values.len()
            || velocity.len() > MAX_TASK_DIM
        {
            return Err(PathRejection::ColumnMismatch);
        }
        self.push(t, values)?;
        self.flags |= PATH_DERIVATIVES;
        self.velocity[k][..velocity.len()].copy_from_slice(velocity);
        self.acceleration[k][..acceleration.len()].copy_from_slice(acceleration);
        Ok(())
    }

    /// Knot `k`'s velocity and acceleration, `dim` entries each (zero
    /// without [`PATH_DERIVATIVES`]).
    pub fn derivatives(&self, k: usize, dim: usize) -> (&[f64], &[f64]) {
        let dim = dim.min(MAX_TASK_DIM);
        (&self.velocity[k][..dim], &self.acceleration[k][..dim])
    }

    /// The checks that need no model (module docs); a refusal names the
    /// knot when it is one knot's.
    pub fn validate(&self) -> Result<(), KnotsRefusal> {
        if self.header.schema_version != CLIENT_SCHEMA_VERSION {
            return Err(SetpointRejection::SchemaMismatch.into());
        }
        let base = self.flags & !PATH_DERIVATIVES;
        if base != PATH_NEW && base != PATH_EXTEND {
            return Err(PathRejection::BadFlags.into());
        }
        if self.level as usize >= MAX_LEVELS {
            return Err(SetpointRejection::LevelCapacity.into());
        }
        if self.columns == 0 || self.columns as usize > MAX_PATH_COLUMNS {
            return Err(PathRejection::ColumnMismatch.into());
        }
        if self.count == 0 || self.count as usize > MAX_KNOTS_PER_MESSAGE {
            return Err(PathRejection::KnotCount.into());
        }
        // A level's dimension is at most its columns.
        let dim = self.columns().min(MAX_TASK_DIM);
        for k in 0..self.count() {
            let (t, v) = self.knot(k);
            let (vel, acc) = self.derivatives(k, dim);
            if !t.is_finite() || v.iter().chain(vel).chain(acc).any(|x| !x.is_finite()) {
                return Err(KnotsRefusal::at(SetpointRejection::NonFinite, k));
            }
            if t < 0.0 || (k > 0 && t <= self.t[k - 1]) {
                return Err(KnotsRefusal::at(PathRejection::NotIncreasing, k));
            }
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn knots() -> PathKnots {
        let mut p = PathKnots::zeroed();
        p.flags = PATH_NEW;
        p.level = 1;
        for k in 0..4 {
            p.push(k as f64 * 0.1, &[0.4, 0.01 * k as f64, 0.3])
                .unwrap();
        }
        p
    }

    #[test]
    fn a_well_formed_message_passes_and_each_fault_has_its_code() {
        assert_eq!(knots().validate(), Ok(()));
        type Edit<'a> = &'a dyn Fn(&mut PathKnots);
        let cases: [(Edit, u32); 7] = [
            (&|p| p.header.schema_version += 1, 1),
            (&|p| p.flags = PATH_NEW | PATH_EXTEND, 201),
            (&|p| p.level = MAX_LEVELS as u32, 6),
            (&|p| p.count = 0, 202),
            (&|p| p.values[2][1] = f64::NAN, 8),
            (&|p| p.t[2] = p.t[1], 203),
            (&|p| p.columns = 0, 204),
        ];
        for (edit, code) in cases {
            let mut p = knots();
            edit(&mut p);
            assert_eq!(p.validate().unwrap_err().code(), code);
        }
        let mut p = knots();
        p.t[0] = -0.1;
        assert_eq!(
            p.validate().unwrap_err(),
            KnotsRefusal::at(PathRejection::NotIncreasing, 0)
        );
        // The knot a refusal is about.
        let mut p = knots();
        p.t[2] = p.t[1];
        assert_eq!(p.validate().unwrap_err().knot, Some(2));
        assert_eq!(p.validate().unwrap_err().knot_field(), 2);
        let mut p = knots();
        p.count = 0;
        assert_eq!(p.validate().unwrap_err().knot_field(), crate::NO_KNOT);
    }

    #[test]
    fn samples_carry_finite_derivatives_and_either_base_flag() {
        let mut p = PathKnots::zeroed();
        p.flags = PATH_NEW;
        p.push_sample(0.0, &[0.4, 0.0, 0.3], &[0.1, 0.0, 0.0], &[0.0; 3])
            .unwrap();
        p.push_sample(
            0.001,
            &[0.4001, 0.0, 0.3],
            &[0.1, 0.0, 0.0],
            &[1.0, 0.0, 0.0],
        )
        .unwrap();
        assert!(p.has_derivatives() && p.is_new());
        assert_eq!(p.validate(), Ok(()));
        assert_eq!(
            p.derivatives(1, 3),
            (&[0.1, 0.0, 0.0][..], &[1.0, 0.0, 0.0][..])
        );
        p.flags = PATH_EXTEND | PATH_DERIVATIVES;
        assert!(!p.is_new());
        assert_eq!(p.validate(), Ok(()));
        p.acceleration[1][2] = f64::INFINITY;
        assert_eq!(
            p.validate(),
            Err(KnotsRefusal::at(SetpointRejection::NonFinite, 1))
        );
        assert_eq!(
            p.push_sample(0.002, &[0.4, 0.0, 0.3], &[0.0; 4], &[0.0; 4]),
            Err(PathRejection::ColumnMismatch)
        );
        p.flags = PATH_NEW | PATH_EXTEND | PATH_DERIVATIVES;
        assert_eq!(p.validate().unwrap_err().code(), 201);
    }

    #[test]
    fn codes_round_trip_and_push_keeps_to_the_capacity() {
        for r in PathRejection::ALL {
            assert_eq!(PathRejection::from_code(r.code()), Some(r));
        }
        assert_eq!(PathRejection::from_code(200), None);
        assert_eq!(PathRejection::from_code(214), None);
        let mut p = knots();
        assert_eq!(p.push(1.0, &[0.0; 2]), Err(PathRejection::ColumnMismatch));
        for k in 4..MAX_KNOTS_PER_MESSAGE {
            p.push(k as f64, &[0.0; 3]).unwrap();
        }
        assert_eq!(p.push(99.0, &[0.0; 3]), Err(PathRejection::KnotCount));
        assert_eq!(p.knot(3), (0.30000000000000004, &[0.4, 0.03, 0.3][..]));
    }
}
