//! `hcc jitter` smoke test: a short floor and a 2 s pair on the two cores.
//! Checks that the report has every figure and setting and that the counts
//! add up (cycles = received commands + misses). The latencies themselves
//! depend on the machine and are printed, never asserted.

use hcc_system_tests::*;
use std::process::Command;
use std::time::Duration;

const FIGURES: [&str; 5] = [
    "sim_tick_lateness",
    "state_to_command_latency",
    "controller_wakeup_latency",
    "controller_compute_time",
    "controller_control_law_time",
];
const STATS: [&str; 11] = [
    "count",
    "min_ns",
    "p50_ns",
    "p90_ns",
    "p99_ns",
    "p999_ns",
    "p9999_ns",
    "max_ns",
    "mean_ns",
    "saturated",
    "negative",
];

#[test]
fn jitter_reports_every_figure_and_consistent_counts() {
    let dir = TempDir::new("jitter");
    let namespace = unique_namespace("jitter");
    let prefix = unique_file_prefix();
    let out = dir.path().join("jitter");
    let run = run_with_timeout(
        Command::new(bin("hcc"))
            .current_dir(repo_root())
            .env(FILE_PREFIX_ENV, &prefix)
            .args(["jitter", "--duration", "2", "--floor-duration", "0.5"])
            .args(["--namespace", &namespace, "--quiet"])
            .arg("--out")
            .arg(&out),
        dir.path(),
        "jitter",
        Duration::from_secs(120),
    );
    assert!(run.status.success(), "hcc jitter failed\n{}", run.log());
    println!("{}", run.stdout);

    let report = read_json(&out.join("jitter.json"));
    for name in FIGURES {
        let f = &report["figures"][name];
        for s in STATS {
            assert!(f["pair"][s].is_number(), "{name}.pair.{s} missing: {f}");
        }
        assert!(
            f["pair"]["count"].as_u64().unwrap() > 0,
            "{name}: no sample"
        );
        let curve = f["curve"].as_array().expect("curve");
        assert!(!curve.is_empty(), "{name}: empty curve");
        let (p50, p99, max) = (
            f["pair"]["p50_ns"].as_u64().unwrap(),
            f["pair"]["p99_ns"].as_u64().unwrap(),
            f["pair"]["max_ns"].as_u64().unwrap(),
        );
        assert!(p50 <= p99 && p99 <= max, "{name}: percentiles out of order");
        if !name.starts_with("controller_c") {
            for s in STATS {
                assert!(f["floor"][s].is_number(), "{name}.floor.{s} missing: {f}");
            }
            assert!(f["ratio"]["p99.9"].is_number() || f["ratio"]["p99.9"].is_null());
        }
    }
    // The counts add up: every period after the first command was answered or missed.
    let c = &report["counts"];
    let cycles = c["cycles"].as_u64().unwrap();
    let received = c["received_commands"].as_u64().unwrap();
    let missed = c["missed_commands"].as_u64().unwrap();
    assert_eq!(cycles, received + missed, "{c}");
    assert_eq!(c["consistent"], true, "{c}");
    let periods = c["periods"].as_u64().unwrap();
    assert_eq!(
        periods,
        cycles
            + c["waiting_for_controller"].as_u64().unwrap()
            + c["stopped_periods"].as_u64().unwrap(),
        "{c}"
    );
    // 2 s at 1 kHz.
    assert!((1990..=2001).contains(&periods), "{c}");
    assert!(cycles > 1900, "the controller answered from the start: {c}");
    // One sample of tick lateness and of the controller per period.
    let ticks = report["figures"]["sim_tick_lateness"]["pair"]["count"]
        .as_u64()
        .unwrap();
    assert_eq!(ticks, periods, "one tick per period");
    let wakeups = report["figures"]["controller_wakeup_latency"]["pair"]["count"]
        .as_u64()
        .unwrap();
    assert_eq!(wakeups, c["controller_cycles"].as_u64().unwrap(), "{c}");
    let answered = report["figures"]["state_to_command_latency"]["pair"]["count"]
        .as_u64()
        .unwrap();
    assert!(answered >= received, "every received answer was timed: {c}");
    // Floor cycles per core.
    for f in c["floor"].as_array().expect("floor counts") {
        assert_eq!(f["cycles"].as_u64().unwrap(), 500, "{f}");
    }

    // The settings a reader needs to judge the figures.
    let s = &report["settings"];
    for key in ["kernel", "cpu_model", "cpus", "rt_throttling"] {
        assert!(!s["machine"][key].is_null(), "machine.{key} missing: {s}");
    }
    assert_eq!(s["wait"], "hybrid");
    assert_eq!(s["duration_s"], 2.0);
    for who in ["sim", "controller"] {
        assert!(s["obtained"][who].is_object(), "obtained.{who}: {s}");
    }
    assert!(report["steal_fraction"]["pair"].is_object());
    assert!(!report["targets"].as_array().unwrap().is_empty());

    let png = std::fs::read(out.join("jitter.png")).expect("jitter.png");
    assert!(png.starts_with(b"\x89PNG"));
    assert!(run.stdout.contains("simulator tick lateness") && run.stdout.contains("floor"));
    assert_clean(&namespace, &prefix);
}
