//! The null space of the augmented Jacobian of the levels above the lowest
//! (eqs. 6–9), for Z_r = V_{r−1}ᵀ: an orthonormal basis V kept continuous in
//! time (the crate docs, "Basis continuity"), its parallel-transport
//! derivative V̇ = −J⁺ J̇ V, and Λ_r = Vᵀ M V (eq. 18) with its inverse and
//! derivative.

use super::{Controller, GRAM_FLOOR};
use crate::ControlError;
use hcc_linalg::basis::{AlignWork, null_space_basis, orthonormalize_polar, procrustes_align};
use hcc_linalg::products::{copy, gemm, gemm_nt, gemm_sym, transpose_into};
use hcc_linalg::spd::{Conditioning, SpdWork, damped_spd_inverse};
use hcc_linalg::symmetric::transpose_add;
use nalgebra::{DMatrix, DVector};

/// Smallest singular value of the previous basis projected onto the new null space
/// (the cosine of the largest principal angle between them) for which the basis is
/// continued; below it the state jumped and a fresh basis is taken.
const MIN_OVERLAP: f64 = 0.5;

/// Null space of the augmented Jacobian of the levels above the lowest one
/// (eqs. 6–9), for Z_r = V_{r−1}ᵀ.
#[derive(Clone, Debug)]
pub(super) struct NullSpace {
    pub(super) qr_work: DMatrix<f64>,
    pub(super) qr_q: DMatrix<f64>,
    /// V_{i−1}: orthonormal basis (n × (n − k)), and Vᵀ.
    pub(super) v: DMatrix<f64>,
    pub(super) vt: DMatrix<f64>,
    pub(super) v_prev: DMatrix<f64>,
    pub(super) has_prev: bool,
    pub(super) vdot: DMatrix<f64>,
    pub(super) vdot_t: DMatrix<f64>,
    pub(super) gram: DMatrix<f64>,
    pub(super) gram_inv: DMatrix<f64>,
    pub(super) t1: DMatrix<f64>,
    pub(super) t2: DMatrix<f64>,
    /// M V and Ṁ V (n × (n − k)).
    pub(super) mv: DMatrix<f64>,
    pub(super) mdv: DMatrix<f64>,
    /// VᵀMV, S = (VᵀMV)⁻¹ and X = d/dt (VᵀMV) = V̇ᵀMV + VᵀṀV + VᵀMV̇, so Ṡ = −S X S.
    pub(super) vtmv: DMatrix<f64>,
    pub(super) s: DMatrix<f64>,
    pub(super) x: DMatrix<f64>,
    pub(super) tmp_dd: DMatrix<f64>,
    /// J̄_rᵀ = M V S (n × (n − K)).
    pub(super) jbar_t: DMatrix<f64>,
    /// Vᵀ x and S Vᵀ x for the classical projector form.
    pub(super) y_nd: DVector<f64>,
    pub(super) y_nd2: DVector<f64>,
    /// J x and (J Jᵀ)⁻¹ J x for the kinematic projector form.
    pub(super) y_k: DVector<f64>,
    pub(super) y_k2: DVector<f64>,
    pub(super) spd_k: SpdWork,
    pub(super) spd_d: SpdWork,
    pub(super) align: AlignWork,
    pub(super) gram_cond: Conditioning,
    pub(super) s_cond: Conditioning,
}

impl NullSpace {
    /// The lowest level's null space for `r` levels on `n` joints: `ktop` rows
    /// above it, n − `ktop` columns (empty with a single level).
    pub(super) fn below(r: usize, n: usize, ktop: usize) -> NullSpace {
        if r > 1 {
            NullSpace::new(n, ktop, n - ktop)
        } else {
            NullSpace::new(0, 0, 0)
        }
    }

    /// Buffers for an `nb`-joint robot (0 without a null-space level), `kb` rows above
    /// the lowest level and an `nd`-dimensional null space.
    fn new(nb: usize, kb: usize, nd: usize) -> NullSpace {
        NullSpace {
            qr_work: DMatrix::zeros(nb, kb),
            qr_q: DMatrix::zeros(nb, nb),
            v: DMatrix::zeros(nb, nd),
            vt: DMatrix::zeros(nd, nb),
            v_prev: DMatrix::zeros(nb, nd),
            has_prev: false,
            vdot: DMatrix::zeros(nb, nd),
            vdot_t: DMatrix::zeros(nd, nb),
            gram: DMatrix::zeros(kb, kb),
            gram_inv: DMatrix::zeros(kb, kb),
            t1: DMatrix::zeros(kb, nd),
            t2: DMatrix::zeros(kb, nd),
            mv: DMatrix::zeros(nb, nd),
            mdv: DMatrix::zeros(nb, nd),
            vtmv: DMatrix::zeros(nd, nd),
            s: DMatrix::zeros(nd, nd),
            x: DMatrix::zeros(nd, nd),
            tmp_dd: DMatrix::zeros(nd, nd),
            jbar_t: DMatrix::zeros(nb, nd),
            y_nd: DVector::zeros(nd),
            y_nd2: DVector::zeros(nd),
            y_k: DVector::zeros(kb),
            y_k2: DVector::zeros(kb),
            spd_k: SpdWork::new(kb),
            spd_d: SpdWork::new(nd),
            align: AlignWork::new(nb, nd),
            gram_cond: Conditioning::default(),
            s_cond: Conditioning::default(),
        }
    }
}

