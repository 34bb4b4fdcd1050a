"""Print derived kernels as C99, NumPy and Markdown, deterministically.

Same inputs give byte-identical files: symbols are named from the kernel's argument names, common
subexpressions are numbered in the order SymPy's CSE returns them, and no dates or tool versions
enter a file body (they live in manifest.json).
"""
from __future__ import annotations

import ast

import hashlib
import json
import platform
from pathlib import Path

import sympy as sp

from .cse_pass import tidy
from .kernel import Kernel
from .printers import (HEADER, PREFIX, USER_HEADER, CasadiPrinter, CPrinter, CPrinterF32, NpPrinter,  # noqa: F401
                       NpPrinterF32, _hoist_pow_bases)   # (re-exported: derive.user and tests use codegen.<name>)


def _unpack(k: Kernel, used: set, emit) -> None:
    """Bind each used input symbol once (a symmetric matrix repeats symbols: first entry wins)."""
    seen = set()
    for a in k.inputs:
        if a.shape == ():
            continue
        for i, s in enumerate(a.flat):
            if s in used and s not in seen:
                seen.add(s)
                emit(a, i, s)


def _used_where(where: list, exprs: list) -> list:
    """The named subexpressions the outputs need (directly or through later ones), in order."""
    need = set().union(*(sp.sympify(e).free_symbols for e in exprs)) if exprs else set()
    keep = []
    for s, e in reversed(where):
        if s in need:
            keep.append((s, e))
            need |= e.free_symbols
    return keep[::-1]


class Printed:
    """One kernel after CSE: temporaries, reduced outputs and op counts."""

    def __init__(self, k: Kernel):
        self.k = k
        self.output_exprs = k.output_exprs   # (substituting the where-symbols takes seconds for the largest: once)
        self.ops_before = int(sum(sp.count_ops(e) for e in self.output_exprs))
        # Named subexpressions (k.where) are atoms to CSE and printed first, as written, as temporaries.
        exprs = k.printed_exprs
        temps, reduced = tidy(*sp.cse(exprs, symbols=sp.numbered_symbols("t"), order="canonical"))
        self.temps, self.reduced = _hoist_pow_bases(_used_where(k.where, exprs) + temps, reduced)
        self.ops_after = int(sum(sp.count_ops(e) for _, e in self.temps) + sum(sp.count_ops(e) for e in self.reduced))
        self.has_piecewise = any(e.has(sp.Piecewise) for e in self.output_exprs)
        named = {s for s, _ in k.where}
        free = set().union(*(sp.sympify(e).free_symbols for e in exprs + [e for _, e in _used_where(k.where, exprs)])) if exprs else set()
        self.used = free - named
        unknown = self.used - set(k.input_symbols)
        if unknown:
            raise RuntimeError(f"derive: kernel {k.name} uses undeclared symbols {sorted(map(str, unknown))}")


def _c_sig(k: Kernel, prefix: str = PREFIX, real: str = "double") -> str:
    args = []
    for a in k.inputs:
        args.append(f"{real} {a.name}" if a.shape == () else f"const {real} *{a.name}")
    for a in k.outputs:
        args.append(f"{real} *{a.name}")
    return f"void {prefix}{k.name}({', '.join(args)})"


def _shape_txt(a) -> str:
    return "scalar" if a.shape == () else "[" + "×".join(map(str, a.shape)) + "]"


def _doc_lines(k: Kernel) -> list[str]:
    lines = [f"{k.name}: {k.summary}."]
    for a in k.inputs:
        lines.append(f"  in  {a.name} {_shape_txt(a)}: {a.doc}")
    for a in k.outputs:
        lines.append(f"  out {a.name} {_shape_txt(a)}: {a.doc}")
    return lines


def _np_doc_lines(k: Kernel) -> list[str]:
    """The NumPy kernel's docstring in numpydoc form (inputs broadcast over leading batch axes)."""
    def shp(a, kind):
        return f"{kind}, shape (..., {', '.join(map(str, a.shape))})" if a.shape else f"{kind}, shape (...)"
    lines = [f"{k.summary}.", "", f"Generated kernel ``{k.name}``; inputs broadcast over leading batch axes.",
             "", "Parameters", "----------"]
    for a in k.inputs:
        lines += [f"{a.name} : {shp(a, 'array_like')}", f"    {a.doc}"]
    lines += ["", "Returns", "-------"]
    for a in k.outputs:
        lines += [f"{a.name} : {shp(a, 'ndarray')}", f"    {a.doc}"]
    return lines + [""]


def _c_kernel(p: Printed, pr: CPrinter, prefix: str, real: str = "double") -> list[str]:
    k = p.k
    c = [_c_sig(k, prefix, real) + " {"]
    _unpack(k, p.used, lambda a, i, s: c.append(f"    const {real} {s} = {a.name}[{i}];"))
    for t, e in p.temps:
        c.append(f"    const {real} {t} = {pr.doprint(e)};")
    idx = 0
    for a in k.outputs:
        for i in range(a.size):
            e = p.reduced[idx]
            idx += 1
            target = a.name + (f"[{i}]" if a.shape != () else "[0]")
            c.append(f"    {target} = {pr.doprint(e)};")
    return c + ["}", ""]


