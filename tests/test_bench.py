"""`lavendersim bench`: the quick run works and its output/JSON are well formed (timings are never
checked), a crashed section makes it exit 1, and the hand-written peers (the bitwise RK4, the FMA RK4,
the DOPRI5) compute the Sim's trajectory (so the ratios against them are honest).

The hand-written kernel needs a C compiler and the peer needs MuJoCo (bench extra): marked
`needs("cc")` / `needs("mujoco")` (tests/conftest.py: skipped without them, failed under CI=true)."""
from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest

from conftest import NUMPY_SLOW, have, run_main
from lavendersim import bench


def bench_contract_available() -> bool:
    """Whether the extension has the opt-in FMA tiles (False without the C extension)."""
    try:
        from lavendersim.backends.c_backend import contract_available
    except ImportError:
        return False
    return contract_available()


N_TARGETS = 32   # target lines besides the per-body ones (scenes.py: + the wheeled build and the 1e6 lines; dopri5: + dense output;
                 # simd: + contract='fma' against the flop floor)


@pytest.fixture(scope="module")
def quick(tmp_path_factory):
    """`lavendersim bench --quick --out FILE` through cli.main in this process (conftest.run_main: exit code, stdout
    and stderr captured, stderr not a terminal as on a pipe); no interpreter started for it."""
    path = tmp_path_factory.mktemp("bench") / "bench.json"
    return run_main("bench", "--quick", "--out", path), path


def test_quick_runs_and_prints_its_standing(quick):
    r, _ = quick
    assert r.returncode == 0, r.stderr
    out = r.stdout
    for heading in ("machine :", "single body", "batched: N bodies in one C call", "effect sets on one body",
                    "per-body effects, C: one applied_torque per body", "float32 batch, C", "scene build (C backend",
                    "full inertia tensor vs principal moments", "targets"):
        assert heading in out
    lines = [ln.split() for ln in out.splitlines()]
    status = [ln[0] for ln in lines if ln and ln[0] in ("PASS", "MISS", "N/A")]
    assert len(status) == N_TARGETS + len(bench.PER_BODY_SIZES_QUICK)  # one line per target, whatever the timings
    assert r.stderr == ""  # no progress lines on a pipe (a bar on a terminal only)


