//! Tests of the `replay` module.

use super::*;
use hcc_msgs::{CommandMode, TelemetryTimings};

/// What a controller daemon published over `k` cycles of the paper's
/// arm held at rest: states, commands, telemetry (seq 1..=k), and the
/// setpoints `sent` (each with the state it arrived with).
struct Run {
    states: Vec<JointState>,
    commands: Vec<TorqueCommand>,
    telemetry: Vec<Box<Telemetry>>,
}

fn daemon_run(scenario: &Scenario, k: u64, sent: &[(u64, Setpoint)]) -> Run {
    daemon_run_on(scenario, (1..=k).map(|seq| (seq, seq * 1_000_000)), sent)
}

/// [`daemon_run`] on states of the given (seq, stamp); the setpoints
/// `sent` arrive with the k-th state (1-based).
fn daemon_run_on(
    scenario: &Scenario,
    keys: impl Iterator<Item = (u64, u64)>,
    sent: &[(u64, Setpoint)],
) -> Run {
    let mut replay = Replay::new(scenario).unwrap();
    let cycle = &mut replay.cycle;
    let n = scenario.model.nq();
    let mut run = Run {
        states: vec![],
        commands: vec![],
        telemetry: vec![],
    };
    for (k, (seq, stamp)) in (1..).zip(keys) {
        let mut s = JointState::zeroed();
        s.set_n_joints(n).unwrap();
        s.set_q(scenario.q0.as_slice()).unwrap();
        s.header.seq = seq;
        s.header.stamp_ns = stamp;
        let mut arrived = sent.iter().filter(|(at, _)| *at == k).map(|(_, sp)| *sp);
        assert!(matches!(
            cycle.step(&s, s.header.stamp_ns, || arrived.next()),
            Answer::Command(_)
        ));
        run.commands
            .push(*cycle.stamp_command(s.header.stamp_ns + 5_000));
        let t = cycle.finish_telemetry(0, TelemetryTimings::default(), s.header.stamp_ns);
        run.telemetry.push(Box::new(*t));
        run.states.push(s);
    }
    run
}

/// Reads cycle `i` of `run` as the recorder drains it: state, command,
/// telemetry.
fn feed(replay: &mut Replay, run: &Run, i: usize) {
    replay.on_state(run.states[i]);
    replay.on_command(run.commands[i]);
    replay.on_telemetry(run.telemetry[i].clone());
}

fn paper_sim1() -> Scenario {
    let path = concat!(env!("CARGO_MANIFEST_DIR"), "/../../config/paper-sim1.toml");
    Scenario::load(path).unwrap()
}

/// A goal setpoint of the joint level (level 3) of client 7.
fn joint_goal(seq: u64, goal: f64) -> Setpoint {
    Setpoint::for_level(7, seq, 2, 1)
        .with_goal(&[goal])
        .unwrap()
}

