//! The scenario service: a tool that connects after the controller published
//! its document reads it whole (the service keeps the last sample and the
//! publisher's connection upkeep hands it over); with no controller, or an
//! older one without the service, the tool is told which, with the
//! `--config` hint. Own file prefix and namespace; the
//! files are removed after.

use std::time::Duration;

use hcc_msgs::ipc::{self, ScenarioPublisher, ScenarioReadError, UpdateConnections, read_scenario};
use hcc_msgs::scenario::{JointInfo, LevelInfo, SCENARIO_SCHEMA_VERSION, ScenarioDoc};
use hcc_msgs::{Namespace, ServiceNames};
use iceoryx2::prelude::SignalHandlingMode;

fn doc(namespace: &str) -> ScenarioDoc {
    ScenarioDoc {
        version: SCENARIO_SCHEMA_VERSION,
        name: "paper-sim1".into(),
        namespace: namespace.into(),
        rate_hz: 1000.0,
        form: "extended".into(),
        coriolis_cancellation: true,
        gravity_compensation: true,
        path: "config/paper-sim1.toml".into(),
        // A document of some size: a long scenario text.
        toml: "# a comment line of the scenario\n".repeat(4000),
        urdf_path: "planar4.urdf".into(),
        urdf: "<robot name=\"planar4\"/>".into(),
        paths: Default::default(),
        levels: vec![
            LevelInfo {
                name: "TCP position".into(),
                tasks: vec!["position".into()],
                dim: 2,
                goal: vec![0.9, 0.8],
                stiffness: vec![1000.0, 0.0, 0.0, 1000.0],
                damping: vec![40.0, 0.0, 0.0, 40.0],
            },
            LevelInfo {
                name: "joint 1".into(),
                tasks: vec!["joint".into()],
                dim: 1,
                goal: vec![0.35],
                stiffness: vec![2400.0],
                damping: vec![15.0],
            },
        ],
        joints: (1..=4)
            .map(|k| JointInfo::new(&format!("joint{k}"), -3.0, 3.0, 2.0, f64::INFINITY))
            .collect(),
    }
}

#[test]
fn a_tool_that_connects_later_reads_the_whole_document_and_none_without_a_controller() {
    let prefix = format!("hcctscn{}_", std::process::id());
    let names = ServiceNames::for_namespace(Namespace::unique("scenario_svc").unwrap());
    let sent = doc(names.namespace().as_str());
    {
        // A tool that opened the namespace's services itself is no controller.
        let tool = ipc::create_node("tool", SignalHandlingMode::Disabled, Some(&prefix)).unwrap();
        let tool_services = ipc::Services::open(&tool, &names).unwrap();
        let e = read_scenario(&tool, &names, Duration::from_millis(20)).unwrap_err();
        assert!(matches!(e, ScenarioReadError::NoController { .. }), "{e}");
        assert!(e.to_string().contains("--config"), "{e}");
        // A controller older than the scenario service: attached to its
        // services, no scenario.
        let node = ipc::create_node(
            ipc::CONTROLLER_NODE,
            SignalHandlingMode::Disabled,
            Some(&prefix),
        )
        .unwrap();
        let services = ipc::Services::open(&node, &names).unwrap();
        let e = read_scenario(&node, &names, Duration::from_millis(20)).unwrap_err();
        assert!(
            matches!(e, ScenarioReadError::OlderController { .. }),
            "{e}"
        );
        assert!(
            e.to_string().contains("older") && e.to_string().contains("--config"),
            "{e}"
        );

        let publisher = ScenarioPublisher::publish(&node, &names, &sent).unwrap();
        let reader = std::thread::spawn({
            let (names, prefix) = (names.clone(), prefix.clone());
            move || {
                let node =
                    ipc::create_node("tool", SignalHandlingMode::Disabled, Some(&prefix)).unwrap();
                read_scenario(&node, &names, Duration::from_secs(10))
            }
        });
        // The controller's connection upkeep.
        while !reader.is_finished() {
            publisher.update_connections().unwrap();
            std::thread::sleep(Duration::from_millis(1));
        }
        let got = reader.join().unwrap().unwrap();
        assert_eq!(got, sent);
        assert_eq!(got.joints[0].effort, None);
        drop((services, tool_services));
    }
    let files = ipc::leftover_files(&prefix).unwrap();
    for f in files.iter().filter(|f| f.global_mgmt) {
        std::fs::remove_file(&f.path).unwrap();
    }
    let rest: Vec<_> = files.iter().filter(|f| !f.global_mgmt).collect();
    assert!(rest.is_empty(), "files left behind: {rest:?}");
}
