"""The physics inside the structure-preserving integrators and the wheel model, derived once.

The backends hold only control flow (loops, Newton iteration count and stopping, step-size
control); every formula they apply comes from here:

* splitting: the free rotation composed of exact principal-axis flows in the Strang sequence of
  derive/tableaux.py (flow of H_a = L_a²/(2 I_a) for time τ: the body momentum turns about body axis
  a by −τ L_a/I_a and the attitude by +τ L_a/I_a, q ← q ⊗ [sin(θ/2) e_a, cos(θ/2)]), the half kick of
  v and ω under the loads, and the drift of p;
* implicit_gyro: the residual of I(ω⁺ − ω) + h ω⁺ × Iω⁺ = h τ_B, its Jacobian (differentiated here
  by SymPy) and one Newton update by the closed-form (adjugate) solve; the exp-map attitude step
  q ← q ⊗ exp(h ω/2) with its series where the angle is small; the semi-implicit translation;
* rk4_expmap (Runge–Kutta–Munthe-Kaas, RKMK4): RK4 on (p, v, u, ω) where the attitude is
  q = q₀ ⊗ exp(u/2) with u the body-frame rotation vector relative to the step's start, u̇ given by
  the inverse derivative of the exponential map, truncated after the order-4 terms
  u̇ = dexp⁻¹₋ᵤ(ω) ≈ ω + ½ u × ω + (1/12) u × (u × ω) (Bernoulli numbers B₁ = −½, B₂ = 1/6 with ad₋ᵤ;
  Munthe-Kaas, Appl. Numer. Math. 29 (1999) 115; Hairer, Lubich & Wanner, Geometric Numerical
  Integration, IV.8): within a step u = O(h), so the dropped terms (B₄ u⁴ …) are O(h⁴) in u̇ and the
  step stays of order 4; every stage's attitude, and the final one, is q₀ ⊗ exp(u/2) by quat_exp_step
  (with h = 1), unit to rounding;
* the free translation of a body with a model (ṗ = v, v̇ = F/m), and the reaction-wheel motor
  saturation (clip to ±torque_limit, no drive beyond speed_limit).

Units: SI; frames as in the argument docs. Quaternions (x, y, z, w), scalar last.
"""
from __future__ import annotations

import sympy as sp

from .kernel import Arg, Kernel, mat, scalar, vec
from .quaternion import qmul
from .tableaux import STRANG

# Below this half-angle |ω| h / 2 the exp map uses its series: sin(a)/|ω| = (h/2)(1 − a²/6 + a⁴/120 …);
# the dropped a⁴/120 is below 1e-34 relative there, far under rounding.
EXP_SERIES_BELOW = sp.Rational(1, 10**8)


def axis_flow(I_b, q, L, a: int, tau):
    """Exact flow for time tau of H_a = L_a²/(2 I_a): returns (q ⊗ [sin(θ/2) e_a, cos(θ/2)], L turned
    about body axis a by −θ), θ = tau L_a / I_a."""
    return axis_rotation(q, L, a, tau * L[a] / I_b[a])


def axis_rotation(q, L, a: int, th):
    """(q ⊗ [sin(θ/2) e_a, cos(θ/2)], L turned about body axis a by −θ): the exact flow of any H = f(L_a)
    with θ = τ f'(L_a) (L_a is constant along it)."""
    j, k = (a + 1) % 3, (a + 2) % 3
    sh, ch = sp.sin(th / 2), sp.cos(th / 2)
    c, s = 1 - 2 * sh * sh, 2 * sh * ch   # cos θ, sin θ from the half angle (one sin, one cos)
    L = list(L)
    L[j], L[k] = c * L[j] + s * L[k], -s * L[j] + c * L[k]
    e = [0, 0, 0, 0]
    e[a], e[3] = sh, ch
    return qmul(q, sp.Matrix(e)), L


def strang_rotation(I_b, q, omega_b, h):
    """The free rotation over h by the Strang sequence of exact axis flows; (q_next, omega_next)."""
    L = [I_b[i] * omega_b[i] for i in range(3)]
    for a, frac in STRANG:
        q, L = axis_flow(I_b, q, L, a, frac * h)
    return q, sp.Matrix([L[i] / I_b[i] for i in range(3)])


