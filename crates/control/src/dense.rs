//! Small dense kernels that never allocate: products into preallocated outputs,
//! a Householder null-space basis, a cyclic Jacobi eigen-solver, damped SPD
//! inversion and the orthogonal Procrustes alignment of a basis.
//!
//! Every function assumes outputs of the right size (checked by the caller at
//! construction). The products work on the column-major storage with small register
//! blocks (no packing buffer, so nothing to allocate — the matrices of a robot
//! controller are at most a few dozen rows). Every element is summed in the order of
//! the plain triple loop, so the results do not depend on the blocking.

use nalgebra::{DMatrix, DVector};

/// Rows per register block of the column-oriented kernels.
const MR: usize = 8;

/// `alpha * s + beta * c` exactly as the reference triple loop forms it.
#[inline(always)]
fn scale(alpha: f64, s: f64, beta: f64, c: f64) -> f64 {
    alpha * s + if beta == 0.0 { 0.0 } else { beta * c }
}

/// The right operand of [`gemm_cols`]: element (l, j) of op(b) is
/// `data[l * ls + j * js]` (b itself: ls = 1, js = k; bᵀ: ls = n, js = 1; a vector:
/// ls = 1, js = 0).
#[derive(Clone, Copy)]
struct Strided<'b> {
    data: &'b [f64],
    ls: usize,
    js: usize,
}

/// `c = alpha * a * op(b) + beta * c` for `a` m × k (column-major slice), op(b) k × n
/// and `c` m × n. Column-major: rows in blocks of at most [`MR`] accumulators (a
/// kernel per block width, so small matrices run fully unrolled), one output column at
/// a time, so the inner loop runs down contiguous columns of `a` and vectorises. Every
/// element is still summed over l in increasing order, so the result is bitwise that
/// of the plain dot-product loop.
#[inline(always)]
fn gemm_cols(
    c: &mut [f64],
    alpha: f64,
    a: &[f64],
    (m, k, n): (usize, usize, usize),
    b: Strided,
    beta: f64,
) {
    // The bounds the unchecked loads and stores of `rows` rely on.
    assert!(a.len() >= m * k && c.len() >= m * n);
    assert!(k == 0 || n == 0 || (k - 1) * b.ls + (n - 1) * b.js < b.data.len());
    #[cfg(target_arch = "x86_64")]
    if m * k * n >= AVX2_MIN_WORK && std::arch::is_x86_feature_detected!("avx2") {
        if std::arch::is_x86_feature_detected!("fma") {
            if (1..=FIXED_MAX).contains(&m) && (1..=FIXED_MAX).contains(&k) {
                // SAFETY: the CPU supports AVX2 and FMA (just checked); the bounds are
                // checked above.
                unsafe { FIXED_FMA[(m - 1) * FIXED_MAX + k - 1](c, alpha, a, n, b, beta) };
                return;
            }
            // SAFETY: the CPU supports AVX2 and FMA (just checked); the bounds are
            // checked above.
            unsafe { gemm_cols_avx2_fma(c, alpha, a, (m, k, n), b, beta, m) };
        } else {
            // SAFETY: the CPU supports AVX2 (just checked); the bounds are checked above.
            unsafe { gemm_cols_avx2(c, alpha, a, (m, k, n), b, beta, m) };
        }
        return;
    }
    if (1..=FIXED_MAX).contains(&m) && (1..=FIXED_MAX).contains(&k) {
        FIXED[(m - 1) * FIXED_MAX + k - 1](c, alpha, a, n, b, beta);
        return;
    }
    gemm_blocks::<1, false>(c, alpha, a, (m, k, n), b, beta, m);
}

/// The largest row count and inner dimension of the fixed-size product builds.
const FIXED_MAX: usize = 8;

/// A build of the portable [`gemm_cols`] for one (m, k): `(c, alpha, a, n, b, beta)`.
type FixedKernel = fn(&mut [f64], f64, &[f64], usize, Strided, f64);

/// `[$f::<M, K>, …]` for M, K in 1..=8 (row-major in (M, K)).
macro_rules! fixed_table {
    ($f:ident) => {
        fixed_table!(@m $f, [1 2 3 4 5 6 7 8])
    };
    (@m $f:ident, [$($m:literal)*]) => {
        [$(
            $f::<$m, 1>, $f::<$m, 2>, $f::<$m, 3>, $f::<$m, 4>,
            $f::<$m, 5>, $f::<$m, 6>, $f::<$m, 7>, $f::<$m, 8>,
        )*]
    };
}

