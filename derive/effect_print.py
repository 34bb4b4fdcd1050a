"""Printing of effect declarations beyond their kernels: the C dispatch, the NumPy dispatch, the
Python metadata module and the EQUATIONS.md tables. Built-in effects and user effects are printed
by the same functions (derive.codegen and derive.user call them).

Every effect is printed as an *accumulating* function of one calling convention,

    apply(p, x, v_w, m, I_b, F, tau)      (C: adds into F[3], tau[3]; NumPy: returns (F or None, tau or None))

p the effect's parameters (its row after [code, body]), x the body state, v_w the COM velocity the
effect sees, m and I_b the body's mass and principal moments: the state offsets come from
derive.layout.STATE, the parameter offsets from the declaration.
"""
from __future__ import annotations

import pprint
from collections.abc import Sequence

from . import effect as E
from . import effect_fuse, effect_fuse_user
from .effect_decay import decay_rate
from .printers import NpPrinter
from .layout import STATE

C_ARGS = ("const double *p, const double *x, const double *v_w, double m, const double *I_b, "
          "double *F, double *tau")


def c_args(real: str = "double") -> str:
    """The effect calling convention's C parameters in precision `real` (C_ARGS for double)."""
    return C_ARGS.replace("double", real)


def _in_state(name: str) -> bool:
    return any(f.name == name for f in STATE.fields)


def _c_arg(decl: E.EffectDecl, a) -> str:
    """C expression passed for kernel input a of an effect kernel."""
    if a.name in ("v_w", "m", "I_b"):
        return a.name
    if _in_state(a.name):
        return f"x + {STATE.offset(a.name)} /* LV_STATE_{a.name.upper()} */"
    o = decl.offsets()[a.name]
    return f"p[{o}]" if a.shape == () else f"p + {o}"


def c_effect_functions(decl: E.EffectDecl, prefix: str, fn_name: str, storage: str, real: str = "double",
                       body: bool = False) -> list[str]:
    """The accumulating C function of one effect (calls its kernel, adds its outputs), in precision `real`; body:
    its body-frame form (effect_<name>_b: the torque is added to tau in the body frame)."""
    k = decl.body_kernel() if body else decl.kernel()
    outputs = decl.body_outputs if body else decl.outputs
    assert k is not None and outputs is not None     # body: only for effects with a body-frame form
    used = {a.name for a in k.inputs}
    lines = [f"/* {decl.name}: adds {' and '.join(n for n, _ in outputs)} for one body. "
             f"p = [{', '.join(f'{p.name}({p.size})' for p in decl.params)}] */",
             f"{storage}void {fn_name}({c_args(real)})", "{"]
    lines += [f"    {real} {n}[3];" for n, _ in outputs]
    unused = [n for n in ("p", "x", "v_w", "m", "I_b") if n not in used and not (n == "x" and used & {"p_w", "q", "omega_b"})
              and not (n == "p" and decl.params)]
    unused += [n for n, outs in (("F", (E.OUT_FORCE,)), ("tau", (E.OUT_TORQUE, E.OUT_TORQUE_B)))
               if not set(outs) & set(dict(outputs))]
    if unused:
        lines.append("    " + " ".join(f"(void){n};" for n in unused))
    args = [_c_arg(decl, a) for a in k.inputs] + [n for n, _ in outputs]
    lines.append(f"    {prefix}{k.name}({', '.join(args)});")
    for n, _ in outputs:
        acc = "F" if n == E.OUT_FORCE else "tau"
        lines.append("    " + " ".join(f"{acc}[{i}] += {n}[{i}];" for i in range(3)))
    lines.append("}")
    return lines


