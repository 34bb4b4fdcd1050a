"""User declarations: effects and kernels declared in one file outside the package, printed like ours.

A declaration file is plain Python that imports ``lavendersim.derive.effect`` (and, for plain kernels,
``lavendersim.derive.kernel``) and defines ``EFFECTS`` (a list of ``effect(...)``), ``KERNELS``
(a list of ``Kernel(...)``) and/or ``TABLEAUX`` (a list of :func:`tableau`, explicit Runge–Kutta methods). Its set name is the file's stem. :func:`render_user` prints, with the
same printers as the built-ins: kernels.h / kernels.c (one shared library: kernels ``lvu_<set>_*``,
effects ``lvu_effect_<name>``), kernels_numpy.py (kernels and the effects' NumPy dispatch),
kernels_casadi.py, effects_meta.py (the metadata lavendersim.effects reads) and EQUATIONS.md.
``lavendersim derive --user FILE`` writes them and compiles the library (lavendersim.extending).

Everything that can go wrong with a declaration — the file raises, ``EFFECTS`` is not a list, a
``STATE`` field that does not exist, a bad shape, a function one of the printers has no mapping for,
an expression nested too deeply for SymPy — raises :class:`DeclarationError`, one line naming the
file (and the line, effect or kernel) and the problem.
"""
from __future__ import annotations

import hashlib
import importlib.util
import re
import sys
import traceback
from collections.abc import Sequence
from dataclasses import dataclass
from fractions import Fraction
from functools import lru_cache
from pathlib import Path

import numpy as np
import sympy as sp

from .effect import EffectDecl
from .kernel import Kernel
from .tableaux import _real_axis_limit, _stability_polynomial, imaginary_axis_bound, integrator_names

_SET_NAME = re.compile(r"^[a-z][a-z0-9_]*$")


class DeclarationError(ValueError):
    """A declaration file that cannot be derived; the message is one line naming the file and the
    effect, kernel or line at fault."""


def set_name_of(path: Path) -> str:
    """The set name of a declaration file: its stem (lowercase letters, digits, _)."""
    stem = Path(path).stem
    if not _SET_NAME.match(stem):
        raise DeclarationError(f"{path}: the file name (without .py) names the set and must be lowercase letters, "
                               f"digits and _, starting with a letter, e.g. my_effects.py; got {stem!r}")
    return stem


def _one_line(text: object) -> str:
    return " ".join(str(text).split())


def _explain(exc: BaseException) -> str:
    """An exception raised while running a declaration, in words (the common mistakes named)."""
    if isinstance(exc, RecursionError):
        return ("an expression is nested too deeply for SymPy (RecursionError); build a long sum or product "
                "in one call, sp.Add(*terms) or sp.Mul(*factors), not term by term in a loop")
    m = re.match(r"'_State' object has no attribute '(\w+)'", str(exc))
    if isinstance(exc, AttributeError) and m:
        from .effect import STATE, _State

        fields = list(_State.FIELDS) + [n for n in ("R_WB", "omega_w") if hasattr(STATE, n)]
        return f"STATE has no field {m[1]!r} (STATE's fields: {', '.join(fields)})"
    if type(exc) is ValueError:   # derive's own checks (effect, param, Kernel): their message names the culprit
        return _one_line(exc)
    return f"{type(exc).__name__}: {_one_line(exc)}"


def _line_in(path: Path, exc: BaseException) -> str:
    """' line N' of the innermost frame of the traceback that is in the declaration file, or ''."""
    line = ""
    for frame, lineno in traceback.walk_tb(exc.__traceback__):
        if Path(frame.f_code.co_filename) == path:
            line = f" line {lineno}"
    return line


