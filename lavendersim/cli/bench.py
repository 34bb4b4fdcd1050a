"""``lavendersim bench``: speed as ratios against peers measured in the same run (:mod:`lavendersim.bench`).

Exit 0 when every section ran (a missed target is reported, never an error); 1 when a section crashed (the
others still run and print; one line on stderr names the crashed sections and why); 2 on bad input."""
from __future__ import annotations

import sys

from . import _common

HELP = "speed as ratios against peers measured in the same run"


def add_parser(sub) -> None:
    from lavendersim.bench import SECTIONS

    b = sub.add_parser("bench", help=HELP, parents=[_common.parent(
                           json_help="print every figure as one JSON document on stdout (no report text)")],
                       description="Speed of LavenderSim as ratios against peers measured in the same run, in CPU "
                                   "time; prints PASS/MISS against the project's speed targets (a miss never fails "
                                   "the command; a crashed section exits 1). MuJoCo is measured when the bench extra "
                                   "is installed: pip install -e '.[bench]'.")
    b.add_argument("--quick", action="store_true", help="short run (small step counts, N up to 1e3) for tests")
    b.add_argument("--out", metavar="FILE", help="also write every figure to FILE as JSON")
    b.add_argument("--rounds", type=int, default=None, help="interleaved rounds per section (default 5; 2 with --quick)")
    b.add_argument("--no-mujoco", action="store_true", help="skip MuJoCo even when it is installed")
    b.add_argument("--only", metavar="SECTION[,SECTION...]", default=None,
                   help=f"run only these sections: {', '.join(SECTIONS)}")
    b.add_argument("--markdown", action="store_true",
                   help="print the targets as one Markdown table headed by the run's machine stamp (as "
                        "docs/performance.md shows them) instead of the report")
    b.add_argument("--from", dest="from_file", metavar="RUN.json", default=None,
                   help="measure nothing: re-print the run that --out saved in RUN.json (with --markdown: its table)")
    b.set_defaults(fn=run)


def run(args) -> int:
    import json
    from pathlib import Path

    from lavendersim import bench
    from lavendersim import validate as V

    if args.rounds is not None:   # checked before a run of minutes, not after
        V.integer("rounds", args.rounds, minimum=1)
    if args.out is not None:
        V.writable_file("out", args.out)
    if args.from_file is not None:
        res = _saved_run(args.from_file)
    else:
        only = None if args.only is None else [s.strip() for s in args.only.split(",") if s.strip()]
        bar = _common.progress(desc="bench", enabled=not args.quiet)
        try:
            res = bench.run(quick=args.quick, rounds=args.rounds, use_mujoco=not args.no_mujoco, only=only,
                            progress=None if bar.disable else bar.set_description)
        finally:
            bar.close()
    if args.json:
        _common.emit_json(res)
    else:
        _common.say(args, bench.targets_markdown(res) if args.markdown else bench.report(res))
    if args.out is not None:
        path = Path(args.out)
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text(json.dumps(_common.plain(res), indent=1, allow_nan=False) + "\n", encoding="utf-8")
        _common.say(args, f"\nwrote {path}")
    failed = bench.failed_sections(res)
    if failed:
        print("lavendersim bench: section(s) crashed: " + "; ".join(
            f"{e['section']} ({_common.one_line(e['error'])})" for e in failed), file=sys.stderr)
        return 1
    return 0


def _saved_run(path: str) -> dict:
    """The results a run wrote with --out (LavenderInputError naming --from when the file is not one)."""
    import json
    from pathlib import Path

    from lavendersim import validate as V

    try:
        res = json.loads(Path(path).read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as e:
        raise V.LavenderInputError("from", f"must be a JSON file written by `lavendersim bench --out` ({_common.one_line(e)})",
                                   f", got {path!r}") from None
    if not isinstance(res, dict) or not {"machine", "standing", "quick", "config"} <= set(res):
        raise V.LavenderInputError("from", "must be the results of `lavendersim bench --out` (machine, standing, "
                                   "config and quick at its top level)", f", got {path!r}")
    return res
