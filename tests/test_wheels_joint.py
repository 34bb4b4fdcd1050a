"""Spherical joint and reaction wheels as scene effects, on both backends (never skipped)."""
import numpy as np
import pytest

import lavendersim as lv
from lavendersim import LavenderInputError as E
from lavendersim.generated import kernels_numpy as K
from lavendersim.generated import layout as LY

# Long NumPy runs are in the slow set (NUMPY_SLOW: tests/conftest.py); test_c_and_numpy_agree_on_a_mixed_scene
# checks quickly that NumPy computes what C computes.
from conftest import NUMPY_SLOW
from wheel_reference import body_axis_wheels_rhs

BACKENDS = ["numpy", "c"]
INTEGRATORS = ["euler", "semi_implicit_euler", "rk4"]
SIDE, MASS = 0.15, 1.0
I_CUBE = MASS * SIDE**2 / 6  # 0.00375 kg·m²
J3 = [2e-4, 3e-4, 2.5e-4]


def wheel_cube(joint=True, anchor=(0, 0, 0), J=J3, torque_limit=0.2, speed_limit=400.0, c_w=0.0, cutoff=1.0, **state):
    """The wheel cube; cutoff=1 (explicit): the hard speed cut-off these saturation tests pin down
    (the default torque–speed line motor: tests/test_motor.py)."""
    s = lv.Scene()
    s.add_body(lv.Body.box("cube", MASS, (SIDE, SIDE, SIDE), **state))
    if joint:
        s.add_effect("spherical_joint", body="cube", anchor_w=list(anchor))
    s.add_effect("reaction_wheels", body="cube", J=list(J), torque_limit=torque_limit, speed_limit=speed_limit, c_w=c_w,
                 cutoff=cutoff)
    return s


# ---------------------------------------------------------------- momentum exchange

@pytest.mark.parametrize("backend", NUMPY_SLOW)
@pytest.mark.parametrize("joint", [True, False])
def test_momentum_exchange_is_exact(backend, joint):
    """No damping, joint at the centre (or none), no other effect: L_body + L_wheels is constant."""
    sim = lv.Sim(wheel_cube(joint=joint, omega_b=(0.3, -0.2, 0.5)), dt=1e-3, integrator="rk4", backend=backend)
    sim.set_wheel_command("cube", [0.001, -0.002, 0.0])
    Lb0, Lw0 = sim.wheel_momentum_w("cube")
    L0 = Lb0 + Lw0
    worst = 0.0
    for _ in range(20):  # 2 s, checked every 0.1 s
        sim.run(100)
        Lb, Lw = sim.wheel_momentum_w("cube")
        worst = max(worst, np.linalg.norm(Lb + Lw - L0))
    assert worst <= 1e-12 * np.linalg.norm(L0)
    dLb, dLw = Lb - Lb0, Lw - Lw0
    assert np.linalg.norm(dLb) > 4e-3  # a real exchange happened (kg·m²/s)
    assert np.linalg.norm(dLb + dLw) <= 1e-12 * np.linalg.norm(dLb)
    assert np.all(np.abs(sim.wheel_rates("cube")[:2]) > 10.0)
    np.testing.assert_array_equal(sim.wheel_command_applied("cube"), [0.001, -0.002, 0.0])


# ---------------------------------------------------------------- signs (lab 04 / paw-check)

@pytest.mark.parametrize("backend", BACKENDS)
@pytest.mark.parametrize("sign", [1.0, -1.0])
def test_x_wheel_command_signs_and_exact_rates(backend, sign):
    J = [2e-4, 2e-4, 2e-4]
    sim = lv.Sim(wheel_cube(J=J), dt=1e-3, integrator="rk4", backend=backend)
    u = sign * 0.05
    sim.set_wheel_command("cube", [u, 0, 0])
    tr = sim.record(500)
    W, w = tr.body("cube").Omega[1:, 0], tr.body("cube").omega_b[1:, 0]
    assert np.all(sign * W > 0) and np.all(sign * w < 0)
    # isotropic cube, pivot at the centre, from rest: constant accelerations
    t = tr.t[1:]
    np.testing.assert_allclose(w, -u * t / (I_CUBE - J[0]), rtol=1e-12)
    np.testing.assert_allclose(W, u * t / J[0] + u * t / (I_CUBE - J[0]), rtol=1e-12)
    assert np.all(tr.body("cube").omega_b[:, 1:] == 0) and np.all(tr.body("cube").Omega[:, 1:] == 0)


# ---------------------------------------------------------------- saturation

