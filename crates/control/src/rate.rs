//! Gains the control rate can carry: the discrete-time stability of each
//! level's spring–damper at the control period T.
//!
//! A level's damper D_i and spring K_i act on the motion ẋ_i = J_i q̇ through
//! the inertia the arm shows in that direction. Sampled with a zero-order hold
//! at T, a mode of inertia m, stiffness k and damping d is stable only for
//! b = d T / m < 2 and a = k T² / m < 2 b (Jury's test of
//! z² + (a/2 + b − 2) z + (1 + a/2 − b) for the held torque on a double
//! integrator); near the bounds it rings. Per level
//!
//! b_i = T λ_max(W_i D_i),  a_i = T² λ_max(W_i K_i),  W_i = J_i M⁻¹ J_iᵀ,
//!
//! (the largest d/m over the directions of the task; the eigenvalues of W D are
//! those of L_Dᵀ W L_D with D = L_D L_Dᵀ, symmetric). W_i is the
//! task-space mobility of the whole arm, not restricted to the null space of the
//! levels above: an upper bound of the restricted one (a Rayleigh quotient over
//! a subspace is at most the one over the whole space), so the check may refuse
//! a lower level's gains that the hierarchy would carry, never the other way
//! round. The check asks b_i ≤ [`B_MAX`] (three quarters of the bound 2, a
//! margin for the coupling between levels and the robot's own delays) and
//! a_i ≤ [`A_MAX`] at the initial configuration (`Controller::new`) and for every gains
//! setpoint at the state of the cycle that takes it.
//!
//! Example: a bare FR3's joint 7 (inertia ≈ 6e-5 kg·m²) under a posture damping of
//! 2 N·m·s/rad at 1 kHz has b ≈ 33: the damper itself drives an oscillation.
//! D = 0.05 gives b ≈ 0.8.

use hcc_linalg::cholesky::{cholesky_in_place, cholesky_solve_matrix_in_place};
use hcc_linalg::eigen::symmetric_eigenvalues;
use hcc_linalg::products::{gemm, gemm_tn, transpose_into};
use nalgebra::{DMatrix, DVector};

/// Largest T λ_max(W D) accepted (the stability bound is 2).
pub const B_MAX: f64 = 1.5;
/// Largest T² λ_max(W K) accepted.
pub const A_MAX: f64 = 1.0;
/// Jacobi sweeps for the m × m eigenvalues (m ≤ n ≤ 16 converge in < 10).
const SWEEPS: usize = 30;

/// Which gain of a level the control rate cannot carry.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct GainRate {
    /// The level (0-based).
    pub level: usize,
    /// The damping (b) or the stiffness (a).
    pub damping: bool,
    /// b_i or a_i.
    pub value: f64,
    /// The bound it exceeds ([`B_MAX`] or [`A_MAX`]).
    pub bound: f64,
    /// The largest entry of the gain as given.
    pub largest_entry: f64,
    /// The control period T (s).
    pub period_s: f64,
}

impl GainRate {
    /// The factor by which the gain must be scaled down to be carried.
    pub fn scale(&self) -> f64 {
        self.bound / self.value
    }
}

impl std::fmt::Display for GainRate {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let (what, sym, expr) = if self.damping {
            ("damping", "D", "T·λmax(J M⁻¹ Jᵀ D)")
        } else {
            ("stiffness", "K", "T²·λmax(J M⁻¹ Jᵀ K)")
        };
        write!(
            f,
            "its {what} is more than the control rate ({:.0} Hz) can carry: {expr} = {:.3} > {} \
             (the arm is too light in that direction for it); scale {sym} by at most {:.3} \
             (its largest entry {} to at most {})",
            1.0 / self.period_s,
            self.value,
            self.bound,
            self.scale(),
            self.largest_entry,
            floor_significant(self.largest_entry * self.scale(), 4),
        )
    }
}

