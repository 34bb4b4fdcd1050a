"""The simulator: steps a scene's bodies with a chosen integrator on a chosen backend.

The scene is read once at construction (bodies, initial states, declared effects); later edits to
the scene do not affect an existing Sim. Times in s.

Joints and reaction wheels: a body's mass and I_b are the whole body with its wheels locked, about
its COM. With a spherical_joint at anchor a, the Sim fixes r_b = R^T (p_w − a) (pivot → COM, body
frame) from the body's initial state and I_p = parallel_axis(diag(I_b), m, −r_b); the body's p_w,
v_w then follow the joint (pivot_kinematics) and are not integrated. A wheeled body without a joint
rotates about its COM (I_p = diag(I_b), r_b = 0) and translates freely. Wheel commands are held
(zero-order) until changed and saturated at the start of every step.

Integrators (`integrator=`; `sim.rhs_evals` counts right-hand-side evaluations, cumulative):
* "euler", "semi_implicit_euler" (1 evaluation per step), "rk4" (4): fixed step dt, any body.
* "dopri5": adaptive Dormand–Prince 5(4) with FSAL and error control (`rtol`, default 1e-6; `atol`,
  default 1e-9; the error of each accepted substep is at most 1 in Hairer's RMS norm of
  err_i / (atol + rtol max(|y_i|, |y_new_i|)) over the body's numbers). dt is the output interval:
  every step advances exactly dt with as many accepted substeps as needed (controller: safety 0.9,
  growth in [0.2, 5], no growth right after a rejection; the proposal is kept between steps). A
  substep below dt·1e-12, or more than 10⁶ substeps in one step, raises DivergenceError naming the
  step and body ("could not meet rtol/atol"). Any body (joints and wheels too; wheel torques held
  over each dt). The C backend chooses each body's step sizes independently; NumPy uses one shared
  step (the largest body error decides), so results agree to the tolerance, not bitwise. rhs_evals
  is the largest per-body count (C), or the shared count (NumPy) — per body for a single body. FSAL:
  the last stage is the next substep's first, within one run()/step() call; each call starts with
  one fresh evaluation (the state may have been set in between), as does every output step of a
  body with wheels (its held torque may change). q is normalized after every accepted substep.
* "splitting": second-order Strang splitting of the free rigid body into the exact flows of
  L_a²/(2I_a) about the principal axes, 1(h/2) 2(h/2) 3(h) 2(h/2) 1(h/2) (q by exact axis rotations,
  unit by construction; torque-free, world L and |L_b| conserved to rounding, energy oscillates
  boundedly), effects as half kicks of v and ω (explicit midpoint when damping makes them depend
  on v or ω), p drifted by h v. Plain bodies only (no spherical_joint / reaction_wheels).
* "implicit_gyro": the gyroscopic term implicit in the body frame, I(ω⁺ − ω)/dt + ω⁺ × Iω⁺ = τ_b,
  solved by Newton's method to rounding (Catto, GDC 2015; Bullet's implicit gyroscopic force);
  q ← q ⊗ exp(dt ω⁺/2); v, p semi-implicit Euler; loads at the start of the step. First order; a
  torque-free step never gains energy (E − E⁺ = ½(ω − ω⁺)ᵀI(ω − ω⁺)), stable at large |ω|·dt.
  Plain bodies only.
Unsupported combinations (splitting / implicit_gyro with a joint or wheels; rtol/atol with a fixed-step
integrator) raise LavenderInputError at construction.
"""
from __future__ import annotations

import numpy as np

from . import backends
from . import effects as effects_mod
from . import validate as V
from .backends import ADAPTIVE, KIND_JOINT, KIND_WHEELS, PLAIN_ONLY, Adaptive, Models
from .bodies import BodyState
from .errors import DivergenceError
from .generated import layout as LY
from .kernels import K
from .scene import Scene


class Trajectory:
    """Recorded samples: t (T,), x (T, nb, 13), Omega (T, nb, 3) wheel rates (zeros without wheels)."""

    def __init__(self, names: list[str], t: np.ndarray, x: np.ndarray, Omega: np.ndarray | None = None):
        self.names, self.t, self.x = names, t, x
        self.Omega = np.zeros(x.shape[:-1] + (3,)) if Omega is None else Omega

    def body(self, name: str) -> BodyState:
        if name not in self.names:
            raise V.LavenderInputError("body", f"unknown body {name!r}; bodies: {', '.join(self.names)}")
        i = self.names.index(name)
        return BodyState(self.x[:, i], self.Omega[:, i])


