"""The simulator: steps a scene's bodies with a chosen integrator on a chosen backend.

The scene is read once at construction (bodies, initial states, declared effects); later edits to
the scene do not affect an existing Sim. Times in s.
"""
from __future__ import annotations

import numpy as np

from . import backends
from . import validate as V
from .bodies import BodyState
from .errors import DivergenceError
from .kernels import K
from .scene import Scene

_EFFECT_NAMES = {1: "applied_torque", 2: "force_at_point", 3: "gravity", 4: "linear_damping", 5: "angular_damping"}


class Trajectory:
    """Recorded samples: t (T,), x (T, nb, 13)."""

    def __init__(self, names: list[str], t: np.ndarray, x: np.ndarray):
        self.names, self.t, self.x = names, t, x

    def body(self, name: str) -> BodyState:
        if name not in self.names:
            raise V.LavenderInputError("body", f"unknown body {name!r}; bodies: {', '.join(self.names)}")
        return BodyState(self.x[:, self.names.index(name)])


class Sim:
    def __init__(self, scene: Scene, dt: float = 1e-3, integrator: str = "rk4", backend: str = "c", normalize: bool = True):
        if not isinstance(scene, Scene):
            raise V.LavenderInputError("scene", "must be a lavendersim.Scene", f", got {type(scene).__name__}")
        self.dt = V.dt("dt", dt)
        self.integrator = V.choice("integrator", integrator, backends.INTEGRATORS)
        if not isinstance(normalize, (bool, np.bool_)):
            raise V.LavenderInputError("normalize", "must be True or False", f", got {normalize!r}")
        self.normalize = bool(normalize)
        self.backend = backends.get(backend)
        self.names = list(scene.bodies)
        self.bodies = dict(scene.bodies)
        self.x, self.params, self.effects = scene.arrays()
        self._effect_objs = list(scene.effects)
        self.t = 0.0
        self.steps = 0

    # ---- what runs -------------------------------------------------------------------------
    @property
    def pipeline(self) -> list[str]:
        """Each line is work done per step: the integrator, then per body its RHS kernels."""
        n = backends.INTEGRATORS[self.integrator]
        lines = [f"{self.integrator}: {n} RHS evaluation{'s' if n > 1 else ''} per step on the {self.backend.name} backend"
                 + (", then normalize q" if self.normalize else ", q not normalized")]
        for i, name in enumerate(self.names):
            mine = [e for e in self._effect_objs if e.body in (None, name)]
            if not mine:
                lines.append(f"{name}: rigid_body_rhs_free (torque- and force-free; no effect terms)")
            else:
                terms = " + ".join(e.describe() for e in mine)
                lines.append(f"{name}: {terms} -> rigid_body_rhs")
        return lines

    # ---- stepping -------------------------------------------------------------------------
    def _advance(self, n: int) -> None:
        try:
            self.backend.advance(self.x, self.params, self.effects, self.integrator, self.normalize, self.dt, n)
        except DivergenceError as e:
            raise DivergenceError(self.steps + e.step, e.body, e.cause, self.names[e.body],
                                  t=(self.steps + e.step + 1) * self.dt) from None
        self.steps += n
        self.t = self.steps * self.dt

    def step(self) -> None:
        self._advance(1)

    def run(self, n_steps: int) -> None:
        n = V.integer("n_steps", n_steps, minimum=0)
        if n:
            self._advance(n)

    def run_for(self, duration: float) -> None:
        """Advance by round(duration / dt) steps."""
        self.run(int(round(V.scalar("duration", duration, nonnegative=True) / self.dt)))

    def record(self, n_steps: int, every: int = 1) -> Trajectory:
        """Advance n_steps, sampling the state every `every` steps; includes the initial sample."""
        n = V.integer("n_steps", n_steps, minimum=0)
        every = V.integer("every", every, minimum=1)
        if n % every:
            raise V.LavenderInputError("every", f"must divide n_steps ({n})", f", got {every}")
        xs, ts = [self.x.copy()], [self.t]
        for _ in range(n // every):
            self._advance(every)
            xs.append(self.x.copy())
            ts.append(self.t)
        return Trajectory(self.names, np.array(ts), np.stack(xs))

    # ---- state access ---------------------------------------------------------------------
    def state(self, name: str) -> BodyState:
        return BodyState(self.x[self._i(name)].copy())

    def set_state(self, name: str, *, p_w=None, q=None, v_w=None, omega_b=None, omega_w=None) -> None:
        """Set parts of one body's state; everything is validated before anything changes."""
        i = self._i(name)
        x = self.x[i].copy()
        if p_w is not None:
            x[0:3] = V.vector("p_w", p_w)
        if q is not None:
            x[3:7] = V.quaternion("q", q)
        if v_w is not None:
            x[7:10] = V.vector("v_w", v_w)
        if omega_b is not None and omega_w is not None:
            raise V.LavenderInputError("omega_w", "give omega_b or omega_w, not both")
        if omega_b is not None:
            x[10:13] = V.vector("omega_b", omega_b)
        if omega_w is not None:
            x[10:13] = K.world_to_body(x[3:7], V.vector("omega_w", omega_w))
        self.x[i] = x

    def _i(self, name: str) -> int:
        if name not in self.names:
            raise V.LavenderInputError("body", f"unknown body {name!r}; bodies: {', '.join(self.names)}")
        return self.names.index(name)

    def kinetic_energy(self, name: str | None = None) -> float:
        """Kinetic energy of one body, or of all bodies (name=None), J."""
        idx = range(len(self.names)) if name is None else [self._i(name)]
        return float(sum(K.kinetic_energy(self.params[i, 0], self.params[i, 1:4], self.x[i, 7:10], self.x[i, 10:13]) for i in idx))

    def angular_momentum_w(self, name: str) -> np.ndarray:
        """Angular momentum about the body's COM, world frame, kg·m²/s."""
        i = self._i(name)
        return K.angular_momentum_world(self.x[i, 3:7], self.params[i, 1:4], self.x[i, 10:13])

    def linear_momentum_w(self, name: str) -> np.ndarray:
        i = self._i(name)
        return self.params[i, 0] * self.x[i, 7:10]
