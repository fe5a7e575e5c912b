//! Global allocator for the real-time threads of hcc.
//!
//! # Why
//!
//! The 1 kHz torque loop must not call into the system allocator (a `malloc`
//! can take a lock, `mmap`/`brk`, or page-fault) and must not page-fault.
//! The controller's own code is allocation-free, but iceoryx2 0.10 makes one
//! heap allocation per `Publisher::loan_uninit` (and so per `send_copy`): a
//! 48-byte reference-counted shared state created with `Rc::new` and freed on
//! the same thread when the sample is sent or dropped. (`Subscriber::receive`,
//! `Listener::timed_wait*` and `Notifier::notify` allocate nothing; `WaitSet`
//! allocates and is not used in the loop.)
//!
//! Rather than pin an old iceoryx2 or patch it, [`RtAllocator`] serves the
//! real-time threads' small blocks from a preallocated, pre-faulted,
//! lock-free pool: with it the loop makes zero calls into the system
//! allocator and takes zero page faults.
//!
//! # How
//!
//! * A thread marks itself real-time with [`enter_rt`] / [`leave_rt`] (or the
//!   scope guard [`RtSection`]). The flag is a const-initialised thread-local
//!   `Cell<bool>`, whose access never allocates.
//! * While a thread is real-time, each request with size ≤ [`BLOCK_SIZE`] and
//!   align ≤ [`BLOCK_ALIGN`] gets a block from a static pool of [`BLOCK_COUNT`]
//!   blocks (page-aligned, in `.bss`), claimed with an atomic occupancy bitmap
//!   (`fetch_or` to claim, `fetch_and` to free: lock-free and ABA-free).
//! * `dealloc` recognises pool blocks by address, so a block freed on any
//!   thread, real-time or not, returns to the pool. Everything else goes to
//!   [`std::alloc::System`].
//! * Larger or over-aligned requests on a real-time thread, and requests when
//!   the pool is full, fall back to `System` and are counted
//!   ([`Stats::rt_fallbacks`]) so tests and the controller's diagnostics see them.
//! * Threads that are not real-time never take pool blocks: their behaviour
//!   and cost are those of `System` plus a thread-local flag check.
//!
//! # Use
//!
//! The crate does not install itself. Each binary that runs a real-time loop
//! opts in at its root:
//!
//! ```
//! #[global_allocator]
//! static ALLOCATOR: hcc_rtalloc::RtAllocator = hcc_rtalloc::RtAllocator::new();
//! # fn main() {}
//! ```
//!
//! and at start-up of the real-time thread:
//!
//! ```no_run
//! # fn control_cycle() -> bool { false }
//! # fn main() -> Result<(), hcc_rtalloc::Error> {
//! if let Err(e) = hcc_rtalloc::lock_memory() {
//!     // EPERM without CAP_IPC_LOCK: report and go on.
//!     eprintln!("warning: {e}");
//! }
//! hcc_rtalloc::prefault(); // map every pool page
//! hcc_rtalloc::prefault_stack(256 * 1024)?;
//! let _rt = hcc_rtalloc::RtSection::enter();
//! while control_cycle() {}
//! # Ok(())
//! # }
//! ```
//!
//! [`pool_active`] tells at run time whether the pool is in effect (that is,
//! whether the binary installed the allocator).
//!
//! Linux only in practice: the flag relies on native thread-local storage
//! (a thread-local that allocates on first access would recurse into the
//! allocator), and [`page_faults`] is per thread only on Linux.

mod audit;
mod memory;
mod pool;

use std::alloc::{GlobalAlloc, Layout, System};
use std::cell::Cell;
use std::sync::atomic::{AtomicU64, Ordering};

pub use audit::{LoopAudit, LoopReport};
pub use memory::{PageFaults, lock_memory, page_faults, prefault_stack, unlock_memory};
pub use pool::{BLOCK_ALIGN, BLOCK_COUNT, BLOCK_SIZE, POOL_BYTES, is_pool_ptr};

