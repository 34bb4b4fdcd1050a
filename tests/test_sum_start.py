"""Every sum of effect contributions starts at IEEE's additive identity -0.0 (derive/effect_fuse.py SUM_START,
printed as kernels.h LV_SUM_START and effects_meta.SUM_START): -0 + x == x bitwise for every x, ±0 included, so a
sum is its terms' sum alone and a sum of nothing (or of -0 terms) is -0. The C and NumPy backends must agree on the
sign of every zero, which np.array_equal does not see: here states are compared byte for byte (tobytes), over every
right-hand-side kind (free, constant force / torque / both, state-reading force, body-frame torque with and without a
force, a coupled force, bodies without effects beside forced ones), every fixed-step integrator, the scalar path and
the SIMD tiles (n = 5 and 67, every instruction set), float32, and model bodies (joint, wheels). Bodies start with
signed zeros in p_w, v_w and omega_b (-0 and +0), and the effects hold -0 components, so each sum's start shows.
(_lavender_c is built by `pip install`; the suite needs the C backend.)"""
from __future__ import annotations

import numpy as np
import pytest

import lavendersim as lv
from lavendersim import _lavender_c as C
from lavendersim import effects as E
from lavendersim.backends import INTEGRATORS
from lavendersim.backends import numpy_scalar as SC
from lavendersim.generated import layout as LY

TABLES = {
    "free": [],
    "gravity (a -0 component)": [("gravity", {"g_w": (-0.0, 0.0, -9.81)})],
    "applied torque": [("applied_torque", {"torque_w": (-0.0, 0.0, 0.3)})],
    "gravity + torque": [("gravity", {"g_w": (-0.0, 0.0, -9.81)}), ("applied_torque", {"torque_w": (0.0, -0.0, 0.3)})],
    "linear damping": [("linear_damping", {"c": 0.1})],
    "angular damping (body frame)": [("angular_damping", {"c": 0.1})],
    "angular damping + gravity": [("angular_damping", {"c": 0.1}), ("gravity", {"g_w": (-0.0, 0.0, -9.81)})],
    "force at a point (coupled)": [("force_at_point", {"r_b": (0.1, -0.0, 0.0), "F_w": (-0.0, 0.0, 0.5)})],
    "torque + angular damping": [("applied_torque", {"torque_w": (-0.0, 0.0, 0.3)}), ("angular_damping", {"c": 0.1})],
}
FIXED = [k for k, stages in INTEGRATORS.items() if stages is not None]


def _scene(n: int, table: str, per_body: bool) -> lv.Scene:
    """n boxes; every third at rest in v_w and omega_b's first components with signed zeros (-0, +0) and p_w (-0, +0,
    z). per_body: the effects on every other body only (the rest have none, beside forced bodies)."""
    rng = np.random.default_rng(n)
    s = lv.Scene()
    for i in range(n):
        zero = i % 3 == 0
        s.add_body(lv.Body.box(f"b{i}", 1.0 + rng.random(), tuple(0.1 + rng.random(3)),
                               p_w=(-0.0, 0.0, rng.standard_normal()) if zero else tuple(rng.standard_normal(3)),
                               q=tuple(rng.standard_normal(4)),
                               v_w=(-0.0, 0.0, rng.standard_normal()) if zero else tuple(rng.standard_normal(3)),
                               omega_b=(-0.0, 0.0, 2.0) if zero else tuple(rng.standard_normal(3))))
    for name, params in TABLES[table]:
        if per_body:
            for i in range(0, n, 2):
                s.add_effect(name, body=f"b{i}", **params)
        else:
            s.add_effect(name, **params)
    return s


def _run(s: lv.Scene, backend: str, integrator: str, dtype: str = "float64", steps: int = 40) -> np.ndarray:
    sim = lv.Sim(s, dt=1e-3, integrator=integrator, backend=backend, dtype=dtype)
    sim.run(steps)
    return np.array(sim.x)


def test_the_start_is_the_additive_identity():
    assert E.SUM_START == 0.0 and np.signbit(E.SUM_START)
    x = np.array([0.0, -0.0, 1.5, -2.25, np.inf, -np.inf, 5e-324, -5e-324])
    assert (E.SUM_START + x).tobytes() == x.tobytes()         # -0 + x is x, the zeros' signs included
    assert not np.signbit(0.0 + x[1])                         # the old start: +0 + -0 = +0


