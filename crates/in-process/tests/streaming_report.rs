//! The streaming report of real closed-loop runs: the online metrics equal
//! `Metrics::compute` on the full table, figure for figure, and the streamed
//! `trajectory.csv` has the bytes of the table's CSV.

use hcc_config::Scenario;
use hcc_in_process::{Run, simulate};
use hcc_report::{Metrics, MetricsAccumulator, RunWriter};
use std::path::PathBuf;

fn run(name: &str, duration: f64) -> Run {
    let path = PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("../../config")
        .join(name);
    let mut s = Scenario::load(path).unwrap();
    s.set_duration(duration).unwrap();
    simulate(&s).unwrap()
}

/// Metrics as JSON (NaN-safe comparison of every figure).
fn json(m: &Metrics) -> String {
    serde_json::to_string(m).unwrap()
}

#[test]
fn online_metrics_of_real_runs_equal_the_batch_metrics() {
    // A pose level of mixed units (by-unit groups), and a push by an external
    // wrench (the energies rise and fall again).
    for (name, duration) in [
        ("panda-cartesian-impedance.toml", 0.8),
        ("panda-null-space-comparison-push.toml", 1.2),
    ] {
        let run = run(name, duration);
        let traj = &run.trajectory;
        let mut acc = MetricsAccumulator::new(traj.columns(), &run.description).unwrap();
        for row in traj.rows() {
            acc.push_row(row).unwrap();
        }
        let online = acc.finish(&run.description).unwrap();
        let batch = Metrics::compute(traj, &run.description).unwrap();
        assert_eq!(json(&online), json(&batch), "{name}");
    }
}

#[test]
fn streamed_results_of_a_real_run_equal_the_in_memory_ones() {
    let run = run("paper-sim1.toml", 0.3);
    let traj = &run.trajectory;
    let base = option_env!("CARGO_TARGET_TMPDIR")
        .map(PathBuf::from)
        .unwrap_or_else(std::env::temp_dir);
    let dir = base.join(format!("hcc-plant-streaming-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    let mut w = RunWriter::new(&dir, traj.columns().to_vec(), &run.description, false).unwrap();
    for row in traj.rows() {
        w.push_row(row).unwrap();
    }
    let out = w.finish(&run.description).unwrap();
    let csv = std::fs::read_to_string(dir.join(hcc_report::TRAJECTORY_FILE)).unwrap();
    assert!(csv == traj.to_csv_string(), "the streamed CSV differs");
    let batch = Metrics::compute(traj, &run.description).unwrap();
    assert_eq!(json(&out.metrics), json(&batch));
    let _ = std::fs::remove_dir_all(&dir);
}
