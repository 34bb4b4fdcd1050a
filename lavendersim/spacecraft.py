"""A spacecraft file: a scene file plus its controller, sensors, actuator, maneuver and Monte Carlo.

A spacecraft file is TOML (read with the standard library's ``tomllib``). Its scene part — ``[body]``
with ``[body.wheels]`` (and optionally ``[body.joint]``) and ``[[effects]]`` — is exactly the format
:mod:`lavendersim.scene_file` saves and loads; the other tables say how the body is controlled and
flown. SI units throughout (angles in the names: ``_deg``), frames by suffix (``_b`` the body frame
the file writes the inertia in, ``_w`` world)::

    name = "6U CubeSat"                   # optional title

    [body]                                # the scene part (lavendersim.scene_file)
    name = "sat"
    mass = 12.0
    inertia = [[0.2, 0.004, -0.002], [0.004, 0.25, 0.003], [-0.002, 0.003, 0.08]]

    [body.wheels]
    axes_b = [[1.4142135623730951, 0.0, 1.0], [0.0, 1.4142135623730951, 1.0],
              [-1.4142135623730951, 0.0, 1.0], [0.0, -1.4142135623730951, 1.0]]   # scaled to unit
    J = 3e-5
    torque_limit = 0.002
    speed_limit = 600.0

    [controller]
    period = 0.1                          # s (10 Hz)
    delay = 0.01                          # s, computation delay, 0 <= delay <= period (default 0)
    null_bias = 100.0                     # rad/s, null-space wheel-speed target (default 0)
    # q_ref = [0, 0, 0, 1]                # the attitude held (default: the body's q)
    # Q = [...]; R = [...]                # LQR weights: a number, the diagonal, or the matrix;
    [controller.weights]                  # or Bryson's rule (lavendersim.control.default_weights):
    attitude_deg = 1.0
    rate = 0.02

    [sensors]                             # optional: all zero by default
    attitude_noise = 1e-4                 # rad, 1-sigma per axis (star tracker)
    gyro_noise = 1e-5                     # rad/s, 1-sigma
    gyro_bias = [2e-5, -1e-5, 1e-5]       # rad/s, body frame (a number: the same on each axis)
    wheel_speed_noise = 0.05              # rad/s, 1-sigma
    seed = 1

    [actuator]
    lag = 0.02                            # s, first-order wheel-torque lag (default 0)

    [maneuver]                            # starts angle_deg about axis from q_ref, brought back to it
    angle_deg = 30.0
    axis = [1.0, 2.0, 3.0]                # body frame
    duration = 120.0                      # s simulated
    settle_threshold_deg = 0.1            # (default 0.1)
    settle_within = 60.0                  # s: the stated settle time (optional; reported as met or not)
    # Omega0 = [0, 0, 0, 0]               # rad/s, wheel speeds at the start (default: the null-space bias)

    [simulator]                           # optional
    dt = 0.001                            # s, the Sim's RK4 step: a whole fraction of the period and the delay
                                          # (default min(1 ms, period), at most 10,000 steps per period)

    [monte_carlo]                         # optional: `lavendersim lqr --spacecraft F --monte-carlo N`
    n = 50
    inertia_uncertainty = 0.05            # relative: the inertia becomes D I D, D = diag(sqrt(1 ± u)) uniform per body axis
    seed = 0

:func:`load` checks every key: an unknown one, a wrong type or shape, a non-positive value raises
:class:`lavendersim.validate.LavenderInputError` naming the key path (``controller.period``,
``body.wheels.axes_b[2]``) and the rule, and nothing is built. The spacecraft files shipped with the
package (:func:`shipped`) are the 6U CubeSat and the chapter's cubes (`lavendersim lqr --scenario` and
``--layout``).
"""
from __future__ import annotations

import copy
import math
import os
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from . import scene_file as SF
from . import validate as V
from .scene import Scene

__all__ = ["Spacecraft", "ControllerSpec", "Maneuver", "MonteCarloSpec", "load", "from_dict", "shipped", "design",
           "sensors", "fly", "figures", "external_effects", "monte_carlo"]

