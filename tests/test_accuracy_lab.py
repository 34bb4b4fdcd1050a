"""lavendersim lab accuracy: the quick sweep's output is well-formed and its content is consistent.

Timings are measured by the lab but never asserted here: only the structure of the output, the
accuracy data (errors shrink with dt at the integrator's order) and that every verdict agrees with
the points it was drawn from.
"""
from __future__ import annotations

import json
import math

import numpy as np
import pytest

from conftest import have
from lavendersim import backends as B
from lavendersim import labs
from lavendersim.labs import accuracy as A


@pytest.fixture(scope="module")
def quick(quick_accuracy):
    """labs.run("accuracy", out, quick=True): the session's one quick accuracy lab (conftest), saved once."""
    result = quick_accuracy.saved()
    data = json.loads((result.out_dir / "results.json").read_text())
    return result, data


def _points(data, case=None, method=None):
    return [p for p in data["points"] if (case is None or p["case"] == case) and (method is None or p["method"] == method)]


def test_quick_passes_and_writes_files(quick):
    result, data = quick
    assert result.passed, "; ".join(c.describe() for c in result.failures)
    assert data["passed"] is True and data["mode"] == "quick"
    assert data == json.loads(json.dumps(dict(result)))      # the returned dict is what was written
    for name in ("results.json", "points.csv", "work_precision_time.png", "work_precision_rhs.png",
                 "work_precision_omega.png", "drift_vs_time.png"):
        p = result.out_dir / name
        assert p.exists() and p.stat().st_size > 500, name
    for name in ("work_precision_time.png", "drift_vs_time.png"):
        assert (result.out_dir / name).read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    rows = (result.out_dir / "points.csv").read_text().splitlines()
    assert len(rows) == len(data["points"]) + 1


def test_json_is_well_formed(quick):
    _, data = quick
    for key in ("machine", "table", "verdicts", "points", "methods", "drift_series"):
        assert key in data, key
    m = data["machine"]
    for key in ("cpu", "logical_cores", "python", "numpy", "scipy", "compiler", "git_commit"):
        assert m[key], key
    assert "float32" in data and "rk4 [c float32]" in data["float32"]   # the precision axis
    assert "rk4 [c float32]" in {m["label"] for m in data["methods"]}
    keys = {"case", "method", "param", "value", "steps", "rhs_evals", "attitude_error", "omega_error",
            "energy_drift", "momentum_drift", "wall_s", "wall_per_sim_s", "repeats", "diverged"}
    labels = {m["label"] for m in data["methods"]}
    for p in data["points"]:
        assert keys <= set(p), set(keys) - set(p)
        assert p["method"] in labels and p["param"] in ("dt", "rtol") and p["value"] > 0
        if p["diverged"] is None:
            for k in ("attitude_error", "omega_error", "energy_drift", "momentum_drift", "wall_per_sim_s"):
                assert isinstance(p[k], float) and math.isfinite(p[k]) and p[k] >= 0, (p["method"], k)
            assert 0 <= p["attitude_error"] <= math.pi
            assert p["rhs_evals"] is None or p["rhs_evals"] > 0
    for row in data["table"]:
        assert row["method"] in labels
        assert row["verdict"] in ("on the Pareto front", "beaten", "out of range")


def test_every_integrator_backend_and_peer_appears(quick):
    _, data = quick
    methods = {p["method"] for p in data["points"]}
    for name in B.INTEGRATORS:
        for backend in B.BACKENDS:
            assert f"{name} [{backend}]" in methods, f"{name} [{backend}]"
    assert {"scipy RK45", "scipy DOP853"} <= methods
    mujoco, why = A._mujoco()
    assert (mujoco is not None) == have("mujoco"), why     # under CI=true MuJoCo must be measured
    if mujoco is not None:
        assert {"MuJoCo Euler", "MuJoCo implicitfast", "MuJoCo RK4"} <= methods
        assert data["mujoco"].startswith("measured")
    else:
        assert data["mujoco"].startswith("not measured")
    assert {p["case"] for p in data["points"]} == set(A.QUICK["cases"])
    for name in A.QUICK["cases"]:
        assert name in data["cases"]
        assert {p["method"] for p in _points(data, case=name)} == methods
    # an adaptive integrator sweeps rtol, the fixed-step ones dt
    for name in A.adaptive_integrators():
        assert {p["param"] for p in data["points"] if p["method"].startswith(f"{name} [")} == {"rtol"}


