//! Behaviour of the real-time block pool with `RtAllocator` installed as this
//! test binary's global allocator.
//!
//! The pool and its counters are process-wide, so the tests take a common lock
//! and compare counters before/after their own work.

use std::alloc::{Layout, alloc, alloc_zeroed, dealloc, realloc};
use std::hint::black_box;
use std::rc::Rc;
use std::sync::{Barrier, Mutex, MutexGuard};

use hcc_rtalloc::{
    BLOCK_ALIGN, BLOCK_COUNT, BLOCK_SIZE, RtAllocator, RtSection, is_pool_ptr, is_rt, stats,
    thread_stats,
};

#[global_allocator]
static ALLOCATOR: RtAllocator = RtAllocator::new();

static SERIAL: Mutex<()> = Mutex::new(());

fn serial() -> MutexGuard<'static, ()> {
    SERIAL
        .lock()
        .unwrap_or_else(|poisoned| poisoned.into_inner())
}

const CYCLES: usize = 10_000;

#[test]
fn allocator_is_installed_and_flag_scopes() {
    let _serial = serial();
    assert!(hcc_rtalloc::pool_active());
    assert!(!is_rt());
    {
        let _outer = RtSection::enter();
        assert!(is_rt());
        {
            let _inner = RtSection::enter();
            assert!(is_rt());
        }
        assert!(is_rt(), "inner guard restores the outer state");
    }
    assert!(!is_rt());
    hcc_rtalloc::enter_rt();
    assert!(is_rt());
    hcc_rtalloc::leave_rt();
    assert!(!is_rt());
}

/// The iceoryx2 per-loan pattern: `Rc::new` of a 48-byte state, dropped in the
/// same cycle.
#[test]
fn rc_cycles_on_rt_thread_never_reach_the_system_allocator() {
    let _serial = serial();
    let baseline = stats();
    let before = thread_stats();
    let _rt = RtSection::enter();
    hcc_rtalloc::reset_high_water();

    let mut max_in_use = 0;
    let mut not_back_to_baseline = 0usize;
    for i in 0..CYCLES {
        let state = black_box(Rc::new([i as u8; 48]));
        let held = stats().pool_in_use;
        max_in_use = max_in_use.max(held);
        assert!(is_pool_ptr(Rc::as_ptr(&state).cast()));
        drop(state);
        if stats().pool_in_use != baseline.pool_in_use {
            not_back_to_baseline += 1;
        }
    }
    drop(_rt);

    let thread = thread_stats().since(before);
    let after = stats();
    assert_eq!(thread.system_allocs, 0, "{thread:?}");
    assert_eq!(thread.system_frees, 0, "{thread:?}");
    assert_eq!(thread.fallbacks, 0, "{thread:?}");
    assert_eq!(thread.pool_allocs, CYCLES as u64);
    assert_eq!(thread.pool_frees, CYCLES as u64);
    assert_eq!(after.rt_system_allocs, baseline.rt_system_allocs);
    assert_eq!(after.rt_system_frees, baseline.rt_system_frees);
    assert_eq!(after.rt_fallbacks, baseline.rt_fallbacks);
    assert_eq!(not_back_to_baseline, 0);
    assert_eq!(max_in_use, baseline.pool_in_use + 1);
    assert_eq!(after.pool_high_water, baseline.pool_in_use + 1);
    assert_eq!(after.pool_in_use, baseline.pool_in_use);
}

#[repr(C, align(128))]
struct OverAligned([u8; 16]);

