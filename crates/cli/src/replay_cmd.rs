//! `hcc replay FILE.mcap [--config FILE]`: feeds the recorded joint states
//! and setpoints through the control cycle again — the code the controller
//! daemon runs each cycle ([`hcc_cycle::ControlCycle`]: stream checks, the
//! law of eq. 19, the torque filter, saturation), in process, see
//! [`hcc_replay::replay`] — and compares (`hcc_replay::compare`) its torque commands with the recorded
//! ones, bit for bit.
//!
//! For a recording of the same build and scenario every torque is
//! bit-identical; otherwise the first differing cycle and joint are printed
//! and the exit status is non-zero. A regression tool (does a change alter
//! the torques?) and the proof that the loop is deterministic.

use anyhow::bail;
use hcc_replay::compare::compare_file;
use hcc_replay::derive;
use std::path::PathBuf;

#[derive(clap::Args, Debug)]
pub struct ReplayArgs {
    /// The recording (from `hcc run`, `hcc record` or `hcc simulate`).
    pub recording: PathBuf,
    /// The scenario the controller ran (default: the one the recording names).
    #[arg(long)]
    pub config: Option<PathBuf>,
}

pub fn run(args: ReplayArgs) -> anyhow::Result<()> {
    let scenario = derive::scenario_of(&args.recording, args.config.as_deref())?;
    let period = scenario.period_s();
    let cmp = compare_file(&args.recording, &scenario)?;
    let read = &cmp.replay;
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
