"""Issue 13: the wheel motor's torque–speed line (wheel_motor, derived in derive/integrator_physics.py
and printed for C, NumPy and CasADi), the hard cut-off only as the explicit reaction_wheels
cutoff=1, and viscous wheel friction c_w."""
from __future__ import annotations

import numpy as np
import pytest

import lavendersim as lv
from conftest import NUMPY_SLOW
from lavendersim.kernels import K
from lavendersim.validate import LavenderInputError

BACKENDS = ("c", "numpy")
TL, SL = 0.2, 400.0


def line(cmd, Om, tl=TL, sl=SL):
    """Independent formula: clip to ±stall; driving faster, at most stall (1 − |Ω|/Ω0) (≥ 0)."""
    u = np.clip(cmd, -tl, tl)
    avail = tl * np.maximum(0.0, 1 - np.abs(Om) / sl)
    return np.where(u * Om > 0, np.sign(u) * np.minimum(np.abs(u), avail), u)


def cube(cutoff=0.0, c_w=0.0):
    s = lv.Scene()
    s.add_body(lv.Body.box("cube", 1.0, (0.15, 0.15, 0.15)))
    s.add_effect("spherical_joint", body="cube", anchor_w=(0, 0, 0))
    s.add_effect("reaction_wheels", body="cube", J=[5.7e-4] * 3, torque_limit=TL, speed_limit=SL, c_w=c_w, cutoff=cutoff)
    return s


def test_kernel_is_the_line_and_cutoff_1_is_the_old_saturation():
    rng = np.random.default_rng(3)
    cmd = rng.uniform(-0.5, 0.5, (2000, 3))
    Om = rng.uniform(-600, 600, (2000, 3))
    Om[:10] = [[0, 400, -400]] * 10
    np.testing.assert_allclose(K.wheel_motor(cmd, Om, TL, SL, 0.0), line(cmd, Om), rtol=0, atol=1e-15)
    np.testing.assert_array_equal(K.wheel_motor(cmd, Om, TL, SL, 1.0), K.wheel_saturation(cmd, Om, TL, SL))


@pytest.mark.needs("control")
def test_casadi_printing_matches_numpy():
    import casadi as ca
    from lavendersim.generated import kernels_casadi as KC

    rng = np.random.default_rng(4)
    for _ in range(50):
        c, W = rng.uniform(-0.5, 0.5, 3), rng.uniform(-500, 500, 3)
        for cut in (0.0, 1.0):
            got = np.asarray(ca.DM(KC.wheel_motor(ca.DM(c), ca.DM(W), TL, SL, cut))).ravel()
            np.testing.assert_allclose(got, K.wheel_motor(c, W, TL, SL, cut), rtol=0, atol=1e-15)


@pytest.mark.parametrize("backend", BACKENDS)
def test_sim_applies_the_line(backend):
    sim = lv.Sim(cube(), dt=1e-3, backend=backend)
    for Om, cmd in (([100, -200, 399], [0.5, -0.5, 0.5]), ([100, -200, 500], [-0.5, 0.5, -0.05]),
                    ([0, 450, -100], [0.05, 0.1, -0.3])):
        sim.set_state("cube", Omega=Om)
        sim.set_wheel_command("cube", cmd)
        sim.step()
        np.testing.assert_allclose(sim.wheel_command_applied("cube"), line(np.array(cmd), np.array(Om, float)),
                                   rtol=0, atol=1e-15)


@pytest.mark.parametrize("backend", NUMPY_SLOW)   # NumPy: 20-45 s when loaded; in the slow set
def test_driving_from_rest_is_smooth_and_stays_below_no_load_speed(backend):
    """Full command for 3 s: the applied torque falls smoothly (no 0 ↔ 0.2 flips), the wheel speed
    rises monotonically toward but below 400 rad/s; with cutoff=1 the old flipping is still there."""
    for cutoff in (0.0, 1.0):
        sim = lv.Sim(cube(cutoff), dt=1e-3, backend=backend)
        sim.set_wheel_command("cube", [0.5, 0, 0])
        u, W = [], []
        for _ in range(3000):
            sim.step()
            u.append(sim.wheel_command_applied("cube")[0])
            W.append(sim.wheel_rates("cube")[0])
        u, W = np.array(u), np.array(W)
        if cutoff == 0.0:
            assert np.all(np.diff(W) > 0) and W[-1] < SL and W[-1] > 0.9 * SL
            assert np.max(np.abs(np.diff(u))) < 1e-3
        else:
            assert W.max() >= SL and np.max(np.abs(np.diff(u))) == pytest.approx(TL)


@pytest.mark.parametrize("backend", NUMPY_SLOW)   # NumPy: 20-45 s when loaded; in the slow set
def test_viscous_friction_with_the_line_settles_below_no_load(backend):
    """With c_w the steady wheel speed solves stall (1 − Ω/Ω0) = c_w Ω: Ω* = stall / (stall/Ω0 + c_w)."""
    c_w = 2e-4
    sim = lv.Sim(cube(c_w=c_w), dt=2e-3, backend=backend)
    sim.set_wheel_command("cube", [0.5, 0, 0])
    sim.run(10000)  # 20 s: many time constants
    W_star = TL / (TL / SL + c_w)
    # the cube counter-rotates and keeps no torque: its rate goes to zero (a body on a joint at the centre)
    assert sim.wheel_rates("cube")[0] == pytest.approx(W_star, rel=1e-3)


def test_cutoff_must_be_0_or_1():
    with pytest.raises(LavenderInputError) as e:
        cube(cutoff=0.5)
    assert e.value.field == "reaction_wheels.cutoff"
