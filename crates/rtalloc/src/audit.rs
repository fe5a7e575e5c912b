//! The allocation audit of a real-time loop, for the tests that prove a loop
//! allocation-free (the controller's, the simulator's, a driver's): what
//! "allocation-free" means here, defined once.
//!
//! ```no_run
//! # fn iteration() {}
//! let mut audit = hcc_rtalloc::LoopAudit::prepare(512 * 1024);
//! for _ in 0..1_000 { iteration(); }      // warm-up: connections, caches
//! audit.start();
//! for _ in 0..10_000 { iteration(); audit.note(); }
//! let report = audit.finish();
//! println!("{}", report.line("my loop", 10_000));
//! report.check().unwrap();
//! ```

use crate::{
    PageFaults, RtSection, Stats, ThreadStats, lock_memory, page_faults, prefault, prefault_stack,
    reset_high_water, stats, thread_stats,
};

/// A loop being audited (see the module docs).
pub struct LoopAudit {
    locked: bool,
    rt: Option<RtSection>,
    baseline: Stats,
    before: ThreadStats,
    faults_before: PageFaults,
    varying: u64,
}

/// What a real-time loop did between [`LoopAudit::start`] and
/// [`LoopAudit::finish`].
#[derive(Debug, Clone, Copy)]
pub struct LoopReport {
    /// The real-time thread's own allocations.
    pub during: ThreadStats,
    /// The pool when the measurement started, and when it ended.
    pub baseline: Stats,
    pub after: Stats,
    /// Iterations whose pool occupancy after them differed from the baseline.
    pub varying: u64,
    /// Page faults of the thread.
    pub faults: PageFaults,
    /// Whether memory was locked (then a major fault is unexpected too).
    pub locked: bool,
}

impl LoopAudit {
    /// Prepares the calling thread as a real-time loop's is prepared: locks
    /// memory when permitted (said on stdout when not), pre-faults the pool
    /// and `stack_bytes` of stack, enters the real-time section. Then warm
    /// the loop up and call [`LoopAudit::start`].
    pub fn prepare(stack_bytes: usize) -> LoopAudit {
        let locked = lock_memory()
            .map_err(|e| println!("{e}: major page faults cannot be ruled out"))
            .is_ok();
        prefault();
        let _ = prefault_stack(stack_bytes);
        LoopAudit {
            locked,
            rt: Some(RtSection::enter()),
            baseline: stats(),
            before: thread_stats(),
            faults_before: PageFaults::default(),
            varying: 0,
        }
    }

    /// The measurement starts now (after the warm-up).
    pub fn start(&mut self) {
        reset_high_water();
        self.baseline = stats();
        self.before = thread_stats();
        self.faults_before = page_faults().unwrap_or_default();
        self.varying = 0;
    }

    /// After one measured iteration: notes the pool's occupancy.
    pub fn note(&mut self) {
        self.varying += u64::from(stats().pool_in_use != self.baseline.pool_in_use);
    }

    /// The measurement ends: leaves the real-time section; the report.
    pub fn finish(mut self) -> LoopReport {
        let faults = page_faults().unwrap_or_default().since(self.faults_before);
        drop(self.rt.take());
        LoopReport {
            during: thread_stats().since(self.before),
            baseline: self.baseline,
            after: stats(),
            varying: self.varying,
            faults,
            locked: self.locked,
        }
    }
}

impl LoopReport {
    /// One line of figures, `what` ran `iterations` times.
    pub fn line(&self, what: &str, iterations: u64) -> String {
        format!(
            "{what}, {iterations} iterations: {:.2} pool allocs per iteration, {} system allocs, {} fallbacks, pool in use {} (high-water {}), page faults {:?}",
            self.during.pool_allocs as f64 / iterations.max(1) as f64,
            self.during.system_allocs,
            self.during.fallbacks,
            self.after.pool_in_use,
            self.after.pool_high_water,
            self.faults,
        )
    }

    /// Whether the loop was allocation-free: no call into the system
    /// allocator (allocation or free) and no fallback from the pool; the
    /// pool's occupancy the same after every iteration and at the end as at
    /// the start, its high-water at most 4 blocks above (one iteration's
    /// loans in flight); no page fault that the preparation should have ruled
    /// out ([`PageFaults::unexpected`]). The first failed condition, named.
    pub fn check(&self) -> Result<(), String> {
        let (d, a) = (&self.during, &self.after);
        let fail = |what: &str| Err(format!("{what}: {self:?}"));
        if d.system_allocs != 0 || d.system_frees != 0 {
            return fail("calls into the system allocator");
        }
        if d.fallbacks != 0 {
            return fail("requests the pool could not serve");
        }
        if a.rt_system_allocs != self.baseline.rt_system_allocs {
            return fail("system allocations of a real-time thread");
        }
        if self.varying != 0 || a.pool_in_use != self.baseline.pool_in_use {
            return fail("pool occupancy not constant from iteration to iteration");
        }
        if a.pool_high_water > self.baseline.pool_in_use + 4 {
            return fail("pool occupancy not bounded");
        }
        if self.faults.unexpected(self.locked) != 0 {
            return fail("page faults in the prepared section");
        }
        Ok(())
    }
}
