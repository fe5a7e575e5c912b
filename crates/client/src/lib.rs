//! # hcc-client — commanding a running hcc controller
//!
//! A [`Client`] connects to a controller's namespace, sends [`Setpoint`]s on
//! `hcc/<ns>/setpoint` (goals, velocity feed-forward, stiffness, damping,
//! transitions) and reads its telemetry, where the controller answers every
//! setpoint ([`hcc_msgs::SetpointAnswer`]: accepted, or a [`SetpointRejection`]
//! code). Levels are 0-based here, in the order of the scenario's
//! `[[level]]`s.
//!
//! ```no_run
//! use std::time::Duration;
//! let mut client = hcc_client::Client::connect("panda", None).unwrap();
//! let seq = client.set_goal(0, &[0.5, 0.1, 0.4], 2.0).unwrap();
//! let answer = client.wait_until_accepted(seq, Duration::from_secs(1)).unwrap();
//! println!("moving over {:.2} s", answer.duration_s);
//! client.wait_until_converged(0, 1e-3, Duration::from_secs(5)).unwrap();
//! ```
//!
//! Not for a real-time thread: connecting allocates; sending and reading do
//! not, but waiting sleeps.

mod path;
pub use path::KnotsRefused;

use std::time::{Duration, Instant};

use hcc_msgs::ipc::{
    self, IpcError, IpcNode, PathPublisher, Services, SetpointPublisher, TelemetrySubscriber,
};
use hcc_msgs::{
    ANSWER_ACCEPTED, ServiceNames, Setpoint, SetpointAnswer, SetpointRejection, Telemetry,
};
use iceoryx2::prelude::SignalHandlingMode;

/// Telemetry queue of a client (it keeps the newest sample).
const TELEMETRY_BUFFER: usize = 16;
/// Poll interval while waiting.
const POLL: Duration = Duration::from_millis(1);

