//! Robots and hierarchies shared by the controller tests.
#![allow(dead_code)]

use hcc_control::{ControllerSpec, LevelSpec, TaskSpec};
use hcc_model::Model;
use nalgebra::{DMatrix, DVector};

pub fn data_path(name: &str) -> String {
    format!("{}/../../tests/data/{name}", env!("CARGO_MANIFEST_DIR"))
}

pub fn reference() -> serde_json::Value {
    let text = std::fs::read_to_string(data_path("paper_planar4.json")).expect("reference file");
    serde_json::from_str(&text).expect("reference JSON")
}

pub fn planar() -> Model {
    let path = format!("{}/../../config/planar4.urdf", env!("CARGO_MANIFEST_DIR"));
    Model::from_urdf_file(
        &path,
        None,
        "tcp",
        Some(nalgebra::Vector3::new(0.0, -9.81, 0.0)),
    )
    .expect("planar URDF")
}

pub fn panda() -> Model {
    let path = format!(
        "{}/../../config/robots/panda/panda.urdf",
        env!("CARGO_MANIFEST_DIR")
    );
    Model::from_urdf_file(&path, None, "panda_hand_tcp", None).expect("Panda URDF")
}

fn diag(v: &[f64]) -> DMatrix<f64> {
    DMatrix::from_diagonal(&DVector::from_column_slice(v))
}

/// The paper's hierarchy (Table I) with the gains of simulation `sim` ("sim1"/"sim2", Table II).
pub fn planar_spec(model: &Model, sim: &str) -> ControllerSpec {
    let r = reference();
    let g = &r["gains"][sim];
    let f = |v: &serde_json::Value| v.as_f64().expect("number");
    let vec = |v: &serde_json::Value| -> Vec<f64> {
        v.as_array().expect("array").iter().map(f).collect()
    };
    let tcp = model.frame_id("tcp").expect("tcp frame");
    let goal = &r["tasks"]["goal"];
    ControllerSpec::new(vec![
        LevelSpec {
            name: "tcp position".into(),
            tasks: vec![TaskSpec::Position {
                frame: tcp,
                axes: vec![0, 1],
            }],
            stiffness: diag(&vec(&g["K1"])),
            damping: diag(&vec(&g["D1"])),
            goal: DVector::from_vec(vec(&goal[0])),
        },
        LevelSpec {
            name: "tcp rotation".into(),
            tasks: vec![TaskSpec::JointCombination {
                weights: DMatrix::from_row_slice(1, 4, &[1.0, 1.0, 1.0, 1.0]),
            }],
            stiffness: diag(&[f(&g["K2"])]),
            damping: diag(&[f(&g["D2"])]),
            goal: DVector::from_vec(vec(&goal[1])),
        },
        LevelSpec {
            name: "joint 1".into(),
            tasks: vec![TaskSpec::Joints { indices: vec![0] }],
            stiffness: diag(&[f(&g["K3"])]),
            damping: diag(&[f(&g["D3"])]),
            goal: DVector::from_vec(vec(&goal[2])),
        },
    ])
}

/// Panda: TCP position / TCP orientation / posture.
/// The Panda's controller at rest at `q0` (7 values) with its TCP goal
/// `offset` (m) from the TCP, the orientation and the posture at theirs,
/// `tank_initial` J in the energy tanks, after one cycle; and the TCP's
/// position.
pub fn panda_tcp_offset(
    q0: &[f64],
    offset: [f64; 3],
    tank_initial: f64,
) -> (hcc_control::Controller, [f64; 3]) {
    panda_tcp_offset_with(q0, offset, |s| s.safety.tank_initial = tank_initial)
}

/// [`panda_tcp_offset`] with the spec changed by `change` first.
pub fn panda_tcp_offset_with(
    q0: &[f64],
    offset: [f64; 3],
    change: impl FnOnce(&mut ControllerSpec),
) -> (hcc_control::Controller, [f64; 3]) {
    let model = panda();
    let mut spec = panda_spec(&model);
    change(&mut spec);
    let q = nalgebra::DVector::from_column_slice(q0);
    let mut data = hcc_model::Data::new(&model);
    hcc_model::forward_kinematics(&model, &mut data, &q);
    let tcp = model.frame_id("panda_hand_tcp").expect("tcp");
    let placement = hcc_model::frame_placement(&model, &data, tcp);
    let p = placement.translation.vector;
    let (roll, pitch, yaw) = placement.rotation.euler_angles();
    spec.levels[0].goal =
        nalgebra::DVector::from_vec(vec![p[0] + offset[0], p[1] + offset[1], p[2] + offset[2]]);
    spec.levels[1].goal = nalgebra::DVector::from_vec(vec![roll, pitch, yaw]);
    spec.levels[2].goal = q.clone();
    let mut c = hcc_control::Controller::new(&model, spec, &q).expect("ctl");
    c.step(q0, &vec![0.0; q0.len()]).expect("step");
    (c, [p[0], p[1], p[2]])
}