DATA = Path(__file__).resolve().parent / "data" / "spacecraft"
SECTIONS = SF.SPACECRAFT_TABLES   # beside the scene part
CONTROLLER_KEYS = ("body", "period", "delay", "Q", "R", "weights", "q_ref", "null_bias")
WEIGHT_KEYS = ("attitude_deg", "rate", "wheel_speed_fraction", "torque_fraction")
SENSOR_KEYS = ("attitude_noise", "gyro_noise", "gyro_bias", "wheel_speed_noise", "seed")
ACTUATOR_KEYS = ("lag",)
MANEUVER_KEYS = ("angle_deg", "axis", "duration", "settle_threshold_deg", "settle_within", "Omega0")
SIMULATOR_KEYS = ("dt",)
MONTE_CARLO_KEYS = ("n", "inertia_uncertainty", "seed")


@dataclass(frozen=True)
class ControllerSpec:
    """The ``[controller]`` table: arguments of :func:`lavendersim.control.design`.

    Parameters
    ----------
    period : float
        Controller period, s; > 0.
    delay : float
        Computation delay, s; 0 <= delay <= period.
    Q, R : float, ndarray or None
        LQR weights as written (number, diagonal or matrix; None: Bryson, ``weights``).
    weights : dict
        Bryson's acceptable values (``attitude_deg``, ``rate``, ``wheel_speed_fraction``, ``torque_fraction``).
    q_ref : ndarray (4,)
        Attitude held, (x, y, z, w), body to world.
    null_bias : float
        Null-space wheel-speed target, rad/s.
    """

    period: float
    delay: float
    Q: Any
    R: Any
    weights: dict
    q_ref: np.ndarray
    null_bias: float


@dataclass(frozen=True)
class Maneuver:
    """The ``[maneuver]`` table: start ``angle_deg`` about ``axis`` (body frame) from q_ref, fly ``duration`` s.

    Parameters
    ----------
    angle_deg : float
        The slew, deg.
    axis : ndarray (3,)
        Unit axis, body frame.
    duration : float
        Simulated time, s.
    settle_threshold_deg : float
        Settled: the attitude error stays below this, deg.
    settle_within : float or None
        The stated settle time, s (None: not stated).
    Omega0 : ndarray (N,) or None
        Wheel speeds at the start, rad/s (None: the controller's null-space bias Omega_ref).
    """

    angle_deg: float
    axis: np.ndarray
    duration: float
    settle_threshold_deg: float
    settle_within: float | None
    Omega0: np.ndarray | None = None


@dataclass(frozen=True)
class MonteCarloSpec:
    """The ``[monte_carlo]`` table.

    Parameters
    ----------
    n : int
        Runs (``--monte-carlo N`` overrides it).
    inertia_uncertainty : float
        Relative spread of the flown body's inertia (D I D with D = diag(sqrt(1 + u U(−1, 1))) per body axis, u in
        [0, 0.5)); the controller is the nominal design.
    seed : int
        Seed of the inertia draws; run i flies the sensors with seed ``sensors.seed + seed + i``.
    """

    n: int
    inertia_uncertainty: float
    seed: int


@dataclass(frozen=True)
class Spacecraft:
    """A spacecraft read from a file (see the module docstring): its scene and how it is controlled and flown.

    Parameters
    ----------
    name : str
        The title (default: the body's name).
    scene : Scene
        The scene part: the body, its wheels (and joint), the extra effects.
    body : str
        The controlled body.
    controller : ControllerSpec
    sensors : dict
        Keywords of :class:`lavendersim.control.Sensors` (attitude_noise, gyro_noise, gyro_bias, wheel_speed_noise, seed).
    actuator_lag : float
        First-order actuator time constant, s.
    maneuver : Maneuver
    dt : float
        The Sim's RK4 step, s.
    monte_carlo : MonteCarloSpec or None
    source : str
        The file it was read from ("" for a dict).
    """

    name: str
    scene: Scene
    body: str
    controller: ControllerSpec
    sensors: dict
    actuator_lag: float
    maneuver: Maneuver
    dt: float
    monte_carlo: MonteCarloSpec | None
    source: str = ""

    @property
    def n_wheels(self) -> int:
        """Number of wheels on the controlled body."""
        return int(np.size(self.scene.model_effects(self.body)["reaction_wheels"].values["J"]))

    @property
    def q_ref(self) -> np.ndarray:
        """The attitude held at the end of the maneuver, (x, y, z, w)."""
        return self.controller.q_ref

    @property
    def q0(self) -> np.ndarray:
        """The maneuver's start: q_ref rotated ``angle_deg`` about ``axis`` (body frame), (x, y, z, w)."""
        from .kernels import K

        m = self.maneuver
        qa = np.asarray(K.axis_angle_to_quat(m.axis, math.radians(m.angle_deg)), dtype=float)
        return np.asarray(K.quat_normalize(K.quat_mul(self.q_ref, qa)), dtype=float)


