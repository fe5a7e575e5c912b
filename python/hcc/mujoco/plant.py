"""The MuJoCo plant: the robot of a scenario, optionally in a contact scene.

Per control period the joint torque τ is held (zero-order hold) over the
scenario's substeps of MuJoCo's RK4 with timestep integrator_dt_s, and the
time is re-anchored to k T afterwards, exactly as the Rust plant does.
External wrenches of the scenario act at their link frame's origin (world
axes) during their time window; they are evaluated at every RK4 stage (a
control callback), like the Rust plant evaluates them at every stage.

Loads (docs/load.md): a massless body ``hcc_load`` welded to the tip link
carries the load in the hand — ``[robot.load]`` from the start, each
``[[simulation.load]]`` from its ``start_s`` (taken at the first RK4 step that
begins at or after it, as the Rust plant takes it), its mass, centre of mass
and inertia written into the compiled model (MuJoCo recomputes the composite
inertia from them every step). :meth:`Plant.robot_gravity` is the robot's own
g(q), which knows no load: what a driver that adds gravity adds.

Scene ``wall``: a rigid, frictionless box whose face passes through
``point`` with outward normal ``normal``, and a sphere of ``tool_radius``
(massless) at the tip link, the only shape of the robot that touches it.
The contact force MuJoCo computes is reported by :meth:`Plant.contact_force`
and never reaches the controller.
"""

from __future__ import annotations

import math
import pathlib
from dataclasses import dataclass, field
from typing import Any

import mujoco
import numpy as np

from ..scenario import Load, Scenario, ScenarioError, load_toml
from .model import RobotModel, build_spec, compile_robot

#: The body welded to the tip link that carries the load in the hand.
LOAD_BODY: str = "hcc_load"


@dataclass
class WallScene:
    """A wall the TCP can be commanded into."""

    #: A point on the wall's surface, m (world).
    point: list[float]
    #: Unit normal of the surface, pointing out of the wall (towards the robot).
    normal: list[float]
    #: Radius of the tool sphere at the tip link, m.
    tool_radius: float = 0.01
    #: Half thickness of the wall box, m.
    thickness: float = 0.05
    #: Half extent of the wall along its surface, m.
    extent: float = 1.0


@dataclass
class SceneFile:
    """The MuJoCo-only settings of a run (a small TOML file next to the scenario).

    The scenario file itself accepts no unknown sections, so these live in
    their own file::

        [mujoco]
        scene = "wall"

        [mujoco.wall]
        point = [0.55, 0.0, 0.4]
        normal = [-1.0, 0.0, 0.0]
        tool_radius = 0.01
    """

    path: pathlib.Path
    wall: WallScene | None = None
    extra: dict[str, Any] = field(default_factory=dict)

    @staticmethod
    def load(path: str | pathlib.Path) -> "SceneFile":
        """Reads and checks ``path``."""
        path = pathlib.Path(path)
        doc = load_toml(path)
        unknown = set(doc) - {"mujoco"}
        if unknown:
            raise ScenarioError(f"{path}: unknown sections {sorted(unknown)} (only [mujoco])")
        mj = doc.get("mujoco", {})
        scene = mj.get("scene", "none")
        if scene == "none":
            return SceneFile(path)
        if scene != "wall":
            raise ScenarioError(f"{path}: mujoco.scene must be \"wall\" or \"none\", got {scene!r}")
        w = mj.get("wall", {})
        try:
            point = [float(x) for x in w["point"]]
            normal = [float(x) for x in w["normal"]]
        except (KeyError, TypeError, ValueError) as e:
            raise ScenarioError(f"{path}: [mujoco.wall] needs point and normal (3 numbers)") from e
        norm = math.sqrt(sum(x * x for x in normal))
        if len(point) != 3 or len(normal) != 3 or not norm > 0 or not all(map(math.isfinite, point)):
            raise ScenarioError(f"{path}: mujoco.wall.point/normal must be 3 finite numbers, normal ≠ 0")
        radius = float(w.get("tool_radius", 0.01))
        if not radius > 0:
            raise ScenarioError(f"{path}: mujoco.wall.tool_radius must be positive")
        return SceneFile(path, WallScene(point, [x / norm for x in normal], radius))


def _quat_x_to(n: np.ndarray) -> list[float]:
    """Unit quaternion (w, x, y, z) rotating the x axis onto unit vector ``n``."""
    x = np.array([1.0, 0.0, 0.0])
    c = float(np.dot(x, n))
    if c < -1.0 + 1e-12:
        return [0.0, 0.0, 0.0, 1.0]
    axis = np.cross(x, n)
    q = np.array([1.0 + c, *axis])
    return list(q / np.linalg.norm(q))


