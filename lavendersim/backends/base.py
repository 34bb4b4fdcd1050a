"""The backends' shared definitions (registry, model arrays, tableaux, checks), imported by the package and by
the concrete backends (c_backend, numpy_backend), which never import the package itself: no import circle.
See lavendersim.backends for the contract."""
from __future__ import annotations

import numpy as np

from .. import validate as V
from ..generated import layout as LAYOUT
from ..generated import tableaux as TABLEAUX
from ..generated.layout import KIND_JOINT, KIND_WHEELS, MODEL_LAYOUT, MODEL_SIZE  # noqa: F401  (re-exported)

# The integrator registry, printed from derive/tableaux.py (nothing else lists integrators): name -> RHS
# evaluations per step (None: adaptive, counted as it runs; see rhs_per_step for how the structure-preserving
# methods are counted), the adaptive ones, and those that step plain rigid bodies only (no spherical_joint, no
# reaction_wheels: their exact sub-flows / implicit solve use the diagonal principal inertia of a free body).
INTEGRATORS = dict(TABLEAUX.RHS_PER_STEP)
ADAPTIVE = TABLEAUX.ADAPTIVE
PLAIN_ONLY = TABLEAUX.PLAIN_ONLY
BACKENDS = ("c", "numpy")
# Precisions of the state (Sim(..., dtype=)): float32 runs the single-precision printing of the same kernels
# (generated/kernels_f32.c, generated/kernels_numpy_f32.py) for these integrators on plain bodies with
# built-in effects; anything else is float64 only.
DTYPES = ("float64", "float32")
FLOAT32_INTEGRATORS = TABLEAUX.FLOAT32_INTEGRATORS


def of_family(family: str) -> tuple:
    """The registered integrators of one family, in code order.

    Parameters
    ----------
    family : str
        One of derive/tableaux.py's FAMILIES, e.g. "explicit_rk" (euler, semi_implicit_euler, rk4: the chapter's
        labs offer these).

    Returns
    -------
    tuple of str
    """
    return tuple(n for n, f in TABLEAUX.INTEGRATOR_FAMILY.items() if f == family)


class Tableau:
    """An explicit Runge–Kutta method declared by its Butcher tableau (a user's, from ``lavendersim derive --user``).

    Both backends step it with one generic explicit-RK stepper (``Sim(..., integrator=name)``), with effects,
    joints and wheels, in float64.

    Parameters
    ----------
    name : str
        What users pass to ``Sim(..., integrator=)``; must not be a built-in integrator's name.
    c : (s,) float
        The nodes; c[i] = sum(A[i, :i]).
    A : (s, s) float
        The coefficients, strictly lower triangular (explicit).
    b : (s,) float
        The weights.
    order : int
        The order the tableau's declaration claims (checked against the order conditions on registration).
    source : str
        Where it was declared (the user set's name), for messages.
    real_axis : float or None, optional
        Its stability limit on the negative real axis, |lambda| h (derive computes it from R(z); the Sim's
        decay check reads it as it reads REAL_AXIS_STABILITY for a built-in).
    wdt_max : float or None, optional
        Its validity bound |omega| dt <= wdt_max (ratio exponent 0, as rk4's; derive computes it from R(iy)).
    """

    __slots__ = ("name", "c", "A", "b", "order", "source", "real_axis", "wdt_max")

    def __init__(self, name: str, c, A, b, order: int, source: str = "", *, real_axis: float | None = None,
                 wdt_max: float | None = None):
        self.name, self.order, self.source = str(name), int(order), str(source)
        self.real_axis = None if real_axis is None else float(real_axis)
        self.wdt_max = None if wdt_max is None else float(wdt_max)
        self.c = np.ascontiguousarray(c, dtype=np.float64)
        self.A = np.ascontiguousarray(A, dtype=np.float64)
        self.b = np.ascontiguousarray(b, dtype=np.float64)
        for arr in (self.c, self.A, self.b):
            arr.setflags(write=False)

    @property
    def stages(self) -> int:
        """s, the number of stages (right-hand-side evaluations per step)."""
        return int(self.b.shape[0])

    def __repr__(self) -> str:
        return f"Tableau({self.name!r}, stages={self.stages}, order={self.order}, source={self.source!r})"


# User-declared explicit Runge-Kutta integrators by name (filled by lavendersim.extending when a user set that
# declares TABLEAUX loads). The built-in registry above never changes; these come and go with user sets.
USER_TABLEAUX: dict[str, Tableau] = {}


