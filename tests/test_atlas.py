"""lavendersim lab atlas and lavendersim.executor: the quick atlas's JSON, its physics, and the same
bytes from every executor (this process, local processes, a dask.distributed LocalCluster).

The Dask test needs the distributed extra: skipped with a one-line reason without it, failed under
CI=true. tests/conftest.py's shared helper decides when it knows the tool "distributed"; until then
the same rule is applied inline here (_need_distributed). No timing is asserted anywhere.
"""
from __future__ import annotations

import json
import math
import os
import subprocess
import sys

import numpy as np
import pytest
from conftest import run_main
from lavendersim.labs import accuracy as ACC
from lavendersim.labs import atlas as A

from lavendersim import backends as B
from lavendersim import executor as X
from lavendersim import labs
from lavendersim import oracle as R
from lavendersim._install import MissingExtraError
from lavendersim.validate import LavenderInputError

CELL_KEYS = {"integrator", "omega_dt", "ratio", "axis", "status", "energy_drift", "energy_gain", "L_norm_drift",
             "L_norm_gain", "L_world_drift", "attitude_error", "omega_error", "steps", "dt", "T", "rhs_evals",
             "backend", "rtol", "atol", "diverged_at_step", "message", "I_b", "omega_b0", "reference",
             "within_bound"}
METRIC_KEYS = ("energy_drift", "energy_gain", "L_norm_drift", "L_norm_gain", "L_world_drift")


def _need_distributed() -> None:
    """Skip without dask.distributed (fail under CI=true): conftest's helper if it knows the tool."""
    try:
        import conftest
    except ImportError:
        conftest = None
    if conftest is not None and "distributed" in getattr(conftest, "TOOLS", {}):
        conftest.require("distributed")
        return
    try:
        import distributed  # noqa: F401
    except ImportError as exc:
        why = f"needs distributed ({type(exc).__name__}: {exc}): pip install -e '.[distributed]'"
        if os.environ.get("CI", "").strip().lower() == "true":
            pytest.fail(why + " (CI=true: every optional tool must be present)", pytrace=False)
        pytest.skip(why)


@pytest.fixture(scope="module")
def serial(quick_atlas):
    """labs.run("atlas", out, quick=True, workers=1): the session's one quick atlas (conftest), saved once."""
    result = quick_atlas.saved()
    text = (result.out_dir / "results.json").read_text()
    return result, text, json.loads(text)


def _cells(data, integrator=None, axis=None, ratio=None, omega_dt=None):
    return [c for c in data["cells"]
            if (integrator is None or c["integrator"] == integrator) and (axis is None or c["axis"] == axis)
            and (ratio is None or c["ratio"] == ratio) and (omega_dt is None or c["omega_dt"] == omega_dt)]


# ------------------------------------------------------------------------------------------ the lab

def test_quick_atlas_passes_and_writes_files(serial):
    result, _, data = serial
    assert result.passed, "; ".join(c.describe() for c in result.failures)
    assert data["passed"] is True and data["mode"] == "quick"
    assert data == json.loads(json.dumps(dict(result)))          # the returned dict is what was written
    for name in ("atlas_status.png", "atlas_energy.png", "atlas_momentum.png", "atlas_attitude.png"):
        p = result.out_dir / name
        assert p.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n" and p.stat().st_size > 20_000, name
    run_info = json.loads((result.out_dir / "run.json").read_text())
    assert run_info["kind"] == "serial" and run_info["cells"] == len(data["cells"])
    assert "wall_time_s" not in data and "executor" not in data    # how it ran is not part of the results


def test_json_schema(serial):
    _, _, data = serial
    integrators = list(B.INTEGRATORS)
    wdts, ratios = A.GRIDS["quick"]
    assert data["grid"] == {"omega_dt": list(wdts), "ratio": list(ratios), "axis": list(A.AXES),
                            "integrators": integrators}
    assert wdts[0] == 1e-4 and wdts[-1] == 10.0 and ratios[0] == 1.0 and ratios[-1] == 1e6
    assert set(wdts) <= set(A.FULL_WDT) and set(ratios) <= set(A.FULL_RATIOS)   # quick cells are full-grid cells
    cells = data["cells"]
    assert len(cells) == len(integrators) * len(wdts) * len(ratios) * len(A.AXES)
    assert len({(c["integrator"], c["axis"], c["ratio"], c["omega_dt"]) for c in cells}) == len(cells)
    assert [A.cell_key(c, integrators) for c in cells] == sorted(A.cell_key(c, integrators) for c in cells)
    for c in cells:
        assert set(c) == CELL_KEYS, set(c) ^ CELL_KEYS
        assert c["status"] in A.STATUSES
        assert c["steps"] == A.horizon_steps(c["omega_dt"]) and c["steps"] % A.SAMPLES == 0
        assert c["T"] >= A.ROTATIONS * 2 * math.pi / A.OMEGA * (1 - 1e-12)
        assert (c["rtol"] is not None) == (c["integrator"] in B.ADAPTIVE)
        ran = c["status"] in ("ok", "blew_up")
        for k in METRIC_KEYS:
            assert (c[k] is not None) == ran or (c["status"] == "blew_up" and c[k] is None), (k, c)
        if c["status"] == "diverged":
            assert c["diverged_at_step"] is not None and "diverged" in c["message"]
        if c["status"] == "ok":
            assert c["energy_gain"] <= A.BLOWUP and c["L_norm_gain"] <= A.BLOWUP
            assert c["attitude_error"] is None or 0.0 <= c["attitude_error"] <= math.pi + 1e-12
            assert c["L_norm_drift"] <= c["L_world_drift"] * (1 + 1e-9) + 1e-15   # | |L|−|L0| | ≤ |L − L0|
    for key in ("energy_drift", "L_world_drift", "attitude_error"):
        assert data["bounds"][key] > 0
    names = {p["name"] for p in data["hard_case_points"]}
    assert {"thin_rod", "long_horizon", "divergence_report"} <= names


