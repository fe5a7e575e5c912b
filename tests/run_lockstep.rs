//! `hcc run --lockstep`: the two daemons (hcc-sim, hcc-controller) as real
//! processes over iceoryx2, the simulator waiting for every command, give
//! the same trajectory as the in-process `hcc simulate` — every column of
//! every row, to 1e-12.

use hcc_system_tests::*;
use std::process::Command;
use std::time::Duration;

#[test]
fn lockstep_run_over_ipc_reproduces_hcc_simulate() {
    let dir = TempDir::new("run_lockstep");
    let namespace = unique_namespace("run_lockstep");
    let prefix = unique_file_prefix();
    let config = repo_root().join("config/paper-sim1.toml");

    let sim = run_with_timeout(
        Command::new(bin("hcc"))
            .current_dir(repo_root())
            .arg("simulate")
            .arg(&config)
            .arg("--out")
            .arg(dir.path().join("simulate"))
            .arg("--no-plots"),
        dir.path(),
        "simulate",
        Duration::from_secs(120),
    );
    assert!(sim.status.success(), "hcc simulate failed\n{}", sim.log());

    let run = run_with_timeout(
        Command::new(bin("hcc"))
            .current_dir(repo_root())
            .env(FILE_PREFIX_ENV, &prefix)
            .arg("run")
            .arg(&config)
            .arg("--lockstep")
            .args(["--namespace", &namespace])
            .arg("--out")
            .arg(dir.path().join("run"))
            .arg("--no-plots"),
        dir.path(),
        "run",
        Duration::from_secs(300),
    );
    assert!(
        run.status.success(),
        "hcc run --lockstep failed\n{}",
        run.log()
    );

    let a = read_csv(&dir.path().join("simulate/trajectory.csv"));
    let b = read_csv(&dir.path().join("run/trajectory.csv"));
    let (worst, column, row) = max_csv_difference(&a, &b);
    println!(
        "{} rows x {} columns; largest difference {worst:e} (column {column}, row {row})",
        a.1.len(),
        a.0.len()
    );
    assert!(
        worst <= 1e-12,
        "hcc run --lockstep differs from hcc simulate by {worst:e} in column {column} at row {row}"
    );
    assert_eq!(a.1.len(), 3001, "3 s at 1 kHz, both ends included");

    // The recorder lost nothing and says so.
    let metrics = read_json(&dir.path().join("run/metrics.json"));
    let ipc = &metrics["run"]["settings"]["ipc"];
    assert_eq!(ipc["mode"], "lockstep", "{ipc}");
    for stream in ["joint_state", "torque_command", "telemetry"] {
        assert_eq!(ipc["recorder_gaps"][stream], 0, "{ipc}");
    }
    assert_eq!(ipc["rows"], ipc["expected_rows"], "{ipc}");
    assert!(run.stdout.contains("latency"), "{}", run.log());

    assert_clean(&namespace, &prefix);
}