/// Errors of the memory helpers.
#[derive(Debug, thiserror::Error)]
pub enum Error {
    /// `mlockall(MCL_CURRENT | MCL_FUTURE)` failed (typically `EPERM` without
    /// `CAP_IPC_LOCK`, or `ENOMEM` for a small `RLIMIT_MEMLOCK`).
    #[error("mlockall(MCL_CURRENT | MCL_FUTURE) failed: {0}")]
    LockMemory(#[source] std::io::Error),
    /// `munlockall()` failed.
    #[error("munlockall() failed: {0}")]
    UnlockMemory(#[source] std::io::Error),
    /// `getrusage` failed.
    #[error("getrusage failed: {0}")]
    ResourceUsage(#[source] std::io::Error),
    /// The calling thread's stack is too small to pre-fault the requested amount.
    #[error(
        "prefault_stack: {requested} bytes requested but only {available} bytes of this thread's stack are usable"
    )]
    StackTooSmall {
        /// Bytes asked for.
        requested: usize,
        /// Bytes of stack left below the caller, less a safety margin.
        available: usize,
    },
}

thread_local! {
    /// Whether the current thread is real-time (served from the pool).
    static RT: Cell<bool> = const { Cell::new(false) };
    /// Allocation counters of the current thread.
    static THREAD: Cell<ThreadStats> = const { Cell::new(ThreadStats::ZERO) };
}

/// Mark the current thread as real-time: from now on its small allocations
/// come from the pool.
pub fn enter_rt() {
    RT.with(|rt| rt.set(true));
}

/// Mark the current thread as not real-time: its allocations go to `System`
/// again. Pool blocks it still holds return to the pool when freed.
pub fn leave_rt() {
    RT.with(|rt| rt.set(false));
}

/// Whether the current thread is marked real-time.
pub fn is_rt() -> bool {
    RT.with(Cell::get)
}

/// Scope guard: marks the thread real-time on [`RtSection::enter`] and
/// restores the previous state when dropped (also on unwinding).
#[derive(Debug)]
#[must_use = "the thread leaves the real-time state when the guard is dropped"]
pub struct RtSection {
    previous: bool,
    // Thread-bound: the guard must be dropped on the thread that created it.
    _not_send: core::marker::PhantomData<*const ()>,
}

impl RtSection {
    /// Mark the current thread real-time until the guard is dropped.
    pub fn enter() -> RtSection {
        let previous = is_rt();
        enter_rt();
        RtSection {
            previous,
            _not_send: core::marker::PhantomData,
        }
    }
}

impl Drop for RtSection {
    fn drop(&mut self) {
        RT.with(|rt| rt.set(self.previous));
    }
}

// Process-wide counters (relaxed; each is individually exact, a snapshot of
// several is not atomic).
static RT_SYSTEM_ALLOCS: AtomicU64 = AtomicU64::new(0);
static RT_SYSTEM_FREES: AtomicU64 = AtomicU64::new(0);
static RT_FALLBACKS: AtomicU64 = AtomicU64::new(0);
static POOL_EXHAUSTED: AtomicU64 = AtomicU64::new(0);
static POOL_ALLOCS: AtomicU64 = AtomicU64::new(0);
static POOL_FREES: AtomicU64 = AtomicU64::new(0);
static POOL_IN_USE: AtomicU64 = AtomicU64::new(0);
static POOL_HIGH_WATER: AtomicU64 = AtomicU64::new(0);
static POOL_DOUBLE_FREES: AtomicU64 = AtomicU64::new(0);

/// Process-wide allocator counters, see [`stats`]. Counters are cumulative
/// since process start; take differences around the code under test.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct Stats {
    /// Calls into `System` (alloc, alloc_zeroed, realloc) made on real-time threads.
    pub rt_system_allocs: u64,
    /// `System` deallocations made on real-time threads.
    pub rt_system_frees: u64,
    /// Real-time requests the pool could not serve (too large, over-aligned,
    /// pool full, or realloc of a non-pool block), served by `System`.
    pub rt_fallbacks: u64,
    /// The subset of [`Stats::rt_fallbacks`] caused by a full pool.
    pub pool_exhausted: u64,
    /// Blocks handed out by the pool.
    pub pool_allocs: u64,
    /// Blocks returned to the pool (from any thread).
    pub pool_frees: u64,
    /// Blocks currently handed out.
    pub pool_in_use: u64,
    /// Largest [`Stats::pool_in_use`] seen since start or [`reset_high_water`].
    pub pool_high_water: u64,
    /// Frees of pool blocks that were not handed out (caller bug; ignored).
    pub pool_double_frees: u64,
}

