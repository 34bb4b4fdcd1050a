"""Issue 13: linearize any scene (python-control StateSpace from the derived CasADi kernels), checked
against finite differences of the simulator's own step; lqr/dlqr conventions; closed_loop with a
callable controller and the response object.

Tolerances (finite_difference: central differences h = 1e-5 of one Euler step, Richardson in dt from
1e-4): relative to max(1, max |entry|), A ≤ 1e-5 and B ≤ 1e-7 — measured 5e-7 / 4e-9 (free body,
float rounding of p_w ~ 3 m over h·dt), 2e-9 / 7e-10 (pivoted body), 3e-7 / 6e-9 (wheel cube off
equilibrium, wheels at 40 rad/s). The user-declared effect (docs/extending.md's set):
tests/test_extending.py::test_linearize_a_scene_with_user_effects. A dropped gyroscopic, gravity or
wheel term is O(1e-2..1e1) there.
"""
from __future__ import annotations

import numpy as np
import pytest

import lavendersim as lv
from lavendersim import control as lc
from lavendersim.validate import LavenderInputError

pytestmark = pytest.mark.needs("control")

A_REL, B_REL = 1e-5, 1e-7
BACKENDS = ("c", "numpy")


def free_scene():
    s = lv.Scene()
    s.add_body(lv.Body.box("b", 2.0, (0.4, 0.3, 0.2), p_w=(1, 2, 3), q=(0.1, 0.2, 0.3, 0.9), v_w=(0.5, -0.2, 0.1),
                           omega_b=(0.3, -0.2, 0.5)))
    s.add_effect("applied_torque", body="b", torque_w=(0.01, -0.02, 0.03))
    s.add_effect("gravity", body="b", g_w=(0, 0, -9.81))
    s.add_effect("angular_damping", body="b", c=0.01)
    return s


def pivot_scene(torque=(0.0, 0.0, 0.0)):
    s = lv.Scene()
    s.add_body(lv.Body.box("p", 1.0, (0.1, 0.1, 0.5), p_w=(0, 0.1, 0.2), q=(0.2, 0, 0, 0.98), omega_b=(0.2, 0.1, -0.3)))
    s.add_effect("spherical_joint", body="p", anchor_w=(0, 0, 0))
    s.add_effect("gravity", body="p", g_w=(0, 0, -9.81))
    s.add_effect("applied_torque", body="p", torque_w=torque)
    return s


def check(lin, scene, backend):
    A, B = lc.finite_difference(lin, scene, backend=backend)
    res = lc.linearization_residual(lin, A, B)
    assert res["A_rel"] <= A_REL and res["B_rel"] <= B_REL, res
    return res


@pytest.mark.parametrize("backend", BACKENDS)
def test_free_body_with_applied_torque(backend):
    s = free_scene()
    lin = lc.linearize(s, inputs=["applied_torque.torque_w"])
    assert (lin.nstates, lin.ninputs) == (12, 3)
    assert lin.state_labels[:4] == ["b_p_x", "b_p_y", "b_p_z", "b_dtheta_x"]
    assert lin.input_labels == ["applied_torque_torque_w_0", "applied_torque_torque_w_1", "applied_torque_torque_w_2"]
    assert lin.rank == 6   # a torque cannot move the COM: p, v uncontrollable
    np.testing.assert_allclose(lin.u0, [0.01, -0.02, 0.03])
    check(lin, s, backend)


@pytest.mark.parametrize("backend", BACKENDS)
def test_pivoted_body_under_gravity(backend):
    s = pivot_scene()
    lin = lc.linearize(s, inputs=["applied_torque.torque_w"])
    assert lin.nstates == 6 and lin.controllable
    assert lin.equilibrium_residual > 1   # tilted and spinning: not an equilibrium, still linearized
    check(lin, s, backend)


@pytest.mark.parametrize("backend", BACKENDS)
def test_wheel_cube_off_equilibrium(backend):
    s = lc.chapter_cube("corner", damping=2e-3, wheel_damping=1e-4, q=lc.rotated(lc.cube_upright_q("corner"), [1, 0, 0], 5.0),
                        omega_b=(0.1, -0.2, 0.05))
    sim = lv.Sim(s, backend=backend)
    sim.set_state(lc.BODY, Omega=(40.0, -25.0, 10.0))
    sim.set_wheel_command(lc.BODY, (0.01, -0.02, 0.005))
    lin = lc.linearize(sim)
    assert lin.input_labels == ["cube_u_x", "cube_u_y", "cube_u_z"] and lin.nstates == 9
    np.testing.assert_allclose(lin.u0, [0.01, -0.02, 0.005])
    check(lin, s, backend)


