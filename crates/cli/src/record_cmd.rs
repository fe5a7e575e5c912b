//! `hcc record --namespace NS [--duration S] [--out FILE.mcap] [--config FILE]`:
//! records a running namespace into an MCAP file as a pure subscriber — it
//! never publishes and never waits on the loop; the daemons' publishers do
//! not block on it (safe overflow), and what it could not keep up with is
//! counted as gaps, printed and stored in the file (module `capture`).
//!
//! It stops on Ctrl-C or SIGTERM, after `--duration` seconds, or when the
//! controller is gone (no telemetry for `--idle-timeout` seconds after it
//! was heard), and then closes the file cleanly (summary, index, final
//! counts). Killed with SIGKILL, it leaves a file readable up to its last
//! chunk (at most a second old).

use anyhow::{Context, bail};
use hcc_config::{Scenario, ToolScenarioError};
use hcc_msgs::{ServiceNames, ipc};
use hcc_record::mcap_log::{self, RunInfo};
use std::collections::BTreeMap;
use std::path::PathBuf;
use std::time::{Duration, Instant};

use crate::daemons::{install_signal_handlers, interrupted};
use hcc_record::capture::{self, Received, Receiver, StreamRecorder};

// The help texts name the scenario's TOML tables as [table] and placeholders as
// <name>: neither an intra-doc link nor HTML.
#[allow(rustdoc::broken_intra_doc_links, rustdoc::invalid_html_tags)]
#[derive(clap::Args, Debug)]
pub struct RecordArgs {
    /// Namespace of the running controller and driver.
    #[arg(long)]
    pub namespace: String,
    /// Stop after this many seconds (default: until Ctrl-C or the controller is gone).
    #[arg(long)]
    pub duration: Option<f64>,
    /// The recording (default: hcc-<namespace>-<start time>.mcap).
    #[arg(long)]
    pub out: Option<PathBuf>,
    /// The scenario the controller runs (default: the one it publishes on
    /// its scenario service): stored in the file (the TOML's and the URDF's
    /// texts), so that `hcc plot` and `hcc replay` need nothing else.
    #[arg(long)]
    pub config: Option<PathBuf>,
    /// iceoryx2 file prefix of the daemons (default: HCC_IPC_FILE_PREFIX, else iceoryx2's).
    #[arg(long)]
    pub file_prefix: Option<String>,
    /// The controller is gone when its telemetry stops for this long, s.
    #[arg(long, default_value_t = 2.0)]
    pub idle_timeout: f64,
    /// Give up when no telemetry arrives within this many seconds of the start.
    #[arg(long, default_value_t = 30.0)]
    pub wait: f64,
    /// SCHED_FIFO priority of the thread that drains the queues (0: normal
    /// scheduling). Below the daemons' loops; without it a loaded machine
    /// can keep the recorder from draining for longer than the queues hold
    /// (128 ms) and samples are lost (counted as gaps).
    #[arg(long, default_value_t = capture::RECEIVER_PRIORITY, value_parser = clap::value_parser!(i32).range(0..=99))]
    pub receiver_priority: i32,
    /// No progress lines on stderr.
    #[arg(long)]
    pub quiet: bool,
}

fn positive(what: &str, v: f64) -> anyhow::Result<Duration> {
    if !(v.is_finite() && v > 0.0) {
        bail!("{what} must be a positive number of seconds, not {v}");
    }
    Ok(Duration::from_secs_f64(v))
}

/// The recording's metadata: the recorder, the namespace, the start time,
/// the scenario when known (`--config`) and the machine.
fn run_info(namespace: &str, scenario: Option<&Scenario>, clock: (u64, u64)) -> RunInfo {
    let mut run = capture::run_metadata("hcc record", namespace, clock);
    if let Some(s) = scenario {
        run.insert("control_rate_hz".into(), s.rate_hz.to_string());
    }
    RunInfo {
        run,
        scenario: scenario.map(RunInfo::describe_scenario).unwrap_or_default(),
        machine: capture::machine_metadata(),
    }
}

