"""Issue 30, scale: the growth check of wheeled bodies is one batched kernel call (bitwise the per-body
loop it replaced), and Scene.add_effect indexes effects per body (the same refusals, O(1) per call).

Behaviour only: no timing here (the figures are in the issue's note, measured in CPU time)."""
import pickle
import warnings

import numpy as np
import pytest

import lavendersim as lv
from lavendersim import backends
from lavendersim import sim as sim_mod
from lavendersim.errors import DivergenceError, ValidityBoundWarning
from lavendersim.generated import layout as LY
from lavendersim.effects import ImmutableEffectError
from lavendersim.validate import LavenderInputError


def _norm(v):
    """|v| of one vector as np.linalg.norm(..., axis=-1) computes it for each row: sqrt(add.reduce(v*v)). (NumPy >= 2.4
    computes np.linalg.norm of a 1-D array as sqrt(dot(v, v)) through BLAS, which may round differently.)"""
    return float(np.sqrt(np.add.reduce(v * v, axis=-1)))


def _total(rows, x, Omega, i):
    """Body i's total wheel momentum (the printed kernel on its row alone)."""
    s = slice(i, i + 1)
    return backends.wheel_total_momentum_batch(rows[s], x[s, LY.STATE_Q], x[s, LY.STATE_OMEGA_B], Omega[s])[0]


def _loop_invariants(sim, x, Omega, reference=False):
    """Sim._invariants as it was before issue 30: a Python loop over the free wheeled bodies."""
    nb = len(sim.names)
    E, L = np.zeros(nb), np.zeros(nb)
    with np.errstate(over="ignore", invalid="ignore"):
        if sim._free_any:
            f = sim._free
            I_b, w_b = sim._params[f][:, LY.PARAM_I_B], x[f][:, LY.STATE_OMEGA_B]
            E[f] = sim_mod.K.kinetic_energy(sim._params[f, LY.PARAM_M], I_b, x[f][:, LY.STATE_V_W], w_b)
            L[f] = np.linalg.norm(sim_mod.K.body_momentum(I_b, w_b), axis=-1)
        for i in np.flatnonzero(sim._free_wheels):
            Lb, Lw = backends.wheel_momentum(sim._models.rows[i], x[i, LY.STATE_Q], x[i, LY.STATE_OMEGA_B], Omega[i])
            L[i] = _norm(_total(sim._models.rows, x, Omega, i))
            if reference:
                parts = _norm(Lb) + float(np.abs(sim._models.rows[i, LY.MODEL_J] * Omega[i]).sum())
                L[i] = max(L[i], sim_mod.L_FLOOR * parts)
    return E, L


def _loop_momenta(budget, x, Omega):
    """LoadBudget._momenta as it was before issue 30 (per-body loop over the wheeled bodies)."""
    nb = x.shape[0]
    L, P = np.zeros(nb), np.zeros(nb)
    with np.errstate(over="ignore", invalid="ignore"):
        f = budget.plain
        if f.any():
            L[f] = np.linalg.norm(sim_mod.K.body_momentum(budget.params[f][:, LY.PARAM_I_B], x[f][:, LY.STATE_OMEGA_B]), axis=-1)
        for i in budget.wheeled:
            L[i] = _norm(_total(budget.rows, x, Omega, i))
        P[budget.loaded] = budget.params[budget.loaded, LY.PARAM_M] * np.linalg.norm(x[budget.loaded][:, LY.STATE_V_W], axis=-1)
    return L, P


def _mixed_scene(rng):
    """Plain, full-inertia and wheeled bodies (2, 3, 4 wheels), some with an applied torque."""
    sc = lv.Scene()
    full = np.array([[0.03, 0.004, -0.002], [0.004, 0.05, 0.001], [-0.002, 0.001, 0.04]])
    for i in range(24):
        w = rng.normal(size=3) * 3
        if i % 6 == 0:
            sc.add_body(lv.Body(f"b{i}", 1.0, full, omega_b=w))
        else:
            sc.add_body(lv.Body.box(f"b{i}", 1.0 + 0.1 * i, (0.1, 0.2 + 0.01 * i, 0.3), omega_b=w))
        n = (0, 3, 4, 2)[i % 4]
        if n:
            A = rng.normal(size=(3, n))
            A /= np.linalg.norm(A, axis=0)
            sc.add_effect("reaction_wheels", body=f"b{i}", axes_b=A.T, J=list(1e-4 * (1 + rng.random(n))),
                          torque_limit=0.1, speed_limit=200.0)
        if i % 5 == 0:
            sc.add_effect("applied_torque", body=f"b{i}", torque_w=[0.0, 1e-3, 0.0])
    return sc


