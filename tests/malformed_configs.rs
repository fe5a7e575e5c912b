//! Malformed scenario files through the real binaries: each of the cases
//! below makes `hcc-controller`, `hcc-sim` and `hcc simulate` exit with a
//! non-zero code (not a panic, not a signal) and an error that names the
//! file, the offending field and, where the TOML has one, its line. No
//! daemon is left running and no shared memory is created.
//!
//! The cases are edits of `config/paper-sim1.toml`. A configured CPU core
//! that this machine does not offer is an error of the daemons that would
//! pin to it (checked at their start-up); `hcc simulate`, which pins
//! nothing, accepts such a file (`Scenario::check_cpu_core`).

use std::path::{Path, PathBuf};
use std::process::Command;
use std::time::{Duration, Instant};

use hcc_system_tests::*;

/// Which binaries a case is run through.
#[derive(Clone, Copy, PartialEq)]
enum Via {
    All,
    /// Only the daemons (a `[controller_daemon]`/`[sim_daemon]` setting
    /// checked at their start-up).
    Controller,
    Sim,
}

struct Case {
    name: &'static str,
    /// The scenario text, or None for a file that does not exist.
    text: Option<String>,
    /// Must appear in the error (the dotted field path, or the file name).
    field: &'static str,
    /// A substring of the offending line of `text`: the error must name that line.
    line_of: Option<&'static str>,
    via: Via,
}

fn base() -> String {
    std::fs::read_to_string(repo_root().join("config/paper-sim1.toml")).unwrap()
}

/// `base` with the first `from` replaced by `to`.
fn edit(from: &str, to: &str) -> String {
    let b = base();
    assert!(b.contains(from), "paper-sim1.toml has no {from:?}");
    b.replacen(from, to, 1)
}

fn append(extra: &str) -> String {
    format!("{}\n{extra}\n", base())
}

fn case(
    name: &'static str,
    text: String,
    field: &'static str,
    line_of: Option<&'static str>,
) -> Case {
    Case {
        name,
        text: Some(text),
        field,
        line_of,
        via: Via::All,
    }
}

