"""The integrator physics derived in derive/integrator_physics.py, against independent formulas, on both
backends (the NumPy kernels and the same kernels compiled in C); the printed layouts and tableaux."""
from __future__ import annotations

import re
from fractions import Fraction
from pathlib import Path

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from lavendersim.backends import c_backend
from lavendersim.cli import generated_dir
from lavendersim.generated import kernels_numpy as KN
from lavendersim.generated import layout as LY
from lavendersim.generated import tableaux as T

GEN = generated_dir()
ROOT = Path(__file__).resolve().parents[1]


class _C:
    """The generated kernels evaluated through C, called like kernels_numpy."""

    def __getattr__(self, name):
        return lambda *args: c_backend.eval_kernel(name, *args)


BACKENDS = {"numpy": KN, "c": _C()}


@pytest.fixture(params=list(BACKENDS))
def K(request):
    return BACKENDS[request.param]


def _rng(seed=0):
    return np.random.default_rng(seed)


def _quats(rng, n):
    q = rng.normal(size=(n, 4))
    return q / np.linalg.norm(q, axis=1, keepdims=True)


def _inertia(rng, n):
    return rng.uniform(0.2, 3.0, (n, 3))


def _qmul(a, b):
    """Hamilton product of (x, y, z, w) quaternions through scipy (an independent formula)."""
    return (Rotation.from_quat(a) * Rotation.from_quat(b)).as_quat(canonical=False)


def _same_rotation(q, ref, atol):
    """|q − ref| or |q + ref| (q and −q are one rotation) below atol, row by row."""
    d = np.minimum(np.linalg.norm(q - ref, axis=-1), np.linalg.norm(q + ref, axis=-1))
    assert np.all(d <= atol), d.max()


# ---------------------------------------------------------------- implicit gyroscopic step

def _gyro_inputs(rng, n=20):
    I, w, tau = _inertia(rng, n), rng.normal(size=(n, 3)) * 5, rng.normal(size=(n, 3))
    h, w1 = rng.uniform(1e-3, 0.3, n), w + rng.normal(size=(n, 3))
    return I, w, tau, h, w1


def test_gyro_residual_is_the_implicit_euler_equation(K):
    I, w, tau, h, w1 = _gyro_inputs(_rng(1))
    g = K.implicit_gyro_residual(I, w, tau, h, w1)
    ref = I * (w1 - w) + h[:, None] * np.cross(w1, I * w1) - h[:, None] * tau
    np.testing.assert_allclose(g, ref, rtol=0, atol=1e-12 * np.max(np.abs(ref)))


def test_gyro_jacobian_equals_finite_differences_of_the_residual(K):
    I, w, tau, h, w1 = _gyro_inputs(_rng(2))
    J = K.implicit_gyro_jacobian(I, h, w1)
    eps = 1e-6
    fd = np.empty_like(J)
    for c in range(3):
        dp, dm = w1.copy(), w1.copy()
        dp[:, c] += eps
        dm[:, c] -= eps
        fd[:, :, c] = (K.implicit_gyro_residual(I, w, tau, h, dp) - K.implicit_gyro_residual(I, w, tau, h, dm)) / (2 * eps)
    # central differences of a quadratic residual are exact up to rounding (~1e-16 |g| / eps)
    np.testing.assert_allclose(J, fd, rtol=0, atol=1e-8)


def test_gyro_newton_update_is_a_linear_solve_with_the_jacobian(K):
    I, w, tau, h, w1 = _gyro_inputs(_rng(3))
    new, delta = K.implicit_gyro_newton(I, w, tau, h, w1)
    J = K.implicit_gyro_jacobian(I, h, w1)
    g = K.implicit_gyro_residual(I, w, tau, h, w1)
    ref = np.linalg.solve(J, g[..., None])[..., 0]
    np.testing.assert_allclose(delta, ref, rtol=1e-12, atol=1e-13)
    np.testing.assert_array_equal(new, w1 - delta)


