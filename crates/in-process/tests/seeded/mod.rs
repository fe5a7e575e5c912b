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

/// `f` of every item on `threads` threads (one per core; 1: on this one),
/// the results in the items' order. Each thread takes the next item left,
/// so a slow item holds up no other.
#[allow(dead_code)] // used by the sweeps only
pub fn on_threads<T: Sync, R: Send>(
    items: &[T],
    threads: usize,
    f: impl Fn(&T) -> R + Sync,
) -> Vec<R> {
    use std::sync::atomic::{AtomicUsize, Ordering};
    let next = AtomicUsize::new(0);
    let work = || {
        let mut done = Vec::new();
        loop {
            let k = next.fetch_add(1, Ordering::Relaxed);
            let Some(item) = items.get(k) else {
                break;
            };
            done.push((k, f(item)));
        }
        done
    };
    let mut done: Vec<(usize, R)> = if threads > 1 {
        std::thread::scope(|s| {
            let handles: Vec<_> = (0..threads).map(|_| s.spawn(work)).collect();
            handles
                .into_iter()
                .flat_map(|h| h.join().expect("a sweep thread panicked"))
                .collect()
        })
    } else {
        work()
    };
    done.sort_by_key(|d| d.0);
    done.into_iter().map(|d| d.1).collect()
}
