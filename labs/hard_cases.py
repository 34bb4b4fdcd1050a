"""Hard cases stay numerically stable: a named catalogue, each case with a bound that is asserted.

    lavendersim lab hard [--out DIR] [--backend c|numpy] [--cases a,b,...] [--integrator NAME]

Every dynamic case ("trial") is run with every integrator in ``lavendersim.backends.INTEGRATORS``
(discovered at run time) and recorded in a survival table: ``pass`` (the case's bounds hold),
``stable`` (finite, but a bound is missed: the worst figure is named), ``blew up`` (finite but
error > 1 with no DivergenceError: dt_range only; since issue 11 none is expected — a run beyond its
integrator's validity bound, or whose energy / |L| doubles on a torque-free body, raises), ``diverged`` (a
DivergenceError naming the step, the body and the cause), ``SILENT NaN`` (a bug: never expected)
or ``error`` (the integrator refused the case). The bounds are *asserted* (checks, exit 1 when one
fails) only for the integrator the issue names for that case (``rk4`` unless stated;
``implicit_gyro`` for the large-step fast spin); ``--integrator NAME`` asserts them with NAME
instead (a failure mode: ``--integrator euler`` fails most of them).

Conventions: quaternions (x, y, z, w), scalar last, q = R_WB; ω_b in the body frame; relative
drift = max_t |x(t) − x(0)| / |x(0)| (lavendersim.oracle.relative_drift); attitude error = the
rotation angle between two orientations (oracle.attitude_error, rad); ω error = max_t
|ω_b(t) − ω_ref(t)| / |ω_b(0)|. The exact torque-free motion (oracle.torque_free, Jacobi
elliptic functions) is the reference; DOP853 at rtol = atol = 1e-13 (oracle.dop853) checks it.
Runs longer than 5 000 steps use the C backend whatever --backend says (the catalogue is about
stability, not about the NumPy backend's speed); the backend of each trial is in results.json.

The catalogue (bounds; the measured figures are in results.json and the survival table):
  intermediate_axis_flips  diag(1,2,3), ω0 = (1e-3, 5, 1e-3), 60 s, RK4 dt = 1e-3: the sign
                           changes of ω_2 (Hermite-interpolated between samples) match the exact
                           ones (4K(m)/λ period) within 1 ms; energy drift ≤ 1e-10.
  fast_major_spin          diag(1,2,3), ω0 = (0.5, 0.5, 50), 10 s: RK4 dt = 1e-3 energy drift ≤ 1e-9;
  fast_major_spin_dt1e-2   implicit_gyro dt = 1e-2 (|ω|·dt = 0.5): E(t) ≤ E(0)(1 + 1e-12) at every
                           step and no divergence (the check fails while implicit_gyro is absent).
  thin_rod, extreme_ratio_symmetric, extreme_ratio_flat
                           I = (0.01, 1, 1.0001), (1e-6, 1, 1), (1e-6, 0.5, 0.5 + 1e-6);
                           ω0 = (5, 1, 0.5), 10 s, RK4 dt = 1e-3: attitude error vs exact ≤ 3e-9 rad,
                           ω error ≤ 1e-9, energy drift ≤ 1e-10, |L_w| drift ≤ 1e-9; the exact
                           reference agrees with DOP853 to ≤ 1e-10 (rad and relative ω).
  near_equal_moments_12, near_equal_moments_23
                           (1, 1 + 1e-9, 2) and (1, 2, 2 + 1e-9), 10 s, RK4 dt = 1e-3: attitude
                           error ≤ 1e-10 rad, ω error ≤ 1e-12, energy drift ≤ 1e-12 vs exact; no
                           spurious motion: |ω − ω_symmetric| ≤ 2 (δ/I) |ω0|² T (the first-order
                           physical effect of the split δ) vs the exactly symmetric body's closed form.
  long_horizon             10^6 RK4 steps (dt = 1e-3, 1000 s, C backend, normalized), diag(1,2,3),
                           ω0 = (1, 0.5, 0.2): | |q| − 1 | ≤ 1e-12 at every sample, energy drift
                           ≤ 1e-10, |L_w| drift ≤ 1e-9, attitude error vs exact ≤ 1e-8 rad.
  dt_range                 dt = 1e-7 … 1e-1 (decades), diag(1,2,3), ω0 = (1, 0.5, 0.2) and
                           (0.5, 0.5, 50), T = max(0.1 s, 10 dt), RK4: error at T (attitude, rad;
                           ω, relative) ≤ 1e-12 + 2 n (|ω| dt)^5 / 120 (the rounding floor plus
                           twice RK4's leading rotation-phase error over n steps); where
                           |ω| dt > 2√2 (RK4's stability limit) a DivergenceError naming the step,
                           the body and |omega|*dt is required instead — never a silent NaN.
  near_antipodal_quaternions
                           R(q) = R(−q) exactly; attitude_error(q, −q) ≤ 1e-15, (q, −q + ε) ≤ 4|ε|;
                           matrix_to_quat and quat_to_axis_angle ↔ axis_angle_to_quat reproduce
                           the rotation to ≤ 1e-15 rad near w = 0 and w = ±1 (no NaN); stepping from
                           q and −q (with a world torque) gives q_a = −q_b, ω_a = ω_b to ≤ 1e-15.
  euler_at_gimbal_lock     euler_xyz_to_quat ∘ quat_to_euler_xyz at pitch = ±90°, ±90° ± 1e-9,
                           ±1e-12, ±1e-6 (random roll, yaw): the rotation is reproduced to
                           ≤ 1e-9 rad, no NaN.
  body_vs_world_kinematics quat_derivative_body(q, ω_b) = quat_derivative_world(q, R(q) ω_b) to
                           ≤ 1e-15 · max(1, |ω|) on random inputs.
  divergence_report        explicit Euler, dt = 0.1, a calm body and a spinner (|ω|·dt = 5): with
                           Sim's default on_bound="raise" the first step is refused naming the
                           validity bound; opted in (on_bound="warn"), one good step, then run(1000)
                           raises DivergenceError (growth check, before infinity) naming the step,
                           the spinner and |omega|*dt; the sim's state, step count and time are
                           unchanged; never a silent NaN.
"""
from __future__ import annotations

import functools
import math
import time
import warnings
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import numpy as np

import lavendersim as lv
from lavendersim import backends
from lavendersim import oracle as R
from lavendersim import validate as V
from lavendersim.errors import DivergenceError, ValidityBoundWarning
from lavendersim.kernels import K
from lavendersim import figures as F

from . import common as C
from .diverged import failed_figure

NAME = "hard"
TITLE = "hard cases stay numerically stable: a named catalogue with asserted bounds; which integrators survive each"

C_BACKEND_ABOVE = 5_000           # runs longer than this many steps use the C backend
Q0 = K.quat_normalize([0.1, 0.2, 0.3, 0.9])
IDENTITY = np.array([0.0, 0.0, 0.0, 1.0])