def load_declarations(path) -> tuple[list[EffectDecl], list[Kernel], list["TableauDecl"]]:
    """Run a declaration file and return its EFFECTS, KERNELS and TABLEAUX (each optional, not all empty).

    Raises
    ------
    FileNotFoundError
        No such file.
    DeclarationError
        The file raises when run, or declares something that is not an effect or kernel (one line).
    """
    path = Path(path).resolve()
    if not path.is_file():
        raise FileNotFoundError(f"{path}: no such declaration file")
    name = f"lavendersim_user_declaration_{set_name_of(path)}"
    spec = importlib.util.spec_from_file_location(name, path)
    if spec is None or spec.loader is None:   # a name Python does not load as source (no .py)
        raise DeclarationError(f"{path}: a declaration file is Python source: its name must end in .py")
    module = importlib.util.module_from_spec(spec)
    sys.modules[name] = module
    try:
        spec.loader.exec_module(module)
    except SyntaxError as exc:
        raise DeclarationError(f"{path} line {exc.lineno}: not valid Python: {exc.msg}") from None
    except Exception as exc:  # the user's code: anything it raises is reported in one line, never a traceback
        raise DeclarationError(f"{path}{_line_in(path, exc)}: {_explain(exc)}") from exc
    finally:
        sys.modules.pop(name, None)
    effects = _listed(path, module, "EFFECTS", EffectDecl, "an effect(...) of lavendersim.derive.effect")
    kernels = _listed(path, module, "KERNELS", Kernel, "a Kernel(...) of lavendersim.derive.kernel")
    tableaux = _listed(path, module, "TABLEAUX", TableauDecl, "a tableau(...) of lavendersim.derive.user")
    if not effects and not kernels and not tableaux:
        raise DeclarationError(f"{path}: declares nothing; define EFFECTS = [effect(...), ...], "
                               "KERNELS = [Kernel(...), ...] and/or TABLEAUX = [tableau(...), ...]")
    for e in effects:
        if e.kind != "force":
            raise DeclarationError(f"{path}: EFFECTS[{effects.index(e)}] ({e.name!r}) is a model effect; a user set "
                                   "declares force effects made with effect()")
    # an effect's kernel effect_<name> (C: lvu_effect_<name>), its body-frame form's effect_<name>_b (torque_b alone:
    # lvu_effect_<name>_b) and the plain kernels share one namespace
    names = ([e.kernel_name for e in effects] + [e.kernel_name + "_b" for e in effects if e.body_outputs is not None]
             + [k.name for k in kernels])
    dup = sorted({n for n in names if names.count(n) > 1})
    dup = dup or sorted({t.name for t in tableaux if [u.name for u in tableaux].count(t.name) > 1})
    if dup:
        raise DeclarationError(f"{path}: duplicate names {dup}")
    return effects, kernels, tableaux


def _listed(path: Path, module, attr: str, cls, what: str) -> list:
    value = getattr(module, attr, [])
    if not isinstance(value, (list, tuple)):
        raise DeclarationError(f"{path}: {attr} must be a list, each item {what}; got {type(value).__name__} "
                               f"{_one_line(repr(value))[:60]}")
    for i, v in enumerate(value):
        if not isinstance(v, cls):
            raise DeclarationError(f"{path}: {attr}[{i}] must be {what}, got {type(v).__name__} "
                                   f"{_one_line(repr(v))[:60]}")
    return list(value)


def _label(k: Kernel) -> str:
    return f"effect {k.name[len('effect_'):]!r}" if k.name.startswith("effect_") else f"kernel {k.name!r}"


def _probe(path: Path, k: Kernel, printers: dict) -> None:
    """Every function the kernel's outputs apply, printed alone by each printer (innermost first):
    a function a printer has no mapping for (or prints as non-vectorized Python) raises naming the
    effect or kernel, the function and the backend."""
    apps = set()
    for e in k.output_exprs:
        apps |= sp.sympify(e).atoms(sp.Function)
    for app in sorted(apps, key=lambda a: (sp.count_ops(a), sp.srepr(a))):
        if isinstance(app, sp.Piecewise):
            continue
        try:
            probe = app.func(*(sp.Dummy(real=True) for _ in app.args))
        except Exception:  # noqa: BLE001 - a function of a fixed arity or argument kind: probe it as written
            probe = app
        fname = getattr(app.func, "__name__", str(app.func))
        for backend, printer in printers.items():
            try:
                text = printer.doprint(probe)
            except Exception:  # noqa: BLE001 - the printers raise several types for an unknown function
                raise DeclarationError(f"{path}: {_label(k)} uses {fname}(), which the {backend} printer cannot "
                                       f"print (no {backend} function for it); write it with functions C99, NumPy "
                                       "and CasADi all have (sin, cos, tan, exp, log, sqrt, tanh, ...)") from None
            if backend == "NumPy" and re.search(r"(?<!vectorize\()\bmath\.", text):   # math.f: one number at a time
                raise DeclarationError(f"{path}: {_label(k)} uses {fname}(), which NumPy has no vectorized function "
                                       "for (the NumPy backend steps every body at once)")


