"""Issue 11's accepted-bad inputs and hangs, one test each: every public input is validated where it
enters (LavenderInputError naming the field, nothing half-applied), and the CLI answers a bad value
with exit 2 and one line — never a traceback, never a hang (subprocesses run under a timeout)."""
from __future__ import annotations

import os
import pickle
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

import lavendersim as lv
from lavendersim import cli
from lavendersim import effects as E
from lavendersim import validate as V
from lavendersim import viewer as VW
from lavendersim.bodies import ImmutableBodyError
from lavendersim.validate import LavenderInputError

from conftest import missing, require

TIMEOUT = 300.0   # s, for subprocesses: only ever reached when the command hangs (the bug)


def _cube(name="b", **kw):
    return lv.Body.box(name, 1.0, (0.2, 0.2, 0.2), **kw)


# ---------------------------------------------------------------- bodies ----------------------------------------------
@pytest.mark.parametrize("field,value", [("mass", -5), ("I_b", (1, 1, 50)), ("x0", np.zeros(13)), ("shape", None),
                                         ("name", "other"), ("colour", "red")])
def test_body_is_immutable_after_validation(field, value):
    b = _cube()
    before = (b.name, b.mass, b.I_b.copy(), b.shape, b.x0.copy())
    with pytest.raises(ImmutableBodyError) as e:
        setattr(b, field, value)
    assert e.value.field == f"body.{field}" and isinstance(e.value, (LavenderInputError, AttributeError))
    assert (b.name, b.mass, b.shape) == before[:2] + before[3:4]
    np.testing.assert_array_equal(b.I_b, before[2])
    np.testing.assert_array_equal(b.x0, before[4])


def test_body_arrays_are_read_only_and_a_sim_sees_the_validated_values():
    b = lv.Body("b", 1.0, (1.0, 2.0, 2.5))
    with pytest.raises(ValueError):
        b.I_b[2] = 50.0
    with pytest.raises(ValueError):
        b.x0[0] = np.nan
    s = lv.Scene()
    s.add_body(b)
    sim = lv.Sim(s, backend="numpy")
    np.testing.assert_array_equal(sim.params[0], [1.0, 1.0, 2.0, 2.5])
    c = pickle.loads(pickle.dumps(b))
    assert c.mass == 1.0 and not c.I_b.flags.writeable
    with pytest.raises(ImmutableBodyError):
        c.mass = -1


@pytest.mark.parametrize("shape,field", [
    (("cone", (1.0,)), "shape[0]"), (("box", (1.0, 1.0)), "shape[1]"), (("box", (1.0, -1.0, 1.0)), "shape[1][1]"),
    (("sphere", (np.nan,)), "shape[1]"), ("box", "shape"), ((1, 2, 3), "shape"), (("cylinder", "ab"), "shape[1]"),
    (("box", (1.0, 0.0, 1.0)), "shape[1][1]"), ((b"box", (1, 1, 1)), "shape[0]"),
])
def test_body_shape_is_validated(shape, field):
    with pytest.raises(LavenderInputError) as e:
        lv.Body("b", 1.0, (1, 1, 1), shape=shape)
    assert e.value.field == field


def test_body_shape_accepted_forms():
    assert lv.Body("b", 1.0, (1, 1, 1), shape=("sphere", 0.5)).shape == ("sphere", (0.5,))
    assert lv.Body("b", 1.0, (1, 1, 1), shape=["box", [1, 2, 3]]).shape == ("box", (1.0, 2.0, 3.0))
    assert lv.Body.cylinder("c", 1.0, 0.1, 0.5).shape == ("cylinder", (0.1, 0.5))


@pytest.mark.parametrize("call,field", [
    (lambda: lv.Body("b", 1.0, (1, 1, 1), omega=(1, 0, 0)), "omega"),
    (lambda: lv.Body("b", 1.0, (1, 1, 1), shap=None), "shap"),
    (lambda: lv.Body("b"), "mass"),
    (lambda: lv.Body.box("b", 1.0, (1, 1, 1), velocity=(1, 0, 0)), "velocity"),
    (lambda: lv.Body.box("b", 1.0, (1, 1, 1), shape=("box", (1, 1, 1))), "shape"),
    (lambda: lv.Body.sphere("b", 1.0), "radius"),
    (lambda: lv.Scene(bodies=[]), "bodies"),
    (lambda: lv.Scene().add_body(_cube(), replace=True), "replace"),
    (lambda: lv.Sim(_scene(), dt=1e-3, integrater="rk4"), "integrater"),
    (lambda: lv.Sim(_scene(), 1e-3, "rk4", "numpy", True, None, None, "extra"), "Sim"),
])
def test_unknown_and_missing_arguments_are_input_errors(call, field):
    with pytest.raises(LavenderInputError) as e:
        call()
    assert e.value.field == field


