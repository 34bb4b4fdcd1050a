"""Issue 30: Scene.add_effects declares one effect on many bodies as ONE batch (its columns, not n Effect
objects); scene.effects still reads as the per-body Effects, built when read. The batch builds the Sim the loop
of add_effect builds (bitwise), is validated like any input (a bad row: the field named, the scene unchanged),
and edits, pickles, copies, set_effect_params and the scene file all see its effects.

Behaviour only: no timing here (the figures are in the issue's note, measured in CPU time)."""
import copy
import pickle

import numpy as np
import pytest

import lavendersim as lv
from lavendersim import scene_file
from lavendersim.effects import Effect, make
from lavendersim.validate import LavenderInputError


def _scene(n, seed=2, tensor_at=None):
    rng = np.random.default_rng(seed)
    sc = lv.Scene()
    sc.add_bodies([f"b{i}" for i in range(n)], 1.0 + rng.random(n), rng.uniform(1.0, 1.5, (n, 3)),
                  omega_b=rng.normal(size=(n, 3)), p_w=rng.normal(size=(n, 3)))
    if tensor_at is not None:         # one body with a full inertia tensor (stepped in its principal frame)
        I = np.array([[2.0, 0.3, 0.0], [0.3, 1.5, 0.1], [0.0, 0.1, 1.8]])
        sc.add_body(lv.Body("t", 1.0, I, omega_b=(0.1, 0.2, 0.3)))
    return sc


def _names(sc):
    return list(sc.bodies)


def _batch_entries(sc):
    return [e for e in sc.effects.items() if not isinstance(e, Effect)]


def test_one_call_is_one_entry_and_its_effects_are_built_when_read_keeping_their_identity():
    n = 50
    sc = _scene(n)
    tq = np.random.default_rng(1).normal(size=(n, 3)) * 1e-3
    out = sc.add_effects("applied_torque", _names(sc), torque_w=tq)
    assert len(sc.effects.items()) == 1 and len(sc.effects) == n == len(out)
    (batch,) = _batch_entries(sc)
    assert len(batch._made) == 1               # only the first row went through add_effect (the template)
    e7 = sc.effects[7]
    assert isinstance(e7, Effect) and e7.name == "applied_torque" and e7.body == "b7"
    assert np.array_equal(e7.values["torque_w"], tq[7]) and not e7.values["torque_w"].flags.writeable
    assert out[7] is e7 is sc.effects[7] and out[-1] is sc.effects[n - 1] and len(batch._made) == 3
    assert [e.body for e in sc.effects] == _names(sc) and len(batch._made) == n
    # the caller's array stays the caller's: writeable, and a later edit does not reach the scene
    assert tq.flags.writeable
    tq[7] = 99.0
    assert np.array_equal(sc.effects[7].values["torque_w"], sc.tables().effects[7, 2:5])
    assert sc.tables().effects[7, 2] != 99.0


@pytest.mark.parametrize("backend", ["c", "numpy"])
def test_a_batch_with_a_rotated_body_builds_the_sim_the_loop_builds_bitwise(backend):
    """A full-inertia body in a force_at_point batch (r_b is body-frame: its row is rotated) and a wheels batch
    next to a per-body joint: the Sim equals the one add_effect per body builds."""
    n = 12
    rng = np.random.default_rng(4)
    F, r = rng.normal(size=(n + 1, 3)), rng.normal(size=(n + 1, 3)) * 0.1
    J = rng.uniform(1e-4, 5e-4, (n, 3))
    one, many = _scene(n, tensor_at=True), _scene(n, tensor_at=True)
    names = _names(one)
    for i, b in enumerate(names):
        one.add_effect("force_at_point", body=b, F_w=F[i], r_b=r[i])
    for i in range(n):
        one.add_effect("reaction_wheels", body=names[i], J=J[i], torque_limit=0.1, speed_limit=50.0)
    one.add_effect("spherical_joint", body="b2", anchor_w=[0.0, 0.0, 0.0])
    many.add_effects("force_at_point", names, F_w=F, r_b=r)
    many.add_effects("reaction_wheels", names[:n], J=J, torque_limit=0.1, speed_limit=50.0)
    many.add_effect("spherical_joint", body="b2", anchor_w=[0.0, 0.0, 0.0])
    sa, sb = lv.Sim(one, dt=1e-3, backend=backend), lv.Sim(many, dt=1e-3, backend=backend)
    assert np.array_equal(sa.effects, sb.effects) and np.array_equal(sa.model.rows, sb.model.rows)
    assert np.array_equal(sa.x, sb.x) and np.array_equal(sa.model.wheel_counts, sb.model.wheel_counts)
    sa.set_wheel_commands(np.full((n + 1, 3), 1e-3) * (np.arange(n + 1) < n)[:, None])
    sb.set_wheel_commands(np.full((n + 1, 3), 1e-3) * (np.arange(n + 1) < n)[:, None])
    sa.run(40)
    sb.run(40)
    assert np.array_equal(sa.x, sb.x) and np.array_equal(sa.model.Omega, sb.model.Omega)
    assert sa.pipeline == sb.pipeline


