"""Experiment 02: integrate a constant world angular velocity — Euler-angle addition vs quaternions.

Parameters (resolved from the chapter's figures): omega_w = [1.2, 0.7, 0.9] rad/s constant,
dt = 0.01 s, T = 4 s, start at the identity. Three integrations:
  * naive: add dt * omega to intrinsic XYZ Euler angles (R = Rx(a) Ry(b) Rz(c), euler_xyz_to_quat);
  * quaternion: integrate_orientation (explicit step q += dt 1/2 [omega_w, 0] ⊗ q, then normalize);
  * unnormalized: the same explicit step (quat_derivative_world) without normalizing.
Exact answer: R(T) = exp(T [omega_w]x), i.e. axis_angle_to_quat(omega/|omega|, |omega| T).
Errors are the rotation angle between the computed and exact orientations, in degrees
(q and -q are the same orientation; the unnormalized state is normalized before comparing).
Chapter figures: 87.6° (naive), 0.0087° (quaternion), |q| = 1.0138 (unnormalized).

Closed forms, printed alongside: each normalized explicit step turns by 2 atan(|w| dt / 2) about
the fixed axis instead of |w| dt, so the quaternion error is n (|w| dt - 2 atan(|w| dt / 2)); each
unnormalized step multiplies |q| by sqrt(1 + (|w| dt / 2)^2).

Paw-check 4: with body-frame angular velocity the product moves to the other side,
q_dot = 1/2 q ⊗ [omega_b, 0]; for a constant world omega, omega_b = R^T omega_w (world_to_body).
Started from a 90° rotation about y, that trajectory equals the world-form one to ~1e-12, and the
wrong order (1/2 [omega_b, 0] ⊗ q) diverges. From the identity start the wrong order happens to
agree, because then omega_b = omega_w and q stays a rotation about omega — which commutes with
[omega, 0]: a start at identity hides the bug, so the paw-check uses a rotated start.

Failure modes: --single-axis (omega = [|omega|, 0, 0]: Euler-angle addition is then exact and
the bug is hidden, while the quaternion figures stay the same because they depend only on
|omega|); --dt larger (the quaternion error grows, ~dt^2).
"""
from __future__ import annotations

import math

import numpy as np

from lavendersim import validate as V
from lavendersim.kernels import K
from lavendersim import figures as F

from . import common as C
from .diverged import failed_figure

NAME = "02"
TITLE = "Euler-angle addition vs quaternion integration of a constant world angular velocity (paw-check 4)"

OMEGA_W = (1.2, 0.7, 0.9)
DT = 0.01
T_END = 4.0
# chapter figures and their tolerances
NAIVE_DEG, NAIVE_TOL = 87.63, 0.05
QUAT_DEG, QUAT_TOL = 0.00866, 0.00005
NORM, NORM_TOL = 1.01379, 0.00005
PAW4_TOL = 1e-12
PAW4_Q0_AXIS, PAW4_Q0_ANGLE = (0.0, 1.0, 0.0), math.pi / 2


def _steps(dt: float) -> int:
    return C.steps("dt", T_END, dt)  # at most C.MAX_STEPS, a whole number of steps


def integrate(omega_w, dt: float, n: int, q0=(0.0, 0.0, 0.0, 1.0)):
    """All methods over n steps; returns dict of (n+1, 4) quaternion histories (and Euler angles)."""
    w = np.asarray(omega_w, float)
    q0 = np.asarray(q0, float)
    H = {k: np.empty((n + 1, 4)) for k in ("quaternion", "unnormalized", "naive", "body", "wrong_order")}
    for k in H:
        H[k][0] = q0
    angles = np.asarray(K.quat_to_euler_xyz(q0), float)
    for i in range(n):
        H["quaternion"][i + 1] = K.integrate_orientation(H["quaternion"][i], w, dt)
        qu = H["unnormalized"][i]
        H["unnormalized"][i + 1] = qu + dt * K.quat_derivative_world(qu, w)
        angles = angles + dt * w  # the deliberate mistake: omega treated as Euler-angle rates
        H["naive"][i + 1] = K.euler_xyz_to_quat(angles[0], angles[1], angles[2])
        # paw-check 4: body-frame omega with the body-form product, and with the wrong order
        qb = H["body"][i]
        wb = K.world_to_body(qb, w)
        H["body"][i + 1] = K.quat_normalize(qb + dt * K.quat_derivative_body(qb, wb))
        qx = H["wrong_order"][i]
        wbx = K.world_to_body(qx, w)
        H["wrong_order"][i + 1] = K.quat_normalize(qx + dt * K.quat_derivative_world(qx, wbx))
    return H


