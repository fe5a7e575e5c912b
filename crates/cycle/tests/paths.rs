//! A level that follows a path (a scenario's `trajectory`) and a goal
//! setpoint for it: the newest command wins. The setpoint's transition
//! starts from where the path is (no jump of the equilibrium), the path
//! stops driving the level, and the level ends at the setpoint's goal.

mod common;

use std::path::PathBuf;

use hcc_config::Scenario;
use hcc_cycle::{ControlCycle, CycleSettings};
use hcc_msgs::{ANSWER_ACCEPTED, JointState, Setpoint};
use hcc_plant::zoh::{LoopTiming, run_zoh};

/// The shipped scenario `name` and its control cycle.
fn cycle_of(name: &str) -> (Scenario, ControlCycle) {
    cycle_with(name, true)
}

/// [`cycle_of`], the tracking feed-forward off for every level when not
/// `feed_forward` (a path then pulls its level's goal along).
fn cycle_with(name: &str, feed_forward: bool) -> (Scenario, ControlCycle) {
    let path = PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("../../config")
        .join(format!("{name}.toml"));
    let sc = Scenario::load(&path).unwrap();
    let c = hcc_cycle::controller_for(&sc).unwrap();
    let mut settings = CycleSettings::from_scenario(&sc);
    if !feed_forward {
        settings.tracking.feed_forward = vec![false; c.levels()];
    }
    let d = ControlCycle::new(c, &settings).unwrap();
    (sc, d)
}

#[test]
fn a_goal_setpoint_takes_a_path_level_over_from_where_the_path_is() {
    let (sc, mut d) = cycle_of("panda-figure-eight");
    let mut plant = hcc_plant::plant_for(&sc).unwrap();
    let n = sc.model.nq();
    let period_ns = sc.period_ns();
    let timing = LoopTiming {
        control_period_s: sc.period_s(),
        substeps: 10,
        cycles: 3000,
    };
    let (take_at, target) = (1500, [0.50, 0.02, 0.42]);
    let mut goals: Vec<[f64; 3]> = Vec::new();
    run_zoh(&mut plant, timing, |k, _t, q, qd, tau| {
        if k == take_at {
            let sp = Setpoint::for_level(5, 1, 0, 3)
                .with_goal(&target)
                .unwrap()
                .with_duration(0.5);
            assert_eq!(d.take_setpoint_now(&sp), ANSWER_ACCEPTED);
        }
        let mut s = JointState::zeroed();
        s.set_joints(q.as_slice(), qd.as_slice(), &vec![0.0; n])
            .unwrap();
        s.header.seq = k as u64 + 1;
        d.decide(&s, (k as u64 + 1) * period_ns);
        let g = &d.telemetry().goal[0];
        goals.push([g[0], g[1], g[2]]);
        tau.as_mut_slice().copy_from_slice(d.command().tau());
        Ok(())
    })
    .unwrap();
    let step = |k: usize| {
        (0..3)
            .map(|a| (goals[k + 1][a] - goals[k][a]).powi(2))
            .sum::<f64>()
            .sqrt()
    };
    // On the path the equilibrium moves at most ~0.16 m/s (0.16 mm per
    // cycle); the handover keeps that order: no jump.
    let largest = (1..goals.len() - 1).map(step).fold(0.0, f64::max);
    println!(
        "largest step of level 1's equilibrium per cycle: {largest:.3e} m; at the handover {:.3e} m",
        step(take_at - 1)
    );
    assert!(largest < 5e-4, "{largest:.3e} m");
    // The path no longer drives the level: it ends at the setpoint's goal.
    let last = goals[goals.len() - 1];
    assert!(
        (0..3).all(|a| (last[a] - target[a]).abs() < 1e-12),
        "{last:?}"
    );
}

/// A 5 cm circle in the y-z plane at 0.25 Hz through `start` (its first
/// point), its phase rising smoothly from rest over the first second: the
/// knot at t.
fn circle(start: [f64; 3], t: f64) -> [f64; 3] {
    let x = t.min(1.0);
    let phase = if t <= 1.0 {
        x.powi(6) - 3.0 * x.powi(5) + 2.5 * x.powi(4)
    } else {
        t - 0.5
    };
    let w = 2.0 * std::f64::consts::PI * 0.25;
    let (r, a) = (0.05, w * phase);
    [
        start[0],
        start[1] + r * a.sin(),
        start[2] + r * (1.0 - a.cos()),
    ]
}

