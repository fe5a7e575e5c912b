//! The recorder on the zero-order-hold loop with a simple joint-space law
//! (independent of the hierarchical controller and the control cycle): row
//! layout, determinism, convergence, and the disturbing-acceleration columns.

use hcc_config::Scenario;
use hcc_in_process::{PlantEnergyModel, column_names};
use hcc_plant::{LoopTiming, SimError, run_zoh};
use hcc_record::{Cycle, CycleOutput, LawTerms, Recorder};
use hcc_report::Trajectory;
use nalgebra::{DMatrix, DVector};
use std::path::PathBuf;

fn scenario() -> Scenario {
    let path =
        PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../tests/data/planar-joint-pd.toml");
    Scenario::load(&path).unwrap()
}

/// Level 1: PD on joint 1; level 2: PD on all joints projected away from joint 1
/// (zeroed at joint 1, a crude but valid "null space" for a selection task).
struct JointPd {
    model: hcc_model::Model,
    data: hcc_model::Data,
    goals: [DVector<f64>; 2],
    gains: [(f64, f64); 2],
    tau: DVector<f64>,
    level: [DVector<f64>; 2],
    mu: DVector<f64>,
    err: [DVector<f64>; 2],
    s: [f64; 2],
    /// J_1 selects joint 1, J_2 is the identity (joint-space tasks).
    jac: [DMatrix<f64>; 2],
}

impl JointPd {
    fn compute(&mut self, q: &DVector<f64>, qd: &DVector<f64>) -> Result<(), SimError> {
        hcc_model::gravity(&self.model, &mut self.data, q);
        self.err[0][0] = q[0] - self.goals[0][0];
        self.err[1] = q - &self.goals[1];
        let (k1, d1) = self.gains[0];
        let (k2, d2) = self.gains[1];
        self.level[0].fill(0.0);
        self.level[0][0] = -k1 * self.err[0][0] - d1 * qd[0];
        self.level[1] = -(&self.err[1] * k2) - qd * d2;
        self.level[1][0] = 0.0;
        self.tau = &self.data.g + &self.level[0] + &self.level[1];
        self.s[0] = 0.5 * k1 * self.err[0][0].powi(2);
        self.s[1] = 0.5 * k2 * self.err[1].norm_squared();
        Ok(())
    }
}

impl CycleOutput for JointPd {
    fn tau(&self) -> &[f64] {
        self.tau.as_slice()
    }
    fn level_torque(&self, i: usize) -> &[f64] {
        self.level[i].as_slice()
    }
    fn tau_mu(&self) -> &[f64] {
        self.mu.as_slice()
    }
    fn task_error(&self, i: usize) -> &[f64] {
        self.err[i].as_slice()
    }
    fn level_energy(&self, i: usize) -> f64 {
        self.s[i]
    }
    fn p_mu(&self) -> f64 {
        0.0
    }
}

impl LawTerms for JointPd {
    fn level_potential(&self, i: usize) -> f64 {
        self.s[i]
    }
    fn task_jacobian(&self, i: usize) -> &DMatrix<f64> {
        &self.jac[i]
    }
    fn extended_jacobian(&self) -> Option<(Vec<usize>, DMatrix<f64>)> {
        None
    }
}

/// The closed loop of `s` with `law` (sampled at the control rate, torque
/// held), recorded row by row.
fn simulate_with(s: &Scenario, law: &mut JointPd) -> Result<Trajectory, SimError> {
    let cycles = s.cycles() as usize;
    let mut plant = hcc_plant::plant_for(s)?;
    let energy = PlantEnergyModel(hcc_plant::plant_for(s)?);
    let mut recorder = Recorder::new(s, false, Box::new(energy)).unwrap();
    let mut table = recorder.trajectory(cycles + 1).unwrap();
    let timing = LoopTiming {
        control_period_s: s.period_s(),
        substeps: s.simulation.substeps,
        cycles,
    };
    run_zoh(&mut plant, timing, |_, t, q, qd, tau| {
        law.compute(q, qd)?;
        tau.copy_from(&law.tau);
        let row = Cycle {
            t,
            q: q.as_slice(),
            qd: qd.as_slice(),
            output: &*law,
            law: Some(&*law),
        };
        recorder
            .record(&row, &mut table)
            .map_err(|e| SimError::Invalid(e.to_string()))
    })?;
    Ok(table)
}

fn law(s: &Scenario) -> JointPd {
    let z = DVector::zeros(4);
    JointPd {
        model: s.model.clone(),
        data: hcc_model::Data::new(&s.model),
        goals: [s.levels()[0].goal.clone(), s.levels()[1].goal.clone()],
        gains: [(200.0, 30.0), (50.0, 8.0)],
        tau: z.clone(),
        level: [z.clone(), z.clone()],
        mu: z.clone(),
        err: [DVector::zeros(1), z],
        s: [0.0; 2],
        jac: [
            DMatrix::from_row_slice(1, 4, &[1.0, 0.0, 0.0, 0.0]),
            DMatrix::identity(4, 4),
        ],
    }
}

#[test]
fn rows_columns_and_determinism() {
    let s = scenario();
    let table = simulate_with(&s, &mut law(&s)).unwrap();
    let t = &table;
    assert_eq!(t.columns(), column_names(&s, false).as_slice());
    assert_eq!(t.n_rows(), 501);
    let time = t.column("t").unwrap();
    assert_eq!(time[0], 0.0);
    assert_eq!(time[500], 0.5);
    // Joint 1 converges to its goal (level 1).
    let e1 = t.column("e1_1").unwrap();
    assert!((e1[0] - 0.2).abs() < 1e-12);
    assert!(e1[500].abs() < 5e-3, "e1 {}", e1[500]);
    // τ_μ = 0 here, so its accelerations are 0.
    assert!(t.column("acc1_mu").unwrap().iter().all(|v| *v == 0.0));
    // Level 2's torque is zero at joint 1 but still accelerates joint 1 through the
    // coupled inertia: J_1 M⁻¹ τ_2 ≠ 0 (no dynamically consistent projection here).
    assert!(t.column("acc1_2").unwrap()[1] > 1e-3);
    // Applied torque column equals the sum of the parts plus g (first row, q0).
    let mut data = hcc_model::Data::new(&s.model);
    hcc_model::gravity(&s.model, &mut data, &s.q0);
    for k in 1..=4 {
        let tau = t.column(&format!("tau{k}")).unwrap()[0];
        let parts = t.column(&format!("tau_L1_{k}")).unwrap()[0]
            + t.column(&format!("tau_L2_{k}")).unwrap()[0];
        assert!((tau - parts - data.g[k - 1]).abs() < 1e-12);
    }
    // Plant energy columns: E_kin = ½ q̇ᵀ M q̇ at a later row.
    let row = t.row(250);
    let q = DVector::from_column_slice(&row[1..5]);
    let qd = DVector::from_column_slice(&row[5..9]);
    hcc_model::crba(&s.model, &mut data, &q);
    let m: &DMatrix<f64> = &data.m;
    let ekin = 0.5 * qd.dot(&(m * &qd));
    assert!((t.column("E_kin").unwrap()[250] - ekin).abs() < 1e-12);
    // Deterministic: a second run is bit-identical.
    let again = simulate_with(&s, &mut law(&s)).unwrap();
    assert!(again.bit_identical(&table), "a second run differs");
}