def _c_packed_table(printed: list[Printed], prefix: str) -> list[str]:
    """Packed wrappers: one contiguous input and output buffer per call, for generic dispatch and tests."""
    c = []
    for p in printed:
        k = p.k
        args, off = [], 0
        for a in k.inputs:
            args.append(f"in[{off}]" if a.shape == () else f"in + {off}")
            off += a.size
        oo = 0
        for a in k.outputs:
            args.append(f"out + {oo}")
            oo += a.size
        c.append(f"static void packed_{k.name}(const double *in, double *out) {{ {prefix}{k.name}({', '.join(args)}); }}")
    c += ["", "const lv_kernel_info lv_kernel_table[LV_KERNEL_COUNT] = {"]
    for p in printed:
        k = p.k
        n_in = sum(a.size for a in k.inputs)
        n_out = sum(a.size for a in k.outputs)
        c.append(f'    {{"{k.name}", {n_in}, {n_out}, packed_{k.name}}},')
    c.append("};")
    return c


def print_c(printed: list[Printed], effects: list | None = None) -> tuple[str, str]:
    """kernels.h and kernels.c: every kernel, the packed kernel table, and the built-in effects'
    codes, accumulating functions and dispatch (effects: [(code, EffectDecl)])."""
    from . import effect_print

    effects = effects or []
    pr = CPrinter()
    h = [f"/* {HEADER} */", "/* LavenderSim kernels, C99. No allocation, no globals; arrays are row-major doubles.",
         "   Quaternions are (x, y, z, w), scalar last. Outputs may alias inputs (inputs are read first). */",
         "#ifndef LAVENDERSIM_KERNELS_H", "#define LAVENDERSIM_KERNELS_H", "",
         "typedef struct {", "    const char *name;", "    int n_in;   /* doubles in the packed input */",
         "    int n_out;  /* doubles in the packed output */", "    void (*packed)(const double *in, double *out);",
         "} lv_kernel_info;", "", f"#define LV_KERNEL_COUNT {len(printed)}", "extern const lv_kernel_info lv_kernel_table[LV_KERNEL_COUNT];", ""]
    c = [f"/* {HEADER} */", "#include <math.h>", '#include "kernels.h"', ""]
    for p in printed:
        h += ["/* " + "\n   ".join(_doc_lines(p.k)) + " */", _c_sig(p.k) + ";", ""]
        c += _c_kernel(p, pr, PREFIX)
    if effects:
        h += effect_print.c_header(effects)
        c += effect_print.c_source(effects, PREFIX)
    c += _c_packed_table(printed, PREFIX)
    h.append("#endif")
    return "\n".join(h) + "\n", "\n".join(c) + "\n"


F32_PREFIX = "lvf_"


def print_c_f32(printed: list[Printed], effects: list | None = None) -> tuple[str, str]:
    """kernels_f32.h and kernels_f32.c: every kernel printed again in single precision (prefix lvf_, float
    arguments, float math and literals; CPrinterF32) and the built-in effects' float accumulating functions
    with their dispatch lvf_effect_apply (effect codes from kernels.h). Compiled by the float32 step loop
    (lavendersim/csrc/step_f32.c), which includes kernels_f32.c into its translation unit."""
    from . import effect_print

    pr = CPrinterF32()
    h = [f"/* {HEADER} */", "/* LavenderSim kernels in single precision, C99: the kernels of kernels.h printed from the same",
         "   SymPy expressions with float arithmetic (sqrtf, 1.0F, ...). No allocation, no globals; arrays are",
         "   row-major floats. Quaternions are (x, y, z, w), scalar last. Outputs may alias inputs. */",
         "#ifndef LAVENDERSIM_KERNELS_F32_H", "#define LAVENDERSIM_KERNELS_F32_H", ""]
    c = [f"/* {HEADER} */", "#include <math.h>", '#include "kernels.h"', '#include "kernels_f32.h"', ""]
    for p in printed:
        h += [f"/* {p.k.name}: {p.k.summary} (float; see kernels.h) */", _c_sig(p.k, F32_PREFIX, "float") + ";"]
        c += _c_kernel(p, pr, F32_PREFIX, "float")
    if effects:
        c += effect_print.c_source_real(effects, F32_PREFIX, "float")
    h += ["", "#endif"]
    return "\n".join(h) + "\n", "\n".join(c) + "\n"


