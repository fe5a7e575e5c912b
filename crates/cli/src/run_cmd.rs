//! `hcc run CONFIG [--out DIR] [--duration S] [--lockstep] [--namespace NS]`:
//! the main job over inter-process communication.
//!
//! The launcher starts the two daemons as child processes — the plant
//! simulator `hcc-sim` and the controller `hcc-controller`, found next to the
//! `hcc` executable — in a namespace of their own (unique unless given), and
//! records the run from the outside: it subscribes to the joint states, the
//! torque commands and the controller's telemetry (the services of the
//! hcc-msgs contract) and writes one row per controller cycle in exactly the
//! column layout of `hcc simulate` (see `hcc_plant::closed_loop`), then
//! `trajectory.csv`, `metrics.json` and the plots through hcc-report.
//!
//! # Where each column comes from
//!
//! A row joins the controller's [`Telemetry`] of one cycle with the
//! [`JointState`] it consumed (`telemetry.state_seq`):
//! - `t` = k · T for the state of sequence number k (T = 1 / control rate:
//!   the simulator numbers its states k = 0, 1, … per control period),
//! - `q`, `qd` from the state; `tau` (τ of eq. 19, gravity included when
//!   configured), `e<i>_<k>`, `S<i>` (eqs. 26, 28), `P_mu`, `tau_L<i>_<k>`
//!   (eqs. 20, 21) and `tau_mu_<k>` (eq. 22) from the telemetry,
//! - the derived columns are computed here, off the real-time path, by the
//!   recorder `hcc simulate` uses (hcc-record), from the recorded state and the
//!   telemetry's torques: `acc<i>_<j>` = ‖J_i M⁻¹ τ_j‖, `accv<i>_<j>` =
//!   ‖J̄_i M⁻¹ τ_j‖ and the split of S_i into `S<i>_kin` / `S<i>_pot`, with J_i,
//!   J̄ (eq. 4) and V_i (eq. 28) of a shadow copy of the controller
//!   (hcc-control) fed with the same states, and `E_kin`, `E_pot` from the
//!   plant model. The shadow's τ is compared with the telemetry's τ as a
//!   consistency check (reported, not used); where the shadow fails, the
//!   columns that need it are NaN.
//!
//! # Scheduled setpoints
//!
//! A scenario's `[[setpoint]]` entries are sent by a scheduler thread of the
//! launcher through the setpoint service, as a client sends them
//! ([`crate::run_schedule`]): each carries its cycle k as its application
//! point, the controller takes it in the cycle of state k, and the shadow
//! controller applies the same schedule at the same cycles (the in-process
//! `hcc_controller::schedule::Schedule` of `hcc simulate`). A lockstep run
//! with a schedule therefore equals `hcc simulate`; in real time every entry
//! that arrives ahead of its state (all of them, normally: they are sent
//! well ahead) is applied at its exact cycle, a late one on receipt
//! (counted). A rejected entry makes the run fail after its results are
//! written.
//!
//! # Not disturbing the real-time loops
//!
//! Publishers of the contract never block (safe overflow): the recorder's
//! subscribers have the largest queue the services allow and are drained
//! before any row is computed, and every stream goes through a
//! [`SequenceChecker`], so lost samples are counted and reported, never lost
//! silently.
//!
//! # Stopping
//!
//! The run ends when the simulator exits after `--duration` (its last state
//! has status Stopped); the controller is then sent SIGTERM. Ctrl-C (SIGINT)
//! or SIGTERM to `hcc run` sends SIGTERM to both children (by pid), waits for
//! them and writes the partial results. If a child fails, the other one is
//! stopped and `hcc run` exits with an error that includes the tail of the
//! failed child's stderr. The children run in their own process group (a
//! Ctrl-C at the terminal reaches only the launcher, which stops them in
//! order) and receive SIGTERM if the launcher dies.

use anyhow::{Context, anyhow, bail};
use hcc_config::Scenario;
use hcc_msgs::ipc::{self, MAX_SUBSCRIBER_BUFFER, Services};
use hcc_msgs::{
    CommandMode, DriverStatus, JointState, Namespace, SeqEvent, SequenceChecker, ServiceNames,
    Telemetry, TorqueCommand,
};
use hcc_plant::closed_loop::{self, ControlLaw, HierarchicalLaw, Sampled, describe};
use hcc_record::{Cycle, CycleOutput, LawTerms, Recorder};
use hcc_report::Trajectory;
use iceoryx2::prelude::SignalHandlingMode;
use nalgebra::DVector;
use std::collections::VecDeque;
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, mpsc};
use std::time::{Duration, Instant};
use tracing::warn;

