"""lavendersim — 3D rigid-body mechanics: derive the equations, run the chapter's labs, design LQR
wheel controllers, view scenes live, measure speed.

The top-level parser imports nothing heavy: each command's own parser (and its modules) is built
only when that command runs, so ``lavendersim --help`` answers at once. Every error a user can
cause — a bad option value, a missing optional extra, an unbuildable backend — is one line on
stderr and exit code 2, never a traceback.
"""
from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

from ._version import __version__

# command -> one-line help (the command's full parser is built by BUILDERS[command] when it runs)
COMMANDS = {
    "derive": "derive the equations with SymPy and print them into generated/",
    "lab": "run a chapter lab (or `all`); exits 1 if a figure is off",
    "lqr": "design an LQR wheel controller for a spacecraft file and fly its maneuver (control extra)",
    "view": "run a scene live in the browser viewer (viewer extra)",
    "bench": "speed as ratios against peers measured in the same run",
    "effects": "list the effects a scene can declare and their parameters (units, rules, defaults)",
}


def generated_dir() -> Path:
    """The generated/ folder, found without importing it: importing runs the integrity check, which must
    not stop `lavendersim derive` from repairing a half-written or hand-edited folder."""
    import importlib.util

    spec = importlib.util.find_spec("lavendersim.generated")
    return Path(next(iter(spec.submodule_search_locations))).resolve()


def _derive_user(args) -> int:
    """derive --user FILE: print the user set of FILE (C, NumPy, CasADi, EQUATIONS.md), compile it, swap it in.
    Every failure (the declaration raises or cannot be printed, a clash with another set, the C does not
    compile, CC names no compiler) is one line and exit 2, and leaves the last good set in place."""
    from lavendersim import extending

    if args.check:
        return _fail("derive: --check applies to the built-in equations, not to --user")
    t0 = time.perf_counter()
    try:
        s = extending.derive(args.user, out=args.out)
    except extending.UserBuildError as exc:   # the full compiler output is in the log file it names
        return _fail(f"derive --user: {' '.join(exc.summary.split())}")
    except (OSError, ValueError) as exc:   # missing file, DeclarationError, UserSetError, OutputFolderError
        return _fail(f"derive --user: {' '.join(str(exc).split())}")
    except Exception as exc:  # noqa: BLE001 - the declaration is the user's code: one line, never a traceback
        return _fail(f"derive --user {args.user}: {type(exc).__name__}: {' '.join(str(exc).split())}")
    cc = " ".join(s.manifest["library"]["compiler"])
    how = f"cached, nothing recompiled; built with {cc}" if s.library_built_now is False else f"compiled with {cc}"
    print(f"derived {args.user} into {s.directory} in {time.perf_counter() - t0:.2f} s")
    if s.replaced_declaration is not None:
        print(f"replaced the set derived from {s.replaced_declaration} (that file no longer exists)")
    if s.effect_names:
        print(f"effects: {', '.join(s.effect_names)} — scene.add_effect(NAME, body=..., ...) on the c and numpy backends")
    if s.kernel_names:
        print(f"kernels: {', '.join(s.kernel_names)} (C: kernels.h; NumPy/CasADi: lavendersim.extending.load(FILE).numpy/.casadi)")
    print(f"C library: {s.library_path} ({how}; its sha256 in {s.directory / extending.MANIFEST})")
    if args.out:
        print(f"outside the user directory: load it with lavendersim.effects.load_user({str(s.directory)!r})")
    return 0


def _derive(args) -> int:
    from lavendersim._install import rebuild_command
    from lavendersim.derive import codegen

    from lavendersim import validate as V

    if args.out is not None and not args.check:   # --out '' is refused, never taken for "no --out"
        out_dir = V.writable_dir("out", args.out)  # exit 2 and one line, before anything is derived
        # derive swaps a complete sibling folder in (derive/atomic.py): the parent must be writable too
        V.writable_dir("out", out_dir.resolve().parent)
    if args.user:
        return _derive_user(args)
    if args.out is not None and not str(args.out):
        raise V.LavenderInputError("out", "expected a directory path", ", got ''")
    out = Path(args.out) if args.out is not None else generated_dir()
    t0 = time.perf_counter()
    if args.check:
        stale = codegen.check(out, full=args.full)
        dt = time.perf_counter() - t0
        if stale:
            print(f"generated/ is stale ({out}): {', '.join(stale)} differ from what derive/ produces.", file=sys.stderr)
            print(f"Run `lavendersim derive` to regenerate, then rebuild the C backend with `{rebuild_command()}`.",
                  file=sys.stderr)
            return 1
        print(f"generated/ is current ({out}; {dt:.2f} s)")
        return 0
    from lavendersim.derive.atomic import OutputFolderError

    try:
        changed = codegen.write(out)   # atomic: the folder is swapped in whole (derive/atomic.py)
    except OutputFolderError as exc:
        return _fail(f"derive: {exc}")
    dt = time.perf_counter() - t0
    print(f"derived into {out} in {dt:.2f} s; changed: {', '.join(changed) if changed else 'nothing'}")
    if changed and any(n.startswith("kernels.") for n in changed):
        print(f"C kernels changed: rebuild the compiled backend with `{rebuild_command()}`")
    return 0


