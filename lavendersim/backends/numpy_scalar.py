"""The NumPy backend's path for a few plain bodies: each body stepped in Python floats.

A NumPy call costs about a microsecond whatever its size, and one vectorized RK4 step makes a few hundred, so for
a handful of bodies a loop over Python floats is faster. This path runs the kernels printed for floats
(generated/kernels_scalar.py: the NumPy printing's expressions, operation for operation) through the explicit
Runge–Kutta stepper's sums in its order (numpy_backend._ExplicitRK.axpy), so a body's numbers are the vectorized
path's bit for bit. It takes plain float64 bodies whose effects all have a float printing (the built-in ones),
stepped by an explicit Runge–Kutta tableau; the caller (NumpyBackend.advance) uses it up to SCALAR_MAX_BODIES.
Anything it cannot finish as the vectorized path would (a non-finite number, a division by zero, a domain error)
raises Fallback before any state is written, and the vectorized path takes the whole call over: it reports the
divergence as always.
"""
from __future__ import annotations

import math

import numpy as np

from ..effects import (FLAG_COUPLED, FLAG_USES_STATE, INC_SCALE_C, INC_SCALE_HQ, RHS_BODY, RHS_BODY_F, RHS_FORCE,
                       RHS_FULL, RHS_SPLIT, ROW_BODY, ROW_CODE, ROW_PARAMS, SUM_START, constant_kind, rhs_classes,
                       spec_for_code)
from ..generated import kernels_scalar as KS
from ..generated import layout as LY

# Largest scene stepped in floats, by measurement (RK4, CPU time, 2 shared cores): the float path costs 6-8 us per
# body-step torque-free and 20-25 us with gravity and damping, flat in N; the vectorized path ~170 us (~840 us) per
# step at N = 1; they cross near N = 30 (float / vectorized at N = 16: 0.58, 0.44; N = 32: 1.09, 0.85)
SCALAR_MAX_BODIES = 24

_P, _Q, _V, _W = LY.STATE_P_W, LY.STATE_Q, LY.STATE_V_W, LY.STATE_OMEGA_B


class Fallback(Exception):
    """The float path stops; the vectorized path takes the call over (nothing was written)."""


class ScalarBodies:
    """Each body's constants as floats: Euler's coefficients, mass, moments and its effects in table order
    [(apply, parameters)] (the every-body ones included), and the (torque, force) of its constant kind when its
    effects all read no state (effects.constant_kind; else None); or None from build() when an effect has no float
    printing."""

    def __init__(self, params, effects):
        self.bodies = []
        body = effects[:, ROW_BODY].astype(int).tolist() if len(effects) else []
        codes = [int(c) for c in effects[:, ROW_CODE]] if len(effects) else []
        applies = [KS.EFFECT_APPLY_BY_CODE.get(c) for c in codes]
        self.ok = all(a is not None for a in applies)
        rows = [tuple(r) for r in effects[:, ROW_PARAMS:].tolist()] if len(effects) else []
        flags = [spec_for_code(c).rhs_flags if a is not None else 0 for c, a in zip(codes, applies)]
        user = [a is not None and spec_for_code(c).user_set is not None for c, a in zip(codes, applies)]
        for b, row in enumerate(params.tolist()):
            m, I = row[LY.PARAM_M], tuple(row[LY.PARAM_I_B])
            mine = [r for r in range(len(body)) if body[r] < 0 or body[r] == b]
            f = 0
            for r in mine:
                f |= flags[r]
            cls = int(rhs_classes(np.array([f]))[0])
            body_form = cls in (RHS_BODY, RHS_BODY_F)
            mine_fx = [(KS.EFFECT_APPLY_B_BY_CODE.get(codes[r], applies[r]) if body_form else applies[r], rows[r])
                       for r in mine]
            # decoupled (numpy_backend._forced_groups' rule): its rotation staged alone, its translation's flow on
            # its affine forces' sums (table order from SUM_START)
            split = RHS_SPLIT[cls] if f & FLAG_USES_STATE and not f & FLAG_COUPLED else 0
            aff = [(KS.EFFECT_AFFINE_BY_CODE[codes[r]], rows[r]) for r in mine if codes[r] in KS.EFFECT_AFFINE_BY_CODE]
            const = constant_kind(f, any(user[r] for r in mine)) if mine else None
            self.bodies.append((KS.euler_coefficients(I), m, I, (cls, mine_fx, split, aff), const))


