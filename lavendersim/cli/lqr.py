"""``lavendersim lqr``: design a sampled LQR wheel controller for a spacecraft file and fly its maneuver.

The command line layer only: the file is read by :mod:`lavendersim.spacecraft`, designed and flown by
:mod:`lavendersim.control`'s one stack. ``--scenario center|corner`` and ``--layout cube3|pyramid4`` load
the spacecraft files shipped with the package (``lavendersim.spacecraft.shipped()``). Every bad option,
key or value is one line naming it on stderr and exit code 2; a maneuver that misses the file's stated
settle time (``maneuver.settle_within``) or a wheel limit exits 1.
"""
from __future__ import annotations

import math
from pathlib import Path

from . import _common

HELP = "design a sampled LQR wheel controller for a spacecraft file and fly its maneuver (control extra)"
SCENARIOS = {"center": "cube_center", "corner": "cube_corner"}
LAYOUTS = {"cube3": None, "pyramid4": "cube_pyramid4"}
# what --plot may end with (matplotlib's writers that need nothing beyond matplotlib and Pillow); no suffix: PNG
PLOT_SUFFIXES = (".png", ".pdf", ".svg", ".svgz", ".eps", ".ps", ".jpg", ".jpeg", ".tif", ".tiff")


def add_parser(sub) -> None:
    """Add ``lavendersim lqr`` to the command line's subcommands ``sub`` (its handler: :func:`run`)."""
    p = sub.add_parser("lqr", help=HELP, parents=[_common.parent(json_help="print the design (rank, poles), the "
                       "maneuver's figures and the Monte Carlo summary as one JSON document on stdout")], description=HELP[0].upper() + HELP[1:] + ". The spacecraft file (TOML) "
                              "gives the body (mass, inertia tensor), its wheels (axes, J, limits, motor), the controller "
                              "(period, delay, Q/R or Bryson weights, null-space bias), sensors, actuator lag, the maneuver "
                              "and the Monte Carlo spread: see docs/spacecraft.md or lavendersim.spacecraft. Exit 0: flown; "
                              "1: the stated settle time was missed or a wheel limit exceeded; 2: bad input.")
    src = p.add_mutually_exclusive_group()
    src.add_argument("--spacecraft", metavar="FILE", help="the spacecraft file (TOML), or the name of a shipped one: "
                     "cubesat6u, cube_center, cube_corner, cube_pyramid4")
    src.add_argument("--scenario", choices=tuple(SCENARIOS), default=None, help="the chapter's cube: center (joint at the "
                     "centre, ReactionWheelCube-v0; the default) or corner (balancing on a corner under gravity); "
                     "the shipped files cube_center / cube_corner")
    p.add_argument("--layout", choices=tuple(LAYOUTS), default=None, help="cube3 (three body-axis wheels: --scenario) or "
                   "pyramid4 (a free cube with four pyramid wheels: the shipped file cube_pyramid4)")
    p.add_argument("--plot", metavar="PATH", default=None, help="write the response plot to PATH (its suffix picks "
                   f"the format: {', '.join(PLOT_SUFFIXES)}; none: PNG)")
    p.add_argument("--no-noise", action="store_true", help="fly with perfect measurements (ignore [sensors])")
    p.add_argument("--monte-carlo", type=int, default=None, metavar="N", help="also fly N plants: the inertia tensor "
                   "perturbed by [monte_carlo] inertia_uncertainty and new sensor seeds")
    p.add_argument("--workers", type=int, default=None, help="Monte Carlo on N local processes (default: every core; 1: serial)")
    p.add_argument("--dask", default=None, metavar="ADDRESS", help="Monte Carlo on the Dask scheduler at ADDRESS "
                   "(the distributed extra)")
    p.add_argument("--export-c", metavar="DIR", default=None, help="write the designed controller as C99 (controller.h, "
                   "controller.c, an example main.c) to DIR, compile it with -std=c99 -Wall -Wextra -pedantic -Werror and "
                   "fly it in the loop (float64 and float32) against the Python controller: lavendersim.controller_c")
    p.add_argument("--backend", default="auto", choices=("auto", "c", "numpy"),
                   help="simulator backend (default auto: C when built, else NumPy with a warning)")
    p.set_defaults(fn=run)


