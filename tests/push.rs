//! An external push on the simulated robot (a `[[simulation.wrench]]` acting in
//! hcc-sim only; the controller never sees it) is resisted compliantly: the
//! TCP gives way by about F / K_1 (level 1: K_1 = 1000 N/m), no more, and
//! returns to its goal after the push ends.

use hcc_system_tests::*;
use std::process::Command;
use std::time::Duration;

const PUSH: &str = r#"
# Test push: 10 N along x on the TCP from 1.0 s to 1.5 s.
[[simulation.wrench]]
start_s = 1.0
duration_s = 0.5
link = "tcp"
force = [10.0, 0.0, 0.0]
"#;

#[test]
fn a_push_is_resisted_compliantly_and_the_arm_returns() {
    let dir = TempDir::new("push");
    let namespace = unique_namespace("push");
    let prefix = unique_file_prefix();
    let config = scenario_copy("paper-sim1.toml", dir.path(), PUSH);
    let out = dir.path().join("run");

    let run = run_with_timeout(
        Command::new(bin("hcc"))
            .current_dir(repo_root())
            .env(FILE_PREFIX_ENV, &prefix)
            .arg("run")
            .arg(&config)
            .args(["--lockstep", "--duration", "3", "--no-plots"])
            .args(["--namespace", &namespace])
            .arg("--out")
            .arg(&out),
        dir.path(),
        "run",
        Duration::from_secs(300),
    );
    assert!(run.status.success(), "hcc run failed\n{}", run.log());

    let (header, rows) = read_csv(&out.join("trajectory.csv"));
    let col = |name: &str| header.iter().position(|c| c == name).expect(name);
    let (t, ex, ey) = (col("t"), col("e1_1"), col("e1_2"));
    let err = |r: &Vec<f64>| (r[ex] * r[ex] + r[ey] * r[ey]).sqrt();
    let max_in = |a: f64, b: f64| {
        rows.iter()
            .filter(|r| r[t] >= a && r[t] < b)
            .map(err)
            .fold(0.0_f64, f64::max)
    };
    let before = max_in(0.9, 1.0);
    let during = max_in(1.0, 1.5);
    let end = max_in(2.9, 3.01);
    println!(
        "TCP error: before the push {before:.2e} m, during {during:.4} m (F/K1 = 0.01 m), at the end {end:.2e} m"
    );
    assert!(before < 1e-3, "not converged before the push: {before} m");
    // Compliant: it gives way (nonzero), by about F/K1, bounded.
    assert!(
        during > 3e-3 && during < 3e-2,
        "deflection during the push {during} m, expected about 0.01 m"
    );
    assert!(end < 1e-3, "the arm did not return after the push: {end} m");

    assert_clean(&namespace, &prefix);
}
