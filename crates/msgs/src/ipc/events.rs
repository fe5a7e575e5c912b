//! The event ports (`state_ready`, `command_ready`) and the precise wait for a
//! notification until a deadline.

use iceoryx2::port::listener::{Listener, ListenerCreateError};
use iceoryx2::port::notifier::{Notifier, NotifierCreateError};
use iceoryx2::prelude::*;
use iceoryx2::service::port_factory::event;

use super::error::IpcError;
use super::node::Ipc;

/// Notifier of an event service.
pub type EventNotifier = Notifier<Ipc>;
/// Listener of an event service.
pub type EventListener = Listener<Ipc>;

/// A notifier of `service` whose plain `notify` sends `default_event`.
pub(super) fn notifier(
    factory: &event::PortFactory<Ipc>,
    service: &str,
    default_event: usize,
) -> Result<EventNotifier, IpcError> {
    factory
        .notifier_builder()
        .default_event_id(EventId::new(default_event))
        .create()
        .map_err(|e| IpcError::Port {
            service: service.to_owned(),
            port: "notifier",
            reason: match e {
                NotifierCreateError::ExceedsMaxSupportedNotifiers => {
                    "it already has the maximum number of notifiers".to_owned()
                }
                other => format!("iceoryx2 failure {other:?}"),
            },
        })
}

/// A listener of `service`.
pub(super) fn listener(
    factory: &event::PortFactory<Ipc>,
    service: &str,
) -> Result<EventListener, IpcError> {
    factory
        .listener_builder()
        .create()
        .map_err(|e| IpcError::Port {
            service: service.to_owned(),
            port: "listener",
            reason: match e {
                ListenerCreateError::ExceedsMaxSupportedListeners => {
                    "it already has the maximum number of listeners".to_owned()
                }
                other => format!("iceoryx2 failure {other:?}"),
            },
        })
}

/// Waits until `listener` has a pending notification or the `CLOCK_MONOTONIC`
/// time `deadline_ns` has come, whichever is first; true if a notification is
/// pending (it is not consumed: drain it with `try_wait`). Returns at once
/// when the deadline has passed.
///
/// Use it instead of `Listener::timed_wait` for deadlines inside a control
/// period: iceoryx2 0.10's event (a Unix datagram socket) implements the
/// timeout with `SO_RCVTIMEO`, which the kernel counts in scheduler ticks — a
/// `timed_wait` of 200 µs without a notification returns after up to one tick
/// (4 ms with `CONFIG_HZ=250`). This waits on the listener's file descriptor
/// with `ppoll`, whose timeout is a high-resolution timer (precise to the
/// thread's timer slack). One system call, no allocation.
pub fn wait_for_event_until(listener: &EventListener, deadline_ns: u64) -> bool {
    // SAFETY: the descriptor is only used for this call, while `listener`
    // (which owns it) is borrowed.
    let fd = unsafe { listener.file_descriptor().native_handle() };
    let mut pfd = libc::pollfd {
        fd,
        events: libc::POLLIN,
        revents: 0,
    };
    let rest = deadline_ns.saturating_sub(crate::monotonic_now_ns());
    let ts = libc::timespec {
        tv_sec: (rest / 1_000_000_000) as libc::time_t,
        tv_nsec: (rest % 1_000_000_000) as libc::c_long,
    };
    // SAFETY: one valid pollfd, a valid timespec, no signal mask change.
    let rc = unsafe { libc::ppoll(&mut pfd, 1, &ts, std::ptr::null()) };
    // rc < 0 is EINTR (a signal, e.g. the SIGTERM that sets a stop flag the
    // caller checks) or a bad descriptor: the wait ends either way.
    rc > 0 && pfd.revents & libc::POLLIN != 0
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::ipc::node::create_node;
    use crate::ipc::services::Services;
    use crate::ipc::testing::{remove_global_mgmt, unique_prefix};
    use crate::{Namespace, ServiceNames};

    #[test]
    fn event_wait_until_a_deadline_or_a_notification() {
        let prefix = unique_prefix("evt");
        {
            let names = ServiceNames::for_namespace(Namespace::unique("evt_test").unwrap());
            let node =
                create_node("hcc-msgs-evt", SignalHandlingMode::Disabled, Some(&prefix)).unwrap();
            let services = Services::open(&node, &names).unwrap();
            let notifier = services.command_ready_notifier().unwrap();
            let listener = services.command_ready_listener().unwrap();
            let now = crate::monotonic_now_ns;

            // Nothing pending: returns false, never before the deadline.
            let mut overshoot_ppoll = 0;
            for _ in 0..5 {
                let deadline = now() + 500_000;
                assert!(!wait_for_event_until(&listener, deadline));
                let t = now();
                assert!(t >= deadline, "returned {} ns early", deadline - t);
                overshoot_ppoll = overshoot_ppoll.max(t - deadline);
            }
            // A deadline in the past returns at once.
            assert!(!wait_for_event_until(&listener, 0));

            // Pending: true at once, until drained.
            notifier.notify().unwrap();
            assert!(wait_for_event_until(&listener, now() + 1_000_000_000));
            assert!(wait_for_event_until(&listener, 0), "not consumed");
            let mut events = 0;
            listener.try_wait(|_| events += 1).unwrap();
            assert_eq!(events, 1);
            assert!(!wait_for_event_until(&listener, now() + 100_000));

            // For the record (not asserted): iceoryx2's own timed wait of the same 500 µs.
            let t0 = now();
            listener
                .timed_wait(|_| {}, std::time::Duration::from_micros(500))
                .unwrap();
            println!(
                "500 µs without a notification: ppoll overshoots by at most {:.1} µs, Listener::timed_wait took {:.1} µs",
                overshoot_ppoll as f64 * 1e-3,
                (now() - t0) as f64 * 1e-3
            );
        }
        let rest = remove_global_mgmt(&prefix);
        assert!(rest.is_empty(), "files left behind: {rest:?}");
    }
}
