"""Sim(..., dtype="float32"): the single-precision printing of the kernels (generated/kernels_f32.c,
generated/kernels_numpy_f32.py) stepped by csrc/step_f32.c (the fixed_loop.h template in float) and by the
NumPy backend on float32 arrays.

Stated tolerance (what float32 gives, checked here): after n steps every state number is within
TOL_PER_STEP * n * (1 + |x|) of the float64 run's (float32 rounds at ~6e-8 per operation; the measured
drift of these scenes is 0.5e-8 .. 7e-8 per step and unit, so the bound has a margin of ~3x over the worst);
C and NumPy agree bitwise in float32 (the same expressions, the same order, no FMA, no promotion to double).
"""
from __future__ import annotations

import numpy as np
import pytest

import lavendersim as lv
from lavendersim.errors import DivergenceError
from lavendersim.validate import LavenderInputError

TOL_PER_STEP = 2e-7
INTEGRATORS = ("euler", "semi_implicit_euler", "rk4")


def _scene(n: int = 5, effects: bool = True, seed: int = 1) -> lv.Scene:
    rng = np.random.default_rng(seed)
    s = lv.Scene()
    for i in range(n):
        q = rng.normal(size=4)
        s.add_body(lv.Body.box(f"b{i}", mass=1.0 + i, size=(0.8, 0.3 + 0.1 * i, 0.2), q=q / np.linalg.norm(q),
                               omega_b=rng.normal(size=3), v_w=rng.normal(size=3)))
    if effects:
        s.add_effect("applied_torque", body="b1", torque_w=[0, 0, 0.02])
        s.add_effect("gravity", g_w=[0, 0, -9.81])
        s.add_effect("angular_damping", body="b2", c=0.01)
        s.add_effect("linear_damping", body="b3", c=0.1)
        s.add_effect("force_at_point", body="b4", r_b=[0.1, 0, 0], F_w=[0, 1, 0])
    return s


def _run(scene, integrator, backend, dtype, n, dt=1e-3):
    sim = lv.Sim(scene, dt=dt, integrator=integrator, backend=backend, dtype=dtype)
    sim.run(n)
    return sim


@pytest.mark.parametrize("integrator", INTEGRATORS)
@pytest.mark.parametrize("effects", [False, True])
def test_c_and_numpy_float32_bitwise(integrator, effects):
    """Both backends compute the same float32 bits (5 bodies, every built-in effect when effects)."""
    sc = _scene(effects=effects)
    a = _run(sc, integrator, "c", "float32", 300).x
    b = _run(sc, integrator, "numpy", "float32", 300).x
    assert a.dtype == b.dtype == np.float32
    np.testing.assert_array_equal(a, b)


@pytest.mark.parametrize("integrator", INTEGRATORS)
@pytest.mark.parametrize("effects", [False, True])
def test_float32_within_tolerance_of_float64(integrator, effects):
    """float32 tracks float64 within TOL_PER_STEP * n * (1 + |x|), and it is really float32 (not float64:
    the difference is above float64 rounding)."""
    n = 2000
    sc = _scene(effects=effects)
    x32 = _run(sc, integrator, "c", "float32", n).x.astype(np.float64)
    x64 = _run(sc, integrator, "c", "float64", n).x
    err = np.abs(x32 - x64)
    assert np.all(err <= TOL_PER_STEP * n * (1 + np.abs(x64))), float((err / (1 + np.abs(x64))).max() / n)
    assert err.max() > 1e-9


def test_float32_torque_free_long_run_keeps_invariants():
    """A torque-free tumbling box, 10^4 rk4 steps in float32: energy and |L| within 1e-4 relative of the
    float64 run's (which conserves them to ~1e-10 here)."""
    s = lv.Scene()
    s.add_body(lv.Body.box("box", mass=2.0, size=(0.8, 0.4, 0.2), omega_b=[0.1, 3.0, 0.05]))
    sims = {d: _run(s, "rk4", "c", d, 10_000) for d in ("float32", "float64")}
    E = {d: sims[d].kinetic_energy() for d in sims}
    L = {d: np.linalg.norm(sims[d].angular_momentum_w("box")) for d in sims}
    assert abs(E["float32"] / E["float64"] - 1) < 1e-4
    assert abs(L["float32"] / L["float64"] - 1) < 1e-4


@pytest.mark.parametrize("backend", ["c", "numpy"])
def test_float32_state_dtype(backend):
    sim = lv.Sim(_scene(), dt=1e-3, integrator="rk4", backend=backend, dtype="float32")
    assert sim.dtype == "float32"
    for view in (sim.x, sim.p_w, sim.q, sim.v_w, sim.omega_b):
        assert view.dtype == np.float32
    st = sim.state("b0")
    assert st.q.dtype == np.float32 and st.omega_b.dtype == np.float32
    tr = sim.record(20, every=10)
    assert tr.x.dtype == np.float32 and tr.x.shape == (3, 5, 13)
    sim.set_state("b0", omega_b=[0.1, 0.2, 0.3])
    assert sim.x.dtype == np.float32
    np.testing.assert_array_equal(sim.omega_b[0], np.float32([0.1, 0.2, 0.3]))
    assert lv.Sim(_scene(), dt=1e-3, backend=backend).x.dtype == np.float64   # the default