/// The Panda regulating its pose (`config/panda-pose-posture.toml`); at 2 s
/// a client sends level 1 (TCP position) path messages. Per cycle from then:
/// the TCP's error to the path's desired value, the desired value, the
/// commanded torque; the answers the client saw.
struct Sent {
    err: Vec<f64>,
    desired: Vec<[f64; 3]>,
    tau: Vec<Vec<f64>>,
    start: [f64; 3],
    /// The answers' codes (each message's, or as they showed in telemetry
    /// when checked).
    codes: Vec<u32>,
    /// The answers in telemetry: (seq, code, knot) as each showed.
    answers: Vec<(u64, u32, Option<usize>)>,
    /// Messages sent, and how many the client's slot counts answered.
    sent: u64,
    answered: u64,
    stopped: u64,
    counters: hcc_cycle::CoreCounters,
    /// The worker's time per message checked, s (checked runs).
    check_s: Vec<f64>,
    /// Per cycle: the storage H at its sample, what the tanks' refill and
    /// the command tank's grant added at it, and the commands' work over
    /// the period it starts where no command tank pays it (J).
    h: Vec<f64>,
    refill: Vec<f64>,
    work: Vec<f64>,
}

/// Runs the Panda regulating its pose for 2 s, then `seconds` more: from
/// then on the messages `send(cycle_from_2s, path_start)` returns are handed
/// to the cycle before each decision — taken at once, or, `checked`, through
/// the feasibility check (its worker run between cycles).
fn run_sending(
    seconds: f64,
    checked: bool,
    send: impl FnMut(usize, [f64; 3]) -> Vec<hcc_msgs::PathKnots>,
) -> Sent {
    run_sending_with(seconds, checked, true, send)
}

/// [`run_sending`], with the tracking feed-forward or without.
fn run_sending_with(
    seconds: f64,
    checked: bool,
    feed_forward: bool,
    mut send: impl FnMut(usize, [f64; 3]) -> Vec<hcc_msgs::PathKnots>,
) -> Sent {
    let (sc, mut d) = cycle_with("panda-pose-posture", feed_forward);
    let mut worker = checked.then(|| d.check_paths_at_run_time());
    let mut plant = hcc_plant::plant_for(&sc).unwrap();
    let n = sc.model.nq();
    let period_ns = sc.period_ns();
    let send_at = 2000;
    let timing = LoopTiming {
        control_period_s: sc.period_s(),
        substeps: 10,
        cycles: send_at + (seconds * 1000.0) as usize,
    };
    let mut out = Sent {
        err: Vec::new(),
        desired: Vec::new(),
        tau: Vec::new(),
        start: [0.0; 3],
        codes: Vec::new(),
        answers: Vec::new(),
        sent: 0,
        answered: 0,
        stopped: 0,
        counters: Default::default(),
        check_s: Vec::new(),
        h: Vec::new(),
        refill: Vec::new(),
        work: Vec::new(),
    };
    run_zoh(&mut plant, timing, |k, _t, q, qd, tau| {
        let mut s = JointState::zeroed();
        s.set_joints(q.as_slice(), qd.as_slice(), &vec![0.0; n])
            .unwrap();
        s.header.seq = k as u64 + 1;
        if k == send_at {
            // From the level's equilibrium (its goal).
            let g = &d.telemetry().goal[0];
            out.start = [g[0], g[1], g[2]];
        }
        if k >= send_at {
            let msgs = send(k - send_at, out.start);
            out.sent += msgs.len() as u64;
            if checked {
                let mut msgs = msgs.into_iter();
                d.take_paths_at(&s, || msgs.next());
            } else {
                out.codes.extend(msgs.iter().map(|m| d.take_path(m)));
            }
        }
        d.decide(&s, (k as u64 + 1) * period_ns);
        if let Some(w) = worker.as_mut() {
            let began = std::time::Instant::now();
            let checked = w.run_pending();
            if checked > 0 {
                let each = began.elapsed().as_secs_f64() / checked as f64;
                out.check_s.extend(std::iter::repeat_n(each, checked));
            }
        }
        if let Some(a) = d.telemetry().answer_for(9)
            && out.answers.last().is_none_or(|l| l.0 != a.seq)
        {
            out.answers.push((a.seq, a.code, a.refused_knot()));
            out.answered = a.answered;
            if checked {
                out.codes.push(a.code);
            }
        }
        if k >= send_at {
            let t = d.telemetry();
            let e = t.task_error(0);
            out.err
                .push((e[0] * e[0] + e[1] * e[1] + e[2] * e[2]).sqrt());
            out.desired.push([t.goal[0][0], t.goal[0][1], t.goal[0][2]]);
            out.tau.push(d.command().tau().to_vec());
            let input = d.controller().output().command_input;
            out.h.push(d.storage());
            out.refill.push(input.refill + input.granted);
            out.work.push(if input.paid {
                0.0
            } else {
                sc.period_s() * (input.goal_power + input.feed_forward_power)
            });
        }
        tau.as_mut_slice().copy_from_slice(d.command().tau());
        Ok(())
    })
    .unwrap();
    out.stopped = d.counters().core.paths_stopped;
    out.counters = d.counters().core;
    out
}

