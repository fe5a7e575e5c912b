//! Torque limits that keep the hierarchy: the control torque is scaled, not
//! clipped joint by joint.
//!
//! Clipping each joint to its limit changes the direction of τ: the levels'
//! torques no longer add up to what the hierarchy computed, a lower level's
//! torque leaks into a higher level's task, and the clipped feedback is no
//! longer the passive one of the paper (a light arm whips around when a large
//! initial error saturates every joint). [`saturate`] instead scales the control
//! part c = τ − g (or τ, when g is not part of it) by one factor s ∈ [0, 1], the
//! largest for which every |g_k + s c_k| ≤ limit_k. All levels are scaled alike,
//! so J_i M⁻¹ τ_j = 0 (j > i) still holds, the direction of every task force is
//! kept and s · P of a dissipative feedback stays dissipative. Only a joint
//! whose gravity torque alone exceeds its limit is clipped (nothing can hold
//! the robot there).

/// Scales the control part of `tau` into the limits (see the module docs) and
/// returns whether anything changed. `gravity`: the g(q) contained in `tau`
/// (None when it contains none). Allocation-free; a non-positive or NaN limit
/// clips that joint to 0, a non-finite entry becomes g (or 0). Lengths must
/// agree (extra entries are ignored).
pub fn saturate(tau: &mut [f64], gravity: Option<&[f64]>, limits: &[f64]) -> bool {
    let g = |k: usize| gravity.map_or(0.0, |g| g[k]);
    let n = tau.len().min(limits.len());
    let mut s: f64 = 1.0;
    for k in 0..n {
        let c = tau[k] - g(k);
        let room = limits[k] - g(k).abs();
        if c.abs() > room && room > 0.0 && c.is_finite() {
            s = s.min(room / c.abs());
        }
    }
    let mut changed = false;
    for k in 0..n {
        let limit = if limits[k] > 0.0 { limits[k] } else { 0.0 };
        let c = tau[k] - g(k);
        // A non-finite control torque (never from a successful control cycle)
        // is replaced by g alone.
        let mut t = if c.is_finite() { g(k) + s * c } else { g(k) };
        // Gravity alone beyond the limit (or a bad limit): clip.
        if t > limit {
            t = limit;
        } else if t < -limit {
            t = -limit;
        }
        if t != tau[k] {
            changed = true;
            tau[k] = t;
        }
    }
    changed
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn within_limits_nothing_changes() {
        let mut tau = [1.0, -2.0, 3.0];
        assert!(!saturate(&mut tau, None, &[5.0, 5.0, 5.0]));
        assert_eq!(tau, [1.0, -2.0, 3.0]);
    }

    #[test]
    fn the_direction_of_the_control_torque_is_kept() {
        // Without gravity: τ scaled by 10/20.
        let mut tau = [20.0, -5.0, 2.0];
        assert!(saturate(&mut tau, None, &[10.0, 10.0, 10.0]));
        assert_eq!(tau, [10.0, -2.5, 1.0]);
        // With gravity: c = τ − g scaled so that the tightest joint meets its limit.
        let g = [4.0, -1.0, 0.0];
        let mut tau = [24.0, -6.0, 10.0];
        assert!(saturate(&mut tau, Some(&g), &[10.0, 10.0, 10.0]));
        // c = (20, −5, 10); room (6, 9, 10): s = 6/20 = 0.3.
        let want = [4.0 + 6.0, -1.0 - 1.5, 3.0];
        for (a, b) in tau.iter().zip(want) {
            assert!((a - b).abs() < 1e-12, "{tau:?}");
        }
        assert!(tau.iter().zip([10.0; 3]).all(|(t, l)| t.abs() <= l + 1e-12));
    }

    #[test]
    fn gravity_beyond_the_limit_is_clipped() {
        let g = [15.0, 1.0];
        let mut tau = [16.0, 3.0];
        assert!(saturate(&mut tau, Some(&g), &[10.0, 10.0]));
        assert_eq!(tau, [10.0, 3.0]);
        let mut tau = [f64::INFINITY, 1.0];
        assert!(saturate(&mut tau, None, &[10.0, 10.0]));
        assert_eq!(tau, [0.0, 1.0]);
        let mut tau = [3.0, 1.0];
        assert!(saturate(&mut tau, None, &[f64::NAN, -1.0]));
        assert_eq!(tau, [0.0, 0.0]);
        let mut tau = [3.0];
        assert!(!saturate(&mut tau, None, &[f64::INFINITY]));
    }
}