def axis_flow_kernel(a: int, I_b, q, L_b, tau) -> "Kernel":
    """Kernel axis_flow_{x,y,z}: one exact axis flow on (q, L_B) for time tau (axis_flow)."""
    qn, Ln = axis_flow(I_b, q, list(L_b), a, tau)
    n = "xyz"[a]
    return Kernel(f"axis_flow_{n}", f"Exact flow of H_{n} = L_{n}²/(2 I_{n}) on (q, L_B) for time τ",
                  rf"\theta = \tau L_{n}/I_{n},\ q \leftarrow q \otimes [\sin\tfrac\theta2 e_{n}, \cos\tfrac\theta2],"
                  rf"\ L_B \leftarrow R_{n}(-\theta) L_B",
                  [Arg("I_b", I_b, "principal moments, body frame, kg·m²", "positive"),
                   Arg("q", q, "orientation (x, y, z, w), R_WB, unit", "unit_quaternion"),
                   Arg("L_b", L_b, "angular momentum, body frame, kg·m²/s"), Arg("tau", tau, "duration of the flow, s")],
                  [Arg("q_next", qn, "orientation (unit when q is)"), Arg("L_next", sp.Matrix(Ln), "kg·m²/s, body frame")],
                  "Integrator physics",
                  notes=["splitting4 applies the free program printed in generated/tableaux (COMPOSITIONS) of these flows to "
                         "bodies without effects; each keeps |L_B|, L_W and |q| to rounding."])


# symtop4: the free rigid body split around a symmetric top (reference axis r):
#     H = |L|²/(2 I_r) + ½ c_a L_a² + ½ c_b L_b²,   c_i = 1/I_i − 1/I_r   (c_r = 0).
# |L|² is a Casimir of the Lie–Poisson bracket, so its flow (the "sphere" flow: a rotation of the attitude
# about the body momentum at rate |L|/I_r, L_B fixed) commutes with every flow of a function of L_B; the
# A part |L|²/(2 I_r) + ½ c_a L_a² is then solved exactly by the sphere flow times the axis flow of ½ c_a L_a²
# (a symmetric top), and B = ½ c_b L_b² is an axis flow. The splitting error is a sum of nested brackets each
# containing {L_a², L_b²}, i.e. proportional to c_a c_b: the score of the reference axis r is |c_a c_b|, and
# the intermediate principal axis minimises it (proved in _check); a body that is a symmetric top about one
# of its axes has c_b = 0 and is integrated exactly.


def symtop_leftover(I_b, I_r) -> sp.Matrix:
    """c_i = 1/I_i − 1/I_r, the coefficients left over when |L|²/(2 I_r) is split off H."""
    return sp.Matrix([1 / I_b[i] - 1 / I_r for i in range(3)])


def symtop_score(I_b) -> sp.Matrix:
    """score_r = |c_j c_k| (j, k the other two axes) for r = 0, 1, 2: the size of the splitting error."""
    out = []
    for r in range(3):
        c = symtop_leftover(I_b, I_b[r])
        j, k = (r + 1) % 3, (r + 2) % 3
        out.append(sp.Abs(c[j] * c[k]))
    return sp.Matrix(out)


def symtop_axis_flow(q, L, a: int, c, tau):
    """Exact flow for time tau of ½ c L_a²: θ = tau c L_a (axis_rotation)."""
    return axis_rotation(q, L, a, tau * c * L[a])


def sphere_flow(q, L_b, I_r, tau) -> sp.Matrix:
    """Exact flow for time tau (either sign) of |L|²/(2 I_r): the attitude turns by the body rate L_B/I_r
    held over tau, q ⊗ [sin(a) L_B/|L|, cos a], a = tau |L|/(2 I_r), L_B unchanged; sin(a)/|L| by its series
    where |a| is small (as quat_exp_step)."""
    n = sp.sqrt(L_b.dot(L_b))
    a = tau * n / (2 * I_r)
    sa = sp.Piecewise((sp.sin(a) / n, sp.Abs(a) > EXP_SERIES_BELOW), (tau / (2 * I_r) * (1 - a * a / 6), True))
    return qmul(q, sp.Matrix([sa * L_b[0], sa * L_b[1], sa * L_b[2], sp.cos(a)]))


