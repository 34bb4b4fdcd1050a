"""Lab accuracy: what accuracy costs in time — work-precision of every integrator, both backends, and peers.

Cases (torque-free, start at identity, T = 10 s; the reference is the exact motion of
lavendersim.oracle.torque_free, Jacobi elliptic functions):
  * box_w1, box_w2: the chapter's box 0.8 x 0.2 x 0.2 m, 1 kg (I_b = [0.08, 0.68, 0.68]/12 kg·m²),
    omega_b(0) = [1, 0.5, 0.2] and [0.1, 2, 0.1] rad/s;
  * diag_w1, diag_w2: I_b = diag(1, 2, 3) kg·m², 1 kg, the same two omega_b(0).

Methods, each measured in the same run on this machine:
  * every integrator of lavendersim.backends.INTEGRATORS (discovered at run time) on both backends
    ("c": the stepping loop runs inside C, timed around Sim.run; "numpy": vectorized NumPy, one
    Python step per dt), fixed step dt = 2^-4 ... 2^-12 s (the NumPy backend stops earlier when one
    run would take longer than a budget; see numpy_run_budget_s); an adaptive integrator (one that
    Sim accepts rtol/atol for) sweeps rtol = 1e-3 ... 1e-13 instead (atol = rtol);
  * scipy.integrate.solve_ivp RK45 and DOP853 on the generated NumPy kernel rigid_body_rhs_free
    (the same right-hand side), rtol = 1e-3 ... 1e-13 (atol = rtol);
  * MuJoCo's Euler, implicitfast and RK4 when the `mujoco` package is importable (pip install -e
    '.[bench]'): one free body with the same mass and principal inertia in an MJCF string, no
    gravity, contacts and constraints disabled, stepped inside C by mujoco.rollout, dt = 2^-4 ...
    2^-12 s. Its free-joint quaternion (w, x, y, z) is converted to ours (x, y, z, w); its angular
    velocity is in the body frame like ours.
  * the precision axis: euler, semi_implicit_euler and rk4 also in float32 on the C backend
    (Sim(dtype="float32"), methods "<name> [c float32]"; the NumPy backend's float32 is bitwise the
    C backend's, tests/test_float32.py), so the verdicts weigh the precision a user picks.

Measures per point (a method at one dt or rtol, one case):
  * attitude error at T: attitude_error(q(T), q_exact(T)) in rad; omega error |omega_b(T) -
    omega_exact(T)| in rad/s;
  * energy drift max_t |E(t) - E(0)| / E(0) and world angular-momentum drift
    max_t |L_w(t) - L_w(0)| / |L_w(0)| (lavendersim.oracle.relative_drift) over every step (every
    accepted step for scipy; every dt-sample for an adaptive Sim); q normalized before L_w for scipy;
  * wall time per simulated second: the minimum over repeats of one whole run's wall time / T
    (repeats are interleaved round-robin across all points so slow drifts of the machine's load
    hit every method alike; 5 rounds in the full run, runs under 10 ms get up to 20); Sim
    construction is outside the timed region, the one Python call of Sim.run / solve_ivp /
    rollout inside it (a fixed ~10-20 µs per run that dominates the coarsest C points);
  * RHS evaluations over the run: sim.rhs_evals (every Sim counts them); solve_ivp's nfev; MuJoCo:
    forward-dynamics evaluations (1 per step, 4 for RK4).

Verdict (per case, on attitude error vs wall time per simulated second). A point B dominates a
point A when B belongs to another method, err(B) <= err(A) and B is faster: time(B) < time(A)/1.1,
or, when the times are within the 10% timing margin (min-of-repeats noise on a shared machine),
err(B) < err(A) strictly — so two points never dominate each other. Errors are clamped below at
error_floor = 1e-11 rad (the reference agrees with DOP853 to ~1e-12 and rounding over 10^4 steps
is ~1e-12 .. 1e-11, so differences below it are noise, not accuracy). Only points with
err <= error_ceiling = 1e-2 rad take part (a cheap answer wrong by more than half a degree is on
no one's menu). A method is "on the Pareto front" in a case when at least one of its points there
is not dominated, "beaten" when every one of them is (the output names the methods that dominate),
and "out of range" when it never reaches the ceiling. The plain verdict per method: "on the
Pareto front" if it is on the front in at least one case, else "beaten" if it is beaten in at
least one case, else "out of range". The same verdicts against RHS evaluations instead of time
are in the JSON.

Checks (the exit code; never timings): the exact reference agrees with DOP853 at rtol = atol =
1e-13; RK4 on the C backend at the smallest dt is within 1e-9 (rad, rad/s) of the exact solution;
the NumPy and C backends agree at every common point; the measured convergence orders (least-squares
slope of log attitude error vs log dt over the asymptotic window 1e-10 < err < 0.2 rad) match
euler 1, semi_implicit_euler 1, rk4 4, splitting 2, implicit_gyro 1 within 0.35; every adaptive
method (ours, scipy's RK45 and DOP853) at its tightest rtol within 100 x rtol of the exact
attitude; MuJoCo (when installed) converges to the same reference: RK4 within 1e-8 at the smallest
dt with order 4, Euler with order 1; the verdicts are consistent with the points.

Where it runs: the errors, drifts and RHS counts of every point (one task per case x method
sweep) are computed on lavendersim.executor — every local core by default, --workers 1 in this
process, --dask ADDRESS on an existing Dask scheduler (the distributed extra); they are the same
numbers on any executor. The wall times are not: they are measured afterwards, serially in this
process, once the workers have exited (timing under parallel workers would measure contention for
the cores, not the method). A NumPy dt sweep's early stop (numpy_run_budget_s) uses the wall time
of the error run where it ran, so under busy workers it can stop one point earlier.

--quick: two cases (box_w1, diag_w2), dt 2^-4 ... 2^-10 s on C and MuJoCo (2^-4 ... 2^-6 on NumPy),
rtol 1e-3 ... 1e-8, one repeat: every method and check, in well under 20 s.
From Python, ``run(out_dir)`` runs the quick sweep (what ``lavendersim lab all`` runs);
``run(out_dir, quick=False)`` and the command line without --quick run the full sweep. The lab
measures both backends whatever --backend says.

Files: OUT/accuracy/results.json (the lab's flat figures and checks, plus "machine", "table",
"verdicts" and "points": every measured point), points.csv, work_precision_time.png (error vs
wall time per simulated second), work_precision_rhs.png (error vs RHS evaluations),
work_precision_omega.png (omega error vs time), drift_vs_time.png (energy and momentum drift
over the run at dt = 2^-6 s / rtol = 1e-6).
"""
from __future__ import annotations

import csv
import functools
import io
import math
import os
import sys
import sysconfig
import time
import warnings
from dataclasses import asdict, dataclass, field
from typing import Any

import numpy as np

import lavendersim as lv
from lavendersim import backends as B
from lavendersim import executor as X
from lavendersim import oracle as R
from lavendersim import validate as V
from lavendersim._install import extra_command
from lavendersim.errors import DivergenceError, ValidityBoundWarning
from lavendersim.generated import tableaux as TABLEAUX
from lavendersim.kernels import K
from lavendersim import figures as F

from . import common as C
from .diverged import failed_figure

NAME = "accuracy"
TITLE = "what accuracy costs in time: work-precision of every integrator x dt x backend, scipy and MuJoCo"

T_END = 10.0
MASS = 1.0
BOX_SIZE = (0.8, 0.2, 0.2)
OMEGAS = {"w1": (1.0, 0.5, 0.2), "w2": (0.1, 2.0, 0.1)}
ERROR_FLOOR = 1e-11       # rad: below this errors count as equal (reference ~1e-12, rounding over 1e4 steps)
ERROR_CEILING = 1e-2      # rad: points less accurate than this take no part in the verdict
TIME_MARGIN = 0.10        # wall times within 10% count as equally fast (min-of-repeats noise under load)
ORDER_WINDOW = (1e-10, 0.2)
ORDER_TOL = 0.35
# expected convergence order of attitude error in dt for integrators we know by name
# each fixed-step integrator's order torque-free, from the printed registry (derive/tableaux.py)
EXPECTED_ORDER = {n: o for n, o in TABLEAUX.INTEGRATOR_ORDER.items() if n not in B.ADAPTIVE}
ADAPTIVE_ERROR_FACTOR = 100.0
DRIFT_DT_EXP, DRIFT_RTOL = 6, 1e-6        # the runs drawn in drift_vs_time.png
NUMPY_RUN_BUDGET_S = 0.8                  # one NumPy run longer than this ends its dt sweep (full mode)

