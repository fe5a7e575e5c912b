//! Small dense kernels that never allocate: products into preallocated outputs,
//! a Householder null-space basis, a cyclic Jacobi eigen-solver, damped SPD
//! inversion and the orthogonal Procrustes alignment of a basis.
//!
//! Every function assumes outputs of the right size (checked by the caller at
//! construction); loops are plain column-major triple loops — the matrices of a
//! robot controller are at most a few dozen rows, where this is as fast as a
//! blocked kernel and, unlike one, allocates no packing buffer.

use nalgebra::{DMatrix, DVector};

/// `c = alpha * a * b + beta * c`.
pub fn gemm(c: &mut DMatrix<f64>, alpha: f64, a: &DMatrix<f64>, b: &DMatrix<f64>, beta: f64) {
    let (m, k, n) = (a.nrows(), a.ncols(), b.ncols());
    debug_assert_eq!(b.nrows(), k);
    debug_assert_eq!(c.shape(), (m, n));
    for j in 0..n {
        for i in 0..m {
            let mut s = 0.0;
            for l in 0..k {
                s += a[(i, l)] * b[(l, j)];
            }
            c[(i, j)] = alpha * s + if beta == 0.0 { 0.0 } else { beta * c[(i, j)] };
        }
    }
}

/// `c = alpha * aᵀ * b + beta * c`.
pub fn gemm_tn(c: &mut DMatrix<f64>, alpha: f64, a: &DMatrix<f64>, b: &DMatrix<f64>, beta: f64) {
    let (m, k, n) = (a.ncols(), a.nrows(), b.ncols());
    debug_assert_eq!(b.nrows(), k);
    debug_assert_eq!(c.shape(), (m, n));
    for j in 0..n {
        for i in 0..m {
            let mut s = 0.0;
            for l in 0..k {
                s += a[(l, i)] * b[(l, j)];
            }
            c[(i, j)] = alpha * s + if beta == 0.0 { 0.0 } else { beta * c[(i, j)] };
        }
    }
}

/// `c = alpha * a * bᵀ + beta * c`.
pub fn gemm_nt(c: &mut DMatrix<f64>, alpha: f64, a: &DMatrix<f64>, b: &DMatrix<f64>, beta: f64) {
    let (m, k, n) = (a.nrows(), a.ncols(), b.nrows());
    debug_assert_eq!(b.ncols(), k);
    debug_assert_eq!(c.shape(), (m, n));
    for j in 0..n {
        for i in 0..m {
            let mut s = 0.0;
            for l in 0..k {
                s += a[(i, l)] * b[(j, l)];
            }
            c[(i, j)] = alpha * s + if beta == 0.0 { 0.0 } else { beta * c[(i, j)] };
        }
    }
}

/// `y = alpha * a * x + beta * y`.
pub fn gemv(y: &mut DVector<f64>, alpha: f64, a: &DMatrix<f64>, x: &DVector<f64>, beta: f64) {
    debug_assert_eq!(a.ncols(), x.len());
    debug_assert_eq!(a.nrows(), y.len());
    for i in 0..a.nrows() {
        let mut s = 0.0;
        for l in 0..a.ncols() {
            s += a[(i, l)] * x[l];
        }
        y[i] = alpha * s + if beta == 0.0 { 0.0 } else { beta * y[i] };
    }
}

/// `y = alpha * aᵀ * x + beta * y`.
pub fn gemv_t(y: &mut DVector<f64>, alpha: f64, a: &DMatrix<f64>, x: &DVector<f64>, beta: f64) {
    debug_assert_eq!(a.nrows(), x.len());
    debug_assert_eq!(a.ncols(), y.len());
    for j in 0..a.ncols() {
        let mut s = 0.0;
        for l in 0..a.nrows() {
            s += a[(l, j)] * x[l];
        }
        y[j] = alpha * s + if beta == 0.0 { 0.0 } else { beta * y[j] };
    }
}

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

