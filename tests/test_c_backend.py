"""The compiled backend (lavendersim._lavender_c + lavendersim.backends.c_backend) against a plain
reference written here with the generated NumPy kernels, one body and one step at a time."""
from __future__ import annotations

import importlib
import re
import shutil

import numpy as np
import pytest

from lavendersim.errors import DivergenceError, StaleBuildError
from lavendersim.generated import kernels_numpy as K

from lavendersim.backends import c_backend  # required, never skipped: `pip install -e .` builds it
_c = c_backend._c
CBackend = c_backend.CBackend

INTEGRATORS = ("euler", "semi_implicit_euler", "rk4")
TOL = 1e-12


# ---------------------------------------------------------------- reference (straightforward, per body)

def ref_rhs(x, prm, effects, b):
    m, I = prm[0], prm[1:4]
    mine = [e for e in effects if int(e[1]) in (-1, b)]
    if not mine:
        return K.rigid_body_rhs_free(x, I)
    F, tau, tau_b = np.zeros(3), np.zeros(3), np.zeros(3)
    # the effect contract: angular damping declares its torque in the body frame; a body whose torques are all
    # body-frame takes them so (nothing rotated), else as the world torque R tau_b
    body_frame = not any(int(e[0]) in (1, 2) for e in mine)
    for e in mine:
        kind, p = int(e[0]), e[2:8]
        if kind == 1:
            tau = tau + p[0:3]
        elif kind == 2:
            F = F + p[3:6]
            tau = tau + K.force_at_point(x[3:7], p[0:3], p[3:6])
        elif kind == 3:
            F = F + K.effect_gravity(m, p[0:3])
        elif kind == 4:
            F = F + K.effect_linear_damping(x[7:10], p[0])
        elif kind == 5 and body_frame:
            tau_b = tau_b - p[0] * x[10:13]
        elif kind == 5:
            tau = tau + K.effect_angular_damping(x[3:7], x[10:13], p[0])
        else:
            raise AssertionError(kind)
    xd = K.rigid_body_rhs(x, m, I, F, tau)
    xd[10:13] += tau_b / I
    return xd


def ref_step(x, prm, effects, b, integrator, normalize, dt):
    f = lambda y: ref_rhs(y, prm, effects, b)  # noqa: E731
    if integrator == "euler":
        xn = x + dt * f(x)
    elif integrator == "semi_implicit_euler":
        k = f(x)
        xn = x.copy()
        xn[7:13] = x[7:13] + dt * k[7:13]
        xn[0:3] = x[0:3] + dt * xn[7:10]
        xn[3:7] = x[3:7] + dt * K.quat_derivative_body(x[3:7], xn[10:13])
    else:
        k1 = f(x)
        k2 = f(x + dt / 2 * k1)
        k3 = f(x + dt / 2 * k2)
        k4 = f(x + dt * k3)
        xn = x + dt / 6 * (k1 + 2 * k2 + 2 * k3 + k4)
    if normalize:
        xn[3:7] = xn[3:7] / np.sqrt(np.sum(xn[3:7] ** 2))
    return xn


def ref_advance(state, params, effects, integrator, normalize, dt, n_steps):
    out = state.copy()
    for b in range(state.shape[0]):
        x = state[b].copy()
        for _ in range(n_steps):
            x = ref_step(x, params[b], effects, b, integrator, normalize, dt)
        out[b] = x
    return out


def random_bodies(rng, nb):
    state = np.zeros((nb, 13))
    state[:, 0:3] = rng.uniform(-1, 1, (nb, 3))
    q = rng.normal(size=(nb, 4))
    state[:, 3:7] = q / np.linalg.norm(q, axis=1, keepdims=True)
    state[:, 7:10] = rng.uniform(-1, 1, (nb, 3))
    state[:, 10:13] = rng.uniform(-3, 3, (nb, 3))
    params = np.column_stack([rng.uniform(0.5, 2, nb), rng.uniform(0.5, 1, nb),
                              rng.uniform(1, 1.5, nb), rng.uniform(1.5, 2, nb)])
    return state, params


def effect(kind, body, *p):
    row = np.zeros(8)
    row[0], row[1] = kind, body
    row[2:2 + len(p)] = p
    return row


