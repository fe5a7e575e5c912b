//! What the server does with each sample, live or played back: count it
//! (sequence gaps and restarts per stream), decide whether it is published
//! (the `--rate` limit), and publish it with the transform tree and the
//! joint limits of a published joint state.
//!
//! The rate limit picks joint states on a grid of their own stamps (the
//! first state at or after each multiple of the period), and publishes the
//! torque command and the telemetry that answer exactly those states, so
//! that every published q has its τ and its cycle's errors beside it.
//! Setpoints are always published.

use hcc_msgs::{SeqEvent, SequenceChecker};
use hcc_record::mcap_log::{
    JointStateMsg, LoadMsg, PathMsg, SetpointMsg, TelemetryMsg, TorqueCommandMsg,
};
use std::collections::VecDeque;
use std::time::{Duration, Instant};

use crate::channels::{Channels, JointLimitsMsg, LoadMarker, Stream, StreamCounts, ViewMsg};
use crate::frames::FrameTree;

/// Admits one sample per period of its stamps.
#[derive(Clone, Debug)]
pub struct RateGate {
    period_ns: u64,
    next_ns: Option<u64>,
}

impl RateGate {
    /// At most `rate_hz` samples per second of stamps (0: every sample).
    pub fn new(rate_hz: f64) -> RateGate {
        let period_ns = if rate_hz > 0.0 {
            (1e9 / rate_hz).round() as u64
        } else {
            0
        };
        RateGate {
            period_ns,
            next_ns: None,
        }
    }

    /// Whether the sample stamped `stamp_ns` is published. A stamp far
    /// behind the grid (a restarted publisher with another clock) restarts it.
    pub fn admit(&mut self, stamp_ns: u64) -> bool {
        if self.period_ns == 0 {
            return true;
        }
        match self.next_ns {
            Some(next) if stamp_ns < next && next - stamp_ns <= 2 * self.period_ns => false,
            Some(next) if stamp_ns >= next => {
                let mut n = next + self.period_ns;
                if n <= stamp_ns {
                    // Behind by more than a period (a gap): restart the grid.
                    n = stamp_ns + self.period_ns;
                }
                self.next_ns = Some(n);
                true
            }
            _ => {
                self.next_ns = Some(stamp_ns + self.period_ns);
                true
            }
        }
    }
}

/// Sequence bookkeeping of one stream.
#[derive(Default)]
struct Seq {
    checker: SequenceChecker,
}

impl Seq {
    /// Counts `seq`; whether the sample is new (not a duplicate). A sequence
    /// that goes backwards is a restarted publisher: counted, and followed
    /// from there.
    fn observe(&mut self, seq: u64, counts: &mut StreamCounts) -> bool {
        counts.received += 1;
        let restarts = self.checker.restarts();
        let event = self.checker.observe_restarting(seq);
        counts.restarts += self.checker.restarts() - restarts;
        match event {
            SeqEvent::Gap { missed } => counts.gaps += missed,
            SeqEvent::Duplicate => return false,
            _ => {}
        }
        true
    }
}

/// Joint limits of the model, `None` where the URDF gives none.
struct Limits {
    lower: Vec<Option<f64>>,
    upper: Vec<Option<f64>>,
    velocity: Vec<Option<f64>>,
    effort: Vec<Option<f64>>,
}

fn finite(x: f64) -> Option<f64> {
    x.is_finite().then_some(x)
}

impl Limits {
    fn of(model: &hcc_model::Model) -> Limits {
        let pick =
            |f: fn(&hcc_model::Joint) -> f64| model.joints.iter().map(|j| finite(f(j))).collect();
        Limits {
            lower: pick(|j| j.lower),
            upper: pick(|j| j.upper),
            velocity: pick(|j| j.velocity_limit),
            effort: pick(|j| j.effort_limit),
        }
    }

