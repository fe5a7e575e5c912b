//! The tracking form on the Panda (docs/tracking.md), `config/panda-figure-eight.toml`:
//! the TCP on a figure-eight, the orientation held, joint 3 on a sine in the
//! null space, exact model, 1 kHz, starting on the paths. Prints the figures
//! the docs quote.

use std::path::PathBuf;

use hcc_config::Scenario;
use hcc_in_process::run_observed;

fn scenario() -> Scenario {
    let path =
        PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../config/panda-figure-eight.toml");
    Scenario::load(path).expect("the figure-eight scenario loads")
}

/// Per cycle: t, each level's task error x_i − x_{i,d} and level 1's
/// desired value x_{1,d} (telemetry).
struct Errors {
    t: Vec<f64>,
    e: Vec<[Vec<f64>; 3]>,
    xd: Vec<Vec<f64>>,
}

fn run(scenario: &Scenario) -> Errors {
    let mut out = Errors {
        t: Vec::new(),
        e: Vec::new(),
        xd: Vec::new(),
    };
    run_observed(scenario, &mut |view| {
        let tel = view.cycle.telemetry();
        out.t.push(view.t);
        out.e.push([0, 1, 2].map(|i| tel.task_error(i).to_vec()));
        out.xd.push(tel.goal[0][..3].to_vec());
        Ok(())
    })
    .expect("the run");
    out
}

fn norm(v: &[f64]) -> f64 {
    v.iter().map(|x| x * x).sum::<f64>().sqrt()
}

impl Errors {
    /// The largest ‖e_i‖ from `from` s on.
    fn max_after(&self, i: usize, from: f64) -> f64 {
        self.t
            .iter()
            .zip(&self.e)
            .filter(|(t, _)| **t >= from)
            .map(|(_, e)| norm(&e[i]))
            .fold(0.0, f64::max)
    }

    /// The decay rate λ of ‖e_i‖ ≈ c e^{−λ t}: least squares on ln ‖e_i‖
    /// over the first `window` s.
    fn decay_rate(&self, i: usize, window: f64) -> f64 {
        let pts: Vec<(f64, f64)> = self
            .t
            .iter()
            .zip(&self.e)
            .filter(|(t, e)| **t <= window && norm(&e[i]) > 0.0)
            .map(|(t, e)| (*t, norm(&e[i]).ln()))
            .collect();
        let n = pts.len() as f64;
        let (st, sy) = pts.iter().fold((0.0, 0.0), |a, p| (a.0 + p.0, a.1 + p.1));
        let (mt, my) = (st / n, sy / n);
        let (num, den) = pts.iter().fold((0.0, 0.0), |a, p| {
            (a.0 + (p.0 - mt) * (p.1 - my), a.1 + (p.0 - mt) * (p.0 - mt))
        });
        -num / den
    }
}

