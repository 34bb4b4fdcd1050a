"""LQR wheel controllers and linearization of any scene: CasADi from the derived kernels + python-control.

:func:`linearize` composes a scene's right-hand side in CasADi from ``generated/kernels_casadi.py``
— the model kernels (rigid_body_rhs, pivot_body_rhs, wheel_body_rhs, wheel_motor) and the CasADi
printing of every effect the scene declares, user effects included (lavendersim._linearize) — and
differentiates it at an operating point. It returns a :class:`Linearization`, a ``control.StateSpace``
with named states, inputs and outputs (``sample(dt)``: the zero-order-hold discretization);
:func:`finite_difference` checks it against the simulator's own step.

The reaction-wheel cube (:class:`CubeModel`) is one such scene. State (error coordinates, 9):
``x = [dtheta (3), omega_b (3), Omega - Omega_0 (3)]`` where the attitude error ``dtheta`` (rad,
body frame) is defined by ``q = q_ref ⊗ [dtheta/2, sqrt(1 - |dtheta/2|²)]``; ``omega_b`` rad/s;
``Omega`` wheel rates relative to the body, rad/s. Input ``u`` (3): motor torques on the wheels, N·m
(the cube receives −u), relative to the equilibrium torque ``u_0 = c_w Omega_0``. The motor's
torque–speed line limits the drive torque to ``torque_limit (1 − |Ω|/speed_limit)`` (``motor="line"``,
default) or cuts it off at ``speed_limit`` (``motor="cutoff"``).

Scenarios (:class:`CubeModel`):
  * ``"center"`` — ReactionWheelCube-v0: spherical joint at the cube's centre (no gravity
    torque), equilibrium at ``q_ref`` (default identity).
  * ``"corner"`` — Cubli-like balancing on one corner under gravity: the joint is at the body
    corner ``-s/2 (1, 1, 1)``; the equilibrium has the body diagonal vertical, COM above the corner.

Internal torques cannot change the total angular momentum, so without damping the linear model is
not fully controllable: the centre scenario has rank 6 of 9 (all three momentum components are
conserved) and the corner scenario rank 8 of 9 (gravity's torque is horizontal; the vertical
momentum is conserved). :func:`lqr` and :func:`dlqr` (python-control conventions: a StateSpace,
(A, B) or A, B, then Q, R) then design on the controllable subspace (an orthonormal Krylov basis
``T``): ``Kc, Sc, Ec = control.lqr(TᵀAT, TᵀB, TᵀQT, R)`` and ``K = Kc Tᵀ``, and report the
uncontrollable directions (``LQRResult.uncontrollable``: those conserved momenta, constants of the
motion, not errors to regulate). With a full-rank model it is plainly ``control.lqr(A, B, Q, R)``.
:func:`closed_loop` runs a gain or any controller ``u = f(t, x)`` in the nonlinear simulator and
returns a :class:`Response` (t, states, inputs, outputs as python-control names them; ``plot()``);
:func:`monte_carlo` re-runs it on perturbed plants on any lavendersim.executor.

From Python::

    from lavendersim import control as lc
    res = lc.design(scenario="center", Q=[...9...], R=[...3...], theta0_deg=20, axis=[1, 2, 3])
    res.K, res.poles, res.settling_time, res.peak_torque, res.peak_wheel_speed, res.plot("r.png")
    lin = lc.linearize(sim, inputs=["applied_torque.torque_w"])      # any scene or Sim
    K, S, E = lc.dlqr(lin.sample(0.01), Q, R)

From the shell: ``lavendersim lqr --scenario corner --theta0 3 --json`` (``--monte-carlo N --seed S
--workers W`` or ``--dask ADDRESS`` for the robustness runs). ``--layout pyramid4``: four wheels on a
pyramid (lavendersim.wheel_layout) — a 30° slew with null-space wheel-speed management and the
momentum check.
"""
from __future__ import annotations

import json
import math
import numbers
from collections.abc import Callable
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import ArrayLike

from . import validate as V
from ._install import require
from .kernels import K as KN

if TYPE_CHECKING:  # annotations only: casadi is an optional extra, Scene/Sim load lazily
    import argparse
    import os

    from ._linearize import Linearization
    from .scene import Scene
    from .sim import Sim

SCENARIOS = ("center", "corner")
LAYOUT_CHOICES = ("cube3", "pyramid4")
MOTORS = ("line", "cutoff")
STATE_LABELS = ("dtheta_x", "dtheta_y", "dtheta_z", "omega_x", "omega_y", "omega_z", "Omega_x", "Omega_y", "Omega_z")
INPUT_LABELS = ("u_x", "u_y", "u_z")
BODY = "cube"


# ----------------------------------------------------------------------------------------------
# model
# ----------------------------------------------------------------------------------------------


