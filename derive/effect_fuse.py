"""The fused effect tiles' patterns (csrc/batch_simd.h), derived from the effect declarations and printed into
kernels.h as X-macros.

A tile of plain bodies whose effects read the state steps either in stage passes (one lane loop per effect and
stage) or, when its effects are a *pattern* after a run of effects that read no state (their sums taken once per
call), on a fused tile: the plain tile's lane loop, each lane's whole RK4 step in registers, with the pattern's
generated effect functions inlined (their codes known to the compiler). A pattern is an ordered sequence of up to
FUSED_MAX distinct built-in effects that read the state (FLAG_USES_STATE): their printed kernels are closed-form
expressions of one body's numbers, so each is a lane expression. A user effect (its tile form, a call into the
user's library) never fuses.

A pattern's tile kinds are the right-hand-side classes a body with the pattern can have (tile_kind: which of
FORCE, TORQUE_W, TORQUE_B its effects' flags carry; printed as a table for csrc/step.c's rhs_class and the NumPy
backend's rhs_classes), whatever the effects that read no state before it
add: batch_simd.h compiles one fused tile per (kind, pattern) of this table, in each kind's effect tile stepper.
"""
from __future__ import annotations

from collections.abc import Sequence
from typing import NamedTuple
from itertools import permutations

from . import effect as E
from .rigid_body import CONST_DP, CONST_DV, CONST_SIZE, CONST_TAU, FLOW_SIZE, INC_C, INC_HQ, INC_SCALE_SIZE

FUSED_MAX = 2   # effects per pattern (batch_simd.h's fused tile loads this many parameter rows)
# Tile kinds of plain bodies with effects (csrc/step.c's LV_RHS_* names, batch_simd.h's LV_TILE_RHS_<kind>).
TILE_KINDS = ("TORQUE", "FULL", "FORCE", "BODY", "BODY_F")


# The effect flags that choose a plain body's right-hand-side class; bit j of an index of the printed table
# (kinds_by_flags) says whether RHS_BITS[j] is among the body's flags.
RHS_BITS = (E.FLAG_FORCE, E.FLAG_TORQUE_W, E.FLAG_TORQUE_B)


class RhsCall(NamedTuple):
    """What a plain body of one tile kind runs after its effects' sums f (force, world) and t (torque): the kernel and
    its arguments, named from x (the state), mass, cf (the Euler coefficients c_b), f, t, zero (a zero vector) and out
    (d/dt of x); accel: f is turned into a_w = F/m first (linear_acceleration, in place); body_frame: t sums the effects'
    body-frame forms (the body dispatch). pipeline: the kernel and its words as Sim.pipeline names them."""
    kernel: str
    args: tuple[str, ...]
    accel: bool
    body_frame: bool
    pipeline: str
    inc: tuple[str, tuple[str, ...]]   # the kind's scaled increments kernel and its arguments (sc: the constants S)


