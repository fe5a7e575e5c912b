//! `hcc follow` with real processes (hcc-controller + hcc-sim in real time):
//! a 5 cm circle at 0.25 Hz in the TCP's y-z plane, streamed to the Panda's
//! TCP level while it runs; from 3 s after it began the TCP stays within
//! 1 mm of the path; a path that does not start at the level's equilibrium
//! is refused with its knots and reason, and the controller keeps running.
//! `hcc record` attached for the whole run: `hcc replay` repeats it bit for
//! bit, the path messages and the loads told to it (one refused) taken again
//! in their cycles.

mod monitor;

use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

use hcc_system_tests::*;
use monitor::Daemon;

fn config() -> PathBuf {
    repo_root().join("config/panda-pose-posture.toml")
}

/// The circle through `start` (its first point), its phase rising smoothly
/// from rest over the first second, a knot every 20 ms for `seconds`.
fn circle_csv(start: [f64; 3], seconds: f64) -> String {
    let mut s = String::from("t,x,y,z\n");
    let w = 2.0 * std::f64::consts::PI * 0.25;
    for k in 0..=(seconds / 0.02).round() as usize {
        let t = k as f64 * 0.02;
        let x = t.min(1.0);
        let phase = if t <= 1.0 {
            x.powi(6) - 3.0 * x.powi(5) + 2.5 * x.powi(4)
        } else {
            t - 0.5
        };
        let a = w * phase;
        s += &format!(
            "{t:.2},{},{},{}\n",
            start[0],
            start[1] + 0.05 * a.sin(),
            start[2] + 0.05 * (1.0 - a.cos())
        );
    }
    s
}

/// From `start` straight out along x to `x_end` at the same height over
/// `seconds`, a knot every 0.1 s.
fn line_csv(start: [f64; 3], x_end: f64, seconds: f64) -> String {
    let mut s = String::from("t,x,y,z\n");
    for k in 0..=(seconds / 0.1).round() as usize {
        let t = k as f64 * 0.1;
        let x = start[0] + (x_end - start[0]) * t / seconds;
        s += &format!("{t:.1},{x},{},{}\n", start[1], start[2]);
    }
    s
}

/// `hcc ARGS --namespace NS`, below the daemons' priority (nice 10, as the
/// recorder): on two cores the clients must not take the loop's time.
fn hcc(args: &[&str], ns: &str, prefix: &str, dir: &Path, tag: &str, secs: u64) -> Finished {
    let mut cmd = Command::new("nice");
    cmd.args(["-n", "10"])
        .arg(bin("hcc"))
        .env(FILE_PREFIX_ENV, prefix)
        .args(args)
        .args(["--namespace", ns]);
    run_with_timeout(&mut cmd, dir, tag, Duration::from_secs(secs))
}

fn tcp_error(ns: &str, prefix: &str, dir: &Path) -> f64 {
    let out = hcc(
        &["monitor", "--json", "--count", "1"],
        ns,
        prefix,
        dir,
        "mon",
        30,
    );
    assert!(out.status.success(), "{}", out.log());
    let v: serde_json::Value = serde_json::from_str(out.stdout.trim()).unwrap();
    v["levels"][0]["error_norm"].as_f64().unwrap()
}

