"""Rigid-body dynamics: Euler's rotation equations, the state right-hand side, energy, momentum.

State x (13 numbers), the layout every integrator and backend uses (declared in derive/layout.py,
printed as generated/layout.h and layout.py): p_w (3) position of the centre of mass, world frame,
m; q (4) orientation R_WB as (x, y, z, w), unit; v_w (3) velocity of the centre of mass, world
frame, m/s; omega_b (3) angular velocity, body frame, rad/s.
Inertia is diagonal in the body frame (principal axes): I_b = (I_x, I_y, I_z), kg·m².

Euler's equations are printed division-free: ω̇_x = k_x ω_y ω_z + r_x τ_x (cyclic) with the
inertia-only coefficients c_b = (k_x, k_y, k_z, r_x, r_y, r_z), k_x = (I_y − I_z)/I_x, r_x = 1/I_x
(euler_coefficients). The kernels that take I_b compute c_b first as named subexpressions
(Kernel.where), so they print exactly the arithmetic of the *_c kernels that take c_b: a step loop
computes c_b once per call (kernel euler_coefficients) and its stages divide by nothing, with bits
equal to the I_b kernels'.
"""
from __future__ import annotations

import sympy as sp

from .kernel import Arg, Kernel, scalar, vec
from .layout import CONSTANTS, EULER
from .layout import STATE as X
from .quaternion import pure, qmul, quat_rate_body, rotate_to_body, rotation_matrix
from .tableaux import EXPLICIT_RK, constant_acceleration_weights

STATE = "state (p_w[3] m, q[4] (x,y,z,w), v_w[3] m/s, omega_b[3] rad/s)"


def euler_coefficients(I_b: sp.Matrix) -> sp.Matrix:
    """c_b = (k_x, k_y, k_z, r_x, r_y, r_z): k_x = (I_y − I_z)/I_x (cyclic, dimensionless), r_x = 1/I_x
    (1/(kg·m²)). Exactly 0 = k_x when I_y = I_z, so the gyroscopic term of a symmetric axis is exactly zero."""
    k = [(I_b[(i + 1) % 3] - I_b[(i + 2) % 3]) / I_b[i] for i in range(3)]
    return EULER.assemble(k=k, r=[1 / I_b[i] for i in range(3)])


def euler_rhs_c(c_b, w: sp.Matrix, tau_b) -> sp.Matrix:
    """ω̇_b from the coefficients c_b (euler_coefficients): ω̇_x = k_x ω_y ω_z + r_x τ_x (cyclic)."""
    k, r = EULER.part(c_b, "k"), EULER.part(c_b, "r")
    return sp.Matrix([k[i] * w[(i + 1) % 3] * w[(i + 2) % 3] + r[i] * tau_b[i] for i in range(3)])


def euler_rhs(I_b: sp.Matrix, w: sp.Matrix, tau_b) -> sp.Matrix:
    """ω̇_b from I ω̇ + ω × (I ω) = τ, per axis (the coefficients of euler_coefficients substituted):
    ω̇_x = ((I_y − I_z)/I_x) ω_y ω_z + τ_x/I_x (and cyclic)."""
    return euler_rhs_c(euler_coefficients(I_b), w, tau_b)


def _check_euler(I_b, w, tau):
    """Proof that the per-axis coefficient form is I⁻¹(τ − ω × Iω)."""
    I = sp.diag(*I_b)
    ref = I.inv() * (tau - w.cross(I * w))
    if (ref - euler_rhs(I_b, w, tau)).applyfunc(sp.simplify) != sp.zeros(3, 1):
        raise RuntimeError("derive: per-axis Euler equations differ from I⁻¹(τ − ω × Iω)")


def _check_rate_scale(q, w) -> None:
    """Proof that dq/dt = QUAT_RATE_SCALE q ⊗ [ω_b, 0] (the printed constant a step folds into its dt)."""
    scale = dict((n, v) for n, v, _ in CONSTANTS)["QUAT_RATE_SCALE"]
    if (quat_rate_body(q, w) - sp.nsimplify(scale) * qmul(q, pure(w))).applyfunc(sp.expand) != sp.zeros(4, 1):
        raise RuntimeError("derive: QUAT_RATE_SCALE is not the scale of quat_rate_body")

# The constants of a stage's scaled increments (rigid_body_increment_scale): C = sdt k_b (3), R = sdt r_b (3), h_q,
# sdt, h_m = sdt/m; their count and offsets (printed into kernels.h by derive/effect_fuse.py: LV_INC_SCALE_SIZE).
INC_SCALE_SIZE = 9
INC_C, INC_R, INC_HQ, INC_SDT, INC_HM = slice(0, 3), slice(3, 6), 6, 7, 8
# A body whose effects all read no state (the constant kinds TORQUE, FULL, FORCE) steps only (q, omega_b) through the
# stages and its translation by the exact flow of a constant acceleration; its constants per call, CONST_SIZE numbers:
# S (rigid_body_increment_scale), the world torque's constants T_w = (tau_w, 2 tau_w) (rigid_body_torque_constants,
# CONST_TAU_SIZE numbers), then dv_w, dp_w (constant_acceleration_steps). Printed into kernels.h by
# derive/effect_fuse.py (LV_CONST_*).
CONST_TAU_SIZE = 6
CONST_TAU, CONST_DV = INC_SCALE_SIZE, INC_SCALE_SIZE + CONST_TAU_SIZE
CONST_DP = CONST_DV + 3
CONST_SIZE = CONST_DP + 3


def inc_scale(c_b, m, sdt) -> list:
    """S = (sdt k_b, sdt r_b, sdt QUAT_RATE_SCALE, sdt, sdt/m) of the Euler coefficients c_b, the mass and sdt."""
    scale = sp.nsimplify(dict((n, v) for n, v, _ in CONSTANTS)["QUAT_RATE_SCALE"])
    k, r = EULER.part(c_b, "k"), EULER.part(c_b, "r")
    return [sdt * k[i] for i in range(3)] + [sdt * r[i] for i in range(3)] + [sdt * scale, sdt, sdt / m]