def _order(pts, lo=1e-10, hi=0.2):
    xs = [math.log(p["value"]) for p in pts if p["diverged"] is None and lo < p["attitude_error"] < hi]
    ys = [math.log(p["attitude_error"]) for p in pts if p["diverged"] is None and lo < p["attitude_error"] < hi]
    assert len(xs) >= 3, "too few points in the asymptotic window"
    return float(np.polyfit(xs, ys, 1)[0])


@pytest.mark.parametrize("integrator,order", [("euler", 1), ("semi_implicit_euler", 1), ("rk4", 4),
                                              ("splitting", 2), ("implicit_gyro", 1)])
def test_errors_decrease_with_dt_at_the_expected_order(quick, integrator, order):
    _, data = quick
    if integrator not in B.INTEGRATORS:
        pytest.skip(f"{integrator} not in INTEGRATORS")
    cases = {p["case"] for p in data["points"]}
    for case in cases:
        pts = sorted(_points(data, case, f"{integrator} [c]"), key=lambda p: -p["value"])
        errs = [p["attitude_error"] for p in pts if p["attitude_error"] > 1e-10]
        assert all(b < a for a, b in zip(errs[1:], errs[2:])), (case, errs)   # shrinking (first may saturate)
        assert abs(_order(pts) - order) <= 0.35, (case, _order(pts))
        # the NumPy backend runs the same algorithm: same errors at the dt both measured
        for pn in _points(data, case, f"{integrator} [numpy]"):
            pc = next(p for p in pts if p["value"] == pn["value"])
            assert pn["attitude_error"] == pytest.approx(pc["attitude_error"], rel=1e-6, abs=1e-12)


def test_adaptive_and_peers_converge_to_the_reference(quick):
    _, data = quick
    for label in [f"{n} [c]" for n in A.adaptive_integrators()] + ["scipy RK45", "scipy DOP853"]:
        for case in {p["case"] for p in data["points"]}:
            pts = sorted(_points(data, case, label), key=lambda p: -p["value"])
            tight = pts[-1]
            assert tight["attitude_error"] <= 100 * tight["value"], (label, case)
            assert tight["attitude_error"] < pts[0]["attitude_error"], (label, case)
    if have("mujoco"):
        for case in {p["case"] for p in data["points"]}:
            pts = _points(data, case, "MuJoCo RK4")
            assert abs(_order(pts) - 4) <= 0.35
            assert min(p["attitude_error"] for p in pts) < 1e-9


def _dominated(p, others, definition):
    """Another point at least as accurate (errors clamped at the floor) and faster by more than the
    timing margin, or strictly more accurate and within the margin — as the JSON defines it."""
    floor, margin = definition["error_floor"], definition["time_margin"]
    ep, tp = max(p["attitude_error"], floor), p["wall_per_sim_s"]
    for o in others:
        eo, to = max(o["attitude_error"], floor), o["wall_per_sim_s"]
        if eo <= ep and (to * (1 + margin) < tp or (eo < ep and to <= tp * (1 + margin))):
            return True
    return False


def test_verdicts_are_consistent_with_the_points(quick):
    """Recomputed from the JSON alone: a 'beaten' method has every point (within the ceiling)
    dominated by another method's point; an 'on the Pareto front' method has one that is not."""
    _, data = quick
    per_case = data["verdicts"]["by_wall_time"]["per_case"]
    definition = data["verdicts"]["definition"]
    ceiling = data["error_ceiling"]
    assert definition["error_ceiling"] == ceiling
    for case, per in per_case.items():
        eligible = [p for p in _points(data, case) if p["diverged"] is None and p["attitude_error"] <= ceiling]
        for method, v in per.items():
            mine = [p for p in eligible if p["method"] == method]
            others = [p for p in eligible if p["method"] != method]
            if v["verdict"] == "beaten":
                assert mine and all(_dominated(p, others, definition) for p in mine), (case, method)
                for p in mine:  # the named dominators really dominate
                    assert any(_dominated(p, [o for o in others if o["method"] == b], definition) for b in v["beaten_by"])
            elif v["verdict"] == "on the Pareto front":
                assert any(not _dominated(p, others, definition) for p in mine), (case, method)
            else:
                assert v["verdict"] == "out of range" and not mine, (case, method)
    overall = data["verdicts"]["by_wall_time"]["overall"]
    for method, v in overall.items():
        cases = [per_case[c][method]["verdict"] for c in per_case if method in per_case[c]]
        if v["verdict"] == "on the Pareto front":
            assert "on the Pareto front" in cases
        elif v["verdict"] == "beaten":
            assert "on the Pareto front" not in cases and "beaten" in cases
        else:
            assert set(cases) == {"out of range"}
    # the table and the flat figures carry the same verdicts
    for row in data["table"]:
        assert row["verdict"] == overall[row["method"]]["verdict"]
        assert data[f"verdict_{A._key(row['method'])}"] == overall[row["method"]]["text"]


