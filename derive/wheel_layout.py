"""Reaction wheels on arbitrary spin axes: N ≥ 1 wheels, axis matrix A_b (3×N, unit columns, body
frame) — the one wheel model; the chapter's body-axis cube (derive/wheel_cube.py, three wheels on body
x, y, z) is A_b = 1, proved here at derive time.

Rotational state: q (4) orientation R_WB (x, y, z, w); omega_b (3) body angular velocity, body
frame, rad/s; Omega (N) wheel spin rates relative to the body about their axes, rad/s.

Parameters (SI): I_p — inertia of the body (wheels counted as locked) about the pivot P, body frame,
kg·m², symmetric; A_b — wheel spin axes as columns, body frame; J — wheel axial inertias, kg·m²; r_b
— P→COM offset, body frame, m; F_w, tau_w — total force at the COM and torque about it from the
scene's effects, world frame (N, N·m); u — motor torques on the wheels, N·m (the body receives
−A_b u); c_w — wheel bearing damping, N·m·s/rad.

Equations (derived once, for any N; printed for the counts in WHEEL_COUNTS):
  H = I_p ω + A_b J Ω,   Ḣ + ω × H = τ_P,   J_i (a_iᵀ ω̇ + Ω̇_i) = u_i − c_w Ω_i, so
  (I_p − A_b J A_bᵀ) ω̇ = τ_P − ω × H − A_b (u − c_w Ω),   Ω̇ = J⁻¹(u − c_w Ω) − A_bᵀ ω̇.
The wheel momentum h_w = J (A_bᵀ ω + Ω) (N components, each about its wheel's axis).
"""
from __future__ import annotations

from typing import cast

import sympy as sp

from .integrator_physics import motor
from .kernel import Arg, Kernel, mat, scalar, vec
from .layout import WCOEF, WHEELS_MAX, on_axes
from .quaternion import pure, qmul, rotation_matrix
from .wheel_cube import solve3, sym3, torque_about_pivot, wheel_rhs

WHEEL_COUNTS = (3, 4)   # printed kernels (each count adds derive and compile time: N = 1…6 tripled derive): wheels<N>_body_rhs, wheels<N>_momentum, wheels<N>_motor


def layout_rhs(q, w, Om, I_p, A, J, r_b, F_w, tau_w, u, c_w):
    """(q̇, ω̇, Ω̇) of a body carrying N wheels on the columns of A (3×N); J, Om, u are N-vectors."""
    n = A.shape[1]
    Jd = sp.diag(*J)
    H = I_p * w + A * Jd * Om
    rhs = torque_about_pivot(q, r_b, F_w, tau_w) - w.cross(H) - A * (u - c_w * Om)
    w_dot = solve3(I_p - A * Jd * A.T, rhs)
    Om_dot = sp.Matrix([(u[i] - c_w * Om[i]) / J[i] for i in range(n)]) - A.T * w_dot
    return qmul(q, pure(w)) / 2, w_dot, Om_dot


def coefficient_where(I_p, A, J) -> tuple[sp.Matrix, list]:
    """The inertia-only coefficients of the N-wheel equations, k_w = [M⁻¹ (9, row-major), 1/J (N)] with
    M = I_p − A_b J A_bᵀ, as (k_w symbols, where): M (6 named entries), its cofactors (6) and 1/det M
    are named subexpressions, so the code forms M and solves by the adjugate (a fully expanded adjugate,
    a polynomial in A_b, J and I_p, prints ~1400 operations for N = 4). They depend on the model row
    only: the step loops compute them once per body and call (wheels<N>_coefficients) and the
    right-hand side (wheels<N>_body_rhs_c) then divides by nothing, like the Euler coefficients c_b."""
    n = A.shape[1]
    Mx = I_p - A * sp.diag(*J) * A.T
    M, C = sym3("M"), sym3("C")
    pairs = [(i, j) for i in range(3) for j in range(i, 3)]
    cof = {(0, 0): M[1, 1] * M[2, 2] - M[1, 2] ** 2, (0, 1): M[0, 2] * M[1, 2] - M[0, 1] * M[2, 2],
           (0, 2): M[0, 1] * M[1, 2] - M[0, 2] * M[1, 1], (1, 1): M[0, 0] * M[2, 2] - M[0, 2] ** 2,
           (1, 2): M[0, 1] * M[0, 2] - M[0, 0] * M[1, 2], (2, 2): M[0, 0] * M[1, 1] - M[0, 1] ** 2}
    inv = sp.Symbol("inv_det_M", real=True)
    k_w = vec("k_w", 9 + n)
    where = ([(M[i, j], Mx[i, j]) for i, j in pairs] + [(C[i, j], cof[(i, j)]) for i, j in pairs]
             + [(inv, 1 / (M[0, 0] * C[0, 0] + M[0, 1] * C[0, 1] + M[0, 2] * C[0, 2]))]
             + [(k_w[3 * i + j], C[i, j] * inv) for i in range(3) for j in range(3)]
             + [(k_w[9 + i], 1 / J[i]) for i in range(n)])
    return k_w, where


