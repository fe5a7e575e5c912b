//! The JSON messages of a recording, one type per channel, converted from
//! and back to the contract's messages (hcc-msgs) without loss: numbers are
//! written in their shortest round-trip form and read back bit-identically
//! (NaN and ±∞, which JSON cannot hold, are written as `null` and read back
//! as NaN; the controller rejects both alike).
//!
//! Field names follow the paper: per level `error` (x̃_i), `S` (storage
//! S_i, eqs. 26/28), `tau` (τ_i, eqs. 20/21); at the top `tau` (τ, eq. 19),
//! `tau_mu` (τ_μ, eq. 22), `tau_gravity` (g(q)), `P_mu` (τ_μᵀ q̇) and `H`
//! (the storage of the arm and the controller; per level `V`, its potential
//! as H counts it).

use hcc_msgs::{
    CommandMode, DriverStatus, Header, JointState, MAX_GAIN_ENTRIES, MAX_JOINTS, MAX_LEVELS,
    MAX_SETPOINT_CLIENTS, MAX_TASK_DIM, Setpoint, SetpointAnswer, Telemetry, TelemetryCounters,
    TelemetryTimings, TorqueCommand,
};
use serde::{Deserialize, Deserializer, Serialize};
use std::collections::BTreeMap;

/// NaN: a field that a recording made before it was added lacks.
fn nan() -> f64 {
    f64::NAN
}

/// Reads a number or `null` (NaN).
pub(super) fn num<'de, D: Deserializer<'de>>(d: D) -> Result<f64, D::Error> {
    Ok(Option::<f64>::deserialize(d)?.unwrap_or(f64::NAN))
}

/// Reads an array of numbers or `null`s (NaN).
pub(super) fn nums<'de, D: Deserializer<'de>>(d: D) -> Result<Vec<f64>, D::Error> {
    Ok(Vec::<Option<f64>>::deserialize(d)?
        .into_iter()
        .map(|v| v.unwrap_or(f64::NAN))
        .collect())
}

/// Copies `src` into the front of `dst`, or fails naming the field.
fn fill(dst: &mut [f64], src: &[f64], what: &str) -> Result<(), String> {
    if src.len() > dst.len() {
        return Err(format!(
            "{what} has {} entries, the capacity is {}",
            src.len(),
            dst.len()
        ));
    }
    dst[..src.len()].copy_from_slice(src);
    Ok(())
}

fn header(seq: u64, stamp_ns: u64, n: usize) -> Result<Header, String> {
    if n > MAX_JOINTS {
        return Err(format!("{n} joints, the capacity is {MAX_JOINTS}"));
    }
    let mut h = Header::new();
    h.seq = seq;
    h.stamp_ns = stamp_ns;
    h.n_joints = n as u32;
    Ok(h)
}

/// Name of a driver status code.
pub fn status_name(code: u32) -> &'static str {
    match DriverStatus::from_code(code) {
        Ok(DriverStatus::Ok) => "ok",
        Ok(DriverStatus::FallbackActive) => "fallback_active",
        Ok(DriverStatus::Stopping) => "stopping",
        Ok(DriverStatus::Stopped) => "stopped",
        Err(_) => "unknown",
    }
}

/// Name of a command mode code.
pub fn mode_name(code: u32) -> &'static str {
    match CommandMode::from_code(code) {
        Ok(CommandMode::Normal) => "normal",
        Ok(CommandMode::SafeHold) => "safe_hold",
        Ok(CommandMode::Singular) => "singular",
        Ok(CommandMode::Stop) => "stop",
        Err(_) => "unknown",
    }
}

/// `/joint_state`: a [`JointState`].
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct JointStateMsg {
    pub seq: u64,
    /// Sampling instant, CLOCK_MONOTONIC ns.
    pub stamp_ns: u64,
    pub schema_version: u32,
    pub status: String,
    pub status_code: u32,
    pub flags: u32,
    pub missed_commands: u64,
    pub fallback_cycles: u64,
    #[serde(deserialize_with = "nums")]
    pub q: Vec<f64>,
    #[serde(deserialize_with = "nums")]
    pub qd: Vec<f64>,
    #[serde(deserialize_with = "nums")]
    pub tau_measured: Vec<f64>,
}

impl From<&JointState> for JointStateMsg {
    fn from(s: &JointState) -> Self {
        JointStateMsg {
            seq: s.header.seq,
            stamp_ns: s.header.stamp_ns,
            schema_version: s.header.schema_version,
            status: status_name(s.status).into(),
            status_code: s.status,
            flags: s.flags,
            missed_commands: s.missed_commands,
            fallback_cycles: s.fallback_cycles,
            q: s.q().to_vec(),
            qd: s.qd().to_vec(),
            tau_measured: s.tau_measured().to_vec(),
        }
    }
}

