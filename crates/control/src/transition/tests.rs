//! The transitions' profile, shapes and clocks, against their definitions.

use super::*;
use nalgebra::{DMatrix, DVector, UnitQuaternion, Vector3};

fn rpy(v: &DVector<f64>) -> UnitQuaternion<f64> {
    rpy_at(v.as_slice(), 0)
}

#[test]
fn profile_endpoints_rest_and_clamp() {
    assert_eq!(quintic(0.0), (0.0, 0.0, 0.0));
    let (s, ds, dds) = quintic(1.0);
    assert_eq!((s, ds, dds), (1.0, 0.0, 0.0));
    assert_eq!(quintic(-3.0), (0.0, 0.0, 0.0));
    assert_eq!(quintic(7.0), (1.0, 0.0, 0.0));
    // Symmetric: s(½) = ½, peak speed 15/8 there, no acceleration.
    let (s, ds, dds) = quintic(0.5);
    assert!((s - 0.5).abs() < 1e-15 && (ds - 1.875).abs() < 1e-15 && dds.abs() < 1e-15);
    // Monotone.
    let mut last = 0.0;
    for k in 1..=1000 {
        let (s, ds, _) = quintic(k as f64 / 1000.0);
        assert!(s >= last && ds >= 0.0);
        last = s;
    }
}

#[test]
fn profile_is_c2() {
    // The derivatives are those of s (central differences), and s, s′, s″
    // are continuous across σ = 0 and σ = 1 (zero on the outside).
    let h = 1e-6;
    for k in 0..=200 {
        let x = k as f64 / 200.0;
        let (_, ds, dds) = quintic(x);
        if (h..=1.0 - h).contains(&x) {
            let num_ds = (quintic(x + h).0 - quintic(x - h).0) / (2.0 * h);
            let num_dds = (quintic(x + h).1 - quintic(x - h).1) / (2.0 * h);
            assert!((num_ds - ds).abs() < 1e-8, "s′ at {x}");
            assert!((num_dds - dds).abs() < 1e-6, "s″ at {x}");
        }
    }
    for edge in [0.0, 1.0] {
        let (a, b) = (quintic(edge - 1e-9), quintic(edge + 1e-9));
        assert!((a.0 - b.0).abs() < 1e-12);
        assert!((a.1 - b.1).abs() < 1e-12);
        assert!((a.2 - b.2).abs() < 1e-7);
    }
}

fn diag(v: &[f64]) -> DMatrix<f64> {
    DMatrix::from_diagonal(&DVector::from_column_slice(v))
}

/// A stiffness change sent while the goal moves leaves the goal's
/// motion exactly as it was; the gains reach their target on their own
/// clock, and a later goal leaves the gain transition on its way.
#[test]
fn goal_and_gains_move_on_clocks_of_their_own() {
    let k = diag(&[500.0, 500.0]);
    let d = diag(&[40.0, 40.0]);
    let goal = Target {
        goal: Some(&[0.2, 0.0]),
        ..Target::default()
    };
    let mut plain = Transition::new(GoalKind::Vector, &[0.0, 1.0], &k, &d).unwrap();
    let mut t = plain.clone();
    plain.start(goal, 1.0);
    t.start(goal, 1.0);
    let dt = 1e-3;
    for _ in 0..500 {
        plain.advance(dt);
        t.advance(dt);
    }
    let stiff = diag(&[800.0, 800.0]);
    t.start(
        Target {
            stiffness: Some(&stiff),
            ..Target::default()
        },
        0.2,
    );
    assert_eq!(t.stiffness(), &k, "no jump of K at the start");
    for step in 0..500 {
        plain.advance(dt);
        t.advance(dt);
        assert_eq!(t.goal(), plain.goal(), "goal unchanged at step {step}");
        assert_eq!(t.goal_velocity(), plain.goal_velocity());
        if step == 99 {
            let mid = t.stiffness()[(0, 0)];
            assert!((mid - 650.0).abs() < 1e-9, "K half way at σ = ½: {mid}");
            assert!(t.is_moving());
        }
    }
    assert_eq!(t.goal(), &[0.2, 0.0]);
    assert_eq!(t.stiffness(), &stiff);
    assert_eq!(t.damping(), &d);
    assert!(!t.is_moving());
    // A new goal during a gain transition: the gains go on to their target.
    let soft = diag(&[300.0, 300.0]);
    t.start(
        Target {
            stiffness: Some(&soft),
            ..Target::default()
        },
        1.0,
    );
    for _ in 0..250 {
        t.advance(dt);
    }
    let k_quarter = t.stiffness()[(0, 0)];
    t.start(
        Target {
            goal: Some(&[0.0, 0.0]),
            ..Target::default()
        },
        0.1,
    );
    assert_eq!(
        t.stiffness()[(0, 0)],
        k_quarter,
        "the gains go on from where they are"
    );
    for _ in 0..750 {
        t.advance(dt);
    }
    assert_eq!(t.stiffness(), &soft);
    assert_eq!(t.goal(), &[0.0, 0.0]);
}

