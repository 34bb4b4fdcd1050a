"""``lavendersim derive``: print the equations of derive/ into generated/, check them, or derive a user's set.

It says what it is doing: one line per phase on stderr (a bar on a terminal), nothing with ``--quiet``;
``--json`` prints what was done (folder, changed or stale files, seconds) as one JSON document.
"""
from __future__ import annotations

import inspect
import sys
import time
from pathlib import Path

from . import _common

HELP = "derive the equations with SymPy and print them into generated/"


def add_parser(sub) -> None:
    d = sub.add_parser("derive", help=HELP, description=HELP[0].upper() + HELP[1:] + ". Progress (one line per "
                       "phase, or a bar on a terminal) goes to stderr.",
                       parents=[_common.parent(json_help="print what was done (folder, changed or stale files, "
                                                         "seconds) as one JSON document on stdout")])
    d.add_argument("--check", action="store_true", help="write nothing; exit 1 and name the stale files if generated/ is not current")
    d.add_argument("--full", action="store_true", help="with --check: always re-derive in memory (skip the manifest fast path)")
    d.add_argument("--out", help="output directory (default: the package's generated/; with --user: the user "
                                 "directory's sets/, see lavendersim.extending)")
    d.add_argument("--user", metavar="FILE", help="derive YOUR declarations (EFFECTS, KERNELS and/or TABLEAUX in FILE, see "
                                                  "docs/extending.md): print them and compile their C (cached)")
    d.set_defaults(fn=run)


class _Phases:
    """The progress callback derive's codegen calls before each phase: a bar on a terminal, else one stderr line
    per phase ("derive: printing C ..."), nothing when quiet. Phases are few (under ten), so a pipe gets a
    handful of lines, never a flood."""

    def __init__(self, quiet: bool):
        self.quiet, self.bar, self.t0 = quiet, None, time.perf_counter()
        if not quiet and _common.is_terminal():
            self.bar = _common.progress(desc="derive", unit="phase")

    def __call__(self, phase: str) -> None:
        if self.quiet:
            return
        if self.bar is not None:
            self.bar.set_description(f"derive: {phase}")
            self.bar.update(1)
        else:
            print(f"derive: {phase} ({time.perf_counter() - self.t0:.0f} s)", file=sys.stderr, flush=True)

    def close(self) -> None:
        if self.bar is not None:
            self.bar.close()


def _with_phases(fn, *a, phases, **k):
    """fn(*a, **k), passing the progress callback when fn takes one."""
    if "progress" in inspect.signature(fn).parameters:
        k["progress"] = phases
    try:
        return fn(*a, **k)
    finally:
        phases.close()


def run(args) -> int:
    from lavendersim import validate as V

    if args.out is not None and not args.check:   # --out '' is refused, never taken for "no --out"
        out_dir = V.writable_dir("out", args.out)  # exit 2 and one line, before anything is derived
        # derive swaps a complete sibling folder in (derive/atomic.py): the parent must be writable too
        V.writable_dir("out", out_dir.resolve().parent)
    if args.user:
        return _user(args)
    if args.out is not None and not str(args.out):
        raise V.LavenderInputError("out", "expected a directory path", ", got ''")
    from . import generated_dir

    out = Path(args.out) if args.out is not None else generated_dir()
    return _check(args, out) if args.check else _write(args, out)


def _check(args, out: Path) -> int:
    from lavendersim._install import rebuild_command
    from lavendersim.derive import codegen

    t0 = time.perf_counter()
    stale = _with_phases(codegen.check, out, full=args.full, phases=_Phases(args.quiet))
    dt = time.perf_counter() - t0
    if args.json:
        _common.emit_json({"directory": str(out), "current": not stale, "stale": stale, "seconds": dt})
    if stale:
        if not args.json:
            print(f"generated/ is stale ({out}): {', '.join(stale)} differ from what derive/ produces.", file=sys.stderr)
        if not (args.json or args.quiet):
            print(f"Run `lavendersim derive` to regenerate, then rebuild the C backend with `{rebuild_command()}`.",
                  file=sys.stderr)
        return 1
    _common.say(args, f"generated/ is current ({out}; {dt:.2f} s)")
    return 0


