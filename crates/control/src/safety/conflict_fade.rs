//! **Conflict fade.** A level i ≥ 2 whose goal is unreachable given the levels
//! above it (an algorithmic conflict: Λ_i = Z_i M Z_iᵀ of eq. 18 becomes singular,
//! its conditioning r_i = `StepOutput::conditioning` falls, while the levels above stay
//! regular) keeps pulling in the direction it lost through the damped inverse: the
//! arm creeps along the self-motion that makes the conflict worse (e.g. a wrist
//! centre pulled beyond reach by the orientation level stretches the elbow). With
//! `conflict_fade_ratio` = ε_c > 0 its fade is lowered to
//!
//! β_i(q) ← min(β_i(q), β_c(r_i)),  β_c(r) = smoothstep(log_100(r / ε_c)) (0 at ε_c, 1 from 100 ε_c),
//!
//! before the passive fade below. r_i is the smaller eigenvalue ratio of Λ_i and of
//! G = J_aug M⁻¹ J_augᵀ of the levels above (the ratio the null-space damping uses),
//! so near a singularity of the levels above the level fades from 100 ε_c on as
//! well, earlier than the plain fade (100 `singular_ratio`). The same storage
//! function, so the same argument
//! holds — a fade-out removes −β̇_i V_i ≥ 0 from E, a fade-in (once r_i ≥ 100 ε_c
//! again) is paid from the tank, and the null-space damping (c_i from β_i) takes the
//! faded level's place. β_c is C¹ in log r_i (no torque jump); 1 wherever
//! r_i ≥ 100 ε_c, so a regular hierarchy is untouched bit for bit.

use super::{CONFLICT_RELEASE_FACTOR, Safety, SafetyOutput};

impl Safety {
    /// The conflict fade (module docs): β_i(q) ← min(β_i(q), β_c(r_i)) in
    /// `fade` for every level i ≥ 2, r_i its `conditioning`; latches and
    /// releases the conflict and counts the cycles it acted in.
    pub(super) fn conflict_fade(
        &mut self,
        fade: &mut [f64],
        conditioning: &[f64],
        out: &mut SafetyOutput,
    ) {
        let eps_c = self.spec.conflict_fade_ratio;
        out.conflict_fade_active = false;
        if eps_c > 0.0 {
            // The conflict fade: a level whose own Λ_i (eq. 18) is near-singular has
            // lost a direction to the levels above; its spring fades with r_i.
            let release = CONFLICT_RELEASE_FACTOR * crate::FADE_RANGE * eps_c;
            for i in 1..fade.len() {
                let own = crate::fade::fade_factor(conditioning[i], eps_c);
                if own < fade[i] {
                    fade[i] = own;
                    out.conflict_fade_active = true;
                }
                // The conflict is over only well out of its fade region (or
                // with a new goal: `release_conflict`).
                if own < 1.0 {
                    self.conflict_latched[i] = true;
                } else if conditioning[i] >= release {
                    self.conflict_latched[i] = false;
                }
            }
        }
        out.conflict_fade_cycles += u64::from(out.conflict_fade_active);
    }

    /// Level `i` has a new goal: a conflict it was faded for may be over.
    pub(crate) fn release_conflict(&mut self, i: usize) {
        if let Some(l) = self.conflict_latched.get_mut(i) {
            *l = false;
        }
    }
}
