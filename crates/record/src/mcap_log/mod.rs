//! Recordings of a run in MCAP, the log container of the robotics tools
//! (Foxglove, PlotJuggler, ROS 2 bags): one file, one channel per stream of
//! the hcc-msgs contract, JSON messages with a JSON Schema per channel, and
//! metadata records that say what was recorded.
//!
//! # File layout
//!
//! | channel           | message                          | one per                     |
//! |-------------------|----------------------------------|-----------------------------|
//! | `/joint_state`    | [`JointStateMsg`]                | driver state (1 kHz)        |
//! | `/torque_command` | [`TorqueCommandMsg`]             | controller command          |
//! | `/telemetry`      | [`TelemetryMsg`] (per level: `error`, `S`, `tau`, …; `tau_mu`, `P_mu`) | controller cycle |
//! | `/setpoint`       | [`SetpointMsg`]                  | client setpoint             |
//! | `/recorder`       | [`RecorderMsg`] (received, gaps) | second, and the last one    |
//! | `/path`           | [`PathMsg`]                      | client path message         |
//! | `/load`           | [`LoadMsg`]                      | client load message         |
//!
//! Metadata records: [`META_RUN`] (hcc and iceoryx2 versions, the recorder,
//! namespace, start time, control rate), [`META_SCENARIO`] (the scenario
//! TOML text, its path, the URDF's robot name, path and SHA-256),
//! [`META_MACHINE`] (the machine facts of `hcc jitter`), and at a clean end
//! [`META_END`] (the final counts and why the recording ended).
//!
//! A message's log and publish times are its own stamp (CLOCK_MONOTONIC of
//! the publisher) shifted to Unix time by the offset measured when the
//! recording started, so the streams line up in a viewer's timeline.
//!
//! # Crash safety and memory
//!
//! Messages go into zstd-compressed chunks; [`McapWriter`] closes the chunk
//! and hands it to the kernel at least once per second of wall time
//! ([`FLUSH_INTERVAL`]) and whenever it exceeds [`CHUNK_SIZE`] bytes
//! uncompressed. A recorder killed with SIGKILL leaves a file that lacks
//! only its summary section and the chunk in progress; [`read`] reads such a
//! file up to its last complete chunk and says it was truncated. The writer
//! holds one chunk at most and a small index per chunk (memory independent
//! of the run's length for any practical run: ~100 B per flushed chunk).

mod load_msg;
mod messages;
mod path_msg;
pub mod schemas;

pub use load_msg::LoadMsg;
pub use messages::{
    AnswerMsg, JointStateMsg, LevelMsg, RecorderMsg, SetpointMsg, StreamStats, TelemetryLoadMsg,
    TelemetryMsg, TimingsMsg, TorqueCommandMsg, mode_name, status_name,
};
pub use path_msg::PathMsg;
pub use schemas::schema;

use hcc_msgs::{JointState, LoadSetpoint, PathKnots, Setpoint, Telemetry, TorqueCommand};
use mcap::records::{MessageHeader, Metadata};
use mcap::sans_io::{LinearReadEvent, LinearReader, LinearReaderOptions};
use std::collections::BTreeMap;
use std::fs::File;
use std::io::{BufWriter, Read, Write};
use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

/// Topic of the joint states.
pub const TOPIC_JOINT_STATE: &str = "/joint_state";
/// Topic of the torque commands.
pub const TOPIC_TORQUE_COMMAND: &str = "/torque_command";
/// Topic of the controller's telemetry.
pub const TOPIC_TELEMETRY: &str = "/telemetry";
/// Topic of the clients' setpoints.
pub const TOPIC_SETPOINT: &str = "/setpoint";
/// Topic of the recorder's own counts (drops, gaps).
pub const TOPIC_RECORDER: &str = "/recorder";
/// Topic of the clients' path knots (after the others: added later).
pub const TOPIC_PATH: &str = "/path";
/// Topic of the clients' load messages (after the others: added later).
pub const TOPIC_LOAD: &str = "/load";
/// Every topic, in channel order.
pub const TOPICS: [&str; 7] = [
    TOPIC_JOINT_STATE,
    TOPIC_TORQUE_COMMAND,
    TOPIC_TELEMETRY,
    TOPIC_SETPOINT,
    TOPIC_RECORDER,
    TOPIC_PATH,
    TOPIC_LOAD,
];