def test_gyro_newton_iteration_solves_the_residual_to_rounding(K):
    I, w, tau, h, _ = _gyro_inputs(_rng(4))
    w1 = w.copy()
    for _ in range(T.GYRO_MAX_ITER):
        w1, d = K.implicit_gyro_newton(I, w, tau, h, w1)
    g = K.implicit_gyro_residual(I, w, tau, h, w1)
    scale = np.max(np.abs(I * w), axis=1) + np.max(np.abs(h[:, None] * tau), axis=1)
    assert np.all(np.max(np.abs(g), axis=1) <= 1e-14 * scale)
    # torque-free, the solved step never gains energy: E − E⁺ = ½(ω − ω⁺)ᵀ I (ω − ω⁺)
    w0 = w.copy()
    for _ in range(T.GYRO_MAX_ITER):
        w0, _ = K.implicit_gyro_newton(I, w, 0 * tau, h, w0)
    loss = 0.5 * np.sum(I * w * w, axis=1) - 0.5 * np.sum(I * w0 * w0, axis=1)
    np.testing.assert_allclose(loss, 0.5 * np.sum(I * (w - w0) ** 2, axis=1), rtol=1e-9, atol=1e-12)


# ---------------------------------------------------------------- exp-map attitude step

@pytest.mark.parametrize("angle", [0.0, 1e-12, 1e-9, 0.99e-8, 1.01e-8, 1e-7, 1e-4, 0.3, 2.0, 3.1])
def test_quat_exp_step_is_the_exact_rotation_both_sides_of_the_series(K, angle):
    """a = h|ω|/2 around the switch at 1e-8 and far from it; a batch mixes them (vectorized select)."""
    rng = _rng(5)
    n = 8
    q = _quats(rng, n)
    axis = rng.normal(size=(n, 3))
    axis /= np.linalg.norm(axis, axis=1, keepdims=True)
    h = rng.uniform(1e-3, 1e-1, n)
    w = axis * (2 * angle / h)[:, None]
    got = K.quat_exp_step(q, w, h)
    ref = _qmul(q, Rotation.from_rotvec(h[:, None] * w).as_quat(canonical=False))
    _same_rotation(got, ref, 4e-16 * 4)
    np.testing.assert_allclose(np.linalg.norm(got, axis=1), 1.0, atol=4e-16 * 4)


def test_quat_exp_step_batch_mixing_small_and_large_angles_matches_row_by_row(K):
    rng = _rng(6)
    q, h = _quats(rng, 6), np.full(6, 0.01)
    w = rng.normal(size=(6, 3)) * np.array([0.0, 1e-9, 1e-6, 1.0, 100.0, 600.0])[:, None]
    together = K.quat_exp_step(q, w, h)
    for i in range(6):
        np.testing.assert_array_equal(together[i], K.quat_exp_step(q[i], w[i], h[i]))
    np.testing.assert_array_equal(together[0], q[0])  # ω = 0: the identity rotation, exactly


# ---------------------------------------------------------------- splitting

STRANG_REF = [(0, 0.5), (1, 0.5), (2, 1.0), (1, 0.5), (0, 0.5)]  # typed here on purpose: an independent peer


def _strang_reference(I, q, w, h):
    """Exact flows of L_a²/(2 I_a) composed with scipy: the attitude turns by +θ about body axis a, the body
    momentum by −θ, θ = τ L_a / I_a."""
    q, L = q.copy(), I * w
    for a, f in STRANG_REF:
        th = f * h * L[:, a] / I[:, a]
        e = np.zeros((len(th), 3))
        e[:, a] = th
        r = Rotation.from_rotvec(e)
        q = _qmul(q, r.as_quat(canonical=False))
        L = r.inv().apply(L)
    return q, L / I


