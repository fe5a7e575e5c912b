//! `[contact]`: the external-torque observer and the contact detection.
//!
//! ```toml
//! [contact]
//! observer_gain = 100.0   # K_O, 1/s: scalar or one per joint
//! threshold = 2.0         # N·m: contact when some |r_j| exceeds it (scalar or per joint)
//! release = 0.5           # contact cleared when every |r_j| is below release × threshold
//! reaction = "report"     # "report" | "soften" | "hold" (what a contact does to the torque)
//! soften_fraction = 0.2   # soften: the levels' stiffness while in contact, × K_i
//! ramp_s = 0.1            # soften, hold: the time of a full ramp in or out, s
//! hold_damping = 1.0      # hold: joint damping D_h, N·m·s/rad (scalar or per joint)
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
//!
//! **Reactions** (`hcc_cycle`'s module `reaction`). `report` (default): the
//! torque is the law's, bit for bit. `soften`: while a contact is flagged, every
//! level's stiffness is scaled by κ ramped from 1 to `soften_fraction` with the
//! quintic (minimum-jerk) profile over `ramp_s`, and back after the contact
//! clears; damping unchanged. `hold`: a contact latches the hold, and τ ramps
//! over `ramp_s` to g(q) − D_h q̇ (gravity and joint damping), kept until a
//! client's setpoint is accepted (any level), which ramps back to the law.
//! Defaults: κ = 0.2 (a fifth of the stiffness: a push of 15 N moves the hand
//! five times as far, but the arm still returns when released), `ramp_s` =
//! 0.1 s (ten observer time constants: the ramp, not the estimate, sets the
//! torque rate), D_h = 1 N·m·s/rad, checked against the control rate
//! (T (M⁻¹(q0))_jj D_h,j ≤ 1.5, the bound of `hcc_control::rate`).

use hcc_model::Model;
use nalgebra::DVector;
use serde::Deserialize;

use crate::context::Ctx;
use crate::error::ConfigError;
use crate::values::PerJoint;
use hcc_spec::contact::{Contact, Reaction};

/// Largest T (M⁻¹)_jj D_h,j accepted for `hold` (`hcc_control::rate::B_MAX`).
const HOLD_B_MAX: f64 = 1.5;

/// `[contact]` as written.
#[derive(Clone, Debug, Default, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ContactSection {
    pub observer_gain: Option<PerJoint>,
    pub threshold: Option<PerJoint>,
    pub release: Option<f64>,
    pub reaction: Option<Reaction>,
    pub soften_fraction: Option<f64>,
    pub ramp_s: Option<f64>,
    pub hold_damping: Option<PerJoint>,
}

/// Checks `[contact]` against the model's joint count, the control rate and
/// (for `hold`) the arm's inertia at `q0`.
pub(crate) fn resolve(
    cx: &Ctx,
    model: &Model,
    q0: &DVector<f64>,
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
    resolve_reaction(cx, model, q0, s, control_rate_hz, &mut c)?;
    Ok(c)
}

/// The reaction's fields of `[contact]` into `c`.
fn resolve_reaction(
    cx: &Ctx,
    model: &Model,
    q0: &DVector<f64>,
    s: &ContactSection,
    control_rate_hz: f64,
    c: &mut Contact,
) -> Result<(), ConfigError> {
    c.reaction = s.reaction.unwrap_or_default();
    if let Some(f) = s.soften_fraction {
        if !(f > 0.0 && f <= 1.0) {
            return Err(cx.err(
                "contact.soften_fraction",
                format!("must be in (0, 1] (a fraction of the stiffness), got {f}"),
            ));
        }
        c.soften_fraction = f;
    }
    if let Some(t) = s.ramp_s {
        if !(t > 0.0 && t.is_finite()) {
            return Err(cx.err(
                "contact.ramp_s",
                format!("must be a positive number of seconds, got {t}"),
            ));
        }
        c.ramp_s = t;
    }
    let n = model.nq();
    if let Some(d) = &s.hold_damping {
        c.hold_damping = cx.per_joint("contact.hold_damping", d, n, false)?;
        if let Some(k) = c.hold_damping.iter().position(|x| *x <= 0.0) {
            return Err(cx.err(
                "contact.hold_damping",
                format!("[{k}] must be positive, got {}", c.hold_damping[k]),
            ));
        }
    }
    if c.reaction == Reaction::Hold {
        check_hold_rate(cx, model, q0, &c.hold_damping, control_rate_hz)?;
    }
    Ok(())
}

/// The hold's damper must be one the control rate carries: b_j = T (M⁻¹)_jj
/// D_h,j ≤ 1.5 at `q0` (a joint damper on the mode of joint j alone;
/// `hcc_control::rate` explains the bound).
fn check_hold_rate(
    cx: &Ctx,
    model: &Model,
    q0: &DVector<f64>,
    damping: &DVector<f64>,
    control_rate_hz: f64,
) -> Result<(), ConfigError> {
    let mut data = hcc_model::Data::new(model);
    hcc_model::crba(model, &mut data, q0);
    let Some(m_inv) = data.m.clone().try_inverse() else {
        return Ok(());
    };
    let period = 1.0 / control_rate_hz;
    for (j, d) in damping.iter().enumerate() {
        let b = period * m_inv[(j, j)] * d;
        if b > HOLD_B_MAX {
            return Err(cx.err(
                "contact.hold_damping",
                format!(
                    "[{j}] = {d} N·m·s/rad is more than the control rate carries on that joint \
                     (T (M⁻¹)_jj D = {b:.2} > {HOLD_B_MAX} at initial.q0); at most {:.3e}",
                    HOLD_B_MAX / (period * m_inv[(j, j)])
                ),
            ));
        }
    }
    Ok(())
}
