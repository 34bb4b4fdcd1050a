"""Particle systems: centre of mass, linear momentum, angular momentum about the COM.

A set of point masses moving rigidly (COM velocity v_COM plus a rotation omega about the COM):
  * p = sum m_i v_i equals m v_COM;
  * L = sum (r_i - r_COM) x m_i (v_i - v_COM) equals I omega, with I the particles' inertia about
    the COM in world axes (each point mass moved by the parallel-axis kernel) — same frame for
    I and omega, as the chapter stresses;
  * paw-check 1: double every mass -> COM and velocities (v_COM, omega) are unchanged, the total
    mass, p and L double. (Doubling is exact in binary floating point, so the checks are exact.)
A second, non-rigid set (arbitrary velocities) checks p = m v_COM where L = I omega has no meaning.
All sums go through lavendersim.particles, which sums the generated per-particle kernels.
"""
from __future__ import annotations

import numpy as np

from lavendersim import particles as P
from lavendersim import figures as F

from . import common as C
from .diverged import failed_figure

NAME = "momentum"
TITLE = "particle system: COM, p, L about the COM; L = I omega for rigid motion; paw-check 1 (double the masses)"

# five point masses (kg) at world positions (m): a small irregular body
MASSES = (1.0, 2.0, 0.5, 1.5, 3.0)
POSITIONS = ((0.3, 0.1, 0.0), (-0.2, 0.4, 0.1), (0.1, -0.3, 0.2), (-0.4, -0.1, -0.2), (0.2, 0.2, -0.1))
V_COM = (0.5, -0.2, 0.1)      # m/s
OMEGA_W = (0.4, -1.1, 2.0)    # rad/s, world frame
# non-rigid set: arbitrary velocities (m/s)
FREE_VELOCITIES = ((1.0, 0.0, 0.0), (0.0, -2.0, 0.5), (0.3, 0.3, 0.3), (-1.0, 0.5, 0.0), (0.2, 0.0, -0.4))
REL_TOL = 1e-12


def add_arguments(parser) -> None:
    parser.add_argument("--mass-scale", type=float, default=2.0, metavar="S",
                        help="paw-check 1 multiplies every mass by S (default 2: exact in floating point)")


def options_from_args(args) -> dict:
    return {"mass_scale": args.mass_scale}


def rigid_velocities(r_w, r_com, v_com, omega_w):
    """Velocities of points moving rigidly: v_i = v_COM + omega x (r_i - r_COM).

    This builds the lab's input motion (kinematics of the scenario), not an equation under test."""
    return v_com + np.cross(omega_w, r_w - r_com)


def _rel(a, b) -> float:
    a, b = np.asarray(a, float), np.asarray(b, float)
    return float(np.max(np.abs(a - b)) / max(float(np.max(np.abs(b))), 1e-300))


def run(out_dir=C.DEFAULT_OUT, backend: str = "auto", **options) -> C.LabResult:
    """:func:`compute`, then write OUT/momentum/ (results.json, momentum.png)."""
    return compute(backend, **options).save(out_dir)


@failed_figure
def compute(backend: str = "auto", mass_scale: float = 2.0) -> C.LabResult:
    """Run the lab and return its :class:`~lavendersim.labs.common.LabResult`; writes nothing."""
    C.check_backend(backend)  # validated only: this lab evaluates the generated NumPy kernels, no simulator
    backend = C.NO_SIMULATOR
    s = C.bounded("mass_scale", mass_scale, positive=True)
    m = np.array(MASSES)
    r = np.array(POSITIONS)
    omega = np.array(OMEGA_W)
    v_com_in = np.array(V_COM)

    M = P.total_mass(m)
    r_com = P.center_of_mass(m, r)
    v = rigid_velocities(r, r_com, v_com_in, omega)
    p = P.linear_momentum(m, v)
    v_com = P.com_velocity(m, v)
    L = P.angular_momentum_com(m, r, v)
    I = P.inertia_com(m, r)
    I_omega = I @ omega
    # the same body seen from another origin: r -> r + d changes neither p nor L about the COM
    d = np.array([5.0, -3.0, 2.0])
    L_shift = P.angular_momentum_com(m, r + d, v)

    # paw-check 1: scale every mass
    m2 = s * m
    M2 = P.total_mass(m2)
    r_com2 = P.center_of_mass(m2, r)
    p2 = P.linear_momentum(m2, v)
    v_com2 = P.com_velocity(m2, v)
    L2 = P.angular_momentum_com(m2, r, v)
    # omega recovered from L2 = I2 omega: the rotation rate is unchanged
    omega2 = np.linalg.solve(P.inertia_com(m2, r), L2)

    # non-rigid set
    vf = np.array(FREE_VELOCITIES)
    p_free = P.linear_momentum(m, vf)
    v_com_free = P.com_velocity(m, vf)
    L_free = P.angular_momentum_com(m, r, vf)

    figures = {
        "total_mass": M, "com_w": r_com, "com_velocity_w": v_com, "p_w": p, "L_com_w": L,
        "I_com_w": I.ravel(), "I_omega_w": I_omega, "L_minus_I_omega_rel": _rel(L, I_omega),
        "L_com_after_origin_shift_w": L_shift,
        "scaled_total_mass": M2, "scaled_com_w": r_com2, "scaled_com_velocity_w": v_com2,
        "scaled_p_w": p2, "scaled_L_com_w": L2, "scaled_omega_w": omega2,
        "free_p_w": p_free, "free_com_velocity_w": v_com_free, "free_L_com_w": L_free,
    }
    params = {
        "backend": backend, "masses": m, "positions_w": r.ravel(), "v_com_in_w": v_com_in,
        "omega_w": omega, "mass_scale": s, "origin_shift_w": d, "free_velocities_w": vf.ravel(),
    }
    exact = s == 2.0
    tol = 0.0 if exact else REL_TOL
    note = "exact: doubling is exact in binary floating point" if exact else f"relative {REL_TOL:g}"
    checks = [
        C.at_most("p_equals_m_vcom", _rel(p, M * v_com_in), REL_TOL, "p = sum m_i v_i = m v_COM (relative)"),
        C.at_most("L_equals_I_omega", _rel(L, I_omega), REL_TOL,
                  "L about the COM = I_COM omega, both in world axes (relative)"),
        C.at_most("L_independent_of_origin", _rel(L_shift, L), REL_TOL, "L about the COM ignores where the origin is"),
        C.at_most("paw1_com_unchanged", _rel(r_com2, r_com), tol, note),
        C.at_most("paw1_com_velocity_unchanged", _rel(v_com2, v_com), tol, note),
        C.at_most("paw1_omega_unchanged", _rel(omega2, omega), REL_TOL, "rotation rate from L = I omega (relative)"),
        C.at_most("paw1_total_mass_scales", abs(M2 - s * M) / (s * M), tol, note),
        C.at_most("paw1_p_scales", _rel(p2, s * p), tol, note),
        C.at_most("paw1_L_scales", _rel(L2, s * L), tol, note),
        C.at_most("free_p_equals_m_vcom", _rel(p_free, M * v_com_free), REL_TOL, "non-rigid set (relative)"),
    ]

    data = {"m": m, "r": r, "v": v, "r_com": r_com, "v_com": v_com, "p": p, "p2": p2, "L": L, "L2": L2,
            "I_omega": I_omega, "s": s}
    return C.make_result(NAME, figures, params, checks, {"momentum.png": _plot}, data,
                         headline=("L_minus_I_omega_rel", "<= 1e-12 (L about the COM = I ω)"))


