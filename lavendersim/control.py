"""LQR wheel controllers and linearization of any scene: CasADi from the derived kernels + python-control.

:func:`linearize` composes a scene's right-hand side in CasADi from ``generated/kernels_casadi.py``
— the model kernels (rigid_body_rhs, pivot_body_rhs, wheels4_body_rhs, wheels4_motor) and the CasADi
printing of every effect the scene declares, user effects included (lavendersim._linearize) — and
differentiates it at an operating point. It returns a :class:`Linearization`, a ``control.StateSpace``
with named states, inputs and outputs (``sample(dt)``: the zero-order-hold discretization);
:func:`finite_difference` checks it against the simulator's own step.

One control stack serves every scene with ``reaction_wheels`` (lavendersim.wheel_control, re-exported
here): :func:`design` — discrete LQR on the zero-order-hold discretization at the controller's period,
the computation delay and actuator lag in the model, minimum-norm allocation with optional null-space
wheel-speed biasing, the conserved momenta handled on the controllable subspace — returns a
:class:`Controller` whose step is a CasADi Function (printable); :func:`closed_loop` flies it in the
nonlinear simulator with a zero-order hold, :class:`Sensors` (star tracker, gyro noise and bias,
wheel-speed noise, seeded), actuator lag, delay and the wheels' saturation, returning a
:class:`Response` (settling time, peak torque and wheel speed, |L| drift); :func:`monte_carlo` sweeps
noise seeds and inertia uncertainty on any lavendersim.executor. :func:`chapter_cube` builds the
chapter's cube (``"center"``: ReactionWheelCube-v0, joint at the centre; ``"corner"``: Cubli-like
balancing on a corner under gravity) and lavendersim.wheel_layout.pyramid_cube the four-wheel pyramid.

Internal torques cannot change the total angular momentum, so without damping the linear model is
not fully controllable (the centre cube: rank 6 of 9; the corner: 8 of 9, gravity's torque is
horizontal). :func:`lqr` and :func:`dlqr` (python-control conventions: a StateSpace, (A, B) or A, B,
then Q, R) then design on the controllable subspace (an orthonormal Krylov basis ``T``):
``Kc, Sc, Ec = control.lqr(TᵀAT, TᵀB, TᵀQT, R)`` and ``K = Kc Tᵀ``, and report the uncontrollable
directions (``LQRResult.uncontrollable``: conserved momenta, not errors to regulate). With a full-rank
model it is plainly ``control.lqr(A, B, Q, R)``.

From Python::

    from lavendersim import control as lc
    scene = lc.chapter_cube("center")                       # or any Scene with reaction_wheels
    ctrl = lc.design(scene, period=0.002)                   # Controller: K, poles, ctrl.function (CasADi)
    r = lc.closed_loop(scene, ctrl, T=5, q0=lc.rotated(ctrl.q_ref, (1, 2, 3), 20),
                       sensors=lc.Sensors(attitude_noise=1e-4, seed=1))
    r.settling_time(), r.peak_torque, r.peak_wheel_speed, r.L_drift, r.plot("r.png")
    lin = lc.linearize(scene)                              # a python-control StateSpace
    K, S, E = lc.dlqr(lin.sample(0.01), Q, R)

From the shell: ``lavendersim lqr --spacecraft FILE`` (lavendersim.cli_lqr; ``--scenario center|corner`` and
``--layout pyramid4`` fly the chapter's cubes from the shipped spacecraft files).
"""
from __future__ import annotations

import math
import numbers
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import ArrayLike

from . import validate as V
from ._install import require
from .kernels import K as KN

if TYPE_CHECKING:  # annotations only: casadi is an optional extra, Scene/Sim load lazily
    from ._linearize import Linearization
    from .scene import Scene
    from .sim import Sim

SCENARIOS = ("center", "corner")
MOTORS = ("line", "cutoff")
BODY = "cube"


# ----------------------------------------------------------------------------------------------
# the chapter's cube, as a Scene
# ----------------------------------------------------------------------------------------------


def cube_upright_q(scenario: str = "center") -> np.ndarray:
    """The chapter cube's equilibrium orientation: identity (centre); the body diagonal (1, 1, 1) along +z
    world (corner: the COM straight above the pivot corner).

    Parameters
    ----------
    scenario : {"center", "corner"}, default "center"

    Returns
    -------
    ndarray (4,)
        Quaternion (x, y, z, w), body to world.
    """
    if V.choice("scenario", scenario, SCENARIOS) == "center":
        return np.array([0.0, 0.0, 0.0, 1.0])
    d = np.ones(3) / math.sqrt(3.0)
    return np.asarray(KN.quat_from_two_vectors(d, [0.0, 0.0, 1.0]), dtype=float)


def cube_r_b(scenario: str, size: float) -> np.ndarray:
    """Pivot → COM of the chapter cube, body frame, m: 0 (centre) or ``size/2 (1, 1, 1)`` (corner).

    Parameters
    ----------
    scenario : {"center", "corner"}
    size : float
        Side of the cube, m.

    Returns
    -------
    ndarray (3,)
    """
    return np.zeros(3) if V.choice("scenario", scenario, SCENARIOS) == "center" else np.full(3, size / 2)


