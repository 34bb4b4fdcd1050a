"""What a plain body's step runs, for ``Sim.pipeline``: the path each backend takes for it (torque-free, constant
effects, decoupled, the 13-number stages, or a right-hand side) and the printed kernels of that path, both read from
derive's tables (generated/effects_meta.py: RHS_KINDS_BY_FLAGS, RHS_CONSTANT, RHS_SPLIT, PIPELINE_KERNELS;
generated/tableaux.py: SCALED_RK, COMPOSITIONS). Nothing here names a kernel."""
from __future__ import annotations

from collections.abc import Sequence

from . import effects as _effects
from .generated import effects_meta as _META
from .generated import tableaux as _TAB


# The integrator families whose steps run structured kernels of their own (an implicit solve, the exp-map update):
# a pipeline line names them, not the kernels inside (derive/tableaux.py declares each integrator's family).
_NOT_ITEMIZED_FAMILIES = frozenset({"implicit", "lie_group_rk"})


def itemized(integrator: str) -> bool:
    """Whether plain_kernels itemizes the step of integrator (a built-in name or a user tableau's: explicit)."""
    return _TAB.INTEGRATOR_FAMILY.get(integrator, "explicit_rk") not in _NOT_ITEMIZED_FAMILIES


def body_kind(flags: int) -> str:
    """The right-hand-side kind (TORQUE, FULL, FORCE, BODY, BODY_F) of a plain body whose effects' rhs_flags OR to
    `flags` (at least one effect): effects.rhs_kind, derive's printed rule."""
    return _effects.rhs_kind(flags)


def rk4_path(backend: str, flags: int, user: bool) -> str:
    """The built-in RK4's path (a key of PIPELINE_KERNELS[backend] after "rk4:") of a plain body on backend.

    Parameters
    ----------
    backend : {"c", "numpy"}
        The Sim's backend.
    flags : int
        The OR of the body's effects' rhs_flags (0: no effect).
    user : bool
        Some effect of the body is a user effect (user effects are never constant or decoupled).

    Returns
    -------
    str
        "FREE"; "CONST_<kind>" when every effect reads no state (RHS_CONSTANT; csrc/step.c rhs_kind,
        numpy_backend._forced_groups); "SPLIT_<kind>" when the kind may step decoupled (RHS_SPLIT) and no effect
        couples translation and rotation (FLAG_COUPLED; on NumPy also some effect reads the state); else the kind.
    """
    if flags == 0 and not user:
        return "FREE"
    kind = body_kind(flags)
    reads = bool(flags & _META.FLAG_USES_STATE)
    if not user and not reads and kind in _META.RHS_CONSTANT:
        return f"CONST_{kind}"
    if not user and _META.RHS_SPLIT[kind] and not flags & _META.FLAG_COUPLED and (reads or backend == "c"):
        return f"SPLIT_{kind}"
    return kind


def plain_kernels(backend: str, integrator: str, flags: int, user: bool) -> str:
    """What a plain body's step runs on backend with integrator, as Sim.pipeline prints it: each part of the step and
    its printed kernels ("stages (q, omega_b): <kernel>; translation: <kernel>; constants: <kernels>"),
    or, for a composition, its printed flows (tableaux.COMPOSITIONS: the kicked program with effects, else the free
    one).

    Parameters
    ----------
    backend : {"c", "numpy"}
        The Sim's backend.
    integrator : str
        The Sim's integrator (a built-in name, or a user tableau's: stepped on the right-hand side).
    flags : int
        The OR of the body's effects' rhs_flags (0: no effect).
    user : bool
        Some effect of the body is a user effect.

    Returns
    -------
    str
        The parts, "; "-separated.
    """
    if integrator in _TAB.COMPOSITIONS:
        _, kicked, free = _TAB.COMPOSITIONS[integrator]
        program = kicked if flags or user else free
        return "flows: " + ", ".join(dict.fromkeys(f for f, _ in program))
    table = _META.PIPELINE_KERNELS[backend]
    if integrator in _TAB.SCALED_RK:
        parts = table[f"{integrator}:{rk4_path(backend, flags, user)}"]
    else:
        path = "FREE" if flags == 0 and not user else body_kind(flags)
        parts = table.get(f"{integrator}:{path}", table[f"rhs:{path}"])
    return "; ".join(f"{what}: {', '.join(names)}" for what, names in parts)


def kernel_names(lines: Sequence[str]) -> set[str]:
    """Every kernel name PIPELINE_KERNELS holds that occurs in lines (for tests and tools: which printed kernels a
    pipeline names)."""
    names = {n for table in _META.PIPELINE_KERNELS.values() for parts in table.values() for _, ns in parts for n in ns}
    words = {w.strip(",;()") for line in lines for w in line.split()}
    return names & words
