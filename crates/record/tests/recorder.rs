//! The recorder on its own: row layout, the derived columns against an
//! independent computation, unknown law terms, bad sizes, streaming sinks.

use hcc_config::Scenario;
use hcc_record::{
    Cycle, CycleOutput, EnergyModel, LawTerms, RecordError, Recorder, RowSink, column_names,
};
use nalgebra::{DMatrix, DVector};
use std::path::PathBuf;

fn scenario() -> Scenario {
    let path =
        PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../tests/data/planar-joint-pd.toml");
    Scenario::load(&path).unwrap()
}

/// A cycle's output with fixed values.
struct Output {
    tau: Vec<f64>,
    level: [Vec<f64>; 2],
    mu: Vec<f64>,
    err: [Vec<f64>; 2],
}

impl Output {
    fn new() -> Output {
        Output {
            tau: vec![1.0, 2.0, 3.0, 4.0],
            level: [vec![0.5, -0.5, 0.25, 0.0], vec![0.0, 1.0, -1.0, 2.0]],
            mu: vec![0.1, 0.0, -0.1, 0.2],
            err: [vec![0.01], vec![0.1, 0.2, 0.3, 0.4]],
        }
    }
}

impl CycleOutput for Output {
    fn tau(&self) -> &[f64] {
        &self.tau
    }
    fn level_torque(&self, i: usize) -> &[f64] {
        &self.level[i]
    }
    fn tau_mu(&self) -> &[f64] {
        &self.mu
    }
    fn task_error(&self, i: usize) -> &[f64] {
        &self.err[i]
    }
    fn level_energy(&self, i: usize) -> f64 {
        [3.0, 5.0][i]
    }
    fn p_mu(&self) -> f64 {
        0.125
    }
    fn external_torque(&self) -> Option<&[f64]> {
        Some(&[0.5, -1.0, 2.0, 0.0])
    }
    fn contact(&self) -> Option<bool> {
        Some(true)
    }
    fn h(&self) -> Option<f64> {
        Some(11.5)
    }
    fn potential_in_h(&self, i: usize) -> Option<f64> {
        Some([1.0, 1.5][i])
    }
    fn tank(&self, i: usize) -> Option<(f64, f64)> {
        Some([(0.0, 1.0), (2.5, 0.75)][i])
    }
    fn desired(&self, i: usize) -> Option<&[f64]> {
        Some([&[0.35][..], &[0.0, -0.3, 0.0, -2.2]][i])
    }
}

/// Joint-space terms: J_1 selects joint 1, J_2 = I; J̄ = J stacked (not a
/// decomposition, only its shape matters here).
struct Terms {
    jac: [DMatrix<f64>; 2],
}

impl Terms {
    fn new() -> Terms {
        Terms {
            jac: [
                DMatrix::from_row_slice(1, 4, &[1.0, 0.0, 0.0, 0.0]),
                DMatrix::identity(4, 4),
            ],
        }
    }
}

impl LawTerms for Terms {
    fn task_jacobian(&self, i: usize) -> &DMatrix<f64> {
        &self.jac[i]
    }
    fn level_potential(&self, i: usize) -> f64 {
        [1.0, 2.0][i]
    }
    fn extended_jacobian(&self) -> Option<(Vec<usize>, DMatrix<f64>)> {
        let mut jbar = DMatrix::zeros(4, 4);
        jbar.fill_with_identity();
        Some((vec![1, 3], jbar))
    }
}

struct FixedEnergy;

impl EnergyModel for FixedEnergy {
    fn energy_at(
        &mut self,
        _t: f64,
        q: &DVector<f64>,
        _qd: &DVector<f64>,
    ) -> Result<(f64, f64), RecordError> {
        Ok((7.0, q[0]))
    }
}

/// A sink that keeps the rows it gets (as a file writer would stream them).
#[derive(Default)]
struct Rows(Vec<Vec<f64>>);

impl RowSink for Rows {
    fn push_row(&mut self, row: &[f64]) -> Result<(), RecordError> {
        self.0.push(row.to_vec());
        Ok(())
    }
}

