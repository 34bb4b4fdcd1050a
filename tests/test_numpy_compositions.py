"""Issue 29: the NumPy backend's one composition engine walks the printed programs (generated/tableaux.py
COMPOSITIONS, derive/tableaux.py compositions()), as the C engine does; no composition is written by hand."""
from __future__ import annotations

import inspect

import numpy as np
import pytest

import lavendersim as lv
from lavendersim.backends import numpy_backend as NB
from lavendersim.generated import tableaux as T
from lavendersim.kernels import K

COMPOSITIONS = [n for n, f in T.INTEGRATOR_FAMILY.items() if f == "composition"]
# rows of mixed symmetric-top splits: three (a, b) axis pairs, and symmetric tops (c_b = 0) among them
INERTIAS = [(1.0, 2.0, 3.0), (3.0, 2.0, 1.5), (2.0, 3.0, 1.5), tuple(K.inertia_box(1.0, 0.8, 0.2, 0.2)),
            (2.0, 1.0, 1.0), (1.2, 1.5, 2.5)]


def _scene(effects=False, only=None):
    """INERTIAS' bodies (or body only alone), b0 under gravity and b1 damped with effects."""
    rng = np.random.default_rng(3)
    scene = lv.Scene()
    for i, I_b in enumerate(INERTIAS):
        w, v = rng.normal(size=3) * 2, rng.normal(size=3)
        if only in (None, i):
            scene.add_body(lv.Body(f"b{i}", 1.5, I_b, omega_b=w, v_w=v))
    if effects and only in (None, 0):
        scene.add_effect("gravity", g_w=(0.0, 0.0, -9.81), body="b0")
    if effects and only in (None, 1):
        scene.add_effect("angular_damping", c=0.2, body="b1")
    return scene


def test_every_composition_is_its_printed_program():
    """Each composition's stepper walks COMPOSITIONS[name]; the module names no per-integrator table or stepper."""
    assert set(NB._PROGRAMS) == set(COMPOSITIONS) == set(T.COMPOSITIONS)
    src = inspect.getsource(NB)
    for word in ("SPLIT4_SEQ", "SPLIT4_GAMMA", "SYMTOP4_", "BM6_", "SYMTOP_STRANG_A"):
        assert word not in src, word
    for name in COMPOSITIONS:
        assert not hasattr(NB, f"_step_{name}"), name
        assert NB._PROGRAMS[name][0] == T.COMPOSITIONS[name][0]


@pytest.mark.parametrize("name", COMPOSITIONS)
def test_grouped_rows_equal_each_body_alone(name):
    """Bodies of different symmetric-top splits step together (grouped by their axes) to the same doubles as
    each body alone (one group), free and under loads."""
    for effects in (False, True):
        sim = lv.Sim(_scene(effects), dt=0.02, integrator=name, backend="numpy")
        sim.run(15)
        for i in range(len(INERTIAS)):
            alone = lv.Sim(_scene(effects, only=i), dt=0.02, integrator=name, backend="numpy")
            alone.run(15)
            np.testing.assert_array_equal(alone.x[0], sim.x[i], err_msg=f"{name} body {i} effects={effects}")


def test_a_new_composition_of_existing_flows_is_data_only():
    """A program declared as data runs on the engine: splitting's Strang rotation written as its five principal
    axis flows on L_b (momentum ... rate) steps as splitting does (to rounding: other arithmetic)."""
    axes = tuple((f"axis_{'xyz'[a]}", f) for a, f in T.STRANG)
    rot = (("momentum", 0.0),) + axes + (("rate", 0.0),)
    kicked = (("kick", 0.5), ("drift", 1.0)) + rot + (("kick", 0.5),)
    NB._PROGRAMS["h7_axes"] = NB._program((1.0,), kicked, (("drift", 1.0),) + rot)
    try:
        for effects in (False, True):
            sim = lv.Sim(_scene(effects), dt=0.01, integrator="splitting", backend="numpy")
            plan = NB.NumpyBackend().plan(sim._params, sim._effects)
            x = sim.x.copy()
            a = NB._composition(plan, x, 0.01, "splitting")
            b = NB._composition(plan, x, 0.01, "h7_axes")
            assert not np.array_equal(a, x)
            np.testing.assert_allclose(b, a, rtol=0, atol=1e-14)
    finally:
        del NB._PROGRAMS["h7_axes"]