#[test]
fn oversize_overaligned_and_exhausted_requests_fall_back_to_system() {
    let _serial = serial();
    // Containers for the exhaustion test, allocated before going real-time.
    let mut held: Vec<Box<[u8; 32]>> = Vec::with_capacity(BLOCK_COUNT + 1);
    let baseline = stats();
    let before = thread_stats();
    {
        let _rt = RtSection::enter();

        let big = black_box(Box::new([7u8; BLOCK_SIZE + 1]));
        assert!(!is_pool_ptr(big.as_ptr()));
        let aligned = black_box(Box::new(OverAligned([1; 16])));
        assert!(!is_pool_ptr(aligned.0.as_ptr()));
        assert_eq!((&*aligned as *const OverAligned as usize) % 128, 0);
        assert!(std::mem::align_of::<OverAligned>() > BLOCK_ALIGN);
        let exact = black_box(Box::new([3u8; BLOCK_SIZE]));
        assert!(is_pool_ptr(exact.as_ptr()), "exactly BLOCK_SIZE fits");
        drop((big, aligned, exact));

        let mid = stats();
        assert_eq!(mid.rt_fallbacks - baseline.rt_fallbacks, 2);
        assert_eq!(mid.rt_system_allocs - baseline.rt_system_allocs, 2);
        assert_eq!(mid.rt_system_frees - baseline.rt_system_frees, 2);
        assert_eq!(mid.pool_exhausted, baseline.pool_exhausted);

        // Fill the pool, then one more.
        let free = BLOCK_COUNT - baseline.pool_in_use as usize;
        for i in 0..=free {
            held.push(Box::new([i as u8; 32]));
        }
        let pooled = held.iter().filter(|b| is_pool_ptr(b.as_ptr())).count();
        assert_eq!(pooled, free);
        assert!(!is_pool_ptr(held[free].as_ptr()));
        let full = stats();
        assert_eq!(full.pool_in_use, BLOCK_COUNT as u64);
        assert_eq!(full.pool_exhausted - baseline.pool_exhausted, 1);
        assert_eq!(full.rt_fallbacks - baseline.rt_fallbacks, 3);
        for (i, b) in held.iter().enumerate() {
            assert!(b.iter().all(|&x| x == i as u8), "block {i} intact");
        }
        held.clear();
    }
    let thread = thread_stats().since(before);
    assert_eq!(thread.fallbacks, 3);
    assert_eq!(stats().pool_in_use, baseline.pool_in_use);
}

#[test]
fn blocks_freed_on_another_thread_return_to_the_pool() {
    let _serial = serial();
    let baseline = stats();
    let block = std::thread::spawn(|| {
        let _rt = RtSection::enter();
        black_box(Box::new([0x5au8; 64]))
    })
    .join()
    .unwrap_or_else(|_| panic!("allocating thread panicked"));
    assert!(is_pool_ptr(block.as_ptr()));
    assert_eq!(stats().pool_in_use, baseline.pool_in_use + 1);
    assert!(!is_rt());
    let before = thread_stats();
    drop(block);
    let thread = thread_stats().since(before);
    assert_eq!(thread.pool_frees, 1);
    assert_eq!(thread.system_frees, 0);
    let after = stats();
    assert_eq!(after.pool_in_use, baseline.pool_in_use);
    assert_eq!(after.pool_frees - baseline.pool_frees, 1);
    assert_eq!(after.pool_double_frees, baseline.pool_double_frees);
}

#[test]
fn non_rt_threads_never_take_pool_blocks() {
    let _serial = serial();
    let baseline = stats();
    let thread = std::thread::spawn(|| {
        let before = thread_stats();
        let mut in_pool = 0;
        for i in 0..1000usize {
            let a = black_box(Box::new([i as u8; 16]));
            let b = black_box(Rc::new([0u8; 48]));
            let s = black_box(format!("{i}"));
            let mut v = black_box(Vec::<u8>::with_capacity(8));
            v.extend_from_slice(&[1, 2, 3]);
            in_pool += [
                a.as_ptr(),
                Rc::as_ptr(&b).cast::<u8>(),
                s.as_ptr(),
                v.as_ptr(),
            ]
            .iter()
            .filter(|p| is_pool_ptr(**p))
            .count();
        }
        (in_pool, thread_stats().since(before))
    })
    .join()
    .unwrap_or_else(|_| panic!("worker panicked"));
    let (in_pool, counts) = thread;
    assert_eq!(in_pool, 0);
    assert_eq!(counts.pool_allocs, 0);
    assert_eq!(counts.fallbacks, 0);
    assert!(counts.system_allocs >= 4000);
    let after = stats();
    assert_eq!(after.pool_allocs, baseline.pool_allocs);
    assert_eq!(after.rt_system_allocs, baseline.rt_system_allocs);
}

