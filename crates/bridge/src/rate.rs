//! Rates: the decimation of a stream to the bridge's `--rate`, and the cap
//! on remote setpoints.

/// Passes every k-th sample of a stream by its sequence number (+1 per
/// control cycle in every stream of the contract), k = the control rate
/// over the bridge's rate, rounded ([`Decimator::every`]): exact whatever
/// the jitter of the stamps or of the bridge's own scheduling. A 1 kHz
/// stream decimated to 100 Hz passes every tenth sample, to 1 kHz every
/// sample. A sample lost before the bridge read it moves the next one
/// passed to the first sample after it; a repeated sequence number does
/// not pass; one that goes backwards (a restarted source) passes and starts again.
#[derive(Debug, Clone)]
pub struct Decimator {
    every: u64,
    /// (last sequence number seen, next one due).
    state: Option<(u64, u64)>,
}

impl Decimator {
    /// A decimator of a `source_hz` stream to `rate_hz` (both > 0).
    pub fn new(source_hz: f64, rate_hz: f64) -> Decimator {
        Decimator {
            every: Self::every(source_hz, rate_hz),
            state: None,
        }
    }

    /// k: every k-th sample passes (at least 1).
    pub fn every(source_hz: f64, rate_hz: f64) -> u64 {
        (source_hz / rate_hz).round().max(1.0) as u64
    }

    /// Whether the sample numbered `seq` passes.
    pub fn pass(&mut self, seq: u64) -> bool {
        let (pass, next) = match self.state {
            Some((last, due)) if seq == last => (false, due),
            Some((last, due)) if seq > last => {
                if seq < due {
                    (false, due)
                } else {
                    (true, seq + self.every)
                }
            }
            // The first sample, or a source that started again.
            _ => (true, seq + self.every),
        };
        self.state = Some((seq, next));
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

    fn passed(rate: f64, seqs: impl Iterator<Item = u64>) -> Vec<u64> {
        let mut d = Decimator::new(1000.0, rate);
        seqs.filter(|&s| d.pass(s)).collect()
    }

    #[test]
    fn a_1khz_stream_decimated_to_100hz_passes_every_tenth() {
        let out = passed(100.0, 5..1005);
        assert_eq!(out.len(), 100);
        assert!(out.windows(2).all(|w| w[1] - w[0] == 10));
        assert_eq!(Decimator::every(1000.0, 300.0), 3);
        assert_eq!(Decimator::every(1000.0, 5000.0), 1);
    }

    #[test]
    fn lost_samples_shift_the_next_one() {
        // Samples 12..=17 lost in the queue: 20 is due, 21 comes first.
        let seqs = (0..12).chain(21..45);
        assert_eq!(passed(100.0, seqs), [0, 10, 21, 31, 41]);
    }

    #[test]
    fn at_the_source_rate_everything_passes() {
        assert_eq!(passed(1000.0, 0..500).len(), 500);
    }

    #[test]
    fn a_restarted_source_passes_at_once() {
        let mut d = Decimator::new(1000.0, 100.0);
        assert!(d.pass(100));
        assert!(!d.pass(101));
        assert!(d.pass(3), "backwards: a new source");
        assert!(!d.pass(4));
        assert!(d.pass(13));
        assert!(!d.pass(13), "a duplicate is not due");
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
