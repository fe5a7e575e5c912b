//! What a joint state is worth before the law sees it: validation, the
//! gravity agreement and the sequence of the driver's stream.
//!
//! A state that fails validation (schema, joint count, NaN/Inf, unknown
//! status or flags) or disagrees with the controller about who adds gravity
//! (`hcc_msgs::check_gravity_agreement`: exactly one side adds g(q)) is
//! [`Verdict::Invalid`]. A well-formed state goes through the
//! [`SequenceChecker`]: the next one, or a gap the driver can have made in
//! the time elapsed ([`max_plausible_gap`]), is used; a duplicate is not
//! answered again; one that goes backwards or jumps further ahead is
//! [`Verdict::OutOfSequence`].
//!
//! **A new peer.** When states come back after an outage (the cycle says so
//! with `resumed`), a state that continues the old sequence (the same driver
//! after a stall) is used as is, while one that does not (a restarted driver
//! counts from 0) starts a new stream; without an outage, [`RESYNC_RUN`]
//! consecutive rejected states that follow each other (a driver restarted
//! within the stale timeout) do the same. A new stream is used at once and
//! flagged ([`Verdict::Use`] with `new_peer`), so that the cycle forgets
//! what it knew of the old peer.

use hcc_msgs::{JointState, SeqEvent, SequenceChecker};

/// Consecutive rejected sequence numbers (backwards or implausible jumps)
/// that follow each other, taken as a restarted peer.
pub const RESYNC_RUN: u32 = 3;

/// Slack of [`max_plausible_gap`], in states.
pub const GAP_SLACK: u64 = 16;

/// The largest number of states a driver publishing one state per period can
/// have skipped in `elapsed_ns`: twice the periods elapsed plus
/// [`GAP_SLACK`] (wake-up jitter, a driver running slightly fast). A larger
/// jump of the sequence number is a corrupt or foreign stream and is rejected.
pub const fn max_plausible_gap(elapsed_ns: u64, period_ns: u64) -> u64 {
    let periods = match elapsed_ns.checked_div(period_ns) {
        Some(p) => p,
        None => 0,
    };
    periods.saturating_mul(2).saturating_add(GAP_SLACK)
}

/// How a state is to be used.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Verdict {
    /// Run the law on it; `missed` states were skipped before it; `new_peer`:
    /// it starts a new stream (a restarted driver).
    Use { missed: u64, new_peer: bool },
    /// Malformed, or a gravity conflict: answer with the safe command.
    Invalid { gravity_conflict: bool },
    /// Backwards or implausibly far ahead: answer with the safe command.
    OutOfSequence,
    /// The state already answered: do not answer again.
    Duplicate,
}

/// The checks of the driver's stream (see the module docs).
#[derive(Debug, Clone)]
pub struct StreamCheck {
    n: usize,
    gravity_compensation: bool,
    period_ns: u64,
    checker: SequenceChecker,
    /// Consecutive rejected sequence numbers that follow each other.
    resync_run: u32,
    /// Sequence number of the last rejected state of that run.
    resync_last: u64,
    /// Wake-up time of the last state whose sequence number was accepted.
    last_accepted_ns: u64,
}

impl StreamCheck {
    /// The checks for a robot of `n` joints whose states come every
    /// `period_ns`; `gravity_compensation`: the controller adds g(q).
    pub fn new(n: usize, gravity_compensation: bool, period_ns: u64) -> StreamCheck {
        StreamCheck {
            n,
            gravity_compensation,
            period_ns,
            checker: SequenceChecker::new(),
            resync_run: 0,
            resync_last: 0,
            last_accepted_ns: 0,
        }
    }

    /// Whether `state` is well-formed for this robot (what the setpoint
    /// clock trusts).
    pub fn well_formed(&self, state: &JointState) -> bool {
        state.validate(self.n).is_ok()
    }

    /// The verdict on `state`, received at `wake_ns`; `resumed`: the first
    /// state after a peer loss. Allocation-free.
    pub fn classify(&mut self, state: &JointState, wake_ns: u64, resumed: bool) -> Verdict {
        let well_formed = self.well_formed(state);
        let gravity_conflict =
            well_formed && state.driver_compensates_gravity() == self.gravity_compensation;
        if !well_formed || gravity_conflict {
            return Verdict::Invalid { gravity_conflict };
        }
        self.sequence(state.header.seq, wake_ns, resumed)
    }

