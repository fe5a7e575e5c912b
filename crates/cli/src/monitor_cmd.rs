//! `hcc monitor`: a running controller's telemetry, watched through
//! hcc-client — a table refreshed in place, or JSON lines. Besides the
//! levels and the counters it shows the contact watch: the contact flag and
//! the largest |τ_ext,j| of the observer's estimate (docs/contact.md).

use std::io::{IsTerminal, Write};
use std::time::{Duration, Instant};

use anyhow::{Context, bail};
use hcc_msgs::{Telemetry, TelemetryCounters};
use hcc_record::mcap_log::mode_name;

use crate::setpoint_cmd::{Target, connect, scenario_of, timeout};

/// `hcc monitor`.
#[derive(clap::Args, Debug)]
pub struct MonitorArgs {
    #[command(flatten)]
    pub target: Target,
    /// One JSON object per line instead of a table.
    #[arg(long)]
    pub json: bool,
    /// Stop after this many samples.
    #[arg(long)]
    pub count: Option<u64>,
    /// Samples per second shown (table) or written (JSON).
    #[arg(long, default_value_t = 4.0)]
    pub rate: f64,
    /// The controller's scenario TOML: names the levels as its `[[level]]`
    /// tables do (telemetry carries numbers only). By default the names come
    /// from the controller's scenario service; "level N" when it has none.
    #[arg(long)]
    pub config: Option<std::path::PathBuf>,
}

/// The name of level `i` (0-based): from the scenario, else "level N".
fn level_name(names: &[String], i: usize) -> String {
    names
        .get(i)
        .cloned()
        .unwrap_or_else(|| format!("level {}", i + 1))
}

/// The level names and task dimensions of `--config`, else of the
/// controller's scenario service (the dimensions are checked against the
/// telemetry's, see [`check_names`]). A controller without the service (not
/// running, or older) is said on stderr and its levels are "level N".
fn config_levels(
    config: Option<&std::path::Path>,
    target: &Target,
) -> anyhow::Result<(Vec<String>, Vec<usize>)> {
    let Some(path) = config else {
        return Ok(match scenario_of(target) {
            Ok(doc) => doc.levels.into_iter().map(|l| (l.name, l.dim)).unzip(),
            Err(e) => {
                eprintln!("hcc monitor: {e:#}; the levels are shown as \"level N\"");
                (Vec::new(), Vec::new())
            }
        });
    };
    let scenario = hcc_config::Scenario::load(path).context("--config")?;
    let names = scenario.levels().iter().map(|l| l.name.clone()).collect();
    Ok((names, scenario.task_dims()))
}

/// An error when the controller's levels are not those of `--config`.
fn check_names(names: &[String], dims: &[usize], t: &Telemetry) -> anyhow::Result<()> {
    let got: Vec<usize> = (0..t.levels()).map(|i| t.task_dims[i] as usize).collect();
    if !names.is_empty() && got != dims {
        bail!(
            "the controller runs levels of dimensions {got:?}, the scenario (--config, or its scenario service) has {dims:?}"
        );
    }
    Ok(())
}

/// The largest |τ_ext,j| of the sample and its joint j (1-based; 0 for a
/// robot without joints).
fn largest_external_torque(t: &Telemetry) -> (f64, usize) {
    t.tau_ext()
        .iter()
        .enumerate()
        .fold((0.0, 0), |(m, j), (k, r)| {
            if r.abs() > m {
                (r.abs(), k + 1)
            } else {
                (m, j)
            }
        })
}

