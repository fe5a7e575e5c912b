//! The in-process closed loop of a scenario: the controller sampled at the
//! control rate (state read at t_k, torque held over [t_k, t_{k+1}): zero-order
//! hold), the plant integrated with RK4 at the integrator step, external
//! wrenches acting on the plant only. Deterministic: the same scenario gives
//! bit-identical results.
//!
//! One trajectory row is recorded per controller cycle from t = 0 to t =
//! duration (both included) by the recorder of hcc-record
//! ([`hcc_record::Recorder`]; its documentation lists the columns), the same
//! recorder `hcc run` uses.

use crate::zoh::{LoopTiming, run_zoh};
use crate::{ExternalWrench, Plant, SimError};
use hcc_config::Scenario;
use hcc_control::Controller;
use hcc_record::{Cycle, CycleOutput, EnergyModel, LawTerms, RecordError, Recorder};
use hcc_report::{RunDescription, Trajectory};
use nalgebra::{DMatrix, DVector};

pub use hcc_record::{column_names, describe};

/// What the closed loop needs from a controller, sampled once per cycle.
pub trait ControlLaw {
    /// Computes the command for the sampled state (q, q̇).
    fn compute(&mut self, q: &DVector<f64>, qd: &DVector<f64>) -> Result<(), SimError>;
    /// Torque to apply, τ of eq. (19) (gravity included when the scenario asks for it).
    fn tau(&self) -> &DVector<f64>;
    /// Torque contribution τ_i of level `i` (0-based), eqs. (20)/(21).
    fn level_torque(&self, i: usize) -> &DVector<f64>;
    /// Coriolis cancellation τ_μ, eq. (22) (zero when disabled).
    fn tau_mu(&self) -> &DVector<f64>;
    /// Task error x_i − x_{i,d} of level `i`.
    fn task_error(&self, i: usize) -> &DVector<f64>;
    /// Level energy S_i, eqs. (26)/(28).
    fn level_energy(&self, i: usize) -> f64;
    /// Potential V_i(x̃_i) of level `i` (the rest of S_i is kinetic).
    fn level_potential(&self, i: usize) -> f64;
    /// Power of τ_μ, P_μ = τ_μᵀ q̇.
    fn p_mu(&self) -> f64;
    /// The task Jacobian J_i of level `i` at the last sampled state (for the
    /// disturbing accelerations ‖J_i M⁻¹ τ_j‖, see [`LawTerms::task_jacobian`]).
    fn task_jacobian(&self, i: usize) -> &DMatrix<f64>;
    /// Whether [`ControlLaw::extended_jacobian`] is available (decides the columns).
    fn has_extended_jacobian(&self) -> bool {
        false
    }
    /// The extended Jacobian J̄ of eq. (4) of the last cycle, stacked level by level
    /// (row blocks of the sizes `dims` of v_i); `None` if not available.
    fn extended_jacobian(&self) -> Option<(Vec<usize>, DMatrix<f64>)> {
        None
    }
}

/// Result of a simulation: the trajectory table and what the report needs to know.
#[derive(Clone, Debug)]
pub struct Run {
    pub trajectory: Trajectory,
    pub description: RunDescription,
}

/// Builds the plant of a scenario (model, initial state, friction, wrenches).
pub fn plant_for(scenario: &Scenario) -> Result<Plant, SimError> {
    let s = &scenario.simulation;
    let mut plant = Plant::new(
        scenario.model.clone(),
        &scenario.q0,
        &scenario.qd0,
        &s.joint_friction,
    )?;
    plant.set_wrenches(
        s.wrenches
            .iter()
            .map(|w| ExternalWrench {
                start_s: w.start_s,
                duration_s: w.duration_s,
                frame: w.frame_id,
                force: w.force,
                torque: w.torque,
            })
            .collect(),
    )?;
    Ok(plant)
}

impl EnergyModel for Plant {
    fn energy_at(
        &mut self,
        t: f64,
        q: &DVector<f64>,
        qd: &DVector<f64>,
    ) -> Result<(f64, f64), RecordError> {
        self.set_state(t, q, qd)
            .map_err(|e| RecordError::Invalid(e.to_string()))?;
        let energy = self.energy();
        Ok((energy.kinetic, energy.potential))
    }
}

/// The recorder of `scenario` (`with_v`: with the `accv` columns), the plant's
/// energy taken from the scenario's plant ([`plant_for`]).
pub fn recorder(scenario: &Scenario, with_v: bool) -> Result<Recorder, SimError> {
    Recorder::new(scenario, with_v, Box::new(plant_for(scenario)?))
        .map_err(|e| SimError::Invalid(e.to_string()))
}

/// A [`ControlLaw`] after its cycle, as the recorder reads it.
pub struct Sampled<'a, L: ControlLaw>(pub &'a L);

