"""C backend: the step loop runs inside the compiled extension `lavendersim._lavender_c`.

One `advance` call advances every body by n_steps steps without returning to Python (bodies outer,
steps inner). The extension embeds the sha256 of the generated C sources (HASHED) it was built
from; importing this module compares it with the files on disk and raises StaleBuildError (naming
the rebuild command) when they differ. If the extension was never built, the ImportError says how.
"""
from __future__ import annotations

import functools
import hashlib
import importlib
import json
from pathlib import Path
from typing import Any

import numpy as np

from .. import validate as V
from ..effects import ROW, ROW_BODY
from ..errors import DivergenceError, StaleBuildError
from ..generated import tableaux as TABLEAUX
from .._install import rebuild_command
from ..generated import layout as LY
from .base import (ADAPTIVE, FLOAT32_INTEGRATORS, KIND_WHEELS, PLAIN_ONLY, Adaptive, Models, Tableau, no_root_cause,
                   norm_safe, rk_weights, tableau_of, tolerance_cause)

REBUILD = rebuild_command()
HASHED = ("kernels.c", "kernels.h", "layout.h", "tableaux.h", "kernels_f32.c", "kernels_f32.h")  # every generated file the extension compiles
INTEGRATOR_CODES = TABLEAUX.INTEGRATOR_CODES   # the printed registry (derive/tableaux.py)

# The compiled extension (lavendersim/_lavender_c*.so) is a leaf: its C imports nothing of the package. It is
# loaded by name, because an import statement of a module that has no .py file reads, to the import-graph scans
# (tests/test_import_cycles, the stop hook), as an import of the lavendersim package itself: a false circle
# lavendersim -> sim -> backends -> c_backend -> lavendersim.
try:
    _c = importlib.import_module("lavendersim._lavender_c")
except ImportError as exc:  # not built (or built for another interpreter)
    raise ImportError(
        "lavendersim's C backend (lavendersim._lavender_c) is not built or failed to load "
        f"({exc}). Build it with `{REBUILD}` (needs a C99 compiler and the Python headers), or use the "
        "NumPy backend (backend='numpy'; backend='auto', the default, falls back to it)."
    ) from exc


def generated_dir() -> Path:
    """The folder of the ``lavendersim.generated`` package (resolved), whose C sources the build must match.

    Returns
    -------
    Path
    """
    from ..generated import layout  # any module of the package: its folder is the package's

    return Path(layout.__file__).resolve().parent


def generated_hash(gen_dir: Path) -> str:
    """sha256 over the per-file sha256 of the generated C sources HASHED (same recipe as setup.py).

    Parameters
    ----------
    gen_dir : Path
        Folder holding the HASHED files.

    Returns
    -------
    str
        Hex digest.

    Raises
    ------
    OSError
        A HASHED file cannot be read.
    """
    h = hashlib.sha256()
    for name in HASHED:
        h.update(f"{name} {hashlib.sha256((gen_dir / name).read_bytes()).hexdigest()}\n".encode())
    return h.hexdigest()


def _generated_inconsistent(gen_dir: Path) -> list[str]:
    """Files of gen_dir whose sha256 differs from manifest.json (hand-edited or half-regenerated)."""
    try:
        man = json.loads((gen_dir / "manifest.json").read_text(encoding="utf-8"))
        want = man["outputs_sha256"]
    except (OSError, ValueError, KeyError, TypeError):
        return ["manifest.json"]
    bad = []
    for name in HASHED:
        p = gen_dir / name
        if name not in want or not p.is_file() or hashlib.sha256(p.read_bytes()).hexdigest() != want[name]:
            bad.append(name)
    return bad


def check_build(gen_dir: Path | None = None, built_hash: str | None = None) -> None:
    """Raise StaleBuildError if the extension was built from other generated sources than gen_dir's.

    Parameters
    ----------
    gen_dir : Path, optional
        Folder of the generated C sources (default :func:`generated_dir`).
    built_hash : str, optional
        The hash the extension was built from (default the extension's ``GENERATED_HASH``).

    Raises
    ------
    lavendersim.errors.StaleBuildError
        The hashes differ or the sources cannot be read; the message names the rebuild command
        (and ``lavendersim derive`` when generated/ does not match its manifest).
    """
    gen_dir = generated_dir() if gen_dir is None else Path(gen_dir)
    built = _c.GENERATED_HASH if built_hash is None else built_hash
    try:
        current = generated_hash(gen_dir)
    except OSError as exc:
        raise StaleBuildError(f"cannot read the generated C sources in {gen_dir} ({exc}); "
                              f"run `lavendersim derive`, then rebuild with `{REBUILD}`") from exc
    if built == current:
        return
    msg = (f"lavendersim._lavender_c is stale: it was built from other generated C sources than "
           f"{gen_dir}/ ({', '.join(HASHED)}; built {built[:12]}…, on disk {current[:12]}…). "
           f"Rebuild it with `{REBUILD}`.")
    bad = _generated_inconsistent(gen_dir)
    if bad:
        msg += (f" generated/ itself does not match its manifest ({', '.join(bad)}): "
                f"regenerate it with `lavendersim derive` first, then run `{REBUILD}`.")
    raise StaleBuildError(msg)