/// `x` > 0 rounded down to `digits` significant digits (a bound printed as
/// "at most" must hold as printed).
fn floor_significant(x: f64, digits: i32) -> f64 {
    if !(x > 0.0 && x.is_finite()) {
        return x;
    }
    let p = 10f64.powi(digits - 1 - x.log10().floor() as i32);
    (x * p).floor() / p
}

/// Buffers of the check for a task of m rows and n joints.
#[derive(Clone, Debug)]
pub struct RateWork {
    /// M⁻¹ J_iᵀ (n × m).
    y: DMatrix<f64>,
    /// W = J_i M⁻¹ J_iᵀ (m × m).
    w: DMatrix<f64>,
    /// L_G, the Cholesky factor of the gain (m × m).
    lg: DMatrix<f64>,
    /// W L_G, then L_Gᵀ W L_G (m × m).
    t: DMatrix<f64>,
    u: DMatrix<f64>,
    evals: DVector<f64>,
}

impl RateWork {
    /// Buffers for m rows and n joints.
    pub fn new(m: usize, n: usize) -> RateWork {
        RateWork {
            y: DMatrix::zeros(n, m),
            w: DMatrix::zeros(m, m),
            lg: DMatrix::zeros(m, m),
            t: DMatrix::zeros(m, m),
            u: DMatrix::zeros(m, m),
            evals: DVector::zeros(m),
        }
    }

    /// W = J M⁻¹ Jᵀ of the Jacobian `j` (m × n) and the Cholesky factor `chol`
    /// of M (lower triangle), kept for [`RateWork::lambda_max`]. False if a solve
    /// fails. Allocation-free.
    pub fn set_mobility(&mut self, chol: &DMatrix<f64>, j: &DMatrix<f64>) -> bool {
        transpose_into(&mut self.y, j);
        if cholesky_solve_matrix_in_place(chol, &mut self.y).is_err() {
            return false;
        }
        gemm(&mut self.w, 1.0, j, &self.y, 0.0);
        true
    }

    /// λ_max(W G) of the symmetric positive definite gain `g` (m × m) and the
    /// mobility of the last [`RateWork::set_mobility`]; ∞ if `g` is not positive
    /// definite. Allocation-free.
    pub fn lambda_max(&mut self, g: &DMatrix<f64>) -> f64 {
        self.lg.copy_from(g);
        if cholesky_in_place(&mut self.lg).is_err() {
            return f64::INFINITY;
        }
        gemm(&mut self.t, 1.0, &self.w, &self.lg, 0.0);
        gemm_tn(&mut self.u, 1.0, &self.lg, &self.t, 0.0);
        // Symmetric up to rounding: symmetrise before the Jacobi sweeps.
        let m = self.u.nrows();
        for a in 0..m {
            for b in 0..a {
                let s = 0.5 * (self.u[(a, b)] + self.u[(b, a)]);
                self.u[(a, b)] = s;
                self.u[(b, a)] = s;
            }
        }
        symmetric_eigenvalues(&mut self.u, &mut self.evals, SWEEPS);
        self.evals.iter().copied().fold(0.0, f64::max)
    }
}

/// Checks the gains of level `level` (stiffness `k`, damping `d`) against the
/// mobility in `work` ([`RateWork::set_mobility`]) at the period `period_s`.
/// Allocation-free.
pub fn check_level(
    work: &mut RateWork,
    level: usize,
    k: &DMatrix<f64>,
    d: &DMatrix<f64>,
    period_s: f64,
) -> Result<(), GainRate> {
    let largest = |g: &DMatrix<f64>| g.iter().fold(0.0_f64, |m, x| m.max(x.abs()));
    let b = period_s * work.lambda_max(d);
    if b.is_nan() || b > B_MAX {
        return Err(GainRate {
            level,
            damping: true,
            value: b,
            bound: B_MAX,
            largest_entry: largest(d),
            period_s,
        });
    }
    let a = period_s * period_s * work.lambda_max(k);
    if a.is_nan() || a > A_MAX {
        return Err(GainRate {
            level,
            damping: false,
            value: a,
            bound: A_MAX,
            largest_entry: largest(k),
            period_s,
        });
    }
    Ok(())
}
