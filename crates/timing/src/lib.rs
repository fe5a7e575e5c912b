//! Latency figures of the real-time loops.
//!
//! - [`LatencyHistogram`]: an HDR histogram (the hdrhistogram crate) of
//!   durations in nanoseconds with fixed bounds, 1 ns to 60 s at three
//!   significant digits. It never resizes, so [`LatencyHistogram::record`]
//!   never allocates, and its counts are written once at construction so that
//!   recording takes no page fault either: safe inside a 1 kHz loop.
//! - [`LatencySummary`] and [`QuantilePoint`]: what a histogram says (min,
//!   p50 … p99.99, max) and its quantile curve, for tables, JSON and plots.
//! - [`DaemonTimings`]: the timing report a daemon writes when it stops
//!   (`--stats FILE`), read back by `hcc jitter`.
//! - [`machine`]: facts about the machine that a timing report must carry
//!   (kernel, CPU model, real-time throttling, steal time, the
//!   `/dev/cpu_dma_latency` request).

use std::collections::BTreeMap;
use std::path::Path;

use hdrhistogram::Histogram;
use serde::{Deserialize, Serialize};

pub mod machine;

/// Errors of reading or writing a timing report.
#[derive(Debug, thiserror::Error)]
pub enum TimingError {
    /// The file could not be read or written.
    #[error("{path}: {source}")]
    Io {
        path: String,
        #[source]
        source: std::io::Error,
    },
    /// The file is not a timing report.
    #[error("{path}: not a timing report: {source}")]
    Format {
        path: String,
        #[source]
        source: serde_json::Error,
    },
}

/// Durations in nanoseconds, 1 ns … 60 s at three significant digits (a value
/// is known to 0.1 %), fixed bounds. Values above the range are recorded as
/// the highest trackable value and counted in [`LatencySummary::saturated`];
/// negative durations (a clock read on another core that came out a little
/// earlier) are recorded as 0 and counted in [`LatencySummary::negative`].
#[derive(Clone, Debug)]
pub struct LatencyHistogram {
    histogram: Histogram<u64>,
    saturated: u64,
    negative: u64,
}

impl Default for LatencyHistogram {
    fn default() -> Self {
        Self::new()
    }
}

impl LatencyHistogram {
    /// Highest trackable value, ns.
    pub const HIGHEST_NS: u64 = 60_000_000_000;
    /// Significant decimal digits.
    pub const SIGNIFICANT_DIGITS: u8 = 3;

    /// An empty histogram; allocates its counts (about 200 KiB) and writes
    /// every page of them once.
    pub fn new() -> LatencyHistogram {
        let mut histogram =
            Histogram::<u64>::new_with_bounds(1, Self::HIGHEST_NS, Self::SIGNIFICANT_DIGITS)
                .expect("constant, valid bounds");
        histogram.auto(false);
        // Writes every count: the pages are faulted in here, not in the loop.
        histogram.reset();
        LatencyHistogram {
            histogram,
            saturated: 0,
            negative: 0,
        }
    }

    /// Records one duration. Allocation-free, no system call.
    #[inline]
    pub fn record(&mut self, ns: u64) {
        if ns > Self::HIGHEST_NS {
            self.saturated += 1;
        }
        self.histogram.saturating_record(ns);
    }

    /// Records a difference of two clock readings that may come out negative.
    #[inline]
    pub fn record_signed(&mut self, ns: i64) {
        if ns < 0 {
            self.negative += 1;
        }
        self.record(ns.max(0) as u64);
    }

    /// Number of recorded values.
    pub fn count(&self) -> u64 {
        self.histogram.len()
    }

    /// Forgets every value (keeps the memory).
    pub fn clear(&mut self) {
        self.histogram.reset();
        self.saturated = 0;
        self.negative = 0;
    }

    /// Adds every value of `other`.
    pub fn merge(&mut self, other: &LatencyHistogram) {
        // Same bounds on both sides: addition cannot fail.
        let _ = self.histogram.add(&other.histogram);
        self.saturated += other.saturated;
        self.negative += other.negative;
    }

    /// Count of values strictly above `ns`.
    pub fn count_above(&self, ns: u64) -> u64 {
        let at_or_below = self.histogram.count_between(0, ns);
        self.histogram.len().saturating_sub(at_or_below)
    }

    /// Value at quantile `q` (0…1), ns; 0 when empty.
    pub fn value_at_quantile(&self, q: f64) -> u64 {
        if self.histogram.is_empty() {
            return 0;
        }
        self.histogram.value_at_quantile(q)
    }

