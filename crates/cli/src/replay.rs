//! A recording's controller cycles, run through the control cycle again
//! ([`hcc_cycle::ControlCycle`], the code the controller daemon runs) in
//! process: `hcc replay` compares the replayed commands with the recorded
//! ones bit for bit; the derivation of a recording's results (`hcc run`,
//! `hcc plot FILE.mcap`, `hcc export`) reads the law's terms (J_i, J̄, V_i)
//! at each recorded state from it.
//!
//! The recording says which state each cycle consumed (`telemetry.state_seq`),
//! when it woke (`state.stamp_ns + telemetry.timings.wakeup_latency_ns`,
//! which the sequence plausibility uses), which setpoints it took (the
//! answers counted in its telemetry), and where the controller reported a
//! lost peer (a telemetry sample flagged `TELEMETRY_FLAG_PEER_LOST`): the
//! replay repeats exactly that. The streams are drained one after the other
//! into the file, so a cycle is replayed once its inputs have been read: a
//! later state, its command (or a later one: then its own was lost), and the
//! setpoints it answered. What the recording lacks (a state, a command, a
//! setpoint lost before the file) is counted and handed on, never guessed.

use std::collections::{BTreeMap, VecDeque};

use anyhow::anyhow;
use hcc_config::Scenario;
use hcc_control::Controller;
use hcc_cycle::{Answer, ControlCycle, CycleSettings};
use hcc_msgs::{JointState, Setpoint, TELEMETRY_FLAG_PEER_LOST, Telemetry, TorqueCommand};

/// What the replay counted.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct ReplayCounts {
    /// Cycles replayed (their state was in the recording).
    pub cycles: u64,
    /// Stale events repeated.
    pub stale: u64,
    /// Setpoints taken again.
    pub setpoints_taken: u64,
    /// Setpoints the controller answered that the recording does not hold.
    pub setpoints_missing: u64,
    /// Cycles whose state the recording does not hold (not replayed).
    pub states_missing: u64,
    /// Recorded states no cycle consumed (the controller skipped them).
    pub states_skipped: u64,
}

/// One cycle of the recording and its replay.
pub struct Replayed<'a> {
    /// The recorded telemetry of the cycle.
    pub telemetry: &'a Telemetry,
    /// The state it consumed (`None`: not in the recording; not replayed).
    pub state: Option<&'a JointState>,
    /// The recorded command (`None`: not in the recording).
    pub recorded: Option<&'a TorqueCommand>,
    /// The replay's answer (`None` when not replayed).
    pub answer: Option<Answer>,
    /// The replayed cycle after its step: its command, telemetry and law.
    pub cycle: &'a ControlCycle,
    /// Setpoints the controller took in this cycle that the recording does
    /// not hold (the replay went on without them).
    pub setpoints_missing: u64,
    /// Handed on at the end of the file, its inputs incomplete.
    pub at_end: bool,
}

/// The replay state (module docs).
pub struct Replay {
    cycle: ControlCycle,
    /// Recorded states not yet consumed (seq ascending).
    states: VecDeque<JointState>,
    /// Recorded commands by their seq, not yet handed on.
    commands: BTreeMap<u64, TorqueCommand>,
    /// The largest command seq read.
    last_command_seq: Option<u64>,
    /// Recorded setpoints per client, not yet taken.
    setpoints: BTreeMap<u64, VecDeque<Setpoint>>,
    /// Setpoints answered per client so far, as the telemetry counts them.
    answered: BTreeMap<u64, u64>,
    /// Telemetry waiting for its inputs to be read.
    pending: VecDeque<Box<Telemetry>>,
    last_state_seq: Option<u64>,
    counts: ReplayCounts,
}

impl Replay {
    /// The replay of recordings of `scenario`'s controller.
    pub fn new(scenario: &Scenario) -> anyhow::Result<Replay> {
        let controller = Controller::new(&scenario.model, scenario.spec.clone(), &scenario.q0)
            .map_err(|e| anyhow!("{}: controller: {e}", scenario.path.display()))?;
        let cycle = ControlCycle::new(controller, &CycleSettings::from_scenario(scenario))
            .map_err(|e| anyhow!("the controller of {}: {e}", scenario.path.display()))?;
        Ok(Replay {
            cycle,
            states: VecDeque::new(),
            commands: BTreeMap::new(),
            last_command_seq: None,
            setpoints: BTreeMap::new(),
            answered: BTreeMap::new(),
            pending: VecDeque::new(),
            last_state_seq: None,
            counts: ReplayCounts::default(),
        })
    }

    /// What was counted so far.
    pub fn counts(&self) -> ReplayCounts {
        self.counts
    }

    /// A recorded joint state (kept if it comes after the last one: a
    /// duplicate was not answered again).
    pub fn on_state(&mut self, s: JointState) {
        if self.last_state_seq.is_none_or(|l| s.header.seq > l) {
            self.last_state_seq = Some(s.header.seq);
            self.states.push_back(s);
        }
    }