def test_unknown_keyword_names_the_close_match():
    with pytest.raises(LavenderInputError, match=r"did you mean 'omega_b'\?"):
        lv.Body("b", 1.0, (1, 1, 1), omega_bb=(1, 0, 0))


def _scene(*bodies):
    s = lv.Scene()
    for b in bodies or (_cube(),):
        s.add_body(b)
    return s


# ---------------------------------------------------------------- validate --------------------------------------------
def test_quaternion_of_huge_entries_normalizes():
    np.testing.assert_array_equal(V.quaternion("q", (1e308,) * 4), [0.5, 0.5, 0.5, 0.5])
    np.testing.assert_allclose(V.quaternion("q", (-1.7e308, 0, 0, 1.7e308)), [-2 ** -0.5, 0, 0, 2 ** -0.5], rtol=1e-15)
    np.testing.assert_array_equal(V.quaternion("q", (0, 0, 0, 1e-200)), [0, 0, 0, 1])
    with pytest.raises(LavenderInputError, match="zero quaternion"):
        V.quaternion("q", (5e-324, 0, 0, 0))


@pytest.mark.parametrize("tensor", [
    [[9e307, 0, 0], [0, 1, 0], [0, 0, 1]],
    [[1, 0, 0], [0, 1, 0], [0, 0, 9e307]],
    [[1, 9e307, 0], [9e307, 1, 0], [0, 0, 1]],
    [[9e307, 9e307, 0], [9e307, 9e307, 0], [0, 0, 1]],
    [[1.7e308, 1e308, 0], [1e308, 1.7e308, 0], [0, 0, 1.7e308]],
])
def test_inertia_near_the_float64_limit_is_an_input_error_naming_I_b(tensor):
    for check in (lambda t: V.inertia("I_b", t), lambda t: V.principal_axes(t, field="I_b")):
        with pytest.raises(LavenderInputError) as e:
            check(tensor)
        assert e.value.field == "I_b"


def test_huge_but_valid_inertia_is_kept_exactly():
    np.testing.assert_array_equal(V.inertia("I_b", np.diag([9e307, 9e307, 9e307])), [9e307] * 3)
    moments, R = V.principal_axes(np.diag([1.7e308, 1.7e308, 1.7e308]))
    np.testing.assert_array_equal(moments, [1.7e308] * 3)
    np.testing.assert_array_equal(V.inertia("I_b", np.diag([1.0, 2.0, 2.5])), [1.0, 2.0, 2.5])


def test_safe_norm():
    assert V.safe_norm([1e308, 1e308, 0]) == pytest.approx(1e308 * 2 ** 0.5, rel=1e-15)
    assert V.safe_norm([3e-320, 4e-320]) == pytest.approx(5e-320, rel=1e-3)
    assert V.safe_norm([1.7e308, 1.7e308]) == np.inf
    assert V.safe_norm([0, 0, 0]) == 0.0


# ---------------------------------------------------------------- effects ---------------------------------------------
def test_two_huge_torques_are_rejected_at_add_time_scene_unchanged():
    s = _scene(lv.Body("b", 1.0, (10, 10, 10)))
    s.add_effect("applied_torque", body="b", torque_w=(6e299, 0, 0))
    with pytest.raises(LavenderInputError, match="net torque on body 'b'.*bound is 1e\\+300") as e:
        s.add_effect("applied_torque", body="b", torque_w=(6e299, 0, 0))
    assert e.value.field == "applied_torque.torque_w"
    assert len(s.effects) == 1
    with pytest.raises(LavenderInputError) as e:
        s.add_effect("applied_torque", body="b", torque_w=(1e308, 0, 0))
    assert e.value.field == "applied_torque.torque_w" and len(s.effects) == 1