#[test]
fn vector_goal_moves_smoothly_and_arrives() {
    let k = diag(&[500.0, 500.0]);
    let d = diag(&[40.0, 40.0]);
    let mut t = Transition::new(GoalKind::Vector, &[0.0, 1.0], &k, &d).unwrap();
    assert!(!t.is_moving());
    t.start(
        Target {
            goal: Some(&[0.2, 0.0]),
            ..Target::default()
        },
        2.0,
    );
    assert_eq!(t.goal(), &[0.0, 1.0], "no jump at the start");
    assert_eq!(t.goal_velocity(), &[0.0, 0.0]);
    let dt = 1e-3;
    let mut travelled = 0.0;
    let mut prev = t.goal()[0];
    for _ in 0..1000 {
        t.advance(dt);
        travelled += (t.goal()[0] - prev).abs();
        prev = t.goal()[0];
    }
    assert!((t.progress() - 0.5).abs() < 1e-12);
    assert!((t.goal()[0] - 0.1).abs() < 1e-12, "half way at σ = ½");
    // Peak speed 15/8 · Δ / T.
    assert!((t.goal_velocity()[0] - 1.875 * 0.2 / 2.0).abs() < 1e-9);
    assert!((t.goal_velocity()[1] + 1.875 * 1.0 / 2.0).abs() < 1e-9);
    for _ in 0..1500 {
        t.advance(dt);
    }
    assert!(!t.is_moving());
    assert_eq!(t.goal(), &[0.2, 0.0]);
    assert_eq!(t.goal_velocity(), &[0.0, 0.0]);
    assert!(travelled <= 0.1 + 1e-12, "monotone");
    // Zero duration: the target at once.
    t.start(
        Target {
            goal: Some(&[1.0, 1.0]),
            ..Target::default()
        },
        0.0,
    );
    assert_eq!(t.goal(), &[1.0, 1.0]);
    assert_eq!(t.progress(), 1.0);
}

#[test]
fn a_new_target_starts_from_where_the_equilibrium_is() {
    let k = diag(&[1.0]);
    let mut t = Transition::new(GoalKind::Vector, &[0.0], &k, &k).unwrap();
    t.start(
        Target {
            goal: Some(&[1.0]),
            ..Target::default()
        },
        1.0,
    );
    for _ in 0..500 {
        t.advance(1e-3);
    }
    let here = t.goal()[0];
    t.start(
        Target {
            goal: Some(&[-1.0]),
            ..Target::default()
        },
        1.0,
    );
    assert_eq!(t.goal()[0], here);
    assert_eq!(t.target_goal(), &[-1.0]);
    t.advance(1.0);
    assert_eq!(t.goal(), &[-1.0]);
}

