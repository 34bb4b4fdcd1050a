"""dopri5 is one algorithm on both backends (issue 29): the NumPy backend steps each body on its own step sizes,
as C does (csrc/step.c advance_dopri5, mirrored operation for operation in backends/numpy_backend.py), so the
two agree bitwise — states, each body's step-size proposal h and its RHS count — and a body's answer does not
depend on which other bodies share its scene.

Per-body h and counts are read through the backend API (lavendersim.backends: Adaptive, get(...).advance) on
the arrays a Sim exposes (sim.x, sim.params, sim.effects); whole scenes with joints and wheels through Sim."""
import numpy as np
import pytest

import lavendersim as lv
from lavendersim import backends as B
from lavendersim.backends import numpy_backend as NB

BACKENDS = ["c", "numpy"]
RTOL, ATOL = 1e-10, 1e-12
I_ASYM = (1.0, 2.0, 3.0)
TUMBLE = (0.05, 2.0, 0.05)   # near the intermediate axis: the body flips over every ~2 s (Dzhanibekov)


def scene(bodies, effects=()):
    """bodies: (name, inertia, omega_b); effects: (name, kwargs), those on a body not in the scene left out."""
    s = lv.Scene()
    for name, I, w in bodies:
        s.add_body(lv.Body(name, 1.0, I, omega_b=w))
    for name, kw in effects:
        if kw.get("body", s.bodies and next(iter(s.bodies))) in s.bodies:
            s.add_effect(name, **kw)
    return s


RATES = [("slow", I_ASYM, (1e-3, 2e-3, 0.0)), ("tumble", I_ASYM, TUMBLE), ("mid", (2.0, 2.5, 3.0), (1.0, 0.5, 0.2)),
         ("fast", (1.0, 1.5, 2.2), (30.0, -10.0, 5.0))]
LOADS = [("gravity", {"g_w": (0, 0, -9.81)}), ("angular_damping", {"body": "mid", "c": 0.3}),
         ("angular_damping", {"body": "fast", "c": 0.05}),
         ("force_at_point", {"body": "tumble", "r_b": (0.2, 0, 0), "F_w": (0, 1.0, 0)})]


def advance(s, backend, n, dt=0.25, calls=1):
    """The scene's bodies advanced by `calls` backend calls of n output steps of dt: (state, h, nfev)."""
    sim = lv.Sim(s, dt=dt, integrator="dopri5", rtol=RTOL, atol=ATOL, backend=backend)
    x = sim.x.copy()
    ad = B.Adaptive(RTOL, ATOL, x.shape[0])
    for _ in range(calls):
        B.get(backend).advance(x, sim.params, sim.effects, "dopri5", sim.normalize, dt, n, None, ad)
    return x, ad.h, ad.nfev


@pytest.mark.parametrize("bodies, effects", [
    ([("b", I_ASYM, TUMBLE)], []),
    (RATES, []),
    (RATES, LOADS),
], ids=["tumbling", "rates", "rates+effects"])
def test_c_and_numpy_agree_bitwise_per_body(bodies, effects):
    """2 s at rtol 1e-10 (8 output steps of 0.25 s, in two calls: the proposal is carried, FSAL restarts):
    the states, each body's h and RHS count are the same doubles on both backends (so within 1e-12)."""
    out = {b: advance(scene(bodies, effects), b, 4, calls=2) for b in BACKENDS}
    (xc, hc, nc), (xn, hn, nn) = out["c"], out["numpy"]
    assert np.max(np.abs(xc - xn)) <= 1e-12
    assert np.array_equal(xc, xn) and np.array_equal(hc, hn) and np.array_equal(nc, nn)
    assert np.all(nn > 0) and np.all(hn > 0)
    if len(bodies) > 1:   # each body its own step sizes: the slow body spends a fraction of the fast one's work
        assert nn[0] * 10 < nn[-1] and hn[0] > 10 * hn[-1]


def test_powers_by_math_pow_give_the_same_numbers(monkeypatch):
    """The controller's powers through math.pow (the path taken where NumPy's power is not libm's pow): C = NumPy
    bitwise all the same."""
    monkeypatch.setattr(NB, "_numpy_power_is_libm", lambda p: False)
    out = {b: advance(scene(RATES, LOADS), b, 4) for b in BACKENDS}
    for a, b in zip(out["c"], out["numpy"]):
        assert np.array_equal(a, b)


def test_tumbling_body_meets_its_tolerance_through_the_flip():
    """The tumbling body against a fine RK4 (2 s, dt 1e-4: its error ~1e-14): within 1e-8 on both backends."""
    s = scene([("b", I_ASYM, TUMBLE)])
    rk = lv.Sim(s, dt=1e-4, integrator="rk4", backend="c")
    rk.run(20000)
    for backend in BACKENDS:
        x = advance(s, backend, 8)[0]
        np.testing.assert_allclose(x, rk.x, rtol=0, atol=1e-8)


