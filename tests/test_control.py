"""Control workflow on the chapter's cube (lavendersim.control.chapter_cube, a Scene): the CasADi
linearization checked against the runtime simulator, controllability, LQR, the sampled design
(control.design) and its closed loop in the nonlinear simulator (both backends, and against an
independent RK4 reference stepper), `lavendersim lqr`, and bad parameters. The sampled loop on other
scenes (pyramid, a user's skewed wheels), sensors, delay and lag: tests/test_closed_loop.py."""
from __future__ import annotations

import math
import sys
from types import SimpleNamespace

import numpy as np
import pytest

from lavendersim import control as lc
from lavendersim.validate import LavenderInputError

sys.path.insert(0, __import__("os").path.dirname(__file__))
# The closed loops' NumPy runs are in the slow set (NUMPY_SLOW: tests/conftest.py); the C runs stay,
# and test_closed_loop_matches_an_independent_reference_stepper checks the loop itself quickly.
from conftest import NUMPY_SLOW  # noqa: E402
from wheel_reference import RefSim  # noqa: E402

BACKENDS = ("c", "numpy")

pytestmark = pytest.mark.needs("control")   # casadi + python-control (tests/conftest.py)


def _lin(scenario="center", Omega0=(0, 0, 0), **params):
    scene = lc.chapter_cube(scenario, **params)
    c_w = params.get("wheel_damping", 0.0)
    lin = lc.linearize(scene, {"cube": {"Omega": Omega0}}, {"cube.u": c_w * np.asarray(Omega0, float)}, inputs=["cube.u"])
    return scene, lin


def _design(scenario, **kw):
    """The chapter's design as `lavendersim lqr` makes it: dlqr at 2 ms, attitude weight 2° (centre) or 0.5° (corner)."""
    scene = lc.chapter_cube(scenario)
    ctrl = lc.design(scene, period=2e-3, q_ref=lc.cube_upright_q(scenario),
                     weights={"attitude_deg": 2.0 if scenario == "center" else 0.5}, **kw)
    return scene, ctrl


# ------------------------------------------------------------------------ linearization


@pytest.mark.parametrize("backend", BACKENDS)
@pytest.mark.parametrize("case", [
    ("center", {}, (0, 0, 0)),
    ("center", {"damping": 1e-3}, (50.0, -20.0, 10.0)),   # gyroscopic wheel momentum at the equilibrium
    ("corner", {}, (0, 0, 0)),
    ("corner", {"damping": 2e-3, "mass": 1.3, "J": (5e-4, 6e-4, 7e-4)}, (0, 0, 0)),
])
def test_A_B_match_finite_differences_of_the_simulator(backend, case):
    scenario, params, Om0 = case
    scene, lin = _lin(scenario, Om0, **params)
    # at an equilibrium one Euler step's Jacobian is exact in dt (no extrapolation needed): a 1 ms step keeps the
    # rounding (eps / (h dt)) small, the old finite_difference_AB's settings
    A_fd, B_fd = lc.finite_difference(lin, scene, backend=backend, dt=1e-3, extrapolate=False)
    res = lc.linearization_residual(lin, A_fd, B_fd)
    assert res["A_abs"] <= 1e-6 and res["B_abs"] <= 1e-6, res
    assert res["A_rel"] <= 1e-7 and res["B_rel"] <= 1e-9, res


def test_corner_linearization_is_gravity_stiffness():
    scene, lin = _lin("corner", q=lc.cube_upright_q("corner"))
    # upright: body diagonal vertical, COM straight above the pivot
    d = lc.KN.quat_rotate(lin.q_ref, lc.cube_r_b("corner", 0.15))
    assert np.allclose(d[:2], 0, atol=1e-15) and d[2] > 0
    assert lin.equilibrium_residual < 1e-12
    G = lin.A[3:6, 0:3]
    # rotation about the vertical (body diagonal) meets no gravity stiffness; tilts are unstable
    assert np.max(np.abs(G @ np.ones(3))) < 1e-12
    ev = np.linalg.eigvals(lin.A)
    assert ev.real.max() > 5  # inverted pendulum
    assert np.allclose(lin.A[0:3, 3:6], np.eye(3))