use crate::daemons::{
    Daemon, TERMINATE_GRACE, daemon_path, describe_status, install_signal_handlers, interrupted,
    wait_until_controller_listens,
};
use crate::run_schedule::Scheduler;
use crate::simulate_cmd::write_results;

/// Default scenario of `hcc run`: the paper's simulation #1.
pub const DEFAULT_CONFIG: &str = "config/paper-sim1.toml";

/// Time to wait for the first joint state after the start of the children.
const STARTUP_TIMEOUT: Duration = Duration::from_secs(20);
/// A running simulator that publishes nothing for this long is considered hung.
const STALL_TIMEOUT: Duration = Duration::from_secs(10);
/// `hcc-sim --lockstep-timeout-ms` of a lockstep run: a command missing
/// this long is a miss (the simulator falls back and the run is no longer
/// deterministic), so it is far above any stall of a loaded machine.
const LOCKSTEP_TIMEOUT_MS: f64 = 5000.0;
/// Time the controller gets to answer the simulator's last state.
const FINAL_ANSWER_GRACE: Duration = Duration::from_millis(500);

#[derive(clap::Args, Debug)]
pub struct RunArgs {
    /// Scenario TOML file.
    #[arg(default_value = DEFAULT_CONFIG)]
    pub config: PathBuf,
    /// Output directory (created if missing; default out/<scenario name>).
    #[arg(long)]
    pub out: Option<PathBuf>,
    /// Simulated duration in s (overrides [simulation] duration_s).
    #[arg(long, allow_negative_numbers = true)]
    pub duration: Option<f64>,
    /// Make the simulator wait for each command (deterministic; reproduces `hcc simulate`).
    #[arg(long)]
    pub lockstep: bool,
    /// IPC namespace of the run (default: a unique one, so runs never share services).
    #[arg(long)]
    pub namespace: Option<String>,
    /// iceoryx2 file prefix shared with the children (default: the HCC_IPC_FILE_PREFIX
    /// environment variable, else iceoryx2's default).
    #[arg(long)]
    pub file_prefix: Option<String>,
    /// Skip the PNG plots (CSV and metrics only).
    #[arg(long)]
    pub no_plots: bool,
    /// No progress lines on stderr.
    #[arg(long)]
    pub quiet: bool,
    /// Run the daemons with normal scheduling. By default a real-time run
    /// asks for the real-time set-up `hcc jitter` measures: SCHED_FIFO
    /// priority 80, locked memory, the hybrid wait in both daemons and, on a
    /// machine with two cores or more, one core per daemon (simulator on
    /// the first, controller on the second) unless the scenario pins them.
    /// A daemon that may not have them says so and runs normally.
    #[arg(long)]
    pub no_rt: bool,
}

/// SCHED_FIFO priority of the daemons of a real-time `hcc run`.
const RUN_PRIORITY: i32 = 80;

/// The real-time arguments of a real-time run's daemons: (simulator,
/// controller). The controller's wait strategy is the scenario's
/// (`[controller_daemon] wait_strategy`, hybrid by default); a priority the
/// scenario sets is kept. When SCHED_FIFO is not permitted, it warns once
/// here and asks for normal scheduling.
fn realtime_args(scenario: &Scenario, quiet: bool) -> (Vec<String>, Vec<String>) {
    let mut sim = vec![
        "--wait".to_string(),
        "hybrid".to_string(),
        "--mlock".to_string(),
    ];
    let mut controller = vec!["--mlock".to_string()];
    match hcc_rt::fifo_permitted(RUN_PRIORITY) {
        Ok(()) => {
            sim.extend(["--sched-priority".to_string(), RUN_PRIORITY.to_string()]);
            if scenario.controller_daemon.sched_priority.is_none() {
                controller.extend(["--sched-priority".to_string(), RUN_PRIORITY.to_string()]);
            }
        }
        Err(e) if !quiet => warn!(
            "SCHED_FIFO {RUN_PRIORITY} is not permitted ({e}): the daemons run with normal \
             scheduling and may miss commands under load (grant CAP_SYS_NICE or an rtprio \
             limit, see the README's timing section; --no-rt silences this)"
        ),
        Err(_) => {}
    }
    let cores = hcc_rt::available_cores();
    if cores.len() >= 2
        && scenario.sim_daemon.cpu_core.is_none()
        && scenario.controller_daemon.cpu_core.is_none()
    {
        sim.extend(["--cpu-core".to_string(), cores[0].to_string()]);
        controller.extend(["--cpu-core".to_string(), cores[1].to_string()]);
    }
    (sim, controller)
}