def wheel_scene():
    s = scene(RATES[:2], LOADS[:1])
    s.add_body(lv.Body.box("cube", 1.0, (0.15, 0.15, 0.15), omega_b=(0.3, -0.2, 0.5)))
    s.add_effect("spherical_joint", body="cube", anchor_w=[0, 0, 0.1])
    s.add_effect("reaction_wheels", body="cube", J=[2e-4, 3e-4, 2.5e-4], torque_limit=0.2, speed_limit=400.0,
                 c_w=0.01)
    s.add_effect("angular_damping", body="cube", c=0.02)
    return s


def test_c_and_numpy_agree_bitwise_with_a_jointed_wheeled_body():
    """A jointed cube with three wheels (commands changed between calls: each output step re-evaluates its first
    stage) beside plain bodies, 2 s: states, wheel rates, applied torques and the RHS count agree bitwise."""
    out = {}
    for backend in BACKENDS:
        sim = lv.Sim(wheel_scene(), dt=0.1, integrator="dopri5", rtol=RTOL, atol=ATOL, backend=backend)
        sim.set_wheel_command("cube", [0.001, -0.002, 0.0])
        sim.run(10)
        sim.set_wheel_command("cube", [-0.003, 0.0, 0.002])
        sim.run(10)
        out[backend] = (sim.x.copy(), sim.wheel_rates("cube"), sim.wheel_torques_applied.copy(), sim.rhs_evals)
    (xc, Wc, uc, nc), (xn, Wn, un, nn) = out["c"], out["numpy"]
    assert np.max(np.abs(xc - xn)) <= 1e-12
    assert np.array_equal(xc, xn) and np.array_equal(Wc, Wn) and np.array_equal(uc, un) and nc == nn
    assert np.any(Wn != 0.0)


def test_a_body_does_not_depend_on_its_neighbours():
    """NumPy: a body alone == the same body beside a fast spinner and other loaded bodies (listed before and after
    it), bitwise, with its own h and count; and a plain body beside a wheeled one == alone (the extended state)."""
    me = ("me", I_ASYM, TUMBLE)
    alone = advance(scene([me], LOADS[:1]), "numpy", 4, calls=2)
    for bodies in ([me, RATES[3]], [RATES[3], RATES[0], me, RATES[2]]):
        x, h, n = advance(scene(bodies, LOADS[:3]), "numpy", 4, calls=2)
        i = [b[0] for b in bodies].index("me")
        assert np.array_equal(x[i], alone[0][0]) and h[i] == alone[1][0] and n[i] == alone[2][0]
        assert n[[b[0] for b in bodies].index("fast")] > 10 * n[i]
    # beside a jointed wheeled cube (the plain body then steps in the [x, Omega] rows)
    sims = {}
    for name, s in (("alone", scene(RATES[:1], LOADS[:1])), ("beside", wheel_scene())):
        sims[name] = lv.Sim(s, dt=0.1, integrator="dopri5", rtol=RTOL, atol=ATOL, backend="numpy")
        sims[name].run(10)
    assert np.array_equal(sims["alone"].state("slow").omega_b, sims["beside"].state("slow").omega_b)
    assert np.array_equal(sims["alone"].state("slow").q, sims["beside"].state("slow").q)
    assert np.array_equal(sims["alone"].state("slow").p_w, sims["beside"].state("slow").p_w)


def test_many_bodies_agree_bitwise():
    """40 random bodies (rates over 4 decades, inertias, some damped): C = NumPy bitwise (states, h, counts)."""
    rng = np.random.default_rng(29)
    bodies, effects = [], [("gravity", {"g_w": (0, 0, -9.81)})]
    for i in range(40):
        I = np.sort(rng.uniform(1.0, 1.9, 3))
        bodies.append((f"b{i}", tuple(I), tuple(rng.normal(size=3) * 10 ** rng.uniform(-2, 1.3))))
        if i % 3 == 0:
            effects.append(("angular_damping", {"body": f"b{i}", "c": float(rng.uniform(0.01, 1.0))}))
    out = {b: advance(scene(bodies, effects), b, 3, dt=0.2, calls=2) for b in BACKENDS}
    for a, b in zip(out["c"], out["numpy"]):
        assert np.array_equal(a, b)
    assert np.ptp(out["numpy"][2]) > 0   # the counts differ between bodies


@pytest.mark.parametrize("order", [("stiff", "calm"), ("calm", "stiff")])
def test_a_failure_is_named_alike(order):
    """A body that cannot meet the tolerance: both backends raise the same DivergenceError (step, body, cause)
    whichever its index, and leave the Sim as it was."""
    errs = {}
    for backend in BACKENDS:
        s = scene([(n, I_ASYM, (1.0, 0.5, 0.2)) for n in order],
                  [("angular_damping", {"body": "stiff", "c": 1e14})])
        sim = lv.Sim(s, dt=1.0, integrator="dopri5", backend=backend)
        before = sim.x.copy()
        with pytest.raises(lv.DivergenceError) as e:
            sim.run(3)
        assert np.array_equal(sim.x, before) and sim.rhs_evals == 0
        errs[backend] = (e.value.step, e.value.body_name, str(e.value))
    assert errs["c"] == errs["numpy"] and errs["c"][1] == "stiff" and "could not meet rtol" in errs["c"][2]