def _rhs(y, c, m, I, effects):
    """d/dt of one plain body's state y (13 floats) with effects (its class, [(apply, p)]): their sums in table order
    (from SUM_START, as the vectorized sums) and its class's right-hand side (numpy_backend._ForcedGroup.rhs)."""
    cls, effects = effects[:2]
    if not effects:   # no effect: torque-free, as C and the vectorized path step it (v_w' is the printed 0, +0)
        return KS.rigid_body_rhs_free_c(y, c)
    F, T = _sums(y, m, I, effects)
    if cls == RHS_FULL:
        return KS.rigid_body_rhs_c(y, m, c, F, T)
    a = KS.linear_acceleration(m, F) if cls != RHS_BODY else (0.0, 0.0, 0.0)
    if cls == RHS_FORCE:
        return KS.rigid_body_rhs_force_c(y, c, a)
    return KS.rigid_body_rhs_body_c(y, c, a, T)


def _sums(y, m, I, effects):
    """The force and torque sums (F, T) of one plain body's effects [(apply, p)] at its state y (13 floats), in table
    order from SUM_START (-0.0, IEEE's additive identity), as the vectorized sums."""
    Fx = Fy = Fz = Tx = Ty = Tz = SUM_START
    v = y[_V]
    for apply, p in effects:
        f, t = apply(p, y, v, m, I)
        if f is not None:
            Fx, Fy, Fz = Fx + f[0], Fy + f[1], Fz + f[2]
        if t is not None:
            Tx, Ty, Tz = Tx + t[0], Ty + t[1], Tz + t[2]
    return (Fx, Fy, Fz), (Tx, Ty, Tz)


def _inc(y, S, effects):
    """The scaled increments H = s dt d/dt y of one plain body (13 floats) with effects (its class, [(apply, p)]) and
    constants S (rigid_body_increment_scale): _rhs's sums, then the class's increments kernel
    (numpy_backend._ForcedGroup.inc)."""
    (cls, effects, *_), m, I = effects
    F, T = _sums(y, m, I, effects)
    q, w, v = y[_Q], y[_W], y[_V]
    if cls == RHS_FULL:
        return KS.rigid_body_increments_c(q, w, v, S, F, T)
    if cls == RHS_FORCE:
        return KS.rigid_body_increments_force_c(q, w, v, S, F)
    return KS.rigid_body_increments_body_c(q, w, v, S, F, T)   # BODY: F is the sum of no force, SUM_START


def _sum(terms, stage: str, i: int, h: str) -> str:
    """Component i of x + h (a_0 k_j0 + ...) as Python source: numpy_backend._ExplicitRK.axpy's operations in its
    order (one term a = ±2^e: x + k (a h); else a coefficient of 1 not multiplied, the sum left to right, times h)."""
    if len(terms) == 1 and math.frexp(terms[0][1])[0] == 0.5:
        return f"x{i} + k{terms[0][0]}_{i}*{stage}"
    acc = None
    for j, a in terms:
        t = f"k{j}_{i}" if a == 1.0 else f"k{j}_{i}*{a!r}"
        acc = t if acc is None else f"({acc} + {t})"
    return f"x{i} + {acc}*{h}"


_RUNS: dict = {}


def _run_of(rk, normalize: bool):
    """n steps of tableau rk on one body as a compiled Python function run(x, n, h, f, args) -> x (a tuple of 13
    floats; f(y, *args) the right-hand side): the stages and the end written out component by component."""
    key = (rk.rows, rk.weights, rk.den, normalize)
    run = _RUNS.get(key)
    if run is None:
        n = LY.STATE_SIZE
        xs = ", ".join(f"x{i}" for i in range(n))
        src = ["def run(x, n, h, f, args):", f"    he = h / {rk.den!r}"]
        for s, terms in enumerate(rk.rows):
            if len(terms) == 1 and math.frexp(terms[0][1])[0] == 0.5:
                src.append(f"    ah{s} = {terms[0][1]!r} * h")
        src += ["    for _ in range(n):", f"        {xs}, = x"]
        for s, terms in enumerate(rk.rows):
            y = "x" if not terms else "(" + ", ".join(_sum(terms, f"ah{s}", i, "h") for i in range(n)) + ")"
            src.append(f"        {', '.join(f'k{s}_{i}' for i in range(n))}, = f({y}, *args)")
        end = [_sum(rk.weights, "ah_end", i, "he") for i in range(n)]
        if len(rk.weights) == 1 and math.frexp(rk.weights[0][1])[0] == 0.5:
            src.insert(2, f"    ah_end = {rk.weights[0][1]!r} * he")
        src.append(f"        x = ({', '.join(end)})")
        if normalize:
            q = _Q
            src.append(f"        x = x[:{q.start}] + normalize(x[{q.start}:{q.stop}]) + x[{q.stop}:]")
        src += ["        if not isfinite(sum(x)):   # the sum first, as the vectorized check", "            raise Fallback",
                "    return x"]
        ns = {"normalize": KS.quat_normalize, "isfinite": math.isfinite, "Fallback": Fallback}
        exec("\n".join(src), ns)   # noqa: S102 (source built above from the tableau's numbers only)
        run = _RUNS[key] = ns["run"]
    return run