def test_controllability_rank_and_conserved_momentum():
    (_, c), (_, k), (_, d) = _lin("center"), _lin("corner"), _lin("center", damping=1e-3)
    assert (c.rank, k.rank, d.rank) == (6, 8, 6)
    for lin in (c, k, d):
        U = lin.uncontrollable_basis
        # the complement is conserved: Uᵀ A = 0 and Uᵀ B = 0 (momentum the wheels cannot change)
        assert np.max(np.abs(U.T @ lin.A)) < 1e-9 * max(1, np.abs(lin.A).max())
        assert np.max(np.abs(U.T @ lin.B)) < 1e-9 * np.abs(lin.B).max()
    # centre, no damping: the conserved directions are the body momentum I ω + J Ω
    I, J = 1.0 * 0.15 ** 2 / 6, 5.7e-4
    H = np.hstack([np.zeros((3, 3)), I * np.eye(3), J * np.eye(3)])
    assert np.linalg.matrix_rank(np.hstack([c.uncontrollable_basis, H.T / np.linalg.norm(H)]), tol=1e-9) == 3


def test_lqr_gain_and_poles():
    for scenario in lc.SCENARIOS:
        scene, lin = _lin(scenario)
        Q, R = lc.default_weights(scene)
        K, S, E = lc.lqr(lin, Q, R)
        assert K.shape == (3, 9) and S.shape == (9, 9)
        assert np.allclose(S, S.T, atol=1e-9 * np.abs(S).max())
        n_unc = 9 - lin.rank
        # the uncontrollable (conserved) modes stay at 0; every other pole is in the left half-plane
        assert np.sum(np.abs(E) < 1e-9) == n_unc
        assert np.all(E[np.abs(E) >= 1e-9].real < 0)


def test_full_rank_model_goes_straight_to_control_lqr():
    import control as ct

    rng = np.random.default_rng(1)
    A, B = rng.normal(size=(9, 9)), rng.normal(size=(9, 3))
    K2, S2, _ = ct.lqr(A, B, np.eye(9), np.eye(3))
    for args in ((ct.ss(A, B, np.eye(9), 0), np.eye(9), np.eye(3)), ((A, B), np.eye(9), np.eye(3)), (A, B, np.eye(9), np.eye(3))):
        res = lc.lqr(*args)
        K, S, E = res
        assert res.rank == 9 and res.controllable and res.uncontrollable.shape == (9, 0)
        assert np.allclose(K, K2, rtol=1e-10, atol=1e-12) and np.allclose(S, S2, rtol=1e-10, atol=1e-12)


# ------------------------------------------------------------------------ the sampled design and its loop


@pytest.mark.parametrize("scenario, rank", [("center", 6), ("corner", 8)])
def test_design_at_the_controller_rate_is_stable(scenario, rank):
    _, ctrl = _design(scenario)
    assert ctrl.rank == rank and ctrl.L.shape == (3, 9) and ctrl.K.shape == (3, 9)
    assert np.all(np.abs(ctrl.poles) < 1) and ctrl.poles.size == rank
    # the gain is the dlqr of the ZOH model at 2 ms (python-control on the controllable subspace)
    Ad, Bd = ctrl.sys_d
    assert np.allclose(Ad, ctrl.lin.sample(2e-3).A, rtol=0, atol=1e-12)
    K = lc.dlqr((Ad, Bd), ctrl.Q, ctrl.R).K
    assert np.allclose(ctrl.K, K, rtol=1e-8, atol=1e-10 * np.abs(K).max())


@pytest.mark.needs("gym")
@pytest.mark.parametrize("backend", NUMPY_SLOW)
def test_attitude_regulation_reaction_wheel_cube_v0(backend):
    """(a) ReactionWheelCube-v0 (joint at the centre, damping 1e-3) under a controller designed at the
    env's 10 ms period: 20° about (1,2,3) to below 0.1° within 1 s, never beyond the 0.2 N·m limit."""
    import gymnasium as gym

    env = gym.make("lavendersim:ReactionWheelCube-v0", backend=backend).unwrapped
    ctrl = lc.design(env.scene, period=env.control_dt)
    env.reset(seed=0, options={"q": lc.rotated(env.target_q, [1, 2, 3], 20.0)})
    assert env.angle_error_deg() == pytest.approx(20.0, abs=1e-9)
    errs, torques, speeds = [], [], []
    for _ in range(200):  # 2 s at 100 Hz
        st = env.sim.state("cube")
        a = (ctrl.command(st.q, st.omega_b, env.sim.wheel_rates("cube")) / env.torque_limit).astype(np.float32)
        _, _, term, trunc, info = env.step(a)
        assert not term and not trunc
        errs.append(info["angle_error_deg"])
        torques.append(np.abs(info["torque_applied"]).max())
        speeds.append(np.abs(env.sim.wheel_rates("cube")).max())
    errs = np.array(errs)
    t = 0.01 * np.arange(1, errs.size + 1)
    settle = t[np.flatnonzero(errs >= 0.1)[-1] + 1]
    assert settle <= 1.0
    assert errs[-1] < 1e-3
    assert 0.95 * env.torque_limit <= max(torques) <= env.torque_limit   # the start saturates
    assert max(speeds) < env.speed_limit


