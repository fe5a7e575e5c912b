//! `hcc run --view`: `hcc view` as a child process beside the daemons (a
//! pure subscriber of the run's namespace, at normal priority), started
//! before the controller so that it sees the run from its first state, and
//! stopped by pid (SIGTERM) whenever the run ends: the [`ViewChild`] is
//! dropped on every exit path, and the child gets SIGTERM if the launcher
//! dies.

use anyhow::{Context, bail};
use std::path::Path;
use std::time::{Duration, Instant};

use crate::daemons::{Daemon, TERMINATE_GRACE, describe_status};

/// Time `hcc view` gets to subscribe and listen.
const READY_TIMEOUT: Duration = Duration::from_secs(20);

/// The line `hcc view` prints once it subscribes and listens.
const READY_PREFIX: &str = "hcc view: ws://";

/// The running `hcc view` of a run; stopped when dropped.
pub struct ViewChild {
    daemon: Daemon,
    /// Its address line (`hcc view: ws://HOST:PORT (...)`).
    pub line: String,
}

impl ViewChild {
    /// Starts `hcc view --namespace NAMESPACE --config CONFIG --port PORT
    /// --rate RATE` and waits until it listens.
    pub fn start(
        namespace: &str,
        file_prefix: Option<&str>,
        config: &Path,
        port: u16,
        rate: f64,
    ) -> anyhow::Result<ViewChild> {
        let exe = std::env::current_exe().context("cannot locate the hcc executable")?;
        let args = [
            "view".to_string(),
            "--namespace".to_string(),
            namespace.to_string(),
            "--config".to_string(),
            config.display().to_string(),
            "--port".to_string(),
            port.to_string(),
            "--rate".to_string(),
            rate.to_string(),
            "--quiet".to_string(),
        ];
        let mut daemon = Daemon::spawn("hcc view", &exe, &args, file_prefix)?;
        let waiting = Instant::now();
        loop {
            if let Some(line) = daemon
                .stdout_lines()
                .into_iter()
                .find(|l| l.starts_with(READY_PREFIX))
            {
                return Ok(ViewChild { daemon, line });
            }
            if let Some(s) = daemon.poll() {
                bail!(
                    "hcc view (pid {}) exited with {} at start-up; its stderr ends with:\n{}",
                    daemon.pid(),
                    describe_status(s),
                    daemon.stderr_tail()
                );
            }
            if waiting.elapsed() > READY_TIMEOUT || crate::daemons::interrupted() {
                daemon.terminate(TERMINATE_GRACE);
                bail!(
                    "hcc view did not start within {} s; its stderr ends with:\n{}",
                    READY_TIMEOUT.as_secs(),
                    daemon.stderr_tail()
                );
            }
            std::thread::sleep(Duration::from_millis(10));
        }
    }
}

impl Drop for ViewChild {
    fn drop(&mut self) {
        self.daemon.terminate(TERMINATE_GRACE);
    }
}
