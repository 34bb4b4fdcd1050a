"""Sim(..., contract=...): the arithmetic of the C backend's torque-free RK4 SIMD tiles (csrc/batch_simd.h).
"off" (the default) is bitwise the NumPy backend; "fma", the opt-in copy of the tiles compiled with a*b+c fused,
runs, stays within a small measured distance of the bitwise path, and is validated like every setting.
(_lavender_c is built by `pip install`; the suite needs the C backend.)"""
from __future__ import annotations

import pickle

import numpy as np
import pytest

import lavendersim as lv
from lavendersim.backends.c_backend import contract_available
from lavendersim.generated import kernels_numpy
from lavendersim.generated import layout as LY
from lavendersim.validate import LavenderInputError

# Measured (session 17's host, AVX2 + FMA): these 17 tumbling bodies (|omega_b| up to 9.2 rad/s), 400 RK4 steps of
# 1e-2 s: max |fma - bitwise| 5.3e-14 over the state. The bound leaves ~20x for other CPUs and compilers (AVX-512
# fuses other pairs); a wrong term or a lost step is off by orders of magnitude more.
FMA_BOUND = 1e-12


def _tumbling(n: int = 17, seed: int = 3) -> lv.Scene:
    """n plain bodies without effects (the torque-free tiles), random boxes tumbling about every axis."""
    rng = np.random.default_rng(seed)
    sc = lv.Scene()
    for i in range(n):
        sc.add_body(lv.Body.box(f"b{i}", 0.5 + rng.random(), tuple(0.1 + rng.random(3)),
                                q=tuple(rng.standard_normal(4)), omega_b=tuple(3.0 * rng.standard_normal(3)),
                                v_w=tuple(rng.standard_normal(3)), p_w=tuple(rng.standard_normal(3))))
    return sc


def _run(sc: lv.Scene, steps: int, **kw) -> np.ndarray:
    sim = lv.Sim(sc, dt=1e-2, integrator="rk4", **kw)
    sim.run(steps)
    return np.array(sim.x, copy=True)


def test_default_is_bitwise_numpy():
    sc = _tumbling()
    np.testing.assert_array_equal(_run(sc, 150, backend="c"), _run(sc, 150, backend="numpy"))
    np.testing.assert_array_equal(_run(sc, 150, backend="c", contract="off"), _run(sc, 150, backend="numpy"))


def test_fma_runs_within_the_measured_bound_of_the_bitwise_path():
    sc = _tumbling()
    off, fma = _run(sc, 400, backend="c"), _run(sc, 400, backend="c", contract="fma")
    assert np.all(np.isfinite(fma))
    assert float(np.max(np.abs(fma - off))) <= FMA_BOUND
    if contract_available():   # the FMA copy ran: some bits differ (else the opt-in would be a no-op)
        assert not np.array_equal(fma, off)
    else:                      # no FMA copy here: the bitwise tiles ran
        np.testing.assert_array_equal(fma, off)


def test_fma_step_run_and_pickle_agree_with_each_other():
    sc = _tumbling(5)
    a = lv.Sim(sc, dt=1e-2, integrator="rk4", backend="c", contract="fma")
    b = lv.Sim(sc, dt=1e-2, integrator="rk4", backend="c", contract="fma")
    for _ in range(20):
        a.step()
    b.run(20)
    np.testing.assert_array_equal(a.x, b.x)
    c = pickle.loads(pickle.dumps(b))
    assert c.contract == "fma"
    b.run(30)
    c.run(30)
    np.testing.assert_array_equal(c.x, b.x)


@pytest.mark.parametrize("bad", ["fast", "FMA", 1, None, True])
def test_contract_rejects_a_bad_value(bad):
    with pytest.raises(LavenderInputError, match="contract"):
        lv.Sim(_tumbling(2), backend="c", contract=bad)


@pytest.mark.parametrize("kw", [{"backend": "numpy"}, {"backend": "c", "dtype": "float32"}])
def test_fma_needs_the_c_backend_in_float64(kw):
    with pytest.raises(LavenderInputError, match="contract"):
        lv.Sim(_tumbling(2), contract="fma", **kw)


def test_contract_is_fixed_once_built():
    sim = lv.Sim(_tumbling(2), backend="c", contract="fma")
    assert sim.contract == "fma"
    with pytest.raises(LavenderInputError, match="contract"):
        sim.contract = "off"