def test_quick_json_is_well_formed(quick):
    _, path = quick
    d = json.loads(path.read_text())
    assert d["schema"] == bench.SCHEMA and d["quick"] is True
    for key in ("cpu", "cores", "python", "numpy", "compiler_version", "git_commit", "date"):
        assert key in d["machine"]
    for key in ("c_rk4", "numpy_rk4", "python_step_c", "python_step_numpy"):
        s = d["single_body"][key]
        assert s["ns_min"] > 0 and s["ns_min"] <= s["ns_median"] and len(s["ns_samples"]) == s["rounds"]
    assert [b["n_bodies"] for b in d["batched"]] == list(bench.BATCH_SIZES_QUICK)
    for b in d["batched"]:
        assert b["c"]["ns_min"] > 0 and b["numpy"]["ns_min"] > 0
    assert [e["name"] for e in d["effects"]] == [name for name, _ in bench.EFFECT_SETS]
    assert d["effects"][0]["ratio_to_torque_free"] == 1.0
    assert d["effects"][-1]["effects"] == ["applied_torque", "linear_damping", "angular_damping", "gravity",
                                           "spherical_joint", "reaction_wheels"]
    assert [p["n_bodies"] for p in d["per_body_effects"]] == list(bench.PER_BODY_SIZES_QUICK)
    sc = d["scenes"]   # the scene-build section: --quick builds a tenth of the target's 1e4 bodies
    assert sc["n_bodies"] == bench.scenes.SCENE_N // 10
    assert 0 < sc["cases"]["build"]["ns_min"] and sc["state_ratio"] > 0 and sc["one_by_one_over_batched"] > 0
    # issue 30's scaling lines: the wheeled build (a tenth of 1e5 in --quick); the 1e6 process in full runs only
    assert sc["n_wheeled"] == bench.scenes.WHEELED_N // 10 and sc["cases"]["build_wheeled"]["ns_min"] > 0
    assert "plain_big" in sc and sc["plain_big"] is None
    fi = d["inertia"]   # full tensors against principal moments, in the same rounds
    assert list(fi["sizes"]) == [str(n) for n in bench.full_inertia.SIZES_QUICK]
    assert all(v["run_ratio"] > 0 and v["read_ratio"] > 0 for v in fi["sizes"].values())
    for r in d["float32_batch"]:   # float32 beside float64 in the same rounds, and close to it
        assert r["float32"]["ns_min"] > 0 and r["speedup"] > 0 and r["max_abs_diff_after_steps"] < 1e-3
    for p in d["per_body_effects"]:
        assert p["plain"]["ns_min"] > 0 and p["applied_torque"]["ns_min"] > 0
        assert p["ratio"] == p["applied_torque"]["ns_min"] / p["plain"]["ns_min"]
    assert [t["status"] in ("PASS", "MISS", "N/A") for t in d["standing"]] == [True] * (N_TARGETS + len(bench.PER_BODY_SIZES_QUICK))
    assert d["errors"] == [] and d["config"]["clock"].startswith("CPU time")
    assert all(s["clock"] == "cpu" for s in d["single_body"].values())
    assert any(t["name"] == "one Python sim.step(), c backend" for t in d["standing"])
    assert all(math.isfinite(v) for v in d["ratios"].values())
    hw = d["handwritten"]
    assert hw["available"] == have("cc"), hw
    if hw["available"]:
        assert "handwritten_c" in d["single_body"] and "c_rk4_over_handwritten_c" in d["ratios"]
        assert hw["agreement"]["max_abs_diff"] == 0.0 and hw["agreement"]["bitwise"]  # same arithmetic
    if "simd_batch" in d:  # the C extension is built: every ISA level and hand SoA copy agree bitwise
        sb = d["simd_batch"]
        assert [r["n_bodies"] for r in sb["sizes"]] == list(bench.SIMD_SIZES_QUICK)
        assert sb["isa_levels"][0] == "scalar" and sb["best_isa"] == sb["isa_levels"][-1] == d["machine"]["isa"]
        for r in sb["sizes"]:
            assert r["bitwise_identical"]
            for nm in sb["isa_levels"]:
                assert r[f"lavendersim_{nm}"]["ns_min"] > 0
            if hw["available"]:
                assert r["ratio_to_hand_soa"] > 0 and f"hand_soa_{r['best_hand_isa']}" in r
    mj = d["mujoco"]
    assert mj["available"] == have("mujoco"), mj
    if mj["available"]:
        assert "mujoco_RK4_mj_step" in d["single_body"] and "mujoco_RK4_mj_step_over_c_rk4" in d["ratios"]
        assert "mujoco_RK4_vs_lavendersim_rk4" in mj["agreement"]
    else:
        assert mj["reason"]


@pytest.mark.needs("cc")
@pytest.mark.parametrize("backend", NUMPY_SLOW)    # 20 000 NumPy steps: the slow set
def test_handwritten_kernel_computes_the_sims_trajectory(backend):
    kernel = bench.HandwrittenKernel()
    a = bench.handwritten_agreement(kernel, n_steps=20_000, every=2_000, backend=backend)
    if backend == "c":   # the hand loop writes each expression in the generated kernel's order
        assert a["max_abs_diff"] == 0.0, a
    assert a["max_abs_diff"] <= 1e-12, a


@pytest.mark.needs("cc")
def test_handwritten_kernel_reports_divergence_with_check():
    kernel = bench.HandwrittenKernel()
    x = bench.initial_state()
    x[10:13] = [1e200, 1e200, 1e200]  # overflows in the first step
    start = x.copy()
    assert kernel.advance(x, bench.inertia(), bench.DT, 10, check=True) == 0
    np.testing.assert_array_equal(x, start)  # left at the last finite state


