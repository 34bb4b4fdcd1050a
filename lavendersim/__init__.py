"""LavenderSim: 3D rigid-body mechanics with SymPy-derived, generated C and NumPy kernels.

Conventions: quaternions (x, y, z, w), scalar last; R_WB maps body to world; suffixes _w/_b name
the frame; SI units; float64.

The public names below are loaded on first use (``lavendersim.Sim`` imports the simulator then),
so ``import lavendersim`` and the ``lavendersim`` command start fast; ``import lavendersim`` never
imports gymnasium, SymPy or scipy.integrate.
"""
from __future__ import annotations

import importlib
from typing import TYPE_CHECKING

from ._version import __version__

# public name -> the module that defines it
_EXPORTS = {
    "Body": "bodies", "BodyState": "bodies", "inertia_about_com": "bodies",
    "AppliedTorque": "effects", "ForceAtPoint": "effects", "Gravity": "effects", "LinearDamping": "effects",
    "AngularDamping": "effects",
    "DivergenceError": "errors", "StaleBuildError": "errors",
    "Scene": "scene",
    "Sim": "sim", "Trajectory": "sim",
    "LavenderInputError": "validate",
    "MissingExtraError": "_install",
}

__all__ = ["Body", "BodyState", "inertia_about_com", "AppliedTorque", "ForceAtPoint", "Gravity", "LinearDamping", "AngularDamping",
           "DivergenceError", "StaleBuildError", "Scene", "Sim", "Trajectory", "LavenderInputError",
           "MissingExtraError", "__version__"]

if TYPE_CHECKING:  # for type checkers and IDEs; at run time the names load lazily
    from ._install import MissingExtraError
    from .bodies import Body, BodyState, inertia_about_com
    from .effects import AngularDamping, AppliedTorque, ForceAtPoint, Gravity, LinearDamping
    from .errors import DivergenceError, StaleBuildError
    from .scene import Scene
    from .sim import Sim, Trajectory
    from .validate import LavenderInputError


def __getattr__(name: str):
    module = _EXPORTS.get(name)
    if module is None:
        raise AttributeError(f"module 'lavendersim' has no attribute {name!r}")
    value = getattr(importlib.import_module(f".{module}", __name__), name)
    globals()[name] = value
    return value


def __dir__() -> list[str]:
    return sorted(set(globals()) | set(_EXPORTS))


from ._integrity import install as _check_generated_on_import  # noqa: E402  (stdlib only; hashes nothing now)

_check_generated_on_import()  # every lavendersim.generated module is checked against manifest.json before it runs

from .envs import register as _register_envs  # noqa: E402  (light: never imports gymnasium)

_register_envs()  # ReactionWheelCube-v0: gymnasium.make("lavendersim:ReactionWheelCube-v0")
