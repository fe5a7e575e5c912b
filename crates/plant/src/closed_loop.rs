//! The in-process closed loop of a scenario: the controller sampled at the
//! control rate (state read at t_k, torque held over [t_k, t_{k+1}): zero-order
//! hold), the plant integrated with RK4 at the integrator step, external
//! wrenches acting on the plant only. Deterministic: the same scenario gives
//! bit-identical results.
//!
//! One trajectory row is recorded per controller cycle from t = 0 to t =
//! duration (both included), with the columns of [`hcc_report::columns`]:
//! the required ones (t, q, q̇, τ, task errors, S_i, P_μ), then
//! - `tau_L<i>_<k>` and `tau_mu_<k>`: the torque of each level (eqs. 20, 21) and τ_μ (eq. 22),
//! - `acc<i>_<j>` for i ≠ j: the norm ‖J_i M⁻¹ τ_j‖ of the task-space acceleration
//!   that the control torque of level j alone produces on level i (Fig. 5). With a
//!   strict hierarchy it vanishes for j > i (J_i M⁻¹ N_j = 0); for j < i it is the
//!   admissible influence of a higher level on a lower one. `acc<i>_mu` is the same
//!   for τ_μ. J_i is the analytic task Jacobian (angular-velocity rows for an
//!   orientation task, selection rows for a joint task),
//! - `accv<i>_<j>` and `accv<i>_mu` (when the law provides J̄): the same in the
//!   paper's local null-space coordinates, ‖J̄_i M⁻¹ τ_j‖ = ‖v̇_i‖ caused by τ_j
//!   (eqs. 3, 15, 24, 25). The block-diagonal Λ (eq. 16) makes it vanish for every
//!   j ≠ i, so these columns measure the decoupling of Sec. III numerically;
//!   `accv<i>_mu` = ‖Λ_i⁻¹ Σ_{j≠i} μ_ij v_j‖ is the coupling that τ_μ cancels,
//! - `S<i>_pot` = V_i(x̃_i) (the potential of eq. 28) and `S<i>_kin` = S_i − V_i
//!   (the kinetic part ½ v_iᵀ Λ_i v_i),
//! - `E_kin`, `E_pot`: mechanical energy of the plant.

use crate::zoh::{LoopTiming, run_zoh};
use crate::{ExternalWrench, Plant, SimError};
use hcc_config::{Scenario, Task, TaskUnit};
use hcc_control::Controller;
use hcc_model::Model;
use hcc_report::{ErrorUnit, LevelDescription, RunDescription, Trajectory, columns};
use nalgebra::{DMatrix, DVector};
use std::collections::BTreeMap;

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

/// Task Jacobians J_i of the scenario's levels, evaluated from the model.
struct TaskJacobians {
    frame_jac: DMatrix<f64>,
    jac: Vec<DMatrix<f64>>,
}

impl TaskJacobians {
    fn new(model: &Model, scenario: &Scenario) -> TaskJacobians {
        let n = model.nq();
        TaskJacobians {
            frame_jac: DMatrix::zeros(6, n),
            jac: scenario
                .levels
                .iter()
                .map(|l| DMatrix::zeros(l.task.dim(), n))
                .collect(),
        }
    }

    /// Needs forward kinematics at q in `data`.
    fn update(&mut self, model: &Model, data: &hcc_model::Data, scenario: &Scenario) {
        for (l, jac) in scenario.levels.iter().zip(self.jac.iter_mut()) {
            jac.fill(0.0);
            match &l.task {
                Task::Position { frame_id, axes, .. } => {
                    hcc_model::frame_jacobian(model, data, *frame_id, &mut self.frame_jac);
                    for (r, &a) in axes.iter().enumerate() {
                        jac.row_mut(r).copy_from(&self.frame_jac.row(a));
                    }
                }
                Task::Orientation { frame_id, .. } => {
                    hcc_model::frame_jacobian(model, data, *frame_id, &mut self.frame_jac);
                    for r in 0..3 {
                        jac.row_mut(r).copy_from(&self.frame_jac.row(3 + r));
                    }
                }
                Task::PlanarOrientation { frame_id, axis, .. } => {
                    hcc_model::frame_jacobian(model, data, *frame_id, &mut self.frame_jac);
                    jac.row_mut(0).copy_from(&self.frame_jac.row(3 + axis));
                }
                Task::Joint { joints } => {
                    for (r, &j) in joints.iter().enumerate() {
                        jac[(r, j)] = 1.0;
                    }
                }
                Task::Posture { .. } => jac.fill_with_identity(),
                Task::JointCombination { weights } => jac.copy_from(weights),
            }
        }
    }
}

