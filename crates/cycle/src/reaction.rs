//! What a contact does to the torque (`[contact] reaction`,
//! `hcc_spec::contact::Reaction`), smoothly.
//!
//! A reaction moves one value h ∈ [0, 1] (0: the law as configured, 1: the
//! reaction in full) along the quintic minimum-jerk profile
//! (`hcc_control::transition::quintic`) towards its target; a full ramp takes
//! `ramp_s`, a partial one (a contact that clears mid-ramp) the fraction of it
//! it covers, starting from where h is. h is therefore continuous, its rate at
//! most 15/8 per `ramp_s` (the profile's peak slope), zero at both ends of an
//! uninterrupted ramp; on a reversal mid-ramp its rate changes sign (h is C⁰
//! there, its slope bounded). The torque is continuous in h, so no reaction
//! steps the torque: the step per cycle is bounded by 15/8 · T/`ramp_s` times
//! the torque the reaction takes away or adds.
//!
//! **soften.** Target h = 1 while the contact flag is set (as of the previous
//! state: the observer runs after the law), 0 otherwise; every level's spring
//! is scaled by κ = 1 − (1 − `soften_fraction`) h
//! (`hcc_control::Controller::set_stiffness_scale`), damping unchanged.
//! *Passivity.* The law's storage is E = T_kin + κ Σ V_i (Sec. IV of the
//! paper, with every K_i scaled by κ). With κ fixed the law is the paper's,
//! whose storage only the external port (τ_extᵀ q̇) raises; a varying κ adds
//! the power κ̇ Σ V_i: ≤ 0 while softening (κ falls: the springs' energy
//! drops), ≥ 0 while restoring, at most (1 − κ_min) Σ V_i over a whole
//! restore — the spring energy taken away while softening, at most, as the
//! potentials of a stationary arm. With the energy tanks on, each step of κ
//! is booked through them (`Controller::ramp_stiffness_scale`): what the
//! softening takes from the springs goes into the fade's tank, the restore
//! is paid from the tanks' spare, and a restore they cannot pay waits
//! (counted, `reaction_restore_held`): H with the tanks does not change by κ.
//! `crates/in-process/tests/contact_reaction.rs` checks the balance E_k − E_0
//! ≤ Σ Δκ Σ V_i/κ + external work along a push.
//!
//! **hold.** A contact's onset latches the hold (target h = 1); a client's
//! accepted setpoint (any level, any field) releases it (target h = 0); a
//! contact that goes on through the release does not latch again until it
//! ends and a new one begins. τ = τ_law + h (τ_hold − τ_law) with τ_hold =
//! g(q) − D_h q̇ (g only when the controller adds gravity): gravity and a joint
//! damper, the defined safe torque, which the saturation and the torque
//! filter then treat like the law's. *Passivity.* τ − g = (1 − h)(τ_law − g)
//! − h D_h q̇, so with the storage E = T_kin + (1 − h) Σ V_i the power is
//! −(1 − h) (the law's dissipation) − h q̇ᵀ D_h q̇ − ḣ Σ V_i + τ_extᵀ q̇: the
//! ramp into the hold (ḣ ≥ 0) only removes energy; the ramp out adds at most
//! Σ V_i, the springs' energy at the configuration where the hold left the
//! arm (a client's new goal there makes it small). With the energy tanks on,
//! each step of the share 1 − h is booked through them
//! (`Controller::ramp_law_share`): the ramp in fills the fade's tank, the
//! release is paid from the tanks' spare, and a release they cannot pay
//! waits (counted, `reaction_restore_held`).
//!
//! **report.** h stays 0 and nothing is touched: the torques are bit for bit
//! the law's.
//!
//! Allocation-free after [`ContactReaction::new`].

use hcc_control::Controller;
use hcc_control::transition::quintic;
use hcc_msgs::MAX_JOINTS;
use hcc_spec::contact::{Contact, Reaction};

#[cfg(test)]
mod tests;

/// h's ramp: from `from` to `to` over `duration` s.
#[derive(Clone, Copy, Debug)]
struct Ramp {
    from: f64,
    to: f64,
    elapsed: f64,
    duration: f64,
}

impl Ramp {
    fn value(&self) -> f64 {
        if self.duration <= 0.0 {
            return self.to;
        }
        let (s, _, _) = quintic(self.elapsed / self.duration);
        self.from + (self.to - self.from) * s
    }

    /// Aims at `target` from where h is, over the share of `full_s` it covers.
    fn aim(&mut self, target: f64, full_s: f64) {
        if self.to != target {
            let now = self.value();
            self.from = now;
            self.to = target;
            self.elapsed = 0.0;
            self.duration = (target - now).abs() * full_s;
        }
    }

