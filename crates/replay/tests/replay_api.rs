//! The library's API as its doc example uses it: a recording made in
//! process (the paper's simulation #1: the messages the driver and the
//! control cycle exchanged), opened, replayed and compared — every torque
//! bit-identical, every cycle answered — and its results derived.

use hcc_config::Scenario;
use hcc_record::mcap_log::{McapWriter, RecorderMsg, RunInfo};
use hcc_replay::compare::compare_file;
use hcc_replay::derive::{derive, results_writer, scenario_of};
use hcc_replay::replay::replay_file;
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

/// A directory of its own under the system's temporary one, removed on drop.
struct Dir(PathBuf);

impl Drop for Dir {
    fn drop(&mut self) {
        let _ = std::fs::remove_dir_all(&self.0);
    }
}

/// Records `scenario` run in process into `path`; the number of cycles.
fn record(scenario: &Scenario, path: &Path) -> u64 {
    let mut run = BTreeMap::new();
    run.insert("recorder".into(), "replay_api test".into());
    let info = RunInfo {
        run,
        scenario: RunInfo::describe_scenario(scenario),
        machine: BTreeMap::new(),
    };
    let mut w = McapWriter::create(path, &info, (0, 0)).expect("recording");
    let mut cycles = 0;
    hcc_in_process::simulate_observed(scenario, &mut |c| {
        w.joint_state(c.state).expect("state");
        w.torque_command(c.cycle.command()).expect("command");
        w.telemetry(c.cycle.telemetry()).expect("telemetry");
        cycles += 1;
        Ok(())
    })
    .expect("simulation");
    let mut stats = RecorderMsg::default();
    for s in [
        &mut stats.joint_state,
        &mut stats.torque_command,
        &mut stats.telemetry,
    ] {
        s.received = cycles;
        s.recorded = cycles;
    }
    w.finish(&stats, BTreeMap::new()).expect("finish");
    cycles
}

#[test]
fn a_recording_opened_replayed_and_compared_bit_for_bit() {
    let root = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../..");
    let mut scenario = Scenario::load(root.join("config/paper-sim1.toml")).expect("scenario");
    scenario.set_duration(0.3).expect("duration");
    let dir = Dir(std::env::temp_dir().join(format!(
        "hcc-replay-api-{}-{}",
        std::process::id(),
        std::time::SystemTime::now()
            .duration_since(std::time::UNIX_EPOCH)
            .map_or(0, |d| d.as_nanos())
    )));
    std::fs::create_dir_all(&dir.0).expect("dir");
    let file = dir.0.join("run.mcap");
    let cycles = record(&scenario, &file);
    assert!(cycles > 250, "{cycles}");

    // The doc example's steps: the scenario from the file, the replay, the
    // comparison of every command.
    let from_file = scenario_of(&file, None).expect("the recording's scenario");
    let (mut compared, mut differing) = (0u64, 0u64);
    let done = replay_file(&file, &from_file, &mut |cycle| {
        let (Some(recorded), Some(replayed)) = (cycle.recorded, cycle.replayed_command()) else {
            panic!("cycle {} not replayed", cycle.telemetry.header.seq);
        };
        let same = recorded.mode == replayed.mode
            && recorded
                .tau()
                .iter()
                .zip(replayed.tau())
                .all(|(a, b)| a.to_bits() == b.to_bits());
        differing += u64::from(!same);
        compared += 1;
        Ok(true)
    })
    .expect("replay");
    assert_eq!(compared, cycles);
    assert_eq!(differing, 0);
    assert_eq!(done.counts.cycles, cycles);
    assert!(done.truncated.is_none());
    // Stopping early: the callback's `false` ends the replay.
    let mut seen = 0;
    replay_file(&file, &from_file, &mut |_| {
        seen += 1;
        Ok(seen < 10)
    })
    .expect("replay");
    assert_eq!(seen, 10);
    // What `hcc replay` prints, as a value.
    let cmp = compare_file(&file, &from_file).expect("comparison");
    assert_eq!((cmp.compared, cmp.incomplete), (cycles, 0));
    assert!(cmp.first_difference.is_none());
    assert!(cmp.first_cycle.is_some());
    // The results, as `hcc plot` writes them: one row per cycle, the metrics.
    let out = dir.0.join("derived");
    let mut writer = results_writer(&from_file, &out, true).expect("writer");
    let derived = derive(&file, &from_file, &mut writer).expect("derivation");
    assert_eq!(derived.rows.rows as u64, cycles);
    let metrics = writer
        .finish(&derived.description)
        .expect("results")
        .metrics;
    assert!(!metrics.summary().is_empty());
    assert!(out.join("trajectory.csv").exists() && out.join("metrics.json").exists());
}
