"""``Sim.model``: the public, read-only view of what a Sim steps, for applications (the envs, the linearization)
that need more than the per-body accessors — so that no application touches a Sim's private attributes."""
from __future__ import annotations

import numpy as np

from .generated import layout as LY


def _ro(a: np.ndarray) -> np.ndarray:
    """A read-only view sharing memory with a (its WRITEABLE flag cannot be turned back on)."""
    return np.frombuffer(memoryview(a).toreadonly(), dtype=a.dtype).reshape(a.shape)


class SimModel:
    """The model a Sim steps, read-only, live (the arrays share memory with the Sim's; they change as it runs).

    Bodies are in the Sim's order (``sim.names``). A body given a full inertia tensor is stepped in its principal
    frame: ``state`` and ``rows`` are in that frame, ``frames`` maps it to the body frame (None when every body's
    frame is principal). Take it with ``sim.model``; it is cheap (each attribute is read from the Sim when asked).

    Attributes
    ----------
    rows : ndarray (nb, MODEL_SIZE), read-only
        Per-body model rows (generated/layout.py MODEL_LAYOUT: kind, I_p, r_b, anchor_w, J, limits, c_w, A_b).
    wheel_counts : ndarray (nb,) int, read-only
        Reaction wheels per body (0 without).
    state : ndarray (nb, 13), read-only
        The stepped state rows [p_w, q, v_w, omega_b] (STATE layout; principal frames), float64 or float32.
    Omega, applied : ndarray (nb, WHEELS_MAX), read-only
        Wheel rates relative to the body, rad/s, and the saturated motor torques of the last step, N·m.
    command : ndarray (nb, WHEELS_MAX), writable
        The held motor commands, N·m. Writing it is :meth:`Sim.set_wheel_commands` without its checks, for a
        stepping loop that validated its numbers (finite; the slots beyond a body's wheels stay 0); every step
        saturates them.
    frames : object or None
        The principal-frame map of bodies given a full inertia tensor (``rotation(i)``: R_bp, 3×3;
        ``internal_row(i, x)``: a body-frame state row in the principal frame), or None.
    effects : tuple
        The scene's effect declarations (force and model effects) the Sim was built from, in scene order.
    advance : callable or None
        ``advance(n) -> bool``: :meth:`Sim.run`'s C fast path for ``1 <= n <= fast_steps`` (False: it stepped
        aside, call ``sim.run(n)``); None where the Sim has none.
    fast_steps : int
        The most steps one ``advance`` call takes.
    counters : object
        ``counters.steps``: the Sim's step count (``sim.steps``), readable without a property call.
    """

    __slots__ = ("_sim",)

    def __init__(self, sim):
        object.__setattr__(self, "_sim", sim)

    def __setattr__(self, name, value):
        raise AttributeError(f"sim.model is read-only (sim.model.{name})")

    rows = property(lambda self: _ro(self._sim._models.rows))
    wheel_counts = property(lambda self: _ro(np.asarray(self._sim._wheel_n)))
    state = property(lambda self: _ro(self._sim._x))
    Omega = property(lambda self: _ro(self._sim._models.Omega))
    applied = property(lambda self: _ro(self._sim._models.applied))
    command = property(lambda self: self._sim._models.command)
    frames = property(lambda self: self._sim._frames)
    effects = property(lambda self: tuple(self._sim._effect_objs))
    advance = property(lambda self: None if self._sim._fast is None else self._sim._fast.advance)
    fast_steps = property(lambda self: int(self._sim._fast_n))
    counters = property(lambda self: self._sim._ctr)

    def kind(self, i: int) -> tuple[bool, bool]:
        """(jointed, wheeled) of body i."""
        k = int(self._sim._models.rows[i, LY.MODEL_KIND])
        return bool(k & LY.KIND_JOINT), bool(k & LY.KIND_WHEELS)
