//! The tracking form of the hierarchy (docs/tracking.md; after Dietrich &
//! Ott, "Hierarchical Impedance-Based Tracking Control of Kinematically
//! Redundant Robots", IEEE T-RO 36(1), 2020, derived here in the IROS 2013
//! paper's coordinates).
//!
//! A level that tracks has a desired x_{i,d}(t), ẋ_{i,d}(t), ẍ_{i,d}(t). The
//! desired local velocities follow level by level from q̇_d = Σ_j Z_jᵀ v_{j,d}
//! (eq. 13 with (J̄⁻¹)_1 = M⁻¹ J_1ᵀ Λ_1, (J̄⁻¹)_j = Z_jᵀ):
//!
//! v_{1,d} = ẋ_{1,d},  v_{i,d} = A_i⁺ (ẋ_{i,d} − J_i q̇_d^{(i−1)}),  A_i = J_i Z_iᵀ,
//!
//! q̇_d^{(i)} = q̇_d^{(i−1)} + Z_iᵀ v_{i,d} (T.1; A_i⁺ = A_i⁻¹ where A_i is square,
//! the least-squares or least-norm inverse for a lowest level that is not).
//! Then v_{i,d} = J̄_i q̇_d (J̄_i Z_jᵀ = δ_ij I), and J_j q̇_d = ẋ_{j,d} for
//! every level j whose A_j is square. Their derivatives along the motion,
//! with ṗ_j = Z_jᵀ v̇_{j,d} + Ż_jᵀ v_{j,d}:
//!
//! v̇_{1,d} = ẍ_{1,d},
//! v̇_{i,d} = A_i⁺ (ẍ_{i,d} − J̇_i q̇_d^{(i)} − J_i (Σ_{j<i} ṗ_j + Ż_iᵀ v_{i,d}))  (T.2)
//!
//! (from J_i q̈_d + J̇_i q̇_d = ẍ_{i,d}; exact where A_i is square). The
//! feed-forward of level i,
//!
//! τ_ff,i = J̄_iᵀ (Λ_i v̇_{i,d} + μ_ii v_{i,d}),  μ_ii v_{i,d} = Λ_i (J̄_i M⁻¹ C − J̄̇_i) Z_iᵀ v_{i,d}  (T.3)
//!
//! with τ_μ of eq. (22) unchanged (on the measured v_j), turns each level's
//! closed loop into (T.4)
//!
//! Λ_i ṽ̇_i + μ_ii ṽ_i + Z_i J_iᵀ F_i = (J̄⁻ᵀ τ_ext)_i,  ṽ_i = v_i − v_{i,d},
//!
//! F_i = ∂V_i/∂x_i(x̃_i)ᵀ + D_i (ẋ_i − ẋ_{i,d}) (level 1: Z_1 J_1ᵀ = I). With
//! every ẋ_{i,d} = ẍ_{i,d} = 0 the feed-forward vanishes and is not added:
//! the regulation law bit for bit. Allocation-free.

use super::Controller;
use hcc_linalg::products::{gemm_nt, gemm_tn, gemv, gemv_t};
use hcc_linalg::spd::{SpdWork, damped_spd_inverse};
use nalgebra::{DMatrix, DVector};

/// One level's tracking buffers and desired local velocities.
#[derive(Clone, Debug)]
pub(super) struct TrackLevel {
    /// The level receives the feed-forward (T.3).
    pub(super) on: bool,
    /// ẍ_{i,d} (zero for a level that does not track).
    pub(super) xdd: DVector<f64>,
    /// v_{i,d} and v̇_{i,d} (T.1, T.2).
    pub(super) vd: DVector<f64>,
    pub(super) vd_dot: DVector<f64>,
    /// J_i q̇_d^{(i−1)}: the velocity the levels above are meant to induce in
    /// level i (the energy tank counts the drag relative to it).
    pub(super) w_d: DVector<f64>,
    /// A_i = J_i Z_iᵀ (m × d), its Gram matrix (the smaller of AᵀA, AAᵀ), the
    /// Gram matrix's damped inverse and workspace.
    a: DMatrix<f64>,
    gram: DMatrix<f64>,
    gram_inv: DMatrix<f64>,
    spd: SpdWork,
    rhs: DVector<f64>,
    sol: DVector<f64>,
}