def _fail(message: str, code: int = 2) -> int:
    return _common.fail(message, code, prog="lavendersim lqr")


def _check_plot(path: str) -> None:
    """--plot: a writable file whose suffix (if any) is one of PLOT_SUFFIXES; LavenderInputError naming --plot."""
    from .. import validate as V

    suffix = Path(path).suffix.lower()
    if suffix and suffix not in PLOT_SUFFIXES:
        raise V.LavenderInputError("--plot", f"must end with one of {', '.join(PLOT_SUFFIXES)} (or no suffix: PNG)",
                                   f", got {path!r}")
    V.writable_file("--plot", path)


def _source(args) -> str:
    """The spacecraft file to load (a path or a shipped name)."""
    from .. import validate as V

    if args.spacecraft is not None:
        if args.layout is not None:
            raise V.LavenderInputError("--layout", "takes no --spacecraft: the file gives the wheel layout")
        return args.spacecraft
    if args.layout == "pyramid4":
        if args.scenario is not None:
            raise V.LavenderInputError("--scenario", "--layout pyramid4 is a free cube: it has no scenario")
        shipped = LAYOUTS["pyramid4"]
        assert shipped is not None
        return shipped
    return SCENARIOS[args.scenario or "center"]


def _text(fig: dict, mc: dict | None) -> str:
    d, f, m = fig["design"], fig["figures"], fig["maneuver"]
    st = f"{f['settling_time']:.4g} s" if math.isfinite(f["settling_time"]) else "never"
    stated = "" if m["settle_within"] is None else f" (stated: within {m['settle_within']:g} s: " \
        f"{'met' if f['settled_within'] else 'MISSED'})"
    lines = [f"{fig['spacecraft']} ({fig['file']}): body {fig['body']!r}, {fig['wheels']} wheels",
             f"design: discrete LQR at {d['period']:g} s (delay {d['delay']:g} s, actuator lag {d['actuator_lag']:g} s); "
             f"controllability rank {d['controllability_rank']} of {d['n_states']}; largest closed-loop |z| "
             f"{d['max_pole_modulus']:.6f}",
             f"maneuver: {m['angle_deg']:g}° about {[round(a, 4) for a in m['axis']]} (body frame), {m['duration']:g} s",
             f"settling time (< {m['settle_threshold_deg']:g}°) {st}{stated}; final error {f['final_error_deg']:.3g}°",
             f"peak wheel torque {f['peak_torque_max']:.4g} N·m (limit {f['torque_limit']:g}), peak wheel speed "
             f"{f['peak_wheel_speed_max']:.4g} rad/s (limit {f['speed_limit']:g}); within limits: {f['within_limits']}",
             f"total angular momentum drift {f['L_drift']:.3g} (relative)"
             + (f"; external: {', '.join(f['external_effects'])}" if f["external_effects"] else "; no external torque")]
    if mc is not None:
        def row(k, unit):
            v = mc[k]
            return f"{k} {v['p50']:.4g} median, {v['p90']:.4g} p90, {v['p100']:.4g} max {unit}" if v["p50"] is not None \
                else f"{k} -"

        within = (f" ({mc['settled_within']} within {mc['settle_within']:g} s)" if mc["settle_within"] else "") \
            + (f", {mc['failed']} failed draws (--json lists why)" if mc.get("failed") else "")
        lines.append(f"Monte Carlo, {mc['n']} runs (inertia ±{100 * mc['inertia_spread']:g}% per axis, sensor seeds "
                     f"{mc['sensors']['seed']}+): {mc['n'] - mc['failures']} settled{within}; {row('settling_time', 's')}; "
                     f"{row('peak_torque', 'N·m')}; {row('peak_wheel_speed', 'rad/s')}")
    return "\n".join(lines)


