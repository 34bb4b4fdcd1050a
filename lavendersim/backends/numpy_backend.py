"""NumPy backend: every body of a scene stepped at once, vectorized over the body axis.

The right-hand side evaluates only the declared effects: bodies with none use the torque-free
kernel; the others accumulate F_w and tau_w effect by effect (table order) and use rigid_body_rhs.
Bodies with a spherical joint and/or reaction wheels (kind != 0 in the model rows) accumulate the
same way (a jointed body's linear damping sees its kinematic COM velocity, pivot_kinematics) and
use wheel_body_rhs (wheels) or pivot_body_rhs (joint only). With such bodies the stepped state is
(nb, 16) = [x (13), Omega (3)]; a jointed body's p_w, v_w are not integrated but set from
pivot_kinematics after every step.
"""
from __future__ import annotations

import numpy as np

from ..errors import DivergenceError
from ..kernels import K
from . import KIND_JOINT, KIND_WHEELS, MODEL_LAYOUT as L, Models, divergence_cause, saturate


def _terms(effects: np.ndarray, idx: np.ndarray) -> list:
    """Per effect acting on any body of idx: (code, positions within idx or slice(None), parameters)."""
    pos = {int(b): k for k, b in enumerate(idx)}
    terms = []
    for row in effects:
        b = int(row[1])
        if b < 0:
            terms.append((int(row[0]), slice(None), row[2:8].copy()))
        elif b in pos:
            terms.append((int(row[0]), np.array([pos[b]]), row[2:8].copy()))
    return terms


def _sums(terms, m, q, v, w):
    """Total force at the COM and torque about it, world frame, summed in table order."""
    F = np.zeros((q.shape[0], 3))
    tau = np.zeros((q.shape[0], 3))
    for code, at, p in terms:
        if code == 1:
            tau[at] += p[0:3]
        elif code == 2:
            F[at] += p[3:6]
            tau[at] += K.force_at_point(q[at], p[0:3], p[3:6])
        elif code == 3:
            F[at] += K.gravity_force(m[at], p[0:3])
        elif code == 4:
            F[at] += K.linear_damping(p[0], v[at])
        elif code == 5:
            tau[at] += K.angular_damping(q[at], p[0], w[at])
    return F, tau


class _Group:
    """Bodies with a joint and/or wheels that share one rotational kernel."""

    def __init__(self, idx, effects, m, rows):
        self.idx = idx
        self.terms = _terms(effects, idx)
        self.m = m[idx]
        r = rows[idx]
        kind = r[:, 0].astype(np.int64)
        self.jointed = (kind & KIND_JOINT) != 0
        # the kinematic COM velocity is only needed by linear damping
        self.needs_v = bool(self.jointed.any()) and any(code == 4 for code, _, _ in self.terms)
        self.I_p = r[:, L["I_p"]].reshape(-1, 3, 3).copy()
        self.r_b, self.anchor, self.J = r[:, L["r_b"]].copy(), r[:, L["anchor_w"]].copy(), r[:, L["J"]].copy()
        self.tl, self.sl, self.c_w = r[:, 19].copy(), r[:, 20].copy(), r[:, 21].copy()

    def velocity(self, x):
        """COM velocity for the effects: kinematic for jointed bodies, the state's otherwise."""
        v = x[:, 7:10]
        if self.needs_v:
            kin = K.pivot_kinematics(x[:, 3:7], x[:, 10:13], self.anchor, self.r_b)[1]
            v = np.where(self.jointed[:, None], kin, v)
        return v

    def translation(self, x, F, out):
        """p, v derivatives: zero for jointed bodies (set from the joint after the step), free otherwise."""
        out[:, 0:3] = np.where(self.jointed[:, None], 0.0, x[:, 7:10])
        out[:, 7:10] = np.where(self.jointed[:, None], 0.0, F / self.m[:, None])


