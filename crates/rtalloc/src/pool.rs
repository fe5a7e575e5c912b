//! The static block pool: fixed-size blocks ("segregated fixed-size storage")
//! in one page-aligned array in `.bss`, with an occupancy bitmap of
//! [`AtomicU64`] words.
//!
//! Allocation finds a clear bit and claims it with `fetch_or`; the thread whose
//! `fetch_or` returned the bit still clear owns the block. Freeing clears the
//! bit with `fetch_and`. A failed claim means another thread won that bit, so
//! the scheme is lock-free (some thread always makes progress), and it is free
//! of the ABA problem because the bitmap holds no pointers or version-sensitive
//! links, only the occupancy of each block.

use core::cell::UnsafeCell;
use core::sync::atomic::{AtomicU64, Ordering};

/// Size in bytes of one pool block: the largest allocation the pool serves.
///
/// 512 bytes covers iceoryx2's per-loan shared state (48 bytes) and the
/// vector a notifier builds when it finds its service's listener set changed
/// (4 listeners × 120 bytes: a driver that stops between its last state and
/// the notification of the answer; 128-byte blocks sent that one to the
/// system allocator), with the other small reference-counted or boxed values.
pub const BLOCK_SIZE: usize = 512;

/// Alignment in bytes of every pool block: the largest alignment the pool serves.
///
/// 64 bytes is a cache line, so two blocks used by different threads never
/// share a line.
pub const BLOCK_ALIGN: usize = 64;

/// Number of blocks in the pool (a multiple of 64, one bitmap word per 64 blocks).
///
/// 256 blocks × 512 bytes = 128 KiB. A 1 kHz control loop that loans one
/// iceoryx2 sample per cycle holds one block at a time; the rest is headroom
/// for several real-time threads and for samples held across cycles.
pub const BLOCK_COUNT: usize = 256;

/// Total size of the pool in bytes.
pub const POOL_BYTES: usize = BLOCK_SIZE * BLOCK_COUNT;

/// Alignment of the pool array: one (small) page, so each page holds whole blocks.
const POOL_ALIGN: usize = 4096;

const WORDS: usize = BLOCK_COUNT / 64;

const _: () = {
    assert!(BLOCK_COUNT > 0 && BLOCK_COUNT.is_multiple_of(64));
    assert!(BLOCK_ALIGN.is_power_of_two());
    assert!(BLOCK_SIZE.is_multiple_of(BLOCK_ALIGN));
    assert!(POOL_ALIGN.is_multiple_of(BLOCK_ALIGN));
    assert!(POOL_ALIGN.is_multiple_of(BLOCK_SIZE));
};

#[repr(C, align(4096))]
struct PoolMemory(UnsafeCell<[u8; POOL_BYTES]>);

// SAFETY: every byte of the pool is accessed only by the owner of the block it
// belongs to; ownership is handed out exclusively through the atomic bitmap.
unsafe impl Sync for PoolMemory {}

const _: () = assert!(core::mem::align_of::<PoolMemory>() == POOL_ALIGN);

/// The pool memory. Zero-initialised, so it lives in `.bss` and costs no
/// file size; its pages are mapped on first touch (see [`crate::prefault`]).
static POOL: PoolMemory = PoolMemory(UnsafeCell::new([0; POOL_BYTES]));

/// Occupancy bitmap: bit `i % 64` of word `i / 64` is set while block `i` is
/// handed out.
static BITMAP: [AtomicU64; WORDS] = [const { AtomicU64::new(0) }; WORDS];

fn base() -> *mut u8 {
    POOL.0.get().cast::<u8>()
}

/// Whether `ptr` points into the pool. Blocks are recognised by address range
/// alone, so a pool block may be freed from any thread.
pub fn is_pool_ptr(ptr: *const u8) -> bool {
    (ptr as usize).wrapping_sub(base() as usize) < POOL_BYTES
}

/// Whether a request of this size and alignment fits in one block.
pub(crate) fn fits(size: usize, align: usize) -> bool {
    size <= BLOCK_SIZE && align <= BLOCK_ALIGN
}

/// Claim the lowest free block. Lowest-first keeps a steady-state loop on the
/// same block (and page) every cycle. Returns `None` when the pool is full.
pub(crate) fn claim() -> Option<*mut u8> {
    for (w, word) in BITMAP.iter().enumerate() {
        let mut current = word.load(Ordering::Relaxed);
        while current != u64::MAX {
            let bit = (!current).trailing_zeros() as usize;
            let mask = 1u64 << bit;
            // Acquire pairs with the Release in `release`: the previous owner's
            // accesses to the block happen before ours.
            let previous = word.fetch_or(mask, Ordering::Acquire);
            if previous & mask == 0 {
                // SAFETY: w * 64 + bit < BLOCK_COUNT, so the offset stays inside POOL.
                return Some(unsafe { base().add((w * 64 + bit) * BLOCK_SIZE) });
            }
            current = previous | mask;
        }
    }
    None
}

/// Return the block at `ptr` (which must satisfy [`is_pool_ptr`]) to the pool.
/// Returns false if the block was not handed out (a double free).
pub(crate) fn release(ptr: *mut u8) -> bool {
    let index = (ptr as usize - base() as usize) / BLOCK_SIZE;
    let mask = 1u64 << (index % 64);
    let previous = BITMAP[index / 64].fetch_and(!mask, Ordering::Release);
    previous & mask != 0
}

/// Write to every free block once (claiming it for the moment of the write),
/// so that all pool pages are backed by private, writable pages. Blocks in use
/// are left untouched: their owner has the page mapped already in practice.
pub(crate) fn touch_free_blocks() {
    for index in 0..BLOCK_COUNT {
        let word = &BITMAP[index / 64];
        let mask = 1u64 << (index % 64);
        if word.fetch_or(mask, Ordering::Acquire) & mask == 0 {
            // SAFETY: the block is claimed by us; index < BLOCK_COUNT.
            unsafe { core::ptr::write_volatile(base().add(index * BLOCK_SIZE), 0) };
            word.fetch_and(!mask, Ordering::Release);
        }
    }
}
