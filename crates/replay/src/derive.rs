//! The results of a recorded run, derived from its MCAP file: the rows of
//! `trajectory.csv` in exactly the column layout of `hcc simulate` (see
//! `hcc_in_process`), the metrics and the IPC figures. `hcc run` derives its
//! outputs from its `run.mcap` with this code after the run, `hcc plot
//! FILE.mcap` and `hcc export` do the same with any recording.
//!
//! # Where each column comes from
//!
//! A row joins the controller's `/telemetry` of one cycle with the
//! `/joint_state` it consumed (`telemetry.state_seq`), exactly as `hcc
//! simulate` builds its rows from the in-process cycle:
//! - `t` = k · T for the state of sequence number k (T = 1 / control rate:
//!   the drivers number their states k = 0, 1, … per control period); after
//!   a driver restart (its states numbered from the start again) t goes on
//!   from the last state's by the time between their stamps, in periods,
//! - `q`, `qd` from the state; `tau` (τ as commanded), `e<i>_<k>`, `S<i>`
//!   (eqs. 26, 28), `P_mu`, `tau_L<i>_<k>` (eqs. 20, 21) and `tau_mu_<k>`
//!   (eq. 22) from the telemetry,
//! - the derived columns are computed here, never on the real-time path, by
//!   the recorder `hcc simulate` uses (hcc-record): `acc<i>_<j>` = ‖J_i M⁻¹
//!   τ_j‖, `accv<i>_<j>` = ‖J̄_i M⁻¹ τ_j‖ and the split of S_i into
//!   `S<i>_kin` / `S<i>_pot`, with J_i, J̄ (eq. 4) and V_i (eq. 28) of the
//!   control cycle replayed on the recorded states and setpoints
//!   ([`crate::replay`]), and `E_kin`, `E_pot` from the plant model. The
//!   replayed τ is compared with the recorded one as a consistency check
//!   (reported); where a cycle could not be replayed (its state lost before
//!   the file), the columns that need the law are NaN.
//!
//! Every stream goes through a [`SequenceChecker`] here as it did in the
//! recorder, so samples lost before the file are counted and reported.

use anyhow::{Context, anyhow, bail};
use hcc_config::Scenario;
use hcc_cycle::Answer;
use hcc_in_process::describe;
use hcc_msgs::{CommandMode, JointState, SeqEvent, SequenceChecker, Telemetry, TorqueCommand};
use hcc_record::mcap_log::{self, Entry, META_RUN, META_SCENARIO, ReadSummary};
use hcc_record::{Cycle, LawTerms, Recorder, RowSink, WithWrench};
use hcc_report::{RunDescription, RunWriter};
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use crate::replay::{Replay, Replayed};

/// Builds the rows of `hcc simulate`'s layout from the replayed cycles: the
/// recorded state and telemetry, and the law's terms of the replay.
pub struct RowBuilder<'a> {
    scenario: &'a Scenario,
    n: usize,
    dims: Vec<usize>,
    period: f64,
    recorder: Recorder,
    /// Rows built so far.
    pub rows: usize,
    /// Rows whose state the replayed law did not run on (law columns NaN).
    pub rows_without_law: u64,
    /// The largest |τ replayed − τ recorded| over the rows.
    pub replay_tau_diff: f64,
    /// The last row's state (seq, stamp), and the periods added to the seq
    /// of the states since the last driver restart (t = (k + offset) · T).
    last_state: Option<(u64, u64)>,
    seq_offset: u64,
}

