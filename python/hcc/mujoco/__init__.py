"""A plant driver for the hcc controller on the MuJoCo physics engine.

``python -m hcc.mujoco CONFIG [--namespace NS] [--lockstep] [--duration S]``
reads the scenario TOML the Rust daemons read and speaks the contract
exactly as ``hcc-sim`` does: an independent physics engine driving the
controller through the contract alone.
"""

from .driver import Applied, MujocoDriver
from .plant import Plant, SceneFile, WallScene

__all__ = ["Applied", "MujocoDriver", "Plant", "SceneFile", "WallScene"]
