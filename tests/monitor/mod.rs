//! What the fault tests share: starting the daemons as separate processes on
//! a test's own namespace and file prefix, and a monitor that watches the
//! namespace's joint states, torque commands and telemetry the way a
//! recorder does (largest queues, drained every millisecond).

#![allow(dead_code)]

use std::path::{Path, PathBuf};
use std::process::Command;
use std::time::{Duration, Instant};

use hcc_msgs::ipc::{
    self, CommandSubscriber, IpcNode, MAX_SUBSCRIBER_BUFFER, Services, StateSubscriber,
    TelemetrySubscriber,
};
use hcc_msgs::{JointState, ServiceNames, Telemetry, TelemetryCounters, TorqueCommand};
use hcc_system_tests::{ChildGuard, FILE_PREFIX_ENV, bin, repo_root};
use iceoryx2::prelude::SignalHandlingMode;

/// The slice of a telemetry sample the tests look at.
#[derive(Debug, Clone, Copy)]
pub struct TelemetryRecord {
    pub stamp_ns: u64,
    pub state_seq: u64,
    pub command_seq: u64,
    pub mode: u32,
    pub counters: TelemetryCounters,
    pub max_abs_tau: f64,
    pub singular_levels: u32,
    /// The sample reports a lost driver (no answer).
    pub peer_lost: bool,
}

impl TelemetryRecord {
    fn from(t: &Telemetry) -> TelemetryRecord {
        TelemetryRecord {
            stamp_ns: t.header.stamp_ns,
            state_seq: t.state_seq,
            command_seq: t.command_seq,
            mode: t.mode,
            counters: t.counters,
            max_abs_tau: t.tau().iter().fold(0.0, |m, x| m.max(x.abs())),
            singular_levels: t.singular_levels,
            peer_lost: t.peer_lost(),
        }
    }
}

/// Subscribes to a namespace's streams and keeps everything it receives.
pub struct Monitor {
    // Drop order: ports, then services, then the node.
    states_sub: StateSubscriber,
    commands_sub: CommandSubscriber,
    telemetry_sub: TelemetrySubscriber,
    services: Services,
    node: IpcNode,
    pub states: Vec<JointState>,
    pub commands: Vec<TorqueCommand>,
    pub telemetry: Vec<TelemetryRecord>,
}

impl Monitor {
    pub fn new(namespace: &str, prefix: &str) -> Monitor {
        let node = ipc::create_node(
            "fault-test-monitor",
            SignalHandlingMode::Disabled,
            Some(prefix),
        )
        .expect("monitor node");
        let names = ServiceNames::new(namespace).expect("namespace");
        let services = Services::open(&node, &names).expect("services");
        Monitor {
            states_sub: services
                .joint_state_subscriber(MAX_SUBSCRIBER_BUFFER)
                .unwrap(),
            commands_sub: services
                .torque_command_subscriber(MAX_SUBSCRIBER_BUFFER)
                .unwrap(),
            telemetry_sub: services
                .telemetry_subscriber(MAX_SUBSCRIBER_BUFFER)
                .unwrap(),
            services,
            node,
            states: Vec::new(),
            commands: Vec::new(),
            telemetry: Vec::new(),
        }
    }

    /// The services, e.g. to try opening a second publisher.
    pub fn services(&self) -> &Services {
        &self.services
    }

    /// Drains all three queues.
    pub fn pump(&mut self) {
        while let Ok(Some(s)) = self.states_sub.receive() {
            self.states.push(*s);
        }
        while let Ok(Some(c)) = self.commands_sub.receive() {
            self.commands.push(*c);
        }
        while let Ok(Some(t)) = self.telemetry_sub.receive() {
            self.telemetry.push(TelemetryRecord::from(&t));
        }
    }

    /// Pumps every millisecond until `done` holds; panics with `what` after `timeout`.
    pub fn wait_until(
        &mut self,
        what: &str,
        timeout: Duration,
        mut done: impl FnMut(&Monitor) -> bool,
    ) {
        let start = Instant::now();
        loop {
            self.pump();
            if done(self) {
                return;
            }
            assert!(
                start.elapsed() < timeout,
                "timed out after {} s waiting for: {what} ({} states, {} commands, {} telemetry samples seen)",
                timeout.as_secs(),
                self.states.len(),
                self.commands.len(),
                self.telemetry.len()
            );
            std::thread::sleep(Duration::from_millis(1));
        }
    }