impl TrackLevel {
    /// Buffers for a level of task dimension `m` and local dimension `d`.
    pub(super) fn new(m: usize, d: usize) -> TrackLevel {
        let s = m.min(d);
        TrackLevel {
            on: false,
            xdd: DVector::zeros(m),
            vd: DVector::zeros(d),
            vd_dot: DVector::zeros(d),
            w_d: DVector::zeros(m),
            a: DMatrix::zeros(m, d),
            gram: DMatrix::zeros(s, s),
            gram_inv: DMatrix::zeros(s, s),
            spd: SpdWork::new(s),
            rhs: DVector::zeros(m),
            sol: DVector::zeros(s),
        }
    }

    /// out = A⁺ rhs with the Gram matrix's damped inverse of this cycle.
    fn solve(&mut self, out: &mut DVector<f64>) {
        let (m, d) = self.a.shape();
        if m >= d {
            // (AᵀA)⁻¹ Aᵀ b.
            gemv_t(&mut self.sol, 1.0, &self.a, &self.rhs, 0.0);
            gemv(out, 1.0, &self.gram_inv, &self.sol, 0.0);
        } else {
            // Aᵀ (AAᵀ)⁻¹ b.
            gemv(&mut self.sol, 1.0, &self.gram_inv, &self.rhs, 0.0);
            gemv_t(out, 1.0, &self.a, &self.sol, 0.0);
        }
    }
}

/// The desired joint velocity and acceleration parts the levels build up.
#[derive(Clone, Debug)]
pub(super) struct TrackWork {
    /// q̇_d^{(i)} = Σ_{j≤i} Z_jᵀ v_{j,d}.
    qd_d: DVector<f64>,
    /// Σ_{j<i} ṗ_j.
    pdot: DVector<f64>,
    /// Z_iᵀ v_{i,d}, Ż_iᵀ v_{i,d} and scratch (n).
    p: DVector<f64>,
    zdot_v: DVector<f64>,
    e: DVector<f64>,
    t: DVector<f64>,
    /// Level 1's m_1-vectors.
    y1: DVector<f64>,
    c1: DVector<f64>,
    /// The feed-forward was formed this cycle (some level tracks and moves).
    pub(super) active: bool,
}

impl TrackWork {
    pub(super) fn new(n: usize, m1: usize) -> TrackWork {
        TrackWork {
            qd_d: DVector::zeros(n),
            pdot: DVector::zeros(n),
            p: DVector::zeros(n),
            zdot_v: DVector::zeros(n),
            e: DVector::zeros(n),
            t: DVector::zeros(n),
            y1: DVector::zeros(m1),
            c1: DVector::zeros(m1),
            active: false,
        }
    }
}

impl Controller {
    /// The lowest level that tracks and has a moving desired value somewhere
    /// at or above it, or `None` (then nothing is formed: the regulation law).
    fn tracking_depth(&self) -> Option<usize> {
        let last = self.levels.iter().rposition(|l| l.track.on)?;
        let moving = self.levels[..=last]
            .iter()
            .any(|l| l.goal_moving || l.track.xdd.iter().any(|&a| a != 0.0));
        moving.then_some(last)
    }

