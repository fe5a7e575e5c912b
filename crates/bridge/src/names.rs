//! Names on the wire of rmw_zenoh (ROS 2 Jazzy and later), built exactly as
//! rmw_zenoh builds them, so that ROS 2 nodes running `rmw_zenoh_cpp` match
//! hcc's topics and list its node:
//!
//! * ROS names ([`ros_name`]): hcc's namespace and level names made valid
//!   ROS name tokens (lower case, other characters `_`).
//! * the data key expression ([`topic_key`]):
//!   `<domain>/<topic without its leading '/'>/<dds type name>/<type hash>`
//!   (rmw_zenoh `TopicInfo`: the topic key expression), e.g.
//!   `0/panda/joint_states/sensor_msgs::msg::dds_::JointState_/RIHS01_a13e…`;
//! * the liveliness tokens of the graph ([`LivelinessToken`]):
//!   `@ros2_lv/<domain>/<zid>/<nid>/<eid>/<NN|MP|MS>/<enclave>/<namespace>/<node>`
//!   and, for publishers and subscribers,
//!   `/<topic>/<dds type name>/<type hash>/<qos>`, with every `/` inside a
//!   part replaced by `%` (rmw_zenoh `liveliness_utils.cpp`:
//!   `Entity::Entity`, `mangle_name`, `qos_to_keyexpr`);
//! * the entity's GID ([`entity_gid`]): XXH3-128 of its liveliness key
//!   expression, low 64 bits then high 64 bits, little endian (rmw_zenoh
//!   `Entity::Entity`), carried in every sample's attachment.

use xxhash_rust::xxh3::xxh3_128;

/// Prefix of every rmw_zenoh liveliness token.
pub const ADMIN_SPACE: &str = "@ros2_lv";

/// The QoS part of a token for rmw_zenoh's default profile (reliable,
/// volatile, keep last 10; deadline, lifespan and liveliness at their
/// defaults), in rmw_zenoh's compact form where defaults are left empty:
/// `<reliability>:<durability>:<history>,<depth>:<deadline s>,<ns>:<lifespan s>,<ns>:<liveliness>,<lease s>,<ns>`.
/// Reliable publishers match reliable and best-effort subscriptions alike.
pub const DEFAULT_QOS: &str = "::,10:,:,:,,";

/// The node name of the bridge in the ROS graph.
pub const NODE_NAME: &str = "hcc_bridge";

/// A ROS 2 message type: its name and its RIHS01 type hash (REP 2011).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct RosType {
    /// `package/msg/Type`.
    pub name: &'static str,
    /// `RIHS01_` and the SHA-256 of the type description, in hex.
    pub hash: &'static str,
}

impl RosType {
    /// The DDS type name rmw_zenoh puts in keys and tokens:
    /// `package::msg::dds_::Type_`.
    pub fn dds_name(&self) -> String {
        let mut parts = self.name.rsplitn(2, '/');
        let ty = parts.next().unwrap_or_default();
        let pkg = parts.next().unwrap_or_default().replace('/', "::");
        format!("{pkg}::dds_::{ty}_")
    }
}

/// A string made a valid ROS name token: ASCII letters lower-cased, digits
/// kept, every other character (and every run of them) one `_`, no `_` at
/// either end, and `level_`/`hcc_` style `prefix` put in front when the
/// result is empty or starts with a digit (ROS name tokens must start with
/// a letter or `_`, must not hold `__`).
pub fn ros_name(raw: &str, prefix: &str) -> String {
    let mut out = String::with_capacity(raw.len());
    for c in raw.chars() {
        if c.is_ascii_alphanumeric() {
            out.push(c.to_ascii_lowercase());
        } else if !out.is_empty() && !out.ends_with('_') {
            out.push('_');
        }
    }
    while out.ends_with('_') {
        out.pop();
    }
    if out.is_empty() || out.starts_with(|c: char| c.is_ascii_digit()) {
        out.insert_str(0, prefix);
    }
    out
}

