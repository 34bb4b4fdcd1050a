"""User declarations: effects and kernels declared in one file outside the package, printed like ours.

A declaration file is plain Python that imports ``lavendersim.derive.effect`` (and, for plain kernels,
``lavendersim.derive.kernel``) and defines ``EFFECTS`` (a list of ``effect(...)``) and/or ``KERNELS``
(a list of ``Kernel(...)``). Its set name is the file's stem. :func:`render_user` prints, with the
same printers as the built-ins: kernels.h / kernels.c (one shared library: kernels ``lvu_<set>_*``,
effects ``lvu_effect_<name>``), kernels_numpy.py (kernels and the effects' NumPy dispatch),
kernels_casadi.py, effects_meta.py (the metadata lavendersim.effects reads) and EQUATIONS.md.
``lavendersim derive --user FILE`` writes them and compiles the library (lavendersim.extending).
"""
from __future__ import annotations

import hashlib
import importlib.util
import re
import sys
from pathlib import Path

from .effect import EffectDecl
from .kernel import Kernel

_SET_NAME = re.compile(r"^[a-z][a-z0-9_]*$")


def set_name_of(path: Path) -> str:
    """The set name of a declaration file: its stem (lowercase letters, digits, _)."""
    stem = Path(path).stem
    if not _SET_NAME.match(stem):
        raise ValueError(f"{path}: the file name (without .py) names the set and must be lowercase letters, digits "
                         f"and _, starting with a letter, e.g. my_effects.py; got {stem!r}")
    return stem


def load_declarations(path) -> tuple[list[EffectDecl], list[Kernel]]:
    """Run a declaration file and return its EFFECTS and KERNELS (each optional, not both empty)."""
    path = Path(path).resolve()
    if not path.is_file():
        raise FileNotFoundError(f"{path}: no such declaration file")
    name = f"lavendersim_user_declaration_{set_name_of(path)}"
    spec = importlib.util.spec_from_file_location(name, path)
    module = importlib.util.module_from_spec(spec)
    sys.modules[name] = module
    try:
        spec.loader.exec_module(module)
    finally:
        sys.modules.pop(name, None)
    effects = list(getattr(module, "EFFECTS", []))
    kernels = list(getattr(module, "KERNELS", []))
    if not effects and not kernels:
        raise ValueError(f"{path}: declares nothing; define EFFECTS = [effect(...), ...] and/or KERNELS = [Kernel(...), ...]")
    for e in effects:
        if not isinstance(e, EffectDecl) or e.kind != "force":
            raise ValueError(f"{path}: EFFECTS must hold force effects made with lavendersim.derive.effect.effect(), "
                             f"got {e!r}")
    for k in kernels:
        if not isinstance(k, Kernel):
            raise ValueError(f"{path}: KERNELS must hold lavendersim.derive.kernel.Kernel objects, got {k!r}")
    names = [e.kernel_name for e in effects] + [k.name for k in kernels]
    dup = sorted({n for n in names if names.count(n) > 1})
    if dup:
        raise ValueError(f"{path}: duplicate names {dup}")
    return effects, kernels


def render_user(path) -> tuple[str, dict[str, str]]:
    """(set name, {file name: text}) for a declaration file, printed deterministically."""
    from . import codegen
    from .effect_print import meta_module

    path = Path(path).resolve()
    set_name = set_name_of(path)
    effects, kernels = load_declarations(path)
    header = codegen.USER_HEADER
    printed = [codegen.Printed(k) for k in kernels] + [codegen.Printed(e.kernel(group="User effects")) for e in effects]
    h, c = codegen.print_c_user(printed, effects, set_name)
    coded = [(None, e) for e in effects]
    extra = {"set_name": set_name, "declaration": str(path),
             "declaration_sha256": hashlib.sha256(path.read_bytes()).hexdigest(),
             "kernels": tuple(k.name for k in kernels)}
    files = {"kernels.h": h, "kernels.c": c,
             "kernels_numpy.py": codegen.print_numpy(printed, coded, header=header),
             "kernels_casadi.py": codegen.print_casadi(printed, header=header),
             "effects_meta.py": meta_module(coded, header, extra),
             "EQUATIONS.md": codegen.print_markdown(printed, coded, title=f"User equations: {set_name}", header=header)}
    return set_name, files
