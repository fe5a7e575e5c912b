//! `hcc run CONFIG [--out DIR] [--duration S] [--lockstep] [--namespace NS] [--no-rt]`:
//! the main job over inter-process communication.
//!
//! The launcher starts the two daemons as child processes — the plant
//! simulator `hcc-sim` and the controller `hcc-controller`, found next to the
//! `hcc` executable — in a namespace of their own (unique unless given), and
//! records the run from the outside with the recorder of `hcc record`
//! (module `capture`): joint states, torque commands, telemetry and setpoints
//! stream into `DIR/run.mcap` as they arrive, so memory does not grow with
//! the run and a crash keeps what was recorded. After the run,
//! `trajectory.csv` (exactly the column layout of `hcc simulate`),
//! `metrics.json` and the plots are derived from `run.mcap` by the code of
//! `hcc plot FILE.mcap` (module `derive`, which documents where each column
//! comes from; the shadow controller of the derived columns runs there, far
//! from the real-time path).
//!
//! # Not disturbing the real-time loops
//!
//! Publishers of the contract never block (safe overflow): the recorder's
//! subscribers have the largest queue the services allow and are drained
//! every millisecond by a thread that only copies, and every stream goes through
//! a [`hcc_msgs::SequenceChecker`], so lost samples are counted, reported and
//! stored in the file, never lost silently.
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
use hcc_msgs::ipc::{self};
use hcc_msgs::{DriverStatus, JointState, Namespace, ServiceNames, Telemetry};
use hcc_record::mcap_log::RunInfo;
use iceoryx2::prelude::SignalHandlingMode;
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};
use tracing::warn;

use crate::daemons::{
    Daemon, TERMINATE_GRACE, daemon_path, describe_status, install_signal_handlers, interrupted,
    wait_until_controller_listens,
};
use crate::run_schedule::{ScheduleReport, Scheduler};
use crate::view_child::ViewChild;
use hcc_record::capture::{self, Received, Receiver, StreamRecorder};

/// Default scenario of `hcc run`: the paper's simulation #1.
pub const DEFAULT_CONFIG: &str = "config/paper-sim1.toml";

/// The simulator's timing report of a real-time run (`hcc-sim --stats`), in
/// the output directory.
pub const SIM_TIMINGS_FILE: &str = "sim-timings.json";

/// The simulator's account of a real-time run's missed commands, from its
/// timing report: how many followed a late tick of its own — a state
/// published with less than its command window before the next tick (its
/// core stalled, then ticks back to back to catch up), which no controller
/// could have answered in time — and its late ticks. `None` without a report
/// (a lockstep run, a simulator that was killed).
fn sim_report(out: &Path) -> Option<String> {
    let t = hcc_timing::DaemonTimings::read_json(&out.join(SIM_TIMINGS_FILE)).ok()?;
    let missed = t.counter("missed_commands");
    Some(format!(
        "  simulator: missed commands {missed}, {} of them after a late tick of its own (less than \
         the command window left for the answer: the machine, not the controller); ticks late by \
         more than 0.8 periods {} of {}",
        t.counter("short_window_misses").min(missed),
        t.counter("ticks_late"),
        t.counter("periods"),
    ))
}

/// Time to wait for the first joint state after the start of the children.
const STARTUP_TIMEOUT: Duration = Duration::from_secs(20);
/// A running simulator that publishes nothing for this long is considered hung.
const STALL_TIMEOUT: Duration = Duration::from_secs(10);
/// `hcc-sim --lockstep-max-speed` of a lockstep run: at most five times
/// faster than real time (a 3 s scenario in at least 0.6 s; about 1 s measured).
const LOCKSTEP_MAX_SPEED: f64 = 5.0;

/// `hcc-sim --lockstep-timeout-ms` of a lockstep run: a command missing
/// this long is a miss (the simulator falls back and the run is no longer
/// deterministic), so it is far above any stall of a loaded machine.
const LOCKSTEP_TIMEOUT_MS: f64 = 5000.0;
/// Time the controller gets to answer the simulator's last state.
const FINAL_ANSWER_GRACE: Duration = Duration::from_millis(500);

// The help texts name the scenario's TOML tables as [table] and placeholders as
// <name>: neither an intra-doc link nor HTML.
#[allow(rustdoc::broken_intra_doc_links, rustdoc::invalid_html_tags)]
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
    /// Start `hcc view` beside the daemons: the run served live to Foxglove
    /// over WebSocket on 127.0.0.1 (`--view-port`).
    #[arg(long)]
    pub view: bool,
    /// Port of `--view` (0: any free port; the address is printed).
    #[arg(long, default_value_t = 8765)]
    pub view_port: u16,
    /// Joint states `--view` publishes per second, with their commands and
    /// telemetry (0: every sample).
    #[arg(long, default_value_t = 100.0)]
    pub view_rate: f64,
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