/// [`ros_name`] of every level name, made unique by `_2`, `_3`, … in
/// order (two levels named alike must not share a goal topic).
pub fn unique_ros_names<S: AsRef<str>>(raw: &[S], prefix: &str) -> Vec<String> {
    let mut out: Vec<String> = Vec::with_capacity(raw.len());
    for (i, r) in raw.iter().enumerate() {
        let base = ros_name(r.as_ref(), &format!("{prefix}{}_", i + 1));
        let mut name = base.clone();
        let mut k = 2;
        while out.contains(&name) {
            name = format!("{base}_{k}");
            k += 1;
        }
        out.push(name);
    }
    out
}

/// `/` replaced by `%`, as rmw_zenoh mangles names inside a token.
pub fn mangle(name: &str) -> String {
    name.replace('/', "%")
}

/// The data key expression of `topic` (absolute, `/a/b`) of `ty` in `domain`.
pub fn topic_key(domain: u32, topic: &str, ty: &RosType) -> String {
    format!(
        "{domain}/{}/{}/{}",
        topic.trim_matches('/'),
        ty.dds_name(),
        ty.hash
    )
}

/// Kind of a graph entity in a liveliness token.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum EntityKind {
    /// A node (`NN`).
    Node,
    /// A publisher (`MP`).
    Publisher,
    /// A subscription (`MS`).
    Subscription,
}

impl EntityKind {
    /// The token's code.
    pub fn code(self) -> &'static str {
        match self {
            EntityKind::Node => "NN",
            EntityKind::Publisher => "MP",
            EntityKind::Subscription => "MS",
        }
    }
}

/// The parts of one liveliness token.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct LivelinessToken<'a> {
    /// ROS domain id.
    pub domain: u32,
    /// The Zenoh session id, as Zenoh prints it.
    pub zid: &'a str,
    /// The node's id within the session.
    pub node_id: u32,
    /// The entity's id within the session (the node's own for `NN`).
    pub entity_id: u32,
    /// Node, publisher or subscription.
    pub kind: EntityKind,
    /// The node's namespace (absolute, `/` for none).
    pub namespace: &'a str,
    /// The node's name.
    pub node: &'a str,
    /// Topic (absolute) and type, for publishers and subscriptions.
    pub topic: Option<(&'a str, &'a RosType)>,
}

impl LivelinessToken<'_> {
    /// The key expression: the enclave is `/` (no security enclave).
    pub fn key(&self) -> String {
        let mut key = format!(
            "{ADMIN_SPACE}/{}/{}/{}/{}/{}/{}/{}/{}",
            self.domain,
            self.zid,
            self.node_id,
            self.entity_id,
            self.kind.code(),
            mangle("/"),
            mangle(self.namespace),
            mangle(self.node)
        );
        if let Some((topic, ty)) = self.topic {
            key.push_str(&format!(
                "/{}/{}/{}/{DEFAULT_QOS}",
                mangle(topic),
                mangle(&ty.dds_name()),
                mangle(ty.hash)
            ));
        }
        key
    }
}

/// The GID rmw_zenoh gives the entity of liveliness key `key`: XXH3-128 of
/// the key, its low 64 bits then its high 64 bits, each little endian.
pub fn entity_gid(key: &str) -> [u8; 16] {
    let h = xxh3_128(key.as_bytes());
    let mut gid = [0u8; 16];
    gid[..8].copy_from_slice(&(h as u64).to_le_bytes());
    gid[8..].copy_from_slice(&((h >> 64) as u64).to_le_bytes());
    gid
}

#[cfg(test)]
mod tests {
    use super::*;

    const JOINT_STATE: RosType = RosType {
        name: "sensor_msgs/msg/JointState",
        hash: "RIHS01_a13ee3a330e346c9d87b5aa18d24e11690752bd33a0350f11c5882bc9179260e",
    };

    #[test]
    fn dds_type_names() {
        assert_eq!(
            JOINT_STATE.dds_name(),
            "sensor_msgs::msg::dds_::JointState_"
        );
        let t = RosType {
            name: "hcc_msgs/msg/Telemetry",
            hash: "RIHS01_0",
        };
        assert_eq!(t.dds_name(), "hcc_msgs::msg::dds_::Telemetry_");
    }