class _Plan:
    """Which kernels run for which bodies: precomputed once per (params, effects, model rows)."""

    def __init__(self, params: np.ndarray, effects: np.ndarray, rows: np.ndarray | None = None):
        nb = params.shape[0]
        self.m, self.I = params[:, 0], params[:, 1:4]
        kind = np.zeros(nb, np.int64) if rows is None else rows[:, 0].astype(np.int64)
        touched = np.zeros(nb, bool)
        for row in effects:
            if row[1] < 0:
                touched[:] = True
            else:
                touched[int(row[1])] = True
        plain = kind == 0
        self.has_models = not plain.all()
        self.all_free = not touched.any() and not self.has_models
        self.free = np.flatnonzero(plain & ~touched)
        self.forced = np.flatnonzero(plain & touched)
        self.terms = _terms(effects, self.forced)
        self.m_f, self.I_f = self.m[self.forced], self.I[self.forced]
        self.I_free = self.I[self.free]
        wheels = np.flatnonzero((kind & KIND_WHEELS) != 0)
        pivot = np.flatnonzero(kind == KIND_JOINT)
        self.wheels = _Group(wheels, effects, self.m, rows) if wheels.size else None
        self.pivot = _Group(pivot, effects, self.m, rows) if pivot.size else None
        self.jointed = np.flatnonzero((kind & KIND_JOINT) != 0)
        if self.jointed.size:
            r = rows[self.jointed]
            self.j_anchor, self.j_r_b = r[:, L["anchor_w"]].copy(), r[:, L["r_b"]].copy()

    def rhs(self, x: np.ndarray, u: np.ndarray | None = None) -> np.ndarray:
        """d/dt of x (nb, 13), or of [x, Omega] (nb, 16) with u (n_wheeled, 3) when bodies have models."""
        if self.all_free:
            return K.rigid_body_rhs_free(x, self.I)
        out = np.empty_like(x)
        if x.shape[1] > 13:
            out[:, 13:] = 0.0
        if self.free.size:
            out[self.free, :13] = K.rigid_body_rhs_free(x[self.free, :13], self.I_free)
        if self.forced.size:
            xf = x[self.forced, :13]
            F, tau = _sums(self.terms, self.m_f, xf[:, 3:7], xf[:, 7:10], xf[:, 10:13])
            out[self.forced, :13] = K.rigid_body_rhs(xf, self.m_f, self.I_f, F, tau)
        g = self.wheels
        if g is not None:
            xg = x[g.idx]
            F, tau = _sums(g.terms, g.m, xg[:, 3:7], g.velocity(xg), xg[:, 10:13])
            o = np.empty((g.idx.size, 16))
            o[:, 3:7], o[:, 10:13], o[:, 13:16] = K.wheel_body_rhs(
                xg[:, 3:7], xg[:, 10:13], xg[:, 13:16], g.I_p, g.J, g.r_b, F, tau, u, g.c_w)
            g.translation(xg, F, o)
            out[g.idx] = o
        g = self.pivot
        if g is not None:
            xg = x[g.idx]
            F, tau = _sums(g.terms, g.m, xg[:, 3:7], g.velocity(xg), xg[:, 10:13])
            o = np.zeros((g.idx.size, 16))
            o[:, 3:7], o[:, 10:13] = K.pivot_body_rhs(xg[:, 3:7], xg[:, 10:13], g.I_p, g.r_b, F, tau)
            g.translation(xg, F, o)
            out[g.idx] = o
        return out

    def applied(self, x: np.ndarray, command: np.ndarray) -> np.ndarray | None:
        """Saturated wheel torques for this step (zero-order hold), for the wheeled bodies."""
        g = self.wheels
        if g is None:
            return None
        return saturate(command[g.idx], x[g.idx, 13:16], g.tl, g.sl)

    def wheel_info(self, x: np.ndarray, b: int) -> tuple:
        """(Omega, (J, c_w)) of body b if it has wheels, else (None, None): for divergence_cause."""
        g = self.wheels
        if g is None or b not in g.idx:
            return None, None
        k = int(np.flatnonzero(g.idx == b)[0])
        return x[b, 13:16], (g.J[k], g.c_w[k])

    def constrain(self, x: np.ndarray) -> None:
        """Jointed bodies: p_w, v_w from the joint kinematics of the new q, omega."""
        if self.jointed.size:
            j = self.jointed
            x[j, 0:3], x[j, 7:10] = K.pivot_kinematics(x[j, 3:7], x[j, 10:13], self.j_anchor, self.j_r_b)


