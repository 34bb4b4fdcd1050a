"""Control corner cases (issue 28): a design that cannot stabilize is refused naming the mode; weights are real
finite matrices; a Monte Carlo draw that fails is a failed sample, not the end of the sweep."""
from __future__ import annotations

import math
import pickle

import numpy as np
import pytest

import lavendersim as lv
from lavendersim import control as lc
from lavendersim.validate import LavenderInputError

pytestmark = pytest.mark.needs("control")

E1 = np.array([[1.0], [0.0]])


# ------------------------------------------------------------------------ unstable modes no input reaches


def test_the_audits_lqr_is_refused_naming_the_mode():
    """lqr(A = I, B = e1): the audit's 'design' had E = [-1.41, +1.0]; x[1] grows as e^t whatever the gain."""
    import control as ct

    with pytest.raises(np.linalg.LinAlgError):          # python-control refuses the pair too
        ct.lqr(np.eye(2), E1, np.eye(2), 1.0)
    with pytest.raises(lc.DesignError) as e:
        lc.lqr(np.eye(2), E1, np.eye(2), 1.0)
    assert isinstance(e.value, LavenderInputError) and e.value.field == "sys"
    assert e.value.eigenvalue == pytest.approx(1.0, abs=1e-12) and e.value.states == ("x[1]",)
    assert not e.value.discrete and "+1" in str(e.value) and "x[1]" in str(e.value)
    # discrete: |z| = 1.2 > 1 on the second state
    with pytest.raises(lc.DesignError) as e:
        lc.dlqr(np.diag([0.5, 1.2]), E1, np.eye(2), 1.0)
    assert e.value.eigenvalue == pytest.approx(1.2, abs=1e-12) and e.value.states == ("x[1]",) and e.value.discrete


def test_a_design_error_pickles_with_its_fields():
    with pytest.raises(lc.DesignError) as e:
        lc.lqr(np.eye(2), E1, np.eye(2), 1.0)
    back = pickle.loads(pickle.dumps(e.value))
    assert type(back) is lc.DesignError and str(back) == str(e.value)
    assert (back.field, back.eigenvalue, back.states, back.discrete) == ("sys", e.value.eigenvalue, ("x[1]",), False)


def test_stable_and_marginal_uncontrollable_modes_still_design():
    """A stable uncontrollable mode (-1) and a marginal one (0: a conserved quantity) design as before."""
    for a in (-1.0, 0.0):
        K, S, E = lc.lqr(np.diag([1.0, a]), E1, np.eye(2), 1.0)
        np.testing.assert_allclose(np.sort(E.real), np.sort([-math.sqrt(2.0), a]), atol=1e-12)
        np.testing.assert_allclose(K, [[1 + math.sqrt(2.0), 0.0]], atol=1e-12)
    # a double integrator no input reaches (a free body's position: p' = v, v' = 0) is marginal, not unstable
    A = np.zeros((3, 3))
    A[1, 2] = 1.0
    A[0, 0] = 1.0
    assert lc.lqr(A, np.array([[1.0], [0.0], [0.0]]), np.eye(3), 1.0).rank == 1


@pytest.mark.parametrize("growth, refused", [(1e-3, True), (1e-9, False)])
def test_the_growth_threshold_is_scaled_to_the_model(growth, refused):
    """An uncontrollable mode growing at 1e-3 of the model's fastest rate (1/s) is refused; 1e-9 is marginal."""
    A = np.diag([1.0, growth])
    if refused:
        with pytest.raises(lc.DesignError) as e:
            lc.lqr(A, E1, np.eye(2), 1.0)
        assert e.value.eigenvalue == pytest.approx(growth, rel=1e-9)
    else:
        assert lc.lqr(A, E1, np.eye(2), 1.0).rank == 1