    fn message(&self, q: &[f64], qd: &[f64], tau: &[f64]) -> JointLimitsMsg {
        let q_fraction: Vec<Option<f64>> = q
            .iter()
            .enumerate()
            .map(|(k, &x)| match (self.lower.get(k)?, self.upper.get(k)?) {
                (Some(lo), Some(hi)) if hi > lo => {
                    finite((x - 0.5 * (lo + hi)) / (0.5 * (hi - lo)))
                }
                _ => None,
            })
            .collect();
        let ratio = |v: &[f64], lim: &[Option<f64>]| -> Vec<Option<f64>> {
            v.iter()
                .enumerate()
                .map(|(k, &x)| match lim.get(k).copied().flatten() {
                    Some(l) if l > 0.0 => finite(x / l),
                    _ => None,
                })
                .collect()
        };
        let qd_fraction = ratio(qd, &self.velocity);
        let tau_fraction = ratio(tau, &self.effort);
        let max = |v: &[Option<f64>]| v.iter().flatten().map(|x| x.abs()).reduce(f64::max);
        JointLimitsMsg {
            q_lower: self.lower.clone(),
            q_upper: self.upper.clone(),
            qd_max: self.velocity.clone(),
            tau_max: self.effort.clone(),
            q_fraction_max: max(&q_fraction),
            qd_fraction_max: max(&qd_fraction),
            tau_fraction_max: max(&tau_fraction),
            q_fraction,
            qd_fraction,
            tau_fraction,
        }
    }
}

/// Joint-state sequence numbers published lately (their command and
/// telemetry are published too).
const ADMITTED: usize = 512;

/// Interval of the `/view` counts.
pub const STATS_INTERVAL: Duration = Duration::from_secs(1);

/// The server's handling of samples (see the module documentation).
pub struct Viewer {
    channels: Channels,
    tree: Option<FrameTree>,
    limits: Option<Limits>,
    urdf: Option<String>,
    gate: RateGate,
    admitted: VecDeque<u64>,
    seqs: [Seq; 3],
    counts: ViewMsg,
    /// Active goal and error of each level, from the newest published telemetry.
    goals: Vec<(Vec<f64>, Vec<f64>)>,
    /// τ of the newest published command.
    tau: Vec<f64>,
    /// The load the controller's model carries, from the newest published
    /// telemetry: mass (kg) and centre of mass in the tip frame.
    load: (f64, nalgebra::Vector3<f64>),
    started: Instant,
    next_stats: Instant,
}

impl Viewer {
    /// A viewer publishing into `channels` at most `rate_hz` joint states a
    /// second (0: all), with the transform tree and limits of `tree`'s model
    /// and the URDF text `urdf` when known.
    pub fn new(
        channels: Channels,
        tree: Option<FrameTree>,
        urdf: Option<String>,
        rate_hz: f64,
    ) -> Viewer {
        let now = Instant::now();
        Viewer {
            channels,
            limits: tree.as_ref().map(|t| Limits::of(t.model())),
            tree,
            urdf,
            gate: RateGate::new(rate_hz),
            admitted: VecDeque::with_capacity(ADMITTED),
            seqs: Default::default(),
            counts: ViewMsg {
                rate_hz,
                ..ViewMsg::default()
            },
            goals: Vec::new(),
            tau: Vec::new(),
            load: (0.0, nalgebra::Vector3::zeros()),
            started: now,
            next_stats: now + STATS_INTERVAL,
        }
    }

    /// Whether a client subscribes to any of the streams.
    pub fn watched(&self) -> bool {
        self.channels.any_wanted()
    }

    /// The counts so far.
    pub fn counts(&self) -> &ViewMsg {
        &self.counts
    }

    /// A joint state (`seq`, `stamp_ns`), logged at `log_time` (Unix ns);
    /// `msg` builds its message when it is published.
    pub fn joint_state(
        &mut self,
        seq: u64,
        stamp_ns: u64,
        log_time: u64,
        msg: impl FnOnce() -> JointStateMsg,
    ) {
        let restarts = self.counts.joint_state.restarts;
        if !self.seqs[0].observe(seq, &mut self.counts.joint_state) {
            return;
        }
        if self.counts.joint_state.restarts != restarts {
            self.admitted.clear();
        }
        if !self.gate.admit(stamp_ns) {
            return;
        }
        if self.admitted.len() == ADMITTED {
            self.admitted.pop_front();
        }
        self.admitted.push_back(seq);
        let m = msg();
        self.channels.recorded(Stream::JointState, &m, log_time);
        self.counts.joint_state.published += 1;
        self.draw(&m, log_time);
    }