/// A recorder that attached mid-run heard the telemetry from cycle 20
/// on, the commands from 22 on and the states from 24 on (its
/// subscribers connect one by one): cycles 20–23 are handed on as
/// before the recording, not as gaps, and the replay starts at cycle 24.
/// The arm is held at q0, away from the equilibrium, where the daemon's
/// history reaches the torque's last bits (bit-identity from mid-run
/// needs the equilibrium: `tests/record_attach.rs`); the torques agree
/// to 1e-9.
#[test]
fn a_recording_that_starts_mid_run_is_replayed_from_its_first_complete_cycle() {
    let scenario = paper_sim1();
    let Run {
        states,
        commands,
        telemetry,
    } = daemon_run(&scenario, 60, &[]);
    let mut replay = Replay::new(&scenario).unwrap();
    let (mut before, mut compared, mut gaps) = (vec![], vec![], 0);
    let mut each = |r: &Replayed<'_>| {
        let cycle = r.telemetry.header.seq;
        if r.before_recording {
            assert!(r.state.is_none() && r.answer.is_none());
            before.push(cycle);
            return Ok(true);
        }
        match (r.state, r.recorded, r.answer) {
            (Some(_), Some(recorded), Some(Answer::Command(_))) => {
                for (a, b) in recorded.tau().iter().zip(r.cycle.command().tau()) {
                    assert!((a - b).abs() <= 1e-9 * a.abs().max(1.0), "{a} vs {b}");
                }
                compared.push(cycle);
            }
            _ => gaps += 1,
        }
        Ok(true)
    };
    // The streams drained one after the other, ten cycles per drain.
    for chunk in 0..6 {
        let range = chunk * 10..(chunk + 1) * 10;
        for s in &states[range.clone()] {
            if s.header.seq >= 24 {
                replay.on_state(*s);
            }
        }
        for c in &commands[range.clone()] {
            if c.header.seq >= 22 {
                replay.on_command(*c);
            }
        }
        for t in &telemetry[range] {
            if t.header.seq >= 20 {
                replay.on_telemetry(t.clone());
            }
        }
        assert!(replay.advance(false, &mut each).unwrap());
    }
    assert!(replay.advance(true, &mut each).unwrap());
    assert_eq!(before, vec![20, 21, 22, 23]);
    assert_eq!(compared, (24..=60).collect::<Vec<_>>());
    assert_eq!(gaps, 0);
    let counts = replay.counts();
    assert_eq!(counts.cycles_before_recording, 4);
    assert_eq!(counts.states_missing, 0);
    assert_eq!(counts.states_skipped, 0);
    assert_eq!(counts.states_before_first_cycle, 0);
    assert_eq!(counts.cycles, 37);
}

/// A state lost after the replay started is a gap, not "before the
/// recording": the marking only ever covers the first cycles.
#[test]
fn a_state_lost_after_the_start_is_a_gap() {
    let scenario = paper_sim1();
    let Run {
        states,
        commands,
        telemetry,
    } = daemon_run(&scenario, 30, &[]);
    let mut replay = Replay::new(&scenario).unwrap();
    let (mut before, mut missing) = (0, vec![]);
    let mut each = |r: &Replayed<'_>| {
        if r.before_recording {
            before += 1;
        } else if r.state.is_none() {
            missing.push(r.telemetry.header.seq);
        }
        Ok(true)
    };
    for i in 0..30 {
        if states[i].header.seq != 12 {
            replay.on_state(states[i]);
        }
        replay.on_command(commands[i]);
        replay.on_telemetry(telemetry[i].clone());
        assert!(replay.advance(false, &mut each).unwrap());
    }
    assert!(replay.advance(true, &mut each).unwrap());
    assert_eq!(before, 0);
    assert_eq!(missing, vec![12]);
    assert_eq!(replay.counts().states_missing, 1);
}

/// A recorder attached after a client's first setpoint (cycle 5; the
/// file from cycle 20 on) and before its second (cycle 40): the first
/// is history — not a setpoint the file lacks, and no reason to hold the
/// cycles back until the end of the file — and the second is taken again.
#[test]
fn setpoints_answered_before_a_mid_run_recording_are_history() {
    let scenario = paper_sim1();
    let sent = [(5, joint_goal(1, 0.36)), (40, joint_goal(2, 0.37))];
    let run = daemon_run(&scenario, 60, &sent);
    let mut replay = Replay::new(&scenario).unwrap();
    let (mut handed, mut incomplete) = (vec![], 0);
    let mut each = |r: &Replayed<'_>| {
        assert!(!r.before_recording);
        if r.at_end || r.setpoints_missing > 0 || r.state.is_none() {
            incomplete += 1;
        }
        handed.push(r.telemetry.header.seq);
        Ok(true)
    };
    for i in 19..60 {
        if let Some((_, sp)) = sent.iter().find(|(at, _)| *at == i as u64 + 1) {
            replay.on_setpoint(*sp);
        }
        feed(&mut replay, &run, i);
        assert!(replay.advance(false, &mut each).unwrap());
        // Each cycle is handed on once its state and command are read.
        assert!(replay.ctl.pending.is_empty(), "cycle {}", i + 1);
    }
    assert!(replay.advance(true, &mut each).unwrap());
    assert_eq!(handed, (20..=60).collect::<Vec<_>>());
    assert_eq!(incomplete, 0);
    let counts = replay.counts();
    assert_eq!(counts.setpoints_taken, 1);
    assert_eq!(counts.setpoints_missing, 0);
}