def _states(sim, rng):
    """The current state and perturbed ones: large and tiny rates, wheels spinning, a NaN and an inf row."""
    x0, W0 = sim._x.copy(), sim._models.Omega.copy()
    out = [(x0, W0)]
    for scale in (1e-9, 1.0, 1e6):
        x, W = x0.copy(), W0.copy()
        x[:, LY.STATE_OMEGA_B] = rng.normal(size=(x.shape[0], 3)) * scale
        q = rng.normal(size=(x.shape[0], 4))
        x[:, LY.STATE_Q] = q / np.linalg.norm(q, axis=1, keepdims=True)
        W[:] = rng.normal(size=W.shape) * scale * 10
        out.append((x, W))
    x, W = out[-1][0].copy(), out[-1][1].copy()
    x[1, LY.STATE_OMEGA_B.start] = np.nan
    x[2, LY.STATE_OMEGA_B.start] = np.inf
    W[3, 0] = np.inf
    out.append((x, W))
    return out


@pytest.mark.parametrize("backend", ["c", "numpy"])
def test_batched_invariants_equal_the_per_body_loop_bitwise(backend):
    rng = np.random.default_rng(30)
    sim = lv.Sim(_mixed_scene(rng), dt=1e-3, backend=backend)
    assert len(sim._fw) >= 6 and sim._free_any and sim._budget is not None and len(sim._budget.wheeled) >= 2
    for x, W in _states(sim, rng):
        for reference in (False, True):
            E, L = sim._invariants(x, W, reference=reference)
            E2, L2 = _loop_invariants(sim, x, W, reference=reference)
            np.testing.assert_array_equal(E, E2)
            np.testing.assert_array_equal(L, L2)     # bitwise, NaN where the loop had NaN
        Lb, Pb = sim._budget._momenta(x, W)
        Lb2, Pb2 = _loop_momenta(sim._budget, x, W)
        np.testing.assert_array_equal(Lb, Lb2)
        np.testing.assert_array_equal(Pb, Pb2)
    assert sim._L0[sim._fw].min() > 0


def test_wheel_momentum_batch_rows_are_wheel_momentum():
    rng = np.random.default_rng(3)
    sim = lv.Sim(_mixed_scene(rng), dt=1e-3)
    idx = sim._fw
    x, W = _states(sim, rng)[2]
    Lb, Lw = backends.wheel_momentum_batch(sim._models.rows[idx], x[idx, LY.STATE_Q], x[idx, LY.STATE_OMEGA_B], W[idx])
    assert Lb.shape == Lw.shape == (idx.size, 3)
    for k, i in enumerate(idx):
        b, w = backends.wheel_momentum(sim._models.rows[i], x[i, LY.STATE_Q], x[i, LY.STATE_OMEGA_B], W[i])
        np.testing.assert_array_equal(Lb[k], b)
        np.testing.assert_array_equal(Lw[k], w)
        # the growth check's one-sum total is body + wheels up to rounding of the parts
        L = backends.wheel_total_momentum_batch(sim._models.rows[idx], x[idx, LY.STATE_Q], x[idx, LY.STATE_OMEGA_B], W[idx])
        parts = np.linalg.norm(b) + np.linalg.norm(w)
        assert np.abs(L[k] - (b + w)).max() <= 1e-14 * parts and parts > 0


def _diverging_scene(loaded):
    sc = lv.Scene()
    for i in range(6):
        sc.add_body(lv.Body.box(f"w{i}", 1.0, (0.1, 0.2, 0.3), omega_b=[0.3, 0.2 + 0.05 * i, 0.1]))
        sc.add_effect("reaction_wheels", body=f"w{i}", J=[1e-4] * 3, torque_limit=0.1, speed_limit=100.0)
        if loaded:
            sc.add_effect("applied_torque", body=f"w{i}", torque_w=[0.0, 0.0, 1e-6])
    # one body spins fast: euler's energy (and |L|) grows on it first
    sc.add_body(lv.Body.box("fast", 1.0, (0.1, 0.2, 0.3), omega_b=[30.0, 45.0, 20.0]))
    sc.add_effect("reaction_wheels", body="fast", J=[1e-4] * 3, torque_limit=0.1, speed_limit=100.0)
    if loaded:
        sc.add_effect("applied_torque", body="fast", torque_w=[0.0, 0.0, 1e-6])
    return sc