def c_header(effects: list[tuple[int, E.EffectDecl]]) -> list[str]:
    """kernels.h: effect table layout, codes, the calling convention and the dispatch prototypes."""
    h = ["/* ---- Scene effects (derive/effects.py): effect table layout, codes and dispatch ---------------- */",
         f"#define LV_EFFECT_ROW_CODE {E.ROW_CODE}     /* an effect table row: [code, body, parameters...] */",
         f"#define LV_EFFECT_ROW_BODY {E.ROW_BODY}     /* the body index, or -1 for every body */",
         f"#define LV_EFFECT_ROW_PARAMS {E.ROW_PARAMS}   /* the effect's parameters start here */",
         f"#define LV_EFFECT_ROW_MIN_PARAMS {E.ROW_MIN_PARAMS} /* a row holds at least this many parameters */",
         f"#define LV_EFFECT_USER_BASE {E.USER_CODE_BASE} /* codes of user effects (loaded at run time) start here */",
         f"#define LV_EFFECT_ABI {E.ABI_VERSION}          /* version of the calling convention below */",
         f"#define LV_EFFECT_USES_V {E.FLAG_USES_V}       /* flag: the effect reads v_w */",
         f"#define LV_EFFECT_USES_OMEGA {E.FLAG_USES_OMEGA}   /* flag: the effect reads omega_b */",
         f"#define LV_EFFECT_FORCE {E.FLAG_FORCE}        /* flag: the effect adds a force */",
         f"#define LV_EFFECT_USES_STATE {E.FLAG_USES_STATE}   /* flag: the effect reads a state value (else constant) */",
         f"#define LV_EFFECT_TORQUE_W {E.FLAG_TORQUE_W}    /* flag: the effect declares a world-frame torque */",
         f"#define LV_EFFECT_TORQUE_B {E.FLAG_TORQUE_B}    /* flag: its torque is declared in the body frame only (lv_effect_apply_b) */"]
    for code, d in effects:
        h.append(f"#define LV_EFFECT_{d.name.upper()} {code} /* p = [{', '.join(f'{p.name}({p.size})' for p in d.params)}] */")
    h += ["/* Every built-in effect code above, for a dispatch a stepping loop writes once: X(code) each. */",
          "#define LV_EFFECT_BUILTINS(X) " + " ".join(f"X(LV_EFFECT_{d.name.upper()})" for _, d in effects)]
    h += ["/* An effect adds its force at the COM (F, world, N) and torque about it (tau, world, N·m) for one",
          "   body: p its parameters, x the body state, v_w the COM velocity it sees (the state's, or a joint's",
          "   kinematic one), m and I_b the body's mass and principal moments. */",
          f"typedef void (*lv_effect_fn)({C_ARGS});",
          f"#define LV_EFFECT_TILE {E.TILE_LANES} /* lanes per row of a SIMD tile (the tile form below) */",
          "/* The tile form of an effect: lanes b0 .. b1-1 of a struct of arrays (lane b of row k at [k][b]): x the",
          "   states (LV_STATE_SIZE rows), p the effect's parameters (a row each), m the masses, I_b the principal",
          "   moments (3 rows); adds into F and tau (3 rows each), each lane as lv_effect_fn adds for one body (v_w: the",
          "   state's). User libraries export one per instruction set: lvu_effect_tile<LV_EFFECT_TILE>_<name>_<isa>. */",
          "typedef void (*lv_effect_tile_fn)(long b0, long b1, const double (*x)[LV_EFFECT_TILE], "
          "const double (*p)[LV_EFFECT_TILE], const double *m, const double (*I_b)[LV_EFFECT_TILE], "
          "double (*F)[LV_EFFECT_TILE], double (*tau)[LV_EFFECT_TILE]);",
          "/* The dispatch, static inline int lv_effect_apply(int code, <the arguments above>), is defined in",
          "   kernels.c (compile kernels.c into the translation unit that steps, so it inlines): it adds built-in",
          "   effect `code`'s force and torque and returns 0, or returns -1 for a code that is not a built-in",
          "   effect (then nothing is added: the caller reports it). lv_effect_apply_b (the same arguments) is the",
          "   dispatch of a plain body whose torques are all declared in the body frame (LV_EFFECT_TORQUE_B, no",
          "   LV_EFFECT_TORQUE_W): it adds such an effect's torque to tau in the body frame, else as lv_effect_apply. */",
          "/* Built-in effect `code`: its number of parameters, its LV_EFFECT_USES_* flags, its name; -1 (NULL)",
          "   for a code that is not a built-in effect. */",
          "int lv_effect_n_params(int code);", "int lv_effect_flags(int code);", "const char *lv_effect_name(int code);"]
    return h + effect_fuse.c_header(effects) + [""]


def _switch(signature: str, effects, value, default: str) -> list[str]:
    out = [signature, "{", "    switch (code) {"]
    for code, d in effects:
        out.append(f"    case LV_EFFECT_{d.name.upper()}: return {value(d)};")
    out += [f"    default: return {default};", "    }", "}", ""]
    return out