def _printers() -> dict:
    from . import codegen

    return {"C": codegen.CPrinter(), "NumPy": codegen.NpPrinter(), "CasADi": codegen.CasadiPrinter()}


def _printed(path: Path, k: Kernel, printers: dict):
    from . import codegen

    try:
        _probe(path, k, printers)
        return codegen.Printed(k)
    except DeclarationError:
        raise
    except RecursionError:
        raise DeclarationError(f"{path}: {_label(k)}: an expression is nested too deeply to print (RecursionError); "
                               "build a long sum or product in one call, sp.Add(*terms) or sp.Mul(*factors)") from None
    except Exception as exc:  # noqa: BLE001 - SymPy's CSE / our checks: one line naming the kernel
        raise DeclarationError(f"{path}: {_label(k)}: {_explain(exc)}") from exc


def _print_files(printed: list, effects: list, set_name: str, extra: dict, tableaux: tuple = ()) -> dict[str, str]:
    from . import codegen
    from .effect_print import meta_module

    header = codegen.USER_HEADER
    coded = [(None, e) for e in effects]
    h, c = codegen.print_c_user(printed, effects, set_name)
    md = codegen.print_markdown(printed, coded, title=f"User equations: {set_name}", header=header)
    if tableaux:   # the same doubles for C (exported arrays) and Python (effects_meta.TABLEAUX)
        th, tc = _c_tableaux(tableaux)
        h = h[:h.rindex("#endif")] + "\n".join(th) + "\n\n#endif\n"
        c, md = c + "\n".join(tc) + "\n", md + _md_tableaux(tableaux)
        extra = {**extra, "tableaux": tuple(t.meta() for t in tableaux)}
    return {"kernels.h": h, "kernels.c": c,
            "kernels_numpy.py": codegen.print_numpy(printed, coded, header=header),
            "kernels_casadi.py": codegen.print_casadi(printed, header=header),
            "effects_meta.py": meta_module(coded, header, extra), "EQUATIONS.md": md}


def _culprit(printed: list, decls: list, set_name: str, extra: dict) -> str:
    """'effect NAME: ' / 'kernel NAME: ' of the first declaration that fails to print on its own, or ''."""
    for p, d in zip(printed, decls):
        try:
            _print_files([p], [] if isinstance(d, Kernel) else [d], set_name, extra)
        except Exception:  # noqa: BLE001 - found it
            return f"{_label(p.k)}: "
    return ""


def _effect_kernels(path: Path, e: EffectDecl) -> list[Kernel]:
    """The effect's kernel and, for an effect declaring torque_b alone (FLAG_TORQUE_B), its body-frame form's."""
    try:
        body = e.body_kernel(group="User effects")
        return [e.kernel(group="User effects")] + ([body] if body is not None else [])
    except Exception as exc:  # noqa: BLE001 - one line naming the effect
        raise DeclarationError(f"{path}: effect {e.name!r}: {_explain(exc)}") from exc


def render_user(path) -> tuple[str, dict[str, str]]:
    """(set name, {file name: text}) for a declaration file, printed deterministically.

    Raises
    ------
    DeclarationError
        One line naming the file and the effect or kernel that cannot be derived or printed.
    """
    path = Path(path).resolve()
    set_name = set_name_of(path)
    effects, kernels, tableaux = load_declarations(path)
    printers = _printers()
    user_kernels = [(k, k) for k in kernels] + [(ek, e) for e in effects for ek in _effect_kernels(path, e)]
    printed = [_printed(path, k, printers) for k, _ in user_kernels]
    extra = {"set_name": set_name, "declaration": str(path),
             "declaration_sha256": hashlib.sha256(path.read_bytes()).hexdigest(),
             "kernels": tuple(k.name for k in kernels)}
    try:
        files = _print_files(printed, effects, set_name, extra, tuple(tableaux))
    except RecursionError:
        raise DeclarationError(f"{path}: {_culprit(printed, [d for _, d in user_kernels], set_name, extra)}an "
                               "expression is nested too deeply to print (RecursionError); build a long sum or "
                               "product in one call, sp.Add(*terms) or sp.Mul(*factors)") from None
    except Exception as exc:  # noqa: BLE001 - one line naming the effect or kernel, never a printer's traceback
        who = _culprit(printed, [d for _, d in user_kernels], set_name, extra)
        raise DeclarationError(f"{path}: {who}printing failed: {_explain(exc)}") from exc
    for name, text in files.items():
        if name.endswith(".py"):
            try:
                compile(text, name, "exec")
            except SyntaxError as exc:
                raise DeclarationError(f"{path}: the printed {name} is not valid Python (line {exc.lineno}: "
                                       f"{exc.msg}); this is a printer bug, please report it") from None
    return set_name, files


