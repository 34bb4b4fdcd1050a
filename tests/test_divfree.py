"""Euler's equations printed division-free (issue 12): the kernels that take I_b compute the Euler
coefficients c_b = (k_x, k_y, k_z, r_x, r_y, r_z) (k_x = (I_y - I_z)/I_x, r_x = 1/I_x) as named
subexpressions (derive Kernel.where) and print exactly the arithmetic of the *_c kernels that take c_b,
which the RK4 fast path and the SIMD tiles call with c_b computed once per call. So:
the *_c kernels on euler_coefficients(I_b) give bitwise the I_b kernels (C and NumPy), C == NumPy
bitwise, the printed *_c right-hand sides divide by nothing, and the C RK4 fast path (every ISA) is
bitwise the NumPy backend's RK4 on the I_b kernels, with applied torques too."""
from __future__ import annotations

import re
from pathlib import Path

import numpy as np
import pytest
import sympy as sp

import lavendersim as lv
from lavendersim import _lavender_c as C
from lavendersim.backends.c_backend import eval_kernel


def _gen_dir() -> Path:
    from lavendersim.backends.c_backend import generated_dir

    return generated_dir()


def _kn():
    from lavendersim.generated import kernels_numpy

    return kernels_numpy


def _bodies(n: int, seed: int):
    rng = np.random.default_rng(seed)
    I_b = 0.05 + rng.random((n, 3)) * rng.choice([1.0, 10.0, 1e3], (n, 1))
    I_b[::7, 1] = I_b[::7, 2]                      # symmetric tops: k_x exactly 0
    x = rng.standard_normal((n, 13)) * np.array([1.0] * 7 + [1.0] * 3 + [5.0] * 3)
    tau_w = rng.standard_normal((n, 3))
    F_w = rng.standard_normal((n, 3))
    m = 0.1 + rng.random(n)
    return I_b, x, tau_w, F_w, m


@pytest.mark.parametrize("backend", ["c", "numpy"])
def test_c_kernels_on_the_coefficients_are_the_inertia_kernels_bitwise(backend):
    K = _kn()
    ev = (lambda name, *a: eval_kernel(name, *a)) if backend == "c" else (lambda name, *a: getattr(K, name)(*a))
    I_b, x, tau_w, F_w, m = _bodies(257, seed=12)
    c_b = ev("euler_coefficients", I_b)
    assert c_b.shape == (257, 6)
    np.testing.assert_array_equal(c_b[:, 0], (I_b[:, 1] - I_b[:, 2]) / I_b[:, 0])   # correctly rounded quotient
    np.testing.assert_array_equal(c_b[:, 4], 1.0 / I_b[:, 1])
    assert np.all(c_b[::7, 0] == 0.0)
    np.testing.assert_array_equal(ev("rigid_body_rhs_free_c", x, c_b), ev("rigid_body_rhs_free", x, I_b))
    np.testing.assert_array_equal(ev("rigid_body_rhs_torque_c", x, c_b, tau_w), ev("rigid_body_rhs_torque", x, I_b, tau_w))
    np.testing.assert_array_equal(ev("rigid_body_rhs_c", x, m, c_b, F_w, tau_w), ev("rigid_body_rhs", x, m, I_b, F_w, tau_w))
    free = ev("rigid_body_rhs_free", x, I_b)
    np.testing.assert_array_equal(free[:, 10], c_b[:, 0] * x[:, 11] * x[:, 12])   # the printed grouping


def test_c_and_numpy_print_the_same_coefficient_arithmetic():
    K = _kn()
    I_b, x, tau_w, F_w, m = _bodies(129, seed=3)
    c_b = K.euler_coefficients(I_b)
    np.testing.assert_array_equal(eval_kernel("euler_coefficients", I_b), c_b)
    for name, args in (("rigid_body_rhs_free_c", (x, c_b)), ("rigid_body_rhs_torque_c", (x, c_b, tau_w)),
                       ("rigid_body_rhs_c", (x, m, c_b, F_w, tau_w)), ("euler_equations", (I_b, x[:, 10:], tau_w))):
        np.testing.assert_array_equal(eval_kernel(name, *args), getattr(K, name)(*args), err_msg=name)