FULL: dict[str, Any] = dict(cases=("box_w1", "box_w2", "diag_w1", "diag_w2"), dt_exps=tuple(range(4, 13)),
                            numpy_dt_exps=tuple(range(4, 13)), numpy_budget=NUMPY_RUN_BUDGET_S,
                            rtols=tuple(10.0 ** -k for k in range(3, 14)),
                            numpy_rtols=tuple(10.0 ** -k for k in range(3, 14)),
                            mj_dt_exps=tuple(range(4, 13)), repeats=5, time_budget=0.25)
QUICK: dict[str, Any] = dict(cases=("box_w1", "diag_w2"), dt_exps=tuple(range(4, 11)), numpy_dt_exps=(4, 5, 6),
                             numpy_budget=0.3, rtols=tuple(10.0 ** -k for k in range(3, 9)),
                             numpy_rtols=(1e-3, 1e-4, 1e-5), mj_dt_exps=tuple(range(4, 11)), repeats=1, time_budget=0.0)


@dataclass(frozen=True)
class Case:
    name: str
    label: str
    I_b: np.ndarray
    omega_b0: np.ndarray


def cases() -> dict[str, Case]:
    I_box = np.asarray(K.inertia_box(MASS, *BOX_SIZE), dtype=float)
    I_diag = np.array([1.0, 2.0, 3.0])
    out = {}
    for bname, I, blabel in (("box", I_box, "box 0.8x0.2x0.2 m"), ("diag", I_diag, "diag(1,2,3)")):
        for wname, w in OMEGAS.items():
            out[f"{bname}_{wname}"] = Case(f"{bname}_{wname}", f"{blabel}, w0={list(w)}", I, np.array(w, float))
    return out


@dataclass
class Method:
    label: str            # e.g. "rk4 [c]", "scipy DOP853", "MuJoCo RK4"
    family: str           # lavendersim | scipy | mujoco
    integrator: str
    backend: str          # c | numpy | scipy | mujoco
    param: str            # dt | rtol
    stages: int | None = None
    dtype: str = "float64"  # the precision axis: Sim(dtype=...) ("float32": label "rk4 [c float32]")
    order: int | None = None  # the expected order in dt (a fixed-step lavendersim integrator, float64)


@dataclass
class Point:
    case: str
    method: str
    param: str
    value: float
    steps: int | None = None
    rhs_evals: int | None = None
    rhs_evals_source: str = ""
    attitude_error: float = math.nan       # NaN: not measured (null in results.json)
    omega_error: float = math.nan
    energy_drift: float = math.nan
    momentum_drift: float = math.nan
    wall_s: float | None = None
    wall_per_sim_s: float | None = None
    repeats: int = 0
    diverged: str | None = None
    final_x: list | None = field(default=None, repr=False)

    @property
    def ok(self) -> bool:
        return self.diverged is None and math.isfinite(self.attitude_error)


# ------------------------------------------------------------------------------------------ options

# ------------------------------------------------------------------------------------------ discovery

def adaptive_integrators() -> list[str]:
    """Integrators that take rtol/atol (the printed registry's adaptive ones)."""
    return list(B.ADAPTIVE)


def _probe(m: "Method") -> str | None:
    """None if the Sim steps this integrator on this backend, else why not: every registered integrator must
    (the lab records a failure as a failed check, never as 'unavailable')."""
    try:
        sim = _make_sim(cases()["diag_w1"], m, 1e-6 if m.param == "rtol" else 2.0 ** -4)
        sim.run(1)
    except Exception as exc:  # recorded as the failed check runs_<label>
        return f"{type(exc).__name__}: {exc}"
    return None


def methods(mujoco_ok: bool, integrators=None) -> tuple[list[Method], dict]:
    """The methods to measure and {label: reason} for the integrators that raised when probed.

    ``integrators``: the lavendersim integrators to measure (None: every built-in one); a name that is not
    built in is a user tableau (:func:`lavendersim.extending.tableau`), measured on both backends."""
    out, broken = [], {}
    names = list(B.INTEGRATORS) if integrators is None else list(integrators)
    adaptive = adaptive_integrators()

    def probed(m: Method) -> None:
        why = _probe(m)
        if why:
            broken[m.label] = why
        else:
            out.append(m)

    for backend in ("c", "numpy"):
        for name in names:
            stages, order = _stages_and_order(name)
            param = "rtol" if name in adaptive else "dt"
            probed(Method(f"{name} [{backend}]", "lavendersim", name, backend, param, stages, order=order))
    for name in getattr(B, "FLOAT32_INTEGRATORS", ()):   # the precision axis: float32 beside float64, C backend
        if name in names:
            probed(Method(f"{name} [c float32]", "lavendersim", name, "c", "dt", B.INTEGRATORS[name], dtype="float32"))
    for name in ("RK45", "DOP853"):
        out.append(Method(f"scipy {name}", "scipy", name, "scipy", "rtol"))
    if mujoco_ok:
        for name, stages, order in (("Euler", 1, 1), ("implicitfast", 1, None), ("RK4", 4, 4)):
            out.append(Method(f"MuJoCo {name}", "mujoco", name, "mujoco", "dt", stages, order=order))
    return out, broken


def _stages_and_order(name: str) -> tuple[int | None, int | None]:
    """(RHS evaluations per step, expected order) of a built-in integrator or a user tableau."""
    if name in B.INTEGRATORS:
        stages = B.INTEGRATORS[name]
        return (None if stages is None else int(stages)), EXPECTED_ORDER.get(name)
    from lavendersim import extending

    tab = extending.tableau(name)   # LavenderInputError naming the known ones for an unknown name
    return int(tab.stages), int(tab.order)


def _mujoco():
    try:
        import mujoco  # noqa: F401
        from mujoco import rollout  # noqa: F401
        return mujoco, None
    except Exception as exc:  # not installed or broken: the lab says so and runs without it
        return None, f"{type(exc).__name__}: {exc}"


# ------------------------------------------------------------------------------------------ measures

def _envelope(series: np.ndarray, t: np.ndarray, n: int = 200):
    """(t, max-of-bin) of a series downsampled to at most n bins, for the drift plot."""
    if len(series) <= n:
        return t, series
    edges = np.linspace(0, len(series), n + 1).astype(int)
    return (np.array([t[b - 1] for b in edges[1:]]),
            np.array([series[a:b].max() for a, b in zip(edges[:-1], edges[1:])]))


def _score(pt: Point, case: Case, exact, t, x, keep_drift: bool, drifts: dict):
    """Errors at T of samples x (T, 13); drifts of E and L_w (the printed kernels) with q normalized."""
    q, w = x[:, C.Q], x[:, C.OMEGA_B]
    xn = np.array(x, dtype=float)
    xn[:, C.Q] = K.quat_normalize(q)
    E, L = C.energy_momentum(case.I_b, xn, MASS)
    pt.attitude_error = float(R.attitude_error(q[-1], exact.q[-1]))
    pt.omega_error = float(np.linalg.norm(w[-1] - exact.omega_b[-1]))
    pt.energy_drift = R.relative_drift(E)
    pt.momentum_drift = R.relative_drift(L)
    if keep_drift:
        e_rel = np.abs(E - E[0]) / E[0]
        l_rel = np.linalg.norm(L - L[0], axis=-1) / np.linalg.norm(L[0])
        te, ee = _envelope(e_rel, t)
        _, le = _envelope(l_rel, t)
        drifts[(case.name, pt.method)] = {"t": te.tolist(), "energy": ee.tolist(), "momentum": le.tolist(),
                                          "at": f"{pt.param} = {_param_text(pt.param, pt.value)}"}


def _param_text(param, value) -> str:
    if param == "dt":
        k = -math.log2(value)
        return f"2^-{k:.0f} s" if abs(k - round(k)) < 1e-12 else f"{value:g} s"
    return f"{value:.0e}"


# ------------------------------------------------------------------------------------------ runners

def _scene(case: Case):
    sc = lv.Scene()
    sc.add_body(lv.Body("b", MASS, case.I_b, omega_b=case.omega_b0))
    return sc


ADAPTIVE_SAMPLE_DT = 0.25   # s: output interval of the adaptive Sim's second (drift) run


