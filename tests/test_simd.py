"""The batched torque-free RK4 path in C (lavendersim/csrc/batch_simd.h): struct-of-arrays tiles that the
compiler vectorizes, one copy per instruction set chosen at run time. Every instruction set the CPU has
must give bitwise the scalar block path's states (same operations in the same order, no FMA
contraction), for body counts that are no multiple of any lane count, with q normalized or not, and a
body that diverges inside a tile must be reported exactly as the scalar path reports it.
(_lavender_c is built by `pip install`; the suite needs the C backend.)"""
from __future__ import annotations

import numpy as np
import pytest

import lavendersim as lv
from lavendersim import _lavender_c as C


@pytest.fixture
def levels():
    """Every ISA level this CPU runs, scalar (0: the SIMD path off) first; the best is restored after."""
    best = C.isa(-1)[2]
    yield list(range(best + 1))
    C.isa(-1)


def _scene(n: int, seed: int, effect_every: int = 0) -> lv.Scene:
    rng = np.random.default_rng(seed)
    sc = lv.Scene()
    for i in range(n):
        sc.add_body(lv.Body.box(f"b{i}", 0.5 + rng.random(), tuple(0.1 + rng.random(3)),
                                q=tuple(rng.standard_normal(4)), omega_b=tuple(3.0 * rng.standard_normal(3)),
                                v_w=tuple(rng.standard_normal(3)), p_w=tuple(rng.standard_normal(3))))
        if effect_every and i % effect_every == 0:
            sc.add_effect("applied_torque", body=f"b{i}", torque_w=[1e-2, -2e-2, 3e-2])
    return sc


def _run(sc: lv.Scene, level: int, steps: int, normalize: bool = True) -> np.ndarray:
    assert C.isa(level)[0] == level
    sim = lv.Sim(sc, dt=1e-2, integrator="rk4", backend="c", normalize=normalize)
    sim.run(steps)
    return np.array(sim.x, copy=True)


def test_isa_reports_names_and_caps_at_the_best(levels):
    cur, name, best, best_name = C.isa()
    assert (cur, name) == (best, best_name) and best == levels[-1]
    assert C.isa(0)[1] == "scalar" and C.isa(C.ISA_AVX512)[0] == best  # capped at what the CPU has
    with pytest.raises(ValueError, match="level"):
        C.isa(7)


@pytest.mark.parametrize("n", [2, 3, 4, 5, 8, 16, 17, 67, 131])   # 64 bodies per tile; lanes of 2, 4, 8; padded
                                                                # small tiles
@pytest.mark.parametrize("normalize", [True, False])
def test_every_isa_is_the_scalar_path_bitwise(levels, n, normalize):
    sc = _scene(n, seed=n)
    want = _run(sc, 0, 150, normalize)
    for level in levels[1:]:
        np.testing.assert_array_equal(_run(sc, level, 150, normalize), want, err_msg=C.isa(level)[1])


def test_mixed_scene_free_bodies_on_the_simd_path_are_bitwise(levels):
    """Free bodies beside bodies with effects: the free ones take the tiles, the others the block path."""
    sc = _scene(70, seed=9, effect_every=3)
    want = _run(sc, 0, 100)
    for level in levels[1:]:
        np.testing.assert_array_equal(_run(sc, level, 100), want)


def _assert_levels_report_alike(levels, x0, params, effects, bad):
    """RK4 50 steps of dt 1e-2 from x0 at every instruction-set level: a body of `bad` diverges (status 1) with a
    finite last state, and every level reports the same status, step, body and that body's last state bitwise."""
    x0 = np.array(x0, dtype=np.float64, copy=True)
    params = np.ascontiguousarray(params, dtype=np.float64)
    effects = np.ascontiguousarray(effects, dtype=np.float64)
    reports = []
    for level in levels:
        C.isa(level)
        x = x0.copy()
        status, step, body = C.simulate(x, params, effects, C.RK4, 1, 1e-2, 50)
        reports.append((status, step, body, x[body].copy()))
    assert reports[0][0] == 1 and reports[0][2] in bad and np.isfinite(reports[0][3]).all(), reports[0][:3]
    for r in reports[1:]:
        assert r[:3] == reports[0][:3]
        np.testing.assert_array_equal(r[3], reports[0][3])


