//! The results of a recorded run, derived from its MCAP file: the rows of
//! `trajectory.csv` in exactly the column layout of `hcc simulate` (see
//! `hcc_plant::closed_loop`), the metrics and the IPC figures. `hcc run`
//! derives its outputs from its `run.mcap` with this code after the run,
//! `hcc plot FILE.mcap` and `hcc export` do the same with any recording.
//!
//! # Where each column comes from
//!
//! A row joins the controller's `/telemetry` of one cycle with the
//! `/joint_state` it consumed (`telemetry.state_seq`):
//! - `t` = k · T for the state of sequence number k (T = 1 / control rate:
//!   the simulator numbers its states k = 0, 1, … per control period),
//! - `q`, `qd` from the state; `tau` (τ of eq. 19, gravity included when
//!   configured), `e<i>_<k>`, `S<i>` (eqs. 26, 28), `P_mu`, `tau_L<i>_<k>`
//!   (eqs. 20, 21) and `tau_mu_<k>` (eq. 22) from the telemetry,
//! - the derived columns are computed here, never on the real-time path, by
//!   the recorder `hcc simulate` uses (hcc-record), from the recorded state
//!   and the telemetry's torques: `acc<i>_<j>` = ‖J_i M⁻¹ τ_j‖, `accv<i>_<j>`
//!   = ‖J̄_i M⁻¹ τ_j‖ and the split of S_i into `S<i>_kin` / `S<i>_pot`, with
//!   J_i, J̄ (eq. 4) and V_i (eq. 28) of a shadow copy of the controller
//!   (hcc-control) fed with the same states, and `E_kin`, `E_pot` from the
//!   plant model. The shadow's τ is compared with the telemetry's τ as a
//!   consistency check (reported, not used); where the shadow fails, the
//!   columns that need it are NaN.
//!
//! Every stream goes through a [`SequenceChecker`] here as it did in the
//! recorder, so samples lost before the file are counted and reported.

use anyhow::{Context, anyhow, bail};
use hcc_config::Scenario;
use hcc_msgs::{CommandMode, JointState, SeqEvent, SequenceChecker, Telemetry, TorqueCommand};
use hcc_plant::closed_loop::{self, ControlLaw, HierarchicalLaw, Sampled, describe};
use hcc_record::mcap_log::{self, Entry, META_RUN, META_SCENARIO, ReadSummary};
use hcc_record::{Cycle, CycleOutput, LawTerms, Recorder, RowSink};
use hcc_report::{RunDescription, RunWriter};
use nalgebra::DVector;
use std::collections::{BTreeMap, VecDeque};
use std::path::{Path, PathBuf};

/// The part of a joint state the rows need.
#[derive(Clone, Debug)]
struct StateRecord {
    seq: u64,
    q: Vec<f64>,
    qd: Vec<f64>,
}

/// The controller's telemetry of one cycle, as the recorder reads it.
struct TelemetryCycle<'a> {
    tel: &'a Telemetry,
    n: usize,
}

impl CycleOutput for TelemetryCycle<'_> {
    fn tau(&self) -> &[f64] {
        self.tel.tau()
    }
    fn level_torque(&self, i: usize) -> &[f64] {
        self.tel.tau_level(i)
    }
    fn tau_mu(&self) -> &[f64] {
        &self.tel.tau_mu[..self.n]
    }
    fn task_error(&self, i: usize) -> &[f64] {
        self.tel.task_error(i)
    }
    fn level_energy(&self, i: usize) -> f64 {
        self.tel.storage[i]
    }
    fn p_mu(&self) -> f64 {
        self.tel.p_mu
    }
}

/// Builds the rows of `hcc simulate`'s layout from states and telemetry: the
/// telemetry gives the law's output, a shadow controller fed with the same
/// states the terms of the derived columns (J_i, J̄, V_i).
pub struct RowBuilder<'a> {
    scenario: &'a Scenario,
    n: usize,
    dims: Vec<usize>,
    period: f64,
    recorder: Recorder,
    /// Rows built so far.
    pub rows: usize,
    shadow: HierarchicalLaw,
    pub shadow_failures: u64,
    pub shadow_tau_diff: f64,
    q: DVector<f64>,
    qd: DVector<f64>,
}