def _check_symtop(I_b) -> None:
    """The split sums to the free rigid-body energy; |L|² Poisson-commutes with each L_a²; the intermediate
    axis minimises the score |c_a c_b|."""
    L = vec("L", 3)
    H = sum((L[i] ** 2 / (2 * I_b[i]) for i in range(3)), sp.Integer(0))
    for r in range(3):
        c = symtop_leftover(I_b, I_b[r])
        if c[r] != 0 or sp.simplify(L.dot(L) / (2 * I_b[r]) + sum(c[i] * L[i] ** 2 / 2 for i in range(3)) - H) != 0:
            raise RuntimeError(f"derive: the symmetric-top split about axis {r} does not sum to the energy")

    def bracket(F, G):  # Lie–Poisson bracket on so(3)*: {F, G} = −L · (∇F × ∇G)
        gF = sp.Matrix([sp.diff(F, x) for x in L])
        gG = sp.Matrix([sp.diff(G, x) for x in L])
        return -L.dot(gF.cross(gG))
    for a in range(3):
        if sp.expand(bracket(L.dot(L), L[a] ** 2)) != 0:
            raise RuntimeError(f"derive: |L|^2 does not commute with L_{a}^2")
    # order the moments I_hi >= I_mid >= I_lo by their inverses 1/I = s, s + x, s + x + y (x, y >= 0)
    s, x, y = sp.symbols("s x y", nonnegative=True)
    inv = {"hi": s, "mid": s + x, "lo": s + x + y}
    sc = {r: sp.expand(sp.Abs(sp.expand((inv[j] - inv[r]) * (inv[k] - inv[r]))))
          for r, (j, k) in {"hi": ("mid", "lo"), "mid": ("hi", "lo"), "lo": ("hi", "mid")}.items()}
    if sp.expand(sc["mid"] - sc["hi"]) != -x ** 2 or sp.expand(sc["mid"] - sc["lo"]) != -y ** 2:
        raise RuntimeError("derive: the intermediate axis does not minimise the symmetric-top score")


def symtop_kernels(I_b, q, L_b, tau) -> list[Kernel]:
    """symtop_score, symtop_leftover, symtop_axis_flow_{x,y,z} and sphere_flow."""
    g = "Integrator physics"
    I_r, c = scalar("I_r", positive=True), scalar("c")
    _check_symtop(I_b)
    IB = Arg("I_b", I_b, "principal moments, body frame, kg·m²", "positive")
    Q = Arg("q", q, "orientation (x, y, z, w), R_WB, unit", "unit_quaternion")
    LB = Arg("L_b", L_b, "angular momentum, body frame, kg·m²/s")
    TAU = Arg("tau", tau, "duration of the flow, s")
    IR = Arg("I_r", I_r, "the reference moment I_b[r], kg·m²", "positive")
    out = [
        Kernel("symtop_score", "Size of the symmetric-top splitting error for each reference axis r",
               r"s_r = \lvert (1/I_j - 1/I_r)(1/I_k - 1/I_r)\rvert",
               [IB], [Arg("score", symtop_score(I_b), "1/(kg·m²)², one per reference axis r = 0, 1, 2")], g,
               notes=["symtop4 takes r = argmin s_r (the first on ties): the intermediate principal axis "
                      "(proved at derivation); the splitting error is proportional to s_r."]),
        Kernel("symtop_leftover", "Coefficients left over when |L|²/(2 I_r) is split off the energy",
               r"c_i = 1/I_i - 1/I_r,\quad H = \lvert L\rvert^2/(2 I_r) + \tfrac12 \textstyle\sum_i c_i L_i^2",
               [IB, IR], [Arg("c", symtop_leftover(I_b, I_r), "1/(kg·m²), body axes (0 on the reference axis)")], g),
    ]
    for a in range(3):
        n = "xyz"[a]
        qn, Ln = symtop_axis_flow(q, list(L_b), a, c, tau)
        out.append(Kernel(f"symtop_axis_flow_{n}", f"Exact flow of ½ c L_{n}² on (q, L_B) for time τ",
                          rf"\theta = \tau c L_{n},\ q \leftarrow q \otimes [\sin\tfrac\theta2 e_{n}, \cos\tfrac\theta2],"
                          rf"\ L_B \leftarrow R_{n}(-\theta) L_B",
                          [Q, LB, Arg("c", c, "coefficient of ½ L²_axis in the energy, 1/(kg·m²)"), TAU],
                          [Arg("q_next", qn, "orientation (unit when q is)"), Arg("L_next", sp.Matrix(Ln), "kg·m²/s, body frame")], g))
    out.append(Kernel("sphere_flow", "Exact flow of |L|²/(2 I_r) on q for time τ (L_B is unchanged)",
                      r"q \leftarrow q \otimes [\tfrac{\sin a}{\lVert L\rVert} L_B, \cos a],\ a = \tau\lVert L_B\rVert/(2 I_r)",
                      [Q, LB, IR, TAU], [Arg("q_next", sphere_flow(q, L_b, I_r, tau), "orientation (unit when q is)")], g,
                      notes=["|L|² is a Casimir: this flow commutes with every axis flow, so it may be applied "
                             "before or after them within one part of the splitting."]))
    return out