/// The portable products with m, k ≤ [`FIXED_MAX`], indexed by (m − 1) 8 + k − 1.
static FIXED: [FixedKernel; FIXED_MAX * FIXED_MAX] = fixed_table!(fixed_cols);

/// A build of [`gemm_cols_avx2_fma`] for one (m, k).
#[cfg(target_arch = "x86_64")]
type FixedKernelFma = unsafe fn(&mut [f64], f64, &[f64], usize, Strided, f64);

/// The AVX2 and FMA products with m, k ≤ [`FIXED_MAX`], indexed as [`FIXED`].
#[cfg(target_arch = "x86_64")]
static FIXED_FMA: [FixedKernelFma; FIXED_MAX * FIXED_MAX] = fixed_table!(fixed_cols_fma);

/// [`gemm_cols_avx2_fma`] for m = M, k = K: its single row block with the inner loop
/// fully unrolled (the same fused operations in the same order).
///
/// # Safety
/// The CPU must support AVX2 and FMA, and the sizes must satisfy the checks of
/// [`gemm_cols`] with m = M and k = K.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,fma")]
unsafe fn fixed_cols_fma<const M: usize, const K: usize>(
    c: &mut [f64],
    alpha: f64,
    a: &[f64],
    n: usize,
    b: Strided,
    beta: f64,
) {
    rows::<M, 4, true>(c, alpha, a, (M, K, n), 0, b, beta);
}

/// [`gemm_cols`] for m = M, k = K (sizes checked there): fully unrolled over the
/// rows and the inner dimension, one output column at a time — the operations of
/// [`gemm_blocks`] in the same order, without its loop set-up.
fn fixed_cols<const M: usize, const K: usize>(
    c: &mut [f64],
    alpha: f64,
    a: &[f64],
    n: usize,
    b: Strided,
    beta: f64,
) {
    let a = &a[..M * K];
    let c = &mut c[..M * n];
    let bp = b.data.as_ptr();
    for (j, cj) in c.chunks_exact_mut(M).enumerate() {
        let mut s = [0.0; M];
        for l in 0..K {
            // SAFETY: l < K = k and j < n, so l ls + j js ≤ (k − 1) ls + (n − 1) js,
            // which `gemm_cols` checked to be inside b.
            let bl = unsafe { *bp.add(l * b.ls + j * b.js) };
            for (t, st) in s.iter_mut().enumerate() {
                *st = madd::<false>(*st, a[l * M + t], bl);
            }
        }
        for (x, &st) in cj.iter_mut().zip(&s) {
            *x = scale(alpha, st, beta, *x);
        }
    }
}

/// Products of at least this many multiply-adds run in the AVX2 build of
/// [`gemm_blocks`] where the CPU has it (four lanes instead of two, four output columns
/// at a time, fused multiply-adds where the CPU has them; below this the products are
/// too short to gain from the wider registers).
#[cfg(target_arch = "x86_64")]
const AVX2_MIN_WORK: usize = 64;

/// [`gemm_blocks`] compiled for AVX2 without fused multiply-adds: every product and
/// sum is rounded as in the portable build (the CPUs with AVX2 but no FMA).
///
/// # Safety
/// The CPU must support AVX2, and the sizes must satisfy the checks of [`gemm_cols`].
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
unsafe fn gemm_cols_avx2(
    c: &mut [f64],
    alpha: f64,
    a: &[f64],
    (m, k, n): (usize, usize, usize),
    b: Strided,
    beta: f64,
    rows_end: usize,
) {
    gemm_blocks::<4, false>(c, alpha, a, (m, k, n), b, beta, rows_end);
}

/// [`gemm_blocks`] compiled for AVX2 and FMA: every multiply-add of the sums is one
/// fused operation (one rounding instead of two: half the arithmetic, and results that
/// differ from the portable build's at the rounding level, the same on every CPU with
/// these features).
///
/// # Safety
/// The CPU must support AVX2 and FMA, and the sizes must satisfy the checks of
/// [`gemm_cols`].
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,fma")]
unsafe fn gemm_cols_avx2_fma(
    c: &mut [f64],
    alpha: f64,
    a: &[f64],
    (m, k, n): (usize, usize, usize),
    b: Strided,
    beta: f64,
    rows_end: usize,
) {
    gemm_blocks::<4, true>(c, alpha, a, (m, k, n), b, beta, rows_end);
}