/// A setpoint the recorder lost (cycle 10's) holds its cycle back only
/// for a bounded time: the cycle is handed on with the setpoint counted
/// missing, and the telemetry waiting for inputs never exceeds
/// [`MAX_PENDING`] samples, however long the file.
#[test]
fn a_lost_setpoint_holds_the_replay_back_for_a_bounded_time() {
    let scenario = paper_sim1();
    let k = MAX_PENDING as u64 + 200;
    let sent = [(10, joint_goal(1, 0.36))];
    let run = daemon_run(&scenario, k, &sent);
    let mut replay = Replay::new(&scenario).unwrap();
    let (mut handed, mut missing_at, mut largest) = (0, vec![], 0);
    let mut each = |r: &Replayed<'_>| {
        handed += 1;
        if r.setpoints_missing > 0 {
            assert!(!r.at_end);
            missing_at.push(r.telemetry.header.seq);
        }
        Ok(true)
    };
    for i in 0..k as usize {
        feed(&mut replay, &run, i);
        assert!(replay.advance(false, &mut each).unwrap());
        largest = largest.max(replay.ctl.pending.len());
    }
    assert!(replay.advance(true, &mut each).unwrap());
    assert_eq!(handed, k);
    assert_eq!(missing_at, vec![10]);
    assert_eq!(replay.counts().setpoints_missing, 1);
    assert!(largest <= MAX_PENDING, "{largest}");
}

/// A driver restarted mid-recording (its states numbered from 1 again,
/// stamped later): the controller answered the new states (the safe
/// command until it took them for a new peer, then the law), and the
/// replay follows it — every cycle replayed, bit-identical, the restart
/// counted; before, every state after the restart was dropped as "not
/// after the last one" and every later cycle was a gap.
#[test]
fn a_driver_restarted_mid_recording_is_followed() {
    let scenario = paper_sim1();
    let ms = 1_000_000;
    let first = (1..=40).map(|seq| (seq, seq * ms));
    let second = (1..=40).map(|seq| (seq, (60 + seq) * ms));
    let run = daemon_run_on(&scenario, first.chain(second), &[]);
    let mut replay = Replay::new(&scenario).unwrap();
    let (mut compared, mut safe, mut gaps) = (0, 0, 0);
    let mut each = |r: &Replayed<'_>| {
        match (r.state, r.recorded, r.answer) {
            (Some(_), Some(recorded), Some(Answer::Command(mode))) => {
                let bits = |t: &[f64]| t.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
                assert_eq!(bits(recorded.tau()), bits(r.cycle.command().tau()));
                assert_eq!(recorded.mode, mode.code());
                compared += 1;
                if mode == CommandMode::SafeHold {
                    safe += 1;
                }
            }
            _ => gaps += 1,
        }
        Ok(true)
    };
    for i in 0..run.states.len() {
        feed(&mut replay, &run, i);
        assert!(replay.advance(false, &mut each).unwrap());
    }
    assert!(replay.advance(true, &mut each).unwrap());
    assert_eq!((compared, gaps), (80, 0));
    assert!(
        safe > 0,
        "the controller answered the restart with the safe command"
    );
    let counts = replay.counts();
    assert_eq!(counts.driver_restarts, 1);
    assert_eq!(counts.cycles, 80);
    assert_eq!(counts.states_skipped, 0);
}