EFFECTS = {
    "none": [],
    "applied_torque": [effect(1, -1, 0.3, -0.2, 0.5)],
    "force_at_point": [effect(2, 0, 0.1, 0.2, -0.3, 1.0, -2.0, 0.5), effect(2, 1, -0.2, 0.0, 0.4, 0.0, 0.0, 3.0)],
    "gravity": [effect(3, -1, 0.0, 0.0, -9.81)],
    "linear_damping": [effect(4, 1, 0.7)],
    "angular_damping": [effect(5, -1, 0.4)],
    "all": [effect(3, -1, 0, 0, -9.81), effect(1, 0, 0.1, 0.2, 0.3), effect(5, 1, 0.2),
            effect(2, 0, 0.1, 0, 0, 0, 1, 0), effect(4, -1, 0.3), effect(1, 0, -0.05, 0, 0.02)],
}


def effects_array(name):
    rows = EFFECTS[name]
    return np.array(rows, dtype=np.float64).reshape(len(rows), 8)


# ---------------------------------------------------------------- agreement with the reference

@pytest.mark.parametrize("effects_name", list(EFFECTS))
@pytest.mark.parametrize("integrator", INTEGRATORS)
@pytest.mark.parametrize("normalize", [True, False])
def test_matches_reference(integrator, effects_name, normalize):
    rng = np.random.default_rng(42)
    state, params = random_bodies(rng, 3)  # body 2 has no effect in several sets: the free path
    effects = effects_array(effects_name)
    want = ref_advance(state, params, effects, integrator, normalize, 0.01, 25)
    got = state.copy()
    CBackend().advance(got, params, effects, integrator, normalize, 0.01, 25)
    scale = max(1.0, np.max(np.abs(want)))
    assert np.max(np.abs(got - want)) <= TOL * scale
    assert not np.array_equal(got, state)


def test_effects_change_the_motion():
    """Each effect kind actually acts (so the comparisons above are not vacuously free motion)."""
    rng = np.random.default_rng(3)
    state, params = random_bodies(rng, 2)
    free = state.copy()
    CBackend().advance(free, params, effects_array("none"), "rk4", True, 0.01, 10)
    for name in ("applied_torque", "force_at_point", "gravity", "linear_damping", "angular_damping"):
        s = state.copy()
        CBackend().advance(s, params, effects_array(name), "rk4", True, 0.01, 10)
        assert np.max(np.abs(s - free)) > 1e-6, name


def test_effect_order_and_targeting():
    rng = np.random.default_rng(5)
    state, params = random_bodies(rng, 4)
    eff = np.array([effect(1, 2, 1.0, 0, 0), effect(3, 3, 0, 0, -1)])
    got = state.copy()
    CBackend().advance(got, params, eff, "rk4", True, 0.01, 5)
    untouched = state[[0, 1]].copy()
    CBackend().advance(untouched, params[[0, 1]], np.zeros((0, 8)), "rk4", True, 0.01, 5)
    np.testing.assert_array_equal(got[[0, 1]], untouched)  # free kernel: bit-identical


def test_many_bodies_equal_separate_calls():
    rng = np.random.default_rng(7)
    state, params = random_bodies(rng, 50)
    eff = effects_array("all")  # targets bodies 0 and 1 specifically, the rest via -1
    for integrator in INTEGRATORS:
        together = state.copy()
        CBackend().advance(together, params, eff, integrator, True, 0.005, 40)
        for b in range(state.shape[0]):
            one = state[b:b + 1].copy()
            # re-target this body's effects to index 0 in a one-body call
            e = eff.copy()
            keep = (e[:, 1] == -1) | (e[:, 1] == b)
            e = e[keep]
            e[:, 1] = np.where(e[:, 1] == -1, -1, 0)
            CBackend().advance(one, params[b:b + 1], e, integrator, True, 0.005, 40)
            np.testing.assert_array_equal(together[b], one[0])


def test_one_call_equals_many_calls():
    rng = np.random.default_rng(8)
    state, params = random_bodies(rng, 5)
    eff = effects_array("all")
    a, b = state.copy(), state.copy()
    CBackend().advance(a, params, eff, "rk4", True, 0.01, 30)
    for _ in range(30):
        CBackend().advance(b, params, eff, "rk4", True, 0.01, 1)
    np.testing.assert_array_equal(a, b)


def test_zero_steps_and_zero_bodies():
    rng = np.random.default_rng(9)
    state, params = random_bodies(rng, 3)
    s = state.copy()
    CBackend().advance(s, params, effects_array("gravity"), "rk4", True, 0.01, 0)
    np.testing.assert_array_equal(s, state)
    empty = np.zeros((0, 13))
    CBackend().advance(empty, np.zeros((0, 4)), np.zeros((0, 8)), "euler", False, 0.01, 10)


# ---------------------------------------------------------------- normalization

