//! The control cycle allocates nothing — not even from the real-time pool —
//! through valid states, NaN states, duplicates, steps backwards, stale
//! timeouts and a setpoint every cycle (accepted, queued and rejected ones),
//! with the torque filter on, and the contact observer estimating and
//! flagging contacts (low thresholds: the states' q̇ = 0 while q moves is an
//! "external torque" to it, and every rejected state resets it) — with each
//! contact reaction (`report`, `soften`, `hold`: the reaction acts within the
//! counted window). Counted by `RtAllocator`, this test binary's global
//! allocator.

use std::path::PathBuf;

use hcc_config::Scenario;
use hcc_control::Controller;
use hcc_cycle::{Answer, ControlCycle, CycleSettings};
use hcc_msgs::{CommandMode, JointState, PATH_EXTEND, PATH_NEW, PathKnots, Setpoint};
use hcc_rtalloc::{RtAllocator, RtSection, thread_stats};
use hcc_spec::contact::Reaction;

#[global_allocator]
static ALLOCATOR: RtAllocator = RtAllocator::new();

const WARM_UP: u64 = 3_000;

fn scenario() -> Scenario {
    let path = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../config/paper-sim1.toml");
    Scenario::load(&path).unwrap()
}

#[test]
fn the_cycle_allocates_nothing() {
    for reaction in [Reaction::Report, Reaction::Soften, Reaction::Hold] {
        allocates_nothing_with(reaction);
    }
}

fn allocates_nothing_with(reaction: Reaction) {
    let scenario = scenario();
    let n = scenario.model.nq();
    let controller = Controller::new(&scenario.model, scenario.spec.clone(), &scenario.q0).unwrap();
    // With the whole torque filter on (rate limit and low-pass).
    let mut settings = CycleSettings::from_scenario(&scenario);
    settings.torque_filter.torque_rate_limit = Some(10.0);
    settings.torque_filter.low_pass_hz = Some(100.0);
    settings.contact.threshold.fill(0.05);
    settings.contact.reaction = reaction;
    settings.contact.ramp_s = 0.005;
    let mut cycle = ControlCycle::new(controller, &settings).unwrap();
    let q0: Vec<f64> = scenario.q0.iter().copied().collect();
    let mut states = Vec::new();
    for k in 0..2 * WARM_UP {
        let mut s = JointState::zeroed();
        let q: Vec<f64> = q0
            .iter()
            .map(|q| q + 0.05 * (k as f64 * 1e-3).sin())
            .collect();
        s.set_joints(&q, &vec![0.0; n], &vec![0.0; n]).unwrap();
        s.header.seq = k;
        match k % 97 {
            // A NaN, a duplicate, a step backwards: the safe command or no answer.
            13 => s.q[0] = f64::NAN,
            29 => s.header.seq = k - 1,
            61 => s.header.seq = k / 2,
            _ => {}
        }
        states.push(s);
    }
    // A setpoint every cycle (prepared beforehand): goals along a small
    // circle, gain changes, full matrices, and rejected ones (NaN, not SPD,
    // unknown level).
    let setpoints: Vec<Setpoint> = (0..2 * WARM_UP)
        .map(|k| {
            let phase = k as f64 * 1e-3;
            let goal = [0.90 + 0.02 * phase.sin(), 0.80 + 0.02 * phase.cos()];
            let mut sp = Setpoint::for_level(k % 3 + 1, k, 0, 2)
                .with_goal(&goal)
                .unwrap()
                .with_velocity(&[0.02 * phase.cos(), -0.02 * phase.sin()])
                .unwrap()
                .with_duration(0.01);
            if k.is_multiple_of(5) {
                // Due two states later: through the queue of waiting setpoints.
                sp = sp.with_apply_at(k + 2);
            }
            match k % 7 {
                1 => sp = sp.with_stiffness(&[1000.0, 10.0, 10.0, 900.0]).unwrap(),
                2 => sp.goal[0] = f64::NAN,
                3 => sp = sp.with_damping(&[40.0, -1.0]).unwrap(),
                4 => sp.level = 6,
                _ => {}
            }
            sp
        })
        .collect();
    let step = |cycle: &mut ControlCycle, k: u64| {
        if k % 500 == 499 {
            cycle.stale(k * 1_000_000);
        }
        let mut setpoint = Some(setpoints[k as usize]);
        // A path sent at run time (docs/tracking.md): begun from level 1's
        // equilibrium, extended by samples (with their derivatives), and a
        // refused extension (back in time).
        if k % 250 == 100 || k % 250 == 150 || k % 250 == 160 {
            let g = &cycle.telemetry().goal[0];
            let (x, y) = (g[0], g[1]);
            let mut knots = PathKnots::zeroed();
            let (flags, t0) = match k % 250 {
                100 => (PATH_NEW, 0.0),
                150 => (PATH_EXTEND, 0.4),
                _ => (PATH_EXTEND, 0.1),
            };
            knots.flags = flags;
            for j in 0..8 {
                let (t, p) = (t0 + 0.02 * j as f64, [x + 1e-4 * j as f64, y]);
                let _ = if k % 250 == 150 {
                    knots.push_sample(t, &p, &[5e-3, 0.0], &[0.0, 0.0])
                } else {
                    knots.push(t, &p)
                };
            }
            // As the daemon hands them on: every message of the cycle.
            let mut once = Some(knots);
            cycle.take_paths(|| once.take());
        }
        let answer = cycle.step(&states[k as usize], k * 1_000_000, || setpoint.take());
        let code = cycle
            .telemetry()
            .answer_for(setpoints[k as usize].client_id)
            .map_or(0, |a| a.code);
        (answer, code)
    };
    let rt = RtSection::enter();
    for k in 0..WARM_UP {
        step(&mut cycle, k);
    }
    let before = thread_stats();
    let mut answers = [0u64; 2];
    let mut setpoint_answers = [0u64; 2];
    let mut reacted = 0.0_f64;
    for k in WARM_UP..2 * WARM_UP {
        let (answer, code) = step(&mut cycle, k);
        reacted = reacted.max(cycle.reaction_level().0);
        setpoint_answers[usize::from(code != 0)] += 1;
        match answer {
            Answer::Command(CommandMode::SafeHold) => answers[1] += 1,
            Answer::Command(_) => answers[0] += 1,
            Answer::Duplicate => {}
        }
    }
    let during = thread_stats().since(before);
    drop(rt);
    println!(
        "cycle ({reaction:?}), {WARM_UP} states (normal, safe hold): {answers:?}; \
         largest reaction level {reacted:.2}; {during:?}"
    );
    assert_eq!(reacted > 0.0, reaction != Reaction::Report, "{reacted}");
    assert!(answers[0] > 0 && answers[1] > 0, "{answers:?}");
    let c = cycle.counters().telemetry;
    assert!(c.rate_limited > 0 && c.low_passed > 0, "{c:?}");
    // The observer ran and the detector flagged contacts and released them.
    let core = cycle.counters().core;
    assert!(core.contact_events > 1, "{core:?}");
    assert!(
        core.contact_cycles > 0 && core.contact_cycles < c.cycles,
        "{core:?}"
    );
    assert!(cycle.external_torque().iter().any(|r| *r != 0.0));
    // And the wrench at the position level's frame from it.
    assert_eq!(cycle.wrench_level(), Some(0));
    assert!(cycle.external_wrench().iter().any(|f| *f != 0.0));
    // Setpoints accepted and rejected, every cycle.
    assert!(
        setpoint_answers[0] > 0 && setpoint_answers[1] > 0,
        "{setpoint_answers:?}"
    );
    assert_eq!(during.pool_allocs, 0, "{during:?}");
    assert_eq!(during.system_allocs, 0, "{during:?}");
    assert_eq!(during.fallbacks, 0, "{during:?}");
}

