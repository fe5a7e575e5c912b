//! The dynamically consistent decomposition of one cycle (eqs. 3–13, 15–18):
//! the levels above the lowest stacked (Y = J M⁻¹ by solves, W = J M⁻¹ Jᵀ and
//! their derivatives), level 1's Λ_1 (eq. 18) with J̄_1 = J_1, and for each
//! null-space level Z_i (eq. 11 with the projector of eq. 8, or V_{r−1}ᵀ for
//! the lowest), J̄_i (eq. 5), Λ_i, Λ̇_i (eq. 18) and its fade.

use super::{Controller, GRAM_FLOOR};
use crate::ControlError;
use crate::fade::fade_factor;
use hcc_linalg::blocks::copy_block;
use hcc_linalg::products::{
    copy, gemm, gemm_leading, gemm_nt, gemm_nt_leading, transpose_cols_into, transpose_into,
};
use hcc_linalg::spd::damped_spd_inverse;
use hcc_linalg::symmetric::add_own_transpose;

impl Controller {
    /// The decomposition of one cycle: the levels above the lowest stacked —
    /// Y = J M⁻¹ (by solves, M⁻¹ is never formed), W = J M⁻¹ Jᵀ, whose diagonal
    /// blocks are J_i M⁻¹ J_iᵀ and whose leading blocks are J_aug M⁻¹ J_augᵀ
    /// (eq. 8), and their derivatives with d/dt M⁻¹ = −M⁻¹ Ṁ M⁻¹ — then level 1
    /// and every null-space level.
    pub(super) fn decompose(&mut self) -> Result<(), ControlError> {
        self.stack_top()?;
        self.first_level();
        for i in 1..self.levels.len() {
            self.null_space_level(i)?;
        }
        self.out.any_singular = self.out.singular.iter().any(|&s| s);
        Ok(())
    }

    /// The levels above the lowest, stacked ([`Controller::decompose`]).
    pub(super) fn stack_top(&mut self) -> Result<(), ControlError> {
        let n = self.n;
        let mut row = 0;
        let top = self.jtop.nrows();
        for l in &self.levels {
            if row == top {
                break;
            }
            copy_block(&mut self.jtop, row, 0, &l.j, 0, 0, l.m, n);
            copy_block(&mut self.jtop_dot, row, 0, &l.jdot, 0, 0, l.m, n);
            row += l.m;
        }
        transpose_into(&mut self.jtop_t, &self.jtop);
        copy(&mut self.yt, &self.jtop_t);
        hcc_model::linalg::cholesky_solve_slice(self.chol.as_slice(), n, self.yt.as_mut_slice())
            .map_err(|_| ControlError::Numerical("M⁻¹ Jᵀ"))?;
        gemm(&mut self.w, 1.0, &self.jtop, &self.yt, 0.0);
        if self.middle {
            transpose_into(&mut self.yt_dot, &self.jtop_dot);
            gemm(&mut self.yt_dot, -1.0, &self.mdot, &self.yt, 1.0);
            hcc_model::linalg::cholesky_solve_slice(
                self.chol.as_slice(),
                n,
                self.yt_dot.as_mut_slice(),
            )
            .map_err(|_| ControlError::Numerical("d/dt M⁻¹ Jᵀ"))?;
            gemm_leading(&mut self.w_dot, 1.0, &self.jtop_dot, &self.yt, 0.0);
            gemm_leading(&mut self.w_dot, 1.0, &self.jtop, &self.yt_dot, 1.0);
        }
        Ok(())
    }

    /// Level 1: Λ_1 = (J_1 M⁻¹ J_1ᵀ)⁻¹ (eq. 18), J̄_1 = J_1.
    pub(super) fn first_level(&mut self) {
        let eps = self.spec.singular_ratio;
        let l = &mut self.levels[0];
        copy_block(&mut l.lambda_inv, 0, 0, &self.w, 0, 0, l.m, l.m);
        let c = damped_spd_inverse(&l.lambda_inv, &mut l.lambda, &mut l.spd, eps, GRAM_FLOOR);
        self.first_cond = c;
        self.out.conditioning[0] = c.ratio;
        self.out.singular[0] = c.damping > 0.0;
        copy(&mut l.jbar, &l.j);
        // (J̄⁻¹)_1 = J_1^{M+} = M⁻¹ J_1ᵀ Λ_1 (eq. 13); M⁻¹ J_1ᵀ is the first m_1
        // columns of M⁻¹ Jᵀ.
        gemm_leading(&mut l.jbar_inv, 1.0, &self.yt, &l.lambda, 0.0);
    }