@pytest.mark.parametrize("backend", NUMPY_SLOW)
def test_corner_balancing(backend):
    """(b) Cubli-like corner balance (15 cm, 1 kg, J = 5.7e-4 kg·m², 0.2 N·m, 400 rad/s) from a
    3° tilt, dlqr at 2 ms: settles below 0.1° (measured 0.162 s) and stays there, within limits."""
    scene, ctrl = _design("corner")
    r = lc.closed_loop(scene, ctrl, T=4.0, q0=lc.rotated(ctrl.q_ref, lc.CORNER_AXIS, 3.0), dt=1e-3, backend=backend)
    tilt0 = math.degrees(math.acos(lc.KN.quat_rotate(r.q[0], np.ones(3) / math.sqrt(3))[2]))
    assert tilt0 == pytest.approx(3.0, abs=1e-9)  # a pure tilt
    assert r.settling_time() <= 0.2
    assert r.final_error_deg < 0.1
    assert r.within_limits and np.all(r.peak_torque <= 0.2) and np.all(r.peak_wheel_speed < 400)
    assert np.max(r.error_deg) < 5.0


def test_closed_loop_matches_an_independent_reference_stepper():
    """The sampled loop in the Sim equals the same controller on RK4 of the generated NumPy kernel
    (tests/wheel_reference.py), sample for sample."""
    scene, ctrl = _design("corner")
    q0 = lc.rotated(ctrl.q_ref, lc.CORNER_AXIS, 3.0)
    a = lc.closed_loop(scene, ctrl, T=1.0, q0=q0, dt=1e-3, backend="c")
    s = 0.15
    m = SimpleNamespace(mass=1.0, g_w=np.array([0, 0, -9.81]), gravity=True, damping=0.0, wheel_damping=0.0, J=np.full(3, 5.7e-4),
                        r_b=lc.cube_r_b("corner", s), torque_limit=0.2, speed_limit=400.0, motor="line",
                        I_p=np.asarray(lc.KN.parallel_axis(np.diag(np.full(3, s * s / 6)), 1.0, -lc.cube_r_b("corner", s))).reshape(3, 3))
    ref = RefSim(m, q0)
    ctrl.reset()
    err = []
    for k in range(a.t.size):
        err.append(lc.error_angle_deg(ref.q, ctrl.q_ref))
        if k == a.t.size - 1:
            break
        ref.cmd = ctrl.command(ref.q, ref.w, ref.Om)
        ref.run(2)
    assert np.max(np.abs(a.error_deg - np.array(err))) < 1e-9


def test_conserved_momentum_offset_is_absorbed_by_the_wheels():
    """Starting with wheel momentum (H ≠ 0), the target is the equilibrium with that momentum in
    the wheels: the attitude still converges, |L| is kept."""
    scene, ctrl = _design("center")
    r = lc.closed_loop(scene, ctrl, T=3.0, q0=lc.rotated(ctrl.q_ref, [1, 2, 3], 10.0), Omega0=(30.0, -10.0, 5.0),
                       dt=1e-3, backend="c")
    assert r.final_error_deg < 0.01
    assert r.L_drift < 1e-9


