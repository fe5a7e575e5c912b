//! The [`LoadSetpoint`] message: a client tells the controller what the
//! robot's hand holds from now on (docs/load.md) — a gripped part, a tool, a
//! camera — so that the controller's model (gravity, inertia, the contact
//! observer) follows it. Published on `hcc/<ns>/load`
//! ([`crate::ServiceNames::load`]) and answered in the client's answer slot
//! like a setpoint (the client numbers both together).
//!
//! The load is held rigidly at the tip frame: its mass (kg), its centre of
//! mass in the tip frame (m) and its rotational inertia about the centre of
//! mass in the tip frame's axes (kg·m², as a URDF gives it: ixx, ixy, ixz,
//! iyy, iyz, izz). The controller's model ramps to it over
//! [`LoadSetpoint::ramp_s`] (0: [`DEFAULT_LOAD_RAMP_S`]); it replaces the load
//! before (a zero mass: the hand holds nothing). [`LoadSetpoint::validate`]
//! checks what needs no model; the controller checks the physics and the
//! payload limit ([`LoadRejection`]).

use iceoryx2::prelude::ZeroCopySend;

use crate::CLIENT_SCHEMA_VERSION;
use crate::setpoint::{MAX_TRANSITION_S, SetpointRejection};
use crate::types::Header;

/// The ramp of a load whose message gives none, s.
pub const DEFAULT_LOAD_RAMP_S: f64 = 0.2;

/// Why the controller refused a load (codes from 301, apart from
/// [`SetpointRejection`]'s and the paths', with which they share the answer
/// slots).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[repr(u32)]
pub enum LoadRejection {
    /// The mass is negative.
    NegativeMass = 301,
    /// The mass is above the robot's payload limit (`[robot] payload_kg`).
    AbovePayload = 302,
    /// The inertia is not a physical one (not positive semidefinite, or a
    /// principal moment above the sum of the other two).
    NotPhysical = 303,
    /// The ramp is negative or above [`MAX_TRANSITION_S`].
    BadRamp = 304,
}

impl LoadRejection {
    /// Every rejection, in code order.
    pub const ALL: [LoadRejection; 4] = [
        Self::NegativeMass,
        Self::AbovePayload,
        Self::NotPhysical,
        Self::BadRamp,
    ];

    /// The stable code.
    pub const fn code(self) -> u32 {
        self as u32
    }

    /// Decodes a code; `None` for codes that are not a load's.
    pub const fn from_code(code: u32) -> Option<Self> {
        if code < 301 || code as usize > 300 + Self::ALL.len() {
            None
        } else {
            Some(Self::ALL[code as usize - 301])
        }
    }

    /// A short machine-friendly name (`snake_case`).
    pub const fn name(self) -> &'static str {
        match self {
            Self::NegativeMass => "negative_mass",
            Self::AbovePayload => "above_payload",
            Self::NotPhysical => "not_physical",
            Self::BadRamp => "bad_ramp",
        }
    }

    /// The reason in plain words.
    pub const fn reason(self) -> &'static str {
        match self {
            Self::NegativeMass => "the load's mass is negative",
            Self::AbovePayload => "the load is heavier than the robot's payload limit",
            Self::NotPhysical => {
                "the load's inertia is not a physical one (positive semidefinite, triangle inequalities)"
            }
            Self::BadRamp => "the ramp is negative or too long",
        }
    }
}

impl std::fmt::Display for LoadRejection {
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

impl std::error::Error for LoadRejection {}

/// Why a load message was refused: a reason it shares with a setpoint
/// (schema, non-finite values), or the load's own.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum LoadRefusal {
    Setpoint(SetpointRejection),
    Load(LoadRejection),
}

impl LoadRefusal {
    /// The answer code.
    pub const fn code(self) -> u32 {
        match self {
            Self::Setpoint(r) => r.code(),
            Self::Load(r) => r.code(),
        }
    }
}

impl From<SetpointRejection> for LoadRefusal {
    fn from(r: SetpointRejection) -> Self {
        Self::Setpoint(r)
    }
}

