"""Stability atlas: where every integrator stays stable, and how large its errors grow, over |ω|·dt × inertia ratio × spin axis.

    lavendersim lab atlas [--out DIR] [--backend auto|c|numpy] [--quick] [--workers N | --dask ADDRESS]
                          [--rtol R] [--quiet]

The "hard cases stay numerically stable" demand as a picture. Every integrator of
lavendersim.backends.INTEGRATORS (discovered at run time; the adaptive dopri5 at rtol = 1e-6,
atol = 1e-9 — Sim's defaults, --rtol changes both in proportion — with dt its output interval) runs
one torque-free body per cell of the grid

  |ω|·dt      1e-4 … 10 rad per step, 3 per decade (16 values; --quick: 1 per decade, 6 values)
  ratio       I_max / I_min = 1 … 1e6, 2 per decade (13 values; --quick: 1, 1e3, 1e6)
  spin axis   major, intermediate, minor

Body: I_b = (1/ratio, I_mid, 1) kg·m² with I_mid in the middle of what the triangle inequality
allows, (max(I_min, 1 − I_min) + 1) / 2 (ratio 1 is a sphere: its three "axes" are x, y, z).
Spin: |ω| = 1 rad/s (torque-free motion depends on dt only through |ω|·dt), near the chosen
principal axis: ω_b(0) = |ω| (e_axis + 1e-3 e_j + 1e-3 e_k) / |…| — a perturbation of 1e-3 |ω| on
each of the two other principal axes (ω0 is 1.4e-3 rad = 0.08° off the axis). q(0) is the
catalogue's generic attitude (lab hard's Q0).
Horizon: 5 rotations of the initial spin, T = 5 · 2π / |ω| = 31.4 s, i.e. n = 10π / (|ω| dt) steps
rounded up to a multiple of 200 (314 200 steps at |ω|·dt = 1e-4), and never fewer than 1 000 steps
(so every |ω|·dt ≥ 0.03 runs exactly 1 000 steps: instability has 1 000 steps to show). Samples:
200 evenly spaced in steps plus the initial state; cells run on the C backend when they take more
than 5 000 steps (as in lab hard), else on --backend.

Per cell (results.json "cells", sorted by integrator, axis, ratio, |ω|·dt — never completion order):
  status           ok | diverged (DivergenceError: the step is recorded) | blew_up (finite, no error,
                   but the energy or |L| more than doubled: a silent blow-up; a decay, such as
                   implicit_gyro's dissipation, is not one) | silent_nan
                   (a non-finite state without DivergenceError: a bug) | error (refused the case) |
                   not_run (more than NUMPY_MAX_STEPS steps while the C backend is unavailable: left
                   unmapped rather than run for minutes on NumPy; the lab's checks use the cells that ran)
  energy_drift     max over the samples |E(t) − E(0)| / E(0);   energy_gain  max (E(t)/E(0) − 1)
  L_norm_drift     max | |L_b(t)| − |L_b(0)| | / |L_b(0)|   (|L|, the Casimir)
  L_world_drift    max |L_w(t) − L_w(0)| / |L_w(0)|           (the conserved world vector; ≥ the above)
  attitude_error   max rotation angle (rad) to lavendersim.oracle.torque_free (the exact
                   Jacobi-elliptic motion) at the samples; omega_error  max |ω − ω_exact| / |ω0|
  steps, rhs_evals, dt, T, backend, rtol/atol (adaptive), diverged_at_step, message
  within_bound     |ω0|·dt·ratio^p ≤ the integrator's declared validity bound (derive/tableaux.py: WDT_MAX,
                   WDT_RATIO_EXPONENT; dopri5 has none). The cells run with Sim(..., on_bound="warn") so
                   that the atlas maps behaviour beyond the bound too (a default Sim raises there); Sim's
                   growth check (max_growth = 2: E or |L| ×2 on a torque-free body, the same line as
                   BLOWUP here) stays on, so a cell that doubles is a caught divergence, not a silent blow-up.
Exact zeros and values below 1e-16 are drawn at 1e-16 (the colour bars' lower end).

Pictures (one figure per metric; rows = integrators, columns = spin axes, log axes): energy
drift, world-L drift, attitude error, each with one colour bar; diverged cells grey, silent
blow-ups red, silent NaN magenta, refusals white; the catalogue's bounds (lab hard's ROD_BOUNDS:
energy ≤ 1e-10, L_w ≤ 1e-9, attitude ≤ 3e-9 rad) drawn as a black outline around the cells where
the bound holds; RK4's linear stability limit |ω|·dt = 2√2 dashed on the rk4 row; the catalogue's
own trials (lab hard) as stars on the row of the integrator each is asserted with. atlas_status.png:
the status of every cell, "within the catalogue's bounds" distinguished from "stable".

Checks (bounds that hold here and would fail if an integrator regressed):
  * no cell anywhere ends in a silent NaN or an error other than DivergenceError;
  * no cell within its integrator's declared validity bound is a silent blow-up (issue 11);
  * rk4 at |ω|·dt ≤ 1e-3: ok for every ratio and axis, within all three catalogue bounds;
  * rk4 at |ω|·dt = 10 (beyond its limit 2√2) on every non-spherical body diverges or blows up — an
    inaccurate-but-finite answer there would be silent (a sphere's ω_b is constant, so only its
    attitude goes wrong: the check leaves ratio 1 out);
  * euler at |ω|·dt = 10 on every non-spherical body diverges or blows up;
  * implicit_gyro never gains energy: max energy_gain ≤ 1e-12 over every cell where it ran;
  * splitting conserves world L to rounding wherever it ran, blow-ups included: L_world_drift ≤
    4 ε · steps (ε = 2.2e-16; rounding accumulates linearly, at most ~1e-16 per step here);
    splitting4 likewise with the same allowance per axis flow: 4 ε · 21/5 · steps (21 flows per step);
  * dopri5 is ok in every cell, and its energy and world-L drift are ≤ rtol × its substeps (rhs_evals / 6;
    the controller bounds each substep's error by ~rtol) wherever the horizon is 5 rotations (|ω|·dt ≤ 0.031;
    beyond, 1 000 steps cover up to 1 600 rotations).

Executors: by default the cells run in a pool of processes on every local core; --workers 1 runs
them in this process; --dask ADDRESS sends them to the workers of an existing Dask scheduler (the
distributed extra). The cells are deterministic, so results.json is byte-identical whichever
executor ran it; how it ran (executor, wall time) goes to run.json beside it.

--quick: the coarse grid (6 × 3 × 3 cells per integrator, a subset of the full grid with the same
numbers in each shared cell): ~21 s of CPU on one core (the cells ~15 s, the four pictures the
rest). From Python, ``run(out_dir)`` is the quick atlas — what ``lavendersim lab all`` runs; the
command line without --quick runs the full atlas (16 × 13 × 3 cells per integrator: the cells take
~3.5 min on one core, measured on a loaded 2-core Xeon).

Files: OUT/atlas/results.json (flat figures and checks, plus "grid", "cells", "bounds",
"hard_case_points"), run.json, atlas_status.png, atlas_energy.png, atlas_momentum.png,
atlas_attitude.png.
"""
from __future__ import annotations

