"""Every name a public docstring of lavendersim points to exists (issue 31): dotted references
``lavendersim.x.y`` and Sphinx roles (:func:`~lavendersim.x.y`, :meth:`Class.method`, :data:`NAME`, …) are
resolved by import + getattr, relative ones against the docstring's module and class."""
from __future__ import annotations

import importlib
import inspect
import pkgutil
import re

import pytest

import lavendersim
from lavendersim._install import MissingExtraError

ROLE = re.compile(r":(?:py:)?(?:func|meth|class|data|attr|mod|obj|exc|const|property):`~?\.?([A-Za-z_][\w.]*)`")
DOTTED = re.compile(r"(?<![\w./-])(lavendersim(?:\.[A-Za-z_]\w*)+)")
# not names: file paths and folders the docstrings mention in prose (generated/..., lavendersim/...)
PATHLIKE = re.compile(r"lavendersim\.(?:py|toml|json|md|h|c)$")


# the packages that live outside lavendersim/ (pyproject's package-dir): walked as well
REMAPPED = ("lavendersim.derive", "lavendersim.generated", "lavendersim.labs")


def _public(name: str) -> bool:
    return not any(part.startswith("_") for part in name.split(".")[1:]) or name.endswith("._linearize")


def _modules():
    names = ["lavendersim", *REMAPPED]
    for pkg in ["lavendersim", *REMAPPED]:
        names += [m.name for m in pkgutil.walk_packages(importlib.import_module(pkg).__path__, pkg + ".")
                  if _public(m.name) and m.name not in names]
    out = []
    for name in names:
        try:
            out.append(importlib.import_module(name))
        except (MissingExtraError, ImportError):   # an optional extra (viewer, gymnasium, casadi) not installed
            continue
    return out


def _docstrings(mod):
    """(where, owner class or None, docstring) of the module and its public classes, functions, methods."""
    if mod.__doc__:
        yield mod.__name__, None, mod.__doc__
    for name, obj in vars(mod).items():
        if name.startswith("_") or getattr(obj, "__module__", None) != mod.__name__:
            continue
        if inspect.isclass(obj):
            if obj.__doc__:
                yield f"{mod.__name__}.{name}", obj, obj.__doc__
            for mname, m in vars(obj).items():
                if mname.startswith("_"):
                    continue
                doc = getattr(m.fget if isinstance(m, property) else getattr(m, "__func__", m), "__doc__", None)
                if doc and (inspect.isfunction(getattr(m, "__func__", m)) or isinstance(m, property)):
                    yield f"{mod.__name__}.{name}.{mname}", obj, doc
        elif inspect.isfunction(obj) and obj.__doc__:
            yield f"{mod.__name__}.{name}", None, obj.__doc__


def _resolve_absolute(dotted: str) -> bool:
    parts = dotted.split(".")
    for i in range(len(parts), 0, -1):
        try:
            obj = importlib.import_module(".".join(parts[:i]))
        except (MissingExtraError, ImportError):
            if i == 1:
                return False
            continue
        try:
            for p in parts[i:]:
                obj = getattr(obj, p)
            return True
        except AttributeError:
            return False
    return False


def _resolve(ref: str, mod, owner) -> bool:
    if ref.split(".")[0] in ("lavendersim", "numpy", "control", "casadi", "gymnasium", "matplotlib", "scipy", "sympy",
                               "distributed", "dask", "mujoco", "numba", "jax"):
        head = ref.split(".")[0]
        try:
            importlib.import_module(head)
        except ImportError:
            return True                     # a third-party name we cannot check without its extra
        return _resolve_absolute(ref)
    if owner is not None and _walk(owner, ref):
        return True
    return _walk(mod, ref) or _resolve_absolute("lavendersim." + ref) or _walk(__builtins__, ref)


def _walk(obj, dotted: str) -> bool:
    for p in dotted.split("."):
        obj = obj.get(p, _MISSING) if isinstance(obj, dict) else getattr(obj, p, _MISSING)
        if obj is _MISSING:
            return False
    return True


_MISSING = object()


def _references():
    seen = set()
    for mod in _modules():
        for where, owner, doc in _docstrings(mod):
            refs = [(m.group(1), "role") for m in ROLE.finditer(doc)]
            refs += [(m.group(1), "dotted") for m in DOTTED.finditer(doc) if not PATHLIKE.search(m.group(1))]
            for ref, kind in refs:
                key = (where, ref)
                if key not in seen:
                    seen.add(key)
                    yield where, owner, mod, ref


def test_the_scan_finds_references():
    refs = {ref for _, _, _, ref in _references()}
    assert "lavendersim.effects.describe" in refs         # Scene.add_effect's pointer to the listing
    assert len(refs) > 20


def test_every_name_a_docstring_points_to_exists():
    missing = sorted({f"{where}: {ref}" for where, owner, mod, ref in _references() if not _resolve(ref, mod, owner)})
    assert not missing, "docstrings point to names that do not exist:\n  " + "\n  ".join(missing)