/// `s + a b`, fused (one rounding) in the builds for FMA.
#[inline(always)]
fn madd<const FMA: bool>(s: f64, a: f64, b: f64) -> f64 {
    if FMA { a.mul_add(b, s) } else { s + a * b }
}

/// The row blocks of [`gemm_cols`] (sizes checked there), `NC` output columns at a
/// time; rows `rows_end..m` are left as they are (all rows: `rows_end` = m).
#[inline(always)]
fn gemm_blocks<const NC: usize, const FMA: bool>(
    c: &mut [f64],
    alpha: f64,
    a: &[f64],
    (m, k, n): (usize, usize, usize),
    b: Strided,
    beta: f64,
    rows_end: usize,
) {
    debug_assert!(rows_end <= m);
    let mut i = 0;
    while i < rows_end {
        let w = MR.min(rows_end - i);
        match w {
            8 => rows::<8, NC, FMA>(c, alpha, a, (m, k, n), i, b, beta),
            7 => rows::<7, NC, FMA>(c, alpha, a, (m, k, n), i, b, beta),
            6 => rows::<6, NC, FMA>(c, alpha, a, (m, k, n), i, b, beta),
            5 => rows::<5, NC, FMA>(c, alpha, a, (m, k, n), i, b, beta),
            4 => rows::<4, NC, FMA>(c, alpha, a, (m, k, n), i, b, beta),
            3 => rows::<3, NC, FMA>(c, alpha, a, (m, k, n), i, b, beta),
            2 => rows::<2, NC, FMA>(c, alpha, a, (m, k, n), i, b, beta),
            _ => rows::<1, NC, FMA>(c, alpha, a, (m, k, n), i, b, beta),
        }
        i += w;
    }
}

/// Rows i..i+W of [`gemm_cols`]: `NC` output columns at a time (W × NC accumulators,
/// which the compiler keeps in vector registers across the rows: NC independent
/// chains of additions instead of one), the remaining columns one at a time.
#[inline(always)]
fn rows<const W: usize, const NC: usize, const FMA: bool>(
    c: &mut [f64],
    alpha: f64,
    a: &[f64],
    (m, k, n): (usize, usize, usize),
    i: usize,
    b: Strided,
    beta: f64,
) {
    debug_assert!(i + W <= m);
    let (ap, bp, cp) = (a.as_ptr(), b.data.as_ptr(), c.as_mut_ptr());
    let mut j = 0;
    while j + NC <= n {
        let mut s = [[0.0; W]; NC];
        for l in 0..k {
            // SAFETY: l < k and j + u < n, so l ls + (j + u) js ≤ (k − 1) ls + (n − 1) js,
            // which `gemm_cols` checked to be inside b; l m + i + t < (k − 1) m + m =
            // k m ≤ a.len() since i + t < i + W ≤ m.
            let al: [f64; W] = std::array::from_fn(|t| unsafe { *ap.add(l * m + i + t) });
            for (u, su) in s.iter_mut().enumerate() {
                let bl = unsafe { *bp.add(l * b.ls + (j + u) * b.js) };
                for (st, &at) in su.iter_mut().zip(&al) {
                    *st = madd::<FMA>(*st, at, bl);
                }
            }
        }
        for (u, su) in s.iter().enumerate() {
            for (t, &st) in su.iter().enumerate() {
                // SAFETY: (j + u) m + i + t < (n − 1) m + m = m n ≤ c.len() (checked in
                // `gemm_cols`).
                let x = unsafe { &mut *cp.add((j + u) * m + i + t) };
                *x = scale(alpha, st, beta, *x);
            }
        }
        j += NC;
    }
    for j in j..n {
        let mut s = [0.0; W];
        for l in 0..k {
            // SAFETY: as above, with one column j < n.
            let bl = unsafe { *bp.add(l * b.ls + j * b.js) };
            for (t, st) in s.iter_mut().enumerate() {
                *st = madd::<FMA>(*st, unsafe { *ap.add(l * m + i + t) }, bl);
            }
        }
        for (t, &st) in s.iter().enumerate() {
            // SAFETY: j m + i + t < (n − 1) m + m = m n ≤ c.len() (checked in `gemm_cols`).
            let x = unsafe { &mut *cp.add(j * m + i + t) };
            *x = scale(alpha, st, beta, *x);
        }
    }
}

