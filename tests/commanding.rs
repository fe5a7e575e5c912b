//! Commanding a running controller with real processes: `hcc goal` moves the
//! Panda's TCP (hcc-controller + hcc-sim) to a new goal, bad setpoints are
//! rejected with their reason and a non-zero exit while the controller keeps
//! running, `hcc gains` changes a stiffness, and `hcc monitor --json --count K`
//! prints K JSON lines.

mod monitor;

use std::path::{Path, PathBuf};
use std::process::Command;
use std::time::{Duration, Instant};

use hcc_system_tests::*;
use monitor::Daemon;

fn config() -> PathBuf {
    repo_root().join("config/panda-pose-posture.toml")
}

fn hcc(args: &[&str], ns: &str, prefix: &str, dir: &Path, tag: &str) -> Finished {
    let mut cmd = Command::new(bin("hcc"));
    cmd.env(FILE_PREFIX_ENV, prefix)
        .args(args)
        .args(["--namespace", ns]);
    run_with_timeout(&mut cmd, dir, tag, Duration::from_secs(30))
}

/// The newest `hcc monitor --json` sample.
fn sample(ns: &str, prefix: &str, dir: &Path) -> serde_json::Value {
    let out = hcc(
        &["monitor", "--json", "--count", "1"],
        ns,
        prefix,
        dir,
        "sample",
    );
    assert!(out.status.success(), "{}", out.log());
    serde_json::from_str(out.stdout.trim()).unwrap()
}

fn error_norm(s: &serde_json::Value, level: usize) -> f64 {
    s["levels"][level]["error_norm"].as_f64().unwrap()
}