check_build()


def _kernel_index() -> dict[str, tuple[int, int, int]]:
    return {name: (i, n_in, n_out) for i, (name, n_in, n_out) in enumerate(_c.kernels())}


_INDEX = _kernel_index()


def eval_kernel(name: str, *inputs):
    """Evaluate generated kernel `name` through C, broadcasting leading batch axes like
    generated/kernels_numpy.py. Returns the outputs (a tuple when there are several), shaped like
    the NumPy kernel's: batch + output shape.

    Parameters
    ----------
    name : str
        A kernel of generated/kernels_numpy.py's ``KERNELS``.
    *inputs : array_like
        One per kernel input, each ending in that input's shape; leading axes broadcast.

    Returns
    -------
    ndarray or tuple of ndarray
        float64, batch shape + each output's shape.

    Raises
    ------
    KeyError
        Unknown kernel.
    TypeError
        Wrong number of inputs.
    ValueError
        An input whose trailing shape does not match.
    """
    from ..generated.kernels_numpy import KERNELS

    if name not in KERNELS or name not in _INDEX:
        raise KeyError(f"eval_kernel: unknown kernel {name!r}")
    entry: tuple[Any, ...] = KERNELS[name]   # (fn, [(input, shape)], [(output, shape)])
    _, in_spec, out_spec = entry
    index, n_in, n_out = _INDEX[name]
    if len(inputs) != len(in_spec):
        raise TypeError(f"eval_kernel({name}): expected {len(in_spec)} inputs "
                        f"({', '.join(n for n, _ in in_spec)}), got {len(inputs)}")
    arrs, batches = [], []
    for (arg, shape), value in zip(in_spec, inputs):
        a = np.asarray(value, dtype=np.float64)
        k = len(shape)
        if a.ndim < k or tuple(a.shape[a.ndim - k:]) != tuple(shape):
            raise ValueError(f"eval_kernel({name}): input {arg} must end in shape {shape}, got {a.shape}")
        arrs.append(a)
        batches.append(a.shape[:a.ndim - k])
    batch = np.broadcast_shapes(*batches)
    rows = int(np.prod(batch, dtype=np.int64))
    packed = np.empty((rows, n_in))
    col = 0
    for (arg, shape), a in zip(in_spec, arrs):
        size = int(np.prod(shape, dtype=np.int64))
        packed[:, col:col + size] = np.broadcast_to(a, batch + tuple(shape)).reshape(rows, size)
        col += size
    if col != n_in:
        raise RuntimeError(f"eval_kernel({name}): NumPy kernel table packs {col} inputs, C table {n_in}; "
                           f"rebuild with `{REBUILD}`")
    out = np.empty((rows, n_out))
    _c.eval_kernel(index, packed, out)
    results, col = [], 0
    for arg, shape in out_spec:
        size = int(np.prod(shape, dtype=np.int64))
        results.append(out[:, col:col + size].reshape(batch + tuple(shape)).copy())
        col += size
    return results[0] if len(results) == 1 else tuple(results)


def scalar_kernel(name: str):
    """Generated kernel `name` through C as a function of Python numbers, for a hot loop on one row (no arrays).

    Parameters
    ----------
    name : str
        A kernel of the C table (``lavendersim._lavender_c.kernels()``).

    Returns
    -------
    callable
        ``f(x0, ..., x{n_in-1})``: the inputs flattened in the kernel's argument order (a quaternion's
        four numbers (x, y, z, w), then the next argument's); returns a float when the kernel has one output
        number, else a tuple of its n_out numbers in order.

    Raises
    ------
    KeyError
        Unknown kernel.
    """
    if name not in _INDEX:
        raise KeyError(f"scalar_kernel: unknown kernel {name!r}")
    return functools.partial(_c.call_kernel, _INDEX[name][0])


