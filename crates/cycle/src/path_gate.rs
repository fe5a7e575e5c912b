//! The real-time side of the run-time paths' feasibility check: path
//! messages wait here, not yet taken, while the worker (crate `path_check`)
//! rolls the hierarchy out along them.
//!
//! A path message is handed to the worker with the cycle's configuration
//! and the levels' goals through a wait-free ring, and waits in a FIFO. The
//! worker's verdicts come back through a second ring. The FIFO is taken from
//! its head, in arrival order, as far as its messages have their verdicts:
//! a feasible message goes through the cycle's own checks and is taken (or
//! refused) as any path message; an infeasible one is refused with the knot
//! (`infeasible`, 212). A message whose verdict has not come within the
//! timeout, or that found the ring or the FIFO full, is refused `unchecked`
//! (213). Both are counted. After a refusal of these two kinds no later
//! message is answered in the same cycle, so that it is the last answer its
//! client sees there (a replay reads it from the recorded telemetry).
//!
//! A client's setpoint that arrives while a path message of the same client
//! waits here waits behind it: a client's messages are answered in the
//! order it sent them (the newest command wins; a replay takes them in that
//! order). Allocation-free after [`PathGate::new`].

use std::collections::VecDeque;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::Duration;

use hcc_msgs::{KnotsRefusal, MAX_JOINTS, PathKnots, PathRejection, Setpoint};

use crate::path_check::{CheckRequest, PathChecker, Verdict};

/// Messages the gate holds at most (path messages and the setpoints that
/// wait behind them).
pub const GATE_CAPACITY: usize = 64;

/// How long the worker sleeps when no request waits (a message waits about
/// this long more for its verdict; the real-time thread never wakes it: no
/// system call in the loop).
pub const CHECK_IDLE_SLEEP: Duration = Duration::from_millis(1);

/// A message waiting for its turn.
// Both variants are large (a path's knots, a setpoint's gains): boxing one
// would allocate in the loop.
#[allow(clippy::large_enum_variant)]
pub(crate) enum Waiting {
    /// A path message and its verdict once it came (`Some(None)`: feasible).
    Path {
        knots: PathKnots,
        token: u64,
        /// The cycle it arrived in.
        since: u64,
        verdict: Option<Option<KnotsRefusal>>,
    },
    /// A client's setpoint behind its path messages.
    Setpoint(Setpoint),
}

/// What the head of the gate asks of the cycle.
#[allow(clippy::large_enum_variant)]
pub(crate) enum Turn {
    /// Take this path message (its verdict: feasible).
    Take(PathKnots),
    /// Refuse it so (and answer nothing more this cycle).
    Refuse(PathKnots, KnotsRefusal),
    /// Take this setpoint.
    Setpoint(Setpoint),
}

/// The cycle's side of the check.
pub(crate) struct PathGate {
    requests: rtrb::Producer<CheckRequest>,
    verdicts: rtrb::Consumer<Verdict>,
    waiting: VecDeque<Waiting>,
    next_token: u64,
    cycle: u64,
    timeout_cycles: u64,
    q: [f64; MAX_JOINTS],
}

/// The worker's side: its checker and the two rings' other ends.
pub struct PathCheckWorker {
    checker: PathChecker,
    requests: rtrb::Consumer<CheckRequest>,
    verdicts: rtrb::Producer<Verdict>,
}

impl PathCheckWorker {
    /// Checks every request waiting; returns how many it checked.
    pub fn run_pending(&mut self) -> usize {
        let mut checked = 0;
        while let Ok(request) = self.requests.pop() {
            let verdict = self.checker.check(&request);
            // The rings are as long as each other and the gate drains its
            // verdicts every cycle; a verdict that finds no room is lost and
            // its message refused `unchecked` at the timeout.
            let _ = self.verdicts.push(verdict);
            checked += 1;
        }
        checked
    }

    /// Checks requests as they come until `done` is set or the cycle's side
    /// is gone, sleeping [`CHECK_IDLE_SLEEP`] when there is none: the body of the
    /// worker's thread.
    pub fn run(mut self, done: &AtomicBool) {
        while !done.load(Ordering::Relaxed) && !self.abandoned() {
            if self.run_pending() == 0 {
                std::thread::sleep(CHECK_IDLE_SLEEP);
            }
        }
    }

    /// Whether the cycle's side is gone (the worker may end).
    pub fn abandoned(&self) -> bool {
        self.requests.is_abandoned()
    }
}