def test_splitting_rotation_is_the_composition_of_exact_axis_flows(K):
    rng = _rng(7)
    n = 12
    I, q, w, h = _inertia(rng, n), _quats(rng, n), rng.normal(size=(n, 3)) * 3, rng.uniform(1e-3, 0.5, n)
    qn, wn = K.splitting_rotation(I, q, w, h)
    q_ref, w_ref = _strang_reference(I, q, w, h)
    _same_rotation(qn, q_ref, 2e-15)
    np.testing.assert_allclose(wn, w_ref, rtol=0, atol=2e-14 * np.max(np.abs(w)))


def test_splitting_rotation_conserves_world_momentum_and_body_momentum_norm(K):
    rng = _rng(8)
    n = 12
    I, q, w, h = _inertia(rng, n), _quats(rng, n), rng.normal(size=(n, 3)) * 3, rng.uniform(1e-3, 0.5, n)
    qn, wn = K.splitting_rotation(I, q, w, h)
    L0 = Rotation.from_quat(q).apply(I * w)
    L1 = Rotation.from_quat(qn).apply(I * wn)
    np.testing.assert_allclose(L1, L0, rtol=0, atol=1e-14 * np.max(np.abs(L0)))
    np.testing.assert_allclose(np.linalg.norm(I * wn, axis=1), np.linalg.norm(I * w, axis=1), rtol=1e-14)


def test_splitting_rotation_of_a_principal_spin_is_the_exact_rotation(K):
    I, q = np.array([1.0, 2.0, 3.0]), np.array([0.1, -0.2, 0.3, 0.9]) / np.linalg.norm([0.1, -0.2, 0.3, 0.9])
    for a in range(3):
        w = np.zeros(3)
        w[a] = 2.5
        qn, wn = K.splitting_rotation(I, q, w, 0.2)
        _same_rotation(qn, _qmul(q, Rotation.from_rotvec(0.2 * w).as_quat(canonical=False)), 4e-16)
        np.testing.assert_allclose(wn, w, rtol=0, atol=1e-15)


def test_kick_drift_and_translation_kernels(K):
    rng = _rng(9)
    n = 10
    m, I = rng.uniform(0.5, 3, n), _inertia(rng, n)
    p, v, w, F, tb = (rng.normal(size=(n, 3)) for _ in range(5))
    h = rng.uniform(1e-3, 0.1, n)
    vn, wn = K.splitting_kick(m, I, v, w, F, tb, h)
    np.testing.assert_allclose(vn, v + h[:, None] * F / m[:, None], rtol=4e-16, atol=4e-16)
    np.testing.assert_allclose(wn, w + h[:, None] * tb / I, rtol=4e-16, atol=4e-16)
    np.testing.assert_allclose(K.translation_drift(p, v, h), p + h[:, None] * v, rtol=4e-16, atol=4e-16)
    pn, vn2 = K.semi_implicit_translation(m, p, v, F, h)
    np.testing.assert_array_equal(vn2, vn)
    np.testing.assert_allclose(pn, p + h[:, None] * vn, rtol=4e-16, atol=4e-16)
    pd, vd = K.translation_rhs(m, v, F)
    np.testing.assert_array_equal(pd, v)
    np.testing.assert_allclose(vd, F / m[:, None], rtol=4e-16)


# ---------------------------------------------------------------- wheel saturation

def _saturate_reference(command, Omega, tl, sl):
    """The saturation as it was written by hand before it was derived."""
    u = np.minimum(np.maximum(command, -tl[:, None]), tl[:, None])
    return np.where((np.abs(Omega) >= sl[:, None]) & (u * Omega > 0), 0.0, u)