@pytest.mark.needs("cc")
def test_handwritten_soa_loop_is_the_scalar_loop_bitwise():
    """The SoA peer (one body per lane) gives bitwise the scalar peer's states, at every instruction set
    this CPU and compiler have, for a body count that is no multiple of any lane count."""
    kernel = bench.HandwrittenKernel()
    info = bench.extension_isa()   # what this CPU runs (the extension's detection); baseline without it
    best = info["best_level"] if info else 1
    kernel.compile_soa([(nm, extra) for lvl, nm, extra in bench.SOA_ISAS if lvl <= best])
    assert "sse2" in kernel.soa, kernel.soa_errors
    rng = np.random.default_rng(3)
    n = 131
    X = np.tile(bench.initial_state()[:, None], (1, n))
    X[10:13] = 3.0 * rng.standard_normal((3, n))
    I = np.ascontiguousarray(np.tile(bench.inertia()[:, None], (1, n)) * (1.0 + rng.random((3, n))))
    want = X.copy()
    for b in range(n):
        x = np.ascontiguousarray(want[:, b])
        kernel.advance(x, np.ascontiguousarray(I[:, b]), bench.DT, 200)
        want[:, b] = x
    for nm in kernel.soa:
        got = X.copy()
        kernel.advance_soa(nm, got, I, bench.DT, 200)
        np.testing.assert_array_equal(got, want, err_msg=nm)


@pytest.mark.needs("mujoco")
def test_mujoco_model_matches_the_body():
    mb = bench.MujocoBody("RK4")
    np.testing.assert_allclose(mb.m.body_mass[1], bench.MASS)
    np.testing.assert_allclose(mb.m.body_inertia[1], bench.inertia(), rtol=1e-12)
    x = bench.initial_state()
    np.testing.assert_allclose(mb.d.qpos[3:7], [x[6], x[3], x[4], x[5]])  # MuJoCo's (w, x, y, z)
    a = bench.mujoco_agreement(100)
    assert a["mujoco_RK4_vs_lavendersim_rk4"]["attitude_rad_max"] < 1e-10
    assert a["mujoco_RK4_vs_lavendersim_rk4"]["omega_b_max"] < 1e-10


def test_quick_json_has_the_issue_30_ratios(quick):
    """The effect-cost table (every set against plain bodies, at every N), small scenes against large N, dopri5
    per RHS against the hand DOPRI5, the batch against the FMA loop and the flop floor: in the JSON's ratios
    and as target lines (their values are not checked)."""
    _, path = quick
    d = json.loads(path.read_text())
    r, names = d["ratios"], {t["name"] for t in d["standing"]}
    for nm, _, limit in bench.effect_cost.SETS[1:]:
        assert any(t["name"].startswith(nm + " / plain body") and t["limit"] == limit for t in d["standing"])
        if "gravity_gradient" not in nm:   # the user effect is derived in the full run only
            for n in bench.effect_cost.SIZES_QUICK:
                assert r[f"effect_cost[{nm}]_{n}_over_plain"] > 0
    for row in d["effect_cost"]["sizes"].values():   # short calls of whole chunks (timing.py), as many per set
        assert all(row["steps_per_call"][nm] % row["steps_per_chunk"][nm] == 0 for nm in row["ratios"])
        assert len({row[nm]["rounds"] for nm in row["ratios"]}) == 1 and row["plain"]["rounds"] >= 2 * d["config"]["rounds"]
    for n in bench.SMALL_SIZES:
        assert r[f"small_scene_{n}_over_N_{max(bench.BATCH_SIZES_QUICK)}"] > 0
    assert any(nm.startswith("small scenes") for nm in names)
    npx = d["numpy_peers"]["sizes"]   # H2's hand NumPy / pure-Python peers compute the backend's physics
    assert r["numpy_1_over_python_rk4"] > 0 and npx["1"]["max_abs_diff"] <= 1e-12, npx["1"]
    for n in bench.numpy_section.SIZES_QUICK:
        assert r[f"numpy_{n}_over_hand_rk4_soa"] > 0 and npx[str(n)]["max_abs_diff"] <= 1e-12, npx[str(n)]
    for n, v in d["numpy_peers"]["effects"].items():   # gravity+damping: the peers type the drag torque in the body
        assert v["ratio"] > 0 and v["max_abs_diff"] <= 1e-12, (n, v)   # frame, equal to the printed one to rounding
    if have("cc"):
        assert r["dopri5_per_rhs_over_hand"] > 0
        a = d["dopri5"]["agreement"]
        assert a["max_abs_diff"] <= 1e-12 and a["rhs_evals_lavendersim"] == a["rhs_evals_hand"], a
        if "simd_batch" in d:
            n = bench.SIMD_SIZES_QUICK[0]
            for key in ("ratio_to_hand_fma", "ratio_to_flop_floor", "hand_fma_over_flop_floor"):
                assert r[f"simd_batch_{n}_{key}"] > 0
            if bench_contract_available():   # the opt-in FMA tiles beside the bitwise ones, and how far they are
                assert r[f"simd_batch_{n}_fma_ratio_to_flop_floor"] > 0
                assert 0 < d["simd_batch"]["sizes"][0]["fma_max_abs_diff_50_steps"] <= 1e-12
        assert all(v <= 1e-12 for k, v in d["handwritten"]["fma_agreement"].items() if k.startswith("max_abs"))