def print_c_user(printed: list[Printed], effects: list, set_name: str) -> tuple[str, str]:
    """A user set's kernels.h / kernels.c: its kernels (prefix lvu_<set>_) and its effects' exported
    accumulating functions lvu_effect_<name>, compiled into one shared library."""
    from . import effect_print

    pr = CPrinter()
    prefix = f"lvu_{set_name}_"
    guard = f"LAVENDERSIM_USER_{set_name.upper()}_H"
    h = [f"/* {USER_HEADER} */", f"/* User kernels of {set_name!r}, C99 (see lavendersim docs/extending.md). Arrays are",
         "   row-major doubles; quaternions (x, y, z, w), scalar last. */", f"#ifndef {guard}", f"#define {guard}", ""]
    c = [f"/* {USER_HEADER} */", "#include <math.h>", '#include "kernels.h"', "",
         "#if defined(__GNUC__) || defined(__clang__)  /* the library is built with -fvisibility=hidden */",
         '#define LV_EXPORT __attribute__((visibility("default")))', "#else", "#define LV_EXPORT", "#endif", ""]
    for p in printed:   # every kernel exported: a plain kernel is callable from Python (ctypes) too
        h += ["/* " + "\n   ".join(_doc_lines(p.k)) + " */", _c_sig(p.k, prefix) + ";", ""]
        c += ["LV_EXPORT " + line if i == 0 else line for i, line in enumerate(_c_kernel(p, pr, prefix))]
    for d in effects:
        h.append(f"void {effect_print.user_function(d)}({effect_print.C_ARGS});")
        if d.body_outputs is not None:   # its body-frame form (FLAG_TORQUE_B): the torque added in the body frame
            h.append(f"void {effect_print.user_function(d, True)}({effect_print.C_ARGS});")
    c += effect_print.c_user_source(effects, prefix)
    h += ["", "#endif"]
    return "\n".join(h) + "\n", "\n".join(c) + "\n"


_UFUNCS = {ast.Add: "add", ast.Sub: "subtract", ast.Mult: "multiply", ast.Div: "divide"}


def _np_assign(target: str, code: str) -> str:
    """`target = code` with code's last operation writing into target (numpy.<ufunc>(left, right, out=target)): the
    same operations in the same order, without a temporary and its copy (issue 30)."""
    tree = ast.parse(code, mode="eval").body
    if not any(isinstance(n, ast.Name) for n in ast.walk(tree)):     # a constant: assigned
        return f"{target} = {code}"
    if isinstance(tree, ast.BinOp) and type(tree.op) in _UFUNCS:
        return f"numpy.{_UFUNCS[type(tree.op)]}({ast.unparse(tree.left)}, {ast.unparse(tree.right)}, out={target})"
    if isinstance(tree, ast.UnaryOp) and isinstance(tree.op, ast.USub):
        return f"numpy.negative({ast.unparse(tree.operand)}, out={target})"
    return f"{target} = {code}"


def _np_lead_neg(code: str) -> str:
    """code with each sum whose left term is a negated product and whose right term is not, `-a*b + r`, written as
    `r - a*b`: the same number ((-a)*b is -(a*b) exactly, x - y is x + (-y), a sum commutes; signed zeros
    included) without the negation's NumPy call (one array pass). The C printing keeps the SymPy form."""
    class LeadNeg(ast.NodeTransformer):
        def visit_BinOp(self, node):
            self.generic_visit(node)
            if isinstance(node.op, ast.Add):
                left = _unnegated(node.left)
                if left is not None and _unnegated(node.right) is None:
                    return ast.BinOp(node.right, ast.Sub(), left)
            return node

    tree = ast.parse(code, mode="eval")
    new = ast.unparse(LeadNeg().visit(tree))
    return code if new == ast.unparse(ast.parse(code, mode="eval")) else new


def _unnegated(node):
    """node = -a or a product -a * b * ... (its leftmost factor negated): a (* b * ...), else None."""
    if isinstance(node, ast.UnaryOp) and isinstance(node.op, ast.USub):
        return node.operand
    if isinstance(node, ast.BinOp) and isinstance(node.op, ast.Mult):
        left = _unnegated(node.left)
        return None if left is None else ast.BinOp(left, ast.Mult(), node.right)
    return None


# elementwise calls a run of components may share (their arguments broadcast like the operators')
_NP_ELEMENTWISE = {"numpy.sqrt", "numpy.minimum", "numpy.maximum", "numpy.float32"}


def _np_template(code: str, comp: dict, j: int) -> ast.Expression | None:
    """code's AST with each unpacked vector component (comp: name -> (input, index)) renamed `input@(index - j)`
    (relative to component j of the output); None if it holds an operation that is not elementwise over a run of
    components (a call other than _NP_ELEMENTWISE, a subscript, numpy.select)."""
    tree = ast.parse(code, mode="eval")
    for node in ast.walk(tree):
        if isinstance(node, ast.Call):
            if ast.unparse(node.func) not in _NP_ELEMENTWISE:
                return None
        elif isinstance(node, ast.Name):
            if node.id in comp:
                a, i = comp[node.id]
                node.id = f"{a}@{i - j}"
        elif not isinstance(node, (ast.Expression, ast.BinOp, ast.UnaryOp, ast.Constant, ast.Attribute, ast.Load,
                                   ast.operator, ast.unaryop)):
            return None
    return tree


class _Block(ast.NodeTransformer):
    """A run's template as one operation on slices: `input@off` -> input[..., i+off:i+off+L], a batch-shaped name
    (a scalar input or a temporary) -> name[..., None] (broadcast over the run)."""

    def __init__(self, i: int, n: int, batch_names: set):
        self.i, self.n, self.batch_names = i, n, batch_names

    def visit_Name(self, node):
        if "@" in node.id:
            a, off = node.id.split("@")
            s = self.i + int(off)
            return ast.parse(f"{a}[..., {s}:{s + self.n}]", mode="eval").body
        if node.id in self.batch_names:
            return ast.parse(f"{node.id}[..., None]", mode="eval").body
        return node