def test_wheel_saturation_keeps_its_semantics_bitwise(K):
    rng = _rng(10)
    n = 400
    tl, sl = rng.uniform(0.05, 0.5, n), rng.uniform(10, 50, n)
    cmd = rng.normal(size=(n, 3)) * 0.4
    Om = rng.normal(size=(n, 3)) * 40
    # edges: exactly at the limits, zero command / rate, signed zeros
    cmd[:20, 0], Om[20:40, 1] = tl[:20], sl[20:40]
    cmd[40:60, 2], Om[60:80, 0] = -tl[40:60], -sl[60:80]
    cmd[80:90], Om[90:100], cmd[100:110] = 0.0, 0.0, -0.0
    got = K.wheel_saturation(cmd, Om, tl, sl)
    ref = _saturate_reference(cmd, Om, tl, sl)
    np.testing.assert_array_equal(got, ref)
    assert np.any(got == 0.0) and np.any(np.abs(got) == tl[:, None]) and np.any((got != 0) & (np.abs(got) < tl[:, None]))


# ---------------------------------------------------------------- printing

def _kernel_source(text, start, end):
    i = text.index(start)
    return text[i:text.index(end, i)]


def test_the_exp_map_series_is_a_c_branch_and_a_numpy_select():
    c = _kernel_source((GEN / "kernels.c").read_text(), "void lv_quat_exp_step(", "\n}\n")
    assert "?" in c and "sin(" in c
    py = _kernel_source((GEN / "kernels_numpy.py").read_text(), "def quat_exp_step(", "\n\n\n")
    assert "numpy.select(" in py


def test_layout_header_and_module_agree():
    defines = dict(re.findall(r"#define LV_(\w+) (\d+)\b", (GEN / "layout.h").read_text()))
    for row, layout in (("STATE", LY.STATE_LAYOUT), ("PARAM", LY.PARAM_LAYOUT), ("MODEL", LY.MODEL_LAYOUT),
                        ("XS", LY.XS_LAYOUT)):
        off = 0
        for name, sl in layout.items():
            assert sl.start == off and int(defines[f"{row}_{name.upper()}"]) == off
            off = sl.stop
        assert int(defines[f"{row}_SIZE"]) == off == getattr(LY, f"{row}_SIZE")
    assert (LY.STATE_SIZE, LY.PARAM_SIZE, LY.MODEL_SIZE, LY.XS_SIZE) == (13, 4, 36, 17)   # MODEL_CUTOFF: issue 13; 4 wheel slots (J, A_b, Omega)
    assert LY.STATE_Q == slice(3, 7) and LY.MODEL_TORQUE_LIMIT == 20 and LY.MODEL_A_B == slice(24, 36)


def test_tableaux_header_and_module_agree_with_the_published_coefficients():
    h = (GEN / "tableaux.h").read_text()
    rows = re.search(r"LV_DP_A\[7\]\[6\] = \{(.*?)\n\};", h, re.S).group(1)
    a_c = [[float(v) for v in r.split(",") if v.strip()] for r in re.findall(r"\{([^{}]*)\}", rows)]
    for s_, row in enumerate(T.DP_A):
        assert a_c[s_][:len(row)] == list(row) and all(v == 0.0 for v in a_c[s_][len(row):])
    e_c = [float(v) for v in re.search(r"LV_DP_E\[7\] = \{(.*?)\};", h).group(1).split(",")]
    assert e_c == list(T.DP_E)
    # Hairer, Nørsett & Wanner, table II.5.2 (b̂: the 4th-order weights), typed here independently
    published_e = [Fraction(71, 57600), 0, Fraction(-71, 16695), Fraction(71, 1920), Fraction(-17253, 339200),
                   Fraction(22, 525), Fraction(-1, 40)]
    assert list(T.DP_E) == [float(f) for f in published_e]
    assert T.DP_A[4] == (19372 / 6561, -25360 / 2187, 64448 / 6561, -212 / 729)
    assert sum(T.DP_A[6]) == pytest.approx(1.0, abs=1e-15)
    for name in ("DP_SAFETY", "DP_FACMIN", "DP_FACMAX", "DP_HMIN_REL", "GYRO_TOL_SQ", "RK4_B_DEN"):
        m = re.search(rf"#define LV_{name} \(?([-0-9.e]+)", h)
        assert float(m.group(1)) == float(getattr(T, name)), name
    assert (T.DP_SAFETY, T.DP_FACMIN, T.DP_FACMAX, T.DP_HMIN_REL, T.DP_MAX_SUBSTEPS) == (0.9, 0.2, 5.0, 1e-12, 1_000_000)
    assert [T.RK4_B0, T.RK4_B1, T.RK4_B2, T.RK4_B3] == [1.0, 2.0, 2.0, 1.0] and T.RK4_B_DEN == 6
    assert T.STRANG == tuple(STRANG_REF)


