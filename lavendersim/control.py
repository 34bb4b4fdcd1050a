"""LQR wheel controllers for the reaction-wheel cube: CasADi linearization + python-control.

The model is the derived one, nothing typed by hand: :func:`linearize` builds the right-hand side
in CasADi from ``generated/kernels_casadi.py`` — ``wheel_body_rhs`` with ``F_w = effect_gravity(m,
g_w)`` and ``tau_w = effect_angular_damping(q, omega_b, c)``, the inertia from ``inertia_box`` and
``parallel_axis`` — and differentiates it at an equilibrium.

State (error coordinates, 9): ``x = [dtheta (3), omega_b (3), Omega - Omega_0 (3)]`` where the
attitude error ``dtheta`` (rad, body frame) is defined by ``q = q_ref ⊗ [dtheta/2, sqrt(1 -
|dtheta/2|²)]``, i.e. ``dtheta = 2 vec(q_ref* ⊗ q)`` on the hemisphere ``w >= 0``; ``omega_b``
rad/s; ``Omega`` wheel rates relative to the body, rad/s. Input ``u`` (3): motor torques on the
wheels, N·m (the cube receives −u), relative to the equilibrium torque ``u_0 = c_w Omega_0``.

Scenarios (:class:`CubeModel`):
  * ``"center"`` — ReactionWheelCube-v0: spherical joint at the cube's centre (no gravity
    torque), equilibrium at ``q_ref`` (default identity).
  * ``"corner"`` — Cubli-like balancing on one corner under gravity: the joint is at the body
    corner ``-s/2 (1, 1, 1)``; the equilibrium has the body diagonal vertical, COM above the corner.

Internal torques cannot change the total angular momentum, so without damping the linear model is
not fully controllable: the centre scenario has rank 6 of 9 (all three momentum components are
conserved) and the corner scenario rank 8 of 9 (gravity's torque is horizontal; the vertical
momentum is conserved). :func:`lqr` then designs on the controllable subspace (an orthonormal
Krylov basis ``T``): ``Kc, Sc, Ec = control.lqr(TᵀAT, TᵀB, TᵀQT, R)`` and ``K = Kc Tᵀ``; the
uncontrollable modes are those conserved momenta (eigenvalue 0: they are constants of the motion,
not errors to regulate). With a full-rank model it is plainly ``control.lqr(A, B, Q, R)``.

From Python::

    from lavendersim import control as lc
    res = lc.design(scenario="center", Q=[...9...], R=[...3...], theta0_deg=20, axis=[1, 2, 3])
    res.K, res.poles, res.settling_time, res.peak_torque, res.peak_wheel_speed, res.plot("r.png")

From the shell: ``lavendersim lqr --scenario corner --theta0 3 --json``.
"""
from __future__ import annotations

import json
import math
import numbers
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import ArrayLike

from . import validate as V
from ._install import require
from .kernels import K as KN

if TYPE_CHECKING:  # annotations only: casadi is an optional extra, Scene/Sim load lazily
    import argparse
    import os

    import casadi

    from .scene import Scene
    from .sim import Sim

SCENARIOS = ("center", "corner")
STATE_LABELS = ("dtheta_x", "dtheta_y", "dtheta_z", "omega_x", "omega_y", "omega_z", "Omega_x", "Omega_y", "Omega_z")
INPUT_LABELS = ("u_x", "u_y", "u_z")
BODY = "cube"


# ----------------------------------------------------------------------------------------------
# model
# ----------------------------------------------------------------------------------------------


