"""Backends advance the state arrays of a scene: `advance(state, params, effects, integrator,
normalize, dt, n_steps)` mutates state (nb, 13) in place or raises DivergenceError and leaves it
unchanged. "numpy" needs no compiler; "c" steps inside C."""
from __future__ import annotations

import numpy as np

from .. import validate as V

INTEGRATORS = {"euler": 1, "semi_implicit_euler": 1, "rk4": 4}  # name -> RHS evaluations per step
BACKENDS = ("c", "numpy")


def get(name: str):
    name = V.choice("backend", name, BACKENDS)
    if name == "numpy":
        from .numpy_backend import NumpyBackend

        return NumpyBackend()
    from .c_backend import CBackend

    return CBackend()


def divergence_cause(x_before: np.ndarray, dt: float, integrator: str) -> str:
    """A plain guess at why one body's step went non-finite, from its state before the step."""
    with np.errstate(over="ignore", invalid="ignore"):
        w = float(np.linalg.norm(x_before[10:13]))
        v = float(np.linalg.norm(x_before[7:10]))
    if not np.all(np.isfinite(x_before)):
        return "the state was already non-finite before the step"
    wdt = w * dt
    limit = {"euler": 0.1, "semi_implicit_euler": 0.1, "rk4": 1.0}.get(integrator, 1.0)
    if wdt > limit:
        return f"|omega|*dt = {wdt:.3g} is too large for {integrator} (keep it below ~{limit}); reduce dt"
    return (f"state grew without bound (|omega| = {w:.3g} rad/s, |v| = {v:.3g} m/s, dt = {dt:g} s); "
            "check effect strengths (damping c*dt/I, forces) and the integrator")