@pytest.mark.parametrize("name,params,field", [
    ("force_at_point", {"r_b": (1e200, 0, 0), "F_w": (0, 1e200, 0)}, "force_at_point.r_b"),
    ("gravity", {"g_w": (0, 0, -1e301)}, "gravity.g_w"),
    ("applied_torque", {"torque_w": (0, 0, 1e300)}, "applied_torque.torque_w"),   # |tau|/I = 6e300 > 1e300
])
def test_effect_loads_beyond_the_bound_are_rejected(name, params, field):
    s = _scene()
    with pytest.raises(LavenderInputError) as e:
        s.add_effect(name, **params)
    assert e.value.field == field and s.effects == []


def test_a_body_that_would_overflow_under_every_body_effects_is_rejected():
    s = _scene()
    s.add_effect("gravity", g_w=(0, 0, -1e290))
    with pytest.raises(LavenderInputError, match="net force on body 'heavy'") as e:
        s.add_body(lv.Body.box("heavy", 1e20, (1, 1, 1)))
    assert e.value.field == "body" and list(s.bodies) == ["b"]


def test_joint_anchor_far_away_is_rejected_at_add_time_naming_anchor_w():
    s = _scene()
    with pytest.raises(LavenderInputError) as e:
        s.add_effect("spherical_joint", body="b", anchor_w=(1e200, 0, 0))
    assert e.value.field == "spherical_joint.anchor_w" and s.effects == []
    s.add_effect("spherical_joint", body="b", anchor_w=(0.1, 0.1, 0.1))   # a near anchor still works
    lv.Sim(s, backend="numpy").run(5)


# ---------------------------------------------------------------- env -------------------------------------------------
@pytest.fixture
def gym():
    require("gym")
    import gymnasium

    return gymnasium


@pytest.mark.parametrize("action", [np.array([1j, 0, 0]), [0.1, 0.2 + 0j, 0.3], [True, False, True],
                                    np.array([True, False, True]), np.array([0, 0, 1e400]), [[0, 0, 0]]])
def test_env_actions_must_be_real_finite_numbers(gym, action):
    env = gym.make("lavendersim:ReactionWheelCube-v0", backend="numpy").unwrapped
    env.reset(seed=1)
    x0 = env.sim.x.copy()
    with pytest.raises(LavenderInputError) as e:
        env.step(action)
    assert e.value.field == "action"
    np.testing.assert_array_equal(env.sim.x, x0)
    assert env.sim.steps == 0


@pytest.mark.parametrize("mode", ["human", "rgb_array_list", "ansi"])
def test_env_unsupported_render_modes_are_rejected_through_gym_make(gym, mode):
    with pytest.raises(LavenderInputError) as e:
        gym.make("lavendersim:ReactionWheelCube-v0", render_mode=mode)
    assert e.value.field == "render_mode"


def test_env_rejects_unknown_keywords_and_bad_reset_without_changing_anything(gym):
    with pytest.raises(LavenderInputError) as e:
        gym.make("lavendersim:ReactionWheelCube-v0", speed_limt=100.0)
    assert e.value.field == "speed_limt"
    env = gym.make("lavendersim:ReactionWheelCube-v0", backend="numpy").unwrapped
    env.reset(seed=3)
    state = env.np_random.bit_generator.state
    sim = env.sim
    for kw, field in [({"seed": -1}, "seed"), ({"seed": 1.5}, "seed"), ({"options": [1]}, "options"),
                      ({"seed": 4, "options": {"q": (0, 0, 0, 0)}}, "options.q"),
                      ({"seed": 4, "options": {"omega_b": (1e3, 0, 0)}}, "options.omega_b")]:
        with pytest.raises(LavenderInputError) as e:
            env.reset(**kw)
        assert e.value.field == field
        assert env.np_random.bit_generator.state == state and env.sim is sim


# ---------------------------------------------------------------- viewer ----------------------------------------------
@pytest.mark.parametrize("vec", [(1e308, 0, 0), (1e200, 0, 0), (3e38, 3e38, 0), (-1e39, 0, 0)])
def test_viewer_vectors_whose_arrow_overflows_are_rejected(vec):
    with pytest.raises(LavenderInputError) as e:
        VW.validate_overlays({"vectors": [{"origin": [0, 0, 0], "vector": vec}]}, ["b"])
    assert e.value.field == "overlays.vectors[0].vector"
    with pytest.raises(LavenderInputError) as e:
        VW.validate_overlays({"vectors": [{"origin": [1e39, 0, 0], "vector": (1, 0, 0)}]}, ["b"])
    assert e.value.field == "overlays.vectors[0].origin"
    with pytest.raises(LavenderInputError) as e:   # the product scale * vector overflows
        VW.validate_overlays({"vectors": [{"origin": [0, 0, 0], "vector": (1e30, 0, 0), "scale": 1e30}]}, ["b"])
    assert e.value.field == "overlays.vectors[0].vector"