@pytest.mark.parametrize("backend", BACKENDS)
@pytest.mark.parametrize("joint", [False, True])
def test_pyramid_layout_off_equilibrium(backend, joint):
    """Four wheels on a pyramid (reaction_wheels axes_b: the Sim's N-axis kernel), spinning, commanded, with
    gravity on a pivot or free: the linearization (wheels4 CasADi kernels, padding stripped) against finite
    differences of the Sim's own step."""
    from lavendersim import wheel_layout as WL

    s = lv.Scene()
    s.add_body(lv.Body.box("sc", 1.0, (0.15, 0.15, 0.15), p_w=(0, 0.1, 0.2), q=(0.1, -0.2, 0.05, 0.97),
                           omega_b=(0.3, -0.2, 0.5)))
    s.add_effect("reaction_wheels", body="sc", axes_b=WL.pyramid_axes().T, J=(5e-4, 5.5e-4, 6e-4, 6.5e-4),
                 torque_limit=0.2, speed_limit=400.0, c_w=1e-4)
    s.add_effect("gravity", body="sc")
    if joint:
        s.add_effect("spherical_joint", body="sc", anchor_w=(0, 0, 0))
    sim = lv.Sim(s, backend=backend)
    sim.set_state("sc", Omega=(40.0, -25.0, 10.0, 60.0))
    sim.set_wheel_command("sc", (0.01, -0.02, 0.005, 0.03))
    lin = lc.linearize(sim)
    assert lin.input_labels == ["sc_u_1", "sc_u_2", "sc_u_3", "sc_u_4"]
    assert lin.nstates == (6 if joint else 12) + 4 and lin.state_labels[-4:] == [f"sc_Omega_{k}" for k in (1, 2, 3, 4)]
    np.testing.assert_allclose(lin.u0, [0.01, -0.02, 0.005, 0.03])
    check(lin, s, backend)


def test_bad_inputs_name_the_field():
    s = pivot_scene()
    for kw, field in (({"inputs": ["nope.x"]}, "inputs"), ({"inputs": ["applied_torque.nope"]}, "inputs"),
                      ({"inputs": ["p.u"]}, "inputs"), ({"outputs": ["p_dtheta_q"]}, "outputs"),
                      ({"x0": {"q": 1}}, "x0"), ({"x0": {"p": {"p_w": (1, 2, 3)}}}, "x0['p'].p_w"),
                      ({"inputs": ["applied_torque.torque_w"], "u0": {"x.y": 1}}, "u0")):
        with pytest.raises(LavenderInputError) as e:
            lc.linearize(s, **kw)
        assert e.value.field == field, (kw, e.value)


def test_outputs_and_discrete():
    s = pivot_scene()
    lin = lc.linearize(s, inputs=["applied_torque.torque_w"], outputs=["p_dtheta_x", "p_omega_z"])
    assert lin.C.shape == (2, 6) and lin.output_labels == ["p_dtheta_x", "p_omega_z"]
    d = lc.linearize(s, inputs=["applied_torque.torque_w"], dt=0.01)
    import control as ct

    ref = ct.c2d(ct.ss(lin.A, lin.B, np.eye(6), 0), 0.01, "zoh")
    assert d.dt == 0.01 and d.state_labels == lin.state_labels
    np.testing.assert_allclose(d.A, ref.A, rtol=1e-12, atol=1e-14)
    np.testing.assert_allclose(d.B, ref.B, rtol=1e-12, atol=1e-14)


# ------------------------------------------------------------------------ lqr / dlqr


def test_ct_lqr_and_ours_agree_on_a_controllable_system():
    import control as ct

    lin = lc.linearize(pivot_scene(), inputs=["applied_torque.torque_w"])
    assert lin.controllable
    Q, R = np.diag([100, 100, 100, 1, 1, 1.0]), np.eye(3) * 10
    K, S, E = lc.lqr(lin, Q, R)
    K2, S2, E2 = ct.lqr(lin, Q, R)
    np.testing.assert_allclose(K, K2, rtol=1e-9, atol=1e-12)
    np.testing.assert_allclose(S, S2, rtol=1e-9, atol=1e-12)
    np.testing.assert_allclose(np.sort_complex(E), np.sort_complex(E2), rtol=1e-8)
    Kd, Sd, _ = lc.dlqr(lin.sample(0.01), Q, R)
    Kd2, Sd2, _ = ct.dlqr(lin.sample(0.01), Q, R)
    np.testing.assert_allclose(Kd, Kd2, rtol=1e-9, atol=1e-12)


