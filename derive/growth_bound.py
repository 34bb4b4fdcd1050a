"""A cheap upper bound on a wheeled body's total angular momentum, for the growth screen (issue 29).

The growth check limits |L| of a wheeled body and its wheels, L = R(q) (I_p ω + A J Ω) (wheels<N>_total_momentum,
derive/wheel_layout.py). The C screen evaluates it for every wheeled body at every check; most bodies are far inside
their limit. This bound lets the screen pass those without the rotation and the products:

    |L| <= B = s_q (‖I_p‖_F |ω| + Σ_i J_i |a_i| |Ω_i|),   s_q = |q|² + |1 − |q|²|,

because the printed R(q) is |q|² R̂ + (1 − |q|²) 1 with R̂ a rotation (checked below: Q = R(q) − (1 − |q|²) 1 has
QᵀQ = |q|⁴ 1), so ‖R(q)‖₂ <= s_q; ‖I_p ω‖ <= ‖I_p‖_F |ω| and ‖A J Ω‖ <= Σ_i J_i |a_i| |Ω_i| (triangle inequality).
The row-only factors c = [‖I_p‖_F, J_i |a_i|] are one kernel (once per model row); the bound, squared and widened by
MOMENTUM_BOUND_SLACK, is the other. The slack covers the rounding of both evaluations: the printed |L|² rounds
with a relative error a small multiple of 2⁻⁵³ of the sums of its terms' magnitudes, which B bounds within a factor
of 3 (|R_ij| sums at most 1 + 2|q|² <= 3 s_q), and the bound's own rounding is a few ulps, so a computed |L|² is
at most the computed MOMENTUM_BOUND_SLACK-widened B² for any finite input (1e-10 is ~10⁵ times that). Where the
bound is not below the limit (or is NaN or inf), the screen evaluates |L| itself: it never passes a body the exact
check would refuse.
"""
from __future__ import annotations

import sympy as sp

from .kernel import Arg, Kernel, mat, scalar, vec
from .layout import WHEELS_MAX
from .quaternion import rotation_matrix
from .wheel_cube import sym3
from .wheel_layout import layout_total_momentum

# The relative widening of the bound's square: covers the rounding of |L|² and of the bound (module docstring).
MOMENTUM_BOUND_SLACK = sp.Rational(1, 10**10)
N_BOUND = 1 + WHEELS_MAX   # the row factors: ‖I_p‖_F, then J_i |a_i| per wheel slot


def _check() -> None:
    """Derive-time checks: the printed R(q) minus (1 − |q|²) 1 is |q|² times a rotation (QᵀQ = |q|⁴ 1, symbolic);
    and at random rational inputs (non-unit q, general I_p, axes of any length) the bound is at least |L|."""
    import random

    q = vec("q", 4)
    n2 = q.dot(q)
    Qm = rotation_matrix(q) - (1 - n2) * sp.eye(3)
    if (Qm.T * Qm - n2 ** 2 * sp.eye(3)).applyfunc(sp.expand) != sp.zeros(3, 3):
        raise RuntimeError("derive: the printed R(q) is not |q|^2 R + (1 - |q|^2) 1 (growth_bound's premise)")
    rng = random.Random(29)
    rnd = lambda: sp.Rational(rng.randint(-60, 60), rng.randint(1, 9))   # noqa: E731
    for _ in range(20):
        qv, w, Om = sp.Matrix([rnd() for _ in range(4)]), sp.Matrix([rnd() for _ in range(3)]), sp.Matrix([rnd() for _ in range(WHEELS_MAX)])
        S = sp.Matrix(3, 3, lambda i, j: rnd())
        I_p, A = S * S.T, sp.Matrix(3, WHEELS_MAX, lambda i, j: rnd())
        J = sp.Matrix([abs(rnd()) / 100 for _ in range(WHEELS_MAX)])
        L = layout_total_momentum(qv, w, Om, I_p, A, J)
        c = _factors(I_p, A, J)
        B = _bound(qv, sp.sqrt(w.dot(w)), Om, c)
        if not sp.N(B ** 2 - L.dot(L), 50) >= 0:
            raise RuntimeError("derive: the wheeled momentum bound is below |L| at a sampled state")


