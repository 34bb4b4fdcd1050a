"""The oracle: LavenderSim's deliberately independent accuracy references, in one place (labs, tests and
benchmarks all measure against this module).

Independent on purpose: nothing here is derived in derive/ or stepped by a backend. The exact solutions are
written from the textbook (Landau & Lifshitz) with SciPy's special functions, and `dop853` is SciPy's
integrator, not one of ours; this module imports no backend, no Sim and no integrator table. It uses the
printed kernels only for bookkeeping it does not test (quaternion products and conversions, the energy and
momentum of the initial state, the right-hand side `dop853` integrates by default), so that an error in the
simulator's equations or integrators cannot hide by being repeated here. Do not "simplify" it into the runtime.

* `constant_omega` — the closed-form attitude under a constant world angular velocity,
  q(t) = exp(t[ω_w]×) q0.
* `torque_free` — the exact torque-free motion of a rigid body with principal inertia I_b
  (Landau & Lifshitz, Mechanics §37): body ω(t) from Jacobi's elliptic functions (both polhode
  families, the separatrix with sech/tanh, the symmetric top with sin/cos, the sphere and the
  permanent rotations), and the attitude from the constant world angular momentum plus the angle
  about it, integrated by composite Gauss–Legendre quadrature over one period of its rate.
* `dop853` — scipy's DOP853 at rtol = atol = 1e-13 on the 13-number rigid-body state, with the
  generated `rigid_body_rhs_free` kernel or any user right-hand side.
* `attitude_error`, `relative_drift`, `torque_free_period` — the measures everyone reports.

Conventions are the package's: quaternions (x, y, z, w), scalar last, q = R_WB; ω_b in the body
frame; state x = [p_w(3), q(4), v_w(3), omega_b(3)]. Times are seconds from the initial state
(t = 0); `torque_free` and `constant_omega` accept any real times, `dop853` integrates forward and
backward from 0 as needed.

Accuracy of `torque_free` (measured in tests/test_reference.py against DOP853 and against
scipy.integrate.quad for the angle): ω to a few 1e-15 relative to |ω|, attitude to ~1e-13 rad over
tens of seconds. scipy's `ellipj` loses accuracy near m → 1 for arguments beyond K/2, so the
argument is reduced to [0, K/2] with the quarter-period identities before calling it.
"""
from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import ArrayLike
from scipy.integrate import solve_ivp
from scipy.special import elliprf, ellipk, ellipkm1

from .generated import kernels_numpy as K
from .generated import layout as LY

__all__ = ["constant_omega", "torque_free", "torque_free_period", "dop853", "attitude_error",
           "relative_drift", "TorqueFreeMotion", "Integrated"]

_GL_X, _GL_W = np.polynomial.legendre.leggauss(16)


# --------------------------------------------------------------------------- small helpers

def _as_times(t) -> tuple[np.ndarray, bool]:
    t = np.asarray(t, dtype=float)
    scalar = t.ndim == 0
    t = np.atleast_1d(t)
    if t.ndim != 1 or not np.all(np.isfinite(t)):
        raise ValueError("t must be a finite scalar or 1-D array of times, s")
    return t, scalar


def _unit_q(q0) -> np.ndarray:
    q0 = np.asarray(q0, dtype=float)
    if q0.shape != (4,) or not np.all(np.isfinite(q0)) or np.linalg.norm(q0) == 0:
        raise ValueError("q0 must be a finite non-zero quaternion (x, y, z, w)")
    return q0 / np.linalg.norm(q0)


def _vec3(name, v) -> np.ndarray:
    v = np.asarray(v, dtype=float)
    if v.shape != (3,) or not np.all(np.isfinite(v)):
        raise ValueError(f"{name} must be 3 finite numbers")
    return v


def _inertia(I_b) -> np.ndarray:
    I_b = _vec3("I_b", I_b)
    if np.any(I_b <= 0):
        raise ValueError("I_b must be positive principal moments, kg·m²")
    return I_b