CASES = ("intermediate_axis_flips", "fast_major_spin", "thin_rod", "extreme_inertia_ratios", "near_equal_moments",
         "long_horizon", "dt_range", "near_antipodal_quaternions", "euler_at_gimbal_lock",
         "body_vs_world_kinematics", "divergence_report")


# ------------------------------------------------------------------------------------------ runs


@dataclass
class Run:
    """One simulation: t (T,), x (T, nb, 13) on success; error (DivergenceError or other) otherwise."""
    integrator: str
    backend: str
    t: np.ndarray = field(default_factory=lambda: np.empty(0))
    x: np.ndarray = field(default_factory=lambda: np.empty((0, 0, C.LY.STATE_SIZE)))
    error: Exception | None = None
    wall: float = 0.0

    @property
    def silent_nan(self) -> bool:
        return self.error is None and not bool(np.all(np.isfinite(self.x)))


ADAPTIVE_TOL = {"rtol": 1e-12, "atol": 1e-12}   # adaptive integrators run at these tolerances here


def adaptive_options(integrator: str) -> dict:
    return dict(ADAPTIVE_TOL) if integrator in getattr(backends, "ADAPTIVE", ()) else {}


def fast_backend(backend: str) -> str:
    """The C backend for long runs when it is available, else `backend` (NumPy: slower, same results)."""
    return "c" if backends.c_unavailable() is None else backend


def simulate(bodies, dt, n, every, integrator, backend, effects=(), normalize=True) -> Run:
    """Build a scene of `bodies` [(name, I_b, ω_b0, q0)] and record n steps, sampling every `every`."""
    scene = lv.Scene()
    for name, I_b, w0, q0 in bodies:
        scene.add_body(lv.Body(name, 1.0, I_b, omega_b=w0, q=q0))
    for name, params in effects:
        scene.add_effect(name, **params)
    if n > C_BACKEND_ABOVE:
        backend = fast_backend(backend)
    run = Run(integrator, backend)
    t0 = time.perf_counter()
    try:
        sim = lv.Sim(scene, dt=dt, integrator=integrator, backend=backend, normalize=normalize,
                     **adaptive_options(integrator))
        tr = sim.record(n, every)
        run.t, run.x = tr.t, tr.x
    except Exception as exc:  # DivergenceError, or an integrator that refuses the case
        run.error = exc
    run.wall = time.perf_counter() - t0
    return run


def standard_metrics(I_b, w0, x, ref=None) -> dict:
    """Drifts of E, L_w and |q| of one body's samples x (T, 13) (printed kernels); errors against ``ref``."""
    E, L = C.energy_momentum(np.asarray(I_b, float), x)
    m = {"energy_drift": R.relative_drift(E), "energy_gain": float(np.max(E / E[0] - 1.0)),
         "momentum_drift": R.relative_drift(L), "qnorm_deviation": float(np.max(np.abs(np.linalg.norm(x[:, C.Q], axis=1) - 1.0)))}
    if ref is not None:
        m["attitude_error"] = float(np.max(R.attitude_error(ref.q, x[:, C.Q])))
        m["omega_error"] = float(np.max(np.linalg.norm(ref.omega_b - x[:, C.OMEGA_B], axis=1)) / np.linalg.norm(w0))
    return m


def flip_times(t, w, I_b, axis: int) -> np.ndarray:
    """Zero crossings of ω_axis: each bracketing sample pair refined by the cubic Hermite interpolant
    with the rates from Euler's equations (torque-free)."""
    s = w[:, axis]
    idx = np.flatnonzero(np.signbit(s[1:]) != np.signbit(s[:-1]))
    wdot = K.euler_equations(np.broadcast_to(I_b, w.shape), w, np.zeros_like(w))[:, axis]
    out = []
    for i in idx:
        h, f0, f1, d0, d1 = t[i + 1] - t[i], s[i], s[i + 1], wdot[i] * (t[i + 1] - t[i]), wdot[i + 1] * (t[i + 1] - t[i])
        coeffs = [2 * f0 + d0 - 2 * f1 + d1, -3 * f0 - 2 * d0 + 3 * f1 - d1, d0, f0]
        roots = np.roots(coeffs)
        roots = roots[np.abs(roots.imag) < 1e-9].real
        roots = roots[(roots >= -1e-9) & (roots <= 1 + 1e-9)]
        lin = f0 / (f0 - f1) if f0 != f1 else 0.5
        r = roots[np.argmin(np.abs(roots - lin))] if roots.size else lin
        out.append(t[i] + r * h)
    return np.array(out)


# ------------------------------------------------------------------------------------------ the table


@dataclass
class Trial:
    """A dynamic scenario run for every integrator; bounds asserted for `integrator`."""
    name: str
    case: str
    I_b: tuple
    w0: tuple
    q0: np.ndarray
    dt: float
    T: float
    every: int
    integrator: str
    bounds: dict                       # metric -> (limit, note)
    reference: bool = True             # compare with oracle.torque_free at the samples
    extra: Callable[..., dict] | None = None   # callable(trial, run, ref) -> dict of further metrics
    description: str = ""
    dop853: bool = False               # also check the exact reference against DOP853

    @property
    def n(self) -> int:
        return int(round(self.T / self.dt))


@dataclass
class CaseOut:
    figures: dict = field(default_factory=dict)
    params: dict = field(default_factory=dict)
    checks: list = field(default_factory=list)
    survival: dict = field(default_factory=dict)      # row label -> {integrator: status}
    plot: dict = field(default_factory=dict)          # data for the summary figure


def _status_of(run: Run, metrics: dict, bounds: dict) -> str:
    if run.error is not None:
        if isinstance(run.error, DivergenceError):
            return f"diverged at step {run.error.step}"
        return f"error: {type(run.error).__name__}: {str(run.error)[:80]}"
    if run.silent_nan:
        return "SILENT NaN"
    worst, ratio = None, 0.0
    for k, (limit, _) in bounds.items():
        v = metrics.get(k, math.nan)
        r = v / limit if limit > 0 else (0.0 if v <= 0 else math.inf)
        if not math.isfinite(v) or not v <= limit:
            if worst is None or not r <= ratio:
                worst, ratio = k, r
    if worst is None:
        return "pass"
    return f"stable ({worst} = {metrics[worst]:.2g} > {bounds[worst][0]:.0e})"