@pytest.mark.parametrize("backend", BACKENDS)
def test_command_is_clipped_to_the_torque_limit(backend):
    sim = lv.Sim(wheel_cube(J=[2e-4] * 3, torque_limit=0.2), dt=1e-3, backend=backend)
    np.testing.assert_array_equal(sim.wheel_command_applied("cube"), [0, 0, 0])  # before any step
    sim.set_wheel_command("cube", [0.5, -3.0, 0.1])
    sim.step()
    np.testing.assert_array_equal(sim.wheel_command_applied("cube"), [0.2, -0.2, 0.1])
    np.testing.assert_array_equal(sim.wheel_command("cube"), [0.5, -3.0, 0.1])  # the command is kept
    # the body felt exactly the clipped torque
    np.testing.assert_allclose(sim.state("cube").omega_b, -np.array([0.2, -0.2, 0.1]) * 1e-3 / (I_CUBE - 2e-4),
                               rtol=1e-12)


@pytest.mark.parametrize("backend", BACKENDS)
def test_a_wheel_at_its_speed_limit_is_not_driven_further(backend):
    sim = lv.Sim(wheel_cube(J=[2e-4] * 3, speed_limit=400.0), dt=1e-3, backend=backend)
    sim.set_state("cube", Omega=[400.0, -400.0, 399.0])
    sim.set_wheel_command("cube", [0.1, -0.1, 0.0])
    sim.run(10)
    np.testing.assert_array_equal(sim.wheel_command_applied("cube"), [0.0, 0.0, 0.0])
    np.testing.assert_array_equal(sim.wheel_rates("cube"), [400.0, -400.0, 399.0])  # no drive, no damping
    np.testing.assert_array_equal(sim.state("cube").omega_b, [0, 0, 0])
    sim.set_wheel_command("cube", [-0.1, 0.1, 0.1])  # braking at the limit is allowed; z is below it
    sim.step()
    np.testing.assert_array_equal(sim.wheel_command_applied("cube"), [-0.1, 0.1, 0.1])
    W = sim.wheel_rates("cube")
    assert W[0] < 400.0 and W[1] > -400.0 and W[2] > 399.0


@pytest.mark.parametrize("backend", BACKENDS)
def test_driving_from_rest_stops_at_the_speed_limit(backend):
    sim = lv.Sim(wheel_cube(J=[2e-4] * 3, speed_limit=50.0, torque_limit=0.2), dt=1e-3, backend=backend)
    sim.set_wheel_command("cube", [1.0, 0, 0])  # clipped to 0.2: ~ 1053 rad/s² on the wheel
    tr = sim.record(200)
    W = tr.body("cube").Omega[:, 0]
    step_gain = 0.2 * 1e-3 * (1 / 2e-4 + 1 / (I_CUBE - 2e-4))
    assert W.max() < 50.0 + step_gain  # overshoots by at most one step
    assert W[-1] == W[-50] >= 50.0  # then held: no drive, no damping
    np.testing.assert_array_equal(sim.wheel_command_applied("cube"), [0, 0, 0])


# ---------------------------------------------------------------- joint

ANCHOR = np.array([0.2, -0.1, 1.0])


def pendulum(backend, L=0.4, m=1.3, g=9.81, **kw):
    s = lv.Scene()
    body = lv.Body.box("rod", m, (0.1, 0.12, 0.3), p_w=ANCHOR + [0, 0, -L], **kw)
    s.add_body(body)
    s.add_effect("spherical_joint", body="rod", anchor_w=list(ANCHOR))
    s.add_effect("gravity", g_w=(0, 0, -g))
    return lv.Sim(s, dt=1e-3, integrator="rk4", backend=backend), body


@pytest.mark.parametrize("backend", NUMPY_SLOW)
def test_the_anchored_point_stays_at_the_anchor(backend):
    q0 = K.axis_angle_to_quat(np.array([1.0, 2.0, 2.0]) / 3, 0.6)
    s = lv.Scene()
    s.add_body(lv.Body.box("b", 2.0, (0.3, 0.2, 0.1), p_w=(0.5, 0.2, 0.9), q=q0, omega_b=(2.0, -1.0, 3.0)))
    s.add_effect("spherical_joint", body="b", anchor_w=[0.4, 0.3, 1.0])
    s.add_effect("gravity")
    s.add_effect("linear_damping", c=0.3)
    sim = lv.Sim(s, dt=1e-3, backend=backend)
    r_b = K.quat_to_matrix(q0).T @ (np.array([0.5, 0.2, 0.9]) - [0.4, 0.3, 1.0])
    d0 = np.linalg.norm(r_b)
    tr = sim.record(3000, every=10)
    st = tr.body("b")
    anchored = st.p_w - np.einsum("tij,j->ti", st.R_wb, r_b)
    assert np.max(np.abs(anchored - [0.4, 0.3, 1.0])) <= 1e-12
    assert np.max(np.abs(np.linalg.norm(st.p_w - [0.4, 0.3, 1.0], axis=1) - d0)) <= 1e-12
    # the COM velocity is the joint's: v = omega_w x (p - a)
    v = np.cross(st.omega_w, st.p_w - [0.4, 0.3, 1.0])
    assert np.max(np.abs(st.v_w - v)) <= 1e-12
    assert np.ptp(st.p_w[:, 2]) > 0.05  # it really moved under gravity