def layout_rhs_c(q, w, Om, I_p, A, J, k_w, r_b, F_w, tau_w, u, c_w) -> tuple[tuple, list]:
    """layout_rhs on the coefficients k_w = [M⁻¹ (9), 1/J (N)] (coefficient_where): ((q̇, ω̇, Ω̇), where). The
    wheel sums are named subexpressions (J Ω, u − c_w Ω, their images A_b J Ω and A_b (u − c_w Ω), I_p ω,
    H, ω × H), so the printed sums are short and independent: the step loops' critical path (one RK4 stage
    after another) stays short for any N."""
    n = A.shape[1]
    jo, g = vec("JOmega", n), vec("g_w", n)
    hw, gw, Iw, H, cr = vec("h_A", 3), vec("g_A", 3), vec("I_omega", 3), vec("H_b", 3), vec("wxH", 3)
    where = ([(jo[i], J[i] * Om[i]) for i in range(n)] + [(g[i], u[i] - c_w * Om[i]) for i in range(n)]
             + [(hw[k], sum((A[k, i] * jo[i] for i in range(n)), sp.Integer(0))) for k in range(3)]
             + [(Iw[k], (I_p * w)[k]) for k in range(3)] + [(H[k], Iw[k] + hw[k]) for k in range(3)]
             + [(cr[k], w.cross(H)[k]) for k in range(3)]
             + [(gw[k], sum((A[k, i] * g[i] for i in range(n)), sp.Integer(0))) for k in range(3)])
    Minv = sp.Matrix(3, 3, list(k_w[:9]))
    rhs = torque_about_pivot(q, r_b, F_w, tau_w) - cr - gw
    w_dot = Minv * rhs
    Om_dot = sp.Matrix([g[i] * k_w[9 + i] for i in range(n)]) - A.T * w_dot
    return (qmul(q, pure(w)) / 2, w_dot, Om_dot), where


def layout_momentum(q, w, Om, I_p, A, J):
    """(L_body_w, L_wheels_w, h_w): world momenta of the body (wheels locked, minus their spin) and of
    the wheels' spin about P; h_w = J (Aᵀω + Ω) the wheels' axial momenta (N)."""
    R, Jd = rotation_matrix(q), sp.diag(*J)
    h = Jd * (A.T * w + Om)
    return R * ((I_p - A * Jd * A.T) * w), R * (A * h), h


def layout_total_momentum(q, w, Om, I_p, A, J):
    """L_w = R (I_p ω + A J Ω): the world momentum of body and wheels about P in one sum, layout_momentum's
    L_body_w + L_wheels_w with the A J Aᵀ ω terms cancelled (_check proves it)."""
    return rotation_matrix(q) * (I_p * w + A * sp.diag(*J) * Om)


def motor_n(command, Omega, torque_limit, speed_limit, cutoff) -> sp.Matrix:
    """integrator_physics.motor applied wheel by wheel (each wheel's line depends on its own Ω_i only)."""
    z = sp.Integer(0)
    return sp.Matrix([motor(sp.Matrix([command[i], z, z]), sp.Matrix([Omega[i], z, z]), torque_limit, speed_limit, cutoff)[0]
                      for i in range(len(command))])


def _random_rationals(rng, rows: int, cols: int = 1) -> sp.Matrix:
    return sp.Matrix(rows, cols, lambda i, j: sp.Rational(rng.randint(-40, 40), rng.randint(1, 9)))


