"""Issue 13: `lavendersim lqr --monte-carlo N --seed S`: the same summary for the same seed in this
process, on 2 local processes and on a dask.distributed LocalCluster (lavendersim.executor)."""
from __future__ import annotations

import json

import pytest

from lavendersim import control as lc
from lavendersim import executor as X

pytestmark = pytest.mark.needs("control")

N, SEED = 4, 7


@pytest.fixture(scope="module")
def design():
    return lc.design("corner", T=0.5, backend="c")


@pytest.fixture(scope="module")
def serial(design):
    return lc.monte_carlo(design, N, SEED, X.resolve(workers=1))


def test_summary_is_sensible_and_seeded(design, serial):
    mc = serial
    assert mc["n"] == N and len(mc["samples"]) == N and mc["failures"] == 0
    assert 0 < mc["settling_time"]["p50"] <= mc["settling_time"]["p100"] < 0.5
    other = lc.monte_carlo(design, N, SEED + 1, X.resolve(workers=1))
    assert json.dumps(other) != json.dumps(mc)                      # another seed draws other plants
    tasks = lc.monte_carlo_tasks(design.model, N, SEED)
    assert len({t["mass"] for t in tasks}) == N and all(0.9 <= t["mass"] <= 1.1 for t in tasks)


def test_two_local_processes_give_the_identical_summary(design, serial):
    two = lc.monte_carlo(design, N, SEED, X.Executor(X.PROCESSES, 2))
    assert json.dumps(two) == json.dumps(serial)


@pytest.mark.needs("distributed")
def test_a_local_dask_cluster_gives_the_identical_summary(design, serial):
    from dask.distributed import LocalCluster

    with LocalCluster(n_workers=2, threads_per_worker=1, processes=True, dashboard_address=None) as cluster:
        got = lc.monte_carlo(design, N, SEED, X.resolve(dask=cluster.scheduler_address))
    assert json.dumps(got) == json.dumps(serial)


def test_cli_monte_carlo_json(capsys):
    from lavendersim import cli

    args = ["lqr", "--scenario", "corner", "--monte-carlo", "3", "--workers", "1", "--json"]
    assert cli.main(args) == 0
    f = json.loads(capsys.readouterr().out)
    assert f["monte_carlo"]["n"] == 3 and f["monte_carlo"]["seed"] == 0 and "runs" not in f["monte_carlo"]
    assert f["monte_carlo"]["settled"] == 3
    assert cli.main(["lqr", "--monte-carlo", "0"]) == 2
    assert "monte-carlo" in capsys.readouterr().err