def tableau_of(name: str) -> Tableau | None:
    """The user-declared tableau named ``name``, or None for a built-in (or unknown) integrator.

    Parameters
    ----------
    name : str
        An integrator name.

    Returns
    -------
    Tableau or None
    """
    return USER_TABLEAUX.get(name)


def rk_weights(tab: Tableau) -> tuple[np.ndarray, float]:
    """The weights of a tableau's step as ``b_num / b_den``, the form both backends' explicit-RK stepper combine.

    When every b_i is (to the bit) a rational with denominator at most 10**6, b_den is their common denominator
    and b_num the integer numerators: then x + (dt / b_den) * sum(b_num k) is bitwise the built-in rk4 for RK4's
    tableau (its dt/6 * (k1 + 2 k2 + 2 k3 + k4)). Otherwise (b, 1.0).

    Parameters
    ----------
    tab : Tableau

    Returns
    -------
    b_num : ndarray (s,) float64
    b_den : float
        > 0.
    """
    from fractions import Fraction
    from math import lcm

    fr = [Fraction(float(b)).limit_denominator(10 ** 6) for b in tab.b]
    den = lcm(*(f.denominator for f in fr)) if fr else 1
    if den <= 10 ** 6 and all(float(f) == float(b) for f, b in zip(fr, tab.b)):
        return np.array([float(f * den) for f in fr], dtype=np.float64), float(den)
    return np.array(tab.b, dtype=np.float64), 1.0


DOPRI5_HMIN_REL = TABLEAUX.DP_HMIN_REL          # a substep below dt * this means the tolerance cannot be met
DOPRI5_MAX_SUBSTEPS = TABLEAUX.DP_MAX_SUBSTEPS  # ... as do more substeps than this within one output step


class Adaptive:
    """Adaptive-stepping arrays shared by both backends: rtol, atol; h (nb,) each body's step-size
    proposal carried between calls (0: choose one); nfev (nb,) RHS evaluations spent per body; dense
    (nb, DENSE_SIZE) each wheel-less body's dense output carried between calls (layout DENSE: the
    integrator's own state ahead of the output and its continuous extension; a row is used only while
    the body's state is the one the last call wrote, so a written state starts afresh).

    Parameters
    ----------
    rtol, atol : float
        Relative and absolute error tolerances of dopri5.
    nb : int
        Number of bodies (``h`` and ``nfev`` start as zeros of shape (nb,)).
    dense : bool, optional
        Carry each body's dense output between calls (default True). False: every call starts each
        body afresh from its state (one evaluation); within a call the output steps still take no
        substep of their own.
    """

    def __init__(self, rtol: float, atol: float, nb: int, dense: bool = True):
        self.rtol, self.atol = float(rtol), float(atol)
        self.h = np.zeros(nb)
        self.nfev = np.zeros(nb)
        self.dense = np.zeros((nb, LAYOUT.DENSE_SIZE)) if dense else None

    def save(self) -> tuple:
        """A copy of the arrays that evolve (h, nfev, dense), for load."""
        return (self.h.copy(), self.nfev.copy(), None if self.dense is None else self.dense.copy())

    def load(self, saved: tuple) -> None:
        """Put back what save returned (a 2-tuple (h, nfev) of an older pickle: the dense output starts afresh)."""
        self.h[...], self.nfev[...] = saved[0], saved[1]
        if self.dense is not None:
            if len(saved) > 2 and saved[2] is not None:
                self.dense[...] = saved[2]
            else:
                self.forget()

    def forget(self) -> None:
        """Drop the dense output (the next call starts each body afresh from its state): the forces changed."""
        if self.dense is not None:
            self.dense[:, LAYOUT.DENSE_VALID] = 0.0