def _corner_one_wheel() -> lv.Scene:
    """The chapter's corner cube balancing under gravity with ONE wheel, on the body diagonal: upright, that axis
    is vertical, so no wheel torque can tilt the cube and both tilts fall (an inverted pendulum) on their own."""
    q0 = lc.cube_upright_q("corner")
    s = lv.Scene()
    s.add_body(lv.Body.box("cube", mass=1.0, size=(0.15,) * 3, p_w=lc.KN.quat_rotate(q0, lc.cube_r_b("corner", 0.15)), q=q0))
    s.add_effect("spherical_joint", body="cube", anchor_w=[0.0, 0.0, 0.0])
    s.add_effect("reaction_wheels", body="cube", J=[5.7e-4], axes_b=[[3 ** -0.5] * 3], torque_limit=0.2, speed_limit=400.0)
    s.add_effect("gravity", body="cube", g_w=[0.0, 0.0, -9.81])
    return s


def test_design_refuses_a_falling_axis_no_wheel_reaches():
    scene = _corner_one_wheel()
    q0 = lc.cube_upright_q("corner")
    with pytest.raises(lc.DesignError) as e:
        lc.design(scene, period=2e-3, q_ref=q0)
    # the mode is the gravity tilt: z = e^{sigma Ts} with sigma the continuous model's unstable eigenvalue
    sigma = float(np.max(np.linalg.eigvals(lc.linearize(scene, {"cube": {"q": q0}}).A).real))
    assert sigma > 5.0
    assert e.value.discrete and e.value.field == "scene"
    assert abs(e.value.eigenvalue - math.exp(sigma * 2e-3)) < 1e-9
    assert set(e.value.states) >= {"cube_dtheta_x", "cube_dtheta_y", "cube_dtheta_z"}
    assert not any("Omega" in s for s in e.value.states)      # the wheel's own speed is not in the falling mode
    assert f"{sigma:+.4g}/s" in str(e.value)                   # the continuous rate, in words
    assert e.value.eigenvalue.imag == 0.0                       # a real double root (both tilts), not ±1e-16j
    # the same plant's Linearization (a control.StateSpace) given to lqr / dlqr: refused, its state labels named
    lin = lc.linearize(scene, {"cube": {"q": q0}})
    with pytest.raises(lc.DesignError) as c:
        lc.lqr(lin, np.eye(lin.nstates), 1.0)
    # the tilt is a double root: any basis of its 2-D eigenspace is right, so which tilt angles the first mode names
    # turns on the last bits of A (it named dtheta_x before the attitude chart was printed, dtheta_y/z after)
    assert c.value.eigenvalue == pytest.approx(sigma, rel=1e-9)
    assert any(s.startswith("cube_dtheta_") for s in c.value.states)
    assert not any("Omega" in s for s in c.value.states)
    with pytest.raises(lc.DesignError) as d:
        lc.dlqr(lin.sample(2e-3), np.eye(lin.nstates), 1.0)
    assert abs(d.value.eigenvalue - e.value.eigenvalue) < 1e-9 and f"{sigma:+.4g}/s" in str(d.value)


def _corner_one_wheel_file(tmp_path):
    import tomllib

    from lavendersim import spacecraft as S

    d = tomllib.loads(S.shipped()["cube_corner"].read_text(encoding="utf-8"))
    d["body"]["wheels"] = {"J": [5.7e-4], "axes_b": [[1.0, 1.0, 1.0]], "torque_limit": 0.2, "speed_limit": 400.0}
    return d


def test_the_spacecraft_file_and_the_cli_refuse_it_in_one_line(tmp_path, capsys):
    """The same plant as a spacecraft file: S.design raises the DesignError; `lqr` prints one line, exit 2."""
    from lavendersim import cli
    from lavendersim import scene_file as SF
    from lavendersim import spacecraft as S

    d = _corner_one_wheel_file(tmp_path)
    with pytest.raises(lc.DesignError) as e:
        S.design(S.from_dict(d))
    assert abs(e.value.eigenvalue) > 1.01 and "cube_dtheta_x" in e.value.states
    path = tmp_path / "one_wheel.toml"
    path.write_text(SF.dumps(d), encoding="utf-8")
    assert cli.main(["lqr", "--spacecraft", str(path)]) == 2
    out, err = capsys.readouterr()
    assert out == "" and len(err.strip().splitlines()) == 1 and "no input reaches" in err and "cube_dtheta" in err


