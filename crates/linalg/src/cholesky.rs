//! Small in-place dense linear algebra that never allocates.
//!
//! Every routine works on caller-provided storage and returns a [`LinalgError`]
//! instead of panicking on bad input (wrong sizes, a matrix that is not
//! positive definite). The routines are generic over nalgebra storage, so they
//! accept `DMatrix`/`DVector` as well as views into larger preallocated buffers
//! (`DMatrixViewMut`, `DVectorViewMut`) and fixed-size matrices.
//!
//! The Cholesky factorisation is the textbook column-by-column
//! (Cholesky–Banachiewicz/Crout) variant, Golub & Van Loan, "Matrix
//! Computations", Alg. 4.2.1: `A = L Lᵀ` with `L` lower triangular and a
//! strictly positive diagonal.
//!
//! Typical real-time use (all buffers allocated once beforehand):
//! ```
//! use hcc_linalg::{cholesky_in_place, cholesky_solve_in_place};
//! use nalgebra::{DMatrix, DVector};
//! let a = DMatrix::from_row_slice(2, 2, &[4.0, 2.0, 2.0, 3.0]);
//! let mut l = DMatrix::zeros(2, 2);
//! let mut x = DVector::from_vec(vec![2.0, 1.0]);
//! l.copy_from(&a);
//! cholesky_in_place(&mut l).unwrap();
//! cholesky_solve_in_place(&l, &mut x).unwrap(); // x = A⁻¹ b
//! assert!((&a * &x - DVector::from_vec(vec![2.0, 1.0])).norm() < 1e-12);
//! ```

use nalgebra::{Dim, Matrix, RawStorage, RawStorageMut};

/// Errors of the dense routines.
#[derive(Clone, Copy, Debug, PartialEq, thiserror::Error)]
pub enum LinalgError {
    /// The matrix is not (numerically) positive definite: the pivot of row/column
    /// `index` was `pivot` (≤ 0 or not finite).
    #[error("matrix is not positive definite: pivot {index} is {pivot}")]
    NotPositiveDefinite { index: usize, pivot: f64 },
    /// Operand sizes do not fit together.
    #[error("dimension mismatch in {operation}: expected {expected}, got {got}")]
    DimensionMismatch {
        operation: &'static str,
        expected: usize,
        got: usize,
    },
}

fn check(operation: &'static str, expected: usize, got: usize) -> Result<(), LinalgError> {
    if expected == got {
        Ok(())
    } else {
        Err(LinalgError::DimensionMismatch {
            operation,
            expected,
            got,
        })
    }
}

/// Cholesky factorisation in place: on entry `a` holds a symmetric positive
/// definite matrix (only its lower triangle is read), on success it holds the
/// lower-triangular factor `L` with `A = L Lᵀ` (strict upper triangle set to 0).
///
/// Fails with [`LinalgError::NotPositiveDefinite`] if a pivot is ≤ 0 or not
/// finite (then `a` is partially overwritten), or
/// [`LinalgError::DimensionMismatch`] if `a` is not square. O(n³/3), no allocation.
pub fn cholesky_in_place<R: Dim, C: Dim, S: RawStorageMut<f64, R, C>>(
    a: &mut Matrix<f64, R, C, S>,
) -> Result<(), LinalgError> {
    let n = a.nrows();
    check("cholesky_in_place (square)", n, a.ncols())?;
    for j in 0..n {
        let mut d = a[(j, j)];
        for k in 0..j {
            let l = a[(j, k)];
            d -= l * l;
        }
        if !(d > 0.0 && d.is_finite()) {
            return Err(LinalgError::NotPositiveDefinite { index: j, pivot: d });
        }
        let ljj = d.sqrt();
        a[(j, j)] = ljj;
        for i in (j + 1)..n {
            let mut s = a[(i, j)];
            for k in 0..j {
                s -= a[(i, k)] * a[(j, k)];
            }
            a[(i, j)] = s / ljj;
        }
        for i in 0..j {
            a[(i, j)] = 0.0;
        }
    }
    Ok(())
}

/// Solves `A x = b` in place given the Cholesky factor `l` of `A` (from
/// [`cholesky_in_place`]): on entry `b` is the right-hand side, on return the
/// solution. Forward substitution with `L`, back substitution with `Lᵀ`.
/// Only the lower triangle of `l` is read. No allocation.
pub fn cholesky_solve_in_place<
    R: Dim,
    C: Dim,
    S: RawStorage<f64, R, C>,
    RB: Dim,
    CB: Dim,
    SB: RawStorageMut<f64, RB, CB>,