/// Metadata record of the run (versions, recorder, namespace, start time).
pub const META_RUN: &str = "hcc_run";
/// Metadata record of the scenario (TOML text, URDF name and hash).
pub const META_SCENARIO: &str = "hcc_scenario";
/// Metadata record of the machine.
pub const META_MACHINE: &str = "hcc_machine";
/// Metadata record written at a clean end (final counts, end reason).
pub const META_END: &str = "hcc_recording_end";

/// Uncompressed size at which a chunk is closed, bytes.
pub const CHUNK_SIZE: u64 = 1 << 20;
/// Longest time a message waits in an open chunk.
pub const FLUSH_INTERVAL: Duration = Duration::from_secs(1);
/// The profile string of the file header.
pub const PROFILE: &str = "hcc";

/// Errors of writing or reading a recording; each names the file.
#[derive(Debug, thiserror::Error)]
pub enum LogError {
    #[error("{}: {error}", path.display())]
    Io {
        path: PathBuf,
        error: std::io::Error,
    },
    #[error("{}: {error}", path.display())]
    Mcap {
        path: PathBuf,
        error: mcap::McapError,
    },
    #[error("{}: {message}", path.display())]
    Format { path: PathBuf, message: String },
}

/// What a recording says about itself, written as metadata records when it
/// is created. Each map is one record (values are strings, as MCAP wants).
#[derive(Clone, Debug, Default)]
pub struct RunInfo {
    pub run: BTreeMap<String, String>,
    pub scenario: BTreeMap<String, String>,
    pub machine: BTreeMap<String, String>,
}

/// A JSON object's entries as metadata strings (strings as they are, other
/// values as JSON).
pub fn json_entries(value: &serde_json::Value) -> BTreeMap<String, String> {
    let mut out = BTreeMap::new();
    if let Some(obj) = value.as_object() {
        for (k, v) in obj {
            let s = match v {
                serde_json::Value::String(s) => s.clone(),
                other => other.to_string(),
            };
            out.insert(k.clone(), s);
        }
    }
    out
}

/// Hex SHA-256 of `bytes`.
pub fn sha256_hex(bytes: &[u8]) -> String {
    use sha2::Digest;
    let digest = sha2::Sha256::digest(bytes);
    digest.iter().map(|b| format!("{b:02x}")).collect()
}

impl RunInfo {
    /// The scenario record of `scenario`: its TOML text as loaded, path,
    /// name, the URDF's path, text, robot name and SHA-256, the levels'
    /// path files with their texts (`paths`, JSON) — what a replay
    /// or a plot needs to build the scenario again without the files.
    pub fn describe_scenario(scenario: &hcc_config::Scenario) -> BTreeMap<String, String> {
        let mut m = BTreeMap::new();
        m.insert("name".into(), scenario.name.clone());
        let path = std::fs::canonicalize(&scenario.path).unwrap_or_else(|_| scenario.path.clone());
        m.insert("path".into(), path.display().to_string());
        m.insert("toml".into(), scenario.text().to_string());
        m.insert("urdf_path".into(), scenario.urdf_path.display().to_string());
        if let Ok(urdf) = std::fs::read(&scenario.urdf_path) {
            m.insert("urdf_sha256".into(), sha256_hex(&urdf));
            m.insert("urdf_bytes".into(), urdf.len().to_string());
            m.insert("urdf_name".into(), robot_name(&urdf).unwrap_or_default());
            if let Ok(text) = String::from_utf8(urdf) {
                m.insert("urdf".into(), text);
            }
        }
        let paths = scenario.path_texts();
        if !paths.is_empty() {
            // The levels' path files (`trajectory`) with their texts.
            m.insert(
                "paths".into(),
                serde_json::to_string(&paths).unwrap_or_default(),
            );
        }
        m.insert("n_joints".into(), scenario.model.nq().to_string());
        m.insert("control_rate_hz".into(), scenario.rate_hz.to_string());
        m.insert(
            "levels".into(),
            serde_json::to_string(
                &scenario
                    .levels()
                    .iter()
                    .map(|l| l.name.clone())
                    .collect::<Vec<_>>(),
            )
            .unwrap_or_default(),
        );
        m
    }
}

/// The `name` attribute of the URDF's `<robot>` element.
fn robot_name(urdf: &[u8]) -> Option<String> {
    let text = std::str::from_utf8(urdf).ok()?;
    let start = text.find("<robot")?;
    let tag = &text[start..start + text[start..].find('>')?];
    let at = tag.find("name")?;
    let rest = tag[at + 4..].trim_start().strip_prefix('=')?.trim_start();
    let quote = rest.chars().next()?;
    let rest = &rest[1..];
    Some(rest[..rest.find(quote)?].to_string())
}

