"""ReactionWheelCube-v0: a cube with three body-axis reaction wheels on a world-anchored spherical
joint, stepped by the LavenderSim runtime (C backend by default, NumPy optional).

Tasks
  * ``task="center"`` (default): joint at the cube's centre (no gravity torque); hold the target
    attitude (identity unless ``target_q`` is given). Episodes start at rest, rotated by a uniform
    random angle in [0, ``init_angle_deg``] (default 20°) about a uniformly random axis.
  * ``task="corner"``: Cubli-like balancing on one corner under gravity (joint at the corner
    −s/2 (1,1,1), target: body diagonal vertical). Episodes start at rest, tilted by a uniform
    random angle in [0, ``init_angle_deg``] (default 3°) about a random horizontal axis.

Model (lavendersim.control.chapter_cube, a Scene): 15 cm, 1 kg cube, wheel spin inertia 5.7e-4 kg·m², motor
torque limit 0.2 N·m, wheel speed limit 400 rad/s, cube angular damping ``damping`` = 1e-3 N·m·s/rad.

Action: ``Box(-1, 1, (3,), float32)`` — wheel motor torques as fractions of the torque limit
(x, y, z wheels). Values outside [-1, 1] are saturated (clipped); the simulator saturates again at
the wheel speed limit (no torque that would spin a wheel at the limit faster). An action of the
wrong shape or with NaN/inf raises ``LavenderInputError`` naming ``action``.

Observation: ``Box(float32, (10,))`` = cube attitude q (x, y, z, w) (in [-1, 1]), cube body rates
omega_b (rad/s, 3, within ±200), wheel speeds relative to the cube Omega (rad/s, 3, within ±2 ×
the speed limit).

Reward (per step): ``-(theta² + 0.05 |omega_b|² + 0.01 |action|²)`` with theta the rotation angle
(rad) between the cube and the target attitude — 0 is perfect holding.

Termination: the simulator diverged (non-finite state; ``info["diverged"]`` holds the message),
a rate left the observation bounds (``info["out_of_bounds"]``), or, for the corner task, the tilt of the body diagonal from vertical exceeds ``max_tilt_deg``
(default 20°). Truncation: ``max_episode_steps`` = 1000 steps (10 s at the default 0.01 s control
period) through gymnasium's TimeLimit when made with ``gymnasium.make``; the unwrapped env does
not truncate by itself.

Seeding: ``reset(seed=...)`` seeds ``self.np_random``; the same seed gives the same episode.
``reset(options={"q": ..., "omega_b": ..., "Omega": ...})`` sets the initial state explicitly.

Rendering: ``render_mode="rgb_array"`` returns an (H, W, 3) uint8 image drawn with matplotlib's
Agg canvas (cube edges and body axes; no display needed); ``None`` renders nothing. Any other mode
(``"human"``, ``"rgb_array_list"``, ...) raises LavenderInputError naming ``render_mode``, also through
``gymnasium.make`` (the registered entry point is :func:`make_env`, so gymnasium does not swap an
unsupported mode for a wrapper of its own).

Every argument is validated: unknown keyword arguments (of the env or of the chapter_cube it builds),
a bad ``seed`` or ``options`` raise LavenderInputError naming it.
"""
from __future__ import annotations

import inspect
import math
from collections.abc import Callable, Mapping, Sequence
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import ArrayLike

from .. import backends
from .. import control as lc
from .. import validate as V
from .._install import require
from ..errors import DivergenceError
from ..generated import layout as LY
from ..kernels import K

if TYPE_CHECKING:
    import gymnasium as gym
    from gymnasium import spaces
    from matplotlib.figure import Figure

    from ..sim import Sim
else:   # at run time through require: a missing gymnasium names the extra that installs it
    gym = require("gymnasium", "gym", "the ReactionWheelCube-v0 environment")
    spaces = require("gymnasium.spaces", "gym", "the ReactionWheelCube-v0 environment")

BODY = lc.BODY
MAX_SUBSTEPS = 100_000  # simulator steps per control step (control_dt / dt), at most

_NW = LY.WHEELS_BODY_AXES   # the cube's three wheels: the first slots of the Sim's wheel arrays
# the observation's fields: q (x, y, z, w), omega_b (rad/s), the three wheel rates Omega (rad/s)
OBS_Q, OBS_OMEGA_B, OBS_OMEGA = slice(0, 4), slice(4, 7), slice(7, 10)


