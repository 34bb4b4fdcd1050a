"""Tests-only reference for the reaction-wheel cube: RK4 on the chapter's body-axis wheel equations written
out here with NumPy (body_axis_wheels_rhs; + effect_gravity / effect_angular_damping), with the Sim's wheel API
(set_wheel_command, wheel_command_applied, wheel_rates, state, run, t). An independent stepper the runtime
Sim (the printed N-wheel model on A_b = [I | 0]) is compared against; not used by the package."""
from __future__ import annotations

from types import SimpleNamespace

import numpy as np

from lavendersim.kernels import K


def body_axis_wheels_rhs(q, w, Om, I_p, J, r_b, F_w, tau_w, u, c_w):
    """(q̇, ω̇, Ω̇) of a body with three wheels on its x, y, z axes about a pivot, written out independently of the
    printed kernels: τ_P = Rᵀτ_W + r_B × RᵀF_W, (I_P − J) ω̇ = τ_P − ω × (I_P ω + J Ω) − u + c_w Ω,
    Ω̇ = J⁻¹(u − c_w Ω) − ω̇ (np.linalg.solve, np.cross); q̇ from the quat_derivative_body kernel."""
    R = K.quat_to_matrix(q)
    tau_p = R.T @ tau_w + np.cross(r_b, R.T @ F_w)
    w_dot = np.linalg.solve(I_p - np.diag(J), tau_p - np.cross(w, I_p @ w + J * Om) - u + c_w * Om)
    return K.quat_derivative_body(q, w), w_dot, (u - c_w * Om) / J - w_dot


class RefSim:
    def __init__(self, model, q0, omega_b=(0, 0, 0), Omega=(0, 0, 0), dt=1e-3):
        self.m = model
        self.dt = dt
        self.q = np.asarray(q0, float).copy()
        self.w = np.asarray(omega_b, float).copy()
        self.Om = np.asarray(Omega, float).copy()
        self.cmd = np.zeros(3)
        self.applied = np.zeros(3)
        self.steps = 0

    @property
    def t(self):
        return self.steps * self.dt

    def _f(self, q, w, Om, u):
        m = self.m
        F = K.effect_gravity(m.mass, m.g_w) if m.gravity else np.zeros(3)
        tau = K.effect_angular_damping(q, w, m.damping)
        return body_axis_wheels_rhs(q, w, Om, m.I_p, m.J, m.r_b, F, tau, u, m.wheel_damping)

    def _saturate(self):
        u = np.clip(self.cmd, -self.m.torque_limit, self.m.torque_limit)
        if getattr(self.m, "motor", "cutoff") == "cutoff":
            return np.where((np.abs(self.Om) >= self.m.speed_limit) & (u * self.Om > 0), 0.0, u)
        # torque–speed line: driving the wheel faster, at most stall · (1 − |Ω| / no-load speed), never below 0
        avail = self.m.torque_limit * np.maximum(0.0, 1.0 - np.abs(self.Om) / self.m.speed_limit)
        drive = u * self.Om > 0
        return np.where(drive, np.sign(u) * np.minimum(np.abs(u), avail), u)

    def step(self):
        u = self._saturate()
        self.applied = u
        h = self.dt
        y = (self.q, self.w, self.Om)
        k1 = self._f(*y, u)
        k2 = self._f(*(a + h / 2 * b for a, b in zip(y, k1)), u)
        k3 = self._f(*(a + h / 2 * b for a, b in zip(y, k2)), u)
        k4 = self._f(*(a + h * b for a, b in zip(y, k3)), u)
        q, w, Om = (a + h / 6 * (b1 + 2 * b2 + 2 * b3 + b4) for a, b1, b2, b3, b4 in zip(y, k1, k2, k3, k4))
        self.q, self.w, self.Om = q / np.linalg.norm(q), w, Om
        self.steps += 1

    def run(self, n):
        for _ in range(n):
            self.step()

    def set_wheel_command(self, body, u):
        self.cmd = np.asarray(u, float).copy()

    def wheel_command_applied(self, body):
        return self.applied.copy()

    def wheel_rates(self, body):
        return self.Om.copy()

    def state(self, body):
        return SimpleNamespace(q=self.q.copy(), omega_b=self.w.copy(), Omega=self.Om.copy())