    /// The summary figures.
    pub fn summary(&self) -> LatencySummary {
        let h = &self.histogram;
        if h.is_empty() {
            return LatencySummary::default();
        }
        let q = |q: f64| h.value_at_quantile(q);
        LatencySummary {
            count: h.len(),
            min_ns: h.min(),
            p50_ns: q(0.50),
            p90_ns: q(0.90),
            p99_ns: q(0.99),
            p999_ns: q(0.999),
            p9999_ns: q(0.9999),
            max_ns: h.max(),
            mean_ns: h.mean(),
            saturated: self.saturated,
            negative: self.negative,
        }
    }

    /// The quantile curve: the value reached at percentiles spaced evenly on
    /// the 1 / (1 − p) scale (HdrHistogram's percentile distribution, five
    /// points per halving of the remaining fraction), ending at the maximum.
    pub fn curve(&self) -> Vec<QuantilePoint> {
        let h = &self.histogram;
        if h.is_empty() {
            return Vec::new();
        }
        let mut points: Vec<QuantilePoint> = h
            .iter_quantiles(5)
            .map(|v| QuantilePoint {
                percentile: v.quantile_iterated_to() * 100.0,
                value_ns: h.highest_equivalent(v.value_iterated_to()).min(h.max()),
            })
            .collect();
        points.dedup_by(|b, a| a.percentile == b.percentile);
        points
    }
}

/// Figures of one latency distribution, ns (0 when there is no sample).
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct LatencySummary {
    /// Number of samples.
    pub count: u64,
    pub min_ns: u64,
    pub p50_ns: u64,
    pub p90_ns: u64,
    pub p99_ns: u64,
    pub p999_ns: u64,
    pub p9999_ns: u64,
    pub max_ns: u64,
    pub mean_ns: f64,
    /// Samples above the histogram's range (recorded as its highest value).
    pub saturated: u64,
    /// Negative differences (recorded as 0).
    pub negative: u64,
}

impl LatencySummary {
    /// Labels of [`LatencySummary::values_ns`].
    pub const LABELS: [&'static str; 7] = ["min", "p50", "p90", "p99", "p99.9", "p99.99", "max"];

    /// min, p50, p90, p99, p99.9, p99.99, max, ns.
    pub fn values_ns(&self) -> [u64; 7] {
        [
            self.min_ns,
            self.p50_ns,
            self.p90_ns,
            self.p99_ns,
            self.p999_ns,
            self.p9999_ns,
            self.max_ns,
        ]
    }

    /// One line in µs: `p50 17.2 µs, p99 …, p99.9 …, max … (N samples)`.
    pub fn line_us(&self) -> String {
        if self.count == 0 {
            return "no samples".into();
        }
        format!(
            "p50 {:.1} µs, p99 {:.1} µs, p99.9 {:.1} µs, max {:.1} µs ({} samples)",
            self.p50_ns as f64 * 1e-3,
            self.p99_ns as f64 * 1e-3,
            self.p999_ns as f64 * 1e-3,
            self.max_ns as f64 * 1e-3,
            self.count
        )
    }
}

/// One point of a quantile curve.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct QuantilePoint {
    /// Percentile, 0…100.
    pub percentile: f64,
    /// Largest value at or below that percentile, ns.
    pub value_ns: u64,
}

/// A named latency distribution: its summary and its quantile curve.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct Figure {
    pub summary: LatencySummary,
    pub curve: Vec<QuantilePoint>,
}

impl From<&LatencyHistogram> for Figure {
    fn from(h: &LatencyHistogram) -> Figure {
        Figure {
            summary: h.summary(),
            curve: h.curve(),
        }
    }
}

/// The real-time set-up a thread actually obtained.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct RtObtained {
    /// The core the thread is pinned to.
    pub pinned_core: Option<usize>,
    /// `SCHED_FIFO` priority, if obtained (else normal scheduling).
    pub fifo_priority: Option<i32>,
    /// `mlockall` succeeded.
    pub memory_locked: bool,
    /// The timer slack is 1 ns.
    pub timer_slack_1ns: bool,
    /// What was asked for and not obtained.
    pub warnings: Vec<String>,
}

/// The timing report of one daemon: written when it stops (`--stats FILE`).
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct DaemonTimings {
    /// `hcc-sim`, `hcc-controller`, …
    pub daemon: String,
    /// Wait strategy of its loop (`event`, `hybrid`).
    pub wait: String,
    /// Real-time set-up obtained by its loop thread.
    pub rt: RtObtained,
    /// Wall time the loop ran, s.
    pub run_s: f64,
    /// Latency distributions by name.
    pub figures: BTreeMap<String, Figure>,
    /// Event counters by name.
    pub counters: BTreeMap<String, u64>,
}

