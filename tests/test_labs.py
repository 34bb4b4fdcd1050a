"""The chapter's labs: figures against SPEC tolerances, files written, paw-checks, CLI exit codes."""
from __future__ import annotations

import json
import subprocess
import sys

import numpy as np
import pytest

from lavendersim import labs
from lavendersim import particles as P
from lavendersim.labs import common as C
from lavendersim.validate import LavenderInputError


def _files_ok(result, pngs):
    d = result.out_dir
    data = json.loads((d / "results.json").read_text())
    assert data == json.loads(json.dumps(dict(result)))  # the returned dict is what was written
    assert all(not isinstance(v, dict) for v in data.values())  # flat
    for name in pngs:
        p = d / name
        assert p.exists() and p.stat().st_size > 1000
        assert p.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    return data


# A test that checks a lab's numbers, not its files, computes it (labs.compute: no PNG drawn, ~0.5-1.5 s CPU each); the
# files of every lab are checked by the tests that run it (labs.run: compute + save) with its chapter parameters.


def _passed(result):
    assert result.passed, "; ".join(c.describe() for c in result.failures)
    assert result["passed"] is True
    assert all(result[f"check_{c.name}"] for c in result.checks)


# ---------------------------------------------------------------------------------- force


def test_force_lab(tmp_path):
    r = labs.run("force", tmp_path, backend="numpy")
    _passed(r)
    data = _files_ok(r, ["force.png"])
    assert np.max(np.abs(np.array(data["torque"]) - [0.0, 0.0, 1.5])) <= 1e-12
    assert np.max(np.abs(data["torque_along_lever_arm"])) <= 1e-12
    assert np.max(np.abs(np.array(data["torque_at_minus_offset"]) - [0.0, 0.0, -1.5])) <= 1e-12  # paw-check 2
    assert data["alpha_rel_error"] <= 1e-8 and data["alpha_tilted_rel_error"] <= 1e-8
    assert data["r_w"] == [0.3, 0.0, 0.0] and data["F_w"] == [0.0, 5.0, 0.0]


# ---------------------------------------------------------------------------------- momentum


def test_momentum_lab(tmp_path):
    r = labs.run("momentum", tmp_path, backend="numpy")
    _passed(r)
    data = _files_ok(r, ["momentum.png"])
    # paw-check 1: doubling the masses
    assert data["scaled_com_w"] == data["com_w"]
    assert data["scaled_com_velocity_w"] == data["com_velocity_w"]
    assert data["scaled_p_w"] == [2 * x for x in data["p_w"]]
    assert data["scaled_L_com_w"] == [2 * x for x in data["L_com_w"]]
    assert data["L_minus_I_omega_rel"] <= 1e-12


def test_particles_module():
    m = [1.0, 3.0]
    r = [[0.0, 0.0, 0.0], [4.0, 0.0, 0.0]]
    v = [[0.0, 1.0, 0.0], [0.0, -1.0, 0.0]]
    assert P.total_mass(m) == 4.0
    np.testing.assert_allclose(P.center_of_mass(m, r), [3.0, 0.0, 0.0])
    np.testing.assert_allclose(P.linear_momentum(m, v), [0.0, -2.0, 0.0])
    # L about the COM: (-3,0,0) x 1*(0,1.5,0) + (1,0,0) x 3*(0,-0.5,0) = (0,0,-4.5) + (0,0,-1.5)
    np.testing.assert_allclose(P.angular_momentum_com(m, r, v), [0.0, 0.0, -6.0])
    with pytest.raises(LavenderInputError, match="m"):
        P.total_mass([1.0, -1.0])
    with pytest.raises(LavenderInputError, match="r_w"):
        P.center_of_mass([1.0, 2.0], [[0, 0, 0]])
    with pytest.raises(LavenderInputError, match="v_w"):
        P.linear_momentum([1.0], [[0, 0, np.nan]])
    with pytest.raises(LavenderInputError):
        P.total_mass([])


# ---------------------------------------------------------------------------------- 01