/// Cyclic Jacobi eigen-decomposition of the symmetric matrix `a` (destroyed):
/// eigenvalues into `evals`, eigenvectors (columns) into `evecs`
/// (Golub & Van Loan, Alg. 8.5.3). Converges quadratically; at most `max_sweeps`.
pub fn symmetric_eigen(
    a: &mut DMatrix<f64>,
    evals: &mut DVector<f64>,
    evecs: &mut DMatrix<f64>,
    max_sweeps: usize,
) {
    let n = a.nrows();
    evecs.fill_with_identity();
    for _ in 0..max_sweeps {
        let mut off = 0.0;
        let mut diag = 0.0;
        for j in 0..n {
            diag += a[(j, j)] * a[(j, j)];
            for i in 0..j {
                off += a[(i, j)] * a[(i, j)];
            }
        }
        if off <= 1e-30 * diag || off == 0.0 {
            break;
        }
        for p in 0..n {
            for qi in (p + 1)..n {
                let apq = a[(p, qi)];
                if apq == 0.0 {
                    continue;
                }
                let theta = (a[(qi, qi)] - a[(p, p)]) / (2.0 * apq);
                let t = theta.signum() / (theta.abs() + (theta * theta + 1.0).sqrt());
                let t = if theta == 0.0 { 1.0 } else { t };
                let c = 1.0 / (t * t + 1.0).sqrt();
                let s = t * c;
                for k in 0..n {
                    let akp = a[(k, p)];
                    let akq = a[(k, qi)];
                    a[(k, p)] = c * akp - s * akq;
                    a[(k, qi)] = s * akp + c * akq;
                }
                for k in 0..n {
                    let apk = a[(p, k)];
                    let aqk = a[(qi, k)];
                    a[(p, k)] = c * apk - s * aqk;
                    a[(qi, k)] = s * apk + c * aqk;
                }
                for k in 0..n {
                    let vkp = evecs[(k, p)];
                    let vkq = evecs[(k, qi)];
                    evecs[(k, p)] = c * vkp - s * vkq;
                    evecs[(k, qi)] = s * vkp + c * vkq;
                }
            }
        }
    }
    for i in 0..n {
        evals[i] = a[(i, i)];
    }
}

/// Workspace of [`damped_spd_inverse`] for matrices up to `m`×`m`.
#[derive(Clone, Debug)]
pub struct SpdWork {
    a: DMatrix<f64>,
    evals: DVector<f64>,
    evecs: DMatrix<f64>,
}

impl SpdWork {
    pub fn new(m: usize) -> SpdWork {
        SpdWork {
            a: DMatrix::zeros(m, m),
            evals: DVector::zeros(m),
            evecs: DMatrix::zeros(m, m),
        }
    }
}

/// Result of a damped inversion.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Conditioning {
    /// Smallest / largest eigenvalue of the inverted matrix (1 = perfectly conditioned).
    pub ratio: f64,
    /// Damping δ added to every eigenvalue (0 away from singularities).
    pub damping: f64,
}