impl<'a> RowBuilder<'a> {
    fn new(scenario: &'a Scenario) -> anyhow::Result<RowBuilder<'a>> {
        let n = scenario.model.nq();
        Ok(RowBuilder {
            scenario,
            n,
            dims: scenario.task_dims(),
            period: 1.0 / scenario.simulation.control_rate_hz,
            rows: 0,
            recorder: closed_loop::recorder(scenario, true)?,
            shadow: crate::simulate_cmd::scheduled_law(scenario)?,
            shadow_failures: 0,
            shadow_tau_diff: 0.0,
            q: DVector::zeros(n),
            qd: DVector::zeros(n),
        })
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

    /// Runs the shadow controller on the state (a check of the telemetry's
    /// τ); whether it succeeded.
    fn step_shadow(&mut self, state: &StateRecord, tel: &Telemetry) -> bool {
        self.q.as_mut_slice().copy_from_slice(&state.q);
        self.qd.as_mut_slice().copy_from_slice(&state.qd);
        // The schedule's cycle k is the state's sequence number.
        self.shadow.set_next_cycle(state.seq);
        if self.shadow.compute(&self.q, &self.qd).is_err() {
            self.shadow_failures += 1;
            return false;
        }
        let d = self
            .shadow
            .tau()
            .iter()
            .zip(tel.tau())
            .fold(0.0_f64, |m, (a, b)| m.max((a - b).abs()));
        self.shadow_tau_diff = self.shadow_tau_diff.max(d);
        true
    }

    /// Pushes the row of one controller cycle into `sink`: `tel` answered `state`.
    fn push(
        &mut self,
        state: &StateRecord,
        tel: &Telemetry,
        sink: &mut dyn RowSink,
    ) -> anyhow::Result<()> {
        self.check_shape(tel)?;
        if state.q.len() != self.n || state.qd.len() != self.n {
            bail!(
                "joint state {} has {} joints, the scenario {}",
                state.seq,
                state.q.len(),
                self.n
            );
        }
        let shadow_ok = self.step_shadow(state, tel);
        let output = TelemetryCycle { tel, n: self.n };
        let shadow = Sampled(&self.shadow);
        let cycle = Cycle {
            // hcc-sim numbers its states k = 0, 1, … (t_k = k T), as run_zoh does.
            t: state.seq as f64 * self.period,
            q: &state.q,
            qd: &state.qd,
            output: &output,
            law: shadow_ok.then_some(&shadow as &dyn LawTerms),
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
    fn observe(&mut self, seq: u64) -> SeqEvent {
        self.received += 1;
        self.checker.observe(seq)
    }
}

/// What the recording says about the run, stream by stream.
pub struct Recording {
    states: Stream,
    commands: Stream,
    telemetry: Stream,
    setpoints: u64,
    /// Received states not yet joined with telemetry (seq ascending).
    pending_states: VecDeque<StateRecord>,
    /// Received telemetry not yet joined (its state may still be in flight).
    pending_telemetry: VecDeque<Box<Telemetry>>,
    last_state_seq: Option<u64>,
    pub last_state: Option<JointState>,
    pub last_telemetry: Option<Box<Telemetry>>,
    /// Controller cycles whose state the recording does not have.
    unmatched_telemetry: u64,
    /// Telemetry of cycles without a new state (stale events of the controller).
    stale_telemetry: u64,
    /// State seq of the last row.
    last_joined_seq: Option<u64>,
    /// States the controller did not answer (it skips to the newest state when late).
    unanswered_states: u64,
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
            pending_states: VecDeque::new(),
            pending_telemetry: VecDeque::new(),
            last_state_seq: None,
            last_state: None,
            last_telemetry: None,
            unmatched_telemetry: 0,
            stale_telemetry: 0,
            last_joined_seq: None,
            unanswered_states: 0,
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

    fn on_state(&mut self, s: &JointState) {
        if !self.states.observe(s.header.seq).is_accepted() {
            return;
        }
        self.last_state_seq = Some(s.header.seq);
        self.pending_states.push_back(StateRecord {
            seq: s.header.seq,
            q: s.q().to_vec(),
            qd: s.qd().to_vec(),
        });
        self.last_state = Some(*s);
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

    fn on_telemetry(&mut self, t: Box<Telemetry>) {
        if !self.telemetry.observe(t.header.seq).is_accepted() {
            return;
        }
        self.pending_telemetry.push_back(t);
    }

    /// Joins pending telemetry with its states and pushes the rows into
    /// `sink`. With `flush`, telemetry whose state never arrived is given up.
    fn join(
        &mut self,
        rows: &mut RowBuilder,
        sink: &mut dyn RowSink,
        flush: bool,
    ) -> anyhow::Result<()> {
        while let Some(tel) = self.pending_telemetry.front() {
            let want = tel.state_seq;
            if self.last_joined_seq.is_some_and(|last| want <= last) {
                // Telemetry of a cycle without a new state (the controller's
                // stale-state event): no row.
                self.pending_telemetry.pop_front();
                self.stale_telemetry += 1;
                continue;
            }
            if !flush && self.last_state_seq.is_none_or(|last| want > last) {
                break; // its state comes later in the file
            }
            while let Some(s) = self.pending_states.front() {
                if s.seq < want {
                    self.pending_states.pop_front();
                    self.unanswered_states += 1;
                } else {
                    break;
                }
            }
            let Some(tel) = self.pending_telemetry.pop_front() else {
                break;
            };
            match self.pending_states.front() {
                Some(s) if s.seq == want => {
                    if let Some(s) = self.pending_states.pop_front() {
                        rows.push(&s, &tel, sink)?;
                    }
                    self.last_joined_seq = Some(want);
                    self.last_telemetry = Some(tel);
                }
                _ => self.unmatched_telemetry += 1,
            }
        }
        if flush {
            self.unanswered_states += self.pending_states.len() as u64;
            self.pending_states.clear();
        }
        Ok(())
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
    let config: PathBuf = match (config, recorded.and_then(|m| m.get("path"))) {
        (Some(c), _) => c.to_path_buf(),
        (None, Some(p)) => PathBuf::from(p),
        (None, None) => bail!(
            "{} names no scenario (recorded without --config?): give it with --config",
            path.display()
        ),
    };
    let mut scenario =
        Scenario::load(&config).with_context(|| format!("the scenario of {}", path.display()))?;
    if let Some(hash) = recorded.and_then(|m| m.get("urdf_sha256"))
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
        closed_loop::column_names(scenario, true),
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
    let mut metadata = BTreeMap::new();
    let bad = |e: String| anyhow!("{}: {e}", path.display());
    let read = mcap_log::read::<anyhow::Error>(path, |_, entry| {
        match entry {
            Entry::JointState(s) => rec.on_state(&s.to_msg().map_err(bad)?),
            Entry::TorqueCommand(c) => rec.on_command(&c.to_msg().map_err(bad)?),
            Entry::Telemetry(t) => rec.on_telemetry(t.to_msg().map_err(bad)?),
            Entry::Setpoint(_) => rec.setpoints += 1,
            Entry::Recorder(_) => {}
            Entry::Metadata(name, map) => {
                metadata.insert(name, map);
            }
        }
        rec.join(&mut rows, sink, false)
    })?;
    rec.join(&mut rows, sink, true)?;
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
        .then(|| (s.duration_s * s.control_rate_hz).round() as u64 + 1);
    let mode = run_meta
        .get("mode")
        .cloned()
        .unwrap_or_else(|| "unknown".into());
    let mut d = Derived {
        rows,
        rec,
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
            "telemetry_without_state": rec.unmatched_telemetry,
            "stale_telemetry": rec.stale_telemetry,
            "states_not_answered_by_the_controller": rec.unanswered_states,
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
            "shadow_controller_max_tau_difference": self.rows.shadow_tau_diff,
            "shadow_controller_failures": self.rows.shadow_failures,
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
            "  recorder: gaps {} (states {}, commands {}, telemetry {}), telemetry without state {}, states not answered {}",
            rec.gaps(),
            rec.states.checker.missed(),
            rec.commands.checker.missed(),
            rec.telemetry.checker.missed(),
            rec.unmatched_telemetry,
            rec.unanswered_states
        );
        if rec.setpoints > 0 {
            println!("  setpoints recorded: {}", rec.setpoints);
        }
        if self.rows.shadow_failures > 0 {
            println!(
                "  warning: the shadow controller failed on {} states (acc, accv and S_kin/S_pot are NaN there)",
                self.rows.shadow_failures
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
