"""The designed wheel controller printed as C99 for a flight computer, and flown in the loop (issue 27).

:func:`render` / :func:`export_c` print a :class:`lavendersim.control.Controller` as a
dependency-free C99 pair ``controller.h`` / ``controller.c`` (plus an example ``main.c``): one step
function per precision over fixed-size arrays, no allocation, no globals but ``static const`` data, only
libm (``fmin``/``fmax``/``isfinite`` and whatever the expressions use)::

    int lv_controller_step(const double q[4], const double omega_b[3], const double Omega[N],
                           const double q_ref[4], double z[NZ], double u[N]);
    int lv_controller_step_f32(const float q[4], ...same shapes..., float z[NZ], float u[N]);
    void lv_controller_reset(double z[NZ]);      /* and _f32: the memory at the operating torque */

The body of the step is printed from the controller's own expressions — :attr:`Controller.function`,
the CasADi SX ``Function`` that :meth:`Controller.command` evaluates (attitude chart, gains, allocation,
saturation, memory update) — instruction by instruction (``Function.instruction_id`` /
``instruction_input`` / ``instruction_output`` / ``instruction_constant``), as straight-line
single-assignment C in CasADi's evaluation order; nothing is typed by hand. CasADi's own C generator
is not used: its output does not compile with ``-Wall -Wextra -Werror`` unmodified (unused ``iw``,
``w``, ``mem`` parameters) and carries work arrays and a memory API a flight computer does not need.
Printed without contraction (``-ffp-contract=off``) the float64 step performs the same IEEE operations
in the same order as CasADi's virtual machine, so it reproduces the Python commands bit for bit.

The C adds one thing the expressions do not have: a non-finite input (NaN or inf in any measurement,
reference or the memory) is refused — the step returns 1, writes the operating torque ``u0`` and leaves
``z`` unchanged — because ``fmin``/``fmax`` would otherwise turn a NaN into a full-scale torque.

:func:`compile_library` builds the pair with the strict flags (:data:`CFLAGS`) into a shared library;
:class:`CompiledController` is a Controller whose :meth:`~CompiledController.command` calls it
(ctypes), so :func:`lavendersim.control.closed_loop` flies the printed C in place of the Python step
(software in the loop); :func:`verify` / :func:`sil` compare the two runs.
"""
from __future__ import annotations

import ctypes
import hashlib
import math
import os
import subprocess
import tempfile
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from . import validate as V
from ._files import replace_file
from .wheel_control import Controller

PREFIX = "lv_controller"
FILES = ("controller.h", "controller.c", "main.c")
# the strict compile of the printed files (the issue's flags), then what the float32 step must also pass:
# no implicit float -> double promotion and no silent narrowing (a float-only FPU target)
STRICT = ("-std=c99", "-Wall", "-Wextra", "-pedantic", "-Werror")
CFLAGS = STRICT + ("-Wdouble-promotion", "-Wfloat-conversion", "-O2", "-ffp-contract=off")


class CompileError(RuntimeError):
    """Compiling the printed controller failed; the message holds the command and the compiler's full output."""


# ----------------------------------------------------------------------------------------------
# the instruction printer
# ----------------------------------------------------------------------------------------------


def _ops() -> dict[int, tuple[int, str]]:
    """CasADi operation code -> (arity, C template with {0}, {1}, {f} (libm suffix), {one}, {zero})."""
    import casadi as ca

    cmp = "(({0}) {op} ({1}) ? {one} : {zero})"
    fn1 = {"EXP": "exp", "LOG": "log", "SQRT": "sqrt", "SIN": "sin", "COS": "cos", "TAN": "tan", "ASIN": "asin",
           "ACOS": "acos", "ATAN": "atan", "FLOOR": "floor", "CEIL": "ceil", "FABS": "fabs", "ERF": "erf",
           "SINH": "sinh", "COSH": "cosh", "TANH": "tanh", "ASINH": "asinh", "ACOSH": "acosh", "ATANH": "atanh",
           "LOG1P": "log1p", "EXPM1": "expm1"}
    fn2 = {"POW": "pow", "CONSTPOW": "pow", "FMOD": "fmod", "COPYSIGN": "copysign", "FMIN": "fmin", "FMAX": "fmax",
           "ATAN2": "atan2", "HYPOT": "hypot", "REMAINDER": "remainder"}
    t = {ca.OP_ADD: (2, "{0} + {1}"), ca.OP_SUB: (2, "{0} - {1}"), ca.OP_MUL: (2, "{0} * {1}"),
         ca.OP_DIV: (2, "{0} / {1}"), ca.OP_NEG: (1, "-{0}"), ca.OP_SQ: (1, "{0} * {0}"),
         ca.OP_TWICE: (1, "{0} + {0}"), ca.OP_INV: (1, "{one} / {0}"),
         ca.OP_LT: (2, cmp.replace("{op}", "<")), ca.OP_LE: (2, cmp.replace("{op}", "<=")),
         ca.OP_EQ: (2, cmp.replace("{op}", "==")), ca.OP_NE: (2, cmp.replace("{op}", "!=")),
         ca.OP_NOT: (1, "(({0}) == {zero} ? {one} : {zero})"),
         ca.OP_AND: (2, "(({0}) != {zero} && ({1}) != {zero} ? {one} : {zero})"),
         ca.OP_OR: (2, "(({0}) != {zero} || ({1}) != {zero} ? {one} : {zero})"),
         ca.OP_IF_ELSE_ZERO: (2, "(({0}) != {zero} ? {1} : {zero})"),
         ca.OP_SIGN: (1, "(({0}) < {zero} ? -{one} : (({0}) > {zero} ? {one} : {0}))")}
    t.update({getattr(ca, "OP_" + k): (1, v + "{f}({0})") for k, v in fn1.items()})
    t.update({getattr(ca, "OP_" + k): (2, v + "{f}({0}, {1})") for k, v in fn2.items()})
    return t


