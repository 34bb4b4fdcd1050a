"""Linearization of any scene, composed in CasADi from the derived kernels (private: the public
entry points are lavendersim.control.linearize and lavendersim.control.Linearization).

Nothing here is a second model: each body's right-hand side is the generated CasADi printing of
the same declarations the backends run (``rigid_body_rhs``, ``translation_rhs``, ``pivot_body_rhs``,
``wheels<N>_body_rhs``, ``wheels<N>_motor``, ``pivot_kinematics`` in generated/kernels_casadi.py), with
the force and torque of every force effect the scene declares on the body from that effect's own
CasADi printing (built-in or user, :func:`lavendersim.effects.casadi_expr`). The model constants
(inertia about the pivot, r_b, wheel inertias and limits) are the Sim's model rows.

Error coordinates per body, in scene order (labels ``"BODY_BLOCK_AXIS"``, e.g. ``"cube_dtheta_x"``:
python-control signal names may not contain a dot):

* a free body: ``p`` (3, m, world) − p_ref, ``dtheta`` (3), ``v`` (3, m/s, world) − v_ref,
  ``omega`` (3, rad/s, body) − omega_ref;
* a body on a spherical joint: ``dtheta``, ``omega`` (its p_w and v_w follow from them);
* with reaction wheels also ``Omega`` (3, rad/s) − Omega_ref.

The attitude error dtheta (rad, body frame) is defined by ``q = q_ref ⊗ [dtheta/2, sqrt(1 −
|dtheta/2|²)]``. Inputs are wheel commands (``"BODY.u"``, 3 each, N·m) or parameters of declared
force effects (``"EFFECT.PARAM"``, e.g. ``"applied_torque.torque_w"``), each relative to its value
u0 at the operating point.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from types import SimpleNamespace

import casadi as ca
import control as ct
import numpy as np

from . import backends
from . import effects as E
from . import validate as V
from .attitude import attitude_error, perturbed
from .lqr import controllable_basis, uncontrollable
from .generated import kernels_casadi as KC
from .generated import layout as LY
from .kernels import K as KN

AXES = ("x", "y", "z")


# ------------------------------------------------------------------------------------------------
# reference (operating point) per body
# ------------------------------------------------------------------------------------------------


@dataclass
class BodyRef:
    """One body's operating point and model constants (from the Sim's rows)."""

    name: str
    joint: bool
    wheels: bool
    x: np.ndarray                 # (13,) reference state, STATE layout
    Omega: np.ndarray             # (N,) reference wheel rates, rad/s (N = n_wheels; (3,) zeros without wheels)
    m: float
    I_b: np.ndarray               # (3,)
    row: np.ndarray = field(repr=False)   # the Sim's model row (MODEL layout)
    offset: int = 0               # first index of this body's block in the error state
    command: np.ndarray | None = None     # the held wheel command when the wheels are not an input
    n_wheels: int = 0             # its wheels (0 without)
    on_axes: bool = False         # named 1 … N (a layout on axes_b); False: x, y, z (the body axes, A_b = [I | 0])
    R_bp: np.ndarray | None = None        # its principal axes in the body frame (None: the body frame is principal)
    x_pub: np.ndarray | None = None       # (13,) the reference state in the body frame (x is the principal frame's)

    def __post_init__(self):
        if self.x_pub is None:
            self.x_pub = self.x

    @property
    def blocks(self) -> tuple[str, ...]:
        b = ("dtheta", "omega") if self.joint else ("p", "dtheta", "v", "omega")
        return b + (("Omega",) if self.wheels else ())

    def block_size(self, block: str) -> int:
        return self.n_wheels if block == "Omega" else 3

    @property
    def size(self) -> int:
        return sum(self.block_size(b) for b in self.blocks)

    def index(self, block: str) -> slice:
        k = self.offset + sum(self.block_size(b) for b in self.blocks[:self.blocks.index(block)])
        return slice(k, k + self.block_size(block))

    def split(self, xb) -> dict:
        """This body's error block xb (its size) cut into its blocks by name."""
        return {b: xb[self.index(b).start - self.offset:self.index(b).stop - self.offset] for b in self.blocks}

    def labels(self, prefix: bool = True) -> list[str]:
        pre = f"{self.name}_" if prefix else ""
        return [f"{pre}{b}_{a}" for b in self.blocks for a in wheel_labels(self.block_size(b), self.on_axes, b == "Omega")]


