"""``lavendersim lab NAME|all``: run the chapter's labs (:mod:`lavendersim.labs`) from the command line.

    lavendersim lab NAME [--out DIR] [--backend auto|c|numpy] [--json] [--quiet|--verbose] [lab options]
    lavendersim lab all  [--out DIR] [--backend auto|c|numpy] [--json] [--quiet|--verbose]

Each lab writes OUT/NAME/ (results.json and its plots). ``--json`` prints the results (what results.json holds;
for ``all`` an object per lab) as one JSON document on stdout. Exit 0: every check passes; 1: a figure is off
(or a failure mode diverged); 2: bad input.
"""
from __future__ import annotations

import argparse
import sys
import time
from typing import Any

from . import _common

HELP = "run a chapter lab (or `all`); exits non-zero if a figure is off"


def add_parser(sub) -> None:
    """Add ``lab NAME|all`` to the ``lavendersim`` command line (each leaf sets ``fn``)."""
    from lavendersim import labs

    parent = _lab_parent()
    lab = sub.add_parser("lab", help=HELP, description=labs.__doc__.split("\n\n")[0])
    names = lab.add_subparsers(dest="lab_name", required=True, metavar="NAME")
    for name in labs.LABS:
        mod = labs.lab_module(name)
        parents = [parent] + ([_view_parent(labs.LAB_VIEWS[name])] if name in labs.LAB_VIEWS else [])
        p = names.add_parser(name, parents=parents, help=mod.TITLE, description=mod.__doc__,
                             formatter_class=argparse.RawDescriptionHelpFormatter)
        for flag, keyword, kw in lab_options(name):
            p.add_argument(flag, dest=keyword, **{"default": argparse.SUPPRESS, **kw})
        p.set_defaults(fn=run_one)
    a = names.add_parser("all", parents=[parent],
                         help="run every lab with its chapter parameters (accuracy and atlas quick); one line per lab")
    a.set_defaults(fn=run_all)


def _names(text: str) -> list[str]:
    return [c.strip() for c in text.split(",") if c.strip()]


def lab_options(name: str) -> list[tuple[str, str, dict]]:
    """Lab ``name``'s own options (its failure modes and paw-checks): (flag, the keyword of the lab's
    ``compute`` it sets, argparse keywords). An option not given is not passed (``compute``'s default is
    the chapter's), except ``--quick``: the command line runs the full sweep unless asked."""
    from lavendersim import backends, labs

    cases = ", ".join(labs.lab_module("hard").CASES) if name == "hard" else ""
    chapter = dict(choices=backends.of_family("explicit_rk"))   # the chapter's methods: euler, ..., rk4
    Option = tuple[str, str, dict[str, Any]]   # (flag, dest, add_argument's keywords)
    quick: Option = ("--quick", "quick", dict(action="store_true", default=False))   # compute's default is the quick sweep
    workers: Option = ("--workers", "workers", dict(type=int, metavar="N", help="local worker processes (default: every "
                                            "core; 1 = serial in this process)"))
    dask: Option = ("--dask", "dask", dict(metavar="ADDRESS", help="run on an existing Dask scheduler, e.g. tcp://host:8786 "
                                   "(the distributed extra)"))
    table: dict[str, list[Option]] = {
        "force": [("--offset", "offset", dict(type=float, metavar="X", help="lever arm along x in m (default 0.3; "
                                             "paw-check 2 is always run at -0.3)"))],
        "momentum": [("--mass-scale", "mass_scale", dict(type=float, metavar="S", help="paw-check 1 multiplies every "
                                                         "mass by S (default 2: exact in floating point)"))],
        "01": [("--dt", "dt", dict(type=float, help="time step in s (default 1e-3); 0.1 s / dt must be an integer")),
               ("--integrator", "integrator", dict(chapter, help="failure mode: euler shows integration error in "
                                                                  "the rotation angle (default rk4)")),
               ("--damping", "damping", dict(type=float, metavar="C", help="failure mode: angular damping c in "
                                             "N·m·s/rad on every body (e.g. 0.01); the ratio is no longer constant"))],
        "02": [("--dt", "dt", dict(type=float, help="time step in s (default 0.01); T / dt must be an integer")),
               ("--single-axis", "single_axis", dict(action="store_true", help="failure mode: omega = [|omega|, 0, 0] "
                                                     "rad/s, which hides the Euler-angle bug"))],
        "03": [("--dt", "dt", dict(type=float, help="time step in s (default 1e-3)")),
               ("--integrator", "integrator", dict(chapter, help="failure mode: euler shows energy drift (default rk4)")),
               ("--no-normalize", "normalize", dict(action="store_false", help="failure mode: do not renormalize q "
                                                     "after each step")),
               ("--search", "search", dict(action="store_true", help="also rerun the parameter search that chose the "
                                           "mixed-axis setup and print its hits"))],
        "04": [("--torque", "torque", dict(type=float, metavar="U", help="x-wheel command in N·m (default 0.05; below "
                                           "the 0.2 N·m limit)")),
               ("--T", "T", dict(type=float, help="duration of the sign runs in s (default 1)"))],
        "hard": [("--cases", "cases", dict(type=_names, metavar="A,B", help="comma-separated subset of the catalogue "
                                           f"(default: all): {cases}")),
                 ("--integrator", "integrator", dict(help="failure mode: assert every bound with this integrator "
                                                     "instead of the one the issue names"))],
        "accuracy": [(quick[0], quick[1], dict(quick[2], help="reduced sweep (2 cases, dt 2^-4..2^-9, 1 repeat; "
                                                              "< 20 s) for tests")),
                     ("--no-mujoco", "mujoco", dict(action="store_false", help="skip MuJoCo even when it is installed")),
                     (*workers[:2], dict(workers[2], help=workers[2]["help"] + "; the timing runs are always serial "
                                                                               "in this process")),
                     (*dask[:2], dict(dask[2], help=dask[2]["help"] + "; timing stays local and serial")),
                     ("--integrators", "integrators", dict(type=_names, metavar="A,B", help="comma-separated lavendersim "
                      "integrators to measure (default: every built-in); a name that is not built in is a user's tableau "
                      "(lavendersim derive --user, docs/extending.md), measured on both backends with its declared "
                      "order as the expected slope"))],
        "atlas": [(quick[0], quick[1], dict(quick[2], help="coarse grid: |ω|·dt 1e-4…10 one per decade, ratios 1, "
                                                           "1e3, 1e6 (~20 s on one core; what lab all runs)")),
                  workers, dask,
                  ("--rtol", "rtol", dict(type=float, help="dopri5's rtol (default 1e-6; atol = rtol × 1e-3)"))],
    }
    return table.get(name, [])