/// Nanoseconds since the Unix epoch now, and CLOCK_MONOTONIC now: the pair
/// that maps message stamps onto the timeline.
pub fn clock_pair() -> (u64, u64) {
    let unix = std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map_or(0, |d| d.as_nanos() as u64);
    (unix, hcc_msgs::monotonic_now_ns())
}

/// Channel ids of the topics, in [`TOPICS`] order.
type Channels = [u16; TOPICS.len()];

/// Streams messages into an MCAP file (see the module documentation).
pub struct McapWriter {
    path: PathBuf,
    writer: Option<mcap::Writer<BufWriter<File>>>,
    channels: Channels,
    sequence: [u32; TOPICS.len()],
    /// Unix ns minus monotonic ns at the start.
    offset_ns: i128,
    last_flush: Instant,
    buf: Vec<u8>,
    messages: u64,
}

impl McapWriter {
    /// Creates `path` (its directory too), writes the header, the channels
    /// and schemas and the metadata of `info`, and flushes it. `clock`:
    /// (Unix ns, monotonic ns) at one instant ([`clock_pair`]), which maps
    /// the messages' stamps onto Unix time.
    pub fn create(path: &Path, info: &RunInfo, clock: (u64, u64)) -> Result<McapWriter, LogError> {
        let io = |error| LogError::Io {
            path: path.to_path_buf(),
            error,
        };
        if let Some(dir) = path.parent().filter(|d| !d.as_os_str().is_empty()) {
            std::fs::create_dir_all(dir).map_err(io)?;
        }
        let file = File::create(path).map_err(io)?;
        let mcap_err = |error: mcap::McapError| LogError::Mcap {
            path: path.to_path_buf(),
            error,
        };
        let mut writer = mcap::WriteOptions::new()
            .profile(PROFILE)
            .library(format!("hcc {}", env!("CARGO_PKG_VERSION")))
            .compression(Some(mcap::Compression::Zstd))
            .compression_threads(0)
            .chunk_size(Some(CHUNK_SIZE))
            .create(BufWriter::with_capacity(1 << 16, file))
            .map_err(mcap_err)?;
        let mut channels = [0; TOPICS.len()];
        for (k, topic) in TOPICS.iter().enumerate() {
            let (name, schema) = schemas::schema(topic);
            let schema_id = writer
                .add_schema(name, "jsonschema", schema.as_bytes())
                .map_err(mcap_err)?;
            channels[k] = writer
                .add_channel(schema_id, topic, "json", &BTreeMap::new())
                .map_err(mcap_err)?;
        }
        for (name, map) in [
            (META_RUN, &info.run),
            (META_SCENARIO, &info.scenario),
            (META_MACHINE, &info.machine),
        ] {
            writer
                .write_metadata(&Metadata {
                    name: name.into(),
                    metadata: map.clone(),
                })
                .map_err(mcap_err)?;
        }
        writer.flush().map_err(mcap_err)?;
        Ok(McapWriter {
            path: path.to_path_buf(),
            writer: Some(writer),
            channels,
            sequence: [0; TOPICS.len()],
            offset_ns: clock.0 as i128 - clock.1 as i128,
            last_flush: Instant::now(),
            buf: Vec::with_capacity(8192),
            messages: 0,
        })
    }

    /// The file being written.
    pub fn path(&self) -> &Path {
        &self.path
    }

    /// Messages written so far.
    pub fn messages(&self) -> u64 {
        self.messages
    }

    fn mcap_err(&self, error: mcap::McapError) -> LogError {
        LogError::Mcap {
            path: self.path.clone(),
            error,
        }
    }

    /// Unix time of a monotonic stamp.
    fn log_time(&self, stamp_ns: u64) -> u64 {
        (stamp_ns as i128 + self.offset_ns).clamp(0, u64::MAX as i128) as u64
    }

    fn write<T: serde::Serialize>(
        &mut self,
        k: usize,
        stamp_ns: u64,
        msg: &T,
    ) -> Result<(), LogError> {
        self.buf.clear();
        serde_json::to_writer(&mut self.buf, msg).map_err(|e| LogError::Format {
            path: self.path.clone(),
            message: format!("cannot encode a {} message: {e}", TOPICS[k]),
        })?;
        self.sequence[k] = self.sequence[k].wrapping_add(1);
        let time = self.log_time(stamp_ns);
        let header = MessageHeader {
            channel_id: self.channels[k],
            sequence: self.sequence[k],
            log_time: time,
            publish_time: time,
        };
        let Some(w) = self.writer.as_mut() else {
            return Err(LogError::Format {
                path: self.path.clone(),
                message: "the recording is closed".into(),
            });
        };
        let r = w.write_to_known_channel(&header, &self.buf);
        r.map_err(|e| self.mcap_err(e))?;
        self.messages += 1;
        self.flush_if_due()
    }

