"""The dopri5 section of `lavendersim bench`: LavenderSim's adaptive Dormand–Prince 5(4) against a hand C DOPRI5.

One torque-free body (the bench's box), rtol = 1e-6, atol = 1e-9, output interval DT_OUT, stepped by
``Sim.run(n)`` on the C backend and by the hand-written peer (handwritten_dopri5.c: the same algorithm and
controller, only q and omega_b through the stages, compiled now with the extension's flags, called through
ctypes), interleaved call by call in short calls of equal length (timing.py; CPU time, min over the calls). The
figure is the cost per right-hand-side evaluation: each call's time / its ``sim.rhs_evals`` against the same for
the peer (target: LavenderSim <= 1.2x the peer). Before
timing, both advance the same state by AGREE_STEPS output steps: their states and evaluation counts are
recorded (the peer is right when they agree to ~1e-12 with equal counts).

Dense output: the same body over DENSE_T seconds by ``Sim.run(DENSE_T / DENSE_DT)`` at dt = DENSE_DT against
``Sim.run(1)`` at dt = DENSE_T (target: at most 1.3x; before dense output each output step clipped a substep).
"""
from __future__ import annotations

import ctypes
from pathlib import Path

import numpy as np

SOURCE = Path(__file__).resolve().parent / "handwritten_dopri5.c"
DT_OUT = 0.1
# dense output: T seconds by run(T / DENSE_DT) at dt = DENSE_DT against run(1) at dt = T (same body, same rtol)
DENSE_T, DENSE_T_QUICK, DENSE_DT = 1000.0, 20.0, 0.01
RTOL, ATOL = 1e-6, 1e-9
AGREE_STEPS = 200
_dp = ctypes.POINTER(ctypes.c_double)


class HandDopri5:
    """handwritten_dopri5.c compiled by ``compile_c`` (lavendersim.bench), one body per call."""

    def __init__(self, compile_c):
        lib, self.command = compile_c(SOURCE, [])
        f = lib.lv_ref_dopri5_free
        f.argtypes = [_dp, _dp, ctypes.c_double, ctypes.c_long, ctypes.c_double, ctypes.c_double, _dp, _dp]
        f.restype = ctypes.c_long
        self._f = f
        self.h = np.zeros(1)      # the step proposal, kept between calls (<= 0: Hairer's starting step)
        self.nfev = np.zeros(1)   # right-hand-side evaluations, cumulative

    def advance(self, x: np.ndarray, I_b: np.ndarray, dt: float, n_steps: int) -> int:
        """Advance x (13,) float64 in place by n_steps output steps of dt; -1, or the step that failed."""
        if x.dtype != np.float64 or x.shape != (13,) or not x.flags.c_contiguous:
            raise TypeError("x must be a C-contiguous float64 array of shape (13,)")
        I_b = np.ascontiguousarray(I_b, dtype=np.float64)
        return int(self._f(x.ctypes.data_as(_dp), I_b.ctypes.data_as(_dp), float(dt), int(n_steps), RTOL, ATOL,
                           self.h.ctypes.data_as(_dp), self.nfev.ctypes.data_as(_dp)))


def agreement(peer: HandDopri5, single_sim, x0: np.ndarray, I_b: np.ndarray, n_steps: int = AGREE_STEPS) -> dict:
    """The peer and ``Sim(dopri5)`` from x0 over n_steps output steps: largest state difference, both counts."""
    sim = single_sim("c", "dopri5", dt=DT_OUT)
    sim.run(n_steps)
    x = x0.copy()
    peer.h[0], peer.nfev[0] = 0.0, 0.0
    status = peer.advance(x, I_b, DT_OUT, n_steps)
    return {"steps": n_steps, "status": status, "max_abs_diff": float(np.max(np.abs(np.asarray(sim.x)[0] - x))),
            "rhs_evals_lavendersim": int(sim.rhs_evals), "rhs_evals_hand": int(peer.nfev[0])}


def dopri5_section(quick: bool, rounds: int, interleaved_calls, compile_c, single_sim, x0, I_b) -> dict:
    """Time Sim(dopri5).run against the peer in short calls of equal length interleaved call by call
    (timing.interleaved_calls: output steps per call calibrated per side); ns per output step and per
    right-hand-side evaluation, each the minimum over the calls."""
    peer = HandDopri5(compile_c)
    out = {"dt": DT_OUT, "rtol": RTOL, "atol": ATOL, "compile_command": peer.command,
           "agreement": agreement(peer, single_sim, x0, I_b)}
    sim = single_sim("c", "dopri5", dt=DT_OUT)
    x = x0.copy()
    sim.run(1)
    peer.h[0] = 0.0
    peer.advance(x, I_b, DT_OUT, 1)

    def ours(k: int) -> int:
        e0 = sim.rhs_evals
        sim.run(k)
        return int(sim.rhs_evals - e0)

    def hand(k: int) -> int:
        e0 = float(peer.nfev[0])
        peer.advance(x, I_b, DT_OUT, k)
        return int(float(peer.nfev[0]) - e0)

    t = interleaved_calls({"lavendersim": (ours, 1, "counted"), "hand": (hand, 1, "counted")}, rounds, "dopri5")
    for k, v in t.items():   # the helper's figures are ns per RHS evaluation (fn returns the count)
        steps = v["count_per_call"]
        rhs = v.pop("units_samples")
        per_rhs = v["ns_samples"]
        per_step = [ns * u / steps for ns, u in zip(per_rhs, rhs)]
        v.update(ns_per_rhs=min(per_rhs), ns_per_rhs_median=v["ns_median"], rhs_per_step=sum(rhs) / (steps * len(rhs)),
                 ns_min=min(per_step), ns_median=float(np.median(per_step)), ns_samples=per_step,
                 units_per_call=steps)
    out["steps"] = t["lavendersim"]["count_per_call"]
    out.update(t)
    out["ratio_per_rhs"] = t["lavendersim"]["ns_per_rhs"] / t["hand"]["ns_per_rhs"]
    return out


