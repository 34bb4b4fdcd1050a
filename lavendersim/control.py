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

From the shell: ``lavendersim lqr --spacecraft FILE`` (lavendersim.cli.lqr; ``--scenario center|corner`` and
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
from .attitude import attitude_error, error_angle_deg, perturbed, rotated  # noqa: F401  (re-exported)
from .lqr import (controllable_basis, uncontrollable, _weight, DesignError, _growth, _stability_tol, _mode_states, unstable_uncontrollable_modes, _refuse_unstable, _is_real, _eig_text, _check_closed_loop, LQRResult, _pair, _design, lqr, dlqr, WEIGHT_MAX, STABILITY_RTOL)  # noqa: F401  (re-exported)

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
    from .bodies import Body
    from .scene import Scene

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
    scene = Scene()
    scene.add_body(Body.box(name, mass=mass, size=(size, size, size), p_w=p_w, q=q0, omega_b=omega_b))
    scene.add_effect("spherical_joint", body=name, anchor_w=[0.0, 0.0, 0.0])
    scene.add_effect("reaction_wheels", body=name, J=Jv.tolist(), torque_limit=torque_limit, speed_limit=speed_limit,
                     c_w=wheel_damping, cutoff=float(motor == "cutoff"))
    if scenario == "corner" and g > 0:
        scene.add_effect("gravity", body=name, g_w=[0.0, 0.0, -g])
    if damping > 0:
        scene.add_effect("angular_damping", body=name, c=damping)
    return scene


# ----------------------------------------------------------------------------------------------
# linearization (CasADi, from the generated kernels)
# ----------------------------------------------------------------------------------------------


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
    from .scene import Scene
    from .sim import Sim

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
        new = Scene()
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
        sim = Sim(scene_with(du), dt=dt, integrator="euler", backend=backend, max_growth=None)
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
