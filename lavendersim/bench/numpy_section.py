"""The NumPy-backend section of `lavendersim bench`: the backend against hand-written NumPy and plain Python (issue 30).

The peers are lavendersim/bench/numpy_peers.py (written by hand, not the printed kernels): ``hand_rk4_soa`` (struct
of arrays, coefficients once per run) at N = 1e3 and 1e5 (quick: 1e3), and ``python_rk4`` (one body, Python
floats) at N = 1, each interleaved with ``Sim(..., backend="numpy").run`` and with ``NumpyBackend.advance`` alone
(no Sim checks or chunks; ``advance_ratio``) on the same bodies (torque-free RK4, q normalized; CPU time, min over
rounds), torque-free and with scene-wide gravity and damping (the peers type the same model). Targets: the backend within 1.5x of the hand NumPy loop at every N (both cases), and no slower than
the Python loop for one body (torque-free). Before timing, each peer and the backend advance the same state by
AGREE_STEPS steps; the largest difference is recorded (the peers are right when it is ~1e-12 or less).
"""
from __future__ import annotations

from typing import Any

import numpy as np

from ..generated import layout as LY

SIZES_FULL = (1_000, 100_000)
SIZES_QUICK = (1_000,)
AGREE_STEPS = 50
MIN_STEPS = 32   # steps per timed call at least (full run): the stepping, not a run's setup (4 steps at N = 1e5 before)


GRAVITY, C_LIN, C_ANG = (0.0, 0.0, -9.81), 0.1, 0.05    # the "gravity+damping" case: scene-wide effects


def _with_effects(sim):
    """The bodies of sim with scene-wide gravity, linear_damping (C_LIN) and angular_damping (C_ANG)."""
    from ..scene import Scene
    from ..sim import Sim

    x, prm = np.asarray(sim.x), np.asarray(sim.params)
    s = Scene()
    s.add_bodies([f"b{i}" for i in range(len(x))], prm[:, LY.PARAM_M], prm[:, LY.PARAM_I_B], p_w=x[:, LY.STATE_P_W],
                 q=x[:, LY.STATE_Q], v_w=x[:, LY.STATE_V_W], omega_b=x[:, LY.STATE_OMEGA_B])
    s.add_effect("gravity", g_w=GRAVITY)
    s.add_effect("linear_damping", c=C_LIN)
    s.add_effect("angular_damping", c=C_ANG)
    return Sim(s, dt=sim.dt, integrator="rk4", backend="numpy")


def _case(n, sim, ref, I, steps, rounds, interleaved, forced) -> dict:
    """One N: the backend (sim.run) against its peer, interleaved; ref checks the peer's numbers first."""
    from . import numpy_peers as P

    m = np.asarray(sim.params)[:, LY.PARAM_M]
    kw: dict[str, Any] = dict(g_w=GRAVITY, c_lin=C_LIN, c_ang=C_ANG) if forced else {}
    ref.run(AGREE_STEPS)
    if n == 1:
        x0 = P.python_state(np.asarray(sim.x))
        got = np.asarray(P.python_rk4(x0, I[:, 0], sim.dt, AGREE_STEPS, m=float(m[0]), **kw))
        state = {"x": list(x0)}

        def hand(steps=steps):
            state["x"] = P.python_rk4(state["x"], I[:, 0], sim.dt, steps, m=float(m[0]), **kw)
    else:
        X = P.soa_state(np.asarray(sim.x).reshape(n, -1))
        Xa = X.copy()
        P.hand_rk4_soa(Xa, I, sim.dt, AGREE_STEPS, m=m, **kw)
        got = Xa.T

        def hand(steps=steps):
            P.hand_rk4_soa(X, I, sim.dt, steps, m=m, **kw)
    diff = float(np.max(np.abs(np.asarray(ref.x).reshape(n, -1) - np.asarray(got).reshape(n, -1))))
    cases: dict[str, tuple[Any, ...]] = {"numpy": (lambda s=sim, k=steps: s.run(k), steps * n), "hand": (hand, steps * n),
                                         "advance": (_advance(sim, steps), steps * n)}
    t = interleaved(cases, rounds, f"NumPy vs hand N = {n}" + (" gravity+damping" if forced else ""))
    return {"steps": steps, **t, "ratio": t["numpy"]["ns_min"] / t["hand"]["ns_min"],
            "advance_ratio": t["advance"]["ns_min"] / t["hand"]["ns_min"],
            "peer": "python_rk4" if n == 1 else "hand_rk4_soa", "max_abs_diff": diff}


