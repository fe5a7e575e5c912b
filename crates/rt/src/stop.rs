//! SIGINT and SIGTERM request a clean stop: the handler stores into an atomic
//! (async-signal-safe, no allocation) that loops poll once per period with
//! [`stop_requested`]. The sleeps of [`crate::sleep`] return early once a stop
//! was requested.

use std::sync::atomic::{AtomicBool, Ordering};

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

/// Whether SIGINT or SIGTERM was received since [`install_stop_handler`].
/// Allocation-free (one atomic load).
pub fn stop_requested() -> bool {
    STOP.load(Ordering::Relaxed)
}
