"""generated/kernels_scalar.py (the kernels printed for Python floats) equals the NumPy printing bitwise.

Every kernel of kernels_numpy.KERNELS, at seeded inputs in [0.5, 2]: the float kernel returns the NumPy kernel's
numbers bit for bit, or raises (ValueError, ZeroDivisionError) where NumPy meets an invalid operation or a division
by zero (checked with numpy.errstate(all="raise"); a kernel with branches evaluates them all in NumPy, so there the
float kernel may raise on a branch NumPy leaves unused). matrix_to_quat is checked bitwise on rotation matrices.
The effects' float dispatch equals the NumPy one.

Where the NumPy printing calls a function NumPy evaluates with its own routines rather than the C library's
(arctan2, arccos, arcsin, arctan, exp, log, tan, tanh, power: NumPy >= 2.4 has SIMD implementations of these, which
differ from libm, and so from Python's math module, in the last bit at ~5 % of inputs; measured 1 ulp at most for
each, 200 000 inputs), the two agree to 1 ulp instead (np.testing.assert_array_max_ulp); every other kernel (+ - * /,
sqrt, sin, cos, min, max, branches) stays bitwise.
"""
from __future__ import annotations

import inspect
import re

import numpy as np
import pytest

from lavendersim.generated import kernels_numpy as KN
from lavendersim.generated import kernels_scalar as KS

POINTS = 4
# NumPy functions evaluated by NumPy's own routines (not libm): their kernels agree with math's to 1 ulp
OWN_ROUTINES = re.compile(r"numpy\.(arctan2|arccos|arcsin|arctan|exp|log|tan|tanh|power)\(|\*\*")


def _floats(a: np.ndarray):
    return float(a) if a.shape == () else tuple(a.ravel().tolist())


def _flat(out, n_out: int) -> list[np.ndarray]:
    outs = (out,) if n_out == 1 else out
    return [np.asarray(o, dtype=float).ravel() for o in outs]


@pytest.mark.parametrize("name", sorted(KN.KERNELS))
def test_scalar_kernel_is_numpy_bitwise(name):
    fn, ins, outs = KN.KERNELS[name]
    rng = np.random.default_rng(sum(map(ord, name)))
    own = OWN_ROUTINES.search(inspect.getsource(fn)) is not None
    for _ in range(POINTS):
        args = [rng.uniform(0.5, 2.0, shape) for _, shape in ins]
        try:
            got = KS.__dict__[name](*[_floats(a) for a in args])
        except (ValueError, ZeroDivisionError):
            if "numpy.errstate" in inspect.getsource(fn):   # NumPy evaluates every branch, NaN where invalid
                continue
            with pytest.raises(FloatingPointError), np.errstate(all="raise", under="ignore"):
                fn(*args)
            continue
        with np.errstate(all="ignore"):
            want = fn(*args)
        for w, g in zip(_flat(want, len(outs)), _flat(got, len(outs))):
            if own:
                np.testing.assert_array_max_ulp(w, g, maxulp=1)
            else:
                assert w.tobytes() == g.tobytes(), f"{name}: {w} != {g}"


def test_every_kernel_is_printed_for_floats():
    assert set(KN.KERNELS) <= set(KS.__dict__)


@pytest.mark.parametrize("name", sorted(KN.EFFECT_APPLY))
def test_scalar_effect_dispatch_is_numpy_bitwise(name):
    from lavendersim import effects as E

    rng = np.random.default_rng(len(name))
    n_params = max(E.REGISTRY[name].n_params, 1)
    p, x, v, m, I = rng.uniform(0.5, 2.0, n_params), rng.uniform(-1, 1, 13), rng.normal(size=3), 1.5, rng.uniform(1, 2, 3)
    x[3:7] /= np.linalg.norm(x[3:7])
    want = KN.EFFECT_APPLY[name](p[None], x[None], v[None], np.array([m]), I[None])
    got = KS.EFFECT_APPLY[name](tuple(p.tolist()), tuple(x.tolist()), tuple(v.tolist()), m, tuple(I.tolist()))
    for w, g in zip(want, got):
        assert (w is None) == (g is None)
        if w is not None:
            assert np.asarray(w, float).ravel().tobytes() == np.asarray(g, float).tobytes()


def test_matrix_to_quat_on_rotations_is_bitwise():
    rng = np.random.default_rng(5)
    for i in range(8):
        q = rng.normal(size=4)
        q[[int(np.argmax(np.abs(q))), i % 4]] = q[[i % 4, int(np.argmax(np.abs(q)))]]   # each of Shepperd's branches
        R = KN.quat_to_matrix(q / np.linalg.norm(q))
        assert KN.matrix_to_quat(R).tobytes() == np.array(KS.matrix_to_quat(tuple(R.ravel().tolist()))).tobytes()
