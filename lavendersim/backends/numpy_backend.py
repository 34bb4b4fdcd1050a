"""NumPy backend: every body of a scene stepped at once, vectorized over the body axis.

The right-hand side evaluates only the declared effects: bodies with none use the torque-free
kernel; the others accumulate F_w and tau_w in table order through each effect's printed NumPy
dispatch (generated/kernels_numpy.py, or a user set's), indexed per body once per plan
(_EffectIndex), and use rigid_body_rhs. An effect code no declaration has raises.
Bodies with a spherical joint and/or reaction wheels (kind != 0 in the model rows) accumulate the
same way (a jointed body's effects that read v_w see its kinematic COM velocity) and
use wheels<WHEELS_MAX>_body_rhs (the one wheel model, on the model row's axes; body-axis wheels are
A_b = [I | 0]) or pivot_body_rhs (joint only). With such bodies the stepped state is (nb, XS_SIZE) =
[x (13), Omega (WHEELS_MAX)]; a jointed body's p_w, v_w are not integrated but set from
pivot_kinematics after every step.
"""
from __future__ import annotations

import functools
import inspect
import itertools
import math
from typing import Any, NamedTuple

import numpy as np

from ..effects import ROW_BODY
from ..errors import DivergenceError
from ..generated import layout as LY
from ..generated import tableaux as T
from ..kernels import K
from . import numpy_scalar as SC
from ..effects import INC_SCALE_C, INC_SCALE_HQ, RHS_BODY, RHS_BODY_F, RHS_FORCE, RHS_FULL, SUM_START
from .base import (DOPRI5_HMIN_REL, DOPRI5_MAX_SUBSTEPS, FLOAT32_INTEGRATORS, KIND_JOINT, KIND_WHEELS, PLAIN_ONLY,
               Adaptive, Models, divergence_cause, no_root_cause, rk_weights, tableau_of, tolerance_cause,
               wheel_counts)

P, Q, V, W = LY.STATE_P_W, LY.STATE_Q, LY.STATE_V_W, LY.STATE_OMEGA_B  # state-row fields
X, OM = LY.XS_X, LY.XS_OMEGA                                               # extended state [x, Omega]
_WHEELS_RHS = getattr(K, f"wheels{LY.WHEELS_MAX}_body_rhs")                  # every wheeled body, on its row's axes
_WHEELS_MOTOR = getattr(K, f"wheels{LY.WHEELS_MAX}_motor")
U, U0 = slice(Q.start, Q.start + 3), Q.start + 3  # rk4_expmap: u in q's first three slots, the fourth held at 0


class _EffectIndex:
    """The effects acting on bodies idx, indexed per body once (CSR: each body's effects in table
    order, the every-body ones included). Evaluation is vectorized per effect code over all its
    (body, effect) pairs; the sums are then taken in each body's table order, so they are bitwise
    those of the C backend. A body pays for its own effects only; an unknown code raises."""

    def __init__(self, effects: np.ndarray, idx: np.ndarray, m: np.ndarray, I: np.ndarray, kmod=None,
                 body_frame=False):
        from .. import effects as E

        def apply_of(spec):
            """The effect's NumPy function; body_frame: its body-frame form when it has one (FLAG_TORQUE_B)."""
            if body_frame and spec.rhs_flags & E.FLAG_TORQUE_B:   # a built-in's printed form, or the user set's
                return (K if spec.user_set is None else spec.user_set.numpy).EFFECT_APPLY_B[spec.name]
            return E.numpy_apply(spec.code) if kmod is None else kmod.EFFECT_APPLY[spec.name]

        self.dtype = m.dtype   # float32 plans sum in float32 with the float32 printing of the effects (kmod)

        n = idx.size
        nb = m.shape[0]
        pos = np.full(nb, -1, np.int64)
        pos[idx] = np.arange(n)
        body = effects[:, E.ROW_BODY].astype(np.int64) if len(effects) else np.zeros(0, np.int64)
        every = np.flatnonzero(body < 0)
        own = np.flatnonzero(body >= 0)
        loc = pos[body[own]]
        pair_row = np.concatenate([np.repeat(every, n), own[loc >= 0]])
        pair_loc = np.concatenate([np.tile(np.arange(n), every.size), loc[loc >= 0]])
        order = np.lexsort((pair_row, pair_loc))
        pair_row, pair_loc = pair_row[order], pair_loc[order]
        start = np.concatenate([[0], np.cumsum(np.bincount(pair_loc, minlength=n))])
        rank = np.arange(pair_row.size) - start[pair_loc]
        codes = effects[pair_row, E.ROW_CODE].astype(np.int64) if pair_row.size else np.zeros(0, np.int64)
        self.npairs = pair_row.size
        self.m, self.I = m[idx], I[idx]
        self.groups = []  # (apply, pair positions, body positions, parameters)
        self.names: list[str] = []   # each group's effect name
        has_F, has_T = np.zeros(self.npairs, bool), np.zeros(self.npairs, bool)
        self.velocity = np.zeros(n, bool)  # bodies with an effect that reads v_w or omega_b
        self.uses_v = False                # some effect reads v_w
        for code in np.unique(codes):
            spec = E.spec_for_code(int(code))  # LavenderInputError for a code no effect declares
            sel = np.flatnonzero(codes == code)
            apply = apply_of(spec)
            self.groups.append((apply, sel, pair_loc[sel], effects[pair_row[sel], E.ROW_PARAMS:].copy()))
            self.names.append(spec.name)
            has_F[sel], has_T[sel] = "F_w" in spec.outputs, "tau_w" in spec.outputs
            if spec.velocity_dependent:
                self.velocity[pair_loc[sel]] = True
            self.uses_v |= spec.uses_v_w
        # every effect acts on every body (no per-body rows): each effect evaluated on all the bodies at once, in
        # table order, with its own parameters: the same sums, no gather or scatter
        # An effect that reads no state value (its kernel's inputs: parameters, m, I_b) is evaluated once here.
        self.uniform = None
        self.nothing: np.ndarray | None = None   # (n, 3) sum of no terms, struct-of-arrays, on first use (_nothing)
        self.program: tuple | None = None       # _uniform_sums' calls (_uniform_program), on first use
        self.bound: tuple | None = None         # ... bound to the last buffers it was given (_bind)
        if n and every.size == len(effects):
            self.uniform = []
            for r in every:
                spec = E.spec_for_code(int(effects[r, E.ROW_CODE]))
                apply = apply_of(spec)
                # its parameters as one row (n_params,): the kernels broadcast it over the bodies, so a coefficient
                # enters as a scalar (e.g. -c once per call, not once per body: 1.4 us of a 4.3 us damping call at 1e3)
                p = effects[r, E.ROW_PARAMS:].copy()
                const = None if set(spec.state_inputs) - {"m", "I_b"} or spec.uses_v_w else apply(p, None, None,
                                                                                                 self.m, self.I)
                takes_out = "out" in inspect.signature(apply).parameters     # (a user set printed before out=: no)
                self.uniform.append((apply, p, "F_w" in spec.outputs, "tau_w" in spec.outputs, const, takes_out))
            self.base = [self._constant_prefix(j) for j in (0, 1)]
        self.ranks = []  # per rank k: (bodies, pairs) adding a force, (bodies, pairs) adding a torque
        for k in range(int(rank.max()) + 1 if rank.size else 0):
            f = np.flatnonzero((rank == k) & has_F)
            t = np.flatnonzero((rank == k) & has_T)
            self.ranks.append((pair_loc[f], f, pair_loc[t], t))

    def affine(self, kmod) -> tuple[np.ndarray, np.ndarray]:
        """The decoupled forces' sums per body (F0 (n, 3), k (n,)): each effect's printed affine form (kmod's
        EFFECT_AFFINE: F = F0 − k v_W; an effect without a force adds nothing: SUM_START, -0) added in table order
        from SUM_START, as csrc/step.c lv_split_flow_scale adds lv_effect_affine's."""
        n = self.m.shape[0]
        cF, ck = np.full((self.npairs, 3), SUM_START), np.full(self.npairs, SUM_START)
        for (_, sel, loc, p), name in zip(self.groups, self.names):
            fn = kmod.EFFECT_AFFINE.get(name)
            if fn is not None:
                cF[sel], ck[sel] = fn(p, self.m[loc])
        F0, k = np.full((n, 3), SUM_START), np.full(n, SUM_START)
        for locF, f, _, _ in self.ranks:
            F0[locF] += cF[f]
            k[locF] += ck[f]
        return F0, k

    def _constant_prefix(self, j: int) -> tuple[int, np.ndarray | None]:
        """Scene-wide effects, output j (0: force, 1: torque): (how many of its leading terms are constant, their
        sum SUM_START + c_1 + c_2 + ... in table order, struct-of-arrays, or None)."""
        terms = [u[4] and u[4][j] for u in self.uniform if u[2 + j]]
        k = next((i for i, c in enumerate(terms) if c is None), len(terms))
        if not k:
            return 0, None
        acc = _soa(np.full((self.m.shape[0], 3), SUM_START, self.dtype))
        for c in terms[:k]:
            acc += c
        return k, acc

    def _uniform_program(self) -> tuple:
        """_uniform_sums' calls, fixed once per plan: for each effect that adds a term each call (apply, p, its
        constant output or None, takes_out, the out slots its output is written into (None: not written), the adds
        (j, prev): out[j] = prev + t_j with prev None (t + SUM_START), an array (the constant prefix) or j (the
        running sum)), and per output the array returned when no term is added each call (None: out[j]; the sum of
        nothing is _nothing(), SUM_START)."""
        done, prog = [0, 0], []     # terms of each output summed so far
        for apply, p, has_F, has_T, const, takes_out in self.uniform:
            dest: list = [None, None]
            adds = []
            for j, has in enumerate((has_F, has_T)):
                k, base = self.base[j]
                done[j] += has
                if has and done[j] > k:     # the first term is written into the sum itself, then + SUM_START
                    dest[j] = j if done[j] == 1 else 2 + j
                    adds.append((j, base if done[j] == k + 1 else j))
            if adds:
                prog.append((apply, p, const, takes_out, tuple(dest), tuple(adds)))
        fixed = tuple(None if done[j] > self.base[j][0] else (self.base[j][1] if self.base[j][0] else self._nothing())
                      for j in (0, 1))
        return tuple(prog), fixed

    def _bind(self, out) -> tuple:
        """_uniform_program's calls on the buffers out: (out, per effect (apply, p, its constant output or None, the
        out= it takes or None, the adds (left operand or None for t + SUM_START, destination, j)), the (F, tau)
        returned)."""
        if self.program is None:
            self.program = self._uniform_program()
        calls = []
        for apply, p, const, takes_out, (a, b), adds in self.program[0]:
            o = (None if a is None else out[a], None if b is None else out[b]) if takes_out else None
            calls.append((apply, p, const, o, tuple((None if prev is None else out[j] if isinstance(prev, int) else prev,
                                                    out[j], j) for j, prev in adds)))
        fF, fT = self.program[1]     # no term, or constant terms only: the plan's own array (read only; no copy)
        return out, tuple(calls), (out[0] if fF is None else fF, out[1] if fT is None else fT)

    def _uniform_sums(self, x, v, out):
        """sums() when every effect acts on every body: each effect on all the bodies at once, in table order, the
        leading constant terms folded once per plan (_constant_prefix). out: (F, tau, and two scratch arrays of
        their shape); the effects' kernels write into them where their printing takes out= (no copies). The calls
        are bound to out once (_bind) while the same buffers come back."""
        bound = self.bound
        if bound is None or bound[0] is not out:
            bound = self.bound = self._bind(out)
        m, I = self.m, self.I
        for apply, p, const, o, adds in bound[1]:
            ft = const if const is not None else apply(p, x, v, m, I) if o is None else apply(p, x, v, m, I, out=o)
            for left, dst, j in adds:
                # the running sum SUM_START + t_1 + t_2 + ...: the first term as t + SUM_START (t itself, -0 kept)
                if left is None:
                    np.add(ft[j], SUM_START, out=dst)
                else:
                    np.add(left, ft[j], out=dst)
        return bound[2]

    def _nothing(self) -> np.ndarray:
        """The sum of no terms (SUM_START) per body, (n, 3) struct-of-arrays, made once."""
        if self.nothing is None:
            self.nothing = _soa(np.full((self.m.shape[0], 3), SUM_START, self.dtype))
        return self.nothing

    def sums(self, x: np.ndarray, v: np.ndarray, out: tuple[np.ndarray, ...] | None = None
             ) -> tuple[np.ndarray, np.ndarray]:
        """Total force at the COM and torque about it (world), per body of idx: x their states (n, >= 13),
        v the COM velocities the effects see; with uniform effects written into out when given (F, tau and two
        scratch arrays of their shape: Plan.loads_buffer)."""
        n = x.shape[0]
        if self.uniform is not None and self.npairs:
            return self._uniform_sums(x, v, out or tuple(np.empty((n, 3), self.dtype) for _ in range(4)))
        F, tau = np.full((n, 3), SUM_START, self.dtype), np.full((n, 3), SUM_START, self.dtype)
        if not self.npairs:
            return F, tau
        cF, cT = np.empty((self.npairs, 3), self.dtype), np.empty((self.npairs, 3), self.dtype)
        for apply, sel, loc, p in self.groups:
            f, t = apply(p, x[loc], v[loc], self.m[loc], self.I[loc])
            if f is not None:
                cF[sel] = f
            if t is not None:
                cT[sel] = t
        for locF, f, locT, t in self.ranks:
            F[locF] += cF[f]
            tau[locT] += cT[t]
        return F, tau