@pytest.mark.parametrize("per_body", [False, True])
@pytest.mark.parametrize("n", [5, 67])
@pytest.mark.parametrize("table", list(TABLES))
def test_c_and_numpy_agree_on_every_sign_of_zero(monkeypatch, table, n, per_body):
    """Byte for byte (signed zeros included), C at every instruction set against NumPy (its vectorized sums and,
    n = 5, its scalar path too), for every fixed-step integrator."""
    s = _scene(n, table, per_body)
    for integrator in FIXED:
        ref = _run(s, "numpy", integrator)
        if n == 5:
            monkeypatch.setattr(SC, "SCALAR_MAX_BODIES", 0)            # the vectorized NumPy path as well
            assert _run(s, "numpy", integrator).tobytes() == ref.tobytes(), (integrator, "vectorized")
            monkeypatch.undo()
        try:
            for level in range(C.isa(-1)[2] + 1):
                C.isa(level)
                got = _run(s, "c", integrator)
                assert got.tobytes() == ref.tobytes(), (integrator, C.isa()[1],
                                                        np.argwhere(np.signbit(got) != np.signbit(ref))[:4])
        finally:
            C.isa(-1)


@pytest.mark.parametrize("table", ["gravity (a -0 component)", "gravity + torque", "angular damping + gravity"])
@pytest.mark.parametrize("integrator", ["rk4", "euler", "semi_implicit_euler"])
def test_a_minus_zero_force_keeps_a_minus_zero_velocity(table, integrator):
    """gravity's x force is m times -0 = -0; summed from -0 it stays -0 (from +0 it was +0), so a body whose v_w's x
    is -0 keeps it, on both backends (its p_w's x -0 too: p + h v with v = -0)."""
    s = _scene(67, table, per_body=False)
    for backend in ("numpy", "c"):
        x = _run(s, backend, integrator)
        assert np.signbit(x[::3, LY.STATE_V_W.start]).all(), backend
        assert (x[::3, LY.STATE_V_W.start] == 0.0).all(), backend


@pytest.mark.parametrize("table", ["free", "gravity (a -0 component)", "gravity + torque", "linear damping",
                                   "angular damping + gravity"])
@pytest.mark.parametrize("integrator", ["rk4", "euler", "semi_implicit_euler"])
def test_float32_agrees_on_every_sign_of_zero(table, integrator):
    """float32 (csrc/fixed_loop.h, its sums from (float)LV_SUM_START = -0.0f) against NumPy's float32, byte for byte."""
    for n in (5, 67):
        s = _scene(n, table, per_body=n == 5)
        assert _run(s, "c", integrator, "float32").tobytes() == _run(s, "numpy", integrator, "float32").tobytes()


def _cubes(n: int, effects: bool) -> lv.Scene:
    """n jointed cubes with three reaction wheels and n free wheeled cubes (model bodies: csrc/model_simd.h's tiles
    and step.c's model_rhs_of), at rest in omega_b's first component (-0); with scene-wide effects or none."""
    rng = np.random.default_rng(n)
    s = lv.Scene()
    wheels = dict(J=[1.0e-4, 1.2e-4, 0.9e-4], torque_limit=0.2, speed_limit=300.0, c_w=1e-5)
    for i in range(2 * n):
        q = rng.standard_normal(4)
        joint = i < n
        s.add_body(lv.Body.box(f"c{i}", mass=0.5 + rng.random(), size=(0.1, 0.12, 0.15),
                               p_w=(-0.0, 0.0, 0.1), q=tuple(q / np.linalg.norm(q)),
                               omega_b=(-0.0, 0.0, 2.0 * rng.standard_normal()),
                               v_w=(0.0, 0.0, 0.0) if joint else (-0.0, 0.0, 0.5)))
        if joint:
            s.add_effect("spherical_joint", body=f"c{i}", anchor_w=list(0.05 * rng.standard_normal(3)))
        s.add_effect("reaction_wheels", body=f"c{i}", **wheels)
    if effects:
        s.add_effect("gravity", g_w=(-0.0, 0.0, -9.81))
        s.add_effect("angular_damping", c=0.05)
    return s


@pytest.mark.parametrize("effects", [False, True])
@pytest.mark.parametrize("n", [3, 40])
def test_model_bodies_agree_on_every_sign_of_zero(n, effects):
    s = _cubes(n, effects)
    for integrator in ("rk4", "euler"):
        ref = _run(s, "numpy", integrator)
        try:
            for level in range(C.isa(-1)[2] + 1):
                C.isa(level)
                assert _run(s, "c", integrator).tobytes() == ref.tobytes(), (integrator, C.isa()[1])
        finally:
            C.isa(-1)
