"""SymPy derivations: the one place where LavenderSim's equations are written down.

`all_kernels()` collects every kernel, `all_effects()` every effect declaration (derive.effect);
`derive.codegen` prints them into generated/.
"""
from __future__ import annotations

MODULES = ("particles", "inertia", "effects", "quaternion", "rigid_body", "wheel_cube", "integrator_physics")


def all_kernels():
    """Every kernel, in a fixed order (module order above, then declaration order)."""
    import importlib

    out = []
    for name in MODULES:
        out.extend(importlib.import_module(f"{__name__}.{name}").kernels())
    names = [k.name for k in out]
    if len(set(names)) != len(names):
        raise RuntimeError(f"derive: duplicate kernel names {sorted(n for n in names if names.count(n) > 1)}")
    return out


def all_effects():
    """Every built-in effect declaration, in code order (code = position + 1)."""
    from .effects import declarations

    out = declarations()
    names = [d.name for d in out]
    if len(set(names)) != len(names):
        raise RuntimeError(f"derive: duplicate effect names {sorted(n for n in names if names.count(n) > 1)}")
    return out
