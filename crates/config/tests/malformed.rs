//! Table-driven checks of malformed scenario files: each case must fail with an
//! error that names the offending field (dotted path) and, where given, the line.

use hcc_config::{ConfigError, Scenario, TaskSpec};
use std::path::PathBuf;

/// A valid scenario (the paper's simulation #1). The file name is virtual; the
/// URDF path resolves relative to the repository's config directory.
const BASE: &str = r#"name = "base"

[robot]
urdf = "planar4.urdf"
root_link = "base"
tip_link = "tcp"
gravity = [0.0, -9.81, 0.0]

[[level]]
task = "position"
frame = "tcp"
axes = ["x", "y"]
stiffness = [1000.0, 1000.0]
damping = [40.0, 40.0]
goal = [0.90, 0.80]

[[level]]
task = "orientation"
axes = ["z"]
stiffness = 800.0
damping = 5.0
goal = [-1.57]

[[level]]
task = "joint"
joints = ["joint1"]
stiffness = 2400.0
damping = 15.0
goal = [0.35]

[controller]
rate_hz = 1000.0
coriolis_cancellation = true

[initial]
q0 = [0.4, -0.5088, -1.6578, 0.3966]

[simulation]
duration_s = 3.0
integrator_dt_s = 1e-4

[[simulation.wrench]]
start_s = 1.0
duration_s = 0.2
link = "tcp"
force = [0.0, -5.0, 0.0]

[controller_daemon]
cpu_core = 1
sched_priority = 80
torque_limits = 100.0

[sim_daemon]
mode = "lockstep"
"#;

fn virtual_path() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../config/test-scenario.toml")
}

fn load(text: &str) -> Result<Scenario, ConfigError> {
    Scenario::from_toml_str(text, &virtual_path())
}

fn edit(from: &str, to: &str) -> String {
    assert!(BASE.contains(from), "base has no {from:?}");
    BASE.replacen(from, to, 1)
}

#[test]
fn base_is_valid() {
    let s = load(BASE).unwrap();
    assert_eq!(s.model.nq(), 4);
    assert_eq!(s.levels().len(), 3);
    assert_eq!(s.levels()[0].dim(4), 2);
    assert!(matches!(
        s.levels()[1].tasks[..],
        [TaskSpec::PlanarOrientation { axis: 2, .. }]
    ));
    assert!(
        matches!(&s.levels()[2].tasks[..], [TaskSpec::Joints { indices }] if indices == &vec![0])
    );
    assert_eq!(s.levels()[0].stiffness[(1, 1)], 1000.0);
    assert_eq!(s.levels()[1].damping[(0, 0)], 5.0);
    assert_eq!(s.simulation.substeps, 10);
    assert_eq!(s.simulation.wrenches.len(), 1);
    assert_eq!(s.qd0.len(), 4);
    assert_eq!(s.controller_daemon.torque_limits[3], 100.0);
    assert_eq!(s.controller_daemon.sched_priority, Some(80));
    assert_eq!(s.sim_daemon.mode, hcc_config::SimMode::Lockstep);
    assert_eq!(s.ipc.namespace, "hcc");
    assert_eq!(s.name, "base");
    // The controller spec holds the levels.
    assert_eq!(s.spec.levels.len(), 3);
    assert_eq!(s.spec.levels[2].goal[0], 0.35);
    assert!(s.spec.coriolis_cancellation && s.spec.gravity_compensation);
}

