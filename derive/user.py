"""User declarations: effects and kernels declared in one file outside the package, printed like ours.

A declaration file is plain Python that imports ``lavendersim.derive.effect`` (and, for plain kernels,
``lavendersim.derive.kernel``) and defines ``EFFECTS`` (a list of ``effect(...)``) and/or ``KERNELS``
(a list of ``Kernel(...)``). Its set name is the file's stem. :func:`render_user` prints, with the
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
from pathlib import Path

import sympy as sp

from .effect import EffectDecl
from .kernel import Kernel

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


def _one_line(text: str) -> str:
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


def load_declarations(path) -> tuple[list[EffectDecl], list[Kernel]]:
    """Run a declaration file and return its EFFECTS and KERNELS (each optional, not both empty).

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
    if not effects and not kernels:
        raise DeclarationError(f"{path}: declares nothing; define EFFECTS = [effect(...), ...] and/or "
                               "KERNELS = [Kernel(...), ...]")
    for e in effects:
        if e.kind != "force":
            raise DeclarationError(f"{path}: EFFECTS[{effects.index(e)}] ({e.name!r}) is a model effect; a user set "
                                   "declares force effects made with effect()")
    names = [e.kernel_name for e in effects] + [k.name for k in kernels]
    dup = sorted({n for n in names if names.count(n) > 1})
    if dup:
        raise DeclarationError(f"{path}: duplicate names {dup}")
    return effects, kernels


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


def _print_files(printed: list, effects: list, set_name: str, extra: dict) -> dict[str, str]:
    from . import codegen
    from .effect_print import meta_module

    header = codegen.USER_HEADER
    coded = [(None, e) for e in effects]
    h, c = codegen.print_c_user(printed, effects, set_name)
    return {"kernels.h": h, "kernels.c": c,
            "kernels_numpy.py": codegen.print_numpy(printed, coded, header=header),
            "kernels_casadi.py": codegen.print_casadi(printed, header=header),
            "effects_meta.py": meta_module(coded, header, extra),
            "EQUATIONS.md": codegen.print_markdown(printed, coded, title=f"User equations: {set_name}", header=header)}


def _culprit(printed: list, decls: list, set_name: str, extra: dict) -> str:
    """'effect NAME: ' / 'kernel NAME: ' of the first declaration that fails to print on its own, or ''."""
    for p, d in zip(printed, decls):
        try:
            _print_files([p], [] if isinstance(d, Kernel) else [d], set_name, extra)
        except Exception:  # noqa: BLE001 - found it
            return f"{_label(p.k)}: "
    return ""


def _effect_kernel(path: Path, e: EffectDecl) -> Kernel:
    try:
        return e.kernel(group="User effects")
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
    effects, kernels = load_declarations(path)
    printers = _printers()
    user_kernels = [(k, k) for k in kernels] + [(_effect_kernel(path, e), e) for e in effects]
    printed = [_printed(path, k, printers) for k, _ in user_kernels]
    extra = {"set_name": set_name, "declaration": str(path),
             "declaration_sha256": hashlib.sha256(path.read_bytes()).hexdigest(),
             "kernels": tuple(k.name for k in kernels)}
    try:
        files = _print_files(printed, effects, set_name, extra)
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
