//! The server's channels and what goes into them.
//!
//! | topic                | schema (encoding)                         | what                                   |
//! |----------------------|-------------------------------------------|----------------------------------------|
//! | `/joint_state`       | `hcc.JointState` (JSON)                   | the recording's channel, at `--rate`   |
//! | `/torque_command`    | `hcc.TorqueCommand` (JSON)                | the command answering a published state |
//! | `/telemetry`         | `hcc.Telemetry` (JSON)                    | the cycle of a published state         |
//! | `/setpoint`          | `hcc.Setpoint` (JSON)                     | every setpoint                         |
//! | `/path`              | `hcc.PathKnots` (JSON)                    | every path message                     |
//! | `/load`              | `hcc.LoadSetpoint` (JSON)                 | every load message                     |
//! | `/tf`                | `foxglove.FrameTransforms` (protobuf)     | the chain's links, TCP and goal frames |
//! | `/chain`            | `foxglove.SceneUpdate` (protobuf)         | the chain as a stick figure (joint origins); the load in the hand as a sphere at its centre of mass |
//! | `/joint_limits`      | `hcc.JointLimits` (JSON)                  | q, q̇, τ against the URDF's limits     |
//! | `/robot_description` | `hcc.RobotDescription` (JSON, `data`)     | the URDF text                          |
//! | `/view`              | `hcc.View` (JSON)                         | what the server received, published and lost |
//!
//! The first six use the channel names and JSON schemas of the recordings
//! (`hcc_record::mcap_log`), so one Foxglove layout opens a live server and
//! a recording alike. Log times are the messages' own stamps
//! (CLOCK_MONOTONIC) shifted to Unix time, as in a recording.

use anyhow::Context as _;
use foxglove::messages::{
    Color, FrameTransform, FrameTransforms, LinePrimitive, Point3, Quaternion, SceneEntity,
    SceneEntityDeletion, SceneUpdate, SpherePrimitive, Timestamp, Vector3, line_primitive,
    scene_entity_deletion,
};
use foxglove::{Channel, Context, PartialMetadata, RawChannel, Schema};
use hcc_record::mcap_log::schemas::{integer, number, numbers, object};
use hcc_record::mcap_log::{
    self, TOPIC_JOINT_STATE, TOPIC_LOAD, TOPIC_PATH, TOPIC_SETPOINT, TOPIC_TELEMETRY,
    TOPIC_TORQUE_COMMAND,
};
use serde::Serialize;
use serde_json::json;
use std::sync::Arc;

use crate::frames::Transform;

/// Topic of the transform tree.
pub const TOPIC_TF: &str = "/tf";
/// Topic of the chain's stick figure.
pub const TOPIC_CHAIN: &str = "/chain";
/// Topic of the joints against their limits.
pub const TOPIC_JOINT_LIMITS: &str = "/joint_limits";
/// Topic of the URDF text.
pub const TOPIC_ROBOT_DESCRIPTION: &str = "/robot_description";
/// Topic of the server's own counts.
pub const TOPIC_VIEW: &str = "/view";

/// The recording's topics that the server carries too.
pub const RECORDED_TOPICS: [&str; 6] = [
    TOPIC_JOINT_STATE,
    TOPIC_TORQUE_COMMAND,
    TOPIC_TELEMETRY,
    TOPIC_SETPOINT,
    TOPIC_PATH,
    TOPIC_LOAD,
];

/// Counts of one stream of the server.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize)]
pub struct StreamCounts {
    /// Samples received from the namespace (or read from the recording).
    pub received: u64,
    /// Samples published to the clients.
    pub published: u64,
    /// Samples lost before the server saw them (sequence gaps: its queue
    /// overflowed).
    pub gaps: u64,
    /// Times the publisher restarted (its sequence went backwards).
    pub restarts: u64,
}

/// `/view`: what the server received, published and lost so far.
#[derive(Clone, Debug, Default, PartialEq, Serialize)]
pub struct ViewMsg {
    /// Wall time since the server started, s.
    pub elapsed_s: f64,
    /// Connected clients.
    pub clients: u64,
    /// The `--rate` limit (0: every sample).
    pub rate_hz: f64,
    pub joint_state: StreamCounts,
    pub torque_command: StreamCounts,
    pub telemetry: StreamCounts,
    pub setpoint: StreamCounts,
    pub path: StreamCounts,
    pub load: StreamCounts,
    /// Transform sets published on `/tf`.
    pub tf_published: u64,
    /// Joint states not drawn (wrong size or a non-finite position).
    pub bad_states: u64,
}

