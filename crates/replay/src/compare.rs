//! A recording's commands against its replay, bit for bit ([`compare_file`],
//! what `hcc replay` prints): every cycle whose inputs the recording holds is
//! replayed through the control cycle ([`crate::replay`]) and its command's
//! mode and torques compared with the recorded ones to the last bit; the
//! comparison stops at the first difference. A cycle whose state, command or
//! setpoints the recording lacks (a gap) ends it with an error, but at the
//! end of the file, where it is counted as incomplete.

use anyhow::bail;
use hcc_config::Scenario;
use hcc_cycle::Answer;
use hcc_record::mcap_log;
use std::path::Path;

use crate::replay::{FileReplay, Replayed, replay_file};

/// Where the replay differs from the recording.
#[derive(Debug, Clone)]
pub struct Difference {
    /// The cycle (its telemetry's sequence number).
    pub cycle: u64,
    /// The joint state it answered.
    pub state_seq: u64,
    /// What differs, in words.
    pub what: String,
}

/// The comparison of replayed and recorded commands.
#[derive(Debug, Default)]
pub struct Comparison {
    /// Cycles compared, every torque bit-identical.
    pub compared: u64,
    /// Cycles at the end whose inputs the recording does not hold.
    pub incomplete: u64,
    /// The cycle the comparison started at (the first whose inputs the
    /// recording holds).
    pub first_cycle: Option<u64>,
    /// The first cycle whose replay differs (the comparison stops there).
    pub first_difference: Option<Difference>,
    /// The replay's counts and whether the file ends early.
    pub replay: FileReplay,
}

impl Comparison {
    /// Compares one cycle; whether to go on.
    pub fn cycle(&mut self, r: &Replayed<'_>, n: usize) -> anyhow::Result<bool> {
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

/// Replays the recording at `path` (made with `scenario`) and compares every
/// command with the recorded one ([`Comparison::cycle`]).
pub fn compare_file(path: &Path, scenario: &Scenario) -> anyhow::Result<Comparison> {
    let n = scenario.model.nq();
    let mut cmp = Comparison::default();
    let done = replay_file(path, scenario, &mut |r| cmp.cycle(r, n))?;
    cmp.replay = done;
    Ok(cmp)
}