def exact(omega_w, t, q0=(0.0, 0.0, 0.0, 1.0)):
    """exp(t [omega]x) R0 as quaternions, shape (len(t), 4)."""
    w = np.asarray(omega_w, float)
    speed = float(np.linalg.norm(w))
    axis = w / speed
    q_rot = K.axis_angle_to_quat(np.broadcast_to(axis, (len(t), 3)), speed * np.asarray(t))
    return K.quat_mul(q_rot, np.broadcast_to(np.asarray(q0, float), (len(t), 4)))


def run(out_dir=C.DEFAULT_OUT, backend: str = "auto", **options) -> C.LabResult:
    """:func:`compute`, then write OUT/02/ (results.json, orientation.png)."""
    return compute(backend, **options).save(out_dir)


@failed_figure
def compute(backend: str = "auto", dt: float = DT, single_axis: bool = False) -> C.LabResult:
    """Run the lab and return its :class:`~lavendersim.labs.common.LabResult`; writes nothing."""
    C.check_backend(backend)  # validated only: this lab evaluates the generated NumPy kernels, no simulator
    dt = V.dt("dt", dt)
    C.flags(single_axis=single_axis)
    n = _steps(dt)
    speed = float(np.linalg.norm(OMEGA_W))
    w = np.array([speed, 0.0, 0.0]) if single_axis else np.array(OMEGA_W)
    f, data = _measure(w, dt, n)
    data["single_axis"] = single_axis
    params = {
        "backend": C.NO_SIMULATOR, "omega_w": w, "dt": dt, "T": T_END, "n_steps": n, "q0": np.array([0.0, 0.0, 0.0, 1.0]),
        "single_axis": bool(single_axis), "euler_convention": "intrinsic XYZ, R = Rx(roll) Ry(pitch) Rz(yaw)",
        "paw4_q0": PAW4_Q0,
    }
    if dt != DT:   # the failure mode's reference: the chapter's dt
        ref = integrate(w, DT, _steps(DT))
        f["quaternion_error_deg_at_dt_0.01"] = float(C.angle_between_deg(K, ref["quaternion"][-1:], exact(w, [T_END]))[0])
        f["quaternion_error_ratio_vs_dt_0.01"] = f["quaternion_error_deg"] / f["quaternion_error_deg_at_dt_0.01"]
    chapter_dt = dt == DT
    checks = C.checks(
        chapter_dt and not single_axis and ("naive_euler_error_deg", f["naive_euler_error_deg"], "≈",
                                            (NAIVE_DEG, NAIVE_TOL), "chapter 87.6°"),
        # the quaternion figures depend only on |omega| and dt, so they hold for --single-axis too
        chapter_dt and ("quaternion_error_deg", f["quaternion_error_deg"], "≈", (QUAT_DEG, QUAT_TOL), "chapter 0.0087°"),
        chapter_dt and ("unnormalized_norm", f["unnormalized_norm"], "≈", (NORM, NORM_TOL), "chapter 1.0138"),
        single_axis and ("single_axis_hides_euler_bug", f["naive_euler_error_deg"], "<=", 1e-9,
                         "failure mode: Euler-angle addition is exact for a single-axis rotation (deg)"),
        dt > DT and ("larger_dt_increases_quaternion_error", f["quaternion_error_ratio_vs_dt_0.01"], ">", 1.0,
                     f"failure mode: error at dt = {dt:g} s over error at dt = 0.01 s"),
        ("quaternion_error_matches_closed_form", f["quaternion_error_deg"], "≈",
         (f["quaternion_error_deg_closed_form"], 1e-9), "n (|w| dt - 2 atan(|w| dt / 2)), deg"),
        ("unnormalized_norm_matches_closed_form", f["unnormalized_norm"], "≈", (f["unnormalized_norm_closed_form"], 1e-12),
         "(1 + (|w| dt / 2)^2)^(n / 2)"),
        ("paw4_body_form_equals_world_form", f["paw4_body_vs_world_max_abs"], "<=", PAW4_TOL,
         "max |q_body - q_world| over the run, start 90° about y"),
        ("paw4_wrong_order_diverges", f["paw4_wrong_order_error_deg"], ">", 1.0,
         "body omega with the world-form order: error at T in degrees"),
    )
    return C.make_result(NAME, f, params, checks, {"orientation.png": _plot}, data,
                         headline=("naive_euler_error_deg", f"{NAIVE_DEG:g} ± {NAIVE_TOL:g}° (quaternion "
                                   f"{QUAT_DEG:g}°) at the chapter's dt"))


PAW4_Q0 = K.axis_angle_to_quat(np.array(PAW4_Q0_AXIS), PAW4_Q0_ANGLE)


