//! The symmetric eigenproblem by the cyclic Jacobi method (Golub & Van Loan,
//! "Matrix Computations", Sec. 8.5): in place, allocation-free, for the small
//! Gram matrices of the law (their conditioning, the stiffness limit).

use nalgebra::{DMatrix, DVector};

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
