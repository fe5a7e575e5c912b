//! What the simulator's real-time thread shares with its logging thread:
//! counters and flags in relaxed atomics ([`LoopStatus`]), stored by the
//! loop and reported by `log_loop` every 100 ms (the real-time thread
//! never logs).

use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::time::Duration;

/// Counters and flags shared with the logging thread (all relaxed atomics).
#[derive(Default)]
pub struct LoopStatus {
    pub(crate) missed: AtomicU64,
    pub(crate) fallback_cycles: AtomicU64,
    pub(crate) in_fallback: AtomicBool,
    pub(crate) has_command: AtomicBool,
    pub(crate) overruns: AtomicU64,
    pub(crate) rejected: AtomicU64,
}

/// The logging thread: reports the loop's transitions and counters, read
/// from `status` every 100 ms, until `done`.
pub(crate) fn log_loop(status: &LoopStatus, done: &AtomicBool) {
    let (mut missed, mut fallback, mut overruns, mut rejected) = (0, false, 0, 0);
    let mut connected = false;
    while !done.load(Ordering::Relaxed) {
        std::thread::sleep(Duration::from_millis(100));
        if !connected && status.has_command.load(Ordering::Relaxed) {
            connected = true;
            tracing::info!("receiving torque commands");
        }
        let f = status.in_fallback.load(Ordering::Relaxed);
        if f != fallback {
            fallback = f;
            if f {
                tracing::warn!(
                    "no applicable torque command: fallback active (gravity held, joint damping)"
                );
            } else {
                tracing::info!("torque commands are back; fallback ended");
            }
        }
        let m = status.missed.load(Ordering::Relaxed);
        if m != missed {
            tracing::warn!("missed commands: {m} (+{})", m - missed);
            missed = m;
        }
        let o = status.overruns.load(Ordering::Relaxed);
        if o != overruns {
            tracing::warn!("clock overruns (re-anchored): {o}");
            overruns = o;
        }
        let r = status.rejected.load(Ordering::Relaxed);
        if r != rejected {
            tracing::warn!("rejected commands (invalid or gravity conflict): {r}");
            rejected = r;
        }
    }
}
