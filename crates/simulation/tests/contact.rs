//! Feeling contact without a sensor, against the physics of the plant: the
//! momentum observer's r (`hcc_control::contact`, run by the cycle core)
//! against a known push — 15 N at the Panda's TCP for 0.5 s through
//! `[[simulation.wrench]]`, and 5 N·m on one joint — and the contact flag's
//! timing; free motion of the shipped scenarios flags no contact with the
//! default thresholds (the largest |r| per joint printed); and the observer
//! only observes: the torques are bit for bit the same whatever it flags.
//! The wrench estimate F̂ = pinv(Jᵀ) r at the position level's frame against
//! the push at the TCP, in the cycle and in the trajectory's `f_ext_<k>`.

use std::path::PathBuf;

use hcc_config::Scenario;
use hcc_control::Controller;
use hcc_cycle::{ControlCycle, CycleSettings};
use hcc_msgs::JointState;
use hcc_plant::LoopTiming;
use nalgebra::{DMatrix, DVector, Vector6};

const PUSH_START: f64 = 1.5;
const PUSH_S: f64 = 0.5;

fn config(name: &str) -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("../../config")
        .join(name)
}

fn load(name: &str, extra: &str) -> Scenario {
    let path = config(name);
    let text = std::fs::read_to_string(&path).unwrap() + extra;
    Scenario::from_toml_str(&text, &path).unwrap()
}

/// One cycle as the test sees it: t, q, r, the contact flag, F̂.
struct Sample {
    t: f64,
    q: Vec<f64>,
    r: Vec<f64>,
    contact: bool,
    f: Vec<f64>,
}

fn run(scenario: &Scenario) -> Vec<Sample> {
    let mut out = Vec::new();
    hcc_simulation::run_observed(scenario, &mut |v| {
        out.push(sample(v));
        Ok(())
    })
    .unwrap();
    out
}

fn sample(v: &hcc_simulation::CycleView<'_>) -> Sample {
    Sample {
        t: v.t,
        q: v.state.q().to_vec(),
        r: v.cycle.telemetry().tau_ext().to_vec(),
        contact: v.cycle.telemetry().contact(),
        f: v.cycle.external_wrench().to_vec(),
    }
}

/// [`run`], with the trajectory `hcc simulate` writes.
fn simulate(scenario: &Scenario) -> (Vec<Sample>, hcc_report::Trajectory) {
    let mut out = Vec::new();
    let run = hcc_simulation::simulate_observed(scenario, &mut |v| {
        out.push(sample(v));
        Ok(())
    })
    .unwrap();
    (out, run.trajectory)
}

/// Timing of the flag against a push over [start, end): the delay to the
/// first flagged cycle, the delay from the end to the first clear cycle,
/// and whether it was flagged outside [start, clear).
fn flag_timing(samples: &[Sample], start: f64, end: f64) -> (f64, f64) {
    let eps = 1e-9;
    let on = samples
        .iter()
        .find(|s| s.contact)
        .expect("contact is flagged");
    assert!(
        on.t >= start - eps,
        "flagged before the push, at {} s",
        on.t
    );
    let off = samples
        .iter()
        .find(|s| s.t >= end - eps && !s.contact)
        .expect("contact is cleared");
    assert!(
        samples
            .iter()
            .all(|s| !s.contact || (s.t >= on.t && s.t < off.t)),
        "flagged again after the clear"
    );
    assert!(
        samples
            .iter()
            .filter(|s| s.t >= on.t && s.t < end)
            .all(|s| s.contact),
        "the flag dropped during the push"
    );
    (on.t - start, off.t - end)
}

/// |r − reference| over the cycles in [from, to) relative to the peak of
/// |reference| (over every cycle): the worst case.
fn relative_error(samples: &[Sample], reference: &[Vec<f64>], from: f64, to: f64) -> (f64, f64) {
    let peak = reference
        .iter()
        .flatten()
        .fold(0.0_f64, |m, x| m.max(x.abs()));
    let mut worst = 0.0_f64;
    for (s, r) in samples.iter().zip(reference) {
        if s.t >= from && s.t < to {
            for (a, b) in s.r.iter().zip(r) {
                worst = worst.max((a - b).abs());
            }
        }
    }
    (worst / peak, peak)
}

