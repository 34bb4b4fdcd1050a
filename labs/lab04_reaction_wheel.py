"""Experiment 04: can an internal actuator rotate a body without pushing on the outside world?

The ReactionWheelCube-v0 model (lavendersim.control.chapter_cube, scenario "center"): a 15 cm, 1 kg cube
(I = m s²/6 = 3.75e-3 kg·m², wheels locked) on a spherical joint at its centre, three body-axis
wheels of spin inertia J = 5.7e-4 kg·m², motor limit 0.2 N·m, wheel speed limit 400 rad/s, cube
angular damping c = 1e-3 N·m·s/rad (the chapter's environment has damping and the joint). Each run
starts at rest, holds a wheel torque command for T = 1 s (dt = 1 ms, RK4), and records every step.

  * positive x-wheel command u = +0.05 N·m: every recorded wheel sample Omega_x > 0 and every cube
    sample omega_x < 0 (samples t in (0, T]; at t = 0 both are exactly 0, the rest state). The
    magnitudes differ — |Omega_x| / |omega_x| = I/J = 6.6 without damping, 7.5 with it — because the wheel's
    spin inertia is much smaller than the cube's.
  * paw-check 6: the reversed command u = −0.05 N·m reverses both signs everywhere (and the run is
    the exact mirror: |Omega_rev + Omega_pos| and |omega_rev + omega_pos| are reported).
  * two wheels at once (x and y, +0.05 N·m each): the reported cross-axis coupling is the z response
    and the departure from superposition of the x-only and y-only runs. For this isotropic cube
    with equal wheels it is ~0 (omega, Omega and the damping torque all stay along (1, 1, 0), so
    omega × H has no component to excite z); the lab then shows real gyroscopic coupling: with the
    z wheel pre-spun at 100 rad/s, an x command turns the cube about y (omega × J Omega).
  * saturation (the motor's torque–speed line, wheel_motor kernel): a 0.5 N·m command is clipped to
    the 0.2 N·m stall torque at rest; as the x wheel speeds up the torque it can apply falls linearly
    to 0 at the 400 rad/s no-load speed, so held for 1.5 s the applied torque follows 0.2 (1 − Ω/400)
    (checked to 1e-12), changes smoothly (no step jump above 0.01 N·m, where the old hard cut-off
    flipped between 0 and 0.2) and the wheel approaches but never passes 400 rad/s.
  * beyond the chapter: damping off, joint at the centre (no external torque), a cube spinning at
    omega_b = (0.3, −0.2, 0.5) rad/s and time-varying commands on all three wheels: the exchange is
    exact, ΔL_cube = −ΔL_wheels in the world frame (wheel_momentum kernel), max over the run of
    |ΔL_cube + ΔL_wheels| / max |ΔL_wheels| ≤ 1e-9.

Options: --torque U (command magnitude, N·m, default 0.05; must stay below the limit) and --T.
"""
from __future__ import annotations

import math

import numpy as np

import lavendersim as lv
from lavendersim import control as lc
from lavendersim import validate as V
from lavendersim import figures as F

from . import common as C
from .diverged import failed_figure

NAME = "04"
TITLE = "reaction wheel: cube and wheel spin opposite ways (paw-check 6: reversed command), coupling, saturation, exact momentum exchange"

TORQUE = 0.05
T_END = 1.0
T_SAT = 1.5
DT = 1e-3
DAMPING = 1e-3
BODY = lc.BODY


