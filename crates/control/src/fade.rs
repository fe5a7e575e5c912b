//! The fade of the lower levels near a singularity (crate docs,
//! "Singularities"): a level's torque (and τ_μ) is scaled by β of the
//! eigenvalue ratio of the inversion its projection depends on.

/// The lower levels' torques and τ_μ fade out between `FADE_RANGE × singular_ratio`
/// and `singular_ratio` of a level's eigenvalue ratio (see the crate docs, "Singularities").
pub const FADE_RANGE: f64 = hcc_linalg::spd::EXACT_RATIO_FACTOR;

/// Smoothstep on the log scale: 0 at or below `eps`, 1 at or above `FADE_RANGE × eps`.
pub(crate) fn fade_factor(ratio: f64, eps: f64) -> f64 {
    if ratio.is_nan() || ratio <= eps {
        return 0.0;
    }
    let hi = FADE_RANGE * eps;
    if ratio >= hi {
        return 1.0;
    }
    let t = (ratio / eps).ln() / FADE_RANGE.ln();
    t * t * (3.0 - 2.0 * t)
}
