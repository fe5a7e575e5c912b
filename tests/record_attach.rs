//! `hcc record` attached to a controller and a simulator that were started
//! on their own (by hand, as a user runs a robot), not by `hcc run`:
//!
//! * it records all four streams from the moment it attaches, nothing lost,
//!   and the scenario the controller publishes on its scenario service (no
//!   `--config`); `hcc plot` derives the results from the file alone;
//! * `hcc replay` of a recording that starts mid-run: a fresh controller
//!   takes over at the first recorded state; with the paper's arm at rest,
//!   no setpoint and a one-dimensional null space (its basis unique up to a
//!   sign the controller keeps), nothing of the daemon's history matters and
//!   every torque is bit-identical;
//! * a recording across a simulator killed and started again (as a user
//!   swaps the simulator for a driver), and across a controller killed and
//!   started again: the recorder counts the restarted streams, `hcc plot`
//!   derives every cycle, `hcc replay` follows the new daemon (numbering
//!   from the start again; a fresh control cycle for a new controller) bit
//!   for bit;
//! * the controller's log accounts for the recorder's connections: made
//!   while it waits (its connection upkeep), or — when the recorder attached
//!   while the loop was busy or blocked on a late state — by the next send,
//!   then counted as allocations on the torque path. Which of the two
//!   happens is a matter of timing here, so it is printed, not asserted; the
//!   upkeep itself is proven deterministically by
//!   `crates/daemons/controller/tests/loop_no_alloc.rs`.

mod monitor;

use std::path::Path;
use std::process::{Command, Stdio};
use std::time::Duration;

use hcc_system_tests::*;
use monitor::{Daemon, Monitor};

const LONG: Duration = Duration::from_secs(60);

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

/// `hcc plot FILE --out DIR/plot`: its metrics and trajectory rows.
fn plot(file: &Path, dir: &Path) -> (serde_json::Value, Vec<Vec<f64>>) {
    let plot = run_with_timeout(
        Command::new(bin("hcc"))
            .arg("plot")
            .arg(file)
            .arg("--out")
            .arg(dir.join("plot")),
        dir,
        "plot",
        Duration::from_secs(120),
    );
    assert!(plot.status.success(), "hcc plot failed:\n{}", plot.log());
    let metrics = read_json(&dir.join("plot/metrics.json"));
    let (_, rows) = read_csv(&dir.join("plot/trajectory.csv"));
    (metrics, rows)
}

/// `hcc replay FILE`, which must succeed with every torque bit-identical;
/// its output.
fn replay_bit_identical(file: &Path, dir: &Path) -> String {
    let replay = run_with_timeout(
        Command::new(bin("hcc")).arg("replay").arg(file),
        dir,
        "replay",
        Duration::from_secs(120),
    );
    let log = replay.log();
    println!("{log}");
    assert!(replay.status.success(), "{log}");
    assert!(log.contains("every torque bit-identical"), "{log}");
    log
}

