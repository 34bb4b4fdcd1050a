"""Row layouts shared by derive/, the C step loop and the Python runtime, declared once.

Every array the backends exchange is a table of float64 rows. Each layout below names the fields of
one row in order; `lavendersim derive` prints them as named offsets for C (generated/layout.h,
`LV_<ROW>_<FIELD>` and `LV_<ROW>_SIZE`) and Python (generated/layout.py, a slice per vector field,
an index per scalar field, `<ROW>_SIZE` and a `<ROW>_LAYOUT` dict of slices). Backends index rows
by these names only, never by literal numbers.

The effect-row layout ([code, body, p0 … p5]) is declared with the effects, not here.
"""
from __future__ import annotations

from dataclasses import dataclass

import sympy as sp

from .printers import HEADER

# Reaction wheels per body inside a Sim: every wheeled body carries this many wheel slots (rates, motor
# commands, applied torques, inertias, axes) and is stepped by the one N-wheel model, the printed
# wheels<WHEELS_MAX> kernels. A layout of fewer wheels pads the rest with a zero axis, J = 1, at rest
# (derive/wheel_layout.py proves a padded wheel changes nothing); the default layout, three wheels on
# the body axes, is A_b = [I | 0] in the first WHEELS_BODY_AXES slots.
WHEELS_MAX = 4
WHEELS_BODY_AXES = 3


@dataclass(frozen=True)
class Field:
    name: str
    size: int
    doc: str


class Layout:
    """An ordered row of named fields; offsets follow from the declaration order."""

    def __init__(self, prefix: str, title: str, fields: list[Field]):
        self.prefix, self.title, self.fields = prefix, title, fields
        names = [f.name for f in fields]
        if len(set(names)) != len(names):
            raise RuntimeError(f"derive: layout {prefix} repeats a field name")

    def offset(self, name: str) -> int:
        off = 0
        for f in self.fields:
            if f.name == name:
                return off
            off += f.size
        raise KeyError(f"layout {self.prefix}: no field {name!r}")

    def field(self, name: str) -> Field:
        return next(f for f in self.fields if f.name == name)

    def slice(self, name: str) -> slice:
        o = self.offset(name)
        return slice(o, o + self.field(name).size)

    @property
    def size(self) -> int:
        return sum(f.size for f in self.fields)

    def part(self, row: sp.Matrix, name: str) -> sp.Matrix:
        """The field `name` of a symbolic row (a column Matrix of this layout's size)."""
        if row.rows != self.size:
            raise RuntimeError(f"derive: a {self.prefix} row has {self.size} entries, got {row.rows}")
        return row[self.slice(name), 0]

    def assemble(self, **parts) -> sp.Matrix:
        """A symbolic row from one column per field, in this layout's order."""
        if set(parts) != {f.name for f in self.fields}:
            raise RuntimeError(f"derive: a {self.prefix} row needs exactly the fields {[f.name for f in self.fields]}")
        cols = [sp.Matrix(parts[f.name]) for f in self.fields]
        for f, c in zip(self.fields, cols):
            if c.shape != (f.size, 1):
                raise RuntimeError(f"derive: {self.prefix}.{f.name} has {f.size} entries, got shape {c.shape}")
        return sp.Matrix.vstack(*cols)


STATE = Layout("STATE", "body state x", [
    Field("p_w", 3, "position of the centre of mass, world frame, m"),
    Field("q", 4, "orientation R_WB as (x, y, z, w), unit"),
    Field("v_w", 3, "velocity of the centre of mass, world frame, m/s"),
    Field("omega_b", 3, "angular velocity, body frame, rad/s"),
])

PARAM = Layout("PARAM", "body parameters", [
    Field("m", 1, "mass, kg"),
    Field("I_b", 3, "principal moments of inertia (I_x, I_y, I_z), body frame, kg·m²"),
])

