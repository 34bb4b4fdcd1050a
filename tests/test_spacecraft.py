"""Issue 26: spacecraft files and `lavendersim lqr --spacecraft FILE`.

The file format (lavendersim.spacecraft, its scene part lavendersim.scene_file): every bad key or value
raises a LavenderInputError naming its key path, and the command prints it as one line with exit 2.
The shipped 6U CubeSat and a spacecraft of this test's own (another tensor, three skewed wheels, a 5 Hz
controller with delay and actuator lag) settle a 30° slew within their stated time, never exceed a
wheel's torque or speed limit, and keep the total angular momentum to <= 1e-9 relative (no external
torque, sensors off for that check). The chapter's `--scenario` / `--layout` figures are those measured
before the files replaced the options. scene_to_dict / scene_from_dict round-trip through TOML text.
"""
from __future__ import annotations

import copy
import json
import tomllib

import numpy as np
import pytest

import lavendersim as lv
from lavendersim import cli
from lavendersim import scene_file as SF
from lavendersim import spacecraft as S
from lavendersim.validate import LavenderInputError

SKEW3 = """
name = "3U with three skewed wheels"

[body]
name = "bus"
mass = 4.0
inertia = [[0.045, -0.002, 0.001],
           [-0.002, 0.04, 0.0015],
           [0.001, 0.0015, 0.012]]

[body.wheels]
axes_b = [[1.0, 0.2, 0.1], [0.1, 1.0, -0.2], [-0.2, 0.1, 1.0]]   # skewed: neither unit nor orthogonal
J = [1.5e-5, 1.5e-5, 1e-5]
torque_limit = 0.001
speed_limit = 800.0
motor = "line"

[controller]
period = 0.2                  # 5 Hz
delay = 0.04

[controller.weights]
attitude_deg = 1.0
rate = 0.02

[sensors]
attitude_noise = 5e-5
gyro_noise = 1e-5
gyro_bias = 1e-5
wheel_speed_noise = 0.1
seed = 7

[actuator]
lag = 0.05

[maneuver]
angle_deg = 30.0
axis = [-1.0, 0.5, 2.0]
duration = 60.0
settle_within = 40.0

[simulator]
dt = 0.01

[monte_carlo]
n = 2
inertia_uncertainty = 0.1
seed = 3
"""


@pytest.fixture(scope="module")
def skew3_dict():
    return tomllib.loads(SKEW3)


@pytest.fixture(scope="module")
def skew3_file(tmp_path_factory):
    p = tmp_path_factory.mktemp("sc") / "skew3.toml"
    p.write_text(SKEW3, encoding="utf-8")
    return p


# ---------------------------------------------------------------------------------------------
# reading
# ---------------------------------------------------------------------------------------------


def test_shipped_files():
    assert set(S.shipped()) == {"cubesat6u", "cube_center", "cube_corner", "cube_pyramid4"}
    sc = S.load("cubesat6u")
    assert S.load("cubesat6u.toml").source == sc.source == str(S.shipped()["cubesat6u"])
    b = sc.scene.bodies["sat"]
    assert (sc.name, sc.body, sc.n_wheels, b.mass) == ("6U CubeSat", "sat", 4, 12.0)
    np.testing.assert_allclose(b.inertia_b, [[0.2, 0.004, -0.002], [0.004, 0.25, 0.003], [-0.002, 0.003, 0.08]],
                               rtol=0, atol=1e-16)
    w = sc.scene.model_effects("sat")["reaction_wheels"].values
    np.testing.assert_allclose(np.linalg.norm(w["axes_b"], axis=1), 1.0, atol=1e-15)    # written (√2, 0, 1): scaled
    np.testing.assert_allclose(w["axes_b"].T @ w["axes_b"], np.eye(3) * 4 / 3, atol=1e-15)   # the pyramid
    assert (w["J"].tolist(), float(w["torque_limit"]), float(w["speed_limit"])) == ([3e-5] * 4, 0.002, 600.0)
    assert sc.controller.period == 0.1 and sc.maneuver.angle_deg == 30.0
    np.testing.assert_allclose(np.degrees(2 * np.arccos(abs(sc.q0[3]))), 30.0, atol=1e-12)
    # a shape without inertia is the uniform solid (the chapter's cube), the corner's q is its q_ref
    c = S.load("cube_corner")
    np.testing.assert_allclose(c.scene.bodies["cube"].I_b, 1.0 * (0.15 ** 2 + 0.15 ** 2) / 12, rtol=1e-15)
    np.testing.assert_array_equal(c.q_ref, c.scene.bodies["cube"].x0[3:7])
    assert S.external_effects(c) == ["spherical_joint", "gravity"] and S.external_effects(sc) == []