@pytest.mark.parametrize("integrator", INTEGRATORS)
def test_normalize_on_off(integrator):
    rng = np.random.default_rng(11)
    state, params = random_bodies(rng, 4)
    on, off = state.copy(), state.copy()
    CBackend().advance(on, params, np.zeros((0, 8)), integrator, True, 0.02, 200)
    CBackend().advance(off, params, np.zeros((0, 8)), integrator, False, 0.02, 200)
    n_on = np.linalg.norm(on[:, 3:7], axis=1)
    n_off = np.linalg.norm(off[:, 3:7], axis=1)
    assert np.max(np.abs(n_on - 1)) <= 4e-16
    assert np.max(np.abs(n_off - 1)) > 1e-12  # drift left in place without normalization
    if integrator != "rk4":  # explicit-form steps only ever lengthen q
        assert np.all(n_off > 1)
    want = ref_advance(state, params, np.zeros((0, 8)), integrator, False, 0.02, 200)
    assert np.max(np.abs(off - want)) <= TOL * max(1.0, np.max(np.abs(want)))


# ---------------------------------------------------------------- divergence

def diverging_setup():
    rng = np.random.default_rng(13)
    state, params = random_bodies(rng, 3)
    state[1, 10:13] = [300.0, 200.0, 100.0]  # only body 1 blows up under explicit Euler
    return state, params


def test_divergence_raises_and_restores():
    state, params = diverging_setup()
    s = state.copy()
    with pytest.raises(DivergenceError) as info:
        CBackend().advance(s, params, effects_array("angular_damping"), "euler", False, 0.05, 200)
    err = info.value
    assert isinstance(err, FloatingPointError)
    assert err.body == 1
    assert 0 <= err.step < 200
    np.testing.assert_array_equal(s, state)  # nothing half-applied (body 0 was advanced, then restored)
    msg = str(err)
    assert f"step {err.step}" in msg and "body 1" in msg
    # the step index is exact: err.step steps are fine, one more diverges
    ok = state.copy()
    CBackend().advance(ok, params, effects_array("angular_damping"), "euler", False, 0.05, err.step)
    assert np.all(np.isfinite(ok))
    with pytest.raises(DivergenceError) as again:
        CBackend().advance(ok, params, effects_array("angular_damping"), "euler", False, 0.05, 1)
    assert again.value.step == 0 and again.value.body == 1
    assert "omega" in str(again.value) and "euler" in str(again.value)


@pytest.mark.parametrize("dtype", ["float64", "float32"])
def test_divergence_without_restore_names_the_step_and_leaves_the_arrays(dtype):
    """restore=False (Sim's chunks: Sim restores by replay) takes no copy: the same step and body as with
    restore, the arrays as the C call left them, and the error says they were not restored (float32:
    the float32 loop, csrc/step_f32.c, likewise)."""
    state, params = diverging_setup()
    state, params, effects = state.astype(dtype), params.astype(dtype), effects_array("angular_damping").astype(dtype)
    kept, left = state.copy(), state.copy()
    with pytest.raises(DivergenceError) as with_copy:
        CBackend().advance(kept, params, effects, "euler", False, 0.05, 200)
    with pytest.raises(DivergenceError, match="not restored") as without:
        CBackend().advance(left, params, effects, "euler", False, 0.05, 200, restore=False)
    assert (without.value.step, without.value.body) == (with_copy.value.step, with_copy.value.body)
    np.testing.assert_array_equal(kept, state)
    raw = state.copy()       # the C call alone, nobody restoring
    call = _c.simulate if dtype == "float64" else _c.simulate_f32
    status, step, body = call(raw, params, effects, 0, 0, 0.05, 200)
    assert (status, step, body) == (1, without.value.step, without.value.body)
    np.testing.assert_array_equal(left, raw)


@pytest.mark.parametrize("nb,bad", [(3, 1), (9, 6), (8, 0), (5, 4)])
def test_divergence_low_level_contract(nb, bad):
    """The failing body ends at its last finite state (the other rows are unspecified: CBackend
    restores them). C steps bodies in blocks; the contract must not depend on that."""
    rng = np.random.default_rng(nb)
    state, params = random_bodies(rng, nb)
    state[bad, 10:13] = [300.0, 200.0, 100.0]
    s = state.copy()
    status, step, body = _c.simulate(s, params, np.zeros((0, 8)), 0, 0, 0.05, 200)
    assert (status, body) == (1, bad)
    assert np.all(np.isfinite(s))
    last = state[bad:bad + 1].copy()
    assert _c.simulate(last, params[bad:bad + 1], np.zeros((0, 8)), 0, 0, 0.05, step) == (0, -1, -1)
    np.testing.assert_array_equal(s[bad], last[0])
    ok = (bad + 1) % nb
    assert _c.simulate(state[ok:ok + 1].copy(), params[ok:ok + 1], np.zeros((0, 8)), 0, 0, 0.05, 1) == (0, -1, -1)