def test_viewer_node_names_are_injective():
    names = ["x/y", "x_y", "x%2Fy", "x y", "x", "x/", "ü"]
    nodes = [VW.node_name(n) for n in names]
    assert len(set(nodes)) == len(names)
    assert all(n.startswith("/bodies/") and "/" not in n[len("/bodies/"):] for n in nodes)


@pytest.mark.parametrize("host,rule", [("192.0.2.1", "not an address of this machine"),
                                       ("not a host!", "neither an IP address nor a valid host name"),
                                       ("", "expected"), (8080, "expected"), ("host..name", "neither")])
def test_viewer_host_is_checked_at_once(host, rule):
    with pytest.raises(LavenderInputError, match=rule) as e:
        VW.check_host(host)
    assert e.value.field == "host"


@pytest.mark.needs("viewer")
def test_viewer_colliding_names_draw_and_a_failed_frame_is_never_success():
    s = _scene(_cube("x/y"), _cube("x_y", p_w=(1, 0, 0)))
    sim = lv.Sim(s, backend="numpy")
    with VW.Viewer(port=0) as v:
        n = v.publish_frame(sim)
        assert v.wait_applied(n, 60.0)
        st = v.scene_state()
        assert sorted(st["bodies"]) == ["x/y", "x_y"]
        assert st["bodies"]["x_y"]["position"] == [1.0, 0.0, 0.0] and st["bodies"]["x/y"]["position"] == [0.0, 0.0, 0.0]
        with pytest.raises(LavenderInputError):
            VW.Viewer(host="192.0.2.1", port=0)

        def broken(frame):
            raise RuntimeError("cannot draw")

        good, v._apply = v._apply, broken
        n = v.publish_frame(sim)
        with pytest.raises(VW.ViewerError, match=f"frame {n} could not be drawn"):
            v.wait_applied(n, 60.0)
        n2 = v.publish_frame(sim)    # reported once (by wait_applied): this one publishes, and fails too
        with pytest.raises(VW.ViewerError):
            v.wait_applied(n2, 60.0)
        v._apply = good
        n3 = v.publish_frame(sim)
        assert v.wait_applied(n3, 60.0)
        assert v.stats()["failed"] == 2 and v.stats()["applied"] >= 2


@pytest.mark.needs("viewer")
def test_viewer_failure_is_raised_by_the_next_publish_when_nobody_waited():
    sim = lv.Sim(_scene(), backend="numpy")
    with VW.Viewer(port=0) as v:
        v._apply = lambda frame: (_ for _ in ()).throw(RuntimeError("cannot draw"))
        n = v.publish_frame(sim)
        import time
        deadline = time.monotonic() + 60.0
        while v.stats()["failed"] == 0 and time.monotonic() < deadline:
            time.sleep(0.01)
        assert v.stats()["failed"] == 1
        with pytest.raises(VW.ViewerError, match=f"frame {n} could not be drawn"):
            v.publish_frame(sim)
        assert v.stats()["published"] == 1   # the raising call published nothing


# ---------------------------------------------------------------- CLI -------------------------------------------------
def _cli_in_process(argv, capsys):
    code = cli.main(argv)
    err = capsys.readouterr().err.strip().splitlines()
    return code, err


def _cli_subprocess(argv, cwd):
    out = subprocess.run([sys.executable, "-m", "lavendersim.cli", *argv], capture_output=True, text=True,
                         timeout=TIMEOUT, cwd=cwd, env={**os.environ, "PYTHONWARNINGS": "ignore"})
    return out.returncode, out.stderr.strip().splitlines()