def test_skewed_axes_are_normalized(skew3_dict):
    sc = S.from_dict(skew3_dict)
    A = sc.scene.model_effects("bus")["reaction_wheels"].values["axes_b"]
    raw = np.array(skew3_dict["body"]["wheels"]["axes_b"])
    np.testing.assert_allclose(A, raw / np.linalg.norm(raw, axis=1)[:, None], rtol=1e-15)
    assert (sc.controller.period, sc.controller.delay, sc.actuator_lag) == (0.2, 0.04, 0.05)
    assert sc.sensors == {"attitude_noise": 5e-5, "gyro_noise": 1e-5, "wheel_speed_noise": 0.1,
                          "gyro_bias": (1e-5, 1e-5, 1e-5), "seed": 7}


def _set(path, value):
    """A mutation of the file dict: set (or with value DEL, delete) the key at a dotted path."""
    def apply(d):
        keys = path.split(".")
        for k in keys[:-1]:
            d = d[int(k)] if isinstance(d, list) else d.setdefault(k, {})
        if value is DEL:
            del d[keys[-1]]
        elif isinstance(d, list):
            d[int(keys[-1])] = value
        else:
            d[keys[-1]] = value
    return apply


DEL = object()

BAD = [  # (mutation, the key path the error names, a piece of the rule)
    (_set("controler", {"period": 1}), "controler", "unknown key"),
    (_set("scene_format", 2), "scene_format", "reads scene_format 1"),
    (_set("name", 3), "name", "non-empty string"),
    (_set("body", []), "body", "non-empty array of tables"),
    (_set("body.masss", 1.0), "body.masss", "did you mean 'mass'"),
    (_set("body.mass", -1.0), "body.mass", "> 0"),
    (_set("body.mass", "12"), "body.mass", "expected a real number"),
    (_set("body.mass", True), "body.mass", "not a bool"),
    (_set("body.name", ""), "body.name", "non-empty string"),
    (_set("body.inertia", DEL), "body.inertia", "is required"),
    (_set("body.inertia", [[0.045, 0.0, 0.0], [0.0, 0.04, 0.0]]), "body.inertia", "at least 3 and at most 3 rows"),
    (_set("body.inertia", [[0.045, 0.01, 0.0], [0.0, 0.04, 0.0], [0.0, 0.0, 0.012]]), "body.inertia", "symmetric"),
    (_set("body.inertia", [[1.0, 2.0, 0.0], [2.0, 1.0, 0.0], [0.0, 0.0, 1.0]]), "body.inertia", "positive"),
    (_set("body.inertia", [0.01, 0.01, 0.05]), "body.inertia", "triangle inequality"),
    (_set("body.com_offset", [0.1, 0.2]), "body.com_offset", "shape (3,)"),
    (_set("body.com_offset", [0.0, 0.0, 0.2]), "body.inertia", ""),     # 4 kg 0.2 m off: I_o too small for it
    (_set("body.q", [0.0, 0.0, 0.0, 0.0]), "body.q", "zero quaternion"),
    (_set("body.omega_b", [0.0, float("nan"), 0.0]), "body.omega_b", "finite"),
    (_set("body.shape", {"kind": "cone", "dims": [1.0]}), "body.shape.kind", "unknown name 'cone'"),
    (_set("body.shape", {"kind": "box", "dims": [0.1, -0.2, 0.3]}), "body.shape.dims[1]", "> 0"),
    (_set("body.shape", {"kind": "box", "dims": [0.1, 0.2]}), "body.shape.dims", "shape (3,)"),
    (_set("body.shape", {"kind": "box"}), "body.shape.dims", "is required"),
    (_set("body.wheels", DEL), "controller.body", "no body has wheels"),
    (_set("body.wheels.axes_b.2", [0.0, 0.0]), "body.wheels.axes_b[2]", "shape (3,)"),
    (_set("body.wheels.axes_b.1", [0.0, 0.0, 0.0]), "body.wheels.axes_b[1]", "non-zero"),
    (_set("body.wheels.axes_b.0", [1.0, "x", 0.0]), "body.wheels.axes_b[0]", "real numbers"),
    (_set("body.wheels.axes_b", [[1.0, 0.0, 0.0]] * 5), "body.wheels.axes_b", "at most 4 rows"),
    (_set("body.wheels.axes_b", 1.0), "body.wheels.axes_b", "list of rows"),
    (_set("body.wheels.J", [1.5e-5, 1.5e-5]), "body.wheels.J", "shape (3,)"),
    (_set("body.wheels.J", [1.5e-5, -1.0, 1e-5]), "body.wheels.J[1]", "> 0"),
    (_set("body.wheels.J", 0.0), "body.wheels.J", "> 0"),
    (_set("body.wheels.J", 0.03), "body.wheels.J", "positive definite"),
    (_set("body.wheels.torque_limit", 0.0), "body.wheels.torque_limit", "> 0"),
    (_set("body.wheels.speed_limit", -5.0), "body.wheels.speed_limit", "> 0"),
    (_set("body.wheels.speed_limit", DEL), "body.wheels.speed_limit", "is required"),
    (_set("body.wheels.c_w", -1e-6), "body.wheels.c_w", ">= 0"),
    (_set("body.wheels.motor", "linear"), "body.wheels.motor", "unknown name 'linear'"),
    (_set("body.wheels.speed", 3.0), "body.wheels.speed", "unknown key"),
    (_set("body.joint", {"anchor": [0.0, 0.0, 0.0]}), "body.joint.anchor", "unknown key"),
    (_set("effects", [{"name": "gravit"}]), "effects[0].name", "did you mean 'gravity'"),
    (_set("effects", [{"name": "reaction_wheels"}]), "effects[0].name", "[body.wheels]"),
    (_set("effects", [{"name": "gravity", "body": "nope"}]), "effects[0].body", "unknown body 'nope'"),
    (_set("effects", [{"name": "applied_torque", "torque_w": [1.0, 2.0]}]), "effects[0].torque_w", "shape (3,)"),
    (_set("effects", [{"name": "angular_damping", "c": 0.1, "k": 1.0}]), "effects[0].k", "unknown parameter"),
    (_set("effects", [{"body": "bus"}]), "effects[0].name", "is required"),
    (_set("effects", {"name": "gravity"}), "effects", "array of tables"),
    (_set("controller", DEL), "controller.period", "is required"),
    (_set("controller.period", 0.0), "controller.period", "> 0"),
    (_set("controller.delay", 0.5), "controller.delay", "at most the period"),
    (_set("controller.delay", -0.01), "controller.delay", ">= 0"),
    (_set("controller.Q", [1.0, 2.0, 3.0]), "controller.Q", "shape (9,)"),
    (_set("controller.Q", [[float(i == j) + (i == 0 and j == 1) for j in range(9)] for i in range(9)]),
     "controller.Q", "symmetric"),
    (_set("controller.Q", [1.0] * 8 + [-1.0]), "controller.Q[8]", ">= 0"),
    (_set("controller.R", [1.0, 0.0, 1.0]), "controller.R[1]", "> 0"),
    (_set("controller.R", 0.0), "controller.R", "> 0"),
    (_set("controller.weights.attitude", 1.0), "controller.weights.attitude", "unknown key"),
    (_set("controller.weights.rate", 0.0), "controller.weights.rate", "> 0"),
    (_set("controller.q_ref", [0.0, 0.0, 1.0]), "controller.q_ref", "shape (4,)"),
    (_set("controller.null_bias", 10.0), "controller.null_bias", "null space"),
    (_set("controller.body", "nope"), "controller.body", "[body.wheels]"),
    (_set("sensors.gyro_noise", -1.0), "sensors.gyro_noise", ">= 0"),
    (_set("sensors.seed", 1.5), "sensors.seed", "integer"),
    (_set("sensors.gyro_bias", [1e-5, 2e-5]), "sensors.gyro_bias", "shape (3,)"),
    (_set("sensors.star_tracker", 1.0), "sensors.star_tracker", "unknown key"),
    (_set("actuator", 3), "actuator", "must be a table"),
    (_set("actuator.lag", -0.1), "actuator.lag", ">= 0"),
    (_set("maneuver", DEL), "maneuver.angle_deg", "is required"),
    (_set("maneuver.angle_deg", 200.0), "maneuver.angle_deg", "±180"),
    (_set("maneuver.axis", [0.0, 0.0, 0.0]), "maneuver.axis", "non-zero"),
    (_set("maneuver.duration", 0.0), "maneuver.duration", "> 0"),
    (_set("maneuver.settle_within", -1.0), "maneuver.settle_within", "> 0"),
    (_set("maneuver.Omega0", [0.0, 0.0]), "maneuver.Omega0", "one speed per wheel"),
    (_set("simulator.dt", 0.03), "simulator.dt", "controller period"),
    (_set("simulator.dt", 0.025), "simulator.dt", "controller delay"),
    (_set("simulator.dt", 5e-324), "simulator.dt", "at most 10,000 steps"),
    (_set("controller.period", 1e308), "simulator.dt", "at most 10,000 steps"),
    (_set("simulator.integrator", "rk4"), "simulator.integrator", "unknown key"),
    (_set("monte_carlo.n", 0), "monte_carlo.n", ">= 1"),
    (_set("monte_carlo.inertia_uncertainty", 0.6), "monte_carlo.inertia_uncertainty", "below 0.5"),
]
IDS = [f"{i}-{field}" for i, (_, field, _) in enumerate(BAD)]