def _divergence(loaded, backend, loop):
    sim = lv.Sim(_diverging_scene(loaded), dt=0.02, integrator="euler", backend=backend, on_bound="warn")
    if loop:   # the reference: the per-body loops of before issue 30
        sim._invariants = lambda x, W, reference=False: _loop_invariants(sim, x, W, reference)
        if sim._budget is not None:
            sim._budget._momenta = lambda x, W, *cols: _loop_momenta(sim._budget, x, W)   # (cols: v, w as gathered)
        sim._reference()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", ValidityBoundWarning)
        with pytest.raises(DivergenceError) as ei:
            sim.run(5000)
    return ei.value, sim.steps, sim._x.copy()


@pytest.mark.parametrize("loaded", [False, True])
@pytest.mark.parametrize("backend", ["c", "numpy"])
def test_a_diverging_wheeled_body_is_named_at_the_same_step(loaded, backend):
    e, steps, x = _divergence(loaded, backend, loop=False)
    e2, steps2, x2 = _divergence(loaded, backend, loop=True)
    assert e.body_name == "fast" and e.body == 6
    assert (e.step, e.body, e.cause, e.t) == (e2.step, e2.body, e2.cause, e2.t)
    assert steps == steps2
    np.testing.assert_array_equal(x, x2)
    # the growth check fired (not the validity bound, which only warns here): free or load budget
    assert ("loads can supply" in e.cause) if loaded else e.cause.startswith("|L| grew")


# ---- Scene.add_effect: an index per body, the same refusals --------------------------------------------

def _scene_of(n):
    sc = lv.Scene()
    sc.add_bodies([f"b{i}" for i in range(n)], np.ones(n), np.tile([0.02, 0.03, 0.04], (n, 1)))
    return sc


def _refusal(sc, *args, **kw):
    before = list(sc.effects)
    with pytest.raises(LavenderInputError) as ei:
        sc.add_effect(*args, **kw)
    assert sc.effects == before          # nothing half-applied
    return ei.value.field, str(ei.value)


def test_duplicate_per_body_effects_are_refused_with_the_same_field():
    sc = _scene_of(5)
    for i in range(5):
        sc.add_effect("reaction_wheels", body=f"b{i}", J=[1e-4] * 3, torque_limit=0.1, speed_limit=100.0)
    field, text = _refusal(sc, "reaction_wheels", body="b3", J=[1e-4] * 3, torque_limit=0.1, speed_limit=100.0)
    assert field == "reaction_wheels.body" and "body 'b3' already has a reaction_wheels; at most one per body" in text
    field, text = _refusal(sc, "applied_torque", body="nobody", torque_w=[0, 0, 1.0])
    assert field == "applied_torque.body" and "unknown body 'nobody'" in text
    # another per-body effect on the same body, or the same effect on a body without one, is accepted
    sc.add_effect("spherical_joint", body="b3", anchor_w=[0.0, 0.0, 0.0])
    assert set(sc.model_effects("b3")) == {"reaction_wheels", "spherical_joint"}
    assert set(sc.model_effects("b4")) == {"reaction_wheels"} and sc.model_effects("b0")["reaction_wheels"].body == "b0"


def test_the_index_follows_edits_of_the_effects_list():
    """scene.effects stays a list one may edit (envs/vector.py appends to it): the duplicate check sees every
    edit, appends and removals alike."""
    sc = _scene_of(3)
    from lavendersim.effects import make
    e = make("reaction_wheels", body="b1", J=[1e-4] * 3, torque_limit=0.1, speed_limit=100.0)
    sc.effects.append(e)                      # direct append: the index sees it
    assert _refusal(sc, e)[0] == "reaction_wheels.body"
    sc.effects.remove(e)                      # removal: the body may have one again
    sc.add_effect(e)
    assert sc.effects == [e] and sc.model_effects("b1") == {"reaction_wheels": e}
    sc.effects = []                           # assignment (tests/test_extending.py does it)
    assert sc.model_effects("b1") == {}
    sc.add_effect(e)
    del sc.effects[0]
    sc.add_effect(e)
    assert sc.effects == [e]
    sc.effects.insert(0, make("applied_torque", body="b2", torque_w=[0, 0, 1.0]))
    assert _refusal(sc, e)[0] == "reaction_wheels.body"
    import pickle
    sc2 = pickle.loads(pickle.dumps(sc))
    assert [x.name for x in sc2.effects] == ["applied_torque", "reaction_wheels"]
    assert _refusal(sc2, e)[0] == "reaction_wheels.body"