>(
    l: &Matrix<f64, R, C, S>,
    b: &mut Matrix<f64, RB, CB, SB>,
) -> Result<(), LinalgError> {
    let n = l.nrows();
    check("cholesky_solve_in_place (square factor)", n, l.ncols())?;
    check("cholesky_solve_in_place (rhs rows)", n, b.nrows())?;
    for col in 0..b.ncols() {
        // L y = b
        for i in 0..n {
            let mut s = b[(i, col)];
            for k in 0..i {
                s -= l[(i, k)] * b[(k, col)];
            }
            b[(i, col)] = s / l[(i, i)];
        }
        // Lᵀ x = y
        for i in (0..n).rev() {
            let mut s = b[(i, col)];
            for k in (i + 1)..n {
                s -= l[(k, i)] * b[(k, col)];
            }
            b[(i, col)] = s / l[(i, i)];
        }
    }
    Ok(())
}

/// Solves `A X = B` in place for a matrix right-hand side `B` (every column
/// separately), given the Cholesky factor `l` of `A`. Same as
/// [`cholesky_solve_in_place`], which already accepts matrices; kept as an
/// explicit name for readability at call sites.
pub fn cholesky_solve_matrix_in_place<
    R: Dim,
    C: Dim,
    S: RawStorage<f64, R, C>,
    RB: Dim,
    CB: Dim,
    SB: RawStorageMut<f64, RB, CB>,
>(
    l: &Matrix<f64, R, C, S>,
    b: &mut Matrix<f64, RB, CB, SB>,
) -> Result<(), LinalgError> {
    cholesky_solve_in_place(l, b)
}

/// The sizes at which nalgebra's own Cholesky factorisation
/// (`Cholesky::new_unchecked`, column `axpy`s in place, no allocation) is
/// faster than [`cholesky_in_place_slice`] (benchmark `kernels`: 1.1–1.2× for
/// 5 ≤ n ≤ 12, even at 16; the left-looking form here is 1.4–2.3× faster at
/// 3, 4 and 32).
pub const NALGEBRA_FACTOR_SIZES: std::ops::RangeInclusive<usize> = 5..=16;

/// The Cholesky factor of the SPD matrix `a`, in place (`A = L Lᵀ`, strict
/// upper triangle 0), by the faster of the two factorisations at its size:
/// nalgebra's for [`NALGEBRA_FACTOR_SIZES`], else
/// [`cholesky_in_place_slice`]. The same errors as it. Allocation-free (the
/// matrix's storage is moved into nalgebra's factorisation and back).
pub fn cholesky_factor(a: &mut nalgebra::DMatrix<f64>) -> Result<(), LinalgError> {
    let n = a.nrows();
    check("cholesky_factor (square)", n, a.ncols())?;
    if !NALGEBRA_FACTOR_SIZES.contains(&n) {
        return cholesky_in_place_slice(a.as_mut_slice(), n);
    }
    // A pivot ≤ 0 gives NaN (the square root of a negative), which fails
    // the check below as the slice form's own check would.
    *a = nalgebra::Cholesky::new_unchecked(std::mem::take(a)).unpack();
    match (0..n)
        .map(|j| (j, a[(j, j)]))
        .find(|(_, d)| !(*d > 0.0 && d.is_finite()))
    {
        Some((index, pivot)) => Err(LinalgError::NotPositiveDefinite { index, pivot }),
        None => Ok(()),
    }
}

/// [`cholesky_in_place`] for a contiguous column-major `n × n` slice `a` (a
/// `DMatrix`'s storage), in the left-looking column form: column j is updated by the
/// columns k < j as whole contiguous runs (`a[j.., j] −= a[j.., k] a[j, k]`), which
/// vectorises (four columns k per pass). Every element still receives its products in
/// increasing k and is divided by the pivot last, so the factor is bitwise that of
/// [`cholesky_in_place`].
/// The strict upper triangle is set to 0.
pub fn cholesky_in_place_slice(a: &mut [f64], n: usize) -> Result<(), LinalgError> {
    check("cholesky_in_place_slice (n × n)", n * n, a.len())?;
    // Robot sizes run in a build for their size (loops unrolled, index checks folded).
    match n {
        1 => factor_n(a, 1),
        2 => factor_n(a, 2),
        3 => factor_n(a, 3),
        4 => factor_n(a, 4),
        5 => factor_n(a, 5),
        6 => factor_n(a, 6),
        7 => factor_n(a, 7),
        _ => factor_n(a, n),
    }
}