def dense_section(quick: bool, rounds: int, interleaved_calls, single_sim) -> dict:
    """CPU time of T seconds of the body at an output interval DENSE_DT (one run of T / DENSE_DT steps) against one
    output step of T, both continuing their trajectories; each call repeats its run as many times as ~2 ms take
    (timing.interleaved_calls), interleaved call by call; RHS evaluations of one run."""
    T = DENSE_T_QUICK if quick else DENSE_T
    n = round(T / DENSE_DT)
    sims = {"dt = T": (single_sim("c", "dopri5", dt=T), 1), f"dt = {DENSE_DT}": (single_sim("c", "dopri5", dt=DENSE_DT), n)}
    evals: dict[str, int] = {}

    def case(k):
        sim, m = sims[k]

        def run(reps: int) -> None:
            for _ in range(reps):
                e0 = sim.rhs_evals
                sim.run(m)
                evals[k] = sim.rhs_evals - e0
        return run

    t = interleaved_calls({k: (case(k), 1) for k in sims}, rounds, "dopri5 dense output")
    coarse, fine = t["dt = T"], t[f"dt = {DENSE_DT}"]
    return {"T": T, "dt": DENSE_DT, "coarse_s": coarse["ns_min"] * 1e-9, "fine_s": fine["ns_min"] * 1e-9,
            "rhs_coarse": evals["dt = T"], "rhs_fine": evals[f"dt = {DENSE_DT}"],
            "ratio": fine["ns_min"] / coarse["ns_min"]}


def standing_lines(res: dict, line, targets: dict) -> list[dict]:
    d = res.get("dopri5") or {}
    v = d.get("ratio_per_rhs")
    basis = (d.get("unavailable", "section not run or crashed") if v is None else
             f"ns per right-hand-side evaluation, one body, dt = {d['dt']} s, rtol {d['rtol']:g}: "
             f"{d['lavendersim']['ns_per_rhs']:.1f} against {d['hand']['ns_per_rhs']:.1f} "
             f"(handwritten_dopri5.c); states agree to {d['agreement']['max_abs_diff']:.1e}")
    g = d.get("dense") or {}
    w = g.get("ratio")
    dbasis = (d.get("unavailable", "section not run or crashed") if w is None else
              f"{g['T']:g} s of one body at rtol {d['rtol']:g} by run({round(g['T'] / g['dt'])}) at dt = {g['dt']} against "
              f"run(1) at dt = {g['T']:g}: {g['fine_s'] * 1e3:.2f} against {g['coarse_s'] * 1e3:.2f} ms CPU, RHS evaluations "
              f"{g['rhs_fine']} against {g['rhs_coarse']}")
    return [line("dopri5 per RHS evaluation / hand C DOPRI5", v, targets["dopri5_per_rhs_vs_hand"], "max", "x", basis),
            line("dopri5 output interval 0.01 s / one output step (dense output)", w, targets["dopri5_dense_vs_coarse"],
                 "max", "x", dbasis)]


def report_lines(res: dict, fmt) -> list[str]:
    d = res.get("dopri5")
    if not d:
        return []
    a = d["agreement"]
    L = ["", f"dopri5, one body, C (dt = {d['dt']} s, rtol {d['rtol']:g}, atol {d['atol']:g})   per output step  "
             "RHS/step  ns per RHS"]
    for k, label in (("lavendersim", "LavenderSim Sim.run"), ("hand", "hand C DOPRI5 (handwritten_dopri5.c)")):
        L.append(f"  {label:<40}{fmt(d[k]['ns_min'])}  {d[k]['rhs_per_step']:8.2f}  {d[k]['ns_per_rhs']:9.1f}")
    L.append(f"  agreement over {a['steps']} steps: max |Δx| = {a['max_abs_diff']:.2e}; RHS evaluations "
             f"{a['rhs_evals_lavendersim']} (ours) vs {a['rhs_evals_hand']} (hand)")
    g = d.get("dense")
    if g:
        L.append(f"  dense output, {g['T']:g} s: dt = {g['dt']} {g['fine_s'] * 1e3:.3f} ms ({g['rhs_fine']} RHS), "
                 f"dt = T {g['coarse_s'] * 1e3:.3f} ms ({g['rhs_coarse']} RHS): {g['ratio']:.2f}x")
    return L
