"""Hand-written peers of the NumPy backend for ``lavendersim bench`` (issue 30): what a good NumPy programmer writes
for the classic RK4 on N rigid bodies, and a pure-Python loop on floats for one body.

Both step the same model as ``Sim(..., integrator="rk4", backend="numpy")`` (q normalized after every step), with
no effects or with a uniform gravity g_w, a linear drag -c_lin v_w and an angular drag -c_ang ω_w (each body the
same). They are peers, not oracles: written for speed, in the way the physics is usually typed by hand (the
body-frame drag torque as -c_ang ω_b; the backend rotates it into the world and back, equal for a unit q), so
they agree with the backend to the integrator's truncation error, not to the bit.

* :func:`hand_rk4_soa` — struct-of-arrays (13, N) state, the inertia coefficients once per run, only q and ω
  (and, with effects, v) through the stages, in preallocated buffers (ufuncs with out=, in-place sums; no rows
  stacked into new arrays), p from v without a right-hand side of its own.
* :func:`python_rk4` — one body, plain Python floats (lists and tuples), the same RK4.
* :func:`soa_state` and :func:`python_state` turn the backend's (N, 13) rows into each peer's layout.
"""
from __future__ import annotations

import math

import numpy as np

from ..generated import layout as LY


def soa_state(x: np.ndarray) -> np.ndarray:
    """(13, N) C-contiguous copy of states x (N, 13) (layout generated/layout.py): one contiguous row per number."""
    return np.array(np.asarray(x, dtype=np.float64).T, order="C")     # a copy (for N = 1, x.T is contiguous already)


def python_state(x: np.ndarray) -> list[float]:
    """One body's state (13,) as a list of Python floats."""
    return [float(v) for v in np.asarray(x, dtype=np.float64).reshape(-1)[:LY.STATE_SIZE]]


def _coefficients(I_b):
    """Euler's coefficients k = ((I_y - I_z)/I_x, ...) and 1/I (each (N,) or a float), once per run."""
    I0, I1, I2 = I_b
    return (I1 - I2) / I0, (I2 - I0) / I1, (I0 - I1) / I2, 1.0 / I0, 1.0 / I1, 1.0 / I2


def hand_rk4_soa(X: np.ndarray, I_b: np.ndarray, dt: float, n_steps: int, m=None, g_w=None, c_lin: float = 0.0,
                 c_ang: float = 0.0) -> None:
    """Classic RK4 on N bodies in struct-of-arrays layout, q normalized after each step; X updated in place.

    The stages go through preallocated (k, N) buffers (ufuncs with out=, no stacking of rows): torque-free, only
    (q, omega) (7 rows) and p += dt v; with effects, the contiguous rows (q, v_w, omega) of X (10 rows), p from
    the stages' v.

    Parameters
    ----------
    X : ndarray (13, N)
        States, C-contiguous, one row per number: p_w (m), q (x, y, z, w), v_w (m/s), omega_b (rad/s)
        (:func:`soa_state`).
    I_b : ndarray (3, N)
        Principal moments, body frame, kg·m².
    dt : float
        Step, s.
    n_steps : int
    m : ndarray (N,), optional
        Masses, kg (read only with c_lin).
    g_w : (3,) float, optional
        Uniform gravity, world frame, m/s².
    c_lin : float
        Linear drag coefficient, N·s/m (force -c_lin v_w).
    c_ang : float
        Angular drag coefficient, N·m·s/rad (torque -c_ang omega_w, i.e. -c_ang omega_b in the body frame).
    """
    k0, k1, k2, r0, r1, r2 = _coefficients(I_b)
    d = (-c_ang * r0, -c_ang * r1, -c_ang * r2) if c_ang else None
    forced = g_w is not None or bool(c_lin)
    g = (np.zeros(3) if g_w is None else np.asarray(g_w, dtype=np.float64))[:, None]
    dv = -c_lin / np.asarray(m, dtype=np.float64) if c_lin else None
    n = X.shape[1]
    p, q = X[0:3], X[3:7]
    rows = 10 if forced else 7                 # (q, v, omega) of X, or (q, omega) gathered
    y = X[3:13] if forced else np.empty((7, n))
    iw = 7 if forced else 4                    # omega's first row in y
    ks = [np.empty((rows, n)) for _ in range(4)]
    ys = [np.empty((rows, n)) for _ in range(3)]
    s = np.empty((rows, n))
    h2, h6 = 0.5 * dt, dt / 6.0

    def f(y, k):
        qx, qy, qz, qw = y[0:4]
        wx, wy, wz = y[iw:iw + 3]
        hx, hy, hz = 0.5 * wx, 0.5 * wy, 0.5 * wz
        np.add(hx * qw - hy * qz, hz * qy, out=k[0])
        np.subtract(hx * qz + hy * qw, hz * qx, out=k[1])
        np.add(hy * qx - hx * qy, hz * qw, out=k[2])
        np.negative(hx * qx + hy * qy + hz * qz, out=k[3])
        if d is None:
            np.multiply(k0 * wy, wz, out=k[iw])
            np.multiply(k1 * wx, wz, out=k[iw + 1])
            np.multiply(k2 * wx, wy, out=k[iw + 2])
        else:
            np.add(k0 * wy * wz, d[0] * wx, out=k[iw])
            np.add(k1 * wx * wz, d[1] * wy, out=k[iw + 1])
            np.add(k2 * wx * wy, d[2] * wz, out=k[iw + 2])
        if forced:      # v' = g + dv v
            kv = k[4:7]
            if dv is None:
                kv[...] = g
            else:
                np.multiply(y[4:7], dv, out=kv)
                kv += g

    for _ in range(n_steps):
        if not forced:
            y[0:4], y[4:7] = q, X[10:13]
        f(y, ks[0])
        for i, a in ((1, h2), (2, h2), (3, dt)):
            np.multiply(ks[i - 1], a, out=ys[i - 1])
            ys[i - 1] += y
            f(ys[i - 1], ks[i])
        if forced:      # p' = v: the stages' v
            sp = s[0:3]
            np.add(ys[0][4:7], ys[1][4:7], out=sp)
            sp *= 2.0
            sp += y[4:7]
            sp += ys[2][4:7]
            sp *= h6
            p += sp
        else:
            p += dt * X[7:10]
        np.add(ks[1], ks[2], out=s)
        s *= 2.0
        s += ks[0]
        s += ks[3]
        s *= h6
        y += s
        if not forced:
            q[...], X[10:13] = y[0:4], y[4:7]
        q /= np.sqrt(q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3])


