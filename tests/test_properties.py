"""Property-based tests (hypothesis, derandomized): invariants over random valid bodies and states.

Bodies: principal moments obeying the triangle inequality (I_a <= I_b <= I_c <= I_a + I_b, in a
random axis order, ratios up to 100), masses 0.1 … 10 kg; states: random unit q, |ω_i| <= 5 rad/s.
"""
from __future__ import annotations

import numpy as np
from hypothesis import HealthCheck, assume, given, settings
from hypothesis import strategies as st

import lavendersim as lv
from lavendersim import backends
from lavendersim import oracle as R
from lavendersim.kernels import K

# No timing checks: no per-example deadline, and not hypothesis's "data generation too slow" health
# check (wall-clock based: it fails on a loaded machine, not on a wrong result).
FAST = settings(derandomize=True, max_examples=40, deadline=None, suppress_health_check=[HealthCheck.too_slow])
KERNELS = settings(derandomize=True, max_examples=200, deadline=None, suppress_health_check=[HealthCheck.too_slow])

finite = st.floats(-1.0, 1.0, allow_nan=False, allow_infinity=False)


@st.composite
def moments(draw):
    a = draw(st.floats(0.05, 5.0))
    b = draw(st.floats(a, 5.0))
    c = b + draw(st.floats(0.0, 1.0)) * a            # b <= c <= a + b
    perm = draw(st.permutations([0, 1, 2]))
    return np.array([a, b, c])[list(perm)]


@st.composite
def unit_quaternions(draw):
    q = np.array([draw(finite) for _ in range(4)])
    assume(np.linalg.norm(q) > 1e-3)
    return q / np.linalg.norm(q)


vectors = st.lists(st.floats(-5.0, 5.0, allow_nan=False), min_size=3, max_size=3).map(np.array)
masses = st.floats(0.1, 10.0)
dts = st.sampled_from([1e-4, 1e-3, 3e-3, 1e-2])


def _sim(I_b, m, q, w, dt, integrator="rk4", backend="c", effects=()):
    scene = lv.Scene()
    scene.add_body(lv.Body("b", m, I_b, q=q, omega_b=w, v_w=(0.1, 0.0, -0.2)))
    for name, params in effects:
        scene.add_effect(name, **params)
    opts = {"rtol": 1e-12, "atol": 1e-12} if integrator in getattr(backends, "ADAPTIVE", ()) else {}
    return lv.Sim(scene, dt=dt, integrator=integrator, backend=backend, **opts)


# ------------------------------------------------------------------------------------ dynamics


@FAST
@given(I_b=moments(), m=masses, q=unit_quaternions(), w=vectors, dt=dts)
def test_rk4_conserves_energy_and_momentum(I_b, m, q, w, dt):
    """Torque-free RK4, 200 steps: relative drift of E and of world L ≤ 1e-12 + 10 (|ω| T)(|ω| dt)^4
    (RK4's global error; the triangle inequality keeps every Euler-equation rate ≤ |ω|)."""
    assume(np.linalg.norm(w) > 1e-3)
    n = 200
    sim = _sim(I_b, m, q, w, dt)
    tr = sim.record(n, 10)
    x = tr.x[:, 0]
    E = 0.5 * np.sum(I_b * x[:, 10:13] ** 2, axis=1)
    L = K.angular_momentum_world(x[:, 3:7], I_b, x[:, 10:13])
    wdt = np.linalg.norm(w) * dt
    bound = 1e-12 + 10 * (np.linalg.norm(w) * n * dt) * wdt ** 4
    assert R.relative_drift(E) <= bound
    assert R.relative_drift(L) <= bound
    assert abs(np.linalg.norm(L[-1]) - np.linalg.norm(L[0])) <= bound * np.linalg.norm(L[0])


@FAST
@given(I_b=moments(), m=masses, q=unit_quaternions(), w=vectors, dt=dts,
       integrator=st.sampled_from(sorted(backends.INTEGRATORS)))
def test_quaternion_stays_unit(I_b, m, q, w, dt, integrator):
    sim = _sim(I_b, m, q, w, dt, integrator=integrator)
    try:
        tr = sim.record(100, 10)
    except lv.DivergenceError:
        return  # an explicit method may diverge at the larger dt: reported, never a NaN state
    assert np.all(np.isfinite(tr.x))
    assert np.max(np.abs(np.linalg.norm(tr.x[:, 0, 3:7], axis=1) - 1.0)) <= 1e-15


