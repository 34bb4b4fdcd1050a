"""Gymnasium environments built on the LavenderSim runtime (the ``gym`` extra).

``ReactionWheelCube-v0`` is reachable as ``gymnasium.make("lavendersim:ReactionWheelCube-v0")``.
``import lavendersim`` does not import gymnasium: it registers the environment at once when
gymnasium is already imported, and otherwise as soon as gymnasium is imported (a one-shot import
hook), so the id works whichever of the two is imported first.
"""
from __future__ import annotations

import importlib.abc
import importlib.machinery
import sys

ENV_ID = "ReactionWheelCube-v0"
# a function, not the class: gymnasium.make then passes render_mode through unchanged (given a class whose
# metadata lacks the mode, it would swap "human" for "rgb_array" plus its HumanRendering wrapper)
ENTRY_POINT = "lavendersim.envs.reaction_wheel_cube:make_env"
VECTOR_ENTRY_POINT = "lavendersim.envs.vector:make_vec_env"   # N cubes in one Sim (gymnasium.make_vec)
MAX_EPISODE_STEPS = 1000


def _register_now(gymnasium) -> None:
    if ENV_ID not in gymnasium.registry:
        gymnasium.register(id=ENV_ID, entry_point=ENTRY_POINT, max_episode_steps=MAX_EPISODE_STEPS,
                           vector_entry_point=VECTOR_ENTRY_POINT)


class _RegisteringLoader(importlib.abc.Loader):
    """Runs gymnasium's own loader, then registers our environments in the fresh module."""

    def __init__(self, loader):
        self._loader = loader

    def create_module(self, spec):
        return self._loader.create_module(spec)

    def exec_module(self, module):
        self._loader.exec_module(module)
        _register_now(module)


class _GymnasiumImportHook(importlib.abc.MetaPathFinder):
    """A meta-path finder that only ever answers for the top-level ``gymnasium`` package, once."""

    def find_spec(self, fullname, path, target=None):
        if fullname != "gymnasium":
            return None
        _remove_hook()
        spec = importlib.machinery.PathFinder.find_spec(fullname, path)
        if spec is not None and spec.loader is not None:
            spec.loader = _RegisteringLoader(spec.loader)
        return spec


def _remove_hook() -> None:
    sys.meta_path[:] = [f for f in sys.meta_path if not isinstance(f, _GymnasiumImportHook)]


def register() -> None:
    """Register ReactionWheelCube-v0 with gymnasium now if it is imported, else when it is.

    Never imports gymnasium itself (``import lavendersim`` stays light)."""
    gymnasium = sys.modules.get("gymnasium")
    if gymnasium is not None:
        _register_now(gymnasium)
    elif not any(isinstance(f, _GymnasiumImportHook) for f in sys.meta_path):
        sys.meta_path.insert(0, _GymnasiumImportHook())


def __getattr__(name):
    if name == "ReactionWheelCubeEnv":
        from .reaction_wheel_cube import ReactionWheelCubeEnv

        return ReactionWheelCubeEnv
    if name == "ReactionWheelCubeVectorEnv":
        from .vector import ReactionWheelCubeVectorEnv

        return ReactionWheelCubeVectorEnv
    raise AttributeError(name)