@pytest.mark.parametrize("backend", NUMPY_SLOW)
def test_compound_pendulum_period(backend):
    L, m, g = 0.4, 1.3, 9.81
    sim, body = pendulum(backend, L, m, g)
    I_axis = body.I_b[1] + m * L**2
    T = 2 * np.pi * np.sqrt(I_axis / (m * g * L))
    sim.set_state("rod", omega_b=(0, 0.005 * 2 * np.pi / T, 0))  # amplitude 0.005 rad
    tr = sim.record(6000)
    p = tr.body("rod").p_w - ANCHOR
    th = np.arctan2(p[:, 0], -p[:, 2])
    i = np.flatnonzero((th[:-1] < 0) & (th[1:] >= 0))
    crossings = tr.t[i] + (0 - th[i]) / (th[i + 1] - th[i]) * sim.dt
    assert len(crossings) >= 4
    T_sim = np.mean(np.diff(crossings))
    assert abs(T_sim / T - 1) <= 1e-4
    assert abs(T_sim / T - 1) > 0 and "pivot_body_rhs" in sim.pipeline[1]


@pytest.mark.parametrize("backend", NUMPY_SLOW)
def test_pendulum_energy_is_conserved(backend):
    m, g, L = 1.3, 9.81, 0.4
    sim, _ = pendulum(backend, L, m, g, omega_b=(4.0, 6.0, 1.5))
    I_p = K.parallel_axis(np.diag(sim.params[0, 1:4]), m, [0, 0, L])

    def energy():
        st = sim.state("rod")
        return 0.5 * st.omega_b @ I_p @ st.omega_b + m * g * st.p_w[2]

    E0, worst, zs = energy(), 0.0, []
    for _ in range(50):  # 5 s
        sim.run(100)
        worst = max(worst, abs(energy() - E0))
        zs.append(sim.state("rod").p_w[2])
    assert worst <= 1e-9 * m * g * L
    assert max(zs) - min(zs) > 0.2 * L  # large swings, not a near-rest check
    # kinetic energy of the locked body about its COM equals ½ ωᵀ I_p ω about the pivot
    st = sim.state("rod")
    assert sim.kinetic_energy("rod") == pytest.approx(0.5 * st.omega_b @ I_p @ st.omega_b, rel=1e-12)


@pytest.mark.parametrize("backend", BACKENDS)
def test_linear_damping_on_a_jointed_body_uses_its_kinematic_velocity(backend):
    """dE/dt = F_damping · v = -c |v|², with v = omega_w x (p - a) the joint's COM velocity."""
    m, g, L, c = 1.3, 9.81, 0.4, 0.7
    s = lv.Scene()
    s.add_body(lv.Body.box("rod", m, (0.1, 0.12, 0.3), p_w=ANCHOR + [0.1, 0, -L], omega_b=(1.0, -2.0, 0.5)))
    s.add_effect("spherical_joint", body="rod", anchor_w=list(ANCHOR))
    s.add_effect("gravity", g_w=(0, 0, -g))
    s.add_effect("linear_damping", c=c)
    dt = 1e-7
    sim = lv.Sim(s, dt=dt, integrator="rk4", backend=backend)
    r_b = np.array([0.1, 0, -L])
    I_p = K.parallel_axis(np.diag(sim.params[0, 1:4]), m, -r_b)

    def energy():
        st = sim.state("rod")
        return 0.5 * st.omega_b @ I_p @ st.omega_b + m * g * st.p_w[2]

    v0 = sim.state("rod").v_w
    np.testing.assert_allclose(v0, np.cross(sim.state("rod").omega_w, r_b), rtol=1e-15)
    E0 = energy()
    sim.step()
    assert (energy() - E0) / dt == pytest.approx(-c * v0 @ v0, rel=1e-6)