impl DaemonTimings {
    /// Writes the report as JSON to `path`.
    pub fn write_json(&self, path: &Path) -> Result<(), TimingError> {
        let text = serde_json::to_string_pretty(self).map_err(|e| TimingError::Format {
            path: path.display().to_string(),
            source: e,
        })?;
        std::fs::write(path, text + "\n").map_err(|e| TimingError::Io {
            path: path.display().to_string(),
            source: e,
        })
    }

    /// Reads a report written by [`DaemonTimings::write_json`].
    pub fn read_json(path: &Path) -> Result<DaemonTimings, TimingError> {
        let text = std::fs::read_to_string(path).map_err(|e| TimingError::Io {
            path: path.display().to_string(),
            source: e,
        })?;
        serde_json::from_str(&text).map_err(|e| TimingError::Format {
            path: path.display().to_string(),
            source: e,
        })
    }

    /// A latency distribution by name (empty if missing).
    pub fn figure(&self, name: &str) -> Figure {
        self.figures.get(name).cloned().unwrap_or_default()
    }

    /// A counter by name (0 if missing).
    pub fn counter(&self, name: &str) -> u64 {
        self.counters.get(name).copied().unwrap_or(0)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn summary_of_known_values() {
        let mut h = LatencyHistogram::new();
        for v in 1..=1000u64 {
            h.record(v * 1000);
        }
        let s = h.summary();
        assert_eq!(s.count, 1000);
        assert_eq!(s.min_ns, 1000);
        // Three significant digits: within 0.1 %.
        let close = |got: u64, want: u64| (got as f64 - want as f64).abs() <= 1e-3 * want as f64;
        assert!(close(s.p50_ns, 500_000), "{s:?}");
        assert!(close(s.p99_ns, 990_000), "{s:?}");
        assert!(close(s.max_ns, 1_000_000), "{s:?}");
        assert!((s.mean_ns - 500_500.0).abs() < 1e-3 * 500_500.0);
        assert_eq!(h.count_above(900_000), 100);
    }

    #[test]
    fn out_of_range_values_are_counted_not_lost() {
        let mut h = LatencyHistogram::new();
        h.record(LatencyHistogram::HIGHEST_NS * 2);
        h.record_signed(-5);
        h.record(0);
        let s = h.summary();
        assert_eq!(s.count, 3);
        assert_eq!(s.saturated, 1);
        assert_eq!(s.negative, 1);
        assert_eq!(s.min_ns, 0);
    }

    #[test]
    fn curve_is_monotonic_and_ends_at_the_maximum() {
        let mut h = LatencyHistogram::new();
        for v in 0..100_000u64 {
            h.record(1000 + (v * 7919) % 50_000);
        }
        h.record(2_000_000);
        let c = h.curve();
        assert!(c.len() > 10);
        for w in c.windows(2) {
            assert!(w[1].percentile > w[0].percentile);
            assert!(w[1].value_ns >= w[0].value_ns);
        }
        assert_eq!(c.last().unwrap().percentile, 100.0);
        assert_eq!(c.last().unwrap().value_ns, h.summary().max_ns);
    }

    #[test]
    fn merge_and_empty() {
        let mut a = LatencyHistogram::new();
        let mut b = LatencyHistogram::new();
        assert_eq!(a.summary(), LatencySummary::default());
        assert!(a.curve().is_empty());
        a.record(10);
        b.record(20);
        a.merge(&b);
        assert_eq!(a.count(), 2);
        a.clear();
        assert_eq!(a.count(), 0);
    }

    #[test]
    fn report_round_trip() {
        let mut h = LatencyHistogram::new();
        h.record(1234);
        let mut r = DaemonTimings {
            daemon: "hcc-sim".into(),
            wait: "hybrid".into(),
            run_s: 1.5,
            ..Default::default()
        };
        r.figures.insert("tick_lateness".into(), Figure::from(&h));
        r.counters.insert("ticks".into(), 7);
        let dir = std::env::temp_dir().join(format!("hcc-timing-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let path = dir.join("t.json");
        r.write_json(&path).unwrap();
        let back = DaemonTimings::read_json(&path).unwrap();
        assert_eq!(back, r);
        assert_eq!(back.counter("ticks"), 7);
        assert_eq!(back.counter("missing"), 0);
        std::fs::write(&path, "{").unwrap();
        let err = DaemonTimings::read_json(&path).unwrap_err().to_string();
        assert!(err.contains("not a timing report"), "{err}");
        std::fs::remove_dir_all(&dir).unwrap();
    }
}
