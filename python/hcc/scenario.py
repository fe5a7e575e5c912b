"""The parts of a scenario TOML that a plant driver needs.

Reads the same file as the Rust daemons (``[robot]``, ``[initial]``,
``[simulation]``, ``[ipc]``, ``[sim_daemon]``) with the same defaults; the
controller's own sections (levels, gains) are not interpreted here. Values
are checked with clear errors.
"""

from __future__ import annotations

import math
import pathlib
import tomllib
from dataclasses import dataclass, field
from typing import Any


class ScenarioError(ValueError):
    """A scenario that cannot be used (the text names the file and the field)."""


@dataclass
class Wrench:
    """A force/torque at a link frame origin (world axes) during [start_s, start_s + duration_s)."""

    link: str
    start_s: float
    duration_s: float
    force: list[float]
    torque: list[float]

    def active_at(self, t: float) -> bool:
        """Whether the wrench acts at time ``t``."""
        return self.start_s <= t < self.start_s + self.duration_s


@dataclass
class Load:
    """A load held rigidly at the tip frame (``[robot.load]``, ``[[simulation.load]]``;
    docs/load.md): mass (kg), centre of mass in the tip frame (m), rotational inertia
    about it in the tip's axes (kg·m²: ixx, ixy, ixz, iyy, iyz, izz)."""

    mass: float
    com: list[float]
    inertia: list[float]

    def inertia_matrix(self) -> list[list[float]]:
        """The symmetric 3×3 inertia."""
        xx, xy, xz, yy, yz, zz = self.inertia
        return [[xx, xy, xz], [xy, yy, yz], [xz, yz, zz]]


@dataclass
class TimedLoad:
    """From ``start_s`` on the plant's tip carries ``load`` (replacing the one before)."""

    start_s: float
    load: Load


@dataclass
class Scenario:
    """Robot, initial state, plant and driver settings of a scenario."""

    path: pathlib.Path
    name: str
    urdf: pathlib.Path
    root_link: str | None
    tip_link: str
    gravity: list[float]
    gravity_compensation: bool
    q0: list[float]
    qd0: list[float] | None
    duration_s: float
    rate_hz: float
    integrator_dt_s: float
    joint_friction: float | list[float]
    wrenches: list[Wrench]
    namespace: str
    mode: str
    hold_cycles: int
    fallback_damping: float | list[float]
    levels: list[dict[str, Any]] = field(default_factory=list)
    #: The load the tip carries from the start (``[robot.load]``), if any.
    robot_load: Load | None = None
    #: Loads the plant's tip takes at a time (``[[simulation.load]]``), by time.
    loads: list[TimedLoad] = field(default_factory=list)

    @property
    def period_s(self) -> float:
        """Control period T = 1 / rate_hz (``[controller] rate_hz``)."""
        return 1.0 / self.rate_hz

    @property
    def substeps(self) -> int:
        """Integrator steps per control period (T / integrator_dt_s, an integer)."""
        return round(self.period_s / self.integrator_dt_s)

    @staticmethod
    def load(path: str | pathlib.Path) -> "Scenario":
        """Reads and checks ``path``."""
        path = pathlib.Path(path)
        return _parse(path, load_toml(path))


def load_toml(path: pathlib.Path) -> dict[str, Any]:
    """Reads a TOML file; a clear error naming the file if it cannot be read or parsed."""
    try:
        return tomllib.loads(path.read_text())
    except OSError as e:
        raise ScenarioError(f"{path}: cannot read it: {e.strerror}") from e
    except tomllib.TOMLDecodeError as e:
        raise ScenarioError(f"{path}: not valid TOML: {e}") from e


def _number(path: pathlib.Path, name: str, v: Any, positive: bool = False) -> float:
    if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v):
        raise ScenarioError(f"{path}: {name} must be a finite number, got {v!r}")
    if positive and v <= 0:
        raise ScenarioError(f"{path}: {name} must be positive, got {v}")
    return float(v)


def _vector(path: pathlib.Path, name: str, v: Any, n: int | None = None) -> list[float]:
    if not isinstance(v, list):
        raise ScenarioError(f"{path}: {name} must be an array of numbers, got {v!r}")
    out = [_number(path, f"{name}[{i}]", x) for i, x in enumerate(v)]
    if n is not None and len(out) != n:
        raise ScenarioError(f"{path}: {name} has {len(out)} entries, expected {n}")
    return out


def _per_joint(path: pathlib.Path, name: str, v: Any) -> float | list[float]:
    if isinstance(v, list):
        out = _vector(path, name, v)
    else:
        out = [_number(path, name, v)]
    if any(x < 0 for x in out):
        raise ScenarioError(f"{path}: {name} must not be negative")
    return out if isinstance(v, list) else out[0]