def reference_run(m, I_b, y0, anchor, r_b, J, c_w, limits, u_cmd, g, c_lin, c_ang, dt, n):
    """A plain per-step RK4 of one jointed wheeled body written straight from the chapter's body-axis equations
    (tests/wheel_reference.py) and the documented semantics (kinematic COM velocity in every stage,
    zero-order-hold saturation)."""
    I_p = K.parallel_axis(np.diag(I_b), m, -r_b)

    def f(y, u):
        q, w, W = y[3:7], y[10:13], y[13:16]
        v = K.pivot_kinematics(q, w, anchor, r_b)[1]
        F = m * np.asarray(g) - c_lin * v
        tau = -c_ang * K.quat_rotate(q, w)
        qd, wd, Wd = body_axis_wheels_rhs(q, w, W, I_p, J, r_b, F, tau, u, c_w)
        return np.concatenate([np.zeros(3), qd, np.zeros(3), wd, Wd])

    y = y0.copy()
    for _ in range(n):
        u = np.clip(u_cmd, -limits[0], limits[0])
        u = np.where((np.abs(y[13:16]) >= limits[1]) & (u * y[13:16] > 0), 0.0, u)
        k1 = f(y, u)
        k2 = f(y + dt / 2 * k1, u)
        k3 = f(y + dt / 2 * k2, u)
        k4 = f(y + dt * k3, u)
        y = y + dt / 6 * (k1 + 2 * k2 + 2 * k3 + k4)
        y[3:7] /= np.linalg.norm(y[3:7])
        y[0:3], y[7:10] = K.pivot_kinematics(y[3:7], y[10:13], anchor, r_b)
    return y, u


@pytest.mark.parametrize("backend", NUMPY_SLOW)
def test_jointed_wheeled_body_matches_a_plain_reference(backend):
    m, J, c_w, lim, cmd = 1.0, np.array(J3), 2e-5, (0.02, 30.0), np.array([0.05, -0.01, 0.004])
    anchor, p0 = np.array([0.0, 0.0, 0.0]), np.array([0.075, 0.075, 0.075])
    q0 = K.axis_angle_to_quat(np.array([1.0, -1.0, 0]) / np.sqrt(2), 0.3)
    s = wheel_cube(J=J, torque_limit=lim[0], speed_limit=lim[1], c_w=c_w, p_w=p0, q=q0, omega_b=(0.3, -0.2, 0.1))
    s.add_effect("gravity")
    s.add_effect("linear_damping", c=0.5)
    s.add_effect("angular_damping", c=1e-3)
    sim = lv.Sim(s, dt=1e-3, integrator="rk4", backend=backend)
    sim.set_wheel_command("cube", cmd)
    sim.run(600)
    r_b = K.quat_to_matrix(q0).T @ (p0 - anchor)
    y0 = np.concatenate([p0, q0, [0, 0, 0], [0.3, -0.2, 0.1], [0, 0, 0]])
    y, u = reference_run(m, np.full(3, I_CUBE), y0, anchor, r_b, J, c_w, lim, cmd, (0, 0, -9.81), 0.5, 1e-3, 1e-3, 600)
    got = np.concatenate([sim.x[0], sim.wheel_rates("cube")])
    assert np.max(np.abs(got - y)) <= 1e-12 * max(1.0, np.max(np.abs(y)))
    np.testing.assert_array_equal(sim.wheel_command_applied("cube"), u)
    assert abs(y[13]) >= lim[1]  # the x wheel reached its speed limit on the way


@pytest.mark.parametrize("backend", NUMPY_SLOW)
def test_joint_at_the_com_without_forces_moves_like_the_free_body(backend):
    kw = dict(omega_b=(1.0, 0.5, 0.2), p_w=(0.1, 0.2, 0.3))
    free = lv.Scene()
    free.add_body(lv.Body("b", 1.0, (1.0, 2.0, 3.0), **kw))
    pinned = lv.Scene()
    pinned.add_body(lv.Body("b", 1.0, (1.0, 2.0, 3.0), **kw))
    pinned.add_effect("spherical_joint", body="b", anchor_w=[0.1, 0.2, 0.3])
    a, b = lv.Sim(free, backend=backend), lv.Sim(pinned, backend=backend)
    a.run(2000)
    b.run(2000)
    np.testing.assert_allclose(b.x, a.x, rtol=0, atol=1e-12)


# ---------------------------------------------------------------- zero strength

