"""Off-center force: a force F applied at an offset r from the COM produces torque tau = r x F.

Chapter figure: r = [0.3, 0, 0] m, F = [0, 5, 0] N  ->  tau = [0, 0, 1.5] N·m (exact to 1e-12).
A force along the lever arm gives zero torque. Paw-check 2: the same force at r = [-0.3, 0, 0] m
gives [0, 0, -1.5] N·m.

Then through the simulator: a body at rest (the chapter's 0.8 x 0.2 x 0.2 m, 1 kg rod, whose long
axis is body x, so the 0.3 m offset lies inside it) gets a force_at_point effect. After one RK4 step
of a tiny dt from rest, omega_w / dt is the angular acceleration up to O(dt^2) (at rest the
gyroscopic term and the rotation of the lever arm enter only at second order); it must equal
I_w^-1 tau from the apply_inv_inertia kernel. A second copy in a general orientation checks the
body-frame offset and the world inertia, and the COM acceleration must be F / m.
"""
from __future__ import annotations

import numpy as np

import lavendersim as lv
from lavendersim.kernels import K
from lavendersim import figures as S   # (F is the force here)

from . import common as C
from .diverged import failed_figure

NAME = "force"
TITLE = "off-center force: torque = r x F, zero along the lever arm, reversed at -r; checked in the simulator"

R_W = (0.3, 0.0, 0.0)
F_W = (0.0, 5.0, 0.0)
TAU_EXPECTED = (0.0, 0.0, 1.5)
EXACT_TOL = 1e-12
ROD_SIZE = (0.8, 0.2, 0.2)
ROD_MASS = 1.0
# a general orientation for the second simulated rod: 0.7 rad about (1, 2, 3)/|.|
TILT_AXIS = (1.0, 2.0, 3.0)
TILT_ANGLE = 0.7
SIM_DT = 1e-6
SIM_REL_TOL = 1e-8  # O(dt^2) truncation of omega(dt)/dt at dt = 1e-6, with margin


def run(out_dir=C.DEFAULT_OUT, backend: str = "auto", **options) -> C.LabResult:
    """:func:`compute`, then write OUT/force/ (results.json, force.png)."""
    return compute(backend, **options).save(out_dir)