@dataclass(frozen=True)
class _Precision:
    ctype: str
    suffix: str          # of the step function's name
    libm: str            # "f" for sinf, fminf ...

    def literal(self, v: float) -> str:
        if math.isnan(v):
            return "NAN"
        if math.isinf(v):
            return "INFINITY" if v > 0 else "(-INFINITY)"
        if self.ctype == "float":
            f = np.float32(v)
            if not np.isfinite(f):
                raise V.LavenderInputError("controller", "a constant of the expressions overflows float32",
                                           f", got {v!r}")
            s = str(f) + "f"
        else:
            s = repr(float(v))
        return f"({s})" if s.startswith("-") else s


F64 = _Precision("double", "", "")
F32 = _Precision("float", "_f32", "f")


def _program(fn: Any) -> tuple[list, dict[tuple[int, int], int]]:
    """The Function's instructions as SSA nodes, and the output map.

    Returns
    -------
    nodes : list of (kind, payload)
        ``("in", (input, element))``, ``("const", value)`` or ``("op", (code, [node ids]))``.
    outputs : dict
        ``(output, element) -> node id``.
    """
    import casadi as ca

    ops = _ops()
    rows_in = [list(fn.sparsity_in(i).row()) for i in range(fn.n_in())]
    nodes: list = []
    slot: dict[int, int] = {}
    outputs: dict[tuple[int, int], int] = {}
    for k in range(fn.n_instructions()):
        op, ins, outs = fn.instruction_id(k), list(fn.instruction_input(k)), list(fn.instruction_output(k))
        if op == ca.OP_INPUT:
            nodes.append(("in", (ins[0], rows_in[ins[0]][ins[1]])))
            slot[outs[0]] = len(nodes) - 1
        elif op == ca.OP_OUTPUT:
            rows = fn.sparsity_out(outs[0]).row()
            outputs[(outs[0], rows[outs[1]])] = slot[ins[0]]
        elif op == ca.OP_CONST:
            nodes.append(("const", float(fn.instruction_constant(k))))
            slot[outs[0]] = len(nodes) - 1
        elif op in ops:
            arity = ops[op][0]
            nodes.append(("op", (op, [slot[i] for i in ins[:arity]])))
            slot[outs[0]] = len(nodes) - 1
        else:
            raise NotImplementedError(f"controller_c: CasADi operation {op} has no C99 printing "
                                      f"(instruction {k} of {fn.name()})")
    return nodes, outputs


def _step_body(fn: Any, names: list[str], prec: _Precision) -> tuple[list[str], dict[tuple[int, int], str], int]:
    """C statements (one ``const T tK = ...;`` per live operation) and the output expressions.

    Returns
    -------
    lines : list of str
    outputs : dict
        ``(output, element) -> C name of its value``.
    n_ops : int
        Arithmetic operations printed.
    """
    nodes, outputs = _program(fn)
    live = [False] * len(nodes)
    stack = list(outputs.values())
    while stack:
        i = stack.pop()
        if not live[i]:
            live[i] = True
            if nodes[i][0] == "op":
                stack.extend(nodes[i][1][1])
    ops = _ops()
    one, zero = prec.literal(1.0), prec.literal(0.0)
    expr: dict[int, str] = {}
    lines: list[str] = []
    n_ops = 0
    for i, (kind, p) in enumerate(nodes):
        if not live[i]:
            continue
        if kind == "in":
            expr[i] = f"{names[p[0]]}[{p[1]}]"
        elif kind == "const":
            expr[i] = prec.literal(p)
        else:
            code, args = p
            text = ops[code][1].format(*[expr[a] for a in args], f=prec.libm, one=one, zero=zero)
            expr[i] = f"t{i}"
            lines.append(f"const {prec.ctype} t{i} = {text};")
            n_ops += 1
    out: dict[tuple[int, int], str] = {}
    for key, i in outputs.items():
        if nodes[i][0] != "op":   # an input or a constant passed through: read before any output is written
            name = f"o{key[0]}_{key[1]}"
            lines.append(f"const {prec.ctype} {name} = {expr[i]};")
            out[key] = name
        else:
            out[key] = expr[i]
    return lines, out, n_ops