@pytest.mark.parametrize("bad", [[29], [29, 5], [63, 64]])   # in a tile; two tiles; tile edges
def test_divergence_in_a_tile_is_reported_as_on_the_scalar_path(levels, bad):
    """Bodies blow up among 70 (lv_simulate's contract): every level returns the same status, step and
    body (the earliest step, then the lowest body), and that body's last finite state."""
    from lavendersim.effects import ROW
    n = 70
    x0, params, _ = _scene(n, seed=4).arrays()
    x0 = np.array(x0, dtype=np.float64, copy=True)
    for k, b in enumerate(bad):
        x0[b, 10:13] = [1e150 * (k + 1), 1e150, 1e150]   # overflows within a few steps
    _assert_levels_report_alike(levels, x0, params, np.zeros((0, ROW)), bad)


@pytest.fixture
def two_threads():
    """The SIMD tiles of a call shared by two threads; one thread again after."""
    assert C.threads(2) in (1, 2)   # 1 where the build has no POSIX threads
    yield
    C.threads(1)


@pytest.mark.parametrize("n", [129, 300])                 # 3 and 5 tiles of 64, the last one partial
def test_two_threads_are_one_thread_bitwise(levels, n, two_threads):
    sc = _scene(n, seed=n + 1)
    C.threads(1)
    want = _run(sc, levels[-1], 120)
    C.threads(2)
    np.testing.assert_array_equal(_run(sc, levels[-1], 120), want)
    np.testing.assert_array_equal(_run(sc, 0, 120), want)   # the scalar path ignores threads


@pytest.mark.parametrize("bad", [[200], [10, 250], [250, 10]])   # in the second share; in both
def test_divergence_with_two_threads_is_reported_as_with_one(levels, bad, two_threads):
    from lavendersim.effects import ROW
    x0, params, _ = _scene(300, seed=8).arrays()
    x0 = np.array(x0, dtype=np.float64, copy=True)
    params = np.ascontiguousarray(params, dtype=np.float64)
    for k, b in enumerate(bad):
        x0[b, 10:13] = [1e150 * 10.0 ** k, 1e150, 1e150]   # the later ones overflow sooner
    reports = []
    for threads in (1, 2):
        C.threads(threads)
        x = x0.copy()
        status, step, body = C.simulate(x, params, np.zeros((0, ROW)), C.RK4, 1, 1e-2, 50)
        reports.append((status, step, body, x[body].copy()))
    assert reports[0][0] == 1 and reports[0][2] in bad
    assert reports[1][:3] == reports[0][:3]
    np.testing.assert_array_equal(reports[1][3], reports[0][3])


def test_threads_rejects_a_bad_count():
    with pytest.raises(ValueError, match="threads"):
        C.threads(0)
    assert C.threads() == 1


def _effect_scene(n: int, seed: int) -> lv.Scene:
    """n random bodies, each with its own effects: one applied_torque (most), two (their sum in table
    order), gravity with a torque (the full right-hand side), every-body gravity, or angular damping
    (reads the state: stays off the constant-effect tiles)."""
    sc = _scene(n, seed)
    rng = np.random.default_rng(seed + 100)
    for i in range(n):
        k = i % 7
        sc.add_effect("applied_torque", body=f"b{i}", torque_w=list(1e-3 * rng.standard_normal(3)))
        if k == 1:
            sc.add_effect("applied_torque", body=f"b{i}", torque_w=list(1e-5 * rng.standard_normal(3)))
        elif k == 2:
            sc.add_effect("gravity", body=f"b{i}", g_w=list(rng.standard_normal(3)))
        elif k == 3:
            sc.add_effect("angular_damping", body=f"b{i}", c=0.1 + rng.random())
    return sc


@pytest.mark.parametrize("n", [1, 3, 16, 17, 67, 131])     # any count with constant effects takes the tiles
@pytest.mark.parametrize("normalize", [True, False])
def test_constant_effects_on_the_tiles_are_the_scalar_path_bitwise(levels, n, normalize):
    """Bodies whose effects read no state (applied_torque, gravity) take the SIMD tiles with their sums
    evaluated once per call; every level gives the scalar path's bits."""
    sc = _effect_scene(n, seed=3 * n)
    want = _run(sc, 0, 120, normalize)
    assert np.isfinite(want).all()
    for level in levels[1:]:
        np.testing.assert_array_equal(_run(sc, level, 120, normalize), want, err_msg=C.isa(level)[1])


