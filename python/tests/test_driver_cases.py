"""hcc.Driver against the shared cases of the driver contract.

The same file (tests/data/driver_cases.json) runs against the Rust
hcc_msgs::driver::DriverLogic (crates/msgs/tests/driver_cases.rs), so both
implementations agree on every branch.
"""

from __future__ import annotations

import json
import math
from typing import Any

import pytest

from hcc import Driver, DriverSettings, DriverStatus, JointState, MsgError, TorqueCommand
from hcc.driver import Action, Offer

from conftest import ROOT

CASES = json.loads((ROOT / "tests" / "data" / "driver_cases.json").read_text())["cases"]


def num(v: Any) -> float:
    """A number of the case file ('inf', '-inf', 'nan' as strings)."""
    return float(v)


def nums(vs: list[Any]) -> list[float]:
    return [num(v) for v in vs]


def offer_result(o: Offer) -> str:
    if o.applicable:
        return "applicable_current" if o.current else "applicable_late"
    assert o.rejection is not None
    if o.rejection.value == "too_late":
        return f"too_late:{o.cycles}"
    return o.rejection.value


def build_command(step: dict[str, Any], latest: JointState) -> TorqueCommand:
    c = TorqueCommand.zeroed()
    tau = nums(step["tau"])
    c.header.n_joints = len(tau)
    for k, t in enumerate(tau):
        c.tau[k] = t
    c.header.seq = step["seq"]
    c.state_seq = step.get("answers", latest.header.seq)
    c.state_stamp_ns = latest.header.stamp_ns
    c.mode = step["mode"]
    flags = step.get("flags", "agree")
    c.flags = (0 if latest.driver_compensates_gravity() else 1) if flags == "agree" else flags
    if "n_joints" in step:
        c.header.n_joints = step["n_joints"]
    if "schema_version" in step:
        c.header.schema_version = step["schema_version"]
    return c


def check_counters(driver: Driver, expect: dict[str, Any]) -> None:
    if "status" in expect:
        assert driver.status == DriverStatus[expect["status"].upper()]
    for key in ("missed_commands", "fallback_cycles", "applied"):
        if key in expect:
            assert getattr(driver, key) == expect[key], key
    if "stop_reason" in expect:
        assert driver.stop_reason is not None and driver.stop_reason.value == expect["stop_reason"]
    if "rejections" in expect:
        got = {r.value: count for r, count in driver.rejections.items()}
        assert got == expect["rejections"]


@pytest.mark.parametrize("case", CASES, ids=[c["name"] for c in CASES])
def test_case(case: dict[str, Any]) -> None:
    s = case["settings"]
    driver = Driver(
        DriverSettings(
            n=s["n"],
            late_tolerance=s["late_tolerance"],
            hold_cycles=s["hold_cycles"],
            fallback_timeout_cycles=s["fallback_timeout_cycles"],
            fallback_damping=nums(s["fallback_damping"]),
            compensates_gravity=s["compensates_gravity"],
        )
    )
    latest = JointState.zeroed()
    last: TorqueCommand | None = None
    for i, step in enumerate(case["steps"]):
        op, expect = step["op"], step.get("expect")
        where = f"step {i} ({op})"
        if op == "publish":
            msg = JointState.zeroed()
            try:
                seq = driver.fill_state(
                    msg, nums(step["q"]), nums(step["qd"]), nums(step["tau"]), step["stamp_ns"]
                )
            except MsgError:
                assert expect == "error", where
                continue
            assert expect != "error", where
            assert seq == expect["seq"] == msg.header.seq, where
            assert msg.status == DriverStatus[expect["status"].upper()], where
            assert msg.flags == expect["flags"], where
            assert msg.missed_commands == expect["missed_commands"], where
            assert msg.fallback_cycles == expect["fallback_cycles"], where
            msg.validate(s["n"])
            latest = msg
        elif op == "offer":
            last = build_command(step, latest)
            assert offer_result(driver.offer(last, latest)) == expect, where
        elif op == "decide":
            command = last if step["command"] == "last" else None
            tau = [math.nan] * s["n"]
            action = driver.decide(command, nums(step["qd"]), nums(step["gravity"]), tau)
            assert action == Action(expect["action"]), where
            assert tau == nums(expect["tau"]), where
            check_counters(driver, expect)
        elif op == "request_stop":
            assert driver.request_stop() == Action(expect), where
        elif op == "stop_completed":
            driver.stop_completed()
        elif op == "check":
            check_counters(driver, expect)
        else:
            pytest.fail(f"unknown op {op!r} in {where}")