def _make_sim(case, m: Method, value, dt: float | None = None):
    """Fixed step: dt = value. Adaptive: rtol = atol = value and dt the output interval (default T:
    one output step, so the integrator's own step sequence is never clipped at output times)."""
    if m.param == "rtol":
        return lv.Sim(_scene(case), dt=T_END if dt is None else dt, integrator=m.integrator, backend=m.backend,
                      rtol=value, atol=value)
    # the sweep measures error against dt beyond each integrator's validity bound too (issue 11): opted in,
    # the ValidityBoundWarnings silenced where the runs happen (measure_sweep)
    return lv.Sim(_scene(case), dt=value, integrator=m.integrator, backend=m.backend, on_bound="warn", dtype=m.dtype)


def _measure_sim(case, m, value, exact, drifts, keep_drift):
    """Fixed step: one run recorded at every step gives the error at T and the drifts. Adaptive: the
    error at T and the RHS count come from one output step of T; the drifts from a second run with
    output every ADAPTIVE_SAMPLE_DT (sampled there; its clipping at output times changes the step
    sequence slightly). Timing: a fresh Sim per repeat (construction outside the timed region)."""
    pt = Point(case.name, m.label, m.param, float(value))
    adaptive = m.param == "rtol"
    n = 1 if adaptive else int(round(T_END / value))
    sim = _make_sim(case, m, value)
    try:
        if adaptive:
            sim.run(1)
            sample_dt = ADAPTIVE_SAMPLE_DT
            dsim = _make_sim(case, m, value, dt=sample_dt)
            traj = dsim.record(int(round(T_END / sample_dt)))
        else:
            traj = sim.record(n)
    except DivergenceError as exc:
        pt.diverged = str(exc)
        return pt
    x = traj.x[:, 0]
    pt.steps = None if adaptive else int(sim.steps)
    pt.rhs_evals, pt.rhs_evals_source = int(sim.rhs_evals), "sim.rhs_evals"   # (every Sim counts them)
    xT = sim.x[0].copy()
    pt.final_x = xT.tolist()
    _score(pt, case, exact, traj.t, x, keep_drift, drifts)
    if adaptive:   # the error at T is the unclipped run's (_score used the sampled run's last sample)
        pt.attitude_error = float(R.attitude_error(xT[C.Q], exact.q[-1]))
        pt.omega_error = float(np.linalg.norm(xT[C.OMEGA_B] - exact.omega_b[-1]))
        pt.rhs_evals_source += " (one output step of T)"
    return pt


def _timed(run) -> float:
    """The wall time of one call run(), s."""
    t0 = time.perf_counter()
    run()
    return time.perf_counter() - t0


def _sim_job(case, m, value):
    """The timed run of a Sim point: a fresh Sim (constructed outside the timed region), run to T."""
    n = 1 if m.param == "rtol" else int(round(T_END / value))

    def job():
        s = _make_sim(case, m, value)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", ValidityBoundWarning)
            return _timed(lambda: s.run(n))

    return job


def _scipy_solver(case, m, rtol):
    """solve() -> solve_ivp's solution of the case with the generated NumPy kernel as RHS."""
    from lavendersim.generated import kernels_numpy as KN
    from scipy.integrate import solve_ivp

    I_b = case.I_b
    x0 = lv.Body("b", MASS, I_b, omega_b=case.omega_b0).x0

    def rhs(_t, x):
        return KN.rigid_body_rhs_free(x, I_b)

    def solve():
        return solve_ivp(rhs, (0.0, T_END), x0, method=m.integrator, rtol=rtol, atol=rtol)

    return solve


def _scipy_job(case, m, rtol):
    return functools.partial(_timed, _scipy_solver(case, m, rtol))


def _measure_scipy(case, m, rtol, exact, drifts, keep_drift):
    pt = Point(case.name, m.label, "rtol", float(rtol))
    sol = _scipy_solver(case, m, rtol)()
    if not sol.success:
        pt.diverged = f"solve_ivp failed: {sol.message}"
        return pt
    y = sol.y.T
    pt.steps = len(sol.t) - 1
    pt.rhs_evals, pt.rhs_evals_source = int(sol.nfev), "solve_ivp nfev"
    y[:, C.Q] = K.quat_normalize(y[:, C.Q])
    pt.final_x = y[-1].tolist()
    _score(pt, case, exact, sol.t, y, keep_drift, drifts)
    return pt


MJCF = """<mujoco model="accuracy_free_body">
  <option timestep="{dt!r}" gravity="0 0 0" integrator="{integrator}">
    <flag contact="disable" constraint="disable"/>
  </option>
  <worldbody>
    <body name="b">
      <freejoint/>
      <inertial pos="0 0 0" mass="{mass!r}" diaginertia="{I0!r} {I1!r} {I2!r}"/>
    </body>
  </worldbody>
</mujoco>"""


def mujoco_model(mujoco, case: Case, integrator: str, dt: float):
    """A single free body with the case's mass and principal inertia (body frame = principal frame)."""
    xml = MJCF.format(dt=float(dt), integrator=integrator, mass=float(MASS), I0=float(case.I_b[0]),
                      I1=float(case.I_b[1]), I2=float(case.I_b[2]))
    return mujoco.MjModel.from_xml_string(xml)


def _mujoco_setup(mujoco, case, m, dt):
    """(model, data, initial FULLPHYSICS state, steps) of one MuJoCo point."""
    model = mujoco_model(mujoco, case, m.integrator, dt)
    data = mujoco.MjData(model)
    data.qpos[:] = [0, 0, 0, 1, 0, 0, 0]             # position, quaternion (w, x, y, z)
    data.qvel[:] = np.concatenate([[0, 0, 0], case.omega_b0])  # linear (world), angular (body frame)
    spec = mujoco.mjtState.mjSTATE_FULLPHYSICS
    s0 = np.empty(mujoco.mj_stateSize(model, spec))
    mujoco.mj_getState(model, data, s0, spec)
    return model, data, s0, int(round(T_END / dt))


def _mujoco_job(mujoco, case, m, dt):
    from mujoco import rollout

    model, data, s0, n = _mujoco_setup(mujoco, case, m, dt)
    return functools.partial(_timed, lambda: rollout.rollout(model, data, s0[None, :], nstep=n))


def _measure_mujoco(mujoco, case, m, dt, exact, drifts, keep_drift):
    from mujoco import rollout

    model, data, s0, n = _mujoco_setup(mujoco, case, m, dt)
    nq = model.nq
    state, _ = rollout.rollout(model, data, s0[None, :], nstep=n)
    st = np.vstack([s0[None, :], state[0]])        # FULLPHYSICS: time, qpos (7), qvel (6), ...
    pt = Point(case.name, m.label, "dt", float(dt), steps=n)
    qpos, qvel = st[:, 1:1 + nq], st[:, 1 + nq:1 + nq + model.nv]
    if not np.all(np.isfinite(qpos)) or not np.all(np.isfinite(qvel)):
        pt.diverged = "MuJoCo state went non-finite"
        return pt
    if abs(st[-1, 0] - T_END) > 1e-9:
        raise RuntimeError(f"MuJoCo rollout ended at t = {st[-1, 0]!r}, expected {T_END}")
    x = np.empty((len(st), C.LY.STATE_SIZE))        # MuJoCo's free joint in the STATE layout
    x[:, C.P_W], x[:, C.V_W] = qpos[:, :3], qvel[:, :3]
    x[:, C.Q] = K.quat_normalize(qpos[:, [4, 5, 6, 3]])  # (w, x, y, z) -> (x, y, z, w)
    x[:, C.OMEGA_B] = qvel[:, 3:6]                  # the free joint's angular velocity is in the body frame
    pt.rhs_evals, pt.rhs_evals_source = n * m.stages, "MuJoCo forward evaluations (steps x 4 for RK4, else steps)"
    pt.final_x = x[-1].tolist()
    _score(pt, case, exact, st[:, 0], x, keep_drift, drifts)
    return pt


# ------------------------------------------------------------------------------------------ sweeps

def sweep_values(m: Method, cfg: dict) -> list[float]:
    """The dt (or rtol) values of one method's sweep, coarse to fine.

    Parameters
    ----------
    m : Method
        The method (its family, backend and parameter decide which list of ``cfg`` applies).
    cfg : dict
        QUICK or FULL.

    Returns
    -------
    list of float
    """
    if m.family == "lavendersim":
        if m.param == "rtol":
            return list(cfg["rtols"] if m.backend == "c" else cfg["numpy_rtols"])
        exps = cfg["dt_exps"] if m.backend == "c" else cfg["numpy_dt_exps"]
        return [2.0 ** -k for k in exps]
    if m.family == "scipy":
        return list(cfg["rtols"])
    return [2.0 ** -k for k in cfg["mj_dt_exps"]]


