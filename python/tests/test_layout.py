"""The ctypes mirrors have exactly the Rust layout, names and settings.

Rust prints its own figures (``cargo run -p hcc-msgs --example layout``,
std::mem::offset_of!); every struct's size, alignment, field offsets and
iceoryx2 type name, the capacities, service names, service settings and
flag bits are compared here, so the two sides can never drift silently.
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
    assert rust["schema_version"] == msgs.SCHEMA_VERSION
    assert rust["max_joints"] == msgs.MAX_JOINTS
    assert rust["max_levels"] == msgs.MAX_LEVELS
    assert rust["max_task_dim"] == msgs.MAX_TASK_DIM
    assert rust["ipc_file_prefix_env"] == ipc.FILE_PREFIX_ENV
    flags = rust["flags"]
    assert flags["state_driver_gravity_compensation"] == msgs.STATE_FLAG_DRIVER_GRAVITY_COMPENSATION
    assert flags["command_gravity_included"] == msgs.COMMAND_FLAG_GRAVITY_INCLUDED
    assert flags["telemetry_peer_lost"] == msgs.TELEMETRY_FLAG_PEER_LOST


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
    s.flags = 2
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
    c.header.schema_version = 2
    with pytest.raises(msgs.MsgError):
        c.validate(2)