def run_trial(trial: Trial, integrators: list[str], backend: str, assert_with: str | None) -> CaseOut:
    out = CaseOut()
    named = assert_with or trial.integrator
    n = trial.n
    every = trial.every
    t_samples = np.arange(0, n + 1, every) * trial.dt
    ref = R.torque_free(trial.I_b, trial.w0, trial.q0, t_samples) if trial.reference else None
    row, runs = {}, {}
    long_on_numpy = n > C_BACKEND_ABOVE and fast_backend(backend) != "c"
    for integ in integrators:
        if long_on_numpy and integ != named:
            # without the C backend a long horizon runs only the asserted integrator (NumPy: ~100 µs a step)
            row[integ] = f"not run: {n} steps need the C backend (unavailable here)"
            continue
        run = simulate([("body", trial.I_b, trial.w0, trial.q0)], trial.dt, n, every, integ, backend)
        metrics: dict = {}
        if run.error is None and not run.silent_nan:
            metrics = standard_metrics(trial.I_b, trial.w0, run.x[:, 0], ref)
            if trial.extra is not None:
                metrics.update(trial.extra(trial, run, ref))
        row[integ] = _status_of(run, metrics, trial.bounds)
        runs[integ] = (run, metrics)
    out.survival[trial.name] = row
    p = trial.name
    out.params[f"{p}_setup"] = (f"I_b = {list(trial.I_b)} kg·m², omega_b0 = {list(trial.w0)} rad/s, "
                                f"q0 = {np.round(trial.q0, 6).tolist()}, dt = {trial.dt:g} s, T = {trial.T:g} s "
                                f"({n} steps), asserted with {named}, backend "
                                f"{fast_backend(backend) if n > C_BACKEND_ABOVE else backend}" + (f"; {trial.description}" if trial.description else ""))
    if named not in integrators:
        out.checks.append(C.holds(f"{p}_integrator_available", False,
                                  f"{named!r} is not in lavendersim.backends.INTEGRATORS "
                                  f"({', '.join(integrators)}): the bounds of {p} cannot be checked"))
        return out
    run, metrics = runs[named]
    if run.error is not None or run.silent_nan:
        why = "a silent NaN" if run.silent_nan else f"{type(run.error).__name__}: {run.error}"
        out.checks.append(C.holds(f"{p}_runs", False, f"{named}: {why}"))
        return out
    for k, v in metrics.items():
        if isinstance(v, (float, int, np.floating)):
            out.figures[f"{p}_{k}"] = float(v)
    for k, (limit, note) in trial.bounds.items():
        out.checks.append(C.at_most(f"{p}_{k}", metrics[k], limit, f"{named}; {note}"))
    out.plot[p] = (run, ref)
    return out


# ------------------------------------------------------------------------------------------ cases


def _flips_extra(trial, run, ref):
    tr = ref.intermediate_zero_crossings(trial.T)
    ts = flip_times(run.t, run.x[:, 0, C.OMEGA_B], np.asarray(trial.I_b, float), ref.intermediate_axis)
    if len(ts) != len(tr):
        err = math.inf
    else:
        err = float(np.max(np.abs(ts - tr))) if len(tr) else math.inf
    period = 2 * float(np.mean(np.diff(ts))) if len(ts) > 1 else math.nan
    return {"flip_time_error": err, "flip_count": float(len(ts)), "flip_count_exact": float(len(tr)),
            "period_from_flips": period, "period_exact": float(ref.period),
            "period_error": abs(period - ref.period) if math.isfinite(period) else math.inf}


def _with_dop853(ctx, trial: Trial) -> CaseOut:
    out = ctx.trial(trial)
    t = np.arange(0, trial.n + 1, trial.every) * trial.dt
    ex = R.torque_free(trial.I_b, trial.w0, trial.q0, t)
    dop = R.dop853(trial.I_b, trial.w0, trial.q0, t)
    att = float(np.max(R.attitude_error(ex.q, dop.q)))
    om = float(np.max(np.linalg.norm(ex.omega_b - dop.omega_b, axis=1)) / np.linalg.norm(trial.w0))
    out.figures[f"{trial.name}_reference_vs_dop853_attitude"] = att
    out.figures[f"{trial.name}_reference_vs_dop853_omega"] = om
    out.checks.append(C.at_most(f"{trial.name}_reference_vs_dop853", max(att, om), 1e-10,
                                "exact torque-free solution vs DOP853 (rtol = atol = 1e-13): rad and relative ω"))
    return out


def _symmetric_extra(sym_I):
    """ω's departure from the exactly symmetric body, divided by the first-order size of the physical
    effect of the split δ (relative): (δ/I) |ω0|² t. The exact motion's own departure is reported too."""
    def extra(trial, run, ref):
        sym = R.torque_free(sym_I, trial.w0, trial.q0, run.t)
        split = float(np.max(np.abs(np.asarray(trial.I_b) - np.asarray(sym_I)) / np.asarray(sym_I)))
        scale = split * float(np.dot(trial.w0, trial.w0)) * trial.T
        dev = float(np.max(np.linalg.norm(sym.omega_b - run.x[:, 0, C.OMEGA_B], axis=1)))
        exact = float(np.max(np.linalg.norm(sym.omega_b - ref.omega_b, axis=1)))
        return {"omega_vs_symmetric": dev, "omega_vs_symmetric_exact": exact,
                "omega_vs_symmetric_scaled": dev / scale}
    return extra


ROD_BOUNDS = {"attitude_error": (3e-9, "max attitude error vs the exact solution, rad"),
              "omega_error": (1e-9, "max |ω − ω_exact| / |ω0|"),
              "energy_drift": (1e-10, "relative kinetic-energy drift"),
              "momentum_drift": (1e-9, "relative world angular-momentum drift")}
NEAR_EQUAL_BOUNDS = {"attitude_error": (1e-10, "max attitude error vs the exact solution, rad"),
                     "omega_error": (1e-12, "max |ω − ω_exact| / |ω0|"),
                     "energy_drift": (1e-12, "relative kinetic-energy drift"),
                     "omega_vs_symmetric_scaled": (2.0, "max |ω − ω_symmetric| / ((δ/I) |ω0|² T): no motion beyond "
                                                        "the first-order physical effect of the 1e-9 split")}