def _continuous(q: np.ndarray, q_first: np.ndarray) -> np.ndarray:
    """Choose each sample's sign (q ≡ −q) so the series is continuous in sample order."""
    q = q.copy()
    prev = q_first
    for i in range(len(q)):
        if np.dot(q[i], prev) < 0:
            q[i] = -q[i]
        prev = q[i]
    return q


# --------------------------------------------------------------------------- measures

def attitude_error(q_a: ArrayLike, q_b: ArrayLike) -> np.ndarray:
    """Rotation angle (rad, in [0, π]) between orientations q_a and q_b, vectorized; q ≡ −q.

    2·atan2(|vec(q_a* ⊗ q_b)|, |w(q_a* ⊗ q_b)|): exact to rounding for tiny angles (no arccos of a
    number near 1) and independent of the inputs' norms.

    Parameters
    ----------
    q_a, q_b : array_like, shape (..., 4)
        Quaternions (x, y, z, w), broadcast against each other; need not be unit.

    Returns
    -------
    ndarray, shape (...)
        Angles, rad.

    Examples
    --------
    >>> import numpy as np
    >>> from lavendersim.oracle import attitude_error
    >>> float(attitude_error([0, 0, 0, 1], [0, 0, np.sin(0.05), np.cos(0.05)]))   # 0.1 rad about z
    0.1
    """
    return K.quat_error_angle(np.asarray(q_b, float), np.asarray(q_a, float))    # the generated kernel (derive)


def relative_drift(series: ArrayLike) -> float:
    """max_t |x(t) − x(0)| / |x(0)| of a scalar series (T,) or a vector series (T, k) (Euclidean
    norm), e.g. energy or world angular momentum. If x(0) = 0 the absolute drift is returned.

    Parameters
    ----------
    series : array_like, shape (T,) or (T, k)

    Returns
    -------
    float
    """
    x = np.asarray(series, dtype=float)
    if x.ndim == 1:
        x = x[:, None]
    ref = np.linalg.norm(x[0])
    dev = np.max(np.linalg.norm(x - x[0], axis=-1))
    return float(dev / ref) if ref > 0 else float(dev)


# --------------------------------------------------------------------------- constant ω

def constant_omega(q0: ArrayLike, omega_w: ArrayLike, t: ArrayLike) -> np.ndarray:
    """Exact attitude under a constant world angular velocity: q(t) = exp(t[ω_w]×) q0, i.e.
    axis_angle_to_quat(ω̂, |ω| t) ⊗ q0.

    Parameters
    ----------
    q0 : array_like, shape (4,)
        Initial orientation R_WB (x, y, z, w).
    omega_w : array_like, shape (3,)
        Angular velocity, world frame, rad/s.
    t : float or array_like, shape (T,)
        Times, s.

    Returns
    -------
    ndarray, shape (T, 4) or (4,)
        (T, 4) for an array t, (4,) for a scalar.
    """
    t, scalar = _as_times(t)
    q0 = _unit_q(q0)
    w = _vec3("omega_w", omega_w)
    speed = np.linalg.norm(w)
    if speed == 0:
        q = np.broadcast_to(q0, (len(t), 4)).copy()
    else:
        rot = K.axis_angle_to_quat(np.broadcast_to(w / speed, (len(t), 3)), speed * t)
        q = K.quat_mul(rot, q0)
    return q[0] if scalar else q


# --------------------------------------------------------------------------- Jacobi functions

def _ellipj_agm(u, m: float, m1: float):
    """sn, cn, dn(u | m) for m = 1 − m1 given by m1 (so m near 1 keeps its full precision), by the
    arithmetic–geometric mean and the descending recursion of Abramowitz & Stegun 16.4 (the
    algorithm of scipy's ellipj, which takes m and so rounds 1 − m1)."""
    a, b, c = [1.0], [math.sqrt(m1)], [math.sqrt(m)]
    while abs(c[-1]) > 1e-17 * a[-1] and len(a) < 40:
        a.append((a[-1] + b[-1]) / 2)
        b.append(math.sqrt(a[-2] * b[-1]))
        c.append((a[-2] - b[-2]) / 2)
    n = len(a) - 1
    phi = (2.0 ** n) * a[n] * np.asarray(u, dtype=float)
    for j in range(n, 0, -1):
        prev = phi
        phi = (phi + np.arcsin(c[j] / a[j] * np.sin(phi))) / 2
    sn, cn = np.sin(phi), np.cos(phi)
    dn = cn / np.cos(prev - phi) if n > 0 else np.ones_like(phi)
    return sn, cn, dn


