"""The ctypes mirrors have exactly the Rust layout, names and settings.

Rust prints its own figures (``cargo run -p hcc-msgs --example layout``,
std::mem::offset_of!); every struct's size, alignment, field offsets and
iceoryx2 type name, the capacities, service names, service settings, flag
bits, setpoint constants and rejection codes (with their names and reasons)
are compared here, so the two sides can never drift silently. The Python
mirror of ``Setpoint::validate`` is checked on the cases of the Rust tests.
"""

from __future__ import annotations

import ctypes
import json
from typing import Any

import pytest

from hcc import ipc, msgs

from conftest import cargo_json


@pytest.fixture(scope="module")
def rust() -> dict[str, Any]:
    return json.loads(cargo_json("run", "-q", "-p", "hcc-msgs", "--example", "layout"))


def test_constants(rust: dict[str, Any]) -> None:
    assert rust["driver_schema_version"] == msgs.DRIVER_SCHEMA_VERSION
    assert rust["client_schema_version"] == msgs.CLIENT_SCHEMA_VERSION
    assert rust["max_joints"] == msgs.MAX_JOINTS
    assert rust["max_levels"] == msgs.MAX_LEVELS
    assert rust["max_task_dim"] == msgs.MAX_TASK_DIM
    assert rust["ipc_file_prefix_env"] == ipc.FILE_PREFIX_ENV
    flags = rust["flags"]
    assert flags["state_driver_gravity_compensation"] == msgs.STATE_FLAG_DRIVER_GRAVITY_COMPENSATION
    assert flags["state_driver_polls_commands"] == msgs.STATE_FLAG_DRIVER_POLLS_COMMANDS
    assert flags["state_flags_known"] == msgs.STATE_FLAGS_KNOWN
    assert flags["command_gravity_included"] == msgs.COMMAND_FLAG_GRAVITY_INCLUDED
    assert flags["telemetry_peer_lost"] == msgs.TELEMETRY_FLAG_PEER_LOST
    assert flags["telemetry_contact"] == msgs.TELEMETRY_FLAG_CONTACT
    assert flags["telemetry_contact_hold"] == msgs.TELEMETRY_FLAG_CONTACT_HOLD
    for key in [
        "setpoint_goal", "setpoint_velocity", "setpoint_stiffness", "setpoint_damping",
        "setpoint_fields_known", "gain_stiffness_full", "gain_damping_full", "gain_layout_known",
        "path_new", "path_extend", "path_flags_known",
    ]:
        assert flags[key] == getattr(msgs, key.upper()), key
    assert len(flags) == 18, "a flag is not compared"
    setpoint = rust["setpoint"]
    assert set(setpoint) == {
        "max_setpoint_clients", "max_pending_setpoints", "max_gain_entries", "max_transition_s",
        "symmetry_tolerance", "answer_accepted", "max_knots_per_message", "max_path_columns",
    }
    for key, value in setpoint.items():
        assert getattr(msgs, key.upper()) == value, key


def test_rejection_codes_names_and_reasons(rust: dict[str, Any]) -> None:
    codes = rust["rejections"]
    assert [r["code"] for r in codes] == [r.value for r in msgs.SetpointRejection]
    for r in codes:
        mine = msgs.SetpointRejection(r["code"])
        assert mine.label == r["name"], r
        assert mine.reason == r["reason"], r
        assert str(mine) == f"{r['name']} (code {r['code']}): {r['reason']}"
        assert msgs.SetpointRejection.from_code(r["code"]) is mine
    assert msgs.SetpointRejection.from_code(msgs.ANSWER_ACCEPTED) is None
    assert msgs.SetpointRejection.from_code(len(codes) + 1) is None


def test_path_rejection_codes_names_and_reasons(rust: dict[str, Any]) -> None:
    codes = rust["path_rejections"]
    assert [r["code"] for r in codes] == [r.value for r in msgs.PathRejection]
    for r in codes:
        mine = msgs.PathRejection(r["code"])
        assert (mine.label, mine.reason) == (r["name"], r["reason"]), r
        assert str(mine) == f"{r['name']} (code {r['code']}): {r['reason']}"
    assert msgs.PathRejection.from_code(200) is None


def test_load_rejection_codes_names_and_reasons(rust: dict[str, Any]) -> None:
    codes = rust["load_rejections"]
    assert [r["code"] for r in codes] == [r.value for r in msgs.LoadRejection]
    for r in codes:
        mine = msgs.LoadRejection(r["code"])
        assert (mine.label, mine.reason) == (r["name"], r["reason"]), r
        assert str(mine) == f"{r['name']} (code {r['code']}): {r['reason']}"
    assert msgs.LoadRejection.from_code(300) is None