# ---------------------------------------------------------------------------------------------
# Explicit Runge–Kutta tableaux declared by users (TABLEAUX = [tableau(...)])
# ---------------------------------------------------------------------------------------------

MAX_ORDER = 8        # order conditions are checked up to here (115 trees of order 8)
MAX_STAGES = 16


@dataclass(frozen=True)
class TableauDecl:
    """An explicit Runge–Kutta method declared by its Butcher tableau, validated (see :func:`tableau`).

    c, A (s×s, strictly lower), b: SymPy numbers (exact: Rational or exact irrational) or floats (then
    ``exact`` is False); real_axis and wdt_max: its validity bounds (floats)."""

    name: str
    summary: str
    c: tuple
    A: tuple
    b: tuple
    order: int
    exact: bool
    real_axis: float
    wdt_max: float

    @property
    def stages(self) -> int:
        return len(self.b)

    def doubles(self) -> dict:
        """c, A (rows), b as the correctly rounded doubles both backends use."""
        return {"c": tuple(map(_double, self.c)), "A": tuple(tuple(map(_double, r)) for r in self.A),
                "b": tuple(map(_double, self.b))}

    def meta(self) -> dict:
        """The entry printed into effects_meta.py's TABLEAUX (lavendersim.extending registers it)."""
        out = {"name": self.name, "summary": self.summary, "order": self.order, "stages": self.stages}
        out.update(self.doubles())
        if self.exact:
            out["exact"] = {"c": tuple(map(str, self.c)), "A": tuple(tuple(map(str, r)) for r in self.A),
                            "b": tuple(map(str, self.b))}
        out.update(real_axis=self.real_axis, wdt_max=self.wdt_max)
        return out


def _double(x) -> float:
    """The correctly rounded double of an exact number (a Rational by integer division), or the float."""
    if isinstance(x, float):
        return x
    if isinstance(x, sp.Rational):
        return int(x.p) / int(x.q)
    return float(sp.N(x, 40))


def _number(where: str, x):
    """One tableau entry as a SymPy exact number or a finite float; ValueError naming `where` otherwise."""
    if isinstance(x, bool):
        raise ValueError(f"{where} must be a number, got {x!r}")
    if isinstance(x, (float, np.floating)):
        if not np.isfinite(x):
            raise ValueError(f"{where} must be finite, got {x!r}")
        return float(x)
    if isinstance(x, (int, np.integer, Fraction)):
        f = x if isinstance(x, Fraction) else Fraction(int(x))
        return sp.Rational(f.numerator, f.denominator)
    if isinstance(x, str):
        try:
            return sp.Rational(x.strip())
        except (TypeError, ValueError):
            raise ValueError(f"{where} = {x!r} is not a rational like '1/6' or '0.25'") from None
    if isinstance(x, sp.Basic) and x.is_number:
        if x.has(sp.Float):
            return _number(where, float(x))
        if x.is_real and x.is_finite:
            return sp.nsimplify(x) if x.is_Rational else x
        raise ValueError(f"{where} = {x} is not a finite real number")
    raise ValueError(f"{where} must be a number (int, Fraction, 'p/q', float or an exact SymPy number), got "
                     f"{type(x).__name__} {_one_line(repr(x))[:40]}")


def _rows(name: str, A, s: int) -> tuple:
    """A as s full rows of s numbers: row i given as its i strictly lower entries or as all s (zeros from i on)."""
    if not isinstance(A, (list, tuple)) or len(A) != s:
        raise ValueError(f"tableau {name!r}: A must be a list of {s} rows (one per stage, as b has {s} weights), got "
                         f"{len(A) if isinstance(A, (list, tuple)) else type(A).__name__}")
    out = []
    for i, row in enumerate(A):
        if not isinstance(row, (list, tuple)) or len(row) not in (i, s):
            raise ValueError(f"tableau {name!r}: A[{i}] must list its {i} entries left of the diagonal (or all {s}), "
                             f"got {len(row) if isinstance(row, (list, tuple)) else type(row).__name__}")
        vals = [_number(f"tableau {name!r}: A[{i}][{j}]", v) for j, v in enumerate(row)]
        for j in range(i, len(vals)):
            if vals[j] != 0:
                raise ValueError(f"tableau {name!r}: A must be strictly lower triangular (an explicit method), but "
                                 f"A[{i}][{j}] = {vals[j]} (j >= i)")
        out.append(tuple(vals[:i]) + (sp.Integer(0),) * (s - i))
    return tuple(out)


