//! The hand-written kernels of hcc-linalg against nalgebra's own in-place
//! routines, at the sizes of a robot controller: the Panda (n = 7, task
//! dimensions 1, 3, 6, 7), the planar arm of the paper (n = 4) and a 32-joint
//! chain. Each pair is timed in the same run, in alternating rounds (the
//! machine's drift hits both alike); printed: the median time per call of
//! each and their ratio (hcc / nalgebra: below 1, the hand-written kernel is
//! faster). Where nalgebra has no in-place routine (A Bᵀ, the Jacobi
//! eigen-solver, the damped SPD inverse), there is nothing to compare.
//!
//! `cargo bench -p hcc-linalg --bench kernels` (release build).

use std::hint::black_box;
use std::time::Instant;

use hcc_linalg::cholesky::{cholesky_in_place_slice, cholesky_solve_slice};
use hcc_linalg::products::{gemm, gemm_tn, gemv, gemv_t};
use nalgebra::{Cholesky, DMatrix, DVector};

/// Rounds per kernel (each round times one batch of each side).
const ROUNDS: usize = 41;
/// Calls per batch.
const BATCH: usize = 2_000;

/// A deterministic matrix of entries in [-1, 1).
fn matrix(r: usize, c: usize, seed: u64) -> DMatrix<f64> {
    let mut s = seed
        .wrapping_mul(6364136223846793005)
        .wrapping_add(1442695040888963407);
    DMatrix::from_fn(r, c, |_, _| {
        s = s
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        ((s >> 11) as f64 / (1u64 << 53) as f64) * 2.0 - 1.0
    })
}

/// A symmetric positive definite n × n matrix.
fn spd(n: usize) -> DMatrix<f64> {
    let a = matrix(n, n, 7);
    &a * a.transpose() + DMatrix::identity(n, n) * n as f64
}

/// ns per call of one batch of `f`.
fn batch(f: &mut dyn FnMut()) -> f64 {
    let start = Instant::now();
    for _ in 0..BATCH {
        f();
    }
    start.elapsed().as_nanos() as f64 / BATCH as f64
}

fn median(mut v: Vec<f64>) -> f64 {
    v.sort_by(f64::total_cmp);
    v[v.len() / 2]
}

/// Times `ours` and `theirs` in alternating rounds; prints a row.
fn compare(what: &str, ours: &mut dyn FnMut(), theirs: &mut dyn FnMut()) {
    let (mut a, mut b) = (Vec::new(), Vec::new());
    for r in 0..ROUNDS {
        // Alternate which side goes first.
        if r % 2 == 0 {
            a.push(batch(ours));
            b.push(batch(theirs));
        } else {
            b.push(batch(theirs));
            a.push(batch(ours));
        }
    }
    let (a, b) = (median(a), median(b));
    println!("{what:<34} {a:>10.1} {b:>10.1} {:>8.2}", a / b);
}

fn products() {
    // (m, k, n) of c = a b (m × k times k × n): the Panda's J M⁻¹ Jᵀ, Z M,
    // V-blocks …, the planar arm's, and a 32-joint chain's.
    for (m, k, n) in [
        (4, 4, 4),
        (7, 7, 7),
        (6, 7, 7),
        (7, 7, 6),
        (6, 7, 6),
        (1, 7, 7),
        (12, 12, 12),
        (16, 16, 16),
        (6, 32, 32),
        (32, 32, 6),
        (32, 32, 32),
    ] {
        let (a, b) = (matrix(m, k, 1), matrix(k, n, 2));
        let mut c = DMatrix::zeros(m, n);
        let mut d = DMatrix::zeros(m, n);
        compare(
            &format!("gemm   {m}x{k} * {k}x{n}"),
            &mut || gemm(black_box(&mut c), 1.0, black_box(&a), black_box(&b), 0.0),
            &mut || black_box(&mut d).gemm(1.0, black_box(&a), black_box(&b), 0.0),
        );
    }
    // c = aᵀ b (m × n) with a k × m, b k × n: Gram matrices and the basis
    // alignment (m = n = the null space's dimension).
    for (m, k, n) in [
        (1, 7, 1),
        (2, 7, 2),
        (3, 7, 3),
        (1, 7, 7),
        (4, 4, 4),
        (6, 7, 6),
        (7, 7, 7),
        (26, 32, 26),
        (32, 32, 32),
    ] {
        let (at, b) = (matrix(k, m, 3), matrix(k, n, 2));
        let mut c = DMatrix::zeros(m, n);
        let mut d = DMatrix::zeros(m, n);
        compare(
            &format!("gemm_tn {k}x{m}' * {k}x{n}"),
            &mut || gemm_tn(black_box(&mut c), 1.0, black_box(&at), black_box(&b), 0.0),
            &mut || black_box(&mut d).gemm_tr(1.0, black_box(&at), black_box(&b), 0.0),
        );
    }
    for (m, n) in [(7, 7), (6, 7), (7, 6), (32, 32)] {
        let a = matrix(m, n, 4);
        let (x, xt) = (DVector::from_element(n, 0.3), DVector::from_element(m, 0.3));
        let (mut y, mut z) = (DVector::zeros(m), DVector::zeros(m));
        compare(
            &format!("gemv   {m}x{n}"),
            &mut || gemv(black_box(&mut y), 1.0, black_box(&a), black_box(&x), 0.0),
            &mut || black_box(&mut z).gemv(1.0, black_box(&a), black_box(&x), 0.0),
        );
        let (mut y, mut z) = (DVector::zeros(n), DVector::zeros(n));
        compare(
            &format!("gemv_t {m}x{n}"),
            &mut || gemv_t(black_box(&mut y), 1.0, black_box(&a), black_box(&xt), 0.0),
            &mut || black_box(&mut z).gemv_tr(1.0, black_box(&a), black_box(&xt), 0.0),
        );
    }
}

fn cholesky() {
    for n in [3, 4, 5, 6, 7, 8, 12, 16, 32] {
        let a = spd(n);
        let mut l = a.clone();
        // nalgebra's factorisation works in place on the matrix it is given:
        // the buffer goes in and comes back (a move, no allocation).
        let mut buf = Some(a.clone());
        compare(
            &format!("cholesky {n}x{n}"),
            &mut || {
                l.copy_from(&a);
                let _ = cholesky_in_place_slice(black_box(l.as_mut_slice()), n);
            },
            &mut || {
                let mut m = buf.take().unwrap_or_default();
                m.copy_from(&a);
                let chol = Cholesky::new_unchecked(black_box(m));
                buf = Some(chol.unpack_dirty());
            },
        );
        let mut l = a.clone();
        cholesky_in_place_slice(l.as_mut_slice(), n).unwrap();
        let chol = Cholesky::new(a.clone()).unwrap();
        let rhs = matrix(n, n, 9);
        let (mut x, mut y) = (rhs.clone(), rhs.clone());
        compare(
            &format!("cholesky solve {n}x{n}, {n} rhs"),
            &mut || {
                x.copy_from(&rhs);
                let _ = cholesky_solve_slice(l.as_slice(), n, black_box(x.as_mut_slice()));
            },
            &mut || {
                y.copy_from(&rhs);
                chol.solve_mut(black_box(&mut y));
            },
        );
    }
}

fn main() {
    println!(
        "{:<34} {:>10} {:>10} {:>8}",
        "kernel [ns per call]", "hcc", "nalgebra", "ratio"
    );
    products();
    cholesky();
}
