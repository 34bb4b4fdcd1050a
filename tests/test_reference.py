"""lavendersim.oracle: the exact torque-free motion and constant-ω attitude against DOP853,
mpmath and independent closed forms; invariants; inertia order; the near-separatrix period;
attitude_error and relative_drift."""
from __future__ import annotations

import math

import mpmath as mp
import numpy as np
import pytest
from scipy.integrate import quad, solve_ivp
from scipy.optimize import brentq

from lavendersim import oracle as R
from lavendersim.generated import kernels_numpy as K

Q0 = K.quat_normalize(np.array([0.3, -0.2, 0.5, 0.8]))
BOX = tuple(float(v) for v in K.inertia_box(1.0, 0.8, 0.2, 0.2))
T10 = np.linspace(0.0, 10.0, 201)

CASES = {
    "diag123_minor_family": ((1.0, 2.0, 3.0), (1.0, 0.5, 0.2)),      # L² < 2E I2: circles axis 1
    "diag123_major_family": ((1.0, 2.0, 3.0), (0.1, 2.0, 0.1)),      # L² > 2E I2: circles axis 3
    "box_0.8x0.2x0.2_mixed": (BOX, (0.7, -1.3, 2.1)),                # symmetric (I_y = I_z)
    "diag312_odd_order": ((3.0, 1.0, 2.0), (0.2, 1.0, -0.5)),
    "diag132_odd_order": ((1.0, 3.0, 2.0), (-1.0, 0.2, 0.5)),
    "thin_rod": ((0.01, 1.0, 1.0001), (1.0, 2.0, 3.0)),
}


def _energy(I, w):
    return K.kinetic_energy(1.0, np.asarray(I, float), np.zeros(3), w)


def _momentum(I, q, w):
    return K.angular_momentum_world(q, np.asarray(I, float), w)


@pytest.mark.parametrize("name", list(CASES))
def test_torque_free_matches_dop853(name):
    I, w0 = CASES[name]
    ref = R.torque_free(I, w0, Q0, T10)
    num = R.dop853(I, w0, Q0, T10)
    assert np.max(np.abs(ref.omega_b - num.omega_b)) <= 1e-10
    assert np.max(R.attitude_error(ref.q, num.q)) <= 1e-9
    assert ref.omega_b.shape == (len(T10), 3) and ref.q.shape == (len(T10), 4)
    assert np.allclose(ref.q[0], Q0, atol=1e-15) and np.allclose(ref.omega_b[0], w0, atol=1e-15)


def test_the_tolerances_bite():
    """A body 1e-6 off in one moment already fails the agreement bounds of the test above."""
    I, w0 = CASES["diag123_major_family"]
    ref = R.torque_free((1.0 + 1e-6, 2.0, 3.0), w0, Q0, T10)
    num = R.dop853(I, w0, Q0, T10)
    assert np.max(np.abs(ref.omega_b - num.omega_b)) > 1e-10
    assert np.max(R.attitude_error(ref.q, num.q)) > 1e-9


@pytest.mark.parametrize("I, w0", list(CASES.values()) + [((1.0, 2.0, 3.0), (1e-3, 5.0, 1e-3)),
                                                          ((2.0, 3.0, 6.0), (3.0, 0.5, 1.0))])
def test_reference_conserves_its_invariants(I, w0):
    t = np.linspace(-5.0, 60.0, 651)
    ref = R.torque_free(I, w0, Q0, t)
    E, L = _energy(I, ref.omega_b), _momentum(I, ref.q, ref.omega_b)
    assert R.relative_drift(E) <= 1e-13 and R.relative_drift(L) <= 1e-13
    assert math.isclose(ref.E, float(_energy(I, np.asarray(w0, float))), rel_tol=1e-15)
    assert np.allclose(ref.L_w, L[0], rtol=0, atol=1e-14 * np.linalg.norm(L[0]))