fn state() -> (Vec<f64>, Vec<f64>) {
    (vec![0.4, -0.5, -1.6, 0.4], vec![0.1, 0.2, -0.3, 0.0])
}

#[test]
fn one_row_per_cycle_in_the_layout_of_column_names() {
    let s = scenario();
    let mut rec = Recorder::new(&s, true, Box::new(FixedEnergy)).unwrap();
    assert_eq!(rec.columns(), column_names(&s, true).as_slice());
    let (q, qd) = state();
    let (out, terms) = (Output::new(), Terms::new());
    let mut table = rec.trajectory(3).unwrap();
    let mut sink = Rows::default();
    for k in 0..3 {
        let cycle = Cycle {
            t: k as f64 * 1e-3,
            q: &q,
            qd: &qd,
            output: &out,
            law: Some(&terms),
        };
        rec.record(&cycle, &mut table).unwrap();
        rec.record(&cycle, &mut sink).unwrap();
    }
    assert_eq!(table.n_rows(), 3);
    assert_eq!(sink.0.len(), 3);
    assert_eq!(sink.0[2].as_slice(), table.row(2));
    assert_eq!(rec.last_row(), table.row(2));
    let get = |name: &str| table.column(name).unwrap()[1];
    assert_eq!(get("t"), 1e-3);
    assert_eq!(get("q3"), -1.6);
    assert_eq!(get("qd2"), 0.2);
    assert_eq!(get("tau4"), 4.0);
    assert_eq!(get("e1_1"), 0.01);
    assert_eq!(get("xd2_4"), -2.2);
    assert_eq!(get("e2_4"), 0.4);
    assert_eq!(get("S2"), 5.0);
    assert_eq!(get("P_mu"), 0.125);
    assert_eq!(get("tau_L2_4"), 2.0);
    assert_eq!(get("tau_mu_3"), -0.1);
    // S_i = kinetic + potential, V_i from the law.
    assert_eq!(get("S1_pot"), 1.0);
    assert_eq!(get("S1_kin"), 2.0);
    assert_eq!(get("S2_pot"), 2.0);
    assert_eq!(get("S2_kin"), 3.0);
    assert_eq!(get("E_kin"), 7.0);
    assert_eq!(get("E_pot"), 0.4);
    assert_eq!(get("tau_ext_3"), 2.0);
    assert_eq!(get("contact"), 1.0);
    // H and each level's potential in it, from the output.
    assert_eq!(get("H"), 11.5);
    assert_eq!(get("V_1"), 1.0);
    assert_eq!(get("V_2"), 1.5);
    assert_eq!(get("tank_2"), 2.5);
    assert_eq!(get("valve_2"), 0.75);
    // Joint levels only: no frame for a wrench estimate, no `f_ext_<k>`.
    assert_eq!(hcc_record::wrench_rows(&s), 0);
    assert!(table.column("f_ext_1").is_none());
}

#[test]
fn derived_columns_match_an_independent_computation() {
    let s = scenario();
    let mut rec = Recorder::new(&s, true, Box::new(FixedEnergy)).unwrap();
    let (q, qd) = state();
    let (out, terms) = (Output::new(), Terms::new());
    let mut table = rec.trajectory(1).unwrap();
    let cycle = Cycle {
        t: 0.0,
        q: &q,
        qd: &qd,
        output: &out,
        law: Some(&terms),
    };
    rec.record(&cycle, &mut table).unwrap();
    let mut data = hcc_model::Data::new(&s.model);
    hcc_model::crba(&s.model, &mut data, &DVector::from_column_slice(&q));
    let minv = data.m.clone().try_inverse().unwrap();
    let torques = [&out.level[0], &out.level[1], &out.mu];
    let acc = |i: usize, j: usize| {
        (&terms.jac[i] * &minv * DVector::from_column_slice(torques[j])).norm()
    };
    let got = |name: &str| table.column(name).unwrap()[0];
    for (name, want) in [
        ("acc1_2", acc(0, 1)),
        ("acc1_mu", acc(0, 2)),
        ("acc2_1", acc(1, 0)),
        ("acc2_mu", acc(1, 2)),
    ] {
        assert!(
            (got(name) - want).abs() <= 1e-9 * want.abs().max(1.0),
            "{name}: {} vs {want}",
            got(name)
        );
    }
    // J̄ = I here: accv<i>_<j> is the norm of the rows of block i of M⁻¹ τ_j.
    let x = &minv * DVector::from_column_slice(&out.level[1]);
    assert!((got("accv1_2") - x[0].abs()).abs() < 1e-9);
    let x = &minv * DVector::from_column_slice(&out.mu);
    assert!((got("accv2_mu") - x.rows(1, 3).norm()).abs() < 1e-9);
}

