//! Recording into a [`LatencyHistogram`] never allocates (counting global
//! allocator), so it may run inside the 1 kHz loops.

use hcc_timing::LatencyHistogram;

/// Counts the allocations of each thread (`hcc_rtalloc::thread_stats`), so the
/// test harness's own threads never disturb the count.
#[global_allocator]
static GLOBAL: hcc_rtalloc::RtAllocator = hcc_rtalloc::RtAllocator::new();

#[test]
fn recording_allocates_nothing_over_the_whole_range() {
    let mut h = LatencyHistogram::new();
    let before = hcc_rtalloc::thread_stats().allocs;
    let mut v = 1u64;
    for i in 0..100_000u64 {
        // Values from 0 ns to far beyond the range, and negative differences.
        h.record(v);
        h.record_signed(-(i as i64 % 3));
        v = v.wrapping_mul(3).wrapping_add(i) % (4 * LatencyHistogram::HIGHEST_NS);
    }
    let after = hcc_rtalloc::thread_stats().allocs;
    assert_eq!(after - before, 0, "allocations while recording");
    assert_eq!(h.count(), 200_000);
    assert!(h.summary().saturated > 0);
}