#[test]
fn joint_combination_and_posture() {
    let text = edit(
        "task = \"orientation\"\naxes = [\"z\"]",
        "task = \"joint_combination\"\nweights = [[1.0, 1.0, 1.0, 1.0]]",
    )
    .replacen(
        "joints = [\"joint1\"]\nstiffness = 2400.0\ndamping = 15.0\ngoal = [0.35]",
        "stiffness = 10.0\ndamping = 1.0\ngoal = [0.0, 0.0, 0.0, 0.0]",
        1,
    );
    let s = load(&text).unwrap();
    assert!(
        matches!(&s.spec.levels[1].tasks[..], [TaskSpec::JointCombination { weights }] if weights.shape() == (1, 4))
    );
    assert!(matches!(s.spec.levels[2].tasks[..], [TaskSpec::Posture]));
    assert_eq!(s.levels()[2].dim(4), 4);
    let mut s = s;
    s.set_coriolis_cancellation(false).unwrap();
    assert!(!s.spec.coriolis_cancellation);
    assert!(s.set_duration(0.0).is_err());
    s.set_duration(0.5).unwrap();
    assert_eq!(s.simulation.duration_s, 0.5);
}

/// (case, modified text, expected field path in the message, expected line if checked)
fn cases() -> Vec<(&'static str, String, &'static str, Option<usize>)> {
    vec![
        (
            "syntax error",
            edit("goal = [0.90, 0.80]", "goal = [0.90, 0.80"),
            "level[0]",
            Some(17),
        ),
        (
            "unknown top-level field",
            edit("name = \"base\"", "name = \"base\"\nfoo = 1"),
            "foo",
            Some(2),
        ),
        (
            "unknown level field",
            edit("stiffness = 800.0", "stiffnes = 800.0"),
            "level[1].stiffnes",
            Some(20),
        ),
        (
            "unknown robot field",
            edit("tip_link = \"tcp\"", "tip_link = \"tcp\"\ntip = \"x\""),
            "robot.tip",
            Some(7),
        ),
        (
            "missing tip link",
            edit("tip_link = \"tcp\"\n", ""),
            "robot",
            None,
        ),
        (
            "missing initial",
            edit("[initial]\nq0 = [0.4, -0.5088, -1.6578, 0.3966]\n", ""),
            "initial",
            None,
        ),
        (
            "q0 length",
            edit(
                "q0 = [0.4, -0.5088, -1.6578, 0.3966]",
                "q0 = [0.4, -0.5088, -1.6578]",
            ),
            "initial.q0",
            Some(36),
        ),
        (
            "qd0 length",
            edit("[initial]\n", "[initial]\nqd0 = [0.0, 0.0]\n"),
            "initial.qd0",
            Some(36),
        ),
        (
            "q0 not finite",
            edit("q0 = [0.4,", "q0 = [nan,"),
            "initial.q0[0]",
            Some(36),
        ),
        (
            "gravity length",
            edit("gravity = [0.0, -9.81, 0.0]", "gravity = [0.0, -9.81]"),
            "robot.gravity",
            Some(7),
        ),
        (
            "stiffness diagonal length",
            edit(
                "stiffness = [1000.0, 1000.0]",
                "stiffness = [1000.0, 1000.0, 5.0]",
            ),
            "level[0].stiffness",
            Some(13),
        ),
        (
            "negative stiffness",
            edit("stiffness = 800.0", "stiffness = -800.0"),
            "level[1].stiffness",
            Some(20),
        ),
        (
            "non-symmetric stiffness",
            edit(
                "stiffness = [1000.0, 1000.0]",
                "stiffness = [[1000.0, 10.0], [0.0, 1000.0]]",
            ),
            "level[0].stiffness",
            Some(13),
        ),
        (
            "indefinite damping",
            edit(
                "damping = [40.0, 40.0]",
                "damping = [[1.0, 2.0], [2.0, 1.0]]",
            ),
            "level[0].damping",
            Some(14),
        ),
        (
            "zero damping",
            edit("damping = 15.0", "damping = 0.0"),
            "level[2].damping",
            Some(28),
        ),
        (
            "matrix of wrong size",
            edit("damping = 5.0", "damping = [[5.0, 0.0], [0.0, 5.0]]"),
            "level[1].damping",
            Some(21),
        ),
        (
            "goal length",
            edit("goal = [0.90, 0.80]", "goal = [0.90]"),
            "level[0].goal",
            Some(15),
        ),
        (
            "goal not finite",
            edit("goal = [0.90, 0.80]", "goal = [inf, 0.80]"),
            "level[0].goal[0]",
            Some(15),
        ),
        (
            "unknown frame",
            edit("frame = \"tcp\"", "frame = \"hand\""),
            "level[0].frame",
            Some(11),
        ),
        (
            "unknown joint",
            edit("joints = [\"joint1\"]", "joints = [\"joint9\"]"),
            "level[2].joints[0]",
            Some(26),
        ),
        (
            "joint listed twice",
            edit("joints = [\"joint1\"]", "joints = [\"joint1\", \"joint1\"]"),
            "level[2].joints[1]",
            Some(26),
        ),
        (
            "unknown task kind",
            edit("task = \"joint\"", "task = \"velocity\""),
            "level[2].task",
            Some(25),
        ),
        (
            "field not used by the task",
            edit("task = \"joint\"", "task = \"joint\"\naxes = [\"x\"]"),
            "level[2].axes",
            Some(26),
        ),
        (
            "two axes for an orientation",
            edit("axes = [\"z\"]", "axes = [\"x\", \"z\"]"),
            "level[1].axes",
            Some(19),
        ),
        (
            "unknown axis",
            edit("axes = [\"z\"]", "axes = [\"w\"]"),
            "level[1].axes",
            Some(19),
        ),
        (
            "axis listed twice",
            edit("axes = [\"x\", \"y\"]", "axes = [\"x\", \"x\"]"),
            "level[0].axes",
            Some(12),
        ),
        (
            "unknown tip link",
            edit("tip_link = \"tcp\"", "tip_link = \"gripper\""),
            "robot",
            Some(6),
        ),
        (
            "unknown root link",
            edit("root_link = \"base\"", "root_link = \"ground\""),
            "robot",
            Some(5),
        ),
        (
            "missing urdf",
            edit("urdf = \"planar4.urdf\"", "urdf = \"nothing.urdf\""),
            "robot",
            Some(4),
        ),
        (
            "no null space left",
            edit(
                "joints = [\"joint1\"]\nstiffness = 2400.0\ndamping = 15.0\ngoal = [0.35]",
                "joints = [\"joint1\", \"joint2\", \"joint3\"]\nstiffness = 2400.0\ndamping = 15.0\ngoal = [0.35, 0.0, 0.0]\n\n[[level]]\ntask = \"joint\"\nstiffness = 1.0\ndamping = 1.0\ngoal = [0.0, 0.0, 0.0, 0.0]",
            ),
            "level[3]",
            Some(31),
        ),
        (
            "zero control rate",
            edit("rate_hz = 1000.0", "rate_hz = 0.0"),
            "controller.rate_hz",
            Some(32),
        ),
        (
            "dt not dividing the period",
            edit("integrator_dt_s = 1e-4", "integrator_dt_s = 3e-4"),
            "simulation.integrator_dt_s",
            Some(40),
        ),
        (
            "negative duration",
            edit("duration_s = 3.0", "duration_s = -3.0"),
            "simulation.duration_s",
            Some(39),
        ),
        (
            "friction length",
            edit(
                "integrator_dt_s = 1e-4",
                "integrator_dt_s = 1e-4\njoint_friction = [0.1, 0.1]",
            ),
            "simulation.joint_friction",
            Some(41),
        ),
        (
            "negative friction",
            edit(
                "integrator_dt_s = 1e-4",
                "integrator_dt_s = 1e-4\njoint_friction = [0.1, 0.1, -0.1, 0.1]",
            ),
            "simulation.joint_friction[2]",
            Some(41),
        ),
        (
            "wrench unknown link",
            edit("\nlink = \"tcp\"", "\nlink = \"tool\""),
            "simulation.wrench[0].link",
            Some(45),
        ),
        (
            "wrench force length",
            edit("force = [0.0, -5.0, 0.0]", "force = [0.0, -5.0]"),
            "simulation.wrench[0].force",
            Some(46),
        ),
        (
            "wrench negative duration",
            edit("duration_s = 0.2", "duration_s = -0.2"),
            "simulation.wrench[0].duration_s",
            Some(44),
        ),
        (
            "wrench unknown field",
            edit(
                "\nlink = \"tcp\"",
                "\nlink = \"tcp\"\nmoment = [0.0, 0.0, 1.0]",
            ),
            "simulation.wrench[0].moment",
            Some(46),
        ),
        (
            "sched priority",
            edit("sched_priority = 80", "sched_priority = 0"),
            "controller_daemon.sched_priority",
            Some(50),
        ),
        (
            "negative torque limit",
            edit(
                "torque_limits = 100.0",
                "torque_limits = [100.0, -1.0, 100.0, 100.0]",
            ),
            "controller_daemon.torque_limits[1]",
            Some(51),
        ),
        (
            "stale timeout",
            edit(
                "torque_limits = 100.0",
                "torque_limits = 100.0\nstale_timeout_ms = 0.0",
            ),
            "controller_daemon.stale_timeout_ms",
            Some(52),
        ),
        (
            "cache warm-up not a boolean",
            edit(
                "torque_limits = 100.0",
                "torque_limits = 100.0\nwarm_up = \"yes\"",
            ),
            "controller_daemon.warm_up",
            Some(52),
        ),
        (
            "sim daemon mode",
            edit("mode = \"lockstep\"", "mode = \"fast\""),
            "sim_daemon.mode",
            Some(54),
        ),
        (
            "fallback damping",
            edit(
                "mode = \"lockstep\"",
                "mode = \"lockstep\"\nfallback_damping = -1.0",
            ),
            "sim_daemon.fallback_damping",
            Some(55),
        ),
        (
            "ipc namespace",
            format!("{BASE}\n[ipc]\nnamespace = \"a/b\"\n"),
            "ipc.namespace",
            Some(57),
        ),
        (
            "controller form",
            edit(
                "coriolis_cancellation = true",
                "coriolis_cancellation = true\nform = \"other\"",
            ),
            "controller.form",
            Some(34),
        ),
        (
            "singular ratio",
            edit(
                "coriolis_cancellation = true",
                "coriolis_cancellation = true\nsingularity = { singular_ratio = 2.0 }",
            ),
            "controller.singularity.singular_ratio",
            Some(34),
        ),
        (
            "unknown singularity field",
            edit(
                "coriolis_cancellation = true",
                "coriolis_cancellation = true\n[controller.singularity]\nthreshold = 1e-4",
            ),
            "controller.singularity.threshold",
            Some(35),
        ),
        (
            "weights missing",
            edit(
                "task = \"orientation\"\naxes = [\"z\"]",
                "task = \"joint_combination\"",
            ),
            "level[1].weights",
            Some(17),
        ),
        (
            "weights row length",
            edit(
                "task = \"orientation\"\naxes = [\"z\"]",
                "task = \"joint_combination\"\nweights = [[1.0, 1.0, 1.0]]",
            ),
            "level[1].weights[0]",
            Some(19),
        ),
        (
            "weights on a joint task",
            edit(
                "joints = [\"joint1\"]",
                "joints = [\"joint1\"]\nweights = [[1.0, 0.0, 0.0, 0.0]]",
            ),
            "level[2].weights",
            Some(27),
        ),
        (
            "wrong type",
            edit(
                "coriolis_cancellation = true",
                "coriolis_cancellation = \"yes\"",
            ),
            "controller.coriolis_cancellation",
            Some(33),
        ),
    ]
}

