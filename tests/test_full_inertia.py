"""Full inertia tensors in the user's body frame (issue 26): a Body takes any symmetric positive definite
tensor; the Sim steps its principal frame and every public quantity stays in the body frame."""
from __future__ import annotations

import pickle

import numpy as np
import pytest
from scipy.integrate import solve_ivp
from scipy.spatial.transform import Rotation

import lavendersim as lv
from lavendersim import validate as V

# the 6U CubeSat of issue 26 (inertia from CAD, kg·m²)
I_SAT = np.array([[0.2, 0.004, -0.002], [0.004, 0.25, 0.003], [-0.002, 0.003, 0.08]])
Q0 = np.array([0.1, 0.2, 0.3, 0.9]) / np.linalg.norm([0.1, 0.2, 0.3, 0.9])
W0 = np.array([0.3, -0.2, 0.5])
BACKENDS = ["numpy", "c"]   # the C extension is built by every install (as tests/test_sim.py assumes)


def _dop853(I, q0, w0, T):
    """An independent full-tensor integration (q_dot = ½ q ⊗ [ω, 0], I ω̇ = −ω × I ω) by scipy's Rotation and
    DOP853 at rtol = atol = 1e-13: (q, omega_b) at T."""
    I_inv = np.linalg.inv(I)

    def f(t, y):
        q, w = y[:4], y[4:]
        x, y_, z, s = q   # ½ q ⊗ [w, 0], written out (x, y, z, w order)
        q_dot = 0.5 * np.array([[s, -z, y_], [z, s, -x], [-y_, x, s], [-x, -y_, -z]]) @ w
        return np.concatenate([q_dot, I_inv @ (-np.cross(w, I @ w))])

    r = solve_ivp(f, [0.0, T], np.concatenate([q0, w0]), method="DOP853", rtol=1e-13, atol=1e-13)
    q = r.y[:4, -1]
    return q / np.linalg.norm(q), r.y[4:, -1]


def _sat(I=I_SAT, **state):
    sc = lv.Scene()
    sc.add_body(lv.Body("sat", 12.0, I, **({"q": Q0, "omega_b": W0} | state)))
    return sc


def test_full_tensor_matches_an_independent_dop853_after_100_s():
    q_ref, w_ref = _dop853(I_SAT, Q0, W0, 100.0)
    backend = "c"
    for integrator, dt, kw in (("rk4", 1e-3, {}), ("dopri5", 1e-2, {"rtol": 1e-12, "atol": 1e-14})):
        sim = lv.Sim(_sat(), dt=dt, integrator=integrator, backend=backend, **kw)
        sim.run_for(100.0)
        s = sim.state("sat")
        q = s.q * np.sign(s.q @ q_ref)
        assert np.max(np.abs(q - q_ref)) <= 1e-9, integrator
        assert np.max(np.abs(s.omega_b - w_ref)) <= 1e-9, integrator


def test_the_numpy_backend_agrees_with_c_on_a_full_tensor():
    out = []
    for b in ("c", "numpy"):
        sim = lv.Sim(_sat(), dt=1e-3, integrator="rk4", backend=b)
        out.append(sim.record(200, every=50).x)
    np.testing.assert_allclose(out[0], out[1], rtol=0, atol=1e-13)


def test_body_keeps_the_tensor_and_reports_its_principal_frame():
    b = lv.Body("sat", 12.0, I_SAT)
    assert not b.principal
    np.testing.assert_allclose(b.inertia_b, I_SAT, rtol=0, atol=1e-15)
    np.testing.assert_allclose(b.R_bp @ b.R_bp.T, np.eye(3), atol=1e-15)
    assert np.linalg.det(b.R_bp) == pytest.approx(1.0, abs=1e-14)
    assert np.all(np.abs(np.diag(b.R_bp)) > 0.99)   # the principal axes nearest the body axes, in their order
    np.testing.assert_allclose(np.sort(b.I_b), np.linalg.eigvalsh(I_SAT), rtol=1e-14)
    c = pickle.loads(pickle.dumps(b))
    np.testing.assert_array_equal(c.R_bp, b.R_bp)
    np.testing.assert_array_equal(c.inertia_b, b.inertia_b)
    d = lv.Body("d", 1.0, np.diag([1.0, 2.0, 2.5]))
    assert d.principal and np.array_equal(d.I_b, [1.0, 2.0, 2.5]) and np.array_equal(d.R_bp, np.eye(3))


