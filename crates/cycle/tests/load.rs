//! A load announced at run time (`ControlCycle::set_load`) as the plant's
//! hand takes it: the controller's model ramps to it, so the arm holds its
//! pose without calling the load a collision, and the torque grows within
//! the filter's rate.

mod common;
use common::state_of;

use std::path::PathBuf;

use hcc_config::Scenario;
use hcc_cycle::{ControlCycle, CycleSettings};
use hcc_msgs::JointState;
use hcc_plant::zoh::{LoopTiming, run_zoh};

/// Per cycle from the attach time: whether a contact was flagged, the TCP
/// position error, the torque sent.
struct Run {
    contact: Vec<bool>,
    err: Vec<f64>,
    tau: Vec<Vec<f64>>,
}

/// The shipped scenario `file` whose plant's hand takes `mass` kg at 0.1 m
/// along the tip's z at `start_s`, and a control cycle of it.
fn with_load(file: &str, start_s: f64, mass: f64) -> (Scenario, ControlCycle) {
    let path = PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("../../config")
        .join(file);
    let text = std::fs::read_to_string(&path).unwrap()
        + &format!(
            "\n[[simulation.load]]\nstart_s = {start_s}\nmass = {mass}\ncom = [0.0, 0.0, 0.1]\n"
        );
    let sc = Scenario::from_toml_str(&text, &path).unwrap();
    let c = hcc_cycle::controller_for(&sc).unwrap();
    let d = ControlCycle::new(c, &CycleSettings::from_scenario(&sc)).unwrap();
    (sc, d)
}

/// The Panda holding its pose; its hand takes 1 kg at 0.1 m along the tip's
/// z at 1 s; announced then over `ramp_s` when `announce` is given.
fn run(announce: Option<f64>) -> Run {
    let (sc, mut d) = with_load("panda-pose-posture.toml", 1.0, 1.0);
    let mut plant = hcc_plant::plant_for(&sc).unwrap();
    let attach = 1000;
    let timing = LoopTiming {
        control_period_s: sc.period_s(),
        substeps: 10,
        cycles: 3000,
    };
    let mut out = Run {
        contact: Vec::new(),
        err: Vec::new(),
        tau: Vec::new(),
    };
    run_zoh(&mut plant, timing, |k, _t, q, qd, tau| {
        if k == attach
            && let Some(ramp) = announce
        {
            d.set_load(&hcc_model::Load::point(1.0, [0.0, 0.0, 0.1]), ramp)
                .unwrap();
        }
        let s = state_of(q.as_slice(), qd.as_slice(), k as u64 + 1);
        d.decide(&s, (k as u64 + 1) * sc.period_ns());
        if k >= attach {
            let t = d.telemetry();
            let e = t.task_error(0);
            out.contact.push(t.contact());
            out.err
                .push((e[0] * e[0] + e[1] * e[1] + e[2] * e[2]).sqrt());
            out.tau.push(d.command().tau().to_vec());
        }
        tau.as_mut_slice().copy_from_slice(d.command().tau());
        Ok(())
    })
    .unwrap();
    out
}

#[test]
fn a_load_announced_as_it_is_taken_is_held_without_a_contact() {
    let unannounced = run(None);
    let announced = run(Some(0.1));
    let sag = unannounced.err[unannounced.err.len() - 1];
    let flagged = unannounced.contact.iter().position(|c| *c);
    let after_1s = announced.err[1000..].iter().fold(0.0_f64, |m, e| m.max(*e));
    let worst = announced.err.iter().fold(0.0_f64, |m, e| m.max(*e));
    let step = common::largest_torque_step(&announced.tau);
    println!(
        "unannounced: contact flagged {flagged:?} cycles after the load, the TCP sags {sag:.2e} m; \
         announced over 0.1 s: no contact {}, the TCP at most {worst:.2e} m off, {after_1s:.2e} m from \
         1 s after; largest torque step {step:.3} N·m",
        !announced.contact.iter().any(|c| *c)
    );
    assert!(flagged.is_some_and(|k| k <= 20));
    assert!(
        !announced.contact.iter().any(|c| *c),
        "a contact was flagged"
    );
    assert!(after_1s < 1e-3, "{after_1s:e} m");
    // The filter's rate: 1000 N·m/s, 1 N·m per cycle.
    assert!(step <= 1.0 + 1e-9, "{step} N·m");
}