def _c_body(name: str) -> str:
    src = (_gen_dir() / "kernels.c").read_text(encoding="utf-8")
    m = re.search(r"^void lv_" + name + r"\(.*?^}", src, re.S | re.M)
    assert m, name
    return m.group(0)


@pytest.mark.parametrize("name", ["rigid_body_rhs_free_c", "rigid_body_rhs_torque_c"])
def test_printed_coefficient_right_hand_sides_divide_by_nothing(name):
    body = _c_body(name)
    assert "/" not in body.replace("(1.0/2.0)", "")          # the only quotient is the constant 1/2
    assert "x_dot[10] = c_b_0*x_11*x_12" in body


def test_inertia_kernels_print_the_coefficients_first_as_named_constants():
    for name in ("rigid_body_rhs_free", "rigid_body_rhs_torque", "rigid_body_rhs", "euler_coefficients"):
        body = _c_body(name)
        assert "const double c_b_0 = (I_b_1 - I_b_2)/I_b_0;" in body, name
        assert body.index("c_b_0 = ") < body.index("x_dot[" if "rhs" in name else "c_b[0]"), name
    # the free kernel needs only the k's: unused named subexpressions are not printed
    assert "c_b_3" not in _c_body("rigid_body_rhs_free")


def test_where_is_substituted_in_output_exprs_and_kept_in_printed_exprs():
    from lavendersim.derive.codegen import CPrinter, Printed, _c_kernel
    from lavendersim.derive.kernel import Arg, Kernel, vec

    a, c = vec("a", 2), sp.Symbol("c_0", real=True)
    k = Kernel("demo", "demo", "", [Arg("a", a, "in")], [Arg("y", sp.Matrix([c * a[0] * a[1]]), "out")],
               where=[(c, (a[0] - a[1]) / a[1])])
    assert k.output_exprs[0] == (a[0] - a[1]) / a[1] * a[0] * a[1]
    assert k.printed_exprs[0] == c * a[0] * a[1]
    text = "\n".join(_c_kernel(Printed(k), CPrinter(), "lv_"))
    assert "const double c_0 = (a_0 - a_1)/a_1;" in text and "y[0] = a_0*a_1*c_0;" in text
    with pytest.raises(ValueError, match="fresh symbol"):
        Kernel("bad", "bad", "", [Arg("a", a, "in")], [Arg("y", a, "out")], where=[(a[0], a[1])])


@pytest.fixture
def levels():
    best = C.isa(-1)[2]
    yield list(range(best + 1))
    C.isa(-1)


@pytest.mark.parametrize("effect_every", [0, 3])
def test_c_rk4_at_every_isa_is_the_numpy_backend_bitwise(levels, effect_every):
    """The C fast path (c_b once per call, *_c kernels; scalar and SIMD tiles) against the NumPy backend
    (the I_b kernels, c_b recomputed in every stage) on random bodies, a torque on every third."""
    rng = np.random.default_rng(7 + effect_every)
    sc = lv.Scene()
    for i in range(37):
        sc.add_body(lv.Body.box(f"b{i}", 0.5 + rng.random(), tuple(0.1 + rng.random(3)),
                                q=tuple(rng.standard_normal(4)), omega_b=tuple(3.0 * rng.standard_normal(3)),
                                v_w=tuple(rng.standard_normal(3)), p_w=tuple(rng.standard_normal(3))))
        if effect_every and i % effect_every == 0:
            sc.add_effect("applied_torque", body=f"b{i}", torque_w=tuple(1e-1 * rng.standard_normal(3)))
    ref = lv.Sim(sc, dt=1e-2, integrator="rk4", backend="numpy")
    ref.run(120)
    for level in levels:
        C.isa(level)
        sim = lv.Sim(sc, dt=1e-2, integrator="rk4", backend="c")
        sim.run(120)
        np.testing.assert_array_equal(np.asarray(sim.x), np.asarray(ref.x), err_msg=C.isa(level)[1])
