//! A joint velocity limit that holds in discrete time for the torque that is
//! sent (after the saturation), one control period ahead.
//!
//! With τ held over the period T, the model the law already has predicts
//!
//! q̇⁺ = q̇ + T q̈,  q̈ = M⁻¹ (τ − h),  h = C q̇ (+ g where τ contains it).
//!
//! |q̇⁺_k| ≤ v̄_k = [`VELOCITY_LIMIT_FRACTION`] · v_max,k is, for the change
//! a = M⁻¹ Δτ of the acceleration that a correction Δτ makes, a box
//! l ≤ a ≤ u with l_k = (−v̄_k − q̇_k)/T − q̈_k, u_k = (v̄_k − q̇_k)/T − q̈_k.
//! The smallest correction in the metric of the kinetic energy,
//!
//! min ½ Δτᵀ M⁻¹ Δτ = ½ aᵀ M a  subject to  l ≤ a ≤ u,
//!
//! is a small box-constrained QP (n variables), solved exactly by an active
//! set (a fixed number of iterations; allocation-free). Where 0 is inside the
//! box (every joint stays below v̄ in the next period) nothing is done and τ is
//! bit for bit the law's.
//!
//! **It only removes energy.** The KKT conditions give M a + μ = 0 with a
//! multiplier μ_k ≥ 0 on a joint held at its upper bound (≤ 0 at its lower, 0
//! where free), so Δτ = M a = −μ: a torque on the limited joints only, against
//! the bound that holds them. Its power Δτᵀ q̇ = −Σ μ_k q̇_k is ≤ 0 whenever each
//! limited joint moves towards the bound it is held at. The other case — the
//! upper bound active while q̇_k < 0 — needs the law to reverse the joint by
//! more than v̄_k + |q̇_k| within one period; the correction then holds that
//! reversal to v̄_k (it takes away torque that would drive the joint past its
//! limit the other way).
//!
//! Without a torque-rate limit downstream the correction arrives in the period
//! it is computed for, so the bound holds up to the model's drift within a
//! period. With a rate limit the torque cannot follow it within a period (the
//! cycle leaves that case to the velocity barrier of [`crate::safety`]).
//!
//! Where the active set does not settle within its iterations (or a sub-block
//! of M cannot be factored), the last iterate is projected onto the box: a
//! correction that still keeps every bound, not the smallest (counted in
//! [`VelocityLimitOutcome::fallback`]).

use hcc_linalg::cholesky::{cholesky_in_place_slice, cholesky_solve_slice};
use hcc_linalg::products::gemv;
use nalgebra::{DMatrix, DVector};

/// The share of the URDF velocity limit the next period's predicted speed is
/// held to: 0.01 below the 0.95 the sweeps assert, for the model's drift
/// within a period (measured on the fast-goal sweep: 1e-4 of the limit).
pub const VELOCITY_LIMIT_FRACTION: f64 = 0.94;

/// Where a joint is in the active set.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Bound {
    Free,
    Lower,
    Upper,
}

/// What the limit did to one torque.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct VelocityLimitOutcome {
    /// A joint's next-period speed would have passed v̄: τ was corrected.
    pub acted: bool,
    /// The largest |Δτ_k| of the correction (N·m; 0 when it did not act).
    pub largest_correction: f64,
    /// The active set did not settle: the projected iterate was used.
    pub fallback: bool,
}

/// The preallocated storage of [`limit_velocity`] for `n` joints.
#[derive(Clone, Debug)]
pub struct VelocityLimitWork {
    qdd: DVector<f64>,
    lo: Vec<f64>,
    hi: Vec<f64>,
    a: DVector<f64>,
    ma: DVector<f64>,
    bound: Vec<Bound>,
    free: Vec<usize>,
    sub: Vec<f64>,
    rhs: Vec<f64>,
}

impl VelocityLimitWork {
    /// Storage for `n` joints (allocates).
    pub fn new(n: usize) -> VelocityLimitWork {
        VelocityLimitWork {
            qdd: DVector::zeros(n),
            lo: vec![0.0; n],
            hi: vec![0.0; n],
            a: DVector::zeros(n),
            ma: DVector::zeros(n),
            bound: vec![Bound::Free; n],
            free: Vec::with_capacity(n),
            sub: vec![0.0; n * n],
            rhs: vec![0.0; n],
        }
    }
}

/// What the prediction of one period needs: `m` = M(q), `chol` its Cholesky
/// factor (lower), `h` = C q̇ (+ g where τ contains g), `qd` = q̇, `v_max` the
/// URDF velocity limits (a non-finite one: no limit), `period_s` = T.
#[derive(Clone, Copy, Debug)]
pub struct PeriodModel<'a> {
    pub m: &'a DMatrix<f64>,
    pub chol: &'a DMatrix<f64>,
    pub h: &'a DVector<f64>,
    pub qd: &'a [f64],
    pub v_max: &'a [f64],
    pub period_s: f64,
}