/// `dst = src` for matrices or vectors of the same shape, as one slice copy (nalgebra's
/// `copy_from` goes element by element through its two-dimensional indexing).
#[inline]
pub fn copy<C: nalgebra::Dim>(
    dst: &mut nalgebra::OMatrix<f64, nalgebra::Dyn, C>,
    src: &nalgebra::OMatrix<f64, nalgebra::Dyn, C>,
) where
    nalgebra::DefaultAllocator: nalgebra::allocator::Allocator<nalgebra::Dyn, C>,
{
    assert_eq!(dst.shape(), src.shape());
    dst.as_mut_slice().copy_from_slice(src.as_slice());
}

/// `c = alpha * a * b + beta * c`.
pub fn gemm(c: &mut DMatrix<f64>, alpha: f64, a: &DMatrix<f64>, b: &DMatrix<f64>, beta: f64) {
    assert_eq!(b.ncols(), c.ncols());
    assert_eq!(a.ncols(), b.nrows());
    gemm_leading(c, alpha, a, b, beta);
}

/// `c = alpha * a[.., ..k] * b[.., ..p] + beta * c` with k = the rows of `b` and p =
/// the columns of `c`: [`gemm`] on the leading columns of `a` and of `b` (prefixes of
/// their column-major storage, so nothing is copied) — a product of which only the
/// first columns are needed, or with the first block of a stacked matrix.
pub fn gemm_leading(
    c: &mut DMatrix<f64>,
    alpha: f64,
    a: &DMatrix<f64>,
    b: &DMatrix<f64>,
    beta: f64,
) {
    let (m, k, n) = (c.nrows(), b.nrows(), c.ncols());
    assert_eq!(a.nrows(), m);
    assert!(k <= a.ncols() && n <= b.ncols());
    let b = Strided {
        data: b.as_slice(),
        ls: 1,
        js: k,
    };
    gemm_cols(
        c.as_mut_slice(),
        alpha,
        &a.as_slice()[..m * k],
        (m, k, n),
        b,
        beta,
    );
}

/// `c = a b` for a product known to be symmetric (e.g. Vᵀ (M V) with M symmetric and
/// Vᵀ stored): only the upper triangle is formed (with the diagonal blocks of the
/// kernel; the strict lower triangle is left undefined), then mirrored onto the lower
/// one, so the result is exactly symmetric at about half the cost. Every upper element
/// is the same sum as in [`gemm`] (the same kernel for the same sizes), so the result
/// is bitwise that of [`gemm`] followed by [`mirror_upper`].
pub fn gemm_sym(c: &mut DMatrix<f64>, a: &DMatrix<f64>, b: &DMatrix<f64>) {
    let (m, k, n) = (a.nrows(), a.ncols(), b.ncols());
    assert_eq!(b.nrows(), k);
    assert_eq!(c.shape(), (m, n));
    assert_eq!(m, n);
    let (a, bd, cs) = (a.as_slice(), b.as_slice(), c.as_mut_slice());
    // The kernel `gemm_cols` would choose for the whole product (FMA or not decides
    // the roundings).
    #[cfg(target_arch = "x86_64")]
    let (avx2, fma) = {
        let avx2 = m * k * n >= AVX2_MIN_WORK && std::arch::is_x86_feature_detected!("avx2");
        (avx2, avx2 && std::arch::is_x86_feature_detected!("fma"))
    };
    // Four columns at a time, rows down to the last of them.
    let mut j = 0;
    while j < n {
        let cols = 4.min(n - j);
        let rows_end = (j + cols).min(m);
        let b = Strided {
            data: &bd[j * k..(j + cols) * k],
            ls: 1,
            js: k,
        };
        let c = &mut cs[j * m..(j + cols) * m];
        #[cfg(target_arch = "x86_64")]
        if avx2 {
            if fma {
                // SAFETY: the CPU supports AVX2 and FMA (checked above); a is m × k,
                // b k × cols and c m × cols, as `gemm_cols` requires.
                unsafe { gemm_cols_avx2_fma(c, 1.0, a, (m, k, cols), b, 0.0, rows_end) };
            } else {
                // SAFETY: the CPU supports AVX2 (checked above); sizes as above.
                unsafe { gemm_cols_avx2(c, 1.0, a, (m, k, cols), b, 0.0, rows_end) };
            }
            j += cols;
            continue;
        }
        gemm_blocks::<1, false>(c, 1.0, a, (m, k, cols), b, 0.0, rows_end);
        j += cols;
    }
    // The upper triangle onto the lower one (as `mirror_upper`).
    for j in 0..n {
        for i in (j + 1)..n {
            cs[j * n + i] = cs[i * n + j];
        }
    }
}