def _write(args, out: Path) -> int:
    from lavendersim._install import rebuild_command
    from lavendersim.derive import codegen
    from lavendersim.derive.atomic import OutputFolderError

    t0 = time.perf_counter()
    try:   # atomic: the folder is swapped in whole (derive/atomic.py)
        changed = _with_phases(codegen.write, out, phases=_Phases(args.quiet))
    except OutputFolderError as exc:
        return _common.fail(f"derive: {exc}")
    dt = time.perf_counter() - t0
    # the compiled backend is built from the package's generated/ only: a folder elsewhere never needs a rebuild
    from . import generated_dir

    ours = out.resolve() == generated_dir()
    rebuild = ours and any(n.startswith("kernels.") for n in changed)
    if args.json:
        _common.emit_json({"directory": str(out), "changed": changed, "seconds": dt,
                           "rebuild": rebuild_command() if rebuild else None})
    _common.say(args, f"derived into {out} in {dt:.2f} s; changed: {', '.join(changed) if changed else 'nothing'}")
    if rebuild:
        _common.say(args, f"C kernels changed: rebuild the compiled backend with `{rebuild_command()}`")
    return 0


def _user(args) -> int:
    """derive --user FILE: print the user set of FILE (C, NumPy, CasADi, EQUATIONS.md), compile it, swap it in.
    Every failure (the declaration raises or cannot be printed, a clash with another set, the C does not
    compile, CC names no compiler) is one line and exit 2, and leaves the last good set in place."""
    from lavendersim import extending

    if args.check:
        return _common.fail("derive: --check applies to the built-in equations, not to --user")
    t0 = time.perf_counter()
    try:
        s = extending.derive(args.user, out=args.out)
    except extending.UserBuildError as exc:   # the full compiler output is in the log file it names
        return _common.fail(f"derive --user: {exc.summary}")
    except (OSError, ValueError) as exc:   # missing file, DeclarationError, UserSetError, OutputFolderError
        return _common.fail(f"derive --user: {exc}")
    except Exception as exc:  # noqa: BLE001 - the declaration is the user's code: one line, never a traceback
        return _common.fail(f"derive --user {args.user}: {type(exc).__name__}: {exc}")
    if args.json:
        _common.emit_json({"directory": str(s.directory), "seconds": time.perf_counter() - t0,
                           "effects": list(s.effect_names), "kernels": list(s.kernel_names),
                           "tableaux": list(getattr(s, "tableau_names", [])),
                           "library": str(s.library_path), "compiled": s.library_built_now is not False,
                           "replaced": None if s.replaced_declaration is None else str(s.replaced_declaration)})
        return 0
    cc = " ".join(s.manifest["library"]["compiler"])
    how = f"cached, nothing recompiled; built with {cc}" if s.library_built_now is False else f"compiled with {cc}"
    lines = [f"derived {args.user} into {s.directory} in {time.perf_counter() - t0:.2f} s"]
    if s.replaced_declaration is not None:
        lines.append(f"replaced the set derived from {s.replaced_declaration} (that file no longer exists)")
    if s.effect_names:
        lines.append(f"effects: {', '.join(s.effect_names)} — scene.add_effect(NAME, body=..., ...) on the c and "
                     "numpy backends")
    if s.kernel_names:
        lines.append(f"kernels: {', '.join(s.kernel_names)} (C: kernels.h; NumPy/CasADi: "
                     "lavendersim.extending.load(FILE).numpy/.casadi)")
    tableaux = getattr(s, "tableaux", ())
    if tableaux:
        lines.append("tableaux: " + ", ".join(f"{t['name']} (order {t['order']}, {t['stages']} stages)" for t in tableaux)
                     + " — Sim(..., integrator=NAME) on the c and numpy backends")
    lines.append(f"C library: {s.library_path} ({how}; its sha256 in {s.directory / extending.MANIFEST})")
    if args.out:
        lines.append(f"outside the user directory: load it with lavendersim.effects.load_user({str(s.directory)!r})")
    _common.say(args, "\n".join(lines))
    return 0