impl<'a> RowBuilder<'a> {
    fn new(scenario: &'a Scenario) -> anyhow::Result<RowBuilder<'a>> {
        Ok(RowBuilder {
            scenario,
            n: scenario.model.nq(),
            dims: scenario.task_dims(),
            period: scenario.period_s(),
            rows: 0,
            rows_without_law: 0,
            recorder: hcc_in_process::recorder(scenario)?,
            replay_tau_diff: 0.0,
            last_state: None,
            seq_offset: 0,
        })
    }

    /// The state's time in control periods: its seq, plus the offset that
    /// makes a restarted driver's states (numbered from the start again) go
    /// on from the last one's by the time between their stamps (at least a
    /// period).
    fn periods(&mut self, state: &JointState) -> u64 {
        let (seq, stamp) = (state.header.seq, state.header.stamp_ns);
        if let Some((last_seq, last_stamp)) = self.last_state
            && seq < last_seq
        {
            let gap = stamp.saturating_sub(last_stamp) as f64 * 1e-9 / self.period;
            let gap = (gap.round() as u64).max(1);
            self.seq_offset = last_seq + self.seq_offset + gap - seq;
        }
        self.last_state = Some((seq, stamp));
        seq + self.seq_offset
    }

    /// Checks that the controller runs the hierarchy of the scenario.
    fn check_shape(&self, tel: &Telemetry) -> anyhow::Result<()> {
        tel.validate(self.n)
            .map_err(|e| anyhow!("telemetry of hcc-controller: {e}"))?;
        let dims: Vec<usize> = (0..tel.levels())
            .map(|i| tel.task_dims[i] as usize)
            .collect();
        if dims != self.dims {
            bail!(
                "the controller runs levels of dimensions {dims:?}, but {} has {:?}",
                self.scenario.path.display(),
                self.dims
            );
        }
        Ok(())
    }

    /// The row of a replayed cycle into `sink`; its telemetry, when it has
    /// a row, becomes the last one (`last`). Always goes on.
    fn take(
        &mut self,
        r: &Replayed<'_>,
        last: &mut Option<Box<Telemetry>>,
        sink: &mut dyn RowSink,
    ) -> anyhow::Result<bool> {
        self.push(r, sink)?;
        if r.state.is_some() {
            *last = Some(Box::new(*r.telemetry));
        }
        Ok(true)
    }

    /// Pushes the row of one replayed cycle into `sink` (nothing for a cycle
    /// whose state the recording does not hold).
    fn push(&mut self, r: &Replayed<'_>, sink: &mut dyn RowSink) -> anyhow::Result<()> {
        let Some(state) = r.state else {
            return Ok(());
        };
        let tel = r.telemetry;
        self.check_shape(tel)?;
        if state.n() != self.n {
            bail!(
                "joint state {} has {} joints, the scenario {}",
                state.header.seq,
                state.n(),
                self.n
            );
        }
        let law_ran = matches!(r.answer, Some(Answer::Command(m)) if m != CommandMode::SafeHold);
        if law_ran {
            let d = r
                .cycle
                .command()
                .tau()
                .iter()
                .zip(tel.tau())
                .fold(0.0_f64, |m, (a, b)| m.max((a - b).abs()));
            self.replay_tau_diff = self.replay_tau_diff.max(d);
        } else {
            self.rows_without_law += 1;
        }
        // F̂ is the replayed cycle's (the telemetry does not carry it).
        let output = WithWrench {
            output: tel,
            wrench: r.cycle.external_wrench(),
        };
        let cycle = Cycle {
            // The drivers number their states k = 0, 1, … (t_k = k T).
            t: self.periods(state) as f64 * self.period,
            q: state.q(),
            qd: state.qd(),
            output: &output,
            law: law_ran.then_some(r.cycle.controller() as &dyn LawTerms),
        };
        self.recorder.record(&cycle, sink)?;
        self.rows += 1;
        Ok(())
    }
}

/// Sequence bookkeeping of one stream.
#[derive(Default)]
struct Stream {
    checker: SequenceChecker,
    received: u64,
}

impl Stream {
    /// Checks `seq`; one below the last starts the stream again (a
    /// restarted publisher: one publisher's samples arrive in order).
    fn observe(&mut self, seq: u64) -> SeqEvent {
        self.received += 1;
        self.checker.observe_restarting(seq)
    }
}

/// What the recording says about the run, stream by stream.
pub struct Recording {
    states: Stream,
    commands: Stream,
    telemetry: Stream,
    setpoints: u64,
    paths: u64,
    loads: u64,
    pub last_state: Option<JointState>,
    pub last_telemetry: Option<Box<Telemetry>>,
    latencies_ns: Vec<u64>,
    /// Commands per mode (Normal, SafeHold, Singular, Stop, unknown).
    modes: [u64; 5],
}

impl Recording {
    fn new() -> Recording {
        Recording {
            states: Stream::default(),
            commands: Stream::default(),
            telemetry: Stream::default(),
            setpoints: 0,
            paths: 0,
            loads: 0,
            last_state: None,
            last_telemetry: None,
            latencies_ns: Vec::new(),
            modes: [0; 5],
        }
    }

    /// Samples lost on the three streams.
    pub fn gaps(&self) -> u64 {
        self.states.checker.missed()
            + self.commands.checker.missed()
            + self.telemetry.checker.missed()
    }

    /// Whether the state continues its stream or starts it again (a
    /// restarted driver, numbering from below the last seq); a duplicate is
    /// not replayed.
    fn on_state(&mut self, s: &JointState) -> bool {
        if !self.states.observe(s.header.seq).is_accepted() {
            return false;
        }
        self.last_state = Some(*s);
        true
    }