class _Group:
    """Bodies with a joint and/or wheels that share one rotational kernel (pivot_body_rhs or the wheel model)."""

    def __init__(self, idx, effects, m, I, rows):
        self.idx = idx
        self.index = _EffectIndex(effects, idx, m, I)
        self.m = m[idx]
        r = rows[idx]
        kind = r[:, LY.MODEL_KIND].astype(np.int64)
        self.jointed = (kind & KIND_JOINT) != 0
        # the kinematic COM velocity is only needed by effects that read v_w
        self.needs_v = bool(self.jointed.any()) and self.index.uses_v
        self.I_p = r[:, LY.MODEL_I_P].reshape(-1, 3, 3).copy()
        self.r_b, self.anchor, self.J = r[:, LY.MODEL_R_B].copy(), r[:, LY.MODEL_ANCHOR_W].copy(), r[:, LY.MODEL_J].copy()
        self.tl, self.sl = r[:, LY.MODEL_TORQUE_LIMIT].copy(), r[:, LY.MODEL_SPEED_LIMIT].copy()
        self.c_w = r[:, LY.MODEL_C_W].copy()
        self.cutoff = r[:, LY.MODEL_CUTOFF].copy()
        self.A_b = r[:, LY.MODEL_A_B].reshape(-1, 3, LY.WHEELS_MAX).copy()
        self.n_wheels = wheel_counts(r)

    def wheel_rhs(self, xg, F, tau, u, o):
        """q, omega_b, Omega derivatives of the group's wheeled bodies into o (padded wheel slots stay at rest)."""
        o[:, Q], o[:, W], o[:, OM] = _WHEELS_RHS(xg[:, Q], xg[:, W], xg[:, OM], self.I_p, self.A_b, self.J,
                                                 self.r_b, F, tau, u, self.c_w)

    def motor(self, command, Omega):
        """The torques the group's motors apply (command, Omega: its rows, (n, WHEELS_MAX))."""
        return _WHEELS_MOTOR(command, Omega, self.tl, self.sl, self.cutoff)

    def velocity(self, x):
        """COM velocity for the effects: kinematic for jointed bodies, the state's otherwise."""
        v = x[:, V]
        if self.needs_v:
            kin = K.pivot_kinematics(x[:, Q], x[:, W], self.anchor, self.r_b)[1]
            v = np.where(self.jointed[:, None], kin, v)
        return v

    def translation(self, x, F, out):
        """p, v derivatives: zero for jointed bodies (set from the joint after the step), free otherwise."""
        p_dot, v_dot = K.translation_rhs(self.m, x[:, V], F)
        out[:, P] = np.where(self.jointed[:, None], 0.0, p_dot)
        out[:, V] = np.where(self.jointed[:, None], 0.0, v_dot)


# Bodies from which a step forms the rows its right-hand side reads one run each (fewer bytes) rather than one run
# over them (fewer NumPy calls); measured: /work/notes/s15/H6.md
ROWS_SPLIT_BODIES = 8192


def _runs(rows) -> tuple[tuple[int, int], ...]:
    """Sorted row numbers as contiguous runs [(start, stop)]."""
    out: list[list[int]] = []
    for r in sorted(rows):
        if out and out[-1][1] == r:
            out[-1][1] = r + 1
        else:
            out.append([r, r + 1])
    return tuple((a, b) for a, b in out)


class _StateRows:
    """The state rows an explicit Runge–Kutta step of plain bodies forms, from the printed READS and ZEROS tables
    (generated/kernels_scalar.py): in a stage only the rows its right-hand side reads (the kernels' and the effects'
    inputs); a row whose rate is identically 0 (every kernel in use prints 0) as x + z, z the step's sum over zeros
    (±0: the same number as the full sum); the other rows as the full sum. Runs (start, stop) of rows."""

    __slots__ = ("stage", "zero", "end", "few")

    def __init__(self, width, reads, zeros):
        self.stage = _runs(set(reads) - set(zeros))
        self.zero = _runs(zeros)
        self.end = _runs(set(range(width)) - set(zeros))
        # below ROWS_SPLIT_BODIES a NumPy call costs more than its rows: one run over the rows read, zero rates
        # summed in full (the same numbers), and every row at the end
        self.few = _StateRows.__new__(_StateRows)
        self.few.stage, self.few.zero, self.few.end = _runs(range(min(reads), max(reads) + 1)), (), ((0, width),)
        self.few.few = self.few

    def at(self, n: int) -> _StateRows:
        """The runs for n bodies (fewer NumPy calls for small n)."""
        return self if n >= ROWS_SPLIT_BODIES else self.few

    @staticmethod
    def of(plan, effects) -> _StateRows | None:
        from .. import effects as E
        from ..generated import kernels_scalar as KS

        if not hasattr(KS, "READS"):       # a generated/ printed before the tables: every row, as before
            return None
        reads, zeros = set(), set(range(LY.STATE_SIZE))
        kernels = (["rigid_body_rhs_free_c"] if plan.free.size else []) + (["rigid_body_rhs_c"] if plan.forced.size else [])
        read_table: dict[str, Any] = KS.READS      # kernel -> argument -> the rows it reads
        zero_table: dict[str, Any] = KS.ZEROS      # kernel -> output -> the rows it leaves 0
        for name in kernels:
            reads |= set(read_table[name]["x"])
            zeros &= set(zero_table[name]["x_dot"])
        for code in set(effects[:, E.ROW_CODE].astype(int).tolist()) if plan.forced.size else ():
            spec = E.spec_for_code(code)
            for field in spec.state_inputs + (("v_w",) if spec.uses_v_w else ()):
                sl = getattr(LY, f"STATE_{field.upper()}", None)
                reads |= set(range(sl.start, sl.stop)) if sl is not None else set()
        return _StateRows(LY.STATE_SIZE, reads, zeros)


