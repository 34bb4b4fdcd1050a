"""Issue 13: reaction wheels on N spin axes inside Sim (``reaction_wheels(axes_b=..., J=...)``).

Every layout is stepped by the one wheel model, the printed wheels<WHEELS_MAX> kernels (kind KIND_WHEELS),
unused slots padded; the default layout is A_b = [I | 0]. Checked here: a permuted body-axis layout against
the default one (same physics, permuted arithmetic: within rounding), C against NumPy, momentum conservation and exchange
with damping off, validation of the declaration, and the wheel
arrays' shapes as a user reads them. The scene linearization of a pyramid is in test_linearize.py; the
30° pyramid slew (lavendersim.wheel_layout, now stepped by Sim) in test_wheel_layout.py.
"""
from __future__ import annotations

import numpy as np
import pytest

import lavendersim as lv
from lavendersim import wheel_layout as WL
from lavendersim.backends import KIND_WHEELS, on_body_axes
from lavendersim.generated import layout as LY
from lavendersim.validate import LavenderInputError

BACKENDS = ("c", "numpy")
WHEELS = dict(torque_limit=0.2, speed_limit=400.0)


def pyramid_scene(c_w=0.0, joint=False, gravity=False):
    s = lv.Scene()
    s.add_body(lv.Body.box("sc", 1.0, (0.15, 0.15, 0.15), p_w=(0.0, 0.0, 0.3), q=(0.1, -0.2, 0.05, 0.97),
                           omega_b=(0.3, -0.2, 0.5)))
    s.add_effect("reaction_wheels", body="sc", axes_b=WL.pyramid_axes().T, J=(5e-4, 5.5e-4, 6e-4, 6.5e-4), c_w=c_w,
                 **WHEELS)
    if joint:
        s.add_effect("spherical_joint", body="sc", anchor_w=(0.0, 0.0, 0.0))
    if gravity:
        s.add_effect("gravity", body="sc")
    return s


def test_a_layout_gets_the_axes_kernel_and_n_wheel_arrays():
    sim = lv.Sim(pyramid_scene(), dt=1e-3, backend="numpy")
    assert int(sim._models.rows[0, LY.MODEL_KIND]) == KIND_WHEELS and not on_body_axes(sim._models.rows[0])
    assert sim.wheel_rates("sc").shape == (4,) and sim.state("sc").Omega.shape == (4,)
    assert any("rotation and wheels: wheels4_body_rhs;" in line and "wheels: 4 on axes_b" in line for line in sim.pipeline)
    sim.set_wheel_command("sc", [0.1, -0.1, 0.05, 0.0])
    with pytest.raises(LavenderInputError, match="u"):
        sim.set_wheel_command("sc", [0.1, -0.1, 0.05])          # four wheels take four commands
    sim.run(5)
    assert np.all(sim.wheel_command_applied("sc")[:3] != 0)
    e = pyramid_scene().effects[0]
    assert e.params_flat().size == 4 + 12 + 4 and "axes_b=[[" in e.describe()   # a matrix parameter flattens
    tr = sim.record(4, every=2)
    assert tr.Omega.shape == (3, 1, LY.WHEELS_MAX) and tr.body("sc").Omega.shape == (3, 4)
    np.testing.assert_array_equal(tr.body("sc").Omega[-1], sim.wheel_rates("sc"))
    # the default layout: the same wheel model on A_b = [I | 0], its arrays three wide
    cube = lv.Scene()
    cube.add_body(lv.Body.box("c", 1.0, (0.15, 0.15, 0.15)))
    cube.add_effect("reaction_wheels", body="c", J=(5e-4, 5e-4, 5e-4), **WHEELS)
    sc = lv.Sim(cube, dt=1e-3, backend="numpy")
    assert int(sc._models.rows[0, LY.MODEL_KIND]) == KIND_WHEELS and sc.wheel_rates("c").shape == (3,)
    assert on_body_axes(sc._models.rows[0]) and any("wheels: 3 on the body axes" in line for line in sc.pipeline)
    np.testing.assert_array_equal(sc._models.A_b[0], np.eye(3, LY.WHEELS_MAX))


@pytest.mark.parametrize("n", [1, 2, 3, 4])
def test_any_count_up_to_wheels_max_conserves_momentum_with_damping_off(n):
    """No external torque, damping off, spinning body, every wheel driven: total world L constant (RK4
    truncation only) and ΔL_body = −ΔL_wheels, for every N ≤ WHEELS_MAX (the padded slots stay at rest)."""
    rng = np.random.default_rng(n)
    A = rng.normal(size=(n, 3))
    A /= np.linalg.norm(A, axis=1, keepdims=True)
    s = lv.Scene()
    s.add_body(lv.Body.box("b", 1.0, (0.15, 0.2, 0.25), omega_b=(0.3, -0.2, 0.5)))
    s.add_effect("reaction_wheels", body="b", axes_b=A, J=np.full(n, 4e-4), **WHEELS)
    sim = lv.Sim(s, dt=2.5e-4, integrator="rk4")
    Lb0, Lw0 = sim.wheel_momentum_w("b")
    worst_x, worst_L, scale = 0.0, 0.0, 0.0
    for k in range(40):
        sim.set_wheel_command("b", 0.05 * np.sin(0.5 * k + np.arange(n)))
        sim.run(200)
        Lb, Lw = sim.wheel_momentum_w("b")
        worst_x = max(worst_x, float(np.linalg.norm((Lb - Lb0) + (Lw - Lw0))))
        worst_L = max(worst_L, float(np.linalg.norm(Lb + Lw - Lb0 - Lw0)))
        scale = max(scale, float(np.linalg.norm(Lw - Lw0)))
    assert scale > 1e-3                                   # the wheels really exchanged momentum
    assert worst_x / scale <= 1e-9 and worst_L / np.linalg.norm(Lb0 + Lw0) <= 1e-9
    assert np.all(sim._models.Omega[0, n:] == 0.0)        # the padded slots never moved