/// The circle's first `knots` knots (every 20 ms), all sent at 2 s in
/// messages of 16.
impl Sent {
    /// The worker's time per message: median, 99 % and largest, ms.
    fn check_ms(&self) -> String {
        let mut t = self.check_s.clone();
        t.sort_by(f64::total_cmp);
        let at = |q: f64| t[((t.len() - 1) as f64 * q) as usize] * 1e3;
        format!(
            "check per message: median {:.3} ms, p99 {:.3} ms, max {:.3} ms ({} messages)",
            at(0.5),
            at(0.99),
            at(1.0),
            t.len()
        )
    }

    /// The largest change of a joint torque from one cycle to the next, N·m.
    fn largest_torque_step(&self) -> f64 {
        common::largest_torque_step(&self.tau)
    }

    /// How far the desired values of the first `cycles` cycles are off the
    /// circle in its plane, m.
    fn off_circle(&self, cycles: usize) -> f64 {
        self.desired[..cycles]
            .iter()
            .enumerate()
            .map(|(k, x)| {
                let c = circle(self.start, k as f64 * 1e-3);
                ((x[1] - c[1]).powi(2) + (x[2] - c[2]).powi(2)).sqrt()
            })
            .fold(0.0_f64, f64::max)
    }
}

fn send_circle(knots: usize, seconds: f64) -> Sent {
    send_circle_with(knots, seconds, true)
}

/// [`send_circle`], with the tracking feed-forward or without.
fn send_circle_with(knots: usize, seconds: f64, feed_forward: bool) -> Sent {
    use hcc_msgs::{PATH_EXTEND, PATH_NEW, PathKnots};
    run_sending_with(seconds, false, feed_forward, |k, start| {
        let mut msgs = Vec::new();
        if k > 0 {
            return msgs;
        }
        let mut msg = PathKnots::zeroed();
        for j in 0..knots {
            if msg.count() == hcc_msgs::MAX_KNOTS_PER_MESSAGE {
                msgs.push(msg);
                msg = PathKnots::zeroed();
            }
            if msg.count() == 0 {
                msg.flags = if j == 0 { PATH_NEW } else { PATH_EXTEND };
                msg.client_id = 9;
                msg.header.seq = msgs.len() as u64 + 1;
            }
            let t = j as f64 * 0.02;
            msg.push(t, &circle(start, t)).unwrap();
        }
        msgs.push(msg);
        msgs
    })
}

