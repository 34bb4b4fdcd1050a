"""Integrator tableaux and constants, declared once (exact rationals where they are rationals).

`lavendersim derive` prints them for the C step loop (generated/tableaux.h) and the NumPy backend
(generated/tableaux.py); neither backend types a coefficient. Each float is the correctly rounded
value of its rational (Python's int/int division), printed with repr so that C parses the same
double.

* RK4: the classic tableau; its weights are kept as integers over a common divisor, so that the
  combination x + (dt/6)(k1 + 2 k2 + 2 k3 + k4) is evaluated the way it always was.
* Dormand–Prince 5(4) (Hairer, Nørsett & Wanner, Solving ODEs I, table II.5.2): A (its last row is
  the 5th-order weights b: FSAL), the error weights E = b − b̂, the step-size controller and the
  starting-step heuristic (Solving ODEs I, II.4).
* Strang splitting of the free rigid body: the sequence of exact principal-axis flows
  (axis, fraction of h), from which derive/integrator_physics.py composes the derived rotation, and
  the half kicks of the loads around it (explicit midpoint steps when damping is declared).
* splitting4: a symmetric composition of the Strang step (above) with step fractions gamma_i, which
  raises its order from 2 to 4 (Yoshida, Phys. Lett. A 150 (1990) 262, and Suzuki, Phys. Lett. A
  146 (1990) 319: for a symmetric basic method of order 2, Σγ = 1 and Σγ³ = 0 give order 4; Hairer,
  Lubich & Wanner, Geometric Numerical Integration, II.4 and V.3). The coefficients are algebraic
  numbers, printed as their correctly rounded doubles (evaluated to 50 digits first). A body without
  effects takes the substeps' flows as one sequence (split4_sequence, neighbours about one axis merged).
  Order 4 torque-free and with loads that depend on p and q only (each splitting step is then
  symmetric); order 3 with a velocity-dependent effect (the explicit-midpoint kick is not symmetric,
  so only the h³ error term cancels; measured error ratio 8 per halving with angular damping).
  Validity bound (for the lead to wire into the per-integrator bounds): like splitting its flows are
  exact rotations, so it never overflows and never raises; it is accurate for |ω|·dt ≲ 0.1 (the quick
  atlas: every cell ok at |ω|·dt = 0.1 for inertia ratios 1…1e6 and all axes, with world L to
  rounding) and silently wrong (energy ×5 … ×1e6, attitude off by π) at |ω|·dt ≥ 1 about the major or
  intermediate axis once the inertia ratio is ≥ 1e3 — the same region as splitting's.
* rk4_expmap: the classic RK4 tableau above, applied in the exponential coordinates of the attitude
  (Runge–Kutta–Munthe-Kaas, see derive/integrator_physics.py); no constant of its own. Validity bound:
  RK4's for the gyroscopic term: accurate for |ω|·dt ≲ 0.1 (quick atlas: energy drift ≤ 4e-7 there);
  finite but wrong at |ω|·dt = 1 once the inertia ratio is ≥ 1e3 (energy drift up to 0.67, attitude
  off by up to π — silent, like rk4's); non-finite and reported as DivergenceError at |ω|·dt = 10 for
  ratio ≥ 1e3. For a sphere (constant ω) it is exact at any |ω|·dt (the exponential map is the
  exact flow; attitude error 8e-13 rad at |ω|·dt = 10).
* implicit_gyro: the Newton iteration's cap and stopping rule.
"""
from __future__ import annotations

import functools
from dataclasses import dataclass

import sympy as sp

from .printers import HEADER

R = sp.Rational


@dataclass(frozen=True)
class Integrator:
    """One integrator of the registry: everything a backend, the Sim or a lab asks about it is here.

    name: what users pass to ``Sim(..., integrator=)``; code: its number in the C step loop; family: the stepper
    that runs it ("explicit_rk": a Runge–Kutta tableau; "adaptive_rk": an embedded pair with step control;
    "composition": kicks and exact flows; "implicit": a Newton step; "lie_group_rk": a tableau in exponential
    coordinates); order: its order torque-free; evals: right-hand-side evaluations per step as counted
    (None: adaptive, counted as it runs; see backends.rhs_per_step); plain_only: no spherical_joint or
    reaction_wheels (its exact sub-flows use a free body's principal inertia); float32: runs in single
    precision; summary: one line."""

    name: str
    code: int
    family: str
    order: int
    evals: object
    plain_only: bool
    float32: bool
    summary: str

    @property
    def adaptive(self) -> bool:
        return self.family == "adaptive_rk"


# The registry (issue 29): nothing else lists integrators; C and Python print it from here. Codes are fixed
# (saved runs and the C step loop's switch use them); a new integrator takes the next code.
FAMILIES = ("explicit_rk", "adaptive_rk", "composition", "implicit", "lie_group_rk")
# Status codes of the C step loop (generated/tableaux.h LV_*; the C backend reads them from tableaux.py)
STATUS = (("OK", 0, "the steps were taken"),
          ("DIVERGED", 1, "a state became non-finite; see fail_step / fail_body"),
          ("TOLERANCE", 2, "dopri5: the step size fell below dt*DP_HMIN_REL (or over DP_MAX_SUBSTEPS substeps in one "
                           "step) without meeting rtol/atol; same state contract as DIVERGED, and h[fail_body] holds "
                           "the step size that was too small"),
          ("NO_ROOT", 3, "implicit_gyro: the Newton solve of a step did not converge (no root near omega); same "
                         "state contract as DIVERGED"),
          ("BAD_ARGUMENT", -1, "an argument the step loop refuses; nothing changed"),
          ("UNKNOWN_EFFECT", -2, "an effect row's code is no declared effect's (*fail_step = the row); nothing changed"),
          ("NO_MEMORY", -3, "the per-body effect index could not be allocated; nothing changed"))

RK4_C = (R(0), R(1, 2), R(1, 2), R(1))                 # nodes: stage s is evaluated at x + c_s dt k_{s-1}
RK4_B_NUM = (1, 2, 2, 1)                               # weights b = RK4_B_NUM / RK4_B_DEN
RK4_B_DEN = 6
# The explicit Runge-Kutta integrators whose stage s is evaluated at x + c_s dt k_{s-1} (a subdiagonal tableau):
# name -> (nodes c, weights b_num, divisor b_den). Their C update and step are printed from these (_c_explicit_rk).
EXPLICIT_RK = {"euler": ((R(0),), (1,), 1), "rk4": (RK4_C, RK4_B_NUM, RK4_B_DEN)}
# The explicit RKs whose torque-free step the default paths take in its scaled-increment form (scaled_program): C's
# free-body paths (csrc/step.c lv_free_rk4_h, the SIMD tiles) and NumPy's (numpy_backend._free_rk4_h) print it.
SCALED_RK = ("rk4",)


def scaled_program(c, b_num, b_den) -> tuple:
    """The scaled-increment form of a subdiagonal explicit RK (EXPLICIT_RK) on a torque-free body: (s, stages, end).

    s is the common scale of the stage increments H_i = s dt k_i (the smallest nonzero node; a right-hand side
    computes H_i at k_i's own cost by taking s dt into its constants: rigid_body_increments_free_c). Stage i
    (1 .. n) is (w_i, m_i, shared): H_i enters the running sum acc = w_1 H_1 + w_2 H_2 + ... (left to right) with
    w_i = b_num_i, and stage i+1's input is x + m_i H_i with m_i = c_{i+1} / s (None at the last stage); shared:
    w_i = m_i (not 1), the multiple is formed once for both. The step ends at x + end acc, end = 1 / (b_den s)
    (b_i dt k_i = end b_num_i H_i). A multiple 1 multiplies by nothing, 2 is H + H (exact, an add).
    RK4: s = 1/2, stages (1, 1), (2, 1), (2, 2, shared), (1, -), end 1/3."""
    s = min(x for x in c if x != 0)
    n = len(c)
    stages = tuple((R(b_num[i]), (c[i + 1] / s if i + 1 < n else None),
                    i + 1 < n and R(b_num[i]) == c[i + 1] / s != 1) for i in range(n))
    return s, stages, 1 / (R(b_den) * s)


def _check_scaled(c, b_num, b_den) -> None:
    """Proof that the scaled program's stage inputs and end are the tableau's (symbols x, k_1 .. k_n, dt)."""
    s, stages, end = scaled_program(c, b_num, b_den)
    x, dt = sp.symbols("x dt")
    k = sp.symbols(f"k1:{len(c) + 1}")
    H = [s * dt * ki for ki in k]
    for i, (_, m, _) in enumerate(stages[:-1]):
        if sp.expand(x + m * H[i] - (x + c[i + 1] * dt * k[i])) != 0:
            raise RuntimeError(f"derive: the scaled program's stage {i + 2} input is not the tableau's")
    acc = sum((w * Hi for (w, _, _), Hi in zip(stages, H)), sp.Integer(0))
    if sp.expand(x + end * acc - (x + dt * sum(R(b, b_den) * ki for b, ki in zip(b_num, k)))) != 0:
        raise RuntimeError("derive: the scaled program's end is not the tableau's step")