@pytest.mark.parametrize("integrator", ["euler", "semi_implicit_euler", "rk4"])
@pytest.mark.parametrize("wild", [1, 5])
def test_divergence_earliest_step_across_bodies(integrator, wild):
    """A calm body 0 that diverges late and a wild body that diverges early (in the same block of four
    or the next): both backends report the earliest failing step, then the lowest body at that step."""
    from lavendersim.backends.numpy_backend import NumpyBackend

    nb, dt = 7, 0.05
    params = np.tile([2.0, 0.1, 0.2, 0.3], (nb, 1))
    state = np.zeros((nb, 13))
    state[:, 6] = 1.0
    state[:, 10:13] = [0.1, 0.2, 0.05]                                   # healthy bodies
    state[0, 10:13] = np.array([1.0, 2.0, 3.0]) / np.sqrt(14) * (20.0 if integrator != "rk4" else 60.0)
    state[wild, 10:13] = np.array([3.0, -1.0, 2.0]) / np.sqrt(14) * 100.0
    alone = {}
    for b in (0, wild):
        with pytest.raises(DivergenceError) as one:
            CBackend().advance(state[b:b + 1].copy(), params[:1], np.zeros((0, 8)), integrator, False, dt, 5000)
        alone[b] = one.value.step
    assert alone[wild] < alone[0]  # the scene really has the late/early pair
    got = {}
    for backend in (CBackend(), NumpyBackend()):
        s = state.copy()
        with pytest.raises(DivergenceError) as info:
            backend.advance(s, params, np.zeros((0, 8)), integrator, False, dt, 5000)
        np.testing.assert_array_equal(s, state)
        got[backend.name] = (info.value.step, info.value.body)
    assert got["c"] == got["numpy"] == (alone[wild], wild)
    # the cause: the start state's |omega|*dt, and the (finite) state just before the failing step
    s = state.copy()
    with pytest.raises(DivergenceError, match=r"\|omega\|\*dt = 5 is beyond \w+.s validity bound .*just before step"):
        CBackend().advance(s, params, np.zeros((0, 8)), integrator, False, dt, 5000)
    # same step in two bodies: the lower index wins
    twin = state.copy()
    twin[0] = twin[wild]
    assert _c.simulate(twin.copy(), params, np.zeros((0, 8)), {"euler": 0, "semi_implicit_euler": 1, "rk4": 2}[integrator],
                       0, dt, 5000)[1:] == (alone[wild], 0)


def test_divergence_earliest_step_models_and_structured():
    """The same ordering with a wheel body failing late before a plain body failing early, and for
    splitting (bodies stepped one by one)."""
    rng = np.random.default_rng(31)
    kinds = [2, 0, 0, 0, 0, 3]
    state, params = random_bodies(rng, len(kinds))
    md = random_models(rng, state, params, kinds)
    md.rows[0, LY.MODEL_C_W] = 10.0                      # body 0's wheels blow up, after a while (step 17)
    state[4, 10:13] = [3000.0, 2000.0, 1000.0]           # body 4 blows up sooner (step 8) under explicit Euler
    got = {}
    for backend in (CBackend(), NumpyBackend()):
        s, m = state.copy(), copy_models(md)
        with pytest.raises(DivergenceError) as info:
            backend.advance(s, params, np.zeros((0, 8)), "euler", False, 0.01, 300, m)
        got[backend.name] = (info.value.step, info.value.body)
        np.testing.assert_array_equal(s, state)
        np.testing.assert_array_equal(m.Omega, md.Omega)
    assert got["c"] == got["numpy"] and got["c"][1] == 4
    s0, m0 = state[:1].copy(), copy_models(Models(md.rows[:1], md.Omega[:1], md.command[:1], md.applied[:1]))
    with pytest.raises(DivergenceError) as late:
        CBackend().advance(s0, params[:1], np.zeros((0, 8)), "euler", False, 0.01, 300, m0)
    assert late.value.step > got["c"][0]
    # splitting (one body at a time in C): angular damping beyond its limit on body 0 (fails at step
    # ~250) and, stronger, on body 2 (fails at step 75). The exploding attitude is chaotic, so the exact
    # step follows the rounding of the derived splitting kernels (it was 76 with the hand-written flows, 75 until
    # angular damping declared its torque in the body frame: its world form R(-c omega_b) rounds differently; 75
    # again since R_WB tau_b prints as the quaternion sandwich, issue 30).
    pst, pp = random_bodies(np.random.default_rng(37), 3)
    eff = np.array([effect(5, 0, 150.0), effect(5, 2, 400.0)])
    res = {}
    for backend in (CBackend(), NumpyBackend()):
        with pytest.raises(DivergenceError) as info:
            backend.advance(pst.copy(), pp, eff, "splitting", True, 0.05, 400)
        res[backend.name] = (info.value.step, info.value.body)
    assert res["c"] == res["numpy"] == (75, 2)