DIAG123 = (1.0, 2.0, 3.0)
# The catalogue's dynamic trials, declared once: (name, case, I_b, ω0, q0, dt, T, sample every, the integrator whose
# bounds are asserted, bounds, ...); lab atlas marks where each sits in its map
TRIALS = (
    Trial("intermediate_axis_flips", "intermediate_axis_flips", DIAG123, (1e-3, 5.0, 1e-3), IDENTITY, 1e-3, 60.0, 10,
          "rk4", {"flip_time_error": (1e-3, "max |t_flip − t_exact| (s), sign changes of ω_2 vs 4K(m)/λ"),
                  "energy_drift": (1e-10, "relative kinetic-energy drift")},
          extra=_flips_extra, description="flip times from the samples every 10 ms, Hermite-refined"),
    Trial("fast_major_spin", "fast_major_spin", DIAG123, (0.5, 0.5, 50.0), IDENTITY, 1e-3, 10.0, 10, "rk4",
          {"energy_drift": (1e-9, "relative kinetic-energy drift over 10 s (|ω|·dt = 0.05)")}),
    Trial("fast_major_spin_dt1e-2", "fast_major_spin", DIAG123, (0.5, 0.5, 50.0), IDENTITY, 1e-2, 10.0, 1,
          "implicit_gyro", {"energy_gain": (1e-12, "max_t E(t)/E(0) − 1 at every step: never gains energy "
                                                   "(|ω|·dt = 0.5); a divergence fails the case")}, reference=False),
    Trial("thin_rod", "thin_rod", (0.01, 1.0, 1.0001), (5.0, 1.0, 0.5), Q0, 1e-3, 10.0, 100, "rk4", ROD_BOUNDS,
          dop853=True),
    Trial("extreme_ratio_symmetric", "extreme_inertia_ratios", (1e-6, 1.0, 1.0), (5.0, 1.0, 0.5), Q0, 1e-3, 10.0, 100,
          "rk4", ROD_BOUNDS, description="I_min/I_max = 1e-6", dop853=True),
    Trial("extreme_ratio_flat", "extreme_inertia_ratios", (1e-6, 0.5, 0.5 + 1e-6), (5.0, 1.0, 0.5), Q0, 1e-3, 10.0,
          100, "rk4", ROD_BOUNDS, description="I_min/I_max = 2e-6 at the triangle-inequality edge", dop853=True),
    Trial("near_equal_moments_12", "near_equal_moments", (1.0, 1.0 + 1e-9, 2.0), (1.0, 0.5, 0.2), Q0, 1e-3, 10.0, 100,
          "rk4", NEAR_EQUAL_BOUNDS, extra=_symmetric_extra((1.0, 1.0, 2.0))),
    Trial("near_equal_moments_23", "near_equal_moments", (1.0, 2.0, 2.0 + 1e-9), (0.1, 2.0, 0.1), Q0, 1e-3, 10.0, 100,
          "rk4", NEAR_EQUAL_BOUNDS, extra=_symmetric_extra((1.0, 2.0, 2.0))),
    Trial("long_horizon", "long_horizon", DIAG123, (1.0, 0.5, 0.2), Q0, 1e-3, 1000.0, 1000, "rk4",
          {"qnorm_deviation": (1e-12, "max_t | |q| − 1 | over 10^6 steps (normalized)"),
           "energy_drift": (1e-10, "relative kinetic-energy drift"),
           "momentum_drift": (1e-9, "relative world angular-momentum drift"),
           "attitude_error": (1e-8, "max attitude error vs the exact solution, rad")}, description="10^6 steps"),
)


def case_trials(ctx, case: str) -> CaseOut:
    """A dynamic case of the catalogue: its TRIALS, each run with every integrator."""
    out = merge(*(_with_dop853(ctx, t) if t.dop853 else ctx.trial(t) for t in TRIALS if t.case == case))
    if case == "intermediate_axis_flips":
        t = TRIALS[0]
        out.figures["intermediate_axis_flips_period_4K_over_lambda"] = float(R.torque_free_period(t.I_b, t.w0))
    return out


DT_RANGE = (1e-7, 1e-6, 1e-5, 1e-4, 1e-3, 1e-2, 1e-1)
DT_BODIES = {"moderate": (1.0, 0.5, 0.2), "fast": (0.5, 0.5, 50.0)}
RK4_STABILITY = 2 * math.sqrt(2)


def dt_bound(w0, dt, n) -> float:
    return 1e-12 + 2 * n * (np.linalg.norm(w0) * dt) ** 5 / 120


def case_dt_range(ctx) -> CaseOut:
    out = CaseOut()
    I_b = (1.0, 2.0, 3.0)
    named = ctx.assert_with or "rk4"
    plot = {}
    for bname, w0 in DT_BODIES.items():
        for integ in ctx.integrators:
            plot_rows = []
            statuses = []
            for dt in DT_RANGE:
                T = max(0.1, 10 * dt)
                n = int(round(T / dt))
                run = simulate([("body", I_b, w0, Q0)], dt, n, n, integ, ctx.backend)
                wdt = float(np.linalg.norm(w0) * dt)
                bound = dt_bound(w0, dt, n)
                must_diverge = wdt > RK4_STABILITY
                label = f"dt_range_{bname}_dt{dt:.0e}"
                if run.error is not None:
                    div = isinstance(run.error, DivergenceError)
                    named_ok = (isinstance(run.error, DivergenceError) and "|omega|*dt" in str(run.error)
                                and run.error.body_name == "body")
                    statuses.append(f"{dt:.0e}: diverged" if div else f"{dt:.0e}: error")
                    err = math.nan
                    ok = named_ok and must_diverge
                    how = f"raised {type(run.error).__name__}: {run.error}"
                elif run.silent_nan:
                    statuses.append(f"{dt:.0e}: SILENT NaN")
                    err, ok, how = math.nan, False, "a silent NaN"
                else:
                    ex = R.torque_free(I_b, w0, Q0, [n * dt])
                    x = run.x[-1, 0]
                    err = max(float(R.attitude_error(ex.q[0], x[C.Q])),
                              float(np.linalg.norm(ex.omega_b[0] - x[C.OMEGA_B]) / np.linalg.norm(w0)))
                    ok = err <= bound and not must_diverge
                    how = f"error {err:.3g} (bound {bound:.3g})"
                    statuses.append(f"{dt:.0e}: " + ("ok" if err <= bound else
                                                         (f"err {err:.0e}" if err <= 1.0 else f"BLEW UP, err {err:.0e}, no DivergenceError")))
                plot_rows.append((dt, err, bound))
                if integ == named:
                    out.figures[f"{label}_error"] = err if math.isfinite(err) else (
                        f"not computed: the run {'raised ' + type(run.error).__name__ if run.error else 'went NaN'}"
                        + (f" at step {run.error.step}" if isinstance(run.error, DivergenceError) else ""))
                    out.figures[f"{label}_omega_dt"] = wdt
                    expect = ("a DivergenceError naming the step, the body and |omega|*dt" if must_diverge
                              else f"error at T ≤ {bound:.3g}")
                    out.checks.append(C.holds(f"{label}_outcome", ok, f"{named}, T = {T:g} s, |ω|·dt = {wdt:.3g}: "
                                              f"expected {expect}; got {how}"))
            plot[(bname, integ)] = plot_rows
            nan = any("SILENT" in s for s in statuses)
            bad = [s for s in statuses if not s.endswith(("ok", "diverged"))]
            blew = any("BLEW UP" in s for s in statuses)
            out.survival.setdefault(f"dt_range_{bname}", {})[integ] = (
                "SILENT NaN" if nan else ("pass" if not bad else ("blew up" if blew else "stable") + " ("
                                          + "; ".join(statuses) + ")"))
    out.params["dt_range_setup"] = (f"I_b = {list(I_b)}, q0 = {np.round(Q0, 6).tolist()}, bodies "
                                    f"{ {k: list(v) for k, v in DT_BODIES.items()} }, dt = {list(DT_RANGE)}, "
                                    "T = max(0.1 s, 10 dt); bound 1e-12 + 2 n (|ω| dt)^5 / 120; "
                                    f"|ω| dt > 2√2 must diverge; asserted with {named}")
    out.plot["dt_range"] = (plot, named)
    return out