def affine_flow(c, b_num, b_den) -> tuple[sp.Expr, sp.Expr, sp.Expr, sp.Expr]:
    """(R, P, Q, S), polynomials in z = λ dt: one step of the explicit subdiagonal RK (nodes c, weights b_num / b_den;
    stage s at x + c_s dt k_{s-1}) on p' = v, v' = a − λ v (a, λ constant over the step) is exactly
    v⁺ = R v + dt P a, p⁺ = p + dt Q v + dt² S a. Derived by applying the tableau to that linear system symbolically."""
    z, dt, lam, a, v, p = sp.symbols("z dt lambda a v p")
    kv: list[sp.Expr] = []
    kp: list[sp.Expr] = []
    for i, ci in enumerate(c):
        vi = v + (ci * dt * kv[i - 1] if i else 0)
        kv.append(a - lam * vi)
        kp.append(vi)
    b = [sp.Rational(n, b_den) for n in b_num]
    v1 = sp.expand((v + dt * sum(bi * k for bi, k in zip(b, kv))).subs(lam, z / dt))
    p1 = sp.expand((p + dt * sum(bi * k for bi, k in zip(b, kp))).subs(lam, z / dt))
    R_, P_ = v1.coeff(v), sp.expand(v1.coeff(a) / dt)
    Q_, S_ = sp.expand(p1.coeff(v) / dt), sp.expand(p1.coeff(a) / dt ** 2)
    for e in (R_, P_, Q_, S_):
        if e.free_symbols - {z}:
            raise RuntimeError("derive: the affine flow's coefficients are not polynomials in z = λ dt")
    if sp.expand(R_ * v + dt * P_ * a - v1) != 0 or sp.expand(p + dt * Q_ * v + dt ** 2 * S_ * a - p1) != 0:
        raise RuntimeError("derive: the affine flow does not reproduce the tableau's step")
    return R_, P_, Q_, S_


# translation_flow_scale's constants T (once per body and call): R(z), dt Q(z), dv = dt P(z) a, dp = dt² S(z) a.
FLOW_SIZE = 8
FLOW_R, FLOW_Q, FLOW_DV, FLOW_DP = 0, 1, slice(2, 5), slice(5, 8)


class NegativeZero(sp.AtomicExpr):
    """IEEE's -0.0 as a printed constant: the additive identity (-0 + x = x for every double x, signed zeros
    included), so a compiler folds x + (-0.0) to x where it may not fold x + 0.0 ((-0) + (+0) = +0). An increment
    that is exactly zero prints as it (NO_FORCE): a stage input x + m H and the step's end x + (acc + w H) e are then
    x bitwise, and the compiler keeps x itself through the stages. SymPy has no signed zero (Float(-0.0) is 0), hence
    an atom of its own; substitute 0 for it in a proof."""
    is_commutative = True
    is_real = True
    is_number = True

    def _eval_evalf(self, prec):
        return sp.Float(0, precision=prec)

    def __float__(self) -> float:
        return -0.0

    def _ccode(self, printer) -> str:
        return "-0.0"

    _numpycode = _pythoncode = _ccode

    def _latex(self, printer) -> str:
        return "-0"

    def _sympystr(self, printer) -> str:
        return "-0.0"


NEG_ZERO = NegativeZero()
# The velocity increments of a body without a force: -0, the additive identity (NegativeZero), so v_W + H_v is v_W.
NO_FORCE = sp.Matrix([NEG_ZERO] * 3)


def increments(xq, xw, xv, S, F_w, tau_b) -> sp.Matrix:
    """H = (s dt) x' of a body (q, omega_b, v_w) with the constants S (inc_scale): H_p = sdt v_W, H_q = q (x)
    [h_q omega_B, 0], H_v = h_m F_W (0 when F_w is None; NO_FORCE's -0 when F_w is NO_FORCE), H_omega,x = C_x omega_y
    omega_z + R_x tau_B,x (cyclic; no torque term when tau_b is None). On the symbols of rigid_body_increments_free_c
    (q, omega_b): the same printed arithmetic for q and omega_b where the torque is zero (a body under a force alone
    turns bitwise as a free one)."""
    coef = EULER.assemble(k=list(S[INC_C]), r=list(S[INC_R]))
    v_inc = sp.zeros(3, 1) if F_w is None else F_w if F_w is NO_FORCE else S[INC_HM] * F_w
    return X.assemble(p_w=S[INC_SDT] * xv, q=qmul(xq, pure(S[INC_HQ] * xw)), v_w=v_inc,
                      omega_b=euler_rhs_c(coef, xw, sp.zeros(3, 1) if tau_b is None else tau_b))


def _check_increments(xq, xw, xv, S, c_b, m, sdt, F_w, tau_w) -> None:
    """Proof that the increments are sdt times rigid_body_rhs_c's rates (S = inc_scale(c_b, m, sdt))."""
    rate = X.assemble(p_w=xv, q=quat_rate_body(xq, xw), v_w=F_w / m,
                      omega_b=euler_rhs_c(c_b, xw, rotate_to_body(xq, tau_w)))
    H = increments(xq, xw, xv, S, F_w, rotate_to_body(xq, tau_w)).subs(dict(zip(S, inc_scale(c_b, m, sdt))))
    if (H - sdt * rate).applyfunc(sp.expand) != sp.zeros(X.size, 1):
        raise RuntimeError("derive: the scaled increments are not s dt times the rates")


