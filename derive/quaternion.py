"""Quaternion algebra in (x, y, z, w) order, scalar last, and orientation kinematics.

R(q) maps body coordinates to world coordinates (R_WB). Intrinsic XYZ Euler angles (a, b, c)
mean R = Rx(a) Ry(b) Rz(c), in radians. Angular velocity in rad/s; omega_w in the world frame,
omega_b in the body frame.
"""
from __future__ import annotations

import sympy as sp

from .kernel import Arg, Kernel, scalar, vec
from .layout import CONSTANTS

# Terms of the series of (1 + eps)^(-1/2) that quat_renormalize_near_unit keeps: eps^0 .. eps^RENORM_ORDER. An even
# order keeps the polynomial positive for every eps (q's direction kept even outside the validity range).
RENORM_ORDER = 2


def qmul(a: sp.Matrix, b: sp.Matrix) -> sp.Matrix:
    """Hamilton product a ⊗ b of (x, y, z, w) quaternions."""
    av, aw = a[:3, 0], a[3]
    bv, bw = b[:3, 0], b[3]
    v = aw * bv + bw * av + av.cross(bv)
    return sp.Matrix([v[0], v[1], v[2], aw * bw - av.dot(bv)])


def qconj(q: sp.Matrix) -> sp.Matrix:
    return sp.Matrix([-q[0], -q[1], -q[2], q[3]])


def pure(v: sp.Matrix) -> sp.Matrix:
    """The pure quaternion [v, 0]."""
    return sp.Matrix([v[0], v[1], v[2], 0])


def quat_rate_body(q: sp.Matrix, omega_b: sp.Matrix) -> sp.Matrix:
    """Quaternion kinematics with the body-frame angular velocity: q̇ = ½ q ⊗ [ω_b, 0]."""
    return qmul(q, pure(omega_b)) / 2


def quat_rate_world(q: sp.Matrix, omega_w: sp.Matrix) -> sp.Matrix:
    """Quaternion kinematics with the world-frame angular velocity: q̇ = ½ [ω_w, 0] ⊗ q."""
    return qmul(pure(omega_w), q) / 2


