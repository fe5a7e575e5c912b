//! What the energy tanks hold to spare for the stages after the law
//! (`Controller::tank_spare`, `Controller::draw_tank_spare`): the fade's tank
//! and each level's tank above the band its valve opens over — drawn without
//! closing any level's valve.

mod common;
use common::*;
use hcc_control::Controller;
use hcc_control::energy_tank::{TANK_BAND, TANK_FLOOR};
use nalgebra::DVector;

const Q0: [f64; 7] = [0.1, -0.2, 0.05, -2.0, 0.1, 1.9, 0.7];
const QD: [f64; 7] = [0.1, -0.2, 0.15, 0.1, -0.3, 0.2, 0.25];

/// The Panda's controller after 50 cycles in motion (its tanks filled).
fn panda_after_50_cycles() -> Controller {
    let model = panda();
    let spec = panda_spec(&model);
    let mut c = Controller::new(&model, spec, &DVector::from_vec(Q0.to_vec())).expect("ctl");
    for _ in 0..50 {
        c.step(&Q0, &QD).expect("step");
    }
    c
}

#[test]
fn the_spare_is_drawn_down_to_the_valves_band_and_no_further() {
    let mut c = panda_after_50_cycles();
    let spare = c.tank_spare();
    assert!(
        spare > 1.0,
        "the tanks start with tank_initial and more: {spare}"
    );
    // A part of it, then more than there is: what is there.
    assert!((c.draw_tank_spare(0.1) - 0.1).abs() < 1e-15);
    assert!((c.tank_spare() - (spare - 0.1)).abs() < 1e-9);
    let rest = c.draw_tank_spare(1e6);
    assert!((rest - (spare - 0.1)).abs() < 1e-9, "{rest} of {spare}");
    assert_eq!(c.tank_spare(), 0.0);
    assert_eq!(c.draw_tank_spare(1.0), 0.0);
    assert_eq!(c.draw_tank_spare(f64::NAN), 0.0);
    // The next cycle's sample: every level's tank at the top of its valve's
    // band, so every valve still open.
    let out = c.step(&Q0, &QD).expect("step");
    for i in 1..3 {
        assert!(
            (out.tank[i] - (TANK_FLOOR + TANK_BAND)).abs() < 1e-12,
            "{:?}",
            out.tank
        );
        assert_eq!(out.tank_valve[i], 1.0, "{:?}", out.tank_valve);
    }
}

#[test]
fn without_the_tanks_there_is_no_spare() {
    let model = panda();
    let mut spec = panda_spec(&model);
    spec.safety.energy_tanks = false;
    let mut c = Controller::new(&model, spec, &DVector::from_vec(Q0.to_vec())).expect("ctl");
    c.step(&Q0, &QD).expect("step");
    assert_eq!(c.tank_spare(), 0.0);
    assert_eq!(c.draw_tank_spare(1.0), 0.0);
}

/// A change of the storage the model itself makes (a load ramping in):
/// a rise paid from the spare, a fall into the fade's tank, a rise the
/// spare cannot pay refused with nothing taken.
#[test]
fn a_model_change_is_booked_or_refused_whole() {
    let mut c = panda_after_50_cycles();
    let spare = c.tank_spare();
    assert!(c.book_model_change(0.25));
    assert!((c.tank_spare() - (spare - 0.25)).abs() < 1e-9);
    assert!(c.book_model_change(-0.1), "a fall is always booked");
    assert!((c.tank_spare() - (spare - 0.15)).abs() < 1e-9);
    let left = c.tank_spare();
    assert!(!c.book_model_change(left + 1.0), "more than the spare");
    assert!((c.tank_spare() - left).abs() < 1e-9, "nothing taken");
    assert!(c.book_model_change(0.0) && c.book_model_change(f64::NAN));
}

/// The kinetic energy of a load at the tip's twist is what it adds to the
/// arm's: ½ q̇ᵀ (M_loaded − M_bare) q̇, for a load with its own inertia off
/// the tip's axis.
#[test]
fn a_load_s_kinetic_energy_is_what_it_adds_to_the_arm_s() {
    use hcc_model::{Data, Load, crba, set_load};
    use nalgebra::{Matrix3, Vector3};
    let bare = panda();
    let load = Load {
        mass: 1.5,
        com: Vector3::new(0.04, -0.03, 0.12),
        inertia: Matrix3::from_diagonal(&Vector3::new(2e-3, 3e-3, 4e-3)),
    };
    let mut loaded = bare.clone();
    set_load(&mut loaded, &load);
    let mut c =
        Controller::new(&bare, panda_spec(&bare), &DVector::from_vec(Q0.to_vec())).expect("ctl");
    c.step(&Q0, &QD).expect("step");
    let t = c.load_kinetic_energy(&load, &Q0, &QD);
    let qd = DVector::from_vec(QD.to_vec());
    // ½ q̇ᵀ (M_loaded − M_bare) q̇ at q.
    let added = |q: &[f64]| {
        let q = DVector::from_column_slice(q);
        let m = |model: &hcc_model::Model| {
            let mut d = Data::new(model);
            crba(model, &mut d, &q);
            d.m.clone()
        };
        0.5 * qd.dot(&((m(&loaded) - m(&bare)) * &qd))
    };
    let want = added(&Q0);
    println!("a load's kinetic energy {t:.6e} J, ½ q̇ᵀ ΔM q̇ {want:.6e} J");
    assert!(
        (t - want).abs() < 1e-12 * want.abs().max(1e-3),
        "{t} vs {want}"
    );
    assert_eq!(c.load_kinetic_energy(&Load::none(), &Q0, &QD), 0.0);
    // Taken at the state it is asked for, not at the last cycle's: the
    // next cycle's storage counts the load at its own state.
    let q1: Vec<f64> = Q0
        .iter()
        .enumerate()
        .map(|(k, x)| x + 0.05 * (k as f64 + 1.0))
        .collect();
    let t1 = c.load_kinetic_energy(&load, &q1, &QD);
    let want1 = added(&q1);
    assert!(
        (t1 - want1).abs() < 1e-12 * want1.abs().max(1e-3),
        "{t1} vs {want1} (at the last cycle's state: {t})"
    );
    assert!(
        (want1 - want).abs() > 1e-6,
        "the states differ in T: {want1} {want}"
    );
}