fn cases() -> Vec<Case> {
    let mut v = vec![
        Case {
            name: "missing file",
            text: None,
            field: "does-not-exist.toml",
            line_of: None,
            via: Via::All,
        },
        case("empty file", String::new(), "robot", None),
        case(
            "TOML syntax error",
            edit("goal = [0.90, 0.80]", "goal = [0.90, 0.80"),
            "level[0].goal",
            // The parser stops at the next table header, still inside the array.
            Some("[[level]]\nname = \"TCP rotation\""),
        ),
        case(
            "unknown top-level field",
            edit("name = \"paper-sim1\"", "name = \"paper-sim1\"\nnmae = \"typo\""),
            "nmae",
            Some("nmae = "),
        ),
        case(
            "unknown field in a level",
            edit("stiffness = 800.0", "stiffnes = 800.0"),
            "level[1].stiffnes",
            Some("stiffnes = 800.0"),
        ),
        case(
            "unknown field in [controller_daemon]",
            append("[controller_daemon]\nstale_timeout = 3.0"),
            "controller_daemon.stale_timeout",
            Some("stale_timeout = 3.0"),
        ),
        case(
            "unknown field in [sim_daemon]",
            append("[sim_daemon]\nhold_cycle = 3"),
            "sim_daemon.hold_cycle",
            Some("hold_cycle = 3"),
        ),
        case(
            "missing tip link",
            edit("tip_link = \"tcp\"\n", ""),
            "tip_link",
            None,
        ),
        case(
            "wrong type",
            edit("coriolis_cancellation = true", "coriolis_cancellation = \"yes\""),
            "controller.coriolis_cancellation",
            Some("coriolis_cancellation = \"yes\""),
        ),
        case(
            "q0 of the wrong length",
            edit("q0 = [0.3999999999999999, ", "q0 = ["),
            "initial.q0",
            Some("q0 = ["),
        ),
        case(
            "gravity of the wrong length",
            edit("gravity = [0.0, -9.81, 0.0]", "gravity = [0.0, -9.81]"),
            "robot.gravity",
            Some("gravity = [0.0, -9.81]"),
        ),
        case(
            "stiffness diagonal of the wrong length",
            edit("stiffness = [1000.0, 1000.0]", "stiffness = [1000.0, 1000.0, 1000.0]"),
            "level[0].stiffness",
            Some("stiffness = [1000.0, 1000.0, 1000.0]"),
        ),
        case(
            "negative stiffness",
            edit("stiffness = 800.0", "stiffness = -800.0"),
            "level[1].stiffness",
            Some("stiffness = -800.0"),
        ),
        case(
            "negative damping",
            edit("damping = 15.0", "damping = -15.0"),
            "level[2].damping",
            Some("damping = -15.0"),
        ),
        case(
            "non-symmetric stiffness",
            edit(
                "stiffness = [1000.0, 1000.0]",
                "stiffness = [[1000.0, 50.0], [0.0, 1000.0]]",
            ),
            "level[0].stiffness",
            Some("stiffness = [[1000.0, 50.0]"),
        ),
        case(
            "non-symmetric damping",
            edit("damping = [40.0, 40.0]", "damping = [[40.0, 0.0], [5.0, 40.0]]"),
            "level[0].damping",
            Some("damping = [[40.0, 0.0]"),
        ),
        case(
            "indefinite damping",
            edit("damping = [40.0, 40.0]", "damping = [[1.0, 2.0], [2.0, 1.0]]"),
            "level[0].damping",
            Some("damping = [[1.0, 2.0]"),
        ),
        case(
            "goal of the wrong length",
            edit("goal = [0.90, 0.80]", "goal = [0.90]"),
            "level[0].goal",
            Some("goal = [0.90]"),
        ),
        case(
            "goal not finite",
            edit("goal = [0.90, 0.80]", "goal = [nan, 0.80]"),
            "level[0].goal[0]",
            Some("goal = [nan, 0.80]"),
        ),
        case(
            "unknown link as a task frame",
            edit("frame = \"tcp\"", "frame = \"hand\""),
            "level[0].frame",
            Some("frame = \"hand\""),
        ),
        case(
            "unknown tip link",
            edit("tip_link = \"tcp\"", "tip_link = \"gripper\""),
            "robot",
            Some("tip_link = \"gripper\""),
        ),
        case(
            "unknown root link",
            edit("root_link = \"base\"", "root_link = \"world\""),
            "robot",
            Some("root_link = \"world\""),
        ),
        case(
            "missing URDF",
            edit("urdf = \"planar4.urdf\"", "urdf = \"planar5.urdf\""),
            "planar5.urdf",
            Some("urdf = "),
        ),
        case(
            "unknown joint",
            edit("joints = [\"joint1\"]", "joints = [\"joint7\"]"),
            "level[2].joints[0]",
            Some("joints = [\"joint7\"]"),
        ),
        case(
            "joint listed twice",
            edit("joints = [\"joint1\"]", "joints = [\"joint1\", \"joint1\"]"),
            "level[2].joints[1]",
            Some("joints = [\"joint1\", \"joint1\"]"),
        ),
        case(
            "unknown task kind",
            edit("task = \"joint\"", "task = \"force\""),
            "level[2].task",
            Some("task = \"force\""),
        ),
        case(
            "field not used by the task",
            edit("task = \"joint\"", "task = \"joint\"\nframe = \"tcp\""),
            "level[2].frame",
            None,
        ),
        case(
            "hierarchy: no null space left below level 1",
            edit(
                "task = \"position\"\nframe = \"tcp\"\naxes = [\"x\", \"y\"]\nstiffness = [1000.0, 1000.0]  # K1, N/m\ndamping = [40.0, 40.0]  # D1, Ns/m\ngoal = [0.90, 0.80]",
                "task = \"joint\"\nstiffness = 100.0\ndamping = 10.0\ngoal = [0.0, 0.0, 0.0, 0.0]",
            ),
            "level[1]",
            None,
        ),
        case(
            "hierarchy: levels 1-2 use every degree of freedom",
            edit("axes = [\"z\"]", "axes = [\"z\"]\n# (made 2-D below)")
                .replacen(
                    "task = \"orientation\"\nframe = \"tcp\"\naxes = [\"z\"]\n# (made 2-D below)\nstiffness = 800.0  # K2, Nm/rad\ndamping = 5.0  # D2, Nms/rad\ngoal = [-1.57]",
                    "task = \"joint\"\njoints = [\"joint3\", \"joint4\"]\nstiffness = 800.0\ndamping = 5.0\ngoal = [0.0, 0.0]",
                    1,
                ),
            "level[2]",
            None,
        ),
        case(
            "singular_ratio out of range",
            edit("form = \"extended\"", "form = \"extended\"\nsingularity = { singular_ratio = 1.5 }"),
            "controller.singularity.singular_ratio",
            Some("singularity = {"),
        ),
        case(
            "zero control rate",
            edit("rate_hz = 1000.0", "rate_hz = 0.0"),
            "controller.rate_hz",
            Some("rate_hz = 0.0"),
        ),
        case(
            "integrator step not dividing the period",
            edit("integrator_dt_s = 1e-4", "integrator_dt_s = 3e-4"),
            "simulation.integrator_dt_s",
            Some("integrator_dt_s = 3e-4"),
        ),
        case(
            "negative duration",
            edit("duration_s = 3.0", "duration_s = -3.0"),
            "simulation.duration_s",
            Some("duration_s = -3.0"),
        ),
        case(
            "negative friction",
            edit("joint_friction = 0.0", "joint_friction = [0.1, -0.1, 0.1, 0.1]"),
            "simulation.joint_friction[1]",
            Some("joint_friction = "),
        ),
        case(
            "wrench on an unknown link",
            edit(
                "joint_friction = 0.0",
                "joint_friction = 0.0\n\n[[simulation.wrench]]\nstart_s = 0.5\nduration_s = 0.1\nlink = \"gripper\"\nforce = [1.0, 0.0, 0.0]",
            ),
            "simulation.wrench[0].link",
            Some("link = \"gripper\""),
        ),
        case(
            "SCHED_FIFO priority out of range",
            append("[controller_daemon]\nsched_priority = 100"),
            "controller_daemon.sched_priority",
            Some("sched_priority = 100"),
        ),
        case(
            "negative torque limit",
            append("[controller_daemon]\ntorque_limits = [50.0, -1.0, 50.0, 50.0]"),
            "controller_daemon.torque_limits[1]",
            Some("torque_limits = "),
        ),
        case(
            "zero stale timeout",
            append("[controller_daemon]\nstale_timeout_ms = 0.0"),
            "controller_daemon.stale_timeout_ms",
            Some("stale_timeout_ms = 0.0"),
        ),
        case(
            "CPU core beyond any CPU index",
            append("[controller_daemon]\ncpu_core = 5000"),
            "controller_daemon.cpu_core",
            Some("cpu_core = 5000"),
        ),
        case(
            "negative fallback damping",
            append("[sim_daemon]\nfallback_damping = -2.0"),
            "sim_daemon.fallback_damping",
            Some("fallback_damping = -2.0"),
        ),
        case(
            "invalid namespace",
            edit("namespace = \"hcc_sim1\"", "namespace = \"hcc/sim1\""),
            "ipc.namespace",
            Some("namespace = \"hcc/sim1\""),
        ),
    ];
    // CPU cores this machine does not offer: errors of the daemon that pins.
    v.push(Case {
        name: "unreachable CPU core of the controller",
        text: Some(append("[controller_daemon]\ncpu_core = 1000")),
        field: "controller_daemon.cpu_core",
        line_of: Some("cpu_core = 1000"),
        via: Via::Controller,
    });
    v.push(Case {
        name: "unreachable CPU core of the simulator",
        text: Some(append("[sim_daemon]\ncpu_core = 1000")),
        field: "sim_daemon.cpu_core",
        line_of: Some("cpu_core = 1000"),
        via: Via::Sim,
    });
    v
}