#[test]
fn the_control_rate_under_simulation_is_refused_naming_the_controller_table() {
    let e = load(&edit(
        "duration_s = 3.0\n",
        "duration_s = 3.0\ncontrol_rate_hz = 1000.0\n",
    ))
    .unwrap_err();
    let msg = e.to_string();
    assert!(msg.contains("simulation.control_rate_hz"), "{msg}");
    assert!(msg.contains("[controller] rate_hz"), "{msg}");
    assert_eq!(e.line(), Some(40), "{msg}");
    // The key in its place runs, at the rate it gives.
    let s = load(&edit("rate_hz = 1000.0", "rate_hz = 500.0")).unwrap();
    assert_eq!(s.rate_hz, 500.0);
    assert_eq!(s.period_ns(), 2_000_000);
}

#[test]
fn malformed_configs_name_the_field() {
    let mut failures = Vec::new();
    let all = cases();
    assert!(all.len() >= 30);
    for (name, text, field, line) in all {
        match load(&text) {
            Ok(_) => failures.push(format!("{name}: loaded without error")),
            Err(e) => {
                let msg = e.to_string();
                if !msg.contains(field) {
                    failures.push(format!("{name}: message does not name {field:?}: {msg}"));
                }
                if !msg.contains("test-scenario.toml") {
                    failures.push(format!("{name}: message does not name the file: {msg}"));
                }
                if let Some(l) = line
                    && e.line() != Some(l)
                {
                    failures.push(format!("{name}: line {:?}, expected {l}: {msg}", e.line()));
                }
            }
        }
    }
    assert!(
        failures.is_empty(),
        "{} failures:\n{}",
        failures.len(),
        failures.join("\n")
    );
}