/// [`cholesky_in_place_slice`] (size checked there), inlined into its builds per size.
#[inline(always)]
fn factor_n(a: &mut [f64], n: usize) -> Result<(), LinalgError> {
    let a = &mut a[..n * n];
    for j in 0..n {
        let (done, rest) = a.split_at_mut(j * n);
        let col = &mut rest[..n];
        // Four columns k at a time in one pass over column j (each element still
        // receives its products in increasing k), then the rest one by one.
        let mut quads = done.chunks_exact(4 * n);
        for q in &mut quads {
            let (c0, q) = q.split_at(n);
            let (c1, q) = q.split_at(n);
            let (c2, c3) = q.split_at(n);
            let (l0, l1, l2, l3) = (c0[j], c1[j], c2[j], c3[j]);
            for ((x, (&a0, &a1)), (&a2, &a3)) in col[j..]
                .iter_mut()
                .zip(c0[j..].iter().zip(&c1[j..]))
                .zip(c2[j..].iter().zip(&c3[j..]))
            {
                *x = (((*x - a0 * l0) - a1 * l1) - a2 * l2) - a3 * l3;
            }
        }
        for ck in quads.remainder().chunks_exact(n) {
            let ljk = ck[j];
            for (x, &l) in col[j..].iter_mut().zip(&ck[j..]) {
                *x -= l * ljk;
            }
        }
        let d = col[j];
        if !(d > 0.0 && d.is_finite()) {
            return Err(LinalgError::NotPositiveDefinite { index: j, pivot: d });
        }
        let ljj = d.sqrt();
        col[j] = ljj;
        for x in &mut col[j + 1..] {
            *x /= ljj;
        }
        col[..j].fill(0.0);
    }
    Ok(())
}

/// [`cholesky_solve_in_place`] for contiguous column-major storage: `l` the `n × n`
/// factor, `b` the right-hand sides, `b.len() / n` columns of `n`. From n = 8 on the
/// right-hand sides are solved four at a time, interleaved (element i of the four
/// side by side), so every step of the substitutions is one vector operation across
/// them: the divisions and the long subtraction chains of the back substitution run
/// four wide (in one AVX register where the CPU has AVX2) instead of one after the
/// other. Smaller factors are solved column by column (`solve_columns`). Either way
/// every element is formed by the same operations in the same order as in
/// [`cholesky_solve_in_place`] (separate multiplications and subtractions, over k in
/// increasing order, divided by the pivot last), so the solution is bitwise the same.
pub fn cholesky_solve_slice(l: &[f64], n: usize, b: &mut [f64]) -> Result<(), LinalgError> {
    check("cholesky_solve_slice (n × n factor)", n * n, l.len())?;
    if n == 0 {
        return Ok(());
    }
    check("cholesky_solve_slice (rhs rows)", 0, b.len() % n)?;
    if !(INTERLEAVED_MIN..=INTERLEAVED_MAX).contains(&n) {
        // Robot sizes run in a build for their size (loops unrolled, index checks
        // folded).
        match n {
            1 => solve_columns(l, b, 1),
            2 => solve_columns(l, b, 2),
            3 => solve_columns(l, b, 3),
            4 => solve_columns(l, b, 4),
            5 => solve_columns(l, b, 5),
            6 => solve_columns(l, b, 6),
            7 => solve_columns(l, b, 7),
            _ => solve_columns(l, b, n),
        }
        return Ok(());
    }
    #[cfg(target_arch = "x86_64")]
    if std::arch::is_x86_feature_detected!("avx2") {
        // SAFETY: the CPU supports AVX2 (just checked).
        unsafe { solve_interleaved_avx2(l, b, n) };
        return Ok(());
    }
    solve_interleaved::<false>(l, b, n);
    Ok(())
}

/// Right-hand sides per interleaved block of [`cholesky_solve_slice`] (one AVX2 register).
const LANES: usize = 4;

