"""Command line: `lavendersim derive [--check]`, `lavendersim lab NAME|all`."""
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
    args = p.parse_args(argv)
    return int(args.fn(args) or 0)


if __name__ == "__main__":
    sys.exit(main())
