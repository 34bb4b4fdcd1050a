"""``lavendersim effects [NAME]``: the effects a scene can declare and their parameters (units, rules, defaults,
frames), built-in and the user sets in the user directory; the same as :func:`lavendersim.effects.describe` and
:func:`lavendersim.effects.list_effects`."""
from __future__ import annotations

import sys

from . import _common

HELP = "list the effects a scene can declare and their parameters (units, rules, defaults)"


def add_parser(sub) -> None:
    e = sub.add_parser("effects", help=HELP, parents=[_common.parent(
                           json_help="print machine-readable JSON (a list, one object per effect) to stdout")],
                       description="List the effects a scene can declare (built-in and the user sets in the user "
                                   "directory) with each parameter's shape, unit, rule, default and frame; the same as "
                                   "lavendersim.effects.describe() / list_effects().")
    e.add_argument("name", metavar="NAME", nargs="?", default=None, help="only this effect")
    e.set_defaults(fn=run)


def _load_user_sets(quiet: bool) -> None:
    """Load every set in the user directory; a set that cannot be loaded is named on stderr in one line (unless
    quiet) and skipped."""
    from lavendersim import extending

    root = extending.sets_dir()
    for d in sorted(p for p in root.iterdir() if p.is_dir()) if root.is_dir() else ():
        try:
            extending.load(d)
        except Exception as exc:  # noqa: BLE001 - a broken set must not hide the others
            if not quiet:
                print(f"lavendersim effects: skipped the user set {d} ({_common.one_line(exc)})", file=sys.stderr)


def run(args) -> int:
    from lavendersim import effects

    if args.name is None:
        _load_user_sets(args.quiet)
    if args.json:
        _common.emit_json(effects.list_effects(args.name))
    else:
        text = effects.describe(args.name)   # an unknown NAME raises (one line, exit 2) even with --quiet
        if not args.quiet:
            print(text, end="")
    return 0