/// One telemetry sample as the monitor's JSON object; `names` name the
/// levels (missing ones: "level N").
pub fn sample_json(t: &Telemetry, names: &[String]) -> serde_json::Value {
    let levels: Vec<_> = (0..t.levels())
        .map(|i| {
            let m = t.task_error(i).len();
            let error = t.task_error(i);
            serde_json::json!({
                "level": i + 1,
                "name": level_name(names, i),
                "error": error,
                "error_norm": error.iter().map(|x| x * x).sum::<f64>().sqrt(),
                "goal": t.goal(i),
                "stiffness": &t.stiffness_diag[i][..m],
                "damping": &t.damping_diag[i][..m],
                "storage": t.storage[i],
                "potential": t.potential[i],
                "tank": t.tank[i],
                "tank_valve": t.tank_valve[i],
                "singular": t.is_singular(i),
                "transition_progress": t.transition_progress[i],
            })
        })
        .collect();
    let counters: serde_json::Map<_, _> = t
        .counters
        .entries()
        .iter()
        .map(|(k, v)| ((*k).to_owned(), serde_json::json!(v)))
        .collect();
    serde_json::json!({
        "stamp_ns": t.header.stamp_ns,
        "seq": t.header.seq,
        "mode": mode_name(t.mode),
        "levels": levels,
        "tau": t.tau(),
        "H": t.h,
        "load": {
            "mass": t.load_mass,
            "com": t.load_com,
            "progress": t.load_progress,
        },
        "contact": t.contact(),
        "contact_hold": t.contact_hold(),
        "tau_ext": t.tau_ext(),
        "tau_ext_max": largest_external_torque(t).0,
        "tau_ext_max_joint": largest_external_torque(t).1,
        "counters": counters,
        "compute_ns": t.timings.compute_ns,
        "wakeup_latency_ns": t.timings.wakeup_latency_ns,
    })
}

/// The load the controller's model carries, and its ramp while one runs.
fn load_line(t: &Telemetry) -> String {
    let c = t.load_com;
    let ramp = if t.load_progress < 1.0 {
        format!(" (announcing: {:.0} % ramped)", 100.0 * t.load_progress)
    } else {
        String::new()
    };
    format!(
        "load {:.3} kg at ({:.3}, {:.3}, {:.3}) m in the tip frame{ramp}\n",
        t.load_mass, c[0], c[1], c[2]
    )
}

fn table(t: &Telemetry, names: &[String]) -> String {
    let mut s = format!(
        "seq {}  mode {}  compute {:.1} µs  latency {:.1} µs\n",
        t.header.seq,
        mode_name(t.mode),
        t.timings.compute_ns as f64 * 1e-3,
        t.timings.wakeup_latency_ns as f64 * 1e-3
    );
    let width = (0..t.levels())
        .map(|i| level_name(names, i).chars().count() + 4)
        .max()
        .unwrap_or(6)
        .max(6);
    s += &format!(
        "{:<width$} |error|      storage      V in H       tank (J)     valve  progress  singular  goal\n",
        "level"
    );
    for i in 0..t.levels() {
        let e = t.task_error(i);
        let label = if names.get(i).is_some() {
            format!("{} {}", i + 1, level_name(names, i))
        } else {
            (i + 1).to_string()
        };
        s += &format!(
            "{:<width$} {:<12.3e} {:<12.3e} {:<12.3e} {:<12.3e} {:<6.3} {:<9.2} {:<9} {:?}\n",
            label,
            e.iter().map(|x| x * x).sum::<f64>().sqrt(),
            t.storage[i],
            t.potential[i],
            t.tank[i],
            t.tank_valve[i],
            t.transition_progress[i],
            t.is_singular(i),
            t.goal(i)
        );
    }
    s += &format!("storage H {:.4} J (arm and controller)\n", t.h);
    s += &load_line(t);
    let (r_max, joint) = largest_external_torque(t);
    s += &format!(
        "contact {}  max |tau_ext| {:.3} N·m (joint {}){}\n",
        if t.contact() { "YES" } else { "no" },
        r_max,
        joint,
        if t.contact_hold() {
            "  HOLD (gravity and damping; a setpoint releases it)"
        } else {
            ""
        }
    );
    let c: &TelemetryCounters = &t.counters;
    s += &format!(
        "cycles {}  saturated {}  rate-limited {}  velocity-limited {} (largest {:.3} N·m)  singular {}  invalid {}  missed {}\n",
        c.cycles,
        c.saturations,
        c.rate_limited,
        c.velocity_limited,
        c.velocity_limit_max_correction_mnm as f64 * 1e-3,
        c.singular_cycles,
        c.invalid_states,
        c.missed_states
    );
    s
}