/// `c = alpha * a * bᵀ + beta * c`.
pub fn gemm_nt(c: &mut DMatrix<f64>, alpha: f64, a: &DMatrix<f64>, b: &DMatrix<f64>, beta: f64) {
    assert_eq!(b.ncols(), a.ncols());
    gemm_nt_leading(c, alpha, a, b, beta);
}

/// `c = alpha * a * b[.., ..k]ᵀ + beta * c` with k = the columns of `a`: [`gemm_nt`]
/// with the leading columns of `b` (a prefix of its storage, nothing copied).
pub fn gemm_nt_leading(
    c: &mut DMatrix<f64>,
    alpha: f64,
    a: &DMatrix<f64>,
    b: &DMatrix<f64>,
    beta: f64,
) {
    let (m, k, n) = (a.nrows(), a.ncols(), b.nrows());
    assert!(k <= b.ncols());
    assert_eq!(c.shape(), (m, n));
    let b = Strided {
        data: &b.as_slice()[..n * k],
        ls: n,
        js: 1,
    };
    gemm_cols(c.as_mut_slice(), alpha, a.as_slice(), (m, k, n), b, beta);
}

/// `c = alpha * aᵀ * b + beta * c`: dot products of contiguous columns, a 4 × 2 block of
/// them at a time (eight independent sums, each over l in increasing order).
pub fn gemm_tn(c: &mut DMatrix<f64>, alpha: f64, a: &DMatrix<f64>, b: &DMatrix<f64>, beta: f64) {
    let (m, k, n) = (a.ncols(), a.nrows(), b.ncols());
    assert_eq!(b.nrows(), k);
    assert_eq!(c.shape(), (m, n));
    gemm_tn_block(c, alpha, a, b, beta, false);
}

/// `c = aᵀ b` for a product known to be symmetric (e.g. Vᵀ M V with M symmetric): the
/// upper triangle (and the diagonal blocks) are computed, the lower one mirrored, so
/// the result is exactly symmetric at about half the cost.
pub fn gemm_tn_sym(c: &mut DMatrix<f64>, a: &DMatrix<f64>, b: &DMatrix<f64>) {
    let (m, k, n) = (a.ncols(), a.nrows(), b.ncols());
    assert_eq!(b.nrows(), k);
    assert_eq!(c.shape(), (m, n));
    assert_eq!(m, n);
    gemm_tn_block(c, 1.0, a, b, 0.0, true);
    mirror_upper(c);
}

/// `out = aᵀ` (row i of `a`, a strided run, becomes column i of `out`).
pub fn transpose_into(out: &mut DMatrix<f64>, a: &DMatrix<f64>) {
    assert_eq!(out.nrows(), a.ncols());
    transpose_cols_into(out, a, 0);
}

/// `out = a[.., c0..c0 + p]ᵀ` with p = the rows of `out`: the transpose of a block of
/// columns (row i of `a` from column c0 on becomes column i of `out`).
pub fn transpose_cols_into(out: &mut DMatrix<f64>, a: &DMatrix<f64>, c0: usize) {
    let (r, p) = (a.nrows(), out.nrows());
    assert_eq!(out.ncols(), r);
    assert!(c0 + p <= a.ncols());
    if r == 0 || p == 0 {
        return;
    }
    // Four columns c0 + t.. of `a` (contiguous) at a time become rows t..t + 4 of
    // `out`: four streams read down the columns, four adjacent elements written to
    // every column of `out`.
    let a = &a.as_slice()[c0 * r..(c0 + p) * r];
    let out = out.as_mut_slice();
    if p <= FIXED_MAX && r <= FIXED_MAX {
        FIXED_TRANSPOSE[(p - 1) * FIXED_MAX + r - 1](out, a);
        return;
    }
    let mut t = 0;
    while t + 4 <= p {
        let (s0, s1) = (&a[t * r..(t + 1) * r], &a[(t + 1) * r..(t + 2) * r]);
        let (s2, s3) = (&a[(t + 2) * r..(t + 3) * r], &a[(t + 3) * r..(t + 4) * r]);
        for (i, col) in out.chunks_exact_mut(p).enumerate() {
            col[t..t + 4].copy_from_slice(&[s0[i], s1[i], s2[i], s3[i]]);
        }
        t += 4;
    }
    while t < p {
        let src = &a[t * r..(t + 1) * r];
        for (col, &x) in out.chunks_exact_mut(p).zip(src) {
            col[t] = x;
        }
        t += 1;
    }
}