@dataclass
class CubeModel:
    """The reaction-wheel cube: a uniform cube on a spherical joint with three body-axis wheels.

    A cube of side ``size`` (m) and total mass ``mass`` (kg, wheels included and locked),
    uniform, with three body-axis reaction wheels of spin inertia ``J`` (kg·m²), motor torque
    limit ``torque_limit`` (N·m), wheel speed limit ``speed_limit`` (rad/s), cube angular damping
    ``damping`` (N·m·s/rad, the "angular_damping" effect), wheel bearing damping ``wheel_damping``
    (N·m·s/rad, the motor's viscous friction), gravity ``g`` (m/s², along −z world). ``motor``:
    "line" (default) — the torque a wheel can apply to speed itself up falls linearly from the stall
    torque ``torque_limit`` at rest to 0 at the no-load speed ``speed_limit`` (wheel_motor kernel);
    "cutoff" — full torque below ``speed_limit``, none beyond (the old hard cut-off). Defaults are Cubli-like (15 cm, 1 kg;
    Cubli: 1.42 kg, wheel inertia 0.57e-3 kg·m², Maxon EC45-flat motors): J = 5.7e-4 kg·m² per
    wheel, 0.2 N·m, 400 rad/s (3800 rpm).

    Parameters
    ----------
    scenario : {"center", "corner"}, default "center"
        ``"center"``: the joint at the cube's centre (no gravity torque); ``"corner"``: the joint at
        the body corner ``-size/2 (1, 1, 1)``, balancing under gravity (see the module docstring).
    mass : float, default 1.0
        Total mass, kg, wheels included; > 0.
    size : float, default 0.15
        Side of the cube, m; > 0.
    J : float or array_like (3,), default (5.7e-4, 5.7e-4, 5.7e-4)
        Spin inertia of each wheel about its body axis (x, y, z), kg·m²; a scalar gives all three.
        Each > 0, and ``I_p − diag(J)`` must be positive definite. Stored as an ndarray (3,).
    torque_limit : float, default 0.2
        Motor torque limit (stall torque), N·m; > 0.
    speed_limit : float, default 400.0
        Wheel speed limit (no-load speed), rad/s, relative to the body; > 0.
    damping : float, default 0.0
        Cube angular damping coefficient, N·m·s/rad; >= 0 (0: no "angular_damping" effect).
    wheel_damping : float, default 0.0
        Wheel bearing (viscous) damping ``c_w``, N·m·s/rad; >= 0.
    g : float, default 9.81
        Gravitational acceleration, m/s², along −z world; >= 0 (used by the corner scenario only).
    motor : {"line", "cutoff"}, default "line"
        The motor's torque–speed model (see above).

    Raises
    ------
    lavendersim.validate.LavenderInputError
        If a parameter is out of range (unknown scenario or motor, a non-positive mass, size, J,
        torque_limit or speed_limit, a negative damping, wheel_damping or g, a non-finite value) or
        if ``I_p − diag(J)`` is not positive definite.
    """

    scenario: str = "center"
    mass: float = 1.0
    size: float = 0.15
    J: ArrayLike = (5.7e-4, 5.7e-4, 5.7e-4)
    torque_limit: float = 0.2
    speed_limit: float = 400.0
    damping: float = 0.0
    wheel_damping: float = 0.0
    g: float = 9.81
    motor: str = "line"

    def __post_init__(self):
        self.motor = V.choice("motor", self.motor, MOTORS)
        self.scenario = V.choice("scenario", self.scenario, SCENARIOS)
        self.mass = V.positive("mass", self.mass)
        self.size = V.positive("size", self.size)
        J = np.full(3, V.scalar("J", self.J)) if isinstance(self.J, (numbers.Real, np.ndarray)) and np.ndim(self.J) == 0 \
            else V.vector("J", self.J)
        if np.any(J <= 0):
            raise V.LavenderInputError("J", "wheel spin inertias must be positive", f", got {J.tolist()}")
        self.J = J
        self.torque_limit = V.positive("torque_limit", self.torque_limit)
        self.speed_limit = V.positive("speed_limit", self.speed_limit)
        self.damping = V.scalar("damping", self.damping, nonnegative=True)
        self.wheel_damping = V.scalar("wheel_damping", self.wheel_damping, nonnegative=True)
        self.g = V.scalar("g", self.g, nonnegative=True)
        ev = np.linalg.eigvalsh(self.I_p - np.diag(self.J))
        if ev.min() <= 0:
            raise V.LavenderInputError("J", "I_p − J must be positive definite (the wheels cannot carry more inertia "
                                       "than the cube about the pivot)", f", got J = {self.J.tolist()}, I_p = {np.diag(self.I_p).tolist()}")

    # geometry -----------------------------------------------------------------------------
    @property
    def I_c(self) -> np.ndarray:
        """Principal inertia about the COM, kg·m² (inertia_box kernel)."""
        s = self.size
        return np.asarray(KN.inertia_box(self.mass, s, s, s), dtype=float)

    @property
    def r_b(self) -> np.ndarray:
        """Pivot → COM, body frame, m."""
        return np.zeros(3) if self.scenario == "center" else np.full(3, self.size / 2)

    @property
    def I_p(self) -> np.ndarray:
        """Inertia about the pivot, body frame (parallel_axis kernel), kg·m²."""
        return np.asarray(KN.parallel_axis(np.diag(self.I_c), self.mass, -self.r_b), dtype=float).reshape(3, 3)

    @property
    def g_w(self) -> np.ndarray:
        """Gravity vector, world frame, m/s²: ``(0, 0, −g)``, ndarray (3,)."""
        return np.array([0.0, 0.0, -self.g])

    @property
    def gravity(self) -> bool:
        """Gravity is declared for the corner scenario (at the centre it has no torque)."""
        return self.scenario == "corner" and self.g > 0

    def upright_q(self) -> np.ndarray:
        """Equilibrium orientation: identity (centre); body diagonal (1,1,1) along +z world (corner)."""
        if self.scenario == "center":
            return np.array([0.0, 0.0, 0.0, 1.0])
        d = np.ones(3) / math.sqrt(3.0)
        return np.asarray(KN.quat_from_two_vectors(d, [0.0, 0.0, 1.0]), dtype=float)

    # runtime scene ------------------------------------------------------------------------
    def scene(self, q0: ArrayLike | None = None, omega_b: ArrayLike = (0, 0, 0), Omega: ArrayLike | None = None) -> Scene:
        """Build the Scene for the runtime simulator.

        The scene has body "cube" (COM placed at anchor + R r_b), a spherical joint at the origin,
        reaction wheels, and the declared damping/gravity.

        Parameters
        ----------
        q0 : array_like (4,), optional
            Initial orientation of the cube, body to world, quaternion (x, y, z, w); normalized.
            Default: :meth:`upright_q`.
        omega_b : array_like (3,), default (0, 0, 0)
            Initial angular velocity of the cube, body frame, rad/s.
        Omega : array_like (3,), optional
            Not used: the Scene carries no wheel rates (they start at 0). Set them on the Sim, as
            :meth:`make_sim` does.

        Returns
        -------
        Scene
            A new :class:`lavendersim.scene.Scene`.

        Raises
        ------
        lavendersim.validate.LavenderInputError
            If ``q0`` is not a valid quaternion, or ``omega_b`` is invalid.
        """
        import lavendersim as lv

        q0 = self.upright_q() if q0 is None else V.quaternion("q0", q0)
        p_w = np.asarray(KN.quat_rotate(q0, self.r_b), dtype=float)
        s = self.size
        scene = lv.Scene()
        scene.add_body(lv.Body.box(BODY, mass=self.mass, size=(s, s, s), p_w=p_w, q=q0, omega_b=omega_b))
        scene.add_effect("spherical_joint", body=BODY, anchor_w=[0.0, 0.0, 0.0])
        scene.add_effect("reaction_wheels", body=BODY, J=self.J.tolist(), torque_limit=self.torque_limit,
                         speed_limit=self.speed_limit, c_w=self.wheel_damping, cutoff=float(self.motor == "cutoff"))
        if self.gravity:
            scene.add_effect("gravity", body=BODY, g_w=self.g_w)
        if self.damping > 0:
            scene.add_effect("angular_damping", body=BODY, c=self.damping)
        return scene

    def make_sim(self, q0: ArrayLike | None = None, omega_b: ArrayLike = (0, 0, 0), Omega: ArrayLike = (0, 0, 0),
                 dt: float = 1e-3, backend: str = "auto", integrator: str = "rk4") -> Sim:
        """Build a Sim of the cube (:meth:`scene`) with the given initial state.

        Parameters
        ----------
        q0 : array_like (4,), optional
            Initial orientation of the cube, body to world, quaternion (x, y, z, w); normalized.
            Default: :meth:`upright_q`.
        omega_b : array_like (3,), default (0, 0, 0)
            Initial angular velocity of the cube, body frame, rad/s.
        Omega : array_like (3,), default (0, 0, 0)
            Initial wheel rates relative to the body, rad/s.
        dt : float, default 1e-3
            Integrator time step, s.
        backend : str, default "auto"
            Simulator backend: ``"auto"``, ``"c"`` or ``"numpy"``.
        integrator : str, default "rk4"
            The Sim's integrator (e.g. ``"rk4"``, ``"euler"``).

        Returns
        -------
        Sim
            A new :class:`lavendersim.sim.Sim`, at t = 0, wheel commands 0.

        Raises
        ------
        lavendersim.validate.LavenderInputError
            If ``q0``, ``omega_b``, ``Omega`` or a Sim option is invalid.
        """
        import lavendersim as lv

        sim = lv.Sim(self.scene(q0, omega_b), dt=dt, integrator=integrator, backend=backend)
        if np.any(np.asarray(Omega, dtype=float) != 0):
            sim.set_state(BODY, Omega=V.vector("Omega", Omega))
        return sim

    def as_dict(self) -> dict[str, Any]:
        """The model's parameters as a JSON-serializable dict.

        Returns
        -------
        dict
            ``scenario, mass, size, J (list of 3), torque_limit, speed_limit, damping,
            wheel_damping, g, motor`` (the constructor's keywords: ``CubeModel(**d)`` rebuilds it).
        """
        return {"scenario": self.scenario, "mass": self.mass, "size": self.size, "J": self.J.tolist(),
                "torque_limit": self.torque_limit, "speed_limit": self.speed_limit, "damping": self.damping,
                "wheel_damping": self.wheel_damping, "g": self.g, "motor": self.motor}


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


