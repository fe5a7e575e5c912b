//! A daemon that fails makes `hcc run` fail: here hcc-sim cannot publish joint
//! states because another driver already does in the namespace (the contract
//! allows one publisher per service). The launcher stops the controller,
//! exits with an error that carries the tail of hcc-sim's stderr, and leaves
//! no process behind.

use hcc_system_tests::*;
use std::process::Command;
use std::time::{Duration, Instant};

#[test]
fn a_failing_daemon_stops_the_run_with_its_stderr() {
    let dir = TempDir::new("run_child_failure");
    let namespace = unique_namespace("run_child_failure");
    let prefix = unique_file_prefix();
    let config = repo_root().join("config/paper-sim1.toml");
    let driver_err = dir.path().join("driver.stderr");

    // Another driver owns the joint states of the namespace.
    let mut driver = ChildGuard::spawn(
        Command::new(bin("hcc-driver-example"))
            .env(FILE_PREFIX_ENV, &prefix)
            .arg(&config)
            .args(["--namespace", &namespace])
            // No controller answers it until hcc run starts one: without a
            // long fallback timeout it would stop after 100 ms of misses and
            // free the service before hcc-sim tries to open it.
            .args(["--fallback-timeout-ms", "600000"])
            .stdout(std::fs::File::create(dir.path().join("driver.stdout")).unwrap())
            .stderr(std::fs::File::create(&driver_err).unwrap()),
    );
    let start = Instant::now();
    while !std::fs::read_to_string(&driver_err)
        .unwrap_or_default()
        .contains("joints at")
    {
        assert!(start.elapsed() < Duration::from_secs(30), "driver not up");
        std::thread::sleep(Duration::from_millis(20));
    }

    let run = run_with_timeout(
        Command::new(bin("hcc"))
            .current_dir(repo_root())
            .env(FILE_PREFIX_ENV, &prefix)
            .arg("run")
            .arg(&config)
            .args(["--namespace", &namespace, "--no-plots"])
            .arg("--out")
            .arg(dir.path().join("run")),
        dir.path(),
        "run",
        Duration::from_secs(60),
    );
    let _ = Command::new("kill")
        .args(["-TERM", &driver.pid().to_string()])
        .status();
    driver.wait_timeout(Duration::from_secs(10));

    assert!(!run.status.success(), "hcc run succeeded\n{}", run.log());
    assert!(
        run.stderr.contains("hcc-sim") && run.stderr.contains("already has a publisher"),
        "the error should name hcc-sim and quote its stderr\n{}",
        run.log()
    );
    assert_clean(&namespace, &prefix);
}