@failed_figure
def compute(backend: str = "auto", offset: float = R_W[0]) -> C.LabResult:
    """Run the lab and return its :class:`~lavendersim.labs.common.LabResult`; writes nothing."""
    backend = C.check_backend(backend)
    x = C.bounded("offset", offset)
    r, F = np.array([x, 0.0, 0.0]), np.array(F_W)
    F_along, r_neg = np.array([5.0, 0.0, 0.0]), np.array([-R_W[0], 0.0, 0.0])  # along the lever arm; paw-check 2
    # pure kernels; only the perpendicular part contributes: F = [3, 4, 0] at r gives the torque of [0, 4, 0]
    tau = K.torque_from_force(r, F)
    f = {"torque": tau, "torque_along_lever_arm": K.torque_from_force(r, F_along),
         "torque_at_minus_offset": K.torque_from_force(r_neg, F),
         "torque_mixed_force": K.torque_from_force(r, np.array([3.0, 4.0, 0.0]))}
    tau_perp = K.torque_from_force(r, np.array([0.0, 4.0, 0.0]))
    sim_f, I_b, pipeline = _simulated(r, F, backend)
    f.update(sim_f)
    params = {
        "backend": backend, "r_w": r, "F_w": F, "F_along_lever_w": F_along, "paw_check_r_w": r_neg,
        "body": "box", "body_size": np.array(ROD_SIZE), "body_mass": ROD_MASS, "I_b": I_b,
        "tilt_axis": np.array(TILT_AXIS), "tilt_angle": TILT_ANGLE, "sim_dt": SIM_DT, "integrator": "rk4",
        "pipeline": " | ".join(pipeline),
    }
    chapter, worst = x == R_W[0], lambda v: float(np.max(np.abs(v)))
    checks = C.checks(
        chapter and ("torque", worst(tau - TAU_EXPECTED), "<=", EXACT_TOL, "max |tau - [0, 0, 1.5]| N·m (chapter)"),
        not chapter and ("torque_z_equals_x_Fy", abs(tau[2] - x * F[1]) + abs(tau[0]) + abs(tau[1]), "<=", EXACT_TOL,
                         f"offset {x} m: tau should be [0, 0, {x * F[1]}]"),
        ("torque_along_lever_arm", worst(f["torque_along_lever_arm"]), "<=", EXACT_TOL,
         "force along the lever arm gives zero torque"),
        ("paw2_torque_at_minus_0.3", worst(f["torque_at_minus_offset"] - np.array([0.0, 0.0, -1.5])), "<=", EXACT_TOL,
         "paw-check 2: F at -0.3 m gives [0, 0, -1.5] N·m"),
        ("perpendicular_part_only", worst(f["torque_mixed_force"] - tau_perp), "<=", EXACT_TOL,
         "F = [3, 4, 0] N gives the torque of its perpendicular part [0, 4, 0] N"),
        ("alpha_sim_vs_apply_inv_inertia", f["alpha_rel_error"], "<=", SIM_REL_TOL,
         "relative, body at rest in identity orientation"),
        ("alpha_tilted_sim_vs_apply_inv_inertia", f["alpha_tilted_rel_error"], "<=", SIM_REL_TOL,
         "relative, body at rest in a general orientation"),
        ("apply_inv_inertia_equals_inverse_world_inertia", f["apply_inv_inertia_vs_matrix_inverse"], "<=", 1e-12,
         "apply_inv_inertia(q, I_b, tau) == world_inertia(q, I_b)^-1 tau"),
        ("com_acceleration_F_over_m", worst(f["com_acceleration_w"] - F / ROD_MASS), "<=", 1e-9,
         "the force also accelerates the COM: a = F / m, m/s²"),
    )
    data = {"r": r, "F": F, "F_along": F_along, "tau": tau, "tau_along": f["torque_along_lever_arm"],
            "tau_neg": f["torque_at_minus_offset"], "tau_mixed": f["torque_mixed_force"]}
    return C.make_result(NAME, f, params, checks, {"force.png": _plot}, data,
                         headline=("torque", "[0, 0, 1.5] N·m within 1e-12"))


def _simulated(r, F, backend: str):
    """One RK4 step of dt = 1e-6 s of the rod at rest (identity and tilted) under F at r: alpha and the COM's
    acceleration against the kernels. Returns (figures, I_b, pipeline)."""
    q_tilt = K.axis_angle_to_quat(np.array(TILT_AXIS) / np.linalg.norm(TILT_AXIS), TILT_ANGLE)
    scene = lv.Scene()
    rod = scene.add_body(lv.Body.box("rod", mass=ROD_MASS, size=ROD_SIZE))
    scene.add_body(lv.Body.box("rod_tilted", mass=ROD_MASS, size=ROD_SIZE, q=q_tilt, p_w=[0.0, 1.0, 0.0]))
    scene.add_effect("force_at_point", body="rod", r_b=r, F_w=F)
    scene.add_effect("force_at_point", body="rod_tilted", r_b=r, F_w=F)
    sim = lv.Sim(scene, dt=SIM_DT, integrator="rk4", backend=backend)
    sim.step()
    I_b, identity = rod.I_b, np.array([0.0, 0.0, 0.0, 1.0])
    alpha_pred = K.apply_inv_inertia(identity, I_b, K.force_at_point(identity, r, F))
    alpha_sim = sim.state("rod").omega_w / SIM_DT
    tau_tilt = K.force_at_point(q_tilt, r, F)  # = torque_from_force(R r_b, F)
    alpha_pred_tilt = K.apply_inv_inertia(q_tilt, I_b, tau_tilt)
    alpha_sim_tilt = sim.state("rod_tilted").omega_w / SIM_DT
    # I_w^-1 tau by a matrix inverse of world_inertia, as an independent cross-check of the kernel
    alpha_matrix_tilt = np.linalg.solve(K.world_inertia(q_tilt, I_b), tau_tilt)

    def rel(a, b):
        return float(np.max(np.abs(a - b)) / max(np.max(np.abs(b)), 1e-300))

    return {
        "alpha_predicted_w": alpha_pred, "alpha_simulated_w": alpha_sim, "alpha_rel_error": rel(alpha_sim, alpha_pred),
        "alpha_tilted_predicted_w": alpha_pred_tilt, "alpha_tilted_simulated_w": alpha_sim_tilt,
        "alpha_tilted_rel_error": rel(alpha_sim_tilt, alpha_pred_tilt),
        "apply_inv_inertia_vs_matrix_inverse": rel(alpha_pred_tilt, alpha_matrix_tilt),
        "com_acceleration_w": sim.state("rod").v_w / SIM_DT,
    }, I_b, sim.pipeline