def wheel_labels(n: int, on_axes: bool, wheel: bool = True) -> tuple[str, ...]:
    """Component names: x, y, z for a 3-vector and body-axis wheels; 1 … N for wheels on axes_b."""
    return tuple(str(k + 1) for k in range(n)) if wheel and on_axes else AXES


@dataclass
class InputRef:
    """One named input: a body's wheel commands or a declared effect's parameter."""

    name: str                     # "BODY.u" or "EFFECT.PARAM"
    kind: str                     # "wheels" or "effect"
    body: str | None
    effect_index: int | None      # index in scene.effects
    param: str | None
    size: int
    offset: int = 0

    on_axes: bool = False         # wheel commands of a layout on axes_b (named u_1 … u_N)

    def labels(self) -> list[str]:
        if self.kind == "wheels":
            return [f"{self.body}_u_{a}" for a in wheel_labels(self.size, self.on_axes)]
        base = self.name.replace(".", "_")
        return [base] if self.size == 1 else [f"{base}_{k}" for k in range(self.size)]


def _sim_of(sim_or_scene):
    from .scene import Scene
    from .sim import Sim

    if isinstance(sim_or_scene, Sim):   # the Sim keeps its scene's effect objects (the declarations)
        return sim_or_scene, SimpleNamespace(effects=list(sim_or_scene.model.effects))
    if isinstance(sim_or_scene, Scene):
        return Sim(sim_or_scene, dt=1e-3, integrator="rk4", backend="numpy"), sim_or_scene
    raise V.LavenderInputError("sim_or_scene", "must be a lavendersim Sim or Scene", f", got {type(sim_or_scene).__name__}")


def body_refs(sim, x0: dict | None) -> list[BodyRef]:
    """The operating point of every body: the Sim's current state, overridden per body by x0[name]
    (a dict of p_w, q, v_w, omega_b, Omega)."""
    x0 = {} if x0 is None else x0
    if not isinstance(x0, dict):
        raise V.LavenderInputError("x0", "must be a dict {body name: {p_w, q, v_w, omega_b, Omega}} or None",
                                   f", got {type(x0).__name__}")
    unknown = sorted(set(x0) - set(sim.names))
    if unknown:
        raise V.LavenderInputError("x0", f"unknown body {unknown[0]!r}; bodies: {', '.join(sim.names)}")
    model = sim.model
    rows, frames = model.rows, model.frames
    refs, off = [], 0
    for i, name in enumerate(sim.names):
        joint, wheels = model.kind(i)
        n_w = int(model.wheel_counts[i])
        x = sim.x[i].copy()
        Om = model.Omega[i, :n_w].copy()
        over = x0.get(name, {})
        allowed = {"q", "omega_b", "Omega"} | (set() if joint else {"p_w", "v_w"})
        bad = sorted(set(over) - allowed)
        if bad:
            raise V.LavenderInputError(f"x0[{name!r}].{bad[0]}", f"not a state of this body; give any of {', '.join(sorted(allowed))}"
                                       + (" (a jointed body's p_w, v_w follow from q, omega)" if joint else ""))
        for key, sl in (("p_w", LY.STATE_P_W), ("v_w", LY.STATE_V_W), ("omega_b", LY.STATE_OMEGA_B)):
            if key in over:
                x[sl] = V.vector(f"x0[{name!r}].{key}", over[key])
        if "q" in over:
            x[LY.STATE_Q] = V.quaternion(f"x0[{name!r}].q", over["q"])
        if "Omega" in over:
            if not wheels:
                raise V.LavenderInputError(f"x0[{name!r}].Omega", f"body {name!r} has no reaction_wheels")
            Om = V.vector(f"x0[{name!r}].Omega", over["Omega"], n_w)
        R_bp = None if frames is None else frames.rotation(i)
        x_int = x if R_bp is None else frames.internal_row(i, x)   # the model runs in the principal frame
        if joint:
            r = rows[i]
            x_int[LY.STATE_P_W], x_int[LY.STATE_V_W] = KN.pivot_kinematics(
                x_int[LY.STATE_Q], x_int[LY.STATE_OMEGA_B], r[LY.MODEL_ANCHOR_W], r[LY.MODEL_R_B])
            x[LY.STATE_P_W], x[LY.STATE_V_W] = x_int[LY.STATE_P_W], x_int[LY.STATE_V_W]
        ref = BodyRef(name, joint, wheels, x_int, Om, float(sim.params[i, LY.PARAM_M]), sim.params[i, LY.PARAM_I_B].copy(),
                      rows[i].copy(), off, n_wheels=n_w, on_axes=wheels and not backends.on_body_axes(rows[i]),
                      R_bp=R_bp, x_pub=x)
        off += ref.size
        refs.append(ref)
    return refs


