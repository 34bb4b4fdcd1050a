"""The generic explicit Runge–Kutta stepper of both backends (a user's backends.Tableau; NumPy: numpy_backend's
_ExplicitRK, C: csrc/step.c advance_tableau): classic RK4 declared as a tableau steps bitwise as the built-in rk4
(bodies with effects, wheeled and jointed bodies; torque-free ones to rounding: the built-in takes its scaled-increment
form there), Kutta's third-order method agrees with an independent
plain-Python implementation to 1e-13 (and with its stages written out on wheeled and jointed bodies), C = NumPy bitwise
on a user tableau, a tableau a backend cannot step is refused naming `integrator`, and a divergence is reported with
nothing half-applied."""
import math

import numpy as np
import pytest

import lavendersim as lv
from lavendersim import backends as B
from lavendersim.backends import KIND_WHEELS, Models, Tableau, rk_weights, wheel_row
from lavendersim.backends.numpy_backend import NumpyBackend, _Plan
from lavendersim.effects import REGISTRY
from lavendersim.errors import DivergenceError
from lavendersim.generated import layout as LY
from lavendersim.kernels import K

RK4 = Tableau("test_rk4_tableau", [0, 0.5, 0.5, 1], [[0, 0, 0, 0], [0.5, 0, 0, 0], [0, 0.5, 0, 0], [0, 0, 1, 0]],
              [1 / 6, 1 / 3, 1 / 3, 1 / 6], 4, "tests")
KUTTA3 = Tableau("test_kutta3", [0, 0.5, 1], [[0, 0, 0], [0.5, 0, 0], [-1.0, 2.0, 0]], [1 / 6, 2 / 3, 1 / 6], 3,
                 "tests")


def c_backend():
    """The C backend (the test is skipped without the compiled extension)."""
    return pytest.importorskip("lavendersim.backends.c_backend").CBackend()


@pytest.fixture(params=["numpy", "c"])
def backend(request):
    return NumpyBackend() if request.param == "numpy" else c_backend()


@pytest.fixture
def tableaux():
    """RK4 and Kutta3 registered as user tableaux for the test, and removed after it."""
    before = dict(B.USER_TABLEAUX)
    B.USER_TABLEAUX.update({t.name: t for t in (RK4, KUTTA3)})
    yield
    B.USER_TABLEAUX.clear()
    B.USER_TABLEAUX.update(before)


def scene(effects):
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


def arrays(s):
    sim = lv.Sim(s, dt=0.01, integrator="rk4", backend="numpy")
    return sim.x.copy(), sim.params.copy(), sim.effects.copy(), sim.names


def advanced(backend, x0, params, eff, name, n, normalize=True, dt=0.01):
    x = x0.copy()
    backend.advance(x, params, eff, name, normalize, dt, n)
    return x


def test_rk4_weights_are_their_common_denominator():
    np.testing.assert_array_equal(rk_weights(RK4)[0], [1.0, 2.0, 2.0, 1.0])
    assert rk_weights(RK4)[1] == 6.0
    assert rk_weights(KUTTA3)[1] == 6.0 and list(rk_weights(KUTTA3)[0]) == [1.0, 4.0, 1.0]
    odd = Tableau("odd", [0, 0.3], [[0, 0], [0.3, 0]], [math.pi / 10, 1 - math.pi / 10], 1)
    assert rk_weights(odd)[1] == 1.0 and list(rk_weights(odd)[0]) == list(odd.b)


@pytest.mark.parametrize("normalize", [True, False])
@pytest.mark.parametrize("effects", [False, True], ids=["free", "gravity+damping"])
def test_rk4_declared_as_a_tableau_agrees_with_the_builtin_rk4_to_rounding(tableaux, backend, effects, normalize):
    """b = (1/6, 1/3, 1/3, 1/6) is stepped as (1, 2, 2, 1)/6 (backends.rk_weights). The built-in rk4 steps plain
    bodies, torque-free or with effects, in its scaled-increment form (tableaux.h LV_RK4_SCALED_STEP: the same
    method, other roundings), so the tableau agrees with it to rounding, not bitwise."""
    x0, params, eff, _ = arrays(scene(effects))
    rk4 = advanced(backend, x0, params, eff, "rk4", 300, normalize)
    assert np.max(np.abs(rk4 - x0)) > 0.1   # the bodies moved
    tab = advanced(backend, x0, params, eff, RK4.name, 300, normalize)
    np.testing.assert_allclose(tab, rk4, rtol=0, atol=1e-12)
    assert not np.array_equal(tab, rk4)   # (the bodies did take the other form)