/// `hcc monitor`: reads the controller's telemetry (never writes to it).
pub fn monitor(args: MonitorArgs) -> anyhow::Result<()> {
    if !(args.rate.is_finite() && args.rate > 0.0) {
        bail!("--rate must be positive");
    }
    let (names, dims) = config_levels(args.config.as_deref(), &args.target)?;
    let mut client = connect(&args.target)?;
    let wait = timeout(&args.target)?;
    let every = Duration::from_secs_f64(1.0 / args.rate);
    let clear = !args.json && std::io::stdout().is_terminal();
    let mut out = std::io::stdout().lock();
    let mut shown = 0u64;
    let mut last_seq = None;
    let mut heard = Instant::now();
    while args.count.is_none_or(|k| shown < k) {
        let sample = client.poll_telemetry().copied();
        match sample.filter(|t| Some(t.header.seq) != last_seq) {
            Some(t) => {
                if last_seq.is_none() {
                    check_names(&names, &dims, &t)?;
                }
                last_seq = Some(t.header.seq);
                heard = Instant::now();
                if args.json {
                    writeln!(out, "{}", sample_json(&t, &names))?;
                } else {
                    if clear {
                        write!(out, "\x1b[2J\x1b[H")?;
                    }
                    write!(out, "{}", table(&t, &names))?;
                }
                out.flush()?;
                shown += 1;
                std::thread::sleep(every);
            }
            None if heard.elapsed() > wait => {
                bail!(
                    "no telemetry from namespace {:?} within {:.1} s (is hcc-controller running?)",
                    args.target.namespace,
                    wait.as_secs_f64()
                )
            }
            None => std::thread::sleep(Duration::from_millis(2)),
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use hcc_msgs::{TELEMETRY_FLAG_CONTACT, TELEMETRY_FLAG_CONTACT_HOLD};

    /// A 4-joint sample of two levels with r = (0.5, −3.25, 1, 0).
    fn sample(contact: bool) -> Box<Telemetry> {
        let mut t = Box::new(Telemetry::zeroed());
        t.set_shape(4, &[2, 2]).unwrap();
        t.tau_ext[..4].copy_from_slice(&[0.5, -3.25, 1.0, 0.0]);
        if contact {
            t.flags |= TELEMETRY_FLAG_CONTACT;
        }
        t
    }

    #[test]
    fn the_json_carries_the_contact_flag_and_the_largest_external_torque() {
        for contact in [false, true] {
            let v = sample_json(&sample(contact), &[]);
            assert_eq!(v["contact"], contact);
            assert_eq!(v["tau_ext_max"], 3.25);
            assert_eq!(v["tau_ext_max_joint"], 2);
            assert_eq!(v["tau_ext"], serde_json::json!([0.5, -3.25, 1.0, 0.0]));
        }
    }

    #[test]
    fn the_table_shows_the_contact_flag_and_the_largest_external_torque() {
        let quiet = table(&sample(false), &[]);
        assert!(
            quiet.contains("contact no  max |tau_ext| 3.250 N·m (joint 2)"),
            "{quiet}"
        );
        let pushed = table(&sample(true), &[]);
        assert!(
            pushed.contains("contact YES  max |tau_ext| 3.250 N·m"),
            "{pushed}"
        );
        assert!(!pushed.contains("HOLD"), "{pushed}");
        let mut held = sample(true);
        held.flags |= TELEMETRY_FLAG_CONTACT_HOLD;
        assert!(table(&held, &[]).contains("HOLD"));
        assert_eq!(sample_json(&held, &[])["contact_hold"], true);
    }

    #[test]
    fn the_load_and_its_ramp_are_shown() {
        let mut t = sample(false);
        assert!(
            table(&t, &[]).contains("load 0.000 kg at (0.000, 0.000, 0.000) m in the tip frame\n")
        );
        t.load_mass = 0.25;
        t.load_com = [0.0, 0.0, 0.1];
        t.load_progress = 0.5;
        let s = table(&t, &[]);
        assert!(
            s.contains("load 0.250 kg at (0.000, 0.000, 0.100) m in the tip frame (announcing: 50 % ramped)"),
            "{s}"
        );
        let v = sample_json(&t, &[]);
        assert_eq!(
            v["load"],
            serde_json::json!({"mass": 0.25, "com": [0.0, 0.0, 0.1], "progress": 0.5})
        );
    }
}