class ReactionWheelCubeEnv(gym.Env):
    """The reaction-wheel cube as a Gymnasium environment (``lavendersim:ReactionWheelCube-v0``).

    Action: wheel torques in [-1, 1]³ scaled to the motor limit and saturated. Observation (float32):
    attitude q (x, y, z, w), body rates omega_b (rad/s), wheel rates Omega (rad/s).

    Parameters
    ----------
    task : {"center", "corner"}, optional
        Balance on the centre joint or on a corner (Cubli-like).
    backend : {"auto", "c", "numpy"}, optional
        Simulator backend.
    render_mode : {None, "rgb_array"}, optional
    control_dt : float, optional
        Seconds per env step (a multiple of `dt`).
    dt : float, optional
        Simulator step, s.
    damping : float, optional
        Joint damping, N·m·s/rad.
    init_angle_deg : float or None, optional
        Largest random initial tilt from the target, degrees.
    max_tilt_deg : float, optional
        Terminate beyond this error, degrees.
    target_q : array_like, shape (4,), optional
        Target attitude (x, y, z, w).
    **model_params
        lavendersim.control.chapter_cube's keywords (mass, size, J, torque_limit, speed_limit,
        wheel_damping, g, motor).

    Examples
    --------
    >>> import gymnasium as gym, lavendersim   # doctest: +SKIP
    >>> env = gym.make("lavendersim:ReactionWheelCube-v0")   # doctest: +SKIP
    >>> obs, info = env.reset(seed=0)   # doctest: +SKIP
    >>> obs, reward, terminated, truncated, info = env.step([0.0, 0.0, 0.0])   # doctest: +SKIP
    """

    metadata = {"render_modes": ["rgb_array"], "render_fps": 50}
    action_space: spaces.Box
    observation_space: spaces.Box

    @V.keywords
    def __init__(self, task: str = "center", backend: str = "auto", render_mode: str | None = None, *,
                 control_dt: float = 0.01, dt: float = 1e-3, damping: float = 1e-3, init_angle_deg: float | None = None,
                 max_tilt_deg: float = 20.0, target_q: ArrayLike | None = None,
                 **model_params: Any) -> None:
        super().__init__()
        task = V.choice("task", task, lc.SCENARIOS)
        if render_mode is not None and (not isinstance(render_mode, str) or render_mode not in self.metadata["render_modes"]):
            raise V.LavenderInputError("render_mode", "must be None or 'rgb_array'", f", got {render_mode!r}")
        self.render_mode = render_mode
        known = sorted(set(inspect.signature(lc.chapter_cube).parameters) - {"scenario", "damping", "q", "omega_b", "name"})
        unknown = sorted(set(model_params) - set(known))
        if unknown:
            raise V.LavenderInputError(unknown[0], "unknown keyword argument of ReactionWheelCube-v0",
                                       f"; known: task, backend, render_mode, control_dt, dt, damping, init_angle_deg, "
                                       f"max_tilt_deg, target_q and the chapter cube's {', '.join(known)}")
        self.backend = backends.resolve(backend)
        self.task = task
        self._cube = {"damping": damping, **model_params}
        self.scene = lc.chapter_cube(task, **self._cube)   # the template: validates the parameters
        wheels = self.scene.model_effects(BODY)["reaction_wheels"].values
        self.torque_limit, self.speed_limit = float(wheels["torque_limit"]), float(wheels["speed_limit"])
        self.size = float(self.scene.bodies[BODY].shape[1][0])
        self.r_b = lc.cube_r_b(task, self.size)
        self.dt = V.dt("dt", dt)
        self.control_dt = V.dt("control_dt", control_dt)
        ratio = self.control_dt / self.dt
        if not ratio <= MAX_SUBSTEPS:
            raise V.LavenderInputError("dt", f"control_dt / dt = {ratio:.3g} simulator steps per control step; at most "
                                       f"{MAX_SUBSTEPS:,} are allowed", f", got dt = {dt!r}")
        self.substeps = int(round(ratio))
        if self.substeps < 1 or abs(self.substeps * self.dt - self.control_dt) > 1e-9 * self.control_dt:
            raise V.LavenderInputError("control_dt", f"must be a whole multiple of dt = {self.dt:g}", f", got {control_dt!r}")
        self.init_angle_deg = V.scalar("init_angle_deg", (20.0 if self.task == "center" else 3.0)
                                       if init_angle_deg is None else init_angle_deg, nonnegative=True)
        self.max_tilt_deg = V.positive("max_tilt_deg", max_tilt_deg)
        if target_q is not None and self.task == "corner":
            raise V.LavenderInputError("target_q", "the corner task's target is fixed (body diagonal vertical)")
        self.target_q = lc.cube_upright_q(task) if target_q is None else V.quaternion("target_q", target_q)
        self._tq = tuple(float(v) for v in self.target_q)
        self.action_space = spaces.Box(-1.0, 1.0, shape=(3,), dtype=np.float32)
        # finite bounds (gymnasium's checker rejects infinite ones): leaving them ends the episode
        self.rate_bound = 200.0                               # rad/s, cube
        self.wheel_bound = 2.0 * self.speed_limit       # rad/s
        hi = np.array([1.0] * 4 + [self.rate_bound] * 3 + [self.wheel_bound] * 3, dtype=np.float32)
        self.observation_space = spaces.Box(-hi, hi, dtype=np.float32)
        self.sim: Sim | None = None
        self._fig: Figure | None = None
        self._last_u = np.zeros(3)
        self._io: _StepIO | None = None

    # ---- pickle and deepcopy -----------------------------------------------------------------
    def __getstate__(self) -> dict:
        """The env pickles (and deep-copies) as its settings, spaces, random generator and Sim (which pickles its whole
        state, held commands and counters included; see Sim.__reduce__): reset/step on the copy give the original's
        numbers bit for bit. The step path's handles on the Sim (memoryviews) are taken again on the next step; a
        figure is drawn again on the next render."""
        state = self.__dict__.copy()
        state["_io"], state["_fig"] = None, None
        state.pop("_ax", None)
        return state

    # ---- helpers --------------------------------------------------------------------------
    def _make_sim(self, q0: np.ndarray, omega_b: np.ndarray, Omega: np.ndarray) -> Sim:
        """A Sim of the chapter cube at q0, omega_b (rad/s) with wheel rates Omega (rad/s), RK4 at dt."""
        from ..sim import Sim

        sim = Sim(lc.chapter_cube(self.task, q=q0, omega_b=omega_b, **self._cube), dt=self.dt, integrator="rk4",
                  backend=self.backend)
        if np.any(Omega != 0):
            sim.set_state(BODY, Omega=Omega)
        return sim

    def _live_sim(self) -> Sim:
        """The episode's Sim (RuntimeError before the first reset and after close)."""
        if self.sim is None:
            raise RuntimeError("ReactionWheelCube-v0: call reset() first")
        return self.sim

    def _raw(self) -> np.ndarray:
        """[q (4), omega_b (3), Omega (3)] of the cube (a copy, from the Sim's views)."""
        sim, raw = self._live_sim(), np.empty(10)
        raw[OBS_Q], raw[OBS_OMEGA_B], raw[OBS_OMEGA] = sim.q[0], sim.omega_b[0], sim.Omega[0, :_NW]
        return raw

    def _obs(self, raw=None) -> np.ndarray:
        raw = self._raw() if raw is None else raw
        # np.clip's bounds, as ufuncs (the same numbers; cheaper for a 10-vector)
        return np.minimum(np.maximum(raw, self.observation_space.low), self.observation_space.high).astype(np.float32)

    def angle_error_deg(self, q: Sequence[float] | np.ndarray | None = None) -> float:
        """Rotation angle between the cube and the target attitude, degrees: the generated kernel
        quat_error_angle, 2 atan2(|e_v|, |e_w|) with e = q_t* ⊗ q (accurate near 0 and 180°).

        Parameters
        ----------
        q : array_like, shape (4,), optional
            An attitude (default: the current one).

        Returns
        -------
        float
        """
        q = self._live_sim().state(BODY).q if q is None else q
        return math.degrees(error_angle_fn()(float(q[0]), float(q[1]), float(q[2]), float(q[3]), *self._tq))

    def tilt_deg(self, q: ArrayLike | None = None) -> float:
        """Corner task: angle of the body diagonal (pivot → COM) from vertical, degrees.

        Parameters
        ----------
        q : array_like, shape (4,), optional
            An attitude (default: the current one).

        Returns
        -------
        float
        """
        q = self._live_sim().state(BODY).q if q is None else q
        d = K.quat_rotate(q, np.ones(3) / math.sqrt(3.0))
        return float(math.degrees(math.atan2(math.hypot(float(d[0]), float(d[1])), float(d[2]))))

    def _initial_q(self) -> np.ndarray:
        return initial_q(self.np_random, self.task, self.target_q, self.init_angle_deg)

    # ---- gymnasium API --------------------------------------------------------------------
    def reset(self, *, seed: int | None = None,
              options: dict[str, Any] | None = None) -> tuple[np.ndarray, dict[str, Any]]:
        """Start an episode (Gymnasium API).

        Parameters
        ----------
        seed : int or None, optional
            Seeds the initial-tilt generator.
        options : dict, optional
            ``q`` (4,), ``omega_b`` (3,) rad/s, ``Omega`` (3,) rad/s: a given initial state.

        Returns
        -------
        observation : ndarray, shape (10,), float32
        info : dict
            ``t``, ``angle_error_deg``, ``torque_applied`` (and ``tilt_deg`` on the corner).

        Raises
        ------
        LavenderInputError
            On a bad seed or option; nothing changes.
        """
        if seed is not None:
            seed = V.integer("seed", seed, minimum=0)  # a Python int (gymnasium refuses numpy integers)
        if options is not None and not isinstance(options, Mapping):
            raise V.LavenderInputError("options", "expected a dict or None", f", got {V._describe(options)}")
        unknown = sorted(str(k) for k in (options or {}) if k not in ("q", "omega_b", "Omega"))
        if unknown:
            raise V.LavenderInputError(f"options.{unknown[0]}", "unknown reset option; known: q, omega_b, Omega")
        options = dict(options or {})
        # everything is validated before the generator is re-seeded: a rejected reset changes nothing
        q_given = V.quaternion("options.q", options["q"]) if "q" in options else None
        w0 = V.vector("options.omega_b", options.get("omega_b", (0.0, 0.0, 0.0)))
        Om0 = V.vector("options.Omega", options.get("Omega", (0.0, 0.0, 0.0)))
        if np.max(np.abs(w0)) > self.rate_bound:
            raise V.LavenderInputError("options.omega_b", f"must be within ±{self.rate_bound:g} rad/s (the observation bounds)")
        if np.max(np.abs(Om0)) > self.wheel_bound:
            raise V.LavenderInputError("options.Omega", f"must be within ±{self.wheel_bound:g} rad/s (the observation bounds)")
        super().reset(seed=seed)
        q0 = self._initial_q() if q_given is None else q_given
        self.sim = self._make_sim(q0, w0, Om0)
        self._last_u = np.zeros(3)
        return self._obs(), self._info()

    def _info(self, angle=None, tilt=None, **extra) -> dict:
        info = {"t": float(self._live_sim().t), "angle_error_deg": self.angle_error_deg() if angle is None else angle,
                "torque_applied": np.asarray(self._last_u, dtype=float)}
        if self.task == "corner":
            info["tilt_deg"] = self.tilt_deg() if tilt is None else tilt
        info.update(extra)
        return info

    def step(self, action: ArrayLike) -> tuple[np.ndarray, float, bool, bool, dict[str, Any]]:
        """Advance `control_dt` with the wheel torques `action` (Gymnasium API).

        Parameters
        ----------
        action : array_like, shape (3,)
            Wheel torques as fractions of the motor limit, clipped to [-1, 1].

        Returns
        -------
        observation : ndarray, shape (10,), float32
        reward : float
            ``-(theta² + 0.05 |omega_b|² + 0.01 |action|²)``, theta the attitude error in rad.
        terminated : bool
            Beyond `max_tilt_deg`, or the simulation diverged (``info["diverged"]``).
        truncated : bool
        info : dict

        Raises
        ------
        LavenderInputError
            On an action that is not 3 finite real numbers.
        RuntimeError
            Before :meth:`reset`.
        """
        sim = self.sim
        if sim is None:
            raise RuntimeError("ReactionWheelCube-v0: call reset() before step()")
        # the step path: a few reads and writes through memoryviews, one C call (Sim.run's fast path), float
        # arithmetic and one float32 array; the numbers are those of Sim.run and the NumPy formulation before
        io = self._io if self._io is not None and self._io.sim is sim else self._bind(sim)
        # real finite numbers of shape (3,): complex, bool, str, None, NaN/inf and other shapes are rejected
        a0, a1, a2 = _action3(action)
        # validated (finite, saturated) above: written straight into the held command (set_wheel_command's array)
        tl, cmd = io.torque_limit, io.command
        # (typeshed's memoryview.__setitem__ takes ints only; this view's format is "d")
        cmd[0], cmd[1], cmd[2] = a0 * tl, a1 * tl, a2 * tl  # type: ignore[call-overload]
        if io.advance is None or not io.advance(self.substeps):   # the C fast path of Sim.run, else Sim.run
            try:
                sim.run(self.substeps)
            except DivergenceError as exc:
                self._last_u = io.applied_row.copy()
                return self._diverged({"diverged": str(exc)})
            if not all(map(math.isfinite, io.x.tolist() + io.Omega.tolist())):
                self._last_u = io.applied_row.copy()
                return self._diverged({})
        self._last_u = u = io.applied_row.copy()
        r = io.x.tolist()
        q, w = r[LY.STATE_Q], r[LY.STATE_OMEGA_B]
        w0, w1, w2 = w
        W0, W1, W2 = io.Omega.tolist()
        q0, q1, q2, q3 = q
        t0, t1, t2, t3 = self._tq
        theta = io.error_angle(q0, q1, q2, q3, t0, t1, t2, t3)
        angle = math.degrees(theta)
        reward = -(theta * theta + 0.05 * (w0 * w0 + w1 * w1 + w2 * w2) + 0.01 * (a0 * a0 + a1 * a1 + a2 * a2))
        ob = io.obs_mv          # the float32 observation, written through a memoryview (C's double -> float cast)
        ob[0], ob[1], ob[2], ob[3], ob[4], ob[5], ob[6], ob[7], ob[8], ob[9] = q0, q1, q2, q3, w0, w1, w2, W0, W1, W2
        obs = io.obs.copy()
        info = {"t": io.counters.steps * io.dt, "angle_error_deg": angle, "torque_applied": u}
        terminated = False
        if self.task == "corner":
            info["tilt_deg"] = tilt = self.tilt_deg(q)
            terminated = tilt > self.max_tilt_deg
        wb, Ob = io.w_in, io.Om_in       # within both the termination and the observation bounds: nothing to do
        if not (-wb <= w0 <= wb and -wb <= w1 <= wb and -wb <= w2 <= wb and -Ob <= W0 <= Ob and -Ob <= W1 <= Ob
                and -Ob <= W2 <= Ob and -1.0 <= q0 <= 1.0 and -1.0 <= q1 <= 1.0 and -1.0 <= q2 <= 1.0
                and -1.0 <= q3 <= 1.0):
            if max(abs(w0), abs(w1), abs(w2)) > self.rate_bound or max(abs(W0), abs(W1), abs(W2)) > self.wheel_bound:
                terminated, info["out_of_bounds"] = True, True
            # the observation bounds (float32 numbers: clipping after the cast equals np.clip before it)
            obs = np.minimum(np.maximum(obs, self.observation_space.low), self.observation_space.high)
        return obs, reward, terminated, False, info

    def _diverged(self, extra: dict) -> tuple[np.ndarray, float, bool, bool, dict[str, Any]]:
        """The step's result when the simulation diverged: the observation of the (restored or non-finite) state with
        non-finite numbers as 0, reward -1e3, terminated, ``info["diverged"]`` (the message)."""
        obs = np.nan_to_num(self._obs(self._raw()), nan=0.0, posinf=0.0, neginf=0.0)
        extra.setdefault("diverged", "non-finite state")
        return obs, -1e3, True, False, self._info(angle=float("nan"), tilt=float("nan"), **extra)

    def _bind(self, sim: Sim) -> _StepIO:
        """The step path's handles on `sim` (taken once per Sim: reset builds a new one)."""
        self._io = _StepIO(self, sim)
        return self._io

    def render(self) -> np.ndarray | None:
        """The current frame as an (H, W, 3) uint8 image (render_mode "rgb_array"), or None."""
        if self.render_mode is None:
            return None
        from matplotlib.backends.backend_agg import FigureCanvasAgg

        if self._fig is None:
            from matplotlib.figure import Figure

            self._fig = Figure(figsize=(3.2, 3.2), dpi=100)
            FigureCanvasAgg(self._fig)
            self._ax = self._fig.add_subplot(projection="3d")
        from ..figures import axis_style

        ax = self._ax
        ax.cla()
        s = self.size
        st = self.sim.state(BODY) if self.sim is not None else None
        q = st.q if st is not None else self.target_q
        R = K.quat_to_matrix(q)
        com = R @ self.r_b
        corners = np.array([[i, j, k] for i in (-1, 1) for j in (-1, 1) for k in (-1, 1)], float) * s / 2
        pts = com + corners @ R.T
        for a_ in range(8):
            for b_ in range(a_ + 1, 8):
                if np.sum(corners[a_] != corners[b_]) == 1:
                    ax.plot(*pts[[a_, b_]].T, color="0.4", lw=1)
        for i in range(3):   # body x, y, z in the house colours (lavendersim.figures.AXIS_STYLE)
            ax.quiver(*com, *(R[:, i] * s * 0.9), color=axis_style(i)["color"], lw=2)
        lim = s * 1.2
        ax.set_xlim(-lim, lim); ax.set_ylim(-lim, lim); ax.set_zlim(-lim * (0.3 if self.task == "corner" else 1), lim * (1.7 if self.task == "corner" else 1))
        ax.set_title(f"t = {0 if self.sim is None else self.sim.t:.2f} s", fontsize=8)
        canvas = self._fig.canvas
        assert isinstance(canvas, FigureCanvasAgg)   # (set above)
        canvas.draw()
        return np.asarray(canvas.buffer_rgba())[..., :3].copy()

    def close(self) -> None:
        """Release the simulator and the figure."""
        self._fig = None
        self.sim = None