def test_a_crashed_section_exits_1_and_the_rest_still_prints(monkeypatch, capsys):
    from lavendersim import cli

    def boom(ctx):
        raise RuntimeError("boom\nsecond line")

    monkeypatch.setitem(bench.RUNNERS, "scenes", boom)
    assert cli.main(["bench", "--quick", "--rounds", "1", "--only", "effects,scenes"]) == 1
    out, err = capsys.readouterr()
    assert "effect sets on one body" in out and "\ntargets\n" in out   # the section that ran is reported
    assert "CRASH section scenes: RuntimeError: boom second line" in out
    assert len(err.strip().splitlines()) == 1 and "scenes (RuntimeError: boom second line)" in err, err


def test_json_is_the_only_thing_on_stdout(capsys):
    from lavendersim import cli

    assert cli.main(["bench", "--quick", "--rounds", "1", "--only", "effects", "--json"]) == 0
    out, err = capsys.readouterr()
    d = json.loads(out)
    assert d["errors"] == [] and [e["name"] for e in d["effects"]] == [nm for nm, _ in bench.EFFECT_SETS]
    assert err == ""   # no progress when stderr is not a terminal


def test_markdown_reprints_a_saved_run_as_one_table_of_its_targets(quick):
    """`--from RUN.json --markdown` measures nothing and prints the saved run's targets, one row each, with its
    status and figure (the tables of docs/performance.md are pasted from it)."""
    _, path = quick
    d = json.loads(path.read_text())
    r = run_main("bench", "--from", path, "--markdown")
    assert r.returncode == 0, r.stderr
    rows = [ln for ln in r.stdout.splitlines() if ln.startswith("| ") and not ln.startswith("| target |")]
    assert len(rows) == len(d["standing"]) and (d["machine"]["git_commit"] or "unknown")[:12] in r.stdout
    for row, t in zip(rows, d["standing"]):
        cells = [c.strip() for c in row.strip("|").split(" | ")]
        assert cells[3] == t["status"]
        assert cells[1] == ("—" if t["value"] is None else f"{t['value']:.3g} {t['unit']}")
    assert run_main("bench", "--from", path).stdout.rstrip().endswith(bench.report(d).rstrip().splitlines()[-1])


def test_from_a_file_that_is_no_saved_run_is_one_line_exit_2(tmp_path):
    bad = tmp_path / "x.json"
    bad.write_text('{"a": 1}')
    for path in (bad, tmp_path / "missing.json"):
        r = run_main("bench", "--from", path, "--markdown")
        assert r.returncode == 2 and r.stdout == "" and len(r.stderr.strip().splitlines()) == 1 and "from" in r.stderr


def test_unknown_section_is_one_line_exit_2(capsys):
    from lavendersim import cli

    assert cli.main(["bench", "--only", "effects,nope"]) == 2
    out, err = capsys.readouterr()
    assert out == "" and len(err.strip().splitlines()) == 1 and "nope" in err and "only" in err


