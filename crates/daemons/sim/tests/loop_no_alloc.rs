//! The acceptance check of the simulator's loop: 10 000 periods of publish
//! state → wait for the answer → tick (take the command, integrate RK4,
//! publish the next state) of [`SimLoop`], against an in-test controller that
//! answers every state with the paper's control law, through real iceoryx2
//! shared memory (own namespace and file prefix), with `RtAllocator`
//! installed as this test binary's global allocator.
//!
//! After warm-up the real-time thread makes no call into the system
//! allocator, the pool occupancy is constant from period to period, and the
//! thread takes no page fault (memory locked, as the daemon does it, when
//! permitted).

mod common;

use std::path::PathBuf;

use hcc_config::Scenario;
use hcc_control::Controller;
use hcc_msgs::ipc::{self, Services};
use hcc_msgs::{
    COMMAND_FLAG_GRAVITY_INCLUDED, CommandMode, MAX_JOINTS, Namespace, ServiceNames, TorqueCommand,
    monotonic_now_ns,
};
use hcc_rt::WaitStrategy;
use hcc_rtalloc::{LoopAudit, RtAllocator};
use hcc_sim::SimDriver;
use hcc_sim::{LoopStatus, Ports, SimLoop};
use iceoryx2::prelude::SignalHandlingMode;

#[global_allocator]
static ALLOCATOR: RtAllocator = RtAllocator::new();

const WARM_UP: u64 = 2_000;
const PERIODS: u64 = 10_000;

#[test]
fn ten_thousand_periods_without_system_allocation_or_page_fault() {
    assert!(hcc_rtalloc::pool_active());
    let prefix = format!("hccts{}_", std::process::id());
    {
        let path =
            PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../../config/paper-sim1.toml");
        let scenario = Scenario::load(&path).unwrap();
        let n = scenario.model.nq();
        let names = ServiceNames::for_namespace(Namespace::unique("sim_noalloc").unwrap());
        let node =
            ipc::create_node("sim-loop-test", SignalHandlingMode::Disabled, Some(&prefix)).unwrap();
        let services = Services::open(&node, &names).unwrap();
        let ports = Ports::open(&services).unwrap();
        // The in-test controller.
        let states = services.joint_state_subscriber(2).unwrap();
        let commands = services.torque_command_publisher().unwrap();
        let command_ready = services.command_ready_notifier().unwrap();
        let mut controller =
            Controller::new(&scenario.model, scenario.spec.clone(), &scenario.q0).unwrap();
        let mut command = TorqueCommand::zeroed();
        command.set_n_joints(n).unwrap();
        command.flags = COMMAND_FLAG_GRAVITY_INCLUDED;
        command.mode = CommandMode::Normal.code();

        let status = LoopStatus::default();
        let mut driver = SimDriver::new(&scenario).unwrap();
        driver.set_duration(1e6).unwrap();
        let mut lp = SimLoop::new(driver, &ports, &status, WaitStrategy::Hybrid);

        let mut seq = 0u64;
        // The controller answers the newest state; then the loop's period.
        let mut one = |lp: &mut SimLoop| -> bool {
            let mut ok = false;
            while let Ok(Some(state)) = states.receive() {
                let q = &state.q()[..n];
                let qd = &state.qd()[..n];
                let mut tau = [0.0; MAX_JOINTS];
                match controller.step(q, qd) {
                    Ok(out) => tau[..n].copy_from_slice(out.tau.as_slice()),
                    Err(_) => return false,
                }
                seq += 1;
                command.header.seq = seq;
                command.header.stamp_ns = monotonic_now_ns();
                command.answer(&state);
                command.tau[..n].copy_from_slice(&tau[..n]);
                ok = commands.send_copy(command).is_ok() && command_ready.notify().is_ok();
            }
            lp.wait_for_answer(monotonic_now_ns() + 800_000);
            ok & lp.tick().unwrap_or(false)
        };

        let mut audit = LoopAudit::prepare(512 * 1024);
        lp.publish();
        let mut failures = 0u64;
        for _ in 0..WARM_UP {
            failures += u64::from(!one(&mut lp));
        }
        audit.start();
        for _ in 0..PERIODS {
            failures += u64::from(!one(&mut lp));
            audit.note();
        }
        let report = audit.finish();
        let counters = lp.driver().counters();

        println!(
            "{}; driver {counters:?}",
            report.line("simulator loop", PERIODS)
        );
        assert_eq!(failures, 0, "periods that did not round-trip");
        assert_eq!(counters.missed_commands, 0, "{counters:?}");
        assert_eq!(counters.applied_commands, WARM_UP + PERIODS, "{counters:?}");
        assert_eq!(lp.driver().k(), WARM_UP + PERIODS);
        report.check().unwrap();
        assert!(
            report.during.pool_allocs > 0,
            "iceoryx2 loans are served by the pool"
        );
        // The loop really closed: 12 s of the paper's simulation #1 converged.
        let e = controller.output().task_error[0].norm();
        assert!(e < 1e-6, "level-1 error {e:e} after {} s", lp.driver().t());
    }
    common::assert_no_leftover_files(&prefix);
}