def input_refs(sim, scene, inputs) -> list[InputRef]:
    """Parse the input names (default: every wheeled body's commands)."""
    model = sim.model
    wheeled = [n for i, n in enumerate(sim.names) if model.kind(i)[1]]
    if inputs is None:
        inputs = [f"{n}.u" for n in wheeled]
    if isinstance(inputs, str):
        inputs = [inputs]
    out: list[InputRef] = []
    off = 0
    for name in inputs:
        if not isinstance(name, str) or "." not in name:
            raise V.LavenderInputError("inputs", "each input is 'BODY.u' (wheel commands) or 'EFFECT.PARAM' (a declared "
                                       "force effect's parameter)", f", got {name!r}")
        head, tail = name.rsplit(".", 1)
        if tail == "u" and head in sim.names:
            if head not in wheeled:
                raise V.LavenderInputError("inputs", f"body {head!r} has no reaction_wheels", f", got {name!r}")
            i = sim.names.index(head)
            ref = InputRef(name, "wheels", head, None, None, int(model.wheel_counts[i]), off,
                           on_axes=not backends.on_body_axes(model.rows[i]))
        else:
            idx = [k for k, e in enumerate(scene.effects) if e.name == head and not e.per_body]
            if len(idx) != 1:
                known = sorted({e.name for e in scene.effects if not e.per_body})
                rule = "is not a force effect of the scene" if not idx else "names more than one effect of the scene"
                raise V.LavenderInputError("inputs", f"{head!r} {rule} (force effects: {', '.join(known) or 'none'}; "
                                           "wheel commands: " + (", ".join(f"{n}.u" for n in wheeled) or "none") + ")",
                                           f", got {name!r}")
            e = scene.effects[idx[0]]
            if tail not in e.fields:
                raise V.LavenderInputError("inputs", f"effect {head!r} has no parameter {tail!r} (parameters: "
                                           f"{', '.join(e.fields)})", f", got {name!r}")
            size = int(np.atleast_1d(e.values[tail]).size)
            ref = InputRef(name, "effect", e.body, idx[0], tail, size, off)
        if any(r.name == name for r in out):
            raise V.LavenderInputError("inputs", "duplicate input", f", got {name!r}")
        off += ref.size
        out.append(ref)
    return out