#[test]
fn a_circle_sent_at_run_time_is_tracked_within_a_millimetre() {
    // 5 s of knots (251, within the level's 256), sent at once.
    let s = send_circle(251, 6.0);
    assert!(s.codes.iter().all(|&c| c == 0), "answers {:?}", s.codes);
    let from = 2000; // 2 s after the path began
    let worst = s.err[from..].iter().fold(0.0_f64, |m, e| m.max(*e));
    let off_circle = s.off_circle(4900);
    println!(
        "run-time circle: largest TCP error to the path from 2 s {worst:.3e} m; the path off the \
         circle by at most {off_circle:.3e} m (knots every 20 ms)"
    );
    assert!(worst < 1e-3, "{worst:.3e} m");
    assert!(off_circle < 1e-4, "{off_circle:.3e} m");
}

impl Sent {
    /// The refill after the first cycle, the booked work (sum of |work|),
    /// and the largest rise of H from one cycle to the next beyond the
    /// input (work and refill) with its cycle.
    fn energy_figures(&self) -> (f64, f64, f64, usize) {
        let after: f64 = self.refill[1..].iter().sum();
        let (mut rise, mut at) = (f64::NEG_INFINITY, 0);
        for k in 1..self.h.len() {
            let r = self.h[k] - self.h[k - 1] - self.work[k - 1] - self.refill[k];
            if r > rise {
                (rise, at) = (r, k);
            }
        }
        let work = self.work.iter().map(|w| w.abs()).sum();
        (after, work, rise, at)
    }
}

/// A path is a command when its message is taken, not at every sample: the
/// tanks are refilled once, in the cycle that takes the circle's messages.
/// Pulled along (no feed-forward), while the TCP follows the circle H rises
/// from one cycle to the next by no more than the path's work on level 1's
/// spring and damper, the input. (Before, every sample refilled the tanks.)
/// With the tracking feed-forward as well: the levels above are meant to drag
/// the posture's spring by w_d = J_i q̇_d^{(i−1)}, which its tank does not
/// pay, and that share is an input too (unbooked, H rose by 1.1 mJ per
/// cycle as the arm followed).
#[test]
fn a_path_refills_the_tanks_once_and_its_work_is_the_input() {
    let s = send_circle_with(251, 6.0, false);
    assert!(s.codes.iter().all(|&c| c == 0), "answers {:?}", s.codes);
    let (after, work, rise, at) = s.energy_figures();
    let tracked = send_circle(251, 6.0);
    let (tracked_after, _, tracked_rise, tracked_at) = tracked.energy_figures();
    println!(
        "path, pulled along: refill {:.4} J when taken, {after:.2e} J after; |work| booked \
         {work:.3} J over {} cycles; H rose beyond the input by at most {rise:.2e} J (cycle {at}); \
         tracked: refill after {tracked_after:.2e} J, H beyond the input {tracked_rise:.2e} J \
         (cycle {tracked_at})",
        s.refill[0],
        s.h.len()
    );
    assert!(s.refill[0] > 0.0, "the message refills the tanks");
    assert_eq!(after, 0.0, "the samples refill nothing");
    assert_eq!(tracked_after, 0.0, "the samples refill nothing");
    assert!(work > 0.0, "the path's work is booked");
    assert!(
        rise < 1e-4,
        "H rose by {rise:.2e} J beyond the input at cycle {at}"
    );
    assert!(
        tracked_rise < 1e-4,
        "tracked: H rose by {tracked_rise:.2e} J beyond the input at cycle {tracked_at}"
    );
}

#[test]
fn a_stream_that_stops_mid_path_comes_to_rest_on_its_last_knot() {
    let s = send_circle(100, 4.0);
    assert!(s.codes.iter().all(|&c| c == 0), "answers {:?}", s.codes);
    assert_eq!(s.stopped, 1);
    let last = circle(s.start, 99.0 * 0.02);
    let end = s.desired[s.desired.len() - 1];
    assert!(
        (0..3).all(|a| (end[a] - last[a]).abs() < 1e-9),
        "{end:?} vs {last:?}"
    );
    let settled = s.err[s.err.len() - 1];
    // No torque step above the filter's rate (1000 N·m/s: 1 N·m per cycle).
    let step = s.largest_torque_step();
    println!(
        "stopped stream: at rest {settled:.2e} m from its last knot; largest torque step {step:.3} N·m"
    );
    assert!(settled < 1e-4 && step <= 1.0 + 1e-9, "{settled} {step}");
}

