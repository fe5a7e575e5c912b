//! The cache warm-up of the hybrid wait: shortly before the next state is
//! expected, a copy of the law (its twin) steps on the last state, so that
//! the law's code is in the caches and its branches in the predictors when
//! the state comes. Nothing of it reaches a command; its data is its own.
//!
//! When it runs ([`warm_up_turn`]): [`WarmUpLead::ns`] before the expected
//! state, late enough that nothing cools the caches again before the state,
//! early enough that the step is over when it comes; not once the state is
//! due; never for a law whose step takes more than a third of the spin. How
//! well that works is measured: every warm-up is timed, and those still
//! running when their state was published are counted ([`WarmUpOverlaps`]).

use hcc_control::Controller;
use hcc_msgs::{JointState, monotonic_now_ns};
use hcc_timing::LatencyHistogram;

/// What the cache warm-up's lead before the expected state is made of.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct WarmUpLead {
    /// The law's last step, ns.
    pub step_ns: u64,
    /// The warm-ups' recent peak duration ([`DecayingPeak`]; 0 before the first), ns.
    pub warm_up_ns: u64,
    /// How much earlier than expected states came lately ([`DecayingPeak`]), ns.
    pub early_ns: u64,
}

impl WarmUpLead {
    /// How long before the expected state the warm-up starts: 1.5 times its
    /// recent peak duration (a warm-up's step is slower than the answering
    /// one, its caches being the cold ones: 1.5–1.8 times here) but at least
    /// three steps (before the first warm-up) and at least 25 µs (the
    /// Panda's step is 3–4 µs), plus how much earlier than expected states
    /// came lately (a driver's stamps move with what it computes before
    /// them) — so that the warm-up is over when the state comes. Not earlier
    /// than needed: at the start of the 150 µs spin the law in the loop
    /// still took 5.2–5.6 µs at the median against 3.5–3.7 µs when warmed
    /// 15–30 µs before the state (README, timing section).
    pub fn ns(&self) -> u64 {
        let own = self.warm_up_ns + self.warm_up_ns / 2;
        (3 * self.step_ns)
            .max(WARM_UP_MIN_LEAD_NS)
            .max(own)
            .saturating_add(self.early_ns)
    }
}

/// A recent peak: follows a larger value at once and decays by 1/64 per
/// value noted (to half in about 44), so that it sits near the top of what
/// the last few hundred values were.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct DecayingPeak(u64);

impl DecayingPeak {
    /// Notes `value`, counted as at most `cap` (one value far out, such as
    /// a step stalled by the host, must not hold the peak up for long).
    pub fn note(&mut self, value: u64, cap: u64) {
        self.0 = value.min(cap).max(self.0 - self.0 / 64);
    }

    /// The peak (0 before the first value).
    pub fn get(self) -> u64 {
        self.0
    }
}

/// The shortest lead of the cache warm-up before the expected state, ns.
pub const WARM_UP_MIN_LEAD_NS: u64 = 25_000;

/// What the hybrid spin does about the cache warm-up at one of its turns.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum WarmUpTurn {
    /// Too early: look again at the next turn of the spin.
    NotYet,
    /// Warm up now (once in this wait).
    Run,
    /// No warm-up in this wait: the state is due or overdue (a step now would
    /// delay its answer), or the law's step is too long for the spin.
    Skip,
}

/// The cache warm-up's timing in a hybrid wait ([`crate::LoopSettings::warm_up`]):
/// at `now` (ns), with the next state expected at `expected` and a spin of
/// `hybrid_lead_ns` before it. It runs [`WarmUpLead::ns`] before the state
/// (from the spin's start when that is longer than the spin), not earlier
/// (what is warmed at the spin's start has cooled when the state comes) and
/// not once the state is due; never when three of the law's steps do not
/// fit in the spin.
pub fn warm_up_turn(now: u64, expected: u64, lead: WarmUpLead, hybrid_lead_ns: u64) -> WarmUpTurn {
    if 3 * lead.step_ns > hybrid_lead_ns || now >= expected {
        WarmUpTurn::Skip
    } else if now < expected.saturating_sub(lead.ns()) {
        WarmUpTurn::NotYet
    } else {
        WarmUpTurn::Run
    }
}

