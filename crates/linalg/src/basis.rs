//! Orthonormal bases of a null space: a Householder QR basis, and the basis
//! closest to a previous one (the orthogonal Procrustes alignment, by the
//! polar factor), so that a basis continues smoothly from cycle to cycle.
//! Allocation-free.

use nalgebra::{DMatrix, DVector};

use crate::eigen::symmetric_eigen;
use crate::products::{copy, gemm, gemm_sym, gemm_tn, transpose_into};

/// Orthonormal basis of the null space of `a` (k×n, k < n) into `v` (n×(n−k)),
/// from the Householder QR decomposition of `aᵀ` (Golub & Van Loan, Alg. 5.2.1):
/// `aᵀ = Q R`, the last n−k columns of Q span null(a). `work` (n×k) receives
/// the factorisation, `q` (n×n) the accumulated Q. Deterministic for a given `a`.
pub fn null_space_basis(
    a: &DMatrix<f64>,
    work: &mut DMatrix<f64>,
    q: &mut DMatrix<f64>,
    v: &mut DMatrix<f64>,
) {
    let (k, n) = a.shape();
    for i in 0..n {
        for j in 0..k {
            work[(i, j)] = a[(j, i)];
        }
    }
    q.fill_with_identity();
    for j in 0..k.min(n) {
        // Householder vector for column j below the diagonal, stored in place.
        let mut norm2 = 0.0;
        for i in j..n {
            norm2 += work[(i, j)] * work[(i, j)];
        }
        let norm = norm2.sqrt();
        if norm == 0.0 {
            continue;
        }
        let x0 = work[(j, j)];
        let alpha = if x0 >= 0.0 { -norm } else { norm };
        work[(j, j)] = x0 - alpha;
        let mut vnorm2 = 0.0;
        for i in j..n {
            vnorm2 += work[(i, j)] * work[(i, j)];
        }
        if vnorm2 == 0.0 {
            continue;
        }
        let beta = 2.0 / vnorm2;
        // Apply H = I − beta u uᵀ to the remaining columns of work.
        for c in (j + 1)..k {
            let mut s = 0.0;
            for i in j..n {
                s += work[(i, j)] * work[(i, c)];
            }
            s *= beta;
            for i in j..n {
                work[(i, c)] -= s * work[(i, j)];
            }
        }
        // Q ← Q H (accumulate from the right).
        for r in 0..n {
            let mut s = 0.0;
            for i in j..n {
                s += q[(r, i)] * work[(i, j)];
            }
            s *= beta;
            for i in j..n {
                q[(r, i)] -= s * work[(i, j)];
            }
        }
    }
    let d = n - k;
    for c in 0..d {
        for r in 0..n {
            v[(r, c)] = q[(r, k + c)];
        }
    }
}

/// Workspace of [`procrustes_align`] for bases with `d` columns.
#[derive(Clone, Debug)]
pub struct AlignWork {
    x: DMatrix<f64>,
    xtx: DMatrix<f64>,
    pow: DMatrix<f64>,
    pow2: DMatrix<f64>,
    evals: DVector<f64>,
    evecs: DMatrix<f64>,
    r: DMatrix<f64>,
    tmp: DMatrix<f64>,
    /// wᵀ (d × n): wᵀw by the column kernel.
    wt: DMatrix<f64>,
}

impl AlignWork {
    pub fn new(n: usize, d: usize) -> AlignWork {
        AlignWork {
            x: DMatrix::zeros(d, d),
            xtx: DMatrix::zeros(d, d),
            pow: DMatrix::zeros(d, d),
            pow2: DMatrix::zeros(d, d),
            evals: DVector::zeros(d),
            evecs: DMatrix::zeros(d, d),
            r: DMatrix::zeros(d, d),
            tmp: DMatrix::zeros(n, d),
            wt: DMatrix::zeros(d, n),
        }
    }
}

/// `work.r = (work.xtx)^{-1/2}` for the symmetric positive semi-definite `work.xtx`
/// (destroyed) by its eigen-decomposition. Returns the square root of the smallest
/// eigenvalue; at or below `min_sigma` (or NaN) `work.r` is left undefined.
fn inverse_sqrt(work: &mut AlignWork, min_sigma: f64) -> f64 {
    let d = work.xtx.nrows();
    symmetric_eigen(&mut work.xtx, &mut work.evals, &mut work.evecs, 30);
    let mut smin = f64::INFINITY;
    for i in 0..d {
        smin = smin.min(work.evals[i].max(0.0).sqrt());
    }
    if smin.is_nan() || smin <= min_sigma {
        return smin;
    }
    // U diag(1/sqrt(λ)) Uᵀ.
    work.r.fill(0.0);
    for k in 0..d {
        let w = 1.0 / work.evals[k].sqrt();
        for j in 0..d {
            let ujk = work.evecs[(j, k)] * w;
            for i in 0..d {
                work.r[(i, j)] += work.evecs[(i, k)] * ujk;
            }
        }
    }
    smin
}

