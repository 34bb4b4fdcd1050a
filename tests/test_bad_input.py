"""Every public entry point rejects bad input with an error naming the field; nothing is half-applied."""
import numpy as np
import pytest

import lavendersim as lv
from lavendersim import LavenderInputError as E


def one_body_scene():
    s = lv.Scene()
    s.add_body(lv.Body.box("cube", 1.0, (0.2, 0.2, 0.2)))
    return s


@pytest.mark.parametrize("kwargs,field", [
    (dict(mass=0.0, inertia=[1, 1, 1]), "mass"),
    (dict(mass=-1.0, inertia=[1, 1, 1]), "mass"),
    (dict(mass=float("nan"), inertia=[1, 1, 1]), "mass"),
    (dict(mass=1.0, inertia=[1, 1, 3]), "inertia"),          # triangle inequality
    (dict(mass=1.0, inertia=[[1, 0.5, 0], [0, 1, 0], [0, 0, 1]]), "inertia"),   # not symmetric
    (dict(mass=1.0, inertia=[[1, 2, 0], [2, 1, 0], [0, 0, 1]]), "inertia"),     # not positive definite
    (dict(mass=1.0, inertia=[1, 1]), "inertia"),            # wrong shape
    (dict(mass=1.0, inertia=[1, 1, 1], q=[0, 0, 0, 0]), "q"),
    (dict(mass=1.0, inertia=[1, 1, 1], q=[0, 0, np.nan, 1]), "q"),
    (dict(mass=1.0, inertia=[1, 1, 1], omega_b=[0, np.inf, 0]), "omega_b"),
    (dict(mass=1.0, inertia=[1, 1, 1], p_w=[0, 0]), "p_w"),
    (dict(mass=1.0, inertia=[1, 1, 1], omega_b=[0, 0, 1], omega_w=[0, 0, 1]), "omega_w"),
])
def test_body_rejects(kwargs, field):
    with pytest.raises(E) as e:
        lv.Body("b", **kwargs)
    assert e.value.field == field
    assert str(e.value).startswith(field)


def test_box_rejects_non_positive_size():
    with pytest.raises(E, match=r"size\[1\]"):
        lv.Body.box("b", 1.0, (1, 0, 1))


@pytest.mark.parametrize("kwargs,field", [
    (dict(dt=0.0), "dt"), (dict(dt=-1e-3), "dt"), (dict(dt=float("nan")), "dt"),
    (dict(integrator="rk5"), "integrator"), (dict(backend="gpu"), "backend"), (dict(normalize="yes"), "normalize"),
])
def test_sim_rejects(kwargs, field):
    with pytest.raises(E) as e:
        lv.Sim(one_body_scene(), **{"backend": "numpy", **kwargs})
    assert e.value.field == field


def test_unknown_effect_name_lists_the_known_ones():
    s = one_body_scene()
    with pytest.raises(E, match="gravity") as e:
        s.add_effect("gravty")
    assert e.value.field == "effect" and s.effects == []


@pytest.mark.parametrize("name,params,field", [
    ("applied_torque", {"torque_w": [0, 0]}, "applied_torque.torque_w"),
    ("applied_torque", {"torque_w": [0, 0, np.nan]}, "applied_torque.torque_w"),
    ("applied_torque", {}, "applied_torque.torque_w"),
    ("applied_torque", {"torque_w": [0, 0, 1], "tork": 1}, "applied_torque.tork"),
    ("force_at_point", {"r_b": [1, 0, 0], "F_w": "up"}, "force_at_point.F_w"),
    ("linear_damping", {"c": -0.1}, "linear_damping.c"),
    ("angular_damping", {"c": np.inf}, "angular_damping.c"),
    ("gravity", {"g_w": [0, 0, -9.81], "body": "nobody"}, "gravity.body"),
])
def test_effect_parameters_are_validated_and_nothing_is_added(name, params, field):
    s = one_body_scene()
    params = dict(params)
    body = params.pop("body", None)
    with pytest.raises(E) as e:
        s.add_effect(name, body=body, **params)
    assert e.value.field == field
    assert s.effects == []


def test_duplicate_body_name_is_rejected_and_scene_unchanged():
    s = one_body_scene()
    with pytest.raises(E, match="duplicate"):
        s.add_body(lv.Body.sphere("cube", 1.0, 0.1))
    assert len(s.bodies) == 1 and s.bodies["cube"].shape[0] == "box"


def test_empty_scene_cannot_be_simulated():
    with pytest.raises(E, match="at least one body"):
        lv.Sim(lv.Scene(), backend="numpy")


def test_set_state_validates_everything_before_changing_anything():
    sim = lv.Sim(one_body_scene(), backend="numpy")
    before = sim.x.copy()
    with pytest.raises(E) as e:
        sim.set_state("cube", p_w=[1, 2, 3], omega_b=[0, np.nan, 0])
    assert e.value.field == "omega_b"
    assert np.array_equal(sim.x, before)
    with pytest.raises(E, match="unknown body"):
        sim.set_state("ball", p_w=[1, 2, 3])


@pytest.mark.parametrize("call,field", [
    (lambda sim: sim.run(-1), "n_steps"), (lambda sim: sim.run(1.5), "n_steps"),
    (lambda sim: sim.record(10, every=3), "every"), (lambda sim: sim.state("nobody"), "body"),
])
def test_sim_calls_reject(call, field):
    sim = lv.Sim(one_body_scene(), backend="numpy")
    with pytest.raises(E) as e:
        call(sim)
    assert e.value.field == field
    assert sim.steps == 0
