"""The hard-case catalogue (labs/hard_cases.py): every bound of issue 4's "Hard cases" asserted.

The lab runs once (C backend, every integrator in INTEGRATORS) and each test asserts the checks
of its case by name, plus direct figures; a few cases are re-run directly (NumPy backend, the
divergence report on both backends, the CLI's exit codes).
"""
from __future__ import annotations

import json
import subprocess
import sys

import numpy as np
import pytest

import lavendersim as lv
from lavendersim import backends
from lavendersim import oracle as R
from lavendersim.errors import DivergenceError
from lavendersim.labs import hard_cases as H


@pytest.fixture(scope="module")
def lab(hard_lab):
    """The session's lab hard (conftest's, shared with test_lab_library), saved once as H.run saves it; on C."""
    assert hard_lab.result["backend"] == "c", "the C backend is not built (lavendersim's rebuild message says how)"
    return hard_lab.saved()


def _checks(result, prefix):
    found = [c for c in result.checks if c.name.startswith(prefix)]
    assert found, f"no checks named {prefix}*"
    return found


def _assert_checks(result, prefix):
    bad = [c.describe() for c in _checks(result, prefix) if not c.passed]
    assert not bad, "; ".join(bad)


# ------------------------------------------------------------------------------------ the lab itself


def test_lab_files_and_survival_table(lab):
    data = json.loads((lab.out_dir / "results.json").read_text())
    assert data == json.loads(json.dumps(dict(lab)))
    png = lab.out_dir / "hard_cases.png"
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n" and png.stat().st_size > 10_000
    table = (lab.out_dir / "survival.md").read_text()
    for integ in backends.INTEGRATORS:  # every integrator is a column and has a status per trial
        assert integ in table.splitlines()[2]
        for row in lab.data["survival"]:
            assert f"survival_{row}_{integ}" in data
    assert not any("SILENT NaN" in s for row in lab.data["survival"].values() for s in row.values())
    assert lab.data["survival"]["intermediate_axis_flips"]["rk4"] == "pass"


def test_intermediate_axis_flips(lab):
    _assert_checks(lab, "intermediate_axis_flips_")
    assert lab["intermediate_axis_flips_flip_time_error"] <= 1e-3
    assert lab["intermediate_axis_flips_energy_drift"] <= 1e-10
    assert lab["intermediate_axis_flips_flip_count"] == lab["intermediate_axis_flips_flip_count_exact"] >= 8
    # the period from the flips is the exact 4K(m)/λ
    P = R.torque_free_period((1, 2, 3), (1e-3, 5, 1e-3))
    assert lab["intermediate_axis_flips_period_exact"] == P
    assert abs(lab["intermediate_axis_flips_period_from_flips"] - P) <= 1e-3


def test_fast_major_spin_rk4(lab):
    _assert_checks(lab, "fast_major_spin_energy_drift")
    assert lab["fast_major_spin_energy_drift"] <= 1e-9


def test_implicit_gyro_is_available():
    # coordinated with the integrator work: this must fail loudly (not skip) until it lands
    assert "implicit_gyro" in backends.INTEGRATORS, f"implicit_gyro missing from {list(backends.INTEGRATORS)}"


def test_fast_major_spin_implicit_gyro_never_gains_energy(lab):
    assert "implicit_gyro" in backends.INTEGRATORS
    _assert_checks(lab, "fast_major_spin_dt1e-2_")
    # direct, every step, both backends
    I_b, w0 = np.array([1.0, 2.0, 3.0]), np.array([0.5, 0.5, 50.0])
    for backend in ("c", "numpy"):
        run = H.simulate([("b", I_b, w0, H.IDENTITY)], 1e-2, 1000, 1, "implicit_gyro", backend)
        assert run.error is None, run.error
        E = 0.5 * np.sum(I_b * run.x[:, 0, 10:13] ** 2, axis=1)
        assert np.all(np.isfinite(run.x))
        assert np.all(E <= E[0] * (1 + 1e-12)), (backend, float(np.max(E / E[0] - 1)))


@pytest.mark.parametrize("trial", ["thin_rod", "extreme_ratio_symmetric", "extreme_ratio_flat"])
def test_thin_rod_and_extreme_ratios(lab, trial):
    _assert_checks(lab, f"{trial}_")
    assert lab[f"{trial}_attitude_error"] <= 3e-9 and lab[f"{trial}_omega_error"] <= 1e-9
    assert lab[f"{trial}_energy_drift"] <= 1e-10 and lab[f"{trial}_momentum_drift"] <= 1e-9
    assert lab[f"{trial}_reference_vs_dop853_attitude"] <= 1e-10


@pytest.mark.slow   # the fast_major_spin case again, on NumPy (the lab fixture runs it on C)
def test_short_trials_on_numpy_backend():
    # runs of at most C_BACKEND_ABOVE steps use the NumPy backend when asked (here implicit_gyro at dt = 1e-2)
    out = H.run_case("fast_major_spin", backend="numpy")
    bad = [c.describe() for c in out.checks if not c.passed]
    assert not bad, bad


