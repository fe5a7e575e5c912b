//! `[[setpoint]]`: the schedule is checked at load (errors name the field),
//! sorted by time, and absent by default.

use hcc_config::Scenario;
use hcc_config::schedule::SCHEDULE_CLIENT_ID;
use hcc_msgs::{SETPOINT_DAMPING, SETPOINT_GOAL, SETPOINT_STIFFNESS};
use std::path::PathBuf;

fn load(extra: &str) -> Result<Scenario, hcc_config::ConfigError> {
    let path = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../config/paper-sim1.toml");
    let text = std::fs::read_to_string(&path).unwrap() + extra;
    Scenario::from_toml_str(&text, &path)
}

#[test]
fn no_schedule_by_default() {
    assert!(load("").unwrap().setpoints.is_empty());
}

#[test]
fn entries_are_built_and_sorted_by_time() {
    let s = load(
        "\n[[setpoint]]\nt = 2.0\nlevel = 1\ngoal = [0.5, 0.6]\nduration = 1.0\n\
         \n[[setpoint]]\nt = 0.5\nlevel = 1\nstiffness = [800, 100, 100, 800]\ndamping = [40, 40]\n",
    )
    .unwrap();
    let sp = &s.setpoints;
    assert_eq!(sp.len(), 2);
    assert_eq!((sp[0].t_s, sp[1].t_s), (0.5, 2.0));
    let (a, b) = (&sp[0].setpoint, &sp[1].setpoint);
    assert_eq!(a.level, 0, "1-based in the file, 0-based in the message");
    assert_eq!(a.fields, SETPOINT_STIFFNESS | SETPOINT_DAMPING);
    assert!(a.stiffness_full() && !a.damping_full());
    assert_eq!(b.fields, SETPOINT_GOAL);
    assert_eq!(b.goal(), &[0.5, 0.6]);
    assert_eq!(b.duration_s, 1.0);
    assert_eq!((a.header.seq, b.header.seq), (1, 2));
    assert!(
        sp.iter()
            .all(|s| s.setpoint.client_id == SCHEDULE_CLIENT_ID)
    );
    // The cycle that takes it: the first k with k · T ≥ t.
    assert_eq!(sp[1].cycle(1000.0), 2000);
    let mut late = sp[1];
    late.t_s = 2.0004;
    assert_eq!(late.cycle(1000.0), 2001);
}

#[test]
fn bad_entries_name_the_field() {
    for (extra, field) in [
        ("t = -1.0\nlevel = 1\ngoal = [0.5, 0.6]", "setpoint[0].t"),
        ("t = 1.0\nlevel = 0\ngoal = [0.5, 0.6]", "setpoint[0].level"),
        ("t = 1.0\nlevel = 9\ngoal = [0.5, 0.6]", "setpoint[0].level"),
        ("t = 1.0\nlevel = 1\ngoal = [0.5]", "setpoint[0].goal"),
        ("t = 1.0\nlevel = 1\ngoal = [0.5, nan]", "setpoint[0].goal"),
        (
            "t = 1.0\nlevel = 1\nvelocity = [0.1, 0.0]",
            "setpoint[0].velocity",
        ),
        (
            "t = 1.0\nlevel = 1\nstiffness = [800, -1]",
            "setpoint[0].stiffness",
        ),
        (
            "t = 1.0\nlevel = 1\nstiffness = [800, 1, 2, 800]",
            "setpoint[0].stiffness",
        ),
        (
            // Symmetric and indefinite (eigenvalues 3 and -1).
            "t = 1.0\nlevel = 1\ndamping = [1, 2, 2, 1]",
            "setpoint[0].damping",
        ),
        (
            "t = 1.0\nlevel = 1\ndamping = [1, 2, 3]",
            "setpoint[0].damping",
        ),
        (
            "t = 1.0\nlevel = 1\ngoal = [0.5, 0.6]\nduration = -2.0",
            "setpoint[0].duration",
        ),
        ("t = 1.0\nlevel = 1", "setpoint[0]"),
    ] {
        let e = load(&format!("\n[[setpoint]]\n{extra}\n"))
            .unwrap_err()
            .to_string();
        assert!(e.contains(field), "{extra}: {e}");
    }
    // The index is the entry's place in the file.
    let e = load("\n[[setpoint]]\nt = 1.0\nlevel = 2\ngoal = [0.1]\n\n[[setpoint]]\nt = 0.5\nlevel = 3\ngoal = [0.1, 0.2]\n")
        .unwrap_err()
        .to_string();
    assert!(e.contains("setpoint[1].goal"), "{e}");
    assert!(load("\n[[setpoint]]\nt = 1.0\nlevel = 1\nunknown = 1\n").is_err());
}