    /// Classifies the sequence number `seq` of a well-formed state.
    fn sequence(&mut self, seq: u64, wake: u64, resumed: bool) -> Verdict {
        let mut probe = self.checker;
        let event = probe.observe(seq);
        let plausible = match event {
            SeqEvent::First | SeqEvent::Next => true,
            SeqEvent::Gap { missed } => {
                missed
                    <= max_plausible_gap(wake.saturating_sub(self.last_accepted_ns), self.period_ns)
            }
            SeqEvent::Duplicate | SeqEvent::Backwards { .. } => false,
        };
        if plausible {
            self.checker = probe;
            self.resync_run = 0;
            self.last_accepted_ns = wake;
            let missed = match event {
                SeqEvent::Gap { missed } => missed,
                _ => 0,
            };
            return Verdict::Use {
                missed,
                new_peer: false,
            };
        }
        if event == SeqEvent::Duplicate && !resumed {
            return Verdict::Duplicate;
        }
        // A stream that does not continue the old one: after an outage it is
        // a new peer; otherwise only once RESYNC_RUN rejected states follow
        // each other (a restarted driver), never for a single corrupt one.
        self.resync_run = if self.resync_run > 0 && seq == self.resync_last.wrapping_add(1) {
            self.resync_run + 1
        } else {
            1
        };
        self.resync_last = seq;
        if resumed || self.resync_run >= RESYNC_RUN {
            self.checker.reset();
            self.checker.observe(seq);
            self.resync_run = 0;
            self.last_accepted_ns = wake;
            return Verdict::Use {
                missed: 0,
                new_peer: true,
            };
        }
        Verdict::OutOfSequence
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const PERIOD: u64 = 1_000_000;

    fn state(seq: u64) -> JointState {
        let mut s = JointState::zeroed();
        s.set_joints(&[0.1, 0.2], &[0.0, 0.0], &[0.0, 0.0]).unwrap();
        s.header.seq = seq;
        s
    }

    fn used(missed: u64) -> Verdict {
        Verdict::Use {
            missed,
            new_peer: false,
        }
    }

    #[test]
    fn a_gap_is_used_when_the_driver_can_have_made_it() {
        let mut c = StreamCheck::new(2, true, PERIOD);
        assert_eq!(c.classify(&state(0), 0, false), used(0));
        assert_eq!(c.classify(&state(1), PERIOD, false), used(0));
        // Three periods later: up to 2·3 + 16 states may have been skipped;
        // one period after that, 2 + 16.
        assert_eq!(c.classify(&state(24), 4 * PERIOD, false), used(22));
        assert_eq!(
            c.classify(&state(24 + 1 + 2 + 16 + 1), 5 * PERIOD, false),
            Verdict::OutOfSequence
        );
        assert_eq!(
            c.classify(&state(24), 5 * PERIOD, false),
            Verdict::Duplicate
        );
    }

    #[test]
    fn a_restarted_driver_is_a_new_peer_after_a_run_of_following_states() {
        let mut c = StreamCheck::new(2, true, PERIOD);
        for k in 0..100 {
            assert_eq!(c.classify(&state(k), k * PERIOD, false), used(0));
        }
        let t = 100 * PERIOD;
        assert_eq!(c.classify(&state(0), t, false), Verdict::OutOfSequence);
        assert_eq!(
            c.classify(&state(1), t + PERIOD, false),
            Verdict::OutOfSequence
        );
        assert_eq!(
            c.classify(&state(2), t + 2 * PERIOD, false),
            Verdict::Use {
                missed: 0,
                new_peer: true
            }
        );
        assert_eq!(c.classify(&state(3), t + 3 * PERIOD, false), used(0));
        // After an outage, the first state that does not continue is a new peer.
        assert_eq!(
            c.classify(&state(0), t + 90 * PERIOD, true),
            Verdict::Use {
                missed: 0,
                new_peer: true
            }
        );
    }

    #[test]
    fn malformed_states_and_gravity_conflicts_are_invalid() {
        let mut c = StreamCheck::new(2, true, PERIOD);
        let mut nan = state(0);
        nan.q[1] = f64::NAN;
        assert_eq!(
            c.classify(&nan, 0, false),
            Verdict::Invalid {
                gravity_conflict: false
            }
        );
        let mut both = state(0);
        both.flags |= hcc_msgs::STATE_FLAG_DRIVER_GRAVITY_COMPENSATION;
        assert_eq!(
            c.classify(&both, 0, false),
            Verdict::Invalid {
                gravity_conflict: true
            }
        );
        assert!(!c.well_formed(&nan) && c.well_formed(&both));
    }
}