def test_permuted_body_axes_match_the_default_layout():
    """Three wheels on body y, x, z (a permutation) against the default body-axis layout with J and commands
    permuted alike: the same physics with the wheel sums in another order, equal to rounding after 2 s with a
    joint and gravity."""
    perm = [1, 0, 2]
    J, u = np.array([4e-4, 5e-4, 6e-4]), np.array([0.02, -0.03, 0.01])
    runs = {}
    for name, axes in (("body", None), ("axes", np.eye(3)[perm])):
        s = lv.Scene()
        s.add_body(lv.Body.box("b", 1.2, (0.1, 0.15, 0.2), p_w=(0.0, 0.1, 0.2), q=(0.2, 0.0, 0.0, 0.98),
                               omega_b=(0.2, 0.1, -0.3)))
        s.add_effect("spherical_joint", body="b", anchor_w=(0.0, 0.0, 0.0))
        s.add_effect("gravity", body="b")
        kw = {} if axes is None else {"axes_b": axes}
        s.add_effect("reaction_wheels", body="b", J=J if axes is None else J[perm], c_w=1e-5, **kw, **WHEELS)
        sim = lv.Sim(s, dt=1e-3, integrator="rk4", backend="c")
        assert on_body_axes(sim._models.rows[0]) == (axes is None)
        sim.set_state("b", Omega=np.array([30.0, -20.0, 10.0]) if axes is None else np.array([30.0, -20.0, 10.0])[perm])
        sim.set_wheel_command("b", u if axes is None else u[perm])
        sim.run(2000)
        st = sim.state("b")
        runs[name] = np.concatenate([st.x, st.Omega if axes is None else st.Omega[np.argsort(perm)]])
    np.testing.assert_allclose(runs["axes"], runs["body"], rtol=0, atol=1e-11)


@pytest.mark.parametrize("integrator", ["euler", "semi_implicit_euler", "rk4", "dopri5"])
def test_c_and_numpy_agree_on_a_jointed_pyramid(integrator):
    out = {}
    for backend in BACKENDS:
        sim = lv.Sim(pyramid_scene(c_w=1e-4, joint=True, gravity=True), dt=1e-3, integrator=integrator, backend=backend)
        sim.set_state("sc", Omega=(40.0, -30.0, 20.0, 5.0))
        sim.set_wheel_command("sc", (0.05, -0.02, 0.01, 0.03))
        sim.run(300)
        out[backend] = (sim.x.copy(), sim.wheel_rates("sc"), sim.wheel_command_applied("sc"))
    for a, b in zip(out["c"], out["numpy"]):
        np.testing.assert_allclose(a, b, rtol=1e-12, atol=1e-12)


@pytest.mark.parametrize("params, field, rule", [
    ({"axes_b": [[1, 0, 0], [0, 1, 0]], "J": [1e-4, 1e-4, 1e-4]}, "reaction_wheels.J", "one inertia per wheel axis"),
    ({"axes_b": [[1, 0, 0], [0, 2, 0], [0, 0, 1]], "J": [1e-4] * 3}, "reaction_wheels.axes_b", "unit vector"),
    ({"axes_b": np.eye(5, 3), "J": [1e-4] * 4}, "reaction_wheels.axes_b", "1 to 4"),
    ({"axes_b": np.eye(3), "J": [1e-4] * 5}, "reaction_wheels.J", "1 to 4"),
    ({"axes_b": [[1, 0, 0, 0]], "J": [1e-4]}, "reaction_wheels.axes_b", "shape"),
    ({"axes_b": [[1, 0, 0], [1, 0, 0]], "J": [0.004, 0.004]}, "reaction_wheels.J", "positive definite"),
    ({"axes_b": [[0, 0, 1]], "J": [-1e-4]}, "reaction_wheels.J", ">"),
])
def test_bad_layouts_are_refused_naming_the_field(params, field, rule):
    s = lv.Scene()
    s.add_body(lv.Body.box("b", 1.0, (0.15, 0.15, 0.15)))
    with pytest.raises(LavenderInputError, match=rule) as info:
        s.add_effect("reaction_wheels", body="b", **params, **WHEELS)
    assert info.value.field == field
    assert not s.effects                                  # nothing half-applied
