"""The attitude-error angle, written once in derive (kernel quat_error_angle), and the C kernels called on
Python numbers (c_backend.scalar_kernel), which the env's step uses for it."""
from __future__ import annotations

import functools
import math

import gymnasium
import numpy as np
import pytest

from lavendersim import control as lc
from lavendersim.backends import c_backend  # required, never skipped: `pip install -e .` builds it
from lavendersim.envs.reaction_wheel_cube import error_angle_fn
from lavendersim.generated import kernels_numpy as K


def unit_quats(rng, n):
    q = rng.standard_normal((n, 4))
    return q / np.linalg.norm(q, axis=1, keepdims=True)


@pytest.mark.parametrize("name, n_in", [("quat_error_angle", 8), ("quat_mul", 8), ("quat_to_axis_angle", 4),
                                        ("rigid_body_rhs_free", 16)])
def test_scalar_kernel_is_eval_kernel_bitwise(name, n_in):
    rng = np.random.default_rng(7)
    f = c_backend.scalar_kernel(name)
    _, in_spec, _ = K.KERNELS[name]
    assert sum(int(np.prod(s, dtype=int)) for _, s in in_spec) == n_in
    for _ in range(20):
        row = rng.standard_normal(n_in)
        args, col = [], 0
        for _, shape in in_spec:
            size = int(np.prod(shape, dtype=int))
            args.append(row[col:col + size].reshape(shape))
            col += size
        ref = c_backend.eval_kernel(name, *args)
        ref = np.concatenate([np.ravel(r) for r in ref]) if isinstance(ref, tuple) else np.ravel(ref)
        got = f(*row.tolist())
        got = np.atleast_1d(np.asarray(got, dtype=float))
        assert isinstance(f(*row.tolist()), float if ref.size == 1 else tuple)
        np.testing.assert_array_equal(got, ref)


def test_scalar_kernel_rejects_bad_calls():
    f = c_backend.scalar_kernel("quat_error_angle")
    with pytest.raises(TypeError, match=r"quat_error_angle.*expected 8 numbers, got 7"):
        f(0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0)
    with pytest.raises(TypeError):
        f(0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, "1")
    with pytest.raises(KeyError, match="no_such_kernel"):
        c_backend.scalar_kernel("no_such_kernel")
    with pytest.raises(ValueError, match="out of range"):
        c_backend._c.call_kernel(10**6, 1.0)


def test_error_angle_is_the_rotation_angle():
    """2 atan2(|e_v|, |e_w|) is the angle of the rotation q_ref* ⊗ q: θ about any axis from any reference, the
    same for −q, and accurate to a few ulps of θ from 1e-9 rad up to a half turn."""
    rng = np.random.default_rng(3)
    f = error_angle_fn()
    for theta in (0.0, 1e-9, 1e-4, 0.3, 1.0, 2.0, math.pi - 1e-6, math.pi):
        for ref in unit_quats(rng, 4):
            axis = rng.standard_normal(3)
            axis /= np.linalg.norm(axis)
            q = K.quat_mul(ref, K.axis_angle_to_quat(axis, theta))
            for qq in (q, -q):
                got = f(*qq.tolist(), *ref.tolist())
                assert got == pytest.approx(theta, rel=1e-7 if theta > math.pi - 1e-5 else 1e-12, abs=1e-15)


def test_error_angle_printings_agree():
    """The env's scalar call (C) is eval_kernel's C bitwise; control.error_angle_deg and the vector env (the NumPy
    printing) agree with it to an ulp: the arithmetic is the same, but NumPy's arctan2 is its own SIMD routine, not
    libm's atan2 (they differ by one ulp on ~8 % of these rows)."""
    rng = np.random.default_rng(11)
    q, ref = unit_quats(rng, 200), unit_quats(rng, 1)[0]
    f = error_angle_fn()
    scalar = np.array([f(*row.tolist(), *ref.tolist()) for row in q])
    np.testing.assert_array_equal(scalar, c_backend.eval_kernel("quat_error_angle", q, ref))
    np.testing.assert_allclose(np.degrees(scalar), lc.error_angle_deg(q, ref), rtol=4.5e-16, atol=0)
    np.testing.assert_allclose(scalar, K.quat_error_angle(q, ref), rtol=4.5e-16, atol=0)


def test_env_reports_the_kernel_angle():
    env = gymnasium.make("lavendersim:ReactionWheelCube-v0").unwrapped
    env.reset(seed=4)
    _, reward, _, _, info = env.step(np.array([0.3, -0.2, 0.1], np.float32))
    q = env.sim.state("cube").q
    theta = float(c_backend.eval_kernel("quat_error_angle", q, env.target_q))
    assert info["angle_error_deg"] == math.degrees(theta) == env.angle_error_deg()
    assert info["angle_error_deg"] > 1.0       # the reset drew an attitude away from the target
    w = env.sim.state("cube").omega_b
    a = np.array([0.3, -0.2, 0.1], np.float32).astype(float)
    assert reward == pytest.approx(-(theta ** 2 + 0.05 * w @ w + 0.01 * a @ a), rel=1e-12)


def test_error_angle_without_the_c_backend(monkeypatch):
    """Where the compiled backend does not load, the env's angle is the NumPy printing of the same kernel."""
    import sys

    import lavendersim.envs.reaction_wheel_cube as rwc

    monkeypatch.setattr(rwc, "_ERROR_ANGLE", [])
    import lavendersim.backends as backends_pkg

    monkeypatch.setitem(sys.modules, "lavendersim.backends.c_backend", None)     # `import` raises ImportError
    monkeypatch.delattr(backends_pkg, "c_backend")
    f = rwc.error_angle_fn()
    assert not isinstance(f, functools.partial)      # not scalar_kernel's C call
    rng = np.random.default_rng(5)
    q, ref = unit_quats(rng, 50), unit_quats(rng, 1)[0]
    got = np.array([f(*row.tolist(), *ref.tolist()) for row in q])
    assert all(type(f(*row.tolist(), *ref.tolist())) is float for row in q[:3])
    np.testing.assert_array_equal(got, K.quat_error_angle(q, ref))