def test_many_bodies_on_the_builtin_fast_paths(tableaux, backend):
    """C's rk4 puts 40 torque-free bodies on SIMD tiles and lockstep blocks; the tableau steps them one by one: the
    same to rounding (the built-in's form for plain bodies is the scaled-increment one, LV_RK4_SCALED_STEP), the
    damped body too."""
    rng = np.random.default_rng(3)
    nb = 40
    x0 = np.zeros((nb, LY.STATE_SIZE))
    q = rng.normal(size=(nb, 4))
    x0[:, LY.STATE_Q] = q / np.linalg.norm(q, axis=1, keepdims=True)
    x0[:, LY.STATE_OMEGA_B] = rng.uniform(-3, 3, (nb, 3))
    x0[:, LY.STATE_V_W] = rng.normal(size=(nb, 3))
    params = np.column_stack([rng.uniform(0.5, 2, nb), rng.uniform(0.5, 2, (nb, 3))])
    eff = np.zeros((1, 8))
    eff[0, :3] = [REGISTRY["angular_damping"].code, 7, 0.1]
    rk4, tab = advanced(backend, x0, params, eff, "rk4", 100), advanced(backend, x0, params, eff, RK4.name, 100)
    assert not np.array_equal(tab[7], rk4[7])   # (the damped body took the scaled form too)
    np.testing.assert_allclose(tab, rk4, rtol=0, atol=1e-12)


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


def test_kutta3_against_an_independent_implementation(tableaux, backend):
    x0, params, eff, names = arrays(scene(True))
    x = advanced(backend, x0, params, eff, KUTTA3.name, 300)
    damping = {"a": (0.4, 0.3), "b": (0.0, 0.05), "c": (0.0, 0.0)}
    for i, name in enumerate(names):
        m, I = float(params[i, LY.PARAM_M]), [float(v) for v in params[i, LY.PARAM_I_B]]
        ref = np.array(kutta3([float(v) for v in x0[i]], 0.01, 300, m, I, (0.0, 0.0, -9.81), *damping[name]))
        assert np.max(np.abs(x[i] - ref) / np.maximum(1.0, np.abs(ref))) <= 1e-13, name
        assert np.max(np.abs(x[i] - x0[i])) > 0.1      # it moved: the comparison can fail
    # third order, not rk4 under another name
    assert np.max(np.abs(x - advanced(backend, x0, params, eff, "rk4", 300))) > 1e-9


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


def run(backend, name, state, params, effects, md, n=80, dt=0.005):
    x, m = state.copy(), copy(md)
    backend.advance(x, params, effects, name, True, dt, n, m)
    return x, m


def test_wheeled_and_jointed_bodies_rk4_bitwise(tableaux, backend):
    state, params, effects, md = models_scene(np.random.default_rng(5))
    xa, ma = run(backend, "rk4", state, params, effects, md)
    xb, mb = run(backend, RK4.name, state, params, effects, md)
    assert np.max(np.abs(ma.Omega - md.Omega)) > 1e-3 and np.all(ma.applied[[1, 3, 4], :3] != 0)
    # the bodies with models keep the tableau's RK4 (csrc/model_simd.h, LV_RK4_STEP): bitwise; the plain body 0 (gravity)
    # takes the built-in's scaled-increment form (LV_RK4_SCALED_STEP): the same to rounding
    np.testing.assert_array_equal(xa[1:], xb[1:])
    np.testing.assert_allclose(xa[0], xb[0], rtol=0, atol=1e-12)
    assert not np.array_equal(xa[0], xb[0])
    np.testing.assert_array_equal(ma.Omega, mb.Omega)
    np.testing.assert_array_equal(ma.applied, mb.applied)


def test_kutta3_on_wheeled_and_jointed_bodies_is_its_stages_written_out(tableaux, backend):
    """Kutta3 on the NumPy plan's right-hand side, the stages written out (the wheel torques held over each step)."""
    state, params, effects, md = models_scene(np.random.default_rng(5))
    xk, mk = run(backend, KUTTA3.name, state, params, effects, md)
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
    assert np.max(np.abs(xk - y[:, :LY.STATE_SIZE])) <= 1e-13 * max(1.0, np.max(np.abs(y)))
    assert np.max(np.abs(mk.Omega - y[:, LY.XS_OMEGA])) <= 1e-13 * max(1.0, np.max(np.abs(mk.Omega)))
    assert np.max(np.abs(xk - run(backend, "rk4", state, params, effects, md)[0])) > 1e-9    # a different method
    # the jointed bodies stay on their joint
    for b in (2, 3):
        r_b, anchor = md.rows[b, LY.MODEL_R_B], md.rows[b, LY.MODEL_ANCHOR_W]
        np.testing.assert_allclose(xk[b, LY.STATE_P_W] - K.quat_rotate(xk[b, LY.STATE_Q], r_b), anchor, atol=1e-12)