@dataclass
class CubeModel:
    """A cube of side ``size`` (m) and total mass ``mass`` (kg, wheels included and locked),
    uniform, with three body-axis reaction wheels of spin inertia ``J`` (kg·m²), motor torque
    limit ``torque_limit`` (N·m), wheel speed limit ``speed_limit`` (rad/s), cube angular damping
    ``damping`` (N·m·s/rad, the "angular_damping" effect), wheel bearing damping ``wheel_damping``
    (N·m·s/rad), gravity ``g`` (m/s², along −z world). Defaults are Cubli-like (15 cm, 1 kg;
    Cubli: 1.42 kg, wheel inertia 0.57e-3 kg·m², Maxon EC45-flat motors): J = 5.7e-4 kg·m² per
    wheel, 0.2 N·m, 400 rad/s (3800 rpm).

    Parameters
    ----------
    scenario : {"center", "corner"}
        Spherical joint at the cube's centre, or on a corner (Cubli-like balancing).
    mass : float
        Total mass, kg (wheels included).
    size : float
        Side length, m.
    J : float or array_like, shape (3,)
        Wheel spin inertias about body x, y, z, kg·m².
    torque_limit : float
        Motor torque limit, N·m.
    speed_limit : float
        Wheel speed limit, rad/s.
    damping, wheel_damping : float
        N·m·s/rad, >= 0.
    g : float
        m/s², >= 0 (along −z world).
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

    def __post_init__(self):
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
        """Gravitational acceleration, world frame, m/s² (along −z)."""
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
        """The Scene for the runtime simulator: body "cube" (COM placed at anchor + R r_b), a
        spherical joint at the origin, reaction wheels, and the declared damping/gravity.

        Parameters
        ----------
        q0 : array_like, shape (4,), optional
            Attitude (x, y, z, w); default upright.
        omega_b : array_like, shape (3,), optional
            Body rates, rad/s.
        Omega : array_like, shape (3,), optional
            Unused here (set wheel rates on the Sim).

        Returns
        -------
        Scene
        """
        import lavendersim as lv

        q0 = self.upright_q() if q0 is None else V.quaternion("q0", q0)
        p_w = np.asarray(KN.quat_rotate(q0, self.r_b), dtype=float)
        s = self.size
        scene = lv.Scene()
        scene.add_body(lv.Body.box(BODY, mass=self.mass, size=(s, s, s), p_w=p_w, q=q0, omega_b=omega_b))
        scene.add_effect("spherical_joint", body=BODY, anchor_w=[0.0, 0.0, 0.0])
        scene.add_effect("reaction_wheels", body=BODY, J=self.J.tolist(), torque_limit=self.torque_limit,
                         speed_limit=self.speed_limit, c_w=self.wheel_damping)
        if self.gravity:
            scene.add_effect("gravity", body=BODY, g_w=self.g_w)
        if self.damping > 0:
            scene.add_effect("angular_damping", body=BODY, c=self.damping)
        return scene

    def make_sim(self, q0: ArrayLike | None = None, omega_b: ArrayLike = (0, 0, 0), Omega: ArrayLike = (0, 0, 0),
                 dt: float = 1e-3, backend: str = "auto", integrator: str = "rk4") -> Sim:
        """A Sim of :meth:`scene` with wheel rates `Omega`.

        Parameters
        ----------
        q0, omega_b : optional
            As in :meth:`scene`.
        Omega : array_like, shape (3,), optional
            Wheel rates relative to the body, rad/s.
        dt : float, optional
            Step, s.
        backend, integrator : str, optional
            As in :class:`lavendersim.Sim`.

        Returns
        -------
        Sim
        """
        import lavendersim as lv

        sim = lv.Sim(self.scene(q0, omega_b), dt=dt, integrator=integrator, backend=backend)
        if np.any(np.asarray(Omega, dtype=float) != 0):
            sim.set_state(BODY, Omega=V.vector("Omega", Omega))
        return sim

    def as_dict(self) -> dict[str, Any]:
        """The fields as plain JSON-able values."""
        return {"scenario": self.scenario, "mass": self.mass, "size": self.size, "J": self.J.tolist(),
                "torque_limit": self.torque_limit, "speed_limit": self.speed_limit, "damping": self.damping,
                "wheel_damping": self.wheel_damping, "g": self.g}


# ----------------------------------------------------------------------------------------------
# attitude error coordinates
# ----------------------------------------------------------------------------------------------


def attitude_error(q: ArrayLike, q_ref: ArrayLike) -> np.ndarray:
    """dtheta = 2 vec(q_ref* ⊗ q), sign chosen so the scalar part is >= 0 (rad, body frame).

    Parameters
    ----------
    q, q_ref : array_like, shape (..., 4)
        Quaternions (x, y, z, w).

    Returns
    -------
    ndarray, shape (..., 3)
    """
    qe = np.asarray(KN.quat_mul(KN.quat_conj(np.asarray(q_ref, float)), np.asarray(q, float)), dtype=float)
    sgn = np.where(qe[..., 3:4] < 0, -1.0, 1.0)
    return 2.0 * sgn * qe[..., 0:3]


def error_angle_deg(q: ArrayLike, q_ref: ArrayLike) -> np.ndarray:
    """Rotation angle between q and q_ref, degrees in [0, 180].

    Parameters
    ----------
    q, q_ref : array_like, shape (..., 4)
        Quaternions (x, y, z, w).

    Returns
    -------
    ndarray, shape (...)
    """
    qe = np.asarray(KN.quat_mul(KN.quat_conj(np.asarray(q_ref, float)), np.asarray(q, float)), dtype=float)
    s = np.linalg.norm(qe[..., 0:3], axis=-1)
    return np.degrees(2.0 * np.arctan2(s, np.abs(qe[..., 3])))


def perturbed(q_ref: ArrayLike, dtheta: ArrayLike) -> np.ndarray:
    """q = q_ref ⊗ [dtheta/2, sqrt(1 - |dtheta/2|²)] (the inverse of attitude_error).

    Parameters
    ----------
    q_ref : array_like, shape (4,)
        Reference (x, y, z, w).
    dtheta : array_like, shape (3,)
        Error coordinates, rad, body frame, |dtheta| < 2.

    Returns
    -------
    ndarray, shape (4,)
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
    q_ref : array_like, shape (4,)
        Reference (x, y, z, w).
    axis : array_like, shape (3,)
        Non-zero body-frame axis.
    angle_deg : float
        Degrees.

    Returns
    -------
    ndarray, shape (4,)
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