#[test]
fn missing_file_is_named() {
    let p = virtual_path().with_file_name("does-not-exist.toml");
    let e = Scenario::load(&p).unwrap_err();
    assert!(matches!(e, ConfigError::Io { .. }));
    assert!(e.to_string().contains("does-not-exist.toml"), "{e}");
}

#[test]
fn shipped_scenarios_load() {
    let dir = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../config");
    for f in [
        "paper-sim1.toml",
        "paper-sim2.toml",
        "panda-pose-posture.toml",
        "panda-cartesian-impedance.toml",
    ] {
        let p = dir.join(f);
        if f.starts_with("panda") && !p.exists() {
            continue;
        }
        let s = Scenario::load(&p).unwrap_or_else(|e| panic!("{e}"));
        assert_eq!(s.simulation.duration_s, 3.0, "{f}");
    }
    for f in [
        "panda-null-space-comparison.toml",
        "panda-null-space-comparison-push.toml",
    ] {
        let s = Scenario::load(dir.join(f)).unwrap_or_else(|e| panic!("{e}"));
        assert!(
            matches!(s.levels()[0].tasks[..], [TaskSpec::Pose { .. }]),
            "{f}"
        );
    }
}

#[test]
fn cpu_cores_are_checked_against_the_available_ones() {
    // The loader accepts any CPU index (the scenario may be meant for
    // another machine); the daemon that pins checks it at start-up.
    let s = load(BASE).unwrap();
    assert_eq!(s.controller_daemon.cpu_core, Some(1));
    assert!(s.check_cpu_core("controller_daemon", &[0, 1]).is_ok());
    assert!(
        s.check_cpu_core("sim_daemon", &[0]).is_ok(),
        "none configured"
    );
    let e = s.check_cpu_core("controller_daemon", &[0]).unwrap_err();
    let msg = e.to_string();
    assert!(
        msg.contains("controller_daemon.cpu_core") && msg.contains("available: 0"),
        "{msg}"
    );
    let e = load(&edit("cpu_core = 1", "cpu_core = 4096")).unwrap_err();
    assert!(e.to_string().contains("controller_daemon.cpu_core"), "{e}");
    assert_eq!(e.line(), Some(49));
    // The default stale timeout is three control periods; the cache warm-up is on.
    assert_eq!(s.controller_daemon.stale_timeout_ms, 3.0);
    assert!(s.controller_daemon.warm_up);
    let slow = load(&edit("rate_hz = 1000.0", "rate_hz = 500.0")).unwrap();
    assert_eq!(slow.controller_daemon.stale_timeout_ms, 6.0);
}