def linearize(sim_or_scene: CubeModel | Sim | Scene, x0: dict | None = None, u0: dict | None = None, *,
              inputs: list[str] | str | None = None, outputs: list[str] | str | None = None, dt: float | None = None,
              q_ref: ArrayLike | None = None, Omega0: ArrayLike = (0, 0, 0), name: str = "lavendersim") -> Any:
    """Linearize a scene (or the wheel cube) at an operating point, by CasADi AD of the derived kernels.

    The right-hand side is composed from generated/kernels_casadi.py — each body's model kernel
    (rigid_body_rhs, pivot_body_rhs, wheel_body_rhs with wheel_motor) and the CasADi printing of
    every force effect the scene declares, user effects included — so it is the model the backends
    step. See lavendersim._linearize for the error coordinates (per body p, dtheta, v, omega; a
    jointed body dtheta, omega; wheels add Omega) and the input names. For a CubeModel, ``x0``,
    ``u0``, ``inputs``, ``outputs`` and ``name`` are not used; for a Sim or Scene, ``q_ref`` and
    ``Omega0`` are not used.

    Parameters
    ----------
    sim_or_scene : Sim, Scene or CubeModel
        What to linearize. A Sim's current state (and held wheel commands) is the default operating
        point; a Scene's is its bodies' initial state. A CubeModel gives the 9-state cube model
        (states ``STATE_LABELS``, inputs ``INPUT_LABELS``) at ``q_ref`` (default: upright) with wheel
        rates ``Omega0`` (rad/s) and the equilibrium torque u0 = c_w Omega0; it must be an equilibrium.
    x0 : dict, optional
        ``{body: {"q": (4,), "omega_b": (3,), "Omega": (3,), "p_w": (3,), "v_w": (3,)}}`` overriding
        parts of the operating point (p_w, v_w only for free bodies).
    u0 : dict, optional
        ``{input name: value}`` overriding the operating input (default: the held wheel commands, the
        effects' declared parameter values).
    inputs : list of str, optional
        ``"BODY.u"`` (3 wheel commands, N·m) or ``"EFFECT.PARAM"`` (a parameter of a force effect
        declared once on the scene). Default: every wheeled body's commands.
    outputs : list of str, optional
        State labels to output (default: every state, C = I).
    dt : float, optional
        If given, the zero-order-hold discretization at this period (s) is returned.
    q_ref : array_like (4,), optional
        CubeModel only: the operating orientation, body to world, quaternion (x, y, z, w)
        (normalized). Default: ``model.upright_q()``.
    Omega0 : array_like (3,), default (0, 0, 0)
        CubeModel only: the operating wheel rates relative to the body, rad/s.
    name : str, default "lavendersim"
        Name of the returned system (Sim or Scene only; a CubeModel's is ``"wheel_cube"``).

    Returns
    -------
    Linearization
        A ``control.StateSpace`` (n states, m inputs du = u − u0) with named states, inputs and
        outputs, the operating point, ``f0`` (the right-hand side there) and the controllable subspace.

    Raises
    ------
    lavendersim._install.MissingExtraError
        If python-control or CasADi (the ``control`` extra) is not installed.
    lavendersim.validate.LavenderInputError
        If an argument is invalid, or (CubeModel) if the operating point (``q_ref``, ``Omega0``) is not
        an equilibrium of the model (the right-hand side is not zero there).
    """
    require("control", "control", "the StateSpace linearization")
    require("casadi", "control", "the CasADi linearization")
    from . import _linearize as L

    if isinstance(sim_or_scene, CubeModel):
        return _linearize_cube(sim_or_scene, q_ref, Omega0, dt)
    return L.linearize_scene(sim_or_scene, x0, u0, inputs=inputs, outputs=outputs, dt=dt, name=name)


def _linearize_cube(model: CubeModel, q_ref: ArrayLike | None, Omega0: ArrayLike, dt: float | None) -> Any:
    from . import _linearize as L

    q_ref = model.upright_q() if q_ref is None else V.quaternion("q_ref", q_ref)
    Omega0 = V.vector("Omega0", Omega0)
    sim = model.make_sim(q_ref, Omega=Omega0, backend="numpy")
    lin = L.linearize_scene(sim, None, {f"{BODY}.u": model.wheel_damping * Omega0}, inputs=[f"{BODY}.u"],
                            labels=list(STATE_LABELS), name="wheel_cube")
    lin = L.Linearization(lin.A, lin.B, lin.C, lin.D, 0, bodies=lin.bodies, input_refs=lin.input_refs, u0=lin.u0,
                          f0=lin.f0, wheel_states=lin.wheel_states, states=list(STATE_LABELS), inputs=list(INPUT_LABELS),
                          outputs=list(STATE_LABELS), name="wheel_cube")
    res = float(np.max(np.abs(lin.f0)))
    if res > 1e-9 * max(1.0, float(np.max(np.abs(lin.A)))):
        raise V.LavenderInputError("q_ref", "is not an equilibrium of the model (the right-hand side is not zero there: "
                                   "for the corner scenario the COM must be straight above the pivot)", f", |f| = {res:.3g}")
    return lin if dt is None else lin.sample(dt)


# ----------------------------------------------------------------------------------------------
# LQR
# ----------------------------------------------------------------------------------------------


def _weight(name: str, value, n: int, definite: bool) -> np.ndarray:
    """A weight matrix from a scalar, a diagonal (n,) or a matrix (n, n); checked symmetric and
    positive semidefinite (Q) or positive definite (R)."""
    try:
        arr = np.asarray(value, dtype=float)
    except (TypeError, ValueError):
        raise V.LavenderInputError(name, f"must be a number, a diagonal of {n} numbers or a {n}×{n} matrix",
                                   f", got {value!r}") from None
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
    if not np.allclose(arr, arr.T, rtol=1e-12, atol=1e-12 * max(1.0, np.abs(arr).max())):
        raise V.LavenderInputError(name, "must be symmetric")
    ev = np.linalg.eigvalsh((arr + arr.T) / 2)
    tol = 1e-12 * max(1.0, np.abs(ev).max())
    if definite and ev.min() <= tol:
        raise V.LavenderInputError(name, "must be positive definite", f", smallest eigenvalue {ev.min():.3g}")
    if not definite and ev.min() < -tol:
        raise V.LavenderInputError(name, "must be positive semidefinite", f", smallest eigenvalue {ev.min():.3g}")
    return (arr + arr.T) / 2


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


