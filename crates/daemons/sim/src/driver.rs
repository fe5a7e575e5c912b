//! The simulated robot driver: the plant of `hcc-sim` (RK4, the robot
//! dynamics of paper Eq. (1), viscous friction, external wrenches through the
//! link Jacobian) behind the driver side of the hcc-msgs timing contract.
//!
//! Per control period k the driver publishes the state (q_k, q̇_k) exactly as
//! the plant holds it, then applies a torque over [t_k, t_{k+1}] with a
//! zero-order hold and integrates with the same RK4 sub-steps and time
//! re-anchoring as `hcc simulate` ([`hcc_plant::run_zoh`]), so a lockstep run over
//! IPC reproduces the in-process closed loop bit for bit.
//!
//! Which torque ([`SimDriver::advance`]):
//! * the newest command, if it passes [`TorqueCommand::validate`], agrees on
//!   gravity ([`hcc_msgs::check_gravity_agreement`]), answers state k
//!   ([`hcc_msgs::command_freshness`] = `Current`) and its mode applies torque;
//! * otherwise a **miss**, detected in the period whose command is missing:
//!   status `FallbackActive` from that period on (counted in `missed_commands`
//!   and `fallback_cycles`); the last applied command is held for
//!   `hold_cycles` periods, then τ = g(q_k) − D q̇_k (gravity held, strong
//!   joint damping: a braking robot) until fresh commands arrive again (e.g.
//!   from a restarted controller, which is accepted at its first command);
//! * before the first command ever (controller not up yet) the fallback is
//!   applied without counting misses, so the arm does not fall;
//! * a `Stop` command ends control for the session: status `Stopped`,
//!   fallback braking from then on.
//!
//! When the controller does not include gravity (the scenario's
//! `gravity_compensation = false`), the simulated driver compensates gravity
//! itself like many commercial arms: it sets
//! [`STATE_FLAG_DRIVER_GRAVITY_COMPENSATION`] and adds g(q_k) to every command.
//!
//! [`SimDriver::advance`] allocates nothing.

use hcc_config::Scenario;
use hcc_model::{Data, Model};
use hcc_msgs::{
    CommandFreshness, CommandMode, DriverStatus, JointState,
    STATE_FLAG_DRIVER_GRAVITY_COMPENSATION, TorqueCommand, check_gravity_agreement,
    command_freshness,
};
use hcc_plant::{Plant, SimError};
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
    data: Data,
    n: usize,
    substeps: usize,
    period_s: f64,
    h: f64,
    cycles_total: Option<u64>,
    k: u64,
    hold_cycles: u32,
    fallback_damping: DVector<f64>,
    driver_gravity: bool,
    tau: DVector<f64>,
    last_command_tau: DVector<f64>,
    have_command: bool,
    consecutive_misses: u32,
    status: DriverStatus,
    counters: DriverCounters,
    state_flags: u32,
}

impl SimDriver {
    /// The driver of `scenario`: its plant (model, q0, q̇0, friction,
    /// wrenches), control rate, RK4 sub-steps and `[sim_daemon]` fallback settings.
    pub fn new(scenario: &Scenario) -> Result<SimDriver, SimError> {
        let plant = hcc_plant::closed_loop::plant_for(scenario)?;
        let s = &scenario.simulation;
        let n = plant.model().nq();
        // The same arithmetic as hcc_plant::closed_loop::simulate_with / run_zoh.
        let period_s = 1.0 / s.control_rate_hz;
        let h = period_s / s.substeps as f64;
        let driver_gravity = !scenario.spec.gravity_compensation;
        Ok(SimDriver {
            data: Data::new(plant.model()),
            n,
            substeps: s.substeps,
            period_s,
            h,
            cycles_total: None,
            k: 0,
            hold_cycles: scenario.sim_daemon.hold_cycles,
            fallback_damping: scenario.sim_daemon.fallback_damping.clone(),
            driver_gravity,
            tau: DVector::zeros(n),
            last_command_tau: DVector::zeros(n),
            have_command: false,
            consecutive_misses: 0,
            status: DriverStatus::FallbackActive,
            counters: DriverCounters::default(),
            state_flags: if driver_gravity {
                STATE_FLAG_DRIVER_GRAVITY_COMPENSATION
            } else {
                0
            },
            plant,
        })
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
        self.have_command
    }