def test_overflowing_loads_are_refused_naming_the_same_field_and_effects():
    """The messages are the ones the scanning add_effect gave (recorded from it at 38f795f): the effects
    already on the body are named in the order declared."""
    sc = _scene_of(4)
    sc.add_effect("applied_torque", body="b2", torque_w=[0.0, 0.0, 1.5e298])
    sc.add_effect("gravity", g_w=[0.0, 0.0, -9.81])
    tail = "at its initial state = 1.5e+300 rad/s²; the bound is 1e+300 rad/s² (with applied_torque, gravity)"
    for body in ("b2", None):     # on b2 alone, or scene-wide: b2 is the body it overflows on
        field, text = _refusal(sc, "applied_torque", body=body, torque_w=[0.0, 0.0, 1.5e298])
        assert field == "applied_torque.torque_w"
        assert text == ("applied_torque.torque_w: too large: the angular acceleration |tau|/min(I_b) on body 'b2' "
                        + tail)
    field, text = _refusal(sc, "force_at_point", body="b1", r_b=[1.0, 0, 0], F_w=[0, 0, 1e301])
    assert (field, text) == ("force_at_point.F_w", "force_at_point.F_w: too large: the net force on body 'b1' at its "
                             "initial state = 1e+301 N; the bound is 1e+300 N (with gravity)")
    field, text = _refusal(sc, "gravity", g_w=[0.0, 0.0, -1e301])
    assert (field, text) == ("gravity.g_w", "gravity.g_w: too large: the net force on body 'b0' at its initial state "
                             "= 1e+301 N; the bound is 1e+300 N (with gravity)")
    with pytest.raises(LavenderInputError) as ei:
        sc.add_body(lv.Body("huge", 1e300, (1.0, 1.0, 1.0)))
    assert ei.value.field == "body" and str(ei.value) == (
        "body: the net force on body 'huge' at its initial state = 9.81e+300 N; the bound is 1e+300 N with the "
        "scene's effects on every body (gravity)")
    assert "huge" not in sc.bodies and [e.name for e in sc.effects] == ["applied_torque", "gravity"]


def test_scene_index_and_tables_with_many_per_body_effects():
    n = 300
    sc = _scene_of(n)
    for i in range(n - 1, -1, -1):
        sc.add_effect("applied_torque", body=f"b{i}", torque_w=[0.0, 0.0, 1e-3 * i])
    assert [sc.index(f"b{i}") for i in (0, 17, n - 1)] == [0, 17, n - 1]
    sc.add_body(lv.Body("late", 1.0, (1.0, 1.0, 1.0)))
    assert sc.index("late") == n
    with pytest.raises(LavenderInputError):
        sc.index("nobody")
    t = sc.tables()
    body_col = t.effects[:, 1].astype(int)
    np.testing.assert_array_equal(body_col, np.arange(n - 1, -1, -1))


def _scanning_check(sc, effect):
    """The every-body overflow check as the scanning add_effect did it: the first body's message, or None."""
    from lavendersim.effects import largest_param, load_overflow
    for b in sc.bodies.values():
        mine = [e for e in sc.effects if not e.per_body and e.body in (None, b.name)]
        why = load_overflow([effect], b) or load_overflow(mine + [effect], b)
        if why:
            return largest_param(effect) + ": too large: " + why + (
                f" (with {', '.join(e.name for e in mine)})" if mine else "")
    return None


@pytest.mark.parametrize("seed", range(4))
def test_every_body_effects_refused_exactly_where_the_scan_refused(seed):
    """The vectorized bound only clears bodies; near the limit (loads within 1e-12 of MAX_LOAD, cancelling
    sums, tiny masses) the refusal and its message are the scanning check's."""
    from lavendersim.effects import MAX_LOAD, make
    rng = np.random.default_rng(seed)
    n = 40
    sc = lv.Scene()
    q = rng.normal(size=(n, 4))
    sc.add_bodies([f"b{i}" for i in range(n)], 10.0 ** rng.uniform(-1, 3, n), np.tile([0.02, 0.03, 0.04], (n, 1)),
                  q=q, omega_b=rng.normal(size=(n, 3)))
    for i in rng.choice(n, 15, replace=False):
        sc.add_effect("applied_torque", body=f"b{i}", torque_w=rng.normal(size=3) * 1e297)
        if i % 2:
            sc.add_effect("force_at_point", body=f"b{i}", r_b=[0.1, 0.0, 0.0], F_w=-rng.normal(size=3) * 1e295)
    tried = refused = 0
    for k in range(12):
        scale = MAX_LOAD * (1 + rng.choice([-1e-12, 1e-12, -0.5, 1.0])) * 0.02
        e = (make("applied_torque", torque_w=[0.0, 0.0, scale]) if k % 3 == 0 else
             make("force_at_point", r_b=[0.0, 0.05, 0.0], F_w=rng.normal(size=3) * scale * 10 ** rng.uniform(-4, 1)) if k % 3 == 1
             else make("gravity", g_w=[0.0, 0.0, -scale * 10 ** rng.uniform(-3, 1)]))
        want = _scanning_check(sc, e)
        tried += 1
        if want is None:
            sc.add_effect(e)
            sc.effects.remove(e)      # keep the scene as it was for the next trial
        else:
            refused += 1
            assert _refusal(sc, e)[1] == want
    assert refused >= 2 and tried - refused >= 2


