//! Two real processes over iceoryx2: `hcc-sim --lockstep` and the controller
//! daemon, on the paper's simulation #1 (own namespace and file prefix).
//!
//! The controller process is this test binary started again in "controller
//! mode" (it runs `hcc_controller::daemon`, the code of the `hcc-controller`
//! binary), because a test can only name the binaries of its own package.
//!
//! Checks: the arm converges toward the goal, the lockstep run reproduces the
//! in-process closed loop of `hcc simulate` to ≤ 1e-12, both processes stop
//! cleanly with exit code 0, and no shared-memory file of the test's prefix
//! remains (except the per-prefix global management segment, removed here).

mod common;

use std::path::PathBuf;
use std::process::{Child, Command, ExitStatus, Stdio};
use std::time::{Duration, Instant};

use hcc_config::Scenario;
use hcc_control::Controller;
use hcc_msgs::ipc::{self, MAX_SUBSCRIBER_BUFFER, Services};
use hcc_msgs::{DriverStatus, JointState, Namespace, ServiceNames};
use iceoryx2::prelude::SignalHandlingMode;

#[global_allocator]
static ALLOCATOR: hcc_rtalloc::RtAllocator = hcc_rtalloc::RtAllocator::new();

const CONTROLLER_MODE_ENV: &str = "HCC_TEST_CONTROLLER_ARGS";

fn config_path() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../../config/paper-sim1.toml")
}

/// In controller mode (set by the parent test), run the controller daemon.
#[test]
fn controller_process() {
    let Ok(args) = std::env::var(CONTROLLER_MODE_ENV) else {
        return;
    };
    let args = std::iter::once("hcc-controller".to_string())
        .chain(args.split('\u{1f}').map(str::to_string));
    let code = hcc_controller::daemon::main_with_args(args);
    std::process::exit(if code == std::process::ExitCode::SUCCESS {
        0
    } else {
        2
    });
}

/// A child process that is killed when the guard is dropped.
struct ChildGuard {
    child: Option<Child>,
}

impl ChildGuard {
    fn terminate(&mut self, timeout: Duration) -> Option<ExitStatus> {
        let child = self.child.as_mut()?;
        // SAFETY: sending a signal to our own child.
        unsafe { libc::kill(child.id() as libc::pid_t, libc::SIGTERM) };
        self.wait(timeout)
    }

    fn wait(&mut self, timeout: Duration) -> Option<ExitStatus> {
        let child = self.child.as_mut()?;
        let start = Instant::now();
        while start.elapsed() < timeout {
            if let Ok(Some(status)) = child.try_wait() {
                self.child = None;
                return Some(status);
            }
            std::thread::sleep(Duration::from_millis(5));
        }
        None
    }
}

impl Drop for ChildGuard {
    fn drop(&mut self) {
        if let Some(mut child) = self.child.take() {
            let _ = child.kill();
            let _ = child.wait();
        }
    }
}

fn spawn_controller(ns: &str, prefix: &str) -> ChildGuard {
    let config = config_path();
    let args = [
        config.to_str().unwrap(),
        "--namespace",
        ns,
        "--file-prefix",
        prefix,
        "--wait",
        "event",
    ]
    .join("\u{1f}");
    let child = Command::new(std::env::current_exe().unwrap())
        .args([
            "--exact",
            "controller_process",
            "--nocapture",
            "--test-threads=1",
        ])
        .env(CONTROLLER_MODE_ENV, args)
        .stdout(Stdio::null())
        .spawn()
        .unwrap();
    ChildGuard { child: Some(child) }
}

fn spawn_sim(ns: &str, prefix: &str, extra: &[&str]) -> ChildGuard {
    let child = Command::new(env!("CARGO_BIN_EXE_hcc-sim"))
        .arg(config_path())
        .args(["--namespace", ns, "--file-prefix", prefix])
        .args(extra)
        .spawn()
        .unwrap();
    ChildGuard { child: Some(child) }
}

