"""What a plain body's step runs, for ``Sim.pipeline``: the path each backend takes for it (torque-free, constant
effects, decoupled, the 13-number stages, or a right-hand side) and the printed kernels of that path, both read from
derive's tables (generated/effects_meta.py: RHS_KINDS_BY_FLAGS, RHS_CONSTANT, RHS_SPLIT, PIPELINE_KERNELS;
generated/tableaux.py: SCALED_RK, COMPOSITIONS). Nothing here names a kernel.

``Pipeline`` is what the property returns: the integrator's line and each body's line on demand, and the scene's
paths (bodies grouped by what their step runs, their indices as ranges), built in O(N) from the effect table."""
from __future__ import annotations

from collections.abc import Callable, Iterator, Sequence
from typing import NamedTuple, overload

import numpy as np

from . import effects as _effects
from .generated import effects_meta as _META
from .generated import tableaux as _TAB

__all__ = ["Pipeline", "PathGroup"]   # what Sim.pipeline returns; the functions are the Sim's helpers


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


def float32_path(flags: int) -> str:
    """A plain float32 body's path (a key of PIPELINE_KERNELS[backend] after "float32:<how>:"): csrc/fixed_loop.h's
    tile kind (LV_FIXED_*): "FREE" (no effect), "ANY" (some effect reads the state), else "CONST_FORCE" (a force) or
    "CONST_TORQUE" (the loads summed once per call). float32 takes built-in effects only (Sim checks it)."""
    if flags == 0:
        return "FREE"
    if flags & _META.FLAG_USES_STATE:
        return "ANY"
    return "CONST_FORCE" if flags & _META.FLAG_FORCE else "CONST_TORQUE"


