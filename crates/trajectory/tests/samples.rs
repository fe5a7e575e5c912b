//! A stream of samples (knots with their velocity and acceleration,
//! `PathStream::push_sample`): the path passes through every sample with
//! exactly its derivatives, an orientation's ω and ω̇ included, needs one
//! sample ahead, and a stream that stops comes to rest on its last sample
//! without a velocity step.

use hcc_trajectory::{Block, PathStream, StreamState};
use nalgebra::{UnitQuaternion, Vector3};

const DT: f64 = 1e-3;

/// A TCP on a 5 cm circle (0.25 Hz) and its exact derivatives.
fn circle(t: f64) -> ([f64; 3], [f64; 3], [f64; 3]) {
    let w = 2.0 * std::f64::consts::PI * 0.25;
    let (s, c) = (w * t).sin_cos();
    (
        [0.4, 0.05 * s, 0.4 + 0.05 * c],
        [0.0, 0.05 * w * c, -0.05 * w * s],
        [0.0, -0.05 * w * w * s, -0.05 * w * w * c],
    )
}

/// An orientation turning about a fixed axis with a growing rate,
/// R(t) = R₀ exp(θ(t) n) with θ = 0.3 t + 0.2 t²: q, ω = θ̇ R₀n,
/// ω̇ = θ̈ R₀n (base frame).
fn turning(t: f64) -> ([f64; 4], [f64; 3], [f64; 3]) {
    let r0 = UnitQuaternion::from_euler_angles(0.2, -0.4, 1.0);
    let n = Vector3::new(1.0, 2.0, -0.5).normalize();
    let (theta, rate, accel) = (0.3 * t + 0.2 * t * t, 0.3 + 0.4 * t, 0.4);
    let q = r0 * UnitQuaternion::from_scaled_axis(n * theta);
    let axis = r0 * n;
    (
        [q.w, q.i, q.j, q.k],
        (axis * rate).into(),
        (axis * accel).into(),
    )
}

#[test]
fn samples_one_ahead_are_passed_with_their_own_derivatives() {
    let mut p = PathStream::new(&[Block::Vector(3)], 8, 1.0);
    let mut out = p.sample_buffer();
    let mut worst = [0.0_f64; 3];
    let mut between = 0.0_f64;
    // Each sample is pushed one control period before the path reaches it.
    let (x, v, a) = circle(0.0);
    p.push_sample(0.0, &x, &v, &a).unwrap();
    for step in 0..2000 {
        let t = step as f64 * DT;
        let (x, v, a) = circle(t + DT);
        p.push_sample(t + DT, &x, &v, &a).unwrap();
        p.sample(t, &mut out);
        let (x, v, a) = circle(t);
        let got = [&out.goal, &out.velocity, &out.acceleration];
        for (e, (got, want)) in worst.iter_mut().zip(got.iter().zip([x, v, a])) {
            *e = got
                .iter()
                .zip(want)
                .fold(*e, |m, (g, w)| m.max((g - w).abs()));
        }
        // Half-way between two samples: the quintic's error is O(h⁶).
        p.sample(t + 0.5 * DT, &mut out);
        let (x, _, _) = circle(t + 0.5 * DT);
        between = out
            .goal
            .iter()
            .zip(x)
            .fold(between, |m, (g, w)| m.max((g - w).abs()));
    }
    println!(
        "samples: at the samples {:.1e} m, {:.1e} m/s, {:.1e} m/s²; between them {between:.1e} m",
        worst[0], worst[1], worst[2]
    );
    assert!(
        worst.iter().all(|e| *e < 1e-12),
        "position, velocity, acceleration at the samples: {worst:?}"
    );
    assert!(between < 1e-12, "between the samples: {between}");
    assert_eq!(p.state(2.0), StreamState::Running);
}