def test_design_on_a_single_wheel_free_body_still_flies():
    """One wheel on z of a free body: the x, y attitudes are unactuated double integrators (marginal), p and v too."""
    s = lv.Scene()
    s.add_body(lv.Body.box("sat", 4.0, (0.1, 0.2, 0.3)))
    s.add_effect("reaction_wheels", body="sat", axes_b=[[0.0, 0.0, 1.0]], J=[2e-5], torque_limit=5e-3, speed_limit=600.0)
    c = lc.design(s, period=0.2)
    assert c.rank == 2 and np.all(np.abs(c.poles) < 1)
    r = lc.closed_loop(s, c, T=20.0, q0=lc.rotated(c.q_ref, (0, 0, 1), 10.0), backend="c")
    assert r.settling_time() == pytest.approx(3.4, abs=1e-9) and r.final_error_deg < 1e-9


def test_a_solver_gain_that_does_not_stabilize_is_refused(monkeypatch):
    """After solving, the closed loop on the controllable subspace is checked (a solver returning a bad gain)."""
    import control as ct

    monkeypatch.setattr(ct, "lqr", lambda A, B, Q, R: (np.zeros((B.shape[1], A.shape[0])), np.eye(A.shape[0]), None))
    with pytest.raises(lc.DesignError) as e:
        lc.lqr(np.array([[2.0]]), np.array([[1.0]]), 1.0, 1.0)
    assert e.value.eigenvalue == pytest.approx(2.0) and "closed loop unstable" in e.value.rule


# ------------------------------------------------------------------------ weights are real finite matrices


BAD_WEIGHTS = [
    (1 + 1j, "real"), (np.array([1 + 1j, 2.0]), "real"), (True, "real"), (np.bool_(True), "real"), ([True, True], "real"),
    ("1", "real"), (["1", "2"], "real"), ([["1", "0"], ["0", "1"]], "real"), (object(), "real"), (None, "real"),
    (np.nan, "finite"), ([np.inf, 1.0], "finite"), (np.ones(3), "2 entries"), (np.ones((2, 3)), "2×2"),
    ([[1.0, 0.5], [0.0, 1.0]], "symmetric"), (1e200, "between"), (1e-200, "between"),
]


@pytest.mark.parametrize("which", ["Q", "R"])
@pytest.mark.parametrize("value, rule", BAD_WEIGHTS, ids=lambda v: type(v).__name__ if not isinstance(v, str) else v)
def test_lqr_refuses_a_weight_that_is_not_a_real_finite_matrix(which, value, rule):
    import warnings

    with warnings.catch_warnings():
        warnings.simplefilter("error")        # no ComplexWarning: the imaginary part is never silently dropped
        with pytest.raises(LavenderInputError) as e:
            lc.lqr(np.zeros((2, 2)), np.eye(2), value if which == "Q" else np.eye(2), value if which == "R" else np.eye(2))
    assert e.value.field == which and rule in str(e.value), e.value


def test_definiteness_is_the_rule_q_psd_r_pd():
    A, B = np.zeros((2, 2)), np.eye(2)
    for Q, R, field, rule in ((np.diag([1.0, -1.0]), 1.0, "Q", "positive semidefinite"),
                              (1.0, [[1.0, 2.0], [2.0, 1.0]], "R", "positive definite"),
                              (1.0, np.diag([1.0, 0.0]), "R", "positive definite")):
        with pytest.raises(LavenderInputError) as e:
            lc.lqr(A, B, Q, R)
        assert e.value.field == field and rule in e.value.rule
    # a PSD Q with a zero eigenvalue and a real-valued Fraction are fine, and the gain is the one the floats give
    from fractions import Fraction

    K1 = lc.lqr(-np.eye(2), B, np.diag([1.0, 0.0]), [Fraction(1, 2), Fraction(1, 2)]).K
    np.testing.assert_allclose(K1, lc.lqr(-np.eye(2), B, np.diag([1.0, 0.0]), 0.5).K, rtol=0, atol=0)
    assert K1[0, 0] == pytest.approx(math.sqrt(3.0) - 1, rel=1e-12) and K1[1, 1] == 0.0


