//! `hcc record` attached to a controller and a simulator that were started
//! on their own (by hand, as a user runs a robot), not by `hcc run`:
//!
//! * it records all four streams from the moment it attaches, nothing lost,
//!   and `hcc plot` derives the results from the file;
//! * `hcc replay` of a recording that starts mid-run: a fresh controller
//!   takes over at the first recorded state; with the paper's arm at rest,
//!   no setpoint and a one-dimensional null space (its basis unique up to a
//!   sign the controller keeps), nothing of the daemon's history matters and
//!   every torque is bit-identical;
//! * the controller's log accounts for the recorder's connections: made
//!   while it waits (its connection upkeep), or — when the recorder attached
//!   while the loop was busy or blocked on a late state — by the next send,
//!   then counted as allocations on the torque path. Which of the two
//!   happens is a matter of timing here, so it is printed, not asserted; the
//!   upkeep itself is proven deterministically by
//!   `crates/daemons/controller/tests/loop_no_alloc.rs`.

mod monitor;

use std::process::Command;
use std::time::Duration;

use hcc_system_tests::*;
use monitor::{Daemon, Monitor};

/// The largest count of the controller's upkeep lines ("peer connections
/// made or dropped while waiting: N") in `log`.
fn upkeep_count(log: &str) -> u64 {
    const KEY: &str = "peer connections made or dropped while waiting: ";
    log.match_indices(KEY)
        .filter_map(|(i, _)| {
            let rest = &log[i + KEY.len()..];
            rest.split_whitespace().next()?.parse().ok()
        })
        .max()
        .unwrap_or(0)
}

#[test]
fn hcc_record_attached_to_daemons_started_by_hand() {
    let dir = TempDir::new("record_attach");
    let ns = unique_namespace("record_attach");
    let prefix = unique_file_prefix();
    let config = repo_root().join("config/paper-sim1.toml");
    let file = dir.path().join("attached.mcap");
    {
        let mut mon = Monitor::new(&ns, &prefix);
        let mut ctl = Daemon::controller(&ns, &prefix, dir.path(), "controller");
        let mut sim = Daemon::sim(&ns, &prefix, dir.path(), "sim");
        mon.wait_until(
            "1500 cycles before the recorder attaches",
            Duration::from_secs(60),
            |m| m.telemetry.len() >= 1500,
        );
        // The logging thread reports every 100 ms.
        std::thread::sleep(Duration::from_millis(300));
        let before = upkeep_count(&ctl.log());
        let rec = run_with_timeout(
            Command::new(bin("hcc"))
                .args(["record", "--namespace", &ns, "--file-prefix", &prefix])
                .args(["--duration", "2", "--quiet", "--config"])
                .arg(&config)
                .arg("--out")
                .arg(&file),
            dir.path(),
            "record",
            Duration::from_secs(60),
        );
        assert!(rec.status.success(), "hcc record failed:\n{}", rec.log());
        let out = rec.log();
        println!("{out}");
        assert!(out.contains("recorded "), "{out}");
        // Give the controller's logging thread (100 ms) time to report.
        std::thread::sleep(Duration::from_millis(300));
        sim.stop();
        ctl.stop();
        let log = ctl.log();
        println!("controller log:\n{log}");
        println!(
            "connection updates while waiting: {before} before the recorder, {} after",
            upkeep_count(&log)
        );
        assert!(
            log.contains("rt system allocations on the torque path after warm-up"),
            "{log}"
        );
    }
    assert_clean(&ns, &prefix);

    // The file: every stream, from the attach on (not from the start).
    let plot = run_with_timeout(
        Command::new(bin("hcc"))
            .arg("plot")
            .arg(&file)
            .arg("--out")
            .arg(dir.path().join("plot")),
        dir.path(),
        "plot",
        Duration::from_secs(120),
    );
    assert!(plot.status.success(), "hcc plot failed:\n{}", plot.log());
    let metrics = read_json(&dir.path().join("plot/metrics.json"));
    println!("{metrics:#}");
    let (_, rows) = read_csv(&dir.path().join("plot/trajectory.csv"));
    assert!(rows.len() > 1500, "rows: {}", rows.len());
    let t0 = rows[0][0];
    assert!(t0 >= 1.4, "the recording starts mid-run, not at t = {t0}");

    // Replay from the middle of the run.
    let replay = run_with_timeout(
        Command::new(bin("hcc")).arg("replay").arg(&file),
        dir.path(),
        "replay",
        Duration::from_secs(120),
    );
    let log = replay.log();
    println!("{log}");
    assert!(replay.status.success(), "{log}");
    assert!(log.contains("every torque bit-identical"), "{log}");
}
