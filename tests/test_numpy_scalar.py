"""The NumPy backend's float path for a few bodies (lavendersim/backends/numpy_scalar.py) steps bit for bit as its
vectorized path: explicit Runge–Kutta tableaux (built-in and user), with and without effects (per body and
scene-wide, every built-in force effect), normalized or not; it hands back to the vectorized path (which reports
the divergence, nothing applied) where a number is not finite; it is taken only where it applies."""
import numpy as np
import pytest

import lavendersim as lv
from lavendersim import backends as B
from lavendersim.backends import Tableau
from lavendersim.backends import numpy_scalar as SC
from lavendersim.backends.numpy_backend import _BUILTIN_RK, NumpyBackend
from lavendersim.generated import layout as LY

KUTTA3 = Tableau("test_scalar_kutta3", [0, 0.5, 1], [[0, 0, 0], [0.5, 0, 0], [-1.0, 2.0, 0]], [1 / 6, 2 / 3, 1 / 6], 3,
                 "tests")
RALSTON = Tableau("test_scalar_ralston", [0, 2 / 3], [[0, 0], [2 / 3, 0]], [1 / 4, 3 / 4], 2, "tests")


@pytest.fixture
def tableaux():
    before = dict(B.USER_TABLEAUX)
    B.USER_TABLEAUX.update({t.name: t for t in (KUTTA3, RALSTON)})
    yield
    B.USER_TABLEAUX.clear()
    B.USER_TABLEAUX.update(before)


def scene(n=5, effects="mixed"):
    rng = np.random.default_rng(11)
    s = lv.Scene()
    q = rng.normal(size=(n, 4))
    s.add_bodies([f"b{i}" for i in range(n)], rng.uniform(0.5, 2, n), np.sort(rng.uniform(1.0, 1.9, (n, 3)), axis=1),
                 q=q / np.linalg.norm(q, axis=1, keepdims=True), omega_b=rng.uniform(-3, 3, (n, 3)),
                 v_w=rng.normal(size=(n, 3)), p_w=rng.normal(size=(n, 3)))
    if effects in ("mixed", "uniform"):
        s.add_effect("gravity", g_w=(0.1, 0.0, -9.81))
        s.add_effect("linear_damping", c=0.3)
    if effects == "mixed":
        s.add_effect("angular_damping", body="b1", c=0.2)
        s.add_effect("applied_torque", body="b2", torque_w=(0.1, -0.2, 0.3))
        s.add_effect("force_at_point", body="b2", F_w=(0.5, 0.1, -0.2), r_b=(0.1, 0.2, -0.1))
        s.add_effect("angular_damping", body="b2", c=0.05)
    return s


def run(s, integrator, scalar, n_steps=60, dt=0.01, normalize=True, monkeypatch=None):
    """(state after n_steps, whether the float path took the call)."""
    sim = lv.Sim(s, dt=dt, integrator="rk4", backend="numpy")
    x = sim.x.copy()
    calls = []
    real = SC.advance

    def spy(*a, **k):
        calls.append(1)
        return real(*a, **k)
    monkeypatch.setattr(SC, "advance", spy)
    monkeypatch.setattr(SC, "SCALAR_MAX_BODIES", 10**6 if scalar else 0)
    NumpyBackend().advance(x, sim.params, sim.effects, integrator, normalize, dt, n_steps)
    return x, bool(calls)


@pytest.mark.parametrize("integrator", ["rk4", "euler", KUTTA3.name, RALSTON.name])
@pytest.mark.parametrize("effects", ["none", "uniform", "mixed"])
@pytest.mark.parametrize("normalize", [True, False])
def test_float_path_is_the_vectorized_path_bitwise(tableaux, monkeypatch, integrator, effects, normalize):
    a, took = run(scene(5, effects), integrator, True, normalize=normalize, monkeypatch=monkeypatch)
    b, took_b = run(scene(5, effects), integrator, False, normalize=normalize, monkeypatch=monkeypatch)
    assert took and not took_b
    start = lv.Sim(scene(5, effects), dt=0.01, backend="numpy").x
    assert np.max(np.abs(a - start)) > 1e-2                      # the bodies moved
    assert a.tobytes() == b.tobytes()


def test_path_taken_only_where_it_applies(monkeypatch):
    assert run(scene(SC.SCALAR_MAX_BODIES), "rk4", True, 2, monkeypatch=monkeypatch)[1]
    monkeypatch.undo()
    assert run(scene(SC.SCALAR_MAX_BODIES), "rk4", True, 2, monkeypatch=monkeypatch)[1]   # at the default limit
    monkeypatch.undo()
    for integrator in ("semi_implicit_euler", "splitting", "rk4_expmap"):
        assert not run(scene(3), integrator, True, 2, monkeypatch=monkeypatch)[1]
        monkeypatch.undo()
    sim = lv.Sim(scene(SC.SCALAR_MAX_BODIES + 1), dt=0.01, backend="numpy")
    monkeypatch.setattr(SC, "advance", lambda *a, **k: pytest.fail("float path above SCALAR_MAX_BODIES"))
    NumpyBackend().advance(sim.x.copy(), sim.params, sim.effects, "rk4", True, 0.01, 2)


def test_divergence_hands_back_and_is_reported(monkeypatch):
    sim = lv.Sim(scene(3, "mixed"), dt=0.01, backend="numpy")
    x = sim.x.copy()
    x[1, LY.STATE_OMEGA_B] = (1e200, 1e200, 1e200)
    before = x.copy()
    with pytest.raises(lv.errors.DivergenceError) as info:
        NumpyBackend().advance(x, sim.params, sim.effects, "rk4", True, 0.01, 5)
    assert info.value.body == 1 and info.value.step == 0
    assert x.tobytes() == before.tobytes()
    x[1, LY.STATE_OMEGA_B] = (1e200, 1e200, 1e200)
    with pytest.raises(SC.Fallback):                     # the float path itself stops, writing nothing
        SC.advance(SC.ScalarBodies(sim.params, sim.effects), x, _BUILTIN_RK["rk4"], True, 0.01, 5)
    assert x.tobytes() == before.tobytes()


def test_sim_run_on_one_body_uses_the_float_path(monkeypatch):
    calls = []
    real = SC.advance
    monkeypatch.setattr(SC, "advance", lambda *a, **k: (calls.append(1), real(*a, **k))[1])
    s = lv.Scene()
    s.add_body(lv.Body("a", 1.0, (1.0, 2.0, 3.0), omega_b=(0.1, 2.0, 0.1)))
    sim = lv.Sim(s, dt=0.01, integrator="rk4", backend="numpy")
    sim.run(100)
    c = lv.Sim(s, dt=0.01, integrator="rk4", backend="c")
    c.run(100)
    assert calls
    np.testing.assert_allclose(sim.x, c.x, rtol=0, atol=1e-13)