def c_source(effects: list[tuple[int, E.EffectDecl]], prefix: str) -> list[str]:
    """kernels.c: each built-in effect's accumulating function and the generated dispatch."""
    c = ["/* ---- Scene effects: accumulating functions and dispatch -------------------------------------- */"]
    for _, d in effects:
        c += c_effect_functions(d, prefix, f"lv_effect_acc_{d.name}", "static inline ") + [""]
    c += ["/* Add built-in effect `code`'s force and torque; 0, or -1 for a code that is not a built-in effect. */",
          f"static inline int lv_effect_apply(int code, {C_ARGS})", "{", "    switch (code) {"]
    for _, d in effects:
        c.append(f"    case LV_EFFECT_{d.name.upper()}: lv_effect_acc_{d.name}(p, x, v_w, m, I_b, F, tau); return 0;")
    c += ["    default: return -1; /* not a built-in effect: the caller reports it */", "    }", "}", ""]
    body = [d for _, d in effects if d.body_outputs is not None]
    for d in body:
        c += c_effect_functions(d, prefix, f"lv_effect_acc_b_{d.name}", "static inline ", body=True) + [""]
    c += ["/* lv_effect_apply for a plain body whose torques are all body-frame (LV_EFFECT_TORQUE_B): such an effect's",
          "   torque added to tau in the body frame; 0, or -1 for a code that is not a built-in effect. */",
          f"static inline int lv_effect_apply_b(int code, {C_ARGS})", "{", "    switch (code) {"]
    for _, d in effects:
        acc = f"lv_effect_acc_b_{d.name}" if d in body else f"lv_effect_acc_{d.name}"
        c.append(f"    case LV_EFFECT_{d.name.upper()}: {acc}(p, x, v_w, m, I_b, F, tau); return 0;")
    c += ["    default: return -1; /* not a built-in effect: the caller reports it */", "    }", "}", ""]
    c += _switch("int lv_effect_n_params(int code)", effects, lambda d: str(d.n_params), "-1")
    c += _switch("int lv_effect_flags(int code)", effects, lambda d: str(d.flags), "-1")
    c += _switch("const char *lv_effect_name(int code)", effects, lambda d: f'"{d.name}"', "0")
    return c


def c_source_real(effects: list[tuple[int, E.EffectDecl]], prefix: str, real: str) -> list[str]:
    """The built-in effects' accumulating functions and their dispatch (static inline int
    <prefix>effect_apply(int code, ...)) in precision `real` (float for kernels_f32.c); the codes, parameter
    counts and flags are kernels.h's."""
    c = [f"/* ---- Scene effects in {real}: accumulating functions and dispatch ---------------------------- */"]
    for _, d in effects:
        c += c_effect_functions(d, prefix, f"{prefix}effect_acc_{d.name}", "static inline ", real) + [""]
    c += ["/* Add built-in effect `code`'s force and torque; 0, or -1 for a code that is not a built-in effect. */",
          f"static inline int {prefix}effect_apply(int code, {c_args(real)})", "{", "    switch (code) {"]
    for _, d in effects:
        c.append(f"    case LV_EFFECT_{d.name.upper()}: {prefix}effect_acc_{d.name}(p, x, v_w, m, I_b, F, tau); return 0;")
    c += ["    default: return -1; /* not a built-in effect: the caller reports it */", "    }", "}", ""]
    return c


TILE_ISAS = ("base", "avx2", "avx512")   # the tile form's copies (LV_ISA_BASE .. LV_ISA_AVX512 of csrc/step.h)


def user_function(decl: E.EffectDecl, body: bool = False) -> str:
    """The name a user effect's accumulating function is exported under: lvu_effect_<name>, its body-frame form
    lvu_effect_<name>_b (derive.user refuses a set where that name is another effect's)."""
    return f"lvu_effect_{decl.name}_b" if body else f"lvu_effect_{decl.name}"


def user_tile_function(decl: E.EffectDecl, isa: str, body: bool = False) -> str:
    """The name of a user effect's tile form at instruction set isa (its body-frame form's: body)."""
    return f"lvu_effect_tile{E.TILE_LANES}_{decl.name}{'_b' if body else ''}_{isa}"