    fn on_command(&mut self, c: &TorqueCommand) {
        if !self.commands.observe(c.header.seq).is_accepted() {
            return;
        }
        self.latencies_ns
            .push(c.header.stamp_ns.saturating_sub(c.state_stamp_ns));
        let k = match c.mode() {
            Ok(CommandMode::Normal) => 0,
            Ok(CommandMode::SafeHold) => 1,
            Ok(CommandMode::Singular) => 2,
            Ok(CommandMode::Stop) => 3,
            Err(_) => 4,
        };
        self.modes[k] += 1;
    }

    /// Whether the sample continues its stream or starts it again (a
    /// restarted controller); a duplicate is not replayed.
    fn on_telemetry(&mut self, t: &Telemetry) -> bool {
        self.telemetry.observe(t.header.seq).is_accepted()
    }
}

/// Nearest-rank percentile of sorted values.
pub fn percentile(sorted: &[u64], p: f64) -> Option<u64> {
    if sorted.is_empty() {
        return None;
    }
    let rank = ((p / 100.0) * sorted.len() as f64).ceil() as usize;
    Some(sorted[rank.clamp(1, sorted.len()) - 1])
}

/// A recorded run, derived.
pub struct Derived<'a> {
    pub rows: RowBuilder<'a>,
    pub rec: Recording,
    /// What the replay of the recording counted.
    pub replayed: crate::replay::ReplayCounts,
    pub description: RunDescription,
    pub read: ReadSummary,
    /// State → command latencies, sorted.
    latencies_ns: Vec<u64>,
    expected_rows: Option<u64>,
    mode: String,
}

/// The scenario of a recording: `config` if given, else the one it names
/// (its recorded path), warning when the URDF differs from the recorded one.
pub fn scenario_of(path: &Path, config: Option<&Path>) -> anyhow::Result<Scenario> {
    let meta = mcap_log::read_metadata(path)?;
    let recorded = meta.get(META_SCENARIO);
    let field = |k: &str| recorded.and_then(|m| m.get(k)).filter(|v| !v.is_empty());
    let from_recording = config.is_none() && field("toml").is_some();
    let config: PathBuf = match (config, field("path")) {
        (Some(c), _) => c.to_path_buf(),
        (None, Some(p)) => PathBuf::from(p),
        (None, None) => bail!(
            "{} names no scenario (recorded without --config, from a controller without the scenario service?): give it with --config",
            path.display()
        ),
    };
    let what = || format!("the scenario of {}", path.display());
    let mut scenario = if from_recording {
        // The texts the recording carries: the scenario as it ran, whatever
        // the files say now (the URDF from the file when not recorded).
        let toml = field("toml").map(String::as_str).unwrap_or_default();
        let paths = field("paths")
            .and_then(|p| serde_json::from_str(p).ok())
            .unwrap_or_default();
        Scenario::from_texts(toml, &config, field("urdf").map(String::as_str), &paths)
            .with_context(what)?
    } else {
        Scenario::load(&config).with_context(what)?
    };
    if field("urdf").is_none()
        && let Some(hash) = recorded.and_then(|m| m.get("urdf_sha256"))
        && let Ok(urdf) = std::fs::read(&scenario.urdf_path)
        && &mcap_log::sha256_hex(&urdf) != hash
    {
        tracing::warn!(
            "{} differs from the URDF of the recording (SHA-256 {hash}); the derived columns use the file as it is now",
            scenario.urdf_path.display()
        );
    }
    if let Some(d) = meta
        .get(META_RUN)
        .and_then(|m| m.get("duration_s"))
        .and_then(|d| d.parse::<f64>().ok())
    {
        scenario
            .set_duration(d)
            .with_context(|| format!("the recorded duration {d} s"))?;
    }
    Ok(scenario)
}

/// The writer of the results of `scenario`'s recordings into `out` (the
/// columns of [`derive()`]'s rows; with the plots unless `no_plots`): give it to
/// [`derive()`], then finish it with the derived description.
pub fn results_writer(
    scenario: &Scenario,
    out: &Path,
    no_plots: bool,
) -> anyhow::Result<RunWriter> {
    Ok(RunWriter::new(
        out,
        hcc_in_process::column_names(scenario, true),
        &describe(scenario),
        !no_plots,
    )?)
}