#[test]
fn orientation_follows_the_geodesic() {
    let k = diag(&[10.0; 3]);
    let mut t = Transition::new(GoalKind::RollPitchYaw, &[0.0, 0.0, 0.0], &k, &k).unwrap();
    let yaw = std::f64::consts::FRAC_PI_2;
    t.start(
        Target {
            goal: Some(&[0.0, 0.0, yaw]),
            ..Target::default()
        },
        1.0,
    );
    t.advance(0.5);
    let g = t.goal();
    assert!(g[0].abs() < 1e-12 && g[1].abs() < 1e-12);
    assert!((g[2] - yaw / 2.0).abs() < 1e-12, "{g:?}");
    let w = t.goal_velocity();
    assert!(
        (w[2] - 1.875 * yaw).abs() < 1e-9 && w[0].abs() < 1e-12,
        "{w:?}"
    );

    // A general pair: the angle to the start grows as s·θ, on the geodesic.
    let (a, b) = ([0.3, -0.4, 1.0], [-1.2, 0.5, -2.5]);
    let mut t = Transition::new(GoalKind::RollPitchYaw, &a, &k, &k).unwrap();
    t.start(
        Target {
            goal: Some(&b),
            ..Target::default()
        },
        1.0,
    );
    let (ra, rb) = (
        rpy(&DVector::from_column_slice(&a)),
        rpy(&DVector::from_column_slice(&b)),
    );
    let theta = ra.angle_to(&rb);
    for k in 1..=10 {
        t.advance(0.1);
        let (s, _, _) = quintic(k as f64 / 10.0);
        let r = rpy(&DVector::from_column_slice(t.goal()));
        assert!((ra.angle_to(&r) - s * theta).abs() < 1e-9);
        assert!((r.angle_to(&rb) - (1.0 - s) * theta).abs() < 1e-9);
    }
    assert!(t.current_rotation().angle_to(&rb) < 1e-12);
}

#[test]
fn a_pose_moves_its_position_linearly_and_its_orientation_on_the_geodesic() {
    let k = diag(&[100.0; 6]);
    let from = [0.4, 0.0, 0.5, 3.0, -0.2, 0.1];
    let to = [0.5, 0.1, 0.3, -2.0, 0.6, -1.2];
    let mut t = Transition::new(GoalKind::Pose, &from, &k, &k).unwrap();
    t.start(
        Target {
            goal: Some(&to),
            ..Target::default()
        },
        1.0,
    );
    let (ra, rb) = (rpy_at(&from, 3), rpy_at(&to, 3));
    let theta = ra.angle_to(&rb);
    let axis = (ra.inverse() * rb).axis().unwrap();
    assert!(theta > 1.0, "a large rotation: {theta}");
    let mut last_angle = 0.0;
    let steps = 200;
    for k in 1..=steps {
        t.advance(1.0 / steps as f64);
        let (s, ds, _) = quintic(k as f64 / steps as f64);
        let g = t.goal();
        // Position rows: the straight line, at s.
        for a in 0..3 {
            assert!((g[a] - (from[a] + s * (to[a] - from[a]))).abs() < 1e-12);
            assert!((t.goal_velocity()[a] - ds * (to[a] - from[a])).abs() < 1e-9);
        }
        // Orientation rows: on the geodesic — the angle to the start grows
        // monotonically (as s·θ), the axis of R_0ᵀ R(t) stays that of R_0ᵀ R_1.
        let r = rpy_at(g, 3);
        let angle = ra.angle_to(&r);
        assert!(angle >= last_angle - 1e-12, "monotone at step {k}");
        assert!((angle - s * theta).abs() < 1e-9, "s·θ at step {k}");
        if angle > 1e-6 {
            let ax = (ra.inverse() * r).axis().unwrap();
            assert!(
                (ax.into_inner() - axis.into_inner()).norm() < 1e-9,
                "axis at step {k}"
            );
        }
        // ω_d along the world-frame axis R_0 n, of size ṡ θ.
        let w = Vector3::new(
            t.goal_velocity()[3],
            t.goal_velocity()[4],
            t.goal_velocity()[5],
        );
        let expected = ra * axis.into_inner() * (ds * theta);
        if k < steps {
            assert!((w - expected).norm() < 1e-9, "ω at step {k}: {w:?}");
        }
        last_angle = angle;
    }
    assert!(!t.is_moving());
    assert_eq!(t.goal(), &to, "at rest on the target as sent");
    assert_eq!(t.goal_velocity(), &[0.0; 6]);
    // The distance for the speed limit: √(|Δp|² + θ²).
    let back = t.distance_to(&from);
    let dp: f64 = (0..3).map(|a| (to[a] - from[a]).powi(2)).sum();
    assert!((back - (dp + theta * theta).sqrt()).abs() < 1e-9);
    let e = Transition::new(
        GoalKind::Pose,
        &[0.0; 3],
        &diag(&[1.0; 3]),
        &diag(&[1.0; 3]),
    )
    .unwrap_err();
    assert!(e.to_string().contains("6 values"), "{e}");
}

