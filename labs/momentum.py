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
from lavendersim.kernels import K

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
    s = C.bounded("mass_scale", mass_scale, positive=True)
    m, r, omega, v_com_in = np.array(MASSES), np.array(POSITIONS), np.array(OMEGA_W), np.array(V_COM)
    d = np.array([5.0, -3.0, 2.0])   # another origin: r -> r + d changes neither p nor L about the COM
    vf = np.array(FREE_VELOCITIES)   # a non-rigid set
    v = K.rigid_point_velocity(v_com_in, omega, r - P.center_of_mass(m, r))   # the points move rigidly (the input)
    f = {**_moments("", m, r, v), "I_com_w": P.inertia_com(m, r).ravel()}
    f["I_omega_w"] = P.inertia_com(m, r) @ omega
    f["L_minus_I_omega_rel"] = _rel(f["L_com_w"], f["I_omega_w"])
    f["L_com_after_origin_shift_w"] = P.angular_momentum_com(m, r + d, v)
    # paw-check 1: scale every mass; omega recovered from L2 = I2 omega: the rotation rate is unchanged
    f.update(_moments("scaled_", s * m, r, v))
    f["scaled_omega_w"] = np.linalg.solve(P.inertia_com(s * m, r), f["scaled_L_com_w"])
    f.update({k: v for k, v in _moments("free_", m, r, vf).items() if k in FREE_FIGURES})
    params = {
        "backend": C.NO_SIMULATOR, "masses": m, "positions_w": r.ravel(), "v_com_in_w": v_com_in,
        "omega_w": omega, "mass_scale": s, "origin_shift_w": d, "free_velocities_w": vf.ravel(),
    }
    exact = s == 2.0
    tol = 0.0 if exact else REL_TOL
    note = "exact: doubling is exact in binary floating point" if exact else f"relative {REL_TOL:g}"
    M, L, p = f["total_mass"], f["L_com_w"], f["p_w"]
    checks = C.checks(
        ("p_equals_m_vcom", _rel(p, M * v_com_in), "<=", REL_TOL, "p = sum m_i v_i = m v_COM (relative)"),
        ("L_equals_I_omega", f["L_minus_I_omega_rel"], "<=", REL_TOL,
         "L about the COM = I_COM omega, both in world axes (relative)"),
        ("L_independent_of_origin", _rel(f["L_com_after_origin_shift_w"], L), "<=", REL_TOL,
         "L about the COM ignores where the origin is"),
        ("paw1_com_unchanged", _rel(f["scaled_com_w"], f["com_w"]), "<=", tol, note),
        ("paw1_com_velocity_unchanged", _rel(f["scaled_com_velocity_w"], f["com_velocity_w"]), "<=", tol, note),
        ("paw1_omega_unchanged", _rel(f["scaled_omega_w"], omega), "<=", REL_TOL,
         "rotation rate from L = I omega (relative)"),
        ("paw1_total_mass_scales", abs(f["scaled_total_mass"] - s * M) / (s * M), "<=", tol, note),
        ("paw1_p_scales", _rel(f["scaled_p_w"], s * p), "<=", tol, note),
        ("paw1_L_scales", _rel(f["scaled_L_com_w"], s * L), "<=", tol, note),
        ("free_p_equals_m_vcom", _rel(f["free_p_w"], M * f["free_com_velocity_w"]), "<=", REL_TOL,
         "non-rigid set (relative)"),
    )
    data = {"m": m, "r": r, "v": v, "r_com": f["com_w"], "v_com": f["com_velocity_w"], "p": p, "p2": f["scaled_p_w"],
            "L": L, "L2": f["scaled_L_com_w"], "I_omega": f["I_omega_w"], "s": s}
    return C.make_result(NAME, {k: f[k] for k in FIGURES}, params, checks, {"momentum.png": _plot}, data,
                         headline=("L_minus_I_omega_rel", "<= 1e-12 (L about the COM = I ω)"))


def _moments(prefix: str, m, r, v) -> dict:
    """Total mass, COM, COM velocity, p and L about the COM of particles (the printed particle kernels)."""
    return {f"{prefix}total_mass": P.total_mass(m), f"{prefix}com_w": P.center_of_mass(m, r),
            f"{prefix}com_velocity_w": P.com_velocity(m, v), f"{prefix}p_w": P.linear_momentum(m, v),
            f"{prefix}L_com_w": P.angular_momentum_com(m, r, v)}


FREE_FIGURES = ("free_p_w", "free_com_velocity_w", "free_L_com_w")
FIGURES = ("total_mass", "com_w", "com_velocity_w", "p_w", "L_com_w", "I_com_w", "I_omega_w", "L_minus_I_omega_rel",
           "L_com_after_origin_shift_w", "scaled_total_mass", "scaled_com_w", "scaled_com_velocity_w", "scaled_p_w",
           "scaled_L_com_w", "scaled_omega_w") + FREE_FIGURES   # results.json's order


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
