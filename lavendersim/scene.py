"""A scene: bodies plus the effects it declares, and nothing else."""
from __future__ import annotations

import bisect
import itertools
import operator
from collections.abc import Mapping, MutableSequence, Sequence
from types import MappingProxyType
from typing import NamedTuple

import numpy as np
from numpy.typing import ArrayLike

from . import validate as V
from .bodies import P, Q, STATE_SIZE, VEL, W, Body
from .effects import (EFFECTS, MAX_LOAD, ROW, ROW_BODY, ROW_CODE, ROW_PARAMS, Effect, check_declared, largest_param,
                      load_overflow, make, numpy_apply)
from .frames import PrincipalFrames
from .generated import layout as LY
from .kernels import K


def _declared(effect: Effect) -> bool:
    try:
        check_declared(effect)
    except V.LavenderInputError:
        return False
    return True


class _Batch:
    """One effect declared on many bodies (Scene.add_effects, issue 30): the effect class, the bodies (n,) and the
    validated values — one shared value per parameter, or a read-only (n, ...) float64 column of one value per body.
    It stands for n per-body Effects, each built only when read (then kept, so it keeps its identity); a scene
    and a Sim read its columns directly. Immutable, as an Effect is: copies share it."""

    __slots__ = ("cls", "bodies", "shared", "cols", "_made", "_off", "_where", "_at")

    def __init__(self, cls, bodies: list, shared: dict, cols: dict, made: dict | None = None, off: int = 0,
                 at: tuple | None = None) -> None:
        self.cls, self.bodies, self.shared, self.cols = cls, bodies, shared, cols
        self._made: dict = made if made is not None else {}    # the effects built, by position + _off (shared by parts)
        self._off = off
        self._where: dict | None = None
        self._at = at         # (a body table's core, the bodies' indices in it): see positions

    name = property(lambda self: self.cls.name)
    code = property(lambda self: self.cls.code)
    spec = property(lambda self: self.cls.spec)
    per_body = property(lambda self: self.cls.per_body)

    def __len__(self) -> int:
        return len(self.bodies)

    def __reduce__(self):   # its first effect pickles its class (a user effect's set is registered on load)
        return (_batch_like, (self.effect(0), self.bodies, self.shared, self.cols))

    def __copy__(self):
        return self

    def __deepcopy__(self, memo):
        return self

    def effect(self, j: int) -> Effect:
        """The j-th effect: built as Effect.__init__ would after validating (it refuses setattr), once."""
        e = self._made.get(j + self._off)
        if e is None:
            e = object.__new__(self.cls)
            values = {f: (self.shared[f] if f in self.shared else
                          float(self.cols[f][j]) if self.cols[f].ndim == 1 else self.cols[f][j]) for f in self.cls.fields}
            e.__dict__["body"] = self.bodies[j]
            e.__dict__["values"] = MappingProxyType(values)
            self._made[j + self._off] = e
        return e

    def part(self, lo: int, hi: int) -> "_Batch":
        """Effects lo..hi-1 as a batch (views of the columns; the effects built, and built later, shared)."""
        return _Batch(self.cls, self.bodies[lo:hi], self.shared, {f: a[lo:hi] for f, a in self.cols.items()},
                      self._made, self._off + lo, None if self._at is None else (self._at[0], self._at[1][lo:hi]))

    def positions(self, core: dict) -> np.ndarray:
        """The bodies' indices (n,) in a body table (its core dict; -1: not in it), kept for that table (a body's
        index never changes)."""
        if self._at is None or self._at[0] is not core:
            pos = _name_index(core)
            self._at = (core, np.fromiter((pos.get(b, -1) for b in self.bodies), np.int64, len(self.bodies)))
        return self._at[1]

    def where(self, body: str) -> list:
        """The positions j of `body` in this batch (in order)."""
        if self._where is None:
            w = dict(zip(self.bodies, range(len(self.bodies))))
            if len(w) == len(self.bodies):
                self._where = w
            else:
                self._where = {}
                for j, b in enumerate(self.bodies):
                    self._where.setdefault(b, []).append(j)
        at = self._where.get(body)
        return [] if at is None else at if isinstance(at, list) else [at]

    def column(self, f: str) -> np.ndarray:
        """Parameter f of every effect, (n, *shape) float64 (a shared value broadcast, read-only)."""
        if f in self.cols:
            return self.cols[f]
        v = np.asarray(self.shared[f], dtype=np.float64)
        return np.broadcast_to(v, (len(self.bodies),) + v.shape)

    def params_flat(self) -> np.ndarray:
        """Effect.params_flat of every effect, stacked (n, n_params)."""
        n = len(self.bodies)
        cols = [self.column(f).reshape(n, -1) for f in self.cls.fields]
        return np.concatenate(cols, axis=1) if cols else np.zeros((n, 0))


def _batch_like(first: Effect, bodies: list, shared: dict, cols: dict) -> _Batch:
    """Unpickle a _Batch: its first effect (rebuilt and validated by Effect's unpickling) names the class and
    validates the shared values; each column is checked against its parameter's declared rule again (as
    add_effects' screen does) and made read-only."""
    cls = type(first)
    specs = {p.name: p for p in (cls.spec.params if cls.spec is not None else ())}
    for f, a in cols.items():
        a = np.asarray(a, dtype=np.float64)
        if f not in specs or a.shape[:1] != (len(bodies),) or _breaks_rule(a, specs[f]).any():
            raise V.LavenderInputError(f"{cls.name}.{f}", "a pickled batch's column breaks its declared rule or shape")
        a.flags.writeable = False
        cols[f] = a
    shared = {f: first.values[f] for f in shared}
    return _Batch(cls, list(bodies), shared, cols, {0: first})


