//! Rates: the decimation of a stream to the bridge's `--rate`, and the cap
//! on remote setpoints.

/// Passes one sample per period of a stream, judged by the samples' own
/// stamps (so the decimated stream keeps the source's timing whatever the
/// bridge's scheduling): the first sample passes, then the first sample
/// stamped at or after each due time, the due times one period apart
/// (kept on their grid, so the source's jitter does not accumulate; a
/// sample up to [`Decimator::SLACK_NS`] early counts as on time). A 1 kHz
/// stream decimated to 100 Hz passes every tenth sample; decimated to
/// 1 kHz, every sample. After a gap longer than a period the grid restarts
/// at the next sample, and a stamp that goes backwards (a restarted
/// source) passes and restarts it too.
#[derive(Debug, Clone)]
pub struct Decimator {
    period_ns: u64,
    slack_ns: u64,
    /// (last stamp seen, next due time).
    state: Option<(u64, u64)>,
}

impl Decimator {
    /// How early a sample may be and still count as due: half a period of
    /// a 1 kHz source, so its jitter neither skips nor doubles a sample.
    pub const SLACK_NS: u64 = 500_000;

    /// A decimator to `rate_hz` (> 0).
    pub fn new(rate_hz: f64) -> Decimator {
        let period_ns = (1e9 / rate_hz) as u64;
        Decimator {
            period_ns,
            slack_ns: Self::SLACK_NS.min(period_ns / 2),
            state: None,
        }
    }

    /// Whether the sample stamped `stamp_ns` passes.
    pub fn pass(&mut self, stamp_ns: u64) -> bool {
        let (pass, next) = match self.state {
            Some((last, due)) if stamp_ns >= last => {
                if stamp_ns + self.slack_ns < due {
                    (false, due)
                } else if stamp_ns >= due + self.period_ns {
                    (true, stamp_ns + self.period_ns)
                } else {
                    (true, due + self.period_ns)
                }
            }
            // The first sample, or a source that started again.
            _ => (true, stamp_ns + self.period_ns),
        };
        self.state = Some((stamp_ns, next));
        pass
    }
}

/// A token bucket: at most `rate` events per second on average, bursts of
/// at most `burst`. The remote setpoints' cap: over it, a setpoint is
/// refused and counted, never queued.
#[derive(Debug, Clone)]
pub struct RateLimiter {
    rate_per_ns: f64,
    burst: f64,
    tokens: f64,
    last_ns: Option<u64>,
}

impl RateLimiter {
    /// A full bucket of `burst` (≥ 1) tokens refilled at `rate_hz`.
    pub fn new(rate_hz: f64, burst: u32) -> RateLimiter {
        let burst = f64::from(burst.max(1));
        RateLimiter {
            rate_per_ns: rate_hz / 1e9,
            burst,
            tokens: burst,
            last_ns: None,
        }
    }

    /// Takes a token at time `now_ns` (monotonic); false when none is left.
    pub fn allow(&mut self, now_ns: u64) -> bool {
        if let Some(last) = self.last_ns {
            let dt = now_ns.saturating_sub(last) as f64;
            self.tokens = (self.tokens + dt * self.rate_per_ns).min(self.burst);
        }
        self.last_ns = Some(now_ns.max(self.last_ns.unwrap_or(0)));
        if self.tokens >= 1.0 {
            self.tokens -= 1.0;
            true
        } else {
            false
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const MS: u64 = 1_000_000;

    fn passed(rate: f64, stamps: impl Iterator<Item = u64>) -> Vec<u64> {
        let mut d = Decimator::new(rate);
        stamps.filter(|&s| d.pass(s)).collect()
    }

    #[test]
    fn a_1khz_stream_decimated_to_100hz_passes_every_tenth() {
        let out = passed(100.0, (0..1000).map(|k| 5 * MS + k * MS));
        assert_eq!(out.len(), 100);
        assert!(out.windows(2).all(|w| w[1] - w[0] == 10 * MS));
    }

    #[test]
    fn jitter_does_not_change_the_count() {
        // ±0.3 ms of jitter on a 1 kHz stream.
        let jitter = [0i64, 300_000, -300_000, 150_000, -50_000];
        let stamps =
            (0..2000u64).map(|k| (10 * MS + k * MS).wrapping_add_signed(jitter[k as usize % 5]));
        let out = passed(100.0, stamps);
        assert!((199..=201).contains(&out.len()), "{}", out.len());
    }

    #[test]
    fn at_the_source_rate_everything_passes() {
        assert_eq!(passed(1000.0, (0..500).map(|k| k * MS)).len(), 500);
    }

    #[test]
    fn a_restarted_source_passes_at_once() {
        let mut d = Decimator::new(100.0);
        assert!(d.pass(100 * MS));
        assert!(!d.pass(101 * MS));
        assert!(d.pass(3 * MS), "backwards: a new source");
        assert!(!d.pass(4 * MS));
        assert!(d.pass(13 * MS));
    }

    #[test]
    fn the_limiter_allows_the_burst_then_the_rate() {
        let mut l = RateLimiter::new(10.0, 3);
        let t0 = 1_000 * MS;
        assert!((0..3).all(|_| l.allow(t0)));
        assert!(!l.allow(t0), "burst spent");
        assert!(!l.allow(t0 + 50 * MS), "half a token");
        assert!(l.allow(t0 + 100 * MS), "one token after 1/rate");
        // A flood of 10 000 over one second gets the burst and the rate.
        let mut l = RateLimiter::new(50.0, 5);
        let allowed = (0..10_000u64).filter(|k| l.allow(t0 + k * 100_000)).count();
        assert!((54..=56).contains(&allowed), "{allowed}");
    }

    #[test]
    fn the_limiter_survives_a_clock_going_backwards() {
        let mut l = RateLimiter::new(1.0, 1);
        assert!(l.allow(10 * MS));
        assert!(!l.allow(5 * MS));
        assert!(!l.allow(10 * MS));
    }
}
