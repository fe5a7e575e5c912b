//! `hcc replay FILE.mcap [--config FILE]`: feeds the recorded joint states
//! and setpoints through the controller's decision again — the same code
//! the daemon runs each cycle ([`hcc_controller::Decider`]: validation,
//! sequence, the law of eq. 19, the output stages, saturation), in process
//! — and compares its torque commands with the recorded ones, bit for bit.
//!
//! The recording says which state each cycle consumed (`telemetry.state_seq`),
//! when it woke (`state.stamp_ns + telemetry.timings.wakeup_latency_ns`,
//! which the sequence plausibility uses), which setpoints it took (the
//! answers counted in its telemetry), and where the controller reported a
//! lost peer (a stale telemetry sample): the replay repeats exactly that.
//! For a recording of the same build and scenario every torque is
//! bit-identical; otherwise the first differing cycle and joint are printed
//! and the exit status is non-zero. A regression tool (does a change alter
//! the torques?) and the proof that the loop is deterministic.

use anyhow::{Context, anyhow, bail};
use hcc_control::Controller;
use hcc_controller::{Answer, CycleSettings, Decider};
use hcc_msgs::{JointState, Setpoint, TELEMETRY_FLAG_PEER_LOST, Telemetry, TorqueCommand};
use hcc_record::mcap_log::{self, Entry};
use std::collections::{BTreeMap, VecDeque};
use std::path::PathBuf;

use crate::derive;

#[derive(clap::Args, Debug)]
pub struct ReplayArgs {
    /// The recording (from `hcc run` or `hcc record`).
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

/// The replay state.
struct Replay {
    decider: Decider,
    n: usize,
    period: f64,
    /// Recorded states not yet consumed (seq ascending).
    states: VecDeque<JointState>,
    /// Recorded commands by their seq, not yet compared.
    commands: BTreeMap<u64, TorqueCommand>,
    /// Recorded setpoints per client, not yet taken.
    setpoints: BTreeMap<u64, VecDeque<Setpoint>>,
    /// Setpoints answered per client so far, as the telemetry counts them.
    answered: BTreeMap<u64, u64>,
    /// Telemetry waiting for its state (or its setpoints) to be read.
    pending: VecDeque<Box<Telemetry>>,
    last_state_seq: Option<u64>,
    cycles: u64,
    compared: u64,
    stale: u64,
    setpoints_taken: u64,
    /// Cycles at the end whose inputs the recording does not hold.
    incomplete: u64,
    first_difference: Option<Difference>,
}

impl Replay {
    /// Replays the pending cycles whose inputs have been read (all with `flush`).
    fn advance(&mut self, flush: bool) -> anyhow::Result<()> {
        while let Some(tel) = self.pending.front() {
            let stale = tel.flags & TELEMETRY_FLAG_PEER_LOST != 0;
            if !stale && !self.inputs_read(tel, flush) {
                if !flush {
                    // The cycle's command or setpoints come later in the file
                    // (the streams are drained one after the other).
                    break;
                }
                // The recording ends (or has a gap) before them.
                self.incomplete = self.pending.len() as u64;
                self.pending.clear();
                break;
            }
            let Some(tel) = self.pending.pop_front() else {
                break;
            };
            if stale {
                let _ = self.decider.stale(tel.header.stamp_ns);
                self.stale += 1;
                continue;
            }
            self.take_setpoints(&tel)?;
            self.cycle(&tel)?;
            if self.first_difference.is_some() {
                return Ok(());
            }
        }
        Ok(())
    }

    /// Whether the inputs of `tel`'s cycle have been read: a later state
    /// (so its own state is in; at the end of the file, its own state), its
    /// command, and the setpoints it answered.
    fn inputs_read(&self, tel: &Telemetry, end: bool) -> bool {
        self.last_state_seq
            .is_some_and(|s| s > tel.state_seq || (end && s == tel.state_seq))
            && self.commands.contains_key(&tel.command_seq)
            && tel.setpoint_answers.iter().all(|a| {
                let before = self.answered.get(&a.client_id).copied().unwrap_or(0);
                let queued = self
                    .setpoints
                    .get(&a.client_id)
                    .map_or(0, |q| q.len() as u64);
                a.answered <= before + queued
            })
    }

    /// Takes the setpoints the controller took in the cycle of `tel`.
    fn take_setpoints(&mut self, tel: &Telemetry) -> anyhow::Result<()> {
        for a in tel.setpoint_answers.iter().filter(|a| a.answered > 0) {
            let before = self.answered.get(&a.client_id).copied().unwrap_or(0);
            for _ in before..a.answered {
                let s = self
                    .setpoints
                    .get_mut(&a.client_id)
                    .and_then(|q| q.pop_front())
                    .ok_or_else(|| {
                        anyhow!(
                            "cycle {}: the controller answered a setpoint of client {} that the recording does not hold",
                            tel.header.seq,
                            a.client_id
                        )
                    })?;
                self.decider.take_setpoint(&s);
                self.setpoints_taken += 1;
            }
            self.answered.insert(a.client_id, a.answered.max(before));
        }
        Ok(())
    }