def _normalize(x: np.ndarray) -> None:
    x[:, 3:7] = K.quat_normalize(x[:, 3:7])


def step(plan: _Plan, x: np.ndarray, integrator: str, normalize: bool, dt: float, u=None) -> np.ndarray:
    """One step of every body; returns the new state array. x is (nb, 13), or (nb, 16) = [x, Omega]
    with u the wheeled bodies' applied torques when the plan has joints or wheels."""
    f = (lambda y: plan.rhs(y, u)) if plan.has_models else plan.rhs  # noqa: E731
    if integrator == "euler":
        xn = x + dt * f(x)
    elif integrator == "semi_implicit_euler":
        k = f(x)
        xn = x.copy()
        xn[:, 7:] += dt * k[:, 7:]  # v, omega (and Omega) first
        xn[:, 0:3] += dt * xn[:, 7:10]
        xn[:, 3:7] += dt * K.quat_derivative_body(x[:, 3:7], xn[:, 10:13])
    elif integrator == "rk4":
        h = dt / 2
        k1 = f(x)
        k2 = f(x + h * k1)
        k3 = f(x + h * k2)
        k4 = f(x + dt * k3)
        xn = x + (dt / 6) * (k1 + 2 * k2 + 2 * k3 + k4)
    else:  # validated by Sim; kept for direct callers
        raise ValueError(f"integrator: unknown {integrator!r}")
    if normalize:
        _normalize(xn)
    if plan.has_models:
        plan.constrain(xn)
    return xn


class NumpyBackend:
    name = "numpy"

    def __init__(self):
        self._plan_key = None
        self._plan = None

    def plan(self, params: np.ndarray, effects: np.ndarray, rows: np.ndarray | None = None) -> _Plan:
        key = (params.tobytes(), effects.tobytes(), None if rows is None else rows.tobytes())
        if key != self._plan_key:
            self._plan, self._plan_key = _Plan(params, effects, rows), key
        return self._plan

    def advance(self, state, params, effects, integrator: str, normalize: bool, dt: float, n_steps: int,
                models: Models | None = None) -> None:
        plan = self.plan(params, effects, None if models is None else models.rows)
        if not plan.has_models:
            x = state.copy()
            with np.errstate(over="ignore", invalid="ignore", divide="ignore"):  # non-finite results are caught below
                self._loop(plan, x, integrator, normalize, dt, n_steps)
            state[...] = x
            return
        x = np.concatenate([state, models.Omega], axis=1)
        applied = models.applied.copy()
        with np.errstate(over="ignore", invalid="ignore", divide="ignore"):
            self._loop(plan, x, integrator, normalize, dt, n_steps, models.command, applied)
        state[...] = x[:, :13]
        models.Omega[...] = x[:, 13:16]
        models.applied[...] = applied

    @staticmethod
    def _loop(plan, x, integrator, normalize, dt, n_steps, command=None, applied=None) -> None:
        for i in range(n_steps):
            u = None if command is None else plan.applied(x, command)
            xn = step(plan, x, integrator, normalize, dt, u)
            if not np.isfinite(xn).all():
                b = int(np.flatnonzero(~np.isfinite(xn).all(axis=1))[0])
                raise DivergenceError(i, b, divergence_cause(x[b, :13], dt, integrator, *plan.wheel_info(x, b)))
            x[...] = xn
            if u is not None:
                applied[plan.wheels.idx] = u