def gyro_residual(I_b, omega_b, tau_b, h, w1) -> sp.Matrix:
    """g(ω⁺) = I(ω⁺ − ω) + h ω⁺ × (I ω⁺) − h τ_B (body frame, diagonal I)."""
    Iw1 = sp.Matrix([I_b[i] * w1[i] for i in range(3)])
    return sp.Matrix([I_b[i] * (w1[i] - omega_b[i]) for i in range(3)]) + h * w1.cross(Iw1) - h * tau_b


def newton_update(g: sp.Matrix, J: sp.Matrix, w1: sp.Matrix) -> tuple[sp.Matrix, sp.Matrix]:
    """(w1 − J⁻¹ g, J⁻¹ g) with J⁻¹ g by the adjugate over the determinant (cofactor expansion along the
    first row, reusing the adjugate), printed over the entries of J and g as shared subexpressions."""
    Jp, gp = mat("Jp", 3, 3), vec("gp", 3)
    A = Jp.adjugate()
    det = sum((Jp[0, c] * A[c, 0] for c in range(3)), sp.Integer(0))
    d = (A * gp) / det
    sub = {Jp[r, c]: J[r, c] for r in range(3) for c in range(3)}
    sub.update({gp[i]: g[i] for i in range(3)})
    d = d.xreplace(sub)
    return w1 - d, d


def quat_exp_step(q, omega_b, h) -> sp.Matrix:
    """q ⊗ exp(h ω_B / 2) = q ⊗ [sin(a) ω/|ω|, cos a], a = h|ω|/2; sin(a)/|ω| by its series for small a."""
    n = sp.sqrt(omega_b.dot(omega_b))
    a = h * n / 2
    sa = sp.Piecewise((sp.sin(a) / n, a > EXP_SERIES_BELOW), (h / 2 * (1 - a * a / 6), True))
    e = sp.Matrix([sa * omega_b[0], sa * omega_b[1], sa * omega_b[2], sp.cos(a)])
    return qmul(q, e)


def rkmk_dexpinv(u_b, omega_b) -> sp.Matrix:
    """u̇ = dexp⁻¹₋ᵤ(ω) truncated for order 4: ω + ½ u × ω + (1/12) u × (u × ω) (q = q₀ ⊗ exp(u/2), q̇ = ½ q ⊗ ω)."""
    uxw = u_b.cross(omega_b)
    return omega_b + uxw / 2 + u_b.cross(uxw) / 12


def saturation(command, Omega, torque_limit, speed_limit) -> sp.Matrix:
    """Clip each command to ±torque_limit; zero where |Omega_i| ≥ speed_limit and the torque would
    drive the wheel faster (u_i Omega_i > 0)."""
    out = []
    for i in range(3):
        c = command[i]
        u = sp.Piecewise((-torque_limit, c < -torque_limit), (torque_limit, c > torque_limit), (c, True))
        out.append(sp.Piecewise((0, sp.And(sp.Abs(Omega[i]) >= speed_limit, u * Omega[i] > 0)), (u, True)))
    return sp.Matrix(out)


def motor(command, Omega, torque_limit, speed_limit, cutoff) -> sp.Matrix:
    """The torque a wheel motor applies. cutoff > 0: :func:`saturation` (the old hard cut-off).
    Otherwise a DC motor's torque–speed line: the command is clipped to ±torque_limit (the stall
    torque, a current limit) and, when it drives the wheel faster (same sign as Omega_i), to the
    available torque torque_limit (1 − |Omega_i| / speed_limit) (zero at the no-load speed
    speed_limit and beyond); braking keeps the full ±torque_limit. Continuous in Omega."""
    cut = saturation(command, Omega, torque_limit, speed_limit)
    out = []
    for i in range(3):
        c, W = command[i], Omega[i]
        u = sp.Piecewise((-torque_limit, c < -torque_limit), (torque_limit, c > torque_limit), (c, True))
        a = torque_limit * (1 - sp.Abs(W) / speed_limit)   # available drive torque below the no-load speed
        line = sp.Piecewise((0, sp.And(W >= speed_limit, c > 0)), (0, sp.And(W <= -speed_limit, c < 0)),
                            (a, sp.And(W > 0, W < speed_limit, c > a)), (-a, sp.And(W < 0, W > -speed_limit, c < -a)),
                            (u, True))
        out.append(sp.Piecewise((cut[i], cutoff > 0), (line, True)))
    return sp.Matrix(out)


