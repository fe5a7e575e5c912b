//! Where a routine hands its work to nalgebra at some sizes (benchmark
//! `kernels`), both paths give the same results to rounding, refuse the same
//! bad input, and allocate nothing.

use hcc_linalg::products::{GEMM_TN_BLOCK_MIN_ROWS, GEMV_T_NALGEBRA_MIN_ENTRIES, gemm_tn, gemv_t};
use hcc_linalg::{LinalgError, cholesky_factor, cholesky_in_place};
use nalgebra::{DMatrix, DVector};

#[global_allocator]
static GLOBAL: hcc_rtalloc::RtAllocator = hcc_rtalloc::RtAllocator::new();

fn matrix(r: usize, c: usize, seed: usize) -> DMatrix<f64> {
    DMatrix::from_fn(r, c, |i, j| {
        (((i * 7 + j * 13 + seed * 3) % 17) as f64 - 8.0) / 9.0
    })
}

fn spd(n: usize) -> DMatrix<f64> {
    let a = matrix(n, n, 1);
    &a * a.transpose() + DMatrix::identity(n, n) * n as f64
}

#[test]
fn the_factor_is_the_textbook_one_at_every_size() {
    for n in 1..=34 {
        let a = spd(n);
        let mut textbook = a.clone();
        cholesky_in_place(&mut textbook).unwrap();
        let mut l = a.clone();
        cholesky_factor(&mut l).unwrap();
        let scale = a.amax();
        assert!((&l - &textbook).amax() <= 1e-13 * scale, "n = {n}");
        assert!((&l * l.transpose() - &a).amax() <= 1e-12 * scale, "n = {n}");
        assert_eq!(
            l.upper_triangle() - DMatrix::from_diagonal(&l.diagonal()),
            DMatrix::zeros(n, n)
        );
    }
}

#[test]
fn both_factorisations_refuse_a_matrix_that_is_not_positive_definite() {
    for n in [3, 7, 12, 32] {
        let mut a = spd(n);
        a[(n - 1, n - 1)] = -1.0;
        let e = cholesky_factor(&mut a).unwrap_err();
        assert!(
            matches!(e, LinalgError::NotPositiveDefinite { index, .. } if index == n - 1),
            "n = {n}: {e:?}"
        );
        let mut nan = spd(n);
        nan[(1, 1)] = f64::NAN;
        assert!(cholesky_factor(&mut nan).is_err(), "n = {n}");
    }
    assert!(cholesky_factor(&mut DMatrix::zeros(3, 4)).is_err());
}

#[test]
fn gemm_tn_and_gemv_t_agree_with_the_plain_products_on_both_sides_of_the_switch() {
    for m in [
        1,
        2,
        GEMM_TN_BLOCK_MIN_ROWS - 1,
        GEMM_TN_BLOCK_MIN_ROWS,
        6,
        9,
    ] {
        let (a, b) = (matrix(7, m, 2), matrix(7, 5, 3));
        let mut c = matrix(m, 5, 4);
        let want = a.transpose() * &b * 2.0 + &c * 0.5;
        gemm_tn(&mut c, 2.0, &a, &b, 0.5);
        assert!((c - want).amax() < 1e-13, "m = {m}");
    }
    let side = (GEMV_T_NALGEBRA_MIN_ENTRIES as f64).sqrt() as usize;
    for n in [7, side - 1, side, side + 3] {
        let a = matrix(n, n, 5);
        let x = DVector::from_fn(n, |i, _| i as f64 * 0.1 - 1.0);
        let mut y = DVector::from_element(n, 1.0);
        let want = a.transpose() * &x * 3.0 - &y;
        gemv_t(&mut y, 3.0, &a, &x, -1.0);
        assert!((y - want).amax() < 1e-12, "n = {n}");
    }
}

#[test]
fn the_switched_routines_allocate_nothing() {
    let mut l = spd(7);
    let a = l.clone();
    let (at, b) = (matrix(7, 2, 2), matrix(7, 2, 3));
    let mut c = DMatrix::zeros(2, 2);
    let big = matrix(40, 40, 6);
    let x = DVector::from_element(40, 0.5);
    let mut y = DVector::zeros(40);
    let before = hcc_rtalloc::thread_stats();
    for _ in 0..100 {
        l.copy_from(&a);
        cholesky_factor(&mut l).unwrap();
        gemm_tn(&mut c, 1.0, &at, &b, 0.0);
        gemv_t(&mut y, 1.0, &big, &x, 0.0);
    }
    let during = hcc_rtalloc::thread_stats().since(before);
    assert_eq!(during.allocs, 0, "{during:?}");
}