@pytest.mark.needs("cc")
def test_fma_peer_computes_the_sims_trajectory():
    """The unconstrained FMA loop (other rounding, fewer flops) agrees with the Sim to 1e-12 over 1 000 steps of
    257 bodies, in every variant that compiles here; and its flop-rate probe runs."""
    kernel = bench.HandwrittenKernel()
    kernel.compile_fma()
    assert kernel.fma, kernel.fma_errors
    a = bench.fma_agreement(kernel)
    for name in kernel.fma:
        assert a[f"max_abs_diff_{name}"] <= 1e-12, a
    assert math.isfinite(kernel.peak_fma(1000, 0.999999, 1e-7))


@pytest.mark.needs("cc")
def test_fma_peer_normalizes_a_state_far_from_unit_exactly():
    """The FMA peer's series normalization (as the FMA tiles') falls back to q / |q| beyond its range: bodies
    started at |q|^2 = 9 and 0.25 beside unit ones end one step later unit to rounding, as the Sim's bitwise path."""
    kernel = bench.HandwrittenKernel()
    kernel.compile_fma()
    assert kernel.fma, kernel.fma_errors
    _, _, X0, I = bench._batch_arrays(16)
    X0[3:7, 2] *= 3.0
    X0[3:7, 9] *= 0.5
    for name in kernel.fma:
        X = X0.copy()
        kernel.advance_fma(name, X, I, bench.DT, 1)
        assert float(np.max(np.abs(np.linalg.norm(X[3:7], axis=0) - 1.0))) <= 4e-16, name


@pytest.mark.needs("cc")
def test_dopri5_peer_computes_the_sims_trajectory():
    """The hand DOPRI5 (same controller, dense output) takes the Sim's steps: same states to 1e-12, same RHS counts
    (dense output: fewer substeps than output steps at dt = 0.1 s, so the count is below 300 x 6 but above 300)."""
    peer = bench.dopri5.HandDopri5(bench.compile_c)
    a = bench.dopri5.agreement(peer, bench.single_sim, bench.initial_state(), bench.inertia(), n_steps=300)
    assert a["status"] == -1 and a["max_abs_diff"] <= 1e-12, a
    assert a["rhs_evals_lavendersim"] == a["rhs_evals_hand"] > 300, a


def test_the_plain_big_process_reports_build_memory_and_step_ratio():
    """bench.scenes.plain_big (full runs: 1e6 bodies in a fresh process), small here: its figures are there."""
    d = bench.scenes.plain_big(3000, 1000, 2)
    assert d["n_bodies"] == 3000 and d["small_n"] == 1000 and d["build_s"] > 0 and d["rss_per_body_B"] >= 0
    assert d["ns_big"] > 0 and d["ns_small"] > 0 and d["step_ratio"] == d["ns_big"] / d["ns_small"]
    # every round kept (the min is the figure), with its page faults and system time per body-step
    assert len(d["rounds"]["big"]) == len(d["rounds"]["small"]) == 2 and d["ns_big"] == min(d["rounds"]["big"])
    assert d["ns_small"] == min(d["rounds"]["small"])
    assert all(len(f) == 2 and f[0] >= 0 and f[1] >= 0 for key in ("big", "small") for f in d["faults_sys_ns"][key])


@pytest.mark.skipif(not Path("/proc/self/clear_refs").exists(), reason="no resettable peak RSS (not Linux)")
def test_the_plain_big_memory_is_the_builds_own_whatever_the_parents_peak():
    """Linux carries a parent's peak RSS into a child's ru_maxrss across fork and exec: measured that way, a child of a
    large bench process read 0 B per body. The child's figure is its build's own: more than zero, and the same
    (within allocator noise) whether this parent holds 320 MB more or not."""
    alone = bench.scenes.plain_big(100_000, 1000, 1)
    held = np.ones(40_000_000)          # 320 MB resident in this (parent) process while the child runs
    beside = bench.scenes.plain_big(100_000, 1000, 1)
    assert held[-1] == 1.0
    assert alone["rss_basis"].startswith("VmHWM") and alone["rss_per_body_B"] > 0, alone
    assert 0.5 * alone["rss_per_body_B"] <= beside["rss_per_body_B"] <= 2 * alone["rss_per_body_B"], (alone, beside)