class _StepIO:
    """What ReactionWheelCubeEnv.step reads and writes on its Sim, taken once per Sim: flat float64 memoryviews of
    body 0's state row, wheel rates and held command (element access without NumPy's per-call cost), its applied
    torques' row, the Stepper's ``advance`` (Sim.run's C fast path for this many substeps; None where Sim.run
    would not take it), a float32 observation buffer with a memoryview, and the bounds within which neither a
    termination bound nor an observation bound is reached (Python floats)."""

    __slots__ = ("sim", "x", "Omega", "command", "applied", "applied_row", "advance", "counters", "dt", "torque_limit",
                 "obs", "obs_mv", "w_in", "Om_in", "error_angle")
    sim: Sim
    x: memoryview[float]
    Omega: memoryview[float]
    command: memoryview[float]
    applied: memoryview[float]
    applied_row: np.ndarray
    advance: Callable[[int], bool] | None
    counters: Any
    dt: float
    torque_limit: float
    obs: np.ndarray
    obs_mv: memoryview[float]
    w_in: float
    Om_in: float
    error_angle: Callable[..., float]

    def __init__(self, env: ReactionWheelCubeEnv, sim: Sim) -> None:
        def flat(a: np.ndarray) -> memoryview[float]:
            return a.data.cast("B").cast("d")

        self.sim = sim
        m = sim.model
        self.x = flat(m.state[0])
        self.Omega, self.command, self.applied = flat(m.Omega[0, :_NW]), flat(m.command[0, :_NW]), flat(m.applied[0, :_NW])
        self.applied_row = m.applied[0, :_NW]
        self.advance = m.advance if 1 <= env.substeps <= m.fast_steps else None
        self.counters, self.dt = m.counters, sim.dt     # sim.t = steps * dt
        self.torque_limit = float(env.torque_limit)
        self.obs = np.zeros(10, np.float32)
        self.obs_mv = self.obs.data.cast("B").cast("f")
        high = env.observation_space.high
        self.w_in = min(float(env.rate_bound), float(high[4]))
        self.Om_in = min(float(env.wheel_bound), float(high[7]))
        self.error_angle = error_angle_fn()