def _factors(I_p: sp.Matrix, A: sp.Matrix, J: sp.Matrix) -> sp.Matrix:
    """[‖I_p‖_F, J_i |a_i| ...]: the bound's factors of a model row."""
    cols = [sp.sqrt(sum((A[k, i] ** 2 for k in range(3)), sp.Integer(0))) for i in range(A.shape[1])]
    return sp.Matrix([sp.sqrt(sum((e ** 2 for e in I_p), sp.Integer(0)))] + [J[i] * cols[i] for i in range(A.shape[1])])


def _bound(q: sp.Matrix, w, Om: sp.Matrix, c: sp.Matrix):
    n2 = q.dot(q)
    return (n2 + sp.Abs(1 - n2)) * (c[0] * w + sum((c[1 + i] * sp.Abs(Om[i]) for i in range(len(Om))), sp.Integer(0)))


def kernels() -> list[Kernel]:
    _check()
    g = "Growth check"
    I_p, A, J = sym3("I_p"), mat("A_b", 3, WHEELS_MAX), vec("J", WHEELS_MAX)
    q, w, Om, c = vec("q", 4), scalar("omega_norm", positive=True), vec("Omega", WHEELS_MAX), vec("c", N_BOUND)
    n2, s, B = sp.Symbol("q_norm2", real=True), sp.Symbol("s_q", real=True), sp.Symbol("L_bound", real=True)
    where = [(n2, q.dot(q)), (s, n2 + sp.Abs(1 - n2)),
             (B, s * (c[0] * w + sum((c[1 + i] * sp.Abs(Om[i]) for i in range(WHEELS_MAX)), sp.Integer(0))))]
    return [
        Kernel(f"wheels{WHEELS_MAX}_momentum_bound_factors", "A wheeled body's row factors of its momentum bound",
               r"c = [\lVert I_P\rVert_F,\ J_i \lVert a_i\rVert]",
               [Arg("I_p", I_p, "inertia about the pivot (wheels locked), body frame, kg·m², symmetric row-major", "inertia_sym"),
                Arg("A_b", A, f"wheel spin axes as columns (3×{WHEELS_MAX}), body frame, row-major", "unit_vector"),
                Arg("J", J, f"wheel axial inertias ({WHEELS_MAX}), kg·m²", "positive")],
               [Arg("c", _factors(I_p, A, J), f"[‖I_p‖_F (kg·m²), J_i |a_i| ({WHEELS_MAX}, kg·m²)]")], g,
               notes=[f"Once per model row; wheels{WHEELS_MAX}_momentum_bound reads them at every check."]),
        Kernel(f"wheels{WHEELS_MAX}_momentum_bound", "An upper bound on the squared total momentum of a wheeled body, as computed",
               r"|L|^2 \le (1 + \epsilon)\,\big(s_q (c_0 |\omega| + \sum_i c_i |\Omega_i|)\big)^2,\ s_q = |q|^2 + |1 - |q|^2|",
               [Arg("q", q, "orientation (x, y, z, w), R_WB (any norm)"),
                Arg("omega_norm", w, "|omega_b|, rad/s (validity_wdt's)", "positive"),
                Arg("Omega", Om, f"wheel rates relative to the body ({WHEELS_MAX}), rad/s"),
                Arg("c", c, f"wheels{WHEELS_MAX}_momentum_bound_factors of the body's row", "positive")],
               [Arg("L2_max", (1 + MOMENTUM_BOUND_SLACK) * B * B,
                    f"(kg·m²/s)²: at least wheels{WHEELS_MAX}_total_momentum's |L|² as computed (epsilon = "
                    f"MOMENTUM_BOUND_SLACK = {float(MOMENTUM_BOUND_SLACK):g}, the rounding of both)")], g, where=where,
               notes=["derive/growth_bound.py: why it bounds |L| (the printed R(q) is |q|² R + (1 − |q|²) 1, checked "
                      "at derive time) and why the slack covers the rounding. The growth screen passes a body whose "
                      "bound is inside its limit and evaluates |L| itself otherwise."]),
    ]