def _check(I_b, w, tau, h, w1) -> None:
    """Derivation-time proofs: the Jacobian is I + h([ω⁺]ₓ I − [Iω⁺]ₓ); a Strang step of a spin about
    one principal axis is the exact rotation about it."""
    def skew(v):
        return sp.Matrix([[0, -v[2], v[1]], [v[2], 0, -v[0]], [-v[1], v[0], 0]])
    I = sp.diag(*I_b)
    J = gyro_residual(I_b, w, tau, h, w1).jacobian(w1)
    if (J - (I + h * (skew(w1) * I - skew(I * w1)))).applyfunc(sp.expand) != sp.zeros(3, 3):
        raise RuntimeError("derive: the implicit-gyro Jacobian differs from I + h([w]x I - [I w]x)")
    # RKMK: with R = R0 exp([u]x) and Rᵀ Ṙ = [ω]x, ω = dexp₋ᵤ(u̇) = u̇ − ½ u × u̇ + (1/6) u × (u × u̇) − …;
    # the truncated inverse must undo it up to the dropped O(|u|³) terms
    eps, u = sp.Symbol("eps"), vec("u", 3)
    ud = rkmk_dexpinv(eps * u, w)
    back = ud - (eps * u).cross(ud) / 2 + (eps * u).cross((eps * u).cross(ud)) / 6
    for k in range(3):
        if (back - w).applyfunc(lambda e: sp.expand(e).coeff(eps, k)) != sp.zeros(3, 1):
            raise RuntimeError(f"derive: the RKMK dexp inverse is not the inverse of dexp at order eps^{k}")
    q = vec("q", 4)
    wz = sp.Matrix([0, 0, w[2]])
    qn, wn = strang_rotation(I_b, q, wz, h)
    exact = qmul(q, sp.Matrix([0, 0, sp.sin(h * w[2] / 2), sp.cos(h * w[2] / 2)]))
    if (qn - exact).applyfunc(sp.simplify) != sp.zeros(4, 1) or (wn - wz).applyfunc(sp.simplify) != sp.zeros(3, 1):
        raise RuntimeError("derive: the Strang rotation of a principal-axis spin is not the exact rotation")