def function_c(fn: Any, name: str, precision: str = "float64") -> str:
    """Any CasADi SX Function with dense inputs and outputs printed as one C99 function (the printer alone).

    ``void name(const T in0[n0], ..., T out0[m0], ...)`` with the Function's own argument names; the
    body is what :func:`render` prints for the controller's step. Used to test the printer on every
    operation it knows.

    Parameters
    ----------
    fn : casadi.Function
        An SX Function (``fn.is_a("SXFunction")``).
    name : str
        The C function's name.
    precision : {"float64", "float32"}, default "float64"

    Returns
    -------
    str
        The function's C source (needs ``<math.h>``).
    """
    p = F32 if precision == "float32" else F64
    ins = [fn.name_in(i) for i in range(fn.n_in())]
    lines, outs, _ = _step_body(fn, ins, p)
    args = [f"const {p.ctype} {a}[{max(fn.nnz_in(i), 1)}]" for i, a in enumerate(ins)]
    args += [f"{p.ctype} {fn.name_out(i)}[{max(fn.numel_out(i), 1)}]" for i in range(fn.n_out())]
    body = [f"void {name}({', '.join(args)})", "{"]
    body += [f"    (void){a};" for a in ins]
    body += ["    " + ln for ln in lines]
    for i in range(fn.n_out()):
        body += [f"    {fn.name_out(i)}[{r}] = {outs.get((i, r), p.literal(0.0))};" for r in range(fn.numel_out(i))]
    return "\n".join(body + ["}", ""])


# ----------------------------------------------------------------------------------------------
# the files
# ----------------------------------------------------------------------------------------------


def _comment(text: str) -> str:
    """Text safe inside a C block comment (no comment terminator, ASCII-only)."""
    return text.replace("*/", "* /").encode("ascii", "replace").decode("ascii")


def _vec(a: Any) -> str:
    return "[" + ", ".join(repr(float(x)) for x in np.ravel(a)) + "]"


def _macro(prefix: str) -> str:
    return prefix.upper()


@dataclass(frozen=True)
class Printed:
    """The printed controller: the files' text and the code's size.

    Parameters
    ----------
    files : dict
        ``{"controller.h": text, "controller.c": text, "main.c": text}``.
    prefix : str
        The C names' prefix (``lv_controller``: ``lv_controller_step``, ``LV_CONTROLLER_N``).
    n_ops : int
        Arithmetic operations in one step (either precision).
    n_instructions : int
        Instructions of the CasADi Function it was printed from.
    lines : dict
        Lines per file.
    """

    files: dict
    prefix: str
    n_ops: int
    n_instructions: int
    lines: dict


def render(controller: Controller, *, prefix: str = PREFIX, source: str = "", example_q: Any = None) -> Printed:
    """Print a designed controller as C99 (``controller.h``, ``controller.c``, an example ``main.c``).

    Deterministic: the same controller prints byte-identical files (no dates, no paths but ``source``).

    Parameters
    ----------
    controller : Controller
        From :func:`lavendersim.control.design`.
    prefix : str, default "lv_controller"
        Prefix of every C name (a C identifier): ``{prefix}_step``, ``{prefix}_step_f32``, ``{prefix}_reset``,
        macros ``{PREFIX}_N`` ...
    source : str, optional
        Where the design came from (a spacecraft file's name), stated in the header.
    example_q : array_like (4,), optional
        The attitude main.c's single step starts from (x, y, z, w); default 10 degrees about body x from q_ref.

    Returns
    -------
    Printed

    Raises
    ------
    lavendersim.validate.LavenderInputError
        ``controller`` is not a Controller, ``prefix`` is not a C identifier.
    """
    if not isinstance(controller, Controller):
        raise V.LavenderInputError("controller", "must be a Controller from lavendersim.control.design",
                                   f", got {V._describe(controller)}")
    if not isinstance(prefix, str) or not prefix.isidentifier() or not prefix.isascii():
        raise V.LavenderInputError("prefix", "must be a C identifier (letters, digits, _)", f", got {prefix!r}")
    fn = controller.function
    names = ["q", "omega_b", "Omega", "q_ref", "z"]
    if [fn.name_in(i) for i in range(fn.n_in())] != names or [fn.name_out(i) for i in range(fn.n_out())] != ["u", "z_next"]:
        raise V.LavenderInputError("controller", "its function must be step(q, omega_b, Omega, q_ref, z) -> (u, z_next)")
    bodies = {p.ctype: _step_body(fn, names, p) for p in (F64, F32)}
    n_ops = bodies["double"][2]
    h = _header(controller, prefix, source, n_ops, fn.n_instructions())
    c = _source_c(controller, prefix, bodies)
    m = _main_c(controller, prefix, example_q)
    files = {"controller.h": h, "controller.c": c, "main.c": m}
    return Printed(files, prefix, n_ops, int(fn.n_instructions()), {k: v.count("\n") for k, v in files.items()})


def _dims(ctrl: Controller) -> tuple[int, int]:
    """(N, NZ as declared: at least 1, C99 has no zero-length arrays)."""
    return ctrl.n, max(ctrl.nz, 1)


def _signature(prefix: str, ctrl: Controller, p: _Precision) -> str:
    P = _macro(prefix)
    T = p.ctype
    return (f"int {prefix}_step{p.suffix}(const {T} q[4], const {T} omega_b[3], const {T} Omega[{P}_N],\n"
            f"    const {T} q_ref[4], {T} z[{P}_NZ], {T} u[{P}_N])")