def sweep_tasks(use: list[Case], meths: list[Method], cfg: dict, exacts: dict) -> list[tuple]:
    """The tasks of :func:`measure_sweep`: one per case x method.

    Parameters
    ----------
    use : list of Case
    meths : list of Method
    cfg : dict
        QUICK or FULL (possibly edited): the sweep values and the NumPy run budget come from it.
    exacts : dict
        Case name -> the exact motion at [0, T_END].

    Returns
    -------
    list of tuple
        ``(case, method, values, exact, numpy_budget)``, case-major: the order of the points in
        results.json.
    """
    return [(case, m, sweep_values(m, cfg), exacts[case.name], cfg["numpy_budget"]) for case in use for m in meths]


def measure_sweep(task: tuple) -> dict:
    """The errors of one method's sweep in one case: the executor's unit of work.

    Parameters
    ----------
    task : tuple
        ``(case, method, values, exact, numpy_budget)`` from :func:`sweep_tasks`.

    Returns
    -------
    dict
        "points": the Points in sweep order (no wall times); "drifts": the drift series kept
        for drift_vs_time.png; "skipped": why a NumPy dt sweep stopped early, or None; "seconds":
        the wall time of the sweep (progress only).

    Notes
    -----
    A NumPy dt sweep stops after a run longer than numpy_budget s; that run's wall time is
    measured where the sweep runs, so under busy parallel workers it can stop a point earlier
    than serially (the points it keeps are the same numbers). Nothing here is a timing result:
    the timed runs happen afterwards, serially, in the calling process.
    """
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", ValidityBoundWarning)
        return _measure_sweep(task)


def _measure_sweep(task: tuple) -> dict:
    case, m, values, exact, numpy_budget = task
    mj = _mujoco()[0] if m.family == "mujoco" else None
    points, skipped = [], None
    drifts: dict = {}
    t_m = time.perf_counter()
    for v in values:
        keep = (m.param == "dt" and abs(v - 2.0 ** -DRIFT_DT_EXP) < 1e-15) or \
               (m.param == "rtol" and abs(v / DRIFT_RTOL - 1) < 1e-9)
        t0 = time.perf_counter()
        if m.family == "lavendersim":
            pt = _measure_sim(case, m, v, exact, drifts, keep)
        elif m.family == "scipy":
            pt = _measure_scipy(case, m, v, exact, drifts, keep)
        else:
            pt = _measure_mujoco(mj, case, m, v, exact, drifts, keep)
        took = time.perf_counter() - t0
        points.append(pt)
        if m.backend == "numpy" and m.param == "dt" and took > numpy_budget and v != values[-1]:
            rest = [_param_text("dt", x) for x in values if x < v]
            skipped = f"{case.name} {m.label}: {', '.join(rest)} (one run took {took:.2f} s)"
            break
    return {"points": points, "drifts": drifts, "skipped": skipped, "seconds": time.perf_counter() - t_m}


def _timing_job(mj, case: Case, m: Method, value: float):
    """A callable that runs one point once and returns its wall time (s): built and run in this process."""
    if m.family == "lavendersim":
        return _sim_job(case, m, value)
    if m.family == "scipy":
        return _scipy_job(case, m, value)
    return _mujoco_job(mj, case, m, value)


# ------------------------------------------------------------------------------------------ timing

SHORT_RUN_S, SHORT_RUN_ROUNDS = 0.01, 4     # runs under 10 ms get 4x the rounds (they are cheap and noisiest)


def _time_jobs(jobs: list, repeats: int, budget: float, say, bar=None) -> list[tuple[float, int]]:
    """Run every job `repeats` times round-robin (each round visits all jobs once), then the jobs
    whose best run is under SHORT_RUN_S for (SHORT_RUN_ROUNDS - 1) x repeats more rounds, and
    return (min wall time, repeats done) per job. A job whose single run exceeds `budget` s
    stops after its first repeat (its minimum is then that run)."""
    best = [math.inf] * len(jobs)
    done = [0] * len(jobs)
    rounds = max(1, repeats) * (SHORT_RUN_ROUNDS if repeats > 1 else 1)
    if bar is not None:
        bar.reset(total=rounds * len(jobs))
        bar.set_description("lab accuracy: timing")
    for r in range(rounds):
        t_round = time.perf_counter()
        extra = r >= max(1, repeats)
        for i, job in enumerate(jobs):
            if job is None or (done[i] and best[i] > budget) or (extra and best[i] >= SHORT_RUN_S):
                continue
            best[i] = min(best[i], job())
            done[i] += 1
        if bar is not None:
            bar.update(len(jobs))
        if not extra or r == rounds - 1:
            say(f"timing round {r + 1}/{rounds} done in {time.perf_counter() - t_round:.1f} s"
                + (f" (rounds after the first {repeats} time only the runs under 10 ms)" if not extra and repeats > 1
                   and r == repeats - 1 else ""))
    return list(zip(best, done))


# ------------------------------------------------------------------------------------------ analysis

def convergence_order(points: list[Point], window=ORDER_WINDOW, min_points: int = 3) -> float | None:
    """Least-squares slope of log attitude error vs log dt (or log rtol) over the points inside the
    window (at least min_points, else None)."""
    xs, ys = [], []
    for p in points:
        if p.ok and window[0] < p.attitude_error < window[1]:
            xs.append(math.log(p.value))
            ys.append(math.log(p.attitude_error))
    if len(xs) < max(2, min_points):
        return None
    return float(np.polyfit(xs, ys, 1)[0])


def _clamped(e: float) -> float:
    return max(e, ERROR_FLOOR)


def dominates(e_b: float, c_b: float, e_a: float, c_a: float) -> bool:
    """Point b = (error, cost) dominates point a: b is at least as accurate (errors clamped at
    ERROR_FLOOR) and faster, where a cost within TIME_MARGIN of a's counts as equally fast and then
    b must be strictly more accurate. No two points dominate each other."""
    eb, ea = _clamped(e_b), _clamped(e_a)
    return eb <= ea and (c_b < c_a / (1 + TIME_MARGIN) or (eb < ea and c_b <= c_a * (1 + TIME_MARGIN)))


def dominated_by(p_err: float, p_cost: float, own: str, pool: list[tuple[str, float, float]]) -> list[str]:
    """Methods other than `own` with a point that dominates (p_err, p_cost)."""
    return sorted({m for m, e, c in pool if m != own and dominates(e, c, p_err, p_cost)})


def verdicts(points: list[Point], cost: str = "wall_per_sim_s") -> dict:
    """Per case and method: "on the Pareto front", "beaten" (with the dominating methods) or
    "out of range" (never within ERROR_CEILING), by attitude error against `cost`."""
    out: dict = {}
    for case in sorted({p.case for p in points}):
        pts = [p for p in points if p.case == case and p.ok and getattr(p, cost) is not None
               and p.attitude_error <= ERROR_CEILING]
        pool = [(p.method, p.attitude_error, getattr(p, cost)) for p in pts]
        per: dict = {}
        for method in sorted({p.method for p in points if p.case == case}):
            mine = [p for p in pts if p.method == method]
            if not mine:
                per[method] = {"verdict": "out of range", "beaten_by": [], "front_points": [], "overall_front_points": []}
                continue
            by, front = set(), []
            for p in mine:
                d = dominated_by(p.attitude_error, getattr(p, cost), method, pool)
                if d:
                    by.update(d)
                else:
                    front.append(p.value)
            # methods that dominate every one of this method's points
            whole = sorted(m for m in by if all(m in dominated_by(p.attitude_error, getattr(p, cost), method, pool)
                                                 for p in mine))
            # the points on the overall front of the case: dominated by no other point, own method's included
            overall = [p.value for p in mine
                       if not any(dominates(e, c, p.attitude_error, getattr(p, cost))
                                  for m2, e, c in pool if not (m2 == method and e == p.attitude_error
                                                               and c == getattr(p, cost)))]
            per[method] = {"verdict": "on the Pareto front" if front else "beaten",
                           "beaten_by": sorted(by) if not front else [], "beaten_everywhere_by": whole if not front else [],
                           "front_points": front, "overall_front_points": overall}
        out[case] = per
    return out