/// The cache warm-ups that were still running when the state they prepared
/// for was published: that state waited for them (its wake-up latency holds
/// the wait).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct WarmUpOverlaps {
    /// How many.
    pub count: u64,
    /// The longest wait they caused, ns.
    pub max_ns: u64,
}

impl WarmUpOverlaps {
    /// Notes a warm-up that ended at `end_ns` before a state stamped `stamp_ns`
    /// (the same clock); an overlap when the state came first.
    pub fn note(&mut self, end_ns: u64, stamp_ns: u64) {
        if stamp_ns != 0 && stamp_ns < end_ns {
            self.count += 1;
            self.max_ns = self.max_ns.max(end_ns - stamp_ns);
        }
    }
}

/// The warm-up's state in the loop: the twin, whether it ran in this wait,
/// and what the lead follows.
pub struct WarmUp {
    /// The law's twin (`None`: the warm-up is off).
    twin: Option<Box<Controller>>,
    /// The warm-up ran (or was skipped) in this wait.
    done: bool,
    /// Warm-ups run since start-up.
    count: u64,
    /// The warm-ups' recent peak duration (their lead follows it), ns.
    peak: DecayingPeak,
    /// How much earlier than expected the states came lately, ns.
    early: DecayingPeak,
    /// When the hybrid wait expects the next state (0: no expectation), ns.
    expected_ns: u64,
    /// The lead of the last warm-up, ns.
    last_lead_ns: u64,
    /// When this wait's warm-up ended (0: none in this wait), ns.
    end_ns: u64,
    /// Warm-ups that were still running when their state was published.
    overlaps: WarmUpOverlaps,
}

impl WarmUp {
    /// The warm-up of `controller` (a twin is cloned now), or none when `on` is false.
    pub fn new(controller: &Controller, on: bool) -> WarmUp {
        WarmUp {
            twin: on.then(|| Box::new(controller.clone())),
            done: false,
            count: 0,
            peak: DecayingPeak::default(),
            early: DecayingPeak::default(),
            expected_ns: 0,
            last_lead_ns: 0,
            end_ns: 0,
            overlaps: WarmUpOverlaps::default(),
        }
    }

    /// The hybrid wait expects the next state at `expected_ns`.
    pub fn expect(&mut self, expected_ns: u64) {
        self.expected_ns = expected_ns;
    }

    /// A turn of the hybrid spin at `now` before the state expected at
    /// `expected` (ns), a spin of `spin_ns`: runs the twin on `last` (the
    /// last state the law ran on; `step_ns` its step's duration, `None` if
    /// the law did not run) when [`warm_up_turn`] says so, once per wait,
    /// and times it into `timing`. Allocation-free.
    pub fn turn(
        &mut self,
        now: u64,
        expected: u64,
        spin_ns: u64,
        last: (&JointState, Option<u64>),
        timing: &mut LatencyHistogram,
    ) {
        let (state, step_ns) = last;
        let (Some(twin), Some(step_ns), false) = (self.twin.as_deref_mut(), step_ns, self.done)
        else {
            return;
        };
        let lead = WarmUpLead {
            step_ns,
            warm_up_ns: self.peak.get(),
            early_ns: self.early.get(),
        };
        match warm_up_turn(now, expected, lead, spin_ns) {
            WarmUpTurn::NotYet => {}
            WarmUpTurn::Skip => self.done = true,
            WarmUpTurn::Run => {
                self.done = true;
                let _ = twin.step(state.q(), state.qd());
                self.count += 1;
                let end = monotonic_now_ns();
                let took = end.saturating_sub(now);
                timing.record(took);
                self.peak.note(took, spin_ns);
                self.last_lead_ns = lead.ns();
                self.end_ns = end;
            }
        }
    }