def rhs_per_step(integrator: str, effects: np.ndarray, nb: int) -> int | None:
    """RHS evaluations per step of the fixed-step integrators (None for adaptive ones).

    splitting: its torque-free part (three exact axis rotations) is counted as 1; a body with effects
    evaluates them once per half kick (2 per step), twice per half kick with an effect that reads v_w
    or omega_b (4 per step; from the effects' declarations, e.g. linear or angular damping). implicit_gyro: 1 (the effects once, then a 3×3 Newton solve of the gyroscopic term to
    rounding, typically 3–6 iterations, not counted). splitting4: SPLIT4_STAGES splitting steps, each
    counted as splitting's. rk4_expmap: 4 (as rk4; the exp maps and dexp inverses are not counted).
    symtop4: counted as splitting4 (SYMTOP4_STAGES Strang steps of exact flows, kicks as splitting's).
    symtop_bm6: counted as symtop4 (torque-free, 21 axis flows and a sphere flow per step, counted as
    SYMTOP4_STAGES; with effects the same SYMTOP4_STAGES kicked stages as symtop4).
    The scene's count is the largest body's.

    Parameters
    ----------
    integrator : str
        A key of INTEGRATORS.
    effects : ndarray (n, ROW)
        The scene's effect table (its code column decides the splitting counts).
    nb : int
        Number of bodies (not used by the count).

    Returns
    -------
    int or None
        None for adaptive integrators.

    Raises
    ------
    KeyError
        ``integrator`` is not in INTEGRATORS.
    """
    tab = USER_TABLEAUX.get(integrator)
    if tab is not None:
        return tab.stages
    n = INTEGRATORS[integrator]
    if TABLEAUX.INTEGRATOR_FAMILY[integrator] != "composition" or n is None or len(effects) == 0:
        return n
    from ..effects import ROW_CODE, velocity_dependent

    per = 4 if velocity_dependent(np.unique(effects[:, ROW_CODE].astype(np.int64))) else 2
    return per * n     # n stages (splitting: 1), each kicked twice (four evaluations with a velocity-reading load)

# Per-body model row (float64), MODEL_LAYOUT / MODEL_SIZE printed from derive/layout.py: kind is a bit set,
# KIND_JOINT | KIND_WHEELS (the wheels on the row's A_b columns: one wheel model, body-axis wheels are A_b = [I | 0]).


class Models:
    """Per-body model arrays shared by both backends (see the module docstring).

    Parameters
    ----------
    rows : ndarray (nb, MODEL_SIZE)
        Per-body model rows laid out as MODEL_LAYOUT.
    Omega : ndarray (nb, WHEELS_MAX)
        Wheel rates relative to the body, rad/s (integrated in place).
    command : ndarray (nb, WHEELS_MAX)
        Motor torque commands, N·m, held over a call.
    applied : ndarray (nb, WHEELS_MAX)
        Written with the saturated motor torques of the last step, N·m.
    """

    def __init__(self, rows: np.ndarray, Omega: np.ndarray, command: np.ndarray, applied: np.ndarray):
        self.rows, self.Omega, self.command, self.applied = rows, Omega, command, applied

    @classmethod
    def empty(cls, nb: int) -> "Models":
        """All-zero arrays for nb bodies (every body of kind 0, plain).

        Parameters
        ----------
        nb : int
            Number of bodies.

        Returns
        -------
        Models
        """
        nw = LAYOUT.XS_OMEGA_LEN   # wheel rates (commands, applied torques) per body
        return cls(np.zeros((nb, MODEL_SIZE)), np.zeros((nb, nw)), np.zeros((nb, nw)), np.zeros((nb, nw)))

    @property
    def kind(self) -> np.ndarray:
        """Each body's model kind (bit set KIND_JOINT | KIND_WHEELS; 0 plain), int64 (nb,)."""
        return self.rows[:, LAYOUT.MODEL_KIND].astype(np.int64)

    @property
    def wheel_counts(self) -> np.ndarray:
        """Wheels per body, int64 (nb,) (see :func:`wheel_counts`)."""
        return wheel_counts(self.rows)

    @property
    def A_b(self) -> np.ndarray:
        """Each body's wheel axes as columns, body frame, (nb, 3, WHEELS_MAX) (a view of the rows)."""
        return self.rows[:, LAYOUT.MODEL_A_B].reshape(-1, 3, LAYOUT.WHEELS_MAX)


def wheel_counts(rows: np.ndarray) -> np.ndarray:
    """Wheels per body of model rows: 0 without wheels, else the A_b columns in use (a padded slot has a
    zero axis).

    Parameters
    ----------
    rows : ndarray (nb, MODEL_SIZE) or (MODEL_SIZE,)
        Model rows.

    Returns
    -------
    ndarray of int64, shape (nb,) (or a scalar for one row)
    """
    r = np.asarray(rows)
    kind = r[..., LAYOUT.MODEL_KIND].astype(np.int64)
    A = r[..., LAYOUT.MODEL_A_B].reshape(r.shape[:-1] + (3, LAYOUT.WHEELS_MAX))
    used = np.count_nonzero(np.any(A != 0.0, axis=-2), axis=-1)
    return np.where((kind & KIND_WHEELS) == 0, 0, used)