def _same(x, y) -> bool:
    if isinstance(x, float) or isinstance(y, float):
        return abs(float(x) - float(y)) <= 1e-14 * max(1.0, abs(float(x)), abs(float(y)))
    return sp.simplify(x - y) == 0


@lru_cache(maxsize=None)
def _trees(n: int) -> tuple:
    """The rooted trees with n vertices, each a sorted tuple of its root's subtrees (() is the single vertex)."""
    if n == 1:
        return ((),)
    out = set()

    def grow(left: int, kids: tuple) -> None:
        if left == 0:
            out.add(tuple(sorted(kids)))
            return
        for size in range(1, left + 1):
            for t in _trees(size):
                if not kids or t >= kids[-1]:
                    grow(left - size, kids + (t,))
    grow(n - 1, ())
    return tuple(sorted(out))


def _gamma(t: tuple) -> int:
    size = 1 + sum(_size(u) for u in t)
    return size * int(np.prod([_gamma(u) for u in t], dtype=object)) if t else 1


def _size(t: tuple) -> int:
    return 1 + sum(_size(u) for u in t)


def _weights(t: tuple, A: tuple, s: int) -> list:
    """Φ(t): the stage vector of the elementary weight (ones for the single vertex, Π_children A Φ(child))."""
    out = [sp.Integer(1)] * s
    for u in t:
        g = _weights(u, A, s)
        Ag = [sum((A[i][j] * g[j] for j in range(i)), sp.Integer(0)) for i in range(s)]
        out = [o * a for o, a in zip(out, Ag)]
    return out


def _tree_text(t: tuple) -> str:
    """The condition's vector in words: c for A·1, products as powers (Σ b_i (that)_i = 1/γ)."""
    if not t:
        return "1"
    parts = ["c" if not u else f"A({_tree_text(u)})" for u in t]
    return "·".join(f"{p}^{parts.count(p)}" if parts.count(p) > 1 else p for p in dict.fromkeys(parts))


def _check_order(name: str, A: tuple, b: tuple, order: int, exact: bool) -> None:
    """Every order condition Σ b_i Φ_i(t) = 1/γ(t), |t| <= order (Butcher); ValueError naming the first that fails."""
    s = len(b)
    for n in range(1, order + 1):
        for t in _trees(n):
            lhs = sum((bi * g for bi, g in zip(b, _weights(t, A, s))), sp.Integer(0))
            want = sp.Rational(1, _gamma(t))
            ok = sp.simplify(lhs - want) == 0 if exact else abs(float(lhs) - float(want)) <= 1e-12 * max(1.0, sum(
                abs(float(bi * g)) for bi, g in zip(b, _weights(t, A, s))))
            if not ok:
                got = sp.nsimplify(lhs) if exact else float(lhs)
                raise ValueError(f"tableau {name!r} declares order {order}, but an order-{n} condition fails: "
                                 f"Σ b_i ({_tree_text(t)})_i = {got}, must be {want} (it has order {n - 1})")