def chapter_cube(scenario: str = "center", *, mass: float = 1.0, size: float = 0.15, J: ArrayLike = 5.7e-4,
                 torque_limit: float = 0.2, speed_limit: float = 400.0, damping: float = 0.0, wheel_damping: float = 0.0,
                 g: float = 9.81, motor: str = "line", q: ArrayLike | None = None, omega_b: ArrayLike = (0, 0, 0),
                 name: str = BODY) -> Scene:
    """The chapter's reaction-wheel cube as a Scene: a uniform cube on a spherical joint, three body-axis wheels.

    Body ``name`` (a box of side ``size``, mass ``mass`` with the wheels locked), a spherical joint at
    the world origin — at the cube's centre (``"center"``, ReactionWheelCube-v0) or at its body corner
    ``−size/2 (1, 1, 1)`` (``"corner"``, Cubli-like balancing under gravity ``g`` along −z world) —,
    ``reaction_wheels`` on the body axes (spin inertia ``J``, stall torque ``torque_limit``, no-load
    speed ``speed_limit``, bearing damping ``wheel_damping``, the torque–speed line or a hard cut-off),
    and ``angular_damping`` when ``damping > 0``. Defaults are Cubli-like: 15 cm, 1 kg, J = 5.7e-4 kg·m²,
    0.2 N·m, 400 rad/s.

    Parameters
    ----------
    scenario : {"center", "corner"}, default "center"
    mass, size : float
        kg, m; > 0.
    J : float or array_like (3,), default 5.7e-4
        Wheel spin inertias, kg·m², > 0 (the inertia about the pivot minus diag(J) must stay positive definite).
    torque_limit, speed_limit : float
        N·m, rad/s; > 0.
    damping, wheel_damping : float
        Cube angular damping and wheel bearing damping, N·m·s/rad; >= 0.
    g : float, default 9.81
        m/s², >= 0 (declared for the corner scenario only).
    motor : {"line", "cutoff"}, default "line"
    q : array_like (4,), optional
        Initial orientation (default :func:`cube_upright_q`).
    omega_b : array_like (3,), default (0, 0, 0)
        Initial body rate, rad/s.
    name : str, default "cube"
        The body's name.

    Returns
    -------
    Scene

    Raises
    ------
    lavendersim.validate.LavenderInputError
        A parameter out of range, naming it.
    """
    import lavendersim as lv

    scenario = V.choice("scenario", scenario, SCENARIOS)
    motor = V.choice("motor", motor, MOTORS)
    mass, size = V.positive("mass", mass), V.positive("size", size)
    Jv = np.full(3, V.scalar("J", J)) if isinstance(J, numbers.Real) else V.vector("J", J)
    if np.any(Jv <= 0):
        raise V.LavenderInputError("J", "wheel spin inertias must be positive", f", got {Jv.tolist()}")
    torque_limit, speed_limit = V.positive("torque_limit", torque_limit), V.positive("speed_limit", speed_limit)
    damping = V.scalar("damping", damping, nonnegative=True)
    wheel_damping = V.scalar("wheel_damping", wheel_damping, nonnegative=True)
    g = V.scalar("g", g, nonnegative=True)
    q0 = cube_upright_q(scenario) if q is None else V.quaternion("q", q)
    p_w = np.asarray(KN.quat_rotate(q0, cube_r_b(scenario, size)), dtype=float)
    scene = lv.Scene()
    scene.add_body(lv.Body.box(name, mass=mass, size=(size, size, size), p_w=p_w, q=q0, omega_b=omega_b))
    scene.add_effect("spherical_joint", body=name, anchor_w=[0.0, 0.0, 0.0])
    scene.add_effect("reaction_wheels", body=name, J=Jv.tolist(), torque_limit=torque_limit, speed_limit=speed_limit,
                     c_w=wheel_damping, cutoff=float(motor == "cutoff"))
    if scenario == "corner" and g > 0:
        scene.add_effect("gravity", body=name, g_w=[0.0, 0.0, -g])
    if damping > 0:
        scene.add_effect("angular_damping", body=name, c=damping)
    return scene


# ----------------------------------------------------------------------------------------------
# attitude error coordinates
# ----------------------------------------------------------------------------------------------


def attitude_error(q: ArrayLike, q_ref: ArrayLike) -> np.ndarray:
    """Attitude error dtheta = 2 vec(q_ref* ⊗ q), sign chosen so the scalar part is >= 0 (rad, body frame).

    Parameters
    ----------
    q : array_like (4,) or (..., 4)
        Orientation(s), body to world, quaternion (x, y, z, w), unit length.
    q_ref : array_like (4,) or (..., 4)
        Reference orientation(s), quaternion (x, y, z, w), unit length; broadcasts against ``q``.

    Returns
    -------
    ndarray (3,) or (..., 3)
        dtheta, rad, in the reference's body frame (the inverse of :func:`perturbed` for
        |dtheta| < 2).
    """
    qe = np.asarray(KN.quat_mul(KN.quat_conj(np.asarray(q_ref, float)), np.asarray(q, float)), dtype=float)
    sgn = np.where(qe[..., 3:4] < 0, -1.0, 1.0)
    return 2.0 * sgn * qe[..., 0:3]


def error_angle_deg(q: ArrayLike, q_ref: ArrayLike) -> np.ndarray:
    """Rotation angle between q and q_ref, degrees in [0, 180].

    Parameters
    ----------
    q : array_like (4,) or (..., 4)
        Orientation(s), body to world, quaternion (x, y, z, w), unit length.
    q_ref : array_like (4,) or (..., 4)
        Reference orientation(s), quaternion (x, y, z, w), unit length; broadcasts against ``q``.

    Returns
    -------
    float or ndarray (...,)
        The angle of the rotation q_ref* ⊗ q, deg (q and −q give the same angle).
    """
    return np.degrees(KN.quat_error_angle(np.asarray(q, float), np.asarray(q_ref, float)))