@pytest.mark.parametrize("C", [
    np.array([[0.0, 0.0, 1.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]]),     # cyclic relabelling
    np.array([[0.0, 1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, -1.0]]),    # swap x, y (and flip z)
])
@pytest.mark.parametrize("I, w0", [((1.0, 2.0, 3.0), (1.0, 0.5, 0.2)), ((1.0, 2.0, 3.0), (0.1, 2.0, 0.1)),
                                   ((1.0, 2.0, 3.0), (1e-3, 5.0, 1e-3))])
def test_inertia_order_is_only_a_relabelling(C, I, w0):
    """The same body described in axes B' = B·C (C a proper signed permutation): I' = Cᵀ I C,
    ω' = Cᵀ ω, q' = q ⊗ q(C); the reference must give the same motion."""
    I, w0 = np.asarray(I), np.asarray(w0)
    Ip = np.diag(C.T @ np.diag(I) @ C)
    qC = K.matrix_to_quat(C)
    a = R.torque_free(I, w0, Q0, T10)
    b = R.torque_free(Ip, C.T @ w0, K.quat_mul(Q0, qC), T10)
    assert not np.allclose(Ip, I)
    assert np.max(np.abs(b.omega_b - a.omega_b @ C)) <= 1e-13
    assert np.max(R.attitude_error(b.q, K.quat_mul(a.q, qC))) <= 1e-12
    assert math.isclose(a.period, b.period, rel_tol=1e-14)


@pytest.mark.parametrize("I, w0, s", [(BOX, (0.7, -1.3, 2.1), 0), ((1.0, 1.0, 3.0), (1.0, 0.5, 0.2), 2),
                                      ((2.0, 1.0, 2.0), (0.3, -2.0, 0.9), 1)])
def test_symmetric_body_closed_form(I, w0, s):
    """Symmetric top, independently: ω_s constant, ω_⊥ turning at Ω = (I_s − I_t) ω_s / I_t, and
    R(t) = exp(t [L_w / I_t]×) R0 exp(−t Ω [e_s]×)."""
    I, w0 = np.asarray(I), np.asarray(w0)
    j, k = (s + 1) % 3, (s + 2) % 3
    It = I[j]
    Om = (I[s] - It) * w0[s] / It
    t = np.linspace(-3.0, 20.0, 231)
    z = (w0[j] + 1j * w0[k]) * np.exp(1j * Om * t)
    w = np.empty((len(t), 3))
    w[:, s], w[:, j], w[:, k] = w0[s], z.real, z.imag
    L_w = _momentum(I, Q0, w0)
    e_s = np.eye(3)[s]
    q = K.quat_mul(K.quat_mul(R.constant_omega(np.array([0, 0, 0, 1.0]), L_w / It, t), Q0),
                   K.axis_angle_to_quat(np.broadcast_to(e_s, (len(t), 3)), -Om * t))
    ref = R.torque_free(I, w0, Q0, t)
    assert ref.kind == "symmetric"
    assert np.max(np.abs(ref.omega_b - w)) <= 1e-13
    assert np.max(R.attitude_error(ref.q, q)) <= 1e-12
    assert math.isclose(ref.period, 2 * math.pi / abs(Om), rel_tol=1e-15)
    assert R.torque_free_period(I, w0) == ref.period