@pytest.mark.parametrize("backend", NUMPY_SLOW)
@pytest.mark.parametrize("joint", [True, False])
def test_idle_wheels_change_nothing_when_the_body_does_not_accelerate(backend, joint):
    """u = 0, Omega = 0 on an isotropic cube spinning freely (gravity on the free one): identical motion."""
    kw = dict(omega_b=(1.3, -0.7, 2.9), v_w=(0.5, 0, 1.0))
    plain = lv.Scene()
    plain.add_body(lv.Body.box("cube", MASS, (SIDE,) * 3, **kw))
    wheels = wheel_cube(joint=joint, **kw)
    if joint:  # pinned at its centre
        plain.add_effect("spherical_joint", body="cube", anchor_w=[0, 0, 0])
    else:  # free, falling
        plain.add_effect("gravity")
        wheels.add_effect("gravity")
    a, b = lv.Sim(plain, backend=backend), lv.Sim(wheels, backend=backend)
    a.run(2000)
    b.run(2000)
    np.testing.assert_allclose(b.x, a.x, rtol=0, atol=1e-12)
    np.testing.assert_allclose(b.wheel_rates("cube"), 0, atol=1e-12)


@pytest.mark.parametrize("backend", NUMPY_SLOW)
@pytest.mark.parametrize("joint", [True, False])
def test_idle_wheels_in_the_zero_inertia_limit_match_the_body_without_wheels(backend, joint):
    """Free (u = 0) wheels decouple from the body about their axes, so a torqued body with idle
    wheels accelerates as if its inertia were I - J (checked below); at J -> 0 that is the plain body."""
    q0 = K.axis_angle_to_quat(np.array([0.0, 0.6, 0.8]), 0.4)
    kw = dict(q=q0, omega_b=(1.0, 0.5, -0.2), p_w=(0, 0, -0.3))

    def scene(J=None):
        s = lv.Scene()
        s.add_body(lv.Body("b", 1.0, (0.4, 0.5, 0.6), **kw))
        if joint:
            s.add_effect("spherical_joint", body="b", anchor_w=[0, 0, 0])
        s.add_effect("gravity")
        s.add_effect("applied_torque", body="b", torque_w=(0.1, -0.05, 0.2))
        s.add_effect("angular_damping", c=0.02)
        if J is not None:
            s.add_effect("reaction_wheels", body="b", J=J, torque_limit=1.0, speed_limit=100.0)
        return s

    a, b = lv.Sim(scene(), backend=backend), lv.Sim(scene([1e-14] * 3), backend=backend)
    a.run(1000)
    b.run(1000)
    np.testing.assert_allclose(b.x, a.x, rtol=0, atol=1e-12)
    # with a finite J the free wheels matter: the first-step acceleration is (I_p - J)^-1 (...)
    big = lv.Sim(scene([0.1, 0.1, 0.1]), dt=1e-6, integrator="euler", backend=backend, normalize=False)
    ref = lv.Sim(scene(), dt=1e-6, integrator="euler", backend=backend, normalize=False)
    w0 = big.x[0, 10:13].copy()
    big.step()
    ref.step()
    assert np.linalg.norm((big.x[0, 10:13] - w0) - (ref.x[0, 10:13] - w0)) > 1e-8


# ---------------------------------------------------------------- backends agree

def mixed_scene():
    s = lv.Scene()
    q1 = K.axis_angle_to_quat(np.array([1.0, 0, 1.0]) / np.sqrt(2), 0.3)
    s.add_body(lv.Body("free", 1.5, (1.0, 2.0, 2.5), omega_b=(1.0, 0.5, 0.2), v_w=(0.1, 0, 0)))
    s.add_body(lv.Body.box("cube", MASS, (SIDE,) * 3, q=q1, p_w=(0.075, 0.075, 0.075), omega_b=(0.4, -0.3, 0.2)))
    s.add_body(lv.Body.box("pend", 0.8, (0.1, 0.1, 0.4), p_w=(1, 1, 0.8), omega_b=(1.0, 2.0, 0.5)))
    s.add_body(lv.Body.box("drone", 2.0, (0.3, 0.3, 0.1), omega_b=(0.2, 0.1, -0.4)))
    s.add_body(lv.Body("idle", 1.0, (1.0, 1.5, 2.0), omega_b=(0.3, -1.0, 0.5)))
    s.add_effect("spherical_joint", body="cube", anchor_w=[0, 0, 0])
    s.add_effect("reaction_wheels", body="cube", J=J3, torque_limit=0.2, speed_limit=60.0, c_w=1e-5)
    s.add_effect("spherical_joint", body="pend", anchor_w=[1, 1, 1])
    s.add_effect("reaction_wheels", body="drone", J=[1e-3, 1e-3, 2e-3], torque_limit=0.05, speed_limit=200.0)
    s.add_effect("gravity")
    s.add_effect("linear_damping", c=0.2)
    s.add_effect("angular_damping", body="cube", c=0.003)
    s.add_effect("force_at_point", body="pend", r_b=(0.05, 0, 0.1), F_w=(0.3, 0, 0))
    return s