    /// Closes the open chunk and hands it to the kernel if the last flush
    /// is [`FLUSH_INTERVAL`] ago.
    pub fn flush_if_due(&mut self) -> Result<(), LogError> {
        if self.last_flush.elapsed() >= FLUSH_INTERVAL {
            self.flush()?;
        }
        Ok(())
    }

    /// Closes the open chunk and hands it to the kernel now.
    pub fn flush(&mut self) -> Result<(), LogError> {
        self.last_flush = Instant::now();
        if let Some(w) = self.writer.as_mut() {
            let r = w.flush();
            r.map_err(|e| self.mcap_err(e))?;
        }
        Ok(())
    }

    pub fn joint_state(&mut self, s: &JointState) -> Result<(), LogError> {
        self.write(0, s.header.stamp_ns, &JointStateMsg::from(s))
    }

    pub fn torque_command(&mut self, c: &TorqueCommand) -> Result<(), LogError> {
        self.write(1, c.header.stamp_ns, &TorqueCommandMsg::from(c))
    }

    pub fn telemetry(&mut self, t: &Telemetry) -> Result<(), LogError> {
        self.write(2, t.header.stamp_ns, &TelemetryMsg::from(t))
    }

    pub fn setpoint(&mut self, s: &Setpoint) -> Result<(), LogError> {
        self.write(3, s.header.stamp_ns, &SetpointMsg::from(s))
    }

    /// Appends a client's path message.
    pub fn path_knots(&mut self, p: &PathKnots) -> Result<(), LogError> {
        self.write(5, p.header.stamp_ns, &PathMsg::from(p))
    }

    /// Appends a client's load message.
    pub fn load(&mut self, l: &LoadSetpoint) -> Result<(), LogError> {
        self.write(6, l.header.stamp_ns, &LoadMsg::from(l))
    }

    /// The recorder's counts, stamped `now_ns` (monotonic).
    pub fn recorder(&mut self, r: &RecorderMsg, now_ns: u64) -> Result<(), LogError> {
        self.write(4, now_ns, r)
    }

    /// Writes the final counts (as a `/recorder` message and the
    /// [`META_END`] record with `end`), the summary and closes the file.
    pub fn finish(
        mut self,
        last: &RecorderMsg,
        end: BTreeMap<String, String>,
    ) -> Result<(), LogError> {
        let mut last = last.clone();
        last.last = true;
        last.update_total();
        self.recorder(&last, hcc_msgs::monotonic_now_ns())?;
        let mut end = end;
        if let Ok(serde_json::Value::Object(counts)) = serde_json::to_value(&last) {
            for (k, v) in counts {
                end.entry(k).or_insert_with(|| v.to_string());
            }
        }
        let mut w = self.writer.take().ok_or_else(|| LogError::Format {
            path: self.path.clone(),
            message: "the recording is closed".into(),
        })?;
        let path = self.path.clone();
        let mcap_err = |error: mcap::McapError| LogError::Mcap {
            path: path.clone(),
            error,
        };
        w.write_metadata(&Metadata {
            name: META_END.into(),
            metadata: end,
        })
        .map_err(mcap_err)?;
        w.finish().map_err(mcap_err)?;
        let mut inner = w.into_inner();
        inner.flush().map_err(|error| LogError::Io {
            path: path.clone(),
            error,
        })?;
        Ok(())
    }
}

impl Drop for McapWriter {
    fn drop(&mut self) {
        // Not finished (an error on the way): keep what was written readable.
        if let Some(mut w) = self.writer.take() {
            let _ = w.flush();
            let _ = w.finish();
        }
    }
}

/// One entry of a recording, in file order.
#[derive(Clone, Debug)]
pub enum Entry {
    JointState(JointStateMsg),
    TorqueCommand(TorqueCommandMsg),
    Telemetry(Box<TelemetryMsg>),
    Setpoint(Box<SetpointMsg>),
    Path(Box<PathMsg>),
    Load(Box<LoadMsg>),
    Recorder(Box<RecorderMsg>),
    /// A metadata record: its name and entries.
    Metadata(String, BTreeMap<String, String>),
}