def _run(damping, u_of_t, T, backend, omega_b=(0, 0, 0), Omega=(0, 0, 0), momentum=False):
    """The chapter cube (centre joint, angular damping `damping`) starting at omega_b, Omega: hold u_of_t(t) per
    step; record t, omega_b, Omega, applied torque (and momenta)."""
    sim = lv.Sim(lc.chapter_cube("center", damping=damping, omega_b=omega_b), dt=DT, integrator="rk4", backend=backend)
    if np.any(np.asarray(Omega, dtype=float) != 0):
        sim.set_state(BODY, Omega=V.vector("Omega", Omega))
    n = int(round(T / DT))
    t = np.empty(n + 1)
    w, Om, ua = np.empty((n + 1, 3)), np.empty((n + 1, 3)), np.zeros((n + 1, 3))
    Lb, Lw = np.empty((n + 1, 3)), np.empty((n + 1, 3))
    for k in range(n + 1):
        t[k], w[k], Om[k] = sim.t, sim.state(BODY).omega_b, sim.wheel_rates(BODY)
        if momentum:
            Lb[k], Lw[k] = sim.wheel_momentum_w(BODY)
        if k == n:
            break
        sim.set_wheel_command(BODY, u_of_t(sim.t))
        sim.step()
        ua[k + 1] = sim.wheel_command_applied(BODY)
    return {"t": t, "w": w, "Om": Om, "u": ua, "Lb": Lb, "Lw": Lw}


def run(out_dir=C.DEFAULT_OUT, backend: str = "auto", **options) -> C.LabResult:
    """:func:`compute`, then write OUT/04/ (results.json, reaction_wheel.png)."""
    return compute(backend, **options).save(out_dir)


@failed_figure
def compute(backend: str = "auto", torque: float = TORQUE, T: float = T_END) -> C.LabResult:
    """Run the lab and return its :class:`~lavendersim.labs.common.LabResult`; writes nothing."""
    backend = C.check_backend(backend)
    U = V.positive("torque", torque)
    T = V.positive("T", T)
    model = lc.chapter_cube("center", damping=DAMPING)
    cube, wheels = model.bodies[BODY], model.model_effects(BODY)["reaction_wheels"].values
    torque_limit, speed_limit = wheels["torque_limit"], wheels["speed_limit"]
    if U >= torque_limit:
        raise V.LavenderInputError("torque", f"must be below the motor limit {torque_limit:g} N·m for the sign runs "
                                   "(saturation has its own run)", f", got {U!r}")
    if int(round(T / DT)) < 2:
        raise V.LavenderInputError("T", f"must be at least 2 steps of {DT:g} s", f", got {T!r}")
    C.steps("T", T, DT, whole=False, limit=C.MAX_PY_STEPS, value=T)  # stepped in Python, every step recorded
    runs = _runs(U, T, backend)
    f = _figures(runs, torque_limit, speed_limit)
    params = {"backend": backend, "torque": U, "T": T, "dt": DT, "integrator": "rk4", "damping": DAMPING,
              "mass": cube.mass, "size": cube.shape[1][0], "J": wheels["J"], "I_cube": cube.I_b,
              "torque_limit": torque_limit, "speed_limit": speed_limit,
              "gyro_Omega_z0": 100.0, "exchange_omega_b0": np.array([0.3, -0.2, 0.5]), "exchange_damping": 0.0}
    checks = C.checks(
        ("wheel_all_positive", f["wheel_all_positive"], "holds", None, f"every x-wheel sample in (0, {T:g}] s > 0"),
        ("cube_all_negative", f["cube_all_negative"], "holds", None, f"every cube omega_x sample in (0, {T:g}] s < 0"),
        ("paw6_reversed_command_reverses_both", f["reversed_ok"], "holds", None,
         "reversed command: wheel all < 0, cube all > 0, an exact mirror of the positive run"),
        ("wheel_faster_than_cube", f["wheel_to_cube_rate_ratio"], ">", 1.0,
         "|Omega_x| / |omega_x| at T: different magnitudes"),
        ("single_wheel_stays_on_axis", f["single_wheel_other_axes_max"], "<=", 1e-12,
         "y, z rates of the x-only run (rad/s)"),
        ("two_wheels_z_coupling", f["two_wheels_cross_axis_coupling"], "<=", 1e-9,
         "isotropic cube, equal wheels: no z response (rad/s)"),
        ("gyroscopic_coupling_shown", f["gyro_coupling_omega_y_over_omega_x"], ">", 0.01,
         "z wheel pre-spun at 100 rad/s: an x command turns the cube about y"),
        ("saturation_clips_to_limit", f["saturation_applied_max"], "≈", (torque_limit, 1e-15),
         "0.5 N·m command -> applied (N·m)"),
        ("saturation_speed_limit", f["saturation_peak_wheel_speed"], "<=", speed_limit + f["saturation_step_increment"],
         "x wheel stays within one step's increment of the 400 rad/s limit"),
        ("saturation_follows_torque_speed_line", f["saturation_torque_speed_line_error"], "<=", 1e-12,
         "|applied u_x − 0.2 (1 − Ω_x/400)| over the run (N·m)"),
        ("saturation_is_smooth", f["saturation_max_torque_jump"], "<=", 0.01,
         "largest step-to-step change of the applied torque (N·m)"),
        ("saturation_below_no_load_speed", f["saturation_wheel_speed_T"], "<", speed_limit,
         "wheel speed at the end (rad/s)"),
        ("momentum_exchange_error", f["momentum_exchange_error"], "<=", 1e-9,
         "damping off, joint at the centre: max |ΔL_cube + ΔL_wheels| / max |ΔL_wheels|, world frame"),
    )
    ex = runs["ex"]
    data = {**runs, "dLb": ex["Lb"] - ex["Lb"][0], "dLw": ex["Lw"] - ex["Lw"][0], "scale": f["momentum_exchange_scale"],
            "exchange_err": f["momentum_exchange_error"], "U": U, "ratio": f["wheel_to_cube_rate_ratio"],
            "coupling_z": f["two_wheels_cross_axis_coupling"], "gyro_ratio": f["gyro_coupling_omega_y_over_omega_x"],
            "torque_limit": torque_limit, "speed_limit": speed_limit, "backend": backend}
    return C.make_result(NAME, f, params, checks, {"reaction_wheel.png": _plot}, data,
                         headline=("momentum_exchange_error", "<= 1e-9 (ΔL_cube = −ΔL_wheels; wheel and cube "
                                   "spin opposite ways)"))


