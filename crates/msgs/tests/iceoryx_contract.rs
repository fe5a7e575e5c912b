//! The contract types work through iceoryx2, and iceoryx2 refuses a peer whose
//! payload type carries a different version of its part of the contract. Uses process-local
//! services, so no shared-memory files are created.

use hcc_msgs::{JointState, MAX_JOINTS, Namespace, SequenceChecker, ServiceNames, TorqueCommand};
use iceoryx2::prelude::*;
use iceoryx2::service::builder::publish_subscribe::PublishSubscribeOpenError;

/// A peer built against an older schema: same layout, older type name.
#[derive(Debug, Clone, Copy, ZeroCopySend)]
#[type_name("hcc_msgs::JointState@driver0")]
#[repr(C)]
struct OldJointState {
    bytes: [u8; core::mem::size_of::<JointState>()],
    _align: [u64; 0],
}

#[test]
fn iceoryx_refuses_a_peer_with_another_schema() {
    let names = ServiceNames::for_namespace(Namespace::unique("msgs_schema").unwrap());
    let node = NodeBuilder::new().create::<local::Service>().unwrap();
    let name = ServiceName::new(names.joint_state()).unwrap();
    let _service = node
        .service_builder(&name)
        .publish_subscribe::<JointState>()
        .create()
        .unwrap();
    assert_eq!(
        core::mem::size_of::<OldJointState>(),
        core::mem::size_of::<JointState>()
    );
    let old = node
        .service_builder(&name)
        .publish_subscribe::<OldJointState>()
        .open();
    assert!(
        matches!(old, Err(PublishSubscribeOpenError::IncompatibleTypes)),
        "{old:?}"
    );
    // The same type opens fine.
    node.service_builder(&name)
        .publish_subscribe::<JointState>()
        .open()
        .unwrap();
}

#[test]
fn state_and_command_round_trip() {
    let names = ServiceNames::for_namespace(Namespace::unique("msgs_roundtrip").unwrap());
    let node = NodeBuilder::new().create::<local::Service>().unwrap();
    let state_service = node
        .service_builder(&ServiceName::new(names.joint_state()).unwrap())
        .publish_subscribe::<JointState>()
        .open_or_create()
        .unwrap();
    let command_service = node
        .service_builder(&ServiceName::new(names.torque_command()).unwrap())
        .publish_subscribe::<TorqueCommand>()
        .open_or_create()
        .unwrap();
    let state_pub = state_service.publisher_builder().create().unwrap();
    let state_sub = state_service.subscriber_builder().create().unwrap();
    let command_pub = command_service.publisher_builder().create().unwrap();
    let command_sub = command_service.subscriber_builder().create().unwrap();

    let n = 7;
    let mut checker = SequenceChecker::new();
    for k in 1..=5u64 {
        // Driver: write the state in place in shared memory.
        let mut sample = state_pub
            .loan_uninit()
            .unwrap()
            .write_payload(JointState::zeroed());
        let s = sample.payload_mut();
        s.header.seq = k;
        s.header.stamp_ns = hcc_msgs::monotonic_now_ns();
        let q = [k as f64 * 0.1; 7];
        s.set_joints(&q, &[0.0; 7], &[0.0; 7]).unwrap();
        sample.send().unwrap();

        // Controller: receive, validate, answer.
        let received = state_sub.receive().unwrap().unwrap();
        received.validate(n).unwrap();
        assert!(checker.observe(received.header.seq).is_accepted());
        let mut cmd = TorqueCommand::zeroed();
        cmd.header.seq = k;
        cmd.set_n_joints(n).unwrap();
        cmd.set_tau(received.q()).unwrap();
        cmd.answer(&received);
        command_pub.send_copy(cmd).unwrap();

        // Driver: the command answers the latest state.
        let c = command_sub.receive().unwrap().unwrap();
        c.validate(n).unwrap();
        assert_eq!(c.state_seq, k);
        assert_eq!(c.tau(), &q);
        assert!(c.tau[n..MAX_JOINTS].iter().all(|&x| x == 0.0));
    }
    assert_eq!(checker.accepted(), 5);
}