/// How far [`read`] got.
#[derive(Clone, Debug, Default)]
pub struct ReadSummary {
    /// Messages per topic.
    pub messages: BTreeMap<String, u64>,
    /// Why the file ends early (it has no summary: the recorder was killed),
    /// or `None` for a complete file.
    pub truncated: Option<String>,
}

/// Reads the recording at `path` in file order and hands every entry (with
/// its log time, ns since the Unix epoch; 0 for metadata) to `visit`. A
/// truncated file (a recorder killed mid-run) is read up to its last
/// complete chunk, and [`ReadSummary::truncated`] says so. Messages of
/// other topics are skipped; a message that does not decode is an error.
pub fn read<E: From<LogError>>(
    path: &Path,
    mut visit: impl FnMut(u64, Entry) -> Result<(), E>,
) -> Result<ReadSummary, E> {
    let io = |error| LogError::Io {
        path: path.to_path_buf(),
        error,
    };
    let mut file = File::open(path).map_err(io)?;
    let mut reader = LinearReader::new_with_options(
        LinearReaderOptions::default()
            // A chunk is checked whole before any of its messages is used:
            // a chunk cut short by a crash yields nothing.
            .with_prevalidate_chunk_crcs(true)
            .with_record_length_limit(1 << 30),
    );
    let mut topics: BTreeMap<u16, String> = BTreeMap::new();
    let mut summary = ReadSummary::default();
    let mut saw_footer = false;
    let format = |message: String| LogError::Format {
        path: path.to_path_buf(),
        message,
    };
    while let Some(event) = reader.next_event() {
        let event = match event {
            Ok(e) => e,
            Err(e) => {
                if saw_footer {
                    break;
                }
                summary.truncated = Some(e.to_string());
                break;
            }
        };
        match event {
            LinearReadEvent::ReadRequest(n) => {
                let buf = reader.insert(n);
                let got = file.read(buf).map_err(io)?;
                reader.notify_read(got);
            }
            LinearReadEvent::Record { data, opcode } => {
                let record = match mcap::parse_record(opcode, data) {
                    Ok(r) => r,
                    Err(e) => {
                        summary.truncated = Some(e.to_string());
                        break;
                    }
                };
                match record {
                    mcap::records::Record::Channel(c) => {
                        topics.insert(c.id, c.topic);
                    }
                    mcap::records::Record::Metadata(m) => {
                        visit(0, Entry::Metadata(m.name, m.metadata))?;
                    }
                    mcap::records::Record::Footer(_) => saw_footer = true,
                    mcap::records::Record::Message { header, data } => {
                        let Some(topic) = topics.get(&header.channel_id) else {
                            return Err(format(format!(
                                "a message on unknown channel {}",
                                header.channel_id
                            ))
                            .into());
                        };
                        let decode = |e: serde_json::Error| {
                            format(format!("a {topic} message does not decode: {e}"))
                        };
                        let entry = match topic.as_str() {
                            TOPIC_JOINT_STATE => {
                                Entry::JointState(serde_json::from_slice(&data).map_err(decode)?)
                            }
                            TOPIC_TORQUE_COMMAND => {
                                Entry::TorqueCommand(serde_json::from_slice(&data).map_err(decode)?)
                            }
                            TOPIC_TELEMETRY => {
                                Entry::Telemetry(serde_json::from_slice(&data).map_err(decode)?)
                            }
                            TOPIC_SETPOINT => {
                                Entry::Setpoint(serde_json::from_slice(&data).map_err(decode)?)
                            }
                            TOPIC_PATH => {
                                Entry::Path(serde_json::from_slice(&data).map_err(decode)?)
                            }
                            TOPIC_LOAD => {
                                Entry::Load(serde_json::from_slice(&data).map_err(decode)?)
                            }
                            TOPIC_RECORDER => {
                                Entry::Recorder(serde_json::from_slice(&data).map_err(decode)?)
                            }
                            _ => continue,
                        };
                        *summary.messages.entry(topic.clone()).or_insert(0) += 1;
                        visit(header.log_time, entry)?;
                    }
                    _ => {}
                }
            }
        }
    }
    if !saw_footer && summary.truncated.is_none() {
        summary.truncated = Some("the file ends without its summary".into());
    }
    Ok(summary)
}

/// A helper for tests and tools: the metadata records of a recording.
pub fn read_metadata(path: &Path) -> Result<BTreeMap<String, BTreeMap<String, String>>, LogError> {
    let mut out = BTreeMap::new();
    read::<LogError>(path, |_, e| {
        if let Entry::Metadata(name, map) = e {
            out.insert(name, map);
        }
        Ok(())
    })?;
    Ok(out)
}