def test_non_finite_input():
    state, params = diverging_setup()
    state[2, 0] = np.nan
    s = state.copy()
    with pytest.raises(DivergenceError) as info:
        CBackend().advance(s, params, np.zeros((0, 8)), "rk4", True, 0.01, 10)
    assert info.value.step == 0 and info.value.body == 2
    assert "non-finite" in str(info.value)
    np.testing.assert_array_equal(np.isnan(s), np.isnan(state))
    np.testing.assert_array_equal(np.nan_to_num(s), np.nan_to_num(state))
    p = params.copy()
    p[0, 0] = np.inf
    state[2, 0] = 0.0
    with pytest.raises(DivergenceError, match="non-finite input"):
        CBackend().advance(state.copy(), p, effects_array("gravity"), "rk4", True, 0.01, 10)


# ---------------------------------------------------------------- argument checking

def test_bad_buffers():
    rng = np.random.default_rng(17)
    state, params = random_bodies(rng, 2)
    E = np.zeros((0, 8))
    with pytest.raises(TypeError, match="float64"):
        _c.simulate(state.astype(np.float32), params, E, 2, 1, 0.01, 1)
    with pytest.raises(TypeError, match="C-contiguous"):
        _c.simulate(np.asfortranarray(np.zeros((3, 13))), np.zeros((3, 4)), E, 2, 1, 0.01, 1)
    ro = state.copy()
    ro.flags.writeable = False
    with pytest.raises(TypeError, match="writable"):
        _c.simulate(ro, params, E, 2, 1, 0.01, 1)
    with pytest.raises(ValueError, match=r"\(n, 13\)"):
        _c.simulate(np.zeros((2, 12)), params, E, 2, 1, 0.01, 1)
    with pytest.raises(ValueError, match="params has 3 rows"):
        _c.simulate(state.copy(), np.ones((3, 4)), E, 2, 1, 0.01, 1)
    with pytest.raises(ValueError, match=r"code 9\.0 is not a declared effect \(built-in codes: 1 \(applied_torque\)"):
        _c.simulate(state.copy(), params, np.array([effect(9, -1)]), 2, 1, 0.01, 1)
    with pytest.raises(ValueError, match="body"):
        _c.simulate(state.copy(), params, np.array([effect(1, 2)]), 2, 1, 0.01, 1)
    with pytest.raises(ValueError, match="body"):
        _c.simulate(state.copy(), params, np.array([effect(1, 0.5)]), 2, 1, 0.01, 1)
    with pytest.raises(ValueError, match="integrator"):  # one past the last code
        _c.simulate(state.copy(), params, E, max(c_backend.INTEGRATOR_CODES.values()) + 1, 1, 0.01, 1)
    with pytest.raises(ValueError, match="adaptive integrator needs h"):
        _c.simulate(state.copy(), params, E, 3, 1, 0.01, 1)
    with pytest.raises(ValueError, match="rtol > 0"):
        _c.simulate(state.copy(), params, E, 3, 1, 0.01, 1, None, None, None, None, np.zeros(2), np.zeros(2), 0.0, 1e-9)
    with pytest.raises(ValueError, match="one float64 per body"):
        _c.simulate(state.copy(), params, E, 3, 1, 0.01, 1, None, None, None, None, np.zeros(3), np.zeros(2), 1e-6, 1e-9)
    with pytest.raises(ValueError, match="n_steps"):
        _c.simulate(state.copy(), params, E, 2, 1, 0.01, -1)
    with pytest.raises(ValueError, match="dt"):
        _c.simulate(state.copy(), params, E, 2, 1, float("nan"), 1)
    with pytest.raises(TypeError):
        _c.simulate([[0.0] * 13], params[:1], E, 2, 1, 0.01, 1)
    with pytest.raises(ValueError, match="integrator"):
        CBackend().advance(state.copy(), params, E, "verlet", True, 0.01, 1)
    with pytest.raises(TypeError, match="state"):
        CBackend().advance(state[:, ::-1], params, E, "rk4", True, 0.01, 1)
    # eval_kernel
    idx = {n: i for i, (n, _, _) in enumerate(_c.kernels())}
    with pytest.raises(ValueError, match="multiple of n_in"):
        _c.eval_kernel(idx["quat_mul"], np.zeros(7), np.zeros(4))
    with pytest.raises(ValueError, match="out holds"):
        _c.eval_kernel(idx["quat_mul"], np.zeros(16), np.zeros(4))
    with pytest.raises(ValueError, match="out of range"):
        _c.eval_kernel(len(idx), np.zeros(8), np.zeros(4))
    with pytest.raises(TypeError, match="float64"):
        _c.eval_kernel(idx["quat_mul"], np.zeros(8, np.int64), np.zeros(4))
    with pytest.raises(ValueError, match="shape"):
        c_backend.eval_kernel("quat_mul", np.zeros(3), np.zeros(4))


