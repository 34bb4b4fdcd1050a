"""The NumPy backend's generic explicit Runge–Kutta stepper (a Butcher tableau, backends.Tableau): classic RK4
declared as a tableau steps as the built-in rk4, and Kutta's third-order method agrees with an independent
plain-Python implementation, with gravity and damping, and on wheeled and jointed bodies."""
import math

import numpy as np
import pytest

import lavendersim as lv
from lavendersim import backends as B
from lavendersim.backends import KIND_WHEELS, Models, Tableau, wheel_row
from lavendersim.backends.numpy_backend import NumpyBackend, _Plan
from lavendersim.effects import REGISTRY
from lavendersim.generated import layout as LY
from lavendersim.kernels import K

RK4 = Tableau("test_rk4_tableau", [0, 0.5, 0.5, 1], [[0, 0, 0, 0], [0.5, 0, 0, 0], [0, 0.5, 0, 0], [0, 0, 1, 0]],
              [1 / 6, 1 / 3, 1 / 3, 1 / 6], 4, "tests")
KUTTA3_A = [[0, 0, 0], [0.5, 0, 0], [-1.0, 2.0, 0]]
KUTTA3_B = [1 / 6, 2 / 3, 1 / 6]
KUTTA3 = Tableau("test_kutta3", [0, 0.5, 1], KUTTA3_A, KUTTA3_B, 3, "tests")


@pytest.fixture
def tableaux():
    """RK4 and Kutta3 registered as user tableaux for the test, and removed after it."""
    before = dict(B.USER_TABLEAUX)
    B.USER_TABLEAUX.update({t.name: t for t in (RK4, KUTTA3)})
    yield
    B.USER_TABLEAUX.clear()
    B.USER_TABLEAUX.update(before)


def scene(effects=True):
    s = lv.Scene()
    s.add_body(lv.Body("a", 2.0, (1.0, 2.0, 3.0), omega_b=(1.0, 0.5, 0.2), v_w=(0.3, -0.1, 2.0)))
    s.add_body(lv.Body("b", 0.7, (0.4, 0.5, 0.9), omega_b=(-3.0, 1.5, 0.7), p_w=(1, 2, 3)))
    s.add_body(lv.Body("c", 1.3, (2.0, 2.0, 1.0), omega_b=(0.2, 0.0, 4.0)))
    if effects:
        s.add_effect("gravity", g_w=(0.0, 0.0, -9.81))
        s.add_effect("linear_damping", body="a", c=0.4)
        s.add_effect("angular_damping", body="a", c=0.3)
        s.add_effect("angular_damping", body="b", c=0.05)
    return s


def advance(s, integrator, n=200, dt=0.01, normalize=True):
    sim = lv.Sim(s, dt=dt, integrator="rk4", backend="numpy")
    x = sim.x.copy()
    NumpyBackend().advance(x, sim.params, sim.effects, integrator, normalize, dt, n)
    return x


@pytest.mark.parametrize("effects", [False, True], ids=["free", "gravity+damping"])
def test_rk4_declared_as_a_tableau_steps_as_the_builtin_rk4(tableaux, effects):
    a = advance(scene(effects), "rk4")
    b = advance(scene(effects), RK4.name)
    assert np.max(np.abs(a - advance(scene(effects), "rk4", n=199))) > 1e-3   # the runs move
    # b = (1/6, 1/3, 1/3, 1/6) is stepped as (1, 2, 2, 1)/6 (backends.rk_weights), as rk4
    np.testing.assert_array_equal(a, b)


# ---------------------------------------------------------------- an independent Kutta3, plain Python floats

def quat_mul(a, b):
    ax, ay, az, aw = a
    bx, by, bz, bw = b
    return (aw * bx + ax * bw + ay * bz - az * by, aw * by - ax * bz + ay * bw + az * bx,
            aw * bz + ax * by - ay * bx + az * bw, aw * bw - ax * bx - ay * by - az * bz)


def cross(a, b):
    return (a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0])