# The one statement of the kind -> right-hand side rule, printed into kernels.h (LV_RHS_CALL_<kind>,
# LV_RHS_BODY_FRAME_<kind>: csrc/step.c's plain_rhs, batch_simd.h's effect tiles, the user's fused tiles of
# effect_fuse_user) and effects_meta (RHS_KERNELS: Sim.pipeline). TORQUE runs the torque-only kernel, bitwise
# rigid_body_rhs on a zero force (the NumPy backend runs that one: the pipeline names it); BODY's a_w is zero, bitwise
# the +0/m of the NumPy backend; BODY's increments have no force (rigid_body_increments_torque_b_c: H_v is -0, the
# additive identity, so v_W stays v_W bitwise through the stages and a compiler keeps it).
RHS_OF_KIND = {
    "TORQUE": RhsCall("rigid_body_rhs_torque_c", ("x", "cf", "t", "out"), False, False, "rigid_body_rhs (world torques)",
                      ("rigid_body_increments_torque_c", ("x", "sc", "t", "out"))),
    "FULL": RhsCall("rigid_body_rhs_c", ("x", "mass", "cf", "f", "t", "out"), False, False,
                    "rigid_body_rhs (world torques)", ("rigid_body_increments_c", ("x", "sc", "f", "t", "out"))),
    "FORCE": RhsCall("rigid_body_rhs_force_c", ("x", "cf", "f", "out"), True, False,
                     "rigid_body_rhs_force (a force, no torque: a_w = F/m)",
                     ("rigid_body_increments_force_c", ("x", "sc", "f", "out"))),
    "BODY": RhsCall("rigid_body_rhs_body_c", ("x", "cf", "zero", "t", "out"), False, True,
                    "rigid_body_rhs_body (torques declared in the body frame)",
                    ("rigid_body_increments_torque_b_c", ("x", "sc", "t", "out"))),
    "BODY_F": RhsCall("rigid_body_rhs_body_c", ("x", "cf", "f", "t", "out"), True, True,
                      "rigid_body_rhs_body (a force; torques declared in the body frame)",
                      ("rigid_body_increments_body_c", ("x", "sc", "f", "t", "out"))),
}
# The constant kinds (every effect of the body reads no state): kind -> (torque, force). Such a body stages only
# (q, omega_b): with its world torque sum (rigid_body_increments_torque_h) when `torque`, else as a torque-free body
# (rigid_body_increments_free_c); its translation by the constant force's exact flow (translation_flow_constant) when
# `force`, else translation_drift with v_w kept. Printed into kernels.h (LV_CONST_TORQUE_<kind>, LV_CONST_FORCE_<kind>:
# csrc/step.c lv_const_rk4_h) and effects_meta (RHS_CONSTANT: the NumPy backends).
CONSTANT_KINDS = {"TORQUE": (True, False), "FULL": (True, True), "FORCE": (False, True)}
RHS_CALL_PARAMS = ("x", "mass", "cf", "f", "t", "out")   # LV_RHS_CALL_<kind>'s parameters
RHS_INC_PARAMS = ("x", "mass", "sc", "f", "t", "out")    # LV_RHS_INC_<kind>'s parameters


def rhs_inc_c(kind: str) -> str:
    """The C expression of kind's scaled increments (RHS_OF_KIND inc: rigid_body_increments*_c, s dt folded into the
    constants sc = rigid_body_increment_scale's S, so the force sum f is not divided: H_v = h_m f) on RHS_INC_PARAMS."""
    kernel, args = RHS_OF_KIND[kind].inc
    parts = [f"(void)({p})" for p in RHS_INC_PARAMS if p not in args]
    state = "(x) + LV_STATE_Q, (x) + LV_STATE_OMEGA_B, (x) + LV_STATE_V_W"   # the kernel's (q, omega_b, v_w)
    a = ", ".join("(const double[3]){0.0, 0.0, 0.0}" if x == "zero" else state if x == "x" else x for x in args)
    return f"({', '.join(parts + [f'lv_{kernel}({a})'])})"


def rhs_call_c(kind: str) -> str:
    """The C expression of kind's right-hand side (RHS_OF_KIND) on the macro parameters RHS_CALL_PARAMS."""
    r = RHS_OF_KIND[kind]
    used = set(r.args) | ({"mass", "f"} if r.accel else set())
    parts = [f"(void)({p})" for p in RHS_CALL_PARAMS if p not in used]
    if r.accel:
        parts.append("lv_linear_acceleration(mass, f, f)")
    args = ", ".join("(const double[3]){0.0, 0.0, 0.0}" if a == "zero" else a for a in r.args)
    parts.append(f"lv_{r.kernel}({args})")
    return f"({', '.join(parts)})"