_ERROR_ANGLE: list = []


def error_angle_fn() -> Callable[..., float]:
    """The generated kernel quat_error_angle as a function of eight numbers, chosen once per process.

    Returns
    -------
    callable
        ``f(q0, q1, q2, q3, t0, t1, t2, t3) -> float``: the angle between attitudes q and t (each (x, y, z, w)),
        rad in [0, π]; the C printing through ``scalar_kernel`` (one call, no arrays) when the compiled backend
        loads, else the NumPy printing.
    """
    if not _ERROR_ANGLE:
        try:
            from ..backends import c_backend
            fn = c_backend.scalar_kernel("quat_error_angle")
        except ImportError:          # not built, or stale (StaleBuildError): the NumPy printing, same formula
            from ..kernels import K

            def fn(q0, q1, q2, q3, t0, t1, t2, t3):
                return float(K.quat_error_angle((q0, q1, q2, q3), (t0, t1, t2, t3)))
        _ERROR_ANGLE.append(fn)
    return _ERROR_ANGLE[0]


def _action3(action: ArrayLike) -> tuple[float, float, float]:
    """The action as three floats saturated to [-1, 1] (:func:`_action`'s numbers): a float ndarray of shape (3,)
    with finite entries takes a shortcut; anything else V.array's checks (LavenderInputError naming ``action``)."""
    if type(action) is np.ndarray and action.shape == (3,) and action.dtype.kind == "f":
        a0, a1, a2 = action.tolist()
        if a0 - a0 == 0.0 and a1 - a1 == 0.0 and a2 - a2 == 0.0:     # finite (inf - inf and NaN are NaN)
            return (-1.0 if a0 < -1.0 else 1.0 if a0 > 1.0 else a0, -1.0 if a1 < -1.0 else 1.0 if a1 > 1.0 else a1,
                    -1.0 if a2 < -1.0 else 1.0 if a2 > 1.0 else a2)
    a0, a1, a2 = _action(action).tolist()
    return a0, a1, a2


