//! The simulated robot driver: the plant (RK4, the robot dynamics of paper
//! Eq. (1), viscous friction, external wrenches through the link Jacobian)
//! behind the driver side of the hcc-msgs contract
//! ([`hcc_msgs::driver::DriverLogic`], the same logic a real driver runs).
//! The `hcc-sim` daemon runs it over iceoryx2; `hcc simulate` runs it in
//! process, against the same control cycle.
//!
//! Per control period k the driver publishes the state (q_k, q̇_k) exactly as
//! the plant holds it, then applies a torque over [t_k, t_{k+1}] with a
//! zero-order hold ([`crate::PeriodStep`], the step of [`crate::run_zoh`]).
//!
//! Which torque ([`SimDriver::advance`]), with the simulator's
//! [`DriverSettings`] ([`SimDriver::settings`]):
//! * the newest command, if it passes [`TorqueCommand::validate`], agrees on
//!   gravity, answers state k (`Current`; no late tolerance, no sequence
//!   check: the newest command is offered again each period) and its mode
//!   applies torque;
//! * otherwise a **miss**, detected in the period whose command is missing:
//!   status `FallbackActive` from that period on (counted in `missed_commands`
//!   and `fallback_cycles`); the last applied command is held for
//!   `hold_cycles` periods, then τ = g(q_k) − D q̇_k (gravity held, strong
//!   joint damping: a braking robot) until fresh commands arrive again (e.g.
//!   from a restarted controller, which is accepted at its first command) —
//!   no timeout;
//! * before the first command ever (controller not up yet) the fallback is
//!   applied without counting misses, so the arm does not fall;
//! * a `Stop` command ends control for the session: status `Stopped` at once,
//!   fallback braking from then on ([`StopMode::Brake`]).
//!
//! When the controller does not include gravity (the scenario's
//! `gravity_compensation = false`), the simulated driver compensates gravity
//! itself like many commercial arms ([`Gravity::DriverAdds`]): it sets
//! `STATE_FLAG_DRIVER_GRAVITY_COMPENSATION` and adds g(q_k) to every command —
//! g of the robot's own model, which knows no load in the hand (as a robot
//! that was not told one): the load's gravity is the controller's to add
//! (docs/load.md).
//!
//! [`SimDriver::advance`] allocates nothing.

use crate::{PeriodStep, Plant, SimError};
use hcc_config::Scenario;
use hcc_model::{Data, Model};
use hcc_msgs::driver::{Action, DriverLogic, DriverSettings, Gravity, Offer, StopMode};
use hcc_msgs::{DriverStatus, JointState, MAX_JOINTS, TorqueCommand};
use nalgebra::DVector;

/// How the torque of one period was chosen.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Applied {
    /// A fresh command.
    Command,
    /// The last command, held after a miss.
    Held,
    /// The fallback (braking), after more than `hold_cycles` misses.
    Fallback,
    /// The fallback before the first command (not counted as a miss).
    WaitingForController,
    /// The fallback after a `Stop` command.
    Stopped,
}

impl From<Action> for Applied {
    fn from(action: Action) -> Applied {
        match action {
            Action::Apply => Applied::Command,
            Action::Hold => Applied::Held,
            Action::Fallback => Applied::Fallback,
            Action::Waiting => Applied::WaitingForController,
            Action::Stop { .. } => Applied::Stopped,
        }
    }
}

/// Counters of the driver.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct DriverCounters {
    /// Periods with no applicable command (after the first command).
    pub missed_commands: u64,
    /// Periods in the fallback (holding or braking; also before the first command).
    pub fallback_cycles: u64,
    /// Commands applied.
    pub applied_commands: u64,
    /// Commands rejected by validation or gravity agreement.
    pub rejected_commands: u64,
}

/// The plant plus the driver's command handling.
pub struct SimDriver {
    plant: Plant,
    /// The robot's own model (its gravity when the driver adds it): the
    /// plant's without any load.
    robot: Model,
    data: Data,
    n: usize,
    step: PeriodStep,
    period_s: f64,
    cycles_total: Option<u64>,
    k: u64,
    logic: DriverLogic,
    tau: DVector<f64>,
}

impl SimDriver {
    /// The driver of `scenario`: its plant (model, q0, q̇0, friction,
    /// wrenches), control rate, RK4 sub-steps and `[sim_daemon]` fallback settings.
    pub fn new(scenario: &Scenario) -> Result<SimDriver, SimError> {
        let plant = crate::plant_for(scenario)?;
        let s = &scenario.simulation;
        let n = plant.model().nq();
        // The same arithmetic as run_zoh.
        let period_s = scenario.period_s();
        let mut robot = plant.model().clone();
        hcc_model::set_load(&mut robot, &hcc_model::Load::none());
        Ok(SimDriver {
            data: Data::new(plant.model()),
            robot,
            n,
            step: PeriodStep::new(period_s, s.substeps)?,
            period_s,
            cycles_total: None,
            k: 0,
            logic: DriverLogic::new(Self::settings(scenario, n)),
            tau: DVector::zeros(n),
            plant,
        })
    }

