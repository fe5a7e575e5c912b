//! The ROS 2 messages the bridge writes and reads, in plain CDR ([`crate::cdr`]),
//! field by field in the order of their `.msg` definitions (ROS 2 Jazzy's
//! `common_interfaces` for the standard ones; `ros/hcc_msgs/msg/*.msg` of
//! this repository for hcc's telemetry), with their RIHS01 type hashes.
//!
//! The hashes are those ROS 2 computes from the type descriptions (REP 2011;
//! `sensor_msgs/msg/JointState`'s is quoted by the issue that asked for the
//! bridge); the Python tests recompute every one of them independently
//! from the message definitions (the `rosbags` package) and compare them
//! with the hashes the running bridge announces.

use hcc_msgs::{MAX_SETPOINT_CLIENTS, SetpointRejection, Telemetry};

use crate::cdr::{CdrError, CdrReader, CdrWriter};
use crate::names::RosType;

/// `sensor_msgs/msg/JointState`.
pub const JOINT_STATE: RosType = RosType {
    name: "sensor_msgs/msg/JointState",
    hash: "RIHS01_a13ee3a330e346c9d87b5aa18d24e11690752bd33a0350f11c5882bc9179260e",
};
/// `geometry_msgs/msg/PoseStamped`.
pub const POSE_STAMPED: RosType = RosType {
    name: "geometry_msgs/msg/PoseStamped",
    hash: "RIHS01_10f3786d7d40fd2b54367835614bff85d4ad3b5dab62bf8bca0cc232d73b4cd8",
};
/// `geometry_msgs/msg/PointStamped`.
pub const POINT_STAMPED: RosType = RosType {
    name: "geometry_msgs/msg/PointStamped",
    hash: "RIHS01_4c0296af86e01e562e9e0405d138a01537247580076c58ea38d7923ac1045897",
};
/// `geometry_msgs/msg/QuaternionStamped`.
pub const QUATERNION_STAMPED: RosType = RosType {
    name: "geometry_msgs/msg/QuaternionStamped",
    hash: "RIHS01_381add86c6c3160644d228ca342182c7fd6c7fab11c7a85ad817a9cc22dbac6e",
};
/// `std_msgs/msg/Float64MultiArray`.
pub const FLOAT64_MULTI_ARRAY: RosType = RosType {
    name: "std_msgs/msg/Float64MultiArray",
    hash: "RIHS01_1025ddc6b9552d191f89ef1a8d2f60f3d373e28b283d8891ddcc974e8c55397f",
};
/// `hcc_msgs/msg/Telemetry` (`ros/hcc_msgs/msg/Telemetry.msg`).
pub const TELEMETRY: RosType = RosType {
    name: "hcc_msgs/msg/Telemetry",
    hash: "RIHS01_715655cde20dd09c5cfa090561ba9bf36da8a823b27019ce59c04d3a2f3bba40",
};

/// `builtin_interfaces/msg/Time`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct RosTime {
    /// Seconds since the Unix epoch.
    pub sec: i32,
    /// Nanoseconds within the second, < 10⁹.
    pub nanosec: u32,
}

impl RosTime {
    /// The time of `ns` nanoseconds since the epoch (saturating at the
    /// limits of `int32` seconds).
    pub fn from_ns(ns: i64) -> RosTime {
        let sec = ns.div_euclid(1_000_000_000);
        let nanosec = ns.rem_euclid(1_000_000_000) as u32;
        match i32::try_from(sec) {
            Ok(sec) => RosTime { sec, nanosec },
            Err(_) if sec < 0 => RosTime {
                sec: i32::MIN,
                nanosec: 0,
            },
            Err(_) => RosTime {
                sec: i32::MAX,
                nanosec: 999_999_999,
            },
        }
    }
}

/// Moves the daemons' CLOCK_MONOTONIC stamps to CLOCK_REALTIME (ROS time)
/// by the offset between the two clocks read once at start: the stamps of
/// one bridge run keep their exact spacing.
#[derive(Debug, Clone, Copy)]
pub struct ClockMap {
    offset_ns: i64,
}

impl ClockMap {
    /// Reads both clocks now.
    pub fn now() -> ClockMap {
        let mono = hcc_msgs::monotonic_now_ns() as i64;
        let real = crate::attachment::realtime_now_ns();
        ClockMap {
            offset_ns: real - mono,
        }
    }

    /// A fixed offset (tests).
    pub fn with_offset(offset_ns: i64) -> ClockMap {
        ClockMap { offset_ns }
    }

