//! The gain checks a setpoint needs the law's linear algebra for: a full K
//! or D positive definite, and every eigenvalue of K at most the level's
//! `max_stiffness` (after [`Setpoint::validate`] checked the shape: a diagonal
//! positive, a full matrix symmetric). Both by a Cholesky factorisation
//! (`hcc_linalg::cholesky_in_place_slice`) in a stack buffer: allocation-free.

use hcc_msgs::{
    MAX_GAIN_ENTRIES, SETPOINT_DAMPING, SETPOINT_STIFFNESS, Setpoint, SetpointRejection,
};

/// A full K and D that the setpoint sets are positive definite
/// ([`SetpointRejection::NotPositiveDefinite`] otherwise; a diagonal one was checked
/// by [`Setpoint::validate`]).
pub(super) fn check_positive_definite(sp: &Setpoint) -> Result<(), SetpointRejection> {
    let m = sp.dim();
    let gains = [
        (SETPOINT_STIFFNESS, sp.stiffness_full(), sp.stiffness()),
        (SETPOINT_DAMPING, sp.damping_full(), sp.damping()),
    ];
    for (bit, full, values) in gains {
        if sp.sets(bit) && full && !positive_definite(|j, k| values[j * m + k], m) {
            return Err(SetpointRejection::NotPositiveDefinite);
        }
    }
    Ok(())
}

/// Whether every eigenvalue of the (valid, symmetric, positive definite) K
/// sent is at most `limit`: limit·I − K is positive semi-definite, tested as
/// (1 + 10⁻¹²)·limit·I − K positive definite.
pub(super) fn stiffness_within(sp: &Setpoint, limit: f64) -> bool {
    let m = sp.dim();
    if !sp.stiffness_full() {
        return sp.stiffness().iter().all(|&k| k <= limit);
    }
    let top = limit * (1.0 + 1e-12);
    positive_definite(
        |j, k| {
            let d = if j == k { top } else { 0.0 };
            d - sp.stiffness_at(j, k)
        },
        m,
    )
}

/// Whether the symmetric m×m matrix with lower-triangle entries `a(j, k)`
/// (j ≥ k) is positive definite: its Cholesky factorisation A = L Lᵀ finds
/// every pivot > 0 and finite (an overflow to NaN is not).
fn positive_definite(a: impl Fn(usize, usize) -> f64, m: usize) -> bool {
    let mut l = [0.0_f64; MAX_GAIN_ENTRIES];
    // Column-major, lower triangle (the factorisation reads only that).
    for k in 0..m {
        for j in k..m {
            l[k * m + j] = a(j, k);
        }
    }
    hcc_linalg::cholesky_in_place_slice(&mut l[..m * m], m).is_ok()
}

#[cfg(test)]
mod tests {
    use super::*;
    use hcc_msgs::MAX_TASK_DIM;

    /// A setpoint of the m×m row-major K `a` (the message's own builder).
    fn full_stiffness(m: usize, a: &[f64]) -> Setpoint {
        Setpoint::for_level(1, 1, 0, m).with_stiffness(a).unwrap()
    }

    #[test]
    fn the_stiffness_limit_is_on_the_largest_eigenvalue() {
        // [[4, 1], [1, 3]]: eigenvalues (7 ± √5) / 2 = 4.618…, 2.38…
        let s = full_stiffness(2, &[4.0, 1.0, 1.0, 3.0]);
        let top = (7.0 + 5.0_f64.sqrt()) / 2.0;
        assert!(stiffness_within(&s, top));
        assert!(stiffness_within(&s, 4.7));
        assert!(!stiffness_within(&s, 4.6));
        let d = Setpoint::for_level(1, 1, 0, 2)
            .with_stiffness(&[100.0, 300.0])
            .unwrap();
        assert!(stiffness_within(&d, 300.0) && !stiffness_within(&d, 299.0));
    }

    #[test]
    fn full_gains_must_be_positive_definite() {
        let s = full_stiffness(2, &[4.0, 1.0, 1.0, 3.0]);
        assert_eq!(check_positive_definite(&s), Ok(()));
        // Symmetric, indefinite (eigenvalues 3 and -1).
        let s = full_stiffness(2, &[1.0, 2.0, 2.0, 1.0]);
        assert_eq!(s.validate(), Ok(()));
        assert_eq!(
            check_positive_definite(&s),
            Err(SetpointRejection::NotPositiveDefinite)
        );
        // Positive semi-definite is rejected too.
        let s = full_stiffness(2, &[1.0, 1.0, 1.0, 1.0]);
        assert_eq!(
            check_positive_definite(&s),
            Err(SetpointRejection::NotPositiveDefinite)
        );
        // Huge values overflow to NaN in the factorisation: rejected, no panic.
        let s = full_stiffness(2, &[1e308, 1e308, 1e308, 1e308]);
        assert_eq!(
            check_positive_definite(&s),
            Err(SetpointRejection::NotPositiveDefinite)
        );
        // The largest: a 32×32 SPD matrix (diagonally dominant).
        let m = MAX_TASK_DIM;
        let mut a = [0.0; MAX_GAIN_ENTRIES];
        for j in 0..m {
            for k in 0..m {
                a[j * m + k] = if j == k { 2.0 * m as f64 } else { 1.0 };
            }
        }
        let s = full_stiffness(m, &a);
        assert_eq!(check_positive_definite(&s), Ok(()));
        // The same for damping, with an indefinite damping matrix.
        a[0] = -1.0;
        let s = Setpoint::for_level(1, 1, 0, m).with_damping(&a).unwrap();
        assert_eq!(s.validate(), Ok(()));
        assert_eq!(
            check_positive_definite(&s),
            Err(SetpointRejection::NotPositiveDefinite)
        );
    }
}