class Sim:
    @V.keywords  # unknown keyword arguments raise LavenderInputError naming them
    def __init__(self, scene: Scene, dt: float = 1e-3, integrator: str = "rk4", backend: str = "auto", normalize: bool = True,
                 rtol: float | None = None, atol: float | None = None):
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
        for e in scene.effects:  # an effect no declaration printed is an error, never a no-op
            effects_mod.check_declared(e)
        self.x, self.params, self.effects = scene.arrays()
        self._effect_objs = list(scene.effects)
        self._models = self._build_models(scene)
        self._adaptive = None
        if self.integrator in ADAPTIVE:
            rtol = 1e-6 if rtol is None else V.scalar("rtol", rtol, positive=True)
            atol = 1e-9 if atol is None else V.scalar("atol", atol, nonnegative=True)
            if not 1e-14 <= rtol < 1:
                raise V.LavenderInputError("rtol", "must be in [1e-14, 1) (below 1e-14 rounding dominates)", f", got {rtol!r}")
            self._adaptive = Adaptive(rtol, atol, len(self.names))
        else:
            for field, value in (("rtol", rtol), ("atol", atol)):
                if value is not None:
                    raise V.LavenderInputError(field, f"applies to the adaptive integrators ({', '.join(ADAPTIVE)}) only; "
                                               f"{self.integrator!r} uses the fixed step dt")
        if self.integrator in PLAIN_ONLY:
            for i, name in enumerate(self.names):
                kind = self._kind(i)
                if kind:
                    what = " and ".join(w for f, w in ((KIND_JOINT, "a spherical_joint"), (KIND_WHEELS, "reaction_wheels")) if kind & f)
                    raise V.LavenderInputError(
                        "integrator", f"{self.integrator!r} steps plain rigid bodies only, but body {name!r} has {what}; "
                        "use rk4 or dopri5 for jointed or wheeled bodies")
        self._per_step = backends.rhs_per_step(self.integrator, self.effects, len(self.names))
        self.t = 0.0
        self.steps = 0
        self.rhs_evals = 0

    @property
    def rtol(self) -> float | None:
        return None if self._adaptive is None else self._adaptive.rtol

    @property
    def atol(self) -> float | None:
        return None if self._adaptive is None else self._adaptive.atol

    def _build_models(self, scene: Scene) -> Models:
        """Per-body model rows (kind, I_p, r_b, anchor, J, limits, c_w) from the joint/wheel effects."""
        nb = len(self.names)
        models = Models.empty(nb)
        rows = models.rows
        for i, name in enumerate(self.names):
            m, I_b = self.params[i, LY.PARAM_M], self.params[i, LY.PARAM_I_B]
            me = scene.model_effects(name)
            kind, I_p, r_b, anchor = 0, np.diag(I_b), np.zeros(3), np.zeros(3)
            if "spherical_joint" in me:
                kind |= KIND_JOINT
                anchor = me["spherical_joint"].values["anchor_w"]
                r_b = K.quat_to_matrix(self.x[i, LY.STATE_Q]).T @ (self.x[i, LY.STATE_P_W] - anchor)
                I_p = K.parallel_axis(np.diag(I_b), m, -r_b)
                self.x[i, LY.STATE_P_W], self.x[i, LY.STATE_V_W] = K.pivot_kinematics(
                    self.x[i, LY.STATE_Q], self.x[i, LY.STATE_OMEGA_B], anchor, r_b)
            if "reaction_wheels" in me:
                kind |= KIND_WHEELS
                w = me["reaction_wheels"].values
                rows[i, LY.MODEL_J] = w["J"]
                rows[i, LY.MODEL_TORQUE_LIMIT], rows[i, LY.MODEL_SPEED_LIMIT] = w["torque_limit"], w["speed_limit"]
                rows[i, LY.MODEL_C_W] = w["c_w"]
            rows[i, LY.MODEL_KIND] = kind
            rows[i, LY.MODEL_I_P] = np.asarray(I_p).reshape(9)
            rows[i, LY.MODEL_R_B] = r_b
            rows[i, LY.MODEL_ANCHOR_W] = anchor
        return models

    def _kind(self, i: int) -> int:
        return int(self._models.rows[i, LY.MODEL_KIND])

    # ---- what runs -------------------------------------------------------------------------
    @property
    def pipeline(self) -> list[str]:
        """Each line is work done per step: the integrator, then per body its RHS kernels."""
        n = self._per_step
        if n is None:
            head = (f"{self.integrator}: adaptive (rtol={self.rtol:g}, atol={self.atol:g}), RHS evaluations counted, "
                    f"each step advances exactly dt on the {self.backend.name} backend"
                    + (" (per-body step sizes)" if self.backend.name == "c" else " (one shared step size)"))
        else:
            head = f"{self.integrator}: {n} RHS evaluation{'s' if n > 1 else ''} per step on the {self.backend.name} backend"
        lines = [head + (", then normalize q" if self.normalize else ", q not normalized")]
        for i, name in enumerate(self.names):
            mine = [e for e in self._effect_objs if e.body in (None, name)]
            kind = self._kind(i)
            if kind:
                model = [e for e in mine if e.per_body]
                forces = [e for e in mine if not e.per_body]
                kernel = "wheel_body_rhs" if kind & KIND_WHEELS else "pivot_body_rhs"
                terms = " + ".join(e.describe() for e in model + forces)
                extra = []
                if kind & KIND_WHEELS:
                    extra.append("wheel torques saturated per step (zero-order hold)")
                if kind & KIND_JOINT:
                    r_b = self._models.rows[i, LY.MODEL_R_B]
                    extra.append(f"r_b={np.array2string(r_b, precision=4)}; p_w, v_w from pivot_kinematics after each step"
                                 + (" and for linear damping" if any(e.name == "linear_damping" for e in forces) else ""))
                else:
                    extra.append("translation: v_dot = F/m")
                lines.append(f"{name}: {terms} -> {kernel} ({'; '.join(extra)})")
            elif not mine:
                lines.append(f"{name}: rigid_body_rhs_free (torque- and force-free; no effect terms)")
            else:
                terms = " + ".join(e.describe() for e in mine)
                lines.append(f"{name}: {terms} -> rigid_body_rhs")
        return lines

    # ---- stepping -------------------------------------------------------------------------
    def _advance(self, n: int) -> None:
        models = self._models if self._models.rows[:, LY.MODEL_KIND].any() else None
        ad = self._adaptive
        before = None if ad is None else ad.nfev.copy()
        try:
            self.backend.advance(self.x, self.params, self.effects, self.integrator, self.normalize, self.dt, n, models,
                                 *(() if ad is None else (ad,)))
        except DivergenceError as e:
            raise DivergenceError(self.steps + e.step, e.body, e.cause, self.names[e.body],
                                  t=(self.steps + e.step + 1) * self.dt) from None
        self.rhs_evals += n * self._per_step if ad is None else int(np.max(ad.nfev - before, initial=0))
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
        xs, Ws, ts = [self.x.copy()], [self._models.Omega.copy()], [self.t]
        for _ in range(n // every):
            self._advance(every)
            xs.append(self.x.copy())
            Ws.append(self._models.Omega.copy())
            ts.append(self.t)
        return Trajectory(self.names, np.array(ts), np.stack(xs), np.stack(Ws))

    # ---- state access ---------------------------------------------------------------------
    def state(self, name: str) -> BodyState:
        i = self._i(name)
        return BodyState(self.x[i].copy(), self._models.Omega[i].copy())

    @V.keywords  # an unknown keyword (a typo such as omega=) is a LavenderInputError naming it
    def set_state(self, name: str, *, p_w=None, q=None, v_w=None, omega_b=None, omega_w=None, Omega=None) -> None:
        """Set parts of one body's state; everything is validated before anything changes.

        Omega (wheel rates, rad/s) only for a body with reaction_wheels. A jointed body's p_w and v_w
        follow from q and omega (pivot_kinematics) and cannot be set."""
        i = self._i(name)
        kind = self._kind(i)
        x = self.x[i].copy()
        if kind & KIND_JOINT:
            for field, value in (("p_w", p_w), ("v_w", v_w)):
                if value is not None:
                    raise V.LavenderInputError(field, f"body {name!r} is on a spherical_joint: its p_w and v_w follow "
                                               "from q and omega; set those instead")
        if p_w is not None:
            x[LY.STATE_P_W] = V.vector("p_w", p_w)
        if q is not None:
            x[LY.STATE_Q] = V.quaternion("q", q)
        if v_w is not None:
            x[LY.STATE_V_W] = V.vector("v_w", v_w)
        if omega_b is not None and omega_w is not None:
            raise V.LavenderInputError("omega_w", "give omega_b or omega_w, not both")
        if omega_b is not None:
            x[LY.STATE_OMEGA_B] = V.vector("omega_b", omega_b)
        if omega_w is not None:
            x[LY.STATE_OMEGA_B] = K.world_to_body(x[LY.STATE_Q], V.vector("omega_w", omega_w))
        W = None
        if Omega is not None:
            if not kind & KIND_WHEELS:
                raise V.LavenderInputError("Omega", f"body {name!r} has no reaction_wheels")
            W = V.vector("Omega", Omega)
        if kind & KIND_JOINT:
            r = self._models.rows[i]
            x[LY.STATE_P_W], x[LY.STATE_V_W] = K.pivot_kinematics(x[LY.STATE_Q], x[LY.STATE_OMEGA_B],
                                                                 r[LY.MODEL_ANCHOR_W], r[LY.MODEL_R_B])
        self.x[i] = x
        if W is not None:
            self._models.Omega[i] = W

    # ---- reaction wheels ------------------------------------------------------------------
    def _wheeled(self, name: str) -> int:
        i = self._i(name)
        if not self._kind(i) & KIND_WHEELS:
            raise V.LavenderInputError("body", f"body {name!r} has no reaction_wheels")
        return i

    def set_wheel_command(self, name: str, u) -> None:
        """Motor torques on the wheels (N·m, body x, y, z), held until changed; saturated every step."""
        i = self._wheeled(name)
        self._models.command[i] = V.vector("u", u)

    def wheel_command(self, name: str) -> np.ndarray:
        """The commanded (unsaturated) wheel torques, N·m."""
        return self._models.command[self._wheeled(name)].copy()

    def wheel_command_applied(self, name: str) -> np.ndarray:
        """The saturated wheel torques used in the most recent step (zeros before the first), N·m."""
        return self._models.applied[self._wheeled(name)].copy()

    def wheel_rates(self, name: str) -> np.ndarray:
        """Wheel rates relative to the body, Omega (3,), rad/s."""
        return self._models.Omega[self._wheeled(name)].copy()

    def wheel_momentum_w(self, name: str) -> tuple[np.ndarray, np.ndarray]:
        """(L_body_w, L_wheels_w), world frame, kg·m²/s, from the wheel_momentum kernel: about the
        joint's pivot for a jointed body, about the COM otherwise; L_wheels_w is zero without wheels."""
        i = self._i(name)
        r = self._models.rows[i]
        return K.wheel_momentum(self.x[i, LY.STATE_Q], self.x[i, LY.STATE_OMEGA_B], self._models.Omega[i],
                                r[LY.MODEL_I_P].reshape(3, 3), r[LY.MODEL_J])

    def _i(self, name: str) -> int:
        if name not in self.names:
            raise V.LavenderInputError("body", f"unknown body {name!r}; bodies: {', '.join(self.names)}")
        return self.names.index(name)

    def kinetic_energy(self, name: str | None = None) -> float:
        """Kinetic energy of one body, or of all bodies (name=None), J: ½ m|v|² + ½ ωᵀ I_b ω with
        wheels locked (a jointed body's v_w is its kinematic COM velocity; wheel spin not included)."""
        idx = range(len(self.names)) if name is None else [self._i(name)]
        return float(sum(K.kinetic_energy(self.params[i, LY.PARAM_M], self.params[i, LY.PARAM_I_B], self.x[i, LY.STATE_V_W],
                                          self.x[i, LY.STATE_OMEGA_B]) for i in idx))

    def angular_momentum_w(self, name: str) -> np.ndarray:
        """Angular momentum about the body's COM, world frame, kg·m²/s."""
        i = self._i(name)
        return K.angular_momentum_world(self.x[i, LY.STATE_Q], self.params[i, LY.PARAM_I_B],
                                        self.x[i, LY.STATE_OMEGA_B])

    def linear_momentum_w(self, name: str) -> np.ndarray:
        i = self._i(name)
        return self.params[i, LY.PARAM_M] * self.x[i, LY.STATE_V_W]