/// `/joint_limits`: the published joint state against the URDF's limits.
/// Fractions are ±1 at a limit (`null` where the URDF gives none).
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct JointLimitsMsg {
    pub q_lower: Vec<Option<f64>>,
    pub q_upper: Vec<Option<f64>>,
    pub qd_max: Vec<Option<f64>>,
    pub tau_max: Vec<Option<f64>>,
    /// (q − mid) / half range: −1 at the lower limit, +1 at the upper.
    pub q_fraction: Vec<Option<f64>>,
    /// q̇ / q̇_max.
    pub qd_fraction: Vec<Option<f64>>,
    /// τ / τ_max of the newest command.
    pub tau_fraction: Vec<Option<f64>>,
    /// The largest |fraction| of each kind (a one-line plot of how close the arm is).
    pub q_fraction_max: Option<f64>,
    pub qd_fraction_max: Option<f64>,
    pub tau_fraction_max: Option<f64>,
}

fn counts_schema() -> serde_json::Value {
    json!({"type": "object", "properties": {
        "received": integer("samples received"),
        "published": integer("samples published"),
        "gaps": integer("samples lost before the server (sequence gaps)"),
        "restarts": integer("publisher restarts (sequence went backwards)"),
    }})
}

/// JSON Schema of `/view`.
pub fn view_schema() -> String {
    object(
        "hcc.View",
        "What hcc view received, published and lost",
        json!({
            "elapsed_s": number("wall time since the server started, s"),
            "clients": integer("connected clients"),
            "rate_hz": number("publication rate limit (0: every sample)"),
            "joint_state": counts_schema(),
            "torque_command": counts_schema(),
            "telemetry": counts_schema(),
            "setpoint": counts_schema(),
            "path": counts_schema(),
            "load": counts_schema(),
            "tf_published": integer("transform sets published"),
            "bad_states": integer("joint states not drawn (bad size or value)"),
        }),
    )
    .to_string()
}

/// JSON Schema of `/joint_limits`.
pub fn joint_limits_schema() -> String {
    object(
        "hcc.JointLimits",
        "The joint state against the URDF's limits (fractions: ±1 at a limit)",
        json!({
            "q_lower": numbers("lower position limits, rad (m)"),
            "q_upper": numbers("upper position limits, rad (m)"),
            "qd_max": numbers("velocity limits, rad/s (m/s)"),
            "tau_max": numbers("effort limits, N·m (N)"),
            "q_fraction": numbers("(q − mid) / half range: −1 lower limit, +1 upper limit"),
            "qd_fraction": numbers("q̇ / q̇_max"),
            "tau_fraction": numbers("τ / τ_max of the newest torque command"),
            "q_fraction_max": number("largest |q_fraction|"),
            "qd_fraction_max": number("largest |qd_fraction|"),
            "tau_fraction_max": number("largest |tau_fraction|"),
        }),
    )
    .to_string()
}

/// JSON Schema of `/robot_description` (the field name of ROS's std_msgs/String).
pub fn robot_description_schema() -> String {
    object(
        "hcc.RobotDescription",
        "The robot's URDF",
        json!({"data": {"type": "string", "description": "URDF XML"}}),
    )
    .to_string()
}

/// The channels of one server, on their own context.
pub struct Channels {
    recorded: [Arc<RawChannel>; RECORDED_TOPICS.len()],
    tf: Channel<FrameTransforms>,
    chain: Channel<SceneUpdate>,
    joint_limits: Arc<RawChannel>,
    robot_description: Arc<RawChannel>,
    view: Arc<RawChannel>,
    buf: Vec<u8>,
}

fn json_channel(
    ctx: &Arc<Context>,
    topic: &str,
    name: &str,
    schema: String,
) -> anyhow::Result<Arc<RawChannel>> {
    ctx.channel_builder(topic)
        .message_encoding("json")
        .schema(Schema::new(name, "jsonschema", schema.into_bytes()))
        .build_raw()
        .with_context(|| format!("cannot create the channel {topic}"))
}

/// Index of a recorded topic's channel.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Stream {
    JointState = 0,
    TorqueCommand = 1,
    Telemetry = 2,
    Setpoint = 3,
    Path = 4,
    Load = 5,
}