def _check_lab01(r):
    _passed(r)
    data = _files_ok(r, ["equal_torque.png"])
    assert abs(data["alpha_cube"] - 3.0) <= 1e-9 and abs(data["alpha_cube_sim"] - 3.0) <= 1e-9
    assert abs(data["alpha_rod"] - 0.02 / (0.68 / 12)) <= 1e-9 and abs(data["alpha_rod_sim"] - 0.352941176470588) <= 1e-9
    assert abs(data["omega_ratio"] - 8.5) <= 1e-9
    # paw-check 3: the rod rotated 90° about y responds like the cube
    assert abs(data["paw3_alpha_rod_y90"] - data["alpha_cube"]) <= 1e-9
    assert abs(data["paw3_alpha_rod_y90_sim"] - data["alpha_cube"]) <= 1e-9
    I_w = np.array(data["paw3_I_w_rod_y90"]).reshape(3, 3)
    assert abs(I_w[2, 2] - 1 / 150) <= 1e-15


def test_lab01_numpy(tmp_path):
    _check_lab01(labs.run("01", tmp_path, backend="numpy"))


def test_lab01_c_backend(tmp_path):
    _check_lab01(labs.run("01", tmp_path, backend="c"))


def test_lab01_damping_failure_mode():
    r = labs.compute("01", backend="numpy", damping=0.01)
    _passed(r)
    assert abs(r["omega_ratio"] - 8.5) > 0.1  # no longer the inertia ratio
    assert r["omega_ratio"] != pytest.approx(r["omega_ratio_at_half_time"], abs=1e-3)  # and not constant
    assert "check_omega_ratio" not in r


def test_lab01_euler_failure_mode():
    r = labs.compute("01", backend="numpy", integrator="euler")
    _passed(r)
    assert r["integration_error"] > 1e-6  # the rotation angle is off
    assert abs(r["omega_ratio"] - 8.5) <= 1e-9  # omega itself is linear in t: still exact


def test_lab01_rejects_bad_options(tmp_path):
    with pytest.raises(LavenderInputError, match="dt"):
        labs.run("01", tmp_path, backend="numpy", dt=0.003)  # 0.1 s is not a whole number of steps
    with pytest.raises(LavenderInputError, match="integrator"):
        labs.run("01", tmp_path, backend="numpy", integrator="rk5")
    with pytest.raises(LavenderInputError, match="backend"):
        labs.run("01", tmp_path, backend="fortran")


# ---------------------------------------------------------------------------------- 02


def test_lab02(tmp_path):
    r = labs.run("02", tmp_path, backend="numpy")
    _passed(r)
    data = _files_ok(r, ["orientation.png"])
    assert abs(data["naive_euler_error_deg"] - 87.63) <= 0.05
    assert abs(data["quaternion_error_deg"] - 0.00866) <= 0.00005
    assert abs(data["unnormalized_norm"] - 1.01379) <= 0.00005
    assert data["omega_w"] == [1.2, 0.7, 0.9] and data["dt"] == 0.01 and data["T"] == 4.0
    # paw-check 4: body form with q ⊗ [w_b, 0] matches the world form; the wrong order diverges
    assert data["paw4_body_vs_world_max_abs"] <= 1e-12
    assert data["paw4_wrong_order_error_deg"] > 1.0


def test_lab02_single_axis_hides_the_bug():
    r = labs.compute("02", backend="numpy", single_axis=True)
    _passed(r)
    assert r["naive_euler_error_deg"] <= 1e-9
    assert abs(r["quaternion_error_deg"] - 0.00866) <= 0.00005  # depends only on |omega|


def test_lab02_larger_dt_increases_quaternion_error():
    r = labs.compute("02", backend="numpy", dt=0.02)
    _passed(r)
    assert r["quaternion_error_deg"] > 3 * r["quaternion_error_deg_at_dt_0.01"]  # ~dt^2


# ---------------------------------------------------------------------------------- 03