def test_load_checks_mirror_the_rust_validate() -> None:
    """The cases of crates/msgs/src/load.rs, through the Python mirror."""
    ok = msgs.LoadSetpoint.of(1.0, (0.0, 0.0, 0.1))
    assert ok.check() is None
    L, S = msgs.LoadRejection, msgs.SetpointRejection
    for change, expected in [
        (lambda m: setattr(m, "mass", -1.0), L.NEGATIVE_MASS),
        (lambda m: setattr(m, "ramp_s", -0.1), L.BAD_RAMP),
        (lambda m: m.inertia.__setitem__(2, float("nan")), S.NON_FINITE),
        (lambda m: setattr(m.header, "schema_version", m.header.schema_version + 1), S.SCHEMA_MISMATCH),
    ]:
        m = msgs.LoadSetpoint.of(1.0, (0.0, 0.0, 0.1))
        change(m)
        assert m.check() is expected
    with pytest.raises(msgs.MsgError):
        msgs.LoadSetpoint.of(1.0, (0.0, 0.1))


def test_path_knots_checks_mirror_the_rust_validate() -> None:
    """The cases of crates/msgs/src/path.rs, through the Python mirror."""
    def knots() -> msgs.PathKnots:
        p = msgs.PathKnots.zeroed()
        p.flags = msgs.PATH_NEW
        p.level = 1
        for k in range(4):
            p.push(k * 0.1, [0.4, 0.01 * k, 0.3])
        return p

    assert knots().check() is None
    P, S = msgs.PathRejection, msgs.SetpointRejection
    cases = [
        (lambda p: setattr(p.header, "schema_version", p.header.schema_version + 1), S.SCHEMA_MISMATCH),
        (lambda p: setattr(p, "flags", msgs.PATH_NEW | msgs.PATH_EXTEND), P.BAD_FLAGS),
        (lambda p: setattr(p, "level", msgs.MAX_LEVELS), S.LEVEL_CAPACITY),
        (lambda p: setattr(p, "count", 0), P.KNOT_COUNT),
        (lambda p: p.values[2].__setitem__(1, float("nan")), S.NON_FINITE),
        (lambda p: p.t.__setitem__(2, p.t[1]), P.NOT_INCREASING),
        (lambda p: setattr(p, "columns", 0), P.COLUMN_MISMATCH),
    ]
    for edit, code in cases:
        p = knots()
        edit(p)
        assert p.check() is code, code
    p = knots()
    with pytest.raises(msgs.MsgError):
        p.push(1.0, [0.0, 0.0])


def test_every_struct_has_the_rust_layout(rust: dict[str, Any]) -> None:
    structs = rust["structs"]
    assert set(structs) == set(msgs.WIRE_TYPES), "a type is missing on one side"
    for name, spec in structs.items():
        t = msgs.WIRE_TYPES[name]
        assert t.type_name() == spec["type_name"], name
        assert ctypes.sizeof(t) == spec["size"], name
        assert ctypes.alignment(t) == spec["align"], name
        py_fields = [f[0] for f in t._fields_]
        assert py_fields == [f["name"] for f in spec["fields"]], name
        for f in spec["fields"]:
            assert getattr(t, f["name"]).offset == f["offset"], f"{name}.{f['name']}"


def test_service_names_and_settings(rust: dict[str, Any]) -> None:
    names = ipc.ServiceNames("NS")
    for key, value in rust["services"].items():
        assert getattr(names, key) == value, key
    for key, value in rust["settings"].items():
        assert getattr(ipc, key.upper()) == value, key


def test_bad_namespaces_are_refused() -> None:
    for bad in ["", "a/b", "-x", "x" * 65, "ü"]:
        with pytest.raises(ValueError):
            ipc.ServiceNames(bad)
    ipc.ServiceNames("Robot-1_a")
    ipc.ServiceNames("x" * 64)


def test_validation_mirrors_the_rust_checks() -> None:
    s = msgs.JointState.zeroed()
    s.set_joints([0.1, 0.2], [0.0, 0.0], [0.0, 0.0])
    s.validate(2)
    with pytest.raises(msgs.MsgError):
        s.validate(3)
    s.flags = msgs.STATE_FLAG_DRIVER_POLLS_COMMANDS
    s.validate(2)
    s.flags = 4
    with pytest.raises(msgs.MsgError):
        s.validate(2)
    with pytest.raises(msgs.MsgError):
        s.set_joints([float("nan")], [0.0], [0.0])
    c = msgs.TorqueCommand.zeroed()
    c.header.n_joints = 2
    c.validate(2)
    c.mode = 77
    with pytest.raises(msgs.MsgError):
        c.validate(2)
    c.mode = 0
    c.tau[1] = float("inf")
    with pytest.raises(msgs.MsgError):
        c.validate(2)
    c.tau[1] = 0.0
    c.header.schema_version = msgs.DRIVER_SCHEMA_VERSION + 1
    with pytest.raises(msgs.MsgError):
        c.validate(2)