# ---- session 14: bodies kept as arrays, Scene.add_effects, batched Sim construction ----------------------------

def _plain(n, seed=7, **kw):
    rng = np.random.default_rng(seed)
    sc = lv.Scene()
    sc.add_bodies([f"b{i}" for i in range(n)], 10.0 ** rng.uniform(-1, 1, n), rng.uniform(1.0, 1.5, (n, 3)),
                  omega_b=rng.normal(size=(n, 3)), p_w=rng.normal(size=(n, 3)), **kw)
    return sc


def _mixed_by_loop(n, tq, J):
    """The scene add_effects builds, one add_effect per body (the path it must equal)."""
    sc = _plain(n)
    for i in range(n):
        sc.add_effect("reaction_wheels", body=f"b{i}", J=J[i], torque_limit=0.1, speed_limit=50.0)
    for i in range(n):
        sc.add_effect("applied_torque", body=f"b{i}", torque_w=tq[i])
    sc.add_effect("gravity", g_w=[0.0, 0.0, -9.81])
    sc.add_effect("force_at_point", body="b3", F_w=[1.0, 0.0, 0.0], r_b=[0.0, 0.1, 0.0])
    return sc


@pytest.mark.parametrize("backend", ["c", "numpy"])
def test_add_effects_builds_the_scene_and_sim_the_loop_builds_bitwise(backend):
    n = 40
    rng = np.random.default_rng(3)
    tq, J = rng.normal(size=(n, 3)) * 1e-3, rng.uniform(1e-4, 5e-4, (n, 3))
    one = _mixed_by_loop(n, tq, J)
    many = _plain(n)
    names = [f"b{i}" for i in range(n)]
    wheels = many.add_effects("reaction_wheels", names, J=J, torque_limit=0.1, speed_limit=50.0)
    torques = many.add_effects("applied_torque", names, torque_w=tq)
    many.add_effect("gravity", g_w=[0.0, 0.0, -9.81])
    many.add_effect("force_at_point", body="b3", F_w=[1.0, 0.0, 0.0], r_b=[0.0, 0.1, 0.0])
    assert [e.body for e in wheels] == names == [e.body for e in torques]
    assert [repr(e) for e in sorted(one.effects, key=repr)] == [repr(e) for e in sorted(many.effects, key=repr)]
    assert many.model_effects("b5")["reaction_wheels"] is wheels[5]
    with pytest.raises(ImmutableEffectError):
        torques[0].body = "b1"
    assert not torques[2].values["torque_w"].flags.writeable
    sa, sb = lv.Sim(one, dt=1e-3, backend=backend), lv.Sim(many, dt=1e-3, backend=backend)
    # the force table lists the same rows (the loop interleaves the two effects per body: compare as sets)
    assert sorted(map(tuple, sa.effects)) == sorted(map(tuple, sb.effects))
    assert np.array_equal(sa.model.rows, sb.model.rows) and np.array_equal(sa.x, sb.x)
    sa.run(30)
    sb.run(30)
    assert np.array_equal(sa.x, sb.x) and np.array_equal(sa.model.Omega, sb.model.Omega)


@pytest.mark.parametrize("bad, field, at", [
    (lambda tq: np.r_[tq[:7], [[np.nan, 0, 0]], tq[8:]], "applied_torque.torque_w", 7),
    (lambda tq: np.r_[tq[:11], [[1e301, 0, 0]], tq[12:]], "applied_torque.torque_w", 11),
])
def test_add_effects_refuses_the_first_bad_body_as_add_effect_does_and_adds_nothing(bad, field, at):
    n = 20
    tq = bad(np.random.default_rng(1).normal(size=(n, 3)))
    names = [f"b{i}" for i in range(n)]
    loop = _plain(n)
    with pytest.raises(LavenderInputError) as one:
        for i in range(n):
            loop.add_effect("applied_torque", body=names[i], torque_w=tq[i])
    sc = _plain(n)
    before = list(sc.effects)
    with pytest.raises(LavenderInputError) as many:
        sc.add_effects("applied_torque", names, torque_w=tq)
    assert many.value.field == one.value.field == field and many.value.rule == one.value.rule
    assert str(many.value) == str(one.value) + f" (bodies[{at}] = 'b{at}')"
    assert sc.effects == before and not sc.effects.has_per_body("applied_torque", "b0")
    assert len(lv.Sim(sc, dt=1e-3).effects) == 0          # nothing half-applied