def tableau(name: str, A, b, order: int, c=None, summary: str = "") -> TableauDecl:
    """An explicit Runge–Kutta method for ``Sim(..., integrator=name)``, declared in a user's file
    (``TABLEAUX = [tableau(...)]``, docs/extending.md).

    Parameters
    ----------
    name : str
        Lowercase letters, digits, _; not a built-in integrator's name.
    A : list of s rows
        Row i lists its i entries left of the diagonal (``[[], [1/2], [-1, 2]]``), or all s entries with zeros
        from the diagonal on. Entries: int, fractions.Fraction, a string ``"p/q"``, an exact SymPy number
        (checked exactly) or a float (checked to 1e-12).
    b : list of s numbers
        The weights.
    order : int
        Its order, 1 … MAX_ORDER: every Butcher order condition up to it must hold.
    c : list of s numbers, optional
        The nodes; derived as the row sums of A when omitted, and must equal them when given.
    summary : str, optional
        One line, shown in EQUATIONS.md.

    Returns
    -------
    TableauDecl

    Raises
    ------
    ValueError
        Naming the tableau, the field and the rule broken.
    """
    if not isinstance(name, str) or not _SET_NAME.match(name):
        raise ValueError(f"tableau name must be lowercase letters, digits and _, starting with a letter, got {name!r}")
    if name in integrator_names():
        raise ValueError(f"tableau {name!r} is the name of a built-in integrator; rename it")
    if isinstance(order, bool) or not isinstance(order, (int, np.integer)) or not 1 <= order <= MAX_ORDER:
        raise ValueError(f"tableau {name!r}: order must be an integer 1 … {MAX_ORDER}, got {order!r}")
    if not isinstance(b, (list, tuple)) or not 1 <= len(b) <= MAX_STAGES:
        raise ValueError(f"tableau {name!r}: b must be a list of 1 … {MAX_STAGES} weights, got "
                         f"{len(b) if isinstance(b, (list, tuple)) else type(b).__name__}")
    s = len(b)
    bv = tuple(_number(f"tableau {name!r}: b[{i}]", v) for i, v in enumerate(b))
    Av = _rows(name, A, s)
    sums = tuple(sum(Av[i][:i], sp.Integer(0)) for i in range(s))
    if c is None:
        cv = sums
    else:
        if not isinstance(c, (list, tuple)) or len(c) != s:
            raise ValueError(f"tableau {name!r}: c must be a list of {s} nodes (as b), got "
                             f"{len(c) if isinstance(c, (list, tuple)) else type(c).__name__}")
        cv = tuple(_number(f"tableau {name!r}: c[{i}]", v) for i, v in enumerate(c))
        for i in range(s):
            if not _same(cv[i], sums[i]):
                raise ValueError(f"tableau {name!r}: c[{i}] = {cv[i]}, but the sum of A[{i}] is {sums[i]} "
                                 "(c_i = Σ_j A_ij)")
    exact = not any(isinstance(v, float) for v in bv + cv + sum(Av, ()))
    _check_order(name, Av, bv, int(order), exact)
    R_z = _stability_polynomial([r[:i] for i, r in enumerate(Av)], list(bv))
    return TableauDecl(name, " ".join(str(summary).split()), cv, Av, bv, int(order), exact,
                       _real_axis_limit(R_z), imaginary_axis_bound(R_z))


def _c_tableaux(tableaux: Sequence[TableauDecl]) -> tuple[list[str], list[str]]:
    """kernels.h declarations and kernels.c definitions of the tableaux: lvu_tableau_<name> = c, A row-major, b
    (the doubles effects_meta.py holds, printed with repr: C parses the same double)."""
    h, c = [], ["/* ---- User tableaux: c (s), A (s x s, row-major), b (s) ---- */"]
    for t in tableaux:
        d = t.doubles()
        vals = list(d["c"]) + [v for r in d["A"] for v in r] + list(d["b"])
        n = len(vals)
        h.append(f"/* {t.name}: explicit Runge-Kutta, {t.stages} stages, order {t.order}. {t.summary} */")
        h.append(f"extern const double lvu_tableau_{t.name}[{n}];")
        c.append(f"LV_EXPORT const double lvu_tableau_{t.name}[{n}] = {{{', '.join(map(repr, vals))}}};")
    return h, c


def _md_tableaux(tableaux: Sequence[TableauDecl]) -> str:
    out = ["", "## Tableaux (explicit Runge–Kutta)", ""]
    for t in tableaux:
        show = (lambda v: sp.latex(v)) if t.exact else repr
        rows = [f"{show(t.c[i])} & " + " & ".join(show(v) for v in t.A[i]) for i in range(t.stages)]
        out += [f"### {t.name}", "", t.summary, "",
                f"Order {t.order} (every order condition up to it checked), {t.stages} stages; stable on the negative "
                f"real axis for |λ|h < {t.real_axis:.6g}; validity bound |ω|·dt ≤ {t.wdt_max:.6g}.", "",
                "$$\\begin{array}{c|" + "c" * t.stages + "}" + " \\\\ ".join(rows) + " \\\\ \\hline & "
                + " & ".join(show(v) for v in t.b) + "\\end{array}$$", ""]
    return "\n".join(out)
