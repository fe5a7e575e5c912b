//! **Null-space damping of faded levels.** A faded level no longer damps the motion it
//! controlled (the self-motion the levels above it leave free). In its place, level i
//! adds the joint damping c_i M q̇ projected into the null space of the levels above
//! it with the dynamically consistent projector,
//!
//! τ_N,i = −c_i Nᵀ_i M N_i q̇ = −c_i (M q̇ − J_augᵀ G⁻¹ J_aug q̇),  G = J_aug M⁻¹ J_augᵀ
//!
//! (eq. 8; N_i = I − M⁻¹ J_augᵀ G⁻¹ J_aug), with c_i = (1 − min(β_i, β(r_i))) ·
//! `null_space_damping`, where β(r_i) is the fade function of the level's own
//! conditioning r_i (`StepOutput::conditioning`): a level in an algorithmic singularity
//! (Λ_i = Z_i M Z_iᵀ singular) keeps its torque but no longer controls the
//! direction it lost, which is damped in its place.
//! J_aug M⁻¹ τ_N,i = 0: the levels above are not disturbed, and its power
//! −c_i (q̇ᵀ M q̇ − ẋ_augᵀ G⁻¹ ẋ_aug) ≤ 0 — also with the damped inverse (G + δI)⁻¹ ≤ G⁺
//! that is used where G is singular, since ẋᵀ G⁺ ẋ ≤ q̇ᵀ M q̇ for ẋ = J_aug q̇.

use super::{CycleTerms, Safety, SafetyOutput};
use hcc_linalg::products::gemv;
use hcc_linalg::spd::damped_spd_inverse_only;

impl Safety {
    /// τ_N,i = −c_i (M q̇ − J_augᵀ G⁻¹ J_aug q̇) for every faded level i ≥ 2.
    pub(super) fn null_space_damping(&mut self, c: &CycleTerms, out: &mut SafetyOutput) {
        let rate = self.spec.null_space_damping;
        if rate == 0.0 {
            return;
        }
        for i in 1..c.fade.len() {
            // Faded, or singular itself (Λ_i, eq. 18): the motion it no longer controls.
            let own = crate::fade::fade_factor(c.conditioning[i], c.singular_ratio);
            let beta = c.fade[i].min(own);
            if beta >= 1.0 {
                continue;
            }
            self.project_above(i, c);
            let ci = (1.0 - beta) * rate;
            let p = self.add_null_space_damping(ci, c, out);
            // Applied with the law's share (a contact hold blends the rest away).
            self.fill_power += c.law_share * p;
            out.null_space_damping_active = true;
        }
    }

    /// y = G⁻¹ J_aug q̇ (damped inverse where G is singular) for the levels
    /// above level `i`, and from it `null_momentum` = M q̇ − J_augᵀ y.
    pub(super) fn project_above(&mut self, i: usize, c: &CycleTerms) {
        let ktop = c.jtop.nrows();
        let k = self.k_above[i].min(ktop);
        if !self.xdot_fresh {
            gemv(&mut self.xdot, 1.0, c.jtop, c.qd, 0.0);
            self.xdot_fresh = true;
        }
        let g = &mut self.g[i];
        for a in 0..k {
            for b in 0..k {
                g[(a, b)] = c.w[(a, b)];
            }
        }
        damped_spd_inverse_only(
            g,
            &mut self.g_inv[i],
            &mut self.spd[i],
            c.singular_ratio,
            1e-12,
        );
        for a in 0..k {
            let mut s = 0.0;
            for b in 0..k {
                s += self.g_inv[i][(a, b)] * self.xdot[b];
            }
            self.y[a] = s;
        }
        for col in 0..c.qd.len() {
            let mut jty = 0.0;
            for a in 0..k {
                jty += c.jtop[(a, col)] * self.y[a];
            }
            self.null_momentum[col] = self.mqd[col] - jty;
        }
    }

    /// Adds −rate (M q̇ − J_augᵀ y) (after [`Safety::project_above`]) to
    /// `out.tau`; returns the power it removes, rate (q̇ᵀ M q̇ − ẋ_augᵀ G⁻¹ ẋ_aug) ≥ 0.
    pub(super) fn add_null_space_damping(
        &self,
        rate: f64,
        c: &CycleTerms,
        out: &mut SafetyOutput,
    ) -> f64 {
        let mut p = 0.0;
        for col in 0..c.qd.len() {
            let t = -rate * self.null_momentum[col];
            out.tau[col] += t;
            p -= t * c.qd[col];
        }
        p.max(0.0)
    }

    /// 2 × the kinetic energy in the null space of the levels above (after
    /// [`Safety::project_above`]): q̇ᵀ M q̇ − ẋ_augᵀ G⁻¹ ẋ_aug ≥ 0.
    pub(super) fn null_space_kinetic2(&self, c: &CycleTerms) -> f64 {
        let mut s = 0.0;
        for col in 0..c.qd.len() {
            s += c.qd[col] * self.null_momentum[col];
        }
        s.max(0.0)
    }
}