# ---------------------------------------------------------------------------------------------
# reading
# ---------------------------------------------------------------------------------------------


def _weight(path: str, value: Any, n: int, name: str) -> Any:
    """Q or R as written: a number, the n diagonal entries, or the (n, n) matrix; checked on load as design checks
    it (real finite entries within lavendersim.control.WEIGHT_MAX, symmetric, Q PSD, R PD), named by its key."""
    from .lqr import _weight as weight_matrix

    if isinstance(value, list) and value and isinstance(value[0], list):
        M = SF.rows(path, value, n, min_rows=n, max_rows=n)
        if not np.allclose(M, M.T, rtol=1e-12, atol=0.0):
            raise V.LavenderInputError(path, f"the {name} matrix must be symmetric")
        weight_matrix(path, M, n, definite=name == "R")
        return M
    if isinstance(value, list):
        d = V.vector(path, value, n)
    else:
        d = np.array([V.scalar(path, value)])
    rule = (lambda x: x > 0) if name == "R" else (lambda x: x >= 0)
    for i, x in enumerate(d):
        if not rule(x):
            where = path if d.size == 1 and not isinstance(value, list) else f"{path}[{i}]"
            raise V.LavenderInputError(where, f"{name} entries must be {'> 0' if name == 'R' else '>= 0'}", f", got {x!r}")
    weight_matrix(path, d if isinstance(value, list) else float(d[0]), n, definite=name == "R")
    return float(d[0]) if not isinstance(value, list) else d


def _wheeled_body(scene: Scene, name: Any) -> str:
    """The controlled body: ``controller.body``, or the scene's only body with wheels."""
    wheeled = [b for b in scene.bodies if "reaction_wheels" in scene.model_effects(b)]
    if name is None:
        if len(wheeled) != 1:
            raise V.LavenderInputError("controller.body", "name the body to control" if wheeled else
                                       "no body has wheels: add a [body.wheels] table", f"; wheeled bodies: {', '.join(wheeled) or 'none'}")
        return wheeled[0]
    name = SF.text("controller.body", name)
    if name not in wheeled:
        raise V.LavenderInputError("controller.body", f"must name a body with [body.wheels]", f", got {name!r}; "
                                   f"wheeled bodies: {', '.join(wheeled) or 'none'}")
    return name


def _controller(d: dict, scene: Scene, body: str, n: int) -> ControllerSpec:
    c = SF.table("controller", d.get("controller", {}), CONTROLLER_KEYS, required=("period",))
    period = V.positive("controller.period", c["period"])
    delay = V.scalar("controller.delay", c.get("delay", 0.0), nonnegative=True)
    if delay > period:
        raise V.LavenderInputError("controller.delay", f"must be at most the period ({period:g} s)", f", got {delay!r}")
    Q = None if "Q" not in c else _weight("controller.Q", c["Q"], 6 + n, "Q")
    R = None if "R" not in c else _weight("controller.R", c["R"], n, "R")
    weights = {}
    if "weights" in c:
        w = SF.table("controller.weights", c["weights"], WEIGHT_KEYS)
        weights = {k: V.positive(f"controller.weights.{k}", v) for k, v in w.items()}
        if Q is not None and R is not None:
            raise V.LavenderInputError("controller.weights", "Q and R are both given: weights would be unused")
        from .wheel_control import default_weights

        try:   # Bryson's weights checked on load (an overflow to inf or underflow to 0), named by the file's key
            default_weights(scene, body, **weights)
        except V.LavenderInputError as exc:
            raise V.LavenderInputError(f"controller.weights.{exc.field}" if exc.field in WEIGHT_KEYS else exc.field,
                                       exc.rule, exc.detail) from None
    x0 = scene.bodies[body].x0
    from .generated import layout as LY

    q_ref = V.quaternion("controller.q_ref", c["q_ref"]) if "q_ref" in c else np.array(x0[LY.STATE_Q])
    null_bias = V.scalar("controller.null_bias", c.get("null_bias", 0.0))
    if null_bias != 0.0 and n <= 3:
        raise V.LavenderInputError("controller.null_bias", "needs more wheels than axes (a null space)",
                                   f", got {null_bias!r} with {n} wheels")
    return ControllerSpec(period, delay, Q, R, weights, q_ref, null_bias)


