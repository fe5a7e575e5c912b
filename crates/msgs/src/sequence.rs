//! Sequence-number bookkeeping: [`SequenceChecker`] and [`command_freshness`].
//!
//! Both are allocation-free and `Copy`, for use in the control loop.

use crate::error::MsgError;

/// Classification of a received sequence number relative to the last accepted one.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum SeqEvent {
    /// First sample since construction or [`SequenceChecker::reset`]; accepted.
    First,
    /// Exactly last + 1; accepted.
    Next,
    /// `missed` sequence numbers were skipped (seq = last + 1 + missed); accepted.
    Gap { missed: u64 },
    /// Same as the last accepted one; rejected (the state is not advanced).
    Duplicate,
    /// Smaller than the last accepted one by `by`; rejected (the state is not
    /// advanced). Repeated Backwards events usually mean the peer restarted:
    /// the caller may then [`SequenceChecker::reset`].
    Backwards { by: u64 },
}

impl SeqEvent {
    /// Whether the sample should be used (First, Next, Gap).
    pub const fn is_accepted(self) -> bool {
        matches!(self, Self::First | Self::Next | Self::Gap { .. })
    }

    /// Converts a rejection into an error naming the message; `Ok(missed)`
    /// (0 for First/Next) when accepted. `seq` is the received number.
    pub const fn to_result(self, msg: &'static str, seq: u64) -> Result<u64, MsgError> {
        match self {
            Self::First | Self::Next => Ok(0),
            Self::Gap { missed } => Ok(missed),
            Self::Duplicate => Err(MsgError::DuplicateSequence { msg, seq }),
            Self::Backwards { by } => Err(MsgError::SequenceBackwards {
                msg,
                seq,
                last: seq.wrapping_add(by),
            }),
        }
    }
}

/// State machine over a stream's sequence numbers, with running totals.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct SequenceChecker {
    last: Option<u64>,
    accepted: u64,
    missed: u64,
    duplicates: u64,
    backwards: u64,
    restarts: u64,
}

impl SequenceChecker {
    /// A checker that has seen nothing.
    pub const fn new() -> Self {
        Self {
            last: None,
            accepted: 0,
            missed: 0,
            duplicates: 0,
            backwards: 0,
            restarts: 0,
        }
    }

    /// Classifies `seq`; advances the last accepted number on First/Next/Gap.
    pub fn observe(&mut self, seq: u64) -> SeqEvent {
        let event = match self.last {
            None => SeqEvent::First,
            Some(last) if seq == last => SeqEvent::Duplicate,
            Some(last) if seq < last => SeqEvent::Backwards { by: last - seq },
            Some(last) if seq == last.wrapping_add(1) => SeqEvent::Next,
            // seq > last + 1 here, so the subtraction cannot underflow.
            Some(last) => SeqEvent::Gap {
                missed: seq - last - 1,
            },
        };
        match event {
            SeqEvent::First | SeqEvent::Next => {
                self.last = Some(seq);
                self.accepted += 1;
            }
            SeqEvent::Gap { missed } => {
                self.last = Some(seq);
                self.accepted += 1;
                self.missed = self.missed.saturating_add(missed);
            }
            SeqEvent::Duplicate => self.duplicates += 1,
            SeqEvent::Backwards { .. } => self.backwards += 1,
        }
        event
    }

    /// [`SequenceChecker::observe`] for a stream whose publisher may be
    /// replaced by a new one (a restarted daemon) while one publisher's
    /// numbers only grow: a number below the last starts the stream again
    /// from it — counted in [`SequenceChecker::restarts`], not in
    /// `backwards`, and returned as `First`.
    pub fn observe_restarting(&mut self, seq: u64) -> SeqEvent {
        match self.observe(seq) {
            SeqEvent::Backwards { .. } => {
                self.backwards -= 1;
                self.restarts += 1;
                self.last = None;
                self.observe(seq)
            }
            e => e,
        }
    }

    /// Forgets the last number (keeps the totals): the next one is `First`.
    pub fn reset(&mut self) {
        self.last = None;
    }

    /// Last accepted sequence number.
    pub const fn last(&self) -> Option<u64> {
        self.last
    }

    /// Accepted samples.
    pub const fn accepted(&self) -> u64 {
        self.accepted
    }

    /// Sum of all gaps.
    pub const fn missed(&self) -> u64 {
        self.missed
    }

    /// Duplicates seen.
    pub const fn duplicates(&self) -> u64 {
        self.duplicates
    }

