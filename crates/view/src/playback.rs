//! `hcc view FILE.mcap`: a recording played back through the live server,
//! paced by its log times (`--speed`) from the moment a client subscribes
//! to one of its channels (so that a viewer opened after the command sees
//! the run from its start), with the transform tree, stick figure
//! and limits computed from its joint states as live. The scenario comes
//! from `--config`, else from the recording's scenario record (its file if
//! it still exists, else the TOML text stored in the recording).

use anyhow::{Context as _, bail};
use hcc_config::Scenario;
use hcc_record::mcap_log::{self, Entry, META_SCENARIO};
use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

use crate::viewer::stats_line;
use crate::{Args, Server};

/// The scenario of a recording, from its metadata.
fn recorded_scenario(file: &Path) -> anyhow::Result<Option<Scenario>> {
    let meta = mcap_log::read_metadata(file)?;
    let Some(s) = meta.get(META_SCENARIO) else {
        return Ok(None);
    };
    let Some(path) = s.get("path").map(PathBuf::from) else {
        return Ok(None);
    };
    if let Ok(scenario) = Scenario::load(&path) {
        return Ok(Some(scenario));
    }
    match s.get("toml") {
        Some(text) if !text.is_empty() => {
            Ok(Some(Scenario::from_toml_str(text, &path).with_context(
                || format!("the scenario stored in {} does not load", file.display()),
            )?))
        }
        _ => Ok(None),
    }
}

/// Publishes what is due between samples: the URDF for a new subscriber,
/// the counts once a second.
fn between(server: &mut Server, log_time: u64) {
    if server.description_wanted() {
        server.viewer.robot_description(log_time);
    }
    let clients = server.clients();
    server.viewer.tick(clients, log_time);
}

/// Serves (URDF requests, counts at `log_time`) until `done` or Ctrl-C;
/// whether `done` ended it.
fn serve_until(server: &mut Server, log_time: u64, done: impl Fn(&Server) -> bool) -> bool {
    loop {
        if done(server) {
            return true;
        }
        if hcc_rt::stop_requested() {
            return false;
        }
        between(server, log_time);
        std::thread::sleep(Duration::from_millis(20));
    }
}

/// Stop of the playback by a signal (not an error of the file).
#[derive(Debug)]
struct Stopped;

impl std::fmt::Display for Stopped {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str("stopped")
    }
}

impl std::error::Error for Stopped {}

pub fn run(args: &Args, file: &Path) -> anyhow::Result<()> {
    if !(args.speed.is_finite() && args.speed > 0.0) {
        bail!("--speed must be a positive number, not {}", args.speed);
    }
    let scenario = match &args.config {
        Some(c) => Some(Scenario::load(c).context("--config")?),
        None => recorded_scenario(file)?,
    };
    if scenario.is_none() && !args.quiet {
        eprintln!(
            "hcc view: the recording names no scenario and no --config was given: no transform tree"
        );
    }
    let mut server = crate::start(
        args,
        scenario.as_ref(),
        &format!("playback of {}", file.display()),
    )?;
    if !args.quiet {
        eprintln!("hcc view: waiting for a client to subscribe (Ctrl-C to stop)");
    }
    if !serve_until(&mut server, mcap_log::clock_pair().0, |s| {
        s.viewer.watched()
    }) {
        server.handle.stop().wait_blocking();
        return Ok(());
    }
    let mut start: Option<(u64, Instant)> = None;
    let speed = args.speed;
    let result = mcap_log::read::<anyhow::Error>(file, |log_time, entry| {
        if let Entry::Metadata(..) = entry {
            return Ok(());
        }
        let (t0, wall0) = *start.get_or_insert((log_time, Instant::now()));
        let due =
            wall0 + Duration::from_secs_f64(log_time.saturating_sub(t0) as f64 * 1e-9 / speed);
        loop {
            if hcc_rt::stop_requested() {
                return Err(Stopped.into());
            }
            let now = Instant::now();
            if now >= due {
                break;
            }
            between(&mut server, log_time);
            std::thread::sleep((due - now).min(Duration::from_millis(5)));
        }
        let v = &mut server.viewer;
        match entry {
            Entry::JointState(m) => v.joint_state(m.seq, m.stamp_ns, log_time, || m),
            Entry::TorqueCommand(m) => v.torque_command(m.seq, m.state_seq, log_time, || m),
            Entry::Telemetry(m) => v.telemetry(m.seq, m.state_seq, log_time, || *m),
            Entry::Setpoint(m) => v.setpoint(log_time, &m),
            Entry::Path(m) => v.path(log_time, &m),
            Entry::Load(m) => v.load(log_time, &m),
            Entry::Recorder(_) | Entry::Metadata(..) => {}
        }
        between(&mut server, log_time);
        Ok(())
    });
    match result {
        Ok(summary) => {
            let mut line = format!(
                "hcc view: played {}; {}",
                file.display(),
                stats_line(server.viewer.counts())
            );
            if let Some(why) = summary.truncated {
                line.push_str(&format!(" (the file is truncated: {why})"));
            }
            println!("{line}");
        }
        Err(e) if e.is::<Stopped>() => {}
        Err(e) => return Err(e),
    }
    if !args.exit_at_end {
        let end = start.map_or(0, |(t0, w0)| t0 + w0.elapsed().as_nanos() as u64);
        serve_until(&mut server, end, |_| false);
    }
    server.handle.stop().wait_blocking();
    Ok(())
}