def perturbed(q_ref: ArrayLike, dtheta: ArrayLike) -> np.ndarray:
    """Orientation at attitude error dtheta: q = q_ref ⊗ [dtheta/2, sqrt(1 - |dtheta/2|²)].

    The inverse of :func:`attitude_error`.

    Parameters
    ----------
    q_ref : array_like (4,)
        Reference orientation, body to world, quaternion (x, y, z, w), unit length.
    dtheta : array_like (3,)
        Attitude error, rad, body frame; |dtheta| < 2.

    Returns
    -------
    ndarray (4,)
        q, quaternion (x, y, z, w).

    Raises
    ------
    lavendersim.validate.LavenderInputError
        If |dtheta| >= 2.
    """
    h = np.asarray(dtheta, float) / 2
    n2 = float(h @ h)
    if n2 >= 1:
        raise V.LavenderInputError("dtheta", "must satisfy |dtheta| < 2", f", got |dtheta| = {2 * math.sqrt(n2):.4g}")
    return np.asarray(KN.quat_mul(np.asarray(q_ref, float), np.concatenate([h, [math.sqrt(1 - n2)]])), dtype=float)


def rotated(q_ref: ArrayLike, axis: ArrayLike, angle_deg: float) -> np.ndarray:
    """q_ref ⊗ rotation by angle_deg about a body-frame axis (normalized).

    Parameters
    ----------
    q_ref : array_like (4,)
        Reference orientation, body to world, quaternion (x, y, z, w), unit length.
    axis : array_like (3,)
        Rotation axis, body frame of ``q_ref``; any non-zero length (normalized here).
    angle_deg : float
        Rotation angle, deg (right-handed about ``axis``).

    Returns
    -------
    ndarray (4,)
        The rotated orientation, quaternion (x, y, z, w).

    Raises
    ------
    lavendersim.validate.LavenderInputError
        If ``axis`` is not a finite 3-vector or is zero, or ``angle_deg`` is not a finite number
        (reported as ``theta0_deg``).
    """
    axis = V.vector("axis", axis)
    n = np.linalg.norm(axis)
    if n == 0:
        raise V.LavenderInputError("axis", "must be a non-zero vector")
    qa = np.asarray(KN.axis_angle_to_quat(axis / n, math.radians(V.scalar("theta0_deg", angle_deg))), dtype=float)
    return np.asarray(KN.quat_mul(np.asarray(q_ref, float), qa), dtype=float)


# ----------------------------------------------------------------------------------------------
# linearization (CasADi, from the generated kernels)
# ----------------------------------------------------------------------------------------------


def controllable_basis(A: np.ndarray, B: np.ndarray, tol: float = 1e-9, discrete: bool = False) -> np.ndarray:
    """Orthonormal basis (n, rank) of the controllable subspace span[B, AB, A²B, …].

    Krylov with re-orthogonalization; A and B scaled to unit norm, singular values below tol dropped.
    For a discrete pair the Krylov space of A − I is used (the same space, better conditioned when
    A ≈ I).

    Parameters
    ----------
    A : array_like (n, n)
        State matrix (continuous, or discrete with ``discrete=True``).
    B : array_like (n, m)
        Input matrix.
    tol : float, default 1e-9
        Rank tolerance on the singular values of the (unit-norm scaled) Krylov blocks; for B,
        relative to its largest singular value.
    discrete : bool, default False
        Whether (A, B) is a discrete-time pair (use A − I).

    Returns
    -------
    ndarray (n, rank)
        Orthonormal columns spanning the controllable subspace; (n, 0) if B is empty.
    """
    A, B = np.asarray(A, float), np.asarray(B, float)
    n = A.shape[0]
    if discrete:
        A = A - np.eye(n)
    if B.size == 0:
        return np.zeros((n, 0))
    An = A / max(np.linalg.norm(A, 2), 1e-300)
    Bn = B / max(np.linalg.norm(B, 2), 1e-300)
    U, s, _ = np.linalg.svd(Bn, full_matrices=False)
    new = U[:, s > tol * max(s.max(), 1e-300)]
    basis = new
    for _ in range(n):
        W = An @ new
        for _ in range(2):
            W = W - basis @ (basis.T @ W)
        if W.size == 0:
            break
        U, s, _ = np.linalg.svd(W, full_matrices=False)
        keep = s > tol
        if not keep.any():
            break
        new = U[:, keep]
        basis = np.hstack([basis, new])
        if basis.shape[1] >= n:
            break
    return basis


def uncontrollable(basis: np.ndarray, n: int) -> np.ndarray:
    """Orthonormal complement (n, n − rank) of an orthonormal basis (n, rank) of the controllable subspace.

    Parameters
    ----------
    basis : ndarray (n, rank)
        Orthonormal basis of the controllable subspace (from :func:`controllable_basis`).
    n : int
        State dimension.

    Returns
    -------
    ndarray (n, n − rank)
        Orthonormal basis of the uncontrollable directions; (n, 0) when rank >= n.
    """
    if basis.shape[1] >= n:
        return np.zeros((n, 0))
    P = np.eye(n) - basis @ basis.T
    Uf, _, _ = np.linalg.svd(P)
    return Uf[:, : n - basis.shape[1]]