impl PathGate {
    /// A gate and its worker (`checker`); a verdict is waited for
    /// `timeout_cycles` cycles at most. Allocates.
    pub(crate) fn new(checker: PathChecker, timeout_cycles: u64) -> (PathGate, PathCheckWorker) {
        let (requests, worker_requests) = rtrb::RingBuffer::new(GATE_CAPACITY);
        let (worker_verdicts, verdicts) = rtrb::RingBuffer::new(GATE_CAPACITY);
        let gate = PathGate {
            requests,
            verdicts,
            waiting: VecDeque::with_capacity(GATE_CAPACITY),
            next_token: 1,
            cycle: 0,
            timeout_cycles: timeout_cycles.max(1),
            q: [0.0; MAX_JOINTS],
        };
        let worker = PathCheckWorker {
            checker,
            requests: worker_requests,
            verdicts: worker_verdicts,
        };
        (gate, worker)
    }

    /// The configuration of the cycle's state (the next requests start
    /// their rollouts there).
    pub(crate) fn note_q(&mut self, q: &[f64]) {
        let n = q.len().min(MAX_JOINTS);
        self.q[..n].copy_from_slice(&q[..n]);
    }

    /// One cycle on: the verdicts that came, written into their messages.
    pub(crate) fn begin_cycle(&mut self) {
        self.cycle += 1;
        while let Ok(v) = self.verdicts.pop() {
            let found = self.waiting.iter_mut().find_map(|w| match w {
                Waiting::Path { token, verdict, .. } if *token == v.token => Some(verdict),
                _ => None,
            });
            // A verdict for a message refused at its timeout is dropped.
            if let Some(verdict) = found {
                *verdict = Some(v.refusal);
            }
        }
    }

    /// Whether a message of `client_id` waits here.
    pub(crate) fn holds_client(&self, client_id: u64) -> bool {
        self.waiting.iter().any(|w| match w {
            Waiting::Path { knots, .. } => knots.client_id == client_id,
            Waiting::Setpoint(s) => s.client_id == client_id,
        })
    }

    /// Queues a setpoint behind its client's path messages; `false` when
    /// the gate is full.
    pub(crate) fn defer(&mut self, setpoint: &Setpoint) -> bool {
        if self.waiting.len() == GATE_CAPACITY {
            return false;
        }
        self.waiting.push_back(Waiting::Setpoint(*setpoint));
        true
    }

    /// Hands `knots` to the worker with the configuration and the levels'
    /// goals (`goal(i)`, the goal format) and queues it; `false` when the
    /// gate is full (the cycle refuses it `unchecked` at once). A message
    /// the worker's ring has no room for waits with that verdict; one that
    /// failed the cycle's `precheck` is not checked: it waits for its turn,
    /// when the cycle's checks refuse it.
    pub(crate) fn submit<'a>(
        &mut self,
        knots: &PathKnots,
        prechecked: bool,
        goal: impl Fn(usize) -> Option<&'a [f64]>,
    ) -> bool {
        if self.waiting.len() == GATE_CAPACITY {
            return false;
        }
        let token = self.next_token;
        self.next_token += 1;
        if !prechecked {
            self.waiting.push_back(Waiting::Path {
                knots: *knots,
                token,
                since: self.cycle,
                verdict: Some(None),
            });
            return true;
        }
        let mut request = CheckRequest::zeroed();
        request.token = token;
        request.knots = *knots;
        request.q = self.q;
        for (i, g) in request.goals.iter_mut().enumerate() {
            if let Some(goal) = goal(i) {
                let m = goal.len().min(g.len());
                g[..m].copy_from_slice(&goal[..m]);
            }
        }
        let verdict = match self.requests.push(request) {
            Ok(()) => None,
            Err(_) => Some(Some(KnotsRefusal::from(PathRejection::Unchecked))),
        };
        self.waiting.push_back(Waiting::Path {
            knots: *knots,
            token,
            since: self.cycle,
            verdict,
        });
        true
    }

    /// The head's turn, if it has come: a message with its verdict, one
    /// whose verdict is overdue (refused `unchecked`), or a setpoint.
    pub(crate) fn next(&mut self) -> Option<Turn> {
        let ready = match self.waiting.front()? {
            Waiting::Path {
                verdict: None,
                since,
                ..
            } => self.cycle.saturating_sub(*since) >= self.timeout_cycles,
            _ => true,
        };
        if !ready {
            return None;
        }
        Some(match self.waiting.pop_front()? {
            Waiting::Path { knots, verdict, .. } => match verdict {
                Some(None) => Turn::Take(knots),
                Some(Some(refusal)) => Turn::Refuse(knots, refusal),
                None => Turn::Refuse(knots, PathRejection::Unchecked.into()),
            },
            Waiting::Setpoint(s) => Turn::Setpoint(s),
        })
    }

    /// Messages waiting.
    pub(crate) fn len(&self) -> usize {
        self.waiting.len()
    }
}
