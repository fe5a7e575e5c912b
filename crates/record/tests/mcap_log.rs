//! The MCAP recording: messages read back bit for bit, metadata, and a file
//! cut short (a recorder killed mid-run) read up to its last complete chunk.

use hcc_msgs::{JointState, Setpoint, Telemetry, TorqueCommand};
use hcc_record::mcap_log::{self, Entry, McapWriter, RecorderMsg, RunInfo};
use std::collections::BTreeMap;
use std::path::PathBuf;

fn temp(name: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("hcc_mcap_log_{}_{name}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    dir.join("run.mcap")
}

fn state(k: u64) -> JointState {
    let mut s = JointState::zeroed();
    s.header.seq = k;
    s.header.stamp_ns = 1_000_000 * k;
    s.set_n_joints(4).unwrap();
    // Values whose shortest decimal form is long, a negative zero, a subnormal.
    let x = k as f64;
    s.set_q(&[
        0.1 * x,
        -0.0,
        f64::MIN_POSITIVE / 3.0,
        (x + 1.0).sqrt() / 7.0,
    ])
    .unwrap();
    s.set_qd(&[1.0 / 3.0, f64::MAX, -1e-300, std::f64::consts::PI * x])
        .unwrap();
    s
}

fn telemetry(k: u64) -> Box<Telemetry> {
    let mut t = Box::new(Telemetry::zeroed());
    t.set_shape(4, &[2, 1, 4]).unwrap();
    t.header.seq = k + 1;
    t.header.stamp_ns = 1_000_000 * k + 50_000;
    t.state_seq = k;
    t.command_seq = k + 1;
    for j in 0..4 {
        t.tau[j] = (k as f64 + 0.3) * (j as f64 + 1.0).ln();
        t.tau_mu[j] = 1e-17 * j as f64;
        for i in 0..3 {
            t.tau_level[i][j] = (i * 10 + j) as f64 / 9.0;
        }
    }
    t.task_error[0][..2].copy_from_slice(&[1e-3, -2e-3]);
    t.task_error[1][0] = f64::NAN;
    t.storage[..3].copy_from_slice(&[0.5, 0.25, 1.0 / 7.0]);
    t.p_mu = -1.5e-16;
    t.counters.cycles = k + 1;
    t.timings.wakeup_latency_ns = -3;
    t.setpoint_answers[2].client_id = 42;
    t.setpoint_answers[2].answered = 1;
    t.setpoint_answers[2].seq = 7;
    t.load_mass = 0.5 + 1.0 / 3.0;
    t.load_com = [0.0, -1e-17, 0.1];
    t.load_progress = k as f64 / 49.0;
    t
}

fn info() -> RunInfo {
    let mut run = BTreeMap::new();
    run.insert("recorder".to_string(), "test".to_string());
    RunInfo {
        run,
        ..RunInfo::default()
    }
}

#[test]
fn messages_read_back_bit_for_bit() {
    let path = temp("roundtrip");
    let mut w = McapWriter::create(&path, &info(), (1_700_000_000_000_000_000, 0)).unwrap();
    let mut command = TorqueCommand::zeroed();
    command.set_n_joints(4).unwrap();
    command.set_tau(&[1.0, -2.5, 1e-310, 0.1 + 0.2]).unwrap();
    let setpoint = Setpoint::for_level(42, 7, 0, 2)
        .with_goal(&[0.3, 0.4])
        .unwrap()
        .with_stiffness(&[100.0, 200.0])
        .unwrap()
        .with_duration(1.5);
    for k in 0..50 {
        w.joint_state(&state(k)).unwrap();
        w.torque_command(&command).unwrap();
        w.telemetry(&telemetry(k)).unwrap();
    }
    w.setpoint(&setpoint).unwrap();
    let mut knots = hcc_msgs::PathKnots::zeroed();
    knots.flags = hcc_msgs::PATH_NEW;
    knots.client_id = 42;
    knots.header.seq = 8;
    knots
        .push_sample(0.0, &[0.3, 0.4], &[0.1 / 3.0, -0.0], &[1e-310, 2.0])
        .unwrap();
    knots
        .push_sample(0.25, &[0.31, 0.4], &[0.0, 0.0], &[0.0, 0.0])
        .unwrap();
    w.path_knots(&knots).unwrap();
    let mut load = hcc_msgs::LoadSetpoint::point(42, 9, 0.5, [0.0, 0.0, 0.1]);
    load.inertia = [1e-3, 0.0, 0.0, 1e-3, 0.0, 1.5e-3];
    w.load(&load).unwrap();
    w.finish(&RecorderMsg::default(), BTreeMap::new()).unwrap();

    let mut k = 0;
    let mut metadata = BTreeMap::new();
    let summary = mcap_log::read::<mcap_log::LogError>(&path, |time, e| {
        match e {
            Entry::JointState(s) => {
                let back = s.to_msg().unwrap();
                let want = state(k);
                // Bit-identical, including −0.0 and the subnormal.
                assert_eq!(
                    bytes_of(&back),
                    bytes_of(&want),
                    "state {k} differs after the round trip"
                );
                assert_eq!(time, 1_700_000_000_000_000_000 + 1_000_000 * k);
            }
            Entry::TorqueCommand(c) => {
                let back = c.to_msg().unwrap();
                let bits = |v: &[f64]| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
                assert_eq!(bits(back.tau()), bits(command.tau()));
            }
            Entry::Telemetry(t) => {
                let back = t.to_msg().unwrap();
                let want = telemetry(k);
                assert!(back.task_error[1][0].is_nan());
                let mut a = *back;
                let mut b = *want;
                a.task_error[1][0] = 0.0;
                b.task_error[1][0] = 0.0;
                assert_eq!(bytes_of(&a), bytes_of(&b), "telemetry {k}");
                assert_eq!(t.levels[0].storage, 0.5);
                k += 1;
            }
            Entry::Setpoint(s) => {
                let back = s.to_msg().unwrap();
                assert_eq!(bytes_of(&back), bytes_of(&setpoint));
            }
            Entry::Path(p) => {
                let back = p.to_msg().unwrap();
                assert_eq!(bytes_of(&back), bytes_of(&knots));
            }
            Entry::Load(l) => {
                let back = l.to_msg().unwrap();
                assert_eq!(bytes_of(&back), bytes_of(&load));
            }
            Entry::Metadata(name, map) => {
                metadata.insert(name, map);
            }
            Entry::Recorder(r) => assert!(r.last),
        }
        Ok(())
    })
    .unwrap();
    assert_eq!(k, 50);
    assert!(summary.truncated.is_none(), "{:?}", summary.truncated);
    assert_eq!(summary.messages["/telemetry"], 50);
    assert_eq!(summary.messages["/path"], 1);
    assert_eq!(summary.messages["/load"], 1);
    assert_eq!(metadata["hcc_run"]["recorder"], "test");
    assert!(metadata.contains_key(mcap_log::META_END));
}

/// The bytes of a plain-data message (padding is zero: every message starts zeroed).
fn bytes_of<T: Copy>(v: &T) -> Vec<u8> {
    // SAFETY: T is a repr(C) message without pointers, fully initialised
    // (built from `zeroed()`), so reading its bytes is defined.
    unsafe { std::slice::from_raw_parts(v as *const T as *const u8, std::mem::size_of::<T>()) }
        .to_vec()
}

#[test]
fn a_file_cut_short_reads_to_its_last_complete_chunk() {
    let path = temp("truncated");
    let mut w = McapWriter::create(&path, &info(), (0, 0)).unwrap();
    let mut sizes = Vec::new();
    for k in 0..300 {
        w.joint_state(&state(k)).unwrap();
        w.telemetry(&telemetry(k)).unwrap();
        if k % 100 == 99 {
            // What the once-per-second flush does.
            w.flush().unwrap();
            sizes.push(std::fs::metadata(&path).unwrap().len());
        }
    }
    // A recorder killed now: the bytes of two flushed chunks and part of a third.
    std::mem::forget(w);
    let full = std::fs::read(&path).unwrap();
    let cut = &full[..(sizes[1] as usize + (sizes[2] - sizes[1]) as usize / 2)];
    let cut_path = path.with_file_name("cut.mcap");
    std::fs::write(&cut_path, cut).unwrap();

    let mut states = 0;
    let summary = mcap_log::read::<mcap_log::LogError>(&cut_path, |_, e| {
        if let Entry::JointState(s) = e {
            assert_eq!(s.seq, states);
            states += 1;
        }
        Ok(())
    })
    .unwrap();
    assert_eq!(states, 200, "the two complete chunks, nothing of the third");
    assert!(summary.truncated.is_some());
}

/// The figures behind the choice of JSON (not a test of behaviour; run with
/// `--ignored --nocapture`): bytes and encoding time per 1 kHz cycle (joint
/// state, command, telemetry), zstd-compressed, against the raw structs.
#[test]
#[ignore]
fn encoding_figures() {
    use std::time::Instant;
    let cycles = 5000u64;
    let dir = temp("figures");
    let json = dir.with_file_name("json.mcap");
    let start = Instant::now();
    let mut w = McapWriter::create(&json, &info(), (0, 0)).unwrap();
    let mut command = TorqueCommand::zeroed();
    command.set_n_joints(4).unwrap();
    for k in 0..cycles {
        w.joint_state(&state(k)).unwrap();
        w.torque_command(&command).unwrap();
        w.telemetry(&telemetry(k)).unwrap();
    }
    w.finish(&RecorderMsg::default(), BTreeMap::new()).unwrap();
    let json_s = start.elapsed().as_secs_f64();
    let json_b = std::fs::metadata(&json).unwrap().len();

    // The alternative: the raw fixed-size structs, zstd level 3.
    let start = Instant::now();
    let mut raw = Vec::new();
    for k in 0..cycles {
        raw.extend(bytes_of(&state(k)));
        raw.extend(bytes_of(&command));
        raw.extend(bytes_of(&*telemetry(k)));
    }
    let packed = zstd_len(&raw);
    let raw_s = start.elapsed().as_secs_f64();
    println!(
        "per cycle: JSON+zstd {:.0} B, {:.1} µs; raw structs+zstd {:.0} B ({} B uncompressed), {:.1} µs",
        json_b as f64 / cycles as f64,
        json_s * 1e6 / cycles as f64,
        packed as f64 / cycles as f64,
        raw.len() as u64 / cycles,
        raw_s * 1e6 / cycles as f64
    );
}

fn zstd_len(data: &[u8]) -> usize {
    // Through an MCAP writer without a schema: the same chunking and compressor.
    let mut buf = std::io::Cursor::new(Vec::new());
    let mut w = mcap::Writer::new(&mut buf).unwrap();
    let ch = w.add_channel(0, "raw", "raw", &BTreeMap::new()).unwrap();
    for (k, part) in data.chunks(13_000).enumerate() {
        w.write_to_known_channel(
            &mcap::records::MessageHeader {
                channel_id: ch,
                sequence: k as u32,
                log_time: k as u64,
                publish_time: k as u64,
            },
            part,
        )
        .unwrap();
    }
    w.finish().unwrap();
    drop(w);
    buf.into_inner().len()
}
