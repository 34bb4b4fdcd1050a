"""Inertia tensors from their integral definition I = ∫(|r|² 1 − r rᵀ) dm, in kg·m².

Body frame at the centre of mass, axes along the principal axes. Box of full side lengths
(w, h, d) along (x, y, z); solid cylinder of radius r and height h along z; solid sphere of
radius r. Uniform density; mass m in kg, lengths in m.
"""
from __future__ import annotations

import sympy as sp

from .kernel import Arg, Kernel, mat, scalar, vec
from .quaternion import rotation_matrix


def _integrand(x, y, z):
    r = sp.Matrix([x, y, z])
    return (r.dot(r)) * sp.eye(3) - r * r.T


def box_inertia(m, w, h, d) -> sp.Matrix:
    x, y, z = sp.symbols("x y z", real=True)
    rho = m / (w * h * d)
    return (rho * _integrand(x, y, z)).applyfunc(
        lambda e: sp.integrate(e, (x, -w / 2, w / 2), (y, -h / 2, h / 2), (z, -d / 2, d / 2)))


def cylinder_inertia(m, r, h) -> sp.Matrix:
    s, phi, z = sp.symbols("s phi z", real=True, nonnegative=True)
    rho = m / (sp.pi * r**2 * h)
    f = rho * _integrand(s * sp.cos(phi), s * sp.sin(phi), z) * s  # Jacobian s
    return f.applyfunc(lambda e: sp.simplify(sp.integrate(e, (s, 0, r), (phi, 0, 2 * sp.pi), (z, -h / 2, h / 2))))


def sphere_inertia(m, r) -> sp.Matrix:
    s, th, ph = sp.symbols("s theta phi", real=True, nonnegative=True)
    rho = m / (sp.Rational(4, 3) * sp.pi * r**3)
    x, y, z = s * sp.sin(th) * sp.cos(ph), s * sp.sin(th) * sp.sin(ph), s * sp.cos(th)
    f = rho * _integrand(x, y, z) * s**2 * sp.sin(th)  # Jacobian s² sin θ
    return f.applyfunc(lambda e: sp.simplify(sp.integrate(e, (s, 0, r), (th, 0, sp.pi), (ph, 0, 2 * sp.pi))))


def parallel_axis(I_c: sp.Matrix, m, d: sp.Matrix) -> sp.Matrix:
    """Inertia about a point displaced by d from the COM: I_c + m(|d|² 1 − d dᵀ)."""
    return I_c + m * (d.dot(d) * sp.eye(3) - d * d.T)


def _diag(M: sp.Matrix) -> sp.Matrix:
    if any(M[i, j] != 0 for i in range(3) for j in range(3) if i != j):
        raise RuntimeError("derive: principal-axis inertia integral has off-diagonal terms")
    return sp.Matrix([M[0, 0], M[1, 1], M[2, 2]])


def kernels() -> list[Kernel]:
    g = "Inertia"
    m = scalar("m", positive=True)
    w, h, d, r = (scalar(n, positive=True) for n in ("w", "h", "d", "r"))
    box = box_inertia(m, w, h, d)
    expected = m / 12 * sp.diag(h**2 + d**2, w**2 + d**2, w**2 + h**2)
    if (box - expected).applyfunc(sp.simplify) != sp.zeros(3, 3):
        raise RuntimeError("derive: box inertia integral differs from m/12 diag(h²+d², w²+d², w²+h²)")
    cyl, sph = cylinder_inertia(m, r, h), sphere_inertia(m, r)
    I_c, dvec, q, I_b = mat("I_c", 3, 3), vec("d", 3), vec("q", 4), vec("I_b", 3)
    R = rotation_matrix(q)
    I_w = R * sp.diag(*I_b) * R.T
    KG = "kg"
    I_o, cvec = mat("I_o", 3, 3), vec("c", 3)
    about_com = I_o - (parallel_axis(sp.zeros(3, 3), m, cvec))
    if (parallel_axis(about_com, m, cvec) - I_o).applyfunc(sp.expand) != sp.zeros(3, 3):
        raise RuntimeError("derive: inertia_about_com is not the inverse of parallel_axis")
    return [
        Kernel("inertia_box", "Principal inertia of a solid box, integrated over its volume",
               r"I_B = \int_V (\lVert r\rVert^2 \mathbf 1 - r r^T)\,dm = \tfrac{m}{12}\operatorname{diag}(h^2+d^2,\ w^2+d^2,\ w^2+h^2)",
               [Arg("m", m, "mass, kg", "positive"), Arg("w", w, "x side, m", "positive"), Arg("h", h, "y side, m", "positive"),
                Arg("d", d, "z side, m", "positive")], [Arg("I_b", _diag(expected), "principal moments, body frame, kg·m²")], g,
               notes=["The volume integral is evaluated symbolically and proven equal to the closed form printed here."]),
        Kernel("inertia_cylinder", "Principal inertia of a solid cylinder along body z",
               r"I_B = \operatorname{diag}\!\left(\tfrac{m}{12}(3r^2+h^2),\ \tfrac{m}{12}(3r^2+h^2),\ \tfrac{m r^2}{2}\right)",
               [Arg("m", m, "mass, kg", "positive"), Arg("r", r, "radius, m", "positive"), Arg("h", h, "height along z, m", "positive")],
               [Arg("I_b", _diag(cyl), "principal moments, body frame, kg·m²")], g),
        Kernel("inertia_sphere", "Principal inertia of a solid sphere", r"I_B = \tfrac{2}{5} m r^2 \mathbf 1",
               [Arg("m", m, "mass, kg", "positive"), Arg("r", r, "radius, m", "positive")],
               [Arg("I_b", _diag(sph), "principal moments, body frame, kg·m²")], g),
        Kernel("parallel_axis", "Inertia about a point offset by d from the centre of mass",
               r"I_O = I_C + m(\lVert d\rVert^2 \mathbf 1 - d d^T)",
               [Arg("I_c", I_c, "inertia about the COM, kg·m², row-major"), Arg("m", m, "mass, " + KG, "positive"),
                Arg("d", dvec, "offset of the point from the COM, m (same frame as I_c)")],
               [Arg("I_o", parallel_axis(I_c, m, dvec), "inertia about the point, kg·m², row-major")], g),
        Kernel("inertia_about_com", "Inertia about the centre of mass from the inertia about a reference point O "
               "(CAD mass properties), the COM at c from O",
               r"I_C = I_O - m(\lVert c\rVert^2 \mathbf 1 - c c^T)",
               [Arg("I_o", I_o, "inertia about the reference point, kg·m², row-major"), Arg("m", m, "mass, " + KG, "positive"),
                Arg("c", cvec, "COM position relative to the reference point, m (same frame as I_o)")],
               [Arg("I_c", about_com, "inertia about the COM, kg·m², row-major")], g,
               notes=["The parallel-axis theorem read backwards; derive proves that moving the result back by c "
                      "gives I_O again."]),
        Kernel("world_inertia", "Body inertia written in world coordinates", r"I_W = R_{WB} I_B R_{WB}^T",
               [Arg("q", q, "orientation (x, y, z, w), R_WB, unit", "unit_quaternion"), Arg("I_b", I_b, "principal moments, body frame, kg·m²", "positive")],
               [Arg("I_w", I_w, "inertia, world frame, kg·m², row-major")], g),
    ]