#[test]
fn hcc_follow_streams_a_circle_that_the_tcp_tracks_within_a_millimetre() {
    let dir = TempDir::new("follow");
    let ns = unique_namespace("follow");
    let prefix = unique_file_prefix();
    let goal = [0.55, 0.20, 0.30];
    let circle = dir.path().join("circle.csv");
    std::fs::write(&circle, circle_csv(goal, 9.0)).unwrap();
    let recording = dir.path().join("follow.mcap");
    let away = dir.path().join("away.csv");
    std::fs::write(&away, circle_csv([0.70, 0.20, 0.30], 2.0)).unwrap();
    let out_of_reach = dir.path().join("out_of_reach.csv");
    std::fs::write(&out_of_reach, line_csv(goal, 0.95, 8.0)).unwrap();
    {
        let mut ctl = Daemon::start(
            "hcc-controller",
            &config(),
            &ns,
            &prefix,
            dir.path(),
            "ctl",
            &["--wait", "event"],
        );
        // The recorder below the daemons' priority (nice 10): on two cores
        // its compression must not take the loop's time (unprivileged, the
        // daemons run without SCHED_FIFO here).
        let mut rec = ChildGuard::spawn(
            Command::new("nice")
                .args(["-n", "10"])
                .arg(bin("hcc"))
                .env(FILE_PREFIX_ENV, &prefix)
                .args([
                    "record",
                    "--namespace",
                    &ns,
                    "--quiet",
                    "--idle-timeout",
                    "60",
                ])
                .arg("--out")
                .arg(&recording)
                .stdout(std::fs::File::create(dir.path().join("record.out")).unwrap())
                .stderr(Stdio::inherit()),
        );
        // From the first cycle on (the simulator starts after it), so that
        // the replay starts where the controller did.
        let attached = Instant::now();
        while !recording.exists() {
            assert!(
                attached.elapsed() < Duration::from_secs(20),
                "hcc record wrote nothing"
            );
            std::thread::sleep(Duration::from_millis(20));
        }
        std::thread::sleep(Duration::from_millis(300));
        let mut sim = Daemon::start(
            "hcc-sim",
            &config(),
            &ns,
            &prefix,
            dir.path(),
            "sim",
            &["--realtime", "--duration", "60"],
        );
        let start = Instant::now();
        while tcp_error(&ns, &prefix, dir.path()) > 1e-3 {
            assert!(start.elapsed() < Duration::from_secs(20), "never settled");
            std::thread::sleep(Duration::from_millis(200));
        }
        let c = circle.to_string_lossy().into_owned();
        let out = hcc(
            &["follow", "--level", "1", &c],
            &ns,
            &prefix,
            dir.path(),
            "follow",
            60,
        );
        let log = out.log();
        println!("{log}");
        assert!(out.status.success(), "{log}");
        let worst: f64 = out
            .stdout
            .rsplit("largest level error from 3 s: ")
            .next()
            .and_then(|s| s.trim().parse().ok())
            .unwrap_or_else(|| panic!("no figure in: {log}"));
        assert!(worst < 1e-3, "the TCP left the circle by {worst:.3e} m");

        // A path that starts 15 cm from the level's equilibrium: refused,
        // naming its first knots and the reason; the controller runs on.
        let refused = |file: &Path, tag: &str| {
            let f = file.to_string_lossy().into_owned();
            let out = hcc(
                &["follow", "--level", "1", &f],
                &ns,
                &prefix,
                dir.path(),
                tag,
                60,
            );
            println!("{}", out.log());
            assert!(!out.status.success(), "{}", out.log());
            out
        };
        let out = refused(&away, "away");
        assert!(
            out.stderr.contains("knots 0..=15") && out.stderr.contains("starts_away"),
            "{}",
            out.log()
        );
        assert!(tcp_error(&ns, &prefix, dir.path()) < 1e-3);

        // Out along x past the arm's reach: the first knots are taken and
        // followed, the message where the hierarchy would turn singular is
        // refused (`infeasible`, naming the knot) before the arm gets there;
        // the path stops on its last knot taken.
        let out = refused(&out_of_reach, "out_of_reach");
        assert!(out.stderr.contains("infeasible"), "{}", out.log());
        let knot: usize = out
            .stderr
            .split("knot ")
            .nth(1)
            .and_then(|s| s.split(' ').next())
            .and_then(|s| s.parse().ok())
            .unwrap_or_else(|| panic!("no knot named: {}", out.log()));
        // A knot every 0.1 s: refused between 3.5 s and 5.5 s of the path
        // (x from 0.77 to 0.83 m), before the arm's reach ends.
        assert!((35..=55).contains(&knot), "knot {knot}: {}", out.log());
        let start = Instant::now();
        while tcp_error(&ns, &prefix, dir.path()) > 1e-3 {
            assert!(
                start.elapsed() < Duration::from_secs(20),
                "never came to rest"
            );
            std::thread::sleep(Duration::from_millis(200));
        }
        // The hand's load told (the plant does not carry it: the TCP moves),
        // one refused, and the hand told empty again: replayed too.
        for (args, accepted) in [
            (
                &["--mass", "0.5", "--com", "0", "0", "0.1", "--ramp", "0.1"][..],
                true,
            ),
            (&["--mass", "5"][..], false),
            (&["--mass", "0"][..], true),
        ] {
            let args: Vec<&str> = std::iter::once("load")
                .chain(args.iter().copied())
                .collect();
            let out = hcc(&args, &ns, &prefix, dir.path(), "load", 30);
            assert_eq!(out.status.success(), accepted, "{args:?}: {}", out.log());
            std::thread::sleep(Duration::from_millis(300));
        }
        let start = Instant::now();
        while tcp_error(&ns, &prefix, dir.path()) > 1e-3 {
            assert!(
                start.elapsed() < Duration::from_secs(20),
                "never came back after the load"
            );
            std::thread::sleep(Duration::from_millis(200));
        }
        // SAFETY: a signal to our own child, by pid.
        unsafe { libc::kill(rec.pid() as libc::pid_t, libc::SIGTERM) };
        let status = rec
            .wait_timeout(Duration::from_secs(30))
            .expect("hcc record did not stop on SIGTERM");
        assert!(status.success(), "hcc record: {status}");
        ctl.stop();
        sim.stop();
    }
    // The run with its paths, replayed from the recording bit for bit.
    let out = run_with_timeout(
        Command::new(bin("hcc")).arg("replay").arg(&recording),
        dir.path(),
        "replay",
        Duration::from_secs(120),
    );
    let log = out.log();
    println!("{log}");
    assert!(out.status.success(), "{log}");
    let paths: u64 = log
        .split(" path messages")
        .next()
        .and_then(|s| s.rsplit(' ').next())
        .and_then(|s| s.parse().ok())
        .unwrap_or_else(|| panic!("no path count in: {log}"));
    // The circle's 451 knots in messages of 16, and the refused one.
    assert!(paths >= 29, "{paths} path messages replayed: {log}");
    assert!(log.contains(" 3 load messages"), "{log}");
    assert!(log.contains("bit-identical"), "{log}");
}