impl Channels {
    /// Creates every channel on `ctx`.
    pub fn new(ctx: &Arc<Context>) -> anyhow::Result<Channels> {
        let recorded = RECORDED_TOPICS.map(|topic| {
            let (name, schema) = mcap_log::schema(topic);
            json_channel(ctx, topic, name, schema)
        });
        let [a, b, c, d, e, f] = recorded;
        Ok(Channels {
            recorded: [a?, b?, c?, d?, e?, f?],
            tf: ctx.channel_builder(TOPIC_TF).build::<FrameTransforms>(),
            chain: ctx.channel_builder(TOPIC_CHAIN).build::<SceneUpdate>(),
            joint_limits: json_channel(
                ctx,
                TOPIC_JOINT_LIMITS,
                "hcc.JointLimits",
                joint_limits_schema(),
            )?,
            robot_description: json_channel(
                ctx,
                TOPIC_ROBOT_DESCRIPTION,
                "hcc.RobotDescription",
                robot_description_schema(),
            )?,
            view: json_channel(ctx, TOPIC_VIEW, "hcc.View", view_schema())?,
            buf: Vec::with_capacity(16 * 1024),
        })
    }

    fn log_json<T: Serialize>(buf: &mut Vec<u8>, channel: &RawChannel, msg: &T, log_time: u64) {
        buf.clear();
        // Serialising plain structs of numbers and strings cannot fail.
        if serde_json::to_writer(&mut *buf, msg).is_ok() {
            channel.log_with_meta(buf, PartialMetadata::with_log_time(log_time));
        }
    }

    /// Publishes a message of a recorded topic.
    pub fn recorded<T: Serialize>(&mut self, stream: Stream, msg: &T, log_time: u64) {
        Self::log_json(
            &mut self.buf,
            &self.recorded[stream as usize],
            msg,
            log_time,
        );
    }

    /// Whether any client subscribes to the stream (nothing to encode otherwise).
    pub fn wanted(&self, stream: Stream) -> bool {
        self.recorded[stream as usize].has_sinks()
    }

    /// Whether any client subscribes to any channel.
    pub fn any_wanted(&self) -> bool {
        self.recorded.iter().any(|c| c.has_sinks())
            || self.tf.has_sinks()
            || self.chain.has_sinks()
            || self.joint_limits.has_sinks()
    }

    pub fn joint_limits(&mut self, msg: &JointLimitsMsg, log_time: u64) {
        Self::log_json(&mut self.buf, &self.joint_limits, msg, log_time);
    }

    pub fn view(&mut self, msg: &ViewMsg, log_time: u64) {
        Self::log_json(&mut self.buf, &self.view, msg, log_time);
    }

    pub fn robot_description(&mut self, urdf: &str, log_time: u64) {
        Self::log_json(
            &mut self.buf,
            &self.robot_description,
            &json!({ "data": urdf }),
            log_time,
        );
    }

    /// Publishes the transform tree.
    pub fn tf(&self, transforms: &[Transform], log_time: u64) {
        self.tf.log_with_meta(
            &frame_transforms(transforms, log_time),
            PartialMetadata::with_log_time(log_time),
        );
    }
}

impl Channels {
    /// Publishes the chain's stick figure through `points` (world frame),
    /// and the load in the hand when there is one.
    pub fn chain(
        &self,
        points: &[nalgebra::Vector3<f64>],
        load: Option<LoadMarker>,
        log_time: u64,
    ) {
        if self.chain.has_sinks() {
            self.chain.log_with_meta(
                &stick_figure(points, load, log_time),
                PartialMetadata::with_log_time(log_time),
            );
        }
    }
}

fn stamp(log_time: u64) -> Timestamp {
    Timestamp::new(
        (log_time / 1_000_000_000).min(u32::MAX as u64) as u32,
        (log_time % 1_000_000_000) as u32,
    )
}

/// The load in the hand as the view draws it: its centre of mass in the
/// world and its mass.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct LoadMarker {
    pub com: nalgebra::Vector3<f64>,
    pub mass: f64,
}

/// Id of the load's scene entity on `/chain`.
pub const LOAD_ENTITY: &str = "load";