def _check() -> None:
    """A_b = 1 reproduces the body-axis cube; without external torque H is conserved for any axes; a
    padded wheel (zero axis, J = 1, Ω = u = 0) leaves the other equations as they are and keeps Ω̇ = 0.
    The equations are evaluated in exact rational arithmetic at random rational inputs (three wheels
    on general axes, a general symmetric I_p): the identities hold exactly there, and a wrong term
    would show (a nonzero rational function vanishes at a random point with negligible probability);
    far cheaper than sympy.simplify on the symbolic 3×3 solve."""
    import random

    rng = random.Random(13)
    for _ in range(3):
        q, w, r_b, F, T = (_random_rationals(rng, k) for k in (4, 3, 3, 3, 3))
        Om, u, J = _random_rationals(rng, 3), _random_rationals(rng, 3), _random_rationals(rng, 3).applyfunc(abs) / 100 + sp.ones(3, 1) / 50
        S = _random_rationals(rng, 3, 3)
        I_p, c = S * S.T + 10 * sp.eye(3), sp.Rational(rng.randint(0, 9), 7)
        a = layout_rhs(q, w, Om, I_p, sp.eye(3), J, r_b, F, T, u, c)
        b = wheel_rhs(q, w, Om, I_p, J, r_b, F, T, u, c)
        if any(x != y for x, y in zip(a, b)):
            raise RuntimeError("derive: the N-wheel equations with A_b = 1 differ from the body-axis cube")
        A = _random_rationals(rng, 3, 3)
        _, w_dot, Om_dot = layout_rhs(q, w, Om, I_p, A, J, r_b, sp.zeros(3, 1), sp.zeros(3, 1), u, c)
        H = I_p * w + A * sp.diag(*J) * Om
        if I_p * w_dot + A * sp.diag(*J) * Om_dot + w.cross(H) != sp.zeros(3, 1):
            raise RuntimeError("derive: the N-wheel equations do not conserve angular momentum")
        Lb, Lw, _ = layout_momentum(q, w, Om, I_p, A, J)
        if layout_total_momentum(q, w, Om, I_p, A, J) != Lb + Lw:
            raise RuntimeError("derive: the total wheel momentum differs from body + wheels")
        # a padded wheel (zero axis, J = 1, Omega = u = 0) changes nothing and stays at rest: one printed
        # N-wheel kernel can step any layout of fewer wheels (the plan for N-axis wheels inside Sim, issue 13)
        pad = layout_rhs(q, w, Om.col_join(sp.zeros(1, 1)), I_p, A.row_join(sp.zeros(3, 1)), J.col_join(sp.ones(1, 1)),
                         r_b, F, T, u.col_join(sp.zeros(1, 1)), c)
        ref = layout_rhs(q, w, Om, I_p, A, J, r_b, F, T, u, c)
        if pad[0] != ref[0] or pad[1] != ref[1] or list(pad[2]) != list(ref[2]) + [0]:
            raise RuntimeError("derive: a padded wheel (zero axis, J = 1, at rest, no torque) changes the N-wheel equations")
        # the form the kernels print (named M, cofactors, 1/det M, coefficients k_w) is the same function
        for A_n in (A, A.row_join(sp.zeros(3, 1)), on_axes(4)):
            n = A_n.shape[1]
            J_n, Om_n, u_n = (v.col_join(sp.Matrix(n - 3, 1, [z] * (n - 3))) for v, z in ((J, 1), (Om, 0), (u, 0)))
            k_w, where = coefficient_where(I_p, A_n, J_n)
            out, rhs_where = layout_rhs_c(q, w, Om_n, I_p, A_n, J_n, k_w, r_b, F, T, u_n, c)
            val: dict = {}
            for sym, e in where + rhs_where:
                val[sym] = e.xreplace(val)
            got = [m.xreplace(val) for m in out]
            if got != list(layout_rhs(q, w, Om_n, I_p, A_n, J_n, r_b, F, T, u_n, c)):
                raise RuntimeError("derive: the printed N-wheel kernel (named M, cofactors, coefficients) differs from "
                                   "the N-wheel equations")


