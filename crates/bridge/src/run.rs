//! `hcc bridge`: its arguments and its main loop (forward the decimated
//! samples, take the remote goals, publish the answers).

use std::collections::VecDeque;
use std::path::PathBuf;
use std::sync::{Arc, mpsc};
use std::time::{Duration, Instant};

use anyhow::{Context, bail};
use hcc_client::{Client, ClientError};
use hcc_config::Scenario;
use hcc_msgs::{JointState, ServiceNames, Telemetry, TorqueCommand, ipc};

use crate::attachment::Attachment;
use crate::cdr::CdrWriter;
use crate::counters::{Counters, bump};
use crate::goal::GoalLevel;
use crate::ipc_side::{IpcReader, Sample};
use crate::names;
use crate::names::RosType;
use crate::rate::RateLimiter;
use crate::ros::{self, ClockMap, RemoteAnswer, TelemetryExtras};
use crate::zenoh_side::{Graph, RosPublisher, RosSubscription, zenoh_config};
use crate::{load, trajectory};

/// Highest `--rate`: the control rate.
pub const MAX_RATE_HZ: f64 = 1000.0;
/// Highest `--setpoint-rate`: far below what the controller's setpoint
/// queue takes per cycle, so remote setpoints never push a local client's
/// out of it.
pub const MAX_SETPOINT_RATE_HZ: f64 = 100.0;
/// Remote goals that may wait for the main loop; more are refused (rate).
const GOAL_BACKLOG: usize = 64;
/// Remote publishers whose last answer the telemetry carries.
const REMOTE_ANSWERS: usize = 8;
/// Forwarded goals that wait for the controller's answer.
const PENDING: usize = 64;

/// `hcc bridge`.
// The help texts name placeholders as <name>: not HTML.
#[allow(rustdoc::invalid_html_tags)]
#[derive(clap::Args, Debug, Clone)]
pub struct Args {
    /// Namespace of the running controller and driver (its ROS namespace is
    /// the same name made a valid ROS name: lower case, other characters _).
    #[arg(long)]
    pub namespace: String,
    /// The scenario the controller runs: joint names (URDF), level names
    /// and kinds (the goal topics' types), the frame of Cartesian goals
    /// (default: the one the controller publishes on its scenario service).
    #[arg(long)]
    pub config: Option<PathBuf>,
    /// ROS domain id (default: ROS_DOMAIN_ID, else 0).
    #[arg(long)]
    pub domain: Option<u32>,
    /// Zenoh configuration file (JSON5): endpoints, mode, TLS, user/password
    /// (default: rmw_zenoh's session defaults, a peer connecting to the
    /// router on tcp/localhost:7447).
    #[arg(long)]
    pub zenoh_config: Option<PathBuf>,
    /// Samples per second forwarded per stream, at most 1000: every k-th
    /// sample, k = the scenario's control rate / HZ, rounded.
    #[arg(long, default_value_t = 100.0)]
    pub rate: f64,
    /// Forward remote goals to the controller (default: read-only).
    #[arg(long)]
    pub allow_setpoints: bool,
    /// Remote goals forwarded per second at most (token bucket; the rest is
    /// refused and counted), at most 100.
    #[arg(long, default_value_t = 20.0)]
    pub setpoint_rate: f64,
    /// Remote goals forwarded at once at most (the bucket's size).
    #[arg(long, default_value_t = 5)]
    pub setpoint_burst: u32,
    /// Transition duration of a remote goal, s (0: as fast as the level's
    /// speed limit allows).
    #[arg(long, default_value_t = 0.0)]
    pub goal_duration: f64,
    /// Ramp of a remote load (`/<ns>/load`), s (0: the controller's
    /// default, 0.2 s).
    #[arg(long, default_value_t = 0.0)]
    pub load_ramp: f64,
    /// iceoryx2 file prefix of the daemons (default: HCC_IPC_FILE_PREFIX, else iceoryx2's).
    #[arg(long)]
    pub file_prefix: Option<String>,
    /// Stop after this many seconds (default: until Ctrl-C or SIGTERM).
    #[arg(long)]
    pub duration: Option<f64>,
    /// No progress lines on stderr.
    #[arg(long)]
    pub quiet: bool,
}

