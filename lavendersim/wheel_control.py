"""One reaction-wheel control stack for any Scene: design at the controller's rate, fly it sampled.

Public through :mod:`lavendersim.control` (``control.Sensors``, ``control.design``,
``control.Controller``, ``control.closed_loop``, ``control.Response``, ``control.monte_carlo``).

The plant is any :class:`lavendersim.Scene` whose body carries ``reaction_wheels`` (any name, 1 to 4
wheels on any unit axes ``axes_b``, free or on a spherical joint, any other declared effects). Its
model is :func:`lavendersim.control.linearize` (CasADi, from the printed kernels) at rest at ``q_ref``
with wheel rates ``Omega_ref``; the controlled body's error state is ``x = [dtheta (3, rad, body frame),
omega_b (3, rad/s), Omega − Omega_ref (N, rad/s)]`` with ``q = q_ref ⊗ [dtheta/2, sqrt(1 − |dtheta/2|²)]``.

Design (:func:`design`) — discrete LQR on the zero-order-hold discretization at the controller's
period ``Ts``:

* a computation delay ``0 <= delay <= Ts`` (the command computed from the sample at t_k acts from
  t_k + delay) enters the model as the delayed-input ZOH discretization
  ``x[k+1] = Φ x[k] + Γ1 u[k−1] + Γ0 u[k]`` with ``Γ0 = ∫₀^{Ts−d} e^{As} ds B``,
  ``Γ1 = e^{A(Ts−d)} ∫₀^{d} e^{As} ds B``; the state is augmented with the previous command;
* a first-order actuator lag (time constant ``actuator_lag``: ``ȧ = (u − a)/τ``, the wheels receive
  ``a``) augments the continuous model with ``a``; the controller propagates its own estimate of ``a``;
* the command is allocated: the LQR's inputs are ``v = [τ (r), ν (N − r)]`` — a torque demand on the
  wheels' range (r = rank of the axes; body torque −A_b u) and null-space components — and
  ``u = u_0 + M v`` with ``M = [pinv(A_b) (· U_r), V_null]``: the minimum-norm allocation
  plus the null space (with ``R_v = Mᵀ R M`` the design is the LQR on u, exactly). ``null_bias``
  (rad/s) moves the operating point to ``Omega_ref = null_bias · n`` (n the first null-space vector):
  the null-space wheel speed is regulated to it, which the body never feels (``A_b n = 0``);
* internal wheel torques conserve angular momentum: the design is made on the controllable subspace
  (:func:`lavendersim.control.dlqr`) and the command regulates to the equilibrium that keeps the
  measured state's conserved coordinates (``Linearization.target_map``), folded into the gains.

The controller's step is a set of CasADi SX expressions — the attitude error chart (the printed
``quat_error_chart`` kernel), ``−K x``, the allocation ``M``, a torque saturation with ``fmin``/``fmax``
and the motor's torque–speed line at the measured wheel rates (the printed ``wheels4_motor``) — wrapped in
one ``casadi.Function`` (:attr:`Controller.function`), which Python
evaluates; the same expressions print as C.

The loop (:func:`closed_loop`) samples the Sim every ``Ts`` (measurement models from
:class:`Sensors`, seeded), computes the command, holds it (ZOH) from ``t_k + delay``, passes it
through the first-order lag (integrated exactly per sub-step) and lets the Sim's
``reaction_wheels`` saturate it (torque–speed line). :class:`Response` carries the samples and the
figures: settling time, peak torque and wheel speed per wheel, relative drift of the total angular
momentum, final error.
"""
from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field, replace
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import ArrayLike

from . import validate as V
from ._install import require
from .generated import layout as LY
from .kernels import K as KN

if TYPE_CHECKING:
    from .scene import Scene
    from .sim import Sim

MAX_SAMPLES = 1_000_000      # closed_loop: controller periods per run
MAX_SUBSTEPS = 10_000        # closed_loop: Sim steps per controller period
DEFAULT_SUBSTEPS = 10        # closed_loop: Sim steps per controller period when dt is not given
THRESHOLD_DEG = 0.1          # settling threshold, deg


# ----------------------------------------------------------------------------------------------
# the plant: a scene's wheeled body
# ----------------------------------------------------------------------------------------------


def wheeled_body(scene: Scene, body: str | None = None) -> str:
    """The name of the body whose wheels are controlled.

    Parameters
    ----------
    scene : Scene
        Any scene.
    body : str, optional
        A body name; default: the scene's only body with ``reaction_wheels``.

    Returns
    -------
    str

    Raises
    ------
    lavendersim.validate.LavenderInputError
        ``scene`` is not a Scene, ``body`` is unknown or has no wheels, or (body None) the scene has
        no wheeled body or more than one.
    """
    from .scene import Scene

    if not isinstance(scene, Scene):
        raise V.LavenderInputError("scene", "must be a lavendersim Scene", f", got {V._describe(scene)}")
    wheeled = [n for n in scene.bodies if "reaction_wheels" in scene.model_effects(n)]
    if body is None:
        if len(wheeled) != 1:
            raise V.LavenderInputError("body", "name the body to control" if wheeled else
                                       "the scene has no body with reaction_wheels",
                                       f"; wheeled bodies: {', '.join(wheeled) or 'none'}")
        return wheeled[0]
    if not isinstance(body, str) or body not in scene.bodies:
        raise V.LavenderInputError("body", f"unknown body {body!r}; bodies: {', '.join(scene.bodies)}")
    if body not in wheeled:
        raise V.LavenderInputError("body", f"body {body!r} has no reaction_wheels")
    return body


@dataclass(frozen=True)
class Wheels:
    """A body's wheel layout as declared (``scene.model_effects(body)["reaction_wheels"]``).

    Parameters
    ----------
    axes_b : ndarray (N, 3)
        Unit spin axes, body frame (rows).
    J : ndarray (N,)
        Axial inertias, kg·m².
    torque_limit, speed_limit : float
        Motor stall torque, N·m, and no-load speed, rad/s.
    c_w : float
        Bearing damping, N·m·s/rad.
    cutoff : float, optional
        0: the motor's torque–speed line; 1: the hard cut-off at speed_limit (the effect's ``cutoff``).
    """

    axes_b: np.ndarray
    J: np.ndarray
    torque_limit: float
    speed_limit: float
    c_w: float
    cutoff: float = 0.0

    @classmethod
    def of(cls, scene: Scene, body: str) -> "Wheels":
        """The layout of ``body``'s ``reaction_wheels`` in ``scene``.

        Parameters
        ----------
        scene : Scene
        body : str
            A body of ``scene`` with ``reaction_wheels``.

        Returns
        -------
        Wheels
        """
        v = scene.model_effects(body)["reaction_wheels"].values
        return cls(np.array(v["axes_b"], float).reshape(-1, 3), np.array(v["J"], float).ravel(), float(v["torque_limit"]),
                   float(v["speed_limit"]), float(v["c_w"]), float(v["cutoff"]))

    @property
    def n(self) -> int:
        """Number of wheels N."""
        return self.J.size

    @property
    def A_b(self) -> np.ndarray:
        """Axis matrix (3, N), unit columns: the wheels' total motor torque in the body frame is A_b u."""
        return self.axes_b.T


def allocation(A_b: np.ndarray) -> tuple[np.ndarray, int]:
    """The allocation M (N, N) from virtual inputs v = [τ (r), ν (N − r)] to wheel torques u = M v, and r.

    ``τ`` is a torque demand on the range of ``A_b`` (for r = 3 the body-frame vector A_b u, N·m; for
    r < 3 its components on the left singular vectors U_r): ``M[:, :r] = pinv(A_b) U_r`` (minimum
    norm, so ``A_b M[:, :r] τ = U_r τ``); ``M[:, r:]`` is an orthonormal basis of the null space
    (lavendersim.wheel_layout.null_space). M is invertible.

    Parameters
    ----------
    A_b : ndarray (3, N)
        Wheel axes as unit columns, body frame.

    Returns
    -------
    M : ndarray (N, N)
    r : int
        Rank of ``A_b``.
    """
    from .wheel_layout import null_space

    U, s, _ = np.linalg.svd(A_b)
    r = int(np.sum(s > 1e-9 * max(1.0, s.max())))
    Ur = np.eye(3) if r == 3 else U[:, :r]
    return np.hstack([np.linalg.pinv(A_b) @ Ur, null_space(A_b)]), r


