//! Contact reactions (`[contact] reaction`, hcc-cycle's module `reaction`)
//! against the plant's physics: a push of 15 N at the Panda's TCP for 0.5 s
//! (`[[simulation.wrench]]`) with `soften` and with `hold`. The reaction acts
//! as configured, the largest torque step per cycle is printed beside the
//! `report` run's and bounded, and the energy balance shows the reaction adds
//! no energy beyond what its spring change can (module docs of `reaction`).
//! With no contact, `soften` and `hold` command the paper's torques bit for bit.

use std::path::PathBuf;

use hcc_config::Scenario;
use hcc_in_process::CycleView;
use nalgebra::{DMatrix, DVector, Vector6};

const PUSH_START: f64 = 1.5;
const PUSH_S: f64 = 0.5;
/// Franka's `controller_torque_discontinuity`: 1 N·m per 1 ms cycle.
const STEP_BOUND: f64 = 1.0;

fn load(name: &str, extra: &str) -> Scenario {
    let path = PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("../../config")
        .join(name);
    let text = std::fs::read_to_string(&path).unwrap() + extra;
    Scenario::from_toml_str(&text, &path).unwrap()
}

/// The Panda pushed at its TCP with `contact` appended to `[contact]`, the
/// torque filter off (the steps measured are the cycle's own), `duration_s`.
fn pushed(contact: &str, extra: &str, duration_s: f64) -> Scenario {
    let text = format!(
        "\n[[simulation.wrench]]\nstart_s = {PUSH_START}\nduration_s = {PUSH_S}\n\
         link = \"panda_hand_tcp\"\nforce = [0.0, 15.0, 0.0]\n\n[contact]\n{contact}\n{extra}"
    );
    let mut s = load("panda-pose-posture.toml", &text);
    s.torque_filter.torque_rate_limit = None;
    s.torque_filter.low_pass_hz = None;
    s.set_duration(duration_s).unwrap();
    s
}

/// One cycle as the tests see it.
struct Sample {
    t: f64,
    q: Vec<f64>,
    qd: Vec<f64>,
    tau: Vec<f64>,
    gravity: Vec<f64>,
    contact: bool,
    holding: bool,
    /// h (how far the reaction acts) and κ (the law's stiffness factor).
    h: f64,
    kappa: f64,
    /// Kinetic energy ½ q̇ᵀ M q̇ and Σ V_i as the law applies them (κ-scaled).
    kinetic: f64,
    potential: f64,
    /// Power of the push, (Jᵀ F)ᵀ q̇ (0 outside it).
    push_power: f64,
    /// TCP position and orientation (roll, pitch, yaw).
    tcp: [f64; 3],
    rpy: [f64; 3],
}

fn run(scenario: &Scenario) -> Vec<Sample> {
    let model = &scenario.model;
    let mut data = hcc_model::Data::new(model);
    let frame = model.frame_id("panda_hand_tcp").unwrap();
    let mut jac = DMatrix::zeros(6, model.nq());
    let force = Vector6::new(0.0, 15.0, 0.0, 0.0, 0.0, 0.0);
    let mut out = Vec::new();
    hcc_in_process::run_observed(scenario, &mut |v: &CycleView<'_>| {
        let q = DVector::from_column_slice(v.state.q());
        let qd = DVector::from_column_slice(v.state.qd());
        let law = v.cycle.controller();
        let m = &law.model_terms().m;
        hcc_model::forward_kinematics(model, &mut data, &q);
        hcc_model::frame_jacobian(model, &data, frame, &mut jac);
        let pushing = v.t >= PUSH_START - 1e-9 && v.t < PUSH_START + PUSH_S - 1e-9;
        let push_power = if pushing {
            (jac.transpose() * force).dot(&qd)
        } else {
            0.0
        };
        let pose = hcc_model::frame_placement(model, &data, frame);
        let (tcp, rpy) = (pose.translation, pose.rotation.euler_angles());
        let (h, kappa) = v.cycle.reaction_level();
        out.push(Sample {
            t: v.t,
            q: q.iter().copied().collect(),
            qd: qd.iter().copied().collect(),
            tau: v.cycle.command().tau().to_vec(),
            gravity: law.output().gravity.iter().copied().collect(),
            contact: v.cycle.in_contact(),
            // As clients see it: the telemetry's flag, the cycle's own state.
            holding: {
                let flagged =
                    v.cycle.telemetry().flags & hcc_msgs::TELEMETRY_FLAG_CONTACT_HOLD != 0;
                assert_eq!(flagged, v.cycle.holding(), "t = {}", v.t);
                flagged
            },
            h,
            kappa,
            kinetic: 0.5 * qd.dot(&(m * &qd)),
            potential: law.output().potential.iter().sum(),
            push_power,
            tcp: [tcp.x, tcp.y, tcp.z],
            rpy: [rpy.0, rpy.1, rpy.2],
        });
        Ok(())
    })
    .unwrap();
    out
}

