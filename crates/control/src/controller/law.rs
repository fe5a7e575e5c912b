//! The level torques of the control law: τ_1 = −J_1ᵀ F_1 (eq. 20) and
//! τ_i = −J̄_iᵀ Z_i J_iᵀ F_i (eq. 21), or the classical projector forms
//! (eqs. 8, 9) and the kinematic one for comparison, each scaled by its fade;
//! the local velocities v_i = J̄_i q̇ (eq. 3) and the storages
//! S_i = ½ v_iᵀ Λ_i v_i + V_i (eqs. 26, 28).

use super::Controller;
use crate::spec::Form;
use hcc_linalg::products::{copy, gemv, gemv_t, transpose_cols_into};
use nalgebra::DVector;

impl Controller {
    /// The local velocities v_i = J̄_i q̇ (eq. 3) of every level, once per
    /// cycle after the decomposition (the energy tanks and the level torques
    /// read them).
    pub(super) fn local_velocities(&mut self, qd: &DVector<f64>) {
        for l in &mut self.levels {
            gemv(&mut l.v, 1.0, &l.jbar, qd, 0.0);
        }
    }

    /// Torques of the levels (eqs. 20, 21) from F_i and v_i
    /// ([`Controller::local_velocities`]).
    pub(super) fn level_torques(&mut self) {
        let r = self.levels.len();
        for i in 0..r {
            let l = &mut self.levels[i];
            let tau_i = &mut self.out.tau_level[i];
            if i == 0 {
                gemv_t(tau_i, -1.0, &l.j, &l.f, 0.0);
            } else {
                gemv_t(&mut self.tmp_n, 1.0, &l.j, &l.f, 0.0);
                match self.spec.form {
                    Form::Extended => {
                        gemv(&mut l.y_d, 1.0, &l.z, &self.tmp_n, 0.0);
                        gemv_t(tau_i, -1.0, &l.jbar, &l.y_d, 0.0);
                    }
                    Form::ClassicalProjector if i == r - 1 => {
                        // N_r J_rᵀ F_r with N_r = M V S Vᵀ (eq. 9).
                        let ns = &mut self.basis;
                        gemv_t(&mut ns.y_nd, 1.0, &ns.v, &self.tmp_n, 0.0);
                        gemv(&mut ns.y_nd2, 1.0, &ns.s, &ns.y_nd, 0.0);
                        gemv(&mut self.tmp_n2, 1.0, &ns.v, &ns.y_nd2, 0.0);
                        gemv(tau_i, -1.0, &self.data.m, &self.tmp_n2, 0.0);
                    }
                    Form::ClassicalProjector => {
                        // N_i J_iᵀ F_i with N_i = I − J_augᵀ G⁻¹ J_aug M⁻¹ (eq. 8).
                        let p = &mut l.proj;
                        transpose_cols_into(&mut p.y_aug, &self.yt, 0);
                        gemv(&mut p.y_k, 1.0, &p.y_aug, &self.tmp_n, 0.0);
                        p.y_top.fill(0.0);
                        let (yk, gi) = (&p.y_k, &p.g_inv);
                        for a in 0..p.k {
                            let mut s = 0.0;
                            for b in 0..p.k {
                                s += gi[(a, b)] * yk[b];
                            }
                            p.y_top[a] = s;
                        }
                        copy(tau_i, &self.tmp_n);
                        gemv_t(tau_i, 1.0, &self.jtop, &p.y_top, -1.0);
                    }
                    Form::KinematicProjector => {
                        // (I − J_1ᵀ (J_1ᵀ)⁺) τ_2 with (J_1ᵀ)⁺ = (J_1 J_1ᵀ)⁻¹ J_1 (r = 2:
                        // `jtop` = J_1, the Gram matrix and its damped inverse are the
                        // null space's), τ_2 = −J_2ᵀ F_2.
                        let ns = &mut self.basis;
                        gemv(&mut ns.y_k, 1.0, &self.jtop, &self.tmp_n, 0.0);
                        gemv(&mut ns.y_k2, 1.0, &ns.gram_inv, &ns.y_k, 0.0);
                        copy(tau_i, &self.tmp_n);
                        gemv_t(tau_i, 1.0, &self.jtop, &ns.y_k2, -1.0);
                    }
                }
            }
            if self.out.fade[i] < 1.0 {
                *tau_i *= self.out.fade[i];
            }
            copy(&mut self.out.v[i], &l.v);
            copy(&mut self.out.task_error[i], &l.err);
            self.out.potential[i] = l.potential;
            // S_i = ½ v_iᵀ Λ_i v_i + V_i (eqs. 26, 28).
            gemv(&mut l.y_d2, 1.0, &l.lambda, &l.v, 0.0);
            self.out.storage[i] = 0.5 * l.v.dot(&l.y_d2) + l.potential;
        }
    }
}
