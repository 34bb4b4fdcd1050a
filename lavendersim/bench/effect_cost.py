"""The effect-cost section of `lavendersim bench`: what each effect costs on top of a plain body (issue 30).

At N = 1e3, 1e4, 1e5 bodies (quick: 1e3), one scene per effect set, built with one ``Scene.add_bodies`` and
scene-wide ``add_effect`` calls, stepped by ``Sim.run`` on the C backend (RK4, dt = 1e-3 s), all sets of one
N interleaved call by call in short calls of about equal length (timing.py: ~3 ms, or one chunk where a chunk
takes longer; whole chunks of the Sim's steps between checks, calibrated per set; CPU time, min over all calls).
Each set's ns per body-step is divided by the plain scene's at the same N:

* gravity (target <= 1.3x), applied torque (<= 1.6x), linear + angular damping (<= 1.6x),
  gravity + damping (<= 1.8x), and one user effect, the guide's gravity gradient (docs/extending.md,
  derived into a temporary user directory; <= 2.5x; full run only, from a source checkout);
* each target's line takes the worst N, and says how flat the ratio is (largest / smallest over N).
"""
from __future__ import annotations

import re
import tempfile
from pathlib import Path
from typing import Any

import numpy as np

from .timing import CALL_S

SIZES_FULL = (1_000, 10_000, 100_000)
SIZES_QUICK = (1_000,)
TORQUE_W = (1e-3, 2e-3, -1e-3)
GG_PARAMS = {"mu": 3.986e14, "center_w": (0.0, 0.0, -7.0e6)}   # Earth, the bodies 7000 km from its center
DAMPING = [("linear_damping", {"c": 0.05}), ("angular_damping", {"c": 2e-3})]
SETS: tuple[tuple[str, list[tuple[str, dict[str, Any]]], float | None], ...] = (
    ("plain", [], None),
    ("gravity", [("gravity", {})], 1.3),
    ("applied torque", [("applied_torque", {"torque_w": list(TORQUE_W)})], 1.6),
    ("damping", DAMPING, 1.6),
    ("gravity + damping", [("gravity", {})] + DAMPING, 1.8),
    ("user effect (gravity_gradient)", [("gravity_gradient", GG_PARAMS)], 2.5),
)
GUIDE = Path(__file__).resolve().parent.parent.parent / "docs" / "extending.md"


def guide_effect(workdir: Path) -> str | None:
    """Derive the guide's user set (docs/extending.md's my_effects.py) into workdir and load it.

    Returns None when gravity_gradient can be used, else why not (no source checkout, no compiler, ...)."""
    from .. import effects as E
    if "gravity_gradient" in E.REGISTRY:
        return None
    if not GUIDE.exists():
        return f"{GUIDE} is not there (the guide's set needs a source checkout)"
    blocks = re.findall(r"^```python my_effects\.py\n(.*?)^```", GUIDE.read_text(encoding="utf-8"), re.S | re.M)
    if len(blocks) != 1:
        return "docs/extending.md has no single ```python my_effects.py block"
    from .. import extending
    decl = workdir / "my_effects.py"
    decl.write_text(blocks[0], encoding="utf-8")
    extending.derive(decl, out=workdir / "sets")   # derives, compiles and loads (registers) the set
    return None


def _scene(n: int, effects: list):
    from ..scene import Scene
    from ..sim import Sim
    rng = np.random.default_rng(n)
    scene = Scene()
    scene.add_bodies([f"b{i}" for i in range(n)], np.full(n, 2.0), np.tile([0.0333, 0.1133, 0.1333], (n, 1)),
                     omega_b=rng.standard_normal((n, 3)))
    for name, params in effects:
        scene.add_effect(name, **params)
    return Sim(scene, dt=1e-3, integrator="rk4", backend="c")


