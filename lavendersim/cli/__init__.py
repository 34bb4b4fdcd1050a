"""lavendersim — 3D rigid-body mechanics: derive the equations, run the chapter's labs, design LQR
wheel controllers, view scenes live, measure speed.

Every argparse parser and command of the package lives in this package, one module per command
(``lavendersim.cli.derive``, ``.lab``, ``.lqr``, ``.view``, ``.bench``, ``.effects``): each has
``add_parser(sub)`` and ``run(args) -> int``; the library modules expose the functions they call. The
top-level parser imports nothing heavy: a command's module (and its parser) is imported only when that
command runs, so ``lavendersim --help`` answers at once. Every error a user can cause — a bad option
value, a missing optional extra, an unbuildable backend — is one line on stderr and exit code 2, never
a traceback. ``--json`` and ``--quiet`` mean the same on every command (:mod:`lavendersim.cli._common`).
"""
from __future__ import annotations

import argparse
import importlib
import sys
from pathlib import Path

from .._version import __version__
from ._common import fail as _fail

# command -> one-line help (the command's full parser is built by BUILDERS[command] when it runs)
COMMANDS = {
    "derive": "derive the equations with SymPy and print them into generated/",
    "lab": "run a chapter lab (or `all`); exits 1 if a figure is off",
    "lqr": "design an LQR wheel controller for a spacecraft file and fly its maneuver (control extra)",
    "view": "run a scene live in the browser viewer (viewer extra)",
    "bench": "speed as ratios against peers measured in the same run",
    "effects": "list the effects a scene can declare and their parameters (units, rules, defaults)",
}


def _builder(name: str):
    def build(sub) -> None:
        importlib.import_module(f"{__name__}.{name}").add_parser(sub)
    return build


# command -> add_parser(sub) of its module (lavendersim.cli.NAME), imported when the command runs
BUILDERS = {name: _builder(name) for name in COMMANDS}


def generated_dir() -> Path:
    """The package's generated/ folder (resolved), found without importing it: importing runs the integrity
    check, which must not stop `lavendersim derive` from repairing a half-written or hand-edited folder."""
    from .._integrity import generated_dir as folder

    return Path(folder()).resolve()


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


def main(argv: list[str] | None = None) -> int:
    """Run the command line; returns the exit code.

    0: done; 1: a figure or check failed, or a simulation diverged; 2: any other error — bad input, an
    unusable path, a missing extra or backend, or an unexpected error (one line on stderr, never a
    traceback; ``LAVENDERSIM_TRACEBACK=1`` shows it); 130: interrupted.
    """
    import os

    from .._install import MissingExtraError
    from ..errors import DivergenceError
    from ..validate import LavenderInputError

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

