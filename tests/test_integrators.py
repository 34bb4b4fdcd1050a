"""The integrators beyond euler / semi-implicit Euler / RK4 — dopri5, splitting, implicit_gyro — and the
RHS counter, on both backends (never skipped), against lavendersim.oracle."""
import numpy as np
import pytest

import lavendersim as lv
from lavendersim.errors import ValidityBoundWarning
from lavendersim import oracle as R

# Long NumPy runs are in the slow set (NUMPY_SLOW: tests/conftest.py); test_c_and_numpy_agree
# checks quickly that NumPy computes what C computes.
from conftest import NUMPY_SLOW

BACKENDS = ["numpy", "c"]
I3 = (1.0, 2.0, 3.0)
W0 = (1.0, 0.5, 0.2)


def scene(I=I3, omega_b=W0, **kw):
    s = lv.Scene()
    s.add_body(lv.Body("b", 1.0, I, omega_b=omega_b, **kw))
    return s


def error(sim, ref, k=0):
    """attitude error (rad) + |omega error| (rad/s) against the exact reference sample k."""
    st = sim.state("b")
    return float(R.attitude_error(st.q, ref.q[k])) + float(np.linalg.norm(st.omega_b - ref.omega_b[k]))


def energy(x, I=I3):
    return 0.5 * np.sum(np.asarray(I) * x[..., 10:13] ** 2, axis=-1)


# ---------------------------------------------------------------- convergence order

ORDERS = {"euler": 1, "semi_implicit_euler": 1, "rk4": 4, "splitting": 2, "implicit_gyro": 1}


@pytest.mark.parametrize("backend", BACKENDS)
@pytest.mark.parametrize("integrator", list(ORDERS))
def test_convergence_order_against_the_exact_solution(backend, integrator):
    T = 2.0
    ref = R.torque_free(I3, W0, [0, 0, 0, 1], [T])
    errs = []
    for n in (200, 400, 800):
        sim = lv.Sim(scene(), dt=T / n, integrator=integrator, backend=backend)
        sim.run(n)
        errs.append(error(sim, ref))
    orders = np.log2(np.array(errs[:-1]) / np.array(errs[1:]))
    np.testing.assert_allclose(orders, ORDERS[integrator], atol=0.1)


# ---------------------------------------------------------------- dopri5

@pytest.mark.parametrize("backend", BACKENDS)
def test_dopri5_meets_its_tolerance_with_fewer_evaluations_than_rk4(backend):
    T, rtol = 2.0, 1e-8
    ref = R.torque_free(I3, W0, [0, 0, 0, 1], [T])
    sim = lv.Sim(scene(), dt=0.5, integrator="dopri5", rtol=rtol, atol=rtol * 1e-2, backend=backend)
    sim.run(4)
    assert sim.t == pytest.approx(T, abs=1e-15)
    e_dp = error(sim, ref)
    assert e_dp <= rtol
    # RK4 with the same evaluation budget is less accurate
    n = sim.rhs_evals // 4
    rk = lv.Sim(scene(), dt=T / n, integrator="rk4", backend=backend)
    rk.run(n)
    assert rk.rhs_evals <= sim.rhs_evals
    assert error(rk, ref) > 2 * e_dp


@pytest.mark.parametrize("backend", BACKENDS)
def test_dopri5_error_follows_the_tolerance_and_output_steps_land_on_dt(backend):
    T = 10.0
    ref = R.torque_free(I3, (0.1, 2.0, 0.1), [0, 0, 0, 1], np.arange(1, 11) * 1.0)
    prev = None
    for rtol in (1e-6, 1e-9):
        sim = lv.Sim(scene(omega_b=(0.1, 2.0, 0.1)), dt=1.0, integrator="dopri5", rtol=rtol, atol=rtol * 1e-2,
                     backend=backend)
        for k in range(10):
            sim.step()
            assert sim.t == pytest.approx(k + 1.0, abs=1e-12)
            assert error(sim, ref, k) <= 50 * rtol * T
        assert prev is None or sim.rhs_evals > prev
        prev = sim.rhs_evals


def test_dopri5_backends_agree_to_the_tolerance_on_several_bodies():
    """Both backends step each body on its own step sizes (one algorithm): both meet the tolerance, bitwise equal."""
    s = lv.Scene()
    ws = [(1.0, 0.5, 0.2), (0.1, 2.0, 0.1), (3.0, -1.0, 0.5)]
    for i, w in enumerate(ws):
        s.add_body(lv.Body(f"b{i}", 1.0, I3, omega_b=w))
    out = {}
    for backend in BACKENDS:
        sim = lv.Sim(s, dt=0.25, integrator="dopri5", rtol=1e-9, atol=1e-11, backend=backend)
        sim.run(8)
        out[backend] = sim.x.copy()
        for i, w in enumerate(ws):
            ref = R.torque_free(I3, w, [0, 0, 0, 1], [2.0])
            st = sim.state(f"b{i}")
            assert float(R.attitude_error(st.q, ref.q[0])) + np.linalg.norm(st.omega_b - ref.omega_b[0]) <= 1e-8
    assert np.array_equal(out["c"], out["numpy"])  # the same step sequences (tests/test_dopri5_backends.py)


