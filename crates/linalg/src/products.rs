//! Matrix products into preallocated outputs (`gemm`, `gemv` and their
//! transposed, symmetric and leading-block variants), transposes and copies.
//!
//! **Why hand-written.** nalgebra's `gemm` on `DMatrix` hands every product
//! whose sizes all exceed 5 to `matrixmultiply`, which allocates its packing
//! buffers on every call — not usable in a 1 kHz loop — and at the sizes of a
//! robot controller it is 2–4× slower than the blocks here (benchmark
//! `cargo bench -p hcc-linalg --bench kernels`); nalgebra has no in-place
//! A Bᵀ. Where nalgebra's own allocation-free routines are the faster ones
//! (`gemm_tr` for a result of fewer than four rows, `gemv_tr` from 32 × 32
//! on), [`gemm_tn`] and [`gemv_t`] use them.
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
///
/// Below [`GEMM_TN_BLOCK_MIN_ROWS`] rows of `c` (a null space of dimension 1
/// to 3, a single task row) nalgebra's `gemm_tr` — its dot products, which
/// allocate nothing — is the faster one (benchmark `kernels`: 1.2–1.8× at
/// 7 × 1 to 7 × 3) and is used.
pub fn gemm_tn(c: &mut DMatrix<f64>, alpha: f64, a: &DMatrix<f64>, b: &DMatrix<f64>, beta: f64) {
    let (m, k, n) = (a.ncols(), a.nrows(), b.ncols());
    assert_eq!(b.nrows(), k);
    assert_eq!(c.shape(), (m, n));
    if m < GEMM_TN_BLOCK_MIN_ROWS {
        c.gemm_tr(alpha, a, b, beta);
        return;
    }
    gemm_tn_block(c, alpha, a, b, beta, false);
}

/// The fewest rows of `c = aᵀ b` from which [`gemm_tn`]'s blocks beat
/// nalgebra's `gemm_tr` (benchmark `kernels`).
pub const GEMM_TN_BLOCK_MIN_ROWS: usize = 4;

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
///
/// From [`GEMV_T_NALGEBRA_MIN_ENTRIES`] entries of `a` on (a 32-joint chain's
/// M), nalgebra's `gemv_tr` is a little faster (benchmark `kernels`: 1.06×
/// at 32 × 32) and is used; at robot sizes the dot products here are
/// 1.6–1.8× faster.
pub fn gemv_t(y: &mut DVector<f64>, alpha: f64, a: &DMatrix<f64>, x: &DVector<f64>, beta: f64) {
    if a.len() >= GEMV_T_NALGEBRA_MIN_ENTRIES {
        y.gemv_tr(alpha, a, x, beta);
        return;
    }
    gemv_t_slices(y.as_mut_slice(), alpha, a, x.as_slice(), beta);
}

/// The size of `a` (entries) from which [`gemv_t`] is nalgebra's.
pub const GEMV_T_NALGEBRA_MIN_ENTRIES: usize = 1024;

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
}