def _mp_omega(I, w0, ts):
    """ω_b(t) of Landau §37 evaluated in 40-digit arithmetic (I sorted ascending, both families)."""
    mp.mp.dps = 40
    I1, I2, I3 = (mp.mpf(v) for v in I)
    w1, w2, w3 = (mp.mpf(v) for v in w0)
    L2 = I1**2 * w1**2 + I2**2 * w2**2 + I3**2 * w3**2
    E2 = I1 * w1**2 + I2 * w2**2 + I3 * w3**2
    if L2 > E2 * I2:
        A = [mp.sqrt((E2 * I3 - L2) / (I1 * (I3 - I1))), mp.sqrt((E2 * I3 - L2) / (I2 * (I3 - I2))),
             mp.sqrt((L2 - E2 * I1) / (I3 * (I3 - I1)))]
        lam = mp.sqrt((I3 - I2) * (L2 - E2 * I1) / (I1 * I2 * I3))
        m = (I2 - I1) * (E2 * I3 - L2) / ((I3 - I2) * (L2 - E2 * I1))
        a, c = 0, 2
    else:
        A = [mp.sqrt((E2 * I3 - L2) / (I1 * (I3 - I1))), mp.sqrt((L2 - E2 * I1) / (I2 * (I2 - I1))),
             mp.sqrt((L2 - E2 * I1) / (I3 * (I3 - I1)))]
        lam = mp.sqrt((I2 - I1) * (E2 * I3 - L2) / (I1 * I2 * I3))
        m = (I3 - I2) * (L2 - E2 * I1) / ((I2 - I1) * (E2 * I3 - L2))
        a, c = 2, 0
    w = [w1, w2, w3]
    sc = mp.sign(w[c])
    u0 = mp.ellipf(mp.atan2(sc * w[1] / A[1], w[a] / A[a]), m)
    out = np.empty((len(ts), 3))
    for n, t in enumerate(ts):
        u = lam * mp.mpf(float(t)) + u0
        out[n, a] = float(A[a] * mp.ellipfun("cn", u, m=m))
        out[n, 1] = float(sc * A[1] * mp.ellipfun("sn", u, m=m))
        out[n, c] = float(sc * A[c] * mp.ellipfun("dn", u, m=m))
    return out, float(4 * mp.ellipk(m) / lam)


@pytest.mark.parametrize("w0", [(1.0, 0.5, 0.2), (0.1, 2.0, 0.1), (1e-3, 5.0, 1e-3), (1e-3, 5.0, -1e-3)])
def test_body_omega_matches_40_digit_evaluation(w0):
    ts = np.linspace(0.0, 60.0, 13)
    exact, P = _mp_omega((1.0, 2.0, 3.0), w0, ts)
    ref = R.torque_free((1.0, 2.0, 3.0), w0, Q0, ts)
    assert np.max(np.abs(ref.omega_b - exact)) <= 1e-12 * np.linalg.norm(w0)
    assert math.isclose(ref.period, P, rel_tol=1e-14)


def test_near_separatrix_flips():
    """ω0 = (1e-3, 5, 1e-3), I = diag(1, 2, 3) over 60 s: vs DOP853, and the period vs the
    DOP853-measured sign changes of the intermediate-axis ω (the Dzhanibekov flips)."""
    I, w0 = (1.0, 2.0, 3.0), (1e-3, 5.0, 1e-3)
    t = np.linspace(0.0, 60.0, 601)
    ref = R.torque_free(I, w0, Q0, t)
    x0 = np.zeros(13)
    x0[3:7], x0[10:13] = Q0, w0
    sol = solve_ivp(lambda _t, x: K.rigid_body_rhs_free(x, np.asarray(I)), (0.0, 60.0), x0,
                    method="DOP853", rtol=1e-13, atol=1e-13, dense_output=True)
    num = sol.sol(t).T
    num[:, 3:7] /= np.linalg.norm(num[:, 3:7], axis=1, keepdims=True)
    # DOP853 at 1e-13 is the weaker of the two here (the 40-digit test holds the reference to 1e-12)
    assert np.max(np.abs(ref.omega_b - num[:, 10:13])) <= 2e-6
    assert np.max(R.attitude_error(ref.q, num[:, 3:7])) <= 5e-7
    assert ref.kind == "asymmetric" and 1 - ref.m < 1e-5
    w2 = num[:, 11]
    idx = np.nonzero(np.sign(w2[:-1]) != np.sign(w2[1:]))[0]
    crossings = np.array([brentq(lambda s: sol.sol(s)[11], t[i], t[i + 1], xtol=1e-14) for i in idx])
    predicted = ref.intermediate_zero_crossings(60.0)
    assert len(crossings) == len(predicted) == 9
    assert np.max(np.abs(crossings - predicted)) <= 1e-6
    assert np.max(np.abs(np.diff(crossings) - ref.period / 2)) <= 1e-6
    assert R.torque_free_period(I, w0) == ref.period