def test_constant_effects_tiles_with_an_every_body_effect_and_two_threads(levels, two_threads):
    sc = _effect_scene(150, seed=5)
    sc.add_effect("gravity", g_w=[0.0, 0.0, -9.81])      # body -1: every body, after their own effects
    want = _run(sc, 0, 80)
    for threads in (1, 2):
        C.threads(threads)
        for level in levels[1:]:
            np.testing.assert_array_equal(_run(sc, level, 80), want, err_msg=f"{C.isa(level)[1]}, {threads}")


def test_constant_effects_change_the_motion():
    """The tiles do apply the torque: the same bodies without effects end elsewhere."""
    n = 40
    plain = _run(_scene(n, seed=11), C.isa(-1)[2], 50)
    C.isa(-1)
    forced = _run(_effect_scene(n, seed=11), C.isa(-1)[2], 50)
    assert np.abs(forced[:, 10:13] - plain[:, 10:13]).min(axis=1).max() > 1e-6


@pytest.mark.parametrize("bad", [[29], [40, 5], [63, 64]])
def test_divergence_in_a_constant_effect_tile_is_reported_as_on_the_scalar_path(levels, bad):
    """A huge applied torque overflows omega within a few steps: every level reports the same step, body
    and last finite state."""
    n = 70
    sc = _scene(n, seed=6)
    for i in range(n):
        big = 1e296 * (1.0 + bad.index(i)) if i in bad else 1e-3
        sc.add_effect("applied_torque", body=f"b{i}", torque_w=[big, -big, big])
    _assert_levels_report_alike(levels, *sc.arrays(), bad)


def _state_effect_scene(n: int, seed: int, per_body: bool) -> lv.Scene:
    """n random bodies under effects that read the state (the effect tiles): every body the same codes in the same
    order, scene-wide (per_body False) or each its own parameters (per_body True)."""
    sc = _scene(n, seed)
    rng = np.random.default_rng(seed + 200)
    if not per_body:
        sc.add_effect("gravity", g_w=[0.0, 0.0, -9.81])
        sc.add_effect("linear_damping", c=0.3)
        sc.add_effect("angular_damping", c=2e-3)
        return sc
    for i in range(n):
        sc.add_effect("angular_damping", body=f"b{i}", c=1e-3 * (0.05 + rng.random()))
        sc.add_effect("force_at_point", body=f"b{i}", r_b=list(0.1 * rng.standard_normal(3)),
                      F_w=list(1e-2 * rng.standard_normal(3)))
        sc.add_effect("linear_damping", body=f"b{i}", c=rng.random())
    return sc


@pytest.mark.parametrize("n", [2, 5, 8, 16, 33, 67, 131])
@pytest.mark.parametrize("normalize", [True, False])
@pytest.mark.parametrize("per_body", [False, True])
def test_state_reading_effects_on_the_tiles_are_the_scalar_path_bitwise(levels, n, normalize, per_body):
    """Bodies with the same built-in effects that read the state take the effect tiles (stage passes); every level
    gives the scalar path's bits, and the effects do act (the bodies end elsewhere than free ones)."""
    sc = _state_effect_scene(n, 7 * n, per_body)
    want = _run(sc, 0, 120, normalize)
    assert np.isfinite(want).all()
    for level in levels[1:]:
        np.testing.assert_array_equal(_run(sc, level, 120, normalize), want, err_msg=C.isa(level)[1])
    free = _run(_scene(n, 7 * n), 0, 120, normalize)
    assert np.abs(want[:, 7:13] - free[:, 7:13]).min(axis=1).min() > 1e-9


def test_state_reading_effect_tiles_with_two_threads(levels, two_threads):
    sc = _state_effect_scene(300, 12, per_body=True)
    want = _run(sc, 0, 60)
    for threads in (1, 2):
        C.threads(threads)
        np.testing.assert_array_equal(_run(sc, levels[-1], 60), want, err_msg=f"{threads} threads")