def test_dtype_accepts_numpy_types():
    assert lv.Sim(_scene(), dt=1e-3, dtype=np.float32).dtype == "float32"
    assert lv.Sim(_scene(), dt=1e-3, dtype=np.dtype("float64")).dtype == "float64"


@pytest.mark.parametrize("bad", ["float16", "double", 3, None])
def test_dtype_bad_value(bad):
    with pytest.raises(LavenderInputError, match="dtype"):
        lv.Sim(_scene(), dt=1e-3, dtype=bad)


@pytest.mark.parametrize("integrator", ["dopri5", "splitting", "implicit_gyro", "splitting4", "rk4_expmap", "symtop4"])
def test_float32_unsupported_integrator_rejected(integrator):
    with pytest.raises(LavenderInputError, match="dtype.*float32 steps euler, semi_implicit_euler, rk4 only"):
        lv.Sim(_scene(effects=False), dt=1e-3, integrator=integrator, dtype="float32")


def test_float32_wheels_and_joint_rejected():
    s = lv.Scene()
    s.add_body(lv.Body.box("cube", mass=1.0, size=(0.2, 0.2, 0.2)))
    s.add_effect("reaction_wheels", body="cube", J=[1e-4] * 3, torque_limit=0.1, speed_limit=300.0)
    with pytest.raises(LavenderInputError, match="dtype.*plain rigid bodies only.*'cube'"):
        lv.Sim(s, dt=1e-3, dtype="float32")
    s = lv.Scene()
    s.add_body(lv.Body.box("rod", mass=1.0, size=(0.8, 0.1, 0.1), p_w=[0.4, 0, 0]))
    s.add_effect("spherical_joint", body="rod", anchor_w=[0, 0, 0])
    with pytest.raises(LavenderInputError, match="dtype"):
        lv.Sim(s, dt=1e-3, dtype="float32")


@pytest.mark.parametrize("backend", ["c", "numpy"])
def test_float32_overflow_is_a_divergence(backend):
    """A force that overflows float32 (not float64) in a few steps: DivergenceError naming the step and body,
    and the Sim left as before the call."""
    s = lv.Scene()
    s.add_body(lv.Body.box("calm", mass=1.0, size=(0.2, 0.2, 0.2)))
    s.add_body(lv.Body.box("pushed", mass=1.0, size=(0.2, 0.2, 0.2)))
    s.add_effect("force_at_point", body="pushed", r_b=[0, 0, 0], F_w=[1e38, 0, 0])
    sim = lv.Sim(s, dt=1.0, integrator="euler", backend=backend, dtype="float32")
    before = sim.x.copy()
    with pytest.raises(DivergenceError) as e:
        sim.run(10)
    assert e.value.body == 1 and e.value.step == 3   # v = 1e38, 2e38, 3e38, then 4e38 > float32 max
    np.testing.assert_array_equal(sim.x, before)
    assert sim.steps == 0
    sim64 = lv.Sim(s, dt=1.0, integrator="euler", backend=backend)
    sim64.run(10)   # float64 holds it


def test_float32_numpy_kernels_stay_float32():
    """Every kernel of generated/kernels_numpy_f32.py returns float32 for float32 inputs (no temporary promoted to
    float64 by a literal), and the kernels the float32 step uses agree with the float64 printing to float32
    rounding (relative 1e-5) on random inputs."""
    from lavendersim.generated import kernels_numpy as K64
    from lavendersim.generated import kernels_numpy_f32 as K32

    rng = np.random.default_rng(3)
    assert set(K32.KERNELS) == set(K64.KERNELS)
    for name, (fn, ins, _outs) in K32.KERNELS.items():
        args = [rng.uniform(0.5, 1.5, size=(7,) + tuple(shape)).astype(np.float32) for _, shape in ins]
        with np.errstate(all="ignore"):
            out32 = fn(*args)
            out64 = K64.KERNELS[name][0](*[a.astype(np.float64) for a in args])
        out32 = out32 if isinstance(out32, tuple) else (out32,)
        out64 = out64 if isinstance(out64, tuple) else (out64,)
        for a, b in zip(out32, out64):
            assert a.dtype == np.float32, name
            if name in ("rigid_body_rhs_free", "rigid_body_rhs", "quat_normalize", "translation_drift",
                        "quat_derivative_body", "effect_applied_torque", "effect_force_at_point", "effect_gravity",
                        "effect_linear_damping", "effect_angular_damping"):
                np.testing.assert_allclose(a, b, rtol=1e-5, atol=1e-6, err_msg=name)


