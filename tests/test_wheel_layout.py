"""Issue 13, wheel layouts: N reaction wheels on arbitrary axes (derive/wheel_layout.py, printed as
wheels<N>_body_rhs / _momentum / _motor; lavendersim.wheel_layout) and the 4-wheel pyramid cube
(wheel_layout.pyramid_cube, a Scene) under the one control stack (lavendersim.control): a 30° LQR slew
that settles below 0.1° with every wheel within its limits, null-space wheel-speed management, and the
momentum exchange exact with damping off."""
from __future__ import annotations

import numpy as np
import pytest

import lavendersim as lv
from lavendersim import control as lc
from lavendersim import wheel_layout as WL
from lavendersim.kernels import K
from lavendersim.validate import LavenderInputError
from wheel_reference import body_axis_wheels_rhs

pytestmark = pytest.mark.needs("control")   # casadi + python-control (tests/conftest.py)


@pytest.fixture(scope="module")
def pyramid():
    """The pyramid cube's constants: axes (3, 4), J (4,), the cube's inertia I_p (3, 3)."""
    from types import SimpleNamespace

    return SimpleNamespace(A_b=WL.pyramid_axes(), J=np.full(4, 5.7e-4), I_p=np.eye(3) * 0.15 ** 2 / 6, speed_limit=400.0,
                           torque_limit=0.2)


def test_pyramid_axes_and_null_space(pyramid):
    A = pyramid.A_b
    np.testing.assert_allclose(np.linalg.norm(A, axis=0), 1.0, atol=1e-15)
    np.testing.assert_allclose(A @ A.T, np.eye(3) * 4 / 3, atol=1e-14)       # equal authority on every axis
    n = WL.null_space(A)
    assert n.shape == (4, 1)
    np.testing.assert_allclose(A @ n, 0.0, atol=1e-14)
    np.testing.assert_allclose(np.abs(n[:, 0]), 0.5, atol=1e-14)             # (1, −1, 1, −1)/2 up to sign


def test_kernel_null_torque_moves_no_body_and_conserves_H(pyramid):
    """A torque along the null vector changes only the wheel rates: omega_dot_b is unchanged; with no
    external torque dH/dt + ω × H = 0 (H = I_p ω + A_b J Ω) at a random state."""
    rng = np.random.default_rng(3)
    A, J, I_p, z = pyramid.A_b, pyramid.J, pyramid.I_p, np.zeros(3)
    n = WL.null_space(A)[:, 0]
    for _ in range(5):
        q = rng.normal(size=4)
        q /= np.linalg.norm(q)
        w, W, u, c = rng.normal(size=3), rng.normal(size=4) * 50, rng.normal(size=4) * 0.1, 1e-4
        _, wd, Wd = K.wheels4_body_rhs(q, w, W, I_p, A, J, z, z, z, u, c)
        _, wd2, Wd2 = K.wheels4_body_rhs(q, w, W, I_p, A, J, z, z, z, u + 0.3 * n, c)
        np.testing.assert_allclose(wd2, wd, rtol=0, atol=1e-12 * np.abs(wd).max())
        assert np.abs(Wd2 - Wd).max() > 100.0                                # the wheels do feel it
        H = I_p @ w + A @ (J * W)
        Hdot = I_p @ wd + A @ (J * Wd)
        np.testing.assert_allclose(Hdot + np.cross(w, H), 0.0, atol=1e-12 * np.abs(Hdot).max())


def test_momentum_kernel_matches_definition(pyramid):
    y = np.array([0.1, -0.2, 0.3, 0.9, 0.3, -0.2, 0.5, 10.0, -20.0, 30.0, 5.0])
    y[:4] /= np.linalg.norm(y[:4])
    Lb, Lw, h = (np.asarray(v, float) for v in K.wheels4_momentum(y[:4], y[4:7], y[7:], pyramid.I_p, pyramid.A_b, pyramid.J))
    R = np.asarray(K.quat_to_matrix(y[:4])).reshape(3, 3)
    A, J, w, W = pyramid.A_b, pyramid.J, y[4:7], y[7:]
    np.testing.assert_allclose(h, J * (A.T @ w + W), rtol=1e-14)
    np.testing.assert_allclose(Lb + Lw, R @ (pyramid.I_p @ w + A @ (J * W)), rtol=1e-13)


@pytest.mark.parametrize("A_b, match", [
    (np.hstack([np.eye(3), [[1.0], [1.0], [0.0]]]), r"A_b.*unit vector.*column 3"),
    (np.array([[1.0, 0, 0, np.nan], [0, 1, 0, 0], [0, 0, 1, 1]]), r"A_b.*finite"),
    (np.array([[1.0, 0, -1, 0], [0, 1, 0, -1], [0, 0, 0, 0]]), r"A_b.*span 3-D space.*rank 2"),
    (np.ones((3, 7)) / np.sqrt(3.0), r"A_b.*span 3-D space"),
    (np.zeros((2, 4)), r"A_b"),
])
def test_bad_axes_are_refused(A_b, match):
    with pytest.raises(LavenderInputError, match=match):
        WL.axes("A_b", A_b, span=True)


