//! The control cycle allocates nothing after construction: a counting global
//! allocator over 10 000 steps of the Panda's three-level hierarchy.

mod common;
use common::*;
use hcc_control::Controller;
use nalgebra::DVector;

/// Counts the allocations of each thread (`hcc_rtalloc::thread_stats`), so the
/// test harness's own threads never disturb the count.
#[global_allocator]
static GLOBAL: hcc_rtalloc::RtAllocator = hcc_rtalloc::RtAllocator::new();

#[test]
fn ten_thousand_panda_steps_allocate_nothing() {
    let model = panda();
    let q0 = vec![0.0, -0.3, 0.0, -2.2, 0.0, 2.0, 0.8];
    let mut c = Controller::new(&model, panda_spec(&model), &DVector::from_vec(q0.clone()))
        .expect("controller");
    let mut q = q0.clone();
    let qd = vec![0.1, -0.2, 0.15, 0.1, -0.3, 0.2, 0.25];
    let mut bad = [0.0; 7];
    bad[3] = f64::NAN;
    c.step(&q, &qd).expect("warm-up");
    let k_new = nalgebra::DMatrix::from_diagonal_element(3, 3, 70.0);
    let d_new = nalgebra::DMatrix::from_diagonal_element(3, 3, 5.0);
    let mut k_step = k_new.clone();
    let before = hcc_rtalloc::thread_stats().allocs;
    let mut sum = 0.0;
    for k in 0..10_000 {
        for (qi, vi) in q.iter_mut().zip(&qd) {
            *qi += 1e-4 * vi;
        }
        let out = c.step(&q, &qd).expect("step");
        sum += out.tau[0];
        if k % 1000 == 0 {
            // The rejection path must not allocate either.
            assert!(c.step(&bad, &qd).is_err());
            c.set_goal(0, &[0.4, 0.1, 0.5]).expect("goal");
            c.set_goal_velocity(0, &[0.01, 0.0, -0.01])
                .expect("velocity");
            c.set_gains(1, Some(&k_new), Some(&d_new)).expect("gains");
        }
        if k % 1000 == 500 {
            // A gains transition's step, booked through the tanks.
            k_step.copy_from(&k_new);
            k_step *= 1.0 + 1e-3 * (k / 1000) as f64;
            c.ramp_gains(1, Some(&k_step), None).expect("gains");
            // A goal transition's grant and step, paid from the command tank.
            c.grant_goal_step(0, &[0.45, 0.1, 0.5]).expect("grant");
            c.set_commands_active(true);
            c.ramp_goal(0, &[0.41, 0.1, 0.5], &[0.01, 0.0, 0.0])
                .expect("goal");
        }
        if k % 1000 == 700 {
            c.set_commands_active(false);
        }
        if k == 5000 {
            // The tracking form (docs/tracking.md) from here on: every
            // level tracks, level 1's goal moves.
            c.set_goal_acceleration(0, Some(&[0.02, 0.0, 0.01]))
                .expect("acceleration");
            c.set_goal_acceleration(1, Some(&[0.0; 3]))
                .expect("acceleration");
            c.set_goal_acceleration(2, Some(&[0.0; 7]))
                .expect("acceleration");
        }
    }
    let after = hcc_rtalloc::thread_stats().allocs;
    assert!(sum.is_finite());
    assert_eq!(
        after - before,
        0,
        "the control cycle allocated {} times",
        after - before
    );
}

/// The same for the stacked pose level (coupled 6×6 stiffness) above the posture, in
/// the extended and the kinematic projector form.
#[test]
fn pose_level_steps_allocate_nothing() {
    let model = panda();
    let q0 = vec![0.0, -0.3, 0.0, -2.2, 0.0, 2.0, 0.8];
    for form in [
        hcc_control::Form::Extended,
        hcc_control::Form::KinematicProjector,
    ] {
        let mut spec = panda_pose_spec(&model, true);
        spec.form = form;
        let mut c =
            Controller::new(&model, spec, &DVector::from_vec(q0.clone())).expect("controller");
        let mut q = q0.clone();
        let qd = vec![0.1, -0.2, 0.15, 0.1, -0.3, 0.2, 0.25];
        c.step(&q, &qd).expect("warm-up");
        let before = hcc_rtalloc::thread_stats().allocs;
        let mut sum = 0.0;
        for k in 0..2_000 {
            for (qi, vi) in q.iter_mut().zip(&qd) {
                *qi += 1e-4 * vi;
            }
            sum += c.step(&q, &qd).expect("step").tau[0];
            if k % 500 == 0 {
                c.set_goal(0, &[0.4, 0.1, 0.5, 3.0, 0.1, 0.2])
                    .expect("goal");
            }
        }
        let after = hcc_rtalloc::thread_stats().allocs;
        assert!(sum.is_finite());
        assert_eq!(
            after - before,
            0,
            "{form:?}: allocated {} times",
            after - before
        );
    }
}

