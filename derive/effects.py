"""The scene's effects, each declared once (derive.effect), and the force/torque kernels of the force lab.

Force effects contribute a force at the COM and/or a torque about it, both in the world frame (N,
N·m); their codes are their position in EFFECTS (1, 2, …), the contract between the Python effect
table and both backends. Model effects (a spherical joint, reaction wheels) change a body's model
instead; they declare their parameters here and their equations in derive/wheel_cube.py (body-axis
wheels) and derive/wheel_layout.py (wheels on the axes_b rows).
Units: damping coefficients c in N·s/m (linear) and N·m·s/rad (angular).
"""
from __future__ import annotations

from .effect import STATE as S
from .effect import EffectDecl, effect, model_effect, param
from .kernel import Arg, Kernel, vec
from .layout import WHEELS_MAX
from .quaternion import rotate_to_world


def torque_at_point(q, r_b, F_w):
    """Torque about the COM of a world force F_w applied at the body point r_b: (R_WB r_b) × F_w, R_WB r_b printed
    as the sandwich (quaternion.rotate_to_world, the same polynomial)."""
    return rotate_to_world(q, r_b).cross(F_w)


def declarations() -> list[EffectDecl]:
    """Every built-in effect, in code order (force effects first)."""
    torque_w = param("torque_w", 3, "N·m", "torque about the COM, world frame")
    r_b = param("r_b", 3, "m", "application point relative to the COM, body frame")
    F_w = param("F_w", 3, "N", "force, world frame")
    g_w = param("g_w", 3, "m/s²", "gravitational acceleration, world frame", default=(0.0, 0.0, -9.81))
    c_lin = param("c", (), "N·s/m", "viscous coefficient", rule="nonnegative")
    c_ang = param("c", (), "N·m·s/rad", "viscous coefficient", rule="nonnegative")
    return [
        effect("applied_torque", "A torque about the COM, world frame", [torque_w], torque_w=torque_w.symbol),
        effect("force_at_point", "A world force applied at a body-fixed point: the force acts on the COM plus a torque",
               [r_b, F_w], force_w=F_w.symbol, torque_w=torque_at_point(S.q, r_b.symbol, F_w.symbol),
               caption=r"F_{COM} = F_W,\quad \tau_W = (R_{WB} r_B) \times F_W"),
        effect("gravity", "Uniform gravity acting at the COM", [g_w], force_w=S.m * g_w.symbol, caption=r"F_W = m\,g_W"),
        effect("linear_damping", "Viscous drag on the COM velocity", [c_lin], force_w=-c_lin.symbol * S.v_w,
               caption=r"F_W = -c\,v_W"),
        effect("angular_damping", "Viscous drag on the angular velocity", [c_ang], torque_b=-c_ang.symbol * S.omega_b,
               caption=r"\tau_B = -c\,\omega_B,\quad \tau_W = R_{WB}\,\tau_B = -c\,\omega_W"),
        model_effect("spherical_joint", "World-anchored ball joint: the body point at anchor_w when the Sim starts stays there",
                     [param("anchor_w", 3, "m", "joint anchor, world frame")]),
        model_effect("reaction_wheels", "Reaction wheels on body-fixed spin axes (default three, on body x, y, z); the body's "
                     "mass and inertia include them, locked",
                     [param("J", WHEELS_MAX, "kg·m²", "wheel spin inertias, one per wheel (the body with its wheels free "
                            "must keep a positive definite inertia)", "positive", upto=True),
                      param("axes_b", (WHEELS_MAX, 3), "", "wheel spin axes, one unit row per wheel, body frame",
                            default=((1.0, 0.0, 0.0), (0.0, 1.0, 0.0), (0.0, 0.0, 1.0)), upto=True),
                      param("torque_limit", (), "N·m", "motor stall torque (clips each command)", "positive"),
                      param("speed_limit", (), "rad/s", "motor no-load speed: the drive torque falls linearly to 0 there "
                            "(with cutoff = 1: full torque below it, none beyond)", "positive"),
                      param("c_w", (), "N·m·s/rad", "wheel bearing (viscous) friction", "nonnegative", default=0.0),
                      param("cutoff", (), "", "0: torque–speed line (default); 1: the hard cut-off at speed_limit",
                            "nonnegative", default=0.0)]),
    ]


def kernels() -> list[Kernel]:
    """The force lab's kernels, then one kernel per force effect (effect_<name>)."""
    g = "Torque and effects"
    r_w, F_w, r_b = vec("r_w", 3), vec("F_w", 3), vec("r_b", 3)
    q = vec("q", 4)
    QU = ("q", q, "orientation (x, y, z, w), R_WB, unit", "unit_quaternion")
    plain = [
        Kernel("torque_from_force", "Torque of a force about the COM", r"\tau = r \times F",
               [Arg("r_w", r_w, "application point relative to the COM, world frame, m"), Arg("F_w", F_w, "force, world frame, N")],
               [Arg("tau_w", r_w.cross(F_w), "torque about the COM, world frame, N·m")], g),
        Kernel("force_at_point", "Torque about the COM of a world force applied at a body-fixed point",
               r"\tau_W = (R_{WB} r_B) \times F_W",
               [Arg(*QU), Arg("r_b", r_b, "application point relative to the COM, body frame, m"), Arg("F_w", F_w, "force, world frame, N")],
               [Arg("tau_w", torque_at_point(q, r_b, F_w), "torque about the COM, world frame, N·m")], g),
    ]
    forces = [d for d in declarations() if d.kind == "force"]
    return (plain + [d.kernel() for d in forces] + [k for k in (d.body_kernel() for d in forces) if k is not None]
            + [k for k in (d.affine_kernel() for d in forces) if k is not None])
