//! Peer faults with real processes: `hcc-sim` (real time) and `hcc-controller`
//! on a namespace of their own, one of them killed with SIGKILL mid-run (a
//! crash: no clean-up of its own), then a new one started on the same
//! namespace and file prefix without touching the survivor or the files.
//!
//! * Simulator killed: the controller declares the peer lost after its stale
//!   timeout (three control periods), says so in telemetry (`stale_events`,
//!   `peer_lost_events`) and in a log line, keeps running, and controls the
//!   next simulator without being restarted.
//! * Controller killed: the simulator counts the first period without a
//!   command as a miss and reports its fallback in the very next state
//!   (status `FallbackActive`), holds then brakes, and applies the commands of
//!   a new controller.
//! * Both killed: both restarted on the same namespace work; the stale
//!   iceoryx2 resources of the dead processes are removed at start-up.
//!
//! The latencies are printed, not asserted tightly (shared, noisy machine):
//! the assertions are on counts, sequence numbers and states.

mod monitor;

use std::time::Duration;

use hcc_msgs::{CommandMode, DriverStatus};
use hcc_system_tests::*;
use monitor::{Daemon, Monitor};

const LONG: Duration = Duration::from_secs(60);

/// Normal answers in telemetry from index `from` on.
fn normal_answers(m: &Monitor, from: usize) -> usize {
    m.telemetry[from.min(m.telemetry.len())..]
        .iter()
        .filter(|t| !t.peer_lost && t.mode == CommandMode::Normal.code())
        .count()
}

/// States with status Ok (a command was applied in the period before) from index `from` on.
fn applied_states(m: &Monitor, from: usize) -> usize {
    m.states[from.min(m.states.len())..]
        .iter()
        .filter(|s| s.status == DriverStatus::Ok.code())
        .count()
}

