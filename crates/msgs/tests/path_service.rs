//! The path service (`hcc/<ns>/path`): a client's [`PathKnots`] reach the
//! controller's subscriber whole. Own file prefix and namespace; the files
//! are removed after.

use hcc_msgs::ipc;
use hcc_msgs::{Namespace, PATH_NEW, PathKnots, ServiceNames};
use iceoryx2::prelude::SignalHandlingMode;

#[test]
fn knots_sent_by_a_client_arrive_at_the_controller() {
    let prefix = format!("hcctpath{}_", std::process::id());
    let names = ServiceNames::for_namespace(Namespace::unique("path_svc").unwrap());
    assert!(names.path().ends_with("/path") && names.all().contains(&names.path()));
    {
        let node = ipc::create_node("ctl", SignalHandlingMode::Disabled, Some(&prefix)).unwrap();
        let services = ipc::Services::open(&node, &names).unwrap();
        let sub = services.path_subscriber(ipc::SETPOINT_BUFFER).unwrap();
        let client =
            ipc::create_node("client", SignalHandlingMode::Disabled, Some(&prefix)).unwrap();
        let client_services = ipc::Services::open(&client, &names).unwrap();
        let publisher = client_services.path_publisher().unwrap();
        let mut sent = PathKnots::zeroed();
        sent.flags = PATH_NEW;
        sent.level = 2;
        sent.header.seq = 7;
        for k in 0..5 {
            sent.push(0.1 * k as f64, &[0.4, 0.01 * k as f64, 0.3])
                .unwrap();
        }
        publisher.send_copy(sent).unwrap();
        let got = sub.receive().unwrap().expect("the knots arrived");
        assert_eq!(*got, sent);
        assert_eq!(got.validate(), Ok(()));
    }
    let files = ipc::leftover_files(&prefix).unwrap();
    for f in files.iter().filter(|f| f.global_mgmt) {
        std::fs::remove_file(&f.path).unwrap();
    }
    let rest: Vec<_> = files.iter().filter(|f| !f.global_mgmt).collect();
    assert!(rest.is_empty(), "files left behind: {rest:?}");
}
