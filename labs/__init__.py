"""The chapter's labs: each reproduces a figure of chapter 03 as a command and a Python call.

    lavendersim lab NAME [--out DIR] [--backend auto|c|numpy] [lab options]
    lavendersim lab all  [--out DIR] [--backend auto|c|numpy]

From Python: ``lavendersim.labs.run("01", out_dir, backend="numpy", damping=0.01)`` or the lab
module's own ``run(out_dir, backend=..., **options)``; both return a
:class:`~lavendersim.labs.common.LabResult` (a dict of figures and parameters, with ``checks``
and ``passed``) and never raise because a figure is off.

Every lab module defines NAME, TITLE, ``add_arguments(parser)`` (its failure-mode options),
``options_from_args(args) -> dict`` and ``run``.
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

__all__ = ["LABS", "lab_module", "run", "register_cli", "LabResult"]


def lab_module(name: str):
    from lavendersim import validate as V

    V.choice("lab", name, LABS)
    return importlib.import_module(f"{__name__}.{LABS[name]}")


def run(name: str, out_dir=DEFAULT_OUT, backend: str = "auto", **options) -> LabResult:
    """Run lab ``name`` and return its results (see the module docstring)."""
    return lab_module(name).run(out_dir, backend=backend, **options)


def _common_parent():
    import argparse

    p = argparse.ArgumentParser(add_help=False)
    p.add_argument("--out", default=DEFAULT_OUT, metavar="DIR",
                   help=f"output directory; the lab writes DIR/NAME/results.json and PNGs (default: ./{DEFAULT_OUT})")
    p.add_argument("--backend", default="auto", choices=BACKENDS,
                   help="simulator backend for the labs that step a scene (default auto: C when built, else NumPy with a warning)")
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


def _run_one(args) -> int:
    from lavendersim.validate import LavenderInputError

    from .common import check_out_dir

    mod = lab_module(args.lab_name)
    try:
        check_out_dir(args.out)  # before the lab runs: an unwritable --out is exit 2 at once
    except LavenderInputError as exc:
        print(f"lab {args.lab_name}: invalid option: {exc}", file=sys.stderr)
        return 2
    if getattr(args, "view", False):
        from lavendersim._install import require

        require("viser", "viewer", f"lavendersim lab {args.lab_name} --view")  # before the lab runs, not after
    try:
        options = mod.options_from_args(args)
        result = mod.run(args.out, backend=args.backend, **options)
    except LavenderInputError as exc:
        print(f"lab {args.lab_name}: invalid option: {exc}", file=sys.stderr)
        return 2
    code = report(result)
    if getattr(args, "view", False):
        from lavendersim import viewer

        try:
            viewer.run_scene(viewer.LAB_VIEWS[args.lab_name], duration=args.view_duration, host=args.view_host,
                             port=args.view_port)
        except LavenderInputError as exc:
            print(f"lab {args.lab_name}: invalid option: {exc}", file=sys.stderr)
            return 2
    return code


def _run_all(args) -> int:
    from lavendersim.validate import LavenderInputError

    from .common import check_out_dir

    try:
        check_out_dir(args.out)
    except LavenderInputError as exc:
        print(f"lab all: invalid option: {exc}", file=sys.stderr)
        return 2
    summary = []
    for name in LABS:
        t0 = time.perf_counter()
        try:
            result = lab_module(name).run(args.out, backend=args.backend)
            code = report(result)
            status = "pass" if code == 0 else f"FAIL ({len(result.failures)} of {len(result.checks)} checks)"
        except Exception as exc:  # one broken lab must not hide the others' results
            code = 1
            status = f"ERROR {type(exc).__name__}: {exc}"
            print(f"lab {name}: {status}", file=sys.stderr)
        summary.append((name, code, status, time.perf_counter() - t0))
        print()
    print("lab summary:")
    for name, code, status, secs in summary:
        print(f"  {name:<9} {status}  ({secs:.1f} s)")
    failed = [n for n, c, _, _ in summary if c != 0]
    if failed:
        print(f"{len(failed)} of {len(summary)} labs failed: {', '.join(failed)}", file=sys.stderr)
        return 1
    print(f"all {len(summary)} labs pass")
    return 0


def register_cli(subparsers) -> None:
    """Add ``lab NAME|all`` to the ``lavendersim`` command line (each leaf sets ``fn``)."""
    import argparse

    from lavendersim.viewer import LAB_VIEWS

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
    a = names.add_parser("all", parents=[parent], help="run every lab with its chapter parameters; print a summary")
    a.set_defaults(fn=_run_all)