/// ‖x̃_1‖ of the scenario's first level at state (q, q̇), from the control law.
fn level1_error(controller: &mut Controller, s: &JointState) -> f64 {
    let out = controller.step(s.q(), s.qd()).unwrap();
    out.task_error[0].norm()
}

#[test]
fn lockstep_sim_and_controller_converge_and_match_the_in_process_loop() {
    if std::env::var(CONTROLLER_MODE_ENV).is_ok() {
        return;
    }
    let prefix = format!("hcct2p{}_", std::process::id());
    let ns = Namespace::unique("two_proc").unwrap();
    let duration = 0.5;
    let mut states: Vec<JointState> = Vec::new();
    {
        let names = ServiceNames::for_namespace(ns.clone());
        let node = ipc::create_node(
            "two-process-test",
            SignalHandlingMode::Disabled,
            Some(&prefix),
        )
        .unwrap();
        let services = Services::open(&node, &names).unwrap();
        let recorder = services
            .joint_state_subscriber(MAX_SUBSCRIBER_BUFFER)
            .unwrap();

        // The simulator first: it waits for the controller without moving the arm.
        let mut sim = spawn_sim(
            ns.as_str(),
            &prefix,
            &["--lockstep", "--duration", &duration.to_string()],
        );
        std::thread::sleep(Duration::from_millis(100));
        let mut controller = spawn_controller(ns.as_str(), &prefix);

        let start = Instant::now();
        let mut stopped = false;
        while !stopped && start.elapsed() < Duration::from_secs(120) {
            while let Ok(Some(s)) = recorder.receive() {
                stopped |= s.status == DriverStatus::Stopped.code();
                states.push(*s);
            }
            std::thread::sleep(Duration::from_micros(200));
        }
        assert!(stopped, "the simulator did not finish its run");
        let sim_status = sim.wait(Duration::from_secs(30)).expect("hcc-sim exits");
        assert!(sim_status.success(), "hcc-sim: {sim_status:?}");
        let ctl_status = controller
            .terminate(Duration::from_secs(30))
            .expect("the controller stops on SIGTERM");
        assert!(ctl_status.success(), "controller: {ctl_status:?}");
    }
    common::assert_no_leftover_files(&prefix);

    // Behaviour: the final state is t = duration, the TCP converged toward the goal.
    let mut scenario = Scenario::load(config_path()).unwrap();
    let last = *states.last().unwrap();
    assert_eq!(last.header.seq, (duration * 1000.0) as u64);
    assert_eq!(last.missed_commands, 0);
    assert_eq!(last.fallback_cycles, 0, "lockstep never falls back");
    let mut probe = Controller::new(&scenario.model, scenario.spec.clone(), &scenario.q0).unwrap();
    let first = states.iter().find(|s| s.header.seq == 0).copied();
    let e0 = match first {
        Some(s) => level1_error(&mut probe, &s),
        None => {
            let mut s = JointState::zeroed();
            let n = scenario.model.nq();
            s.set_joints(scenario.q0.as_slice(), &vec![0.0; n], &vec![0.0; n])
                .unwrap();
            level1_error(&mut probe, &s)
        }
    };
    let e_end = level1_error(&mut probe, &last);
    println!(
        "{} states recorded; TCP position error {e0:.4} m → {e_end:.4} m",
        states.len()
    );
    assert!(e_end < 0.2 * e0, "TCP error {e0} → {e_end}: no convergence");

    // The same run in process (hcc simulate): bit-exact up to 1e-12.
    scenario.set_duration(duration).unwrap();
    let run = hcc_plant::closed_loop::simulate(&scenario).unwrap();
    let n = scenario.model.nq();
    let mut worst = 0.0f64;
    let mut compared = 0;
    for s in &states {
        let row = run.trajectory.row(s.header.seq as usize);
        let t = row[0];
        assert!((t - s.header.seq as f64 * 1e-3).abs() < 1e-12);
        for k in 0..n {
            let qi = run.trajectory.column_index(&format!("q{}", k + 1)).unwrap();
            let qdi = run
                .trajectory
                .column_index(&format!("qd{}", k + 1))
                .unwrap();
            worst = worst
                .max((row[qi] - s.q[k]).abs())
                .max((row[qdi] - s.qd[k]).abs());
        }
        compared += 1;
    }
    println!("compared {compared} states with hcc simulate: max |Δq|, |Δq̇| = {worst:e}");
    assert!(compared > 100);
    assert!(
        worst <= 1e-12,
        "IPC lockstep differs from hcc simulate by {worst}"
    );
}

