//! `hcc replay FILE.mcap [--config FILE]`: feeds the recorded joint states
//! and setpoints through the control cycle again — the code the controller
//! daemon runs each cycle ([`hcc_cycle::ControlCycle`]: stream checks, the
//! law of eq. 19, the torque filter, saturation), in process, see
//! [`hcc_replay::replay`] — and compares its torque commands with the recorded
//! ones, bit for bit.
//!
//! For a recording of the same build and scenario every torque is
//! bit-identical; otherwise the first differing cycle and joint are printed
//! and the exit status is non-zero. A regression tool (does a change alter
//! the torques?) and the proof that the loop is deterministic.

use anyhow::bail;
use hcc_cycle::Answer;
use hcc_record::mcap_log;
use hcc_replay::derive;
use hcc_replay::replay::{Replayed, replay_file};
use std::path::PathBuf;

#[derive(clap::Args, Debug)]
pub struct ReplayArgs {
    /// The recording (from `hcc run`, `hcc record` or `hcc simulate`).
    pub recording: PathBuf,
    /// The scenario the controller ran (default: the one the recording names).
    #[arg(long)]
    pub config: Option<PathBuf>,
}

/// Where the replay differs from the recording.
struct Difference {
    cycle: u64,
    state_seq: u64,
    what: String,
}

/// The comparison of replayed and recorded commands.
#[derive(Default)]
struct Comparison {
    compared: u64,
    /// Cycles at the end whose inputs the recording does not hold.
    incomplete: u64,
    /// The cycle the comparison started at (the first whose inputs the
    /// recording holds).
    first_cycle: Option<u64>,
    first_difference: Option<Difference>,
}

impl Comparison {
    /// Compares one cycle; whether to go on.
    fn cycle(&mut self, r: &Replayed<'_>, n: usize) -> anyhow::Result<bool> {
        let tel = r.telemetry;
        if r.before_recording {
            // The recording started mid-run (module `replay`): counted there.
            return Ok(true);
        }
        self.first_cycle.get_or_insert(tel.header.seq);
        let inputs = (r.state, r.recorded, r.answer);
        let (Some(state), Some(recorded), Some(answer), 0) =
            (inputs.0, inputs.1, inputs.2, r.setpoints_missing)
        else {
            if r.at_end {
                self.incomplete += 1;
                return Ok(true);
            }
            let what = match inputs {
                (None, ..) => "joint state",
                (_, None, _) => "command",
                _ => "setpoint",
            };
            bail!(
                "cycle {}: its {what} is not in the recording (a gap): cannot replay further ({} cycles compared)",
                tel.header.seq,
                self.compared
            );
        };
        let mut differ = |what: String| {
            self.first_difference = Some(Difference {
                cycle: tel.header.seq,
                state_seq: state.header.seq,
                what,
            });
            Ok(false)
        };
        let Answer::Command(mode) = answer else {
            return differ(
                "the replay took the state for a duplicate and did not answer it".into(),
            );
        };
        let replayed = r.cycle.command();
        if recorded.mode != mode.code() {
            return differ(format!(
                "mode: recorded {}, replayed {}",
                mcap_log::mode_name(recorded.mode),
                mcap_log::mode_name(mode.code())
            ));
        }
        let (a, b) = (recorded.tau(), replayed.tau());
        if a.len() != n || b.len() != n {
            bail!(
                "cycle {}: commands of {} and {} joints",
                tel.header.seq,
                a.len(),
                b.len()
            );
        }
        if let Some(j) = (0..n).find(|&j| a[j].to_bits() != b[j].to_bits()) {
            return differ(format!(
                "joint {}: recorded τ = {:e} N·m, replayed {:e} N·m (difference {:e})",
                j + 1,
                a[j],
                b[j],
                b[j] - a[j]
            ));
        }
        self.compared += 1;
        Ok(true)
    }
}

pub fn run(args: ReplayArgs) -> anyhow::Result<()> {
    let scenario = derive::scenario_of(&args.recording, args.config.as_deref())?;
    let n = scenario.model.nq();
    let period = scenario.period_s();
    let mut cmp = Comparison::default();
    let read = replay_file(&args.recording, &scenario, &mut |r| cmp.cycle(r, n))?;
    let counts = read.counts;
    if let Some(reason) = &read.truncated {
        println!(
            "note: {} is truncated ({reason}); replayed up to its last complete chunk",
            args.recording.display()
        );
    }
    if let Some(d) = &cmp.first_difference {
        println!(
            "replay differs from the recording at cycle {} (joint state {}, t = {:.3} s) after {} identical cycles: {}",
            d.cycle,
            d.state_seq,
            d.state_seq as f64 * period,
            cmp.compared,
            d.what
        );
        bail!("the replayed torques differ from the recorded ones");
    }
    if cmp.incomplete > 0 {
        println!(
            "note: the last {} cycles lack their joint state, command or setpoints in the recording; replayed up to them",
            cmp.incomplete
        );
    }
    if counts.cycles_before_recording > 0 || counts.setpoints_before_first_cycle > 0 {
        println!(
            "note: the recording starts mid-run: cycles answering a state or command from before it: {}, setpoints recorded but answered before its first cycle: {}; replayed from cycle {}",
            counts.cycles_before_recording,
            counts.setpoints_before_first_cycle,
            cmp.first_cycle.map_or("-".to_string(), |c| c.to_string())
        );
    }
    if counts.setpoints_dropped_at_restart + counts.samples_dropped_at_restart > 0 {
        println!(
            "note: at the controller restarts: setpoints sent to the old controller and not taken again {}, samples of a restart too close to the previous one not replayed {}",
            counts.setpoints_dropped_at_restart, counts.samples_dropped_at_restart
        );
    }
    if cmp.compared == 0 {
        bail!(
            "{} holds no controller cycle to replay",
            args.recording.display()
        );
    }
    println!(
        "replayed {} cycles of {} ({} setpoints, {} path messages, {} load messages, {} stale events, {} driver restarts, {} controller restarts): every torque bit-identical to the recording",
        cmp.compared,
        args.recording.display(),
        counts.setpoints_taken,
        counts.paths_taken,
        counts.loads_taken,
        counts.stale,
        counts.driver_restarts,
        counts.controller_restarts
    );
    Ok(())
}
