//! **Passivity damping.** The paper's law is passive only conditionally (Sec. IV,
//! Proposition 1): level i's projected spring–damper (eqs. 20, 21) can feed energy
//! into the arm while the levels above it still move, and stops doing so once they
//! have converged. In free motion they do; held at a joint limit (the guard, or an
//! end stop) level 1 cannot converge, and the exchange can keep an oscillation going
//! for good — the storage E rising in every swing although every damper dissipates.
//! With the hierarchy's power into E
//!
//! P_h = q̇ᵀ (Σ_i τ_i + τ_μ) + Σ_i β_i (∂V_i/∂x_i) J_i q̇
//!
//! (the dampers' dissipation included; a moving goal's work left out, and while a
//! goal moves nothing is counted), the energy the hierarchy may feed in is
//! budgeted: after a goal or gains change (and once a moving goal stands) the
//! budget is `passivity_budget` plus [`PASSIVITY_TRANSIENT_SHARE`] of E — the
//! sequential convergence of Sec. IV feeds energy while it lasts (the paper's
//! simulations 9 % and 21 % of their E, within 0.25 s) — and that share decays
//! with [`PASSIVITY_TRANSIENT_TIME`]. Each cycle with P_h > 0 pays P_h T from it.
//! As the last half of `passivity_budget` ([`PASSIVITY_ONSET`]) runs out, a
//! growing share w P_h (w the smoothstep of the spent fraction: no torque jump)
//! is damped out instead — first in the null space of level 1 with the
//! dynamically consistent projector, −α (M q̇ − J_1ᵀ G⁻¹ J_1 q̇), then, as far as
//! the motion is level 1's own, over the whole arm, −α' M q̇; α, α' ≤
//! `passivity_damping_rate`. Once the budget is spent, E no longer grows but by
//! what the rate cap leaves; the equilibria are the law's. A regular hierarchy
//! (P_h ≤ 0, or within the budget) is untouched bit for bit.

use super::{
    CycleTerms, PASSIVITY_ONSET, PASSIVITY_TRANSIENT_SHARE, PASSIVITY_TRANSIENT_TIME, Safety,
    SafetyOutput, smoothstep,
};

impl Safety {
    /// A goal or gains changed: the hierarchy may feed `passivity_budget` into E
    /// again before the passivity damping acts.
    pub(crate) fn refill_passivity_budget(&mut self) {
        self.budget = f64::NAN;
    }

    /// The passivity damping (module docs): the hierarchy's power into E is paid
    /// from the budget; what the budget does not cover is damped out in the null
    /// space of level 1, at most at `passivity_damping_rate`.
    /// `energy`: E of this cycle (J).
    pub(super) fn passivity(&mut self, c: &CycleTerms, energy: f64, out: &mut SafetyOutput) {
        if !self.spec.passivity_damping || c.fade.len() < 2 {
            return;
        }
        if c.goal_moving {
            // A moving goal works on the arm; the law is judged once it stands.
            self.refill_passivity_budget();
        }
        let t = self.spec.control_period_s;
        let base = self.spec.passivity_budget;
        if self.budget.is_nan() {
            // Refilled: the budget and a share of the storage for the transient.
            self.budget = base + PASSIVITY_TRANSIENT_SHARE * energy.max(0.0);
        } else if self.budget > base {
            // The transient's share decays: what is above the budget proper.
            self.budget = base + (self.budget - base) * (-t / PASSIVITY_TRANSIENT_TIME).exp();
        }
        let p = c.hierarchy_power;
        // A NaN power counts as none.
        if c.goal_moving || p.is_nan() || p <= 0.0 {
            return;
        }
        // The damping takes over as the budget's last half runs out, smoothly
        // (no torque jump): it pays w p, the budget (1 − w) p.
        let soft = PASSIVITY_ONSET * base;
        let w = if self.budget >= soft {
            0.0
        } else if soft > 0.0 {
            smoothstep(1.0 - self.budget / soft)
        } else {
            1.0
        };
        self.budget = (self.budget - (1.0 - w) * p * t).max(0.0);
        let excess = w * p;
        if excess.is_nan() || excess <= 0.0 {
            return;
        }
        // Not to the fade's tank: this is the energy the hierarchy fed in.
        let cap = self.spec.passivity_damping_rate;
        self.project_above(1, c);
        let k2 = self.null_space_kinetic2(c);
        let mut left = excess;
        if k2 > 0.0 {
            let rate = (excess / k2).min(cap);
            left -= self.add_null_space_damping(rate, c, out);
            out.passivity_active = true;
        }
        // What the null space of level 1 cannot take (the motion is level 1's
        // own): the whole arm's −α M q̇, power −α q̇ᵀ M q̇.
        let kinetic2 = c.qd.dot(&self.mqd);
        if left > 0.0 && kinetic2 > 0.0 {
            let rate = (left / kinetic2).min(cap);
            for col in 0..c.qd.len() {
                out.tau[col] -= rate * self.mqd[col];
            }
            out.passivity_active = true;
        }
    }
}
