//! Capturing a namespace's streams into an MCAP recording, as a pure
//! subscriber: the receiver thread copies every joint state, torque command,
//! telemetry sample, setpoint, path and load message out of the iceoryx2
//! queues through a tap (`hcc_msgs::ipc::Tap`: the largest queues the
//! services allow, 128 samples, i.e. 128 ms
//! at 1 kHz, drained every [`POLL`] — at once again when a drain found half a
//! queue, as in lockstep runs faster than real time — so that publishers,
//! which never block, lose nothing to the recorder), and the
//! [`StreamRecorder`] writes them into
//! the file as they arrive, counting sequence gaps and drops per stream with
//! [`SequenceChecker`]s. Used by `hcc record` and `hcc run` alike.
//!
//! The receiver thread asks for a low SCHED_FIFO priority
//! ([`RECEIVER_PRIORITY`], below the daemons' loops, which it never
//! preempts) when the process may have it: at normal priority a machine
//! loaded by other work (compilers, here) kept it from draining for more
//! than the queues' 128 ms now and then, and samples were lost. Between the
//! receiver and the writer at most [`BACKLOG`] samples wait (about two
//! seconds of the three 1 kHz streams, at most ≈ 25 MB): a writer that
//! falls further behind loses samples, which are counted
//! ([`Receiver::dropped`]) and show as gaps in the file — the recorder's
//! memory stays bounded whatever the load.

use crate::mcap_log::{McapWriter, RecorderMsg, RunInfo, StreamStats};
use anyhow::{Context, bail};
use hcc_msgs::ipc::{TAP_BURST, TapNode, TapStreams, Tapped};
use hcc_msgs::{
    JointState, LoadSetpoint, PathKnots, SeqEvent, SequenceChecker, ServiceNames, Setpoint,
    Telemetry, TorqueCommand,
};
use std::collections::BTreeMap;
use std::path::Path;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::{Arc, mpsc};
use std::time::{Duration, Instant};

/// A sample copied out of shared memory by the receiver thread.
pub enum Received {
    State(Box<JointState>),
    Command(Box<TorqueCommand>),
    Telemetry(Box<Telemetry>),
    Setpoint(Box<Setpoint>),
    Path(Box<PathKnots>),
    Load(Box<LoadSetpoint>),
    /// The receiver failed and stopped.
    Failed(String),
}

/// SCHED_FIFO priority of the receiver thread when permitted: above every
/// normal-priority process, below the daemons' loops (80 by default).
pub const RECEIVER_PRIORITY: i32 = 20;

/// Samples that may wait between the receiver and the writer (about two
/// seconds of joint states, commands and telemetry at 1 kHz).
pub const BACKLOG: usize = 6_000;

/// The receiver's sleep between drains: 1/128 of what a queue holds at
/// 1 kHz. (A 100 µs poll, as before, woke the thread 10 000 times a second
/// on the daemons' cores for nothing.)
pub const POLL: Duration = Duration::from_millis(1);

/// The receiver's sleep between drains in a lockstep run, whose daemons turn
/// as fast as they can (tens of kHz): a queue of [`MAX_SUBSCRIBER_BUFFER`](hcc_msgs::ipc::MAX_SUBSCRIBER_BUFFER)
/// samples then lasts a few milliseconds, and there is no real-time loop
/// whose core the wake-ups would disturb.
pub const LOCKSTEP_POLL: Duration = Duration::from_micros(100);

/// How the receiver keeps up with the publishers.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Pace {
    /// Drains every [`POLL`]; a writer [`BACKLOG`] samples behind loses
    /// samples, counted (the daemons never wait for the recorder).
    Realtime,
    /// Drains every [`LOCKSTEP_POLL`], waits for a writer that is behind, and
    /// publishes its progress after each drain, for the simulator of a
    /// lockstep run to wait on (`hcc_msgs::ipc::RecorderProgressPublisher`):
    /// nothing is lost, however long the recorder stalls.
    Lockstep,
}

/// The subscribers, on a thread of their own that does nothing but copy
/// samples out of the queues into a bounded channel, so that writing the
/// file never delays the draining (in lockstep the daemons run much faster
/// than real time).
pub struct Receiver {
    handle: Option<std::thread::JoinHandle<()>>,
    stop: Arc<AtomicBool>,
    rx: mpsc::Receiver<Received>,
    dropped: Arc<AtomicU64>,
    /// Why the receiver thread runs at normal priority, if it does.
    pub priority_warning: Option<String>,
}