    /// The transform tree and the limits at the published state `m`.
    fn draw(&mut self, m: &JointStateMsg, log_time: u64) {
        let Some(tree) = self.tree.as_mut() else {
            return;
        };
        let goals = &self.goals;
        match tree.at(&m.q, |i| {
            goals.get(i).map(|(g, e)| (g.as_slice(), e.as_slice()))
        }) {
            Some(tf) => {
                self.channels.tf(tf, log_time);
                let (mass, com) = self.load;
                let load = (mass > 0.0 && com.iter().all(|c| c.is_finite())).then(|| LoadMarker {
                    com: tree.tip_point(&com),
                    mass,
                });
                self.channels.chain(tree.chain_points(), load, log_time);
                self.counts.tf_published += 1;
            }
            None => self.counts.bad_states += 1,
        }
        if let Some(limits) = &self.limits {
            let msg = limits.message(&m.q, &m.qd, &self.tau);
            self.channels.joint_limits(&msg, log_time);
        }
    }

    fn answers_published_state(&self, state_seq: u64) -> bool {
        self.admitted.iter().rev().any(|&s| s == state_seq)
    }

    /// A torque command (`seq`, answering `state_seq`).
    pub fn torque_command(
        &mut self,
        seq: u64,
        state_seq: u64,
        log_time: u64,
        msg: impl FnOnce() -> TorqueCommandMsg,
    ) {
        if !self.seqs[1].observe(seq, &mut self.counts.torque_command)
            || !self.answers_published_state(state_seq)
        {
            return;
        }
        let m = msg();
        self.channels.recorded(Stream::TorqueCommand, &m, log_time);
        self.counts.torque_command.published += 1;
        self.tau = m.tau;
    }

    /// A telemetry sample (`seq`, of the cycle of `state_seq`).
    pub fn telemetry(
        &mut self,
        seq: u64,
        state_seq: u64,
        log_time: u64,
        msg: impl FnOnce() -> TelemetryMsg,
    ) {
        if !self.seqs[2].observe(seq, &mut self.counts.telemetry)
            || !self.answers_published_state(state_seq)
        {
            return;
        }
        let m = msg();
        self.channels.recorded(Stream::Telemetry, &m, log_time);
        self.counts.telemetry.published += 1;
        if let [x, y, z] = m.load.com[..] {
            self.load = (m.load.mass, nalgebra::Vector3::new(x, y, z));
        }
        self.goals = m.levels.into_iter().map(|l| (l.goal, l.error)).collect();
    }

    /// A path message (always published, as a setpoint).
    pub fn path(&mut self, log_time: u64, msg: &PathMsg) {
        self.counts.path.received += 1;
        self.channels.recorded(Stream::Path, msg, log_time);
        self.counts.path.published += 1;
    }

    /// A load message (always published, as a setpoint).
    pub fn load(&mut self, log_time: u64, msg: &LoadMsg) {
        self.counts.load.received += 1;
        self.channels.recorded(Stream::Load, msg, log_time);
        self.counts.load.published += 1;
    }

    /// A setpoint (always published; numbered per client, so not checked).
    pub fn setpoint(&mut self, log_time: u64, msg: &SetpointMsg) {
        self.counts.setpoint.received += 1;
        self.channels.recorded(Stream::Setpoint, msg, log_time);
        self.counts.setpoint.published += 1;
    }

    /// Publishes the URDF text (to a client that just subscribed to it).
    pub fn robot_description(&mut self, log_time: u64) {
        if let Some(urdf) = &self.urdf {
            self.channels.robot_description(urdf, log_time);
        }
    }