def _sncndn(u, m: float, m1: float, Kq: float):
    """sn, cn, dn(u | m) with m1 = 1 − m and Kq = K(m): the argument is reduced with the
    quarter-period identities to [0, K/2] (scipy's ellipj loses accuracy beyond K/2 as m → 1 and
    fails beyond K for m > 1 − 1e-9), then evaluated by `_ellipj_agm` from m1."""
    u = np.asarray(u, dtype=float)
    r = np.mod(u, 4 * Kq)
    s1 = np.where(r >= 2 * Kq, -1.0, 1.0)          # u → u − 2K: sn, cn change sign
    r = np.where(r >= 2 * Kq, r - 2 * Kq, r)
    c1 = np.where(r > Kq, -1.0, 1.0)                # u → 2K − u: cn changes sign
    r = np.where(r > Kq, 2 * Kq - r, r)
    near = r > Kq / 2                               # u → K − v: sn = cd v, cn = k' sd v, dn = k' nd v
    v = np.where(near, Kq - r, r)
    sn, cn, dn = _ellipj_agm(v, m, m1)
    kp = math.sqrt(m1)
    sn_, cn_, dn_ = np.where(near, cn / dn, sn), np.where(near, kp * sn / dn, cn), np.where(near, kp / dn, dn)
    return s1 * sn_, s1 * c1 * cn_, dn_


def _ellipf_sc(s: float, c: float, m1: float, Kq: float) -> float:
    """F(φ | m) for the amplitude φ = atan2(s, c) ∈ (−π, π], m = 1 − m1, by Carlson's R_F with
    1 − m sin²φ formed as cos²φ + m1 sin²φ (no rounding of m near 1)."""
    h = math.hypot(s, c)
    s, c = s / h, c / h
    f = s * float(elliprf(c * c, c * c + m1 * s * s, 1.0))
    return f if c >= 0 else math.copysign(2 * Kq, s) - f


# --------------------------------------------------------------------------- torque-free motion