def _design(sys_or_A: Any, args: tuple, discrete: bool) -> LQRResult:
    ct = require("control", "control", "LQR design (python-control)")
    fn = "dlqr" if discrete else "lqr"
    A, B, T, (Q, R) = _pair(sys_or_A, args, fn, discrete)
    n, m = B.shape
    Q = _weight("Q", Q, n, definite=False)
    R = _weight("R", R, m, definite=True)
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
        Q and R are missing or not valid weights (Q symmetric PSD, R symmetric PD), or no input reaches
        any state.
    """
    return _design(sys, args, discrete=True)


def default_weights(model: CubeModel) -> tuple[np.ndarray, np.ndarray]:
    """Bryson-style default LQR weights for the cube's 9 states and 3 inputs.

    Attitude 1/(2°)², rates 1/(0.5 rad/s)², wheels 1/(0.5·limit)², torque 1/(0.5·limit)² (corner:
    attitude 1/(0.5°)²); the angles in rad, the limits ``speed_limit`` (rad/s) and ``torque_limit``
    (N·m).

    Parameters
    ----------
    model : CubeModel
        Gives the scenario and the limits.

    Returns
    -------
    Q : ndarray (9,)
        The diagonal of the state weight (order ``STATE_LABELS``), 1/rad², s²/rad², s²/rad².
    R : ndarray (3,)
        The diagonal of the input weight, 1/(N·m)².
    """
    ang = math.radians(2.0 if model.scenario == "center" else 0.5)
    q = np.concatenate([np.full(3, 1 / ang ** 2), np.full(3, 1 / 0.5 ** 2), np.full(3, 1 / (0.5 * model.speed_limit) ** 2)])
    return q, np.full(3, 1 / (0.5 * model.torque_limit) ** 2)


# ----------------------------------------------------------------------------------------------
# closed loop in the nonlinear simulator
# ----------------------------------------------------------------------------------------------


@dataclass
class Response:
    """A closed-loop run, with python-control's TimeResponseData names and shapes.

    The fields below are its attributes; ``inputs`` (m, T) are the applied (saturated) motor torques,
    N·m (``input_labels``), and ``time`` is ``t``.

    Parameters
    ----------
    t : ndarray (T,)
        Sample times (s), one per control period plus the start.
    error_deg : ndarray (T,)
        Attitude error angle to q_ref, degrees.
    omega_b : ndarray (T, 3)
        Cube angular velocity, body frame, rad/s, per sample.
    Omega : ndarray (T, 3)
        Wheel rates relative to the body, rad/s, per sample.
    u_cmd : ndarray (T, 3)
        Commanded motor torques (clipped to ±torque_limit), N·m, held from each sample to the next
        (the last sample repeats the one before).
    u_applied : ndarray (T, 3)
        Applied motor torques after the wheels' saturation (speed limit included), N·m, per sample.
    q : ndarray (T, 4)
        Orientation, body to world, quaternion (x, y, z, w).
    states : ndarray (n, T), optional
        Error-coordinate states (the linearization's state labels ``state_labels``).
    outputs : ndarray (p, T), optional
        C x (``output_labels``; the states when C = I).
    state_labels : tuple of str, default STATE_LABELS
        Names of the states.
    input_labels : tuple of str, default INPUT_LABELS
        Names of the inputs.
    output_labels : tuple of str, default STATE_LABELS
        Names of the outputs.
    """

    t: np.ndarray
    error_deg: np.ndarray
    omega_b: np.ndarray
    Omega: np.ndarray
    u_cmd: np.ndarray
    u_applied: np.ndarray
    q: np.ndarray
    states: np.ndarray | None = None
    outputs: np.ndarray | None = None
    state_labels: tuple = STATE_LABELS
    input_labels: tuple = INPUT_LABELS
    output_labels: tuple = STATE_LABELS

    @property
    def inputs(self) -> np.ndarray:
        """Applied inputs (m, T), N·m (python-control's layout: one row per input)."""
        return self.u_applied.T

    @property
    def time(self) -> np.ndarray:
        """Alias of t (python-control's TimeResponseData.time)."""
        return self.t

    def settling_time(self, threshold_deg: float) -> float:
        """First time after which the attitude error stays below threshold_deg (inf if never).

        Parameters
        ----------
        threshold_deg : float
            Attitude error threshold, deg.

        Returns
        -------
        float
            The sample time (s) following the last sample with ``error_deg >= threshold_deg``; 0.0 if
            there is none, ``math.inf`` if the last sample is still at or above the threshold.
        """
        above = np.flatnonzero(self.error_deg >= threshold_deg)
        if above.size == 0:
            return 0.0
        if above[-1] == self.t.size - 1:
            return math.inf
        return float(self.t[above[-1] + 1])

    def to_control(self) -> Any:
        """The same run as a ``control.TimeResponseData`` (outputs, states, inputs, labelled)."""
        ct = require("control", "control", "TimeResponseData")
        return ct.TimeResponseData(self.t, self.outputs, self.states, self.inputs, output_labels=list(self.output_labels),
                                   state_labels=list(self.state_labels), input_labels=list(self.input_labels))

    def plot(self, threshold_deg: float = 0.1) -> Any:
        """Plot the run on a new matplotlib Figure (not shown, no pyplot state).

        Four panels against t: attitude error (log), cube rates, applied torques, wheel rates.

        Parameters
        ----------
        threshold_deg : float, default 0.1
            Settling threshold, deg, drawn as a horizontal line on the attitude error panel.

        Returns
        -------
        matplotlib.figure.Figure
        """
        from matplotlib.figure import Figure

        fig = Figure(figsize=(11, 7), layout="constrained")
        ax = fig.subplots(2, 2)
        a = ax[0, 0]
        a.semilogy(self.t, np.maximum(self.error_deg, 1e-6), label="attitude error")
        a.axhline(threshold_deg, color="tab:red", ls=":", label=f"{threshold_deg:g}°")
        a.set_xlabel("t (s)"); a.set_ylabel("attitude error (deg)"); a.legend(fontsize=8)
        for a, data, lab, unit in ((ax[0, 1], self.omega_b, "ω", "cube rate ω_b (rad/s)"),
                                   (ax[1, 0], self.u_applied, "u", "applied motor torque (N·m)"),
                                   (ax[1, 1], self.Omega, "Ω", "wheel speed Ω (rad/s)")):
            for i, c in enumerate("xyz"[: data.shape[1]] if data.shape[1] <= 3 else range(data.shape[1])):
                a.plot(self.t, data[:, i], label=f"{lab}_{c}")
            a.set_xlabel("t (s)"); a.set_ylabel(unit); a.legend(fontsize=8)
        return fig


MAX_CONTROL_STEPS = 1_000_000  # closed_loop: control periods per run


def closed_loop(model: CubeModel, lin: Any, K: ArrayLike | Callable[[float, np.ndarray], ArrayLike], q0: ArrayLike,
                T: float = 5.0, *, omega0: ArrayLike = (0, 0, 0), Omega0: ArrayLike | None = None, dt: float = 1e-3,
                control_dt: float = 2e-3, backend: str = "auto", sim: Sim | None = None) -> Response:
    """Run the cube in the nonlinear simulator under a controller with a zero-order hold of control_dt.

    Parameters
    ----------
    model : CubeModel
        The plant simulated (it may differ from the one ``lin`` linearizes); its ``torque_limit``
        clips the commands.
    lin : Linearization
        Gives the error coordinates x (lin.state) and, for a gain, the operating point.
    K : (3, 9) array or callable
        A gain: u = u0 + du_ss − K (x − x_ss) (lin.feedback), or any controller ``u = K(t, x)``
        returning the 3 motor torques (N·m) from the time (s) and the error state x (9,). Either is
        clipped to ±torque_limit and the Sim's reaction_wheels saturate again (speed limit included).
    q0 : (4,)
        Initial orientation (x, y, z, w).
    T : float, default 5.0
        Duration, s; > 0, at most ``MAX_CONTROL_STEPS`` control periods.
    omega0 : array_like (3,), default (0, 0, 0)
        Initial angular velocity of the cube, body frame, rad/s.
    Omega0 : array_like (3,), optional
        Initial wheel rates relative to the body, rad/s. Default: the operating point's
        ``lin.Omega0``.
    dt : float, default 1e-3
        Simulator time step, s.
    control_dt : float, default 2e-3
        Control period (zero-order hold), s; a whole multiple of ``dt``.
    backend : str, default "auto"
        Simulator backend: ``"auto"``, ``"c"`` or ``"numpy"``.
    sim : Sim, optional
        Any object with the Sim's wheel API instead of building one; then ``q0``, ``omega0``,
        ``Omega0`` and ``backend`` are not used, and its time step should be ``dt`` (each control
        period runs ``control_dt / dt`` steps).

    Returns
    -------
    Response
        Sampled once per control period, from t = 0 to T.

    Raises
    ------
    lavendersim.validate.LavenderInputError
        If ``dt`` or ``control_dt`` is not positive, ``control_dt`` is not a whole multiple of ``dt``,
        ``T`` is not positive or needs more than ``MAX_CONTROL_STEPS`` control periods, a gain ``K`` is
        not (m, n), or the controller returns anything but 3 finite torques.
    lavendersim.errors.DivergenceError
        If the simulation diverges.
    """
    dt = V.dt("dt", dt)
    control_dt = V.dt("control_dt", control_dt)
    sub = int(round(control_dt / dt))
    if sub < 1 or abs(sub * dt - control_dt) > 1e-9 * control_dt:
        raise V.LavenderInputError("control_dt", f"must be a whole multiple of dt = {dt:g}", f", got {control_dt!r}")
    T = V.positive("T", T)
    if not T / control_dt <= MAX_CONTROL_STEPS:  # stepped in Python and recorded: bounded, never a hang
        raise V.LavenderInputError("T", f"would take {T / control_dt:.3g} control steps of {control_dt:g} s; at most "
                                   f"{MAX_CONTROL_STEPS:,} are allowed", f", got {T!r}")
    if callable(K):
        controller = K
    else:
        Km = np.asarray(K, float)
        if Km.shape != (lin.ninputs, lin.nstates):
            raise V.LavenderInputError("K", f"a gain must be {lin.ninputs}×{lin.nstates} (or pass a callable u = f(t, x))",
                                       f", got shape {Km.shape}")
        controller = lambda t, x: lin.control_law(Km, x)  # noqa: E731
    n = int(round(T / control_dt))
    Omega0 = lin.Omega0 if Omega0 is None else V.vector("Omega0", Omega0)
    if sim is None:
        sim = model.make_sim(q0, omega0, Omega0, dt=dt, backend=backend)
    t = np.empty(n + 1)
    qs, ws, Oms = np.empty((n + 1, 4)), np.empty((n + 1, 3)), np.empty((n + 1, 3))
    xs = np.empty((n + 1, lin.nstates))
    ucmd, uapp = np.zeros((n + 1, 3)), np.zeros((n + 1, 3))
    lim = model.torque_limit
    for k in range(n + 1):
        st = sim.state(BODY)
        q, w, Om = st.q, st.omega_b, sim.wheel_rates(BODY)
        t[k], qs[k], ws[k], Oms[k] = sim.t, q, w, Om
        xs[k] = lin.state(q, w, Om)
        if k == n:
            break
        u = np.asarray(controller(float(sim.t), xs[k].copy()), dtype=float)
        if u.shape != (3,) or not np.all(np.isfinite(u)):
            raise V.LavenderInputError("K", "the controller must return 3 finite motor torques (N·m)",
                                       f", got {np.array2string(np.asarray(u), precision=4)} at t = {sim.t:g} s")
        u = np.clip(u, -lim, lim)
        sim.set_wheel_command(BODY, u)
        sim.run(sub)
        ucmd[k], uapp[k] = u, sim.wheel_command_applied(BODY)
    ucmd[n], uapp[n] = ucmd[n - 1], uapp[n - 1]
    C = np.asarray(lin.C, float)
    return Response(t, error_angle_deg(qs, lin.q_ref), ws, Oms, ucmd, uapp, qs, states=xs.T, outputs=C @ xs.T,
                    state_labels=tuple(lin.state_labels), input_labels=tuple(lin.input_labels),
                    output_labels=tuple(lin.output_labels))


# ----------------------------------------------------------------------------------------------
# design(): the whole workflow, as used by `lavendersim lqr`
# ----------------------------------------------------------------------------------------------


@dataclass
class DesignResult:
    """The result of :func:`design`: the model, its linearization, the LQR design and its closed-loop run.

    Parameters
    ----------
    model : CubeModel
        The plant designed for and simulated.
    lin : Linearization
        The continuous 9-state linearization of ``model`` at its upright equilibrium (states
        ``STATE_LABELS``, inputs ``INPUT_LABELS``).
    Q : ndarray (9, 9)
        State weight used (symmetric PSD).
    R : ndarray (3, 3)
        Input weight used (symmetric PD), 1/(N·m)².
    K : ndarray (3, 9)
        The LQR gain, N·m per state unit (u = u0 − K x).
    S : ndarray (9, 9)
        The Riccati solution of the design.
    poles : ndarray (9,)
        Closed-loop eigenvalues of A − B K (complex, sorted by real part), 1/s.
    response : Response
        The closed-loop run in the nonlinear simulator.
    theta0_deg : float
        Initial attitude error, deg.
    axis : ndarray (3,)
        Unit axis of the initial error, body frame.
    threshold_deg : float
        Settling threshold, deg.
    backend : str
        The simulator backend asked for (``"auto"``, ``"c"`` or ``"numpy"``).
    """

    model: CubeModel
    lin: Linearization
    Q: np.ndarray
    R: np.ndarray
    K: np.ndarray
    S: np.ndarray
    poles: np.ndarray
    response: Response
    theta0_deg: float
    axis: np.ndarray
    threshold_deg: float
    backend: str

    @property
    def settling_time(self) -> float:
        """Settling time to within ``threshold_deg``, s (``math.inf`` if never; see :meth:`Response.settling_time`)."""
        return self.response.settling_time(self.threshold_deg)

    @property
    def peak_torque(self) -> float:
        """max |applied motor torque| over wheels and time, N·m."""
        return float(np.max(np.abs(self.response.u_applied)))

    @property
    def peak_wheel_speed(self) -> float:
        """max |wheel rate| over wheels and time, rad/s (relative to the body)."""
        return float(np.max(np.abs(self.response.Omega)))

    @property
    def final_error_deg(self) -> float:
        """Attitude error at the end of the run, deg."""
        return float(self.response.error_deg[-1])

    def figures(self) -> dict[str, Any]:
        """The design's figures of merit and settings as plain Python values (JSON-ready but for inf).

        Returns
        -------
        dict
            ``model`` (:meth:`CubeModel.as_dict`), ``backend``, ``q_ref`` (x, y, z, w),
            ``controllability_rank``, ``n_states``, ``Q``, ``R``, ``K`` (nested lists),
            ``poles_real``, ``poles_imag`` (1/s), ``theta0_deg`` (deg), ``axis``, ``T`` (s),
            ``threshold_deg`` (deg), ``settling_time`` (s, ``math.inf`` if never), ``peak_torque``
            (N·m), ``peak_wheel_speed`` (rad/s), ``final_error_deg`` (deg),
            ``torque_limit_respected`` and ``speed_limit_respected`` (bool).
        """
        p = self.poles
        return {
            "model": self.model.as_dict(), "backend": self.backend,
            "q_ref": self.lin.q_ref.tolist(), "controllability_rank": self.lin.rank, "n_states": 9,
            "Q": self.Q.tolist(), "R": self.R.tolist(), "K": self.K.tolist(),
            "poles_real": p.real.tolist(), "poles_imag": p.imag.tolist(),
            "theta0_deg": self.theta0_deg, "axis": self.axis.tolist(), "T": float(self.response.t[-1]),
            "threshold_deg": self.threshold_deg,
            "settling_time": self.settling_time, "peak_torque": self.peak_torque,
            "peak_wheel_speed": self.peak_wheel_speed, "final_error_deg": self.final_error_deg,
            "torque_limit_respected": bool(self.peak_torque <= self.model.torque_limit * (1 + 1e-12)),
            "speed_limit_respected": bool(self.peak_wheel_speed <= self.model.speed_limit),
        }

    def to_json(self) -> str:
        """:meth:`figures` as an indented JSON string (an infinite settling time becomes null).

        Returns
        -------
        str
        """
        fig = self.figures()
        fig["settling_time"] = fig["settling_time"] if math.isfinite(fig["settling_time"]) else None
        return json.dumps(fig, indent=2)

    def plot(self, path: str | os.PathLike[str]) -> None:
        """Write the response plot to a file (PNG, 100 dpi).

        Four panels against t: attitude error (log, with the threshold and the settling time), cube
        rates, applied motor torques (with ±torque_limit), wheel rates.

        Parameters
        ----------
        path : str or os.PathLike
            Output file; its suffix selects the format (matplotlib's ``savefig``).

        Returns
        -------
        None
        """
        from .figures import new_figure

        r, m = self.response, self.model
        fig, ax = new_figure(2, 2, size=(11, 7), title=f"LQR {m.scenario}: {self.theta0_deg:g}° about "
                             f"{np.round(self.axis, 3).tolist()}, {self.backend} backend")
        a = ax[0, 0]
        a.semilogy(r.t, np.maximum(r.error_deg, 1e-6))
        a.axhline(self.threshold_deg, color="tab:red", ls=":", label=f"{self.threshold_deg:g}°")
        if math.isfinite(self.settling_time):
            a.axvline(self.settling_time, color="tab:gray", ls="--", label=f"settled {self.settling_time:.2f} s")
        a.set_xlabel("t (s)"); a.set_ylabel("attitude error (deg)"); a.legend(fontsize=8)
        a = ax[0, 1]
        for i, c in enumerate("xyz"):
            a.plot(r.t, r.omega_b[:, i], label=f"ω_{c}")
        a.set_xlabel("t (s)"); a.set_ylabel("cube rate ω_b (rad/s)"); a.legend(fontsize=8)
        a = ax[1, 0]
        for i, c in enumerate("xyz"):
            a.plot(r.t, r.u_applied[:, i], label=f"u_{c}")
        a.axhline(m.torque_limit, color="k", ls=":", lw=0.8); a.axhline(-m.torque_limit, color="k", ls=":", lw=0.8)
        a.set_xlabel("t (s)"); a.set_ylabel("applied motor torque (N·m)"); a.legend(fontsize=8)
        a = ax[1, 1]
        for i, c in enumerate("xyz"):
            a.plot(r.t, r.Omega[:, i], label=f"Ω_{c}")
        a.set_xlabel("t (s)"); a.set_ylabel("wheel speed Ω (rad/s)"); a.legend(fontsize=8)
        fig.savefig(path, dpi=100)


DEFAULT_AXIS = (1.0, 2.0, 3.0)
CORNER_AXIS = (1.0, 1.0, -2.0)  # perpendicular to the body diagonal: a pure tilt


def design(scenario: str = "center", Q: ArrayLike | None = None, R: ArrayLike | None = None, *,
           theta0_deg: float | None = None, axis: ArrayLike | None = None, T: float | None = None,
           threshold_deg: float = 0.1, backend: str = "auto", dt: float = 1e-3, control_dt: float = 2e-3,
           model: CubeModel | None = None, sim: Sim | None = None, **model_params: Any) -> DesignResult:
    """Linearize the cube, design the LQR gain and run the closed loop in the simulator.

    Linearize, design the LQR gain, run the closed loop from an initial error of theta0_deg
    about the body axis `axis` (defaults: 20° about (1, 2, 3) centre; 3° about (1, 1, −2), a pure
    tilt, corner), return a DesignResult.
    model_params go to CubeModel (mass, size, J, torque_limit, speed_limit, damping, …).

    Parameters
    ----------
    scenario : {"center", "corner"}, default "center"
        The CubeModel scenario (not used when ``model`` is given).
    Q : array_like, optional
        State weight: a scalar, a diagonal (9,) or a matrix (9, 9); symmetric PSD. Default:
        :func:`default_weights`.
    R : array_like, optional
        Input weight: a scalar, a diagonal (3,) or a matrix (3, 3), 1/(N·m)²; symmetric PD. Default:
        :func:`default_weights`.
    theta0_deg : float, optional
        Initial attitude error, deg (default 20 centre, 3 corner).
    axis : array_like (3,), optional
        Axis of the initial error, body frame, non-zero (default (1, 2, 3) centre, (1, 1, −2) corner).
    T : float, optional
        Simulated time, s (default 5 centre, 6 corner).
    threshold_deg : float, default 0.1
        Settling threshold, deg; > 0.
    backend : str, default "auto"
        Simulator backend: ``"auto"``, ``"c"`` or ``"numpy"``.
    dt : float, default 1e-3
        Simulator time step, s.
    control_dt : float, default 2e-3
        Control period (zero-order hold), s; a whole multiple of ``dt``.
    model : CubeModel, optional
        The plant; when given, ``scenario`` and ``model_params`` are not used.
    sim : Sim, optional
        A simulator to run the closed loop in instead of building one (see :func:`closed_loop`).
    **model_params
        Further CubeModel parameters (mass, size, J, torque_limit, speed_limit, damping,
        wheel_damping, g, motor).

    Returns
    -------
    DesignResult

    Raises
    ------
    lavendersim._install.MissingExtraError
        If python-control or CasADi (the ``control`` extra) is not installed.
    lavendersim.validate.LavenderInputError
        If a model parameter, a weight, ``theta0_deg``, ``axis``, ``T``, ``dt``, ``control_dt`` or
        ``threshold_deg`` is invalid.
    TypeError
        If ``model_params`` has a name CubeModel does not take.
    lavendersim.errors.DivergenceError
        If the closed-loop simulation diverges.
    """
    model = model or CubeModel(scenario=scenario, **model_params)
    lin = linearize(model)
    q_def, r_def = default_weights(model)
    Qm = _weight("Q", q_def if Q is None else Q, 9, definite=False)
    Rm = _weight("R", r_def if R is None else R, 3, definite=True)
    K, S, E = lqr(lin, Qm, Rm)
    theta0 = (20.0 if model.scenario == "center" else 3.0) if theta0_deg is None else theta0_deg
    theta0 = V.scalar("theta0_deg", theta0)
    T = (5.0 if model.scenario == "center" else 6.0) if T is None else T
    axis_v = V.vector("axis", (DEFAULT_AXIS if model.scenario == "center" else CORNER_AXIS) if axis is None else axis)
    q0 = rotated(lin.q_ref, axis_v, theta0)
    resp = closed_loop(model, lin, K, q0, T, dt=dt, control_dt=control_dt, backend=backend, sim=sim)
    return DesignResult(model, lin, Qm, Rm, K, S, E, resp, theta0, axis_v / np.linalg.norm(axis_v),
                        V.positive("threshold_deg", threshold_deg), backend)


# ----------------------------------------------------------------------------------------------
# Monte Carlo robustness
# ----------------------------------------------------------------------------------------------

# Perturbations (independent, uniform, relative to the nominal value): the plant's mass (and with it
# its inertia), its size (inertia and, in the corner scenario, the COM height), each wheel's spin
# inertia, the motor stall torque and no-load speed.
MC_SPREAD = {"mass": 0.10, "size": 0.05, "J": 0.20, "torque_limit": 0.10, "speed_limit": 0.10}


def monte_carlo_tasks(model: CubeModel, n: int, seed: int) -> list[dict[str, Any]]:
    """Draw the perturbed plants' parameters (n dicts for CubeModel) for a Monte Carlo run.

    The parameters are drawn here from one seeded generator (numpy default_rng(seed)) so every
    executor runs the same samples. See MC_SPREAD: each of mass, size, J (per wheel), torque_limit
    and speed_limit is multiplied by 1 + spread·U(−1, 1), independently.

    Parameters
    ----------
    model : CubeModel
        The nominal plant.
    n : int
        Number of samples; >= 1.
    seed : int
        Seed of numpy's default_rng; >= 0.

    Returns
    -------
    list of dict
        n keyword dicts for CubeModel (as :meth:`CubeModel.as_dict`, perturbed).

    Raises
    ------
    lavendersim.validate.LavenderInputError
        If ``n`` or ``seed`` is not an integer in range.
    """
    n = V.integer("monte_carlo", n, minimum=1)
    rng = np.random.default_rng(V.integer("seed", seed, minimum=0))
    base = model.as_dict()
    out = []
    for _ in range(n):
        d = dict(base)
        for key, spread in MC_SPREAD.items():
            nominal = np.asarray(base[key], dtype=float)
            d[key] = (nominal * (1 + spread * rng.uniform(-1, 1, nominal.shape))).tolist()
        out.append(d)
    return out


def monte_carlo_sample(task: dict[str, Any]) -> dict[str, Any]:
    """Run one closed loop of a perturbed plant under the nominal design's gain.

    A module-level function of a picklable task: the executor's contract. Never raises for a plant
    that diverges: it is a failure.

    Parameters
    ----------
    task : dict
        ``model`` (the perturbed plant's CubeModel keywords), ``nominal`` (the nominal plant's, whose
        linearization gives the error coordinates and operating point), ``K`` (3×9 gain, N·m per
        state unit, nested lists), ``axis`` (3, body frame), ``theta0_deg`` (deg), ``T``, ``dt``,
        ``control_dt`` (s), ``backend`` and ``threshold_deg`` (deg).

    Returns
    -------
    dict
        ``settled`` (bool: settled and below the threshold at the end), ``settling_time`` (s, None if
        never or diverged), ``peak_torque`` (N·m, None if diverged), ``final_error_deg`` (deg, None
        if diverged) and ``why`` (the divergence message, else None).

    Raises
    ------
    lavendersim.validate.LavenderInputError
        If the task's parameters are invalid (a divergence is not raised).
    """
    from .errors import DivergenceError

    model = CubeModel(**task["model"])
    lin = linearize(CubeModel(**task["nominal"]))
    K = np.asarray(task["K"], float)
    q0 = rotated(lin.q_ref, task["axis"], task["theta0_deg"])
    try:
        r = closed_loop(model, lin, K, q0, task["T"], dt=task["dt"], control_dt=task["control_dt"], backend=task["backend"])
    except DivergenceError as exc:
        return {"settled": False, "settling_time": None, "peak_torque": None, "final_error_deg": None, "why": str(exc)}
    st = r.settling_time(task["threshold_deg"])
    ok = math.isfinite(st) and bool(r.error_deg[-1] < task["threshold_deg"])
    return {"settled": ok, "settling_time": st if math.isfinite(st) else None,
            "peak_torque": float(np.max(np.abs(r.u_applied))), "final_error_deg": float(r.error_deg[-1]), "why": None}


def monte_carlo(res: DesignResult, n: int, seed: int, executor: Any = None) -> dict[str, Any]:
    """Re-run the closed loop of a design on n perturbed plants (MC_SPREAD), with the design's gain.

    Parameters
    ----------
    res : DesignResult
        The nominal design (its gain K, initial error, T, threshold, backend).
    n, seed : int
        Samples and the seed of numpy's default_rng that draws them.
    executor : lavendersim.executor.Executor, optional
        Where the samples run (serial, local processes, a Dask cluster); results are in sample order,
        so the summary is the same for the same seed on any executor.

    Returns
    -------
    dict
        n, seed, spreads, failures, failure_rate, settling-time and peak-torque percentiles (s, N·m; over
        the settled samples) and the per-sample results.
    """
    from . import executor as X

    nominal = res.model.as_dict()
    base = {"nominal": nominal, "K": res.K.tolist(), "axis": res.axis.tolist(), "theta0_deg": res.theta0_deg,
            "T": float(res.response.t[-1]), "dt": 1e-3, "control_dt": 2e-3, "backend": res.backend,
            "threshold_deg": res.threshold_deg}
    tasks = [{**base, "model": m} for m in monte_carlo_tasks(res.model, n, seed)]
    samples = X.map_tasks(monte_carlo_sample, tasks, executor, feature="lavendersim lqr --dask")
    ok = [s for s in samples if s["settled"]]
    st = np.array([s["settling_time"] for s in ok], dtype=float)
    pk = np.array([s["peak_torque"] for s in samples if s["peak_torque"] is not None], dtype=float)

    def pct(a):
        return {p: (float(np.percentile(a, int(p[1:]))) if a.size else None) for p in ("p50", "p90", "p100")}

    return {"n": len(samples), "seed": int(seed), "spread": dict(MC_SPREAD), "distribution": "uniform, relative",
            "failures": len(samples) - len(ok), "failure_rate": (len(samples) - len(ok)) / len(samples),
            "settling_time": pct(st), "peak_torque": pct(pk), "samples": samples}


# ----------------------------------------------------------------------------------------------
# checking the linearization against the runtime simulator
# ----------------------------------------------------------------------------------------------


def finite_difference_AB(model: CubeModel, lin: Linearization, *, backend: str = "auto", h: float = 1e-5,
                         dt: float = 1e-3, make_sim: Callable[[np.ndarray, np.ndarray, np.ndarray, float], Sim] | None = None
                         ) -> tuple[np.ndarray, np.ndarray]:
    """A and B by central finite differences of the runtime simulator's right-hand side.

    One explicit-Euler step of the Sim (integrator="euler") from an equilibrium perturbation is
    Φ(x, u) = x + dt f(x, u) + (normalization, even in the perturbation), so at the equilibrium
    (Φ(+h e_j) − Φ(−h e_j)) / (2 h) = e_j + dt A e_j exactly in dt; A = ((Φ₊ − Φ₋)/(2h) − e_j)/dt and
    likewise B. The states are mapped to error coordinates with lin.state. `make_sim(q, omega_b,
    Omega, dt)` may replace the Sim (the tests' independent reference uses it).

    Parameters
    ----------
    model : CubeModel
        The cube whose Sim is stepped.
    lin : Linearization
        The cube's continuous linearization (:func:`linearize` of ``model``) at an equilibrium: gives
        q_ref, Omega0, u0 and the error coordinates.
    backend : str, default "auto"
        Simulator backend of the default Sim: ``"auto"``, ``"c"`` or ``"numpy"``.
    h : float, default 1e-5
        Perturbation of each error coordinate (rad, rad/s, rad/s) and input (N·m).
    dt : float, default 1e-3
        The Euler step, s.
    make_sim : callable, optional
        ``make_sim(q (4,), omega_b (3,), Omega (3,), dt) -> Sim``, stepping with explicit Euler.
        Default: ``model.make_sim(..., backend=backend, integrator="euler")``.

    Returns
    -------
    A_fd : ndarray (n, n)
        State matrix, 1/s.
    B_fd : ndarray (n, m)
        Input matrix.
    """
    if make_sim is None:
        def make_sim(q, w, Om, dt_):
            return model.make_sim(q, w, Om, dt=dt_, backend=backend, integrator="euler")

    def phi(x, du):
        q = perturbed(lin.q_ref, x[0:3])
        sim = make_sim(q, x[3:6], lin.Omega0 + x[6:9], dt)
        sim.set_wheel_command(BODY, lin.u0 + du)
        sim.step()
        st = sim.state(BODY)
        return lin.state(st.q, st.omega_b, sim.wheel_rates(BODY))

    n, m = lin.B.shape
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


# ----------------------------------------------------------------------------------------------
# `lavendersim lqr`
# ----------------------------------------------------------------------------------------------


def _numbers(field_name: str, text: str) -> np.ndarray:
    try:
        vals = [float(v) for v in text.replace(";", ",").split(",") if v.strip()]
    except ValueError:
        raise V.LavenderInputError(field_name, "must be comma-separated numbers", f", got {text!r}") from None
    if not vals:
        raise V.LavenderInputError(field_name, "must not be empty")
    return np.array(vals)


def _matrix_arg(field_name: str, text: str | None, n: int):
    """'1' (scalar), 'a,b,…' (n diagonal entries) or n² entries row-major (a full matrix)."""
    if text is None:
        return None
    v = _numbers(field_name, text)
    if v.size == 1:
        return float(v[0])
    if v.size == n:
        return v
    if v.size == n * n:
        return v.reshape(n, n)
    raise V.LavenderInputError(field_name, f"give 1 number, {n} diagonal entries or {n * n} matrix entries (row-major)",
                               f", got {v.size}")


def register_cli(subparsers: argparse._SubParsersAction) -> None:
    """Add the ``lavendersim lqr`` subcommand to the command-line parser.

    Parameters
    ----------
    subparsers : argparse._SubParsersAction
        The ``add_subparsers()`` action of the ``lavendersim`` parser; the ``lqr`` parser's handler
        is set as its ``fn`` default.

    Returns
    -------
    None
    """
    p = subparsers.add_parser("lqr", help="design an LQR wheel controller for the reaction-wheel cube and run it in the simulator",
                              description=__doc__.split("\n\n")[0] + "\n\nQ and R: one number (times identity), the "
                              "diagonal (9 / 3 numbers, comma-separated) or the full matrix row-major (81 / 9 numbers). "
                              "State order: " + ", ".join(STATE_LABELS) + ".")
    p.add_argument("--layout", default="cube3", choices=LAYOUT_CHOICES, help="wheel layout: cube3 (three wheels on the body "
                   "axes, default) or pyramid4 (four wheels on a pyramid, a free cube spacecraft: 30° slew with null-space "
                   "wheel-speed management and the momentum check; lavendersim.wheel_layout)")
    p.add_argument("--scenario", default="center", choices=SCENARIOS, help="center: joint at the centre (ReactionWheelCube-v0); "
                   "corner: balancing on a corner under gravity (default center)")
    p.add_argument("--Q", help="state weight (default: Bryson, see lavendersim.control.default_weights)")
    p.add_argument("--R", help="input weight (default: 1/(0.5 torque_limit)² per wheel)")
    p.add_argument("--mass", type=float, default=1.0, help="total mass, kg (default 1)")
    p.add_argument("--size", type=float, default=0.15, help="cube side, m (default 0.15)")
    p.add_argument("--J", default="5.7e-4", help="wheel spin inertia(s), kg·m²: 1 or 3 numbers (default 5.7e-4)")
    p.add_argument("--torque-limit", type=float, default=0.2, help="motor torque limit, N·m (default 0.2)")
    p.add_argument("--speed-limit", type=float, default=400.0, help="wheel speed limit, rad/s (default 400)")
    p.add_argument("--damping", type=float, default=0.0, help="cube angular damping, N·m·s/rad (default 0)")
    p.add_argument("--wheel-damping", type=float, default=0.0, help="wheel bearing damping, N·m·s/rad (default 0)")
    p.add_argument("--theta0", type=float, default=None, help="initial attitude error, deg (default 20 center, 3 corner)")
    p.add_argument("--axis", default=None, help="initial error axis, body frame, x,y,z (default 1,2,3 center; "
                   "1,1,-2 corner: a pure tilt)")
    p.add_argument("--T", type=float, default=None, help="simulated time, s (default 5 center, 6 corner)")
    p.add_argument("--threshold", type=float, default=0.1, help="settling threshold, deg (default 0.1)")
    p.add_argument("--backend", default="auto", choices=("auto", "c", "numpy"),
                   help="simulator backend (default auto: C when built, else NumPy with a warning)")
    p.add_argument("--plot", default=None, metavar="PATH", help="write the response plot to PATH (PNG; default: no plot)")
    p.add_argument("--json", action="store_true", help="print the figures as JSON")
    p.add_argument("--motor", default="line", choices=MOTORS, help="wheel motor: line (torque–speed line, default) or "
                   "cutoff (full torque up to the speed limit)")
    p.add_argument("--monte-carlo", type=int, default=None, metavar="N", help="also re-run the closed loop on N plants "
                   "with mass, size, wheel inertias and motor parameters perturbed (uniform, see MC_SPREAD)")
    p.add_argument("--seed", type=int, default=0, help="seed of the Monte Carlo draws (default 0)")
    p.add_argument("--workers", type=int, default=None, help="Monte Carlo on N local processes (default: every core; 1: serial)")
    p.add_argument("--dask", default=None, metavar="ADDRESS", help="Monte Carlo on the Dask scheduler at ADDRESS "
                   "(the distributed extra)")
    p.set_defaults(fn=_cli)


def _cli(args) -> int:
    import sys

    if args.layout != "cube3":
        return _cli_layout(args)
    try:
        J = _numbers("J", args.J)
        if J.size not in (1, 3):
            raise V.LavenderInputError("J", "give 1 or 3 wheel inertias", f", got {J.size}")
        axis = None if args.axis is None else _numbers("axis", args.axis)
        if axis is not None and axis.size != 3:
            raise V.LavenderInputError("axis", "must be 3 numbers", f", got {axis.size}")
        if args.plot:
            V.writable_file("plot", args.plot)  # before the design and the run, not after
        for name in ("mass", "size", "torque_limit", "speed_limit", "damping", "wheel_damping", "theta0", "T", "threshold"):
            v = getattr(args, name)
            if v is not None and not math.isfinite(v):
                raise V.LavenderInputError(name.replace("_", "-"), "must be finite", f", got {v!r}")
        model = CubeModel(scenario=args.scenario, mass=args.mass, size=args.size, J=J if J.size == 3 else float(J[0]),
                          torque_limit=args.torque_limit, speed_limit=args.speed_limit, damping=args.damping,
                          wheel_damping=args.wheel_damping, motor=args.motor)
        ex = None
        if args.monte_carlo is not None:
            from . import executor as X

            V.integer("monte-carlo", args.monte_carlo, minimum=1)
            V.integer("seed", args.seed, minimum=0)
            ex = X.resolve(workers=args.workers, dask=args.dask, feature="lavendersim lqr --dask")
        if axis is None:
            axis = DEFAULT_AXIS if model.scenario == "center" else CORNER_AXIS
        res = design(model=model, Q=_matrix_arg("Q", args.Q, 9), R=_matrix_arg("R", args.R, 3), theta0_deg=args.theta0,
                     axis=axis, T=args.T, threshold_deg=args.threshold, backend=args.backend)
        mc = None if args.monte_carlo is None else monte_carlo(res, args.monte_carlo, args.seed, ex)
    except V.LavenderInputError as exc:
        print(f"lavendersim lqr: invalid parameter: {exc}", file=sys.stderr)
        return 2
    if args.plot:
        res.plot(args.plot)
    if args.json:
        if mc is None:
            print(res.to_json())
        else:
            out = json.loads(res.to_json())
            out["monte_carlo"] = {k: v for k, v in mc.items() if k != "samples"}
            print(json.dumps(out, indent=2))
        return 0
    f = res.figures()
    np.set_printoptions(precision=5, suppress=True, linewidth=140)
    print(f"LQR, scenario {model.scenario}: {json.dumps(model.as_dict())}")
    print(f"controllability rank {res.lin.rank} of 9"
          + ("" if res.lin.controllable else " (the rest: conserved angular momentum; designed on the controllable subspace)"))
    print(f"K (N·m per state unit; states {', '.join(STATE_LABELS)}):\n{res.K}")
    print("closed-loop poles: " + ", ".join(f"{z.real:.4g}{z.imag:+.4g}j" for z in res.poles))
    st = f"{f['settling_time']:.3f} s" if math.isfinite(f["settling_time"]) else "never"
    print(f"from {f['theta0_deg']:g}° about {np.round(res.axis, 4).tolist()}: settling time (< {f['threshold_deg']:g}°) {st}, "
          f"final error {f['final_error_deg']:.3g}°, peak torque {f['peak_torque']:.4g} N·m (limit {model.torque_limit:g}), "
          f"peak wheel speed {f['peak_wheel_speed']:.4g} rad/s (limit {model.speed_limit:g})")
    if mc is not None:
        fmt = lambda d, u: ", ".join(f"{k} {v:.4g} {u}" if v is not None else f"{k} -" for k, v in d.items())  # noqa: E731
        print(f"Monte Carlo, {mc['n']} plants (seed {mc['seed']}; uniform ±{', ±'.join(f'{100 * v:g}% {k}' for k, v in MC_SPREAD.items())}): "
              f"failure rate {mc['failure_rate']:.3g} ({mc['failures']}); settling time {fmt(mc['settling_time'], 's')}; "
              f"peak torque {fmt(mc['peak_torque'], 'N·m')}")
    if args.plot:
        print(f"wrote {args.plot}")
    return 0


def _cli_layout(args) -> int:
    """``lavendersim lqr --layout pyramid4``: the slew and the momentum check of lavendersim.wheel_layout."""
    import sys

    from . import wheel_layout as WL

    try:
        unsupported = [(f"--{k.replace('_', '-')}", v) for k, v in (("scenario", args.scenario != "center"), ("monte_carlo", args.monte_carlo),
                                                                   ("dask", args.dask), ("damping", args.damping), ("plot", args.plot))
                       if v not in (None, False, 0.0)]
        if unsupported:
            raise V.LavenderInputError("layout", f"--layout {args.layout} runs the free cube's slew only",
                                       f"; {unsupported[0][0]} is not supported with it")
        for name in ("mass", "size", "torque_limit", "speed_limit", "wheel_damping", "theta0", "T", "threshold"):
            v = getattr(args, name)
            if v is not None and not math.isfinite(v):
                raise V.LavenderInputError(name.replace("_", "-"), "must be finite", f", got {v!r}")
        J = _numbers("J", args.J)
        if J.size not in (1, 4):
            raise V.LavenderInputError("J", f"give 1 or 4 wheel inertias for --layout {args.layout}", f", got {J.size}")
        axis = DEFAULT_AXIS if args.axis is None else _numbers("axis", args.axis)
        if np.size(axis) != 3:
            raise V.LavenderInputError("axis", "must be 3 numbers", f", got {np.size(axis)}")
        model = WL.LAYOUTS[args.layout](J=J if J.size > 1 else float(J[0]), mass=args.mass, size=args.size,
                                        torque_limit=args.torque_limit, speed_limit=args.speed_limit,
                                        wheel_damping=args.wheel_damping, motor=args.motor)
        n = model.n
        res = WL.slew(model, 30.0 if args.theta0 is None else args.theta0, axis, T=3.0 if args.T is None else args.T,
                      Q=_matrix_arg("Q", args.Q, 6 + n), R=_matrix_arg("R", args.R, n), threshold_deg=args.threshold)
        mom = WL.momentum_exchange(WL.LAYOUTS[args.layout](J=model.J, mass=model.mass, size=model.size,
                                                           torque_limit=model.torque_limit, speed_limit=model.speed_limit))
    except V.LavenderInputError as exc:
        print(f"lavendersim lqr: invalid parameter: {exc}", file=sys.stderr)
        return 2
    f = res.figures()
    if args.json:
        print(json.dumps({**f, "K": res.K.tolist(), "A_b": model.A_b.tolist(), "momentum_check": mom}, indent=2))
        return 0
    np.set_printoptions(precision=5, suppress=True, linewidth=140)
    print(f"LQR, layout {args.layout}: {n} wheels, free cube {model.mass:g} kg, {model.size:g} m; axes (columns, body frame):\n{model.A_b}")
    print(f"controllability rank {res.rank} of {6 + n} (the rest: conserved angular momentum); dlqr at {0.01:g} s, "
          f"null-space wheel-speed target {np.round(res.Omega_ref, 3).tolist()} rad/s")
    print(f"K (states {', '.join(WL.state_labels(n))}):\n{res.K}")
    st = f"{f['settling_time']:.3f} s" if math.isfinite(f["settling_time"]) else "never"
    print(f"slew {30.0 if args.theta0 is None else args.theta0:g}° about {np.round(np.asarray(axis, float), 4).tolist()}: settling time "
          f"(< {f['threshold_deg']:g}°) {st}, final error {f['final_error_deg']:.3g}°; peak |Omega_i| "
          f"{np.round(f['peak_wheel_speed'], 2).tolist()} rad/s (limit {model.speed_limit:g}), peak |u_i| "
          f"{np.round(f['peak_torque'], 4).tolist()} N·m (limit {model.torque_limit:g}); within limits: {f['within_limits']}")
    print(f"null-space wheel speed: {f['null_Omega_start'][0]:.4g} → {f['null_Omega_end'][0]:.4g} rad/s "
          f"(target {f['null_Omega_target'][0]:.4g}; no torque on the body: A_b n = 0)")
    print(f"momentum check (damping off, 2 s of varying commands): |ΔL_body + ΔL_wheels| / max|ΔL_wheels| = "
          f"{mom['exchange_residual']:.2e}, |L| drift {mom['L_drift']:.2e}")
    return 0