/// What the launcher watches while the run goes on (the rest is in the file).
struct Live {
    last_state: Option<JointState>,
    last_telemetry: Option<Box<Telemetry>>,
    last_state_seq: Option<u64>,
    /// State seq answered by the newest telemetry.
    answered_seq: Option<u64>,
    sim_stopped: bool,
    first_state_at: Option<Instant>,
    last_sample_at: Instant,
}

impl Live {
    fn new() -> Live {
        Live {
            last_state: None,
            last_telemetry: None,
            last_state_seq: None,
            answered_seq: None,
            sim_stopped: false,
            first_state_at: None,
            last_sample_at: Instant::now(),
        }
    }

    fn see(&mut self, m: &Received) {
        self.last_sample_at = Instant::now();
        match m {
            Received::State(s) => {
                self.first_state_at.get_or_insert_with(Instant::now);
                self.last_state_seq = Some(s.header.seq);
                if s.status() == Ok(DriverStatus::Stopped) {
                    self.sim_stopped = true;
                }
                self.last_state = Some(**s);
            }
            Received::Telemetry(t) => {
                self.answered_seq = Some(t.state_seq);
                self.last_telemetry = Some(t.clone());
            }
            _ => {}
        }
    }
}

/// Hands what the receiver has to the recorder and the live view.
fn pump(
    receiver: &Receiver,
    recorder: &mut StreamRecorder,
    live: &mut Live,
    wait: Duration,
) -> anyhow::Result<usize> {
    receiver.pump(wait, |m| {
        live.see(&m);
        recorder.record(&m)
    })
}