def test_add_effects_refuses_per_body_duplicates_unknown_bodies_and_heavy_wheels_by_name():
    sc = _plain(6)
    sc.add_effect("reaction_wheels", body="b3", J=[1e-4] * 3, torque_limit=0.1, speed_limit=50.0)
    cases = [(["b0", "b1", "b3"], [1e-4] * 3, "reaction_wheels.body: body 'b3' already has a reaction_wheels; at most "
              "one per body (bodies[2] = 'b3')"),
             (["b0", "b1", "b0"], [1e-4] * 3, "(bodies[2] = 'b0')"),
             (["b0", "nope"], [1e-4] * 3, "reaction_wheels.body: unknown body 'nope'"),
             (["b0", "b1"], [[1e-4] * 3, [1e-4, 5.0, 1e-4]], "reaction_wheels.J: J[1] must be below the body's "
              "principal moment")]
    for bodies, J, text in cases:
        with pytest.raises(LavenderInputError, match=None) as err:
            sc.add_effects("reaction_wheels", bodies, J=np.asarray(J) if np.ndim(J) == 2 else J, torque_limit=0.1,
                           speed_limit=50.0)
        assert text in str(err.value) and f"bodies[{len(bodies) - 1}]" in str(err.value)
        assert [e.body for e in sc.effects] == ["b3"]
    with pytest.raises(LavenderInputError, match=r"^effect: .*bodies\[0\]"):
        sc.add_effects("no_such_effect", ["b0"])
    assert sc.add_effects("applied_torque", []) == []


def test_bodies_of_add_bodies_are_arrays_until_asked_for_and_keep_their_identity():
    sc = _plain(5)
    given = sc.add_body(lv.Body("g", 2.0, (1.0, 1.0, 1.5), omega_b=(0.0, 0.0, 1.0)))
    more = sc.add_bodies(["c0", "c1"], [1.0, 3.0], [[1.0, 1.0, 1.0], [1.0, 2.0, 2.5]])
    assert list(sc.bodies) == [f"b{i}" for i in range(5)] + ["g", "c0", "c1"] and len(more) == 2
    assert more[1] is sc.bodies["c1"] and more[-1] is more[1] and sc.bodies["g"] is given
    assert more[1].mass == 3.0 and np.array_equal(more[1].I_b, [1.0, 2.0, 2.5])
    assert not more[1].x0.flags.writeable and more[1].principal
    assert "c1" in sc.bodies and "zz" not in sc.bodies and ["unhashable"] not in sc.bodies
    assert sc.index("c0") == 6 and sc.index("g") == 5
    sim = lv.Sim(sc, dt=1e-3)
    sc.add_bodies(["late"], [1.0], [[1.0, 1.0, 1.0]])            # after the Sim: not one of its bodies
    assert "late" not in sim.bodies and len(sim.bodies) == 8 and sim.names[-1] == "c1"
    with pytest.raises(LavenderInputError, match="unknown body 'late'"):
        sim.state("late")
    back = pickle.loads(pickle.dumps(sc))
    assert list(back.bodies) == list(sc.bodies) and np.array_equal(back.tables().state, sc.tables().state)
    s2 = pickle.loads(pickle.dumps(sim))
    assert np.array_equal(s2.x, sim.x) and s2.names == sim.names