@pytest.mark.parametrize("normalize", [True, False])
@pytest.mark.parametrize("integrator", INTEGRATORS)
def test_float32_tiles_bitwise_numpy(integrator, normalize):
    """The float32 C tiles (torque-free, constant torque, constant force and torque, state-reading effects;
    Euler coefficients once per call, coefficient kernels in the stages) give the NumPy float32 bits: random
    bodies, 83 of them (not a multiple of the 16 float lanes), each kind interleaved with the others."""
    rng = np.random.default_rng(7)
    s = lv.Scene()
    for i in range(83):
        q = rng.normal(size=4)
        s.add_body(lv.Body.box(f"b{i}", mass=rng.uniform(0.5, 3.0), size=rng.uniform(0.1, 1.0, size=3),
                               q=q / np.linalg.norm(q), omega_b=rng.normal(size=3) * 3, v_w=rng.normal(size=3)))
        kind = i % 5
        if kind == 1:
            s.add_effect("applied_torque", body=f"b{i}", torque_w=rng.normal(size=3) * 0.1)
        elif kind == 2:
            s.add_effect("gravity", body=f"b{i}", g_w=[0, 0, -9.81])
            s.add_effect("applied_torque", body=f"b{i}", torque_w=rng.normal(size=3) * 0.1)
        elif kind == 3:
            s.add_effect("angular_damping", body=f"b{i}", c=0.05)
    out = []
    for backend in ("c", "numpy"):
        sim = lv.Sim(s, dt=2e-3, integrator=integrator, backend=backend, dtype="float32", normalize=normalize)
        sim.run(150)
        out.append(sim.x.copy())
    np.testing.assert_array_equal(out[0], out[1])


def test_float32_screen_passes_only_inside_margin():
    """checks_pass (csrc/fast_step.c) on a float32 state, the C screen of a float32 Sim's per-chunk checks:
    passes a state well inside its limits, refuses one at its limits (it passes only what is 1e-5 inside: the
    NumPy check of a float32 state rounds some intermediates to float32), and fails where the float64 screen
    of the same numbers fails."""
    from lavendersim.generated import layout as LY
    from lavendersim.backends import c_backend
    from lavendersim.generated import kernels_numpy as K

    sim = lv.Sim(_scene(effects=False), dt=1e-3, backend="c", dtype="float32")
    x32, params = sim.x.copy(), sim.params
    x64 = x32.astype(np.float64)
    nb = len(x32)
    E = K.kinetic_energy(params[:, LY.PARAM_M], params[:, LY.PARAM_I_B], x64[:, LY.STATE_V_W], x64[:, LY.STATE_OMEGA_B])
    L2 = np.sum(K.body_momentum(params[:, LY.PARAM_I_B], x64[:, LY.STATE_OMEGA_B]) ** 2, axis=1)
    w = np.linalg.norm(x64[:, LY.STATE_OMEGA_B], axis=1)
    scale = np.ones(nb)
    check = c_backend._c.checks_pass

    def growth(fE, fL):
        return np.ascontiguousarray(np.stack([np.zeros(nb), E * fE, L2 * fL], axis=1))

    assert check(x32, params, scale, float(w.max()) * 2, growth(2.0, 2.0))
    assert check(x64, params, scale, float(w.max()) * 2, growth(2.0, 2.0))
    assert not check(x32, params, scale, float(w.max()) * 2, growth(1.0 + 1e-7, 2.0))   # inside, but not by 1e-5
    assert not check(x32, params, scale, float(w.max()) * 2, growth(2.0, 1.0 + 1e-7))
    assert not check(x32, params, scale, float(w.max()) * (1 + 1e-7), growth(2.0, 2.0))
    assert not check(x32, params, scale, float(w.max()) * 2, growth(0.5, 2.0))
    assert not check(x64, params, scale, float(w.max()) * 2, growth(0.5, 2.0))
    # the no-work rate (column 0): at or under it (shrunk by 1e-5 for float32) E and |L| are not evaluated
    def with_rate(rate, fE):
        g = growth(fE, 2.0)
        g[:, 0] = rate
        return g
    assert check(x32, params, scale, float(w.max()) * 2, with_rate(w * (1 + 2e-5), 0.5))    # skipped: passes
    assert not check(x32, params, scale, float(w.max()) * 2, with_rate(w * (1 + 2e-6), 0.5))  # evaluated: fails
    assert check(x64, params, scale, float(w.max()) * 2, with_rate(w * (1 + 2e-6), 0.5))
    bad = x32.copy()
    bad[0, LY.STATE_OMEGA_B] = np.nan
    assert not check(bad, params, scale, np.inf, growth(np.inf, np.inf))
    with pytest.raises(ValueError):
        check(x32.astype(np.float16), params, scale, 1.0, growth(2.0, 2.0))