    /// The contract settings of the simulated robot for `scenario` (n joints).
    pub fn settings(scenario: &Scenario, n: usize) -> DriverSettings {
        let mut fallback_damping = [0.0; MAX_JOINTS];
        for (to, d) in fallback_damping
            .iter_mut()
            .zip(&scenario.sim_daemon.fallback_damping)
        {
            *to = *d;
        }
        DriverSettings {
            n,
            late_tolerance: 0,
            check_sequence: false,
            hold_cycles: u64::from(scenario.sim_daemon.hold_cycles),
            fallback_timeout_cycles: None,
            wait_for_first_command: true,
            fallback_damping,
            gravity: if scenario.spec.gravity_compensation {
                Gravity::ControllerSends
            } else {
                Gravity::DriverAdds
            },
            stop_mode: StopMode::Brake,
        }
    }

    /// Stop after `duration_s` of simulated time (rounded to whole periods):
    /// the state at that time is the final one ([`SimDriver::finished`]).
    pub fn set_duration(&mut self, duration_s: f64) -> Result<(), SimError> {
        let cycles = (duration_s / self.period_s).round();
        if !(duration_s.is_finite() && (1.0..=1e12).contains(&cycles)) {
            return Err(SimError::Invalid(format!(
                "--duration {duration_s} s must be finite and cover at least one control period of {} s",
                self.period_s
            )));
        }
        self.cycles_total = Some(cycles as u64);
        Ok(())
    }

    /// The model.
    pub fn model(&self) -> &Model {
        self.plant.model()
    }

    /// Index k of the current state.
    pub fn k(&self) -> u64 {
        self.k
    }

    /// Simulated time t_k.
    pub fn t(&self) -> f64 {
        self.plant.t()
    }

    /// Control period in s.
    pub fn period_s(&self) -> f64 {
        self.period_s
    }

    /// Whether the final state (of `--duration`) has been reached.
    pub fn finished(&self) -> bool {
        self.cycles_total.is_some_and(|c| self.k >= c)
    }

    /// Whether a command was ever applied.
    pub fn has_command(&self) -> bool {
        self.logic.has_command()
    }

    /// Whether the driver is in the fallback (after misses, not while waiting
    /// for the first command).
    pub fn in_fallback(&self) -> bool {
        self.logic.in_fallback()
    }

    /// Counters.
    pub fn counters(&self) -> DriverCounters {
        let r = self.logic.rejections();
        DriverCounters {
            missed_commands: self.logic.missed_commands(),
            fallback_cycles: self.logic.fallback_cycles(),
            applied_commands: self.logic.applied(),
            rejected_commands: r.invalid + r.gravity_conflict,
        }
    }

    /// Status to publish.
    pub fn status(&self) -> DriverStatus {
        self.logic.status()
    }

    /// Marks the driver stopped (shutdown or end of the run).
    pub fn set_stopped(&mut self) {
        self.logic.request_stop();
    }

    /// The plant.
    pub fn plant(&self) -> &Plant {
        &self.plant
    }

    /// Writes the current state k (exact plant values) into `msg`; `stamp_ns`
    /// is the publication time.
    pub fn write_state(&self, msg: &mut JointState, stamp_ns: u64) {
        let n = self.n;
        msg.header = hcc_msgs::Header::new();
        msg.header.n_joints = n as u32;
        msg.header.seq = self.k;
        msg.header.stamp_ns = stamp_ns;
        self.logic.write_status(msg);
        msg.q = [0.0; hcc_msgs::MAX_JOINTS];
        msg.qd = [0.0; hcc_msgs::MAX_JOINTS];
        msg.tau_measured = [0.0; hcc_msgs::MAX_JOINTS];
        msg.q[..n].copy_from_slice(self.plant.q().as_slice());
        msg.qd[..n].copy_from_slice(self.plant.qd().as_slice());
        // The torque applied over the last period (the "motor" torque).
        msg.tau_measured[..n].copy_from_slice(self.tau.as_slice());
    }

    /// Chooses the torque for [t_k, t_{k+1}] from the newest received command
    /// (see the module docs), integrates the period and advances k.
    pub fn advance(&mut self, newest: Option<&TorqueCommand>) -> Result<Applied, SimError> {
        let command =
            newest.filter(|c| self.logic.offer(c, self.k) == Offer::Applicable { current: true });
        let (model, data, q) = (&self.robot, &mut self.data, self.plant.q());
        let gravity = |g: &mut [f64]| {
            hcc_model::gravity(model, data, q);
            g.copy_from_slice(data.g.as_slice());
        };
        let action = self.logic.decide(
            command,
            self.plant.qd().as_slice(),
            gravity,
            self.tau.as_mut_slice(),
        );
        // Re-anchored to the exact sample time t_{k+1}, as run_zoh does.
        let t_next = (self.k + 1) as f64 * self.period_s;
        self.step.advance(&mut self.plant, &self.tau, t_next)?;
        self.k += 1;
        Ok(action.into())
    }
}