def _sensors(d: dict) -> dict:
    s = SF.table("sensors", d.get("sensors", {}), SENSOR_KEYS)
    out: dict[str, Any] = {k: V.scalar(f"sensors.{k}", s[k], nonnegative=True)
                           for k in ("attitude_noise", "gyro_noise", "wheel_speed_noise") if k in s}
    if "gyro_bias" in s:
        b = s["gyro_bias"]
        out["gyro_bias"] = tuple(V.vector("sensors.gyro_bias", b).tolist()) if isinstance(b, list) \
            else (V.scalar("sensors.gyro_bias", b),) * 3
    if "seed" in s:
        out["seed"] = V.integer("sensors.seed", s["seed"], minimum=0)
    return out


def _maneuver(d: dict) -> Maneuver:
    m = SF.table("maneuver", d.get("maneuver", {}), MANEUVER_KEYS, required=("angle_deg", "axis", "duration"))
    angle = V.scalar("maneuver.angle_deg", m["angle_deg"])
    if not abs(angle) <= 180.0:
        raise V.LavenderInputError("maneuver.angle_deg", "must be within ±180°", f", got {angle!r}")
    axis = V.vector("maneuver.axis", m["axis"])
    norm = float(np.linalg.norm(axis))
    if not norm > 0:
        raise V.LavenderInputError("maneuver.axis", "must be a non-zero vector", f", got {V._nums(axis)}")
    within = None if "settle_within" not in m else V.positive("maneuver.settle_within", m["settle_within"])
    Om0 = None if "Omega0" not in m else V.array("maneuver.Omega0", m["Omega0"], (None,))
    return Maneuver(angle, axis / norm, V.positive("maneuver.duration", m["duration"]),
                    V.positive("maneuver.settle_threshold_deg", m.get("settle_threshold_deg", 0.1)), within, Om0)


def _monte_carlo(d: dict) -> MonteCarloSpec | None:
    if "monte_carlo" not in d:
        return None
    m = SF.table("monte_carlo", d["monte_carlo"], MONTE_CARLO_KEYS)
    unc = V.scalar("monte_carlo.inertia_uncertainty", m.get("inertia_uncertainty", 0.0), nonnegative=True)
    if not unc < 0.5:
        raise V.LavenderInputError("monte_carlo.inertia_uncertainty", "must be below 0.5 (a relative spread)", f", got {unc!r}")
    return MonteCarloSpec(V.integer("monte_carlo.n", m.get("n", 20), minimum=1), unc,
                          V.integer("monte_carlo.seed", m.get("seed", 0), minimum=0))