    /// The ROS time of monotonic `ns`.
    pub fn ros_time(&self, monotonic_ns: u64) -> RosTime {
        RosTime::from_ns((monotonic_ns as i64).saturating_add(self.offset_ns))
    }
}

/// `std_msgs/msg/Header`.
fn header(w: &mut CdrWriter, stamp: RosTime, frame_id: &str) {
    w.i32(stamp.sec).u32(stamp.nanosec).string(frame_id);
}

/// Writes a `sensor_msgs/msg/JointState` (empty slices for fields the
/// stream does not have, as ROS documents).
pub fn write_joint_state(
    w: &mut CdrWriter,
    stamp: RosTime,
    names: &[String],
    position: &[f64],
    velocity: &[f64],
    effort: &[f64],
) {
    w.start();
    header(w, stamp, "");
    w.seq_string(names)
        .seq_f64(position)
        .seq_f64(velocity)
        .seq_f64(effort);
}

/// The answer to a remote goal (`hcc_msgs/msg/RemoteAnswer`).
#[derive(Debug, Clone, PartialEq)]
pub struct RemoteAnswer {
    /// The remote publisher's GID.
    pub source_gid: [u8; 16],
    /// Its sequence number of the goal.
    pub source_seq: i64,
    /// The level addressed (0-based).
    pub level: u32,
    /// 0 accepted, a controller rejection code, or a `REFUSED_*` code.
    pub code: u32,
    /// The reason in words (`accepted`, a rejection's name, the bridge's).
    pub reason: String,
    /// The transition duration in force, s.
    pub duration_s: f64,
}

/// Refused: the bridge is read-only (no `--allow-setpoints`).
pub const REFUSED_READ_ONLY: u32 = 100;
/// Refused: over the bridge's setpoint rate cap.
pub const REFUSED_RATE: u32 = 101;
/// Refused: the message could not be read or converted.
pub const REFUSED_BAD_MESSAGE: u32 = 102;
/// Refused: the controller could not be reached.
pub const REFUSED_UNREACHABLE: u32 = 103;

/// What the telemetry message carries besides the controller's sample.
#[derive(Debug, Clone, Copy)]
pub struct TelemetryExtras<'a> {
    /// The scenario's level names.
    pub level_names: &'a [String],
    /// The bridge's counters, (name, value).
    pub bridge_counters: &'a [(&'static str, u64)],
    /// The bridge's client id (0: read-only).
    pub bridge_client_id: u64,
    /// The last answer of each recent remote publisher.
    pub remote_answers: &'a [RemoteAnswer],
}

/// The name of an answer code: `accepted` or the rejection's name.
pub fn answer_reason(code: u32) -> String {
    match code {
        hcc_msgs::ANSWER_ACCEPTED => "accepted".into(),
        c => SetpointRejection::from_code(c)
            .map(|r| r.name().to_string())
            .or_else(|| hcc_msgs::PathRejection::from_code(c).map(|r| r.name().to_string()))
            .unwrap_or_else(|| format!("code {c}")),
    }
}

/// `hcc_msgs/msg/Level` of level `i` of `t`.
fn write_level(w: &mut CdrWriter, t: &Telemetry, i: usize, name: &str) {
    let m = (t.task_dims[i] as usize).min(hcc_msgs::MAX_TASK_DIM);
    w.string(name)
        .u32(m as u32)
        .seq_f64(&t.task_error[i][..m])
        .seq_f64(&t.goal[i][..m])
        .seq_f64(&t.stiffness_diag[i][..m])
        .seq_f64(&t.damping_diag[i][..m])
        .f64(t.storage[i])
        .f64(t.min_singular_value[i])
        .f64(t.transition_progress[i])
        .bool(t.is_singular(i));
}

