//! Inversion of symmetric positive definite matrices: exact (by the
//! Cholesky factor), and damped, (A + δI)⁻¹ with δ rising smoothly from 0 as
//! the eigenvalue ratio falls below a threshold (damped least squares on the
//! Gram matrix), with the conditioning it measured. Allocation-free.

use nalgebra::{DMatrix, DVector};

use crate::eigen::{symmetric_eigen, symmetric_eigenvalues};
use crate::products::copy;

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

/// Inverse of the symmetric positive definite `a` (lower triangle read) into `out`
/// through its Cholesky factor `L` (left in `factor`): `A⁻¹ = L⁻ᵀ L⁻¹`, with `L⁻¹`
/// formed in `out` and overwritten by the product column by column, exactly
/// symmetric. False (with `out` undefined) when a pivot is not positive and finite.
/// The sizes of task spaces (up to six) run in a build for their size, fully unrolled.
pub fn spd_inverse(a: &DMatrix<f64>, factor: &mut DMatrix<f64>, out: &mut DMatrix<f64>) -> bool {
    let n = a.nrows();
    assert_eq!(a.shape(), (n, n));
    assert_eq!(factor.shape(), (n, n));
    assert_eq!(out.shape(), (n, n));
    let (a, l, x) = (a.as_slice(), factor.as_mut_slice(), out.as_mut_slice());
    match n {
        1 => spd_inverse_n(a, l, x, 1),
        2 => spd_inverse_n(a, l, x, 2),
        3 => spd_inverse_n(a, l, x, 3),
        4 => spd_inverse_n(a, l, x, 4),
        5 => spd_inverse_n(a, l, x, 5),
        6 => spd_inverse_n(a, l, x, 6),
        _ => spd_inverse_large(a, l, x, n),
    }
}

/// [`spd_inverse_n`] for larger matrices, with the same operations in the same order
/// (the same bits, but for the sign of an exact zero in L⁻¹) arranged to vectorise and
/// to overlap: the factor left-looking by columns (column j less l[j.., p] l_jp for
/// p < j, contiguous runs), L⁻¹ by forward substitution of L X = I with all columns
/// advancing together row by row (each element of a column as in the dot-product form:
/// −(a + b + …) and ((0 − a) − b) − … round alike), and the product with four sums
/// side by side.
fn spd_inverse_large(a: &[f64], l: &mut [f64], x: &mut [f64], n: usize) -> bool {
    let (a, l, x) = (&a[..n * n], &mut l[..n * n], &mut x[..n * n]);
    l.copy_from_slice(a);
    for j in 0..n {
        let (done, rest) = l.split_at_mut(j * n);
        let col = &mut rest[..n];
        for cp in done.chunks_exact(n) {
            let ljp = cp[j];
            for (y, &v) in col[j..].iter_mut().zip(&cp[j..]) {
                *y -= v * ljp;
            }
        }
        let d = col[j];
        if !(d > 0.0 && d.is_finite()) {
            return false;
        }
        let ljj = d.sqrt();
        col[j] = ljj;
        for y in &mut col[j + 1..] {
            *y /= ljj;
        }
    }
    // L⁻¹ into x.
    for (j, c) in x.chunks_exact_mut(n).enumerate() {
        c.fill(0.0);
        c[j] = 1.0;
    }
    for (k, lk) in l.chunks_exact(n).enumerate() {
        let (lkk, below) = (lk[k], &lk[k + 1..]);
        for c in x.chunks_exact_mut(n).take(k + 1) {
            let xk = c[k] / lkk;
            c[k] = xk;
            for (y, &v) in c[k + 1..].iter_mut().zip(below) {
                *y -= v * xk;
            }
        }
    }
    // (A⁻¹)_ij = Σ_{p ≥ i} (L⁻¹)_pi (L⁻¹)_pj for i ≥ j, in place as in `spd_inverse_n`,
    // rows i..i + 4 of column j together (written after all four are summed).
    for j in 0..n {
        let mut i = j;
        while i + 4 <= n {
            let (ci, cj) = (i * n, j * n);
            let mut s = [0.0; 4];
            for t in 0..4 {
                for p in i + t..i + 3 {
                    s[t] += x[ci + t * n + p] * x[cj + p];
                }
            }
            for p in i + 3..n {
                let xj = x[cj + p];
                for (t, st) in s.iter_mut().enumerate() {
                    *st += x[ci + t * n + p] * xj;
                }
            }
            x[cj + i..cj + i + 4].copy_from_slice(&s);
            i += 4;
        }
        for i in i..n {
            x[j * n + i] = inverse_entry(x, n, i, j);
        }
    }
    mirror_lower_into_upper(x, n);
    true
}