/// A two-level Panda scenario whose first level is written as stacked
/// `[[level.task]]` tables (`STACK`), to be edited by the tests below.
const STACKED: &str = r#"[robot]
urdf = "robots/panda/panda.urdf"
tip_link = "panda_hand_tcp"

[[level]]
name = "hand"

[[level.task]]
kind = "position"
stiffness = 300.0
damping = 35.0
goal = [0.48, 0.0, 0.41]

[[level.task]]
kind = "orientation"
stiffness = [20.0, 20.0, 20.0]
damping = 9.0
goal = [3.0, 0.0, 0.0]

[[level]]
task = "joint"
stiffness = 5.0
damping = 4.5
goal = [0.0, -0.3, 0.0, -2.2, 0.0, 2.0, 0.8]

[initial]
q0 = [0.0, -0.3, 0.0, -2.2, 0.0, 2.0, 0.8]
"#;

#[test]
fn stacked_tasks_and_the_pose_task() {
    let s = load(STACKED).unwrap_or_else(|e| panic!("{e}"));
    let l = &s.levels()[0];
    assert!(matches!(
        l.tasks[..],
        [TaskSpec::Position { .. }, TaskSpec::Orientation { .. }]
    ));
    assert_eq!(l.dim(7), 6);
    // Block-diagonal K and D from the per-task gains, goals stacked.
    assert_eq!(l.stiffness[(2, 2)], 300.0);
    assert_eq!(l.stiffness[(3, 3)], 20.0);
    assert_eq!(l.stiffness[(0, 3)], 0.0);
    assert_eq!(l.damping[(5, 5)], 9.0);
    assert_eq!(l.goal.as_slice(), &[0.48, 0.0, 0.41, 3.0, 0.0, 0.0]);
    assert_eq!(l.unit(7), None);
    assert_eq!(s.levels()[1].unit(7), Some(hcc_config::TaskUnit::Angle));

    // One gain for the whole stacked level (here a full 6×6 matrix).
    let full = STACKED
        .replace("stiffness = 300.0\n", "")
        .replace("stiffness = [20.0, 20.0, 20.0]\n", "")
        .replace(
            "name = \"hand\"\n",
            "name = \"hand\"\nstiffness = [[300, 0, 0, 0, 5, 0], [0, 300, 0, 0, 0, 0], [0, 0, 300, 0, 0, 0], [0, 0, 0, 20, 0, 0], [5, 0, 0, 0, 20, 0], [0, 0, 0, 0, 0, 20]]\n",
        );
    let s = load(&full).unwrap_or_else(|e| panic!("{e}"));
    assert_eq!(s.levels()[0].stiffness[(4, 0)], 5.0);

    // task = "pose": the same level as one task.
    let pose = STACKED.replacen(
        "name = \"hand\"\n",
        "name = \"hand\"\ntask = \"pose\"\nstiffness = [300, 300, 300, 20, 20, 20]\ndamping = [35, 35, 35, 9, 9, 9]\ngoal = [0.48, 0.0, 0.41, 3.0, 0.0, 0.0]\n",
        1,
    );
    let pose = pose[..pose.find("[[level.task]]").unwrap()].to_string()
        + &pose[pose.find("[[level]]\ntask = \"joint\"").unwrap()..];
    let s = load(&pose).unwrap_or_else(|e| panic!("{e}"));
    assert!(matches!(s.levels()[0].tasks[..], [TaskSpec::Pose { .. }]));
    assert_eq!(s.levels()[0].name, "hand");
    assert_eq!(s.levels()[0].damping[(4, 4)], 9.0);

    // The comparison form.
    let kin = STACKED.replace(
        "[initial]",
        "[controller]\nform = \"kinematic_projector\"\n\n[initial]",
    );
    let s = load(&kin).unwrap_or_else(|e| panic!("{e}"));
    assert_eq!(s.spec.form, hcc_config::Form::KinematicProjector);
}