def test_bad_wheel_parameters_are_refused():
    for J in ([1e-4, 1e-4, -1e-4, 1e-4], 0.01, [1e-4, 1e-4]):    # negative; heavier than the 0.00375 kg·m² cube; 2 of 4
        with pytest.raises(LavenderInputError) as e:
            WL.pyramid_cube(J=J)
        assert "J" in e.value.field
    with pytest.raises(LavenderInputError) as e:
        lc.design(WL.pyramid_cube(), period=0.01, null_bias=1000.0)
    assert e.value.field == "null_bias" and "speed_limit" in str(e.value)


def test_pyramid_slew_settles_within_limits_and_manages_null_speed(pyramid):
    scene = WL.pyramid_cube()
    ctrl = lc.design(scene, period=0.01, null_bias=50.0)
    assert ctrl.rank == 7                           # 16 states: p, v (6) and 3 conserved momentum components left
    r = lc.closed_loop(scene, ctrl, T=3.0, q0=lc.rotated(ctrl.q_ref, (1.0, 2.0, 3.0), 30.0), Omega0=np.zeros(4), dt=1e-3,
                       backend="c")
    f = r.figures()
    assert r.error_deg[0] == pytest.approx(30.0, abs=1e-9)
    assert f["settling_time"] == pytest.approx(0.43, abs=1e-9)   # the README's figure (and the old wheel_layout.slew's)
    assert np.all(r.error_deg[r.t >= f["settling_time"]] < 0.1)
    assert f["final_error_deg"] < 1e-3
    assert f["within_limits"]
    np.testing.assert_allclose(f["peak_wheel_speed"], 23.0227110931837, rtol=1e-9)   # README: every wheel ≤ 23 rad/s
    assert np.all(np.abs(r.applied) <= pyramid.torque_limit + 1e-15)
    # null-space management: the wheels' null component went from 0 to its target (50 rad/s) …
    n = WL.null_space(pyramid.A_b)[:, 0]
    assert n @ r.Omega[0] == 0.0
    assert n @ r.Omega[-1] == pytest.approx(46.05, abs=0.01)      # README: 0 → 46 rad/s in the 3 s
    # … and the rest of the wheel momentum is what the slew needs: back to 0 at rest (H = 0)
    np.testing.assert_allclose(r.Omega[-1] - n * (n @ r.Omega[-1]), 0.0, atol=0.05)
    assert r.L_drift <= 1e-9


def test_pyramid_momentum_exchange_exact_with_damping_off():
    out = lc.momentum_exchange(WL.pyramid_cube(wheel_damping=0.0))
    assert out["max_dL_wheels"] > 0.05             # real exchange happened
    assert out["exchange_residual"] <= 1e-9
    assert out["L_drift"] <= 1e-9
    assert out["exchange_residual"] == pytest.approx(1.0836557412199025e-11, rel=1e-3)   # the README's 1.1e-11


def test_printed_counts_and_three_body_axes_equal_the_cube_equations():
    """Derived once for any N, printed for N = 3 and 4 (WHEEL_COUNTS); with A_b = 1 (and for N = 4 a padded fourth
    slot) the kernels are the chapter's body-axis cube equations (written out in tests/wheel_reference.py; to
    rounding), pivot offset, external load and damping included; the padded slot stays at rest."""
    assert WL.printed_counts() == (3, 4)
    rng = np.random.default_rng(7)
    S = rng.normal(size=(3, 3))
    I_p = S @ S.T + 5 * np.eye(3)
    q = rng.normal(size=4)
    q /= np.linalg.norm(q)
    w, W, J, r, F, tau, u = (rng.normal(size=3) for _ in range(7))
    J = np.abs(J) * 0.1 + 0.05
    a = K.wheels3_body_rhs(q, w, W, I_p, np.eye(3), J, r, F, tau, u, 0.3)
    b = body_axis_wheels_rhs(q, w, W, I_p, J, r, F, tau, u, 0.3)
    pad = lambda v, z: np.append(v, z)  # noqa: E731
    c = K.wheels4_body_rhs(q, w, pad(W, 0.0), I_p, np.eye(3, 4), pad(J, 1.0), r, F, tau, pad(u, 0.0), 0.3)
    assert c[2][3] == 0.0
    for x, y, z in zip(a, b, c):
        np.testing.assert_allclose(x, y, rtol=1e-13, atol=1e-13)
        np.testing.assert_array_equal(z[:x.size], x)      # the padded slot changes no operation's result


@pytest.mark.parametrize("n", [3, 4])
def test_other_counts_momentum_exchange(n):
    """A tilted 3-wheel set (no null space) and a random 4-wheel set (1-D null space) conserve L exactly too."""
    rng = np.random.default_rng(n)
    A = rng.normal(size=(3, n))
    A /= np.linalg.norm(A, axis=0)
    scene = lv.Scene()
    scene.add_body(lv.Body.box("sc", 1.0, (0.15, 0.15, 0.15)))
    scene.add_effect("reaction_wheels", body="sc", axes_b=A.T, J=[2e-4] * n, torque_limit=0.2, speed_limit=400.0)
    assert WL.null_space(A).shape == (n, n - 3)
    out = lc.momentum_exchange(scene, T=0.5)
    assert out["max_dL_wheels"] > 0.01
    assert out["exchange_residual"] <= 1e-9 and out["L_drift"] <= 1e-9