def _check_lab03(r):
    _passed(r)
    data = _files_ok(r, ["torque_free.png"])
    assert data["principal_omega_change"] <= 1e-12 and data["principal_omega_change_max"] <= 1e-12
    assert abs(data["mixed_omega_change"] - 3.30) <= 0.005
    assert abs(data["mixed_omega_change"] - data["mixed_omega_change_closed_form"]) <= 1e-9
    assert data["momentum_error"] < 4e-7
    assert data["momentum_error"] < 1e-10  # the float64 figure
    assert data["energy_error"] < 1e-10
    # paw-check 5: the intermediate axis is the least forgiving
    assert data["paw5_intermediate_axis"] == "y" and data["paw5_least_forgiving_axis"] == "y"
    assert data["paw5_max_deviation_y"] > 10 * max(data["paw5_max_deviation_x"], data["paw5_max_deviation_z"])
    assert data["omega_b0_mixed"] == [3.0, 2.0, 1.0] and data["T"] == 3.0


@pytest.mark.slow   # the same lab on NumPy; test_lab03_c_backend checks the same figures
def test_lab03_numpy(tmp_path):
    _check_lab03(labs.run("03", tmp_path, backend="numpy"))


def test_lab03_c_backend(tmp_path):
    _check_lab03(labs.run("03", tmp_path, backend="c"))


def test_lab03_euler_energy_drift():
    r = labs.compute("03", backend="numpy", integrator="euler", normalize=False)
    _passed(r)
    assert r["energy_error"] > 1e-3
    assert r["quaternion_norm_max_deviation"] > 1e-4


def test_lab03_parameter_search_has_one_hit():
    hits, total = labs.lab_module("03").search_candidates()
    assert total > 10000
    assert [(h["body"].split()[0], tuple(h["omega0"]), h["T"], h["definition"]) for h in hits] == [
        ("rod", (3, 2, 1), 3, "|w(T)-w0|")]


# ---------------------------------------------------------------------------------- checking, CLI


def test_check_outside_tolerance_fails_and_names_the_figure(tmp_path, capsys):
    bad = C.close("omega_ratio", 8.4, 8.5, 1e-9, "deliberately wrong")
    good = C.at_most("torque", 0.0, 1e-12)
    r = C.finish("selftest", tmp_path, {"omega_ratio": 8.4}, {"dt": 0.001}, [good, bad], {})
    assert not r.passed and r["passed"] is False and r["check_omega_ratio"] is False
    assert json.loads((tmp_path / "selftest" / "results.json").read_text())["passed"] is False
    assert C.report(r) == 1
    err = capsys.readouterr().err
    assert "omega_ratio = 8.4" in err and "expected 8.5" in err and "1.000000e-09" in err
    assert C.report(C.finish("selftest2", tmp_path, {}, {}, [good], {})) == 0
    assert not C.close("x", float("nan"), 0.0, 1.0).passed  # non-finite never passes


def test_lab_failing_figure_exits_nonzero(tmp_path, monkeypatch):
    """A deliberately wrong expectation inside a lab makes its CLI exit 1."""
    from lavendersim import cli

    mod = labs.lab_module("force")
    monkeypatch.setattr(mod, "TAU_EXPECTED", (0.0, 0.0, 1.6))
    assert cli.main(["lab", "force", "--out", str(tmp_path), "--backend", "numpy"]) == 1


def test_cli_smoke(tmp_path):
    out = subprocess.run([sys.executable, "-m", "lavendersim.cli", "lab", "force", "--out", str(tmp_path),
                          "--backend", "numpy"], capture_output=True, text=True, timeout=300)
    assert out.returncode == 0, out.stderr
    assert "torque = [0, 0, 1.5]" in out.stdout
    assert (tmp_path / "force" / "results.json").exists()


def test_cli_bad_option_exits_2(tmp_path):
    out = subprocess.run([sys.executable, "-m", "lavendersim.cli", "lab", "02", "--out", str(tmp_path),
                          "--backend", "numpy", "--dt", "0.003"], capture_output=True, text=True, timeout=300)
    assert out.returncode == 2 and "dt" in out.stderr


@pytest.mark.slow   # every lab end to end on NumPy (minutes); each lab has its own faster tests here
def test_cli_all(tmp_path):
    out = subprocess.run([sys.executable, "-m", "lavendersim.cli", "lab", "all", "--out", str(tmp_path),
                          "--backend", "numpy"], capture_output=True, text=True, timeout=3600)
    assert out.returncode == 0, out.stdout + out.stderr
    assert f"all {len(labs.LABS)} labs pass" in out.stdout
    for name in labs.LABS:
        assert (tmp_path / name / "results.json").exists()