def plain_kernels(backend: str, integrator: str, flags: int, user: bool, dtype: str = "float64") -> str:
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
    dtype : {"float64", "float32"}, optional
        The Sim's dtype (float32: csrc/fixed_loop.h's tiles, float32_path).

    Returns
    -------
    str
        The parts, "; "-separated.
    """
    table = _META.PIPELINE_KERNELS[backend]
    if dtype == "float32":
        path = float32_path(flags)
        parts = table.get(f"float32:{integrator}:{path}", table[f"float32:rhs:{path}"])
    elif integrator in _TAB.COMPOSITIONS:
        _, kicked, free = _TAB.COMPOSITIONS[integrator]
        program = kicked if flags or user else free
        return "flows: " + ", ".join(dict.fromkeys(f for f, _ in program))
    elif integrator in _TAB.SCALED_RK:
        parts = table[f"{integrator}:{rk4_path(backend, flags, user)}"]
    else:   # a right-hand side, or an implicit / Lie-group step of its own (a row of its name)
        path = "FREE" if flags == 0 and not user else body_kind(flags)
        parts = table.get(f"{integrator}:{path}", table[f"rhs:{path}"])
    return "; ".join(f"{what}: {', '.join(names)}" for what, names in parts)


def model_kernels(backend: str, integrator: str, wheels: bool, on_axes: bool, joint: bool, reads_v: bool) -> str:
    """What the step of a body with a joint and/or wheels runs on backend with integrator, as Sim.pipeline prints it:
    its rotation (with wheels: the wheel model, the motors, the constants) and its translation, from derive's rows
    "<integrator>:model_rotation:<rot>" (a user's tableau: "tableau:...") and "model_translation:<trans>".

    Parameters
    ----------
    backend : {"c", "numpy"}
        The Sim's backend.
    integrator : str
        The Sim's integrator (one that steps such bodies: not PLAIN_ONLY).
    wheels, on_axes, joint : bool
        The body has wheels; on the default layout A_b = [I | 0] (backends.on_body_axes); a spherical joint.
    reads_v : bool
        A jointed body's effects read v_w (FLAG_USES_V): its kinematic velocity is formed in the right-hand side too.

    Returns
    -------
    str
        The parts, "; "-separated.
    """
    table = _META.PIPELINE_KERNELS[backend]
    rot = ("WHEELS_ON_AXES" if on_axes else "WHEELS") if wheels else "PIVOT"
    trans = ("JOINT_V" if reads_v else "JOINT") if joint else "FREE"
    key = f"{integrator}:model_rotation:{rot}"
    parts = table.get(key, table[f"tableau:model_rotation:{rot}"]) + table[f"model_translation:{trans}"]
    return "; ".join(f"{what}: {', '.join(names)}" for what, names in parts)


def kernel_names(lines: Sequence[str]) -> set[str]:
    """Every kernel name PIPELINE_KERNELS holds that occurs in lines (for tests and tools: which printed kernels a
    pipeline names)."""
    names = {n for table in _META.PIPELINE_KERNELS.values() for parts in table.values() for _, ns in parts for n in ns}
    words = {w.strip(",;()") for line in lines for w in line.split()}
    return names & words


# ---- the scene's paths ----------------------------------------------------------------------------------------------
def path_keys(table: np.ndarray, extra: np.ndarray) -> np.ndarray:
    """One int64 per body, equal for two bodies exactly when their steps run the same path: the codes of the effects
    the effect table holds for it (a row's body -1: every body) and `extra`'s per-body part (model kind, wheels, ...).

    Parameters
    ----------
    table : ndarray, shape (rows, width)
        The Sim's effect table ([code, body, parameters ...] per row; effects.ROW_CODE, ROW_BODY).
    extra : ndarray of int64, shape (n,)
        The rest of each body's path (n bodies), non-negative and below 2**16.

    Returns
    -------
    ndarray of int64, shape (n,)
        O(n) per distinct effect code; the keys so far are renumbered densely when the codes outrun int64's bits.
    """
    key = np.array(extra, dtype=np.int64)
    codes, bodies = table[:, _effects.ROW_CODE], table[:, _effects.ROW_BODY]
    shift = 16
    for c in np.unique(codes):
        if shift > 62:                         # (more codes than bits: number the keys so far densely)
            _, key = np.unique(key, return_inverse=True)
            shift = max(int(key.max()).bit_length(), 1)
        on = bodies[codes == c]
        bit = np.int64(1) << np.int64(shift)
        if (on < 0).any():
            key |= bit
        else:
            key[on.astype(np.intp)] |= bit
        shift += 1
    return key


class PathGroup(NamedTuple):
    """The bodies of a scene whose steps run one path (Pipeline.groups).

    Parameters
    ----------
    path : str
        What their step runs: ``"<effect names> -> <kernels>"`` as a body line says it, without values.
    n_bodies : int
        How many bodies.
    ranges : ndarray of int64, shape (r, 2)
        Their indices (Sim.names order) as [start, stop) ranges, ascending.
    """

    path: str
    n_bodies: int
    ranges: np.ndarray

    def indices(self) -> np.ndarray:
        """The bodies' indices, ascending, int64 (n_bodies,)."""
        return np.concatenate([np.arange(a, b) for a, b in self.ranges]) if len(self.ranges) else np.zeros(0, np.int64)


def group_runs(key: np.ndarray) -> list[tuple[int, int, np.ndarray]]:
    """The bodies grouped by key: (first body, count, [start, stop) ranges (r, 2)) per distinct key, ordered by first
    body. O(n) over the bodies plus a sort of the runs of equal keys (bodies added together form one run)."""
    n = key.size
    if n == 0:
        return []
    starts = np.flatnonzero(np.concatenate(([True], key[1:] != key[:-1])))
    stops = np.append(starts[1:], n)
    _, first_run, run_group = np.unique(key[starts], return_index=True, return_inverse=True)
    order = np.argsort(run_group, kind="stable")
    bounds = np.searchsorted(run_group[order], np.arange(first_run.size + 1))
    out = []
    for g in np.argsort(first_run, kind="stable"):
        runs = order[bounds[g]:bounds[g + 1]]
        ranges = np.stack([starts[runs], stops[runs]], axis=1).astype(np.int64)
        out.append((int(starts[first_run[g]]), int((ranges[:, 1] - ranges[:, 0]).sum()), ranges))
    return out


def ranges_text(ranges: np.ndarray, limit: int = 8) -> str:
    """Ranges [start, stop) as "0–499, 750" (at most `limit`, then how many more)."""
    words = [f"{a}" if b - a == 1 else f"{a}–{b - 1}" for a, b in ranges[:limit].tolist()]
    more = len(ranges) - limit
    return ", ".join(words) + (f", … (+{more} more ranges)" if more > 0 else "")


class Pipeline(Sequence[str]):
    """What a Sim's step runs (``Sim.pipeline``): a sequence of lines, ``[0]`` the integrator's, ``[1 + i]`` body i's
    (``"<name>: <effect terms with values> -> <kernels>"``), each made when read; printed (``str``), the scene's
    paths: one line per distinct path with its bodies as index ranges and their count, so it reads the same at any N.

    Parameters
    ----------
    head : str
        The integrator's line.
    names : sequence of str
        The bodies' names (Sim.names).
    line : callable
        line(i, values) -> body i's line without its name; values False: the effects' names only (the path).
    keys : callable
        keys() -> int64 (n,): equal for two bodies exactly when their steps run the same path (path_keys).
    index : callable
        index(name) -> the body's index (raises LavenderInputError naming an unknown body).

    Notes
    -----
    The lines are read from the Sim when asked for: a Pipeline kept across ``Sim.set_effect_params`` shows the new
    values. Building the grouped view is O(N) (one int64 key per body, runs of equal keys); a body's line is O(its
    effects).
    """

    def __init__(self, head: str, names: Sequence[str], line: Callable[[int, bool], str],
                 keys: Callable[[], np.ndarray], index: Callable[[str], int]):
        self.head = head
        self._names, self._line, self._keys, self._index = names, line, keys, index

    def __len__(self) -> int:
        return 1 + len(self._names)

    @overload
    def __getitem__(self, k: int) -> str: ...

    @overload
    def __getitem__(self, k: slice) -> list[str]: ...

    def __getitem__(self, k: int | slice) -> str | list[str]:
        if isinstance(k, slice):
            return [self[j] for j in range(*k.indices(len(self)))]
        n = len(self)
        if not -n <= k < n:
            raise IndexError(f"pipeline line {k} out of range ({n} lines: the integrator's, then one per body)")
        k = k % n
        return self.head if k == 0 else f"{self._names[k - 1]}: {self._line(k - 1, True)}"

    def __iter__(self) -> Iterator[str]:
        yield self.head
        for i, name in enumerate(self._names):
            yield f"{name}: {self._line(i, True)}"

    def __eq__(self, other: object) -> bool:
        if isinstance(other, (Pipeline, list, tuple)):
            return len(self) == len(other) and all(a == b for a, b in zip(self, other))
        return NotImplemented

    __hash__ = None   # type: ignore[assignment]

    def body(self, body: int | str) -> str:
        """One body's line, ``"<name>: <effect terms with values> -> <kernels>"``.

        Parameters
        ----------
        body : int or str
            Its index (Sim.names order) or name.

        Returns
        -------
        str
        """
        i = self._index(body) if isinstance(body, str) else int(body)
        if not 0 <= i < len(self._names):
            raise IndexError(f"body index {body} out of range ({len(self._names)} bodies)")
        return self[1 + i]

    def groups(self) -> list[PathGroup]:
        """The scene's paths: the bodies grouped by what their step runs, ordered by their first body.

        Returns
        -------
        list of PathGroup
            (path, n_bodies, ranges) per distinct path; the n_bodies sum to the number of bodies.
        """
        return [PathGroup(self._line(first, False), count, ranges) for first, count, ranges in group_runs(self._keys())]

    def summary(self, max_ranges: int = 8) -> str:
        """The integrator's line, then one line per path, ``"bodies 0–499, 750 (501): <path>"``.

        Parameters
        ----------
        max_ranges : int, optional
            Index ranges shown per path (then how many more).

        Returns
        -------
        str
        """
        out = [self.head]
        for g in self.groups():
            who = (f"body {g.ranges[0, 0]}" if g.n_bodies == 1
                   else f"bodies {ranges_text(g.ranges, max_ranges)} ({g.n_bodies})")
            out.append(f"{who}: {g.path}")
        out.append("(one body's line with its values: sim.pipeline.body(i or name), or sim.pipeline[1 + i]; "
                   "the paths as data: sim.pipeline.groups())")
        return "\n".join(out)

    def __str__(self) -> str:
        return self.summary()

    def __repr__(self) -> str:
        return self.summary()
