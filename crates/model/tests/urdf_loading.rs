//! Loading chains from URDF: structure, locked subtrees, limits, and every
//! error case (each error names the file and the offending element).

mod common;

use common::*;
use hcc_model::*;
use nalgebra::{DMatrix, DVector, Vector3};

/// A small robot: base -j1(revolute z)-> a -j2(`j2_type`, axis `axis`)-> b -fixed-> tip,
/// with `b_inertial` as link b's inertial element and `extra` appended.
fn robot(j2_type: &str, axis: &str, b_inertial: &str, extra: &str) -> String {
    format!(
        r#"<?xml version="1.0"?>
<robot name="small">
  <link name="base"/>
  <link name="a">
    <inertial><origin xyz="0 0 0.1"/><mass value="1"/><inertia ixx="0.01" ixy="0" ixz="0" iyy="0.01" iyz="0" izz="0.01"/></inertial>
  </link>
  <link name="b">{b_inertial}</link>
  <link name="tip"/>
  <joint name="j1" type="revolute">
    <parent link="base"/><child link="a"/><origin xyz="0 0 0.2"/><axis xyz="0 0 1"/>
    <limit lower="-1" upper="1" effort="10" velocity="2"/>
  </joint>
  <joint name="j2" type="{j2_type}">
    <parent link="a"/><child link="b"/><origin xyz="0 0 0.3"/><axis xyz="{axis}"/>
    <limit lower="-0.5" upper="0.5" effort="5" velocity="1"/>
  </joint>
  <joint name="tip_joint" type="fixed">
    <parent link="b"/><child link="tip"/><origin xyz="0.1 0 0"/>
  </joint>
  {extra}
</robot>"#
    )
}

const GOOD_B: &str = r#"<inertial><origin xyz="0.05 0 0"/><mass value="0.5"/><inertia ixx="0.002" ixy="0" ixz="0" iyy="0.003" iyz="0" izz="0.004"/></inertial>"#;

fn load(urdf: &str) -> Result<Model, ModelError> {
    Model::from_urdf_str(urdf, None, "tip", None)
}

fn expect_err(urdf: &str, needles: &[&str]) -> ModelError {
    let err = load(urdf).expect_err("loading should fail");
    let msg = err.to_string();
    assert!(
        msg.contains("<urdf string>"),
        "message does not name the source: {msg}"
    );
    for n in needles {
        assert!(msg.contains(n), "message '{msg}' does not mention '{n}'");
    }
    err
}

#[test]
fn panda_structure() {
    let model = panda();
    assert_eq!(model.nq(), 7);
    assert_eq!(model.root_link, "panda_link0");
    assert_eq!(model.tip_link, "panda_hand_tcp");
    let mut locked = model.locked_joints.clone();
    locked.sort();
    assert_eq!(locked, ["panda_finger_joint1", "panda_finger_joint2"]);
    // Every link is a frame; the fingers and the hand move with body 7.
    assert_eq!(model.frames.len(), 13);
    for name in [
        "panda_link0",
        "panda_link8",
        "panda_hand",
        "panda_leftfinger",
        "panda_rightfinger",
    ] {
        assert!(model.frame_id(name).is_some(), "{name} is not a frame");
    }
    assert_eq!(
        model.frames[model.frame_id("panda_link0").unwrap()].body,
        None
    );
    assert_eq!(
        model.frames[model.frame_id("panda_leftfinger").unwrap()].body,
        Some(6)
    );
    // Hand (0.73 kg) and fingers (2 × 0.015 kg) are lumped into body 7.
    let link7 = 0.735522 + 0.73 + 0.03;
    assert!((model.joints[6].inertia.mass - link7).abs() < 1e-12);
    let effort: Vec<f64> = model.effort_limits().iter().copied().collect();
    assert_eq!(effort, [87.0, 87.0, 87.0, 87.0, 12.0, 12.0, 12.0]);
    assert_eq!(
        (model.joints[3].lower, model.joints[3].upper),
        (-3.0718, -0.0698)
    );
    assert_eq!(model.joints[0].velocity_limit, 2.175);
    assert_eq!(model.gravity, Vector3::new(0.0, 0.0, -9.81));
}

#[test]
fn shorter_chains_lock_the_rest() {
    // Tip in the middle: joints 5..7 and the fingers are locked, their inertia lumped.
    let full = panda();
    let model = Model::from_urdf_file(PANDA_URDF, None, "panda_link4", None).unwrap();
    assert_eq!(model.nq(), 4);
    assert_eq!(model.locked_joints.len(), 5);
    assert!((model.total_mass() - full.total_mass()).abs() < 1e-12);
    // With joints 5..7 at zero, M's upper-left block equals the full model's.
    let mut data_full = Data::new(&full);
    let mut data = Data::new(&model);
    let q = DVector::from_vec(vec![0.3, -0.4, 0.5, -1.5]);
    let q_full = DVector::from_vec(vec![0.3, -0.4, 0.5, -1.5, 0.0, 0.0, 0.0]);
    crba(&model, &mut data, &q);
    crba(&full, &mut data_full, &q_full);
    let block: DMatrix<f64> = data_full.m.view((0, 0), (4, 4)).into_owned();
    assert!(rel(&data.m, &block) < 1e-12);
    gravity(&model, &mut data, &q);
    gravity(&full, &mut data_full, &q_full);
    assert!(relv(&data.g, &data_full.g.rows(0, 4).into_owned()) < 1e-12);
    // Chosen root: the chain from link 2 has 5 joints.
    let sub =
        Model::from_urdf_file(PANDA_URDF, Some("panda_link2"), "panda_hand_tcp", None).unwrap();
    assert_eq!(sub.nq(), 5);
    assert_eq!(sub.joints[0].name, "panda_joint3");
    assert_eq!(sub.frames[0].name, "panda_link2");
}