impl Controller {
    /// Null space of the augmented Jacobian above the lowest level (eqs. 6–9): the
    /// basis V_{r−1}, its derivative V̇ = −J⁺ J̇ V (parallel transport), M V, Ṁ V,
    /// Vᵀ M V, its inverse S and X = d/dt (VᵀMV). The basis is kept continuous in
    /// time (Z_r = V_{r−1}ᵀ depends on it).
    pub(super) fn null_space(&mut self) -> Result<(), ControlError> {
        let eps = self.spec.singular_ratio;
        let ns = &mut self.basis;
        let (jaug, jaug_t, jaug_dot) = (&self.jtop, &self.jtop_t, &self.jtop_dot);
        // J⁺ = Jᵀ (J Jᵀ)⁻¹ (damped near singularities).
        gemm_nt(&mut ns.gram, 1.0, jaug, jaug, 0.0);
        ns.gram_cond =
            damped_spd_inverse(&ns.gram, &mut ns.gram_inv, &mut ns.spd_k, eps, GRAM_FLOOR);
        // The basis V: the previous cycle's basis projected onto the null space,
        // W = (I − J⁺ J) V_prev, and orthonormalised by its polar factor — the
        // orthonormal basis of null(J) closest to V_prev (the Procrustes-aligned one).
        // Unlike a fresh factorisation this stays continuous when J_aug loses rank
        // (the null space grows, W keeps following V_prev). Without a usable previous
        // basis (first cycle, after `reset`, or a jump of the state): Householder QR,
        // aligned to the previous basis when there is one.
        let mut continued = false;
        if ns.has_prev {
            gemm(&mut ns.t1, 1.0, jaug, &ns.v_prev, 0.0);
            gemm(&mut ns.t2, 1.0, &ns.gram_inv, &ns.t1, 0.0);
            copy(&mut ns.v, &ns.v_prev);
            gemm(&mut ns.v, -1.0, jaug_t, &ns.t2, 1.0);
            continued = orthonormalize_polar(&mut ns.v, &mut ns.align, MIN_OVERLAP) > MIN_OVERLAP;
        }
        if !continued {
            null_space_basis(jaug, &mut ns.qr_work, &mut ns.qr_q, &mut ns.v);
            if ns.has_prev {
                procrustes_align(&mut ns.v, &ns.v_prev, &mut ns.align);
            }
        }
        copy(&mut ns.v_prev, &ns.v);
        ns.has_prev = true;
        // V̇ = −J⁺ J̇ V (parallel transport).
        gemm(&mut ns.t1, 1.0, jaug_dot, &ns.v, 0.0);
        gemm(&mut ns.t2, 1.0, &ns.gram_inv, &ns.t1, 0.0);
        gemm(&mut ns.vdot, -1.0, jaug_t, &ns.t2, 0.0);
        // S = (VᵀMV)⁻¹ (always positive definite) and X = V̇ᵀMV + VᵀṀV + VᵀMV̇; the
        // products with Vᵀ and V̇ᵀ (= Z_r and Ż_r) by the column kernel, the symmetric
        // ones with the upper triangle mirrored.
        transpose_into(&mut ns.vt, &ns.v);
        transpose_into(&mut ns.vdot_t, &ns.vdot);
        gemm(&mut ns.mv, 1.0, &self.data.m, &ns.v, 0.0);
        gemm_sym(&mut ns.vtmv, &ns.vt, &ns.mv);
        ns.s_cond = damped_spd_inverse(&ns.vtmv, &mut ns.s, &mut ns.spd_d, eps, GRAM_FLOOR);
        gemm(&mut ns.mdv, 1.0, &self.mdot, &ns.v, 0.0);
        gemm_sym(&mut ns.x, &ns.vt, &ns.mdv);
        gemm(&mut ns.tmp_dd, 1.0, &ns.vdot_t, &ns.mv, 0.0);
        ns.x += &ns.tmp_dd;
        transpose_add(&mut ns.x, &ns.tmp_dd);
        Ok(())
    }
}