import functools
import json
import math
import os
import sys
import time
import warnings
from typing import Any

import numpy as np

import lavendersim as lv
from lavendersim import backends as B
from lavendersim import executor as X
from lavendersim.generated import tableaux as TABLEAUX
from lavendersim import oracle as R
from lavendersim import validate as V
from lavendersim import sim as S
from lavendersim.errors import DivergenceError, ValidityBoundWarning
from lavendersim.kernels import K
from lavendersim import figures as F

from . import common as C
from .diverged import failed_figure
from . import hard_cases as H

NAME = "atlas"
TITLE = "stability atlas: every integrator over |ω|·dt × inertia ratio × spin axis (heat maps, JSON; --quick in lab all)"

OMEGA = 1.0                      # rad/s
PERTURBATION = 1e-3              # of |ω|, on each of the two other principal axes
ROTATIONS = 5                    # horizon, in rotations of the initial spin
MIN_STEPS = 1000
SAMPLES = 200
BLOWUP = 1.0                     # energy or |L| grew by more than 100 % (more than doubled): a blow-up
FLOOR = 1e-16                    # smallest value drawn
AXES = ("major", "intermediate", "minor")
AXIS_INDEX = {"minor": 0, "intermediate": 1, "major": 2}    # I_b is sorted ascending
RTOL, ATOL = 1e-6, 1e-9          # dopri5 (Sim's defaults); atol scales with --rtol

FULL_WDT = tuple(10.0 ** (k / 3) for k in range(-12, 4))       # 1e-4 … 10, 3 per decade
FULL_RATIOS = tuple(10.0 ** (k / 2) for k in range(13))     # 1 … 1e6, 2 per decade
GRIDS = {"full": (FULL_WDT, FULL_RATIOS), "quick": (FULL_WDT[::3], FULL_RATIOS[::6])}

# the catalogue's bounds (lab hard), drawn in and checked
BOUNDS = {"energy_drift": H.ROD_BOUNDS["energy_drift"][0], "L_world_drift": H.ROD_BOUNDS["momentum_drift"][0],
          "attitude_error": H.ROD_BOUNDS["attitude_error"][0]}
ENERGY_GAIN_BOUND = 1e-12        # lab hard's fast_major_spin_dt1e-2 bound for implicit_gyro
EPS = float(np.finfo(float).eps)
SPLITTING_L_PER_STEP = 4.0       # world-L drift of splitting ≤ 4 ε per step: rounding, linear in the steps
# a composition's torque-free step (its printed free program, generated/tableaux.py COMPOSITIONS) applies some exact
# rotations (axis, top and sphere flows; strang = the STRANG sequence's) where splitting applies 5: the same
# allowance per rotation (measured: splitting4 2.5 ε per step at most over the quick grid)
_ROTATIONS = {n: sum(len(TABLEAUX.STRANG) if f == "strang" else f not in ("drift", "momentum", "rate") for f, _ in free)
              for n, (_, _, free) in TABLEAUX.COMPOSITIONS.items()}
L_PER_STEP = {n: SPLITTING_L_PER_STEP * k / len(TABLEAUX.STRANG) for n, k in _ROTATIONS.items()}
RK4_SMALL_WDT = 1e-3
STATUSES = ("ok", "diverged", "blew_up", "silent_nan", "error", "not_run")
# Without the C backend, cells longer than this are "not_run" (the quick atlas's |ω|·dt = 1e-4 column,
# ~3e5 steps per cell, would take ~10 s each on NumPy: half an hour for lab all on a compiler-less machine).
NUMPY_MAX_STEPS = 40_000


# ------------------------------------------------------------------------------------------ the grid

def inertia(ratio: float) -> np.ndarray:
    """Principal moments (1/ratio, I_mid, 1) kg·m², I_mid in the middle of the triangle-inequality range."""
    i_min = 1.0 / ratio
    return np.array([i_min, (max(i_min, 1.0 - i_min) + 1.0) / 2.0, 1.0])


def initial_omega(axis: str) -> np.ndarray:
    """ω_b(0) of norm OMEGA along the principal axis `axis`, perturbed by PERTURBATION on the other two."""
    v = np.full(3, PERTURBATION)
    v[AXIS_INDEX[axis]] = 1.0
    return OMEGA * v / np.linalg.norm(v)


def horizon_steps(wdt: float) -> int:
    """Steps covering ROTATIONS rotations at |ω|·dt = wdt, a multiple of SAMPLES, at least MIN_STEPS."""
    n = SAMPLES * math.ceil(ROTATIONS * 2 * math.pi / wdt / SAMPLES - 1e-9)
    return max(MIN_STEPS, n)


def make_tasks(wdts, ratios, integrators, backend: str, rtol: float, atol: float) -> list[tuple]:
    """One task per (|ω|·dt, ratio, axis), each running every integrator; longest first (load balance)."""
    tasks = [(float(w), float(r), a, tuple(integrators), backend, rtol, atol)
             for w in wdts for r in ratios for a in AXES]
    return sorted(tasks, key=lambda t: (-horizon_steps(t[0]), t[1], AXES.index(t[2])))


# ------------------------------------------------------------------------------------------ one cell

def cell_metrics(I_b: np.ndarray, w0: np.ndarray, x: np.ndarray, ref) -> dict:
    """Drifts and errors of one run's samples.

    Parameters
    ----------
    I_b : ndarray (3,)
        Principal moments, kg·m².
    w0 : ndarray (3,)
        ω_b(0), rad/s.
    x : ndarray (S, 13)
        The body's sampled states (finite).
    ref : TorqueFreeMotion or None
        The exact motion at the same times; None leaves attitude_error and omega_error None.

    Returns
    -------
    dict
        energy_drift, energy_gain, L_norm_drift, L_norm_gain, L_world_drift, attitude_error (rad),
        omega_error (relative to |ω0|); a value that overflows is None.
    """
    q, w = x[:, C.Q], x[:, C.OMEGA_B]
    with np.errstate(over="ignore", invalid="ignore"):
        E, Lw = C.energy_momentum(I_b, x)
        Ln = np.linalg.norm(K.body_momentum(I_b, w), axis=1)
        m = {"energy_drift": R.relative_drift(E), "energy_gain": float(np.max(E / E[0] - 1.0)),
             "L_norm_drift": float(np.max(np.abs(Ln - Ln[0])) / Ln[0]), "L_norm_gain": float(np.max(Ln / Ln[0] - 1.0)),
             "L_world_drift": R.relative_drift(Lw), "attitude_error": None, "omega_error": None}
        if ref is not None:
            m["attitude_error"] = float(np.max(R.attitude_error(ref.q, q)))
            m["omega_error"] = float(np.max(np.linalg.norm(ref.omega_b - w, axis=1)) / np.linalg.norm(w0))
    return {k: C.finite_or_none(v) for k, v in m.items()}


def _blew_up(m: dict) -> bool:
    """E or |L| grew by more than BLOWUP (a decay, e.g. implicit_gyro's dissipation, is not a blow-up)."""
    if any(m[k] is None for k in ("energy_drift", "energy_gain", "L_norm_drift", "L_norm_gain", "L_world_drift")):
        return True           # an invariant overflowed although the state is finite
    return m["energy_gain"] > BLOWUP or m["L_norm_gain"] > BLOWUP


