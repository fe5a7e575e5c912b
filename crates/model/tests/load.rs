//! A load at the tip frame, checked against physics rather than against the
//! code that lumps it in: the gravity torque it adds is −J_comᵀ m g (the
//! Jacobian of its centre of mass, from the tip frame's Jacobian shifted by
//! ω × r), a point load adds m J_comᵀ J_com to M, and the robot with a load
//! of zero mass is the robot without one, bit for bit.

mod common;

use common::panda;
use hcc_model::{
    Data, Load, LoadError, Model, crba, forward_kinematics, frame_jacobian, frame_placement,
    gravity, load_gravity, set_load,
};
use nalgebra::{DMatrix, DVector, Matrix3, Vector3};

/// Configurations across the Panda's range.
fn configurations() -> Vec<DVector<f64>> {
    (0..6)
        .map(|k| {
            let s = k as f64;
            DVector::from_vec(vec![
                0.3 * s - 0.8,
                -0.4 + 0.15 * s,
                0.2 * s - 0.5,
                -2.4 + 0.25 * s,
                0.5 - 0.2 * s,
                1.2 + 0.2 * s,
                0.4 * s - 1.0,
            ])
        })
        .collect()
}

/// The 3×n Jacobian of the point at `com` (tip frame) at `q`.
fn com_jacobian(model: &Model, q: &DVector<f64>, com: &Vector3<f64>) -> DMatrix<f64> {
    let mut data = Data::new(model);
    forward_kinematics(model, &mut data, q);
    let tip = model.tip_frame();
    let mut j = DMatrix::zeros(6, model.nq());
    frame_jacobian(model, &data, tip, &mut j);
    let r = frame_placement(model, &data, tip).rotation * com;
    // v = v_tip + ω × r = v_tip − r × ω.
    let linear = j.rows(0, 3).into_owned();
    let angular = j.rows(3, 3).into_owned();
    linear - DMatrix::from_column_slice(3, 3, r.cross_matrix().as_slice()) * angular
}

fn gravity_at(model: &Model, q: &DVector<f64>) -> DVector<f64> {
    let mut data = Data::new(model);
    gravity(model, &mut data, q);
    data.g.clone()
}

fn mass_matrix_at(model: &Model, q: &DVector<f64>) -> DMatrix<f64> {
    let mut data = Data::new(model);
    crba(model, &mut data, q);
    data.m.clone()
}

#[test]
fn a_load_adds_its_gravity_torque_and_its_inertia() {
    let bare = panda();
    let load = Load::point(1.0, [0.0, 0.0, 0.1]);
    let mut loaded = bare.clone();
    set_load(&mut loaded, &load);
    let (mut worst_g, mut worst_m) = (0.0_f64, 0.0_f64);
    for q in configurations() {
        let jc = com_jacobian(&bare, &q, &load.com);
        // The torque that holds the load against gravity: −J_comᵀ m g.
        let expected = -(jc.transpose() * (bare.gravity * load.mass));
        let added = gravity_at(&loaded, &q) - gravity_at(&bare, &q);
        worst_g = worst_g.max((added - &expected).amax() / expected.amax());
        let expected_m = load.mass * jc.transpose() * &jc;
        let added_m = mass_matrix_at(&loaded, &q) - mass_matrix_at(&bare, &q);
        worst_m = worst_m.max((added_m - &expected_m).amax() / expected_m.amax());
    }
    println!(
        "1 kg at 0.1 m along the tip's z: gravity torque off −J_comᵀ m g by {worst_g:.1e}, \
         inertia off m J_comᵀ J_com by {worst_m:.1e} (relative to the largest entry)"
    );
    assert!(worst_g < 1e-12, "{worst_g:e}");
    assert!(worst_m < 1e-12, "{worst_m:e}");
}