def _goal(level: int, values: list[float]) -> msgs.Setpoint:
    s = msgs.Setpoint.zeroed()
    s.level = level
    s.fields = msgs.SETPOINT_GOAL
    s.dim = len(values)
    for k, v in enumerate(values):
        s.goal[k] = v
    return s


def _full_stiffness(m: int, a: list[float]) -> msgs.Setpoint:
    s = msgs.Setpoint.zeroed()
    s.fields = msgs.SETPOINT_STIFFNESS
    s.gain_layout = msgs.GAIN_STIFFNESS_FULL
    s.dim = m
    for k, v in enumerate(a):
        s.stiffness[k] = v
    return s


R = msgs.SetpointRejection


def test_setpoint_checks_mirror_the_rust_validate() -> None:
    """The cases of crates/msgs/src/setpoint.rs, through the Python mirror."""
    nan, inf = float("nan"), float("inf")
    assert _goal(1, [0.4, 0.1, 0.5]).check() is None
    s = _goal(0, [0.1] * msgs.MAX_TASK_DIM)
    s.fields |= msgs.SETPOINT_VELOCITY
    s.duration_s = 2.0
    assert s.check() is None
    # Header, fields and capacities.
    s = _goal(0, [1.0])
    s.header.schema_version = msgs.CLIENT_SCHEMA_VERSION + 1
    assert s.check() is R.SCHEMA_MISMATCH
    s = _goal(0, [1.0])
    s.fields |= 1 << 7
    assert s.check() is R.UNKNOWN_FIELDS
    s.fields = 0
    assert s.check() is R.NOTHING_SET
    s.fields = msgs.SETPOINT_VELOCITY
    assert s.check() is R.VELOCITY_WITHOUT_GOAL
    s = _goal(0, [1.0])
    s.gain_layout = 1 << 5
    assert s.check() is R.UNKNOWN_LAYOUT
    assert _goal(msgs.MAX_LEVELS, [1.0]).check() is R.LEVEL_CAPACITY
    assert _goal(0, []).check() is R.DIMENSION_CAPACITY
    s = _goal(0, [1.0])
    s.dim = msgs.MAX_TASK_DIM + 1
    assert s.check() is R.DIMENSION_CAPACITY
    s.dim = 0xFFFF_FFFF
    assert s.check() is R.DIMENSION_CAPACITY
    assert len(s.goal_list()) == msgs.MAX_TASK_DIM, "accessors clamp"
    # Only the values used must be finite; the duration must be usable.
    s = _goal(0, [1.0, nan])
    assert s.check() is R.NON_FINITE
    s.goal[1] = 0.0
    s.goal[5] = nan
    s.velocity[0] = inf
    s.stiffness[0] = nan
    assert s.check() is None
    s.fields |= msgs.SETPOINT_VELOCITY
    assert s.check() is R.NON_FINITE
    s = _goal(0, [1.0])
    s.duration_s = nan
    assert s.check() is R.NON_FINITE
    s.duration_s = -0.1
    assert s.check() is R.BAD_DURATION
    s.duration_s = 2 * msgs.MAX_TRANSITION_S
    assert s.check() is R.BAD_DURATION
    s.duration_s = msgs.MAX_TRANSITION_S
    assert s.check() is None
    with pytest.raises(msgs.SetpointError) as e:
        _goal(0, [nan]).validate()
    assert e.value.rejection is R.NON_FINITE and "non_finite" in str(e.value)