/// The body of [`spd_inverse`] on n × n column-major slices (a constant n where it is
/// inlined with one, so the loops unroll and the index checks fold away; the same
/// operations in the same order either way).
#[inline(always)]
fn spd_inverse_n(a: &[f64], l: &mut [f64], x: &mut [f64], n: usize) -> bool {
    let (a, l, x) = (&a[..n * n], &mut l[..n * n], &mut x[..n * n]);
    // A = L Lᵀ (column j from the columns before it).
    for j in 0..n {
        let mut d = a[j * n + j];
        for p in 0..j {
            d -= l[p * n + j] * l[p * n + j];
        }
        if !(d > 0.0 && d.is_finite()) {
            return false;
        }
        let ljj = d.sqrt();
        l[j * n + j] = ljj;
        for i in (j + 1)..n {
            let mut s = a[j * n + i];
            for p in 0..j {
                s -= l[p * n + i] * l[p * n + j];
            }
            l[j * n + i] = s / ljj;
        }
    }
    // L⁻¹ (lower triangular) into x.
    for j in 0..n {
        for i in 0..j {
            x[j * n + i] = 0.0;
        }
        x[j * n + j] = 1.0 / l[j * n + j];
        for i in (j + 1)..n {
            let mut s = 0.0;
            for p in j..i {
                s += l[p * n + i] * x[j * n + p];
            }
            x[j * n + i] = -s / l[i * n + i];
        }
    }
    // (A⁻¹)_ij = Σ_{p ≥ i} (L⁻¹)_pi (L⁻¹)_pj for i ≥ j, in place: entry (i, j) is the last
    // use of (L⁻¹)_ij, and column i > j is still intact.
    for j in 0..n {
        for i in j..n {
            x[j * n + i] = inverse_entry(x, n, i, j);
        }
    }
    mirror_lower_into_upper(x, n);
    true
}

/// (A⁻¹)_ij = Σ_{p ≥ i} (L⁻¹)_pi (L⁻¹)_pj for i ≥ j, with L⁻¹ in the n × n
/// column-major `x` (column i from row i down, column j likewise).
#[inline(always)]
fn inverse_entry(x: &[f64], n: usize, i: usize, j: usize) -> f64 {
    let mut s = 0.0;
    for p in i..n {
        s += x[i * n + p] * x[j * n + p];
    }
    s
}

/// The upper triangle of the n × n column-major `x` from its lower one (the last
/// step of both inversions above: their product forms the lower triangle only).
#[inline(always)]
fn mirror_lower_into_upper(x: &mut [f64], n: usize) {
    for j in 0..n {
        for i in (j + 1)..n {
            x[i * n + j] = x[j * n + i];
        }
    }
}

/// [`damped_spd_inverse`] reports the exact eigenvalue ratio below this multiple of
/// its threshold ε (the controller fades the lower levels there and needs the ratio
/// to be continuous in the state).
pub const EXACT_RATIO_FACTOR: f64 = 100.0;

/// Result of a damped inversion.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Conditioning {
    /// Smallest / largest eigenvalue of the inverted matrix (1 = perfectly conditioned).
    pub ratio: f64,
    /// Damping δ added to every eigenvalue (0 away from singularities).
    pub damping: f64,
}

/// The conditioning of `a` when its exact inverse (in `out`, from the Cholesky factor)
/// needs no damping, else None (the eigen-decomposition decides):
/// 1. λ_min ≥ 1/‖A⁻¹‖_F and λ_max ≤ tr A: the ratio is at least 1/(‖A⁻¹‖_F tr A),
///    accepted (and reported) when that clears [`EXACT_RATIO_FACTOR`] `× ε`. (A
///    tighter bound, ‖A‖_F for tr A, would report a different ratio, and the safety
///    layer's conflict fade reads the ratio up to 100 ε_c = 10⁻³.)
/// 2. Otherwise the eigenvalues alone (no eigenvectors): the exact ratio, and no
///    damping when it is at least ε — unless λ_min ≤ 1/max_i (A⁻¹)_ii and
///    λ_max ≥ max_i a_ii already put the ratio below ε (damping certainly due).
fn undamped_conditioning(
    a: &DMatrix<f64>,
    out: &DMatrix<f64>,
    work: &mut SpdWork,
    eps: f64,
    floor: f64,
) -> Option<Conditioning> {
    let m = a.nrows();
    let trace: f64 = (0..m).map(|i| a[(i, i)]).sum();
    let bound = 1.0 / (out.norm() * trace);
    if !(bound.is_finite() && trace >= floor) {
        return None;
    }
    let accept = |ratio: f64| Conditioning {
        ratio: ratio.min(1.0),
        damping: 0.0,
    };
    if bound >= EXACT_RATIO_FACTOR * eps {
        return Some(accept(bound));
    }
    let max_diag = |x: &DMatrix<f64>| (0..m).map(|i| x[(i, i)]).fold(0.0, f64::max);
    let upper = 1.0 / (max_diag(out) * max_diag(a));
    // NaN (a vanished diagonal) as well as below ε: the eigen-decomposition decides.
    if upper.is_nan() || upper < eps {
        return None;
    }
    copy(&mut work.a, a);
    symmetric_eigenvalues(&mut work.a, &mut work.evals, 30);
    let (mut lmin, mut lmax) = (f64::INFINITY, 0.0f64);
    for &l in work.evals.iter() {
        lmax = lmax.max(l);
        lmin = lmin.min(l);
    }
    let ratio = if lmax > 0.0 {
        lmin.max(0.0) / lmax
    } else {
        0.0
    };
    (ratio >= eps && lmax >= floor).then(|| accept(ratio))
}