#[test]
fn the_panda_tracks_a_figure_eight_with_the_posture_on_a_sine_in_the_null_space() {
    let s = scenario();
    assert!(s.tracking.any() && s.tracking.feed_forward.iter().all(|&f| f));
    let tracked = run(&s);
    let (e1, e2, e3) = (
        tracked.max_after(0, 3.0),
        tracked.max_after(1, 3.0),
        tracked.max_after(2, 3.0),
    );
    println!(
        "tracking, largest error from 3 s: TCP {e1:.3e} m, orientation {e2:.3e} rad, joint 3 {e3:.3e} rad"
    );
    assert!(e1 < 1e-4, "TCP error {e1:.3e} m");
    assert!(e3 < 1e-3, "joint 3 error {e3:.3e} rad");
    assert!(e2 < 1e-3, "orientation error {e2:.3e} rad");

    // Strictness while tracking: the same run with joint 3 held at its start
    // moves the TCP by what the posture's motion does to it.
    let mut held = s.clone();
    held.tracking.paths[2] = None;
    let still = run(&held);
    let moved = tracked
        .e
        .iter()
        .zip(&still.e)
        .map(|(a, b)| {
            norm(
                &a[0]
                    .iter()
                    .zip(&b[0])
                    .map(|(x, y)| x - y)
                    .collect::<Vec<_>>(),
            )
        })
        .fold(0.0, f64::max);
    println!("the posture's motion moves the TCP by at most {moved:.3e} m");
    assert!(moved < 1e-6, "{moved:.3e} m");

    // Pulled along: no feed-forward, the goal a spring pulls — with the
    // damping relative to the path's velocity (the default, as transitions
    // do) and with the paper's D ẋ.
    let mut pulled = s.clone();
    pulled.tracking.feed_forward = vec![false; 3];
    let relative = run(&pulled).max_after(0, 3.0);
    pulled.setpoint_limits.relative_damping = false;
    let pulled_abs = run(&pulled);
    let absolute = pulled_abs.max_after(0, 3.0);
    plot(&tracked, &pulled_abs);
    println!(
        "TCP error from 3 s: tracking {e1:.3e} m; pulled along {relative:.3e} m (damping relative \
         to the path, {:.0}×), {absolute:.3e} m (D ẋ, {:.0}×)",
        relative / e1,
        absolute / e1
    );
    assert!(relative > 100.0 * e1 && absolute > 100.0 * e1);
    assert!(
        absolute >= 0.01,
        "pulled along with D ẋ lags {absolute:.3e} m"
    );
}

#[test]
fn started_off_the_path_every_level_s_error_decays() {
    let mut s = scenario();
    // Joint 3 0.04 rad off its path: the TCP about 2 cm off its path, the
    // hand's orientation 0.04 rad off.
    s.q0[2] += 0.04;
    let off = run(&s);
    let e0: Vec<f64> = (0..3).map(|i| norm(&off.e[0][i])).collect();
    let rates: Vec<f64> = (0..3).map(|i| off.decay_rate(i, 1.5)).collect();
    let e2s: Vec<f64> = (0..3).map(|i| off.max_after(i, 2.0)).collect();
    println!(
        "started off the path by {:.3e} m, {:.3e} rad, {:.3e} rad: fitted decay rates {:.1} {:.1} {:.1} 1/s; \
         largest error from 2 s {:.2e} m, {:.2e} rad, {:.2e} rad",
        e0[0], e0[1], e0[2], rates[0], rates[1], rates[2], e2s[0], e2s[1], e2s[2]
    );
    assert!(
        e0[0] > 0.015 && e0[0] < 0.025,
        "TCP starts {:.3e} m off",
        e0[0]
    );
    for i in 0..3 {
        assert!(
            rates[i] > 1.0,
            "level {} decays at {:.2} 1/s",
            i + 1,
            rates[i]
        );
        assert!(
            e2s[i] < 0.01 * e0[i].max(1e-3),
            "level {} at 2 s: {:.2e}",
            i + 1,
            e2s[i]
        );
    }
}

#[test]
fn a_path_that_does_not_start_at_the_arm_is_refused() {
    let mut s = scenario();
    s.q0[2] += 0.5;
    let Err(e) = hcc_cycle::controller_for(&s) else {
        panic!("a path 0.5 rad from joint 3 is refused");
    };
    let e = e.to_string();
    println!("{e}");
    assert!(
        e.contains("level[0].trajectory") && e.contains("panda-figure-eight-tcp.csv"),
        "{e}"
    );
    assert!(
        e.contains("row 7:") && e.contains("start the path where the arm is"),
        "{e}"
    );
}

#[test]
fn a_path_faster_than_its_level_s_max_speed_is_refused() {
    let mut s = scenario();
    // The figure-eight's TCP peaks at ≈ 0.22 m/s; level 1's limit to 0.1 m/s.
    s.setpoint_limits.levels[0].max_speed = 0.1;
    let Err(e) = hcc_cycle::controller_for(&s) else {
        panic!("a path faster than max_speed is refused");
    };
    let e = e.to_string();
    println!("{e}");
    assert!(
        e.contains("level[0].trajectory") && e.contains("faster than the level's"),
        "{e}"
    );
    // The shipped limits pass.
    assert!(hcc_cycle::controller_for(&scenario()).is_ok());
}