def overall_verdicts(per_case: dict, method_labels: list[str]) -> dict:
    out = {}
    for m in method_labels:
        vs = {c: per_case[c][m]["verdict"] for c in per_case if m in per_case[c]}
        front = [c for c, v in vs.items() if v == "on the Pareto front"]
        if front:
            text = "on the Pareto front" + (f" (in {len(front)}/{len(vs)} cases: {', '.join(front)})"
                                            if len(front) < len(vs) else f" (all {len(vs)} cases)")
            out[m] = {"verdict": "on the Pareto front", "text": text, "cases": vs}
        elif all(v == "out of range" for v in vs.values()):
            out[m] = {"verdict": "out of range", "cases": vs,
                      "text": f"out of range (never within {ERROR_CEILING:g} rad in the sweep)"}
        else:
            by = sorted(set().union(*(per_case[c][m]["beaten_by"] for c in vs)) if vs else set())
            every = set.intersection(*(set(per_case[c][m]["beaten_everywhere_by"]) for c in vs
                                       if vs[c] == "beaten")) if any(v == "beaten" for v in vs.values()) else set()
            oor = [c for c, v in vs.items() if v == "out of range"]
            text = "beaten" + (f" (every point by: {_few(sorted(every, key=_rank))})" if every else
                               f" (by: {_few(sorted(by, key=_rank))})" if by else "")
            if oor:
                text += f"; never within {ERROR_CEILING:g} rad in {', '.join(oor)}"
            out[m] = {"verdict": "beaten", "text": text, "cases": vs, "beaten_by": by,
                      "beaten_everywhere_by": sorted(every)}
    return out


def _rank(label: str) -> tuple:
    """C-backend methods first, then peers, then NumPy (for naming the few that beat a method)."""
    return ("[numpy]" in label, label.startswith(("scipy", "MuJoCo")), label)


def _few(labels: list[str], n: int = 3) -> str:
    return ", ".join(labels[:n]) + (f" and {len(labels) - n} more" if len(labels) > n else "")


def _worst(costs: list[float | None]) -> float | None:
    """The largest cost, or None when one of them is None (a case that never reaches the tolerance)."""
    return None if any(c is None for c in costs) else max(c for c in costs if c is not None)


def cost_to_reach(points: list[Point], tol: float, cost: str = "wall_per_sim_s") -> float | None:
    """Cheapest cost among the points with attitude error <= tol (None if none reaches it)."""
    c = [getattr(p, cost) for p in points if p.ok and p.attitude_error <= tol and getattr(p, cost) is not None]
    return min(c) if c else None


# ------------------------------------------------------------------------------------------ machine

def machine_stamp(mujoco) -> dict:
    """The bench's machine stamp (CPU, versions, compiler, commit) plus what this study adds:
    scipy's version, the compiler flags, the load at the start. ``git_commit`` names the installed
    version when the package does not run from a git checkout."""
    import scipy

    from lavendersim import bench

    m = bench.machine_stamp()
    commit = (m["git_commit"] + (" (with uncommitted changes)" if m["git_dirty"] else "")
              if m["git_commit"] else f"not a git checkout (lavendersim {m['lavendersim']} installed)")
    return {
        "cpu": m["cpu"], "logical_cores": m["cores"], "affinity_cores": m["cores_usable"],
        "platform": m["platform"], "python": m["python"], "numpy": m["numpy"],
        "scipy": scipy.__version__, "mujoco": getattr(mujoco, "__version__", None) if mujoco else None,
        "compiler": f"{m['compiler']}: {m['compiler_version']}" if m["compiler"] else "no C compiler found",
        "c_flags": sysconfig.get_config_var("CFLAGS") or "",
        "git_commit": commit, "loadavg_start": m["loadavg"],
    }


# ------------------------------------------------------------------------------------------ run

def run(out_dir=C.DEFAULT_OUT, backend: str = "auto", **options) -> C.LabResult:
    """:func:`compute`, then write OUT/accuracy/ (results.json, points.csv and the four PNGs)."""
    return compute(backend, **options).save(out_dir)


@failed_figure
def compute(backend: str = "auto", quick: bool = True, mujoco: bool = True, progress: bool = False,
            workers: int | None = None, dask: str | None = None, integrators=None) -> C.LabResult:
    """Run the study and return its LabResult, writing nothing; ``quick=True`` (the Python default, what ``lab all`` runs) is the reduced
    sweep, ``quick=False`` the full one (the command line's default). ``backend`` is accepted for
    the labs' common interface and ignored: both backends are always measured. ``workers`` /
    ``dask`` choose where the errors are computed (lavendersim.executor.resolve: None = every
    local core, 1 = this process, or an existing Dask scheduler's address); the timing runs are
    always serial in this process, after the error computation has finished. ``integrators``: the
    lavendersim integrators to measure (None: every built-in one; a user tableau's name measures it on both
    backends, against its declared order)."""
    C.check_backend(backend)
    C.flags(quick=quick, mujoco=mujoco, progress=progress)
    if integrators is not None and (isinstance(integrators, str) or not integrators):
        raise V.LavenderInputError("integrators", "must be a non-empty list of integrator names", f", got {integrators!r}")
    cfg = QUICK if quick else FULL
    t_start = time.perf_counter()
    bar = C.progress(total=None, desc="lab accuracy", unit="run", enabled=progress)

    def say(msg):           # progress lines: on a terminal only, above the bar
        if not bar.disable:
            bar.write(f"[accuracy {time.perf_counter() - t_start:6.1f} s] {msg}", file=sys.stderr)

    # Where the errors are computed is resolved first, so a missing distributed extra or an
    # unreachable scheduler is reported before any work is done.
    ex = X.resolve(workers=workers, dask=dask, feature="lavendersim lab accuracy --dask")
    mj, mj_missing = (None, "skipped (mujoco=False)") if not mujoco else _mujoco()
    use = [cases()[c] for c in cfg["cases"]]
    meths, broken = methods(mj is not None, integrators)
    stamp = machine_stamp(mj)
    for label, why in broken.items():
        say(f"FAILED to run: {label}: {why}")
    say(f"{len(use)} cases x {len(meths)} methods; integrators {integrators or list(B.INTEGRATORS)}; "
        f"adaptive {adaptive_integrators() or 'none'}; MuJoCo {stamp['mujoco'] or 'not available: ' + str(mj_missing)}")
    exacts, figures, rows = _references(use)
    say("exact references agree with DOP853")
    points, drifts, skipped = _sweeps(ex, mj, use, meths, cfg, exacts, bar, say)
    stamp["loadavg_end"] = list(os.getloadavg()) if hasattr(os, "getloadavg") else None
    stamp["errors_computed_on"] = ex.describe()
    stamp["timing"] = "serial, in this process, after the error computation"
    by: dict[tuple[str, str], list[Point]] = {}
    for p in points:
        by.setdefault((p.case, p.method), []).append(p)
    orders = {key: _order(pts) for key, pts in by.items()}
    per_case = verdicts(points)
    checks = C.checks(*[(f"runs_{_key(label)}", False, "holds", None, why) for label, why in broken.items()], *rows,
                      *(row for case in use for row in _case_checks(case, meths, by, orders)),
                      ("verdicts_consistent", verdicts_consistent(points, per_case), "holds", None,
                       "every 'beaten' method's points are each dominated by another method's point; every "
                       "'on the Pareto front' method has an undominated point"))
    names = list(B.INTEGRATORS) if integrators is None else list(integrators)
    result = _result(figures, checks, use, meths, broken, points, drifts, skipped, by, orders, per_case, stamp, mj,
                     mj_missing, cfg, quick, names)
    say(f"done in {time.perf_counter() - t_start:.1f} s")
    return result


def _references(use: list[Case]):
    """The exact motions (Jacobi) of the cases, their distance to DOP853 at T as figures and check rows."""
    exacts, figures, rows = {}, {}, []
    for case in use:
        exact = R.torque_free(case.I_b, case.omega_b0, [0, 0, 0, 1], [0.0, T_END])
        ref = R.dop853(case.I_b, case.omega_b0, [0, 0, 0, 1], [T_END])
        exacts[case.name] = exact
        att = float(R.attitude_error(ref.q[-1], exact.q[-1]))
        dw = float(np.linalg.norm(ref.omega_b[-1] - exact.omega_b[-1]))
        figures[f"reference_vs_dop853_attitude_{case.name}"] = att
        figures[f"reference_vs_dop853_omega_{case.name}"] = dw
        rows.append((f"reference_vs_dop853_{case.name}", max(att, dw), "<=", 1e-10,
                     f"exact (Jacobi) vs DOP853 rtol=atol=1e-13 at T: attitude {att:.2e} rad, "
                     f"omega {dw:.2e} rad/s ({exact.kind})"))
    return exacts, figures, rows


