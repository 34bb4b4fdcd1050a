"""The simulator: steps a scene's bodies with a chosen integrator on a chosen backend.

The scene is read once at construction (bodies, initial states, declared effects); later edits to
the scene do not affect an existing Sim. Times in s.

Joints and reaction wheels: a body's mass and I_b are the whole body with its wheels locked, about
its COM. With a spherical_joint at anchor a, the Sim fixes r_b = R^T (p_w − a) (pivot → COM, body
frame) from the body's initial state and I_p = parallel_axis(diag(I_b), m, −r_b); the body's p_w,
v_w then follow the joint (pivot_kinematics) and are not integrated. A wheeled body without a joint
rotates about its COM (I_p = diag(I_b), r_b = 0) and translates freely. Wheel commands are held
(zero-order) until changed and saturated at the start of every step.

Integrators (`integrator=`; `sim.rhs_evals` counts right-hand-side evaluations, cumulative):

* "euler", "semi_implicit_euler" (1 evaluation per step), "rk4" (4): fixed step dt, any body.
* "dopri5": adaptive Dormand–Prince 5(4) with FSAL and error control (`rtol`, default 1e-6; `atol`,
  default 1e-9; the error of each accepted substep is at most 1 in Hairer's RMS norm of
  err_i / (atol + rtol max(|y_i|, |y_new_i|)) over the body's numbers). dt is the output interval:
  every step advances exactly dt with as many accepted substeps as needed (controller: safety 0.9,
  growth in [0.2, 5], no growth right after a rejection; the proposal is kept between steps). A
  substep below dt·1e-12, or more than 10⁶ substeps in one step, raises DivergenceError naming the
  step and body ("could not meet rtol/atol"). Any body (joints and wheels too; wheel torques held
  over each dt). Each body chooses its own step sizes, on both backends by the same algorithm (the
  NumPy backend mirrors C's operation for operation: the results are bitwise equal, per-body step
  sizes and counts too). rhs_evals is the largest per-body count — per body for a single body. Dense
  output (a body without wheels): the integrator steps on past each output time and the state there
  is read off the Dormand–Prince continuous extension (order 4; q normalized), so an output interval
  forces no substep (step() after step() costs about what run(n) costs); it carries on across calls
  while the state is the one the last call wrote (a state written in between, or set_effect_params,
  starts afresh with one evaluation). A body with wheels lands on every output time (its held torque
  may change there) and starts each output step with a fresh evaluation. FSAL otherwise: the last
  stage is the next substep's first. q is normalized after every accepted substep.
* "splitting": second-order Strang splitting of the free rigid body into the exact flows of
  L_a²/(2I_a) about the principal axes, 1(h/2) 2(h/2) 3(h) 2(h/2) 1(h/2) (q by exact axis rotations,
  unit by construction; torque-free, world L and |L_b| conserved to rounding, energy oscillates
  boundedly), effects as half kicks of v and ω (explicit midpoint when damping makes them depend
  on v or ω), p drifted by h v. Plain bodies only (no spherical_joint / reaction_wheels).
* "implicit_gyro": the gyroscopic term implicit in the body frame, I(ω⁺ − ω)/dt + ω⁺ × Iω⁺ = τ_b,
  solved by Newton's method to rounding (Catto, GDC 2015; Bullet's implicit gyroscopic force);
  q ← q ⊗ exp(dt ω⁺/2); v, p semi-implicit Euler; loads at the start of the step. First order; a
  torque-free step never gains energy (E − E⁺ = ½(ω − ω⁺)ᵀI(ω − ω⁺)), stable at large |ω|·dt.
  Plain bodies only.
* "splitting4": fourth order, Suzuki's symmetric composition of the splitting step, steps γ h with
  γ = (p, p, 1 − 4p, p, p), p = 1/(4 − 4^(1/3)) (Suzuki, Phys. Lett. A 146 (1990) 319). Torque-free:
  world L, |L_b| and |q| conserved to rounding like splitting (the five substeps' axis flows applied
  as one sequence of 21 exact rotations). Effects as in splitting, per substep: order 4 with loads
  that depend on position and attitude only, order 3 with a velocity-dependent effect (damping: the
  midpoint kick is not symmetric). rhs_evals: 5 per step torque-free, 5 × splitting's with effects.
  Plain bodies only. Like splitting it never overflows: keep |ω|·dt below ~1 for accuracy.
* "rk4_expmap": RK4 in the exponential coordinates of the attitude (Runge–Kutta–Munthe-Kaas, order 4):
  each stage's attitude is q0 ⊗ exp(u/2), u̇ = ω + ½ u × ω + (1/12) u × (u × ω), and the step ends
  with q = q0 ⊗ exp(u/2): unit to rounding even with normalize=False; p, v, ω exactly as RK4's
  stages. 4 evaluations per step; its stability limit is RK4's (|ω|·dt ≲ 1 for the gyroscopic term).
  Plain bodies only.

* "symtop4": fourth order, the free rigid body split around a symmetric top about the intermediate
  axis r, H = |L|²/(2 I_r) + ½ c_a L_a² + ½ c_b L_b² (c_i = 1/I_i − 1/I_r): exact sphere and axis
  flows (17 rotations per step torque-free), composed with splitting4's Suzuki coefficients. Exact for
  a symmetric top (c_b = 0); torque-free, world L, |L_b| and |q| conserved to rounding. Effects as
  splitting4's, per stage: order 4 with loads of position and attitude only, order 3 with damping.
  rhs_evals counted as splitting4's. Plain bodies only; validity bound splitting4's.
* "symtop_bm6": sixth order, symtop4's split composed by Blanes & Moan's optimized 10-stage order-6
  splitting (S10, J. Comput. Appl. Math. 142 (2002) 313): 21 exact axis flows and one sphere flow per
  step torque-free; world L, |L_b| and |q| conserved to rounding, exact for a symmetric top. Effects:
  symtop4's kicked stages around this rotation (order 4 with loads of position and attitude, 3 with
  damping). rhs_evals counted as symtop4's. Plain bodies only; validity bound symtop4's.

Precision (`dtype=`, keyword only): "float64" (default) or "float32". float32 steps the single-precision
printing of the same SymPy kernels (C: csrc/step_f32.c on generated/kernels_f32.c, vectorized over bodies;
NumPy: generated/kernels_numpy_f32.py; the two agree bitwise) for euler, semi_implicit_euler and rk4 on plain
bodies with built-in effects; the state, its views, state() and record() are float32 (the divergence checks
evaluate in float64; step() takes the Python path). Anything else with float32 raises LavenderInputError.

Unsupported combinations (splitting / implicit_gyro / splitting4 / rk4_expmap / symtop4 / symtop_bm6 with a joint or wheels;
rtol/atol with a fixed-step integrator) raise LavenderInputError at construction.

Divergence before infinity (checked per chunk of steps, so the stepping itself is unchanged bit for bit):
a run is advanced in chunks of about CHUNK_WORK right-hand-side evaluations (on the C backend with a fixed-step
integrator at least CHUNK_MIN_STEPS_C steps within CHUNK_WORK_MAX evaluations, CHUNK_WORK_MAX_PLAIN for a scene of
plain bodies without effects, CHUNK_WORK_MAX_EFFECTS for plain bodies with effects; NumPy CHUNK_MIN_STEPS within
CHUNK_WORK_MAX_NUMPY); after each chunk every body
is checked against

* its integrator's validity bound, |omega|*dt*(I_max/I_min)**p <= WDT_MAX (declared once in
  derive/tableaux.py, printed in generated/tableaux.py; dopri5 has none): beyond it the run raises
  DivergenceError naming the bound, or with on_bound="warn" warns once per body (ValidityBoundWarning);
* for a body no effect acts on (torque- and force-free): its kinetic energy and |L| may not grow beyond
  max_growth times their values at construction / the last set_state (default 2; None: off); a wheeled
  body without a joint and without other effects: its total |L| (body + wheels) likewise.

A chunk that fails a check (or goes non-finite) is re-run from its start in smaller pieces to find the
first step whose state fails (the states are recomputed bit for bit; for dopri5, whose FSAL stage does
not carry across calls, to the tolerance). DivergenceError then names the step, the body and the
cause, and the Sim is left exactly as it was before the call — for run, run_for and record alike (and on
KeyboardInterrupt, which a long run sees between chunks). A Sim steps under its own lock: two threads
stepping one Sim serialize (never a lost step); two Sims run in parallel (the C loop releases the GIL).
n_steps per call is at most MAX_STEPS.

On the C backend a small scene (at most FAST_STEP_WORK right-hand-side evaluations per step, fixed-step
integrators, no free wheeled body under the growth check) takes step() and run(n) for n up to one chunk
inside C (lavendersim/csrc/fast_step.c): the same step, finiteness, bound and growth checks and restore, bit for
bit; anything it cannot prove passes (a check fails, the state was written since the last check, another thread
holds the Sim) goes to the Python path above, which raises or warns. The state is read through zero-copy
read-only views (x, p_w, q, v_w, omega_b, Omega, wheel_torques_applied); set_state is the writer.
"""
from __future__ import annotations

import os
import sys
import threading
import types
import warnings
import weakref
from collections.abc import Sequence

import numpy as np

from . import backends
from . import effects as effects_mod
from . import validate as V
from .backends import ADAPTIVE, KIND_JOINT, KIND_WHEELS, PLAIN_ONLY, Adaptive, Models
from .bodies import BodyState
from . import load_checks
from . import pipeline as pipeline_mod
from .errors import DivergenceError, ValidityBoundWarning
from .frames import public_rows
from .generated import effects_meta as _META
from .generated import layout as LY
from .kernels import K
from .scene import Scene, _Batch, _EffectList, _effect_rows, _name_index
from .sim_model import SimModel

MAX_STEPS = 2**53          # steps per call and in total: the step counter and t = steps*dt stay exact in float64
CHUNK_WORK = 2**20         # right-hand-side evaluations (summed over bodies) per backend call between checks
CHUNK_MIN_STEPS = 64       # NumPy backend, fixed step: a chunk is at least this many steps (a call's setup and checks,
CHUNK_WORK_MAX = 2**25     # ~60-100 ns per body, then cost ~1-2 ns per body-step; C: CHUNK_MIN_STEPS_C) within this many evaluations (the
                           # latency of KeyboardInterrupt: ~0.1 s for plain RK4 bodies, ~4 s for wheeled ones)
CHUNK_WORK_MAX_PLAIN = 2**30   # the same for plain bodies without effects (the SIMD tiles, ~1.2 ns per evaluation):
CHUNK_WORK_MAX_EFFECTS = 2**28   # the same for plain bodies with effects (no joint, no wheels: the SIMD effect tiles,
                           # ~1.2-3.5 ns per evaluation; a user effect's stage passes ~8): at 1e5 bodies 256 steps
                           # (0.1-0.4 s), at 1e6 67. Within CHUNK_WORK_MAX the chunk was 83 steps at 1e5 and its ~40 ns
                           # per body cost showed: gravity 5.40 against 4.81 ns per body-step, applied torque 8.32
                           # against 7.73, where plain bodies read 4.56 either way (Sim.run of whole chunks, one process,
                           # interleaved; /work/notes/s24/lead/chunk_probe.py; issue 30's "flat in N")
CHUNK_MIN_STEPS_C = 256    # C: at least this many steps (any fixed-step scene, within its cap: the same for plain and
                           # effect bodies, whose bench lines compare them): at 1e6 plain bodies 256 steps (~1.2 s); at 8 the C call
                           # streaming the state in and out and the check reading it cost 1.3-1.4x the stepping; at 64
                           # ~40 ns per body and chunk still, ~10 % (ns per body-step, Sim.run of one chunk, N = 1e4 /
                           # 1e5 / 1e6: 5.08 / 5.07 / 5.05 at 64 steps, 4.60 / 4.56 / 4.57 at 256, 4.5 at 512; issue 30)
CHUNK_WORK_MAX_NUMPY = 2**23   # the NumPy backend, fixed step: long chunks within this many evaluations (RK4 at 1e5
                           # bodies: 20 steps, ~0.5 s torque-free, ~1.2 s with effects; at 2 steps per call its
                           # check cost ~0.6x the stepping, H3's measurement, issue 30)
ON_BOUND = ("raise", "warn")
CONTRACT = ("off", "fma")  # Sim(contract=...): the torque-free SIMD tiles bitwise (default) or with fused multiply-adds
CHECK_BLOCK = 1 << 16       # bodies per kernel call when the checks read every body: bounded temporaries at 1e6
FAST_STEP_WORK = 4096      # step() runs inside C (holding the GIL) for scenes of at most this many evaluations per step
ADAPTIVE_STEP_WORK = 6     # an adaptive integrator's evaluations per body-step for that cap: one dopri5 substep