def _term(k: float, h: str) -> str:
    """k H as tableaux.h's LV_<NAME>_SCALED_UPDATE forms it (numpy_backend._h_term), as Python source."""
    return h if k == 1.0 else f"({h} + {h})" if k == 2.0 else f"{h}*{k!r}"


def _stage_lines(i: int, w, m, shared: bool, end, ys, Ys, Hs, As) -> list[str]:
    """Stage i of a scaled-increment program (generated/tableaux.py SCALED_RK) written out number by number, as
    numpy_backend._scaled_stages forms it: from the increments Hs, the running sum of w H (into As; a shared multiple
    formed once, d<r>) and the stage's input y + m H into Ys, or at the last stage (m None) the step's end
    y + (acc + w H) end. ys, Ys, Hs, As: the names of the numbers."""
    src = []
    for r in range(len(ys)):
        t = _term(w, Hs[r])
        if shared:
            src.append(f"        d{r} = {t}")
            t = f"d{r}"
        acc = t if i == 0 else f"{As[r]} + {t}"
        if m is None:
            src.append(f"        {Ys[r]} = {ys[r]} + " + (f"({acc})*{end!r}" if end != 1.0 else f"({acc})"))
        else:
            src.append(f"        {As[r]} = {acc}")
            src.append(f"        {Ys[r]} = {ys[r]} + {t if shared else _term(m, Hs[r])}")
    return src


def _rot_src(prog, normalize: bool, head: list[str], inc_args: str) -> tuple[list[str], str, str]:
    """The source the writers of bodies that stage only (q, omega_b) share (_run_h_of, _run_hs_of): head (the def
    line and what comes before the step loop), the loop's unpacking of x into p, q, v, w, and per stage of the
    scaled-increment form prog the increments inc(q rows, omega_b rows, inc_args) and _stage_lines. Returns the lines,
    the step's end q (normalized when asked) and its omega_b as source tuples."""
    _, stages, end = prog
    nq = _Q.stop - _Q.start
    ny = nq + (_W.stop - _W.start)
    ys = [f"y{r}" for r in range(ny)]
    Ys, Hs, As = ([f"{v}{r}" for r in range(ny)] for v in "YHa")
    src = head + ["    for _ in range(n):",
                  f"        p, q, v, w = x[{_P.start}:{_P.stop}], x[{_Q.start}:{_Q.stop}], x[{_V.start}:{_V.stop}], "
                  f"x[{_W.start}:{_W.stop}]",
                  f"        {', '.join(ys)}, = q + w"]
    cur = ys
    for i, (w, m, shared) in enumerate(stages):
        src.append(f"        ({', '.join(Hs[:nq])}), ({', '.join(Hs[nq:])}) = inc(({', '.join(cur[:nq])},), "
                   f"({', '.join(cur[nq:])},), {inc_args})")
        src += _stage_lines(i, w, m, shared, end, ys, Ys, Hs, As)
        cur = Ys
    qn = f"normalize(({', '.join(Ys[:nq])},))" if normalize else f"({', '.join(Ys[:nq])},)"
    return src, qn, f"({', '.join(Ys[nq:])},)"


_RUNS_H: dict = {}