/// Orthogonal Procrustes alignment: replaces the orthonormal basis `v` (n×d) by
/// `v R` with the orthogonal `R` that brings it closest to `prev` in the Frobenius
/// norm, `R = X (XᵀX)^{-1/2}` with `X = vᵀ prev` (the polar factor; Higham,
/// "Functions of Matrices", ch. 8). Between nearby configurations this is a
/// first-order approximation of parallel transport of the basis. Returns the
/// smallest singular value of `X`: near 0 the subspaces jumped and no alignment is
/// possible (the basis is left as it is).
pub fn procrustes_align(v: &mut DMatrix<f64>, prev: &DMatrix<f64>, work: &mut AlignWork) -> f64 {
    gemm_tn(&mut work.x, 1.0, v, prev, 0.0);
    gemm_tn(&mut work.xtx, 1.0, &work.x, &work.x, 0.0);
    let smin = inverse_sqrt(work, 1e-6);
    if smin.is_nan() || smin <= 1e-6 {
        return smin;
    }
    // R = X (XᵀX)^{-1/2}, then v ← v R.
    copy(&mut work.xtx, &work.r);
    gemm(&mut work.r, 1.0, &work.x, &work.xtx, 0.0);
    copy(&mut work.tmp, v);
    gemm(v, 1.0, &work.tmp, &work.r, 0.0);
    smin
}

/// Largest ‖I − wᵀw‖_F for which [`orthonormalize_polar`] sums the binomial series
/// instead of decomposing wᵀw (then at most six terms reach the rounding level).
const POLAR_SERIES_MAX: f64 = 1e-3;

/// Replaces `w` (n×d, full column rank) by its orthonormal polar factor
/// `w (wᵀw)^{-1/2}`: the orthonormal basis of span(w) closest to `w` in the Frobenius
/// norm (Higham, "Functions of Matrices", ch. 8). Returns the smallest singular value
/// of `w` (a lower bound of it on the series path); at or below `min_sigma` `w` is
/// left unchanged.
///
/// For a nearly orthonormal `w` (the usual case: the previous basis projected onto a
/// null space that moved a little), with E = I − wᵀw and ‖E‖_F ≤ 10⁻³,
/// (wᵀw)^{-1/2} = (I − E)^{-1/2} = Σ_k binom(2k, k) (E/4)^k is summed until the next
/// term falls below 10⁻¹⁷ (two or three terms per control cycle), which is the same
/// matrix to rounding as the eigen-decomposition used otherwise, for a fraction of
/// its cost.
pub fn orthonormalize_polar(w: &mut DMatrix<f64>, work: &mut AlignWork, min_sigma: f64) -> f64 {
    // wᵀw from wᵀ by the (vectorised) column kernel, upper triangle mirrored.
    transpose_into(&mut work.wt, w);
    gemm_sym(&mut work.xtx, &work.wt, w);
    let d = w.ncols();
    let mut e2 = 0.0;
    for j in 0..d {
        for i in 0..d {
            let e = if i == j { 1.0 } else { 0.0 } - work.xtx[(i, j)];
            work.pow[(i, j)] = e;
            e2 += e * e;
        }
    }
    let enorm = e2.sqrt();
    let smin_bound = (1.0 - enorm).max(0.0).sqrt();
    if enorm <= POLAR_SERIES_MAX && smin_bound > min_sigma {
        // R = I + ½ E + ⅜ E² + …, c_k = c_{k−1} (2k − 1) / (2k); ‖E^k‖ ≤ ‖E‖_F^k.
        let mut coef = 0.5;
        for j in 0..d {
            for i in 0..d {
                work.r[(i, j)] = if i == j { 1.0 } else { 0.0 } + coef * work.pow[(i, j)];
            }
        }
        copy(&mut work.x, &work.pow);
        let mut pnorm = enorm;
        let mut k = 1.0;
        loop {
            let next = coef * (2.0 * k + 1.0) / (2.0 * k + 2.0);
            pnorm *= enorm;
            if next * pnorm <= 1e-17 {
                break;
            }
            gemm(&mut work.pow2, 1.0, &work.pow, &work.x, 0.0);
            std::mem::swap(&mut work.pow, &mut work.pow2);
            for j in 0..d {
                for i in 0..d {
                    work.r[(i, j)] += next * work.pow[(i, j)];
                }
            }
            coef = next;
            k += 1.0;
        }
        copy(&mut work.tmp, w);
        gemm(w, 1.0, &work.tmp, &work.r, 0.0);
        return smin_bound;
    }
    let smin = inverse_sqrt(work, min_sigma);
    if smin.is_nan() || smin <= min_sigma {
        return smin;
    }
    copy(&mut work.tmp, w);
    gemm(w, 1.0, &work.tmp, &work.r, 0.0);
    smin
}