def run_cell(integrator: str, wdt: float, ratio: float, axis: str, backend: str, rtol: float, atol: float,
             ref=None) -> dict:
    """Run one cell of the atlas; never raises for a numerical failure (it is the cell's status).

    Parameters
    ----------
    integrator : str
        A name of lavendersim.backends.INTEGRATORS.
    wdt : float
        |ω|·dt, rad per step (dt = wdt / OMEGA; the output interval for an adaptive integrator).
    ratio : float
        I_max / I_min of the body (:func:`inertia`).
    axis : {"major", "intermediate", "minor"}
        The principal axis of the near-axis spin (:func:`initial_omega`).
    backend : str
        Backend for runs of at most 5 000 steps (longer ones use C when it is built).
    rtol, atol : float
        Tolerances of an adaptive integrator (ignored by the others).
    ref : TorqueFreeMotion or None
        The exact motion at the cell's sample times, for the attitude and ω errors.

    Returns
    -------
    dict
        The cell's row of results.json (see the module docstring).
    """
    cell = _new_cell(integrator, wdt, ratio, axis, backend, rtol, atol)
    I_b, w0, dt, n, adaptive = inertia(ratio), initial_omega(axis), cell["dt"], cell["steps"], cell["rtol"] is not None
    scene = lv.Scene()
    scene.add_body(lv.Body("body", 1.0, I_b, omega_b=w0, q=H.Q0))
    if n > NUMPY_MAX_STEPS and cell["backend"] != "c":     # long, and the C backend is unavailable
        cell.update(status="not_run", message=f"{n} steps on the NumPy backend: not run (more than NUMPY_MAX_STEPS = "
                                              f"{NUMPY_MAX_STEPS} without the C backend: {B.c_unavailable()})")
        return cell
    try:
        # the atlas maps behaviour beyond each integrator's declared validity bound too: it opts in with
        # on_bound="warn" (a default Sim raises DivergenceError there); the growth check stays at its default
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", ValidityBoundWarning)
            tols: dict[str, Any] = {"rtol": rtol, "atol": atol} if adaptive else {}
            sim = lv.Sim(scene, dt=dt, integrator=integrator, backend=cell["backend"], on_bound="warn", **tols)
            tr = sim.record(n, n // SAMPLES)
    except DivergenceError as exc:
        cell.update(status="diverged", diverged_at_step=int(exc.step), message=str(exc))
        return cell
    except Exception as exc:      # an integrator that refuses the case: recorded, checked, drawn
        cell.update(status="error", message=f"{type(exc).__name__}: {exc}")
        return cell
    cell["rhs_evals"] = int(sim.rhs_evals)
    x = tr.x[:, 0]
    if not np.all(np.isfinite(x)):
        cell["status"] = "silent_nan"
        return cell
    m = cell_metrics(I_b, w0, x, ref)
    cell.update(m)
    cell["status"] = "blew_up" if _blew_up(m) else "ok"
    return cell


def _new_cell(integrator: str, wdt: float, ratio: float, axis: str, backend: str, rtol: float, atol: float) -> dict:
    """A cell's row before it runs: its body, spin, steps, backend and whether it is within the validity bound."""
    I_b, w0 = inertia(ratio), initial_omega(axis)
    dt, n = wdt / OMEGA, horizon_steps(wdt)
    adaptive, bound = integrator in B.ADAPTIVE, S.validity_bound(integrator)
    return {"integrator": integrator, "omega_dt": wdt, "ratio": ratio, "axis": axis, "status": None,
            "energy_drift": None, "energy_gain": None, "L_norm_drift": None, "L_norm_gain": None, "L_world_drift": None,
            "attitude_error": None, "omega_error": None, "steps": n, "dt": dt, "T": n * dt, "rhs_evals": None,
            "backend": H.fast_backend(backend) if n > H.C_BACKEND_ABOVE else backend,
            "rtol": rtol if adaptive else None, "atol": atol if adaptive else None,
            "diverged_at_step": None, "message": None, "I_b": I_b.tolist(), "omega_b0": w0.tolist(),
            "within_bound": bool(bound is None or float(np.linalg.norm(w0)) * dt * ratio ** bound[1] <= bound[0])}


def run_group(task: tuple) -> list[dict]:
    """Every integrator at one (|ω|·dt, ratio, axis): the executor's unit of work.

    Parameters
    ----------
    task : tuple
        ``(wdt, ratio, axis, integrators, backend, rtol, atol)`` as made by :func:`make_tasks`.

    Returns
    -------
    list of dict
        One cell per integrator, in the order of ``integrators``. The exact reference is computed
        once for the group (all integrators sample the same times); where it cannot be, the cells
        say so in "reference" and carry no attitude error.
    """
    wdt, ratio, axis, integrators, backend, rtol, atol = task
    n = horizon_steps(wdt)
    every = n // SAMPLES
    t = np.arange(0, n + 1, every) * (wdt / OMEGA)
    try:
        ref, why = R.torque_free(inertia(ratio), initial_omega(axis), H.Q0, t), None
    except Exception as exc:      # no exact solution here: the cells say so and carry no attitude error
        ref, why = None, f"reference unavailable: {type(exc).__name__}: {exc}"
    cells = []
    for integ in integrators:
        c = run_cell(integ, wdt, ratio, axis, backend, rtol, atol, ref)
        c["reference"] = why if ref is None else f"oracle.torque_free ({ref.kind})"
        cells.append(c)
    return cells


def cell_key(cell: dict, integrators) -> tuple:
    """Sort key of a cell: (integrator's index, axis index, ratio, |ω|·dt)."""
    return (list(integrators).index(cell["integrator"]), AXES.index(cell["axis"]), cell["ratio"], cell["omega_dt"])


def compute_cells(wdts, ratios, integrators, backend, rtol, atol, executor: X.Executor, bar=None) -> list[dict]:
    """Every cell of a grid, computed on `executor`.

    Parameters
    ----------
    wdts, ratios : sequence of float
        The |ω|·dt and inertia-ratio values.
    integrators : list of str
        The integrators to run (rows of the pictures).
    backend : str
        Backend of the short runs (see :func:`run_cell`).
    rtol, atol : float
        Adaptive tolerances.
    executor : lavendersim.executor.Executor
        Where the groups run.
    bar : tqdm or None
        A progress bar advanced as the groups finish (labs.common.progress).

    Returns
    -------
    list of dict
        The cells sorted by :func:`cell_key` (integrator, axis, ratio, |ω|·dt): the same list
        whatever the executor and the completion order.
    """
    tasks = make_tasks(wdts, ratios, integrators, backend, rtol, atol)
    if bar is None:
        groups = executor.map(run_group, tasks, feature="lavendersim lab atlas --dask")
    else:
        groups = C.map_with_progress(executor, run_group, tasks, bar, feature="lavendersim lab atlas --dask")
    cells = [c for g in groups for c in g]
    return sorted(cells, key=lambda c: cell_key(c, integrators))


# ------------------------------------------------------------------------------------------ checks

def _select(cells, integrator=None, status=None, **where):
    out = []
    for c in cells:
        if integrator is not None and c["integrator"] != integrator:
            continue
        if status is not None and c["status"] not in ((status,) if isinstance(status, str) else status):
            continue
        if all(f(c[k]) for k, f in where.items()):
            out.append(c)
    return out


def _worst(cells, key) -> float:
    vals = [c[key] for c in cells]
    if any(v is None for v in vals):
        return math.inf
    return max(vals, default=0.0)


def _where(cells, limit=4) -> str:
    txt = "; ".join(f"{c['integrator']} {c['axis']} ratio {c['ratio']:.3g} |ω|dt {c['omega_dt']:.3g}: {c['status']}"
                    for c in cells[:limit])
    return txt + (f" and {len(cells) - limit} more" if len(cells) > limit else "")


def _available(name, integrators, checks) -> bool:
    if name in integrators:
        return True
    checks.append(C.holds(f"{name}_available", False, f"{name!r} is not in lavendersim.backends.INTEGRATORS "
                                                      f"({', '.join(integrators)}): its atlas check cannot run"))
    return False


def _unstable_at_top(cells, integ, name) -> C.Check:
    """`integ` at |ω|·dt = 10 on every non-spherical body: diverged or blew up, never quietly finite."""
    top = _select(cells, integ, omega_dt=lambda w: w >= 10.0 * (1 - 1e-9), ratio=lambda r: r > 1.0)
    calm = [c for c in top if c["status"] not in ("diverged", "blew_up")]
    return C.holds(name, not calm and bool(top),
                   f"{integ} at |ω|·dt = 10 on every non-spherical body diverges or blows up ({len(top)} cells)"
                   + (f"; quietly finite: {_where(calm)}" if calm else ""))


def _rk4_checks(cells, checks, fig) -> None:
    small = _select(cells, "rk4", omega_dt=lambda w: w <= RK4_SMALL_WDT * (1 + 1e-9))
    not_ok = [c for c in small if c["status"] != "ok"]
    checks.append(C.holds("rk4_small_steps_ok", not not_ok and bool(small),
                          f"rk4 at |ω|·dt ≤ {RK4_SMALL_WDT:g}: ok for every ratio and axis ({len(small)} cells)"
                          + (f"; not ok: {_where(not_ok)}" if not_ok else "")))
    for key, bound in BOUNDS.items():
        fig[f"rk4_small_steps_worst_{key}"] = w = _worst(small, key)
        checks.append(C.at_most(f"rk4_small_steps_{key}", w, bound,
                                f"rk4, |ω|·dt ≤ {RK4_SMALL_WDT:g}, every ratio and axis, {ROTATIONS} rotations: "
                                "the catalogue's bound (lab hard ROD_BOUNDS)"))
    checks.append(_unstable_at_top(cells, "rk4", "rk4_beyond_stability_not_silent"))


def _implicit_gyro_checks(cells, checks, fig) -> None:
    ran = _select(cells, "implicit_gyro", status=("ok", "blew_up"))
    fig["implicit_gyro_max_energy_gain"] = g = _worst(ran, "energy_gain")
    gained = [c for c in ran if c["energy_gain"] is None or c["energy_gain"] > ENERGY_GAIN_BOUND]
    checks.append(C.at_most("implicit_gyro_never_gains_energy", g, ENERGY_GAIN_BOUND,
                            f"max over the {len(ran)} cells where implicit_gyro ran of max_t E(t)/E(0) − 1 "
                            "(at the samples; lab hard's bound)" + (f"; gains in {_where(gained)}" if gained else "")))


def _splitting_checks(cells, checks, fig, name: str, bound: float) -> None:
    ran = _select(cells, name, status=("ok", "blew_up"))
    fig[f"{name}_max_L_world_drift"] = _worst(ran, "L_world_drift")
    per_step = [math.inf if c["L_world_drift"] is None else c["L_world_drift"] / (c["steps"] * EPS) for c in ran]
    fig[f"{name}_max_L_world_drift_per_step_eps"] = d = max(per_step, default=0.0)
    checks.append(C.at_most(f"{name}_conserves_L", d, bound,
                            f"max over the {len(ran)} cells where {name} ran (blow-ups included: exact axis "
                            "rotations keep L_w whatever |ω|·dt) of world-L drift / (steps × machine epsilon): "
                            "rounding only, however large |ω|·dt"))


def _adaptive_checks(cells, checks, fig, name: str, rtol: float) -> None:
    mine = _select(cells, name)
    not_ok = [c for c in mine if c["status"] != "ok"]
    checks.append(C.holds(f"{name}_ok_everywhere", not not_ok and bool(mine),
                          f"{name} (rtol {rtol:g}) ok in every cell" + (f"; not ok: {_where(not_ok)}" if not_ok else "")))
    short = [c for c in mine if horizon_steps(c["omega_dt"]) > MIN_STEPS]
    d = max(_worst(short, "energy_drift"), _worst(short, "L_world_drift"))
    fig[f"{name}_worst_drift_{ROTATIONS}_rotations"] = d
    # The controller bounds each accepted substep's error by ~rtol (relative), so a run's drift is bounded by
    # rtol × its substeps (≈ rhs_evals / 6: six per substep, FSAL), not by rtol: with dense output the integrator
    # takes the substeps its controller picks (~100 over 5 rotations) instead of landing on every output time.
    per = [max(_worst([c], "energy_drift"), _worst([c], "L_world_drift")) / (rtol * max(1.0, c["rhs_evals"] / 6))
           for c in short]
    fig[f"{name}_worst_drift_per_substep_rtol"] = r = max(per, default=0.0)
    checks.append(C.at_most(f"{name}_drift_within_rtol_per_substep", r, 1.0,
                            f"{name}: max over the cells whose horizon is {ROTATIONS} rotations (|ω|·dt ≤ "
                            f"{ROTATIONS * 2 * math.pi / MIN_STEPS:.3g}) of energy and world-L drift / (rtol × "
                            "substeps) ≤ 1: the local error control summed over the run"))


def atlas_checks(cells: list[dict], integrators, rtol: float) -> tuple[list[C.Check], dict]:
    """The lab's checks (see the module docstring) and the figures they are drawn from.

    Parameters
    ----------
    cells : list of dict
        Every cell of the atlas (as in results.json).
    integrators : list of str
        The integrators that ran; a check about a missing one fails, naming it.
    rtol : float
        The adaptive integrators' rtol.

    Returns
    -------
    (list of Check, dict)
        The checks and a flat dict of the figures they measured.
    """
    checks, fig = [], {}
    fig["cells_not_run"] = sum(c["status"] == "not_run" for c in cells)     # no C backend: see NUMPY_MAX_STEPS
    cells = [c for c in cells if c["status"] != "not_run"]
    bad = [c for c in cells if c["status"] in ("silent_nan", "error")]
    checks.append(C.holds("no_silent_nan_or_error", not bad,
                          "every non-finite run raised DivergenceError and no integrator refused a cell"
                          + (f"; found: {_where(bad)}" if bad else "")))
    silent = [c for c in cells if c["status"] == "blew_up" and c.get("within_bound", True)]
    fig["blew_up_within_bound"] = len(silent)
    checks.append(C.holds("no_silent_blow_up_within_bounds", not silent,
                          "no cell within its integrator's declared validity bound (derive/tableaux.py WDT_MAX) "
                          "more than doubled E or |L| without a DivergenceError (beyond the bound a default Sim "
                          "raises; the atlas opts in with on_bound='warn' to map it)"
                          + (f"; found: {_where(silent)}" if silent else "")))
    def declare(name, add):   # integrator -> its checks (appending to checks and fig); a missing one fails
        if _available(name, integrators, checks):
            add(cells, checks, fig)

    declare("rk4", _rk4_checks)
    declare("euler", lambda *a: checks.append(_unstable_at_top(cells, "euler", "euler_unstable_at_large_steps")))
    declare("implicit_gyro", _implicit_gyro_checks)
    for name, bound in L_PER_STEP.items():
        declare(name, functools.partial(_splitting_checks, name=name, bound=bound))
    for name in B.ADAPTIVE:
        declare(name, functools.partial(_adaptive_checks, name=name, rtol=rtol))
    return checks, fig


# ------------------------------------------------------------------------------------------ the catalogue's trials

# lab hard's dynamic trials: (name, I_b, omega_b0, dt, the integrator its bounds are asserted with)
HARD_TRIALS = tuple((t.name, t.I_b, t.w0, t.dt, t.integrator) for t in H.TRIALS) + (
    ("divergence_report", H.DIV_I, H.DIV_SPIN, H.DIV_DT, "euler"),
) + tuple((f"dt_range_{b}_dt{dt:.0e}", H.DIAG123, w, dt, "rk4") for b, w in H.DT_BODIES.items() for dt in H.DT_RANGE)


def hard_case_points(wdts) -> list[dict]:
    """Where lab hard's trials sit in the atlas: |ω|·dt, inertia ratio I_max/I_min, the principal axis
    with the largest |ω_i| and the integrator; only the trials inside the atlas's |ω|·dt range."""
    lo, hi = min(wdts), max(wdts)
    out = []
    for name, I_b, w0, dt, integ in HARD_TRIALS:
        I, w = np.asarray(I_b, float), np.asarray(w0, float)
        wdt = float(np.linalg.norm(w) * dt)
        if not lo / 1.5 <= wdt <= hi * 1.5:
            continue
        order = np.argsort(I, kind="stable")                 # sorted axis 0 = minor, 2 = major
        axis = ("minor", "intermediate", "major")[int(np.argmax(np.abs(w[order])))]
        out.append({"name": name, "omega_dt": wdt, "ratio": float(I.max() / I.min()), "axis": axis,
                    "integrator": integ, "dt_range": name.startswith("dt_range")})
    return out


# ------------------------------------------------------------------------------------------ pictures

# Okabe–Ito (lavendersim.figures): blown-up cells are also hatched, and each status is told apart by
# lightness as well as hue, so the maps read under colour-vision deficiencies
STATUS_COLORS = {"diverged": F.GREY, "blew_up": F.VERMILLION, "silent_nan": F.PURPLE, "error": "#ffffff",
                 "no_reference": "#e0e0e0", "not_run": F.YELLOW}
STATUS_TEXT = {"diverged": "diverged: DivergenceError raised", "blew_up": "silent blow-up: E or |L| more than doubled, no error",
               "silent_nan": "silent NaN: non-finite without DivergenceError", "error": "refused (error)",
               "no_reference": "no exact reference for this cell",
               "not_run": f"not run: > {NUMPY_MAX_STEPS} steps without the C backend"}
METRICS = {  # metric -> (file, colour-bar label, vmax, bound label)
    "energy_drift": ("atlas_energy.png", "relative energy drift  max_t |E(t) − E(0)| / E(0)", 1.0,
                     "energy drift ≤ {b:.0e}"),
    "L_world_drift": ("atlas_momentum.png", "world angular-momentum drift  max_t |L_w(t) − L_w(0)| / |L_w(0)|", 2.0,
                      "world-L drift ≤ {b:.0e}"),
    "attitude_error": ("atlas_attitude.png", "attitude error vs the exact motion  max_t angle (rad)", math.pi,
                       "attitude error ≤ {b:.0e} rad"),
}
OVERVIEW_COLORS = (F.BLUE, F.SKY_BLUE, STATUS_COLORS["diverged"], STATUS_COLORS["blew_up"],
                   STATUS_COLORS["silent_nan"], STATUS_COLORS["error"], STATUS_COLORS["not_run"])


def _edges(values) -> np.ndarray:
    """Cell edges of a log-spaced grid: geometric midpoints, half a step beyond each end."""
    lv_ = np.log10(np.asarray(values, float))
    step = np.diff(lv_).min() if len(lv_) > 1 else 1.0
    mids = (lv_[1:] + lv_[:-1]) / 2
    return 10.0 ** np.concatenate([[lv_[0] - step / 2], mids, [lv_[-1] + step / 2]])


def _grid(cells, integ, axis, wdts, ratios, fn) -> np.ndarray:
    """fn(cell) over the (ratio, |ω|·dt) grid of one panel (rows = ratios)."""
    idx = {(c["ratio"], c["omega_dt"]): c for c in cells if c["integrator"] == integ and c["axis"] == axis}
    return np.array([[fn(idx.get((r, w))) for w in wdts] for r in ratios], dtype=float)


def _outline(ax, inside: np.ndarray, xe, ye, **style) -> None:
    """Staircase boundary (on cell edges) of the cells where `inside` is True."""
    from matplotlib.collections import LineCollection

    segs = []
    ny, nx = inside.shape
    pad = np.zeros((ny + 2, nx + 2), bool)
    pad[1:-1, 1:-1] = inside
    for i in range(ny + 1):                       # horizontal edges between rows i-1 and i
        for j in range(nx):
            if pad[i, j + 1] != pad[i + 1, j + 1]:
                segs.append([(xe[j], ye[i]), (xe[j + 1], ye[i])])
    for i in range(ny):                           # vertical edges between columns j-1 and j
        for j in range(nx + 1):
            if pad[i + 1, j] != pad[i + 1, j + 1]:
                segs.append([(xe[j], ye[i]), (xe[j], ye[i + 1])])
    if segs:
        ax.add_collection(LineCollection(segs, **style))


def _decade(x: float) -> str:
    k = round(math.log10(x))
    return {0: "1", 1: "10"}.get(k, f"1e{k}")


def _decorate(ax, integ, axis, row, col, nrows, xe, ye, hard_points, scales: bool = True) -> None:
    """Titles, labels, lines and markers of one panel; its scales, limits and ticks when ``scales`` (the lab's
    figure shares them between all its panels: set once; the caller's axes (ax=) each)."""
    from matplotlib.ticker import FixedFormatter, FixedLocator, NullLocator

    if scales:
        ax.set_xscale("log")
        ax.set_yscale("log")
        ax.set_xlim(xe[0], xe[-1])
        ax.set_ylim(ye[0], ye[-1])
        for axis_, edges in ((ax.xaxis, xe), (ax.yaxis, ye)):
            ks = list(range(math.ceil(math.log10(edges[0])), math.floor(math.log10(edges[-1])) + 1))
            ks = [k for k in ks if k >= 0] if axis_ is ax.yaxis else ks     # ratios start at 1
            ks = ks[::math.ceil(len(ks) / 7)]
            axis_.set_major_locator(FixedLocator([10.0 ** k for k in ks]))  # decades, no minor ticks, plain text
            axis_.set_major_formatter(FixedFormatter([_decade(10.0 ** k) for k in ks]))
            axis_.set_minor_locator(NullLocator())
    ax.set_title(f"{integ} · {axis}", fontsize=8.5)
    if row == nrows - 1:
        ax.set_xlabel("|ω|·dt (rad per step)", fontsize=8)
    else:
        ax.tick_params(labelbottom=False)
    if col == 0:
        ax.set_ylabel("I_max / I_min", fontsize=8)
    else:
        ax.tick_params(labelleft=False)
    ax.axvline(ROTATIONS * 2 * math.pi / MIN_STEPS, color="0.35", lw=0.8, ls=":")
    if integ == "rk4":
        ax.axvline(H.RK4_STABILITY, color="k", lw=1.0, ls="--")
    for p in hard_points:
        if p["integrator"] == integ and p["axis"] == axis:
            ax.plot(p["omega_dt"], p["ratio"], "o" if p["dt_range"] else "*", ms=5 if p["dt_range"] else 9,
                    mfc="white", mec="k", mew=0.8, zorder=5)


def _not_run_handle(cells) -> list:
    """The legend entry for cells that were not run (none when every cell ran)."""
    from matplotlib.patches import Patch

    if not any(c["status"] == "not_run" for c in cells):
        return []
    return [Patch(facecolor=STATUS_COLORS["not_run"], edgecolor="k", lw=0.5, label=STATUS_TEXT["not_run"])]


def _legend_handles(extra: list, hatched: bool = False) -> list:
    """Legend entries: `extra` first, then the statuses and the lines and markers of _decorate."""
    from matplotlib.lines import Line2D
    from matplotlib.patches import Patch

    hs = list(extra) + [Patch(facecolor=STATUS_COLORS[k], edgecolor="k", lw=0.5, label=STATUS_TEXT[k])
                        for k in ("diverged", "blew_up", "silent_nan", "error")]
    if hatched:     # metric maps: a blown-up cell keeps its value's colour under red hatching
        hs[len(extra) + 1] = Patch(facecolor="white", edgecolor=STATUS_COLORS["blew_up"], hatch="xxx",
                                   label=STATUS_TEXT["blew_up"] + " (value underneath; solid red: value overflowed)")
    hs += [Line2D([], [], color="0.35", ls=":", label=f"horizon: left {ROTATIONS} rotations, right {MIN_STEPS} steps"),
           Line2D([], [], color="k", ls="--", label="RK4 stability limit |ω|·dt = 2√2 (rk4 rows)"),
           Line2D([], [], ls="", marker="*", ms=9, mfc="white", mec="k", label="lab hard trial, on the row of its asserted integrator"),
           Line2D([], [], ls="", marker="o", ms=5, mfc="white", mec="k", label="lab hard dt_range point (rk4)")]
    return hs


def _layout(n: int) -> tuple[int, int]:
    """(rows, blocks) of the panel grid: more than four integrators sit in two blocks side by side, so the
    figure fits a screen (10 integrators: 5 rows × 6 panels, ~1650 × 1400 px at 110 dpi)."""
    blocks = 2 if n > 4 else 1
    return math.ceil(n / blocks), blocks


def _place(r: int, c: int, n: int) -> tuple[int, int, int]:
    """Panel (row, column) of integrator r, spin axis c, and the `nrows` _decorate should see (the panel
    is the bottom of its block when row == nrows - 1)."""
    nr, _ = _layout(n)
    row = r % nr
    bottom = row == nr - 1 or r == n - 1
    return row, (r // nr) * len(AXES) + c, row + 1 if bottom else nr + 1


def _figure(integrators, title, ax=None):
    """A headless figure with a panel per integrator and spin axis, axes shared; the axes array it
    returns is indexed [integrator, axis] whatever the layout (``ax``: the caller's, n × 3 in row order)."""
    n = len(integrators)
    if ax is not None:
        fig, axes = C.new_figure(n, len(AXES), ax=ax)
        return fig, axes
    nr, blocks = _layout(n)
    # a fixed grid (_fit): constrained layout over 31 axes costs ~2.5 s of CPU a draw
    fig, grid = C.new_figure(nr, blocks * len(AXES), size=(15.0, 2.0 * nr + 2.6), layout=None)
    fig.suptitle(title, y=1 - 0.04 / fig.get_figheight(), va="top")
    for a in grid.flat[1:]:
        a.sharex(grid[0, 0])
        a.sharey(grid[0, 0])
    axes = np.empty((n, len(AXES)), dtype=object)
    for r in range(n):
        for c in range(len(AXES)):
            row, col, _ = _place(r, c, n)
            axes[r, c] = grid[row, col]
    used = {id(a) for a in axes.flat}
    for a in grid.flat:
        if id(a) not in used:
            a.set_visible(False)
    return fig, axes


#: the fixed grid of a lab figure (inches): left margin (y tick labels and label), top margin (suptitle and
#: panel titles), gaps between panels (titles; hidden tick labels), height of x tick labels and label under the
#: panels, the colour bar's width, its gap to the panels and the room right of it (ticks and label)
GRID_IN = {"left": 0.58, "top": 0.48, "wgap": 0.13, "hgap": 0.32, "xlabels": 0.49, "cbar": 0.28, "cbar_pad": 0.13,
           "cbar_room": 0.70}


def _fit(fig, axes, legend, colorbar=None, label: str = ""):
    """Place the panels on a fixed grid: the legend (lower center) under them, the colour bar (a mappable, with
    its ``label``) right of them; what constrained layout gave, without its cost."""
    w, h = fig.get_size_inches()
    g = GRID_IN
    legend_h = legend.get_window_extent(fig.canvas.get_renderer()).height / fig.dpi
    right = g["cbar_pad"] + g["cbar"] + g["cbar_room"] if colorbar is not None else 0.04
    grid = axes[0, 0].get_subplotspec().get_gridspec()
    nr, nc = grid.get_geometry()
    pw = (w - g["left"] - right - (nc - 1) * g["wgap"]) / nc
    bottom = 0.05 + legend_h + g["xlabels"]
    ph = (h - g["top"] - bottom - (nr - 1) * g["hgap"]) / nr
    fig.subplots_adjust(left=g["left"] / w, right=1 - right / w, bottom=bottom / h, top=1 - g["top"] / h,
                        wspace=g["wgap"] / pw, hspace=g["hgap"] / ph)
    if colorbar is not None:
        span = h - g["top"] - bottom
        cax = fig.add_axes(((w - right + g["cbar_pad"]) / w, (bottom + span / 4) / h, g["cbar"] / w, span / 2 / h),
                           label="<colorbar>")
        cb = fig.colorbar(colorbar, cax=cax, extend="both")
        cb.set_label(label, fontsize=8)


def _metric_value(cell, metric) -> float:
    """What a metric panel colours: the value of a cell that ran (ok or blew up), else NaN."""
    if cell is None or cell["status"] not in ("ok", "blew_up") or cell[metric] is None:
        return math.nan
    return max(cell[metric], FLOOR)


def _status_code(cell, metric, codes) -> float:
    """The flat colour of a cell without a value (diverged, silent NaN, error, no reference), else NaN."""
    if cell is None:
        return codes["error"]
    if cell["status"] in ("ok", "blew_up"):
        if cell[metric] is not None:
            return math.nan
        return codes["blew_up" if cell["status"] == "blew_up" else "no_reference"]
    return codes[cell["status"]]


def _hatch_blowups(ax, cells, integ, axis, wdts, ratios, xe, ye) -> None:
    """Red cross-hatching over the blown-up cells (their value stays visible underneath)."""
    from matplotlib.patches import Rectangle

    blown = _grid(cells, integ, axis, wdts, ratios, lambda x: x is not None and x["status"] == "blew_up")
    for i, j in zip(*np.nonzero(blown)):
        ax.add_patch(Rectangle((xe[j], ye[i]), xe[j + 1] - xe[j], ye[i + 1] - ye[i], fill=False, hatch="xxx",
                               edgecolor=STATUS_COLORS["blew_up"], lw=1.2, zorder=3))


def metric_figure(metric: str, cells, integrators, wdts, ratios, hard_points, ax=None):
    """Heat maps of one metric: rows = integrators, columns = spin axes, one colour bar.

    Returns (file name, matplotlib Figure)."""
    from matplotlib.artist import Artist
    from matplotlib.colors import ListedColormap, LogNorm
    from matplotlib.lines import Line2D
    from matplotlib.patches import Patch

    fname, label, vmax, bound_text = METRICS[metric]
    bound = BOUNDS[metric]
    xe, ye = _edges(wdts), _edges(ratios)
    own = ax is None            # the lab's figure (a fixed grid), not the caller's axes
    fig, axes = _figure(integrators, f"Stability atlas: {label.split('  ')[0]} over {ROTATIONS} rotations "
                                     f"(≥ {MIN_STEPS} steps), torque-free near-axis spin, |ω| = {OMEGA:g} rad/s", ax)
    norm = LogNorm(vmin=FLOOR, vmax=vmax)
    codes = {k: i for i, k in enumerate(STATUS_COLORS)}
    cat = ListedColormap(list(STATUS_COLORS.values()))
    mesh = None
    for r, integ in enumerate(integrators):
        for c, axis in enumerate(AXES):
            ax = axes[r, c]
            val = _grid(cells, integ, axis, wdts, ratios, lambda x: _metric_value(x, metric))
            st = _grid(cells, integ, axis, wdts, ratios, lambda x: _status_code(x, metric, codes))
            mesh = ax.pcolormesh(xe, ye, np.ma.masked_invalid(val), cmap="viridis", norm=norm)
            ax.pcolormesh(xe, ye, np.ma.masked_invalid(st), cmap=cat, vmin=-0.5, vmax=len(codes) - 0.5,
                          edgecolors="face")
            _hatch_blowups(ax, cells, integ, axis, wdts, ratios, xe, ye)
            inside = np.nan_to_num(val, nan=np.inf) <= bound
            _outline(ax, inside, xe, ye, colors="k", linewidths=1.6, zorder=4)
            _outline(ax, inside, xe, ye, colors="w", linewidths=0.6, zorder=4)
            _decorate(ax, integ, axis, *_place(r, c, len(integrators)), xe, ye, hard_points, not own or r + c == 0)
    extra: list[Artist] = [Line2D([], [], color="k", lw=1.6, label="lab hard's bound " + bound_text.format(b=bound)
                    + " holds inside the outline")]
    if any(c["status"] == "ok" and c[metric] is None for c in cells):
        extra.append(Patch(facecolor=STATUS_COLORS["no_reference"], edgecolor="k", lw=0.5,
                           label=STATUS_TEXT["no_reference"]))
    extra += _not_run_handle(cells)
    legend = fig.legend(handles=_legend_handles(extra, hatched=True), loc="outside lower center", ncols=3,
                        fontsize=7.5, frameon=False)
    cbar_label = label + f"  (values < {FLOOR:.0e}, incl. 0, at the bottom)"
    if own:
        _fit(fig, axes, legend, mesh, cbar_label)
    else:
        fig.colorbar(mesh, ax=axes, location="right", shrink=0.5, pad=0.01, extend="both").set_label(cbar_label,
                                                                                                     fontsize=8)
    return fname, fig


def _overview_code(c) -> float:
    if c is None:
        return 5.0
    if c["status"] == "ok":
        within = all(c[k] is not None and c[k] <= b for k, b in BOUNDS.items())
        return 0.0 if within else 1.0
    return float(2 + ("diverged", "blew_up", "silent_nan", "error", "not_run").index(c["status"]))


def status_figure(cells, integrators, wdts, ratios, hard_points, ax=None):
    """Where each integrator stays stable: the status of every cell, within-the-bounds distinguished."""
    from matplotlib.colors import ListedColormap
    from matplotlib.patches import Patch

    xe, ye = _edges(wdts), _edges(ratios)
    own = ax is None
    fig, axes = _figure(integrators, f"Stability atlas: where each integrator stays stable "
                                     f"({ROTATIONS} rotations, ≥ {MIN_STEPS} steps; near-axis spin, perturbation "
                                     f"{PERTURBATION:g}·|ω| on the other two axes)", ax)
    cmap = ListedColormap(list(OVERVIEW_COLORS))
    for r, integ in enumerate(integrators):
        for c, axis in enumerate(AXES):
            ax = axes[r, c]
            ax.pcolormesh(xe, ye, _grid(cells, integ, axis, wdts, ratios, _overview_code), cmap=cmap, vmin=-0.5,
                          vmax=len(OVERVIEW_COLORS) - 0.5, edgecolors="w", linewidth=0.3)
            _decorate(ax, integ, axis, *_place(r, c, len(integrators)), xe, ye, hard_points, not own or r + c == 0)
    bounds = ", ".join(f"{k.replace('_', ' ')} ≤ {b:.0e}" for k, b in BOUNDS.items())
    extra = [Patch(facecolor=OVERVIEW_COLORS[0], edgecolor="k", lw=0.5, label=f"stable, within lab hard's bounds ({bounds})"),
             Patch(facecolor=OVERVIEW_COLORS[1], edgecolor="k", lw=0.5, label="stable (finite, no blow-up), a bound missed")]
    extra += _not_run_handle(cells)
    legend = fig.legend(handles=_legend_handles(extra), loc="outside lower center", ncols=3, fontsize=7.5,
                        frameon=False)
    if own:
        _fit(fig, axes, legend)
    return "atlas_status.png", fig


def make_plots(cells, integrators, wdts, ratios, hard_points, only: str | None = None, ax=None) -> dict:
    """{file name: Figure} of the atlas (only the one named ``only`` when given; ``ax``: its axes,
    integrators × 3 spin axes in row order)."""
    plots: dict = {}
    if only in (None, "atlas_status.png"):
        plots.update([status_figure(cells, integrators, wdts, ratios, hard_points, ax=ax)])
    for metric in METRICS:
        if only in (None, METRICS[metric][0]):
            fname, fig = metric_figure(metric, cells, integrators, wdts, ratios, hard_points, ax=ax)
            plots[fname] = fig
    return plots


def _plot_one(name: str, d: dict, ax=None):
    """One PNG of the atlas, drawn from the result's data (LabResult.figure; ``ax``: its axes)."""
    return make_plots(d["cells"], d["integrators"], d["wdts"], d["ratios"], d["hard_points"], only=name, ax=ax)[name]


# ------------------------------------------------------------------------------------------ run

def _validate(quick, rtol, progress):
    C.flags(quick=quick, progress=progress)
    rtol = V.scalar("rtol", rtol, positive=True)
    if not 1e-14 <= rtol < 1:
        raise V.LavenderInputError("rtol", "must be in [1e-14, 1)", f", got {rtol!r}")
    return rtol


def _summary(cells, integrators) -> dict:
    """Per integrator: how many cells in each status, and the largest |ω|·dt at which every cell is ok."""
    fig = {}
    for integ in integrators:
        mine = [c for c in cells if c["integrator"] == integ]
        for st in STATUSES:
            fig[f"cells_{integ}_{st}"] = sum(c["status"] == st for c in mine)
        wdts = sorted({c["omega_dt"] for c in mine})
        stable = [w for w in wdts if all(c["status"] == "ok" for c in mine
                                         if c["omega_dt"] <= w and c["status"] != "not_run")]
        fig[f"stable_up_to_omega_dt_{integ}"] = max(stable) if stable else 0.0
    return fig


def run(out_dir=C.DEFAULT_OUT, backend: str = "auto", **options) -> C.LabResult:
    """:func:`compute`, then write OUT/atlas/ (results.json, run.json and the four PNGs)."""
    return compute(backend, **options).save(out_dir)


@failed_figure
def compute(backend: str = "auto", quick: bool = True, workers: int | None = None, dask: str | None = None,
            rtol: float = RTOL, progress: bool = False) -> C.LabResult:
    """Compute the atlas and return its LabResult, writing nothing (see the module docstring).

    Parameters
    ----------
    backend : {"auto", "c", "numpy"}
        Backend of the cells of at most 5 000 steps (longer ones use C when it is built).
    quick : bool
        The coarse grid (the Python default, what ``lavendersim lab all`` runs); False = the full grid.
    workers : int or None
        Local worker processes (None = every core, 1 = serial in this process).
    dask : str or None
        Address of an existing Dask scheduler to run the cells on instead (the distributed extra).
    rtol : float
        dopri5's rtol (atol = rtol × 1e-3).
    progress : bool
        A progress bar on stderr (on a terminal only).

    Returns
    -------
    LabResult
        The flat figures and checks, plus ``"grid"``, ``"cells"``, ``"bounds"`` and
        ``"hard_case_points"`` (all also in results.json); run.json holds how it ran (executor, wall time, load).
    """
    backend = C.check_backend(backend)
    rtol = _validate(quick, rtol, progress)
    atol = rtol * (ATOL / RTOL)
    ex = X.resolve(workers=workers, dask=dask, feature="lavendersim lab atlas --dask")
    mode = "quick" if quick else "full"
    wdts, ratios = GRIDS[mode]
    integrators = list(B.INTEGRATORS)
    t0 = time.perf_counter()

    bar = C.progress(total=len(wdts) * len(ratios) * len(AXES), desc="lab atlas", unit="group", enabled=progress)

    def say(msg):           # progress lines: on a terminal only, above the bar
        if not bar.disable:
            bar.write(f"[atlas {time.perf_counter() - t0:6.1f} s] {msg}", file=sys.stderr)

    say(f"{mode} grid: {len(wdts)} |ω|·dt × {len(ratios)} ratios × {len(AXES)} axes × {len(integrators)} integrators "
        f"on {ex.describe()}")
    cells = compute_cells(wdts, ratios, integrators, backend, rtol, atol, ex, bar)
    bar.close()
    wall = time.perf_counter() - t0
    say(f"{len(cells)} cells in {wall:.1f} s")
    result = _result(cells, integrators, mode, backend, rtol, atol, wdts, ratios, quick)
    run_info = {"executor": ex.describe(), "kind": ex.kind, "workers": ex.workers, "dask": ex.address,
                "wall_time_s": wall, "tasks": len(wdts) * len(ratios) * len(AXES), "cells": len(cells),
                "local_cores": X.local_cores(), "loadavg": list(os.getloadavg()) if hasattr(os, "getloadavg") else None}
    result.extra_files["run.json"] = json.dumps(run_info, indent=1) + "\n"
    say(f"done in {time.perf_counter() - t0:.1f} s")
    return result


def _result(cells, integrators, mode, backend, rtol, atol, wdts, ratios, quick) -> C.LabResult:
    """The atlas's LabResult: its checks, the per-integrator summary, the parameters and the nested data."""
    checks, figures = atlas_checks(cells, integrators, rtol)
    figures.update(_summary(cells, integrators))
    hard_points = hard_case_points(wdts)
    params = {
        "mode": mode, "backend": backend, "integrators": ", ".join(integrators),
        "omega": OMEGA, "perturbation": PERTURBATION, "rotations": ROTATIONS, "min_steps": MIN_STEPS,
        "samples": SAMPLES, "dopri5_rtol": rtol, "dopri5_atol": atol, "blowup_growth": BLOWUP,
        "horizon": f"{ROTATIONS} rotations of the initial spin (T = {ROTATIONS}·2π/|ω|), steps rounded up to a "
                   f"multiple of {SAMPLES}, at least {MIN_STEPS} steps",
        "body": "I_b = (1/ratio, (max(1/ratio, 1 − 1/ratio) + 1)/2, 1) kg·m²; q0 = lab hard's Q0",
        "spin": f"omega_b0 = |ω| (e_axis + {PERTURBATION:g} e_j + {PERTURBATION:g} e_k)/|…|, |ω| = {OMEGA:g} rad/s",
        "long_runs_backend": f"c (cells over {H.C_BACKEND_ABOVE} steps)",
    }
    plots = {name: functools.partial(_plot_one, name)
             for name in ("atlas_status.png", *(METRICS[m][0] for m in METRICS))}
    data = {"cells": cells, "integrators": integrators, "wdts": wdts, "ratios": ratios, "hard_points": hard_points}
    figures["cells_silent_nan_or_error"] = sum(c["status"] in ("silent_nan", "error") for c in cells)
    result = C.make_result(NAME, figures, params, checks, plots, data,
                           headline=("cells_silent_nan_or_error", "0 (every cell ok, or a DivergenceError)"))
    result.mode = f"{mode} grid, {len(cells)} cells" + ("; `lab atlas` runs the full grid" if quick else "")
    result["grid"] = {"omega_dt": list(wdts), "ratio": list(ratios), "axis": list(AXES), "integrators": integrators}
    result["bounds"] = {**BOUNDS, "implicit_gyro_energy_gain": ENERGY_GAIN_BOUND, "splitting_L_world_drift_per_step_eps": L_PER_STEP["splitting"],
                        "splitting4_L_world_drift_per_step_eps": L_PER_STEP["splitting4"],
                        "rk4_stability_limit_omega_dt": H.RK4_STABILITY}
    result["hard_case_points"] = hard_points
    result["cells"] = cells
    return result
