//! Waits to absolute `CLOCK_MONOTONIC` deadlines (ns, the clock of
//! [`hcc_msgs::monotonic_now_ns`] and of every message stamp). Absolute
//! deadlines do not drift: a loop computes t_0 + k T and sleeps to it,
//! however long the period's work took. All of these are allocation-free.

use crate::stop::stop_requested;
use hcc_msgs::monotonic_now_ns;

/// The precise wait for an IPC event: until the listener has a pending
/// notification or the deadline has come (`ppoll` on the listener's file
/// descriptor, a high-resolution timeout; iceoryx2's own `timed_wait` rounds
/// to scheduler ticks). It lives in `hcc-msgs` with the transport whose
/// descriptor it polls; see [`hcc_msgs::ipc::wait_for_event_until`].
pub use hcc_msgs::ipc::wait_for_event_until;

/// Sleeps until the `CLOCK_MONOTONIC` time `deadline_ns` (absolute,
/// `clock_nanosleep(TIMER_ABSTIME)`), retrying after signals unless a stop
/// was requested. Returns at once when the deadline has passed.
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
/// requested. The spin makes only vDSO clock reads.
pub fn sleep_until_hybrid_ns(deadline_ns: u64, lead_ns: u64) {
    sleep_until_hybrid_with(deadline_ns, lead_ns, || {});
}

/// [`sleep_until_hybrid_ns`] that calls `idle` before it sleeps and on every
/// pass of its spin: the place for work that must not fall on the path
/// after the deadline (e.g. [`crate::ConnectionUpkeep::run`]). `idle` must be
/// short and allocation-free when it has nothing to do.
pub fn sleep_until_hybrid_with(deadline_ns: u64, lead_ns: u64, mut idle: impl FnMut()) {
    let wake = deadline_ns.saturating_sub(lead_ns);
    idle();
    if monotonic_now_ns() < wake {
        sleep_until_ns(wake);
    }
    while monotonic_now_ns() < deadline_ns && !stop_requested() {
        idle();
        std::hint::spin_loop();
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::WaitStrategy;

    #[test]
    fn sleep_reaches_the_deadline() {
        for _ in 0..20 {
            let deadline = monotonic_now_ns() + 300_000;
            sleep_until_ns(deadline);
            let now = monotonic_now_ns();
            assert!(now >= deadline, "woke {} ns early", deadline - now);
        }
        // A deadline in the past returns at once.
        let t0 = monotonic_now_ns();
        sleep_until_ns(t0.saturating_sub(1_000_000));
        assert!(monotonic_now_ns() - t0 < 50_000_000);
    }

    #[test]
    fn hybrid_wait_reaches_the_deadline_by_spinning_the_last_part() {
        for lead in [0, 100_000, HYBRID_LEAD_NS, 10_000_000] {
            let deadline = monotonic_now_ns() + 500_000;
            sleep_until_hybrid_ns(deadline, lead);
            let now = monotonic_now_ns();
            assert!(
                now >= deadline,
                "lead {lead}: woke {} ns early",
                deadline - now
            );
        }
        for w in [WaitStrategy::Event, WaitStrategy::Hybrid] {
            let deadline = monotonic_now_ns() + 200_000;
            w.sleep_until(deadline);
            assert!(monotonic_now_ns() >= deadline, "{w}");
        }
    }
}