def test_verdict_rules_on_synthetic_points():
    P = A.Point
    pts = [P("c", "fast", "dt", 1.0, attitude_error=1e-6, wall_per_sim_s=1.0),
           P("c", "fast", "dt", 0.5, attitude_error=1e-9, wall_per_sim_s=2.0),
           P("c", "slow", "dt", 1.0, attitude_error=1e-6, wall_per_sim_s=3.0),     # fast(1) dominates
           P("c", "slow", "dt", 0.5, attitude_error=1e-9, wall_per_sim_s=2.5),     # fast(0.5) dominates
           P("c", "precise", "rtol", 1e-9, attitude_error=1e-13, wall_per_sim_s=9.0),  # below the floor: ties
           P("c", "cheap_bad", "dt", 1.0, attitude_error=0.5, wall_per_sim_s=0.1),  # above the ceiling
           P("c", "niche", "dt", 1.0, attitude_error=1e-3, wall_per_sim_s=0.5)]     # cheapest at 1e-3
    pts.append(P("c", "fast", "dt", 0.1, attitude_error=5e-12, wall_per_sim_s=5.0))
    # within the 10% timing margin: strictly more accurate wins; equally accurate is a tie (no one wins)
    pts.append(P("c", "close_but_worse", "dt", 1.0, attitude_error=2e-6, wall_per_sim_s=0.97))
    pts.append(P("c", "tie", "dt", 1.0, attitude_error=1e-9, wall_per_sim_s=1.9))
    v = A.verdicts(pts)["c"]
    assert v["close_but_worse"]["verdict"] == "beaten" and v["close_but_worse"]["beaten_by"] == ["fast"]
    assert v["tie"]["verdict"] == "on the Pareto front" and v["fast"]["verdict"] == "on the Pareto front"
    assert A.dominates(1e-6, 1.0, 2e-6, 0.97) and not A.dominates(2e-6, 0.97, 1e-6, 1.0)
    assert not A.dominates(1e-9, 2.0, 1e-9, 1.9) and not A.dominates(1e-9, 1.9, 1e-9, 2.0)
    assert v["fast"]["verdict"] == "on the Pareto front"
    assert v["slow"]["verdict"] == "beaten" and v["slow"]["beaten_everywhere_by"] == ["fast", "tie"]
    assert v["precise"]["verdict"] == "beaten"            # 1e-13 and 5e-12 are both at the floor; fast is cheaper
    assert v["cheap_bad"]["verdict"] == "out of range"
    assert v["niche"]["verdict"] == "on the Pareto front"
    assert A.verdicts_consistent(pts, A.verdicts(pts))
    forged = A.verdicts(pts)
    forged["c"]["fast"]["verdict"] = "beaten"
    assert not A.verdicts_consistent(pts, forged)


def test_convergence_order_fit():
    pts = [A.Point("c", "m", "dt", 2.0 ** -k, attitude_error=3.0 * 2.0 ** (-2 * k)) for k in range(3, 10)]
    assert A.convergence_order(pts) == pytest.approx(2.0)
    assert A.convergence_order(pts[:2]) is None


def test_runs_and_says_so_without_mujoco(tmp_path, monkeypatch):
    """Without the mujoco package the lab still runs and its output says MuJoCo was not measured."""
    monkeypatch.setattr(A, "_mujoco", lambda: (None, "ModuleNotFoundError: No module named 'mujoco'"))
    # a tiny sweep: what is checked is the MuJoCo branch, not the points
    monkeypatch.setattr(A, "QUICK", dict(A.QUICK, cases=("box_w1",), dt_exps=(4, 5, 6), numpy_dt_exps=(4,),
                                         rtols=(1e-3, 1e-4, 1e-5), numpy_rtols=(1e-3,), mj_dt_exps=(4,)))
    # workers=1: in this process, where the monkeypatched _mujoco applies (and no worker pool to start)
    result = labs.run("accuracy", tmp_path, quick=True, workers=1)
    data = json.loads((tmp_path / "accuracy" / "results.json").read_text())
    assert data["mujoco"].startswith("not measured") and "No module named 'mujoco'" in data["mujoco"]
    assert data["machine"]["mujoco"] is None
    assert not any(p["method"].startswith("MuJoCo") for p in data["points"])
    assert not any(c.name.startswith("mujoco") for c in result.checks)
