"""Every generated kernel agrees through C, NumPy and CasADi and as the SymPy expression at 30 digits.

Inputs are drawn (seeded) from each input's declared domain on the SymPy side. Tolerance, per output:
|value - ref| <= 1e-12 * max(1, max |ref| of that output). The CasADi kernels need the control extra
(`needs("control")`, tests/conftest.py); C and NumPy are checked on every install.
"""
from __future__ import annotations

import numpy as np
import pytest
import sympy as sp

from lavendersim.generated import kernels_numpy

from lavendersim.backends import c_backend  # required: the C build is part of `pip install -e .`

N_POINTS = 6
DPS = 30
RTOL = 1e-12


@pytest.fixture(scope="module")
def sympy_kernels(derivation):
    """The session's derivation (tests/conftest.py): derive.all_kernels(), computed once."""
    return {k.name: k for k in derivation.kernels}


@pytest.fixture(scope="module")
def cases(sympy_kernels):
    """name -> (input points, SymPy reference at 30 digits per point), computed once per kernel and
    shared by the C/NumPy and the CasADi checks."""
    memo = {}

    def get(name):
        if name not in memo:
            kernel = sympy_kernels[name]
            rng = np.random.default_rng(sum(map(ord, name)) * 7919)
            points = [draw_inputs(rng, kernel, i) for i in range(N_POINTS)]
            memo[name] = points, [sympy_reference(kernel, p) for p in points]
        return memo[name]
    return get


def _unit(rng, n):
    v = rng.normal(size=n)
    return v / np.linalg.norm(v)


def draw(rng, domain: str, shape: tuple) -> np.ndarray:
    n = int(np.prod(shape, dtype=int))
    if domain == "real":
        v = rng.uniform(-2.0, 2.0, n)
    elif domain == "positive":
        v = rng.uniform(0.2, 3.0, n)
    elif domain == "small":
        v = rng.uniform(-1e-3, 1e-3, n)
    elif domain in ("unit_quaternion", "unit_vector"):
        v = _unit(rng, n)
    elif domain == "spd_diag":  # principal moments of a physical body: positive, triangle inequality
        while True:
            v = rng.uniform(0.2, 3.0, n)
            if n != 3 or all(v[i] <= v[(i + 1) % 3] + v[(i + 2) % 3] for i in range(3)):
                break
    elif domain == "inertia_sym":  # symmetric, diagonally dominant, diagonal above any "positive" draw
        d = np.diag(rng.uniform(4.0, 6.0, 3))
        off = np.triu(rng.uniform(-0.3, 0.3, (3, 3)), 1)
        v = (d + off + off.T).ravel()
    else:
        raise AssertionError(f"unknown domain {domain!r}")
    return v.reshape(shape)


def draw_inputs(rng, kernel, i: int = 0) -> list[np.ndarray]:
    if kernel.name == "matrix_to_quat":  # must be a rotation matrix; cycle Shepperd's four branches
        (arg,) = kernel.inputs
        assert arg.shape == (3, 3)
        q = _unit(rng, 4)
        big = int(np.argmax(np.abs(q)))
        q[[big, i % 4]] = q[[i % 4, big]]
        return [kernels_numpy.quat_to_matrix(q)]
    return [draw(rng, a.domain, a.shape) for a in kernel.inputs]


def sympy_reference(kernel, values: list[np.ndarray]) -> list[np.ndarray]:
    subs = {}
    for arg, val in zip(kernel.inputs, values):
        for sym, x in zip(arg.flat, np.ravel(val)):
            subs[sym] = sp.Float(float(x), DPS)
    flat = []
    for e in kernel.output_exprs:
        r = sp.sympify(e).xreplace(subs).evalf(DPS)
        if r.is_Boolean or not r.is_number:
            raise AssertionError(f"{kernel.name}: output did not evaluate to a number: {r}")
        flat.append(float(r))
    out, i = [], 0
    for arg in kernel.outputs:
        out.append(np.array(flat[i:i + arg.size]).reshape(arg.shape))
        i += arg.size
    return out


def as_list(x):
    return list(x) if isinstance(x, tuple) else [x]


def test_sympy_and_numpy_tables_match(sympy_kernels):
    assert list(kernels_numpy.KERNELS) == list(sympy_kernels)
    assert [n for n, _, _ in c_backend._c.kernels()] == list(kernels_numpy.KERNELS)


@pytest.mark.parametrize("name", list(kernels_numpy.KERNELS))
def test_kernel_agrees(name, sympy_kernels, cases):
    kernel = sympy_kernels[name]
    fn, in_spec, out_spec = kernels_numpy.KERNELS[name]
    assert [(a.name, a.shape) for a in kernel.inputs] == [(n, tuple(s)) for n, s in in_spec]
    assert [(a.name, a.shape) for a in kernel.outputs] == [(n, tuple(s)) for n, s in out_spec]
    points, refs = cases(name)
    # evaluate C and NumPy on the whole batch at once (exercises the batch packing too)
    batched = [np.stack([p[j] for p in points]) for j in range(len(in_spec))]
    c_out = as_list(c_backend.eval_kernel(name, *batched))
    np_out = as_list(fn(*batched))
    for i, ref in enumerate(refs):
        for (oname, shape), r, c, n in zip(out_spec, ref, c_out, np_out):
            tol = RTOL * max(1.0, float(np.max(np.abs(r))))
            assert c[i].shape == r.shape and n[i].shape == r.shape
            assert np.max(np.abs(c[i] - r)) <= tol, f"C {name}.{oname} at point {i}: {c[i]} vs {r}"
            assert np.max(np.abs(n[i] - r)) <= tol, f"NumPy {name}.{oname} at point {i}: {n[i]} vs {r}"


@pytest.mark.needs("control")
@pytest.mark.parametrize("name", list(kernels_numpy.KERNELS))
def test_casadi_kernel_agrees(name, cases):
    import casadi

    from lavendersim.generated import kernels_casadi

    _, _, out_spec = kernels_numpy.KERNELS[name]
    cas = getattr(kernels_casadi, name)
    points, refs = cases(name)
    for i, (p, ref) in enumerate(zip(points, refs)):
        cas_out = as_list(cas(*[casadi.DM(np.ravel(v)) if np.ndim(v) else float(v) for v in p]))
        assert len(cas_out) == len(out_spec), (name, len(cas_out))
        for (oname, shape), r, ca in zip(out_spec, ref, cas_out):
            ca = np.array(casadi.DM(ca)).ravel().reshape(r.shape)
            tol = RTOL * max(1.0, float(np.max(np.abs(r))))
            assert np.max(np.abs(ca - r)) <= tol, f"CasADi {name}.{oname} at point {i}: {ca} vs {r}"


def test_reference_can_fail(sympy_kernels):
    """The comparison is not vacuous: a perturbed input gives a mismatch beyond the tolerance."""
    kernel = sympy_kernels["quat_rotate"]
    rng = np.random.default_rng(1)
    q, v = draw_inputs(rng, kernel)
    (ref,) = sympy_reference(kernel, [q, v])
    c = c_backend.eval_kernel("quat_rotate", q, v + 1e-9)
    assert np.max(np.abs(c - ref)) > RTOL * max(1.0, np.max(np.abs(ref)))