#[test]
fn goals_gains_rejections_and_the_monitor() {
    let dir = TempDir::new("commanding");
    let ns = unique_namespace("commanding");
    let prefix = unique_file_prefix();
    {
        let mut ctl = Daemon::start(
            "hcc-controller",
            &config(),
            &ns,
            &prefix,
            dir.path(),
            "ctl",
            &[],
        );
        let mut sim = Daemon::start(
            "hcc-sim",
            &config(),
            &ns,
            &prefix,
            dir.path(),
            "sim",
            &["--realtime", "--duration", "60"],
        );
        // Let the arm settle at the scenario's goal.
        let start = Instant::now();
        while error_norm(&sample(&ns, &prefix, dir.path()), 0) > 1e-3 {
            assert!(start.elapsed() < Duration::from_secs(20), "never settled");
            std::thread::sleep(Duration::from_millis(200));
        }

        // The monitor: K JSON lines with the documented keys.
        let out = hcc(
            &["monitor", "--json", "--count", "3"],
            &ns,
            &prefix,
            dir.path(),
            "mon",
        );
        assert!(out.status.success(), "{}", out.log());
        let lines: Vec<&str> = out.stdout.lines().collect();
        assert_eq!(lines.len(), 3, "{}", out.stdout);
        for line in lines {
            let v: serde_json::Value = serde_json::from_str(line).unwrap();
            for key in [
                "stamp_ns",
                "mode",
                "levels",
                "tau",
                "counters",
                "contact",
                "tau_ext",
                "tau_ext_max",
                "tau_ext_max_joint",
            ] {
                assert!(!v[key].is_null(), "{key} missing in {line}");
            }
            // Settled, untouched: the contact watch sees nothing.
            assert_eq!(v["contact"], false, "{line}");
            assert!(v["tau_ext_max"].as_f64().unwrap() < 2.0, "{line}");
            let l = &v["levels"][0];
            for key in ["level", "name", "error", "error_norm", "goal", "storage"] {
                assert!(!l[key].is_null(), "{key} missing in {line}");
            }
        }

        // Without --config the levels have the names the controller's
        // scenario service gives; with the scenario file the same; a
        // scenario of other levels is refused.
        let from_service = sample(&ns, &prefix, dir.path());
        let names: Vec<&str> = (0..3)
            .map(|i| from_service["levels"][i]["name"].as_str().unwrap())
            .collect();
        assert_eq!(
            names,
            ["TCP position", "TCP orientation", "posture"],
            "{from_service}"
        );
        let cfg = config();
        let named = hcc(
            &[
                "monitor",
                "--json",
                "--count",
                "1",
                "--config",
                cfg.to_str().unwrap(),
            ],
            &ns,
            &prefix,
            dir.path(),
            "named",
        );
        assert!(named.status.success(), "{}", named.log());
        let v: serde_json::Value = serde_json::from_str(named.stdout.trim()).unwrap();
        let names: Vec<&str> = (0..3)
            .map(|i| v["levels"][i]["name"].as_str().unwrap())
            .collect();
        assert_eq!(names, ["TCP position", "TCP orientation", "posture"], "{v}");
        let other = repo_root().join("config/paper-sim1.toml");
        let refused = hcc(
            &[
                "monitor",
                "--count",
                "1",
                "--config",
                other.to_str().unwrap(),
            ],
            &ns,
            &prefix,
            dir.path(),
            "refused",
        );
        assert!(!refused.status.success(), "{}", refused.log());
        assert!(refused.stderr.contains("dimensions"), "{}", refused.log());

        // A goal 10 cm away, over 1 s: accepted, and the TCP is there (< 1 mm)
        // within the transition plus 2 s of the controller's time (counted in
        // its telemetry samples, one per answered state at 1 kHz; the wall
        // clock of a loaded machine says nothing about the control).
        let t0 = Instant::now();
        let seq0 = sample(&ns, &prefix, dir.path())["seq"].as_u64().unwrap();
        let out = hcc(
            &[
                "goal",
                "--level",
                "1",
                "--duration",
                "1.0",
                "0.55",
                "0.10",
                "0.30",
            ],
            &ns,
            &prefix,
            dir.path(),
            "goal",
        );
        assert!(out.status.success(), "{}", out.log());
        assert!(out.stdout.contains("accepted"), "{}", out.stdout);
        let reached = loop {
            let s = sample(&ns, &prefix, dir.path());
            let goal: Vec<f64> = serde_json::from_value(s["levels"][0]["goal"].clone()).unwrap();
            let cycles = s["seq"].as_u64().unwrap().saturating_sub(seq0);
            if (goal[1] - 0.10).abs() < 1e-12 && error_norm(&s, 0) < 1e-3 {
                break (cycles, t0.elapsed());
            }
            assert!(cycles < 3000, "not there after 3 s of control: {s}");
            assert!(t0.elapsed() < Duration::from_secs(120), "no progress: {s}");
            std::thread::sleep(Duration::from_millis(50));
        };
        println!(
            "TCP within 1 mm of the new goal after {} control cycles ({:.2} s of wall time)",
            reached.0,
            reached.1.as_secs_f64()
        );

        // Bad setpoints: the controller's reason, a non-zero exit, nothing changed.
        for (args, reason) in [
            (
                vec!["goal", "--level", "1", "3.0", "0.0", "0.3"],
                "outside_workspace",
            ),
            (
                vec!["goal", "--level", "elbow", "0.5", "0.0", "0.3"],
                "no level \"elbow\"",
            ),
            (
                vec!["goal", "--level", "7", "0.5", "0.0", "0.3"],
                "unknown_level",
            ),
            (
                vec!["goal", "--level", "1", "0.5", "0.0"],
                "dimension_mismatch",
            ),
            (
                vec!["goal", "--level", "3", "0", "0", "0", "1.0", "0", "0", "0"],
                "joint_limit",
            ),
            (
                vec![
                    "gains",
                    "--level",
                    "1",
                    "--dim",
                    "3",
                    "--stiffness",
                    "1e6",
                    "1e6",
                    "1e6",
                ],
                "stiffness_above_limit",
            ),
            (
                vec![
                    "gains",
                    "--level",
                    "1",
                    "--dim",
                    "3",
                    "--damping",
                    "1",
                    "-1",
                    "1",
                ],
                "not_positive_definite",
            ),
            (
                vec![
                    "load",
                    "--mass",
                    "1.0",
                    "--inertia",
                    "0.1",
                    "0",
                    "0",
                    "0.1",
                    "0",
                    "0.3",
                ],
                "not_physical",
            ),
            (vec!["load", "--mass", "5.0"], "above_payload"),
            (vec!["load", "--mass", "-1.0"], "negative_mass"),
        ] {
            let out = hcc(&args, &ns, &prefix, dir.path(), "bad");
            assert!(!out.status.success(), "{args:?}: {}", out.log());
            assert!(out.stderr.contains(reason), "{args:?}: {}", out.log());
        }
        assert!(ctl.running() && sim.running(), "the pair keeps running");
        let s = sample(&ns, &prefix, dir.path());
        let goal: Vec<f64> = serde_json::from_value(s["levels"][0]["goal"].clone()).unwrap();
        assert_eq!(goal, [0.55, 0.10, 0.30], "targets unchanged");

        // The hand takes a load and the controller is told: the pair's plant
        // does not carry it, so the TCP moves by what the model now
        // compensates (K⁻¹ m g, a few mm) — the load is in the law.
        let out = hcc(
            &[
                "load", "--mass", "0.5", "--com", "0", "0", "0.1", "--ramp", "0.1",
            ],
            &ns,
            &prefix,
            dir.path(),
            "load",
        );
        assert!(out.status.success(), "{}", out.log());
        assert!(out.stdout.contains("accepted"), "{}", out.stdout);
        std::thread::sleep(Duration::from_millis(1000));
        let s = sample(&ns, &prefix, dir.path());
        let moved = error_norm(&s, 0);
        // The monitor shows what the model carries.
        assert_eq!(
            s["load"],
            serde_json::json!({"mass": 0.5, "com": [0.0, 0.0, 0.1], "progress": 1.0})
        );
        let out = hcc(&["load", "--mass", "0"], &ns, &prefix, dir.path(), "unload");
        assert!(out.status.success(), "{}", out.log());
        let back = loop {
            let e = error_norm(&sample(&ns, &prefix, dir.path()), 0);
            if e < 1e-3 || t0.elapsed() > Duration::from_secs(120) {
                break e;
            }
            std::thread::sleep(Duration::from_millis(50));
        };
        println!(
            "a 0.5 kg load told but not carried moves the TCP {moved:.2e} m; unloaded, {back:.2e} m"
        );
        assert!(moved > 1e-3, "{moved:e} m: the load is not in the law");
        assert!(back < 1e-3, "{back:e} m");

        // A stiffness change shows in the monitor. The level by its name and
        // no --dim: both from the controller's scenario service.
        let out = hcc(
            &[
                "gains",
                "--level",
                "TCP position",
                "--stiffness",
                "500",
                "500",
                "500",
                "--duration",
                "0.2",
            ],
            &ns,
            &prefix,
            dir.path(),
            "gains",
        );
        assert!(out.status.success(), "{}", out.log());
        std::thread::sleep(Duration::from_millis(400));
        let s = sample(&ns, &prefix, dir.path());
        assert_eq!(
            s["levels"][0]["stiffness"],
            serde_json::json!([500.0, 500.0, 500.0])
        );
        ctl.stop();
        sim.stop();
    }
    assert_clean(&ns, &prefix);
}