def __getattr__(name: str) -> Any:
    """``Linearization`` (a control.StateSpace subclass) is built when python-control is first needed."""
    if name == "Linearization":
        require("control", "control", "the StateSpace linearization")
        require("casadi", "control", "the CasADi linearization")
        from ._linearize import Linearization
        return Linearization
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


def linearize(sim_or_scene: Sim | Scene, x0: dict | None = None, u0: dict | None = None, *,
              inputs: list[str] | str | None = None, outputs: list[str] | str | None = None, dt: float | None = None,
              name: str = "lavendersim") -> Any:
    """Linearize any scene at an operating point, by CasADi AD of the derived kernels.

    The right-hand side is composed from generated/kernels_casadi.py — each body's model kernel
    (rigid_body_rhs, pivot_body_rhs, the wheel kernels with the motor line) and the CasADi printing of
    every force effect the scene declares, user effects included — so it is the model the backends
    step. See lavendersim._linearize for the error coordinates (per body p, dtheta, v, omega; a
    jointed body dtheta, omega; wheels add Omega) and the input names.

    Parameters
    ----------
    sim_or_scene : Sim or Scene
        What to linearize. A Sim's current state (and held wheel commands) is the default operating
        point; a Scene's is its bodies' initial state.
    x0 : dict, optional
        ``{body: {"q": (4,), "omega_b": (3,), "Omega": (N,), "p_w": (3,), "v_w": (3,)}}`` overriding
        parts of the operating point (p_w, v_w only for free bodies).
    u0 : dict, optional
        ``{input name: value}`` overriding the operating input (default: the held wheel commands, the
        effects' declared parameter values).
    inputs : list of str, optional
        ``"BODY.u"`` (N wheel commands, N·m) or ``"EFFECT.PARAM"`` (a parameter of a force effect
        declared once on the scene). Default: every wheeled body's commands.
    outputs : list of str, optional
        State labels to output (default: every state, C = I).
    dt : float, optional
        If given, the zero-order-hold discretization at this period (s) is returned.
    name : str, default "lavendersim"
        Name of the returned system.

    Returns
    -------
    Linearization
        A ``control.StateSpace`` (n states, m inputs du = u − u0) with named states, inputs and
        outputs, the operating point, ``f0`` (the right-hand side there) and the controllable subspace.
        Every StateSpace operation of python-control applies (``control.feedback``, series, ``sample``).

    Raises
    ------
    lavendersim._install.MissingExtraError
        If python-control or CasADi (the ``control`` extra) is not installed.
    lavendersim.validate.LavenderInputError
        If an argument is invalid.
    """
    require("control", "control", "the StateSpace linearization")
    require("casadi", "control", "the CasADi linearization")
    from . import _linearize as L

    return L.linearize_scene(sim_or_scene, x0, u0, inputs=inputs, outputs=outputs, dt=dt, name=name)


# ----------------------------------------------------------------------------------------------
# LQR
# ----------------------------------------------------------------------------------------------


WEIGHT_MAX = 1e150   # |entries| of Q and R: the Riccati solution and the gain scale with them (sqrt(Q/R), sqrt(Q R))


def _weight(name: str, value, n: int, definite: bool) -> np.ndarray:
    """A weight matrix (n, n) from a scalar, a diagonal (n,) or a matrix (n, n) of real numbers, checked
    finite, its nonzero entries within [1/WEIGHT_MAX, WEIGHT_MAX] in magnitude, symmetric and positive
    semidefinite (Q) or positive definite (R).

    Complex, bool, string and object entries are refused (numpy would cast "1" or True to 1.0 and drop an
    imaginary part), naming ``name`` and the rule; nothing is rounded into a weight."""
    what = f"must be a real number, a diagonal of {n} real numbers or a {n}×{n} real matrix"
    try:
        arr = V._real_array(name, value)
    except V.LavenderInputError as exc:
        raise V.LavenderInputError(name, what, f" ({exc.rule}{exc.detail})") from None
    if arr.ndim == 0:
        arr = np.full(n, float(arr))
    if arr.ndim == 1:
        if arr.shape != (n,):
            raise V.LavenderInputError(name, f"a diagonal must have {n} entries", f", got {arr.shape[0]}")
        arr = np.diag(arr)
    if arr.shape != (n, n):
        raise V.LavenderInputError(name, f"must be {n}×{n} (or a diagonal of {n})", f", got shape {arr.shape}")
    if not np.all(np.isfinite(arr)):
        raise V.LavenderInputError(name, "must be finite (no NaN or inf)")
    mag = np.abs(arr)
    big = float(mag.max(initial=0.0))
    small = float(mag[mag > 0].min(initial=np.inf))
    if big > WEIGHT_MAX or small < 1 / WEIGHT_MAX:
        raise V.LavenderInputError(name, f"nonzero entries must be between {1 / WEIGHT_MAX:g} and {WEIGHT_MAX:g} in "
                                   "magnitude (rescale Q and R together)", f", got {big if big > WEIGHT_MAX else small:.3g}")
    if not np.allclose(arr, arr.T, rtol=1e-12, atol=1e-12 * max(1.0, big)):
        raise V.LavenderInputError(name, "must be symmetric")
    sym = arr / 2 + arr.T / 2
    ev = np.linalg.eigvalsh(sym)
    tol = 1e-12 * max(1.0, np.abs(ev).max())
    if definite and ev.min() <= tol:
        raise V.LavenderInputError(name, "must be positive definite", f", smallest eigenvalue {ev.min():.3g}")
    if not definite and ev.min() < -tol:
        raise V.LavenderInputError(name, "must be positive semidefinite", f", smallest eigenvalue {ev.min():.3g}")
    return sym