#[test]
fn a_path_the_hierarchy_cannot_follow_is_refused_where_it_fails() {
    // The TCP from where it is straight out along x to 0.95 m at its height
    // (the Panda reaches ≈ 0.86 m from the shoulder): slow enough for the
    // speed limit, inside the workspace ball, but the arm stretches and the
    // law turns singular, or the TCP falls behind, before the end.
    let mut s = scenario();
    let start = [0.484046815, 0.0, 0.412629775];
    let mut csv = String::from("t,x,y,z\n");
    for k in 0..=80 {
        let t = k as f64 * 0.1;
        let x = start[0] + (0.95 - start[0]) * (t / 8.0);
        csv += &format!("{t:.1},{x},{},{}\n", start[1], start[2]);
    }
    let path = s.tracking.paths[0].as_mut().unwrap();
    path.trajectory = hcc_trajectory::Trajectory::parse(&csv, path.trajectory.blocks()).unwrap();
    let Err(e) = hcc_cycle::controller_for(&s) else {
        panic!("a path out of reach is refused");
    };
    let e = e.to_string();
    println!("{e}");
    assert!(
        e.contains("level[0].trajectory") && e.contains("cannot be followed from initial.q0"),
        "{e}"
    );
    // The shipped figure-eight is followed: the rollout's smallest
    // conditioning per level.
    let sc = scenario();
    let c = hcc_cycle::controller_for(&sc).unwrap();
    let paths: Vec<_> = sc
        .tracking
        .paths
        .iter()
        .map(|p| p.as_ref().map(|p| &p.trajectory))
        .collect();
    let r = hcc_cycle::feasibility::check_paths(&c, sc.q0.as_slice(), &paths, 0.005).unwrap();
    println!(
        "figure-eight rollout: {} steps, smallest conditioning {:?}",
        r.steps, r.conditioning
    );
    assert!(r.steps > 1000);
}

/// With `HCC_TRACKING_PLOTS=<dir>` set: the TCP's y and z, desired and
/// actual, tracking and pulled along (D ẋ), and the TCP error of both, as
/// `<dir>/tracking-figure-eight.png` (the figure of docs/tracking.md).
fn plot(tracked: &Errors, pulled: &Errors) {
    let Some(dir) = std::env::var_os("HCC_TRACKING_PLOTS") else {
        return;
    };
    let dir = PathBuf::from(dir);
    std::fs::create_dir_all(&dir).unwrap();
    let shown: Vec<usize> = (0..tracked.t.len()).step_by(10).collect();
    let t: Vec<f64> = shown.iter().map(|&k| tracked.t[k]).collect();
    let actual = |r: &Errors, a: usize| -> Vec<f64> {
        shown.iter().map(|&k| r.xd[k][a] + r.e[k][0][a]).collect()
    };
    let axis = |a: usize, name: &str| hcc_report::TimePanel {
        title: format!("TCP {name}: desired, tracking, pulled along"),
        y_label: format!("{name} [m]"),
        series: vec![
            (
                "desired x_d".into(),
                shown.iter().map(|&k| tracked.xd[k][a]).collect(),
            ),
            ("tracking".into(), actual(tracked, a)),
            ("pulled along (D xdot)".into(), actual(pulled, a)),
        ],
    };
    let error_mm =
        |r: &Errors| -> Vec<f64> { shown.iter().map(|&k| 1e3 * norm(&r.e[k][0])).collect() };
    let panels = [
        axis(1, "y"),
        axis(2, "z"),
        hcc_report::TimePanel {
            title: "TCP error |x - x_d|".into(),
            y_label: "error [mm]".into(),
            series: vec![
                ("tracking".into(), error_mm(tracked)),
                ("pulled along (D xdot)".into(), error_mm(pulled)),
            ],
        },
    ];
    hcc_report::plot_time_series(
        &dir.join("tracking-figure-eight.png"),
        "panda-figure-eight: the TCP on a figure-eight, tracking vs pulled along",
        &t,
        &panels,
    )
    .unwrap();
}

