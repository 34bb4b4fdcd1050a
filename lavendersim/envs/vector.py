"""ReactionWheelCube-v0 as a Gymnasium vector environment: N cubes in one Sim, stepped by one batched call.

``gymnasium.make_vec("lavendersim:ReactionWheelCube-v0", num_envs=N, vectorization_mode="vector_entry_point")``
builds :class:`ReactionWheelCubeVectorEnv`. Each sub-environment is the single environment (same task,
model, spaces, reward, termination; see lavendersim.envs.reaction_wheel_cube): body ``cube{i}`` of one Sim,
on its own spherical joint, with its own wheels, under the scene-wide gravity and damping. One ``step``
sets every wheel command at once and advances all N cubes with one ``Sim.run`` (one C call on the C
backend), so its observations are those of N single environments stepped alike (bitwise on one backend).

Gymnasium 1.x rules: autoreset in next-step mode (``metadata["autoreset_mode"]``): a sub-environment that
terminated or truncated is reset by the next ``step``, which ignores its action and returns its first
observation with reward 0, terminated and truncated False. Truncation after ``max_episode_steps`` steps
(1000 when made through gymnasium, as the TimeLimit of the single env). Seeding per sub-environment:
``reset(seed=s)`` seeds sub-environment i with s + i (as SyncVectorEnv does), ``reset(seed=[s0, s1, ...])``
each with its own, None keeps the generators. ``reset(options={"reset_mask": mask})`` resets the masked ones.

Speed: the cubes are advanced by one C call per step; ``lavendersim.backends.c_backend.threads(2)`` (process-wide)
shares them over two threads, with bitwise the same results (tests/test_vector_env.py). The step's ``Sim.run`` takes
the Sim's C fast path (``Stepper.advance``, enabled for any N by ``Sim.fast_chunks``): the same checks at the end of
the step and the same numbers as the Python path, which it falls back to for anything those checks refuse; it holds
the GIL while the cubes are stepped. The rest of a step is a fixed number of NumPy calls on preallocated buffers
(no Python loop over the sub-environments except over those being reset).

A sub-environment whose simulation diverges (DivergenceError) terminates with reward -1e3 and the
observation of its state before the step (as the single env), and ``info["diverged"]`` marks it; the others
advance normally. No rendering (render_mode must be None).

``info`` (of ``reset`` and ``step``) holds the single env's measures per cube, arrays with a leading axis N:
``angle_error_deg``, ``torque_applied`` (N, 3) and, on the corner, ``tilt_deg`` (not its clock ``t``); beside each
key ``k``, gymnasium's mask ``info["_k"]`` (N,) of the cubes it is about (after ``reset``: the cubes reset).
"""
from __future__ import annotations

import math
from collections.abc import Mapping
from typing import Any

import numpy as np

from .. import validate as V
from .._install import require
from ..errors import DivergenceError
from ..generated import layout as LY
from ..kernels import K
from .. import control as lc
from .reaction_wheel_cube import BODY, OBS_OMEGA, OBS_OMEGA_B, OBS_Q, ReactionWheelCubeEnv, initial_q

gym = require("gymnasium", "gym", "the ReactionWheelCube-v0 vector environment")
require("gymnasium.vector", "gym", "the ReactionWheelCube-v0 vector environment")
from gymnasium.utils import seeding  # noqa: E402
from gymnasium.vector import AutoresetMode, VectorEnv  # noqa: E402
from gymnasium.vector.utils import batch_space  # noqa: E402