#[test]
fn a_load_message_is_checked_answered_and_ramped_in() {
    use hcc_msgs::LoadSetpoint;
    let path =
        PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../config/panda-pose-posture.toml");
    // The shipped scenario: the Panda's payload limit of 3 kg.
    let sc = Scenario::load(&path).unwrap();
    let c = hcc_cycle::controller_for(&sc).unwrap();
    let mut d = ControlCycle::new(c, &CycleSettings::from_scenario(&sc)).unwrap();
    let answer = |d: &ControlCycle| {
        let a = d.telemetry().answer_for(7).copied().unwrap();
        (a.seq, a.code)
    };
    let mut heavy = LoadSetpoint::point(7, 1, 3.5, [0.0, 0.0, 0.1]);
    assert_eq!(d.take_load(&heavy), 302);
    assert_eq!(answer(&d), (1, 302));
    heavy.mass = -1.0;
    heavy.header.seq = 2;
    assert_eq!(d.take_load(&heavy), 301);
    let mut odd = LoadSetpoint::point(7, 3, 1.0, [0.0, 0.0, 0.1]);
    odd.inertia = [0.1, 0.0, 0.0, 0.1, 0.0, 0.3];
    assert_eq!(d.take_load(&odd), 303);
    odd.inertia = [0.0; 6];
    odd.ramp_s = -1.0;
    assert_eq!(d.take_load(&odd), 304);
    // A good one: taken over its ramp (0.05 s), then the model carries it.
    let mut good = LoadSetpoint::point(7, 5, 1.0, [0.0, 0.0, 0.1]);
    good.ramp_s = 0.05;
    assert_eq!(d.take_load(&good), 0);
    assert_eq!(answer(&d), (5, 0));
    let n = sc.model.nq();
    let mut s = JointState::zeroed();
    let q: Vec<f64> = sc.q0.iter().copied().collect();
    s.set_joints(&q, &vec![0.0; n], &vec![0.0; n]).unwrap();
    let mut masses = Vec::new();
    let mut progress = Vec::new();
    for k in 1..=60 {
        s.header.seq = k;
        d.decide(&s, k * sc.period_ns());
        masses.push(d.controller().model().load.mass);
        // The telemetry says what the model carries and how far the ramp is.
        let t = d.telemetry();
        assert_eq!(t.load_mass, masses[masses.len() - 1]);
        progress.push(t.load_progress);
    }
    assert!(progress[0] > 0.0 && progress[0] < 0.05, "{progress:?}");
    assert!(progress.windows(2).all(|w| w[1] >= w[0]));
    assert_eq!(progress[49..], [1.0; 11]);
    let com = d.telemetry().load_com;
    assert!(
        (com[2] - 0.1).abs() < 1e-15 && com[0] == 0.0 && com[1] == 0.0,
        "{com:?}"
    );
    assert!(masses[0] > 0.0 && masses[0] < 0.01, "{masses:?}");
    assert!(masses.windows(2).all(|w| w[1] >= w[0]));
    assert_eq!(masses[49..], [1.0; 11]);
}