# NumPy in the slow set: its reference run (2000 rk4 steps of one body, Python per step) cost ~8 s CPU; NumPy = C
# bitwise on a jointed wheeled cube under dopri5: test_dopri5_backends::test_c_and_numpy_agree_bitwise_with_a_jointed_...
@pytest.mark.parametrize("backend", NUMPY_SLOW)
def test_dopri5_steps_jointed_and_wheeled_bodies(backend):
    s = lv.Scene()
    s.add_body(lv.Body.box("cube", 1.0, (0.15, 0.15, 0.15), omega_b=(0.3, -0.2, 0.5)))
    s.add_effect("spherical_joint", body="cube", anchor_w=[0, 0, 0])
    s.add_effect("reaction_wheels", body="cube", J=[2e-4, 3e-4, 2.5e-4], torque_limit=0.2, speed_limit=400.0, c_w=0.0)
    sim = lv.Sim(s, dt=0.1, integrator="dopri5", rtol=1e-10, atol=1e-12, backend=backend)
    sim.set_wheel_command("cube", [0.001, -0.002, 0.0])
    L0 = sum(sim.wheel_momentum_w("cube"))
    sim.run(20)
    assert np.linalg.norm(sum(sim.wheel_momentum_w("cube")) - L0) <= 1e-9 * np.linalg.norm(L0)
    rk = lv.Sim(s, dt=1e-3, integrator="rk4", backend=backend)
    rk.set_wheel_command("cube", [0.001, -0.002, 0.0])
    rk.run(2000)
    np.testing.assert_allclose(sim.x, rk.x, atol=1e-8)
    np.testing.assert_allclose(sim.wheel_rates("cube"), rk.wheel_rates("cube"), rtol=1e-8)


@pytest.mark.parametrize("backend", BACKENDS)
def test_dopri5_with_effects_matches_a_fine_rk4(backend):
    s = scene(v_w=(0.5, 0, 0))
    s.add_effect("gravity", g_w=(0, 0, -9.81))
    s.add_effect("angular_damping", body="b", c=0.3)
    s.add_effect("force_at_point", body="b", r_b=(0.2, 0, 0), F_w=(0, 1.0, 0))
    dp = lv.Sim(s, dt=0.5, integrator="dopri5", rtol=1e-10, atol=1e-12, backend=backend)
    dp.run(4)
    rk = lv.Sim(s, dt=1e-3, integrator="rk4", backend=backend)
    rk.run(2000)
    np.testing.assert_allclose(dp.x, rk.x, rtol=0, atol=1e-8)


@pytest.mark.parametrize("backend", BACKENDS)
def test_dopri5_that_cannot_meet_its_tolerance_names_the_body_and_restores(backend):
    s = lv.Scene()
    s.add_body(lv.Body("calm", 1.0, I3, omega_b=W0))
    s.add_body(lv.Body("stiff", 1.0, I3, omega_b=W0))
    s.add_effect("angular_damping", body="stiff", c=1e14)  # stable step ~3e-14 s < dt * 1e-12
    sim = lv.Sim(s, dt=1.0, integrator="dopri5", backend=backend)
    before = sim.x.copy()
    with pytest.raises(lv.DivergenceError) as e:
        sim.run(3)
    assert e.value.body_name == "stiff" and "could not meet rtol" in str(e.value) and "step 0" in str(e.value)
    assert np.array_equal(sim.x, before) and sim.steps == 0 and sim.rhs_evals == 0


# ---------------------------------------------------------------- splitting

@pytest.mark.parametrize("backend", NUMPY_SLOW)
def test_splitting_energy_stays_bounded_where_rk4_drifts(backend):
    """dt = 0.3 (|omega| dt ~ 0.35), 10^4 steps: the splitting's energy error oscillates (no secular
    growth) and L_w is conserved to rounding; RK4's energy decays steadily."""
    out = {}
    for integ in ("splitting", "rk4"):
        sim = lv.Sim(scene(), dt=0.3, integrator=integ, backend=backend)
        L0 = sim.angular_momentum_w("b")
        tr = sim.record(10_000, every=10)
        dE = energy(tr.x[:, 0]) / energy(tr.x[0, 0]) - 1
        out[integ] = dE
        if integ == "splitting":
            assert np.linalg.norm(sim.angular_momentum_w("b") - L0) <= 1e-12 * np.linalg.norm(L0)
    k = 100
    s = out["splitting"]
    assert np.max(np.abs(s[-k:])) <= 1.5 * np.max(np.abs(s[:k])) and np.max(np.abs(s)) < 1e-3
    assert abs(s[-k:].mean() - s[:k].mean()) <= 0.1 * np.max(np.abs(s))
    r = out["rk4"]
    assert r[-1] < -1e-3 and np.all(np.diff(r[::100]) < 0)  # monotone decay