def _runs(U: float, T: float, backend: str) -> dict:
    """The lab's runs: sign (x, reversed, y, x and y), gyroscopic, saturation and the momentum exchange."""
    const = lambda u: (lambda t: np.asarray(u, float))  # noqa: E731
    return {"pos": _run(DAMPING, const([U, 0, 0]), T, backend), "rev": _run(DAMPING, const([-U, 0, 0]), T, backend),
            "ys": _run(DAMPING, const([0, U, 0]), T, backend), "xy": _run(DAMPING, const([U, U, 0]), T, backend),
            "gyro": _run(DAMPING, const([U, 0, 0]), T, backend, Omega=(0, 0, 100.0)),
            "sat": _run(DAMPING, const([0.5, 0, 0]), T_SAT, backend),
            "ex": _run(0.0, lambda t: np.array([0.08 * math.sin(7 * t), -0.05, 0.12 * math.cos(3 * t)]), T, backend,
                       omega_b=(0.3, -0.2, 0.5), momentum=True)}


def _figures(r: dict, torque_limit: float, speed_limit: float) -> dict:
    """The figures of the runs: signs and the mirror (paw-check 6), coupling, saturation, momentum exchange."""
    pos, rev, xy, gyro, sat, ex = r["pos"], r["rev"], r["xy"], r["gyro"], r["sat"], r["ex"]
    s = slice(1, None)  # samples after the command starts (t = 0 is the rest state, exactly 0)
    mirror_err = float(max(np.max(np.abs(rev["Om"] + pos["Om"])), np.max(np.abs(rev["w"] + pos["w"]))))
    rev_wheel_negative, rev_cube_positive = bool(np.all(rev["Om"][s, 0] < 0)), bool(np.all(rev["w"][s, 0] > 0))
    # the torque–speed line: u[k+1] was applied over step k, from the wheel speed Om[k]
    line = torque_limit * np.clip(1 - sat["Om"][:-1, 0] / speed_limit, 0, 1)
    dLb, dLw = ex["Lb"] - ex["Lb"][0], ex["Lw"] - ex["Lw"][0]
    scale = float(np.max(np.linalg.norm(dLw, axis=1)))
    L_tot = ex["Lb"] + ex["Lw"]
    return {
        "wheel_all_positive": bool(np.all(pos["Om"][s, 0] > 0)), "cube_all_negative": bool(np.all(pos["w"][s, 0] < 0)),
        "reversed_wheel_all_negative": rev_wheel_negative, "reversed_cube_all_positive": rev_cube_positive,
        "reversed_ok": bool(rev_wheel_negative and rev_cube_positive and mirror_err <= 1e-9 * np.max(np.abs(pos["Om"]))),
        "reversed_mirror_error": mirror_err,
        "omega_x_T": float(pos["w"][-1, 0]), "Omega_x_T": float(pos["Om"][-1, 0]),
        "wheel_to_cube_rate_ratio": float(pos["Om"][-1, 0] / -pos["w"][-1, 0]),
        "single_wheel_other_axes_max": float(max(np.max(np.abs(pos["w"][:, 1:])), np.max(np.abs(pos["Om"][:, 1:])))),
        "two_wheels_cross_axis_coupling": float(max(np.max(np.abs(xy["w"][:, 2])), np.max(np.abs(xy["Om"][:, 2])))),
        "two_wheels_superposition_error": float(max(np.max(np.abs(xy["w"] - pos["w"] - r["ys"]["w"])),
                                                    np.max(np.abs(xy["Om"] - pos["Om"] - r["ys"]["Om"])))),
        "two_wheels_omega_T": xy["w"][-1], "two_wheels_Omega_T": xy["Om"][-1],
        "gyro_coupling_omega_y_over_omega_x": float(np.max(np.abs(gyro["w"][:, 1])) / np.max(np.abs(gyro["w"][:, 0]))),
        "gyro_omega_T": gyro["w"][-1],
        "saturation_command": 0.5, "saturation_applied_max": float(np.max(np.abs(sat["u"]))),
        "saturation_applied_first": float(sat["u"][1, 0]),
        "saturation_peak_wheel_speed": float(np.max(np.abs(sat["Om"][:, 0]))),
        "saturation_wheel_speed_T": float(sat["Om"][-1, 0]),
        # the largest one-step increase of Omega_x under full torque bounds the overshoot past the limit
        "saturation_step_increment": float(np.max(np.diff(sat["Om"][:, 0]))),
        "saturation_torque_speed_line_error": float(np.max(np.abs(sat["u"][1:, 0] - np.minimum(0.5, line)))),
        "saturation_max_torque_jump": float(np.max(np.abs(np.diff(sat["u"][1:, 0])))),
        "momentum_exchange_error": float(np.max(np.linalg.norm(dLb + dLw, axis=1)) / scale),
        "momentum_exchange_scale": scale,
        "total_momentum_drift": float(np.max(np.linalg.norm(L_tot - L_tot[0], axis=1)) / np.linalg.norm(L_tot[0])),
    }


