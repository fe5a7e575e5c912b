//! `hcc run --lockstep`: the two daemons (hcc-sim, hcc-controller) as real
//! processes over iceoryx2, the simulator waiting for every command, give
//! the same trajectory as the in-process `hcc simulate` — every column of
//! every row, bit for bit: both run the same driver and the same control
//! cycle. With a `[[setpoint]]` schedule (`hcc run` sends it through the
//! setpoint service, each entry applied at its cycle; `hcc simulate` hands
//! it to the cycle with the state of its cycle), with the torque filter on,
//! and for a robot that adds gravity itself. `hcc replay` of the in-process
//! run's recording is bit-identical too. A recorder stopped again and again
//! for longer than its queues last loses nothing: the simulator waits for it.

use hcc_system_tests::*;
use std::path::Path;
use std::process::Command;
use std::time::Duration;

/// The tests one after the other (each is two daemons running flat out).
static SERIAL: std::sync::Mutex<()> = std::sync::Mutex::new(());

/// Runs `config` (for `duration` s, if given) with `hcc simulate` and with
/// `hcc run --lockstep`, asserts that the trajectories are bit-identical and
/// that the recorder lost nothing; returns the rows and the run's `ipc`
/// figures.
fn compare(test: &str, config: &Path, duration: Option<f64>) -> (usize, serde_json::Value) {
    let dir = TempDir::new(test);
    compare_in(&dir, test, config, duration, false)
}

/// Stops the `hcc run` of `namespace` (and so its recorder) for 150 ms of
/// every 200 ms until `done`, then lets it run; returns how many times it
/// stopped it. A stop is six times what the recorder's queues hold at the
/// lockstep's pace (128 samples at 5 kHz).
fn stutter(namespace: &str, done: &std::sync::atomic::AtomicBool) -> u32 {
    use std::sync::atomic::Ordering;
    let mut stops = 0;
    while !done.load(Ordering::SeqCst) {
        let launcher = processes_with(namespace)
            .into_iter()
            .find(|(_, cmdline)| cmdline.contains(" run ") && cmdline.contains("--lockstep"));
        let Some((pid, _)) = launcher else {
            std::thread::sleep(Duration::from_millis(5));
            continue;
        };
        // SAFETY: signals to the test's own child, by its id.
        unsafe { libc::kill(pid as i32, libc::SIGSTOP) };
        std::thread::sleep(Duration::from_millis(150));
        unsafe { libc::kill(pid as i32, libc::SIGCONT) };
        stops += 1;
        std::thread::sleep(Duration::from_millis(50));
    }
    stops
}