def constant_acceleration_weights(c, b_num, b_den) -> tuple:
    """(w_v, w_p) of a subdiagonal explicit RK (EXPLICIT_RK) on the translation p' = v, v' = a with a constant a: its
    step is v⁺ = v + w_v dt a, p⁺ = p + w_v dt v + w_p dt² a, exactly (w_v = Σ b_i, w_p = Σ b_i c_i: the stages see
    v + c_i dt a). Derived by running the tableau's stages on symbols and checked to be that form; RK4: (1, 1/2).
    A body whose effects read no state steps its translation by it (rigid_body.py translation_flow_constant)."""
    p, v, a, dt = sp.symbols("p v a dt")
    kp, kv, prev = [], [], None
    for ci in c:   # stage i is evaluated at x + c_i dt k_{i-1}
        vi = v if prev is None else v + ci * dt * prev[1]
        prev = (vi, a)
        kp.append(vi)
        kv.append(a)
    b = [R(x, b_den) for x in b_num]
    p1 = p + dt * sum((bi * k for bi, k in zip(b, kp)), sp.Integer(0))
    v1 = v + dt * sum((bi * k for bi, k in zip(b, kv)), sp.Integer(0))
    w_v, w_p = sum(b, sp.Integer(0)), sum((bi * ci for bi, ci in zip(b, c)), sp.Integer(0))
    if sp.expand(v1 - (v + w_v * dt * a)) != 0 or sp.expand(p1 - (p + w_v * dt * v + w_p * dt ** 2 * a)) != 0:
        raise RuntimeError("derive: the tableau's step of a constant acceleration is not v + w_v dt a, p + w_v dt v + "
                           "w_p dt² a")
    return w_v, w_p


def _stability_polynomial(A, b) -> sp.Expr:
    """R(z) = 1 + z bᵀ (I − z A)⁻¹ 1 of an explicit Runge–Kutta tableau (y' = λy: y₁ = R(λh) y₀)."""
    z = sp.Symbol("z")
    n = len(b)
    Am = sp.Matrix(n, n, lambda i, j: A[i][j] if j < len(A[i]) else 0)
    return sp.expand(1 + z * (sp.Matrix(b).T * (sp.eye(n) - z * Am).inv() * sp.ones(n, 1))[0])


def explicit_rk_polynomial(name: str) -> sp.Expr:
    """R(z) of a built-in explicit RK (EXPLICIT_RK) as the backends apply it: a subdiagonal A, a_{s,s-1} = c_s."""
    c, b_num, b_den = EXPLICIT_RK[name]
    return _stability_polynomial([[]] + [[0] * (s - 1) + [c[s]] for s in range(1, len(c))], [R(n, b_den) for n in b_num])


def _first_root(poly: sp.Expr, y: sp.Symbol) -> float | None:
    """The smallest positive real root of a polynomial in y (its root at 0, of any multiplicity, set aside)."""
    p = sp.Poly(poly, y)
    k = min(m for (m,), _ in p.terms())
    p = sp.Poly(sp.expand(sp.cancel(p.as_expr() / y**k)), y)
    roots = [float(sp.re(r)) for r in p.nroots(n=30, maxsteps=500) if abs(sp.im(r)) < 1e-20 and sp.re(r) > 1e-12]
    return min(roots) if roots else None


GROWTH_PER_STEP = R(101, 100)   # |R(iy)|^2 allowed when R is not stable on the imaginary axis (euler's 0.1)