/// A build of [`transpose_cols_into`] for one size: `(out, a)`.
type FixedTranspose = fn(&mut [f64], &[f64]);

/// The transposes of P columns of R rows, P, R ≤ [`FIXED_MAX`], indexed as [`FIXED`]
/// by (P, R).
static FIXED_TRANSPOSE: [FixedTranspose; FIXED_MAX * FIXED_MAX] = fixed_table!(fixed_transpose);

/// `out` (R × P) = the transpose of the P contiguous columns of R rows in `a`, unrolled.
fn fixed_transpose<const P: usize, const R: usize>(out: &mut [f64], a: &[f64]) {
    let (out, a) = (&mut out[..P * R], &a[..P * R]);
    for t in 0..P {
        for i in 0..R {
            out[i * P + t] = a[t * R + i];
        }
    }
}

/// Copies the upper triangle of the square `c` onto its lower one (exactly symmetric).
pub fn mirror_upper(c: &mut DMatrix<f64>) {
    let n = c.nrows();
    assert_eq!(c.ncols(), n);
    for j in 0..n {
        for i in (j + 1)..n {
            c[(i, j)] = c[(j, i)];
        }
    }
}

fn column(x: &[f64], k: usize, j: usize) -> &[f64] {
    &x[j * k..(j + 1) * k]
}

/// The dot-product kernel of [`gemm_tn`]; with `upper` only the blocks reaching the
/// upper triangle (rows i ≤ the block's last column) are computed.
#[inline(always)]
fn gemm_tn_block(
    c: &mut DMatrix<f64>,
    alpha: f64,
    a: &DMatrix<f64>,
    b: &DMatrix<f64>,
    beta: f64,
    upper: bool,
) {
    let (m, k, n) = (a.ncols(), a.nrows(), b.ncols());
    let (a, b) = (a.as_slice(), b.as_slice());
    let c = c.as_mut_slice();
    let col = |x, j| column(x, k, j);
    let mut j = 0;
    while j < n {
        let nb = 2.min(n - j);
        let b0 = col(b, j);
        let b1 = col(b, j + nb - 1);
        let rows = if upper { (j + nb).min(m) } else { m };
        let mut i = 0;
        while i + 4 <= rows {
            let (a0, a1, a2, a3) = (col(a, i), col(a, i + 1), col(a, i + 2), col(a, i + 3));
            let mut s = [[0.0; 4]; 2];
            for l in 0..k {
                let (x0, x1) = (b0[l], b1[l]);
                s[0][0] += a0[l] * x0;
                s[0][1] += a1[l] * x0;
                s[0][2] += a2[l] * x0;
                s[0][3] += a3[l] * x0;
                s[1][0] += a0[l] * x1;
                s[1][1] += a1[l] * x1;
                s[1][2] += a2[l] * x1;
                s[1][3] += a3[l] * x1;
            }
            for (jj, sj) in s.iter().enumerate().take(nb) {
                for (t, &v) in sj.iter().enumerate() {
                    let x = &mut c[(j + jj) * m + i + t];
                    *x = scale(alpha, v, beta, *x);
                }
            }
            i += 4;
        }
        while i < rows {
            let ai = col(a, i);
            let mut s = [0.0; 2];
            for l in 0..k {
                s[0] += ai[l] * b0[l];
                s[1] += ai[l] * b1[l];
            }
            for (jj, &v) in s.iter().enumerate().take(nb) {
                let x = &mut c[(j + jj) * m + i];
                *x = scale(alpha, v, beta, *x);
            }
            i += 1;
        }
        j += nb;
    }
}

/// `y = alpha * a * x + beta * y` (the kernel of [`gemm`] with one column).
pub fn gemv(y: &mut DVector<f64>, alpha: f64, a: &DMatrix<f64>, x: &DVector<f64>, beta: f64) {
    gemv_slices(y.as_mut_slice(), alpha, a, x.as_slice(), beta);
}

/// [`gemv`] with `x` and `y` slices (e.g. columns of a matrix, nothing copied).
pub fn gemv_slices(y: &mut [f64], alpha: f64, a: &DMatrix<f64>, x: &[f64], beta: f64) {
    let (m, k) = a.shape();
    assert_eq!(k, x.len());
    assert_eq!(m, y.len());
    let x = Strided {
        data: x,
        ls: 1,
        js: 0,
    };
    gemm_cols(y, alpha, a.as_slice(), (m, k, 1), x, beta);
}