def _header(ctrl: Controller, prefix: str, source: str, n_ops: int, n_instr: int) -> str:
    from . import __version__

    P = _macro(prefix)
    n, nz = _dims(ctrl)
    wh = ctrl.wheels
    guard = f"{P}_H"
    mem = []
    if ctrl.actuator_lag > 0:
        mem.append(f"the estimate of the lagged torque a ({n}, N*m)")
    if ctrl.delay > 0:
        mem.append(f"the previous command ({n}, N*m)")
    memory = " then ".join(mem) if mem else "none (one unused slot: C99 has no zero-length arrays)"
    axes = "\n".join(f" *   wheel {i + 1}: {_vec(a)}" for i, a in enumerate(wh.axes_b))
    d = ctrl.figures()
    lines = [
        "/* Reaction-wheel attitude controller, printed by lavendersim " + _comment(__version__) + " (lavendersim.controller_c).",
        " * Do not edit: regenerate with `lavendersim lqr --spacecraft FILE --export-c DIR` or",
        " * lavendersim.controller_c.export_c(controller, DIR).",
        " *",
        f" * Design: body {_comment(repr(ctrl.body))}" + (f", from {_comment(source)}" if source else "") + ".",
        f" *   discrete LQR (lavendersim.control.design) on the zero-order-hold discretization at the period,",
        f" *   controllability rank {ctrl.rank} of {d['n_states']} states, largest closed-loop |z| "
        f"{d['max_pole_modulus']:.9f}.",
        f" *   Sample period {ctrl.Ts!r} s; computation delay {ctrl.delay!r} s (the command computed from the",
        " *   sample at t_k is to act from t_k + delay, held until the next one: zero-order hold);",
        f" *   actuator lag modelled {ctrl.actuator_lag!r} s (first order).",
        f" *   Design attitude q_ref (x, y, z, w) = {_vec(ctrl.q_ref)}",
        f" *   Operating wheel rates Omega_ref = {_vec(ctrl.Omega_ref)} rad/s (null-space bias),",
        f" *   operating torques u0 = {_vec(ctrl.u0)} N*m.",
        f" *   Wheels: {n}, rank of the axes {ctrl.rank_axes}; J = {_vec(wh.J)} kg*m^2;",
        f" *   torque limit {wh.torque_limit!r} N*m (every command is saturated to it), speed limit",
        f" *   {wh.speed_limit!r} rad/s (not enforced here: the motor line's), bearing damping {wh.c_w!r} N*m*s/rad.",
        " *   Spin axes, body frame (unit):",
        axes,
        " *",
        " * Step (call once per sample period; float64 and float32 variants, the same operations):",
        " *   q        measured attitude, body to world, quaternion (x, y, z, w), unit",
        " *   omega_b  measured body rate, body frame, rad/s",
        f" *   Omega    measured wheel rates relative to the body, rad/s ({P}_N wheels, in the order above)",
        " *   q_ref    reference attitude, body to world, (x, y, z, w), unit (normally the design's q_ref)",
        f" *   z        the controller's memory ({P}_NZ), read and updated in place: {memory};",
        f" *            set it once with {prefix}_reset before the first step",
        f" *   u        wheel motor torque commands, N*m, each within +-{P}_TORQUE_LIMIT",
        " *   returns  0; 1 if any input (q, omega_b, Omega, q_ref, z) is not finite: then u = u0 and z is unchanged",
        " *",
        f" * Printed from the controller's CasADi expressions ({n_instr} instructions): attitude error chart",
        " * dtheta = 2 sign(e_w) e_v, e = q_ref* (x) q; -L x - L_z (z - z0); allocation; saturation; memory update.",
        f" * {n_ops} arithmetic operations per step; no allocation, no globals but static const data, libm only.",
        " */",
        f"#ifndef {guard}",
        f"#define {guard}",
        "",
        f"#define {P}_N {n}                 /* wheels */",
        f"#define {P}_NZ {nz}                /* memory size */",
        f"#define {P}_PERIOD {ctrl.Ts!r}          /* s */",
        f"#define {P}_DELAY {ctrl.delay!r}            /* s */",
        f"#define {P}_TORQUE_LIMIT {wh.torque_limit!r}   /* N*m */",
        f"#define {P}_SPEED_LIMIT {wh.speed_limit!r}     /* rad/s */",
        "",
        f"void {prefix}_reset(double z[{P}_NZ]);",
        _signature(prefix, ctrl, F64) + ";",
        f"void {prefix}_reset_f32(float z[{P}_NZ]);",
        _signature(prefix, ctrl, F32) + ";",
        "",
        f"#endif /* {guard} */",
        "",
    ]
    return "\n".join(lines)


def _source_c(ctrl: Controller, prefix: str, bodies: dict) -> str:
    P = _macro(prefix)
    n, nz = _dims(ctrl)
    z0 = ctrl.z0 if ctrl.nz else np.zeros(1)
    out = [f"/* {prefix}: printed by lavendersim.controller_c from the controller's CasADi expressions; see controller.h. */",
           '#include "controller.h"', "", "#include <math.h>", ""]
    for p in (F64, F32):
        T = p.ctype
        lines, outs, _ = bodies[T]
        lit = [p.literal(float(v)) for v in z0]
        u0 = [p.literal(float(v)) for v in ctrl.u0]
        s = p.suffix
        out += [f"static const {T} {prefix}_z0{s}[{P}_NZ] = {{{', '.join(lit)}}};",
                f"static const {T} {prefix}_u0{s}[{P}_N] = {{{', '.join(u0)}}};", "",
                f"static int {prefix}_finite{s}(const {T} *x, int n)", "{", "    int i;",
                "    for (i = 0; i < n; ++i) {", "        if (!isfinite(x[i])) {", "            return 0;", "        }",
                "    }", "    return 1;", "}", "",
                f"void {prefix}_reset{s}({T} z[{P}_NZ])", "{", "    int i;",
                f"    for (i = 0; i < {P}_NZ; ++i) {{", f"        z[i] = {prefix}_z0{s}[i];", "    }", "}", "",
                _signature(prefix, ctrl, p), "{",
                f"    if (!({prefix}_finite{s}(q, 4) && {prefix}_finite{s}(omega_b, 3) && {prefix}_finite{s}(Omega, {P}_N)",
                f"          && {prefix}_finite{s}(q_ref, 4) && {prefix}_finite{s}(z, {P}_NZ))) {{",
                "        int i;", f"        for (i = 0; i < {P}_N; ++i) {{", f"            u[i] = {prefix}_u0{s}[i];",
                "        }", "        return 1;", "    }", "    {"]
        out += ["        " + ln for ln in lines]
        for i in range(ctrl.nz):
            out.append(f"        z[{i}] = {outs.get((1, i), p.literal(0.0))};")
        for i in range(ctrl.n):
            out.append(f"        u[{i}] = {outs.get((0, i), p.literal(0.0))};")
        out += ["    }", "    return 0;", "}", ""]
    return "\n".join(out)


