"""lavendersim.derive.symbolic: the public SymPy layer equals the textbook formulas and the kernels."""
from __future__ import annotations

import lavendersim.derive as D
import numpy as np
import pytest
import sympy as sp
from lavendersim.derive import symbolic as S

from lavendersim.kernels import K

m, w, h, d, r = (S.symbols(n) for n in ("m", "w", "h", "d", "r"))


def test_box_inertia_is_the_textbook_formula_and_simplified():
    I = S.inertia_box()
    textbook = sp.diag(m * (h**2 + d**2) / 12, m * (w**2 + d**2) / 12, m * (w**2 + h**2) / 12)
    assert isinstance(I, sp.MatrixBase) and I.shape == (3, 3)
    assert (I - textbook).applyfunc(sp.simplify) == sp.zeros(3, 3)
    # printed simplified: no d left in the zz entry (it used to print d*(h**2*m/(12*d) + m*w**2/(12*d)))
    assert I[2, 2] == m * (h**2 + w**2) / 12
    assert d not in I[2, 2].free_symbols
    for i in range(3):
        for j in range(3):
            if i != j:
                assert I[i, j] == 0


def test_cylinder_and_sphere_are_the_textbook_formulas():
    I_c = S.inertia_cylinder()
    assert (I_c - sp.diag(m * (3 * r**2 + h**2) / 12, m * (3 * r**2 + h**2) / 12, m * r**2 / 2)
            ).applyfunc(sp.simplify) == sp.zeros(3, 3)
    assert (S.inertia_sphere() - sp.Rational(2, 5) * m * r**2 * sp.eye(3)).applyfunc(sp.simplify) == sp.zeros(3, 3)


def test_numbers_in_numbers_out_and_the_kernels_agree():
    assert S.inertia_box(12, 1, 2, 3) == sp.diag(13, 10, 5)
    f = sp.lambdify([m, w, h, d], S.inertia_box(), "numpy")
    got = np.diag(f(2.0, 0.3, 0.2, 0.1))
    np.testing.assert_allclose(got, K.inertia_box(2.0, 0.3, 0.2, 0.1), rtol=1e-15)
    g = sp.lambdify([m, r, h], S.inertia_cylinder(), "numpy")
    np.testing.assert_allclose(np.diag(g(1.5, 0.2, 0.7)), K.inertia_cylinder(1.5, 0.2, 0.7), rtol=1e-15)


def test_euler_equations_lambdified_match_the_numpy_kernel():
    I_b, omega_b, tau_b = S.symbols("I_b"), S.symbols("omega_b"), S.symbols("tau_b")
    f = sp.lambdify([I_b, omega_b, tau_b], S.euler_equations(), "numpy")
    rng = np.random.default_rng(14)
    for _ in range(20):
        Ib = rng.uniform(0.1, 3.0, 3)
        w_b = rng.normal(size=3) * 5
        t_b = rng.normal(size=3)
        want = K.euler_equations(Ib, w_b, t_b)
        np.testing.assert_allclose(np.asarray(f(Ib, w_b, t_b), dtype=float).ravel(), want, rtol=1e-13, atol=1e-13)


def test_euler_equations_are_newton_euler():
    I_b, wv, tv = S.symbols("I_b"), S.symbols("omega_b"), S.symbols("tau_b")
    I = sp.diag(*I_b)
    ref = I.inv() * (tv - wv.cross(I * wv))
    assert (S.euler_equations() - ref).applyfunc(sp.simplify) == sp.zeros(3, 1)


def test_quaternion_kinematics_body_and_world_forms_agree():
    q, w_b = S.symbols("q"), S.symbols("omega_b")
    w_w = S.rotation_matrix(q) * w_b
    diff = S.quat_rate_world(q, w_w) - S.quat_rate_body(q, w_b)
    # equal on the unit sphere: substitute q_w² = 1 − q_x² − q_y² − q_z²
    qx, qy, qz, qw = q
    on_sphere = diff.applyfunc(lambda e: sp.simplify(sp.expand(e).subs(qw**2, 1 - qx**2 - qy**2 - qz**2)))
    assert on_sphere == sp.zeros(4, 1)
    fb = sp.lambdify([q, w_b], S.quat_rate_body(), "numpy")
    fw = sp.lambdify([q, S.symbols("omega_w")], S.quat_rate_world(), "numpy")
    rng = np.random.default_rng(3)
    qn = rng.normal(size=4)
    qn /= np.linalg.norm(qn)
    wb = rng.normal(size=3)
    np.testing.assert_allclose(np.ravel(fb(qn, wb)), K.quat_derivative_body(qn, wb), rtol=1e-14, atol=1e-15)
    ww = K.quat_rotate(qn, wb)
    np.testing.assert_allclose(np.ravel(fw(qn, ww)), K.quat_derivative_world(qn, ww), rtol=1e-14, atol=1e-15)


def test_reexported_from_derive_and_usable_with_printers():
    assert D.inertia_box is S.inertia_box and D.euler_equations is S.euler_equations
    assert D.symbolic is S
    assert "frac{m" in sp.latex(D.inertia_box()[2, 2]) or "m \\left(" in sp.latex(D.inertia_box()[2, 2])
    with pytest.raises(KeyError, match="known"):
        S.symbols("nope")
    with pytest.raises(AttributeError):
        D.no_such_name  # noqa: B018