fn progress_line(live: &Live, recorder: &StreamRecorder, period: f64) -> String {
    let t = live.last_state_seq.map_or(0.0, |k| k as f64 * period);
    let stats = recorder.stats();
    let mut s = format!(
        "hcc run: t = {t:7.3} s, {} cycles recorded",
        stats.telemetry.recorded
    );
    if let Some(tel) = &live.last_telemetry {
        let errs: Vec<String> = (0..tel.levels())
            .map(|i| {
                let e = tel.task_error(i);
                format!("{:.2e}", e.iter().map(|x| x * x).sum::<f64>().sqrt())
            })
            .collect();
        s.push_str(&format!(", |e| per level [{}]", errs.join(", ")));
    }
    if let Some(st) = &live.last_state {
        s.push_str(&format!(", missed commands {}", st.missed_commands));
    }
    s.push_str(&format!(", recorder gaps {}", stats.total_gaps));
    s
}

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
            // A simulator that waits for the recorder is not a lost driver:
            // no stale-peer report per 3 ms of such a wait, which would
            // fill the recorder's telemetry queue.
            controller_args.extend([
                "--stale-timeout-ms".to_string(),
                format!("{LOCKSTEP_TIMEOUT_MS:?}"),
            ]);
            // A loaded machine may stall the controller for longer than the
            // simulator's default 100 ms; a lockstep run must stay exact
            // (the launcher itself notices a dead or hung child).
            sim_args.extend([
                "--lockstep-timeout-ms".to_string(),
                format!("{LOCKSTEP_TIMEOUT_MS:?}"),
                // The recorder is not in the lockstep: at five times a 1 kHz
                // rate its queues (128 samples) last 25 ms instead of the few
                // ms of an unpaced run, which host stalls of the recorder's
                // CPU exceeded now and then (samples lost).
                "--lockstep-max-speed".to_string(),
                format!("{LOCKSTEP_MAX_SPEED:?}"),
                // And it waits for the recorder, which publishes its
                // progress (capture::Pace::Lockstep): a stall of the
                // recorder longer than its queues then loses nothing.
                "--lockstep-recorder".to_string(),
            ]);
        } else if !args.no_rt {
            let (sim_rt, controller_rt) = realtime_args(scenario, args.quiet);
            sim_args.extend(sim_rt);
            controller_args.extend(controller_rt);
        }
        let out = args
            .out
            .clone()
            .unwrap_or_else(|| Path::new("out").join(&scenario.name));
        if !lockstep {
            // The simulator's timing report: which misses followed a late
            // tick of its own ([`sim_report`]).
            sim_args.extend([
                "--stats".to_string(),
                out.join(SIM_TIMINGS_FILE).display().to_string(),
            ]);
        }
        Ok(Launch {
            names: ServiceNames::for_namespace(namespace.clone()),
            namespace,
            file_prefix,
            out,
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
    /// `other_subscribers`: the launcher's own joint-state subscribers (the
    /// recorder, and `hcc view` with `--view`).
    fn spawn(
        &self,
        scenario: &Scenario,
        other_subscribers: usize,
    ) -> anyhow::Result<(Daemon, Daemon, Option<Scheduler>)> {
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
        wait_until_controller_listens(&mut controller, &node, &self.names, other_subscribers)?;
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
    fn check(&mut self, rec: &Live, started: Instant) -> Option<End> {
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
        recorder: &mut StreamRecorder,
        live: &mut Live,
    ) -> anyhow::Result<()> {
        let until = Instant::now() + FINAL_ANSWER_GRACE;
        while Instant::now() < until && self.controller.poll().is_none() {
            pump(receiver, recorder, live, Duration::from_millis(1))?;
            if live.answered_seq.is_some() && live.answered_seq >= live.last_state_seq {
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
    recorder: &mut StreamRecorder,
    live: &mut Live,
    children: &mut Children,
    started: Instant,
    quiet: bool,
    period: f64,
) -> anyhow::Result<End> {
    let mut next_progress = started + Duration::from_secs(1);
    loop {
        pump(receiver, recorder, live, Duration::from_millis(1))?;
        recorder.tick()?;
        if interrupted() {
            return Ok(End::Interrupted);
        }
        if let Some(end) = children.check(live, started) {
            return Ok(end);
        }
        if Instant::now() >= next_progress {
            if !quiet {
                eprintln!("{}", progress_line(live, recorder, period));
            }
            next_progress += Duration::from_secs(1);
        }
    }
}

/// The exit of `hcc run`: success, or an error that says why and where the
/// partial results are.
fn outcome(
    end: End,
    sim_stopped: bool,
    written: bool,
    out: &Path,
    started: Instant,
) -> anyhow::Result<()> {
    match end {
        End::Finished => {
            if !sim_stopped {
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

/// The metadata of a run's recording.
fn run_info(scenario: &Scenario, launch: &Launch, recorder: &str, clock: (u64, u64)) -> RunInfo {
    let mut run = capture::run_metadata(recorder, launch.namespace.as_str(), clock);
    run.insert("mode".into(), launch.mode.into());
    run.insert("duration_s".into(), format!("{:?}", launch.duration));
    run.insert("control_rate_hz".into(), scenario.rate_hz.to_string());
    RunInfo {
        run,
        scenario: RunInfo::describe_scenario(scenario),
        machine: capture::machine_metadata(),
    }
}

/// Derives trajectory.csv, metrics.json and the plots of the recording in
/// `out` (as `hcc plot` does), with the scheduler's report (if any) under
/// `ipc.scheduled_setpoints` of metrics.json; whether there were rows to write.
fn write_derived(
    recording: &Path,
    scenario: &Scenario,
    out: &Path,
    no_plots: bool,
    schedule: Option<serde_json::Value>,
) -> anyhow::Result<bool> {
    let mut writer = hcc_replay::derive::results_writer(scenario, out, no_plots)?;
    let mut d = hcc_replay::derive::derive(recording, scenario, &mut writer)?;
    if let Some(report) = schedule
        && let Some(ipc) = d.description.settings.get_mut("ipc")
    {
        ipc["scheduled_setpoints"] = report;
    }
    if d.rows.rows == 0 {
        d.print();
        return Ok(false);
    }
    let m = writer.finish(&d.description)?.metrics;
    print!("{}", m.summary());
    d.print();
    Ok(true)
}

/// The recorder's receiver of a run. It drains at a low real-time priority
/// when permitted (the daemons' warning already says when SCHED_FIFO is not),
/// also in lockstep, whose daemons run at normal priority as fast as they
/// can: there it drains every 100 µs and publishes its progress, which the
/// simulator waits for (`hcc-sim --lockstep-recorder`), so that a stall of
/// the recorder on a loaded machine delays the run instead of losing
/// samples.
fn start_receiver(args: &RunArgs, launch: &Launch) -> anyhow::Result<Receiver> {
    let priority = (!args.no_rt).then_some(capture::RECEIVER_PRIORITY);
    let pace = if launch.mode == "lockstep" {
        capture::Pace::Lockstep
    } else {
        capture::Pace::Realtime
    };
    let receiver = Receiver::start(
        "hcc-run",
        launch.file_prefix.clone(),
        launch.names.clone(),
        priority,
        pace,
    )?;
    if let Some(w) = &receiver.priority_warning {
        tracing::debug!("{w}");
    }
    Ok(receiver)
}

/// The recording's closing metadata: how the run ended and how many samples
/// the writer fell behind on.
fn end_metadata(end: &End, dropped: u64) -> BTreeMap<String, String> {
    let mut meta = BTreeMap::new();
    meta.insert("dropped_writer_behind".into(), dropped.to_string());
    let how = match end {
        End::Finished => "finished",
        End::Interrupted => "interrupted",
        End::Failed(_) => "a daemon failed",
    };
    meta.insert("end".into(), how.to_string());
    meta
}

/// The run's summary on the terminal: the simulator's report, the setpoint
/// schedule, the daemons' own output and where the results are.
fn print_results(
    out: &Path,
    written: bool,
    schedule: Option<&ScheduleReport>,
    children: &mut Children,
    quiet: bool,
) {
    if written && let Some(line) = sim_report(out) {
        println!("{line}");
    }
    if let Some(report) = schedule {
        println!("{}", report.line());
        if report.late > 0 {
            println!(
                "  warning: {} scheduled setpoint(s) reached the controller after their cycle and were applied on receipt",
                report.late
            );
        }
    }
    if !quiet {
        for line in children
            .sim
            .stdout_lines()
            .iter()
            .chain(children.controller.stdout_lines().iter())
        {
            if !line.trim().is_empty() {
                eprintln!("  | {line}");
            }
        }
    }
    if written {
        println!("results in {}", out.display());
    }
}

pub fn run(args: RunArgs) -> anyhow::Result<()> {
    let mut scenario = Scenario::load(&args.config)?;
    // What the law refuses at q0, before any process starts.
    hcc_cycle::controller_for(&scenario)?;
    if let Some(d) = args.duration {
        scenario
            .set_duration(d)
            .with_context(|| format!("--duration {d}"))?;
    }
    let launch = Launch::new(&args, &scenario)?;
    let recording = launch.out.join(capture::RECORDING_FILE);

    // Subscribe before the children start, so that no sample is missed.
    let receiver = start_receiver(&args, &launch)?;
    let clock = hcc_record::mcap_log::clock_pair();
    let mut recorder = StreamRecorder::create(
        &recording,
        &run_info(&scenario, &launch, "hcc run", clock),
        clock,
    )?;
    // A report left by an earlier run in this directory is not this run's.
    let _ = std::fs::remove_file(launch.out.join(SIM_TIMINGS_FILE));
    let mut live = Live::new();
    install_signal_handlers()?;
    if !args.quiet {
        eprintln!(
            "hcc run: {} ({}, {} s) in namespace {}, recording to {}",
            scenario.name,
            launch.mode,
            launch.duration,
            launch.namespace,
            recording.display()
        );
    }
    // Dropped (and so stopped) on every way out of this function.
    let view = args
        .view
        .then(|| {
            ViewChild::start(
                launch.namespace.as_str(),
                launch.file_prefix.as_deref(),
                &args.config,
                args.view_port,
                args.view_rate,
            )
        })
        .transpose()?;
    if let Some(v) = &view {
        eprintln!("{}", v.line);
    }
    let (controller, sim, scheduler) = launch.spawn(&scenario, 1 + usize::from(view.is_some()))?;
    let mut children = Children { controller, sim };
    let started = Instant::now();
    let period = scenario.period_s();
    let end = record_run(
        &receiver,
        &mut recorder,
        &mut live,
        &mut children,
        started,
        args.quiet,
        period,
    )?;
    if matches!(end, End::Finished) {
        children.await_last_answer(&receiver, &mut recorder, &mut live)?;
    }
    // Stop what still runs, collecting the samples published meanwhile.
    let end = children.stop(end);
    let schedule = scheduler.map(Scheduler::finish);
    let dropped = receiver.dropped();
    receiver.finish(|m| {
        live.see(&m);
        recorder.record(&m)
    })?;
    let stats = recorder.finish(end_metadata(&end, dropped))?;
    if !args.quiet {
        eprintln!("hcc run: recorded {}", capture::stats_line(&stats));
    }

    let written = write_derived(
        &recording,
        &scenario,
        &launch.out,
        args.no_plots,
        schedule
            .as_ref()
            .map(|report| report.json(&scenario.setpoints)),
    )?;
    print_results(
        &launch.out,
        written,
        schedule.as_ref(),
        &mut children,
        args.quiet,
    );
    outcome(end, live.sim_stopped, written, &launch.out, started)?;
    match &schedule {
        Some(report) => report.check(&scenario.setpoints),
        None => Ok(()),
    }
}