def test_splitting_long_horizon_10e5_steps_c():
    sim = lv.Sim(scene(), dt=0.05, integrator="splitting", backend="c", normalize=False)
    L0 = sim.angular_momentum_w("b")
    tr = sim.record(100_000, every=100)
    dE = energy(tr.x[:, 0]) / energy(tr.x[0, 0]) - 1
    assert np.max(np.abs(dE[-100:])) <= 1.5 * np.max(np.abs(dE[:100])) < 1e-4
    assert np.max(np.abs(np.linalg.norm(tr.x[:, 0, 3:7], axis=1) - 1)) <= 1e-12  # unit by construction
    assert np.linalg.norm(sim.angular_momentum_w("b") - L0) <= 1e-11 * np.linalg.norm(L0)


# ---------------------------------------------------------------- implicit_gyro

@pytest.mark.parametrize("backend", BACKENDS)
def test_implicit_gyro_fast_major_axis_spin_never_gains_energy(backend):
    sim = lv.Sim(scene(omega_b=(0.5, 0.5, 50.0)), dt=1e-2, integrator="implicit_gyro", backend=backend)
    E0 = sim.kinetic_energy()
    tr = sim.record(1000)  # 10 s
    E = energy(tr.x[:, 0])
    assert np.all(np.isfinite(tr.x))
    assert np.all(np.diff(E) <= 1e-15 * E0)
    assert np.max(E) <= E0 * (1 + 1e-12)
    assert E[-1] > 0.999 * E0  # dissipates a little, does not collapse


@pytest.mark.parametrize("backend", BACKENDS)
def test_implicit_gyro_stays_stable_at_huge_omega_dt(backend):
    # |w| dt ~ 10: stable, but beyond implicit_gyro's validity bound (pi, attitude aliasing): the user opts in
    with pytest.raises(lv.DivergenceError, match="validity bound"):
        lv.Sim(scene(omega_b=(30.0, 200.0, 5.0)), dt=0.05, integrator="implicit_gyro", backend=backend).run(1)
    sim = lv.Sim(scene(omega_b=(30.0, 200.0, 5.0)), dt=0.05, integrator="implicit_gyro", backend=backend,
                 on_bound="warn")
    E0 = sim.kinetic_energy()
    with pytest.warns(ValidityBoundWarning, match="implicit_gyro's validity bound"):
        sim.run(2000)
    assert np.all(np.isfinite(sim.x)) and sim.kinetic_energy() <= E0 * (1 + 1e-12)
    assert abs(np.linalg.norm(sim.state("b").q) - 1) <= 1e-12


# ---------------------------------------------------------------- backends agree, counters, bad combinations

def forced_scene():
    s = lv.Scene()
    s.add_body(lv.Body("a", 2.0, (0.8, 1.0, 1.7), omega_b=(0.3, -1.0, 2.0), v_w=(1, 0, 0)))
    s.add_body(lv.Body("b", 1.0, I3, omega_b=W0))
    s.add_body(lv.Body("c", 1.5, (1.0, 1.0, 2.0), omega_b=(1.0, 1.0, 1.0)))
    s.add_effect("gravity", g_w=(0, 0, -9.81))
    s.add_effect("force_at_point", body="a", r_b=(0.1, 0.2, 0), F_w=(0, 0, 3.0))
    s.add_effect("applied_torque", body="c", torque_w=(0.1, 0.0, -0.2))
    s.add_effect("angular_damping", body="c", c=0.2)
    s.add_effect("linear_damping", body="a", c=0.3)
    return s


@pytest.mark.parametrize("integrator", ["splitting", "implicit_gyro"])
def test_c_and_numpy_agree(integrator):
    out = {}
    for backend in BACKENDS:
        sim = lv.Sim(forced_scene(), dt=1e-2, integrator=integrator, backend=backend)
        sim.run(300)
        out[backend] = sim.x.copy()
    np.testing.assert_allclose(out["c"], out["numpy"], rtol=0, atol=1e-11)


