//! Samples loaned ahead of time ([`PreLoan`]), so that a loop's send pays only
//! for the write and the delivery.

use std::fmt::Debug;

use iceoryx2::port::SendError;
use iceoryx2::port::publisher::Publisher;
use iceoryx2::prelude::*;
use iceoryx2::sample_mut_uninit::SampleMutUninit;

use super::node::Ipc;

/// A sample loaned ahead of time, so that the send on a loop's critical path
/// does not also pay for the loan.
///
/// `Publisher::send_copy` is a loan (taking a chunk from the publisher's data
/// segment: its free list, which the other side's releases have touched, so
/// cache misses across cores) followed by the copy and the delivery. A loop
/// that knows it will publish next cycle takes the loan off its critical path
/// ([`PreLoan::refill`], e.g. right after its send or while it waits) and on
/// the path only writes and delivers ([`PreLoan::send`]). Without a loan in
/// hand (none taken yet, or the loan failed) [`PreLoan::send`] loans as
/// `send_copy` does, so the outcome of a send is the same either way.
///
/// Holds at most one loaned sample of the publisher (its limit is
/// [`MAX_LOANED_SAMPLES`]); dropping it returns the
/// sample unsent. Neither call allocates.
///
/// [`MAX_LOANED_SAMPLES`]: super::MAX_LOANED_SAMPLES
pub struct PreLoan<T: Debug + ZeroCopySend + 'static> {
    sample: Option<SampleMutUninit<Ipc, std::mem::MaybeUninit<T>, ()>>,
    preloaned_sends: u64,
    loan_failures: u64,
}

impl<T: Debug + ZeroCopySend + 'static> Default for PreLoan<T> {
    fn default() -> Self {
        PreLoan {
            sample: None,
            preloaned_sends: 0,
            loan_failures: 0,
        }
    }
}

impl<T: Debug + ZeroCopySend + 'static> PreLoan<T> {
    /// Nothing loaned yet.
    pub fn new() -> Self {
        Self::default()
    }

    /// Loans a sample from `publisher` unless one is in hand. Returns whether
    /// one is in hand afterwards; a failed loan is counted
    /// ([`PreLoan::loan_failures`]) and [`PreLoan::send`] loans again.
    pub fn refill(&mut self, publisher: &Publisher<Ipc, T, ()>) -> bool {
        if self.sample.is_none() {
            match publisher.loan_uninit() {
                Ok(sample) => self.sample = Some(sample),
                Err(_) => self.loan_failures += 1,
            }
        }
        self.sample.is_some()
    }

    /// Publishes `value` in the sample in hand, or in a sample loaned now.
    /// The same result as `publisher.send_copy(value)`.
    pub fn send(
        &mut self,
        publisher: &Publisher<Ipc, T, ()>,
        value: T,
    ) -> Result<usize, SendError> {
        match self.sample.take() {
            Some(sample) => {
                self.preloaned_sends += 1;
                sample.write_payload(value).send()
            }
            None => publisher.send_copy(value),
        }
    }

    /// Whether a sample is in hand.
    pub fn is_loaned(&self) -> bool {
        self.sample.is_some()
    }

    /// Sends that used a sample loaned ahead of time.
    pub fn preloaned_sends(&self) -> u64 {
        self.preloaned_sends
    }

    /// Loans ahead of time that failed (the sends then loaned on the path).
    pub fn loan_failures(&self) -> u64 {
        self.loan_failures
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::ipc::node::create_node;
    use crate::ipc::services::Services;
    use crate::ipc::settings::{MAX_LOANED_SAMPLES, MAX_SUBSCRIBER_BUFFER};
    use crate::ipc::testing::{remove_global_mgmt, unique_prefix};
    use crate::{Namespace, ServiceNames, TorqueCommand};

    #[test]
    fn a_preloaned_send_delivers_what_send_copy_delivers() {
        let prefix = unique_prefix("pre");
        {
            let names = ServiceNames::for_namespace(Namespace::unique("pre_test").unwrap());
            let node =
                create_node("hcc-msgs-test", SignalHandlingMode::Disabled, Some(&prefix)).unwrap();
            let services = Services::open(&node, &names).unwrap();
            let publisher = services.torque_command_publisher().unwrap();
            let subscriber = services
                .torque_command_subscriber(MAX_SUBSCRIBER_BUFFER)
                .unwrap();
            let command = |seq: u64| {
                let mut c = TorqueCommand::zeroed();
                c.header.seq = seq;
                c.tau[0] = seq as f64 * 0.5;
                c
            };
            let mut pre = PreLoan::new();
            // Without a loan in hand the send loans on the spot.
            assert!(!pre.is_loaned());
            assert_eq!(pre.send(&publisher, command(1)).unwrap(), 1);
            assert_eq!(pre.preloaned_sends(), 0);
            for seq in 2..40 {
                assert!(pre.refill(&publisher));
                // A second refill keeps the sample in hand (one loan at a time).
                assert!(pre.refill(&publisher));
                assert!(pre.is_loaned());
                assert_eq!(pre.send(&publisher, command(seq)).unwrap(), 1);
                assert!(!pre.is_loaned());
            }
            assert_eq!((pre.preloaned_sends(), pre.loan_failures()), (38, 0));
            // A loan dropped unsent goes back: as many loans as before afterwards.
            assert!(pre.refill(&publisher));
            drop(pre);
            let held: Vec<_> = (0..MAX_LOANED_SAMPLES)
                .map(|_| publisher.loan_uninit().unwrap())
                .collect();
            drop(held);
            let mut got = Vec::new();
            while let Some(c) = subscriber.receive().unwrap() {
                got.push((c.header.seq, c.tau[0]));
            }
            let want: Vec<_> = (1..40).map(|seq| (seq, seq as f64 * 0.5)).collect();
            assert_eq!(got, want);
        }
        let rest = remove_global_mgmt(&prefix);
        assert!(rest.is_empty(), "files left behind: {rest:?}");
    }
}