def _main_c(ctrl: Controller, prefix: str, example_q: Any) -> str:
    from .kernels import K as KN

    P = _macro(prefix)
    if example_q is None:
        example_q = np.asarray(KN.quat_mul(ctrl.q_ref, KN.axis_angle_to_quat(np.array([1.0, 0, 0]), math.radians(10))),
                               dtype=float)
        where = "the attitude 10 degrees about body x off q_ref"
    else:
        example_q = V.quaternion("example_q", example_q)
        where = "the given attitude"
    arr = lambda a: "{" + ", ".join(repr(float(v)) for v in np.ravel(a)) + "}"   # noqa: E731
    return "\n".join([
        f"/* One step of {prefix} (see controller.h): {where}, at rest, wheels at",
        " * their operating rates. Build: cc -std=c99 -Wall -Wextra -pedantic -Werror main.c controller.c -lm */",
        "#include <stdio.h>", "", '#include "controller.h"', "",
        "int main(void)", "{",
        f"    const double q[4] = {arr(example_q)};",
        "    const double omega_b[3] = {0.0, 0.0, 0.0};",
        f"    const double Omega[{P}_N] = {arr(ctrl.Omega_ref)};",
        f"    const double q_ref[4] = {arr(ctrl.q_ref)};",
        f"    double z[{P}_NZ];", f"    double u[{P}_N];", "    int i;",
        f"    {prefix}_reset(z);",
        f"    if ({prefix}_step(q, omega_b, Omega, q_ref, z, u) != 0) {{",
        '        fprintf(stderr, "non-finite input\\n");', "        return 1;", "    }",
        f"    for (i = 0; i < {P}_N; ++i) {{", '        printf("u[%d] = %.17g N*m\\n", i, u[i]);', "    }",
        "    return 0;", "}", ""])


def export_c(controller: Controller, directory: str | os.PathLike, *, prefix: str = PREFIX, source: str = "",
             example_q: Any = None) -> Printed:
    """Write ``controller.h``, ``controller.c`` and ``main.c`` (see :func:`render`) into ``directory``.

    Parameters
    ----------
    controller : Controller
    directory : str or os.PathLike
        Created if missing; existing files of those names are replaced.
    prefix, source, example_q
        As :func:`render`.

    Returns
    -------
    Printed

    Raises
    ------
    lavendersim.validate.LavenderInputError
        A bad controller or prefix, or ``directory`` cannot be created or is a file.
    """
    printed = render(controller, prefix=prefix, source=source, example_q=example_q)
    d = V.writable_dir("directory", directory)
    for name, text in printed.files.items():   # never through a link planted in the folder
        replace_file(d / name, text, encoding="ascii")
    return printed


# ----------------------------------------------------------------------------------------------
# compiling and flying the printed C
# ----------------------------------------------------------------------------------------------


def compile_command(sources: list[str], output: str, *, shared: bool = True) -> list[str]:
    """The compiler command used for the printed files: $CC (else cc, gcc) with :data:`CFLAGS`.

    Parameters
    ----------
    sources : list of str
        C files.
    output : str
        The file to write.
    shared : bool, default True
        A shared library (``-fPIC -shared``); False: an executable.

    Returns
    -------
    list of str
    """
    from .extending import compiler

    return [*compiler(), *CFLAGS, *(("-fPIC", "-shared") if shared else ()), *sources, "-o", output, "-lm"]


def compile_library(printed: Printed, directory: str | os.PathLike | None = None) -> tuple[Path, list[str]]:
    """Compile the printed ``controller.c`` into a shared library with the strict flags.

    Parameters
    ----------
    printed : Printed
    directory : str or os.PathLike, optional
        Where to write the sources and the library (default: a new temporary directory).

    Returns
    -------
    path : Path
        The library.
    command : list of str
        The compiler command run.

    Raises
    ------
    CompileError
        The compiler failed or is missing (the command and its full output in the message).
    """
    from .extending import UserBuildError

    d = Path(tempfile.mkdtemp(prefix="lv_controller_c_") if directory is None else directory)
    d.mkdir(parents=True, exist_ok=True)
    for name in ("controller.h", "controller.c"):
        replace_file(d / name, printed.files[name], encoding="ascii")
    digest = hashlib.sha256(printed.files["controller.c"].encode()).hexdigest()[:12]
    lib = d / f"lib{printed.prefix}_{digest}.so"
    try:
        cmd = compile_command(["controller.c"], lib.name)
    except UserBuildError as exc:
        raise CompileError(str(exc)) from None
    run = subprocess.run(cmd, cwd=d, capture_output=True, text=True)
    if run.returncode != 0:
        raise CompileError(f"compiling the printed controller failed in {d}:\n$ {' '.join(cmd)}\n{run.stdout}{run.stderr}")
    return lib, cmd


