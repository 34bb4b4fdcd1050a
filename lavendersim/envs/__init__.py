"""Gymnasium environments built on the LavenderSim runtime.

``ReactionWheelCube-v0`` is registered when ``lavendersim`` is imported (if gymnasium is
installed) and is reachable as ``gymnasium.make("lavendersim:ReactionWheelCube-v0")``.
"""
from __future__ import annotations

ENV_ID = "ReactionWheelCube-v0"
ENTRY_POINT = "lavendersim.envs.reaction_wheel_cube:ReactionWheelCubeEnv"
MAX_EPISODE_STEPS = 1000


def register() -> bool:
    """Register ReactionWheelCube-v0 with gymnasium unless it already is; False if gymnasium is
    not installed."""
    try:
        import gymnasium
    except ImportError:
        return False
    if ENV_ID not in gymnasium.registry:
        gymnasium.register(id=ENV_ID, entry_point=ENTRY_POINT, max_episode_steps=MAX_EPISODE_STEPS)
    return True


def __getattr__(name):
    if name == "ReactionWheelCubeEnv":
        from .reaction_wheel_cube import ReactionWheelCubeEnv

        return ReactionWheelCubeEnv
    raise AttributeError(name)
