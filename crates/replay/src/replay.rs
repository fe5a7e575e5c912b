//! A recording's controller cycles, run through the control cycle again
//! ([`hcc_cycle::ControlCycle`], the code the controller daemon runs) in
//! process: `hcc replay` compares the replayed commands with the recorded
//! ones bit for bit; the derivation of a recording's results (`hcc run`,
//! `hcc plot FILE.mcap`, `hcc export`) reads the law's terms (J_i, J̄, V_i)
//! at each recorded state from it.
//!
//! The recording says which state each cycle consumed (`telemetry.state_seq`,
//! and the state's stamp that its command echoes: the two tell a restarted
//! driver's states from the old one's, whose sequence numbers start again),
//! when it woke (`state.stamp_ns + telemetry.timings.wakeup_latency_ns`,
//! which the sequence plausibility uses), which setpoints and path messages
//! it took (the answers counted in its telemetry: a client numbers both
//! together; the cycle takes its setpoints, then its paths, as the daemon
//! does), and where the controller reported a
//! lost peer (a telemetry sample flagged `TELEMETRY_FLAG_PEER_LOST`): the
//! replay repeats exactly that. The streams are drained one after the other
//! into the file, so a cycle is replayed once its inputs have been read: its
//! command (or a later one: then its own was lost), its state or a later one
//! (by the stamp the command echoes; without the command, a later seq), and
//! the setpoints it answered. What the recording lacks (a state, a command, a
//! setpoint lost before the file) is counted and handed on, never guessed.
//!
//! A recording attached to a running controller (`hcc record`) starts
//! mid-run, and its subscribers connect one by one: its first cycles may
//! have consumed a state or answered with a command that was published
//! before the recorder heard that stream (seq below the first recorded one).
//! Those cycles are handed on marked [`Replayed::before_recording`] and
//! counted, not replayed; the replay starts at the first cycle whose inputs
//! the file holds.
//!
//! A restarted driver (its states numbered from the start again) is
//! followed: the states are matched by seq and stamp. A restarted
//! controller (its commands and telemetry numbered from the start again)
//! is followed too: once the first controller's cycles are replayed, a
//! fresh control cycle of the same scenario takes over, as the new
//! controller did ([`ReplayCounts::controller_restarts`]). The setpoints
//! still queued then were sent to the old controller (the new one never
//! receives what was published before it subscribed): they are dropped and
//! counted. A new controller of another scenario shows as a difference.

use std::collections::{BTreeMap, VecDeque};

use anyhow::anyhow;
use hcc_config::Scenario;
use hcc_cycle::{Answer, ControlCycle, CycleSettings};
use hcc_msgs::{
    ClientMessage, JointState, KnotsRefusal, LoadSetpoint, PathKnots, PathRejection, Setpoint,
    SetpointAnswer, TELEMETRY_FLAG_PEER_LOST, Telemetry, TorqueCommand,
};

/// What [`replay_file`] went through.
#[derive(Debug, Clone, Default)]
pub struct FileReplay {
    /// The replay's counts.
    pub counts: ReplayCounts,
    /// Why the file ends early (the recorder was killed: replayed up to its
    /// last complete chunk), or `None` for a complete file.
    pub truncated: Option<String>,
}