class CompiledController(Controller):
    """A :class:`Controller` whose step is the printed C, compiled: ``command`` calls ``{prefix}_step[_f32]`` (ctypes).

    Everything else (gains, limits, ``Ts``, ``Omega_ref`` ...) is the design's, so
    :func:`lavendersim.control.closed_loop` flies it as it flies the Python controller.

    Parameters
    ----------
    controller : Controller
        The design (copied; not changed).
    precision : {"float64", "float32"}, default "float64"
        Which printed step to call.
    printed : Printed, optional
        Default :func:`render` ``(controller)``.
    library : path-like, optional
        A library already compiled from ``printed`` (:func:`compile_library`); default: compiled now.
    command : list of str, optional
        The command ``library`` was compiled with (reported).

    Attributes
    ----------
    precision : str
    library : Path
        The shared library.
    compile_command : list of str
    printed : Printed
    """

    def __init__(self, controller: Controller, *, precision: str = "float64", printed: Printed | None = None,
                 library: str | os.PathLike | None = None, command: list | None = None):
        if not isinstance(controller, Controller):
            raise V.LavenderInputError("controller", "must be a Controller from lavendersim.control.design",
                                       f", got {V._describe(controller)}")
        if precision not in ("float64", "float32"):
            raise V.LavenderInputError("precision", "must be 'float64' or 'float32'", f", got {precision!r}")
        printed = render(controller) if printed is None else printed
        if library is None:
            library, command = compile_library(printed)
        self.__dict__.update(controller.__getstate__())
        self._fn = controller._fn
        self.precision, self.library, self.compile_command, self.printed = precision, Path(library), list(command or []), printed
        lib = ctypes.CDLL(str(library))
        s = "_f32" if precision == "float32" else ""
        ptr = ctypes.POINTER(ctypes.c_float if precision == "float32" else ctypes.c_double)
        self._dtype = np.float32 if precision == "float32" else np.float64
        self._step = getattr(lib, f"{printed.prefix}_step{s}")
        self._step.argtypes = [ptr] * 6
        self._step.restype = ctypes.c_int
        self._reset = getattr(lib, f"{printed.prefix}_reset{s}")
        self._reset.argtypes = [ptr]
        self._reset.restype = None
        self._ptr = ptr
        self._lib = lib
        self.reset()

    def reset(self) -> None:
        """The memory z at the operating torque, set by the printed ``{prefix}_reset``."""
        self._zbuf = np.zeros(max(self.nz, 1), dtype=self._dtype)
        self._reset(self._zbuf.ctypes.data_as(self._ptr))
        self.z = self._zbuf[:self.nz].astype(float)

    def command(self, meas_q, meas_omega_b, meas_Omega, q_ref=None) -> np.ndarray:
        """The printed step's wheel torques (N,), N·m (float64 values of the chosen precision's results), advancing z.

        Parameters
        ----------
        meas_q : array_like (4,)
            Measured attitude, body to world, (x, y, z, w), unit.
        meas_omega_b : array_like (3,)
            Measured body rate, body frame, rad/s.
        meas_Omega : array_like (N,)
            Measured wheel rates relative to the body, rad/s.
        q_ref : array_like (4,), optional
            Reference attitude (default: the design's ``q_ref``).

        Returns
        -------
        ndarray (N,)

        Raises
        ------
        FloatingPointError
            The step refused a non-finite input (returned 1).
        """
        dt = self._dtype
        args = [np.ascontiguousarray(a, dtype=dt) for a in
                (meas_q, meas_omega_b, meas_Omega, self.q_ref if q_ref is None else q_ref)]
        u = np.zeros(self.n, dtype=dt)
        rc = self._step(*[a.ctypes.data_as(self._ptr) for a in args], self._zbuf.ctypes.data_as(self._ptr),
                        u.ctypes.data_as(self._ptr))
        if rc != 0:
            raise FloatingPointError(f"{self.printed.prefix}_step: a non-finite input (returned {rc})")
        self.z = self._zbuf[:self.nz].astype(float)
        return u.astype(float)

    def __copy__(self) -> "CompiledController":
        """A copy sharing the loaded library, with its own memory z."""
        new = type(self).__new__(type(self))
        new.__dict__.update(self.__dict__)
        new._zbuf = self._zbuf.copy()
        new.z = self.z.copy()
        return new

    def __getstate__(self):
        raise TypeError("a CompiledController holds a loaded library and does not pickle (another process cannot "
                        "use it); send its Controller and compile there")


# ----------------------------------------------------------------------------------------------
# software in the loop
# ----------------------------------------------------------------------------------------------

COMMAND_REL_TOL = 1e-12      # float64: max relative command difference at any sample (issue 27)
TRAJECTORY_TOL = 1e-9        # float64: max |difference| of q, omega_b (rad/s), Omega (rad/s) at any sample
SETTLE_REL_TOL = 0.05        # float32: settling time within 5 % of float64's


