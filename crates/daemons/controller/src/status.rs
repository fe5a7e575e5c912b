//! What the loop shares with the non-real-time logging thread: every counter
//! of the loop and a few flags, as relaxed atomics.
//!
//! The counters are defined once: those telemetry carries in
//! [`TelemetryCounters`] (hcc-msgs), the daemon's own in [`DaemonCounters`]
//! below, both with `hcc_msgs::define_counters!`. [`LoopCounters`] joins
//! them, and [`Status`] holds one atomic per counter in the same order, so
//! the logs, the `--stats` report and the shared atomics all follow a new
//! counter without another edit.

use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};

use hcc_msgs::TelemetryCounters;

hcc_msgs::define_counters! {
    /// Counters of the daemon that telemetry does not carry (totals since start).
    #[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
    pub struct DaemonCounters {
        /// States whose control law failed numerically (answered with SafeHold).
        numerical_failures: "numerical failures of the control law (answered with SafeHold)",
        /// Peer restarts detected (a new stream after an outage, or rejected
        /// states that follow each other).
        peer_restarts: "new peer detected; sequence checker reset",
    }
}

/// Every counter of the loop: telemetry's, then the daemon's own.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct LoopCounters {
    /// The counters telemetry carries.
    pub telemetry: TelemetryCounters,
    /// The daemon's own counters.
    pub daemon: DaemonCounters,
}

impl LoopCounters {
    /// Number of counters.
    pub const COUNT: usize = TelemetryCounters::COUNT + DaemonCounters::COUNT;

    /// Name of counter `i` (telemetry's first).
    const fn name(i: usize) -> &'static str {
        if i < TelemetryCounters::COUNT {
            TelemetryCounters::NAMES[i]
        } else {
            DaemonCounters::NAMES[i - TelemetryCounters::COUNT]
        }
    }

    /// Description of counter `i` (telemetry's first).
    const fn label(i: usize) -> &'static str {
        if i < TelemetryCounters::COUNT {
            TelemetryCounters::LABELS[i]
        } else {
            DaemonCounters::LABELS[i - TelemetryCounters::COUNT]
        }
    }

    /// The values, telemetry's first, each in field order.
    pub fn values(&self) -> [u64; Self::COUNT] {
        let t = self.telemetry.values();
        let d = self.daemon.values();
        std::array::from_fn(|i| {
            if i < TelemetryCounters::COUNT {
                t[i]
            } else {
                d[i - TelemetryCounters::COUNT]
            }
        })
    }

    /// The counters from their values in the order of [`LoopCounters::values`].
    pub fn from_values(values: [u64; Self::COUNT]) -> LoopCounters {
        let (t, d) = values.split_at(TelemetryCounters::COUNT);
        LoopCounters {
            telemetry: TelemetryCounters::from_values(std::array::from_fn(|i| t[i])),
            daemon: DaemonCounters::from_values(std::array::from_fn(|i| d[i])),
        }
    }

    /// (name, description, value) of every counter, telemetry's first.
    pub fn entries(&self) -> [(&'static str, &'static str, u64); Self::COUNT] {
        let values = self.values();
        std::array::from_fn(|i| (Self::name(i), Self::label(i), values[i]))
    }
}

/// Counters and flags shared with the logging thread (all relaxed atomics).
#[derive(Debug, Default)]
pub struct Status {
    /// One per counter, in the order of [`LoopCounters::values`].
    counters: [AtomicU64; LoopCounters::COUNT],
    /// The peer is currently lost (no state within the stale timeout).
    pub peer_lost: AtomicBool,
    /// When the current (or last) loss was detected, CLOCK_MONOTONIC ns.
    pub peer_lost_at_ns: AtomicU64,
    /// Wake-up time of the last state received, CLOCK_MONOTONIC ns.
    pub last_state_ns: AtomicU64,
    /// `header.seq` of the last state received.
    pub last_state_seq: AtomicU64,
    /// At least one state was received.
    pub connected: AtomicBool,
    /// Worst compute time so far, ns.
    pub max_compute_ns: AtomicU64,
    /// Connection upkeep while waiting ([`hcc_rt::UpkeepCounts`]): updates
    /// that changed something, their system allocations on the real-time
    /// thread, their longest duration (ns).
    pub upkeep_updates: AtomicU64,
    pub upkeep_system_allocs: AtomicU64,
    pub upkeep_max_ns: AtomicU64,
}

impl Status {
    /// Stores the loop's counters (allocation-free, lock-free).
    pub fn publish(&self, counters: &LoopCounters) {
        for (a, v) in self.counters.iter().zip(counters.values()) {
            a.store(v, Ordering::Relaxed);
        }
    }

    /// Stores the connection upkeep's counts (allocation-free, lock-free).
    pub fn publish_upkeep(&self, c: &hcc_rt::UpkeepCounts) {
        self.upkeep_updates.store(c.updates, Ordering::Relaxed);
        self.upkeep_system_allocs
            .store(c.system_allocs, Ordering::Relaxed);
        self.upkeep_max_ns.store(c.max_ns, Ordering::Relaxed);
    }

    /// Every counter as last published.
    pub fn loop_counters(&self) -> LoopCounters {
        LoopCounters::from_values(std::array::from_fn(|i| {
            self.counters[i].load(Ordering::Relaxed)
        }))
    }

    /// The counters as in telemetry.
    pub fn counters(&self) -> TelemetryCounters {
        self.loop_counters().telemetry
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_counter_round_trips_through_the_atomics_in_one_order() {
        let mut values = [0u64; LoopCounters::COUNT];
        for (i, v) in values.iter_mut().enumerate() {
            *v = 10 + i as u64;
        }
        let c = LoopCounters::from_values(values);
        assert_eq!(c.telemetry.cycles, 10);
        assert_eq!(c.telemetry.send_failures, 18);
        assert_eq!(c.telemetry.rate_limited, 19);
        assert_eq!(c.telemetry.low_passed, 20);
        assert_eq!(c.daemon.numerical_failures, 21);
        assert_eq!(c.daemon.peer_restarts, 22);
        let status = Status::default();
        status.publish(&c);
        assert_eq!(status.loop_counters(), c);
        assert_eq!(status.counters(), c.telemetry);
        let entries = c.entries();
        assert_eq!(entries[0], ("cycles", "cycles", 10));
        assert_eq!(entries[12].0, "peer_restarts");
        assert!(entries[12].1.contains("new peer detected"));
        let names: Vec<_> = entries.iter().map(|e| e.0).collect();
        let mut unique = names.clone();
        unique.sort_unstable();
        unique.dedup();
        assert_eq!(unique.len(), names.len(), "{names:?}");
    }
}