MODEL = Layout("MODEL", "per-body model row (spherical joint and/or reaction wheels)", [
    Field("kind", 1, "bit set of the KIND_* flags; 0: a plain rigid body (the row is ignored)"),
    Field("I_p", 9, "inertia about the pivot (wheels locked), body frame, kg·m², row-major"),
    Field("r_b", 3, "pivot → COM, body frame, m"),
    Field("anchor_w", 3, "joint anchor, world frame, m"),
    Field("J", WHEELS_MAX, "wheel spin inertias, kg·m² (unused slots 1)"),
    Field("torque_limit", 1, "motor torque limit, N·m"),
    Field("speed_limit", 1, "no drive beyond this |Omega_i|, rad/s"),
    Field("c_w", 1, "wheel bearing damping, N·m·s/rad"),
    Field("cutoff", 1, "wheel motor: 0 torque–speed line (stall torque_limit, no-load speed_limit); 1 hard cut-off"),
    Field("A_b", 3 * WHEELS_MAX, "wheel spin axes as the columns of a 3×WHEELS_MAX matrix, body frame, row-major "
          "(unused slots 0)"),
])

XS = Layout("XS", "extended state of a body with a model: x then the wheel rates", [
    Field("x", STATE.size, "the body state (STATE layout)"),
    Field("Omega", WHEELS_MAX, "wheel rates relative to the body, rad/s (unused slots 0)"),
])

EULER = Layout("EULER", "Euler coefficients c_b of a body (derive/rigid_body.py euler_coefficients)", [
    Field("k", 3, "k_x = (I_y - I_z)/I_x (cyclic), body frame, dimensionless"),
    Field("r", 3, "r_x = 1/I_x (cyclic), body frame, 1/(kg·m²)"),
])

WCOEF = Layout("WCOEF", "wheel-model coefficients k_w of a wheeled body (derive/wheel_layout.py wheels<WHEELS_MAX>_coefficients)", [
    Field("Minv", 9, "(I_p − A_b J A_bᵀ)⁻¹, body frame, row-major, 1/(kg·m²)"),
    Field("J_inv", WHEELS_MAX, "1/J per wheel slot, 1/(kg·m²)"),
])

DENSE = Layout("DENSE", "dopri5's dense output of a body, carried between calls (derive/tableaux.py DP_DENSE)", [
    Field("valid", 1, "1: the fields below continue the state x_out the last call wrote; else start afresh"),
    Field("ahead", 1, "how far the integrator's own time is ahead of the state's, s (>= 0)"),
    Field("h_last", 1, "length of the last accepted substep, s"),
    Field("z", XS.size, "the integrator's own [x, Omega], at the state's time + ahead"),
    Field("f", XS.size, "d/dt of z: the next substep's first stage (FSAL)"),
    Field("x_out", STATE.size, "the state the last call wrote"),
    Field("coef", 5 * XS.size, "the last substep's dense-output coefficients Y0..Y4, row-major (5, XS)"),
    Field("lead0", 1, "the lead at the last accepted substep (or where the count restarted), s: ahead is "
          "lead0 - passed dt, one rounding, while that holds bitwise (an output skip costs O(1), split-invariant)"),
    Field("passed", 1, "output steps of dt since lead0 (an integer, as a double)"),
])

LAYOUTS = (STATE, PARAM, MODEL, XS, EULER, WCOEF, DENSE)

# Model kinds: bits of MODEL.kind.
KINDS = (("JOINT", 1, "world-anchored spherical joint: p_w, v_w follow from q, omega"),
         ("WHEELS", 2, "reaction wheels: up to WHEELS_MAX on the columns of A_b (wheels<WHEELS_MAX>_body_rhs), Omega "
          "integrated, motor torques saturated"))
CONSTANTS = (("WHEELS_MAX", WHEELS_MAX, "wheel slots per body (XS.Omega, MODEL.J, the columns of MODEL.A_b)"),
             ("WHEELS_BODY_AXES", WHEELS_BODY_AXES, "wheels of the default layout: the body x, y, z axes, A_b = [I | 0]"),
             ("WHEELS_BOUND_SIZE", 1 + WHEELS_MAX, "factors of a wheeled row's momentum bound, [|I_p|_F, J_i |a_i|] "
              "(derive/growth_bound.py)"),
             ("QUAT_RATE_SCALE", 0.5, "dq/dt = QUAT_RATE_SCALE q (x) [omega_b, 0] (rigid_body_rates_free_c returns the "
              "product; a step folds the scale into its dt; checked in derive/rigid_body.py)"),
             ("QUAT_RENORM_EPS_MAX", 2.0 ** -18, "|eps| = ||q|^2 - 1| up to which quat_renormalize_near_unit leaves "
              "|q| within 2^-53 of 1 by its series alone (checked in derive/quaternion.py); beyond it, q / |q|"))


