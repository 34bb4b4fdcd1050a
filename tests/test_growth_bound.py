"""The wheeled momentum bound of the growth screen (derive/growth_bound.py): at least the total |L|² the screen
would otherwise compute, on both printings, for states far from the usual ones (q off unit norm, axes of any
length, wide inertia ratios, fast wheels)."""
from __future__ import annotations

import numpy as np
import pytest

from lavendersim.generated import layout as LY
from lavendersim.kernels import K

N = LY.WHEELS_MAX


def _states(rng, n):
    """n random wheeled-body states and rows (q norms 0.2-3 and within 1e-12 of 1, omega and Omega over 12 decades,
    SPD I_p with ratios up to ~1e4, axes unit, of any length, or a padded zero column)."""
    q = rng.normal(size=(n, 4))
    q /= np.linalg.norm(q, axis=1, keepdims=True)
    q *= np.where(rng.random((n, 1)) < 0.5, rng.uniform(0.2, 3.0, (n, 1)), 1 + rng.uniform(-1e-12, 1e-12, (n, 1)))
    w = rng.normal(size=(n, 3)) * 10.0 ** rng.uniform(-6, 6, (n, 1))
    Om = rng.normal(size=(n, N)) * 10.0 ** rng.uniform(-6, 6, (n, 1))
    S = rng.normal(size=(n, 3, 3))
    I_p = S @ np.swapaxes(S, 1, 2) + np.einsum("n,ij->nij", 10.0 ** rng.uniform(-4, 0, n), np.eye(3))
    A = rng.normal(size=(n, 3, N))
    A *= np.where(rng.random((n, 1, N)) < 0.5, 1 / np.linalg.norm(A, axis=1, keepdims=True), rng.uniform(0, 3, (n, 1, N)))
    A[rng.random(n) < 0.2, :, N - 1] = 0.0          # a padded slot
    J = 10.0 ** rng.uniform(-6, -2, (n, N))
    return q, w, Om, I_p, A, J


@pytest.mark.parametrize("backend", ["numpy", "c"])
def test_the_bound_is_at_least_the_computed_total_momentum(backend):
    rng = np.random.default_rng(29)
    q, w, Om, I_p, A, J = _states(rng, 20000)
    if backend == "c":
        from lavendersim.backends import c_backend

        def ev(name, *a):
            return c_backend.eval_kernel(name, *a)
    else:
        def ev(name, *a):
            return getattr(K, name)(*a)
    L = ev(f"wheels{N}_total_momentum", q, w, Om, I_p, A, J)
    L2 = L[:, 0] * L[:, 0] + L[:, 1] * L[:, 1] + L[:, 2] * L[:, 2]       # as the C screen sums it
    w_abs = ev("validity_wdt", w, np.ones(len(w)))[0]                  # the screen's |omega|
    c = ev(f"wheels{N}_momentum_bound_factors", I_p, A, J)
    B2 = ev(f"wheels{N}_momentum_bound", q, w_abs, Om, c)
    assert np.all(np.isfinite(B2)) and np.all(B2 >= L2)
    # how loose it is at worst for a unit q and wheels at rest: omega along I_p's largest principal direction gives
    # |L| = lambda_max |omega|, the bound |I_p|_F |omega| (at most sqrt(3) lambda_max), so the ratio is that of squares
    top = np.linalg.eigh(I_p)[1][:, :, -1]
    unit = q / np.linalg.norm(q, axis=1, keepdims=True)
    L_top = ev(f"wheels{N}_total_momentum", unit, top, np.zeros_like(Om), I_p, A, J)
    ratio = ev(f"wheels{N}_momentum_bound", unit, np.ones(len(q)), np.zeros_like(Om), c) / np.sum(L_top ** 2, axis=1)
    assert np.all(ratio >= 1.0) and np.all(ratio <= np.sum(I_p ** 2, axis=(1, 2)) / np.linalg.eigvalsh(I_p)[:, -1] ** 2 * (1 + 1e-9))


def test_the_bound_reaches_past_a_dropped_term():
    """The factor |q|^2 + |1 - |q|^2| is needed: with |q|^2 alone the bound fails for a short q (the printed R(q) is
    |q|^2 R + (1 - |q|^2) 1), so a wrong print would show here."""
    q = np.array([0.0, 0.0, 0.0, 0.3])
    I_p, A, J = np.diag([1.0, 2.0, 3.0]), np.zeros((3, N)), np.ones(N) * 1e-3
    w = np.array([0.0, 0.0, 1.0])
    L = getattr(K, f"wheels{N}_total_momentum")(q, w, np.zeros(N), I_p, A, J)
    c = getattr(K, f"wheels{N}_momentum_bound_factors")(I_p, A, J)
    B2 = getattr(K, f"wheels{N}_momentum_bound")(q, 1.0, np.zeros(N), c)
    assert L @ L <= B2
    assert L @ L > (0.09 * c[0]) ** 2     # |q|^2 |I_p|_F |omega| alone is below |L| here