def from_dict(d: dict, *, source: str = "") -> Spacecraft:
    """Build a :class:`Spacecraft` from the dict a spacecraft file reads into.

    Parameters
    ----------
    d : dict
        ``tomllib.load`` of the file.
    source : str, optional
        Where it came from (kept in ``Spacecraft.source``).

    Returns
    -------
    Spacecraft

    Raises
    ------
    LavenderInputError
        Naming the key path (``maneuver.axis``, ``body.wheels.J``) and the rule; nothing is built.
    """
    scene = SF.scene_from_dict(d, extra=SECTIONS)
    c = SF.table("controller", d.get("controller", {}), CONTROLLER_KEYS, required=("period",))
    body = _wheeled_body(scene, c.get("body"))
    n = int(np.size(scene.model_effects(body)["reaction_wheels"].values["J"]))
    ctrl = _controller(d, scene, body, n)
    sensors = _sensors(d)
    lag = V.scalar("actuator.lag", SF.table("actuator", d.get("actuator", {}), ACTUATOR_KEYS).get("lag", 0.0),
                   nonnegative=True)
    man = _maneuver(d)
    sim = SF.table("simulator", d.get("simulator", {}), SIMULATOR_KEYS)
    most, most_sub = _limits()
    default_dt = min(1e-3, ctrl.period) if ctrl.period / 1e-3 <= most_sub else ctrl.period / most_sub
    dt = V.dt("simulator.dt", sim.get("dt", default_dt))
    sub = ctrl.period / dt
    if not sub <= most_sub * (1 + 1e-9):
        raise V.LavenderInputError("simulator.dt", f"must divide the controller period {ctrl.period:g} s into at most "
                                   f"{most_sub:,} steps", f", got {dt!r}")
    if abs(sub - round(sub)) > 1e-9 * sub:
        raise V.LavenderInputError("simulator.dt", f"must divide the controller period {ctrl.period:g} s into whole steps",
                                   f", got {dt!r}")
    nd = ctrl.delay / dt
    if abs(nd - round(nd)) > 1e-9 * max(1.0, nd):
        raise V.LavenderInputError("simulator.dt", f"must divide the controller delay {ctrl.delay:g} s into whole steps",
                                   f", got {dt!r}")
    if not man.duration / ctrl.period <= most:
        raise V.LavenderInputError("maneuver.duration", f"would take {man.duration / ctrl.period:.3g} controller periods; "
                                   f"at most {most:,} are allowed", f", got {man.duration!r}")
    if man.Omega0 is not None and man.Omega0.size != n:
        raise V.LavenderInputError("maneuver.Omega0", f"needs one speed per wheel ({n})", f", got {man.Omega0.size}")
    name = SF.text("name", d["name"]) if "name" in d else body
    return Spacecraft(name, scene, body, ctrl, sensors, lag, man, dt, _monte_carlo(d), source)


def load(path: str | os.PathLike[str]) -> Spacecraft:
    """Read a spacecraft file (TOML; see the module docstring).

    Parameters
    ----------
    path : str or os.PathLike
        The file, or the name of a shipped one (:func:`shipped`).

    Returns
    -------
    Spacecraft

    Raises
    ------
    LavenderInputError
        A missing file, bad TOML, or a bad key (its path named).
    """
    p = Path(path)
    name = p.stem if p.suffix == ".toml" and p.parent == Path(".") else str(path)
    if not p.exists() and name in shipped():   # a shipped name ("cubesat6u" or "cubesat6u.toml")
        p = shipped()[name]
    return from_dict(SF.read_toml(p, field=str(path)), source=str(p))


def shipped() -> dict[str, Path]:
    """The spacecraft files shipped with the package, by name (file stem).

    Returns
    -------
    dict of str to Path
        ``cubesat6u`` (the 6U CubeSat of the worked example), ``cube_center`` and ``cube_corner``
        (``lavendersim lqr --scenario``), ``cube_pyramid4`` (``--layout pyramid4``).
    """
    return {p.stem: p for p in sorted(DATA.glob("*.toml"))}


# ---------------------------------------------------------------------------------------------
# designing and flying (lavendersim.control's one stack)
# ---------------------------------------------------------------------------------------------


def _stack():
    """lavendersim.control: the one control stack (design, Sensors, closed_loop, monte_carlo)."""
    from . import control

    return control


def _limits() -> tuple[int, int]:
    """closed_loop's bounds: (controller periods per run, Sim steps per period)."""
    from .wheel_control import MAX_SAMPLES, MAX_SUBSTEPS

    return MAX_SAMPLES, MAX_SUBSTEPS


