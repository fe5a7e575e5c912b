//! The in-process closed loop (see the crate docs).

use hcc_config::Scenario;
use hcc_cycle::{Answer, ControlCycle, CycleSettings, Schedule};
use hcc_msgs::{CommandMode, JointState, TelemetryTimings};
use hcc_plant::{SimDriver, SimError};
use hcc_record::{Cycle, LawTerms, RecordError, WithWrench};
use hcc_report::{RunDescription, Trajectory};

use crate::energy::recorder;

/// Result of a simulation: the trajectory table and what the report needs to know.
#[derive(Clone, Debug)]
pub struct Run {
    pub trajectory: Trajectory,
    pub description: RunDescription,
}

/// One cycle of an in-process run, as an observer sees it once the command
/// is decided (before it is applied).
pub struct CycleView<'a> {
    /// The cycle index k (the state's sequence number).
    pub k: u64,
    /// Its time t_k = k T, s.
    pub t: f64,
    /// The state the driver published.
    pub state: &'a JointState,
    /// The control cycle after its step: the command, the telemetry sample,
    /// the law (its output and terms at this state).
    pub cycle: &'a ControlCycle,
}

/// Runs the closed loop of `scenario`: the simulated driver and the control
/// cycle, exchanging messages by function call (crate docs).
pub fn simulate(scenario: &Scenario) -> Result<Run, SimError> {
    simulate_observed(scenario, &mut |_| Ok(()))
}

/// [`simulate`], calling `observe` in every cycle once its command is decided
/// (e.g. to record the cycle's messages, or to log the law's terms).
pub fn simulate_observed(
    scenario: &Scenario,
    observe: &mut dyn FnMut(&CycleView<'_>) -> Result<(), SimError>,
) -> Result<Run, SimError> {
    let mut recorder = recorder(scenario)?;
    let mut trajectory = recorder
        .trajectory(scenario.cycles() as usize + 1)
        .map_err(record_error)?;
    let description = run_observed(scenario, &mut |view| {
        observe(view)?;
        let law_ran = view.cycle.command().mode != CommandMode::SafeHold.code();
        let output = WithWrench {
            output: view.cycle.telemetry(),
            wrench: view.cycle.external_wrench(),
        };
        let row = Cycle {
            t: view.t,
            q: view.state.q(),
            qd: view.state.qd(),
            output: &output,
            law: law_ran.then_some(view.cycle.controller() as &dyn LawTerms),
        };
        recorder.record(&row, &mut trajectory).map_err(record_error)
    })?;
    Ok(Run {
        trajectory,
        description,
    })
}

/// The closed loop of `scenario` without the trajectory rows: `observe` sees
/// every cycle (a sweep of many long runs that only needs a few figures of
/// each). Returns the run's description.
pub fn run_observed(
    scenario: &Scenario,
    observe: &mut dyn FnMut(&CycleView<'_>) -> Result<(), SimError>,
) -> Result<RunDescription, SimError> {
    let mut run = InProcess::new(scenario)?;
    let cycles = scenario.cycles();
    for k in 0..=cycles {
        let t = run.cycle(k, k == cycles)?;
        observe(&CycleView {
            k,
            t,
            state: &run.state,
            cycle: &run.cycle,
        })?;
        if k < cycles {
            run.driver.advance(Some(run.cycle.command()))?;
        }
    }
    Ok(run.describe(scenario))
}

fn record_error(e: RecordError) -> SimError {
    SimError::Invalid(e.to_string())
}

/// The two ends and what passes between them.
struct InProcess {
    driver: SimDriver,
    cycle: ControlCycle,
    schedule: Schedule,
    state: JointState,
    period_ns: u64,
    period_s: f64,
}

impl InProcess {
    fn new(scenario: &Scenario) -> Result<InProcess, SimError> {
        let invalid = |e: String| SimError::Invalid(e);
        let controller = hcc_cycle::controller_for(scenario).map_err(|e| invalid(e.to_string()))?;
        let settings = CycleSettings::from_scenario(scenario);
        let cycle = ControlCycle::new(controller, &settings).map_err(|e| invalid(e.to_string()))?;
        Ok(InProcess {
            driver: SimDriver::new(scenario)?,
            cycle,
            schedule: Schedule::new(scenario),
            state: JointState::zeroed(),
            period_ns: settings.period_ns,
            period_s: scenario.period_s(),
        })
    }

    /// Cycle k: the driver publishes state k (with status `Stopped` when
    /// `last`, as `hcc-sim` publishes its final state), the control cycle
    /// answers it with the setpoints due. Returns t_k.
    fn cycle(&mut self, k: u64, last: bool) -> Result<f64, SimError> {
        let t = k as f64 * self.period_s;
        // The daemons' clocks, simulated: state k published at k T.
        let stamp = k * self.period_ns;
        if last {
            self.driver.set_stopped();
        }
        self.driver.write_state(&mut self.state, stamp);
        let schedule = &mut self.schedule;
        let answer = self.cycle.step(&self.state, stamp, || schedule.due(k));
        self.schedule
            .check(self.cycle.telemetry())
            .map_err(SimError::Invalid)?;
        if answer == Answer::Duplicate {
            return Err(SimError::Invalid(format!(
                "t = {t} s: the control cycle took state {k} for a duplicate"
            )));
        }
        self.cycle.stamp_command(stamp);
        self.cycle
            .finish_telemetry(0, TelemetryTimings::default(), stamp);
        Ok(t)
    }

    /// The run's description: the scenario's, and what the cycle, its
    /// safety layer and the plant's end stops counted (only what happened).
    fn describe(&self, scenario: &Scenario) -> RunDescription {
        let mut description = hcc_record::describe(scenario);
        let c = self.cycle.counters();
        description.settings.insert(
            "saturated_cycles".into(),
            serde_json::json!(c.telemetry.saturations),
        );
        let safety = &self.cycle.controller().output().safety;
        let stops = self.driver.plant().end_stops();
        for (key, value) in [
            ("rate_limited_cycles", c.telemetry.rate_limited),
            ("velocity_corrected_cycles", c.telemetry.velocity_limited),
            ("numerical_failures", c.core.numerical_failures),
            ("joint_limit_guard_cycles", safety.joint_limit_cycles),
            ("velocity_limit_cycles", safety.velocity_limit_cycles),
            ("spring_saturation_cycles", safety.spring_saturated_cycles),
            ("conflict_fade_cycles", safety.conflict_fade_cycles),
            ("passivity_damping_cycles", safety.passivity_cycles),
            ("end_stop_contacts", stops.contacts()),
            ("end_stop_steps", stops.contact_steps()),
            (
                "velocity_limit_violation_steps",
                stops.velocity_violation_steps(),
            ),
        ] {
            if value > 0 {
                description.settings.insert(key.into(), value.into());
            }
        }
        description
    }
}