def _lab_parent() -> argparse.ArgumentParser:
    from lavendersim.labs.common import BACKENDS, DEFAULT_OUT

    p = argparse.ArgumentParser(add_help=False)
    p.add_argument("--out", default=DEFAULT_OUT, metavar="DIR",
                   help=f"output directory; the lab writes DIR/NAME/results.json and PNGs (default: ./{DEFAULT_OUT})")
    p.add_argument("--backend", default="auto", choices=BACKENDS,
                   help="simulator backend for the labs that step a scene (default auto: C when built, else NumPy with a warning)")
    p.add_argument("--json", action="store_true",
                   help="print the results (what results.json holds; lab all: an object per lab) as one JSON "
                        "document on stdout")
    out = p.add_mutually_exclusive_group()
    out.add_argument("--quiet", action="store_true",
                     help="print only failures; no progress bar (a bar is shown on a terminal only)")
    out.add_argument("--verbose", action="store_true",
                     help="also print every parameter in full, each check and the files written (lab all: each "
                          "lab's figures and checks too)")
    return p


def _view_parent(scene: str) -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(add_help=False)
    v = p.add_argument_group(f"live view (the viewer extra; scene {scene!r} of lavendersim.viewer)")
    v.add_argument("--view", action="store_true",
                   help="after the lab, run its scene live in the browser viewer at http://VIEW_HOST:VIEW_PORT")
    v.add_argument("--view-host", default="127.0.0.1", help="interface for --view (default 127.0.0.1)")
    v.add_argument("--view-port", type=int, default=8080, help="port for --view (default 8080; 0 = any free)")
    v.add_argument("--view-duration", type=float, default=None,
                   help="simulated seconds to stream with --view (default: until Ctrl-C)")
    return p


def _verbosity(args) -> int:
    """0: failures only (--quiet, and --json: stdout holds the JSON); 1: the default; 2: --verbose."""
    return 0 if args.quiet or args.json else (2 if args.verbose else 1)


def _options(mod, args, options: dict) -> dict:
    """The lab's options, with progress=... for the labs whose compute() draws a progress bar (a terminal only)."""
    import inspect

    if "progress" in inspect.signature(mod.compute).parameters and "progress" not in options:
        options = {**options, "progress": not args.quiet}
    return options


def _invalid(name: str, exc: BaseException) -> int:
    print(f"lab {name}: invalid option: {_common.one_line(exc)}", file=sys.stderr)
    return 2


def _check_view(args) -> None:
    """--view: the extra is there and the host and port are ones the viewer accepts, before the lab runs."""
    from lavendersim import validate as V
    from lavendersim import viewer
    from lavendersim._install import require

    require("viser", "viewer", f"lavendersim lab {args.lab_name} --view")
    viewer.check_host(args.view_host)
    if not 0 <= V.integer("port", args.view_port) <= 65535:
        raise V.LavenderInputError("port", "must be in 0..65535", f", got {args.view_port}")