@pytest.mark.parametrize("integrator", INTEGRATORS)
def test_c_and_numpy_agree_on_a_mixed_scene(integrator):
    sims = {be: lv.Sim(mixed_scene(), dt=1e-3, integrator=integrator, backend=be) for be in BACKENDS}
    for sim in sims.values():
        sim.set_wheel_command("cube", [0.5, -0.05, 0.01])  # x saturates at 0.2, then at the speed limit
        sim.set_wheel_command("drone", [0.01, 0.02, -0.03])
        sim.run(700)
        sim.set_wheel_command("cube", [-0.1, 0.0, 0.03])
        sim.run(300)
    a, b = sims["numpy"], sims["c"]
    scale = max(1.0, np.max(np.abs(a.x)))
    assert np.max(np.abs(a.x - b.x)) <= 1e-12 * scale
    np.testing.assert_allclose(b._models.Omega, a._models.Omega, rtol=0, atol=1e-12 * max(1.0, np.max(np.abs(a._models.Omega))))
    np.testing.assert_array_equal(b._models.applied, a._models.applied)
    assert abs(a.wheel_rates("cube")[0]) > 50.0  # reached the 60 rad/s region; the limit logic ran
    # bodies without joint/wheels are untouched by the model machinery
    plain = lv.Scene()
    plain.add_body(lv.Body("idle", 1.0, (1.0, 1.5, 2.0), omega_b=(0.3, -1.0, 0.5)))
    plain.add_effect("gravity")
    plain.add_effect("linear_damping", c=0.2)
    ref = lv.Sim(plain, dt=1e-3, integrator=integrator, backend="c")
    ref.run(1000)
    np.testing.assert_array_equal(b.state("idle").x, ref.state("idle").x)


@pytest.mark.parametrize("backend", BACKENDS)
def test_pipeline_names_the_joint_wheels_and_kernels(backend):
    sim = lv.Sim(mixed_scene(), backend=backend)
    p = dict(line.split(": ", 1) for line in sim.pipeline[1:])
    wheel_rhs = "wheels4_on_axes_rhs_c" if backend == "c" else "wheels4_body_rhs"   # (rk4: C's on-axes print)
    assert "spherical_joint" in p["cube"] and "reaction_wheels" in p["cube"] and f"rotation and wheels: {wheel_rhs};" in p["cube"]
    # (C skips a jointed body's translation_rhs; NumPy forms it for the whole group and zeroes it)
    assert "wheels: 3 on the body axes" in p["cube"] and ("translation_rhs" in p["cube"]) == (backend == "numpy")
    assert "pivot_kinematics" in p["cube"]
    assert "spherical_joint" in p["pend"] and "pivot_body_rhs" in p["pend"] and "reaction_wheels" not in p["pend"]
    assert "reaction_wheels" in p["drone"] and wheel_rhs in p["drone"] and "spherical_joint" not in p["drone"]
    assert "translation: translation_rhs" in p["drone"] and "pivot_kinematics" not in p["drone"]
    assert "rigid_body_increments_free_c" in p["free"] and "wheel" not in p["free"] and "joint" not in p["free"]


@pytest.mark.parametrize("backend", BACKENDS)
def test_semi_implicit_euler_updates_rates_before_q(backend):
    sims = {i: lv.Sim(wheel_cube(J=[2e-4] * 3), dt=1e-2, integrator=i, backend=backend) for i in ("euler", "semi_implicit_euler")}
    for sim in sims.values():
        sim.set_wheel_command("cube", [0.05, 0, 0])
        sim.step()
    np.testing.assert_array_equal(sims["euler"].state("cube").q, [0, 0, 0, 1])  # q moved with the old omega = 0
    assert sims["semi_implicit_euler"].state("cube").q[0] < 0  # q moved with the new omega_x < 0
    for sim in sims.values():
        np.testing.assert_allclose(sim.wheel_rates("cube")[0], 0.05 * 1e-2 * (1 / 2e-4 + 1 / (I_CUBE - 2e-4)), rtol=1e-12)


# ---------------------------------------------------------------- state access, recording, divergence

