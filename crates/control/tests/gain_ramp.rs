//! A gains transition's steps booked through the energy tanks
//! (`Controller::ramp_gains`): a stiffer spring stores β κ ½ eᵀ ΔK e more at
//! its present stretch, paid from the tanks' spare; a softer one gives it to
//! the fade's tank; H plus the tanks does not change by either. A stiffening
//! the spare cannot pay is refused whole. A contact reaction's stiffness
//! scale κ (`Controller::ramp_stiffness_scale`) goes the same way.

mod common;
use common::*;
use hcc_control::Controller;
use nalgebra::{DMatrix, DVector};

const Q0: [f64; 7] = [0.1, -0.2, 0.05, -2.0, 0.1, 1.9, 0.7];
const REST: [f64; 7] = [0.0; 7];

/// The Panda's controller at rest at `Q0`, its TCP 5 cm from its goal along
/// x, the orientation and the posture at theirs (V = ½ · 800 · 0.05² = 1 J;
/// every tank filled with `tank_initial` plus half of it, below `tank_max`).
fn panda_stretched_5cm() -> Controller {
    let tank_initial = panda_spec(&panda()).safety.tank_initial;
    panda_tcp_offset(&Q0, [0.05, 0.0, 0.0], tank_initial).0
}

fn h(c: &mut Controller) -> f64 {
    c.step(&Q0, &REST).expect("step").safety.h
}

fn k1(c: &Controller) -> DMatrix<f64> {
    c.level_target(0).expect("level").stiffness.clone()
}

#[test]
fn a_stiffening_is_paid_from_the_spare_and_h_does_not_change() {
    let mut c = panda_stretched_5cm();
    let before = h(&mut c);
    assert!((h(&mut c) - before).abs() < 1e-12, "at rest H stands still");
    let out = c.step(&Q0, &REST).expect("step");
    assert!((out.potential[0] - 1.0).abs() < 1e-9, "{:?}", out.potential);
    assert!(out.potential[1].abs() < 1e-12 && out.potential[2].abs() < 1e-12);
    let k = k1(&c) * 1.5;
    // ½ eᵀ ΔK e with e = 5 cm, ΔK = 400 N/m.
    let energy = c.stiffness_change_energy(0, &k);
    assert!((energy - 0.5).abs() < 1e-9, "{energy}");
    let spare = c.tank_spare();
    assert!(spare > energy, "{spare}");
    assert!(c.ramp_gains(0, Some(&k), None).expect("gains"));
    assert_eq!(k1(&c), k);
    assert!((c.tank_spare() - (spare - energy)).abs() < 1e-9);
    let out = c.step(&Q0, &REST).expect("step");
    assert!((out.potential[0] - 1.5).abs() < 1e-9);
    let after = out.safety.h;
    assert!(
        (after - before).abs() < 1e-9,
        "H {before} → {after}: the tanks paid the spring's rise"
    );
}

#[test]
fn a_softening_fills_the_fade_tank_and_h_does_not_change() {
    let mut c = panda_stretched_5cm();
    let before = h(&mut c);
    let spare = c.tank_spare();
    let k = k1(&c) * 0.75;
    let energy = c.stiffness_change_energy(0, &k);
    assert!((energy + 0.25).abs() < 1e-9, "{energy}");
    assert!(c.ramp_gains(0, Some(&k), None).expect("gains"));
    assert!((c.tank_spare() - (spare + 0.25)).abs() < 1e-9);
    let after = h(&mut c);
    assert!((after - before).abs() < 1e-9, "H {before} → {after}");
}

