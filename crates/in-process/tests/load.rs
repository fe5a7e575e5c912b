//! A load announced in the scenario (`[robot.load]`): the plant carries it
//! and the controller's model knows it, so the hierarchy holds its pose as
//! without one — the gravity torque includes the load's, nothing sags.

use std::path::PathBuf;

use hcc_config::Scenario;
use hcc_in_process::run_observed;

fn pose_posture(load: &str) -> Scenario {
    let path =
        PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../config/panda-pose-posture.toml");
    let text = std::fs::read_to_string(&path).unwrap() + load;
    let mut s = Scenario::from_toml_str(&text, &path).unwrap();
    s.set_duration(3.0).unwrap();
    s
}

/// The largest TCP position error over the last second, m.
fn settled_error(scenario: &Scenario) -> f64 {
    let mut worst: f64 = 0.0;
    run_observed(scenario, &mut |view| {
        if view.t >= 2.0 {
            let e = view.cycle.telemetry().task_error(0);
            worst = worst.max((e[0] * e[0] + e[1] * e[1] + e[2] * e[2]).sqrt());
        }
        Ok(())
    })
    .unwrap();
    worst
}

#[test]
fn an_announced_load_is_held_as_the_arm_without_one() {
    let bare = settled_error(&pose_posture(""));
    let loaded = settled_error(&pose_posture(
        "\n[robot.load]\nmass = 1.0\ncom = [0.0, 0.0, 0.1]\n",
    ));
    println!(
        "TCP error over the last second: {bare:.2e} m without a load, {loaded:.2e} m with 1 kg announced"
    );
    assert!(loaded < 1e-3, "{loaded:e} m");
}

#[test]
fn an_unannounced_load_is_felt_as_a_contact_whose_torque_is_its_weight() {
    // 1 kg at 0.1 m along the tip's z, taken by the plant's hand at 1 s: the
    // controller's model does not know it.
    let scenario =
        pose_posture("\n[[simulation.load]]\nstart_s = 1.0\nmass = 1.0\ncom = [0.0, 0.0, 0.1]\n");
    let bare = scenario.model.clone();
    let load = hcc_model::Load::point(1.0, [0.0, 0.0, 0.1]);
    let mut flagged_at = None;
    let mut worst_share: f64 = 0.0;
    let mut last = (Vec::new(), Vec::new());
    run_observed(&scenario, &mut |view| {
        let tel = view.cycle.telemetry();
        if view.t >= 1.0 && flagged_at.is_none() && tel.contact() {
            flagged_at = Some(view.t);
        }
        if view.t >= 2.5 {
            // The load's gravity torque where the arm is.
            let q = nalgebra::DVector::from_column_slice(view.state.q());
            let expected = load_gravity_torque(&bare, &q, &load);
            let off = tel
                .tau_ext()
                .iter()
                .zip(expected.iter())
                .map(|(a, b)| (a - b).abs())
                .fold(0.0, f64::max);
            worst_share = worst_share.max(off / expected.amax());
            last = (tel.tau_ext().to_vec(), expected.as_slice().to_vec());
        }
        Ok(())
    })
    .unwrap();
    println!(
        "contact flagged {:?} s after the load; from 2.5 s the estimate off the load's weight by at \
         most {:.2} % of its largest entry; last estimate {:?}, weight {:?}",
        flagged_at.map(|t| t - 1.0),
        100.0 * worst_share,
        last.0,
        last.1
    );
    let after = flagged_at.expect("no contact flagged") - 1.0;
    assert!(after <= 0.020, "flagged {after} s after the load");
    assert!(worst_share < 0.02, "{worst_share}");
}

/// −(−J_comᵀ m g): the external torque the load's weight puts on the joints,
/// J_comᵀ m g (g the gravity vector), at `q`.
fn load_gravity_torque(
    model: &hcc_model::Model,
    q: &nalgebra::DVector<f64>,
    load: &hcc_model::Load,
) -> nalgebra::DVector<f64> {
    let mut data = hcc_model::Data::new(model);
    hcc_model::forward_kinematics(model, &mut data, q);
    let tip = model.tip_frame();
    let mut j = nalgebra::DMatrix::zeros(6, model.nq());
    hcc_model::frame_jacobian(model, &data, tip, &mut j);
    let r = hcc_model::frame_placement(model, &data, tip).rotation * load.com;
    let jc = j.rows(0, 3).into_owned()
        - nalgebra::DMatrix::from_column_slice(3, 3, r.cross_matrix().as_slice())
            * j.rows(3, 3).into_owned();
    jc.transpose() * (model.gravity * load.mass)
}