impl<L: ControlLaw> CycleOutput for Sampled<'_, L> {
    fn tau(&self) -> &[f64] {
        self.0.tau().as_slice()
    }
    fn level_torque(&self, i: usize) -> &[f64] {
        self.0.level_torque(i).as_slice()
    }
    fn tau_mu(&self) -> &[f64] {
        self.0.tau_mu().as_slice()
    }
    fn task_error(&self, i: usize) -> &[f64] {
        self.0.task_error(i).as_slice()
    }
    fn level_energy(&self, i: usize) -> f64 {
        self.0.level_energy(i)
    }
    fn p_mu(&self) -> f64 {
        self.0.p_mu()
    }
}

impl<L: ControlLaw> LawTerms for Sampled<'_, L> {
    fn task_jacobian(&self, i: usize) -> &DMatrix<f64> {
        self.0.task_jacobian(i)
    }
    fn level_potential(&self, i: usize) -> f64 {
        self.0.level_potential(i)
    }
    fn extended_jacobian(&self) -> Option<(Vec<usize>, DMatrix<f64>)> {
        self.0.extended_jacobian()
    }
}

/// A per-cycle observer of [`simulate_observed`]: cycle k, its time t_k,
/// the sampled state (q, q̇) and the law after its step at that state.
pub type Observer<'a, L> =
    dyn FnMut(usize, f64, &DVector<f64>, &DVector<f64>, &L) -> Result<(), SimError> + 'a;

/// Runs the closed loop of `scenario` with the control law `law`.
pub fn simulate_with<L: ControlLaw>(scenario: &Scenario, law: &mut L) -> Result<Run, SimError> {
    simulate_observed(scenario, law, &mut |_, _, _, _, _| Ok(()))
}