@dataclass
class TorqueFreeMotion:
    """The exact torque-free motion sampled at t.

    t (T,), omega_b (T, 3) rad/s, q (T, 4) (x, y, z, w) R_WB (sign made continuous in sample
    order); E (J, rotational kinetic energy) and L_w (world angular momentum) — the invariants;
    period: of ω_b(t) (4K(m)/λ asymmetric, 2π/|Ω| symmetric; inf at the separatrix and for
    constant ω); kind: "constant", "symmetric", "asymmetric" or "separatrix"; for the elliptic
    cases m (parameter, k²), lam (λ, 1/s), u0 (phase at t = 0) and Kq = K(m), with ω_b of the
    intermediate principal axis ∝ sn(λ t + u0).

    Parameters
    ----------
    t : ndarray, shape (T,)
        Sample times, s.
    omega_b : ndarray, shape (T, 3)
        Angular velocity, body frame, rad/s.
    q : ndarray, shape (T, 4)
        Orientation R_WB (x, y, z, w).
    period : float
        Period of omega_b(t), s.
    E : float
        Rotational kinetic energy, J.
    L_w : ndarray, shape (3,)
        World angular momentum, kg·m²/s.
    kind : {"constant", "symmetric", "asymmetric", "separatrix"}
    m, lam, u0, Kq : float, optional
        Elliptic parameter k², rate λ (1/s), phase at t = 0, K(m).
    intermediate_axis : int, optional
        Index of the intermediate principal axis (-1 if none).
    details : dict, optional
        Further numbers of the solution.
    """
    t: np.ndarray
    omega_b: np.ndarray
    q: np.ndarray
    period: float
    E: float
    L_w: np.ndarray
    kind: str
    m: float = float("nan")
    lam: float = float("nan")
    u0: float = float("nan")
    Kq: float = float("nan")
    intermediate_axis: int = -1
    details: dict = field(default_factory=dict)

    def intermediate_zero_crossings(self, t_end: float, t_start: float = 0.0) -> np.ndarray:
        """Times in [t_start, t_end] at which ω_b of the intermediate axis changes sign (the
        Dzhanibekov flips of a polhode circling the major or minor axis): λt + u0 = 2K·j, spaced
        by half the period. Asymmetric bodies only (one crossing at the separatrix).

        Parameters
        ----------
        t_end : float
            End of the window, s.
        t_start : float, optional
            Start of the window, s.

        Returns
        -------
        ndarray
            Crossing times, s.
        """
        if self.kind == "separatrix":
            tc = np.array([-self.u0 / self.lam])
        elif self.kind == "asymmetric":
            j = np.arange(math.ceil((self.lam * t_start + self.u0) / (2 * self.Kq)),
                          math.floor((self.lam * t_end + self.u0) / (2 * self.Kq)) + 1)
            tc = (2 * self.Kq * j - self.u0) / self.lam
        else:
            raise ValueError(f"no intermediate-axis flips for a {self.kind} motion")
        return tc[(tc >= t_start) & (tc <= t_end)]