#[test]
fn simulator_killed_controller_reports_keeps_running_and_controls_a_new_one() {
    let dir = TempDir::new("sim_killed");
    let ns = unique_namespace("sim_killed");
    let prefix = unique_file_prefix();
    {
        let mut mon = Monitor::new(&ns, &prefix);
        let mut ctl = Daemon::controller(&ns, &prefix, dir.path(), "controller");
        let mut sim = Daemon::sim(&ns, &prefix, dir.path(), "sim1");
        mon.wait_until("300 normal cycles with the first simulator", LONG, |m| {
            normal_answers(m, 0) >= 300
        });
        // (On a loaded machine a late tick of the simulator may already have
        // been reported as a short loss; only the loss after the kill counts.)
        let before = mon.last_telemetry().unwrap().counters;

        sim.crash();
        let killed_at = hcc_msgs::monotonic_now_ns();
        let after_kill = |m: &Monitor| {
            m.telemetry
                .iter()
                .position(|t| t.peer_lost && t.stamp_ns >= killed_at)
        };
        mon.wait_until("the controller declares the peer lost", LONG, |m| {
            after_kill(m).is_some()
        });
        let last_state = *mon.states.last().unwrap();
        let detected = mon.telemetry[after_kill(&mon).unwrap()];
        let latency_ms = detected.stamp_ns.saturating_sub(last_state.header.stamp_ns) as f64 / 1e6;
        println!(
            "simulator killed: last state seq {} → peer lost reported in telemetry {latency_ms:.2} ms after its stamp (stale timeout 3 ms = 3 periods)",
            last_state.header.seq
        );
        assert!(detected.counters.peer_lost_events >= before.peer_lost_events.max(1));
        assert!(detected.counters.stale_events > before.stale_events);
        // The stale sample is not a new answer: it carries the last state answered.
        assert_eq!(detected.state_seq, last_state.header.seq);
        assert!(
            latency_ms >= 3.0,
            "declared lost {latency_ms} ms after the last state, before the 3 ms timeout"
        );
        assert!(
            latency_ms < 1000.0,
            "detection took {latency_ms} ms (expected a few ms)"
        );

        // Still running, still reporting: one stale sample per timeout.
        mon.wait_until("further stale reports", LONG, |m| {
            m.last_telemetry().unwrap().counters.stale_events >= detected.counters.stale_events + 10
        });
        assert!(ctl.running(), "the controller exited:\n{}", ctl.log());
        assert_eq!(
            mon.last_telemetry().unwrap().counters.peer_lost_events,
            detected.counters.peer_lost_events,
            "one loss is one event"
        );
        let log = ctl.wait_for_log("peer lost: no joint state for", LONG);
        let line = log.lines().find(|l| l.contains("peer lost:")).unwrap();
        println!("controller log: {line}");

        // A new simulator on the same namespace: accepted, controlled.
        let states_before = mon.states.len();
        let telemetry_before = mon.telemetry.len();
        let mut sim2 = Daemon::sim(&ns, &prefix, dir.path(), "sim2");
        mon.wait_until("300 normal cycles with the second simulator", LONG, |m| {
            normal_answers(m, telemetry_before) >= 300 && applied_states(m, states_before) >= 300
        });
        let resumed = mon.telemetry[telemetry_before..]
            .iter()
            .find(|t| !t.peer_lost)
            .unwrap();
        assert_eq!(resumed.mode, CommandMode::Normal.code());
        println!(
            "second simulator: first answer to state seq {}; controller counters at the end {:?}",
            resumed.state_seq,
            mon.last_telemetry().unwrap().counters
        );
        assert!(
            resumed.state_seq < last_state.header.seq,
            "the new simulator counts from 0"
        );
        assert!(ctl.running(), "the controller was not restarted");
        let log = ctl.wait_for_log("joint states are back", LONG);
        assert!(log.contains("new peer detected"), "{log}");
        let sim2_log = sim2.wait_for_log("receiving torque commands", LONG);
        assert!(
            sim2_log.contains("removed the stale iceoryx2 resources of 1 dead process"),
            "the new simulator should report the clean-up of the dead one:\n{sim2_log}"
        );
        assert!(!log.contains("panicked") && !sim2_log.contains("panicked"));

        sim2.stop();
        ctl.stop();
        let _ = &mut sim;
    }
    assert_clean(&ns, &prefix);
}