def _np_block(codes: list[str], first: int, comp: dict, sizes: dict, batch_names: set) -> str | None:
    """codes (components first, first + 1, ...) as one operation on slices when they are one expression on shifted
    components of the same inputs (e.g. -c*v_w_0, -c*v_w_1, -c*v_w_2, or copies x_7, x_8, x_9), else None."""
    n = len(codes)
    tpl = [t for j, c in enumerate(codes) if (t := _np_template(c, comp, first + j)) is not None]
    if n < 2 or len(tpl) < n or len({ast.dump(t) for t in tpl}) != 1:
        return None
    tree = tpl[0]
    shifted = [nm.id.split("@") for nm in ast.walk(tree) if isinstance(nm, ast.Name) and "@" in nm.id]
    if not shifted or not all(0 <= first + int(o) and first + int(o) + n <= sizes[a] for a, o in shifted):
        return None
    return ast.unparse(_Block(first, n, batch_names).visit(tree).body)


def _np_runs(codes: list[str], comp: dict, sizes: dict, batch_names: set, name: str) -> list[tuple[int, int, str, list]]:
    """The components of one vector output `name` as runs (first, length, code, lines before): a run of components
    that are one expression on shifted components (_np_block) prints as one operation on slices, the same operations
    on every number (issue 30: fewer NumPy calls); the others one each, sharing an operand where _np_shared can."""
    runs: list[tuple[int, int, str, list]] = []
    j = 0
    while j < len(codes):
        e = len(codes)
        while e > j + 1 and _np_block(codes[j:e], j, comp, sizes, batch_names) is None:
            e -= 1
        blk = _np_block(codes[j:e], j, comp, sizes, batch_names) if e > j + 1 else None
        runs.append((j, e - j, blk, []) if blk is not None else (j, 1, codes[j], []))
        j += runs[-1][1]
    out: list[tuple[int, int, str, list]] = []
    k = 0
    while k < len(runs):
        e = k     # the singles from k on whose last operation is the same binary one
        trees: list = []
        while e < len(runs) and runs[e][1] == 1:
            t = ast.parse(runs[e][2], mode="eval").body
            if not isinstance(t, ast.BinOp) or (trees and type(t.op) is not type(trees[0].op)):
                break
            trees.append(t)
            e += 1
        shared = _np_shared(trees, runs[k][0], comp, sizes, batch_names, name) if len(trees) > 1 else None
        out.extend(shared or runs[k:max(e, k + 1)])
        k = max(e, k + 1)
    return out


def _np_shared(trees: list, first: int, comp: dict, sizes: dict, batch_names: set, name: str) -> list | None:
    """Components first, first + 1, ... (trees: each a binary operation, all the same one) when one operand of them
    is a run (e.g. the r_x*tau_x, r_y*tau_y, r_z*tau_z of Euler's equations): that operand computed once, on
    slices, into a temporary each reads (runs as _np_runs'), else None. An operand that is a component stays."""
    tmp = f"{name}_{first}_{first + len(trees)}"
    if tmp in comp or tmp in sizes or tmp in batch_names:
        return None
    for side in ("right", "left"):
        if not all(isinstance(getattr(t, side), (ast.BinOp, ast.UnaryOp, ast.Call)) for t in trees):
            continue
        blk = _np_block([ast.unparse(getattr(t, side)) for t in trees], first, comp, sizes, batch_names)
        if blk is None:
            continue
        out = []
        for j, t in enumerate(trees):
            setattr(t, side, ast.parse(f"{tmp}[..., {j}]", mode="eval").body)
            out.append((first + j, 1, ast.unparse(t), [f"{tmp} = {blk}"] if j == 0 else []))
        return out
    return None


def _np_temps(p: Printed, pr: NpPrinter, comp: dict, sizes: dict, batch_names: set) -> list[str]:
    """The temporaries' lines; consecutive ones that are one expression on shifted components (e.g. the halves of
    omega_b: t0 = 0.5*x_10, t1 = 0.5*x_11, t2 = 0.5*x_12) computed once on slices and read as its columns."""
    names = [str(t) for t, _ in p.temps]
    codes = [_np_lead_neg(pr.doprint(e)) for _, e in p.temps]
    lines: list[str] = []
    j = 0
    while j < len(codes):
        e = len(codes)
        while e > j + 1 and _np_block(codes[j:e], 0, comp, sizes, batch_names) is None:
            e -= 1
        blk = _np_block(codes[j:e], 0, comp, sizes, batch_names) if e > j + 1 else None
        run = f"{names[j]}_{e - j}"
        if blk is None or run in comp or run in sizes or run in batch_names or run in names:
            lines.append(f"{names[j]} = {codes[j]}")
            j += 1
            continue
        lines.append(f"{run} = {blk}")
        lines += [f"{names[i]} = {run}[..., {i - j}]" for i in range(j, e)]
        j = e
    return lines