@pytest.mark.parametrize("field, make_bad, at", [
    ("applied_torque.torque_w", lambda tq: tq.__setitem__((5, 1), np.inf), 5),
    ("applied_torque.torque_w", lambda tq: tq.__setitem__((9, 0), np.nan), 9),
])
def test_a_bad_row_names_the_field_and_body_and_leaves_the_scene_unchanged(field, make_bad, at):
    n = 20
    sc = _scene(n)
    sc.add_effect("gravity", g_w=[0.0, 0.0, -9.81])
    sc.add_effects("applied_torque", _names(sc)[:4], torque_w=np.zeros((4, 3)))
    before_items, before = list(sc.effects.items()), list(sc.effects)
    tq = np.random.default_rng(0).normal(size=(n, 3))
    make_bad(tq)
    with pytest.raises(LavenderInputError) as err:
        sc.add_effects("applied_torque", _names(sc), torque_w=tq)
    assert err.value.field == field and f"(bodies[{at}] = 'b{at}')" in str(err.value)
    assert sc.effects.items() == before_items and sc.effects == before and len(sc.effects) == 5
    assert len(lv.Sim(sc, dt=1e-3).effects) == 5             # nothing half-applied


def test_bad_shapes_rules_and_names_are_refused_by_field_and_nothing_is_added():
    n = 6
    sc = _scene(n)
    names = _names(sc)
    cases = [
        (dict(torque_w=np.zeros((n, 2))), "applied_torque", "applied_torque.torque_w"),     # (n, 2): not 3-vectors
        (dict(torque_w=np.zeros((n - 1, 3))), "applied_torque", "applied_torque.torque_w"),  # one row short
        (dict(torque_w=[0.0, 0.0, 1.0], thrust=1.0), "applied_torque", "applied_torque.thrust"),
        (dict(J=[1e-4] * 3, torque_limit=0.1, speed_limit=np.r_[np.ones(n - 1), -1.0]), "reaction_wheels",
         "reaction_wheels.speed_limit"),
        (dict(J=[1e-4] * 3, torque_limit=np.r_[0.1, 0.0, np.full(n - 2, 0.1)], speed_limit=1.0), "reaction_wheels",
         "reaction_wheels.torque_limit"),
        (dict(J=np.tile([1e-4, 1e-4, 9.0], (n, 1)), torque_limit=0.1, speed_limit=1.0), "reaction_wheels",
         "reaction_wheels.J"),
    ]
    for params, name, field in cases:
        with pytest.raises(LavenderInputError) as err:
            sc.add_effects(name, names, **params)
        assert err.value.field == field, (params, str(err.value))
        assert len(sc.effects) == 0 and sc.effects.items() == []
    with pytest.raises(LavenderInputError) as err:
        sc.add_effects("applied_torque", "b0", torque_w=[0, 0, 1.0])       # one name, not a sequence of names
    assert err.value.field == "bodies"
    with pytest.raises(LavenderInputError) as err:
        sc.add_effects("applied_torque", ["b0", 3], torque_w=[0, 0, 1.0])
    assert err.value.field == "applied_torque.body" and "(bodies[1] = 3)" in str(err.value)
    assert len(sc.effects) == 0


def test_a_second_batch_on_the_same_bodies_is_refused_for_model_effects_and_allowed_for_forces():
    sc = _scene(5)
    names = _names(sc)
    sc.add_effects("reaction_wheels", names[1:4], J=[1e-4] * 3, torque_limit=0.1, speed_limit=1.0)
    with pytest.raises(LavenderInputError) as err:
        sc.add_effect("reaction_wheels", body="b2", J=[1e-4] * 3, torque_limit=0.1, speed_limit=1.0)
    assert "body 'b2' already has a reaction_wheels" in str(err.value)
    with pytest.raises(LavenderInputError) as err:
        sc.add_effects("reaction_wheels", ["b0", "b3"], J=[1e-4] * 3, torque_limit=0.1, speed_limit=1.0)
    assert "body 'b3' already has a reaction_wheels" in str(err.value) and "(bodies[1] = 'b3')" in str(err.value)
    assert sc.model_effects("b3")["reaction_wheels"] is sc.effects[2] and sc.model_effects("b0") == {}
    sc.add_effects("applied_torque", ["b1", "b1", "b2"], torque_w=np.eye(3) * 1e-3)   # forces may repeat
    assert [e.body for e in sc.effects.forces_on("b1")] == ["b1", "b1"]
    s = lv.Sim(sc, dt=1e-3)
    assert list(s.model.wheel_counts) == [0, 3, 3, 3, 0] and s.model.wheel_counts.dtype == np.int64
    np.testing.assert_array_equal(s.effects[:, 1], [1, 1, 2])