def on_body_axes(row: np.ndarray) -> bool:
    """Whether a model row's wheels are the default layout: three on the body x, y, z axes in that order
    (A_b = [I | 0]). Only names depend on it (x, y, z instead of 1 … N); every layout steps alike.

    Parameters
    ----------
    row : ndarray (MODEL_SIZE,)
        A model row.

    Returns
    -------
    bool
    """
    A = np.asarray(row)[LAYOUT.MODEL_A_B].reshape(3, LAYOUT.WHEELS_MAX)
    n = LAYOUT.WHEELS_BODY_AXES
    return bool(int(row[LAYOUT.MODEL_KIND]) & KIND_WHEELS) and bool(np.array_equal(A[:, :n], np.eye(3))
                                                                    and not A[:, n:].any())


def wheel_row(row: np.ndarray, J: np.ndarray, A_b: np.ndarray) -> int:
    """Write a wheel layout into one model row: J and A_b's columns in the first N slots, the rest padded
    (J = 1, zero axis: derive/wheel_layout.py proves such a wheel changes nothing).

    Parameters
    ----------
    row : ndarray (MODEL_SIZE,)
        The body's model row, written in place (J and A_b only).
    J : ndarray (N,)
        Wheel axial inertias, kg·m².
    A_b : ndarray (3, N)
        Wheel spin axes as unit columns, body frame.

    Returns
    -------
    int
        The kind bit the layout adds: KIND_WHEELS.
    """
    n = J.size
    pad_J = np.ones(LAYOUT.WHEELS_MAX)
    pad_J[:n] = J
    pad_A = np.zeros((3, LAYOUT.WHEELS_MAX))
    pad_A[:, :n] = A_b
    row[LAYOUT.MODEL_J], row[LAYOUT.MODEL_A_B] = pad_J, pad_A.reshape(-1)
    return KIND_WHEELS