def test_eval_kernel_broadcasts_like_numpy():
    rng = np.random.default_rng(19)
    q = rng.normal(size=(5, 1, 4))
    v = rng.normal(size=(3, 3))
    np.testing.assert_allclose(c_backend.eval_kernel("quat_rotate", q, v), K.quat_rotate(q, v), rtol=0, atol=1e-14)
    axis, angle = c_backend.eval_kernel("quat_to_axis_angle", K.quat_normalize(q))
    ax2, an2 = K.quat_to_axis_angle(K.quat_normalize(q))
    assert axis.shape == ax2.shape == (5, 1, 3) and angle.shape == an2.shape == (5, 1)
    assert c_backend.eval_kernel("kinetic_energy", 2.0, [1, 2, 3], [1, 0, 0], [0, 1, 0]).shape == ()


def test_kernel_table_matches_numpy():
    table = _c.kernels()
    assert len(table) == _c.KERNEL_COUNT == len(K.KERNELS)
    for (name, n_in, n_out), (kname, (_, ins, outs)) in zip(table, K.KERNELS.items()):
        assert name == kname
        assert n_in == sum(int(np.prod(s, dtype=int)) for _, s in ins)
        assert n_out == sum(int(np.prod(s, dtype=int)) for _, s in outs)


# ---------------------------------------------------------------- staleness

def test_build_is_current():
    assert _c.GENERATED_HASH == c_backend.generated_hash(c_backend.generated_dir())
    c_backend.check_build()


def test_stale_copy_of_generated(tmp_path):
    gen = c_backend.generated_dir()
    for f in gen.iterdir():
        if f.is_file():
            shutil.copy(f, tmp_path / f.name)
    c_backend.check_build(tmp_path)  # an identical copy is current
    with open(tmp_path / "kernels.c", "a") as fh:
        fh.write("/* changed */\n")
    with pytest.raises(StaleBuildError) as info:
        c_backend.check_build(tmp_path)
    msg = str(info.value)
    assert f"`{c_backend.REBUILD}`" in msg       # the rebuild command for how this copy was installed
    assert "lavendersim derive" in msg  # the edit also broke generated/'s own manifest
    assert isinstance(info.value, ImportError)


def test_stale_hash_on_import(monkeypatch):
    monkeypatch.setattr(_c, "GENERATED_HASH", "0" * 64)
    try:
        with pytest.raises(StaleBuildError, match=re.escape(f"`{c_backend.REBUILD}`")):
            importlib.reload(c_backend)
    finally:
        monkeypatch.undo()
        importlib.reload(c_backend)
    assert "lavendersim derive" not in _stale_message_for_current_generated()


def _stale_message_for_current_generated():
    try:
        c_backend.check_build(built_hash="f" * 64)
    except StaleBuildError as exc:
        return str(exc)
    raise AssertionError("check_build accepted a wrong hash")


# ---------------------------------------------------------------- joint / wheel models through the C loop

from lavendersim.backends import KIND_JOINT, KIND_WHEELS, MODEL_SIZE, Models, on_body_axes, wheel_row  # noqa: E402
from lavendersim.backends.numpy_backend import NumpyBackend  # noqa: E402
from lavendersim.generated import layout as LY  # noqa: E402