/// The largest |τ_k − τ_{k−1}| over the cycles from `from` s on.
fn largest_step(samples: &[Sample], from: f64) -> f64 {
    samples
        .windows(2)
        .filter(|w| w[0].t >= from)
        .flat_map(|w| w[0].tau.iter().zip(&w[1].tau).map(|(a, b)| (a - b).abs()))
        .fold(0.0, f64::max)
}

/// The energy balance from `from` s on (module docs of `reaction`): with
/// E = T_kin + c Σ V̄ (V̄ the unscaled potentials, c the storage factor of
/// each sample), D_k = E_k − E_0 − W_push − W_c, W_c = Σ Δc Σ V̄ the work of the
/// spring change. Passive: D never rises. Returns the largest rise of D
/// over any interval and the largest |W_c| (the scale it is measured against).
fn energy_rise(samples: &[Sample], from: f64, c: impl Fn(&Sample) -> f64) -> (f64, f64) {
    let samples: Vec<&Sample> = samples.iter().filter(|s| s.t >= from).collect();
    let period = samples[1].t - samples[0].t;
    // Σ V̄ from what the law applied (κ V̄ under soften, V̄ otherwise).
    let bare = |s: &Sample| s.potential / s.kappa;
    let energy = |s: &Sample| s.kinetic + c(s) * bare(s);
    let (e0, mut w_push, mut w_c) = (energy(samples[0]), 0.0, 0.0);
    let (mut lowest, mut rise, mut w_c_max) = (0.0_f64, 0.0_f64, 0.0_f64);
    for w in samples.windows(2) {
        // Trapezoidal work of the push and of the spring change.
        w_push += 0.5 * (w[0].push_power + w[1].push_power) * period;
        w_c += (c(w[1]) - c(w[0])) * 0.5 * (bare(w[0]) + bare(w[1]));
        w_c_max = w_c_max.max(w_c.abs());
        let d = energy(w[1]) - e0 - w_push - w_c;
        lowest = lowest.min(d);
        rise = rise.max(d - lowest);
    }
    (rise, w_c_max)
}