def kernels() -> list[Kernel]:
    g = "Integrator physics"
    I_b, q, omega_b, tau_b = vec("I_b", 3), vec("q", 4), vec("omega_b", 3), vec("tau_b", 3)
    p_w, v_w, F_w, w1 = vec("p_w", 3), vec("v_w", 3), vec("F_w", 3), vec("omega_next", 3)
    m, h = scalar("m", positive=True), scalar("h")
    u_b, L_b, tau = vec("u_b", 3), vec("L_b", 3), scalar("tau")
    cmd, Om, tl, sl = vec("command", 3), vec("Omega", 3), scalar("torque_limit"), scalar("speed_limit")
    _check(I_b, omega_b, tau_b, h, w1)
    q_s, w_s = strang_rotation(I_b, q, omega_b, h)
    res = gyro_residual(I_b, omega_b, tau_b, h, w1)
    jac = res.jacobian(w1)
    w_new, delta = newton_update(res, jac, w1)
    v_kick = v_w + h * F_w / m
    seq = r"\,".join(rf"\Phi_{'xyz'[a]}({sp.latex(f)}h)" for a, f in STRANG)
    IB = ("I_b", I_b, "principal moments, body frame, kg·m²", "positive")
    Q = ("q", q, "orientation (x, y, z, w), R_WB, unit", "unit_quaternion")
    W = ("omega_b", omega_b, "angular velocity, body frame, rad/s")
    H = ("h", h, "time step, s", "positive")
    M = ("m", m, "mass, kg", "positive")
    TB = ("tau_b", tau_b, "torque, body frame, N·m")
    W1 = ("omega_next", w1, "current iterate of the new angular velocity ω⁺, body frame, rad/s")
    GY = [Arg(*IB), Arg(*W), Arg(*TB), Arg(*H), Arg(*W1)]
    return [
        Kernel("splitting_rotation", "Free rotation over h by Strang splitting into exact principal-axis flows",
               rf"(q, L_B) \leftarrow {seq}\,(q, I_B\omega_B),\quad \Phi_a(\tau):\ \theta = \tau L_a/I_a,\ "
               r"q \leftarrow q \otimes [\sin\tfrac\theta2 e_a, \cos\tfrac\theta2],\ L_B \leftarrow R_a(-\theta) L_B",
               [Arg(*IB), Arg(*Q), Arg(*W), Arg(*H)],
               [Arg("q_next", q_s, "orientation after h (unit when q is)"), Arg("omega_next", w_s, "rad/s, body frame")], g,
               notes=["Torque-free, it conserves the world angular momentum and |L_B| to rounding; second order."]),
        *[axis_flow_kernel(a, I_b, q, L_b, tau) for a in range(3)],
        *symtop_kernels(I_b, q, L_b, tau),
        Kernel("body_momentum", "Body angular momentum of a body with principal moments I_B", r"L_B = I_B \omega_B",
               [Arg(*IB), Arg(*W)], [Arg("L_b", sp.Matrix([I_b[i] * omega_b[i] for i in range(3)]), "kg·m²/s, body frame")], g),
        Kernel("body_rate", "Body angular velocity from the body angular momentum", r"\omega_B = I_B^{-1} L_B",
               [Arg(*IB), Arg("L_b", L_b, "angular momentum, body frame, kg·m²/s")],
               [Arg("omega_b", sp.Matrix([L_b[i] / I_b[i] for i in range(3)]), "rad/s, body frame")], g),
        Kernel("splitting_kick", "Kick of v and ω under a force and a body torque for time h (q, p fixed)",
               r"v_W \leftarrow v_W + h F_W/m,\quad \omega_B \leftarrow \omega_B + h I_B^{-1}\tau_B",
               [Arg(*M), Arg(*IB), Arg("v_w", v_w, "COM velocity, world frame, m/s"), Arg(*W),
                Arg("F_w", F_w, "force at the COM, world frame, N"), Arg(*TB), Arg(*H)],
               [Arg("v_next", v_kick, "m/s, world frame"),
                Arg("omega_next", sp.Matrix([omega_b[i] + h * tau_b[i] / I_b[i] for i in range(3)]), "rad/s, body frame")], g),
        Kernel("translation_drift", "Drift of the COM position for time h", r"p_W \leftarrow p_W + h\,v_W",
               [Arg("p_w", p_w, "COM position, world frame, m"), Arg("v_w", v_w, "COM velocity, world frame, m/s"), Arg(*H)],
               [Arg("p_next", p_w + h * v_w, "m, world frame")], g),
        Kernel("semi_implicit_translation", "Semi-implicit Euler step of the COM under a force",
               r"v_W \leftarrow v_W + h F_W/m,\quad p_W \leftarrow p_W + h\,v_W",
               [Arg(*M), Arg("p_w", p_w, "COM position, world frame, m"), Arg("v_w", v_w, "COM velocity, world frame, m/s"),
                Arg("F_w", F_w, "force at the COM, world frame, N"), Arg(*H)],
               [Arg("p_next", p_w + h * v_kick, "m, world frame"), Arg("v_next", v_kick, "m/s, world frame")], g),
        Kernel("translation_rhs", "COM translation of a free body", r"\dot p_W = v_W,\quad \dot v_W = F_W/m",
               [Arg(*M), Arg("v_w", v_w, "COM velocity, world frame, m/s"), Arg("F_w", F_w, "force at the COM, world frame, N")],
               [Arg("p_dot", v_w, "m/s, world frame"), Arg("v_dot", F_w / m, "m/s², world frame")], g),
        Kernel("implicit_gyro_residual", "Residual of the implicit gyroscopic step",
               r"g(\omega^+) = I_B(\omega^+ - \omega_B) + h\,\omega^+ \times I_B\omega^+ - h\,\tau_B",
               GY, [Arg("g", res, "N·m·s")], g),
        Kernel("implicit_gyro_jacobian", "Jacobian of the implicit-gyro residual, differentiated by SymPy",
               r"\partial g/\partial\omega^+ = I_B + h([\omega^+]_\times I_B - [I_B\omega^+]_\times)",
               [Arg(*IB), Arg(*H), Arg(*W1)], [Arg("J", jac, "kg·m², row-major")], g,
               notes=["The residual is linear in ω and τ_B, so its Jacobian depends on I_B, h and ω⁺ only."]),
        Kernel("implicit_gyro_newton", "One Newton update of the implicit gyroscopic step (adjugate solve)",
               r"\delta = (\partial g/\partial\omega^+)^{-1} g(\omega^+) = \operatorname{adj}(J)\,g/\det J,\quad \omega^+ \leftarrow \omega^+ - \delta",
               GY, [Arg("omega_new", w_new, "next iterate, rad/s, body frame"), Arg("delta", delta, "the Newton step, rad/s")], g,
               notes=["Solved to rounding, a torque-free step never gains energy: E − E⁺ = ½(ω − ω⁺)ᵀI(ω − ω⁺) ≥ 0."]),
        Kernel("quat_exp_step", "Attitude step by the exponential map of a body angular velocity held over h",
               r"q \leftarrow q \otimes \left[\tfrac{\sin a}{\lVert\omega\rVert}\omega_B,\ \cos a\right],\ a = \tfrac h2\lVert\omega_B\rVert"
               r"\quad\left(\tfrac{\sin a}{\lVert\omega\rVert} \approx \tfrac h2(1 - \tfrac{a^2}{6})\ \text{for}\ a \le 10^{-8}\right)",
               [Arg(*Q), Arg(*W), Arg(*H)], [Arg("q_next", quat_exp_step(q, omega_b, h), "orientation (unit when q is)")], g),
        Kernel("rkmk_dexpinv", "Rate of the attitude's exponential coordinates (RKMK4, truncated dexp inverse)",
               r"\dot u_B = \omega_B + \tfrac12\,u_B\times\omega_B + \tfrac1{12}\,u_B\times(u_B\times\omega_B)",
               [Arg("u_b", u_b, "rotation vector of the attitude relative to the step's start, body frame, rad"), Arg(*W)],
               [Arg("u_dot", rkmk_dexpinv(u_b, omega_b), "rad/s, body frame")], g,
               notes=["q = q₀ ⊗ exp(u/2) (quat_exp_step with h = 1); the dexp inverse series is cut after its "
                      "u² term, exact to O(|u|³ |ω|), which keeps RK4's order 4 since u = O(h) within a step."]),
        Kernel("wheel_saturation", "Motor torques actually applied: clipped, and cut off beyond the speed limit",
               r"u_i = \begin{cases} 0 & |\Omega_i| \ge \Omega_{max},\ \bar u_i \Omega_i > 0 \\ \bar u_i & \text{else}\end{cases},"
               r"\quad \bar u_i = \min(\max(c_i, -u_{max}), u_{max})",
               [Arg("command", cmd, "commanded motor torques, N·m"), Arg("Omega", Om, "wheel rates relative to the body, rad/s"),
                Arg("torque_limit", tl, "N·m", "positive"), Arg("speed_limit", sl, "rad/s", "positive")],
               [Arg("u", saturation(cmd, Om, tl, sl), "applied motor torques, N·m")], g),
        Kernel("wheel_motor", "Motor torques actually applied: a torque–speed line from the stall torque to the no-load "
               "speed (cutoff = 0), or the hard cut-off of wheel_saturation (cutoff = 1)",
               r"u_i = \begin{cases} \mathrm{sign}(\Omega_i)\,a_i & \bar u_i \Omega_i > 0,\ |\bar u_i| > a_i \\ \bar u_i & "
               r"\text{else}\end{cases},\quad a_i = u_{max}\max(0, 1 - |\Omega_i|/\Omega_{0}),\quad "
               r"\bar u_i = \min(\max(c_i, -u_{max}), u_{max})",
               [Arg("command", cmd, "commanded motor torques, N·m"), Arg("Omega", Om, "wheel rates relative to the body, rad/s"),
                Arg("torque_limit", tl, "stall torque (current limit), N·m", "positive"),
                Arg("speed_limit", sl, "no-load speed, rad/s", "positive"),
                Arg("cutoff", scalar("cutoff"), "1: hard cut-off at speed_limit instead of the line; 0: the line")],
               [Arg("u", motor(cmd, Om, tl, sl, scalar("cutoff")), "applied motor torques, N·m")], g,
               notes=["Viscous wheel friction is the wheel damping c_w of wheels<N>_body_rhs (−c_w Ω on the wheel)."]),
    ]
