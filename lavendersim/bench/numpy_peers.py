"""Hand-written peers of the NumPy backend for ``lavendersim bench`` (issue 30): what a good NumPy programmer writes
for the classic RK4 on N rigid bodies, and a pure-Python loop on floats for one body.

Both step the same model as ``Sim(..., integrator="rk4", backend="numpy")`` (q normalized after every step), with
no effects or with a uniform gravity g_w, a linear drag -c_lin v_w and an angular drag -c_ang ω_w (each body the
same). They are peers, not oracles: written for speed, in the way the physics is usually typed by hand (the
body-frame drag torque as -c_ang ω_b; the backend rotates it into the world and back, equal for a unit q), so
they agree with the backend to the integrator's truncation error, not to the bit.

* :func:`hand_rk4_soa` — struct-of-arrays (13, N) state, the inertia coefficients once per run, only q and ω
  (and, with drag, v) through the stages, p and v advanced in closed form where the stages do not need them.
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

    Parameters
    ----------
    X : ndarray (13, N)
        States, one row per number: p_w (m), q (x, y, z, w), v_w (m/s), omega_b (rad/s) (:func:`soa_state`).
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
    if c_ang:
        d0, d1, d2 = -c_ang * r0, -c_ang * r1, -c_ang * r2
    forced = g_w is not None or c_lin
    if forced:
        g = np.zeros(3) if g_w is None else np.asarray(g_w, dtype=np.float64)
        dv = -c_lin / np.asarray(m, dtype=np.float64) if c_lin else 0.0
    p, q, v, w = X[0:3], X[3:7], X[7:10], X[10:13]
    h2, h6 = 0.5 * dt, dt / 6.0

    def f(q, w):
        qx, qy, qz, qw = q
        wx, wy, wz = w
        hx, hy, hz = 0.5 * wx, 0.5 * wy, 0.5 * wz
        dq = np.array((hx * qw - hy * qz + hz * qy, hx * qz + hy * qw - hz * qx,
                       -hx * qy + hy * qx + hz * qw, -hx * qx - hy * qy - hz * qz))
        dw = np.array((k0 * wy * wz, k1 * wx * wz, k2 * wx * wy))
        if c_ang:
            dw[0] += d0 * wx
            dw[1] += d1 * wy
            dw[2] += d2 * wz
        return dq, dw

    for _ in range(n_steps):
        a_q, a_w = f(q, w)
        b_q, b_w = f(q + h2 * a_q, w + h2 * a_w)
        c_q, c_w = f(q + h2 * b_q, w + h2 * b_w)
        d_q, d_w = f(q + dt * c_q, w + dt * c_w)
        if forced:      # v' = g + dv v (linear, decoupled): RK4's stages in closed form
            a_v = g[:, None] + dv * v
            b_v = g[:, None] + dv * (v + h2 * a_v)
            c_v = g[:, None] + dv * (v + h2 * b_v)
            d_v = g[:, None] + dv * (v + dt * c_v)
            p += h6 * (v + 2.0 * (v + h2 * a_v) + 2.0 * (v + h2 * b_v) + (v + dt * c_v))
            v += h6 * (a_v + 2.0 * b_v + 2.0 * c_v + d_v)
        else:
            p += dt * v
        q += h6 * (a_q + 2.0 * b_q + 2.0 * c_q + d_q)
        w += h6 * (a_w + 2.0 * b_w + 2.0 * c_w + d_w)
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