/// The scenario the recording stores: `--config` (a warning when it is not
/// what the controller runs: its replay would not be bit for bit), else the
/// one the controller publishes; none — said on stderr — from a controller
/// without the scenario service.
fn recorded_scenario(
    args: &RecordArgs,
    names: &ServiceNames,
    file_prefix: Option<&str>,
    wait: Duration,
) -> anyhow::Result<Option<Scenario>> {
    let tool = "hcc-record-scenario";
    match hcc_config::scenario_for_tool(tool, args.config.as_deref(), names, file_prefix, wait) {
        Ok((s, differs)) => {
            if let Some(d) = differs {
                eprintln!("hcc record: warning: --config: {d}");
            }
            Ok(Some(s))
        }
        Err(ToolScenarioError::Config(e)) => Err(e).context("--config"),
        Err(e) => {
            eprintln!(
                "hcc record: {e}; the recording names no scenario (give it to hcc plot and hcc replay with --config)"
            );
            Ok(None)
        }
    }
}

pub fn run(args: RecordArgs) -> anyhow::Result<()> {
    let names = ServiceNames::new(&args.namespace).context("--namespace")?;
    let duration = args
        .duration
        .map(|d| positive("--duration", d))
        .transpose()?;
    let idle = positive("--idle-timeout", args.idle_timeout)?;
    let wait = positive("--wait", args.wait)?;
    let file_prefix = args.file_prefix.clone().or_else(ipc::file_prefix_from_env);
    ipc::config(file_prefix.as_deref()).context("--file-prefix")?;
    let scenario = recorded_scenario(&args, &names, file_prefix.as_deref(), wait)?;
    let clock = mcap_log::clock_pair();
    let out = args.out.clone().unwrap_or_else(|| {
        let stamp: String = capture::rfc3339(clock.0)
            .chars()
            .filter(|c| c.is_ascii_digit())
            .take(14)
            .collect();
        PathBuf::from(format!("hcc-{}-{stamp}.mcap", args.namespace))
    });
    let info = run_info(&args.namespace, scenario.as_ref(), clock);
    let node = format!("hcc-record-{}", std::process::id());
    let priority = (args.receiver_priority > 0).then_some(args.receiver_priority);
    let receiver = Receiver::start(&node, file_prefix, names, priority, capture::Pace::Realtime)?;
    if let Some(w) = &receiver.priority_warning {
        eprintln!("hcc record: warning: {w}");
    }
    let mut recorder = StreamRecorder::create(&out, &info, clock)?;
    install_signal_handlers()?;
    if !args.quiet {
        eprintln!(
            "hcc record: namespace {} into {} (Ctrl-C to stop)",
            args.namespace,
            out.display()
        );
    }
    let started = Instant::now();
    let mut last_telemetry: Option<Instant> = None;
    let end = loop {
        receiver.pump(Duration::from_millis(1), |m| {
            if let Received::Telemetry(_) = m {
                last_telemetry = Some(Instant::now());
            }
            recorder.record(&m)
        })?;
        if let Some(stats) = recorder.tick()?
            && !args.quiet
        {
            eprintln!(
                "hcc record: {:.0} s, {}",
                stats.elapsed_s,
                capture::stats_line(&stats)
            );
        }
        if interrupted() {
            break "interrupted".to_string();
        }
        if duration.is_some_and(|d| started.elapsed() >= d) {
            break "duration".to_string();
        }
        match last_telemetry {
            Some(t) if t.elapsed() >= idle => {
                break format!(
                    "the controller is gone (no telemetry for {:.1} s)",
                    idle.as_secs_f64()
                );
            }
            None if started.elapsed() >= wait => {
                break format!(
                    "no telemetry within {:.1} s (is hcc-controller running in namespace {}?)",
                    wait.as_secs_f64(),
                    args.namespace
                );
            }
            _ => {}
        }
    };
    let dropped = receiver.dropped();
    receiver.finish(|m| recorder.record(&m))?;
    let mut end_meta = BTreeMap::new();
    end_meta.insert("end".into(), end.clone());
    end_meta.insert("dropped_writer_behind".into(), dropped.to_string());
    if dropped > 0 {
        eprintln!(
            "hcc record: warning: the file writer fell {} samples behind; {dropped} samples dropped (counted as gaps)",
            capture::BACKLOG
        );
    }
    let stats = recorder.finish(end_meta)?;
    println!(
        "recorded {:.1} s into {} ({}): {}",
        started.elapsed().as_secs_f64(),
        out.display(),
        end,
        capture::stats_line(&stats)
    );
    if last_telemetry.is_none() {
        bail!(
            "no telemetry from namespace {} was recorded (stopped by: {end})",
            args.namespace
        );
    }
    Ok(())
}