def input_u0(sim, scene, ins: list[InputRef], u0) -> np.ndarray:
    """The operating input: the Sim's held wheel commands and the effects' declared values, overridden by u0."""
    u0 = {} if u0 is None else u0
    if not isinstance(u0, dict):
        raise V.LavenderInputError("u0", "must be a dict {input name: value} or None", f", got {type(u0).__name__}")
    unknown = sorted(set(u0) - {r.name for r in ins})
    if unknown:
        raise V.LavenderInputError("u0", f"{unknown[0]!r} is not one of the inputs ({', '.join(r.name for r in ins)})")
    vals = []
    for r in ins:
        if r.name in u0:
            v = V.vector(f"u0[{r.name!r}]", np.atleast_1d(np.asarray(u0[r.name], dtype=float)), r.size)
        elif r.kind == "wheels":
            v = sim.wheel_command(r.body)
        else:
            v = np.atleast_1d(np.asarray(scene.effects[r.effect_index].values[r.param], dtype=float))
        vals.append(np.asarray(v, dtype=float).reshape(r.size))
    return np.concatenate(vals) if vals else np.zeros(0)


# ------------------------------------------------------------------------------------------------
# the CasADi right-hand side in error coordinates
# ------------------------------------------------------------------------------------------------


def _dtheta_dot(q_ref: np.ndarray, q, q_dot):
    """d/dt dtheta of the printed chart dtheta = quat_error_chart(q, q_ref) (2 vec(q_ref* ⊗ q) on the
    chart's domain, e_w > 0: linear in q, so its Jacobian is constant)."""
    qs = ca.SX.sym("qs", 4)
    return ca.mtimes(ca.substitute(ca.jacobian(KC.quat_error_chart(qs, ca.DM(q_ref)), qs), qs, q), q_dot)


def _loads(scene, ref: BodyRef, p_w, q, v_w, w, params_of):
    """(F_w, tau_w): the sum of the force effects on this body, each from its own CasADi printing."""
    F, tau = ca.DM.zeros(3, 1), ca.DM.zeros(3, 1)
    state = {"p_w": p_w, "q": q, "v_w": v_w, "omega_b": w, "m": ca.DM(ref.m), "I_b": ca.DM(ref.I_b)}
    for k, e in enumerate(scene.effects):
        if e.per_body or e.body not in (None, ref.name):
            continue
        spec = E.check_declared(e)
        kw = {s: state[s] for s in spec.state_inputs}
        kw.update(params_of(k, e))
        if ref.R_bp is not None:   # body-frame parameters (r_b) into the body's principal frame
            for p in spec.params:
                if p.frame == "body":
                    kw[p.name] = ca.mtimes(ca.DM(ref.R_bp.T), kw[p.name])
        f, t = E.casadi_expr(e.name, **kw)
        F, tau = F + f, tau + t
    return F, tau


def _body_rhs(scene, ref: BodyRef, xb, params_of, wheel_u):
    """The time derivative of this body's error block (CasADi column)."""
    r = ref.row
    get = ref.split(xb)
    q = KC.quat_error_chart_inverse(ca.DM(ref.x[LY.STATE_Q]), get["dtheta"])
    w = ca.DM(ref.x[LY.STATE_OMEGA_B]) + get["omega"]
    I_p, r_b = ca.DM(r[LY.MODEL_I_P]), ca.DM(r[LY.MODEL_R_B])
    if ref.joint:
        p_w, v_w = KC.pivot_kinematics(q, w, ca.DM(r[LY.MODEL_ANCHOR_W]), r_b)
    else:
        p_w, v_w = ca.DM(ref.x[LY.STATE_P_W]) + get["p"], ca.DM(ref.x[LY.STATE_V_W]) + get["v"]
    F, tau = _loads(scene, ref, p_w, q, v_w, w, params_of)
    out = {}
    if ref.wheels:
        q_dot, out["omega"], out["Omega"] = _wheel_rhs(ref, q, w, ca.DM(ref.Omega) + get["Omega"], wheel_u, F, tau)
        if not ref.joint:
            out["p"], out["v"] = KC.translation_rhs(ref.m, v_w, F)
    elif ref.joint:
        q_dot, out["omega"] = KC.pivot_body_rhs(q, w, I_p, r_b, F, tau)
    else:
        xd = KC.rigid_body_rhs(ca.vertcat(p_w, q, v_w, w), ref.m, ca.DM(ref.I_b), F, tau)
        q_dot = xd[LY.STATE_Q]
        out["p"], out["v"], out["omega"] = xd[LY.STATE_P_W], xd[LY.STATE_V_W], xd[LY.STATE_OMEGA_B]
    out["dtheta"] = _dtheta_dot(ref.x[LY.STATE_Q], q, q_dot)
    return ca.vertcat(*[out[b] for b in ref.blocks])


