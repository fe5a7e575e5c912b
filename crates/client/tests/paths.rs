//! A path sent with the client (`Client::follow`) over real iceoryx2
//! services to the controller's decision step running in its own thread (a
//! stand-in for the daemon): accepted message by message; a knot out of the
//! level's workspace refused with the knot, its message's knots and the reason.

use std::path::PathBuf;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::Duration;

use hcc_client::{Client, ClientError};
use hcc_config::Scenario;
use hcc_cycle::{ControlCycle, CycleSettings};
use hcc_msgs::ipc::{self, Services};
use hcc_msgs::{JointState, Namespace, ServiceNames, SetpointRejection};
use iceoryx2::prelude::SignalHandlingMode;

#[test]
fn a_path_is_accepted_message_by_message_and_a_bad_knot_is_named() {
    let prefix = format!("hcccp{}_", std::process::id());
    let ns = Namespace::unique("client_path").unwrap();
    let stop = Arc::new(AtomicBool::new(false));
    let stand_in = {
        let (prefix, names, stop) = (
            prefix.clone(),
            ServiceNames::for_namespace(ns.clone()),
            stop.clone(),
        );
        std::thread::spawn(move || {
            let node =
                ipc::create_node("ctl-stand-in", SignalHandlingMode::Disabled, Some(&prefix))
                    .unwrap();
            let services = Services::open(&node, &names).unwrap();
            let paths = services.path_subscriber(16).unwrap();
            let telemetry = services.telemetry_publisher().unwrap();
            let path = PathBuf::from(env!("CARGO_MANIFEST_DIR"))
                .join("../../config/panda-pose-posture.toml");
            let sc = Scenario::load(&path).unwrap();
            let c = hcc_cycle::controller_for(&sc).unwrap();
            let mut d = ControlCycle::new(c, &CycleSettings::from_scenario(&sc)).unwrap();
            let n = sc.model.nq();
            let mut state = JointState::zeroed();
            state
                .set_joints(sc.q0.as_slice(), &vec![0.0; n], &vec![0.0; n])
                .unwrap();
            let mut k = 0;
            while !stop.load(Ordering::Relaxed) {
                k += 1;
                while let Ok(Some(knots)) = paths.receive() {
                    d.take_path(&knots);
                }
                state.header.seq = k;
                d.decide(&state, k * 1_000_000);
                telemetry.send_copy(*d.telemetry()).unwrap();
                std::thread::sleep(Duration::from_millis(1));
            }
        })
    };
    let mut client = Client::connect(ns.as_str(), Some(&prefix)).unwrap();
    // The stand-in listens once it publishes telemetry (a message sent
    // before its subscriber exists would be lost).
    let deadline = std::time::Instant::now() + Duration::from_secs(30);
    while client.poll_telemetry().is_none() {
        assert!(
            std::time::Instant::now() < deadline,
            "no stand-in telemetry"
        );
        std::thread::sleep(Duration::from_millis(5));
    }
    // 1 cm along y over 1 s from the level's goal, a knot every 20 ms: four
    // messages, each answered before the next goes.
    let times: Vec<f64> = (0..51).map(|k| k as f64 * 0.02).collect();
    let points: Vec<Vec<f64>> = times
        .iter()
        .map(|t| vec![0.55, 0.20 + 0.01 * t, 0.30])
        .collect();
    let timeout = Duration::from_secs(5);
    client
        .follow(0, &times, &points, 0, timeout)
        .expect("accepted");
    // A new path from where the first one is, its knot 20 out of reach.
    std::thread::sleep(Duration::from_millis(1200));
    let here = client.poll_telemetry().expect("telemetry").goal[0];
    let mut points: Vec<Vec<f64>> = times.iter().map(|_| here[..3].to_vec()).collect();
    points[20] = vec![3.0, 0.0, 0.3];
    let e = client.follow(0, &times, &points, 0, timeout).unwrap_err();
    println!("{e}");
    assert_eq!((e.first, e.last, e.knot), (16, 31, Some(20)), "{e}");
    assert_eq!(e.t_knot(&times), Some(times[20]));
    assert!(
        matches!(
            e.error,
            ClientError::Rejected(SetpointRejection::OutsideWorkspace)
        ),
        "{e}"
    );
    stop.store(true, Ordering::Relaxed);
    stand_in.join().unwrap();
    drop(client);
    let files = ipc::leftover_files(&prefix).unwrap();
    for f in files.iter().filter(|f| f.global_mgmt) {
        std::fs::remove_file(&f.path).unwrap();
    }
}