impl Args {
    fn check(&self) -> anyhow::Result<()> {
        if !(self.rate.is_finite() && self.rate > 0.0 && self.rate <= MAX_RATE_HZ) {
            bail!("--rate must be in (0, {MAX_RATE_HZ}] Hz, not {}", self.rate);
        }
        let r = self.setpoint_rate;
        if !(r.is_finite() && r > 0.0 && r <= MAX_SETPOINT_RATE_HZ) {
            bail!("--setpoint-rate must be in (0, {MAX_SETPOINT_RATE_HZ}] Hz, not {r}");
        }
        if !(self.goal_duration.is_finite() && self.goal_duration >= 0.0) {
            bail!("--goal-duration must be a non-negative number of s");
        }
        let max = hcc_msgs::MAX_TRANSITION_S;
        if !(self.load_ramp.is_finite() && (0.0..=max).contains(&self.load_ramp)) {
            bail!(
                "--load-ramp must be in [0, {max}] s, not {}",
                self.load_ramp
            );
        }
        if let Some(d) = self.duration
            && !(d.is_finite() && d > 0.0)
        {
            bail!("--duration must be a positive number of s, not {d}");
        }
        Ok(())
    }

    fn domain(&self) -> anyhow::Result<u32> {
        match (self.domain, std::env::var("ROS_DOMAIN_ID")) {
            (Some(d), _) => Ok(d),
            (None, Ok(v)) if !v.trim().is_empty() => v
                .trim()
                .parse()
                .with_context(|| format!("ROS_DOMAIN_ID={v:?} is not a domain id")),
            _ => Ok(0),
        }
    }
}

/// The bridge's client when it forwards a remote goal or path now: none when
/// read-only, and within the setpoint rate (the refusal, code and reason,
/// counted).
fn admit<'a>(
    client: &'a mut Option<Client>,
    limiter: &mut RateLimiter,
    c: &Counters,
) -> Result<&'a mut Client, (u32, String)> {
    let Some(client) = client.as_mut() else {
        bump(&c.goals_refused_read_only);
        return Err((
            ros::REFUSED_READ_ONLY,
            "read-only bridge (no --allow-setpoints)".into(),
        ));
    };
    if !limiter.allow(hcc_msgs::monotonic_now_ns()) {
        bump(&c.goals_refused_rate);
        return Err((ros::REFUSED_RATE, "over the bridge's setpoint rate".into()));
    }
    Ok(client)
}

/// The topic a remote message came on.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Topic {
    /// A level's goal topic.
    Goal,
    /// A level's path topic (trajectory.rs).
    Path,
    /// The load topic (load.rs); no level.
    Load,
}

/// A remote goal, path or load as the Zenoh callback hands it on.
struct RemoteGoal {
    level: usize,
    payload: Vec<u8>,
    attachment: Option<Attachment>,
    topic: Topic,
}

/// A forwarded goal waiting for the controller's answer.
struct Pending {
    seq: u64,
    gid: [u8; 16],
    source_seq: i64,
    level: u32,
}

/// The publishers and what they need.
struct Outputs {
    states: RosPublisher,
    commands: RosPublisher,
    telemetry: RosPublisher,
    writer: CdrWriter,
    clock: ClockMap,
    joint_names: Vec<String>,
    level_names: Vec<String>,
    warned_joints: bool,
}

/// The remote goals' side.
struct Goals {
    levels: Vec<GoalLevel>,
    /// Per level, its joint names (a joint level's; the check of a
    /// trajectory's `joint_names`) and its equilibrium as the last telemetry
    /// gave it (where a trajectory that starts later than 0 starts from).
    joints: Vec<Vec<String>>,
    equilibrium: Vec<Vec<f64>>,
    root_link: String,
    /// The robot's tip link: the frame of a remote load.
    tip_link: String,
    client: Option<Client>,
    limiter: RateLimiter,
    duration_s: f64,
    load_ramp_s: f64,
    rx: mpsc::Receiver<RemoteGoal>,
    pending: VecDeque<Pending>,
    answers: VecDeque<RemoteAnswer>,
    _subscriptions: Vec<RosSubscription>,
}

