//! The scheduler of `hcc run`: a scenario's `[[setpoint]]` entries sent to
//! the running controller through the setpoint service, as any client sends
//! them (hcc-client), so that `hcc run` applies the schedule `hcc simulate`
//! applies in-process.
//!
//! Each entry carries its application point: `apply_at_state_seq` = its
//! cycle k (the first t_k = k · T ≥ t, [`ScheduledSetpoint::cycle`]; hcc-sim
//! numbers its states k = 0, 1, …). The controller keeps an entry that
//! arrives ahead of its state in its queue of waiting setpoints and takes it
//! in the cycle of state k, before that cycle's transitions advance and its
//! law steps — where `hcc simulate` hands it to the same control cycle
//! (`hcc_cycle::Schedule`) — so a lockstep run equals `hcc simulate` exactly, and a real-time run applies
//! every entry that arrived ahead at its exact cycle too.
//!
//! The thread sends the first [`WINDOW`] entries before the simulator starts
//! (so entries due at t = 0 are there for the first state), then one more
//! for each one the controller answered, so that never more than [`WINDOW`]
//! of them wait in the controller (its queue holds
//! [`hcc_msgs::MAX_PENDING_SETPOINTS`] for all clients) or in the service's
//! queue. It reads the answers in the telemetry (accepted or rejected,
//! late): a rejected entry is an error of the run, a late one (it arrived
//! after its state, e.g. on a loaded machine; applied on receipt) is counted
//! and reported.

use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::mpsc;
use std::time::{Duration, Instant};

use anyhow::{Context, bail};
use hcc_client::Client;
use hcc_config::Scenario;
use hcc_config::schedule::{SCHEDULE_CLIENT_ID, ScheduledSetpoint};
use hcc_msgs::{ANSWER_ACCEPTED, Setpoint, SetpointRejection};

/// Scheduled setpoints in flight at most (sent, not yet answered).
pub const WINDOW: usize = 8;
/// How long the first send may wait for the controller's subscriber.
const CONNECT_TIMEOUT: Duration = Duration::from_secs(10);
/// Poll interval of the thread.
const POLL: Duration = Duration::from_micros(200);

/// What the scheduler did, for the summary and metrics.json.
#[derive(Debug, Clone, Default)]
pub struct ScheduleReport {
    /// Entries of the scenario.
    pub entries: usize,
    /// Entries due within the run (cycle ≤ the last one); only these are sent.
    pub due: usize,
    /// Entries sent.
    pub sent: usize,
    /// Entries the controller answered.
    pub answered: u64,
    /// Entries the controller rejected.
    pub rejected: u64,
    /// Entries applied late (after their state).
    pub late: u64,
    /// The last rejection seen: (index of the entry, code).
    pub last_rejection: Option<(usize, u32)>,
    /// Why the thread failed, if it did.
    pub error: Option<String>,
}

impl ScheduleReport {
    /// The `scheduled_setpoints` entry of metrics.json.
    pub fn json(&self, schedule: &[ScheduledSetpoint]) -> serde_json::Value {
        serde_json::json!({
            "entries": self.entries,
            "due_within_the_run": self.due,
            "sent": self.sent,
            "answered": self.answered,
            "rejected": self.rejected,
            "late": self.late,
            "last_rejection": self.last_rejection.map(|(k, code)| self.describe(schedule, k, code)),
            "error": self.error,
        })
    }

    /// One entry's rejection in words.
    fn describe(&self, schedule: &[ScheduledSetpoint], k: usize, code: u32) -> String {
        let reason = SetpointRejection::from_code(code)
            .map_or("unknown code".to_string(), |r| r.to_string());
        match schedule.get(k) {
            Some(e) => format!(
                "the scheduled setpoint at t = {} s for level {} was rejected: {reason}",
                e.t_s,
                e.setpoint.level + 1
            ),
            None => format!("a scheduled setpoint was rejected: {reason}"),
        }
    }

    /// The summary line.
    pub fn line(&self) -> String {
        format!(
            "  scheduled setpoints: {} of {} due in the run sent, {} answered, {} rejected, {} late",
            self.sent, self.due, self.answered, self.rejected, self.late
        )
    }

    /// An error when the schedule failed (a rejected entry, a failed thread).
    pub fn check(&self, schedule: &[ScheduledSetpoint]) -> anyhow::Result<()> {
        if let Some(e) = &self.error {
            bail!("scheduler: {e}");
        }
        if self.rejected > 0 {
            let last = self.last_rejection.map_or_else(
                || "the controller's telemetry names the reason".to_string(),
                |(k, code)| self.describe(schedule, k, code),
            );
            bail!(
                "{} scheduled setpoint(s) rejected by hcc-controller; {last}",
                self.rejected
            );
        }
        Ok(())
    }
}

/// The running scheduler thread.
pub struct Scheduler {
    handle: Option<std::thread::JoinHandle<ScheduleReport>>,
    stop: Arc<AtomicBool>,
}