class DesignError(V.LavenderInputError):
    """The LQR design cannot stabilize the model: a mode no input reaches grows on its own (python-control
    refuses such a pair), or the solved gain leaves the closed loop unstable.

    A :class:`lavendersim.validate.LavenderInputError` (``field``, ``rule``, ``detail``) with the mode.

    Parameters
    ----------
    field, rule, detail : str
        As LavenderInputError (``field``: ``"sys"`` for lqr/dlqr, ``"scene"`` for design).
    eigenvalue : complex
        The mode's eigenvalue (continuous: 1/s; discrete: per sample).
    states : tuple of str
        The states the mode lives in (largest components of its PBH left eigenvector first).
    discrete : bool
        Whether the eigenvalue is discrete-time.
    """

    _init_fields = ("field", "rule", "detail", "eigenvalue", "states", "discrete")   # pickles with them

    def __init__(self, field: str, rule: str, detail: str = "", eigenvalue: complex = 0j, states: tuple = (),
                 discrete: bool = False) -> None:
        super().__init__(field, rule, detail)
        self.eigenvalue, self.states, self.discrete = complex(eigenvalue), tuple(states), bool(discrete)


STABILITY_RTOL = 1e-6   # a mode is unstable when it grows faster than this fraction of the model's fastest rate


def _growth(lam: np.ndarray, discrete: bool) -> np.ndarray:
    """Growth of eigenvalues past the stability boundary: |z| − 1 (discrete) or Re s (continuous)."""
    return np.abs(lam) - 1.0 if discrete else np.real(lam)


def _stability_tol(A: np.ndarray, block: np.ndarray, discrete: bool) -> float:
    """Growth below which a mode counts as marginal: STABILITY_RTOL times the fastest rate of the model
    (spectral radius of A, or of A − I discrete: unit-free), plus the rounding split of a double
    integrator's eigenvalues (10 sqrt(eps ‖A‖ ‖block‖): free positions and unactuated axes sit there)."""
    n = A.shape[0]
    fast = float(np.max(np.abs(np.linalg.eigvals(A - np.eye(n) if discrete else A)), initial=0.0))
    eps = np.finfo(float).eps
    return STABILITY_RTOL * fast + 10.0 * math.sqrt(eps * np.linalg.norm(A, 2) * max(np.linalg.norm(block, 2), eps))


def _mode_states(w: np.ndarray, labels: list[str]) -> tuple[str, ...]:
    """The states a mode lives in: components of its left eigenvector at least a tenth of the largest, largest first."""
    a = np.abs(w)
    order = np.argsort(-a, kind="stable")
    return tuple(labels[i] for i in order if a[i] >= 0.1 * a.max())


def unstable_uncontrollable_modes(A: ArrayLike, B: ArrayLike, *, discrete: bool = False, basis: np.ndarray | None = None,
                                  labels: list[str] | None = None) -> list[tuple[complex, tuple[str, ...]]]:
    """The PBH stabilizability test: the modes no input reaches that grow on their own.

    With T an orthonormal basis of the controllable subspace (:func:`controllable_basis`) and U its
    complement, the uncontrollable dynamics are ``Uᵀ A U`` (the subspace is A-invariant); a left eigenvector
    y of it gives ``w = U y`` with ``wᵀ A = λ wᵀ`` and ``wᵀ B = 0`` (rank [A − λI, B] < n): the coordinate
    ``w·x`` evolves as ``e^{λt}`` (or ``λ^k``) whatever the input. A mode is unstable when its growth
    (``Re λ``, or ``|λ| − 1`` discrete) exceeds ``STABILITY_RTOL`` (1e-6) times the model's fastest rate plus
    the rounding split of a double integrator: the marginal modes of internal torques (conserved momenta,
    a free body's position, an unactuated axis's attitude) pass.

    Parameters
    ----------
    A : array_like (n, n)
        State matrix (continuous, or discrete with ``discrete=True``).
    B : array_like (n, m)
        Input matrix.
    discrete : bool, default False
    basis : ndarray (n, rank), optional
        The controllable subspace (default :func:`controllable_basis`).
    labels : list of str, optional
        State names (default ``x[0]``, ``x[1]``, ...).

    Returns
    -------
    list of (complex, tuple of str)
        Each unstable uncontrollable mode (one of a complex pair): its eigenvalue and the states it
        lives in (largest components of w first); empty when (A, B) is stabilizable.
    """
    from scipy.linalg import eig

    A, B = np.asarray(A, float), np.asarray(B, float)
    n = A.shape[0]
    T = controllable_basis(A, B, discrete=discrete) if basis is None else basis
    U = uncontrollable(T, n)
    if U.shape[1] == 0:
        return []
    labels = [f"x[{i}]" for i in range(n)] if labels is None else list(labels)
    Auu = U.T @ A @ U
    lam, W = eig(Auu, left=True, right=False)
    tol = _stability_tol(A, Auu, discrete)
    g = _growth(lam, discrete)
    out = []
    for i in np.argsort(-g, kind="stable"):
        z = complex(lam[i])
        if g[i] > tol and (z.imag >= 0 or _is_real(z)):     # one of a complex pair; every real root
            out.append((complex(z.real) if _is_real(z) else z, _mode_states(U @ W[:, i], labels)))
    return out