@dataclass
class Linearization:
    """The cube linearized in error coordinates x = [dtheta (rad), omega_b (rad/s), Omega − Omega0 (rad/s)].

    Parameters
    ----------
    A : ndarray, shape (9, 9)
    B : ndarray, shape (9, 3)
        Input: motor torques du (N·m) about u0.
    q_ref : ndarray, shape (4,)
        Equilibrium attitude (x, y, z, w).
    Omega0 : ndarray, shape (3,)
        Equilibrium wheel rates, rad/s.
    u0 : ndarray, shape (3,)
        Equilibrium motor torques, N·m.
    rank : int
        Rank of the controllability matrix.
    basis : ndarray, shape (9, rank)
        Orthonormal basis of the controllable subspace.
    equilibrium_residual : float
        |f(0, 0)| at the equilibrium.
    state_labels, input_labels : tuple of str
    """
    A: np.ndarray
    B: np.ndarray
    q_ref: np.ndarray
    Omega0: np.ndarray
    u0: np.ndarray
    rank: int
    basis: np.ndarray = field(repr=False)   # orthonormal basis of the controllable subspace (9 × rank)
    equilibrium_residual: float = 0.0
    state_labels: tuple = STATE_LABELS
    input_labels: tuple = INPUT_LABELS

    @property
    def controllable(self) -> bool:
        """Whether the pair (A, B) is fully controllable."""
        return self.rank == self.A.shape[0]

    @property
    def uncontrollable_basis(self) -> np.ndarray:
        """Orthonormal basis U of the complement of the controllable subspace (9 × (9 − rank)):
        Uᵀx are the conserved (momentum) coordinates no wheel torque can change."""
        n = self.A.shape[0]
        if self.rank == n:
            return np.zeros((n, 0))
        P = np.eye(n) - self.basis @ self.basis.T
        Uf, s, _ = np.linalg.svd(P)
        return Uf[:, : n - self.rank]

    def target(self, x: ArrayLike) -> tuple[np.ndarray, np.ndarray]:
        """(x_ss, du_ss): the equilibrium with dtheta = 0, omega = 0 that has the same conserved
        coordinates Uᵀx as x (wheel speeds Omega_ss absorb the momentum), and the torque holding it.
        Zero when x carries no conserved momentum (e.g. starting at rest without damping).

        Parameters
        ----------
        x : array_like, shape (9,)
            Error-coordinate state.

        Returns
        -------
        x_ss : ndarray, shape (9,)
        du_ss : ndarray, shape (3,)
        """
        n = self.A.shape[0]
        x_ss, du = np.zeros(n), np.zeros(self.B.shape[1])
        if self.rank == n:
            return x_ss, du
        U = self.uncontrollable_basis
        x_ss[6:9] = np.linalg.lstsq(U[6:9, :].T, U.T @ x, rcond=None)[0]
        r = self.A @ x_ss
        if np.any(r != 0):
            du = np.linalg.lstsq(self.B, -r, rcond=None)[0]
        return x_ss, du

    def feedback(self, K: ArrayLike, x: ArrayLike) -> np.ndarray:
        """u = u0 + du_ss − K (x − x_ss) (unsaturated), N·m.

        Parameters
        ----------
        K : array_like, shape (3, 9)
            Gain.
        x : array_like, shape (9,)
            Error-coordinate state.

        Returns
        -------
        ndarray, shape (3,)
        """
        x_ss, du = self.target(x)
        return self.u0 + du - np.asarray(K) @ (x - x_ss)

    def state(self, q: ArrayLike, omega_b: ArrayLike, Omega: ArrayLike) -> np.ndarray:
        """Error-coordinate state x from a simulator state.

        Parameters
        ----------
        q : array_like, shape (4,)
            Attitude (x, y, z, w).
        omega_b : array_like, shape (3,)
            Body rates, rad/s.
        Omega : array_like, shape (3,)
            Wheel rates, rad/s.

        Returns
        -------
        ndarray, shape (9,)
        """
        return np.concatenate([attitude_error(q, self.q_ref), np.asarray(omega_b, float),
                               np.asarray(Omega, float) - self.Omega0])