def tile_kind(flags: int) -> str:
    """The right-hand-side class of a plain body whose effects' flags OR to `flags` (at least one effect): body-frame
    torques only (BODY, BODY_F with a force), no torque (FORCE), world torques (TORQUE, FULL with a force). The one
    statement of the rule: printed as a table (kinds_by_flags) for csrc/step.c's rhs_class and the NumPy backend's
    lavendersim.effects.rhs_classes."""
    force = bool(flags & E.FLAG_FORCE)
    if flags & E.FLAG_TORQUE_B and not flags & E.FLAG_TORQUE_W:
        return "BODY_F" if force else "BODY"
    if not flags & (E.FLAG_TORQUE_W | E.FLAG_TORQUE_B):
        return "FORCE"
    return "FULL" if force else "TORQUE"


def kinds_by_flags() -> tuple[str, ...]:
    """tile_kind of every combination of RHS_BITS: entry i for the flags holding RHS_BITS[j] exactly when bit j of i
    is set (2 ** len(RHS_BITS) entries)."""
    return tuple(tile_kind(sum(b for j, b in enumerate(RHS_BITS) if i >> j & 1)) for i in range(1 << len(RHS_BITS)))


# Where every sum of effect contributions starts (C: kernels.h LV_SUM_START; NumPy: effects_meta.SUM_START): IEEE's
# additive identity -0.0. -0 + x == x bitwise for every x (+0 and -0 included), so a sum from it equals the sum of its
# terms alone (gcc folds the first add away), and a sum of nothing or of -0 terms is -0 (+0 + -0 would give +0).
SUM_START = -0.0


def rhs_c_header() -> list[str]:
    """kernels.h's printed rule: LV_RHS_FLAGS_INDEX(flags), the table index of an OR of effect flags,
    LV_RHS_KINDS_BY_FLAGS(K), the initializer of the table, each kind named K(kind) (kind in TILE_KINDS), and each
    kind's right-hand side (RHS_OF_KIND): LV_RHS_CALL_<kind>, LV_RHS_BODY_FRAME_<kind>, LV_RHS_KINDS(X)."""
    names = {E.FLAG_FORCE: "LV_EFFECT_FORCE", E.FLAG_TORQUE_W: "LV_EFFECT_TORQUE_W", E.FLAG_TORQUE_B: "LV_EFFECT_TORQUE_B"}
    index = " | ".join(f"((((flags) & {names[b]}) != 0) << {j})" for j, b in enumerate(RHS_BITS))
    out = ["/* The right-hand-side class of a plain body with effects, from the OR of their flags (derive/effect_fuse.py",
           "   tile_kind, printed as a table): LV_RHS_KINDS_BY_FLAGS(K)[LV_RHS_FLAGS_INDEX(flags)], K(kind) naming",
           "   each class (TORQUE, FULL, FORCE, BODY, BODY_F). */",
           f"#define LV_RHS_FLAGS_INDEX(flags) ({index})",
           f"#define LV_RHS_KINDS_BY_FLAGS(K) {{{', '.join(f'K({k})' for k in kinds_by_flags())}}}",
           "/* Each class's right-hand side after its effects' sums (derive/effect_fuse.py RHS_OF_KIND):",
           "   LV_RHS_CALL_<kind>(x, mass, cf, f, t, out) on the state x, the mass, the Euler coefficients cf, the sums f",
           "   (force, world; overwritten with a_w = F/m where the class divides) and t (torque), into out = d/dt x;",
           "   LV_RHS_BODY_FRAME_<kind>: 1 when t sums the effects' body-frame forms. LV_RHS_KINDS(X): X(kind) each. */",
           "#define LV_RHS_KINDS(X) " + " ".join(f"X({k})" for k in TILE_KINDS),
           "/* The built-in RK4 steps each class in the scaled-increment form (tableaux.h LV_RK4_SCALED_STEP on the 13",
           "   numbers): LV_RHS_INC_<kind>(x, mass, sc, f, t, out), the increments H = (s dt) d/dt x into out after the",
           "   same sums, sc the body's LV_INC_SCALE_SIZE constants (rigid_body_increment_scale: s dt folded into the",
           "   Euler coefficients, 1/I, q's rate scale and 1/m, once per body and call). */",
           f"#define LV_INC_SCALE_SIZE {INC_SCALE_SIZE}",
           "/* Every sum of effect contributions (force, torque, their constant prefixes) starts at LV_SUM_START, IEEE's",
           "   additive identity (derive/effect_fuse.py SUM_START; NumPy: effects_meta.SUM_START): -0 + x == x bitwise. */",
           f"#define LV_SUM_START ({SUM_START!r})",
           "#define LV_SUM_START3 {LV_SUM_START, LV_SUM_START, LV_SUM_START} /* a 3-vector sum's start */",
           "/* A body whose effects all read no state (the constant kinds) stages only (q, omega_b) (csrc/step.c",
           "   lv_const_rk4_h): LV_CONST_SIZE constants per body and call, S (LV_INC_SCALE_SIZE) at 0, the world torque's",
           "   rigid_body_torque_constants (tau_w, 2 tau_w) at LV_CONST_TAU, constant_acceleration_steps' dv_w, dp_w at",
           "   LV_CONST_DV, LV_CONST_DP; LV_CONST_TORQUE_<kind>:",
           "   q and omega_b take the torque (rigid_body_increments_torque_h; else the torque-free increments),",
           "   LV_CONST_FORCE_<kind>: p and v take translation_flow_constant (else translation_drift, v kept). */",
           f"#define LV_CONST_SIZE {CONST_SIZE}", f"#define LV_CONST_TAU {CONST_TAU}", f"#define LV_CONST_DV {CONST_DV}",
           f"#define LV_CONST_DP {CONST_DP}"]
    for kind, (torque, force) in CONSTANT_KINDS.items():
        out += [f"#define LV_CONST_TORQUE_{kind} {int(torque)}", f"#define LV_CONST_FORCE_{kind} {int(force)}"]
    for kind in TILE_KINDS:
        out += [f"#define LV_RHS_BODY_FRAME_{kind} {int(RHS_OF_KIND[kind].body_frame)}",
                f"#define LV_RHS_CALL_{kind}({', '.join(RHS_CALL_PARAMS)}) {rhs_call_c(kind)}",
                f"#define LV_RHS_INC_{kind}({', '.join(RHS_INC_PARAMS)}) {rhs_inc_c(kind)}"]
    return out