@pytest.mark.parametrize("backend", NUMPY_SLOW)
def test_splitting_with_effects_converges_at_second_order(backend):
    ref = lv.Sim(forced_scene(), dt=2.5e-4, integrator="rk4", backend=backend)
    ref.run(4000)
    errs = []
    for n in (100, 200, 400):
        sim = lv.Sim(forced_scene(), dt=1.0 / n, integrator="splitting", backend=backend)
        sim.run(n)
        errs.append(np.max(np.abs(sim.x - ref.x)))
    orders = np.log2(np.array(errs[:-1]) / np.array(errs[1:]))
    np.testing.assert_allclose(orders, 2, atol=0.15)


@pytest.mark.parametrize("backend", BACKENDS)
def test_rhs_evals_counter(backend):
    expect = {"euler": 1, "semi_implicit_euler": 1, "rk4": 4, "splitting": 1, "implicit_gyro": 1}
    for integ, k in expect.items():
        sim = lv.Sim(scene(), dt=1e-2, integrator=integ, backend=backend)
        sim.run(7)
        sim.step()
        assert sim.rhs_evals == 8 * k
    assert lv.Sim(forced_scene(), integrator="splitting", backend=backend).pipeline[0].startswith("splitting: 4 RHS")
    sim = lv.Sim(scene(), dt=0.5, integrator="dopri5", backend=backend)
    assert "adaptive" in sim.pipeline[0]
    sim.step()
    first = sim.rhs_evals
    assert first >= 8 and (first - 2) % 6 == 0  # k1 + starting-step probe + 6 per substep (FSAL)
    sim.step()
    assert (sim.rhs_evals - first) % 6 == 0  # dense output: a call continues from the carried FSAL stage
    sim.run(5)
    assert (sim.rhs_evals - first) % 6 == 0  # and so do output steps within one call
    before = sim.rhs_evals
    sim.set_state("b", omega_b=sim.state("b").omega_b * 1.001)
    sim.step()
    assert (sim.rhs_evals - before) % 6 == 1  # a written state starts afresh: k1 is evaluated again


def test_dopri5_counts_agree_between_backends_for_one_body():
    n = {}
    for backend in BACKENDS:
        sim = lv.Sim(scene(), dt=0.5, integrator="dopri5", rtol=1e-8, atol=1e-10, backend=backend)
        sim.run(4)
        n[backend] = sim.rhs_evals
    assert n["c"] == n["numpy"]


def wheel_scene(joint, wheels):
    s = lv.Scene()
    s.add_body(lv.Body("free", 1.0, I3))
    s.add_body(lv.Body.box("cube", 1.0, (0.15, 0.15, 0.15)))
    if joint:
        s.add_effect("spherical_joint", body="cube", anchor_w=[0, 0, 0.1])
    if wheels:
        s.add_effect("reaction_wheels", body="cube", J=[2e-4] * 3, torque_limit=0.2, speed_limit=400.0, c_w=0.0)
    return s


@pytest.mark.parametrize("backend", BACKENDS)
@pytest.mark.parametrize("integrator", ["splitting", "implicit_gyro"])
@pytest.mark.parametrize("joint,wheels", [(True, False), (False, True), (True, True)])
def test_plain_only_integrators_reject_joints_and_wheels(backend, integrator, joint, wheels):
    with pytest.raises(lv.LavenderInputError, match="'cube'") as e:
        lv.Sim(wheel_scene(joint, wheels), integrator=integrator, backend=backend)
    assert e.value.field == "integrator" and "rk4 or dopri5" in str(e.value)


def test_backends_reject_plain_only_integrators_with_models_directly():
    from lavendersim import backends as B

    sim = lv.Sim(wheel_scene(True, True), integrator="rk4", backend="numpy")
    for be in (B.get("numpy"), B.get("c")):
        with pytest.raises(ValueError, match="plain rigid bodies only"):
            be.advance(sim.x.copy(), sim.params, sim.effects, "splitting", True, 1e-3, 1, sim._models)
        with pytest.raises(ValueError, match="needs adaptive"):
            be.advance(sim.x.copy(), sim.params, sim.effects, "dopri5", True, 1e-3, 1, sim._models)


@pytest.mark.parametrize("kw,field", [({"rtol": 1e-6}, "rtol"), ({"atol": 1e-9}, "atol")])
def test_tolerances_only_with_the_adaptive_integrator(kw, field):
    with pytest.raises(lv.LavenderInputError) as e:
        lv.Sim(scene(), integrator="rk4", **kw)
    assert e.value.field == field and "dopri5" in str(e.value)


@pytest.mark.parametrize("kw,field", [({"rtol": 0.0}, "rtol"), ({"rtol": 1e-16}, "rtol"), ({"rtol": 2.0}, "rtol"),
                                      ({"atol": -1.0}, "atol"), ({"rtol": float("nan")}, "rtol"), ({"atol": True}, "atol")])
def test_bad_tolerances(kw, field):
    with pytest.raises(lv.LavenderInputError) as e:
        lv.Sim(scene(), integrator="dopri5", **kw)
    assert e.value.field == field
