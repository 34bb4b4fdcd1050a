"""Backends advance the state arrays of a scene:

    advance(state, params, effects, integrator, normalize, dt, n_steps, models=None, adaptive=None)

mutates state (nb, 13) (float64; or float32: FLOAT32_INTEGRATORS on plain bodies, built-in effects, in single
precision throughout) (and, with `models`, models.Omega and models.applied; with `adaptive`,
adaptive.h and adaptive.nfev) in place, or raises DivergenceError and leaves every array unchanged.
"numpy" needs no compiler; "c" steps inside C. dopri5 needs `adaptive` (an Adaptive); the PLAIN_ONLY
integrators (splitting, implicit_gyro, splitting4, rk4_expmap, symtop4, symtop_bm6) accept plain bodies only (ValueError
otherwise; Sim raises LavenderInputError first).

`models` (a `Models`, or None when no body has a joint or wheels) carries the per-body model:
rows (nb, MODEL_SIZE) laid out as MODEL_LAYOUT; Omega (nb, WHEELS_MAX) wheel rates relative to the
body, rad/s (integrated); command (nb, WHEELS_MAX) motor torque commands, N·m, held over the whole
call; applied (nb, WHEELS_MAX) written with the saturated torques of the last step. A body uses the
first Models.wheel_counts[b] slots (three on the body axes; the rest padded, at rest). A body of kind 0 uses the
plain rigid-body paths and ignores its row; bodies of different kinds mix freely.
"""
from __future__ import annotations

from .base import *  # noqa: F401,F403  (the shared definitions, re-exported: lavendersim.backends.X as before)
from .. import validate as V

BACKEND_CHOICES = ("auto",) + BACKENDS
_UNSET = object()
_c_problem: object = _UNSET   # why the C backend cannot be used (str), None if it can; looked up once
_fallback_warned = False


class BackendFallbackWarning(UserWarning):
    """backend="auto" chose the NumPy backend because the C backend cannot be used (the text says why)."""


def c_unavailable() -> str | None:
    """Why the C backend cannot be used in this process (not built, failed to load, stale), or None.

    Looked up once per process; importing the C backend checks that the build matches generated/."""
    global _c_problem
    if _c_problem is _UNSET:
        try:
            from . import c_backend  # noqa: F401  (ImportError, or StaleBuildError which is one)
            _c_problem = None
        except ImportError as exc:
            _c_problem = str(exc)
    return _c_problem  # type: ignore[return-value]


def resolve(name: str = "auto") -> str:
    """The backend a name stands for: "c", "numpy", or for "auto" C when its extension is built and
    current, else NumPy with one warning per process (a BackendFallbackWarning that says why).

    An explicit "c" is returned as is: loading it (:func:`get`) raises ImportError / StaleBuildError
    with the fix.

    Parameters
    ----------
    name : {"auto", "c", "numpy"}, default "auto"

    Returns
    -------
    str
        "c" or "numpy".

    Raises
    ------
    lavendersim.validate.LavenderInputError
        ``name`` is not one of BACKEND_CHOICES.

    Warns
    -----
    BackendFallbackWarning
        "auto" fell back to NumPy (once per process).
    """
    global _fallback_warned
    name = V.choice("backend", name, BACKEND_CHOICES)
    if name != "auto":
        return name
    why = c_unavailable()
    if why is None:
        return "c"
    if not _fallback_warned:
        import warnings

        _fallback_warned = True
        warnings.warn(f"LavenderSim runs on the NumPy backend (much slower): the C backend is unavailable: {why}",
                      BackendFallbackWarning, stacklevel=3)
    return "numpy"


def get(name: str = "auto"):
    """A backend object for `name` ("auto", "c" or "numpy"; see resolve).

    Parameters
    ----------
    name : {"auto", "c", "numpy"}, default "auto"

    Returns
    -------
    NumpyBackend or CBackend
        An object with ``advance(state, params, effects, integrator, normalize, dt, n_steps, models=None,
        adaptive=None)``.

    Raises
    ------
    ImportError
        An explicit "c" whose extension is not built, or is stale (StaleBuildError).
    """
    name = resolve(name)
    if name == "numpy":
        from .numpy_backend import NumpyBackend

        return NumpyBackend()
    from .c_backend import CBackend

    return CBackend()