def kernels_for(n: int) -> list[Kernel]:
    """The three kernels of an n-wheel layout."""
    g = "Pivoted bodies and reaction wheels"
    q, w, Om = vec("q", 4), vec("omega_b", 3), vec("Omega", n)
    A, J, u = mat("A_b", 3, n), vec("J", n), vec("u", n)
    r_b, F_w, tau_w, I_p, c_w = vec("r_b", 3), vec("F_w", 3), vec("tau_w", 3), sym3("I_p"), scalar("c_w")
    k_w, coef_where = coefficient_where(I_p, A, J)
    (q_dot, w_dot, Om_dot), rhs_where = layout_rhs_c(q, w, Om, I_p, A, J, k_w, r_b, F_w, tau_w, u, c_w)
    where = coef_where + rhs_where
    Lb, Lw, h = layout_momentum(q, w, Om, I_p, A, J)
    Q = Arg("q", q, "orientation (x, y, z, w), R_WB", "unit_quaternion")
    W = Arg("omega_b", w, "angular velocity, body frame, rad/s")
    OM = Arg("Omega", Om, f"wheel rates relative to the body about their axes ({n}), rad/s")
    IP = Arg("I_p", I_p, "inertia about the pivot (wheels locked), body frame, kg·m², symmetric row-major", "inertia_sym")
    AB = Arg("A_b", A, f"wheel spin axes as columns (3×{n}, unit columns), body frame, row-major", "unit_vector")
    JJ = Arg("J", J, f"wheel axial inertias ({n}), kg·m²", "positive")
    cmd, tl, sl, cut = vec("command", n), scalar("torque_limit"), scalar("speed_limit"), scalar("cutoff")
    note = [f"{n} wheels; I_p and I_p − A_b J A_bᵀ must be positive definite (the runtime validates them).",
            "With A_b = 1 (three wheels on the body x, y, z axes; any further slot padded: zero axis, J = 1, at rest) "
            "these are the chapter's reaction-wheel cube, (I_P − J)ω̇ = τ_P − ω × (I_Pω + JΩ) − u + c_wΩ, "
            "Ω̇ = J⁻¹(u − c_wΩ) − ω̇ (derive/wheel_cube.py): proved equal at derive time. Every wheeled body "
            "in a Sim is stepped by this model (the N = WHEELS_MAX print)."]
    loads = [Arg("r_b", r_b, "pivot → COM, body frame, m", "small"), Arg("F_w", F_w, "total force at the COM, world frame, N"),
             Arg("tau_w", tau_w, "total torque about the COM, world frame, N·m"),
             Arg("u", u, "motor torques on the wheels (body gets −A_b u), N·m"),
             Arg("c_w", c_w, "wheel damping, N·m·s/rad", "positive")]
    rates = [Arg("q_dot", q_dot, "1/s"), Arg("omega_dot_b", w_dot, "rad/s², body frame"), Arg("Omega_dot", Om_dot, "rad/s²")]
    KW = Arg("k_w", k_w, f"wheel-model coefficients [M⁻¹ (3×3 row-major, M = I_p − A_b J A_bᵀ, body frame, 1/(kg·m²)), "
             f"1/J ({n}, 1/(kg·m²))], from wheels{n}_coefficients")
    # the default layout's right-hand side: the same equations with A_b = [I | 0] substituted (the A_b sums fold away)
    axes = dict(zip(A, on_axes(n)))
    axes_where = [(s, e.xreplace(axes)) for s, e in rhs_where]
    axes_rates = [Arg(a.name, cast(sp.Matrix, a.value).xreplace(axes), a.doc) for a in rates]   # (Arg.value: object)
    coefficient_kernels = [] if n != WHEELS_MAX else [
        Kernel(f"wheels{n}_coefficients", f"The inertia-only coefficients of the {n}-wheel equations, computed once per body and call",
               r"k_w = [(I_P - A J A^T)^{-1},\ J^{-1}]",
               [IP, AB, JJ], [Arg("k_w", sp.Matrix([e for _, e in coef_where[-len(k_w):]]), KW.doc)], g,
               notes=[f"The step loops call it once per body and call; wheels{n}_body_rhs_c then divides by nothing.",
                      f"Printed from the same named subexpressions as wheels{n}_body_rhs, so its k_w is bitwise that kernel's."],
               where=coef_where[:-len(k_w)]),
        Kernel(f"wheels{n}_body_rhs_c", f"wheels{n}_body_rhs on the coefficients k_w (no division)",
               r"\dot\omega = M^{-1}(\tau_P - \omega\times(I_P\omega + A J\Omega) - A(u - c_w\Omega)),\ "
               r"\dot\Omega = J^{-1}(u - c_w\Omega) - A^T\dot\omega",
               [Q, W, OM, IP, AB, JJ, KW, *loads], rates, g, where=rhs_where,
               notes=[f"Bitwise wheels{n}_body_rhs, given k_w = wheels{n}_coefficients(I_p, A_b, J) (the same printed arithmetic)."]),
        Kernel(f"wheels{n}_on_axes_rhs_c", f"wheels{n}_body_rhs_c of the default layout, A_b = [I | 0] substituted",
               r"\dot\omega = M^{-1}(\tau_P - \omega\times(I_P\omega + J\Omega) - (u - c_w\Omega)),\ "
               r"\dot\Omega = J^{-1}(u - c_w\Omega) - [I | 0]^T\dot\omega",
               [Q, W, OM, IP, JJ, KW, *loads], axes_rates, g, where=axes_where,
               notes=[f"wheels{n}_body_rhs_c at A_b = [I | 0] (three wheels on the body axes, the other slots padded): "
                      "the same expressions with the axes substituted, so the products by 1 and the terms times 0 "
                      f"fold away; equal to wheels{n}_body_rhs_c up to the sign of a zero (x + 0·y is x)."]),
        Kernel(f"wheels{n}_total_momentum", f"World angular momentum about the pivot of a body with {n} wheels and its wheels, one sum",
               r"L = R (I_P\omega + A J \Omega)", [Q, W, OM, IP, AB, JJ],
               [Arg("L_w", layout_total_momentum(q, w, Om, I_p, A, J), "kg·m²/s, world")], g,
               notes=[f"L_body_w + L_wheels_w of wheels{n}_momentum (proved equal at derive time) at a third of its "
                      "arithmetic: the growth check's |L| of a wheeled body (C screen and NumPy check alike)."]),
    ]
    return [
        Kernel(f"wheels{n}_body_rhs", f"Body with {n} reaction wheels on arbitrary axes rotating about a pivot",
               r"(I_P - A J A^T)\dot\omega = \tau_P - \omega\times(I_P\omega + A J\Omega) - A(u - c_w\Omega),\quad "
               r"\dot\Omega = J^{-1}(u - c_w\Omega) - A^T\dot\omega,\quad \dot q = \tfrac12 q\otimes[\omega,0]",
               [Q, W, OM, IP, AB, JJ, *loads], rates, g, note, where=where),
        *coefficient_kernels,
        Kernel(f"wheels{n}_momentum", f"World angular momentum about the pivot of a body with {n} wheels, and the wheels' axial momenta",
               r"L_{body} = R (I_P - A J A^T)\omega,\quad L_{wheels} = R A h_w,\quad h_w = J(A^T\omega + \Omega)",
               [Q, W, OM, IP, AB, JJ],
               [Arg("L_body_w", Lb, "kg·m²/s, world"), Arg("L_wheels_w", Lw, "kg·m²/s, world"),
                Arg("h_w", h, "axial momentum of each wheel, kg·m²/s")], g),
        Kernel(f"wheels{n}_motor", f"Motor torques actually applied on {n} wheels (the wheel_motor line, per wheel)",
               r"u_i = \mathrm{wheel\_motor}(c_i, \Omega_i)",
               [Arg("command", cmd, "commanded motor torques, N·m"), Arg("Omega", Om, "wheel rates relative to the body, rad/s"),
                Arg("torque_limit", tl, "stall torque (current limit), N·m", "positive"),
                Arg("speed_limit", sl, "no-load speed, rad/s", "positive"),
                Arg("cutoff", cut, "1: hard cut-off at speed_limit instead of the line; 0: the line")],
               [Arg("u", motor_n(cmd, Om, tl, sl, cut), "applied motor torques, N·m")], g),
    ]


def kernels() -> list[Kernel]:
    if WCOEF.size != 9 + WHEELS_MAX or WCOEF.slice("J_inv") != slice(9, 9 + WHEELS_MAX):
        raise RuntimeError("derive: the WCOEF layout (derive/layout.py) must be [M⁻¹ (9), 1/J (WHEELS_MAX)], "
                           "the k_w of wheels<WHEELS_MAX>_coefficients")
    if WHEELS_MAX not in WHEEL_COUNTS:
        raise RuntimeError(f"derive: Sim steps wheel layouts with the wheels{WHEELS_MAX} kernels (derive/layout.py "
                           f"WHEELS_MAX); WHEEL_COUNTS {WHEEL_COUNTS} must include it")
    _check()
    return [k for n in WHEEL_COUNTS for k in kernels_for(n)]