def _cause(start: np.ndarray, pre: np.ndarray, params: np.ndarray, effects: np.ndarray, body: int,
           step: int, dt: float, integrator: str, model: tuple | None = None) -> str:
    """Likely cause, from the body's state at the start of the call (`start`) and just before the
    failing step (`pre`, its last finite state). model = (row, Omega at start, Omega before the
    failing step, command) for a body with a joint or wheels; the Omega entries are None without wheels."""
    if not np.all(np.isfinite(params[body])):
        return f"non-finite input: params of body {body} are {params[body].tolist()}"
    mine = effects[(effects[:, ROW_BODY] == -1) | (effects[:, ROW_BODY] == body)]
    if mine.size and not np.all(np.isfinite(mine)):
        return f"non-finite input: an effect acting on body {body} has non-finite parameters"
    if model is not None and not np.all(np.isfinite(model[0])):
        return f"non-finite input: the joint/wheel model row of body {body} has non-finite entries"
    if model is not None and not np.all(np.isfinite(model[3])):
        return f"non-finite input: the wheel command of body {body} is {model[3].tolist()}"
    W0 = None if model is None else model[1]
    if not np.all(np.isfinite(start)) or (W0 is not None and not np.all(np.isfinite(W0))):
        return "non-finite input: the state was already non-finite before the step"
    from .base import divergence_cause, wheel_counts

    n = int(wheel_counts(model[0])) if model is not None and W0 is not None else 0
    wheels = None if model is None or W0 is None else (model[0][LY.MODEL_J][:n], model[0][LY.MODEL_C_W])
    cause = divergence_cause(start, dt, integrator, params[body, LY.PARAM_I_B], None if W0 is None else W0[:n], wheels)
    if step > 0:
        wtxt = "" if model is None or W0 is None else f", |Omega| = {norm_safe(model[2]):.3g} rad/s"
        cause += (f" (just before step {step}: |omega|*dt = {norm_safe(pre[LY.STATE_OMEGA_B]) * dt:.3g}, "
                  f"|v| = {norm_safe(pre[LY.STATE_V_W]):.3g} m/s{wtxt})")
    return cause


def user_effect_table(effects: np.ndarray) -> np.ndarray | None:
    """The C user-effect table for the codes in this effect table: int64 (n, 16) rows [function address,
    n_params, flags, tile forms (base, avx2, avx512), body-frame form, its tile forms, fused tiles (q raw: base,
    avx2, avx512; normalized: the same)] (csrc/step.h lv_user_table_row; 0: none, the body-frame ones for an
    effect declaring torque_b alone, the fused ones for an effect that reads the state), row i for code
    USER_CODE_BASE + i; None when no user code appears. Compiles (cached) and loads each user set's library on
    first use.

    Parameters
    ----------
    effects : ndarray (n, ROW)
        The scene's effect table.

    Returns
    -------
    ndarray (m, 16) of int64 or None

    Raises
    ------
    lavendersim.validate.LavenderInputError
        A user code that no declaration has.
    """
    from .. import effects as E

    codes = np.unique(effects[:, E.ROW_CODE]).astype(np.int64) if len(effects) else np.zeros(0, np.int64)
    user = codes[codes >= E.USER_CODE_BASE]
    if not user.size:
        return None
    table = np.zeros((int(user.max()) - E.USER_CODE_BASE + 1, 16), dtype=np.int64)
    for code in user:
        spec = E.spec_for_code(int(code))  # LavenderInputError for a code no declaration has
        assert spec.user_set is not None   # (a user code)
        s, body = spec.user_set, bool(spec.rhs_flags & E.FLAG_TORQUE_B)   # body: its body-frame forms (torque_b)
        table[code - E.USER_CODE_BASE] = (s.c_function(spec.name), spec.n_params, spec.rhs_flags,
                                          *s.c_tile_functions(spec.name),
                                          s.c_function(spec.name, True) if body else 0,
                                          *(s.c_tile_functions(spec.name, True) if body else (0, 0, 0)),
                                          *s.c_fused_tiles(spec.name))
    return table


def _f64_rows(name: str, a, cols: int, nb: int, writable: bool = False) -> np.ndarray:
    if writable:
        if not isinstance(a, np.ndarray) or a.dtype != np.float64 or not a.flags.c_contiguous or not a.flags.writeable:
            raise TypeError(f"models.{name} must be a writable C-contiguous float64 numpy array of shape ({nb}, {cols})")
    else:
        a = np.ascontiguousarray(a, dtype=np.float64)
    if a.shape != (nb, cols):
        raise ValueError(f"models.{name} must have shape ({nb}, {cols}), got {a.shape}")
    return a


