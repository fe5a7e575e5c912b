//! The cycle's part of the paths sent at run time: a client's path
//! messages taken in the cycle of their state, at once or through the
//! feasibility check's gate (crate modules `paths`, `path_gate`,
//! `path_check`; docs/tracking.md).

use hcc_msgs::JointState;
use hcc_msgs::{KnotsRefusal, NO_KNOT, PathKnots, PathRejection, ipc::SETPOINT_BUFFER};

use super::ControlCycle;
use crate::path_check::PathChecker;
use crate::path_gate::{PathCheckWorker, PathGate, Turn};

impl ControlCycle {
    /// Takes a client's path knots ([`PathKnots`], docs/tracking.md) in the
    /// cycle of the last well-formed state: checked against the level,
    /// starting or extending its path, answered in the client's slot like a
    /// setpoint. Returns the answer code. Allocation-free.
    pub fn take_path(&mut self, knots: &PathKnots) -> u32 {
        let code = self.paths.take(
            knots,
            self.clock_seq,
            &mut self.controller,
            &mut self.setpoints,
        );
        self.setpoints.fill(&mut self.telemetry);
        code
    }

    /// [`ControlCycle::take_paths`] in the cycle of `state` (its sequence
    /// number, when well-formed, times a new path's start as
    /// [`ControlCycle::take_setpoints`] does): what a replay does with the
    /// path messages a recording says were taken in a cycle.
    pub fn take_paths_at(
        &mut self,
        state: &JointState,
        next_knots: impl FnMut() -> Option<PathKnots>,
    ) {
        if self.stream.well_formed(state) {
            self.clock_seq = state.header.seq;
            if let Some(gate) = self.gate.as_mut() {
                gate.note_q(state.q());
            }
        }
        self.take_paths(next_knots);
    }

    /// Takes every path message `next_knots` yields (at most
    /// [`SETPOINT_BUFFER`]), as [`ControlCycle::take_path`] does, and writes
    /// the answers into the telemetry once. What the controller daemon calls
    /// each cycle after [`ControlCycle::take_setpoints`]. Allocation-free.
    pub fn take_paths(&mut self, mut next_knots: impl FnMut() -> Option<PathKnots>) {
        if self.gate.is_some() {
            self.take_paths_checked(next_knots);
            return;
        }
        let mut taken = false;
        for _ in 0..SETPOINT_BUFFER {
            let Some(knots) = next_knots() else {
                break;
            };
            self.paths.take(
                &knots,
                self.clock_seq,
                &mut self.controller,
                &mut self.setpoints,
            );
            taken = true;
        }
        if taken {
            self.setpoints.fill(&mut self.telemetry);
        }
    }

    /// [`ControlCycle::take_paths`] with the feasibility check (module
    /// `path_gate`): the verdicts that came in, the new messages handed to
    /// the worker, then the messages whose turn has come, in arrival order.
    fn take_paths_checked(&mut self, mut next_knots: impl FnMut() -> Option<PathKnots>) {
        let Some(gate) = self.gate.as_mut() else {
            return;
        };
        let setpoints = &mut self.setpoints;
        let core = &mut self.counters.core;
        let mut answered = false;
        gate.begin_cycle();
        for _ in 0..SETPOINT_BUFFER {
            let Some(knots) = next_knots() else {
                break;
            };
            let prechecked = self.paths.precheck(&knots, setpoints).is_ok();
            if !gate.submit(&knots, prechecked, |i| setpoints.equilibrium(i)) {
                let code = (PathRejection::Unchecked.code(), NO_KNOT);
                setpoints.record_answer(knots.client_id, knots.header.seq, knots.level, code);
                core.paths_unchecked += 1;
                answered = true;
            }
        }
        while let Some(turn) = gate.next() {
            answered = true;
            match turn {
                Turn::Take(knots) => {
                    self.paths
                        .take(&knots, self.clock_seq, &mut self.controller, setpoints);
                }
                Turn::Setpoint(setpoint) => {
                    setpoints.receive(&setpoint, self.clock_seq, &mut self.controller);
                }
                Turn::Refuse(knots, refusal) => {
                    let code = (refusal.code(), refusal.knot_field());
                    setpoints.record_answer(knots.client_id, knots.header.seq, knots.level, code);
                    if refusal.code() == PathRejection::Infeasible.code() {
                        core.paths_infeasible += 1;
                    } else {
                        core.paths_unchecked += 1;
                    }
                    // The last answer its client sees in this cycle.
                    break;
                }
            }
        }
        if answered {
            setpoints.fill(&mut self.telemetry);
        }
    }

    /// From now on, the path messages [`ControlCycle::take_paths`] takes
    /// wait for a feasibility check (module `path_gate`): returns the worker
    /// that checks them, to run on a thread of its own
    /// ([`PathCheckWorker::run_pending`]). Allocates (start-up only).
    pub fn check_paths_at_run_time(&mut self) -> PathCheckWorker {
        let checker = PathChecker::new(
            &self.controller,
            self.path_knots,
            crate::feasibility::ROLLOUT_STEP_S,
        );
        let timeout_cycles = (self.path_check_timeout_s / self.period_s).ceil() as u64;
        let (gate, worker) = PathGate::new(checker, timeout_cycles);
        self.gate = Some(gate);
        worker
    }

    /// Refuses a client's path message as `refusal` without taking it: what
    /// a replay does with a message the recording says the feasibility
    /// check refused.
    pub fn refuse_path(&mut self, knots: &PathKnots, refusal: KnotsRefusal) {
        let code = (refusal.code(), refusal.knot_field());
        self.setpoints
            .record_answer(knots.client_id, knots.header.seq, knots.level, code);
        self.setpoints.fill(&mut self.telemetry);
    }

    /// Path messages (and setpoints behind them) waiting for their
    /// feasibility check.
    pub fn paths_in_check(&self) -> usize {
        self.gate.as_ref().map_or(0, PathGate::len)
    }
}