def _add_derive(sub) -> None:
    d = sub.add_parser("derive", help=COMMANDS["derive"], description=COMMANDS["derive"] + ".")
    d.add_argument("--check", action="store_true", help="write nothing; exit 1 and name the stale files if generated/ is not current")
    d.add_argument("--full", action="store_true", help="with --check: always re-derive in memory (skip the manifest fast path)")
    d.add_argument("--out", help="output directory (default: the package's generated/; with --user: the user "
                                 "directory's sets/, see lavendersim.extending)")
    d.add_argument("--user", metavar="FILE", help="derive YOUR declarations (EFFECTS and/or KERNELS in FILE, see "
                                                  "docs/extending.md): print them and compile their C (cached)")
    d.set_defaults(fn=_derive)


def _view(args) -> int:
    from lavendersim import viewer

    try:   # the labs' scenes (lab03) were registered when the parser was built (_add_view)
        viewer.run_scene(args.scene, duration=args.duration, host=args.host, port=args.port, rate_hz=args.rate,
                         replay=args.replay)
    except viewer.ViewerError as exc:  # a frame could not be drawn: one line, exit 1 (not a usage error)
        print(f"lavendersim view: {exc}", file=sys.stderr)
        return 1
    return 0


def _add_view(sub) -> None:
    from lavendersim.labs import register_views
    from lavendersim.viewer import DEFAULT_HOST, DEFAULT_PORT, SCENES

    register_views()   # the labs' scenes (lab03) beside the viewer's own, in the help and for _view

    v = sub.add_parser("view", help=COMMANDS["view"],
                       description="Run a scene in real time and stream it to a browser page "
                                   f"(scenes: {', '.join(SCENES)}). Needs the viewer extra: pip install 'lavendersim[viewer]'.")
    v.add_argument("scene", metavar="NAME", help=f"scene to run: {', '.join(SCENES)}")
    v.add_argument("--duration", type=float, default=None, help="simulated seconds to run (default: until Ctrl-C)")
    v.add_argument("--host", default=DEFAULT_HOST, help=f"interface to bind (default {DEFAULT_HOST}: this machine only; "
                                                        "0.0.0.0 or :: listens on every interface, with a warning)")
    v.add_argument("--port", type=int, default=DEFAULT_PORT, help=f"TCP port (default {DEFAULT_PORT}; 0 = any free port)")
    v.add_argument("--rate", type=float, default=60.0, help="frames published per second of simulated time (default 60)")
    v.add_argument("--replay", action="store_true",
                   help="record --duration simulated seconds (default 10) first, then replay them with a time slider "
                        "to scrub (until Ctrl-C). Live or replayed, the page's side panel has Pause/Resume, a speed "
                        "slider and checkboxes for the body axes and each vector")
    v.set_defaults(fn=_view)


def _add_bench(sub) -> None:
    from lavendersim.bench import add_arguments, command

    b = sub.add_parser("bench", help=COMMANDS["bench"],
                       description="Speed of LavenderSim as ratios against peers measured in the same run; prints "
                                   "PASS/MISS against the project's speed targets (a miss never fails the command). "
                                   "MuJoCo is measured when the bench extra is installed: pip install 'lavendersim[bench]'.")
    add_arguments(b)
    b.set_defaults(fn=command)


def _add_lab(sub) -> None:
    from lavendersim.labs import register_cli

    register_cli(sub)


def _add_lqr(sub) -> None:
    from lavendersim.cli_lqr import register_cli

    register_cli(sub)


def _load_user_sets() -> None:
    """Load every set in the user directory (``lavendersim effects`` lists the user's effects too); a set that
    cannot be loaded is named on stderr in one line and skipped."""
    from lavendersim import extending

    root = extending.sets_dir()
    for d in sorted(p for p in root.iterdir() if p.is_dir()) if root.is_dir() else ():
        try:
            extending.load(d)
        except Exception as exc:  # noqa: BLE001 - a broken set must not hide the others
            print(f"lavendersim effects: skipped the user set {d} ({' '.join(str(exc).split())})", file=sys.stderr)