MAX_STAGES = 16  # LV_TABLEAU_MAX_STAGES (csrc/step.h)


@functools.lru_cache(maxsize=64)
def _tableau_arg(tab: Tableau) -> tuple:
    """simulate's `tableau` argument (a (s, s), b_num (s,), b_den) for a user's explicit Runge-Kutta method; ValueError
    naming `integrator` for a tableau C cannot step (its shapes, an implicit entry, a non-finite number, too many stages)."""
    A, b, c = np.asarray(tab.A, np.float64), np.asarray(tab.b, np.float64), np.asarray(tab.c, np.float64)
    s = b.shape[0] if b.ndim == 1 else -1
    if not (1 <= s <= MAX_STAGES) or A.shape != (s, s) or c.shape != (s,):
        raise ValueError(f"integrator: tableau {tab.name!r} must have b (s,), c (s,) and A (s, s) with 1 <= s <= "
                         f"{MAX_STAGES}, got b {b.shape}, c {c.shape}, A {A.shape}")
    if not (np.all(np.isfinite(A)) and np.all(np.isfinite(b))) or np.any(np.triu(A) != 0.0):
        raise ValueError(f"integrator: tableau {tab.name!r} must be explicit (A strictly lower triangular) with finite "
                         "entries")
    b_num, b_den = rk_weights(tab)
    return (np.ascontiguousarray(A), np.ascontiguousarray(b_num), float(b_den))


MAX_THREADS = 64  # LV_MAX_THREADS (csrc/step.h)
# the cause a DivergenceError names when advance(restore=False) failed (the caller restores and re-runs for the cause)
NOT_RESTORED = "non-finite state or failed solve (arrays not restored: restore=False; re-run with restore=True for the cause)"


def threads(n: int | None = None) -> int:
    """The threads that share the batched RK4 path and the jointed / wheeled bodies of one C call, process-wide.

    Parameters
    ----------
    n : int, optional
        1 .. MAX_THREADS: set it first (default 1). Plain bodies are split over the threads in tiles of 64
        (groups of at least 16 force-free plain bodies stepped with RK4); bodies with a spherical joint or
        reaction wheels (euler, semi_implicit_euler, rk4; e.g. the ReactionWheelCube-v0 vector env's cubes) in
        shares of consecutive bodies once a call has enough of them (512 body-steps per thread); other bodies
        and integrators run on the calling thread. Results are bitwise those of one thread.

    Returns
    -------
    int
        The number in use (1 where the build has no POSIX threads).

    Raises
    ------
    LavenderInputError
        n is not an integer in 1 .. MAX_THREADS.
    """
    if n is not None:
        n = V.integer("threads", n, minimum=1)
        if n > MAX_THREADS:
            raise V.LavenderInputError("threads", f"must be at most {MAX_THREADS}", f", got {n}")
        return int(_c.threads(n))
    return int(_c.threads())


def isa() -> dict:
    """The instruction set of the batched RK4 paths (plain and jointed wheel bodies): ``{"current": name, "best": name}``
    ("scalar", "sse2" or "baseline", "avx2", "avx512f"; the best this CPU supports is chosen at import)."""
    cur, name, best, best_name = _c.isa()
    return {"current": name, "best": best_name}


def call_cache(nb: int, models: bool) -> Any:
    """What a C call decides per call from the effect table (and the model rows), kept across calls for a caller
    that advances the same nb bodies call after call (Sim): pass it as ``CBackend.advance(..., cache=...)``.

    Parameters
    ----------
    nb : int
        The bodies the calls step (>= 1).
    models : bool
        The calls pass model rows (joints, wheels): their per-body entries are kept too, compared bytewise per call.

    Returns
    -------
    object or None
        An opaque handle (freed with it), or None with an extension built before it existed.
    """
    f = getattr(_c, "call_cache", None)
    return None if f is None else f(int(nb), bool(models))


def contract_available() -> bool:
    """Whether ``contract="fma"`` has its FMA copy of the torque-free RK4 SIMD tiles here (a GCC build on a CPU with
    AVX2 and FMA); without it that mode steps bitwise. An extension built before the copy existed: False."""
    f = getattr(_c, "contract_available", None)
    return bool(f()) if f is not None else False


