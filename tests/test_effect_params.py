"""Effects are immutable once validated; a force effect's parameters change between steps only through
Sim.set_effect_params (validated, all or nothing, seen by both backends)."""
from __future__ import annotations

import copy
import pickle

import numpy as np
import pytest

import lavendersim as lv
from lavendersim.effects import ImmutableEffectError

I_SAT = np.array([[0.2, 0.004, -0.002], [0.004, 0.25, 0.003], [-0.002, 0.003, 0.08]])


def _scene(I=(0.1, 0.2, 0.3)):
    sc = lv.Scene()
    sc.add_body(lv.Body("b", 2.0, I, omega_b=[0.1, -0.2, 0.3]))
    torque = sc.add_effect("applied_torque", body="b", torque_w=[0.0, 0.0, 0.0])
    push = sc.add_effect("force_at_point", body="b", r_b=[0.1, 0.0, 0.0], F_w=[0.0, 0.0, 0.0])
    return sc, torque, push


def test_assigning_to_an_effect_raises_naming_the_field():
    _, torque, _ = _scene()
    with pytest.raises(ImmutableEffectError, match=r"^applied_torque\.torque_w: an effect is immutable") as ei:
        torque.torque_w = [1.0, 2.0, 3.0]
    assert isinstance(ei.value, lv.LavenderInputError) and isinstance(ei.value, AttributeError)
    with pytest.raises(ImmutableEffectError, match=r"applied_torque\.body"):
        torque.body = "other"
    with pytest.raises(TypeError):
        torque.values["torque_w"] = np.ones(3)        # a read-only mapping
    with pytest.raises(ValueError):
        torque.values["torque_w"][0] = 1.0            # of read-only arrays
    np.testing.assert_array_equal(torque.torque_w, [0.0, 0.0, 0.0])   # reading a parameter by name works
    assert copy.deepcopy(torque) is torque
    again = pickle.loads(pickle.dumps(torque))
    assert again.name == "applied_torque" and np.array_equal(again.torque_w, torque.torque_w)


@pytest.mark.parametrize("backend", ["numpy", "c"])
def test_set_effect_params_changes_the_steps_that_follow(backend):
    """Changing the torque and the force between two runs equals a Sim built with the new values from then on."""
    sc, torque, push = _scene()
    sim = lv.Sim(sc, dt=1e-3, backend=backend)
    sim.run(100)
    mid = sim.state("b")
    torque = sim.set_effect_params(torque, torque_w=[0.0, 0.01, 0.02])
    sim.set_effect_params(push, F_w=[0.5, 0.0, 0.0])
    sim.run(200)
    ref_scene = lv.Scene()
    ref_scene.add_body(lv.Body("b", 2.0, (0.1, 0.2, 0.3), p_w=mid.p_w, q=mid.q, v_w=mid.v_w, omega_b=mid.omega_b))
    ref_scene.add_effect("applied_torque", body="b", torque_w=[0.0, 0.01, 0.02])
    ref_scene.add_effect("force_at_point", body="b", r_b=[0.1, 0.0, 0.0], F_w=[0.5, 0.0, 0.0])
    ref = lv.Sim(ref_scene, dt=1e-3, backend=backend)
    ref.run(200)
    np.testing.assert_allclose(sim.state("b").x, ref.state("b").x, rtol=0, atol=1e-15)
    assert np.array_equal(torque.torque_w, [0.0, 0.01, 0.02])
    assert any("torque_w=[0. 0.01 0.02]" in line for line in sim.pipeline)   # what runs shows the new values


def test_both_backends_see_the_change_alike():
    out = []
    for backend in ("numpy", "c"):
        sc, torque, _ = _scene()
        sim = lv.Sim(sc, dt=1e-3, backend=backend)
        for k in range(5):
            torque = sim.set_effect_params(torque, torque_w=[0.001 * k, -0.002 * k, 0.0])
            sim.run(20)
        out.append(sim.state("b").x)
    np.testing.assert_allclose(out[0], out[1], rtol=0, atol=1e-14)


def test_a_body_frame_parameter_is_in_the_users_frame_for_a_full_tensor():
    """r_b of a full-tensor body given in its own axes: the same torque as computed by hand, (R_wb r_b) × F."""
    sc = lv.Scene()
    sc.add_body(lv.Body("sat", 12.0, I_SAT, q=[0.1, 0.2, 0.3, 0.9]))
    push = sc.add_effect("force_at_point", body="sat", r_b=[0.0, 0.0, 0.0], F_w=[0.0, 0.0, 0.0])
    sim = lv.Sim(sc, dt=1e-4)
    r_b, F_w = np.array([0.1, -0.05, 0.2]), np.array([0.0, 0.3, -0.1])
    sim.set_effect_params(push, r_b=r_b, F_w=F_w)
    s0 = sim.state("sat")
    L0 = sim.angular_momentum_w("sat")
    sim.step()
    tau_w = np.cross(s0.R_wb @ r_b, F_w)
    np.testing.assert_allclose((sim.angular_momentum_w("sat") - L0) / 1e-4, tau_w, rtol=1e-9, atol=1e-12)


def test_bad_calls_change_nothing():
    sc, torque, push = _scene()
    sc.add_effect("reaction_wheels", body="b", J=[1e-4] * 3, torque_limit=0.1, speed_limit=100.0)
    sim = lv.Sim(sc, dt=1e-3)
    before = sim.effects.copy()
    for kwargs, field in (({"torque_w": [np.nan, 0, 0]}, "applied_torque.torque_w"),
                          ({"torque_w": [1.0, 2.0]}, "applied_torque.torque_w"),
                          ({"tourque_w": [1.0, 2.0, 3.0]}, "applied_torque.tourque_w"),
                          ({"torque_w": [1e308, 1e308, 0.0]}, "applied_torque.torque_w")):
        with pytest.raises(lv.LavenderInputError) as ei:
            sim.set_effect_params(torque, **kwargs)
        assert ei.value.field == field
    wheels = sc.model_effects("b")["reaction_wheels"]
    with pytest.raises(lv.LavenderInputError, match="model effect"):
        sim.set_effect_params(wheels, torque_limit=1.0)
    other, t2, _ = _scene()
    with pytest.raises(lv.LavenderInputError, match="not a force effect of this Sim"):
        sim.set_effect_params(t2, torque_w=[0.0, 0.0, 1.0])
    assert np.array_equal(sim.effects, before)
