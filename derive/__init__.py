"""SymPy derivations: the one place where LavenderSim's equations are written down.

`all_kernels()` collects every kernel; `derive.codegen` prints them into generated/.
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