def casadi_rhs(model: CubeModel, q_ref: ArrayLike, Omega0: ArrayLike = (0, 0, 0)) -> tuple[casadi.Function, np.ndarray]:
    """(f, u0): the CasADi Function f(x, du) -> x_dot in error coordinates, built from kernels_casadi,
    and the equilibrium motor torque u0 = c_w Omega0 (3,), N·m.

    Parameters
    ----------
    model : CubeModel
        The cube.
    q_ref : array_like, shape (4,)
        Equilibrium attitude.
    Omega0 : array_like, shape (3,), optional
        Equilibrium wheel rates, rad/s.

    Returns
    -------
    f : casadi.Function
    u0 : ndarray, shape (3,)
    """
    ca = require("casadi", "control", "the CasADi linearization")
    from .generated import kernels_casadi as KC

    q_ref = ca.DM(np.asarray(q_ref, float))
    Om0 = ca.DM(np.asarray(Omega0, float))
    u0 = model.wheel_damping * Om0
    x = ca.SX.sym("x", 9)
    du = ca.SX.sym("du", 3)
    half = x[0:3] / 2
    q = KC.quat_mul(q_ref, ca.vertcat(half, ca.sqrt(1 - ca.dot(half, half))))
    w, Om, u = x[3:6], Om0 + x[6:9], u0 + du
    s = model.size
    Ic = KC.inertia_box(model.mass, s, s, s)
    Ic_flat = ca.vertcat(Ic[0], 0, 0, 0, Ic[1], 0, 0, 0, Ic[2])
    r_b = ca.DM(model.r_b)
    I_p = KC.parallel_axis(Ic_flat, model.mass, -r_b)
    F_w = KC.effect_gravity(model.mass, ca.DM(model.g_w)) if model.gravity else ca.DM.zeros(3)
    tau_w = KC.effect_angular_damping(q, w, model.damping)
    q_dot, w_dot, Om_dot = KC.wheel_body_rhs(q, w, Om, I_p, ca.DM(model.J), r_b, F_w, tau_w, u, model.wheel_damping)
    # d(dtheta)/dt = (∂e/∂q) q_dot with e(q) = 2 vec(q_ref* ⊗ q) (linear in q: a constant Jacobian)
    qs = ca.SX.sym("q", 4)
    e = 2 * KC.quat_mul(KC.quat_conj(q_ref), qs)[0:3]
    Je = ca.jacobian(e, qs)
    dth_dot = ca.mtimes(ca.substitute(Je, qs, q), q_dot)
    f = ca.vertcat(dth_dot, w_dot, Om_dot)
    return ca.Function("wheel_cube_error_rhs", [x, du], [f], ["x", "du"], ["x_dot"]), np.asarray(u0, float).ravel()


def controllable_basis(A: np.ndarray, B: np.ndarray, tol: float = 1e-9) -> np.ndarray:
    """Orthonormal basis of the controllable subspace span[B, AB, A²B, …] (Krylov with
    re-orthogonalization; A and B scaled to unit norm, singular values below tol dropped).

    Parameters
    ----------
    A : ndarray, shape (n, n)
    B : ndarray, shape (n, m)
    tol : float, optional

    Returns
    -------
    ndarray, shape (n, rank)
    """
    n = A.shape[0]
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


