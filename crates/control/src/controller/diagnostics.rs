//! The stacked matrices of one cycle for checks and debugging (allocates; not
//! for the loop): J̄ (eq. 4), J̄̇, J̄⁻¹ (eq. 13), Λ (eq. 16) and
//! μ = Λ (J̄ M⁻¹ C − J̄̇) J̄⁻¹ (eq. 17), with M, M⁻¹ and C.

use super::Controller;
use nalgebra::DMatrix;

impl Controller {
    /// Diagnostics (not for the control loop: allocates). The stacked J̄ (eq. 4), J̄̇,
    /// J̄⁻¹ (eq. 13), Λ (eq. 16, block-diagonal by construction of eq. 18) and
    /// μ = Λ (J̄ M⁻¹ C − J̄̇) J̄⁻¹ (eq. 17) of the last cycle, plus M, M⁻¹, C and the
    /// level sizes d_i. Meaningful when the lowest level is a null-space level
    /// (Σ d_i = n).
    pub fn diagnostics(&self) -> Diagnostics {
        let n = self.n;
        let total: usize = self.levels.iter().map(|l| l.d).sum();
        let mut jbar = DMatrix::zeros(total, n);
        let mut jbar_dot = DMatrix::zeros(total, n);
        let mut jbar_inv = DMatrix::zeros(n, total);
        let mut lambda = DMatrix::zeros(total, total);
        let mut row = 0;
        for l in &self.levels {
            jbar.view_mut((row, 0), (l.d, n)).copy_from(&l.jbar);
            // J̄̇_1 = J̇_1, J̄̇_i = Λ_i⁻¹ (Ż M + Z Ṁ − Λ̇_i J̄_i) (not formed by the step).
            let jd = if row == 0 {
                l.jdot.clone()
            } else {
                &l.lambda_inv
                    * (&l.zdot * &self.data.m + &l.z * &self.mdot - &l.lambda_dot * &l.jbar)
            };
            jbar_dot.view_mut((row, 0), (l.d, n)).copy_from(&jd);
            // (J̄⁻¹)_1 = J_1^{M+}, (J̄⁻¹)_i = Z_iᵀ (eq. 13).
            let ji = if row == 0 {
                l.jbar_inv.clone()
            } else {
                l.z.transpose()
            };
            jbar_inv.view_mut((0, row), (n, l.d)).copy_from(&ji);
            lambda.view_mut((row, row), (l.d, l.d)).copy_from(&l.lambda);
            row += l.d;
        }
        let mut minv = DMatrix::identity(n, n);
        // The factor is valid after any cycle that got past M (else M⁻¹ is NaN).
        if hcc_model::linalg::cholesky_solve_matrix_in_place(&self.chol, &mut minv).is_err() {
            minv.fill(f64::NAN);
        }
        let mu = if total == n {
            &lambda * (&jbar * &minv * &self.data.c - &jbar_dot) * &jbar_inv
        } else {
            DMatrix::zeros(total, total)
        };
        Diagnostics {
            dims: self.levels.iter().map(|l| l.d).collect(),
            jacobians: self.levels.iter().map(|l| l.j.clone()).collect(),
            z: self.levels.iter().map(|l| l.z.clone()).collect(),
            jbar,
            jbar_dot,
            jbar_inv,
            lambda,
            mu,
            m: self.data.m.clone(),
            minv,
            c: self.data.c.clone(),
        }
    }
}

/// Stacked matrices of one cycle, for checks and debugging.
#[derive(Clone, Debug)]
pub struct Diagnostics {
    /// d_i = dim v_i per level.
    pub dims: Vec<usize>,
    /// J_i per level.
    pub jacobians: Vec<DMatrix<f64>>,
    /// Z_i per level (J_1 for level 1).
    pub z: Vec<DMatrix<f64>>,
    pub jbar: DMatrix<f64>,
    pub jbar_dot: DMatrix<f64>,
    pub jbar_inv: DMatrix<f64>,
    pub lambda: DMatrix<f64>,
    pub mu: DMatrix<f64>,
    pub m: DMatrix<f64>,
    pub minv: DMatrix<f64>,
    pub c: DMatrix<f64>,
}