def _rand_q(rng, n):
    return K.quat_normalize(rng.normal(size=(n, 4)))


def case_near_antipodal_quaternions(ctx) -> CaseOut:
    out = CaseOut()
    rng = np.random.default_rng(4)
    q = _rand_q(rng, 2000)
    eps = 1e-12 * rng.normal(size=q.shape)
    f = out.figures
    f["antipodal_matrix_difference"] = float(np.max(np.abs(K.quat_to_matrix(q) - K.quat_to_matrix(-q))))
    f["antipodal_attitude_error"] = float(np.max(R.attitude_error(q, -q)))
    f["antipodal_eps_attitude_ratio"] = float(np.max(R.attitude_error(q, -q + eps) / np.linalg.norm(eps, axis=1)))
    families = {
        "w0": np.c_[rng.normal(size=(500, 3)), np.zeros(500)],
        "w_tiny": np.c_[rng.normal(size=(500, 3)), 1e-9 * rng.normal(size=500)],
        "w_pm1": np.c_[1e-9 * rng.normal(size=(500, 3)), rng.choice([-1.0, 1.0], 500)],
        "w_pm1_exact": np.c_[np.zeros((500, 3)), rng.choice([-1.0, 1.0], 500)],
        "w_pm1_1e-17": np.c_[1e-17 * rng.normal(size=(500, 3)), rng.choice([-1.0, 1.0], 500)],
    }
    m2q_worst, aa_worst, finite = 0.0, 0.0, True
    for name, qq in families.items():
        qq = K.quat_normalize(qq)
        q2 = K.matrix_to_quat(K.quat_to_matrix(qq))
        ax, ang = K.quat_to_axis_angle(qq)
        q3 = K.axis_angle_to_quat(ax, ang)
        finite &= bool(np.all(np.isfinite(q2)) and np.all(np.isfinite(q3)) and np.all(np.isfinite(ang)))
        e2, e3 = float(np.max(R.attitude_error(qq, q2))), float(np.max(R.attitude_error(qq, q3)))
        f[f"antipodal_matrix_to_quat_{name}"] = e2
        f[f"antipodal_axis_angle_{name}"] = e3
        m2q_worst, aa_worst = max(m2q_worst, e2), max(aa_worst, e3)
    out.checks += C.checks(
        ("antipodal_same_matrix", f["antipodal_matrix_difference"], "<=", 0.0, "max |R(q) − R(−q)|, exactly 0"),
        ("antipodal_attitude_error", f["antipodal_attitude_error"], "<=", 1e-15, "attitude_error(q, −q), rad"),
        ("antipodal_eps_attitude", f["antipodal_eps_attitude_ratio"], "<=", 4.0,
         "attitude_error(q, −q + ε) / |ε| for |ε| ~ 1e-12"),
        ("antipodal_matrix_to_quat", m2q_worst, "<=", 1e-15, "matrix_to_quat(R(q)) vs q near w = 0 and w = ±1, rad"),
        ("antipodal_axis_angle", aa_worst, "<=", 1e-15,
         "axis_angle_to_quat(quat_to_axis_angle(q)) vs q near w = 0 and w = ±1, rad"),
        ("antipodal_kernels_finite", finite, "holds", None, "no NaN from matrix_to_quat / quat_to_axis_angle near "
                                                            "w = 0, ±1"),
    )
    return _antipodal_stepping(ctx, out)


def _antipodal_stepping(ctx, out: CaseOut) -> CaseOut:
    """Stepping from q and −q, with a world torque so R(q) enters the dynamics: q_a = −q_b, ω_a = ω_b."""
    f, named = out.figures, ctx.assert_with or "rk4"
    I_b, w0 = (1.0, 2.0, 3.0), (1.0, 0.5, 0.2)
    torque = ("applied_torque", {"torque_w": [0.1, -0.2, 0.05]})
    row = {}
    for integ in ctx.integrators:
        ra = simulate([("body", I_b, w0, Q0)], 1e-3, 2000, 100, integ, ctx.backend, [torque])
        rb = simulate([("body", I_b, w0, -Q0)], 1e-3, 2000, 100, integ, ctx.backend, [torque])
        if ra.error is not None or rb.error is not None:
            e = ra.error or rb.error
            row[integ] = f"diverged at step {e.step}" if isinstance(e, DivergenceError) else f"error: {type(e).__name__}"
            d = math.inf
        elif ra.silent_nan or rb.silent_nan:
            row[integ], d = "SILENT NaN", math.inf
        else:
            d = float(max(np.max(np.abs(ra.x[:, 0, C.Q] + rb.x[:, 0, C.Q])),
                          np.max(np.abs(ra.x[:, 0, C.OMEGA_B] - rb.x[:, 0, C.OMEGA_B]))))
            row[integ] = "pass" if d <= 1e-15 else f"stable (sign mismatch {d:.2g})"
        if integ == named:
            f["antipodal_trajectory_sign_mismatch"] = d
            out.checks.append(C.at_most("antipodal_trajectories", d, 1e-15,
                                        f"{named}, 2 s with a world torque: max |q_a + q_b|, |ω_a − ω_b|"))
    out.survival["near_antipodal_stepping"] = row
    out.params["near_antipodal_setup"] = ("2000 random unit q, |ε| ~ 1e-12; 500 q per family near w = 0 and w = ±1; "
                                          f"stepping: I_b = {list(I_b)}, ω0 = {list(w0)}, torque_w = [0.1, -0.2, 0.05], "
                                          "dt = 1e-3, 2 s")
    return out


GIMBAL_OFFSETS = (0.0, 1e-9, -1e-9, 1e-12, -1e-12, 1e-6, -1e-6)


def gimbal_round_trip_errors(n: int = 200, seed: int = 5) -> dict:
    """{(pitch0, offset): (max attitude error rad, all finite)} of euler_xyz_to_quat ∘ quat_to_euler_xyz."""
    rng = np.random.default_rng(seed)
    res = {}
    for p0 in (math.pi / 2, -math.pi / 2):
        for d in GIMBAL_OFFSETS:
            roll, yaw = rng.uniform(-math.pi, math.pi, (2, n))
            q = K.euler_xyz_to_quat(roll, np.full(n, p0 + d), yaw)
            rpy = K.quat_to_euler_xyz(q)
            q2 = K.euler_xyz_to_quat(rpy[:, 0], rpy[:, 1], rpy[:, 2])
            res[(p0, d)] = (float(np.max(R.attitude_error(q, q2))), bool(np.all(np.isfinite(rpy))))
    return res