@pytest.mark.parametrize("backend", BACKENDS)
def test_state_access_and_trajectory_carry_omega(backend):
    sim = lv.Sim(mixed_scene(), backend=backend)
    sim.set_state("cube", Omega=[1.0, -2.0, 3.0])
    np.testing.assert_array_equal(sim.state("cube").Omega, [1.0, -2.0, 3.0])
    np.testing.assert_array_equal(sim.wheel_rates("cube"), [1.0, -2.0, 3.0])
    np.testing.assert_array_equal(sim.state("free").Omega, [0, 0, 0])
    tr = sim.record(10, every=5)
    assert tr.Omega.shape == (3, 5, LY.WHEELS_MAX) and tr.body("cube").Omega.shape == (3, 3)   # all slots; the body its 3
    np.testing.assert_array_equal(tr.body("cube").Omega[0], [1.0, -2.0, 3.0])
    np.testing.assert_array_equal(tr.body("free").Omega, np.zeros((3, 3)))
    # setting q on a jointed body moves its COM with it
    q = K.axis_angle_to_quat(np.array([1.0, 0, 0]), np.pi / 2)
    sim.set_state("pend", q=q, omega_b=(0, 0, 0))
    np.testing.assert_allclose(sim.state("pend").p_w, [1, 1.2, 1], atol=1e-15)
    np.testing.assert_array_equal(sim.state("pend").v_w, [0, 0, 0])
    # without a joint, momentum is about the COM: L_body + L_wheels = R (I_b ω + J Ω)
    Lb, Lw = sim.wheel_momentum_w("drone")
    st = sim.state("drone")
    H_b = sim.params[3, 1:4] * st.omega_b + np.array([1e-3, 1e-3, 2e-3]) * st.Omega
    np.testing.assert_allclose(Lb + Lw, st.R_wb @ H_b, rtol=1e-12)


@pytest.mark.parametrize("backend", BACKENDS)
def test_divergence_in_the_wheel_rates_restores_everything(backend):
    s = lv.Scene()
    s.add_body(lv.Body.sphere("calm", 1.0, 0.1))
    s.add_body(lv.Body.box("cube", MASS, (SIDE,) * 3))
    s.add_effect("reaction_wheels", body="cube", J=[1e-4] * 3, torque_limit=0.2, speed_limit=1e9, c_w=1.0)
    sim = lv.Sim(s, dt=1e-3, integrator="euler", backend=backend)  # c_w dt / J = 10: unstable
    sim.set_wheel_command("cube", [0.1, 0, 0])
    sim.run(3)
    before = (sim.x.copy(), sim.wheel_rates("cube"), sim.wheel_command_applied("cube"), sim.steps)
    with pytest.raises(lv.DivergenceError) as e:
        sim.run(10_000)
    assert e.value.body == 1 and e.value.body_name == "cube" and "Omega" in str(e.value)
    assert np.array_equal(sim.x, before[0]) and np.array_equal(sim.wheel_rates("cube"), before[1])
    assert np.array_equal(sim.wheel_command_applied("cube"), before[2]) and sim.steps == before[3]
    # the cube's body rates stay finite and small; only the wheel rates blow up
    assert 0 < e.value.step < 10_000


# ---------------------------------------------------------------- bad input

def one_cube():
    s = lv.Scene()
    s.add_body(lv.Body.box("cube", MASS, (SIDE,) * 3))
    return s


OK_WHEELS = dict(J=[1e-4] * 3, torque_limit=0.2, speed_limit=400.0)


