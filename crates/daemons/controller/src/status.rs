//! What the loop shares with the non-real-time logging thread: every counter
//! of the control cycle and a few flags, as relaxed atomics.
//!
//! The counters are defined once, in [`hcc_cycle::counters`];
//! [`LoopStatus`] holds one atomic per counter in the order of
//! [`CycleCounters::values`], so the logs, the `--stats` report and the
//! shared atomics all follow a new counter without another edit.

use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};

use hcc_cycle::CycleCounters;
use hcc_msgs::TelemetryCounters;

/// Counters and flags shared with the logging thread (all relaxed atomics).
#[derive(Debug, Default)]
pub struct LoopStatus {
    /// One per counter, in the order of [`CycleCounters::values`].
    counters: [AtomicU64; CycleCounters::COUNT],
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

impl LoopStatus {
    /// Stores the loop's counters (allocation-free, lock-free).
    pub fn publish(&self, counters: &CycleCounters) {
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
    pub fn loop_counters(&self) -> CycleCounters {
        CycleCounters::from_values(std::array::from_fn(|i| {
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
        let mut values = [0u64; CycleCounters::COUNT];
        for (i, v) in values.iter_mut().enumerate() {
            *v = 10 + i as u64;
        }
        let c = CycleCounters::from_values(values);
        let status = LoopStatus::default();
        status.publish(&c);
        assert_eq!(status.loop_counters(), c);
        assert_eq!(status.counters(), c.telemetry);
    }
}