def test_setpoint_gains_must_be_symmetric_positive_definite() -> None:
    s = msgs.Setpoint.zeroed()
    s.fields = msgs.SETPOINT_STIFFNESS | msgs.SETPOINT_DAMPING
    s.dim = 3
    for k, (kk, dd) in enumerate([(500.0, 40.0), (500.0, 40.0), (200.0, 20.0)]):
        s.stiffness[k], s.damping[k] = kk, dd
    assert s.check() is None
    s.damping[1] = 0.0
    assert s.check() is R.NOT_POSITIVE_DEFINITE
    s.damping[1] = 40.0
    s.stiffness[0] = -1.0
    assert s.check() is R.NOT_POSITIVE_DEFINITE
    assert _full_stiffness(2, [4.0, 1.0, 1.0, 3.0]).check() is None
    assert _full_stiffness(2, [1.0, 2.0, 2.0, 1.0]).check() is R.NOT_POSITIVE_DEFINITE
    assert _full_stiffness(2, [1.0, 1.0, 1.0, 1.0]).check() is R.NOT_POSITIVE_DEFINITE
    assert _full_stiffness(2, [4.0, 1.0, 0.0, 3.0]).check() is R.NOT_SYMMETRIC
    assert _full_stiffness(2, [4.0, 1.0, 1.0 + 1e-12, 3.0]).check() is None
    assert _full_stiffness(2, [1e308] * 4).check() is R.NOT_POSITIVE_DEFINITE
    m = msgs.MAX_TASK_DIM
    a = [2.0 * m if j == k else 1.0 for j in range(m) for k in range(m)]
    s = _full_stiffness(m, a)
    assert s.check() is None
    s.fields = msgs.SETPOINT_DAMPING
    s.gain_layout = msgs.GAIN_DAMPING_FULL
    for k, v in enumerate(a):
        s.damping[k] = v
    s.damping[0] = -1.0
    assert s.check() is R.NOT_POSITIVE_DEFINITE


def test_setpoint_builders_fill_and_size_check() -> None:
    s = (
        msgs.Setpoint.for_level(7, 3, 1, 2)
        .with_goal([0.4, 0.5])
        .with_velocity([0.1, 0.0])
        .with_stiffness([[400.0, 10.0], [10.0, 300.0]])
        .with_damping([30.0, 20.0])
        .with_duration(1.5)
        .with_apply_at(1234)
    )
    assert s.check() is None
    assert s.apply_at_state_seq == 1234
    assert (s.client_id, s.header.seq, s.level, s.header.schema_version) == (
        7, 3, 1, msgs.CLIENT_SCHEMA_VERSION,
    )
    assert s.fields == msgs.SETPOINT_FIELDS_KNOWN
    assert s.stiffness_full() and not s.damping_full()
    assert s.stiffness_list() == [400.0, 10.0, 10.0, 300.0]
    assert s.damping_list() == [30.0, 20.0] and s.duration_s == 1.5
    # Back to a diagonal clears the layout bit.
    assert not s.with_stiffness([1.0, 2.0]).stiffness_full()
    base = msgs.Setpoint.for_level(1, 1, 0, 3)
    for build, code in [
        (lambda: base.with_goal([1.0]), R.DIMENSION_MISMATCH),
        (lambda: base.with_stiffness([1.0] * 4), R.DIMENSION_MISMATCH),
        (lambda: msgs.Setpoint.for_level(1, 1, 0, 0).with_goal([]), R.DIMENSION_CAPACITY),
        (lambda: msgs.Setpoint.for_level(1, 1, 0, 33).with_damping([1.0] * 33), R.DIMENSION_CAPACITY),
    ]:
        with pytest.raises(msgs.SetpointError) as e:
            build()
        assert e.value.rejection is code
    far = msgs.Setpoint.for_level(1, 1, 99, 1).with_goal([0.0])
    assert far.check() is R.LEVEL_CAPACITY
    with pytest.raises(ValueError):
        msgs.Setpoint.for_level(1, 1, -1, 3)


def test_telemetry_answers_and_per_level_values() -> None:
    t = msgs.Telemetry()
    t.n_levels, t.task_dims[0] = 1, 3
    for k in range(3):
        t.goal[0][k] = 0.1 * (k + 1)
        t.stiffness_diag[0][k] = 500.0
        t.damping_diag[0][k] = 40.0
    t.goal[0][3] = 9.0  # beyond m: not reported
    t.transition_progress[0] = 0.25
    assert t.goal_list(0) == [0.1, 0.2, 0.30000000000000004]
    assert t.stiffness_diag_list(0) == [500.0] * 3 and t.damping_diag_list(0) == [40.0] * 3
    assert t.goal_list(1) == [] and t.progress(0) == 0.25 and t.progress(3) != t.progress(3)
    assert t.answer_for(5) is None
    t.setpoint_answers[3].client_id = 5
    assert t.answer_for(5) is None, "an empty slot (answered 0) is no answer"
    t.setpoint_answers[3].answered, t.setpoint_answers[3].seq = 2, 11
    t.setpoint_answers[3].code = R.JOINT_LIMIT
    a = t.answer_for(5)
    assert a is not None and a.seq == 11 and not a.accepted() and a.rejection() is R.JOINT_LIMIT