/// Runs the bridge until Ctrl-C, SIGTERM or `--duration`.
pub fn run(args: Args) -> anyhow::Result<()> {
    args.check()?;
    let names = ServiceNames::new(&args.namespace).context("--namespace")?;
    let domain = args.domain()?;
    let file_prefix = args.file_prefix.clone().or_else(ipc::file_prefix_from_env);
    ipc::config(file_prefix.as_deref()).context("--file-prefix")?;
    let (scenario, differs) = hcc_config::scenario_for_tool(
        "hcc-bridge-scenario",
        args.config.as_deref(),
        &names,
        file_prefix.as_deref(),
        std::time::Duration::from_secs(5),
    )
    .context("the scenario (--config, or the controller's scenario service)")?;
    if let Some(d) = differs {
        tracing::warn!("--config: {d}");
    }
    let ros_ns = names::ros_name(&args.namespace, "hcc_");
    let counters = Arc::new(Counters::default());
    hcc_rt::install_stop_handler().context("cannot install the SIGINT/SIGTERM handlers")?;

    let mut graph = Graph::open(zenoh_config(args.zenoh_config.as_deref())?, domain, &ros_ns)?;
    let mut out = Outputs::declare(&mut graph, &scenario)?;
    let mut goals = Goals::declare(
        &mut graph,
        &scenario,
        &out.level_names,
        &args,
        &file_prefix,
        &counters,
    )?;
    let node = format!("hcc-bridge-{}", std::process::id());
    let rates = (scenario.rate_hz, args.rate);
    let reader = IpcReader::start(&node, file_prefix, names, rates, counters.clone())?;
    if !args.quiet {
        eprintln!(
            "hcc bridge: namespace {} on Zenoh {} (domain {domain}, zid {}), {} Hz, {}",
            args.namespace,
            graph.topic("*"),
            graph.zid(),
            args.rate,
            if goals.client.is_some() {
                "setpoints allowed"
            } else {
                "read-only"
            }
        );
    }
    let started = Instant::now();
    let mut last_progress = Instant::now();
    let end = loop {
        if hcc_rt::stop_requested() {
            break "interrupted".to_string();
        }
        if args
            .duration
            .is_some_and(|d| started.elapsed().as_secs_f64() >= d)
        {
            break "duration".to_string();
        }
        match reader.rx.recv_timeout(Duration::from_millis(5)) {
            Ok(Sample::Failed(e)) => bail!("iceoryx2 reader: {e}"),
            Ok(s) => out.forward(s, &mut goals, &counters),
            Err(mpsc::RecvTimeoutError::Timeout) => {}
            Err(mpsc::RecvTimeoutError::Disconnected) => bail!("the iceoryx2 reader stopped"),
        }
        goals.take_all(&counters);
        if !args.quiet && last_progress.elapsed() >= Duration::from_secs(10) {
            last_progress = Instant::now();
            eprintln!(
                "hcc bridge: {:.0} s, {}",
                started.elapsed().as_secs_f64(),
                summary(&counters, &out)
            );
        }
    };
    drop(reader);
    let bytes = out.bytes();
    println!(
        "{{\"end\": \"{end}\", \"seconds\": {:.3}, \"bytes_published\": {bytes}, {}}}",
        started.elapsed().as_secs_f64(),
        counters
            .snapshot()
            .iter()
            .map(|(n, v)| format!("\"{n}\": {v}"))
            .collect::<Vec<_>>()
            .join(", ")
    );
    drop(goals);
    drop(out);
    graph.close()
}

fn summary(c: &Counters, out: &Outputs) -> String {
    let s = c.snapshot();
    let get = |name: &str| s.iter().find(|(n, _)| *n == name).map_or(0, |(_, v)| *v);
    format!(
        "{} published ({:.1} MB), {} decimated, {} lost in the queues, {} dropped behind; goals: {} received, {} forwarded",
        get("bridge_published"),
        out.bytes() as f64 / 1e6,
        get("bridge_decimated"),
        get("bridge_ipc_lost"),
        get("bridge_dropped_behind"),
        get("bridge_goals_received"),
        get("bridge_goals_forwarded"),
    )
}

impl Outputs {
    fn declare(graph: &mut Graph, scenario: &Scenario) -> anyhow::Result<Outputs> {
        let level_names: Vec<String> = scenario.levels().iter().map(|l| l.name.clone()).collect();
        Ok(Outputs {
            states: graph.publisher(&graph.topic("joint_states"), &ros::JOINT_STATE)?,
            commands: graph.publisher(&graph.topic("torque_command"), &ros::JOINT_STATE)?,
            telemetry: graph.publisher(&graph.topic("telemetry"), &ros::TELEMETRY)?,
            writer: CdrWriter::new(),
            clock: ClockMap::now(),
            joint_names: scenario
                .model
                .joints
                .iter()
                .map(|j| j.name.clone())
                .collect(),
            level_names,
            warned_joints: false,
        })
    }

