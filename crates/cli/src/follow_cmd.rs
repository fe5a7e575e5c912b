//! `hcc follow`: a path file (a scenario's `trajectory` format) sent to a
//! running controller's level while it runs (docs/tracking.md). The path's
//! t = 0 is the cycle that accepts it (or `--start-at` s later); its knots go
//! out ahead of the path by `--window` s (at most three quarters of the
//! controller's window, `[setpoint_limits] path_knots`), each message after
//! the controller answered the
//! one before. Progress is printed every half second; at the end, the
//! level's largest tracking error from 3 s on.

use std::time::{Duration, Instant};

use anyhow::{Context, bail};
use hcc_client::Client;

use crate::setpoint_cmd::{Target, connect, level_index, scenario_of, timeout};

/// `hcc follow`.
#[derive(clap::Args, Debug)]
pub struct FollowArgs {
    #[command(flatten)]
    pub target: Target,
    /// Level: 1-based, or its name (from the controller's scenario service).
    #[arg(long)]
    pub level: String,
    /// Start the path this many s after the controller accepts it.
    #[arg(long, default_value_t = 0.0)]
    pub start_at: f64,
    /// How far ahead of the path its knots are sent, s.
    #[arg(long, default_value_t = 2.0)]
    pub window: f64,
    /// The path: a header row, then rows t, c1, c2, … (the format of a
    /// scenario's `trajectory`; docs/tracking.md).
    pub file: std::path::PathBuf,
}

/// The level's task error norm in the newest telemetry.
fn error_norm(client: &mut Client, level: usize) -> Option<f64> {
    let t = client.poll_telemetry()?;
    let e = t.task_error(level);
    Some(e.iter().map(|x| x * x).sum::<f64>().sqrt())
}

/// `hcc follow`: exit 0 once the whole path was accepted and has run.
pub fn follow(args: FollowArgs) -> anyhow::Result<()> {
    let (level, _) = level_index(&args.target, &args.level)?;
    let doc = scenario_of(&args.target).context("hcc follow needs the controller's scenario")?;
    let scenario = hcc_config::Scenario::from_document(&doc)?;
    let Some(spec) = scenario.spec.levels.get(level) else {
        bail!("the controller has {} levels", scenario.spec.levels.len());
    };
    let blocks = hcc_spec::tracking::blocks(&spec.tasks, scenario.model.nq());
    // Knots sent ahead of where the path is at most: within the controller's
    // window, with room for what arrives while the path moves on.
    let max_ahead = (scenario.setpoint_limits.path_knots * 3 / 4).max(2);
    let text = std::fs::read_to_string(&args.file)
        .with_context(|| format!("cannot read {}", args.file.display()))?;
    let rows = hcc_trajectory::read_rows(&text, &blocks)
        .with_context(|| format!("{}", args.file.display()))?;
    let times: Vec<f64> = rows.iter().map(|r| r.0).collect();
    let points: Vec<Vec<f64>> = rows.into_iter().map(|r| r.1).collect();
    let duration = times[times.len() - 1];
    if !(args.window > 0.0 && args.start_at >= 0.0) {
        bail!("--window must be positive and --start-at not negative");
    }
    let wait = timeout(&args.target)?;
    let mut client = connect(&args.target)?;
    let state_seq = client
        .poll_telemetry()
        .map(|t| t.state_seq)
        .or_else(|| {
            std::thread::sleep(Duration::from_millis(50));
            client.poll_telemetry().map(|t| t.state_seq)
        })
        .context("no telemetry from the controller (is it running in this namespace?)")?;
    let start_seq = if args.start_at > 0.0 {
        state_seq + (args.start_at * doc.rate_hz).round() as u64
    } else {
        0
    };
    // The knots from `from` on up to time `until` (at most max_ahead).
    let ahead = |from: usize, until: f64| -> usize {
        let mut k = from;
        while k < times.len() && times[k] <= until && k - from < max_ahead {
            k += 1;
        }
        k
    };
    // The first message holds two knots at least (the path's first segment).
    let first = ahead(0, args.window).max(2).min(times.len());
    let accepted = client
        .follow(level, &times[..first], &points[..first], start_seq, wait)
        .map_err(|e| refused(&args.file, e, &times))?;
    let begin = Instant::now() + Duration::from_secs_f64(args.start_at);
    println!(
        "level {} path of {} knots over {duration:.3} s accepted (seq {}); {first} sent",
        args.level,
        times.len(),
        accepted.seq
    );
    let mut sent = first;
    let mut next_report = Instant::now();
    let mut worst: f64 = 0.0;
    loop {
        // 0 until the path begins (elapsed saturates).
        let t = begin.elapsed().as_secs_f64();
        if sent < times.len() {
            let passed = times.partition_point(|&tk| tk < t);
            let until = ahead(sent, t + args.window).min(passed + max_ahead);
            if until > sent {
                client
                    .extend_path(level, &times[sent..until], &points[sent..until], wait)
                    .map_err(|e| refused(&args.file, in_file(e, sent), &times))?;
                sent = until;
            }
        }
        let e = error_norm(&mut client, level);
        if t >= 3.0 {
            worst = worst.max(e.unwrap_or(0.0));
        }
        if Instant::now() >= next_report {
            println!(
                "t = {t:6.2} s of {duration:.2} s, {sent}/{} knots sent, level error {}",
                times.len(),
                e.map_or("-".into(), |e| format!("{e:.3e}"))
            );
            next_report += Duration::from_millis(500);
        }
        if t > duration + 0.5 && sent == times.len() {
            break;
        }
        std::thread::sleep(Duration::from_millis(2));
    }
    println!("path done; largest level error from 3 s: {worst:.3e}");
    Ok(())
}

/// A refusal of the message that began at the file's knot `offset`, its
/// knots numbered as in the file.
fn in_file(mut e: hcc_client::KnotsRefused, offset: usize) -> hcc_client::KnotsRefused {
    e.first += offset;
    e.last += offset;
    e.knot = e.knot.map(|k| k + offset);
    e
}

/// The error of a refused message of `file`, with the refused knot's time.
fn refused(file: &std::path::Path, e: hcc_client::KnotsRefused, times: &[f64]) -> anyhow::Error {
    match e.t_knot(times) {
        Some(t) => anyhow::anyhow!("{}: {e} (the knot at t = {t} s)", file.display()),
        None => anyhow::anyhow!("{}: {e}", file.display()),
    }
}