def rotation_matrix(q: sp.Matrix) -> sp.Matrix:
    """R_WB of a unit quaternion (x, y, z, w)."""
    x, y, z, w = q
    return sp.Matrix([
        [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
        [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
        [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)],
    ])


def rotate(q: sp.Matrix, v: sp.Matrix) -> sp.Matrix:
    """R(q) v, written as the vector part of q ⊗ [v,0] ⊗ q*, expanded to R v (unit q)."""
    return rotation_matrix(q) * v


def rotate_to_body(q: sp.Matrix, v_w: sp.Matrix) -> sp.Matrix:
    """R(q)ᵀ v_w, the world vector v_w in the body frame, as v − w t + q_v × t with t = (2 q_v) × v
    (the sandwich q* ⊗ [v,0] ⊗ q with its two cross products kept): 30 multiplies and adds against the
    matrix form's ~46 (R(q) built, then Rᵀ v). The same polynomial as rotation_matrix(q).T * v_w for
    any q, unit or not (proved in _check_identities); the rounding differs."""
    qv, w = q[:3, 0], q[3]
    t = (2 * qv).cross(v_w)
    return v_w - w * t + qv.cross(t)


def rotate_to_world(q: sp.Matrix, v_b: sp.Matrix) -> sp.Matrix:
    """R(q) v_b, the body vector v_b in the world frame, as v + w t + q_v × t with t = (2 q_v) × v (the sandwich
    q ⊗ [v,0] ⊗ q* with its two cross products kept): 15 multiplies (2 q_v as adds) against the matrix form's ~18
    (R(q) built, then R v). The same polynomial as rotation_matrix(q) * v_b for any q, unit or not (proved in
    _check_identities); the rounding differs."""
    qv, w = q[:3, 0], q[3]
    t = (2 * qv).cross(v_b)
    return v_b + w * t + qv.cross(t)


class Rotation(sp.MutableDenseMatrix):
    """R_WB = rotation_matrix(q), or its transpose, that multiplies 3-vectors as the sandwich.

    Its entries are rotation_matrix(q)'s (its transpose's); ``R * v`` with a 3×1 matrix v is
    rotate_to_world(q, v) (R_WB) or rotate_to_body(q, v) (R_WBᵀ), the same polynomial as the matrix
    product, printed cheaper. ``.T`` keeps the flag; every other operation (entries, R·M, M·R, sums,
    subs, copies) gives a plain Matrix, so no result of one is taken for a rotation. Not assignable.

    Parameters
    ----------
    q : sympy.Matrix (4×1)
        The quaternion (x, y, z, w) of R_WB.
    transposed : bool
        The transpose R_WBᵀ (world → body) instead of R_WB (body → world).
    """

    _op_priority = 10.02      # above Matrix's (10.01): M * R comes to __rmul__ (a plain product)

    def __new__(cls, q: sp.Matrix, transposed: bool = False):
        R = rotation_matrix(q)
        obj = sp.MutableDenseMatrix._fromrep.__func__(cls, (R.T if transposed else R)._rep)
        obj.q, obj.transposed = sp.Matrix(q), bool(transposed)
        return obj

    @classmethod
    def _new(cls, *args, **kwargs):            # results of operations: plain matrices
        return sp.MutableDenseMatrix._new(*args, **kwargs)

    @classmethod
    def _fromrep(cls, rep):
        return sp.MutableDenseMatrix._fromrep(rep)

    def plain(self) -> sp.Matrix:
        """The matrix as a plain sympy Matrix (products of it are matrix products)."""
        return sp.MutableDenseMatrix._new(self.rows, self.cols, list(self))

    @property
    def T(self) -> "Rotation":
        return Rotation(self.q, not self.transposed)

    def transpose(self) -> "Rotation":
        return self.T

    def __mul__(self, other):
        if isinstance(other, sp.MatrixBase) and other.shape == (3, 1):
            return (rotate_to_body if self.transposed else rotate_to_world)(self.q, sp.Matrix(other))
        return self.plain() * other

    def __matmul__(self, other):
        return self.__mul__(other)

    def __rmul__(self, other):
        return other * self.plain() if isinstance(other, sp.MatrixBase) else self.plain().__rmul__(other)

    def __rmatmul__(self, other):
        return self.__rmul__(other)

    def __setitem__(self, key, value):
        raise TypeError("derive: a Rotation (STATE.R_WB) is not assignable; copy it with .plain() first")


def rot_x(a):
    c, s = sp.cos(a), sp.sin(a)
    return sp.Matrix([[1, 0, 0], [0, c, -s], [0, s, c]])


def rot_y(b):
    c, s = sp.cos(b), sp.sin(b)
    return sp.Matrix([[c, 0, s], [0, 1, 0], [-s, 0, c]])


def rot_z(c_):
    c, s = sp.cos(c_), sp.sin(c_)
    return sp.Matrix([[c, -s, 0], [s, c, 0], [0, 0, 1]])


def axis_angle_quat(u: sp.Matrix, theta) -> sp.Matrix:
    s = sp.sin(theta / 2)
    return sp.Matrix([u[0] * s, u[1] * s, u[2] * s, sp.cos(theta / 2)])


def renorm_series(eps: sp.Symbol, order: int = RENORM_ORDER) -> sp.Expr:
    """1/sqrt(1 + eps) to order eps^order, in Horner form: 1 - eps/2 + 3 eps^2/8 (order 2)."""
    c = [sp.binomial(sp.Rational(-1, 2), k) for k in range(order + 1)]
    p = c[order]
    for k in range(order - 1, -1, -1):
        p = c[k] + eps * p
    return p


def renorm_error_bound(order: int, eps_max) -> sp.Rational:
    """An upper bound of ||q p(eps)| - 1| = |sqrt(1 + eps) p(eps) - 1| over |eps| <= eps_max < 1, exact: the
    series' first dropped coefficient |c| eps_max^(order+1) / (1 - eps_max) (the coefficients of (1 + eps)^(-1/2)
    fall in magnitude, so the geometric sum bounds the tail for either sign of eps), times sqrt(1 + eps_max) < 1 +
    eps_max."""
    d = sp.nsimplify(eps_max)
    c = abs(sp.binomial(sp.Rational(-1, 2), order + 1))
    return c * d ** (order + 1) / (1 - d) * (1 + d)


def _check_renorm(order: int) -> sp.Rational:
    """Derivation-time proofs for quat_renormalize_near_unit: the polynomial is the Taylor series of 1/sqrt(1 + eps)
    to eps^order, positive for every real eps (the direction of q is kept), and within QUAT_RENORM_EPS_MAX it
    leaves |q| within 2^-53 of 1 (below a double's rounding of 1). Returns the bound."""
    e = sp.Symbol("eps", real=True)
    p = renorm_series(e, order)
    taylor = sp.series(1 / sp.sqrt(1 + e), e, 0, order + 1).removeO()
    if sp.expand(p - taylor) != 0:
        raise RuntimeError("derive: renorm_series is not the Taylor series of 1/sqrt(1 + eps)")
    if order % 2 or sp.Poly(sp.expand(p), e).count_roots() != 0:
        raise RuntimeError("derive: renorm_series has a real root (q's direction would flip)")
    eps_max = dict((n, v) for n, v, _ in CONSTANTS)["QUAT_RENORM_EPS_MAX"]
    bound = renorm_error_bound(order, eps_max)
    if not bound <= sp.Rational(1, 2**53):
        raise RuntimeError(f"derive: QUAT_RENORM_EPS_MAX = {eps_max} is too wide for order {order}: "
                           f"||q| - 1| up to {float(bound):.3g}")
    return bound


def _check_identities() -> None:
    """Derivation-time proofs: R(q) from the sandwich product; rotate_to_body and rotate_to_world (Rotation's
    products) are R(q)ᵀ v and R(q) v as polynomials; Euler XYZ quaternion gives Rx Ry Rz."""
    q = vec("q", 4)
    v = vec("v", 3)
    sandwich = qmul(qmul(q, pure(v)), qconj(q))[:3, 0]
    unit = {q[3] ** 2: 1 - q[0] ** 2 - q[1] ** 2 - q[2] ** 2}
    diff = (sandwich - rotation_matrix(q) * v).applyfunc(lambda e: sp.expand(sp.expand(e).subs(unit)))
    if diff != sp.zeros(3, 1):
        raise RuntimeError("derive: R(q) v does not equal q ⊗ [v,0] ⊗ q*")
    if (rotate_to_body(q, v) - rotation_matrix(q).T * v).applyfunc(sp.expand) != sp.zeros(3, 1):
        raise RuntimeError("derive: rotate_to_body(q, v) is not R(q)ᵀ v as a polynomial")
    if (rotate_to_world(q, v) - rotation_matrix(q) * v).applyfunc(sp.expand) != sp.zeros(3, 1):
        raise RuntimeError("derive: rotate_to_world(q, v) is not R(q) v as a polynomial")
    # Euler angles 2a, 2b, 2c: the quaternion holds cos/sin of a, b, c, the matrices (expand_trig) polynomials in them;
    # each entry of the difference, with cos and sin as symbols, must reduce to 0 modulo cos^2 + sin^2 = 1 (exact, and
    # ~40x cheaper than simplify on the entries)
    half = sp.symbols("a b c", real=True)
    qe = euler_xyz_quat(*(2 * h for h in half))
    d = rotation_matrix(qe) - rot_x(2 * half[0]) * rot_y(2 * half[1]) * rot_z(2 * half[2])
    cs = sp.symbols("c_a s_a c_b s_b c_c s_c")
    poly = {f(h): cs[2 * i + j] for i, h in enumerate(half) for j, f in enumerate((sp.cos, sp.sin))}
    circles = [cs[2 * i] ** 2 + cs[2 * i + 1] ** 2 - 1 for i in range(3)]
    if any(sp.reduced(sp.expand(sp.expand_trig(e).xreplace(poly)), circles, *cs)[1] != 0 for e in d):
        raise RuntimeError("derive: Euler XYZ quaternion does not reproduce Rx Ry Rz")


def euler_xyz_quat(a, b, c) -> sp.Matrix:
    """Quaternion of intrinsic XYZ angles: qx(a) ⊗ qy(b) ⊗ qz(c)."""
    ex, ey, ez = sp.Matrix([1, 0, 0]), sp.Matrix([0, 1, 0]), sp.Matrix([0, 0, 1])
    return qmul(qmul(axis_angle_quat(ex, a), axis_angle_quat(ey, b)), axis_angle_quat(ez, c))


def kernels() -> list[Kernel]:
    _check_identities()
    g = "Quaternions and orientation kinematics"
    a, b, q = vec("a", 4), vec("b", 4), vec("q", 4)
    v_b, omega_w, omega_b, u = vec("v_b", 3), vec("omega_w", 3), vec("omega_b", 3), vec("axis", 3)
    R = vec("R", 9)
    Rm = sp.Matrix(3, 3, list(R))
    dt, theta = scalar("dt", positive=True), scalar("angle")
    ea, eb, ec = scalar("roll"), scalar("pitch"), scalar("yaw")
    qd_world = quat_rate_world(q, omega_w)
    qd_body = quat_rate_body(q, omega_b)
    q_step = q + dt * qd_world
    norm = sp.sqrt(q_step.dot(q_step))
    qnorm = sp.sqrt(q.dot(q))

    # Rotation matrix → quaternion (Shepperd): pick the largest of w², x², y², z² to divide by.
    tr = Rm[0, 0] + Rm[1, 1] + Rm[2, 2]
    def _branch(k):
        if k == 3:
            s = 2 * sp.sqrt(1 + tr)
            return [(Rm[2, 1] - Rm[1, 2]) / s, (Rm[0, 2] - Rm[2, 0]) / s, (Rm[1, 0] - Rm[0, 1]) / s, s / 4]
        i, j, k2 = k, (k + 1) % 3, (k + 2) % 3
        s = 2 * sp.sqrt(1 + Rm[i, i] - Rm[j, j] - Rm[k2, k2])
        out = [0, 0, 0, 0]
        out[i] = s / 4
        out[j] = (Rm[j, i] + Rm[i, j]) / s
        out[k2] = (Rm[k2, i] + Rm[i, k2]) / s
        out[3] = (Rm[k2, j] - Rm[j, k2]) / s
        return out
    br = [_branch(k) for k in (3, 0, 1, 2)]
    c_w = sp.And(tr >= Rm[0, 0], tr >= Rm[1, 1], tr >= Rm[2, 2])
    c_x = sp.And(Rm[0, 0] >= Rm[1, 1], Rm[0, 0] >= Rm[2, 2])
    c_y = Rm[1, 1] >= Rm[2, 2]
    from_R = sp.Matrix([sp.Piecewise((br[0][i], c_w), (br[1][i], c_x), (br[2][i], c_y), (br[3][i], True))
                        for i in range(4)])

    # Quaternion → intrinsic XYZ angles, branch-free near gimbal lock (Shoemake's residual method):
    # pitch = atan2(R02, |cos pitch|) with |cos pitch| = hypot(R12, R22); roll = atan2(−R12, R22);
    # yaw from what is left, Rx(roll)ᵀ R = Ry Rz, whose row 1 is (sin yaw, cos yaw, 0). At ±90° pitch
    # roll is whatever the rounding of R12, R22 says and yaw absorbs the rest, so the rotation is
    # reproduced to rounding. Only an exactly zero hypot takes the (roll = 0) branch.
    Rq = rotation_matrix(q)
    n = sp.sqrt(Rq[1, 2] ** 2 + Rq[2, 2] ** 2)
    exact_lock = sp.Eq(n, 0)
    s_roll = sp.Piecewise((0, exact_lock), (-Rq[1, 2] / n, True))
    c_roll = sp.Piecewise((1, exact_lock), (Rq[2, 2] / n, True))
    to_euler = sp.Matrix([
        sp.atan2(-Rq[1, 2], Rq[2, 2]),
        sp.atan2(Rq[0, 2], n),
        sp.atan2(c_roll * Rq[1, 0] + s_roll * Rq[2, 0], c_roll * Rq[1, 1] + s_roll * Rq[2, 1]),
    ])
    vnorm = sp.sqrt(q[0] ** 2 + q[1] ** 2 + q[2] ** 2)
    half = sp.atan2(vnorm, q[3])
    small = vnorm <= sp.Rational(1, 10**300)
    to_axis = sp.Matrix([sp.Piecewise((1 if i == 0 else 0, small), (q[i] / vnorm, True)) for i in range(3)])

    # The angle between attitudes q and q_ref: that of e = q_ref* ⊗ q, with |e_w| so that q and −q (one attitude)
    # give the same angle; atan2 keeps it accurate near 0 and near π alike.
    q_ref = vec("q_ref", 4)
    e = qmul(qconj(q_ref), q)
    err_angle = 2 * sp.atan2(sp.sqrt(e[0] ** 2 + e[1] ** 2 + e[2] ** 2), sp.Abs(e[3]))

    # The attitude-error chart of the wheel controllers (lavendersim.control.design): dtheta = 2 sgn(e_w) e_v with
    # e = q_ref* ⊗ q, the rotation vector of e to first order (|dtheta| = 2 sin(θ/2)), the same for q and −q;
    # e_w = 0 (a half turn) takes the + branch.
    chart = sp.Matrix([sp.Piecewise((-2 * e[i], e[3] < 0), (2 * e[i], True)) for i in range(3)])

    # Shortest arc taking the unit vector a onto the unit vector b: q ∝ [a × b, 1 + a·b]. When b is
    # (nearly) −a that direction is lost to rounding, so the half turn about an axis ⟂ a is taken
    # instead: a × e_x, or a × e_y when a lies within 45° of e_x.
    ua, ub = vec("a", 3), vec("b", 3)
    arc = sp.Matrix([*ua.cross(ub), 1 + ua.dot(ub)])
    perp = sp.Matrix([sp.Piecewise((e, ua[0] ** 2 <= sp.Rational(1, 2)), (f, True))
                      for e, f in zip(ua.cross(sp.Matrix([1, 0, 0])), ua.cross(sp.Matrix([0, 1, 0])))])
    flip = 1 + ua.dot(ub) <= sp.Rational(1, 10**12)
    from_two = sp.Matrix([sp.Piecewise((perp[i] / sp.sqrt(perp.dot(perp)), flip), (arc[i] / sp.sqrt(arc.dot(arc)), True))
                          for i in range(3)] + [sp.Piecewise((0, flip), (arc[3] / sp.sqrt(arc.dot(arc)), True))])

    # Near-unit renormalization without sqrt or division (the opt-in FMA tiles, after each RK4 step): q p(eps),
    # eps = |q|^2 - 1, p the series of 1/sqrt(1 + eps); the direction exact, |q| within 2^-53 of 1 while
    # |eps| <= QUAT_RENORM_EPS_MAX (the caller checks eps and takes quat_normalize beyond it).
    renorm_bound = _check_renorm(RENORM_ORDER)
    eps = sp.Symbol("eps_q", real=True)
    near = q * renorm_series(eps)

    Q = "quaternion (x, y, z, w), scalar last"
    return [
        Kernel("quat_mul", "Hamilton product", r"a \otimes b = \begin{bmatrix} a_w b_v + b_w a_v + a_v \times b_v \\ a_w b_w - a_v \cdot b_v \end{bmatrix}",
               [Arg("a", a, Q), Arg("b", b, Q)], [Arg("ab", qmul(a, b), Q)], g),
        Kernel("quat_conj", "Conjugate (inverse of a unit quaternion)", r"q^* = [-q_v, q_w]",
               [Arg("q", q, Q)], [Arg("q_conj", qconj(q), Q)], g),
        Kernel("quat_normalize", "Scale to unit length", r"\hat q = q / \lVert q \rVert",
               [Arg("q", q, Q)], [Arg("q_unit", q / qnorm, Q)], g),
        Kernel("quat_renormalize_near_unit", "Scale a near-unit quaternion to unit length without sqrt or division",
               r"\hat q = q\,(1 - \tfrac12\varepsilon + \tfrac38\varepsilon^2),\ \varepsilon = \lVert q \rVert^2 - 1",
               [Arg("q", q, Q + ", |q| near 1", "unit_quaternion")],
               [Arg("q_unit", near, Q + ", unit to rounding while |eps| <= QUAT_RENORM_EPS_MAX"),
                Arg("eps", eps, "|q|^2 - 1: the caller takes quat_normalize where |eps| > QUAT_RENORM_EPS_MAX (or NaN)")],
               g, where=[(eps, q.dot(q) - 1)],
               notes=[f"The Taylor series of 1/sqrt(1 + eps) to eps^{RENORM_ORDER} (checked at derive time): q's "
                      "direction exact (the polynomial has no real root), ||q_unit| - 1| <= "
                      f"{float(renorm_bound):.2g} from the series for |eps| <= QUAT_RENORM_EPS_MAX = 2^-18, below "
                      "a double's rounding; after an RK4 step from a unit q, eps is the step's rounding (~1e-16) "
                      "plus its O((|omega| dt)^6) norm error.",
                      "Not bitwise quat_normalize: the opt-in FMA tiles (Sim(..., contract=\"fma\")) use it."]),
        Kernel("quat_rotate", "Rotate a body vector into the world frame", r"v_w = R(q)\,v_b = (q \otimes [v_b,0] \otimes q^*)_v",
               [Arg("q", q, Q + ", unit, R_WB", "unit_quaternion"), Arg("v_b", v_b, "vector, body frame")],
               [Arg("v_w", rotate(q, v_b), "vector, world frame")], g),
        Kernel("quat_to_matrix", "Rotation matrix R_WB", r"R(q) = (q_w^2 - q_v^T q_v)\mathbf{1} + 2 q_v q_v^T + 2 q_w [q_v]_\times",
               [Arg("q", q, Q + ", unit", "unit_quaternion")], [Arg("R_wb", rotation_matrix(q), "3×3 rotation, body → world, row-major")], g),
        Kernel("matrix_to_quat", "Quaternion of a rotation matrix (Shepperd's branch on the largest component)",
               r"q_w = \tfrac12\sqrt{1+\operatorname{tr}R},\; q_v = \frac{1}{4q_w}\begin{bmatrix}R_{21}-R_{12}\\R_{02}-R_{20}\\R_{10}-R_{01}\end{bmatrix}\ \text{(or the analogous branch)}",
               [Arg("R_wb", Rm, "3×3 rotation, body → world, row-major", "real")], [Arg("q", from_R, Q)], g,
               notes=["Input must be a rotation matrix; tests draw it from a random unit quaternion."]),
        Kernel("axis_angle_to_quat", "Quaternion of a rotation by angle about a unit axis", r"q = [\hat u \sin(\theta/2), \cos(\theta/2)]",
               [Arg("axis", u, "unit axis (any frame)", "unit_vector"), Arg("angle", theta, "angle, rad")],
               [Arg("q", axis_angle_quat(u, theta), Q)], g),
        Kernel("quat_from_two_vectors", "Shortest-arc rotation taking one unit vector onto another",
               r"q = \frac{[a \times b,\ 1 + a \cdot b]}{\lVert [a \times b,\ 1 + a \cdot b] \rVert}"
               r"\ \text{(a half turn about an axis} \perp a \text{ when } b \approx -a)",
               [Arg("a", ua, "unit vector (any frame)", "unit_vector"), Arg("b", ub, "unit vector, same frame", "unit_vector")],
               [Arg("q", from_two, Q + ", unit: R(q) a = b")], g),
        Kernel("quat_to_axis_angle", "Unit axis and angle in [0, 2π] of a unit quaternion", r"\theta = 2\,\operatorname{atan2}(\lVert q_v\rVert, q_w),\ \hat u = q_v/\lVert q_v\rVert",
               [Arg("q", q, Q + ", unit", "unit_quaternion")],
               [Arg("axis", to_axis, "unit axis ([1,0,0] for the identity)"), Arg("angle", 2 * half, "angle, rad")], g),
        Kernel("quat_error_angle", "Angle of the rotation between two attitudes (q and −q alike), in [0, π]",
               r"\theta = 2\,\operatorname{atan2}(\lVert e_v\rVert, |e_w|),\ e = q_{ref}^* \otimes q",
               [Arg("q", q, Q + ", unit", "unit_quaternion"), Arg("q_ref", q_ref, Q + ", unit", "unit_quaternion")],
               [Arg("angle", err_angle, "angle, rad")], g),
        Kernel("quat_error_chart", "Attitude-error chart of the wheel controllers: 2 sgn(e_w) e_v (q and −q alike)",
               r"\delta\theta = 2\,\operatorname{sgn}(e_w)\,e_v,\ e = q_{ref}^* \otimes q"
               r"\ (\lVert\delta\theta\rVert = 2\sin(\theta/2),\ \operatorname{sgn}(0) = 1)",
               [Arg("q", q, Q + ", unit, body to world", "unit_quaternion"),
                Arg("q_ref", q_ref, Q + ", unit, body to world", "unit_quaternion")],
               [Arg("dtheta", chart, "attitude error, body frame, rad (the rotation vector of e to first order)")], g),
        Kernel("euler_xyz_to_quat", "Quaternion of intrinsic XYZ Euler angles, R = Rx(roll) Ry(pitch) Rz(yaw)",
               r"q = q_x(a) \otimes q_y(b) \otimes q_z(c)",
               [Arg("roll", ea, "rad"), Arg("pitch", eb, "rad"), Arg("yaw", ec, "rad")], [Arg("q", euler_xyz_quat(ea, eb, ec), Q)], g),
        Kernel("quat_to_euler_xyz", "Intrinsic XYZ Euler angles of a unit quaternion, exact through gimbal lock",
               r"a = \operatorname{atan2}(-R_{12}, R_{22}),\ b = \operatorname{atan2}(R_{02}, \sqrt{R_{12}^2 + R_{22}^2}),\ "
               r"c = \operatorname{atan2}(\cos a\,R_{10} + \sin a\,R_{20},\ \cos a\,R_{11} + \sin a\,R_{21})",
               [Arg("q", q, Q + ", unit", "unit_quaternion")], [Arg("rpy", to_euler, "(roll, pitch, yaw), rad")], g),
        Kernel("quat_derivative_world", "Quaternion rate from world-frame angular velocity", r"\dot q = \tfrac12 [\omega_w, 0] \otimes q",
               [Arg("q", q, Q), Arg("omega_w", omega_w, "angular velocity, world frame, rad/s")], [Arg("q_dot", qd_world, "1/s")], g),
        Kernel("quat_derivative_body", "Quaternion rate from body-frame angular velocity", r"\dot q = \tfrac12 q \otimes [\omega_b, 0]",
               [Arg("q", q, Q), Arg("omega_b", omega_b, "angular velocity, body frame, rad/s")], [Arg("q_dot", qd_body, "1/s")], g),
        Kernel("integrate_orientation", "One explicit world-form step, then normalization (the chapter's default)",
               r"q_{n+1} = \frac{q_n + \Delta t\,\tfrac12[\omega_w,0]\otimes q_n}{\lVert q_n + \Delta t\,\tfrac12[\omega_w,0]\otimes q_n \rVert}",
               [Arg("q", q, Q), Arg("omega_w", omega_w, "angular velocity, world frame, rad/s"), Arg("dt", dt, "time step, s", "positive")],
               [Arg("q_next", q_step / norm, Q + ", unit")], g),
    ]