#[test]
fn soften_ramps_the_stiffness_down_in_contact_and_back() {
    let report = run(&pushed("", "", 3.0));
    let fraction = 0.2;
    let ramp = 0.1;
    let soft = run(&pushed(
        &format!("reaction = \"soften\"\nsoften_fraction = {fraction}\nramp_s = {ramp}"),
        "",
        3.0,
    ));
    let onset = soft.iter().find(|s| s.contact).expect("flagged").t;
    let clear = soft
        .iter()
        .find(|s| s.t > onset && !s.contact)
        .expect("cleared")
        .t;
    // Before the push: the law's torque, bit for bit.
    for (a, b) in report.iter().zip(&soft).filter(|(a, _)| a.t <= onset) {
        assert_eq!(a.tau, b.tau, "t = {}", a.t);
    }
    // κ = fraction from one ramp after the onset to the clear; 1 again one
    // ramp after the clear.
    for s in &soft {
        if s.t >= onset + ramp + 2e-3 && s.t < clear {
            assert!(
                (s.kappa - fraction).abs() < 1e-12,
                "t = {}: {}",
                s.t,
                s.kappa
            );
        }
        if s.t >= clear + ramp + 2e-3 {
            assert_eq!(s.kappa, 1.0, "t = {}", s.t);
        }
        assert!(s.kappa >= fraction - 1e-12 && s.kappa <= 1.0);
    }
    // The softened arm yields further under the same push.
    let deflection = |run: &[Sample]| {
        let rest = run.iter().find(|s| s.t >= PUSH_START - 1e-9).unwrap().tcp[1];
        run.iter()
            .filter(|s| s.t < PUSH_START + PUSH_S)
            .map(|s| s.tcp[1] - rest)
            .fold(0.0, f64::max)
    };
    let (d_report, d_soft) = (deflection(&report), deflection(&soft));
    let (step_report, step_soft) = (largest_step(&report, 1.0), largest_step(&soft, 1.0));
    let (rise_report, _) = energy_rise(&report, 1.0, |_| 1.0);
    let (rise_soft, w_kappa) = energy_rise(&soft, 1.0, |s| s.kappa);
    println!(
        "soften (κ → {fraction} over {ramp} s): flagged at {onset:.3} s, cleared at {clear:.3} s; \
         push deflection of the TCP {:.1} mm (report {:.1} mm); largest torque step per cycle \
         {step_soft:.4} N·m (report {step_report:.4} N·m); energy: largest rise of \
         E − W_push − W_κ {rise_soft:.2e} J (report {rise_report:.2e} J), |W_κ| up to {w_kappa:.3} J",
        1e3 * d_soft,
        1e3 * d_report
    );
    assert!(d_soft > 2.0 * d_report, "{d_soft} vs {d_report}");
    assert!(step_soft <= STEP_BOUND, "{step_soft}");
    // Passive up to the discretisation, which the report run shows.
    assert!(
        rise_soft <= 2.0 * rise_report + 1e-3 * w_kappa,
        "{rise_soft} vs {rise_report}"
    );
}

/// `[[setpoint]]`s at `t` for the three levels of the Panda scenario: the
/// goals of the pose of `at` (a client's "continue from here").
fn goals_of(at: &Sample, t: f64) -> String {
    let list = |v: &[f64]| {
        let v: Vec<String> = v.iter().map(|x| format!("{x:?}")).collect();
        v.join(", ")
    };
    format!(
        "\n[[setpoint]]\nt = {t}\nlevel = 1\ngoal = [{}]\n\
         \n[[setpoint]]\nt = {t}\nlevel = 2\ngoal = [{}]\n\
         \n[[setpoint]]\nt = {t}\nlevel = 3\ngoal = [{}]\n",
        list(&at.tcp),
        list(&at.rpy),
        list(&at.q)
    )
}

