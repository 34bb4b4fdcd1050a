"""Lab 04 (reaction wheel): the chapter's sign checks, paw-check 6, coupling, saturation, the exact
momentum exchange, files, CLI exit codes, both backends."""
from __future__ import annotations

import json
import subprocess
import sys

import pytest

from conftest import NUMPY_SLOW, run_main
from lavendersim import labs
from lavendersim.validate import LavenderInputError


@pytest.fixture(scope="module")
def lab04(tmp_path_factory):
    """Lab 04 run at most once per backend, shared by the checks below: backend -> (result, out dir)."""
    memo = {}

    def run(backend):
        if backend not in memo:
            d = tmp_path_factory.mktemp(f"lab04_{backend}")
            memo[backend] = labs.run("04", d, backend=backend), d
        return memo[backend]
    return run


@pytest.mark.parametrize("backend", NUMPY_SLOW)   # the NumPy lab takes twice the C one: slow set
def test_lab04(lab04, backend):
    r, out = lab04(backend)
    assert r.passed, "; ".join(c.describe() for c in r.failures)
    data = json.loads((out / "04" / "results.json").read_text())
    assert data == json.loads(json.dumps(dict(r)))
    for key in ("wheel_all_positive", "cube_all_negative", "reversed_ok"):
        assert data[key] is True
    assert data["momentum_exchange_error"] <= 1e-9
    assert data["reversed_mirror_error"] == 0.0
    assert data["wheel_to_cube_rate_ratio"] > 5          # different magnitudes
    assert data["two_wheels_cross_axis_coupling"] <= 1e-9  # isotropic cube: none
    assert data["gyro_coupling_omega_y_over_omega_x"] > 0.1  # pre-spun z wheel: gyroscopic coupling
    assert data["saturation_applied_max"] == 0.2
    assert data["saturation_peak_wheel_speed"] <= 400 + data["saturation_step_increment"]
    png = out / "04" / "reaction_wheel.png"
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n" and png.stat().st_size > 1000


@pytest.mark.slow   # needs the NumPy lab; NumPy = C for wheels: test_wheels_joint.py (mixed scene)
def test_lab04_backends_agree(lab04):
    (a, _), (b, _) = lab04("c"), lab04("numpy")
    assert abs(a["omega_x_T"] - b["omega_x_T"]) < 1e-9 and abs(a["Omega_x_T"] - b["Omega_x_T"]) < 1e-9


def test_lab04_torque_option_and_bad_options(tmp_path):
    r = labs.compute("04", backend="c", torque=0.1, T=0.5)    # the numbers only: no PNG (test_lab04 checks the files)
    assert r.passed and r["Omega_x_T"] > 0 and r["omega_x_T"] < 0
    for kw, field in (({"torque": 0.3}, "torque"), ({"torque": -0.1}, "torque"), ({"T": float("nan")}, "T")):
        with pytest.raises(LavenderInputError) as e:
            labs.run("04", tmp_path, **kw)
        assert e.value.field == field


@pytest.mark.slow   # the whole lab again, through the CLI
def test_lab04_cli(tmp_path):
    p = subprocess.run([sys.executable, "-m", "lavendersim.cli", "lab", "04", "--out", str(tmp_path)],
                       capture_output=True, text=True, timeout=1800)
    assert p.returncode == 0, p.stderr
    assert "lab 04: all" in p.stdout


def test_lab04_cli_rejects_a_bad_torque(tmp_path):
    # through cli.main in this process (its parser, guard and messages); a lab's bad option in a real process, exit 2:
    # test_labs.py::test_cli_bad_option_exits_2
    p = run_main("lab", "04", "--out", tmp_path, "--torque", "0.5")
    assert p.returncode == 2 and "torque" in p.stderr
    assert not (tmp_path / "04").exists()


def test_lab04_failing_check_exits_nonzero(tmp_path, monkeypatch, capsys):
    """A reversed trend (wheel rates with the wrong sign) fails the sign checks and exits 1."""
    from lavendersim.labs import common as C
    from lavendersim.labs import lab04_reaction_wheel as L

    real = L._run

    def flipped(*a, **k):
        out = real(*a, **k)
        out["Om"] = -out["Om"]
        return out

    monkeypatch.setattr(L, "_run", flipped)
    r = L.compute(backend="c")                   # the checks only: no PNG drawn
    assert not r.passed and r["wheel_all_positive"] is False
    assert C.report(r) == 1
    assert "wheel_all_positive" in capsys.readouterr().err