class CBackend:
    """advance(state, params, effects, integrator, normalize, dt, n_steps, models=None) inside C;
    see the module doc and lavendersim.backends."""

    name = "c"

    def advance(self, state, params, effects, integrator: str, normalize: bool, dt: float, n_steps: int,
                models: Models | None = None, adaptive: Adaptive | None = None, *, restore: bool = True,
                contract: str = "off", cache: Any = None) -> None:
        """Advance every body by n_steps steps inside C, in place (see lavendersim.backends).

        Parameters
        ----------
        state : ndarray (nb, STATE_SIZE)
            Writable C-contiguous float64 (or float32: :meth:`_advance_f32`); mutated in place.
        params : ndarray (nb, PARAM_SIZE)
            Per-body parameters (inertia I_b in kg·m², mass in kg, ...).
        effects : ndarray (n, ROW)
            Effect table.
        integrator : str
            A key of INTEGRATOR_CODES, or a user's explicit Runge-Kutta method (``tableau_of(integrator)``, float64
            only), stepped by the generic tableau stepper (csrc/step.c advance_tableau).
        normalize : bool
            Renormalize the quaternion (x, y, z, w) after each step.
        dt : float
            Step, s.
        n_steps : int
            Steps to take.
        models : Models, optional
            Per-body joint / wheel model (Omega and applied are mutated).
        adaptive : Adaptive, optional
            Needed by dopri5 (h and nfev are mutated).
        restore : bool, optional
            True (default): on divergence every array is restored to its value at the call (a copy of the state is
            taken per call: ~10-40 ns per body at 10^6 bodies). False, for a caller that keeps its own snapshot (Sim
            restores by replay): no copy; on divergence the arrays are left as the C call left them and the error
            names the step and body only.
        contract : {"off", "fma"}, optional
            "off" (default): bitwise. "fma": the torque-free RK4 SIMD tiles run their FMA copy where it exists
            (:func:`contract_available`; results differ from "off" in the last bits); every other path is bitwise.
        cache : object, optional
            A :func:`call_cache` for these arrays, passed call after call (float64): what a call decides from the
            effect table and the model rows (the effect index, the order of the bodies) is kept in it instead of built
            per call. The same numbers with or without it; one call at a time per cache.

        Raises
        ------
        ValueError
            Unknown integrator, dopri5 without ``adaptive``, a PLAIN_ONLY integrator with a model body, or a user
            tableau C cannot step (shapes, not explicit, more than MAX_STAGES stages) or on a float32 state.
        TypeError
            ``state`` is not a writable C-contiguous float64 array.
        lavendersim.errors.DivergenceError
            A body's state became non-finite or the solve failed; every array is left unchanged.
        """
        tab = None if integrator in INTEGRATOR_CODES else tableau_of(integrator)
        if integrator not in INTEGRATOR_CODES and tab is None:
            raise ValueError(f"integrator: must be one of {', '.join(INTEGRATOR_CODES)}, got {integrator!r}")
        if isinstance(state, np.ndarray) and state.dtype == np.float32:
            if tab is not None:
                raise ValueError(f"integrator: {integrator!r} (a user-declared tableau) steps float64 only")
            return self._advance_f32(state, params, effects, integrator, normalize, dt, n_steps, models, restore)
        if integrator in ADAPTIVE and adaptive is None:
            raise ValueError(f"integrator: {integrator} needs adaptive (a lavendersim.backends.Adaptive)")
        if integrator in PLAIN_ONLY and models is not None and np.any(np.asarray(models.rows)[:, LY.MODEL_KIND] != 0):
            raise ValueError(f"integrator: {integrator} steps plain rigid bodies only (no spherical_joint or reaction_wheels)")
        if not isinstance(state, np.ndarray) or state.dtype != np.float64 or not state.flags.c_contiguous \
                or not state.flags.writeable:
            raise TypeError(f"state must be a writable C-contiguous float64 numpy array of shape (nb, {LY.STATE_SIZE})")
        params = np.ascontiguousarray(params, dtype=np.float64)
        effects = np.ascontiguousarray(effects, dtype=np.float64)
        if effects.size == 0:
            effects = effects.reshape(0, ROW)
        user = user_effect_table(effects)
        snapshot = state.copy() if restore else None
        extra: tuple[Any, ...] = ()
        if models is not None:
            nb = state.shape[0]
            rows = _f64_rows("rows", models.rows, LY.MODEL_SIZE, nb)
            Omega = _f64_rows("Omega", models.Omega, LY.XS_OMEGA_LEN, nb, writable=True)
            command = _f64_rows("command", models.command, LY.XS_OMEGA_LEN, nb)
            applied = _f64_rows("applied", models.applied, LY.XS_OMEGA_LEN, nb, writable=True)
            extra = (rows, Omega, command, applied)
            if restore:
                snap_W, snap_u = Omega.copy(), applied.copy()
        if not extra:
            extra = (None, None, None, None)
        if adaptive is not None and integrator in ADAPTIVE:
            if restore:
                saved = adaptive.save()
            extra = extra + (adaptive.h, adaptive.nfev, adaptive.rtol, adaptive.atol)
        else:
            extra = extra + (None, None, 0.0, 0.0)
        extra = extra + (user, None if tab is None else _tableau_arg(tab),
                         adaptive.dense if adaptive is not None and integrator in TABLEAUX.ADAPTIVE else None)
        tail = ((1 if contract == "fma" else 0, cache) if cache is not None
                else (1,) if contract == "fma" else ())   # (an extension before 1: no arg)
        status, step, body = _c.simulate(state, params, effects, INTEGRATOR_CODES.get(integrator, 0),
                                         1 if normalize else 0, float(dt), int(n_steps), *extra, *tail)
        if status == TABLEAUX.STATUS_OK:
            return
        if snapshot is None:   # (restore False: no copy of the state was taken)
            raise DivergenceError(step, body, NOT_RESTORED)
        tol_cause = None
        if adaptive is not None and integrator in ADAPTIVE:
            if status == TABLEAUX.STATUS_TOLERANCE:
                tol_cause = tolerance_cause(adaptive, float(adaptive.h[body]), float(dt), state[body])
            adaptive.load(saved)
        pre = state[body].copy()  # the failing body is left at its last finite state
        state[...] = snapshot
        model = None
        if models is not None:
            pre_W = Omega[body].copy()
            Omega[...] = snap_W
            applied[...] = snap_u
            if int(rows[body, LY.MODEL_KIND]):
                W0 = snap_W[body] if int(rows[body, LY.MODEL_KIND]) & KIND_WHEELS else None
                model = (rows[body], W0, None if W0 is None else pre_W, command[body])
        if tol_cause is not None:
            raise DivergenceError(step, body, tol_cause)
        if status == TABLEAUX.STATUS_NO_ROOT:  # implicit_gyro's Newton solve did not converge
            raise DivergenceError(step, body, no_root_cause(pre, params[body, LY.PARAM_I_B], float(dt)))
        raise DivergenceError(step, body, _cause(snapshot[body], pre, params, effects, body, step,
                                                 float(dt), integrator, model))

    def _advance_f32(self, state, params, effects, integrator, normalize, dt, n_steps, models, restore=True) -> None:
        """advance on a float32 state (csrc/step_f32.c): plain bodies, FLOAT32_INTEGRATORS, built-in effects;
        params and effects are used as float32 (pass them as float32 to avoid a copy per call); restore as
        :meth:`advance`'s (False: no copy of the state per call)."""
        if integrator not in FLOAT32_INTEGRATORS:
            raise ValueError(f"integrator: float32 steps {', '.join(FLOAT32_INTEGRATORS)} only, got {integrator!r}")
        if models is not None and np.any(np.asarray(models.rows)[:, LY.MODEL_KIND] != 0):
            raise ValueError("float32 steps plain rigid bodies only (no spherical_joint or reaction_wheels)")
        if not state.flags.c_contiguous or not state.flags.writeable:
            raise TypeError(f"state must be a writable C-contiguous numpy array of shape (nb, {LY.STATE_SIZE})")
        params32 = np.ascontiguousarray(params, dtype=np.float32)
        effects32 = np.ascontiguousarray(effects, dtype=np.float32)
        if effects32.size == 0:
            effects32 = effects32.reshape(0, ROW)
        snapshot = state.copy() if restore else None
        status, step, body = _c.simulate_f32(state, params32, effects32, INTEGRATOR_CODES[integrator],
                                             1 if normalize else 0, float(dt), int(n_steps))
        if status == TABLEAUX.STATUS_OK:
            return
        if snapshot is None:   # (restore False: no copy of the state was taken)
            raise DivergenceError(step, body, NOT_RESTORED)
        pre = state[body].astype(np.float64)  # the failing body is left at its last finite state
        state[...] = snapshot
        e64 = np.asarray(effects, np.float64)
        e64 = e64.reshape(0, ROW) if e64.size == 0 else e64
        raise DivergenceError(step, body, _cause(snapshot[body].astype(np.float64), pre, np.asarray(params, np.float64),
                                                 e64, body, step, float(dt), integrator))