def linearize(model: CubeModel, q_ref: ArrayLike | None = None, Omega0: ArrayLike = (0, 0, 0),
              tol: float = 1e-9) -> Linearization:
    """A = ∂f/∂x, B = ∂f/∂u at (q_ref, omega = 0, Omega = Omega0, u = c_w Omega0), by CasADi AD.

    Parameters
    ----------
    model : CubeModel
        The cube.
    q_ref : array_like, shape (4,), optional
        Equilibrium attitude (default upright).
    Omega0 : array_like, shape (3,), optional
        Equilibrium wheel rates, rad/s.
    tol : float, optional
        Rank tolerance (see :func:`controllable_basis`).

    Returns
    -------
    Linearization
    """
    ca = require("casadi", "control", "the CasADi linearization")
    q_ref = model.upright_q() if q_ref is None else V.quaternion("q_ref", q_ref)
    Omega0 = V.vector("Omega0", Omega0)
    f, u0 = casadi_rhs(model, q_ref, Omega0)
    x, du = ca.SX.sym("x", 9), ca.SX.sym("du", 3)
    fx = f(x, du)
    jac = ca.Function("wheel_cube_linearization", [x, du], [fx, ca.jacobian(fx, x), ca.jacobian(fx, du)])
    f0, A, B = (np.asarray(m, dtype=float) for m in jac(np.zeros(9), np.zeros(3)))
    res = float(np.max(np.abs(f0)))
    scale = max(1.0, float(np.max(np.abs(A))))
    if res > 1e-9 * scale:
        raise V.LavenderInputError("q_ref", "is not an equilibrium of the model (the right-hand side is not zero there: "
                                   "for the corner scenario the COM must be straight above the pivot)", f", |f| = {res:.3g}")
    basis = controllable_basis(A, B, tol)
    return Linearization(A, B, q_ref, Omega0, u0, basis.shape[1], basis, res)


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