#[test]
fn realloc_keeps_fitting_blocks_and_moves_growing_ones() {
    let _serial = serial();
    let baseline = stats();
    let before = thread_stats();
    let _rt = RtSection::enter();
    unsafe {
        // Grow within the block: same pointer.
        let layout = Layout::from_size_align(32, 8).unwrap();
        let p = alloc(layout);
        assert!(is_pool_ptr(p));
        for i in 0..32 {
            p.add(i).write(i as u8);
        }
        let p2 = realloc(p, layout, 64);
        assert_eq!(p2, p);
        let p3 = realloc(p2, Layout::from_size_align(64, 8).unwrap(), BLOCK_SIZE);
        assert_eq!(p3, p);
        // Shrink: same pointer.
        let p4 = realloc(p3, Layout::from_size_align(BLOCK_SIZE, 8).unwrap(), 16);
        assert_eq!(p4, p);
        let p5 = realloc(p4, Layout::from_size_align(16, 8).unwrap(), 32);
        assert_eq!(p5, p);
        assert_eq!(stats().pool_in_use, baseline.pool_in_use + 1);
        assert_eq!(thread_stats().since(before).fallbacks, 0);

        // Grow beyond the block: moved to System, content kept, block freed.
        let big = realloc(p5, layout, 4 * BLOCK_SIZE);
        assert!(!big.is_null() && !is_pool_ptr(big));
        for i in 0..32 {
            assert_eq!(*big.add(i), i as u8);
        }
        assert_eq!(stats().pool_in_use, baseline.pool_in_use);
        assert_eq!(thread_stats().since(before).fallbacks, 1);

        // Realloc of a System block on an RT thread is a fallback.
        let bigger = realloc(
            big,
            Layout::from_size_align(4 * BLOCK_SIZE, 8).unwrap(),
            4096,
        );
        assert!(!is_pool_ptr(bigger));
        for i in 0..32 {
            assert_eq!(*bigger.add(i), i as u8);
        }
        assert_eq!(thread_stats().since(before).fallbacks, 2);
        dealloc(bigger, Layout::from_size_align(4096, 8).unwrap());

        // alloc_zeroed from the pool zeroes a dirtied block.
        let full = Layout::from_size_align(BLOCK_SIZE, BLOCK_ALIGN).unwrap();
        let dirty = alloc(full);
        assert!(is_pool_ptr(dirty));
        assert_eq!(dirty as usize % BLOCK_ALIGN, 0);
        dirty.write_bytes(0xab, BLOCK_SIZE);
        dealloc(dirty, full);
        let zeroed = alloc_zeroed(full);
        assert!(is_pool_ptr(zeroed));
        assert!((0..BLOCK_SIZE).all(|i| *zeroed.add(i) == 0));
        dealloc(zeroed, full);
    }

    // A Vec growing on an RT thread: in the pool while it fits, then moved.
    let mut v: Vec<u8> = Vec::new();
    let mut pool_ptr = None;
    for i in 0..BLOCK_SIZE {
        v.push(i as u8);
        assert!(is_pool_ptr(v.as_ptr()));
        if v.capacity() >= 16 {
            let p = *pool_ptr.get_or_insert(v.as_ptr());
            assert_eq!(v.as_ptr(), p, "grows in place inside the block");
        }
    }
    v.push(0xff);
    assert!(!is_pool_ptr(v.as_ptr()));
    assert!(
        v.iter()
            .take(BLOCK_SIZE)
            .enumerate()
            .all(|(i, &x)| x == i as u8)
    );
    drop(v);
    drop(_rt);

    // Realloc of a pool block on a non-RT thread: kept while it fits, moved to
    // System (no fallback: the thread is not real-time) when it grows.
    let block = {
        let _rt = RtSection::enter();
        unsafe { alloc(Layout::from_size_align(8, 8).unwrap()) }
    };
    assert!(is_pool_ptr(block));
    let non_rt_before = thread_stats();
    unsafe {
        block.write_bytes(0x11, 8);
        let same = realloc(block, Layout::from_size_align(8, 8).unwrap(), 100);
        assert_eq!(same, block);
        let moved = realloc(same, Layout::from_size_align(100, 8).unwrap(), 1000);
        assert!(!is_pool_ptr(moved));
        assert!((0..8).all(|i| *moved.add(i) == 0x11));
        dealloc(moved, Layout::from_size_align(1000, 8).unwrap());
    }
    let non_rt = thread_stats().since(non_rt_before);
    assert_eq!(non_rt.fallbacks, 0);
    assert_eq!(non_rt.pool_frees, 1);

    let after = stats();
    assert_eq!(after.pool_in_use, baseline.pool_in_use);
    assert_eq!(after.pool_double_frees, baseline.pool_double_frees);
}

