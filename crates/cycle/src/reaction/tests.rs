//! `soften`'s κ and `hold`'s share through the law's energy tanks: a restore
//! or a release the tanks cannot pay waits (counted) and goes on once a
//! command refills them.

use super::ContactReaction;
use hcc_config::Scenario;
use hcc_control::Controller;
use hcc_spec::contact::{Contact, Reaction};
use std::path::PathBuf;

/// The shipped Panda's controller at rest at its start, its TCP goal 10 cm
/// off (a stretched spring), after one cycle; the state (q, q̇ = 0).
fn stretched() -> (Controller, Vec<f64>, Vec<f64>) {
    let path =
        PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../config/panda-pose-posture.toml");
    let sc = Scenario::load(&path).unwrap();
    let mut spec = sc.spec.clone();
    spec.levels[0].goal[1] += 0.1;
    let mut c = Controller::new(&sc.model, spec, &sc.q0).unwrap();
    let (q, rest) = (sc.q0.as_slice().to_vec(), vec![0.0; sc.model.nq()]);
    c.step(&q, &rest).unwrap();
    (c, q, rest)
}

#[test]
fn a_restore_the_tanks_cannot_pay_waits_for_them() {
    let (mut c, q, rest) = stretched();
    let n = q.len();
    let mut contact = Contact::defaults(n);
    contact.reaction = Reaction::Soften;
    contact.soften_fraction = 0.5;
    contact.ramp_s = 0.05;
    let mut r = ContactReaction::new(&contact);
    let dt = 1e-3;
    for _ in 0..100 {
        r.before_law(true, false, 0, dt, &mut c);
        c.step(&q, &rest).unwrap();
    }
    assert_eq!((r.level(), c.stiffness_scale()), (1.0, 0.5));
    // The contact is over, but the tanks hold nothing to spare.
    c.draw_tank_spare(1e9);
    for _ in 0..100 {
        r.before_law(false, false, 0, dt, &mut c);
    }
    assert_eq!((r.level(), c.stiffness_scale()), (1.0, 0.5));
    assert_eq!(r.restore_held, 100);
    // A command refills them (in the law's next cycle): the restore goes on.
    c.command_taken();
    c.step(&q, &rest).unwrap();
    for _ in 0..100 {
        r.before_law(false, false, 0, dt, &mut c);
        c.step(&q, &rest).unwrap();
    }
    assert_eq!((r.level(), c.stiffness_scale()), (0.0, 1.0));
    assert_eq!(r.restore_held, 100);
}

#[test]
fn a_release_the_tanks_cannot_pay_waits_for_them() {
    // `hold`: the law's share 1 − h of the torque is booked as soften's κ
    // is; a release (a setpoint taken) the tanks cannot pay waits.
    let (mut c, q, rest) = stretched();
    let n = q.len();
    let h0 = c.output().safety.h;
    let mut contact = Contact::defaults(n);
    contact.reaction = Reaction::Hold;
    contact.ramp_s = 0.05;
    let mut r = ContactReaction::new(&contact);
    let dt = 1e-3;
    r.before_law(true, true, 0, dt, &mut c);
    c.step(&q, &rest).unwrap();
    for _ in 0..100 {
        r.before_law(true, false, 0, dt, &mut c);
        c.step(&q, &rest).unwrap();
    }
    assert!(r.held() && r.level() == 1.0);
    // The springs' storage left for the fade's tank (which keeps up to its
    // cap): H did not rise.
    assert!(
        c.output().safety.h <= h0 + 1e-9,
        "{h0} → {}",
        c.output().safety.h
    );
    // A setpoint releases the hold, but the tanks hold nothing to spare.
    c.draw_tank_spare(1e9);
    for _ in 0..100 {
        r.before_law(false, false, 1, dt, &mut c);
    }
    assert!(!r.held());
    assert_eq!(r.level(), 1.0);
    assert_eq!(r.restore_held, 100);
    // A command refills them (in the law's next cycle): the release goes on.
    c.command_taken();
    c.step(&q, &rest).unwrap();
    for _ in 0..100 {
        r.before_law(false, false, 1, dt, &mut c);
        c.step(&q, &rest).unwrap();
    }
    assert_eq!(r.level(), 0.0);
    assert_eq!(r.restore_held, 100);
}