def case_euler_at_gimbal_lock(ctx) -> CaseOut:
    out = CaseOut()
    res = gimbal_round_trip_errors()
    worst = 0.0
    for (p0, d), (err, finite) in res.items():
        out.figures[f"gimbal_pitch_{'+' if p0 > 0 else '-'}90deg{d:+.0e}_error"] = err
        worst = max(worst, err if finite else math.inf)
    out.figures["gimbal_worst_error"] = worst
    out.checks.append(C.at_most("gimbal_round_trip", worst, 1e-9,
                                "max attitude error (rad) of euler_xyz_to_quat(quat_to_euler_xyz(q)) at pitch ±90° "
                                "and ±90° ± {1e-12, 1e-9, 1e-6}, 200 random roll/yaw each; NaN counts as failure"))
    out.checks.append(C.holds("gimbal_finite", all(fin for _, fin in res.values()), "no NaN in the Euler angles"))
    return out


def case_body_vs_world_kinematics(ctx) -> CaseOut:
    out = CaseOut()
    rng = np.random.default_rng(6)
    q = _rand_q(rng, 5000)
    w = rng.normal(size=(5000, 3)) * rng.choice([1e-3, 1.0, 1e3], size=(5000, 1))
    a = K.quat_derivative_body(q, w)
    b = K.quat_derivative_world(q, np.einsum("nij,nj->ni", K.quat_to_matrix(q), w))
    c = K.quat_derivative_world(q, K.quat_rotate(q, w))
    scale = np.maximum(1.0, np.linalg.norm(w, axis=1))
    rel = float(np.max(np.max(np.abs(a - b), axis=1) / scale))
    rel_rot = float(np.max(np.max(np.abs(a - c), axis=1) / scale))
    out.figures["body_vs_world_max_difference_scaled"] = rel
    out.figures["body_vs_world_quat_rotate_scaled"] = rel_rot
    out.checks.append(C.at_most("body_vs_world_kinematics", max(rel, rel_rot), 1e-15,
                                "max |q̇_body(q, ω_b) − q̇_world(q, R ω_b)| / max(1, |ω|), 5000 random q, ω (|ω| 1e-3 … 1e3)"))
    return out


DIVERGENCE_STEPS = 1000   # the calm body survives these under explicit Euler at dt = 0.1 (it diverges after ~4700)


DIV_I, DIV_CALM, DIV_SPIN, DIV_DT = (1.0, 2.0, 3.0), (0.1, 0.2, 0.3), (0.5, 0.5, 50.0), 0.1


def divergence_trial(integrator: str, backend: str, steps: int = DIVERGENCE_STEPS, on_bound: str = "warn") -> dict:
    """A calm body and a spinner (|ω|·dt = 5) at dt = 0.1: one good step, then run(steps).

    |ω|·dt = 5 is beyond every fixed-step integrator's validity bound: with on_bound="raise" (Sim's
    default) the first step is refused; with "warn" (the default here: the trial shows the divergence
    found during a run) the growth check or the non-finite check stops it before infinity.
    Returns {"error": DivergenceError | other exception | None, "unchanged": bool, "finite": bool, "sim": Sim}."""
    scene = lv.Scene()
    scene.add_body(lv.Body("calm", 1.0, DIV_I, omega_b=DIV_CALM))
    scene.add_body(lv.Body("spinner", 1.0, DIV_I, omega_b=DIV_SPIN, q=Q0))
    out: dict[str, Any] = {"error": None, "unchanged": False, "finite": False, "sim": None}
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", ValidityBoundWarning)
            sim = lv.Sim(scene, dt=DIV_DT, integrator=integrator, backend=backend, on_bound=on_bound,
                         **adaptive_options(integrator))
            out["sim"] = sim
            x0, steps0, t0 = sim.x.copy(), sim.steps, sim.t
            sim.run(1)
            x0, steps0, t0 = sim.x.copy(), sim.steps, sim.t
            sim.run(steps)
    except Exception as exc:  # DivergenceError, or an integrator that refuses: recorded, not hidden
        out["error"] = exc
        if out["sim"] is not None and isinstance(exc, DivergenceError):
            out["unchanged"] = bool(np.array_equal(sim.x, x0) and sim.steps == steps0 and sim.t == t0)
    if out["sim"] is not None:
        out["finite"] = bool(np.all(np.isfinite(out["sim"].x)))
    return out


def message_names_all(err: DivergenceError) -> bool:
    msg = str(err)
    return (f"step {err.step}" in msg and "body 1 ('spinner')" in msg and "|omega|*dt" in msg
            and err.body == 1 and err.body_name == "spinner" and err.step >= 1)


def case_divergence_report(ctx) -> CaseOut:
    out = CaseOut()
    named = ctx.assert_with or "euler"
    row = {}
    for integ in ctx.integrators:
        # an adaptive integrator survives by taking ~10^5 substeps here: on the C backend whatever --backend says
        slow = integ != named and integ in getattr(backends, "ADAPTIVE", ())
        r = divergence_trial(integ, fast_backend(ctx.backend) if slow else ctx.backend)
        err = r["error"]
        if err is None:
            row[integ] = "survived (finite)" if r["finite"] else "SILENT NaN"
            if integ == named:
                out.checks.append(C.holds("divergence_raised", False, f"{named} at |ω|·dt = 5 did not raise"
                                          + ("" if r["finite"] else " and left a silent NaN")))
            continue
        if not isinstance(err, DivergenceError):
            row[integ] = f"error: {type(err).__name__}"
            if integ == named:
                out.checks.append(C.holds("divergence_raised", False, f"{named}: {type(err).__name__}: {err}"))
            continue
        names = message_names_all(err)
        row[integ] = (f"raised at step {err.step}" + ("" if names else ", message incomplete")
                      + ("" if r["unchanged"] else ", STATE CHANGED"))
        if integ == named:
            out.figures["divergence_step"] = int(err.step)
            out.figures["divergence_message"] = str(err)
            out.checks += [
                C.holds("divergence_message_names_step_body_cause", names,
                        f"{named}: message names the step, body 1 'spinner' and |omega|*dt: {str(err)!r}"),
                C.holds("divergence_state_unchanged", r["unchanged"], "sim.x, sim.steps and sim.t are those before run()"),
            ]
            other = "numpy" if ctx.backend == "c" else "c"
            if other == "c" and backends.c_unavailable():
                out.params["divergence_other_backend"] = "not compared: the C backend is unavailable here"
                continue
            e2 = divergence_trial(integ, other)["error"]
            same = isinstance(e2, DivergenceError) and (e2.step, e2.body) == (err.step, err.body)
            out.figures[f"divergence_message_{other}"] = str(e2)
            out.checks.append(
                C.holds("divergence_same_on_both_backends", same,
                        f"{ctx.backend}: step {err.step}, body {err.body}; {other}: "
                        + (f"step {e2.step}, body {e2.body}" if isinstance(e2, DivergenceError) else repr(e2))))
    if named in ctx.integrators:   # a default Sim (on_bound="raise") refuses the first step, naming the bound
        r = divergence_trial(named, ctx.backend, on_bound="raise")
        err = r["error"]
        ok = (isinstance(err, DivergenceError) and err.step == 0 and "validity bound" in str(err)
              and err.body_name == "spinner" and r["unchanged"])
        out.figures["divergence_bound_message"] = str(err)
        out.checks.append(C.holds("divergence_bound_refuses_first_step", ok,
                                  f"{named}, Sim's default on_bound='raise': the first step is refused naming the "
                                  f"spinner and the validity bound, state unchanged: {str(err)!r}"))
    if named not in ctx.integrators:
        out.checks.append(C.holds("divergence_integrator_available", False, f"{named!r} not in INTEGRATORS"))
    out.survival["divergence_report"] = row
    out.params["divergence_setup"] = (f"I_b = {list(DIV_I)}, bodies calm ω0 = {list(DIV_CALM)} and spinner ω0 = "
                                      f"{list(DIV_SPIN)}, dt = {DIV_DT}, one good step then run({DIVERGENCE_STEPS}); "
                                      f"asserted with {named}")
    return out