def _np_outputs(p: Printed, pr: NpPrinter, dtype: str, comp: dict, sizes: dict, batch_names: set
                ) -> tuple[list[str], list[str]]:
    """A NumPy kernel's temporaries and outputs (lines) and the names it returns."""
    k = p.k
    ind = "    "
    body = []
    if p.has_piecewise:
        body.append("    with numpy.errstate(invalid='ignore', divide='ignore'):  # numpy.select evaluates every branch")
        ind = "        "
    body += [ind + line for line in _np_temps(p, pr, comp, sizes, batch_names)]
    idx = 0
    rets: list[str] = []
    for a in k.outputs:
        shp = "" if a.shape == () else " + " + repr(tuple(a.shape))
        body.append(f"{ind}{a.name}_out = numpy.empty(batch{shp}" + (")" if dtype == "float64" else f", dtype=numpy.{dtype})")
                    + f" if out is None or out[{len(rets)}] is None else out[{len(rets)}]")
        codes = [_np_lead_neg(pr.doprint(e)) for e in p.reduced[idx:idx + a.size]]
        idx += a.size
        if a.shape == ():
            body.append(ind + _np_assign(f"{a.name}_out[...]", codes[0]))
        elif len(a.shape) == 1:
            for i, n, code, pre in _np_runs(codes, comp, sizes, batch_names, a.name):
                body += [ind + line for line in pre]
                body.append(ind + _np_assign(f"{a.name}_out[..., {i}:{i + n}]" if n > 1 else f"{a.name}_out[..., {i}]", code))
        else:
            for i, code in enumerate(codes):
                body.append(ind + _np_assign(f"{a.name}_out[..., {i // a.shape[1]}, {i % a.shape[1]}]", code))
        rets.append(f"{a.name}_out")
    return body, rets


def _np_kernel(p: Printed, pr: NpPrinter, dtype: str = "float64") -> list[str]:
    k = p.k
    doc = "\n".join(f"    {line}" if line else "" for line in _np_doc_lines(k)).lstrip()
    # out=: the arrays to write the outputs into (one per output, None: allocate), e.g. component-major (k, n)
    # buffers' transposes, so a struct-of-arrays caller writes each component contiguously and allocates nothing
    doc = doc.replace("\n\n    Returns", "\n    out : tuple of (ndarray or None), optional\n        arrays the outputs are "
                      "written into, in order (None: a new array); none may overlap an input\n\n    Returns", 1)
    out = [f"def {k.name}({', '.join(a.name for a in k.inputs)}, *, out=None):", f'    """{doc}    """']
    for a in k.inputs:
        out.append(f"    {a.name} = numpy.asarray({a.name}, dtype=numpy.{dtype})")
    lead = []
    for a in k.inputs:
        nd = len(a.shape)
        lead.append(f"{a.name}.shape" if nd == 0 else f"{a.name}.shape[:-{nd}]")
    # the batch shape: equal input batch shapes (the usual call) compared in Python, broadcast_shapes (~20 us) otherwise
    same = " == ".join(lead)
    # ... and only when an output is allocated (a caller passing every out= pays neither)
    missing = " or ".join(["out is None"] + [f"out[{i}] is None" for i in range(len(k.outputs))])
    out.append(f"    if {missing}:")
    out.append(f"        batch = {lead[0]}" if len(lead) == 1 else
               f"        batch = {lead[0]} if {same} else numpy.broadcast_shapes({', '.join(lead)})")

    unpack: list[tuple[str, str]] = []     # (symbol, its line)
    comp: dict[str, tuple[str, int]] = {}  # a 1-D input's component symbol -> (input, index)

    def emit(a, i, s):
        ix = f"{i}" if len(a.shape) == 1 else f"{i // a.shape[1]}, {i % a.shape[1]}"
        unpack.append((str(s), f"    {s} = {a.name}[..., {ix}]"))
        if len(a.shape) == 1:
            comp[str(s)] = (a.name, i)
    _unpack(k, p.used, emit)
    sizes = {a.name: a.size for a in k.inputs}
    # names that are arrays of the batch shape: the scalar inputs and the temporaries that read an input
    batch_names = {a.name for a in k.inputs if a.shape == ()} | {str(t) for t, e in p.temps if e.free_symbols}
    body, rets = _np_outputs(p, pr, dtype, comp, sizes, batch_names)
    # only the components still read one by one are unpacked (a run reads its input's slice)
    read = {n.id for line in body if not line.strip().startswith("with ")
            for n in ast.walk(ast.parse(line.strip())) if isinstance(n, ast.Name)}
    out += [line for s, line in unpack if s in read] + body
    out += [f"    return {', '.join(rets)}", "", ""]
    return out