/// Snapshot of the process-wide counters.
pub fn stats() -> Stats {
    let get = |c: &AtomicU64| c.load(Ordering::Relaxed);
    Stats {
        rt_system_allocs: get(&RT_SYSTEM_ALLOCS),
        rt_system_frees: get(&RT_SYSTEM_FREES),
        rt_fallbacks: get(&RT_FALLBACKS),
        pool_exhausted: get(&POOL_EXHAUSTED),
        pool_allocs: get(&POOL_ALLOCS),
        pool_frees: get(&POOL_FREES),
        pool_in_use: get(&POOL_IN_USE),
        pool_high_water: get(&POOL_HIGH_WATER),
        pool_double_frees: get(&POOL_DOUBLE_FREES),
    }
}

/// Set the high-water mark to the current occupancy, to measure the peak of
/// one phase (e.g. the steady-state loop after start-up).
pub fn reset_high_water() {
    POOL_HIGH_WATER.store(POOL_IN_USE.load(Ordering::Relaxed), Ordering::Relaxed);
}

/// Allocator calls made by the current thread, see [`thread_stats`].
/// Cumulative since the thread started.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct ThreadStats {
    /// Calls to alloc, alloc_zeroed and realloc (whatever served them).
    pub allocs: u64,
    /// Calls to dealloc.
    pub frees: u64,
    /// Pool blocks claimed.
    pub pool_allocs: u64,
    /// Pool blocks returned.
    pub pool_frees: u64,
    /// Calls into `System` alloc, alloc_zeroed or realloc.
    pub system_allocs: u64,
    /// Calls into `System` dealloc.
    pub system_frees: u64,
    /// Requests made while real-time that `System` served.
    pub fallbacks: u64,
}

impl ThreadStats {
    const ZERO: ThreadStats = ThreadStats {
        allocs: 0,
        frees: 0,
        pool_allocs: 0,
        pool_frees: 0,
        system_allocs: 0,
        system_frees: 0,
        fallbacks: 0,
    };

    /// Counts since `earlier` (saturating at zero).
    pub fn since(self, earlier: ThreadStats) -> ThreadStats {
        ThreadStats {
            allocs: self.allocs.saturating_sub(earlier.allocs),
            frees: self.frees.saturating_sub(earlier.frees),
            pool_allocs: self.pool_allocs.saturating_sub(earlier.pool_allocs),
            pool_frees: self.pool_frees.saturating_sub(earlier.pool_frees),
            system_allocs: self.system_allocs.saturating_sub(earlier.system_allocs),
            system_frees: self.system_frees.saturating_sub(earlier.system_frees),
            fallbacks: self.fallbacks.saturating_sub(earlier.fallbacks),
        }
    }
}

/// The current thread's allocator counters (independent of other threads, so
/// usable in tests that run in parallel).
pub fn thread_stats() -> ThreadStats {
    THREAD.with(Cell::get)
}

fn count(update: impl FnOnce(&mut ThreadStats)) {
    THREAD.with(|cell| {
        let mut s = cell.get();
        update(&mut s);
        cell.set(s);
    });
}

fn bump(counter: &AtomicU64) {
    counter.fetch_add(1, Ordering::Relaxed);
}

/// Touch every free pool block once so that all pool pages are mapped before
/// real-time use. Call at start-up, before the real-time loop (blocks in use
/// are skipped; a concurrent real-time allocation may momentarily see a
/// touched block as taken and move on to the next).
pub fn prefault() {
    pool::touch_free_blocks();
}

/// Whether the pool is in effect in this process, i.e. whether the binary
/// installed [`RtAllocator`] as its global allocator: allocates one byte as a
/// real-time thread and checks where it came from.
pub fn pool_active() -> bool {
    let _rt = RtSection::enter();
    let probe = core::hint::black_box(Box::new(0u8));
    is_pool_ptr(&*probe)
}

/// The global allocator: `System`, plus the block pool for real-time threads.
/// See the crate documentation.
#[derive(Debug, Default)]
pub struct RtAllocator {
    _private: (),
}