def meta_extra() -> dict:
    """effects_meta.py's printed rule (the NumPy backend's copy of the table): RHS_BITS, RHS_KINDS_BY_FLAGS,
    RHS_KERNELS (each kind's right-hand side as Sim.pipeline names it), the NumPy classes (RHS_CLASSES,
    RHS_CLASS_OF_KIND), how each steps decoupled (RHS_SPLIT_BY_CLASS) and where effect sums start (SUM_START)."""
    return {"rhs_bits": RHS_BITS, "rhs_kinds_by_flags": kinds_by_flags(),
            "rhs_kernels": {k: RHS_OF_KIND[k].pipeline for k in TILE_KINDS},
            "rhs_increments": {k: RHS_OF_KIND[k].inc[0] for k in TILE_KINDS},
            "flag_coupled": E.FLAG_COUPLED, "rhs_split": SPLIT_OF_KIND, "rhs_classes": NUMPY_CLASSES,
            "rhs_class_of_kind": NUMPY_CLASS_OF_KIND, "rhs_split_by_class": split_by_class(),
            "inc_scale_c": (INC_C.start, INC_C.stop), "inc_scale_hq": INC_HQ, "rhs_constant": CONSTANT_KINDS,
            "sum_start": SUM_START}


def _constant_flags(effects: Sequence[tuple[int, E.EffectDecl]]) -> set[int]:
    """Every OR of the flags of a set of built-in force effects that read no state (the empty set's 0 included)."""
    out = {0}
    for _, d in effects:
        if d.kind == "force" and not d.flags & E.FLAG_USES_STATE:
            out |= {f | d.flags for f in out}
    return out