/// The smallest n solved interleaved: below it the columns' short chains, advanced
/// together by [`solve_columns`], overlap well enough and the interleaving does not pay.
const INTERLEAVED_MIN: usize = 8;

/// The largest n solved interleaved (the block lives on the stack, n × [`LANES`]
/// values); larger factors take [`solve_columns`].
const INTERLEAVED_MAX: usize = 64;

/// [`solve_interleaved`] compiled for AVX2 (no fused multiply-adds: the same roundings).
///
/// # Safety
/// The CPU must support AVX2.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
unsafe fn solve_interleaved_avx2(l: &[f64], b: &mut [f64], n: usize) {
    solve_interleaved::<true>(l, b, n);
}

/// The substitutions of [`cholesky_solve_slice`] for [`INTERLEAVED_MIN`] ≤ n ≤
/// [`INTERLEAVED_MAX`] (sizes checked there; `AVX`: the lane operations as AVX
/// instructions, only in [`solve_interleaved_avx2`]). Every full group of [`LANES`] right-hand sides is interleaved in
/// place (element i of the four side by side), the last, partial group in a block on
/// the stack (its lanes past the last column zero, and they stay zero); every row of
/// the substitutions then runs over all groups before the next, so that their chains
/// of divisions and subtractions overlap.
#[inline(always)]
fn solve_interleaved<const AVX: bool>(l: &[f64], b: &mut [f64], n: usize) {
    let l = &l[..n * n];
    let mut tmp = [0.0; LANES * INTERLEAVED_MAX];
    let tmp = &mut tmp[..LANES * n];
    let mut tail = [[0.0; LANES]; INTERLEAVED_MAX];
    let tail = &mut tail[..n];
    let full = b.len() / (LANES * n) * (LANES * n);
    let (head, rest) = b.split_at_mut(full);
    for group in head.chunks_exact_mut(LANES * n) {
        tmp.copy_from_slice(group);
        for (i, x) in group.chunks_exact_mut(LANES).enumerate() {
            for (u, xu) in x.iter_mut().enumerate() {
                *xu = tmp[u * n + i];
            }
        }
    }
    for (u, x) in rest.chunks_exact(n).enumerate() {
        for (ti, &xi) in tail.iter_mut().zip(x) {
            ti[u] = xi;
        }
    }
    let (groups, _) = head.as_chunks_mut::<LANES>();
    let has_tail = !rest.is_empty();
    // The groups, each n rows of LANES: the interleaved ones in `b`, then the tail.
    macro_rules! each_group {
        (|$t:ident| $body:block) => {
            for $t in groups.chunks_exact_mut(n) $body
            if has_tail {
                let $t = &mut *tail;
                $body
            }
        };
    }
    // L y = b, column-oriented: y_k = b_k / l_kk, then b_i −= l_ik y_k for i > k.
    for (k, lk) in l.chunks_exact(n).enumerate() {
        let (lkk, lt) = (lk[k], &lk[k + 1..]);
        each_group!(|t| {
            let (done, below) = t.split_at_mut(k + 1);
            let yk = div_lanes::<AVX>(&done[k], lkk);
            done[k] = yk;
            for (ti, &lik) in below.iter_mut().zip(lt) {
                sub_scaled::<AVX>(ti, lik, &yk);
            }
        });
    }
    // Lᵀ x = y: x_i = (y_i − Σ_{k>i} l_ki x_k) / l_ii down the contiguous column i.
    for (i, li) in l.chunks_exact(n).enumerate().rev() {
        let (lii, lt) = (li[i], &li[i + 1..]);
        each_group!(|t| {
            let (upto, below) = t.split_at_mut(i + 1);
            let mut s = upto[i];
            for (tk, &lki) in below.iter().zip(lt) {
                sub_scaled::<AVX>(&mut s, lki, tk);
            }
            upto[i] = div_lanes::<AVX>(&s, lii);
        });
    }
    for group in head.chunks_exact_mut(LANES * n) {
        tmp.copy_from_slice(group);
        for (u, x) in group.chunks_exact_mut(n).enumerate() {
            for (i, xi) in x.iter_mut().enumerate() {
                *xi = tmp[i * LANES + u];
            }
        }
    }
    for (u, x) in rest.chunks_exact_mut(n).enumerate() {
        for (xi, ti) in x.iter_mut().zip(tail.iter()) {
            *xi = ti[u];
        }
    }
}