def random_models(rng, state, params, kinds, on_axes=()):
    """Model rows for the given kinds (joint anchored 0.1-0.3 m from the COM; wheels ~5% of I: three on the
    body axes, or for the bodies in on_axes 2-4 wheels on random unit axes; the unused slots padded)."""
    nb = state.shape[0]
    md = Models.empty(nb)
    for b, kind in enumerate(kinds):
        I_b = params[b, LY.PARAM_I_B]
        r_b = rng.uniform(-0.3, 0.3, 3) if kind & KIND_JOINT else np.zeros(3)
        anchor = state[b, LY.STATE_P_W] - K.quat_rotate(state[b, LY.STATE_Q], r_b)
        row = md.rows[b]
        row[LY.MODEL_KIND] = kind
        row[LY.MODEL_I_P] = K.parallel_axis(np.diag(I_b), params[b, LY.PARAM_M], -r_b).reshape(9)
        row[LY.MODEL_R_B], row[LY.MODEL_ANCHOR_W] = r_b, anchor
        if kind & KIND_WHEELS:
            axes = b in on_axes
            n = int(rng.integers(2, LY.WHEELS_MAX + 1)) if axes else LY.WHEELS_BODY_AXES
            A = rng.normal(size=(3, n)) if axes else np.eye(3)
            A /= np.linalg.norm(A, axis=0)
            J = 0.05 * (I_b.min() * np.ones(n) if axes else I_b)
            assert wheel_row(row, J, A) == KIND_WHEELS and on_body_axes(row) == (not axes)
            row[LY.MODEL_TORQUE_LIMIT], row[LY.MODEL_SPEED_LIMIT], row[LY.MODEL_C_W] = 0.3, 40.0, 1e-3
            md.Omega[b, :n] = rng.uniform(-5, 5, n)
            md.command[b, :n] = rng.uniform(-0.5, 0.5, n)
    return md


def copy_models(md):
    return Models(md.rows.copy(), md.Omega.copy(), md.command.copy(), md.applied.copy())


@pytest.mark.parametrize("integrator", INTEGRATORS)
@pytest.mark.parametrize("effects_name", ["none", "all"])
def test_models_match_the_numpy_backend(integrator, effects_name):
    """Plain, jointed, wheeled and jointed+wheeled bodies, wheels on the body axes and on random axes
    (bodies 11 and 13; the same wheel model), interleaved (plain runs are blocked in C)."""
    rng = np.random.default_rng(21)
    kinds = [0, 3, 0, 0, 2, 1, 0, 0, 0, 0, 3, 2, 0, 3]
    state, params = random_bodies(rng, len(kinds))
    md = random_models(rng, state, params, kinds, on_axes=(11, 13))
    effects = effects_array(effects_name)
    a, ma = state.copy(), copy_models(md)
    b, mb = state.copy(), copy_models(md)
    NumpyBackend().advance(a, params, effects, integrator, True, 0.005, 60, ma)
    CBackend().advance(b, params, effects, integrator, True, 0.005, 60, mb)
    assert np.max(np.abs(a - b)) <= TOL * max(1.0, np.max(np.abs(a)))
    assert np.max(np.abs(ma.Omega - mb.Omega)) <= TOL * max(1.0, np.max(np.abs(ma.Omega)))
    np.testing.assert_array_equal(ma.applied, mb.applied)
    n = md.wheel_counts
    assert list(n) == [0, 3, 0, 0, 3, 0, 0, 0, 0, 0, 3, n[11], 0, n[13]] and min(n[11], n[13]) >= 2
    used = np.arange(LY.WHEELS_MAX)[None, :] < n[:, None]
    assert np.all(mb.applied[used] != 0) and np.all(mb.applied[~used] == 0) and np.all(mb.Omega[~used] == 0)
    # plain bodies are bit-identical to a call without models
    plain = state.copy()
    CBackend().advance(plain, params, effects, integrator, True, 0.005, 60)
    idx = [i for i, k in enumerate(kinds) if k == 0]
    np.testing.assert_array_equal(b[idx], plain[idx])


def test_model_divergence_low_level_contract():
    rng = np.random.default_rng(23)
    kinds = [0, 2, 3, 0, 0]
    state, params = random_bodies(rng, len(kinds))
    md = random_models(rng, state, params, kinds)
    md.rows[2, LY.MODEL_C_W] = 1e3  # wheel damping far beyond explicit Euler's limit: body 2's wheels blow up
    s, m2 = state.copy(), copy_models(md)
    status, step, body = _c.simulate(s, params, np.zeros((0, 8)), 0, 0, 0.01, 300, m2.rows, m2.Omega, m2.command, m2.applied)
    assert (status, body) == (1, 2) and step > 0
    assert np.all(np.isfinite(s)) and np.all(np.isfinite(m2.Omega))
    np.testing.assert_array_equal(m2.applied[2], md.applied[2])   # failing body's applied untouched
    one, m1 = state.copy(), copy_models(md)                       # the failing body holds its last finite state
    _c.simulate(one, params, np.zeros((0, 8)), 0, 0, 0.01, step, m1.rows, m1.Omega, m1.command, m1.applied)
    np.testing.assert_array_equal(s[2], one[2])
    np.testing.assert_array_equal(m2.Omega[2], m1.Omega[2])
    # through CBackend everything is restored and the cause names the wheel damping
    s, m3 = state.copy(), copy_models(md)
    with pytest.raises(DivergenceError, match="wheel damping") as info:
        CBackend().advance(s, params, np.zeros((0, 8)), "euler", False, 0.01, 300, m3)
    assert info.value.body == 2 and info.value.step == step
    np.testing.assert_array_equal(s, state)
    np.testing.assert_array_equal(m3.Omega, md.Omega)
    np.testing.assert_array_equal(m3.applied, md.applied)


