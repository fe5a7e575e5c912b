//! Real-time set-up of the calling thread, the usual Linux recipe: pin it to
//! one core, switch it to `SCHED_FIFO`, lock memory (`mlockall`), pre-fault
//! the stack and the allocator pool, shrink the timer slack to 1 ns
//! (`PR_SET_TIMERSLACK`, so that absolute sleeps wake on time). Each step
//! that needs a privilege the process does not have is reported as a warning
//! and skipped: the process still runs, only with worse latency.
//!
//! Also the start-up clean-up of the shared-memory resources that crashed
//! processes left behind ([`cleanup_stale_resources`]).

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

/// Whether a thread of this process may switch to `SCHED_FIFO` at
/// `priority`: tried on a short-lived thread of its own, so the caller's
/// scheduling is unchanged. The error says why not (no `CAP_SYS_NICE`, an
/// `RLIMIT_RTPRIO` below `priority`, a container without real-time budget).
pub fn fifo_permitted(priority: i32) -> std::io::Result<()> {
    std::thread::spawn(move || set_fifo(priority))
        .join()
        .unwrap_or_else(|_| Err(std::io::Error::other("the probe thread panicked")))
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

/// Lowers the calling thread's priority to nice `nice` (0..=19; no
/// privilege needed): a helper thread of a real-time daemon that must give
/// way to everything the loop depends on (Linux: per thread).
pub fn lower_priority(nice: i32) -> std::io::Result<()> {
    // SAFETY: gettid has no preconditions.
    let tid = unsafe { libc::gettid() };
    // SAFETY: setpriority on this thread's own id.
    if unsafe { libc::setpriority(libc::PRIO_PROCESS, tid as libc::id_t, nice.clamp(0, 19)) } != 0 {
        return Err(std::io::Error::last_os_error());
    }
    Ok(())
}
