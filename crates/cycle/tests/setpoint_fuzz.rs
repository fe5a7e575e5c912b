//! 10 000 random setpoints at 1 kHz (random levels, sizes, NaNs, huge
//! values, non-SPD and asymmetric matrices, random durations), one per cycle,
//! against the Panda in closed loop with the plant: no panic, every torque
//! finite and within the torque limits, every setpoint answered with its own
//! sequence number.

use std::path::PathBuf;

use hcc_config::Scenario;
use hcc_control::Controller;
use hcc_cycle::{ControlCycle, CycleSettings};
use hcc_msgs::{
    GAIN_DAMPING_FULL, GAIN_STIFFNESS_FULL, JointState, MAX_TASK_DIM, SETPOINT_FIELDS_KNOWN,
    Setpoint,
};
use hcc_plant::zoh::{LoopTiming, run_zoh};
use rand::rngs::StdRng;
use rand::{RngExt, SeedableRng};

fn value(rng: &mut StdRng, base: f64) -> f64 {
    match rng.random_range(0..20) {
        0 => f64::NAN,
        1 => f64::INFINITY,
        2 => 1e300,
        3 => -1e6,
        4 => 0.0,
        _ => base * rng.random_range(0.5..1.5) + rng.random_range(-0.1..0.1),
    }
}

fn random_setpoint(rng: &mut StdRng, seq: u64) -> Setpoint {
    let dims = [3, 3, 7];
    let level = rng.random_range(0..4usize);
    let dim = if rng.random_range(0..10) == 0 {
        rng.random_range(0..=MAX_TASK_DIM + 2)
    } else {
        dims[level.min(2)]
    };
    let mut sp = Setpoint::for_level(77, seq, level, dim);
    sp.fields = rng.random_range(0..=SETPOINT_FIELDS_KNOWN + 1);
    sp.gain_layout = rng.random_range(0..4u32) & (GAIN_STIFFNESS_FULL | GAIN_DAMPING_FULL);
    sp.duration_s = value(rng, 0.05);
    let m = dim.min(MAX_TASK_DIM);
    let goal = [[0.55, 0.2, 0.3], [std::f64::consts::PI, 0.0, 0.0]];
    for (a, (g, v)) in sp
        .goal
        .iter_mut()
        .zip(sp.velocity.iter_mut())
        .take(m)
        .enumerate()
    {
        let base = if level < 2 && a < 3 {
            goal[level][a]
        } else {
            0.0
        };
        *g = value(rng, base);
        *v = value(rng, 0.01);
    }
    for a in 0..m * m {
        let diag = a % (m + 1) == 0;
        sp.stiffness[a] = value(rng, if diag { 300.0 } else { 5.0 });
        sp.damping[a] = value(rng, if diag { 20.0 } else { 1.0 });
    }
    if sp.gain_layout & GAIN_STIFFNESS_FULL == 0 {
        for a in 0..m {
            sp.stiffness[a] = value(rng, 300.0);
        }
    }
    sp
}

#[test]
fn ten_thousand_random_setpoints() {
    let path =
        PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../config/panda-pose-posture.toml");
    let sc = Scenario::load(&path).unwrap();
    let settings = CycleSettings::from_scenario(&sc);
    let limits = settings.torque_limits.clone();
    let c = Controller::new(&sc.model, sc.spec.clone(), &sc.q0).unwrap();
    let mut d = ControlCycle::new(c, &settings).unwrap();
    let mut plant = hcc_plant::plant_for(&sc).unwrap();
    let n = sc.model.nq();
    let mut rng = StdRng::seed_from_u64(10_000);
    let mut codes = [0u64; 17];
    let timing = LoopTiming {
        control_period_s: 1e-3,
        substeps: sc.simulation.substeps,
        cycles: 9_999,
    };
    run_zoh(&mut plant, timing, |k, _t, q, qd, tau| {
        let seq = k as u64 + 1;
        let sp = random_setpoint(&mut rng, seq);
        let code = d.take_setpoint_now(&sp);
        codes[(code as usize).min(16)] += 1;
        let mut s = JointState::zeroed();
        s.set_joints(q.as_slice(), qd.as_slice(), &vec![0.0; n])
            .unwrap();
        s.header.seq = seq;
        d.decide(&s, seq * 1_000_000);
        let answer = d.telemetry().answer_for(77).copied().expect("answered");
        assert_eq!(answer.seq, seq, "every setpoint answered");
        assert_eq!(answer.code, code);
        let out = d.command().tau();
        for (j, t) in out.iter().enumerate() {
            assert!(t.is_finite(), "cycle {k}: τ_{j} = {t}");
            assert!(
                t.abs() <= limits[j] + 1e-9,
                "cycle {k}: |τ_{j}| = {t} > {}",
                limits[j]
            );
        }
        tau.as_mut_slice().copy_from_slice(out);
        Ok(())
    })
    .unwrap();
    println!("answer codes (0 = accepted, then the rejection codes): {codes:?}");
    assert!(codes[0] > 0, "some were accepted: {codes:?}");
    assert_eq!(codes.iter().sum::<u64>(), 10_000);
    assert!(plant.q().iter().all(|x| x.is_finite()));
}
