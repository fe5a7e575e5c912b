//! Ctrl-C on `hcc run`: the launcher stops both daemons (SIGTERM by pid),
//! waits for them, writes the partial results and exits with an error; no
//! process and no shared memory of the run is left.

use hcc_system_tests::*;
use std::process::Command;
use std::time::{Duration, Instant};

#[test]
fn sigint_stops_both_daemons_and_keeps_partial_results() {
    let dir = TempDir::new("run_interrupt");
    let namespace = unique_namespace("run_interrupt");
    let prefix = unique_file_prefix();
    let out = dir.path().join("run");
    let err_path = dir.path().join("run.stderr");

    let mut run = ChildGuard::spawn(
        Command::new(bin("hcc"))
            .current_dir(repo_root())
            .env(FILE_PREFIX_ENV, &prefix)
            .args([
                "run",
                "config/paper-sim1.toml",
                "--duration",
                "60",
                "--no-plots",
            ])
            .args(["--namespace", &namespace])
            .arg("--out")
            .arg(&out)
            .stdout(std::fs::File::create(dir.path().join("run.stdout")).unwrap())
            .stderr(std::fs::File::create(&err_path).unwrap()),
    );
    // Wait until the run is under way (a progress line), then press Ctrl-C.
    let start = Instant::now();
    loop {
        let err = std::fs::read_to_string(&err_path).unwrap_or_default();
        if err.contains("hcc run: t =") {
            break;
        }
        assert!(
            run.child.try_wait().unwrap().is_none(),
            "hcc run ended early:\n{err}"
        );
        assert!(
            start.elapsed() < Duration::from_secs(60),
            "no progress:\n{err}"
        );
        std::thread::sleep(Duration::from_millis(50));
    }
    assert_eq!(
        processes_with(&namespace).len(),
        3,
        "hcc run, hcc-sim and hcc-controller should be running: {:?}",
        processes_with(&namespace)
    );
    let status = Command::new("kill")
        .args(["-INT", &run.pid().to_string()])
        .status()
        .unwrap();
    assert!(status.success());
    let status = run
        .wait_timeout(Duration::from_secs(30))
        .expect("hcc run did not stop within 30 s of SIGINT");
    let err = std::fs::read_to_string(&err_path).unwrap_or_default();
    assert!(!status.success(), "an interrupted run reports failure");
    assert!(err.contains("interrupted"), "{err}");
    // Partial results.
    let (_, rows) = read_csv(&out.join("trajectory.csv"));
    assert!(rows.len() > 100, "{} rows", rows.len());

    assert_clean(&namespace, &prefix);
}
