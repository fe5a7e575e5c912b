//! `hcc-sim` as a process over iceoryx2 without a controller (own namespace
//! and file prefix): it holds the arm, reports the fallback, stops cleanly on
//! SIGTERM and leaves no shared-memory file behind; start-up errors exit
//! non-zero with a message naming the cause. (The daemons together:
//! `tests/two_processes.rs` and `tests/run_lockstep.rs` of the workspace.)

mod common;

use std::path::PathBuf;
use std::process::{Child, Command, ExitStatus};
use std::time::{Duration, Instant};

use hcc_config::Scenario;
use hcc_msgs::ipc::{self, MAX_SUBSCRIBER_BUFFER, Services};
use hcc_msgs::{DriverStatus, Namespace, ServiceNames};
use iceoryx2::prelude::SignalHandlingMode;

#[global_allocator]
static ALLOCATOR: hcc_rtalloc::RtAllocator = hcc_rtalloc::RtAllocator::new();

fn config_path() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../../config/paper-sim1.toml")
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

fn spawn_sim(ns: &str, prefix: &str, extra: &[&str]) -> ChildGuard {
    let child = Command::new(env!("CARGO_BIN_EXE_hcc-sim"))
        .arg(config_path())
        .args(["--namespace", ns, "--file-prefix", prefix])
        .args(extra)
        .spawn()
        .unwrap();
    ChildGuard { child: Some(child) }
}

#[test]
fn realtime_sim_without_controller_holds_the_arm_and_stops_cleanly() {
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