def _run_h_of(prog, normalize: bool, torque: bool = False, force: bool = False):
    """n steps of one body that stages only (q, omega_b) in the scaled-increment form prog (generated/tableaux.py
    SCALED_RK) as a compiled Python function run(x, n, h, R, dv, dp) -> x (13 floats), written out number by number:
    numpy_backend._free_rk4_h's operations in its order (C's lv_free_rk4_h) for a torque-free body, or
    numpy_backend._const_rk4_h's (C's lv_const_rk4_h) for a body whose effects read no state. The increments: with
    torque the printed rigid_body_increments_torque_h on R = (S, rigid_body_torque_constants(tau_w)), else rigid_body_increments_free_c on
    R = (C, h_q) (rigid_body_increment_scale_free); p and v: with force the printed translation_flow_constant on
    dv, dp (constant_acceleration_steps), else translation_drift with v kept."""
    key = (prog, normalize, torque, force)
    run = _RUNS_H.get(key)
    if run is None:
        src, qn, wn = _rot_src(prog, normalize, ["def run(x, n, h, R, dv, dp):", "    R0, R1 = R"], "R0, R1")
        if force:
            src.append("        pn, vn = flow(p, v, h, dv, dp)")
            src.append(f"        x = tuple(pn) + tuple({qn}) + tuple(vn) + {wn}")
        else:
            src.append(f"        x = tuple(drift(p, v, h)) + tuple({qn}) + v + {wn}")
        src += ["        if not isfinite(sum(x)):   # the sum first, as the vectorized check", "            raise Fallback",
                "    return x"]
        ns = {"normalize": KS.quat_normalize, "isfinite": math.isfinite, "Fallback": Fallback,
              "inc": KS.rigid_body_increments_torque_h if torque else KS.rigid_body_increments_free_c,
              "drift": KS.translation_drift, "flow": KS.translation_flow_constant}
        exec("\n".join(src), ns)   # noqa: S102 (source built above from the printed program's numbers only)
        run = _RUNS_H[key] = ns["run"]
    return run


def _run_const(x, n_steps, dt, scaled, normalize, c, m, I, effects, const):
    """n_steps of one body whose effects all read no state (const = (torque, force), effects.constant_kind) by
    _run_h_of: their sums once (_sums, as numpy_backend._const_rk4_h takes them), then the call's constants."""
    torque, force = const
    F, T = _sums(x, m, I, effects[1])
    sdt = scaled[0] * dt
    R = ((KS.rigid_body_increment_scale(c, m, sdt), KS.rigid_body_torque_constants(T)) if torque
         else KS.rigid_body_increment_scale_free(c, sdt))
    dv, dp = KS.constant_acceleration_steps(m, F, dt) if force else (None, None)
    return _run_h_of(scaled, normalize, torque, force)(x, n_steps, dt, R, dv, dp)


_RUNS_HF: dict = {}


def _run_hf_of(prog, normalize: bool):
    """n steps of one body with effects in the scaled-increment form prog (generated/tableaux.py SCALED_RK) on its 13
    numbers as a compiled Python function run(x, n, S, args) -> x (S its increment constants, args _inc's effects):
    numpy_backend._forced_rk4_h's operations in its order (C's LV_RK4_SCALED_STEP), written out number by number."""
    key = (prog, normalize)
    run = _RUNS_HF.get(key)
    if run is None:
        s, stages, end = prog
        n = LY.STATE_SIZE
        xs, Ys, Hs, As = ([f"{v}{r}" for r in range(n)] for v in "xYHa")
        src = ["def run(x, n, S, args):", "    for _ in range(n):", f"        {', '.join(xs)}, = x"]
        cur = xs
        for i, (w, m, shared) in enumerate(stages):
            src.append(f"        {', '.join(Hs)}, = inc(({', '.join(cur)},), S, args)")
            src += _stage_lines(i, w, m, shared, end, xs, Ys, Hs, As)
            cur = Ys
        src.append(f"        x = ({', '.join(Ys)},)")
        if normalize:
            q = _Q
            src.append(f"        x = x[:{q.start}] + normalize(x[{q.start}:{q.stop}]) + x[{q.stop}:]")
        src += ["        if not isfinite(sum(x)):   # the sum first, as the vectorized check", "            raise Fallback",
                "    return x"]
        ns = {"normalize": KS.quat_normalize, "isfinite": math.isfinite, "Fallback": Fallback, "inc": _inc}
        exec("\n".join(src), ns)   # noqa: S102 (source built above from the printed program's numbers only)
        run = _RUNS_HF[key] = ns["run"]
    return run


_RUNS_HS: dict = {}