def test_the_name_index_is_built_on_the_first_look_up_and_refuses_as_the_eager_one_did():
    """add_bodies into an empty scene builds no name -> index dict (~63 B per body of the 1e6-body build's peak,
    issue 30): duplicates are found with a set, and the index is built on the first look-up by name. The refusals,
    look-ups and a Sim's bodies are those of the eager index."""
    sc = lv.Scene()
    with pytest.raises(LavenderInputError, match=r"names\[3\]: duplicate name 'b1' \(also names\[1\]\)"):
        sc.add_bodies(["b0", "b1", "b2", "b1"], np.ones(4), np.ones((4, 3)))
    assert len(sc.bodies) == 0 and list(sc.bodies) == []
    sc.add_bodies([f"b{i}" for i in range(6)], np.arange(1.0, 7.0), np.ones((6, 3)))
    table = sc._bodies._c
    assert table["pos"] is None                                  # stepped by index: no dict yet
    sim = lv.Sim(sc, dt=1e-3, backend="numpy")
    assert table["pos"] is None and sim.names == tuple(f"b{i}" for i in range(6))
    assert sim.state("b4").p_w.tolist() == [0.0, 0.0, 0.0] and sc.index("b5") == 5 and table["pos"] is not None
    with pytest.raises(LavenderInputError, match=r"names\[1\]: duplicate name 'b2'$"):
        sc.add_bodies(["n0", "b2"], [1.0, 1.0], np.ones((2, 3)))
    with pytest.raises(LavenderInputError, match="body.name: duplicate name 'b0'"):
        sc.add_body(lv.Body("b0", 1.0, (1.0, 1.0, 1.0)))
    sc.add_body(lv.Body("g", 1.0, (1.0, 1.0, 1.0)))
    sc.add_bodies(["n0", "n1"], [1.0, 2.0], np.ones((2, 3)))
    assert [sc.index(n) for n in ("g", "n0", "n1", "b0")] == [6, 7, 8, 0] and sc.bodies["n1"].mass == 2.0
    assert "n1" not in sim.bodies and sim.bodies["b3"].mass == 4.0
    later = lv.Scene()                                           # a look-up before any index: built from the names
    later.add_bodies(["a", "b"], [1.0, 2.0], np.ones((2, 3)))
    later.add_body(lv.Body("c", 3.0, (1.0, 1.0, 1.0)))          # (its duplicate check builds it)
    assert [later.index(n) for n in "abc"] == [0, 1, 2]
    back = pickle.loads(pickle.dumps(sc))
    assert list(back.bodies) == list(sc.bodies) and back.index("n1") == 8


@pytest.mark.parametrize("given", [(), ("q",), ("q", "omega_b"), ("p_w", "v_w"), ("p_w", "q", "v_w", "omega_w")])
def test_add_bodies_keeps_only_the_given_state_blocks_and_reads_as_the_bodies_one_by_one(given):
    """The scene keeps an add_bodies call's state blocks that were given (a default block, zeros or the identity q,
    is not stored: 56 of 104 B per body at 1e6 bodies given q and omega_b, issue 30); each Body's x0, the scene's
    tables and a Sim's state are bitwise those of the same bodies added one by one."""
    rng = np.random.default_rng(3)
    n = 5
    kw = {"p_w": rng.normal(size=(n, 3)), "q": rng.normal(size=(n, 4)), "v_w": rng.normal(size=(n, 3)),
          "omega_b": rng.normal(size=(n, 3)), "omega_w": rng.normal(size=(n, 3))}
    kw = {k: kw[k] for k in given}
    names, m, I = [f"b{i}" for i in range(n)], rng.uniform(1, 2, n), rng.uniform(1.0, 1.5, (n, 3))
    batch, loop = lv.Scene(), lv.Scene()
    batch.add_bodies(names, m, I, **kw)
    for i in range(n):
        loop.add_body(lv.Body(names[i], m[i], I[i], **{k: v[i] for k, v in kw.items()}))
    states = batch._bodies._c["batches"][0][1]
    assert len(states.blocks) == len(given)
    for name in names:
        x0 = batch.bodies[name].x0
        assert np.array_equal(x0, loop.bodies[name].x0) and not x0.flags.writeable
        assert batch.bodies[name] is batch.bodies[name]
    assert np.array_equal(batch.tables().state, loop.tables().state)
    sb, sl = lv.Sim(batch, dt=1e-2), lv.Sim(loop, dt=1e-2)
    sb.run(20)
    sl.run(20)
    assert np.array_equal(sb.x, sl.x)


def test_a_scene_wide_effect_then_add_bodies_refuses_the_first_overflowing_row_as_add_body_does():
    sc = lv.Scene()
    sc.add_body(lv.Body("a", 1.0, (1.0, 1.0, 1.0)))
    sc.add_effect("gravity", g_w=[0.0, 0.0, -1e299])
    masses = [1.0, 2.0, 50.0, 60.0]                            # |F| = m g: 5e300 is the first beyond 1e300
    with pytest.raises(LavenderInputError) as many:
        sc.add_bodies(["p", "q", "r", "s"], masses, [[1.0, 1.0, 1.0]] * 4)
    with pytest.raises(LavenderInputError) as one:
        sc.add_body(lv.Body("r", 50.0, (1.0, 1.0, 1.0)))
    assert many.value.field == "names[2]" and one.value.rule in many.value.rule
    assert list(sc.bodies) == ["a"]