def test_exact_separatrix():
    """L² = 2E I2 exactly (I = (2, 3, 6), ω0 = (3, ½, 1)): sech/tanh; DOP853 leaves the unstable
    homoclinic orbit after a few seconds, so agreement is checked on |t| ≤ 3 s."""
    I, w0 = (2.0, 3.0, 6.0), (3.0, 0.5, 1.0)
    t = np.linspace(-3.0, 3.0, 121)
    ref = R.torque_free(I, w0, Q0, t)
    num = R.dop853(I, w0, Q0, t)
    assert ref.kind == "separatrix" and ref.period == math.inf
    assert np.max(np.abs(ref.omega_b - num.omega_b)) <= 1e-10
    assert np.max(R.attitude_error(ref.q, num.q)) <= 1e-9
    far = R.torque_free(I, w0, Q0, [200.0])                  # tends to a spin about the middle axis
    assert np.allclose(far.omega_b[0], [0.0, math.sqrt(2 * ref.E / 3.0), 0.0], atol=1e-12)


@pytest.mark.parametrize("I, w0", [((1.0, 2.0, 3.0), (0.0, 5.0, 0.0)), ((2.0, 2.0, 2.0), (1.0, 0.5, 0.2)),
                                   ((1.0, 1.0, 3.0), (0.4, -0.3, 0.0))])
def test_constant_omega_motions(I, w0):
    ref = R.torque_free(I, w0, Q0, T10)
    num = R.dop853(I, w0, Q0, T10)
    assert ref.kind == "constant" and ref.period == math.inf
    assert np.all(ref.omega_b == np.asarray(w0))
    assert np.max(R.attitude_error(ref.q, num.q)) <= 1e-10