/// What went wrong, in plain words.
#[derive(Debug, thiserror::Error)]
pub enum ClientError {
    /// The namespace or the services could not be opened.
    #[error(transparent)]
    Ipc(#[from] IpcError),
    /// The namespace is invalid.
    #[error(transparent)]
    Namespace(#[from] hcc_msgs::NamespaceError),
    /// The setpoint failed the checks before it was sent (nothing was sent).
    #[error("setpoint not sent: {0}")]
    Invalid(SetpointRejection),
    /// Publishing failed.
    #[error("cannot send the setpoint: {0}")]
    Send(String),
    /// The controller rejected the setpoint.
    #[error("rejected by the controller: {0}")]
    Rejected(SetpointRejection),
    /// The path's knots failed the checks before they were sent (nothing
    /// was sent).
    #[error("path not sent: {0}")]
    PathInvalid(hcc_msgs::KnotsRejection),
    /// The controller refused the path's knots.
    #[error("path refused by the controller: {0}")]
    PathRejected(hcc_msgs::PathRejection),
    /// The load failed the checks before it was sent (nothing was sent).
    #[error("load not sent: {0}")]
    LoadInvalid(hcc_msgs::LoadRefusal),
    /// The controller refused the load.
    #[error("load refused by the controller: {0}")]
    LoadRejected(hcc_msgs::LoadRejection),
    /// The controller answered with a code this client does not know.
    #[error("the controller answered with unknown code {0}")]
    UnknownCode(u32),
    /// No answer (or no convergence) within the timeout.
    #[error("{0}")]
    Timeout(String),
}

/// The error of a refusal's answer code (a setpoint's or a path's).
fn rejection(code: u32) -> ClientError {
    if let Some(r) = SetpointRejection::from_code(code) {
        ClientError::Rejected(r)
    } else if let Some(r) = hcc_msgs::PathRejection::from_code(code) {
        ClientError::PathRejected(r)
    } else if let Some(r) = hcc_msgs::LoadRejection::from_code(code) {
        ClientError::LoadRejected(r)
    } else {
        ClientError::UnknownCode(code)
    }
}

/// A connection to one controller.
pub struct Client {
    _node: IpcNode,
    publisher: SetpointPublisher,
    paths: PathPublisher,
    loads: hcc_msgs::ipc::LoadPublisher,
    telemetry: TelemetrySubscriber,
    client_id: u64,
    seq: u64,
    latest: Option<Box<Telemetry>>,
}

impl Client {
    /// Connects to the controller of `namespace` (with the iceoryx2 file
    /// prefix of its peers, or the default).
    pub fn connect(namespace: &str, file_prefix: Option<&str>) -> Result<Client, ClientError> {
        let names = ServiceNames::new(namespace)?;
        let pid = std::process::id() as u64;
        let node = ipc::create_node(
            &format!("hcc-client-{pid}"),
            SignalHandlingMode::Disabled,
            file_prefix,
        )?;
        let services = Services::open(&node, &names)?;
        let publisher = services.setpoint_publisher()?;
        let paths = services.path_publisher()?;
        let loads = services.load_publisher()?;
        let telemetry = services.telemetry_subscriber(TELEMETRY_BUFFER)?;
        // Unique among the clients of one host: the process id and the clock.
        let client_id = (pid << 32) ^ (hcc_msgs::monotonic_now_ns() & 0xffff_ffff);
        Ok(Client {
            _node: node,
            publisher,
            paths,
            loads,
            telemetry,
            client_id,
            seq: 0,
            latest: None,
        })
    }

    /// This client's id (answers are kept under it).
    pub fn client_id(&self) -> u64 {
        self.client_id
    }

    /// A setpoint of this client for `level` (0-based) and dimension `dim`,
    /// with the next sequence number; fill it with the `with_*` builders and
    /// hand it to [`Client::send`].
    pub fn setpoint(&mut self, level: usize, dim: usize) -> Setpoint {
        self.seq += 1;
        Setpoint::for_level(self.client_id, self.seq, level, dim)
    }

    /// Checks `setpoint` (the model-free checks) and publishes it; returns
    /// its sequence number. Use it for a stream (e.g. goal and velocity
    /// every millisecond).
    pub fn send(&mut self, setpoint: &Setpoint) -> Result<u64, ClientError> {
        self.publish(setpoint)?;
        Ok(setpoint.header.seq)
    }

    /// [`Client::send`], returning how many subscribers (controllers) the
    /// setpoint reached: 0 means no controller listens yet, and the setpoint
    /// is lost (the service keeps no history).
    pub fn publish(&mut self, setpoint: &Setpoint) -> Result<usize, ClientError> {
        setpoint.validate().map_err(ClientError::Invalid)?;
        let mut s = *setpoint;
        s.header.stamp_ns = hcc_msgs::monotonic_now_ns();
        self.publisher
            .send_copy(s)
            .map_err(|e| ClientError::Send(format!("{e:?}")))
    }

    /// Sets level `level`'s goal (its task coordinates, as in the TOML) over
    /// a transition of `duration_s` (0: as fast as the level allows).
    pub fn set_goal(
        &mut self,
        level: usize,
        goal: &[f64],
        duration_s: f64,
    ) -> Result<u64, ClientError> {
        let sp = self
            .setpoint(level, goal.len())
            .with_goal(goal)
            .map_err(ClientError::Invalid)?
            .with_duration(duration_s);
        self.send(&sp)
    }

    /// Sets level `level`'s stiffness and/or damping (m diagonal values or
    /// m² row-major each; an empty slice keeps one) over `duration_s`.
    pub fn set_gains(
        &mut self,
        level: usize,
        dim: usize,
        stiffness: &[f64],
        damping: &[f64],
        duration_s: f64,
    ) -> Result<u64, ClientError> {
        let mut sp = self.setpoint(level, dim).with_duration(duration_s);
        if !stiffness.is_empty() {
            sp = sp.with_stiffness(stiffness).map_err(ClientError::Invalid)?;
        }
        if !damping.is_empty() {
            sp = sp.with_damping(damping).map_err(ClientError::Invalid)?;
        }
        self.send(&sp)
    }

    /// Reads the telemetry queue; returns the newest sample seen so far.
    pub fn poll_telemetry(&mut self) -> Option<&Telemetry> {
        while let Ok(Some(sample)) = self.telemetry.receive() {
            match &mut self.latest {
                Some(t) => **t = *sample,
                None => self.latest = Some(Box::new(*sample)),
            }
        }
        self.latest.as_deref()
    }

    /// Tells the controller the load the robot's hand holds from now on
    /// (docs/load.md; `message` with this client's id and next sequence
    /// number filled in) and waits for the answer: accepted, or the reason.
    pub fn set_load(
        &mut self,
        mut message: hcc_msgs::LoadSetpoint,
        timeout: Duration,
    ) -> Result<SetpointAnswer, ClientError> {
        message.client_id = self.client_id;
        message.validate().map_err(ClientError::LoadInvalid)?;
        self.seq += 1;
        message.header.seq = self.seq;
        message.header.stamp_ns = hcc_msgs::monotonic_now_ns();
        self.loads
            .send_copy(message)
            .map_err(|e| ClientError::Send(format!("{e:?}")))?;
        let seq = self.seq;
        self.wait_until_accepted(seq, timeout)
    }

    /// Waits for the controller's answer to this client's setpoint `seq`:
    /// the answer when accepted, [`ClientError::Rejected`] with the reason,
    /// or [`ClientError::Timeout`] when no controller answers.
    pub fn wait_until_accepted(
        &mut self,
        seq: u64,
        timeout: Duration,
    ) -> Result<SetpointAnswer, ClientError> {
        let a = self.wait_for_answer(seq, timeout)?;
        match a.code {
            ANSWER_ACCEPTED => Ok(a),
            code => Err(rejection(code)),
        }
    }

    /// Waits for the controller's answer to this client's message `seq`,
    /// whatever its code.
    pub(crate) fn wait_for_answer(
        &mut self,
        seq: u64,
        timeout: Duration,
    ) -> Result<SetpointAnswer, ClientError> {
        let id = self.client_id;
        let deadline = Instant::now() + timeout;
        loop {
            let answer = self
                .poll_telemetry()
                .and_then(|t| t.answer_for(id).copied())
                .filter(|a| a.seq >= seq);
            if let Some(a) = answer {
                return Ok(a);
            }
            if Instant::now() >= deadline {
                return Err(ClientError::Timeout(format!(
                    "no controller answered setpoint {seq} within {:.1} s (is hcc-controller running in this namespace?)",
                    timeout.as_secs_f64()
                )));
            }
            std::thread::sleep(POLL);
        }
    }

    /// Waits until level `level`'s transition is over and its task error
    /// norm is ≤ `tolerance`; returns that norm.
    pub fn wait_until_converged(
        &mut self,
        level: usize,
        tolerance: f64,
        timeout: Duration,
    ) -> Result<f64, ClientError> {
        let deadline = Instant::now() + timeout;
        let mut last = f64::NAN;
        loop {
            if let Some(t) = self.poll_telemetry() {
                let e = t.task_error(level);
                last = e.iter().map(|x| x * x).sum::<f64>().sqrt();
                let at_rest = level < t.levels() && t.transition_progress[level] >= 1.0;
                if at_rest && !e.is_empty() && last <= tolerance {
                    return Ok(last);
                }
            }
            if Instant::now() >= deadline {
                return Err(ClientError::Timeout(format!(
                    "level {level} did not converge to {tolerance} within {:.1} s (error {last:.3e})",
                    timeout.as_secs_f64()
                )));
            }
            std::thread::sleep(POLL);
        }
    }
}
