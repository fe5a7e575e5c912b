//! Real-time set-up of a daemon thread and the few OS calls its loop makes,
//! shared by the controller daemon and the plant-simulator daemon.
//!
//! The usual Linux recipe: pin the thread to one core, switch it to
//! `SCHED_FIFO`, lock memory (`mlockall`), pre-fault the stack and the
//! allocator pool, shrink the timer slack to 1 ns (`PR_SET_TIMERSLACK`), and
//! sleep with `clock_nanosleep(CLOCK_MONOTONIC, TIMER_ABSTIME)` to absolute
//! deadlines. Each step that needs a privilege the process does not have is
//! reported as a warning and skipped: the daemon still runs, only with worse
//! latency.
//!
//! SIGINT and SIGTERM set a flag ([`install_stop_handler`], [`stop_requested`])
//! that the loop polls once per cycle: an async-signal-safe store into an
//! atomic, no allocation.

use std::sync::atomic::{AtomicBool, Ordering};

/// What [`prepare_rt_thread`] should do.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct RtSettings {
    /// Pin the calling thread to this CPU core.
    pub cpu_core: Option<usize>,
    /// `SCHED_FIFO` priority (1..=99); `None` keeps normal scheduling.
    pub sched_priority: Option<i32>,
    /// `mlockall(MCL_CURRENT | MCL_FUTURE)`.
    pub lock_memory: bool,
    /// Bytes of stack to pre-fault.
    pub prefault_stack_bytes: usize,
}

/// What [`prepare_rt_thread`] achieved; `warnings` lists what it could not do.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct RtReport {
    /// The thread is pinned to the requested core.
    pub pinned: bool,
    /// The thread runs under `SCHED_FIFO`.
    pub fifo: bool,
    /// Memory is locked.
    pub memory_locked: bool,
    /// The timer slack is 1 ns.
    pub timer_slack: bool,
    /// The stack was pre-faulted.
    pub stack_prefaulted: bool,
    /// One line per step that failed (with the reason and its consequence).
    pub warnings: Vec<String>,
}

impl RtReport {
    /// What was obtained, for a timing report.
    pub fn obtained(&self, settings: &RtSettings) -> hcc_timing::RtObtained {
        hcc_timing::RtObtained {
            pinned_core: settings.cpu_core.filter(|_| self.pinned),
            fifo_priority: settings.sched_priority.filter(|_| self.fifo),
            memory_locked: self.memory_locked,
            timer_slack_1ns: self.timer_slack,
            warnings: self.warnings.clone(),
        }
    }
}

/// Prepares the calling thread for its real-time loop (see the module docs).
/// Never fails: what is not permitted is reported in [`RtReport::warnings`].
/// Also pre-faults the real-time allocator pool (`hcc_rtalloc::prefault`).
pub fn prepare_rt_thread(settings: &RtSettings) -> RtReport {
    let mut report = RtReport::default();
    if let Some(core) = settings.cpu_core {
        let known = core_affinity::get_core_ids()
            .map(|ids| ids.iter().any(|c| c.id == core))
            .unwrap_or(false);
        if known && core_affinity::set_for_current(core_affinity::CoreId { id: core }) {
            report.pinned = true;
        } else {
            report.warnings.push(format!(
                "cannot pin the thread to CPU core {core} (no such core or not permitted); running unpinned"
            ));
        }
    }
    if let Some(priority) = settings.sched_priority {
        match set_fifo(priority) {
            Ok(()) => report.fifo = true,
            Err(e) => report.warnings.push(format!(
                "cannot switch to SCHED_FIFO priority {priority}: {e} (needs CAP_SYS_NICE or an rtprio limit); running with normal scheduling"
            )),
        }
    }
    if settings.lock_memory {
        match hcc_rtalloc::lock_memory() {
            Ok(()) => report.memory_locked = true,
            Err(e) => report.warnings.push(format!(
                "{e} (needs CAP_IPC_LOCK or a larger memlock limit); memory is not locked and may page out"
            )),
        }
    }
    // SAFETY: prctl(PR_SET_TIMERSLACK) only changes this thread's timer slack.
    let rc = unsafe { libc::prctl(libc::PR_SET_TIMERSLACK, 1 as libc::c_ulong, 0, 0, 0) };
    if rc == 0 {
        report.timer_slack = true;
    } else {
        report.warnings.push(format!(
            "cannot set the timer slack to 1 ns: {}",
            std::io::Error::last_os_error()
        ));
    }
    hcc_rtalloc::prefault();
    if settings.prefault_stack_bytes > 0 {
        match hcc_rtalloc::prefault_stack(settings.prefault_stack_bytes) {
            Ok(()) => report.stack_prefaulted = true,
            Err(e) => report.warnings.push(format!("{e}")),
        }
    }
    report
}