    /// v_{i,d}, v̇_{i,d} of every level down to the lowest that tracks (T.1,
    /// T.2) and the feed-forward τ_ff = Σ_i β_i J̄_iᵀ (Λ_i v̇_{i,d} + μ_ii v_{i,d})
    /// of the levels that track (T.3; β_i the level's fade), into
    /// [`super::StepOutput::tau_feed_forward`]. After the decomposition and
    /// v_i, before the energy tanks.
    pub(super) fn tracking_feed_forward(&mut self) -> Result<(), crate::ControlError> {
        self.out.tau_feed_forward.fill(0.0);
        let depth = match self.tracking_depth() {
            Some(d) if self.spec.form == crate::spec::Form::Extended => d,
            _ => {
                if self.track.active {
                    for l in &mut self.levels {
                        l.track.vd.fill(0.0);
                        l.track.vd_dot.fill(0.0);
                        l.track.w_d.fill(0.0);
                    }
                }
                self.track.active = false;
                return Ok(());
            }
        };
        self.track.active = true;
        self.track.qd_d.fill(0.0);
        self.track.pdot.fill(0.0);
        // Each level's feed-forward right after its desired velocities, while
        // `track.p` holds its Z_iᵀ v_{i,d}.
        for i in 0..=depth {
            if i == 0 {
                self.first_level_desired()?;
            } else {
                self.level_desired(i);
            }
            if self.levels[i].track.on {
                self.level_feed_forward(i)?;
            }
        }
        Ok(())
    }

    /// Level 1 (T.1, T.2): v_{1,d} = ẋ_{1,d}, v̇_{1,d} = ẍ_{1,d}, and the
    /// joint-space parts p_1 = Z_1ᵀ v_{1,d}, ṗ_1 = Z_1ᵀ v̇_{1,d} + Ż_1ᵀ v_{1,d}
    /// with Z_1ᵀ = M⁻¹ J_1ᵀ Λ_1: e = M⁻¹ (J̇_1ᵀ Λ_1 v − Ṁ p_1), then
    /// Ż_1ᵀ v = e − Z_1ᵀ (J̇_1 p_1 + J_1 e) (Λ̇_1 = −Λ_1 Ẇ_11 Λ_1).
    fn first_level_desired(&mut self) -> Result<(), crate::ControlError> {
        let tw = &mut self.track;
        let l = &mut self.levels[0];
        let tl = &mut l.track;
        tl.w_d.fill(0.0);
        tl.vd.copy_from(&l.goal_velocity);
        tl.vd_dot.copy_from(&tl.xdd);
        gemv(&mut tw.p, 1.0, &l.jbar_inv, &tl.vd, 0.0);
        gemv(&mut tw.y1, 1.0, &l.lambda, &tl.vd, 0.0);
        gemv_t(&mut tw.e, 1.0, &l.jdot, &tw.y1, 0.0);
        gemv(&mut tw.e, -1.0, &self.mdot, &tw.p, 1.0);
        hcc_model::linalg::cholesky_solve_slice(self.chol.as_slice(), self.n, tw.e.as_mut_slice())
            .map_err(|_| crate::ControlError::Numerical("M⁻¹ in the tracking terms"))?;
        gemv(&mut tw.c1, 1.0, &l.jdot, &tw.p, 0.0);
        gemv(&mut tw.c1, 1.0, &l.j, &tw.e, 1.0);
        tw.zdot_v.copy_from(&tw.e);
        gemv(&mut tw.zdot_v, -1.0, &l.jbar_inv, &tw.c1, 1.0);
        tw.qd_d.copy_from(&tw.p);
        gemv(&mut tw.pdot, 1.0, &l.jbar_inv, &tl.vd_dot, 0.0);
        tw.pdot += &tw.zdot_v;
        Ok(())
    }