#[test]
fn realtime_sim_without_controller_holds_the_arm_and_stops_cleanly() {
    if std::env::var(CONTROLLER_MODE_ENV).is_ok() {
        return;
    }
    let prefix = format!("hcctrt{}_", std::process::id());
    let ns = Namespace::unique("sim_alone").unwrap();
    let scenario = Scenario::load(config_path()).unwrap();
    let mut last = None;
    {
        let names = ServiceNames::for_namespace(ns.clone());
        let node = ipc::create_node(
            "sim-alone-test",
            SignalHandlingMode::Disabled,
            Some(&prefix),
        )
        .unwrap();
        let services = Services::open(&node, &names).unwrap();
        let recorder = services
            .joint_state_subscriber(MAX_SUBSCRIBER_BUFFER)
            .unwrap();
        // Real time, no --duration: runs until SIGTERM.
        let mut sim = spawn_sim(ns.as_str(), &prefix, &["--realtime"]);
        let start = Instant::now();
        let mut fallback_seen = false;
        while start.elapsed() < Duration::from_secs(60) {
            while let Ok(Some(s)) = recorder.receive() {
                fallback_seen |= s.status == DriverStatus::FallbackActive.code();
                last = Some(*s);
            }
            if last.is_some_and(|s| s.header.seq >= 200) {
                break;
            }
            std::thread::sleep(Duration::from_millis(1));
        }
        assert!(
            fallback_seen,
            "status FallbackActive while no controller runs"
        );
        let status = sim
            .terminate(Duration::from_secs(30))
            .expect("hcc-sim stops");
        assert!(status.success(), "{status:?}");
        while let Ok(Some(s)) = recorder.receive() {
            last = Some(*s);
        }
    }
    common::assert_no_leftover_files(&prefix);
    let last = last.expect("states were published");
    assert_eq!(last.status, DriverStatus::Stopped.code(), "final state");
    assert_eq!(last.missed_commands, 0, "no miss before the first command");
    assert!(last.fallback_cycles >= 200);
    let drift = last
        .q()
        .iter()
        .zip(scenario.q0.iter())
        .map(|(a, b)| (a - b).abs())
        .fold(0.0, f64::max);
    assert!(
        drift < 1e-6,
        "the arm moved by {drift} rad without a controller"
    );
}

#[test]
fn start_up_errors_exit_nonzero_with_a_clear_message() {
    if std::env::var(CONTROLLER_MODE_ENV).is_ok() {
        return;
    }
    let dir = std::env::temp_dir().join(format!("hcc-simd-bad-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let text = std::fs::read_to_string(config_path()).unwrap();
    let urdf = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../../config/planar4.urdf");
    let text = text
        .replace("planar4.urdf", urdf.to_str().unwrap())
        .replace("[ipc]", "[sim_daemon]\nhold_cycle = 3\n\n[ipc]");
    let bad = dir.join("bad.toml");
    std::fs::write(&bad, text).unwrap();
    let out = Command::new(env!("CARGO_BIN_EXE_hcc-sim"))
        .arg(&bad)
        .output()
        .unwrap();
    let _ = std::fs::remove_dir_all(&dir);
    assert!(!out.status.success());
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.contains("hold_cycle"), "{err}");

    let out = Command::new(env!("CARGO_BIN_EXE_hcc-sim"))
        .arg(config_path())
        .args(["--namespace", "bad/ns"])
        .output()
        .unwrap();
    assert!(!out.status.success());
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.contains("bad/ns"), "{err}");
}