@pytest.mark.parametrize("backend", BACKENDS)
@pytest.mark.parametrize("integrator", ["euler", "semi_implicit_euler", "rk4", "splitting", "implicit_gyro"])
def test_a_full_tensor_body_is_its_principal_body_seen_in_the_users_axes(backend, integrator):
    """The same physical body built in its principal frame by hand: state(), record() and the views are
    the principal body's state rotated into the user's axes (q_wb = q_wp ⊗ q_pb, omega_b = R_bp omega_p)."""
    full = lv.Body("sat", 12.0, I_SAT)
    R, I_p = full.R_bp, full.I_b
    q_bp = Rotation.from_matrix(R).as_quat()
    q_wp = (Rotation.from_quat(Q0) * Rotation.from_quat(q_bp)).as_quat()
    sims = []
    for body in (lv.Body("sat", 12.0, I_SAT, q=Q0, omega_b=W0), lv.Body("sat", 12.0, I_p, q=q_wp, omega_b=R.T @ W0)):
        sc = lv.Scene()
        sc.add_body(body)
        sc.add_effect("force_at_point", body="sat", r_b=[0.1, -0.05, 0.2] if body.principal is False else
                      R.T @ [0.1, -0.05, 0.2], F_w=[0.0, 0.3, -0.1])
        sims.append(lv.Sim(sc, dt=1e-3, integrator=integrator, backend=backend))
    tr_full, tr_p = (s.record(300, every=100) for s in sims)
    q_p, w_p = tr_p.x[..., 3:7], tr_p.x[..., 10:13]
    q_expect = (Rotation.from_quat(q_p.reshape(-1, 4)) * Rotation.from_quat(q_bp).inv()).as_quat().reshape(q_p.shape)
    q_got = tr_full.x[..., 3:7]
    q_expect *= np.sign(np.sum(q_got * q_expect, axis=-1))[..., None]
    np.testing.assert_allclose(q_got, q_expect, atol=1e-12)
    np.testing.assert_allclose(tr_full.x[..., 10:13], w_p @ R.T, atol=1e-12)
    np.testing.assert_allclose(tr_full.x[..., 0:3], tr_p.x[..., 0:3], atol=1e-12)   # world-frame blocks agree
    s = sims[0].state("sat")
    np.testing.assert_allclose(s.q, q_got[-1, 0], atol=1e-15)
    np.testing.assert_allclose(sims[0].q[0], s.q, atol=0)
    np.testing.assert_allclose(sims[0].omega_b[0], s.omega_b, atol=0)
    assert not sims[0].x.flags.writeable


def test_set_state_takes_the_users_frame_and_changes_only_what_it_is_given():
    sim = lv.Sim(_sat(), dt=1e-3)
    q = Rotation.from_rotvec([0.2, -0.4, 0.1]).as_quat()
    sim.set_state("sat", q=q, omega_b=[0.01, 0.02, -0.03])
    s = sim.state("sat")
    np.testing.assert_allclose(s.q * np.sign(s.q @ q), q, atol=1e-15)
    np.testing.assert_allclose(s.omega_b, [0.01, 0.02, -0.03], atol=1e-16)
    before = sim._x.copy()
    sim.set_state("sat", p_w=[1.0, 2.0, 3.0])
    assert np.array_equal(sim._x[0, 3:], before[0, 3:])   # q and omega untouched to the bit
    sim.set_state("sat", omega_w=[0.0, 0.0, 0.5])
    np.testing.assert_allclose(sim.state("sat").omega_w, [0.0, 0.0, 0.5], atol=1e-15)


def test_angular_momentum_and_energy_are_those_of_the_tensor():
    sim = lv.Sim(_sat(), dt=1e-3)
    s = sim.state("sat")
    L_expect = s.R_wb @ (I_SAT @ W0)
    np.testing.assert_allclose(sim.angular_momentum_w("sat"), L_expect, rtol=1e-14, atol=1e-16)
    assert sim.kinetic_energy("sat") == pytest.approx(0.5 * W0 @ I_SAT @ W0, rel=1e-14)
    sim.run(2000)
    np.testing.assert_allclose(sim.angular_momentum_w("sat"), L_expect, rtol=1e-10)


def test_wheel_axes_are_in_the_users_body_frame():
    """Wheels on the body frame's axes of a full-tensor body: momentum exchange conserves the total
    (body + wheels) angular momentum in the world, and the wheel momentum follows the user's axes."""
    sc = _sat(omega_b=[0.0, 0.0, 0.0], q=[0, 0, 0, 1])
    A = np.array([[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0], [1.0, 1.0, 1.0]]) / np.array([[1], [1], [1], [3 ** 0.5]])
    sc.add_effect("reaction_wheels", body="sat", axes_b=A, J=[3e-5] * 4, torque_limit=0.002, speed_limit=600.0)
    sim = lv.Sim(sc, dt=1e-3)
    sim.set_wheel_command("sat", [0.0, 0.0, 0.0, 0.001])
    sim.run(500)
    body_L, wheel_L = sim.wheel_momentum_w("sat")
    assert np.linalg.norm(body_L) > 1e-4
    assert np.linalg.norm(body_L + wheel_L) <= 1e-12 * np.linalg.norm(body_L)
    # the body turns about −I⁻¹ a (the reaction of a wheel along a = (1, 1, 1)/√3 in the user's axes)
    w = sim.state("sat").omega_b
    a = A[3]
    expect = -np.linalg.solve(I_SAT - (A.T * 3e-5) @ A, a)
    assert np.dot(w, expect) / (np.linalg.norm(w) * np.linalg.norm(expect)) > 1 - 1e-6