/// A controller restarted mid-recording (its telemetry and commands
/// numbered from 1 again, the driver's states going on, a gap of 50
/// states between the two controllers): the replay hands on the first
/// controller's 30 cycles and then, with a fresh control cycle, the
/// second one's 40 — every torque bit-identical, the restart counted,
/// the unanswered states skipped. The streams interleave as the
/// recorder drains them: the new controller's first commands are read
/// before the old one's last telemetry.
#[test]
fn a_restarted_controller_is_followed_with_a_fresh_cycle() {
    let scenario = paper_sim1();
    let ms = 1_000_000;
    let first = daemon_run(&scenario, 30, &[]);
    let second = daemon_run_on(&scenario, (81..=120).map(|seq| (seq, seq * ms)), &[]);
    let mut replay = Replay::new(&scenario).unwrap();
    let mut handed = vec![];
    let mut each = |r: &Replayed<'_>| {
        let (Some(recorded), Some(Answer::Command(_))) = (r.recorded, r.answer) else {
            panic!(
                "cycle {} not replayed: state {:?}, recorded {:?}, answer {:?}",
                r.telemetry.header.seq,
                r.state.map(|s| s.header.seq),
                r.recorded.map(|c| c.header.seq),
                r.answer
            );
        };
        let bits = |t: &[f64]| t.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
        assert_eq!(bits(recorded.tau()), bits(r.cycle.command().tau()));
        handed.push(r.telemetry.header.seq);
        Ok(true)
    };
    for i in 0..28 {
        feed(&mut replay, &first, i);
        assert!(replay.advance(false, &mut each).unwrap());
    }
    // The old controller's last two cycles: their states and commands,
    // then the new one's first command, then the old telemetry.
    for i in 28..30 {
        replay.on_state(first.states[i]);
        replay.on_command(first.commands[i]);
    }
    let mut idle = JointState::zeroed();
    idle.set_n_joints(4).unwrap();
    for seq in 31..=80 {
        idle.header.seq = seq;
        idle.header.stamp_ns = seq * ms;
        replay.on_state(idle);
    }
    replay.on_state(second.states[0]);
    replay.on_command(second.commands[0]);
    for i in 28..30 {
        replay.on_telemetry(first.telemetry[i].clone());
    }
    replay.on_telemetry(second.telemetry[0].clone());
    assert!(replay.advance(false, &mut each).unwrap());
    for i in 1..40 {
        feed(&mut replay, &second, i);
        assert!(replay.advance(false, &mut each).unwrap());
    }
    assert!(replay.advance(true, &mut each).unwrap());
    let expected: Vec<u64> = (1..=30).chain(1..=40).collect();
    assert_eq!(handed, expected);
    let counts = replay.counts();
    assert_eq!(counts.controller_restarts, 1);
    assert_eq!(counts.cycles, 70);
    assert_eq!(counts.states_skipped, 50);
    assert_eq!(counts.samples_dropped_at_restart, 0);
}

/// States that no telemetry consumes (the controller gone, the driver
/// still publishing) are kept up to 2 · [`MAX_PENDING`], the oldest
/// dropped and counted.
#[test]
fn states_without_cycles_are_bounded() {
    let scenario = paper_sim1();
    let mut replay = Replay::new(&scenario).unwrap();
    let mut s = JointState::zeroed();
    s.set_n_joints(4).unwrap();
    for seq in 1..=3 * MAX_PENDING as u64 {
        s.header.seq = seq;
        s.header.stamp_ns = seq * 1_000_000;
        replay.on_state(s);
    }
    assert_eq!(replay.states.len(), 2 * MAX_PENDING);
    assert_eq!(replay.counts().states_dropped, MAX_PENDING as u64);
    assert_eq!(
        replay.states.front().unwrap().header.seq,
        MAX_PENDING as u64 + 1
    );
}