/// The one-period velocity limit (module docs) on the torque `tau` about to be
/// sent, in place, at the state and with the model of `p`. Allocation-free.
pub fn limit_velocity(
    p: &PeriodModel<'_>,
    tau: &mut [f64],
    w: &mut VelocityLimitWork,
) -> VelocityLimitOutcome {
    let (m, chol, h, qd, v_max, period_s) = (p.m, p.chol, p.h, p.qd, p.v_max, p.period_s);
    let n = tau.len();
    let mut out = VelocityLimitOutcome::default();
    // q̈ = M⁻¹ (τ − h).
    for k in 0..n {
        w.qdd[k] = tau[k] - h[k];
    }
    if hcc_linalg::cholesky::cholesky_solve_in_place(chol, &mut w.qdd).is_err() {
        return out;
    }
    let mut inside = true;
    for k in 0..n {
        let vbar = VELOCITY_LIMIT_FRACTION * v_max[k];
        if !vbar.is_finite() || !w.qdd[k].is_finite() {
            (w.lo[k], w.hi[k]) = (f64::NEG_INFINITY, f64::INFINITY);
            continue;
        }
        w.lo[k] = (-vbar - qd[k]) / period_s - w.qdd[k];
        w.hi[k] = (vbar - qd[k]) / period_s - w.qdd[k];
        inside &= w.lo[k] <= 0.0 && w.hi[k] >= 0.0;
    }
    if inside {
        return out;
    }
    out.fallback = !solve_box_qp(m, w);
    // Δτ = M a: the correction.
    gemv(&mut w.ma, 1.0, m, &w.a, 0.0);
    for (t, d) in tau.iter_mut().zip(w.ma.iter()) {
        *t += d;
        out.largest_correction = out.largest_correction.max(d.abs());
    }
    out.acted = true;
    out
}

/// min ½ aᵀ M a over lo ≤ a ≤ hi into `w.a` by a primal–dual active set;
/// false when it did not settle (then `w.a` is the projected last iterate).
fn solve_box_qp(m: &DMatrix<f64>, w: &mut VelocityLimitWork) -> bool {
    let n = w.a.len();
    // Start at a = 0 with every violated bound active.
    for k in 0..n {
        (w.bound[k], w.a[k]) = if w.lo[k] > 0.0 {
            (Bound::Lower, w.lo[k])
        } else if w.hi[k] < 0.0 {
            (Bound::Upper, w.hi[k])
        } else {
            (Bound::Free, 0.0)
        };
    }
    for _ in 0..4 * n + 4 {
        if !solve_free(m, w) {
            break;
        }
        // Primal: the free joint furthest outside its box comes to its bound.
        let mut worst = (0.0, n, Bound::Free);
        for k in 0..n {
            if w.bound[k] != Bound::Free {
                continue;
            }
            if w.lo[k] - w.a[k] > worst.0 {
                worst = (w.lo[k] - w.a[k], k, Bound::Lower);
            } else if w.a[k] - w.hi[k] > worst.0 {
                worst = (w.a[k] - w.hi[k], k, Bound::Upper);
            }
        }
        if worst.1 < n {
            let k = worst.1;
            w.bound[k] = worst.2;
            w.a[k] = if worst.2 == Bound::Lower {
                w.lo[k]
            } else {
                w.hi[k]
            };
            continue;
        }
        // Dual: μ = −M a ≥ 0 at an upper bound, ≤ 0 at a lower; the joint with
        // the wrong sign furthest is freed.
        gemv(&mut w.ma, 1.0, m, &w.a, 0.0);
        let mut wrong = (0.0, n);
        for k in 0..n {
            let g = match w.bound[k] {
                Bound::Upper => w.ma[k],
                Bound::Lower => -w.ma[k],
                Bound::Free => continue,
            };
            if g > wrong.0 {
                wrong = (g, k);
            }
        }
        if wrong.1 == n {
            return true;
        }
        w.bound[wrong.1] = Bound::Free;
    }
    for k in 0..n {
        w.a[k] = w.a[k].clamp(w.lo[k], w.hi[k]);
    }
    false
}