#[test]
fn planar4_structure() {
    let model = planar();
    assert_eq!(model.nq(), 4);
    assert_eq!(model.root_link, "base");
    assert!(
        model
            .joints
            .iter()
            .all(|j| j.lower == f64::NEG_INFINITY && j.upper == f64::INFINITY)
    );
    assert!((model.total_mass() - 4.0).abs() < 1e-15);
    let mut data = Data::new(&model);
    forward_kinematics(&model, &mut data, &DVector::zeros(4));
    let tcp = frame_placement(&model, &data, model.tip_frame());
    assert!((tcp.translation.vector - Vector3::new(0.0, 2.0, 0.0)).norm() < 1e-15);
}

#[test]
fn small_robot_prismatic_and_limits() {
    let model = load(&robot("prismatic", "1 0 0", GOOD_B, "")).unwrap();
    assert_eq!(model.nq(), 2);
    assert_eq!(model.joints[1].kind, JointKind::Prismatic);
    assert_eq!((model.joints[1].lower, model.joints[1].upper), (-0.5, 0.5));
    assert_eq!(model.joints[1].effort_limit, 5.0);
    let mut data = Data::new(&model);
    forward_kinematics(&model, &mut data, &DVector::from_vec(vec![0.0, 0.25]));
    let p = frame_placement(&model, &data, model.tip_frame())
        .translation
        .vector;
    assert!((p - Vector3::new(0.35, 0.0, 0.5)).norm() < 1e-15);
    // Continuous: unlimited position.
    let model = load(&robot("continuous", "0 1 0", GOOD_B, "")).unwrap();
    assert_eq!(model.joints[1].upper, f64::INFINITY);
    // Axis is normalised.
    let model = load(&robot("revolute", "0 3 4", GOOD_B, "")).unwrap();
    assert!((model.joints[1].axis - Vector3::new(0.0, 0.6, 0.8)).norm() < 1e-15);
    // A fixed joint on the chain is allowed: j2 fixed → 1 DOF, b lumped into body 1.
    let model = load(&robot("fixed", "0 0 1", GOOD_B, "")).unwrap();
    assert_eq!(model.nq(), 1);
    assert!((model.joints[0].inertia.mass - 1.5).abs() < 1e-15);
}

#[test]
fn missing_file() {
    let err = Model::from_urdf_file("no/such/robot.urdf", None, "tip", None).unwrap_err();
    assert!(matches!(err, ModelError::Io { .. }));
    assert!(err.to_string().contains("no/such/robot.urdf"));
}

#[test]
fn xml_errors() {
    let err = expect_err("<robot name=\"x\"><link name=\"a\"></robot>", &[]);
    assert!(matches!(err, ModelError::Parse { .. }), "{err:?}");
    let err = expect_err("this is not xml", &[]);
    assert!(matches!(err, ModelError::Parse { .. }), "{err:?}");
}

#[test]
fn unknown_links() {
    let urdf = robot("revolute", "0 0 1", GOOD_B, "");
    let err = Model::from_urdf_str(&urdf, None, "nope", None).unwrap_err();
    assert!(matches!(err, ModelError::UnknownLink { .. }));
    assert!(err.to_string().contains("'nope'") && err.to_string().contains("tip"));
    let err = Model::from_urdf_str(&urdf, Some("nowhere"), "tip", None).unwrap_err();
    assert!(err.to_string().contains("'nowhere'") && err.to_string().contains("root"));
    let bad = robot(
        "revolute",
        "0 0 1",
        GOOD_B,
        r#"<joint name="dangling" type="fixed"><parent link="b"/><child link="ghost"/></joint>"#,
    );
    let err = expect_err(&bad, &["ghost", "dangling"]);
    assert!(matches!(err, ModelError::UnknownLink { .. }));
}

#[test]
fn tip_not_below_root() {
    let urdf = robot("revolute", "0 0 1", GOOD_B, "");
    let err = Model::from_urdf_str(&urdf, Some("b"), "a", None).unwrap_err();
    assert!(matches!(err, ModelError::TipNotBelowRoot { .. }), "{err:?}");
    assert!(err.to_string().contains("'a'") && err.to_string().contains("'b'"));
    let err = Model::from_urdf_str(&urdf, Some("a"), "a", None).unwrap_err();
    assert!(matches!(err, ModelError::TipNotBelowRoot { .. }), "{err:?}");
    // Only fixed joints between root and tip.
    let err = Model::from_urdf_str(&urdf, Some("b"), "tip", None).unwrap_err();
    assert!(matches!(err, ModelError::NoMovableJoint { .. }), "{err:?}");
}