@pytest.mark.parametrize("argv,needle", [
    (["lab", "01", "--dt", "1e-300"], "at most 1,000,000 steps"),
    (["lab", "02", "--dt", "5e-324"], "at most 1,000,000 steps"),
    (["lab", "03", "--dt", "1e-300", "--search"], "at most 1,000,000 steps"),
    (["lab", "04", "--T", "1e300"], "at most 200,000 steps"),
    (["lqr", "--spacecraft", "{long}"], "maneuver.duration: would take 5e+302 controller periods; at most 1,000,000"),
])
def test_cli_step_counts_are_bounded_exit_2_one_line(argv, needle, tmp_path):
    if argv[0] == "lqr":   # the maneuver's duration comes from the spacecraft file
        from lavendersim import spacecraft as S

        text = S.shipped()["cube_center"].read_text(encoding="utf-8").replace("duration = 5.0", "duration = 1e300")
        (tmp_path / "long.toml").write_text(text, encoding="utf-8")
        argv = [a.format(long=tmp_path / "long.toml") for a in argv]
    code, err = _cli_subprocess(argv + (["--out", str(tmp_path)] if argv[0] == "lab" else []), tmp_path)
    assert code == 2 and len(err) == 1 and needle in err[0], err


def test_cli_bad_view_host_exits_2_at_once(tmp_path):
    require("viewer")
    for host in ("not a host!", "192.0.2.1"):
        code, err = _cli_subprocess(["view", "tumble", "--host", host, "--duration", "0.1", "--port", "0"], tmp_path)
        assert code == 2 and len(err) == 1 and "host" in err[0], err


@pytest.fixture
def a_file(tmp_path) -> Path:
    f = tmp_path / "plain-file"
    f.write_text("not a directory\n")
    return f


@pytest.mark.parametrize("argv", [
    ["lab", "01", "--out", "{f}/sub"], ["lab", "force", "--out", "{f}"], ["lab", "all", "--out", "{f}"],
    ["bench", "--quick", "--out", "{f}/x.json"], ["derive", "--out", "{f}/gen"],
    ["derive", "--user", "{d}"], ["bench", "--rounds", "-1"], ["bench", "--rounds", "0"],
])
def test_cli_unwritable_paths_and_bad_counts_exit_2_one_line(argv, a_file, capsys):
    argv = [a.format(f=a_file, d=a_file.parent) for a in argv]
    code, err = _cli_in_process(argv, capsys)
    assert code == 2 and len(err) == 1, err
    assert a_file.read_text() == "not a directory\n"   # nothing written through the file


def test_cli_lqr_plot_path_checked_first(a_file, capsys):
    require("control")
    code, err = _cli_in_process(["lqr", "--plot", f"{a_file}/p.png"], capsys)
    assert code == 2 and len(err) == 1 and "plot" in err[0], err


def test_lab_finish_turns_os_errors_into_input_errors(a_file):
    from lavendersim.labs import common as C

    with pytest.raises(LavenderInputError) as e:
        C.finish("x", a_file, {}, {}, [], {})
    assert e.value.field == "out"
    with pytest.raises(LavenderInputError):
        C.steps("dt", 0.1, 1e-9)
    assert C.steps("dt", 0.1, 1e-3) == 100


def test_bench_run_rejects_bad_rounds():
    from lavendersim import bench

    for bad in (-1, 0, 1.5, True, 10 ** 6):
        with pytest.raises(LavenderInputError) as e:
            bench.run(quick=True, rounds=bad)
        assert e.value.field == "rounds"


def test_effect_module_bound_is_documented():
    assert E.MAX_LOAD == 1e300


def test_env_constructor_regressions_found_by_the_fuzz(gym):
    """Found by tests/test_fuzz.py with more examples: numpy's ValueError for a ragged J, OverflowError for
    a subnormal dt, ValueError for an array render_mode, gymnasium's Error for a numpy-integer seed."""
    from lavendersim.envs.reaction_wheel_cube import ReactionWheelCubeEnv

    for kw, field in [({"J": (None, [], 0.0, 0.0)}, "J"), ({"dt": 5e-324}, "dt"), ({"dt": 1e-8}, "dt"),
                      ({"render_mode": np.zeros(2)}, "render_mode")]:
        with pytest.raises(LavenderInputError) as e:
            ReactionWheelCubeEnv(backend="numpy", **kw)
        assert e.value.field == field
    env = ReactionWheelCubeEnv(backend="numpy")
    env.reset(seed=np.int8(3))
    a = env.np_random.random()
    env.reset(seed=3)
    assert env.np_random.random() == a


def test_set_state_unknown_keyword_is_an_input_error():
    sim = lv.Sim(_scene(), backend="numpy")
    x = sim.x.copy()
    with pytest.raises(LavenderInputError) as e:
        sim.set_state("b", omega=(1, 0, 0))
    assert e.value.field == "omega"
    np.testing.assert_array_equal(sim.x, x)