def print_numpy(printed: list[Printed], effects: list | None = None, header: str = HEADER,
                dtype: str = "float64") -> str:
    """kernels_numpy.py: every kernel vectorized, the KERNELS table and the effects' dispatch. The module imports
    NumPy only (the runtime's loader checks it against manifest.json: lavendersim._integrity)."""
    from . import effect_print

    pr = NpPrinter() if dtype == "float64" else NpPrinterF32()
    prec = [] if dtype == "float64" else [f"Single precision: inputs are taken as {dtype} and every temporary and output is",
                                          f"{dtype} (the same expressions as the C kernels of kernels_f32.c)."]
    out = [f'"""{header}', "", "LavenderSim kernels for NumPy, vectorized over leading batch axes: an input of shape",
           "(..., n) broadcasts against the others; scalars may be floats or arrays of the batch shape.",
           "Quaternions are (x, y, z, w), scalar last; matrices are (..., 3, 3)." + ("" if prec else '"""'),
           *prec[:-1], *(prec[-1:] and [prec[-1] + '"""'])]
    body = []
    meta = []
    for p in printed:
        k = p.k
        body += _np_kernel(p, pr, dtype)
        meta.append(f"    {k.name!r}: ({k.name}, {[(a.name, tuple(a.shape)) for a in k.inputs]!r}, "
                    f"{[(a.name, tuple(a.shape)) for a in k.outputs]!r}),")
    # `import math` only where a kernel calls it (erf, element by element): the built-in files are unchanged
    out += (["import math", "", "import numpy", "", ""] if any("math." in line for line in body)
            else ["import numpy", "", ""]) + body
    out.append("# name -> (function, [(input, shape)], [(output, shape)]), in the order of the C kernel table")
    out.append("KERNELS = {")
    out.extend(meta)
    out.append("}")
    if effects:
        out += ["", ""] + effect_print.numpy_dispatch(effects)
    return "\n".join(out) + "\n"


def print_casadi(printed: list[Printed], header: str = HEADER) -> str:
    pr = CasadiPrinter()
    out = [f'"""{header}', "", "LavenderSim kernels for CasADi: the same expressions as kernels.c, over casadi SX/MX/DM.",
           "Each input is a column vector (matrices flattened row-major, scalars as scalars); each output",
           'is returned as a column vector (casadi.vertcat), several outputs as a tuple."""', "import casadi", "", ""]
    for p in printed:
        k = p.k
        out.append(f"def {k.name}({', '.join(a.name for a in k.inputs)}):")
        out.append('    """' + "\n    ".join(_doc_lines(k)) + '"""')
        _unpack(k, p.used, lambda a, i, s: out.append(f"    {s} = {a.name}[{i}]"))
        for t, e in p.temps:
            out.append(f"    {t} = {pr.doprint(e)}")
        idx, rets = 0, []
        for a in k.outputs:
            items = [pr.doprint(p.reduced[idx + i]) for i in range(a.size)]
            idx += a.size
            rets.append(f"casadi.vertcat({', '.join(items)})" if a.shape != () else f"casadi.vertcat({items[0]})")
        out.append(f"    return {', '.join(rets)}")
        out.append("")
        out.append("")
    return "\n".join(out).rstrip() + "\n"


# ---- LaTeX, printed from the SymPy expressions --------------------------------------------------

_GREEK = {"alpha", "beta", "gamma", "delta", "epsilon", "zeta", "eta", "theta", "kappa", "lambda", "mu", "nu", "xi",
          "pi", "rho", "sigma", "tau", "phi", "chi", "psi", "omega", "Omega", "Gamma", "Delta", "Theta", "Phi", "Psi"}
# Direct form when the outputs print in at most this many characters; else the CSE form (temporaries).
LATEX_DIRECT_MAX = 1500


def _tex_name(name: str, index: str | None = None) -> str:
    """omega_b, 0 -> \\omega_{b,0}; torque_w -> \\mathrm{torque}_{w}; q_dot -> \\dot{q}; m -> m."""
    head, *rest = name.split("_")
    dot = "dot" in rest
    sub = ",".join(x for x in rest if x != "dot")
    h = "\\" + head if head in _GREEK else (head if len(head) == 1 else rf"\mathrm{{{head}}}")
    h = rf"\dot{{{h}}}" if dot else h
    parts = [x for x in (sub, index) if x]
    return h + (f"_{{{','.join(parts)}}}" if parts else "")


def _tex_symbols(k: Kernel, temps) -> dict:
    names = {}
    for a in k.inputs:
        for i, s in enumerate(a.flat):
            if s in names:
                continue
            if a.shape == ():
                names[s] = _tex_name(a.name)
            else:
                ix = str(i) if len(a.shape) == 1 else f"{i // a.shape[1]}{i % a.shape[1]}"
                names[s] = _tex_name(a.name, ix)
    named = {s for s, _ in k.where}
    for t, _ in temps:
        if t in named:   # a where-symbol: c_b_0 -> c_{b,0}
            head, _, ix = str(t).rpartition("_")
            names[t] = _tex_name(head, ix)
        else:
            names[t] = f"t_{{{str(t)[1:]}}}"
    return names


def _tex_value(a, exprs, names) -> str:
    if a.shape == ():
        return sp.latex(exprs[0], symbol_names=names)
    shape = a.shape if len(a.shape) == 2 else (a.shape[0], 1)
    return sp.latex(sp.Matrix(shape[0], shape[1], list(exprs)), symbol_names=names)