def patterns(effects: Sequence[tuple[int, E.EffectDecl]]) -> list[tuple[int, tuple[int, ...], tuple[str, ...]]]:
    """The fused patterns of the built-in effects [(code, declaration)]: (id from 1, the effect codes in table order,
    the tile kinds it applies to, in TILE_KINDS order), the longer patterns first, each length in code order."""
    fusable = [(c, d) for c, d in effects if d.kind == "force" and d.flags & E.FLAG_USES_STATE]
    extra = _constant_flags(effects)
    out: list[tuple[int, tuple[int, ...], tuple[str, ...]]] = []
    for n in range(FUSED_MAX, 0, -1):
        for seq in permutations(fusable, n):
            flags = 0
            for _, d in seq:
                flags |= d.flags
            kinds = {tile_kind(flags | f) for f in extra}
            out.append((len(out) + 1, tuple(c for c, _ in seq), tuple(k for k in TILE_KINDS if k in kinds)))
    return out


# The tile kinds whose bodies may step decoupled (no effect FLAG_COUPLED): their rotation staged on (q, omega_b) alone,
# torque-free (1: rigid_body_increments_free_c) or under the body-frame torque sums (2: rigid_body_increments_rot_b_c),
# their translation by translation_flow. World torques (TORQUE, FULL) keep the 13-number stages.
SPLIT_OF_KIND = {"TORQUE": 0, "FULL": 0, "FORCE": 1, "BODY": 2, "BODY_F": 2}
# The NumPy backends' right-hand-side classes (lavendersim.effects RHS_FULL, RHS_FORCE, RHS_BODY, RHS_BODY_F): the tile
# kinds with TORQUE merged into FULL (a world torque alone runs rigid_body_rhs_c there on a zero force, bitwise the
# torque-only kernel). Printed into effects_meta: RHS_CLASSES, RHS_CLASS_OF_KIND, RHS_SPLIT_BY_CLASS.
NUMPY_CLASSES = ("FULL", "FORCE", "BODY", "BODY_F")
NUMPY_CLASS_OF_KIND = {k: NUMPY_CLASSES.index("FULL" if k == "TORQUE" else k) for k in TILE_KINDS}


def split_by_class() -> tuple[int, ...]:
    """SPLIT_OF_KIND per NumPy class (NUMPY_CLASSES order): how a decoupled body of the class steps its rotation (0: the
    13-number stages). The kinds a class merges must agree."""
    out = []
    for c, name in enumerate(NUMPY_CLASSES):
        splits = {SPLIT_OF_KIND[k] for k in TILE_KINDS if NUMPY_CLASS_OF_KIND[k] == c}
        if len(splits) != 1:
            raise RuntimeError(f"derive: the kinds of NumPy class {name} step decoupled differently: {sorted(splits)}")
        out.append(splits.pop())
    return tuple(out)


def pattern_split(effects: Sequence[tuple[int, E.EffectDecl]], codes: tuple[int, ...]) -> bool:
    """Whether a pattern's effects all leave translation and rotation decoupled (no FLAG_COUPLED: affine_force)."""
    decl = dict(effects)
    return all(not decl[c].flags & E.FLAG_COUPLED for c in codes)


