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