/// Replays the recording at `path`, made with `scenario`: reads it in file
/// order, feeds every state, command, telemetry sample and client message
/// to a [`Replay`] and hands each replayed cycle to `each`, which returns
/// whether to go on. Allocates (it reads a file).
pub fn replay_file(
    path: &std::path::Path,
    scenario: &Scenario,
    each: &mut dyn FnMut(&Replayed<'_>) -> anyhow::Result<bool>,
) -> anyhow::Result<FileReplay> {
    use hcc_record::mcap_log::{self, Entry};
    let mut replay = Replay::new(scenario)?;
    let mut going = true;
    let bad = |e: String| anyhow!("{}: {e}", path.display());
    let read = mcap_log::read::<anyhow::Error>(path, |_, entry| {
        if !going {
            return Ok(());
        }
        match entry {
            Entry::JointState(s) => replay.on_state(s.to_msg().map_err(bad)?),
            Entry::TorqueCommand(c) => replay.on_command(c.to_msg().map_err(bad)?),
            Entry::Telemetry(t) => replay.on_telemetry(t.to_msg().map_err(bad)?),
            Entry::Setpoint(s) => replay.on_setpoint(s.to_msg().map_err(bad)?),
            Entry::Path(p) => replay.on_path(p.to_msg().map_err(bad)?),
            Entry::Load(l) => replay.on_load(l.to_msg().map_err(bad)?),
            Entry::Recorder(_) | Entry::Metadata(..) => {}
        }
        going = replay.advance(false, each)?;
        Ok(())
    })?;
    if going {
        replay.advance(true, each)?;
    }
    Ok(FileReplay {
        counts: replay.counts(),
        truncated: read.truncated,
    })
}

/// The most telemetry samples held back waiting for their inputs. The
/// recorder drains at most [`hcc_msgs::ipc::MAX_SUBSCRIBER_BUFFER`] samples of
/// a stream at a time, so a cycle's inputs follow it within a drain or two;
/// one still incomplete this many samples later was lost before the file,
/// and the cycle is handed on without it (a bounded memory, whatever the
/// recording's length).
pub const MAX_PENDING: usize = 4096;

/// What the replay counted.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct ReplayCounts {
    /// Cycles replayed (their state was in the recording).
    pub cycles: u64,
    /// Stale events repeated.
    pub stale: u64,
    /// Setpoints taken again.
    pub setpoints_taken: u64,
    /// Path messages taken again.
    pub paths_taken: u64,
    /// Load messages taken again.
    pub loads_taken: u64,
    /// Setpoints the controller answered that the recording does not hold.
    pub setpoints_missing: u64,
    /// Recorded setpoints answered before the first replayed cycle (history
    /// of a recording that starts mid-run; not taken again).
    pub setpoints_before_first_cycle: u64,
    /// Cycles whose state the recording does not hold (not replayed).
    pub states_missing: u64,
    /// Recorded states no cycle consumed (the controller skipped them).
    pub states_skipped: u64,
    /// Times the state stream started again below its last sequence number
    /// (a restarted or replaced driver).
    pub driver_restarts: u64,
    /// Times the controller's commands and telemetry were numbered again
    /// from below (a restarted controller; a fresh control cycle took over).
    pub controller_restarts: u64,
    /// Setpoints still queued at a controller restart (sent to the old
    /// controller; not taken again).
    pub setpoints_dropped_at_restart: u64,
    /// Commands and telemetry of a further controller restart that came
    /// before the replay reached the previous one (not replayed).
    pub samples_dropped_at_restart: u64,
    /// Recorded states dropped unconsumed to bound the memory (more than
    /// [`MAX_PENDING`] · 2 waiting: no cycle will consume them).
    pub states_dropped: u64,
    /// Cycles at the start whose state or command was published before the
    /// recorder heard that stream (not replayed).
    pub cycles_before_recording: u64,
    /// Recorded states older than the first recorded cycle's (their cycles
    /// were over before the recorder heard the telemetry).
    pub states_before_first_cycle: u64,
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
    /// A cycle at the start of a recording that began mid-run: its state or
    /// command precedes the first recorded one (module docs); not replayed.
    pub before_recording: bool,
}

impl Replayed<'_> {
    /// The replay's command of this cycle (`None` when the replay did not
    /// answer with one: not replayed, or the state taken for a duplicate).
    pub fn replayed_command(&self) -> Option<&TorqueCommand> {
        matches!(self.answer, Some(Answer::Command(_))).then(|| self.cycle.command())
    }
}