/// `y = alpha * aᵀ * x + beta * y` (dot products of columns, four at a time).
pub fn gemv_t(y: &mut DVector<f64>, alpha: f64, a: &DMatrix<f64>, x: &DVector<f64>, beta: f64) {
    gemv_t_slices(y.as_mut_slice(), alpha, a, x.as_slice(), beta);
}

/// [`gemv_t`] with `x` and `y` slices (e.g. columns of a matrix, nothing copied).
pub fn gemv_t_slices(y: &mut [f64], alpha: f64, a: &DMatrix<f64>, x: &[f64], beta: f64) {
    assert_eq!(a.shape(), (x.len(), y.len()));
    gemv_t_slice(y, alpha, a.as_slice(), x, beta);
}

/// [`gemv_t`] on slices: `a` column-major with columns of the length of `x`, as many
/// as `y` has elements.
fn gemv_t_slice(y: &mut [f64], alpha: f64, a: &[f64], x: &[f64], beta: f64) {
    let (k, n) = (x.len(), y.len());
    assert_eq!(a.len(), k * n);
    if (1..=FIXED_MAX).contains(&k) {
        FIXED_T[k - 1](y, alpha, a, x, beta);
        return;
    }
    let mut j = 0;
    while j + 4 <= n {
        let c = &a[j * k..(j + 4) * k];
        let mut s = [0.0; 4];
        for l in 0..k {
            s[0] += c[l] * x[l];
            s[1] += c[k + l] * x[l];
            s[2] += c[2 * k + l] * x[l];
            s[3] += c[3 * k + l] * x[l];
        }
        for t in 0..4 {
            y[j + t] = scale(alpha, s[t], beta, y[j + t]);
        }
        j += 4;
    }
    while j < n {
        let c = &a[j * k..(j + 1) * k];
        let mut s = 0.0;
        for l in 0..k {
            s += c[l] * x[l];
        }
        y[j] = scale(alpha, s, beta, y[j]);
        j += 1;
    }
}

/// A build of [`gemv_t`] for one dot-product length k: `(y, alpha, a, x, beta)`.
type FixedKernelT = fn(&mut [f64], f64, &[f64], &[f64], f64);

/// The [`gemv_t`] builds for k = 1..=8, indexed by k − 1.
static FIXED_T: [FixedKernelT; FIXED_MAX] = [
    fixed_dots::<1>,
    fixed_dots::<2>,
    fixed_dots::<3>,
    fixed_dots::<4>,
    fixed_dots::<5>,
    fixed_dots::<6>,
    fixed_dots::<7>,
    fixed_dots::<8>,
];