@pytest.mark.filterwarnings("ignore::scipy.integrate.IntegrationWarning")  # quad's own roundoff notice
def test_precession_angle_matches_quad():
    """The Gauss–Legendre antiderivative extended by periodicity vs scipy's quad on φ̇."""
    I, w0 = np.array([1.0, 2.0, 3.0]), np.array([0.1, 2.0, 0.1])
    sol = R._Solution(I, w0)
    axis = 0
    others = [1, 2]

    def rate(s):
        w = sol.omega(np.array([s]))[0]
        return sol.L * sum(I[i] * w[i] ** 2 for i in others) / sum(I[i] ** 2 * w[i] ** 2 for i in others)

    t = np.array([0.7, 5.3, 13.0, 31.4, -4.2])
    phi = R._precession_angle(sol, axis, t)
    for tk, pk in zip(t, phi):
        edges = np.linspace(0.0, tk, int(abs(tk) // 1.0) + 2)
        exact = sum(quad(rate, lo, hi, epsabs=1e-14, epsrel=1e-14, limit=200)[0] for lo, hi in zip(edges[:-1], edges[1:]))
        assert abs(pk - exact) <= 1e-12 * max(1.0, abs(exact))


def test_long_horizon_and_negative_times():
    I, w0 = (1.0, 2.0, 3.0), (1.0, 0.5, 0.2)
    t = np.array([-7.5, -1.0, 0.0, 2.0, 40.0])
    ref = R.torque_free(I, w0, Q0, t)
    num = R.dop853(I, w0, Q0, t)
    assert np.max(np.abs(ref.omega_b - num.omega_b)) <= 1e-10
    assert np.max(R.attitude_error(ref.q, num.q)) <= 1e-9


def test_constant_omega_matches_dop853_and_lab02():
    w = np.array([1.2, 0.7, 0.9])
    t = np.linspace(0.0, 4.0, 41)
    q = R.constant_omega(Q0, w, t)
    sol = solve_ivp(lambda _t, y: K.quat_derivative_world(y, w), (0.0, 4.0), Q0, method="DOP853",
                    rtol=1e-13, atol=1e-13, t_eval=t)
    assert np.max(R.attitude_error(q, sol.y.T)) <= 1e-11
    # lab 02: from the identity, q(T) = axis_angle_to_quat(ω/|ω|, |ω| T) at T = 4 s
    qT = R.constant_omega([0, 0, 0, 1.0], w, 4.0)
    expect = K.axis_angle_to_quat(w / np.linalg.norm(w), np.linalg.norm(w) * 4.0)
    assert qT.shape == (4,) and np.max(np.abs(qT - expect)) <= 1e-15
    assert R.attitude_error(R.constant_omega(Q0, np.zeros(3), 3.0), Q0) <= 2.3e-16
    # and the body form of the same motion, torque-free with a sphere
    ref = R.torque_free((2.0, 2.0, 2.0), K.world_to_body(Q0, w), Q0, t)
    assert np.max(R.attitude_error(ref.q, q)) <= 1e-14


def test_attitude_error():
    rng = np.random.default_rng(7)
    q = K.quat_normalize(rng.normal(size=(50, 4)))
    # q ≡ −q: zero up to the rounding of the product q_a* ⊗ q_b (bitwise 0 is not promised)
    assert np.max(R.attitude_error(q, -q)) <= 2.3e-16 and np.max(R.attitude_error(q, q)) <= 2.3e-16
    assert R.attitude_error([0.0, 0.0, 0.0, 1.0], [0.0, 0.0, 0.0, -1.0]) == 0.0
    axis = K.quat_normalize(np.append(rng.normal(size=3), 0.0))[:3]
    ident = np.array([0.0, 0.0, 0.0, 1.0])
    for ang in (1e-15, 3e-12, 1e-8, 1e-4, 0.5, 3.0):
        got = R.attitude_error(ident, K.axis_angle_to_quat(axis, ang))
        assert abs(got - ang) <= 1e-15 * ang
        assert abs(R.attitude_error(-K.axis_angle_to_quat(axis, ang), ident) - ang) <= 1e-15 * ang
    # about any base orientation: exact to rounding in the composed quaternion (a few 1e-16 rad)
    d = K.axis_angle_to_quat(np.broadcast_to(axis, (50, 3)), 1e-9)
    assert np.max(np.abs(R.attitude_error(q, K.quat_mul(q, d)) - 1e-9)) <= 1e-15
    assert abs(R.attitude_error(ident, [0.0, 0.0, 1.0, 0.0]) - math.pi) <= 1e-15
    assert abs(R.attitude_error(ident, 2.5 * K.axis_angle_to_quat(axis, 0.3)) - 0.3) <= 1e-15


def test_relative_drift():
    assert R.relative_drift([2.0, 2.0, 2.0 + 2e-12, 2.0 - 4e-12]) == pytest.approx(2e-12, rel=1e-3)
    assert R.relative_drift(np.array([[3.0, 4.0, 0.0], [3.0, 4.0, 5e-10]])) == pytest.approx(1e-10)
    assert R.relative_drift([0.0, 1e-9]) == pytest.approx(1e-9)


def test_dop853_user_rhs_and_state():
    """A user right-hand side (constant body torque about a principal axis) and a full x0."""
    I = np.array([1.0, 2.0, 3.0])
    tau = 0.3

    def rhs(_t, x):
        xd = K.rigid_body_rhs_free(x, I)
        xd[12] += tau / I[2]
        return xd

    x0 = np.zeros(13)
    x0[0:3], x0[6], x0[7:10], x0[12] = (1.0, 2.0, 3.0), 1.0, (0.5, 0.0, -1.0), 0.2
    t = np.array([0.0, 1.0, 2.0])
    out = R.dop853(I, None, None, t, rhs=rhs, x0=x0)
    assert np.allclose(out.x[:, 12], 0.2 + tau / I[2] * t, atol=1e-13)
    assert np.allclose(out.x[:, 0:3], x0[0:3] + np.outer(t, x0[7:10]), atol=1e-12)
    angle = 0.2 * t + 0.5 * tau / I[2] * t**2
    assert np.max(R.attitude_error(out.q, K.axis_angle_to_quat(np.broadcast_to([0, 0, 1.0], (3, 3)), angle))) <= 1e-12
    assert np.allclose(np.linalg.norm(out.q, axis=1), 1.0, atol=1e-15) and out.nfev > 0