@pytest.mark.parametrize("mutate, field, rule", BAD, ids=IDS)
def test_every_bad_key_is_named(skew3_dict, mutate, field, rule):
    d = copy.deepcopy(skew3_dict)
    mutate(d)
    with pytest.raises(LavenderInputError) as exc:
        S.from_dict(d)
    assert exc.value.field == field, str(exc.value)
    assert rule in str(exc.value)


@pytest.mark.parametrize("mutate, field, rule", BAD[::3], ids=IDS[::3])
def test_cli_bad_file_is_one_line_exit_2(skew3_dict, tmp_path, capsys, mutate, field, rule):
    d = copy.deepcopy(skew3_dict)
    mutate(d)
    path = tmp_path / "bad.toml"
    path.write_text(SF.dumps(d), encoding="utf-8")
    assert cli.main(["lqr", "--spacecraft", str(path)]) == 2
    out, err = capsys.readouterr()
    assert out == "" and len(err.strip().splitlines()) == 1 and "Traceback" not in err
    assert err.startswith(f"lavendersim lqr: {path}: {field}: ") and rule in err


@pytest.mark.parametrize("argv, text", [
    (["--spacecraft", "missing.toml"], "missing.toml: cannot be read"),
    (["--spacecraft", "BADTOML"], "is not valid TOML"),
    (["--spacecraft", "GOOD", "--layout", "pyramid4"], "--layout: takes no --spacecraft"),
    (["--layout", "pyramid4", "--scenario", "corner"], "--scenario: --layout pyramid4 is a free cube"),
    (["--spacecraft", "GOOD", "--dask", "tcp://127.0.0.1:1"], "--dask: needs --monte-carlo N"),
    (["--spacecraft", "GOOD", "--monte-carlo", "0"], "--monte-carlo: must be an integer >= 1"),
    (["--spacecraft", "GOOD", "--plot", "THROUGHFILE"], "--plot: cannot write"),
])
def test_cli_usage_errors(tmp_path, capsys, skew3_file, argv, text):
    bad = tmp_path / "bad.toml"
    bad.write_text("[body]\nname = 'x'\nmass = = 1\n", encoding="utf-8")
    sub = {"BADTOML": str(bad), "GOOD": str(skew3_file), "THROUGHFILE": f"{bad}/p.png"}   # a path through a file
    argv = [sub.get(a, a) for a in argv]
    assert cli.main(["lqr", *argv]) == 2
    _, err = capsys.readouterr()
    assert len(err.strip().splitlines()) == 1 and text in err and "Traceback" not in err


