"""``Sim.model``: the public, read-only view of what a Sim steps, for applications (the envs, the linearization)
that need more than the per-body accessors — so that no application touches a Sim's private attributes."""
from __future__ import annotations

from typing import Any

import numpy as np

from .generated import layout as LY


def _ro(a: np.ndarray) -> np.ndarray:
    """A read-only view sharing memory with a (its WRITEABLE flag cannot be turned back on)."""
    return np.frombuffer(a.data.toreadonly(), dtype=a.dtype).reshape(a.shape)


def _attr(get, doc: str) -> property:
    """A read-only property whose getter carries doc (what help() and the API docs show)."""
    get.__doc__ = doc
    return property(get)


class SimModel:
    """The model a Sim steps, read-only, live (the arrays share memory with the Sim's; they change as it runs).

    Bodies are in the Sim's order (``sim.names``). A body given a full inertia tensor is stepped in its principal
    frame: ``state`` and ``rows`` are in that frame, ``frames`` maps it to the body frame (None when every body's
    frame is principal). Take it with ``sim.model``; it is cheap (each attribute is read from the Sim when asked).

    Parameters
    ----------
    sim : lavendersim.Sim
        The Sim to view.
    """

    __slots__ = ("_sim",)
    _sim: Any    # the Sim (not imported: sim imports this module; no import circle, even for annotations)

    def __init__(self, sim: Any) -> None:
        object.__setattr__(self, "_sim", sim)

    def __setattr__(self, name, value):
        raise AttributeError(f"sim.model is read-only (sim.model.{name})")

    rows = _attr(lambda self: _ro(self._sim._models.rows), """ndarray (nb, MODEL_SIZE), read-only: per-body
        model rows (generated/layout.py MODEL_LAYOUT: kind, I_p, r_b, anchor_w, J, limits, c_w, A_b). A plain body's
        row (kind 0: no joint, no wheels) is all zeros and ignored by the steppers; its moments are in ``sim.params``.""")
    wheel_counts = _attr(lambda self: _ro(self._sim._wheel_n.astype(np.int64)),
                            "ndarray (nb,) int, read-only: reaction wheels per body (0 without).")
    state = _attr(lambda self: _ro(self._sim._x), """ndarray (nb, 13), read-only: the stepped state rows
        [p_w, q, v_w, omega_b] (STATE layout; principal frames), float64 or float32.""")
    Omega = _attr(lambda self: _ro(self._sim._models.Omega),
                     "ndarray (nb, WHEELS_MAX), read-only: wheel rates relative to the body, rad/s.")
    applied = _attr(lambda self: _ro(self._sim._models.applied),
                       "ndarray (nb, WHEELS_MAX), read-only: the saturated motor torques of the last step, N·m.")
    command = _attr(lambda self: self._sim._models.command, """ndarray (nb, WHEELS_MAX), writable: the held
        motor commands, N·m. Writing it is Sim.set_wheel_commands without its checks, for a stepping loop that
        validated its numbers (finite; the slots beyond a body's wheels stay 0); every step saturates them.""")
    frames = _attr(lambda self: self._sim._frames, """The principal-frame map of bodies given a full inertia
        tensor (``rotation(i)``: R_bp, 3×3; ``internal_row(i, x)``: a body-frame state row in the principal
        frame), or None.""")
    effects = _attr(lambda self: tuple(self._sim._effect_objs),
                       "tuple: the scene's effect declarations (force and model effects) the Sim was built from.")
    advance = _attr(lambda self: None if self._sim._fast is None else self._sim._fast.advance, """callable or
        None: ``advance(n) -> bool``, Sim.run's C fast path for ``1 <= n <= fast_steps`` (False: it stepped aside,
        call ``sim.run(n)``); None where the Sim has none.""")
    fast_steps = _attr(lambda self: int(self._sim._fast_n), "int: the most steps one ``advance`` call takes.")
    counters = _attr(lambda self: self._sim._ctr,
                        "``counters.steps`` is the Sim's step count (``sim.steps``), read without a property call.")

    def kind(self, i: int) -> tuple[bool, bool]:
        """What body i's model row holds.

        Parameters
        ----------
        i : int
            The body's index in ``sim.names``.

        Returns
        -------
        tuple of bool
            (jointed: on a spherical joint, wheeled: with reaction wheels).
        """
        k = int(self._sim._models.rows[i, LY.MODEL_KIND])
        return bool(k & LY.KIND_JOINT), bool(k & LY.KIND_WHEELS)