# ----------------------------------------------------------------------------------------------
# sensors
# ----------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class Sensors:
    """Measurement models of the sampled loop, seeded and reproducible (numpy ``default_rng(seed)``).

    At each sample, in this order, 3 + 3 + N standard normal numbers are drawn (always, whatever
    the noise levels, so the streams do not depend on them): the star tracker's attitude error
    ``δ`` (rad, body frame): ``q_m = q ⊗ exp(δ/2)``; the gyro: ``omega_m = omega_b + gyro_bias + σ_g n``;
    the wheel tachometers: ``Omega_m = Omega + σ_w n``.

    Parameters
    ----------
    attitude_noise : float, default 0
        Star-tracker noise, rad, 1-sigma per body axis; >= 0.
    gyro_noise : float, default 0
        Gyro noise, rad/s, 1-sigma per axis; >= 0.
    gyro_bias : array_like (3,), default (0, 0, 0)
        Constant gyro bias, rad/s, body frame.
    wheel_speed_noise : float, default 0
        Wheel-speed noise, rad/s, 1-sigma per wheel; >= 0.
    seed : int, default 0
        Seed of the generator; >= 0.

    Raises
    ------
    lavendersim.validate.LavenderInputError
        A negative or non-finite noise level, a bad bias or seed (naming the field).
    """

    attitude_noise: float = 0.0
    gyro_noise: float = 0.0
    gyro_bias: tuple = (0.0, 0.0, 0.0)
    wheel_speed_noise: float = 0.0
    seed: int = 0

    def __post_init__(self):
        for f in ("attitude_noise", "gyro_noise", "wheel_speed_noise"):
            object.__setattr__(self, f, V.scalar(f, getattr(self, f), nonnegative=True))
        object.__setattr__(self, "gyro_bias", tuple(V.vector("gyro_bias", self.gyro_bias).tolist()))
        object.__setattr__(self, "seed", V.integer("seed", self.seed, minimum=0))

    def generator(self) -> np.random.Generator:
        """A fresh generator at this seed."""
        return np.random.default_rng(self.seed)

    def measure(self, rng: np.random.Generator, q: np.ndarray, omega_b: np.ndarray, Omega: np.ndarray
                ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """One sample's measurements of the true values, drawing 6 + N normals from ``rng``.

        Parameters
        ----------
        rng : numpy.random.Generator
            The loop's generator (:meth:`generator`).
        q : ndarray (4,)
            True attitude (x, y, z, w).
        omega_b : ndarray (3,)
            True body rate, rad/s, body frame.
        Omega : ndarray (N,)
            True wheel rates, rad/s.

        Returns
        -------
        q_m : ndarray (4,)
        omega_m : ndarray (3,)
        Omega_m : ndarray (N,)
        """
        z = rng.standard_normal(6 + Omega.size)
        d = self.attitude_noise * z[0:3]
        ang = float(np.linalg.norm(d))
        q_m = q if ang == 0.0 else np.asarray(KN.quat_mul(q, KN.axis_angle_to_quat(d / ang, ang)), dtype=float)
        w_m = omega_b + np.asarray(self.gyro_bias) + self.gyro_noise * z[3:6]
        return q_m, w_m, Omega + self.wheel_speed_noise * z[6:]


# ----------------------------------------------------------------------------------------------
# design
# ----------------------------------------------------------------------------------------------


def default_weights(scene: Scene, body: str | None = None, *, attitude_deg: float = 2.0, rate: float = 0.5,
                    wheel_speed_fraction: float = 0.5, torque_fraction: float = 0.5) -> tuple[np.ndarray, np.ndarray]:
    """Bryson's rule on the controlled body's error state: one over the square of the largest acceptable value.

    Attitude error ``attitude_deg`` (deg), rates ``rate`` (rad/s), wheel speeds
    ``wheel_speed_fraction · speed_limit``, wheel torques ``torque_fraction · torque_limit`` (the
    limits of the body's ``reaction_wheels``). Every other state of the scene's linearization (a
    free body's position and velocity, other bodies) gets weight 0 in :func:`design`.

    Parameters
    ----------
    scene : Scene
        The plant.
    body : str, optional
        The controlled body (default the scene's only wheeled body).
    attitude_deg, rate, wheel_speed_fraction, torque_fraction : float
        The acceptable values (deg, rad/s, fractions of the limits); > 0.

    Returns
    -------
    Q : ndarray (6 + N,)
        Diagonal of the state weight on ``[dtheta (3), omega_b (3), Omega (N)]``, 1/rad², s²/rad², s²/rad².
    R : ndarray (N,)
        Diagonal of the wheel-torque weight, 1/(N·m)².

    Raises
    ------
    lavendersim.validate.LavenderInputError
        A bad scene, body or value (naming it): a value must be a finite real number > 0 whose weight
        ``1/(value·scale)²`` stays within ``[1/WEIGHT_MAX, WEIGHT_MAX]`` (no overflow to inf, no underflow to 0).
    """
    body = wheeled_body(scene, body)
    wh = Wheels.of(scene, body)
    attitude_deg = V.positive("attitude_deg", attitude_deg)
    rate = V.positive("rate", rate)
    fs, ft = V.positive("wheel_speed_fraction", wheel_speed_fraction), V.positive("torque_fraction", torque_fraction)
    from .lqr import WEIGHT_MAX

    def bryson(name: str, value: float, scale: float) -> float:
        x = value * scale
        x2 = x * x                  # (no OverflowError: inf; correctly rounded like x ** 2)
        w = math.inf if x2 == 0.0 else 1.0 / x2
        if not (1.0 / WEIGHT_MAX <= w <= WEIGHT_MAX):   # 1/x² overflowed, underflowed or left the weights' range
            raise V.LavenderInputError(name, f"its Bryson weight 1/(value·scale)² must be within [{1 / WEIGHT_MAX:g}, "
                                       f"{WEIGHT_MAX:g}]", f", got {value!r} (scale {scale:g}): weight {w:.3g}")
        return w

    Q = np.concatenate([np.full(3, bryson("attitude_deg", attitude_deg, math.pi / 180)), np.full(3, bryson("rate", rate, 1.0)),
                        np.full(wh.n, bryson("wheel_speed_fraction", fs, wh.speed_limit))])
    return Q, np.full(wh.n, bryson("torque_fraction", ft, wh.torque_limit))


def _delayed_zoh(A: np.ndarray, B: np.ndarray, Ts: float, d: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(Φ, Γ0, Γ1) of x[k+1] = Φ x[k] + Γ1 u[k−1] + Γ0 u[k], u[k] acting from t_k + d (0 <= d <= Ts)."""
    from scipy.linalg import expm

    n, m = B.shape

    def phi_gamma(t):
        E = expm(np.block([[A, B], [np.zeros((m, n + m))]]) * t)
        return E[:n, :n], E[:n, n:]

    Phi, _ = phi_gamma(Ts)
    P0, G0 = phi_gamma(Ts - d)
    _, Gd = phi_gamma(d)
    return Phi, G0, P0 @ Gd


@dataclass
class Controller:
    """A designed sampled wheel controller (see :func:`design`): gains, allocation, limits, its model.

    Its step is :attr:`function`, a ``casadi.Function`` ``step(q (4), omega_b (3), Omega (N), q_ref (4),
    z (nz)) -> (u (N), z_next (nz))`` built from SX expressions; :meth:`command` evaluates it and
    keeps the memory ``z`` (the actuator-lag estimate ``a`` (N) when ``actuator_lag > 0``, then the
    previous command (N) when ``delay > 0``).

    Parameters
    ----------
    body : str
        The controlled body.
    Ts, delay, actuator_lag : float
        Controller period, computation delay and the designed-for actuator time constant, s.
    q_ref : ndarray (4,)
        Design attitude (x, y, z, w): the operating point and the default reference.
    Omega_ref : ndarray (N,)
        Operating wheel rates, rad/s (the null-space bias).
    u0 : ndarray (N,)
        Operating wheel torques, N·m (``c_w Omega_ref``).
    K : ndarray (N, nd)
        The discrete LQR gain on the design state (x, then a, then the previous command), wheel torques.
    L : ndarray (N, 6 + N)
        The gain on the measured error x_c = [dtheta, omega_b, Omega − Omega_ref] actually applied (the
        conserved-momentum target folded in): u = u0 − L x_c − L_z z.
    L_z : ndarray (N, nz)
        The gain on the memory z.
    Z : ndarray (nz, nz + N)
        The memory update ``z_next = Z [z; u]`` (the lag estimate propagated exactly; the previous command).
    M : ndarray (N, N)
        Allocation (:func:`allocation`): u − u0 = M v.
    rank_axes : int
        Rank of the wheel axes.
    wheels : Wheels
        Limits and axes.
    lin : Linearization
        The continuous model (the scene's, inputs ``BODY.u``).
    sys_d : tuple of ndarray
        (Ad, Bd) of the design model (augmented with lag and delay).
    rank : int
        Controllable-subspace dimension of the design model.
    poles : ndarray
        Closed-loop eigenvalues of Ad − Bd K on the controllable subspace (discrete; all inside the
        unit circle for a stabilizing design).
    Q, R : ndarray
        The weights used (design state, wheel torques).
    """

    body: str
    Ts: float
    delay: float
    actuator_lag: float
    q_ref: np.ndarray
    Omega_ref: np.ndarray
    u0: np.ndarray
    K: np.ndarray
    L: np.ndarray
    L_z: np.ndarray
    Z: np.ndarray
    M: np.ndarray
    rank_axes: int
    wheels: Wheels
    lin: Any
    sys_d: tuple
    rank: int
    poles: np.ndarray
    Q: np.ndarray
    R: np.ndarray
    z: np.ndarray = field(init=False, repr=False)
    _fn: Any = field(default=None, init=False, repr=False)

    def __post_init__(self):
        self.reset()

    @property
    def n(self) -> int:
        """Number of wheels N."""
        return self.wheels.n

    @property
    def nz(self) -> int:
        """Size of the controller's memory z."""
        return self.Z.shape[0]

    @property
    def z0(self) -> np.ndarray:
        """The memory at rest (nz,): the lag estimate and the previous command at u0."""
        return np.tile(self.u0, self.nz // max(self.n, 1)) if self.nz else np.zeros(0)

    def _z0(self) -> np.ndarray:
        return self.z0

    def reset(self) -> None:
        """Clear the memory z (lag estimate and previous command at the operating torque u0)."""
        self.z = self._z0()

    @property
    def function(self) -> Any:
        """``casadi.Function("lv_wheel_controller", [q, omega_b, Omega, q_ref, z], [u, z_next])``."""
        if self._fn is None:
            self._fn = self._build()
        return self._fn

    def _build(self) -> Any:
        ca = require("casadi", "control", "the controller's expressions")
        from .generated import kernels_casadi as KC

        n = self.n
        q, w, Om, qr = ca.SX.sym("q", 4), ca.SX.sym("omega_b", 3), ca.SX.sym("Omega", n), ca.SX.sym("q_ref", 4)
        z = ca.SX.sym("z", self.nz)
        dtheta = KC.quat_error_chart(q, qr)      # the printed chart: 2 sgn(e_w) e_v, e = q_ref* ⊗ q
        x = ca.vertcat(dtheta, w, Om - ca.DM(self.Omega_ref))
        Minv = np.linalg.inv(self.M)
        z0 = ca.DM(self._z0())
        v = -(ca.mtimes(ca.DM(Minv @ self.L), x) + (ca.mtimes(ca.DM(Minv @ self.L_z), z - z0) if self.nz else 0))
        u = ca.DM(self.u0) + ca.mtimes(ca.DM(self.M), v)
        lim = self.wheels.torque_limit
        u = ca.fmin(ca.fmax(u, -lim), lim)
        # the motor line at the measured wheel rates: the printed WHEELS_MAX-wheel motor kernel, the unused slots
        # padded at rest (proved at derive time to change nothing); z then tracks the torque the motors can give
        pad = ca.DM.zeros(LY.WHEELS_MAX - n, 1)
        motor = getattr(KC, f"wheels{LY.WHEELS_MAX}_motor")
        u = motor(ca.vertcat(u, pad), ca.vertcat(Om, pad), lim, self.wheels.speed_limit, self.wheels.cutoff)[0:n]
        zn = ca.mtimes(ca.DM(self.Z), ca.vertcat(z, u)) if self.nz else ca.SX(0, 1)
        return ca.Function("lv_wheel_controller", [q, w, Om, qr, z], [u, zn],
                           ["q", "omega_b", "Omega", "q_ref", "z"], ["u", "z_next"])

    def command(self, meas_q: ArrayLike, meas_omega_b: ArrayLike, meas_Omega: ArrayLike, q_ref: ArrayLike | None = None
                ) -> np.ndarray:
        """The wheel torques (N,) for one sample (torque-saturated and on the motor line), advancing the memory z.

        Parameters
        ----------
        meas_q : array_like (4,)
            Measured attitude, body to world, (x, y, z, w), unit.
        meas_omega_b : array_like (3,)
            Measured body rate, body frame, rad/s.
        meas_Omega : array_like (N,)
            Measured wheel rates relative to the body, rad/s.
        q_ref : array_like (4,), optional
            Reference attitude (default: the design's ``q_ref``).

        Returns
        -------
        ndarray (N,)
            Wheel motor torques, N·m, within ±torque_limit.

        Raises
        ------
        LavenderInputError
            A measurement or the reference of the wrong size or not finite (fmin/fmax would turn a NaN into
            a full-scale torque); z is left as it was.
        """
        qr = self.q_ref if q_ref is None else q_ref
        for field, value, n in (("meas_q", meas_q, 4), ("meas_omega_b", meas_omega_b, 3), ("meas_Omega", meas_Omega, self.n),
                                ("q_ref", qr, 4)):
            V.vector(field, value, n)   # shape and finiteness, named
        u, zn = self.function(meas_q, meas_omega_b, meas_Omega, qr, self.z)
        self.z = np.asarray(zn, float).ravel()
        return np.asarray(u, float).ravel()

    def figures(self) -> dict:
        """The design as plain values: period, delay, lag, rank, poles (real, imag, max |z|), K, L, allocation.

        Returns
        -------
        dict
        """
        p = self.poles
        return {"body": self.body, "period": self.Ts, "delay": self.delay, "actuator_lag": self.actuator_lag,
                "wheels": self.n, "axes_rank": self.rank_axes, "controllability_rank": self.rank,
                "n_states": int(self.sys_d[0].shape[0]), "poles_real": p.real.tolist(), "poles_imag": p.imag.tolist(),
                "max_pole_modulus": float(np.max(np.abs(p), initial=0.0)), "K": self.K.tolist(),
                "L": self.L.tolist(), "allocation": self.M.tolist(), "Omega_ref": self.Omega_ref.tolist(),
                "q_ref": self.q_ref.tolist()}

    def __getstate__(self):
        # to a worker process: the gains and limits; the casadi Function is rebuilt from them there, and the
        # Linearization (a python-control StateSpace holds a lambda: not picklable) stays behind (lin = None)
        d = dict(self.__dict__)
        d["_fn"], d["lin"] = None, None
        return d


def _operating_point(scene: Scene, body: str, wh: Wheels, q_ref: np.ndarray, null_bias: float
                     ) -> tuple[Any, np.ndarray, np.ndarray, int]:
    """(continuous Linearization at rest at q_ref with Omega_ref, Omega_ref, M, rank of the axes)."""
    require("control", "control", "the StateSpace linearization")
    require("casadi", "control", "the CasADi linearization")
    from ._linearize import linearize_scene   # needs python-control and CasADi: imported on first design

    M, r = allocation(wh.A_b)
    n = wh.n
    Om_ref = np.zeros(n)
    if null_bias != 0.0:
        if r == n:
            raise V.LavenderInputError("null_bias", f"needs more wheels than the rank of their axes ({n} wheels, rank {r})",
                                       f", got {null_bias!r}")
        Om_ref = null_bias * M[:, r]
        if np.abs(Om_ref).max() >= wh.speed_limit:
            raise V.LavenderInputError("null_bias", "the null-space wheel-speed target must stay below speed_limit",
                                       f", got max |Omega_ref| = {np.abs(Om_ref).max():.4g} rad/s")
    u0 = wh.c_w * Om_ref
    lin = linearize_scene(scene, {body: {"q": q_ref, "omega_b": np.zeros(3), "Omega": Om_ref}}, {f"{body}.u": u0},
                          inputs=[f"{body}.u"], outputs=None, dt=None, name=f"{body}_wheels")
    if lin.equilibrium_residual > 1e-9 * max(1.0, float(np.max(np.abs(lin.A)))):
        raise V.LavenderInputError("q_ref", "is not an equilibrium of the scene (the right-hand side is not zero at rest "
                                   "there: a body under gravity on a joint must have its COM straight above the pivot)",
                                   f", |f| = {lin.equilibrium_residual:.3g}")
    return lin, Om_ref, M, r


def _augment(A: np.ndarray, B: np.ndarray, Ts: float, delay: float, lag: float
             ) -> tuple[np.ndarray, np.ndarray, int]:
    """(Ad, Bd, nx) of the design model: [x (n), a (N if lag), u_prev (N if delay)], ZOH with the delay."""
    n, m = B.shape
    if lag > 0:
        A = np.block([[A, B], [np.zeros((m, n)), -np.eye(m) / lag]])
        B = np.vstack([np.zeros((n, m)), np.eye(m) / lag])
    nx = A.shape[0]
    Phi, G0, G1 = _delayed_zoh(A, B, Ts, delay)
    if delay == 0.0:
        return Phi, G0, nx
    Ad = np.block([[Phi, G1], [np.zeros((m, nx + m))]])
    Bd = np.vstack([G0, np.eye(m)])
    return Ad, Bd, nx


def design(scene: Scene, body: str | None = None, *, period: float, delay: float = 0.0, Q: ArrayLike | None = None,
           R: ArrayLike | None = None, q_ref: ArrayLike = (0, 0, 0, 1), null_bias: float = 0.0,
           actuator_lag: float = 0.0, weights: dict | None = None) -> Controller:
    """Design a sampled LQR wheel controller for a scene's wheeled body at the controller's rate.

    See the module docstring: the continuous linearization at rest at ``q_ref`` (wheel rates
    ``Omega_ref``: the null-space bias), augmented with the actuator lag, discretized with a
    zero-order hold and the computation delay, then ``dlqr`` on the controllable subspace with the
    inputs in allocation coordinates.

    Parameters
    ----------
    scene : Scene
        The plant: a body with ``reaction_wheels`` (1 to 4 wheels, any axes), free or jointed, and any
        other effects (gravity on a jointed body: ``q_ref`` must be its upright equilibrium).
    body : str, optional
        The controlled body (default the scene's only wheeled body).
    period : float
        Controller period Ts, s; > 0.
    delay : float, default 0
        Computation delay, s; 0 <= delay <= period.
    Q : array_like, optional
        State weight on the body's error ``[dtheta (3), omega_b (3), Omega (N)]``: a scalar, a
        diagonal (6 + N,) or a matrix; symmetric PSD. Default :func:`default_weights` (``weights``).
    R : array_like, optional
        Wheel-torque weight: scalar, (N,) or (N, N), 1/(N·m)²; symmetric PD. Default
        :func:`default_weights`.
    q_ref : array_like (4,), default identity
        Design attitude (x, y, z, w), body to world.
    null_bias : float, default 0
        Null-space wheel-speed target, rad/s (needs more wheels than the rank of their axes).
    actuator_lag : float, default 0
        First-order actuator time constant modelled in the design, s; >= 0.
    weights : dict, optional
        Keyword arguments of :func:`default_weights` (``attitude_deg``, ``rate``, ...).

    Returns
    -------
    Controller

    Raises
    ------
    lavendersim._install.MissingExtraError
        python-control or CasADi (the ``control`` extra) is not installed.
    lavendersim.validate.LavenderInputError
        A bad argument, naming it (period, delay, Q, R, q_ref, null_bias, actuator_lag, body, scene),
        or ``q_ref`` is not an equilibrium.
    lavendersim.control.DesignError
        (a LavenderInputError, field ``scene``) The design model has a mode no wheel reaches that grows on
        its own (e.g. a tilt under gravity about an axis no wheel torque has a component on), naming its
        eigenvalue (per sample, and the continuous rate) and its states; marginal ones (conserved momenta,
        a free body's position, an unactuated axis of a free body) are designed around as before.
    """
    from . import lqr as lc

    body = wheeled_body(scene, body)
    Ts = V.positive("period", period)
    delay = V.scalar("delay", delay, nonnegative=True)
    if delay > Ts:
        raise V.LavenderInputError("delay", f"must be at most the period {Ts:g} s", f", got {delay!r}")
    lag = V.scalar("actuator_lag", actuator_lag, nonnegative=True)
    q_ref = V.quaternion("q_ref", q_ref)
    null_bias = V.scalar("null_bias", null_bias)
    known = ("attitude_deg", "rate", "wheel_speed_fraction", "torque_fraction")
    if weights is not None and not isinstance(weights, dict):
        raise V.LavenderInputError("weights", "must be a dict of default_weights keywords", f", got {V._describe(weights)}")
    bad = sorted(set(weights or {}) - set(known), key=str)
    if bad:
        raise V.LavenderInputError("weights", f"unknown key {bad[0]!r}; known: {', '.join(known)}")
    wh = Wheels.of(scene, body)
    lin, Om_ref, M, r = _operating_point(scene, body, wh, q_ref, null_bias)
    ref = next(b for b in lin.bodies if b.name == body)
    idx = np.r_[np.arange(ref.index("dtheta").start, ref.index("dtheta").stop),
                np.arange(ref.index("omega").start, ref.index("omega").stop),
                np.arange(ref.index("Omega").start, ref.index("Omega").stop)]
    n, m = lin.nstates, lin.ninputs
    Qd, Rd = default_weights(scene, body, **(weights or {}))
    Qx = np.zeros((n, n))
    Qx[np.ix_(idx, idx)] = lc._weight("Q", Qd if Q is None else Q, idx.size, definite=False)
    Ru = lc._weight("R", Rd if R is None else R, m, definite=True)
    Ad, Bd, nx = _augment(np.asarray(lin.A), np.asarray(lin.B), Ts, delay, lag)
    nd = Ad.shape[0]
    Qa = np.zeros((nd, nd))
    Qa[:n, :n] = Qx
    labels = list(lin.state_labels) + [f"{body}_lag_a_{i + 1}" for i in range(m) if lag > 0] \
        + [f"{body}_u_prev_{i + 1}" for i in range(m) if delay > 0]
    res = lc._design((Ad, Bd @ M), (Qa, M.T @ Ru @ M), True, labels=labels, field="scene", period=Ts)
    Kv = np.asarray(res.K)
    K = M @ Kv
    T = lc.controllable_basis(Ad, Bd, discrete=True)
    poles = np.linalg.eigvals(T.T @ (Ad - Bd @ K) @ T)
    poles = poles[np.argsort(-np.abs(poles))]
    L, Lz, Z = _fold(lin, K, idx, n, m, nx, lag, delay, Ts)
    return Controller(body, Ts, delay, lag, q_ref, Om_ref, wh.c_w * Om_ref, K, L, Lz, Z, M, r, wh, lin, (Ad, Bd),
                      int(T.shape[1]), poles, Qa, Ru)


def _fold(lin: Any, K: np.ndarray, idx: np.ndarray, n: int, m: int, nx: int, lag: float, delay: float, Ts: float
          ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(L, L_z, Z): u − u0 = −L x_c − L_z (z − z0) with the conserved-momentum target folded in, and the
    memory update z_next = Z [z; u] (lag estimate propagated exactly; the previous command)."""
    P, G = lin.target_map()                 # x_ss = P x, du_ss = G x (linear in x)
    I = np.eye(n)
    Kx = K[:, :n]
    gain_x = Kx @ (I - P) - G               # u − u0 = −gain_x x − K_a (a − a_ss) − K_p (u_prev − u_ss) ...
    blocks: list[np.ndarray] = []
    off = n
    if lag > 0:
        Ka = K[:, off:off + m]
        gain_x = gain_x - Ka @ G            # a_ss − u0 = G x
        blocks.append(Ka)
        off += m
    if delay > 0:
        Kp = K[:, off:off + m]
        gain_x = gain_x - Kp @ G            # u_prev_ss − u0 = G x
        blocks.append(Kp)
    L = gain_x[:, idx]
    Lz = np.hstack(blocks) if blocks else np.zeros((m, 0))
    nz = Lz.shape[1]
    Z = np.zeros((nz, nz + m))
    if lag > 0:   # a[k+1] = e^{-Ts/τ} a + (the a-rows of the delayed ZOH of ȧ = (u − a)/τ) [u_prev; u]
        _, g0, g1 = _delayed_zoh(-np.eye(m) / lag, np.eye(m) / lag, Ts, delay)
        Z[:m, :m] = math.exp(-Ts / lag) * np.eye(m)
        if delay > 0:
            Z[:m, m:2 * m] = g1
        Z[:m, nz:] = g0
    if delay > 0:   # the new previous command is this command
        Z[nz - m:, nz:] = np.eye(m)
    return L, Lz, Z


# ----------------------------------------------------------------------------------------------
# the sampled closed loop
# ----------------------------------------------------------------------------------------------


@dataclass
class Response:
    """A sampled closed-loop run (one row per controller sample, t_0 = 0 … t_K = T) and its figures.

    Parameters
    ----------
    t : ndarray (K+1,)
        Sample times, s.
    q : ndarray (K+1, 4)
        True attitude, body to world, (x, y, z, w).
    omega_b : ndarray (K+1, 3)
        True body rate, body frame, rad/s.
    Omega : ndarray (K+1, N)
        True wheel rates relative to the body, rad/s.
    q_meas, omega_meas, Omega_meas : ndarray
        The measured values the controller saw (same shapes).
    commands : ndarray (K+1, N)
        Command computed at each sample, N·m (the last row repeats the one before: no command is
        computed at T).
    applied : ndarray (K+1, N)
        Torque the motors applied over the first Sim step after each new command took effect, N·m
        (after lag and the wheels' torque–speed saturation; the last row repeats).
    q_ref : ndarray (4,)
        Reference attitude.
    error_deg : ndarray (K+1,)
        True attitude error angle to q_ref, deg.
    L_w : ndarray (K+1, 3)
        Total angular momentum of the body and its wheels, world frame, kg·m²/s.
    L_wheels_w : ndarray (K+1, 3)
        The wheels' share of it, world frame, kg·m²/s.
    peak_torque : ndarray (N,)
        max |applied torque| per wheel over the first and the last Sim step of every hold (every step with
        an actuator lag), N·m.
    peak_wheel_speed : ndarray (N,)
        max |Omega| per wheel over the samples, rad/s.
    torque_limit, speed_limit : float
        The wheels' limits.
    threshold_deg : float
        Settling threshold, deg.
    """

    t: np.ndarray
    q: np.ndarray
    omega_b: np.ndarray
    Omega: np.ndarray
    q_meas: np.ndarray
    omega_meas: np.ndarray
    Omega_meas: np.ndarray
    commands: np.ndarray
    applied: np.ndarray
    q_ref: np.ndarray
    error_deg: np.ndarray
    L_w: np.ndarray
    L_wheels_w: np.ndarray
    peak_torque: np.ndarray
    peak_wheel_speed: np.ndarray
    torque_limit: float
    speed_limit: float
    threshold_deg: float = THRESHOLD_DEG

    def settling_time(self, threshold_deg: float | None = None) -> float:
        """First sample time after which the error stays below the threshold, s (0 if always; inf if never).

        Parameters
        ----------
        threshold_deg : float, optional
            Threshold, deg (default the run's ``threshold_deg``).

        Returns
        -------
        float
        """
        th = self.threshold_deg if threshold_deg is None else V.positive("threshold_deg", threshold_deg)
        above = np.flatnonzero(self.error_deg >= th)
        if above.size == 0:
            return 0.0
        return math.inf if above[-1] == self.t.size - 1 else float(self.t[above[-1] + 1])

    @property
    def final_error_deg(self) -> float:
        """True attitude error at the end, deg."""
        return float(self.error_deg[-1])

    @property
    def L_drift(self) -> float:
        """max_t |L(t) − L(0)| / max(|L(0)|, max_t |L_wheels(t)|): the relative drift of the total angular
        momentum (body + wheels, world frame), scaled by the momentum present or exchanged (a slew from rest
        has L(0) = 0)."""
        scale = max(float(np.linalg.norm(self.L_w[0])), float(np.linalg.norm(self.L_wheels_w, axis=1).max()), 1e-300)
        return float(np.linalg.norm(self.L_w - self.L_w[0], axis=1).max() / scale)

    @property
    def within_limits(self) -> bool:
        """Every applied torque within the torque limit and every sampled wheel speed within the speed limit."""
        return bool(np.all(self.peak_torque <= self.torque_limit * (1 + 1e-12))
                    and np.all(self.peak_wheel_speed <= self.speed_limit))

    def figures(self) -> dict:
        """The run's figures as plain values (JSON-ready but for an infinite settling time).

        Returns
        -------
        dict
            ``T``, ``threshold_deg``, ``settling_time`` (s), ``final_error_deg``, ``initial_error_deg``,
            ``peak_torque`` and ``peak_wheel_speed`` (lists per wheel), the limits, ``within_limits``, ``L_drift``.
        """
        return {"T": float(self.t[-1]), "threshold_deg": self.threshold_deg, "settling_time": self.settling_time(),
                "final_error_deg": self.final_error_deg, "initial_error_deg": float(self.error_deg[0]),
                "peak_torque": self.peak_torque.tolist(), "peak_wheel_speed": self.peak_wheel_speed.tolist(),
                "torque_limit": self.torque_limit, "speed_limit": self.speed_limit, "within_limits": self.within_limits,
                "L_drift": self.L_drift}

    def plot(self, path: Any = None, title: str = "", *, axes: Any = None) -> Any:
        """Four panels against t (attitude error, log; body rates; applied torques; wheel speeds), in the house
        style (lavendersim.figures: Okabe–Ito colours, components told apart by line style too, legends below
        the panels).

        Parameters
        ----------
        path : str or os.PathLike, optional
            Write the figure there (PNG, 100 dpi); otherwise only return it.
        title : str, optional
            Figure title (not set when ``axes`` is given).
        axes : sequence of 4 matplotlib Axes, optional
            Draw into these (row order: error, rates, torques, wheel speeds) instead of a new figure.

        Returns
        -------
        matplotlib.figure.Figure
            A new figure whose ``show()`` works (lavendersim.figures.new_figure), or the one holding ``axes``.

        Raises
        ------
        LavenderInputError
            ``axes`` does not hold 4 axes.
        """
        from .figures import new_figure, style_axes

        fig, ax = new_figure(2, 2, size=(11, 7.5), title=None if axes is not None else title or "sampled closed loop",
                             ax=axes)
        if axes is not None:
            for a in ax.flat:
                style_axes(a)
        self._plot_error(ax[0, 0])
        for a, data, lab, unit, lim in ((ax[0, 1], self.omega_b, "ω", "body rate ω_b (rad/s)", None),
                                        (ax[1, 0], self.applied, "u", "applied wheel torque (N·m)", self.torque_limit),
                                        (ax[1, 1], self.Omega, "Ω", "wheel speed Ω (rad/s)", self.speed_limit)):
            self._plot_components(a, data, lab, lim)
            a.set_xlabel("t (s)"); a.set_ylabel(unit)
        if path is not None:
            fig.savefig(path, dpi=100)
        return fig

    def _plot_error(self, a: Any) -> None:
        """The attitude error (log) with its threshold and the settling time."""
        from .figures import BLUE, GREY, VERMILLION, legend_below

        a.semilogy(self.t, np.maximum(self.error_deg, 1e-9), color=BLUE, label="attitude error")
        a.axhline(self.threshold_deg, color=VERMILLION, ls=":", label=f"threshold {self.threshold_deg:g}°")
        st = self.settling_time()
        if math.isfinite(st):
            a.axvline(st, color=GREY, ls="--", label=f"settled {st:.3g} s")
        a.set_xlabel("t (s)"); a.set_ylabel("attitude error (deg)")
        legend_below(a, ncols=3)

    def _plot_components(self, a: Any, data: np.ndarray, lab: str, lim: float | None) -> None:
        """One line per body axis (x/y/z styles) or per wheel (palette colour and line style), limits dotted."""
        from .figures import BLACK, CYCLE, LINESTYLES, axis_style, legend_below

        for i in range(data.shape[1]):
            if lab == "ω":
                style = axis_style(i, marker=None)
                name = "xyz"[i]
            else:
                style = {"color": CYCLE[i % len(CYCLE)], "ls": LINESTYLES[i % len(LINESTYLES)]}
                name = str(i + 1)
            a.plot(self.t, data[:, i], label=f"{lab}_{name}", **style)
        if lim is not None and np.abs(data).max(initial=0) > 0.5 * lim:
            a.axhline(lim, color=BLACK, ls=":", lw=0.8, label="limit"); a.axhline(-lim, color=BLACK, ls=":", lw=0.8)
        legend_below(a, ncols=min(data.shape[1] + 1, 5))


def _substeps(Ts: float, delay: float, dt: float | None) -> tuple[int, int]:
    """(Sim steps per period, steps before the delayed command takes effect)."""
    if dt is None:
        for n in range(DEFAULT_SUBSTEPS, MAX_SUBSTEPS + 1):
            nd = delay / Ts * n
            if abs(nd - round(nd)) <= 1e-9 * n:
                return n, int(round(nd))
        raise V.LavenderInputError("delay", "must be a whole multiple of period/n for some n <= "
                                   f"{MAX_SUBSTEPS} (the Sim steps between samples); give dt", f", got {delay!r}")
    dt = V.dt("dt", dt)
    n = int(round(Ts / dt))
    if n < 1 or n > MAX_SUBSTEPS or abs(n * dt - Ts) > 1e-9 * Ts:
        raise V.LavenderInputError("dt", f"the period {Ts:g} s must be a whole multiple of dt (at most {MAX_SUBSTEPS} "
                                   "steps)", f", got {dt!r}")
    nd = delay / dt
    if abs(nd - round(nd)) > 1e-9 * max(1.0, nd):
        raise V.LavenderInputError("delay", f"must be a whole multiple of dt = {dt:g} s", f", got {delay!r}")
    return n, int(round(nd))


class _Actuator:
    """Holds the command the wheels get: the first-order lag ȧ = (c − a)/τ integrated exactly per Sim step
    (the step's command is the exact mean of a over the step, so the wheels receive the lagged impulse)."""

    def __init__(self, sim: Sim, body: str, dt: float, lag: float, a0: np.ndarray):
        self.sim, self.body, self.lag = sim, body, lag
        self.a = a0.copy()
        self.e = math.exp(-dt / lag) if lag > 0 else 0.0
        self.mean = (lag / dt) * (1 - self.e) if lag > 0 else 0.0   # mean of e^{-s/τ} over the step
        self.peak = np.zeros(a0.size)

    def run(self, c: np.ndarray, steps: int) -> np.ndarray | None:
        """Run `steps` Sim steps under the command c; return the torque applied over the first one."""
        if steps == 0:
            return None
        sim, body = self.sim, self.body
        first: np.ndarray | None
        if self.lag == 0:
            sim.set_wheel_command(body, c)
            sim.run(1)
            first = sim.wheel_command_applied(body)
            self.peak = np.maximum(self.peak, np.abs(first))
            if steps > 1:
                sim.run(steps - 1)
                self.peak = np.maximum(self.peak, np.abs(sim.wheel_command_applied(body)))
            self.a = c.copy()
            return first
        first = None
        for _ in range(steps):
            sim.set_wheel_command(body, c + (self.a - c) * self.mean)
            sim.run(1)
            self.a = c + (self.a - c) * self.e
            app = sim.wheel_command_applied(body)
            self.peak = np.maximum(self.peak, np.abs(app))
            first = app if first is None else first
        return first


def _initial_sim(scene: Scene, body: str, ctrl: Controller, dt: float, backend: str, q0, omega0, Omega0) -> Sim:
    from .sim import Sim

    # max_growth=None: a slew from rest (or with the wheels at a null-space bias) has |L(0)| ~ roundoff, which
    # the Sim's relative |L| growth check would call a divergence; the Response reports the |L| drift itself
    # (a non-finite state still raises DivergenceError)
    sim = Sim(scene, dt=dt, integrator="rk4", backend=backend, max_growth=None)
    kw = {}
    if q0 is not None:
        kw["q"] = V.quaternion("q0", q0)
    if omega0 is not None:
        kw["omega_b"] = V.vector("omega0", omega0)
    kw["Omega"] = ctrl.Omega_ref.copy() if Omega0 is None else V.vector("Omega0", Omega0, ctrl.n)
    sim.set_state(body, **kw)
    return sim


def closed_loop(scene: Scene, controller: Controller, *, T: float, q0: ArrayLike | None = None,
                omega0: ArrayLike | None = None, Omega0: ArrayLike | None = None, q_ref: ArrayLike | None = None,
                sensors: Sensors | None = None, actuator_lag: float | None = None, delay: float | None = None,
                dt: float | None = None, disturbances: Callable[[float, Sim], None] | None = None,
                threshold_deg: float = THRESHOLD_DEG, backend: str = "auto") -> Response:
    """Fly a designed controller on a scene in the nonlinear simulator, sampled with a zero-order hold.

    Every ``controller.Ts`` the true state is sampled (and recorded), ``disturbances(t, sim)`` runs,
    the sensors measure, the controller computes the command, which takes effect ``delay`` later and
    is held until the next one (ZOH), through the first-order actuator lag, saturated by the Sim's
    ``reaction_wheels`` (torque–speed line). The Sim steps RK4 at ``dt`` between samples.

    Parameters
    ----------
    scene : Scene
        The plant (may differ from the design's: inertia errors, other effects); the controlled body
        ``controller.body`` must carry the controller's number of wheels.
    controller : Controller
        From :func:`design`; its memory is reset at the start.
    T : float
        Duration, s; > 0 (rounded to whole periods).
    q0 : array_like (4,), optional
        Initial attitude (default: the scene's).
    omega0 : array_like (3,), optional
        Initial body rate, body frame, rad/s (default: the scene's).
    Omega0 : array_like (N,), optional
        Initial wheel rates, rad/s (default: the controller's ``Omega_ref``).
    q_ref : array_like (4,), optional
        Reference attitude (default: the controller's ``q_ref``).
    sensors : Sensors, optional
        Measurement models (default: perfect measurements).
    actuator_lag : float, optional
        The plant's actuator time constant, s (default: the controller's ``actuator_lag``).
    delay : float, optional
        The plant's computation delay, s, 0 <= delay <= Ts (default: the controller's ``delay``).
    dt : float, optional
        Sim step, s: the period divided by a whole number (default ``Ts / 10``, or the smallest
        finer division on which the delay falls).
    disturbances : callable or sequence, optional
        Force effects that change between samples, through ``Sim.set_effect_params``: a callable
        ``disturbances(t, sim)`` run at every sample before the measurement (it calls
        ``sim.set_effect_params(effect, ...)`` itself), or a schedule — a sequence of
        ``(t, effect, {param: value})`` (t in s; effect as ``scene.add_effect`` returned it), each applied
        at the first sample at or after its t (a piecewise-constant disturbance torque, a thruster firing).
    threshold_deg : float, default 0.1
        Settling threshold of the response's figures, deg.
    backend : {"auto", "c", "numpy"}, default "auto"

    Returns
    -------
    Response

    Raises
    ------
    lavendersim.validate.LavenderInputError
        A bad argument (naming it).
    lavendersim.errors.DivergenceError
        The simulation diverged.
    """
    a = _loop_args(scene, controller, T=T, q0=q0, omega0=omega0, Omega0=Omega0, q_ref=q_ref, sensors=sensors,
                   actuator_lag=actuator_lag, delay=delay, dt=dt, disturbances=disturbances, threshold_deg=threshold_deg,
                   backend=backend)
    sim = _initial_sim(scene, a["body"], controller, controller.Ts / a["nsub"], a["backend"], a["q0"], a["omega0"], a["Omega0"])
    return _fly(sim, a["body"], controller, a["sensors"], a["K"], a["nsub"], a["nd"], a["lag"], a["q_ref"], a["disturbances"],
                a["threshold_deg"])


def _loop_args(scene: Scene, controller: Controller, *, T, q0, omega0, Omega0, q_ref, sensors, actuator_lag, delay, dt,
               disturbances, threshold_deg, backend) -> dict:
    """closed_loop's arguments checked (naming each) and resolved, before any Sim is built: the same for every
    plant of a Monte Carlo sweep, so a sweep checks them once."""
    from .backends import BACKEND_CHOICES

    if not isinstance(controller, Controller):
        raise V.LavenderInputError("controller", "must be a Controller from lavendersim.control.design",
                                   f", got {V._describe(controller)}")
    body = wheeled_body(scene, controller.body)
    if Wheels.of(scene, body).n != controller.n:
        raise V.LavenderInputError("scene", f"body {body!r} must carry the controller's {controller.n} wheels")
    Ts = controller.Ts
    T = V.positive("T", T)
    K = int(round(T / Ts))
    if K < 1 or K > MAX_SAMPLES:
        raise V.LavenderInputError("T", f"must be between one period ({Ts:g} s) and {MAX_SAMPLES:,} periods", f", got {T!r}")
    lag = controller.actuator_lag if actuator_lag is None else V.scalar("actuator_lag", actuator_lag, nonnegative=True)
    dly = controller.delay if delay is None else V.scalar("delay", delay, nonnegative=True)
    if dly > Ts:
        raise V.LavenderInputError("delay", f"must be at most the period {Ts:g} s", f", got {delay!r}")
    sensors = Sensors() if sensors is None else sensors
    if not isinstance(sensors, Sensors):
        raise V.LavenderInputError("sensors", "must be a lavendersim.control.Sensors or None", f", got {V._describe(sensors)}")
    disturbances = _disturbances(disturbances)
    qr = controller.q_ref if q_ref is None else V.quaternion("q_ref", q_ref)
    th = V.positive("threshold_deg", threshold_deg)
    nsub, nd = _substeps(Ts, dly, dt)
    backend = V.choice("backend", backend, BACKEND_CHOICES)
    return {"body": body, "K": K, "lag": lag, "sensors": sensors, "disturbances": disturbances, "q_ref": qr,
            "threshold_deg": th, "nsub": nsub, "nd": nd, "backend": backend,
            "q0": None if q0 is None else V.quaternion("q0", q0),
            "omega0": None if omega0 is None else V.vector("omega0", omega0),
            "Omega0": None if Omega0 is None else V.vector("Omega0", Omega0, controller.n)}


def _disturbances(d: Any) -> Callable[[float, Sim], None] | None:
    """A callable (t, sim) from a callable or a schedule of (t, effect, {param: value}) entries (checked here)."""
    if d is None or callable(d):
        return d
    from .effects import Effect

    rule = "must be a callable (t, sim), a sequence of (t, effect, {param: value}) or None"
    if isinstance(d, (str, bytes, dict)) or not hasattr(d, "__iter__"):
        raise V.LavenderInputError("disturbances", rule, f", got {V._describe(d)}")
    entries = []
    for k, e in enumerate(d):
        if not (isinstance(e, (tuple, list)) and len(e) == 3 and isinstance(e[1], Effect) and isinstance(e[2], dict)):
            raise V.LavenderInputError(f"disturbances[{k}]", rule, f", got {V._describe(e)}")
        entries.append((V.scalar(f"disturbances[{k}].t", e[0], nonnegative=True), e[1], dict(e[2])))
    entries.sort(key=lambda e: e[0])
    latest: dict[int, Any] = {}

    def apply(t: float, sim: Sim) -> None:
        while entries and entries[0][0] <= t + 1e-9 * max(1.0, t):
            _, effect, values = entries.pop(0)
            latest[id(effect)] = sim.set_effect_params(latest.get(id(effect), effect), **values)

    return apply


def _fly(sim: Sim, body: str, ctrl: Controller, sensors: Sensors, K: int, nsub: int, nd: int, lag: float,
         q_ref: np.ndarray, disturbances, threshold_deg: float) -> Response:
    n = ctrl.n
    rng = sensors.generator()
    ctrl.reset()
    rec = {k: np.empty((K + 1, w)) for k, w in (("q", 4), ("w", 3), ("Om", n), ("qm", 4), ("wm", 3), ("Omm", n),
                                                ("u", n), ("ua", n), ("L", 3), ("Lw", 3))}
    t = np.empty(K + 1)
    act = _Actuator(sim, body, sim.dt, lag, ctrl.u0.copy())
    held = ctrl.u0.copy()
    for k in range(K + 1):
        if disturbances is not None:
            disturbances(float(sim.t), sim)
        st = sim.state(body)
        q, w, Om = st.q, st.omega_b, sim.wheel_rates(body)
        Lb, Lw = sim.wheel_momentum_w(body)
        t[k], rec["q"][k], rec["w"][k], rec["Om"][k], rec["L"][k], rec["Lw"][k] = sim.t, q, w, Om, Lb + Lw, Lw
        if k == K:
            break
        qm, wm, Omm = sensors.measure(rng, q, w, Om)
        rec["qm"][k], rec["wm"][k], rec["Omm"][k] = qm, wm, Omm
        u = ctrl.command(qm, wm, Omm, q_ref)
        first_old = act.run(held, nd)
        first_new = act.run(u, nsub - nd)
        held = u
        rec["u"][k], rec["ua"][k] = u, first_new if first_new is not None else first_old
    for key in ("qm", "wm", "Omm", "u", "ua"):
        rec[key][K] = rec[key][K - 1]
    err = np.degrees(np.asarray(KN.quat_error_angle(rec["q"], q_ref), dtype=float))
    return Response(t, rec["q"], rec["w"], rec["Om"], rec["qm"], rec["wm"], rec["Omm"], rec["u"], rec["ua"], q_ref.copy(),
                    err, rec["L"], rec["Lw"], act.peak, np.abs(rec["Om"]).max(axis=0), ctrl.wheels.torque_limit,
                    ctrl.wheels.speed_limit, threshold_deg)


# ----------------------------------------------------------------------------------------------
# Monte Carlo: noise seeds and inertia uncertainty
# ----------------------------------------------------------------------------------------------


def perturbed_inertia(scene: Scene, body: str, scale: ArrayLike) -> Scene:
    """A copy of ``scene`` whose ``body`` has inertia ``D I D`` (D = diag(sqrt(scale)), body frame): each
    principal-axis moment of a diagonal inertia is multiplied by ``scale[i]``; a full tensor stays
    symmetric positive definite.

    Parameters
    ----------
    scene : Scene
    body : str
    scale : array_like (3,)
        Positive factors.

    Returns
    -------
    Scene
        A new scene (same effects, the body rebuilt; its shape for the viewer is dropped).
    """
    from .bodies import Body
    from .scene import Scene

    from . import effects as E

    s = V.vector("scale", scale)
    if np.any(s <= 0):
        raise V.LavenderInputError("scale", "inertia factors must be positive", f", got {s.tolist()}")
    new = Scene()
    for name, b in scene.bodies.items():
        if name == body:
            x0 = np.asarray(b.x0, float)
            b = Body(name, b.mass, _perturbed_tensor(b, s), p_w=x0[LY.STATE_P_W], q=x0[LY.STATE_Q], v_w=x0[LY.STATE_V_W],
                     omega_b=x0[LY.STATE_OMEGA_B])
        new.add_body(b)
    for e in scene.effects:
        new.add_effect(E.make(e.name, body=e.body, **dict(e.values)))
    return new


def _perturbed_tensor(b: Any, scale: np.ndarray) -> np.ndarray:
    """D I D (3, 3), body frame, kg·m², D = diag(sqrt(scale)): a body's perturbed inertia tensor (not yet checked)."""
    I = np.asarray(getattr(b, "inertia_b", None) if hasattr(b, "inertia_b") else np.diag(b.I_b), float)
    d = np.sqrt(scale)
    return d[:, None] * I * d[None, :]


# the errors a draw may meet that make it a failed sample (its plant or its run), not the end of the sweep
DRAW_ERRORS = (V.LavenderInputError, ArithmeticError, np.linalg.LinAlgError)


def _failed(exc: BaseException, stage: str) -> dict:
    """A failed draw's figures: None, and why (the error's class, field and message)."""
    return {"settled": False, "settling_time": None, "peak_torque": None, "peak_wheel_speed": None,
            "final_error_deg": None, "L_drift": None, "failed": stage, "error": type(exc).__name__,
            "field": getattr(exc, "field", None), "why": " ".join(str(exc).split())}


def monte_carlo_sample(task: dict) -> dict:
    """One Monte Carlo run (a module-level function of a picklable task: the executor's contract).

    Parameters
    ----------
    task : dict
        ``scene`` (the perturbed plant), ``controller``, ``sensors`` (a Sensors), and
        closed_loop's ``T``, ``q0``, ``omega0``, ``Omega0``, ``dt``, ``threshold_deg``, ``backend``.

    Returns
    -------
    dict
        ``settled`` (bool), ``settling_time`` (s or None), ``peak_torque``, ``peak_wheel_speed`` (max over
        wheels), ``final_error_deg``, ``L_drift``; ``failed`` (None, or ``"run"`` when the run raised one of
        DRAW_ERRORS: a divergence, a validity bound, a state the perturbed plant refuses), then ``error`` (the
        exception's class), ``field`` (a LavenderInputError's) and ``why`` (its message), else None.
    """
    try:
        r = closed_loop(task["scene"], task["controller"], T=task["T"], q0=task["q0"], omega0=task["omega0"], Omega0=task["Omega0"],
                        sensors=task["sensors"], dt=task["dt"], threshold_deg=task["threshold_deg"], backend=task["backend"])
    except DRAW_ERRORS as exc:
        return _failed(exc, "run")
    st = r.settling_time()
    return {"settled": bool(math.isfinite(st) and r.final_error_deg < r.threshold_deg),
            "settling_time": st if math.isfinite(st) else None, "peak_torque": float(r.peak_torque.max()),
            "peak_wheel_speed": float(r.peak_wheel_speed.max()), "final_error_deg": r.final_error_deg,
            "L_drift": r.L_drift, "failed": None, "error": None, "field": None, "why": None}


class SweepError(V.LavenderInputError):
    """Every draw of a Monte Carlo sweep failed (field ``monte_carlo``); ``samples`` holds them, each with its reason.

    Parameters
    ----------
    field, rule, detail : str
        As LavenderInputError.
    samples : list of dict
        The failed samples (monte_carlo's ``samples``).
    """

    _init_fields = ("field", "rule", "detail", "samples")   # pickles with them (lavendersim.errors.PicklableError)

    def __init__(self, field: str, rule: str, detail: str = "", samples: list | None = None) -> None:
        super().__init__(field, rule, detail)
        self.samples = list(samples or [])


def monte_carlo(scene: Scene, controller: Controller, *, n: int, seed: int = 0, T: float, q0: ArrayLike | None = None,
                omega0: ArrayLike | None = None, Omega0: ArrayLike | None = None, sensors: Sensors | None = None,
                inertia_spread: float = 0.1, dt: float | None = None, threshold_deg: float = THRESHOLD_DEG,
                backend: str = "auto", executor: Any = None, progress: Callable[[int], Any] | None = None) -> dict:
    """Fly one controller on n plants: noise seeds ``seed + i`` and the body's inertia perturbed.

    Sample i uses ``sensors`` with seed ``sensors.seed + seed + i`` (default Sensors: noise-free, so only
    the inertia varies) and the inertia factors ``1 + inertia_spread · U(−1, 1)`` per body axis, drawn
    here from ``default_rng(seed)`` (the same samples on every executor).

    A draw that fails is a failed sample, not the end of the sweep: its perturbed inertia is not a rigid
    body's (``failed = "plant"``), or its run raised one of DRAW_ERRORS (``"run"``: a divergence, a
    validity bound, ...); it keeps its index, seed, factors and tensor, and the error's class, field and
    message. The arguments are checked once, before any draw (an error there is the same for every draw);
    the sweep raises only if every draw fails (:class:`SweepError`).

    Parameters
    ----------
    scene, controller :
        The nominal plant and the controller designed for it.
    n : int
        Samples, >= 1.
    seed : int, default 0
        >= 0.
    T, q0, omega0, Omega0, dt, threshold_deg, backend :
        As :func:`closed_loop`.
    sensors : Sensors, optional
    inertia_spread : float, default 0.1
        Relative half-width of the uniform inertia factors, in [0, 1).
    executor : lavendersim.executor.Executor, optional
        Serial, local processes or Dask (default serial).
    progress : callable, optional
        Called with the number of draws just done (a progress bar's ``update``); the draws whose plant is
        refused count at once.

    Returns
    -------
    dict
        ``n``, ``seed``, ``inertia_spread``, ``sensors``, ``failures`` (draws that did not settle, failed ones
        included), ``failure_rate``, ``failed`` (draws that failed) and ``failed_samples`` (those samples),
        percentiles (p50, p90, p100) of ``settling_time`` (s, settled samples), ``peak_torque`` (N·m),
        ``peak_wheel_speed`` (rad/s), ``L_drift`` (over the runs that completed), and ``samples`` (each with its
        ``index``, ``seed``, ``inertia_scale`` and ``inertia_b`` (3×3, body frame, kg·m²), see
        :func:`monte_carlo_sample`).

    Raises
    ------
    lavendersim.validate.LavenderInputError
        A bad argument (naming it), checked once for all draws.
    SweepError
        Every draw failed (the first one's reason in the message).
    """
    from . import executor as X

    if not isinstance(controller, Controller):
        raise V.LavenderInputError("controller", "must be a Controller from lavendersim.control.design",
                                   f", got {V._describe(controller)}")
    n = V.integer("n", n, minimum=1)
    seed = V.integer("seed", seed, minimum=0)
    spread = V.scalar("inertia_spread", inertia_spread, nonnegative=True)
    if spread >= 1:
        raise V.LavenderInputError("inertia_spread", "must be below 1 (inertia factors stay positive)", f", got {spread!r}")
    sensors = Sensors() if sensors is None else sensors
    a = _loop_args(scene, controller, T=T, q0=q0, omega0=omega0, Omega0=Omega0, q_ref=None, sensors=sensors,
                   actuator_lag=None, delay=None, dt=dt, disturbances=None, threshold_deg=threshold_deg, backend=backend)
    body = a["body"]
    rng = np.random.default_rng(seed)
    scales = 1 + spread * rng.uniform(-1, 1, (n, 3))
    base = {"controller": controller, "T": T, "q0": a["q0"], "omega0": a["omega0"], "Omega0": a["Omega0"], "dt": dt,
            "threshold_deg": threshold_deg, "backend": backend}
    drawn: list[dict | None] = [None] * n
    tasks, where = [], []
    for i in range(n):
        try:
            plant = perturbed_inertia(scene, body, scales[i])
        except V.LavenderInputError as exc:     # this draw's inertia is not a rigid body's
            drawn[i] = _failed(exc, "plant")
            continue
        tasks.append({**base, "scene": plant, "sensors": replace(sensors, seed=sensors.seed + seed + i)})
        where.append(i)
    if progress is not None and n > len(tasks):
        progress(n - len(tasks))
    for i, s in zip(where, X.map_tasks(monte_carlo_sample, tasks, executor, feature="lavendersim lqr --dask",
                                       progress=progress)):
        drawn[i] = s
    samples = [s for s in drawn if s is not None]
    assert len(samples) == n   # (each draw failed on its plant or ran)
    for i, s in enumerate(samples):
        s["index"], s["seed"], s["inertia_scale"] = i, sensors.seed + seed + i, scales[i].tolist()
        s["inertia_b"] = _perturbed_tensor(scene.bodies[body], scales[i]).tolist()
    failed = [s for s in samples if s["failed"]]
    if len(failed) == n:
        f = failed[0]
        raise SweepError("monte_carlo", f"every one of the {n} draws failed", f"; draw 0 (seed {f['seed']}, inertia factors "
                         f"{np.round(f['inertia_scale'], 6).tolist()}): {f['why']}", samples)
    ok = [s for s in samples if s["settled"]]

    def pct(key, rows):
        v = np.array([s[key] for s in rows if s[key] is not None], dtype=float)
        return {p: (float(np.percentile(v, int(p[1:]))) if v.size else None) for p in ("p50", "p90", "p100")}

    return {"n": n, "seed": seed, "inertia_spread": spread, "sensors": {k: getattr(sensors, k) for k in ("attitude_noise", "gyro_noise", "gyro_bias", "wheel_speed_noise", "seed")},
            "failures": n - len(ok), "failure_rate": (n - len(ok)) / n, "failed": len(failed), "failed_samples": failed,
            "settling_time": pct("settling_time", ok), "peak_torque": pct("peak_torque", samples),
            "peak_wheel_speed": pct("peak_wheel_speed", samples), "L_drift": pct("L_drift", samples), "samples": samples}


# ----------------------------------------------------------------------------------------------
# the momentum check (any wheeled body)
# ----------------------------------------------------------------------------------------------


def momentum_exchange(scene: Scene, body: str | None = None, *, omega0: ArrayLike = (0.3, -0.2, 0.5), torque: float = 0.05,
                      T: float = 2.0, dt: float = 2.5e-4, period: float = 0.01, backend: str = "auto") -> dict:
    """Lab 04's momentum check for any wheeled body: the body spinning at ``omega0`` and time-varying
    commands ``torque · sin(2 t + i)`` on wheel i (held over each ``period``), RK4 at ``dt``. Without
    external torque and damping the exchange is exact, ΔL_body = −ΔL_wheels (world frame), to RK4's
    truncation error.

    Parameters
    ----------
    scene : Scene
        The plant; declare no external torque and no damping for an exact exchange.
    body : str, optional
        The wheeled body (default the only one).
    omega0 : array_like (3,), default (0.3, -0.2, 0.5)
        Initial body rate, rad/s.
    torque : float, default 0.05
        Command amplitude, N·m, > 0.
    T, dt, period : float
        Duration, Sim step, command hold, s.
    backend : {"auto", "c", "numpy"}

    Returns
    -------
    dict
        ``exchange_residual`` (max |ΔL_body + ΔL_wheels| / max |ΔL_wheels|), ``L_drift``
        (max |L(t) − L(0)| / |L(0)|), ``max_dL_wheels`` (kg·m²/s); sampled every period.
    """
    from .sim import Sim

    body = wheeled_body(scene, body)
    omega0 = V.vector("omega0", omega0)
    torque = V.positive("torque", torque)
    T, dt, period = V.positive("T", T), V.dt("dt", dt), V.positive("period", period)
    n = Wheels.of(scene, body).n
    sim = Sim(scene, dt=dt, integrator="rk4", backend=backend)
    sim.set_state(body, q=(0.0, 0.0, 0.0, 1.0), omega_b=omega0, Omega=np.zeros(n))
    sub = max(1, int(round(period / dt)))
    periods = int(math.ceil(T / (sub * dt) - 1e-9))
    phase = np.arange(n, dtype=float)
    Lb, Lw = np.empty((periods + 1, 3)), np.empty((periods + 1, 3))
    for k in range(periods + 1):
        Lb[k], Lw[k] = sim.wheel_momentum_w(body)
        if k == periods:
            break
        sim.set_wheel_command(body, torque * np.sin(2.0 * k * sub * dt + phase))
        sim.run(sub)
    dLb, dLw = Lb - Lb[0], Lw - Lw[0]
    L0 = Lb[0] + Lw[0]
    scale = float(np.linalg.norm(dLw, axis=1).max())
    return {"exchange_residual": float(np.linalg.norm(dLb + dLw, axis=1).max() / scale),
            "L_drift": float(np.linalg.norm(Lb + Lw - L0, axis=1).max() / np.linalg.norm(L0)), "max_dL_wheels": scale}
