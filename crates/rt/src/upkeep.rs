//! Connection upkeep of a real-time loop's iceoryx2 ports, done while the
//! loop waits rather than on its torque path.
//!
//! iceoryx2 connects a port to the peers that appeared since its last
//! operation lazily, inside that operation: a publisher's `send` first maps
//! the queue of every new subscriber (a shared-memory open and `mmap`, and
//! heap allocations), a subscriber's `receive` does the same for a new
//! publisher. Left alone, the first command sent after `hcc record`,
//! `hcc monitor` or a client's subscriber attached would pay for that
//! connection between the state and its answer, and allocate on the
//! real-time thread. [`ConnectionUpkeep::run`] calls `update_connections`
//! on the loop's ports from its waits instead (every pass of a hybrid wait's
//! spin, and before each sleep): the check is one atomic load per port when
//! nothing changed, and a new peer is connected while the loop has nothing
//! else to do. What the upkeep allocated and how long its longest update
//! took are counted, so that a process can tell them apart from
//! allocations on the torque path.
//!
//! A peer that appears after the last check before a send (in the last
//! spin pass, or while an `event` wait blocks) is still connected by that
//! send: upkeep narrows the window to the loop's busy time, it cannot close
//! it.

use hcc_msgs::ipc::UpdateConnections;
use hcc_msgs::monotonic_now_ns;

/// What the upkeep did so far (cumulative).
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct UpkeepCounts {
    /// Calls that changed something (a connection made or dropped: the
    /// thread allocated or freed).
    pub updates: u64,
    /// Heap allocations made by those calls (any allocator).
    pub allocs: u64,
    /// The subset of [`UpkeepCounts::allocs`] that went to the system
    /// allocator on a real-time thread (see `hcc_rtalloc::Stats::rt_system_allocs`).
    pub system_allocs: u64,
    /// Ports whose update failed (a peer's segment could not be mapped).
    pub failures: u64,
    /// Longest call that changed something, ns.
    pub max_ns: u64,
}

/// The upkeep of a loop's ports; allocation-free itself.
#[derive(Debug, Default)]
pub struct ConnectionUpkeep {
    counts: UpkeepCounts,
}

impl ConnectionUpkeep {
    /// A fresh upkeep with zero counts.
    pub fn new() -> ConnectionUpkeep {
        ConnectionUpkeep::default()
    }

    /// Connects `ports` to the peers that appeared or left since the last
    /// call (iceoryx2's `update_connections`); returns whether anything
    /// changed.
    pub fn run(&mut self, ports: &[&dyn UpdateConnections]) -> bool {
        let before = hcc_rtalloc::thread_stats();
        let t0 = monotonic_now_ns();
        let mut failures = 0;
        for p in ports {
            failures += u64::from(p.update_connections().is_err());
        }
        let after = hcc_rtalloc::thread_stats().since(before);
        self.counts.failures += failures;
        if after.allocs == 0 && after.frees == 0 {
            return false;
        }
        let c = &mut self.counts;
        c.updates += 1;
        c.allocs += after.allocs;
        c.system_allocs += after.system_allocs;
        c.max_ns = c.max_ns.max(monotonic_now_ns().saturating_sub(t0));
        true
    }

    /// The counts so far.
    pub fn counts(&self) -> UpkeepCounts {
        self.counts
    }
}