def _refuse_unstable(A: np.ndarray, B: np.ndarray, T: np.ndarray, discrete: bool, labels: list[str] | None,
                     field: str, period: float | None) -> None:
    """Raise DesignError naming the fastest unstable uncontrollable mode of (A, B), if any."""
    modes = unstable_uncontrollable_modes(A, B, discrete=discrete, basis=T, labels=labels)
    if not modes:
        return
    lam, states = modes[0]
    rate = ""
    if discrete and period is not None:
        rate = f" (a continuous rate of {math.log(abs(lam)) / period:+.4g}/s at the period {period:g} s)"
    more = f"; {len(modes) - 1} more unstable uncontrollable mode(s)" if len(modes) > 1 else ""
    raise DesignError(field, "has an unstable mode no input reaches (not stabilizable: no gain can hold it)",
                      f": eigenvalue {_eig_text(lam)}{rate} in {', '.join(states)}{more}", lam, states, discrete)


def _is_real(lam: complex) -> bool:
    """An eigenvalue whose imaginary part is rounding (a real double root splits into a ±1e-16j pair)."""
    return abs(lam.imag) <= 1e-12 * max(1.0, abs(lam))


def _eig_text(lam: complex) -> str:
    return f"{lam.real:+.6g}" if _is_real(lam) else f"{lam.real:+.6g}{lam.imag:+.6g}j"


def _check_closed_loop(A: np.ndarray, B: np.ndarray, K: np.ndarray, T: np.ndarray, discrete: bool,
                       labels: list[str] | None, field: str) -> None:
    """Raise DesignError if the solved gain leaves a controllable closed-loop mode unstable (a solver failure)."""
    if T.shape[1] == 0:
        return
    Acl = T.T @ (A - B @ K) @ T
    lam, W = np.linalg.eig(Acl)
    g = _growth(lam, discrete)
    i = int(np.argmax(g))
    if g[i] > _stability_tol(A, Acl, discrete):
        w = T @ W[:, i]
        states = _mode_states(w, [f"x[{j}]" for j in range(A.shape[0])] if labels is None else list(labels))
        raise DesignError(field, "the solved LQR gain leaves the closed loop unstable (check Q against the plant)",
                          f": closed-loop eigenvalue {_eig_text(complex(lam[i]))} in {', '.join(states)}",
                          complex(lam[i]), states, discrete)


class LQRResult(tuple):
    """(K, S, E) as python-control's lqr/dlqr return them (unpacks as a 3-tuple), plus how the design
    was made: ``rank`` of the controllable subspace, ``controllable``, and ``uncontrollable`` — an
    orthonormal basis (n, n − rank) of the directions no input can change (their closed-loop
    eigenvalues stay at 0, continuous, or 1, discrete: conserved momenta, not errors to regulate)."""

    K: np.ndarray
    S: np.ndarray
    E: np.ndarray
    rank: int
    uncontrollable: np.ndarray

    def __new__(cls, K: np.ndarray, S: np.ndarray, E: np.ndarray, rank: int, unc: np.ndarray) -> "LQRResult":
        obj = super().__new__(cls, (K, S, E))
        obj.K, obj.S, obj.E, obj.rank, obj.uncontrollable = K, S, E, rank, unc
        return obj

    @property
    def controllable(self) -> bool:
        """Whether the design covered the whole state (rank == n)."""
        return self.uncontrollable.shape[1] == 0


def _pair(sys_or_A: Any, args: tuple, fn: str, discrete: bool) -> tuple[np.ndarray, np.ndarray, np.ndarray, tuple]:
    """(A, B, basis, rest of args) from a StateSpace, an (A, B) pair, or A, B positional (python-control style)."""
    ct = require("control", "control", "LQR design (python-control)")
    basis = None
    if isinstance(sys_or_A, ct.StateSpace):
        if discrete != sys_or_A.isdtime(strict=True):
            raise V.LavenderInputError("sys", f"{fn} needs a {'discrete' if discrete else 'continuous'} StateSpace"
                                       + (" (sample it: lin.sample(dt) or ct.c2d(sys, dt))" if discrete else " (use dlqr)"),
                                       f", got dt = {sys_or_A.dt}")
        A, B = sys_or_A.A, sys_or_A.B
        basis = getattr(sys_or_A, "basis", None)
    elif isinstance(sys_or_A, tuple) and len(sys_or_A) == 2:
        A, B = sys_or_A
    elif len(args) >= 3:
        A, B, args = sys_or_A, args[0], args[1:]
    else:
        raise V.LavenderInputError("sys", f"{fn} takes a control.StateSpace, an (A, B) pair, or A, B, Q, R",
                                   f", got {type(sys_or_A).__name__}")
    try:
        A, B = np.asarray(A, dtype=float), np.asarray(B, dtype=float)
    except (TypeError, ValueError):
        raise V.LavenderInputError("A", "A and B must be numeric matrices") from None
    if B.ndim == 1:
        B = B[:, None]
    n = A.shape[0] if A.ndim == 2 else -1
    if A.ndim != 2 or A.shape != (n, n) or B.ndim != 2 or B.shape[0] != n:
        raise V.LavenderInputError("A", "A must be n×n and B n×m", f", got {A.shape} and {B.shape}")
    if not (np.all(np.isfinite(A)) and np.all(np.isfinite(B))):
        raise V.LavenderInputError("A", "A and B must be finite")
    if len(args) != 2:
        raise V.LavenderInputError("Q", f"{fn} needs Q and R", f", got {len(args)} weight argument(s)")
    if basis is None:
        basis = controllable_basis(A, B, discrete=discrete)
    return A, B, basis, args


