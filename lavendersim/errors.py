"""Exceptions of the runtime (input validation errors live in lavendersim.validate)."""
from __future__ import annotations


class DivergenceError(FloatingPointError):
    """A step produced a non-finite state, ran beyond its integrator's validity bound, grew a conserved
    quantity beyond Sim's max_growth, or (implicit_gyro) had no root its Newton solve could find. The
    simulator's state is left as it was before the call.

    Parameters
    ----------
    step : int
        0-based index of the failing step within the call.
    body : int
        Index of the body in the scene.
    cause : str
        The likely cause, in words.
    body_name : str or None, optional
        The body's name.
    t : float or None, optional
        Simulated time of the failing step, s.
    """

    def __init__(self, step: int, body: int, cause: str, body_name: str | None = None, t: float | None = None):
        self.step, self.body, self.cause, self.body_name, self.t = step, body, cause, body_name, t
        who = f"body {body}" + (f" ({body_name!r})" if body_name else "")
        when = f"step {step}" + (f" (t = {t:.6g} s)" if t is not None else "")
        super().__init__(f"simulation diverged at {when}, {who}: {cause}")

    def __reduce__(self):   # crosses process boundaries (multiprocessing, Dask) with its fields
        return (type(self), (self.step, self.body, self.cause, self.body_name, self.t))


class ValidityBoundWarning(UserWarning):
    """A body ran beyond its integrator's validity bound with Sim(..., on_bound="warn") (the text names it)."""


class StaleBuildError(ImportError):
    """The compiled C backend was built from other generated/ sources than the ones on disk."""


class GeneratedFileError(ImportError):
    """A generated module (generated/kernels_numpy.py) does not match generated/manifest.json: it was
    edited by hand or half-written. The message names the file and `lavendersim derive`."""