def run_one(args) -> int:
    """``lavendersim lab NAME``: compute, save OUT/NAME/, report; then --view."""
    from lavendersim import labs
    from lavendersim.labs.common import check_out_dir
    from lavendersim.labs.diverged import compute_or_failed
    from lavendersim.labs.output import check_folder, lab_lock
    from lavendersim.validate import LavenderInputError

    mod = labs.lab_module(args.lab_name)
    view = getattr(args, "view", False)
    try:
        check_out_dir(args.out)  # before the lab runs: an unwritable --out is exit 2 at once
        if view:
            _check_view(args)
        # OUT/NAME is this run's from before the lab computes until its folder is in place (labs/output.py)
        with lab_lock(args.out, args.lab_name):
            check_folder(args.out, args.lab_name)
            options = _options(mod, args, {k: getattr(args, k) for _f, k, _kw in lab_options(args.lab_name)
                                           if hasattr(args, k)})
            result = compute_or_failed(mod, args.backend, options).save(args.out)
    except LavenderInputError as exc:
        return _invalid(args.lab_name, exc)
    if args.json:
        _common.emit_json(dict(result))
    code = _report(result, args)
    return _view(args) or code if view else code


def _report(result, args) -> int:
    """One lab's report; 0 if every check passes, else 1. By default short (issue 31): the figures and one line;
    --verbose adds every parameter, each check and the files written; --quiet/--json: the failures only."""
    from lavendersim.labs import common as C

    verbosity = _verbosity(args)
    if verbosity != 1:
        return C.report(result, verbosity=verbosity)
    print(f"== lab {result.lab} -> {result.out_dir}")
    for k in result.figure_names:
        print(f"  {k} = {C._show(result[k])}")
    if not result.passed:
        return C.report(result, verbosity=0)
    print(f"lab {result.lab}: all {len(result.checks)} checks pass (every parameter and check: --verbose)")
    return 0


def _view(args) -> int:
    from lavendersim import labs, viewer
    from lavendersim.validate import LavenderInputError

    labs.register_views()
    try:
        viewer.run_scene(labs.LAB_VIEWS[args.lab_name], duration=args.view_duration, host=args.view_host,
                         port=args.view_port)
    except LavenderInputError as exc:
        return _invalid(args.lab_name, exc)
    except viewer.ViewerError as exc:   # a frame could not be drawn: one line, exit 1 (as `lavendersim view`)
        print(f"lab {args.lab_name} --view: {_common.one_line(exc)}", file=sys.stderr)
        return 1
    return 0


def run_all(args) -> int:
    """``lavendersim lab all``: every lab with ALL_OPTIONS, one line each; their folders locked first."""
    import contextlib

    from lavendersim import labs
    from lavendersim.labs.common import check_out_dir
    from lavendersim.labs.output import check_folder, lab_lock
    from lavendersim.validate import LavenderInputError

    locks = contextlib.ExitStack()
    try:
        check_out_dir(args.out)
        for name in labs.LABS:   # every lab's folder is this run's before the first lab computes
            locks.enter_context(lab_lock(args.out, name))
            check_folder(args.out, name)
    except LavenderInputError as exc:
        locks.close()
        return _invalid("all", exc)
    with locks:
        return _run_all_locked(args)


def _run_all_locked(args) -> int:
    from lavendersim import labs
    from lavendersim.labs.common import report
    from lavendersim.labs.diverged import compute_or_failed

    verbosity = _verbosity(args)
    bar = _common.progress(total=len(labs.LABS), desc="lab all", unit="lab", enabled=not args.quiet)

    def say(line: str, stream=None) -> None:
        if bar.disable:
            print(line, file=stream or sys.stdout, flush=True)
        else:
            bar.write(line, file=stream or sys.stdout)

    if verbosity:
        quick = ", ".join(f"{n} ({', '.join(f'{k}={v}' for k, v in o.items())})" for n, o in labs.ALL_OPTIONS.items())
        say(f"lab all: {len(labs.LABS)} labs, backend {args.backend}, results in {args.out}/NAME/; "
            f"quick mode for {quick} — `lab accuracy` and `lab atlas` run the full sweeps; details with --verbose")
    failed: list[str] = []
    results: dict[str, Any] = {}   # name -> its LabResult, or {"error": message}
    for name in labs.LABS:
        bar.set_description(f"lab all: {name}")
        t0 = time.perf_counter()
        mod = labs.lab_module(name)
        try:
            options = _options(mod, args, dict(labs.ALL_OPTIONS.get(name, {})))
            result = results[name] = compute_or_failed(mod, args.backend, options).save(args.out)
        except Exception as exc:  # one broken lab must not hide the others' results
            failed.append(name)
            results[name] = {"error": f"{type(exc).__name__}: {_common.one_line(exc)}"}
            say(f"{name:<9} ERROR {results[name]['error']}  ({time.perf_counter() - t0:.1f} s)", sys.stderr)
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
    if args.json:
        _common.emit_json({"passed": not failed, "failed": failed,
                           "labs": {n: dict(r) for n, r in results.items()}})
    if failed:
        print(f"{len(failed)} of {len(labs.LABS)} labs failed: {', '.join(failed)}", file=sys.stderr)
        return 1
    if verbosity:
        print(f"all {len(labs.LABS)} labs pass")
    return 0