def test_editing_the_list_splits_a_batch_where_the_edit_falls():
    sc = _scene(8)
    names = _names(sc)
    effects = sc.add_effects("applied_torque", names, torque_w=np.arange(24.0).reshape(8, 3) * 1e-3)
    e3, e4 = effects[3], effects[4]
    del sc.effects[3]
    assert [e.body for e in sc.effects] == [n for n in names if n != "b3"] and sc.effects[3] is e4
    sc.effects.insert(1, e3)
    assert [e.body for e in sc.effects][:3] == ["b0", "b3", "b1"]
    other = make("applied_torque", body="b5", torque_w=[0.0, 0.0, 1.0])
    sc.effects[6] = other
    assert sc.effects[6] is other and sc.effects.index(other) == 6 and len(sc.effects) == 8
    sc.effects.remove(e4)
    assert e4 not in list(sc.effects) and len(sc.effects) == 7
    sc.effects.append(e4)
    assert sc.effects[-1] is e4
    t = sc.tables().effects
    np.testing.assert_array_equal(t[:, 1], [sc.index(e.body) for e in sc.effects])
    np.testing.assert_array_equal(t[:, 2:5], np.stack([e.values["torque_w"] for e in sc.effects]))
    del sc.effects[2:5]
    assert len(sc.effects) == 5
    sc.effects.clear()
    assert len(sc.effects) == 0 and sc.effects == []


def test_pickle_deepcopy_and_the_scene_file_keep_a_batch():
    n = 9
    sc = _scene(n)
    names = _names(sc)
    J = np.random.default_rng(2).uniform(1e-4, 5e-4, (n, 3))
    sc.add_effects("reaction_wheels", names, J=J, torque_limit=0.1, speed_limit=50.0)
    sc.add_effects("applied_torque", names[::2], torque_w=np.ones((5, 3)) * 1e-3)
    for other in (pickle.loads(pickle.dumps(sc)), copy.deepcopy(sc)):
        assert len(other.effects.items()) == 2 and [repr(e) for e in other.effects] == [repr(e) for e in sc.effects]
        assert np.array_equal(other.tables().effects, sc.tables().effects)
    back = scene_file.scene_from_dict(scene_file.scene_to_dict(sc))
    assert sorted(map(repr, back.effects)) == sorted(map(repr, sc.effects))
    assert np.array_equal(lv.Sim(back, dt=1e-3).model.rows, lv.Sim(sc, dt=1e-3).model.rows)
    sim = lv.Sim(sc, dt=1e-3)
    sim.set_wheel_commands(np.full((n, 3), 1e-3))
    sim.run(5)
    again = pickle.loads(pickle.dumps(sim))
    sim.run(20)
    again.run(20)
    assert np.array_equal(sim.x, again.x) and np.array_equal(sim.model.Omega, again.model.Omega)
    assert len(again.model.effects) == 2 * n - 4


def test_set_effect_params_on_one_effect_of_a_batch_changes_that_row_only():
    n = 6
    sc = _scene(n)
    effects = sc.add_effects("applied_torque", _names(sc), torque_w=np.zeros((n, 3)))
    sim = lv.Sim(sc, dt=1e-3)
    new = sim.set_effect_params(effects[4], torque_w=[0.0, 0.0, 2e-3])
    expect = np.zeros((n, 3))
    expect[4, 2] = 2e-3
    np.testing.assert_array_equal(sim.effects[:, 2:5], expect)
    assert new in sim.model.effects and effects[4] not in sim.model.effects and effects[3] in sim.model.effects
    newer = sim.set_effect_params(effects[1], torque_w=[1e-3, 0.0, 0.0])   # a second effect of the same batch
    newest = sim.set_effect_params(new, torque_w=[0.0, 0.0, 0.0])          # the one set before
    expect[1, 0], expect[4, 2] = 1e-3, 0.0
    np.testing.assert_array_equal(sim.effects[:, 2:5], expect)
    assert newer in sim.model.effects and newest in sim.model.effects and len(sim.model.effects) == n
    assert sc.effects[4] is effects[4] and not sc.effects[4].values["torque_w"].any()   # the scene unchanged


def test_reinit_body_rewrites_a_batched_wheel_row_as_built():
    n = 4
    sc = _scene(n)
    sc.add_effects("reaction_wheels", _names(sc), J=np.full((n, 3), 2e-4), torque_limit=0.1, speed_limit=50.0)
    sim = lv.Sim(sc, dt=1e-3)
    rows = sim.model.rows.copy()
    sim._models.rows[2] = 0.0
    sim.reinit_body(2, np.zeros(3), np.array([0.0, 0.0, 0.0, 1.0]), np.array([0.1, 0.0, 0.0]), np.zeros(3))
    np.testing.assert_array_equal(sim.model.rows, rows)


def test_an_unpickled_batch_is_read_only_and_checked_again():
    sc = _scene(4)
    sc.add_effects("applied_torque", _names(sc), torque_w=np.ones((4, 3)) * 1e-3)
    back = pickle.loads(pickle.dumps(sc))
    assert not back.effects[2].values["torque_w"].flags.writeable
    (batch,) = _batch_entries(sc)
    data = pickle.dumps(batch).replace(np.float64(1e-3).tobytes(), np.float64(np.nan).tobytes())   # a column tampered
    with pytest.raises(LavenderInputError) as err:
        pickle.loads(data)
    assert err.value.field == "applied_torque.torque_w"