#[test]
fn an_orientation_s_samples_give_back_their_angular_velocity_and_acceleration() {
    let mut p = PathStream::new(&[Block::Rotation], 8, 1.0);
    let mut out = p.sample_buffer();
    let (q, w, wd) = turning(0.0);
    p.push_sample(0.0, &q, &w, &wd).unwrap();
    let mut worst = [0.0_f64; 3];
    for step in 0..1500 {
        let t = step as f64 * 2.0 * DT;
        let (q, w, wd) = turning(t + 2.0 * DT);
        p.push_sample(t + 2.0 * DT, &q, &w, &wd).unwrap();
        p.sample(t, &mut out);
        let (q, w, wd) = turning(t);
        let want =
            UnitQuaternion::from_quaternion(nalgebra::Quaternion::new(q[0], q[1], q[2], q[3]));
        let got = UnitQuaternion::from_euler_angles(out.goal[0], out.goal[1], out.goal[2]);
        worst[0] = worst[0].max(got.angle_to(&want));
        for i in 0..3 {
            worst[1] = worst[1].max((out.velocity[i] - w[i]).abs());
            worst[2] = worst[2].max((out.acceleration[i] - wd[i]).abs());
        }
    }
    println!(
        "orientation samples: angle {:.1e} rad, ω {:.1e}, ω̇ {:.1e}",
        worst[0], worst[1], worst[2]
    );
    assert!(
        worst[0] < 1e-12 && worst[1] < 1e-10 && worst[2] < 1e-8,
        "{worst:?}"
    );
}

#[test]
fn a_stream_of_samples_that_stops_rests_on_its_last_sample_without_a_step() {
    let mut p = PathStream::new(&[Block::Vector(3)], 8, 1.0);
    let mut out = p.sample_buffer();
    let mut trace = Vec::new();
    let last_t = 0.6;
    for step in 0..4000 {
        let t = step as f64 * DT;
        // The device stops sending after 0.6 s.
        if t + DT <= last_t + 1e-9 || step == 0 {
            if step == 0 {
                let (x, v, a) = circle(0.0);
                p.push_sample(0.0, &x, &v, &a).unwrap();
            }
            let (x, v, a) = circle(t + DT);
            p.push_sample(t + DT, &x, &v, &a).unwrap();
        }
        p.sample(t, &mut out);
        trace.push(out.clone());
    }
    assert_eq!(p.state(4.0), StreamState::Done);
    let (x_last, _, _) = circle(last_t);
    let end = trace.last().unwrap();
    assert!(
        (0..3).all(|i| (end.goal[i] - x_last[i]).abs() < 1e-12),
        "{end:?} vs {x_last:?}"
    );
    assert_eq!(end.velocity, vec![0.0; 3]);
    let (mut dv, mut acc) = (0.0_f64, 0.0_f64);
    for w in trace.windows(2) {
        for i in 0..3 {
            dv = dv.max((w[1].velocity[i] - w[0].velocity[i]).abs());
            acc = acc.max(w[1].acceleration[i].abs());
        }
    }
    println!(
        "stopped samples: largest velocity step per ms {dv:.2e}, largest acceleration {acc:.3}"
    );
    // The circle's own acceleration is 0.12 m/s²; the stop's about 1 m/s².
    assert!(dv < 2e-3 && acc < 1.5, "{dv} {acc}");
    let (x, _, _) = circle(last_t + DT);
    assert!(
        p.push_sample(last_t + 2.0, &x, &[0.0; 3], &[0.0; 3])
            .is_err()
    );
}

#[test]
fn a_path_of_one_knot_that_time_has_passed_is_over() {
    let mut p = PathStream::new(&[Block::Vector(1)], 8, 1.0);
    let mut out = p.sample_buffer();
    p.push(0.0, &[0.3]).unwrap();
    p.sample(0.0, &mut out);
    assert_eq!(p.state(0.0), StreamState::Running);
    p.sample(0.01, &mut out);
    assert_eq!(out.goal, vec![0.3]);
    assert_eq!(out.velocity, vec![0.0]);
    assert_eq!(p.state(0.01), StreamState::Done);
    assert!(p.push(0.5, &[0.31]).is_err());
}