def _design(S, sc):
    """S.design, with the Riccati solver's failures (scipy's LinAlgError / ValueError on an ill-posed Q, R) named."""
    import numpy as np

    from .. import validate as V

    try:
        return S.design(sc)
    except (np.linalg.LinAlgError, ValueError) as exc:
        if isinstance(exc, V.LavenderInputError):
            raise
        raise V.LavenderInputError("controller", "the LQR design failed (check Q, R or weights against the plant, "
                                   "the delay and the actuator lag)", f": {' '.join(str(exc).split())}") from None


def run(args) -> int:
    from .. import spacecraft as S
    from .. import validate as V
    from ..errors import DivergenceError

    where = ""
    try:
        path = where = _source(args)
        if args.plot is not None:   # before the design and the run, not after
            _check_plot(args.plot)
        if args.export_c is not None:
            V.writable_dir("--export-c", args.export_c)
        sc = S.load(path)
        ex = None
        if args.monte_carlo is not None or args.dask is not None or args.workers is not None:
            from .. import executor as X

            if args.monte_carlo is None:
                raise V.LavenderInputError("--dask" if args.dask else "--workers", "needs --monte-carlo N")
            V.integer("--monte-carlo", args.monte_carlo, minimum=1)
            ex = X.resolve(workers=args.workers, dask=args.dask, feature="lavendersim lqr --dask")
        ctrl = _design(S, sc)
        resp = S.fly(sc, ctrl, noise=not args.no_noise, backend=args.backend)
        mc = None if args.monte_carlo is None else _monte_carlo(S, sc, ctrl, ex, args)
        exported = None if args.export_c is None else _export_c(S, sc, ctrl, resp, args)
    except V.LavenderInputError as exc:
        return _fail(str(exc) if not where or str(exc).startswith(str(where)) else f"{where}: {exc}")
    except DivergenceError as exc:
        return _fail(f"{where}: simulation diverged: {exc}", 1)
    fig = S.figures(sc, ctrl, resp)
    if args.plot is not None:
        try:
            resp.plot(args.plot, title=f"{sc.name}: {sc.maneuver.angle_deg:g}° slew, controller {sc.controller.period:g} s")
        except OSError as exc:   # checked writable before the run; a disk that filled up since: one line
            return _fail(f"--plot: cannot write {args.plot} ({exc.strerror or exc})")
    if args.json:
        out = dict(fig)
        if mc is not None:
            out["monte_carlo"] = {k: v for k, v in mc.items() if k != "samples"}
        if exported is not None:
            out["export_c"] = exported
        _common.emit_json(out)
    elif not args.quiet:
        print(_text(fig, mc))
        if args.plot is not None:
            print(f"wrote {args.plot}")
        if exported is not None:
            from ..controller_c import summary

            print(summary(exported))
    if exported is not None and exported["compile_error"]:
        return _fail(exported["compile_error"], 1)
    if exported is not None and exported["sil"] is not None and not exported["sil"]["ok"]:
        return _fail(f"{sc.name}: the printed controller failed its software-in-the-loop check", 1)
    f = fig["figures"]
    if f["settled_within"] is False or not f["within_limits"]:
        why = "missed the stated settle time" if f["settled_within"] is False else "exceeded a wheel limit"
        return _fail(f"{sc.name}: {why}", 1)
    return 0


def _monte_carlo(S, sc, ctrl, ex, args) -> dict:
    """--monte-carlo N: the sweep, with a progress bar on stderr when it is a terminal (never on a pipe)."""
    bar = _common.progress(total=args.monte_carlo, desc="lqr: Monte Carlo", unit="run",
                           enabled=not args.quiet)
    try:
        return S.monte_carlo(sc, ctrl, args.monte_carlo, executor=ex, backend=args.backend,
                             progress=None if bar.disable else bar.update)
    finally:
        bar.close()


def _export_c(S, sc, ctrl, resp, args) -> dict:
    """--export-c: the printed controller written to DIR and flown in the loop on the file's maneuver (same noise)."""
    from ..controller_c import export_and_verify

    return export_and_verify(ctrl, args.export_c, lambda c: S.fly(sc, c, noise=not args.no_noise, backend=args.backend),
                             reference=resp, source=Path(args.spacecraft or _source(args)).name)