FUSED_SETS = (["linear_damping"], ["angular_damping"], ["angular_damping", "linear_damping"],
              ["gravity", "angular_damping"], ["gravity", "gravity", "linear_damping", "angular_damping"],
              ["applied_torque", "angular_damping"],                          # TORQUE kind
              ["applied_torque", "linear_damping", "angular_damping"],        # FULL kind
              ["gravity", "applied_torque", "linear_damping"], ["force_at_point"],
              ["applied_torque", "force_at_point", "angular_damping"],
              ["linear_damping", "gravity", "angular_damping"],   # no fused pattern (stage passes): a constant after
              ["linear_damping", "angular_damping", "force_at_point"])   # three state-reading effects: stage passes


def _fused_params(name: str, rng) -> dict:
    """Random parameters of effect `name` for the fused-tile scenes (damping: c dt / I well inside RK4's bound, the
    smallest I here being ~1e-3)."""
    if name == "gravity":
        return {"g_w": list(rng.standard_normal(3))}
    if name == "applied_torque":
        return {"torque_w": list(1e-2 * rng.standard_normal(3))}
    if name == "force_at_point":
        return {"r_b": list(0.1 * rng.standard_normal(3)), "F_w": list(rng.standard_normal(3))}
    return {"c": (1.0 if name == "linear_damping" else 1e-4) * (0.05 + rng.random())}


@pytest.mark.parametrize("names", FUSED_SETS, ids="+".join)
@pytest.mark.parametrize("n", [5, 67])
@pytest.mark.parametrize("normalize", [True, False])
def test_fused_effect_tiles_are_the_scalar_path_bitwise(levels, names, n, normalize):
    """The fused effect tiles (batch_simd.h, kernels.h's LV_EFFECT_FUSED: a pattern of built-in effects reading the
    state after effects that read none, the whole step per lane), of every tile kind, give the scalar path's bits,
    each body its own parameters."""
    sc = _scene(n, 11 * n)
    rng = np.random.default_rng(n)
    for i in range(n):
        for name in names:
            sc.add_effect(name, body=f"b{i}", **_fused_params(name, rng))
    want = _run(sc, 0, 120, normalize)
    assert np.isfinite(want).all()
    for level in levels[1:]:
        np.testing.assert_array_equal(_run(sc, level, 120, normalize), want, err_msg=C.isa(level)[1])
    free = _run(_scene(n, 11 * n), 0, 120, normalize)
    assert np.abs(want[:, 7:13] - free[:, 7:13]).max(axis=1).min() > 1e-6


@pytest.mark.parametrize("bad", [[29], [40, 5], [63, 64]])
def test_divergence_in_a_fused_effect_tile_is_reported_as_on_the_scalar_path(levels, bad):
    """A huge angular damping (c dt / I far above RK4's stability bound) overflows omega within a few steps in the
    fused tile of linear + angular damping: every level reports the same step, body and last finite state."""
    n = 70
    sc = _scene(n, seed=17)
    for i in range(n):
        sc.add_effect("linear_damping", body=f"b{i}", c=0.1)
        sc.add_effect("angular_damping", body=f"b{i}", c=1e150 * (1.0 + bad.index(i)) if i in bad else 1e-3)
    _assert_levels_report_alike(levels, *sc.arrays(), bad)


@pytest.mark.parametrize("bad", [[29], [40, 5], [63, 64]])
@pytest.mark.parametrize("extra", [[], ["linear_damping"]], ids=["fused", "stage_passes"])
def test_divergence_in_an_effect_tile_is_reported_as_on_the_scalar_path(levels, bad, extra):
    """A huge force at a point overflows within a few steps, on the fused tile of force at point + angular damping
    (the FULL kind) or, with a third state-reading effect, the effect tile's stage passes: every level reports the
    same step, body and last finite state."""
    n = 70
    sc = _scene(n, seed=16)
    for i in range(n):
        big = 1e296 * (1.0 + bad.index(i)) if i in bad else 1e-3
        sc.add_effect("force_at_point", body=f"b{i}", r_b=[0.1, 0.2, 0.3], F_w=[big, -big, big])
        sc.add_effect("angular_damping", body=f"b{i}", c=0.1)
        for name in extra:
            sc.add_effect(name, body=f"b{i}", c=0.05)
    _assert_levels_report_alike(levels, *sc.arrays(), bad)
