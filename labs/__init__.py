"""The chapter's labs: each reproduces a figure of chapter 03 as a command and a Python call.

    lavendersim lab NAME [--out DIR] [--backend auto|c|numpy] [lab options]
    lavendersim lab all  [--out DIR] [--backend auto|c|numpy]

From Python: ``lavendersim.labs.compute("01", damping=0.01)`` computes a lab and writes nothing;
``lavendersim.labs.run("01", out_dir, backend="numpy", damping=0.01)`` (or the lab module's own
``compute``/``run``) also writes OUT/NAME/. Both return a :class:`~lavendersim.labs.common.LabResult`
(a dict of figures and parameters, with ``checks``, ``passed``, ``figure(name)`` -> a matplotlib
Figure, ``summary_line()`` and ``save(out_dir)``) and never raise because a figure is off — nor because
a failure mode's simulation diverged: ``labs.compute``/``labs.run`` and the command line return that as a
failed check ``no_divergence`` with the divergence recorded (:mod:`lavendersim.labs.diverged`; a lab
module's own ``compute`` raises it). OUT/NAME/ is written whole, never through a link, one run at a time
(:mod:`lavendersim.labs.output`).

Every lab module defines NAME, TITLE, ``compute(backend, **options)`` (compute -> checks -> the
plots' data; no files) and ``run(out_dir, backend, **options)`` (compute, then save). The command
line, with each lab's options, is :mod:`lavendersim.cli.lab`.
"""
from __future__ import annotations

import importlib

from .common import DEFAULT_OUT, LabResult

# lab name -> module (imported lazily so `lavendersim derive` does not pay for matplotlib)
LABS: dict[str, str] = {
    "force": "force",
    "momentum": "momentum",
    "01": "lab01_equal_torque",
    "02": "lab02_orientation",
    "03": "lab03_torque_free",
    "04": "lab04_reaction_wheel",
    "hard": "hard_cases",
    "accuracy": "accuracy",
    "atlas": "atlas",
}

# lab name -> the lavendersim.viewer scene `lavendersim lab NAME --view` streams after the lab has run
LAB_VIEWS: dict[str, str] = {"03": "lab03", "04": "wheel"}

__all__ = ["LABS", "LAB_VIEWS", "ALL_OPTIONS", "lab_module", "compute", "run", "register_views", "LabResult"]


def _lab03_view():
    """Lab 03's viewer scene, its module imported only when the scene is built."""
    return lab_module("03").view_scene()


def register_views() -> None:
    """Register the labs' own viewer scenes with lavendersim.viewer (``lab03``: lab 03's rods), so
    ``lavendersim view`` and ``lab NAME --view`` find them; the viewer itself does not import labs.
    Idempotent; imports no lab module (each is imported when its scene is built)."""
    from lavendersim import viewer

    viewer.register_scene("lab03", _lab03_view)


def lab_module(name: str):
    """The module of lab ``name`` (imported on first use).

    Parameters
    ----------
    name : str
        A key of LABS ("force", "momentum", "01" … "04", "hard", "accuracy", "atlas").

    Returns
    -------
    module

    Raises
    ------
    lavendersim.validate.LavenderInputError
        ``name`` is not a lab.
    """
    from lavendersim import validate as V

    V.choice("lab", name, LABS)
    return importlib.import_module(f"{__name__}.{LABS[name]}")


def compute(name: str, backend: str = "auto", **options) -> LabResult:
    """Compute lab ``name`` and return its results, writing nothing (see the module docstring).

    Parameters
    ----------
    name : str
        A key of LABS.
    backend : {"auto", "c", "numpy"}, default "auto"
        Simulator backend for the labs that step a scene.
    **options
        The lab's own options (its ``compute`` keywords, e.g. ``damping`` for lab 01).

    Returns
    -------
    LabResult

    Raises
    ------
    lavendersim.validate.LavenderInputError
        Unknown lab or an invalid option.
    """
    from .diverged import compute_or_failed

    return compute_or_failed(lab_module(name), backend, options)


def run(name: str, out_dir=DEFAULT_OUT, backend: str = "auto", **options) -> LabResult:
    """Run lab ``name`` and return its results (see the module docstring).

    Parameters
    ----------
    name : str
        A key of LABS.
    out_dir : str or Path, default DEFAULT_OUT
        Output directory; the lab writes ``out_dir/NAME/``.
    backend : {"auto", "c", "numpy"}, default "auto"
        Simulator backend for the labs that step a scene.
    **options
        The lab's own options (its ``compute`` keywords).

    Returns
    -------
    LabResult

    Raises
    ------
    lavendersim.validate.LavenderInputError
        Unknown lab, an invalid option or an unwritable ``out_dir``.
    """
    return compute(name, backend, **options).save(out_dir)


# what `lab all` runs: every lab with its chapter parameters; the two sweeps in their quick mode (said in the output)
ALL_OPTIONS: dict[str, dict] = {"accuracy": {"quick": True}, "atlas": {"quick": True}}