@FAST
@given(I_b=moments(), m=masses, q=unit_quaternions(), w=vectors,
       integrator=st.sampled_from(sorted(backends.INTEGRATORS)), forced=st.booleans())
def test_c_and_numpy_backends_agree(I_b, m, q, w, integrator, forced):
    """50 steps at dt = 1e-3: fixed-step integrators to 1e-12 (relative to the state's scale), adaptive
    ones (rtol = atol = 1e-12, different step-size bookkeeping) to 1e-9."""
    effects = [("applied_torque", {"torque_w": [0.3, -0.1, 0.2]}), ("gravity", {"g_w": [0, 0, -9.81]}),
               ("angular_damping", {"c": 0.05})] if forced else []
    xs = []
    for backend in ("c", "numpy"):
        sim = _sim(I_b, m, q, w, 1e-3, integrator=integrator, backend=backend, effects=effects)
        sim.run(50)
        xs.append(sim.x[0].copy())
    tol = 1e-9 if integrator in getattr(backends, "ADAPTIVE", ()) else 1e-12
    scale = 1.0 + np.max(np.abs(xs[0]))
    assert np.max(np.abs(xs[0] - xs[1])) <= tol * scale, (integrator, xs[0] - xs[1])
    assert R.attitude_error(xs[0][3:7], xs[1][3:7]) <= 10 * tol


@FAST
@given(I_b=moments(), m=masses, q=unit_quaternions(), w=vectors,
       integrator=st.sampled_from(sorted(backends.INTEGRATORS)), backend=st.sampled_from(["c", "numpy"]))
def test_zero_strength_effects_change_nothing(I_b, m, q, w, integrator, backend):
    zero = [("applied_torque", {"torque_w": [0, 0, 0]}), ("force_at_point", {"r_b": [0.1, 0.2, 0.3], "F_w": [0, 0, 0]}),
            ("gravity", {"g_w": [0, 0, 0]}), ("linear_damping", {"c": 0.0}), ("angular_damping", {"c": 0.0})]
    a = _sim(I_b, m, q, w, 1e-3, integrator=integrator, backend=backend)
    b = _sim(I_b, m, q, w, 1e-3, integrator=integrator, backend=backend, effects=zero)
    a.run(50)
    b.run(50)
    scale = 1.0 + np.max(np.abs(a.x))
    assert np.max(np.abs(a.x - b.x)) <= 1e-13 * scale


# ------------------------------------------------------------------------------------ kernels


@KERNELS
@given(q=unit_quaternions(), p=unit_quaternions(), v=vectors)
def test_quaternion_kernel_identities(q, p, v):
    Rq = K.quat_to_matrix(q)
    s = 1.0 + np.linalg.norm(v)
    # rotate == matrix product; the matrix is a proper rotation
    assert np.allclose(K.quat_rotate(q, v), Rq @ v, rtol=0, atol=1e-14 * s)
    assert np.allclose(Rq @ Rq.T, np.eye(3), rtol=0, atol=1e-14)
    assert abs(np.linalg.det(Rq) - 1.0) <= 1e-14
    # conj is the inverse; q ⊗ q* = identity
    assert np.allclose(K.quat_rotate(K.quat_conj(q), K.quat_rotate(q, v)), v, rtol=0, atol=1e-14 * s)
    assert np.allclose(K.quat_mul(q, K.quat_conj(q)), [0, 0, 0, 1], rtol=0, atol=1e-15)
    # mul composes rotations and keeps the norm
    qp = K.quat_mul(q, p)
    assert abs(np.linalg.norm(qp) - 1.0) <= 1e-15
    assert np.allclose(K.quat_rotate(qp, v), K.quat_rotate(q, K.quat_rotate(p, v)), rtol=0, atol=1e-14 * s)
    assert np.allclose(K.quat_to_matrix(qp), Rq @ K.quat_to_matrix(p), rtol=0, atol=1e-14)
    # from_matrix inverts to_matrix up to sign; q and −q are one rotation
    q2 = K.matrix_to_quat(Rq)
    assert min(np.max(np.abs(q2 - q)), np.max(np.abs(q2 + q))) <= 1e-15 * 4
    assert np.array_equal(K.quat_to_matrix(-q), Rq)
    assert R.attitude_error(q, -q) <= 1e-15
    # the kinematics agree in both frames
    w = v
    assert np.allclose(K.quat_derivative_body(q, w), K.quat_derivative_world(q, Rq @ w), rtol=0, atol=1e-15 * s)