/// The receiver thread's end of the channel: full means the writer is
/// [`BACKLOG`] samples behind, and the sample is dropped and counted — or,
/// when `wait` (a lockstep run), waited for.
struct Sink {
    tx: mpsc::SyncSender<Received>,
    dropped: Arc<AtomicU64>,
    wait: bool,
}

impl Sink {
    fn send(&self, m: Received) {
        if self.wait {
            // Fails only once the writer is gone (nothing to record then).
            let _ = self.tx.send(m);
        } else if let Err(mpsc::TrySendError::Full(_)) = self.tx.try_send(m) {
            self.dropped.fetch_add(1, Ordering::Relaxed);
        }
    }
}

/// A tapped sample, copied out of shared memory.
fn received(m: Tapped<'_>) -> Received {
    match m {
        Tapped::State(s) => Received::State(Box::new(*s)),
        Tapped::Command(c) => Received::Command(Box::new(*c)),
        Tapped::Telemetry(t) => Received::Telemetry(Box::new(*t)),
        Tapped::Setpoint(s) => Received::Setpoint(Box::new(*s)),
        Tapped::Path(p) => Received::Path(Box::new(*p)),
        Tapped::Load(l) => Received::Load(Box::new(*l)),
    }
}

impl Receiver {
    /// Subscribes (on the new thread, node `node_name`, at SCHED_FIFO
    /// `priority` when given and permitted, at `pace`) and returns once the
    /// subscribers (and with [`Pace::Lockstep`] the progress publisher) exist.
    pub fn start(
        node_name: &str,
        file_prefix: Option<String>,
        names: ServiceNames,
        priority: Option<i32>,
        pace: Pace,
    ) -> anyhow::Result<Receiver> {
        let (tx, rx) = mpsc::sync_channel(BACKLOG);
        let dropped = Arc::new(AtomicU64::new(0));
        let lockstep = pace == Pace::Lockstep;
        let poll = if lockstep { LOCKSTEP_POLL } else { POLL };
        let tx = Sink {
            tx,
            dropped: dropped.clone(),
            wait: lockstep,
        };
        type Ready = Result<Option<String>, String>;
        let (ready_tx, ready_rx) = mpsc::sync_channel::<Ready>(1);
        let stop = Arc::new(AtomicBool::new(false));
        let stop_flag = stop.clone();
        let node_name = node_name.to_string();
        let handle = std::thread::Builder::new()
            .name("hcc-receiver".into())
            .spawn(move || {
                let warning = priority.and_then(|p| {
                    hcc_rt::set_fifo(p).err().map(|e| {
                        format!(
                            "the recorder's receiver runs at normal priority (SCHED_FIFO {p}: {e}); \
                             under load it may lose samples (counted as gaps)"
                        )
                    })
                });
                let opened = TapNode::open(
                    &node_name,
                    file_prefix.as_deref(),
                    &names,
                    TapStreams::All,
                )
                .and_then(|mut t| {
                    if lockstep {
                        t.enable_progress()?;
                    }
                    Ok(t)
                });
                let mut tap = match opened {
                    Ok(t) => {
                        let _ = ready_tx.send(Ok(warning));
                        t
                    }
                    Err(e) => {
                        let _ = ready_tx.send(Err(e.to_string()));
                        return;
                    }
                };
                loop {
                    // Read the flag before draining: after a stop request
                    // one more complete drain (every queue emptied) happens,
                    // then the thread ends, whether or not the publishers
                    // are still running.
                    let last = stop_flag.load(Ordering::SeqCst);
                    let drained = tap
                        .tap()
                        .drain(&mut |m| tx.send(received(m)))
                        .and_then(|k| tap.publish_progress().map(|()| k));
                    match drained {
                        Ok(_) if last => break,
                        Ok(k) if k >= TAP_BURST => {}
                        Ok(_) => std::thread::sleep(poll),
                        Err(e) => {
                            // Blocking: the failure must reach the writer.
                            let _ = tx.tx.send(Received::Failed(e.to_string()));
                            break;
                        }
                    }
                }
                drop(tap);
            })
            .context("cannot start the receiver thread")?;
        match ready_rx.recv() {
            Ok(Ok(priority_warning)) => Ok(Receiver {
                handle: Some(handle),
                stop,
                rx,
                dropped,
                priority_warning,
            }),
            Ok(Err(e)) => {
                let _ = handle.join();
                bail!(e)
            }
            Err(_) => bail!("the receiver thread ended during start-up"),
        }
    }

