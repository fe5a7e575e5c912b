//! The driver skeleton against the real controller daemon: hcc-driver-example
//! (stub hardware, joints frozen at q0) publishes states at 1 kHz, the
//! controller answers them, the driver applies the commands that pass the
//! contract's checks; at the end of its run it stops (Stopping, Stopped) and
//! exits cleanly.

use hcc_system_tests::*;
use std::process::Command;
use std::time::Duration;

fn count_before(text: &str, label: &str) -> u64 {
    let i = text
        .find(label)
        .unwrap_or_else(|| panic!("{label:?} not in {text:?}"));
    text[..i]
        .split_whitespace()
        .last()
        .and_then(|w| w.parse().ok())
        .unwrap_or_else(|| panic!("no count before {label:?} in {text:?}"))
}

#[test]
fn driver_skeleton_applies_the_controllers_commands() {
    let dir = TempDir::new("driver_example");
    let namespace = unique_namespace("driver_example");
    let prefix = unique_file_prefix();
    let config = repo_root().join("config/paper-sim1.toml");

    let mut controller = ChildGuard::spawn(
        Command::new(bin("hcc-controller"))
            .env(FILE_PREFIX_ENV, &prefix)
            .arg(&config)
            .args(["--namespace", &namespace])
            .stdout(std::fs::File::create(dir.path().join("controller.stdout")).unwrap())
            .stderr(std::fs::File::create(dir.path().join("controller.stderr")).unwrap()),
    );
    let driver = run_with_timeout(
        Command::new(bin("hcc-driver-example"))
            .env(FILE_PREFIX_ENV, &prefix)
            .arg(&config)
            .args(["--namespace", &namespace, "--duration", "2"]),
        dir.path(),
        "driver",
        Duration::from_secs(60),
    );
    let _ = Command::new("kill")
        .args(["-TERM", &controller.pid().to_string()])
        .status();
    controller.wait_timeout(Duration::from_secs(10));
    assert!(driver.status.success(), "driver failed\n{}", driver.log());
    println!("{}", driver.stdout);

    let applied = count_before(&driver.stdout, "commands applied");
    assert!(applied > 0, "no command applied\n{}", driver.log());
    assert_eq!(count_before(&driver.stdout, "invalid"), 0);
    assert_eq!(count_before(&driver.stdout, "gravity conflict"), 0);
    assert_eq!(count_before(&driver.stdout, "future"), 0);
    assert!(
        driver.stdout.contains("stop: Requested"),
        "{}",
        driver.log()
    );

    assert_clean(&namespace, &prefix);
}
