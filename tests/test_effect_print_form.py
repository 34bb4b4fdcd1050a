"""The form derive prints an effect's outputs in (issue 30): STATE.R_WB times a 3-vector as the quaternion sandwich
(derive/quaternion.py Rotation), and common factors pulled out of sums when that is cheaper after CSE
(derive/effect.py printed_form) — the same functions as declared, cheaper, at rounding level from a literal
evaluation."""
from __future__ import annotations

import numpy as np
import pytest
import sympy as sp

from lavendersim.derive.effect import STATE, _ops_after_cse, constant_factors, effect, param, printed_form
from lavendersim.derive.kernel import Arg, vec
from lavendersim.derive.quaternion import Rotation, rotate_to_body, rotate_to_world, rotation_matrix

Q, V = vec("q", 4), vec("v", 3)


def _zero(m: sp.Matrix) -> bool:
    return m.applyfunc(sp.expand) == sp.zeros(*m.shape)


def test_rotation_times_a_vector_is_the_sandwich_and_the_same_polynomial():
    R, M = Rotation(Q), rotation_matrix(Q)
    assert R == M and R.T == M.T                     # the entries are the matrix's
    assert (R * V) == rotate_to_world(Q, V) and (R.T * V) == rotate_to_body(Q, V)
    assert (R @ V) == rotate_to_world(Q, V)
    assert _zero(R * V - M * V) and _zero(R.T * V - M.T * V)
    assert isinstance(R.T, Rotation) and R.T.transposed and not R.T.T.transposed
    assert _ops_after_cse(list(R.T * V)) < _ops_after_cse(list(M.T * V))
    assert _ops_after_cse(list(R * V)) < _ops_after_cse(list(M * V))


def test_every_other_use_of_a_rotation_is_a_plain_matrix():
    R, M = Rotation(Q), rotation_matrix(Q)
    for out, want in ((R * M, M * M), (M * R, M * M), (V.T * R, V.T * M), (R + M, 2 * M), (-R, -M), (2 * R, 2 * M),
                      (R.subs(Q[0], 0), M.subs(Q[0], 0)), (R.copy(), M), (R * sp.Matrix([V, V]).reshape(3, 2),
                                                                           M * sp.Matrix([V, V]).reshape(3, 2))):
        assert type(out) is sp.MutableDenseMatrix
        assert _zero(out - want)
    with pytest.raises(TypeError, match="not assignable"):
        R[0, 0] = 1


def test_state_rotations_print_as_the_sandwich():
    assert STATE.omega_w == rotate_to_world(STATE.q, STATE.omega_b)
    c = param("c", rule="nonnegative")
    d = effect("body_drag", "drag", params=[c], torque_b=-c.symbol * STATE.omega_b)
    assert _zero(d.torque_world - rotation_matrix(STATE.q) * (-c.symbol * STATE.omega_b))
    assert d.torque_world == rotate_to_world(STATE.q, -c.symbol * STATE.omega_b)


def _gradient_torque() -> tuple[sp.Matrix, list]:
    """The guide's gravity-gradient torque (docs/extending.md), written as the guide writes it."""
    mu, center = param("mu", rule="positive"), param("center_w", shape=3)
    r_w = STATE.p_w - center.symbol
    r = sp.sqrt(r_w.dot(r_w))
    r_hat_b = STATE.R_WB.T * r_w / r
    tau_b = 3 * mu.symbol / r**3 * r_hat_b.cross(sp.diag(*STATE.I_b) * r_hat_b)
    return tau_b, [mu, center]


def test_the_gradient_torque_prints_factored_cheaper_and_equal():
    tau_b, params = _gradient_torque()
    (printed,) = printed_form([tau_b])
    assert printed != tau_b
    I0, I1, I2 = STATE.I_b
    assert any(f.expand() == (I2 - I1) or f.expand() == (I1 - I2) for f in sp.Mul.make_args(printed[0]))
    assert _ops_after_cse(list(printed)) < _ops_after_cse(list(tau_b))
    # the same values at random points (the proof is symbolic; this checks it on numbers)
    rng = np.random.default_rng(30)
    syms = sorted(tau_b.free_symbols, key=str)
    f_decl, f_print = sp.lambdify(syms, tau_b, "numpy"), sp.lambdify(syms, printed, "numpy")
    for _ in range(20):
        x = rng.normal(size=len(syms)) + 2.0
        a, b = np.asarray(f_decl(*x), float), np.asarray(f_print(*x), float)
        assert np.allclose(a, b, rtol=1e-12, atol=0.0)
    # the effect's kernels print this form
    # the effect's kernels print this form, each product of per-body constants (3 μ (I_z − I_y)) named once
    d = effect("gg", "gradient", params=params, torque_b=tau_b)
    k = d.body_kernel()
    assert [s.name for s, _ in k.where] == ["kc0", "kc1", "kc2"]
    assert all(not (e.free_symbols & set(STATE.q) or e.free_symbols & set(STATE.p_w)) for _, e in k.where)
    assert k.outputs[0].value.xreplace(dict(k.where)) == printed
    assert d.torque_b == tau_b                       # the declaration itself is kept as written


def test_a_form_that_is_not_cheaper_is_kept_as_declared():
    a, b = sp.symbols("a b")
    v = sp.Matrix([a + b, a * b, a - b])           # nothing to factor
    assert printed_form([v])[0] is v
    w = sp.Matrix([a * b + a, 0, 0])                # a (b + 1): one multiply either way, no fewer operations
    assert printed_form([w])[0] is w


def test_constant_factors_are_named_only_beside_the_state_and_avoid_input_names():
    mu, kc0 = sp.symbols("mu kc0", real=True)
    I0, I1, _ = STATE.I_b
    q0, q1 = STATE.q[0], STATE.q[1]
    outs = [Arg("tau", sp.Matrix([3 * mu * (I1 - I0) * q0 * q1, 2 * mu * q0, 3 * mu * (I1 - I0)]), "torque")]
    new, where = constant_factors(outs, {"kc0", "mu"})
    assert [s.name for s, _ in where] == ["kc_0"]                 # kc0 is an input name: not reused
    assert where[0][1] == 3 * mu * (I1 - I0)
    assert new[0].value[0] == where[0][0] * q0 * q1
    assert new[0].value[1] == 2 * mu * q0                        # one constant factor beside 2: left as it is
    assert new[0].value[2] == 3 * mu * (I1 - I0)                 # reads no state: nothing to hoist
    assert outs[0].value[0] == 3 * mu * (I1 - I0) * q0 * q1      # the input is not changed
    assert kc0 not in new[0].value.free_symbols