    /// Samples dropped because the writer was [`BACKLOG`] samples behind.
    pub fn dropped(&self) -> u64 {
        self.dropped.load(Ordering::Relaxed)
    }

    /// Hands the samples received so far to `f` (waiting up to `wait` for
    /// the first one); returns how many.
    pub fn pump(
        &self,
        wait: Duration,
        mut f: impl FnMut(Received) -> anyhow::Result<()>,
    ) -> anyhow::Result<usize> {
        let mut k = 0;
        let mut next = self.rx.recv_timeout(wait).ok();
        while let Some(m) = next {
            if let Received::Failed(e) = m {
                bail!("recorder: {e}");
            }
            f(m)?;
            k += 1;
            next = self.rx.try_recv().ok();
        }
        Ok(k)
    }

    /// Stops the thread after a last drain, hands everything to `f` and
    /// closes the subscribers (and the node).
    pub fn finish(
        mut self,
        mut f: impl FnMut(Received) -> anyhow::Result<()>,
    ) -> anyhow::Result<()> {
        self.stop.store(true, Ordering::SeqCst);
        if let Some(h) = self.handle.take() {
            // A lockstep receiver may be waiting for room in the channel.
            while !h.is_finished() {
                self.pump(Duration::from_millis(1), &mut f)?;
            }
            let _ = h.join();
        }
        while self.pump(Duration::ZERO, &mut f)? > 0 {}
        Ok(())
    }
}

impl Drop for Receiver {
    fn drop(&mut self) {
        self.stop.store(true, Ordering::SeqCst);
        if let Some(h) = self.handle.take() {
            // A lockstep receiver may be waiting for room in the channel:
            // what it still hands on is discarded.
            while !h.is_finished() {
                while self.rx.try_recv().is_ok() {}
                std::thread::sleep(Duration::from_millis(1));
            }
            let _ = h.join();
        }
    }
}

/// Sequence bookkeeping of one stream.
#[derive(Default)]
struct Stream {
    checker: SequenceChecker,
    stats: StreamStats,
}

impl Stream {
    fn observe(&mut self, seq: u64) -> SeqEvent {
        self.stats.received += 1;
        // A smaller number is a new publisher's (a restarted daemon).
        let e = self.checker.observe_restarting(seq);
        if let SeqEvent::Gap { .. } = e {
            self.stats.gap_events += 1;
        }
        self.stats.gaps = self.checker.missed();
        self.stats.duplicates = self.checker.duplicates();
        self.stats.backwards = self.checker.backwards();
        self.stats.restarts = self.checker.restarts();
        e
    }
}

/// Writes received samples into an MCAP recording and counts what was lost.
/// Every received sample is written (duplicates too: the file is the log of
/// what was on the wire); the `/recorder` channel carries the counts once
/// per second.
pub struct StreamRecorder {
    writer: McapWriter,
    states: Stream,
    commands: Stream,
    telemetry: Stream,
    /// Setpoints and path messages are numbered per client, together.
    setpoints: BTreeMap<u64, Stream>,
    setpoint_stats: StreamStats,
    path_stats: StreamStats,
    load_stats: StreamStats,
    started: Instant,
    next_report: Instant,
}

impl StreamRecorder {
    /// Creates the recording at `path` with the metadata `info`.
    pub fn create(path: &Path, info: &RunInfo, clock: (u64, u64)) -> anyhow::Result<Self> {
        let writer = McapWriter::create(path, info, clock)?;
        let now = Instant::now();
        Ok(StreamRecorder {
            writer,
            states: Stream::default(),
            commands: Stream::default(),
            telemetry: Stream::default(),
            setpoints: BTreeMap::new(),
            setpoint_stats: StreamStats::default(),
            path_stats: StreamStats::default(),
            load_stats: StreamStats::default(),
            started: now,
            next_report: now + Duration::from_secs(1),
        })
    }

