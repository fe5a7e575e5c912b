//! A scenario whose levels follow paths (`trajectory`, docs/tracking.md),
//! simulated, then replayed from its recording alone: the recording carries
//! the path files' texts with the scenario's, so `hcc replay` rebuilds the
//! same paths after the files are gone, every torque bit-identical.

use std::process::Command;
use std::time::Duration;

use hcc_system_tests::*;

#[test]
fn a_path_scenario_replays_bit_for_bit_without_its_path_files() {
    let dir = TempDir::new("tracking_replay");
    let root = repo_root();
    let urdf = root.join("config/robots/panda/panda.urdf");
    let text = std::fs::read_to_string(root.join("config/panda-figure-eight.toml"))
        .unwrap()
        .replace(
            "urdf = \"robots/panda/panda.urdf\"",
            &format!("urdf = {:?}", urdf.to_string_lossy()),
        );
    let paths = dir.path().join("paths");
    std::fs::create_dir_all(&paths).unwrap();
    for f in [
        "panda-figure-eight-tcp.csv",
        "panda-figure-eight-joint3.csv",
    ] {
        std::fs::copy(root.join("config/paths").join(f), paths.join(f)).unwrap();
    }
    let config = dir.path().join("figure-eight.toml");
    std::fs::write(&config, text).unwrap();

    let sim = run_with_timeout(
        Command::new(bin("hcc"))
            .arg("simulate")
            .arg(&config)
            .args(["--duration", "1.5", "--no-plots", "--out"])
            .arg(dir.path().join("sim")),
        dir.path(),
        "simulate",
        Duration::from_secs(120),
    );
    assert!(sim.status.success(), "hcc simulate failed\n{}", sim.log());

    std::fs::remove_dir_all(&paths).unwrap();
    let replay = run_with_timeout(
        Command::new(bin("hcc"))
            .arg("replay")
            .arg(dir.path().join("sim/run.mcap")),
        dir.path(),
        "replay",
        Duration::from_secs(120),
    );
    let log = replay.log();
    println!("{log}");
    assert!(replay.status.success(), "{log}");
    assert!(log.contains("every torque bit-identical"), "{log}");
}
