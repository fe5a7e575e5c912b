//! The streaming writer gives the outputs of the in-memory table: the same
//! CSV bytes, the same metrics (every figure, bit for bit), on tables built to
//! exercise each figure (rises of the energy, NaN, mixed units).

use hcc_report::{
    CsvWriter, ErrorUnit, LevelDescription, Metrics, MetricsAccumulator, RunDescription, RunWriter,
    Trajectory, columns,
};
use std::collections::BTreeMap;

mod common;

use common::out_dir;

/// Two joints; a 3-D level of mixed units, a 1-D joint level; energies that
/// rise at a few times (a push, a setpoint change) and a NaN in the second.
fn table(rows: usize, nan_at: Option<usize>) -> (Trajectory, RunDescription) {
    let mut cols = columns::required(2, &[3, 1]);
    cols.push(columns::disturbing_acceleration(1, 2));
    cols.push(columns::null_space_acceleration(2, 1));
    let mut traj = Trajectory::new(cols).unwrap();
    for k in 0..rows {
        let t = k as f64 * 1e-3;
        let a = (-5.0 * t).exp() * (1.0 + 0.3 * (40.0 * t).sin());
        let push = if (300..320).contains(&k) { 0.01 } else { 0.0 };
        let s1 = a * a + push + if k > 700 { 1e-3 } else { 0.0 };
        let s2 = if nan_at == Some(k) {
            f64::NAN
        } else {
            (0.5 - t).abs()
        };
        traj.push_row(&[
            t,
            a,
            -a,
            3.0 * a,
            -2.0 * a,
            40.0 * a - 7.0,
            (k as f64).sin(),
            0.1 * a,
            -0.02 * a + push,
            0.002 * (30.0 * t).cos() * a,
            (2.0 - t).max(0.0) * 1e-3,
            s1,
            s2,
            1e-16 * (k as f64).cos(),
            0.5 * a,
            if k == 400 { -9.0 } else { a },
        ])
        .unwrap();
    }
    let run = RunDescription {
        scenario: "streaming".into(),
        n_joints: 2,
        levels: vec![
            LevelDescription {
                name: "pose".into(),
                dim: 3,
                unit: ErrorUnit::Mixed,
                row_units: vec![ErrorUnit::Meter, ErrorUnit::Meter, ErrorUnit::Radian],
            },
            LevelDescription {
                name: "joint".into(),
                dim: 1,
                unit: ErrorUnit::Radian,
                row_units: Vec::new(),
            },
        ],
        settings: BTreeMap::from([("note".to_string(), serde_json::json!("x"))]),
    };
    (traj, run)
}

fn online(traj: &Trajectory, run: &RunDescription) -> Metrics {
    let mut acc = MetricsAccumulator::new(traj.columns(), run).unwrap();
    for row in traj.rows() {
        acc.push_row(row).unwrap();
    }
    acc.finish(run).unwrap()
}

#[test]
fn online_metrics_equal_the_batch_metrics() {
    for (rows, nan_at) in [
        (1, None),
        (2, None),
        (1000, None),
        (2500, Some(1200)),
        (900, Some(899)),
    ] {
        let (traj, run) = table(rows, nan_at);
        let batch = Metrics::compute(&traj, &run).unwrap();
        let streamed = online(&traj, &run);
        // Compare the JSON too: NaN ≠ NaN would fail `==` on equal figures.
        assert_eq!(
            serde_json::to_string(&streamed).unwrap(),
            serde_json::to_string(&batch).unwrap(),
            "{rows} rows"
        );
        assert!(!batch.levels[0].by_unit.is_empty());
    }
    // The table exercises the energy's rises: not non-increasing from 0.
    let (traj, run) = table(1000, None);
    let m = Metrics::compute(&traj, &run).unwrap();
    assert!(m.levels[0].energy_non_increasing_from_s.unwrap() > 0.7);
}

#[test]
fn online_metrics_fail_like_the_batch_metrics() {
    let (traj, run) = table(10, None);
    let acc = MetricsAccumulator::new(traj.columns(), &run).unwrap();
    let e = acc.finish(&run).unwrap_err().to_string();
    assert!(e.contains("no rows"), "{e}");
    let cols: Vec<String> = traj.columns()[..5].to_vec();
    let e = MetricsAccumulator::new(&cols, &run)
        .unwrap_err()
        .to_string();
    assert!(e.contains("no column"), "{e}");
}

#[test]
fn streamed_csv_is_identical_and_results_match() {
    let (traj, run) = table(1500, Some(3));
    let dir = out_dir("streaming");
    std::fs::create_dir_all(&dir).unwrap();
    let csv = dir.join("direct.csv");
    let mut w = CsvWriter::create(&csv, traj.columns()).unwrap();
    for row in traj.rows() {
        w.push_row(row).unwrap();
    }
    assert_eq!(w.rows(), 1500);
    w.finish().unwrap();
    assert_eq!(std::fs::read_to_string(&csv).unwrap(), traj.to_csv_string());

    let out = dir.join("run");
    let mut rw = RunWriter::new(&out, traj.columns().to_vec(), &run, false).unwrap();
    assert!(!out.exists(), "nothing is written before the first row");
    for row in traj.rows() {
        rw.push_row(row).unwrap();
    }
    let res = rw.finish(&run).unwrap();
    assert_eq!(
        std::fs::read_to_string(out.join("trajectory.csv")).unwrap(),
        traj.to_csv_string()
    );
    assert_eq!(
        serde_json::to_string(&res.metrics).unwrap(),
        serde_json::to_string(&Metrics::compute(&traj, &run).unwrap()).unwrap()
    );
    assert_eq!(res.files.len(), 2);
    let _ = std::fs::remove_dir_all(&dir);
}