def rhs(x, m, I, g, c_lin, c_ang):
    """d/dt of one body's 13 numbers under gravity g (world), drag -c_lin v_w, torque -c_ang omega_b (body frame).

    angular_damping declares tau_B = -c omega_B; a body whose torques are all body-frame takes it so (nothing
    rotated). Its world form R^T(-c R omega_B) equals it on the unit sphere only: the stage states' q are not unit."""
    v, q, w = x[7:10], x[3:7], x[10:13]
    q_dot = [0.5 * c for c in quat_mul(q, (w[0], w[1], w[2], 0.0))]
    v_dot = [g[i] - c_lin * v[i] / m for i in range(3)]
    tau_b = [-c_ang * c for c in w]
    gyro = cross(w, [I[i] * w[i] for i in range(3)])
    w_dot = [(tau_b[i] - gyro[i]) / I[i] for i in range(3)]
    return list(v) + q_dot + v_dot + w_dot


def kutta3(x, dt, n, *args):
    for _ in range(n):
        k1 = rhs(x, *args)
        k2 = rhs([xi + dt * 0.5 * a for xi, a in zip(x, k1)], *args)
        k3 = rhs([xi + dt * (-a + 2.0 * b) for xi, a, b in zip(x, k1, k2)], *args)
        x = [xi + dt * (a + 4.0 * b + c) / 6.0 for xi, a, b, c in zip(x, k1, k2, k3)]
        s = math.sqrt(sum(c * c for c in x[3:7]))
        x[3:7] = [c / s for c in x[3:7]]
    return x


def test_kutta3_against_an_independent_implementation(tableaux):
    s = scene(True)
    sim = lv.Sim(s, dt=0.01, integrator="rk4", backend="numpy")
    x0 = sim.x.copy()
    x = advance(s, KUTTA3.name, n=300, dt=0.01)
    damping = {"a": (0.4, 0.3), "b": (0.0, 0.05), "c": (0.0, 0.0)}
    for i, name in enumerate(sim.names):
        m, I = float(sim.params[i, LY.PARAM_M]), [float(v) for v in sim.params[i, LY.PARAM_I_B]]
        ref = np.array(kutta3([float(v) for v in x0[i]], 0.01, 300, m, I, (0.0, 0.0, -9.81), *damping[name]))
        scale = np.maximum(1.0, np.abs(ref))
        assert np.max(np.abs(x[i] - ref) / scale) <= 1e-13, name
        assert np.max(np.abs(x[i] - x0[i])) > 0.1      # it moved: the comparison can fail
    # and it is third order, not RK4 under another name
    assert np.max(np.abs(x - advance(s, "rk4", n=300, dt=0.01))) > 1e-9


# ---------------------------------------------------------------- wheels and joints

def models_scene(rng):
    """Five bodies: plain, wheeled (body axes), jointed, wheeled + jointed, wheeled on 4 random axes."""
    kinds = [0, KIND_WHEELS, 1, 3, KIND_WHEELS]
    nb = len(kinds)
    params = np.column_stack([rng.uniform(0.5, 2.0, nb), rng.uniform(0.5, 2.0, (nb, 3))])
    state = np.zeros((nb, LY.STATE_SIZE))
    state[:, LY.STATE_P_W] = rng.normal(size=(nb, 3))
    q = rng.normal(size=(nb, 4))
    state[:, LY.STATE_Q] = q / np.linalg.norm(q, axis=1, keepdims=True)
    state[:, LY.STATE_V_W] = rng.normal(size=(nb, 3))
    state[:, LY.STATE_OMEGA_B] = rng.uniform(-2, 2, (nb, 3))
    md = Models.empty(nb)
    for b, kind in enumerate(kinds):
        I_b = params[b, LY.PARAM_I_B]
        r_b = rng.uniform(-0.3, 0.3, 3) if kind & 1 else np.zeros(3)
        row = md.rows[b]
        row[LY.MODEL_KIND] = kind
        row[LY.MODEL_I_P] = K.parallel_axis(np.diag(I_b), params[b, LY.PARAM_M], -r_b).reshape(9)
        row[LY.MODEL_R_B] = r_b
        row[LY.MODEL_ANCHOR_W] = state[b, LY.STATE_P_W] - K.quat_rotate(state[b, LY.STATE_Q], r_b)
        if kind & KIND_WHEELS:
            nw = 4 if b == 4 else 3
            A = rng.normal(size=(3, nw)) if b == 4 else np.eye(3)
            A /= np.linalg.norm(A, axis=0)
            wheel_row(row, 0.05 * I_b.min() * np.ones(nw), A)
            row[LY.MODEL_TORQUE_LIMIT], row[LY.MODEL_SPEED_LIMIT], row[LY.MODEL_C_W] = 0.3, 40.0, 1e-3
            md.Omega[b, :nw] = rng.uniform(-5, 5, nw)
            md.command[b, :nw] = rng.uniform(-0.5, 0.5, nw)
    effects = np.zeros((2, 8))     # gravity on every body, angular damping on body 3
    effects[0, :5] = [REGISTRY["gravity"].code, -1, 0.0, 0.0, -9.81]
    effects[1, :3] = [REGISTRY["angular_damping"].code, 3, 0.2]
    return state, params, effects, md