#[test]
fn a_push_at_the_tcp_is_estimated_and_flagged() {
    let extra = format!(
        "\n[[simulation.wrench]]\nstart_s = {PUSH_START}\nduration_s = {PUSH_S}\nlink = \"panda_hand_tcp\"\nforce = [0.0, 15.0, 0.0]\n"
    );
    let mut scenario = load("panda-pose-posture.toml", &extra);
    scenario.set_duration(2.5).unwrap();
    let (samples, trajectory) = simulate(&scenario);
    // The reference: Jᵀ F at each sampled state while the push acts.
    let model = &scenario.model;
    let mut data = hcc_model::Data::new(model);
    let frame = model.frame_id("panda_hand_tcp").unwrap();
    let n = model.nq();
    let mut jac = DMatrix::zeros(6, n);
    let wrench = Vector6::new(0.0, 15.0, 0.0, 0.0, 0.0, 0.0);
    let end = PUSH_START + PUSH_S;
    let reference: Vec<Vec<f64>> = samples
        .iter()
        .map(|s| {
            if s.t < PUSH_START || s.t >= end {
                return vec![0.0; n];
            }
            hcc_model::forward_kinematics(model, &mut data, &DVector::from_column_slice(&s.q));
            hcc_model::frame_jacobian(model, &data, frame, &mut jac);
            (jac.transpose() * wrench).iter().copied().collect()
        })
        .collect();
    let k_o = scenario.contact.observer_gain[0];
    let (err, peak) = relative_error(&samples, &reference, PUSH_START + 5.0 / k_o, end);
    let what = format!("15 N at the TCP (peak |Jᵀ F| {peak:.3} N·m)");
    check_push(&what, &samples, err, end);
    check_wrench(
        &samples,
        &trajectory,
        [0.0, 15.0, 0.0],
        PUSH_START + 5.0 / k_o,
        end,
    );
}

/// F̂ at the TCP (the scenario's first level: its position, 3 rows) within
/// 5 % of the force `applied` over [from, to), and the same figures in the
/// trajectory's `f_ext_<k>` columns; prints the worst error, and the largest
/// |F̂| in free motion before the push.
fn check_wrench(
    samples: &[Sample],
    trajectory: &hcc_report::Trajectory,
    applied: [f64; 3],
    from: f64,
    to: f64,
) {
    let norm = |v: &[f64]| v.iter().map(|x| x * x).sum::<f64>().sqrt();
    let columns: Vec<Vec<f64>> = (1..=3)
        .map(|k| trajectory.require(&format!("f_ext_{k}")).unwrap())
        .collect();
    assert!(
        trajectory.column("f_ext_4").is_none(),
        "one column per task row"
    );
    let (mut worst, mut free) = (0.0_f64, 0.0_f64);
    for (row, s) in samples.iter().enumerate() {
        assert_eq!(s.f.len(), 3);
        for (k, f) in s.f.iter().enumerate() {
            assert_eq!(
                columns[k][row].to_bits(),
                f.to_bits(),
                "row {row}, f_ext_{}",
                k + 1
            );
        }
        if s.t >= from && s.t < to {
            let e: Vec<f64> = s.f.iter().zip(applied).map(|(a, b)| a - b).collect();
            worst = worst.max(norm(&e) / norm(&applied));
        }
        if s.t < PUSH_START {
            free = free.max(norm(&s.f));
        }
    }
    println!(
        "F̂ at the TCP: worst |F̂ − F| / |F| after 5/K_O = {:.2} %; largest |F̂| before the push {free:.2e} N",
        100.0 * worst
    );
    assert!(worst < 0.05, "F̂ off by {:.2} % of |F|", 100.0 * worst);
}

/// Prints the figures of a push over [PUSH_START, end) and checks them: r
/// within 2 % of the peak after 5/K_O, flagged within 20 ms of the start,
/// cleared within 50 ms of the end.
fn check_push(what: &str, samples: &[Sample], err: f64, end: f64) {
    let (on, off) = flag_timing(samples, PUSH_START, end);
    println!(
        "{what}: worst |r − τ_ext| after 5/K_O = {:.2} % of the peak; \
         flagged {:.0} ms after the start, cleared {:.0} ms after the end",
        100.0 * err,
        on * 1e3,
        off * 1e3
    );
    assert!(err < 0.02, "{what}: {err}");
    assert!(on <= 0.020 + 1e-9, "{what}: {on}");
    assert!(off <= 0.050 + 1e-9, "{what}: {off}");
}