def design(sc: Spacecraft) -> Any:
    """Design the file's controller: :func:`lavendersim.control.design` with its ``[controller]`` and ``[actuator]``.

    Parameters
    ----------
    sc : Spacecraft

    Returns
    -------
    lavendersim.control.Controller
    """
    c = sc.controller
    try:
        return _stack().design(sc.scene, sc.body, period=c.period, delay=c.delay, Q=c.Q, R=c.R, q_ref=c.q_ref,
                               null_bias=c.null_bias, actuator_lag=sc.actuator_lag, weights=c.weights or None)
    except V.LavenderInputError as exc:   # named as the file names it
        head, sep, rest = exc.field.partition("[")
        key = _DESIGN_KEYS.get(head, None)
        if key is None:
            raise
        raise V.LavenderInputError(key + sep + rest, exc.rule, exc.detail) from None


# design()'s argument -> the file's key
_DESIGN_KEYS = {"period": "controller.period", "delay": "controller.delay", "Q": "controller.Q", "R": "controller.R",
                "q_ref": "controller.q_ref", "null_bias": "controller.null_bias", "actuator_lag": "actuator.lag",
                "weights": "controller.weights", "body": "controller.body",
                **{k: f"controller.weights.{k}" for k in WEIGHT_KEYS}}


def sensors(sc: Spacecraft, *, noise: bool = True, seed: int | None = None) -> Any:
    """The file's ``[sensors]`` as :class:`lavendersim.control.Sensors` (``noise=False``: perfect measurements).

    Parameters
    ----------
    sc : Spacecraft
    noise : bool, default True
    seed : int, optional
        Overrides the file's seed.

    Returns
    -------
    lavendersim.control.Sensors
    """
    kw = dict(sc.sensors) if noise else {}
    if seed is not None:
        kw["seed"] = seed
    return _stack().Sensors(**kw)


def fly(sc: Spacecraft, controller: Any, *, noise: bool = True, scene: Scene | None = None, seed: int | None = None,
        backend: str = "auto") -> Any:
    """Fly the file's maneuver: :func:`lavendersim.control.closed_loop` from :attr:`Spacecraft.q0` back to q_ref.

    Parameters
    ----------
    sc : Spacecraft
    controller : lavendersim.control.Controller
        From :func:`design`.
    noise : bool, default True
        The file's sensor models (False: perfect measurements).
    scene : Scene, optional
        Another plant (Monte Carlo: a perturbed inertia); default the file's.
    seed : int, optional
        Overrides the sensors' seed.
    backend : {"auto", "c", "numpy"}, default "auto"

    Returns
    -------
    lavendersim.control.Response
    """
    m = sc.maneuver
    try:
        return _stack().closed_loop(sc.scene if scene is None else scene, controller, T=m.duration, q0=sc.q0,
                                    Omega0=m.Omega0, sensors=sensors(sc, noise=noise, seed=seed), dt=sc.dt,
                                    threshold_deg=m.settle_threshold_deg, backend=backend)
    except V.LavenderInputError as exc:   # named as the file names it
        head, sep, rest = exc.field.partition("[")
        key = _FLY_KEYS.get(head)
        if key is None:
            raise
        raise V.LavenderInputError(key + sep + rest, exc.rule, exc.detail) from None


# closed_loop()'s argument -> the file's key
_FLY_KEYS = {"T": "maneuver.duration", "Omega0": "maneuver.Omega0", "dt": "simulator.dt", "delay": "controller.delay",
             "threshold_deg": "maneuver.settle_threshold_deg", **{k: f"sensors.{k}" for k in SENSOR_KEYS}}


def external_effects(sc: Spacecraft) -> list[str]:
    """The effects that can change the controlled body's total angular momentum (a joint, force effects on it).

    Parameters
    ----------
    sc : Spacecraft

    Returns
    -------
    list of str
        Effect names; empty for a free spacecraft (its |L| must then be conserved).
    """
    return [e.name for e in sc.scene.effects if e.name != "reaction_wheels" and e.body in (None, sc.body)]