def python_rk4(x: list, I_b, dt: float, n_steps: int, m: float = 1.0, g_w=None, c_lin: float = 0.0,
               c_ang: float = 0.0) -> list:
    """Classic RK4 on one body in plain Python floats, q normalized after each step.

    Parameters
    ----------
    x : list of 13 float
        State: p_w (m), q (x, y, z, w), v_w (m/s), omega_b (rad/s) (:func:`python_state`).
    I_b : 3 floats
        Principal moments, body frame, kg·m².
    dt : float
        Step, s.
    n_steps : int
    m, g_w, c_lin, c_ang
        As :func:`hand_rk4_soa` (m a float, kg).

    Returns
    -------
    list of 13 float
        The state after n_steps.
    """
    k0, k1, k2, r0, r1, r2 = _coefficients([float(v) for v in I_b])
    gx, gy, gz = (0.0, 0.0, 0.0) if g_w is None else (float(g_w[0]), float(g_w[1]), float(g_w[2]))
    dv = -c_lin / m
    d0, d1, d2 = -c_ang * r0, -c_ang * r1, -c_ang * r2
    h2, h6 = 0.5 * dt, dt / 6.0
    px, py, pz, qx, qy, qz, qw, vx, vy, vz, wx, wy, wz = x

    def f(qx, qy, qz, qw, vx, vy, vz, wx, wy, wz):
        hx, hy, hz = 0.5 * wx, 0.5 * wy, 0.5 * wz
        return (vx, vy, vz,
                hx * qw - hy * qz + hz * qy, hx * qz + hy * qw - hz * qx, -hx * qy + hy * qx + hz * qw,
                -hx * qx - hy * qy - hz * qz,
                gx + dv * vx, gy + dv * vy, gz + dv * vz,
                k0 * wy * wz + d0 * wx, k1 * wx * wz + d1 * wy, k2 * wx * wy + d2 * wz)

    for _ in range(n_steps):
        y = (qx, qy, qz, qw, vx, vy, vz, wx, wy, wz)
        a = f(*y)
        b = f(*[yi + h2 * ai for yi, ai in zip(y, a[3:])])
        c = f(*[yi + h2 * bi for yi, bi in zip(y, b[3:])])
        d = f(*[yi + dt * ci for yi, ci in zip(y, c[3:])])
        px, py, pz, qx, qy, qz, qw, vx, vy, vz, wx, wy, wz = [
            xi + h6 * (ai + 2.0 * bi + 2.0 * ci + di)
            for xi, ai, bi, ci, di in zip((px, py, pz) + y, a, b, c, d)]
        s = 1.0 / math.sqrt(qx * qx + qy * qy + qz * qz + qw * qw)
        qx, qy, qz, qw = qx * s, qy * s, qz * s, qw * s
    return [px, py, pz, qx, qy, qz, qw, vx, vy, vz, wx, wy, wz]