def _plot(d, ax=None):
    m, r, v, r_com, v_com = d["m"], d["r"], d["v"], d["r_com"], d["v_com"]
    p, p2, L, L2, I_omega, s = d["p"], d["p2"], d["L"], d["L2"], d["I_omega"], d["s"]
    fig, ax = C.new_figure(1, 2, size=(12, 5.6), title="Particle system: COM, p and L about the COM", ax=ax)

    from matplotlib.lines import Line2D

    a = ax[0, 0]
    scale = 5.0                   # quiver: 1 m/s drawn as 0.2 m
    a.scatter(r[:, 0], r[:, 1], s=80 * m, color=F.BLUE, alpha=0.6)
    a.quiver(r[:, 0], r[:, 1], v[:, 0], v[:, 1], angles="xy", scale_units="xy", scale=scale, color=F.BLUE, width=0.005)
    a.plot(r_com[0], r_com[1], "k+", ms=14, mew=2)
    a.quiver([r_com[0]], [r_com[1]], [v_com[0]], [v_com[1]], angles="xy", scale_units="xy", scale=scale, color="k",
             width=0.007)
    # the limits hold every point and every arrow tip, with a margin
    pts = np.vstack([r[:, :2], r[:, :2] + v[:, :2] / scale, [r_com[:2]], [r_com[:2] + v_com[:2] / scale]])
    lo, hi = pts.min(axis=0), pts.max(axis=0)
    pad = 0.08 * max(hi - lo)
    a.set_xlim(lo[0] - pad, hi[0] + pad)
    a.set_ylim(lo[1] - pad, hi[1] + pad)
    a.set_xlabel("x (m)")
    a.set_ylabel("y (m)")
    a.set_aspect("equal")
    a.set_title("positions and velocities (top view, 0.2 m per m/s)", fontsize=10)
    handles = [Line2D([], [], ls="", marker="o", color=F.BLUE, alpha=0.6, ms=8, label="particle (area ∝ mass)"),
               Line2D([], [], color=F.BLUE, lw=1.5, label="particle velocity v_i"),
               Line2D([], [], ls="", marker="+", color="k", ms=12, mew=2, label="COM (unchanged when masses double)"),
               Line2D([], [], color="k", lw=2.5, label="COM velocity v_COM")]
    a.legend(handles=handles, fontsize=8, loc="upper center", bbox_to_anchor=(0.5, -0.14), ncols=2)
    b = ax[0, 1]
    xs = np.arange(3)
    wdt = 0.2
    b.bar(xs - 1.5 * wdt, p, wdt, label="p (kg·m/s)", color=F.GREEN)
    b.bar(xs - 0.5 * wdt, p2, wdt, label=f"p, masses ×{s:g}", color=F.GREEN, alpha=0.45, hatch="//")
    b.bar(xs + 0.5 * wdt, L, wdt, label="L about COM (kg·m²/s)", color=F.PURPLE)
    b.bar(xs + 1.5 * wdt, L2, wdt, label=f"L, masses ×{s:g}", color=F.PURPLE, alpha=0.45, hatch="//")
    b.plot(xs + 0.5 * wdt, I_omega, "k_", ms=16, mew=2, label="I ω")
    b.axhline(0, color="k", lw=0.8)
    b.set_xticks(xs, ["x", "y", "z"])
    b.set_xlabel("world component")
    b.set_ylabel("momentum (kg·m/s, kg·m²/s)")
    b.set_title("paw-check 1: p and L scale with the masses")
    b.legend(fontsize=8)
    return fig