class _EffectList(MutableSequence):
    """Scene.effects: the declared effects in order, a mutable sequence of Effects (edit it as a list). An
    add_effects call is kept as one _Batch (its Effects built when read), so 1e5 per-body effects cost their
    arrays (issue 30). It keeps an index of its effects per body, so that add_effect and add_body look up the
    effects on one body in O(effects on it + batches) instead of scanning them all.

    append keeps the index; any other edit drops it (rebuilt on the next look-up) and, where it falls inside a
    batch, splits the batch there first, so the index is never stale however the list is edited."""

    __slots__ = ("_items", "_ends", "_ix")

    def __init__(self, effects=()) -> None:
        self._items: list = list(effects.items() if isinstance(effects, _EffectList) else effects)
        self._ends: list | None = None
        self._ix: dict | None = None

    def items(self) -> list:
        """The entries as stored: Effects and _Batches (do not modify)."""
        return self._items

    def __reduce_ex__(self, protocol):   # pickles its entries (a batch as its columns); the index is rebuilt
        return (_EffectList, (list(self._items),))

    def _bounds(self) -> list:
        if self._ends is None:
            self._ends = list(itertools.accumulate(len(it) if type(it) is _Batch else 1 for it in self._items))
        return self._ends

    def __len__(self) -> int:
        ends = self._bounds()
        return ends[-1] if ends else 0

    def _locate(self, k: int) -> tuple[int, int]:
        """(entry, position in it) of effect k (0 <= k < len)."""
        ends = self._bounds()
        i = bisect.bisect_right(ends, k)
        return i, k - (ends[i - 1] if i else 0)

    def __getitem__(self, k):
        if isinstance(k, slice):
            return [self[j] for j in range(*k.indices(len(self)))]
        n = len(self)
        k = operator.index(k)
        if not -n <= k < n:
            raise IndexError("effect index out of range")
        i, j = self._locate(k % n)
        it = self._items[i]
        return it.effect(j) if type(it) is _Batch else it

    def __iter__(self):
        for it in self._items:
            if type(it) is _Batch:
                yield from map(it.effect, range(len(it)))
            else:
                yield it

    def __eq__(self, other) -> bool:
        return isinstance(other, (list, tuple, _EffectList)) and list(self) == list(other)

    __hash__ = None  # type: ignore[assignment]

    def __repr__(self) -> str:
        return repr(list(self))

    def _split(self, k: int) -> int:
        """Make effect k start an entry (splitting a batch there); its entry index (len(entries) at the end)."""
        if k >= len(self):
            return len(self._items)
        i, j = self._locate(k)
        if j:
            b = self._items[i]
            self._items[i:i + 1] = [b.part(0, j), b.part(j, len(b))]
            self._ends = None
            return i + 1
        return i

    def _edited(self) -> None:
        self._ends = self._ix = None

    def __setitem__(self, k, value) -> None:
        if isinstance(k, slice) or isinstance(value, _Batch):
            effects = list(self)
            effects[k] = value
            self._items = effects
        else:
            n = len(self)
            k = operator.index(k) % n if -n <= k < n else operator.index(k)
            if not 0 <= k < n:
                raise IndexError("effect index out of range")
            self._items[self._split(k):self._split(k + 1)] = [value]   # (the second split after the first)
        self._edited()

    def __delitem__(self, k) -> None:
        lo, hi, step = k.indices(len(self)) if isinstance(k, slice) else (0, 0, 1)
        if isinstance(k, slice) and step == 1:
            a = self._split(lo)
            b = self._split(max(lo, hi))
            del self._items[a:b]
        elif isinstance(k, slice):
            effects = list(self)
            del effects[k]
            self._items = effects
        else:
            n = len(self)
            if not -n <= k < n:
                raise IndexError("effect index out of range")
            k = operator.index(k) % n
            a = self._split(k)
            del self._items[a:self._split(k + 1)]
        self._edited()

    def insert(self, k: int, value) -> None:
        n = len(self)
        k = max(0, min(n, k + n if k < 0 else k))
        self._items.insert(self._split(k), value)
        self._edited()

    def clear(self) -> None:
        self._items = []
        self._edited()

    def sort(self, *, key=None, reverse: bool = False) -> None:
        """Sort in place, as list.sort."""
        self._items = sorted(self, key=key, reverse=reverse)   # type: ignore[arg-type]
        self._edited()

    def append(self, e) -> None:
        """Append an Effect, or a _Batch (one entry for its effects)."""
        self._items.append(e)
        if self._ends is not None:
            self._ends.append(len(self) + (len(e) if type(e) is _Batch else 1))
        if self._ix is not None:
            self._add(len(self) - (len(e) if type(e) is _Batch else 1), e)

    def _index(self) -> dict:
        """{"per_body": {(name, body): count}, "models": {body: [(position, effect)]}, "on": {body: [(position, effect)]},
        "all": [(position, effect)], "batches": [(position of its first effect, batch)]}: per-body Effects by name
        and body and by body; the other Effects by their body (None: every body); each in list order."""
        if self._ix is None:
            self._ix = {"per_body": {}, "models": {}, "on": {}, "all": [], "batches": []}
            k = 0
            for it in self._items:
                self._add(k, it)
                k += len(it) if type(it) is _Batch else 1
        return self._ix

    def _add(self, k: int, e) -> None:
        ix = self._index()
        if type(e) is _Batch:
            ix["batches"].append((k, e))
        elif getattr(e, "per_body", False):
            key = (e.name, e.body)
            ix["per_body"][key] = ix["per_body"].get(key, 0) + 1
            ix["models"].setdefault(e.body, []).append((k, e))
        elif getattr(e, "body", None) is None:
            ix["all"].append((k, e))
        else:
            ix["on"].setdefault(e.body, []).append((k, e))

    def has_per_body(self, name: str, body: str) -> bool:
        """A per-body effect `name` on `body` is in the list."""
        ix = self._index()
        return ix["per_body"].get((name, body), 0) > 0 or any(
            b.per_body and b.name == name and b.where(body) for _, b in ix["batches"])

    def have_per_body(self, name: str, bodies: list) -> np.ndarray:
        """has_per_body(name, b) for each b of `bodies`, (n,) bool."""
        ix = self._index()
        out = np.fromiter(((name, b) in ix["per_body"] for b in bodies), bool, len(bodies))
        for _, bt in ix["batches"]:
            if bt.per_body and bt.name == name:
                out |= np.fromiter((bool(bt.where(b)) for b in bodies), bool, len(bodies))
        return out

    def models_on(self, body: str) -> list:
        """The per-body effects on `body`, in list order."""
        ix = self._index()
        mine = ix["models"].get(body, [])
        batched = [(k + j, b.effect(j)) for k, b in ix["batches"] if b.per_body for j in b.where(body)]
        return [e for _, e in (sorted(mine + batched, key=lambda ke: ke[0]) if batched else mine)]

    def forces_on(self, body: str | None) -> list:
        """The effects that are not per-body and act on `body` (body None and, if given, body == `body`),
        in list order."""
        ix = self._index()
        mine = list(ix["on"].get(body, [])) if body is not None else []
        if body is not None:
            mine += [(k + j, b.effect(j)) for k, b in ix["batches"] if not b.per_body for j in b.where(body)]
        if not mine:
            return [e for _, e in ix["all"]]
        return [e for _, e in sorted(ix["all"] + mine, key=lambda ke: ke[0])]

    def find(self, effect) -> int | None:
        """The position of `effect` (this very object) in the list, or None; a batch's effects found by body."""
        k = 0
        for it in self._items:
            if type(it) is _Batch:
                body = getattr(effect, "body", None)
                for j in it.where(body) if isinstance(body, str) else ():
                    if it._made.get(j + it._off) is effect:
                        return k + j
                k += len(it)
            else:
                if it is effect:
                    return k
                k += 1
        return None