impl From<LoadRejection> for LoadRefusal {
    fn from(r: LoadRejection) -> Self {
        Self::Load(r)
    }
}

impl std::fmt::Display for LoadRefusal {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Self::Setpoint(r) => r.fmt(f),
            Self::Load(r) => r.fmt(f),
        }
    }
}

impl std::error::Error for LoadRefusal {}

/// The load the robot's hand holds from now on (module docs).
#[derive(Debug, Clone, Copy, PartialEq, ZeroCopySend)]
#[type_name("hcc_msgs::LoadSetpoint@client8")]
#[repr(C)]
pub struct LoadSetpoint {
    /// `seq`: the client's sequence number; `stamp_ns`: send time.
    pub header: Header,
    /// The client's identity (as a setpoint's).
    pub client_id: u64,
    /// kg, ≥ 0.
    pub mass: f64,
    /// Centre of mass in the tip frame, m.
    pub com: [f64; 3],
    /// Rotational inertia about the centre of mass, tip axes, kg·m²: ixx,
    /// ixy, ixz, iyy, iyz, izz.
    pub inertia: [f64; 6],
    /// How long the controller's model takes to reach it, s (0:
    /// [`DEFAULT_LOAD_RAMP_S`]).
    pub ramp_s: f64,
}

impl LoadSetpoint {
    /// An empty message of the current schema (no load).
    pub const fn zeroed() -> Self {
        Self {
            header: Header::client(),
            client_id: 0,
            mass: 0.0,
            com: [0.0; 3],
            inertia: [0.0; 6],
            ramp_s: 0.0,
        }
    }

    /// A point mass `mass` at `com` for client `client_id`, its `seq`.
    pub fn point(client_id: u64, seq: u64, mass: f64, com: [f64; 3]) -> Self {
        let mut l = Self::zeroed();
        l.client_id = client_id;
        l.header.seq = seq;
        l.mass = mass;
        l.com = com;
        l
    }

    /// The ramp the controller uses, s.
    pub fn ramp(&self) -> f64 {
        if self.ramp_s > 0.0 {
            self.ramp_s
        } else {
            DEFAULT_LOAD_RAMP_S
        }
    }

    /// What needs no model: the schema, finite values, a mass ≥ 0, a ramp
    /// from 0 to [`MAX_TRANSITION_S`]. Allocation-free.
    pub fn validate(&self) -> Result<(), LoadRefusal> {
        if self.header.schema_version != CLIENT_SCHEMA_VERSION {
            return Err(SetpointRejection::SchemaMismatch.into());
        }
        let values = [self.mass, self.ramp_s]
            .into_iter()
            .chain(self.com)
            .chain(self.inertia);
        if values.into_iter().any(|x| !x.is_finite()) {
            return Err(SetpointRejection::NonFinite.into());
        }
        if self.mass < 0.0 {
            return Err(LoadRejection::NegativeMass.into());
        }
        if !(0.0..=MAX_TRANSITION_S).contains(&self.ramp_s) {
            return Err(LoadRejection::BadRamp.into());
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn codes_round_trip_and_a_message_is_checked() {
        for r in LoadRejection::ALL {
            assert_eq!(LoadRejection::from_code(r.code()), Some(r));
        }
        assert_eq!(LoadRejection::from_code(300), None);
        assert_eq!(LoadRejection::from_code(305), None);
        let ok = LoadSetpoint::point(3, 1, 1.0, [0.0, 0.0, 0.1]);
        assert_eq!(ok.validate(), Ok(()));
        assert_eq!(ok.ramp(), DEFAULT_LOAD_RAMP_S);
        let with = |f: &dyn Fn(&mut LoadSetpoint)| {
            let mut l = ok;
            f(&mut l);
            l.validate().map_err(LoadRefusal::code)
        };
        assert_eq!(with(&|l| l.mass = -1.0), Err(301));
        assert_eq!(with(&|l| l.ramp_s = -0.1), Err(304));
        assert_eq!(with(&|l| l.inertia[2] = f64::NAN), Err(8));
        assert_eq!(with(&|l| l.header.schema_version += 1), Err(1));
    }
}
