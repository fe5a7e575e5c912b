//! Reading, refusals and the sampled rates of a path.

use super::*;

fn pose_text() -> String {
    let mut s = String::from("t,x,y,z,qw,qx,qy,qz\n");
    for k in 0..=20 {
        let t = k as f64 * 0.1;
        let q = UnitQuaternion::from_euler_angles(3.0, 0.2 * (2.0 * t).sin(), 0.5 * t);
        let c = q.coords; // x y z w
        s += &format!(
            "{t},{},{},{},{},{},{},{}\n",
            0.4 + 0.1 * t,
            0.05 * (3.0 * t).sin(),
            0.5,
            c[3],
            c[0],
            c[1],
            c[2]
        );
    }
    s
}

const POSE: [Block; 2] = [Block::Vector(3), Block::Rotation];

#[test]
fn refusals_name_the_row_and_the_reason() {
    let cases = [
        ("t,x\n0,1\n0.5,2\n0.5,3\n", 4, "does not increase"),
        ("t,x\n0,1\n1,NaN\n", 3, "not finite"),
        ("t,x\n0,1\n1,abc\n", 3, "not a number"),
        ("t,x\n0,1\n1,2,3\n", 3, "3 columns, expected 2"),
        ("0,1\n1,2\n", 1, "header"),
        ("t,x\n0.1,1\n", 2, "t = 0"),
        ("t,x,y\n0,1,2\n", 1, "header has 3 columns"),
    ];
    for (text, row, reason) in cases {
        let e = Trajectory::parse(text, &[Block::Vector(1)]).expect_err(text);
        assert_eq!(e.row, row, "{text}: {e}");
        assert!(e.to_string().contains(reason), "{text}: {e}");
    }
    let e = Trajectory::parse("t,w,x,y,z\n0,1,0,0,0\n1,0.5,0,0,0\n", &[Block::Rotation])
        .expect_err("not unit");
    assert!(e.row == 3 && e.reason.contains("unit quaternion"), "{e}");
    let e = Trajectory::parse("t,w,x,y,z\n0,1,0,0,0\n1,0,0,0,1\n", &[Block::Rotation])
        .expect_err("half a turn");
    assert!(e.row == 3 && e.reason.contains("split the path"), "{e}");
    let e = Trajectory::parse("t,x\n", &[Block::Vector(1)]).expect_err("empty");
    assert!(e.reason.contains("no rows"), "{e}");
}

#[test]
fn a_pose_path_passes_its_rows_with_so3_rates_and_holds_at_rest() {
    let path = Trajectory::parse(&pose_text(), &POSE).expect("pose path");
    assert_eq!(
        (path.rows(), path.duration(), path.first_line()),
        (21, 2.0, 2)
    );
    let mut s = path.sample_buffer();
    let rot = |s: &PathSample| UnitQuaternion::from_euler_angles(s.goal[3], s.goal[4], s.goal[5]);
    // The rows themselves.
    path.sample(0.7, &mut s);
    let want = UnitQuaternion::from_euler_angles(3.0, 0.2 * 1.4f64.sin(), 0.35);
    assert!(rot(&s).angle_to(&want) < 1e-12);
    assert!((s.goal[0] - 0.47).abs() < 1e-12);
    // ω and ω̇ are the derivatives of the sampled rotation (world frame).
    let h = 1e-5;
    let mut a = path.sample_buffer();
    let mut b = path.sample_buffer();
    for k in 1..199 {
        let t = k as f64 * 0.0101;
        path.sample(t, &mut s);
        path.sample(t + h, &mut a);
        path.sample(t - h, &mut b);
        let fd_w = (rot(&a) * rot(&b).inverse()).scaled_axis() / (2.0 * h);
        let w = Vector3::from_column_slice(&s.velocity[3..6]);
        assert!((w - fd_w).norm() < 1e-6, "ω at {t}: {w} vs {fd_w}");
        let fd_wd = (Vector3::from_column_slice(&a.velocity[3..6])
            - Vector3::from_column_slice(&b.velocity[3..6]))
            / (2.0 * h);
        let wd = Vector3::from_column_slice(&s.acceleration[3..6]);
        assert!((wd - fd_wd).norm() < 1e-4, "ω̇ at {t}");
        let fd_v = (a.goal[1] - b.goal[1]) / (2.0 * h);
        assert!((s.velocity[1] - fd_v).abs() < 1e-6, "ẏ at {t}");
    }
    // Rest at both ends and after: velocity and acceleration zero, continuous.
    for t in [0.0, 2.0, 3.0] {
        path.sample(t, &mut s);
        assert!(
            s.velocity
                .iter()
                .chain(&s.acceleration)
                .all(|x| x.abs() < 1e-9),
            "t = {t}"
        );
    }
    path.sample(2.0 - 1e-9, &mut a);
    path.sample(2.5, &mut b);
    assert!(rot(&a).angle_to(&rot(&b)) < 1e-9 && (a.goal[0] - b.goal[0]).abs() < 1e-9);
}

#[test]
fn a_single_row_is_held() {
    let path = Trajectory::parse("t,q1,q2\n0,0.1,-0.2\n", &[Block::Vector(2)]).expect("hold");
    let mut s = path.sample_buffer();
    path.sample(0.5, &mut s);
    assert_eq!(s.goal, vec![0.1, -0.2]);
    assert_eq!(s.velocity, vec![0.0; 2]);
}
