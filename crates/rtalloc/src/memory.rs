//! Memory locking, stack pre-faulting and page-fault accounting for the
//! real-time threads (the usual Linux real-time recipe: `mlockall`, touch the
//! stack and the preallocated memory once, then verify with `getrusage`).

use std::io;

use crate::Error;

/// Bytes of stack touched per recursion step of [`prefault_stack`].
const STACK_CHUNK: usize = 4096;

/// Stride of the writes that fault pages in (the smallest Linux page size).
const PAGE_STRIDE: usize = 4096;

/// Stack kept free below the touched region, for the recursion's own frames,
/// signal handlers and the guard page.
const STACK_MARGIN: usize = 64 * 1024;

/// Page faults of the calling thread (Linux: `RUSAGE_THREAD`; elsewhere the
/// whole process, `RUSAGE_SELF`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct PageFaults {
    /// Minor faults: a page was mapped without I/O (first touch of
    /// anonymous/`.bss`/shared memory, copy-on-write).
    pub minor: u64,
    /// Major faults: a page had to be read from disk.
    pub major: u64,
}

impl PageFaults {
    /// Faults since `earlier` (saturating at zero).
    pub fn since(self, earlier: PageFaults) -> PageFaults {
        PageFaults {
            minor: self.minor.saturating_sub(earlier.minor),
            major: self.major.saturating_sub(earlier.major),
        }
    }

    /// The faults a prepared real-time section must not take: every minor fault
    /// (the memory it touches was pre-faulted), and the major ones when memory is
    /// locked. Without [`lock_memory`] the kernel may drop a clean file-backed page
    /// (the binary's code) and read it back on the next touch, a major fault that
    /// only locking rules out.
    pub fn unexpected(self, memory_locked: bool) -> u64 {
        self.minor + if memory_locked { self.major } else { 0 }
    }
}

/// Page-fault counters from `getrusage`: of the calling thread on Linux
/// (`RUSAGE_THREAD`), of the whole process elsewhere (`RUSAGE_SELF`).
pub fn page_faults() -> Result<PageFaults, Error> {
    #[cfg(target_os = "linux")]
    let who = libc::RUSAGE_THREAD;
    #[cfg(not(target_os = "linux"))]
    let who = libc::RUSAGE_SELF;

    // SAFETY: rusage is plain old data; getrusage fills it or fails.
    let mut usage: libc::rusage = unsafe { core::mem::zeroed() };
    // SAFETY: `usage` is a valid, writable rusage.
    if unsafe { libc::getrusage(who, &mut usage) } != 0 {
        return Err(Error::ResourceUsage(io::Error::last_os_error()));
    }
    Ok(PageFaults {
        minor: u64::try_from(usage.ru_minflt).unwrap_or(0),
        major: u64::try_from(usage.ru_majflt).unwrap_or(0),
    })
}

/// Lock all current and future pages of the process in RAM:
/// `mlockall(MCL_CURRENT | MCL_FUTURE)`.
///
/// Fails (as a value) with `EPERM` without `CAP_IPC_LOCK` or a sufficient
/// `RLIMIT_MEMLOCK`, and with `ENOMEM` when the limit is too small for the
/// current mappings. With `MCL_FUTURE` in effect, later large mappings (thread
/// stacks, big allocations) count against the limit too.
pub fn lock_memory() -> Result<(), Error> {
    // SAFETY: mlockall has no memory-safety preconditions.
    if unsafe { libc::mlockall(libc::MCL_CURRENT | libc::MCL_FUTURE) } != 0 {
        return Err(Error::LockMemory(io::Error::last_os_error()));
    }
    Ok(())
}

/// Undo [`lock_memory`]: `munlockall()`.
pub fn unlock_memory() -> Result<(), Error> {
    // SAFETY: munlockall has no memory-safety preconditions.
    if unsafe { libc::munlockall() } != 0 {
        return Err(Error::UnlockMemory(io::Error::last_os_error()));
    }
    Ok(())
}

/// Touch `bytes` of the calling thread's stack below the current frame, so
/// that the real-time loop running at a similar depth takes no page fault on
/// its stack.
///
/// Returns [`Error::StackTooSmall`] instead of overflowing when the thread's
/// remaining stack (less a 64 KiB margin) is smaller than `bytes` (checked on
/// Linux, where the stack bounds are known).
pub fn prefault_stack(bytes: usize) -> Result<(), Error> {
    if let Some(available) = remaining_stack() {
        let usable = available.saturating_sub(STACK_MARGIN);
        if bytes > usable {
            return Err(Error::StackTooSmall {
                requested: bytes,
                available: usable,
            });
        }
    }
    touch_stack(bytes.div_ceil(STACK_CHUNK));
    Ok(())
}

/// One frame with a `STACK_CHUNK` array written (volatile) once per page, then
/// recursion for the remaining chunks. The array is read after the recursive
/// call so the frame cannot be elided or turned into a tail call.
#[inline(never)]
fn touch_stack(chunks: usize) {
    if chunks == 0 {
        return;
    }
    let mut buffer = [0u8; STACK_CHUNK];
    let start = buffer.as_mut_ptr();
    for offset in (0..STACK_CHUNK).step_by(PAGE_STRIDE) {
        // SAFETY: offset < STACK_CHUNK, inside `buffer`.
        unsafe { core::ptr::write_volatile(start.add(offset), 1) };
    }
    touch_stack(chunks - 1);
    core::hint::black_box(&buffer);
}

/// Bytes of stack between the current frame and the lowest address of the
/// calling thread's stack, if the platform reports the stack bounds.
#[cfg(target_os = "linux")]
fn remaining_stack() -> Option<usize> {
    // SAFETY: attr is initialised by pthread_getattr_np before use and
    // destroyed afterwards; the out-pointers are valid locals.
    unsafe {
        let mut attr: libc::pthread_attr_t = core::mem::zeroed();
        if libc::pthread_getattr_np(libc::pthread_self(), &mut attr) != 0 {
            return None;
        }
        let mut low: *mut libc::c_void = core::ptr::null_mut();
        let mut size: libc::size_t = 0;
        let ok = libc::pthread_attr_getstack(&attr, &mut low, &mut size) == 0;
        libc::pthread_attr_destroy(&mut attr);
        if !ok {
            return None;
        }
        let marker = 0u8;
        let here = core::hint::black_box(&marker) as *const u8 as usize;
        Some(here.saturating_sub(low as usize))
    }
}

#[cfg(not(target_os = "linux"))]
fn remaining_stack() -> Option<usize> {
    None
}
