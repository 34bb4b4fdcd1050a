"""Small measures the runtime needs beside the equations of motion, written once here and printed for every
backend (issue 29, "the last hand physics goes to derive/"):

* the inverse of the attitude-error chart (quat_error_chart in derive/quaternion.py): the orientation at
  attitude error dtheta about a reference, q = q_ref ⊗ [dtheta/2, sqrt(1 − |dtheta/2|²)];
* the inertia of a wheeled body with its wheels free, I − A J Aᵀ (the WHEELS_MAX-slot layout);
* the quaternion scaled to unit length without overflow or underflow (divided by max|q_i| first);
* the box of uniform density with a given mass and principal moments (what the viewer draws);
* the velocity of a point moving with a rigid body, v = v_COM + ω × r (the momentum lab's particles).

Quaternions (x, y, z, w), scalar last; SI units.
"""
from __future__ import annotations

import sympy as sp

from .kernel import Arg, Kernel, mat, scalar, vec
from .layout import WHEELS_MAX
from .quaternion import qconj, qmul
from .wheel_cube import sym3

Q = "quaternion (x, y, z, w), scalar last"
# The smallest squared box edge the viewer draws, m² (a degenerate inertia still gets a visible box).
BOX_EDGE2_MIN = sp.Rational(1, 10**6)


def chart_inverse(q_ref: sp.Matrix, dtheta: sp.Matrix) -> sp.Matrix:
    """q = q_ref ⊗ [dtheta/2, sqrt(1 − |dtheta/2|²)]: the orientation whose chart value about q_ref is dtheta."""
    h = dtheta / 2
    return qmul(q_ref, sp.Matrix([h[0], h[1], h[2], sp.sqrt(1 - h.dot(h))]))


def _check_chart() -> None:
    """Derivation-time proof: the unsigned chart 2 vec(q_ref* ⊗ q) of chart_inverse(q_ref, dtheta) is dtheta
    for a unit q_ref (its scalar part, sqrt(1 − |dtheta/2|²), is >= 0, so the signed chart agrees)."""
    q_ref, d = vec("q_ref", 4), vec("dtheta", 3)
    back = 2 * qmul(qconj(q_ref), chart_inverse(q_ref, d))[:3, 0]
    unit = {q_ref[3] ** 2: 1 - q_ref[0] ** 2 - q_ref[1] ** 2 - q_ref[2] ** 2}
    diff = (back - d).applyfunc(lambda e: sp.expand(sp.expand(e).subs(unit)))
    if diff != sp.zeros(3, 1):
        raise RuntimeError("derive: quat_error_chart_inverse is not the inverse of the attitude-error chart")