# ---------------------------------------------------------------------------------------------
# the scene part: scene_to_dict / scene_from_dict / TOML text
# ---------------------------------------------------------------------------------------------


def _two_body_scene():
    scene = lv.Scene()
    scene.add_body(lv.Body("sat", 12.0, [[0.2, 0.004, -0.002], [0.004, 0.25, 0.003], [-0.002, 0.003, 0.08]],
                           q=[0.1, -0.2, 0.3, 0.9], omega_b=[0.01, -0.02, 0.03], p_w=[1.0, 2.0, 3.0]))
    scene.add_body(lv.Body.box("rod", mass=1.0, size=(0.8, 0.2, 0.2), v_w=[0.0, 0.1, 0.0], omega_b=[0.0, 0.0, 2.0]))
    scene.add_body(lv.Body("pend", 2.0, [0.02, 0.03, 0.04], p_w=[0.0, 0.0, -0.5]))
    axes = np.array([[1.0, 0.2, 0.1], [0.1, 1.0, -0.2], [-0.2, 0.1, 1.0], [1.0, 1.0, 1.0]])
    scene.add_effect("reaction_wheels", body="sat", axes_b=axes / np.linalg.norm(axes, axis=1)[:, None],
                     J=[3e-5, 3e-5, 2e-5, 1e-5], torque_limit=0.002, speed_limit=600.0, c_w=1e-7, cutoff=1.0)
    scene.add_effect("spherical_joint", body="pend", anchor_w=[0.0, 0.0, 0.0])
    scene.add_effect("reaction_wheels", body="pend", J=[1e-4, 1e-4, 1e-4], torque_limit=0.1, speed_limit=300.0)
    scene.add_effect("gravity", body=None, g_w=[0.0, 0.0, -9.81])
    scene.add_effect("applied_torque", body="rod", torque_w=[0.0, 0.0, 0.02])
    scene.add_effect("angular_damping", body="sat", c=1e-4)
    return scene