impl JointStateMsg {
    /// The contract message (entries beyond n zero, as writers keep them).
    pub fn to_msg(&self) -> Result<JointState, String> {
        let mut s = JointState::zeroed();
        s.header = header(self.seq, self.stamp_ns, self.q.len())?;
        s.header.schema_version = self.schema_version;
        s.status = self.status_code;
        s.flags = self.flags;
        s.missed_commands = self.missed_commands;
        s.fallback_cycles = self.fallback_cycles;
        fill(&mut s.q, &self.q, "q")?;
        fill(&mut s.qd, &self.qd, "qd")?;
        fill(&mut s.tau_measured, &self.tau_measured, "tau_measured")?;
        Ok(s)
    }
}

/// `/torque_command`: a [`TorqueCommand`].
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct TorqueCommandMsg {
    pub seq: u64,
    /// End of the computation, CLOCK_MONOTONIC ns.
    pub stamp_ns: u64,
    /// The state it answers.
    pub state_seq: u64,
    pub state_stamp_ns: u64,
    pub mode: String,
    pub mode_code: u32,
    pub flags: u32,
    /// τ of eq. (19), N·m.
    #[serde(deserialize_with = "nums")]
    pub tau: Vec<f64>,
}

impl From<&TorqueCommand> for TorqueCommandMsg {
    fn from(c: &TorqueCommand) -> Self {
        TorqueCommandMsg {
            seq: c.header.seq,
            stamp_ns: c.header.stamp_ns,
            state_seq: c.state_seq,
            state_stamp_ns: c.state_stamp_ns,
            mode: mode_name(c.mode).into(),
            mode_code: c.mode,
            flags: c.flags,
            tau: c.tau().to_vec(),
        }
    }
}

impl TorqueCommandMsg {
    /// The contract message.
    pub fn to_msg(&self) -> Result<TorqueCommand, String> {
        let mut c = TorqueCommand::zeroed();
        c.header = header(self.seq, self.stamp_ns, self.tau.len())?;
        c.state_seq = self.state_seq;
        c.state_stamp_ns = self.state_stamp_ns;
        c.mode = self.mode_code;
        c.flags = self.flags;
        fill(&mut c.tau, &self.tau, "tau")?;
        Ok(c)
    }
}

/// One level of a [`TelemetryMsg`] (level numbers 1-based, as in the paper).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct LevelMsg {
    /// 1-based level i.
    pub level: u32,
    /// Task error x̃_i (m_i entries).
    #[serde(deserialize_with = "nums")]
    pub error: Vec<f64>,
    /// ‖x̃_i‖ (for a quick plot; not read back).
    #[serde(deserialize_with = "num")]
    pub error_norm: f64,
    /// Storage function S_i, eqs. (26)/(28).
    #[serde(rename = "S", deserialize_with = "num")]
    pub storage: f64,
    /// The level's potential as H counts it (V_1, β_i V_i; client schema 6,
    /// NaN in recordings made before it).
    #[serde(rename = "V", default = "nan", deserialize_with = "num")]
    pub potential: f64,
    /// The energy in the level's energy tank, J, and the tank's valve in
    /// [0, 1] (client schema 6; NaN in recordings made before it).
    #[serde(default = "nan", deserialize_with = "num")]
    pub tank: f64,
    #[serde(default = "nan", deserialize_with = "num")]
    pub valve: f64,
    /// Torque τ_i of the level, eqs. (20)/(21) (n entries).
    #[serde(deserialize_with = "nums")]
    pub tau: Vec<f64>,
    /// Smallest singular value of the level's (projected) Jacobian.
    #[serde(deserialize_with = "num")]
    pub sigma_min: f64,
    pub singular: bool,
    /// Active goal x_{i,d}(t).
    #[serde(deserialize_with = "nums")]
    pub goal: Vec<f64>,
    /// Diagonal of K_i(t).
    #[serde(deserialize_with = "nums")]
    pub stiffness: Vec<f64>,
    /// Diagonal of D_i(t).
    #[serde(deserialize_with = "nums")]
    pub damping: Vec<f64>,
    #[serde(deserialize_with = "num")]
    pub transition_progress: f64,
}

