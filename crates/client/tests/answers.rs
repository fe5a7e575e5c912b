//! The client over real iceoryx2 services against the controller's decision
//! step (a stand-in for the daemon: it takes the setpoints the client sends
//! and publishes its telemetry): accepted and rejected answers, a timeout
//! without a controller, convergence.

use std::path::PathBuf;
use std::time::Duration;

use hcc_client::{Client, ClientError};
use hcc_config::Scenario;
use hcc_control::Controller;
use hcc_cycle::{ControlCycle, CycleSettings};
use hcc_msgs::ipc::{self, Services};
use hcc_msgs::{JointState, Namespace, ServiceNames, SetpointRejection};
use iceoryx2::prelude::SignalHandlingMode;

#[test]
fn answers_reach_the_client() {
    let prefix = format!("hcccl{}_", std::process::id());
    let ns = Namespace::unique("client").unwrap();
    let names = ServiceNames::for_namespace(ns.clone());
    let node =
        ipc::create_node("ctl-stand-in", SignalHandlingMode::Disabled, Some(&prefix)).unwrap();
    let services = Services::open(&node, &names).unwrap();
    let setpoints = services.setpoint_subscriber(16).unwrap();
    let telemetry = services.telemetry_publisher().unwrap();

    let path =
        PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../config/panda-pose-posture.toml");
    let sc = Scenario::load(&path).unwrap();
    let c = Controller::new(&sc.model, sc.spec.clone(), &sc.q0).unwrap();
    let mut d = ControlCycle::new(c, &CycleSettings::from_scenario(&sc)).unwrap();
    let n = sc.model.nq();
    let mut state = JointState::zeroed();
    state
        .set_joints(sc.q0.as_slice(), &vec![0.0; n], &vec![0.0; n])
        .unwrap();

    let mut client = Client::connect(ns.as_str(), Some(&prefix)).unwrap();
    // No controller publishing yet: a timeout that says so.
    let seq = client.set_goal(0, &[0.55, 0.25, 0.30], 0.5).unwrap();
    let e = client
        .wait_until_accepted(seq, Duration::from_millis(50))
        .unwrap_err();
    assert!(e.to_string().contains("no controller answered"), "{e}");

    // The stand-in answers one cycle.
    let mut cycle = |d: &mut ControlCycle, k: u64| {
        while let Ok(Some(sp)) = setpoints.receive() {
            d.take_setpoint_now(&sp);
        }
        state.header.seq = k;
        d.decide(&state, k * 1_000_000);
        telemetry.send_copy(*d.telemetry()).unwrap();
    };
    cycle(&mut d, 1);
    let a = client
        .wait_until_accepted(seq, Duration::from_secs(1))
        .unwrap();
    assert!((a.duration_s - 0.5).abs() < 1e-12);

    // A rejection carries its reason.
    let seq = client.set_goal(0, &[3.0, 0.0, 0.3], 0.5).unwrap();
    cycle(&mut d, 2);
    match client.wait_until_accepted(seq, Duration::from_secs(1)) {
        Err(ClientError::Rejected(r)) => assert_eq!(r, SetpointRejection::OutsideWorkspace),
        other => panic!("{other:?}"),
    }
    // Invalid before sending: nothing is sent.
    let e = client
        .set_gains(0, 3, &[1.0, -1.0, 1.0], &[], 0.0)
        .unwrap_err();
    assert!(
        matches!(
            e,
            ClientError::Invalid(SetpointRejection::NotPositiveDefinite)
        ),
        "{e}"
    );

    // Convergence of the equilibrium's transition (the state stays at q0, so
    // level 3's error is zero once its transition, none here, is over).
    let e = client
        .wait_until_converged(2, 1e-9, Duration::from_secs(1))
        .unwrap();
    assert!(e <= 1e-9);
    drop(client);
    drop(services);
    drop(node);
    for f in ipc::leftover_files(&prefix)
        .unwrap()
        .iter()
        .filter(|f| f.global_mgmt)
    {
        let _ = std::fs::remove_file(&f.path);
    }
}
