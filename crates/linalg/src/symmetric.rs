//! Sums of a matrix and a transpose, in place and allocation-free: Ṁ = C + Cᵀ
//! (Sec. II of Dietrich, Ott & Albu-Schäffer, IROS 2013) and the symmetric
//! derivatives Λ̇_i and d/dt (VᵀMV) of the control law. The symmetric results are
//! exactly symmetric: (Aᵀ + A)_ij = a_ji + a_ij is formed once and mirrored, the
//! same sum to the bit as its mirror a_ij + a_ji.

use nalgebra::DMatrix;

/// `out = cᵀ + c` (square), one pass over the upper triangle, mirrored.
#[inline]
pub fn sym_sum_transpose(out: &mut DMatrix<f64>, c: &DMatrix<f64>) {
    let n = c.nrows();
    assert_eq!(c.shape(), (n, n));
    assert_eq!(out.shape(), (n, n));
    let (o, c) = (out.as_mut_slice(), c.as_slice());
    for j in 0..n {
        for i in 0..=j {
            let x = c[i * n + j] + c[j * n + i];
            o[j * n + i] = x;
            o[i * n + j] = x;
        }
    }
}

/// `x = x + xᵀ` (square; exactly symmetric).
#[inline]
pub fn add_own_transpose(x: &mut DMatrix<f64>) {
    let n = x.nrows();
    assert_eq!(x.ncols(), n);
    let x = x.as_mut_slice();
    for j in 0..n {
        for i in 0..=j {
            let s = x[i * n + j] + x[j * n + i];
            x[j * n + i] = s;
            x[i * n + j] = s;
        }
    }
}

/// `out += aᵀ` (`out` is cols(a) × rows(a)).
#[inline]
pub fn transpose_add(out: &mut DMatrix<f64>, a: &DMatrix<f64>) {
    let (r, c) = a.shape();
    assert_eq!(out.shape(), (c, r));
    if r == 0 || c == 0 {
        return;
    }
    let a = a.as_slice();
    for (i, col) in out.as_mut_slice().chunks_exact_mut(c).enumerate() {
        for (o, x) in col.iter_mut().zip(a[i..].iter().step_by(r)) {
            *o += *x;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn irregular(r: usize, c: usize) -> DMatrix<f64> {
        DMatrix::from_fn(r, c, |i, j| ((3 * i + 7 * j) as f64 * 0.37).sin() * 1e3)
    }

    fn exactly_symmetric(x: &DMatrix<f64>) -> bool {
        (0..x.nrows()).all(|i| (0..i).all(|j| x[(i, j)].to_bits() == x[(j, i)].to_bits()))
    }

    #[test]
    fn sym_sum_transpose_is_c_plus_ct_and_exactly_symmetric() {
        for n in [0, 1, 2, 7] {
            let c = irregular(n, n);
            let mut out = DMatrix::from_element(n, n, f64::NAN);
            sym_sum_transpose(&mut out, &c);
            // Each entry is one sum of the same two numbers as nalgebra's.
            assert_eq!(out, c.transpose() + &c, "n {n}");
            assert!(exactly_symmetric(&out));
        }
    }

    #[test]
    fn add_own_transpose_is_x_plus_xt_and_exactly_symmetric() {
        for n in [0, 1, 3, 7] {
            let x0 = irregular(n, n);
            let mut x = x0.clone();
            add_own_transpose(&mut x);
            assert_eq!(x, x0.transpose() + &x0, "n {n}");
            assert!(exactly_symmetric(&x));
        }
    }

    #[test]
    fn transpose_add_adds_the_transpose() {
        for (r, c) in [(0, 3), (3, 0), (1, 1), (2, 5), (7, 3)] {
            let a = irregular(r, c);
            let base = irregular(c, r).map(|x| x * 0.5);
            let mut out = base.clone();
            transpose_add(&mut out, &a);
            assert_eq!(out, &base + a.transpose(), "{r} × {c}");
        }
    }

    #[test]
    #[should_panic]
    fn transpose_add_refuses_a_wrong_shape() {
        let mut out = DMatrix::zeros(2, 2);
        transpose_add(&mut out, &DMatrix::zeros(2, 3));
    }
}