@pytest.mark.parametrize("kw, field", [
    ({"Q": 1 + 0j}, "Q"), ({"Q": True}, "Q"), ({"R": "100"}, "R"), ({"R": [100.0, 100.0, np.nan]}, "R"),
    ({"Q": np.ones(8)}, "Q"), ({"R": -np.eye(3)}, "R"), ({"Q": -1.0}, "Q"),
    ({"weights": {"attitude_deg": True}}, "attitude_deg"), ({"weights": {"rate": "0.5"}}, "rate"),
    ({"weights": {"attitude_deg": 1e-200}}, "attitude_deg"),        # 1/x² overflows: named, not "Q: must be finite"
    ({"weights": {"torque_fraction": 1e300}}, "torque_fraction"),   # 1/x² underflows to a zero R
])
def test_design_names_the_weight(kw, field):
    with pytest.raises(LavenderInputError) as e:
        lc.design(lc.chapter_cube("center"), period=2e-3, **kw)
    assert e.value.field == field, e.value


@pytest.mark.parametrize("key, value, field, rule", [
    ("Q", True, "controller.Q", "bool"), ("Q", "1", "controller.Q", "real"), ("Q", ["1"] * 9, "controller.Q", "real"),
    ("Q", (np.eye(9) * np.r_[-1.0, np.ones(8)]).tolist(), "controller.Q", "positive semidefinite"),
    ("R", [[1.0, 2.0, 0.0], [2.0, 1.0, 0.0], [0.0, 0.0, 1.0]], "controller.R", "positive definite"),
    ("R", 1e200, "controller.R", "between"), ("Q", float("nan"), "controller.Q", "finite"),
    ("weights", {"attitude_deg": 1e-200}, "controller.weights.attitude_deg", "Bryson"),
])
def test_a_spacecraft_files_weights_are_checked_on_load(key, value, field, rule):
    import tomllib

    from lavendersim import spacecraft as S

    d = tomllib.loads(S.shipped()["cube_corner"].read_text(encoding="utf-8"))
    d["controller"][key] = value
    if key != "weights":
        d["controller"].pop("weights")
    with pytest.raises(LavenderInputError) as e:
        S.from_dict(d)                                   # on load, before any design
    assert e.value.field == field and rule in str(e.value), e.value


# ------------------------------------------------------------------------ Monte Carlo: a failed draw is a failed sample


def _sat() -> lv.Scene:
    """tests/test_closed_loop.py's user spacecraft: a 10×20×30 cm box, I_x ≈ I_y + I_z − 13 %, three skewed wheels."""
    axes = np.array([[1.0, 0.2, 0.1], [0.1, 1.0, -0.3], [0.3, -0.2, 1.0]])
    s = lv.Scene()
    s.add_body(lv.Body.box("sat", 4.0, (0.1, 0.2, 0.3)))
    s.add_effect("reaction_wheels", body="sat", axes_b=axes / np.linalg.norm(axes, axis=1, keepdims=True),
                 J=[2e-5, 2.5e-5, 3e-5], torque_limit=5e-3, speed_limit=600.0)
    return s


@pytest.fixture(scope="module")
def sat():
    scene = _sat()
    return scene, lc.design(scene, period=0.2)


MC = dict(n=8, seed=1, T=12.0, inertia_spread=0.5, sensors=lc.Sensors(attitude_noise=1e-4, seed=3), backend="c")


