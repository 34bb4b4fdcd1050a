"""The symbolic layer in the open: the SymPy expressions LavenderSim's kernels are printed from.

Every function here returns a plain ``sympy.Matrix`` built by the same derivation that
``lavendersim derive`` prints into generated/ (derive/inertia.py, derive/rigid_body.py,
derive/quaternion.py) — nothing is written a second time — simplified for reading, and ready for
``sympy.lambdify``, ``sympy.latex`` or any SymPy printer.

Conventions (as everywhere in LavenderSim): body frame at the centre of mass along the principal
axes; quaternions (x, y, z, w), scalar last, q = R_WB (body to world); ``_b`` body frame, ``_w``
world frame; SI units (kg, m, kg·m², rad/s, N·m).

Arguments default to symbols (see :func:`symbols`); pass your own symbols or numbers instead.

Examples
--------
>>> import sympy as sp
>>> from lavendersim.derive import symbolic as S
>>> S.inertia_box()
Matrix([
[m*(d**2 + h**2)/12,                  0,                  0],
[                 0, m*(d**2 + w**2)/12,                  0],
[                 0,                  0, m*(h**2 + w**2)/12]])
>>> I_x, I_y, I_z = sp.symbols("I_x I_y I_z", positive=True)
>>> S.euler_equations()[0]
omega_y*omega_z*(I_y - I_z)/I_x + tau_x/I_x
>>> f = sp.lambdify([S.symbols("I_b"), S.symbols("omega_b"), S.symbols("tau_b")], S.euler_equations(), "numpy")
>>> [round(float(v), 4) for v in f([1.0, 2.0, 3.0], [0.1, 1.0, 0.1], [0.0, 0.0, 0.0]).ravel()]
[-0.1, 0.01, -0.0333]
"""
from __future__ import annotations

import sympy as sp

from . import inertia as _inertia
from . import quaternion as _quat
from . import rigid_body as _rb

__all__ = ["symbols", "inertia_box", "inertia_cylinder", "inertia_sphere", "parallel_axis", "euler_equations",
           "rotation_matrix", "quat_product", "quat_rate_body", "quat_rate_world"]

# name -> how to build the default symbol(s); lengths, masses and moments are positive, rates real
_DEFAULTS = {
    "m": lambda: sp.Symbol("m", positive=True),
    "w": lambda: sp.Symbol("w", positive=True),
    "h": lambda: sp.Symbol("h", positive=True),
    "d": lambda: sp.Symbol("d", positive=True),
    "r": lambda: sp.Symbol("r", positive=True),
    "I_b": lambda: sp.Matrix(sp.symbols("I_x I_y I_z", positive=True)),
    "omega_b": lambda: sp.Matrix(sp.symbols("omega_x omega_y omega_z", real=True)),
    "omega_w": lambda: sp.Matrix(sp.symbols("omega_wx omega_wy omega_wz", real=True)),
    "tau_b": lambda: sp.Matrix(sp.symbols("tau_x tau_y tau_z", real=True)),
    "q": lambda: sp.Matrix(sp.symbols("q_x q_y q_z q_w", real=True)),
    "offset": lambda: sp.Matrix(sp.symbols("d_x d_y d_z", real=True)),
}


def symbols(name: str):
    """The default symbol (or column of symbols) this module uses for an argument.

    Parameters
    ----------
    name : {"m", "w", "h", "d", "r", "I_b", "omega_b", "omega_w", "tau_b", "q", "offset"}
        ``m`` mass (kg); ``w, h, d`` box sides along body x, y, z (m); ``r`` radius (m); ``I_b``
        principal moments (I_x, I_y, I_z), kg·m²; ``omega_b``/``omega_w`` angular velocity in the body/world
        frame, rad/s; ``tau_b`` torque, body frame, N·m; ``q`` quaternion (q_x, q_y, q_z, q_w);
        ``offset`` a displacement (d_x, d_y, d_z), m.

    Returns
    -------
    sympy.Symbol or sympy.Matrix
        A Symbol for a scalar, a column Matrix (3×1 or 4×1) for a vector. SymPy symbols with the same
        name and assumptions are equal, so separate calls give the same symbols.

    Raises
    ------
    KeyError
        For an unknown name (the message lists the known ones).
    """
    if name not in _DEFAULTS:
        raise KeyError(f"unknown symbol {name!r}; known: {', '.join(_DEFAULTS)}")
    return _DEFAULTS[name]()


def _or(value, name: str):
    if value is None:
        return symbols(name)
    if name in ("I_b", "omega_b", "omega_w", "tau_b", "q", "offset"):
        return sp.Matrix(value)
    return sp.sympify(value)


def _tidy(M: sp.Matrix) -> sp.Matrix:
    """Each entry simplified, then factored (m*(h**2 + w**2)/12 rather than d*(h**2*m/(12*d) + ...))."""
    return M.applyfunc(lambda e: sp.factor(sp.simplify(e)))


def inertia_box(m=None, w=None, h=None, d=None) -> sp.Matrix:
    """Inertia tensor of a uniform solid box about its centre, body frame, from the volume integral.

    ``I = ∫ (|r|² 1 − r rᵀ) dm`` over the box (derive/inertia.py), simplified.

    Parameters
    ----------
    m : sympy expression or number, optional
        Mass, kg (default the positive symbol ``m``).
    w, h, d : sympy expression or number, optional
        Full side lengths along body x, y, z, m (default positive symbols).

    Returns
    -------
    sympy.Matrix, shape (3, 3)
        ``m/12 · diag(h² + d², w² + d², w² + h²)``, kg·m².

    Examples
    --------
    >>> from lavendersim.derive.symbolic import inertia_box
    >>> inertia_box(12, 1, 2, 3)
    Matrix([
    [13,  0, 0],
    [ 0, 10, 0],
    [ 0,  0, 5]])
    """
    return _tidy(_inertia.box_inertia(_or(m, "m"), _or(w, "w"), _or(h, "h"), _or(d, "d")))


