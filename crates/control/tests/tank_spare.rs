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

#[test]
fn the_spare_is_drawn_down_to_the_valves_band_and_no_further() {
    let model = panda();
    let spec = panda_spec(&model);
    let mut c = Controller::new(&model, spec, &DVector::from_vec(Q0.to_vec())).expect("ctl");
    for _ in 0..50 {
        c.step(&Q0, &QD).expect("step");
    }
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