def print_c() -> str:
    """generated/layout.h."""
    out = [f"/* {HEADER} */", "/* Row layouts of the arrays the step loop exchanges with Python (float64 rows):",
           "   LV_<ROW>_<FIELD> is the offset of a field in its row, LV_<ROW>_<FIELD>_LEN its length (vector",
           "   fields), LV_<ROW>_SIZE the row length. */",
           "#ifndef LAVENDERSIM_LAYOUT_H", "#define LAVENDERSIM_LAYOUT_H", ""]
    for lay in LAYOUTS:
        out.append(f"/* {lay.title} ({lay.size}) */")
        for f in lay.fields:
            out.append(f"#define LV_{lay.prefix}_{f.name.upper()} {lay.offset(f.name)}  /* [{f.size}] {f.doc} */")
            if f.size > 1:
                out.append(f"#define LV_{lay.prefix}_{f.name.upper()}_LEN {f.size}")
        out.append(f"#define LV_{lay.prefix}_SIZE {lay.size}")
        out.append("")
    out.append("/* bits of the model row's kind */")
    out.append("enum {")
    out.extend(f"    LV_KIND_{n} = {v},  /* {doc} */" for n, v, doc in KINDS)
    out.append("};")
    out.extend(f"#define LV_{n} {v}  /* {doc} */" for n, v, doc in CONSTANTS)
    axes = ", ".join(f"{float(a)!r}" for a in on_axes(WHEELS_MAX))
    out.append(f"#define LV_WHEELS_ON_AXES_A_B {{{axes}}}  /* MODEL.A_b of the default layout, [I | 0] */")
    out.append("/* the printed kernels of every wheeled body (derive/wheel_layout.py, N = WHEELS_MAX) */")
    out.extend(f"#define LV_WHEELS_{part.upper()} lv_wheels{WHEELS_MAX}_{part}"
               for part in ("coefficients", "body_rhs_c", "on_axes_rhs_c", "motor", "momentum", "total_momentum",
                            "momentum_bound_factors", "momentum_bound"))
    out += ["", "#endif", ""]
    return "\n".join(out)


def on_axes(n: int) -> sp.Matrix:
    """A_b of the default layout, three wheels on the body x, y, z axes and n − 3 padded slots: [I | 0] (3×n)."""
    return sp.eye(3).row_join(sp.zeros(3, n - 3))


def print_python() -> str:
    """generated/layout.py."""
    out = [f'"""{HEADER}', "", "Row layouts of the arrays the backends exchange (float64 rows): for each row a slice per",
           "vector field (and <ROW>_<FIELD>_LEN, its length), an index per scalar field, <ROW>_SIZE, and",
           "<ROW>_LAYOUT (field -> slice).", '"""', ""]
    for lay in LAYOUTS:
        out.append(f"# {lay.title}")
        for f in lay.fields:
            o = lay.offset(f.name)
            val = str(o) if f.size == 1 else f"slice({o}, {o + f.size})"
            out.append(f"{lay.prefix}_{f.name.upper()} = {val}  # [{f.size}] {f.doc}")
            if f.size > 1:
                out.append(f"{lay.prefix}_{f.name.upper()}_LEN = {f.size}")
        out.append(f"{lay.prefix}_SIZE = {lay.size}")
        items = ", ".join(f"{f.name!r}: slice({lay.offset(f.name)}, {lay.offset(f.name) + f.size})" for f in lay.fields)
        out.append(f"{lay.prefix}_LAYOUT = {{{items}}}")
        out.append("")
    out.append("# bits of the model row's kind")
    out.extend(f"KIND_{n} = {v}  # {doc}" for n, v, doc in KINDS)
    out.extend(f"{n} = {v}  # {doc}" for n, v, doc in CONSTANTS)
    out.append("")
    return "\n".join(out)