def _design(sys_or_A: Any, args: tuple, discrete: bool, *, labels: list[str] | None = None, field: str = "sys",
            period: float | None = None) -> LQRResult:
    ct = require("control", "control", "LQR design (python-control)")
    fn = "dlqr" if discrete else "lqr"
    A, B, T, (Q, R) = _pair(sys_or_A, args, fn, discrete)
    n, m = B.shape
    Q = _weight("Q", Q, n, definite=False)
    R = _weight("R", R, m, definite=True)
    if labels is None and isinstance(sys_or_A, ct.StateSpace):
        labels = list(sys_or_A.state_labels)
    _refuse_unstable(A, B, T, discrete, labels, field, period if period is not None else (
        float(sys_or_A.dt) if discrete and isinstance(sys_or_A, ct.StateSpace) and sys_or_A.dt is not True else None))
    solve = ct.dlqr if discrete else ct.lqr
    if T.shape[1] == n:
        K, S, _ = solve(A, B, Q, R)
    else:
        if T.shape[1] == 0:
            raise V.LavenderInputError("B", "no input reaches any state (the controllable subspace is empty)")
        Qc = T.T @ Q @ T
        Kc, Sc, _ = solve(T.T @ A @ T, T.T @ B, (Qc + Qc.T) / 2, R)
        K, S = np.asarray(Kc) @ T.T, T @ np.asarray(Sc) @ T.T
    K, S = np.asarray(K), np.asarray(S)
    _check_closed_loop(A, B, K, T, discrete, labels, field)
    E = np.linalg.eigvals(A - B @ K)
    E = E[np.argsort(np.abs(E) if discrete else E.real)]
    return LQRResult(K, S, E, T.shape[1], uncontrollable(T, n))


def lqr(sys: Any, *args: Any) -> LQRResult:
    """Continuous LQR, python-control conventions: ``lqr(sys, Q, R)`` with a ``control.StateSpace``
    (a :class:`Linearization` or any continuous one), ``lqr((A, B), Q, R)`` or ``lqr(A, B, Q, R)``.

    When (A, B) is not controllable (internal wheel torques conserve momentum) the design is made on
    the controllable subspace (orthonormal Krylov basis T): ``Kc, Sc = control.lqr(TᵀAT, TᵀB, TᵀQT,
    R)``, ``K = Kc Tᵀ``, ``S = T Sc Tᵀ``; otherwise it is exactly ``control.lqr(A, B, Q, R)``.

    Parameters
    ----------
    sys : control.StateSpace, (A, B) or A
        The model (n states, m inputs).
    *args
        Q (n×n, a diagonal (n,) or a scalar; symmetric PSD) and R (m×m, (m,) or scalar; PD), after
        B when A and B are given separately.

    Returns
    -------
    LQRResult
        Unpacks as (K (m, n), S (n, n), E (n,) closed-loop eigenvalues of A − B K, sorted by real
        part); ``.rank`` and ``.uncontrollable`` report the directions the design cannot move.

    Raises
    ------
    DesignError
        A mode no input reaches grows on its own (:func:`unstable_uncontrollable_modes`: python-control
        refuses such a pair), naming its eigenvalue and states; or the solved gain leaves the closed loop
        unstable. Marginal uncontrollable modes (conserved momenta at 0) are designed around.
    lavendersim.validate.LavenderInputError
        As :func:`dlqr`.
    """
    return _design(sys, args, discrete=False)


def dlqr(sys: Any, *args: Any) -> LQRResult:
    """Discrete LQR (python-control's dlqr), with the same forms and subspace design as :func:`lqr`.

    ``dlqr(lin.sample(Ts), Q, R)``, ``dlqr((Ad, Bd), Q, R)`` or ``dlqr(Ad, Bd, Q, R)``. The gain is
    for u[k] = u0 − K x[k] held over the period (zero-order hold). E are the eigenvalues of Ad − Bd K,
    sorted by modulus (conserved directions at 1).

    Parameters
    ----------
    sys : control.StateSpace, (Ad, Bd) or Ad
        The discrete-time model (n states, m inputs), e.g. ``lin.sample(Ts)``; a StateSpace must be
        discrete (dt > 0).
    *args
        Q (n×n, a diagonal (n,) or a scalar; symmetric PSD) and R (m×m, (m,) or scalar; PD), after
        Bd when Ad and Bd are given separately.

    Returns
    -------
    LQRResult
        Unpacks as (K (m, n), S (n, n), E (n,) closed-loop eigenvalues of Ad − Bd K, sorted by
        modulus); ``.rank`` and ``.uncontrollable`` report the directions the design cannot move.

    Raises
    ------
    lavendersim._install.MissingExtraError
        If python-control (the ``control`` extra) is not installed.
    lavendersim.validate.LavenderInputError
        If the system is continuous or not a recognized form, A, B are not finite n×n, n×m matrices,
        Q and R are missing or not valid weights (real finite numbers; Q symmetric PSD, R symmetric PD), or
        no input reaches any state.
    DesignError
        A mode no input reaches grows on its own (|z| > 1), naming its eigenvalue and states, or the solved
        gain leaves the closed loop unstable. Marginal uncontrollable modes (conserved momenta at 1) pass.
    """
    return _design(sys, args, discrete=True)


# ----------------------------------------------------------------------------------------------
# checking the linearization against the runtime simulator
# ----------------------------------------------------------------------------------------------


