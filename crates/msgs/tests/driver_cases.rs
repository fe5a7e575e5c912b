//! The driver contract logic against the cases shared with the Python
//! implementation (`tests/data/driver_cases.json`, also run by
//! `python/tests/test_driver_cases.py`): both languages agree on every branch.

use hcc_msgs::driver::{
    Action, CommandRejection, DriverLogic, DriverSettings, Gravity, Offer, StopMode, StopReason,
};
use hcc_msgs::{
    COMMAND_FLAG_GRAVITY_INCLUDED, DriverStatus, JointState, MAX_JOINTS, TorqueCommand,
};
use serde_json::Value;

fn num(v: &Value) -> f64 {
    match v {
        Value::String(s) => match s.as_str() {
            "inf" => f64::INFINITY,
            "-inf" => f64::NEG_INFINITY,
            "nan" => f64::NAN,
            other => panic!("not a number: {other:?}"),
        },
        other => other
            .as_f64()
            .unwrap_or_else(|| panic!("not a number: {other}")),
    }
}

fn nums(v: &Value) -> Vec<f64> {
    v.as_array().expect("an array").iter().map(num).collect()
}

fn int(v: &Value) -> u64 {
    v.as_u64().unwrap_or_else(|| panic!("not an integer: {v}"))
}

fn settings(s: &Value) -> DriverSettings {
    let n = int(&s["n"]) as usize;
    let mut damping = [0.0; MAX_JOINTS];
    damping[..n].copy_from_slice(&nums(&s["fallback_damping"]));
    DriverSettings {
        n,
        late_tolerance: int(&s["late_tolerance"]),
        // The cases describe a robot driver (the example driver's and
        // hcc.Driver's policy): sequence checks, a fallback timeout, misses
        // counted from the start, the robot's own safe stop.
        check_sequence: true,
        hold_cycles: int(&s["hold_cycles"]),
        fallback_timeout_cycles: Some(int(&s["fallback_timeout_cycles"])),
        wait_for_first_command: false,
        fallback_damping: damping,
        gravity: if s["compensates_gravity"].as_bool().expect("a bool") {
            Gravity::RobotAdds
        } else {
            Gravity::ControllerSends
        },
        stop_mode: StopMode::SafeStop,
    }
}

fn status(name: &str) -> DriverStatus {
    match name {
        "ok" => DriverStatus::Ok,
        "fallback_active" => DriverStatus::FallbackActive,
        "stopping" => DriverStatus::Stopping,
        "stopped" => DriverStatus::Stopped,
        other => panic!("unknown status {other:?}"),
    }
}

fn action(name: &str) -> Action {
    match name {
        "apply" => Action::Apply,
        "hold" => Action::Hold,
        "fallback" => Action::Fallback,
        "stop_first" => Action::Stop { first: true },
        "stop" => Action::Stop { first: false },
        other => panic!("unknown action {other:?}"),
    }
}

fn stop_reason(name: &str) -> StopReason {
    match name {
        "commanded" => StopReason::Commanded,
        "fallback_timeout" => StopReason::FallbackTimeout,
        "requested" => StopReason::Requested,
        other => panic!("unknown stop reason {other:?}"),
    }
}

fn offer_result(o: Offer) -> String {
    match o {
        Offer::Applicable { current: true } => "applicable_current".into(),
        Offer::Applicable { current: false } => "applicable_late".into(),
        Offer::Rejected(CommandRejection::Old) => "old".into(),
        Offer::Rejected(CommandRejection::Invalid(_)) => "invalid".into(),
        Offer::Rejected(CommandRejection::GravityConflict(_)) => "gravity_conflict".into(),
        Offer::Rejected(CommandRejection::Future) => "future".into(),
        Offer::Rejected(CommandRejection::TooLate { cycles }) => format!("too_late:{cycles}"),
    }
}

fn build_command(step: &Value, latest: &JointState) -> TorqueCommand {
    let mut c = TorqueCommand::zeroed();
    let tau = nums(&step["tau"]);
    c.header.n_joints = tau.len() as u32;
    c.tau[..tau.len()].copy_from_slice(&tau);
    c.header.seq = int(&step["seq"]);
    c.state_seq = step.get("answers").map_or(latest.header.seq, int);
    c.state_stamp_ns = latest.header.stamp_ns;
    c.mode = int(&step["mode"]) as u32;
    c.flags = match step.get("flags") {
        None if latest.driver_compensates_gravity() => 0,
        None => COMMAND_FLAG_GRAVITY_INCLUDED,
        Some(f) => int(f) as u32,
    };
    if let Some(n) = step.get("n_joints") {
        c.header.n_joints = int(n) as u32;
    }
    if let Some(v) = step.get("schema_version") {
        c.header.schema_version = int(v) as u32;
    }
    c
}