@pytest.mark.parametrize("name", [KUTTA3.name, RK4.name])
def test_c_equals_numpy_on_a_user_tableau(tableaux, name):
    """Both backends step a user tableau in the same operation order (csrc/step.h lv_tableau) with the same weights
    (backends.rk_weights): bitwise equal, plain, jointed and wheeled bodies alike."""
    C = c_backend()
    state, params, effects, md = models_scene(np.random.default_rng(11))
    xc, mc = run(C, name, state, params, effects, md)
    xn, mn = run(NumpyBackend(), name, state, params, effects, md)
    np.testing.assert_array_equal(xc, xn)
    np.testing.assert_array_equal(mc.Omega, mn.Omega)
    np.testing.assert_array_equal(mc.applied, mn.applied)
    x0, p0, e0, _ = arrays(scene(True))
    np.testing.assert_array_equal(advanced(C, x0, p0, e0, name, 200), advanced(NumpyBackend(), x0, p0, e0, name, 200))


# ---------------------------------------------------------------- refusals and divergence

def test_float32_is_refused_naming_the_integrator(tableaux, backend):
    x = np.zeros((1, LY.STATE_SIZE), np.float32)
    x[0, 6] = 1
    params = np.array([[1.0, 1.0, 2.0, 3.0]], np.float32)
    with pytest.raises(ValueError, match=r"integrator: 'test_kutta3' \(a user-declared tableau\) steps float64 only"):
        backend.advance(x, params, np.zeros((0, 8), np.float32), KUTTA3.name, True, 0.01, 1)


def test_a_bad_tableau_is_refused_naming_integrator(tableaux):
    C = c_backend()
    x0, params, eff, _ = arrays(scene(False))
    bad = {
        "test_c_wrong_shape": Tableau("test_c_wrong_shape", [0, 0.5], [[0, 0, 0], [0.5, 0, 0]], [0.5, 0.5], 2),
        "test_c_implicit": Tableau("test_c_implicit", [0.5, 1], [[0.5, 0], [0.5, 0.5]], [0.5, 0.5], 2),
        "test_c_nan": Tableau("test_c_nan", [0, 0.5], [[0, 0], [np.nan, 0]], [0.5, 0.5], 2),
        "test_c_too_many": Tableau("test_c_too_many", np.zeros(17), np.zeros((17, 17)), np.ones(17) / 17, 1),
    }
    B.USER_TABLEAUX.update(bad)
    for name in bad:
        x = x0.copy()
        with pytest.raises(ValueError, match=rf"^integrator: tableau '{name}' must"):
            C.advance(x, params, eff, name, True, 0.01, 3)
        np.testing.assert_array_equal(x, x0)
    with pytest.raises(ValueError, match=r"^integrator: must be one of .*got 'no_such_method'"):
        C.advance(x0.copy(), params, eff, "no_such_method", True, 0.01, 3)
    with pytest.raises(ValueError, match=r"integrator: 'test_kutta3' \(a user-declared tableau\) steps float64 only"):
        C.advance(x0.astype(np.float32), params, eff, KUTTA3.name, True, 0.01, 1)


def test_the_extension_refuses_a_malformed_tableau_argument():
    simulate = pytest.importorskip("lavendersim.backends.c_backend")._c.simulate
    x0, params, eff, _ = arrays(scene(False))
    A, b = np.zeros((2, 2)), np.array([0.5, 0.5])
    for tab, msg in [((A, np.ones(3), 1.0), "shape"), ((np.ones((2, 2)), b, 1.0), "explicit"),
                     ((A, b, 0.0), "b_den > 0"), ((A, b), "tableau")]:
        with pytest.raises((ValueError, TypeError), match=msg):
            simulate(x0.copy(), params, eff, 2, 1, 0.01, 1, None, None, None, None, None, None, 0.0, 0.0, None, tab)


def test_divergence_is_reported_and_nothing_is_half_applied(tableaux, backend):
    x0, params, eff, _ = arrays(scene(False))
    x0[1, LY.STATE_OMEGA_B] = (1e200, 1e200, 1e200)
    x = x0.copy()
    with pytest.raises(DivergenceError) as info:
        backend.advance(x, params, eff, KUTTA3.name, True, 0.01, 5)
    assert info.value.body == 1 and info.value.step == 0
    np.testing.assert_array_equal(x, x0)
    # the same report as the built-in rk4's
    with pytest.raises(DivergenceError) as ref:
        backend.advance(x0.copy(), params, eff, "rk4", True, 0.01, 5)
    assert (ref.value.step, ref.value.body) == (info.value.step, info.value.body)