/// [`compare`], writing into `dir`; with `stalls`, `hcc run` is stopped
/// again and again meanwhile ([`stutter`]).
fn compare_in(
    dir: &TempDir,
    test: &str,
    config: &Path,
    duration: Option<f64>,
    stalls: bool,
) -> (usize, serde_json::Value) {
    let _serial = SERIAL.lock().unwrap_or_else(|e| e.into_inner());
    let namespace = unique_namespace(test);
    let prefix = unique_file_prefix();
    let duration_args: Vec<String> = duration
        .map(|d| vec!["--duration".to_string(), format!("{d}")])
        .unwrap_or_default();

    let sim = run_with_timeout(
        Command::new(bin("hcc"))
            .current_dir(repo_root())
            .arg("simulate")
            .arg(config)
            .args(&duration_args)
            .arg("--out")
            .arg(dir.path().join("simulate"))
            .arg("--no-plots"),
        dir.path(),
        "simulate",
        Duration::from_secs(120),
    );
    assert!(sim.status.success(), "hcc simulate failed\n{}", sim.log());

    let done = std::sync::atomic::AtomicBool::new(false);
    let (run, stops) = std::thread::scope(|scope| {
        let stops = stalls.then(|| scope.spawn(|| stutter(&namespace, &done)));
        let run = run_with_timeout(
            Command::new(bin("hcc"))
                .current_dir(repo_root())
                .env(FILE_PREFIX_ENV, &prefix)
                .arg("run")
                .arg(config)
                .args(&duration_args)
                .arg("--lockstep")
                .args(["--namespace", &namespace])
                .arg("--out")
                .arg(dir.path().join("run"))
                .arg("--no-plots"),
            dir.path(),
            "run",
            Duration::from_secs(300),
        );
        done.store(true, std::sync::atomic::Ordering::SeqCst);
        (run, stops.map(|h| h.join().unwrap()))
    });
    assert!(
        run.status.success(),
        "hcc run --lockstep failed\n{}",
        run.log()
    );
    if let Some(stops) = stops {
        println!("hcc run was stopped {stops} times for 150 ms");
        assert!(stops >= 2, "the run was stopped only {stops} times");
    }

    // The recorder lost nothing and says so (first: a lost sample is also
    // a missing row below).
    let metrics = read_json(&dir.path().join("run/metrics.json"));
    let ipc = metrics["run"]["settings"]["ipc"].clone();
    assert_eq!(ipc["mode"], "lockstep", "{ipc}");
    for stream in ["joint_state", "torque_command", "telemetry"] {
        assert_eq!(ipc["recorder_gaps"][stream], 0, "{ipc}");
    }
    assert_eq!(ipc["rows"], ipc["expected_rows"], "{ipc}");
    assert!(run.stdout.contains("latency"), "{}", run.log());

    let a = read_csv(&dir.path().join("simulate/trajectory.csv"));
    let b = read_csv(&dir.path().join("run/trajectory.csv"));
    let (worst, column, row) = max_csv_difference(&a, &b);
    println!(
        "{}: {} rows x {} columns; largest difference {worst:e} (column {column}, row {row})",
        config.display(),
        a.1.len(),
        a.0.len()
    );
    assert!(
        worst == 0.0,
        "hcc run --lockstep differs from hcc simulate by {worst:e} in column {column} at row {row}"
    );

    assert_clean(&namespace, &prefix);
    (a.1.len(), ipc)
}

#[test]
fn lockstep_run_over_ipc_reproduces_hcc_simulate() {
    let (rows, ipc) = compare(
        "run_lockstep",
        &repo_root().join("config/paper-sim1.toml"),
        None,
    );
    assert_eq!(rows, 3001, "3 s at 1 kHz, both ends included");
    assert!(ipc.get("scheduled_setpoints").is_none(), "{ipc}");
}

#[test]
fn lockstep_run_with_a_setpoint_schedule_reproduces_hcc_simulate() {
    // The first 8 s of panda-waypoints: two waypoints, the posture change
    // (t = 5 s) and the stiffness change with the third waypoint (both at
    // t = 7.5 s, the same level, the same cycle).
    let (rows, ipc) = compare(
        "run_lockstep_schedule",
        &repo_root().join("config/panda-waypoints.toml"),
        Some(8.0),
    );
    assert_eq!(rows, 8001);
    let s = &ipc["scheduled_setpoints"];
    assert_eq!(s["entries"], 6, "{s}");
    assert_eq!(s["due_within_the_run"], 5, "{s}");
    assert_eq!(s["sent"], 5, "{s}");
    assert_eq!(s["answered"], 5, "{s}");
    assert_eq!(s["rejected"], 0, "{s}");
    assert_eq!(s["late"], 0, "{s}");
}

#[test]
fn a_rejected_scheduled_setpoint_fails_the_run() {
    let _serial = SERIAL.lock().unwrap_or_else(|e| e.into_inner());
    // panda-waypoints with one more entry at t = 0.2 s: a TCP stiffness
    // above the level's max_stiffness (4 × 300 N/m by default). It passes
    // the load-time checks (model-free); the controller rejects it.
    let dir = TempDir::new("run_lockstep_rejected");
    let namespace = unique_namespace("run_lockstep_rejected");
    let prefix = unique_file_prefix();
    let config = scenario_copy(
        "panda-waypoints.toml",
        dir.path(),
        "\n[[setpoint]]\nt = 0.2\nlevel = 1\nstiffness = [5000.0, 5000.0, 5000.0, 20.0, 20.0, 20.0]\n",
    );
    let run = run_with_timeout(
        Command::new(bin("hcc"))
            .current_dir(repo_root())
            .env(FILE_PREFIX_ENV, &prefix)
            .arg("run")
            .arg(&config)
            .args(["--duration", "1.0", "--lockstep", "--quiet", "--no-plots"])
            .args(["--namespace", &namespace])
            .arg("--out")
            .arg(dir.path().join("run")),
        dir.path(),
        "run",
        Duration::from_secs(120),
    );
    assert!(!run.status.success(), "the run should fail\n{}", run.log());
    assert!(
        run.stderr.contains("rejected")
            && run.stderr.contains("t = 0.2 s for level 1")
            && run.stderr.contains("stiffness_above_limit"),
        "{}",
        run.log()
    );
    // The results are written all the same, and say what happened.
    let metrics = read_json(&dir.path().join("run/metrics.json"));
    let s = &metrics["run"]["settings"]["ipc"]["scheduled_setpoints"];
    assert_eq!(s["rejected"], 1, "{s}");
    assert_eq!(s["answered"], 2, "{s}");
    assert_clean(&namespace, &prefix);
}

