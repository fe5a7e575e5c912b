//! Page faults and memory helpers with `RtAllocator` installed as this test
//! binary's global allocator. Page faults are counted per thread
//! (`RUSAGE_THREAD`), so other tests of this binary do not disturb them.

use std::hint::black_box;
use std::rc::Rc;
use std::sync::{Mutex, MutexGuard};

use hcc_rtalloc::{
    BLOCK_COUNT, Error, RtAllocator, RtSection, is_pool_ptr, page_faults, prefault, prefault_stack,
    stats, thread_stats,
};

#[global_allocator]
static ALLOCATOR: RtAllocator = RtAllocator::new();

static SERIAL: Mutex<()> = Mutex::new(());

fn serial() -> MutexGuard<'static, ()> {
    SERIAL
        .lock()
        .unwrap_or_else(|poisoned| poisoned.into_inner())
}

/// Locks memory as the daemons do (when permitted); says so when it cannot.
fn lock() -> bool {
    hcc_rtalloc::lock_memory()
        .map_err(|e| println!("{e}: major page faults cannot be ruled out"))
        .is_ok()
}

const CYCLES: usize = 10_000;
const STACK: usize = 256 * 1024;

/// One control-cycle stand-in: the iceoryx2 per-loan `Rc` plus some stack use.
#[inline(never)]
fn cycle(i: usize) -> u8 {
    let state = black_box(Rc::new([i as u8; 48]));
    let scratch = black_box([i as u8; 512]);
    state[0].wrapping_add(scratch[511])
}

/// Claim `n` blocks at once, write them, free them.
#[inline(never)]
fn hold_blocks(n: usize) -> usize {
    let mut blocks: [Option<Box<[u8; 64]>>; BLOCK_COUNT] = [const { None }; BLOCK_COUNT];
    for (i, slot) in blocks.iter_mut().take(n).enumerate() {
        *slot = Some(black_box(Box::new([i as u8; 64])));
    }
    blocks
        .iter()
        .flatten()
        .filter(|b| is_pool_ptr(b.as_ptr()))
        .count()
}

#[test]
fn steady_state_rt_cycles_take_no_page_faults() {
    let _serial = serial();
    let locked = lock();
    prefault();
    prefault_stack(STACK).unwrap_or_else(|e| panic!("{e}"));
    let before = thread_stats();
    let _rt = RtSection::enter();

    // Warm-up: maps the code, the counters and the stack frames of the loop.
    let mut sink = 0u8;
    for i in 0..1000 {
        sink = sink.wrapping_add(cycle(i));
    }
    let start = page_faults().unwrap_or_else(|e| panic!("{e}"));
    for i in 0..CYCLES {
        sink = sink.wrapping_add(cycle(i));
    }
    let faults = page_faults().unwrap_or_else(|e| panic!("{e}")).since(start);
    let counts = thread_stats().since(before);
    drop(_rt);
    black_box(sink);

    println!("page faults over {CYCLES} RT cycles after warm-up: {faults:?}");
    assert_eq!(faults.unexpected(locked), 0, "memory locked: {locked}");
    assert_eq!(counts.system_allocs, 0);
    assert_eq!(counts.pool_allocs, (CYCLES + 1000) as u64);
}

/// After `prefault`, claiming blocks on pool pages never used before takes no
/// page fault.
#[test]
fn prefaulted_pool_pages_take_no_fault_on_first_use() {
    let _serial = serial();
    let locked = lock();
    let free = BLOCK_COUNT - stats().pool_in_use as usize;
    prefault();
    prefault_stack(STACK).unwrap_or_else(|e| panic!("{e}"));
    let _rt = RtSection::enter();
    // Warm the code path with a single block.
    assert_eq!(hold_blocks(1), 1);
    let start = page_faults().unwrap_or_else(|e| panic!("{e}"));
    let held = hold_blocks(free);
    let faults = page_faults().unwrap_or_else(|e| panic!("{e}")).since(start);
    drop(_rt);
    assert_eq!(held, free);
    assert_eq!(
        faults.unexpected(locked),
        0,
        "{faults:?}, memory locked: {locked}"
    );
}

#[test]
fn prefault_stack_refuses_more_than_the_thread_has() {
    match prefault_stack(usize::MAX / 2) {
        Err(Error::StackTooSmall {
            requested,
            available,
        }) => {
            assert_eq!(requested, usize::MAX / 2);
            assert!(available < requested);
        }
        other => panic!("expected StackTooSmall, got {other:?}"),
    }
    // A spawned thread with a small stack: asking for more is an error, not a crash.
    let result = std::thread::Builder::new()
        .stack_size(128 * 1024)
        .spawn(|| {
            (
                prefault_stack(1024 * 1024).is_err(),
                prefault_stack(16 * 1024),
            )
        })
        .unwrap_or_else(|e| panic!("spawn: {e}"))
        .join()
        .unwrap_or_else(|_| panic!("stack thread panicked"));
    assert!(result.0);
    assert!(result.1.is_ok(), "{:?}", result.1);
}

#[test]
fn lock_memory_reports_instead_of_panicking() {
    let _serial = serial();
    match hcc_rtalloc::lock_memory() {
        Ok(()) => hcc_rtalloc::unlock_memory().unwrap_or_else(|e| panic!("{e}")),
        Err(e) => {
            let message = e.to_string();
            assert!(message.contains("mlockall"), "{message}");
        }
    }
}