/// [`simulate_with`], calling `observe` after the law's step of every cycle
/// (e.g. to record the cycle's messages).
pub fn simulate_observed<L: ControlLaw>(
    scenario: &Scenario,
    law: &mut L,
    observe: &mut Observer<'_, L>,
) -> Result<Run, SimError> {
    let s = &scenario.simulation;
    let cycles = (s.duration_s * s.control_rate_hz).round() as usize;
    let timing = LoopTiming {
        control_period_s: 1.0 / s.control_rate_hz,
        substeps: s.substeps,
        cycles,
    };
    let mut plant = plant_for(scenario)?;
    let mut recorder = recorder(scenario, law.has_extended_jacobian())?;
    let record_err = |e: RecordError| SimError::Invalid(e.to_string());
    let mut traj = recorder.trajectory(cycles + 1).map_err(record_err)?;

    run_zoh(&mut plant, timing, |k, t, q, qd, tau| {
        law.compute(q, qd)
            .map_err(|e| SimError::Invalid(format!("t = {t} s: {e}")))?;
        observe(k, t, q, qd, &*law)?;
        tau.copy_from(law.tau());
        if let Some(j) = tau.iter().position(|x| !x.is_finite()) {
            return Err(SimError::Invalid(format!(
                "the controller returned a non-finite torque at joint {} at t = {t} s",
                j + 1
            )));
        }
        let sampled = Sampled(&*law);
        let cycle = Cycle {
            t,
            q: q.as_slice(),
            qd: qd.as_slice(),
            output: &sampled,
            law: Some(&sampled),
        };
        recorder.record(&cycle, &mut traj).map_err(record_err)
    })?;
    let mut description = describe(scenario);
    // What the plant's end stops and velocity monitor counted (only when anything
    // happened, so that runs within the limits describe themselves as before).
    let stops = plant.end_stops();
    for (key, value) in [
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
    Ok(Run {
        trajectory: traj,
        description,
    })
}

/// Changes to the law's goals and gains made before a cycle's step (the
/// controller's setpoint side: scheduled setpoints, see `hcc simulate`).
pub trait Commands {
    /// Called before the step of cycle `k` (t_k = k · T); may set goals,
    /// gains and goal velocities of `controller`.
    fn before_step(&mut self, k: u64, controller: &mut Controller) -> Result<(), SimError>;
}

/// The hierarchical compliance controller of hcc-control as a [`ControlLaw`],
/// its torque saturated to `[controller_daemon] torque_limits` exactly as the
/// controller daemon saturates its commands ([`hcc_control::saturate`]: the
/// control part scaled as a whole), so that the in-process run and the daemons
/// apply the same torque.
pub struct HierarchicalLaw {
    controller: Controller,
    limits: DVector<f64>,
    gravity_compensation: bool,
    tau: DVector<f64>,
    saturated_cycles: u64,
    commands: Option<Box<dyn Commands>>,
    /// Cycles computed so far (the index k of the next one).
    cycle: u64,
}

impl HierarchicalLaw {
    /// Builds the controller of `scenario` (its spec, model and initial configuration).
    pub fn new(scenario: &Scenario) -> Result<HierarchicalLaw, SimError> {
        let controller = Controller::new(&scenario.model, scenario.spec.clone(), &scenario.q0)
            .map_err(|e| SimError::Invalid(format!("controller: {e}")))?;
        let n = scenario.model.nq();
        Ok(HierarchicalLaw {
            controller,
            limits: scenario.controller_daemon.torque_limits.clone(),
            gravity_compensation: scenario.spec.gravity_compensation,
            tau: DVector::zeros(n),
            saturated_cycles: 0,
            commands: None,
            cycle: 0,
        })
    }

    /// The law with `commands` applied before every step.
    pub fn with_commands(mut self, commands: Box<dyn Commands>) -> HierarchicalLaw {
        self.commands = Some(commands);
        self
    }

    /// Sets the index k of the next cycle (its [`Commands::before_step`]
    /// gets k; afterwards k counts on by one per cycle). For a law fed with
    /// a driver's numbered states (t_k = k · T), e.g. `hcc run`'s shadow
    /// controller, which sees the states the controller answered.
    pub fn set_next_cycle(&mut self, k: u64) {
        self.cycle = k;
    }

    /// The wrapped controller.
    pub fn controller(&self) -> &Controller {
        &self.controller
    }

    /// Cycles whose torque had to be saturated.
    pub fn saturated_cycles(&self) -> u64 {
        self.saturated_cycles
    }
}

impl ControlLaw for HierarchicalLaw {
    fn compute(&mut self, q: &DVector<f64>, qd: &DVector<f64>) -> Result<(), SimError> {
        if let Some(commands) = &mut self.commands {
            commands.before_step(self.cycle, &mut self.controller)?;
        }
        self.cycle += 1;
        let out = self
            .controller
            .step(q.as_slice(), qd.as_slice())
            .map_err(|e| SimError::Invalid(format!("controller: {e}")))?;
        self.tau.copy_from(&out.tau);
        let gravity = self.gravity_compensation.then_some(out.gravity.as_slice());
        let saturated =
            hcc_control::saturate(self.tau.as_mut_slice(), gravity, self.limits.as_slice());
        self.saturated_cycles += u64::from(saturated);
        Ok(())
    }
    fn tau(&self) -> &DVector<f64> {
        &self.tau
    }
    fn level_torque(&self, i: usize) -> &DVector<f64> {
        &self.controller.output().tau_level[i]
    }
    fn tau_mu(&self) -> &DVector<f64> {
        &self.controller.output().tau_mu
    }
    fn task_error(&self, i: usize) -> &DVector<f64> {
        &self.controller.output().task_error[i]
    }
    fn level_energy(&self, i: usize) -> f64 {
        self.controller.output().storage[i]
    }
    fn level_potential(&self, i: usize) -> f64 {
        self.controller.output().potential[i]
    }
    fn p_mu(&self) -> f64 {
        self.controller.output().p_mu
    }
    fn task_jacobian(&self, i: usize) -> &DMatrix<f64> {
        self.controller.task_jacobian(i)
    }
    fn has_extended_jacobian(&self) -> bool {
        true
    }
    fn extended_jacobian(&self) -> Option<(Vec<usize>, DMatrix<f64>)> {
        let d = self.controller.diagnostics();
        Some((d.dims, d.jbar))
    }
}

/// Runs the closed loop of `scenario` with the hierarchical compliance controller
/// of hcc-control (Sec. IV of the paper), as configured in `scenario.spec`.
/// The torque is saturated as the daemon saturates it; the number of
/// saturated cycles is in the run's settings (`saturated_cycles`).
pub fn simulate(scenario: &Scenario) -> Result<Run, SimError> {
    simulate_law(scenario, HierarchicalLaw::new(scenario)?)
}

/// [`simulate`] with a given law (e.g. one with [`Commands`]).
pub fn simulate_law(scenario: &Scenario, law: HierarchicalLaw) -> Result<Run, SimError> {
    simulate_law_observed(scenario, law, &mut |_, _, _, _, _| Ok(()))
}

/// [`simulate_law`] with a per-cycle observer (see [`simulate_observed`]).
pub fn simulate_law_observed(
    scenario: &Scenario,
    mut law: HierarchicalLaw,
    observe: &mut Observer<'_, HierarchicalLaw>,
) -> Result<Run, SimError> {
    let mut run = simulate_observed(scenario, &mut law, observe)?;
    run.description.settings.insert(
        "saturated_cycles".into(),
        serde_json::json!(law.saturated_cycles()),
    );
    // What the controller's safety layer did (only when it acted).
    let safety = &law.controller().output().safety;
    for (key, value) in [
        ("joint_limit_guard_cycles", safety.joint_limit_cycles),
        ("velocity_limit_cycles", safety.velocity_limit_cycles),
        ("spring_saturation_cycles", safety.spring_saturated_cycles),
        ("conflict_fade_cycles", safety.conflict_fade_cycles),
    ] {
        if value > 0 {
            run.description.settings.insert(key.into(), value.into());
        }
    }
    Ok(run)
}