#[test]
fn a_stiffening_the_spare_cannot_pay_waits_and_the_damping_alone_is_taken() {
    let mut c = panda_stretched_5cm();
    h(&mut c);
    let (k, spare) = (k1(&c), c.tank_spare());
    // ½ · 0.05² · 799 200 N/m ≈ 999 J: more than the tanks hold.
    assert!(!c.ramp_gains(0, Some(&(&k * 1000.0)), None).expect("gains"));
    assert_eq!(k1(&c), k, "nothing changed");
    assert!((c.tank_spare() - spare).abs() < 1e-12, "nothing taken");
    // A damping stores nothing.
    let d = c.level_target(0).expect("level").damping * 2.0;
    assert!(c.ramp_gains(0, None, Some(&d)).expect("gains"));
    assert_eq!(c.level_target(0).expect("level").damping, &d);
    assert!((c.tank_spare() - spare).abs() < 1e-12);
    // Bad gains are errors, as for set_gains.
    assert!(c.ramp_gains(0, Some(&(-&k)), None).is_err());
    assert!(c.ramp_gains(9, Some(&k), None).is_err());
}

/// With the spring saturation the storage is the saturated spring's,
/// V_sat = r_0 r − r_0²/2 beyond its radius r_0 = d_min v / √k_max: a
/// stiffening there books V_sat's change (not ½ eᵀ ΔK e, which would have
/// H fall by the difference), and a damping alone — it sets the radius — is
/// booked as well; H does not change by either.
#[test]
fn with_the_spring_saturation_the_saturated_springs_change_is_booked() {
    let (mut c, _) = panda_tcp_offset_with(&Q0, [0.3, 0.0, 0.0], |s| {
        s.safety.spring_saturation = true;
        // Below the tanks' capacity: nothing decays while it stands.
        s.safety.tank_max = 100.0;
    });
    let out = c.step(&Q0, &REST).expect("step");
    assert!(out.safety.spring_saturated, "beyond the radius");
    // ½ · 800 · 0.3² = 36 J unsaturated; the saturated spring stores less.
    let v = out.potential[0];
    assert!(v > 0.0 && v < 36.0 - 1e-3, "{v}");
    // Takes the gains (each None: as they are): the spring stores what was
    // booked, and H plus the tanks is the same.
    let take = |c: &mut Controller, k: Option<&DMatrix<f64>>, d: Option<&DMatrix<f64>>| {
        let before = c.step(&Q0, &REST).expect("step");
        let (v, h) = (before.potential[0], before.safety.h);
        let energy = c.gains_change_energy(0, k, d);
        assert!(c.tank_spare() > energy, "{}", c.tank_spare());
        assert!(c.ramp_gains(0, k, d).expect("gains"));
        let out = c.step(&Q0, &REST).expect("step");
        let stored = out.potential[0] - v;
        assert!(
            (stored - energy).abs() < 1e-9,
            "stored {stored}, booked {energy}"
        );
        assert!((out.safety.h - h).abs() < 1e-9, "H {h} → {}", out.safety.h);
        energy
    };
    // r = √(2V) grows by √1.5, r_0 falls by √1.5: V_sat = r_0 r − r_0²/2
    // changes by (r_0²/2)(1 − 1/1.5), far from ½ eᵀ ΔK e = 18 J.
    let k = k1(&c) * 1.5;
    let energy = take(&mut c, Some(&k), None);
    let unsaturated = 0.5 * 0.5 * 800.0 * 0.3 * 0.3;
    assert!(
        energy > 0.0 && energy < 0.5 * unsaturated,
        "{energy} (½ eᵀ ΔK e = {unsaturated})"
    );
    // Twice the damping doubles the radius: the saturated spring stores more.
    let d = c.level_target(0).expect("level").damping * 2.0;
    let energy = take(&mut c, None, Some(&d));
    assert!(energy > 0.0, "{energy}");
}

#[test]
fn without_the_tanks_a_ramp_is_taken_as_it_comes() {
    let model = panda();
    let mut spec = panda_spec(&model);
    spec.safety.energy_tanks = false;
    let mut c = Controller::new(&model, spec, &DVector::from_vec(Q0.to_vec())).expect("ctl");
    c.step(&Q0, &REST).expect("step");
    let k = k1(&c) * 1000.0;
    assert!(c.ramp_gains(0, Some(&k), None).expect("gains"));
    assert_eq!(k1(&c), k);
}