def _advance(sim, steps: int):
    """NumpyBackend.advance alone on a copy of sim's bodies (no Sim: its checks and chunking left out), steps a call."""
    from ..backends.numpy_backend import NumpyBackend

    be, x = NumpyBackend(), np.array(sim.x)
    params, effects = np.array(sim.params), np.array(sim.effects)
    return lambda k=steps: be.advance(x, params, effects, "rk4", True, sim.dt, k)


def numpy_section(quick: bool, rounds: int, interleaved, batch_sim, I_b, body_steps: int, progress=None) -> dict:
    """Time the NumPy backend against its peers (see the module docstring).

    Returns
    -------
    dict
        ``sizes``: N -> {"numpy", "hand" stats (ns per body-step), "ratio" (numpy / hand), "steps",
        "max_abs_diff"; "advance" and "advance_ratio": NumpyBackend.advance alone}, torque-free; ``effects``: the
        same with scene-wide gravity and damping.
    """
    out: dict[str, dict] = {"sizes": {}, "effects": {}}
    for n in (1,) + (SIZES_QUICK if quick else SIZES_FULL):
        if progress:
            progress(f"NumPy backend vs hand peers: N = {n}")
        I = np.ascontiguousarray(np.tile(np.asarray(I_b, dtype=float)[:, None], (1, n)))
        steps = max(2 if quick else MIN_STEPS, min(2_000, body_steps // n))
        sim = batch_sim(n, "numpy")
        out["sizes"][str(n)] = _case(n, sim, batch_sim(n, "numpy"), I, steps, rounds, interleaved, False)
        out["effects"][str(n)] = _case(n, _with_effects(sim), _with_effects(sim), I, max(2, steps // 2), rounds,
                                       interleaved, True)
        del sim
    return out


def _per_n(rows: dict) -> str:
    return ", ".join(f"N = {n}: {v['ratio']:.2f}x" + (f" ({v['advance_ratio']:.2f}x)" if "advance_ratio" in v else "")
                     for n, v in rows.items())


def standing_lines(res: dict, line, targets: dict) -> list[dict]:
    sec = (res.get("numpy_peers") or {}).get("sizes", {})
    one = sec.get("1")
    big = {n: v for n, v in sec.items() if n != "1"}
    worst = max((v["ratio"] for v in big.values()), default=None)
    eff = {n: v for n, v in (res.get("numpy_peers") or {}).get("effects", {}).items() if n != "1"}
    worst_eff = max((v["ratio"] for v in eff.values()), default=None)
    return [
        line("NumPy backend / hand NumPy RK4, gravity+damping (worst of N >= 1e3)", worst_eff,
             targets["numpy_vs_hand_numpy"], "max", "x", "section not run or crashed" if worst_eff is None else
             "scene-wide gravity, linear and angular damping; Sim.run (advance alone) " + _per_n(eff)),
        line("NumPy backend / hand NumPy RK4 (worst of N >= 1e3)", worst, targets["numpy_vs_hand_numpy"], "max", "x",
             "section not run or crashed" if worst is None else "Sim(backend='numpy').run / numpy_peers.hand_rk4_soa, ns per "
             "body-step (NumpyBackend.advance alone); " + _per_n(big)),
        line("NumPy backend / a pure-Python RK4 loop, one body", None if one is None else one["ratio"],
             targets["numpy_single_vs_python"], "max", "x",
             "section not run or crashed" if one is None else f"{one['numpy']['ns_min'] / 1e3:.1f} µs against "
             f"{one['hand']['ns_min'] / 1e3:.1f} µs per step (numpy_peers.python_rk4)"),
    ]


def report_lines(res: dict, fmt) -> list[str]:
    sec = (res.get("numpy_peers") or {}).get("sizes")
    if not sec:
        return []
    L = []
    for title, rows in (("torque-free", sec), ("gravity+damping", (res.get("numpy_peers") or {}).get("effects", {}))):
        L += ["", f"NumPy backend against hand peers (RK4, {title})   Sim.run ns/body-step   peer   ratio"
                  "  (advance alone)  max|Δx|"]
        for n, v in rows.items():
            adv = f"{v['advance_ratio']:7.2f}" if "advance_ratio" in v else "    n/a"
            L.append(f"  N = {n:<8} ({v['peer']:<12}, {v['steps']:>5} steps) {v['numpy']['ns_min']:12.1f} "
                     f"{v['hand']['ns_min']:12.1f} {v['ratio']:7.2f}  ({adv})        {v['max_abs_diff']:.1e}")
    return L