class _BodyTable(Mapping):
    """A scene's bodies by name, in the order added (issue 30): the bodies added in batches (add_bodies) are
    columns — their names, initial states (k, 13) and [m, I_b] rows (k, 4) — and become Body objects only when
    asked for (built once, kept); a Body given to add_body is kept as given. So a million bodies cost their
    arrays, not a million Python objects.

    ``frozen()`` is a view of the first len(self) bodies that later adds do not change (what a Sim keeps).

    The name -> index dict (core "pos", see _name_index) is built on the first look-up by name, not by add_bodies:
    at 1e6 bodies it is ~63 B per body of the build's peak (issue 30) that a scene stepped by index never needs."""

    def __init__(self, core: dict | None = None, n: int | None = None):
        self._c = core if core is not None else {"names": [], "pos": None, "batches": [], "starts": [], "given": {},
                                                      "made": {}}
        self._n = n          # None: the scene's live table; else a frozen length

    def __len__(self) -> int:
        return len(self._c["names"]) if self._n is None else self._n

    def __iter__(self):
        names = self._c["names"]
        return iter(names) if self._n is None else itertools.islice(names, self._n)

    def __contains__(self, name) -> bool:
        try:
            i = _name_index(self._c).get(name)
        except TypeError:          # an unhashable name
            return False
        return i is not None and i < len(self)

    def __getitem__(self, name) -> Body:
        return self.body(self.position(name))

    def __reduce__(self):          # pickles as its bodies (Body objects), rebuilt on load
        return (_table_of, ([self.body(i) for i in range(len(self))],))

    def position(self, name) -> int:
        """The body's index (KeyError if it has none here; TypeError for an unhashable name)."""
        i = _name_index(self._c).get(name)
        if i is None or i >= len(self):
            raise KeyError(name)
        return i

    @property
    def positions(self) -> "_Positions":
        """A read-only name -> index mapping (``positions[name]``)."""
        return _Positions(self.frozen())

    @property
    def names(self) -> list:
        """The body names in order (the first len(self) entries; do not modify)."""
        return self._c["names"]

    def frozen(self) -> "_BodyTable":
        return _BodyTable(self._c, len(self))

    def body(self, i: int) -> Body:
        """Body i: as given to add_body, or built from its batch's rows (once)."""
        c = self._c
        b = c["given"].get(i) or c["made"].get(i)
        if b is None:
            start, x, p = c["batches"][bisect.bisect_right(c["starts"], i) - 1]
            c["made"][i] = b = _batch_body(c["names"][i], x.row(i - start), p[i - start])
        return b

    def add(self, body: Body) -> None:
        c = self._c
        c["given"][len(c["names"])] = body
        if c["pos"] is not None:
            c["pos"][body.name] = len(c["names"])
        c["names"].append(body.name)

    def add_batch(self, names: list, x: "_States", p: np.ndarray) -> bool:
        """Append validated bodies: names (k,) new in the table, their initial states x (k rows) and read-only
        [m, I_b] rows p (k, 4); False (and nothing added) if a name repeats within `names`.

        Into an empty table the names are checked with a set (freed on return) and the index is left to the first
        look-up; otherwise the index is built (if it is not yet) and extended."""
        c = self._c
        start = len(c["names"])
        if not start:
            if len(set(names)) != len(names):
                return False
            c["pos"] = None     # (an empty index a refused call's look-ups built)
        else:
            pos = _name_index(c)
            pos.update(zip(names, range(start, start + len(names))))
            if len(pos) != start + len(names):
                for name in names:
                    pos.pop(name, None)
                return False
        c["batches"].append((start, x, p))
        c["starts"].append(start)
        c["names"].extend(names)
        return True

    def arrays(self) -> tuple[np.ndarray, np.ndarray, list]:
        """(initial states (n, 13), [m, I_b] rows (n, 4), the bodies given as Body objects, in order) of the first
        len(self) bodies: a fresh state array; the rows of one add_bodies call (read-only, shared), else a fresh
        array; the given bodies' rows are read from them now (a Body changed past its immutability is then caught
        by _revalidate)."""
        n, c = len(self), self._c
        shared = len(c["batches"]) == 1 and not c["given"] and n > 0    # one add_bodies call: its read-only rows
        state, params = np.empty((n, STATE_SIZE)), c["batches"][0][2][:n] if shared else np.empty((n, 4))
        for start, x, p in c["batches"]:
            k = min(len(x), n - start)
            if k > 0:
                x.fill(state[start:start + k])
                if params.flags.writeable:
                    params[start:start + k] = p[:k]
        idx = [i for i in c["given"] if i < n]
        given = [c["given"][i] for i in idx]
        if given:
            state[idx] = np.stack([b.x0 for b in given])
            params[idx] = np.stack([b.params for b in given])
        return state, params, list(zip(idx, given))


class _States:
    """The initial states (k, 13) of the bodies of one add_bodies call, kept as the blocks of the state row that
    were given (p_w, q, v_w, omega_b; read-only copies): a block left at its default (zeros; q the identity) is not
    stored. At 1e6 bodies given q and omega_b that is 56 B per body instead of the 104 B of whole rows (issue 30)."""

    __slots__ = ("n", "blocks")

    def __init__(self, x: np.ndarray, given: Sequence[slice]) -> None:
        self.n = len(x)
        self.blocks = []
        for s in given:
            a = np.array(x[:, s])
            a.flags.writeable = False
            self.blocks.append((s, a))

    def __len__(self) -> int:
        return self.n

    def row(self, j: int) -> np.ndarray:
        """Body j's initial state (13,), read-only (a new array)."""
        x0 = _DEFAULT_ROW.copy()
        for s, a in self.blocks:
            x0[s] = a[j]
        x0.flags.writeable = False
        return x0

    def fill(self, out: np.ndarray) -> None:
        """Write the first len(out) states into out (k, 13)."""
        k = len(out)
        out[...] = _DEFAULT_ROW
        for s, a in self.blocks:
            out[:, s] = a[:k]


_DEFAULT_ROW = np.zeros(STATE_SIZE)     # a body's state when no block is given: at rest at the origin, q = identity
_DEFAULT_ROW[Q] = (0.0, 0.0, 0.0, 1.0)
_DEFAULT_ROW.flags.writeable = False


def _name_index(core: dict) -> dict:
    """The body table core's name -> index dict (every name in core["names"]), built here on first use."""
    pos = core["pos"]
    if pos is None:
        names = core["names"]
        core["pos"] = pos = dict(zip(names, range(len(names))))
    return pos


class _Positions(Mapping):
    """name -> body index of the bodies of a (frozen) body table."""

    def __init__(self, table: _BodyTable) -> None:
        self._t = table

    def __getitem__(self, name) -> int:
        return self._t.position(name)

    def __len__(self) -> int:
        return len(self._t)

    def __iter__(self):
        return iter(self._t)

    def __contains__(self, name) -> bool:
        return name in self._t


def _table_of(bodies: list) -> _BodyTable:
    t = _BodyTable()
    for b in bodies:
        t.add(b)
    return t


def _batch_body(name: str, x0: np.ndarray, p: np.ndarray) -> Body:
    """A Body from validated rows (its fields filled directly, as Body.__init__ would after validating)."""
    b = object.__new__(Body)
    for f, v in zip(("name", "mass", "I_b", "shape", "x0", "R_bp", "_tensor"),
                    (name, float(p[0]), p[1:4], None, x0, _EYE, None)):
        object.__setattr__(b, f, v)
    return b


_EYE = np.eye(3)        # the body frame of a batch-added body is principal (one read-only identity for all)
_EYE.flags.writeable = False