class _Solution:
    """ω_b(t) of a torque-free body in the original body axes, with the pieces the attitude needs."""

    def __init__(self, I_b: np.ndarray, w0: np.ndarray):
        self.I, self.w0 = I_b, w0
        self.L = float(np.linalg.norm(I_b * w0))
        self.E = float(K.kinetic_energy(1.0, I_b, np.zeros(3), w0))
        self.m = self.lam = self.u0 = self.Kq = float("nan")
        self.mid = -1
        Iw = I_b * w0
        if np.count_nonzero(w0) <= 1 or np.all(np.cross(Iw, w0) == 0) or (I_b[0] == I_b[1] == I_b[2]):
            self.kind, self.period = "constant", math.inf      # permanent rotation: ω_b constant
            self.amp = np.abs(w0)
            return
        eq = [I_b[(i + 1) % 3] == I_b[(i + 2) % 3] for i in range(3)]
        if any(eq):
            self._symmetric(eq.index(True))
        else:
            self._asymmetric()

    # --- symmetric top: ω_s constant, (ω_j + i ω_k) = z0 e^{iΩt}, (s, j, k) cyclic
    def _symmetric(self, s: int):
        I, w0 = self.I, self.w0
        j, k = (s + 1) % 3, (s + 2) % 3
        self.kind = "symmetric"
        self.s, self.j, self.k = s, j, k
        self.Omega = (I[s] - I[j]) * w0[s] / I[j]
        self.z0 = complex(w0[j], w0[k])
        self.period = 2 * math.pi / abs(self.Omega)
        self.amp = np.empty(3)
        self.amp[s], self.amp[j], self.amp[k] = abs(w0[s]), abs(self.z0), abs(self.z0)

    def _asymmetric(self):
        I, w0 = self.I, self.w0
        perm = np.argsort(I, kind="stable")          # sorted axis n is original axis perm[n]
        Pm = np.zeros((3, 3))
        Pm[np.arange(3), perm] = 1.0
        S = np.diag([1.0, 1.0, np.linalg.det(Pm)])   # odd permutation: flip one axis, stay right-handed
        self.Rs = S @ Pm                              # ω_sorted = Rs ω
        I1, I2, I3 = I[perm]
        w1, w2, w3 = self.Rs @ w0
        self.mid = int(perm[1])
        # L² − 2E I_n, each as a sum without cancellation
        d2 = I1 * (I1 - I2) * w1 ** 2 + I3 * (I3 - I2) * w3 ** 2      # L² − 2E I2 (either sign)
        d1 = I2 * (I2 - I1) * w2 ** 2 + I3 * (I3 - I1) * w3 ** 2      # L² − 2E I1 > 0
        d3 = I1 * (I3 - I1) * w1 ** 2 + I2 * (I3 - I2) * w2 ** 2      # 2E I3 − L² > 0
        self.d2 = d2
        if d2 >= 0:     # polhode circles the major axis 3 (or the separatrix): ω1 ∝ cn, ω2 ∝ sn, ω3 ∝ dn
            a, c = 0, 2
            A = np.array([math.sqrt(d3 / (I1 * (I3 - I1))), math.sqrt(d3 / (I2 * (I3 - I2))),
                          math.sqrt(d1 / (I3 * (I3 - I1)))])
            lam = math.sqrt((I3 - I2) * d1 / (I1 * I2 * I3))
            m = (I2 - I1) * d3 / ((I3 - I2) * d1)
            m1 = (I3 - I1) * d2 / ((I3 - I2) * d1)
        else:           # polhode circles the minor axis 1: ω3 ∝ cn, ω2 ∝ sn, ω1 ∝ dn
            a, c = 2, 0
            A = np.array([math.sqrt(d3 / (I1 * (I3 - I1))), math.sqrt(d1 / (I2 * (I2 - I1))),
                          math.sqrt(d1 / (I3 * (I3 - I1)))])
            lam = math.sqrt((I2 - I1) * d3 / (I1 * I2 * I3))
            m = (I3 - I2) * d1 / ((I2 - I1) * d3)
            m1 = (I3 - I1) * (-d2) / ((I2 - I1) * d3)
        ws = np.array([w1, w2, w3])
        self.a, self.c, self.A, self.lam = a, c, A, lam
        self.amp = np.abs(self.Rs.T @ A)
        if d2 == 0:     # separatrix: cn, dn → sech, sn → tanh; ω_a, ω_c keep their signs
            self.kind, self.period, self.m = "separatrix", math.inf, 1.0
            self.sa, self.sc = math.copysign(1.0, ws[a]), math.copysign(1.0, ws[c])
            self.sb = self.sa * self.sc
            self.u0 = math.asinh(self.sb * ws[1] * A[a] / (A[1] * abs(ws[a])))
            return
        # m and m1 = 1 − m, each from its own formula and so each to full relative precision
        # (rounding 1 − m would cost a relative 1e-16/m1 in m1 and a drift of the period near
        # the separatrix); K from the smaller of the two
        self.kind, self.m, self.m1 = "asymmetric", m, m1
        self.Kq = float(ellipkm1(m1)) if m1 < 0.5 else float(ellipk(m))
        self.period = 4 * self.Kq / lam
        # signs: dn > 0 so ω_c keeps its sign; Euler's equations need s_a s_b s_c = +1
        self.sa, self.sc = 1.0, math.copysign(1.0, ws[c])
        self.sb = self.sc
        # am(u0) = atan2(sn u0, cn u0)
        self.u0 = _ellipf_sc(self.sb * ws[1] / A[1], ws[a] / A[a], m1, self.Kq)

    # ω in the original body axes at times t (N,) → (N, 3)
    def omega(self, t: np.ndarray) -> np.ndarray:
        t = np.asarray(t, dtype=float)
        if self.kind == "constant":
            return np.broadcast_to(self.w0, t.shape + (3,)).copy()
        if self.kind == "symmetric":
            z = self.z0 * np.exp(1j * self.Omega * t)
            out = np.empty(t.shape + (3,))
            out[..., self.s], out[..., self.j], out[..., self.k] = self.w0[self.s], z.real, z.imag
            return out
        u = self.lam * t + self.u0
        if self.kind == "separatrix":
            sech = 1.0 / np.cosh(u)
            sn, cn, dn = np.tanh(u), sech, sech
        else:
            sn, cn, dn = _sncndn(u, self.m, self.m1, self.Kq)
        ws = np.empty(t.shape + (3,))
        ws[..., self.a] = self.sa * self.A[self.a] * cn
        ws[..., 1] = self.sb * self.A[1] * sn
        ws[..., self.c] = self.sc * self.A[self.c] * dn
        return ws @ self.Rs                      # ω = Rsᵀ ω_sorted, row-wise