impl LoadMarker {
    /// The sphere's diameter, m: a ball of water of the load's mass (1 kg:
    /// 12.4 cm), at least 2 cm so that a light load shows.
    pub fn diameter(&self) -> f64 {
        (6.0 * self.mass.max(0.0) / (std::f64::consts::PI * 1000.0))
            .cbrt()
            .max(0.02)
    }
}

fn sphere(p: &nalgebra::Vector3<f64>, diameter: f64, color: Color) -> SpherePrimitive {
    SpherePrimitive {
        pose: Some(foxglove::messages::Pose {
            position: Some(Vector3 {
                x: p.x,
                y: p.y,
                z: p.z,
            }),
            orientation: Some(Quaternion {
                x: 0.0,
                y: 0.0,
                z: 0.0,
                w: 1.0,
            }),
        }),
        size: Some(Vector3 {
            x: diameter,
            y: diameter,
            z: diameter,
        }),
        color: Some(color),
    }
}

/// The chain through `points` as one scene entity: a line strip and a
/// sphere at every joint; and the load in the hand as a second entity
/// ([`LOAD_ENTITY`], a translucent sphere at its centre of mass), deleted
/// when the hand holds nothing.
pub fn stick_figure(
    points: &[nalgebra::Vector3<f64>],
    load: Option<LoadMarker>,
    log_time: u64,
) -> SceneUpdate {
    let point = |p: &nalgebra::Vector3<f64>| Point3 {
        x: p.x,
        y: p.y,
        z: p.z,
    };
    let color = Color {
        r: 0.95,
        g: 0.55,
        b: 0.1,
        a: 1.0,
    };
    let mut update = SceneUpdate {
        deletions: Vec::new(),
        entities: vec![SceneEntity {
            timestamp: Some(stamp(log_time)),
            frame_id: crate::frames::WORLD.to_string(),
            id: "chain".to_string(),
            lines: vec![LinePrimitive {
                r#type: line_primitive::Type::LineStrip as i32,
                thickness: 6.0,
                scale_invariant: true,
                points: points.iter().map(point).collect(),
                color: Some(color),
                ..Default::default()
            }],
            spheres: points.iter().map(|p| sphere(p, 0.04, color)).collect(),
            ..Default::default()
        }],
    };
    match load {
        Some(l) => update.entities.push(SceneEntity {
            timestamp: Some(stamp(log_time)),
            frame_id: crate::frames::WORLD.to_string(),
            id: LOAD_ENTITY.to_string(),
            spheres: vec![sphere(
                &l.com,
                l.diameter(),
                Color {
                    r: 0.2,
                    g: 0.5,
                    b: 0.95,
                    a: 0.6,
                },
            )],
            ..Default::default()
        }),
        None => update.deletions.push(SceneEntityDeletion {
            timestamp: Some(stamp(log_time)),
            r#type: scene_entity_deletion::Type::MatchingId as i32,
            id: LOAD_ENTITY.to_string(),
        }),
    }
    update
}