class Scene:
    """Bodies (by name, in the order added) and the effects declared on them.

    Every add is validated before anything is stored: a rejected call leaves the scene as it was.
    Force effects whose parameters would overflow — alone or summed with the other effects on a body,
    as force, torque or acceleration at the body's initial state — are rejected when added.

    Examples
    --------
    >>> import lavendersim as lv
    >>> scene = lv.Scene()
    >>> rod = scene.add_body(lv.Body.box("rod", mass=1.0, size=(0.8, 0.2, 0.2)))
    >>> torque = scene.add_effect("applied_torque", body="rod", torque_w=[0, 0, 0.02])
    >>> list(scene.bodies)
    ['rod']
    """

    @V.keywords
    def __init__(self):
        self._bodies = _BodyTable()           # name -> Body, batches kept as arrays (see _BodyTable)
        self._effects = _EffectList()

    @property
    def effects(self) -> _EffectList:
        """The declared effects, in the order added (a list; add with add_effect, which validates).

        Assigning a list stores a copy of it (the scene keeps an index of its effects per body)."""
        return self._effects

    @effects.setter
    def effects(self, value) -> None:
        self._effects = _EffectList(value)

    def __setstate__(self, state: dict) -> None:
        """Unpickle, also a Scene pickled before issue 30 (its effects a plain list under "effects")."""
        state = dict(state)
        effects = state.pop("effects", None)
        self.__dict__.update(state)
        self.__dict__.pop("_pos", None)
        if isinstance(self._bodies, dict):    # pickled before the body table
            self._bodies = _table_of(list(self._bodies.values()))
        if effects is not None or "_effects" not in state:
            self._effects = _EffectList(effects or [])

    @property
    def bodies(self) -> MappingProxyType:
        """The bodies by name, in the order added: a read-only view (add with add_body, which validates)."""
        return MappingProxyType(self._bodies)

    @V.keywords
    def add_body(self, body: Body) -> Body:
        """Add a (validated, immutable) Body; its name must be new in this scene.

        Parameters
        ----------
        body : Body
            The body to add.

        Returns
        -------
        Body
            `body` itself.

        Raises
        ------
        LavenderInputError
            If `body` is not a Body, its name is taken, or a scene-wide effect would overflow on it.
        """
        if not isinstance(body, Body):
            raise V.LavenderInputError("body", "must be a lavendersim.Body", f", got {type(body).__name__}")
        if body.name in self.bodies:
            raise V.LavenderInputError("body.name", f"duplicate name {body.name!r}")
        every = [e for e in self.effects.forces_on(None) if _declared(e)]
        why = load_overflow(every, body) if every else None
        if why:
            raise V.LavenderInputError("body", f"{why} with the scene's effects on every body "
                                       f"({', '.join(e.name for e in every)})")
        self._bodies.add(body)
        return body

    def add_effect(self, effect: Effect | str, body: str | None = None, **params) -> Effect:
        """Declare an effect: an Effect instance, or its name plus parameters.

        Parameters
        ----------
        effect : str or Effect
            An effect name (``"applied_torque"``, ``"gravity"``, ``"spherical_joint"``, ...) or an instance.
        body : str or None, optional
            The body it acts on; None for every body (effects that allow it, e.g. gravity).
        **params
            The effect's parameters by name, with the units its declaration states
            (``lavendersim.effects.describe()`` lists them), e.g. ``torque_w=[0, 0, 0.02]`` (N·m, world).

        Returns
        -------
        Effect
            The effect as stored.

        Raises
        ------
        LavenderInputError
            On an unknown effect, body or parameter, a bad value, a duplicate per-body effect, or loads
            that would overflow; the scene is left as it was.
        """
        if isinstance(effect, str):
            effect = make(effect, body=body, **params)
        elif not isinstance(effect, Effect):
            raise V.LavenderInputError("effect", "must be an effect name or a lavendersim Effect", f", got {type(effect).__name__}")
        elif body is not None or params:
            raise V.LavenderInputError("effect", "pass parameters either in the Effect instance or with a name, not both")
        if effect.body is not None and effect.body not in self.bodies:
            raise V.LavenderInputError(f"{effect.name}.body", f"unknown body {effect.body!r}; bodies: {', '.join(self.bodies) or 'none'}")
        if effect.per_body:
            if effect.body is None:  # an Effect built by hand without a body
                raise V.LavenderInputError(f"{effect.name}.body", "is required (the name of the body it acts on)")
            if self.effects.has_per_body(effect.name, effect.body):
                raise V.LavenderInputError(f"{effect.name}.body", f"body {effect.body!r} already has a {effect.name}; "
                                           "at most one per body")
            if hasattr(effect, "check_body"):
                effect.check_body(self.bodies[effect.body])
        elif _declared(effect):  # an undeclared effect is refused by Sim (naming how to declare it)
            if effect.body is None:   # the exact check below only where a vectorized bound cannot rule it out
                every = [e for e in self.effects.forces_on(None) if _declared(e)] + [effect]
                x, rows, _ = self._bodies.arrays()
                targets = [self._bodies.body(int(i))
                           for i in _overflow_suspects(every, self.effects, x, rows, self._bodies.positions)]
            else:
                targets = [self.bodies[effect.body]]
            for b in targets:
                mine = [e for e in self.effects.forces_on(b.name) if _declared(e)]
                why = load_overflow([effect], b) or (load_overflow(mine + [effect], b) if mine else None)
                if why:
                    raise V.LavenderInputError(largest_param(effect), f"too large: {why}"
                                               + (f" (with {', '.join(e.name for e in mine)})" if mine else ""))
        self.effects.append(effect)
        return effect

    @V.keywords  # unknown keyword arguments raise LavenderInputError naming them (as the function below)
    def add_bodies(self, names: Sequence[str], masses: ArrayLike, I_b: ArrayLike, *, p_w: ArrayLike | None = None,
                   q: ArrayLike | None = None, v_w: ArrayLike | None = None, omega_b: ArrayLike | None = None,
                   omega_w: ArrayLike | None = None) -> Sequence[Body]:
        # the docstring is add_bodies's (below), set after it
        return add_bodies(self, names, masses, I_b, p_w=p_w, q=q, v_w=v_w, omega_b=omega_b, omega_w=omega_w)

    def add_effects(self, effect: str, bodies, **params) -> Sequence[Effect]:
        """Declare one effect on each of many bodies at once: what ``add_effect(effect, body=b, **params_b)`` for
        each b in order declares, validated over whole arrays and kept as one batch (issue 30).

        The batch is stored as its arrays (one entry of ``scene.effects``, which still reads as the n per-body
        Effects, each built when first read): 1e5 per-body effects cost their numbers, not 1e5 objects.

        Parameters
        ----------
        effect : str
            An effect name acting on one body (``"applied_torque"``, ``"reaction_wheels"``, ...).
        bodies : sequence of str, (n,)
            The body of each effect, in order (a force effect may name a body more than once).
        **params
            The effect's parameters by name, in the units and frames its declaration states: a value of the
            declared shape is shared by every effect; an array with one more leading axis of length n gives each
            body its own, e.g. ``torque_w`` (n, 3), N·m, world frame. The arrays are copied.

        Returns
        -------
        sequence of Effect, (n,)
            The effects as stored, in order (``effects[k]`` is ``scene.effects``'s object for that effect).

        Raises
        ------
        LavenderInputError
            The error ``add_effect`` raises for the first body whose effect it refuses (the same field and rule,
            e.g. ``applied_torque.torque_w``), naming that body (``bodies[17] = 'b17'``); nothing is added.

        Examples
        --------
        >>> import numpy as np, lavendersim as lv
        >>> scene = lv.Scene()
        >>> names = [f"b{i}" for i in range(3)]
        >>> bodies = scene.add_bodies(names, np.ones(3), np.tile([0.02, 0.03, 0.04], (3, 1)))
        >>> torques = scene.add_effects("applied_torque", names, torque_w=[[0, 0, 1e-3], [0, 1e-3, 0], [1e-3, 0, 0]])
        >>> torques[1].body, torques[1].torque_w.tolist(), len(scene.effects)
        ('b1', [0.0, 0.001, 0.0], 3)
        """
        return _add_effects(self, effect, bodies, params)

    def index(self, name: str) -> int:
        """The position of body `name` in the state arrays.

        Parameters
        ----------
        name : str
            A body name.

        Returns
        -------
        int

        Raises
        ------
        LavenderInputError
            If no body has that name.
        """
        if name not in self.bodies:
            raise V.LavenderInputError("body", f"unknown body {name!r}; bodies: {', '.join(self.bodies) or 'none'}")
        return self._bodies.position(name)

    def model_effects(self, name: str) -> dict:
        """The per-body (model) effects declared on body `name`.

        Parameters
        ----------
        name : str
            A body name.

        Returns
        -------
        dict
            ``{"spherical_joint": e, "reaction_wheels": e}``, only the ones declared.
        """
        return {e.name: e for e in self.effects.models_on(name)}

    def arrays(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(state (nb, 13), params (nb, 4) = [m, I_x, I_y, I_z], effects (ne, width)) for the backends.
        The effect table holds only force effects, one row each ([code, body, parameters …], see
        lavendersim.effects; width = the widest, at least effects.ROW); joints and wheels are
        per-body model rows that the Sim builds (they need the initial state).

        A body given a full inertia tensor is stepped in its principal frame (lavendersim.frames): its
        state row and its effects' body-frame parameters (``r_b``) are rotated there; an every-body effect
        with a body-frame parameter then becomes one row per body."""
        t = self.tables()
        return t.state, t.params, t.effects

    def tables(self) -> "Tables":
        """What :meth:`arrays` returns plus the force effects' rows (``rows_of[k]``: the table rows of the
        k-th force effect) and the principal frames (None when every body frame is principal)."""
        if not self.bodies:
            raise V.LavenderInputError("scene.bodies", "a scene needs at least one body")
        state, params, given = self._bodies.arrays()
        nb = len(state)
        if given:   # batch-added bodies are the scene's own read-only arrays, validated when added
            idx = [i for i, _ in given]
            _revalidate([b.name for _, b in given], state[idx], params[idx])
        rotated = [(i, b.R_bp) for i, b in given if not b.principal]
        frames = None
        if rotated:
            R_bp = np.tile(np.eye(3), (nb, 1, 1))
            R_bp[[i for i, _ in rotated]] = np.stack([R for _, R in rotated])
            frames = PrincipalFrames(R_bp)
        if frames is not None:
            for i in frames.idx:
                state[i] = frames.internal_row(int(i), state[i])
        forces = [e for e in self.effects.items() if not e.per_body]      # Effects and batches
        effects, rows_of = _force_table(self, forces, frames, nb)
        return Tables(state, params, effects, _EffectList(forces), rows_of, frames)


# relative margin of the vectorized overflow bound: covers the rounding of the exact check's sums and norms
_BOUND_MARGIN = 1e-9


def _row_norms(a, n: int) -> np.ndarray:
    """|a| per row of an (n, 3)-broadcastable array (0 for None), scaled by max|a| (no overflow or underflow
    of the squares); inf or NaN where a row is not finite."""
    if a is None:
        return np.zeros(n)
    a = np.broadcast_to(np.asarray(a, dtype=np.float64), (n, 3))
    s = np.max(np.abs(a), axis=1)
    safe = np.where(s > 0, s, 1.0)
    return np.where(s > 0, s * np.sqrt(np.sum((a / safe[:, None]) ** 2, axis=1)), s)


def _load_sums(every: list, effects: "_EffectList | None", x: np.ndarray, params: np.ndarray,
               pos=None) -> tuple[np.ndarray, np.ndarray]:
    """Σ_e |F_e| and Σ_e |tau_e| per body (rows of the initial states x (n, 13) and [m, I_b] rows params (n, 4))
    over the declared every-body force effects `every` and (effects given) the per-body force effects of `effects`
    on each body (pos: body name -> row), each evaluated in one batched call of its printed NumPy function.

    A body whose sums stay below MAX_LOAD by a margin (_clear; also over its mass and smallest moment) cannot
    overflow with any subset of these effects: the exact, per-body check (load_overflow) runs on the others only
    (a non-finite term is never cleared; a function that fails on a batch raises, and the caller checks all)."""
    n = len(x)
    m, I_b = params[:, LY.PARAM_M], params[:, LY.PARAM_I_B]
    SF, ST = np.zeros(n), np.zeros(n)
    with np.errstate(all="ignore"):
        for e in every:   # on every body
            p = e.params_flat()
            f, t = numpy_apply(e.code)(np.broadcast_to(p, (n, p.size)), x, x[:, LY.STATE_V_W], m, I_b)
            SF += _row_norms(f, n)
            ST += _row_norms(t, n)
        groups: dict[int, tuple[list, list]] = {}       # effects on one body each, by code
        for body, mine in (effects._index()["on"].items() if effects is not None else ()):
            for _, e in mine:
                if body in pos and _declared(e):
                    idx, ps = groups.setdefault(e.code, ([], []))
                    idx.append(pos[body])
                    ps.append(e.params_flat())
        runs = [(code, np.asarray(idx, dtype=np.int64), np.stack(ps)) for code, (idx, ps) in groups.items()]
        for _, b in (effects._index()["batches"] if effects is not None else ()):
            if not b.per_body and _declared(b):     # a batch of force effects: its columns, its bodies in x
                k = b.positions(pos._t._c) if isinstance(pos, _Positions) else np.fromiter(
                    (pos[name] if name in pos else -1 for name in b.bodies), np.int64, len(b))
                k = np.where(k < len(x), k, -1)
                runs.append((b.code, k[k >= 0], b.params_flat()[k >= 0]))
        for code, k, P in runs:
            xs = x[k]
            f, t = numpy_apply(code)(P, xs, xs[:, LY.STATE_V_W], m[k], I_b[k])
            np.add.at(SF, k, _row_norms(f, k.size))
            np.add.at(ST, k, _row_norms(t, k.size))
    return SF, ST


def _clear(SF: np.ndarray, ST: np.ndarray, params: np.ndarray) -> np.ndarray:
    """Bodies whose load sums (see _load_sums) stay below MAX_LOAD by the margin, as force, torque and both
    accelerations."""
    lim = MAX_LOAD * (1 - _BOUND_MARGIN)
    with np.errstate(all="ignore"):
        return ((SF <= lim) & (ST <= lim) & (SF / params[:, LY.PARAM_M] <= lim)
                & (ST / np.min(params[:, LY.PARAM_I_B], axis=1) <= lim))


def _overflow_suspects(every: list, effects: "_EffectList | None", x: np.ndarray, params: np.ndarray,
                       pos=None) -> np.ndarray:
    """The bodies (rows of x, in order) the exact overflow check must look at: those _load_sums cannot clear, or
    every body when an effect cannot run batched."""
    try:
        return np.flatnonzero(~_clear(*_load_sums(every, effects, x, params, pos), params))
    except Exception:   # noqa: BLE001  (a user effect that cannot run batched: the exact check decides everywhere)
        return np.arange(len(x))


class Tables(NamedTuple):
    """The arrays a Sim is built from (see :meth:`Scene.tables`)."""

    state: np.ndarray
    params: np.ndarray
    effects: np.ndarray
    forces: "_EffectList"        # the force effects (rows_of[k]: the rows of forces[k])
    rows_of: "_RowsOf"
    frames: PrincipalFrames | None


def _force_table(scene: Scene, forces: list, frames: PrincipalFrames | None, nb: int) -> tuple[np.ndarray, "_RowsOf"]:
    """The effect table of the force effects (entries of scene.effects: Effects and batches; one row each,
    [code, body, parameters …]; an every-body effect with a body-frame parameter in a scene with a rotated body one
    row per body) and each effect's rows. Runs of effects of one class that need no rotation, and batches, are
    stacked batched (the rows Effect.row writes, without a call each)."""
    blocks: list[np.ndarray] = []
    rows_of = _RowsOf()
    k, lo = 0, 0
    while lo < len(forces):
        e = forces[lo]
        hi = lo + 1
        if type(e) is _Batch and not _unrotated(e, frames, scene._bodies.positions):
            forces[lo:hi] = [e.effect(j) for j in range(len(e))]     # (a rotated body in it: effect by effect)
            continue
        if type(e) is _Batch or _unrotated(e, frames, scene._bodies.positions):
            while (type(e) is not _Batch and hi < len(forces) and type(forces[hi]) is type(e)
                   and _unrotated(forces[hi], frames, scene._bodies.positions)):
                hi += 1
            run = e.bodies if type(e) is _Batch else [f.body for f in forces[lo:hi]]
            if type(e) is _Batch:
                body = np.where(e.positions(scene._bodies._c) < 0, -2, e.positions(scene._bodies._c)).astype(np.float64)
            else:
                at = _name_index(scene._bodies._c)
                body = np.fromiter((-1 if b is None else at.get(b, -2) for b in run), np.float64, len(run))
            if (body == -2).any() or (body >= nb).any():   # a body not (yet) in the scene: index raises naming it
                scene.index(run[int(np.flatnonzero((body == -2) | (body >= nb))[0])])
            flat = e.params_flat() if type(e) is _Batch else _stacked_params(forces[lo:hi])
            block = np.zeros((len(run), ROW_PARAMS + flat.shape[1]))
            block[:, ROW_CODE], block[:, ROW_BODY], block[:, ROW_PARAMS:] = e.code, body, flat
            rows_of.run(k, len(run))
        else:
            rows = _effect_rows(e, -1 if e.body is None else scene.index(e.body), 0, frames, nb)
            block = np.array(rows, dtype=np.float64).reshape(len(rows), -1)
            rows_of.one(list(range(k, k + len(block))))
        blocks.append(block)
        k += len(block)
        lo = hi
    width = max([ROW] + [b.shape[1] for b in blocks])
    table = np.zeros((k, width))
    k = 0
    for b in blocks:
        table[k:k + len(b), :b.shape[1]] = b
        k += len(b)
    return table, rows_of


class _RowsOf(Sequence):
    """rows_of[k]: the effect-table rows of the k-th force effect (a list of ints), kept as runs of one row per
    effect (a batch's n effects cost one run, not n lists)."""

    def __init__(self) -> None:
        self._starts: list[int] = []      # first effect of each run
        self._runs: list[tuple] = []      # (first row, count) or (explicit rows,)
        self._n = 0

    def run(self, row: int, count: int) -> None:
        self._starts.append(self._n)
        self._runs.append((row, count))
        self._n += count

    def one(self, rows: list) -> None:
        self._starts.append(self._n)
        self._runs.append((rows,))
        self._n += 1

    def __len__(self) -> int:
        return self._n

    def __getitem__(self, k):
        if isinstance(k, slice):
            return [self[j] for j in range(*k.indices(self._n))]
        if not -self._n <= k < self._n:
            raise IndexError(k)
        k %= self._n
        i = bisect.bisect_right(self._starts, k) - 1
        r = self._runs[i]
        return list(r[0]) if len(r) == 1 else [r[0] + k - self._starts[i]]


def _unrotated(e: "Effect | _Batch", frames: PrincipalFrames | None, pos) -> bool:
    """Effect e's row needs no rotation into a principal frame (see _effect_rows)."""
    if frames is None or not any(p.frame == "body" for p in (e.spec.params if e.spec is not None else ())):
        return True
    if isinstance(e, _Batch):
        return all(b in pos and frames.rotation(pos[b]) is None for b in e.bodies)
    return e.body is not None and e.body in pos and frames.rotation(pos[e.body]) is None


def _stacked_params(run: list) -> np.ndarray:
    """Effect.params_flat of each effect of one class, stacked (k, n_params)."""
    fields = type(run[0]).fields
    try:
        cols = [np.asarray([e.values[f] for e in run], dtype=np.float64).reshape(len(run), -1) for f in fields]
    except ValueError:     # parameters of different lengths: one call each
        flats = [e.params_flat() for e in run]
        out = np.zeros((len(run), max(f.size for f in flats)))
        for j, f in enumerate(flats):
            out[j, :f.size] = f
        return out
    return np.concatenate(cols, axis=1) if cols else np.zeros((len(run), 0))


def _effect_rows(e: Effect, body_index: int, width: int, frames: PrincipalFrames | None, nb: int) -> list[np.ndarray]:
    """The effect-table rows of force effect e on body_index (-1: every body), its body-frame parameters
    in each body's principal frame: one row, or one per body for an every-body effect with a body-frame
    parameter in a scene with a non-principal body."""
    body_frame = [p for p in (e.spec.params if e.spec is not None else ()) if p.frame == "body"]
    if frames is None or not body_frame or (body_index >= 0 and frames.rotation(body_index) is None):
        return [e.row(body_index, width)]
    out = []
    for i in (range(nb) if body_index < 0 else (body_index,)):
        r = e.row(i, width)
        R = frames.rotation(i)
        if R is not None:
            for p in body_frame:   # each 3-vector (or row of a matrix) v -> R_bpᵀ v
                sl = slice(ROW_PARAMS + p.offset, ROW_PARAMS + p.offset + p.size)
                r[sl] = (r[sl].reshape(-1, 3) @ R).ravel()
        out.append(r)
    return out


def _revalidate(names, state: np.ndarray, params: np.ndarray) -> None:
    """Body's rules once more over the stacked arrays a Sim is built from (vectorized; a Body is immutable, but
    object.__setattr__ gets past that): a body changed after validation is refused by name, not simulated."""
    m, I_b = params[:, LY.PARAM_M], params[:, LY.PARAM_I_B]
    tri = _triangle_broken(I_b)
    with np.errstate(invalid="ignore", over="ignore"):
        q_norm = np.sqrt(np.sum(state[:, Q] ** 2, axis=1))
    checks = (("mass", ~(np.isfinite(m) & (m > 0)), "must be finite and > 0"),
              ("I_b", ~(np.isfinite(I_b).all(axis=1) & (I_b > 0).all(axis=1)) | tri,
               "principal moments must be finite, > 0 and each at most the sum of the other two"),
              ("x0", ~np.isfinite(state).all(axis=1) | ~(np.abs(q_norm - 1.0) <= 1e-12),
               "the initial state must be finite with a unit quaternion"))
    for field, bad, rule in checks:
        if bad.any():
            name = names[int(np.flatnonzero(bad)[0])]
            raise V.LavenderInputError(f"scene.bodies[{name!r}].{field}",
                                       f"{rule}; the Body was changed after validation (object.__setattr__ gets "
                                       "past its immutability)")


# ---- batched add_bodies (issue 12): the checks of Body / Scene.add_body over whole arrays -------------

def _rows(field: str, value, n: int, width: int | None) -> np.ndarray:
    """A finite real (n,) or (n, width) array (V.array's checks: bools, non-numbers, NaN/inf named by index)."""
    return V.array(field, value, (n,) if width is None else (n, width))


def _first_bad(field: str, bad: np.ndarray, check) -> None:
    """Re-validate the first flagged row with the scalar validator under the field name `field[i]`; it raises
    the same error Body would (the vectorized screen only selects rows, the scalar check decides)."""
    for i in np.flatnonzero(bad)[:1]:
        check(f"{field}[{int(i)}]", int(i))


def _unit_quaternions(q: np.ndarray) -> np.ndarray:
    """V.quaternion per row: zero rows rejected (naming the row), others scaled to unit length as it does."""
    with np.errstate(over="ignore"):   # the printed scaled normalization (derive/measures.py); |q| may be inf
        q_unit, norm = K.quat_normalize_scaled(q)
    _first_bad("q", ~(norm >= V.QUATERNION_MIN_NORM), lambda f, i: V.quaternion(f, q[i]))
    return q_unit


def _triangle_broken(I_b: np.ndarray) -> np.ndarray:
    """Per row of (n, 3) principal moments: some moment exceeds the sum of the other two (rel. V.TRIANGLE_RTOL)."""
    with np.errstate(invalid="ignore", divide="ignore", over="ignore"):
        u = I_b / np.max(I_b, axis=1)[:, None]
        return np.asarray(np.stack([u[:, k] - (u[:, i] + u[:, j]) > V.TRIANGLE_RTOL
                                    for k, (i, j) in enumerate(((1, 2), (0, 2), (0, 1)))], axis=1).any(axis=1))


def _principal_moments(I_b: np.ndarray) -> None:
    """V.inertia's rules for (n, 3) principal moments: all > 0, each <= the sum of the other two (rel. 1e-12)."""
    _first_bad("I_b", ~np.all(I_b > 0, axis=1) | _triangle_broken(I_b), lambda f, i: V.inertia(f, I_b[i]))


@V.keywords
def add_bodies(scene: Scene, names: Sequence[str], masses: ArrayLike, I_b: ArrayLike, *, p_w: ArrayLike | None = None,
               q: ArrayLike | None = None, v_w: ArrayLike | None = None, omega_b: ArrayLike | None = None,
               omega_w: ArrayLike | None = None) -> Sequence[Body]:
    """Add n bodies at once, validated as Body(...) + Scene.add_body validate each, over whole arrays.

    Parameters
    ----------
    scene : Scene
        The scene the bodies join (``Scene.add_bodies`` passes itself).
    names : sequence of str, (n,)
        Non-empty, unique among themselves and new in the scene.
    masses : array_like, (n,)
        kg, finite and > 0.
    I_b : array_like, (n, 3)
        Principal moments about each COM, body frame, kg·m² (> 0, triangle inequality).
    p_w, v_w : array_like, (n, 3), optional
        COM positions (m) and velocities (m/s), world frame; default zeros.
    q : array_like, (n, 4), optional
        Orientations R_WB (x, y, z, w), each normalized (a zero row is rejected); default identity.
    omega_b, omega_w : array_like, (n, 3), optional
        Angular velocities in the body or the world frame (at most one of them); default zeros.

    Returns
    -------
    sequence of Body
        The new bodies, in order (each built when first accessed: a million bodies are stored as arrays).

    Raises
    ------
    LavenderInputError
        A bad row, naming the field and the row (e.g. ``I_b[17]``); nothing is added.
    """
    if isinstance(names, (str, bytes)) or not hasattr(names, "__len__"):
        raise V.LavenderInputError("names", "expected a sequence of body names", f", got {V._describe(names)}")
    names = list(names)
    n = len(names)
    for i, name in enumerate(names):
        if not isinstance(name, str) or not name:
            raise V.LavenderInputError(f"names[{i}]", "must be a non-empty string", f", got {V._describe(name)}")
    if len(scene._bodies) and not _name_index(scene._bodies._c).keys().isdisjoint(names):
        _first_duplicate(scene, names)
    m = _rows("masses", masses, n, None)
    _first_bad("masses", ~(m > 0), lambda f, i: V.positive(f, m[i]))
    I = _rows("I_b", I_b, n, 3)
    _principal_moments(I)
    x = np.empty((n, STATE_SIZE))
    x[...] = _DEFAULT_ROW
    if q is not None:
        x[:, Q] = _unit_quaternions(_rows("q", q, n, 4))
    if p_w is not None:
        x[:, P] = _rows("p_w", p_w, n, 3)
    if v_w is not None:
        x[:, VEL] = _rows("v_w", v_w, n, 3)
    if omega_b is not None and omega_w is not None:
        raise V.LavenderInputError("omega_w", "give omega_b or omega_w, not both")
    if omega_w is not None:
        x[:, W] = K.world_to_body(x[:, Q], _rows("omega_w", omega_w, n, 3)) if n else 0.0
    elif omega_b is not None:
        x[:, W] = _rows("omega_b", omega_b, n, 3)
    p = np.empty((n, 4))
    p[:, LY.PARAM_M], p[:, LY.PARAM_I_B] = m, I
    p.flags.writeable = False
    x.flags.writeable = False
    every = [e for e in scene.effects.forces_on(None) if _declared(e)]
    for i in (_overflow_suspects(every, None, x, p) if every else ()):
        b = _batch_body(names[i], x[i], p[i])
        why = load_overflow(every, b)
        if why:
            raise V.LavenderInputError(f"names[{i}]", f"body {b.name!r}: {why} with the scene's effects on every body "
                                       f"({', '.join(e.name for e in every)})")
    start = len(scene._bodies)
    given = [s for s, v in ((P, p_w), (Q, q), (VEL, v_w), (W, omega_w if omega_b is None else omega_b)) if v is not None]
    states = _States(x, given)
    del x               # (the whole rows: 104 B per body, returned before the table grows)
    if not scene._bodies.add_batch(names, states, p):      # a name repeated within `names`: nothing was added
        _first_duplicate(scene, names)
    return _Added(scene._bodies, start, n)


def _first_duplicate(scene: Scene, names: list) -> None:
    """Refuse the first name (in order) that is taken in the scene or repeats an earlier one."""
    seen: dict[str, int] = {}
    for i, name in enumerate(names):
        if name in scene.bodies or name in seen:
            raise V.LavenderInputError(f"names[{i}]", f"duplicate name {name!r}"
                                       + ("" if name in scene.bodies else f" (also names[{seen[name]}])"))
        seen[name] = i


class _Added(Sequence):
    """The bodies one add_bodies call added, in order: Body objects built on access (see _BodyTable)."""

    def __init__(self, table: _BodyTable, start: int, n: int):
        self._t, self._start, self._n = table, start, n

    def __len__(self) -> int:
        return self._n

    def __getitem__(self, i):
        if isinstance(i, slice):
            return [self[k] for k in range(*i.indices(self._n))]
        if not -self._n <= i < self._n:
            raise IndexError(i)
        return self._t.body(self._start + (i % self._n))


Scene.add_bodies.__doc__ = add_bodies.__doc__


# ---- batched add_effects (issue 30): add_effect's checks over whole arrays ------------------------------------

def _add_effects(scene: Scene, name, bodies, params: dict) -> Sequence[Effect]:
    """Scene.add_effects: a vectorized screen flags every row that might fail one of add_effect's checks (a
    parameter's rule, an unknown or repeated body, the body check of wheels and joints, an overflowing load);
    the unflagged stretches are appended as batches and each flagged row goes through add_effect itself, in order.
    The screen never clears a row add_effect would refuse, so the first refusal is add_effect's; it is raised
    naming the body, after every effect of this call has been taken out again. Accepted, the call's effects
    become one _Batch (the effects add_effect built kept in it)."""
    if isinstance(bodies, (str, bytes)) or not hasattr(bodies, "__len__"):
        raise V.LavenderInputError("bodies", "expected a sequence of body names", f", got {V._describe(bodies)}")
    bodies = list(bodies)
    n = len(bodies)
    if n == 0:
        return _EffectList()
    per_row = {}                    # parameter -> (n, ...) float64 array of one value per body (a copy)
    shared = dict(params)
    cls = EFFECTS.get(name) if isinstance(name, str) else None
    flags = np.zeros(n, bool)
    flags[0] = True                 # the first row through add_effect: it validates the shared values and the class
    if cls is None or cls.spec is None:
        flags[:] = True
    else:
        specs = {p.name: p for p in cls.spec.params}
        for f, v in params.items():
            p = specs.get(f)
            a = _per_body_values(v, p, n)
            if a is None:
                continue
            per_row[f] = a
            del shared[f]
            flags |= _breaks_rule(a, p)
    table = scene._bodies
    pos = _name_index(table._c)
    idx = np.fromiter((pos.get(b, -1) if isinstance(b, str) and b else -1 for b in bodies), np.int64, n)
    flags |= idx < 0
    if not flags.all() and cls is not None:   # (cls None: every row is flagged)
        try:   # a shared value the screen cannot read is judged by add_effect on row 0: then every row goes there
            flags |= _model_flags(scene, cls, idx, per_row, shared, bodies)
            if not cls.per_body and _declared_class(cls):
                flags |= _load_flags(scene, cls, idx, per_row, shared, n)
        except Exception:   # noqa: BLE001
            flags[:] = True
    items = scene.effects.items()
    first = len(items)
    made: dict[int, Effect] = {}
    try:
        for lo, hi, bad in _stretches(flags):
            for i in range(lo, hi) if bad else ():
                try:
                    made[i] = scene.add_effect(name, body=bodies[i], **_row_params(shared, per_row, i))
                except V.LavenderInputError as err:
                    raise V.LavenderInputError(err.field, err.rule, f"{err.detail} (bodies[{i}] = {bodies[i]!r})") from None
            if not bad:
                scene.effects.append(_Batch(cls, bodies[lo:hi], _shared_values(made[0], per_row),
                                            {f: a[lo:hi] for f, a in per_row.items()}))
        batch = _Batch(type(made[0]), bodies, _shared_values(made[0], per_row), per_row, made, 0, (table._c, idx))
    finally:
        del items[first:]       # the call's entries: replaced by one batch, or (refused) nothing half-applied
        scene.effects._edited()
    scene.effects.append(batch)
    return _EffectList([batch])     # (a list of its own: editing it leaves the scene's alone)


def _shared_values(template: Effect, per_row: dict) -> dict:
    """The validated values of the parameters an add_effects call shares (those of its first effect)."""
    return {f: v for f, v in template.values.items() if f not in per_row}


def _per_body_values(v, p, n: int) -> np.ndarray | None:
    """Parameter value v as one value per body (a float64 (n, *shape) array), or None when it is one shared
    value (of the declared shape) — or anything the screen does not read (add_effect judges it on row 0)."""
    if p is None:
        return None
    try:
        a = np.asarray(v)
    except Exception:   # noqa: BLE001
        return None
    if a.dtype.kind not in "iuf" or a.ndim != len(p.shape) + 1 or a.shape[0] != n:
        return None
    out = np.array(a, dtype=np.float64)     # a copy: the caller's array stays theirs (and writeable)
    out.flags.writeable = False
    return out


def _breaks_rule(a: np.ndarray, p) -> np.ndarray:
    """Rows of a per-body parameter array that break its declared rule (finite; > 0 / >= 0; an upto length)."""
    flat = a.reshape(len(a), -1)
    with np.errstate(invalid="ignore"):
        bad = ~np.isfinite(flat).all(axis=1)
        if p.rule == "positive":
            bad |= ~(flat > 0).all(axis=1)
        elif p.rule == "nonnegative":
            bad |= ~(flat >= 0).all(axis=1)
    if (p.upto and not 1 <= a.shape[1] <= p.shape[0]) or (not p.upto and a.shape[1:] != tuple(p.shape)):
        bad[:] = True
    return bad


def _model_flags(scene: Scene, cls, idx: np.ndarray, per_row: dict, shared: dict, bodies: list) -> np.ndarray:
    """Rows a per-body (model) effect might be refused on: the body has one already, or earlier in this call;
    the wheels' check against the body where it is not the plain J < I_b of three wheels on the body axes."""
    n = len(idx)
    flags = np.zeros(n, bool)
    if not cls.per_body:
        return flags
    flags |= scene.effects.have_per_body(cls.name, bodies)
    _, first = np.unique(idx, return_index=True)
    repeat = np.ones(n, bool)
    repeat[first] = False
    flags |= repeat
    if not hasattr(cls, "check_body"):
        return flags
    given = scene._bodies._c["given"]
    axes = shared.get("axes_b", cls.defaults.get("axes_b"))
    simple = (cls.name == "reaction_wheels" and "axes_b" not in per_row and "cutoff" not in per_row
              and axes is not None and np.array_equal(np.asarray(axes, dtype=float), np.eye(3))
              and not (given and any(int(i) in given and not given[int(i)].principal for i in idx)))
    if not simple:
        flags[:] = True
        return flags
    _, params, _ = scene._bodies.arrays()
    J = per_row["J"] if "J" in per_row else np.asarray(shared.get("J"), dtype=np.float64)[None]
    if J.shape[1:] != (3,):
        flags[:] = True
        return flags
    with np.errstate(invalid="ignore"):
        flags |= ~(J < params[np.maximum(idx, 0)][:, LY.PARAM_I_B]).all(axis=1)
    return flags


def _declared_class(cls) -> bool:
    return _declared(object.__new__(cls))


def _load_flags(scene: Scene, cls, idx: np.ndarray, per_row: dict, shared: dict, n: int) -> np.ndarray:
    """Rows whose body might be refused for an overflowing load: the triangle bound (see _overflow_suspects) of
    the scene's force effects on the body plus every effect of this call on it is not clear of MAX_LOAD."""
    x, params, _ = scene._bodies.arrays()
    try:
        SF, ST = _load_sums([e for e in scene.effects.forces_on(None) if _declared(e)], scene.effects, x, params,
                            scene._bodies.positions)
        k = np.maximum(idx, 0)
        P = _flat_params(cls, shared, per_row, n)
        with np.errstate(all="ignore"):
            f, t = numpy_apply(cls.code)(P, x[k], x[k][:, LY.STATE_V_W], params[k, LY.PARAM_M], params[k][:, LY.PARAM_I_B])
            np.add.at(SF, k, _row_norms(f, n))
            np.add.at(ST, k, _row_norms(t, n))
            ok = _clear(SF, ST, params)
    except Exception:   # noqa: BLE001  (the exact check decides)
        return np.ones(n, bool)
    return ~ok[k]


def _flat_params(cls, shared: dict, per_row: dict, n: int) -> np.ndarray:
    """The effects' parameters in row order (Effect.params_flat per row), (n, n_params)."""
    cols = []
    for f in cls.fields:
        v = per_row[f] if f in per_row else np.broadcast_to(
            np.asarray(shared.get(f, cls.defaults.get(f)), dtype=np.float64), (n,) + np.shape(shared.get(f, cls.defaults.get(f))))
        cols.append(np.asarray(v, dtype=np.float64).reshape(n, -1))
    return np.concatenate(cols, axis=1) if cols else np.zeros((n, 0))


def _stretches(flags: np.ndarray):
    """(lo, hi, flagged) runs of equal flags, in order."""
    edges = np.flatnonzero(np.diff(flags.astype(np.int8))) + 1
    bounds = [0, *edges.tolist(), len(flags)]
    return [(lo, hi, bool(flags[lo])) for lo, hi in zip(bounds[:-1], bounds[1:])]


def _row_params(shared: dict, per_row: dict, i: int) -> dict:
    return {**shared, **{f: a[i] for f, a in per_row.items()}}