def figures(sc: Spacecraft, controller: Any, response: Any) -> dict:
    """The design and the maneuver's figures as plain values (JSON-ready but for an infinite settling time).

    Parameters
    ----------
    sc : Spacecraft
    controller : lavendersim.control.Controller
    response : lavendersim.control.Response

    Returns
    -------
    dict
        ``spacecraft``, ``file``, ``body``, ``wheels``; ``design`` (period, delay, actuator_lag,
        controllability_rank, n_states, poles (discrete: real, imag, max modulus), Omega_ref, q_ref); ``maneuver``
        (angle_deg, axis, duration, settle_threshold_deg, settle_within); ``figures``: settling_time (s),
        settled_within (bool or None), peak_torque and peak_wheel_speed (per wheel and max, N·m and rad/s),
        torque_limit, speed_limit, within_limits, final_error_deg, L_drift (relative drift of the total angular
        momentum, meaningful without external torque: ``external_effects`` empty), external_effects.
    """
    d = controller.figures()
    design_ = {k: d[k] for k in ("period", "delay", "actuator_lag", "controllability_rank", "n_states", "poles_real",
                                 "poles_imag", "max_pole_modulus", "Omega_ref", "q_ref")}
    f = response.figures()
    st = f["settling_time"]
    m = sc.maneuver
    ext = external_effects(sc)
    fig = {"settling_time": st, "settled_within": None if m.settle_within is None else bool(st <= m.settle_within),
           "peak_torque": f["peak_torque"], "peak_torque_max": float(np.max(f["peak_torque"])),
           "peak_wheel_speed": f["peak_wheel_speed"], "peak_wheel_speed_max": float(np.max(f["peak_wheel_speed"])),
           "torque_limit": f["torque_limit"], "speed_limit": f["speed_limit"], "within_limits": f["within_limits"],
           "final_error_deg": f["final_error_deg"], "L_drift": f["L_drift"], "external_effects": ext}
    return {"spacecraft": sc.name, "file": sc.source, "body": sc.body, "wheels": sc.n_wheels, "design": design_,
            "maneuver": {"angle_deg": m.angle_deg, "axis": m.axis.tolist(), "duration": m.duration,
                         "settle_threshold_deg": m.settle_threshold_deg, "settle_within": m.settle_within},
            "sensors": dict(sc.sensors), "figures": fig}


# ---------------------------------------------------------------------------------------------
# Monte Carlo: sensor seeds and the inertia tensor
# ---------------------------------------------------------------------------------------------


def monte_carlo(sc: Spacecraft, controller: Any, n: int | None = None, *, executor: Any = None,
                backend: str = "auto", progress: Any = None) -> dict:
    """Fly the nominal controller on ``n`` plants (:func:`lavendersim.control.monte_carlo`): the body's inertia
    perturbed by ``[monte_carlo] inertia_uncertainty`` and the file's sensors with a new seed per run.

    Parameters
    ----------
    sc : Spacecraft
    controller : lavendersim.control.Controller
        The nominal design.
    n : int, optional
        Runs (default the file's ``monte_carlo.n``, else 20).
    executor : lavendersim.executor.Executor, optional
        Where the runs go (default: this process).
    backend : {"auto", "c", "numpy"}, default "auto"
    progress : callable, optional
        Called with the number of runs just done (see :func:`lavendersim.control.monte_carlo`).

    Returns
    -------
    dict
        control.monte_carlo's summary (``n``, ``seed``, ``inertia_spread``, ``failures``, percentiles p50, p90,
        p100 of ``settling_time``, ``peak_torque``, ``peak_wheel_speed``, ``L_drift``, the ``samples``) plus
        ``settle_within`` (the file's stated time, s, or None) and ``settled_within`` (runs settled within it).
    """
    spec = sc.monte_carlo or MonteCarloSpec(20, 0.0, 0)
    n = spec.n if n is None else V.integer("monte-carlo", n, minimum=1)
    m = sc.maneuver
    portable = copy.copy(controller)   # flying needs no linearization, and a StateSpace does not pickle (processes)
    portable.lin = None
    out = _stack().monte_carlo(sc.scene, portable, n=n, seed=spec.seed, T=m.duration, q0=sc.q0, Omega0=m.Omega0,
                               sensors=sensors(sc), inertia_spread=spec.inertia_uncertainty, dt=sc.dt,
                               threshold_deg=m.settle_threshold_deg, backend=backend, executor=executor,
                               progress=progress)
    limit = m.settle_within
    out["settle_within"] = limit
    out["settled_within"] = sum(1 for r in out["samples"] if r["settled"] and (limit is None or r["settling_time"] <= limit))
    return out
