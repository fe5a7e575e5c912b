//! The tap (`hcc_msgs::ipc::Tap`): every sample of a namespace handed on in
//! the contract's order — the client's messages by their common sequence
//! numbers across the three queues, then states, commands, telemetry — with
//! the gaps and the restarts of each loop stream counted. Own file prefix
//! and namespace; the files are removed after.

use hcc_msgs::ipc::{self, Tap, TapStreams, Tapped};
use hcc_msgs::{
    JointState, LoadSetpoint, Namespace, PathKnots, ServiceNames, Setpoint, Telemetry,
    TorqueCommand,
};
use iceoryx2::prelude::SignalHandlingMode;

#[test]
fn a_tap_hands_every_sample_on_in_order_and_counts_gaps_and_restarts() {
    let prefix = format!("hcctap{}_", std::process::id());
    let names = ServiceNames::for_namespace(Namespace::unique("tap").unwrap());
    {
        let node = ipc::create_node("peers", SignalHandlingMode::Disabled, Some(&prefix)).unwrap();
        let services = ipc::Services::open(&node, &names).unwrap();
        let tool = ipc::create_node("tool", SignalHandlingMode::Disabled, Some(&prefix)).unwrap();
        let tool_services = ipc::Services::open(&tool, &names).unwrap();
        let mut tap = Tap::open(&tool_services, TapStreams::All).unwrap();
        let mut loop_only = Tap::open(&tool_services, TapStreams::Loop).unwrap();

        let states = services.joint_state_publisher().unwrap();
        let commands = services.torque_command_publisher().unwrap();
        let telemetry = services.telemetry_publisher().unwrap();
        let setpoints = services.setpoint_publisher().unwrap();
        let paths = services.path_publisher().unwrap();
        let loads = services.load_publisher().unwrap();
        // States 0, 1, 2, 5 (two lost), then 0, 1 (a restarted driver).
        for seq in [0, 1, 2, 5, 0, 1] {
            let mut s = JointState::zeroed();
            s.header.seq = seq;
            states.send_copy(s).unwrap();
        }
        for seq in [0, 1] {
            let mut c = TorqueCommand::zeroed();
            c.header.seq = seq;
            commands.send_copy(c).unwrap();
        }
        let mut t = Telemetry::zeroed();
        t.header.seq = 3;
        telemetry.send_copy(t).unwrap();
        // One client's messages, numbered together: load 1, setpoint 2, path 3,
        // setpoints 4 to 7.
        loads
            .send_copy(LoadSetpoint::point(9, 1, 0.5, [0.0; 3]))
            .unwrap();
        let mut sp = Setpoint::zeroed();
        sp.header.seq = 2;
        setpoints.send_copy(sp).unwrap();
        let mut p = PathKnots::zeroed();
        p.header.seq = 3;
        paths.send_copy(p).unwrap();
        // More than a subscriber may hold out of shared memory at once.
        for seq in 4..=7 {
            sp.header.seq = seq;
            setpoints.send_copy(sp).unwrap();
        }

        let mut order = Vec::new();
        let most = tap
            .drain(&mut |m| {
                order.push(match m {
                    Tapped::State(s) => format!("state {}", s.header.seq),
                    Tapped::Command(c) => format!("command {}", c.header.seq),
                    Tapped::Telemetry(t) => format!("telemetry {}", t.header.seq),
                    Tapped::Setpoint(s) => format!("setpoint {}", s.header.seq),
                    Tapped::Path(p) => format!("path {}", p.header.seq),
                    Tapped::Load(l) => format!("load {}", l.header.seq),
                })
            })
            .unwrap();
        assert_eq!(
            order,
            [
                "load 1",
                "setpoint 2",
                "path 3",
                "setpoint 4",
                "setpoint 5",
                "setpoint 6",
                "setpoint 7",
                "state 0",
                "state 1",
                "state 2",
                "state 5",
                "state 0",
                "state 1",
                "command 0",
                "command 1",
                "telemetry 3"
            ]
        );
        assert_eq!(most, 7);
        let counts = tap.counts();
        assert_eq!(
            (
                counts.joint_state.received,
                counts.joint_state.missed,
                counts.joint_state.restarts
            ),
            (6, 2, 1)
        );
        assert_eq!(counts.torque_command.received, 2);
        assert_eq!(counts.telemetry.received, 1);
        assert_eq!(counts.client_messages, 7);
        assert_eq!(counts.missed(), 2);
        // Nothing left; the loop-only tap saw the loop's streams alone.
        assert_eq!(tap.drain(&mut |_| panic!("empty")).unwrap(), 0);
        let mut seen = 0;
        loop_only
            .drain(&mut |m| {
                assert!(matches!(
                    m,
                    Tapped::State(_) | Tapped::Command(_) | Tapped::Telemetry(_)
                ));
                seen += 1;
            })
            .unwrap();
        assert_eq!(seen, 9);
        assert_eq!(loop_only.counts().client_messages, 0);
    }
    let files = ipc::leftover_files(&prefix).unwrap();
    for f in files.iter().filter(|f| f.global_mgmt) {
        std::fs::remove_file(&f.path).unwrap();
    }
    let rest: Vec<_> = files.iter().filter(|f| !f.global_mgmt).collect();
    assert!(rest.is_empty(), "files left behind: {rest:?}");
}