/// A client's setpoints answered so far (count, last seq).
#[derive(Debug, Clone, Copy)]
struct Answered {
    count: u64,
    seq: u64,
}

/// One controller's commands and telemetry, as read (each numbered +1 per
/// message from its start).
#[derive(Default)]
struct ControllerStreams {
    /// Recorded commands by their seq, not yet handed on.
    commands: BTreeMap<u64, TorqueCommand>,
    /// The first and the largest command seq read.
    first_command_seq: Option<u64>,
    last_command_seq: Option<u64>,
    /// Telemetry waiting for its inputs to be read.
    pending: VecDeque<Box<Telemetry>>,
    /// The last telemetry seq read.
    last_telemetry_seq: Option<u64>,
}

impl ControllerStreams {
    /// Whether `seq` continues the command stream (else it is a restarted
    /// controller's).
    fn continues_commands(&self, seq: u64) -> bool {
        self.last_command_seq.is_none_or(|l| seq > l)
    }

    /// Whether `seq` continues the telemetry stream.
    fn continues_telemetry(&self, seq: u64) -> bool {
        self.last_telemetry_seq.is_none_or(|l| seq > l)
    }

    fn command(&mut self, c: TorqueCommand) {
        let seq = c.header.seq;
        self.first_command_seq.get_or_insert(seq);
        self.last_command_seq = Some(seq);
        self.commands.insert(seq, c);
    }

    fn telemetry(&mut self, t: Box<Telemetry>) {
        self.last_telemetry_seq = Some(t.header.seq);
        self.pending.push_back(t);
    }
}

/// The replay state (module docs).
pub struct Replay {
    /// The scenario, for a fresh control cycle after a controller restart.
    scenario: Scenario,
    cycle: ControlCycle,
    /// Recorded states not yet consumed, in the order read (the driver's
    /// order: seq ascending, starting again after a driver restart).
    states: VecDeque<JointState>,
    /// The controller's commands and telemetry being replayed.
    ctl: ControllerStreams,
    /// A restarted controller's, read before the replay reached them.
    next: Option<ControllerStreams>,
    /// Recorded setpoints, path and load messages per client, not yet
    /// taken, in the client's order.
    setpoints: BTreeMap<u64, VecDeque<ClientMessage>>,
    /// The messages of the cycle being replayed from each client's first
    /// path message on, in the client's order (taken after the setpoints
    /// before them, with its state), and the refusal of the feasibility
    /// check the recording shows for the last one.
    paths_due: Vec<(ClientMessage, Option<KnotsRefusal>)>,
    /// The load messages of the cycle being replayed, taken after its paths
    /// (as the daemon takes them), in the order they were sent.
    loads_due: Vec<LoadSetpoint>,
    /// Per client, the setpoints answered so far, as the telemetry counts
    /// them, and the seq of the last one answered.
    answered: BTreeMap<u64, Answered>,
    /// The last recorded state's (seq, stamp), and the largest stamp read.
    last_state: Option<(u64, u64)>,
    latest_stamp: u64,
    /// The first recorded state's (seq, stamp).
    first_state: Option<(u64, u64)>,
    /// Whether a cycle was handed on (the first one decides what was before).
    started: bool,
    counts: ReplayCounts,
}

/// A control cycle of `scenario`, as a controller starts.
fn fresh_cycle(scenario: &Scenario) -> anyhow::Result<ControlCycle> {
    let controller = hcc_cycle::controller_for(scenario)?;
    ControlCycle::new(controller, &CycleSettings::from_scenario(scenario))
        .map_err(|e| anyhow!("the controller of {}: {e}", scenario.path.display()))
}

