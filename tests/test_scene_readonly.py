"""Issue 11: a Scene's bodies are added through add_body only (validated there); scene.bodies is a
read-only view."""
from __future__ import annotations

import pytest

import lavendersim as lv


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