def effect_cost_section(quick: bool, rounds: int, interleaved_calls, progress=None) -> dict:
    """Time every set of SETS at every N (see the module docstring).

    Parameters
    ----------
    quick : bool
        N = 1e3 only, no user effect.
    rounds : int
        Rounds of ``interleaved_calls`` (timing.py: CALLS_PER_ROUND short calls of each set per round).
    interleaved_calls : callable
        timing.interleaved_calls with the bench's progress bound.

    Returns
    -------
    dict
        ``sizes``: N -> {set name -> stats (ns per body-step), ``steps``: the plain scene's steps per call (whole
        chunks), ``steps_per_call`` and ``steps_per_chunk``: set name -> steps per timed call, per chunk,
        ``ratios``: set name -> ns / plain ns};
        ``user_effect``: None when measured, else why it was not.
    """
    sizes = SIZES_QUICK if quick else SIZES_FULL
    why = "not in --quick (deriving the guide's set takes a minute)" if quick else None
    tmp = None
    if why is None:
        tmp = tempfile.TemporaryDirectory(prefix="lavendersim-bench-user-")
        try:
            why = guide_effect(Path(tmp.name))
        except Exception as exc:  # noqa: BLE001 - reported as the reason; the built-in effects still run
            why = f"deriving the guide's set failed: {type(exc).__name__}: {exc}"
    sets = [(nm, effs) for nm, effs, _ in SETS if not (why and any(e == "gravity_gradient" for e, _ in effs))]
    sizes_out: dict[str, dict] = {}
    out = {"sizes": sizes_out, "user_effect": why}
    for n in sizes:
        if progress:
            progress(f"effect cost: N = {n}: building {len(sets)} scenes")
        sims = {nm: _scene(n, effs) for nm, effs in sets}
        # a call is k whole chunks (the Sim's steps between checks: each chunk pays its C setup and checks, ~30-60 ns
        # per body, as a long run does; a call of part of a chunk would pay them over fewer steps)
        cases = {nm: (lambda k, s=s: s.run(k * s.chunk_steps), n * s.chunk_steps) for nm, s in sims.items()}
        t = interleaved_calls(cases, rounds, f"effect cost N = {n}")
        base = t["plain"]["ns_min"]
        sizes_out[str(n)] = {"steps": t["plain"]["count_per_call"] * sims["plain"].chunk_steps, **t,
                             "steps_per_call": {nm: t[nm]["count_per_call"] * sims[nm].chunk_steps for nm in t},
                             "steps_per_chunk": {nm: sims[nm].chunk_steps for nm in t},
                             "ratios": {nm: t[nm]["ns_min"] / base for nm in t}}
        del sims
    if tmp is not None:
        tmp.cleanup()
    return out


def standing_lines(res: dict, line, targets: dict) -> list[dict]:
    """One PASS/MISS line per effect target: the worst ratio over N, and its spread over N."""
    ec = res.get("effect_cost") or {"sizes": {}}
    out = []
    for nm, _, limit in SETS[1:]:
        vals = {n: row["ratios"][nm] for n, row in ec["sizes"].items() if nm in row["ratios"]}
        worst = max(vals.values(), default=None)
        basis = (ec.get("user_effect") or "section not run or crashed") if worst is None else (
            f"ns per body-step / plain body's, Sim.run in C, ~{CALL_S * 1e3:g} ms calls (whole chunks) interleaved "
            "call by call, min; N = " + ", ".join(vals)
            + f"; flat in N: largest / smallest ratio {max(vals.values()) / min(vals.values()):.2f}")
        out.append(line(f"{nm} / plain body (worst of N)", worst, limit, "max", "x", basis))
    return out


def report_lines(res: dict, fmt) -> list[str]:
    ec = res.get("effect_cost")
    if not ec or not ec["sizes"]:
        return []
    names = [nm for nm, _, _ in SETS]
    L = ["", "effect cost, C (scene-wide effects, RK4): ns per body-step, and x plain at the same N"]
    L.append("  " + f"{'set':<34}" + "".join(f"{'N = ' + n:>22}" for n in ec["sizes"]))
    for nm in names:
        cells = []
        for row in ec["sizes"].values():
            cells.append(f"{row[nm]['ns_min']:10.1f} ({row['ratios'][nm]:5.2f}x)" if nm in row else f"{'—':>19}")
        L.append("  " + f"{nm:<34}" + "".join(f"{c:>22}" for c in cells))
    if ec.get("user_effect"):
        L.append(f"  user effect not measured: {ec['user_effect']}")
    return L