/// [`gemv_t`] for columns of length K (sizes checked there): every y_j = x · a_j summed
/// over l in increasing order, fully unrolled.
fn fixed_dots<const K: usize>(y: &mut [f64], alpha: f64, a: &[f64], x: &[f64], beta: f64) {
    let x: &[f64; K] = x.try_into().expect("x of length k");
    for (yj, col) in y.iter_mut().zip(a.chunks_exact(K)) {
        let mut s = 0.0;
        for (&al, &xl) in col.iter().zip(x) {
            s += al * xl;
        }
        *yj = scale(alpha, s, beta, *yj);
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
    assert_eq!(a.shape(), (n, n));
    assert_eq!(evecs.shape(), (n, n));
    evecs.fill_with_identity();
    jacobi(a.as_mut_slice(), n, Some(evecs.as_mut_slice()), max_sweeps);
    for i in 0..n {
        evals[i] = a[(i, i)];
    }
}

/// The eigenvalues alone of [`symmetric_eigen`] (the same rotations, so the same
/// values to the bit, without accumulating the eigenvectors).
pub fn symmetric_eigenvalues(a: &mut DMatrix<f64>, evals: &mut DVector<f64>, max_sweeps: usize) {
    let n = a.nrows();
    assert_eq!(a.shape(), (n, n));
    jacobi(a.as_mut_slice(), n, None, max_sweeps);
    for i in 0..n {
        evals[i] = a[(i, i)];
    }
}

/// Rotations whose parameters are formed together in [`jacobi`] (a stack buffer).
const JACOBI_BATCH: usize = 8;

/// The sweeps of [`symmetric_eigen`] on the column-major n × n slice `a`, rotating
/// the columns of `v` along when given. Each sweep visits every pair (p, q) once in
/// the round-robin order (n − 1 rounds of ⌊n/2⌋ disjoint pairs, n + 1 with a resting
/// index for odd n; Golub & Van Loan § 8.5.5). A rotation of (p, q) leaves every
/// other entry a_rs, r, s ∉ {p, q}, as it is, so the rotations of one round have
/// their angles from the matrix at the start of the round: their divisions and
/// square roots, which dominate small matrices, are formed side by side instead of
/// one chain per rotation.
fn jacobi(a: &mut [f64], n: usize, mut v: Option<&mut [f64]>, max_sweeps: usize) {
    let a = &mut a[..n * n];
    // Players of the round robin: an even count, index n resting when n is odd.
    let players = n + (n & 1);
    for _ in 0..max_sweeps {
        let mut off = 0.0;
        let mut diag = 0.0;
        for (j, col) in a.chunks_exact(n).enumerate() {
            diag += col[j] * col[j];
            for &x in &col[..j] {
                off += x * x;
            }
        }
        if off <= 1e-30 * diag || off == 0.0 {
            break;
        }
        for round in 0..players.saturating_sub(1) {
            // Player at seat 0 stays; seat j ≥ 1 holds 1 + (j − 1 + round) mod (players − 1).
            let seat = |j: usize| {
                if j == 0 {
                    0
                } else {
                    1 + (j - 1 + round) % (players - 1)
                }
            };
            let mut i = 0;
            while i < players / 2 {
                // Angles of up to JACOBI_BATCH pairs of the round, then their rotations.
                let mut rot = [(0usize, 0usize, 0.0f64, 0.0f64); JACOBI_BATCH];
                let mut count = 0;
                while i < players / 2 && count < JACOBI_BATCH {
                    let (x, y) = (seat(i), seat(players - 1 - i));
                    i += 1;
                    let (p, q) = (x.min(y), x.max(y));
                    if q >= n {
                        continue;
                    }
                    let apq = a[q * n + p];
                    if apq == 0.0 {
                        continue;
                    }
                    let theta = (a[q * n + q] - a[p * n + p]) / (2.0 * apq);
                    let t = theta.signum() / (theta.abs() + (theta * theta + 1.0).sqrt());
                    let t = if theta == 0.0 { 1.0 } else { t };
                    let c = 1.0 / (t * t + 1.0).sqrt();
                    rot[count] = (p, q, c, t * c);
                    count += 1;
                }
                for &(p, q, c, s) in &rot[..count] {
                    rotate_columns(a, n, p, q, c, s);
                    for col in a.chunks_exact_mut(n) {
                        let (apk, aqk) = (col[p], col[q]);
                        col[p] = c * apk - s * aqk;
                        col[q] = s * apk + c * aqk;
                    }
                    if let Some(v) = v.as_deref_mut() {
                        rotate_columns(v, n, p, q, c, s);
                    }
                }
            }
        }
    }
}

/// Columns p < q of the column-major `x` (n rows) ← (c x_p − s x_q, s x_p + c x_q).
#[inline(always)]
fn rotate_columns(x: &mut [f64], n: usize, p: usize, q: usize, c: f64, s: f64) {
    let (left, right) = x.split_at_mut(q * n);
    let (xp, xq) = (&mut left[p * n..(p + 1) * n], &mut right[..n]);
    for (u, w) in xp.iter_mut().zip(xq.iter_mut()) {
        let (kp, kq) = (*u, *w);
        *u = c * kp - s * kq;
        *w = s * kp + c * kq;
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

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn gemm_sym_is_bitwise_gemm_then_mirror() {
        // Below and above the AVX2 threshold, partial and full column groups.
        for (n, k) in [
            (1, 3),
            (2, 5),
            (3, 7),
            (5, 2),
            (6, 9),
            (9, 32),
            (18, 32),
            (23, 11),
        ] {
            let v = DMatrix::from_fn(k, n, |i, j| ((i * 5 + j * 3) % 7) as f64 * 0.31 - 0.9);
            let w = DMatrix::from_fn(k, k, |i, j| 1.0 / (1.0 + i as f64 + j as f64));
            let wv = &w * &v;
            let vt = v.transpose();
            let mut full = DMatrix::zeros(n, n);
            gemm(&mut full, 1.0, &vt, &wv, 0.0);
            mirror_upper(&mut full);
            let mut sym = DMatrix::from_element(n, n, f64::NAN);
            gemm_sym(&mut sym, &vt, &wv);
            assert_eq!(sym, full, "n = {n}, k = {k}");
        }
    }

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