/// The tree as `foxglove.FrameTransforms`.
pub fn frame_transforms(transforms: &[Transform], log_time: u64) -> FrameTransforms {
    let stamp = stamp(log_time);
    FrameTransforms {
        transforms: transforms
            .iter()
            .map(|t| {
                let p = t.pose.translation.vector;
                let r = t.pose.rotation;
                FrameTransform {
                    timestamp: Some(stamp),
                    parent_frame_id: t.parent.clone(),
                    child_frame_id: t.child.clone(),
                    translation: Some(Vector3 {
                        x: p.x,
                        y: p.y,
                        z: p.z,
                    }),
                    rotation: Some(Quaternion {
                        x: r.i,
                        y: r.j,
                        z: r.k,
                        w: r.w,
                    }),
                }
            })
            .collect(),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The live channels carry the recording's topics with the recording's
    /// schemas, byte for byte.
    #[test]
    fn recorded_topics_carry_the_recordings_schemas() {
        let ctx = Context::new();
        let _channels = Channels::new(&ctx).unwrap();
        for topic in RECORDED_TOPICS {
            let ch = ctx.get_channel_by_topic(topic).unwrap();
            let (name, schema) = mcap_log::schema(topic);
            let s = ch.schema().unwrap();
            assert_eq!(s.name, name);
            assert_eq!(s.encoding, "jsonschema");
            assert_eq!(&*s.data, schema.as_bytes());
            assert_eq!(ch.message_encoding(), "json");
        }
        assert!(
            mcap_log::TOPICS
                .iter()
                .all(|t| *t == mcap_log::TOPIC_RECORDER || RECORDED_TOPICS.contains(t))
        );
        let tf = ctx.get_channel_by_topic(TOPIC_TF).unwrap();
        assert_eq!(tf.schema().unwrap().name, "foxglove.FrameTransforms");
        for (topic, schema) in [
            (TOPIC_VIEW, view_schema()),
            (TOPIC_JOINT_LIMITS, joint_limits_schema()),
            (TOPIC_ROBOT_DESCRIPTION, robot_description_schema()),
        ] {
            let ch = ctx.get_channel_by_topic(topic).unwrap();
            assert_eq!(&*ch.schema().unwrap().data, schema.as_bytes());
        }
    }

    /// Every field of the messages the server writes is in its schema.
    #[test]
    fn view_messages_match_their_schemas() {
        for (msg, schema) in [
            (
                serde_json::to_value(ViewMsg::default()).unwrap(),
                view_schema(),
            ),
            (
                serde_json::to_value(JointLimitsMsg {
                    q_lower: vec![],
                    q_upper: vec![],
                    qd_max: vec![],
                    tau_max: vec![],
                    q_fraction: vec![],
                    qd_fraction: vec![],
                    tau_fraction: vec![],
                    q_fraction_max: None,
                    qd_fraction_max: None,
                    tau_fraction_max: None,
                })
                .unwrap(),
                joint_limits_schema(),
            ),
        ] {
            let schema: serde_json::Value = serde_json::from_str(&schema).unwrap();
            let props = schema["properties"].as_object().unwrap();
            let fields = msg.as_object().unwrap();
            assert_eq!(
                props.keys().collect::<Vec<_>>(),
                fields.keys().collect::<Vec<_>>(),
                "{}",
                schema["title"]
            );
        }
    }

    #[test]
    fn the_load_is_a_sphere_at_its_centre_of_mass_and_deleted_without_one() {
        let points = [
            nalgebra::Vector3::zeros(),
            nalgebra::Vector3::new(0.0, 0.0, 0.3),
        ];
        let load = LoadMarker {
            com: nalgebra::Vector3::new(0.1, 0.2, 0.4),
            mass: 1.0,
        };
        let u = stick_figure(&points, Some(load), 5);
        assert!(u.deletions.is_empty());
        let e = u.entities.iter().find(|e| e.id == LOAD_ENTITY).unwrap();
        let s = &e.spheres[0];
        let p = s.pose.as_ref().unwrap().position.unwrap();
        assert_eq!((p.x, p.y, p.z), (0.1, 0.2, 0.4));
        // A ball of water of 1 kg: 12.4 cm across.
        assert!((s.size.unwrap().x - 0.1241).abs() < 1e-4, "{:?}", s.size);
        let light = LoadMarker { mass: 1e-3, ..load };
        assert_eq!(light.diameter(), 0.02);
        let u = stick_figure(&points, None, 5);
        assert_eq!(u.entities.len(), 1, "the chain alone");
        assert_eq!(u.deletions.len(), 1);
        assert_eq!(u.deletions[0].id, LOAD_ENTITY);
    }

    #[test]
    fn transforms_keep_their_values() {
        use nalgebra::{Isometry3, Vector3 as V};
        let pose = Isometry3::new(V::new(0.1, -0.2, 0.3), V::new(0.4, 0.5, -0.6));
        let t = Transform {
            parent: "world".into(),
            child: "a".into(),
            pose,
        };
        let m = frame_transforms(&[t], 1_700_000_000_123_456_789);
        let f = &m.transforms[0];
        let ts = f.timestamp.unwrap();
        assert_eq!((ts.sec(), ts.nsec()), (1_700_000_000, 123_456_789));
        assert_eq!(
            (f.parent_frame_id.as_str(), f.child_frame_id.as_str()),
            ("world", "a")
        );
        let r = f.rotation.unwrap();
        assert_eq!(
            (r.x, r.y, r.z, r.w),
            (
                pose.rotation.i,
                pose.rotation.j,
                pose.rotation.k,
                pose.rotation.w
            )
        );
        let p = f.translation.unwrap();
        assert_eq!((p.x, p.y, p.z), (0.1, -0.2, 0.3));
    }
}
