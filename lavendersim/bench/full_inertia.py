"""The full-inertia section of `lavendersim bench`: what a body given a full inertia tensor costs against the
same body given its principal moments (issue 26: at most 1.5x; a diagonal body keeps its speed).

A full-tensor body is stepped in its principal frame and converted at the public boundary
(lavendersim.frames), so stepping costs the same arithmetic; what it adds is the conversion where state is
read. Measured interleaved in the same rounds (min over rounds, as every section), C backend, RK4, a real
scene's effects (gravity, angular damping and a force at a body point r_b):

* ``run_full`` / ``run_diag`` — ``Sim.run(RUN_STEPS)`` of N bodies, ns per body-step, at N in SIZES;
* ``read_full`` / ``read_diag`` — the readout a controller does every sample: ``sim.state(name)`` of one
  body and the ``sim.q`` view of all N, ns per call.
"""
from __future__ import annotations

import numpy as np

SIZES = (1, 1_000)
SIZES_QUICK = (1, 100)
RUN_STEPS = 1_000
# the 6U CubeSat of issue 26 (kg·m²) and its principal moments
I_FULL = np.array([[0.2, 0.004, -0.002], [0.004, 0.25, 0.003], [-0.002, 0.003, 0.08]])


def _sim(n: int, full: bool):
    from ..bodies import Body
    from ..scene import Scene
    from ..sim import Sim

    I = I_FULL if full else np.linalg.eigvalsh(I_FULL)
    rng = np.random.default_rng(n)
    scene = Scene()
    for i in range(n):
        q = rng.standard_normal(4)
        scene.add_body(Body(f"b{i}", 12.0, I, q=q / np.linalg.norm(q), omega_b=0.1 * rng.standard_normal(3)))
    scene.add_effect("gravity", g_w=[0.0, 0.0, -9.81])
    scene.add_effect("angular_damping", c=1e-4)
    scene.add_effect("force_at_point", r_b=[0.05, -0.02, 0.1], F_w=[0.0, 1e-3, 0.0])
    return Sim(scene, dt=1e-3, integrator="rk4", backend="c")


def inertia_section(quick: bool, rounds: int, interleaved) -> dict:
    """Time full-tensor bodies against diagonal ones (module docstring).

    Parameters
    ----------
    quick : bool
        Short run: N in SIZES_QUICK.
    rounds : int
        Interleaved rounds.
    interleaved : callable
        lavendersim.bench.interleaved (cases name -> (fn, units), rounds, label) -> name -> stats.

    Returns
    -------
    dict
        Per N: the cases' stats (``ns_min`` per body-step or per call) and ``run_ratio`` (full / diagonal,
        stepping) and ``read_ratio`` (full / diagonal, state readout); ``worst_run_ratio`` over N.
    """
    out = {}
    for n in (SIZES_QUICK if quick else SIZES):
        full, diag = _sim(n, True), _sim(n, False)
        last = f"b{n - 1}"
        cases = {"run_full": (lambda s=full: s.run(RUN_STEPS), n * RUN_STEPS),
                 "run_diag": (lambda s=diag: s.run(RUN_STEPS), n * RUN_STEPS),
                 "read_full": (lambda s=full: (s.state(last), s.q), 1),
                 "read_diag": (lambda s=diag: (s.state(last), s.q), 1)}
        t = interleaved(cases, rounds, f"full inertia N = {n}")
        out[str(n)] = {"cases": t, "run_ratio": t["run_full"]["ns_min"] / t["run_diag"]["ns_min"],
                       "read_ratio": t["read_full"]["ns_min"] / t["read_diag"]["ns_min"]}
    return {"sizes": out, "worst_run_ratio": max(v["run_ratio"] for v in out.values())}


def standing_lines(res: dict, line, targets: dict) -> list[dict]:
    """The section's PASS/MISS line, built with lavendersim.bench._line."""
    sec = res.get("inertia")
    if sec is None:
        return [line("full-tensor body / diagonal body, ns per body-step", None, targets["full_inertia_ratio"], "max", "x",
                     "not run")]
    detail = "; ".join(f"N = {n}: step {v['run_ratio']:.2f}x, state()+q read {v['read_ratio']:.2f}x"
                       for n, v in sec["sizes"].items())
    return [line("full-tensor body / diagonal body, ns per body-step (worst N)", sec["worst_run_ratio"],
                 targets["full_inertia_ratio"], "max", "x", detail + " (gravity, damping, force at r_b; C, RK4)")]


def report_lines(res: dict, fmt) -> list[str]:
    """The section of the text report (fmt: lavendersim.bench._f, ns -> text)."""
    sec = res.get("inertia")
    if sec is None:
        return []
    L = ["", "full inertia tensor vs principal moments (C backend, RK4)     per unit     median"]
    for n, v in sec["sizes"].items():
        c = v["cases"]
        for key, label in (("run_full", f"Sim.run, full tensor, N = {n}, per body-step"),
                           ("run_diag", f"Sim.run, diagonal, N = {n}, per body-step"),
                           ("read_full", f"state(name) + q view, full tensor, N = {n}"),
                           ("read_diag", f"state(name) + q view, diagonal, N = {n}")):
            L.append(f"  {label:<56}{fmt(c[key]['ns_min'])} {fmt(c[key]['ns_median'])}")
    return L
