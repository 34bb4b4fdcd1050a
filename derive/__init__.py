"""SymPy derivations: the one place where LavenderSim's equations are written down.

`all_kernels()` collects every kernel, `all_effects()` every effect declaration (derive.effect);
`derive.codegen` prints them into generated/.

The SymPy objects users want — inertia tensors of a box/cylinder/sphere, Euler's equations,
quaternion kinematics in the body and the world frame — are public in :mod:`lavendersim.derive.symbolic`
and re-exported here (``from lavendersim.derive import inertia_box, euler_equations``); they are
loaded on first use, so ``import lavendersim.derive`` stays light.
"""
from __future__ import annotations

_SYMBOLIC = ("symbols", "inertia_box", "inertia_cylinder", "inertia_sphere", "parallel_axis", "euler_equations",
             "rotation_matrix", "quat_product", "quat_rate_body", "quat_rate_world")
__all__ = ["all_kernels", "all_effects", "symbolic", *_SYMBOLIC]


def __getattr__(name: str):
    if name == "symbolic" or name in _SYMBOLIC:
        import importlib

        mod = importlib.import_module(f"{__name__}.symbolic")
        return mod if name == "symbolic" else getattr(mod, name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")

MODULES = ("particles", "inertia", "effects", "quaternion", "rigid_body", "wheel_cube", "integrator_physics", "wheel_layout", "measures", "growth_bound")


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