/// 1-based line where `needle` (which may span lines) first starts in `text`.
fn line_of(text: &str, needle: &str) -> usize {
    let at = text
        .find(needle)
        .unwrap_or_else(|| panic!("the case has no {needle:?}"));
    text[..at].matches('\n').count() + 1
}

/// The scenario file of a case: the edited text with the URDF path made absolute.
fn write_case(dir: &Path, k: usize, text: &str) -> PathBuf {
    let urdf = repo_root().join("config");
    let text = text.replace("urdf = \"", &format!("urdf = \"{}/", urdf.display()));
    let path = dir.join(format!("case{k:02}.toml"));
    std::fs::write(&path, text).unwrap();
    path
}

#[test]
fn malformed_configs_fail_every_binary_with_the_field_and_line() {
    let dir = TempDir::new("malformed");
    let ns = unique_namespace("malformed");
    let prefix = unique_file_prefix();
    let all = cases();
    assert!(all.len() >= 30, "{} cases", all.len());
    let start = Instant::now();
    let mut failures = Vec::new();
    let mut runs = 0;
    for (k, c) in all.iter().enumerate() {
        let path = match &c.text {
            Some(t) => write_case(dir.path(), k, t),
            None => dir.path().join("does-not-exist.toml"),
        };
        let line = c.line_of.map(|needle| {
            let written = std::fs::read_to_string(&path).unwrap();
            line_of(&written, needle)
        });
        let mut commands: Vec<(&str, Command)> = Vec::new();
        if matches!(c.via, Via::All | Via::Controller) {
            let mut cmd = Command::new(bin("hcc-controller"));
            cmd.arg(&path).args(["--namespace", &ns]);
            commands.push(("hcc-controller", cmd));
        }
        if matches!(c.via, Via::All | Via::Sim) {
            let mut cmd = Command::new(bin("hcc-sim"));
            cmd.arg(&path)
                .args(["--namespace", &ns, "--realtime", "--duration", "0.1"]);
            commands.push(("hcc-sim", cmd));
        }
        if c.via == Via::All {
            let mut cmd = Command::new(bin("hcc"));
            cmd.arg("simulate")
                .arg(&path)
                .arg("--out")
                .arg(dir.path().join(format!("out{k:02}")))
                .arg("--no-plots");
            commands.push(("hcc simulate", cmd));
        }
        for (binary, mut cmd) in commands {
            runs += 1;
            cmd.env(FILE_PREFIX_ENV, &prefix);
            let tag = format!("case{k:02}_{}", binary.replace(' ', "_"));
            let out = run_with_timeout(&mut cmd, dir.path(), &tag, Duration::from_secs(60));
            let err = out.stderr.trim_end();
            let problem = if out.status.success() {
                Some("succeeded".to_string())
            } else if out.status.code().is_none() {
                Some(format!("was killed by a signal ({:?})", out.status))
            } else if out.status.code() == Some(101) || err.contains("panicked") {
                Some("panicked".to_string())
            } else if !err.contains(c.field) {
                Some(format!("does not name {:?}", c.field))
            } else if !err.contains(&path.file_name().unwrap().to_string_lossy().to_string()) {
                Some("does not name the file".to_string())
            } else if let Some(l) = line
                && !err.contains(&format!(".toml:{l}:"))
            {
                Some(format!("does not name line {l}"))
            } else {
                None
            };
            match problem {
                Some(p) => failures.push(format!("{} via {binary}: {p}\n    {err}", c.name)),
                None if k % 7 == 0 => println!(
                    "{:>45} via {binary:<14} exit {:?}: {err}",
                    c.name,
                    out.status.code().unwrap()
                ),
                None => {}
            }
        }
    }
    println!(
        "{} cases, {runs} runs of the binaries in {:.1} s",
        all.len(),
        start.elapsed().as_secs_f64()
    );
    assert!(
        failures.is_empty(),
        "{} failures:\n{}",
        failures.len(),
        failures.join("\n")
    );
    // Nothing is left: no process of the namespace or the cases, no shared memory.
    let cases_dir = dir.path().to_string_lossy().to_string();
    assert!(
        processes_with(&cases_dir).is_empty(),
        "{:?}",
        processes_with(&cases_dir)
    );
    assert_clean(&ns, &prefix);
}