def _wheel_model_args(rows: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The wheel kernels' model arguments of one model row (MODEL_SIZE,) or of n rows (n, MODEL_SIZE): I_p (..., 3, 3),
    A_b (..., 3, WHEELS_MAX) and J (..., WHEELS_MAX), views of the rows."""
    lead = rows.shape[:-1]
    return (rows[..., LAYOUT.MODEL_I_P].reshape(lead + (3, 3)),
            rows[..., LAYOUT.MODEL_A_B].reshape(lead + (3, LAYOUT.WHEELS_MAX)), rows[..., LAYOUT.MODEL_J])


def wheel_momentum(row: np.ndarray, q: np.ndarray, omega_b: np.ndarray, Omega: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """World angular momentum about the pivot of a wheeled body (wheels locked) and of its wheels' spin,
    from its model row, through the printed N-wheel kernel (wheels<WHEELS_MAX>_momentum, padded slots at rest).

    Parameters
    ----------
    row : ndarray (MODEL_SIZE,)
        The body's model row (kind with KIND_WHEELS).
    q : ndarray (4,)
        Orientation (x, y, z, w), R_WB.
    omega_b : ndarray (3,)
        Angular velocity, body frame, rad/s.
    Omega : ndarray (WHEELS_MAX,)
        Wheel rates relative to the body, rad/s.

    Returns
    -------
    L_body_w, L_wheels_w : ndarray (3,)
        kg·m²/s, world frame.
    """
    from ..kernels import K

    Lb, Lw, _ = getattr(K, f"wheels{LAYOUT.WHEELS_MAX}_momentum")(q, omega_b, Omega, *_wheel_model_args(row))
    return np.asarray(Lb), np.asarray(Lw)


def wheel_momentum_batch(rows: np.ndarray, q: np.ndarray, omega_b: np.ndarray,
                         Omega: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """:func:`wheel_momentum` of n wheeled bodies in one call of the same printed kernel (it broadcasts over
    a leading batch axis; every operation is elementwise, so row k is bitwise ``wheel_momentum(rows[k], ...)``).

    Parameters
    ----------
    rows : ndarray (n, MODEL_SIZE)
        The bodies' model rows (kind with KIND_WHEELS).
    q : ndarray (n, 4)
        Orientations (x, y, z, w), R_WB.
    omega_b : ndarray (n, 3)
        Angular velocities, body frame, rad/s.
    Omega : ndarray (n, WHEELS_MAX)
        Wheel rates relative to each body, rad/s.

    Returns
    -------
    L_body_w, L_wheels_w : ndarray (n, 3)
        kg·m²/s, world frame.
    """
    from ..kernels import K

    n = rows.shape[0]
    Lb, Lw, _ = getattr(K, f"wheels{LAYOUT.WHEELS_MAX}_momentum")(q, omega_b, Omega, *_wheel_model_args(rows))
    return (np.broadcast_to(np.asarray(Lb), (n, 3)), np.broadcast_to(np.asarray(Lw), (n, 3)))


def wheel_total_momentum_batch(rows: np.ndarray, q: np.ndarray, omega_b: np.ndarray, Omega: np.ndarray) -> np.ndarray:
    """World angular momentum about the pivot of n wheeled bodies and their wheels, L_body_w + L_wheels_w of
    :func:`wheel_momentum_batch` in one sum (the printed wheels<WHEELS_MAX>_total_momentum, elementwise: row k is
    the kernel of body k alone): the growth check's |L| of a wheeled body, as the C screen computes it.

    Parameters
    ----------
    rows : ndarray (n, MODEL_SIZE)
        The bodies' model rows (kind with KIND_WHEELS).
    q : ndarray (n, 4)
        Orientations (x, y, z, w), R_WB.
    omega_b : ndarray (n, 3)
        Angular velocities, body frame, rad/s.
    Omega : ndarray (n, WHEELS_MAX)
        Wheel rates relative to each body, rad/s.

    Returns
    -------
    ndarray (n, 3)
        kg·m²/s, world frame.
    """
    from ..kernels import K

    n = rows.shape[0]
    L = getattr(K, f"wheels{LAYOUT.WHEELS_MAX}_total_momentum")(q, omega_b, Omega, *_wheel_model_args(rows))
    return np.broadcast_to(np.asarray(L), (n, 3))


def norm_safe(v: np.ndarray) -> float:
    """Euclidean norm without overflow for huge finite components (validate.safe_norm), 0 for non-finite input.

    Parameters
    ----------
    v : ndarray
        Any shape; the norm is over all entries.

    Returns
    -------
    float
    """
    return V.safe_norm(v) if np.all(np.isfinite(v)) else 0.0


def tolerance_cause(adaptive: Adaptive, h: float, dt: float, x: np.ndarray) -> str:
    """Why dopri5 stopped: the requested tolerance could not be met.

    Parameters
    ----------
    adaptive : Adaptive
        Its rtol and atol are named.
    h : float
        The last step size proposed, s.
    dt : float
        Output step, s.
    x : ndarray (STATE_SIZE,)
        The body's state (its omega_b, rad/s, is quoted).

    Returns
    -------
    str
        A one-line message with the fix.
    """
    w = norm_safe(np.asarray(x[LAYOUT.STATE_OMEGA_B], dtype=np.float64))
    return (f"dopri5 could not meet rtol={adaptive.rtol:g}, atol={adaptive.atol:g}: the step size fell to "
            f"{h:.3g} s (below dt*{DOPRI5_HMIN_REL:g} = {dt * DOPRI5_HMIN_REL:.3g} s) or one step of dt = {dt:g} s "
            f"needed over {DOPRI5_MAX_SUBSTEPS:,} substeps (|omega| = {w:.3g} rad/s); loosen rtol/atol, check "
            "effect strengths (stiff damping), or use implicit_gyro for very fast spin")


def no_root_cause(x_before: np.ndarray, I_b: np.ndarray, dt: float) -> str:
    """Why implicit_gyro stopped: the Newton solve of the step from x_before did not converge.

    Parameters
    ----------
    x_before : ndarray (STATE_SIZE,)
        The body's state before the failing step (its omega_b, rad/s, is quoted).
    I_b : array_like (3,)
        Principal inertia, body frame, kg·m².
    dt : float
        Step, s.

    Returns
    -------
    str
        A one-line message with the fix.
    """
    w = norm_safe(np.asarray(x_before[LAYOUT.STATE_OMEGA_B], dtype=np.float64))
    I = np.asarray(I_b, dtype=np.float64)
    return (f"Newton did not converge: implicit_gyro's solve of I(omega+ - omega) + dt omega+ x I omega+ = dt tau_b "
            f"found no root within {TABLEAUX.GYRO_MAX_ITER} iterations (|omega|*dt = {w * dt:.3g}, "
            f"I_max/I_min = {float(I.max() / I.min()):.3g}); reduce dt")


def validity_bound(integrator: str) -> tuple[float, float] | None:
    """The validity bound of an integrator, as declared in derive/tableaux.py.

    Parameters
    ----------
    integrator : str
        An integrator name (``lavendersim.backends.INTEGRATORS``, or a user's tableau).

    Returns
    -------
    tuple of (float, float) or None
        ``(WDT_MAX, WDT_RATIO_EXPONENT)``: a body stays within the bound while
        ``|omega| * dt * (I_max / I_min)**p <= WDT_MAX`` (omega in rad/s, dt in s); None if the
        integrator declares no bound (the adaptive ``dopri5`` controls its own error).

    Examples
    --------
    >>> from lavendersim.sim import validity_bound
    >>> validity_bound("euler")
    (0.1, 0.0)
    """
    tab = USER_TABLEAUX.get(integrator)   # a user's explicit tableau: its bound from R(iy) (derive/user.py)
    if tab is not None:
        return (tab.wdt_max, 0.0) if tab.wdt_max is not None else None
    if integrator not in TABLEAUX.WDT_MAX:
        return None
    return float(TABLEAUX.WDT_MAX[integrator]), float(TABLEAUX.WDT_RATIO_EXPONENT.get(integrator, 0.0))


def divergence_cause(x_before: np.ndarray, dt: float, integrator: str, I_b: np.ndarray,
                     Omega_before: np.ndarray | None = None, wheels: tuple | None = None) -> str:
    """A plain guess at why one body's step went non-finite, from its state before the step
    (and, for a body with reaction wheels, its wheel rates and wheels = (J, c_w)).

    Parameters
    ----------
    x_before : ndarray (STATE_SIZE,)
        The body's state before the failing step.
    dt : float
        Step, s.
    integrator : str
        Its validity and stability bounds are looked up in the generated tableaux.
    I_b : array_like (3,)
        Principal inertia, body frame, kg·m²: the validity measure is the printed validity_wdt,
        |omega| dt (I_max/I_min)**p, as the Sim's check and the C screen compute it.
    Omega_before : ndarray (3,), optional
        Wheel rates relative to the body before the step, rad/s.
    wheels : tuple (J, c_w), optional
        Wheel axial inertias, kg·m², and wheel damping, N·m·s/rad.

    Returns
    -------
    str
        A one-line guess with the fix.
    """
    from ..kernels import K

    with np.errstate(over="ignore", invalid="ignore"):
        v = float(np.linalg.norm(x_before[LAYOUT.STATE_V_W]))
        W = None if Omega_before is None else float(np.linalg.norm(Omega_before))
    if not np.all(np.isfinite(x_before)) or (Omega_before is not None and not np.all(np.isfinite(Omega_before))):
        return "the state was already non-finite before the step"
    tab = USER_TABLEAUX.get(integrator)   # a user's tableau carries its own bounds (derive/user.py)
    if wheels is not None:
        J, c_w = np.asarray(wheels[0], dtype=np.float64), float(wheels[1])
        stiff = c_w * dt / float(np.min(J))
        wlimit = tab.real_axis if tab else TABLEAUX.REAL_AXIS_STABILITY.get(integrator)   # from its own tableau
        if wlimit is not None and stiff > wlimit:
            return (f"wheel damping c_w*dt/J = {stiff:.3g} is beyond the stability limit of {integrator} "
                    f"({wlimit:.4g}); the wheel rates Omega blew up: reduce dt or c_w")
    bound = validity_bound(integrator)
    p = 0.0 if bound is None else bound[1]
    with np.errstate(over="ignore", invalid="ignore"):
        scale = K.validity_scale(np.asarray(I_b, dtype=np.float64), dt, p)
        w, wdt = (float(a) for a in K.validity_wdt(np.asarray(x_before[LAYOUT.STATE_OMEGA_B], np.float64), scale))
    if bound is not None and wdt > bound[0]:
        what = "|omega|*dt" + (f"*(I_max/I_min)**{p:g}" if p else "")
        return f"{what} = {wdt:.3g} is beyond {integrator}'s validity bound {bound[0]:.4g} (WDT_MAX); reduce dt"
    wheel_rates = "" if W is None else f", |Omega| = {W:.3g} rad/s"
    return (f"state grew without bound (|omega| = {w:.3g} rad/s{wheel_rates}, |v| = {v:.3g} m/s, dt = {dt:g} s); "
            "check effect strengths (damping c*dt/I, wheel damping c_w*dt/J, forces) and the integrator")
