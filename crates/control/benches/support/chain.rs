//! The synthetic serial chains of the scaling benchmark (see `benches/scaling.rs`).

use hcc_control::{ControllerSpec, LevelSpec, TaskSpec};
use hcc_model::Model;
use nalgebra::{DMatrix, DVector};
use std::fmt::Write as _;

/// URDF of an n-joint chain: a 0.1 m base, then n links of length 1 / n along their z
/// axis, joint k about z (k even) or y (k odd). Link k is a cylinder tapering from
/// r = 6 cm to 3 cm with its mass falling linearly from 1.5 to 0.5 of 16 kg / n
/// (about 16 kg in all), centre of mass at the middle.
pub fn chain_urdf(n: usize) -> String {
    let len = 1.0 / n as f64;
    let mut s = String::new();
    writeln!(s, "<?xml version=\"1.0\"?>\n<robot name=\"chain{n}\">").unwrap();
    writeln!(s, "  <link name=\"base\"/>").unwrap();
    for k in 0..n {
        let f = k as f64 / (n - 1) as f64;
        let m = 16.0 / n as f64 * (1.5 - f);
        let r = 0.06 - 0.03 * f;
        let ixx = m * (3.0 * r * r + len * len) / 12.0;
        let izz = 0.5 * m * r * r;
        writeln!(
            s,
            "  <link name=\"link{k}\"><inertial><origin xyz=\"0 0 {c}\"/><mass value=\"{m}\"/>\
             <inertia ixx=\"{ixx}\" ixy=\"0\" ixz=\"0\" iyy=\"{ixx}\" iyz=\"0\" izz=\"{izz}\"/>\
             </inertial></link>",
            c = 0.5 * len
        )
        .unwrap();
        let parent = if k == 0 {
            "base".to_string()
        } else {
            format!("link{}", k - 1)
        };
        let z = if k == 0 { 0.1 } else { len };
        let axis = if k % 2 == 0 { "0 0 1" } else { "0 1 0" };
        writeln!(
            s,
            "  <joint name=\"j{k}\" type=\"revolute\"><parent link=\"{parent}\"/>\
             <child link=\"link{k}\"/><origin xyz=\"0 0 {z}\"/><axis xyz=\"{axis}\"/>\
             <limit lower=\"-2.9\" upper=\"2.9\" effort=\"100\" velocity=\"2\"/></joint>"
        )
        .unwrap();
    }
    writeln!(
        s,
        "  <link name=\"tcp\"/>\n  <joint name=\"tcp_joint\" type=\"fixed\">\
         <parent link=\"link{}\"/><child link=\"tcp\"/><origin xyz=\"0 0 {len}\"/></joint>\n</robot>",
        n - 1
    )
    .unwrap();
    s
}

/// Start configuration: the y joints bend the chain by about 2 rad in all, the z joints
/// twist it by up to ±0.6 rad in all (a curved, twisted arm away from singularities).
pub fn start_configuration(n: usize) -> Vec<f64> {
    let half = (n / 2) as f64;
    (0..n)
        .map(|k| {
            let x = k as f64;
            if k % 2 == 1 {
                2.0 / half * (1.0 + 0.3 * (1.7 * x).cos())
            } else {
                0.6 / half * (1.3 * x + 0.4).sin()
            }
        })
        .collect()
}

fn diag(n: usize, v: f64) -> DMatrix<f64> {
    DMatrix::from_diagonal_element(n, n, v)
}

/// The hierarchy of the table in the module docs, goals a few cm / a few 0.1 rad away
/// from the start, each level's gains scaled down to what the 1 kHz loop carries
/// at `q0` ([`carried_by_the_rate`]: the light distal links of the longer chains
/// take less than the nominal gains).
pub fn chain_spec(model: &Model, q0: &[f64]) -> ControllerSpec {
    carried_by_the_rate(model, nominal_spec(model, q0), q0)
}

/// `spec` with each level's stiffness and damping scaled down (by 0.9 of the
/// factor the rate check names, until it passes) to what the control rate
/// carries at `q0` (`hcc_control::rate`); unchanged where they are carried.
fn carried_by_the_rate(model: &Model, spec: ControllerSpec, q0: &[f64]) -> ControllerSpec {
    let q0 = DVector::from_column_slice(q0);
    // A controller with gains far below the bounds, only to check the real ones.
    let mut soft = spec.clone();
    for l in &mut soft.levels {
        l.stiffness *= 1e-6;
        l.damping *= 1e-6;
    }
    let mut c = hcc_control::Controller::new(model, soft, &q0).expect("the chain's hierarchy");
    let mut spec = spec;
    for (i, l) in spec.levels.iter_mut().enumerate() {
        while let Err(e) = c.check_gain_rate(i, Some(&l.stiffness), Some(&l.damping)) {
            let gain = if e.damping {
                &mut l.damping
            } else {
                &mut l.stiffness
            };
            *gain *= 0.9 * e.scale();
        }
    }
    spec
}

fn nominal_spec(model: &Model, q0: &[f64]) -> ControllerSpec {
    let n = model.nq();
    let tcp = model.frame_id("tcp").expect("tcp frame");
    let mut data = hcc_model::Data::new(model);
    hcc_model::forward_kinematics(model, &mut data, &DVector::from_column_slice(q0));
    let pose = hcc_model::frame_placement(model, &data, tcp);
    let p = pose.translation.vector;
    let (roll, pitch, yaw) = pose.rotation.euler_angles();
    let position = |axes: Vec<usize>| {
        let goal = axes
            .iter()
            .map(|&a| p[a] + [0.05, -0.03, 0.04][a])
            .collect();
        let m = axes.len();
        LevelSpec {
            name: "tcp position".into(),
            tasks: vec![TaskSpec::Position { frame: tcp, axes }],
            stiffness: diag(m, 800.0),
            damping: diag(m, 60.0),
            goal: DVector::from_vec(goal),
        }
    };
    let joints = |indices: Vec<usize>| {
        let m = indices.len();
        let goal = indices.iter().map(|&k| q0[k] + 0.1).collect();
        LevelSpec {
            name: "joints".into(),
            tasks: vec![TaskSpec::Joints { indices }],
            stiffness: diag(m, 50.0),
            damping: diag(m, 5.0),
            goal: DVector::from_vec(goal),
        }
    };
    let posture = LevelSpec {
        name: "posture".into(),
        tasks: vec![TaskSpec::Posture],
        stiffness: diag(n, 20.0),
        damping: diag(n, 2.0),
        goal: DVector::from_column_slice(q0),
    };
    let levels = if n < 7 {
        vec![position(vec![0, 2]), joints(vec![0]), posture]
    } else {
        let orientation = LevelSpec {
            name: "tcp orientation".into(),
            tasks: vec![TaskSpec::Orientation { frame: tcp }],
            stiffness: diag(3, 60.0),
            damping: diag(3, 4.0),
            goal: DVector::from_vec(vec![roll + 0.2, pitch - 0.1, yaw + 0.3]),
        };
        let mut l = vec![position(vec![0, 1, 2]), orientation];
        if n > 7 {
            l.push(joints((0..n).step_by(4).collect()));
        }
        l.push(posture);
        l
    };
    ControllerSpec::new(levels)
}