@pytest.mark.parametrize("trial", ["near_equal_moments_12", "near_equal_moments_23"])
def test_near_equal_moments(lab, trial):
    _assert_checks(lab, f"{trial}_")
    # the departure from the symmetric body is the physical one (the exact solution's), not spurious
    dev, exact = lab[f"{trial}_omega_vs_symmetric"], lab[f"{trial}_omega_vs_symmetric_exact"]
    assert abs(dev - exact) <= 1e-12


def test_long_horizon(lab):
    _assert_checks(lab, "long_horizon_")
    assert lab["long_horizon_qnorm_deviation"] <= 1e-12


def test_dt_range(lab):
    checks = _checks(lab, "dt_range_")
    assert len(checks) == 2 * len(H.DT_RANGE)
    _assert_checks(lab, "dt_range_")
    for dt in H.DT_RANGE[:4]:  # tiny dt: only rounding, ≤ 1e-12
        assert lab[f"dt_range_moderate_dt{dt:.0e}_error"] <= 1e-12
    # the fast spin at dt = 0.1 (|ω| dt = 5) must diverge with a report, never return a NaN
    # no error figure: it raised (the check above); the figure says so instead of printing nan
    assert lab["dt_range_fast_dt1e-01_error"].startswith("not computed: the run raised DivergenceError at step")
    assert next(c for c in checks if c.name == "dt_range_fast_dt1e-01_outcome").passed


def test_near_antipodal_quaternions(lab):
    _assert_checks(lab, "antipodal_")
    assert lab["antipodal_matrix_difference"] == 0.0
    assert lab["antipodal_trajectory_sign_mismatch"] <= 1e-15


def test_euler_at_gimbal_lock(lab):
    assert all(np.isfinite(v) for k, v in lab.items() if k.startswith("gimbal_pitch_"))
    _assert_checks(lab, "gimbal_")


def test_euler_away_from_gimbal_lock_is_exact():
    # outside the ±1.4e-6 rad band around ±90° the round trip holds to ~1e-15
    res = H.gimbal_round_trip_errors()
    rng = np.random.default_rng(0)
    from lavendersim.kernels import K
    rpy = np.c_[rng.uniform(-3, 3, 500), rng.uniform(-1.5, 1.5, 500), rng.uniform(-3, 3, 500)]
    q = K.euler_xyz_to_quat(rpy[:, 0], rpy[:, 1], rpy[:, 2])
    back = K.quat_to_euler_xyz(q)
    q2 = K.euler_xyz_to_quat(back[:, 0], back[:, 1], back[:, 2])
    assert np.max(R.attitude_error(q, q2)) <= 1e-13
    assert all(fin for _, fin in res.values())  # never NaN, even at the lock


def test_body_vs_world_kinematics(lab):
    _assert_checks(lab, "body_vs_world_")
    assert lab["body_vs_world_max_difference_scaled"] <= 1e-15


@pytest.mark.parametrize("backend", ["c", "numpy"])
def test_divergence_report(backend):
    r = H.divergence_trial("euler", backend)
    err = r["error"]
    assert isinstance(err, DivergenceError), err
    assert H.message_names_all(err), str(err)
    assert "|omega|*dt" in err.cause and err.body_name == "spinner" and f"step {err.step}" in str(err)
    assert r["unchanged"] and r["finite"]


def test_divergence_report_lab(lab):
    _assert_checks(lab, "divergence_")


def test_no_silent_nan_at_huge_dt():
    # every integrator: a huge |ω|·dt either stays finite or raises DivergenceError; nothing returns NaN
    for integ in backends.INTEGRATORS:
        r = H.divergence_trial(integ, "c")
        assert r["finite"], integ
        assert r["error"] is None or isinstance(r["error"], DivergenceError), (integ, r["error"])


# ------------------------------------------------------------------------------------ CLI


@pytest.mark.slow   # three CLI runs of cases the lab fixture checks in-process; lab exit codes: test_labs.py
def test_cli_passes_and_failure_mode_exits_1(tmp_path):
    ok = subprocess.run([sys.executable, "-m", "lavendersim.cli", "lab", "hard", "--out", str(tmp_path),
                         "--cases", "fast_major_spin,long_horizon"], capture_output=True, text=True, timeout=300)
    assert ok.returncode == 0, ok.stdout + ok.stderr
    assert (tmp_path / "hard" / "survival.md").exists()
    bad = subprocess.run([sys.executable, "-m", "lavendersim.cli", "lab", "hard", "--out", str(tmp_path),
                          "--cases", "fast_major_spin", "--integrator", "euler"], capture_output=True, text=True,
                         timeout=300)
    assert bad.returncode == 1, bad.stdout + bad.stderr
    assert "fast_major_spin" in bad.stderr and "FAILED" in bad.stderr
    unknown = subprocess.run([sys.executable, "-m", "lavendersim.cli", "lab", "hard", "--out", str(tmp_path),
                              "--cases", "no_such_case"], capture_output=True, text=True, timeout=300)
    assert unknown.returncode == 2 and "cases" in unknown.stderr


def test_bad_options():
    with pytest.raises(lv.LavenderInputError, match="cases"):
        H.run("/tmp/unused", cases="thin_rod")
    with pytest.raises(lv.LavenderInputError, match="integrator"):
        H.run("/tmp/unused", integrator="leapfrog")
