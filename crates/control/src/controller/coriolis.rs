//! The cancellation of the Coriolis couplings between the levels:
//! τ_μ = Σ_i J̄_iᵀ Σ_{j≠i} μ_ij v_j (eq. 22) with
//! μ = Λ (J̄ M⁻¹ C − J̄̇) J̄⁻¹ (eq. 17), power-conserving (μ_ij = −μ_jiᵀ), so
//! each level's storage is passive (Sec. IV).

use super::Controller;
use crate::ControlError;
use crate::spec::Form;
use hcc_linalg::blocks::column;
use hcc_linalg::products::{gemm, gemv, gemv_slices, gemv_t, gemv_t_slices};
use nalgebra::{DMatrix, DVector};

/// The per-level columns of the τ_μ chains (eq. 22), n × r each: u_i = q̇ − (J̄⁻¹)_i v_i,
/// M⁻¹ C u_i, M u_i and Ṁ u_i.
#[derive(Clone, Debug)]
pub(super) struct MuWork {
    pub(super) u: DMatrix<f64>,
    pub(super) minv_cu: DMatrix<f64>,
    pub(super) mu: DMatrix<f64>,
    pub(super) mdot_u: DMatrix<f64>,
}

impl MuWork {
    pub(super) fn new(n: usize, r: usize) -> MuWork {
        MuWork {
            u: DMatrix::zeros(n, r),
            minv_cu: DMatrix::zeros(n, r),
            mu: DMatrix::zeros(n, r),
            mdot_u: DMatrix::zeros(n, r),
        }
    }
}

impl Controller {
    /// τ_μ = Σ_i J̄_iᵀ Σ_{j≠i} μ_ij v_j (eq. 22) with μ = Λ (J̄ M⁻¹ C − J̄̇) J̄⁻¹ (eq. 17):
    /// Σ_{j≠i} (J̄⁻¹)_j v_j = q̇ − (J̄⁻¹)_i v_i = u, so each level needs one
    /// matrix-vector chain, J̄̇_i u = Λ_i⁻¹ (Ż_i M u + Z_i Ṁ u − Λ̇_i J̄_i u) included
    /// (J̄̇_1 = J̇_1): J̄̇_i itself is never formed.
    pub(super) fn coriolis_cancellation(&mut self, qd: &DVector<f64>) -> Result<(), ControlError> {
        let r = self.levels.len();
        self.out.tau_mu.fill(0.0);
        if self.spec.coriolis_cancellation && self.spec.form != Form::KinematicProjector {
            // The levels' u as the columns of U, then C U, M⁻¹ C U (one solve for all
            // levels, whose substitutions overlap), M U and Ṁ U.
            let (mu, n) = (&mut self.mu, self.n);
            let us = mu.u.as_mut_slice().chunks_exact_mut(n);
            for (i, (l, u)) in self.levels.iter().zip(us).enumerate() {
                u.copy_from_slice(qd.as_slice());
                if i == 0 {
                    gemv_slices(u, -1.0, &l.jbar_inv, l.v.as_slice(), 1.0);
                } else {
                    // (J̄⁻¹)_i = Z_iᵀ (eq. 13).
                    gemv_t_slices(u, -1.0, &l.z, l.v.as_slice(), 1.0);
                }
            }
            gemm(&mut mu.minv_cu, 1.0, &self.data.c, &mu.u, 0.0);
            hcc_model::linalg::cholesky_solve_slice(
                self.chol.as_slice(),
                self.n,
                mu.minv_cu.as_mut_slice(),
            )
            .map_err(|_| ControlError::Numerical("M⁻¹ C"))?;
            if r > 1 {
                gemm(&mut mu.mu, 1.0, &self.data.m, &mu.u, 0.0);
                gemm(&mut mu.mdot_u, 1.0, &self.mdot, &mu.u, 0.0);
            }
            for i in 0..r {
                let l = &mut self.levels[i];
                let u = column(&mu.u, i);
                let y_d = l.y_d.as_mut_slice();
                gemv_slices(y_d, 1.0, &l.jbar, column(&mu.minv_cu, i), 0.0);
                if i == 0 {
                    gemv_slices(y_d, -1.0, &l.jdot, u, 1.0);
                } else {
                    let y_d3 = l.y_d3.as_mut_slice();
                    gemv_slices(y_d3, 1.0, &l.zdot, column(&mu.mu, i), 0.0);
                    gemv_slices(y_d3, 1.0, &l.z, column(&mu.mdot_u, i), 1.0);
                    gemv_slices(l.y_d2.as_mut_slice(), 1.0, &l.jbar, u, 0.0);
                    gemv(&mut l.y_d3, -1.0, &l.lambda_dot, &l.y_d2, 1.0);
                    gemv(&mut l.y_d, -1.0, &l.lambda_inv, &l.y_d3, 1.0);
                }
                gemv(&mut l.y_d2, 1.0, &l.lambda, &l.y_d, 0.0);
                gemv_t(&mut self.out.tau_mu, 1.0, &l.jbar, &l.y_d2, 1.0);
            }
        }
        if self.out.fade_mu < 1.0 {
            self.out.tau_mu *= self.out.fade_mu;
        }
        self.out.p_mu = self.out.tau_mu.dot(qd);
        Ok(())
    }
}