impl Replay {
    /// The replay of recordings of `scenario`'s controller.
    pub fn new(scenario: &Scenario) -> anyhow::Result<Replay> {
        Ok(Replay {
            scenario: scenario.clone(),
            cycle: fresh_cycle(scenario)?,
            states: VecDeque::new(),
            ctl: ControllerStreams::default(),
            next: None,
            setpoints: BTreeMap::new(),
            paths_due: Vec::new(),
            loads_due: Vec::new(),
            answered: BTreeMap::new(),
            last_state: None,
            latest_stamp: 0,
            first_state: None,
            started: false,
            counts: ReplayCounts::default(),
        })
    }

    /// What was counted so far.
    pub fn counts(&self) -> ReplayCounts {
        self.counts
    }

    /// A recorded joint state (a repeat of the last one, the same seq and
    /// stamp, was not answered again and is dropped; a seq below the last
    /// one is a restarted driver's, kept).
    pub fn on_state(&mut self, s: JointState) {
        let key = (s.header.seq, s.header.stamp_ns);
        if self.last_state == Some(key) {
            return;
        }
        if self.states.len() >= 2 * MAX_PENDING {
            self.states.pop_front();
            self.counts.states_dropped += 1;
        }
        if self.last_state.is_some_and(|(seq, _)| key.0 < seq) {
            self.counts.driver_restarts += 1;
        }
        self.first_state.get_or_insert(key);
        self.last_state = Some(key);
        self.latest_stamp = self.latest_stamp.max(key.1);
        self.states.push_back(s);
    }

    /// A recorded torque command (one numbered at or below the last is a
    /// restarted controller's).
    pub fn on_command(&mut self, c: TorqueCommand) {
        let seq = c.header.seq;
        // The new controller's once its commands have begun; before, the old
        // one's while they continue its numbering.
        let to_next = match &self.next {
            Some(n) if n.last_command_seq.is_some() => true,
            _ => !self.ctl.continues_commands(seq),
        };
        if !to_next {
            self.ctl.command(c);
            return;
        }
        let next = self.next.get_or_insert_with(ControllerStreams::default);
        if next.continues_commands(seq) {
            next.command(c);
        } else {
            self.counts.samples_dropped_at_restart += 1;
        }
    }

    /// A recorded setpoint (one the replay has already accounted for as
    /// answered before its first cycle — read after it, its stream drained
    /// later — is history and dropped).
    pub fn on_setpoint(&mut self, s: Setpoint) {
        self.on_client_message(s.client_id, ClientMessage::Setpoint(Box::new(s)));
    }

    /// A recorded path message (as a setpoint: the client numbers both).
    pub fn on_path(&mut self, p: PathKnots) {
        self.on_client_message(p.client_id, ClientMessage::Path(Box::new(p)));
    }

    /// A recorded load message (as a setpoint: the client numbers both).
    pub fn on_load(&mut self, l: LoadSetpoint) {
        self.on_client_message(l.client_id, ClientMessage::Load(Box::new(l)));
    }

    fn on_client_message(&mut self, client_id: u64, m: ClientMessage) {
        if self
            .answered
            .get(&client_id)
            .is_some_and(|a| m.seq() <= a.seq)
        {
            self.counts.setpoints_before_first_cycle += 1;
            return;
        }
        let q = self.setpoints.entry(client_id).or_default();
        // In the client's order (the recorder writes them so; a message
        // read late goes where its seq puts it).
        let at = q.len() - q.iter().rev().take_while(|o| o.seq() > m.seq()).count();
        q.insert(at, m);
    }

    /// A recorded telemetry sample (a cycle, or a stale event); one
    /// numbered at or below the last is a restarted controller's.
    pub fn on_telemetry(&mut self, t: Box<Telemetry>) {
        let seq = t.header.seq;
        let to_next = match &self.next {
            Some(n) if n.last_telemetry_seq.is_some() => true,
            _ => !self.ctl.continues_telemetry(seq),
        };
        if !to_next {
            self.ctl.telemetry(t);
            return;
        }
        let next = self.next.get_or_insert_with(ControllerStreams::default);
        if next.continues_telemetry(seq) {
            next.telemetry(t);
        } else {
            self.counts.samples_dropped_at_restart += 1;
        }
    }

