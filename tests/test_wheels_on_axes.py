"""The default wheel layout's right-hand side (wheels4_on_axes_rhs_c: the one N-wheel model with A_b = [I | 0]
substituted by derive, which the C step loops take for such bodies) is the general print at those axes, and the C
and NumPy steppers still agree on body-axis wheels."""
import numpy as np
import pytest

import lavendersim as lv
from lavendersim.backends import c_unavailable
from lavendersim.generated import layout as LY
from lavendersim.kernels import K


def test_on_axes_kernel_is_the_general_one_at_the_body_axes():
    rng = np.random.default_rng(3)
    n = 64
    q = rng.normal(size=(n, 4))
    q /= np.linalg.norm(q, axis=1, keepdims=True)
    w, Om, r_b, F, tau = (rng.normal(size=(n, k)) for k in (3, LY.WHEELS_MAX, 3, 3, 3))
    Om[:, LY.WHEELS_BODY_AXES:] = 0.0                 # padded slots at rest
    u = rng.normal(size=(n, LY.WHEELS_MAX))
    u[:, LY.WHEELS_BODY_AXES:] = 0.0
    S = rng.normal(size=(n, 3, 3))
    I_p = S @ S.transpose(0, 2, 1) + 5 * np.eye(3)
    J = np.ones((n, LY.WHEELS_MAX))
    J[:, :LY.WHEELS_BODY_AXES] = rng.uniform(0.01, 0.1, (n, LY.WHEELS_BODY_AXES))
    A = np.zeros((3, LY.WHEELS_MAX))
    A[:, :LY.WHEELS_BODY_AXES] = np.eye(3)
    A = np.broadcast_to(A, (n, 3, LY.WHEELS_MAX))
    c_w = rng.uniform(0.0, 1e-2, n)
    k_w = K.wheels4_coefficients(I_p, A, J)
    general = K.wheels4_body_rhs_c(q, w, Om, I_p, A, J, k_w, r_b, F, tau, u, c_w)
    axes = K.wheels4_on_axes_rhs_c(q, w, Om, I_p, J, k_w, r_b, F, tau, u, c_w)
    for g, a in zip(general, axes):
        assert np.array_equal(g, a)
    assert np.any(general[2][:, :LY.WHEELS_BODY_AXES] != 0.0)


@pytest.mark.parametrize("integrator", ["rk4", "euler"])
def test_body_axis_wheels_c_equals_numpy(integrator):
    if c_unavailable() is not None:
        pytest.skip("no C backend")

    def run(backend):
        sc = lv.Scene()
        for i in range(40):   # the 20 jointed wheel bodies, same effects, take the model tiles (rk4, 16 or more)
            sc.add_body(lv.Body(f"b{i}", 1.0 + 0.1 * i, [0.02, 0.03, 0.04], p_w=[0.0, 0.0, float(i)],
                                omega_b=np.random.default_rng(i).normal(size=3)))
            sc.add_effect("reaction_wheels", body=f"b{i}", J=[1e-4] * 3, torque_limit=0.1, speed_limit=100.0)
            if i % 2:
                sc.add_effect("spherical_joint", body=f"b{i}", anchor_w=[0.0, 0.1, float(i) + 0.2])
            else:
                sc.add_effect("applied_torque", body=f"b{i}", torque_w=[0.0, 0.0, 1e-3 * (i + 1)])
        sc.add_effect("gravity", g_w=[0.0, 0.0, -9.81])
        s = lv.Sim(sc, dt=1e-3, integrator=integrator, backend=backend)
        s.run(200)
        return s._x.copy(), s._models.Omega.copy()

    (xc, Wc), (xn, Wn) = run("c"), run("numpy")
    assert np.array_equal(xc, xn)
    assert np.array_equal(Wc, Wn)
    assert np.any(Wc[:, :LY.WHEELS_BODY_AXES] != 0.0)