@pytest.mark.parametrize("value, rule", [
    (np.array([[0.2, 0.01, 0.0], [0.0, 0.25, 0.0], [0.0, 0.0, 0.08]]), "inertia tensor must be symmetric"),
    (np.array([[0.2, 0.3, 0.0], [0.3, 0.25, 0.0], [0.0, 0.0, 0.08]]), "inertia tensor must be positive definite"),
    (Rotation.from_rotvec([0.3, 0.2, 0.1]).as_matrix() @ np.diag([1.0, 1.0, 3.0])
     @ Rotation.from_rotvec([0.3, 0.2, 0.1]).as_matrix().T, "triangle inequality"),
    (np.full((3, 3), np.nan), "finite"),
    (np.ones((2, 3)), "shape"),
])
def test_bad_tensors_are_refused_naming_the_field(value, rule):
    with pytest.raises(lv.LavenderInputError, match=rule) as ei:
        lv.Body("sat", 12.0, value)
    assert ei.value.field == "inertia"


def test_inertia_frame_keeps_a_diagonal_tensor_as_given():
    moments, R = V.inertia_frame("I", np.diag([3.0, 1.0, 2.5]))
    assert np.array_equal(moments, [3.0, 1.0, 2.5]) and np.array_equal(R, np.eye(3))


def test_cad_mass_properties_move_to_the_com():
    rng = np.random.default_rng(5)
    R = Rotation.from_rotvec(rng.normal(size=3)).as_matrix()
    I_c = R @ np.diag([0.1, 0.15, 0.2]) @ R.T
    m, c = 3.0, np.array([0.05, -0.02, 0.1])
    I_o = I_c + m * (c @ c * np.eye(3) - np.outer(c, c))   # what CAD reports about its origin
    np.testing.assert_allclose(lv.inertia_about_com(I_o, m, c), I_c, atol=1e-15)
    with pytest.raises(lv.LavenderInputError) as ei:
        lv.inertia_about_com(I_c, m, [0.0, 0.0, 1.0])   # an offset the tensor cannot have
    assert ei.value.field == "I_o"
    with pytest.raises(lv.LavenderInputError) as ei:
        lv.inertia_about_com(I_o, -1.0, c)
    assert ei.value.field == "mass"


def test_linearization_is_in_the_users_frame():
    """The linearization of a full-tensor body with skewed wheels and an r_b input matches finite
    differences of the Sim (both in the user's axes), as well as a principal body's does."""
    pytest.importorskip("casadi")
    from lavendersim import control

    A = np.array([[1, 0.1, 0], [0, 1, 0.2], [0.3, 0, 1.0]])
    A /= np.linalg.norm(A, axis=1)[:, None]
    res = {}
    for key, I in (("full", I_SAT), ("diag", np.diag([0.2, 0.25, 0.08]))):
        sc = _sat(I, omega_b=[0.01, -0.02, 0.03])
        sc.add_effect("reaction_wheels", body="sat", axes_b=A, J=[3e-5] * 3, torque_limit=0.002, speed_limit=600.0)
        sc.add_effect("force_at_point", body="sat", r_b=[0.1, 0.05, -0.02], F_w=[0.01, 0.02, -0.01])
        sim = lv.Sim(sc, dt=1e-3)
        sim.set_state("sat", Omega=[10.0, -20.0, 30.0])
        lin = control.linearize(sim, inputs=["sat.u", "force_at_point.r_b"])
        A_fd, B_fd = control.finite_difference(lin, sc, h=1e-4, dt=1e-5)
        res[key] = control.linearization_residual(lin, A_fd, B_fd)
        if key == "full":
            np.testing.assert_allclose(lin.q_ref * np.sign(lin.q_ref @ Q0), Q0, atol=1e-15)
            x = lin.state_of(sim)
            assert np.max(np.abs(x)) <= 1e-12   # the Sim is at the operating point in the user's frame
    assert res["full"]["A_rel"] <= 2e-5 and res["full"]["B_rel"] <= 1e-8
    assert res["full"]["A_rel"] <= 3 * res["diag"]["A_rel"]