def _measure(w, dt: float, n: int):
    """The figures of every method against exp(t [omega]x), from the identity and (paw-check 4) from PAW4_Q0."""
    t = np.arange(n + 1) * dt
    speed = float(np.linalg.norm(w))
    H, Q = integrate(w, dt, n), exact(w, t)
    H4, Q4 = integrate(w, dt, n, PAW4_Q0), exact(w, t, PAW4_Q0)
    err = {k: C.angle_between_deg(K, H[k], Q) for k in ("naive", "quaternion", "unnormalized", "wrong_order")}
    err4 = {k: C.angle_between_deg(K, H4[k], Q4) for k in ("body", "wrong_order", "quaternion")}
    norm_unnorm = np.linalg.norm(H["unnormalized"], axis=1)
    f = {
        "naive_euler_error_deg": float(err["naive"][-1]),
        "quaternion_error_deg": float(err["quaternion"][-1]),
        "quaternion_error_deg_closed_form": math.degrees(n * (speed * dt - 2 * math.atan(speed * dt / 2))),
        "unnormalized_norm": float(norm_unnorm[-1]),
        "unnormalized_norm_closed_form": (1 + (speed * dt / 2) ** 2) ** (n / 2),
        "unnormalized_error_deg": float(err["unnormalized"][-1]),
        "naive_euler_max_error_deg": float(np.max(err["naive"])),
        "paw4_body_vs_world_max_abs": float(np.max(np.abs(H4["body"] - H4["quaternion"]))),
        "paw4_body_form_error_deg": float(err4["body"][-1]),
        "paw4_wrong_order_error_deg": float(err4["wrong_order"][-1]),
        "paw4_identity_start_body_vs_world_max_abs": float(np.max(np.abs(H["body"] - H["quaternion"]))),
        "paw4_identity_start_wrong_order_error_deg": float(err["wrong_order"][-1]),
    }
    data = {"w": w, "dt": dt, "t": t, "err_naive": err["naive"], "err_quat": err["quaternion"],
            "err_unnorm": err["unnormalized"], "norm_unnorm": norm_unnorm, "norm_quat": np.linalg.norm(H["quaternion"], axis=1),
            "body_err": err4["body"], "world_err": err4["quaternion"], "wrong_err": err4["wrong_order"]}
    return f, data


def _plot(d, ax=None):
    w, dt, single_axis, t = d["w"], d["dt"], d["single_axis"], d["t"]
    err_naive, err_quat, err_unnorm, norm_unnorm = d["err_naive"], d["err_quat"], d["err_unnorm"], d["norm_unnorm"]
    body_err, wrong_err = d["body_err"], d["wrong_err"]
    fig, ax = C.new_figure(1, 3, size=(14, 4.4),
                           title=f"Constant world ω = {np.array2string(w, precision=3)} rad/s, dt = {dt:g} s"
                                 + (" (single axis)" if single_axis else ""), ax=ax)
    a = ax[0, 0]
    a.semilogy(t[1:], np.maximum(err_naive[1:], 1e-12), label="naive Euler-angle addition", color=F.VERMILLION)
    # the normalized and unnormalized errors coincide: the normalized one is drawn wide underneath
    a.semilogy(t[1:], np.maximum(err_quat[1:], 1e-12), label="quaternion, normalized", color=F.BLUE, lw=4, alpha=0.5)
    a.semilogy(t[1:], np.maximum(err_unnorm[1:], 1e-12), "--", label="quaternion, unnormalized (normalized to compare)",
               color=F.SKY_BLUE)
    a.set_xlabel("time t (s)")
    a.set_ylabel("orientation error (deg)")
    a.set_title(f"error vs exp(t[ω]×): {err_naive[-1]:.2f}° vs {err_quat[-1]:.5f}° at {T_END:g} s")
    a.legend(fontsize=8)
    b = ax[0, 1]
    b.plot(t, norm_unnorm, "--", color=F.SKY_BLUE, label="unnormalized")
    b.plot(t, d["norm_quat"], color=F.BLUE, label="normalized")
    b.set_xlabel("time t (s)")
    b.set_ylabel("|q| (dimensionless)")
    b.set_title(f"norm drift: |q(T)| = {norm_unnorm[-1]:.5f}")
    b.legend(fontsize=8)
    c = ax[0, 2]
    c.semilogy(t[1:], np.maximum(body_err[1:], 1e-12), color=F.GREEN, lw=4, alpha=0.5,
               label="body ω, ½ q⊗[ω_b,0] (correct; = world form)")
    c.semilogy(t[1:], np.maximum(d["world_err"][1:], 1e-12), ":", color=F.BLACK,
               label="world ω, ½ [ω_w,0]⊗q")
    c.semilogy(t[1:], np.maximum(wrong_err[1:], 1e-12), "-.", color=F.ORANGE, label="body ω, ½ [ω_b,0]⊗q (wrong order)")
    c.set_xlabel("time t (s)")
    c.set_ylabel("orientation error (deg)")
    c.set_title("paw-check 4: start 90° about y")
    c.legend(fontsize=8)
    return fig
