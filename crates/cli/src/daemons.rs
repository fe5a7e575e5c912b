//! The daemons as child processes of the `hcc` command (`hcc run`,
//! `hcc jitter`): found next to the `hcc` executable, started in their own
//! process group with SIGTERM on the launcher's death, their output tails kept
//! for error messages, stopped by pid (SIGTERM, then SIGKILL after a grace
//! period); the launcher's own SIGINT/SIGTERM handling; and the readiness
//! probe that tells when the controller listens.

use anyhow::{Context, anyhow, bail};
use hcc_msgs::ipc::{self, MAX_SUBSCRIBER_BUFFER};
use hcc_msgs::{JointState, ServiceNames, Telemetry, TorqueCommand};
use std::collections::VecDeque;
use std::io::{BufRead, BufReader, Read};
use std::path::{Path, PathBuf};
use std::process::{Child, Command, ExitStatus, Stdio};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

/// Lines of a child's output kept for error messages.
const TAIL_LINES: usize = 40;
/// Time the controller gets to open its services.
pub const STARTUP_TIMEOUT: Duration = Duration::from_secs(20);
/// Time a child gets to exit after SIGTERM before it is killed.
pub const TERMINATE_GRACE: Duration = Duration::from_secs(5);

/// SIGINT and SIGTERM set the stop flag of `hcc_rt` (the one the
/// daemons use); the launcher's loops then stop the children.
pub fn install_signal_handlers() -> anyhow::Result<()> {
    hcc_rt::install_stop_handler()
        .map_err(|e| anyhow!("cannot install the SIGINT/SIGTERM handlers: {e}"))
}

/// Whether SIGINT or SIGTERM was received.
pub fn interrupted() -> bool {
    hcc_rt::stop_requested()
}

type Tail = Arc<Mutex<VecDeque<String>>>;

fn keep_tail<R: Read + Send + 'static>(stream: R, tail: Tail) -> std::thread::JoinHandle<()> {
    std::thread::spawn(move || {
        let reader = BufReader::new(stream);
        for line in reader.lines() {
            let Ok(line) = line else { break };
            if let Ok(mut t) = tail.lock() {
                if t.len() == TAIL_LINES {
                    t.pop_front();
                }
                t.push_back(line);
            }
        }
    })
}

/// A daemon started by the launcher: its pid, exit status and output tails.
pub struct Daemon {
    pub name: &'static str,
    child: Child,
    status: Option<ExitStatus>,
    stderr: Tail,
    stdout: Tail,
    readers: Vec<std::thread::JoinHandle<()>>,
}

impl Daemon {
    pub fn spawn(
        name: &'static str,
        exe: &Path,
        args: &[String],
        file_prefix: Option<&str>,
    ) -> anyhow::Result<Daemon> {
        use std::os::unix::process::CommandExt;
        let mut cmd = Command::new(exe);
        cmd.args(args)
            .stdin(Stdio::null())
            .stdout(Stdio::piped())
            .stderr(Stdio::piped())
            // Own process group: a Ctrl-C at the terminal reaches only the
            // launcher, which then stops the children in order.
            .process_group(0);
        if let Some(p) = file_prefix {
            cmd.env(ipc::FILE_PREFIX_ENV, p);
        }
        // SAFETY: getpid before the fork; in the child only async-signal-safe
        // calls (prctl, getppid) and no allocation.
        let parent = unsafe { libc::getpid() };
        unsafe {
            cmd.pre_exec(move || {
                // The child gets SIGTERM if the launcher dies.
                if libc::prctl(libc::PR_SET_PDEATHSIG, libc::SIGTERM) != 0 {
                    return Err(std::io::Error::last_os_error());
                }
                if libc::getppid() != parent {
                    return Err(std::io::Error::from_raw_os_error(libc::ESRCH));
                }
                Ok(())
            });
        }
        let mut child = cmd
            .spawn()
            .with_context(|| format!("cannot start {name} ({})", exe.display()))?;
        tracing::debug!(pid = child.id(), exe = %exe.display(), ?args, "started {name}");
        let stderr: Tail = Arc::new(Mutex::new(VecDeque::new()));
        let stdout: Tail = Arc::new(Mutex::new(VecDeque::new()));
        let mut readers = Vec::new();
        if let Some(s) = child.stderr.take() {
            readers.push(keep_tail(s, stderr.clone()));
        }
        if let Some(s) = child.stdout.take() {
            readers.push(keep_tail(s, stdout.clone()));
        }
        Ok(Daemon {
            name,
            child,
            status: None,
            stderr,
            stdout,
            readers,
        })
    }