/// Reads the recording at `path` and derives its rows for `scenario` (from
/// [`scenario_of`]), pushing each into `sink` as it is derived (memory does
/// not grow with the recording), and the run's figures.
pub fn derive<'a>(
    path: &Path,
    scenario: &'a Scenario,
    sink: &mut dyn RowSink,
) -> anyhow::Result<Derived<'a>> {
    let mut rows = RowBuilder::new(scenario)?;
    let mut rec = Recording::new();
    let mut replay = Replay::new(scenario)?;
    let mut metadata = BTreeMap::new();
    let bad = |e: String| anyhow!("{}: {e}", path.display());
    let read = mcap_log::read::<anyhow::Error>(path, |_, entry| {
        match entry {
            Entry::JointState(s) => {
                let s = s.to_msg().map_err(bad)?;
                if rec.on_state(&s) {
                    replay.on_state(s);
                }
            }
            Entry::TorqueCommand(c) => {
                let c = c.to_msg().map_err(bad)?;
                rec.on_command(&c);
                replay.on_command(c);
            }
            Entry::Telemetry(t) => {
                let t = t.to_msg().map_err(bad)?;
                if rec.on_telemetry(&t) {
                    replay.on_telemetry(t);
                }
            }
            Entry::Path(p) => {
                rec.paths += 1;
                replay.on_path(p.to_msg().map_err(bad)?);
            }
            Entry::Load(l) => {
                rec.loads += 1;
                replay.on_load(l.to_msg().map_err(bad)?);
            }
            Entry::Setpoint(s) => {
                rec.setpoints += 1;
                replay.on_setpoint(s.to_msg().map_err(bad)?);
            }
            Entry::Recorder(_) => {}
            Entry::Metadata(name, map) => {
                metadata.insert(name, map);
            }
        }
        let last = &mut rec.last_telemetry;
        replay
            .advance(false, &mut |r| rows.take(r, last, sink))
            .map(|_| ())
    })?;
    let last = &mut rec.last_telemetry;
    replay.advance(true, &mut |r| rows.take(r, last, sink))?;
    let replayed = replay.counts();
    if let Some(reason) = &read.truncated {
        tracing::warn!(
            "{} is truncated ({reason}): read up to its last complete chunk",
            path.display()
        );
    }
    let run_meta = metadata.get(META_RUN).cloned().unwrap_or_default();
    let mut latencies_ns = std::mem::take(&mut rec.latencies_ns);
    latencies_ns.sort_unstable();
    let s = &scenario.simulation;
    let expected_rows = run_meta
        .contains_key("duration_s")
        .then(|| (s.duration_s * scenario.rate_hz).round() as u64 + 1);
    let mode = run_meta
        .get("mode")
        .cloned()
        .unwrap_or_else(|| "unknown".into());
    let mut d = Derived {
        rows,
        rec,
        replayed,
        description: describe(scenario),
        read,
        latencies_ns,
        expected_rows,
        mode,
    };
    if run_meta.get("recorder").map(String::as_str) != Some("hcc simulate") {
        let ipc = d.ipc_json(&run_meta);
        d.description.settings.insert("ipc".into(), ipc);
    }
    Ok(d)
}