#[test]
fn malformed_stacked_levels_name_the_field() {
    let cases: Vec<(&str, String, &str)> = vec![
        (
            "gain for the level and a task",
            STACKED.replacen(
                "name = \"hand\"\n",
                "name = \"hand\"\nstiffness = 300.0\n",
                1,
            ),
            "level[0].task[0].stiffness",
        ),
        (
            "missing task gain",
            STACKED.replacen("damping = 9.0\n", "", 1),
            "level[0].task[1].damping",
        ),
        (
            "task gain of the wrong size",
            STACKED.replacen(
                "stiffness = [20.0, 20.0, 20.0]",
                "stiffness = [20.0, 20.0]",
                1,
            ),
            "level[0].task[1].stiffness",
        ),
        (
            "frame on a stacked level",
            STACKED.replacen(
                "name = \"hand\"\n",
                "name = \"hand\"\nframe = \"panda_hand_tcp\"\n",
                1,
            ),
            "level[0].frame",
        ),
        (
            "unknown frame in a task table",
            STACKED.replacen(
                "kind = \"orientation\"",
                "kind = \"orientation\"\nframe = \"nowhere\"",
                1,
            ),
            "level[0].task[1].frame",
        ),
        (
            "unknown task kind in a table",
            STACKED.replacen("kind = \"orientation\"", "kind = \"torque\"", 1),
            "level[0].task",
        ),
        (
            "unknown key in a task table",
            STACKED.replacen(
                "kind = \"orientation\"",
                "kind = \"orientation\"\ngain = 1.0",
                1,
            ),
            "level[0].task",
        ),
        (
            "missing goal of a single-task level",
            STACKED.replacen("goal = [0.0, -0.3, 0.0, -2.2, 0.0, 2.0, 0.8]\n", "", 1),
            "level[1].goal",
        ),
        (
            "kinematic projector with three levels",
            edit(
                "coriolis_cancellation = true",
                "coriolis_cancellation = true\nform = \"kinematic_projector\"",
            ),
            "controller.form",
        ),
    ];
    let mut failures = Vec::new();
    for (name, text, field) in cases {
        match load(&text) {
            Ok(_) => failures.push(format!("{name}: loaded without error")),
            Err(e) if !e.to_string().contains(field) => {
                failures.push(format!("{name}: message does not name {field:?}: {e}"))
            }
            Err(_) => {}
        }
    }
    assert!(failures.is_empty(), "{}", failures.join("\n"));
}