/// Damped inverse of a symmetric positive semi-definite matrix `a` (m×m) into `out`:
/// `(A + δ I)⁻¹` through its eigen-decomposition, with the damping
/// `δ = ε λ_max (1 − r/ε)²` switched on smoothly when the eigenvalue ratio
/// `r = λ_min/λ_max` falls below `ε` (the damped least-squares idea of Nakamura &
/// Hanafusa / Maciejewski & Klein, applied to the Gram matrix). Away from singularities
/// (r ≥ ε) it is the exact inverse. The result is bounded by `1/(ε λ_max)` (and by
/// `1/floor` when `a` vanishes altogether).
///
/// Fast path: a Cholesky inverse, kept whenever no damping is due (see
/// `undamped_conditioning`: a guaranteed lower bound of the eigenvalue ratio first,
/// the eigenvalues alone where it cannot decide). Otherwise the eigen-decomposition
/// decides. The reported ratio is exact (and so continuous in the state) wherever it
/// is below `EXACT_RATIO_FACTOR × ε`, else a lower bound of it.
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
    if spd_inverse(a, &mut work.a, out)
        && let Some(c) = undamped_conditioning(a, out, work, eps, floor)
    {
        return c;
    }
    copy(&mut work.a, a);
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

/// The inverse of [`damped_spd_inverse`] alone, for a caller that does not read the
/// conditioning: the same matrix, but the Cholesky inverse is accepted as soon as a
/// guaranteed lower bound of the eigenvalue ratio, 1/(‖A⁻¹‖_F ‖A‖_F) (λ_min ≥
/// 1/‖A⁻¹‖_F, λ_max ≤ ‖A‖_F), shows that no damping is due (at least ε, with
/// λ_max ≥ tr A / m clear of `floor`) — the ratio itself, which the eigen-decomposition
/// would have to find below `EXACT_RATIO_FACTOR × ε`, is not needed.
pub fn damped_spd_inverse_only(
    a: &DMatrix<f64>,
    out: &mut DMatrix<f64>,
    work: &mut SpdWork,
    eps: f64,
    floor: f64,
) {
    let m = a.nrows();
    if m > 0 && spd_inverse(a, &mut work.a, out) {
        let trace: f64 = (0..m).map(|i| a[(i, i)]).sum();
        let bound = 1.0 / (out.norm() * a.norm());
        if bound.is_finite() && bound >= eps && trace >= m as f64 * floor {
            return;
        }
    }
    damped_spd_inverse(a, out, work, eps, floor);
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn spd_inverse_large_matches_the_dot_product_form() {
        for n in 1..=20 {
            let b = DMatrix::from_fn(n, n, |i, j| ((i * 7 + j * 3) % 11) as f64 * 0.37 - 1.4);
            let a = &b * b.transpose() + DMatrix::identity(n, n) * 0.01;
            let (mut l1, mut x1) = (DMatrix::zeros(n, n), DMatrix::zeros(n, n));
            let (mut l2, mut x2) = (DMatrix::zeros(n, n), DMatrix::zeros(n, n));
            assert!(spd_inverse_n(
                a.as_slice(),
                l1.as_mut_slice(),
                x1.as_mut_slice(),
                n
            ));
            assert!(spd_inverse_large(
                a.as_slice(),
                l2.as_mut_slice(),
                x2.as_mut_slice(),
                n
            ));
            assert_eq!(x1, x2, "n = {n}");
            assert!((&a * &x2 - DMatrix::identity(n, n)).norm() < 1e-8);
        }
    }
}