    fn bytes(&self) -> u64 {
        self.states.bytes + self.commands.bytes + self.telemetry.bytes
    }

    /// The joint names for `n` joints: the URDF's, or `joint_<i>` when the
    /// scenario does not match the stream (warned once).
    fn names_for(&mut self, n: usize) -> Vec<String> {
        if n == self.joint_names.len() {
            return self.joint_names.clone();
        }
        if !self.warned_joints {
            self.warned_joints = true;
            tracing::warn!(
                "the stream has {n} joints, the scenario {}: joints named joint_<i> (is --config the controller's scenario?)",
                self.joint_names.len()
            );
        }
        (0..n).map(|i| format!("joint_{i}")).collect()
    }

    fn forward(&mut self, s: Sample, goals: &mut Goals, c: &Counters) {
        let result = match s {
            Sample::State(s) => self.state(&s),
            Sample::Command(cmd) => self.command(&cmd),
            Sample::Telemetry(t) => {
                goals.observe_answers(&t, c);
                self.telemetry(&t, goals, c)
            }
            Sample::Failed(_) => Ok(()),
        };
        match result {
            Ok(()) => bump(&c.published),
            Err(e) => {
                bump(&c.publish_errors);
                tracing::warn!("{e:#}");
            }
        }
    }

    fn state(&mut self, s: &JointState) -> anyhow::Result<()> {
        let names = self.names_for(s.n());
        let stamp = self.clock.ros_time(s.header.stamp_ns);
        ros::write_joint_state(
            &mut self.writer,
            stamp,
            &names,
            s.q(),
            s.qd(),
            s.tau_measured(),
        );
        self.states.put(self.writer.bytes())
    }

    fn command(&mut self, cmd: &TorqueCommand) -> anyhow::Result<()> {
        let names = self.names_for(cmd.n());
        let stamp = self.clock.ros_time(cmd.header.stamp_ns);
        ros::write_joint_state(&mut self.writer, stamp, &names, &[], &[], cmd.tau());
        self.commands.put(self.writer.bytes())
    }

    fn telemetry(&mut self, t: &Telemetry, goals: &Goals, c: &Counters) -> anyhow::Result<()> {
        let counters = c.snapshot();
        let answers: Vec<RemoteAnswer> = goals.answers.iter().cloned().collect();
        let extras = TelemetryExtras {
            level_names: &self.level_names,
            bridge_counters: &counters,
            bridge_client_id: goals.client.as_ref().map_or(0, Client::client_id),
            remote_answers: &answers,
        };
        let stamp = self.clock.ros_time(t.header.stamp_ns);
        ros::write_telemetry(&mut self.writer, t, stamp, &extras);
        self.telemetry.put(self.writer.bytes())
    }
}

impl Goals {
    fn declare(
        graph: &mut Graph,
        scenario: &Scenario,
        level_names: &[String],
        args: &Args,
        file_prefix: &Option<String>,
        counters: &Arc<Counters>,
    ) -> anyhow::Result<Goals> {
        let ros_names = names::unique_ros_names(level_names, "level");
        let levels = GoalLevel::of_scenario(scenario, &ros_names);
        let (tx, rx) = mpsc::sync_channel(GOAL_BACKLOG);
        // Each topic hands its messages to the main loop, counted.
        let mut subscribe = |name: &str, ty: &RosType, level: usize, topic: Topic| {
            let (tx, c) = (tx.clone(), counters.clone());
            graph.subscription(&graph.topic(name), ty, move |sample| {
                let goal = RemoteGoal {
                    level,
                    payload: sample.payload().to_bytes().into_owned(),
                    attachment: Attachment::from_zbytes(sample.attachment()),
                    topic,
                };
                bump(&c.goals_received);
                if tx.try_send(goal).is_err() {
                    bump(&c.goals_refused_rate);
                }
            })
        };
        let mut subscriptions = Vec::new();
        for level in &levels {
            let (name, kind) = (&level.ros_name, &level.kind);
            subscriptions.push(subscribe(
                &format!("{name}/goal"),
                kind.ros_type(),
                level.index,
                Topic::Goal,
            )?);
            // The level's path topic (trajectory.rs).
            subscriptions.push(subscribe(
                &format!("{name}/path"),
                trajectory::ros_type(kind),
                level.index,
                Topic::Path,
            )?);
        }
        // The load topic (load.rs).
        subscriptions.push(subscribe("load", &load::INERTIA_STAMPED, 0, Topic::Load)?);
        let client = if args.allow_setpoints {
            let c =
                Client::connect(&args.namespace, file_prefix.as_deref()).with_context(|| {
                    format!("cannot connect to the controller of {:?}", args.namespace)
                })?;
            Some(c)
        } else {
            None
        };
        let joints = scenario
            .levels()
            .iter()
            .map(|l| trajectory::joint_names(l, scenario))
            .collect();
        let equilibrium = scenario
            .levels()
            .iter()
            .map(|l| l.goal.iter().copied().collect())
            .collect();
        Ok(Goals {
            levels,
            joints,
            equilibrium,
            root_link: scenario.model.root_link.clone(),
            tip_link: scenario.model.tip_link.clone(),
            client,
            limiter: RateLimiter::new(args.setpoint_rate, args.setpoint_burst),
            duration_s: args.goal_duration,
            load_ramp_s: args.load_ramp,
            rx,
            pending: VecDeque::new(),
            answers: VecDeque::new(),
            _subscriptions: subscriptions,
        })
    }