    /// Level i ≥ 2 (T.1, T.2): A_i = J_i Z_iᵀ and its Gram matrix's damped
    /// inverse, v_{i,d}, v̇_{i,d}, and q̇_d, Σ ṗ_j carried on.
    fn level_desired(&mut self, i: usize) {
        let eps = self.spec.singular_ratio;
        let tw = &mut self.track;
        let l = &mut self.levels[i];
        let tl = &mut l.track;
        gemm_nt(&mut tl.a, 1.0, &l.j, &l.z, 0.0);
        if l.m >= l.d {
            gemm_tn(&mut tl.gram, 1.0, &tl.a, &tl.a, 0.0);
        } else {
            gemm_nt(&mut tl.gram, 1.0, &tl.a, &tl.a, 0.0);
        }
        damped_spd_inverse(
            &tl.gram,
            &mut tl.gram_inv,
            &mut tl.spd,
            eps * eps,
            super::GRAM_FLOOR,
        );
        // v_{i,d} = A⁺ (ẋ_{i,d} − J_i q̇_d^{(i−1)}) (T.1).
        gemv(&mut tl.w_d, 1.0, &l.j, &tw.qd_d, 0.0);
        tl.rhs.copy_from(&l.goal_velocity);
        tl.rhs -= &tl.w_d;
        let mut vd = std::mem::take(&mut tl.vd);
        tl.solve(&mut vd);
        tl.vd = vd;
        gemv_t(&mut tw.p, 1.0, &l.z, &tl.vd, 0.0);
        gemv_t(&mut tw.zdot_v, 1.0, &l.zdot, &tl.vd, 0.0);
        tw.qd_d += &tw.p;
        // v̇_{i,d} = A⁺ (ẍ_{i,d} − J̇_i q̇_d^{(i)} − J_i (Σ_{j<i} ṗ_j + Ż_iᵀ v_{i,d})) (T.2).
        tl.rhs.copy_from(&tl.xdd);
        gemv(&mut tl.rhs, -1.0, &l.jdot, &tw.qd_d, 1.0);
        tw.t.copy_from(&tw.pdot);
        tw.t += &tw.zdot_v;
        gemv(&mut tl.rhs, -1.0, &l.j, &tw.t, 1.0);
        let mut vd_dot = std::mem::take(&mut tl.vd_dot);
        tl.solve(&mut vd_dot);
        tl.vd_dot = vd_dot;
        gemv_t(&mut tw.pdot, 1.0, &l.z, &tl.vd_dot, 1.0);
        tw.pdot += &tw.zdot_v;
    }

    /// τ_ff += β_i J̄_iᵀ Λ_i (v̇_{i,d} + (J̄_i M⁻¹ C − J̄̇_i) u), u = Z_iᵀ v_{i,d}
    /// (T.3; J̄̇_i u as in eq. 22's chain, `coriolis.rs`); u is in `track.p`,
    /// where the level's desired velocities left it (the feed-forward uses
    /// `track.e` and `track.t` as scratch, which they no longer need).
    fn level_feed_forward(&mut self, i: usize) -> Result<(), crate::ControlError> {
        let tw = &mut self.track;
        let l = &mut self.levels[i];
        gemv(&mut tw.e, 1.0, &self.data.c, &tw.p, 0.0);
        hcc_model::linalg::cholesky_solve_slice(self.chol.as_slice(), self.n, tw.e.as_mut_slice())
            .map_err(|_| crate::ControlError::Numerical("M⁻¹ C in the tracking terms"))?;
        gemv(&mut l.y_d, 1.0, &l.jbar, &tw.e, 0.0);
        if i == 0 {
            gemv(&mut l.y_d, -1.0, &l.jdot, &tw.p, 1.0);
        } else {
            // J̄̇_i u = Λ_i⁻¹ (Ż_i M u + Z_i Ṁ u − Λ̇_i J̄_i u).
            gemv(&mut tw.t, 1.0, &self.data.m, &tw.p, 0.0);
            gemv(&mut l.y_d3, 1.0, &l.zdot, &tw.t, 0.0);
            gemv(&mut tw.t, 1.0, &self.mdot, &tw.p, 0.0);
            gemv(&mut l.y_d3, 1.0, &l.z, &tw.t, 1.0);
            gemv(&mut l.y_d2, 1.0, &l.jbar, &tw.p, 0.0);
            gemv(&mut l.y_d3, -1.0, &l.lambda_dot, &l.y_d2, 1.0);
            gemv(&mut l.y_d, -1.0, &l.lambda_inv, &l.y_d3, 1.0);
        }
        l.y_d += &l.track.vd_dot;
        gemv(&mut l.y_d2, 1.0, &l.lambda, &l.y_d, 0.0);
        gemv_t(
            &mut self.out.tau_feed_forward,
            self.out.fade[i],
            &l.jbar,
            &l.y_d2,
            1.0,
        );
        Ok(())
    }
}