// ---------------------------------------------------------------------------
// Rows

/// The part of a joint state the recorder keeps.
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
struct RowBuilder<'a> {
    scenario: &'a Scenario,
    n: usize,
    dims: Vec<usize>,
    period: f64,
    recorder: Recorder,
    traj: Trajectory,
    shadow: HierarchicalLaw,
    shadow_failures: u64,
    shadow_tau_diff: f64,
    q: DVector<f64>,
    qd: DVector<f64>,
}

impl<'a> RowBuilder<'a> {
    fn new(scenario: &'a Scenario) -> anyhow::Result<RowBuilder<'a>> {
        let n = scenario.model.nq();
        let s = &scenario.simulation;
        let cycles = (s.duration_s * s.control_rate_hz).round() as usize;
        let recorder = closed_loop::recorder(scenario, true)?;
        Ok(RowBuilder {
            scenario,
            n,
            dims: scenario.task_dims(),
            period: 1.0 / s.control_rate_hz,
            traj: recorder.trajectory(cycles + 1)?,
            recorder,
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
                "hcc-controller runs levels of dimensions {dims:?}, but {} has {:?}",
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

    /// Appends the row of one controller cycle: `tel` answered `state`.
    fn push(&mut self, state: &StateRecord, tel: &Telemetry) -> anyhow::Result<()> {
        self.check_shape(tel)?;
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
        self.recorder.record(&cycle, &mut self.traj)?;
        Ok(())
    }
}

// ---------------------------------------------------------------------------
// Recording

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

/// Everything the recorder learns during a run.
struct Recording {
    states: Stream,
    commands: Stream,
    telemetry: Stream,
    /// Received states not yet joined with telemetry (seq ascending).
    pending_states: VecDeque<StateRecord>,
    /// Received telemetry not yet joined (its state may still be in flight).
    pending_telemetry: VecDeque<Telemetry>,
    last_state_seq: Option<u64>,
    last_state: Option<JointState>,
    last_telemetry: Option<Telemetry>,
    /// Controller cycles whose state the recorder never received.
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
    sim_stopped: bool,
    first_state_at: Option<Instant>,
    last_sample_at: Instant,
}

impl Recording {
    /// Samples lost on the three streams.
    fn gaps(&self) -> u64 {
        self.states.checker.missed()
            + self.commands.checker.missed()
            + self.telemetry.checker.missed()
    }

    fn new() -> Recording {
        Recording {
            states: Stream::default(),
            commands: Stream::default(),
            telemetry: Stream::default(),
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
            sim_stopped: false,
            first_state_at: None,
            last_sample_at: Instant::now(),
        }
    }

    fn on_state(&mut self, s: &JointState) {
        if !self.states.observe(s.header.seq).is_accepted() {
            return;
        }
        self.first_state_at.get_or_insert_with(Instant::now);
        self.last_state_seq = Some(s.header.seq);
        if s.status() == Ok(DriverStatus::Stopped) {
            self.sim_stopped = true;
        }
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

    fn on_telemetry(&mut self, t: &Telemetry) {
        if !self.telemetry.observe(t.header.seq).is_accepted() {
            return;
        }
        self.pending_telemetry.push_back(*t);
    }

    /// Joins pending telemetry with its states and appends the rows. With
    /// `flush`, telemetry whose state never arrived is given up.
    fn join(&mut self, rows: &mut RowBuilder, flush: bool) -> anyhow::Result<()> {
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
                break; // its state is still in flight
            }
            while let Some(s) = self.pending_states.front() {
                if s.seq < want {
                    self.pending_states.pop_front();
                    self.unanswered_states += 1;
                } else {
                    break;
                }
            }
            let tel = self
                .pending_telemetry
                .pop_front()
                .unwrap_or_else(Telemetry::zeroed);
            match self.pending_states.front() {
                Some(s) if s.seq == want => {
                    let s = self.pending_states.pop_front().unwrap_or(StateRecord {
                        seq: want,
                        q: Vec::new(),
                        qd: Vec::new(),
                    });
                    rows.push(&s, &tel)?;
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

/// A sample copied out of shared memory by the receiver thread.
enum Received {
    State(Box<JointState>),
    Command(Box<TorqueCommand>),
    Telemetry(Box<Telemetry>),
    /// The receiver failed and stopped.
    Failed(String),
}

/// The recorder's subscribers, on a thread of their own that does nothing but
/// copy samples out of the queues into a channel, so that the row
/// computations never delay the draining (in lockstep the daemons run much
/// faster than real time).
struct Receiver {
    handle: Option<std::thread::JoinHandle<()>>,
    stop: Arc<AtomicBool>,
    rx: mpsc::Receiver<Received>,
}

/// Reads every queued sample of the three streams into `tx`; returns how many.
fn drain_into(
    states: &ipc::StateSubscriber,
    commands: &ipc::CommandSubscriber,
    telemetry: &ipc::TelemetrySubscriber,
    tx: &mpsc::Sender<Received>,
) -> Result<usize, String> {
    let mut k = 0;
    // States first: a command or telemetry always follows its state.
    while let Some(s) = states
        .receive()
        .map_err(|e| format!("receive joint_state: {e:?}"))?
    {
        let _ = tx.send(Received::State(Box::new(*s)));
        k += 1;
    }
    while let Some(c) = commands
        .receive()
        .map_err(|e| format!("receive torque_command: {e:?}"))?
    {
        let _ = tx.send(Received::Command(Box::new(*c)));
        k += 1;
    }
    while let Some(t) = telemetry
        .receive()
        .map_err(|e| format!("receive telemetry: {e:?}"))?
    {
        let _ = tx.send(Received::Telemetry(Box::new(*t)));
        k += 1;
    }
    Ok(k)
}

impl Receiver {
    /// Subscribes (on the new thread) and returns once the subscribers exist.
    fn start(file_prefix: Option<String>, names: ServiceNames) -> anyhow::Result<Receiver> {
        let (tx, rx) = mpsc::channel();
        let (ready_tx, ready_rx) = mpsc::sync_channel::<Result<(), String>>(1);
        let stop = Arc::new(AtomicBool::new(false));
        let stop_flag = stop.clone();
        let handle = std::thread::Builder::new()
            .name("hcc-run-receiver".into())
            .spawn(move || {
                let setup = || -> anyhow::Result<_> {
                    let node = ipc::create_node(
                        "hcc-run",
                        SignalHandlingMode::Disabled,
                        file_prefix.as_deref(),
                    )?;
                    let services = Services::open(&node, &names)?;
                    let states = services.joint_state_subscriber(MAX_SUBSCRIBER_BUFFER)?;
                    let commands = services.torque_command_subscriber(MAX_SUBSCRIBER_BUFFER)?;
                    let telemetry = services.telemetry_subscriber(MAX_SUBSCRIBER_BUFFER)?;
                    Ok((node, services, states, commands, telemetry))
                };
                let (node, services, states, commands, telemetry) = match setup() {
                    Ok(x) => {
                        let _ = ready_tx.send(Ok(()));
                        x
                    }
                    Err(e) => {
                        let _ = ready_tx.send(Err(format!("{e:#}")));
                        return;
                    }
                };
                loop {
                    // Read the flag before draining: after a stop request
                    // one more complete drain happens.
                    let last = stop_flag.load(Ordering::SeqCst);
                    match drain_into(&states, &commands, &telemetry, &tx) {
                        Ok(0) if last => break,
                        Ok(0) => std::thread::sleep(Duration::from_micros(100)),
                        Ok(_) => {}
                        Err(e) => {
                            let _ = tx.send(Received::Failed(e));
                            break;
                        }
                    }
                }
                drop((states, commands, telemetry));
                drop(services);
                drop(node);
            })
            .context("cannot start the receiver thread")?;
        match ready_rx.recv() {
            Ok(Ok(())) => Ok(Receiver {
                handle: Some(handle),
                stop,
                rx,
            }),
            Ok(Err(e)) => {
                let _ = handle.join();
                bail!(e)
            }
            Err(_) => bail!("the receiver thread ended during start-up"),
        }
    }

    /// Hands the samples received so far to `rec` (waiting up to `wait` for
    /// the first one); returns how many.
    fn pump(&self, rec: &mut Recording, wait: Duration) -> anyhow::Result<usize> {
        let mut k = 0;
        let mut next = self.rx.recv_timeout(wait).ok();
        while let Some(m) = next {
            match m {
                Received::State(s) => rec.on_state(&s),
                Received::Command(c) => rec.on_command(&c),
                Received::Telemetry(t) => rec.on_telemetry(&t),
                Received::Failed(e) => bail!("recorder: {e}"),
            }
            k += 1;
            next = self.rx.try_recv().ok();
        }
        if k > 0 {
            rec.last_sample_at = Instant::now();
        }
        Ok(k)
    }

    /// Stops the thread after a last drain, hands everything to `rec` and
    /// closes the subscribers (and the node).
    fn finish(mut self, rec: &mut Recording) -> anyhow::Result<()> {
        self.stop.store(true, Ordering::SeqCst);
        if let Some(h) = self.handle.take() {
            let _ = h.join();
        }
        while self.pump(rec, Duration::ZERO)? > 0 {}
        Ok(())
    }
}

impl Drop for Receiver {
    fn drop(&mut self) {
        self.stop.store(true, Ordering::SeqCst);
        if let Some(h) = self.handle.take() {
            let _ = h.join();
        }
    }
}

/// Nearest-rank percentile of sorted values.
fn percentile(sorted: &[u64], p: f64) -> Option<u64> {
    if sorted.is_empty() {
        return None;
    }
    let rank = ((p / 100.0) * sorted.len() as f64).ceil() as usize;
    Some(sorted[rank.clamp(1, sorted.len()) - 1])
}

fn progress_line(rec: &Recording, rows: &RowBuilder) -> String {
    let t = rows
        .traj
        .n_rows()
        .checked_sub(1)
        .map(|i| rows.traj.row(i)[0])
        .unwrap_or(0.0);
    let mut s = format!("hcc run: t = {t:7.3} s, {} rows", rows.traj.n_rows());
    if let Some(tel) = &rec.last_telemetry {
        let errs: Vec<String> = (0..tel.levels())
            .map(|i| {
                let e = tel.task_error(i);
                format!("{:.2e}", e.iter().map(|x| x * x).sum::<f64>().sqrt())
            })
            .collect();
        s.push_str(&format!(", |e| per level [{}]", errs.join(", ")));
    }
    if let Some(st) = &rec.last_state {
        s.push_str(&format!(", missed commands {}", st.missed_commands));
    }
    s.push_str(&format!(", recorder gaps {}", rec.gaps()));
    s
}

/// Why the recording ended.
enum End {
    /// The simulator finished its run and exited with success.
    Finished,
    /// Ctrl-C or SIGTERM.
    Interrupted,
    /// A child failed or hung: the message.
    Failed(String),
}

/// What `hcc run` starts: the namespace, the daemons and their arguments.
struct Launch {
    namespace: Namespace,
    file_prefix: Option<String>,
    names: ServiceNames,
    out: PathBuf,
    duration: f64,
    /// "lockstep" or "realtime".
    mode: &'static str,
    sim_exe: PathBuf,
    controller_exe: PathBuf,
    sim_args: Vec<String>,
    controller_args: Vec<String>,
}

impl Launch {
    fn new(args: &RunArgs, scenario: &Scenario) -> anyhow::Result<Launch> {
        let duration = scenario.simulation.duration_s;
        let namespace = match &args.namespace {
            Some(ns) => Namespace::new(ns).context("--namespace")?,
            None => Namespace::unique("hcc_run")?,
        };
        let file_prefix = args.file_prefix.clone().or_else(ipc::file_prefix_from_env);
        ipc::config(file_prefix.as_deref()).context("--file-prefix")?;
        let config_arg = args.config.display().to_string();
        let ns_args = ["--namespace".to_string(), namespace.to_string()];
        let mut controller_args = vec![config_arg.clone()];
        controller_args.extend(ns_args.iter().cloned());
        let mut sim_args = vec![config_arg];
        sim_args.extend(ns_args.iter().cloned());
        sim_args.extend(["--duration".to_string(), format!("{duration:?}")]);
        let lockstep = args.lockstep || scenario.sim_daemon.mode == hcc_config::SimMode::Lockstep;
        if args.lockstep {
            sim_args.push("--lockstep".into());
        }
        if lockstep {
            // States come as fast as the loop turns, not once per period: the
            // controller waits on the state_ready event instead of sleeping until
            // the next expected period.
            controller_args.extend(["--wait".to_string(), "event".to_string()]);
            // A loaded machine may stall the controller for longer than the
            // simulator's default 100 ms; a lockstep run must stay exact
            // (the launcher itself notices a dead or hung child).
            sim_args.extend([
                "--lockstep-timeout-ms".to_string(),
                format!("{LOCKSTEP_TIMEOUT_MS:?}"),
            ]);
        } else if !args.no_rt {
            let (sim_rt, controller_rt) = realtime_args(scenario, args.quiet);
            sim_args.extend(sim_rt);
            controller_args.extend(controller_rt);
        }
        Ok(Launch {
            names: ServiceNames::for_namespace(namespace.clone()),
            namespace,
            file_prefix,
            out: args
                .out
                .clone()
                .unwrap_or_else(|| Path::new("out").join(&scenario.name)),
            duration,
            mode: if lockstep { "lockstep" } else { "realtime" },
            sim_exe: daemon_path("hcc-sim")?,
            controller_exe: daemon_path("hcc-controller")?,
            sim_args,
            controller_args,
        })
    }

    /// Starts the controller, waits until it listens (so that control starts
    /// at t = 0: in real time the plant does not wait), starts the scheduler
    /// of the scenario's `[[setpoint]]`s (if any; its first entries reach the
    /// controller before the first state), then the simulator.
    fn spawn(&self, scenario: &Scenario) -> anyhow::Result<(Daemon, Daemon, Option<Scheduler>)> {
        let node = ipc::create_node(
            "hcc-run-probe",
            SignalHandlingMode::Disabled,
            self.file_prefix.as_deref(),
        )?;
        let mut controller = Daemon::spawn(
            "hcc-controller",
            &self.controller_exe,
            &self.controller_args,
            self.file_prefix.as_deref(),
        )?;
        wait_until_controller_listens(&mut controller, &node, &self.names, 1)?;
        drop(node);
        let scheduler = if scenario.setpoints.is_empty() {
            None
        } else {
            match Scheduler::start(self.namespace.as_str(), self.file_prefix.clone(), scenario) {
                Ok(s) => Some(s),
                Err(e) => {
                    controller.terminate(TERMINATE_GRACE);
                    return Err(e);
                }
            }
        };
        let sim = Daemon::spawn(
            "hcc-sim",
            &self.sim_exe,
            &self.sim_args,
            self.file_prefix.as_deref(),
        )?;
        Ok((controller, sim, scheduler))
    }
}

/// The children of a run.
struct Children {
    controller: Daemon,
    sim: Daemon,
}

impl Children {
    /// Why the run must end now, if it must (a child exited, or the daemons
    /// are silent for too long).
    fn check(&mut self, rec: &Recording, started: Instant) -> Option<End> {
        let (sim, controller) = (&mut self.sim, &mut self.controller);
        if let Some(s) = sim.poll() {
            if s.success() {
                return Some(End::Finished);
            }
            return Some(End::Failed(format!(
                "hcc-sim (pid {}) failed with {}; its stderr ends with:\n{}",
                sim.pid(),
                describe_status(s),
                sim.stderr_tail()
            )));
        }
        if let Some(s) = controller.poll() {
            return Some(End::Failed(format!(
                "hcc-controller (pid {}) exited with {} before the run ended; its stderr ends with:\n{}",
                controller.pid(),
                describe_status(s),
                controller.stderr_tail()
            )));
        }
        let now = Instant::now();
        match rec.first_state_at {
            None if now.duration_since(started) > STARTUP_TIMEOUT => Some(End::Failed(format!(
                "no joint state from hcc-sim within {} s; its stderr ends with:\n{}",
                STARTUP_TIMEOUT.as_secs(),
                sim.stderr_tail()
            ))),
            Some(_) if now.duration_since(rec.last_sample_at) > STALL_TIMEOUT => {
                Some(End::Failed(format!(
                    "no message from the daemons for {} s (hung?); hcc-sim's stderr ends with:\n{}\nhcc-controller's stderr ends with:\n{}",
                    STALL_TIMEOUT.as_secs(),
                    sim.stderr_tail(),
                    controller.stderr_tail()
                )))
            }
            _ => None,
        }
    }

    /// After the simulator's last state, gives the controller a moment to
    /// answer it (its telemetry completes the last row).
    fn await_last_answer(
        &mut self,
        receiver: &Receiver,
        rec: &mut Recording,
    ) -> anyhow::Result<()> {
        let until = Instant::now() + FINAL_ANSWER_GRACE;
        while Instant::now() < until && self.controller.poll().is_none() {
            receiver.pump(rec, Duration::from_millis(1))?;
            let answered = rec
                .pending_telemetry
                .back()
                .map(|t| t.state_seq)
                .or(rec.last_joined_seq);
            if answered.is_some() && answered >= rec.last_state_seq {
                break;
            }
        }
        Ok(())
    }

    /// Stops what still runs; a finished run whose controller did not stop
    /// cleanly becomes a failure.
    fn stop(&mut self, end: End) -> End {
        self.sim.terminate(TERMINATE_GRACE);
        let status = self.controller.terminate(TERMINATE_GRACE);
        let clean = status.is_some_and(|s| {
            use std::os::unix::process::ExitStatusExt;
            s.success() || s.signal() == Some(libc::SIGTERM)
        });
        match end {
            End::Finished if !clean => End::Failed(format!(
                "hcc-controller (pid {}) did not stop cleanly ({}); its stderr ends with:\n{}",
                self.controller.pid(),
                status.map_or("still running".into(), describe_status),
                self.controller.stderr_tail()
            )),
            other => other,
        }
    }
}

/// Records until the run ends (the simulator finished, a child failed, or
/// Ctrl-C), with a progress line per second unless `quiet`.
fn record_run(
    receiver: &Receiver,
    rec: &mut Recording,
    rows: &mut RowBuilder,
    children: &mut Children,
    started: Instant,
    quiet: bool,
) -> anyhow::Result<End> {
    let mut next_progress = started + Duration::from_secs(1);
    loop {
        receiver.pump(rec, Duration::from_millis(1))?;
        rec.join(rows, false)?;
        if interrupted() {
            return Ok(End::Interrupted);
        }
        if let Some(end) = children.check(rec, started) {
            return Ok(end);
        }
        if Instant::now() >= next_progress {
            if !quiet {
                eprintln!("{}", progress_line(rec, rows));
            }
            next_progress += Duration::from_secs(1);
        }
    }
}

/// The figures of the IPC path, for metrics.json and the summary.
struct IpcFigures {
    /// State → command latencies, sorted.
    latencies_ns: Vec<u64>,
    expected_rows: u64,
}

impl IpcFigures {
    fn new(rec: &Recording, scenario: &Scenario) -> IpcFigures {
        let mut latencies_ns = rec.latencies_ns.clone();
        latencies_ns.sort_unstable();
        let s = &scenario.simulation;
        IpcFigures {
            latencies_ns,
            expected_rows: (s.duration_s * s.control_rate_hz).round() as u64 + 1,
        }
    }

    /// Latency percentile `p` in µs.
    fn us(&self, p: f64) -> Option<f64> {
        percentile(&self.latencies_ns, p).map(|v| v as f64 * 1e-3)
    }

    /// The `ipc` entry of the run's settings.
    fn json(&self, launch: &Launch, rec: &Recording, rows: &RowBuilder) -> serde_json::Value {
        let last_state = rec.last_state;
        let last_tel = rec.last_telemetry;
        serde_json::json!({
            "runner": "hcc run (hcc-sim and hcc-controller over iceoryx2)",
            "mode": launch.mode,
            "namespace": launch.namespace.as_str(),
            "expected_rows": self.expected_rows,
            "rows": rows.traj.n_rows(),
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
            "shadow_controller_max_tau_difference": rows.shadow_tau_diff,
            "shadow_controller_failures": rows.shadow_failures,
        })
    }

    /// The lines of the summary after the metrics'.
    fn print(&self, mode: &str, rec: &Recording, rows: &RowBuilder) {
        let fmt_us = |v: Option<f64>| v.map_or("-".to_string(), |v| format!("{v:.1} µs"));
        let (last_state, last_tel) = (rec.last_state, rec.last_telemetry);
        println!(
            "  ipc ({mode}): {} rows of {} expected; driver missed commands {}, fallback cycles {}; controller missed states {}",
            rows.traj.n_rows(),
            self.expected_rows,
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
        if rows.shadow_failures > 0 {
            println!(
                "  warning: the shadow controller failed on {} states (acc, accv and S_kin/S_pot are NaN there)",
                rows.shadow_failures
            );
        }
    }
}

/// The exit of `hcc run`: success, or an error that says why and where the
/// partial results are.
fn outcome(
    end: End,
    rec: &Recording,
    written: bool,
    out: &Path,
    started: Instant,
) -> anyhow::Result<()> {
    match end {
        End::Finished => {
            if !rec.sim_stopped {
                warn!("hcc-sim exited without publishing a Stopped state");
            }
            if !written {
                bail!("the run recorded no controller cycle");
            }
            Ok(())
        }
        End::Interrupted => bail!(
            "interrupted after {:.1} s; both daemons stopped{}",
            started.elapsed().as_secs_f64(),
            if written {
                format!(", partial results in {}", out.display())
            } else {
                String::new()
            }
        ),
        End::Failed(msg) => Err(anyhow!(msg)),
    }
}

pub fn run(args: RunArgs) -> anyhow::Result<()> {
    let mut scenario = Scenario::load(&args.config)?;
    if let Some(d) = args.duration {
        scenario
            .set_duration(d)
            .with_context(|| format!("--duration {d}"))?;
    }
    let launch = Launch::new(&args, &scenario)?;

    // Subscribe before the children start, so that no sample is missed.
    let receiver = Receiver::start(launch.file_prefix.clone(), launch.names.clone())?;
    let mut rows = RowBuilder::new(&scenario)?;
    let mut rec = Recording::new();
    install_signal_handlers()?;
    if !args.quiet {
        eprintln!(
            "hcc run: {} ({}, {} s) in namespace {}",
            scenario.name, launch.mode, launch.duration, launch.namespace
        );
    }
    let (controller, sim, scheduler) = launch.spawn(&scenario)?;
    let mut children = Children { controller, sim };
    let started = Instant::now();
    let end = record_run(
        &receiver,
        &mut rec,
        &mut rows,
        &mut children,
        started,
        args.quiet,
    )?;
    if matches!(end, End::Finished) {
        children.await_last_answer(&receiver, &mut rec)?;
    }
    // Stop what still runs, collecting the samples published meanwhile.
    let end = children.stop(end);
    let schedule = scheduler.map(Scheduler::finish);
    receiver.finish(&mut rec)?;
    rec.join(&mut rows, true)?;

    let figures = IpcFigures::new(&rec, &scenario);
    let mut description = describe(&scenario);
    let mut ipc_json = figures.json(&launch, &rec, &rows);
    if let Some(report) = &schedule {
        ipc_json["scheduled_setpoints"] = report.json(&scenario.setpoints);
    }
    description.settings.insert("ipc".into(), ipc_json);
    let written = if rows.traj.n_rows() == 0 {
        None
    } else {
        Some(write_results(
            &launch.out,
            &rows.traj,
            &description,
            args.no_plots,
        )?)
    };
    if let Some(m) = &written {
        print!("{}", m.summary());
    }
    figures.print(launch.mode, &rec, &rows);
    if let Some(report) = &schedule {
        println!("{}", report.line());
        if report.late > 0 {
            println!(
                "  warning: {} scheduled setpoint(s) reached the controller after their cycle and were applied on receipt",
                report.late
            );
        }
    }
    for line in children
        .sim
        .stdout_lines()
        .iter()
        .chain(children.controller.stdout_lines().iter())
    {
        if !line.trim().is_empty() && !args.quiet {
            eprintln!("  | {line}");
        }
    }
    if written.is_some() {
        println!("results in {}", launch.out.display());
    }
    outcome(end, &rec, written.is_some(), &launch.out, started)?;
    match &schedule {
        Some(report) => report.check(&scenario.setpoints),
        None => Ok(()),
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