/// `/telemetry`: a [`Telemetry`] sample (one per controller cycle).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct TelemetryMsg {
    pub seq: u64,
    pub stamp_ns: u64,
    pub state_seq: u64,
    pub command_seq: u64,
    pub mode: String,
    pub mode_code: u32,
    pub flags: u32,
    pub singular_levels: u32,
    /// τ, eq. (19).
    #[serde(deserialize_with = "nums")]
    pub tau: Vec<f64>,
    /// τ_μ, eq. (22).
    #[serde(deserialize_with = "nums")]
    pub tau_mu: Vec<f64>,
    /// g(q) (zero when the driver adds gravity).
    #[serde(deserialize_with = "nums")]
    pub tau_gravity: Vec<f64>,
    /// r, the estimate of the external joint torque (client schema 4;
    /// empty in recordings made before it).
    #[serde(default, deserialize_with = "nums")]
    pub tau_ext: Vec<f64>,
    /// P_μ = τ_μᵀ q̇.
    #[serde(rename = "P_mu", deserialize_with = "num")]
    pub p_mu: f64,
    /// H, the storage of the arm and the controller (client schema 6; NaN
    /// in recordings made before it).
    #[serde(rename = "H", default = "nan", deserialize_with = "num")]
    pub h: f64,
    /// The load the controller's model carries (client schema 8; no load in
    /// recordings made before it).
    #[serde(default)]
    pub load: TelemetryLoadMsg,
    pub levels: Vec<LevelMsg>,
    pub counters: BTreeMap<String, u64>,
    pub timings: TimingsMsg,
    /// Non-empty answer slots only.
    pub setpoint_answers: Vec<AnswerMsg>,
}

/// The load in [`Telemetry`]: `load_mass`, `load_com`, `load_progress`.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct TelemetryLoadMsg {
    /// kg.
    #[serde(deserialize_with = "num")]
    pub mass: f64,
    /// Centre of mass in the tip frame, m.
    #[serde(deserialize_with = "nums")]
    pub com: Vec<f64>,
    /// The announced load's ramp in [0, 1] (1: none runs).
    #[serde(deserialize_with = "num")]
    pub progress: f64,
}

impl Default for TelemetryLoadMsg {
    fn default() -> Self {
        TelemetryLoadMsg {
            mass: 0.0,
            com: vec![0.0; 3],
            progress: 1.0,
        }
    }
}

/// [`TelemetryTimings`].
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct TimingsMsg {
    pub wakeup_latency_ns: i64,
    pub compute_ns: u64,
    pub period_ns: u64,
    pub max_compute_ns: u64,
}

/// A [`SetpointAnswer`] slot.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct AnswerMsg {
    pub slot: u32,
    pub client_id: u64,
    pub seq: u64,
    pub answered: u64,
    pub code: u32,
    pub level: u32,
    #[serde(deserialize_with = "num")]
    pub duration_s: f64,
    #[serde(default)]
    pub rejected: u32,
    #[serde(default)]
    pub late: u32,
    /// The knot a path message was refused for (absent in recordings
    /// before client schema 7: no knot).
    #[serde(default = "no_knot")]
    pub knot: u32,
}

fn no_knot() -> u32 {
    hcc_msgs::NO_KNOT
}

fn norm(v: &[f64]) -> f64 {
    v.iter().map(|x| x * x).sum::<f64>().sqrt()
}

impl From<&Telemetry> for TelemetryMsg {
    fn from(t: &Telemetry) -> Self {
        let n = t.n();
        let levels = (0..t.levels())
            .map(|i| {
                let m = (t.task_dims[i] as usize).min(MAX_TASK_DIM);
                LevelMsg {
                    level: i as u32 + 1,
                    error: t.task_error(i).to_vec(),
                    error_norm: norm(t.task_error(i)),
                    storage: t.storage[i],
                    potential: t.potential[i],
                    tank: t.tank[i],
                    valve: t.tank_valve[i],
                    tau: t.tau_level(i).to_vec(),
                    sigma_min: t.min_singular_value[i],
                    singular: t.is_singular(i),
                    goal: t.goal[i][..m].to_vec(),
                    stiffness: t.stiffness_diag[i][..m].to_vec(),
                    damping: t.damping_diag[i][..m].to_vec(),
                    transition_progress: t.transition_progress[i],
                }
            })
            .collect();
        TelemetryMsg {
            seq: t.header.seq,
            stamp_ns: t.header.stamp_ns,
            state_seq: t.state_seq,
            command_seq: t.command_seq,
            mode: mode_name(t.mode).into(),
            mode_code: t.mode,
            flags: t.flags,
            singular_levels: t.singular_levels,
            tau: t.tau().to_vec(),
            tau_mu: t.tau_mu[..n].to_vec(),
            tau_gravity: t.tau_gravity[..n].to_vec(),
            tau_ext: t.tau_ext().to_vec(),
            p_mu: t.p_mu,
            h: t.h,
            load: TelemetryLoadMsg {
                mass: t.load_mass,
                com: t.load_com.to_vec(),
                progress: t.load_progress,
            },
            levels,
            counters: t
                .counters
                .entries()
                .iter()
                .map(|&(k, v)| (k.to_string(), v))
                .collect(),
            timings: TimingsMsg {
                wakeup_latency_ns: t.timings.wakeup_latency_ns,
                compute_ns: t.timings.compute_ns,
                period_ns: t.timings.period_ns,
                max_compute_ns: t.timings.max_compute_ns,
            },
            setpoint_answers: t
                .setpoint_answers
                .iter()
                .enumerate()
                .filter(|(_, a)| a.answered > 0)
                .map(|(slot, a)| AnswerMsg {
                    slot: slot as u32,
                    client_id: a.client_id,
                    seq: a.seq,
                    answered: a.answered,
                    code: a.code,
                    level: a.level,
                    duration_s: a.duration_s,
                    rejected: a.rejected,
                    late: a.late,
                    knot: a.knot,
                })
                .collect(),
        }
    }
}