def test_plain_scenes_keep_long_chunks_at_a_million_bodies_scale_and_results_do_not_change():
    """Plain effect-free bodies on C keep CHUNK_MIN_STEPS_C-step chunks up to CHUNK_WORK_MAX_PLAIN evaluations (the
    SIMD tiles: 256 steps at 1e6 bodies), plain bodies with effects up to CHUNK_WORK_MAX_EFFECTS; a scene with wheels
    or a joint takes as many within CHUNK_WORK_MAX; the chunk edges change nothing."""
    n = 140_000                                       # 4 n * 64 > CHUNK_WORK_MAX: the old cap shortens the chunk
    assert sim_mod.chunk_steps(4 * n, True) == sim_mod.CHUNK_WORK_MAX // (4 * n) == 59
    assert sim_mod.chunk_steps(4 * n, True, sim_mod.CHUNK_WORK_MAX_PLAIN) == sim_mod.CHUNK_MIN_STEPS
    assert (sim_mod.chunk_steps(4 * n, True, sim_mod.CHUNK_WORK_MAX_PLAIN, sim_mod.CHUNK_MIN_STEPS_C)
            == sim_mod.CHUNK_MIN_STEPS_C == 256)
    assert sim_mod.chunk_steps(4 * 10**6, True, sim_mod.CHUNK_WORK_MAX_PLAIN, sim_mod.CHUNK_MIN_STEPS_C) == 256
    plain = lv.Sim(_plain(n), dt=1e-3, integrator="rk4", backend="c")
    assert plain._chunk == sim_mod.CHUNK_MIN_STEPS_C
    heavy = _plain(n)
    heavy.add_effect("gravity", g_w=[0.0, 0.0, -9.81])
    assert lv.Sim(heavy, dt=1e-3, integrator="rk4", backend="c")._chunk == sim_mod.CHUNK_MIN_STEPS_C
    assert sim_mod.chunk_steps(4 * 10**6, True, sim_mod.CHUNK_WORK_MAX_EFFECTS, sim_mod.CHUNK_MIN_STEPS_C) == 67
    wheeled = _three_kinds_scene(n)
    assert lv.Sim(wheeled, dt=1e-3, integrator="rk4", backend="c")._chunk == 59
    short = lv.Sim(_plain(n), dt=1e-3, integrator="rk4", backend="c")
    object.__setattr__(short, "_chunk", 8)
    plain.run(300)                                    # one chunk and part of a second
    short.run(300)
    assert np.array_equal(plain.x, short.x) and plain.steps == short.steps == 300


# ---- the checks' reference values, block by block (peak memory at 1e6 bodies) ------------------------------

def _three_kinds_scene(n):
    """n bodies: every third one under an applied torque, every fifth with wheels, the others free."""
    rng = np.random.default_rng(3)
    sc = lv.Scene()
    sc.add_bodies([f"b{i}" for i in range(n)], 1.0 + rng.random(n), 0.03 + 0.01 * rng.random((n, 3)),
                  omega_b=rng.normal(size=(n, 3)), v_w=rng.normal(size=(n, 3)))
    sc.add_effects("applied_torque", bodies=[f"b{i}" for i in range(0, n, 3)], torque_w=[0.0, 0.0, 1e-3])
    sc.add_effects("reaction_wheels", bodies=[f"b{i}" for i in range(1, n, 5)], J=[1e-4] * 3, torque_limit=0.1,
                   speed_limit=100.0)
    return sc


def test_the_checks_reference_values_do_not_depend_on_the_block_size(monkeypatch):
    """Sim._invariants and _safe_rates run their kernels CHECK_BLOCK bodies at a time; blocks of 7 (partly
    selected, wholly selected and empty ones) give bitwise the values of one block."""
    sc = _three_kinds_scene(60)
    one = lv.Sim(sc, dt=1e-3)
    monkeypatch.setattr(sim_mod, "CHECK_BLOCK", 7)
    blocks = lv.Sim(sc, dt=1e-3)
    assert one._free.sum() > 20 and not one._free.all()
    for name in ("_E0", "_L0", "_w_safe", "_g_fast"):
        np.testing.assert_array_equal(getattr(blocks, name), getattr(one, name), err_msg=name)
    assert np.isfinite(one._g_fast[one._free]).all() and (one._E0[one._free] > 0).all()
    for s in (one, blocks):
        s.run(50)
    np.testing.assert_array_equal(blocks.x, one.x)


def test_a_plain_bodys_model_row_is_never_written():
    """A plain body's model row stays all zeros (kind 0, ignored by the steppers); a wheeled body's holds its
    inertia diag(I_b) and its wheels."""
    sc = _three_kinds_scene(20)
    s = lv.Sim(sc, dt=1e-3)
    rows, wheeled = s.model.rows, s.model.wheel_counts > 0
    assert not rows[~wheeled].any()
    I_p = rows[wheeled][:, LY.MODEL_I_P].reshape(-1, 3, 3)
    np.testing.assert_array_equal(I_p, np.stack([np.diag(d) for d in s.params[wheeled][:, LY.PARAM_I_B]]))
