//! The minimum-jerk (quintic) profile s(σ) = 10σ³ − 15σ⁴ + 6σ⁵ of a
//! transition and its clock σ = t / T.

/// The minimum-jerk profile at σ (clamped to [0, 1]): (s, ds/dσ, d²s/dσ²).
#[inline]
pub fn quintic(sigma: f64) -> (f64, f64, f64) {
    let x = sigma.clamp(0.0, 1.0);
    let x2 = x * x;
    let s = x2 * x * (10.0 + x * (-15.0 + 6.0 * x));
    let ds = 30.0 * x2 * (1.0 - x) * (1.0 - x);
    let dds = 60.0 * x * (1.0 - x) * (1.0 - 2.0 * x);
    (s, ds, dds)
}

/// σ = t / T clamped to [0, 1]; 1 for T = 0.
pub(super) fn sigma(elapsed: f64, duration: f64) -> f64 {
    if duration > 0.0 {
        (elapsed / duration).clamp(0.0, 1.0)
    } else {
        1.0
    }
}