    pub fn pid(&self) -> u32 {
        self.child.id()
    }

    /// The exit status if the child has exited.
    pub fn poll(&mut self) -> Option<ExitStatus> {
        if self.status.is_none()
            && let Ok(Some(s)) = self.child.try_wait()
        {
            self.status = Some(s);
        }
        self.status
    }

    /// SIGTERM (by pid), wait up to `grace`, then SIGKILL. Returns the exit status.
    pub fn terminate(&mut self, grace: Duration) -> Option<ExitStatus> {
        if let Some(s) = self.poll() {
            return Some(s);
        }
        if let Ok(pid) = libc::pid_t::try_from(self.pid()) {
            // SAFETY: plain kill(2) on our own, not yet reaped child.
            unsafe {
                libc::kill(pid, libc::SIGTERM);
            }
        }
        let start = Instant::now();
        while start.elapsed() < grace {
            if let Some(s) = self.poll() {
                return Some(s);
            }
            std::thread::sleep(Duration::from_millis(5));
        }
        tracing::warn!(
            "{} (pid {}) did not exit within {:.1} s of SIGTERM; killing it",
            self.name,
            self.pid(),
            grace.as_secs_f64()
        );
        let _ = self.child.kill();
        self.status = self.child.wait().ok();
        self.status
    }

    /// The last lines the child wrote to stderr (after it exited, all of them).
    pub fn stderr_tail(&mut self) -> String {
        if self.status.is_some() {
            for r in self.readers.drain(..) {
                let _ = r.join();
            }
        }
        let lines: Vec<String> = self
            .stderr
            .lock()
            .map(|t| t.iter().cloned().collect())
            .unwrap_or_default();
        if lines.is_empty() {
            "    (nothing on stderr)".to_string()
        } else {
            lines
                .iter()
                .map(|l| format!("    {l}"))
                .collect::<Vec<_>>()
                .join("\n")
        }
    }

    pub fn stdout_lines(&mut self) -> Vec<String> {
        if self.status.is_some() {
            for r in self.readers.drain(..) {
                let _ = r.join();
            }
        }
        self.stdout
            .lock()
            .map(|t| t.iter().cloned().collect())
            .unwrap_or_default()
    }
}

impl Drop for Daemon {
    fn drop(&mut self) {
        if self.poll().is_none() {
            self.terminate(TERMINATE_GRACE);
        }
    }
}

pub fn daemon_path(name: &str) -> anyhow::Result<PathBuf> {
    let exe = std::env::current_exe().context("cannot locate the hcc executable")?;
    let path = exe.with_file_name(name);
    if !path.exists() {
        bail!(
            "{name} not found next to {} (build the daemons: cargo build --release --bins)",
            exe.display()
        );
    }
    Ok(path)
}

pub fn describe_status(s: ExitStatus) -> String {
    use std::os::unix::process::ExitStatusExt;
    match (s.code(), s.signal()) {
        (Some(c), _) => format!("exit code {c}"),
        (None, Some(sig)) => format!("signal {sig}"),
        _ => "unknown status".into(),
    }
}

/// Readiness probe of the controller: whether it has created its torque and
/// telemetry publishers and its joint-state subscriber. Opens the services
/// with the contract's settings (those of `hcc_msgs::ipc`; an opener must ask
/// for exactly what the creator provides).
pub struct ControllerProbe {
    joint_state:
        iceoryx2::service::port_factory::publish_subscribe::PortFactory<ipc::Ipc, JointState, ()>,
    torque_command: iceoryx2::service::port_factory::publish_subscribe::PortFactory<
        ipc::Ipc,
        TorqueCommand,
        (),
    >,
    telemetry:
        iceoryx2::service::port_factory::publish_subscribe::PortFactory<ipc::Ipc, Telemetry, ()>,
}