/// `x −= a y` lane by lane: a multiplication, then a subtraction (the roundings of the
/// scalar form); one AVX multiply and subtract where `AVX`.
#[inline(always)]
fn sub_scaled<const AVX: bool>(x: &mut [f64; LANES], a: f64, y: &[f64; LANES]) {
    #[cfg(target_arch = "x86_64")]
    if AVX {
        // SAFETY: `AVX` is only set in the build for AVX2 (`solve_interleaved_avx2`), which
        // runs only where the CPU has it.
        unsafe { sub_scaled_avx(x, a, y) };
        return;
    }
    for (xu, &yu) in x.iter_mut().zip(y) {
        *xu -= a * yu;
    }
}

/// `x / d` lane by lane; one AVX division where `AVX`.
#[inline(always)]
fn div_lanes<const AVX: bool>(x: &[f64; LANES], d: f64) -> [f64; LANES] {
    #[cfg(target_arch = "x86_64")]
    if AVX {
        // SAFETY: as in `sub_scaled`.
        return unsafe { div_lanes_avx(x, d) };
    }
    std::array::from_fn(|u| x[u] / d)
}

/// [`sub_scaled`] in AVX registers.
///
/// # Safety
/// The CPU must support AVX.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx")]
#[inline]
unsafe fn sub_scaled_avx(x: &mut [f64; LANES], a: f64, y: &[f64; LANES]) {
    use std::arch::x86_64::{_mm256_loadu_pd, _mm256_mul_pd, _mm256_set1_pd};
    use std::arch::x86_64::{_mm256_storeu_pd, _mm256_sub_pd};
    // SAFETY: x and y are four f64 each (unaligned loads and stores).
    unsafe {
        let (xv, yv) = (_mm256_loadu_pd(x.as_ptr()), _mm256_loadu_pd(y.as_ptr()));
        let r = _mm256_sub_pd(xv, _mm256_mul_pd(_mm256_set1_pd(a), yv));
        _mm256_storeu_pd(x.as_mut_ptr(), r);
    }
}

/// [`div_lanes`] in an AVX register.
///
/// # Safety
/// The CPU must support AVX.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx")]
#[inline]
unsafe fn div_lanes_avx(x: &[f64; LANES], d: f64) -> [f64; LANES] {
    use std::arch::x86_64::{_mm256_div_pd, _mm256_loadu_pd, _mm256_set1_pd, _mm256_storeu_pd};
    let mut out = [0.0; LANES];
    // SAFETY: x and out are four f64 each (unaligned loads and stores).
    unsafe {
        let r = _mm256_div_pd(_mm256_loadu_pd(x.as_ptr()), _mm256_set1_pd(d));
        _mm256_storeu_pd(out.as_mut_ptr(), r);
    }
    out
}