    /// Whether a cycle still waiting for its inputs must be handed on now:
    /// [`MAX_PENDING`] telemetry samples read after it.
    fn waited_enough(&self) -> bool {
        let next = self.next.as_ref().map_or(0, |n| n.pending.len());
        self.ctl.pending.len() + next > MAX_PENDING
    }

    /// The restarted controller's streams become the replayed ones, with a
    /// fresh control cycle (module docs).
    fn restart_controller(&mut self) -> anyhow::Result<()> {
        let Some(next) = self.next.take() else {
            return Ok(());
        };
        self.ctl = next;
        self.cycle = fresh_cycle(&self.scenario)?;
        self.answered.clear();
        let queued: usize = self.setpoints.values().map(VecDeque::len).sum();
        self.counts.setpoints_dropped_at_restart += queued as u64;
        self.setpoints.clear();
        self.counts.controller_restarts += 1;
        Ok(())
    }

    /// Replays the pending cycles whose inputs have been read (with `end`:
    /// all of them, the file being over), handing each to `each`, which
    /// returns whether to go on.
    pub fn advance(
        &mut self,
        end: bool,
        each: &mut dyn FnMut(&Replayed<'_>) -> anyhow::Result<bool>,
    ) -> anyhow::Result<bool> {
        loop {
            while let Some(tel) = self.ctl.pending.front() {
                if tel.flags & TELEMETRY_FLAG_PEER_LOST != 0 {
                    let stamp = tel.header.stamp_ns;
                    self.ctl.pending.pop_front();
                    let _ = self.cycle.stale(stamp);
                    self.counts.stale += 1;
                    continue;
                }
                let complete = self.inputs_read(tel);
                if !complete && !end && !self.waited_enough() {
                    // The cycle's state, command or setpoints come later in the file.
                    return Ok(true);
                }
                let Some(tel) = self.ctl.pending.pop_front() else {
                    break;
                };
                if !self.replay(&tel, end && !complete, each)? {
                    return Ok(false);
                }
            }
            // The old controller's cycles are over once the new one's
            // telemetry is read (its commands may come first).
            let restarted = self
                .next
                .as_ref()
                .is_some_and(|n| end || !n.pending.is_empty());
            if !restarted {
                break;
            }
            self.restart_controller()?;
        }
        if end {
            self.counts.states_skipped += self.states.len() as u64;
            self.states.clear();
        }
        Ok(true)
    }

    /// The state the cycle of `tel` consumed: its seq, and its stamp when
    /// the recording holds the cycle's command (which echoes both).
    fn wanted(&self, tel: &Telemetry) -> (u64, Option<u64>) {
        let stamp = self
            .ctl
            .commands
            .get(&tel.command_seq)
            .filter(|c| c.state_seq == tel.state_seq)
            .map(|c| c.state_stamp_ns);
        (tel.state_seq, stamp)
    }

    /// Whether the inputs of `tel`'s cycle have been read: its command or a
    /// later one; its state or a later one (by the stamp its command echoes;
    /// without the command, by seq: a later state); and the setpoints it
    /// answered.
    fn inputs_read(&self, tel: &Telemetry) -> bool {
        if self
            .ctl
            .last_command_seq
            .is_none_or(|c| c < tel.command_seq)
        {
            return false;
        }
        let state_read = match self.wanted(tel) {
            (_, Some(stamp)) => self.latest_stamp >= stamp,
            (seq, None) => self.last_state.is_some_and(|(last, _)| last > seq),
        };
        state_read
            && tel.setpoint_answers.iter().all(|a| {
                let queued = self
                    .setpoints
                    .get(&a.client_id)
                    .map_or(0, |q| q.len() as u64);
                a.answered <= self.answered_before(a) + queued
            })
    }

    /// How many of the client's setpoints were answered before the cycle of
    /// `a`: as counted so far; for a client first heard of in the first
    /// replayed cycle, those the file does not hold (answered before the
    /// recording started: the count less the recorded setpoints up to
    /// `a.seq`); else none.
    fn answered_before(&self, a: &SetpointAnswer) -> u64 {
        match self.answered.get(&a.client_id) {
            Some(known) => known.count,
            None if !self.started => {
                let recorded = self.setpoints.get(&a.client_id).map_or(0, |q| {
                    q.iter().take_while(|s| s.seq() <= a.seq).count() as u64
                });
                a.answered.saturating_sub(recorded)
            }
            None => 0,
        }
    }

    /// Whether the cycle of `tel` consumed a state or answered with a command
    /// published before the recorder heard that stream: both streams are
    /// numbered +1 per message (states stamped in order) and the cycles
    /// follow them in order, so such a cycle can only come first.
    fn before_recording(&self, tel: &Telemetry) -> bool {
        let Some((first_seq, first_stamp)) = self.first_state else {
            return false;
        };
        let state_before = match self.wanted(tel) {
            (_, Some(stamp)) => stamp < first_stamp,
            (seq, None) => seq < first_seq,
        };
        !self.started
            && (state_before
                || self
                    .ctl
                    .first_command_seq
                    .is_some_and(|f| tel.command_seq < f))
    }

    /// Hands on a cycle before the recording (not replayed): the setpoints
    /// it had answered were taken before the file or by it, so its answer
    /// counts are where the replay's setpoints start.
    fn skip_before_recording(
        &mut self,
        tel: &Telemetry,
        each: &mut dyn FnMut(&Replayed<'_>) -> anyhow::Result<bool>,
    ) -> anyhow::Result<bool> {
        self.counts.cycles_before_recording += 1;
        for a in tel.setpoint_answers.iter().filter(|a| a.answered > 0) {
            if let Some(q) = self.setpoints.get_mut(&a.client_id) {
                while q.front().is_some_and(|s| s.seq() <= a.seq) {
                    q.pop_front();
                }
            }
            self.answered.insert(
                a.client_id,
                Answered {
                    count: a.answered,
                    seq: a.seq,
                },
            );
        }
        each(&Replayed {
            telemetry: tel,
            state: None,
            recorded: self.ctl.commands.get(&tel.command_seq),
            answer: None,
            cycle: &self.cycle,
            setpoints_missing: 0,
            at_end: false,
            before_recording: true,
        })
    }

    /// Replays the cycle of `tel`: its setpoints, its state; hands it on.
    fn replay(
        &mut self,
        tel: &Telemetry,
        at_end: bool,
        each: &mut dyn FnMut(&Replayed<'_>) -> anyhow::Result<bool>,
    ) -> anyhow::Result<bool> {
        if self.before_recording(tel) {
            return self.skip_before_recording(tel, each);
        }
        let first = !self.started;
        let setpoints_missing = self.take_setpoints(tel);
        self.started = true;
        let (want, stamp) = self.wanted(tel);
        let found = self
            .states
            .iter()
            .position(|s| s.header.seq == want && stamp.is_none_or(|t| s.header.stamp_ns == t));
        // The states read before it were not answered (or not by a cycle the
        // recording holds); without it, those older than it.
        let older = match found {
            Some(i) => i,
            None => self
                .states
                .iter()
                .take_while(|s| match stamp {
                    Some(t) => s.header.stamp_ns < t,
                    None => s.header.seq < want,
                })
                .count(),
        };
        self.states.drain(..older);
        if first {
            self.counts.states_before_first_cycle += older as u64;
        } else {
            self.counts.states_skipped += older as u64;
        }
        let state = match found {
            Some(_) => self.states.pop_front(),
            None => None,
        };
        // The cycle's paths (and the setpoints that waited behind them), in
        // the cycle of its state.
        for (message, refusal) in std::mem::take(&mut self.paths_due) {
            let mut once = match message {
                ClientMessage::Setpoint(sp) => {
                    self.cycle.take_setpoint_now(&sp);
                    self.counts.setpoints_taken += 1;
                    continue;
                }
                ClientMessage::Path(p) => Some(*p),
                // Loads go to `loads_due` when taken from the client's queue.
                ClientMessage::Load(l) => {
                    self.loads_due.push(*l);
                    continue;
                }
            };
            self.counts.paths_taken += 1;
            match (refusal, once.as_ref()) {
                (Some(r), Some(p)) => self.cycle.refuse_path(p, r),
                _ => match &state {
                    Some(s) => self.cycle.take_paths_at(s, || once.take()),
                    None => self.cycle.take_paths(|| once.take()),
                },
            }
        }
        // Then its loads. The daemon takes them in their arrival order: a
        // client's in its order, across clients by their send time.
        let mut loads = std::mem::take(&mut self.loads_due);
        loads.sort_by_key(|l| l.header.stamp_ns);
        for l in &loads {
            self.cycle.take_load(l);
            self.counts.loads_taken += 1;
        }
        loads.clear();
        self.loads_due = loads;
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
        let recorded = self.ctl.commands.remove(&tel.command_seq);
        // Commands of earlier cycles are not needed any more.
        self.ctl.commands = self.ctl.commands.split_off(&tel.command_seq);
        each(&Replayed {
            telemetry: tel,
            state: state.as_ref(),
            recorded: recorded.as_ref(),
            answer,
            cycle: &self.cycle,
            setpoints_missing,
            at_end,
            before_recording: false,
        })
    }

    /// Takes the messages the controller took in the cycle of `tel` (the
    /// increase of each client's answer count), in the order they were sent:
    /// a client's setpoints before its first path message at once, the rest
    /// after, with the state (as the daemon takes its setpoints, then the
    /// path messages whose feasibility check answered, with the setpoints
    /// that waited behind them, then the loads). A path message the check refused is the
    /// last its client was answered in the cycle: the recorded answer says
    /// so. Returns how many messages the recording lacks.
    fn take_setpoints(&mut self, tel: &Telemetry) -> u64 {
        let mut missing = 0;
        for a in tel.setpoint_answers.iter().filter(|a| a.answered > 0) {
            let before = self.answered_before(a);
            let mut behind_path = false;
            for _ in before..a.answered {
                match self
                    .setpoints
                    .get_mut(&a.client_id)
                    .and_then(|q| q.pop_front())
                {
                    Some(ClientMessage::Setpoint(s)) if !behind_path => {
                        self.cycle.take_setpoint_now(&s);
                        self.counts.setpoints_taken += 1;
                    }
                    Some(ClientMessage::Load(l)) => self.loads_due.push(*l),
                    Some(ClientMessage::Path(p)) => {
                        behind_path = true;
                        let refused = (p.header.seq == a.seq).then(|| check_refusal(a)).flatten();
                        self.paths_due.push((ClientMessage::Path(p), refused));
                    }
                    Some(m) => self.paths_due.push((m, None)),
                    None => missing += 1,
                }
            }
            let count = a.answered.max(before);
            self.answered
                .insert(a.client_id, Answered { count, seq: a.seq });
        }
        self.counts.setpoints_missing += missing;
        missing
    }
}

/// The refusal of the paths' feasibility check an answer records, if it is
/// one (`infeasible`, `unchecked`: a verdict the replay cannot compute again).
fn check_refusal(a: &SetpointAnswer) -> Option<KnotsRefusal> {
    let r = PathRejection::from_code(a.code)
        .filter(|r| matches!(r, PathRejection::Infeasible | PathRejection::Unchecked))?;
    Some(KnotsRefusal {
        rejection: r.into(),
        knot: a.refused_knot(),
    })
}

#[cfg(test)]
mod tests;
