//! The external wrench at a task frame from the estimate of the external
//! joint torque: F̂ = pinv(J_iᵀ) r = (J_i J_iᵀ)⁻¹ J_i r, with J_i the task
//! Jacobian of the wrench level (`hcc_control::ControllerSpec::wrench_level`:
//! the first position or pose level) at the state the law used.
//!
//! For a wrench F acting at the frame alone, r → τ_ext = J_iᵀ F and, J_i
//! having full row rank, F̂ → F (Haddadin, De Luca & Albu-Schäffer, T-RO
//! 2017, §V "contact isolation and identification"). Near a singularity of
//! J_i the Gram matrix J_i J_iᵀ is inverted damped, with the law's
//! `singular_ratio` (`hcc_linalg::spd::damped_spd_inverse_only`): F̂ stays
//! bounded, the components along the lost direction are underestimated.
//! Rows: the level's task rows (forces along its selected world axes, N;
//! for a pose then moments about the world axes at the frame, N·m).
//! Allocation-free after construction.

use hcc_linalg::products::{gemm_nt, gemv_slices};
use hcc_linalg::spd::{SpdWork, damped_spd_inverse_only};
use nalgebra::{DMatrix, DVector};

/// The smallest eigenvalue the Gram matrix's damping keeps clear of (as the
/// law's inversions).
const GRAM_FLOOR: f64 = 1e-12;

/// F̂ of one level, with its workspace.
pub(crate) struct WrenchEstimate {
    /// The level (0-based), `None`: no position or pose level, F̂ is empty.
    level: Option<usize>,
    /// J_i J_iᵀ and its (damped) inverse, m × m.
    gram: DMatrix<f64>,
    gram_inv: DMatrix<f64>,
    work: SpdWork,
    /// J_i r.
    jr: DVector<f64>,
    /// F̂ (length m).
    wrench: DVector<f64>,
    /// The eigenvalue ratio below which the Gram matrix is damped.
    eps: f64,
}

impl WrenchEstimate {
    /// The estimate at `level`, of `m` rows (`None`: none), damped below the
    /// eigenvalue ratio `eps`.
    pub(crate) fn new(level: Option<usize>, m: usize, eps: f64) -> WrenchEstimate {
        let m = if level.is_some() { m } else { 0 };
        WrenchEstimate {
            level,
            gram: DMatrix::zeros(m, m),
            gram_inv: DMatrix::zeros(m, m),
            work: SpdWork::new(m),
            jr: DVector::zeros(m),
            wrench: DVector::zeros(m),
            eps,
        }
    }

    /// The level F̂ is estimated at.
    pub(crate) fn level(&self) -> Option<usize> {
        self.level
    }

    /// F̂ (empty without a wrench level).
    pub(crate) fn wrench(&self) -> &[f64] {
        self.wrench.as_slice()
    }

    /// F̂ = 0 (with r = 0: a reset of the observer).
    pub(crate) fn clear(&mut self) {
        self.wrench.fill(0.0);
    }

    /// F̂ from r and the level's task Jacobian `j` (m × n) at the same
    /// state. Allocation-free.
    pub(crate) fn update(&mut self, j: &DMatrix<f64>, r: &[f64]) {
        if self.level.is_none() || j.nrows() != self.jr.len() {
            return;
        }
        gemm_nt(&mut self.gram, 1.0, j, j, 0.0);
        damped_spd_inverse_only(
            &self.gram,
            &mut self.gram_inv,
            &mut self.work,
            self.eps,
            GRAM_FLOOR,
        );
        gemv_slices(self.jr.as_mut_slice(), 1.0, j, r, 0.0);
        gemv_slices(
            self.wrench.as_mut_slice(),
            1.0,
            &self.gram_inv,
            self.jr.as_slice(),
            0.0,
        );
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_wrench_mapped_to_the_joints_comes_back() {
        // A 3 × 7 Jacobian of full row rank and r = Jᵀ F.
        let j = DMatrix::from_fn(3, 7, |i, k| {
            ((i * 5 + k * 3) % 7) as f64 * 0.1 - 0.3 + 0.05 * (i == k) as u8 as f64
        });
        let f = DVector::from_vec(vec![1.0, -15.0, 4.0]);
        let r = j.transpose() * &f;
        let mut w = WrenchEstimate::new(Some(0), 3, 1e-6);
        w.update(&j, r.as_slice());
        for (a, b) in w.wrench().iter().zip(f.iter()) {
            assert!((a - b).abs() < 1e-9 * 15.0, "{a} vs {b}");
        }
        w.clear();
        assert!(w.wrench().iter().all(|x| *x == 0.0));
    }

    #[test]
    fn a_singular_jacobian_gives_a_bounded_estimate() {
        // Two equal rows: J Jᵀ is singular; the damped inverse stays finite.
        let mut j = DMatrix::from_fn(3, 7, |i, k| (i + k) as f64 * 0.1);
        let row = j.row(0).clone_owned();
        j.set_row(1, &row);
        let r = vec![1.0; 7];
        let mut w = WrenchEstimate::new(Some(0), 3, 1e-6);
        w.update(&j, &r);
        assert!(w.wrench().iter().all(|x| x.is_finite()));
    }

    #[test]
    fn without_a_level_the_estimate_is_empty() {
        let mut w = WrenchEstimate::new(None, 3, 1e-6);
        w.update(&DMatrix::zeros(3, 7), &[0.0; 7]);
        assert!(w.wrench().is_empty());
        assert_eq!(w.level(), None);
    }
}