def test_controller_is_a_casadi_function_of_the_printed_chart():
    import casadi as ca

    _, ctrl = _design("center")
    f = ctrl.function
    assert isinstance(f, ca.Function) and f.name() == "lv_wheel_controller"
    assert f.name_in() == ["q", "omega_b", "Omega", "q_ref", "z"] and f.name_out() == ["u", "z_next"]
    q = lc.rotated(ctrl.q_ref, [1, -2, 0.5], 0.3)
    w, Om = np.array([0.01, -0.02, 0.03]), np.array([1.0, -2.0, 3.0])
    x = np.concatenate([lc.attitude_error(q, ctrl.q_ref), w, Om])
    u = ctrl.command(q, w, Om)
    np.testing.assert_allclose(u, np.clip(ctrl.u0 - ctrl.L @ x, -0.2, 0.2), rtol=1e-13, atol=1e-16)
    # −q is the same attitude: the chart picks the short way
    np.testing.assert_allclose(ctrl.command(-q, w, Om), u, rtol=1e-13, atol=1e-16)


# ------------------------------------------------------------------------ bad parameters, the README's figures


@pytest.mark.parametrize("kwargs, field", [
    ({"Q": np.diag([1, 1, 1, 1, 1, 1, 1, 1, -1.0])}, "Q"),           # not PSD
    ({"Q": np.ones(8)}, "Q"),                                        # wrong size
    ({"Q": np.triu(np.ones((9, 9)))}, "Q"),                          # not symmetric
    ({"R": [1.0, 0.0, 1.0]}, "R"),                                   # not PD
    ({"R": [1.0, float("nan"), 1.0]}, "R"),
    ({"R": np.eye(4)}, "R"),
    ({"period": 0.0}, "period"),
    ({"period": float("nan")}, "period"),
    ({"delay": 0.01}, "delay"),                                      # longer than the period
    ({"delay": -1e-3}, "delay"),
    ({"actuator_lag": -1.0}, "actuator_lag"),
    ({"q_ref": (0, 0, 0, 0)}, "q_ref"),
    ({"null_bias": 10.0}, "null_bias"),                              # three independent wheels: no null space
    ({"body": "sat"}, "body"),
    ({"weights": {"attitude_deg": 0.0}}, "attitude_deg"),
    ({"weights": {"attitude": 1.0}}, "weights"),
    ({"weights": [2.0]}, "weights"),
])
def test_bad_design_parameters_name_the_field(kwargs, field):
    kw = {"period": 2e-3, **kwargs}
    with pytest.raises(LavenderInputError) as e:
        lc.design(lc.chapter_cube("center"), **kw)
    assert e.value.field == field


@pytest.mark.parametrize("kwargs, field", [
    ({"mass": float("nan")}, "mass"), ({"size": -0.1}, "size"), ({"J": (1e-3, 1e-3)}, "J"),
    ({"J": (1e-3, -1e-3, 1e-3)}, "J"), ({"torque_limit": 0.0}, "torque_limit"), ({"damping": -1.0}, "damping"),
    ({"scenario": "edge"}, "scenario"), ({"motor": "stepper"}, "motor"),
])
def test_bad_cube_parameters_name_the_field(kwargs, field):
    with pytest.raises(LavenderInputError) as e:
        lc.chapter_cube(**kwargs)
    assert e.value.field == field


def test_not_an_equilibrium_is_rejected():
    with pytest.raises(LavenderInputError) as e:
        lc.design(lc.chapter_cube("corner"), period=2e-3, q_ref=[0, 0, 0, 1])
    assert e.value.field == "q_ref"


def test_lqr_figures_keep_the_readme_numbers():
    """README: centre 20° about (1,2,3) → < 0.1° in 0.39 s, |u| ≤ 0.2 N·m; corner from 3°: 0.16 s, wheels ≤ 21 rad/s
    (the stack behind `lavendersim lqr --scenario`; measured 0.392 s and 0.162 s, 21.15 rad/s)."""
    for scenario, theta0, T, settle, speed in (("center", 20.0, 5.0, 0.392, 16.27), ("corner", 3.0, 6.0, 0.162, 21.15)):
        scene, ctrl = _design(scenario)
        axis = lc.DEFAULT_AXIS if scenario == "center" else lc.CORNER_AXIS
        r = lc.closed_loop(scene, ctrl, T=T, q0=lc.rotated(ctrl.q_ref, axis, theta0), Omega0=np.zeros(3), dt=1e-3, backend="c")
        assert r.settling_time() == pytest.approx(settle, abs=1e-9)
        assert np.all(r.peak_torque <= 0.2) and r.peak_wheel_speed.max() == pytest.approx(speed, abs=0.01)