def c_tile_function(decl: E.EffectDecl, body: bool = False) -> list[str]:
    """A user effect's tile form (kernels.h's lv_effect_tile_fn): its accumulating function lane by lane over rows
    of E.TILE_LANES doubles, defined once per instruction set (LVU_TILE_COPIES) so that the compiler vectorizes the
    lane loop at each width; flatten inlines the effect and its kernel into the loop. body: the tile form of its
    body-frame form (the torque added to tau in the body frame)."""
    outputs = decl.body_outputs if body else decl.outputs
    assert outputs is not None
    outs = [("F", "F") if n == E.OUT_FORCE else ("tau", "tau") for n, _ in outputs]
    n, body_lines = E.TILE_LANES, []
    rows = f"(*{{}})[{n}]"
    body_lines.append(f"    for (b = b0; b < b1; b++) {{")
    body_lines.append(f"        double xl[{STATE.size}], pl[{max(decl.n_params, 1)}], il[3], F_l[3] = {{0, 0, 0}}, "
                "tau_l[3] = {0, 0, 0};")
    body_lines.append(f"        for (i = 0; i < {STATE.size}; i++) xl[i] = x[i][b];")
    if decl.n_params:
        body_lines.append(f"        for (i = 0; i < {decl.n_params}; i++) pl[i] = p[i][b];")
    body_lines.append("        for (i = 0; i < 3; i++) il[i] = I_b[i][b];")
    for acc, _ in outs:
        body_lines.append(f"        for (i = 0; i < 3; i++) {acc}_l[i] = {acc}[i][b];")
    body_lines.append(f"        {user_function(decl, body)}(pl, xl, xl + {STATE.offset('v_w')}, m[b], il, F_l, tau_l);")
    for acc, _ in outs:
        body_lines.append(f"        for (i = 0; i < 3; i++) {acc}[i][b] = {acc}_l[i];")
    body_lines.append("    }")
    args = (f"long b0, long b1, const double {rows.format('x')}, const double {rows.format('p')}, const double *m, "
            f"const double {rows.format('I_b')}, double {rows.format('F')}, double {rows.format('tau')}")
    macro = f"LVU_TILE_{decl.name.upper()}{'_B' if body else ''}"
    lines = [f"#define {macro}(SUFFIX, ATTR) \\",
             f"LV_EXPORT ATTR LVU_FLATTEN void {user_tile_function(decl, '', body)}##SUFFIX({args}) \\",
             "{ \\", "    long b; \\", "    int i; \\"]
    lines += [ln + " \\" for ln in body_lines] + ["}", f"LVU_TILE_COPIES({macro})"]
    what = f"{decl.name}'s body-frame form" if body else decl.name
    return [f"/* {what} over tile lanes (one copy per instruction set) */"] + lines


def c_user_source(effects: list[E.EffectDecl], prefix: str) -> list[str]:
    """A user set's exported effect functions (lvu_effect_<name>; lvu_effect_<name>_b, the body-frame form of an
    effect that declares torque_b), their tile forms and its ABI marker."""
    c = ["/* ---- User effects: exported accumulating functions (called by lavendersim's C stepping loop) --- */",
         '#if defined(__GNUC__) || defined(__clang__)', '#define LV_EXPORT __attribute__((visibility("default")))',
         "#else", "#define LV_EXPORT", "#endif",
         f"LV_EXPORT const int lvu_abi_version = {E.ABI_VERSION};", ""]
    for d in effects:
        c += c_effect_functions(d, prefix, user_function(d), "LV_EXPORT ") + [""]
        if d.body_outputs is not None:   # FLAG_TORQUE_B: its body-frame form, for plain bodies of body-frame torques
            c += c_effect_functions(d, prefix, user_function(d, True), "LV_EXPORT ", body=True) + [""]
    if effects:
        c += ["/* ---- The effects' tile forms (lv_effect_tile_fn), for lavendersim's SIMD tiles ---------------- */",
              "#if (defined(__GNUC__) || defined(__clang__)) && defined(__x86_64__)",
              "#define LVU_TILE_COPIES(DEF) DEF(base, ) DEF(avx2, __attribute__((target(\"avx2\")))) "
              "DEF(avx512, __attribute__((target(\"avx512f\"))))",
              "#else", "#define LVU_TILE_COPIES(DEF) DEF(base, )", "#endif",
              "#if defined(__GNUC__) || defined(__clang__)", "#define LVU_FLATTEN __attribute__((flatten))",
              "#else", "#define LVU_FLATTEN", "#endif", ""]
        for d in effects:
            c += c_tile_function(d) + [""]
            if d.body_outputs is not None:
                c += c_tile_function(d, body=True) + [""]
        c += effect_fuse_user.c_fused_tiles(effects, user_function)
    return c