def _wheel_rhs(ref: BodyRef, q, w, Om, wheel_u, F, tau):
    """(q_dot, omega_dot_b, Omega_dot) of a wheeled body through the printed CasADi kernels the Sim steps (the
    WHEELS_MAX-wheel model on the row's axes, the unused slots padded at rest); Omega_dot of its N wheels only."""
    r = ref.row
    I_p, r_b = ca.DM(r[LY.MODEL_I_P]), ca.DM(r[LY.MODEL_R_B])
    lim = (float(r[LY.MODEL_TORQUE_LIMIT]), float(r[LY.MODEL_SPEED_LIMIT]), float(r[LY.MODEL_CUTOFF]))
    pad = ca.DM.zeros(LY.WHEELS_MAX - ref.n_wheels, 1)
    Om_all, cmd = ca.vertcat(Om, pad), ca.vertcat(wheel_u, pad)
    u = getattr(KC, f"wheels{LY.WHEELS_MAX}_motor")(cmd, Om_all, *lim)
    q_dot, w_dot, Om_dot = getattr(KC, f"wheels{LY.WHEELS_MAX}_body_rhs")(
        q, w, Om_all, I_p, ca.DM(r[LY.MODEL_A_B]), ca.DM(r[LY.MODEL_J]), r_b, F, tau, u, float(r[LY.MODEL_C_W]))
    return q_dot, w_dot, Om_dot[:ref.n_wheels]


def casadi_error_rhs(scene, refs: list[BodyRef], ins: list[InputRef], u0: np.ndarray) -> ca.Function:
    """f(x, du) -> x_dot in error coordinates (CasADi Function), for the whole scene."""
    n = sum(r.size for r in refs)
    m = sum(r.size for r in ins)
    x, du = ca.SX.sym("x", n), ca.SX.sym("du", m)
    u = ca.DM(u0) + du if m else du

    def params_of(k, e):
        vals = {}
        for f in e.fields:
            vals[f] = ca.DM(np.atleast_1d(np.asarray(e.values[f], dtype=float)))
        for r in ins:
            if r.kind == "effect" and r.effect_index == k:
                vals[r.param] = u[r.offset:r.offset + r.size]
        return vals

    parts = []
    for ref in refs:
        wu: ca.SX | ca.DM | None = next((u[r.offset:r.offset + r.size] for r in ins if r.kind == "wheels" and r.body == ref.name), None)
        if ref.wheels and wu is None:   # not an input: held at the Sim's command (set by the caller via u0 of the ref)
            wu = ca.DM(ref_command(ref))
        parts.append(_body_rhs(scene, ref, x[ref.offset:ref.offset + ref.size], params_of, wu))
    return ca.Function("scene_error_rhs", [x, du], [ca.vertcat(*parts)], ["x", "du"], ["x_dot"])


def frame_transform(refs: list[BodyRef], n: int) -> np.ndarray | None:
    """T (n, n) with x_body = T x_principal: R_bp on the dtheta and omega blocks of each body given a full
    inertia tensor, the identity elsewhere (world-frame blocks, wheel rates); None when there is none.
    dtheta rotates like a vector: q_ref,p* ⊗ q_p = q_bp* ⊗ (q_ref,b* ⊗ q_b) ⊗ q_bp."""
    if all(r.R_bp is None for r in refs):
        return None
    T = np.eye(n)
    for r in refs:
        if r.R_bp is not None:
            for b in ("dtheta", "omega"):
                sl = r.index(b)
                T[sl, sl] = r.R_bp
    return T


def ref_command(ref: BodyRef) -> np.ndarray:
    return np.zeros(ref.n_wheels) if ref.command is None else ref.command


