"""Reaction wheels on arbitrary spin axes (a wheel layout) and the 4-wheel pyramid example.

A layout is a body-frame axis matrix ``A_b`` (3×N, unit columns), the wheels' axial inertias ``J``
(N, kg·m²) and one motor model (stall torque, no-load speed, bearing damping, line or cut-off). The
equations — body + N wheel rates, wheel momentum ``h_w = J (A_bᵀ ω_b + Ω)`` — are derived once for
any N in derive/wheel_layout.py and printed (C, NumPy, CasADi) for the counts in
``generated.kernels.WHEEL_COUNTS`` (``wheels<N>_body_rhs``, ``wheels<N>_momentum``, ``wheels<N>_motor``).

:class:`LayoutCube` is a uniform cube (a small spacecraft, free, no external torque) carrying a
layout; :func:`pyramid4` the usual redundant set of four wheels on a pyramid. With more wheels than
axes the null space of ``A_b`` (``A_b n = 0``) lets the controller move the wheel speeds without any
torque on the body — wheel-speed management (:func:`null_space`). :func:`slew` designs an LQR on the
linearization (CasADi, from the printed kernel) in error coordinates ``x = [dtheta (3), omega_b (3),
Omega − Omega_ref (N)]`` with ``Omega_ref`` a bias in the null space, and runs it in a fixed-step RK4
inside a :class:`lavendersim.Sim` of :meth:`LayoutCube.scene` (the scene's ``reaction_wheels`` on the
layout's axes, stepped by the printed N-wheel kernel in C or NumPy; the motor line applied at each
step's start, commands held over each control period). :func:`momentum_exchange` is lab 04's
momentum check for any layout.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import ArrayLike

from . import validate as V
from .kernels import K as KN

MOTORS = ("line", "cutoff")
BODY = "cube"     # the body of LayoutCube.scene()
UNIT_TOL = 1e-9   # |‖a_i‖ − 1| allowed for an axis


def printed_counts() -> tuple[int, ...]:
    """The wheel counts N with printed kernels (``wheels<N>_body_rhs`` in the generated NumPy module)."""
    from .generated import kernels_numpy as KG

    return tuple(sorted(int(k[6:-9]) for k in dir(KG) if k.startswith("wheels") and k.endswith("_body_rhs")))


def axes(field_name: str, A_b: ArrayLike, *, span: bool = False) -> np.ndarray:
    """Check a wheel axis matrix: (3, N) with N ≥ 1, finite, unit columns; ``span``: rank 3 (every
    body axis reachable — needed for attitude control).

    Parameters
    ----------
    field_name : str
        The name used in the error message.
    A_b : array_like (3, N)
        Wheel spin axes as columns, body frame (a single (3,) axis is one wheel).
    span : bool, default False
        Also require the columns to span 3-D space.

    Returns
    -------
    ndarray (3, N)

    Raises
    ------
    lavendersim.validate.LavenderInputError
        Naming ``field_name`` and the rule broken.
    """
    A = V.array(field_name, A_b, (3, None)) if np.ndim(A_b) != 1 else V.vector(field_name, A_b)[:, None]
    if A.shape[1] < 1:
        raise V.LavenderInputError(field_name, "needs at least one wheel axis (shape (3, N), N ≥ 1)")
    norms = np.linalg.norm(A, axis=0)
    bad = np.flatnonzero(np.abs(norms - 1.0) > UNIT_TOL)
    if bad.size:
        raise V.LavenderInputError(field_name, "each wheel axis (column) must be a unit vector",
                                   f", column {int(bad[0])} has norm {norms[bad[0]]:.6g}")
    if span and np.linalg.matrix_rank(A, tol=1e-9) < 3:
        raise V.LavenderInputError(field_name, "the wheel axes must span 3-D space (rank 3) for attitude control",
                                   f", rank {np.linalg.matrix_rank(A, tol=1e-9)} with {A.shape[1]} wheel(s)")
    return A


def null_space(A_b: ArrayLike) -> np.ndarray:
    """Orthonormal basis (N, N − rank) of the wheel torques that put no torque on the body: ``A_b n = 0``.

    Parameters
    ----------
    A_b : array_like (3, N)
        Wheel spin axes as unit columns, body frame (checked as :func:`axes`).

    Returns
    -------
    ndarray (N, N − rank)
        Orthonormal columns; (N, 0) when the axes are independent.

    Raises
    ------
    lavendersim.validate.LavenderInputError
        ``A_b`` is not a (3, N) matrix of unit columns.
    """
    A = axes("A_b", A_b)
    _, s, vt = np.linalg.svd(A)
    r = int(np.sum(s > 1e-9 * max(1.0, s.max())))
    return vt[r:].T.copy()


def pyramid_axes(elevation_deg: float | None = None) -> np.ndarray:
    """Four wheel axes on a pyramid about body z: azimuths 0°, 90°, 180°, 270°, each raised by
    ``elevation_deg`` from the x–y plane (default atan(1/√2) ≈ 35.26°: equal authority on all
    three axes, ``A_b A_bᵀ = 4/3·1``).

    Parameters
    ----------
    elevation_deg : float, optional
        Elevation of each axis above the body x–y plane, degrees (default atan(1/√2)).

    Returns
    -------
    ndarray (3, 4)
        Unit columns, body frame.
    """
    e = math.atan(1.0 / math.sqrt(2.0)) if elevation_deg is None else math.radians(V.scalar("elevation_deg", elevation_deg))
    cols = []
    for k in range(4):
        a = np.asarray(KN.axis_angle_to_quat([0.0, 0.0, 1.0], k * math.pi / 2), dtype=float)
        cols.append(np.asarray(KN.quat_rotate(a, [math.cos(e), 0.0, math.sin(e)]), dtype=float))
    return np.stack(cols, axis=1)


@dataclass
class LayoutCube:
    """A uniform cube (mass ``mass`` kg, wheels included and locked; side ``size`` m), free — a
    small spacecraft, no external torque — carrying N reaction wheels on the columns of ``A_b``.

    Parameters
    ----------
    A_b : array_like (3, N)
        Wheel spin axes, body frame, unit columns spanning 3-D space; N must have printed kernels
        (:func:`printed_counts`).
    J : float or array_like (N,), default 5.7e-4
        Wheel axial inertias, kg·m², > 0; ``I_p − A_b diag(J) A_bᵀ`` must be positive definite.
    mass, size : float
        kg, m; > 0 (defaults 1 kg, 0.15 m: the Cubli-like cube of lavendersim.control).
    torque_limit, speed_limit : float
        Motor stall torque, N·m, and no-load speed, rad/s (defaults 0.2, 400); > 0.
    wheel_damping : float, default 0
        Wheel bearing damping ``c_w``, N·m·s/rad, >= 0.
    motor : {"line", "cutoff"}, default "line"
        The torque–speed line, or the hard cut-off at ``speed_limit``.

    Raises
    ------
    lavendersim.validate.LavenderInputError
        A parameter out of range, naming it.
    """

    A_b: ArrayLike
    J: ArrayLike = 5.7e-4
    mass: float = 1.0
    size: float = 0.15
    torque_limit: float = 0.2
    speed_limit: float = 400.0
    wheel_damping: float = 0.0
    motor: str = "line"
    _k: dict = field(default_factory=dict, init=False, repr=False)

    def __post_init__(self):
        self.A_b = axes("A_b", self.A_b, span=True)
        n = self.A_b.shape[1]
        if n not in printed_counts():
            raise V.LavenderInputError("A_b", f"kernels are printed for {list(printed_counts())} wheels "
                                       "(derive/wheel_layout.py WHEEL_COUNTS)", f", got {n}")
        self.J = (np.full(n, V.scalar("J", self.J)) if np.ndim(self.J) == 0 else V.vector("J", self.J, n))
        if np.any(self.J <= 0):
            raise V.LavenderInputError("J", "wheel axial inertias must be positive", f", got {self.J.tolist()}")
        self.mass, self.size = V.positive("mass", self.mass), V.positive("size", self.size)
        self.torque_limit = V.positive("torque_limit", self.torque_limit)
        self.speed_limit = V.positive("speed_limit", self.speed_limit)
        self.wheel_damping = V.scalar("wheel_damping", self.wheel_damping, nonnegative=True)
        self.motor = V.choice("motor", self.motor, MOTORS)
        if np.linalg.eigvalsh(self.I_p - self.A_b @ np.diag(self.J) @ self.A_b.T).min() <= 0:
            raise V.LavenderInputError("J", "I_p − A_b J A_bᵀ must be positive definite (the wheels cannot carry "
                                       "more inertia than the body)", f", got J = {self.J.tolist()}")
        import importlib

        KG = importlib.import_module(".generated.kernels_numpy", __package__)
        self._k = {s: getattr(KG, f"wheels{n}_{s}") for s in ("body_rhs", "momentum", "motor")}

    @property
    def n(self) -> int:
        """Number of wheels N."""
        return self.A_b.shape[1]

    @property
    def I_p(self) -> np.ndarray:
        """Inertia about the COM (wheels locked), body frame, kg·m² (inertia_box kernel), (3, 3)."""
        s = self.size
        return np.diag(np.asarray(KN.inertia_box(self.mass, s, s, s), dtype=float))

    @property
    def null(self) -> np.ndarray:
        """Orthonormal null-space basis of ``A_b`` (N, N − 3)."""
        return null_space(self.A_b)

    def rhs(self, y: np.ndarray, u: np.ndarray, c_w: float | None = None) -> np.ndarray:
        """d/dt of y = [q (4), omega_b (3), Omega (N)] with applied wheel torques u (N), free body.

        Parameters
        ----------
        y : ndarray (7 + N,)
            State: quaternion (x, y, z, w) body to world, omega_b (rad/s, body frame), wheel rates
            Omega relative to the body (rad/s).
        u : ndarray (N,)
            Applied wheel motor torques, N·m.
        c_w : float, optional
            Wheel damping, N·m·s/rad (default the model's ``wheel_damping``).

        Returns
        -------
        ndarray (7 + N,)
        """
        z = np.zeros(3)
        qd, wd, Wd = self._k["body_rhs"](y[:4], y[4:7], y[7:], self.I_p, self.A_b, self.J, z, z, z, u,
                                          self.wheel_damping if c_w is None else c_w)
        return np.concatenate([qd, wd, Wd])

    def applied(self, command: np.ndarray, Omega: np.ndarray) -> np.ndarray:
        """Motor torques actually applied (wheels<N>_motor kernel), N·m, (N,).

        Parameters
        ----------
        command : ndarray (N,)
            Commanded wheel torques, N·m.
        Omega : ndarray (N,)
            Wheel rates relative to the body, rad/s.

        Returns
        -------
        ndarray (N,)
            The command saturated by the motor model (``motor``, ``torque_limit``, ``speed_limit``).
        """
        return np.asarray(self._k["motor"](command, Omega, self.torque_limit, self.speed_limit,
                                           1.0 if self.motor == "cutoff" else 0.0), dtype=float)

    def scene(self, c_w: float | None = None, name: str = "cube"):
        """The cube as a :class:`lavendersim.Scene`: a uniform box body carrying ``reaction_wheels`` on the
        layout's axes (the Sim steps it with the printed N-wheel kernels), free, no other effect.

        Parameters
        ----------
        c_w : float, optional
            Wheel damping, N·m·s/rad (default the model's ``wheel_damping``).
        name : str, default "cube"
            The body's name.

        Returns
        -------
        lavendersim.Scene
        """
        from .bodies import Body
        from .scene import Scene

        scene = Scene()
        scene.add_body(Body.box(name, self.mass, (self.size,) * 3))
        scene.add_effect("reaction_wheels", body=name, J=self.J, axes_b=self.A_b.T, torque_limit=self.torque_limit,
                         speed_limit=self.speed_limit, c_w=self.wheel_damping if c_w is None else c_w,
                         cutoff=1.0 if self.motor == "cutoff" else 0.0)
        return scene

    def momentum_w(self, y: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(L_body_w, L_wheels_w, h_w) of state y (wheels<N>_momentum kernel).

        Parameters
        ----------
        y : ndarray (7 + N,)
            State [q (4), omega_b (3), Omega (N)] as in :meth:`rhs`.

        Returns
        -------
        tuple of ndarray
            ``L_body_w`` and ``L_wheels_w``: body and wheel angular momentum, world frame, kg·m²/s,
            (3,) each; ``h_w``: each wheel's axial momentum ``J (A_bᵀ omega_b + Omega)``, (N,).
        """
        Lb, Lw, h = self._k["momentum"](y[:4], y[4:7], y[7:], self.I_p, self.A_b, self.J)
        return np.asarray(Lb, float), np.asarray(Lw, float), np.asarray(h, float)


def pyramid4(**kwargs) -> LayoutCube:
    """The 4-wheel pyramid cube: :class:`LayoutCube` with ``A_b = pyramid_axes()`` (kwargs passed on).

    Parameters
    ----------
    **kwargs
        Any other :class:`LayoutCube` parameter (``J``, ``mass``, ``size``, ``torque_limit``,
        ``speed_limit``, ``wheel_damping``, ``motor``).

    Returns
    -------
    LayoutCube
    """
    return LayoutCube(A_b=pyramid_axes(), **kwargs)


LAYOUTS = {"pyramid4": pyramid4}


# ----------------------------------------------------------------------------------------------
# linearization (CasADi, from the printed kernel) and the closed loop
# ----------------------------------------------------------------------------------------------


def state_labels(n: int) -> list[str]:
    """Names of the error-coordinate states: dtheta (3), omega (3), Omega_0 … Omega_{N−1}.

    Parameters
    ----------
    n : int
        Number of wheels N.

    Returns
    -------
    list of str
        6 + N names.
    """
    return ["dtheta_x", "dtheta_y", "dtheta_z", "omega_x", "omega_y", "omega_z", *(f"Omega_{i}" for i in range(n))]


def linearize(model: LayoutCube, q_ref: ArrayLike = (0, 0, 0, 1), Omega_ref: ArrayLike | None = None):
    """Continuous linearization at rest at ``q_ref`` with wheel rates ``Omega_ref`` (N, rad/s).

    States ``x = [dtheta (3), omega_b (3), Omega − Omega_ref (N)]`` (``q = q_ref ⊗ [dtheta/2, …]``),
    inputs ``u − c_w Omega_ref`` (N, N·m). The right-hand side is the CasADi printing of
    ``wheels<N>_body_rhs``, differentiated by CasADi.

    Parameters
    ----------
    model : LayoutCube
    q_ref : array_like (4,), default (0, 0, 0, 1)
        Reference attitude, quaternion (x, y, z, w), body to world.
    Omega_ref : array_like (N,), optional
        Wheel rates relative to the body at the operating point, rad/s (default zeros).

    Returns
    -------
    control.StateSpace
        Named states (:func:`state_labels`) and inputs ``u_0 … u_{N−1}``; C = identity.

    Raises
    ------
    ImportError
        casadi or python-control is not installed (the control extra).
    lavendersim.validate.LavenderInputError
        ``q_ref`` or ``Omega_ref`` malformed.
    """
    from ._install import require

    ca = require("casadi", "control", "the linearization (CasADi)")
    ct = require("control", "control", "LQR design (python-control)")
    from ._linearize import _attitude, _dtheta_dot
    from .generated import kernels_casadi as KC

    n = model.n
    q_ref = V.quaternion("q_ref", q_ref)
    Om0 = np.zeros(n) if Omega_ref is None else V.vector("Omega_ref", Omega_ref, n)
    x, u = ca.SX.sym("x", 6 + n), ca.SX.sym("u", n)
    q = _attitude(q_ref, x[0:3])
    z = ca.DM.zeros(3)
    qd, wd, Wd = getattr(KC, f"wheels{n}_body_rhs")(q, x[3:6], x[6:] + Om0, ca.DM(model.I_p.ravel()), ca.DM(model.A_b.ravel()),
                                                     ca.DM(model.J), z, z, z, u + model.wheel_damping * Om0,
                                                     model.wheel_damping)
    f = ca.vertcat(_dtheta_dot(q_ref, q, qd), wd, Wd)
    F = ca.Function("f", [x, u], [ca.jacobian(f, x), ca.jacobian(f, u)])
    A, B = (np.asarray(m, dtype=float) for m in F(np.zeros(6 + n), np.zeros(n)))
    labels = state_labels(n)
    return ct.ss(A, B, np.eye(6 + n), np.zeros((6 + n, n)), states=labels, outputs=labels,
                 inputs=[f"u_{i}" for i in range(n)], name=f"wheels{n}")


def default_weights(model: LayoutCube) -> tuple[np.ndarray, np.ndarray]:
    """Bryson's rule as lavendersim.control.default_weights: 2° attitude, 0.5 rad/s, half the wheel
    speed limit, half the torque limit.

    Parameters
    ----------
    model : LayoutCube

    Returns
    -------
    Q : ndarray (6 + N,)
        Diagonal of the state weight (rad⁻², (rad/s)⁻², (rad/s)⁻²).
    R : ndarray (N,)
        Diagonal of the input weight, (N·m)⁻².
    """
    ang = math.radians(2.0)
    Q = np.concatenate([np.full(3, 1 / ang ** 2), np.full(3, 1 / 0.5 ** 2), np.full(model.n, 1 / (0.5 * model.speed_limit) ** 2)])
    return Q, np.full(model.n, 1 / (0.5 * model.torque_limit) ** 2)


def simulate(model: LayoutCube, controller, y0: ArrayLike, T: float, *, dt: float = 1e-3, Ts: float = 0.01,
             c_w: float | None = None, backend: str = "auto") -> dict[str, np.ndarray]:
    """Run ``controller(t, y) -> command (N,)`` (held over each control period ``Ts``) on the
    nonlinear model inside a :class:`lavendersim.Sim` of :meth:`LayoutCube.scene`: fixed-step RK4,
    the printed ``wheels<WHEELS_MAX>_body_rhs`` on the layout's axes (unused slots padded), the
    motor kernel applied at each step's start, the quaternion normalized after each step.

    Parameters
    ----------
    model : LayoutCube
    controller : callable (t, y) -> array_like (N,)
        Commanded wheel torques, N·m; y = [q (4), omega_b (3), Omega (N)].
    y0 : array_like (7 + N,)
        Initial state.
    T, dt, Ts : float
        Duration, integrator step, control period, s (Ts rounded to a whole number of steps).
    c_w : float, optional
        Wheel damping override (default the model's).
    backend : {"auto", "c", "numpy"}, default "auto"
        The Sim's backend.

    Returns
    -------
    dict
        ``t`` (k,), ``y`` (k, 7+N) at each control period, ``u`` (k, N) applied torques at the
        period's start, ``command`` (k, N).

    Raises
    ------
    lavendersim.validate.LavenderInputError
        The controller returned a wrong-sized or non-finite command, or y0 is malformed.
    lavendersim.errors.DivergenceError
        The state became non-finite (step and time named).
    """
    from .sim import Sim

    n = model.n
    y = V.vector("y0", y0, 7 + n)
    T, dt, Ts = V.positive("T", T), V.dt("dt", dt), V.positive("Ts", Ts)
    c_w = None if c_w is None else V.scalar("c_w", c_w, nonnegative=True)
    sim = Sim(model.scene(c_w=c_w), dt=dt, integrator="rk4", backend=backend)
    sim.set_state(BODY, q=y[:4], omega_b=y[4:7], Omega=y[7:])
    sub = max(1, int(round(Ts / dt)))
    periods = int(math.ceil(T / (sub * dt) - 1e-9))
    ts, ys, us, cs = [], [], [], []
    for k in range(periods + 1):
        t = k * sub * dt
        st = sim.state(BODY)
        y = np.concatenate([st.q, st.omega_b, st.Omega])
        cmd = np.asarray(controller(t, y.copy()), dtype=float)
        if cmd.shape != (n,) or not np.all(np.isfinite(cmd)):
            raise V.LavenderInputError("controller", f"must return {n} finite wheel torques", f", got {cmd!r} at t = {t:g} s")
        ts.append(t), ys.append(y), cs.append(cmd)
        if k == periods:
            us.append(model.applied(cmd, y[7:]))
            break
        sim.set_wheel_command(BODY, cmd)
        sim.run(1)                                    # the torque applied over the period's first step
        us.append(sim.wheel_command_applied(BODY))
        sim.run(sub - 1)
    return {"t": np.array(ts), "y": np.array(ys), "u": np.array(us), "command": np.array(cs)}


@dataclass
class SlewResult:
    """A closed-loop slew: gains, the run, and its figures (angles in degrees).

    Parameters
    ----------
    model : LayoutCube
    K : ndarray (N, 6 + N)
        LQR gain, N·m per state unit.
    poles : ndarray
        Closed-loop eigenvalues of the sampled linear model (discrete).
    rank : int
        Controllable-subspace dimension (of 6 + N).
    Omega_ref : ndarray (N,)
        The null-space wheel-speed target, rad/s.
    run : dict
        :func:`simulate`'s output.
    error_deg : ndarray (k,)
        Attitude error at each control period, degrees.
    threshold_deg : float
        Settling threshold, degrees.
    """

    model: LayoutCube
    K: np.ndarray            # (N, 6+N), N·m per state unit
    poles: np.ndarray        # closed-loop eigenvalues of the sampled linear model (discrete)
    rank: int                # controllable-subspace dimension (of 6+N)
    Omega_ref: np.ndarray    # (N,) the null-space wheel-speed target, rad/s
    run: dict                # simulate()'s output
    error_deg: np.ndarray    # (k,) attitude error
    threshold_deg: float

    @property
    def settling_time(self) -> float:
        """First time after which the error stays below the threshold, s (inf: never)."""
        above = np.flatnonzero(self.error_deg >= self.threshold_deg)
        if above.size == 0:
            return 0.0
        return math.inf if above[-1] + 1 >= self.error_deg.size else float(self.run["t"][above[-1] + 1])

    def figures(self) -> dict:
        """Settling time (s), final error (deg), peak |Omega_i| and |u_i| per wheel, the null-space
        component of Omega at start and end (rad/s), ``within_limits``."""
        Om, u = self.run["y"][:, 7:], self.run["u"]
        nb = null_space(self.model.A_b)
        pw, pu = np.abs(Om).max(axis=0), np.abs(u).max(axis=0)
        return {"layout_wheels": self.model.n, "settling_time": self.settling_time,
                "final_error_deg": float(self.error_deg[-1]), "threshold_deg": self.threshold_deg,
                "peak_wheel_speed": pw.tolist(), "peak_torque": pu.tolist(),
                "speed_limit": self.model.speed_limit, "torque_limit": self.model.torque_limit,
                "within_limits": bool(np.all(pw < self.model.speed_limit) and np.all(pu <= self.model.torque_limit)),
                "null_Omega_start": (nb.T @ Om[0]).tolist(), "null_Omega_end": (nb.T @ Om[-1]).tolist(),
                "null_Omega_target": (nb.T @ self.Omega_ref).tolist(), "rank": self.rank, "n_states": 6 + self.model.n}


def slew(model: LayoutCube, theta_deg: float = 30.0, axis: ArrayLike = (1.0, 2.0, 3.0), *, null_bias: float = 50.0,
         Q: ArrayLike | None = None, R: ArrayLike | None = None, T: float = 8.0, dt: float = 1e-3, Ts: float = 0.01,
         threshold_deg: float = 0.1) -> SlewResult:
    """An LQR attitude slew from rest, ``theta_deg`` about ``axis`` (body frame) back to identity, with
    null-space wheel-speed management: the wheel rates are regulated to ``Omega_ref = null_bias · n``
    (n the first unit null vector of ``A_b``), which the body never feels (``A_b n = 0``).

    The gain is ``lavendersim.control.dlqr`` on :func:`linearize` at ``Omega_ref`` sampled with a
    zero-order hold at ``Ts`` (the design on the controllable subspace: total angular momentum is
    conserved); the command ``u = c_w Omega_ref −
    K x`` is held over each control period ``Ts`` in :func:`simulate`.

    Parameters
    ----------
    model : LayoutCube
    theta_deg : float, default 30
        Initial rotation angle, degrees.
    axis : array_like (3,), default (1, 2, 3)
        Initial rotation axis, body frame (normalized).
    null_bias : float, default 50
        Magnitude of the null-space wheel-speed target, rad/s; ``max |Omega_ref|`` must stay below
        ``speed_limit``.
    Q, R : array_like, optional
        LQR weights (default :func:`default_weights`).
    T, dt, Ts : float
        Duration, integrator step, control period, s (defaults 8, 1e-3, 0.01).
    threshold_deg : float, default 0.1
        Settling threshold on the attitude error, degrees, > 0.

    Returns
    -------
    SlewResult

    Raises
    ------
    lavendersim.validate.LavenderInputError
        A parameter out of range (``null_bias`` whose target reaches ``speed_limit``).
    ImportError
        casadi or python-control is not installed (the control extra).
    """
    from . import control as lc

    theta_deg = V.scalar("theta0", theta_deg)
    null_bias = V.scalar("null_bias", null_bias)
    threshold_deg = V.positive("threshold", threshold_deg)
    n = model.n
    nb = null_space(model.A_b)
    Om_ref = null_bias * nb[:, 0] if nb.shape[1] else np.zeros(n)
    if np.abs(Om_ref).max(initial=0.0) >= model.speed_limit:
        raise V.LavenderInputError("null_bias", "the null-space wheel-speed target must stay below speed_limit",
                                   f", got max |Omega_ref| = {np.abs(Om_ref).max():.4g} rad/s")
    lin = linearize(model, Omega_ref=Om_ref).sample(Ts, method="zoh")
    Qd, Rd = default_weights(model)
    res = lc.dlqr(lin, Qd if Q is None else Q, Rd if R is None else R)
    K = np.asarray(res.K)
    q_ref = np.array([0.0, 0.0, 0.0, 1.0])
    q0 = lc.rotated(q_ref, axis, theta_deg)

    def controller(t, y):
        x = np.concatenate([lc.attitude_error(y[:4], q_ref), y[4:7], y[7:] - Om_ref])
        return model.wheel_damping * Om_ref - K @ x

    run = simulate(model, controller, np.concatenate([q0, np.zeros(3 + n)]), T, dt=dt, Ts=Ts)
    err = np.asarray(lc.error_angle_deg(run["y"][:, :4], q_ref), dtype=float)
    return SlewResult(model, K, np.asarray(res.E), int(res.rank), Om_ref, run, err, threshold_deg)


def momentum_exchange(model: LayoutCube, *, omega0: ArrayLike = (0.3, -0.2, 0.5), torque: float = 0.05, T: float = 2.0,
                      dt: float = 2.5e-4) -> dict:
    """Lab 04's momentum check for any layout: damping off, no external torque, the body spinning at
    ``omega0`` (rad/s) and time-varying commands on every wheel (below the torque limit). The exchange
    is exact: ΔL_body = −ΔL_wheels in the world frame (wheels<N>_momentum kernel), to RK4's
    truncation error (∝ dt⁴: pyramid4, 2 s at dt = 2.5e-4 s, exchange 1.1e-11, |L| drift 4e-10).

    Parameters
    ----------
    model : LayoutCube
    omega0 : array_like (3,), default (0.3, -0.2, 0.5)
        Initial body rate omega_b, rad/s, body frame.
    torque : float, default 0.05
        Amplitude of the sinusoidal wheel commands, N·m, > 0.
    T, dt : float
        Duration and RK4 step, s (defaults 2, 2.5e-4).

    Returns
    -------
    dict
        ``exchange_residual``: max over the run of |ΔL_body + ΔL_wheels| / max |ΔL_wheels|;
        ``L_drift``: max |L(t) − L(0)| / |L(0)|; ``max_dL_wheels`` (kg·m²/s).
    """
    omega0 = V.vector("omega0", omega0)
    torque = V.positive("torque", torque)
    n = model.n
    phase = np.arange(n, dtype=float)

    def controller(t, y):
        return torque * np.sin(2.0 * t + phase)

    run = simulate(model, controller, np.concatenate([[0.0, 0.0, 0.0, 1.0], omega0, np.zeros(n)]), T, dt=dt, c_w=0.0)
    L = [model.momentum_w(y) for y in run["y"]]
    Lb = np.array([a for a, _, _ in L])
    Lw = np.array([b for _, b, _ in L])
    dLb, dLw = Lb - Lb[0], Lw - Lw[0]
    L0 = Lb[0] + Lw[0]
    scale = np.linalg.norm(dLw, axis=1).max()
    return {"exchange_residual": float(np.linalg.norm(dLb + dLw, axis=1).max() / scale),
            "L_drift": float(np.linalg.norm(Lb + Lw - L0, axis=1).max() / np.linalg.norm(L0)),
            "max_dL_wheels": float(scale)}