impl TelemetryMsg {
    /// The contract message (the fields the recording holds; `error_norm`
    /// is derived and not read).
    pub fn to_msg(&self) -> Result<Box<Telemetry>, String> {
        let n = self.tau.len();
        let mut t = Box::new(Telemetry::zeroed());
        let dims: Vec<usize> = self.levels.iter().map(|l| l.error.len()).collect();
        t.set_shape(n, &dims).map_err(|e| e.to_string())?;
        t.header.seq = self.seq;
        t.header.stamp_ns = self.stamp_ns;
        t.state_seq = self.state_seq;
        t.command_seq = self.command_seq;
        t.mode = self.mode_code;
        t.flags = self.flags;
        t.singular_levels = self.singular_levels;
        fill(&mut t.tau, &self.tau, "tau")?;
        fill(&mut t.tau_mu, &self.tau_mu, "tau_mu")?;
        fill(&mut t.tau_gravity, &self.tau_gravity, "tau_gravity")?;
        if !self.tau_ext.is_empty() {
            fill(&mut t.tau_ext, &self.tau_ext, "tau_ext")?;
        }
        t.p_mu = self.p_mu;
        t.h = self.h;
        t.load_mass = self.load.mass;
        fill(&mut t.load_com, &self.load.com, "load.com")?;
        t.load_progress = self.load.progress;
        if self.levels.len() > MAX_LEVELS {
            return Err(format!("{} levels", self.levels.len()));
        }
        for (i, l) in self.levels.iter().enumerate() {
            fill(&mut t.tau_level[i], &l.tau, "levels.tau")?;
            fill(&mut t.task_error[i], &l.error, "levels.error")?;
            fill(&mut t.goal[i], &l.goal, "levels.goal")?;
            fill(&mut t.stiffness_diag[i], &l.stiffness, "levels.stiffness")?;
            fill(&mut t.damping_diag[i], &l.damping, "levels.damping")?;
            t.storage[i] = l.storage;
            t.potential[i] = l.potential;
            t.tank[i] = l.tank;
            t.tank_valve[i] = l.valve;
            t.min_singular_value[i] = l.sigma_min;
            t.transition_progress[i] = l.transition_progress;
        }
        let mut values = [0; TelemetryCounters::COUNT];
        for (k, name) in TelemetryCounters::NAMES.iter().enumerate() {
            values[k] = self.counters.get(*name).copied().unwrap_or(0);
        }
        t.counters = TelemetryCounters::from_values(values);
        t.timings = TelemetryTimings {
            wakeup_latency_ns: self.timings.wakeup_latency_ns,
            compute_ns: self.timings.compute_ns,
            period_ns: self.timings.period_ns,
            max_compute_ns: self.timings.max_compute_ns,
        };
        for a in &self.setpoint_answers {
            let slot = a.slot as usize;
            if slot >= MAX_SETPOINT_CLIENTS {
                return Err(format!("setpoint answer slot {slot}"));
            }
            t.setpoint_answers[slot] = SetpointAnswer {
                client_id: a.client_id,
                seq: a.seq,
                answered: a.answered,
                code: a.code,
                level: a.level,
                duration_s: a.duration_s,
                rejected: a.rejected,
                late: a.late,
                knot: a.knot,
                reserved: 0,
            };
        }
        Ok(t)
    }
}