#[test]
fn hcc_record_attached_to_daemons_started_by_hand() {
    let dir = TempDir::new("record_attach");
    let ns = unique_namespace("record_attach");
    let prefix = unique_file_prefix();
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
        // No --config: the recorder stores the scenario the controller
        // publishes on its scenario service, and hcc plot and hcc replay
        // below need nothing else.
        let rec = run_with_timeout(
            Command::new(bin("hcc"))
                .args(["record", "--namespace", &ns, "--file-prefix", &prefix])
                .args(["--duration", "2", "--quiet"])
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
    let (metrics, rows) = plot(&file, dir.path());
    println!("{metrics:#}");
    assert!(rows.len() > 1500, "rows: {}", rows.len());
    let t0 = rows[0][0];
    assert!(t0 >= 1.4, "the recording starts mid-run, not at t = {t0}");

    // Replay from the middle of the run.
    replay_bit_identical(&file, dir.path());
}

/// Which daemon a recording sees restarted.
#[derive(Clone, Copy, PartialEq, Eq, Debug)]
enum Restarted {
    Simulator,
    Controller,
}

/// `hcc record` across a crash of `which` and a new one started on the same
/// namespace: the recorder counts the restart of that daemon's streams (not
/// samples out of sequence), `hcc plot` derives every cycle with t going on,
/// `hcc replay` follows the restart bit for bit.
fn record_across_a_restart(which: Restarted) {
    let tag = match which {
        Restarted::Simulator => "restart_sim",
        Restarted::Controller => "restart_ctl",
    };
    let dir = TempDir::new(tag);
    let ns = unique_namespace(tag);
    let prefix = unique_file_prefix();
    let config = repo_root().join("config/paper-sim1.toml");
    let file = dir.path().join("restart.mcap");
    let out = dir.path().join("record.out");
    {
        let mut mon = Monitor::new(&ns, &prefix);
        let mut ctl = Daemon::controller(&ns, &prefix, dir.path(), "controller");
        let mut sim = Daemon::sim(&ns, &prefix, dir.path(), "sim");
        mon.wait_until("1500 cycles: the arm at rest", LONG, |m| {
            m.telemetry.len() >= 1500
        });
        // A long idle timeout: the recorder must not take the controller's
        // absence for the end of the run.
        let mut rec = ChildGuard::spawn(
            Command::new(bin("hcc"))
                .env(FILE_PREFIX_ENV, &prefix)
                .args([
                    "record",
                    "--namespace",
                    &ns,
                    "--quiet",
                    "--idle-timeout",
                    "60",
                ])
                .arg("--config")
                .arg(&config)
                .arg("--out")
                .arg(&file)
                .stdout(std::fs::File::create(&out).unwrap())
                .stderr(Stdio::inherit()),
        );
        // The file exists once the recorder runs; its subscribers connect
        // within milliseconds, well inside the 300 cycles before the crash.
        let attached = std::time::Instant::now();
        while !file.exists() {
            assert!(attached.elapsed() < LONG, "hcc record wrote nothing");
            std::thread::sleep(Duration::from_millis(20));
        }
        let n = mon.telemetry.len();
        mon.wait_until("300 recorded cycles", LONG, |m| {
            m.telemetry.len() >= n + 300
        });
        match which {
            Restarted::Simulator => {
                sim.crash();
                let n = mon.telemetry.len();
                mon.wait_until("the peer lost", LONG, |m| {
                    m.telemetry[n..].iter().any(|t| t.peer_lost)
                });
                sim = Daemon::sim(&ns, &prefix, dir.path(), "sim2");
            }
            Restarted::Controller => {
                ctl.crash();
                let n = mon.states.len();
                mon.wait_until("200 states without a controller", LONG, |m| {
                    m.states.len() >= n + 200
                });
                ctl = Daemon::controller(&ns, &prefix, dir.path(), "controller2");
            }
        }
        let n = mon.telemetry.len();
        mon.wait_until("300 cycles after the restart", LONG, |m| {
            m.telemetry[n..].iter().filter(|t| !t.peer_lost).count() >= 300
        });
        // SAFETY: a signal to our own child, by pid.
        unsafe { libc::kill(rec.pid() as libc::pid_t, libc::SIGTERM) };
        let status = rec
            .wait_timeout(LONG)
            .expect("hcc record did not stop on SIGTERM");
        let log = std::fs::read_to_string(&out).unwrap_or_default();
        println!("{log}");
        assert!(status.success(), "hcc record: {status}\n{log}");
        let restarted: &[&str] = match which {
            Restarted::Simulator => &["joint_state"],
            Restarted::Controller => &["torque_command", "telemetry"],
        };
        for stream in restarted {
            let counted = log
                .split(", ")
                .any(|part| part.contains(stream) && part.contains("(1 restart)"));
            assert!(counted, "{stream} not counted as restarted once: {log}");
        }
        assert!(!log.contains("out of sequence"), "{log}");
        sim.stop();
        ctl.stop();
    }
    assert_clean(&ns, &prefix);

    let (metrics, rows) = plot(&file, dir.path());
    let ipc = &metrics["run"]["settings"]["ipc"];
    println!("{ipc:#}");
    let (drivers, controllers) = match which {
        Restarted::Simulator => (1, 0),
        Restarted::Controller => (0, 1),
    };
    assert_eq!(ipc["driver_restarts"], drivers, "{ipc:#}");
    assert_eq!(ipc["controller_restarts"], controllers, "{ipc:#}");
    assert_eq!(ipc["telemetry_without_state"], 0, "{ipc:#}");
    assert!(rows.len() > 550, "rows: {}", rows.len());
    // t goes on across the restart (a new simulator numbers its states from
    // the start again).
    for w in rows.windows(2) {
        assert!(
            w[1][0] > w[0][0],
            "t not increasing: {} then {}",
            w[0][0],
            w[1][0]
        );
    }

    let log = replay_bit_identical(&file, dir.path());
    let expected = format!("{drivers} driver restarts, {controllers} controller restarts");
    assert!(log.contains(&expected), "{log}");
}

#[test]
fn hcc_record_across_a_simulator_restart() {
    record_across_a_restart(Restarted::Simulator);
}

#[test]
fn hcc_record_across_a_controller_restart() {
    record_across_a_restart(Restarted::Controller);
}