CASE_FUNCS = {name: globals().get(f"case_{name}") or functools.partial(case_trials, case=name) for name in CASES}


def merge(*outs: CaseOut) -> CaseOut:
    m = CaseOut()
    for o in outs:
        m.figures.update(o.figures)
        m.params.update(o.params)
        m.checks += o.checks
        m.survival.update(o.survival)
        m.plot.update(o.plot)
    return m


class Context:
    def __init__(self, backend: str, integrators: list[str], assert_with: str | None):
        self.backend, self.integrators, self.assert_with = backend, integrators, assert_with

    def trial(self, trial: Trial) -> CaseOut:
        return run_trial(trial, self.integrators, self.backend, self.assert_with)


def run_case(name: str, backend: str = "auto", integrator: str | None = None) -> CaseOut:
    """One case of the catalogue, for every integrator in INTEGRATORS (tests call this directly)."""
    V.choice("case", name, CASES)
    return CASE_FUNCS[name](Context(C.check_backend(backend), list(backends.INTEGRATORS), integrator))


# ------------------------------------------------------------------------------------------ output


def survival_table(survival: dict, integrators: list[str]) -> str:
    """Markdown: one row per trial, one column per integrator."""
    lines = ["| case | " + " | ".join(integrators) + " |", "|---|" + "---|" * len(integrators)]
    for row, st in survival.items():
        lines.append(f"| {row} | " + " | ".join(st.get(i, "—") for i in integrators) + " |")
    return "\n".join(lines) + "\n"


def _status_code(s: str) -> int:
    if s.startswith(("pass", "raised", "survived")):
        return 0
    if s.startswith("stable"):
        return 1
    if s.startswith(("diverged", "blew up")):
        return 2
    return 3


def _bound_ratios(checks) -> dict:
    """{check name: figure / bound} of the asserted upper bounds (a bound of 0: 0 when met, inf when not)."""
    out = {}
    for ch in checks:
        if ch.rule != "<=":
            continue
        v = float(ch.value)
        out[ch.name] = v / ch.bound if ch.bound > 0 else (0.0 if v <= 0 else math.inf)
    return out


def _plot_data(outs: dict) -> dict:
    """What hard_cases.png draws, taken from the cases' runs (arrays only; nothing is re-run to draw)."""
    d: dict[str, dict | None] = {"flips": None, "dt_range": None}
    flips = outs.get("intermediate_axis_flips")
    if flips and "intermediate_axis_flips" in flips.plot:
        run, ref = flips.plot["intermediate_axis_flips"]
        d["flips"] = {"t": run.t, "w2": run.x[:, 0, C.OMEGA_B][:, 1], "exact": ref.intermediate_zero_crossings(run.t[-1])}
    dtr = outs.get("dt_range")
    if dtr and "dt_range" in dtr.plot:
        plot, named = dtr.plot["dt_range"]
        d["dt_range"] = {"named": named, "rows": {b: rows for (b, integ), rows in plot.items() if integ == named}}
    return d


# survival map: colour (Okabe–Ito, light to dark) AND a word in every cell that is not a pass, so the
# four outcomes read under any colour vision and in greyscale: (colour, legend text, cell text, text colour)
STATUS_KEY = ((F.SKY_BLUE, "pass (the case's bounds hold)", "", F.BLACK),
              (F.YELLOW, "finite, a bound missed  [miss]", "miss", F.BLACK),
              (F.ORANGE, "diverged: DivergenceError (or blew up)  [div]", "div", F.BLACK),
              (F.BLACK, "silent NaN or error  [NaN!]", "NaN!", "white"))


def _plots(d, ax=None):
    """hard_cases.png from the result's data: flips, the dt range, every asserted bound, the survival table.

    ``ax``: four Axes to draw into instead (flips, dt range, bounds, survival), in that order."""
    if ax is not None:
        fig, axes = C.new_figure(1, 4, ax=ax)
        a, b, c, sv = axes.ravel()
    else:
        fig, _ = C.new_figure(1, 1, size=(15, 6.5 + 0.16 * max(len(d["bound_ratios"]), len(d["survival"]) * 2)))
        fig.clear()
        fig.suptitle("Hard cases: asserted bounds and the figures measured")
        gs = fig.add_gridspec(3, 2, height_ratios=[1, 1, 1.3], width_ratios=[1, 1.1])
        a, b = fig.add_subplot(gs[0, 0]), fig.add_subplot(gs[1, 0])
        c, sv = fig.add_subplot(gs[0:2, 1]), fig.add_subplot(gs[2, :])
        for x in (a, b, c, sv):
            F.style_axes(x)
    _draw_flips(a, d["flips"])
    _draw_dt_range(b, d["dt_range"])
    _draw_bounds(c, d["bound_ratios"], d["passed"])
    _draw_survival(sv, d["survival"], d["integrators"])
    return fig


def _draw_flips(a, f) -> None:
    """Intermediate-axis flips: ω_2 and the exact flip times."""
    if f is not None:
        a.plot(f["t"], f["w2"], lw=0.8, color=F.BLUE, label="ω_2 (RK4, dt = 1e-3)")
        a.plot(f["exact"], np.zeros_like(f["exact"]), "x", color=F.VERMILLION, mew=2, label="exact flip times (4K(m)/λ)")
        a.legend(fontsize=8, loc="lower left")
    a.set_xlabel("time t (s)")
    a.set_ylabel("ω_2 (rad/s)")
    a.set_title("intermediate-axis flips: diag(1,2,3), ω0 = (1e-3, 5, 1e-3)", fontsize=10)


