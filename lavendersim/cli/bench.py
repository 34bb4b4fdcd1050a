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
        _common.say(args, bench.report(res))
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