def _plot(d, ax=None):
    r, F, F_along = d["r"], d["F"], d["F_along"]
    tau, tau_along, tau_neg, tau_mixed = d["tau"], d["tau_along"], d["tau_neg"], d["tau_mixed"]
    fig, ax = C.new_figure(1, 2, size=(10, 4.2), title="Off-center force: torque = r × F", ax=ax)
    a = ax[0, 0]
    a.add_patch(_rect(ROD_SIZE[0], ROD_SIZE[1]))
    a.annotate("", xy=(r[0], 0), xytext=(0, 0), arrowprops=dict(arrowstyle="->", color="k"))
    a.annotate("", xy=(r[0], 0.1 * F[1]), xytext=(r[0], 0), arrowprops=dict(arrowstyle="->", color=S.VERMILLION, lw=2))
    a.annotate("", xy=(-R_W[0], 0.1 * F[1]), xytext=(-R_W[0], 0),
               arrowprops=dict(arrowstyle="->", color=S.PURPLE, lw=2, ls="--"))
    a.annotate("", xy=(r[0] + 0.1 * F_along[0], 0), xytext=(r[0], 0),
               arrowprops=dict(arrowstyle="->", color=S.GREY, lw=2))
    a.plot([0], [0], "ko")
    a.text(r[0], -0.12, f"r = [{r[0]:g}, 0, 0] m", ha="center")
    a.text(r[0] + 0.02, 0.1 * F[1], "F = [0, 5, 0] N", color=S.VERMILLION)
    a.text(-R_W[0] - 0.02, 0.1 * F[1], "paw-check 2: at −0.3 m", color=S.PURPLE, ha="right")
    a.text(r[0] + 0.5, 0.05, "F along r", color=S.GREY, ha="right")
    a.set_xlim(-1.25, 1.1)
    a.set_ylim(-0.4, 0.7)
    a.set_aspect("equal")
    a.set_xlabel("x (m)")
    a.set_ylabel("y (m)")
    a.set_title("rod 0.8 × 0.2 × 0.2 m, top view (scale 0.1 m/N)")
    b = ax[0, 1]
    labels = ["F⊥ at +0.3 m", "F along r", "F⊥ at −0.3 m", "[3,4,0] N at +0.3"]
    vals = [tau[2], tau_along[2], tau_neg[2], tau_mixed[2]]
    b.bar(labels, vals, color=[S.VERMILLION, S.GREY, S.PURPLE, S.ORANGE], hatch=["", "", "//", ".."], edgecolor=S.BLACK, lw=0.5)
    b.axhline(0, color="k", lw=0.8)
    b.text(1, 0.06, f"{tau_along[2]:g}: no torque", ha="center", color=S.BLACK, fontsize=9)
    b.set_ylabel("torque τ_z (N·m)")
    b.set_title("τ = r × F (torque_from_force kernel)")
    b.tick_params(axis="x", labelsize=8)
    return fig


def _rect(w, h):
    from matplotlib.patches import Rectangle

    return Rectangle((-w / 2, -h / 2), w, h, fill=True, alpha=0.25, color=S.BLUE)
