"""Force and torque contributions of scene effects, all in the world frame about the COM.

Forces in N, torques in N·m, damping coefficients c in N·s/m (linear) and N·m·s/rad (angular).
"""
from __future__ import annotations


from .kernel import Arg, Kernel, scalar, vec
from .quaternion import rotation_matrix


def kernels() -> list[Kernel]:
    g = "Torque and effects"
    r_w, F_w, r_b, g_w = vec("r_w", 3), vec("F_w", 3), vec("r_b", 3), vec("g_w", 3)
    q, v_w, omega_b = vec("q", 4), vec("v_w", 3), vec("omega_b", 3)
    m, c = scalar("m", positive=True), scalar("c")
    R = rotation_matrix(q)
    QU = ("q", q, "orientation (x, y, z, w), R_WB, unit", "unit_quaternion")
    return [
        Kernel("torque_from_force", "Torque of a force about the COM", r"\tau = r \times F",
               [Arg("r_w", r_w, "application point relative to the COM, world frame, m"), Arg("F_w", F_w, "force, world frame, N")],
               [Arg("tau_w", r_w.cross(F_w), "torque about the COM, world frame, N·m")], g),
        Kernel("force_at_point", "A world force applied at a body-fixed point: the force acts on the COM plus a torque",
               r"F_{COM} = F_W,\quad \tau_W = (R_{WB} r_B) \times F_W",
               [Arg(*QU), Arg("r_b", r_b, "application point relative to the COM, body frame, m"), Arg("F_w", F_w, "force, world frame, N")],
               [Arg("tau_w", (R * r_b).cross(F_w), "torque about the COM, world frame, N·m")], g),
        Kernel("gravity_force", "Uniform gravity acting at the COM", r"F_W = m\,g_W",
               [Arg("m", m, "mass, kg", "positive"), Arg("g_w", g_w, "gravitational acceleration, world frame, m/s²")],
               [Arg("F_w", m * g_w, "force, world frame, N")], g),
        Kernel("linear_damping", "Viscous drag on the COM velocity", r"F_W = -c\,v_W",
               [Arg("c", c, "coefficient, N·s/m", "positive"), Arg("v_w", v_w, "COM velocity, world frame, m/s")],
               [Arg("F_w", -c * v_w, "force, world frame, N")], g),
        Kernel("angular_damping", "Viscous drag on the angular velocity", r"\tau_W = -c\,R_{WB}\,\omega_B = -c\,\omega_W",
               [Arg(*QU), Arg("c", c, "coefficient, N·m·s/rad", "positive"), Arg("omega_b", omega_b, "angular velocity, body frame, rad/s")],
               [Arg("tau_w", -c * (R * omega_b), "torque, world frame, N·m")], g),
    ]