def kernels() -> list[Kernel]:
    _check_chart()
    g = "Measures"
    q, q_ref, d = vec("q", 4), vec("q_ref", 4), vec("dtheta", 3)
    # named: printed as written (SymPy would fold (q_i/s)² into q_i²/s², which overflows)
    s, nu = sp.Symbol("q_scale", real=True), sp.Symbol("q_scaled_norm", real=True)
    u = sp.Matrix([sp.Symbol(f"q_scaled_{i}", real=True) for i in range(4)])
    scaled = [(s, sp.Max(*[sp.Abs(x) for x in q]))] + [(u[i], q[i] / s) for i in range(4)] + [(nu, sp.sqrt(u.dot(u)))]
    I_p, A, J = sym3("I_p"), mat("A_b", 3, WHEELS_MAX), vec("J", WHEELS_MAX)
    m, I3 = scalar("m", positive=True), vec("I_b", 3)
    edge2 = [6 * (I3[(k + 1) % 3] + I3[(k + 2) % 3] - I3[k]) / m for k in range(3)]
    v_com, omega_w, r_w = vec("v_com_w", 3), vec("omega_w", 3), vec("r_w", 3)
    edges = sp.Matrix([sp.sqrt(sp.Piecewise((e, e > BOX_EDGE2_MIN), (BOX_EDGE2_MIN, True))) for e in edge2])
    return [
        Kernel("quat_error_chart_inverse", "Orientation at an attitude error about a reference (inverse of quat_error_chart)",
               r"q = q_{ref} \otimes [\delta\theta/2,\ \sqrt{1 - \lVert\delta\theta/2\rVert^2}]",
               [Arg("q_ref", q_ref, Q + ", unit, body to world", "unit_quaternion"),
                Arg("dtheta", d, "attitude error, body frame, rad; |dtheta| < 2", "small")],
               [Arg("q", chart_inverse(q_ref, d), Q + ", unit, body to world")], g,
               notes=["quat_error_chart(quat_error_chart_inverse(q_ref, dtheta), q_ref) = dtheta for |dtheta| < 2 "
                      "(proved at derive time for the unsigned chart; the scalar part here is >= 0)."]),
        Kernel("quat_normalize_scaled", "Scale to unit length without overflow or underflow, and the norm",
               r"s = \max_i |q_i|,\ \hat q = \frac{q/s}{\lVert q/s \rVert},\ \lVert q \rVert = s\,\lVert q/s \rVert",
               [Arg("q", q, Q)],
               [Arg("q_unit", u / nu, Q + ", unit (NaN for the zero quaternion)"),
                Arg("norm", sp.Piecewise((0, sp.Eq(s, 0)), (s * nu, True)), "|q| (0 for the zero quaternion; may overflow to inf)")],
               g, where=scaled,
               notes=["The division by max|q_i| keeps every square finite and normal for entries from 1e-300 to 1e308; "
                      "callers refuse a norm below their minimum before using q_unit."]),
        Kernel(f"wheels{WHEELS_MAX}_free_inertia", "Inertia of a wheeled body with its wheels free to spin",
               r"M = I_P - A J A^T",
               [Arg("I_p", I_p, "inertia with the wheels locked, body frame, kg·m², symmetric row-major", "inertia_sym"),
                Arg("A_b", A, f"wheel spin axes as columns (3×{WHEELS_MAX}; an unused slot is a zero column), body frame, "
                    "row-major", "unit_vector"),
                Arg("J", J, f"wheel axial inertias ({WHEELS_MAX}), kg·m²", "positive")],
               [Arg("M", I_p - A * sp.diag(*J) * A.T, "3×3, body frame, kg·m², row-major (must stay positive definite)")], g),
        Kernel("rigid_point_velocity", "Velocity of a point moving with a rigid body",
               r"v = v_{COM} + \omega \times r",
               [Arg("v_com_w", v_com, "velocity of the centre of mass, world frame, m/s"),
                Arg("omega_w", omega_w, "angular velocity, world frame, rad/s"),
                Arg("r_w", r_w, "the point relative to the centre of mass, world frame, m")],
               [Arg("v_w", v_com + omega_w.cross(r_w), "velocity of the point, world frame, m/s")], g),
        Kernel("box_of_inertia", "Edges of the uniform box with a given mass and principal moments",
               r"a_k = \sqrt{6 (I_{k+1} + I_{k+2} - I_k) / m}",
               [Arg("m", m, "mass, kg", "positive"), Arg("I_b", I3, "principal moments (or the diagonal), kg·m²", "spd_diag")],
               [Arg("edges", edges, f"box edges along the body axes, m (each at least {float(sp.sqrt(BOX_EDGE2_MIN)):g})")], g),
    ] + _validity_kernels(g)


def _validity_kernels(g: str) -> list[Kernel]:
    """The validity bound |omega| dt (I_max/I_min)^p <= WDT_MAX (derive/tableaux.py), in two parts: a body's scale
    dt (I_max/I_min)^p, computed once per scene, and |omega| times it, computed at every check."""
    I3, dt, p = vec("I_b", 3), scalar("dt", positive=True), sp.Symbol("p", nonnegative=True)
    ratio, w = sp.Symbol("I_ratio", positive=True), sp.Symbol("w_abs", nonnegative=True)
    om, scale = vec("omega_b", 3), scalar("scale", positive=True)
    return [
        Kernel("validity_scale", "Scale of a body's validity measure: dt (I_max/I_min)^p",
               r"s = dt\,(I_{max}/I_{min})^p",
               [Arg("I_b", I3, "principal moments, kg·m²", "spd_diag"), Arg("dt", dt, "step, s", "positive"),
                Arg("p", p, "the integrator's ratio exponent (WDT_RATIO_EXPONENT), >= 0", "positive")],
               [Arg("scale", dt * ratio ** p, "s; |omega| times it is the validity measure")], g,
               where=[(ratio, sp.Max(*I3) / sp.Min(*I3))]),
        Kernel("validity_wdt", "A body's validity measure |omega| dt (I_max/I_min)^p and its |omega|",
               r"w = \lVert\omega\rVert,\ v = w\,s",
               [Arg("omega_b", om, "angular velocity, body frame, rad/s"),
                Arg("scale", scale, "validity_scale of the body, s", "positive")],
               [Arg("omega_norm", w, "|omega|, rad/s (inf when it overflows)"),
                Arg("wdt", w * scale, "the measure the integrator's WDT_MAX bounds (dimensionless)")], g,
               where=[(w, sp.sqrt(om.dot(om)))],
               notes=["Sim checks wdt <= WDT_MAX (derive/tableaux.py) per body; the C step screen uses the same "
                      "kernel, so both decide on the same double."]),
    ]