#[test]
fn knots_the_level_cannot_take_are_refused_and_change_nothing() {
    use hcc_msgs::{PATH_EXTEND, PATH_NEW, PathKnots};
    let (_, mut d) = cycle_of("panda-pose-posture");
    let goal = [0.55, 0.20, 0.30];
    let msg = |flags: u32, pts: &[(f64, [f64; 3])]| {
        let mut m = PathKnots::zeroed();
        m.flags = flags;
        for (t, p) in pts {
            m.push(*t, p).unwrap();
        }
        m
    };
    // The answer in the client's slot: the code and the knot it names.
    let answer = |d: &ControlCycle| {
        let a = d.telemetry().answer_for(0).copied().unwrap();
        (a.code, a.refused_knot())
    };
    let take = |d: &mut ControlCycle, m: &PathKnots| {
        d.take_path(m);
        answer(d)
    };
    // Extending with no path; starting away from the equilibrium; a knot
    // out of the arm's reach (the third); the wrong columns; the posture past
    // a limit (the second knot).
    assert_eq!(take(&mut d, &msg(PATH_EXTEND, &[(0.0, goal)])), (207, None));
    assert_eq!(
        take(&mut d, &msg(PATH_NEW, &[(0.0, [0.65, 0.2, 0.3])])),
        (210, Some(0))
    );
    let away = [
        (0.0, goal),
        (0.5, goal),
        (1.0, [3.0, 0.0, 0.3]),
        (1.5, goal),
    ];
    assert_eq!(take(&mut d, &msg(PATH_NEW, &away)), (16, Some(2)));
    let mut m = PathKnots::zeroed();
    m.flags = PATH_NEW;
    m.push(0.0, &[0.5, 0.2]).unwrap();
    assert_eq!(take(&mut d, &m), (204, None));
    let mut m = PathKnots::zeroed();
    m.flags = PATH_NEW;
    m.level = 2;
    m.push(0.0, &[0.0, -0.3, 0.0, -2.2, 0.0, 2.0, 0.8]).unwrap();
    m.push(1.0, &[0.0, -0.3, 0.0, -3.2, 0.0, 2.0, 0.8]).unwrap();
    assert_eq!(take(&mut d, &m), (15, Some(1)));
    // A good start, then an extension that goes back in time.
    assert_eq!(d.take_path(&msg(PATH_NEW, &[(0.0, goal), (0.5, goal)])), 0);
    assert_eq!(d.take_path(&msg(PATH_EXTEND, &[(0.4, goal)])), 203);
    assert_eq!(
        d.take_path(&msg(PATH_EXTEND, &[(0.6, goal), (0.7, goal)])),
        0
    );
    // Faster than the level's max_speed (0.25 m/s by default): 3 cm in
    // 0.1 s between the third knot and the second; an extension whose first
    // knot is 3 cm from the path's last in 0.1 s; a sample's own velocity.
    let step = |dy: f64| [goal[0], goal[1] + dy, goal[2]];
    let fast = [(0.0, goal), (0.1, step(0.01)), (0.2, step(0.04))];
    assert_eq!(take(&mut d, &msg(PATH_NEW, &fast)), (211, Some(2)));
    let ok = [(0.0, goal), (0.1, step(0.01)), (0.2, step(0.02))];
    assert_eq!(take(&mut d, &msg(PATH_NEW, &ok)), (0, None));
    assert_eq!(
        take(&mut d, &msg(PATH_EXTEND, &[(0.3, step(0.05))])),
        (211, Some(0))
    );
    assert_eq!(
        take(&mut d, &msg(PATH_EXTEND, &[(0.3, step(0.04))])),
        (0, None)
    );
    let mut m = PathKnots::zeroed();
    m.flags = PATH_EXTEND;
    m.push_sample(0.4, &step(0.045), &[0.0, 0.3, 0.0], &[0.0; 3])
        .unwrap();
    assert_eq!(take(&mut d, &m), (211, Some(0)));
}