/// Damped inverse of a symmetric positive semi-definite matrix `a` (m×m) into `out`:
/// `(A + δ I)⁻¹` through its eigen-decomposition, with the damping
/// `δ = ε λ_max (1 − r/ε)²` switched on smoothly when the eigenvalue ratio
/// `r = λ_min/λ_max` falls below `ε` (the damped least-squares idea of Nakamura &
/// Hanafusa / Maciejewski & Klein, applied to the Gram matrix). Away from singularities
/// (r ≥ ε) it is the exact inverse. The result is bounded by `1/(ε λ_max)` (and by
/// `1/floor` when `a` vanishes altogether).
///
/// Fast path: a Cholesky inverse, accepted when the guaranteed lower bound of the
/// eigenvalue ratio, `1 / (‖A⁻¹‖_F · tr A)` (λ_min ≥ 1/‖A⁻¹‖_F, λ_max ≤ tr A), is at
/// least `ε` — then no damping is due and the inverse is exact; the reported ratio is
/// that lower bound. Otherwise the eigen-decomposition decides (exact ratio).
pub fn damped_spd_inverse(
    a: &DMatrix<f64>,
    out: &mut DMatrix<f64>,
    work: &mut SpdWork,
    eps: f64,
    floor: f64,
) -> Conditioning {
    let m = a.nrows();
    if m == 0 {
        return Conditioning {
            ratio: 1.0,
            damping: 0.0,
        };
    }
    if hcc_model::linalg::spd_inverse(a, &mut work.a, out).is_ok() {
        let trace: f64 = (0..m).map(|i| a[(i, i)]).sum();
        let inv_norm = out.norm();
        let bound = 1.0 / (inv_norm * trace);
        if bound.is_finite() && bound >= eps && trace >= floor {
            return Conditioning {
                ratio: bound.min(1.0),
                damping: 0.0,
            };
        }
    }
    work.a.copy_from(a);
    symmetric_eigen(&mut work.a, &mut work.evals, &mut work.evecs, 30);
    let mut lmax: f64 = 0.0;
    let mut lmin = f64::INFINITY;
    for i in 0..m {
        let l = work.evals[i];
        lmax = lmax.max(l);
        lmin = lmin.min(l);
    }
    let lmin = lmin.max(0.0);
    let ratio = if lmax > 0.0 { lmin / lmax } else { 0.0 };
    let mut damping = if ratio < eps {
        let s = 1.0 - ratio / eps;
        eps * lmax * s * s
    } else {
        0.0
    };
    damping = damping.max(if lmax < floor { floor } else { 0.0 });
    out.fill(0.0);
    for k in 0..m {
        let l = work.evals[k].max(0.0) + damping;
        let inv = if l > 0.0 { 1.0 / l } else { 0.0 };
        for j in 0..m {
            let vj = work.evecs[(j, k)] * inv;
            for i in 0..m {
                out[(i, j)] += work.evecs[(i, k)] * vj;
            }
        }
    }
    Conditioning { ratio, damping }
}

/// Workspace of [`procrustes_align`] for bases with `d` columns.
#[derive(Clone, Debug)]
pub struct AlignWork {
    x: DMatrix<f64>,
    xtx: DMatrix<f64>,
    evals: DVector<f64>,
    evecs: DMatrix<f64>,
    r: DMatrix<f64>,
    tmp: DMatrix<f64>,
}

impl AlignWork {
    pub fn new(n: usize, d: usize) -> AlignWork {
        AlignWork {
            x: DMatrix::zeros(d, d),
            xtx: DMatrix::zeros(d, d),
            evals: DVector::zeros(d),
            evecs: DMatrix::zeros(d, d),
            r: DMatrix::zeros(d, d),
            tmp: DMatrix::zeros(n, d),
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
    work.xtx.copy_from(&work.r);
    gemm(&mut work.r, 1.0, &work.x, &work.xtx, 0.0);
    work.tmp.copy_from(v);
    gemm(v, 1.0, &work.tmp, &work.r, 0.0);
    smin
}

/// Replaces `w` (n×d, full column rank) by its orthonormal polar factor
/// `w (wᵀw)^{-1/2}`: the orthonormal basis of span(w) closest to `w` in the Frobenius
/// norm (Higham, "Functions of Matrices", ch. 8). Returns the smallest singular value
/// of `w`; at or below `min_sigma` `w` is left unchanged.
pub fn orthonormalize_polar(w: &mut DMatrix<f64>, work: &mut AlignWork, min_sigma: f64) -> f64 {
    gemm_tn(&mut work.xtx, 1.0, w, w, 0.0);
    let smin = inverse_sqrt(work, min_sigma);
    if smin.is_nan() || smin <= min_sigma {
        return smin;
    }
    work.tmp.copy_from(w);
    gemm(w, 1.0, &work.tmp, &work.r, 0.0);
    smin
}