def inertia_cylinder(m=None, r=None, h=None) -> sp.Matrix:
    """Inertia tensor of a uniform solid cylinder (axis along body z) about its centre, body frame.

    Parameters
    ----------
    m : sympy expression or number, optional
        Mass, kg.
    r : sympy expression or number, optional
        Radius, m.
    h : sympy expression or number, optional
        Height along body z, m.

    Returns
    -------
    sympy.Matrix, shape (3, 3)
        ``diag(m(3r² + h²)/12, m(3r² + h²)/12, m r²/2)``, kg·m².
    """
    return _tidy(_inertia.cylinder_inertia(_or(m, "m"), _or(r, "r"), _or(h, "h")))


def inertia_sphere(m=None, r=None) -> sp.Matrix:
    """Inertia tensor of a uniform solid sphere about its centre.

    Parameters
    ----------
    m : sympy expression or number, optional
        Mass, kg.
    r : sympy expression or number, optional
        Radius, m.

    Returns
    -------
    sympy.Matrix, shape (3, 3)
        ``2/5 m r² 1``, kg·m².
    """
    return _tidy(_inertia.sphere_inertia(_or(m, "m"), _or(r, "r")))


def parallel_axis(I_c: sp.Matrix, m=None, offset=None) -> sp.Matrix:
    """Inertia about a point displaced by `offset` from the centre of mass (Steiner).

    Parameters
    ----------
    I_c : sympy.Matrix, shape (3, 3)
        Inertia about the COM, kg·m².
    m : sympy expression or number, optional
        Mass, kg.
    offset : sequence of 3, optional
        Displacement of the point from the COM, same frame as `I_c`, m.

    Returns
    -------
    sympy.Matrix, shape (3, 3)
        ``I_c + m(|d|² 1 − d dᵀ)``.
    """
    return _tidy(_inertia.parallel_axis(sp.Matrix(I_c), _or(m, "m"), _or(offset, "offset")))


def euler_equations(I_b=None, omega_b=None, tau_b=None) -> sp.Matrix:
    """Euler's rotation equations solved for the angular acceleration, body frame.

    ``I ω̇ + ω × (I ω) = τ`` with principal moments, per axis
    ``ω̇_x = ((I_y − I_z)/I_x) ω_y ω_z + τ_x/I_x`` (and cyclic): the expression the ``euler_equations``
    kernel is printed from (derive/rigid_body.py), there with the inertia-only coefficients
    ``(I_y − I_z)/I_x`` and ``1/I_x`` computed first as named subexpressions.

    Parameters
    ----------
    I_b : sequence of 3, optional
        Principal moments (I_x, I_y, I_z), kg·m².
    omega_b : sequence of 3, optional
        Angular velocity, body frame, rad/s.
    tau_b : sequence of 3, optional
        Torque about the COM, body frame, N·m (pass ``[0, 0, 0]`` for torque-free motion).

    Returns
    -------
    sympy.Matrix, shape (3, 1)
        ``omega_dot_b``, rad/s².
    """
    return _rb.euler_rhs(_or(I_b, "I_b"), _or(omega_b, "omega_b"), _or(tau_b, "tau_b"))


def rotation_matrix(q=None) -> sp.Matrix:
    """The rotation matrix R_WB (body to world) of a unit quaternion.

    Parameters
    ----------
    q : sequence of 4, optional
        Quaternion (x, y, z, w), unit.

    Returns
    -------
    sympy.Matrix, shape (3, 3)
    """
    return _quat.rotation_matrix(_or(q, "q"))


def quat_product(a, b) -> sp.Matrix:
    """Hamilton product a ⊗ b of (x, y, z, w) quaternions.

    Parameters
    ----------
    a, b : sequence of 4
        Quaternions (x, y, z, w).

    Returns
    -------
    sympy.Matrix, shape (4, 1)
    """
    return _quat.qmul(sp.Matrix(a), sp.Matrix(b))


def quat_rate_body(q=None, omega_b=None) -> sp.Matrix:
    """Quaternion kinematics with the body-frame angular velocity: ``q̇ = ½ q ⊗ [ω_b, 0]``.

    Parameters
    ----------
    q : sequence of 4, optional
        Orientation R_WB (x, y, z, w).
    omega_b : sequence of 3, optional
        Angular velocity, body frame, rad/s.

    Returns
    -------
    sympy.Matrix, shape (4, 1)
        ``q_dot``, 1/s.
    """
    return _quat.quat_rate_body(_or(q, "q"), _or(omega_b, "omega_b"))


def quat_rate_world(q=None, omega_w=None) -> sp.Matrix:
    """Quaternion kinematics with the world-frame angular velocity: ``q̇ = ½ [ω_w, 0] ⊗ q``.

    Equal to :func:`quat_rate_body` with ``omega_w = R(q) omega_b`` (for a unit q).

    Parameters
    ----------
    q : sequence of 4, optional
        Orientation R_WB (x, y, z, w).
    omega_w : sequence of 3, optional
        Angular velocity, world frame, rad/s.

    Returns
    -------
    sympy.Matrix, shape (4, 1)
        ``q_dot``, 1/s.
    """
    return _quat.quat_rate_world(_or(q, "q"), _or(omega_w, "omega_w"))