/// `[safety]`: every field optional, the defaults of `hcc_spec::SafetySpec` (the
/// control period from the control rate), bad values named.
#[test]
fn safety_section() {
    let s = load(BASE).unwrap();
    let d = hcc_spec::SafetySpec::default();
    assert_eq!(s.spec.safety, d);
    let text = format!("{BASE}\n[safety]\njoint_limit_margin = 0.05\nnull_space_damping = 10.0\n");
    let s = load(&text).unwrap();
    assert_eq!(s.spec.safety.joint_limit_margin, 0.05);
    assert_eq!(s.spec.safety.null_space_damping, 10.0);
    assert_eq!(s.spec.safety.velocity_damping, d.velocity_damping);
    let bad = format!("{BASE}\n[safety]\njoint_limit_margin = -1.0\n");
    let e = load(&bad).unwrap_err().to_string();
    assert!(e.contains("safety.joint_limit_margin"), "{e}");
    let off = format!("{BASE}\n[safety]\nconflict_fade_ratio = 0.0\n");
    assert_eq!(load(&off).unwrap().spec.safety.conflict_fade_ratio, 0.0);
    for v in ["-1e-5", "0.5"] {
        let bad = format!("{BASE}\n[safety]\nconflict_fade_ratio = {v}\n");
        let e = load(&bad).unwrap_err().to_string();
        assert!(e.contains("safety.conflict_fade_ratio"), "{e}");
    }
    let unknown = format!("{BASE}\n[safety]\nmargin = 1.0\n");
    assert!(load(&unknown).is_err());
}