def _sweeps(ex, mj, use, meths, cfg, exacts, bar, say):
    """Every case x method's sweep: errors on the executor, then the timing runs serially here.
    Returns (points, drifts, skipped)."""
    tasks = sweep_tasks(use, meths, cfg, exacts)
    say(f"errors of {len(tasks)} sweeps on {ex.describe()} (timing follows, serially in this process)")
    bar.reset(total=len(tasks))
    bar.set_description("lab accuracy: errors")
    sweeps = C.map_with_progress(ex, measure_sweep, tasks, bar, feature="lavendersim lab accuracy --dask")
    points, jobs, drifts, skipped = [], [], {}, []
    for (case, m, values, _, _), sw in zip(tasks, sweeps):      # in task order, whatever finished first
        points += sw["points"]
        jobs += [None if p.diverged is not None else _timing_job(mj, case, m, p.value) for p in sw["points"]]
        drifts.update(sw["drifts"])
        if sw["skipped"]:
            skipped.append(sw["skipped"])
        say(f"{case.name}: {m.label} ({len(values)} {m.param} values) in {sw['seconds']:.1f} s")
    say(f"timing {sum(j is not None for j in jobs)} runs x {cfg['repeats']} interleaved repeats")
    timed = _time_jobs(jobs, cfg["repeats"], cfg["time_budget"] if cfg["time_budget"] else 0.0, say, bar)
    bar.close()
    for pt, (best, done) in zip(points, timed):
        if pt.ok and done:
            pt.wall_s, pt.repeats = best, done
            pt.wall_per_sim_s = best / T_END
    return points, drifts, skipped


def _order(pts: list[Point]) -> float | None:
    """The convergence order of a sweep; a method accurate enough to leave the window after two dt (splitting4
    on box_w1 reaches 1e-11 at dt = 2^-6): its slope from those two points."""
    o = convergence_order(pts)
    return convergence_order(pts, min_points=2) if o is None else o


def _case_checks(case: Case, meths: list[Method], by: dict, orders: dict) -> list:
    """One case's declared checks: each method's order and convergence, then C = NumPy per integrator."""
    rows = []
    for m in meths:
        pts = [p for p in by.get((case.name, m.label), []) if p.ok]
        if pts:
            rows += _method_checks(case, m, pts, orders[(case.name, m.label)])
    for name in dict.fromkeys(m.integrator for m in meths if m.family == "lavendersim"):
        rows.append(_backends_agree(case, name, by))
    return rows


def _method_checks(case: Case, m: Method, pts: list[Point], o: float | None) -> list:
    """The check rows of one method's sweep in one case (a False row does not apply to this method)."""
    tight = min(pts, key=lambda p: p.value)
    ours, f64 = m.family == "lavendersim", m.dtype == "float64"   # the order checks are float64's (float32 floors)
    fixed_c = ours and f64 and m.param == "dt" and m.backend == "c" and m.order is not None
    # exact here up to rounding at every dt (symtop4 on a symmetric top): no slope to measure
    exact_here = o is None and all(p.attitude_error < ORDER_WINDOW[0] for p in pts)
    tight_err = max(tight.attitude_error, tight.omega_error)
    no_fit = f"; fewer than 2 points with {ORDER_WINDOW[0]:g} < error < {ORDER_WINDOW[1]:g} rad to fit it"
    n = case.name
    return [
        # float32 reaches its rounding floor (~1e-6 rad over 10 s) long before float64's
        m.dtype == "float32" and m.integrator == "rk4" and (
            f"float32_rk4_best_{n}", min(p.attitude_error for p in pts), "<=", 1e-4,
            "float32 RK4 [c]: best attitude error over the dt sweep, rad (float64's reaches 1e-9; the rounding floor "
            "of float32 over the run is ~1e-6)"),
        fixed_c and exact_here and (f"order_{m.integrator}_{n}_below_window", max(p.attitude_error for p in pts), "<=",
                                    ORDER_WINDOW[0], "every dt's attitude error below the order window: exact up to "
                                    "rounding here, the order is not measurable"),
        fixed_c and not exact_here and (f"order_{m.integrator}_{n}", math.nan if o is None else o, "≈",
                                        (m.order, ORDER_TOL), "slope of log attitude error vs log dt, C backend"
                                        + ("" if o is not None else no_fit)),
        ours and f64 and m.integrator == "rk4" and m.backend == "c" and (
            f"rk4_smallest_dt_{n}", tight_err, "<=", 1e-9, f"RK4 [c] at dt = {_param_text('dt', tight.value)}: attitude "
            f"{tight.attitude_error:.2e} rad, omega {tight.omega_error:.2e} rad/s"),
        # an adaptive method converges to the same reference: global error within 100 x rtol
        f64 and m.param == "rtol" and (
            f"tightest_rtol_{_key(m.label)}_{n}", tight.attitude_error, "<=",
            max(ADAPTIVE_ERROR_FACTOR * tight.value, ERROR_FLOOR), f"{m.label} at rtol = {tight.value:.0e}: attitude "
            f"error within {ADAPTIVE_ERROR_FACTOR:g} x rtol of the exact solution"),
        m.family == "mujoco" and m.integrator == "RK4" and (
            f"mujoco_rk4_smallest_dt_{n}", tight_err, "<=", 1e-8, f"MuJoCo RK4 converges to the exact solution "
            f"(attitude {tight.attitude_error:.2e} rad, omega {tight.omega_error:.2e} rad/s)"),
        m.family == "mujoco" and m.order is not None and (
            f"mujoco_{m.integrator.lower()}_order_{n}", math.nan if o is None else o, "≈", (m.order, ORDER_TOL),
            "MuJoCo: slope of log attitude error vs log dt"),
    ]


def _backends_agree(case: Case, name: str, by: dict):
    """The check row C = NumPy of integrator ``name`` at every dt (rtol) both measured in ``case`` (or False)."""
    pc = {p.value: p for p in by.get((case.name, f"{name} [c]"), [])}
    pn = {p.value: p for p in by.get((case.name, f"{name} [numpy]"), [])}
    common = set(pc) & set(pn)
    if not common:
        return False
    worst, allow = 0.0, 1e-9   # the largest difference over its allowance; one algorithm on both backends
    for v in common:
        a, b = pc[v], pn[v]
        if a.ok != b.ok:
            worst = math.inf
        elif a.ok:
            xa, xb = np.array(a.final_x), np.array(b.final_x)
            d = max(float(R.attitude_error(xa[C.Q], xb[C.Q])), float(np.linalg.norm(xa[C.OMEGA_B] - xb[C.OMEGA_B])))
            worst = max(worst, d / allow)
    return (f"backends_agree_{name}_{case.name}", worst, "<=", 1.0, f"max over {len(common)} common points of the "
            "C vs NumPy difference at T (attitude rad, omega rad/s) over its allowance 1e-9 (same algorithm)")


def _summary_table(use, meths, by, orders, overall) -> list[dict]:
    """One row per method: verdict, median order, the cost to reach 1e-3/1e-6/1e-9 rad, best error, drifts."""
    table = []
    for m in meths:
        pts = {c.name: by.get((c.name, m.label), []) for c in use}
        row = {"method": m.label, "param": m.param, "verdict": overall[m.label]["verdict"],
               "verdict_text": overall[m.label]["text"]}
        os_ = [orders[(c.name, m.label)] for c in use if orders.get((c.name, m.label)) is not None]
        row["order"] = float(np.median(os_)) if os_ else None
        for tol in (1e-3, 1e-6, 1e-9):
            cs = _worst([cost_to_reach(pts[c.name], tol) for c in use])
            es = _worst([cost_to_reach(pts[c.name], tol, "rhs_evals") for c in use])
            row[f"us_per_sim_s_to_{tol:.0e}"] = None if cs is None else 1e6 * cs
            row[f"rhs_evals_to_{tol:.0e}"] = None if es is None else int(es)
        errs = [p.attitude_error for c in use for p in pts[c.name] if p.ok]
        row["best_attitude_error"] = max(min(p.attitude_error for p in pts[c.name] if p.ok)
                                         for c in use) if errs else None
        drift_at = 2.0 ** -DRIFT_DT_EXP if m.param == "dt" else DRIFT_RTOL
        dr = [p for c in use for p in pts[c.name] if p.ok and abs(p.value - drift_at) <= 1e-9 * p.value]
        row["energy_drift_at_drift_point"] = max(p.energy_drift for p in dr) if dr else None
        row["momentum_drift_at_drift_point"] = max(p.momentum_drift for p in dr) if dr else None
        table.append(row)
    return table