/// On quaternion rows (V = 2 εᵀ K ε) too, the booked change is the change of
/// the potential: doubling K doubles V.
#[test]
fn an_orientation_level_s_change_is_its_potential_s() {
    let mut c = panda_stretched_5cm();
    let rpy = c.level_target(1).expect("level").goal.to_vec();
    c.set_goal(1, &[rpy[0], rpy[1] + 0.1, rpy[2] + 0.2])
        .expect("goal");
    let v = c.step(&Q0, &REST).expect("step").potential[1];
    assert!(v > 0.1, "{v}");
    let k = c.level_target(1).expect("level").stiffness * 2.0;
    let energy = c.stiffness_change_energy(1, &k);
    assert!((energy - v).abs() < 1e-12 * v.max(1.0), "{energy} vs {v}");
    assert!(c.ramp_gains(1, Some(&k), None).expect("gains"));
    let after = c.step(&Q0, &REST).expect("step").potential[1];
    assert!((after - 2.0 * v).abs() < 1e-9, "{after} vs {}", 2.0 * v);
}

/// A contact reaction's κ through the same bookkeeping: softening puts the
/// springs' share into the fade's tank, restoring takes it back, H with the
/// tanks the same throughout; a restore the spare cannot pay is refused.
#[test]
fn the_stiffness_scale_is_booked_both_ways() {
    let mut c = panda_stretched_5cm();
    let before = h(&mut c);
    let spare = c.tank_spare();
    // V_1 = 1 J, the others 0: half of it leaves the springs.
    assert!(c.ramp_stiffness_scale(0.5));
    assert_eq!(c.stiffness_scale(), 0.5);
    assert!((c.tank_spare() - (spare + 0.5)).abs() < 1e-9);
    let out = c.step(&Q0, &REST).expect("step");
    assert!((out.potential[0] - 0.5).abs() < 1e-9);
    assert!(
        (out.safety.h - before).abs() < 1e-9,
        "H {before} → {}",
        out.safety.h
    );
    assert!(c.ramp_stiffness_scale(1.0));
    assert!((c.tank_spare() - spare).abs() < 1e-9);
    let after = h(&mut c);
    assert!((after - before).abs() < 1e-9, "H {before} → {after}");
    // Softened again, the spare spent: the restore waits.
    assert!(c.ramp_stiffness_scale(0.5));
    h(&mut c);
    c.draw_tank_spare(1e6);
    assert!(!c.ramp_stiffness_scale(1.0));
    assert_eq!(c.stiffness_scale(), 0.5);
    // Out of range: ignored, nothing to wait for.
    assert!(c.ramp_stiffness_scale(1.5) && c.ramp_stiffness_scale(f64::NAN));
    assert_eq!(c.stiffness_scale(), 0.5);
}

#[test]
fn the_law_share_of_a_hold_is_booked_both_ways() {
    // A contact hold blends the law's torque away (share s from 1 to 0): the
    // springs act with s, H counts s Σ β_i V_i, and the change goes through
    // the tanks — into the fade's tank on the way in, from the spare on the
    // way out.
    let mut c = panda_stretched_5cm();
    let before = h(&mut c);
    let spare = c.tank_spare();
    assert!(c.ramp_law_share(0.25));
    // V_1 = 1 J: three quarters of it leave the springs' storage.
    assert!((c.tank_spare() - (spare + 0.75)).abs() < 1e-9);
    let out = c.step(&Q0, &REST).expect("step");
    assert!((out.safety.level_potential[0] - 0.25).abs() < 1e-9);
    assert!(
        (out.safety.h - before).abs() < 1e-9,
        "H {before} → {}",
        out.safety.h
    );
    assert!(c.ramp_law_share(1.0));
    assert!((c.tank_spare() - spare).abs() < 1e-9);
    let after = h(&mut c);
    assert!((after - before).abs() < 1e-9, "H {before} → {after}");
    // Held again, the spare spent: the release waits.
    assert!(c.ramp_law_share(0.0));
    h(&mut c);
    c.draw_tank_spare(1e6);
    assert!(!c.ramp_law_share(1.0));
    assert!(c.ramp_law_share(f64::NAN), "ignored");
}