    /// Handles every goal that arrived.
    fn take_all(&mut self, c: &Counters) {
        while let Ok(g) = self.rx.try_recv() {
            self.take(g, c);
        }
    }

    fn take(&mut self, g: RemoteGoal, c: &Counters) {
        let att = g.attachment.unwrap_or(Attachment {
            sequence_number: 0,
            source_timestamp: 0,
            source_gid: [0; 16],
        });
        let mut answer = RemoteAnswer {
            source_gid: att.source_gid,
            source_seq: att.sequence_number,
            level: match g.topic {
                Topic::Load => load::LOAD_LEVEL,
                _ => g.level as u32,
            },
            code: 0,
            reason: String::new(),
            duration_s: 0.0,
        };
        if g.topic != Topic::Goal {
            // Paths and loads are answered as they are sent.
            let result = match g.topic {
                Topic::Path => self.forward_path(&g, c),
                _ => self.forward_load(&g, c),
            };
            match result {
                Ok(duration_s) => {
                    bump(&c.goals_accepted);
                    answer.reason = ros::answer_reason(0);
                    answer.duration_s = duration_s;
                }
                Err((code, reason)) => {
                    answer.code = code;
                    answer.reason = reason;
                    let what = match g.topic {
                        Topic::Path => format!("path for level {}", g.level + 1),
                        _ => "load".into(),
                    };
                    tracing::info!("remote {what} refused: {}", answer.reason);
                }
            }
            self.record(answer);
            return;
        }
        match self.forward(&g, c) {
            Ok(seq) => {
                if self.pending.len() == PENDING {
                    self.pending.pop_front();
                }
                self.pending.push_back(Pending {
                    seq,
                    gid: att.source_gid,
                    source_seq: att.sequence_number,
                    level: g.level as u32,
                });
                return;
            }
            Err((code, reason)) => {
                answer.code = code;
                answer.reason = reason;
            }
        }
        tracing::info!(
            "remote goal for level {} refused: {}",
            g.level + 1,
            answer.reason
        );
        self.record(answer);
    }

    /// Checks and sends one goal; its setpoint's sequence number, or the
    /// refusal (code, reason).
    fn forward(&mut self, g: &RemoteGoal, c: &Counters) -> Result<u64, (u32, String)> {
        let client = admit(&mut self.client, &mut self.limiter, c)?;
        let level = &self.levels[g.level];
        let goal = ros::read_goal(level.kind.ros_type(), &g.payload)
            .map_err(|e| e.to_string())
            .and_then(|m| level.goal(&m, &self.root_link).map_err(|e| e.to_string()));
        let goal = goal
            .inspect_err(|_| bump(&c.goals_refused_bad))
            .map_err(|e| (ros::REFUSED_BAD_MESSAGE, e))?;
        match client.set_goal(g.level, &goal, self.duration_s) {
            Ok(seq) => {
                bump(&c.goals_forwarded);
                Ok(seq)
            }
            Err(ClientError::Invalid(r)) => {
                bump(&c.goals_refused_bad);
                Err((r.code(), r.name().into()))
            }
            Err(e) => {
                bump(&c.goals_refused_bad);
                Err((ros::REFUSED_UNREACHABLE, e.to_string()))
            }
        }
    }

