"""control.monte_carlo (noise seeds and inertia uncertainty) and `lavendersim lqr --monte-carlo N`: the same
summary for the same seed in this process, on 2 local processes and on a dask.distributed LocalCluster
(lavendersim.executor)."""
from __future__ import annotations

import json

import numpy as np
import pytest

from lavendersim import control as lc
from lavendersim import executor as X

pytestmark = pytest.mark.needs("control")

N, SEED = 4, 7


@pytest.fixture(scope="module")
def design():
    scene = lc.chapter_cube("corner")
    ctrl = lc.design(scene, period=2e-3, q_ref=lc.cube_upright_q("corner"), weights={"attitude_deg": 0.5})
    return scene, ctrl


def _mc(design, seed, executor):
    scene, ctrl = design
    return lc.monte_carlo(scene, ctrl, n=N, seed=seed, T=0.5, q0=lc.rotated(ctrl.q_ref, lc.CORNER_AXIS, 3.0), dt=1e-3,
                          sensors=lc.Sensors(attitude_noise=1e-4, gyro_noise=1e-3), backend="c", executor=executor)


@pytest.fixture(scope="module")
def serial(design):
    return _mc(design, SEED, X.resolve(workers=1))


def test_summary_is_sensible_and_seeded(design, serial):
    mc = serial
    assert mc["n"] == N and len(mc["samples"]) == N and mc["failures"] == 0
    assert 0 < mc["settling_time"]["p50"] <= mc["settling_time"]["p100"] < 0.5
    other = _mc(design, SEED + 1, X.resolve(workers=1))
    assert json.dumps(other) != json.dumps(mc)                      # another seed draws other plants and noise
    scales = np.array([s["inertia_scale"] for s in mc["samples"]])
    assert len(set(scales[:, 0])) == N and np.all((0.9 <= scales) & (scales <= 1.1))
    assert [s["seed"] for s in mc["samples"]] == [SEED + i for i in range(N)]


def test_two_local_processes_give_the_identical_summary(design, serial):
    two = _mc(design, SEED, X.Executor(X.PROCESSES, 2))
    assert json.dumps(two) == json.dumps(serial)


@pytest.mark.needs("distributed")
def test_a_local_dask_cluster_gives_the_identical_summary(design, serial):
    from dask.distributed import LocalCluster

    with LocalCluster(n_workers=2, threads_per_worker=1, processes=True, dashboard_address=None) as cluster:
        got = _mc(design, SEED, X.resolve(dask=cluster.scheduler_address))
    assert json.dumps(got) == json.dumps(serial)


def test_cli_monte_carlo_json(capsys):
    from lavendersim import cli

    args = ["lqr", "--scenario", "corner", "--monte-carlo", "3", "--workers", "1", "--json"]
    assert cli.main(args) == 0
    f = json.loads(capsys.readouterr().out)
    assert f["monte_carlo"]["n"] == 3 and f["monte_carlo"]["seed"] == 0 and "samples" not in f["monte_carlo"]
    assert f["monte_carlo"]["failures"] == 0
    assert cli.main(["lqr", "--monte-carlo", "0"]) == 2
    assert "monte-carlo" in capsys.readouterr().err