def _np_arg(decl: E.EffectDecl, a) -> str:
    if a.name in ("v_w", "m", "I_b"):
        return a.name
    if _in_state(a.name):
        sl = STATE.slice(a.name)
        return f"x[..., {sl.start}:{sl.stop}]"
    o = decl.offsets()[a.name]
    return f"p[..., {o}]" if a.shape == () else f"p[..., {o}:{o + a.size}]"


# the rest of an effect apply function's numpydoc docstring (after its p)
_NP_APPLY_DOC = [
    "    x : array_like, shape (n, 13)", "        Body states [p_w, q (x, y, z, w), v_w, omega_b] the effect acts on.",
    "    v_w : array_like, shape (n, 3)", "        COM velocities it sees, world frame, m/s.",
    "    m : array_like, shape (n,)", "        Masses, kg.",
    "    I_b : array_like, shape (n, 3)", "        Principal moments, body frame, kg·m².",
    "", "    Returns", "    -------",
    "    F_w : ndarray, shape (n, 3) or None", "        Force at the COM, world frame, N (None: the effect has none).",
    "    tau_w : ndarray, shape (n, 3) or None", "        Torque about the COM, world frame, N·m (None: the effect has none).",
]


_NP_OUT_DOC = ["    out : (ndarray, ndarray), optional",
               "        Arrays (n, 3) the force and the torque are written into (the one it has), as the kernel's out=."]


def _np_apply_doc(d: E.EffectDecl, title: str, body: bool = False) -> list[str]:
    """The numpydoc docstring of an effect's apply function (body: its body-frame form, tau_b second)."""
    params_end = _NP_APPLY_DOC.index("    Returns") - 1    # out is the last parameter, before Returns
    ret = _NP_APPLY_DOC[params_end:]
    if body:
        ret = ret[:-2] + ["    tau_b : ndarray, shape (n, 3) or None",
                          "        Torque about the COM, body frame, N·m (None: the effect has none)."]
    return [f'    """{title}', "", "    Parameters", "    ----------", "    p : array_like, shape (n, n_params)",
            f'        The effect\'s parameters per row: [{", ".join(f"{p.name}({p.size})" for p in d.params)}].',
            *_NP_APPLY_DOC[:params_end], *_NP_OUT_DOC, *ret, '    """']