    /// Backwards steps seen.
    pub const fn backwards(&self) -> u64 {
        self.backwards
    }

    /// Restarts seen by [`SequenceChecker::observe_restarting`].
    pub const fn restarts(&self) -> u64 {
        self.restarts
    }
}

/// How a command relates to the driver's latest published state.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum CommandFreshness {
    /// The command answers the latest state.
    Current,
    /// The command answers a state `cycles` cycles older than the latest.
    Late { cycles: u64 },
    /// The command claims to answer a state that was never published
    /// (peer confusion or restart): never apply.
    Future,
}

/// Compares a command's echoed `state_seq` with the driver's latest state
/// `seq`. A driver applies `Current` commands, and `Late` ones only up to
/// its configured tolerance (see the crate docs' timing contract).
pub const fn command_freshness(command_state_seq: u64, latest_state_seq: u64) -> CommandFreshness {
    if command_state_seq == latest_state_seq {
        CommandFreshness::Current
    } else if command_state_seq < latest_state_seq {
        CommandFreshness::Late {
            cycles: latest_state_seq - command_state_seq,
        }
    } else {
        CommandFreshness::Future
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_restarted_publisher_starts_the_stream_again() {
        let mut c = SequenceChecker::new();
        for seq in [5, 6, 8] {
            assert!(c.observe_restarting(seq).is_accepted());
        }
        assert_eq!(c.observe_restarting(8), SeqEvent::Duplicate);
        // A new publisher numbering from 1: First, then followed from there.
        assert_eq!(c.observe_restarting(1), SeqEvent::First);
        assert_eq!(c.observe_restarting(2), SeqEvent::Next);
        assert_eq!(c.observe_restarting(4), SeqEvent::Gap { missed: 1 });
        assert_eq!((c.restarts(), c.backwards()), (1, 0));
        assert_eq!((c.missed(), c.duplicates(), c.accepted()), (2, 1, 6));
        assert_eq!(c.last(), Some(4));
    }

    #[test]
    fn next_gap_duplicate_backwards() {
        let mut c = SequenceChecker::new();
        assert_eq!(c.observe(10), SeqEvent::First);
        assert_eq!(c.observe(11), SeqEvent::Next);
        assert_eq!(c.observe(11), SeqEvent::Duplicate);
        assert_eq!(c.observe(15), SeqEvent::Gap { missed: 3 });
        assert_eq!(c.observe(12), SeqEvent::Backwards { by: 3 });
        // A rejected sample does not advance the state.
        assert_eq!(c.last(), Some(15));
        assert_eq!(c.observe(16), SeqEvent::Next);
        assert_eq!(
            (c.accepted(), c.missed(), c.duplicates(), c.backwards()),
            (4, 3, 1, 1)
        );
    }

    #[test]
    fn reset_resynchronises_after_peer_restart() {
        let mut c = SequenceChecker::new();
        c.observe(1000);
        assert!(!c.observe(0).is_accepted());
        c.reset();
        assert_eq!(c.observe(0), SeqEvent::First);
        assert_eq!(c.observe(1), SeqEvent::Next);
    }

    #[test]
    fn extremes_do_not_overflow() {
        let mut c = SequenceChecker::new();
        c.observe(0);
        assert_eq!(
            c.observe(u64::MAX),
            SeqEvent::Gap {
                missed: u64::MAX - 1
            }
        );
        assert_eq!(c.observe(0), SeqEvent::Backwards { by: u64::MAX });
        assert_eq!(c.observe(u64::MAX), SeqEvent::Duplicate);
    }

    #[test]
    fn to_result_names_the_message() {
        let e = SeqEvent::Backwards { by: 2 }.to_result("joint_state", 5);
        assert_eq!(
            e,
            Err(MsgError::SequenceBackwards {
                msg: "joint_state",
                seq: 5,
                last: 7
            })
        );
        let text = e.unwrap_err().to_string();
        assert!(text.contains("joint_state.header.seq = 5"), "{text}");
        assert_eq!(SeqEvent::Gap { missed: 4 }.to_result("x", 9), Ok(4));
        assert!(SeqEvent::Duplicate.to_result("x", 9).is_err());
    }

    #[test]
    fn freshness() {
        assert_eq!(command_freshness(7, 7), CommandFreshness::Current);
        assert_eq!(
            command_freshness(5, 7),
            CommandFreshness::Late { cycles: 2 }
        );
        assert_eq!(command_freshness(8, 7), CommandFreshness::Future);
    }
}