impl Scheduler {
    /// Connects to `namespace`, sends the first [`WINDOW`] entries and
    /// returns once they reached the controller (call it after the
    /// controller listens, before the simulator starts).
    pub fn start(
        namespace: &str,
        file_prefix: Option<String>,
        scenario: &Scenario,
    ) -> anyhow::Result<Scheduler> {
        let entries = scenario.scheduled_messages();
        let total = scenario.setpoints.len();
        let namespace = namespace.to_string();
        let stop = Arc::new(AtomicBool::new(false));
        let stop_flag = stop.clone();
        let (ready_tx, ready_rx) = mpsc::sync_channel::<Result<(), String>>(1);
        let handle = std::thread::Builder::new()
            .name("hcc-run-scheduler".into())
            .spawn(move || {
                let mut report = ScheduleReport {
                    entries: total,
                    due: entries.len(),
                    ..ScheduleReport::default()
                };
                let mut client = match Client::connect(&namespace, file_prefix.as_deref()) {
                    Ok(c) => c,
                    Err(e) => {
                        let _ = ready_tx.send(Err(format!("cannot connect: {e}")));
                        report.error = Some(e.to_string());
                        return report;
                    }
                };
                let first = entries.len().min(WINDOW);
                if let Err(e) = send_first(&mut client, &entries[..first]) {
                    let _ = ready_tx.send(Err(e.clone()));
                    report.error = Some(e);
                    return report;
                }
                report.sent = first;
                let _ = ready_tx.send(Ok(()));
                follow(&mut client, &entries, &mut report, &stop_flag);
                report
            })
            .context("cannot start the scheduler thread")?;
        match ready_rx.recv() {
            Ok(Ok(())) => Ok(Scheduler {
                handle: Some(handle),
                stop,
            }),
            Ok(Err(e)) => {
                let _ = handle.join();
                bail!("scheduler: {e}")
            }
            Err(_) => bail!("the scheduler thread ended during start-up"),
        }
    }

    /// Stops the thread (after a last look at the telemetry) and returns its report.
    pub fn finish(mut self) -> ScheduleReport {
        self.stop.store(true, Ordering::SeqCst);
        self.handle
            .take()
            .and_then(|h| h.join().ok())
            .unwrap_or_else(|| ScheduleReport {
                error: Some("the scheduler thread panicked".into()),
                ..ScheduleReport::default()
            })
    }
}

impl Drop for Scheduler {
    fn drop(&mut self) {
        self.stop.store(true, Ordering::SeqCst);
        if let Some(h) = self.handle.take() {
            let _ = h.join();
        }
    }
}

/// Sends the first entries; waits (up to [`CONNECT_TIMEOUT`]) until the
/// controller's subscriber receives them.
fn send_first(client: &mut Client, first: &[Setpoint]) -> Result<(), String> {
    let Some((head, rest)) = first.split_first() else {
        return Ok(());
    };
    let deadline = Instant::now() + CONNECT_TIMEOUT;
    loop {
        match client.publish(head) {
            Ok(n) if n > 0 => break,
            Ok(_) if Instant::now() < deadline => std::thread::sleep(Duration::from_millis(1)),
            Ok(_) => {
                return Err(format!(
                    "hcc-controller did not subscribe to setpoints within {} s",
                    CONNECT_TIMEOUT.as_secs()
                ));
            }
            Err(e) => return Err(e.to_string()),
        }
    }
    for sp in rest {
        client.publish(sp).map_err(|e| e.to_string())?;
    }
    Ok(())
}

/// Reads the answers and sends the rest, keeping at most [`WINDOW`] in
/// flight, until every entry is answered or a stop is requested.
fn follow(
    client: &mut Client,
    entries: &[Setpoint],
    report: &mut ScheduleReport,
    stop: &AtomicBool,
) {
    loop {
        // Read the flag first: after a stop request one more look follows.
        let last = stop.load(Ordering::SeqCst);
        if let Some(a) = client
            .poll_telemetry()
            .and_then(|t| t.answer_for(SCHEDULE_CLIENT_ID).copied())
        {
            report.answered = a.answered;
            report.late = u64::from(a.late);
            if u64::from(a.rejected) > report.rejected {
                report.rejected = u64::from(a.rejected);
                // Known when the rejected one is the last answered (sequence
                // numbers are 1 + the entry's index).
                if a.code != ANSWER_ACCEPTED {
                    report.last_rejection = Some((a.seq.saturating_sub(1) as usize, a.code));
                }
            }
        }
        while report.sent < entries.len() && (report.sent as u64) < report.answered + WINDOW as u64
        {
            match client.publish(&entries[report.sent]) {
                Ok(_) => report.sent += 1,
                Err(e) => {
                    report.error = Some(e.to_string());
                    return;
                }
            }
        }
        if last || report.answered >= entries.len() as u64 {
            return;
        }
        std::thread::sleep(POLL);
    }
}