    #[test]
    fn names_are_valid_ros_tokens() {
        assert_eq!(ros_name("TCP pose", "level_"), "tcp_pose");
        assert_eq!(ros_name("elbow-away  (soft)", "level_"), "elbow_away_soft");
        assert_eq!(ros_name("__x__", "level_"), "x");
        assert_eq!(ros_name("3d position", "level_"), "level_3d_position");
        assert_eq!(ros_name("äöü", "level_"), "level_");
        assert_eq!(ros_name("pyt_123_4", "hcc_"), "pyt_123_4");
        assert_eq!(ros_name("My-Robot", "hcc_"), "my_robot");
        let names = unique_ros_names(&["Pose", "pose", "", "posture"], "level");
        assert_eq!(names, ["pose", "pose_2", "level3_", "posture"]);
        for n in names {
            assert!(!n.contains("__") && !n.starts_with(|c: char| c.is_ascii_digit()));
        }
    }

    #[test]
    fn topic_keys_follow_rmw_zenoh() {
        assert_eq!(
            topic_key(0, "/panda/joint_states", &JOINT_STATE),
            "0/panda/joint_states/sensor_msgs::msg::dds_::JointState_/RIHS01_a13ee3a330e346c9d87b5aa18d24e11690752bd33a0350f11c5882bc9179260e"
        );
        assert!(topic_key(42, "/a/b/goal", &JOINT_STATE).starts_with("42/a/b/goal/"));
    }

    #[test]
    fn liveliness_tokens_follow_rmw_zenoh() {
        let node = LivelinessToken {
            domain: 0,
            zid: "aabb",
            node_id: 0,
            entity_id: 0,
            kind: EntityKind::Node,
            namespace: "/panda",
            node: NODE_NAME,
            topic: None,
        };
        assert_eq!(node.key(), "@ros2_lv/0/aabb/0/0/NN/%/%panda/hcc_bridge");
        let publisher = LivelinessToken {
            entity_id: 3,
            kind: EntityKind::Publisher,
            topic: Some(("/panda/joint_states", &JOINT_STATE)),
            ..node.clone()
        };
        assert_eq!(
            publisher.key(),
            "@ros2_lv/0/aabb/0/3/MP/%/%panda/hcc_bridge/%panda%joint_states/\
             sensor_msgs::msg::dds_::JointState_/RIHS01_a13ee3a330e346c9d87b5aa18d24e11690752bd33a0350f11c5882bc9179260e/::,10:,:,:,,"
        );
        let sub = LivelinessToken {
            kind: EntityKind::Subscription,
            ..publisher.clone()
        };
        assert!(sub.key().contains("/MS/"));
        // The parts rmw_zenoh splits on '/': 13 for a topic entity, none empty.
        let key = publisher.key();
        let parts: Vec<&str> = key.split('/').collect();
        assert_eq!(parts.len(), 13);
        assert!(parts.iter().all(|p| !p.is_empty()));
        assert_eq!(parts[5], "MP");
        assert_eq!(parts[12].split(':').count(), 6);
    }

    #[test]
    fn gids_are_the_xxh3_128_of_the_token() {
        let key = "@ros2_lv/0/aabb/0/3/MP/%/%panda/hcc_bridge";
        let gid = entity_gid(key);
        let h = xxh3_128(key.as_bytes());
        assert_eq!(u64::from_le_bytes(gid[..8].try_into().unwrap()), h as u64);
        assert_eq!(
            u64::from_le_bytes(gid[8..].try_into().unwrap()),
            (h >> 64) as u64
        );
        assert_ne!(
            gid,
            entity_gid("@ros2_lv/0/aabb/0/4/MP/%/%panda/hcc_bridge")
        );
        // XXH3-128 of the empty input (the reference value of the algorithm).
        assert_eq!(xxh3_128(b""), 0x99aa_06d3_0147_98d8_6001_c324_468d_497f);
    }
}