#[test]
fn transitions_allocate_nothing() {
    use hcc_control::transition::{GoalKind, Target, Transition};
    use nalgebra::DMatrix;
    let k = DMatrix::from_diagonal_element(3, 3, 1.0);
    let k2 = DMatrix::from_diagonal_element(3, 3, 2.0);
    let mut t = Transition::new(GoalKind::RollPitchYaw, &[0.0; 3], &k, &k).expect("transition");
    let before = hcc_rtalloc::thread_stats().allocs;
    for j in 0..100 {
        t.start(
            Target {
                goal: Some(&[0.1, 0.2, j as f64 * 0.01]),
                stiffness: Some(&k2),
                damping: None,
            },
            0.05,
        );
        for _ in 0..10 {
            t.advance(1e-3);
        }
    }
    assert_eq!(hcc_rtalloc::thread_stats().allocs - before, 0);
    assert!(t.goal().iter().all(|x| x.is_finite()));
}

/// The discrete-time velocity limit, acting on every call (the Panda's wrist
/// driven past its limit with the other joints coupled in), allocates nothing.
#[test]
fn the_velocity_limit_acting_allocates_nothing() {
    use hcc_control::velocity_limit::PeriodModel;
    use hcc_control::{VelocityLimitWork, limit_velocity};
    let model = panda();
    let q0 = vec![0.0, -0.3, 0.0, -2.2, 0.0, 2.0, 0.8];
    let mut c = Controller::new(&model, panda_spec(&model), &DVector::from_vec(q0.clone()))
        .expect("controller");
    let qd = vec![0.4, -0.2, 0.3, 0.1, -0.5, 0.2, 2.3];
    c.step(&q0, &qd).expect("step");
    let terms = c.model_terms();
    let h = &terms.c * DVector::from_vec(qd.clone()) + &terms.g;
    let v_max: Vec<f64> = model.joints.iter().map(|j| j.velocity_limit).collect();
    let p = PeriodModel {
        m: &terms.m,
        chol: c.mass_factor(),
        h: &h,
        qd: &qd,
        v_max: &v_max,
        period_s: 1e-3,
    };
    let mut w = VelocityLimitWork::new(7);
    let before = hcc_rtalloc::thread_stats().allocs;
    let mut acted = 0;
    for k in 0..1000 {
        let mut tau = [30.0, -20.0, 10.0, 5.0, -4.0, 3.0, 5.0 + k as f64 * 1e-3];
        for (t, g) in tau.iter_mut().zip(terms.g.iter()) {
            *t += g;
        }
        acted += usize::from(limit_velocity(&p, &mut tau, &mut w).acted);
    }
    let after = hcc_rtalloc::thread_stats().allocs;
    assert_eq!(acted, 1000, "the limit did not act");
    assert_eq!(after - before, 0, "the velocity limit allocated");
}

/// The velocity limit behind a rate limit (the brake certificate), acting on
/// every call — the Panda's wrist past the bound, so every rule is simulated,
/// bisected and the fall-back chosen — allocates nothing.
#[test]
fn the_brake_certificate_acting_allocates_nothing() {
    use hcc_control::{BrakeModel, BrakeWork, limit_velocity_rate_limited};
    let model = panda();
    let q0 = vec![0.0, -0.3, 0.0, -2.2, 0.0, 2.0, 0.8];
    let mut c = Controller::new(&model, panda_spec(&model), &DVector::from_vec(q0.clone()))
        .expect("controller");
    let qd = vec![0.4, -0.2, 0.3, 0.1, -0.5, 0.2, 2.5];
    c.step(&q0, &qd).expect("step");
    let terms = c.model_terms();
    let v_max: Vec<f64> = model.joints.iter().map(|j| j.velocity_limit).collect();
    let effort: Vec<f64> = model.joints.iter().map(|j| j.effort_limit).collect();
    let previous: Vec<f64> = terms.g.iter().map(|g| g + 2.0).collect();
    let p = BrakeModel {
        m: &terms.m,
        chol: c.mass_factor(),
        c: &terms.c,
        g: &terms.g,
        qd: &qd,
        v_max: &v_max,
        period_s: 1e-3,
        previous: &previous,
        max_step: 1.0,
        effort: &effort,
    };
    let mut w = BrakeWork::new(7);
    let mut acted = 0;
    for k in 0..200 {
        let mut tau = previous.clone();
        tau[6] += 1.0 - k as f64 * 1e-4;
        let start = hcc_rtalloc::thread_stats().allocs;
        acted += usize::from(limit_velocity_rate_limited(&p, &mut tau, &mut w).acted);
        assert_eq!(
            hcc_rtalloc::thread_stats().allocs,
            start,
            "call {k} allocated"
        );
    }
    assert_eq!(acted, 200, "the certificate did not act");
}