impl Derived<'_> {
    /// Latency percentile `p` in µs.
    fn us(&self, p: f64) -> Option<f64> {
        percentile(&self.latencies_ns, p).map(|v| v as f64 * 1e-3)
    }

    /// The `ipc` entry of the run's settings.
    fn ipc_json(&self, run_meta: &BTreeMap<String, String>) -> serde_json::Value {
        let rec = &self.rec;
        let last_state = rec.last_state;
        let last_tel = rec.last_telemetry.as_deref();
        let runner = match run_meta.get("recorder").map(String::as_str) {
            Some("hcc run") => "hcc run (hcc-sim and hcc-controller over iceoryx2)".to_string(),
            Some(other) => format!("{other} (over iceoryx2)"),
            None => "unknown".into(),
        };
        serde_json::json!({
            "runner": runner,
            "mode": self.mode,
            "namespace": run_meta.get("namespace"),
            "expected_rows": self.expected_rows,
            "rows": self.rows.rows,
            "states_received": rec.states.received,
            "commands_received": rec.commands.received,
            "telemetry_received": rec.telemetry.received,
            "recorder_gaps": {
                "joint_state": rec.states.checker.missed(),
                "torque_command": rec.commands.checker.missed(),
                "telemetry": rec.telemetry.checker.missed(),
            },
            "telemetry_without_state": self.replayed.states_missing,
            "telemetry_before_the_recording": self.replayed.cycles_before_recording,
            "driver_restarts": self.replayed.driver_restarts,
            "controller_restarts": self.replayed.controller_restarts,
            "setpoints_dropped_at_controller_restarts": self.replayed.setpoints_dropped_at_restart,
            "stale_telemetry": self.replayed.stale,
            "states_not_answered_by_the_controller": self.replayed.states_skipped,
            "states_before_the_first_cycle": self.replayed.states_before_first_cycle,
            "states_dropped_unconsumed": self.replayed.states_dropped,
            "driver_missed_commands": last_state.map(|s| s.missed_commands),
            "driver_fallback_cycles": last_state.map(|s| s.fallback_cycles),
            "controller_missed_states": last_tel.map(|t| t.counters.missed_states),
            "controller_stale_events": last_tel.map(|t| t.counters.stale_events),
            "controller_invalid_states": last_tel.map(|t| t.counters.invalid_states),
            "controller_saturations": last_tel.map(|t| t.counters.saturations),
            "controller_max_compute_us": last_tel.map(|t| t.timings.max_compute_ns as f64 * 1e-3),
            "commands_by_mode": {
                "normal": rec.modes[0], "safe_hold": rec.modes[1], "singular": rec.modes[2],
                "stop": rec.modes[3], "unknown": rec.modes[4],
            },
            "state_to_command_latency_us": {
                "p50": self.us(50.0), "p99": self.us(99.0), "max": self.us(100.0),
                "samples": self.latencies_ns.len(),
            },
            "replay_max_tau_difference": self.rows.replay_tau_diff,
            "rows_without_the_law": self.rows.rows_without_law,
            "setpoints_missing_from_the_recording": self.replayed.setpoints_missing,
            "setpoints_before_the_first_cycle": self.replayed.setpoints_before_first_cycle,
        })
    }

    /// The lines of the summary after the metrics'.
    pub fn print(&self) {
        let rec = &self.rec;
        let fmt_us = |v: Option<f64>| v.map_or("-".to_string(), |v| format!("{v:.1} µs"));
        let (last_state, last_tel) = (rec.last_state, rec.last_telemetry.as_deref());
        println!(
            "  ipc ({}): {} rows of {} expected; driver missed commands {}, fallback cycles {}; controller missed states {}",
            self.mode,
            self.rows.rows,
            self.expected_rows
                .map_or("-".to_string(), |e| e.to_string()),
            last_state.map_or(0, |s| s.missed_commands),
            last_state.map_or(0, |s| s.fallback_cycles),
            last_tel.map_or(0, |t| t.counters.missed_states),
        );
        println!(
            "  state -> command latency: p50 {}, p99 {}, max {} ({} commands)",
            fmt_us(self.us(50.0)),
            fmt_us(self.us(99.0)),
            fmt_us(self.us(100.0)),
            self.latencies_ns.len()
        );
        println!(
            "  recorder: gaps {} (states {}, commands {}, telemetry {}), cycles before the recording {}, telemetry without state {}, states before the first cycle {}, states not answered {}, driver restarts {}",
            rec.gaps(),
            rec.states.checker.missed(),
            rec.commands.checker.missed(),
            rec.telemetry.checker.missed(),
            self.replayed.cycles_before_recording,
            self.replayed.states_missing,
            self.replayed.states_before_first_cycle,
            self.replayed.states_skipped,
            self.replayed.driver_restarts
        );
        if rec.setpoints > 0 {
            println!("  setpoints recorded: {}", rec.setpoints);
        }
        if rec.paths > 0 {
            println!("  path messages recorded: {}", rec.paths);
        }
        if rec.loads > 0 {
            println!("  load messages recorded: {}", rec.loads);
        }
        if self.replayed.controller_restarts > 0 {
            println!(
                "  note: the controller restarted {} time(s) (its commands and telemetry numbered again); a fresh control cycle of the scenario replays each new one",
                self.replayed.controller_restarts
            );
        }
        if self.rows.rows_without_law > 0 {
            println!(
                "  note: the law did not run on {} recorded states (the safe command): acc, accv and S_kin/S_pot are NaN there",
                self.rows.rows_without_law
            );
        }
        if self.rows.replay_tau_diff > 0.0 {
            println!(
                "  warning: the replayed control cycle differs from the recorded torques by up to {:e} N·m (another build or scenario?)",
                self.rows.replay_tau_diff
            );
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn percentiles_by_nearest_rank() {
        let v: Vec<u64> = (1..=100).collect();
        assert_eq!(percentile(&v, 50.0), Some(50));
        assert_eq!(percentile(&v, 99.0), Some(99));
        assert_eq!(percentile(&v, 100.0), Some(100));
        assert_eq!(percentile(&[7], 50.0), Some(7));
        assert_eq!(percentile(&[], 50.0), None);
    }
}