def copy(md):
    return Models(md.rows.copy(), md.Omega.copy(), md.command.copy(), md.applied.copy())


def test_wheeled_and_jointed_bodies(tableaux):
    state, params, effects, md = models_scene(np.random.default_rng(5))
    runs = {}
    for name in ("rk4", RK4.name, KUTTA3.name):
        x, m = state.copy(), copy(md)
        NumpyBackend().advance(x, params, effects, name, True, 0.005, 80, m)
        runs[name] = (x, m)
    (xa, ma), (xb, mb) = runs["rk4"], runs[RK4.name]
    np.testing.assert_array_equal(xa, xb)
    np.testing.assert_array_equal(ma.Omega, mb.Omega)
    np.testing.assert_array_equal(ma.applied, mb.applied)
    assert np.all(ma.applied[[1, 3, 4], :3] != 0)
    # Kutta3 on the same right-hand side, the stages written out (the wheel torques held over each step)
    plan = _Plan(params, effects, md.rows)
    y = np.concatenate([state, md.Omega], axis=1)
    for _ in range(80):
        u = plan.applied(y, md.command)
        f = lambda z: plan.rhs(z, u)  # noqa: E731
        k1 = f(y)
        k2 = f(y + 0.005 * (0.5 * k1))
        k3 = f(y + 0.005 * (-k1 + 2.0 * k2))
        y = y + 0.005 * (k1 / 6 + 2 * k2 / 3 + k3 / 6)
        y[:, LY.STATE_Q] = K.quat_normalize(y[:, LY.STATE_Q])
        plan.constrain(y)
    xk, mk = runs[KUTTA3.name]
    assert np.max(np.abs(xk - y[:, :LY.STATE_SIZE])) <= 1e-13 * max(1.0, np.max(np.abs(y)))
    assert np.max(np.abs(mk.Omega - y[:, LY.XS_OMEGA])) <= 1e-13 * max(1.0, np.max(np.abs(mk.Omega)))
    assert np.max(np.abs(xk - xa)) > 1e-9       # a different method
    # the jointed bodies stay on their joint
    for b in (2, 3):
        r_b, anchor = md.rows[b, LY.MODEL_R_B], md.rows[b, LY.MODEL_ANCHOR_W]
        np.testing.assert_allclose(xk[b, LY.STATE_P_W] - K.quat_rotate(xk[b, LY.STATE_Q], r_b), anchor, atol=1e-12)


def test_float32_is_refused_naming_the_integrator(tableaux):
    x = np.zeros((1, LY.STATE_SIZE), np.float32)
    x[0, 6] = 1
    params = np.array([[1.0, 1.0, 2.0, 3.0]], np.float32)
    with pytest.raises(ValueError, match=r"integrator: 'test_kutta3' \(a user-declared tableau\) steps float64 only"):
        NumpyBackend().advance(x, params, np.zeros((0, 8), np.float32), KUTTA3.name, True, 0.01, 1)


def test_divergence_is_reported_and_nothing_is_half_applied(tableaux):
    sim = lv.Sim(scene(False), dt=0.01, integrator="rk4", backend="numpy")
    x = sim.x.copy()
    x[1, LY.STATE_OMEGA_B] = (1e200, 1e200, 1e200)
    before = x.copy()
    with pytest.raises(lv.errors.DivergenceError) as info:
        NumpyBackend().advance(x, sim.params, sim.effects, KUTTA3.name, True, 0.01, 5)
    assert info.value.body == 1 and info.value.step == 0
    np.testing.assert_array_equal(x, before)