def imaginary_axis_bound(R_z: sp.Expr) -> float:
    """The validity bound |ω| dt of an explicit tableau (WDT_MAX of the explicit RKs, built-in and users'): the y
    where |R(iy)| first exceeds 1 (rk4: 2√2) when R is stable on the imaginary axis near 0, else where
    |R(iy)|² reaches GROWTH_PER_STEP = 1.01, a mode growing 0.5 % per step (euler: 0.1)."""
    z, y = sp.Symbol("z"), sp.Symbol("y", real=True)
    a = sp.Poly(R_z, z).all_coeffs()[::-1]        # R(z) = Σ a_k z^k; |R(iy)|² = (Σ_even ...)² + (Σ_odd ...)²
    re = sum((a[k] * (-1) ** (k // 2) * y**k for k in range(0, len(a), 2)), sp.Integer(0))
    im = sum((a[k] * (-1) ** (k // 2) * y**k for k in range(1, len(a), 2)), sp.Integer(0))
    mod2 = sp.expand(re**2 + im**2)
    p = sp.Poly(sp.expand(mod2 - 1), y)
    low = [c for (k,), c in sorted(p.terms()) if abs(float(c)) > 1e-14]
    root = _first_root(p.as_expr() if low and float(low[0]) < 0 else sp.expand(mod2 - GROWTH_PER_STEP), y)
    if root is None:   # (|R(iy)|² of a consistent tableau grows without bound: a root exists)
        raise ValueError(f"no validity bound |ω|·dt found on the imaginary axis for R(z) = {R_z}")
    return root


@functools.cache   # (mpmath roots: ~2.5 s for the registry, which print_c, print_python and their checks each ask for)
def _real_axis_limit(R_z: sp.Expr) -> float:
    """The x > 0 where |R(−x)| first reaches 1: a decaying mode λ < 0 is stable for |λ| h below it."""
    z, x = sp.Symbol("z"), sp.Symbol("x")
    roots = []
    for side in (1, -1):
        poly = sp.Poly(sp.expand(R_z.subs(z, -x) - side), x)
        roots += [float(sp.re(r)) for r in poly.nroots(n=30) if abs(sp.im(r)) < 1e-25 and sp.re(r) > 1e-12]
    return min(roots)

DP_A = (
    (),
    (R(1, 5),),
    (R(3, 40), R(9, 40)),
    (R(44, 45), R(-56, 15), R(32, 9)),
    (R(19372, 6561), R(-25360, 2187), R(64448, 6561), R(-212, 729)),
    (R(9017, 3168), R(-355, 33), R(46732, 5247), R(49, 176), R(-5103, 18656)),
    (R(35, 384), R(0), R(500, 1113), R(125, 192), R(-2187, 6784), R(11, 84)),
)
DP_B_HAT = (R(5179, 57600), R(0), R(7571, 16695), R(393, 640), R(-92097, 339200), R(187, 2100), R(1, 40))
DP_ORDER_ERR = 4                    # order of the embedded solution: the controller's exponent is -1/(4 + 1)

# step-size controller
DP_SAFETY = 0.9
DP_FACMIN = 0.2
DP_FACMAX = 5.0
DP_HMIN_REL = 1e-12                 # a substep below dt * this: the tolerance cannot be met
DP_MAX_SUBSTEPS = 1_000_000         # ... nor with more substeps than this within one output step
# starting step (Hairer II.4): h0 = 0.01 d0/d1 unless a norm is below 1e-5 (then 1e-6); h1 from
# (0.01 / max(d1, d2))^(1/5), or max(1e-6, 1e-3 h0) when that maximum is below 1e-15; h = min(100 h0, h1)
DP_INIT_SMALL = 1e-5
DP_INIT_TINY_H = 1e-6
DP_INIT_FRAC = 0.01
DP_INIT_FLAT = 1e-15
DP_INIT_SHRINK = 1e-3
DP_INIT_GROW = 100.0
# The controller's factor SAFETY err^(-1/(DP_ORDER_ERR + 1)) without a libm power per substep (the same doubles on
# both backends): r = err^(-1/5) by DP_ROOT5_NEWTON Newton steps r <- r (DP_ROOT5_A - err r^5) DP_ROOT5_B on
# r^-5 = err, from the bit-pattern seed r0 = double(DP_ROOT5_SEED - bits(err) // 5) (an IEEE double's bits are
# ~2^52 (log2 x + 1023): the seed is (1 + 1/5) 1023 2^52 lowered by DP_ROOT5_SHIFT 2^52, the shift that makes the
# largest error after two steps least). Used for DP_ROOT5_LO <= err <= DP_ROOT5_HI; the factor is clamped to
# [FACMIN, FACMAX] anyway outside (below LO: FACMAX; above HI, or not a number: FACMIN). Largest relative error
# against err^(-1/5) over [LO, HI]: 2.6e-5 (_check_root5, at derive time): the controller is Hairer's to that factor.
DP_ROOT5_NEWTON = 2
DP_ROOT5_SHIFT = R(3, 50)
DP_ROOT5_LO, DP_ROOT5_HI = 1e-6, 1e6
DP_ROOT5_MAX_REL_ERR = 3e-5


def dp_root5_seed() -> int:
    """DP_ROOT5_SEED: the bits of the Newton start for err^(-1/5), see DP_ROOT5_NEWTON."""
    q = DP_ORDER_ERR + 1
    return int(sp.floor((1 + R(1, q)) * 1023 * 2 ** 52 - DP_ROOT5_SHIFT * 2 ** 52))


def dp_root5(e: float) -> float:
    """err^(-1/5) as both backends compute it (Python floats: the same IEEE operations)."""
    import struct
    q = DP_ORDER_ERR + 1
    bits = struct.unpack("<Q", struct.pack("<d", e))[0]
    r = struct.unpack("<d", struct.pack("<Q", dp_root5_seed() - bits // q))[0]
    for _ in range(DP_ROOT5_NEWTON):
        r2 = r * r
        r = r * (float(q + 1) - e * (r2 * r2 * r)) * (1.0 / q)
    return r


# Dense output (Hairer, Norsett & Wanner, Solving ODEs I, II.6; dopri5.f's contd5): over an accepted substep
# y0 -> y1 of length h, with Y1 = y1 - y0, Y2 = h k1 - Y1, Y3 = Y1 - h k7 - Y2 and Y4 = h sum_i DP_DENSE[i] k_i,
# y(t0 + theta h) = y0 + theta (Y1 + (1 - theta) (Y2 + theta (Y3 + (1 - theta) Y4))), order 4 in theta h
# (checked: _check_dense).
DP_DENSE = (R(-12715105075, 11282082432), R(0), R(87487479700, 32700410799), R(-10690763975, 1880347072),
            R(701980252875, 199316789632), R(-1453857185, 822651844), R(69997945, 29380423))

STRANG = ((0, R(1, 2)), (1, R(1, 2)), (2, R(1)), (1, R(1, 2)), (0, R(1, 2)))
SPLIT_KICK = R(1, 2)                # the loads kick v and omega for h/2 before and after the free flow
SPLIT_MIDPOINT = R(1, 2)            # with damping each kick is an explicit midpoint step (its node)

# splitting4: the step x -> S(γ_s h) ∘ … ∘ S(γ_1 h) x of the Strang step S. Two classic choices with closed
# forms, both symmetric with Σγ = 1, Σγ³ = 0 (order 4; proved in _check):
#  * Yoshida's / Suzuki's / Creutz–Gocksch's "triple jump": γ1 = γ3 = 1/(2 − 2^(1/3)), γ2 = −2^(1/3)/(2 − 2^(1/3))
#    (Yoshida 1990, eq. 4.14; Creutz & Gocksch, Phys. Rev. Lett. 63 (1989) 9): 3 Strang steps, but the
#    large negative middle step (−1.70 h) gives a large error constant;
#  * Suzuki's fractal 5-stage composition: γ1 = γ2 = γ4 = γ5 = 1/(4 − 4^(1/3)), γ3 = 1 − 4 γ1 (Suzuki 1990,
#    eq. 17): 5 Strang steps, every |γ| ≤ 0.66, an error constant ~50-100 times smaller.
# Chosen: the one the accuracy lab puts further on the Pareto front (see SPLIT4_GAMMA below).
_CBRT2 = sp.Integer(2) ** R(1, 3)
_CBRT4 = sp.Integer(4) ** R(1, 3)
TRIPLE_JUMP = (1 / (2 - _CBRT2), -_CBRT2 / (2 - _CBRT2), 1 / (2 - _CBRT2))
SUZUKI5 = (1 / (4 - _CBRT4),) * 2 + (1 - 4 / (4 - _CBRT4),) + (1 / (4 - _CBRT4),) * 2
SPLIT4_GAMMA = SUZUKI5


def split4_sequence(gamma=None) -> tuple:
    """splitting4's torque-free rotation as one sequence of exact axis flows (axis, fraction of h): the
    Strang sequence of each substep γ_i h in turn, adjacent flows about one axis merged (the flow of one
    H_a is a one-parameter group, Φ_a(s) Φ_a(t) = Φ_a(s + t)): 21 flows instead of 25 for Suzuki's
    composition. Fractions exact (algebraic)."""
    seq: list[list] = []
    for g in SPLIT4_GAMMA if gamma is None else gamma:
        for a, f in STRANG:
            if seq and seq[-1][0] == a:
                seq[-1][1] += g * f
            else:
                seq.append([a, g * f])
    return tuple((a, f) for a, f in seq)

# symtop4: the symmetric-top splitting (derive/integrator_physics.py) H = A + B, A = |L|²/(2 I_r) + ½ c_a L_a²
# (exact: sphere flow and axis flow), B = ½ c_b L_b² (axis flow), composed as the Strang step
# A(h/2) B(h) A(h/2) and that step as splitting4 composes splitting's: Suzuki's 5-stage composition, order 4.
# Torque-free the neighbouring A halves merge (A is one flow): A B A B … B A with SYMTOP4_STAGES B flows and
# SYMTOP4_STAGES + 1 A flows, fractions of h printed below.
SYMTOP4_GAMMA = SUZUKI5
SYMTOP_STRANG_A = R(1, 2)           # with effects each stage is the Strang step A(h/2) B(h) A(h/2) (this fraction)


def symtop4_sequence(gamma=None) -> tuple[tuple, tuple]:
    """(A fractions, B fractions) of h of symtop4's torque-free step A(a_0 h) B(b_0 h) A(a_1 h) … B(b_{s-1} h)
    A(a_s h): b_i = γ_i, a_0 = γ_1/2, a_i = (γ_i + γ_{i+1})/2, a_s = γ_s/2. Exact (algebraic)."""
    g = list(SYMTOP4_GAMMA if gamma is None else gamma)
    a = [g[0] / 2] + [(g[i] + g[i + 1]) / 2 for i in range(len(g) - 1)] + [g[-1] / 2]
    return tuple(a), tuple(g)


# symtop_bm6: the same split H = A + B as symtop4, composed by Blanes & Moan's optimized order-6 splitting
# (S. Blanes, P. C. Moan, "Practical symplectic partitioned Runge–Kutta and Runge–Kutta–Nyström methods",
# J. Comput. Appl. Math. 142 (2002) 313–330, Table 2, the 10-stage method "S10" / PRK_6^10):
#     A(a_1 h) B(b_1 h) A(a_2 h) … B(b_5 h) A(a_6 h) B(b_5 h) … B(b_1 h) A(a_1 h)
# with the paper's printed a_1..a_5, b_1..b_4 (15 digits; taken as exact decimals here) and a_6 = 1 − 2 Σa_i,
# b_5 = 1/2 − Σb_i (consistency). Here the paper's a_i (11 flows) go to the axis flow with the SMALLER
# leftover |c| (symtop4's B axis) and its b_i (10 flows) to the larger (symtop4's A axis): measured on diag(1, 2, 3)
# that is 2-7 times more accurate than the other assignment at h = 2^-1 .. 2^-3. 11 + 10 axis flows; since the sphere flow of |L|²/(2 I_r) commutes
# with every flow (derive/integrator_physics.py) it is taken once per step for the whole h, so a step is
# 21 axis flows and 1 sphere flow (symtop4: 11 axis flows, 6 sphere flows). Its error constant is far below a
# Suzuki fractal composition's: on diag(1, 2, 3) at h = 2^-4 it is at the reference's rounding (~1e-12 rad)
# where symtop4 is 3e-7. The order (6) is verified at derive time numerically (_check_bm6).
_BM6_A = ("0.0502627644003922", "0.413514300428344", "0.0450798897943977", "-0.188054853819569",
          "0.541960678450780")
_BM6_B = ("0.148816447901042", "-0.132385865767784", "0.067307604692185", "0.432666402578175")


def bm6_sequence() -> tuple[tuple, tuple]:
    """(A fractions (11), B fractions (10)) of h of symtop_bm6's step A B A … B A (Blanes & Moan S10),
    palindromic, each summing to 1 exactly (rationals)."""
    a = [R(x) for x in _BM6_A]
    b = [R(x) for x in _BM6_B]
    a.append(1 - 2 * sum(a))
    b.append(R(1, 2) - sum(b))
    return tuple(a + a[-2::-1]), tuple(b + b[::-1])


# The compositions (family "composition"), declared as programs of flows: a body with effects takes the stages
# γ_i of `gamma` in turn, each the `kicked` program over γ_i h; a body without effects takes the `free` program
# once over h. A program is a sequence of (flow, fraction): the flow runs for fraction × (the stage's time).
# Flows: kick (the loads on v and omega, splitting_kick; explicit midpoint with damping), drift (p += τ v),
# momentum / rate (omega -> L_b = I omega, and back; no time), strang (splitting_rotation on omega), axis_x/y/z (the
# exact principal-axis flow on L_b), top_a / top_b (the symmetric-top split's axis flows of ½ c_a L_a², ½ c_b L_b²),
# top_b_nz (top_b, skipped when c_b = 0: a symmetric top's turn by 0), sphere (the flow of |L|²/(2 I_r)). The C
# composition engine walks these tables (csrc/step.c composition_step).
FLOWS = ("kick", "drift", "momentum", "rate", "strang", "axis_x", "axis_y", "axis_z", "top_a", "top_b", "top_b_nz",
         "sphere")


def compositions() -> dict:
    """name -> (gamma, kicked, free) of every composition integrator (see FLOWS); fractions exact."""
    strang, drift = (("strang", R(1)),), (("drift", R(1)),)

    def on_momentum(flows):
        return (("momentum", R(0)),) + tuple(flows) + (("rate", R(0)),)

    def kicked(rotation):
        return (("kick", SPLIT_KICK),) + drift + tuple(rotation) + (("kick", SPLIT_KICK),)

    def top(fa, fb):            # A(a_0) B(b_0) A(a_1) ... A(a_s); A = the top_a axis flow, then the sphere flow
        out = []
        for i, f in enumerate(fa):
            out += [("top_a", f), ("sphere", f)] + ([("top_b", fb[i])] if i < len(fb) else [])
        return out

    fp, fq = bm6_sequence()     # P(p_0) Q(q_0) ... P(p_s), then one sphere flow for the whole time
    bm6_flows = [fl for i, f in enumerate(fp) for fl in [("top_b_nz", f)] + ([("top_a", fq[i])] if i < len(fq) else [])]
    bm6 = on_momentum(bm6_flows + [("sphere", R(1))])
    return {"splitting": ((R(1),), kicked(strang), drift + strang),
            "splitting4": (SPLIT4_GAMMA, kicked(strang),
                           drift + on_momentum((f"axis_{'xyz'[a]}", f) for a, f in split4_sequence())),
            "symtop4": (SYMTOP4_GAMMA, kicked(on_momentum(top((SYMTOP_STRANG_A,) * 2, (R(1),)))),
                        drift + on_momentum(top(*symtop4_sequence()))),
            "symtop_bm6": (SYMTOP4_GAMMA, kicked(bm6), drift + bm6)}


def _check_bm6() -> None:
    """symtop_bm6's sequence: palindromic, A and B each flow for total time h, and order 6: on exp(h X) with
    X = P + Q for two fixed non-commuting 4×4 matrices (40-digit mpmath), the one-step error of the
    sequence exp(a_1 h P) exp(b_1 h Q) … shrinks by 2^7 = 128 (order 6: local error O(h^7)) when h halves —
    measured 125 for h = 1/16 → 1/32; accepted 100 .. 160 (an order-4 set gives ~32; one coefficient moved by
    1e-6 gives ~7)."""
    import mpmath as mp
    fa, fb = bm6_sequence()
    if list(fa) != list(reversed(fa)) or list(fb) != list(reversed(fb)) or len(fa) != len(fb) + 1:
        raise RuntimeError("derive: the symtop_bm6 sequence is not palindromic A B … B A")
    if sum(fa) != 1 or sum(fb) != 1:
        raise RuntimeError("derive: the symtop_bm6 sequence does not flow A and B for total time h")
    with mp.workdps(40):
        P = mp.matrix([[0, 1, 0, 0], [-1, 0, 2, 0], [0, -2, 0, 1], [0, 0, -1, 0]])
        Q = mp.matrix([[1, 0, 0, 1], [0, -1, 1, 0], [0, 1, 0, 0], [1, 0, 0, 2]]) / 3

        def err(h):
            S = mp.eye(4)
            for i, f in enumerate(fa):
                S = S * mp.expm(P * (mp.mpf(f.p) / f.q * h))
                if i < len(fb):
                    S = S * mp.expm(Q * (mp.mpf(fb[i].p) / fb[i].q * h))
            return mp.mnorm(S - mp.expm((P + Q) * h), 1)
        ratio = err(mp.mpf(1) / 16) / err(mp.mpf(1) / 32)
    if not 100 <= ratio <= 160:
        raise RuntimeError(f"derive: symtop_bm6's local error ratio on halving h is {float(ratio):.1f}, not ~128 (order 6)")


GYRO_MAX_ITER = 30                  # Newton iterations at most
GYRO_TOL_SQ = 1e-32                 # stop when |delta|^2 <= this * |omega_next|^2 (|delta| <= 1e-16 |omega|)
GYRO_ACCEPT_SQ = 1e-20              # after GYRO_MAX_ITER iterations the last update must be at most 1e-10 |omega_next|
                                    # (an ill-conditioned solve stalls at rounding); else the step has no root: divergence

INTEGRATORS = (
    Integrator("euler", 0, "explicit_rk", 1, 1, False, True, "explicit Euler"),
    Integrator("semi_implicit_euler", 1, "explicit_rk", 1, 1, False, True,
               "symplectic Euler: v and omega first, then p and q with the new rates"),
    Integrator("rk4", 2, "explicit_rk", 4, 4, False, True, "the classic Runge–Kutta method"),
    Integrator("dopri5", 3, "adaptive_rk", 5, None, False, False, "Dormand–Prince 5(4), per-body step size control"),
    Integrator("splitting", 4, "composition", 2, 1, True, False,
               "Strang splitting: exact principal-axis flows, the loads' half kicks around them"),
    Integrator("implicit_gyro", 5, "implicit", 1, 1, True, False,
               "implicit gyroscopic term (Newton), exp-map attitude update"),
    Integrator("splitting4", 6, "composition", 4, len(SPLIT4_GAMMA), True, False,
               "Suzuki's symmetric composition of the splitting step"),
    Integrator("rk4_expmap", 7, "lie_group_rk", 4, 4, True, False, "RK4 in exponential coordinates of q (RKMK4)"),
    Integrator("symtop4", 8, "composition", 4, len(SYMTOP4_GAMMA), True, False,
               "symmetric-top splitting, Suzuki's composition"),
    Integrator("symtop_bm6", 9, "composition", 6, len(SYMTOP4_GAMMA), True, False,
               "symmetric-top splitting, Blanes–Moan S10 (torque-free; with effects symtop4's kicked stages)"),
)


# The fixed-step paths of csrc/ (step.c advance_fixed and advance_model, fixed_loop.h, the SIMD tiles): path -> the
# tableau it steps (EXPLICIT_RK's form), or None: the partitioned (symplectic) Euler step, the explicit_rk member
# without a tableau (NumPy's _step_<name>). An explicit RK takes the path whose tableau is its own (tableau identity,
# fixed_path); one without takes C's tableau stepper with its printed tableau (LV_TABLEAU_STEPPED), as a user's does.
FIXED_PATHS = {"euler": ((R(0),), (1,), 1), "semi_implicit": None, "rk4": (RK4_C, RK4_B_NUM, RK4_B_DEN)}


def fixed_path(i: Integrator) -> str | None:
    """The C fixed-step path integrator i takes (FIXED_PATHS), None for the tableau stepper or another family."""
    if i.family != "explicit_rk":
        return None
    tab = EXPLICIT_RK.get(i.name)
    return next((p for p, t in FIXED_PATHS.items() if t == tab), None)


def _paths() -> list[tuple[Integrator, str]]:
    """(integrator, its fixed-step path) for those that take one, in registry order."""
    return [(i, p) for i in INTEGRATORS if (p := fixed_path(i)) is not None]


def integrator_names() -> list[str]:
    return [i.name for i in INTEGRATORS]


# Validity bounds, one per integrator (issue 11): the run is trusted while
#     |omega| * dt * (I_max / I_min) ** WDT_RATIO_EXPONENT[name]  <=  WDT_MAX[name]
# (|omega| rad/s, dt s, per body; beyond it Sim raises DivergenceError naming the bound, or warns with
# on_bound="warn"). An integrator without an entry (the adaptive dopri5: it controls its own error) has none.
#  * euler, semi_implicit_euler: explicit in omega, a rotation mode grows by sqrt(1 + (|omega| dt)^2) per
#    step; at 0.1 that is 0.5 % per step (energy x2.7 in 100 steps): beyond it the answer is not a rotation.
#  * rk4: its linear stability limit on the imaginary axis, |R(iy)| <= 1 for |y| <= 2 sqrt(2).
#  * splitting: the Strang composition of exact axis flows resonates about the major and intermediate
#    axes: measured (atlas body, 1000 steps) the energy grows x2 and more from |omega| dt (I_max/I_min)^(1/4)
#    ~ 1.8-3.2 for ratios 10..1e6; its accuracy degrades sooner with the ratio (I = (1e-9, 1, 1),
#    omega = (5, 1, 0.5), dt = 1e-3: 0.38 rad off after 10 s, rk4 3e-10): the bound takes the square root,
#    |omega| dt (I_max/I_min)^(1/2) <= 1, which is below the resonance for every ratio and refuses that case.
#  * implicit_gyro: unconditionally stable, but beyond half a turn per step the exp-map attitude update
#    aliases (a turn of |omega| dt is indistinguishable from one of 2 pi - |omega| dt).
#  * splitting4: its substeps are the splitting step at gamma_i h, |gamma_i| <= 0.66: splitting's bound
#    (not measured separately yet). rk4_expmap: RK4's tableau, RK4's linear stability limit.
#  * symtop4: like splitting4 a composition of exact rotations (never overflows); its substeps are
#    A(γ_i h/2) B(γ_i h) A(γ_i h/2), |γ_i| <= 0.66, with the splitting error proportional to |c_a c_b| <=
#    splitting's: splitting4's bound (not measured separately yet).
#  * symtop_bm6: symtop4's bound. Measured with the atlas's cells (labs/atlas.py run_cell, C, ratios 1 … 1e6,
#    three axes, |omega| dt = 0.1 … 10): no cell within the bound drifts E by more than 2e-12; the first
#    energy doubling is at |omega| dt = 10 (ratios 10 … 1000; symtop4's at 4.6), and the intermediate-axis
#    spin's energy drift passes 1e-9 from |omega| dt (I_max/I_min)^(1/2) ~ 1.5 (symtop4: ~1 at ratio 100).
# The explicit RKs' bounds come from their tableaux (imaginary_axis_bound, as a user's tableau's: euler 0.1, rk4 2√2).
WDT_MAX = {**{n: imaginary_axis_bound(explicit_rk_polynomial(n)) for n in EXPLICIT_RK}, "splitting": R(1),
           "implicit_gyro": sp.pi, "splitting4": R(1), "symtop4": R(1), "symtop_bm6": R(1)}
WDT_MAX.update(semi_implicit_euler=WDT_MAX["euler"], rk4_expmap=WDT_MAX["rk4"])
WDT_RATIO_EXPONENT = {**{n: R(0) for n in EXPLICIT_RK}, "semi_implicit_euler": R(0), "splitting": R(1, 2),
                      "implicit_gyro": R(0), "splitting4": R(1, 2), "rk4_expmap": R(0),
                      "symtop4": R(1, 2), "symtop_bm6": R(1, 2)}


def _kicked_stages(gammas) -> sp.Expr:
    """R(z) of the splitting family on a linear decay y' = λy (z = λh): the flows leave v and ω alone, each
    stage γ h kicks twice for SPLIT_KICK γ h, and a kick of a velocity-reading load is an explicit midpoint
    step, y (1 + w + SPLIT_MIDPOINT w²) with w = λ · (its time): R(z) = Π_i (1 + a γ_i z + M (a γ_i z)²)²."""
    z = sp.Symbol("z")
    out = sp.Integer(1)
    for g in gammas:
        w = SPLIT_KICK * sp.Float(sp.N(g, 40), 40) * z
        out *= (1 + w + SPLIT_MIDPOINT * w ** 2) ** 2
    return sp.expand(out)


def real_axis_stability() -> dict:
    """Per integrator, the stability limit on the negative real axis of the way it steps a load: a linear decay
    λ (an effect's damping c/m or c/I, a wheel's c_w/J) is stable while |λ|·h stays below it. The explicit
    Runge–Kutta ones from their tableaux (the Euler family 2, RK4 and rk4_expmap 2.785…, Dormand–Prince 5
    3.306…); implicit_gyro takes the loads at the step's start (explicit Euler in them: 2); the splitting family
    kicks (_kicked_stages: splitting 4, its compositions with their γ_i). divergence_cause and the Sim's check of
    every declared decay (an effect's printed decay rate) name it."""
    out = {n: _real_axis_limit(explicit_rk_polynomial(n)) for n in EXPLICIT_RK}   # as tableaux.h applies them
    split4, symtop4 = _real_axis_limit(_kicked_stages(SPLIT4_GAMMA)), _real_axis_limit(_kicked_stages(SYMTOP4_GAMMA))
    return {**out, "semi_implicit_euler": out["euler"], "rk4_expmap": out["rk4"], "implicit_gyro": out["euler"],
            "dopri5": _real_axis_limit(_stability_polynomial(DP_A[:6], DP_A[6])),
            "splitting": _real_axis_limit(_kicked_stages((1,))), "splitting4": split4, "symtop4": symtop4,
            "symtop_bm6": symtop4}


def dp_b() -> tuple:
    return tuple(DP_A[6]) + (R(0),)


def dp_e() -> tuple:
    """Error weights b − b̂ (the 5th-order minus the embedded 4th-order weights)."""
    return tuple(b - bh for b, bh in zip(dp_b(), DP_B_HAT))


def _check_registry() -> None:
    """The registry is consistent: codes 0..n-1 once each, known families, every bound declared for it."""
    codes = sorted(i.code for i in INTEGRATORS)
    if codes != list(range(len(INTEGRATORS))) or len({i.name for i in INTEGRATORS}) != len(INTEGRATORS):
        raise RuntimeError("derive: integrator codes must be 0..n-1, names unique")
    for i in INTEGRATORS:
        if i.family not in FAMILIES:
            raise RuntimeError(f"derive: integrator {i.name}: unknown family {i.family!r}")
        if (i.evals is None) != i.adaptive:
            raise RuntimeError(f"derive: integrator {i.name}: evals is None exactly for the adaptive family")
    fixed = {i.name for i in INTEGRATORS if not i.adaptive}
    if set(WDT_MAX) != fixed or set(WDT_RATIO_EXPONENT) != fixed:
        raise RuntimeError("derive: every fixed-step integrator, and only those, has a validity bound (WDT_MAX)")
    for i in INTEGRATORS:
        if i.family == "explicit_rk" and i.name not in EXPLICIT_RK and fixed_path(i) != "semi_implicit":
            raise RuntimeError(f"derive: explicit RK {i.name} has no tableau (EXPLICIT_RK)")
        if i.float32 and fixed_path(i) is None:
            raise RuntimeError(f"derive: integrator {i.name} is float32 but takes no fixed-step path (FIXED_PATHS): "
                               "csrc/fixed_loop.h steps float32")
    if [p for p in FIXED_PATHS if sum(fixed_path(i) == p for i in INTEGRATORS) != 1]:
        raise RuntimeError("derive: each fixed-step path (FIXED_PATHS) is taken by one integrator")
    comp = compositions()
    if set(comp) != {i.name for i in INTEGRATORS if i.family == "composition"}:
        raise RuntimeError("derive: every composition integrator, and only those, has a program (compositions())")
    if any(f not in FLOWS for g, kicked, free in comp.values() for f, _ in kicked + free):
        raise RuntimeError("derive: a composition program names a flow not in FLOWS")
    if set(real_axis_stability()) != {i.name for i in INTEGRATORS}:
        raise RuntimeError("derive: every integrator has a decay stability limit (real_axis_stability)")


def _check_root5() -> None:
    """The controller's err^(-1/5) (dp_root5) is within DP_ROOT5_MAX_REL_ERR of the power over [LO, HI]."""
    import math
    n = 20001
    lo, hi = math.log(DP_ROOT5_LO), math.log(DP_ROOT5_HI)
    worst = max(abs(dp_root5(e) / e ** (-1.0 / (DP_ORDER_ERR + 1)) - 1.0)
                for e in (math.exp(lo + (hi - lo) * i / (n - 1)) for i in range(n)))
    if not worst <= DP_ROOT5_MAX_REL_ERR:
        raise RuntimeError(f"derive: dp_root5 is {worst:.2e} off err^(-1/5) (allowed {DP_ROOT5_MAX_REL_ERR})")


def _check_dense() -> None:
    """The dense output's weights b_i(theta) meet sum_i b_i(theta) c_i^(k-1) = theta^k / k for k = 1..4 (order 4)
    and give y1 at theta = 1."""
    th = sp.Symbol("theta")
    b, c = dp_b(), [sum(row, R(0)) for row in DP_A]
    one = [R(1)] + [R(0)] * 6
    last = [R(0)] * 6 + [R(1)]
    w = [th * b[i] + th * (1 - th) * (one[i] - b[i]) + th ** 2 * (1 - th) * (2 * b[i] - one[i] - last[i])
         + th ** 2 * (1 - th) ** 2 * DP_DENSE[i] for i in range(7)]
    for k in range(1, 5):
        if sp.expand(sum(w[i] * c[i] ** (k - 1) for i in range(7)) - th ** k / k) != 0:
            raise RuntimeError(f"derive: the Dormand-Prince dense output fails sum b_i(theta) c_i^{k - 1} = theta^{k}/{k}")
    if [sp.expand(x.subs(th, 1)) for x in w] != list(b):
        raise RuntimeError("derive: the Dormand-Prince dense output does not end at y1")


def _check() -> None:
    """Derivation-time proofs of the order conditions that identify the tableaux."""
    _check_registry()
    _check_root5()
    _check_dense()
    c = [sum(row, R(0)) for row in DP_A]
    b, bh = dp_b(), DP_B_HAT
    for w, p in ((b, 5), (bh, 4)):
        # bushy-tree conditions Σ b_i c_i^(k-1) = 1/k up to the order
        for k in range(1, p + 1):
            if sum(w[i] * c[i] ** (k - 1) for i in range(7)) != R(1, k):
                raise RuntimeError(f"derive: Dormand–Prince weights fail Σ b c^{k - 1} = 1/{k}")
    if c[6] != 1 or c[1] != R(1, 5):
        raise RuntimeError("derive: Dormand–Prince nodes are not (0, 1/5, …, 1)")
    if sum(R(n, RK4_B_DEN) for n in RK4_B_NUM) != 1:
        raise RuntimeError("derive: RK4 weights do not sum to 1")
    _check_scaled(RK4_C, RK4_B_NUM, RK4_B_DEN)
    if list(STRANG) != list(reversed(STRANG)):
        raise RuntimeError("derive: the Strang sequence is not symmetric")
    for axis in range(3):
        if sum((f for a, f in STRANG if a == axis), R(0)) != 1:
            raise RuntimeError(f"derive: the Strang sequence does not flow axis {axis} for total time h")
    for name, g in (("triple jump", TRIPLE_JUMP), ("Suzuki 5-stage", SUZUKI5), ("splitting4", SPLIT4_GAMMA)):
        # order 4 of a symmetric composition of a symmetric order-2 method: symmetric, Σγ = 1, Σγ³ = 0
        if list(g) != list(reversed(g)):
            raise RuntimeError(f"derive: the {name} composition is not symmetric")
        for k, want in ((1, 1), (3, 0)):
            if sp.nsimplify(sp.radsimp(sp.expand(sum(x ** k for x in g)))) != want:
                raise RuntimeError(f"derive: the {name} composition fails Σγ^{k} = {want}")
    _check_bm6()
    if list(SYMTOP4_GAMMA) != list(SPLIT4_GAMMA):
        raise RuntimeError("derive: symtop4 is documented as Suzuki's composition, as splitting4")
    fa, fb = symtop4_sequence()
    if fa[0] != SYMTOP_STRANG_A * SYMTOP4_GAMMA[0]:
        raise RuntimeError("derive: the merged symtop4 sequence does not start with the Strang step's A half")
    if list(fa) != list(reversed(fa)) or list(fb) != list(reversed(fb)) or len(fa) != len(fb) + 1:
        raise RuntimeError("derive: the symtop4 sequence is not symmetric")
    for name, f in (("A", fa), ("B", fb)):
        if sp.nsimplify(sp.radsimp(sp.expand(sum(f, R(0))))) != 1:
            raise RuntimeError(f"derive: the symtop4 sequence does not flow {name} for total time h")
    seq = split4_sequence()
    if [a for a, _ in seq] != [a for a, _ in reversed(seq)] or any(seq[i][0] == seq[i + 1][0] for i in range(len(seq) - 1)):
        raise RuntimeError("derive: the merged splitting4 sequence is not symmetric or has unmerged neighbours")
    for axis in range(3):
        if sp.nsimplify(sp.radsimp(sp.expand(sum((f for a, f in seq if a == axis), R(0))))) != 1:
            raise RuntimeError(f"derive: the merged splitting4 sequence does not flow axis {axis} for total time h")


def _f(x) -> str:
    """A rational as a float literal: its correctly rounded double (int / int), shortest repr."""
    r = sp.Rational(x)
    return repr(int(r.p) / int(r.q))


def _fa(x) -> str:
    """An algebraic number as a float literal: its double, from a 50-digit evaluation."""
    return repr(float(sp.N(x, 50)))


def _scalars() -> list[tuple[str, str, str]]:
    """(name, C literal, Python literal) of every scalar constant."""
    ints = [("DP_MAX_SUBSTEPS", DP_MAX_SUBSTEPS), ("GYRO_MAX_ITER", GYRO_MAX_ITER), ("RK4_B_DEN", RK4_B_DEN)]
    floats = [("DP_SAFETY", DP_SAFETY), ("DP_FACMIN", DP_FACMIN), ("DP_FACMAX", DP_FACMAX),
              ("DP_HMIN_REL", DP_HMIN_REL), ("DP_ERR_EXPONENT", -1.0 / (DP_ORDER_ERR + 1)),
              ("DP_INIT_SMALL", DP_INIT_SMALL), ("DP_INIT_TINY_H", DP_INIT_TINY_H), ("DP_INIT_FRAC", DP_INIT_FRAC),
              ("DP_INIT_FLAT", DP_INIT_FLAT), ("DP_INIT_SHRINK", DP_INIT_SHRINK), ("DP_INIT_GROW", DP_INIT_GROW),
              ("DP_INIT_EXPONENT", 1.0 / (DP_ORDER_ERR + 1)), ("GYRO_TOL_SQ", GYRO_TOL_SQ),
              ("GYRO_ACCEPT_SQ", GYRO_ACCEPT_SQ), ("DP_ROOT5_A", DP_ORDER_ERR + 2), ("DP_ROOT5_B", 1.0 / (DP_ORDER_ERR + 1)),
              ("DP_ROOT5_LO", DP_ROOT5_LO), ("DP_ROOT5_HI", DP_ROOT5_HI)]
    ints += [("DP_ROOT5_NEWTON", DP_ROOT5_NEWTON), ("DP_ROOT5_DIV", DP_ORDER_ERR + 1)]
    out = [(n, f"{v}L" if n == "DP_MAX_SUBSTEPS" else str(v), f"{v:_}") for n, v in ints]
    out += [("DP_ROOT5_SEED", f"{dp_root5_seed()}ULL", str(dp_root5_seed()))]
    out += [(n, f"({float(v)!r})" if v < 0 else repr(float(v)), repr(float(v))) for n, v in floats]
    out += [("SPLIT_KICK", _f(SPLIT_KICK), _f(SPLIT_KICK)), ("SPLIT_MIDPOINT", _f(SPLIT_MIDPOINT), _f(SPLIT_MIDPOINT))]
    out += [(f"RK4_C{i}", _f(c), _f(c)) for i, c in enumerate(RK4_C)]
    out += [(f"RK4_B{i}", _f(n), _f(n)) for i, n in enumerate(RK4_B_NUM)]
    for name in sorted(WDT_MAX):
        v, p = repr(float(WDT_MAX[name])), repr(float(WDT_RATIO_EXPONENT[name]))
        out += [(f"WDT_MAX_{name.upper()}", v, v), (f"WDT_RATIO_EXPONENT_{name.upper()}", p, p)]
    return out


def _c_registry() -> list[str]:
    """The integrator registry and the step loop's status codes, for C."""
    up = [(i.name.upper(), i) for i in INTEGRATORS]
    out = ["/* The integrators (derive/tableaux.py INTEGRATORS): codes, capabilities, and LV_INTEGRATORS(X) = X(NAME, code)",
           "   for each (the module's constants). Nothing else lists them. */", "enum {"]
    out += [f"    LV_INTEGRATOR_{n} = {i.code}," for n, i in up[:-1]] + [f"    LV_INTEGRATOR_{up[-1][0]} = {up[-1][1].code}", "};"]
    last = max(INTEGRATORS, key=lambda i: i.code)
    out.append(f"#define LV_INTEGRATOR_LAST LV_INTEGRATOR_{last.name.upper()}")
    for macro, pick in (("PLAIN_ONLY", lambda i: i.plain_only), ("FLOAT32", lambda i: i.float32),
                        ("ADAPTIVE", lambda i: i.adaptive)):
        terms = " || ".join(f"(i) == LV_INTEGRATOR_{i.name.upper()}" for i in INTEGRATORS if pick(i)) or "0"
        out.append(f"#define LV_INTEGRATOR_{macro}(i) ({terms})")
    for fam in FAMILIES:
        terms = " || ".join(f"(i) == LV_INTEGRATOR_{i.name.upper()}" for i in INTEGRATORS if i.family == fam) or "0"
        out.append(f"#define LV_INTEGRATOR_IS_{fam.upper()}(i) ({terms})")
    out.append("#define LV_INTEGRATORS(X) " + " ".join(f"X({n}, {i.code})" for n, i in up))
    out += ["/* The fixed-step paths of csrc/ (derive/tableaux.py FIXED_PATHS): LV_PATH_<path> is the code of the integrator that",
            "   takes it (fixed_path: by tableau identity), LV_INTEGRATOR_FIXED_PATH(i) whether code i takes one. An explicit RK",
            "   without one steps on the tableau stepper with its printed tableau: LV_TABLEAU_STEPPED(X) = X(code, s, A, b_num,",
            "   b_den) for each. */",
            "enum { " + ", ".join(f"LV_PATH_{p.upper()} = LV_INTEGRATOR_{i.name.upper()}" for i, p in _paths()) + " };"]
    out.append("#define LV_INTEGRATOR_FIXED_PATH(i) (" + " || ".join(f"(i) == LV_PATH_{p.upper()}" for _, p in _paths()) + ")")
    stepped = [i for i in INTEGRATORS if i.family == "explicit_rk" and fixed_path(i) is None]
    for i in stepped:
        nodes, b_num, _ = EXPLICIT_RK[i.name]
        s, N = len(nodes), i.name.upper()
        A = [_f(nodes[r]) if k == r - 1 else "0.0" for r in range(s) for k in range(s)]
        out.append(f"static const double LV_{N}_A[{s * s}] = {{" + ", ".join(A) + "};")
        out.append(f"static const double LV_{N}_B_NUM[{s}] = {{" + ", ".join(_f(b) for b in b_num) + "};")
    out.append("#define LV_TABLEAU_STEPPED(X)" + "".join(
        f" X(LV_INTEGRATOR_{i.name.upper()}, {len(EXPLICIT_RK[i.name][0])}, LV_{i.name.upper()}_A, "
        f"LV_{i.name.upper()}_B_NUM, {_f(EXPLICIT_RK[i.name][2])})" for i in stepped))
    out += ["", "/* Status codes of the step loop */", "enum {"]
    out += [f"    LV_{n} = {c}," + f" /* {doc} */" for n, c, doc in STATUS[:-1]]
    n, c, doc = STATUS[-1]
    out += [f"    LV_{n} = {c} /* {doc} */", "};", ""]
    return out


def _c_explicit_rk(name: str, c, b_num, b_den) -> list[str]:
    """LV_<NAME>_UPDATE and LV_<NAME>_STEP of a subdiagonal explicit Runge-Kutta tableau (EXPLICIT_RK), for C."""
    N, s = name.upper(), len(c)
    last = f"(acc) + (REAL){_f(b_num[-1])} * (k)" if s > 1 else f"(REAL){_f(b_num[0])} * (k)"
    cases = [f"(STAGE) == {i} ? ((acc) = {'(acc) + ' if i > 1 else ''}(REAL){_f(b_num[i - 1])} * (k), "
             f"(out) = (x) + (REAL){_f(c[i])} * (dt) * (k))" for i in range(1, s)]
    end = f"((out) = (x) + (dt) / (REAL){_f(b_den)} * ({last}))"
    upd = f"#define LV_{N}_UPDATE(REAL, STAGE, dt, x, k, acc, out) \\\n    (" + " \\\n     : ".join(cases + [end]) + ")"
    step = [f"#define LV_{N}_STEP(REAL, RHS, FOR, AT, dt, x, xn, k, acc, tmp) do {{"]
    for i in range(1, s + 1):
        step.append(f"    RHS({'x' if i == 1 else 'tmp'}, k); "
                    f"FOR((void)LV_{N}_UPDATE(REAL, {i}, dt, AT(x), AT(k), AT(acc), AT({'xn' if i == s else 'tmp'})));")
    return [upd, " \\\n".join(step) + " \\\n} while (0)"]


def _c_scaled_rk(name: str, c, b_num, b_den) -> list[str]:
    """LV_<NAME>_SCALE and LV_<NAME>_SCALED_UPDATE of a subdiagonal explicit RK in its scaled-increment form
    (scaled_program), for C."""
    N = name.upper()
    s, stages, end = scaled_program(c, b_num, b_den)

    def term(k, h="(H)"):
        return h if k == 1 else f"({h} + {h})" if k == 2 else f"(REAL){_f(k)} * {h}"
    cases = []
    for i, (w, m, shared) in enumerate(stages[:-1], start=1):
        if shared:
            acc = "(acc) = (out)" if i == 1 else "(acc) = (acc) + (out)"
            cases.append(f"(STAGE) == {i} ? ((out) = {term(w)}, {acc}, (out) = (x) + (out))")
        else:
            acc = f"(acc) = {term(w)}" if i == 1 else f"(acc) = (acc) + {term(w)}"
            cases.append(f"(STAGE) == {i} ? ({acc}, (out) = (x) + {term(m)})")
    w = stages[-1][0]
    total = f"((acc) + {term(w)})" if len(stages) > 1 else term(w)
    cases.append(f"((out) = (x) + {total}" + (f" * (REAL){_f(end)})" if end != 1 else ")"))
    step = [f"#define LV_{N}_SCALED_STEP(REAL, RHS, FOR, AT, x, xn, H, acc, tmp) do {{"]
    for i in range(1, len(stages) + 1):
        step.append(f"    RHS({'x' if i == 1 else 'tmp'}, H); FOR((void)LV_{N}_SCALED_UPDATE(REAL, {i}, AT(x), AT(H), AT(acc), "
                    f"AT({'xn' if i == len(stages) else 'tmp'})));")
    return [f"#define LV_{N}_SCALE {_f(s)}",
            f"#define LV_{N}_SCALED_UPDATE(REAL, STAGE, x, H, acc, out) \\\n    (" + " \\\n     : ".join(cases) + ")",
            " \\\n".join(step) + " \\\n} while (0)", _c_scaled_fused(N, stages, end)]


def _c_scaled_fused(N: str, stages, end) -> str:
    """LV_<N>_SCALED_UPDATE_FUSED: the same scaled program (scaled_program's stages and end) for code compiled with
    a*b+c contracted into FMAs (the opt-in contract="fma" tiles): a multiple 2 is two adds onto its target, (t + H) +
    H, never H + H, which GCC folds into 2 H and then fuses into the sum: FMA-unit work where the adders are idle.
    The same step to rounding (other roundings than LV_<N>_SCALED_UPDATE: not bitwise it)."""
    def onto(t, k):
        return f"{t} + (H)" if k == 1 else f"({t} + (H)) + (H)" if k == 2 else f"{t} + (REAL){_f(k)} * (H)"

    def first(k):
        return "(H)" if k == 1 else f"(REAL){_f(k)} * (H)"
    cases = []
    for i, (w, m, _) in enumerate(stages[:-1], start=1):
        acc = f"(acc) = {first(w)}" if i == 1 else f"(acc) = {onto('(acc)', w)}"
        cases.append(f"(STAGE) == {i} ? ({acc}, (out) = {onto('(x)', m)})")
    w = stages[-1][0]
    total = f"({onto('(acc)', w)})" if len(stages) > 1 else first(w)
    cases.append(f"((out) = (x) + {total}" + (f" * (REAL){_f(end)})" if end != 1 else ")"))
    return f"#define LV_{N}_SCALED_UPDATE_FUSED(REAL, STAGE, x, H, acc, out) \\\n    (" + " \\\n     : ".join(cases) + ")"


def _py_scaled_rk() -> list[str]:
    """SCALED_RK: name -> (s, ((w, m, shared), ...), end) of scaled_program, as tableaux.h prints it."""
    def fl(v):
        return None if v is None else float(_f(v))
    out = {n: (fl(s), tuple((fl(w), fl(m), bool(sh)) for w, m, sh in st), fl(e))
           for n, (s, st, e) in ((n, scaled_program(*t)) for n, t in EXPLICIT_RK.items() if n in SCALED_RK)}
    return ["# the scaled-increment form of a torque-free step (derive/tableaux.py scaled_program): name -> (s, stages",
            "# (w, m, shared), end); as tableaux.h's LV_<NAME>_SCALED_UPDATE", "SCALED_RK = " + repr(out)]


def _num(x) -> str:
    """A float literal of an exact rational (_f) or algebraic number (_fa)."""
    return _f(x) if isinstance(sp.sympify(x), sp.Rational) else _fa(x)


def _c_compositions() -> list[str]:
    """The composition programs (compositions(), FLOWS) as tables the C composition engine walks."""
    out = ["", "/* The compositions (derive/tableaux.py compositions()): a body with effects takes the n_stages stages",
           "   gamma_i in turn, each the `kicked` program over gamma_i h; a body without effects the `free` program once",
           "   over h. Each lv_flow runs flow for frac times the stage's time (LV_FLOW_*: derive/tableaux.py FLOWS). */",
           "enum { " + ", ".join(f"LV_FLOW_{f.upper()}" for f in FLOWS) + " };",
           "typedef struct { int flow; double frac; } lv_flow;",
           "typedef struct {", "    int n_stages;", "    const double *gamma;", "    int n_kicked;",
           "    const lv_flow *kicked;", "    int n_free;", "    const lv_flow *free;", "} lv_composition;"]
    entries = []
    for name, (g, kicked, free) in compositions().items():
        N = name.upper()
        out.append(f"static const double LV_{N}_GAMMA[{len(g)}] = {{" + ", ".join(_num(x) for x in g) + "};")
        for part, prog in (("KICKED", kicked), ("FREE", free)):
            flows = [f"{{LV_FLOW_{f.upper()}, {_num(x)}}}" for f, x in prog]
            rows = [", ".join(flows[i:i + 4]) for i in range(0, len(flows), 4)]
            out.append(f"static const lv_flow LV_{N}_{part}[{len(prog)}] = {{\n    " + ",\n    ".join(rows) + "};")
        entries.append(f"    [LV_INTEGRATOR_{N}] = {{{len(g)}, LV_{N}_GAMMA, {len(kicked)}, LV_{N}_KICKED, "
                       f"{len(free)}, LV_{N}_FREE}}")
    return out + ["static const lv_composition LV_COMPOSITIONS[LV_INTEGRATOR_LAST + 1] = {", ",\n".join(entries), "};"]


def print_c() -> str:
    """generated/tableaux.h: #defines for scalars, static const arrays for the tableaux."""
    _check()
    out = [f"/* {HEADER} */", "/* The integrator registry, tableaux and constants (derive/tableaux.py). Included through step.h. */",
           "#ifndef LAVENDERSIM_TABLEAUX_H", "#define LAVENDERSIM_TABLEAUX_H", ""]
    out += _c_registry()
    out += [f"#define LV_{n} {c}" for n, c, _ in _scalars()]
    out += ["", "/* The explicit Runge-Kutta integrators of EXPLICIT_RK, stage s at x + c_s dt k_{s-1}: LV_<NAME>_UPDATE(REAL,",
            "   STAGE, dt, x, k, acc, out) is one number's update after stage STAGE's derivative k (1 .. s; a constant",
            "   where it can be): before the last, the running weighted sum acc (b_1 k_1 + b_2 k_2 + ..., left to right) and",
            "   the next stage's input out = x + (c_{STAGE+1} dt) k; at the last, the step's end",
            "   out = x + (dt / b_den) (acc + b_s k). LV_<NAME>_STEP runs every stage on whole vectors: RHS(in, out) the",
            "   right-hand side, FOR(stmt) runs stmt for every number of a vector, AT(v) names that number of v; k, acc and",
            "   tmp are scratch vectors; xn may be x. Every path of csrc/ steps these integrators through them. */"]
    for name, (c, b_num, b_den) in EXPLICIT_RK.items():
        out += _c_explicit_rk(name, c, b_num, b_den)
    out += ["", "/* The scaled-increment form of a torque-free step (derive/tableaux.py scaled_program): H_i = LV_<NAME>_SCALE",
            "   dt k_i (rigid_body_increments_free_c); LV_<NAME>_SCALED_UPDATE(REAL, STAGE, x, H, acc, out) after stage",
            "   STAGE's increment H: before the last, the running sum acc and the next stage's input out = x + m H (adds",
            "   only); at the last, the step's end out = x + (acc + w H) * end. out may not be x (it holds a shared",
            "   multiple first). LV_<NAME>_SCALED_STEP runs every stage as LV_<NAME>_STEP does, RHS(in, H) the increments",
            "   (H, acc, tmp scratch; xn may be x). */"]
    for name in SCALED_RK:
        out += _c_scaled_rk(name, *EXPLICIT_RK[name])
    out += ["", "/* Dormand-Prince 5(4): A (row 6 = the 5th-order weights, FSAL) and E = b - b_hat */",
            "static const double LV_DP_A[7][6] = {"]
    for row in DP_A:
        vals = [_f(a) for a in row] + ["0.0"] * (6 - len(row))
        out.append("    {" + ", ".join(vals) + "},")
    out.append("};")
    out.append("static const double LV_DP_E[7] = {" + ", ".join(_f(e) for e in dp_e()) + "};")
    out.append("/* its dense output's weights (DP_DENSE: Y4 = h sum_i LV_DP_DENSE[i] k_i) */")
    out.append("static const double LV_DP_DENSE[7] = {" + ", ".join(_f(d) for d in DP_DENSE) + "};")
    out += _c_compositions()
    seq = " ".join(f"{'xyz'[a]}({'h' if f == 1 else f'{f}*h'})" for a, f in STRANG)
    out += ["", f"/* Strang splitting of the free rotation, {seq}: composed in derive/ into the kernel",
            "   lv_splitting_rotation (no table is needed at run time). */", "", "#endif", ""]
    return "\n".join(out)


def print_python() -> str:
    """generated/tableaux.py."""
    _check()
    out = [f'"""{HEADER}', "", "Integrator tableaux and constants (derive/tableaux.py), the same doubles as tableaux.h.", '"""', ""]
    out += ["# The integrators (derive/tableaux.py INTEGRATORS): nothing else lists them",
            "INTEGRATOR_CODES = {" + ", ".join(f"{i.name!r}: {i.code}" for i in INTEGRATORS) + "}",
            "INTEGRATOR_FAMILY = {" + ", ".join(f"{i.name!r}: {i.family!r}" for i in INTEGRATORS) + "}",
            "INTEGRATOR_ORDER = {" + ", ".join(f"{i.name!r}: {i.order}" for i in INTEGRATORS) + "}",
            "# right-hand-side evaluations per step as counted (None: adaptive, counted as it runs)",
            "RHS_PER_STEP = {" + ", ".join(f"{i.name!r}: {i.evals!r}" for i in INTEGRATORS) + "}",
            "INTEGRATOR_SUMMARY = {" + ", ".join(f"{i.name!r}: {i.summary!r}" for i in INTEGRATORS) + "}",
            "ADAPTIVE = (" + "".join(f"{i.name!r}, " for i in INTEGRATORS if i.adaptive) + ")",
            "PLAIN_ONLY = (" + "".join(f"{i.name!r}, " for i in INTEGRATORS if i.plain_only) + ")",
            "FLOAT32_INTEGRATORS = (" + "".join(f"{i.name!r}, " for i in INTEGRATORS if i.float32) + ")",
            "# status codes of the C step loop (tableaux.h LV_*)"]
    out += [f"STATUS_{n} = {c}" for n, c, _ in STATUS]
    out.append("")
    out += [f"{n} = {p}" for n, _, p in _scalars()]
    out.append("")
    out.append("# Dormand-Prince 5(4): DP_A[s] (stage s's coefficients; DP_A[6] = the 5th-order weights, FSAL), DP_E = b - b_hat")
    out.append("DP_A = (")
    out.extend("    (" + ", ".join(_f(a) for a in row) + ("," if len(row) == 1 else "") + ")," for row in DP_A)
    out.append(")")
    out.append("DP_E = (" + ", ".join(_f(e) for e in dp_e()) + ")")
    out.append("# its dense output's weights: Y4 = h sum_i DP_DENSE[i] k_i (derive/tableaux.py DP_DENSE)")
    out.append("DP_DENSE = (" + ", ".join(_f(d) for d in DP_DENSE) + ")")
    out.append("RK4_C = (" + ", ".join(_f(c) for c in RK4_C) + ")")
    out.append("RK4_B_NUM = (" + ", ".join(_f(n) for n in RK4_B_NUM) + ")")
    out.append("# explicit RK integrators, stage s at x + c_s dt k_{s-1}: name -> (c, b_num, b_den), as tableaux.h prints them")
    fl = lambda v: tuple(float(_f(x)) for x in v)  # noqa: E731  (the doubles tableaux.h prints)
    out.append("EXPLICIT_RK = " + repr({n: (fl(c), fl(b), float(_f(d))) for n, (c, b, d) in EXPLICIT_RK.items()}))
    out += _py_scaled_rk()
    out.append("# Strang splitting of the free rotation: (axis, fraction of h)")
    out.append("STRANG = (" + ", ".join(f"({a}, {_f(f)})" for a, f in STRANG) + ")")
    out.append("# the compositions: name -> (gamma, kicked program, free program), each program ((flow, fraction), ...)")
    out.append("COMPOSITIONS = {" + ", ".join(
        f"{n!r}: (({''.join(_num(x) + ', ' for x in g)}), "
        + ", ".join("(" + "".join(f"({f!r}, {_num(x)}), " for f, x in prog) + ")" for prog in (k, fr)) + ")"
        for n, (g, k, fr) in compositions().items()) + "}")
    out.append("# validity bounds: |omega| dt (I_max/I_min)**WDT_RATIO_EXPONENT[name] <= WDT_MAX[name] (derive/tableaux.py)")
    out.append("WDT_MAX = {" + ", ".join(f"{n!r}: {float(WDT_MAX[n])!r}" for n in sorted(WDT_MAX)) + "}")
    out.append("WDT_RATIO_EXPONENT = {" + ", ".join(f"{n!r}: {float(WDT_RATIO_EXPONENT[n])!r}"
                                                    for n in sorted(WDT_RATIO_EXPONENT)) + "}")
    out.append("# linear stability limit on the negative real axis, |lambda| h (from each explicit tableau; derive/tableaux.py)")
    lim = real_axis_stability()
    out.append("REAL_AXIS_STABILITY = {" + ", ".join(f"{n!r}: {lim[n]!r}" for n in sorted(lim)) + "}")
    out.append("")
    return "\n".join(out)
