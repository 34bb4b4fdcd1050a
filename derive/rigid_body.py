"""Rigid-body dynamics: Euler's rotation equations, the state right-hand side, energy, momentum.

State x (13 numbers), the layout every integrator and backend uses (declared in derive/layout.py,
printed as generated/layout.h and layout.py): p_w (3) position of the centre of mass, world frame,
m; q (4) orientation R_WB as (x, y, z, w), unit; v_w (3) velocity of the centre of mass, world
frame, m/s; omega_b (3) angular velocity, body frame, rad/s.
Inertia is diagonal in the body frame (principal axes): I_b = (I_x, I_y, I_z), kg·m².
"""
from __future__ import annotations

import sympy as sp

from .kernel import Arg, Kernel, scalar, vec
from .layout import STATE as X
from .quaternion import quat_rate_body, rotation_matrix

STATE = "state (p_w[3] m, q[4] (x,y,z,w), v_w[3] m/s, omega_b[3] rad/s)"


def euler_rhs(I_b: sp.Matrix, w: sp.Matrix, tau_b) -> sp.Matrix:
    """ω̇_b from I ω̇ + ω × (I ω) = τ, written per axis as I_x ω̇_x = (I_y − I_z) ω_y ω_z + τ_x
    (and cyclic) so that the gyroscopic term is exactly zero for isotropic inertia."""
    out = []
    for i in range(3):
        j, k = (i + 1) % 3, (i + 2) % 3
        out.append(((I_b[j] - I_b[k]) * w[j] * w[k] + tau_b[i]) / I_b[i])
    return sp.Matrix(out)


def _check_euler(I_b, w, tau):
    """Proof that the per-axis form is I⁻¹(τ − ω × Iω)."""
    I = sp.diag(*I_b)
    ref = I.inv() * (tau - w.cross(I * w))
    if (ref - euler_rhs(I_b, w, tau)).applyfunc(sp.simplify) != sp.zeros(3, 1):
        raise RuntimeError("derive: per-axis Euler equations differ from I⁻¹(τ − ω × Iω)")


def kernels() -> list[Kernel]:
    g = "Rigid-body dynamics"
    x = vec("x", X.size)
    m = scalar("m", positive=True)
    I_b, F_w, tau_w, tau_b = vec("I_b", 3), vec("F_w", 3), vec("tau_w", 3), vec("tau_b", 3)
    omega_b, v_w, q, vec_w = vec("omega_b", 3), vec("v_w", 3), vec("q", 4), vec("v", 3)
    _check_euler(I_b, omega_b, tau_b)
    xq, xv, xw = X.part(x, "q"), X.part(x, "v_w"), X.part(x, "omega_b")
    R = rotation_matrix(xq)
    qdot = quat_rate_body(xq, xw)
    full = X.assemble(p_w=xv, q=qdot, v_w=F_w / m, omega_b=euler_rhs(I_b, xw, R.T * tau_w))
    free = X.assemble(p_w=xv, q=qdot, v_w=sp.zeros(3, 1), omega_b=euler_rhs(I_b, xw, sp.zeros(3, 1)))
    Rq = rotation_matrix(q)
    inv_apply = Rq * sp.diag(*[1 / I_b[i] for i in range(3)]) * Rq.T * vec_w
    ke = (m * v_w.dot(v_w) + sum(I_b[i] * omega_b[i] ** 2 for i in range(3))) / 2
    IB = ("I_b", I_b, "principal moments, body frame, kg·m²", "positive")
    QU = ("q", q, "orientation (x, y, z, w), R_WB, unit", "unit_quaternion")
    return [
        Kernel("euler_equations", "Euler's rotation equations with external torque, body frame",
               r"I_B \dot\omega_B + \omega_B \times (I_B \omega_B) = \tau_B",
               [Arg(*IB), Arg("omega_b", omega_b, "angular velocity, body frame, rad/s"), Arg("tau_b", tau_b, "torque, body frame, N·m")],
               [Arg("omega_dot_b", euler_rhs(I_b, omega_b, tau_b), "angular acceleration, body frame, rad/s²")], g),
        Kernel("rigid_body_rhs", "State derivative under a world force at the COM and a world torque",
               r"\dot p_W = v_W,\ \dot q = \tfrac12 q \otimes [\omega_B,0],\ \dot v_W = F_W/m,\ \dot\omega_B = I_B^{-1}(R^T\tau_W - \omega_B \times I_B\omega_B)",
               [Arg("x", x, STATE, "real"), Arg("m", m, "mass, kg", "positive"), Arg(*IB),
                Arg("F_w", F_w, "total force at the COM, world frame, N"), Arg("tau_w", tau_w, "total torque about the COM, world frame, N·m")],
               [Arg("x_dot", full, "d/dt of the state")], g,
               notes=["q need not be exactly unit: the body-form rate is used as is; R(q) assumes unit q."]),
        Kernel("rigid_body_rhs_free", "State derivative of a torque-free, force-free body",
               r"\dot p_W = v_W,\ \dot q = \tfrac12 q \otimes [\omega_B,0],\ \dot v_W = 0,\ I_x\dot\omega_x = (I_y - I_z)\omega_y\omega_z\ \text{(cyclic)}",
               [Arg("x", x, STATE, "real"), Arg(*IB)], [Arg("x_dot", free, "d/dt of the state")], g),
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
               [Arg("x", x, STATE, "real"), Arg(*IB), Arg("tau_w", tau_w, "total torque about the COM, world frame, N·m")],
               [Arg("x_dot", full.subs({F_w[i]: 0 for i in range(3)}), "d/dt of the state")], g,
               notes=["Bitwise rigid_body_rhs with F_W = 0 (its v rate F_W/m is then exactly +0)."]),
    ]
