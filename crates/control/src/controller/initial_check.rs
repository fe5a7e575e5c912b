//! The rank checks at the initial configuration (Sec. II): full row rank of
//! every J_i and of the augmented Jacobians (eq. 6), no algorithmic
//! singularity (Z_i M Z_iᵀ of eq. 18 regular), the lowest level filling the
//! remaining null space, and gains the control rate carries. Construction
//! only (allocates).

use super::{Controller, GRAM_FLOOR};
use crate::ControlError;
use hcc_linalg::products::{gemm, gemm_nt, gemm_tn};
use hcc_linalg::spd::{Conditioning, SpdWork, damped_spd_inverse};
use nalgebra::{DMatrix, DVector};

/// The conditioning of the damped inverse of the Gram matrix `g` (allocates).
fn gram_conditioning(g: &DMatrix<f64>, eps: f64) -> Conditioning {
    let mut inv = g.clone();
    damped_spd_inverse(g, &mut inv, &mut SpdWork::new(g.nrows()), eps, GRAM_FLOOR)
}

impl Controller {
    /// Rank checks at the initial configuration (Sec. II: full row rank of every J_i and
    /// of the augmented Jacobians; the lowest level must fill the remaining null space).
    pub(super) fn check_initial(&mut self, q0: &DVector<f64>) -> Result<(), ControlError> {
        let zero = DVector::zeros(self.n);
        self.compute(q0, &zero)
            .map_err(|e| ControlError::Spec(format!("at the initial configuration: {e}")))?;
        let r = self.levels.len();
        for i in 0..r {
            let checks = self
                .check_row_rank(i)
                // The gains the control rate carries (crate::rate).
                .and_then(|()| {
                    self.check_gain_rate(i, None, None)
                        .map_err(|e| e.to_string())
                })
                .and_then(|()| self.check_above(i))
                .and_then(|()| self.check_fills_null_space(i));
            if let Err(why) = checks {
                return Err(ControlError::Level {
                    level: format!("{} ({})", i + 1, self.spec.levels[i].name),
                    why,
                });
            }
        }
        Ok(())
    }

    /// J_i J_iᵀ of full rank (not required of the lowest level, which may be
    /// larger than the remaining null space).
    fn check_row_rank(&self, i: usize) -> Result<(), String> {
        let (r, eps) = (self.levels.len(), self.spec.singular_ratio);
        if !(i < r - 1 || r == 1) {
            return Ok(());
        }
        let lv = &self.levels[i];
        let mut g = DMatrix::zeros(lv.m, lv.m);
        gemm_nt(&mut g, 1.0, &lv.j, &lv.j, 0.0);
        let c = gram_conditioning(&g, eps);
        if c.damping > 0.0 || c.ratio < eps {
            return Err(format!(
                "its Jacobian is singular at the initial configuration (eigenvalue ratio of J Jᵀ {:.3e})",
                c.ratio
            ));
        }
        Ok(())
    }

    /// For a level i ≥ 2: the augmented Jacobian of the levels above it of full
    /// row rank (eq. 6), and its own decomposition regular (Z_i M Z_iᵀ, eq. 18).
    fn check_above(&self, i: usize) -> Result<(), String> {
        let (r, eps) = (self.levels.len(), self.spec.singular_ratio);
        if i == 0 {
            return Ok(());
        }
        let gc = if i == r - 1 {
            self.basis.gram_cond
        } else {
            self.levels[i].proj.g_cond
        };
        if gc.ratio < eps {
            return Err(format!(
                "the Jacobians of the levels above it are not independent at the initial configuration (augmented Jacobian eigenvalue ratio {:.3e})",
                gc.ratio
            ));
        }
        if self.out.singular[i] {
            let why = if i == r - 1 {
                "it cannot fill the remaining null space: J_r V_{r-1} is rank deficient at the initial configuration"
            } else {
                "algorithmic singularity at the initial configuration: its task conflicts with the levels above (Z_i M Z_iᵀ singular)"
            };
            return Err(why.into());
        }
        Ok(())
    }

    /// The lowest level must span the remaining null space: J_r V_{r−1} of full
    /// column rank.
    fn check_fills_null_space(&self, i: usize) -> Result<(), String> {
        let (r, eps) = (self.levels.len(), self.spec.singular_ratio);
        if !(i == r - 1 && r > 1) {
            return Ok(());
        }
        let (lv, ns) = (&self.levels[i], &self.basis);
        let d = ns.v.ncols();
        let mut jv = DMatrix::zeros(lv.m, d);
        gemm(&mut jv, 1.0, &lv.j, &ns.v, 0.0);
        let mut g = DMatrix::zeros(d, d);
        gemm_tn(&mut g, 1.0, &jv, &jv, 0.0);
        let c = gram_conditioning(&g, eps);
        if c.ratio < eps || lv.m < d {
            return Err(format!(
                "the lowest level cannot fill the remaining {d}-dimensional null space (its task has {} dimensions; ratio {:.3e})",
                lv.m, c.ratio
            ));
        }
        Ok(())
    }
}