fn unit(u: TaskUnit) -> ErrorUnit {
    match u {
        TaskUnit::Length => ErrorUnit::Meter,
        TaskUnit::Angle => ErrorUnit::Radian,
    }
}

/// The report's description of a scenario run.
pub fn describe(scenario: &Scenario) -> RunDescription {
    let s = &scenario.simulation;
    let mut settings = BTreeMap::new();
    let mut put = |k: &str, v: serde_json::Value| {
        settings.insert(k.to_string(), v);
    };
    put("config", scenario.path.display().to_string().into());
    put("urdf", scenario.urdf_path.display().to_string().into());
    put("duration_s", s.duration_s.into());
    put("control_rate_hz", s.control_rate_hz.into());
    put("integrator_dt_s", s.integrator_dt_s.into());
    put("integrator", "RK4".into());
    put(
        "coriolis_cancellation",
        scenario.coriolis_cancellation.into(),
    );
    put("gravity_compensation", scenario.gravity_compensation.into());
    put(
        "form",
        match scenario.form {
            hcc_config::FormName::Extended => "extended",
            hcc_config::FormName::Projector => "projector",
        }
        .into(),
    );
    put(
        "joint_friction",
        s.joint_friction
            .iter()
            .copied()
            .collect::<Vec<f64>>()
            .into(),
    );
    put("external_wrenches", s.wrenches.len().into());
    put(
        "q0",
        scenario.q0.iter().copied().collect::<Vec<f64>>().into(),
    );
    RunDescription {
        scenario: scenario.name.clone(),
        n_joints: scenario.model.nq(),
        levels: scenario
            .levels
            .iter()
            .map(|l| LevelDescription {
                name: l.name.clone(),
                dim: l.task.dim(),
                unit: unit(l.task.unit()),
            })
            .collect(),
        settings,
    }
}

