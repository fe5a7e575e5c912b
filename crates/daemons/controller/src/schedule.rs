//! A scenario's `[[setpoint]]` schedule applied to an in-process law through
//! the same [`Commander`] the daemon uses: at cycle k every setpoint whose
//! cycle ([`ScheduledSetpoint::cycle`]) is k is taken, then the transitions
//! advance by one period, then the law steps — the daemon's order (setpoints
//! received before the decision, [`Commander::advance`] before
//! `Controller::step`), so `hcc simulate` and a lockstep `hcc run` that
//! delivers each setpoint before its cycle's state agree.

use hcc_config::Scenario;
use hcc_config::schedule::ScheduledSetpoint;
use hcc_control::Controller;
use hcc_msgs::{ANSWER_ACCEPTED, Rejection};

use crate::commander::Commander;
use crate::cycle::{CycleError, CycleSettings};

/// The schedule and the commander that applies it.
pub struct Schedule {
    commander: Commander,
    entries: Vec<(u64, ScheduledSetpoint)>,
    next: usize,
    dt: f64,
}

impl Schedule {
    /// The schedule of `scenario` for `controller` (its initial goals and gains).
    pub fn new(controller: &Controller, scenario: &Scenario) -> Result<Schedule, CycleError> {
        let settings = CycleSettings::from_scenario(scenario);
        let rate = scenario.simulation.control_rate_hz;
        Ok(Schedule {
            commander: Commander::new(controller, &scenario.commanding)?,
            entries: scenario
                .setpoints
                .iter()
                .map(|s| (s.cycle(rate), *s))
                .collect(),
            next: 0,
            dt: settings.period_ns as f64 * 1e-9,
        })
    }

    /// Before the step of cycle `k`: takes the setpoints due, advances the
    /// transitions. A setpoint the controller rejects is an error naming it.
    pub fn before_step(&mut self, k: u64, controller: &mut Controller) -> Result<(), String> {
        while let Some((cycle, entry)) = self.entries.get(self.next) {
            if *cycle > k {
                break;
            }
            self.next += 1;
            let code = self.commander.take(&entry.setpoint);
            if code != ANSWER_ACCEPTED {
                let reason = Rejection::from_code(code).map_or("unknown code", |r| r.reason());
                return Err(format!(
                    "the scheduled setpoint at t = {} s for level {} was rejected: {reason}",
                    entry.t_s,
                    entry.setpoint.level + 1
                ));
            }
        }
        self.commander.advance(self.dt, controller);
        Ok(())
    }
}
