"""A MuJoCo model of a scenario's robot, built from its URDF.

* ``<visual>`` and ``<collision>`` elements are removed (their meshes are
  not shipped; contact shapes come from the scene instead);
* every movable joint off the chain root_link → tip_link is made fixed at
  its zero position (the Panda's fingers), so the model has exactly the
  controller's n joints, in chain order;
* links whose rotational inertia is below MuJoCo's minimum get 1e-12 kg·m²
  on the diagonal (the paper's planar arm has point masses, which MuJoCo
  refuses);
* static links are kept as bodies (``fusestatic="false"``), so every URDF
  link frame, e.g. the TCP, exists as a body;
* joint limits, URDF damping/friction and armature are removed: the plant is
  M(q) q̈ + C(q, q̇) q̇ + g(q) = τ + τ_ext − F_v q̇ (paper Eq. (1) with the
  scenario's viscous joint friction F_v), as in the Rust plant;
* the integrator is MuJoCo's RK4 with the scenario's integrator step.
"""

from __future__ import annotations

import xml.etree.ElementTree as ET
from dataclasses import dataclass

import mujoco
import numpy as np

from ..scenario import Scenario, ScenarioError

#: Rotational inertia given to point-mass links, kg·m².
POINT_MASS_INERTIA: float = 1e-12
#: Below this a diagonal inertia entry counts as zero (MuJoCo's mjMINVAL).
_MIN_INERTIA: float = 1e-15


@dataclass
class RobotModel:
    """The compiled model and the chain's joint addresses."""

    model: mujoco.MjModel
    joint_names: list[str]
    qpos_adr: np.ndarray
    dof_adr: np.ndarray
    link_bodies: dict[str, int]

    @property
    def n(self) -> int:
        """Number of joints of the chain."""
        return len(self.joint_names)


def _chain(robot: ET.Element, root: str | None, tip: str, where: str) -> tuple[list[str], set[str]]:
    """Movable joints root → tip in order, and all movable joints of the URDF."""
    parent_of: dict[str, tuple[str, ET.Element]] = {}
    movable = set()
    for j in robot.findall("joint"):
        child = j.find("child").get("link")  # type: ignore[union-attr]
        parent = j.find("parent").get("link")  # type: ignore[union-attr]
        parent_of[child] = (parent, j)
        if j.get("type") != "fixed":
            movable.add(j.get("name"))
    links = {link.get("name") for link in robot.findall("link")}
    if tip not in links:
        raise ScenarioError(f"{where}: tip link {tip!r} is not in the URDF")
    if root is not None and root not in links:
        raise ScenarioError(f"{where}: root link {root!r} is not in the URDF")
    chain = []
    link = tip
    while link in parent_of and link != root:
        parent, joint = parent_of[link]
        if joint.get("type") != "fixed":
            chain.append(joint.get("name"))
        link = parent
    if root is not None and link != root:
        raise ScenarioError(f"{where}: {tip!r} is not below {root!r} in the URDF")
    return list(reversed(chain)), movable


def _prepare_urdf(scenario: Scenario) -> tuple[str, list[str]]:
    where = str(scenario.urdf)
    try:
        robot = ET.parse(scenario.urdf).getroot()
    except (OSError, ET.ParseError) as e:
        raise ScenarioError(f"{where}: cannot read the URDF: {e}") from e
    chain, movable = _chain(robot, scenario.root_link, scenario.tip_link, where)
    for link in robot.findall("link"):
        for tag in ("visual", "collision"):
            for e in link.findall(tag):
                link.remove(e)
        inertia = link.find("inertial/inertia")
        if inertia is not None:
            for key in ("ixx", "iyy", "izz"):
                if abs(float(inertia.get(key, "0"))) < _MIN_INERTIA:
                    inertia.set(key, repr(POINT_MASS_INERTIA))
    for j in robot.findall("joint"):
        if j.get("name") in movable and j.get("name") not in chain:
            j.set("type", "fixed")  # locked at its zero position
            for tag in ("mimic", "limit", "axis", "dynamics"):
                for e in j.findall(tag):
                    j.remove(e)
    for e in robot.findall("mujoco"):
        robot.remove(e)
    ext = ET.SubElement(robot, "mujoco")
    ET.SubElement(
        ext,
        "compiler",
        fusestatic="false",
        discardvisual="true",
        balanceinertia="false",
        inertiafromgeom="false",
        angle="radian",
    )
    return ET.tostring(robot, encoding="unicode"), chain


def build_spec(scenario: Scenario) -> tuple[mujoco.MjSpec, list[str]]:
    """The MuJoCo spec of the scenario's robot (editable) and the chain's joints.

    The spec is parsed from the prepared URDF directly: no MJCF text round
    trip, which would round the inertial parameters.
    """
    urdf, chain = _prepare_urdf(scenario)
    try:
        spec = mujoco.MjSpec.from_string(urdf)
    except ValueError as e:
        raise ScenarioError(f"{scenario.urdf}: MuJoCo refuses the robot: {e}") from e
    if len(chain) != len(scenario.q0):
        raise ScenarioError(
            f"{scenario.path}: initial.q0 has {len(scenario.q0)} entries, the chain has {len(chain)} joints"
        )
    return spec, chain


def compile_robot(scenario: Scenario, spec: mujoco.MjSpec, chain: list[str]) -> RobotModel:
    """Compiles ``spec`` with the scenario's plant settings."""
    try:
        m = spec.compile()
    except ValueError as e:
        raise ScenarioError(f"{scenario.path}: MuJoCo cannot compile the scene: {e}") from e
    n = len(chain)
    m.opt.integrator = mujoco.mjtIntegrator.mjINT_RK4
    m.opt.timestep = scenario.integrator_dt_s
    m.opt.gravity[:] = scenario.gravity
    m.jnt_limited[:] = 0
    m.dof_frictionloss[:] = 0.0
    m.dof_armature[:] = 0.0
    friction = scenario.joint_friction
    m.dof_damping[:] = 0.0
    qpos_adr = np.array([m.joint(name).qposadr[0] for name in chain], dtype=int)
    dof_adr = np.array([m.joint(name).dofadr[0] for name in chain], dtype=int)
    if m.nv != n:
        raise ScenarioError(f"{scenario.urdf}: MuJoCo model has {m.nv} joints, the chain {n}")
    f = friction if isinstance(friction, list) else [friction] * n
    if len(f) != n:
        raise ScenarioError(
            f"{scenario.path}: simulation.joint_friction has {len(f)} entries, expected {n}"
        )
    m.dof_damping[dof_adr] = f
    links = {m.body(i).name: i for i in range(m.nbody)}
    return RobotModel(m, chain, qpos_adr, dof_adr, links)
