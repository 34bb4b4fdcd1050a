"""Issue 11: a Scene's bodies are added through add_body only (validated there); scene.bodies is a
read-only view."""
from __future__ import annotations

import numpy as np
import pytest

import lavendersim as lv
from lavendersim.generated import layout as LY


def test_scene_bodies_is_a_read_only_view():
    s = lv.Scene()
    a = s.add_body(lv.Body("a", 1.0, (1.0, 2.0, 3.0)))
    with pytest.raises(TypeError):
        s.bodies["b"] = lv.Body("b", 1.0, (1.0, 1.0, 1.0))
    with pytest.raises(TypeError):
        del s.bodies["a"]
    with pytest.raises(AttributeError):
        s.bodies.clear()
    assert list(s.bodies) == ["a"] and s.bodies["a"] is a
    s.add_body(lv.Body("b", 1.0, (1.0, 1.0, 1.0)))
    assert list(s.bodies) == ["a", "b"]            # the view follows add_body
    lv.Sim(s, dt=0.01).run(2)


@pytest.mark.parametrize("field, value, named", [
    ("mass", -5.0, "mass"), ("mass", float("nan"), "mass"),
    ("I_b", np.array([1.0, 1.0, 50.0]), "I_b"), ("I_b", np.array([1.0, 0.0, 1.0]), "I_b"),
    ("x0", "q (2, 0, 0, 0)", "x0"),
])
def test_a_body_changed_past_its_immutability_is_refused_by_the_sim(field, value, named):
    """Body refuses setattr; object.__setattr__ gets past it, so the Sim re-checks the stacked arrays."""
    s = lv.Scene()
    s.add_body(lv.Body("ok", 1.0, (1.0, 2.0, 2.5)))
    b = s.add_body(lv.Body("b", 1.0, (1.0, 2.0, 2.5)))
    if field == "x0":                   # the same state with a quaternion of norm 2
        value = b.x0.copy()
        value[LY.STATE_Q] = (2.0, 0.0, 0.0, 0.0)
    object.__setattr__(b, field, value)
    with pytest.raises(lv.LavenderInputError, match=rf"scene\.bodies\['b'\]\.{named}: .*changed after validation"):
        lv.Sim(s, dt=0.01)
