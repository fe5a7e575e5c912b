//! Recording into a [`LatencyHistogram`] never allocates (counting global
//! allocator), so it may run inside the 1 kHz loops.

use std::alloc::{GlobalAlloc, Layout, System};
use std::sync::atomic::{AtomicU64, Ordering};

use hcc_timing::LatencyHistogram;

struct Counting;

static ALLOCS: AtomicU64 = AtomicU64::new(0);

// SAFETY: forwards to the system allocator, only counting.
unsafe impl GlobalAlloc for Counting {
    unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
        ALLOCS.fetch_add(1, Ordering::Relaxed);
        unsafe { System.alloc(layout) }
    }
    unsafe fn dealloc(&self, ptr: *mut u8, layout: Layout) {
        unsafe { System.dealloc(ptr, layout) }
    }
    unsafe fn realloc(&self, ptr: *mut u8, layout: Layout, new_size: usize) -> *mut u8 {
        ALLOCS.fetch_add(1, Ordering::Relaxed);
        unsafe { System.realloc(ptr, layout, new_size) }
    }
}

#[global_allocator]
static GLOBAL: Counting = Counting;

#[test]
fn recording_allocates_nothing_over_the_whole_range() {
    let mut h = LatencyHistogram::new();
    let before = ALLOCS.load(Ordering::Relaxed);
    let mut v = 1u64;
    for i in 0..100_000u64 {
        // Values from 0 ns to far beyond the range, and negative differences.
        h.record(v);
        h.record_signed(-(i as i64 % 3));
        v = v.wrapping_mul(3).wrapping_add(i) % (4 * LatencyHistogram::HIGHEST_NS);
    }
    let after = ALLOCS.load(Ordering::Relaxed);
    assert_eq!(after - before, 0, "allocations while recording");
    assert_eq!(h.count(), 200_000);
    assert!(h.summary().saturated > 0);
}
