//! The contact detection's settings (`[contact]`, read by `hcc-config`,
//! used by the control cycle): the momentum observer's gains, the detection
//! threshold and its release, and what a contact does to the torque. The
//! equations and the reasons for the defaults are in `hcc_config::contact`.

use nalgebra::DVector;
use serde::Deserialize;

/// Default K_O, 1/s (`hcc_config::contact`).
pub const DEFAULT_OBSERVER_GAIN: f64 = 100.0;
/// Default detection threshold on |r_j|, N·m (`hcc_config::contact`).
pub const DEFAULT_THRESHOLD: f64 = 2.0;
/// Default release fraction of the threshold (`hcc_config::contact`).
pub const DEFAULT_RELEASE: f64 = 0.5;
/// Default stiffness fraction of `soften` (`hcc_config::contact`).
pub const DEFAULT_SOFTEN_FRACTION: f64 = 0.2;
/// Default time of a reaction's ramp, s (`hcc_config::contact`).
pub const DEFAULT_RAMP_S: f64 = 0.1;
/// Default joint damping of `hold`, N·m·s/rad (`hcc_config::contact`).
pub const DEFAULT_HOLD_DAMPING: f64 = 1.0;
/// What a contact does to the torque (`hcc_config::contact`).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Reaction {
    /// Nothing: the flag and the estimate are reported only.
    #[default]
    Report,
    /// The levels' stiffness ramped down while in contact, back after.
    Soften,
    /// Gravity and joint damping until a client's setpoint is accepted.
    Hold,
}

/// Resolved `[contact]`.
#[derive(Clone, Debug, PartialEq)]
pub struct Contact {
    /// K_O per joint, 1/s (positive, at most the control rate).
    pub observer_gain: DVector<f64>,
    /// Detection threshold on |r_j| per joint, N·m (positive).
    pub threshold: DVector<f64>,
    /// Contact is cleared when every |r_j| < release × threshold_j; in (0, 1].
    pub release: f64,
    /// What a contact does to the torque.
    pub reaction: Reaction,
    /// `soften`: the stiffness fraction κ in contact, in (0, 1].
    pub soften_fraction: f64,
    /// `soften`, `hold`: the time of a full ramp, s (positive, finite).
    pub ramp_s: f64,
    /// `hold`: the joint damping D_h per joint, N·m·s/rad (positive).
    pub hold_damping: DVector<f64>,
}

impl Contact {
    /// The defaults for `n` joints.
    pub fn defaults(n: usize) -> Contact {
        Contact {
            observer_gain: DVector::from_element(n, DEFAULT_OBSERVER_GAIN),
            threshold: DVector::from_element(n, DEFAULT_THRESHOLD),
            release: DEFAULT_RELEASE,
            reaction: Reaction::Report,
            soften_fraction: DEFAULT_SOFTEN_FRACTION,
            ramp_s: DEFAULT_RAMP_S,
            hold_damping: DVector::from_element(n, DEFAULT_HOLD_DAMPING),
        }
    }
}