def test_bad_model_buffers():
    rng = np.random.default_rng(29)
    state, params = random_bodies(rng, 2)
    md = random_models(rng, state, params, [3, 0])
    E = np.zeros((0, 8))
    W3 = np.zeros((2, LY.WHEELS_MAX))
    with pytest.raises(ValueError, match="all four"):
        _c.simulate(state.copy(), params, E, 2, 1, 0.01, 1, md.rows)
    with pytest.raises(ValueError, match=rf"model_rows must have shape \(n, {MODEL_SIZE}\)"):
        _c.simulate(state.copy(), params, E, 2, 1, 0.01, 1, md.rows[:, :-1].copy(), W3.copy(), W3, W3.copy())
    with pytest.raises(ValueError, match="model_rows has 1 rows"):
        _c.simulate(state.copy(), params, E, 2, 1, 0.01, 1, md.rows[:1].copy(), W3.copy(), W3, W3.copy())
    with pytest.raises(ValueError, match="Omega has 1 rows"):
        _c.simulate(state.copy(), params, E, 2, 1, 0.01, 1, md.rows, np.zeros((1, LY.WHEELS_MAX)), W3, W3.copy())
    for k in (4, 6, 7, 8, 2.5, -1):   # beyond the bits (KIND_JOINT | KIND_WHEELS); not an integer
        bad = md.rows.copy()
        bad[1, LY.MODEL_KIND] = k
        with pytest.raises(ValueError, match="kind"):
            _c.simulate(state.copy(), params, E, 2, 1, 0.01, 1, bad, W3.copy(), W3, W3.copy())
    ro = W3.copy()
    ro.flags.writeable = False
    with pytest.raises(TypeError, match="writable"):
        _c.simulate(state.copy(), params, E, 2, 1, 0.01, 1, md.rows, ro, W3, W3.copy())
    with pytest.raises(TypeError, match="float64"):
        _c.simulate(state.copy(), params, E, 2, 1, 0.01, 1, md.rows, W3.copy(), W3.astype(np.float32), W3.copy())
    with pytest.raises(TypeError, match="models.Omega"):
        CBackend().advance(state.copy(), params, E, "rk4", True, 0.01, 1,
                           Models(md.rows, W3.astype(np.float32), W3, W3.copy()))
    with pytest.raises(ValueError, match=rf"models.rows must have shape \(2, {MODEL_SIZE}\)"):
        CBackend().advance(state.copy(), params, E, "rk4", True, 0.01, 1, Models(md.rows[:, :20], W3.copy(), W3, W3.copy()))
    assert MODEL_SIZE == 36   # + MODEL_CUTOFF (issue 13: the wheel motor); J and A_b for 4 wheel slots (N-axis wheels)


@pytest.mark.parametrize("calm", [0, 9])   # the diverging body alone, or in the second block of 8
def test_late_rk4_divergence_is_found_at_its_step_across_check_chunks(calm):
    """The torque-free RK4 fast path checks finiteness once per chunk of steps and replays the chunk
    to find the step; a divergence hundreds of steps in must still be reported at the same step,
    body and restored state as the NumPy backend's per-step check."""
    import lavendersim as lv

    got = {}
    for backend in ("c", "numpy"):
        s = lv.Scene()
        for i in range(calm):
            s.add_body(lv.Body.sphere(f"calm{i}", 1.0, 0.1))
        s.add_body(lv.Body("spin", 1.0, (1.0, 2.0, 3.0), omega_b=(0.01, 0.01, 28.4)))   # |ω|·dt just past RK4's limit
        # the backends' own non-finite check: Sim's bound and growth checks (issue 11) switched off
        sim = lv.Sim(s, dt=0.1, integrator="rk4", backend=backend, on_bound="warn", max_growth=None)
        before = sim.x.copy()
        with pytest.warns(), pytest.raises(DivergenceError) as e:
            sim.run(5000)
        assert np.array_equal(sim.x, before)
        got[backend] = (e.value.step, e.value.body)
    assert got["c"] == got["numpy"] == (204, calm)