/// With a driver that adds gravity with its own model (the FR3 scenario:
/// `gravity_compensation = false`; the simulated driver's model knows no
/// load, as a robot that was not told one), the hand takes 1 kg at 0.1 m
/// along the tip's z at 1 s and the controller is told over 0.1 s: the
/// controller adds the load's own gravity torque, so the flange is back
/// within a millimetre 1 s after, without a contact flag and within the
/// filter's rate. Without the announcement the load pulls the flange off by
/// K⁻¹ m g and the observer flags it.
#[test]
fn a_load_the_driver_does_not_know_is_compensated_by_the_controller() {
    let run = |announce: bool| {
        let (sc, mut d) = with_load("fr3-pose-posture.toml", 1.0, 1.0);
        assert!(!sc.spec.gravity_compensation);
        let mut driver = hcc_plant::SimDriver::new(&sc).unwrap();
        let (mut err, mut contact, mut tau) = (Vec::new(), Vec::new(), Vec::new());
        let mut gravity = Vec::new();
        for k in 0..3000_u64 {
            if announce && k == 1000 {
                d.set_load(&hcc_model::Load::point(1.0, [0.0, 0.0, 0.1]), 0.1)
                    .unwrap();
            }
            let mut s = JointState::zeroed();
            driver.write_state(&mut s, (k + 1) * sc.period_ns());
            d.decide(&s, (k + 1) * sc.period_ns());
            driver.advance(Some(d.command())).unwrap();
            if k >= 1000 {
                let t = d.telemetry();
                let e = t.task_error(0);
                err.push((e[0] * e[0] + e[1] * e[1] + e[2] * e[2]).sqrt());
                contact.push(t.contact());
                tau.push(d.command().tau().to_vec());
                gravity.push(t.tau_gravity[..7].to_vec());
            }
        }
        (err, contact, tau, gravity)
    };
    let (err, contact, tau, gravity) = run(true);
    let after_1s = err[1000..].iter().fold(0.0_f64, |m, e| m.max(*e));
    let step = common::largest_torque_step(&tau);
    let g_load = gravity[gravity.len() - 1]
        .iter()
        .fold(0.0_f64, |m, g| m.max(g.abs()));
    let (sagged, flagged, ..) = run(false);
    let sag = sagged[sagged.len() - 1];
    println!(
        "FR3, the driver adding gravity without the load: announced, the flange {after_1s:.2e} m \
         off from 1 s after, no contact {}, largest torque step {step:.3} N·m, the load's gravity \
         torque in the command up to {g_load:.3} N·m; unannounced, {sag:.2e} m off, contact {}",
        !contact.iter().any(|c| *c),
        flagged.iter().any(|c| *c)
    );
    assert!(after_1s < 1e-3, "{after_1s:e} m");
    assert!(!contact.iter().any(|c| *c), "a contact was flagged");
    // The FR3 scenario's filter: 500 N·m/s, 0.5 N·m per cycle.
    assert!(step <= 0.5 + 1e-9, "{step} N·m");
    assert!(
        g_load > 1.0,
        "the command carries the load's gravity: {g_load} N·m"
    );
    assert!(
        sag > 1e-3,
        "unannounced, the load pulls the flange off: {sag:e} m"
    );
    assert!(
        flagged.iter().any(|c| *c),
        "unannounced, the load is a contact"
    );
}

/// A load announced while the arm moves (the TCP 15 cm in 0.5 s, the hand
/// taking 2 kg as the controller is told over 0.2 s): the load's kinetic
/// energy the model gains is booked by the tanks (module `load_ramp`), the
/// ramp completes, and the arm reaches its goal without a contact flag.
#[test]
fn a_load_announced_in_motion_is_booked_and_ramps_in() {
    let (sc, mut d) = with_load("panda-pose-posture.toml", 0.7, 2.0);
    let mut plant = hcc_plant::plant_for(&sc).unwrap();
    let timing = LoopTiming {
        control_period_s: sc.period_s(),
        substeps: 10,
        cycles: 3000,
    };
    let (mut progress, mut contact, mut speed) = (Vec::new(), false, 0.0_f64);
    run_zoh(&mut plant, timing, |k, _t, q, qd, tau| {
        if k == 500 {
            let g = d.telemetry().goal(0).to_vec();
            let goal = [g[0], g[1] + 0.15, g[2]];
            let sp = hcc_msgs::Setpoint::for_level(9, 1, 0, 3)
                .with_goal(&goal)
                .unwrap()
                .with_duration(0.5);
            assert_eq!(d.take_setpoint_now(&sp), 0);
        }
        if k == 700 {
            d.set_load(&hcc_model::Load::point(2.0, [0.0, 0.0, 0.1]), 0.2)
                .unwrap();
        }
        let s = state_of(q.as_slice(), qd.as_slice(), k as u64 + 1);
        d.decide(&s, (k as u64 + 1) * sc.period_ns());
        if (700..900).contains(&k) {
            speed = speed.max(qd.amax());
        }
        let t = d.telemetry();
        progress.push(t.load_progress);
        contact |= t.contact();
        tau.as_mut_slice().copy_from_slice(d.command().tau());
        Ok(())
    })
    .unwrap();
    let held = d.counters().core.load_ramp_held;
    let done = progress[700..]
        .iter()
        .position(|p| *p >= 1.0)
        .unwrap_or(usize::MAX);
    let e = d.telemetry().task_error(0);
    let err = (e[0] * e[0] + e[1] * e[1] + e[2] * e[2]).sqrt();
    println!(
        "announced in motion (joints up to {speed:.2} rad/s while it ramps): ramp done {done} ms after, \
         held {held} cycles, no contact {}, TCP {err:.2e} m off at 3 s",
        !contact
    );
    assert!(speed > 0.1, "the arm moves while the load ramps: {speed}");
    assert!(
        progress[progress.len() - 1] == 1.0 && (199..=300).contains(&done),
        "{done}"
    );
    assert!(!contact);
    assert!(err < 1e-3, "{err:e} m");
}
