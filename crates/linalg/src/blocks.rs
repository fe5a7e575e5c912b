//! Block copies and column views of column-major matrices, allocation-free:
//! the control law assembles its stacked and per-level blocks (eqs. 6, 8, 18
//! of Dietrich, Ott & Albu-Schäffer, IROS 2013) with them.

use nalgebra::DMatrix;

/// Column `i` of `x` as a slice (column-major storage).
#[inline]
pub fn column(x: &DMatrix<f64>, i: usize) -> &[f64] {
    let n = x.nrows();
    &x.as_slice()[i * n..(i + 1) * n]
}

/// `dst[dr.., dc..] = src[sr..sr + rows, sc..sc + cols]`, column by column.
/// Panics if a block does not fit its matrix (sizes fixed at construction).
#[allow(clippy::too_many_arguments)]
#[inline]
pub fn copy_block(
    dst: &mut DMatrix<f64>,
    dr: usize,
    dc: usize,
    src: &DMatrix<f64>,
    sr: usize,
    sc: usize,
    rows: usize,
    cols: usize,
) {
    let (dm, sm) = (dst.nrows(), src.nrows());
    assert!(dr + rows <= dm && sr + rows <= sm);
    assert!(dc + cols <= dst.ncols() && sc + cols <= src.ncols());
    let (d, s) = (dst.as_mut_slice(), src.as_slice());
    let (to, from) = ((dc * dm + dr, dm), (sc * sm + sr, sm));
    // Short columns as fixed-size moves (no call of the general copy per column).
    match rows {
        1 => copy_cols::<1>(d, s, to, from, cols),
        2 => copy_cols::<2>(d, s, to, from, cols),
        3 => copy_cols::<3>(d, s, to, from, cols),
        4 => copy_cols::<4>(d, s, to, from, cols),
        5 => copy_cols::<5>(d, s, to, from, cols),
        6 => copy_cols::<6>(d, s, to, from, cols),
        _ => {
            for j in 0..cols {
                let o = (dc + j) * dm + dr;
                let i = (sc + j) * sm + sr;
                d[o..o + rows].copy_from_slice(&s[i..i + rows]);
            }
        }
    }
}

/// `cols` columns of `R` elements from `s` (first at `si`, columns `ss` apart) to `d`
/// (first at `di`, columns `ds` apart).
#[inline(always)]
fn copy_cols<const R: usize>(
    d: &mut [f64],
    s: &[f64],
    (di, ds): (usize, usize),
    (si, ss): (usize, usize),
    cols: usize,
) {
    for j in 0..cols {
        let (o, i) = (di + j * ds, si + j * ss);
        let x: [f64; R] = s[i..i + R].try_into().expect("R elements");
        d[o..o + R].copy_from_slice(&x);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn numbered(r: usize, c: usize) -> DMatrix<f64> {
        DMatrix::from_fn(r, c, |i, j| (10 * i + j) as f64 + 0.5)
    }

    #[test]
    fn column_is_the_matrix_column() {
        let x = numbered(4, 3);
        for i in 0..3 {
            assert_eq!(column(&x, i), x.column(i).as_slice());
        }
    }

    #[test]
    fn copy_block_equals_a_view_copy_at_every_height() {
        // Every fixed-size arm (1..=6 rows) and the general one (7, 9).
        for rows in 1..=9 {
            let src = numbered(rows + 3, 5);
            let mut dst = DMatrix::from_element(rows + 4, 6, -1.0);
            let mut want = dst.clone();
            want.view_mut((2, 1), (rows, 4))
                .copy_from(&src.view((1, 1), (rows, 4)));
            copy_block(&mut dst, 2, 1, &src, 1, 1, rows, 4);
            assert_eq!(dst, want, "rows {rows}");
        }
    }

    #[test]
    fn an_empty_block_copies_nothing() {
        let src = numbered(3, 3);
        let mut dst = DMatrix::from_element(3, 3, 7.0);
        copy_block(&mut dst, 0, 0, &src, 0, 0, 0, 3);
        copy_block(&mut dst, 0, 0, &src, 0, 0, 3, 0);
        assert_eq!(dst, DMatrix::from_element(3, 3, 7.0));
    }

    #[test]
    #[should_panic]
    fn a_block_beyond_the_matrix_panics() {
        let src = numbered(3, 3);
        let mut dst = DMatrix::zeros(3, 3);
        copy_block(&mut dst, 1, 0, &src, 0, 0, 3, 3);
    }
}