def _q0(ctrl):
    return lc.rotated(ctrl.q_ref, (0, 0, 1), 20.0)


def test_an_infeasible_draw_is_a_failed_sample_and_the_others_fly_as_alone(sat):
    """Spread 0.5 on a box near its triangle inequality: draws 1, 2, 3 and 5 of seed 1 are no rigid body. They are
    failed samples naming their index, seed, factors and tensor; the other draws' figures are those of flying each
    alone; the summary's percentiles are over the others."""
    from dataclasses import replace

    from lavendersim import wheel_control as W

    scene, ctrl = sat
    mc = lc.monte_carlo(scene, ctrl, q0=_q0(ctrl), **MC)
    scales = 1 + 0.5 * np.random.default_rng(1).uniform(-1, 1, (8, 3))
    assert [s["index"] for s in mc["failed_samples"]] == [1, 2, 3, 5] and mc["failed"] == 4
    I0 = np.diag(scene.bodies["sat"].I_b)
    for s in mc["failed_samples"]:
        i = s["index"]
        assert s["failed"] == "plant" and s["error"] == "LavenderInputError" and s["field"] == "inertia"
        assert s["seed"] == 3 + 1 + i and s["inertia_scale"] == scales[i].tolist()
        np.testing.assert_allclose(s["inertia_b"], np.sqrt(scales[i])[:, None] * I0 * np.sqrt(scales[i])[None, :], rtol=1e-15)
        Id = np.diag(s["inertia_b"])
        assert np.max(Id) > np.sum(Id) - np.max(Id)        # the triangle inequality it names is indeed broken
        assert "triangle inequality" in s["why"] and s["settled"] is False and s["settling_time"] is None
    ok = [s for s in mc["samples"] if not s["failed"]]
    assert [s["index"] for s in ok] == [0, 4, 6, 7] and all(s["settled"] for s in ok)
    for s in ok:
        alone = W.monte_carlo_sample({"scene": W.perturbed_inertia(scene, "sat", scales[s["index"]]), "controller": ctrl,
                                      "sensors": replace(MC["sensors"], seed=s["seed"]), "T": 12.0, "q0": _q0(ctrl),
                                      "omega0": None, "Omega0": None, "dt": None, "threshold_deg": 0.1, "backend": "c"})
        assert {k: s[k] for k in alone} == alone
    st = np.array([s["settling_time"] for s in ok])
    assert mc["settling_time"]["p100"] == st.max() and mc["settling_time"]["p50"] == np.percentile(st, 50)
    assert mc["failures"] == 4 and mc["failure_rate"] == 0.5


def test_a_draw_whose_run_fails_is_a_failed_sample_the_rest_unchanged(sat, monkeypatch):
    """Draw 2's run diverges (any DRAW_ERRORS): failed "run" with the error; every other sample is bit for bit the
    sweep's without the failure."""
    from lavendersim import wheel_control as W
    from lavendersim.errors import DivergenceError

    scene, ctrl = sat
    kw = {**MC, "inertia_spread": 0.05, "n": 4}
    before = lc.monte_carlo(scene, ctrl, q0=_q0(ctrl), **kw)
    real = W.closed_loop

    def diverge_on_seed_6(*a, **k):
        if k["sensors"].seed == 3 + 1 + 2:
            raise DivergenceError(17, 0, "state grew without bound", "sat", t=0.34)
        return real(*a, **k)

    monkeypatch.setattr(W, "closed_loop", diverge_on_seed_6)
    mc = lc.monte_carlo(scene, ctrl, q0=_q0(ctrl), **kw)
    assert mc["failed"] == 1 and [s["index"] for s in mc["failed_samples"]] == [2]
    f = mc["samples"][2]
    assert f["failed"] == "run" and f["error"] == "DivergenceError" and "step 17" in f["why"] and f["seed"] == 6
    assert f["inertia_scale"] == before["samples"][2]["inertia_scale"]
    for i in (0, 1, 3):
        assert mc["samples"][i] == before["samples"][i]
    assert before["failed"] == 0 and before["failed_samples"] == []