/// The free joints F of the active set: M_FF a_F = −M_FA a_A (allocation-free);
/// false when M_FF cannot be factored.
fn solve_free(m: &DMatrix<f64>, w: &mut VelocityLimitWork) -> bool {
    let n = w.a.len();
    w.free.clear();
    w.free.extend((0..n).filter(|&k| w.bound[k] == Bound::Free));
    let f = w.free.len();
    if f == 0 {
        return true;
    }
    for (r, &i) in w.free.iter().enumerate() {
        let mut s = 0.0;
        for k in 0..n {
            if w.bound[k] != Bound::Free {
                s -= m[(i, k)] * w.a[k];
            }
        }
        w.rhs[r] = s;
        for (c, &j) in w.free.iter().enumerate() {
            w.sub[c * f + r] = m[(i, j)];
        }
    }
    let sub = &mut w.sub[..f * f];
    if cholesky_in_place_slice(sub, f).is_err()
        || cholesky_solve_slice(sub, f, &mut w.rhs[..f]).is_err()
    {
        return false;
    }
    for (r, &i) in w.free.iter().enumerate() {
        w.a[i] = w.rhs[r];
    }
    true
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A coupled SPD inertia (a light last joint, as a wrist).
    fn inertia() -> DMatrix<f64> {
        let b = DMatrix::from_fn(4, 4, |i, j| ((i * 4 + j) as f64 * 0.7).sin());
        let mut m = &b * b.transpose() * 0.3
            + DMatrix::from_diagonal(&DVector::from_vec(vec![2.0, 1.5, 0.6, 0.02]));
        m[(3, 3)] += 0.01;
        m
    }

    fn factor(m: &DMatrix<f64>) -> DMatrix<f64> {
        m.clone().cholesky().unwrap().l()
    }

    fn next_speed(m: &DMatrix<f64>, h: &DVector<f64>, qd: &[f64], tau: &[f64], t: f64) -> Vec<f64> {
        let qdd = m
            .clone()
            .cholesky()
            .unwrap()
            .solve(&(DVector::from_column_slice(tau) - h));
        qd.iter().zip(qdd.iter()).map(|(v, a)| v + t * a).collect()
    }

    #[test]
    fn far_from_the_limits_the_torque_is_untouched_bit_for_bit() {
        let m = inertia();
        let h = DVector::from_vec(vec![0.3, -0.2, 0.1, 0.01]);
        let tau0 = [1.0, -2.0, 0.5, 0.001];
        let mut tau = tau0;
        let mut w = VelocityLimitWork::new(4);
        let chol = factor(&m);
        let p = PeriodModel {
            m: &m,
            chol: &chol,
            h: &h,
            qd: &[0.1, 0.0, -0.2, 0.3],
            v_max: &[2.0; 4],
            period_s: 1e-3,
        };
        let out = limit_velocity(&p, &mut tau, &mut w);
        assert!(!out.acted);
        assert_eq!(tau.map(f64::to_bits), tau0.map(f64::to_bits));
    }

    #[test]
    fn the_next_speed_is_held_at_the_bound_by_the_smallest_correction_that_removes_energy() {
        let m = inertia();
        let h = DVector::from_vec(vec![0.3, -0.2, 0.1, 0.01]);
        let (t, vmax) = (1e-3, [2.0; 4]);
        let mut w = VelocityLimitWork::new(4);
        // The wrist at 1.8 rad/s pushed on hard; the shoulder at −1.85 pushed further.
        let qd = [-1.85, 0.2, 0.0, 1.8];
        let tau0 = [-400.0, 5.0, 2.0, 150.0];
        // Without the limit, joints 1 and 4 would pass the bound.
        let v0 = next_speed(&m, &h, &qd, &tau0, t);
        assert!(v0[0] < -1.88 && v0[3] > 1.88, "{v0:?}");
        let mut tau = tau0;
        let chol = factor(&m);
        let p = PeriodModel {
            m: &m,
            chol: &chol,
            h: &h,
            qd: &qd,
            v_max: &vmax,
            period_s: t,
        };
        let out = limit_velocity(&p, &mut tau, &mut w);
        assert!(out.acted && !out.fallback, "{out:?}");
        let v = next_speed(&m, &h, &qd, &tau, t);
        for (k, v) in v.iter().enumerate() {
            assert!(
                v.abs() <= VELOCITY_LIMIT_FRACTION * vmax[k] * (1.0 + 1e-9),
                "joint {k}: {v}"
            );
        }
        // The correction acts on the limited joints only, against their motion.
        let d: Vec<f64> = tau.iter().zip(&tau0).map(|(a, b)| a - b).collect();
        assert!(d[0] > 0.0 && d[3] < 0.0, "{d:?}");
        assert!(
            d[1].abs() < 1e-9 * out.largest_correction
                && d[2].abs() < 1e-9 * out.largest_correction,
            "{d:?}"
        );
        let power: f64 = d.iter().zip(&qd).map(|(a, b)| a * b).sum();
        assert!(power < 0.0);
        // KKT against every single-joint perturbation that keeps the box: no
        // smaller correction in the M⁻¹ metric.
        let cost = |tau: &[f64]| {
            let d = DVector::from_iterator(4, tau.iter().zip(&tau0).map(|(a, b)| a - b));
            d.dot(&m.clone().cholesky().unwrap().solve(&d))
        };
        let best = cost(&tau);
        for k in 0..4 {
            for s in [-1e-4, 1e-4] {
                let mut p = tau;
                p[k] += s;
                let v = next_speed(&m, &h, &qd, &p, t);
                if v.iter()
                    .zip(&vmax)
                    .all(|(v, l)| v.abs() <= VELOCITY_LIMIT_FRACTION * l)
                {
                    assert!(cost(&p) >= best - 1e-12, "joint {k} {s}");
                }
            }
        }
    }
}