def _more_symbols_than(exprs, limit: int) -> bool:
    """True when the expressions hold more than `limit` symbols, each occurrence counted. sympy.latex prints every
    occurrence (a name of at least one character), so more than LATEX_DIRECT_MAX means a direct form longer than that,
    known without printing it (the largest kernels' direct forms, 0.5 MB of LaTeX printed only to be discarded, took
    most of EQUATIONS.md's time)."""
    count = 0
    for e in exprs:
        for x in sp.preorder_traversal(e):
            count += x.is_Symbol
            if count > limit:
                return True
    return False


def latex_of(p: Printed) -> str:
    """The kernel's outputs as LaTeX printed by sympy.latex from its SymPy expressions: directly when
    short, else in the CSE form the code computes (temporaries t_i, then the outputs)."""
    k = p.k
    if not k.where and not _more_symbols_than(p.output_exprs, LATEX_DIRECT_MAX):   # named subexpressions: the CSE form
        names = _tex_symbols(k, [])
        flat, idx, lines = p.output_exprs, 0, []
        for a in k.outputs:
            lines.append(f"{_tex_name(a.name)} = {_tex_value(a, flat[idx:idx + a.size], names)}")
            idx += a.size
        direct = r",\quad ".join(lines)
        if len(direct) <= LATEX_DIRECT_MAX:
            return direct
    names = _tex_symbols(k, p.temps)
    rows = [f"{names[t]} &= {sp.latex(e, symbol_names=names)}" for t, e in p.temps]
    idx = 0
    for a in k.outputs:
        rows.append(f"{_tex_name(a.name)} &= {_tex_value(a, p.reduced[idx:idx + a.size], names)}")
        idx += a.size
    return "\\begin{aligned}\n" + " \\\\\n".join(rows) + "\n\\end{aligned}"


def print_markdown(printed: list[Printed], effects: list | None = None, title: str = "LavenderSim equations",
                   header: str = HEADER) -> str:
    """EQUATIONS.md: per kernel its equation printed from SymPy (sympy.latex of its outputs), an optional
    human caption, inputs/outputs and op counts; per effect its code and parameter table."""
    from . import effect_print

    by_kernel = {d.kernel_name: (c, d) for c, d in (effects or []) if d.kind == "force"}
    out = [f"<!-- {header} -->", f"# {title}", "",
           "Every kernel in `kernels.c`, `kernels_numpy.py` and `kernels_casadi.py` is printed from the SymPy",
           "expression below; the equation shown is `sympy.latex` of the same outputs (in the CSE form the code",
           "computes when it is long), so it cannot drift from the code. A *caption* is a human summary.",
           "Quaternions are (x, y, z, w), scalar last; `R_WB` maps body to world coordinates; SI units.",
           "Op counts are SymPy `count_ops` of the outputs before common-subexpression elimination and of",
           "temporaries plus outputs after it.", ""]
    group = None
    for p in printed:
        k = p.k
        if k.group != group:
            group = k.group
            out += [f"## {group}", ""]
        out += [f"### `{k.name}`", "", k.summary + ".", ""]
        if k.name in by_kernel:
            out += effect_print.markdown_params(by_kernel[k.name][1], by_kernel[k.name][0])
        if k.latex:
            out += [f"Caption: ${k.latex}$", ""]
        out += [f"$${latex_of(p)}$$", "", "| | name | shape | meaning |", "|---|---|---|---|"]
        for a in k.inputs:
            out.append(f"| in | `{a.name}` | {_shape_txt(a)} | {a.doc} |")
        for a in k.outputs:
            out.append(f"| out | `{a.name}` | {_shape_txt(a)} | {a.doc} |")
        out += ["", f"Ops: {p.ops_before} before CSE, {p.ops_after} after ({len(p.temps)} temporaries)."]
        out += [f"Note: {n}" for n in k.notes]
        out.append("")
    models = [(c, d) for c, d in (effects or []) if d.kind == "model"]
    if models:
        out += ["## Model effects", ""]
        for c, d in models:
            out += [f"### `{d.name}`", "", d.summary + ".", ""] + effect_print.markdown_params(d, c)
    return "\n".join(out)


def source_hash() -> str:
    """Hash of the derive/ sources that define the equations and their printing (the real folder: under a strict
    editable install this module is a link in a folder of links made at install time, which lacks a file added since)."""
    h = hashlib.sha256()
    for f in sorted(Path(__file__).resolve().parent.glob("*.py")):
        h.update(f.name.encode())
        h.update(f.read_bytes())
    return h.hexdigest()


def tool_versions() -> dict:
    return {"python": platform.python_version(), "sympy": sp.__version__}