def numpy_dispatch(effects: list[tuple[int | None, E.EffectDecl]]) -> list[str]:
    """NumPy: one accumulating function per effect, EFFECT_APPLY by name, and (built-ins) dispatch by code."""
    out = ["# ---- Scene effects: apply(p, x, v_w, m, I_b) -> (F_com_w or None, tau_com_w or None), rows",
           "# vectorized over a leading axis (one row per body the effect acts on). p: the effect's parameters",
           "# (its row after [code, body]); x: the body states; v_w: the COM velocities it sees; m, I_b.", ""]
    for _, d in effects:
        k = d.kernel()
        outs = dict(d.outputs)
        out.append(f"def effect_apply_{d.name}(p, x, v_w, m, I_b, *, out=None):")
        out += _np_apply_doc(d, f"{d.name}: {d.summary}.")
        # out (F_w, tau_w): the buffers its outputs are written into (the kernel's out=), e.g. struct-of-arrays
        sel = "out" if len(outs) == 2 else "out and out[:1]" if E.OUT_FORCE in outs else "out and out[1:]"
        call = f"{k.name}({', '.join(_np_arg(d, a) for a in k.inputs)}, out={sel})"
        if len(outs) == 2:
            out.append(f"    return {call}")
        elif E.OUT_FORCE in outs:
            out.append(f"    return {call}, None")
        else:
            out.append(f"    return None, {call}")
        out += ["", ""]
    out.append("# effect name -> its apply function")
    out.append("EFFECT_APPLY = {")
    out += [f"    {d.name!r}: effect_apply_{d.name}," for _, d in effects]
    out.append("}")
    body = [d for _, d in effects if d.body_outputs is not None]
    if body:
        out += ["", ""]
        for d in body:
            kb, bo = d.body_kernel(), d.body_outputs
            assert kb is not None and bo is not None
            outs = dict(bo)
            sel = "out" if len(outs) == 2 else "out and out[1:]"
            call = f"{kb.name}({', '.join(_np_arg(d, a) for a in kb.inputs)}, out={sel})"
            out += [f"def effect_apply_b_{d.name}(p, x, v_w, m, I_b, *, out=None):",
                    *_np_apply_doc(d, f"{d.name}, its body-frame form: as effect_apply_{d.name}, the torque in the body "
                                   "frame\n    (a plain body whose torques are all body-frame, FLAG_TORQUE_B).", body=True),
                    f"    return {call}" if len(outs) == 2 else f"    return None, {call}", "", ""]
    out.append("# effect name -> its body-frame form (FLAG_TORQUE_B), for plain bodies whose torques are all body-frame")
    out.append("EFFECT_APPLY_B = {")
    out += [f"    {d.name!r}: effect_apply_b_{d.name}," for d in body]
    out.append("}")
    coded = [(c, d) for c, d in effects if c is not None]
    affine = [(d, ak) for _, d in coded if (ak := d.affine_kernel()) is not None]
    if coded:
        out += ["", "", "# built-in effect name -> its decoupled force's (F0_w (n, 3), k (n,)) from p (n, n_params) and m (n,)",
                "# (derive/effect.py affine_force: F = F0 - k v_W; the effects with a force and no FLAG_COUPLED)",
                "EFFECT_AFFINE = {"]
        out += [f"    {d.name!r}: lambda p, m: {k.name}({', '.join(_np_arg(d, a) for a in k.inputs)})," for d, k in affine]
        out += ["}", ""]
        out += ["# built-in effect code -> its apply function", "EFFECT_APPLY_BY_CODE = {"]
        out += [f"    {c}: effect_apply_{d.name}," for c, d in coded]
        out += ["}", "", "",
                "def effect_apply(code, p, x, v_w, m, I_b):",
                '    """Dispatch by built-in effect code; a code that is not one raises ValueError (never a no-op).',
                "", "    Parameters", "    ----------", "    code : int", "        A built-in effect code.",
                "    p : array_like, shape (n, n_params)", "        The effect's parameters per row.",
                *_NP_APPLY_DOC, '    """',
                "    fn = EFFECT_APPLY_BY_CODE.get(code)",
                "    if fn is None:",
                "        raise ValueError(f\"effect code {code!r} is not a built-in effect (built-in codes: "
                + ", ".join(f"{c} {d.name}" for c, d in coded) + ")\")",
                "    return fn(p, x, v_w, m, I_b)"]
    return out


def meta_entry(code: int | None, d: E.EffectDecl) -> dict:
    """The Python metadata of one effect (plain data: printed as a literal, read by lavendersim.effects)."""
    params, off = [], d.offsets()
    for p in d.params:
        params.append({"name": p.name, "shape": tuple(p.shape), "unit": p.unit, "doc": p.doc, "rule": p.rule,
                       "default": p.default, "offset": off[p.name], "upto": p.upto,
                       "frame": p.frame})
    return {"name": d.name, "code": code, "kind": d.kind, "summary": d.summary, "params": tuple(params),
            "n_params": d.n_params,
            "outputs": tuple("F_w" if n == E.OUT_FORCE else "tau_w" for n, _ in d.outputs),
            "state_inputs": tuple(d.state_inputs) if d.kind == "force" else (),
            "flags": d.flags if d.kind == "force" else 0,
            "kernel": d.kernel_name if d.kind == "force" else None,
            "decay_rate": f"decay_rate_{d.name}" if decay_rate(d) is not None else None}