    /// Writes one received sample.
    pub fn record(&mut self, m: &Received) -> anyhow::Result<()> {
        match m {
            Received::State(s) => {
                self.states.observe(s.header.seq);
                self.writer.joint_state(s)?;
                self.states.stats.recorded += 1;
            }
            Received::Command(c) => {
                self.commands.observe(c.header.seq);
                self.writer.torque_command(c)?;
                self.commands.stats.recorded += 1;
            }
            Received::Telemetry(t) => {
                self.telemetry.observe(t.header.seq);
                self.writer.telemetry(t)?;
                self.telemetry.stats.recorded += 1;
            }
            Received::Setpoint(s) => {
                self.client(s.client_id).observe(s.header.seq);
                self.writer.setpoint(s)?;
                self.setpoint_stats.recorded += 1;
            }
            Received::Path(p) => {
                self.client(p.client_id).observe(p.header.seq);
                self.writer.path_knots(p)?;
                self.path_stats.received += 1;
                self.path_stats.recorded += 1;
            }
            Received::Load(l) => {
                self.client(l.client_id).observe(l.header.seq);
                self.writer.load(l)?;
                self.load_stats.received += 1;
                self.load_stats.recorded += 1;
            }
            Received::Failed(_) => {}
        }
        Ok(())
    }

    /// A client's sequence (setpoints and paths); a bounded map: ids beyond
    /// 64 clients share one checker.
    fn client(&mut self, id: u64) -> &mut Stream {
        let key = if self.setpoints.len() < 64 || self.setpoints.contains_key(&id) {
            id
        } else {
            u64::MAX
        };
        self.setpoints.entry(key).or_default()
    }

    /// The counts so far: `setpoint` counts a client's setpoints, path and
    /// load messages as one sequence (its gaps are any's), `path` and `load`
    /// those messages received and recorded.
    pub fn stats(&self) -> RecorderMsg {
        let mut sp = StreamStats {
            recorded: self.setpoint_stats.recorded
                + self.path_stats.recorded
                + self.load_stats.recorded,
            ..StreamStats::default()
        };
        for s in self.setpoints.values() {
            sp.received += s.stats.received;
            sp.gaps += s.stats.gaps;
            sp.gap_events += s.stats.gap_events;
            sp.duplicates += s.stats.duplicates;
            sp.backwards += s.stats.backwards;
            sp.restarts += s.stats.restarts;
        }
        let mut m = RecorderMsg {
            elapsed_s: self.started.elapsed().as_secs_f64(),
            joint_state: self.states.stats,
            torque_command: self.commands.stats,
            telemetry: self.telemetry.stats,
            setpoint: sp,
            path: self.path_stats,
            load: self.load_stats,
            total_gaps: 0,
            last: false,
        };
        m.update_total();
        m
    }

    /// Once per second: the counts into `/recorder`; and the chunk flush
    /// when due (also without new samples). Returns the counts when it
    /// wrote them.
    pub fn tick(&mut self) -> anyhow::Result<Option<RecorderMsg>> {
        let now = Instant::now();
        let mut out = None;
        if now >= self.next_report {
            let m = self.stats();
            self.writer.recorder(&m, hcc_msgs::monotonic_now_ns())?;
            self.next_report += Duration::from_secs(1);
            if self.next_report < now {
                self.next_report = now + Duration::from_secs(1);
            }
            out = Some(m);
        }
        self.writer.flush_if_due()?;
        Ok(out)
    }

    /// Writes the final counts and `end` and closes the file.
    pub fn finish(self, end: BTreeMap<String, String>) -> anyhow::Result<RecorderMsg> {
        let m = self.stats();
        self.writer.finish(&m, end)?;
        Ok(m)
    }
}

/// One line on the counts: received and lost per stream.
pub fn stats_line(m: &RecorderMsg) -> String {
    let s = |x: &StreamStats| {
        let mut t = format!("{}", x.received);
        if x.gaps > 0 {
            t.push_str(&format!(" ({} lost in {} gaps)", x.gaps, x.gap_events));
        }
        if x.duplicates + x.backwards > 0 {
            t.push_str(&format!(
                " ({} out of sequence)",
                x.duplicates + x.backwards
            ));
        }
        if x.restarts > 0 {
            let s = if x.restarts == 1 { "" } else { "s" };
            t.push_str(&format!(" ({} restart{s})", x.restarts));
        }
        t
    };
    format!(
        "joint_state {}, torque_command {}, telemetry {}, setpoint {}; lost {}",
        s(&m.joint_state),
        s(&m.torque_command),
        s(&m.telemetry),
        s(&m.setpoint),
        m.total_gaps
    )
}