def test_body_and_spin_are_what_the_docstring_says():
    for ratio in (1.0, 1.5, 2.0, 1e3, 1e6):
        I = A.inertia(ratio)
        assert I[2] == 1.0 and I[0] == pytest.approx(1 / ratio) and I[0] <= I[1] <= I[2]
        assert I[0] + I[1] >= I[2]                                    # a physical body
    w = A.initial_omega("intermediate")
    assert np.linalg.norm(w) == pytest.approx(A.OMEGA)
    assert w[0] == w[2] == pytest.approx(A.PERTURBATION * w[1])
    assert A.horizon_steps(1e-4) == 314_200 and A.horizon_steps(10.0) == A.MIN_STEPS


def test_physical_facts(serial):
    _, _, data = serial
    for c in _cells(data, "rk4", omega_dt=1e-4):                      # 314 200 RK4 steps: rounding only
        assert c["status"] == "ok" and c["energy_drift"] <= 1e-12 and c["L_world_drift"] <= 1e-12, c
    for integ in ("euler", "rk4"):                                    # far beyond their stability limits
        top = [c for c in _cells(data, integ, omega_dt=10.0) if c["ratio"] > 1]
        assert top and all(c["status"] in ("diverged", "blew_up") for c in top), [c["status"] for c in top]
    for integ in ("euler", "rk4"):                                    # a sphere: ω×Iω = 0 exactly, E exact
        assert all(c["energy_drift"] == 0.0 for c in _cells(data, integ, ratio=1.0))
    ig = [c for c in _cells(data, "implicit_gyro") if c["status"] in ("ok", "blew_up")]
    assert ig and max(c["energy_gain"] for c in ig) <= 1e-12
    sp = [c for c in _cells(data, "splitting") if c["status"] in ("ok", "blew_up")]
    assert sp and max(c["L_world_drift"] / c["steps"] for c in sp) <= 4 * np.finfo(float).eps
    # the intermediate axis is unstable: at the same |ω|·dt euler's energy error is far larger there
    # than about the major axis (ratio 1e3, |ω|·dt = 1e-2)
    e_mid = _cells(data, "euler", "intermediate", 1e3, 1e-2)[0]["energy_drift"]
    e_maj = _cells(data, "euler", "major", 1e3, 1e-2)[0]["energy_drift"]
    assert e_mid > 100 * e_maj


# ------------------------------------------------------------------------------------------ executors

@pytest.fixture(scope="module")
def local_cluster():
    _need_distributed()
    from dask.distributed import LocalCluster

    with LocalCluster(n_workers=2, threads_per_worker=1, processes=True, dashboard_address=None) as cluster:
        yield cluster


@pytest.mark.slow   # the whole quick atlas again on a 2-worker cluster (~25 s); processes: the test below
def test_dask_cluster_gives_identical_json(serial, local_cluster, tmp_path):
    _, text, _ = serial
    result = labs.run("atlas", tmp_path, quick=True, dask=local_cluster.scheduler_address)
    assert (tmp_path / "atlas" / "results.json").read_text() == text
    info = json.loads((tmp_path / "atlas" / "run.json").read_text())
    assert info["kind"] == "dask" and info["dask"] == local_cluster.scheduler_address
    assert result.passed


def test_local_processes_give_identical_cells():
    wdts, ratios = (1e-2, 10.0), (1e3,)
    args = (wdts, ratios, list(B.INTEGRATORS), "c" if B.c_unavailable() is None else "numpy", A.RTOL, A.ATOL)
    one = A.compute_cells(*args, X.resolve(workers=1))
    two = A.compute_cells(*args, X.Executor(X.PROCESSES, 2))
    assert json.dumps(one) == json.dumps(two)
    assert len(one) == len(B.INTEGRATORS) * 2 * 3


