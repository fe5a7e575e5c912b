//! End-to-end: a synthetic two-level run written to a directory, read back, replotted.

use hcc_report::{
    ErrorUnit, LevelDescription, Metrics, RunDescription, Trajectory, columns, replot, write_run,
};
use std::collections::BTreeMap;

mod common;

use common::out_dir;

fn synthetic() -> (Trajectory, RunDescription) {
    let n = 2;
    let dims = [2, 1];
    let mut cols = columns::required(n, &dims);
    for i in 1..=2 {
        for k in 1..=n {
            cols.push(columns::level_torque(i, k));
        }
    }
    cols.push(columns::disturbing_acceleration(1, 2));
    cols.push(columns::disturbing_acceleration(2, 1));
    cols.push(columns::energy_kinetic(1));
    cols.push(columns::energy_potential(1));
    let mut traj = Trajectory::new(cols).unwrap();
    for k in 0..=500 {
        let t = k as f64 * 1e-3;
        let a = (-8.0 * t).exp();
        let b = (-3.0 * t).exp() * (20.0 * t).cos();
        traj.push_row(&[
            t,
            a,
            b,
            -8.0 * a,
            -3.0 * b,
            10.0 * a,
            -5.0 * b,
            0.06 * a,
            -0.16 * a,
            0.2 * b,
            a * a,
            b * b,
            1e-15 * b,
            6.0 * a,
            4.0 * a,
            -3.0 * b,
            -2.0 * b,
            1e-14 * (30.0 * t).sin(),
            2.0 * a,
            0.3 * a * a,
            0.7 * a * a,
        ])
        .unwrap();
    }
    let run = RunDescription {
        scenario: "synthetic".into(),
        n_joints: n,
        levels: vec![
            LevelDescription {
                name: "TCP position".into(),
                dim: 2,
                unit: ErrorUnit::Meter,
                row_units: Vec::new(),
            },
            LevelDescription {
                name: "joint 1".into(),
                dim: 1,
                unit: ErrorUnit::Radian,
                row_units: Vec::new(),
            },
        ],
        settings: BTreeMap::from([("control_rate_hz".to_string(), serde_json::json!(1000.0))]),
    };
    (traj, run)
}

#[test]
fn write_read_and_replot() {
    let (traj, run) = synthetic();
    let dir = out_dir("write-run");
    let out = write_run(&dir, &traj, &run).unwrap();
    for f in [
        "trajectory.csv",
        "metrics.json",
        "errors.png",
        "torques.png",
        "disturbing_accelerations.png",
        "energies.png",
        "joints.png",
    ] {
        let p = dir.join(f);
        assert!(out.files.contains(&p), "{f} not reported");
        assert!(std::fs::metadata(&p).unwrap().len() > 1000, "{f} too small");
    }
    let back = Trajectory::read_csv(&dir.join("trajectory.csv")).unwrap();
    assert_eq!(back, traj);
    let m = Metrics::read_json(&dir.join("metrics.json")).unwrap();
    assert_eq!(m, out.metrics);
    assert_eq!(m.levels.len(), 2);
    assert!(m.max_disturbing_acceleration["acc2_1"] > 1.9);
    std::fs::remove_file(dir.join("errors.png")).unwrap();
    let files = replot(&dir).unwrap();
    assert!(files.contains(&dir.join("errors.png")));
    if std::env::var_os("HCC_KEEP_TEST_OUTPUT").is_none() {
        let _ = std::fs::remove_dir_all(&dir);
    } else {
        eprintln!("output kept in {}", dir.display());
    }
}

#[test]
fn replot_of_a_missing_directory_names_the_file() {
    let dir = out_dir("missing");
    let e = replot(&dir).unwrap_err().to_string();
    assert!(e.contains("trajectory.csv"), "{e}");
}