class ReactionWheelCubeVectorEnv(VectorEnv):
    """N ReactionWheelCube-v0 environments stepped together (see the module docstring).

    Parameters
    ----------
    num_envs : int
        Number of sub-environments N >= 1.
    max_episode_steps : int or None
        Truncate an episode after this many steps (None: never).
    **env_kwargs
        The single environment's arguments (task, backend, control_dt, dt, damping, init_angle_deg,
        max_tilt_deg, target_q or the chapter cube's parameters), validated by it.

    Notes
    -----
    Observations (N, 10) float32, actions (N, 3) float32 in [-1, 1], rewards (N,) float64,
    terminations and truncations (N,) bool.
    """

    metadata = {"render_modes": [], "autoreset_mode": AutoresetMode.NEXT_STEP}

    @V.keywords
    def __init__(self, num_envs: int = 1, max_episode_steps: int | None = None, render_mode: str | None = None,
                 **env_kwargs: Any) -> None:
        if render_mode is not None:
            raise V.LavenderInputError("render_mode", "the vector environment does not render: must be None",
                                       f", got {render_mode!r}")
        self.num_envs = V.integer("num_envs", num_envs, minimum=1)
        self.max_episode_steps = None if max_episode_steps is None else V.integer("max_episode_steps", max_episode_steps,
                                                                                  minimum=1)
        self.render_mode = None
        one = ReactionWheelCubeEnv(**env_kwargs)    # validates every argument; its settings are the template
        self._one = one
        self.task, self.substeps, self.torque_limit = one.task, one.substeps, one.torque_limit
        self.single_observation_space, self.single_action_space = one.observation_space, one.action_space
        self.observation_space = batch_space(one.observation_space, self.num_envs)
        self.action_space = batch_space(one.action_space, self.num_envs)
        self._low, self._high = one.observation_space.low, one.observation_space.high
        self._target = np.asarray(one.target_q, dtype=float)
        self.sim = self._build_sim()
        n = self.num_envs
        self._raw_buf, self._clip_buf = np.empty((n, 10)), np.empty((n, 10))   # _raw's and _obs's scratch
        self._act_buf = np.empty((n, 3))                 # step's saturated actions (float64)
        # the observation bounds as full (N, 10) float32 arrays: the clipping is then two flat ufunc loops
        self._low_n, self._high_n = (np.ascontiguousarray(np.broadcast_to(b, (n, 10))) for b in (self._low, self._high))
        self._rngs: list[np.random.Generator | None] = [None] * n
        self._start: list[tuple | None] = [None] * n
        self._needs_reset = np.zeros(n, bool)
        self._elapsed = np.zeros(n, np.int64)
        self._started = False

    # ---- construction --------------------------------------------------------------------
    def _build_sim(self):
        from ..bodies import Body
        from ..scene import Scene
        from ..sim import Sim

        from ..effects import make

        one, n = self._one, self.num_envs
        tmpl = one.scene                                  # the single env's chapter cube: its body and effects
        cube, s = tmpl.bodies[BODY], one.size
        q_up = V.quaternion("q0", lc.cube_upright_q(one.task))
        p_w = np.asarray(K.quat_rotate(q_up, one.r_b), dtype=float)
        scene = Scene()
        wheels = dict(tmpl.model_effects(BODY)["reaction_wheels"].values)
        for i in range(n):
            body = Body.box(f"cube{i}", mass=cube.mass, size=(s, s, s), p_w=p_w, q=q_up)
            scene.add_body(body)
        for i in range(n):   # validated model effects, one pair per body (new names: no duplicate scan needed)
            scene.effects.append(make("spherical_joint", body=f"cube{i}", anchor_w=[0.0, 0.0, 0.0]))
            scene.effects.append(make("reaction_wheels", body=f"cube{i}", **wheels))
        for e in tmpl.effects:   # the force effects, declared once for every cube
            if not e.per_body:
                scene.add_effect(e.name, **dict(e.values))
        sim = Sim(scene, dt=self._one.dt, integrator="rk4", backend=self._one.backend)
        sim.fast_chunks()     # one step's run inside C (Stepper.advance: run's checks and results), any N
        return sim

    def _place(self, i: int, q0: np.ndarray, omega_b: np.ndarray, Omega: np.ndarray) -> None:
        """Cube i at the start of an episode, exactly as the single env's _make_sim builds it."""
        q0 = V.quaternion("q0", q0)
        p_w = np.asarray(K.quat_rotate(q0, self._one.r_b), dtype=float)
        self.sim.reinit_body(i, p_w, V.quaternion("q", q0), omega_b, Omega)

    def _reset_one(self, i: int) -> None:
        rng = self._rngs[i]
        if rng is None:
            rng, _ = seeding.np_random(None)
            self._rngs[i] = rng
        one = self._one
        q0 = initial_q(rng, self.task, one.target_q, one.init_angle_deg)
        start = self._start[i] = (q0, np.zeros(3), np.zeros(3))
        self._place(i, *start)
        self._elapsed[i] = 0
        self._needs_reset[i] = False

    # ---- gymnasium API ---------------------------------------------------------------------
    def reset(self, *, seed: int | list | None = None, options: dict[str, Any] | None = None):
        n = self.num_envs
        if options is not None and not isinstance(options, Mapping):
            raise V.LavenderInputError("options", "expected a dict or None", f", got {V._describe(options)}")
        unknown = sorted(str(k) for k in (options or {}) if k != "reset_mask")
        if unknown:
            raise V.LavenderInputError(f"options.{unknown[0]}", "unknown reset option of the vector env; known: reset_mask")
        mask = np.ones(n, bool)
        if options and options.get("reset_mask") is not None:
            mask = np.asarray(options["reset_mask"])
            if mask.dtype != bool or mask.shape != (n,):
                raise V.LavenderInputError("options.reset_mask", f"must be a bool array of shape ({n},)",
                                           f", got {V._describe(options['reset_mask'])}")
        seeds: list[int | None]
        if seed is None:
            seeds = [None] * n
        elif isinstance(seed, (list, tuple)):
            if len(seed) != n:
                raise V.LavenderInputError("seed", f"a list of seeds needs one per sub-environment ({n})", f", got {len(seed)}")
            seeds = [None if s_ is None else V.integer(f"seed[{i}]", s_, minimum=0) for i, s_ in enumerate(seed)]
        else:
            first = V.integer("seed", seed, minimum=0)
            seeds = [first + i for i in range(n)]
        for i in np.flatnonzero(mask):
            s = seeds[i]
            if s is not None:
                self._rngs[i], _ = seeding.np_random(s)
            self._reset_one(int(i))
        self.sim.check_written()     # the start states' pre-step check now: the first run can take the C fast path
        self._started = True
        raw = self._raw()
        q = raw[:, OBS_Q]
        info: dict[str, Any] = {"angle_error_deg": np.degrees(K.quat_error_angle(q, self._target)),
                                "torque_applied": np.zeros((n, LY.WHEELS_BODY_AXES))}
        if self.task == "corner":
            info["tilt_deg"] = self._tilt_deg(q)
        # the single env's reset info (but its clock `t`), per cube; the `_key` masks mark the cubes reset
        return self._obs(raw), {**info, **{f"_{k}": mask.copy() for k in info}}

    def step(self, actions):
        if not self._started:
            raise RuntimeError("ReactionWheelCube-v0 (vector): call reset() before step()")
        n, sim = self.num_envs, self.sim
        a = self._actions(actions)                        # validated float64, saturated (a reused buffer)
        any_reset = bool(self._needs_reset.any())
        resets = np.flatnonzero(self._needs_reset) if any_reset else ()
        for i in resets:                         # next-step autoreset: these start over and do not step
            self._reset_one(int(i))
        if any_reset:
            sim.check_written()     # the written states' pre-step check now: the run stays on the C fast path
        # finite and saturated: written straight into the held commands (set_wheel_commands' array; every cube has
        # wheels), as a * torque_limit
        cmd = sim.model.command[:, :LY.WHEELS_BODY_AXES]    # the cubes' three wheels: the first slots
        np.multiply(a, self.torque_limit, out=cmd)
        if any_reset:
            cmd[resets] = 0.0
        diverged = self._run()
        if any_reset:
            for i in resets:
                self._place(int(i), *self._start[i])
            sim.check_written()     # (again: the next step's run too)
        raw = self._raw()
        for b, (msg, pre) in diverged.items():
            raw[b] = pre
        obs = self._obs(raw)
        q, w = raw[:, OBS_Q], raw[:, OBS_OMEGA_B]
        theta = K.quat_error_angle(q, self._target)      # rad; the single env's kernel, its NumPy printing
        angle = np.degrees(theta)
        reward = -(theta * theta + 0.05 * np.einsum("ij,ij->i", w, w) + 0.01 * np.einsum("ij,ij->i", a, a))
        terminated = self._out_of_bounds(raw)
        info: dict[str, Any] = {"angle_error_deg": angle, "torque_applied": sim.wheel_torques_applied[:, :LY.WHEELS_BODY_AXES].copy()}
        if self.task == "corner":
            tilt = self._tilt_deg(q)
            terminated |= tilt > self._one.max_tilt_deg
            info["tilt_deg"] = tilt
        if diverged:
            rows = list(diverged)
            reward[rows] = -1e3
            terminated[rows] = True
            angle[rows] = np.nan
            info["diverged"] = np.zeros(n, bool)
            info["diverged"][rows] = True
            info["diverged_message"] = np.array([diverged.get(i, ("", None))[0] for i in range(n)], dtype=object)
        self._elapsed += 1
        if any_reset:
            self._elapsed[resets] = 0
        truncated = np.zeros(n, bool) if self.max_episode_steps is None else self._elapsed >= self.max_episode_steps
        if any_reset:
            reward[resets], terminated[resets], truncated[resets] = 0.0, False, False
        self._needs_reset = terminated | truncated
        return obs, reward, terminated, truncated, _with_masks(info, n, diverged)

    def close_extras(self, **kwargs: Any) -> None:
        self.sim = None

    # ---- helpers ---------------------------------------------------------------------------
    def _run(self) -> dict[int, tuple[str, np.ndarray]]:
        """One Sim.run of every cube; a cube that diverges is recorded (message, its state before the step), set
        at rest where it was and the run repeated without it (the Sim restores itself on DivergenceError)."""
        diverged: dict[int, tuple[str, np.ndarray]] = {}
        while True:
            try:
                self.sim.run(self.substeps)
                return diverged
            except DivergenceError as exc:
                b = int(exc.body)
                if b in diverged:
                    raise
                diverged[b] = (str(exc), self._raw()[b].copy())     # (_raw's buffer is reused)
                q = self.sim.q[b].copy()
                self._place(b, q, np.zeros(3), np.zeros(3))

    def _raw(self) -> np.ndarray:
        """[q, omega_b, Omega] of every cube, (N, 10), in a scratch buffer reused by the next call."""
        sim, raw = self.sim, self._raw_buf
        raw[:, OBS_Q], raw[:, OBS_OMEGA_B], raw[:, OBS_OMEGA] = sim.q, sim.omega_b, sim.Omega[:, :LY.WHEELS_BODY_AXES]
        return raw

    def _actions(self, actions) -> np.ndarray:
        """The actions as float64 (N, 3) saturated to [-1, 1], in a buffer reused by the next call: a float ndarray of
        the right shape with finite entries is copied and saturated in place; anything else (and any non-finite
        number) takes V.array's checks (LavenderInputError naming ``actions``)."""
        n, a = self.num_envs, self._act_buf
        ok = type(actions) is np.ndarray and actions.shape == (n, 3) and actions.dtype.kind == "f"
        if ok:
            np.copyto(a, actions)
            ok = bool(np.isfinite(a).all())
        if not ok:
            np.copyto(a, V.array("actions", actions, (n, 3)))     # raises on anything but n x 3 finite real numbers
        return np.minimum(np.maximum(a, -1.0, out=a), 1.0, out=a)

    def _tilt_deg(self, q: np.ndarray) -> np.ndarray:
        """Per cube, the angle of its body diagonal from the world z axis, degrees (the single env's tilt_deg)."""
        d = np.asarray(K.quat_rotate(q, np.ones(3) / math.sqrt(3.0)))
        return np.degrees(np.arctan2(np.hypot(d[:, 0], d[:, 1]), d[:, 2]))

    def _obs(self, raw: np.ndarray) -> np.ndarray:
        """The observations: raw clipped to the bounds (as np.clip), float32 (a new array), non-finite numbers as 0.

        Cast first, then clipped in float32: the bounds are float32 numbers and the cast is monotonic, so this is
        np.clip's result cast, bitwise. Only NaN survives the clipping (inf is clipped to a bound)."""
        obs = raw.astype(np.float32)
        np.maximum(obs, self._low_n, out=obs)
        np.minimum(obs, self._high_n, out=obs)
        total = float(np.add.reduce(obs, axis=None))
        if total != total:             # a NaN somewhere (the clipped numbers are bounded: the sum is finite else)
            np.nan_to_num(obs, copy=False, nan=0.0, posinf=0.0, neginf=0.0)
        return obs

    def _out_of_bounds(self, raw: np.ndarray) -> np.ndarray:
        """Per row: a body rate beyond rate_bound or a wheel rate beyond wheel_bound (NaN is not beyond)."""
        n, one = self.num_envs, self._one
        w, Om = raw[:, OBS_OMEGA_B], raw[:, OBS_OMEGA]
        rb, wb = one.rate_bound, one.wheel_bound
        m0, m1, m2, m3, m4, m5 = np.max(np.abs(raw[:, 4:10]), axis=0).tolist()    # per column, over the rows
        if m0 <= rb and m1 <= rb and m2 <= rb and m3 <= wb and m4 <= wb and m5 <= wb:
            return np.zeros(n, bool)   # every row within both (a NaN anywhere fails the screen: the rows decide)
        return (np.max(np.abs(w), axis=1) > rb) | (np.max(np.abs(Om), axis=1) > wb)


def make_vec_env(num_envs: int = 1, **kwargs: Any) -> ReactionWheelCubeVectorEnv:
    """The vector entry point registered for ReactionWheelCube-v0 (gymnasium.make_vec, vector_entry_point mode)."""
    return ReactionWheelCubeVectorEnv(num_envs=num_envs, **kwargs)


def _with_masks(info: dict[str, Any], n: int, diverged: Mapping[int, Any]) -> dict[str, Any]:
    """Gymnasium's vector-env convention: beside every key ``k`` a boolean array ``info["_k"]`` (n,) marks the
    sub-environments the value is about. The per-cube measures are about every cube; ``diverged`` and
    ``diverged_message`` only about the cubes that diverged in this step."""
    every = np.ones(n, bool)
    some = np.zeros(n, bool)
    some[list(diverged)] = True
    masks = {f"_{k}": (some.copy() if k.startswith("diverged") else every.copy()) for k in info}
    return {**info, **masks}