/// Two real-time threads claim and free blocks concurrently; each writes a
/// pattern unique to (thread, iteration) and checks it before freeing, so a
/// block handed out twice would be detected.
#[test]
fn concurrent_rt_threads_never_share_a_block() {
    const ITERATIONS: u64 = 200_000;
    const SLOTS: usize = 8;
    let _serial = serial();
    let baseline = stats();
    hcc_rtalloc::reset_high_water();
    let barrier = Barrier::new(2);

    let worker = |tag: u64| {
        let _rt = RtSection::enter();
        let before = thread_stats();
        let mut slots: [Option<(u64, Box<[u64; 16]>)>; SLOTS] = Default::default();
        let mut corrupted = 0u64;
        let mut outside_pool = 0u64;
        barrier.wait();
        for i in 0..ITERATIONS {
            let slot = &mut slots[(i as usize) % SLOTS];
            if let Some((stamp, block)) = slot.take()
                && block.iter().any(|&w| w != stamp)
            {
                corrupted += 1;
            }
            let stamp = (tag << 56) | i;
            let block = Box::new([stamp; 16]);
            if !is_pool_ptr(block.as_ptr().cast()) {
                outside_pool += 1;
            }
            *slot = Some((stamp, block));
        }
        for (stamp, block) in slots.iter().flatten() {
            if block.iter().any(|w| w != stamp) {
                corrupted += 1;
            }
        }
        drop(slots);
        (corrupted, outside_pool, thread_stats().since(before))
    };

    let (a, b) = std::thread::scope(|s| {
        let a = s.spawn(|| worker(1));
        let b = s.spawn(|| worker(2));
        (
            a.join().unwrap_or_else(|_| panic!("worker 1 panicked")),
            b.join().unwrap_or_else(|_| panic!("worker 2 panicked")),
        )
    });
    for (corrupted, outside_pool, counts) in [a, b] {
        assert_eq!(corrupted, 0);
        assert_eq!(outside_pool, 0);
        assert_eq!(counts.pool_allocs, ITERATIONS);
        assert_eq!(counts.pool_frees, ITERATIONS);
        assert_eq!(counts.system_allocs, 0);
    }
    let after = stats();
    assert_eq!(after.pool_in_use, baseline.pool_in_use);
    assert_eq!(after.pool_double_frees, baseline.pool_double_frees);
    assert_eq!(after.rt_fallbacks, baseline.rt_fallbacks);
    // Each thread holds at most SLOTS blocks; the relaxed occupancy counter may
    // lag a free by one per thread.
    assert!(after.pool_high_water <= baseline.pool_in_use + 2 * SLOTS as u64 + 2);
}
