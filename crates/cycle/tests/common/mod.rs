//! Helpers the cycle's integration tests share.

/// The largest change of a joint torque from one cycle to the next in
/// `tau` (one command per cycle), N·m.
pub fn largest_torque_step(tau: &[Vec<f64>]) -> f64 {
    tau.windows(2)
        .map(|w| {
            w[0].iter()
                .zip(&w[1])
                .map(|(a, b)| (a - b).abs())
                .fold(0.0, f64::max)
        })
        .fold(0.0_f64, f64::max)
}