class Plant:
    """The scenario's robot in MuJoCo, advanced one control period at a time."""

    def __init__(self, scenario: Scenario, scene: SceneFile | None = None) -> None:
        self.scenario = scenario
        spec, chain = build_spec(scenario)
        self.wall = scene.wall if scene is not None else None
        self._tool_geom = "hcc_tool"
        if self.wall is not None:
            self._add_wall(spec, scenario.tip_link, self.wall)
        tip_body = spec.body(scenario.tip_link)
        if tip_body is None:
            raise ScenarioError(f"tip link {scenario.tip_link!r} is not a body of the MuJoCo model")
        load_body = tip_body.add_body(name=LOAD_BODY)
        load_body.mass = 0.0
        load_body.inertia = [0.0, 0.0, 0.0]
        self.robot: RobotModel = compile_robot(scenario, spec, chain)
        m = self.robot.model
        if self.wall is None:
            m.opt.disableflags |= int(mujoco.mjtDisableBit.mjDSBL_CONTACT)
            m.opt.disableflags |= int(mujoco.mjtDisableBit.mjDSBL_CONSTRAINT)
        self.model = m
        self.data = mujoco.MjData(m)
        self._scratch = mujoco.MjData(m)
        self._g = np.zeros(m.nv)
        self.n = self.robot.n
        self.period_s = scenario.period_s
        self.substeps = scenario.substeps
        self.k = 0
        q0 = np.array(scenario.q0)
        qd0 = np.array(scenario.qd0) if scenario.qd0 is not None else np.zeros(self.n)
        self.data.qpos[self.robot.qpos_adr] = q0
        self.data.qvel[self.robot.dof_adr] = qd0
        self._wrenches = []
        for w in scenario.wrenches:
            if w.link not in self.robot.link_bodies:
                raise ScenarioError(f"{scenario.path}: wrench link {w.link!r} is not a link of the robot")
            self._wrenches.append((w, self.robot.link_bodies[w.link]))
        if self._wrenches:
            mujoco.set_mjcb_control(self._apply_wrenches)
        mujoco.mj_forward(m, self.data)
        self._tool_id = (
            mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_GEOM, self._tool_geom) if self.wall else -1
        )
        self._tip = self.robot.link_bodies[scenario.tip_link]
        self._load_body = self.robot.link_bodies[LOAD_BODY]
        self._jacp = np.zeros((3, m.nv))
        self.load = Load(0.0, [0.0] * 3, [0.0] * 6)
        if scenario.robot_load is not None:
            self.set_load(scenario.robot_load)
        self._loads = list(scenario.loads)
        self._loads_taken = 0
        mujoco.mj_forward(m, self.data)

    def set_load(self, load: Load) -> None:
        """The tip carries ``load`` from now on (replacing the one before): the
        ``hcc_load`` body's mass, centre of mass (tip frame) and principal
        inertia with its axes."""
        if not (load.mass >= 0.0 and math.isfinite(load.mass)):
            raise ScenarioError(f"load mass {load.mass} must be finite and non-negative")
        moments, axes = np.linalg.eigh(np.array(load.inertia_matrix(), dtype=float))
        if moments[0] < -1e-12 * max(1.0, abs(moments[-1])):
            raise ScenarioError(f"load inertia {load.inertia} is not positive semidefinite")
        if np.linalg.det(axes) < 0:
            axes[:, 2] = -axes[:, 2]
        quat = np.zeros(4)
        mujoco.mju_mat2Quat(quat, axes.flatten())
        m, b = self.model, self._load_body
        m.body_mass[b] = load.mass
        m.body_ipos[b] = load.com
        m.body_inertia[b] = np.maximum(moments, 0.0)
        m.body_iquat[b] = quat
        # Compiled with its inertial frame at the body's: MuJoCo would keep
        # skipping the offset (body_sameframe); and the composite inertia of
        # the tip's branch is no longer that of a simple body.
        m.body_sameframe[b] = 0
        m.body_simple[b] = 0
        self.load = load

    def _take_loads(self, t: float) -> None:
        """Takes the timed loads whose time has come at ``t``."""
        while self._loads_taken < len(self._loads) and self._loads[self._loads_taken].start_s <= t + 1e-12:
            self.set_load(self._loads[self._loads_taken].load)
            self._loads_taken += 1

    @staticmethod
    def _add_wall(spec: mujoco.MjSpec, tip: str, wall: WallScene) -> None:
        n = np.array(wall.normal)
        center = np.array(wall.point) - n * wall.thickness
        spec.worldbody.add_geom(
            name="hcc_wall",
            type=mujoco.mjtGeom.mjGEOM_BOX,
            size=[wall.thickness, wall.extent, wall.extent],
            pos=list(center),
            quat=_quat_x_to(n),
            contype=1,
            conaffinity=1,
            condim=1,
        )
        body = spec.body(tip)
        if body is None:
            raise ScenarioError(f"tip link {tip!r} is not a body of the MuJoCo model")
        body.add_geom(
            name="hcc_tool",
            type=mujoco.mjtGeom.mjGEOM_SPHERE,
            size=[wall.tool_radius, 0.0, 0.0],
            contype=2,
            conaffinity=1,
            condim=1,
            density=0.0,
        )

    def close(self) -> None:
        """Removes the wrench callback (a process-wide MuJoCo setting)."""
        if self._wrenches:
            mujoco.set_mjcb_control(None)

    def _apply_wrenches(self, m: Any, d: Any) -> None:
        """Control callback (every RK4 stage): wrench at each link origin → body CoM."""
        d.xfrc_applied[:] = 0.0
        for w, body in self._wrenches:
            if not w.active_at(d.time):
                continue
            f = np.array(w.force)
            lever = d.xpos[body] - d.xipos[body]
            d.xfrc_applied[body, :3] += f
            d.xfrc_applied[body, 3:] += np.array(w.torque) + np.cross(lever, f)

    @property
    def q(self) -> np.ndarray:
        """Joint positions of the chain."""
        return self.data.qpos[self.robot.qpos_adr]

    @property
    def qd(self) -> np.ndarray:
        """Joint velocities of the chain."""
        return self.data.qvel[self.robot.dof_adr]

    @property
    def t(self) -> float:
        """Simulated time t_k = k T."""
        return self.data.time

    def gravity(self) -> np.ndarray:
        """g(q) at the current state (the generalized gravity force of Eq. (1))."""
        s = self._scratch
        s.qpos[:] = self.data.qpos
        s.qvel[:] = 0.0
        mujoco.mj_kinematics(self.model, s)
        mujoco.mj_comPos(self.model, s)
        mujoco.mj_rne(self.model, s, 0, self._g)
        return self._g[self.robot.dof_adr].copy()

    def robot_gravity(self) -> np.ndarray:
        """The robot's own g(q), which knows no load in the hand: :meth:`gravity`
        less the load's −J_cᵀ m g₀ (J_c at the load's centre of mass)."""
        g = self.gravity()
        if self.load.mass == 0.0:
            return g
        s, b = self._scratch, self._load_body
        mujoco.mj_jac(self.model, s, self._jacp, None, s.xipos[b], b)
        held = -(self._jacp.T @ (self.load.mass * self.model.opt.gravity))
        return g - held[self.robot.dof_adr]

    def advance(self, tau: np.ndarray) -> None:
        """Integrates one control period with ``tau`` held; raises on divergence."""
        m, d = self.model, self.data
        d.qfrc_applied[:] = 0.0
        d.qfrc_applied[self.robot.dof_adr] = tau
        if self._loads_taken < len(self._loads):
            # Step by step while a load is still to come, to take it on time.
            for i in range(self.substeps):
                self._take_loads(self.k * self.period_s + i * self.scenario.integrator_dt_s)
                mujoco.mj_step(m, d)
        else:
            mujoco.mj_step(m, d, nstep=self.substeps)
        bad = int(d.warning[mujoco.mjtWarning.mjWARN_BADQACC].number)
        if bad or not (np.all(np.isfinite(d.qpos)) and np.all(np.isfinite(d.qvel))):
            raise FloatingPointError(f"the MuJoCo plant diverged at t = {d.time:.6f} s")
        self.k += 1
        d.time = self.k * self.period_s

    def tip_position(self) -> np.ndarray:
        """World position of the tip link's frame origin."""
        return self.data.xpos[self._tip].copy()

    def contact_force(self) -> np.ndarray:
        """Total contact force the wall exerts on the robot (world, N); zero without a wall."""
        total = np.zeros(3)
        if self._tool_id < 0:
            return total
        f6 = np.zeros(6)
        d = self.data
        for i in range(d.ncon):
            c = d.contact[i]
            if self._tool_id not in (c.geom1, c.geom2):
                continue
            mujoco.mj_contactForce(self.model, d, i, f6)
            world = c.frame.reshape(3, 3).T @ f6[:3]
            # The force acts on geom2 along +frame normal, on geom1 opposite.
            total += world if c.geom2 == self._tool_id else -world
        return total
