"""LavenderSim: 3D rigid-body mechanics with SymPy-derived, generated C and NumPy kernels.

Conventions: quaternions (x, y, z, w), scalar last; R_WB maps body to world; suffixes _w/_b name
the frame; SI units; float64.
"""
from .bodies import Body, BodyState
from .effects import AngularDamping, AppliedTorque, ForceAtPoint, Gravity, LinearDamping
from .errors import DivergenceError, StaleBuildError
from .scene import Scene
from .sim import Sim, Trajectory
from .validate import LavenderInputError

__all__ = ["Body", "BodyState", "Scene", "Sim", "Trajectory", "AppliedTorque", "ForceAtPoint", "Gravity",
           "LinearDamping", "AngularDamping", "DivergenceError", "StaleBuildError", "LavenderInputError"]
from ._version import __version__  # noqa: E402

from .envs import register as _register_envs  # noqa: E402

_register_envs()  # ReactionWheelCube-v0 (gymnasium.make("lavendersim:ReactionWheelCube-v0"))