/// File name of the recording in a results directory (`hcc run`, `hcc simulate`).
pub const RECORDING_FILE: &str = "run.mcap";

/// The run metadata common to every recorder: versions, the recorder, the
/// namespace, the start time.
pub fn run_metadata(
    recorder: &str,
    namespace: &str,
    clock: (u64, u64),
) -> BTreeMap<String, String> {
    let mut m = BTreeMap::new();
    m.insert("recorder".into(), recorder.into());
    m.insert("hcc_version".into(), env!("CARGO_PKG_VERSION").into());
    m.insert("iceoryx2_version".into(), ICEORYX2_VERSION.into());
    m.insert(
        "msgs_driver_schema_version".into(),
        hcc_msgs::DRIVER_SCHEMA_VERSION.to_string(),
    );
    m.insert(
        "msgs_client_schema_version".into(),
        hcc_msgs::CLIENT_SCHEMA_VERSION.to_string(),
    );
    m.insert("namespace".into(), namespace.into());
    m.insert("start_unix_ns".into(), clock.0.to_string());
    m.insert("start_monotonic_ns".into(), clock.1.to_string());
    m.insert("start_time".into(), rfc3339(clock.0));
    m.insert("host_pid".into(), std::process::id().to_string());
    m
}

/// The iceoryx2 version all peers are built against (the workspace pins it).
pub const ICEORYX2_VERSION: &str = "0.10.0";

/// The machine facts `hcc jitter` reports, as metadata.
pub fn machine_metadata() -> BTreeMap<String, String> {
    let info = hcc_timing::machine::MachineInfo::read();
    crate::mcap_log::json_entries(&serde_json::to_value(info).unwrap_or_default())
}

/// `YYYY-MM-DDTHH:MM:SS.mmmZ` of Unix ns (UTC).
pub fn rfc3339(unix_ns: u64) -> String {
    let secs = (unix_ns / 1_000_000_000) as i64;
    let ms = (unix_ns / 1_000_000) % 1000;
    let days = secs.div_euclid(86_400);
    let rem = secs.rem_euclid(86_400);
    // Civil date from days since 1970-01-01 (Howard Hinnant's algorithm).
    let z = days + 719_468;
    let era = z.div_euclid(146_097);
    let doe = z - era * 146_097;
    let yoe = (doe - doe / 1460 + doe / 36_524 - doe / 146_096) / 365;
    let y = yoe + era * 400;
    let doy = doe - (365 * yoe + yoe / 4 - yoe / 100);
    let mp = (5 * doy + 2) / 153;
    let d = doy - (153 * mp + 2) / 5 + 1;
    let m = if mp < 10 { mp + 3 } else { mp - 9 };
    let y = if m <= 2 { y + 1 } else { y };
    format!(
        "{y:04}-{m:02}-{d:02}T{:02}:{:02}:{:02}.{ms:03}Z",
        rem / 3600,
        (rem % 3600) / 60,
        rem % 60
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn rfc3339_of_known_instants() {
        assert_eq!(rfc3339(0), "1970-01-01T00:00:00.000Z");
        // 2000-02-29T12:34:56.789Z
        assert_eq!(rfc3339(951_827_696_789_000_000), "2000-02-29T12:34:56.789Z");
    }

    /// The version a recording names is the one the workspace builds against
    /// (Cargo.lock) and the Python package pins.
    #[test]
    fn the_recorded_iceoryx2_version_follows_the_pins() {
        let root = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../..");
        let lock = std::fs::read_to_string(root.join("Cargo.lock")).unwrap();
        let locked: Vec<&str> = lock
            .split("[[package]]")
            .filter(|p| p.contains("\nname = \"iceoryx2\"\n"))
            .filter_map(|p| p.lines().find_map(|l| l.strip_prefix("version = ")))
            .map(|v| v.trim_matches('"'))
            .collect();
        assert_eq!(locked, [ICEORYX2_VERSION], "Cargo.lock's iceoryx2");
        let python = std::fs::read_to_string(root.join("python/requirements.txt")).unwrap();
        assert!(
            python
                .lines()
                .any(|l| l.trim() == format!("iceoryx2=={ICEORYX2_VERSION}")),
            "python/requirements.txt pins another iceoryx2"
        );
    }
}