fn probe_service<T: std::fmt::Debug + iceoryx2::prelude::ZeroCopySend>(
    node: &ipc::IpcNode,
    name: &str,
    max_subscribers: usize,
) -> anyhow::Result<iceoryx2::service::port_factory::publish_subscribe::PortFactory<ipc::Ipc, T, ()>>
{
    let service = iceoryx2::prelude::ServiceName::new(name)
        .map_err(|e| anyhow!("service {name:?}: invalid name ({e:?})"))?;
    node.service_builder(&service)
        .publish_subscribe::<T>()
        .max_publishers(1)
        .max_subscribers(max_subscribers)
        .max_nodes(ipc::MAX_NODES)
        .history_size(0)
        .subscriber_max_buffer_size(MAX_SUBSCRIBER_BUFFER)
        .subscriber_max_borrowed_samples(ipc::MAX_BORROWED_SAMPLES)
        .enable_safe_overflow(true)
        .open()
        .map_err(|e| anyhow!("service {name:?}: cannot open it to watch the controller ({e:?})"))
}

impl ControllerProbe {
    pub fn new(node: &ipc::IpcNode, names: &ServiceNames) -> anyhow::Result<ControllerProbe> {
        Ok(ControllerProbe {
            joint_state: probe_service(node, names.joint_state(), ipc::MAX_STATE_SUBSCRIBERS)?,
            torque_command: probe_service(
                node,
                names.torque_command(),
                ipc::MAX_COMMAND_SUBSCRIBERS,
            )?,
            telemetry: probe_service(node, names.telemetry(), ipc::MAX_TELEMETRY_SUBSCRIBERS)?,
        })
    }

    /// Whether the controller's ports exist; `others` joint-state subscribers
    /// that are not the controller's (the recorder of `hcc run`) are discounted.
    pub fn ready(&self, others: usize) -> bool {
        use iceoryx2::service::port_factory::PortFactory as _;
        self.torque_command.dynamic_config().number_of_publishers() >= 1
            && self.telemetry.dynamic_config().number_of_publishers() >= 1
            && self.joint_state.dynamic_config().number_of_subscribers() > others
    }
}

/// Waits until the controller `controller` has opened its services on `names`
/// (so that a simulator started now is answered from its first state);
/// `other_subscribers` is the number of joint-state subscribers of the
/// launcher itself. Fails with the controller's stderr if it exits, hangs or
/// the launcher is interrupted.
pub fn wait_until_controller_listens(
    controller: &mut Daemon,
    node: &ipc::IpcNode,
    names: &ServiceNames,
    other_subscribers: usize,
) -> anyhow::Result<()> {
    // The services exist once some process has opened them: the launcher's
    // recorder (hcc run) or the controller itself (hcc jitter).
    let mut probe = None;
    let waiting = Instant::now();
    loop {
        if probe.is_none() {
            probe = ControllerProbe::new(node, names).ok();
        }
        if probe.as_ref().is_some_and(|p| p.ready(other_subscribers)) {
            break;
        }
        if let Some(s) = controller.poll() {
            bail!(
                "hcc-controller (pid {}) exited with {} at start-up; its stderr ends with:\n{}",
                controller.pid(),
                describe_status(s),
                controller.stderr_tail()
            );
        }
        if interrupted() {
            controller.terminate(TERMINATE_GRACE);
            bail!("interrupted while starting hcc-controller");
        }
        if waiting.elapsed() > STARTUP_TIMEOUT {
            controller.terminate(TERMINATE_GRACE);
            bail!(
                "hcc-controller did not open its services within {} s; its stderr ends with:\n{}",
                STARTUP_TIMEOUT.as_secs(),
                controller.stderr_tail()
            );
        }
        std::thread::sleep(Duration::from_millis(2));
    }
    Ok(())
}