class _Plan:
    """Which kernels run for which bodies: precomputed once per (params, effects, model rows)."""

    def __init__(self, params: np.ndarray, effects: np.ndarray, rows: np.ndarray | None = None):
        nb = params.shape[0]
        # float32 params: the float32 plan (plain bodies, built-in effects), on the float32 kernels
        self.K = K if params.dtype != np.float32 else _kernels_f32()
        self.m, self.I = params[:, LY.PARAM_M], params[:, LY.PARAM_I_B]
        kind = np.zeros(nb, np.int64) if rows is None else rows[:, LY.MODEL_KIND].astype(np.int64)
        touched = np.zeros(nb, bool)
        body = effects[:, ROW_BODY].astype(np.int64) if len(effects) else np.zeros(0, np.int64)
        touched[body[body >= 0]] = True
        touched[:] |= bool((body < 0).any())
        plain = kind == 0
        self.has_models = not plain.all()
        self.all_free = not touched.any() and not self.has_models
        self.free = np.flatnonzero(plain & ~touched)
        self.forced = np.flatnonzero(plain & touched)
        self.index = _EffectIndex(effects, self.forced, self.m, self.I, None if self.K is K else self.K)
        self.fgroups: list[_ForcedGroup] | None = None    # the forced bodies by right-hand side class, on first use
        self.one: _ForcedGroup | None = None              # ... its only group when it holds every body
        self.m_f, self.I_f = self.m[self.forced], self.I[self.forced]
        self.damped_f = self.index.velocity  # bodies with an effect that reads v_w or omega_b
        self.wheeled = (kind & KIND_WHEELS) != 0
        self.nb = nb
        # the arrays it was built from, for dopri5's subset plans (_subplan); NumpyBackend.plan replaces them by
        # read-only views of its key's bytes (the arrays as they were, no copy)
        self.source: tuple[np.ndarray | None, ...] = (params, effects, rows)
        self.subplans: dict[Any, _Plan] = {}
        self.I_free = self.I[self.free]
        # Euler's coefficients, once per plan, struct-of-arrays (the kernels read each coefficient contiguously)
        self.c_free = _soa(self.K.euler_coefficients(self.I_free))
        self.c_f = _soa(self.K.euler_coefficients(self.I_f))
        self.works: dict[Any, Any] = {}
        self.last_loads: tuple[np.ndarray, ...] | None = None    # loads_buffer's last answer
        self.scalar = None     # numpy_scalar.ScalarBodies, built on first use
        self.rows = None if self.has_models else _StateRows.of(self, effects)
        pivot = np.flatnonzero(kind == KIND_JOINT)
        wheeled = np.flatnonzero(self.wheeled)   # one wheel model: one group
        self.wheels = [_Group(wheeled, effects, self.m, self.I, rows)] if wheeled.size else []
        self.pivot = _Group(pivot, effects, self.m, self.I, rows) if pivot.size else None
        self.jointed = np.flatnonzero((kind & KIND_JOINT) != 0)
        # dopri5's error norm counts the state and the rates of the wheels in use (padded slots stay 0), as C does
        self.norm_cols = np.where(self.wheeled, LY.XS_OMEGA.start + (wheel_counts(rows) if rows is not None else 0),
                                  LY.STATE_SIZE).astype(float)
        if self.jointed.size:
            assert rows is not None   # (jointed bodies have model rows)
            r = rows[self.jointed]
            self.j_anchor, self.j_r_b = r[:, LY.MODEL_ANCHOR_W].copy(), r[:, LY.MODEL_R_B].copy()

    def work(self, x: np.ndarray, stages: int) -> _Work:
        """The explicit Runge–Kutta stepper's work buffers for states shaped as x, kept for the next call."""
        key = (x.shape, x.dtype.str, stages)
        w = self.works.get(key)
        if w is None:
            w = self.works[key] = _Work(x.shape, x.dtype, stages)
        return w

    def adopt(self, xn: np.ndarray, x: np.ndarray) -> np.ndarray:
        """The state after a step: xn itself when it is a work buffer (x, the state before, takes its place: no
        copy), else x with xn copied in."""
        for w in self.works.values():
            if isinstance(w, _Work) and w.xn is xn:
                w.xn = x
                return xn
        x[...] = xn
        return x

    def loads_buffer(self, x: np.ndarray) -> tuple[np.ndarray, ...]:
        """Struct-of-arrays (n, 3) buffers for the force and torque sums of states shaped as x, and two scratch."""
        w = self.last_loads
        if w is not None and w[0].shape[0] == x.shape[0] and w[0].dtype == x.dtype:
            return w
        key = (x.shape[0], x.dtype.str, "loads")
        w = self.works.get(key)
        if w is None:
            w = self.works[key] = tuple(np.empty((3, x.shape[0]), x.dtype).T for _ in range(4))
        self.last_loads = w
        return w

    def rhs(self, x: np.ndarray, u: np.ndarray | None = None, out: np.ndarray | None = None) -> np.ndarray:
        """d/dt of x (nb, 13), or of [x, Omega] (nb, XS_SIZE) with u (nb, WHEELS_MAX) when bodies have models; into
        out (of x's shape) if given. Plain bodies use Euler's coefficients computed once per plan (the _c kernels)."""
        if self.all_free:
            return self.K.rigid_body_rhs_free_c(x, self.c_free, out=(out,))
        one = self.one
        if one is not None and out is not None:     # every body plain with effects, one class (the branch below)
            return one.rhs(self.K, x, x[:, V], self.loads_buffer(x), out)
        out = np.empty_like(x) if out is None else out
        if x.shape[1] > LY.STATE_SIZE:
            out[:, OM] = 0.0
        if self.free.size:
            out[self.free, X] = self.K.rigid_body_rhs_free_c(x[self.free, X], self.c_free)
        if self.forced.size and self.fgroups is None:
            self.fgroups = _forced_groups(self)
            self.one = self.fgroups[0] if self.forced.size == self.nb and len(self.fgroups) == 1 else None
        fgroups = self.fgroups or []
        if self.forced.size == self.nb and len(fgroups) == 1:  # every body plain, one class: no gather, no scatter
            fgroups[0].rhs(self.K, x, x[:, V], self.loads_buffer(x), out)
        elif self.forced.size:
            for fg in fgroups:
                xf = x[fg.idx, X]
                out[fg.idx, X] = fg.rhs(self.K, xf, xf[:, V], None, None)
        for g in self.wheels:
            assert u is not None   # (bodies with wheels step with their commands)
            xg = x[g.idx]
            F, tau = g.index.sums(xg, g.velocity(xg))
            o = np.empty((g.idx.size, LY.XS_SIZE))
            g.wheel_rhs(xg, F, tau, u[g.idx], o)
            g.translation(xg, F, o)
            out[g.idx] = o
        p = self.pivot
        if p is not None:
            xg = x[p.idx]
            F, tau = p.index.sums(xg, p.velocity(xg))
            o = np.zeros((p.idx.size, LY.XS_SIZE))
            o[:, Q], o[:, W] = K.pivot_body_rhs(xg[:, Q], xg[:, W], p.I_p, p.r_b, F, tau)
            p.translation(xg, F, o)
            out[p.idx] = o
        return out

    def loads(self, x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Plain bodies: (F_w, tau_b) of their effects, (nb, 3) each; SUM_START (-0, the sum of nothing, as C's
        plain_loads and gyro_step) for bodies without effects."""
        F = np.full((x.shape[0], 3), SUM_START)
        tau_b = np.full((x.shape[0], 3), SUM_START)
        if self.forced.size:
            xf = x[self.forced]
            Ff, tf = self.index.sums(xf, xf[:, V])
            F[self.forced], tau_b[self.forced] = Ff, K.world_to_body(xf[:, Q], tf)
        return F, tau_b

    def applied(self, x: np.ndarray, command: np.ndarray) -> np.ndarray | None:
        """Saturated wheel torques for this step (zero-order hold), (nb, WHEELS_MAX) (zero rows for bodies without
        wheels), or None without wheeled bodies."""
        if not self.wheels:
            return None
        u = np.zeros((x.shape[0], LY.WHEELS_MAX))
        for g in self.wheels:
            u[g.idx] = g.motor(command[g.idx], x[g.idx, OM])
        return u

    def wheel_info(self, x: np.ndarray, b: int) -> tuple:
        """(Omega, (J, c_w)) of body b if it has wheels, else (None, None): for divergence_cause."""
        for g in self.wheels:
            if b in g.idx:
                k = int(np.flatnonzero(g.idx == b)[0])
                n = int(g.n_wheels[k])
                return x[b, OM][:n], (g.J[k][:n], g.c_w[k])
        return None, None

    def constrain(self, x: np.ndarray) -> None:
        """Jointed bodies: p_w, v_w from the joint kinematics of the new q, omega."""
        if self.jointed.size:
            j = self.jointed
            x[j, P], x[j, V] = K.pivot_kinematics(x[j, Q], x[j, W], self.j_anchor, self.j_r_b)


class _ForcedGroup:
    """Plain bodies with effects of one right-hand side class: idx (into the plan's bodies), their effect index
    (the body-frame forms for RHS_BODY*), masses and Euler coefficients."""

    def __init__(self, cls, idx, index, m, c, split=0, const=None):
        self.cls, self.idx, self.index, self.m, self.c = cls, idx, index, m, c
        self.split = split   # E.RHS_SPLIT's rotation of a decoupled group (0: the 13-number stages)
        # (torque, force) when every effect of the group's bodies reads no state (effects.constant_kind): the bodies
        # then step (q, omega_b) alone (_const_rk4_h); None: as split says (_forced_rk4_h)
        self.const: tuple[bool, bool] | None = const
        self.const_F: np.ndarray | None = None   # a constant force sum (the index's own array) and its a_w
        self.a_w: np.ndarray | None = None
        self.zeros: np.ndarray | None = None
        self.a_buf: np.ndarray | None = None

    def accel(self, K, F, into=None):
        """a_w = F/m (linear_acceleration), struct-of-arrays; once per plan when F is the index's constant sum, else
        into `into` when given (the v rows of the right-hand side's output: the kernel's ``x_dot[7:10] = a_w`` is
        then an assignment of an array to itself, which NumPy skips, instead of a copy), else into the group's
        buffer (rewritten at every call)."""
        if F is self.const_F:
            return self.a_w
        if self.index.uniform is not None and F is self.index.base[0][1]:
            self.const_F, self.a_w = F, K.linear_acceleration(self.m, F, out=(_soa(np.empty_like(F)),))
            return self.a_w
        if into is None:
            if self.a_buf is None or self.a_buf.shape != F.shape:
                self.a_buf = _soa(np.empty_like(F))
            into = self.a_buf
        return K.linear_acceleration(self.m, F, out=(into,))

    def rhs(self, K, x, v, buf, out):
        F, tau = self.index.sums(x, v, buf)
        dest = None if out is None else (out,)
        into = None if out is None else out[:, V]     # a_w written where the kernel puts it (accel)
        if self.cls == RHS_FORCE:
            return K.rigid_body_rhs_force_c(x, self.c, self.accel(K, F, into), out=dest)
        if self.cls == RHS_FULL:
            return K.rigid_body_rhs_c(x, self.m, self.c, F, tau, out=dest)
        if self.cls == RHS_BODY_F:
            a = self.accel(K, F, into)
        else:
            if self.zeros is None:
                self.zeros = _soa(np.zeros((self.m.shape[0], 3)))
            a = self.zeros
        return K.rigid_body_rhs_body_c(x, self.c, a, tau, out=dest)

    def scales(self, K, sdt: float) -> np.ndarray:
        """The bodies' constants S of the scaled increments (rigid_body_increment_scale: sdt = s dt folded into the
        Euler coefficients, 1/I, q's rate scale and 1/m), struct-of-arrays, kept for the last sdt."""
        key = getattr(self, "_sdt", None)
        if key != sdt:
            self._sdt, self._S = sdt, _soa(K.rigid_body_increment_scale(self.c, self.m, sdt))
        return self._S

    def flow(self, K, dt: float) -> np.ndarray:
        """The bodies' translation_flow constants T (translation_flow_scale of their affine forces' sums, _EffectIndex
        .affine), struct-of-arrays, kept for the last dt."""
        if getattr(self, "_fdt", None) != dt:
            F0, k = self.index.affine(K)
            self._fdt, self._TF = dt, _soa(K.translation_flow_scale(k, F0, self.m, dt))
        return self._TF

    def inc(self, K, x, buf, S, out):
        """The scaled increments H = s dt d/dt x of the group's bodies x (n, 13) into out: the effects' sums as rhs
        takes them, then the class's printed increments kernel (effect_fuse.RHS_OF_KIND's inc, csrc/step.c plain_inc;
        a force is not divided: H_v = h_m F; RHS_BODY's kernel has no force: H_v = -0)."""
        q, w, v = x[:, Q], x[:, W], x[:, V]
        F, tau = self.index.sums(x, v, buf)
        if self.cls == RHS_FORCE:
            return K.rigid_body_increments_force_c(q, w, v, S, F, out=(out,))
        if self.cls == RHS_FULL:
            return K.rigid_body_increments_c(q, w, v, S, F, tau, out=(out,))
        if self.cls == RHS_BODY_F:
            return K.rigid_body_increments_body_c(q, w, v, S, F, tau, out=(out,))
        return K.rigid_body_increments_torque_b_c(q, w, v, S, tau, out=(out,))


def _forced_groups(plan) -> list[_ForcedGroup]:
    """The plan's plain bodies with effects by class; a float32 plan keeps the full kernel for all (its C loop,
    csrc/fixed_loop.h, does too)."""
    from .. import effects as E

    if plan.K is not K:
        return [_ForcedGroup(RHS_FULL, plan.forced, plan.index, plan.m_f, plan.c_f)]
    params, effects, _ = plan.source
    # each row's flags through its code's (one spec look-up per distinct code); a scene-wide row's to every body
    codes, inv = np.unique(effects[:, E.ROW_CODE].astype(np.int64), return_inverse=True)
    specs = [E.spec_for_code(int(c)) for c in codes]
    # a user effect counts as coupling (its affine form is not printed: csrc/step.c effects_decoupled)
    row_flags = np.array([s.rhs_flags | (E.FLAG_COUPLED if s.user_set is not None else 0) for s in specs],
                         np.int64)[inv.reshape(-1)]
    row_user = np.array([s.user_set is not None for s in specs], bool)[inv.reshape(-1)]
    body = effects[:, E.ROW_BODY].astype(np.int64)
    flags = np.full(plan.nb, np.bitwise_or.reduce(row_flags[body < 0]) if (body < 0).any() else 0, np.int64)
    np.bitwise_or.at(flags, body[body >= 0], row_flags[body >= 0])
    user = np.full(plan.nb, bool(row_user[body < 0].any()))
    np.logical_or.at(user, body[body >= 0], row_user[body >= 0])
    fl = flags[plan.forced]
    cls = E.rhs_classes(fl)
    # decoupled (csrc/step.c rhs_kind: its class + LV_RHS_SPLIT): a kind that allows it, effects not all constant, none
    # coupling; the group steps its rotation alone and its translation by the printed flow
    split = np.array([E.RHS_SPLIT[int(c)] for c in cls], np.int64) * (
        (fl & E.FLAG_USES_STATE != 0) & (fl & E.FLAG_COUPLED == 0))
    # effects reading no state (csrc/step.c rhs_kind + LV_RHS_CONSTANT): (q, omega_b) staged alone (_const_rk4_h)
    const = [E.constant_kind(int(f), bool(u)) for f, u in zip(fl, user[plan.forced])]
    ckey = np.array([0 if k is None else 1 + 2 * k[0] + k[1] for k in const], np.int64)
    out = []
    for c, sp, ck in sorted(set(zip(cls.tolist(), split.tolist(), ckey.tolist()))):
        sel = np.flatnonzero((cls == c) & (split == sp) & (ckey == ck))
        idx = plan.forced[sel]
        index = plan.index if c == RHS_FULL and sel.size == plan.forced.size else _EffectIndex(
            effects, idx, plan.m, plan.I, None, body_frame=c in (RHS_BODY, RHS_BODY_F))
        out.append(_ForcedGroup(int(c), idx, index, plan.m_f[sel], _soa(plan.c_f[sel]), int(sp), const[sel[0]]))
    return out


def _kernels_f32():
    """The float32 printing of the kernels (generated/kernels_numpy_f32.py), imported on first use."""
    from ..generated import kernels_numpy_f32

    return kernels_numpy_f32


def _normalize(x: np.ndarray, kmod=K) -> None:
    x[:, Q] = kmod.quat_normalize(x[:, Q])


def _kick(plan, x, h):
    """Kick of the splitting for time h (q, p fixed; splitting_kick): exact for position-only loads;
    an explicit midpoint step for bodies with linear or angular damping."""
    F, tb = plan.loads(x)
    if plan.damped_f.any():
        xm = x.copy()
        xm[:, V], xm[:, W] = K.splitting_kick(plan.m, plan.I, x[:, V], x[:, W], F, tb, T.SPLIT_MIDPOINT * h)
        F2, tb2 = plan.loads(xm)
        d = np.zeros(x.shape[0], bool)
        d[plan.forced[plan.damped_f]] = True
        F, tb = np.where(d[:, None], F2, F), np.where(d[:, None], tb2, tb)
    x[:, V], x[:, W] = K.splitting_kick(plan.m, plan.I, x[:, V], x[:, W], F, tb, h)


_SYMTOP_FLOWS = (K.symtop_axis_flow_x, K.symtop_axis_flow_y, K.symtop_axis_flow_z)


def symtop_axes(I):
    """symtop4's split of each body (rows of I, principal moments): (a, b, I_r, c_a, c_b) — the reference
    axis r with the smallest symtop_score (the first on ties: the intermediate principal axis), the A axis a
    (of the other two, the larger leftover |c| from symtop_leftover, the first on ties), the B axis b, the
    reference moment I_r and the coefficients c_a, c_b (1/(kg·m²)). As the C backend's symtop_axes."""
    rows = np.arange(I.shape[0])
    r = np.argmin(K.symtop_score(I), axis=1)
    I_r = I[rows, r]
    c = K.symtop_leftover(I, I_r)
    j, k = (r + 1) % 3, (r + 2) % 3
    swap = np.abs(c[rows, k]) > np.abs(c[rows, j])
    a, b = np.where(swap, k, j), np.where(swap, j, k)
    return a, b, I_r, c[rows, a], c[rows, b]


class _FlowRows(NamedTuple):
    """Rows that take a program's rotation flows alike: their index (a slice for all), inertia, and for the
    symmetric-top flows the axes a, b (one each for the group), I_r, c_a, c_b and whether c_b = 0."""
    rows: Any
    I: np.ndarray
    a: int = 0
    b: int = 0
    I_r: Any = None
    c_a: Any = None
    c_b: Any = None
    top: bool = False


# The flows of derive/tableaux.py FLOWS (kick aside: it needs every body's loads, _kick) for time tau on a group g's
# rows s = [p, v, q, ω, L_b], in place; as the C engine's composition_step.
def _drift(s, tau, g):
    s[0] = K.translation_drift(s[0], s[1], tau)


def _momentum(s, tau, g):
    s[4] = K.body_momentum(g.I, s[3])


def _rate(s, tau, g):
    s[3] = K.body_rate(g.I, s[4])


def _strang(s, tau, g):
    s[2], s[3] = K.splitting_rotation(g.I, s[2], s[3], tau)


def _axis(flow):
    def run(s, tau, g):
        s[2], s[4] = flow(g.I, s[2], s[4], tau)
    return run


def _top_a(s, tau, g):
    s[2], s[4] = _SYMTOP_FLOWS[g.a](s[2], s[4], g.c_a, tau)


def _top_b(s, tau, g):
    s[2], s[4] = _SYMTOP_FLOWS[g.b](s[2], s[4], g.c_b, tau)


def _top_b_nz(s, tau, g):
    if not g.top:   # c_b = 0: a turn by 0, skipped
        _top_b(s, tau, g)


def _sphere(s, tau, g):
    s[2] = K.sphere_flow(s[2], s[4], g.I_r, tau)


_ROW_FLOWS = {"drift": _drift, "momentum": _momentum, "rate": _rate, "strang": _strang,
              "axis_x": _axis(K.axis_flow_x), "axis_y": _axis(K.axis_flow_y), "axis_z": _axis(K.axis_flow_z),
              "top_a": _top_a, "top_b": _top_b, "top_b_nz": _top_b_nz, "sphere": _sphere}
_TOP_FLOWS = {"top_a", "top_b", "top_b_nz", "sphere"}


def _segments(program):
    """A printed program ((flow, fraction), ...) as ("kick", fraction) and runs of row flows ((flow fn, fraction), ...)."""
    out: list = []
    for flow, frac in program:
        if flow == "kick":
            out.append(("kick", frac))
        elif out and out[-1][0] == "rows":
            out[-1][1].append((_ROW_FLOWS[flow], frac))
        else:
            out.append(("rows", [(_ROW_FLOWS[flow], frac)]))
    return tuple((kind, tuple(body) if kind == "rows" else body) for kind, body in out)


def _program(gammas, kicked, free):
    """A composition (γ, kicked program, free program) as the engine walks it: γ, the two programs as _segments,
    whether its rows need the symmetric-top split and whether c_b = 0 splits the groups (top_b_nz)."""
    flows = {f for f, _ in kicked + free}
    return gammas, _segments(kicked), _segments(free), bool(flows & _TOP_FLOWS), "top_b_nz" in flows


_PROGRAMS = {name: _program(*c) for name, c in T.COMPOSITIONS.items()}   # generated/tableaux.py COMPOSITIONS


def _groups(I, tops: bool, nz: bool, rows=slice(None)) -> list[_FlowRows]:
    """The bodies rows (inertia I) as groups for the flows: one without symmetric-top flows; else one per (a, b)
    (and c_b = 0 with top_b_nz), since a group's axis flows are one printed kernel."""
    if not tops:
        return [_FlowRows(rows, I)]
    a, b, I_r, c_a, c_b = symtop_axes(I)
    top = (c_b == 0.0) if nz else np.zeros(a.shape, bool)
    keys = sorted(set(zip(a.tolist(), b.tolist(), top.tolist())))
    if len(keys) == 1:
        return [_FlowRows(rows, I, *keys[0][:2], I_r, c_a, c_b, keys[0][2])]
    out = []
    for pa, pb, pt in keys:
        m = np.flatnonzero((a == pa) & (b == pb) & (top == pt))
        out.append(_FlowRows(m if isinstance(rows, slice) else rows[m], I[m], pa, pb, I_r[m], c_a[m], c_b[m], pt))
    return out


def _walk(plan, x, segments, g, groups, src=None) -> None:
    """Program segments over time g on x (in place): a kick for frac g (_kick, every body), each run of row flows
    for frac g on every group's rows in turn, the first run reading src's rows (default x)."""
    src = x if src is None else src
    for kind, body in segments:
        if kind == "kick":
            _kick(plan, x, body * g)
            continue
        for grp in groups:
            r = grp.rows
            s = [src[r, P], src[r, V], src[r, Q], src[r, W], None]
            for fn, frac in body:
                fn(s, frac * g, grp)
            x[r, P], x[r, Q], x[r, W] = s[0], s[2], s[3]
        src = x


def _composition(plan, x, h, name):
    """One step of the composition name (generated/tableaux.py COMPOSITIONS, derive/tableaux.py compositions()):
    bodies with effects take the stages γ_i in turn, each the kicked program over γ_i h; bodies without it the
    free program once over h. The C backend's composition_step, operation for operation."""
    gammas, kicked, free_prog, tops, nz = _PROGRAMS[name]
    xn = x.copy()
    if plan.forced.size:
        xf = x.copy()
        groups = _groups(plan.I, tops, nz)
        for gamma in gammas:
            _walk(plan, xf, kicked, gamma * h, groups)
        xn[plan.forced] = xf[plan.forced]
    free = slice(None) if not plan.forced.size else plan.free
    I = plan.I[free]
    if I.shape[0]:
        _walk(plan, xn, free_prog, h, _groups(I, tops, nz, free), src=x)
    return xn


def gyro_newton(I, w, tau_b, h, iterations: int = T.GYRO_MAX_ITER):
    """Solve I(w1 − w) + h w1 × (I w1) = h tau_b for w1 (rows of bodies) by Newton's method from w1 = w,
    to rounding (implicit_gyro_newton: the derived residual, its SymPy Jacobian, the adjugate solve).
    Solved exactly the torque-free step never gains energy: E − E1 = ½(w − w1)ᵀI(w − w1).

    Returns (w1, converged): converged (rows) is False where the last update is above
    sqrt(GYRO_ACCEPT_SQ) |w1| after the iterations (no root near w: the caller reports a divergence)."""
    w1 = w.copy()
    done = np.zeros(w.shape[0], bool)
    for _ in range(iterations):
        w1n, d = K.implicit_gyro_newton(I, w, tau_b, h, w1)
        w1 = np.where(done[:, None], w1, w1n)  # a body that met the rule keeps its iterate (as C stops per body)
        dd, ww = np.sum(d * d, axis=1), np.sum(w1 * w1, axis=1)
        done |= ~(dd > T.GYRO_TOL_SQ * ww)
        if done.all():
            return w1, done
    return w1, done | ~(dd > T.GYRO_ACCEPT_SQ * ww)


def _implicit_gyro(plan, x, h):
    """Loads at the start; w1 by gyro_newton; q ← q ⊗ exp(h w1/2) (quat_exp_step); v += h F/m; p += h v."""
    F, tb = plan.loads(x)
    w1, ok = gyro_newton(plan.I, x[:, W], tb, h)
    plan.no_root = None if ok.all() else ~ok
    xn = x.copy()
    xn[:, Q] = K.quat_exp_step(x[:, Q], w1, h)
    xn[:, W] = w1
    xn[:, P], xn[:, V] = K.semi_implicit_translation(plan.m, x[:, P], x[:, V], F, h)
    return xn


class _ExplicitRK:
    """An explicit Runge–Kutta tableau as the generic stepper reads it: for each stage the nonzero (j, a_ij) in
    increasing j, the nonzero (i, b_i) in increasing i, and a divisor of the weights (b_i = weights / den; a
    user's Tableau has den = 1). Stage i is evaluated at x + h (a_ij0 k_j0 + a_ij1 k_j1 + ...), summed left to
    right; the step ends at x + (h / den) (b_i0 k_i0 + b_i1 k_i1 + ...): the C backend's generic stepper, in
    its order (requests.md, session 14)."""

    __slots__ = ("rows", "weights", "den")

    def __init__(self, A, b, den=1.0):
        s = len(b)
        self.rows = tuple(tuple((j, float(A[i][j])) for j in range(i) if A[i][j] != 0.0) for i in range(s))
        self.weights = tuple((i, float(w)) for i, w in enumerate(b) if w != 0.0)
        self.den = float(den)

    @staticmethod
    def axpy(x, h, terms, ks, out=None, tmp=None):
        """x + h (a_0 k_j0 + a_1 k_j1 + ...), the sum left to right (a coefficient of 1 multiplies exactly: skipped),
        written into out (None: a new array); tmp: scratch of out's shape. x may be out, a k_j may not."""
        if len(terms) == 1 and math.frexp(terms[0][1])[0] == 0.5:   # one term, a = ±2^e: h (a k) = (a h) k exactly
            (j, a), = terms
            return np.add(x, np.multiply(ks[j], a * h, out=out), out=out)
        acc = None
        for j, a in terms:
            t = ks[j] if a == 1.0 else np.multiply(ks[j], a, out=out if acc is None else tmp)
            acc = t if acc is None else np.add(acc, t, out=out)
        return np.add(x, np.multiply(acc, h, out=out), out=out)

    def step(self, f, x, h, work=None, rows=None):
        """One step of x' = f(x) of length h; f(y, out) returns f(y), in out if it can (out None: a new array).
        work: a _Work of x's shape (its buffers are written; the result is its xn), or None to allocate.
        rows: a _StateRows (with work) to form only the rows it names, else every row."""
        if rows is not None and work is not None:
            return self._step_rows(f, x, h, work, rows)
        ks = [None] * len(self.rows)
        for i, terms in enumerate(self.rows):
            y = x if not terms else self.axpy(x, h, terms, ks, work and work.y, work and work.t)
            ks[i] = f(y, work and work.ks[i])
        return self.axpy(x, h / self.den, self.weights, ks, work and work.xn, work and work.t)

    def _step_rows(self, f, x, h, work, rows):
        """step on the rows of rows: each sum over the views bound for (x, work's buffers) (_Work.bound_to), which
        read stage j's rates from work.ks[j] (a rate that f could not write there is copied in: the same numbers)."""
        bound = work.bound_to(self, x, h, rows.at(x.shape[0]))
        for i, terms in enumerate(self.rows):
            k = f(self._run(bound[i], h, terms, work.y) if terms else x, work.ks[i])
            if k is not work.ks[i]:
                np.copyto(work.ks[i], k)
        return self._run(bound[-1], h / self.den, self.weights, work.xn)

    def _run(self, sums, h, terms, out):
        """axpy over the rows of each run, and x + z on the zero-rate rows (z: the sum over zero rates, computed as
        axpy computes it, from -0.0 so that x + z is that sum's result), on views bound once (bind): (x, k_j, out,
        tmp) per run, (x, out, z) per zero-rate run."""
        runs, zero = sums
        for X, ks, O, T in runs:
            self.axpy(X, h, terms, ks, O, T)
        for X, O, z in zero:
            np.add(X, z, out=O)
        return out

    def bind(self, x, h, work, rows) -> tuple:
        """The views _step_rows' sums read and write, per stage and for the end (_run's arguments), on x and the
        buffers of work (its ks[j] being stage j's rates)."""
        X, Y, Xn, T = x.T, work.y.T, work.xn.T, work.t.T
        K = [k.T for k in work.ks]

        def sums(out, terms, hh, runs, zero):
            z = None
            if zero:
                z = _ZERO_SUMS.get((self, terms, hh))
                if z is None:
                    z = _ZERO_SUMS[self, terms, hh] = float(self.axpy(np.full(1, -0.0), hh, terms,
                                                                      [np.zeros(1)] * len(K))[0])
            return (tuple((X[a:b], [k[a:b] for k in K], out[a:b], T[a:b]) for a, b in runs),
                    tuple((X[a:b], out[a:b], z) for a, b in zero))
        return (tuple(sums(Y, terms, h, rows.stage, rows.zero) if terms else None for terms in self.rows)
                + (sums(Xn, self.weights, h / self.den, rows.end, rows.zero),))


_ZERO_SUMS: dict = {}   # (tableau, terms, h) -> the sum over zero rates (±0.0)


class _Work:
    """Work buffers of one state shape (n, k) for the explicit Runge–Kutta stepper, struct-of-arrays: each is the
    (n, k) transpose of a C-contiguous (k, n) array, so every state number of all bodies is one contiguous row."""

    def __init__(self, shape, dtype, stages):
        def new():
            return np.empty(shape[::-1], dtype).T
        self.ks = [new() for _ in range(stages)]
        self.y, self.t, self.xn = new(), new(), new()
        # the stepper's views on these buffers for the last two (x, xn) pairs (a step's x and xn trade places: adopt)
        self.bound: list[tuple] = []

    def bound_to(self, rk, x, h, rows) -> tuple:
        """rk.bind's views for a step from x (kept for the pair (x, xn) and the same tableau, h and rows)."""
        for b in self.bound:
            if b[0] is x and b[1] is self.xn and b[2] is rk and b[3] == h and b[4] is rows:
                return b[5]
        b = (x, self.xn, rk, h, rows, rk.bind(x, h, self, rows))
        self.bound = [b] + self.bound[:1]
        return b[5]


def _total(x: np.ndarray) -> float:
    """The sum of every number of x (finite iff each is, barring overflow), read in memory order: a struct-of-arrays
    x (the transpose of a C-contiguous array) as one contiguous run (np.sum(x) walks it across rows: 1.9x the time
    at 1e3 bodies)."""
    t = x.T
    return np.add.reduce(t.reshape(-1) if t.flags.c_contiguous else x, axis=None)


def _soa(a: np.ndarray) -> np.ndarray:
    """A struct-of-arrays copy of rows a (n, k): the transpose of a C-contiguous (k, n) array."""
    return np.array(a.T, order="C").T


_USER_RK: dict = {}   # user Tableau (by identity) -> its _ExplicitRK


def _user_rk(name: str):
    """The generic stepper's form of the user-declared tableau ``name`` (backends.tableau_of), or None."""
    tab = tableau_of(name)
    if tab is None:
        return None
    rk = _USER_RK.get(name)
    if rk is None or rk[0] is not tab:
        rk = _USER_RK[name] = (tab, _ExplicitRK(tab.A, *rk_weights(tab)))
    return rk[1]


def _explicit_rk(c, b_num, b_den) -> _ExplicitRK:
    """A built-in explicit RK as generated/tableaux.py EXPLICIT_RK prints it: stage s at x + c_s h k_{s-1} (a
    subdiagonal A, a_{s,s-1} = c_s), weights b_num / b_den."""
    n = len(c)
    return _ExplicitRK([[c[i] if j == i - 1 else 0.0 for j in range(n)] for i in range(n)], b_num, b_den)


_BUILTIN_RK = {name: _explicit_rk(*tab) for name, tab in T.EXPLICIT_RK.items()}
_RK4 = _BUILTIN_RK["rk4"]     # also rk4_expmap's tableau


def _step_rk4_expmap(plan, f, x, h):
    """rk4_expmap (RKMK4): the RK4 tableau (_RK4) on y = (p, v, u, ω) with the attitude q = q₀ ⊗ exp(u/2), u the
    body rotation vector since the step's start (u₀ = 0, in q's first three slots, the fourth held at 0). Each
    stage evaluates the right-hand side at its attitude (quat_exp_step(q₀, u, 1); the first at x itself) and
    u̇ = rkmk_dexpinv(u, ω); the end attitude is q₀ ⊗ exp(u₁/2), unit to rounding. The same operations in the
    same order as the C backend's rk4_expmap_step."""
    q0 = x[:, Q]
    y0 = x.copy()
    y0[:, Q] = 0.0

    def f_lie(y, out=None):
        xs = x
        if y is not y0:
            xs = y.copy()
            xs[:, Q] = K.quat_exp_step(q0, y[:, U], 1.0)
        k = plan.rhs(xs)
        k[:, U] = K.rkmk_dexpinv(y[:, U], y[:, W])
        k[:, U0] = 0.0
        return k

    yn = _RK4.step(f_lie, y0, h)
    yn[:, Q] = K.quat_exp_step(q0, yn[:, U], 1.0)
    return yn


def _step_semi_implicit_euler(plan, f, x, h):
    """Symplectic Euler: v, ω (and the wheel rates) first from k = f(x), then p and q with the new rates."""
    k = f(x)
    xn = x.copy()
    for part in (V, W) + ((OM,) if x.shape[1] > LY.STATE_SIZE else ()):
        xn[:, part] += h * k[:, part]
    xn[:, P] = plan.K.translation_drift(x[:, P], xn[:, V], h)
    xn[:, Q] += h * plan.K.quat_derivative_body(x[:, Q], xn[:, W])
    return xn


def _step_implicit_gyro(plan, f, x, h):
    return _implicit_gyro(plan, x, h)


def _stepper_of(name: str):
    """The stepper of a registered integrator: an explicit RK through the tableau stepper (generated/tableaux.py
    EXPLICIT_RK), else its family's member _step_<name> (semi_implicit_euler, partitioned; rk4_expmap, the RK4
    tableau in exponential coordinates; implicit_gyro; the compositions); dopri5 is advance's _dopri5 loop (None)."""
    if name in T.EXPLICIT_RK:
        rk = _BUILTIN_RK[name]
        return lambda plan, f, x, h: rk.step(f, x, h, plan.work(x, len(rk.rows)), plan.rows)  # noqa: E731
    if name in _PROGRAMS:
        return lambda plan, f, x, h: _composition(plan, x, h, name)  # noqa: E731
    return globals().get(f"_step_{name}")


_STEPPERS = {name: _stepper_of(name) for name in T.INTEGRATOR_CODES}


def _h_term(k: float, H, out):
    """k H as tableaux.h's LV_<NAME>_SCALED_UPDATE forms it (1 multiplies by nothing, 2 is H + H), into out unless
    k = 1."""
    return H if k == 1.0 else np.add(H, H, out=out) if k == 2.0 else np.multiply(H, k, out=out)


def _scaled_stages(prog, y, inc, H, A, Y, T1, T2, out):
    """The stages of the scaled-increment form prog (generated/tableaux.py SCALED_RK: (s, stages, end)) from y, as
    tableaux.h's LV_RK4_SCALED_STEP forms them: inc(src) writes the increments H_i = s dt k_i at the stage input src
    into H; each stage's input y + m H (into Y) and the running sum of w H (into A; a shared multiple formed once);
    the step's end y + (acc + w H) end into out (which may be A). T1, T2: scratch for the multiples. Returns out."""
    _, stages, end = prog
    src = y
    for i, (w, m, shared) in enumerate(stages):
        inc(src)
        t = _h_term(w, H, T1)
        if i == 0:
            np.copyto(A, t)
        else:
            np.add(A, t, out=A)
        if m is None:
            if end != 1.0:
                np.multiply(A, end, out=A)
            np.add(y, A, out=out)
        else:
            np.add(y, t if shared else _h_term(m, H, T2), out=Y)
            src = Y
    return out


def _h_rows(plan, prog, x: np.ndarray, inc, key) -> np.ndarray:
    """(q, omega_b) of bodies x (n, 13) after one step of the scaled-increment stages prog (generated/tableaux.py
    SCALED_RK: (s, stages, end)), q not normalized, as (7, n) rows: the C backend's LV_H_STAGES (csrc/step.c
    lv_rot_free_h, lv_rot_torque_h) operation for operation: inc(q, omega_b, out) writes a stage's increments
    H_i = s dt k_i (a printed increments kernel), each stage's input y + m H and the running sum of w H (a shared
    multiple formed once), the end y + (acc + w H) end. Buffers kept by the plan under key."""
    n = x.shape[0]
    buf = plan.works.get(key)
    if buf is None:
        buf = plan.works[key] = np.empty((6, LY.STATE_Q_LEN + LY.STATE_OMEGA_B_LEN, n), x.dtype)
    y, Y, H, A, T1, T2 = buf
    nq = LY.STATE_Q_LEN
    y[:nq], y[nq:] = x[:, Q].T, x[:, W].T
    Hout = (H[:nq].T, H[nq:].T)
    return _scaled_stages(prog, y, lambda src: inc(src[:nq].T, src[nq:].T, Hout), H, A, Y, T1, T2, A)


def _h_store(A: np.ndarray, xn: np.ndarray | None, x: np.ndarray) -> np.ndarray:
    """xn's q and omega_b from _h_rows' A (a new struct-of-arrays state when xn is None)."""
    if xn is None:
        xn = np.empty(x.shape[::-1], x.dtype).T
    nq = LY.STATE_Q_LEN
    xn[:, Q], xn[:, W] = A[:nq].T, A[nq:].T
    return xn


def _free_scale(plan, c: np.ndarray, sdt: float) -> tuple:
    """The torque-free constants (C, h_q) of the Euler coefficients c (the printed rigid_body_increment_scale_free),
    kept by the plan for the last sdt; h_q (sdt QUAT_RATE_SCALE, the same for every body) as one number, so the
    increments multiply by a scalar, not a row (~8 % of a step at N = 1e3)."""
    key = ("free_scale", id(c))
    got = plan.works.get(key)
    if got is None or got[0] != sdt or got[1] is not c:
        C, hq = plan.K.rigid_body_increment_scale_free(c, sdt)
        got = plan.works[key] = (sdt, c, C, hq.reshape(-1)[0] if hq.size else hq)
    return got[2], got[3]


def _free_rk4_h(plan, prog, x: np.ndarray, c: np.ndarray, dt: float, xn: np.ndarray | None = None) -> np.ndarray:
    """One torque-free step of bodies x (n, 13) in the scaled-increment form prog (generated/tableaux.py SCALED_RK:
    (s, stages, end)), q not normalized; c (n, LY.EULER_SIZE) their Euler coefficients. The C backend's
    lv_free_rk4_h (csrc/step.c), operation for operation: q and omega_b by _h_rows on the printed
    rigid_body_increments_free_c (its constants C, h_q from the printed rigid_body_increment_scale_free); p_w by
    the printed translation_drift with v_w, v_w kept. In the plan's precision (plan.K; a float32 plan in float32, as
    step_f32.c's float32 tiles). Returns xn (a new struct-of-arrays state when None)."""
    C, hq = _free_scale(plan, c, prog[0] * dt)
    A = _h_rows(plan, prog, x, lambda q, w, o: plan.K.rigid_body_increments_free_c(q, w, C, hq, out=o),
                ("free_rk4_h", x.shape[0], x.dtype.str))
    xn = _h_store(A, xn, x)
    plan.K.translation_drift(x[:, P], x[:, V], dt, out=(xn[:, P],))
    xn[:, V] = x[:, V]
    return xn


def _const_rk4_h(plan, prog, fg, x: np.ndarray, dt: float, xn: np.ndarray | None = None) -> np.ndarray:
    """One step of the bodies x (n, 13) of forced group fg whose effects all read no state (fg.const = (torque,
    force), effects.constant_kind), q not normalized: the C backend's lv_const_rk4_h (csrc/step.c) operation for
    operation. The effects' sums (F, tau) once; q and omega_b by _h_rows on the printed rigid_body_increments_torque_h
    (the constants S of rigid_body_increment_scale and T = rigid_body_torque_constants(tau)) with a torque, else as a torque-free body (_free_rk4_h's
    increments and constants: the same bits); p_w and v_w by the printed translation_flow_constant on
    constant_acceleration_steps' dv, dp with a force, else translation_drift with v_w kept. Returns xn."""
    torque, force = fg.const
    F, tau = fg.index.sums(x, x[:, V], plan.loads_buffer(x))
    key = ("const_rk4_h", x.shape[0], id(fg))
    if torque:
        S, T = fg.scales(K, prog[0] * dt), K.rigid_body_torque_constants(tau)
        A = _h_rows(plan, prog, x, lambda q, w, o: K.rigid_body_increments_torque_h(q, w, S, T, out=o), key)
    else:
        C, hq = _free_scale(plan, fg.c, prog[0] * dt)
        A = _h_rows(plan, prog, x, lambda q, w, o: K.rigid_body_increments_free_c(q, w, C, hq, out=o), key)
    xn = _h_store(A, xn, x)
    if force:
        dv, dp = K.constant_acceleration_steps(fg.m, F, dt)
        K.translation_flow_constant(x[:, P], x[:, V], dt, dv, dp, out=(xn[:, P], xn[:, V]))
    else:
        K.translation_drift(x[:, P], x[:, V], dt, out=(xn[:, P],))
        xn[:, V] = x[:, V]
    return xn


def _forced_rk4_h(plan, prog, fg, x: np.ndarray, dt: float, xn: np.ndarray | None = None) -> np.ndarray:
    """One step of the bodies x (n, 13) of forced group fg in the scaled-increment form prog (generated/tableaux.py
    SCALED_RK: (s, stages, end)) on all 13 numbers, q not normalized: the C backend's LV_RK4_SCALED_STEP with the
    class's increments (csrc/step.c advance_free_rk4, the effect tiles), operation for operation: each stage's
    increments H_i = s dt k_i (fg.inc), its input x + m H and the running sum of w H (a shared multiple formed once),
    the end x + (acc + w H) end. Buffers kept by the plan. Returns xn (a new struct-of-arrays state when None)."""
    if fg.split:
        return _split_rk4_h(plan, prog, fg, x, dt, xn)
    s = prog[0]
    n = x.shape[0]
    key = ("forced_rk4_h", n, id(fg))
    buf = plan.works.get(key)
    if buf is None:
        buf = plan.works[key] = tuple(np.empty((LY.STATE_SIZE, n)).T for _ in range(5))
    H, A, Y, T1, T2 = buf
    S = fg.scales(K, s * dt)
    loads = plan.loads_buffer(x)
    if xn is None:
        xn = np.empty(x.shape[::-1], x.dtype).T
    return _scaled_stages(prog, x, lambda src: fg.inc(K, src, loads, S, H), H, A, Y, T1, T2, xn)


def _split_rk4_h(plan, prog, fg, x: np.ndarray, dt: float, xn: np.ndarray | None = None) -> np.ndarray:
    """One decoupled step of the bodies x (n, 13) of forced group fg (fg.split: E.RHS_SPLIT), q not normalized: the C
    backend's LV_SPLIT_RK4_H (csrc/step.c; the tiles' LV_TILE_RK4_SPLIT), operation for operation. The rotation (q,
    omega_b) alone through the scaled-increment stages (_scaled_stages, as _free_rk4_h): split 1 the torque-free
    increments on S's C_b and h_q, split 2 the body-frame torque sums at each stage input (the states with q and
    omega_b replaced; the torques read neither p_w nor v_w) and rigid_body_increments_rot_b_c; then p_w, v_w by the
    printed translation_flow on the group's constants (fg.flow). Returns xn (a new struct-of-arrays state when None)."""
    n = x.shape[0]
    key = ("split_rk4_h", n, id(fg))
    buf = plan.works.get(key)
    if buf is None:
        buf = plan.works[key] = (np.empty((6, LY.STATE_Q_LEN + LY.STATE_OMEGA_B_LEN, n)),
                                 np.empty((LY.STATE_SIZE, n)).T)
    (y, Y, H, A, T1, T2), xs = buf
    S, TF = fg.scales(K, prog[0] * dt), fg.flow(K, dt)
    nq = LY.STATE_Q_LEN
    y[:nq], y[nq:] = x[:, Q].T, x[:, W].T
    Hout = (H[:nq].T, H[nq:].T)
    if fg.split == 1:
        C, hq = S[:, INC_SCALE_C], S[:, INC_SCALE_HQ]

        def inc(src):
            return K.rigid_body_increments_free_c(src[:nq].T, src[nq:].T, C, hq, out=Hout)
    else:
        np.copyto(xs, x)
        loads = plan.loads_buffer(x)

        def inc(src):
            xs[:, Q], xs[:, W] = src[:nq].T, src[nq:].T
            tau = fg.index.sums(xs, xs[:, V], loads)[1]
            return K.rigid_body_increments_rot_b_c(src[:nq].T, src[nq:].T, S, tau, out=Hout)
    _scaled_stages(prog, y, inc, H, A, Y, T1, T2, A)
    if xn is None:
        xn = np.empty(x.shape[::-1], x.dtype).T
    xn[:, Q], xn[:, W] = A[:nq].T, A[nq:].T
    K.translation_flow(x[:, P], x[:, V], TF, out=(xn[:, P], xn[:, V]))
    return xn


def _group_rk4_h(plan, prog, fg, x, dt, xn=None) -> np.ndarray:
    """One step of forced group fg's bodies x: _const_rk4_h when their effects all read no state, else
    _forced_rk4_h."""
    return (_const_rk4_h if fg.const is not None else _forced_rk4_h)(plan, prog, fg, x, dt, xn)


def _scaled_step(plan, prog, x, dt, stepper, f) -> np.ndarray:
    """The built-in RK4's step of every body in its scaled-increment form: torque-free bodies by _free_rk4_h, each
    forced group (plain bodies with effects) by _forced_rk4_h; bodies with models (wheels, joints) on the tableau
    stepper (their rows first, the plain rows then written over them)."""
    if plan.forced.size and plan.fgroups is None:
        plan.fgroups = _forced_groups(plan)
        plan.one = plan.fgroups[0] if plan.forced.size == plan.nb and len(plan.fgroups) == 1 else None
    forced = plan.K is K   # (a float32 plan's bodies with effects: the tableau stepper, as fixed_loop.h)
    if plan.one is not None and forced:   # every body plain, one class: no gather, no scatter
        return _group_rk4_h(plan, prog, plan.one, x, dt, plan.work(x, len(prog[1])).xn)
    xn = stepper(plan, f, x, dt) if plan.has_models or not forced else np.empty(x.shape[::-1], x.dtype).T
    if plan.free.size:
        xn[plan.free, X] = _free_rk4_h(plan, prog, _soa(x[plan.free, X]), plan.c_free, dt)
    for fg in plan.fgroups if forced and plan.fgroups else []:
        xn[fg.idx, X] = _group_rk4_h(plan, prog, fg, _soa(x[fg.idx, X]), dt)
    return xn


def step(plan: _Plan, x: np.ndarray, integrator: str, normalize: bool, dt: float, u=None) -> np.ndarray:
    """One step of every body; returns the new state array. x is (nb, 13), or (nb, 16) = [x, Omega]
    with u the wheeled bodies' applied torques when the plan has joints or wheels."""
    def f(y, out=None):
        return plan.rhs(y, u, out)
    stepper = _STEPPERS.get(integrator)
    # torque-free bodies: the scaled-increment form, as C's free paths (a float32 plan in float32, as step_f32.c's);
    # float64 bodies with effects too (a float32 plan's keep the tableau stepper, as fixed_loop.h's)
    prog = T.SCALED_RK.get(integrator) if plan.free.size or (plan.forced.size and plan.K is K) else None
    if prog is not None and plan.all_free:
        xn = _free_rk4_h(plan, prog, x, plan.c_free, dt, plan.work(x, len(prog[1])).xn)
    elif prog is not None and stepper is not None:   # bodies with effects too (models: the tableau stepper)
        xn = _scaled_step(plan, prog, x, dt, stepper, f)
    elif stepper is not None:
        xn = stepper(plan, f, x, dt)
    elif (rk := _user_rk(integrator)) is not None:
        xn = rk.step(f, x, dt, plan.work(x, len(rk.rows)), plan.rows)
    else:  # validated by Sim; kept for direct callers
        raise ValueError(f"integrator: unknown {integrator!r}")
    if normalize:
        # in place: the printed kernel reads q whole (its norm) before one multiply writes q_unit over it elementwise
        q = xn[:, Q]
        plan.K.quat_normalize(q, out=(q,))
    if plan.has_models:
        plan.constrain(xn)
    return xn


class NumpyBackend:
    name = "numpy"

    def __init__(self):
        self._plan_key = None
        self._plan = None

    def plan(self, params: np.ndarray, effects: np.ndarray, rows: np.ndarray | None = None) -> _Plan:
        key = (params.dtype.str, params.tobytes(), effects.tobytes(), None if rows is None else rows.tobytes())
        if key != self._plan_key:
            self._plan, self._plan_key = _Plan(params, effects, rows), key
            self._plan.source = tuple(None if a is None or b is None else np.frombuffer(b, a.dtype).reshape(a.shape)
                                      for a, b in zip((params, effects, rows), key[1:]))
        return self._plan

    def advance(self, state, params, effects, integrator: str, normalize: bool, dt: float | np.floating, n_steps: int,
                models: Models | None = None, adaptive: Adaptive | None = None, *, restore: bool = True) -> None:
        # restore: accepted for the C backend's interface; this backend always restores (it steps a copy)
        if isinstance(state, np.ndarray) and state.dtype == np.float32:   # single precision throughout
            if tableau_of(integrator) is not None:
                raise ValueError(f"integrator: {integrator!r} (a user-declared tableau) steps float64 only")
            if integrator not in FLOAT32_INTEGRATORS:
                raise ValueError(f"integrator: float32 steps {', '.join(FLOAT32_INTEGRATORS)} only, got {integrator!r}")
            if models is not None and np.any(np.asarray(models.rows)[:, LY.MODEL_KIND] != 0):
                raise ValueError("float32 steps plain rigid bodies only (no spherical_joint or reaction_wheels)")
            params, effects, models, dt = (np.asarray(params, np.float32), np.asarray(effects, np.float32), None,
                                           np.float32(dt))
        plan = self.plan(params, effects, None if models is None else models.rows)
        if integrator in PLAIN_ONLY and plan.has_models:
            raise ValueError(f"integrator: {integrator} steps plain rigid bodies only (no spherical_joint or reaction_wheels)")
        if integrator in T.ADAPTIVE and adaptive is None:
            raise ValueError(f"integrator: {integrator} needs adaptive (a lavendersim.backends.Adaptive)")
        if self._scalar(plan, state, integrator, normalize, dt, n_steps):
            return
        loop = self._loop
        if integrator in T.ADAPTIVE:
            assert adaptive is not None   # (checked above)
            h, nfev = adaptive.h.copy(), adaptive.nfev.copy()
            dense = None if adaptive.dense is None else adaptive.dense.copy()

            def loop(plan, x, integrator, normalize, dt, n_steps, command=None, applied=None):  # noqa: E306
                _dopri5(plan, x, integrator, normalize, dt, n_steps, adaptive.rtol, adaptive.atol, h, nfev, command,
                        applied, dense)
        if not plan.has_models:
            x = _soa(state)                  # the working copy, struct-of-arrays (a contiguous row per number)
            with np.errstate(over="ignore", invalid="ignore", divide="ignore"):  # non-finite results are caught below
                loop(plan, x, integrator, normalize, dt, n_steps)
            state[...] = x
        else:
            assert models is not None   # (a plan with models was built from its rows)
            x = _soa(np.concatenate([state, models.Omega], axis=1))
            applied = models.applied.copy()
            with np.errstate(over="ignore", invalid="ignore", divide="ignore"):
                loop(plan, x, integrator, normalize, dt, n_steps, models.command, applied)
            state[...] = x[:, X]
            models.Omega[...] = x[:, OM]
            models.applied[...] = applied
        if integrator in T.ADAPTIVE:
            assert adaptive is not None
            adaptive.h[...], adaptive.nfev[...] = h, nfev
            if dense is not None:
                assert adaptive.dense is not None   # dense was read from it
                adaptive.dense[...] = dense

    @staticmethod
    def _scalar(plan, state, integrator, normalize, dt, n_steps) -> bool:
        """A few plain float64 bodies on an explicit Runge–Kutta tableau: stepped in Python floats (numpy_scalar,
        bitwise the vectorized path) when every effect has a float printing. False: not taken, or handed back."""
        if plan.has_models or plan.nb > SC.SCALAR_MAX_BODIES or plan.K is not K or state.dtype != np.float64:
            return False
        rk = _BUILTIN_RK.get(integrator) or _user_rk(integrator)
        if rk is None:
            return False
        if plan.scalar is None:
            plan.scalar = SC.ScalarBodies(plan.source[0], plan.source[1])
        if not plan.scalar.ok:
            return False
        try:
            SC.advance(plan.scalar, state, rk, normalize, dt, n_steps, T.SCALED_RK.get(integrator))
        except SC.Fallback:
            return False
        return True

    @staticmethod
    def _loop(plan, x, integrator, normalize, dt, n_steps, command=None, applied=None) -> None:
        cur = x
        for i in range(n_steps):
            u = None if command is None else plan.applied(cur, command)
            xn = step(plan, cur, integrator, normalize, dt, u)
            no_root = getattr(plan, "no_root", None)
            if no_root is not None:
                bad = no_root | ~np.isfinite(xn).all(axis=1)
                b = int(np.flatnonzero(bad)[0])
                if no_root[b]:
                    plan.no_root = None
                    raise DivergenceError(i, b, no_root_cause(cur[b, X], plan.I[b], dt))
            if not np.isfinite(_total(xn)) and not np.isfinite(xn).all():   # the sum first: one pass, no array
                b = int(np.flatnonzero(~np.isfinite(xn).all(axis=1))[0])
                raise DivergenceError(i, b, divergence_cause(cur[b, X], dt, integrator, plan.I[b], *plan.wheel_info(cur, b)))
            cur = plan.adopt(xn, cur)
            if u is not None:
                applied[plan.wheeled] = u[plan.wheeled]
        if cur is not x:
            x[...] = cur


# Dormand–Prince 5(4) (Hairer, Nørsett & Wanner, Solving ODEs I, table 5.2): T.DP_A, T.DP_E and the controller
# constants are printed from derive/tableaux.py, the same doubles as the C step loop's. The algorithm is the C
# backend's advance_dopri5 (csrc/step.c), per body: each body has its own step size, substeps, rejections, count
# and failure; the bodies still inside an output interval are stepped together (vectorized over the body axis),
# the others held (a substep of length 0 whose results are not kept). Every operation is C's, in C's order, so a
# body's numbers are C's and do not depend on which other bodies share the scene (bitwise: the controller's factor
# takes no power, _dp_factor; the starting step's power is libm's pow, as C's, through NumPy's power where it is
# libm's, else math.pow: _dp_pow).

_DP_DIVERGED, _DP_TOLERANCE = 1, 2   # a body's failure (0: none)
_DP_SUBPLANS_MAX = 64                 # cached subset plans per plan


def _dp_norm(e, y, yn, rtol, atol, ncols):
    """Per body (row) RMS of e / (atol + rtol max(|y|, |yn|)) over its ncols numbers (C's dp_norm): an exact zero
    counts 0 (even with atol = 0); the squares are summed left to right (cumsum: C's order, not NumPy's pairwise
    sum). The numbers past ncols (a plain body's Omega, a wheeled body's padded slots) are exactly 0."""
    sc = atol + rtol * np.maximum(np.abs(y), np.abs(yn))
    z = np.divide(e, sc, out=np.zeros_like(e), where=e != 0)
    return np.sqrt(np.cumsum(z * z, axis=1)[:, -1] / ncols)


def _dp_factor(e):
    """The controller's factor SAFETY e^(-1/5) per body, as C's dp_factor (derive/tableaux.py DP_ROOT5_*): Newton
    steps on r^-5 = e from a bit-pattern seed within [LO, HI]; FACMAX below (e = 0 included), FACMIN above or NaN."""
    inside = (e >= T.DP_ROOT5_LO) & (e <= T.DP_ROOT5_HI)
    ei = np.where(inside, e, 1.0)
    r = (np.uint64(T.DP_ROOT5_SEED) - ei.view(np.uint64) // np.uint64(T.DP_ROOT5_DIV)).view(np.float64)
    for _ in range(T.DP_ROOT5_NEWTON):
        r2 = r * r
        r = r * (T.DP_ROOT5_A - ei * (r2 * r2 * r)) * T.DP_ROOT5_B
    return np.where(inside, T.DP_SAFETY * r, np.where(e < T.DP_ROOT5_LO, T.DP_FACMAX, T.DP_FACMIN))


def _dp_pow(a, p):
    """a ** p elementwise (a >= 0, NaN or inf; |p| < 1) as C's libm pow: NumPy's power where it gives libm's
    (_numpy_power_is_libm), else math.pow per element (~30 % of the CPU time of 1e3 equal-rate bodies)."""
    if _numpy_power_is_libm(p):
        return a ** p
    return np.fromiter(map(math.pow, a.ravel().tolist(), itertools.repeat(p)), float, a.size).reshape(a.shape)


@functools.lru_cache(maxsize=None)
def _numpy_power_is_libm(p: float) -> bool:
    """NumPy's float64 power to the exponent p equals math.pow (libm's pow) on 4001 bases over 1e-16..1e8 (not
    so where NumPy's power is a vector library's, e.g. SVML on AVX-512 builds, within an ulp or so of libm)."""
    a = np.geomspace(1e-16, 1e8, 4001)
    return bool(np.array_equal(a ** p, np.fromiter(map(math.pow, a.tolist(), itertools.repeat(p)), float, a.size)))


def _subplan(plan, idx):
    """The plan of bodies idx (sorted indices into plan's) alone, cached on plan. A body's right-hand side reads
    its own row only, so each body of the subset gets the numbers it gets in the whole scene."""
    if idx.size == plan.nb:
        return plan
    key = idx.tobytes()
    sub = plan.subplans.get(key)
    if sub is None:
        params, effects, rows = plan.source
        body = effects[:, ROW_BODY].astype(np.int64)
        pos = np.full(plan.nb, -1, np.int64)
        pos[idx] = np.arange(idx.size)
        keep = body < 0                                  # every-body effects, and the subset's own
        keep[~keep] = pos[body[~keep]] >= 0
        eff = effects[keep].copy()
        own = body[keep] >= 0
        eff[own, ROW_BODY] = pos[body[keep][own]]
        if len(plan.subplans) >= _DP_SUBPLANS_MAX:
            plan.subplans.clear()
        sub = plan.subplans[key] = _Plan(params[idx], eff, None if rows is None else rows[idx])
    return sub


def _dp_rhs(plan, y, u):
    """d/dt of y, rows of plan's bodies: (n, 13), or [x, Omega] (n, XS_SIZE) with u their applied wheel torques."""
    if plan.has_models:
        return plan.rhs(y, u)
    if plan.all_free and y.shape[1] > LY.STATE_SIZE:  # plain, effect-free bodies of a scene with models
        out = np.zeros_like(y)
        out[:, X] = plan.K.rigid_body_rhs_free(y[:, X], plan.I)
        return out
    return plan.rhs(y)


def _dp_initial_h(plan, y, f0, u, rtol, atol, dt, ncols):
    """Hairer's starting step (Solving ODEs I, II.4) per body (C's dp_initial_h), from f0 = f(y) and one more
    evaluation; dt where it is not a positive finite number."""
    d0 = _dp_norm(y, y, y, rtol, atol, ncols)
    d1 = _dp_norm(f0, y, y, rtol, atol, ncols)
    h0 = np.where((d0 < T.DP_INIT_SMALL) | (d1 < T.DP_INIT_SMALL), T.DP_INIT_TINY_H, T.DP_INIT_FRAC * d0 / d1)
    h0 = np.where(h0 > dt, dt, h0)
    f1 = _dp_rhs(plan, y + h0[:, None] * f0, u)
    d2 = _dp_norm((f1 - f0) / h0[:, None], y, y, rtol, atol, ncols)
    mx = np.where(d1 > d2, d1, d2)
    shrink = h0 * T.DP_INIT_SHRINK
    h1 = np.where(mx <= T.DP_INIT_FLAT, np.where(shrink > T.DP_INIT_TINY_H, shrink, T.DP_INIT_TINY_H),
                  _dp_pow(T.DP_INIT_FRAC / mx, T.DP_INIT_EXPONENT))
    grow = T.DP_INIT_GROW * h0
    h = np.where(grow < h1, grow, h1)
    return np.where(np.isfinite(h) & (h > 0.0), h, dt)


def _dp_sum(w, k):
    """sum_j w[j] k[j] over the nonzero w[j], left to right (C's dp_combine)."""
    acc = None
    for wj, kj in zip(w, k):
        if wj != 0.0:
            acc = wj * kj if acc is None else acc + wj * kj
    return acc


def _dp_stages(plan, y, k0, hs, u):
    """The six new stages of substeps of lengths hs ((n, 1)) from k0 = f(y): returns (the 5th-order solution,
    i.e. stage 7's point; f there; hs times the error estimate). Sums as C's (_dp_sum). A plain body without
    effects (plan.free) moves p by hs v, with zero p and v errors (C's DP_FREE: only q and omega_b are staged)."""
    k = [k0]
    for s in range(1, 7):
        yn = y + hs * _dp_sum(T.DP_A[s][:s], k)
        k.append(_dp_rhs(plan, yn, u))
    err = hs * _dp_sum(T.DP_E, k)
    f = plan.free
    if f.size:
        yn[f, P] = y[f, P] + hs[f] * y[f, V]
        err[f, P] = 0.0
        err[f, V] = 0.0
    return yn, k[6], err, k


def _dp_coeffs(plan, y0, y1, hs, k):
    """The dense-output coefficients (n, 5, cols) of substeps y0 -> y1 (raw) of lengths hs ((n, 1)), as C's
    dp_dense_coeffs: Y0 = y0, Y1 = y1 - y0, Y2 = hs k1 - Y1, Y3 = Y1 - hs k7 - Y2, Y4 = hs sum_i DP_DENSE[i] k_i;
    a free body's p is linear (Y2..Y4 = 0)."""
    d1 = y1 - y0
    d2 = hs * k[0] - d1
    Y = np.stack([y0, d1, d2, d1 - hs * k[6] - d2, hs * _dp_sum(T.DP_DENSE, k)], axis=1)
    if plan.free.size:
        Y[plan.free, 2:, P] = 0.0
    return Y


def _dp_next_h(rej, h, e, hs, clipped):
    """The controller (C's, per body): the next proposal after an accepted (e <= 1) or rejected substep of hs, with
    h the proposal it was taken from (read for the running bodies only)."""
    p = _dp_factor(e)
    fa = np.where(p > T.DP_FACMAX, T.DP_FACMAX, p)           # accepted
    fa = np.where(fa < T.DP_FACMIN, T.DP_FACMIN, fa)
    fa = np.where(rej & (fa > 1.0), 1.0, fa)                 # no growth right after a rejection
    hf = hs * fa
    # a step shortened to land on the output time does not shrink the proposal
    h_ok = np.where(clipped & (fa >= 1.0) & (h > hf), h, hf)
    fr = np.where(p < T.DP_FACMIN, T.DP_FACMIN, p)           # rejected
    fr = np.where(fr > 1.0, 1.0, fr)
    return np.where(e <= 1.0, h_ok, hs * fr)


def _dp_fail(plan, x, integrator, why, h, i, rtol, atol, dt):
    """DivergenceError of the lowest failing body at output step i (C's choice), with its last output state."""
    b = int(np.flatnonzero(why)[0])
    if why[b] == _DP_TOLERANCE:
        cause = tolerance_cause(Adaptive(rtol, atol, 0), float(h[b]), dt, x[b, X])
    else:
        cause = divergence_cause(x[b, X], dt, integrator, plan.I[b], *plan.wheel_info(x, b))
    return DivergenceError(i, b, cause)


def _dopri5(plan, x, integrator, normalize, dt, n_steps, rtol, atol, hs, nfev, command=None, applied=None, dense=None):
    """Every body by n_steps output steps of dt (C's advance_rk with lv_adaptive, vectorized over bodies): each
    integrates on unclipped (its own state z, `ahead` past the output) and an output is read off its last
    substep's continuous extension; only the call's last output is formed, but a body with wheels lands on every
    output time (its held torque changes there: the substep that would pass it is clipped). The DENSE rows (dense,
    (nb, DENSE_SIZE); None: each call starts afresh) carry z, f(z) and the extension of a body without wheels to the
    next call while its state is the one written (else it starts afresh from it). hs, nfev, dense updated in place;
    the earliest failure (step, then body) raised, as C reports."""
    if n_steps == 0:
        return
    nb, cols = x.shape
    land = plan.wheeled if cols > LY.STATE_SIZE else np.zeros(nb, bool)
    D = np.zeros((nb, LY.DENSE_SIZE)) if dense is None else dense
    same = np.all(np.ascontiguousarray(x[:, X]).view(np.uint64) == D[:, LY.DENSE_X_OUT].view(np.uint64), axis=1)
    valid = (D[:, LY.DENSE_VALID] == 1.0) & same & ~land
    z = np.where(valid[:, None], D[:, LY.DENSE_Z][:, :cols], x)
    k0 = D[:, LY.DENSE_F][:, :cols].copy()
    Y = np.where(valid[:, None, None], D[:, LY.DENSE_COEF].reshape(nb, 5, LY.XS_SIZE)[:, :, :cols], 0.0)
    ahead = np.where(valid, D[:, LY.DENSE_AHEAD], 0.0)
    # the lead after m output steps since a0 is a0 - m dt (one rounding, C's dp_skip); the row's count goes on while
    # it still gives the lead it carries (the same dt)
    a0, m = ahead.copy(), np.zeros(nb)
    go_on = valid & (D[:, LY.DENSE_PASSED] > 0.0) & (D[:, LY.DENSE_LEAD0] - D[:, LY.DENSE_PASSED] * dt == ahead)
    a0[go_on], m[go_on] = D[go_on, LY.DENSE_LEAD0], D[go_on, LY.DENSE_PASSED]
    hl = np.where(valid, D[:, LY.DENSE_H_LAST], 0.0)
    cnt = np.zeros(nb)
    ncols = plan.norm_cols if cols > LY.STATE_SIZE else np.full(nb, float(LY.STATE_SIZE))
    h = hs.copy()
    evaluate, no_clip = np.flatnonzero(~valid), np.zeros(nb, bool)
    for i in range(n_steps):
        u = None if command is None else plan.applied(x, command)
        if evaluate.size:   # f at z (the FSAL stage) under this step's loads: fresh bodies, and landing ones each step
            k0[evaluate] = _dp_rhs(_subplan(plan, evaluate), z[evaluate], None if u is None else u[evaluate])
            cnt[evaluate] += 1
        evaluate = np.flatnonzero(land)
        bad = np.flatnonzero(~(h > 0.0) | ~np.isfinite(h)) if i == 0 else evaluate[:0]
        if bad.size:   # a starting step where there is no proposal
            h[bad] = _dp_initial_h(_subplan(plan, bad), z[bad], k0[bad], None if u is None else u[bad], rtol, atol,
                                   dt, ncols[bad])
            cnt[bad] += 1
        m += 1.0
        ahead = a0 - m * dt
        live = ahead < 0.0
        last = i == n_steps - 1      # no state between is seen: only the call's last is read off (and landings)
        if not last and not live.any():
            continue
        sub, rej, why = np.zeros(nb, np.int64), np.zeros(nb, bool), np.zeros(nb, np.int8)
        while live.any():
            clipped = land & (h >= -ahead)
            step_h = np.where(live, np.where(clipped, -ahead, h), 0.0)
            yn, k7, err, ks = _dp_stages(plan, z, k0, step_h[:, None], u)
            cnt[live] += 6
            e = _dp_norm(err, z, yn, rtol, atol, ncols)
            ok = live & (e <= 1.0)
            h = np.where(live, _dp_next_h(rej, h, e, step_h, clipped if land.any() else no_clip), h)
            Yn = _dp_coeffs(plan, z, yn, step_h[:, None], ks)
            if normalize:
                _normalize(yn)
            if plan.has_models:
                plan.constrain(yn)
            diverged = ok & ~np.isfinite(yn).all(axis=1)
            good = ok & ~diverged
            z[good], k0[good], Y[good] = yn[good], k7[good], Yn[good]   # FSAL: f at the new (un-normalized) point
            ahead = np.where(good, np.where(clipped, 0.0, ahead + step_h), ahead)
            a0, m = np.where(good, ahead, a0), np.where(good, 0.0, m)
            hl = np.where(good, step_h, hl)
            rej = np.where(live, ~ok, rej)
            why[diverged] = _DP_DIVERGED
            live &= ~diverged
            sub[live] += 1
            tol = live & ((h < DOPRI5_HMIN_REL * dt) | (sub > DOPRI5_MAX_SUBSTEPS))
            why[tol] = _DP_TOLERANCE
            live &= ~tol & (ahead < 0.0)
        put = np.ones(nb, bool) if last else land
        if put.any():
            th = ((hl - ahead) / hl)[:, None]
            th1 = 1.0 - th
            out = Y[:, 0] + th * (Y[:, 1] + th1 * (Y[:, 2] + th * (Y[:, 3] + th1 * Y[:, 4])))
            if normalize:
                _normalize(out)
            if plan.has_models:
                plan.constrain(out)
            at = ahead == 0.0            # landed on the output time: z itself (already normalized, on its joint)
            out[at] = z[at]
            why[put & (why == 0) & ~np.isfinite(out).all(axis=1)] = _DP_DIVERGED
        if why.any():
            raise _dp_fail(plan, x, integrator, why, h, i, rtol, atol, dt)
        if put.any():
            x[put] = out[put]
        if u is not None:
            applied[plan.wheeled] = u[plan.wheeled]
    if dense is not None:
        keep = ~land
        D[keep, LY.DENSE_VALID] = 1.0
        D[keep, LY.DENSE_AHEAD], D[keep, LY.DENSE_H_LAST] = ahead[keep], hl[keep]
        D[keep, LY.DENSE_LEAD0], D[keep, LY.DENSE_PASSED] = a0[keep], m[keep]
        D[keep, LY.DENSE_Z.start:LY.DENSE_Z.start + cols] = z[keep]
        D[keep, LY.DENSE_F.start:LY.DENSE_F.start + cols] = k0[keep]
        D[keep, LY.DENSE_X_OUT] = x[keep][:, X]
        coef = np.zeros((nb, 5, LY.XS_SIZE))
        coef[:, :, :cols] = Y
        D[keep, LY.DENSE_COEF] = coef[keep].reshape(-1, 5 * LY.XS_SIZE)
    hs[...] = h
    nfev += cnt
