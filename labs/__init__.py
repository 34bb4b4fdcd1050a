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

Every lab module defines NAME, TITLE, ``add_arguments(parser)`` (its failure-mode options),
``options_from_args(args) -> dict``, ``compute(backend, **options)`` (compute -> checks -> the
plots' data; no files) and ``run(out_dir, backend, **options)`` (compute, then save).
"""
from __future__ import annotations

import importlib
import sys
import time

from .common import BACKENDS, DEFAULT_OUT, LabResult, report

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

__all__ = ["LABS", "LAB_VIEWS", "lab_module", "compute", "run", "register_cli", "register_views", "LabResult"]


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


def _common_parent():
    import argparse

    p = argparse.ArgumentParser(add_help=False)
    p.add_argument("--out", default=DEFAULT_OUT, metavar="DIR",
                   help=f"output directory; the lab writes DIR/NAME/results.json and PNGs (default: ./{DEFAULT_OUT})")
    p.add_argument("--backend", default="auto", choices=BACKENDS,
                   help="simulator backend for the labs that step a scene (default auto: C when built, else NumPy with a warning)")
    out = p.add_mutually_exclusive_group()
    out.add_argument("--quiet", action="store_true",
                     help="print only failures; no progress bar (a bar is shown on a terminal only)")
    out.add_argument("--verbose", action="store_true",
                     help="print every parameter in full (lab all: each lab's figures and checks too)")
    return p


def _view_parent(scene: str):
    import argparse

    p = argparse.ArgumentParser(add_help=False)
    v = p.add_argument_group(f"live view (the viewer extra; scene {scene!r} of lavendersim.viewer)")
    v.add_argument("--view", action="store_true",
                   help="after the lab, run its scene live in the browser viewer at http://VIEW_HOST:VIEW_PORT")
    v.add_argument("--view-host", default="127.0.0.1", help="interface for --view (default 127.0.0.1)")
    v.add_argument("--view-port", type=int, default=8080, help="port for --view (default 8080; 0 = any free)")
    v.add_argument("--view-duration", type=float, default=None,
                   help="simulated seconds to stream with --view (default: until Ctrl-C)")
    return p


def _line(exc: BaseException) -> str:
    """An error's message on one line (the command line's promise: one line, never a traceback)."""
    return " ".join(str(exc).split())


def _verbosity(args) -> int:
    return 0 if getattr(args, "quiet", False) else (2 if getattr(args, "verbose", False) else 1)


def _with_progress(mod, options: dict, args) -> dict:
    """Add progress=... for the labs whose compute() draws a progress bar (shown on a terminal only)."""
    import inspect

    if "progress" in inspect.signature(mod.compute).parameters and "progress" not in options:
        options = {**options, "progress": not getattr(args, "quiet", False)}
    return options


def _run_one(args) -> int:
    from lavendersim.validate import LavenderInputError

    from .common import check_out_dir
    from .diverged import compute_or_failed
    from .output import check_folder, lab_lock

    mod = lab_module(args.lab_name)
    try:
        check_out_dir(args.out)  # before the lab runs: an unwritable --out is exit 2 at once
    except LavenderInputError as exc:
        print(f"lab {args.lab_name}: invalid option: {_line(exc)}", file=sys.stderr)
        return 2
    if getattr(args, "view", False):
        from lavendersim._install import require

        require("viser", "viewer", f"lavendersim lab {args.lab_name} --view")  # before the lab runs, not after
    try:
        if getattr(args, "view", False):   # a host or port the viewer would refuse: exit 2 before the lab runs
            from lavendersim import viewer
            from lavendersim import validate as V

            viewer.check_host(args.view_host)
            if not 0 <= V.integer("port", args.view_port) <= 65535:
                raise LavenderInputError("port", "must be in 0..65535", f", got {args.view_port}")
        # OUT/NAME is this run's from before the lab computes until its folder is in place (labs/output.py)
        with lab_lock(args.out, args.lab_name):
            check_folder(args.out, args.lab_name)
            options = _with_progress(mod, mod.options_from_args(args), args)
            result = compute_or_failed(mod, args.backend, options).save(args.out)
    except LavenderInputError as exc:
        print(f"lab {args.lab_name}: invalid option: {_line(exc)}", file=sys.stderr)
        return 2
    code = report(result, verbosity=_verbosity(args))
    if getattr(args, "view", False):
        from lavendersim import viewer

        register_views()
        try:
            viewer.run_scene(LAB_VIEWS[args.lab_name], duration=args.view_duration, host=args.view_host,
                             port=args.view_port)
        except LavenderInputError as exc:
            print(f"lab {args.lab_name}: invalid option: {_line(exc)}", file=sys.stderr)
            return 2
        except viewer.ViewerError as exc:   # a frame could not be drawn: one line, exit 1 (as `lavendersim view`)
            print(f"lab {args.lab_name} --view: {_line(exc)}", file=sys.stderr)
            return 1
    return code


# what `lab all` runs: every lab with its chapter parameters; the two sweeps in their quick mode (said in the output)
ALL_OPTIONS: dict[str, dict] = {"accuracy": {"quick": True}, "atlas": {"quick": True}}


def _run_all(args) -> int:
    import contextlib

    from lavendersim.validate import LavenderInputError

    from .common import check_out_dir
    from .output import check_folder, lab_lock

    locks = contextlib.ExitStack()
    try:
        check_out_dir(args.out)
        for name in LABS:   # every lab's folder is this run's before the first lab computes
            locks.enter_context(lab_lock(args.out, name))
            check_folder(args.out, name)
    except LavenderInputError as exc:
        locks.close()
        print(f"lab all: invalid option: {_line(exc)}", file=sys.stderr)
        return 2
    with locks:
        return _run_all_locked(args)


def _run_all_locked(args) -> int:
    from .common import progress
    from .diverged import compute_or_failed

    verbosity = _verbosity(args)
    bar = progress(total=len(LABS), desc="lab all", unit="lab", enabled=verbosity > 0)

    def say(line: str, stream=None) -> None:
        if bar.disable:
            print(line, file=stream or sys.stdout, flush=True)
        else:
            bar.write(line, file=stream or sys.stdout)

    if verbosity:
        quick = ", ".join(f"{n} ({', '.join(f'{k}={v}' for k, v in o.items())})" for n, o in ALL_OPTIONS.items())
        say(f"lab all: {len(LABS)} labs, backend {args.backend}, results in {args.out}/NAME/; "
            f"quick mode for {quick} — `lab accuracy` and `lab atlas` run the full sweeps; details with --verbose")
    failed = []
    for name in LABS:
        bar.set_description(f"lab all: {name}")
        t0 = time.perf_counter()
        mod = lab_module(name)
        try:
            options = _with_progress(mod, dict(ALL_OPTIONS.get(name, {})), args)
            result = compute_or_failed(mod, args.backend, options).save(args.out)
        except Exception as exc:  # one broken lab must not hide the others' results
            failed.append(name)
            say(f"{name:<9} ERROR {type(exc).__name__}: {_line(exc)}  "
                f"({time.perf_counter() - t0:.1f} s)", sys.stderr)
            bar.update(1)
            continue
        secs = time.perf_counter() - t0
        if verbosity >= 2:
            report(result, verbosity=verbosity)
        if not result.passed:
            failed.append(name)
        if verbosity or not result.passed:
            say(result.summary_line(secs), None if result.passed else sys.stderr)
        if not result.passed and verbosity < 2:
            for c in result.failures:
                say(f"          FAIL  {c.describe()}", sys.stderr)
        bar.update(1)
    bar.close()
    if failed:
        print(f"{len(failed)} of {len(LABS)} labs failed: {', '.join(failed)}", file=sys.stderr)
        return 1
    if verbosity:
        print(f"all {len(LABS)} labs pass")
    return 0


def register_cli(subparsers) -> None:
    """Add ``lab NAME|all`` to the ``lavendersim`` command line (each leaf sets ``fn``).

    Parameters
    ----------
    subparsers : argparse._SubParsersAction
        The ``lavendersim`` parser's subcommands (from ``add_subparsers``).
    """
    import argparse

    parent = _common_parent()
    lab = subparsers.add_parser("lab", help="run a chapter lab (or `all`); exits non-zero if a figure is off",
                                description=__doc__.split("\n\n")[0])
    names = lab.add_subparsers(dest="lab_name", required=True, metavar="NAME")
    for name in LABS:
        mod = lab_module(name)
        parents = [parent] + ([_view_parent(LAB_VIEWS[name])] if name in LAB_VIEWS else [])
        p = names.add_parser(name, parents=parents, help=mod.TITLE, description=mod.__doc__,
                             formatter_class=argparse.RawDescriptionHelpFormatter)
        mod.add_arguments(p)
        p.set_defaults(fn=_run_one)
    a = names.add_parser("all", parents=[parent],
                         help="run every lab with its chapter parameters (accuracy and atlas quick); one line per lab")
    a.set_defaults(fn=_run_all)