@pytest.mark.parametrize("name,params,field", [
    ("spherical_joint", dict(body="ghost", anchor_w=[0, 0, 0]), "spherical_joint.body"),
    ("reaction_wheels", dict(body="ghost", **OK_WHEELS), "reaction_wheels.body"),
    ("spherical_joint", dict(anchor_w=[0, 0, 0]), "spherical_joint.body"),
    ("reaction_wheels", dict(**OK_WHEELS), "reaction_wheels.body"),
    ("spherical_joint", dict(body="cube", anchor_w=[0, np.nan, 0]), "spherical_joint.anchor_w"),
    ("spherical_joint", dict(body="cube", anchor_w=[0, 0]), "spherical_joint.anchor_w"),
    ("spherical_joint", dict(body="cube"), "spherical_joint.anchor_w"),
    ("reaction_wheels", dict(body="cube", **{**OK_WHEELS, "J": [1e-4, 0, 1e-4]}), "reaction_wheels.J"),
    ("reaction_wheels", dict(body="cube", **{**OK_WHEELS, "J": [1e-4, -1e-4, 1e-4]}), "reaction_wheels.J"),
    ("reaction_wheels", dict(body="cube", **{**OK_WHEELS, "J": [1e-4, np.inf, 1e-4]}), "reaction_wheels.J"),
    ("reaction_wheels", dict(body="cube", **{**OK_WHEELS, "J": [1e-4, 1e-4]}), "reaction_wheels.J"),
    ("reaction_wheels", dict(body="cube", **{**OK_WHEELS, "J": [1e-4, 1e-4, I_CUBE]}), "reaction_wheels.J"),
    ("reaction_wheels", dict(body="cube", **{**OK_WHEELS, "J": [1e-4, 1e-4, 1.0]}), "reaction_wheels.J"),
    ("reaction_wheels", dict(body="cube", **{**OK_WHEELS, "torque_limit": 0.0}), "reaction_wheels.torque_limit"),
    ("reaction_wheels", dict(body="cube", **{**OK_WHEELS, "torque_limit": -1.0}), "reaction_wheels.torque_limit"),
    ("reaction_wheels", dict(body="cube", **{**OK_WHEELS, "torque_limit": np.nan}), "reaction_wheels.torque_limit"),
    ("reaction_wheels", dict(body="cube", **{**OK_WHEELS, "speed_limit": 0.0}), "reaction_wheels.speed_limit"),
    ("reaction_wheels", dict(body="cube", **{**OK_WHEELS, "speed_limit": np.inf}), "reaction_wheels.speed_limit"),
    ("reaction_wheels", dict(body="cube", c_w=-0.1, **OK_WHEELS), "reaction_wheels.c_w"),
    ("reaction_wheels", dict(body="cube", c_w=np.nan, **OK_WHEELS), "reaction_wheels.c_w"),
    ("reaction_wheels", dict(body="cube", J=[1e-4] * 3, speed_limit=400.0), "reaction_wheels.torque_limit"),
    ("reaction_wheels", dict(body="cube", wheel_count=3, **OK_WHEELS), "reaction_wheels.wheel_count"),
])
def test_bad_effect_parameters_add_nothing(name, params, field):
    s = one_cube()
    with pytest.raises(E) as e:
        s.add_effect(name, **params)
    assert e.value.field == field
    assert s.effects == []


@pytest.mark.parametrize("name,params", [("spherical_joint", dict(anchor_w=[1, 0, 0])), ("reaction_wheels", OK_WHEELS)])
def test_at_most_one_joint_and_one_wheel_set_per_body(name, params):
    s = one_cube()
    s.add_body(lv.Body.sphere("ball", 1.0, 0.1))
    first = s.add_effect(name, body="cube", **params)
    with pytest.raises(E, match="at most one") as e:
        s.add_effect(name, body="cube", **params)
    assert e.value.field == f"{name}.body" and s.effects == [first]
    s.add_effect(name, body="ball", **params)  # another body may have its own
    assert len(s.effects) == 2


def test_effect_instances_without_a_body_are_rejected():
    with pytest.raises(E) as e:
        lv.effects.SphericalJoint(anchor_w=[0, 0, 0])
    assert e.value.field == "spherical_joint.body"


@pytest.mark.parametrize("backend", BACKENDS)
def test_wheel_and_joint_accessors_validate_and_change_nothing(backend):
    s = wheel_cube()
    s.add_body(lv.Body.sphere("ball", 1.0, 0.1))
    sim = lv.Sim(s, backend=backend)
    sim.set_wheel_command("cube", [0.01, 0.02, 0.03])
    x0 = sim.x.copy()
    for bad in ([0.1, 0.2], [0.1, np.nan, 0], [[0.1, 0.2, 0.3]], "up", None):
        with pytest.raises(E) as e:
            sim.set_wheel_command("cube", bad)
        assert e.value.field == "u"
    np.testing.assert_array_equal(sim.wheel_command("cube"), [0.01, 0.02, 0.03])
    for call in (lambda: sim.set_wheel_command("ball", [0, 0, 0]), lambda: sim.wheel_rates("ball"),
                 lambda: sim.wheel_command_applied("ball"), lambda: sim.wheel_rates("ghost")):
        with pytest.raises(E) as e:
            call()
        assert e.value.field == "body"
    with pytest.raises(E) as e:
        sim.set_state("cube", omega_b=[1, 2, 3], Omega=[0, np.inf, 0])
    assert e.value.field == "Omega"
    with pytest.raises(E) as e:
        sim.set_state("ball", omega_b=[1, 2, 3], Omega=[0, 0, 0])
    assert e.value.field == "Omega"
    for field in ("p_w", "v_w"):
        with pytest.raises(E, match="spherical_joint") as e:
            sim.set_state("cube", omega_b=[1, 2, 3], **{field: [0, 0, 1]})
        assert e.value.field == field
    np.testing.assert_array_equal(sim.x, x0)
    np.testing.assert_array_equal(sim.wheel_rates("cube"), [0, 0, 0])