def _close(a, b, path=""):
    """Equal dicts, every float bit for bit (a full tensor too: Body keeps it as given)."""
    assert type(a) is type(b), path
    if isinstance(a, dict):
        assert list(a) == list(b), path
        for k in a:
            _close(a[k], b[k], f"{path}.{k}")
    elif isinstance(a, list):
        assert len(a) == len(b), path
        for i, (x, y) in enumerate(zip(a, b)):
            _close(x, y, f"{path}[{i}]")
    else:
        assert a == b, path


def test_scene_round_trip_through_toml_text(tmp_path):
    scene = _two_body_scene()
    d = SF.scene_to_dict(scene)
    text = SF.dumps(d)
    assert tomllib.loads(text) == d                        # the writer is exact for what a scene holds
    assert "[[body]]" in text and "[body.wheels]" in text and "[body.joint]" in text and "[[effects]]" in text
    again = SF.scene_from_dict(tomllib.loads(text))
    _close(SF.scene_to_dict(again), d)
    assert [b.name for b in again.bodies.values()] == ["sat", "rod", "pend"]
    assert sorted((e.name, str(e.body)) for e in again.effects) == sorted((e.name, str(e.body)) for e in scene.effects)
    for name, b in scene.bodies.items():                   # tensors and states bit for bit
        c = again.bodies[name]
        np.testing.assert_array_equal(c.x0, b.x0)
        np.testing.assert_array_equal(c.inertia_b, b.inertia_b)
    assert again.bodies["rod"].shape == scene.bodies["rod"].shape
    # the same scene steps the same: 200 RK4 steps with the wheels commanded
    sims = [lv.Sim(s, dt=1e-3, integrator="rk4", backend="numpy") for s in (scene, again)]
    for sim in sims:
        sim.set_wheel_command("sat", [1e-3, -1e-3, 5e-4, 0.0])
        sim.run(200)
    for name in scene.bodies:
        np.testing.assert_array_equal(sims[1].state(name).x, sims[0].state(name).x)
    # save / load
    path = SF.save(scene, tmp_path / "scene.toml")
    _close(SF.scene_to_dict(SF.load(path)), d)
    SF.save(scene, tmp_path / "again.toml")
    _close(SF.scene_to_dict(SF.load(tmp_path / "again.toml")), d)
    assert (tmp_path / "again.toml").read_text(encoding="utf-8") == text
    # the scene part of a spacecraft file
    sat = SF.load(S.shipped()["cubesat6u"])
    _close(SF.scene_to_dict(sat), SF.scene_to_dict(S.load("cubesat6u").scene))


def test_dumps_strings_and_keys():
    d = {"a b": 'quote " back \\ nl \n tab \t ctl \x01 é', "x": [1, 2.5, -0.0, 1e-300, True], "t": {"k": "v"},
         "arr": [{"n": 1}, {"n": 2, "sub": {"z": [[1.0, 2.0], [3.0, 4.0]]}}], "empty": []}
    assert tomllib.loads(SF.dumps(d)) == d