def finite_difference(lin: Any, scene: Scene, *, backend: str = "auto", h: float = 1e-5, dt: float = 1e-4,
                      extrapolate: bool = True) -> tuple[np.ndarray, np.ndarray]:
    """A and B of any scene by central finite differences of the simulator's own step.

    For each perturbation ±h of one error coordinate (or input) a Sim is built from `scene` (an
    effect-parameter input perturbs that effect's declared value), put at the operating point plus
    the perturbation (``lin.set_state``), stepped once with integrator="euler" and read back in error
    coordinates (``lin.state_of``): Φ(x, u) = x + dt f(x, u) + O(dt²), so
    A e_j ≈ ((Φ(+h e_j) − Φ(−h e_j)) / (2h) − e_j) / dt and B e_j ≈ (Φ(+h e_j) − Φ(−h e_j)) / (2h dt).
    Errors: O(h²) from the differences, O(dt) away from an equilibrium (the chart's curvature; with
    ``extrapolate`` (default) Richardson's 2 D(dt/2) − D(dt) removes it, leaving O(dt²)), and float
    rounding ~ eps / (h dt).

    Parameters
    ----------
    lin : Linearization
        From :func:`linearize` of the same scene (continuous).
    scene : Scene
        The scene that was linearized.
    backend : str, default "auto"
        Simulator backend: ``"auto"``, ``"c"`` or ``"numpy"``.
    h : float, default 1e-5
        Perturbation of each error coordinate and input, in their units; > 0.
    dt : float, default 1e-4
        The Euler step, s; > 0.
    extrapolate : bool, default True
        Richardson-extrapolate from steps dt and dt/2 (removes the O(dt) error).

    Returns
    -------
    (A_fd (n, n), B_fd (n, m))

    Raises
    ------
    lavendersim.validate.LavenderInputError
        If ``h`` or ``dt`` is not a positive finite number.
    """
    import lavendersim as lv

    from . import effects as E

    h, dt = V.positive("h", h), V.dt("dt", dt)
    if extrapolate:
        A1, B1 = finite_difference(lin, scene, backend=backend, h=h, dt=dt, extrapolate=False)
        A2, B2 = finite_difference(lin, scene, backend=backend, h=h, dt=dt / 2, extrapolate=False)
        return 2 * A2 - A1, 2 * B2 - B1
    n, m = lin.nstates, lin.ninputs

    def scene_with(du):
        if not any(r.kind == "effect" for r in lin.input_refs):
            return scene
        new = lv.Scene()
        for b in scene.bodies.values():
            new.add_body(b)
        for k, e in enumerate(scene.effects):
            vals = dict(e.values)
            for r in lin.input_refs:
                if r.kind == "effect" and r.effect_index == k:
                    v = lin.u0[r.offset:r.offset + r.size] + du[r.offset:r.offset + r.size]
                    vals[r.param] = float(v[0]) if np.ndim(e.values[r.param]) == 0 else v
            new.add_effect(E.make(e.name, body=e.body, **vals))
        return new

    def phi(x, du):
        sim = lv.Sim(scene_with(du), dt=dt, integrator="euler", backend=backend, max_growth=None)
        for r in lin.input_refs:
            if r.kind == "wheels":
                sim.set_wheel_command(r.body, lin.u0[r.offset:r.offset + r.size] + du[r.offset:r.offset + r.size])
        for ref in lin.bodies:
            if ref.wheels and not any(r.kind == "wheels" and r.body == ref.name for r in lin.input_refs):
                sim.set_wheel_command(ref.name, ref.command)
        lin.set_state(sim, x)
        sim.step()
        return lin.state_of(sim)

    A, B = np.empty((n, n)), np.empty((n, m))
    for j in range(n):
        e = np.zeros(n)
        e[j] = h
        A[:, j] = ((phi(e, np.zeros(m)) - phi(-e, np.zeros(m))) / (2 * h) - e / h) / dt
    for j in range(m):
        e = np.zeros(m)
        e[j] = h
        B[:, j] = (phi(np.zeros(n), e) - phi(np.zeros(n), -e)) / (2 * h) / dt
    return A, B


def linearization_residual(lin: Linearization, A_fd: ArrayLike, B_fd: ArrayLike) -> dict[str, float]:
    """Compare a linearization with finite-difference matrices.

    max |A − A_fd|, max |B − B_fd| (absolute) and the same relative to max(1, max |entry|) (of
    lin's A and B).

    Parameters
    ----------
    lin : Linearization
        The linearization (its A (n, n) and B (n, m)).
    A_fd : array_like (n, n)
        State matrix to compare, e.g. from :func:`finite_difference`.
    B_fd : array_like (n, m)
        Input matrix to compare.

    Returns
    -------
    dict
        ``A_abs``, ``B_abs``, ``A_rel``, ``B_rel`` (float).
    """
    ea, eb = float(np.max(np.abs(lin.A - A_fd))), float(np.max(np.abs(lin.B - B_fd)))
    return {"A_abs": ea, "B_abs": eb, "A_rel": ea / max(1.0, float(np.max(np.abs(lin.A)))),
            "B_rel": eb / max(1.0, float(np.max(np.abs(lin.B))))}


DEFAULT_AXIS = (1.0, 2.0, 3.0)
CORNER_AXIS = (1.0, 1.0, -2.0)  # perpendicular to the chapter cube's body diagonal: a pure tilt

from .wheel_control import (Controller, Response, Sensors, SweepError, Wheels, allocation, closed_loop,  # noqa: E402
                            default_weights, design, momentum_exchange, monte_carlo, perturbed_inertia, wheeled_body)