    /// Null-space level i ≥ 2 (eqs. 5–13, 16–18).
    pub(super) fn null_space_level(&mut self, i: usize) -> Result<(), ControlError> {
        let (r, eps) = (self.levels.len(), self.spec.singular_ratio);
        let lowest = i == r - 1;
        if lowest {
            self.null_space()?;
        }
        let (above, rest) = self.levels.split_at_mut(i);
        let l = &mut rest[0];
        let (c, gc) = if lowest {
            // Z_r = V_{r−1}ᵀ and Λ_r = Vᵀ M V (eq. 18) with its inverse S and derivative
            // X from the null space; J̄_r = S (M V)ᵀ (eq. 5).
            let ns = &mut self.basis;
            // Vᵀ and V̇ᵀ of this cycle, handed over (the buffers swap; the null space
            // forms both afresh every cycle).
            std::mem::swap(&mut l.z, &mut ns.vt);
            std::mem::swap(&mut l.zdot, &mut ns.vdot_t);
            copy(&mut l.lambda, &ns.vtmv);
            copy(&mut l.lambda_inv, &ns.s);
            copy(&mut l.lambda_dot, &ns.x);
            gemm_nt(&mut ns.jbar_t, 1.0, &ns.mv, &ns.s, 0.0);
            transpose_into(&mut l.jbar, &ns.jbar_t);
            (ns.s_cond, ns.gram_cond)
        } else {
            // Z_i = J_i M⁻¹ N_i (eq. 11) with N_i = I − J_augᵀ (J_aug^{M+})ᵀ (eq. 8):
            // Z_i = Y_i − T Y_aug, T = H G⁻¹, and Ż_i = Ẏ_i − Ṫ Y_aug − T Ẏ_aug with
            // Ṫ = (Ḣ − T Ġ) G⁻¹ — the same Z_i as eq. (12), without a null-space basis.
            let p = &mut l.proj;
            let (k, m) = (p.k, l.m);
            copy_block(&mut p.gdot, 0, 0, &self.w_dot, 0, 0, k, k);
            copy_block(&mut p.h, 0, 0, &self.w, k, 0, m, k);
            copy_block(&mut p.hdot, 0, 0, &self.w_dot, k, 0, m, k);
            // Y_i and Ẏ_i: rows k..k + m of Y and Ẏ; Y_aug and Ẏ_aug (rows 0..k) are
            // read in place as the leading columns of Yᵀ = M⁻¹ Jᵀ and its derivative.
            transpose_cols_into(&mut l.z, &self.yt, k);
            transpose_cols_into(&mut l.zdot, &self.yt_dot, k);
            if i == 1 {
                // G = J_1 M⁻¹ J_1ᵀ = Λ_1⁻¹: its damped inverse is level 1's Λ_1.
                copy(&mut p.g_inv, &above[0].lambda);
                p.g_cond = self.first_cond;
            } else {
                copy_block(&mut p.g, 0, 0, &self.w, 0, 0, k, k);
                p.g_cond = damped_spd_inverse(&p.g, &mut p.g_inv, &mut p.spd, eps, GRAM_FLOOR);
            }
            gemm(&mut p.t, 1.0, &p.h, &p.g_inv, 0.0);
            gemm(&mut p.hdot, -1.0, &p.t, &p.gdot, 1.0);
            gemm(&mut p.tdot, 1.0, &p.hdot, &p.g_inv, 0.0);
            gemm_nt_leading(&mut l.z, -1.0, &p.t, &self.yt, 1.0);
            gemm_nt_leading(&mut l.zdot, -1.0, &p.tdot, &self.yt, 1.0);
            gemm_nt_leading(&mut l.zdot, -1.0, &p.t, &self.yt_dot, 1.0);
            // Λ_i = Z M Zᵀ (eq. 18) and Λ̇_i = Ż M Zᵀ + Z M Żᵀ + Z Ṁ Zᵀ.
            gemm(&mut l.zm, 1.0, &l.z, &self.data.m, 0.0);
            gemm(&mut l.zmdot, 1.0, &l.z, &self.mdot, 0.0);
            gemm_nt(&mut l.lambda, 1.0, &l.zm, &l.z, 0.0);
            // Z M Żᵀ = (Ż M Zᵀ)ᵀ, its elements the same sums of the same products.
            gemm_nt(&mut l.lambda_dot, 1.0, &l.zdot, &l.zm, 0.0);
            add_own_transpose(&mut l.lambda_dot);
            gemm_nt(&mut l.lambda_dot, 1.0, &l.zmdot, &l.z, 1.0);
            let c = damped_spd_inverse(&l.lambda, &mut l.lambda_inv, &mut l.spd, eps, GRAM_FLOOR);
            // J̄_i = (Z M Zᵀ)⁻¹ Z M (eq. 5).
            gemm(&mut l.jbar, 1.0, &l.lambda_inv, &l.zm, 0.0);
            (c, p.g_cond)
        };
        self.out.conditioning[i] = c.ratio.min(gc.ratio);
        self.out.singular[i] = c.damping > 0.0 || gc.damping > 0.0;
        // The projection of level i inverts the Gram matrix of the levels above
        // it: its torque fades as that one becomes singular (crate docs).
        self.out.fade[i] = fade_factor(gc.ratio, eps);
        // (J̄⁻¹)_i = Z_iᵀ (eq. 13): read as Z_iᵀ where it is applied, never formed.
        Ok(())
    }
}