def test_accuracy_sweep_is_the_same_on_local_processes():
    """The accuracy lab's error computation through the executor: same points serially and in 2
    processes (a reduced sweep without MuJoCo; wall times are measured later, serially, and are
    not part of this)."""
    cfg = dict(ACC.QUICK, cases=("diag_w2",), dt_exps=(5, 6), numpy_dt_exps=(5,), numpy_budget=math.inf,
               rtols=(1e-5,), numpy_rtols=(1e-5,))
    case = ACC.cases()["diag_w2"]
    meths, _ = ACC.methods(False)
    exacts = {case.name: R.torque_free(case.I_b, case.omega_b0, [0, 0, 0, 1], [0.0, ACC.T_END])}
    tasks = ACC.sweep_tasks([case], meths, cfg, exacts)
    one = X.resolve(workers=1).map(ACC.measure_sweep, tasks)
    two = X.Executor(X.PROCESSES, 2).map(ACC.measure_sweep, tasks)
    assert [s["points"] for s in one] == [s["points"] for s in two]
    assert [s["drifts"] for s in one] == [s["drifts"] for s in two]
    assert sum(len(s["points"]) for s in one) >= len(meths)
    assert all(p.wall_s is None for s in one for p in s["points"])


def test_executor_keeps_task_order_and_validates():
    tasks = [10.0, 1e-4, 1.0, 1e-3, 0.1]                      # very different costs: completion order differs
    want = [A.horizon_steps(t) for t in tasks]
    assert X.map_tasks(A.horizon_steps, tasks) == want
    assert X.Executor(X.PROCESSES, 2).map(A.horizon_steps, tasks) == want
    assert X.resolve(workers=1) == X.Executor(X.SERIAL, 1)
    assert X.resolve(workers=3) == X.Executor(X.PROCESSES, 3)
    assert X.resolve().workers == X.local_cores()
    for bad in (dict(workers=0), dict(workers=1.5), dict(workers=2, dask="tcp://127.0.0.1:1"), dict(dask="  ")):
        with pytest.raises(LavenderInputError):
            X.resolve(**bad)


def test_missing_distributed_names_the_extra(monkeypatch):
    monkeypatch.setitem(sys.modules, "distributed", None)        # `import distributed` now fails
    with pytest.raises(MissingExtraError) as info:
        X.resolve(dask="tcp://127.0.0.1:8786", feature="lavendersim lab atlas --dask")
    assert info.value.extra == "distributed" and "[distributed]'" in str(info.value) and "'lavendersim[" not in str(info.value)


def test_cli_help_and_registration():
    assert "atlas" in labs.LABS
    out = run_main("lab", "atlas", "--help")         # in this process (the bad value below: a real process)
    assert out.returncode == 0, out.stderr
    for flag in ("--quick", "--workers", "--dask", "--rtol", "lab all"):
        assert flag in out.stdout, flag
    bad = subprocess.run([sys.executable, "-m", "lavendersim", "lab", "atlas", "--quick", "--workers", "0"],
                         capture_output=True, text=True, timeout=120)
    assert bad.returncode == 2 and "workers" in bad.stderr and "Traceback" not in bad.stderr


def test_without_the_c_backend_long_cells_are_not_run_and_drawn_so(monkeypatch):
    """No compiler: a cell of more than NUMPY_MAX_STEPS steps is "not_run" (recorded with why, never run
    for minutes on NumPy), its colour is explained in the legend, and the checks use the cells that ran."""
    import lavendersim.backends as backends

    monkeypatch.setattr(backends, "c_unavailable", lambda: "the C extension is not built (test)")
    wdt_long = 1e-4
    assert A.horizon_steps(wdt_long) > A.NUMPY_MAX_STEPS
    cell = A.run_cell("rk4", wdt_long, 1.0, "major", "auto", 1e-6, 1e-12)
    assert cell["status"] == "not_run" and cell["rhs_evals"] is None and cell["backend"] == "auto"
    assert "NUMPY_MAX_STEPS" in cell["message"] and "not built (test)" in cell["message"]
    short = A.run_cell("rk4", 1.0, 1.0, "major", "auto", 1e-6, 1e-12)
    assert short["status"] == "ok" and short["backend"] == "auto"
    checks, fig = A.atlas_checks([cell, short], ["rk4"], 1e-6)
    assert fig["cells_not_run"] == 1
    f_name, f = A.status_figure([cell, short], ["rk4"], [wdt_long, 1.0], [1.0], [])
    labels = [t.get_text() for leg in f.legends for t in leg.get_texts()]
    assert A.STATUS_TEXT["not_run"] in labels


def test_with_the_c_backend_long_cells_run():
    if B.c_unavailable() is not None:
        pytest.skip(f"the C backend is unavailable here: {B.c_unavailable()}")
    cell = A.run_cell("splitting", 1e-3 / 2, 1.0, "major", "numpy", 1e-6, 1e-12)
    assert A.horizon_steps(1e-3 / 2) > A.NUMPY_MAX_STEPS
    assert cell["status"] == "ok" and cell["backend"] == "c"