#[test]
fn controller_killed_simulator_falls_back_at_once_and_accepts_a_new_controller() {
    let dir = TempDir::new("ctl_killed");
    let ns = unique_namespace("ctl_killed");
    let prefix = unique_file_prefix();
    {
        let mut mon = Monitor::new(&ns, &prefix);
        let mut sim = Daemon::sim(&ns, &prefix, dir.path(), "sim");
        let mut ctl = Daemon::controller(&ns, &prefix, dir.path(), "controller1");
        mon.wait_until("300 applied commands", LONG, |m| {
            applied_states(m, 0) >= 300
        });

        ctl.crash();
        // Long enough for the hold (3 periods) and the braking fallback.
        mon.wait_until("the simulator falls back", LONG, |m| {
            m.states
                .iter()
                .rev()
                .take_while(|s| s.status == DriverStatus::FallbackActive.code())
                .count()
                >= 200
        });
        let answered = mon.commands.iter().map(|c| c.state_seq).max().unwrap();
        let by_seq = |seq: u64| {
            *mon.states
                .iter()
                .find(|s| s.header.seq == seq)
                .unwrap_or_else(|| panic!("state {seq} was not recorded"))
        };
        // State answered+1 was published before the sim could notice; the
        // period after it had no command: reported in state answered+2.
        let unanswered = by_seq(answered + 1);
        let first_report = by_seq(answered + 2);
        println!(
            "controller killed: last command answered state {answered}; miss reported in state {} ({:.2} ms after state {}), i.e. after 1 period",
            first_report.header.seq,
            first_report
                .header
                .stamp_ns
                .saturating_sub(unanswered.header.stamp_ns) as f64
                / 1e6,
            unanswered.header.seq
        );
        assert_eq!(
            first_report.missed_commands,
            unanswered.missed_commands + 1,
            "the first period without a command is a miss"
        );
        assert_eq!(
            first_report.status,
            DriverStatus::FallbackActive.code(),
            "the fallback is reported in the next state"
        );
        // From then on every period is a miss in the fallback, and the arm
        // is braked where it was: gravity held, no fall.
        let tail: Vec<_> = mon
            .states
            .iter()
            .filter(|s| s.header.seq >= first_report.header.seq)
            .copied()
            .collect();
        for w in tail.windows(2) {
            assert_eq!(w[1].status, DriverStatus::FallbackActive.code());
            assert_eq!(
                w[1].fallback_cycles - w[0].fallback_cycles,
                w[1].header.seq - w[0].header.seq
            );
        }
        let drift = tail
            .last()
            .unwrap()
            .q()
            .iter()
            .zip(first_report.q())
            .map(|(a, b)| (a - b).abs())
            .fold(0.0, f64::max);
        println!(
            "fallback for {} periods; the arm moved {drift:.2e} rad",
            tail.len()
        );
        assert!(drift < 0.05, "the arm moved {drift} rad in the fallback");
        assert!(sim.running(), "the simulator exited:\n{}", sim.log());
        sim.wait_for_log("fallback active", LONG);

        // A new controller: its commands are applied again.
        let states_before = mon.states.len();
        let commands_before = mon.commands.len();
        let mut ctl2 = Daemon::controller(&ns, &prefix, dir.path(), "controller2");
        mon.wait_until("300 applied commands of the new controller", LONG, |m| {
            applied_states(m, states_before) >= 300
        });
        let first_new = mon.commands[commands_before..].first().unwrap();
        assert_eq!(first_new.header.seq, 1, "a new controller counts from 1");
        let last = *mon.states.last().unwrap();
        println!(
            "new controller: commands applied again from state {}; simulator counters at the end: missed {}, fallback {}",
            first_new.state_seq, last.missed_commands, last.fallback_cycles
        );
        let log2 = ctl2.log();
        assert!(
            log2.contains("removed the stale iceoryx2 resources of 1 dead process"),
            "the new controller should report the clean-up of the dead one:\n{log2}"
        );
        sim.wait_for_log("torque commands are back", LONG);
        ctl2.stop();
        sim.stop();
    }
    assert_clean(&ns, &prefix);
}

#[test]
fn both_killed_then_both_restarted_on_the_same_namespace() {
    let dir = TempDir::new("both_killed");
    let ns = unique_namespace("both_killed");
    let prefix = unique_file_prefix();
    {
        let mut mon = Monitor::new(&ns, &prefix);
        let mut ctl = Daemon::controller(&ns, &prefix, dir.path(), "controller1");
        let mut sim = Daemon::sim(&ns, &prefix, dir.path(), "sim1");
        mon.wait_until("300 normal cycles", LONG, |m| normal_answers(m, 0) >= 300);
        sim.crash();
        ctl.crash();

        let (states_before, telemetry_before) = (mon.states.len(), mon.telemetry.len());
        let mut ctl2 = Daemon::controller(&ns, &prefix, dir.path(), "controller2");
        let log = ctl2.wait_for_log("waiting for the first joint state", LONG);
        assert!(
            log.contains("removed the stale iceoryx2 resources of 2 dead process"),
            "{log}"
        );
        let mut sim2 = Daemon::sim(&ns, &prefix, dir.path(), "sim2");
        mon.wait_until("300 normal cycles after the restart", LONG, |m| {
            normal_answers(m, telemetry_before) >= 300 && applied_states(m, states_before) >= 300
        });
        assert_eq!(
            mon.last_telemetry().unwrap().counters.invalid_states,
            0,
            "the new controller starts with fresh counters"
        );
        sim2.stop();
        ctl2.stop();
    }
    assert_clean(&ns, &prefix);
}