def _result(figures, checks, use, meths, broken, points, drifts, skipped, by, orders, per_case, stamp, mj, mj_missing,
            cfg, quick, names) -> C.LabResult:
    """The LabResult: figures (verdicts, orders, the table's lines), parameters and the nested data."""
    labels = [m.label for m in meths]
    per_case_rhs = verdicts([p for p in points if p.rhs_evals is not None], cost="rhs_evals")
    overall = overall_verdicts(per_case, labels)
    table = _summary_table(use, meths, by, orders, overall)
    table_text = format_table(table)
    meth_of = {m.label: m for m in meths}
    for label, why in broken.items():
        figures[f"failed_{_key(label)}"] = why
    figures["float32"] = ("measured: " + ", ".join(f"{n} [c float32]" for n in getattr(B, "FLOAT32_INTEGRATORS", ()))
                          + " (Sim(dtype='float32'), C backend; NumPy's float32 is bitwise C's)")
    figures["mujoco"] = (f"measured (mujoco {stamp['mujoco']})" if mj is not None
                         else f"not measured: {mj_missing}; {extra_command('bench')}")
    for m in meths:
        figures[f"verdict_{_key(m.label)}"] = overall[m.label]["text"]
    for (case, label), o in sorted(orders.items()):
        if o is not None and meth_of[label].param == "dt":
            figures[f"order_{_key(label)}_{case}"] = o
    for i, line in enumerate(table_text.splitlines()):
        figures[f"table_{i:02d}"] = line
    if skipped:
        figures["numpy_sweep_shortened"] = "; ".join(skipped)
    params = {
        "mode": "quick" if quick else "full", "cases": ", ".join(f"{c.name}: {c.label}" for c in use), "T": T_END,
        "mass": MASS, "integrators": ", ".join(names), "adaptive": ", ".join(adaptive_integrators()) or "none",
        "dt_sweep": ", ".join(_param_text("dt", 2.0 ** -k) for k in cfg["dt_exps"]),
        "numpy_dt_sweep": ", ".join(_param_text("dt", 2.0 ** -k) for k in cfg["numpy_dt_exps"]),
        "rtol_sweep": ", ".join(f"{r:.0e}" for r in cfg["rtols"]), "repeats": cfg["repeats"],
        "error_floor": ERROR_FLOOR, "error_ceiling": ERROR_CEILING,
        "cpu": stamp["cpu"], "logical_cores": stamp["logical_cores"], "git_commit": stamp["git_commit"],
        "versions": f"python {stamp['python']}, numpy {stamp['numpy']}, scipy {stamp['scipy']}, "
                    f"mujoco {stamp['mujoco']}, {stamp['compiler']}",
    }
    plot_data = {"use": use, "meths": meths, "points": points, "drifts": drifts, "per_case": per_case,
                 "per_case_rhs": per_case_rhs}
    plots = {name: functools.partial(_plot_one, name) for name in PLOT_NAMES}
    rk4 = [f"order_rk4_c_{c.name}" for c in use if f"order_rk4_c_{c.name}" in figures]
    result = C.make_result(NAME, figures, params, checks, plots, plot_data,
                           headline=(rk4[0], f"4 ± {ORDER_TOL:g} (RK4's order, C backend)") if rk4 else None)
    result.mode = f"{'quick' if quick else 'full'} sweep" + ("; `lab accuracy` runs the full one" if quick else "")
    # the nested data: added to the returned dict and written into the same results.json
    result["machine"] = stamp
    result["table"] = table
    result["verdicts"] = {"by_wall_time": {"overall": overall, "per_case": per_case},
                          "by_rhs_evals": {"per_case": per_case_rhs},
                          "definition": {"metric": "attitude error at T (rad) vs wall time per simulated second",
                                         "dominates": "another method's point with error <= (clamped at the floor) "
                                                      "and time < t / (1 + time_margin), or error < and time <= "
                                                      "t (1 + time_margin)",
                                         "time_margin": TIME_MARGIN,
                                         "error_floor": ERROR_FLOOR, "error_ceiling": ERROR_CEILING}}
    result["methods"] = [{"label": m.label, "family": m.family, "integrator": m.integrator, "backend": m.backend,
                          "param": m.param, "stages": m.stages} for m in meths]
    result["points"] = [_point_json(p) for p in points]
    result["drift_series"] = [{"case": c, "method": lab, **d} for (c, lab), d in drifts.items()]
    result.extra_files["points.csv"] = _points_csv(points)
    return result


def _points_csv(points: list[Point]) -> str:
    f = io.StringIO(newline="")
    w = csv.DictWriter(f, fieldnames=[k for k in _point_json(points[0]) if k != "final_x"], extrasaction="ignore")
    w.writeheader()
    for p in points:
        w.writerow(_point_json(p))
    return f.getvalue()


def _key(label: str) -> str:
    return "".join(ch if ch.isalnum() else "_" for ch in label.lower()).strip("_").replace("__", "_")


def _point_json(p: Point) -> dict:
    """The point's fields, in order, as results.json and points.csv hold them (a float not measured or not finite: null)."""
    return {k: C.finite_or_none(v) if isinstance(v, float) else v for k, v in asdict(p).items()}


def verdicts_consistent(points: list[Point], per_case: dict) -> bool:
    """Recheck every verdict against the points directly (independent of `verdicts`' bookkeeping)."""
    for case, per in per_case.items():
        eligible = [p for p in points if p.case == case and p.ok and p.wall_per_sim_s is not None
                    and p.attitude_error <= ERROR_CEILING]
        for method, v in per.items():
            mine = [p for p in eligible if p.method == method]
            others = [p for p in eligible if p.method != method]

            def dom(p):
                return any(dominates(o.attitude_error, o.wall_per_sim_s, p.attitude_error, p.wall_per_sim_s)
                           for o in others)
            if v["verdict"] == "beaten" and not (mine and all(dom(p) for p in mine)):
                return False
            if v["verdict"] == "on the Pareto front" and all(dom(p) for p in mine):
                return False
            if v["verdict"] == "out of range" and mine:
                return False
    return True


def _fmt(x, unit="") -> str:
    if x is None:
        return "-"
    if isinstance(x, int):
        return f"{x:d}"
    return f"{x:.3g}{unit}"


def format_table(table: list[dict]) -> str:
    head = (f"{'method':<26} {'order':>5} {'us/sim-s to 1e-3':>16} {'to 1e-6':>9} {'to 1e-9':>9} "
            f"{'RHS to 1e-6':>11} {'best err':>9} {'E drift':>9} {'L drift':>9}  verdict")
    lines = [head, "-" * len(head)]
    for r in table:
        lines.append(f"{r['method']:<26} {_fmt(r['order']):>5} {_fmt(r['us_per_sim_s_to_1e-03']):>16} "
                     f"{_fmt(r['us_per_sim_s_to_1e-06']):>9} {_fmt(r['us_per_sim_s_to_1e-09']):>9} "
                     f"{_fmt(r['rhs_evals_to_1e-06']):>11} {_fmt(r['best_attitude_error']):>9} "
                     f"{_fmt(r['energy_drift_at_drift_point']):>9} {_fmt(r['momentum_drift_at_drift_point']):>9}  "
                     f"{r['verdict_text']}")
    lines.append("order: median over cases of the slope of log attitude error vs log dt (vs log rtol for "
                 "adaptive/scipy); us/sim-s to X: worst case over cases of the cheapest wall time per simulated "
                 "second (us) with attitude error <= X rad; RHS to 1e-6: evaluations over T; best err: worst case "
                 f"of the smallest attitude error reached (rad); E/L drift: max relative drift at dt = 2^-{DRIFT_DT_EXP} s "
                 f"or rtol = {DRIFT_RTOL:.0e} (worst case)")
    return "\n".join(lines)


# ------------------------------------------------------------------------------------------ plots

_FAMILY_STYLE = {"c": "-", "numpy": "--", "scipy": ":", "mujoco": "-."}
_F32_STYLE = ":"          # float32 differs from float64 in line style and hollow markers, not only in label
_REFERENCE = ("rk4",) + B.ADAPTIVE   # the classic method and the adaptive one(s): grey on the peers' panels, for scale


def _styles(meths) -> dict:
    """Colour and marker per integrator (or peer), from the Okabe–Ito palette: every pair differs."""
    names = []
    for m in meths:
        key = m.integrator if m.family == "lavendersim" else m.label
        if key not in names:
            names.append(key)
    colors = [c for c in F.CYCLE if c != F.YELLOW]        # yellow is too faint for a line on white
    return {n: {"color": colors[i % len(colors)], "marker": F.MARKERS[i % len(F.MARKERS)]} for i, n in enumerate(names)}


PLOT_NAMES = ("work_precision_time.png", "work_precision_rhs.png", "work_precision_omega.png", "drift_vs_time.png")