@dataclass
class SilReport:
    """The printed controller flown in the loop against the Python one (same plant, same sensor noise).

    Parameters
    ----------
    command_rel_f64 : float
        max over samples of ``max_i |u_C − u_py| / max_i |u_py|`` (the C float64 step), 0 when identical.
    commands_identical_f64 : bool
        Every float64 command bit for bit equal to the Python one.
    trajectory_diff_f64 : float
        max over samples of |Δq|, |Δomega_b| (rad/s), |ΔOmega| (rad/s), float64 run against Python's.
    command_diff_f32 : float
        Worst |u_C32 − u_py| at any sample, N·m (the float32 run flies its own trajectory).
    command_diff_f32_rel_limit : float
        ``command_diff_f32 / torque_limit``.
    command_diff_f32_replay : float
        Worst |u_C32 − u_py| when the float32 step is fed the Python run's own measurements (the
        step's rounding alone, without the trajectory's divergence), N·m.
    trajectory_diff_f32 : float
        As ``trajectory_diff_f64`` for the float32 run.
    settling_time_python, settling_time_f64, settling_time_f32 : float
        Settling times, s.
    settle_rel_f32 : float
        ``|t_f32 − t_f64| / t_f64``.
    samples : int
        Controller samples compared.
    compile_command : str
    n_ops, n_instructions : int
        Arithmetic operations in the printed step; instructions of the CasADi Function.
    lines : dict
        Lines per printed file.
    """

    command_rel_f64: float
    commands_identical_f64: bool
    trajectory_diff_f64: float
    command_diff_f32: float
    command_diff_f32_rel_limit: float
    command_diff_f32_replay: float
    trajectory_diff_f32: float
    settling_time_python: float
    settling_time_f64: float
    settling_time_f32: float
    settle_rel_f32: float
    samples: int
    compile_command: str
    n_ops: int
    n_instructions: int
    lines: dict = field(default_factory=dict)

    @property
    def ok(self) -> bool:
        """float64 commands within COMMAND_REL_TOL, trajectories within TRAJECTORY_TOL, float32 settling within 5 %."""
        return bool(self.command_rel_f64 <= COMMAND_REL_TOL and self.trajectory_diff_f64 <= TRAJECTORY_TOL
                    and self.settle_rel_f32 <= SETTLE_REL_TOL)

    def figures(self) -> dict:
        """Plain values (JSON-ready but for an infinite settling time), with ``ok`` and the tolerances."""
        d = {k: getattr(self, k) for k in self.__dataclass_fields__}
        d.update(ok=self.ok, tolerances={"command_rel_f64": COMMAND_REL_TOL, "trajectory_f64": TRAJECTORY_TOL,
                                         "settle_rel_f32": SETTLE_REL_TOL})
        return d


def _trajectory_diff(a: Any, b: Any) -> float:
    return float(max(np.abs(a.q - b.q).max(), np.abs(a.omega_b - b.omega_b).max(), np.abs(a.Omega - b.Omega).max()))


def _command_rel(ref: np.ndarray, other: np.ndarray) -> float:
    num = np.abs(other - ref).max(axis=1)
    den = np.maximum(np.abs(ref).max(axis=1), 1e-300)
    return float((num / den).max())


def replay(controller: Controller, response: Any) -> np.ndarray:
    """The commands ``controller`` computes from a run's recorded measurements, in order (memory reset first).

    Parameters
    ----------
    controller : Controller
        Any controller (a CompiledController: the printed step on the Python run's inputs).
    response : Response
        A closed-loop run (its ``q_meas``, ``omega_meas``, ``Omega_meas``, ``q_ref``).

    Returns
    -------
    ndarray (K, N)
        One command per sample but the last (which computes none), N·m.
    """
    controller.reset()
    K = response.t.size - 1
    return np.array([controller.command(response.q_meas[k], response.omega_meas[k], response.Omega_meas[k], response.q_ref)
                     for k in range(K)]).reshape(K, controller.n)


def compare(reference: Any, f64: Any, f32: Any, torque_limit: float, printed: Printed, command: list,
            replay_f32: np.ndarray | None = None) -> SilReport:
    """A :class:`SilReport` from three Responses of one maneuver: Python, C float64, C float32.

    Parameters
    ----------
    reference, f64, f32 : Response
        The Python controller's run and the printed steps' runs (same plant, same sensor noise).
    torque_limit : float
        N·m.
    printed : Printed
    command : list of str
        The compile command.
    replay_f32 : ndarray (K, N), optional
        The float32 step's commands on the Python run's measurements (:func:`replay`).

    Returns
    -------
    SilReport
    """
    st = [r.settling_time() for r in (reference, f64, f32)]
    srel = abs(st[2] - st[1]) / st[1] if math.isfinite(st[1]) and st[1] > 0 else (0.0 if st[2] == st[1] else math.inf)
    d32 = float(np.abs(f32.commands - reference.commands).max())
    rep = math.nan if replay_f32 is None else float(np.abs(replay_f32 - reference.commands[:-1]).max())
    return SilReport(_command_rel(reference.commands, f64.commands), bool(np.array_equal(reference.commands, f64.commands)),
                     _trajectory_diff(reference, f64), d32, d32 / torque_limit, rep, _trajectory_diff(reference, f32),
                     st[0], st[1], st[2], srel, int(reference.t.size - 1), " ".join(command), printed.n_ops,
                     printed.n_instructions, dict(printed.lines))