def _gl_cumulative(f, span: float, h: float):
    """Antiderivative F(r) = ∫_0^r f for r in [0, span], by 16-point Gauss–Legendre panels of
    width ≤ h: panel sums accumulated exactly, the last partial panel integrated on its own."""
    n = max(1, math.ceil(span / h))
    edges = np.linspace(0.0, span, n + 1)
    lo, hw = edges[:-1], np.diff(edges) / 2
    nodes = (lo + hw)[:, None] + hw[:, None] * _GL_X[None, :]
    panel = hw * (f(nodes) @ _GL_W)
    cum = np.concatenate(([0.0], np.cumsum(panel)))

    def F(r):
        r = np.asarray(r, dtype=float)
        j = np.clip(np.searchsorted(edges, r, side="right") - 1, 0, n - 1)
        a = edges[j]
        half = (r - a) / 2
        x = (a + half)[:, None] + half[:, None] * _GL_X[None, :]
        return cum[j] + half * (f(x) @ _GL_W)

    return F, float(cum[-1])


def _precession_angle(sol: _Solution, axis: int, t: np.ndarray) -> np.ndarray:
    """φ(t) − φ(0): the angle about L of the line of nodes L × e_axis, whose rate is
    φ̇ = |L| Σ_{i≠axis} I_i ω_i² / Σ_{i≠axis} I_i² ω_i² (Landau §37, with `axis` as the Euler z)."""
    I, L = sol.I, sol.L
    others = [i for i in range(3) if i != axis]
    sin2 = 1.0 - (I[axis] * sol.amp[axis] / L) ** 2     # lower bound of sin²θ along the motion
    sharp = min(1.0, math.sqrt(max(sin2, 1e-300)))

    def rate_w(w):
        num = sum(I[i] * w[..., i] ** 2 for i in others)
        den = sum(I[i] ** 2 * w[..., i] ** 2 for i in others)
        return L * num / den

    if sol.kind == "constant":                           # not reached: constant ω uses the closed form
        raise AssertionError
    if sol.kind == "separatrix":
        # φ̇ = L/I_mid + g(u): g = L I_o (I_mid − I_o) ω_o² / (I_mid D) decays like sech²
        o = [i for i in others if i != sol.mid][0]
        Im = I[sol.mid]

        def g(u):
            w = sol.omega((u - sol.u0) / sol.lam)
            den = sum(I[i] ** 2 * w[..., i] ** 2 for i in others)
            return L * I[o] * (Im - I[o]) * w[..., o] ** 2 / (Im * den)

        U = 40.0
        G, _ = _gl_cumulative(g, U, 0.25 * sharp)

        def Godd(u):
            return np.sign(u) * G(np.minimum(np.abs(u), U))
        u = sol.lam * t + sol.u0
        return L / Im * t + (Godd(u) - Godd(np.array([sol.u0]))) / sol.lam
    # periodic rate: period of ω² (half the period of ω)
    P = sol.period / 2
    nu = 2 * math.pi / sol.period if sol.kind == "symmetric" else sol.lam
    F, Fp = _gl_cumulative(lambda s: rate_w(sol.omega(s)), P, min(P / 4, 0.5 * sharp / nu))
    k = np.floor(t / P)
    r = np.clip(t - k * P, 0.0, P)
    return k * Fp + F(r)


def _nodes_frame(l_b: np.ndarray, axis: int) -> np.ndarray:
    """Rotation (body → intermediate) with rows n, l × n, l; n = (l × e_axis)/|l × e_axis|."""
    e = np.zeros(3)
    e[axis] = 1.0
    n = np.cross(l_b, e)
    n /= np.linalg.norm(n, axis=-1, keepdims=True)
    return np.stack([n, np.cross(l_b, n), l_b], axis=-2)