def affine_c_source(effects: Sequence[tuple[int, E.EffectDecl]]) -> list[str]:
    """kernels.h's lv_effect_affine(code, p, m, F0, k): adds a decoupled built-in effect's F0 (3) and k of its
    printed effect_<name>_affine (F = F0 − k v_W) and returns 0; an effect without a force adds nothing (0); -1 for
    a coupled or unknown code."""
    out = ["/* The decoupled step's force of a built-in effect (derive/effect.py affine_force: F = F0 - k v_W): adds its",
           "   F0 (world, N) into F0 and its rate k (kg/s) into *k; 0, or -1 when the effect couples (FLAG_COUPLED). */",
           "static inline int lv_effect_affine(int code, const double *p, double m, double *F0, double *k)", "{",
           "    double f[3], r;", "    (void)p; (void)m; (void)f; (void)r;", "    switch (code) {"]
    for code, d in effects:
        if d.kind != "force" or d.flags & E.FLAG_COUPLED:
            continue
        name = f"LV_EFFECT_{d.name.upper()}"
        if d.force_w is None:
            out.append(f"    case {name}: return 0;")
            continue
        offs = d.offsets()
        args = ["m"] + [f"p[{offs[q.name]}]" if q.shape == () else f"p + {offs[q.name]}" for q in d.params]
        out.append(f"    case {name}: lv_effect_{d.name}_affine({', '.join(args)}, f, &r); "
                   "F0[0] += f[0]; F0[1] += f[1]; F0[2] += f[2]; *k += r; return 0;")
    return out + ["    default: return -1;", "    }", "}"]


def c_header(effects: Sequence[tuple[int, E.EffectDecl]]) -> list[str]:
    """kernels.h's table of the fused patterns: LV_EFFECT_FUSED(X, ...) every pattern and LV_EFFECT_FUSED_<kind>(X,
    ...) those of one tile kind, each a call X(..., id, n, code_0, ..., code_{FUSED_MAX-1}) (codes past n: 0)."""
    names = {c: f"LV_EFFECT_{d.name.upper()}" for c, d in effects}
    pats = patterns(effects)

    def row(pid: int, codes: tuple[int, ...]) -> str:
        cs = [names[c] for c in codes] + ["0"] * (FUSED_MAX - len(codes))
        return f"X(__VA_ARGS__, {pid}, {len(codes)}, {', '.join(cs)})"

    h = ["/* The fused effect tiles' patterns (derive/effect_fuse.py): after a run of effects that read no state, an",
         "   ordered sequence of up to LV_EFFECT_FUSED_MAX distinct built-in effects that read the state, each a lane",
         "   expression; batch_simd.h steps such a tile with the pattern's effect functions inlined in the plain tile's",
         "   lane loop. X(..., id, n, code_0, code_1): the pattern's id (from 1), its n effect codes in table order (0",
         "   past n). LV_EFFECT_FUSED_<kind>: the patterns a body of that right-hand-side class (step.c's LV_RHS_<kind>)",
         "   can have, whatever the effects before them add. */",
         f"#define LV_EFFECT_FUSED_MAX {FUSED_MAX}",
         f"#define LV_EFFECT_FUSED_COUNT {len(pats)}",
         "#define LV_EFFECT_FUSED(X, ...) " + " ".join(row(p, c) for p, c, _ in pats)]
    for kind in TILE_KINDS:
        h.append((f"#define LV_EFFECT_FUSED_{kind}(X, ...) " + " ".join(row(p, c) for p, c, k in pats if kind in k)).rstrip())
    h += ["/* LV_EFFECT_FUSED_SPLIT_<id>: 1 when the pattern's effects are all decoupled (no FLAG_COUPLED); LV_RHS_SPLIT_<kind>",
          "   how a decoupled body of that kind stages its rotation (0 not split, 1 torque-free, 2 body-frame torques);",
          "   LV_FLOW_SIZE translation_flow_scale's constants; LV_INC_SCALE_C / _HQ: C_b and h_q within S. */",
          f"#define LV_EFFECT_COUPLED {E.FLAG_COUPLED} /* flag: the effect couples translation and rotation */",
          f"#define LV_FLOW_SIZE {FLOW_SIZE}", f"#define LV_INC_SCALE_C {INC_C.start}", f"#define LV_INC_SCALE_HQ {INC_HQ}"]
    h += [f"#define LV_EFFECT_FUSED_SPLIT_{p} {int(pattern_split(effects, c))}" for p, c, _ in pats]
    h += [f"#define LV_RHS_SPLIT_{k} {SPLIT_OF_KIND[k]}" for k in TILE_KINDS]
    return h + rhs_c_header() + affine_c_source(effects)