    /// Decides the state of `tel`'s cycle and compares the command.
    fn cycle(&mut self, tel: &Telemetry) -> anyhow::Result<()> {
        let want = tel.state_seq;
        while self.states.front().is_some_and(|s| s.header.seq < want) {
            self.states.pop_front();
        }
        let state = match self.states.front() {
            Some(s) if s.header.seq == want => *s,
            _ => bail!(
                "cycle {}: its joint state {want} is not in the recording (a gap): cannot replay further ({} cycles compared)",
                tel.header.seq,
                self.compared
            ),
        };
        let wake = state
            .header
            .stamp_ns
            .saturating_add_signed(tel.timings.wakeup_latency_ns);
        self.cycles += 1;
        let answer = self.decider.decide(&state, wake);
        let differ = |what: String| Difference {
            cycle: tel.header.seq,
            state_seq: want,
            what,
        };
        let Answer::Command(mode) = answer else {
            self.first_difference = Some(differ(
                "the replay took the state for a duplicate and did not answer it".into(),
            ));
            return Ok(());
        };
        let Some(recorded) = self.commands.remove(&tel.command_seq) else {
            bail!(
                "cycle {}: its command {} is not in the recording (a gap)",
                tel.header.seq,
                tel.command_seq
            );
        };
        self.commands = self.commands.split_off(&tel.command_seq);
        let replayed = self.decider.command();
        if recorded.mode != mode.code() {
            self.first_difference = Some(differ(format!(
                "mode: recorded {}, replayed {}",
                mcap_log::mode_name(recorded.mode),
                mcap_log::mode_name(mode.code())
            )));
            return Ok(());
        }
        let (a, b) = (recorded.tau(), replayed.tau());
        if a.len() != self.n || b.len() != self.n {
            bail!(
                "cycle {}: commands of {} and {} joints",
                tel.header.seq,
                a.len(),
                b.len()
            );
        }
        if let Some(j) = (0..self.n).find(|&j| a[j].to_bits() != b[j].to_bits()) {
            self.first_difference = Some(differ(format!(
                "joint {}: recorded τ = {:e} N·m, replayed {:e} N·m (difference {:e})",
                j + 1,
                a[j],
                b[j],
                b[j] - a[j]
            )));
            return Ok(());
        }
        self.compared += 1;
        Ok(())
    }
}

pub fn run(args: ReplayArgs) -> anyhow::Result<()> {
    let scenario = derive::scenario_of(&args.recording, args.config.as_deref())?;
    let controller = Controller::new(&scenario.model, scenario.spec.clone(), &scenario.q0)
        .map_err(|e| anyhow!("{}: controller: {e}", scenario.path.display()))?;
    let settings = CycleSettings::from_scenario(&scenario);
    let decider = Decider::new(controller, &settings)
        .with_context(|| format!("the controller of {}", scenario.path.display()))?;
    let mut r = Replay {
        decider,
        n: scenario.model.nq(),
        period: 1.0 / scenario.simulation.control_rate_hz,
        states: VecDeque::new(),
        commands: BTreeMap::new(),
        setpoints: BTreeMap::new(),
        answered: BTreeMap::new(),
        pending: VecDeque::new(),
        last_state_seq: None,
        cycles: 0,
        compared: 0,
        stale: 0,
        setpoints_taken: 0,
        incomplete: 0,
        first_difference: None,
    };
    let path = args.recording.clone();
    let bad = |e: String| anyhow!("{}: {e}", path.display());
    let read = mcap_log::read::<anyhow::Error>(&args.recording, |_, entry| {
        if r.first_difference.is_some() {
            return Ok(());
        }
        match entry {
            Entry::JointState(s) => {
                let s = s.to_msg().map_err(bad)?;
                // Keep the stream ascending (duplicates are not answered).
                if r.last_state_seq.is_none_or(|l| s.header.seq > l) {
                    r.last_state_seq = Some(s.header.seq);
                    r.states.push_back(s);
                }
            }
            Entry::TorqueCommand(c) => {
                let c = c.to_msg().map_err(bad)?;
                r.commands.insert(c.header.seq, c);
            }
            Entry::Telemetry(t) => r.pending.push_back(t.to_msg().map_err(bad)?),
            Entry::Setpoint(s) => {
                let s = s.to_msg().map_err(bad)?;
                r.setpoints.entry(s.client_id).or_default().push_back(s);
            }
            Entry::Recorder(_) | Entry::Metadata(..) => {}
        }
        r.advance(false)
    })?;
    if r.first_difference.is_none() {
        r.advance(true)?;
    }
    if let Some(reason) = &read.truncated {
        println!(
            "note: {} is truncated ({reason}); replayed up to its last complete chunk",
            args.recording.display()
        );
    }
    if let Some(d) = &r.first_difference {
        println!(
            "replay differs from the recording at cycle {} (joint state {}, t = {:.3} s) after {} identical cycles: {}",
            d.cycle,
            d.state_seq,
            d.state_seq as f64 * r.period,
            r.compared,
            d.what
        );
        bail!("the replayed torques differ from the recorded ones");
    }
    if r.incomplete > 0 {
        println!(
            "note: the last {} cycles lack their joint state, command or setpoints in the recording; replayed up to them",
            r.incomplete
        );
    }
    if r.compared == 0 {
        bail!(
            "{} holds no controller cycle to replay",
            args.recording.display()
        );
    }
    println!(
        "replayed {} cycles of {} ({} setpoints, {} stale events): every torque bit-identical to the recording",
        r.compared,
        args.recording.display(),
        r.setpoints_taken,
        r.stale
    );
    Ok(())
}