    /// A recorded torque command.
    pub fn on_command(&mut self, c: TorqueCommand) {
        let seq = c.header.seq;
        self.last_command_seq = Some(self.last_command_seq.map_or(seq, |l| l.max(seq)));
        self.commands.insert(seq, c);
    }

    /// A recorded setpoint.
    pub fn on_setpoint(&mut self, s: Setpoint) {
        self.setpoints.entry(s.client_id).or_default().push_back(s);
    }

    /// A recorded telemetry sample (a cycle, or a stale event).
    pub fn on_telemetry(&mut self, t: Box<Telemetry>) {
        self.pending.push_back(t);
    }

    /// Replays the pending cycles whose inputs have been read (with `end`:
    /// all of them, the file being over), handing each to `each`, which
    /// returns whether to go on.
    pub fn advance(
        &mut self,
        end: bool,
        each: &mut dyn FnMut(&Replayed<'_>) -> anyhow::Result<bool>,
    ) -> anyhow::Result<bool> {
        while let Some(tel) = self.pending.front() {
            if tel.flags & TELEMETRY_FLAG_PEER_LOST != 0 {
                let stamp = tel.header.stamp_ns;
                self.pending.pop_front();
                let _ = self.cycle.stale(stamp);
                self.counts.stale += 1;
                continue;
            }
            let complete = self.inputs_read(tel);
            if !complete && !end {
                // The cycle's state, command or setpoints come later in the file.
                return Ok(true);
            }
            let Some(tel) = self.pending.pop_front() else {
                break;
            };
            if !self.replay(&tel, !complete, each)? {
                return Ok(false);
            }
        }
        if end {
            self.counts.states_skipped += self.states.len() as u64;
            self.states.clear();
        }
        Ok(true)
    }

    /// Whether the inputs of `tel`'s cycle have been read: a later state (so
    /// its own is in), its command or a later one, and the setpoints it
    /// answered.
    fn inputs_read(&self, tel: &Telemetry) -> bool {
        self.last_state_seq.is_some_and(|s| s > tel.state_seq)
            && self.last_command_seq.is_some_and(|c| c >= tel.command_seq)
            && tel.setpoint_answers.iter().all(|a| {
                let before = self.answered.get(&a.client_id).copied().unwrap_or(0);
                let queued = self
                    .setpoints
                    .get(&a.client_id)
                    .map_or(0, |q| q.len() as u64);
                a.answered <= before + queued
            })
    }

    /// Replays the cycle of `tel`: its setpoints, its state; hands it on.
    fn replay(
        &mut self,
        tel: &Telemetry,
        at_end: bool,
        each: &mut dyn FnMut(&Replayed<'_>) -> anyhow::Result<bool>,
    ) -> anyhow::Result<bool> {
        let setpoints_missing = self.take_setpoints(tel);
        let want = tel.state_seq;
        while self.states.front().is_some_and(|s| s.header.seq < want) {
            self.states.pop_front();
            self.counts.states_skipped += 1;
        }
        let state = match self.states.front() {
            Some(s) if s.header.seq == want => self.states.pop_front(),
            _ => None,
        };
        let answer = state.map(|s| {
            let wake = s
                .header
                .stamp_ns
                .saturating_add_signed(tel.timings.wakeup_latency_ns);
            self.counts.cycles += 1;
            self.cycle.decide(&s, wake)
        });
        if state.is_none() {
            self.counts.states_missing += 1;
        }
        let recorded = self.commands.remove(&tel.command_seq);
        // Commands of earlier cycles are not needed any more.
        self.commands = self.commands.split_off(&tel.command_seq);
        each(&Replayed {
            telemetry: tel,
            state: state.as_ref(),
            recorded: recorded.as_ref(),
            answer,
            cycle: &self.cycle,
            setpoints_missing,
            at_end,
        })
    }

    /// Takes the setpoints the controller took in the cycle of `tel` (the
    /// increase of each client's answer count), in the order they were sent;
    /// returns how many of them the recording lacks.
    fn take_setpoints(&mut self, tel: &Telemetry) -> u64 {
        let mut missing = 0;
        for a in tel.setpoint_answers.iter().filter(|a| a.answered > 0) {
            let before = self.answered.get(&a.client_id).copied().unwrap_or(0);
            for _ in before..a.answered {
                match self
                    .setpoints
                    .get_mut(&a.client_id)
                    .and_then(|q| q.pop_front())
                {
                    Some(s) => {
                        self.cycle.take_setpoint_now(&s);
                        self.counts.setpoints_taken += 1;
                    }
                    None => missing += 1,
                }
            }
            self.answered.insert(a.client_id, a.answered.max(before));
        }
        self.counts.setpoints_missing += missing;
        missing
    }
}