/// `[torque_filter]` on (rate limit and low-pass): the in-process run and the
/// lockstep run filter the same torques; the in-process recording replays.
#[test]
fn lockstep_run_with_the_torque_filter_is_bit_identical_to_hcc_simulate() {
    let dir = TempDir::new("run_lockstep_filter");
    let config = scenario_copy(
        "paper-sim1.toml",
        dir.path(),
        "\n[torque_filter]\ntorque_rate_limit = 1500.0\nlow_pass_hz = 80.0\n",
    );
    let (rows, _) = compare_in(&dir, "run_lockstep_filter", &config, Some(1.0), false);
    assert_eq!(rows, 1001);
    let metrics = read_json(&dir.path().join("simulate/metrics.json"));
    let limited = &metrics["run"]["settings"]["rate_limited_cycles"];
    assert!(
        limited.as_u64().is_some_and(|n| n > 0),
        "the filter acted: {limited}"
    );
    let replay = run_with_timeout(
        Command::new(bin("hcc"))
            .current_dir(repo_root())
            .arg("replay")
            .arg(dir.path().join("simulate/run.mcap"))
            .arg("--config")
            .arg(&config),
        dir.path(),
        "replay",
        Duration::from_secs(120),
    );
    assert!(replay.status.success(), "{}", replay.log());
    assert!(
        replay.stdout.contains("replayed 1001 cycles") && replay.stdout.contains("bit-identical"),
        "{}",
        replay.log()
    );
}

/// A robot that compensates gravity itself (`[robot] gravity_compensation =
/// false`): its driver adds g(q), in process as over IPC, and the arm holds.
#[test]
fn lockstep_run_of_a_robot_that_adds_gravity_is_bit_identical_to_hcc_simulate() {
    let dir = TempDir::new("run_lockstep_gravity");
    let config = scenario_copy("paper-sim1.toml", dir.path(), "");
    let text = std::fs::read_to_string(&config).unwrap();
    assert!(text.contains("gravity_compensation = true"));
    std::fs::write(
        &config,
        text.replace(
            "gravity_compensation = true",
            "gravity_compensation = false",
        ),
    )
    .unwrap();
    compare_in(&dir, "run_lockstep_gravity", &config, Some(1.0), false);
    let metrics = read_json(&dir.path().join("simulate/metrics.json"));
    let final_error = metrics["levels"][0]["final_error_norm"].as_f64().unwrap();
    assert!(
        final_error < 1e-3,
        "the TCP did not reach its goal: {metrics}"
    );
}

/// The recorder of a lockstep run stopped for 150 ms of every 200 ms — six
/// times what its queues hold at the run's pace, each time — loses nothing:
/// the simulator waits for it (`hcc-sim --lockstep-recorder`), and the run
/// is bit-identical to `hcc simulate` all the same.
#[test]
fn a_stalled_recorder_loses_nothing_in_lockstep() {
    let dir = TempDir::new("run_lockstep_stalls");
    let (rows, _) = compare_in(
        &dir,
        "run_lockstep_stalls",
        &repo_root().join("config/paper-sim1.toml"),
        Some(1.0),
        true,
    );
    assert_eq!(rows, 1001);
}