def jacobians(f: ca.Function, n: int, m: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(f0, A, B) at x = 0, du = 0 by CasADi's automatic differentiation."""
    x, du = ca.SX.sym("x", n), ca.SX.sym("du", m)
    fx = f(x, du)
    jac = ca.Function("scene_linearization", [x, du], [fx, ca.jacobian(fx, x), ca.jacobian(fx, du)])
    f0, A, B = (np.asarray(v, dtype=float).reshape(s) for v, s in zip(jac(np.zeros(n), np.zeros(m)),
                                                                    ((n,), (n, n), (n, m))))
    return f0, A, B


# ------------------------------------------------------------------------------------------------
# mapping between simulator states and error coordinates
# ------------------------------------------------------------------------------------------------


def state_of(refs: list[BodyRef], sim) -> np.ndarray:
    """The error-coordinate state of a Sim built from the same scene."""
    parts: list[np.ndarray] = []
    for ref in refs:
        i = sim.names.index(ref.name)
        x, xr = sim.state(ref.name).x, ref.x_pub   # both in the body frame
        assert xr is not None   # (set by __post_init__)
        blk = {"dtheta": attitude_error(x[LY.STATE_Q], xr[LY.STATE_Q]),
               "omega": x[LY.STATE_OMEGA_B] - xr[LY.STATE_OMEGA_B]}
        if not ref.joint:
            blk["p"], blk["v"] = x[LY.STATE_P_W] - xr[LY.STATE_P_W], x[LY.STATE_V_W] - xr[LY.STATE_V_W]
        if ref.wheels:
            blk["Omega"] = sim.wheel_rates(ref.name) - ref.Omega
        parts.extend(blk[b] for b in ref.blocks)
    return np.concatenate(parts)


def set_state(refs: list[BodyRef], sim, x: np.ndarray) -> None:
    """Put a Sim (built from the same scene) at the error-coordinate state x."""
    for ref in refs:
        get, xr = ref.split(x[ref.offset:ref.offset + ref.size]), ref.x_pub
        assert xr is not None   # (set by __post_init__)
        kw = {"q": perturbed(xr[LY.STATE_Q], get["dtheta"]), "omega_b": xr[LY.STATE_OMEGA_B] + get["omega"]}
        if not ref.joint:
            kw["p_w"], kw["v_w"] = xr[LY.STATE_P_W] + get["p"], xr[LY.STATE_V_W] + get["v"]
        if ref.wheels:
            kw["Omega"] = ref.Omega + get["Omega"]
        sim.set_state(ref.name, **kw)


# ------------------------------------------------------------------------------------------------
# the StateSpace
# ------------------------------------------------------------------------------------------------


class Linearization(ct.StateSpace):
    """A python-control ``StateSpace`` (continuous, or discrete after :meth:`sample`) with what the
    lavendersim designs need: the operating point, the input map and the controllable subspace.

    Besides StateSpace's A, B, C, D, dt and state/input/output labels:

    Attributes
    ----------
    bodies : list of BodyRef
        Each body's operating point and its block of the error state.
    input_refs : list of InputRef
        Each named input and its slice of u.
    u0 : ndarray (m,)
        The operating input (wheel commands N·m, effect parameters in their units); the model's
        input is du = u − u0.
    f0 : ndarray (n,)
        The continuous right-hand side at the operating point (zero at an equilibrium).
    basis : ndarray (n, rank)
        Orthonormal basis of the controllable subspace.
    """

    def __init__(self, A, B, C=None, D=None, dt=0, *, bodies=None, input_refs=None, u0=None, f0=None, basis=None,
                 wheel_states=None, **kwargs):
        A, B = np.asarray(A, float), np.asarray(B, float)
        C = np.eye(A.shape[0]) if C is None else C
        D = np.zeros((np.shape(C)[0], B.shape[1])) if D is None else D
        super().__init__(A, B, C, D, dt, **kwargs)
        self.bodies = bodies or []
        self.input_refs = input_refs or []
        self.u0 = np.zeros(B.shape[1]) if u0 is None else np.asarray(u0, float)
        self.f0 = np.zeros(A.shape[0]) if f0 is None else np.asarray(f0, float)
        self.basis = controllable_basis(self.A, self.B, discrete=self.isdtime(strict=True)) if basis is None else basis
        self.wheel_states = np.zeros(0, int) if wheel_states is None else np.asarray(wheel_states, int)

    # controllability -------------------------------------------------------------------------
    @property
    def rank(self) -> int:
        """Dimension of the controllable subspace."""
        return int(self.basis.shape[1])

    @property
    def controllable(self) -> bool:
        """Whether the pair (A, B) is controllable (rank == n)."""
        return self.rank == self.nstates

    @property
    def uncontrollable_basis(self) -> np.ndarray:
        """Orthonormal basis U (n, n − rank) of the complement of the controllable subspace: Uᵀx are
        the coordinates no input can change (conserved momenta for internal wheel torques)."""
        return uncontrollable(self.basis, self.nstates)

    # operating point -------------------------------------------------------------------------
    @property
    def equilibrium_residual(self) -> float:
        """max |f0|: zero at an equilibrium."""
        return float(np.max(np.abs(self.f0), initial=0.0))

    @property
    def q_ref(self) -> np.ndarray:
        """The first body's reference orientation (x, y, z, w)."""
        return self.bodies[0].x_pub[LY.STATE_Q].copy()

    @property
    def Omega0(self) -> np.ndarray:
        """The first body's reference wheel rates, rad/s (zeros without wheels)."""
        return self.bodies[0].Omega.copy()

    def state(self, q: np.ndarray, omega_b: np.ndarray, Omega: np.ndarray | None = None) -> np.ndarray:
        """Error state of a single jointed body from its q, omega_b (and Omega with wheels)."""
        ref = self.bodies[0]
        if len(self.bodies) != 1 or not ref.joint:
            raise V.LavenderInputError("state", "takes (q, omega_b, Omega) only for one jointed body; use state_of(sim)")
        parts = [attitude_error(q, ref.x_pub[LY.STATE_Q]), np.asarray(omega_b, float) - ref.x_pub[LY.STATE_OMEGA_B]]
        if ref.wheels:
            parts.append(np.asarray(Omega, float) - ref.Omega)
        return np.concatenate(parts)

    def state_of(self, sim) -> np.ndarray:
        """Error-coordinate state (n,) of a Sim built from the linearized scene."""
        return state_of(self.bodies, sim)

    def set_state(self, sim, x: np.ndarray) -> None:
        """Put a Sim built from the linearized scene at error state x (n,)."""
        set_state(self.bodies, sim, np.asarray(x, float))

    def target(self, x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(x_ss, du_ss): the equilibrium that differs from the operating point only in wheel rates and
        has the same conserved coordinates Uᵀx as x, and the input holding it (zeros when x carries
        no conserved momentum or the model has no wheels)."""
        n = self.nstates
        x_ss, du = np.zeros(n), np.zeros(self.ninputs)
        if self.rank == n or self.wheel_states.size == 0:
            return x_ss, du
        U = self.uncontrollable_basis
        w = self.wheel_states
        x_ss[w] = np.linalg.lstsq(U[w, :].T, U.T @ np.asarray(x, float), rcond=1e-9)[0]   # rcond: null-space wheel directions carry no momentum
        Ac = self.A - np.eye(n) if self.isdtime(strict=True) else self.A
        r = Ac @ x_ss
        if np.any(r != 0):
            du = np.linalg.lstsq(self.B, -r, rcond=1e-9)[0]
        return x_ss, du

    def target_map(self) -> tuple[np.ndarray, np.ndarray]:
        """(P (n, n), G (m, n)): :meth:`target` is linear in x, ``x_ss = P x`` and ``du_ss = G x``."""
        cols = [self.target(e) for e in np.eye(self.nstates)]
        return (np.array([c[0] for c in cols]).T.reshape(self.nstates, self.nstates),
                np.array([c[1] for c in cols]).T.reshape(self.ninputs, self.nstates))

    def control_law(self, K: np.ndarray, x: np.ndarray) -> np.ndarray:
        """u = u0 + du_ss − K (x − x_ss) (unsaturated), in the inputs' units: the state feedback u = −K x
        about the operating point, regulating to the equilibrium :meth:`target` that keeps x's conserved
        coordinates. (Not ``StateSpace.feedback``, which closes a loop between two systems and is kept
        as python-control defines it.)

        Parameters
        ----------
        K : array_like (m, n)
            A gain, e.g. from :func:`lavendersim.control.lqr`.
        x : array_like (n,)
            Error-coordinate state.

        Returns
        -------
        ndarray (m,)
        """
        x = np.asarray(x, float)
        x_ss, du = self.target(x)
        return self.u0 + du - np.asarray(K) @ (x - x_ss)

    # discretization --------------------------------------------------------------------------
    def sample(self, Ts: float, method: str = "zoh", **kwargs) -> "Linearization":
        """The discrete model at period Ts (s): zero-order hold by default (python-control's c2d);
        the operating point and the labels are kept."""
        if self.isdtime(strict=True):
            raise V.LavenderInputError("dt", "this model is already discrete", f" (dt = {self.dt})")
        Ts = V.positive("dt", Ts)
        d = ct.StateSpace.sample(ct.StateSpace(self.A, self.B, self.C, self.D), Ts, method=method, **kwargs)
        return Linearization(d.A, d.B, d.C, d.D, Ts, bodies=self.bodies, input_refs=self.input_refs, u0=self.u0,
                             f0=self.f0, wheel_states=self.wheel_states, states=self.state_labels,
                             inputs=self.input_labels, outputs=self.output_labels, name=f"{self.name}_d")


# ------------------------------------------------------------------------------------------------
# linearize()
# ------------------------------------------------------------------------------------------------


def linearize_scene(sim_or_scene, x0=None, u0=None, *, inputs=None, outputs=None, dt=None, name="lavendersim",
                    labels=None) -> Linearization:
    """See lavendersim.control.linearize."""
    sim, scene = _sim_of(sim_or_scene)
    refs = body_refs(sim, x0)
    ins = input_refs(sim, scene, inputs)
    u0v = input_u0(sim, scene, ins, u0)
    for ref in refs:   # wheels that are not inputs keep the Sim's held command
        if ref.wheels:
            ref.command = sim.wheel_command(ref.name)
    n, m = sum(r.size for r in refs), sum(r.size for r in ins)
    f = casadi_error_rhs(scene, refs, ins, u0v)
    f0, A, B = jacobians(f, n, m)
    T = frame_transform(refs, n)
    if T is not None:   # the principal-frame model in the body frames' error coordinates
        A, B, f0 = T @ A @ T.T, T @ B, T @ f0
    if not (np.all(np.isfinite(A)) and np.all(np.isfinite(B)) and np.all(np.isfinite(f0))):
        raise V.LavenderInputError("x0", "the model is not differentiable there (non-finite Jacobian)")
    states = labels or [lab for r in refs for lab in r.labels()]
    C, D = np.eye(n), np.zeros((n, m))
    if outputs is not None:
        outputs = [outputs] if isinstance(outputs, str) else list(outputs)
        bad = [o for o in outputs if o not in states]
        if bad:
            raise V.LavenderInputError("outputs", f"{bad[0]!r} is not a state label (states: {', '.join(states)})")
        C = C[[states.index(o) for o in outputs]]
        D = D[: len(outputs)]
    wheel_states = [i for r in refs if r.wheels for i in range(r.index("Omega").start, r.index("Omega").stop)]
    lin = Linearization(A, B, C, D, 0, bodies=refs, input_refs=ins, u0=u0v, f0=f0, wheel_states=wheel_states,
                        states=states, inputs=[lab for r in ins for lab in r.labels()],
                        outputs=list(outputs) if outputs is not None else states, name=name)
    return lin if dt is None else lin.sample(dt)