/// Writes an `hcc_msgs/msg/Telemetry` of the controller's sample `t`.
pub fn write_telemetry(w: &mut CdrWriter, t: &Telemetry, stamp: RosTime, x: &TelemetryExtras) {
    w.start();
    header(w, stamp, "");
    w.u64(t.header.seq)
        .u64(t.state_seq)
        .u64(t.command_seq)
        .u64(t.header.stamp_ns)
        .u32(t.mode)
        .u32(t.flags)
        .seq_f64(t.tau())
        .f64(t.p_mu);
    let r = t.levels();
    w.seq_len(r);
    for i in 0..r {
        let name = x.level_names.get(i).map_or("", String::as_str);
        write_level(w, t, i, name);
    }
    let counters = t.counters.entries();
    let n = counters.len() + x.bridge_counters.len();
    w.seq_len(n);
    for (name, _) in counters.iter().chain(x.bridge_counters) {
        w.string(name);
    }
    w.seq_len(n);
    for (_, v) in counters.iter().chain(x.bridge_counters) {
        w.u64(*v);
    }
    let answers: Vec<_> = t
        .setpoint_answers
        .iter()
        .filter(|a| a.answered > 0)
        .collect();
    debug_assert!(answers.len() <= MAX_SETPOINT_CLIENTS);
    w.seq_len(answers.len());
    for a in answers {
        w.u64(a.client_id)
            .u64(a.seq)
            .u64(a.answered)
            .u32(a.code)
            .string(&answer_reason(a.code))
            .u32(a.level)
            .f64(a.duration_s)
            .u32(a.rejected)
            .u32(a.late);
    }
    w.u64(x.bridge_client_id);
    w.seq_len(x.remote_answers.len());
    for a in x.remote_answers {
        w.u8_array(&a.source_gid)
            .i64(a.source_seq)
            .u32(a.level)
            .u32(a.code)
            .string(&a.reason)
            .f64(a.duration_s);
    }
    w.seq_f64(t.tau_ext());
    w.f64(t.h)
        .seq_f64(&t.potential[..r])
        .seq_f64(&t.tank[..r])
        .seq_f64(&t.tank_valve[..r])
        .f64(t.load_mass);
    for c in t.load_com {
        w.f64(c);
    }
    w.f64(t.load_progress);
}

/// A goal message as received, before it is checked against its level.
#[derive(Debug, Clone, PartialEq)]
pub enum GoalMsg {
    /// `geometry_msgs/msg/PoseStamped`: frame, position, orientation (x, y, z, w).
    Pose {
        frame: String,
        position: [f64; 3],
        orientation: [f64; 4],
    },
    /// `geometry_msgs/msg/PointStamped`: frame, point.
    Point { frame: String, point: [f64; 3] },
    /// `geometry_msgs/msg/QuaternionStamped`: frame, quaternion (x, y, z, w).
    Quaternion { frame: String, quaternion: [f64; 4] },
    /// `std_msgs/msg/Float64MultiArray`: the data from `layout.data_offset` on.
    Array(Vec<f64>),
}

/// Reads a `std_msgs/msg/Header`; returns the frame id.
fn read_header(r: &mut CdrReader) -> Result<String, CdrError> {
    r.i32("header.stamp.sec")?;
    r.u32("header.stamp.nanosec")?;
    Ok(r.string("header.frame_id")?.to_owned())
}

fn read_3(r: &mut CdrReader, field: &'static str) -> Result<[f64; 3], CdrError> {
    Ok([r.f64(field)?, r.f64(field)?, r.f64(field)?])
}

fn read_4(r: &mut CdrReader, field: &'static str) -> Result<[f64; 4], CdrError> {
    Ok([r.f64(field)?, r.f64(field)?, r.f64(field)?, r.f64(field)?])
}