def _load(path: pathlib.Path, name: str, section: Any) -> Load:
    """A ``[robot.load]``-shaped table: mass ≥ 0, com (3), inertia (6, a point mass
    without); the controller checks the physics (triangle inequalities, payload)."""
    if not isinstance(section, dict):
        raise ScenarioError(f"{path}: {name} must be a table")
    if "mass" not in section:
        raise ScenarioError(f"{path}: {name} needs mass")
    mass = _number(path, f"{name}.mass", section["mass"])
    if mass < 0:
        raise ScenarioError(f"{path}: {name}.mass must not be negative, got {mass}")
    return Load(
        mass=mass,
        com=_vector(path, f"{name}.com", section.get("com", [0.0] * 3), 3),
        inertia=_vector(path, f"{name}.inertia", section.get("inertia", [0.0] * 6), 6),
    )


def _table(path: pathlib.Path, doc: dict[str, Any], name: str) -> dict[str, Any]:
    t = doc.get(name, {})
    if not isinstance(t, dict):
        raise ScenarioError(f"{path}: [{name}] must be a table")
    return t


def _parse(path: pathlib.Path, doc: dict[str, Any]) -> Scenario:
    robot = _table(path, doc, "robot")
    if "urdf" not in robot or "tip_link" not in robot:
        raise ScenarioError(f"{path}: [robot] needs urdf and tip_link")
    initial = _table(path, doc, "initial")
    if "q0" not in initial:
        raise ScenarioError(f"{path}: [initial] needs q0")
    q0 = _vector(path, "initial.q0", initial["q0"])
    qd0 = _vector(path, "initial.qd0", initial["qd0"], len(q0)) if "qd0" in initial else None
    sim = _table(path, doc, "simulation")
    if "control_rate_hz" in sim:
        raise ScenarioError(
            f"{path}: simulation.control_rate_hz: the control rate moved to [controller] rate_hz "
            "(the same value, in Hz): move the line there"
        )
    controller = _table(path, doc, "controller")
    rate = _number(path, "controller.rate_hz", controller.get("rate_hz", 1000.0), True)
    dt = _number(path, "simulation.integrator_dt_s", sim.get("integrator_dt_s", 1e-4), True)
    ratio = (1.0 / rate) / dt
    if round(ratio) < 1 or abs(ratio - round(ratio)) > 1e-6 * ratio:
        raise ScenarioError(
            f"{path}: simulation.integrator_dt_s {dt} must divide the control period {1.0 / rate} s"
        )
    wrenches = []
    for i, w in enumerate(sim.get("wrench", [])):
        p = f"simulation.wrench[{i}]"
        wrenches.append(
            Wrench(
                link=str(w["link"]),
                start_s=_number(path, f"{p}.start_s", w["start_s"]),
                duration_s=_number(path, f"{p}.duration_s", w["duration_s"]),
                force=_vector(path, f"{p}.force", w.get("force", [0.0] * 3), 3),
                torque=_vector(path, f"{p}.torque", w.get("torque", [0.0] * 3), 3),
            )
        )
    robot_load = _load(path, "robot.load", robot["load"]) if "load" in robot else None
    loads = []
    for i, section in enumerate(sim.get("load", [])):
        p = f"simulation.load[{i}]"
        if not isinstance(section, dict) or "start_s" not in section:
            raise ScenarioError(f"{path}: {p} needs start_s")
        start = _number(path, f"{p}.start_s", section["start_s"])
        rest = {k: v for k, v in section.items() if k != "start_s"}
        loads.append(TimedLoad(start, _load(path, p, rest)))
    loads.sort(key=lambda tl: tl.start_s)
    daemon = _table(path, doc, "sim_daemon")
    mode = daemon.get("mode", "realtime")
    if mode not in ("realtime", "lockstep"):
        raise ScenarioError(f"{path}: sim_daemon.mode must be realtime or lockstep, got {mode!r}")
    hold = daemon.get("hold_cycles", 3)
    if isinstance(hold, bool) or not isinstance(hold, int) or hold < 0:
        raise ScenarioError(f"{path}: sim_daemon.hold_cycles must be a non-negative integer")
    return Scenario(
        path=path,
        name=str(doc.get("name", path.stem)),
        urdf=(path.parent / str(robot["urdf"])).resolve(),
        root_link=robot.get("root_link"),
        tip_link=str(robot["tip_link"]),
        gravity=_vector(path, "robot.gravity", robot.get("gravity", [0.0, 0.0, -9.81]), 3),
        gravity_compensation=bool(robot.get("gravity_compensation", True)),
        q0=q0,
        qd0=qd0,
        duration_s=_number(path, "simulation.duration_s", sim.get("duration_s", 3.0), True),
        rate_hz=rate,
        integrator_dt_s=dt,
        joint_friction=_per_joint(path, "simulation.joint_friction", sim.get("joint_friction", 0.0)),
        wrenches=wrenches,
        namespace=str(_table(path, doc, "ipc").get("namespace", "hcc")),
        mode=mode,
        hold_cycles=hold,
        fallback_damping=_per_joint(
            path, "sim_daemon.fallback_damping", daemon.get("fallback_damping", 2.0)
        ),
        levels=list(doc.get("level", [])),
        robot_load=robot_load,
        loads=loads,
    )