/// Column names recorded by [`simulate_with`] for `scenario` (`with_v`: the law
/// provides J̄, so the `accv` columns are recorded).
pub fn column_names(scenario: &Scenario, with_v: bool) -> Vec<String> {
    let n = scenario.model.nq();
    let r = scenario.levels.len();
    let dims: Vec<usize> = scenario.levels.iter().map(|l| l.task.dim()).collect();
    let mut c = columns::required(n, &dims);
    for i in 1..=r {
        c.extend((1..=n).map(|k| columns::level_torque(i, k)));
    }
    c.extend((1..=n).map(columns::mu_torque));
    for i in 1..=r {
        c.extend(
            (1..=r)
                .filter(|&j| j != i)
                .map(|j| columns::disturbing_acceleration(i, j)),
        );
        c.push(columns::mu_acceleration(i));
    }
    if with_v {
        for i in 1..=r {
            c.extend(
                (1..=r)
                    .filter(|&j| j != i)
                    .map(|j| columns::null_space_acceleration(i, j)),
            );
            c.push(columns::null_space_mu_acceleration(i));
        }
    }
    for i in 1..=r {
        c.push(columns::energy_kinetic(i));
        c.push(columns::energy_potential(i));
    }
    c.push(columns::E_KIN.to_string());
    c.push(columns::E_POT.to_string());
    c
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

/// Runs the closed loop of `scenario` with the control law `law`.
pub fn simulate_with<L: ControlLaw>(scenario: &Scenario, law: &mut L) -> Result<Run, SimError> {
    let s = &scenario.simulation;
    let model = &scenario.model;
    let n = model.nq();
    let r = scenario.levels.len();
    let period = 1.0 / s.control_rate_hz;
    let cycles = (s.duration_s * s.control_rate_hz).round() as usize;
    let timing = LoopTiming {
        control_period_s: period,
        substeps: s.substeps,
        cycles,
    };
    let mut plant = plant_for(scenario)?;
    let with_v = law.has_extended_jacobian();
    let names = column_names(scenario, with_v);
    let mut traj = Trajectory::with_capacity(names, cycles + 1)
        .map_err(|e| SimError::Invalid(e.to_string()))?;

    // Recording workspace (allocated once).
    let mut data = hcc_model::Data::new(model);
    let mut jacs = TaskJacobians::new(model, scenario);
    let mut m_chol = DMatrix::zeros(n, n);
    // M⁻¹ τ_j for every level j, then for τ_μ.
    let mut minv_tau: Vec<DVector<f64>> = (0..=r).map(|_| DVector::zeros(n)).collect();
    let mut acc: Vec<DVector<f64>> = scenario
        .levels
        .iter()
        .map(|l| DVector::zeros(l.task.dim()))
        .collect();
    let mut row: Vec<f64> = Vec::with_capacity(traj.columns().len());
    let mut recorder_plant = plant.clone();

    run_zoh(&mut plant, timing, |_k, t, q, qd, tau| {
        law.compute(q, qd)
            .map_err(|e| SimError::Invalid(format!("t = {t} s: {e}")))?;
        tau.copy_from(law.tau());
        if let Some(j) = tau.iter().position(|x| !x.is_finite()) {
            return Err(SimError::Invalid(format!(
                "the controller returned a non-finite torque at joint {} at t = {t} s",
                j + 1
            )));
        }

        // Model quantities at the sampled state for the disturbing accelerations.
        hcc_model::crba(model, &mut data, q);
        jacs.update(model, &data, scenario);
        m_chol.copy_from(&data.m);
        hcc_model::linalg::cholesky_in_place(&mut m_chol)
            .map_err(|e| SimError::Invalid(format!("M(q) at t = {t} s: {e}")))?;

        row.clear();
        row.push(t);
        row.extend(q.iter());
        row.extend(qd.iter());
        row.extend(tau.iter());
        for i in 0..r {
            row.extend(law.task_error(i).iter());
        }
        for i in 0..r {
            row.push(law.level_energy(i));
        }
        row.push(law.p_mu());
        for i in 0..r {
            row.extend(law.level_torque(i).iter());
        }
        row.extend(law.tau_mu().iter());
        for (j, x) in minv_tau.iter_mut().enumerate() {
            x.copy_from(if j < r {
                law.level_torque(j)
            } else {
                law.tau_mu()
            });
            hcc_model::linalg::cholesky_solve_in_place(&m_chol, x)
                .map_err(|e| SimError::Invalid(format!("M(q) solve at t = {t} s: {e}")))?;
        }
        // ‖J_i M⁻¹ τ_j‖ for every j ≠ i, then for τ_μ.
        for (i, acc_i) in acc.iter_mut().enumerate() {
            for (j, x) in minv_tau.iter().enumerate() {
                if j != i {
                    acc_i.gemv(1.0, &jacs.jac[i], x, 0.0);
                    row.push(acc_i.norm());
                }
            }
        }
        // ‖J̄_i M⁻¹ τ_j‖ in the local null-space coordinates.
        if with_v {
            let (dims, jbar) = law
                .extended_jacobian()
                .ok_or_else(|| SimError::Invalid(format!("t = {t} s: the controller gave no J̄")))?;
            if dims.len() != r || jbar.ncols() != n || dims.iter().sum::<usize>() != jbar.nrows() {
                return Err(SimError::Invalid(format!(
                    "t = {t} s: J̄ of the controller has an unexpected shape"
                )));
            }
            let mut offset = 0;
            for (i, &d) in dims.iter().enumerate() {
                let block = jbar.rows(offset, d);
                for (j, x) in minv_tau.iter().enumerate() {
                    if j != i {
                        row.push((block * x).norm());
                    }
                }
                offset += d;
            }
        }
        for i in 0..r {
            let pot = law.level_potential(i);
            row.push(law.level_energy(i) - pot);
            row.push(pot);
        }
        recorder_plant
            .set_state(t, q, qd)
            .map_err(|e| SimError::Invalid(e.to_string()))?;
        let energy = recorder_plant.energy();
        row.push(energy.kinetic);
        row.push(energy.potential);
        traj.push_row(&row)
            .map_err(|e| SimError::Invalid(e.to_string()))?;
        Ok(())
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
            gravity_compensation: scenario.gravity_compensation,
            tau: DVector::zeros(n),
            saturated_cycles: 0,
        })
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
    let mut law = HierarchicalLaw::new(scenario)?;
    let mut run = simulate_with(scenario, &mut law)?;
    run.description.settings.insert(
        "saturated_cycles".into(),
        serde_json::json!(law.saturated_cycles()),
    );
    // What the controller's safety layer did (only when it acted).
    let safety = &law.controller().output().safety;
    for (key, value) in [
        ("joint_limit_guard_cycles", safety.joint_limit_cycles),
        ("velocity_damping_cycles", safety.velocity_limit_cycles),
    ] {
        if value > 0 {
            run.description.settings.insert(key.into(), value.into());
        }
    }
    Ok(run)
}