def chunk_steps(work: int, long_ok: bool, cap: int | None = None, min_steps: int | None = None) -> int:
    """Steps per backend call between checks: CHUNK_WORK's worth, and with long_ok at least min_steps (default
    CHUNK_MIN_STEPS) as long as that stays within cap evaluations (large scenes, whose checks and C setup per call
    would otherwise be paid every step or two).

    Parameters
    ----------
    work : int
        Right-hand-side evaluations per step, summed over the bodies.
    long_ok : bool
        The C or NumPy backend with a fixed-step integrator (their results do not depend on the chunk edges).
    cap : int, optional
        The most evaluations a long chunk takes (default CHUNK_WORK_MAX).
    min_steps : int, optional
        The steps a long chunk takes at least within cap (default CHUNK_MIN_STEPS).

    Returns
    -------
    int
        Steps per chunk, >= 1.
    """
    work = max(1, work)
    n = max(1, CHUNK_WORK // work)
    least = CHUNK_MIN_STEPS if min_steps is None else min_steps
    return max(n, min(least, (CHUNK_WORK_MAX if cap is None else cap) // work)) if long_ok else n


def _read_only_views(x: np.ndarray, Omega: np.ndarray, applied: np.ndarray) -> tuple[np.ndarray, ...]:
    """(x, p_w, q, v_w, omega_b, Omega, applied) as read-only views sharing memory with the arrays. Each is a view
    over a read-only memoryview of the array, so NumPy refuses to turn their WRITEABLE flag back on."""
    def ro(a: np.ndarray) -> np.ndarray:
        return np.frombuffer(a.data.toreadonly(), dtype=a.dtype).reshape(a.shape)

    xr = ro(x)
    return (xr, xr[:, LY.STATE_P_W], xr[:, LY.STATE_Q], xr[:, LY.STATE_V_W], xr[:, LY.STATE_OMEGA_B], ro(Omega), ro(applied))


class _Counters:
    """steps and rhs_evals of a Sim without the C stepper (which keeps them itself)."""

    __slots__ = ("steps", "rhs_evals")

    def __init__(self):
        self.steps = 0
        self.rhs_evals = 0


class _Guard:
    """The Sim's lock (reentrant); while held it marks the C stepper busy, so its fast path steps aside."""

    __slots__ = ("_lock", "_fast")

    def __init__(self, fast):
        self._lock, self._fast = threading.RLock(), fast

    def __enter__(self):
        self._lock.acquire()
        if self._fast is not None:
            self._fast.busy += 1
        return self

    def __exit__(self, *exc):
        if self._fast is not None:
            self._fast.busy -= 1
        self._lock.release()
        return False


def validity_bound(integrator: str) -> tuple[float, float] | None:
    """The validity bound of an integrator: ``backends.validity_bound`` of the name as ``Sim`` resolves it.

    Parameters
    ----------
    integrator : str
        A built-in integrator's name or a user tableau's (found in the user directory and loaded, as ``Sim`` does).

    Returns
    -------
    tuple of (float, float) or None
        ``(WDT_MAX, WDT_RATIO_EXPONENT)``, or None for an integrator that declares no bound (adaptive ones).

    Raises
    ------
    LavenderInputError
        For a name that is neither built in nor a user's tableau (before, an unloaded user tableau gave None).
    """
    return backends.validity_bound(_integrator(integrator))


def _integrator(name) -> str:
    """A built-in integrator's name, or a user tableau's (registered, or found in the user directory and loaded:
    lavendersim.extending.tableau); else LavenderInputError naming the known ones."""
    if isinstance(name, str) and name not in backends.INTEGRATORS:
        from . import extending

        return extending.tableau(name).name
    return V.choice("integrator", name, backends.INTEGRATORS)


def _check_blocks(mask: np.ndarray):
    """The bodies the boolean mask (nb,) selects, as (selector, count) blocks of at most CHECK_BLOCK bodies: a slice
    where a block is wholly selected (views, not copies), else the block's selected indices. The checks' kernels
    run block by block, so their temporaries stay small at any N (peak memory at 1e6 bodies, issue 30)."""
    n = len(mask)
    for a in range(0, n, CHECK_BLOCK):
        b = min(a + CHECK_BLOCK, n)
        m = mask[a:b]
        if m.all():
            yield slice(a, b), b - a
        elif m.any():
            idx = np.flatnonzero(m) + a
            yield idx, len(idx)


def _wheel_rows(rows: np.ndarray, idx: np.ndarray, column, I_b: np.ndarray) -> None:
    """The model rows of bodies idx (k,) whose only model effect is reaction_wheels, in a principal body frame:
    what Sim._model_row writes for each, for all of them at once. column(f): parameter f of their effects,
    (k, *shape); I_b: the principal moments of every body, (nb, 3)."""
    k = len(idx)
    J = column("J")
    n_w = J.shape[1]
    I_p = np.zeros((k, 3, 3))                # about the COM (no joint): diag(I_b)
    I_p[:, [0, 1, 2], [0, 1, 2]] = I_b[idx]
    rows[idx, LY.MODEL_I_P] = I_p.reshape(k, 9)
    pad_J = np.ones((k, LY.WHEELS_MAX))
    pad_J[:, :n_w] = J
    pad_A = np.zeros((k, 3, LY.WHEELS_MAX))
    pad_A[:, :, :n_w] = np.asarray(column("axes_b")).transpose(0, 2, 1)    # A_b = axes_bᵀ
    rows[idx, LY.MODEL_J], rows[idx, LY.MODEL_A_B] = pad_J, pad_A.reshape(k, -1)
    for f, col in (("torque_limit", LY.MODEL_TORQUE_LIMIT), ("speed_limit", LY.MODEL_SPEED_LIMIT),
                   ("c_w", LY.MODEL_C_W), ("cutoff", LY.MODEL_CUTOFF)):
        rows[idx, col] = column(f)
    rows[idx, LY.MODEL_KIND] = KIND_WHEELS


def _rebuild_sim(bodies: list, effects: list, kwargs: dict, state: dict) -> "Sim":
    """Unpickle a Sim: build it from its scene and settings, then load its snapshot."""
    scene = Scene()
    for b in bodies:
        scene.add_body(b)
    for e in effects:
        if type(e) is _Batch:    # one add_effects call (validated again)
            scene.add_effects(e.name, e.bodies, **e.shared, **e.cols)
        else:
            scene.add_effect(e)
    sim = Sim(scene, **kwargs)
    if state.get("fast_chunks"):     # run(n)'s C fast path for any n, as the original had (Sim.fast_chunks)
        sim.fast_chunks()
    sim._load_snapshot(state)
    return sim


class ImmutableSimError(V.LavenderInputError, AttributeError):
    """Assignment to a fixed setting of a built Sim (dt, integrator, backend, …): a LavenderInputError and an
    AttributeError naming the field.

    Parameters
    ----------
    field : str
        ``sim.<attribute>``.
    rule : str
        Why it is refused.
    detail : str, optional
    """


# what a built Sim keeps fixed (assignment raises ImmutableSimError)
_FIXED = frozenset({"dt", "integrator", "normalize", "backend", "names", "bodies", "on_bound", "max_growth", "dtype", "contract",
                    "params", "effects", "x", "p_w", "q", "v_w", "omega_b", "Omega", "t", "pipeline"})
_SETTERS = frozenset({"steps", "rhs_evals"})   # the validated setters: the only public assignments to a built Sim
_LIVE: "weakref.WeakSet[Sim]" = weakref.WeakSet()   # every Sim of this process (the fork handler resets their locks)


def _after_fork_in_child() -> None:
    """A process forked while another thread held a Sim's lock would wait forever for a thread that does not
    exist in it: give every Sim a fresh lock (and clear the C stepper's busy count that lock kept)."""
    for sim in list(_LIVE):
        fast = sim.__dict__.get("_fast")
        if fast is not None:
            fast.busy = 0
        object.__setattr__(sim, "_lock", _Guard(fast))


if hasattr(os, "register_at_fork"):
    os.register_at_fork(after_in_child=_after_fork_in_child)


# the growth check's floor on a wheeled body's reference |L|, relative to the momentum its parts carry
L_FLOOR = 1e-6


def wheeled_momentum_norms(rows: np.ndarray, x: np.ndarray, Omega: np.ndarray, idx: np.ndarray,
                           reference: bool = False) -> np.ndarray:
    """|L| (body + wheels, world) of the wheeled bodies idx, one batched call of the printed total momentum
    (backends.wheel_total_momentum_batch, as the C screen's).

    Parameters
    ----------
    rows : ndarray (nb, MODEL_SIZE)
        Model rows of every body.
    x : ndarray (nb, >= STATE_SIZE)
        States.
    Omega : ndarray (nb, WHEELS_MAX)
        Wheel rates, rad/s.
    idx : ndarray (n,) of int
        The wheeled bodies.
    reference : bool
        The growth check's reference: at least L_FLOOR times |L_body| + Σ J_i |Omega_i| (Sim._invariants).

    Returns
    -------
    ndarray (n,)
        kg·m²/s.
    """
    r, W, q, w = rows[idx], Omega[idx], x[idx, LY.STATE_Q], x[idx, LY.STATE_OMEGA_B]
    L = np.linalg.norm(backends.wheel_total_momentum_batch(r, q, w, W), axis=-1)
    if reference:
        Lb, _ = backends.wheel_momentum_batch(r, q, w, W)
        floor = L_FLOOR * (np.linalg.norm(Lb, axis=-1) + np.abs(r[:, LY.MODEL_J] * W).sum(axis=-1))
        L = np.where(floor > L, floor, L)     # max(L, floor) as Python's max: a NaN L stays NaN
    return L


class Trajectory:
    """Recorded samples of a run (returned by :meth:`Sim.record`).

    Parameters
    ----------
    names : list of str
        Body names, in the order of the second axis of `x`.
    t : ndarray, shape (T,)
        Sample times, s.
    x : ndarray, shape (T, nb, 13)
        Body states ``[p_w(3), q(4) (x, y, z, w), v_w(3), omega_b(3)]`` per sample and body (SI units).
    Omega : ndarray, shape (T, nb, WHEELS_MAX), optional
        Wheel rates relative to the body, rad/s, in each body's wheel slots (zeros when None: bodies
        without wheels).
    wheel_counts : array_like of int, shape (nb,), optional
        Wheels per body (0 without); :meth:`body` returns that many rates (three zeros for a body without
        wheels). Default: every body WHEELS_BODY_AXES.
    """

    def __init__(self, names: Sequence[str], t: np.ndarray, x: np.ndarray, Omega: np.ndarray | None = None,
                 wheel_counts=None):
        self.names, self.t, self.x = list(names), t, x
        self.Omega = np.zeros(x.shape[:-1] + (LY.WHEELS_MAX,)) if Omega is None else Omega
        self.wheel_counts = (np.full(len(names), LY.WHEELS_BODY_AXES) if wheel_counts is None
                             else np.asarray(wheel_counts, dtype=np.int64))

    def body(self, name: str) -> BodyState:
        """The samples of one body.

        Parameters
        ----------
        name : str
            A body name from `names`.

        Returns
        -------
        BodyState
            Its state with a leading sample axis (``.q`` has shape (T, 4), ``.omega_w`` (T, 3), ...).

        Raises
        ------
        LavenderInputError
            If no body has that name.
        """
        if name not in self.names:
            raise V.LavenderInputError("body", f"unknown body {name!r}; bodies: {', '.join(self.names)}")
        i = self.names.index(name)
        return BodyState.of_slots(self.x[:, i], self.Omega[:, i], int(self.wheel_counts[i]))


class Sim:
    """Steps a scene's bodies (see the module docstring).

    Parameters
    ----------
    scene : Scene
        Read once here; later edits to it do not affect this Sim.
    dt : float
        Step (s); the output interval of an adaptive integrator.
    integrator : str
        One of lavendersim.backends.INTEGRATORS.
    backend : {"auto", "c", "numpy"}
        "auto" uses the C extension when it is built and current, else NumPy (with a warning).
    normalize : bool
        Normalize q after every step.
    rtol, atol : float, optional
        Tolerances of the adaptive integrators only.
    on_bound : {"raise", "warn"}
        (keyword only) Beyond the integrator's validity bound (|omega|*dt*(I_max/I_min)**p <= WDT_MAX, derive/tableaux.py):
        "raise" (default) raises DivergenceError at the first step that would run beyond it (set_state:
        LavenderInputError at the call); "warn" runs on with one ValidityBoundWarning per body.
    max_growth : float or None
        (keyword only) A torque- and force-free body whose kinetic energy or |L| (a free wheeled body: whose total |L|)
        exceeds max_growth times its value at construction / the last set_state raises DivergenceError
        (default 2: a conserved quantity that doubles is never rounding; None switches the check off).
    dtype : {"float64", "float32"}
        (keyword only) Precision of the state and of every step's arithmetic (default "float64"). "float32"
        steps the single-precision printing of the same kernels (C: generated/kernels_f32.c; NumPy:
        generated/kernels_numpy_f32.py) for euler, semi_implicit_euler and rk4 on plain bodies with built-in
        effects (anything else raises LavenderInputError naming dtype); the state, its views, state() and
        record() are then float32, while the divergence checks evaluate in float64.
    contract : {"off", "fma"}
        (keyword only) The arithmetic of the C backend's torque-free RK4 SIMD tiles (groups of two or more plain
        bodies without effects, float64). "off" (default): bitwise the scalar path and the NumPy backend. "fma": a
        copy of those tiles compiled with a*b+c fused into one rounding (AVX2/AVX-512 CPUs with FMA, GCC builds;
        elsewhere the bitwise tiles run): faster, and no longer bitwise: the state differs from "off" in the last
        bits (docs/performance.md gives the measured difference over a tumbling run). Every other body and path
        steps bitwise in either mode. Needs backend "c" (resolved) and dtype "float64".

    Raises
    ------
    LavenderInputError
        On any invalid argument (named in the message); nothing is built.

    Examples
    --------
    >>> import lavendersim as lv
    >>> scene = lv.Scene()
    >>> rod = scene.add_body(lv.Body.box("rod", mass=1.0, size=(0.8, 0.2, 0.2)))
    >>> torque = scene.add_effect("applied_torque", body="rod", torque_w=[0, 0, 0.02])
    >>> sim = lv.Sim(scene, dt=1e-3, integrator="rk4")
    >>> sim.run(100)
    >>> round(float(sim.state("rod").omega_w[2]), 6)   # rad/s after 0.1 s
    0.035294
    """

    # set by the setup methods __init__ calls (declared here: some are read by methods defined before them)
    _chunk: int
    _budget: load_checks.LoadBudget | None

    @V.keywords  # unknown keyword arguments raise LavenderInputError naming them
    def __init__(self, scene: Scene, dt: float = 1e-3, integrator: str = "rk4", backend: str = "auto", normalize: bool = True,
                 rtol: float | None = None, atol: float | None = None, *, on_bound: str = "raise",
                 max_growth: float | None = 2.0, dtype: str = "float64", contract: str = "off"):
        if not isinstance(scene, Scene):
            raise V.LavenderInputError("scene", "must be a lavendersim.Scene", f", got {type(scene).__name__}")
        self.dt = V.dt("dt", dt)   # dt and the other settings are fixed once built (Sim.__setattr__)
        self.integrator = _integrator(integrator)
        if not isinstance(normalize, (bool, np.bool_)):
            raise V.LavenderInputError("normalize", "must be True or False", f", got {normalize!r}")
        self.normalize = bool(normalize)
        self.backend = backends.get(backend)
        table = scene._bodies.frozen()     # the scene's bodies now (arrays; Body objects built on access)
        self.names = tuple(table)                               # read-only: a pickle rebuilds the Sim from them
        self.bodies = types.MappingProxyType(table)
        checked = set()
        for e in scene.effects.items():  # an effect no declaration printed is an error, never a no-op
            cls = e.cls if type(e) is _Batch else type(e)
            if cls not in checked:     # (name, code and spec are class attributes: one check per class)
                effects_mod.check_declared(e)
                checked.add(cls)
        tables = scene.tables()   # a body given a full inertia tensor is stepped in its principal frame
        self._x, self._params, self._effects = tables.state, tables.params, tables.effects
        self._frames = tables.frames
        self._forces, self._rows_of = tables.forces, tables.rows_of   # force effects (current) and their rows
        self._forces_given = _EffectList(tables.forces)               # ... as the scene gave them
        self._index = table.positions      # name -> index
        self._effect_objs = _EffectList(scene.effects)       # (batches shared: immutable)
        self._models = self._build_models(scene)
        self._adaptive = None
        if self.integrator in ADAPTIVE:
            rtol = 1e-6 if rtol is None else V.scalar("rtol", rtol, positive=True)
            atol = 1e-9 if atol is None else V.scalar("atol", atol, nonnegative=True)
            if not 1e-14 <= rtol < 1:
                raise V.LavenderInputError("rtol", "must be in [1e-14, 1) (below 1e-14 rounding dominates)", f", got {rtol!r}")
            self._adaptive = Adaptive(rtol, atol, len(self.names))
        else:
            for field, value in (("rtol", rtol), ("atol", atol)):
                if value is not None:
                    raise V.LavenderInputError(field, f"applies to the adaptive integrators ({', '.join(ADAPTIVE)}) only; "
                                               f"{self.integrator!r} uses the fixed step dt")
        if self.integrator in PLAIN_ONLY:
            for i, name in enumerate(self.names):
                kind = self._kind(i)
                if kind:
                    what = " and ".join(w for f, w in ((KIND_JOINT, "a spherical_joint"), (KIND_WHEELS, "reaction_wheels")) if kind & f)
                    raise V.LavenderInputError(
                        "integrator", f"{self.integrator!r} steps plain rigid bodies only, but body {name!r} has {what}; "
                        "use rk4 or dopri5 for jointed or wheeled bodies")
        self.dtype = self._check_dtype(dtype)
        self.contract = self._check_contract(contract)
        self._per_step = backends.rhs_per_step(self.integrator, self._effects, len(self.names))
        self._step_work = self._per_step or ADAPTIVE_STEP_WORK   # evaluations per body-step, for the work caps
        self.on_bound = V.choice("on_bound", on_bound, ON_BOUND)
        if max_growth is not None:
            max_growth = V.scalar("max_growth", max_growth, positive=True)
            if not max_growth > 1.0:
                raise V.LavenderInputError("max_growth", "must be > 1 (or None: no growth check)", f", got {max_growth!r}")
        self.max_growth = max_growth
        self._has_models = bool(self._kinds.any())
        # the arrays the backend steps: float64, or float32 copies of the state, params and effect table
        self._step_params, self._step_effects = self._params, self._effects
        if self.dtype == "float32":
            self._x = self._x.astype(np.float32)
            self._step_params, self._step_effects = self._params.astype(np.float32), self._effects.astype(np.float32)
        # C: what a backend call decides from the effect table and model rows (the effect index, the bodies' order),
        # kept by this Sim from call to call (c_backend.call_cache: a large scene's chunk builds none of it)
        self._c_cache = None
        if self.backend.name == "c" and self.dtype == "float64":
            from .backends import c_backend

            self._c_cache = c_backend.call_cache(len(self.names), self._has_models)
        self._dirty = True         # the state was written since the last check (see _is_checked)
        self._snap_buf: tuple[np.ndarray, ...] | None = None      # _advance's reusable snapshot buffers
        self._check_decays(self._effects, "Sim")
        self._setup_checks()
        self._fast = self._make_stepper()
        self._screen = None
        if self.backend.name == "c":   # the C screen reads float64 and float32 states (csrc/fast_step.c)
            from .backends import c_backend

            self._screen = c_backend._c.checks_pass
        self._g_inf_rows: np.ndarray | None = None     # growth limits that never fire (growth=False), made on first use
        self._ctr = self._fast if self._fast is not None else _Counters()
        self._lock = _Guard(self._fast)
        # run(n) inside C for n up to one chunk (checked at its end, as _advance checks a chunk) within the work cap
        self._fast_n = min(self._chunk, FAST_STEP_WORK // max(1, len(self.names) * self._step_work))
        self._views = _read_only_views(self._x, self._models.Omega, self._models.applied)
        if self._fast is not None:   # sim.step() straight into C; the Python path only when C steps aside
            self._fast.set_fallback(self._step_slow)
            setattr(self, "step", self._fast.step_or_fallback)   # this instance's step is C's (shadows Sim.step)
        self._built = True
        _LIVE.add(self)

    # ---- pickle and deepcopy: the whole state, restorable bit for bit --------------------------
    def __reduce__(self):
        """A Sim pickles (and deep-copies) as its scene (the immutable bodies and effects), its settings and a
        snapshot of everything that evolves: the state, wheel rates, held commands and applied torques, model
        rows, adaptive step sizes, counters and the growth check's references. The copy steps on bit for bit."""
        with self._lock:
            m = self._models
            state = {"x": self._x.copy(), "rows": m.rows.copy(), "Omega": m.Omega.copy(), "command": m.command.copy(),
                     "applied": m.applied.copy(), "steps": self.steps, "rhs_evals": self.rhs_evals,
                     "E0": self._E0.copy(), "L0": self._L0.copy(), "w_safe": self._w_safe.copy(),
                     "g_fast": self._g_fast.copy(), "warned": sorted(self._warned),
                     "budget": None if self._budget is None else self._budget.snapshot(),
                     "adaptive": None if self._adaptive is None else self._adaptive.save(),
                     "fast_chunks": self._fast is not None and self._fast_n == self._chunk}
        kwargs = {"dt": self.dt, "integrator": self.integrator, "backend": self.backend.name, "normalize": self.normalize,
                  "on_bound": self.on_bound, "max_growth": self.max_growth, "dtype": self.dtype, "contract": self.contract}
        if self._adaptive is not None:
            kwargs.update(rtol=self._adaptive.rtol, atol=self._adaptive.atol)
        return (_rebuild_sim, ([self.bodies[n] for n in self.names], list(self._effect_objs.items()), kwargs, state))

    def _load_snapshot(self, st: dict) -> None:
        """Put a freshly built Sim (same scene and settings) at a pickled state (see __reduce__)."""
        with self._lock:
            m = self._models
            self._x[...] = st["x"]
            for name in ("rows", "Omega", "command", "applied"):
                getattr(m, name)[...] = st[name]
            self._rows_written()
            if st["adaptive"] is not None:
                assert self._adaptive is not None   # (built with the same settings)
                self._adaptive.load(st["adaptive"])
            self._ctr.steps, self._ctr.rhs_evals = st["steps"], st["rhs_evals"]
            self._E0[...], self._L0[...], self._w_safe[...], self._g_fast[...] = st["E0"], st["L0"], st["w_safe"], st["g_fast"]
            self._warned = set(st["warned"])
            if st.get("budget") is not None:
                assert self._budget is not None   # (built with the same settings)
                self._budget.restore(st["budget"])
            self._dirty = True   # checked again before the next step (a check of a state that passed passes)

    # ---- settings are fixed; the state changes only through validated calls -------------------
    def __setattr__(self, name: str, value) -> None:
        if self.__dict__.get("_built") and not name.startswith("_") and name not in _SETTERS:
            if name in _FIXED:
                raise ImmutableSimError(f"sim.{name}", "is fixed when the Sim is built (a changed setting would not "
                                        "mean the same on both backends): build a new Sim; the state changes through "
                                        "set_state, set_wheel_command(s) and set_effect_params")
            what = ("is a method of Sim" if callable(getattr(type(self), name, None)) else "is read-only"
                    if hasattr(type(self), name) else "is not an attribute of Sim (a misspelt setting would be ignored)")
            raise ImmutableSimError(f"sim.{name}", f"{what}: a built Sim takes no assignment but its validated "
                                    "setters steps and rhs_evals")
        object.__setattr__(self, name, value)

    def __delattr__(self, name: str) -> None:
        raise ImmutableSimError(f"sim.{name}", "cannot be deleted")

    @property
    def model(self) -> SimModel:
        """The model this Sim steps, read-only and live (:class:`lavendersim.sim_model.SimModel`: model rows, wheel
        counts, stepped state, wheel arrays, principal frames, effect declarations, the C fast path): the public
        API for applications (envs, linearization), which never read a Sim's private attributes."""
        return SimModel(self)

    @property
    def params(self) -> np.ndarray:
        """Per-body parameters (nb, 4) = [m, I_1, I_2, I_3] (principal moments) the backends step: read-only."""
        v = self._params.view()
        v.flags.writeable = False
        return v

    @property
    def effects(self) -> np.ndarray:
        """The force-effect table (ne, width) = [code, body, parameters …] the backends step: read-only (change
        a force effect's parameters with set_effect_params)."""
        v = self._effects.view()
        v.flags.writeable = False
        return v

    def _check_contract(self, contract) -> str:
        """contract as "off" or "fma"; "fma" only on the C backend in float64 (the FMA copy of its tiles)."""
        name = V.choice("contract", contract if isinstance(contract, str) else repr(contract), CONTRACT)
        if name == "fma" and (self.backend.name != "c" or self.dtype != "float64"):
            raise V.LavenderInputError("contract", "'fma' applies to the C backend in float64 (its SIMD tiles), not "
                                       f"backend {self.backend.name!r} with dtype {self.dtype!r}")
        return name

    def _check_dtype(self, dtype) -> str:
        """dtype as "float64" or "float32" (also accepted: numpy.float32 / numpy.float64 and their dtypes); float32
        only where it is printed (backends.FLOAT32_INTEGRATORS, plain bodies, built-in effects)."""
        if isinstance(dtype, np.dtype) or (isinstance(dtype, type) and issubclass(dtype, np.generic)):
            dtype = np.dtype(dtype).name
        name = V.choice("dtype", dtype if isinstance(dtype, str) else repr(dtype), backends.DTYPES)
        if name == "float64":
            return name
        if self.integrator not in backends.FLOAT32_INTEGRATORS:
            raise V.LavenderInputError("dtype", f"float32 steps {', '.join(backends.FLOAT32_INTEGRATORS)} only, not "
                                       f"{self.integrator!r} (use dtype='float64' for it)")
        for i, name_ in enumerate(self.names):
            if self._kind(i):
                raise V.LavenderInputError("dtype", f"float32 steps plain rigid bodies only, but body {name_!r} has a "
                                           "spherical_joint or reaction_wheels (use dtype='float64')")
        if len(self._effects):
            codes = self._effects[:, effects_mod.ROW_CODE]
            if np.any(codes >= effects_mod.USER_CODE_BASE):
                raise V.LavenderInputError("dtype", "float32 steps built-in effects only; the scene has a user effect "
                                           "(use dtype='float64')")
            if len(self.names) >= 2**24:
                raise V.LavenderInputError("dtype", "float32 with effects takes fewer than 2**24 bodies (body indices "
                                           "in the float32 effect table must be exact)")
        return name

    # ---- zero-copy views of the state (read-only: set_state is the writer) ------------------
    @property
    def x(self) -> np.ndarray:
        """The state of every body, (nb, 13) = [p_w(3), q(4), v_w(3), omega_b(3)] per row (layout
        generated/layout.py), in the order of `names`. A read-only view of the array the backends advance
        in place: no copy, always current; write through set_state (which validates), never through it.
        q and omega_b are in each body's own frame; when a body was given a full inertia tensor (stepped in
        its principal frame), x, q and omega_b are read-only converted copies instead of views."""
        return self._views[0] if self._frames is None else self._public(self._views[0])

    def _public(self, a: np.ndarray) -> np.ndarray:
        """Internal state rows in the body frames: a read-only converted copy (bodies with full tensors)."""
        assert self._frames is not None   # (called for a scene with full tensors only)
        out = self._frames.public(a)
        out.flags.writeable = False
        return out

    @property
    def p_w(self) -> np.ndarray:
        """COM positions, world frame, m, (nb, 3): a read-only view of x (see x)."""
        return self._views[1]

    @property
    def q(self) -> np.ndarray:
        """Orientations R_WB as quaternions (x, y, z, w), (nb, 4): a read-only view of x (see x)."""
        return self._views[2] if self._frames is None else self.x[:, LY.STATE_Q]

    @property
    def v_w(self) -> np.ndarray:
        """COM velocities, world frame, m/s, (nb, 3): a read-only view of x (see x)."""
        return self._views[3]

    @property
    def omega_b(self) -> np.ndarray:
        """Angular velocities (body rates), body frame, rad/s, (nb, 3): a read-only view of x (see x)."""
        return self._views[4] if self._frames is None else self.x[:, LY.STATE_OMEGA_B]

    @property
    def Omega(self) -> np.ndarray:
        """Reaction-wheel rates relative to their body, rad/s, (nb, WHEELS_MAX): a body's N wheels in its first
        N columns, in the order of its axes_b (zeros beyond them and for a body without wheels); a read-only
        view (set_state(name, Omega=...) writes them)."""
        return self._views[5]

    # ---- counters (kept by the C stepper when there is one) --------------------------------
    @property
    def steps(self) -> int:
        """Steps taken so far."""
        return self._ctr.steps

    @steps.setter
    def steps(self, n: int) -> None:
        n = V.integer("steps", n, minimum=0)
        if n > MAX_STEPS:   # t = steps * dt stays exact, and the C counters never overflow
            raise V.LavenderInputError("steps", "must be at most MAX_STEPS = 2**53", f", got {n}")
        with self._lock:
            self._ctr.steps = n

    @property
    def t(self) -> float:
        """Simulated time, s: steps * dt."""
        return self._ctr.steps * self.dt

    @property
    def rhs_evals(self) -> int:
        """Right-hand-side evaluations so far (see the module docstring)."""
        return self._ctr.rhs_evals

    @rhs_evals.setter
    def rhs_evals(self, n: int) -> None:
        n = V.integer("rhs_evals", n, minimum=0)
        if n > 2**62:
            raise V.LavenderInputError("rhs_evals", "must be at most 2**62", f", got {n}")
        with self._lock:
            self._ctr.rhs_evals = n

    @property
    def chunk_steps(self) -> int:
        """Steps per backend call between checks (:func:`chunk_steps`): run(n) steps in chunks of this many, each
        paying the backend call's setup and the checks at its end once. Read-only."""
        return self._chunk

    def _make_stepper(self, cap: bool = True):
        """The C fast path of step() (lavendersim/csrc/fast_step.c), or None where it does not apply: not the C
        backend, a scene larger than FAST_STEP_WORK evaluations per step (an adaptive integrator counted
        ADAPTIVE_STEP_WORK per body; the fast path holds the GIL; cap=False: built whatever the size, see fast_chunks),
        or a Python without the GIL. An adaptive integrator's Stepper steps the Adaptive's arrays in place (fast_step.c)."""
        gil = getattr(sys, "_is_gil_enabled", lambda: True)()
        if (self.backend.name != "c" or not gil or self.dtype != "float64"
                or self.contract != "off"   # (the Stepper steps bitwise; contract="fma" goes through advance)
                or self.integrator not in backends.INTEGRATORS   # a user tableau: through advance (no Stepper code)
                or (cap and len(self.names) * self._step_work > FAST_STEP_WORK)):
            return None
        from .backends import c_backend

        m = self._models if self._has_models else None
        models = (None,) * 4 if m is None else (m.rows, m.Omega, m.command, m.applied)
        bound = np.inf if self._bound is None else float(self._bound[0])
        ad = self._adaptive
        adaptive = () if ad is None else (ad.h, ad.nfev, ad.dense, ad.rtol, ad.atol)
        return c_backend._c.Stepper(self._x, self._params, self._effects if self._effects.size else self._effects.reshape(0, 2),
                                    c_backend.INTEGRATOR_CODES[self.integrator], 1 if self.normalize else 0, float(self.dt),
                                    int(self._per_step or 0), MAX_STEPS, self._wdt_scale, bound, self._g_fast,
                                    c_backend.user_effect_table(self._effects), *models, *adaptive)

    # ---- divergence checks ---------------------------------------------------------------
    def _setup_checks(self) -> None:
        nb = len(self.names)
        I = self._params[:, LY.PARAM_I_B]
        self._bound = validity_bound(self.integrator)
        p = 0.0 if self._bound is None else self._bound[1]
        self._wdt_scale = K.validity_scale(I, self.dt, p)     # dt (I_max/I_min)**p, printed (derive/measures.py)
        acted = np.zeros(nb, bool)
        if len(self._effects):
            from .effects import ROW_BODY
            body = self._effects[:, ROW_BODY].astype(np.int64)
            acted[:] = bool(np.any(body < 0))
            acted[body[body >= 0]] = True
        kind = self._kinds
        self._free = ~acted & (kind == 0)                      # E and |L| conserved
        self._free_wheels = ~acted & (kind == KIND_WHEELS)  # total |L| conserved (motor torques are internal)
        self._free_any = bool(self._free.any())
        self._any_free_wheels = bool(self._free_wheels.any())
        self._fw = np.flatnonzero(self._free_wheels)          # the same, as an index array (one batched kernel call)
        # bodies effects act on (not jointed: the joint's reaction is no declared load): a growth budget
        loaded = acted & ((kind & KIND_JOINT) == 0)
        self._budget = (load_checks.LoadBudget(self._params, self._effects, self._models.rows, loaded, self.dt, self.max_growth)
                        if self.max_growth is not None and loaded.any() else None)
        self._warned = set()
        evals = self._per_step if self._per_step is not None else 12
        # the SIMD tiles (plain bodies, with or without effects): a longer chunk still returns soon
        cap = CHUNK_WORK_MAX if self._has_models else CHUNK_WORK_MAX_EFFECTS if len(self._effects) else CHUNK_WORK_MAX_PLAIN
        c = self.backend.name == "c"
        self._chunk = chunk_steps(nb * evals, self._per_step is not None and self.backend.name in ("c", "numpy"),
                                  cap if c else CHUNK_WORK_MAX_NUMPY,
                                  CHUNK_MIN_STEPS_C if c else CHUNK_MIN_STEPS)
        self._reference()

    def _invariants(self, x: np.ndarray, Omega: np.ndarray, reference: bool = False) -> tuple[np.ndarray, np.ndarray]:
        """(kinetic energy, |L|) per body, where the growth check reads them (else 0): E (kinetic_energy) and
        |L| (body_momentum) of the torque- and force-free plain bodies — both are needed: a first-order method
        can move a minor-axis spin towards the major axis, |L| x2 while E stays within x2 (the atlas's euler
        cells) —, |L| (body + wheels, wheel_momentum) of the wheeled ones.

        reference: the growth check's reference |L| of a wheeled body is at least L_FLOOR times the momentum
        its parts carry (|L_body| + Σ J_i |Omega_i|): a total that cancels to rounding (wheels spinning in the
        layout's null space, the body at rest) cannot double by rounding alone and be called a divergence.

        The wheeled bodies go through one batched call of the momentum kernel (wheeled_momentum_norms), about
        1 µs per body per chunk at N = 3e4 (measured, issue 30), not a Python loop per body."""
        nb = len(self.names)
        E, L = np.zeros(nb), np.zeros(nb)
        with np.errstate(over="ignore", invalid="ignore"):
            for f, _ in _check_blocks(self._free) if self._free_any else ():
                p, xf = self._params[f], x[f]
                I_b, w_b = p[:, LY.PARAM_I_B], xf[:, LY.STATE_OMEGA_B]
                E[f] = K.kinetic_energy(p[:, LY.PARAM_M], I_b, xf[:, LY.STATE_V_W], w_b)
                L[f] = np.linalg.norm(K.body_momentum(I_b, w_b), axis=-1)
            if self._any_free_wheels:
                L[self._fw] = wheeled_momentum_norms(self._models.rows, x, Omega, self._fw, reference)
        return E, L

    def _reference(self) -> None:
        """The growth check's reference values (at construction and after set_state), and per free body the
        largest |omega| at which neither its energy can exceed max_growth * E0 (E <= T_translation + I_max |omega|^2 / 2,
        both terms from the kinetic_energy kernel; v is constant on a force-free body) nor its |L| max_growth * L0
        (|L| = |I_b omega_b| <= I_max |omega|): the check evaluates the kernels only for a body above it, so it
        costs nothing while a run is far from its limit."""
        self._E0, self._L0 = self._invariants(self._x, self._models.Omega, reference=True)
        nb = len(self.names)
        # the C screen's growth limits per body (csrc/fast_step.c LV_G_*): no-work rate, max_growth * E0 and
        # (max_growth * L0)^2 with a rounding margin; +inf where no growth check can fire (not free, max_growth None)
        self._g_fast = np.full((nb, 3), np.inf)
        self._w_safe = self._g_fast[:, 0]     # (a view: the free bodies' no-work rates are the screen's)
        self._safe_rates(self._free | self._free_wheels)
        if self._budget is not None:
            steps = self._ctr.steps if "_ctr" in self.__dict__ else 0
            self._budget.reference(self._x, self._models.Omega, steps)
            self._budget.screen_rows(self._g_fast, steps)

    def _safe_rates(self, f: np.ndarray) -> None:
        """w_safe (see _reference) and the screen's limits of the free bodies selected by the boolean mask f, from the
        current E0 and L0 (a free wheeled body: its (max_growth L0)^2, for the |L| of body and wheels)."""
        if self.max_growth is None:
            return
        fw = f & self._free_wheels     # the screen evaluates their |L| of body and wheels (no no-work rate, no E)
        for f, k in _check_blocks(f & self._free):
            p = self._params[f]
            I = p[:, LY.PARAM_I_B]
            with np.errstate(over="ignore", invalid="ignore"):
                T = K.kinetic_energy(p[:, LY.PARAM_M], I, self._x[f][:, LY.STATE_V_W], np.zeros((k, 3)))
                half_Imax = K.kinetic_energy(np.zeros(k), np.repeat(I.max(axis=1)[:, None], 3, axis=1),
                                             np.zeros((k, 3)), np.tile([1.0, 0.0, 0.0], (k, 1)))
                room = np.maximum(self.max_growth * self._E0[f] - T, 0.0)
                w_E = np.sqrt(room / half_Imax)
                w_L = self.max_growth * self._L0[f] / I.max(axis=1)
                self._w_safe[f] = np.minimum(w_E, w_L) * load_checks.SCREEN_MARGIN   # never skip a violation
            with np.errstate(over="ignore"):
                E0, L0 = self._E0[f], self._L0[f]
                margin = load_checks.SCREEN_MARGIN
                self._g_fast[f, 1] = np.where(E0 > 0, self.max_growth * E0 * margin, np.inf)
                self._g_fast[f, 2] = np.where(L0 > 0, (self.max_growth * L0) ** 2 * margin, np.inf)
        with np.errstate(over="ignore"):
            L0 = self._L0[fw]
            self._g_fast[fw, 0], self._g_fast[fw, 1] = -np.inf, np.inf
            self._g_fast[fw, 2] = np.where(L0 > 0, (self.max_growth * L0) ** 2 * load_checks.SCREEN_MARGIN, np.inf)

    def _g_inf(self) -> np.ndarray:
        """(nb, 3) growth limits that never fire: the C screen's table when it checks the validity bound only."""
        if self._g_inf_rows is None:
            self._g_inf_rows = np.full((len(self.names), 3), np.inf)
        return self._g_inf_rows

    def _wdt(self, x: np.ndarray, bodies=slice(None)) -> np.ndarray:
        """|omega|*dt*(I_max/I_min)**p of rows x (of those bodies), the quantity the validity bound limits (the printed
        validity_wdt, as the C screen)."""
        with np.errstate(over="ignore", invalid="ignore"):   # an overflowing norm is inf: beyond any bound
            return K.validity_wdt(x[:, LY.STATE_OMEGA_B], self._wdt_scale[bodies])[1]

    def _bound_text(self, value: float) -> str:
        assert self._bound is not None   # (a value beyond the bound was found)
        wmax, p = self._bound
        what = "|omega|*dt" + (f"*(I_max/I_min)**{p:g}" if p else "")
        return (f"{what} = {value:.3g} is beyond {self.integrator}'s validity bound {wmax:.4g} (WDT_MAX, "
                f"derive/tableaux.py); reduce dt" + ("" if self.integrator in ADAPTIVE else f" or use {ADAPTIVE[0]}"))

    def _violation(self, x: np.ndarray, Omega: np.ndarray, warn: bool = True, growth: bool = True) -> tuple[int, str] | None:
        """The first body (index, cause) of state x that fails a check (growth=False: the bound only), or None;
        for a wheeled body whose wheel damping is beyond the integrator's limit the cause says so first."""
        v = self._violation_raw(x, Omega, warn, growth)
        if v is not None and self._kind(v[0]) & KIND_WHEELS:
            r, n = self._models.rows[v[0]], int(self._wheel_n[v[0]])
            why = backends.divergence_cause(x[v[0]], self.dt, self.integrator, self._params[v[0], LY.PARAM_I_B],
                                            Omega[v[0], :n], (r[LY.MODEL_J][:n], r[LY.MODEL_C_W]))
            if "wheel damping" in why:
                return v[0], f"{why}; {v[1]}"
        return v

    def _violation_raw(self, x, Omega, warn, growth):
        screen = self._screen
        if screen is not None and x is self._x:
            # one pass in C: every body inside the bound and (growth) inside its E and |L| limits (a wheeled body's
            # |L| of body and wheels, from its model row and wheel rates) -> nothing to report
            bound = np.inf if self._bound is None else self._bound[0]
            models = (self._models.rows, Omega) if self._has_models else ()
            if screen(x, self._params, self._wdt_scale, bound, self._g_fast if growth else self._g_inf(), *models):
                return None
        with np.errstate(over="ignore", invalid="ignore"):   # an overflowing norm is inf: beyond any bound
            w, v = K.validity_wdt(x[:, LY.STATE_OMEGA_B], self._wdt_scale)
        if self._bound is not None and not w.size == 0 and not float(v.max()) <= self._bound[0]:
            bad = ~(v <= self._bound[0])
            if bad.any():
                if self.on_bound == "raise":
                    b = int(np.flatnonzero(bad)[0])
                    return b, self._bound_text(float(v[b]))
                if warn:
                    for b in np.flatnonzero(bad):
                        if int(b) not in self._warned:
                            self._warned.add(int(b))
                            warnings.warn(f"body {self.names[b]!r}: {self._bound_text(float(v[b]))}; results beyond it "
                                          "are not trusted (on_bound='warn')", ValidityBoundWarning, stacklevel=4)
        g = self.max_growth
        if growth and g is not None and (self._any_free_wheels or (self._free_any and not bool((w <= self._w_safe).all()))):
            E, L = self._invariants(x, Omega)
            with np.errstate(over="ignore", invalid="ignore"):
                badE = self._free & (self._E0 > 0) & ~(E <= g * self._E0)
                badL = (self._free | self._free_wheels) & (self._L0 > 0) & ~(L <= g * self._L0)
            bad = badE | badL
            if bad.any():
                b = int(np.flatnonzero(bad)[0])
                if badE[b]:
                    return b, (f"kinetic energy grew x{E[b] / self._E0[b]:.3g} (beyond max_growth = {g:g}) on a torque-free "
                               f"body (|omega|*dt = {backends.norm_safe(x[b, LY.STATE_OMEGA_B]) * self.dt:.3g}): "
                               f"{self.integrator} is unstable here; reduce dt")
                return b, (f"|L| grew x{L[b] / self._L0[b]:.3g} (beyond max_growth = {g:g}) on a body no external effect "
                           f"acts on (|omega|*dt = {backends.norm_safe(x[b, LY.STATE_OMEGA_B]) * self.dt:.3g}): "
                           f"{self.integrator} is unstable here; reduce dt")
        if growth and self._budget is not None:
            return self._budget.violation(x, Omega, self._ctr.steps)
        return None

    def _snapshot(self, reuse: bool = False) -> tuple:
        """What a restore needs: the state, (with joints/wheels) wheel rates and applied torques, the adaptive
        arrays, the counters. reuse=True copies into buffers kept by the Sim (no allocation: at 10^6 bodies
        a fresh 100 MB array per call cost more in page faults than the copy); only _advance's start uses them."""
        m, ad, models = self._models, self._adaptive, self._has_models
        if not reuse:
            x, W, u = self._x.copy(), m.Omega.copy() if models else None, m.applied.copy() if models else None
        else:
            if self._snap_buf is None:
                self._snap_buf = tuple(np.empty_like(a) for a in (self._x, m.Omega, m.applied))
            x, W, u = self._snap_buf
            np.copyto(x, self._x)
            if models:
                np.copyto(W, m.Omega)
                np.copyto(u, m.applied)
            else:
                W = u = None
        return (x, W, u, None if ad is None else ad.save(), self.steps, self.rhs_evals)

    def _restore(self, snap: tuple) -> None:
        x, W, u, ad, self._ctr.steps, self._ctr.rhs_evals = snap   # values it read: no re-validation
        self._x[...] = x
        if W is not None:     # None: no body has a joint or wheels, the backends never touch them
            self._models.Omega[...] = W
            self._models.applied[...] = u
        if ad is not None:
            assert self._adaptive is not None   # (a snapshot of this Sim)
            self._adaptive.load(ad)

    @property
    def rtol(self) -> float | None:
        """Relative tolerance of an adaptive integrator (None for a fixed-step one)."""
        return None if self._adaptive is None else self._adaptive.rtol

    @property
    def atol(self) -> float | None:
        """Absolute tolerance of an adaptive integrator (None for a fixed-step one)."""
        return None if self._adaptive is None else self._adaptive.atol

    def _build_models(self, scene: Scene) -> Models:
        """Per-body model rows (kind, I_p, r_b, anchor, J, limits, c_w) from the joint/wheel effects."""
        nb = len(self.names)
        models = Models.empty(nb)
        rows = models.rows
        # a body without model effects keeps its all-zero row (kind 0: the steppers ignore it), never written, so
        # a scene of plain bodies never touches the (nb, MODEL_SIZE) rows' pages (288 B per body at 1e6 bodies)
        modelled: dict[str, dict] = {}      # scene.model_effects(name) of the bodies not in a wheels-only batch
        batches = []
        for e in scene.effects.items():
            if type(e) is _Batch and e.per_body:
                idx = e.positions(scene._bodies._c)
                batches.append((e, np.where((idx < 0) | (idx >= nb), nb, idx)))
            elif type(e) is not _Batch and e.per_body:
                modelled.setdefault(e.body, {})[e.name] = e
        self._wheel_batches = self._batched_wheels(batches, modelled)
        self._modelled = modelled
        wheels_only: dict[int, list] = {}     # wheel count -> [(body index, effect)]: rows written batched
        at = _name_index(scene._bodies._c) if modelled else {}   # (every modelled body is one of this Sim's: the
        for name, me in modelled.items():                        # scene checked it)
            i = at.get(name, nb)
            if i >= nb:           # not one of this Sim's bodies (an effects list assigned by hand): no row, as before
                continue
            if len(me) == 1 and "reaction_wheels" in me and (self._frames is None or self._frames.rotation(i) is None):
                e = me["reaction_wheels"]
                wheels_only.setdefault(e.values["J"].size, []).append((i, e))
            else:
                self._model_row(i, me, rows)
        I_b = self._params[:, LY.PARAM_I_B]
        for group in wheels_only.values():
            idx = np.array([i for i, _ in group], dtype=np.int64)
            _wheel_rows(rows, idx, lambda f, g=group: np.stack([np.asarray(e.values[f], dtype=np.float64) for _, e in g]),
                        I_b)
        for b, idx in self._wheel_batches:
            _wheel_rows(rows, idx, b.column, I_b)
        # each body's kind, read from the modelled bodies' rows only (reading the whole column would fault every page)
        at_rows = np.concatenate([np.fromiter((at.get(name, nb) for name in modelled), np.int64, len(modelled))]
                                 + [idx for _, idx in self._wheel_batches])
        at_rows = at_rows[at_rows < nb]
        self._kinds = np.zeros(nb, np.int8)     # (int8: 1 B per body at 1e6 bodies)
        self._kinds[at_rows] = rows[at_rows, LY.MODEL_KIND].astype(np.int8)
        self._wheel_n = np.zeros(nb, np.int8)   # wheels per body (the model rows' layouts never change)
        wheeled = np.flatnonzero(self._kinds & KIND_WHEELS)
        self._wheel_n[wheeled] = backends.wheel_counts(rows[wheeled])
        return models

    def _batched_wheels(self, batches: list, modelled: dict) -> list:
        """The per-body batches (batch, body indices) that are reaction_wheels alone on their bodies, each body one
        of this Sim's and principal: their rows are written from the batch's columns. The effects of the others go
        into `modelled` (by body name), one by one."""
        nb = len(self.names)
        if not batches:
            return []
        count = np.zeros(nb + 1, np.int16)             # model effects per body (nb: not one of this Sim's)
        pos = self._index
        np.add.at(count, np.fromiter((pos[n] if n in pos else nb for n in modelled), np.int64, len(modelled)), 1)
        for _, idx in batches:
            np.add.at(count, np.minimum(idx, nb), 1)
        rotated = np.zeros(nb + 1, bool)
        if self._frames is not None:
            rotated[self._frames.idx] = True
        fast = []
        for b, idx in batches:
            if b.name == "reaction_wheels" and (idx < nb).all() and (count[idx] == 1).all() and not rotated[idx].any():
                fast.append((b, idx))
            else:
                for j, name in enumerate(b.bodies):
                    modelled.setdefault(name, {})[b.name] = b.effect(j)
        return fast

    def _model_effects(self, name: str) -> dict:
        """Body `name`'s model effects by effect name (as scene.model_effects at construction)."""
        for b, _ in self._wheel_batches:
            for j in b.where(name):
                return {b.name: b.effect(j)}
        return self._modelled.get(name, {})

    def _model_row(self, i: int, me: dict, rows: np.ndarray) -> None:
        """Body i's model row from its model effects me and its current state (a jointed body's r_b, I_p
        from its q and p_w; its p_w, v_w then set from pivot_kinematics)."""
        if not me:                      # a plain body: its row is all zeros (kind 0, ignored by the steppers)
            rows[i] = 0.0
            self._rows_written()
            return
        m, I_b = self._params[i, LY.PARAM_M], self._params[i, LY.PARAM_I_B]
        kind, I_p, r_b, anchor = 0, np.diag(I_b), np.zeros(3), np.zeros(3)
        if "spherical_joint" in me:
            kind |= KIND_JOINT
            anchor = me["spherical_joint"].values["anchor_w"]
            r_b = K.quat_to_matrix(self._x[i, LY.STATE_Q]).T @ (self._x[i, LY.STATE_P_W] - anchor)
            I_p = K.parallel_axis(np.diag(I_b), m, -r_b)
            self._x[i, LY.STATE_P_W], self._x[i, LY.STATE_V_W] = K.pivot_kinematics(
                self._x[i, LY.STATE_Q], self._x[i, LY.STATE_OMEGA_B], anchor, r_b)
        if "reaction_wheels" in me:
            e = me["reaction_wheels"]
            w = e.values
            R_bp = None if self._frames is None else self._frames.rotation(i)
            A_p = e.A_b if R_bp is None else R_bp.T @ e.A_b   # the wheel axes in the principal frame
            kind |= backends.wheel_row(rows[i], w["J"], A_p)
            rows[i, LY.MODEL_TORQUE_LIMIT], rows[i, LY.MODEL_SPEED_LIMIT] = w["torque_limit"], w["speed_limit"]
            rows[i, LY.MODEL_C_W] = w["c_w"]
            rows[i, LY.MODEL_CUTOFF] = w["cutoff"]
        rows[i, LY.MODEL_KIND] = kind
        rows[i, LY.MODEL_I_P] = np.asarray(I_p).reshape(9)
        rows[i, LY.MODEL_R_B] = r_b
        rows[i, LY.MODEL_ANCHOR_W] = anchor
        self._rows_written()

    def _rows_written(self) -> None:
        """Tell the C Stepper (if built) that the model rows were written: it keeps what it decides from them (the step
        kinds, the wheel coefficients: csrc/step.h lv_model_cache) until told. _model_row and _load_snapshot are the
        rows' only writers once it exists (sim.model.rows is a read-only view)."""
        fast = self.__dict__.get("_fast")
        if fast is not None:
            fast.rows_written()

    def reinit_body(self, i: int, p_w: np.ndarray, q: np.ndarray, omega_b: np.ndarray, Omega: np.ndarray) -> None:
        """Body i as if this Sim had been built with it at rest-translation state (p_w, q, v_w = 0, omega_b) and
        then given wheel rates Omega by set_state: model row (joint r_b, I_p), growth reference, wheel command
        and applied torques zeroed. For batched resets (the vector env); the values are not validated here.

        Parameters
        ----------
        i : int
            The body's index in ``names``.
        p_w : ndarray (3,)
            Position, world frame, m (a jointed body's is recomputed from q and its pivot).
        q : ndarray (4,)
            Orientation, body to world, unit quaternion (x, y, z, w).
        omega_b : ndarray (3,)
            Angular velocity, body frame, rad/s.
        Omega : ndarray (N,)
            Wheel rates relative to the body, rad/s (N <= the body's wheels; the others 0).
        """
        with self._lock:
            self._dirty = True
            x = self._x[i]
            x[LY.STATE_P_W], x[LY.STATE_Q], x[LY.STATE_V_W], x[LY.STATE_OMEGA_B] = p_w, q, 0.0, omega_b
            self._model_row(i, self._model_effects(self.names[i]), self._models.rows)
            self._models.Omega[i] = 0.0
            self._models.Omega[i, :np.size(Omega)] = Omega
            self._models.command[i] = 0.0
            self._models.applied[i] = 0.0
            E0, L0 = self._invariants(self._x, self._models.Omega, reference=True)
            self._E0[i], self._L0[i] = E0[i], L0[i]
            self._safe_rates(np.arange(len(self.names)) == i)
            self._rebudget(np.arange(len(self.names)) == i)
            self._warned.discard(i)

    def _rebudget(self, mask=None) -> None:
        """The growth budget of the selected loaded bodies starts again at the current state and step."""
        if self._budget is not None:
            self._budget.reference(self._x, self._models.Omega, self._ctr.steps, mask)
            self._budget.screen_rows(self._g_fast, self._ctr.steps)

    def _check_decays(self, table: np.ndarray, where: str) -> None:
        """The decay bound (lavendersim/load_checks.py) of an effect table: LavenderInputError naming the decays and
        the rule (on_bound="raise"), or a ValidityBoundWarning (on_bound="warn")."""
        hit = load_checks.decay_excess(table, self._params, self.dt, self.integrator)
        if hit is None:
            return
        b, rdt, limit = hit
        mask = load_checks.decay_rows(table) & np.isin(table[:, effects_mod.ROW_BODY].astype(np.int64), (-1, b))
        names = sorted({effects_mod.spec_for_code(int(c)).name for c in table[mask, effects_mod.ROW_CODE]})
        text = f"body {self.names[b]!r}: " + load_checks.decay_text(self.integrator, rdt, limit)
        if self.on_bound == "raise":
            raise V.ValidityBoundError(", ".join(names), text + " (Sim(..., on_bound='warn') to allow it)")
        warnings.warn(f"{where}: {text}; results are not trusted (on_bound='warn')", ValidityBoundWarning, stacklevel=4)

    def _kind(self, i: int) -> int:
        return int(self._models.rows[i, LY.MODEL_KIND])

    # ---- what runs -------------------------------------------------------------------------
    @property
    def pipeline(self) -> pipeline_mod.Pipeline:
        """What runs per step: the integrator's line, each body's line, and the scene's paths.

        A sequence of lines: ``pipeline[0]`` the integrator's, ``pipeline[1 + i]`` (or ``pipeline.body(i or name)``)
        body i's, ``"<name>: <effect terms> -> <kernels>"``. A plain body's kernels are the printed kernels its step
        really runs on this Sim's backend and integrator, by part ("stages (q, omega_b):
        rigid_body_increments_free_c; translation: translation_drift; constants: rigid_body_increment_scale_free"
        for a torque-free RK4 body; a composition's flows; implicit_gyro's loads, Newton solve and exp-map update;
        rk4_expmap's right-hand side and exponential coordinates; a float32 body its tile's kernels), decided from
        derive's tables (lavendersim/pipeline.py, derive/pipeline_meta.py); a body with a joint or wheels its model's
        (rotation and wheels, the motors, the translation or the joint's kinematics; its wheel count and layout). Printed (``print(sim.pipeline)``), it is one
        line per distinct path with the bodies' indices as ranges and their count (``pipeline.groups()`` the same as
        data): readable at a million bodies, built in O(N).

        Returns
        -------
        lavendersim.pipeline.Pipeline
            1 + len(names) lines, each made when read.
        """
        n = self._per_step
        if n is None:
            head = (f"{self.integrator}: adaptive (rtol={self.rtol:g}, atol={self.atol:g}), RHS evaluations counted, "
                    f"each step advances exactly dt on the {self.backend.name} backend"
                    + " (per-body step sizes)")
        else:
            head = f"{self.integrator}: {n} RHS evaluation{'s' if n > 1 else ''} per step on the {self.backend.name} backend"
        head += ", then normalize q" if self.normalize else ", q not normalized"
        return pipeline_mod.Pipeline(head, self.names, self._body_line, self._path_keys, self._i)

    def _path_keys(self) -> np.ndarray:
        """Sim.pipeline's path of each body as one int64 (pipeline.path_keys): its effects' codes from the effect
        table, its model kind, wheel count and layout, and whether it is stepped in a principal frame. O(N)."""
        extra = self._kinds.astype(np.int64) | (self._wheel_n.astype(np.int64) << 2)   # (kind bits 0-1, count 2-9)
        wheeled = np.flatnonzero(self._kinds & KIND_WHEELS)
        if wheeled.size:   # the default layout (backends.on_body_axes, per row: C's on-axes print)
            extra[wheeled] |= np.fromiter((backends.on_body_axes(self._models.rows[i]) for i in wheeled), bool,
                                          wheeled.size).astype(np.int64) << 10
        if self._frames is not None:
            extra[np.asarray(self._frames.idx, dtype=np.intp)] |= 1 << 11
        return pipeline_mod.path_keys(self._effects, extra)

    def _body_line(self, i: int, values: bool = True) -> str:
        """Sim.pipeline's line of body i without its name: its effect terms (with their values, or, values False,
        their names: the path a group of bodies shares), then what its step runs."""
        name = self.names[i]
        model, forces = self._effect_objs.models_on(name), self._effect_objs.forces_on(name)   # (indexed per body)
        mine = model + forces
        kind = self._kind(i)
        if kind:
            wheels, joint = bool(kind & KIND_WHEELS), bool(kind & KIND_JOINT)
            on_axes = wheels and backends.on_body_axes(self._models.rows[i])
            reads_v = any(e.spec.flags & _META.FLAG_USES_V for e in forces)
            kernels = pipeline_mod.model_kernels(self.backend.name, self.integrator, wheels, on_axes, joint, reads_v)
            line = f"{self._terms(mine, values)} -> {kernels}"
            if wheels:
                line += f"; wheels: {self._wheel_n[i]} on {'the body axes' if on_axes else 'axes_b'}"
            if joint and values:
                line += f"; pivot: r_b={np.array2string(self._models.rows[i, LY.MODEL_R_B], precision=4)}"
        else:
            line = self._plain_line(mine, values)
        if self._frames is not None and self._frames.rotation(i) is not None:
            line += "; full inertia tensor: stepped in its principal frame (constant R_bp)"
        return line

    @staticmethod
    def _terms(mine: list, values: bool) -> str:
        """A body line's effect terms: each effect with its values in the order they are summed, or (values False:
        a path's words, the same for every body of the path) the effects' names once each, by effect code."""
        if not mine:
            return "torque- and force-free (no effect terms)"
        if values:
            return " + ".join(e.describe() for e in mine)
        code = {e.name: e.code for e in mine}   # (models: code 0, then by name)
        return " + ".join(sorted(code, key=lambda name: (code[name], name)))

    def _plain_line(self, mine: list, values: bool = True) -> str:
        """Sim.pipeline's line of a plain body with the effects mine: its terms, then the printed kernels its step
        runs on this Sim's backend and integrator (lavendersim/pipeline.py, from derive's tables)."""
        flags = int(np.bitwise_or.reduce([e.spec.rhs_flags for e in mine])) if mine else 0
        user = any(e.spec.user_set is not None for e in mine)
        kernels = pipeline_mod.plain_kernels(self.backend.name, self.integrator, flags, user, self.dtype)
        return f"{self._terms(mine, values)} -> {kernels}"

    # ---- stepping -------------------------------------------------------------------------
    def _backend_advance(self, n: int, restore: bool = True) -> None:
        """n steps on the backend, counters updated; DivergenceError from the backend as it raised it (restore=False:
        the backend keeps no snapshot and leaves the arrays as they are on failure; the caller restores)."""
        models = self._models if self._has_models else None
        ad = self._adaptive
        before = None if ad is None else ad.nfev.copy()
        self.backend.advance(self._x, self._step_params, self._step_effects, self.integrator, self.normalize, self.dt, n, models,
                             *(() if ad is None else (ad,)), restore=restore,
                             **({"contract": self.contract} if self.contract != "off" else {}),
                             **({"cache": self._c_cache} if self._c_cache is not None else {}))
        if ad is None or before is None:
            assert self._per_step is not None   # (a fixed-step integrator)
            self._ctr.rhs_evals += n * self._per_step
        else:
            self._ctr.rhs_evals += int(np.max(ad.nfev - before, initial=0))
        self._ctr.steps += n   # the stepping path bumps the counters directly (the public setters validate)

    def _locate(self, limit: int) -> tuple[int, int, str] | None:
        """From the current state (which passes the checks), the first k in 1..limit whose state after k
        steps fails a check: (k, body, cause), found by re-running in pieces (each piece's end checked,
        the failing piece split again). The state is left somewhere in between: the caller restores it."""
        lo, hi = 0, limit
        while True:
            size = max(1, (hi - lo) // 16)
            k = lo
            found: tuple[int, int, tuple | None] | None = None
            while k < hi:
                m = min(size, hi - k)
                pre = self._snapshot()
                try:
                    self._backend_advance(m)
                except DivergenceError:
                    self._restore(pre)
                    if m == 1:
                        return None       # non-finite before any check failed
                    found = (k, m, None)
                    break
                v = self._violation(self._x, self._models.Omega, warn=False)
                if v is not None:
                    if m == 1:
                        return k + 1, v[0], v[1]
                    self._restore(pre)
                    found = (k, m, v)
                    break
                k += m
            if found is None:
                return None
            lo, hi = found[0], found[0] + found[1]

    def _advance(self, n: int) -> None:
        if self.steps + n > MAX_STEPS:
            raise V.LavenderInputError("n_steps", f"the Sim would pass MAX_STEPS = 2**53 steps in total "
                                       f"({self.steps} done + {n})")
        start = self._snapshot(reuse=True)
        steps0 = self.steps
        sizes: list[int] = []

        def to_chunk_start():
            """Back to the start of the current chunk by replay: restore the call's start and re-run the
            chunks that passed (the same backend calls, so bitwise the same, dopri5 too): no copy per chunk."""
            self._restore(start)
            for size in sizes:
                self._backend_advance(size)

        def fail(k: int, body: int, cause: str):   # k: 0-based index of the failing step within this call
            self._restore(start)
            return DivergenceError(steps0 + k, body, cause, self.names[body], t=(steps0 + k + 1) * self.dt)

        try:
            # before stepping: the bound (the state may have been written since the last check); the growth
            # check ran on the end state of the previous call
            if not self._is_checked():
                v = self._violation(self._x, self._models.Omega, growth=False)
                if v is not None:
                    raise fail(0, v[0], "before the step: " + v[1])
            done = 0
            while done < n:
                m = min(self._chunk, n - done)
                try:
                    self._backend_advance(m, restore=False)   # no copy per chunk: a failure is restored by replay
                except DivergenceError:
                    to_chunk_start()
                    try:     # the same steps again (bitwise), the backend keeping its snapshot: the failure, its cause named
                        self._backend_advance(m)
                    except DivergenceError as e:
                        to_chunk_start()
                        hit = self._locate(e.step) if e.step > 0 else None
                        if hit is not None:
                            raise fail(done + hit[0] - 1, hit[1], hit[2]) from None
                        raise fail(done + e.step, e.body, e.cause) from None
                v = self._violation(self._x, self._models.Omega)
                if v is not None:
                    to_chunk_start()
                    hit = self._locate(m)
                    if hit is None:     # (dopri5: the pieces' trajectory differs from the chunk's by rounding)
                        hit = (m, v[0], v[1])
                    raise fail(done + hit[0] - 1, hit[1], hit[2]) from None
                done += m
                sizes.append(m)
            self._mark_checked()
            if self._budget is not None:   # the C screen's budget limits follow the passed check's time
                self._budget.screen_rows(self._g_fast, self._ctr.steps)
        except DivergenceError:
            raise
        except BaseException:           # KeyboardInterrupt between chunks, or any error: nothing half-applied
            self._restore(start)
            raise

    def fast_chunks(self) -> None:
        """Let run(n) take the C fast path (Stepper.advance) for any n up to one chunk, whatever the scene's size: for
        a caller that advances a large scene by a few steps per call (the vector env: N cubes, one run per env step).
        Stepper.advance checks the chunk's end as _advance does (the validity bound, the growth limits, finite) and
        otherwise restores the arrays bitwise and steps aside to the Python path, so the results, the checks and the
        errors are those of run; but it holds the GIL for the whole call (other Python threads wait for it). The
        Stepper is built here also beyond FAST_STEP_WORK (then sim.step() too runs inside C). On a new Sim only (no
        step taken: the Stepper's counters start at 0); where there is no C fast path at all, nothing changes."""
        if self.steps or self.rhs_evals:
            raise RuntimeError("Sim.fast_chunks: only on a new Sim (no step taken)")
        if self._fast is None:
            fast = self._make_stepper(cap=False)
            if fast is None:
                return
            self._fast, self._ctr, self._lock = fast, fast, _Guard(fast)
            fast.set_fallback(self._step_slow)
            object.__setattr__(self, "step", fast.step_or_fallback)   # (built: no public assignment)
        self._fast_n = self._chunk

    def check_written(self) -> None:
        """_advance's check before stepping (the validity bound of a state written since the last check, e.g. by
        reinit_body), done now where the C screen passes it: the state is then marked checked, so the next run(n)
        can take the C fast path. Exactly what _advance would find (its check of a written state is this screen
        with growth off: passing it reports nothing). Where the screen does not pass, or there is no C fast path,
        nothing changes: run checks the state itself and raises or warns as before."""
        f, screen = self._fast, self._screen
        if f is None or screen is None:
            return
        with self._lock:
            if not f.is_checked() and screen(self._x, self._params, self._wdt_scale,
                                             np.inf if self._bound is None else float(self._bound[0]), self._g_inf()):
                self._mark_checked()

    def _is_checked(self) -> bool:
        """The state is the last one that passed the checks: compared bytewise by the C stepper; else tracked by a
        flag that every writer sets (set_state, reinit_body; the views are read-only and their flag cannot be
        turned back on, so no public path writes the state without setting it)."""
        if self._fast is not None:
            return self._fast.is_checked()
        return not self._dirty

    def _mark_checked(self) -> None:
        if self._fast is not None:
            self._fast.mark_checked()
        self._dirty = False

    def step(self) -> None:
        """Advance one step (see run).

        On the C backend a step whose every check passes is taken inside C (fast_step.c); any other step
        (a check fails, the state was written since the last check, another thread holds the Sim) takes the
        Python path, which raises or warns as run does."""
        f = self._fast
        if f is not None and f.step():
            return
        self._step_slow()

    def _step_slow(self) -> None:
        with self._lock:
            self._advance(1)

    def run(self, n_steps: int) -> None:
        """Advance `n_steps` steps of `dt` (inside C on the C backend).

        Parameters
        ----------
        n_steps : int
            Number of steps, 0 <= n_steps <= MAX_STEPS (2**53).

        Raises
        ------
        DivergenceError
            On a non-finite state, a validity bound exceeded (``on_bound="raise"``) or a growth beyond
            `max_growth`; it names the step, the body and the likely cause, and the Sim is left as
            before the call (see the module docstring).
        LavenderInputError
            If `n_steps` is not an integer in range.
        """
        f = self._fast
        if f is not None and type(n_steps) is int and 0 < n_steps <= self._fast_n:   # (valid as it is: V.integer's n)
            if f.advance(n_steps):
                return     # one chunk inside C, its end checked as _advance checks it
            n = n_steps
        else:
            n = V.integer("n_steps", n_steps, minimum=0)
            if n > MAX_STEPS:
                raise V.LavenderInputError("n_steps", "must be at most MAX_STEPS = 2**53 (9.0e15)", f", got {n}")
            if not n:
                return
            if f is not None and n <= self._fast_n and f.advance(n):
                return
        with self._lock:
            self._advance(n)

    def run_for(self, duration: float) -> None:
        """Advance by ``round(duration / dt)`` steps (as :meth:`run`).

        Parameters
        ----------
        duration : float
            Simulated time to advance, s (>= 0).

        Raises
        ------
        DivergenceError
            As :meth:`run`; the Sim is restored.
        LavenderInputError
            If `duration` is negative, non-finite or more than 2**53 steps.
        """
        d = V.scalar("duration", duration, nonnegative=True)
        n = d / self.dt
        if not n <= MAX_STEPS:
            raise V.LavenderInputError("duration", f"must be at most MAX_STEPS*dt = {MAX_STEPS * self.dt:.3g} s "
                                       "(2**53 steps)", f", got {d!r}")
        self.run(int(round(n)))

    def record(self, n_steps: int, every: int = 1) -> Trajectory:
        """Advance `n_steps`, sampling the state every `every` steps (the initial state included).

        Parameters
        ----------
        n_steps : int
            Number of steps (>= 0).
        every : int, optional
            Sampling interval in steps (>= 1); must divide `n_steps`.

        Returns
        -------
        Trajectory
            ``n_steps // every + 1`` samples: t (T,), x (T, nb, 13), Omega (T, nb, WHEELS_MAX).

        Raises
        ------
        DivergenceError
            As :meth:`run`; on it (or KeyboardInterrupt) the Sim is left exactly as before the call.
        LavenderInputError
            On a bad `n_steps` or `every`.
        """
        n = V.integer("n_steps", n_steps, minimum=0)
        every = V.integer("every", every, minimum=1)
        if n > MAX_STEPS:
            raise V.LavenderInputError("n_steps", "must be at most MAX_STEPS = 2**53 (9.0e15)", f", got {n}")
        if n % every:
            raise V.LavenderInputError("every", f"must divide n_steps ({n})", f", got {every}")
        with self._lock:
            start = self._snapshot()
            xs, Ws, ts = [self._x.copy()], [self._models.Omega.copy()], [self.t]
            try:
                for _ in range(n // every):
                    self._advance(every)
                    xs.append(self._x.copy())
                    Ws.append(self._models.Omega.copy())
                    ts.append(self.t)
            except BaseException:
                self._restore(start)
                raise
        return Trajectory(self.names, np.array(ts), public_rows(self._frames, np.stack(xs)), np.stack(Ws), self._wheel_n)

    # ---- state access ---------------------------------------------------------------------
    def state(self, name: str) -> BodyState:
        """A copy of one body's current state; O(1) in the number of bodies (a dict lookup).

        For every body at once without copying use the views ``x``, ``p_w``, ``q``, ``v_w``, ``omega_b``
        and ``Omega``.

        Parameters
        ----------
        name : str
            The body's name.

        Returns
        -------
        BodyState
            ``p_w`` (3,) m, ``q`` (4,) (x, y, z, w), ``v_w`` (3,) m/s, ``omega_b`` (3,) rad/s, and derived
            ``omega_w``, ``R_wb``; ``Omega`` (N,) the rates of its N wheels, rad/s (three zeros without
            wheels).

        Raises
        ------
        LavenderInputError
            If no body has that name.
        """
        i = self._i(name)
        x = self._x[i].copy() if self._frames is None else self._frames.public_row(i, self._x[i])
        return BodyState.of_slots(x, self._models.Omega[i].copy(), int(self._wheel_n[i]))

    @V.keywords  # an unknown keyword (a typo such as omega=) is a LavenderInputError naming it
    def set_state(self, name: str, *, p_w=None, q=None, v_w=None, omega_b=None, omega_w=None, Omega=None) -> None:
        """Set parts of one body's state; everything is validated before anything changes.

        Omega (wheel rates, rad/s) only for a body with reaction_wheels. A jointed body's p_w and v_w
        follow from q and omega (pivot_kinematics) and cannot be set.

        Parameters
        ----------
        name : str
            The body's name.
        p_w : array_like, shape (3,), optional
            COM position, world frame, m.
        q : array_like, shape (4,), optional
            Orientation quaternion (x, y, z, w), normalized here; body to world.
        v_w : array_like, shape (3,), optional
            COM velocity, world frame, m/s.
        omega_b, omega_w : array_like, shape (3,), optional
            Angular velocity in the body or in the world frame, rad/s (give at most one).
        Omega : array_like, shape (3,), optional
            Wheel rates relative to the body, rad/s.

        Raises
        ------
        LavenderInputError
            On an unknown body or keyword, a bad value, or a state beyond the integrator's validity bound.
        """
        with self._lock:   # read, modify and write the body's row as one update: no lost update against run()
            self._set_state(name, p_w=p_w, q=q, v_w=v_w, omega_b=omega_b, omega_w=omega_w, Omega=Omega)

    def _set_state(self, name: str, *, p_w, q, v_w, omega_b, omega_w, Omega) -> None:
        i = self._i(name)
        kind = self._kind(i)
        frames = self._frames
        R_bp = None if frames is None else frames.rotation(i)
        x = self._x[i].copy() if frames is None or R_bp is None else frames.public_row(i, self._x[i])
        if kind & KIND_JOINT:
            for field, value in (("p_w", p_w), ("v_w", v_w)):
                if value is not None:
                    raise V.LavenderInputError(field, f"body {name!r} is on a spherical_joint: its p_w and v_w follow "
                                               "from q and omega; set those instead")
        if p_w is not None:
            x[LY.STATE_P_W] = V.vector("p_w", p_w)
        if q is not None:
            x[LY.STATE_Q] = V.quaternion("q", q)
        if v_w is not None:
            x[LY.STATE_V_W] = V.vector("v_w", v_w)
        if omega_b is not None and omega_w is not None:
            raise V.LavenderInputError("omega_w", "give omega_b or omega_w, not both")
        if omega_b is not None:
            x[LY.STATE_OMEGA_B] = V.vector("omega_b", omega_b)
        if omega_w is not None:
            x[LY.STATE_OMEGA_B] = K.world_to_body(x[LY.STATE_Q], V.vector("omega_w", omega_w))
        W = None
        if Omega is not None:
            if not kind & KIND_WHEELS:
                raise V.LavenderInputError("Omega", f"body {name!r} has no reaction_wheels")
            W = np.zeros(LY.WHEELS_MAX)
            W[:self._wheel_n[i]] = V.vector("Omega", Omega, int(self._wheel_n[i]))
        if frames is not None and R_bp is not None:   # back to the principal frame: only what was given
            given, x_int = frames.internal_row(i, x), self._x[i].copy()
            x_int[LY.STATE_P_W], x_int[LY.STATE_V_W] = x[LY.STATE_P_W], x[LY.STATE_V_W]
            if q is not None:
                x_int[LY.STATE_Q] = given[LY.STATE_Q]
            if omega_b is not None or omega_w is not None:
                x_int[LY.STATE_OMEGA_B] = given[LY.STATE_OMEGA_B]
            x = x_int
        if kind & KIND_JOINT:
            r = self._models.rows[i]
            x[LY.STATE_P_W], x[LY.STATE_V_W] = K.pivot_kinematics(x[LY.STATE_Q], x[LY.STATE_OMEGA_B],
                                                                 r[LY.MODEL_ANCHOR_W], r[LY.MODEL_R_B])
        field = "omega_w" if omega_w is not None else "omega_b"
        with np.errstate(over="ignore", invalid="ignore"):
            E = K.kinetic_energy(self._params[i, LY.PARAM_M], self._params[i, LY.PARAM_I_B], x[LY.STATE_V_W],
                                 x[LY.STATE_OMEGA_B])
        if not (np.all(np.isfinite(x)) and np.isfinite(E)):
            raise V.LavenderInputError(field if (omega_b is not None or omega_w is not None) else "v_w",
                                       "the body's kinetic energy is not representable (overflows float64)")
        if self._bound is not None:
            wdt = float(self._wdt(x[None], [i])[0])
            if not wdt <= self._bound[0]:
                if self.on_bound == "raise":
                    raise V.ValidityBoundError(field, self._bound_text(wdt) + " (Sim(..., on_bound='warn') to allow it)")
                warnings.warn(f"body {name!r}: {self._bound_text(wdt)}", ValidityBoundWarning, stacklevel=2)
        with self._lock:
            self._dirty = True
            self._x[i] = x
            if W is not None:
                self._models.Omega[i] = W
            E0, L0 = self._invariants(self._x, self._models.Omega, reference=True)
            self._E0[i], self._L0[i] = E0[i], L0[i]
            self._safe_rates(np.arange(len(self.names)) == i)   # the no-work region follows the new E0
            self._rebudget(np.arange(len(self.names)) == i)

    # ---- effect parameters between steps ---------------------------------------------------
    def set_effect_params(self, effect, **values):
        """Change parameters of one force effect for the steps that follow (a disturbance that varies between
        controller samples, a thruster switched on): validated like the effect itself, applied at once or
        not at all, seen by both backends from the next step. Model effects (spherical_joint, reaction_wheels)
        are constants of the body's model and cannot change here.

        Parameters
        ----------
        effect : Effect
            The effect as ``Scene.add_effect`` returned it (or as a previous call returned it).
        **values
            New values of some of its declared parameters, in their units and frames (a body-frame
            parameter such as ``r_b`` in the user's body frame); the others keep theirs.

        Returns
        -------
        Effect
            The effect with its new values (effects are immutable: the scene's object is unchanged).

        Raises
        ------
        LavenderInputError
            If ``effect`` is not a force effect of this Sim, a parameter is unknown or invalid (named
            ``effect.param``), or the new load would overflow; the Sim is left as it was.

        Examples
        --------
        >>> import lavendersim as lv
        >>> scene = lv.Scene()
        >>> b = scene.add_body(lv.Body.box("b", 1.0, (0.1, 0.1, 0.1)))
        >>> push = scene.add_effect("applied_torque", body="b", torque_w=[0, 0, 0])
        >>> sim = lv.Sim(scene, dt=1e-3)
        >>> push = sim.set_effect_params(push, torque_w=[0, 0, 1e-3])
        >>> sim.run(100)
        >>> round(float(sim.state("b").omega_w[2]), 6)
        0.06
        """
        with self._lock:   # the current values are read and replaced as one update
            return self._set_effect_params(effect, values)

    def _set_effect_params(self, effect, values: dict):
        k = self._forces.find(effect)
        k = self._forces_given.find(effect) if k is None else k
        if k is None:
            what = getattr(effect, "name", type(effect).__name__)
            rule = ("is a model effect (a constant of the body's model); build a new Sim to change it"
                    if getattr(effect, "per_body", False) else "is not a force effect of this Sim (pass the object "
                    "Scene.add_effect returned)")
            raise V.LavenderInputError("effect", rule, f", got {what!r}")
        cur = self._forces[k]
        new = effects_mod.make(cur.name, body=cur.body, **{**dict(cur.values), **values})
        targets = [self.bodies[cur.body]] if cur.body is not None else list(self.bodies.values())
        for b in targets:
            why = effects_mod.load_overflow([new], b)
            if why:
                raise V.LavenderInputError(effects_mod.largest_param(new), f"too large: {why}")
        body_index = -1 if cur.body is None else self._index[cur.body]
        rows = _effect_rows(new, body_index, self._effects.shape[1], self._frames, len(self.names))
        table = self._effects.copy()
        for r, row in zip(self._rows_of[k], rows):
            table[r] = row
        self._check_decays(table, "set_effect_params")      # raises before anything changes (on_bound="raise")
        for r, row in zip(self._rows_of[k], rows):
            self._effects[r] = row
            if self._step_effects is not self._effects:
                self._step_effects[r] = row
        self._forces[k] = new
        at = self._effect_objs.find(cur)
        if at is not None:
            self._effect_objs[at] = new
        if self._adaptive is not None:   # dopri5's dense output ran ahead under the old loads
            self._adaptive.forget()
        if self._budget is not None:   # new loads: the budget restarts from this (checked) state
            assert self.max_growth is not None   # (a budget exists only with a growth check)
            self._budget = load_checks.LoadBudget(self._params, self._effects, self._models.rows, self._budget.loaded,
                                                  self.dt, self.max_growth)
            self._rebudget()
        return new

    # ---- reaction wheels ------------------------------------------------------------------
    def _wheeled(self, name: str) -> int:
        i = self._i(name)
        if not self._kind(i) & KIND_WHEELS:
            raise V.LavenderInputError("body", f"body {name!r} has no reaction_wheels")
        return i

    def set_wheel_command(self, name: str, u) -> None:
        """Command motor torques on a body's reaction wheels, held until changed; saturated every step.

        Parameters
        ----------
        name : str
            A body with a ``reaction_wheels`` effect.
        u : array_like, shape (N,)
            Torques on its N wheels in the order of ``axes_b`` (body x, y, z by default), N·m.

        Raises
        ------
        LavenderInputError
            If the body has no wheels or `u` is not N finite numbers.
        """
        i = self._wheeled(name)
        u_full = np.zeros(LY.WHEELS_MAX)
        u_full[:self._wheel_n[i]] = V.vector("u", u, int(self._wheel_n[i]))
        with self._lock:
            self._models.command[i] = u_full

    def set_wheel_commands(self, u) -> None:
        """Motor torques of every body's wheels at once; held until changed, saturated every step, as
        set_wheel_command.

        Parameters
        ----------
        u : array_like, (nb, 3) or (nb, WHEELS_MAX)
            Commanded wheel torques, N·m, in body order, a body's wheels in its first N columns (three
            columns suffice when no body has more than three wheels); the other entries must be zero.

        Raises
        ------
        LavenderInputError
            A wrong shape, a non-finite value, or a non-zero entry beyond a body's wheels.
        """
        nb = len(self.names)
        u = V.array("u", u, (nb, None))
        if u.shape[1] not in (LY.WHEELS_BODY_AXES, LY.WHEELS_MAX):
            raise V.LavenderInputError("u", f"expected shape ({nb}, {LY.WHEELS_BODY_AXES}) or ({nb}, {LY.WHEELS_MAX})",
                                       f", got {u.shape}")
        stray = np.arange(u.shape[1])[None, :] >= self._wheel_n[:, None]
        bad = np.flatnonzero(np.any(stray & (u != 0), axis=1))
        if bad.size:
            b = int(bad[0])
            raise V.LavenderInputError(f"u[{b}]", f"body {self.names[b]!r} has {self._wheel_n[b]} reaction wheel(s): "
                                       "the entries beyond them must be 0")
        with self._lock:   # one update: a run in another thread never sees the zeroed commands
            self._models.command[...] = 0.0
            self._models.command[:, :u.shape[1]] = u

    @property
    def wheel_torques_applied(self) -> np.ndarray:
        """The saturated wheel torques of the most recent step for every body, (nb, WHEELS_MAX) N·m, a body's
        wheels in its first N columns (zeros before the first step and beyond its wheels): a read-only view."""
        return self._views[6]

    def _wheel_values(self, name: str, per_body: np.ndarray) -> np.ndarray:
        """Body `name`'s wheel entries of per_body (nb, WHEELS_MAX), a copy (LavenderInputError without wheels)."""
        i = self._wheeled(name)
        return per_body[i, :self._wheel_n[i]].copy()

    def wheel_command(self, name: str) -> np.ndarray:
        """The commanded (unsaturated) wheel torques, N·m.

        Parameters
        ----------
        name : str
            A body with reaction wheels.

        Returns
        -------
        ndarray, shape (N,)
            One entry per wheel, in the order of ``axes_b``.
        """
        return self._wheel_values(name, self._models.command)

    def wheel_command_applied(self, name: str) -> np.ndarray:
        """The saturated wheel torques used in the most recent step (zeros before the first), N·m.

        Parameters
        ----------
        name : str
            A body with reaction wheels.

        Returns
        -------
        ndarray, shape (N,)
            One entry per wheel, in the order of ``axes_b``.
        """
        return self._wheel_values(name, self._models.applied)

    def wheel_rates(self, name: str) -> np.ndarray:
        """Wheel rates relative to the body, rad/s.

        Parameters
        ----------
        name : str
            A body with reaction wheels.

        Returns
        -------
        ndarray, shape (N,)
            One entry per wheel, in the order of ``axes_b``.
        """
        return self._wheel_values(name, self._models.Omega)

    def wheel_momentum_w(self, name: str) -> tuple[np.ndarray, np.ndarray]:
        """(L_body_w, L_wheels_w), world frame, kg·m²/s, from the wheels<N>_momentum kernel: about the
        joint's pivot for a jointed body, about the COM otherwise; L_wheels_w is zero without wheels.

        Parameters
        ----------
        name : str
            The body's name.

        Returns
        -------
        L_body_w, L_wheels_w : ndarray, shape (3,)
        """
        i = self._i(name)
        return backends.wheel_momentum(self._models.rows[i], self._x[i, LY.STATE_Q], self._x[i, LY.STATE_OMEGA_B],
                                       self._models.Omega[i])

    def _i(self, name: str) -> int:
        try:
            return self._index[name]
        except (KeyError, TypeError):   # TypeError: an unhashable name
            raise V.LavenderInputError("body", f"unknown body {name!r}; bodies: {', '.join(self.names[:20])}"
                                       + (f", … ({len(self.names)} bodies)" if len(self.names) > 20 else "")) from None

    def kinetic_energy(self, name: str | None = None) -> float:
        """Kinetic energy of one body, or of all bodies (name=None), J: ½ m|v|² + ½ ωᵀ I_b ω with
        wheels locked (a jointed body's v_w is its kinematic COM velocity; wheel spin not included).

        Parameters
        ----------
        name : str or None, optional
            A body name, or None for the sum over all bodies.

        Returns
        -------
        float
            Kinetic energy, J.
        """
        idx = range(len(self.names)) if name is None else [self._i(name)]
        return float(sum(K.kinetic_energy(self._params[i, LY.PARAM_M], self._params[i, LY.PARAM_I_B], self._x[i, LY.STATE_V_W],
                                          self._x[i, LY.STATE_OMEGA_B]) for i in idx))

    def angular_momentum_w(self, name: str) -> np.ndarray:
        """Angular momentum about the body's COM, world frame, kg·m²/s.

        Parameters
        ----------
        name : str
            The body's name.

        Returns
        -------
        ndarray, shape (3,)
            ``L_w = R_wb I_b omega_b``.
        """
        i = self._i(name)
        return K.angular_momentum_world(self._x[i, LY.STATE_Q], self._params[i, LY.PARAM_I_B],
                                        self._x[i, LY.STATE_OMEGA_B])

    def linear_momentum_w(self, name: str) -> np.ndarray:
        """Linear momentum ``m v_w``, world frame, kg·m/s.

        Parameters
        ----------
        name : str
            The body's name.

        Returns
        -------
        ndarray, shape (3,)
        """
        i = self._i(name)
        return self._params[i, LY.PARAM_M] * self._x[i, LY.STATE_V_W]
