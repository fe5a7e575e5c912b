//! Two real processes over iceoryx2, started as a user starts them:
//! `hcc-sim --lockstep --duration 0.5` and `hcc-controller` on the paper's
//! simulation #1 (own namespace and file prefix). The simulator runs first
//! and waits for the controller without moving the arm.
//!
//! Checks: every state the simulator published equals, bit for bit, the
//! state of the same cycle of `hcc simulate` (the in-process run of the same
//! driver and control cycle), the TCP converges, both processes stop cleanly
//! with exit code 0, and no shared-memory file of the test's prefix remains.

use hcc_msgs::ipc::{self, MAX_SUBSCRIBER_BUFFER, Services};
use hcc_msgs::{DriverStatus, JointState, Namespace, ServiceNames};
use hcc_system_tests::*;
use iceoryx2::prelude::SignalHandlingMode;
use std::process::Command;
use std::time::{Duration, Instant};

const DURATION: &str = "0.5";

/// Runs the two daemons; the states the simulator published, in order.
fn lockstep_states(namespace: &str, prefix: &str) -> Vec<JointState> {
    let config = repo_root().join("config/paper-sim1.toml");
    let names = ServiceNames::for_namespace(Namespace::new(namespace).unwrap());
    let node = ipc::create_node(
        "two-process-test",
        SignalHandlingMode::Disabled,
        Some(prefix),
    )
    .unwrap();
    let services = Services::open(&node, &names).unwrap();
    let recorder = services
        .joint_state_subscriber(MAX_SUBSCRIBER_BUFFER)
        .unwrap();
    let ipc_args = ["--namespace", namespace, "--file-prefix", prefix];
    let mut sim = ChildGuard::spawn(
        Command::new(bin("hcc-sim"))
            .arg(&config)
            .args(ipc_args)
            .args(["--lockstep", "--duration", DURATION]),
    );
    std::thread::sleep(Duration::from_millis(100));
    let mut controller = ChildGuard::spawn(
        Command::new(bin("hcc-controller"))
            .arg(&config)
            .args(ipc_args)
            .args(["--wait", "event"]),
    );
    let mut states = Vec::new();
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
    let sim_status = sim
        .wait_timeout(Duration::from_secs(30))
        .expect("hcc-sim exits");
    assert!(sim_status.success(), "hcc-sim: {sim_status:?}");
    // SAFETY: a signal to our own child, by its pid.
    unsafe { libc::kill(controller.pid() as libc::pid_t, libc::SIGTERM) };
    let ctl_status = controller
        .wait_timeout(Duration::from_secs(30))
        .expect("the controller stops on SIGTERM");
    assert!(ctl_status.success(), "hcc-controller: {ctl_status:?}");
    states
}

#[test]
fn lockstep_daemons_converge_and_publish_the_states_of_hcc_simulate() {
    let dir = TempDir::new("two_processes");
    let namespace = unique_namespace("two_processes");
    let prefix = unique_file_prefix();
    let states = lockstep_states(&namespace, &prefix);
    assert_clean(&namespace, &prefix);

    let sim = run_with_timeout(
        Command::new(bin("hcc"))
            .current_dir(repo_root())
            .args(["simulate", "config/paper-sim1.toml", "--duration", DURATION])
            .arg("--out")
            .arg(dir.path())
            .arg("--no-plots"),
        dir.path(),
        "simulate",
        Duration::from_secs(120),
    );
    assert!(sim.status.success(), "hcc simulate failed\n{}", sim.log());
    let (header, rows) = read_csv(&dir.path().join("trajectory.csv"));
    let col = |name: &str| header.iter().position(|h| h == name).unwrap();
    let n = 4;
    let last = *states.last().unwrap();
    assert_eq!(last.header.seq, 500, "the final state is t = 0.5 s");
    assert_eq!(last.missed_commands, 0);
    assert_eq!(last.fallback_cycles, 0, "lockstep never falls back");
    let mut compared = 0;
    for s in &states {
        let row = &rows[s.header.seq as usize];
        for j in 0..n {
            let (q, qd) = (
                row[col(&format!("q{}", j + 1))],
                row[col(&format!("qd{}", j + 1))],
            );
            assert_eq!(
                q.to_bits(),
                s.q[j].to_bits(),
                "q{} at state {}",
                j + 1,
                s.header.seq
            );
            assert_eq!(
                qd.to_bits(),
                s.qd[j].to_bits(),
                "qd{} at state {}",
                j + 1,
                s.header.seq
            );
        }
        compared += 1;
    }
    assert!(compared > 100, "{compared} states compared");
    // The TCP converged toward its goal.
    let e = |k: usize| row_norm(&rows[k], &[col("e1_1"), col("e1_2")]);
    println!(
        "{compared} states equal to hcc simulate's; TCP error {:.4} m → {:.4} m",
        e(0),
        e(500)
    );
    assert!(e(500) < 0.2 * e(0), "no convergence");
}

fn row_norm(row: &[f64], cols: &[usize]) -> f64 {
    cols.iter().map(|&c| row[c] * row[c]).sum::<f64>().sqrt()
}