/// What a controller adds when the driver compensates the arm's gravity but
/// not the load's: the loaded model's g less the bare model's, for a load
/// off the tip's axis (r × g₀ matters), from the loaded model alone.
#[test]
fn the_load_s_own_gravity_torque_is_the_difference_of_the_two_models() {
    let bare = panda();
    let mut loaded = bare.clone();
    let load = Load {
        mass: 1.5,
        com: Vector3::new(0.04, -0.03, 0.12),
        inertia: Matrix3::from_diagonal(&Vector3::new(2e-3, 3e-3, 4e-3)),
    };
    set_load(&mut loaded, &load);
    let n = bare.nq();
    let (mut jac, mut g_load) = (DMatrix::zeros(6, n), DVector::zeros(n));
    let mut worst = 0.0_f64;
    for q in configurations() {
        let mut data = Data::new(&loaded);
        forward_kinematics(&loaded, &mut data, &q);
        load_gravity(&loaded, &data, &mut jac, &mut g_load);
        let want = gravity_at(&loaded, &q) - gravity_at(&bare, &q);
        worst = worst.max((&g_load - &want).amax() / want.amax());
    }
    println!("the load's own gravity torque off g(loaded) − g(bare) by {worst:.1e} (relative)");
    assert!(worst < 1e-12, "{worst:e}");
    // No load: zero.
    let mut data = Data::new(&bare);
    forward_kinematics(&bare, &mut data, &configurations()[1]);
    load_gravity(&bare, &data, &mut jac, &mut g_load);
    assert!(g_load.iter().all(|x| *x == 0.0));
}

#[test]
fn a_load_s_own_inertia_adds_to_m_and_no_load_restores_the_robot_bit_for_bit() {
    let bare = panda();
    let mut loaded = bare.clone();
    // A 0.2 m cube of 2 kg, its centre 5 cm off the tip's axis.
    let side = 0.2;
    let i = 2.0 * side * side / 6.0;
    let cube = Load {
        mass: 2.0,
        com: Vector3::new(0.05, 0.0, 0.1),
        inertia: Matrix3::from_diagonal_element(i),
    };
    set_load(&mut loaded, &cube);
    let q = &configurations()[2];
    let m_loaded = mass_matrix_at(&loaded, q);
    let m_point = {
        let mut point = bare.clone();
        set_load(&mut point, &Load::point(2.0, [0.05, 0.0, 0.1]));
        mass_matrix_at(&point, q)
    };
    // The cube's rotational inertia adds J_ωᵀ I_w J_ω (a sphere-like I:
    // any rotation of the axes leaves it i·1).
    let mut data = Data::new(&bare);
    forward_kinematics(&bare, &mut data, q);
    let mut j = DMatrix::zeros(6, bare.nq());
    frame_jacobian(&bare, &data, bare.tip_frame(), &mut j);
    let jw = j.rows(3, 3).into_owned();
    let expected = i * jw.transpose() * &jw;
    let off = (m_loaded - m_point - &expected).amax() / expected.amax();
    assert!(off < 1e-12, "{off:e}");
    // Taking the load off restores the URDF's body exactly.
    set_load(&mut loaded, &Load::none());
    assert_eq!(
        loaded.joints.last().unwrap().inertia,
        bare.joints.last().unwrap().inertia
    );
    assert_eq!(gravity_at(&loaded, q), gravity_at(&bare, q));
}

#[test]
fn loads_that_are_not_physical_or_too_heavy_are_refused() {
    let ok = Load::point(1.0, [0.0, 0.0, 0.1]);
    assert_eq!(ok.check(3.0), Ok(()));
    assert_eq!(Load::none().check(3.0), Ok(()));
    let with = |f: &dyn Fn(&mut Load)| {
        let mut l = ok;
        f(&mut l);
        l.check(3.0)
    };
    assert_eq!(with(&|l| l.mass = -0.1), Err(LoadError::NegativeMass(-0.1)));
    assert_eq!(
        with(&|l| l.mass = 3.5),
        Err(LoadError::AbovePayload {
            mass: 3.5,
            limit: 3.0
        })
    );
    assert_eq!(with(&|l| l.com.x = f64::NAN), Err(LoadError::NonFinite));
    assert_eq!(
        with(&|l| l.inertia[(0, 1)] = 0.01),
        Err(LoadError::NotSymmetric)
    );
    let not_psd = with(&|l| l.inertia = Matrix3::from_diagonal(&Vector3::new(0.1, 0.1, -0.01)));
    assert!(
        matches!(not_psd, Err(LoadError::Inertia(e)) if e.to_string().contains("positive semidefinite")),
        "{not_psd:?}"
    );
    let triangle = with(&|l| l.inertia = Matrix3::from_diagonal(&Vector3::new(0.1, 0.1, 0.3)));
    assert!(
        matches!(triangle, Err(LoadError::Inertia(e)) if e.to_string().contains("triangle")),
        "{triangle:?}"
    );
}
