//! A scenario's `[[setpoint]]` schedule delivered to a [`crate::ControlCycle`]
//! as a client delivers it over IPC: each entry is a setpoint message applied
//! at the state of its cycle ([`hcc_config::schedule::ScheduledSetpoint::message`]),
//! handed to the cycle with that state ([`Schedule::due`] as the source of
//! [`crate::ControlCycle::step`]). `hcc simulate` and a lockstep `hcc run`
//! (whose scheduler sends each entry before its cycle's state) therefore
//! take every entry in the same cycle, through the same code.

use hcc_config::Scenario;
use hcc_config::schedule::SCHEDULE_CLIENT_ID;
use hcc_msgs::{ANSWER_ACCEPTED, Setpoint, SetpointRejection, Telemetry};

/// The schedule: its messages in time order, and what was delivered.
#[derive(Debug, Clone)]
pub struct Schedule {
    messages: Vec<Setpoint>,
    /// Times (s) of the entries, for the error messages.
    times: Vec<f64>,
    next: usize,
    /// Entries delivered in the cycle of state `current`: `first..next`.
    first: usize,
    current: Option<u64>,
    /// Rejections of the schedule's client already reported.
    rejected: u32,
}

impl Schedule {
    /// The schedule of `scenario` (the entries due within its duration).
    pub fn new(scenario: &Scenario) -> Schedule {
        let messages = scenario.scheduled_messages();
        let times = scenario
            .setpoints
            .iter()
            .map(|e| e.t_s)
            .take(messages.len())
            .collect();
        Schedule {
            messages,
            times,
            next: 0,
            first: 0,
            current: None,
            rejected: 0,
        }
    }

    /// The messages, in time order.
    pub fn messages(&self) -> &[Setpoint] {
        &self.messages
    }

    /// The next entry due at or before state `k` (the source of the cycle
    /// of state `k`: call it until `None`).
    pub fn due(&mut self, k: u64) -> Option<Setpoint> {
        if self.current != Some(k) {
            self.current = Some(k);
            self.first = self.next;
        }
        let sp = *self.messages.get(self.next)?;
        if sp.apply_at_state_seq > k {
            return None;
        }
        self.next += 1;
        Some(sp)
    }

    /// After the cycle: an error naming the entry when the controller
    /// rejected one delivered in it (from the answers in `telemetry`).
    pub fn check(&mut self, telemetry: &Telemetry) -> Result<(), String> {
        let Some(answer) = telemetry
            .setpoint_answers
            .iter()
            .find(|a| a.answered > 0 && a.client_id == SCHEDULE_CLIENT_ID)
        else {
            return Ok(());
        };
        if answer.rejected <= self.rejected {
            return Ok(());
        }
        self.rejected = answer.rejected;
        let reason =
            SetpointRejection::from_code(answer.code).map_or("unknown code", |r| r.reason());
        // The answer names the last setpoint taken (its seq = 1 + its index).
        let named = (answer.seq as usize)
            .checked_sub(1)
            .filter(|&i| i < self.messages.len() && answer.code != ANSWER_ACCEPTED);
        Err(match named {
            Some(i) => format!(
                "the scheduled setpoint at t = {} s for level {} was rejected: {reason}",
                self.times[i],
                self.messages[i].level + 1
            ),
            None => format!(
                "one of the scheduled setpoints at t = {} s was rejected (the answer names only the last one taken in a cycle)",
                self.times.get(self.first).copied().unwrap_or(f64::NAN)
            ),
        })
    }
}