def _check_torque_b(H_tb: sp.Matrix, H_body: sp.Matrix, F_w: sp.Matrix) -> None:
    """Proof that rigid_body_increments_torque_b_c is rigid_body_increments_body_c at a zero force, its -0 read as 0:
    every row but v_W the very expression (the same printed arithmetic), v_W's the additive identity."""
    vs = range(X.size)[X.slice("v_w")]
    if any(H_tb[i] != H_body[i] for i in range(X.size) if i not in vs):
        raise RuntimeError("derive: the torque-only increments differ from the body increments beyond v_W")
    if any(H_tb[i] != NEG_ZERO or H_body[i].subs({f: 0 for f in F_w}) != 0 for i in vs):
        raise RuntimeError("derive: the torque-only increments' v_W rows are not the body increments' at F_W = 0")


def _check_torque_h(q, w, S_b, T_w) -> None:
    """Proof that rigid_body_increments_torque_h at a zero torque is rigid_body_increments_free_c on the constants
    rigid_body_increment_scale_free prints (S's C and h_q): the constant kinds' rotation without a torque."""
    H = increments(q, w, sp.zeros(3, 1), S_b, None, rotate_to_body_doubled(q, T_w[:3, 0], T_w[3:, 0]))
    H = H.subs({t: 0 for t in T_w})
    free = X.assemble(p_w=sp.zeros(3, 1), q=qmul(q, pure(S_b[INC_HQ] * w)), v_w=sp.zeros(3, 1),
                      omega_b=euler_rhs_c(EULER.assemble(k=list(S_b[INC_C]), r=[0, 0, 0]), w, sp.zeros(3, 1)))
    for part in ("q", "omega_b"):
        if (X.part(H, part) - X.part(free, part)).applyfunc(sp.expand) != sp.zeros(X.part(H, part).rows, 1):
            raise RuntimeError("derive: the torque increments on (q, omega_b) at zero torque are not the free ones")


def rotate_to_body_doubled(q: sp.Matrix, v_w: sp.Matrix, v2_w: sp.Matrix) -> sp.Matrix:
    """rotate_to_body(q, v_w) with its doubled vector given: v2_w = 2 v_w, a per-call constant when v_w is (a constant
    world torque), so a stage forms t = q_v × v2_w without the factor 2 (rotate_to_body's t = (2 q_v) × v costs a
    multiply or an add per factor at every stage). Derived from rotate_to_body on v2_w/2: its t is then q_v × v2_w
    and its lone v2_w/2 is v_w. The products are bitwise rotate_to_body's ((2a)·b and a·(2b) are the one exact 2ab,
    rounded once; doubling is exact below overflow)."""
    half = rotate_to_body(q, v2_w / 2)
    out = half.xreplace({v2_w[i] / 2: v_w[i] for i in range(3)})
    if any(v2_w[i] / 2 in e.atoms(sp.Mul) for e in out for i in range(3)):
        raise RuntimeError("derive: rotate_to_body_doubled left a halved v2_w")
    ref = rotate_to_body(q, v_w)
    if (out.subs({v2_w[i]: 2 * v_w[i] for i in range(3)}) - ref).applyfunc(sp.expand) != sp.zeros(3, 1):
        raise RuntimeError("derive: rotate_to_body_doubled is not rotate_to_body at v2_w = 2 v_w")
    return out


def torque_constants(tau_w: sp.Matrix) -> sp.Matrix:
    """T_w = (tau_w, 2 tau_w): the constants rigid_body_increments_torque_h takes for a constant world torque."""
    return sp.Matrix([*tau_w, *(2 * tau_w)])


def constant_flow(m, F_w, h, p_w, v_w) -> tuple:
    """The built-in RK4's exact step of the translation p' = v, v' = a = F/m with F constant over the step
    (tableaux.constant_acceleration_weights: v + w_v h a, p + w_v h v + w_p h² a), as printed: the per-call constants
    (where, dv, dp) of constant_acceleration_steps and the step's (where, p_next, v_next) of translation_flow_constant.
    p + h v is formed first as translation_drift forms it (w_v = 1 is required), then dp added: a zero force (dp = 0)
    gives translation_drift's bits, v + 0 = v."""
    w_v, w_p = constant_acceleration_weights(*EXPLICIT_RK["rk4"])
    if w_v != 1:
        raise RuntimeError("derive: RK4's weights do not sum to 1 (its drift is not translation_drift)")
    a = vec("a_w", 3)
    hh = scalar("hh")
    steps = ([*zip(a, F_w / m), (hh, w_p * h * h)], h * a, hh * a)
    d = vec("d_w", 3)
    flow = (list(zip(d, p_w + h * v_w)), d + vec("dp_w", 3), v_w + vec("dv_w", 3))
    return steps, flow