def test_com_offset_moves_cad_inertia_to_the_com():
    I_com = np.array([[0.2, 0.004, -0.002], [0.004, 0.25, 0.003], [-0.002, 0.003, 0.08]])
    m, c = 12.0, np.array([0.01, -0.02, 0.05])
    from lavendersim.kernels import K

    I_ref = np.asarray(K.parallel_axis(I_com, m, -c), dtype=float).reshape(3, 3)   # about the reference point
    d = {"body": {"name": "sat", "mass": m, "inertia": I_ref.tolist(), "com_offset": c.tolist()}}
    b = SF.scene_from_dict(d).bodies["sat"]
    np.testing.assert_allclose(b.inertia_b, I_com, rtol=0, atol=1e-15)


# ---------------------------------------------------------------------------------------------
# flying: `lavendersim lqr --spacecraft`
# ---------------------------------------------------------------------------------------------


def _run(capsys, *argv):
    code = cli.main(["lqr", *argv, "--json"])
    out, err = capsys.readouterr()
    assert code == 0, err
    return json.loads(out)


def _check_flight(fig, *, drift=True):
    f, m = fig["figures"], fig["maneuver"]
    assert f["settling_time"] is not None and f["settling_time"] <= m["settle_within"]
    assert f["settled_within"] is True and f["final_error_deg"] < m["settle_threshold_deg"]
    assert f["within_limits"]
    assert max(f["peak_torque"]) <= f["torque_limit"] * (1 + 1e-12)
    assert max(f["peak_wheel_speed"]) < f["speed_limit"]
    if drift:
        assert f["external_effects"] == [] and f["L_drift"] <= 1e-9
    d = fig["design"]
    assert d["max_pole_modulus"] < 1.0 and len(d["poles_real"]) == d["controllability_rank"]


@pytest.mark.needs("control")
@pytest.mark.parametrize("noise", [False, True], ids=["sensors-off", "sensors-on"])
def test_cubesat_slew(capsys, noise):
    fig = _run(capsys, "--spacecraft", "cubesat6u", *([] if noise else ["--no-noise"]))
    assert (fig["spacecraft"], fig["wheels"], fig["maneuver"]["angle_deg"]) == ("6U CubeSat", 4, 30.0)
    assert fig["design"]["period"] == 0.1 and fig["design"]["delay"] == 0.01 and fig["design"]["actuator_lag"] == 0.02
    _check_flight(fig, drift=not noise)
    if not noise:
        assert fig["figures"]["final_error_deg"] < 1e-6        # perfect sensors: the error keeps shrinking (6e-9° at 60 s)
    else:
        assert fig["sensors"]["seed"] == 1 and fig["figures"]["final_error_deg"] > 1e-6   # noise shows


@pytest.mark.needs("control")
def test_own_spacecraft_skewed_wheels_5hz(capsys, skew3_file, tmp_path):
    plot = tmp_path / "skew.png"
    fig = _run(capsys, "--spacecraft", str(skew3_file), "--no-noise", "--plot", str(plot))
    assert (fig["wheels"], fig["design"]["period"]) == (3, 0.2)
    _check_flight(fig)
    assert plot.stat().st_size > 10_000
    noisy = _run(capsys, "--spacecraft", str(skew3_file))
    _check_flight(noisy, drift=False)
    assert noisy["figures"]["L_drift"] <= 1e-9                  # internal torques: noise cannot change |L|


@pytest.mark.needs("control")
def test_scenario_and_layout_aliases_keep_their_figures(capsys, tmp_path):
    """The figures `lavendersim lqr` printed before the spacecraft files (at 3547e81, saved in the session's
    notes): centre 0.392 s, corner 0.160 s (now 0.162: the discrete design at the 2 ms period, one
    sample later), pyramid4 0.43 s with peak wheel speeds 23.0227 rad/s."""
    c = _run(capsys, "--scenario", "center")["figures"]
    assert c["settling_time"] == pytest.approx(0.392, abs=1e-9) and c["peak_torque_max"] == pytest.approx(0.2)
    assert c["peak_wheel_speed_max"] == pytest.approx(16.27, abs=0.3)      # before: 16.489 (continuous design)
    k = _run(capsys, "--scenario", "corner")["figures"]
    assert k["settling_time"] == pytest.approx(0.160, abs=0.0041) and k["external_effects"] == ["spherical_joint", "gravity"]
    plot = tmp_path / "p4.png"
    p = _run(capsys, "--layout", "pyramid4", "--plot", str(plot))
    f = p["figures"]
    assert f["settling_time"] == pytest.approx(0.43, abs=1e-9)
    np.testing.assert_allclose(f["peak_wheel_speed"], [23.022711093184512] * 4, rtol=1e-9)
    np.testing.assert_allclose(f["peak_torque"], [0.2, 0.2, 0.1893726819785979, 0.034280827792586954], rtol=1e-9)
    assert f["L_drift"] <= 1e-9 and plot.stat().st_size > 10_000          # --plot works for any layout