fn check(logic: &DriverLogic, expect: &Value, at: &str) {
    if let Some(s) = expect.get("status") {
        assert_eq!(logic.status(), status(s.as_str().unwrap()), "{at}: status");
    }
    if let Some(v) = expect.get("missed_commands") {
        assert_eq!(logic.missed_commands(), int(v), "{at}: missed_commands");
    }
    if let Some(v) = expect.get("fallback_cycles") {
        assert_eq!(logic.fallback_cycles(), int(v), "{at}: fallback_cycles");
    }
    if let Some(v) = expect.get("applied") {
        assert_eq!(logic.applied(), int(v), "{at}: applied");
    }
    if let Some(v) = expect.get("stop_reason") {
        let want = stop_reason(v.as_str().unwrap());
        assert_eq!(logic.stop_reason(), Some(want), "{at}: stop_reason");
    }
    if let Some(r) = expect.get("rejections") {
        let got = logic.rejections();
        for (key, value) in [
            ("old", got.old),
            ("invalid", got.invalid),
            ("gravity_conflict", got.gravity_conflict),
            ("future", got.future),
            ("too_late", got.too_late),
        ] {
            assert_eq!(value, int(&r[key]), "{at}: rejections.{key}");
        }
    }
}

fn publish(logic: &mut DriverLogic, step: &Value, latest: &mut JointState, at: &str) {
    let mut msg = JointState::zeroed();
    let result = logic.fill_state(
        &mut msg,
        &nums(&step["q"]),
        &nums(&step["qd"]),
        &nums(&step["tau"]),
        int(&step["stamp_ns"]),
    );
    let expect = &step["expect"];
    if expect == "error" {
        assert!(result.is_err(), "{at}: expected an error");
        return;
    }
    let seq = result.unwrap_or_else(|e| panic!("{at}: {e}"));
    assert_eq!(seq, int(&expect["seq"]), "{at}: seq");
    assert_eq!(msg.header.seq, seq, "{at}: header.seq");
    let want = status(expect["status"].as_str().unwrap());
    assert_eq!(msg.status(), Ok(want), "{at}: status");
    assert_eq!(u64::from(msg.flags), int(&expect["flags"]), "{at}: flags");
    assert_eq!(msg.missed_commands, int(&expect["missed_commands"]), "{at}");
    assert_eq!(msg.fallback_cycles, int(&expect["fallback_cycles"]), "{at}");
    *latest = msg;
}

fn run_case(case: &Value) {
    let name = case["name"].as_str().expect("a name");
    let s = settings(&case["settings"]);
    let n = s.n;
    let mut logic = DriverLogic::new(s);
    let mut latest = JointState::zeroed();
    let mut last: Option<TorqueCommand> = None;
    for (i, step) in case["steps"].as_array().expect("steps").iter().enumerate() {
        let op = step["op"].as_str().expect("an op");
        let at = format!("{name}: step {i} ({op})");
        let expect = &step["expect"];
        match op {
            "publish" => publish(&mut logic, step, &mut latest, &at),
            "offer" => {
                let c = build_command(step, &latest);
                let got = offer_result(logic.offer(&c, latest.header.seq));
                assert_eq!(got, expect.as_str().unwrap(), "{at}");
                last = Some(c);
            }
            "decide" => {
                let command = if step["command"] == "last" {
                    last.as_ref()
                } else {
                    None
                };
                let (qd, g) = (nums(&step["qd"]), nums(&step["gravity"]));
                let mut tau = vec![f64::NAN; n];
                let got = logic.decide(command, &qd, |out| out.copy_from_slice(&g), &mut tau);
                assert_eq!(got, action(expect["action"].as_str().unwrap()), "{at}");
                assert_eq!(tau, nums(&expect["tau"]), "{at}: tau");
                check(&logic, expect, &at);
            }
            "request_stop" => {
                let want = action(expect.as_str().unwrap());
                assert_eq!(logic.request_stop(), want, "{at}");
            }
            "stop_completed" => logic.stop_completed(),
            "check" => check(&logic, expect, &at),
            other => panic!("{at}: unknown op {other:?}"),
        }
    }
}

#[test]
fn shared_driver_cases() {
    let path = concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/../../tests/data/driver_cases.json"
    );
    let text = std::fs::read_to_string(path).unwrap_or_else(|e| panic!("{path}: {e}"));
    let doc: Value = serde_json::from_str(&text).expect("valid JSON");
    let cases = doc["cases"].as_array().expect("cases");
    assert!(cases.len() >= 10, "the case file lost its cases");
    for case in cases {
        run_case(case);
    }
}