/// The CPU cores this process may run on (its affinity mask); empty if it
/// cannot be read.
pub fn available_cores() -> Vec<usize> {
    core_affinity::get_core_ids()
        .map(|ids| ids.into_iter().map(|c| c.id).collect())
        .unwrap_or_default()
}

/// Removes the iceoryx2 resources that crashed processes left under
/// `file_prefix` (see [`hcc_msgs::ipc::cleanup_dead_nodes`]) and returns a
/// line for the log when there were any. Run at start-up, before the node is
/// created, so that a daemon restarted after a crash (its own or its peer's)
/// finds the namespace's single-publisher slots free.
pub fn cleanup_stale_resources(file_prefix: Option<&str>) -> Option<String> {
    match hcc_msgs::ipc::cleanup_dead_nodes(file_prefix) {
        Ok(r) if r.dead == 0 => None,
        Ok(r) => Some(format!(
            "removed the stale iceoryx2 resources of {} dead process(es){}",
            r.removed,
            if r.failed > 0 {
                format!(" ({} could not be removed)", r.failed)
            } else {
                String::new()
            }
        )),
        Err(e) => Some(format!(
            "warning: cannot look for stale iceoryx2 resources: {e}"
        )),
    }
}

/// Switches the calling thread to `SCHED_FIFO` at `priority`.
pub fn set_fifo(priority: i32) -> std::io::Result<()> {
    let param = libc::sched_param {
        sched_priority: priority,
    };
    // SAFETY: `param` is a valid sched_param; pid 0 is the calling thread.
    if unsafe { libc::sched_setscheduler(0, libc::SCHED_FIFO, &param) } != 0 {
        return Err(std::io::Error::last_os_error());
    }
    Ok(())
}

/// Sleeps until the `CLOCK_MONOTONIC` time `deadline_ns` (absolute), retrying
/// after signals. Returns at once when the deadline has passed.
/// Allocation-free.
pub fn sleep_until_ns(deadline_ns: u64) {
    let ts = libc::timespec {
        tv_sec: (deadline_ns / 1_000_000_000) as libc::time_t,
        tv_nsec: (deadline_ns % 1_000_000_000) as libc::c_long,
    };
    loop {
        // SAFETY: `ts` is a valid timespec; the remaining-time pointer may be
        // null with TIMER_ABSTIME.
        let rc = unsafe {
            libc::clock_nanosleep(
                libc::CLOCK_MONOTONIC,
                libc::TIMER_ABSTIME,
                &ts,
                std::ptr::null_mut(),
            )
        };
        if rc != libc::EINTR || stop_requested() {
            return;
        }
    }
}

/// How long before a deadline a hybrid wait stops sleeping and starts to
/// poll, ns. A sleeping thread here wakes 50–100 µs late (idle virtual CPU,
/// host), rarely more; 150 µs covers that at the cost of polling for about
/// 15 % of a 1 ms period.
pub const HYBRID_LEAD_NS: u64 = 150_000;

/// Hybrid wait for the `CLOCK_MONOTONIC` time `deadline_ns`: sleeps until
/// `lead_ns` before it ([`sleep_until_ns`]), then spins on the clock until the
/// deadline. Returns at once when the deadline has passed or a stop was
/// requested. Allocation-free; the spin makes only vDSO clock reads.
pub fn sleep_until_hybrid_ns(deadline_ns: u64, lead_ns: u64) {
    let wake = deadline_ns.saturating_sub(lead_ns);
    if hcc_msgs::monotonic_now_ns() < wake {
        sleep_until_ns(wake);
    }
    while hcc_msgs::monotonic_now_ns() < deadline_ns && !stop_requested() {
        std::hint::spin_loop();
    }
}

static STOP: AtomicBool = AtomicBool::new(false);

extern "C" fn on_stop_signal(_signal: libc::c_int) {
    STOP.store(true, Ordering::SeqCst);
}

/// Installs handlers for SIGINT and SIGTERM that request a clean stop.
pub fn install_stop_handler() -> std::io::Result<()> {
    for signal in [libc::SIGINT, libc::SIGTERM] {
        // SAFETY: the handler only stores into an atomic (async-signal-safe);
        // `action` is fully initialised before use.
        unsafe {
            let mut action: libc::sigaction = std::mem::zeroed();
            action.sa_sigaction = on_stop_signal as *const () as libc::sighandler_t;
            libc::sigemptyset(&mut action.sa_mask);
            action.sa_flags = 0;
            if libc::sigaction(signal, &action, std::ptr::null_mut()) != 0 {
                return Err(std::io::Error::last_os_error());
            }
        }
    }
    Ok(())
}

/// Whether SIGINT/SIGTERM was received (or [`request_stop`] called).
pub fn stop_requested() -> bool {
    STOP.load(Ordering::Relaxed)
}

/// Requests a clean stop, as a signal would.
pub fn request_stop() {
    STOP.store(true, Ordering::SeqCst);
}