def _norm_error(x: np.ndarray) -> float:
    q = x[:, LY.STATE_Q]
    return float(np.max(np.abs(np.sqrt(np.sum(q * q, axis=1)) - 1.0)))


def test_near_unit_renormalization_holds_in_its_range_and_is_wrong_beyond():
    """The printed series (derive/quaternion.py) keeps q's direction and gives |q| = 1 to rounding for |eps| up to
    QUAT_RENORM_EPS_MAX; well beyond it the norm is visibly off, which is why the FMA tiles fall back there."""
    rng = np.random.default_rng(5)
    u = rng.standard_normal((2000, 4))
    u /= np.linalg.norm(u, axis=1, keepdims=True)
    for scale2, bound in ((1.0 + LY.QUAT_RENORM_EPS_MAX, 4e-16), (1.0 - LY.QUAT_RENORM_EPS_MAX, 4e-16),
                          (1.0 + 64 * LY.QUAT_RENORM_EPS_MAX, None)):
        q = u * np.sqrt(scale2)
        q_unit, eps = kernels_numpy.quat_renormalize_near_unit(q)
        np.testing.assert_allclose(eps, scale2 - 1.0, rtol=1e-9)
        err = float(np.max(np.abs(np.linalg.norm(q_unit, axis=1) - 1.0)))
        np.testing.assert_allclose(q_unit / np.linalg.norm(q_unit, axis=1, keepdims=True), u, rtol=0, atol=8e-16)  # a few roundings
        if bound is not None:
            assert err <= bound, (scale2, err)
        else:   # 5/16 (64 eps_max)^3 ~ 4e-12: the series alone would leave that norm error
            assert err > 1e-12, err


@pytest.mark.skipif(not contract_available(), reason="no FMA copy of the tiles on this build / CPU")
def test_fma_tiles_normalize_a_state_far_from_unit_exactly():
    """A state written far from unit (|q|^2 = 9, 0.25, or 1 + 100 eps_max), through the backend: the first step's
    eps is beyond the series' range, the tile's pass divides by |q| there: unit to rounding, as the bitwise path,
    and the other lanes of the same tile (unit q) keep the series."""
    from lavendersim.backends.c_backend import ROW, CBackend
    sim = lv.Sim(_tumbling(24), dt=1e-2, integrator="rk4", backend="c")
    x0, params = np.array(sim.x, copy=True), np.array(sim._step_params, copy=True)
    for b, s in ((0, 3.0), (5, 0.5), (17, np.sqrt(1 + 100 * LY.QUAT_RENORM_EPS_MAX))):
        x0[b, LY.STATE_Q] *= s
    be, empty = CBackend(), np.zeros((0, ROW))
    off, fma = x0.copy(), x0.copy()
    be.advance(off, params, empty, "rk4", True, 1e-2, 3)
    be.advance(fma, params, empty, "rk4", True, 1e-2, 3, contract="fma")
    assert _norm_error(fma) <= 4e-16
    assert float(np.max(np.abs(fma - off))) <= FMA_BOUND


@pytest.mark.skipif(not contract_available(), reason="no FMA copy of the tiles on this build / CPU")
def test_fma_tiles_normalize_wild_steps_exactly():
    """|omega| dt up to ~0.9: RK4's own norm error per step (~(|omega| dt / 2)^6 / 72) is far beyond the series' range
    for some bodies of the tile; every q still ends unit to rounding, and close to the bitwise path's."""
    sc = lv.Scene()
    rng = np.random.default_rng(11)
    for i in range(16):
        sc.add_body(lv.Body.box(f"b{i}", 1.0, (0.3, 0.2, 0.1), q=tuple(rng.standard_normal(4)),
                                omega_b=tuple((0.5 + 0.1 * i) * rng.standard_normal(3) / 0.05)))
    off, fma = _run(sc, 50, backend="c"), _run(sc, 50, backend="c", contract="fma")
    assert _norm_error(fma) <= 4e-16
    assert _norm_error(off) <= 4e-16
    assert float(np.max(np.abs(fma - off))) <= 1e-9   # chaotic tumbling at |omega| dt ~ 1: rounding grows fast