    /// Whether the driver is in the fallback (after misses, not while waiting
    /// for the first command).
    pub fn in_fallback(&self) -> bool {
        self.have_command && self.status == DriverStatus::FallbackActive
    }

    /// Counters.
    pub fn counters(&self) -> DriverCounters {
        self.counters
    }

    /// Status to publish.
    pub fn status(&self) -> DriverStatus {
        self.status
    }

    /// Marks the driver stopped (shutdown or end of the run).
    pub fn set_stopped(&mut self) {
        self.status = DriverStatus::Stopped;
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
        msg.status = self.status.code();
        msg.flags = self.state_flags;
        msg.missed_commands = self.counters.missed_commands;
        msg.fallback_cycles = self.counters.fallback_cycles;
        msg.q = [0.0; hcc_msgs::MAX_JOINTS];
        msg.qd = [0.0; hcc_msgs::MAX_JOINTS];
        msg.tau_measured = [0.0; hcc_msgs::MAX_JOINTS];
        msg.q[..n].copy_from_slice(self.plant.q().as_slice());
        msg.qd[..n].copy_from_slice(self.plant.qd().as_slice());
        // The torque applied over the last period (the "motor" torque).
        msg.tau_measured[..n].copy_from_slice(self.tau.as_slice());
    }

    /// Whether `command` may be applied to state k.
    fn applicable(&mut self, command: &TorqueCommand) -> Option<CommandMode> {
        let mut probe = JointState::zeroed();
        probe.flags = self.state_flags;
        if command.validate(self.n).is_err() || check_gravity_agreement(&probe, command).is_err() {
            self.counters.rejected_commands += 1;
            return None;
        }
        if command_freshness(command.state_seq, self.k) != CommandFreshness::Current {
            return None;
        }
        command.mode().ok()
    }

    /// g(q_k) into `data.g`.
    fn gravity(&mut self) {
        hcc_model::gravity(self.plant.model(), &mut self.data, self.plant.q());
    }

    /// τ = g(q_k) − D q̇_k.
    fn fallback_torque(&mut self) {
        self.gravity();
        for j in 0..self.n {
            self.tau[j] = self.data.g[j] - self.fallback_damping[j] * self.plant.qd()[j];
        }
    }

    /// Chooses the torque for [t_k, t_{k+1}] from the newest received command
    /// (see the module docs), integrates the period and advances k.
    pub fn advance(&mut self, newest: Option<&TorqueCommand>) -> Result<Applied, SimError> {
        let mode = newest.and_then(|c| self.applicable(c).map(|m| (c, m)));
        let applied = if self.status == DriverStatus::Stopped {
            Applied::Stopped
        } else {
            match mode {
                Some((_, CommandMode::Stop)) => {
                    self.status = DriverStatus::Stopped;
                    Applied::Stopped
                }
                Some((command, _)) => {
                    self.tau
                        .as_mut_slice()
                        .copy_from_slice(&command.tau[..self.n]);
                    if self.driver_gravity {
                        self.gravity();
                        self.tau += &self.data.g;
                    }
                    self.last_command_tau.copy_from(&self.tau);
                    self.have_command = true;
                    self.consecutive_misses = 0;
                    self.status = DriverStatus::Ok;
                    self.counters.applied_commands += 1;
                    Applied::Command
                }
                None if !self.have_command => Applied::WaitingForController,
                None => {
                    self.counters.missed_commands += 1;
                    self.consecutive_misses = self.consecutive_misses.saturating_add(1);
                    // The fallback starts with the first miss: hold, then brake.
                    self.status = DriverStatus::FallbackActive;
                    self.counters.fallback_cycles += 1;
                    if self.consecutive_misses <= self.hold_cycles {
                        self.tau.copy_from(&self.last_command_tau);
                        Applied::Held
                    } else {
                        Applied::Fallback
                    }
                }
            }
        };
        match applied {
            Applied::Command | Applied::Held => {}
            Applied::Fallback => self.fallback_torque(),
            Applied::WaitingForController | Applied::Stopped => {
                self.fallback_torque();
                self.counters.fallback_cycles += 1;
            }
        }
        for _ in 0..self.substeps {
            self.plant.step(&self.tau, self.h)?;
        }
        self.k += 1;
        // Re-anchor the clock to the exact sample time, as run_zoh does.
        self.plant.set_time(self.k as f64 * self.period_s);
        Ok(applied)
    }
}