def _draw_dt_range(b, dtr) -> None:
    """The dt range: the error at T against its bound, per body."""
    if dtr is not None:
        for k, (bname, rows) in enumerate(dtr["rows"].items()):
            dt = np.array([r[0] for r in rows])
            e = np.array([r[1] for r in rows], float)
            bd = np.array([r[2] for r in rows])
            col = F.CYCLE[k % len(F.CYCLE)]
            ok = np.isfinite(e)
            b.loglog(dt[ok], np.maximum(e[ok], 1e-17), "o-", color=col, label=f"{bname} spin: error at T")
            b.loglog(dt, bd, ":", color=col, lw=2, label=f"{bname} spin: bound")
            if (~ok).any():
                b.loglog(dt[~ok], bd[~ok], "v", color=col, ms=8, mfc="none",
                         label=f"{bname} spin: DivergenceError raised (no error to draw)")
        b.legend(fontsize=7, loc="upper left")
    b.set_xlabel("dt (s)")
    b.set_ylabel("error at T (rad; relative ω)")
    named = dtr["named"] if dtr else "rk4"
    b.set_title(f"dt range ({named}): error at T against its bound", fontsize=10)


def _draw_bounds(c, ratios, passed) -> None:
    """Every asserted upper bound: figure / bound on a log axis, the missed ones hatched."""
    from matplotlib.patches import Patch

    names = list(ratios)
    vals = [min(max(r, 1e-8), 1e3) if math.isfinite(r) else 1e3 for r in ratios.values()]
    y = np.arange(len(names))
    ok_style, bad_style = F.STATUS_STYLE["pass"], F.STATUS_STYLE["fail"]      # colour and hatch differ
    c.barh(y, vals, color=[(ok_style if passed[n] else bad_style)["color"] for n in names],
           hatch=[(ok_style if passed[n] else bad_style)["hatch"] for n in names], edgecolor="white", lw=0)
    for yi, r in zip(y, ratios.values()):        # no bar to see on a log axis: say the value
        if r < 1e-8:
            c.text(1.3e-8, yi, "0 (exact)" if r == 0 else "< 1e-8", va="center", fontsize=6, color=ok_style["color"])
    c.set_xscale("log")
    c.set_xlim(1e-8, 1e3)
    c.axvline(1.0, color=F.BLACK, lw=0.8)
    c.set_yticks(y, names, fontsize=7)
    c.invert_yaxis()
    c.set_xlabel("figure / bound (< 1 passes; clamped to 1e-8 … 1e3)")
    c.set_title(f"asserted bounds ({len(names)} upper bounds)", fontsize=10)
    c.legend(handles=[Patch(facecolor=ok_style["color"], hatch=ok_style["hatch"], label="within its bound"),
                      Patch(facecolor=bad_style["color"], hatch=bad_style["hatch"], edgecolor="white",
                            label="bound missed (hatched)")],
             fontsize=7, loc="lower right")


def _draw_survival(sv, survival, integrators) -> None:
    """Which integrators survive each case: a colour and a word per cell."""
    from matplotlib.colors import ListedColormap
    from matplotlib.patches import Patch

    rows = list(survival)
    M = np.array([[_status_code(survival[r].get(i, "error")) for i in integrators] for r in rows]).T
    sv.imshow(M, cmap=ListedColormap([k[0] for k in STATUS_KEY]), vmin=0, vmax=3, aspect="auto")
    for (i, j), code in np.ndenumerate(M):
        if STATUS_KEY[code][2]:
            sv.text(j, i, STATUS_KEY[code][2], ha="center", va="center", fontsize=6, color=STATUS_KEY[code][3])
    sv.set_yticks(range(len(integrators)), integrators, fontsize=8)
    sv.set_xticks(range(len(rows)), rows, rotation=30, ha="right", fontsize=7)
    sv.set_title("which integrators survive each case (survival.md has the words)", fontsize=10)
    sv.legend(handles=[Patch(facecolor=k[0], edgecolor=F.GREY, label=k[1]) for k in STATUS_KEY], loc="upper left",
             bbox_to_anchor=(1.01, 1.0), fontsize=8, title="cell colour", title_fontsize=8)


def run(out_dir=C.DEFAULT_OUT, backend: str = "auto", **options) -> C.LabResult:
    """:func:`compute`, then write OUT/hard/ (results.json, hard_cases.png, survival.md)."""
    return compute(backend, **options).save(out_dir)


@failed_figure
def compute(backend: str = "auto", cases=None, integrator: str | None = None, progress: bool = False) -> C.LabResult:
    """Run the catalogue and return its :class:`~lavendersim.labs.common.LabResult`; writes nothing.

    ``progress``: a progress bar on stderr (a TTY only; see :func:`lavendersim.labs.common.progress`)."""
    backend = C.check_backend(backend)
    integrators = list(backends.INTEGRATORS)
    if integrator is not None:
        integrator = V.choice("integrator", integrator, backends.INTEGRATORS)
    if cases is None:
        cases = list(CASES)
    else:
        if isinstance(cases, str) or not cases:
            raise V.LavenderInputError("cases", "must be a non-empty list of case names", f", got {cases!r}")
        cases = [V.choice("cases", c, CASES) for c in cases]
    ctx = Context(backend, integrators, integrator)
    outs, walls = {}, {}
    for name in C.progress(cases, desc="lab hard", unit="case", enabled=progress):
        t0 = time.perf_counter()
        outs[name] = CASE_FUNCS[name](ctx)
        walls[name] = time.perf_counter() - t0
    allc = merge(*outs.values())
    figures = dict(allc.figures)
    for row, st in allc.survival.items():
        for integ, s in st.items():
            figures[f"survival_{row}_{integ}"] = s
    for name, w in walls.items():
        figures[f"wall_time_{name}"] = w
    params = {"backend": backend, "integrators": ", ".join(integrators), "cases": ", ".join(cases),
              "asserted_with": integrator or "the integrator each case names (rk4; implicit_gyro; euler for divergence)",
              "long_runs_backend": f"{fast_backend(backend)} (runs over {C_BACKEND_ABOVE} steps)", **allc.params}
    ratios = _bound_ratios(allc.checks)
    figures["worst_figure_over_bound"] = max(ratios.values(), default=0.0)
    figures["worst_figure_over_bound_name"] = max(ratios, key=lambda k: ratios[k]) if ratios else "none"
    data = {"survival": allc.survival, "integrators": integrators, "bound_ratios": ratios,
            "passed": {ch.name: ch.passed for ch in allc.checks}, **_plot_data(outs)}
    result = C.make_result(NAME, figures, params, allc.checks, {"hard_cases.png": _plots}, data,
                           headline=("worst_figure_over_bound", "<= 1 (every asserted figure within its bound)"))
    result.extra_files["survival.md"] = ("# Which integrators survive each hard case\n\n"
                                         + survival_table(allc.survival, integrators))
    return result