def render(progress=None) -> dict[str, str]:
    """Every file of generated/ (except manifest.json) as text, from a fresh derivation. progress: an optional
    callable given a short phrase before each phase (the CLI shows it)."""
    from . import all_effects, all_kernels, scalar_print
    from . import effect_fuse, pipeline_meta
    from .effect_print import meta_module

    step = progress or (lambda _msg: None)
    step("deriving the equations")
    kernels = all_kernels()
    step(f"simplifying {len(kernels)} kernels")
    printed = [Printed(k) for k in kernels]
    effects = list(enumerate(all_effects(), start=1))
    forces = [(c, d) for c, d in effects if d.kind == "force"]
    step("printing C, NumPy and CasADi")
    h, c = print_c(printed, forces)
    h32, c32 = print_c_f32(printed, forces)
    files = {"kernels.h": h, "kernels.c": c, "kernels_numpy.py": print_numpy(printed, forces),
             "kernels_f32.h": h32, "kernels_f32.c": c32,
             "kernels_numpy_f32.py": print_numpy(printed, forces, dtype="float32"),
             "kernels_casadi.py": print_casadi(printed), "effects_meta.py": meta_module(effects, HEADER, {**effect_fuse.meta_extra(), "pipeline_kernels": pipeline_meta.pipeline_kernels()}),
             "kernels_scalar.py": scalar_print.print_scalar(printed, forces)}
    step("printing EQUATIONS.md")
    files["EQUATIONS.md"] = print_markdown(printed, effects)
    step("printing the layouts and integrator tableaux")
    files.update(contract_files())
    files["__init__.py"] = package_init(sorted(n for n in files if n.endswith(".py")))
    return files


def package_init(modules: list[str]) -> str:
    """generated/__init__.py: a docstring only (generated code imports nothing of the runtime). The runtime checks
    each module against manifest.json when it imports it (lavendersim._integrity's import hook)."""
    return (f'"""{HEADER}\n\nThe printed kernels and tables: {", ".join(m[:-3] for m in modules)}. Imported through '
            'lavendersim, each module is first checked\nagainst manifest.json (lavendersim._integrity)."""\n')


def contract_files() -> dict[str, str]:
    """The row layouts and the integrator tableaux, for C (headers) and Python (modules)."""
    from . import layout, tableaux

    return {"layout.h": layout.print_c(), "layout.py": layout.print_python(),
            "tableaux.h": tableaux.print_c(), "tableaux.py": tableaux.print_python()}


def digest(text: str) -> str:
    return hashlib.sha256(text.encode()).hexdigest()


def manifest_for(files: dict[str, str]) -> str:
    body = {"header": HEADER, "derive_sources_sha256": source_hash(), "tools": tool_versions(),
            "outputs_sha256": {n: digest(t) for n, t in sorted(files.items())}}
    return json.dumps(body, indent=2, sort_keys=True) + "\n"


def write(outdir: Path, progress=None) -> list[str]:
    """Write generated/ atomically; return the files whose content changed.

    Every file is printed in memory first, then the folder is replaced as a whole
    (derive/atomic.py: written into a sibling folder and swapped in), so a run killed at any moment
    leaves outdir either as it was or complete and consistent with its manifest; leftovers of a
    killed run are cleaned up (or put back) by the next one. Unchanged files keep their timestamps;
    nothing is written when nothing changed. outdir may hold only derive's files (and __pycache__):
    anything else raises atomic.OutputFolderError before anything is written."""
    from . import atomic

    outdir = Path(outdir)
    files = render(progress)
    (progress or (lambda _msg: None))(f"writing {outdir}")
    files["manifest.json"] = manifest_for(files)
    owned = set()
    try:  # files an older derive wrote (listed in its manifest) are derive's to drop
        owned = set(json.loads((outdir / "manifest.json").read_text(encoding="utf-8")).get("outputs_sha256", {}))
    except (OSError, ValueError, AttributeError):
        pass
    return atomic.replace_folder(outdir, files, owned=owned)


def check(outdir: Path, full: bool = False, progress=None) -> list[str]:
    """Return the stale files of outdir (empty: current). Writes nothing.

    Fast path: when the manifest records this exact derive/ source hash and tool versions, and every
    output still has its recorded hash, generated/ is current without re-deriving. Otherwise (or
    with full=True) derive in memory and compare every output byte for byte, and the manifest's
    source and output hashes (not its tool versions)."""
    man_path = outdir / "manifest.json"
    try:
        man = json.loads(man_path.read_text(encoding="utf-8"))
    except (OSError, ValueError):
        man = None
    if man is not None:
        (progress or (lambda _msg: None))("checking the manifest")
    if man is not None and not full and man.get("derive_sources_sha256") == source_hash() and man.get("tools") == tool_versions():
        stale = []
        for name, want in sorted(man.get("outputs_sha256", {}).items()):
            p = outdir / name
            if not p.exists() or digest(p.read_text(encoding="utf-8")) != want:
                stale.append(name)
        if not stale:
            return []
    files = render(progress)
    stale = [name for name, text in sorted(files.items())
             if not (outdir / name).exists() or (outdir / name).read_text(encoding="utf-8") != text]
    # The manifest must record these derive/ sources and these outputs. The tool versions it
    # records are provenance only: another Python or SymPy that prints identical files is current.
    want = json.loads(manifest_for(files))
    if man is None or any(man.get(k) != want[k] for k in ("header", "derive_sources_sha256", "outputs_sha256")):
        stale.append("manifest.json")
    return stale