/// The circle's velocity and acceleration (its phase's derivatives).
fn circle_rates(t: f64) -> ([f64; 3], [f64; 3]) {
    let x = t.min(1.0);
    let (phase, dphase, ddphase) = if t <= 1.0 {
        (
            x.powi(6) - 3.0 * x.powi(5) + 2.5 * x.powi(4),
            6.0 * x.powi(5) - 15.0 * x.powi(4) + 10.0 * x.powi(3),
            30.0 * x.powi(4) - 60.0 * x.powi(3) + 30.0 * x.powi(2),
        )
    } else {
        (t - 0.5, 1.0, 0.0)
    };
    let w = 2.0 * std::f64::consts::PI * 0.25;
    let (r, a) = (0.05, w * phase);
    let (s, c) = a.sin_cos();
    let (da, dda) = (w * dphase, w * ddphase);
    (
        [0.0, r * da * c, r * da * s],
        [
            0.0,
            r * dda * c - r * da * da * s,
            r * dda * s + r * da * da * c,
        ],
    )
}

/// As [`send_circle`], but a device's samples: from 2 s, one sample per
/// cycle with its velocity and acceleration, stamped `LEAD` s ahead of the
/// path, for `sampled` s of path; the run lasts `seconds` from 2 s.
fn stream_circle_samples(sampled: f64, seconds: f64, checked: bool) -> Sent {
    use hcc_msgs::{PATH_EXTEND, PATH_NEW, PathKnots};
    const LEAD: f64 = 0.005;
    const DT: f64 = 1e-3;
    let (mut next_t, mut sent) = (0.0, 0);
    run_sending(seconds, checked, |k, start| {
        // Every sample up to LEAD s past where the path is.
        let path_t = k as f64 * DT;
        let mut msg = PathKnots::zeroed();
        while next_t <= path_t + LEAD + 1e-9 && next_t <= sampled + 1e-9 {
            let (v, a) = circle_rates(next_t);
            msg.push_sample(next_t, &circle(start, next_t), &v, &a)
                .unwrap();
            next_t += DT;
        }
        if msg.count() == 0 {
            return Vec::new();
        }
        msg.flags |= if sent == 0 { PATH_NEW } else { PATH_EXTEND };
        msg.client_id = 9;
        sent += 1;
        msg.header.seq = sent;
        vec![msg]
    })
}

#[test]
fn a_device_s_samples_are_tracked_and_a_stream_that_stops_rests_on_its_last() {
    // 3 s of samples, then the device goes quiet; the run goes on to 5 s.
    let s = stream_circle_samples(3.0, 5.0, false);
    assert!(s.codes.iter().all(|&c| c == 0), "answers {:?}", s.codes);
    let worst = s.err[1000..2900].iter().fold(0.0_f64, |m, e| m.max(*e));
    let off_circle = s.off_circle(2990);
    assert_eq!(s.stopped, 1);
    let last = circle(s.start, 3.0);
    let end = s.desired[s.desired.len() - 1];
    let step = s.largest_torque_step();
    let settled = s.err[s.err.len() - 1];
    println!(
        "device samples: TCP error from 1 s {worst:.3e} m; the path off the circle by at most \
         {off_circle:.1e} m; stopped: at rest {settled:.2e} m from its last sample, largest torque \
         step {step:.3} N·m"
    );
    assert!(worst < 1e-3, "{worst:.3e} m");
    assert!(off_circle < 1e-9, "{off_circle:.3e} m");
    assert!(
        (0..3).all(|a| (end[a] - last[a]).abs() < 1e-9),
        "{end:?} vs {last:?}"
    );
    assert!(settled < 1e-4 && step <= 1.0 + 1e-9, "{settled} {step}");
}