/// The closed loop of `scenario` with `torque` on `joint` added to the
/// torque the plant receives during the push (held over each period), the
/// cycle unaware of it.
fn run_with_joint_torque(scenario: &Scenario, joint: usize, torque: f64) -> Vec<Sample> {
    let controller = Controller::new(&scenario.model, scenario.spec.clone(), &scenario.q0).unwrap();
    let mut cycle = ControlCycle::new(controller, &CycleSettings::from_scenario(scenario)).unwrap();
    let s = &scenario.simulation;
    let mut plant = hcc_plant::plant_for(scenario).unwrap();
    let timing = LoopTiming {
        control_period_s: 1.0 / s.control_rate_hz,
        substeps: s.substeps,
        cycles: scenario.cycles() as usize,
    };
    let n = scenario.model.nq();
    let mut state = JointState::zeroed();
    let mut out = Vec::new();
    let period_ns = scenario.simulation.period_ns();
    hcc_plant::run_zoh(&mut plant, timing, |k, t, q, qd, tau| {
        state
            .set_joints(q.as_slice(), qd.as_slice(), &vec![0.0; n])
            .unwrap();
        state.header.seq = k as u64;
        state.header.stamp_ns = k as u64 * period_ns;
        cycle.step(&state, k as u64 * period_ns, || None);
        tau.as_mut_slice()
            .copy_from_slice(&cycle.command().tau[..n]);
        if (PUSH_START..PUSH_START + PUSH_S).contains(&t) {
            tau[joint] += torque;
        }
        out.push(Sample {
            t,
            q: q.iter().copied().collect(),
            r: cycle.external_torque().to_vec(),
            contact: cycle.in_contact(),
            f: cycle.external_wrench().to_vec(),
        });
        Ok(())
    })
    .unwrap();
    out
}

#[test]
fn a_torque_on_one_joint_is_estimated_and_flagged() {
    let mut scenario = load("panda-pose-posture.toml", "");
    scenario.set_duration(2.5).unwrap();
    let (joint, torque) = (3, 5.0);
    let samples = run_with_joint_torque(&scenario, joint, torque);
    // The torque held over [t_k, t_k+1) for t_k in the push: the observer
    // sees it from the state after, t_k+1.
    let period = 1.0 / scenario.simulation.control_rate_hz;
    let end = PUSH_START + PUSH_S;
    let reference: Vec<Vec<f64>> = samples
        .iter()
        .map(|s| {
            let mut r = vec![0.0; s.r.len()];
            if s.t > PUSH_START + 0.5 * period && s.t < end + 0.5 * period {
                r[joint] = torque;
            }
            r
        })
        .collect();
    let k_o = scenario.contact.observer_gain[0];
    let (err, _) = relative_error(&samples, &reference, PUSH_START + 5.0 / k_o, end);
    check_push(
        &format!("{torque} N·m on joint {}", joint + 1),
        &samples,
        err,
        end,
    );
}

#[test]
fn free_motion_of_the_shipped_scenarios_flags_no_contact() {
    for name in [
        "paper-sim1.toml",
        "paper-sim2.toml",
        "panda-pose-posture.toml",
    ] {
        let scenario = load(name, "");
        assert!(scenario.simulation.wrenches.is_empty(), "{name}");
        let samples = run(&scenario);
        let n = scenario.model.nq();
        let mut largest = vec![0.0_f64; n];
        for s in &samples {
            for (m, r) in largest.iter_mut().zip(&s.r) {
                *m = m.max(r.abs());
            }
        }
        let flagged = samples.iter().filter(|s| s.contact).count();
        let text: Vec<String> = largest.iter().map(|m| format!("{m:.2e}")).collect();
        println!(
            "{name}: largest |r| per joint [{}] N·m; threshold {} N·m; {flagged} cycles flagged",
            text.join(", "),
            scenario.contact.threshold[0]
        );
        assert_eq!(flagged, 0, "{name}");
        let threshold = scenario.contact.threshold.as_slice();
        assert!(largest.iter().zip(threshold).all(|(m, t)| m < t), "{name}");
    }
}

/// Every command's torque as bits, and the cycles flagged in contact.
fn torques(scenario: &Scenario) -> (Vec<Vec<u64>>, usize) {
    let (mut out, mut flagged) = (Vec::new(), 0);
    hcc_simulation::run_observed(scenario, &mut |v| {
        let tau = v.cycle.command().tau();
        out.push(tau.iter().map(|t| t.to_bits()).collect());
        flagged += usize::from(v.cycle.in_contact());
        Ok(())
    })
    .unwrap();
    (out, flagged)
}

#[test]
fn the_observer_only_observes() {
    for name in ["paper-sim1.toml", "paper-sim2.toml"] {
        let quiet = load(name, "");
        // Thresholds so low that the model's discretisation error is a contact.
        let alarmed = load(
            name,
            "\n[contact]\nthreshold = 1e-9\nobserver_gain = 500.0\n",
        );
        let ((a, none), (b, all)) = (torques(&quiet), torques(&alarmed));
        assert_eq!(none, 0, "{name}");
        assert!(all > 100, "{name}: {all} of {} flagged", a.len());
        assert_eq!(a.len(), b.len());
        if let Some(k) = (0..a.len()).find(|&k| a[k] != b[k]) {
            panic!("{name}: the observer changed the torque of cycle {k}");
        }
        println!(
            "{name}: {} cycles bit-identical, in contact in 0 and {all} of them",
            a.len()
        );
    }
}