    /// Once per [`STATS_INTERVAL`]: the counts on `/view` (with `clients`
    /// connected); returns them when it published them.
    pub fn tick(&mut self, clients: usize, log_time: u64) -> Option<&ViewMsg> {
        let now = Instant::now();
        if now < self.next_stats {
            return None;
        }
        self.next_stats = (self.next_stats + STATS_INTERVAL).max(now);
        self.counts.elapsed_s = self.started.elapsed().as_secs_f64();
        self.counts.clients = clients as u64;
        self.channels.view(&self.counts, log_time);
        Some(&self.counts)
    }
}

/// One line on the counts: received, published and lost per stream.
pub fn stats_line(m: &ViewMsg) -> String {
    let s = |c: &StreamCounts| {
        let mut t = format!("{}/{}", c.published, c.received);
        if c.gaps > 0 {
            t.push_str(&format!(" ({} lost)", c.gaps));
        }
        if c.restarts > 0 {
            t.push_str(&format!(" ({} restarts)", c.restarts));
        }
        t
    };
    format!(
        "{} client(s); published/received: joint_state {}, torque_command {}, telemetry {}, setpoint {}, path {}, load {}",
        m.clients,
        s(&m.joint_state),
        s(&m.torque_command),
        s(&m.telemetry),
        s(&m.setpoint),
        s(&m.path),
        s(&m.load)
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_gate_admits_one_state_per_period_of_stamps() {
        let mut g = RateGate::new(100.0);
        // 1 kHz states with ±0.2 ms jitter over 10 s.
        let admitted = (0..10_000u64)
            .filter(|k| {
                let jitter = ((k * 7919) % 400) as i64 - 200;
                g.admit(((1_000_000_000 + k * 1_000_000) as i64 + jitter * 1000) as u64)
            })
            .count();
        assert_eq!(admitted, 1000);
        let mut all = RateGate::new(0.0);
        assert!((0..10).all(|k| all.admit(k)));
    }

    #[test]
    fn the_gate_restarts_after_a_gap_or_a_clock_jump_back() {
        let mut g = RateGate::new(100.0);
        assert!(g.admit(1_000_000_000));
        assert!(!g.admit(1_005_000_000));
        // A gap of a second: the next state is admitted and the grid restarts there.
        assert!(g.admit(2_000_000_000));
        assert!(!g.admit(2_009_000_000));
        assert!(g.admit(2_010_000_000));
        // Stamps from a restarted publisher far behind: admitted at once.
        assert!(g.admit(5_000));
        assert!(!g.admit(6_000));
    }

    #[test]
    fn restarts_and_gaps_are_counted() {
        let mut s = Seq::default();
        let mut c = StreamCounts::default();
        for seq in [1, 2, 3, 7, 7, 8, 1, 2] {
            s.observe(seq, &mut c);
        }
        assert_eq!(c.received, 8);
        assert_eq!(c.gaps, 3);
        assert_eq!(c.restarts, 1);
    }

    #[test]
    fn limits_are_fractions_of_the_range() {
        let l = Limits {
            lower: vec![Some(-2.0), None],
            upper: vec![Some(1.0), None],
            velocity: vec![Some(2.0), Some(4.0)],
            effort: vec![Some(10.0), None],
        };
        let m = l.message(&[1.0, 3.0], &[-1.0, 4.0], &[5.0, 1.0]);
        assert_eq!(m.q_fraction, vec![Some(1.0), None]);
        assert_eq!(m.qd_fraction, vec![Some(-0.5), Some(1.0)]);
        assert_eq!(m.tau_fraction, vec![Some(0.5), None]);
        assert_eq!(m.qd_fraction_max, Some(1.0));
        assert_eq!(m.q_lower, vec![Some(-2.0), None]);
        // No command yet: no torque fractions.
        assert_eq!(
            l.message(&[0.0, 0.0], &[0.0, 0.0], &[]).tau_fraction_max,
            None
        );
    }
}