    /// Pumps for `d`.
    pub fn watch_for(&mut self, d: Duration) {
        let start = Instant::now();
        while start.elapsed() < d {
            self.pump();
            std::thread::sleep(Duration::from_millis(1));
        }
        self.pump();
    }

    /// The newest telemetry sample.
    pub fn last_telemetry(&self) -> Option<TelemetryRecord> {
        self.telemetry.last().copied()
    }
}

/// A daemon of this workspace started on a namespace and file prefix, with
/// its stderr in a file.
pub struct Daemon {
    pub guard: ChildGuard,
    pub stderr: PathBuf,
    pub name: String,
}

impl Daemon {
    /// Starts `binary CONFIG --namespace NS [extra]` with the file prefix in
    /// the environment.
    pub fn start(
        binary: &str,
        config: &Path,
        namespace: &str,
        prefix: &str,
        dir: &Path,
        tag: &str,
        extra: &[&str],
    ) -> Daemon {
        let stderr = dir.join(format!("{tag}.stderr"));
        let guard = ChildGuard::spawn(
            Command::new(bin(binary))
                .env(FILE_PREFIX_ENV, prefix)
                .arg(config)
                .args(["--namespace", namespace])
                .args(extra)
                .stdout(std::fs::File::create(dir.join(format!("{tag}.stdout"))).unwrap())
                .stderr(std::fs::File::create(&stderr).unwrap()),
        );
        Daemon {
            guard,
            stderr,
            name: tag.to_string(),
        }
    }

    /// `hcc-controller` on the paper's Sim #1 scenario (the system tests' robot).
    pub fn controller(namespace: &str, prefix: &str, dir: &Path, tag: &str) -> Daemon {
        let config = repo_root().join("config/paper-sim1.toml");
        Daemon::start("hcc-controller", &config, namespace, prefix, dir, tag, &[])
    }

    /// `hcc-sim --realtime` on the paper's Sim #1 scenario.
    pub fn sim(namespace: &str, prefix: &str, dir: &Path, tag: &str) -> Daemon {
        let config = repo_root().join("config/paper-sim1.toml");
        Daemon::start(
            "hcc-sim",
            &config,
            namespace,
            prefix,
            dir,
            tag,
            &["--realtime"],
        )
    }

    pub fn pid(&self) -> u32 {
        self.guard.pid()
    }

    /// Its stderr so far.
    pub fn log(&self) -> String {
        std::fs::read_to_string(&self.stderr).unwrap_or_default()
    }

    /// Whether it is still running.
    pub fn running(&mut self) -> bool {
        matches!(self.guard.child.try_wait(), Ok(None))
    }

    /// SIGKILL: a crash, no clean-up of its own.
    pub fn crash(&mut self) {
        self.guard.kill();
    }

    /// SIGTERM, then waits for a clean exit (panics otherwise).
    pub fn stop(&mut self) {
        // SAFETY: a signal to our own child, by pid.
        unsafe { libc::kill(self.pid() as libc::pid_t, libc::SIGTERM) };
        let status = self
            .guard
            .wait_timeout(Duration::from_secs(20))
            .unwrap_or_else(|| panic!("{} did not stop on SIGTERM:\n{}", self.name, self.log()));
        assert!(
            status.success(),
            "{} exited with {status:?}:\n{}",
            self.name,
            self.log()
        );
    }

    /// Waits until its stderr contains `needle`.
    pub fn wait_for_log(&mut self, needle: &str, timeout: Duration) -> String {
        let start = Instant::now();
        loop {
            let log = self.log();
            if log.contains(needle) {
                return log;
            }
            assert!(
                start.elapsed() < timeout,
                "{} did not log {needle:?} within {} s:\n{log}",
                self.name,
                timeout.as_secs()
            );
            std::thread::sleep(Duration::from_millis(10));
        }
    }
}