def torque_free(I_b: ArrayLike, omega_b0: ArrayLike, q0: ArrayLike, t: ArrayLike) -> TorqueFreeMotion:
    """Exact torque-free motion of a body with principal moments I_b (any order, any equalities)
    from ω_b(0) = omega_b0 and q(0) = q0, sampled at times t (s, any reals).

    ω_b(t) from Jacobi's elliptic functions (Landau–Lifshitz §37) in the frame of sorted moments
    (an odd sorting permutation is made proper by flipping one axis), both polhode families, the
    separatrix L² = 2E I_2 (sech/tanh), symmetric bodies (sin/cos) and constant-ω motions.
    Attitude: R_WB(t) = R_WB(0) M(0)ᵀ R_z(φ(t)) M(t), where M(t) has rows n, l × n, l with l the
    body-frame unit momentum and n the line of nodes of an Euler axis chosen to stay well away
    from l; φ is the quadrature of Landau's φ̇ over one period of it, extended by periodicity.

    Parameters
    ----------
    I_b : array_like, shape (3,)
        Principal moments, kg·m².
    omega_b0 : array_like, shape (3,)
        Initial angular velocity, body frame, rad/s.
    q0 : array_like, shape (4,)
        Initial orientation R_WB (x, y, z, w).
    t : array_like, shape (T,)
        Sample times, s.

    Returns
    -------
    TorqueFreeMotion

    Examples
    --------
    >>> from lavendersim.oracle import torque_free
    >>> m = torque_free([1.0, 2.0, 3.0], [0.01, 1.0, 0.01], [0, 0, 0, 1], [0.0, 1.0])
    >>> m.kind, m.omega_b.shape
    ('asymmetric', (2, 3))
    """
    t, _ = _as_times(t)
    I_b = _inertia(I_b)
    w0 = _vec3("omega_b0", omega_b0)
    q0 = _unit_q(q0)
    sol = _Solution(I_b, w0)
    L_w = K.angular_momentum_world(q0, I_b, w0)
    if sol.kind == "constant":
        w = sol.omega(t)
        q = constant_omega(q0, K.quat_rotate(q0, w0), t)
        return TorqueFreeMotion(t, w, q, sol.period, sol.E, L_w, sol.kind)
    w = sol.omega(t)
    # Euler axis: the principal axis whose momentum share |l_i| stays smallest (never l ∥ e_axis);
    # never the intermediate axis at the separatrix (ω tends to it)
    share = I_b * sol.amp
    if sol.kind == "separatrix":
        share[sol.mid] = np.inf
    axis = int(np.argmin(share))
    phi = _precession_angle(sol, axis, t)
    M0 = _nodes_frame(I_b * w0 / sol.L, axis)
    Mt = _nodes_frame(I_b * w / sol.L, axis)
    q_fix = K.quat_mul(q0, K.quat_conj(K.matrix_to_quat(M0)))
    qz = K.axis_angle_to_quat(np.broadcast_to([0.0, 0.0, 1.0], (len(t), 3)), phi)
    q = K.quat_mul(K.quat_mul(q_fix, qz), K.matrix_to_quat(Mt))
    q = _continuous(q / np.linalg.norm(q, axis=-1, keepdims=True), q0)
    return TorqueFreeMotion(t, w, q, sol.period, sol.E, L_w, sol.kind, m=sol.m, lam=sol.lam,
                            u0=sol.u0, Kq=sol.Kq, intermediate_axis=sol.mid,
                            details={"euler_axis": axis})


def torque_free_period(I_b: ArrayLike, omega_b0: ArrayLike) -> float:
    """Period (s) of the body angular velocity of the torque-free motion: 4K(m)/λ for an
    asymmetric body, 2π/|Ω| (Ω = (I_s − I_t) ω_s / I_t) for a symmetric one; inf at the
    separatrix and when ω_b is constant (sphere, permanent rotation).

    Parameters
    ----------
    I_b : array_like, shape (3,)
        Principal moments, kg·m².
    omega_b0 : array_like, shape (3,)
        Initial angular velocity, body frame, rad/s.

    Returns
    -------
    float
        Period, s.
    """
    return _Solution(_inertia(I_b), _vec3("omega_b0", omega_b0)).period