#[test]
fn unknown_law_terms_give_nan_columns() {
    let s = scenario();
    let mut rec = Recorder::new(&s, true, Box::new(FixedEnergy)).unwrap();
    let (q, qd) = state();
    let out = Output::new();
    let mut table = rec.trajectory(1).unwrap();
    let cycle = Cycle {
        t: 0.0,
        q: &q,
        qd: &qd,
        output: &out,
        law: None,
    };
    rec.record(&cycle, &mut table).unwrap();
    for (name, v) in table.columns().iter().zip(table.row(0)) {
        let split = name.starts_with('S') && (name.ends_with("_kin") || name.ends_with("_pot"));
        let derived = name.starts_with("acc") || split;
        assert_eq!(v.is_nan(), derived, "{name} = {v}");
    }
}

#[test]
fn bad_sizes_are_errors_not_panics() {
    let s = scenario();
    let mut rec = Recorder::new(&s, false, Box::new(FixedEnergy)).unwrap();
    let (q, qd) = state();
    let terms = Terms::new();
    let mut sink = Rows::default();
    let mut out = Output::new();
    out.mu.pop();
    let cycle = Cycle {
        t: 0.5,
        q: &q,
        qd: &qd,
        output: &out,
        law: Some(&terms),
    };
    let e = rec.record(&cycle, &mut sink).unwrap_err().to_string();
    assert!(e.contains("tau_mu") && e.contains("t = 0.5 s"), "{e}");

    let out = Output::new();
    let short = &q[..3];
    let cycle = Cycle {
        q: short,
        output: &out,
        ..cycle
    };
    let e = rec.record(&cycle, &mut sink).unwrap_err().to_string();
    assert!(e.contains("q has length 3"), "{e}");

    let mut terms = Terms::new();
    terms.jac[1] = DMatrix::zeros(3, 4);
    let cycle = Cycle {
        q: &q,
        law: Some(&terms),
        ..cycle
    };
    let e = rec.record(&cycle, &mut sink).unwrap_err().to_string();
    assert!(e.contains("J_2 is 3×4, expected 4×4"), "{e}");
    assert!(sink.0.is_empty());
}

#[test]
fn with_v_needs_the_extended_jacobian() {
    struct NoJbar(Terms);
    impl LawTerms for NoJbar {
        fn task_jacobian(&self, i: usize) -> &DMatrix<f64> {
            self.0.task_jacobian(i)
        }
        fn level_potential(&self, i: usize) -> f64 {
            self.0.level_potential(i)
        }
        fn extended_jacobian(&self) -> Option<(Vec<usize>, DMatrix<f64>)> {
            None
        }
    }
    let s = scenario();
    let mut rec = Recorder::new(&s, true, Box::new(FixedEnergy)).unwrap();
    let (q, qd) = state();
    let (out, terms) = (Output::new(), NoJbar(Terms::new()));
    let cycle = Cycle {
        t: 0.0,
        q: &q,
        qd: &qd,
        output: &out,
        law: Some(&terms),
    };
    let e = rec.record(&cycle, &mut Rows::default()).unwrap_err();
    assert!(e.to_string().contains("no J̄"), "{e}");
    // Without the accv columns it is not asked for.
    let mut rec = Recorder::new(&s, false, Box::new(FixedEnergy)).unwrap();
    rec.record(&cycle, &mut Rows::default()).unwrap();
}