def _plot(d, ax=None):
    pos, rev, xy, gyro, sat, ex = d["pos"], d["rev"], d["xy"], d["gyro"], d["sat"], d["ex"]
    dLb, dLw, scale, exchange_err, U, ratio = d["dLb"], d["dLw"], d["scale"], d["exchange_err"], d["U"], d["ratio"]
    coupling_z, gyro_ratio, backend = d["coupling_z"], d["gyro_ratio"], d["backend"]
    torque_limit, speed_limit = d["torque_limit"], d["speed_limit"]
    fig, ax = C.new_figure(2, 3, size=(15, 10), title=f"Experiment 04: reaction-wheel cube ({backend} backend)", ax=ax)
    cube, wheel = {"color": F.BLUE}, {"color": F.ORANGE}      # the cube and its wheel, in every panel
    # every legend sits under its panel (F.legend_below), off the curves
    a = ax[0, 0]
    a.plot(pos["t"], pos["w"][:, 0], **cube, label="cube ω_x (< 0)")
    a.plot(pos["t"], pos["Om"][:, 0], **wheel, ls="--", label="wheel Ω_x (> 0)")
    a.set_xlabel("t (s)"); a.set_ylabel("rad/s"); F.legend_below(a)
    a.set_title(f"+{U:g} N·m x-wheel: opposite signs, ratio {ratio:.2f}")
    a.axhline(0, color=F.BLACK, lw=0.5)
    a = ax[0, 1]
    for run_, ls, lab in ((pos, "-", "+u"), (rev, "--", "−u (paw-check 6)")):
        a.plot(run_["t"], run_["w"][:, 0] * 10, ls, **cube, label=f"cube ω_x ×10, {lab}")
        a.plot(run_["t"], run_["Om"][:, 0], ls, **wheel, lw=2.5, alpha=0.8, label=f"wheel Ω_x, {lab}")
    a.axhline(0, color=F.BLACK, lw=0.5); a.set_xlabel("t (s)"); a.set_ylabel("rad/s"); F.legend_below(a)
    a.set_title("reversed command reverses both")
    a = ax[0, 2]
    every = max(1, len(xy["t"]) // 12)
    for i, c in enumerate("xyz"):   # equal wheels: ω_x = ω_y, so ω_x is drawn wide underneath
        a.plot(xy["t"], xy["w"][:, i], color=F.AXIS_STYLE[c]["color"], marker=F.AXIS_STYLE[c]["marker"],
               markevery=every, ms=4, mfc="none", lw=4 if i == 0 else 1.5, alpha=0.5 if i == 0 else 1.0,
               label=f"two wheels: ω_{c}" + (" (= ω_y)" if i == 0 else ""))
    for i, c in enumerate("xyz"):
        a.plot(gyro["t"], gyro["w"][:, i], ":", color=F.AXIS_STYLE[c]["color"], lw=2,
               label=f"x cmd, z wheel at 100 rad/s: ω_{c}")
    a.set_xlabel("t (s)"); a.set_ylabel("cube ω_b (rad/s)"); F.legend_below(a, fontsize=7)
    a.set_title(f"coupling: two wheels |ω_z| {coupling_z:.0e}; gyro |ω_y|/|ω_x| {gyro_ratio:.2f}", fontsize=10)
    a = ax[1, 0]
    a.plot(sat["t"][1:], sat["u"][1:, 0], color=F.VERMILLION, label="applied u_x, N·m (command 0.5)")
    a.axhline(torque_limit, color=F.VERMILLION, ls=":", lw=0.8, label=f"stall torque {torque_limit:g} N·m")
    a.set_xlabel("t (s)"); a.set_ylabel("applied torque u_x (N·m)", color=F.VERMILLION)
    a.set_ylim(0, 1.1 * torque_limit)
    b = a.twinx()
    b.plot(sat["t"], sat["Om"][:, 0], **wheel, ls="--", label="wheel Ω_x, rad/s (right axis)")
    b.axhline(speed_limit, **wheel, ls=":", lw=0.8, label=f"no-load speed {speed_limit:g} rad/s")
    b.set_ylabel("wheel Ω_x (rad/s)", color=F.ORANGE)
    b.set_ylim(0, 1.1 * speed_limit)
    h1, l1 = a.get_legend_handles_labels()
    h2, l2 = b.get_legend_handles_labels()
    F.legend_below(a, handles=h1 + h2, labels=l1 + l2, fontsize=7)
    a.set_title("saturation: u = 0.2 (1 − Ω/400), a motor's torque–speed line", fontsize=10)
    a = ax[1, 1]
    for i, c in enumerate("xyz"):
        a.plot(ex["t"], dLb[:, i], **F.axis_style(c, marker=None), label=f"ΔL_cube,{c}")
        a.plot(ex["t"], -dLw[:, i], ":", color=F.BLACK, lw=1, label="−ΔL_wheels" if i == 0 else None)
    a.set_xlabel("t (s)"); a.set_ylabel("kg·m²/s (world)"); F.legend_below(a, ncols=4, fontsize=7)
    a.set_title("no damping: ΔL_cube (colour) = −ΔL_wheels (dotted)")
    a = ax[1, 2]
    a.semilogy(ex["t"][1:], np.maximum(np.linalg.norm(dLb + dLw, axis=1)[1:] / scale, 1e-18), color=F.BLUE,
               label="measured")
    a.axhline(1e-9, color=F.VERMILLION, ls=":", label="bound 1e-9")
    a.set_xlabel("t (s)"); a.set_ylabel("|ΔL_cube + ΔL_wheels| / max|ΔL_wheels|"); F.legend_below(a)
    a.set_title(f"exchange error {exchange_err:.1e}")
    return fig