def test_the_sweep_errors_only_when_every_draw_fails(sat, monkeypatch):
    from lavendersim import wheel_control as W
    from lavendersim.errors import DivergenceError

    scene, ctrl = sat
    calls = []

    def always(*a, **k):
        calls.append(k["sensors"].seed)
        raise DivergenceError(0, 0, "boom", "sat")

    monkeypatch.setattr(W, "closed_loop", always)
    with pytest.raises(W.SweepError) as e:
        lc.monte_carlo(scene, ctrl, q0=_q0(ctrl), **{**MC, "inertia_spread": 0.05, "n": 3})
    assert e.value.field == "monte_carlo" and len(e.value.samples) == 3 and calls == [4, 5, 6]
    assert all(s["failed"] == "run" for s in e.value.samples) and "every one of the 3 draws failed" in str(e.value)
    back = pickle.loads(pickle.dumps(e.value))
    assert back.samples == e.value.samples and str(back) == str(e.value)
    # a user input error, the same for every draw, is raised once before any draw flies
    calls.clear()
    for bad, field in (({"T": 0.0}, "T"), ({"dt": 0.03}, "dt"), ({"q0": (0, 0, 0, 0)}, "q0"), ({"backend": "gpu"}, "backend"),
                       ({"threshold_deg": -1.0}, "threshold_deg"), ({"Omega0": np.zeros(4)}, "Omega0")):
        with pytest.raises(LavenderInputError) as e:
            lc.monte_carlo(scene, ctrl, **{**MC, **bad})
        assert e.value.field == field and not isinstance(e.value, W.SweepError)
    assert calls == []


def test_failed_samples_cross_processes_unchanged(sat):
    from lavendersim import executor as X

    scene, ctrl = sat
    kw = {**MC, "n": 6, "T": 2.0}
    serial = lc.monte_carlo(scene, ctrl, q0=_q0(ctrl), **kw)
    two = lc.monte_carlo(scene, ctrl, q0=_q0(ctrl), executor=X.Executor(X.PROCESSES, 2), **kw)
    assert serial["failed"] == 4 and two == serial


PLATE = """
name = "a flat plate: I_z within 2.5 % of I_x + I_y"

[body]
name = "plate"
mass = 2.0
inertia = [[0.02, 0.0, 0.0], [0.0, 0.02, 0.0], [0.0, 0.0, 0.039]]

[body.wheels]
J = 2e-5
torque_limit = 0.005
speed_limit = 600.0

[controller]
period = 0.2

[maneuver]
angle_deg = 10.0
axis = [1.0, 0.0, 0.0]
duration = 4.0

[simulator]
dt = 0.02

[monte_carlo]
n = 6
inertia_uncertainty = 0.3
seed = 0
"""


def test_cli_monte_carlo_json_lists_the_failed_samples(tmp_path, capsys):
    import json

    from lavendersim import cli

    path = tmp_path / "plate.toml"
    path.write_text(PLATE, encoding="utf-8")
    code = cli.main(["lqr", "--spacecraft", str(path), "--monte-carlo", "6", "--workers", "1", "--json"])
    out, err = capsys.readouterr()
    mc = json.loads(out)["monte_carlo"]
    assert code in (0, 1) and "Traceback" not in err
    scales = 1 + 0.3 * np.random.default_rng(0).uniform(-1, 1, (6, 3))
    infeasible = [i for i in range(6) if 0.039 * scales[i, 2] > 0.02 * (scales[i, 0] + scales[i, 1])]
    assert infeasible and len(infeasible) < 6
    assert mc["failed"] == len(infeasible) and [s["index"] for s in mc["failed_samples"]] == infeasible
    assert all(s["field"] == "inertia" and s["failed"] == "plant" for s in mc["failed_samples"])
    assert mc["failures"] >= mc["failed"] and "samples" not in mc