#[test]
fn not_a_tree() {
    // A second parent for b.
    let two_parents = robot(
        "revolute",
        "0 0 1",
        GOOD_B,
        r#"<joint name="again" type="fixed"><parent link="base"/><child link="b"/></joint>"#,
    );
    let err = expect_err(&two_parents, &["'b'", "again"]);
    assert!(matches!(err, ModelError::NotATree { .. }));
    // A second root.
    let two_roots = robot("revolute", "0 0 1", GOOD_B, r#"<link name="island"/>"#);
    let err = expect_err(&two_roots, &["island"]);
    assert!(matches!(err, ModelError::NotATree { .. }));
    // A cycle (base gets a parent).
    let cycle = robot(
        "revolute",
        "0 0 1",
        GOOD_B,
        r#"<joint name="loop" type="fixed"><parent link="tip"/><child link="base"/></joint>"#,
    );
    let err = expect_err(&cycle, &["cycle"]);
    assert!(matches!(err, ModelError::NotATree { .. }));
    // Duplicate link name.
    let dup = robot("revolute", "0 0 1", GOOD_B, r#"<link name="a"/>"#);
    let err = expect_err(&dup, &["'a'", "duplicate"]);
    assert!(matches!(err, ModelError::NotATree { .. }));
}

#[test]
fn invalid_inertials() {
    let negative = r#"<inertial><mass value="-1"/><inertia ixx="0.1" ixy="0" ixz="0" iyy="0.1" iyz="0" izz="0.1"/></inertial>"#;
    let err = expect_err(
        &robot("revolute", "0 0 1", negative, ""),
        &["'b'", "negative mass"],
    );
    assert!(matches!(err, ModelError::InvalidInertial { .. }));
    let indefinite = r#"<inertial><mass value="1"/><inertia ixx="0.1" ixy="0.5" ixz="0" iyy="0.1" iyz="0" izz="0.1"/></inertial>"#;
    let err = expect_err(
        &robot("revolute", "0 0 1", indefinite, ""),
        &["'b'", "positive semidefinite"],
    );
    assert!(matches!(err, ModelError::InvalidInertial { .. }));
    let triangle = r#"<inertial><mass value="1"/><inertia ixx="0.1" ixy="0" ixz="0" iyy="0.1" iyz="0" izz="0.3"/></inertial>"#;
    let err = expect_err(
        &robot("revolute", "0 0 1", triangle, ""),
        &["'b'", "triangle"],
    );
    assert!(matches!(err, ModelError::InvalidInertial { .. }));
    // Point masses (zero rotational inertia) are fine.
    let point = r#"<inertial><mass value="1"/><inertia ixx="0" ixy="0" ixz="0" iyy="0" iyz="0" izz="0"/></inertial>"#;
    assert!(load(&robot("revolute", "0 0 1", point, "")).is_ok());
}

#[test]
fn unsupported_joints_and_axes() {
    for kind in ["floating", "planar"] {
        let err = expect_err(&robot(kind, "0 0 1", GOOD_B, ""), &["'j2'", kind]);
        assert!(
            matches!(err, ModelError::UnsupportedJoint { .. }),
            "{err:?}"
        );
    }
    // Off the chain a floating joint is just locked.
    let off = robot(
        "revolute",
        "0 0 1",
        GOOD_B,
        r#"<link name="float"/><joint name="fj" type="floating"><parent link="a"/><child link="float"/></joint>"#,
    );
    assert_eq!(load(&off).unwrap().locked_joints, ["fj"]);
    let err = expect_err(&robot("revolute", "0 0 0", GOOD_B, ""), &["'j2'", "axis"]);
    assert!(matches!(err, ModelError::ZeroAxis { .. }));
}

#[test]
fn bad_gravity_and_state_sizes() {
    let urdf = robot("revolute", "0 0 1", GOOD_B, "");
    let err = Model::from_urdf_str(&urdf, None, "tip", Some(Vector3::new(0.0, f64::NAN, 0.0)))
        .unwrap_err();
    assert!(matches!(err, ModelError::InvalidGravity(_)));
    let model = load(&urdf).unwrap();
    let mut data = Data::new(&model);
    let short = DVector::zeros(1);
    let ok = DVector::zeros(2);
    let err = forward_dynamics(&model, &mut data, &short, &ok, &ok).unwrap_err();
    assert!(
        err.to_string().contains("q has length 1, expected 2"),
        "{err}"
    );
    // Functions without a Result fill their output with NaN instead of panicking.
    crba(&model, &mut data, &short);
    assert!(data.m.iter().all(|v| v.is_nan()));
    let mut j = DMatrix::zeros(6, 3);
    frame_jacobian(&model, &data, 0, &mut j);
    assert!(j.iter().all(|v| v.is_nan()));
    assert!(frame_placement(&model, &data, 99).translation.x.is_nan());
}