@pytest.mark.needs("control")
def test_monte_carlo(skew3_dict, capsys, skew3_file):
    d = copy.deepcopy(skew3_dict)
    d["maneuver"]["duration"] = 30.0
    sc = S.from_dict(d)
    ctrl = S.design(sc)
    a = S.monte_carlo(sc, ctrl, 2)
    b = S.monte_carlo(sc, ctrl, 2)
    assert json.dumps(a) == json.dumps(b)                     # seeded: the same runs again
    assert (a["n"], a["failures"], a["settled_within"], a["settle_within"], a["inertia_spread"]) == (2, 0, 2, 40.0, 0.1)
    r0, r1 = a["samples"]
    assert r0["inertia_scale"] != r1["inertia_scale"] and (r0["seed"], r1["seed"]) == (7 + 3, 7 + 3 + 1)
    assert r0["settling_time"] != r1["settling_time"]           # two different plants
    assert max(r0["peak_torque"], r1["peak_torque"]) <= 0.001 * (1 + 1e-12)
    out = _run(capsys, "--spacecraft", str(skew3_file), "--monte-carlo", "2", "--workers", "1")
    mc = out["monte_carlo"]
    assert (mc["n"], mc["seed"], mc["inertia_spread"]) == (2, 3, 0.1) and "samples" not in mc
    assert mc["settled_within"] == 2 and mc["settling_time"]["p100"] <= 40.0


@pytest.fixture(scope="module")
def short_mc(skew3_dict):
    d = copy.deepcopy(skew3_dict)
    d["maneuver"]["duration"] = 15.0
    d["maneuver"].pop("settle_within")
    sc = S.from_dict(d)
    ctrl = S.design(sc)
    return sc, ctrl, S.monte_carlo(sc, ctrl, 2)


@pytest.mark.needs("control")
def test_monte_carlo_on_two_local_processes_is_identical(short_mc):
    from lavendersim import executor as X

    sc, ctrl, serial = short_mc
    assert serial["failures"] == 0
    assert json.dumps(S.monte_carlo(sc, ctrl, 2, executor=X.Executor(X.PROCESSES, 2))) == json.dumps(serial)


@pytest.mark.needs("control", "distributed")
def test_monte_carlo_on_a_local_dask_cluster_is_identical(short_mc):
    from dask.distributed import LocalCluster

    from lavendersim import executor as X

    sc, ctrl, serial = short_mc
    with LocalCluster(n_workers=2, threads_per_worker=1, processes=True, dashboard_address=None) as cluster:
        got = S.monte_carlo(sc, ctrl, 2, executor=X.resolve(dask=cluster.scheduler_address))
    assert json.dumps(got) == json.dumps(serial)


@pytest.mark.needs("control")
def test_cli_a_design_the_solver_refuses_is_one_line_exit_2(skew3_dict, tmp_path, capsys):
    d = copy.deepcopy(skew3_dict)
    d["controller"]["Q"] = 0.0          # nothing to regulate: the Riccati equation has no stabilizing solution
    path = tmp_path / "q0.toml"
    path.write_text(SF.dumps(d), encoding="utf-8")
    assert cli.main(["lqr", "--spacecraft", str(path)]) == 2
    _, err = capsys.readouterr()
    assert len(err.strip().splitlines()) == 1 and f"{path}: controller: the LQR design failed" in err


@pytest.mark.needs("control")
def test_design_errors_name_the_file_keys():
    d = tomllib.loads(S.shipped()["cubesat6u"].read_text(encoding="utf-8"))
    d["controller"]["null_bias"] = 1e6           # beyond the 600 rad/s speed limit: found by control.design
    with pytest.raises(LavenderInputError) as exc:
        S.design(S.from_dict(d))
    assert exc.value.field == "controller.null_bias" and "below speed_limit" in str(exc.value)
