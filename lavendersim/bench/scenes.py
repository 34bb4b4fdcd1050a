"""The scene-building section of `lavendersim bench`: what a large scene costs before its first step.

Measured interleaved in the same rounds (min over rounds, as every section), at N = SCENE_N bodies:

* ``build`` — ``Scene()``, one batched ``Scene.add_bodies`` of N boxes (names, masses, I_b, q, omega_b as
  arrays) and ``Sim(scene, dt, "rk4", backend="c")``: the scene a user builds, ready to step;
* ``build_one_by_one`` — the same scene through N ``Scene.add_body`` calls (the peer a user would write
  without the batched call);
* ``state_big`` / ``state_small`` — ``sim.state(name)`` of the last body of the N-body Sim and of a
  STATE_SMALL_N-body one: their ratio is ~1 when a lookup is O(1), ~N / STATE_SMALL_N when it scans.
"""
from __future__ import annotations

import numpy as np

SCENE_N = 10_000
STATE_SMALL_N = 10


def _arrays(n: int) -> dict:
    """The N bodies' arrays: unit-box-like inertias, random unit q and spins (seeded)."""
    rng = np.random.default_rng(n)
    q = rng.standard_normal((n, 4))
    return {"names": [f"b{i}" for i in range(n)], "masses": np.full(n, 2.0),
            "I_b": np.tile([0.0333, 0.1133, 0.1333], (n, 1)), "q": q / np.linalg.norm(q, axis=1, keepdims=True),
            "omega_b": rng.standard_normal((n, 3))}


def _build(a: dict, batched: bool):
    from ..bodies import Body
    from ..scene import Scene
    from ..sim import Sim

    scene = Scene()
    if batched:
        scene.add_bodies(a["names"], a["masses"], a["I_b"], q=a["q"], omega_b=a["omega_b"])
    else:
        for i, name in enumerate(a["names"]):
            scene.add_body(Body(name, float(a["masses"][i]), a["I_b"][i], q=a["q"][i], omega_b=a["omega_b"][i]))
    return Sim(scene, dt=1e-3, integrator="rk4", backend="c")


def scene_section(quick: bool, rounds: int, interleaved) -> dict:
    """Time building an N-body scene (batched and one by one) and ``sim.state(name)`` (module docstring).

    Parameters
    ----------
    quick : bool
        Short run: N = SCENE_N / 10.
    rounds : int
        Interleaved rounds.
    interleaved : callable
        lavendersim.bench.interleaved (cases name -> (fn, units), rounds, label) -> name -> stats.

    Returns
    -------
    dict
        ``n_bodies``, the per-case stats (``ns_min`` per build or per lookup) and ``state_ratio``
        (state_big / state_small).
    """
    n = SCENE_N // 10 if quick else SCENE_N
    big, small = _arrays(n), _arrays(STATE_SMALL_N)
    sim_big, sim_small = _build(big, True), _build(small, True)
    last_big, last_small = big["names"][-1], small["names"][-1]
    cases = {"build": (lambda: _build(big, True), 1),
             "build_one_by_one": (lambda: _build(big, False), 1),
             "state_big": (lambda: [sim_big.state(last_big) for _ in range(100)], 100),
             "state_small": (lambda: [sim_small.state(last_small) for _ in range(100)], 100)}
    t = interleaved(cases, rounds, f"scene build N = {n}")
    return {"n_bodies": n, "cases": t, "state_ratio": t["state_big"]["ns_min"] / t["state_small"]["ns_min"],
            "one_by_one_over_batched": t["build_one_by_one"]["ns_min"] / t["build"]["ns_min"]}


def standing_lines(res: dict, line, targets: dict) -> list[dict]:
    """The section's PASS/MISS lines, built with lavendersim.bench._line."""
    sec = res.get("scenes")
    if sec is None:
        return [line(f"scene of {SCENE_N:g} bodies built (add_bodies + Sim)", None, targets["scene_build_s"], "max", "s",
                     "not run")]
    c, n = sec["cases"], sec["n_bodies"]
    build_s = c["build"]["ns_min"] / 1e9
    return [line(f"scene of {n:g} bodies built (add_bodies + Sim)", build_s, targets["scene_build_s"], "max", "s",
                 f"one by one (add_body x {n:g} + Sim) {c['build_one_by_one']['ns_min'] / 1e9:.3f} s, "
                 f"{sec['one_by_one_over_batched']:.1f}x"
                 + ("" if n == SCENE_N else f"; --quick: N = {n:g}, not the target's {SCENE_N:g}")),
            line(f"sim.state(name) at N = {n:g} / at N = {STATE_SMALL_N}", sec["state_ratio"], targets["state_lookup_ratio"],
                 "max", "x", f"{c['state_big']['ns_min'] / 1e3:.2f} µs against {c['state_small']['ns_min'] / 1e3:.2f} µs "
                 "per call (O(1): no scan of the bodies)")]


def report_lines(res: dict, fmt) -> list[str]:
    """The section of the text report (fmt: lavendersim.bench._f, ns -> text)."""
    sec = res.get("scenes")
    if sec is None:
        return []
    c, n = sec["cases"], sec["n_bodies"]
    rows = [("build", f"Scene + add_bodies({n:g}) + Sim"), ("build_one_by_one", f"Scene + add_body x {n:g} + Sim"),
            ("state_big", f"sim.state(name), N = {n:g}"), ("state_small", f"sim.state(name), N = {STATE_SMALL_N}")]
    L = ["", "scene build (C backend, RK4)                                  per call     median"]
    for key, label in rows:
        L.append(f"  {label:<56}{fmt(c[key]['ns_min'])} {fmt(c[key]['ns_median'])}")
    return L