# the work-precision plots' columns: which methods each panel draws (split by backend and precision)
_GROUPS = (("C backend: float64 solid, float32 dotted (hollow)", lambda m: m.backend == "c"),
           ("NumPy backend (dashed)", lambda m: m.backend == "numpy"),
           ("peers: scipy dotted, MuJoCo dash-dot; grey: C rk4, dopri5", lambda m: m.backend in ("scipy", "mujoco")))


def _legend(styles) -> tuple[list, list]:
    """One entry per integrator or peer (colour + marker), then what the line styles mean."""
    from matplotlib.lines import Line2D

    handles = [Line2D([], [], color=s["color"], marker=s["marker"], ms=4, ls="-") for s in styles.values()]
    labels = list(styles)
    for ls, mfc, text in (("-", F.BLACK, "C, float64"), (_F32_STYLE, "none", "C, float32"), ("--", F.BLACK, "NumPy"),
                          (":", F.BLACK, "scipy"), ("-.", F.BLACK, "MuJoCo")):
        handles.append(Line2D([], [], color=F.BLACK, marker="o", ms=4, mfc=mfc, ls=ls))
        labels.append(text)
    return handles, labels


def _plot_one(name: str, d: dict, ax=None):
    """One PNG of the study, drawn from the result's data (LabResult.figure; ``ax``: that plot's axes)."""
    return make_plots(d["use"], d["meths"], d["points"], d["drifts"], d["per_case"], d["per_case_rhs"], only=name,
                      ax=ax)[name]


def _draw_method(ax, m, pts, xkey, xscale, ykey, style, front, grey=False):
    pts = sorted(pts, key=lambda p: -p.value)          # along the sweep: coarse to fine
    x = np.array([getattr(p, xkey) for p in pts]) * xscale
    y = np.maximum([getattr(p, ykey) for p in pts], 1e-17)
    f32 = m.dtype == "float32"
    kw = dict(color=F.GREY if grey else style["color"], marker=style["marker"], ms=4,
              mfc="none" if f32 or grey else style["color"], lw=1.0 if grey else 1.3,
              ls=_F32_STYLE if f32 else _FAMILY_STYLE[m.backend], zorder=1 if grey else 2)
    ax.loglog(x, y, label=None if grey else m.label, **kw)
    on = np.array([p.value in front for p in pts], bool)
    if on.any() and not grey:
        ax.loglog(x[on], y[on], "o", color=style["color"], ms=9, mfc="none", mew=1.5)


def make_plots(use, meths, points, drifts, per_case, per_case_rhs, only: str | None = None, ax=None) -> dict:
    """The PNGs. Work-precision: one row per case, one column per backend (C float64 and float32,
    NumPy, the peers); big circles are points of methods on the front of that plot's own verdict
    (attitude error vs time, or vs RHS evaluations); the omega plot marks none. ``ax``: with ``only``,
    the axes to draw that plot into (rows × columns of it, in row order)."""
    styles = _styles(meths)
    plots = {}
    specs = (("work_precision_time.png", "wall_per_sim_s", 1e6, "wall time per simulated second (µs)",
              "attitude_error", "attitude error at T (rad)", True),
             ("work_precision_rhs.png", "rhs_evals", 1.0, "RHS evaluations over T = 10 s",
              "attitude_error", "attitude error at T (rad)", False),
             ("work_precision_omega.png", "wall_per_sim_s", 1e6, "wall time per simulated second (µs)",
              "omega_error", "|ω(T) − ω_exact(T)| (rad/s)", True))
    for spec in specs:
        if only is None or spec[0] == only:
            marks = {"wall_per_sim_s": per_case, "rhs_evals": per_case_rhs}[spec[1]] if spec[4] == "attitude_error" else {}
            plots[spec[0]] = _work_precision_figure(spec, use, meths, points, marks, styles, ax)
    if only in (None, "drift_vs_time.png"):
        plots["drift_vs_time.png"] = _drift_figure(use, meths, drifts, styles, ax)
    return plots


def _work_precision_figure(spec, use, meths, points, marks, styles, ax=None):
    """One work-precision PNG (``spec``: file, x key, x scale, x label, y key, y label, NumPy shown)."""
    from matplotlib.ticker import NullFormatter

    _, xkey, xscale, xlabel, ykey, ylabel, both_backends = spec
    n = len(use)
    groups = [g for g in _GROUPS if both_backends or "NumPy" not in g[0]]    # numpy: the C counts and errors
    ncols = len(groups)
    fig, axes = C.new_figure(n, ncols, size=(5.0 * ncols + 2.6, 3.7 * n + 0.6), ax=ax,
                             title=f"{ylabel.split(' (')[0]} vs {xlabel.split(' (')[0]}, torque-free, T = {T_END:g} s"
                                   + ("" if both_backends else " (NumPy: the same counts and errors as C)"))
    for k, case in enumerate(use):
        for j, (gtitle, member) in enumerate(groups):
            a = axes[k, j]
            peers = "peers" in gtitle
            for m in meths:
                grey = peers and m.backend == "c" and m.integrator in _REFERENCE and m.dtype == "float64"
                if not (member(m) or grey):
                    continue
                pts = [p for p in points if p.case == case.name and p.method == m.label and p.ok
                       and getattr(p, xkey) is not None and getattr(p, ykey) is not None]
                if not pts:
                    continue
                key = m.integrator if m.family == "lavendersim" else m.label
                front = set(marks.get(case.name, {}).get(m.label, {}).get("overall_front_points", []))
                _draw_method(a, m, pts, xkey, xscale, ykey, styles[key], front, grey=grey)
            if ykey == "attitude_error":
                a.axhline(ERROR_CEILING, color=F.GREY, lw=0.6, ls=":")
                a.axhline(ERROR_FLOOR, color=F.GREY, lw=0.6, ls=":")
            a.set_xlabel(xlabel)
            if j == 0:
                a.set_ylabel(f"{case.label}\n{ylabel}", fontsize=9)
            if k == 0:
                a.set_title(gtitle, fontsize=9)
            a.grid(True, which="major", alpha=0.3)
        for j in range(1, ncols):                          # one y range per case row
            axes[k, j].sharey(axes[k, 0])
    for a in axes.ravel():
        a.xaxis.set_minor_formatter(NullFormatter())      # a decade or less: no crowded minor labels
    if ax is None:
        fig.legend(*_legend(styles), loc="outside right center", fontsize=7,
                   title=("circled: the case's Pareto front\n" if ykey == "attitude_error" else "")
                   + "colour + marker: the integrator", title_fontsize=7)
    return fig


def _drift_figure(use, meths, drifts, styles, ax=None):
    """drift_vs_time.png: relative energy and world-L drift over the run, a column per case."""
    n = len(use)
    fig, axes = C.new_figure(2, n, size=(max(4.2 * n + 3, 9.0), 8), ax=ax,
                             title=f"relative drift over the run\n(C backend at dt = 2^-{DRIFT_DT_EXP} s; "
                                   f"rtol = {DRIFT_RTOL:.0e} for adaptive/scipy; MuJoCo at dt = 2^-{DRIFT_DT_EXP} s)")
    for k, case in enumerate(use):
        for row, what in enumerate(("energy", "momentum")):
            a = axes[row, k]
            shown = [m for m in meths if m.backend != "numpy"]
            for i, m in enumerate(shown):
                d = drifts.get((case.name, m.label))
                if not d:
                    continue
                key = m.integrator if m.family == "lavendersim" else m.label
                yv = np.asarray(d[what], float)
                # methods whose drifts coincide (euler and MuJoCo Euler, rk4 and rk4_expmap) stay visible: the
                # earlier in the list, the wider the line underneath
                st = styles[key]
                a.semilogy(d["t"], np.where(yv > 0, yv, np.nan), _F32_STYLE if m.dtype == "float32" else _FAMILY_STYLE[m.backend],
                           color=st["color"], marker=st["marker"], markevery=max(1, len(yv) // 8), ms=4, mfc="none",
                           lw=4.0 - 3.2 * i / max(1, len(shown) - 1), label=m.label.replace(" [c]", ""))
            a.set_xlabel("time t (s)")
            a.set_ylabel("|E(t) − E(0)| / E(0)" if what == "energy" else "|L_w(t) − L_w(0)| / |L_w(0)|")
            a.set_title(f"{case.label}: {what}", fontsize=9)
            a.grid(True, alpha=0.3)
    if ax is None:
        handles, labs_ = axes[0, 0].get_legend_handles_labels()
        fig.legend(handles, labs_, loc="outside right center", fontsize=7)
    return fig