/// The substitutions of [`cholesky_solve_slice`] for large factors, column by column:
/// the forward one column-oriented (`b[i] −= l[i, k] b[k]` for i > k, contiguous in
/// i), the backward one by dot products down the contiguous columns of `l`, four
/// right-hand sides side by side (the same operations in the same order as the
/// interleaved form).
#[inline(always)]
fn solve_columns(l: &[f64], b: &mut [f64], n: usize) {
    let l = &l[..n * n];
    // L y = b
    for (k, lk) in l.chunks_exact(n).enumerate() {
        for x in b.chunks_exact_mut(n) {
            let yk = x[k] / lk[k];
            x[k] = yk;
            for (xi, &lik) in x[k + 1..].iter_mut().zip(&lk[k + 1..]) {
                *xi -= lik * yk;
            }
        }
    }
    // Lᵀ x = y
    for (i, li) in l.chunks_exact(n).enumerate().rev() {
        let (lt, lii) = (&li[i + 1..], li[i]);
        let mut quads = b.chunks_exact_mut(if n >= 8 { 4 * n } else { b.len() + 1 });
        for q in &mut quads {
            let (x01, x23) = q.split_at_mut(2 * n);
            let (x0, x1) = x01.split_at_mut(n);
            let (x2, x3) = x23.split_at_mut(n);
            let mut s = [x0[i], x1[i], x2[i], x3[i]];
            let t = i + 1;
            for (((&lki, &y0), (&y1, &y2)), &y3) in lt
                .iter()
                .zip(&x0[t..])
                .zip(x1[t..].iter().zip(&x2[t..]))
                .zip(&x3[t..])
            {
                s[0] -= lki * y0;
                s[1] -= lki * y1;
                s[2] -= lki * y2;
                s[3] -= lki * y3;
            }
            x0[i] = s[0] / lii;
            x1[i] = s[1] / lii;
            x2[i] = s[2] / lii;
            x3[i] = s[3] / lii;
        }
        for x in quads.into_remainder().chunks_exact_mut(n) {
            let mut s = x[i];
            for (&lki, &xk) in lt.iter().zip(&x[i + 1..]) {
                s -= lki * xk;
            }
            x[i] = s / lii;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::{DMatrix, DVector};

    fn spd(n: usize) -> DMatrix<f64> {
        let b = DMatrix::from_fn(n, n, |i, j| {
            ((i * 7 + j * 3) % 5) as f64 - 2.0 + 0.1 * i as f64
        });
        &b * b.transpose() + DMatrix::identity(n, n)
    }

    #[test]
    fn factor_solve_inverse() {
        for n in 1..13 {
            let a = spd(n);
            let mut l = a.clone();
            cholesky_in_place(&mut l).unwrap();
            assert!((&l * l.transpose() - &a).norm() < 1e-10);
            let b = DVector::from_fn(n, |i, _| i as f64 - 1.5);
            let mut x = b.clone();
            cholesky_solve_in_place(&l, &mut x).unwrap();
            assert!((&a * &x - &b).norm() < 1e-10);
            let mut bm = DMatrix::from_fn(n, 6, |i, j| (i + j) as f64);
            let rhs = bm.clone();
            cholesky_solve_matrix_in_place(&l, &mut bm).unwrap();
            assert!((&a * &bm - &rhs).norm() < 1e-10);
            // The contiguous forms give the same bits.
            let mut ls = a.clone();
            cholesky_in_place_slice(ls.as_mut_slice(), n).unwrap();
            assert_eq!(ls, l);
            let mut bs = rhs.clone();
            cholesky_solve_slice(ls.as_slice(), n, bs.as_mut_slice()).unwrap();
            assert_eq!(bs, bm);
        }
    }

    #[test]
    fn solve_slice_is_bitwise_the_generic_solve() {
        // Both sides of the interleaved block size, 1–7 right-hand sides (partly
        // filled blocks), and the column form past it.
        for n in [8, 20, 33, 64, 65, 70] {
            let mut l = spd(n);
            cholesky_in_place(&mut l).unwrap();
            for cols in 1..=7 {
                let mut bm = rhs_of(n, cols);
                let mut bs = bm.clone();
                cholesky_solve_in_place(&l, &mut bm).unwrap();
                cholesky_solve_slice(l.as_slice(), n, bs.as_mut_slice()).unwrap();
                assert_eq!(bs, bm, "n = {n}, {cols} columns");
                if n <= INTERLEAVED_MAX {
                    // The portable build of the interleaved form too (the CPUs without
                    // AVX2).
                    let mut bp = rhs_of(n, cols);
                    solve_interleaved::<false>(l.as_slice(), bp.as_mut_slice(), n);
                    assert_eq!(bp, bm, "portable, n = {n}, {cols} columns");
                }
            }
        }
    }

    fn rhs_of(n: usize, cols: usize) -> DMatrix<f64> {
        DMatrix::from_fn(n, cols, |i, j| (i as f64 - 3.0) * 0.7 + j as f64)
    }

    #[test]
    fn rejects_indefinite_and_bad_sizes() {
        let mut a = DMatrix::from_row_slice(2, 2, &[1.0, 2.0, 2.0, 1.0]);
        assert!(matches!(
            cholesky_in_place(&mut a),
            Err(LinalgError::NotPositiveDefinite { index: 1, .. })
        ));
        let mut r = DMatrix::<f64>::zeros(2, 3);
        assert!(matches!(
            cholesky_in_place(&mut r),
            Err(LinalgError::DimensionMismatch { .. })
        ));
        let l = DMatrix::<f64>::identity(2, 2);
        let mut b = DVector::<f64>::zeros(3);
        assert!(cholesky_solve_in_place(&l, &mut b).is_err());
        let mut nan = DMatrix::from_row_slice(1, 1, &[f64::NAN]);
        assert!(cholesky_in_place(&mut nan).is_err());
    }
}