def test_uncontrollable_directions_are_reported():
    m = lc.chapter_cube("center")
    W = lc.default_weights(m)
    res = lc.lqr(lc.linearize(m), *W)
    assert res.rank == 6 and not res.controllable and res.uncontrollable.shape == (9, 3)
    # they are the body momentum I ω + J Ω (I = m s²/6 of the 15 cm, 1 kg cube; J = 5.7e-4 kg·m²)
    H = np.hstack([np.zeros((3, 3)), 0.15 ** 2 / 6 * np.eye(3), 5.7e-4 * np.eye(3)])
    assert np.linalg.matrix_rank(np.hstack([res.uncontrollable, H.T / np.linalg.norm(H)]), tol=1e-9) == 3
    dres = lc.dlqr(lc.linearize(m, dt=0.01), *W)
    assert dres.rank == 6 and np.sum(np.abs(np.abs(dres.E) - 1) < 1e-9) == 3
    with pytest.raises(LavenderInputError, match="dlqr"):
        lc.lqr(lc.linearize(m, dt=0.01), *W)
    with pytest.raises(LavenderInputError):
        lc.dlqr(lc.linearize(m), *W)


def test_dlqr_closed_loop_is_stable_in_the_nonlinear_sim():
    """Corner balancing (open-loop unstable, poles at ±~19 1/s) at a 20 ms zero-order hold: the dlqr
    gain of the ZOH model (control.design) settles the 3° tilt below 0.1° and stays within the motor limits."""
    scene = lc.chapter_cube("corner")
    ctrl = lc.design(scene, period=0.02, q_ref=lc.cube_upright_q("corner"), weights={"attitude_deg": 0.5})
    assert np.all(np.abs(ctrl.poles) < 1)
    q0 = lc.rotated(ctrl.q_ref, lc.CORNER_AXIS, 3.0)
    r = lc.closed_loop(scene, ctrl, T=4.0, q0=q0, backend="c")
    assert r.settling_time(0.1) < 1.0 and r.final_error_deg < 0.05
    assert r.within_limits


def test_python_control_operations_work_on_a_linearization():
    """What linearize returns is a StateSpace python-control accepts as is: feedback (python-control's, not
    overridden), lqr on a controllable subsystem, series/parallel, sample."""
    import control as ct

    scene = lc.chapter_cube("center")
    lin = lc.linearize(scene)
    K = np.asarray(lc.lqr(lin, *lc.default_weights(scene)).K)
    cl = ct.feedback(lin, ct.ss([], [], [], K), sign=-1)            # u = −K y, y = x (C = I)
    assert isinstance(cl, ct.StateSpace) and cl.nstates == 9
    np.testing.assert_allclose(cl.A, lin.A - lin.B @ K, rtol=0, atol=1e-12 * np.abs(lin.A - lin.B @ K).max())
    assert ct.feedback(lin, K).nstates == 9                           # a plain gain matrix too
    # lqr on the controllable subsystem (an orthonormal basis T of it: ct.lqr needs a stabilizable pair)
    T = lin.basis
    sub = ct.ss(T.T @ lin.A @ T, T.T @ lin.B, np.eye(T.shape[1]), 0)
    Kc, _, E = ct.lqr(sub, np.eye(T.shape[1]), np.eye(3))
    assert np.all(np.real(E) < 0)
    ser = ct.series(lin, ct.ss([], [], [], np.ones((1, 9))))          # y = sum of the states
    par = ct.parallel(lin, lin)
    assert ser.noutputs == 1 and par.nstates == 18
    d = lin.sample(0.01)
    assert d.dt == 0.01 and isinstance(d, type(lin)) and d.state_labels == lin.state_labels
    np.testing.assert_allclose(d.A, ct.c2d(ct.ss(lin.A, lin.B, lin.C, lin.D), 0.01).A, rtol=1e-12, atol=1e-15)
