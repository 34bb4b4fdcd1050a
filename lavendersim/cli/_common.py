"""What every command of the command line shares: ``--quiet`` and ``--json``, JSON on stdout, progress on a
terminal only, one-line errors.

The conventions (issue 31):

* ``--json`` prints the command's results as ONE JSON document on stdout and nothing else on stdout (no
  report text, no "wrote ..." lines); files are written with ``--out``.
* ``--quiet`` prints nothing on stdout or stderr when the command succeeds (a failure is still one line on
  stderr); ``--json --quiet`` prints the JSON only.
* Progress goes to stderr, as a bar on a terminal only; a pipe or a log gets none (or, for ``derive``, one
  line per phase).
* Exit 0: done; 1: a figure, target or run failed; 2: bad input (one line, never a traceback).
"""
from __future__ import annotations

import argparse
import json
import math
import sys


def parent(json: bool = True, json_help: str = "print the results as one JSON document on stdout (nothing else "
                                               "on stdout)") -> argparse.ArgumentParser:
    """The options every command takes: ``--quiet`` and (when the command has results) ``--json``."""
    p = argparse.ArgumentParser(add_help=False)
    p.add_argument("--quiet", action="store_true", help="print nothing on success (failures: one line on stderr); "
                                                        "no progress")
    if json:
        p.add_argument("--json", action="store_true", help=json_help)
    return p


def is_terminal(stream=None) -> bool:
    stream = sys.stderr if stream is None else stream
    try:
        return bool(stream.isatty())
    except (AttributeError, ValueError):
        return False


def progress(total: int | None = None, desc: str = "", unit: str = "it", enabled: bool = True):
    """A tqdm bar on stderr when ``enabled`` and stderr is a terminal; a silent pass-through with the same
    interface (``update``, ``set_description``, ``write``, ``close``, ``disable``) anywhere else."""
    import shutil

    from tqdm import tqdm

    cols, rows = shutil.get_terminal_size((100, 24))   # a bare pty reports 0 x 0
    return tqdm(total=total, desc=desc, unit=unit, disable=not (enabled and is_terminal()), leave=False,
                file=sys.stderr, ncols=cols, nrows=rows)


def plain(x):
    """A copy JSON can hold: numpy scalars and arrays as Python numbers and lists, non-finite floats as None
    (JSON has no inf), tuples as lists, keys as strings."""
    if isinstance(x, dict):
        return {str(k): plain(v) for k, v in x.items()}
    if isinstance(x, (list, tuple)):
        return [plain(v) for v in x]
    if hasattr(x, "tolist") and not isinstance(x, (str, bytes)):   # numpy scalar or array
        return plain(x.tolist())
    if isinstance(x, float) and not math.isfinite(x):
        return None
    return x


def emit_json(obj) -> None:
    """``obj`` as one JSON document on stdout (see :func:`plain`)."""
    print(json.dumps(plain(obj), indent=1, ensure_ascii=False, allow_nan=False), flush=True)


def say(args, text: str = "", file=None) -> None:
    """Print a human line on stdout (or ``file``) unless --quiet or --json."""
    if not (getattr(args, "quiet", False) or getattr(args, "json", False)):
        print(text, file=file or sys.stdout, flush=True)


def one_line(exc: BaseException | str) -> str:
    """A message on one line (the command line's promise: one line, never a traceback)."""
    return " ".join(str(exc).split())


def fail(message, code: int = 2, prog: str = "lavendersim") -> int:
    """Print ``prog: message`` on one line on stderr; return ``code``."""
    print(f"{prog}: {one_line(message)}", file=sys.stderr)
    return code