#[test]
fn hold_takes_gravity_and_damping_until_a_setpoint_releases_it() {
    let ramp = 0.1;
    let release_t = 3.0;
    let hold = format!("reaction = \"hold\"\nramp_s = {ramp}\nhold_damping = 2.0");
    // Where the hold leaves the arm: the client releases it with those goals.
    let unreleased = run(&pushed(&hold, "", release_t));
    let setpoints = goals_of(unreleased.last().unwrap(), release_t);
    let with_goals = |contact: &str, setpoints: &str| {
        let mut s = pushed(contact, setpoints, 3.5);
        for level in &mut s.setpoint_limits.levels {
            level.max_speed = f64::INFINITY;
        }
        run(&s)
    };
    let report = run(&pushed("", "", 3.5));
    let held = with_goals(&hold, &setpoints);
    // Released with the old goals still in force: the springs' energy where
    // the push left the arm comes back over the ramp (printed only).
    let old_goals = run(&pushed(
        &hold,
        &format!(
            "\n[[setpoint]]\nt = {release_t}\nlevel = 3\ngoal = [0.0, -0.3, 0.0, -2.2, 0.0, 2.0, 0.8]\n"
        ),
        3.5,
    ));
    let onset = held.iter().find(|s| s.contact).expect("flagged").t;
    let released = held
        .iter()
        .find(|s| s.t > onset && !s.holding)
        .expect("released")
        .t;
    assert!(
        (released - release_t).abs() < 1.5e-3,
        "released at {released} s, not by the setpoint at {release_t} s"
    );
    let mut worst = 0.0_f64;
    for s in &held {
        if s.t < onset {
            assert_eq!(s.h, 0.0);
        }
        // Held from the onset on, through the end of the push, until the setpoint.
        if s.t > onset + 1.5e-3 && s.t < released {
            assert!(s.holding, "t = {}", s.t);
        }
        if s.t >= onset + ramp + 2e-3 && s.t < released {
            assert_eq!(s.h, 1.0, "t = {}", s.t);
            for (j, t) in s.tau.iter().enumerate() {
                worst = worst.max((t - (s.gravity[j] - 2.0 * s.qd[j])).abs());
            }
        }
        if s.t >= released + ramp + 2e-3 {
            assert_eq!(s.h, 0.0, "t = {}", s.t);
        }
    }
    assert!(
        worst < 1e-9,
        "the held torque differs from g − D q̇ by {worst}"
    );
    // Held after the push: only the damper acts, the kinetic energy only falls.
    let coasting: Vec<&Sample> = held
        .iter()
        .filter(|s| s.t >= PUSH_START + PUSH_S + 1e-3 && s.t < released)
        .collect();
    let kinetic_rise = coasting
        .windows(2)
        .map(|w| w[1].kinetic - w[0].kinetic)
        .fold(f64::NEG_INFINITY, f64::max);
    let (k_start, k_end) = (coasting[0].kinetic, coasting[coasting.len() - 1].kinetic);
    let (step_report, step_held) = (largest_step(&report, 1.0), largest_step(&held, 1.0));
    let (rise_report, _) = energy_rise(&report, 1.0, |_| 1.0);
    let (rise_held, w_h) = energy_rise(&held, 1.0, |s| 1.0 - s.h);
    let step_old = largest_step(&old_goals, 1.0);
    let (_, w_old) = energy_rise(&old_goals, 1.0, |s| 1.0 - s.h);
    println!(
        "hold (ramp {ramp} s, D_h = 2 N·m·s/rad): flagged at {onset:.3} s, released at \
         {released:.3} s by the setpoint; τ − (g − D_h q̇) while held ≤ {worst:.1e} N·m; \
         kinetic energy after the push {k_start:.3} J → {k_end:.3} J at the release (largest \
         rise per cycle {kinetic_rise:.1e} J); largest torque step per cycle \
         {step_held:.4} N·m (report {step_report:.4} N·m); energy: largest rise of \
         E − W_push − W_h {rise_held:.2e} J (report {rise_report:.2e} J), |W_h| up to {w_h:.3} J; \
         released with the old goals in force instead: largest step {step_old:.2} N·m, |W_h| up \
         to {w_old:.1} J"
    );
    assert!(kinetic_rise <= 1e-9 * k_start, "{kinetic_rise}");
    assert!(k_end < k_start, "{k_end} vs {k_start}");
    assert!(step_held <= STEP_BOUND, "{step_held}");
    assert!(
        rise_held <= 2.0 * rise_report + 1e-3 * w_h,
        "{rise_held} vs {rise_report}"
    );
}

/// Every command's torque as bits.
fn torques(scenario: &Scenario) -> Vec<Vec<u64>> {
    let mut out = Vec::new();
    hcc_in_process::run_observed(scenario, &mut |v| {
        let tau = v.cycle.command().tau();
        out.push(tau.iter().map(|t| t.to_bits()).collect());
        Ok(())
    })
    .unwrap();
    out
}

#[test]
fn without_contact_the_reactions_change_nothing() {
    for name in ["paper-sim1.toml", "paper-sim2.toml"] {
        let report = torques(&load(name, ""));
        for reaction in ["soften", "hold"] {
            let other = torques(&load(
                name,
                &format!("\n[contact]\nreaction = \"{reaction}\"\n"),
            ));
            assert!(report == other, "{name}: {reaction} changed a torque");
        }
        println!(
            "{name}: {} cycles bit-identical with report, soften and hold",
            report.len()
        );
    }
}