    fn advance(&mut self, dt: f64) {
        self.elapsed = (self.elapsed + dt).min(self.duration);
    }
}

/// The reaction's configuration and state.
pub(crate) struct ContactReaction {
    kind: Reaction,
    soften_fraction: f64,
    ramp_s: f64,
    hold_damping: [f64; MAX_JOINTS],
    ramp: Ramp,
    /// h after the last [`ContactReaction::before_law`].
    h: f64,
    /// `hold`: latched by a contact's onset, released by a setpoint.
    held: bool,
    /// The setpoint handler's count of accepted setpoints, as last seen.
    accepted_seen: u64,
    /// Cycles in which `soften`'s restore held: the energy tanks could not
    /// pay the springs' return (`Controller::ramp_stiffness_scale`), or a
    /// `hold`'s release the law's share (`Controller::ramp_law_share`).
    pub(crate) restore_held: u64,
}

impl ContactReaction {
    /// The reaction of `[contact]` (sizes checked by the cycle's settings).
    pub(crate) fn new(contact: &Contact) -> ContactReaction {
        let mut hold_damping = [0.0; MAX_JOINTS];
        let n = contact.hold_damping.len().min(MAX_JOINTS);
        hold_damping[..n].copy_from_slice(&contact.hold_damping.as_slice()[..n]);
        ContactReaction {
            kind: contact.reaction,
            soften_fraction: contact.soften_fraction,
            ramp_s: contact.ramp_s,
            hold_damping,
            ramp: Ramp {
                from: 0.0,
                to: 0.0,
                elapsed: 0.0,
                duration: 0.0,
            },
            h: 0.0,
            held: false,
            accepted_seen: 0,
            restore_held: 0,
        }
    }

    /// h, how far the reaction acts (0: not at all, 1: in full).
    pub(crate) fn level(&self) -> f64 {
        self.h
    }

    /// Whether a hold is latched (a setpoint releases it).
    pub(crate) fn held(&self) -> bool {
        self.held
    }

    /// Before the law of a state: the target from the contact flag (`began`:
    /// a contact began at the previous state) and the setpoints accepted so
    /// far (`accepted`), h advanced by `dt`, and for `soften` the law's κ,
    /// for `hold` the law's share 1 − h of the torque.
    /// Allocation-free.
    pub(crate) fn before_law(
        &mut self,
        in_contact: bool,
        began: bool,
        accepted: u64,
        dt: f64,
        controller: &mut Controller,
    ) {
        let released = accepted != self.accepted_seen;
        self.accepted_seen = accepted;
        let target = match self.kind {
            Reaction::Report => return,
            Reaction::Soften => in_contact,
            Reaction::Hold => {
                if released {
                    self.held = false;
                }
                if began {
                    self.held = true;
                }
                self.held
            }
        };
        self.ramp.aim(if target { 1.0 } else { 0.0 }, self.ramp_s);
        let elapsed = self.ramp.elapsed;
        self.ramp.advance(dt);
        if self.kind == Reaction::Soften {
            // The springs' energy changes with κ: booked through the law's
            // energy tanks; a restore they cannot pay waits (counted).
            let kappa = 1.0 - (1.0 - self.soften_fraction) * self.ramp.value();
            if !controller.ramp_stiffness_scale(kappa) {
                self.ramp.elapsed = elapsed;
                self.restore_held += 1;
            }
            self.h = self.ramp.value();
        } else {
            // The law's share of the blended torque (`blend`): the storage it
            // makes changes with it, booked through the law's energy tanks; a
            // release they cannot pay waits (counted).
            if !controller.ramp_law_share(1.0 - self.ramp.value()) {
                self.ramp.elapsed = elapsed;
                self.restore_held += 1;
            }
            self.h = self.ramp.value();
        }
    }

    /// After the law: for `hold`, τ = τ_law + h (g − D_h q̇ − τ_law) in
    /// place (`gravity` = g(q) when τ includes it, else `None`). Returns
    /// whether the torque changed. Allocation-free.
    pub(crate) fn blend(&self, tau: &mut [f64], gravity: Option<&[f64]>, qd: &[f64]) -> bool {
        if self.kind != Reaction::Hold || self.h <= 0.0 {
            return false;
        }
        for (j, t) in tau.iter_mut().enumerate() {
            let hold = gravity.map_or(0.0, |g| g[j]) - self.hold_damping[j] * qd[j];
            *t = if self.h >= 1.0 {
                hold
            } else {
                *t + self.h * (hold - *t)
            };
        }
        true
    }
}
