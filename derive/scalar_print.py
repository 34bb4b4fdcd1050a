"""Print the kernels for Python floats (generated/kernels_scalar.py): the NumPy backend's path for a few bodies.

Each kernel takes its array inputs as flat sequences of floats (row-major), its scalar inputs as floats, and returns
each array output as a tuple of floats (several outputs as a tuple of those). The expressions are the NumPy
printing's, operation for operation (printers.MathPrinter), so a body's numbers equal the vectorized kernels'.
The effects' accumulating functions follow derive/effect_print.py's convention on the same sequences.
"""
from __future__ import annotations

import sympy as sp

from . import effect as E
from .layout import STATE
from .printers import HEADER, MathPrinter


def _unpack(k, used: set) -> list[str]:
    """One tuple unpacking per array input a kernel reads: its used symbols by name, the others `_`."""
    out, seen = [], set()
    for a in k.inputs:
        if a.shape == () or not any(s in used for s in a.flat):
            continue
        names = []
        for s in a.flat:
            names.append(str(s) if s in used and s not in seen else "_")
            seen.add(s)
        out.append(f"    {', '.join(names)}{',' if len(names) == 1 else ''} = {a.name}")
    return out


def _number(pr: MathPrinter, e) -> str:
    return repr(float(e)) if e.is_Number else pr.doprint(e)


def scalar_kernel(p, pr: MathPrinter) -> list[str]:
    """One kernel (a codegen.Printed) as a Python function on floats."""
    k = p.k
    out = [f"def {k.name}({', '.join(a.name for a in k.inputs)}):", f'    """{k.summary} (floats; see the module)."""']
    out += _unpack(k, p.used)
    out += [f"    {t} = {pr.doprint(e)}" for t, e in p.temps]
    idx, rets = 0, []
    for a in k.outputs:
        items = [_number(pr, sp.sympify(p.reduced[idx + i])) for i in range(a.size)]
        idx += a.size
        rets.append(items[0] if a.shape == () else f"({', '.join(items)}{',' if a.size == 1 else ''})")
    return out + [f"    return {', '.join(rets)}", "", ""]


def _arg(decl: E.EffectDecl, a) -> str:
    if a.name in ("v_w", "m", "I_b"):
        return a.name
    if any(f.name == a.name for f in STATE.fields):
        sl = STATE.slice(a.name)
        return f"x[{sl.start}:{sl.stop}]"
    o = decl.offsets()[a.name]
    return f"p[{o}]" if a.shape == () else f"p[{o}:{o + a.size}]"


def scalar_dispatch(effects: list) -> list[str]:
    """apply(p, x, v_w, m, I_b) -> (F_w or None, tau_w or None) per effect, on one body's floats; EFFECT_APPLY by
    name and EFFECT_APPLY_BY_CODE by built-in code."""
    out = ["# ---- Scene effects: apply(p, x, v_w, m, I_b) -> (F_w or None, tau_w or None), one body: p its parameters",
           "# (the row after [code, body]), x its state (13 floats), v_w the COM velocity it sees, m, I_b (3 floats).", ""]
    for _, d in effects:
        k = d.kernel()
        outs = dict(d.outputs)
        call = f"{k.name}({', '.join(_arg(d, a) for a in k.inputs)})"
        ret = call if len(outs) == 2 else f"{call}, None" if E.OUT_FORCE in outs else f"None, {call}"
        out += [f"def effect_apply_{d.name}(p, x, v_w, m, I_b):", f'    """{d.name}: {d.summary}."""',
                f"    return {ret}", "", ""]
    out += ["EFFECT_APPLY = {", *[f"    {d.name!r}: effect_apply_{d.name}," for _, d in effects], "}",
            "EFFECT_APPLY_BY_CODE = {", *[f"    {c}: effect_apply_{d.name}," for c, d in effects if c is not None], "}"]
    body = [(c, d) for c, d in effects if d.body_outputs is not None]
    for _, d in body:
        k = d.body_kernel()
        call = f"{k.name}({', '.join(_arg(d, a) for a in k.inputs)})"
        ret = call if len(d.body_outputs) == 2 else f"None, {call}"
        out += ["", "", f"def effect_apply_b_{d.name}(p, x, v_w, m, I_b):",
                f'    """{d.name}, its body-frame form (the torque in the body frame)."""', f"    return {ret}"]
    out += ["", "", "# built-in effect code -> its body-frame form (FLAG_TORQUE_B)", "EFFECT_APPLY_B_BY_CODE = {",
            *[f"    {c}: effect_apply_b_{d.name}," for c, d in body if c is not None], "}"]
    affine = [(c, d, k) for c, d in effects if c is not None and (k := d.affine_kernel()) is not None]
    out += ["# built-in effect code -> its decoupled force's (F0_w, k) from p and m (derive/effect.py affine_force)",
            "EFFECT_AFFINE_BY_CODE = {",
            *[f"    {c}: lambda p, m: {k.name}({', '.join(_arg(d, a) for a in k.inputs)})," for c, d, k in affine], "}"]
    return out


def row_tables(printed: list) -> list[str]:
    """READS: kernel -> {input: flat indices its expressions read}; ZEROS: kernel -> {output: flat indices that are
    identically 0}. A stepper forms only the stage rows a kernel reads, and steps rows whose rate is 0 as constants."""
    reads, zeros = [], []
    for p in printed:
        k = p.k
        r = {a.name: tuple(i for i, s in enumerate(a.flat) if s in p.used) for a in k.inputs if a.shape != ()}
        reads.append(f"    {k.name!r}: {r!r},")
        z, idx = {}, 0
        for a in k.outputs:
            z[a.name] = tuple(i for i in range(a.size) if sp.sympify(p.reduced[idx + i]) == 0)
            idx += a.size
        zeros.append(f"    {k.name!r}: {z!r},")
    return (["", "", "# kernel -> {array input: the flat indices it reads}", "READS = {", *reads, "}",
             "# kernel -> {array output: the flat indices that are identically 0}", "ZEROS = {", *zeros, "}"])


def print_scalar(printed: list, effects: list) -> str:
    """generated/kernels_scalar.py: every kernel for Python floats, and the effects' dispatch (effects: the
    built-in force effects [(code, EffectDecl)])."""
    pr = MathPrinter()
    body = []
    for p in printed:
        body += scalar_kernel(p, pr)
    head = [f'"""{HEADER}', "", "LavenderSim kernels for Python floats (one body per call): an array input is a flat",
            "sequence of floats (row-major; quaternions (x, y, z, w), scalar last), an array output a tuple of floats,",
            "several outputs a tuple of those. The same operations in the same order as kernels_numpy.py (a division by",
            'zero or a domain error raises where NumPy gives inf or NaN)."""', "import math", "", ""]
    return "\n".join(head + body + scalar_dispatch(effects) + row_tables(printed)) + "\n"
