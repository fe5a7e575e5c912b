//! `hcc model` as a user runs it: the Panda reference states in, the same keys out,
//! equal to the Pinocchio values; bad input gives an error naming the file.

use hcc_system_tests::*;
use std::process::Command;

fn matrix_rows(v: &serde_json::Value) -> Vec<f64> {
    match v {
        serde_json::Value::Array(a) => a.iter().flat_map(matrix_rows).collect(),
        serde_json::Value::Number(x) => vec![x.as_f64().unwrap()],
        other => panic!("unexpected JSON value {other}"),
    }
}

#[test]
fn hcc_model_reproduces_the_panda_reference() {
    let root = repo_root();
    let reference = root.join("tests/data/panda_dynamics.json");
    let out = Command::new(bin("hcc"))
        .current_dir(&root)
        .args([
            "model",
            "--urdf",
            "config/robots/panda/panda.urdf",
            "--tip",
            "panda_hand_tcp",
            "--states",
        ])
        .arg(&reference)
        .output()
        .expect("run hcc model");
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let got: serde_json::Value = serde_json::from_slice(&out.stdout).expect("JSON output");
    let want = read_json(&reference);
    let (got, want) = (
        got["states"].as_array().unwrap(),
        want["states"].as_array().unwrap(),
    );
    assert_eq!(got.len(), want.len());
    for (k, (g, w)) in got.iter().zip(want).enumerate() {
        for key in [
            "M",
            "C",
            "g",
            "nle",
            "qdd_forward_dynamics",
            "tip_position",
            "tip_rotation",
            "tip_jacobian",
            "tip_jdot_qd",
        ] {
            let (a, b) = (matrix_rows(&g[key]), matrix_rows(&w[key]));
            let d: f64 = a
                .iter()
                .zip(&b)
                .map(|(x, y)| (x - y).powi(2))
                .sum::<f64>()
                .sqrt();
            let nb: f64 = b.iter().map(|y| y * y).sum::<f64>().sqrt();
            assert!(
                a.len() == b.len() && d <= 1e-9 * nb.max(1.0),
                "state {k} {key}: deviation {d:e}"
            );
        }
    }
}

#[test]
fn hcc_model_names_the_bad_file() {
    let root = repo_root();
    let out = Command::new(bin("hcc"))
        .current_dir(&root)
        .args([
            "model",
            "--urdf",
            "no/such.urdf",
            "--tip",
            "x",
            "--states",
            "tests/data/panda_dynamics.json",
        ])
        .output()
        .expect("run hcc model");
    assert!(!out.status.success());
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(
        err.contains("no/such.urdf") && !err.contains("panicked"),
        "{err}"
    );
}