def _flow_scale(aff, m: float, dt: float):
    """translation_flow_scale's constants of a decoupled body: its affine forces [(affine, p)] summed in table order
    from SUM_START (numpy_backend._EffectIndex.affine, C's lv_split_flow_scale)."""
    Fx = Fy = Fz = k = SUM_START
    for fn, p in aff:
        f, r = fn(p, m)
        Fx, Fy, Fz, k = Fx + f[0], Fy + f[1], Fz + f[2], k + r
    return KS.translation_flow_scale(k, (Fx, Fy, Fz), m, dt)


def _rot_b(q, w, S, p, v, args):
    """A decoupled body's rotation increments under its body-frame torque sums at (q, w) (numpy_backend._split_rk4_h)."""
    (_, effects, *_), m, I = args
    return KS.rigid_body_increments_rot_b_c(q, w, S, _sums(p + q + v + w, m, I, effects)[1])


def _rot_free(q, w, S, p, v, args):
    """A decoupled body's torque-free rotation increments on S's C_b and h_q."""
    return KS.rigid_body_increments_free_c(q, w, S[INC_SCALE_C], S[INC_SCALE_HQ])


def _run_hs_of(prog, normalize: bool, split: int):
    """n decoupled steps of one body (split: numpy_backend._split_rk4_h's) in the scaled-increment form prog as a
    compiled Python function run(x, n, S, TF, args) -> x (S its increment constants, TF its flow constants, args
    _inc's effects): the rotation (q, omega_b) through the stages, then translation_flow, written out number by
    number."""
    key = (prog, normalize, split)
    run = _RUNS_HS.get(key)
    if run is None:
        src, qn, wn = _rot_src(prog, normalize, ["def run(x, n, S, TF, args):"], "S, p, v, args")
        src += ["        pn, vn = flow(p, v, TF)",
                f"        x = tuple(pn) + tuple({qn}) + tuple(vn) + {wn}",
                "        if not isfinite(sum(x)):   # the sum first, as the vectorized check", "            raise Fallback",
                "    return x"]
        ns = {"normalize": KS.quat_normalize, "isfinite": math.isfinite, "Fallback": Fallback,
              "inc": _rot_free if split == 1 else _rot_b, "flow": KS.translation_flow}
        exec("\n".join(src), ns)   # noqa: S102 (source built above from the printed program's numbers only)
        run = _RUNS_HS[key] = ns["run"]
    return run


def advance(sb: ScalarBodies, state, rk, normalize: bool, dt: float, n_steps: int, scaled=None) -> None:
    """Step every body of state (n, 13) by n_steps of rk (an _ExplicitRK) of length dt, in floats; state is
    written at the end, all bodies at once; scaled: the scaled-increment form of rk (generated/tableaux.py
    SCALED_RK) that torque-free bodies take, or None. Raises Fallback (state untouched) where the vectorized path
    must decide."""
    run = _run_of(rk, normalize)
    out = []
    try:
        for x, (c, m, I, effects, const) in zip(state.tolist(), sb.bodies):
            if scaled is not None and not effects[1]:   # torque-free (no effect of its own or scene-wide)
                R = KS.rigid_body_increment_scale_free(c, scaled[0] * dt)
                out.append(_run_h_of(scaled, normalize)(tuple(x), n_steps, dt, R, None, None))
            elif scaled is not None and effects[2]:   # decoupled: the rotation staged alone, the translation's flow
                S = KS.rigid_body_increment_scale(c, m, scaled[0] * dt)
                out.append(_run_hs_of(scaled, normalize, effects[2])(tuple(x), n_steps, S, _flow_scale(effects[3], m, dt),
                                                                     (effects, m, I)))
            elif scaled is not None and const is not None:   # effects reading no state: (q, omega_b) staged alone
                out.append(_run_const(tuple(x), n_steps, dt, scaled, normalize, c, m, I, effects, const))
            elif scaled is not None:   # with effects: the scaled-increment form on the 13 numbers
                S = KS.rigid_body_increment_scale(c, m, scaled[0] * dt)
                out.append(_run_hf_of(scaled, normalize)(tuple(x), n_steps, S, (effects, m, I)))
            else:
                out.append(run(x, n_steps, dt, _rhs, (c, m, I, effects)))
    except (ArithmeticError, ValueError) as e:
        raise Fallback from e
    state[...] = out
