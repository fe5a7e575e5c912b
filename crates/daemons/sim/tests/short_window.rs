//! A miss of a state that the simulator itself published late — less than
//! its command window before the tick, as after a stall of its core when the
//! ticks run back to back to catch up — is counted apart
//! (`short_window_misses`), so that `hcc jitter` does not charge the
//! simulator's own lateness to the controller. A miss of a state that had its
//! full window is not. Real iceoryx2 shared memory (own namespace and file
//! prefix), an in-test controller that answers only the first state.

mod common;

use std::path::PathBuf;
use std::time::Duration;

use hcc_config::Scenario;
use hcc_msgs::ipc::{self, Services};
use hcc_msgs::{
    COMMAND_FLAG_GRAVITY_INCLUDED, CommandMode, Namespace, ServiceNames, TorqueCommand,
    monotonic_now_ns,
};
use hcc_rt::WaitStrategy;
use hcc_sim::SimDriver;
use hcc_sim::{LoopStatus, Ports, SimLoop};
use iceoryx2::prelude::SignalHandlingMode;

#[test]
fn a_miss_after_a_late_tick_is_counted_apart_from_a_miss_with_the_full_window() {
    let prefix = format!("hccsw{}_", std::process::id());
    {
        let path =
            PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../../config/paper-sim1.toml");
        let scenario = Scenario::load(&path).unwrap();
        let n = scenario.model.nq();
        let names = ServiceNames::for_namespace(Namespace::unique("sim_short_window").unwrap());
        let node = ipc::create_node(
            "sim-window-test",
            SignalHandlingMode::Disabled,
            Some(&prefix),
        )
        .unwrap();
        let services = Services::open(&node, &names).unwrap();
        let ports = Ports::open(&services).unwrap();
        let states = services.joint_state_subscriber(2).unwrap();
        let commands = services.torque_command_publisher().unwrap();

        let status = LoopStatus::default();
        let mut driver = SimDriver::new(&scenario).unwrap();
        driver.set_duration(10.0).unwrap();
        let mut lp = SimLoop::new(driver, &ports, &status, WaitStrategy::Event).with_polling(true);

        // State 0, answered (g-free zero torque): commands flow from here on.
        lp.publish();
        let state = loop {
            if let Some(s) = states.receive().unwrap() {
                break *s;
            }
        };
        let mut command = TorqueCommand::zeroed();
        command.set_n_joints(n).unwrap();
        command.flags = COMMAND_FLAG_GRAVITY_INCLUDED;
        command.mode = CommandMode::Normal.code();
        command.header.seq = 1;
        command.header.stamp_ns = monotonic_now_ns();
        command.answer(&state);
        commands.send_copy(command).unwrap();
        lp.wait_for_answer(monotonic_now_ns() + 800_000);
        assert!(lp.tick().unwrap());
        assert_eq!(lp.driver().counters().applied_commands, 1);

        // The next states are not answered. A state whose tick comes at once
        // (a catch-up tick): the simulator's own lateness. Tick A publishes
        // the state, tick B right after it misses its answer; B's miss counts
        // as a short window whenever A and B took less than the window (a
        // loaded machine may preempt this thread between them: try again).
        let mut short_seen = false;
        for _ in 0..50 {
            let t0 = monotonic_now_ns();
            assert!(lp.tick().unwrap());
            let (missed, short) = (
                lp.driver().counters().missed_commands,
                lp.short_window_misses(),
            );
            assert!(lp.tick().unwrap());
            let quick = monotonic_now_ns() - t0 < 800_000;
            let c = lp.driver().counters();
            assert_eq!(c.missed_commands, missed + 1, "{c:?}");
            if quick {
                assert_eq!(lp.short_window_misses(), short + 1);
                short_seen = true;
                break;
            }
        }
        assert!(short_seen, "no two ticks within 800 µs in 50 tries");
        assert!(lp.short_window_misses() <= lp.driver().counters().missed_commands);

        // A state that had its full window (0.8 of the period) before its
        // tick and no answer: a miss charged to the controller.
        assert!(lp.tick().unwrap());
        let (missed, short) = (
            lp.driver().counters().missed_commands,
            lp.short_window_misses(),
        );
        std::thread::sleep(Duration::from_micros(900));
        assert!(lp.tick().unwrap());
        let c = lp.driver().counters();
        assert_eq!(c.missed_commands, missed + 1, "{c:?}");
        assert_eq!(lp.short_window_misses(), short);
    }
    common::assert_no_leftover_files(&prefix);
}