def _action(action: ArrayLike) -> np.ndarray:
    """The action as float64 (3,), saturated to [-1, 1]; V.array's checks (a float ndarray of shape (3,) with
    finite entries takes a shortcut to the same result)."""
    if type(action) is np.ndarray and action.shape == (3,) and action.dtype.kind == "f":
        a = action.astype(np.float64)
        if np.isfinite(a).all():
            return np.minimum(np.maximum(a, -1.0), 1.0)
    return np.clip(V.array("action", action, (3,)), -1.0, 1.0)


def initial_q(rng: np.random.Generator, task: str, target_q: np.ndarray, init_angle_deg: float) -> np.ndarray:
    """An episode's initial attitude drawn from rng.

    Parameters
    ----------
    rng : numpy.random.Generator
        The episode's random generator.
    task : {"center", "corner"}
        "center": a uniform random axis; "corner": a random horizontal world axis.
    target_q : ndarray, (4,)
        The target attitude R_WB, (x, y, z, w).
    init_angle_deg : float
        Largest initial rotation from the target, degrees (the angle is uniform in [0, init_angle_deg]).

    Returns
    -------
    ndarray, (4,)
        The initial attitude, (x, y, z, w): the target rotated by the drawn angle about the drawn axis.
    """
    angle = float(rng.uniform(0.0, init_angle_deg))
    if task == "center":
        axis = rng.normal(size=3)
        while np.linalg.norm(axis) < 1e-9:
            axis = rng.normal(size=3)
        return lc.rotated(target_q, axis, angle)
    phi = float(rng.uniform(0.0, 2 * math.pi))
    axis_w = np.array([math.cos(phi), math.sin(phi), 0.0])
    axis_b = K.world_to_body(target_q, axis_w)
    return lc.rotated(target_q, axis_b, angle)


def make_env(**kwargs: Any) -> ReactionWheelCubeEnv:
    """The entry point registered for ReactionWheelCube-v0: builds :class:`ReactionWheelCubeEnv`.

    A plain function (no ``metadata``), so ``gymnasium.make`` passes ``render_mode`` through unchanged and
    an unsupported mode such as ``"human"`` is rejected by the env instead of wrapped.

    Parameters
    ----------
    **kwargs
        Passed to :class:`ReactionWheelCubeEnv`.

    Returns
    -------
    ReactionWheelCubeEnv
    """
    return ReactionWheelCubeEnv(**kwargs)