HAND_PHYSICS = [r"np\.cross", r"\bsin\(", r"\bcos\(", r"np\.linalg\.solve", r"np\.linalg\.inv", r"quat_mul\(",
                r"1e-8", r"/ ?6\b", r"19372", r"\b0\.9\b"]


@pytest.mark.parametrize("path", ["lavendersim/csrc/step.c", "lavendersim/backends/numpy_backend.py",
                                  "lavendersim/backends/__init__.py", "lavendersim/sim.py"])
def test_no_hand_written_physics_or_tableau_in_the_step_code(path):
    text = (ROOT / path).read_text()
    code = re.sub(r"/\*.*?\*/|#[^\n]*|\"\"\".*?\"\"\"", "", text, flags=re.S)  # comments and docstrings
    found = [p for p in HAND_PHYSICS if re.search(p, code)]
    assert not found, f"{path}: {found}"


def test_no_cross_product_typed_by_hand_anywhere_in_the_runtime():
    """Issue 10's grep check: cross products are derived kernels (generated/), never typed in
    lavendersim/ or csrc/ — oracle.py, the deliberately independent oracle (was reference.py), excepted."""
    pkg = ROOT / "lavendersim"
    files = [p for p in pkg.rglob("*") if p.suffix in (".py", ".c", ".h") and p.name != "oracle.py"
             and "generated" not in p.parts]
    assert len(files) > 20
    offenders = []
    for p in files:
        code = re.sub(r"/\*.*?\*/|#[^\n]*|\"\"\".*?\"\"\"", "", p.read_text(), flags=re.S)
        if re.search(r"np\.cross|numpy\.cross|\bcross\(", code):
            offenders.append(str(p.relative_to(ROOT)))
    assert not offenders, offenders


@pytest.mark.parametrize("a, b", [([0, 0, 1], [0, 0, -1]), ([1, 0, 0], [-1, 0, 0]), ([0.6, 0.8, 0], [0, 0, 1]),
                                  ([0, 0, 1], [0, 0, 1]), ([1, 1, 1], [1, -1, 1e-13]), ([0, 0.6, 0.8], [0, -0.6, -0.8])])
def test_quat_from_two_vectors_takes_a_onto_b_also_antiparallel(a, b):
    from lavendersim.generated import kernels_numpy as KN

    a, b = np.asarray(a, float) / np.linalg.norm(a), np.asarray(b, float) / np.linalg.norm(b)
    q = np.asarray(KN.quat_from_two_vectors(a, b), dtype=float)
    assert abs(np.linalg.norm(q) - 1.0) < 1e-15
    assert np.allclose(np.asarray(KN.quat_rotate(q, a), dtype=float), b, atol=2e-16 * 8)


def test_quat_from_two_vectors_on_random_pairs():
    from lavendersim.generated import kernels_numpy as KN

    rng = np.random.default_rng(7)
    a, b = rng.normal(size=(2, 500, 3))
    a /= np.linalg.norm(a, axis=1, keepdims=True)
    b /= np.linalg.norm(b, axis=1, keepdims=True)
    q = np.asarray(KN.quat_from_two_vectors(a, b), dtype=float)       # batched over the leading axis
    got = np.asarray(KN.quat_rotate(q, a), dtype=float)
    assert got.shape == (500, 3)
    assert np.max(np.abs(got - b)) < 1e-14