pub fn panda_spec(model: &Model) -> ControllerSpec {
    let tcp = model.frame_id("panda_hand_tcp").expect("tcp frame");
    ControllerSpec::new(vec![
        LevelSpec {
            name: "tcp position".into(),
            tasks: vec![TaskSpec::Position {
                frame: tcp,
                axes: vec![0, 1, 2],
            }],
            stiffness: diag(&[800.0, 800.0, 800.0]),
            damping: diag(&[60.0, 60.0, 60.0]),
            goal: DVector::from_vec(vec![0.4, 0.1, 0.5]),
        },
        LevelSpec {
            name: "tcp orientation".into(),
            tasks: vec![TaskSpec::Orientation { frame: tcp }],
            stiffness: diag(&[60.0, 60.0, 60.0]),
            damping: diag(&[4.0, 4.0, 4.0]),
            goal: DVector::from_vec(vec![std::f64::consts::PI, 0.0, 0.3]),
        },
        LevelSpec {
            name: "posture".into(),
            tasks: vec![TaskSpec::Posture],
            stiffness: diag(&[20.0; 7]),
            damping: diag(&[2.0; 7]),
            goal: DVector::from_vec(vec![0.0, -0.3, 0.0, -2.2, 0.0, 2.0, 0.8]),
        },
    ])
}

pub fn vec_of(v: &serde_json::Value) -> Vec<f64> {
    v.as_array()
        .expect("array")
        .iter()
        .map(|x| x.as_f64().expect("number"))
        .collect()
}

/// ‖a − b‖ ≤ tol · max(1, ‖b‖).
pub fn close(a: &[f64], b: &[f64], tol: f64) -> bool {
    let d: f64 = a
        .iter()
        .zip(b)
        .map(|(x, y)| (x - y) * (x - y))
        .sum::<f64>()
        .sqrt();
    let nb: f64 = b.iter().map(|y| y * y).sum::<f64>().sqrt();
    a.len() == b.len() && d <= tol * nb.max(1.0)
}

/// Panda: the 6-D TCP pose (one stacked level) / posture, the two levels of the
/// common Cartesian impedance controller. `coupled`: a full 6×6 stiffness (position
/// and orientation rows coupled) instead of a diagonal one.
pub fn panda_pose_spec(model: &Model, coupled: bool) -> ControllerSpec {
    let tcp = model.frame_id("panda_hand_tcp").expect("tcp frame");
    let mut k = diag(&[300.0, 300.0, 300.0, 20.0, 20.0, 20.0]);
    if coupled {
        for (a, b, v) in [(0, 4, 15.0), (1, 3, -10.0), (2, 5, 8.0), (3, 4, 3.0)] {
            k[(a, b)] = v;
            k[(b, a)] = v;
        }
    }
    ControllerSpec::new(vec![
        LevelSpec::single(
            "tcp pose",
            TaskSpec::Pose { frame: tcp },
            k,
            diag(&[35.0, 35.0, 35.0, 9.0, 9.0, 9.0]),
            DVector::from_vec(vec![0.4, 0.1, 0.5, std::f64::consts::PI, 0.0, 0.3]),
        ),
        LevelSpec::single(
            "posture",
            TaskSpec::Posture,
            diag(&[5.0; 7]),
            diag(&[4.5; 7]),
            DVector::from_vec(vec![0.0, -0.3, 0.0, -2.2, 0.0, 2.0, 0.8]),
        ),
    ])
}

/// The same two levels with the pose as two stacked tasks, position then orientation
/// (`[[level.task]]` in a scenario file).
pub fn panda_stacked_spec(model: &Model) -> ControllerSpec {
    let tcp = model.frame_id("panda_hand_tcp").expect("tcp frame");
    let mut spec = panda_pose_spec(model, false);
    spec.levels[0].tasks = vec![
        TaskSpec::Position {
            frame: tcp,
            axes: vec![0, 1, 2],
        },
        TaskSpec::Orientation { frame: tcp },
    ];
    spec
}