#[test]
fn bad_sizes_are_errors() {
    let k = diag(&[1.0; 2]);
    let e = Transition::new(GoalKind::RollPitchYaw, &[0.0; 2], &k, &k).unwrap_err();
    assert!(e.to_string().contains("3 values"), "{e}");
    let e = Transition::new(GoalKind::Vector, &[0.0; 3], &k, &k).unwrap_err();
    assert!(e.to_string().contains("2×2"), "{e}");
    let e = Transition::new(GoalKind::Vector, &[f64::NAN; 2], &k, &k).unwrap_err();
    assert!(e.to_string().contains("non-finite"), "{e}");
}

#[test]
fn gains_stay_symmetric_positive_definite() {
    // Two SPD matrices with very different eigenvectors.
    let k0 = DMatrix::from_row_slice(3, 3, &[900.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0]);
    let k1 = DMatrix::from_row_slice(3, 3, &[2.0, 1.9, 0.0, 1.9, 2.0, 0.0, 0.0, 0.0, 500.0]);
    let d = diag(&[1.0; 3]);
    let mut t = Transition::new(GoalKind::Vector, &[0.0; 3], &k0, &d).unwrap();
    t.start(
        Target {
            stiffness: Some(&k1),
            ..Target::default()
        },
        1.0,
    );
    for _ in 0..=100 {
        let k = t.stiffness();
        assert!((k - k.transpose()).amax() == 0.0, "symmetric");
        let min = k.clone().symmetric_eigenvalues().min();
        assert!(min > 0.0, "SPD, λ_min = {min}");
        assert_eq!(t.goal(), &[0.0; 3], "the goal stays");
        t.advance(0.01);
    }
    assert_eq!(t.stiffness(), &k1);
    assert_eq!(t.damping(), &d);
}

#[test]
fn a_rewound_clock_takes_its_step_again() {
    // The goal's clock and the gains' rewind on their own: the law could
    // not take a step (its tanks could not pay it), so the same step comes
    // again in the next cycle.
    let k = DMatrix::from_diagonal_element(2, 2, 100.0);
    let d = DMatrix::from_diagonal_element(2, 2, 10.0);
    let mut t = Transition::new(GoalKind::Vector, &[0.0, 0.0], &k, &d).unwrap();
    let k1 = DMatrix::from_diagonal_element(2, 2, 200.0);
    t.start(
        Target {
            goal: Some(&[1.0, 0.0]),
            stiffness: Some(&k1),
            damping: None,
        },
        1.0,
    );
    t.advance(0.1);
    let (goal, clock, gains) = (t.goal().to_vec(), t.goal_elapsed(), t.gain_elapsed());
    let stiffness = t.stiffness().clone();
    t.advance(0.1);
    t.rewind_goal(clock);
    assert_eq!(t.goal(), goal.as_slice());
    assert_eq!(t.goal_elapsed(), clock);
    // The gains' clock ran on.
    assert!((t.gain_elapsed() - 0.2).abs() < 1e-12);
    t.rewind_gains(gains);
    assert_eq!(t.stiffness(), &stiffness);
    // Clamped to the transition; a NaN is ignored.
    t.rewind_goal(-5.0);
    assert_eq!(t.goal_elapsed(), 0.0);
    assert_eq!(t.goal(), &[0.0, 0.0]);
    t.rewind_goal(f64::NAN);
    assert_eq!(t.goal_elapsed(), 0.0);
}