/// `/setpoint`: a client's [`Setpoint`] as the controller received it.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct SetpointMsg {
    pub seq: u64,
    pub stamp_ns: u64,
    pub schema_version: u32,
    pub n_joints: u32,
    pub client_id: u64,
    /// 0-based level, as sent.
    pub level: u32,
    pub fields: u32,
    pub dim: u32,
    pub gain_layout: u32,
    #[serde(deserialize_with = "num")]
    pub duration_s: f64,
    #[serde(default)]
    pub apply_at_state_seq: u64,
    #[serde(deserialize_with = "nums")]
    pub goal: Vec<f64>,
    #[serde(deserialize_with = "nums")]
    pub velocity: Vec<f64>,
    #[serde(deserialize_with = "nums")]
    pub stiffness: Vec<f64>,
    #[serde(deserialize_with = "nums")]
    pub damping: Vec<f64>,
}

/// The used prefix of a setpoint array (`dim`, or `dim²` for a full matrix),
/// clamped to the capacity.
fn prefix(values: &[f64], len: usize) -> Vec<f64> {
    values[..len.min(values.len())].to_vec()
}

impl From<&Setpoint> for SetpointMsg {
    fn from(s: &Setpoint) -> Self {
        let dim = (s.dim as usize).min(MAX_TASK_DIM);
        let full = |f: bool| if f { dim * dim } else { dim };
        SetpointMsg {
            seq: s.header.seq,
            stamp_ns: s.header.stamp_ns,
            schema_version: s.header.schema_version,
            n_joints: s.header.n_joints,
            client_id: s.client_id,
            level: s.level,
            fields: s.fields,
            dim: s.dim,
            gain_layout: s.gain_layout,
            duration_s: s.duration_s,
            apply_at_state_seq: s.apply_at_state_seq,
            goal: prefix(&s.goal, dim),
            velocity: prefix(&s.velocity, dim),
            stiffness: prefix(&s.stiffness, full(s.stiffness_full())),
            damping: prefix(&s.damping, full(s.damping_full())),
        }
    }
}

impl SetpointMsg {
    /// The contract message.
    pub fn to_msg(&self) -> Result<Setpoint, String> {
        let mut s = Setpoint::zeroed();
        s.header.seq = self.seq;
        s.header.stamp_ns = self.stamp_ns;
        s.header.schema_version = self.schema_version;
        s.header.n_joints = self.n_joints;
        s.client_id = self.client_id;
        s.level = self.level;
        s.fields = self.fields;
        s.dim = self.dim;
        s.gain_layout = self.gain_layout;
        s.duration_s = self.duration_s;
        s.apply_at_state_seq = self.apply_at_state_seq;
        fill(&mut s.goal, &self.goal, "goal")?;
        fill(&mut s.velocity, &self.velocity, "velocity")?;
        fill(
            &mut s.stiffness[..MAX_GAIN_ENTRIES],
            &self.stiffness,
            "stiffness",
        )?;
        fill(&mut s.damping[..MAX_GAIN_ENTRIES], &self.damping, "damping")?;
        Ok(s)
    }
}

/// Received and lost samples of one stream, as the recorder saw them.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
pub struct StreamStats {
    /// Samples received (accepted or not).
    pub received: u64,
    /// Samples recorded.
    pub recorded: u64,
    /// Samples lost: the sum of the sequence gaps.
    pub gaps: u64,
    /// Sequence gaps (events).
    pub gap_events: u64,
    pub duplicates: u64,
    pub backwards: u64,
    /// Times the stream started again below its last sequence number (a
    /// restarted publisher: a new driver or controller), counted apart from
    /// `backwards` and not as out of sequence.
    #[serde(default)]
    pub restarts: u64,
}

/// `/recorder`: what the recorder counted so far (once per second and at the end).
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct RecorderMsg {
    /// Wall time since the start of the recording, s.
    pub elapsed_s: f64,
    pub joint_state: StreamStats,
    pub torque_command: StreamStats,
    pub telemetry: StreamStats,
    pub setpoint: StreamStats,
    /// Path messages (absent in recordings made before they were recorded).
    #[serde(default)]
    pub path: StreamStats,
    /// Load messages (absent in recordings made before they were recorded).
    #[serde(default)]
    pub load: StreamStats,
    /// Samples lost on all streams.
    pub total_gaps: u64,
    /// Whether this is the final count (the recording ended cleanly).
    pub last: bool,
}

impl RecorderMsg {
    /// Recomputes `total_gaps`.
    pub fn update_total(&mut self) {
        self.total_gaps = self.joint_state.gaps
            + self.torque_command.gaps
            + self.telemetry.gaps
            + self.setpoint.gaps
            + self.path.gaps
            + self.load.gaps;
    }
}