# --------------------------------------------------------------------------- DOP853

@dataclass
class Integrated:
    """A DOP853 reference (returned by :func:`dop853`).

    Parameters
    ----------
    t : ndarray, shape (T,)
        Times, s.
    x : ndarray, shape (T, 13)
        States ``[p_w, q, v_w, omega_b]`` (q normalized).
    nfev : int
        Right-hand-side evaluations.
    """
    t: np.ndarray
    x: np.ndarray
    nfev: int

    @property
    def q(self) -> np.ndarray:
        """Orientations R_WB (x, y, z, w), shape (T, 4)."""
        return self.x[:, LY.STATE_Q]

    @property
    def omega_b(self) -> np.ndarray:
        """Angular velocities, body frame, rad/s, shape (T, 3)."""
        return self.x[:, LY.STATE_OMEGA_B]


def dop853(I_b: ArrayLike, omega_b0: ArrayLike, q0: ArrayLike, t: ArrayLike,
           rhs: Callable[[float, np.ndarray], ArrayLike] | None = None, rtol: float = 1e-13, atol: float = 1e-13,
           x0: ArrayLike | None = None) -> Integrated:
    """solve_ivp(DOP853) reference on the 13-number state from t = 0, with dense output at t (s,
    any reals: negative times are integrated backward). rhs(t, x) → ẋ (13,) defaults to the
    generated torque-free kernel rigid_body_rhs_free(x, I_b); x0 (13,) overrides the initial
    state built from q0, omega_b0 (p_w = v_w = 0). The quaternion is normalized at output.

    Parameters
    ----------
    I_b : array_like, shape (3,)
        Principal moments, kg·m².
    omega_b0 : array_like, shape (3,)
        Initial angular velocity, body frame, rad/s.
    q0 : array_like, shape (4,)
        Initial orientation R_WB (x, y, z, w).
    t : array_like, shape (T,)
        Output times, s.
    rhs : callable, optional
        ``rhs(t, x) -> xdot`` (13,).
    rtol, atol : float, optional
        solve_ivp tolerances.
    x0 : array_like, shape (13,), optional
        Full initial state.

    Returns
    -------
    Integrated
    """
    t, _ = _as_times(t)
    I_b = _inertia(I_b)
    if x0 is None:
        x0 = np.zeros(LY.STATE_SIZE)
        x0[LY.STATE_Q] = _unit_q(q0)
        x0[LY.STATE_OMEGA_B] = _vec3("omega_b0", omega_b0)
    else:
        x0 = np.asarray(x0, dtype=float).copy()
        if x0.shape != (LY.STATE_SIZE,) or not np.all(np.isfinite(x0)):
            raise ValueError(f"x0 must be {LY.STATE_SIZE} finite numbers")
    if rhs is None:
        def rhs(_t, x):
            return K.rigid_body_rhs_free(x, I_b)
    out = np.empty((len(t), LY.STATE_SIZE))
    nfev = 0
    for sel, pick in ((t >= 0, np.max), (t < 0, np.min)):        # forward, then backward from 0
        if not np.any(sel):
            continue
        end = float(pick(t[sel]))
        if end == 0.0:
            out[sel] = x0
            continue
        r = solve_ivp(rhs, (0.0, end), x0, method="DOP853", rtol=rtol, atol=atol, dense_output=True)
        if not r.success:
            raise RuntimeError(f"DOP853 reference failed: {r.message}")
        nfev += r.nfev
        out[sel] = r.sol(t[sel]).T
    out[:, LY.STATE_Q] /= np.linalg.norm(out[:, LY.STATE_Q], axis=1, keepdims=True)
    return Integrated(t, out, nfev)