#[test]
fn samples_every_cycle_pass_the_feasibility_check_and_are_tracked() {
    // The device's stream through the check (its worker between cycles):
    // every message waits one cycle for its verdict, which the 5 ms lead
    // absorbs.
    let s = stream_circle_samples(3.0, 4.0, true);
    assert!(
        s.answers.iter().all(|a| a.1 == 0),
        "refusals: {:?}",
        s.answers.iter().filter(|a| a.1 != 0).collect::<Vec<_>>()
    );
    assert_eq!(s.answered, s.sent, "every message answered");
    let worst = s.err[1000..2900].iter().fold(0.0_f64, |m, e| m.max(*e));
    println!(
        "checked device samples: {} messages, TCP error from 1 s {worst:.3e} m; {}",
        s.sent,
        s.check_ms()
    );
    assert!(worst < 1e-3, "{worst:.3e} m");
    assert_eq!(s.counters.paths_infeasible + s.counters.paths_unchecked, 0);
}

/// The TCP from where it is straight out along x to 0.95 m at its height
/// over 8 s, a knot every 0.1 s: two knots, then messages of `per_message`
/// (as `hcc follow` sends them, one or a few at a time), from 2 s four
/// messages per cycle, through the feasibility check. The arm cannot reach
/// past ~0.9 m: the stacked Jacobian loses rank on the way.
fn out_of_reach(per_message: usize) -> Sent {
    let mut queue = std::collections::VecDeque::new();
    run_sending(1.0, true, move |k, start| {
        if k == 0 {
            queue.extend(line_messages(start, per_message));
        }
        let n = queue.len().min(4);
        queue.drain(..n).collect()
    })
}

/// [`out_of_reach`]'s messages from `start`.
fn line_messages(start: [f64; 3], per_message: usize) -> Vec<hcc_msgs::PathKnots> {
    use hcc_msgs::{PATH_EXTEND, PATH_NEW, PathKnots};
    let at = |t: f64| [start[0] + (0.95 - start[0]) * (t / 8.0), start[1], start[2]];
    let mut msgs: Vec<PathKnots> = Vec::new();
    for j in 0..=80 {
        let full = |m: &PathKnots| m.count() == if j <= 2 { 2 } else { per_message };
        if msgs.last().is_none_or(full) {
            let mut m = PathKnots::zeroed();
            m.flags = if j == 0 { PATH_NEW } else { PATH_EXTEND };
            (m.client_id, m.header.seq) = (9, msgs.len() as u64 + 1);
            msgs.push(m);
        }
        let t = j as f64 * 0.1;
        msgs.last_mut().unwrap().push(t, &at(t)).unwrap();
    }
    msgs
}

#[test]
fn a_path_out_of_reach_sent_at_run_time_is_refused_at_its_knot_and_not_taken() {
    for per_message in [16, 1] {
        let s = out_of_reach(per_message);
        // Refused where the rollout failed (the knot at or after it); every
        // later extension refused too: the path takes no more. Nothing
        // before the refused message was refused.
        let refused = s
            .answers
            .iter()
            .find(|a| a.1 != 0)
            .unwrap_or_else(|| panic!("{:?}", s.answers));
        println!(
            "{per_message} knots per message: first refusal (seq, code, knot) {refused:?}; \
             {} answers, {} refused infeasible; {}",
            s.answered,
            s.counters.paths_infeasible,
            s.check_ms()
        );
        assert_eq!(refused.1, 212);
        let knot_t = match per_message {
            16 => 0.2 + ((refused.0 - 2) as f64 * 16.0 + refused.2.unwrap() as f64) * 0.1,
            _ => 0.2 + (refused.0 - 2) as f64 * 0.1,
        };
        assert!(
            (3.5..=5.5).contains(&knot_t),
            "refused at the knot of {knot_t} s"
        );
        assert_eq!(s.answered, s.sent, "every message answered");
        let after = s.answers.iter().filter(|a| a.0 > refused.0);
        assert!(after.clone().all(|a| a.1 == 212 && a.2 == Some(0)));
        assert_eq!(
            s.counters.paths_infeasible,
            s.sent - refused.0 + 1,
            "{:?}",
            s.answers
        );
        // What was taken is followed: the level's equilibrium went out along
        // x to the last knot taken, never further.
        let furthest = s.desired.iter().map(|x| x[0]).fold(0.0_f64, f64::max);
        let x_at = |t: f64| s.start[0] + (0.95 - s.start[0]) * (t / 8.0);
        assert!(furthest < x_at(knot_t), "{furthest} m");
    }
}
