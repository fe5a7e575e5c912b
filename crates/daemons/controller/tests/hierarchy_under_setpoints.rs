//! The strict hierarchy holds while a lower level's goal moves: a posture
//! goal change (level 3 of the Panda scenario) leaves the TCP (level 1)
//! where it is. Closed loop with the plant (RK4, zero-order hold at 1 kHz),
//! the same run with and without the change; the level-1 deviation between
//! them is printed and bounded. It is not zero only through the sampled
//! loop (the law's J_1 M⁻¹ τ_3 = 0 holds at the sampling instants, the held
//! torque acts on a moving state in between): the deviation shrinks in
//! proportion to the control period and does not depend on the plant's
//! integration step (`the_deviation_is_the_zero_order_hold`).

use std::path::PathBuf;

use hcc_config::Scenario;
use hcc_control::Controller;
use hcc_controller::{CycleSettings, Decider};
use hcc_msgs::{ANSWER_ACCEPTED, JointState, Setpoint};
use hcc_plant::zoh::{LoopTiming, run_zoh};

/// The TCP position error (level 1) per cycle, with or without a posture
/// change at 1 s, at 1 kHz with the scenario's integration step.
fn run(change: bool) -> Vec<[f64; 3]> {
    run_at(change, 1000.0, None)
}

/// [`run`] at `rate_hz` (4 s), the plant integrated with `substeps` RK4
/// steps per control period (default: the scenario's step).
fn run_at(change: bool, rate_hz: f64, substeps: Option<usize>) -> Vec<[f64; 3]> {
    let path =
        PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../../config/panda-pose-posture.toml");
    let sc = Scenario::load(&path).unwrap();
    let mut settings = CycleSettings::from_scenario(&sc);
    let period_ns = (1e9 / rate_hz).round() as u64;
    settings.period_ns = period_ns;
    settings.stale_timeout_ns = 3 * period_ns;
    let c = Controller::new(&sc.model, sc.spec.clone(), &sc.q0).unwrap();
    let mut d = Decider::new(c, &settings).unwrap();
    let mut plant = hcc_plant::closed_loop::plant_for(&sc).unwrap();
    let n = sc.model.nq();
    let mut posture: Vec<f64> = sc.q0.iter().copied().collect();
    posture[0] += 0.3;
    posture[2] -= 0.3;
    let mut out = Vec::new();
    let period = period_ns as f64 * 1e-9;
    let cycles = (4.0 / period).round() as usize;
    let timing = LoopTiming {
        control_period_s: period,
        substeps: substeps
            .unwrap_or_else(|| ((period / sc.simulation.integrator_dt_s).round() as usize).max(1)),
        cycles,
    };
    let change_at = cycles / 4;
    run_zoh(&mut plant, timing, |k, _t, q, qd, tau| {
        if change && k == change_at {
            let sp = Setpoint::for_level(5, 1, 2, n)
                .with_goal(&posture)
                .unwrap()
                .with_duration(1.0);
            assert_eq!(d.take_setpoint(&sp), ANSWER_ACCEPTED);
        }
        let mut s = JointState::zeroed();
        s.set_joints(q.as_slice(), qd.as_slice(), &vec![0.0; n])
            .unwrap();
        s.header.seq = k as u64 + 1;
        d.decide(&s, (k as u64 + 1) * period_ns);
        let e = d.telemetry().task_error(0);
        out.push([e[0], e[1], e[2]]);
        tau.as_mut_slice().copy_from_slice(d.command().tau());
        Ok(())
    })
    .unwrap();
    out
}

#[test]
fn a_posture_goal_change_leaves_the_tcp_where_it_is() {
    let plain = run(false);
    let changed = run(true);
    let deviation = plain.iter().zip(&changed).fold(0.0_f64, |m, (a, b)| {
        let d2: f64 = (0..3).map(|j| (a[j] - b[j]).powi(2)).sum();
        m.max(d2.sqrt())
    });
    println!(
        "largest level-1 (TCP) deviation caused by a 0.3 rad posture goal change over 1 s: {deviation:.3e} m"
    );
    assert_eq!(
        plain[..1000],
        changed[..1000],
        "identical before the change"
    );
    assert!(deviation < 1e-5, "{deviation:e}");
}

/// The largest level-1 deviation between the runs with and without the change.
fn deviation(rate_hz: f64, substeps: Option<usize>) -> f64 {
    let plain = run_at(false, rate_hz, substeps);
    let changed = run_at(true, rate_hz, substeps);
    plain.iter().zip(&changed).fold(0.0_f64, |m, (a, b)| {
        let d2: f64 = (0..3).map(|j| (a[j] - b[j]).powi(2)).sum();
        m.max(d2.sqrt())
    })
}

/// Where the deviation comes from: halving the control period halves it
/// (first order in T, the zero-order hold), while a 4× finer integration
/// step at the same period leaves it unchanged (not the plant's numerics).
/// Continuous-time, the hierarchy is exact (J_1 M⁻¹ τ_3 = 0 at every state).
#[test]
fn the_deviation_is_the_zero_order_hold() {
    // The same integration step (62.5 µs) at every rate.
    let step = 62.5e-6;
    let mut last: Option<(f64, f64)> = None;
    for rate in [500.0, 1000.0, 2000.0, 4000.0] {
        let substeps = (1.0 / (rate * step)).round() as usize;
        let d = deviation(rate, Some(substeps));
        println!(
            "control rate {rate} Hz (T = {:.3} ms, {substeps} RK4 steps of 62.5 µs): level-1 deviation {d:.3e} m, {:.3e} m per ms of T",
            1e3 / rate,
            d * rate / 1e3
        );
        if let Some((r0, d0)) = last {
            let ratio = d0 / d;
            let expected = rate / r0;
            assert!(
                (ratio / expected - 1.0).abs() < 0.25,
                "{r0} Hz → {rate} Hz: the deviation shrank {ratio:.2}×, the period {expected}×"
            );
        }
        last = Some((rate, d));
    }
    // The integration step does not matter (1 kHz: 100 µs vs 25 µs).
    let coarse = deviation(1000.0, Some(10));
    let fine = deviation(1000.0, Some(40));
    println!("1 kHz: deviation {coarse:.3e} m with 100 µs RK4 steps, {fine:.3e} m with 25 µs");
    assert!(
        ((coarse - fine) / fine).abs() < 0.01,
        "{coarse:e} vs {fine:e}"
    );
}
