"""Particle systems: total mass, centre of mass, linear momentum, angular momentum about the COM.

m = Σ m_i, r_COM = Σ m_i r_i / m, p = Σ m_i v_i = m v_COM, L = Σ (r_i − r_COM) × m_i (v_i − v_COM).
The kernels give one particle's contributions; the runtime sums them over the particles.
Positions in m, velocities in m/s, masses in kg, world frame.
"""
from __future__ import annotations

import sympy as sp

from .kernel import Arg, Kernel, scalar, vec


def _check_rigid_identity(n: int = 3) -> None:
    """Proof that for rigid motion v_i = v_c + ω × (r_i − c), L = I ω with I = Σ m_i(|s_i|² 1 − s_i s_iᵀ)."""
    w = vec("w", 3)
    L, I = sp.zeros(3, 1), sp.zeros(3, 3)
    for i in range(n):
        mi, s = scalar(f"m{i}"), vec(f"s{i}", 3)
        L += s.cross(mi * w.cross(s))
        I += mi * (s.dot(s) * sp.eye(3) - s * s.T)
    if (L - I * w).applyfunc(sp.expand) != sp.zeros(3, 1):
        raise RuntimeError("derive: Σ s × m (ω × s) differs from I ω")


def kernels() -> list[Kernel]:
    _check_rigid_identity()
    g = "Particle systems"
    m = scalar("m", positive=True)
    r, v, rc, vc = vec("r_w", 3), vec("v_w", 3), vec("r_com_w", 3), vec("v_com_w", 3)
    return [
        Kernel("particle_moments", "One particle's mass moment and momentum (summed: m r_COM and p)",
               r"m\,r_{COM} = \sum_i m_i r_i,\qquad p = \sum_i m_i v_i",
               [Arg("m", m, "particle mass, kg", "positive"), Arg("r_w", r, "position, world, m"), Arg("v_w", v, "velocity, world, m/s")],
               [Arg("m_r", m * r, "mass moment, kg·m"), Arg("p", m * v, "linear momentum, kg·m/s")], g),
        Kernel("particle_angular_momentum", "One particle's angular momentum about the COM",
               r"L = \sum_i (r_i - r_{COM}) \times m_i (v_i - v_{COM})",
               [Arg("m", m, "particle mass, kg", "positive"), Arg("r_w", r, "position, world, m"), Arg("v_w", v, "velocity, world, m/s"),
                Arg("r_com_w", rc, "centre of mass, world, m"), Arg("v_com_w", vc, "COM velocity, world, m/s")],
               [Arg("L_w", (r - rc).cross(m * (v - vc)), "angular momentum about the COM, world, kg·m²/s")], g),
    ]