def kernels() -> list[Kernel]:
    g = "Rigid-body dynamics"
    x = vec("x", X.size)
    m = scalar("m", positive=True)
    I_b, F_w, tau_w, tau_b = vec("I_b", 3), vec("F_w", 3), vec("tau_w", 3), vec("tau_b", 3)
    omega_b, v_w, q, vec_w = vec("omega_b", 3), vec("v_w", 3), vec("q", 4), vec("v", 3)
    c_b = vec("c_b", EULER.size)
    C_b, h_q = vec("C_b", 3), scalar("h_q")
    S_b, sdt = vec("S_b", INC_SCALE_SIZE), scalar("sdt")
    _check_euler(I_b, omega_b, tau_b)
    _check_rate_scale(q, omega_b)
    _check_increments(q, omega_b, v_w, S_b, c_b, m, sdt, F_w, tau_w)
    # T_w's symbols: tau_w and tau2_w (= 2 tau_w), named so the printed sums keep rotate_to_body's term order (bitwise)
    T_w = sp.Matrix([*tau_w, *vec("tau2_w", 3)])
    _check_torque_h(q, omega_b, S_b, T_w)
    h, p_w, dv_w, dp_w = scalar("h"), vec("p_w", 3), vec("dv_w", 3), vec("dp_w", 3)
    (steps_where, dv, dp), (flow_where, p_next, v_next) = constant_flow(m, F_w, h, p_w, v_w)
    S_expr = inc_scale(c_b, m, sdt)
    H_tq = increments(q, omega_b, v_w, S_b, None, rotate_to_body_doubled(q, T_w[:3, 0], T_w[3:, 0]))
    H_tb = increments(q, omega_b, v_w, S_b, NO_FORCE, tau_b)
    _check_torque_b(H_tb, increments(q, omega_b, v_w, S_b, F_w, tau_b), F_w)
    # c_b as named subexpressions of the kernels that take I_b: the same printed arithmetic as the *_c kernels
    where = list(zip(c_b, euler_coefficients(I_b)))
    xq, xv, xw = X.part(x, "q"), X.part(x, "v_w"), X.part(x, "omega_b")
    qdot = quat_rate_body(xq, xw)
    full = X.assemble(p_w=xv, q=qdot, v_w=F_w / m, omega_b=euler_rhs_c(c_b, xw, rotate_to_body(xq, tau_w)))
    free = X.assemble(p_w=xv, q=qdot, v_w=sp.zeros(3, 1), omega_b=euler_rhs_c(c_b, xw, sp.zeros(3, 1)))
    # a world torque only: the v rate of the sum of no force (SUM_START, -0: F_W/m with F_W = -0), printed as -0
    torque = X.assemble(p_w=xv, q=qdot, v_w=NO_FORCE, omega_b=euler_rhs_c(c_b, xw, rotate_to_body(xq, tau_w)))
    a_w = vec("a_w", 3)
    force_only = X.assemble(p_w=xv, q=qdot, v_w=a_w, omega_b=euler_rhs_c(c_b, xw, sp.zeros(3, 1)))
    body = X.assemble(p_w=xv, q=qdot, v_w=a_w, omega_b=euler_rhs_c(c_b, xw, tau_b))
    Rq = rotation_matrix(q)
    inv_apply = Rq * sp.diag(*[1 / I_b[i] for i in range(3)]) * Rq.T * vec_w
    ke = (m * v_w.dot(v_w) + sum(I_b[i] * omega_b[i] ** 2 for i in range(3))) / 2
    IB = ("I_b", I_b, "principal moments, body frame, kg·m²", "positive")
    CB = ("c_b", c_b, "Euler coefficients (k_x, k_y, k_z, r_x, r_y, r_z), body frame: k_x = (I_y − I_z)/I_x "
          "(cyclic, dimensionless), r_x = 1/I_x (1/(kg·m²)); from euler_coefficients")
    QU = ("q", q, "orientation (x, y, z, w), R_WB, unit", "unit_quaternion")
    XS = ("x", x, STATE, "real")
    SB = ("S_b", S_b, "the increments' constants (C_x, C_y, C_z, R_x, R_y, R_z, h_q, sdt, h_m) of "
          "rigid_body_increment_scale, once per body and call")
    QWV = (Arg("q", q, "orientation (x, y, z, w), R_WB (a stage's value: unit to rounding)", "unit_quaternion"),
           Arg("omega_b", omega_b, "angular velocity, body frame, rad/s"),
           Arg("v_w", v_w, "COM velocity, world frame, m/s"))
    inc_note = ("The built-in RK4 steps a body with effects in the scaled-increment form (tableaux.h "
                "LV_RK4_SCALED_STEP over the 13 numbers): a stage's input and the step's end are adds and one multiply.")
    same = "Bitwise the I_b kernel of the same name without _c, given c_b = euler_coefficients(I_b) (the same printed arithmetic)."
    return flow_kernels(g) + [
        Kernel("euler_equations", "Euler's rotation equations with external torque, body frame",
               r"I_B \dot\omega_B + \omega_B \times (I_B \omega_B) = \tau_B",
               [Arg(*IB), Arg("omega_b", omega_b, "angular velocity, body frame, rad/s"), Arg("tau_b", tau_b, "torque, body frame, N·m")],
               [Arg("omega_dot_b", euler_rhs_c(c_b, omega_b, tau_b), "angular acceleration, body frame, rad/s²")], g,
               where=where),
        Kernel("rigid_body_rhs", "State derivative under a world force at the COM and a world torque",
               r"\dot p_W = v_W,\ \dot q = \tfrac12 q \otimes [\omega_B,0],\ \dot v_W = F_W/m,\ \dot\omega_B = I_B^{-1}(R^T\tau_W - \omega_B \times I_B\omega_B)",
               [Arg(*XS), Arg("m", m, "mass, kg", "positive"), Arg(*IB),
                Arg("F_w", F_w, "total force at the COM, world frame, N"), Arg("tau_w", tau_w, "total torque about the COM, world frame, N·m")],
               [Arg("x_dot", full, "d/dt of the state")], g,
               notes=["q need not be exactly unit: the body-form rate is used as is; R(q) assumes unit q."], where=where),
        Kernel("rigid_body_rhs_free", "State derivative of a torque-free, force-free body",
               r"\dot p_W = v_W,\ \dot q = \tfrac12 q \otimes [\omega_B,0],\ \dot v_W = 0,\ I_x\dot\omega_x = (I_y - I_z)\omega_y\omega_z\ \text{(cyclic)}",
               [Arg(*XS), Arg(*IB)], [Arg("x_dot", free, "d/dt of the state")], g, where=where),
        Kernel("apply_inv_inertia", "Multiply a world vector by I_W⁻¹: rotate into the body, apply the diagonal inverse, rotate back",
               r"I_W^{-1} v = R_{WB}\, \operatorname{diag}(1/I_x, 1/I_y, 1/I_z)\, R_{WB}^T v",
               [Arg(*QU), Arg(*IB), Arg("v", vec_w, "vector, world frame (e.g. torque, N·m)")],
               [Arg("out", inv_apply, "I_W⁻¹ v, world frame (e.g. rad/s²)")], g),
        Kernel("world_to_body", "Express a world vector in the body frame", r"v_B = R_{WB}^T v_W",
               [Arg(*QU), Arg("v_w", vec_w, "vector, world frame")], [Arg("v_b", Rq.T * vec_w, "vector, body frame")], g),
        Kernel("kinetic_energy", "Translational plus rotational kinetic energy",
               r"T = \tfrac12 m \lVert v_W\rVert^2 + \tfrac12 \omega_B^T I_B \omega_B",
               [Arg("m", m, "mass, kg", "positive"), Arg(*IB), Arg("v_w", v_w, "COM velocity, world frame, m/s"),
                Arg("omega_b", omega_b, "angular velocity, body frame, rad/s")], [Arg("T", ke, "energy, J")], g),
        Kernel("angular_momentum_world", "Angular momentum about the COM in the world frame",
               r"L_W = R_{WB} I_B \omega_B", [Arg(*QU), Arg(*IB), Arg("omega_b", omega_b, "angular velocity, body frame, rad/s")],
               [Arg("L_w", Rq * sp.diag(*I_b) * omega_b, "angular momentum, world frame, kg·m²/s")], g),
        Kernel("rigid_body_rhs_torque", "State derivative under a world torque only (rigid_body_rhs with F_W = 0, for bodies whose effects add no force)",
               r"\dot v_W = 0,\ \text{else as rigid\_body\_rhs}",
               [Arg(*XS), Arg(*IB), Arg("tau_w", tau_w, "total torque about the COM, world frame, N·m")],
               [Arg("x_dot", torque, "d/dt of the state")], g,
               notes=["Bitwise rigid_body_rhs with F_W the sum of no force, -0 (effect sums start at IEEE's additive "
                      "identity, derive/effect_fuse.py SUM_START): its v rate F_W/m is then -0, printed as -0.0 "
                      "(NegativeZero), so v_W + h v_dot is v_W bitwise."], where=where),
        Kernel("euler_coefficients", "The inertia-only coefficients of Euler's equations, computed once per body and call",
               r"k_x = (I_y - I_z)/I_x,\ r_x = 1/I_x\ \text{(cyclic)}",
               [Arg(*IB)], [Arg("c_b", c_b, "(k_x, k_y, k_z, r_x, r_y, r_z), body frame; k dimensionless, r 1/(kg·m²)")], g,
               notes=["The step loops call it once per body and call; the *_c right-hand sides then divide by nothing.",
                      "Printed from the same named subexpressions as the I_b kernels, so their c_b is bitwise this one."],
               where=where),
        Kernel("rigid_body_rhs_free_c", "rigid_body_rhs_free on the Euler coefficients c_b (no division)",
               r"\dot\omega_x = k_x\omega_y\omega_z\ \text{(cyclic), else as rigid\_body\_rhs\_free}",
               [Arg(*XS), Arg(*CB)], [Arg("x_dot", free, "d/dt of the state")], g, notes=[same]),
        Kernel("rigid_body_rhs_torque_c", "rigid_body_rhs_torque on the Euler coefficients c_b (no division)",
               r"\dot\omega_x = k_x\omega_y\omega_z + r_x (R^T\tau_W)_x\ \text{(cyclic), else as rigid\_body\_rhs\_torque}",
               [Arg(*XS), Arg(*CB), Arg("tau_w", tau_w, "total torque about the COM, world frame, N·m")],
               [Arg("x_dot", torque, "d/dt of the state")], g, notes=[same]),
        Kernel("rigid_body_rhs_c", "rigid_body_rhs on the Euler coefficients c_b (one division: F_W/m)",
               r"\dot\omega_x = k_x\omega_y\omega_z + r_x (R^T\tau_W)_x\ \text{(cyclic), else as rigid\_body\_rhs}",
               [Arg(*XS), Arg("m", m, "mass, kg", "positive"), Arg(*CB),
                Arg("F_w", F_w, "total force at the COM, world frame, N"), Arg("tau_w", tau_w, "total torque about the COM, world frame, N·m")],
               [Arg("x_dot", full, "d/dt of the state")], g, notes=[same]),
        Kernel("rigid_body_rates_free_c", "The rates a torque-free RK4 step stages: q ⊗ [ω_B, 0] and ω̇_B, on c_b",
               r"g = q \otimes [\omega_B, 0] = \dot q / s,\ \dot\omega_x = k_x\omega_y\omega_z\ \text{(cyclic)}",
               [Arg("q", q, "orientation (x, y, z, w), R_WB (a stage's value: unit to rounding)", "unit_quaternion"),
                Arg("omega_b", omega_b, "angular velocity, body frame, rad/s"), Arg(*CB)],
               [Arg("g", qmul(q, pure(omega_b)), "q ⊗ [ω_b, 0] = (dq/dt) / QUAT_RATE_SCALE, 1/s"),
                Arg("omega_dot_b", euler_rhs_c(c_b, omega_b, sp.zeros(3, 1)), "angular acceleration, body frame, rad/s²")],
               g, notes=["Only q and ω_b change within a torque-free step (v_W' = 0): the opt-in FMA tiles "
                         "(Sim(..., contract=\"fma\"), csrc/batch_simd.h) stage these two with the step QUAT_RATE_SCALE·dt "
                         "for q (the ½ of q̇ folded into it) and move p_W by one Euler step with v_W.",
                         "Not bitwise rigid_body_rhs_free_c's q rate times QUAT_RATE_SCALE (there ½ multiplies ω first)."]),
        Kernel("rigid_body_increments_free_c", "A torque-free RK4 stage's scaled increments H = (s dt) (dq/dt, dω_B/dt)",
               r"H_q = q \otimes [h_q \omega_B, 0],\ H_{\omega,x} = C_x \omega_y \omega_z\ \text{(cyclic)}",
               [Arg("q", q, "orientation (x, y, z, w), R_WB (a stage's value: unit to rounding)", "unit_quaternion"),
                Arg("omega_b", omega_b, "angular velocity, body frame, rad/s"),
                Arg("C_b", C_b, "the gyroscopic coefficients times the stage scale, C_x = (s dt) k_x (cyclic; k_x of "
                                "euler_coefficients, s of tableaux.h LV_RK4_SCALE), once per call, s"),
                Arg("h_q", h_q, "q's scale (s dt) QUAT_RATE_SCALE, once per call, s")],
               [Arg("H_q", qmul(q, pure(h_q * omega_b)), "(s dt) dq/dt, dimensionless"),
                Arg("H_omega", euler_rhs_c(EULER.assemble(k=list(C_b), r=[0, 0, 0]), omega_b, sp.zeros(3, 1)),
                    "(s dt) dω_B/dt, rad/s")],
               g, notes=["The torque-free RK4 step of the default (bitwise) paths stages these increments of q and ω_b "
                         "alone (tableaux.h LV_RK4_SCALED_UPDATE: the stage inputs and the step's end are then adds, "
                         "and one multiply by the printed end factor); p_W moves by translation_drift with v_W (v_W' = 0, "
                         "the weights sum to 1) and v_W is kept.",
                         "The rate of q is scaled through ω_B (h_q ω_B first), as rigid_body_rhs_free_c scales it by ½."]),
        Kernel("rigid_body_increment_scale", "The constants of an RK4 stage's scaled increments H = (s dt) x' of a body "
               "with effects, once per body and call",
               r"S = (s\,dt\,k_B,\ s\,dt\,r_B,\ s\,dt\,\mathrm{QUAT\_RATE\_SCALE},\ s\,dt,\ s\,dt/m)",
               [Arg(*CB), Arg("m", m, "mass, kg", "positive"),
                Arg("sdt", sdt, "the stage scale times the step, LV_RK4_SCALE dt (tableaux.h), s")],
               [Arg("S_b", sp.Matrix(inc_scale(c_b, m, sdt)), "(C_x, C_y, C_z, R_x, R_y, R_z, h_q, sdt, h_m): C = sdt k_b, "
                    "R = sdt r_b, h_q = sdt QUAT_RATE_SCALE, h_m = sdt/m")], g,
               notes=["The increments kernels rigid_body_increments*_c take it: s dt is folded into the Euler "
                      "coefficients, 1/I, q's rate scale and 1/m, so an increment costs what the rate costs."]),
        Kernel("rigid_body_increments_c", "An RK4 stage's scaled increments H = (s dt) x' under a world force and torque",
               r"H = (s\,dt)\,\dot x\ \text{of rigid\_body\_rhs, with } s\,dt \text{ in the constants S}",
               [*QWV, Arg(*SB), Arg("F_w", F_w, "total force at the COM, world frame, N"),
                Arg("tau_w", tau_w, "total torque about the COM, world frame, N·m")],
               [Arg("H", increments(q, omega_b, v_w, S_b, F_w, rotate_to_body(q, tau_w)), "(s dt) d/dt of the state")], g,
               notes=[inc_note]),
        Kernel("rigid_body_increments_torque_c", "An RK4 stage's scaled increments under a world torque only",
               r"H_v = -0,\ \text{else as rigid\_body\_increments\_c}",
               [*QWV, Arg(*SB), Arg("tau_w", tau_w, "total torque about the COM, world frame, N·m")],
               [Arg("H", increments(q, omega_b, v_w, S_b, NO_FORCE, rotate_to_body(q, tau_w)), "(s dt) d/dt of the state")],
               g, notes=[inc_note, "H_v is printed as -0.0 (NO_FORCE): bitwise rigid_body_increments_c on the sum of no "
                         "force (SUM_START, -0: h_m (-0) = -0), and v_W + H_v is v_W."]),
        Kernel("rigid_body_increments_force_c", "An RK4 stage's scaled increments under a force only (no torque)",
               r"H_{\omega,x} = C_x\omega_y\omega_z,\ H_v = h_m F_W,\ \text{else as rigid\_body\_increments\_c}",
               [*QWV, Arg(*SB), Arg("F_w", F_w, "total force at the COM, world frame, N")],
               [Arg("H", increments(q, omega_b, v_w, S_b, F_w, None), "(s dt) d/dt of the state")], g, notes=[inc_note]),
        Kernel("rigid_body_increments_body_c", "An RK4 stage's scaled increments under a force and a body-frame torque",
               r"H_{\omega,x} = C_x\omega_y\omega_z + R_x\tau_{B,x},\ H_v = h_m F_W",
               [*QWV, Arg(*SB), Arg("F_w", F_w, "total force at the COM, world frame, N (0 without a force)"),
                Arg("tau_b", tau_b, "total torque about the COM, body frame, N·m")],
               [Arg("H", increments(q, omega_b, v_w, S_b, F_w, tau_b), "(s dt) d/dt of the state")], g, notes=[inc_note]),
        Kernel("rigid_body_increments_torque_b_c", "An RK4 stage's scaled increments under a body-frame torque only (no "
               "force)", r"H_v = -0,\ \text{else as rigid\_body\_increments\_body\_c}",
               [*QWV, Arg(*SB), Arg("tau_b", tau_b, "total torque about the COM, body frame, N·m")],
               [Arg("H", H_tb, "(s dt) d/dt of the state")], g,
               notes=[inc_note, "H_v is printed as -0.0, IEEE's additive identity (NegativeZero): each stage's v_W + H_v "
                      "and the step's end are v_W bitwise, so the compiler keeps v_W through the stages and forms H_p = "
                      "sdt v_W once per step. rigid_body_increments_body_c on a zero force computes h_m 0 = +0 instead, "
                      "and v_W + (+0) turns a -0 velocity component into +0: the steps differ only there (a v_W "
                      "component of -0, and the sign of a zero H_p from it)."]),
        Kernel("rigid_body_increment_scale_free", "The constants of a torque-free RK4 stage's scaled increments "
               "(rigid_body_increments_free_c), once per body and call",
               r"C_B = s\,dt\,k_B,\ h_q = s\,dt\,\mathrm{QUAT\_RATE\_SCALE}",
               [Arg(*CB), Arg("sdt", sdt, "the stage scale times the step, LV_RK4_SCALE dt (tableaux.h), s")],
               [Arg("C_b", sp.Matrix(S_expr[INC_C]), "C = sdt k_b, s"), Arg("h_q", S_expr[INC_HQ], "sdt QUAT_RATE_SCALE, s")],
               g, notes=["Bitwise rigid_body_increment_scale's C and h_q (the same printed products): a body under a "
                         "force alone (FORCE) turns as a torque-free one."]),
        Kernel("rigid_body_increments_torque_h", "A constant-torque RK4 stage's scaled increments of (q, ω_B) alone",
               r"H_q = q \otimes [h_q \omega_B, 0],\ H_{\omega,x} = C_x\omega_y\omega_z + R_x (R^T\tau_W)_x",
               [QWV[0], QWV[1], Arg(*SB), Arg("T_w", T_w, "the world torque's constants (τ_W, 2τ_W) of "
                                                           "rigid_body_torque_constants, once per body and call")],
               [Arg("H_q", X.part(H_tq, "q"), "(s dt) dq/dt, dimensionless"),
                Arg("H_omega", X.part(H_tq, "omega_b"), "(s dt) dω_B/dt, rad/s")], g,
               notes=["A body whose effects read no state (the constant kinds TORQUE, FULL) stages only q and ω_B "
                      "(tableaux.h LV_RK4_SCALED_UPDATE), as a torque-free body does; its translation takes "
                      "translation_flow_constant (FULL) or translation_drift with v_W kept (TORQUE).",
                      "R^T τ_W as rotate_to_body with the doubled torque given (rotate_to_body_doubled: t = q_v × 2τ_W, "
                      "the factor 2 once per call): bitwise rigid_body_increments_torque_c's q and ω_B rows."]),
        Kernel("rigid_body_torque_constants", "The constants of a constant world torque's stages "
               "(rigid_body_increments_torque_h), once per body and call", r"T_W = (\tau_W,\ 2\tau_W)",
               [Arg("tau_w", tau_w, "total torque about the COM, world frame, N·m (constant over the call)")],
               [Arg("T_w", torque_constants(tau_w), "(τ_W, 2τ_W), N·m")], g,
               notes=["2τ_W is exact (below overflow): rotate_to_body's t = (2 q_v) × τ_W is formed as q_v × (2τ_W), "
                      "the same rounded products."]),
        Kernel("constant_acceleration_steps", "The per-call constants of the exact RK4 step of a translation under a "
               "constant force", r"\Delta v_W = w_v\,h\,F_W/m,\ \Delta p_W = w_p\,h^2\,F_W/m",
               [Arg("m", m, "mass, kg", "positive"), Arg("F_w", F_w, "total force at the COM, world frame, N (constant)"),
                Arg("h", h, "the step, s")],
               [Arg("dv_w", dv, "velocity change over the step, world frame, m/s"),
                Arg("dp_w", dp, "the acceleration's position change over the step, world frame, m")], g,
               where=steps_where,
               notes=["w_v = Σ b_i = 1, w_p = Σ b_i c_i = 1/2 derived from RK4's tableau "
                      "(derive/tableaux.py constant_acceleration_weights): RK4 is exact on p' = v, v' = a."]),
        Kernel("translation_flow_constant", "The exact RK4 step of a translation under a constant force",
               r"p_W \leftarrow (p_W + h\,v_W) + \Delta p_W,\ v_W \leftarrow v_W + \Delta v_W",
               [Arg("p_w", p_w, "COM position, world frame, m"), Arg("v_w", v_w, "COM velocity, world frame, m/s"),
                Arg("h", h, "the step, s"), Arg("dv_w", dv_w, "constant_acceleration_steps' dv_w, m/s"),
                Arg("dp_w", dp_w, "constant_acceleration_steps' dp_w, m")],
               [Arg("p_next", p_next, "m, world frame"), Arg("v_next", v_next, "m/s, world frame")], g,
               where=flow_where,
               notes=["p_W + h v_W is translation_drift's (the same printed operation), then Δp_W is added: a zero "
                      "force gives translation_drift's p and v + 0 (the bits of a body without the force)."]),
        Kernel("linear_acceleration", "Acceleration of the COM under a world force", r"a_W = F_W / m",
               [Arg("m", m, "mass, kg", "positive"), Arg("F_w", F_w, "total force at the COM, world frame, N")],
               [Arg("a_w", F_w / m, "COM acceleration, world frame, m/s²")], g,
               notes=["Bitwise the v rate F_W/m of rigid_body_rhs: a step loop whose force is constant over a call "
                      "divides once per call."]),
        Kernel("rigid_body_rhs_force_c", "State derivative under a force only (no torque), on c_b and the COM acceleration",
               r"\dot v_W = a_W,\ \dot\omega_x = k_x\omega_y\omega_z\ \text{(cyclic), else as rigid\_body\_rhs}",
               [Arg(*XS), Arg(*CB), Arg("a_w", a_w, "COM acceleration F_W/m (linear_acceleration), world frame, m/s²")],
               [Arg("x_dot", force_only, "d/dt of the state")], g,
               notes=["For bodies whose effects declare no torque (gravity, linear damping): nothing rotated, no "
                      "division (a_w is divided once per call when the force is constant)."]),
        Kernel("rigid_body_rhs_body_c", "State derivative under a body-frame torque and a force, on c_b and the COM acceleration",
               r"\dot v_W = a_W,\ \dot\omega_x = k_x\omega_y\omega_z + r_x \tau_{B,x}\ \text{(cyclic), else as rigid\_body\_rhs}",
               [Arg(*XS), Arg(*CB), Arg("a_w", a_w, "COM acceleration F_W/m (linear_acceleration; 0 without a force), world frame, m/s²"),
                Arg("tau_b", tau_b, "total torque about the COM, body frame, N·m")],
               [Arg("x_dot", body, "d/dt of the state")], g,
               notes=["For bodies whose torques are all declared in the body frame (angular_damping: tau_B = -c omega_B): "
                      "nothing rotated."]),
    ]


