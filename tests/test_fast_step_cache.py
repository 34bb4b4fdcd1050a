"""The Stepper (csrc/fast_step.c) keeps what lv_simulate decides from the effect table and the model rows — the effect
index and the fixed-step loops' order of the bodies — from call to call (step.h lv_model_cache; plain scenes too since
session 25, issue 30: a chunk of a large scene pays no malloc or index build). Kept, they must give the states a
call that builds them gives: bitwise the NumPy backend's, across chunks, instruction-set changes between chunks (the
model tiles reorder their part of the kept order in place) and parameter changes."""
from __future__ import annotations

import numpy as np
import pytest

import lavendersim as lv
from lavendersim import _lavender_c as C

WHEELS = dict(J=[1.0e-4, 1.2e-4, 0.9e-4], torque_limit=0.2, speed_limit=300.0, c_w=1e-5)


@pytest.fixture
def best_isa_after():
    yield C.isa(-1)[2]
    C.isa(-1)


def _scene(seed: int) -> lv.Scene:
    """20 jointed wheel cubes (one model-tile group), 2 free wheeled bodies, and plain bodies of every path: free,
    gravity (scene-wide: every body), an applied torque each, damping."""
    rng = np.random.default_rng(seed)
    sc = lv.Scene()
    for i in range(22):
        s = 0.1 + 0.1 * rng.random()
        q = rng.standard_normal(4)
        sc.add_body(lv.Body.box(f"c{i}", 0.5 + rng.random(), (s, s, s), q=tuple(q / np.linalg.norm(q)),
                                omega_b=tuple(2.0 * rng.standard_normal(3))))
        if i < 20:
            sc.add_effect("spherical_joint", body=f"c{i}", anchor_w=list(0.05 * rng.standard_normal(3)))
        sc.add_effect("reaction_wheels", body=f"c{i}", cutoff=float(i % 2), **WHEELS)
    for i in range(40):
        sc.add_body(lv.Body.box(f"p{i}", 1.0 + rng.random(), (0.1, 0.2, 0.3), omega_b=tuple(rng.standard_normal(3)),
                                v_w=tuple(rng.standard_normal(3))))
        if i % 3 == 1:
            sc.add_effect("applied_torque", body=f"p{i}", torque_w=list(1e-3 * rng.standard_normal(3)))
        elif i % 3 == 2:
            sc.add_effect("linear_damping", body=f"p{i}", c=0.2)
    sc.add_effect("gravity", g_w=[0.0, 0.0, -9.81])
    return sc


def _plain_scene(n: int, seed: int) -> lv.Scene:
    rng = np.random.default_rng(seed)
    sc = lv.Scene()
    names = [f"b{i}" for i in range(n)]
    sc.add_bodies(names, 1.0 + rng.random(n), np.tile([0.0333, 0.1133, 0.1333], (n, 1)),
                  omega_b=rng.standard_normal((n, 3)), v_w=rng.standard_normal((n, 3)))
    sc.add_effects("applied_torque", names[::2], torque_w=1e-3 * rng.standard_normal((len(names[::2]), 3)))
    sc.add_effect("linear_damping", body=names[-1], c=0.3)
    return sc


def test_kept_order_across_chunks_and_instruction_sets_is_bitwise_numpy(best_isa_after):
    sc = _scene(11)
    c = lv.Sim(sc, dt=1e-3, backend="c")
    ref = lv.Sim(sc, dt=1e-3, backend="numpy")
    assert c.model.advance is not None   # the Stepper: its cache keeps the index and the order
    for k, level in enumerate([best_isa_after, 0, best_isa_after, best_isa_after, 0]):
        C.isa(level)
        c.run(7 + k)
        ref.run(7 + k)
        np.testing.assert_array_equal(c.x, ref.x)
        np.testing.assert_array_equal(c.model.Omega, ref.model.Omega)


def test_kept_index_reads_the_parameters_as_they_are():
    """set_effect_params rewrites an effect's parameters in the table: the kept index (same codes and bodies) reads
    the new values, as a rebuilt one would."""
    sc = _plain_scene(70, 5)
    sims = [lv.Sim(sc, dt=1e-3, backend=b) for b in ("c", "numpy")]
    eff = [e for e in sims[0].model.effects if e.name == "applied_torque"][3]
    for sim in sims:
        sim.run(40)
    for sim in sims:
        sim.set_effect_params(eff, torque_w=[0.5, -0.25, 0.125])
        sim.run(40)
    np.testing.assert_array_equal(sims[0].x, sims[1].x)
    # and the change acted: a Sim without it differs
    other = lv.Sim(sc, dt=1e-3, backend="c")
    other.run(80)
    assert not np.array_equal(other.x, sims[0].x)


@pytest.mark.parametrize("n", [1, 17, 300])
def test_plain_scenes_keep_their_index_bitwise(n):
    sc = _plain_scene(n, n)
    c, ref = lv.Sim(sc, dt=1e-3, backend="c"), lv.Sim(sc, dt=1e-3, backend="numpy")
    for steps in (1, 64, 3, 300):
        c.run(steps)
        ref.run(steps)
    np.testing.assert_array_equal(c.x, ref.x)


def test_a_large_scene_keeps_its_index_in_the_sims_cache():
    """Beyond FAST_STEP_WORK a Sim has no Stepper: its chunks go through CBackend.advance with the Sim's own
    call_cache; bitwise the NumPy backend's over chunks of every length."""
    sc = _plain_scene(2000, 9)
    c, ref = lv.Sim(sc, dt=1e-3, backend="c"), lv.Sim(sc, dt=1e-3, backend="numpy")
    assert c.model.advance is None and c._c_cache is not None
    for steps in (1, 5, 300):
        c.run(steps)
        ref.run(steps)
    np.testing.assert_array_equal(c.x, ref.x)


def test_a_kept_index_follows_the_table_rewritten_in_place():
    """The cache keeps an index while the table's rows keep their codes and bodies (step.c index_kept): a table
    rewritten in place with other bodies is indexed again, so a call with the cache steps what a call without it
    steps."""
    from lavendersim.backends import c_backend

    be = c_backend.CBackend()
    n = 40
    scenes = []
    for first in (0, 1):   # the same rows, on the even / the odd bodies
        names = [f"b{i}" for i in range(first, n, 2)]
        sc = lv.Scene()
        sc.add_bodies([f"b{i}" for i in range(n)], np.full(n, 1.5), np.tile([0.05, 0.1, 0.12], (n, 1)),
                      omega_b=np.random.default_rng(1).standard_normal((n, 3)))
        sc.add_effects("applied_torque", names, torque_w=np.full((len(names), 3), 1e-2))
        scenes.append(lv.Sim(sc, backend="c"))
    tables = [s._effects.copy() for s in scenes]
    assert tables[0].shape == tables[1].shape and not np.array_equal(tables[0], tables[1])
    params = scenes[0]._params
    out = []
    for cache in (c_backend.call_cache(n, False), None):
        x = scenes[0]._x.copy()
        table = tables[0].copy()
        be.advance(x, params, table, "rk4", True, 1e-3, 50, cache=cache)
        table[...] = tables[1]    # the same array, other bodies
        be.advance(x, params, table, "rk4", True, 1e-3, 50, cache=cache)
        out.append(x)
    np.testing.assert_array_equal(out[0], out[1])
