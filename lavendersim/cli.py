"""Command line: `lavendersim derive [--check]`, `lavendersim lab NAME|all`, `lavendersim view NAME`,
`lavendersim bench [--quick] [--json PATH]`."""
from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path


def generated_dir() -> Path:
    import lavendersim.generated as g

    return Path(g.__file__).resolve().parent


def _derive(args) -> int:
    from lavendersim.derive import codegen

    out = Path(args.out) if args.out else generated_dir()
    t0 = time.perf_counter()
    if args.check:
        stale = codegen.check(out, full=args.full)
        dt = time.perf_counter() - t0
        if stale:
            print(f"generated/ is stale ({out}): {', '.join(stale)} differ from what derive/ produces.", file=sys.stderr)
            print("Run `lavendersim derive` to regenerate, then rebuild the C backend with `pip install -e .`.", file=sys.stderr)
            return 1
        print(f"generated/ is current ({out}; {dt:.2f} s)")
        return 0
    changed = codegen.write(out)
    dt = time.perf_counter() - t0
    print(f"derived into {out} in {dt:.2f} s; changed: {', '.join(changed) if changed else 'nothing'}")
    if changed and any(n.startswith("kernels.") for n in changed):
        print("C kernels changed: rebuild the compiled backend with `pip install -e .`")
    return 0


def _view(args) -> int:
    from lavendersim import viewer
    from lavendersim.validate import LavenderInputError

    try:
        viewer.run_scene(args.scene, duration=args.duration, host=args.host, port=args.port, rate_hz=args.rate)
    except LavenderInputError as exc:
        print(f"view: {exc}", file=sys.stderr)
        return 2
    return 0


def _add_view(sub) -> None:
    from lavendersim.viewer import DEFAULT_HOST, DEFAULT_PORT, SCENES

    v = sub.add_parser("view", help="run a scene live in the browser viewer (viser) at http://HOST:PORT",
                       description="Run a scene in real time and stream it to a browser page "
                                   f"(scenes: {', '.join(SCENES)}).")
    v.add_argument("scene", metavar="NAME", help=f"scene to run: {', '.join(SCENES)}")
    v.add_argument("--duration", type=float, default=None, help="simulated seconds to run (default: until Ctrl-C)")
    v.add_argument("--host", default=DEFAULT_HOST, help=f"interface to bind (default {DEFAULT_HOST}: this machine only)")
    v.add_argument("--port", type=int, default=DEFAULT_PORT, help=f"TCP port (default {DEFAULT_PORT}; 0 = any free port)")
    v.add_argument("--rate", type=float, default=60.0, help="frames published per second of simulated time (default 60)")
    v.set_defaults(fn=_view)


def _add_bench(sub) -> None:
    b = sub.add_parser("bench", help="speed as ratios measured in one run (C, NumPy, hand-written C, MuJoCo)",
                       description="Speed of LavenderSim as ratios against references measured in the same run; "
                                   "prints PASS/MISS against the targets of issue 4 (a miss never fails the command).")

    def _bench(args) -> int:
        from lavendersim.bench import command

        return command(args)

    from lavendersim.bench import add_arguments

    add_arguments(b)
    b.set_defaults(fn=_bench)


def main(argv=None) -> int:
    p = argparse.ArgumentParser(prog="lavendersim", description=__doc__)
    sub = p.add_subparsers(dest="cmd", required=True)
    d = sub.add_parser("derive", help="derive the equations with SymPy and print them into generated/")
    d.add_argument("--check", action="store_true", help="write nothing; exit 1 and name the stale files if generated/ is not current")
    d.add_argument("--full", action="store_true", help="with --check: always re-derive in memory (skip the manifest fast path)")
    d.add_argument("--out", help="output directory (default: the package's generated/)")
    d.set_defaults(fn=_derive)
    from lavendersim.labs import register_cli

    register_cli(sub)
    from lavendersim.control import register_cli as register_lqr

    register_lqr(sub)
    _add_view(sub)
    _add_bench(sub)
    args = p.parse_args(argv)
    return int(args.fn(args) or 0)


if __name__ == "__main__":
    sys.exit(main())
