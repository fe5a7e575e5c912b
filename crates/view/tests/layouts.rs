//! The Foxglove layouts of `docs/foxglove/` loaded and checked against what
//! the server publishes: every panel of the mosaic is configured (and every
//! configuration placed), every message path names a channel of the server
//! and a field of that channel's schema, and the 3-D panels follow the
//! world frame and load the URDF the server serves.

use hcc_record::mcap_log;
use hcc_view::{assets, channels, frames};
use serde_json::Value;
use std::collections::BTreeSet;
use std::path::PathBuf;

fn layouts() -> Vec<(PathBuf, Value)> {
    let dir = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../docs/foxglove");
    let mut out: Vec<(PathBuf, Value)> = std::fs::read_dir(&dir)
        .unwrap()
        .map(|e| e.unwrap().path())
        .filter(|p| p.extension().is_some_and(|e| e == "json"))
        .map(|p| {
            let v = serde_json::from_str(&std::fs::read_to_string(&p).unwrap()).unwrap();
            (p, v)
        })
        .collect();
    out.sort_by(|a, b| a.0.cmp(&b.0));
    out
}

/// The JSON Schema of a JSON channel of the server; `None` for the others.
fn schema(topic: &str) -> Option<Value> {
    let text = match topic {
        channels::TOPIC_VIEW => channels::view_schema(),
        channels::TOPIC_JOINT_LIMITS => channels::joint_limits_schema(),
        channels::TOPIC_ROBOT_DESCRIPTION => channels::robot_description_schema(),
        t if channels::RECORDED_TOPICS.contains(&t) => mcap_log::schema(t).1,
        _ => return None,
    };
    Some(serde_json::from_str(&text).unwrap())
}

fn all_topics() -> BTreeSet<&'static str> {
    let mut t: BTreeSet<&str> = channels::RECORDED_TOPICS.into_iter().collect();
    t.extend([
        channels::TOPIC_TF,
        channels::TOPIC_CHAIN,
        channels::TOPIC_JOINT_LIMITS,
        channels::TOPIC_ROBOT_DESCRIPTION,
        channels::TOPIC_VIEW,
    ]);
    t
}

/// Walks `/topic.a[0].b` through the topic's schema; the error says where it stops.
fn resolve(path: &str) -> Result<(), String> {
    let (topic, rest) = path.split_once('.').unwrap_or((path, ""));
    let mut node = schema(topic).ok_or_else(|| format!("{topic} is not a JSON channel"))?;
    for segment in rest.split('.').filter(|s| !s.is_empty()) {
        let name = segment.split('[').next().unwrap_or(segment);
        node = node["properties"]
            .get(name)
            .or_else(|| node.get("additionalProperties").filter(|a| a.is_object()))
            .cloned()
            .ok_or_else(|| format!("{path}: no field {name}"))?;
        for _ in 0..segment.matches('[').count() {
            if node["type"] != "array" {
                return Err(format!("{path}: {name} is not an array"));
            }
            node = node["items"].clone();
        }
    }
    Ok(())
}

fn leaves(tree: &Value, out: &mut Vec<String>) {
    match tree {
        Value::String(s) => out.push(s.clone()),
        Value::Object(o) => {
            leaves(&o["first"], out);
            leaves(&o["second"], out);
        }
        other => panic!("not a mosaic node: {other}"),
    }
}

#[test]
fn layouts_load_against_the_servers_channels() {
    let layouts = layouts();
    let names: Vec<String> = layouts
        .iter()
        .map(|(p, _)| p.file_name().unwrap().to_string_lossy().into_owned())
        .collect();
    assert_eq!(names, ["hcc-safety.json", "hcc-tuning.json"]);
    let topics = all_topics();
    for (file, layout) in &layouts {
        let file = file.display();
        let config = layout["configById"].as_object().unwrap();
        let mut placed = Vec::new();
        leaves(&layout["layout"], &mut placed);
        let placed_set: BTreeSet<&String> = placed.iter().collect();
        assert_eq!(
            placed_set.len(),
            placed.len(),
            "{file}: a panel placed twice"
        );
        assert_eq!(
            placed_set,
            config.keys().collect::<BTreeSet<_>>(),
            "{file}: placed panels and configurations differ"
        );
        let mut paths = 0;
        for (id, panel) in config {
            let kind = id.split('!').next().unwrap();
            match kind {
                "Plot" | "StateTransitions" => {
                    for p in panel["paths"].as_array().unwrap() {
                        resolve(p["value"].as_str().unwrap())
                            .unwrap_or_else(|e| panic!("{file} {id}: {e}"));
                        assert_eq!(p["timestampMethod"], "receiveTime", "{file} {id}");
                        paths += 1;
                    }
                }
                "RawMessages" => {
                    resolve(panel["topicPath"].as_str().unwrap())
                        .unwrap_or_else(|e| panic!("{file} {id}: {e}"));
                    paths += 1;
                }
                "3D" => {
                    assert_eq!(panel["followTf"], frames::WORLD, "{file} {id}");
                    for t in panel["topics"].as_object().unwrap().keys() {
                        assert!(topics.contains(t.as_str()), "{file} {id}: no channel {t}");
                    }
                    let urdf = panel["layers"]
                        .as_object()
                        .unwrap()
                        .values()
                        .find(|l| l["layerId"] == "foxglove.Urdf")
                        .unwrap_or_else(|| panic!("{file} {id}: no URDF layer"));
                    assert_eq!(urdf["url"], assets::URDF_URI, "{file} {id}");
                }
                other => panic!("{file}: unexpected panel {other}"),
            }
        }
        assert!(paths > 10, "{file}: {paths} message paths");
    }
}

#[test]
fn the_resolver_rejects_what_the_server_does_not_publish() {
    assert!(resolve("/telemetry.levels[0].S").is_ok());
    assert!(resolve("/telemetry.counters.saturations").is_ok());
    assert!(resolve("/telemetry.levels[0].contact").is_err());
    assert!(resolve("/telemetry.P_mu[0]").is_err());
    assert!(resolve("/contact.tau_ext[0]").is_err());
    assert!(resolve("/tf.transforms").is_err());
}