/// Reads a goal of type `ty` (one of the four goal types).
pub fn read_goal(ty: &RosType, payload: &[u8]) -> Result<GoalMsg, CdrError> {
    let mut r = CdrReader::new(payload)?;
    if *ty == FLOAT64_MULTI_ARRAY {
        let dims = r.seq_len("layout.dim")?;
        for _ in 0..dims {
            r.string("layout.dim.label")?;
            r.u32("layout.dim.size")?;
            r.u32("layout.dim.stride")?;
        }
        let offset = r.u32("layout.data_offset")? as usize;
        let mut data = Vec::new();
        r.seq_f64("data", &mut data)?;
        data.drain(..offset.min(data.len()));
        return Ok(GoalMsg::Array(data));
    }
    let frame = read_header(&mut r)?;
    Ok(match *ty {
        t if t == POSE_STAMPED => GoalMsg::Pose {
            frame,
            position: read_3(&mut r, "pose.position")?,
            orientation: read_4(&mut r, "pose.orientation")?,
        },
        t if t == POINT_STAMPED => GoalMsg::Point {
            frame,
            point: read_3(&mut r, "point")?,
        },
        _ => GoalMsg::Quaternion {
            frame,
            quaternion: read_4(&mut r, "quaternion")?,
        },
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use hcc_msgs::TelemetryCounters;

    #[test]
    fn ros_time_splits_and_saturates() {
        assert_eq!(
            RosTime::from_ns(1_700_000_000_123_456_789),
            RosTime {
                sec: 1_700_000_000,
                nanosec: 123_456_789
            }
        );
        assert_eq!(
            RosTime::from_ns(-1),
            RosTime {
                sec: -1,
                nanosec: 999_999_999
            }
        );
        assert_eq!(RosTime::from_ns(i64::MAX).sec, i32::MAX);
        let map = ClockMap::with_offset(1_000_000_000);
        assert_eq!(
            map.ros_time(500),
            RosTime {
                sec: 1,
                nanosec: 500
            }
        );
    }

    #[test]
    fn joint_state_layout() {
        let mut w = CdrWriter::new();
        let names = vec!["j1".to_string(), "joint_2".to_string()];
        write_joint_state(
            &mut w,
            RosTime { sec: 7, nanosec: 9 },
            &names,
            &[0.5, -1.0],
            &[],
            &[3.0, 4.0],
        );
        let mut r = CdrReader::new(w.bytes()).unwrap();
        assert_eq!(r.i32("sec").unwrap(), 7);
        assert_eq!(r.u32("nsec").unwrap(), 9);
        assert_eq!(r.string("frame").unwrap(), "");
        assert_eq!(r.seq_len("name").unwrap(), 2);
        assert_eq!(r.string("n0").unwrap(), "j1");
        assert_eq!(r.string("n1").unwrap(), "joint_2");
        let mut v = Vec::new();
        r.seq_f64("position", &mut v).unwrap();
        assert_eq!(v, [0.5, -1.0]);
        r.seq_f64("velocity", &mut v).unwrap();
        assert!(v.is_empty());
        r.seq_f64("effort", &mut v).unwrap();
        assert_eq!(v, [3.0, 4.0]);
        assert_eq!(r.remaining(), 0);
    }

    #[test]
    fn telemetry_layout_follows_the_msg_definition() {
        let mut t = Telemetry::zeroed();
        t.set_shape(2, &[1, 2]).unwrap();
        t.header.seq = 11;
        t.header.stamp_ns = 99;
        t.state_seq = 10;
        t.tau[..2].copy_from_slice(&[1.5, -2.5]);
        t.p_mu = 1e-12;
        t.tau_ext[..2].copy_from_slice(&[0.125, -7.0]);
        t.h = 12.5;
        t.potential[..2].copy_from_slice(&[3.0, 0.5]);
        t.tank[..2].copy_from_slice(&[0.0, 2.25]);
        t.tank_valve[..2].copy_from_slice(&[1.0, 0.75]);
        t.load_mass = 0.5;
        t.load_com = [0.01, -0.02, 0.1];
        t.load_progress = 0.25;
        t.task_error[1][..2].copy_from_slice(&[0.25, 0.5]);
        t.singular_levels = 0b10;
        t.setpoint_answers[3] = hcc_msgs::SetpointAnswer {
            client_id: 7,
            seq: 4,
            answered: 4,
            code: SetpointRejection::OutsideWorkspace.code(),
            level: 1,
            duration_s: 0.0,
            rejected: 2,
            late: 0,
            ..hcc_msgs::SetpointAnswer::EMPTY
        };
        let names = vec!["a".to_string(), "b".to_string()];
        let remote = [RemoteAnswer {
            source_gid: [9; 16],
            source_seq: -3,
            level: 1,
            code: REFUSED_RATE,
            reason: "rate".into(),
            duration_s: 0.5,
        }];
        let extras = TelemetryExtras {
            level_names: &names,
            bridge_counters: &[("bridge_x", 5)],
            bridge_client_id: 42,
            remote_answers: &remote,
        };
        let mut w = CdrWriter::new();
        write_telemetry(&mut w, &t, RosTime { sec: 1, nanosec: 2 }, &extras);
        let mut r = CdrReader::new(w.bytes()).unwrap();
        let mut v = Vec::new();
        assert_eq!((r.i32("s").unwrap(), r.u32("n").unwrap()), (1, 2));
        assert_eq!(r.string("frame").unwrap(), "");
        let seqs: [u64; 4] = std::array::from_fn(|_| r.u64("seq").unwrap());
        assert_eq!(seqs, [11, 10, 0, 99]);
        assert_eq!((r.u32("mode").unwrap(), r.u32("flags").unwrap()), (0, 0));
        r.seq_f64("tau", &mut v).unwrap();
        assert_eq!(v, [1.5, -2.5]);
        assert_eq!(r.f64("p_mu").unwrap(), 1e-12);
        assert_eq!(r.seq_len("levels").unwrap(), 2);
        for (i, m) in [(0usize, 1usize), (1, 2)] {
            assert_eq!(r.string("name").unwrap(), names[i]);
            assert_eq!(r.u32("dim").unwrap() as usize, m);
            r.seq_f64("error", &mut v).unwrap();
            assert_eq!(v, t.task_error[i][..m]);
            for _ in 0..3 {
                r.seq_f64("goal/gains", &mut v).unwrap();
                assert_eq!(v.len(), m);
            }
            for _ in 0..3 {
                r.f64("scalars").unwrap();
            }
            assert_eq!(r.bool("singular").unwrap(), i == 1);
        }
        let n = TelemetryCounters::COUNT + 1;
        assert_eq!(r.seq_len("counter_names").unwrap(), n);
        let names: Vec<String> = (0..n).map(|_| r.string("c").unwrap().to_owned()).collect();
        assert_eq!(names[0], "cycles");
        assert_eq!(names[n - 1], "bridge_x");
        assert_eq!(r.seq_len("counter_values").unwrap(), n);
        for _ in 0..n - 1 {
            r.u64("v").unwrap();
        }
        assert_eq!(r.u64("v").unwrap(), 5);
        assert_eq!(r.seq_len("answers").unwrap(), 1, "empty slots are left out");
        let ids: [u64; 3] = std::array::from_fn(|_| r.u64("a").unwrap());
        assert_eq!(ids, [7, 4, 4]);
        assert_eq!(r.u32("code").unwrap(), 16);
        assert_eq!(r.string("reason").unwrap(), "outside_workspace");
        assert_eq!(r.u32("level").unwrap(), 1);
        r.f64("duration").unwrap();
        assert_eq!((r.u32("rej").unwrap(), r.u32("late").unwrap()), (2, 0));
        assert_eq!(r.u64("bridge id").unwrap(), 42);
        assert_eq!(r.seq_len("remote").unwrap(), 1);
        assert!((0..16).all(|_| r.u8("gid").unwrap() == 9));
        assert_eq!(r.i64("seq").unwrap(), -3);
        assert_eq!(
            (r.u32("l").unwrap(), r.u32("c").unwrap()),
            (1, REFUSED_RATE)
        );
        assert_eq!(r.string("reason").unwrap(), "rate");
        assert_eq!(r.f64("d").unwrap(), 0.5);
        r.seq_f64("tau_ext", &mut v).unwrap();
        assert_eq!(v, [0.125, -7.0]);
        assert_eq!(r.f64("h").unwrap(), 12.5);
        for (name, want) in [
            ("potential", [3.0, 0.5]),
            ("tank", [0.0, 2.25]),
            ("tank_valve", [1.0, 0.75]),
        ] {
            r.seq_f64(name, &mut v).unwrap();
            assert_eq!(v, want, "{name}");
        }
        for want in [0.5, 0.01, -0.02, 0.1, 0.25] {
            assert_eq!(r.f64("load").unwrap(), want);
        }
        assert_eq!(r.remaining(), 0);
    }

    fn goal_header(w: &mut CdrWriter, frame: &str) {
        w.start().i32(1).u32(2).string(frame);
    }

    #[test]
    fn goals_are_read() {
        let mut w = CdrWriter::new();
        goal_header(&mut w, "world");
        for v in [0.1, 0.2, 0.3, 0.0, 0.0, 0.0, 1.0] {
            w.f64(v);
        }
        assert_eq!(
            read_goal(&POSE_STAMPED, w.bytes()).unwrap(),
            GoalMsg::Pose {
                frame: "world".into(),
                position: [0.1, 0.2, 0.3],
                orientation: [0.0, 0.0, 0.0, 1.0]
            }
        );
        goal_header(&mut w, "");
        w.f64(1.0).f64(2.0).f64(3.0);
        assert_eq!(
            read_goal(&POINT_STAMPED, w.bytes()).unwrap(),
            GoalMsg::Point {
                frame: "".into(),
                point: [1.0, 2.0, 3.0]
            }
        );
        goal_header(&mut w, "base");
        w.f64(0.0).f64(0.0).f64(1.0).f64(0.0);
        assert!(matches!(
            read_goal(&QUATERNION_STAMPED, w.bytes()).unwrap(),
            GoalMsg::Quaternion {
                quaternion: [0.0, 0.0, 1.0, 0.0],
                ..
            }
        ));
        w.start().seq_len(1).string("joints").u32(3).u32(3).u32(1);
        w.seq_f64(&[9.0, 1.0, 2.0, 3.0]);
        assert_eq!(
            read_goal(&FLOAT64_MULTI_ARRAY, w.bytes()).unwrap(),
            GoalMsg::Array(vec![1.0, 2.0, 3.0])
        );
        // Truncated: an error.
        assert!(read_goal(&POSE_STAMPED, &w.bytes()[..10]).is_err());
    }
}