def test_an_output_interval_forces_no_substep():
    """Dense output (issue 30): 2 s of the tumbling body at rtol 1e-10 with an output interval of 0.01 s, by run(200)
    and by 200 step() calls, takes the substeps of dt = 2 s (the outputs are read off the Dormand-Prince continuous
    extension): the same RHS count, on both backends; run(200) and the 200 steps agree bitwise; every state within
    1e-8 of a fine RK4. (Before: every output step clipped a substep and restarted FSAL, ~3.5x the evaluations.)"""
    s = scene([("b", I_ASYM, TUMBLE)])
    rk = lv.Sim(s, dt=1e-4, integrator="rk4", backend="c")
    rk.run(20000)
    kw = dict(integrator="dopri5", rtol=RTOL, atol=ATOL)
    for backend in BACKENDS:
        one = lv.Sim(s, dt=2.0, backend=backend, **kw)
        one.run(1)
        fine = lv.Sim(s, dt=0.01, backend=backend, **kw)
        fine.run(200)
        steps = lv.Sim(s, dt=0.01, backend=backend, **kw)
        for _ in range(200):
            steps.step()
        assert fine.rhs_evals == one.rhs_evals == steps.rhs_evals
        assert np.array_equal(steps.x, fine.x)
        for sim in (one, fine):
            np.testing.assert_allclose(sim.x, rk.x, rtol=0, atol=1e-8)


def test_a_written_state_starts_afresh():
    """The dense output carries on only while a body's state is the one the last call wrote: a body whose state was
    written steps on exactly as with its dense output dropped (Adaptive.forget), the others as if nothing was
    written (bitwise, both backends)."""
    s = scene(RATES[:2], LOADS[1:2])
    for backend in BACKENDS:
        sim = lv.Sim(s, dt=0.25, integrator="dopri5", rtol=RTOL, atol=ATOL, backend=backend)
        x = sim.x.copy()
        ad = B.Adaptive(RTOL, ATOL, x.shape[0])
        be = B.get(backend)
        be.advance(x, sim.params, sim.effects, "dopri5", sim.normalize, 0.25, 3, None, ad)
        runs = {}
        for name, write, forget in (("written", True, False), ("forgotten", True, True), ("as is", False, False)):
            xa, a = x.copy(), B.Adaptive(RTOL, ATOL, x.shape[0])
            a.load(ad.save())
            if write:
                xa[0, 10] += 1e-3
            if forget:
                a.forget()
            be.advance(xa, sim.params, sim.effects, "dopri5", sim.normalize, 0.25, 3, None, a)
            runs[name] = (xa, a.nfev)
        assert np.array_equal(runs["written"][0][0], runs["forgotten"][0][0])
        assert runs["written"][1][0] == runs["forgotten"][1][0]
        assert np.array_equal(runs["written"][0][1], runs["as is"][0][1])
        assert not np.array_equal(runs["written"][0][1], runs["forgotten"][0][1])


def test_a_pickled_sim_steps_on_bitwise():
    """The dense output is part of what a Sim pickles (and what a failed call restores): a copy taken mid-run
    continues bitwise."""
    import pickle
    for backend in BACKENDS:
        sim = lv.Sim(scene(RATES[:2]), dt=0.1, integrator="dopri5", rtol=RTOL, atol=ATOL, backend=backend)
        sim.run(3)
        twin = pickle.loads(pickle.dumps(sim))
        sim.run(4)
        twin.run(4)
        assert np.array_equal(sim.x, twin.x) and sim.rhs_evals == twin.rhs_evals


def test_without_a_carried_dense_output_each_call_starts_afresh():
    """Adaptive(dense=False) carries nothing between calls: each call starts every body afresh from its state (as a
    carried dense output that is forgotten after each call), C = NumPy bitwise (states, h, counts)."""
    s = scene(RATES, LOADS)
    out = {}
    for backend in BACKENDS:
        sim = lv.Sim(s, dt=0.25, integrator="dopri5", rtol=RTOL, atol=ATOL, backend=backend)
        runs = []
        for dense in (False, True):
            x, ad = sim.x.copy(), B.Adaptive(RTOL, ATOL, sim.x.shape[0], dense=dense)
            for _ in range(2):
                B.get(backend).advance(x, sim.params, sim.effects, "dopri5", sim.normalize, 0.25, 3, None, ad)
                ad.forget()
            runs.append((x, ad.h, ad.nfev))
        for a, b in zip(*runs):
            assert np.array_equal(a, b)
        out[backend] = runs[0]
    for a, b in zip(out["c"], out["numpy"]):
        assert np.array_equal(a, b)
    assert np.all(out["c"][2] > 0)
