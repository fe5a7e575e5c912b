//! `[contact]`: the external-torque observer and the contact detection.
//!
//! ```toml
//! [contact]
//! observer_gain = 100.0   # K_O, 1/s: scalar or one per joint
//! threshold = 2.0         # N·m: contact when some |r_j| exceeds it (scalar or per joint)
//! release = 0.5           # contact cleared when every |r_j| is below release × threshold
//! ```
//!
//! Every field is optional; a scenario without `[contact]` runs the observer
//! with the defaults below (the observer only observes: it never changes the
//! torque). The estimate r of the external joint torque follows
//! ṙ = K_O (τ_ext − r) (the generalized-momentum observer of De Luca & Mattone,
//! ICRA 2005; `hcc_control::contact`).
//!
//! **Defaults.** K_O = 100 /s: a time constant of 10 ms, ten control periods at
//! 1 kHz (K_O T = 0.1, far from the sampling limit), so that a push is seen
//! within a few ms and the estimate decays below the release level within
//! about 25 ms of the push's end (ln(peak/release level)/K_O); a larger K_O
//! passes more velocity noise (r's noise grows with K_O) on a real robot.
//! Threshold 2 N·m, release 0.5: 15 N at the Panda's TCP (|Jᵀ F| up to
//! 8.3 N·m) is flagged 3 ms after it starts and cleared 22 ms after it ends,
//! while in free motion of the shipped scenarios |r| stays below 0.007 N·m
//! with the exact model (docs/contact.md). A real arm's model errors
//! (payload, friction, calibration) are far larger than the simulation's:
//! tune the threshold from the |r| the arm shows in free motion.

use hcc_model::Model;
use nalgebra::DVector;
use serde::Deserialize;

use crate::context::Ctx;
use crate::error::ConfigError;
use crate::schema::PerJoint;

/// Default K_O, 1/s (module docs).
pub const DEFAULT_OBSERVER_GAIN: f64 = 100.0;
/// Default detection threshold on |r_j|, N·m (module docs).
pub const DEFAULT_THRESHOLD: f64 = 2.0;
/// Default release fraction of the threshold (module docs).
pub const DEFAULT_RELEASE: f64 = 0.5;

/// `[contact]` as written.
#[derive(Clone, Debug, Default, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ContactSection {
    pub observer_gain: Option<PerJoint>,
    pub threshold: Option<PerJoint>,
    pub release: Option<f64>,
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
}

impl Contact {
    /// The defaults for `n` joints.
    pub fn defaults(n: usize) -> Contact {
        Contact {
            observer_gain: DVector::from_element(n, DEFAULT_OBSERVER_GAIN),
            threshold: DVector::from_element(n, DEFAULT_THRESHOLD),
            release: DEFAULT_RELEASE,
        }
    }
}

/// Checks `[contact]` against the model's joint count and the control rate.
pub(crate) fn resolve(
    cx: &Ctx,
    model: &Model,
    s: &ContactSection,
    control_rate_hz: f64,
) -> Result<Contact, ConfigError> {
    let n = model.nq();
    let mut c = Contact::defaults(n);
    let positive = |path: &str, v: &DVector<f64>| -> Result<(), ConfigError> {
        match v.iter().position(|x| *x <= 0.0) {
            Some(k) => Err(cx.err(path, format!("[{k}] must be positive, got {}", v[k]))),
            None => Ok(()),
        }
    };
    if let Some(g) = &s.observer_gain {
        c.observer_gain = cx.per_joint("contact.observer_gain", g, n, false)?;
        positive("contact.observer_gain", &c.observer_gain)?;
        if let Some(k) = c.observer_gain.iter().position(|k| *k > control_rate_hz) {
            return Err(cx.err(
                "contact.observer_gain",
                format!(
                    "[{k}] = {} /s exceeds the control rate {control_rate_hz} Hz \
                     (K_O T ≤ 1: the observer must be slower than the sampling)",
                    c.observer_gain[k]
                ),
            ));
        }
    }
    if let Some(t) = &s.threshold {
        c.threshold = cx.per_joint("contact.threshold", t, n, false)?;
        positive("contact.threshold", &c.threshold)?;
    }
    if let Some(r) = s.release {
        if !(r > 0.0 && r <= 1.0) {
            return Err(cx.err(
                "contact.release",
                format!("must be in (0, 1] (a fraction of the threshold), got {r}"),
            ));
        }
        c.release = r;
    }
    Ok(c)
}