    /// A state stamped `stamp_ns` arrived: notes how early it came against
    /// the expectation (the lead follows it, capped at `spin_ns`) and whether
    /// this wait's warm-up was still running then; the next wait may warm up
    /// again.
    pub fn arrival(&mut self, stamp_ns: u64, spin_ns: u64) {
        if self.expected_ns != 0 && stamp_ns != 0 {
            let early = self.expected_ns.saturating_sub(stamp_ns);
            self.early.note(early, spin_ns);
        }
        if self.end_ns != 0 {
            self.overlaps.note(self.end_ns, stamp_ns);
        }
        self.expected_ns = 0;
        self.end_ns = 0;
        self.done = false;
    }

    /// Warm-ups run so far.
    pub fn count(&self) -> u64 {
        self.count
    }

    /// The warm-ups that ran into their state's publication.
    pub fn overlaps(&self) -> WarmUpOverlaps {
        self.overlaps
    }

    /// How long before its state the last warm-up was due to start
    /// ([`WarmUpLead::ns`]; 0 before the first), ns.
    pub fn last_lead_ns(&self) -> u64 {
        self.last_lead_ns
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const LEAD: u64 = 150_000;

    /// The lead of a law whose last step took `step_ns`, before any warm-up.
    fn first(step_ns: u64) -> WarmUpLead {
        WarmUpLead {
            step_ns,
            ..WarmUpLead::default()
        }
    }

    #[test]
    fn warm_up_lead_is_three_steps_and_at_least_25_us_before_the_first_warm_up() {
        assert_eq!(first(3_500).ns(), WARM_UP_MIN_LEAD_NS);
        assert_eq!(first(8_333).ns(), WARM_UP_MIN_LEAD_NS);
        assert_eq!(first(10_000).ns(), 30_000);
        assert_eq!(first(50_000).ns(), 150_000);
    }

    #[test]
    fn warm_up_lead_covers_its_own_duration_and_early_states() {
        // Warm-ups of up to 22 µs lately: 33 µs (1.5 times), more than 25 µs.
        let slow = WarmUpLead {
            step_ns: 3_500,
            warm_up_ns: 22_000,
            early_ns: 0,
        };
        assert_eq!(slow.ns(), 33_000);
        // Short warm-ups: the 25 µs floor, or three steps when longer.
        let quick = WarmUpLead {
            warm_up_ns: 6_000,
            ..slow
        };
        assert_eq!(quick.ns(), WARM_UP_MIN_LEAD_NS);
        assert_eq!(
            WarmUpLead {
                step_ns: 12_000,
                ..quick
            }
            .ns(),
            36_000
        );
        // States that came up to 9 µs before their expected time: that much earlier.
        assert_eq!(
            WarmUpLead {
                early_ns: 9_000,
                ..slow
            }
            .ns(),
            42_000
        );
        assert_eq!(
            WarmUpLead {
                early_ns: 9_000,
                ..quick
            }
            .ns(),
            34_000
        );
    }

    #[test]
    fn decaying_peak_follows_a_rise_at_once_and_a_fall_slowly() {
        let mut p = DecayingPeak::default();
        assert_eq!(p.get(), 0);
        p.note(20_000, LEAD);
        assert_eq!(p.get(), 20_000);
        p.note(5_000, LEAD);
        assert_eq!(p.get(), 20_000 - 20_000 / 64);
        // About 44 smaller values halve it; it never falls below the values.
        for _ in 0..43 {
            p.note(5_000, LEAD);
        }
        assert!((9_500..=10_500).contains(&p.get()), "{}", p.get());
        for _ in 0..1_000 {
            p.note(5_000, LEAD);
        }
        assert_eq!(p.get(), 5_000);
        // A value far out counts as the cap, and is forgotten like any other.
        p.note(900_000, LEAD);
        assert_eq!(p.get(), LEAD);
        for _ in 0..200 {
            p.note(5_000, LEAD);
        }
        assert!(p.get() < 10_000, "{}", p.get());
    }

    #[test]
    fn a_warm_up_overlaps_a_state_published_before_it_ended() {
        let mut o = WarmUpOverlaps::default();
        o.note(1_000_000, 1_000_001);
        o.note(1_000_000, 1_000_000);
        assert_eq!(
            o,
            WarmUpOverlaps::default(),
            "ended before or as the state came"
        );
        o.note(1_000_000, 996_000);
        o.note(2_000_000, 1_999_000);
        assert_eq!(
            o,
            WarmUpOverlaps {
                count: 2,
                max_ns: 4_000
            }
        );
        // A state without a stamp says nothing.
        o.note(3_000_000, 0);
        assert_eq!(o.count, 2);
    }

    /// Checks [`warm_up_turn`] with a state expected at 10 ms, at each
    /// offset from it (ns), against the turn wanted there.
    fn check(lead: WarmUpLead, cases: &[(i64, WarmUpTurn)]) {
        let expected = 10_000_000u64;
        for &(offset, want) in cases {
            let now = expected.checked_add_signed(offset).unwrap();
            assert_eq!(
                warm_up_turn(now, expected, lead, LEAD),
                want,
                "{offset} ns from the state, {lead:?}"
            );
        }
    }

    use WarmUpTurn::{NotYet, Run, Skip};

    #[test]
    fn warm_up_runs_in_the_last_lead_before_the_state_only() {
        let lead = LEAD as i64;
        check(
            first(3_500),
            &[
                // The spin starts 150 µs before the state: too early to warm.
                (-lead, NotYet),
                (-25_001, NotYet),
                // From 25 µs before the state until it is due.
                (-25_000, Run),
                (-1, Run),
                // Due or overdue: a step now would delay the answer.
                (0, Skip),
                (40_000, Skip),
            ],
        );
    }

    #[test]
    fn warm_up_moves_earlier_with_slow_warm_ups_and_early_states() {
        let lead = WarmUpLead {
            step_ns: 3_500,
            warm_up_ns: 20_000,
            early_ns: 10_000,
        };
        check(lead, &[(-40_001, NotYet), (-40_000, Run)]);
        // A lead longer than the spin: from the spin's start, never skipped
        // for it (only a long step of the law skips the warm-up).
        let stalled = WarmUpLead {
            warm_up_ns: LEAD,
            ..lead
        };
        check(stalled, &[(-(LEAD as i64), Run)]);
    }

    #[test]
    fn warm_up_of_a_long_step_starts_three_steps_before_or_not_at_all() {
        let spin = LEAD as i64;
        // 20 µs steps: 60 µs before the state.
        check(first(20_000), &[(-60_001, NotYet), (-60_000, Run)]);
        // Three steps fill the spin exactly: still warmed, from its start.
        check(first(50_000), &[(-spin, Run)]);
        // Longer: never (the step would still run when the state comes).
        check(first(50_001), &[(-spin, Skip), (-1_000, Skip)]);
    }

    #[test]
    fn warm_up_near_the_clock_origin_does_not_underflow() {
        assert_eq!(warm_up_turn(0, 10_000, first(3_500), LEAD), WarmUpTurn::Run);
        assert_eq!(
            warm_up_turn(10_000, 10_000, first(3_500), LEAD),
            WarmUpTurn::Skip
        );
        let far = WarmUpLead {
            step_ns: 3_500,
            warm_up_ns: u64::MAX / 2,
            early_ns: u64::MAX,
        };
        assert_eq!(far.ns(), u64::MAX);
        assert_eq!(warm_up_turn(0, 10_000, far, LEAD), WarmUpTurn::Run);
    }
}
