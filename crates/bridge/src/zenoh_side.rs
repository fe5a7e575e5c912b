//! The Zenoh side: one session, the bridge's node in the ROS graph, and its
//! publishers and subscriptions as rmw_zenoh declares them — a liveliness
//! token per entity ([`crate::names::LivelinessToken`]), data on the topic
//! key expression ([`crate::names::topic_key`]), every sample with its
//! attachment ([`crate::attachment::Attachment`]).
//!
//! Publishers drop rather than block when the network is congested
//! (Zenoh's `CongestionControl::Drop`): a slow remote subscriber costs
//! samples (counted), never the bridge's pace.

use std::path::Path;

use anyhow::{Context, anyhow};
use zenoh::liveliness::LivelinessToken;
use zenoh::pubsub::{Publisher, Subscriber};
use zenoh::qos::CongestionControl;
use zenoh::sample::Sample;
use zenoh::{Config, Session, Wait};

use crate::attachment::{Attachment, realtime_now_ns};
use crate::names::{self, EntityKind, NODE_NAME, RosType};

/// The Zenoh configuration: the file given, or rmw_zenoh's default session
/// configuration (`DEFAULT_RMW_ZENOH_SESSION_CONFIG.json5`: a peer that
/// connects to the router on `tcp/localhost:7447`, listens on loopback,
/// no multicast scouting, gossip scouting through the router).
pub fn zenoh_config(file: Option<&Path>) -> anyhow::Result<Config> {
    if let Some(path) = file {
        return Config::from_file(path)
            .map_err(|e| anyhow!("--zenoh-config {}: {e}", path.display()));
    }
    let mut c = Config::default();
    for (key, value) in [
        ("mode", r#""peer""#),
        ("connect/endpoints", r#"["tcp/localhost:7447"]"#),
        ("listen/endpoints", r#"["tcp/localhost:0"]"#),
        ("scouting/multicast/enabled", "false"),
        ("scouting/gossip/enabled", "true"),
    ] {
        c.insert_json5(key, value)
            .map_err(|e| anyhow!("zenoh configuration {key}: {e}"))?;
    }
    Ok(c)
}

/// The bridge's node in the ROS graph of one domain.
pub struct Graph {
    session: Session,
    domain: u32,
    zid: String,
    /// The node's namespace, `/<ns>`.
    namespace: String,
    next_entity: u32,
    _node: LivelinessToken,
}

/// A publisher of one ROS topic.
pub struct RosPublisher {
    publisher: Publisher<'static>,
    _token: LivelinessToken,
    gid: [u8; 16],
    seq: i64,
    /// The topic, `/<ns>/...`.
    pub topic: String,
    /// Bytes published (payload and attachment).
    pub bytes: u64,
}

/// A subscription of one ROS topic (dropped: undeclared).
pub struct RosSubscription {
    _subscriber: Subscriber<()>,
    _token: LivelinessToken,
}

impl Graph {
    /// Opens the session and declares the node `hcc_bridge` in namespace
    /// `/<namespace>` of `domain`.
    pub fn open(config: Config, domain: u32, namespace: &str) -> anyhow::Result<Graph> {
        let session = zenoh::open(config)
            .wait()
            .map_err(|e| anyhow!("cannot open the Zenoh session: {e}"))?;
        let zid = session.zid().to_string();
        let namespace = format!("/{namespace}");
        let key = names::LivelinessToken {
            domain,
            zid: &zid,
            node_id: 0,
            entity_id: 0,
            kind: EntityKind::Node,
            namespace: &namespace,
            node: NODE_NAME,
            topic: None,
        }
        .key();
        let node = declare_token(&session, &key)?;
        Ok(Graph {
            session,
            domain,
            zid,
            namespace,
            next_entity: 1,
            _node: node,
        })
    }

    /// The session's Zenoh id.
    pub fn zid(&self) -> &str {
        &self.zid
    }

    /// `/<ns>/<name>`.
    pub fn topic(&self, name: &str) -> String {
        format!("{}/{name}", self.namespace)
    }

    fn token_key(&mut self, kind: EntityKind, topic: &str, ty: &RosType) -> String {
        let id = self.next_entity;
        self.next_entity += 1;
        names::LivelinessToken {
            domain: self.domain,
            zid: &self.zid,
            node_id: 0,
            entity_id: id,
            kind,
            namespace: &self.namespace,
            node: NODE_NAME,
            topic: Some((topic, ty)),
        }
        .key()
    }

    /// Declares a publisher of `ty` on `topic` (absolute).
    pub fn publisher(&mut self, topic: &str, ty: &RosType) -> anyhow::Result<RosPublisher> {
        let token_key = self.token_key(EntityKind::Publisher, topic, ty);
        let key = names::topic_key(self.domain, topic, ty);
        let publisher = self
            .session
            .declare_publisher(key.clone())
            .congestion_control(CongestionControl::Drop)
            .wait()
            .map_err(|e| anyhow!("cannot declare the publisher {key}: {e}"))?;
        Ok(RosPublisher {
            publisher,
            _token: declare_token(&self.session, &token_key)?,
            gid: names::entity_gid(&token_key),
            seq: 0,
            topic: topic.to_owned(),
            bytes: 0,
        })
    }

    /// Declares a subscription of `ty` on `topic`; `on_sample` runs on a
    /// Zenoh thread for every sample (keep it short: hand the sample on).
    pub fn subscription<F>(
        &mut self,
        topic: &str,
        ty: &RosType,
        on_sample: F,
    ) -> anyhow::Result<RosSubscription>
    where
        F: Fn(Sample) + Send + Sync + 'static,
    {
        let token_key = self.token_key(EntityKind::Subscription, topic, ty);
        let key = names::topic_key(self.domain, topic, ty);
        let subscriber = self
            .session
            .declare_subscriber(key.clone())
            .callback(on_sample)
            .wait()
            .map_err(|e| anyhow!("cannot declare the subscriber {key}: {e}"))?;
        Ok(RosSubscription {
            _subscriber: subscriber,
            _token: declare_token(&self.session, &token_key)?,
        })
    }

    /// Closes the session (undeclares everything at once).
    pub fn close(self) -> anyhow::Result<()> {
        self.session
            .close()
            .wait()
            .map_err(|e| anyhow!("closing the Zenoh session: {e}"))
    }
}

fn declare_token(session: &Session, key: &str) -> anyhow::Result<LivelinessToken> {
    session
        .liveliness()
        .declare_token(key.to_owned())
        .wait()
        .map_err(|e| anyhow!("cannot declare the liveliness token {key}: {e}"))
}

impl RosPublisher {
    /// Publishes one CDR message with the next sequence number.
    pub fn put(&mut self, payload: &[u8]) -> anyhow::Result<()> {
        self.seq += 1;
        let attachment = Attachment {
            sequence_number: self.seq,
            source_timestamp: realtime_now_ns(),
            source_gid: self.gid,
        };
        self.publisher
            .put(payload.to_vec())
            .attachment(attachment.to_zbytes())
            .wait()
            .map_err(|e| anyhow!("{e}"))
            .with_context(|| format!("publishing on {}", self.topic))?;
        self.bytes += (payload.len() + 33) as u64;
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_default_is_rmw_zenohs_session() {
        let c = zenoh_config(None).unwrap();
        let json = |key: &str| c.get_json(key).unwrap();
        assert_eq!(json("mode"), r#""peer""#);
        assert_eq!(json("connect/endpoints"), r#"["tcp/localhost:7447"]"#);
        assert_eq!(json("scouting/multicast/enabled"), "false");
    }

    #[test]
    fn the_documented_tls_example_is_a_valid_configuration() {
        let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../docs/bridge-zenoh-tls.json5");
        let c = zenoh_config(Some(&path)).unwrap();
        assert_eq!(
            c.get_json("connect/endpoints").unwrap(),
            r#"["tls/robot-host:7447"]"#
        );
        assert_eq!(
            c.get_json("transport/auth/usrpwd/user").unwrap(),
            r#""hcc-bridge""#
        );
        assert_eq!(
            c.get_json("transport/link/tls/enable_mtls").unwrap(),
            "true"
        );
        let bad = std::env::temp_dir().join(format!("hcc-bridge-bad-{}.json5", std::process::id()));
        std::fs::write(&bad, "{ mode: 42 }").unwrap();
        let err = zenoh_config(Some(&bad)).unwrap_err().to_string();
        std::fs::remove_file(&bad).unwrap();
        assert!(err.contains("--zenoh-config"), "{err}");
    }
}