def verify(controller: Controller, fly: Callable[[Controller], Any], *, reference: Any = None, printed: Printed | None = None,
           directory: str | os.PathLike | None = None) -> SilReport:
    """Software in the loop: compile the printed controller and fly it (float64, float32) as ``fly`` flies the Python one.

    Parameters
    ----------
    controller : Controller
    fly : callable
        ``fly(controller) -> Response``: one maneuver (e.g. ``lambda c: closed_loop(scene, c, T=...,
        sensors=...)``); called with the C controllers, and with ``controller`` unless ``reference`` is given.
        It must reproduce its sensor noise (a seeded Sensors) so the runs see the same noise.
    reference : Response, optional
        The Python controller's run of the same maneuver (saves flying it again).
    printed : Printed, optional
        Default :func:`render` ``(controller)``.
    directory : str or os.PathLike, optional
        Where to compile and keep the library (default a temporary directory, removed once the library is loaded).

    Returns
    -------
    SilReport

    Raises
    ------
    CompileError
        The printed files do not compile with the strict flags (or no compiler).
    """
    printed = render(controller) if printed is None else printed
    with tempfile.TemporaryDirectory(prefix="lv_controller_c_") as tmp:   # the library is loaded before it goes
        lib, cmd = compile_library(printed, tmp if directory is None else directory)
        compiled = [CompiledController(controller, precision=p, printed=printed, library=lib, command=cmd)
                    for p in ("float64", "float32")]
    ref = fly(controller) if reference is None else reference
    runs = [fly(c) for c in compiled]
    return compare(ref, runs[0], runs[1], controller.wheels.torque_limit, printed, cmd, replay(compiled[1], ref))


def sil(scene: Any, controller: Controller, *, T: float, directory: str | os.PathLike | None = None,
        **closed_loop_kw: Any) -> SilReport:
    """:func:`verify` on ``lavendersim.control.closed_loop(scene, controller, T=T, **closed_loop_kw)``.

    Parameters
    ----------
    scene : Scene
        The plant.
    controller : Controller
    T : float
        Duration, s.
    directory : str or os.PathLike, optional
        Where to compile.
    **closed_loop_kw
        q0, omega0, Omega0, sensors (seeded: every run sees the same noise), dt, backend, ...

    Returns
    -------
    SilReport
    """
    from .wheel_control import closed_loop

    return verify(controller, lambda c: closed_loop(scene, c, T=T, **closed_loop_kw), directory=directory)


def export_and_verify(controller: Controller, directory: str | os.PathLike, fly: Callable[[Controller], Any], *,
                      reference: Any = None, source: str = "") -> dict:
    """:func:`export_c`, then :func:`verify` (compiled in a temporary directory): what ``lavendersim lqr --export-c`` reports.

    Parameters
    ----------
    controller : Controller
    directory : str or os.PathLike
        Receives controller.h, controller.c, main.c.
    fly : callable
        ``fly(controller) -> Response`` (seeded sensors).
    reference : Response, optional
        The Python controller's run of that maneuver.
    source : str, optional
        Stated in the header.

    Returns
    -------
    dict
        ``directory``, ``files``, ``lines``, ``n_ops``, ``n_instructions``, ``compile_command`` (or None),
        ``sil`` (:meth:`SilReport.figures`, or None when no C compiler is found or the files do not compile: then
        ``sil_skipped`` says why, and ``compile_error`` holds the command and the compiler's output).
    """
    from .extending import UserBuildError, compiler

    d = Path(directory)
    printed = export_c(controller, d, source=source)
    out = {"directory": str(d), "files": list(FILES), "lines": dict(printed.lines), "n_ops": printed.n_ops,
           "n_instructions": printed.n_instructions, "compile_command": None, "sil": None, "sil_skipped": None,
           "compile_error": None}
    try:
        compiler()
    except UserBuildError as exc:
        out["sil_skipped"] = str(exc)
        return out
    try:
        rep = verify(controller, fly, reference=reference, printed=printed)
    except CompileError as exc:
        out["sil_skipped"], out["compile_error"] = "the printed files did not compile", str(exc)
        return out
    out["compile_command"] = rep.compile_command
    out["sil"] = rep.figures()
    return out


def summary(report: dict) -> str:
    """Text lines of :func:`export_and_verify`'s report (the CLI's).

    Parameters
    ----------
    report : dict
        From :func:`export_and_verify`.

    Returns
    -------
    str
    """
    lines = [f"exported C99: {', '.join(report['files'])} in {report['directory']} ({report['lines']['controller.c']} "
             f"lines of controller.c, {report['n_ops']} operations per step)"]
    s = report["sil"]
    if s is None:
        return "\n".join(lines + [f"software in the loop skipped: {report['sil_skipped']}"])
    st = lambda v: f"{v:.4g} s" if math.isfinite(v) else "never"   # noqa: E731
    lines += [f"compiled: {s['compile_command']}",
              f"software in the loop, float64: max relative command difference {s['command_rel_f64']:.3g} "
              f"({'bit-identical' if s['commands_identical_f64'] else 'not bit-identical'}), max trajectory difference "
              f"{s['trajectory_diff_f64']:.3g}",
              f"float32: settles {st(s['settling_time_f32'])} (float64 {st(s['settling_time_f64'])}, "
              f"{100 * s['settle_rel_f32']:.3g} %), worst command difference {s['command_diff_f32']:.3g} N·m "
              f"({s['command_diff_f32_rel_limit']:.3g} of the limit); SIL {'passed' if s['ok'] else 'FAILED'}"]
    return "\n".join(lines)