def lqr(lin: Linearization, Q: ArrayLike, R: ArrayLike) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(K, S, E) of python-control's lqr, on the controllable subspace when rank < n (see the
    module docstring). E are the closed-loop eigenvalues of A − B K (the uncontrollable conserved
    modes included, at 0).

    Parameters
    ----------
    lin : Linearization
    Q : array_like
        State weight: a number, the diagonal (9,) or (9, 9).
    R : array_like
        Input weight: a number, the diagonal (3,) or (3, 3), positive definite.

    Returns
    -------
    K : ndarray, shape (3, 9)
        ``u = -K x``.
    S : ndarray, shape (9, 9)
    E : ndarray, shape (9,)
    """
    ct = require("control", "control", "LQR design (python-control)")
    n, m = lin.B.shape
    Q = _weight("Q", Q, n, definite=False)
    R = _weight("R", R, m, definite=True)
    if lin.controllable:
        K, S, _ = ct.lqr(lin.A, lin.B, Q, R)
    else:
        T = lin.basis
        Qc = T.T @ Q @ T
        Kc, Sc, _ = ct.lqr(T.T @ lin.A @ T, T.T @ lin.B, (Qc + Qc.T) / 2, R)
        K, S = Kc @ T.T, T @ Sc @ T.T
    K, S = np.asarray(K), np.asarray(S)
    E = np.linalg.eigvals(lin.A - lin.B @ K)
    return K, S, E[np.argsort(E.real)]


def default_weights(model: CubeModel) -> tuple[np.ndarray, np.ndarray]:
    """Bryson-style defaults: attitude 1/(2°)², rates 1/(0.5 rad/s)², wheels 1/(0.5·limit)²,
    torque 1/(0.5·limit)² (corner: attitude 1/(0.5°)²).

    Parameters
    ----------
    model : CubeModel
        The cube.

    Returns
    -------
    Q_diag : ndarray, shape (9,)
    R_diag : ndarray, shape (3,)
    """
    ang = math.radians(2.0 if model.scenario == "center" else 0.5)
    q = np.concatenate([np.full(3, 1 / ang ** 2), np.full(3, 1 / 0.5 ** 2), np.full(3, 1 / (0.5 * model.speed_limit) ** 2)])
    return q, np.full(3, 1 / (0.5 * model.torque_limit) ** 2)


# ----------------------------------------------------------------------------------------------
# closed loop in the nonlinear simulator
# ----------------------------------------------------------------------------------------------


@dataclass
class Response:
    """A closed-loop run sampled every control period.

    Parameters
    ----------
    t : ndarray, shape (T,)
        s.
    error_deg : ndarray, shape (T,)
        Attitude error, degrees.
    omega_b : ndarray, shape (T, 3)
        rad/s.
    Omega : ndarray, shape (T, 3)
        Wheel rates, rad/s.
    u_cmd, u_applied : ndarray, shape (T, 3)
        Commanded and saturated motor torques, N·m.
    q : ndarray, shape (T, 4)
        Attitude (x, y, z, w).
    """
    t: np.ndarray
    error_deg: np.ndarray
    omega_b: np.ndarray
    Omega: np.ndarray
    u_cmd: np.ndarray
    u_applied: np.ndarray
    q: np.ndarray

    def settling_time(self, threshold_deg: float) -> float:
        """First time after which the attitude error stays below threshold_deg (inf if never).

        Parameters
        ----------
        threshold_deg : float

        Returns
        -------
        float
            s.
        """
        above = np.flatnonzero(self.error_deg >= threshold_deg)
        if above.size == 0:
            return 0.0
        if above[-1] == self.t.size - 1:
            return math.inf
        return float(self.t[above[-1] + 1])


MAX_CONTROL_STEPS = 1_000_000  # closed_loop: control periods per run


def closed_loop(model: CubeModel, lin: Linearization, K: ArrayLike, q0: ArrayLike, T: float = 5.0, *,
                omega0: ArrayLike = (0, 0, 0), Omega0: ArrayLike | None = None, dt: float = 1e-3,
                control_dt: float = 2e-3, backend: str = "auto", sim: Sim | None = None) -> Response:
    """Run u = u0 − K x (clipped to ±torque_limit) with a zero-order hold of control_dt in the
    nonlinear simulator (the Sim's reaction_wheels effect saturates again, speed limit included).
    `sim` may be given (any object with the Sim's wheel API) instead of building one.

    Parameters
    ----------
    model : CubeModel
        The cube.
    lin : Linearization
    K : array_like, shape (3, 9)
    q0 : array_like, shape (4,)
        Initial attitude.
    T : float, optional
        Duration, s.
    omega0, Omega0 : array_like, shape (3,), optional
        Initial body and wheel rates, rad/s.
    dt, control_dt : float, optional
        Simulator step and control period, s.
    backend : str, optional
    sim : Sim, optional

    Returns
    -------
    Response
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
    n = int(round(T / control_dt))
    Omega0 = lin.Omega0 if Omega0 is None else V.vector("Omega0", Omega0)
    if sim is None:
        sim = model.make_sim(q0, omega0, Omega0, dt=dt, backend=backend)
    K = np.asarray(K, float)
    t = np.empty(n + 1)
    qs, ws, Oms = np.empty((n + 1, 4)), np.empty((n + 1, 3)), np.empty((n + 1, 3))
    ucmd, uapp = np.zeros((n + 1, 3)), np.zeros((n + 1, 3))
    lim = model.torque_limit
    for k in range(n + 1):
        st = sim.state(BODY)
        q, w, Om = st.q, st.omega_b, sim.wheel_rates(BODY)
        t[k], qs[k], ws[k], Oms[k] = sim.t, q, w, Om
        if k == n:
            break
        u = np.clip(lin.feedback(K, lin.state(q, w, Om)), -lim, lim)
        sim.set_wheel_command(BODY, u)
        sim.run(sub)
        ucmd[k], uapp[k] = u, sim.wheel_command_applied(BODY)
    ucmd[n], uapp[n] = ucmd[n - 1], uapp[n - 1]
    return Response(t, error_angle_deg(qs, lin.q_ref), ws, Oms, ucmd, uapp, qs)


# ----------------------------------------------------------------------------------------------
# design(): the whole workflow, as used by `lavendersim lqr`
# ----------------------------------------------------------------------------------------------


@dataclass
class DesignResult:
    """What :func:`design` returns: the model, linearization, weights, gain and closed-loop run.

    Parameters
    ----------
    model : CubeModel
    lin : Linearization
    Q, R : ndarray
        Weights used.
    K, S : ndarray
        Gain (3, 9) and Riccati solution (9, 9).
    poles : ndarray
        Closed-loop eigenvalues.
    response : Response
    theta0_deg : float
    axis : ndarray, shape (3,)
    threshold_deg : float
    backend : str
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
        """Settling time to threshold_deg, s (inf if never)."""
        return self.response.settling_time(self.threshold_deg)

    @property
    def peak_torque(self) -> float:
        """max |applied motor torque| over wheels and time, N·m."""
        return float(np.max(np.abs(self.response.u_applied)))

    @property
    def peak_wheel_speed(self) -> float:
        """max |Omega| over wheels and time, rad/s."""
        return float(np.max(np.abs(self.response.Omega)))

    @property
    def final_error_deg(self) -> float:
        """Attitude error at the end, degrees."""
        return float(self.response.error_deg[-1])

    def figures(self) -> dict[str, Any]:
        """The design's figures as a JSON-able dict."""
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
        """:meth:`figures` as JSON text (an infinite settling time as null)."""
        fig = self.figures()
        fig["settling_time"] = fig["settling_time"] if math.isfinite(fig["settling_time"]) else None
        return json.dumps(fig, indent=2)

    def plot(self, path: str | os.PathLike[str]) -> None:
        """Write the response plot (PNG).

        Parameters
        ----------
        path : str or os.PathLike
        """
        from .labs.common import new_figure

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
    """Linearize, design the LQR gain, run the closed loop from an initial error of theta0_deg
    about the body axis `axis` (defaults: 20° about (1, 2, 3) centre; 3° about (1, 1, −2), a pure
    tilt, corner), return a DesignResult.
    model_params go to CubeModel (mass, size, J, torque_limit, speed_limit, damping, …).

    Parameters
    ----------
    scenario : {"center", "corner"}, optional
    Q, R : array_like, optional
        Weights (default :func:`default_weights`).
    theta0_deg : float, optional
        Initial error, degrees.
    axis : array_like, shape (3,), optional
        Body-frame axis of the initial error.
    T : float, optional
        Duration, s.
    threshold_deg : float, optional
        Settling threshold, degrees.
    backend : str, optional
    dt, control_dt : float, optional
        s.
    model : CubeModel, optional
    sim : Sim, optional
    **model_params
        CubeModel fields.

    Returns
    -------
    DesignResult

    Examples
    --------
    >>> from lavendersim.control import design   # doctest: +SKIP
    >>> r = design("center")                      # doctest: +SKIP
    >>> r.settling_time < 1.0                     # doctest: +SKIP
    True
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
        The cube.
    lin : Linearization
    backend : str, optional
    h : float, optional
        Perturbation.
    dt : float, optional
        s.
    make_sim : callable, optional

    Returns
    -------
    A : ndarray, shape (9, 9)
    B : ndarray, shape (9, 3)
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


def linearization_residual(lin: Linearization, A_fd: ArrayLike, B_fd: ArrayLike) -> dict[str, float]:
    """max |A − A_fd|, max |B − B_fd| (absolute) and the same relative to max(1, max |entry|).

    Parameters
    ----------
    lin : Linearization
    A_fd, B_fd : array_like
        Finite-difference A and B.

    Returns
    -------
    dict
        ``A_abs``, ``B_abs``, ``A_rel``, ``B_rel``.
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
    """Add the ``lqr`` subcommand to the CLI.

    Parameters
    ----------
    subparsers : argparse._SubParsersAction
    """
    p = subparsers.add_parser("lqr", help="design an LQR wheel controller for the reaction-wheel cube and run it in the simulator",
                              description=__doc__.split("\n\n")[0] + "\n\nQ and R: one number (times identity), the "
                              "diagonal (9 / 3 numbers, comma-separated) or the full matrix row-major (81 / 9 numbers). "
                              "State order: " + ", ".join(STATE_LABELS) + ".")
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
    p.set_defaults(fn=_cli)


def _cli(args) -> int:
    import sys

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
                          wheel_damping=args.wheel_damping)
        if axis is None:
            axis = DEFAULT_AXIS if model.scenario == "center" else CORNER_AXIS
        res = design(model=model, Q=_matrix_arg("Q", args.Q, 9), R=_matrix_arg("R", args.R, 3), theta0_deg=args.theta0,
                     axis=axis, T=args.T, threshold_deg=args.threshold, backend=args.backend)
    except V.LavenderInputError as exc:
        print(f"lavendersim lqr: invalid parameter: {exc}", file=sys.stderr)
        return 2
    if args.plot:
        res.plot(args.plot)
    if args.json:
        print(res.to_json())
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
    if args.plot:
        print(f"wrote {args.plot}")
    return 0
