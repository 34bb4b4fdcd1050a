"""A lab whose options make its simulation diverge: a failed figure, not an error.

The chapter's failure modes (``lab 01 --damping 100``, ``lab 03 --dt 0.1 --integrator euler``, ...) ask for
settings an explicit integrator cannot step faithfully. The Sim says so — a
:class:`~lavendersim.errors.DivergenceError` while stepping, or a
:class:`~lavendersim.validate.ValidityBoundError` when it is built — and the lab reports it as what it
is: its result has one check, ``no_divergence``, failed, with the divergence recorded in results.json
(``divergence``: the Sim's words; ``divergence_step``, ``divergence_t``, ``divergence_body`` or
``divergence_field``), the options it ran with as its parameters, and no plot. The command line exits 1,
like any failed figure. Every lab module's ``compute`` is decorated with :func:`failed_figure`, so the
module's own ``compute``/``run`` return it too.
"""
from __future__ import annotations

import functools
import inspect
import sys

from lavendersim import validate as V
from lavendersim.errors import DivergenceError

from . import common as C

# what a lab's simulation raises when its options take it beyond what its integrator can step
DIVERGED = (DivergenceError, V.ValidityBoundError)


def _param(v):
    """An option as a results.json value (None: the lab's default; a list of names: comma-joined)."""
    if v is None:
        return "default"
    if isinstance(v, (list, tuple)) and all(isinstance(x, str) for x in v):
        return ", ".join(v)
    try:
        return C._json_value("option", v)
    except TypeError:
        return repr(v)


def diverged_result(lab: str, exc: DivergenceError | V.ValidityBoundError, backend: str, options: dict) -> C.LabResult:
    """The failed :class:`~lavendersim.labs.common.LabResult` of a lab whose simulation diverged.

    Parameters
    ----------
    lab : str
        The lab's name.
    exc : DivergenceError or ValidityBoundError
        What the Sim raised.
    backend : str
        The backend asked for.
    options : dict
        The lab's options as given to its ``compute``.

    Returns
    -------
    LabResult
        One check, ``no_divergence``, failed; figures ``diverged`` and ``divergence*``; no plot.
    """
    text = " ".join(str(exc).split())
    figures: dict = {"diverged": True, "divergence": text}
    if isinstance(exc, DivergenceError):
        figures.update({"divergence_step": int(exc.step), "divergence_body": str(exc.body_name or exc.body)})
        if exc.t is not None:
            figures["divergence_t"] = float(exc.t)
        note = text
    else:
        figures["divergence_field"] = str(exc.field)
        note = f"the Sim refused to start, beyond its integrator's bound: {text}"
    try:
        backend = C.check_backend(backend)   # the backend it ran on ("auto" resolved)
    except V.LavenderInputError:
        pass
    params = {"backend": str(backend), **{k: _param(v) for k, v in options.items() if k != "progress"}}
    checks = [C.holds("no_divergence", False, note)]
    return C.make_result(lab, figures, params, checks)


def failed_figure(compute):
    """Decorate a lab module's ``compute(backend, **options)``: a divergence (:data:`DIVERGED`) is returned as
    :func:`diverged_result` (the lab's ``NAME``, the options as bound to the signature, defaults included).

    Parameters
    ----------
    compute : callable
        The lab's ``compute``.

    Returns
    -------
    callable
        Same signature, never raising DIVERGED.
    """
    signature = inspect.signature(compute)

    @functools.wraps(compute)
    def wrapper(*args, **kwargs):
        try:
            return compute(*args, **kwargs)
        except DIVERGED as exc:
            bound = signature.bind(*args, **kwargs)
            bound.apply_defaults()
            options = dict(bound.arguments)
            backend = options.pop("backend", "auto")
            return diverged_result(sys.modules[compute.__module__].NAME, exc, backend, options)

    return wrapper


def compute_or_failed(mod, backend: str, options: dict) -> C.LabResult:
    """``mod.compute(backend=backend, **options)``; a divergence (:data:`DIVERGED`) becomes a failed result.

    Parameters
    ----------
    mod : module
        The lab's module.
    backend : str
    options : dict
        The lab's ``compute`` keywords.

    Returns
    -------
    LabResult
    """
    try:
        return mod.compute(backend=backend, **options)
    except DIVERGED as exc:
        return diverged_result(mod.NAME, exc, backend, options)
