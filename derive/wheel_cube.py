"""A rigid body rotating about a pivot P (a world-anchored spherical joint, or its own COM when
free), optionally carrying three reaction wheels on its body axes — the chapter's reaction-wheel cube.

Printed: pivot_body_rhs (a joint, no wheels) and pivot_kinematics. The body-axis wheel equations
(wheel_rhs) are the chapter's; they are not printed: every wheeled body is stepped by the N-wheel
model of derive/wheel_layout.py, which proves at derive time that with A_b = 1 it is exactly these
equations (and that they conserve H, _check here).

Rotational state: q (4) orientation R_WB (x, y, z, w); omega_b (3) body angular velocity, body
frame, rad/s; Omega (3) wheel spin rates relative to the body about body x, y, z, rad/s.

Parameters (SI): I_p — inertia of the body (wheels counted as locked) about P, body frame, kg·m²,
symmetric 3×3 row-major (the upper triangle is read); J — wheel spin inertias, kg·m²; r_b — P→COM
offset, body frame, m; F_w — total force at the COM and tau_w — total torque about the COM, both
world frame (N, N·m), from the scene's effects; u — motor torques on the wheels, N·m (the body
receives −u); c_w — wheel bearing damping, N·m·s/rad. The joint's reaction force passes through P
and does no work.

Equations: H = I_p ω + J Ω;  Ḣ + ω × H = τ_P = Rᵀ(tau_w + (R r_b) × F_w);  J(ω̇ + Ω̇) = u − c_w Ω, so
(I_p − J) ω̇ = τ_P − ω × (I_p ω + J Ω) − u + c_w Ω,   Ω̇ = J⁻¹(u − c_w Ω) − ω̇.
"""
from __future__ import annotations

import sympy as sp

from .kernel import Arg, Kernel, scalar, vec
from .quaternion import pure, qmul, rotation_matrix


def sym3(name: str) -> sp.Matrix:
    """Symmetric 3×3 of symbols; entries (i, j) and (j, i) share the symbol name_{min}{max}."""
    return sp.Matrix(3, 3, lambda i, j: sp.Symbol(f"{name}_{min(i, j)}{max(i, j)}", real=True))


def solve3(A: sp.Matrix, b: sp.Matrix) -> sp.Matrix:
    """A⁻¹ b by the adjugate (A symmetric positive definite at run time)."""
    return A.adjugate() * b / A.det()


def torque_about_pivot(q, r_b, F_w, tau_w) -> sp.Matrix:
    """τ_P in the body frame: Rᵀ(τ_W + (R r_B) × F_W) = Rᵀ τ_W + r_B × Rᵀ F_W."""
    R = rotation_matrix(q)
    return R.T * tau_w + r_b.cross(R.T * F_w)


def wheel_rhs(q, w, Om, I_p, J, r_b, F_w, tau_w, u, c_w):
    Jd = sp.diag(*J)
    rhs = torque_about_pivot(q, r_b, F_w, tau_w) - w.cross(I_p * w + Jd * Om) - u + c_w * Om
    w_dot = solve3(I_p - Jd, rhs)
    Om_dot = sp.Matrix([(u[i] - c_w * Om[i]) / J[i] for i in range(3)]) - w_dot
    return qmul(q, pure(w)) / 2, w_dot, Om_dot


def _check() -> None:
    """Without external torque, the total angular momentum is conserved: Ḣ + ω × H = 0."""
    q, w, Om, J, r_b, u = vec("q", 4), vec("w", 3), vec("W", 3), vec("J", 3), vec("r", 3), vec("u", 3)
    I_p = sp.diag(*vec("I", 3))
    _, w_dot, Om_dot = wheel_rhs(q, w, Om, I_p, J, r_b, sp.zeros(3, 1), sp.zeros(3, 1), u, scalar("c"))
    H = I_p * w + sp.diag(*J) * Om
    if (I_p * w_dot + sp.diag(*J) * Om_dot + w.cross(H)).applyfunc(sp.simplify) != sp.zeros(3, 1):
        raise RuntimeError("derive: the wheel equations do not conserve angular momentum")


def kernels() -> list[Kernel]:
    _check()
    g = "Pivoted bodies and reaction wheels"
    q, w = vec("q", 4), vec("omega_b", 3)
    r_b, F_w, tau_w = vec("r_b", 3), vec("F_w", 3), vec("tau_w", 3)
    I_p = sym3("I_p")
    R = rotation_matrix(q)
    Q = ("q", q, "orientation (x, y, z, w), R_WB", "unit_quaternion")
    W = ("omega_b", w, "angular velocity, body frame, rad/s")
    IP = ("I_p", I_p, "inertia about the pivot (wheels locked), body frame, kg·m², symmetric row-major", "inertia_sym")
    RB = ("r_b", r_b, "pivot → COM, body frame, m", "small")
    FT = [Arg("F_w", F_w, "total force at the COM, world frame, N"), Arg("tau_w", tau_w, "total torque about the COM, world frame, N·m")]
    note = ["I_p must be positive definite (the runtime validates it)."]
    return [
        Kernel("pivot_body_rhs", "Rotation about a world-anchored spherical joint (no wheels)",
               r"I_P\dot\omega = \tau_P - \omega\times I_P\omega,\quad \tau_P = R^T\tau_W + r_B\times R^T F_W,\quad \dot q = \tfrac12 q\otimes[\omega,0]",
               [Arg(*Q), Arg(*W), Arg(*IP), Arg(*RB), *FT],
               [Arg("q_dot", qmul(q, pure(w)) / 2, "1/s"),
                Arg("omega_dot_b", solve3(I_p, torque_about_pivot(q, r_b, F_w, tau_w) - w.cross(I_p * w)), "rad/s², body frame")], g, note),
        Kernel("pivot_kinematics", "COM position and velocity of a body on a spherical joint",
               r"p_W = a_W + R r_B,\quad v_W = R(\omega_B \times r_B)",
               [Arg(*Q), Arg(*W), Arg("anchor_w", vec("anchor_w", 3), "joint anchor, world frame, m"), Arg(*RB)],
               [Arg("p_w", vec("anchor_w", 3) + R * r_b, "COM position, world, m"), Arg("v_w", R * w.cross(r_b), "COM velocity, world, m/s")], g),
    ]