def flow_kernels(g: str) -> list[Kernel]:
    """The decoupled step of the built-in RK4 (a plain body none of whose effects is FLAG_COUPLED, derive/effect.py):
    translation by the affine flow (affine_flow of RK4's tableau: exact, per step two multiplies and two adds per
    axis), rotation staged on (q, omega_b) alone with the body-frame torque (rigid_body_increments_rot_b_c)."""
    from .tableaux import EXPLICIT_RK
    R_, P_, Q_, S_ = affine_flow(*EXPLICIT_RK["rk4"])
    z = sp.Symbol("z")
    k, m, dt = scalar("k"), scalar("m", positive=True), scalar("dt")
    F0, p_w, v_w, T = vec("F0_w", 3), vec("p_w", 3), vec("v_w", 3), vec("T", FLOW_SIZE)
    a, lam, zz, hv, hp = vec("a_w", 3), scalar("lambda_"), scalar("z_"), scalar("h_v"), scalar("h_p")
    where = [*zip(a, F0 / m), (lam, k / m), (zz, lam * dt),
             (hv, dt * sp.horner(P_, z).subs(z, zz)), (hp, dt * dt * sp.horner(S_, z).subs(z, zz))]
    outs = [sp.horner(R_, z).subs(z, zz), dt * sp.horner(Q_, z).subs(z, zz)] + [hv * a[i] for i in range(3)] + \
        [hp * a[i] for i in range(3)]
    t = vec("t_p", 3)
    q, omega_b, tau_b, S_b = vec("q", 4), vec("omega_b", 3), vec("tau_b", 3), vec("S_b", INC_SCALE_SIZE)
    H = increments(q, omega_b, vec("v_w", 3), S_b, None, tau_b)
    return [
        Kernel("translation_flow_scale", "The constants of RK4's exact step of the COM under a force F0_W − k v_W, "
               "once per body and call",
               r"z = (k/m)\,dt,\ T = (R(z),\ dt\,Q(z),\ dt\,P(z)\,a_W,\ dt^2 S(z)\,a_W),\ a_W = F0_W/m",
               [Arg("k", k, "the summed rate of the body's forces in v_W (F = F0_W − k v_W), kg/s"),
                Arg("F0_w", F0, "the summed force at v_W = 0, world frame, N"), Arg("m", m, "mass, kg", "positive"),
                Arg("dt", dt, "step, s")],
               [Arg("T", sp.Matrix(outs), "(R, dt Q, dv (3), dp (3)): translation_flow's constants")], g,
               notes=["R, P, Q, S are RK4's step on p' = v, v' = a − λv (affine_flow: its tableau applied to the "
                      "linear system in SymPy), polynomials in z = λ dt: at k = 0 exactly R = 1, dt Q = dt, dv = dt a, "
                      "dp = (dt dt ½) a (the constant-acceleration flow)."],
               where=where),
        Kernel("translation_flow", "RK4's exact step of the COM under a force F0_W − k v_W (its constants T)",
               r"v^+ = R\,v_W + dv,\ p^+ = (p_W + dt\,Q\,v_W) + dp",
               [Arg("p_w", p_w, "COM position, world frame, m"), Arg("v_w", v_w, "COM velocity, world frame, m/s"),
                Arg("T", T, "translation_flow_scale's constants")],
               [Arg("p_next", sp.Matrix([t[i] + T[FLOW_DP][i] for i in range(3)]), "m, world frame"),
                Arg("v_next", sp.Matrix([T[FLOW_R] * v_w[i] + T[FLOW_DV][i] for i in range(3)]), "m/s, world frame")],
               g, notes=["Every add has two terms (p + dt Q v first): the same association in every printing."],
               where=[(t[i], p_w[i] + T[FLOW_Q] * v_w[i]) for i in range(3)]),
        Kernel("rigid_body_increments_rot_b_c", "An RK4 stage's scaled increments of (q, omega_b) alone under a "
               "body-frame torque", r"H_q = q \otimes [h_q\omega_B, 0],\ H_{\omega,x} = C_x\omega_y\omega_z + R_x\tau_{B,x}",
               [Arg("q", q, "orientation (x, y, z, w), R_WB (a stage's value: unit to rounding)", "unit_quaternion"),
                Arg("omega_b", omega_b, "angular velocity, body frame, rad/s"),
                Arg("S_b", S_b, "rigid_body_increment_scale's constants, once per body and call"),
                Arg("tau_b", tau_b, "total torque about the COM, body frame, N·m")],
               [Arg("H_q", X.part(H, "q"), "(s dt) dq/dt"), Arg("H_omega", X.part(H, "omega_b"), "(s dt) dω_B/dt, rad/s")],
               g, notes=["rigid_body_increments_body_c's q and omega_b rows, for a body whose translation takes "
                         "translation_flow."]),
    ]