/// The warped phase time of the shipped paths: its rate rises from 0 to 1
/// over the first second (quintic smoothstep), so a path starts at rest.
fn phase(t: f64) -> f64 {
    let x = t.min(1.0);
    let ramp = x.powi(6) - 3.0 * x.powi(5) + 2.5 * x.powi(4);
    if t <= 1.0 { ramp } else { t - 0.5 }
}

#[test]
fn an_orientation_path_is_tracked_on_so3() {
    // The figure-eight scenario with the hand turning as well: about the
    // world z by 0.3 sin(2π 0.3 τ) rad and about its own x by
    // 0.2 sin(2π 0.2 τ) rad, a quaternion path every 10 ms.
    use nalgebra::{UnitQuaternion, Vector3};
    let dir = std::env::temp_dir().join(format!("hcc-tracking-so3-{}", std::process::id()));
    std::fs::create_dir_all(dir.join("paths")).unwrap();
    let root = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../..");
    for f in [
        "panda-figure-eight-tcp.csv",
        "panda-figure-eight-joint3.csv",
    ] {
        std::fs::copy(root.join("config/paths").join(f), dir.join("paths").join(f)).unwrap();
    }
    let r0 = UnitQuaternion::from_euler_angles(
        -3.140127636212154,
        -0.09998930383585482,
        -0.01467514073335553,
    );
    let mut csv = String::from("t,qw,qx,qy,qz\n");
    for k in 0..=600 {
        let t = k as f64 * 0.01;
        let p = phase(t);
        let yaw = UnitQuaternion::from_axis_angle(
            &Vector3::z_axis(),
            0.3 * (2.0 * std::f64::consts::PI * 0.3 * p).sin(),
        );
        let roll = UnitQuaternion::from_axis_angle(
            &Vector3::x_axis(),
            0.2 * (2.0 * std::f64::consts::PI * 0.2 * p).sin(),
        );
        let q = yaw * r0 * roll;
        csv += &format!("{t:.2},{},{},{},{}\n", q.w, q.i, q.j, q.k);
    }
    std::fs::write(dir.join("paths/hand.csv"), csv).unwrap();
    let urdf = root
        .join("config/robots/panda/panda.urdf")
        .canonicalize()
        .unwrap();
    let text = std::fs::read_to_string(root.join("config/panda-figure-eight.toml"))
        .unwrap()
        .replace(
            "urdf = \"robots/panda/panda.urdf\"",
            &format!("urdf = {:?}", urdf.to_string_lossy()),
        )
        .replace(
            "goal = [-3.140127636212154, -0.09998930383585482, -0.01467514073335553]",
            "trajectory = \"paths/hand.csv\"",
        )
        .replace("duration_s = 10.0", "duration_s = 5.5");
    let path = dir.join("so3.toml");
    std::fs::write(&path, text).unwrap();
    let s = Scenario::load(&path).expect("the orientation path loads");
    std::fs::remove_dir_all(&dir).ok();
    assert!(s.tracking.paths[1].is_some());
    let tracked = run(&s);
    let mut pulled = s.clone();
    pulled.tracking.feed_forward = vec![false; 3];
    let lagging = run(&pulled);
    let (e2, e2_pulled) = (tracked.max_after(1, 3.0), lagging.max_after(1, 3.0));
    let (e1, e3) = (tracked.max_after(0, 3.0), tracked.max_after(2, 3.0));
    println!(
        "orientation path: largest error from 3 s {e2:.3e} rad tracking, {e2_pulled:.3e} rad pulled \
         along; TCP {e1:.3e} m, joint 3 {e3:.3e} rad"
    );
    assert!(e2 < 1e-3, "orientation error {e2:.3e} rad");
    assert!(e2_pulled > 10.0 * e2, "pulled along {e2_pulled:.3e} rad");
    assert!(e1 < 1e-4 && e3 < 1e-3);
}