/// A driver that adds gravity itself (the FR3 scenario) and loads told
/// every 200 cycles, ramped over 0.05 s and taken off again: the model's
/// load, its ramp and the load's own gravity torque in the command allocate
/// nothing.
#[test]
fn loads_and_their_gravity_allocate_nothing() {
    let path = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../config/fr3-pose-posture.toml");
    let scenario = Scenario::load(&path).unwrap();
    assert!(!scenario.spec.gravity_compensation);
    let n = scenario.model.nq();
    let controller = Controller::new(&scenario.model, scenario.spec.clone(), &scenario.q0).unwrap();
    let mut cycle =
        ControlCycle::new(controller, &CycleSettings::from_scenario(&scenario)).unwrap();
    let q0: Vec<f64> = scenario.q0.iter().copied().collect();
    let states: Vec<JointState> = (0..2 * WARM_UP)
        .map(|k| {
            let mut s = JointState::zeroed();
            let q: Vec<f64> = q0
                .iter()
                .map(|q| q + 0.02 * (k as f64 * 1e-3).sin())
                .collect();
            s.set_joints(&q, &vec![0.0; n], &vec![0.0; n]).unwrap();
            s.header.seq = k + 1;
            s.flags |= hcc_msgs::STATE_FLAG_DRIVER_GRAVITY_COMPENSATION;
            s
        })
        .collect();
    let loads: Vec<hcc_msgs::LoadSetpoint> = (0..2 * WARM_UP / 200)
        .map(|j| {
            let mass = if j.is_multiple_of(2) {
                1.0 + 0.1 * j as f64
            } else {
                0.0
            };
            let mut l = hcc_msgs::LoadSetpoint::point(5, j + 1, mass, [0.0, 0.01, 0.1]);
            l.ramp_s = 0.05;
            l
        })
        .collect();
    let step = |cycle: &mut ControlCycle, k: u64| {
        if k.is_multiple_of(200) {
            assert_eq!(cycle.take_load(&loads[(k / 200) as usize]), 0);
        }
        cycle.decide(&states[k as usize], (k + 1) * 1_000_000)
    };
    let rt = RtSection::enter();
    for k in 0..WARM_UP {
        step(&mut cycle, k);
    }
    let before = thread_stats();
    let mut carried = 0.0_f64;
    for k in WARM_UP..2 * WARM_UP {
        step(&mut cycle, k);
        let g = &cycle.telemetry().tau_gravity[..n];
        carried = carried.max(g.iter().fold(0.0, |m, x| m.max(x.abs())));
    }
    let during = thread_stats().since(before);
    drop(rt);
    println!(
        "loads with the driver adding gravity: the load's torque up to {carried:.3} N·m; {during:?}"
    );
    assert!(carried > 1.0, "{carried}");
    assert_eq!(during.pool_allocs, 0, "{during:?}");
    assert_eq!(during.system_allocs, 0, "{during:?}");
    assert_eq!(during.fallbacks, 0, "{during:?}");
}