impl RtAllocator {
    /// The allocator, for `#[global_allocator] static A: RtAllocator = RtAllocator::new();`.
    pub const fn new() -> RtAllocator {
        RtAllocator { _private: () }
    }

    /// Serve a new allocation (without counting it in `ThreadStats::allocs`).
    ///
    /// # Safety
    /// As [`GlobalAlloc::alloc`].
    unsafe fn obtain(&self, layout: Layout, zeroed: bool) -> *mut u8 {
        if is_rt() {
            if pool::fits(layout.size(), layout.align()) {
                if let Some(block) = pool::claim() {
                    bump(&POOL_ALLOCS);
                    let in_use = POOL_IN_USE.fetch_add(1, Ordering::Relaxed) + 1;
                    POOL_HIGH_WATER.fetch_max(in_use, Ordering::Relaxed);
                    count(|s| s.pool_allocs += 1);
                    if zeroed {
                        // SAFETY: the block holds BLOCK_SIZE >= layout.size() bytes.
                        unsafe { block.write_bytes(0, layout.size()) };
                    }
                    return block;
                }
                bump(&POOL_EXHAUSTED);
            }
            bump(&RT_FALLBACKS);
            bump(&RT_SYSTEM_ALLOCS);
            count(|s| s.fallbacks += 1);
        }
        count(|s| s.system_allocs += 1);
        // SAFETY: forwarded caller contract.
        unsafe {
            if zeroed {
                System.alloc_zeroed(layout)
            } else {
                System.alloc(layout)
            }
        }
    }

    fn give_back(block: *mut u8) {
        if pool::release(block) {
            bump(&POOL_FREES);
            POOL_IN_USE.fetch_sub(1, Ordering::Relaxed);
            count(|s| s.pool_frees += 1);
        } else {
            bump(&POOL_DOUBLE_FREES);
        }
    }
}

// SAFETY: pool blocks are BLOCK_SIZE bytes at BLOCK_ALIGN alignment and are
// only handed to requests that fit; each block has one owner at a time (atomic
// bitmap); everything else is delegated to `System` with the caller's layout.
unsafe impl GlobalAlloc for RtAllocator {
    unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
        count(|s| s.allocs += 1);
        // SAFETY: forwarded caller contract.
        unsafe { self.obtain(layout, false) }
    }

    unsafe fn alloc_zeroed(&self, layout: Layout) -> *mut u8 {
        count(|s| s.allocs += 1);
        // SAFETY: forwarded caller contract.
        unsafe { self.obtain(layout, true) }
    }

    unsafe fn dealloc(&self, ptr: *mut u8, layout: Layout) {
        count(|s| s.frees += 1);
        if is_pool_ptr(ptr) {
            Self::give_back(ptr);
            return;
        }
        if is_rt() {
            bump(&RT_SYSTEM_FREES);
        }
        count(|s| s.system_frees += 1);
        // SAFETY: not a pool block, so it came from System with this layout.
        unsafe { System.dealloc(ptr, layout) }
    }

    unsafe fn realloc(&self, ptr: *mut u8, layout: Layout, new_size: usize) -> *mut u8 {
        count(|s| s.allocs += 1);
        if is_pool_ptr(ptr) {
            if new_size <= BLOCK_SIZE {
                // The block still fits (its alignment was checked when it was
                // handed out): keep it.
                return ptr;
            }
            // SAFETY: the caller guarantees new_size, rounded up to
            // layout.align(), does not overflow isize.
            let new_layout = unsafe { Layout::from_size_align_unchecked(new_size, layout.align()) };
            // SAFETY: new_layout has non-zero size.
            let moved = unsafe { self.obtain(new_layout, false) };
            if !moved.is_null() {
                // SAFETY: both regions hold at least min(old, new) bytes and
                // are distinct allocations.
                unsafe { core::ptr::copy_nonoverlapping(ptr, moved, layout.size().min(new_size)) };
                Self::give_back(ptr);
            }
            return moved;
        }
        if is_rt() {
            bump(&RT_FALLBACKS);
            bump(&RT_SYSTEM_ALLOCS);
            count(|s| s.fallbacks += 1);
        }
        count(|s| s.system_allocs += 1);
        // SAFETY: not a pool block, so it came from System with this layout.
        unsafe { System.realloc(ptr, layout, new_size) }
    }
}