    /// Checks and sends one path (trajectory.rs) through the client, a
    /// message at a time after the controller's answer to the one before;
    /// the refusal (code, reason) names the knots.
    fn forward_path(&mut self, g: &RemoteGoal, c: &Counters) -> Result<f64, (u32, String)> {
        let client = admit(&mut self.client, &mut self.limiter, c)?;
        let level = &self.levels[g.level];
        let ty = trajectory::ros_type(&level.kind);
        let knots = trajectory::read_trajectory(ty, &g.payload)
            .map_err(|e| e.to_string())
            .and_then(|m| {
                trajectory::knots(
                    &m,
                    &level.kind,
                    &self.joints[g.level],
                    &self.root_link,
                    &self.equilibrium[g.level],
                )
                .map_err(|e| e.to_string())
            });
        let knots = knots
            .inspect_err(|_| bump(&c.goals_refused_bad))
            .map_err(|e| (ros::REFUSED_BAD_MESSAGE, e))?;
        bump(&c.goals_forwarded);
        let timeout = Duration::from_millis(500);
        let (times, points) = (&knots.times, &knots.points);
        match &knots.rates {
            Some((v, a)) => client.follow_samples(g.level, times, points, (v, a), 0, timeout),
            None => client.follow(g.level, times, points, 0, timeout),
        }
        .map(|_| 0.0)
        .map_err(|e| {
            bump(&c.goals_rejected);
            let code = match &e.error {
                ClientError::Rejected(r) => r.code(),
                ClientError::PathRejected(r) => r.code(),
                ClientError::PathInvalid(r) => r.code(),
                ClientError::Invalid(r) => r.code(),
                _ => ros::REFUSED_UNREACHABLE,
            };
            (code, e.to_string())
        })
    }

    /// Checks and sends one load (load.rs) through the client and waits for
    /// the controller's answer; the ramp, or the refusal (code, reason).
    fn forward_load(&mut self, g: &RemoteGoal, c: &Counters) -> Result<f64, (u32, String)> {
        let client = admit(&mut self.client, &mut self.limiter, c)?;
        let message = load::read_load(&g.payload, &self.tip_link, self.load_ramp_s)
            .inspect_err(|_| bump(&c.goals_refused_bad))
            .map_err(|e| (ros::REFUSED_BAD_MESSAGE, e.to_string()))?;
        bump(&c.goals_forwarded);
        match client.set_load(message, Duration::from_millis(500)) {
            Ok(_) => Ok(message.ramp()),
            Err(e) => {
                bump(&c.goals_rejected);
                let code = match &e {
                    ClientError::LoadRejected(r) => r.code(),
                    ClientError::LoadInvalid(r) => r.code(),
                    ClientError::Rejected(r) | ClientError::Invalid(r) => r.code(),
                    _ => ros::REFUSED_UNREACHABLE,
                };
                Err((code, e.to_string()))
            }
        }
    }

    /// Keeps `answer` as the last of its publisher.
    fn record(&mut self, answer: RemoteAnswer) {
        self.answers.retain(|a| a.source_gid != answer.source_gid);
        if self.answers.len() == REMOTE_ANSWERS {
            self.answers.pop_front();
        }
        self.answers.push_back(answer);
    }

    /// Turns the controller's answer to the bridge's client into the
    /// answers of the remote goals it settles.
    fn observe_answers(&mut self, t: &Telemetry, c: &Counters) {
        for (i, e) in self.equilibrium.iter_mut().enumerate() {
            let m = e.len().min(hcc_msgs::MAX_TASK_DIM);
            if i < t.n_levels as usize {
                e[..m].copy_from_slice(&t.goal[i][..m]);
            }
        }
        let Some(id) = self.client.as_ref().map(Client::client_id) else {
            return;
        };
        let Some(a) = t.answer_for(id).copied() else {
            return;
        };
        // Goals up to the answered one are settled: the answered one gets
        // the answer, earlier ones were superseded by a later goal.
        while let Some(p) = self.pending.front() {
            if p.seq > a.seq {
                break;
            }
            let p = self.pending.pop_front().expect("front exists");
            if p.seq == a.seq {
                let accepted = a.code == hcc_msgs::ANSWER_ACCEPTED;
                bump(if accepted {
                    &c.goals_accepted
                } else {
                    &c.goals_rejected
                });
                self.record(RemoteAnswer {
                    source_gid: p.gid,
                    source_seq: p.source_seq,
                    level: p.level,
                    code: a.code,
                    reason: ros::answer_reason(a.code),
                    duration_s: a.duration_s,
                });
            }
        }
    }
}
