"""Exceptions of the runtime (input validation errors live in lavendersim.validate).

Every exception the package raises crosses process boundaries (multiprocessing, Dask) with its fields:
one whose ``__init__`` takes its fields as arguments derives from :class:`PicklableError` and names them in
``_init_fields``; one that takes a message only needs nothing (BaseException pickles its args and attributes).
tests/test_processes.py finds every exception class of the package and pickles it.
"""
from __future__ import annotations


class PicklableError:
    """Mixin for an exception whose ``__init__`` takes its fields (not its message): pickles as
    ``type(self)(*fields)`` plus its attribute dictionary (notes and any attribute set later included).

    A subclass lists the ``__init__`` arguments, in order, in ``_init_fields``; each is kept as the attribute of
    the same name.
    """

    __slots__ = ()
    _init_fields: tuple[str, ...] = ()

    def __reduce__(self):
        return (type(self), tuple(getattr(self, f) for f in self._init_fields), dict(self.__dict__) or None)


class DivergenceError(PicklableError, FloatingPointError):
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

    _init_fields = ("step", "body", "cause", "body_name", "t")   # crosses process boundaries with them

    def __init__(self, step: int, body: int, cause: str, body_name: str | None = None, t: float | None = None):
        self.step, self.body, self.cause, self.body_name, self.t = step, body, cause, body_name, t
        who = f"body {body}" + (f" ({body_name!r})" if body_name else "")
        when = f"step {step}" + (f" (t = {t:.6g} s)" if t is not None else "")
        super().__init__(f"simulation diverged at {when}, {who}: {cause}")


class ValidityBoundWarning(UserWarning):
    """A body ran beyond its integrator's validity bound with Sim(..., on_bound="warn") (the text names it)."""


class StaleBuildError(ImportError):
    """The compiled C backend was built from other generated/ sources than the ones on disk."""


class GeneratedFileError(ImportError):
    """A generated module (generated/kernels_numpy.py) does not match generated/manifest.json: it was
    edited by hand or half-written. The message names the file and `lavendersim derive`."""