def meta_module(effects: Sequence[tuple[int | None, E.EffectDecl]], header: str, extra: dict | None = None) -> str:
    """A Python module holding the effects' metadata and the table layout constants."""
    lines = [f'"""{header}', "", "Effect metadata printed from the declarations (derive.effect): codes, parameter layout",
             "(shape, unit, rule, default, offset within the row's parameters), outputs, the state values each",
             'effect reads and its flags. lavendersim.effects builds its Effect classes from it."""', "",
             f"ROW_CODE, ROW_BODY, ROW_PARAMS = {E.ROW_CODE}, {E.ROW_BODY}, {E.ROW_PARAMS}",
             f"ROW_MIN_PARAMS = {E.ROW_MIN_PARAMS}", f"USER_CODE_BASE = {E.USER_CODE_BASE}",
             f"ABI_VERSION = {E.ABI_VERSION}",
             f"FLAG_USES_V, FLAG_USES_OMEGA, FLAG_FORCE = {E.FLAG_USES_V}, {E.FLAG_USES_OMEGA}, {E.FLAG_FORCE}",
             f"FLAG_USES_STATE = {E.FLAG_USES_STATE}",
             f"FLAG_TORQUE_W, FLAG_TORQUE_B = {E.FLAG_TORQUE_W}, {E.FLAG_TORQUE_B}",
             f"TILE_LANES, TILE_ISAS = {E.TILE_LANES}, {TILE_ISAS!r}  # a user effect's tile forms: "
             "lvu_effect_tile<TILE_LANES>_<name>_<isa>"]
    for k, v in (extra or {}).items():
        lines.append(f"{k.upper()} = {v!r}")
    lines += ["", "EFFECTS = ("]
    for code, d in effects:
        text = pprint.pformat(meta_entry(code, d), width=110, sort_dicts=False)
        lines.append("    " + text.replace("\n", "\n    ") + ",")
    lines.append(")")
    decays = [(d, decay_rate(d)) for _, d in effects]
    decays = [(d, r) for d, r in decays if r is not None]
    if decays:
        lines += ["", "", "# ---- decay rates (derive/effect_decay.py): max(D) of an effect whose accelerations are -D (v_w, omega_b)"]
        for d, r in decays:
            lines += ["", ""] + _decay_function(d, r)
    return "\n".join(lines) + "\n"


def _decay_function(d: E.EffectDecl, rate) -> list[str]:
    """The printed decay rate of one effect: (p (n, n_params), m (n,), I_b (n, 3)) -> (n,), 1/s."""
    off = d.offsets()
    body = [f"    {p.name} = p[..., {off[p.name]}]" for p in d.params if p.symbol in rate.free_symbols]
    body += [f"    {s} = I_b[..., {i}]" for i, s in enumerate(E.STATE.I_b) if s in rate.free_symbols]
    return [f"def decay_rate_{d.name}(p, m, I_b):",
            f'    """{d.name}: the rate max(D) of its linear decay, 1/s (p: (n, n_params) parameter rows; m: (n,) kg;',
            '    I_b: (n, 3) principal moments, kg·m²). An explicit step is stable while rate * dt stays below the',
            '    integrator\'s REAL_AXIS_STABILITY (generated/tableaux.py)."""',
            "    import numpy",
            "",
            *body,
            f"    return numpy.asarray({NpPrinter().doprint(rate)}, dtype=float) + numpy.zeros(numpy.shape(m))"]


def markdown_params(d: E.EffectDecl, code: int | None) -> list[str]:
    """EQUATIONS.md: an effect's code, parameter table and what it reads."""
    what = "user effect (code assigned when loaded)" if code is None else f"code {code}"
    reads = ", ".join(f"`{s}`" for s in d.state_inputs) or "no state"
    out = [f"Effect `{d.name}` ({d.kind}, {what}); "
           + (f"reads {reads}" + ("; velocity-dependent (splitting kicks by explicit midpoint)"
                                  if d.flags & (E.FLAG_USES_V | E.FLAG_USES_OMEGA) else "")
              if d.kind == "force" else "its equations are the kernels of its model") + ".", "",
           "| parameter | shape | unit | rule | default | offset | meaning |", "|---|---|---|---|---|---|---|"]
    off = d.offsets()
    for p in d.params:
        shape = "scalar" if not p.shape else "[" + ("≤" if p.upto else "") + "×".join(map(str, p.shape)) + "]"
        default = "—" if p.default is None else f"`{p.default}`"
        out.append(f"| `{p.name}` | {shape} | {p.unit or '—'} | {p.rule} | {default} | {off[p.name]} | {p.doc} |")
    out.append("")
    return out
