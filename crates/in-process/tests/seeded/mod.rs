//! The sweeps' seeded generator (xorshift64*): the same goals on every run.

use nalgebra::Vector3;

/// A small deterministic generator, uniform in [0, 1).
pub struct Rng(pub u64);

impl Rng {
    pub fn next(&mut self) -> f64 {
        self.0 ^= self.0 >> 12;
        self.0 ^= self.0 << 25;
        self.0 ^= self.0 >> 27;
        (self.0.wrapping_mul(0x2545_f491_4f6c_dd1d) >> 11) as f64 / (1u64 << 53) as f64
    }

    pub fn range(&mut self, lo: f64, hi: f64) -> f64 {
        lo + (hi - lo) * self.next()
    }

    /// A unit vector, uniform on the sphere.
    #[allow(dead_code)] // used by one of the sweeps only
    pub fn direction(&mut self) -> Vector3<f64> {
        let z = self.range(-1.0, 1.0);
        let phi = self.range(-std::f64::consts::PI, std::f64::consts::PI);
        let r = (1.0 - z * z).sqrt();
        Vector3::new(r * phi.cos(), r * phi.sin(), z)
    }
}

/// The p-quantile (nearest rank) of `sorted` (ascending, not empty).
#[allow(dead_code)] // used by some of the sweeps only
pub fn quantile(sorted: &[f64], p: f64) -> f64 {
    sorted[((p * (sorted.len() as f64 - 1.0)).round() as usize).min(sorted.len() - 1)]
}