def _effects(args) -> int:
    import json

    from lavendersim import effects

    if args.name is None:
        _load_user_sets()
    if args.json:
        print(json.dumps(effects.list_effects(args.name), indent=1, ensure_ascii=False))
    else:
        print(effects.describe(args.name), end="")
    return 0


def _add_effects(sub) -> None:
    e = sub.add_parser("effects", help=COMMANDS["effects"],
                       description="List the effects a scene can declare (built-in and the user sets in the user "
                                   "directory) with each parameter's shape, unit, rule, default and frame; the same as "
                                   "lavendersim.effects.describe() / list_effects().")
    e.add_argument("name", metavar="NAME", nargs="?", default=None, help="only this effect")
    e.add_argument("--json", action="store_true", help="print machine-readable JSON (a list, one object per effect) "
                                                       "to stdout")
    e.set_defaults(fn=_effects)


BUILDERS = {"derive": _add_derive, "lab": _add_lab, "lqr": _add_lqr, "view": _add_view, "bench": _add_bench,
            "effects": _add_effects}


class _Parser(argparse.ArgumentParser):
    """argparse with its usage errors on one line (the error, then where --help is), exit code 2; every
    subcommand's parser is one too (add_subparsers builds them with the parent's class)."""

    def error(self, message: str):
        self.exit(2, f"{self.prog}: error: {' '.join(message.split())} (`{self.prog} --help` lists the options)\n")


def _top_parser(full: str | None) -> argparse.ArgumentParser:
    """The parser; `full` names the one command whose own parser is built (None: names only)."""
    p = _Parser(prog="lavendersim", description=__doc__.split("\n\n")[0],
                epilog="`lavendersim COMMAND --help` describes a command.")
    p.add_argument("--version", action="version", version=f"lavendersim {__version__}")
    sub = p.add_subparsers(dest="cmd", required=True, metavar="COMMAND")
    for name, text in COMMANDS.items():
        if name == full:
            BUILDERS[name](sub)
        else:
            sub.add_parser(name, help=text, add_help=False)
    return p


# set to 1 to see the traceback of an unexpected error (the command line otherwise says it in one line)
TRACEBACK_ENV = "LAVENDERSIM_TRACEBACK"


def _fail(message: str, code: int = 2) -> int:
    print(f"lavendersim: {' '.join(str(message).split())}", file=sys.stderr)   # one line, whatever the message
    return code


def main(argv: list[str] | None = None) -> int:
    """Run the command line; returns the exit code.

    0: done; 1: a figure or check failed, or a simulation diverged; 2: any other error — bad input, an
    unusable path, a missing extra or backend, or an unexpected error (one line on stderr, never a
    traceback; ``LAVENDERSIM_TRACEBACK=1`` shows it); 130: interrupted.
    """
    import os

    from ._install import MissingExtraError
    from .errors import DivergenceError
    from .validate import LavenderInputError

    argv = list(sys.argv[1:] if argv is None else argv)
    command = next((a for a in argv if not a.startswith("-")), None)
    try:
        parser = _top_parser(command if command in COMMANDS else None)
        args = parser.parse_args(argv)
        return int(args.fn(args) or 0)
    except MissingExtraError as exc:
        return _fail(str(exc))
    except LavenderInputError as exc:  # a ValueError naming the field and the rule
        return _fail(f"{command}: invalid input: {exc}")
    except ImportError as exc:  # the C backend asked for by name and not usable: says how to build it
        return _fail(f"{command}: {exc}")
    except DivergenceError as exc:   # a command's own simulation (view, lqr, bench): a failed run, not bad usage
        return _fail(f"{command}: {exc}", 1)
    except BrokenPipeError:   # stdout closed early (`lavendersim ... | head`): stop quietly
        try:
            os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
        except (OSError, ValueError):
            pass
        return 141
    except OSError as exc:   # a path the command was given (or one it derived from it) cannot be used
        where = f" {exc.filename!r}" if getattr(exc, "filename", None) else ""
        return _fail(f"{command}: cannot use{where}: {exc.strerror or exc}")
    except KeyboardInterrupt:
        print("lavendersim: interrupted", file=sys.stderr)
        return 130
    except Exception as exc:  # noqa: BLE001 - the promise is one line, never a traceback
        if os.environ.get(TRACEBACK_ENV, "") not in ("", "0"):
            raise
        return _fail(f"{command}: unexpected error (a bug: please report it with the command; {TRACEBACK_ENV}=1 "
                     f"shows the traceback): {type(exc).__name__}: {exc}")


if __name__ == "__main__":
    sys.exit(main())
