"""Scene effects: what a scene declares is all the simulator evaluates.

Every effect is declared once, in SymPy (built-ins in derive/effects.py; your own in one file outside
the package, see docs/extending.md), and ``lavendersim derive`` prints from that declaration the
metadata this module reads (generated/effects_meta.py, or a user set's effects_meta.py): the code,
the parameters (name, shape, unit, validation rule, default, offset) and what the effect reads. The
Effect classes below are built from it; no code number or parameter layout is typed here.

Force effects act on one named body or, with body=None, on every body. Their rows in the effect
table are [code, body index (-1: all), parameters …] (layout constants ROW_*; a row holds at least
ROW_MIN_PARAMS parameters). Frames and units: see each effect's parameters (``EFFECTS[name].spec``)
or generated/EQUATIONS.md.

Two effects change a body's model instead of adding a force (``per_body = True``; body= required,
at most one of each per body): ``spherical_joint`` pins the body point that coincides with anchor_w
at the start to that world point; ``reaction_wheels`` adds 1 to WHEELS_MAX wheels on the unit axes
``axes_b`` (rows, body frame; default three on the body x, y, z axes), one J per axis, the body with
its wheels free keeping a positive definite inertia (checked by ``check_body``). The Sim turns them into
per-body model rows (lavendersim.backends.MODEL_LAYOUT); they never appear in the effect table.

An effect whose name and code are not declared (an ``Effect`` subclass with a new code) is refused
by ``Sim`` with a LavenderInputError, and both backends refuse an unknown code in the table.
"""
from __future__ import annotations

import re
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from types import MappingProxyType
from typing import TYPE_CHECKING, Any, cast

import numpy as np

from . import user_sets
from . import validate as V
from .generated import effects_meta as _META
from .generated import layout as LY
from .kernels import K

ROW_CODE, ROW_BODY, ROW_PARAMS = _META.ROW_CODE, _META.ROW_BODY, _META.ROW_PARAMS
ROW_MIN_PARAMS = _META.ROW_MIN_PARAMS
ROW = ROW_PARAMS + ROW_MIN_PARAMS  # the narrowest row (wider when an effect has more parameters)
USER_CODE_BASE = _META.USER_CODE_BASE
FLAG_USES_V, FLAG_USES_OMEGA, FLAG_FORCE = _META.FLAG_USES_V, _META.FLAG_USES_OMEGA, _META.FLAG_FORCE
FLAG_TORQUE_W, FLAG_TORQUE_B = _META.FLAG_TORQUE_W, _META.FLAG_TORQUE_B
# Right-hand side classes of plain bodies with effects (rhs_classes), the NumPy backend's codes of the kinds derive
# prints (RHS_CLASS_OF_KIND: TORQUE, world torques only, runs the FULL kernel here: bitwise the same, as in C)
RHS_FULL, RHS_FORCE, RHS_BODY, RHS_BODY_F = (_META.RHS_CLASSES.index(k) for k in ("FULL", "FORCE", "BODY", "BODY_F"))
_RHS_OF_KIND = _META.RHS_CLASS_OF_KIND
# the printed rule (derive/effect_fuse.py tile_kind): class per combination of the flags RHS_BITS
RHS_BITS: tuple[int, ...] = _META.RHS_BITS
_RHS_BY_INDEX = np.array([_RHS_OF_KIND[k] for k in _META.RHS_KINDS_BY_FLAGS], dtype=np.intp)
# how a plain body of each class steps when none of its effects couples translation and rotation (FLAG_COUPLED clear,
# all built-in, not all constant; derive/effect_fuse.py SPLIT_OF_KIND): 0 the 13-number stages, 1 its rotation staged
# torque-free, 2 under its body-frame torque sums; its translation then by the printed translation_flow
FLAG_COUPLED, FLAG_USES_STATE = _META.FLAG_COUPLED, _META.FLAG_USES_STATE
RHS_SPLIT: tuple[int, ...] = _META.RHS_SPLIT_BY_CLASS   # by class (RHS_FULL ...)
INC_SCALE_C, INC_SCALE_HQ = slice(*_META.INC_SCALE_C), _META.INC_SCALE_HQ   # C_b and h_q within the increments' S
# where every sum of effect contributions starts (derive/effect_fuse.py SUM_START, C's LV_SUM_START): IEEE's additive
# identity -0.0, so a sum is bitwise its terms' sum alone and a sum of nothing is -0, as in C
SUM_START: float = float(_META.SUM_START)


def rhs_classes(flags: np.ndarray) -> np.ndarray:
    """The right-hand side class of plain bodies with effects, from the OR of their effects' rhs_flags: RHS_BODY /
    RHS_BODY_F when every torque is declared in the body frame (rigid_body_rhs_body_c on the effects' body-frame
    forms), without / with a force; RHS_FORCE a force and no torque (rigid_body_rhs_force_c on a_w = F/m); else
    RHS_FULL (rigid_body_rhs_c: world torques). The rule is derive's, printed as a table into effects_meta
    (RHS_KINDS_BY_FLAGS) and kernels.h (csrc/step.c rhs_class reads the same table).

    Parameters
    ----------
    flags : ndarray of int
        Per body, the OR of its effects' EffectSpec.rhs_flags.

    Returns
    -------
    ndarray of int
        Per body, RHS_FULL, RHS_FORCE, RHS_BODY or RHS_BODY_F (flags' shape).
    """
    flags = np.asarray(flags)
    index = np.zeros(flags.shape, dtype=np.intp)
    for j, bit in enumerate(RHS_BITS):
        index |= ((flags & bit) != 0).astype(np.intp) << j
    return _RHS_BY_INDEX[index]


def constant_kind(flags: int, user: bool) -> tuple[bool, bool] | None:
    """The step of a plain body with effects when they all read no state (derive/effect_fuse.py CONSTANT_KINDS,
    printed as effects_meta RHS_CONSTANT; csrc/step.c lv_const_rk4_h): (torque, force) of its kind, or None when an
    effect reads the state or is a user effect (csrc effects_constant).

    Parameters
    ----------
    flags : int
        The OR of the body's effects' EffectSpec.rhs_flags.
    user : bool
        Some effect of the body is a user effect.

    Returns
    -------
    tuple of bool or None
        (torque: q and omega_b take the world torque sum, force: p and v take the constant force's exact flow).
    """
    if user or flags & FLAG_USES_STATE:
        return None
    return _META.RHS_CONSTANT.get(rhs_kind(flags))


def rhs_kind(flags: int) -> str:
    """The right-hand-side kind of a plain body with effects: derive's rule, printed as effects_meta.RHS_KINDS_BY_FLAGS
    over RHS_BITS.

    Parameters
    ----------
    flags : int
        The OR of the body's effects' EffectSpec.rhs_flags (at least one effect).

    Returns
    -------
    str
        "TORQUE", "FULL", "FORCE", "BODY" or "BODY_F".
    """
    return _META.RHS_KINDS_BY_FLAGS[sum(1 << j for j, bit in enumerate(RHS_BITS) if flags & bit)]


@dataclass(frozen=True)
class ParamSpec:
    """One declared parameter of an effect (printed by derive into effects_meta).

    Parameters
    ----------
    name : str
        Parameter name (a keyword of the effect).
    shape : tuple
        ``()`` for a scalar, ``(n,)`` for a vector.
    unit : str
        SI unit, e.g. ``"N·m"``.
    doc : str
        Meaning, with its frame.
    rule : {"finite", "positive", "nonnegative"}
        Validation rule applied to every entry.
    default : object
        Default value, or None if required.
    offset : int
        Offset in the row's parameters.
    upto : bool, optional
        The leading length of ``shape`` is a maximum (model effects: e.g. one entry per reaction wheel).
    frame : {"body", "world", None}, optional
        The frame of a 3-vector (or of each row of a matrix): "body" values of a body given a full
        inertia tensor are rotated into its principal frame before the kernels see them.
    """

    name: str
    shape: tuple
    unit: str
    doc: str
    rule: str
    default: object
    offset: int
    upto: bool = False
    frame: str | None = None   # "body": a body-frame vector (or rows of them), rotated for a non-principal body

    @property
    def size(self) -> int:
        """Number of floats the parameter takes in a row (its full declared shape)."""
        return int(np.prod(self.shape)) if self.shape else 1

    def text(self) -> str:
        """The shape as a docstring shows it, e.g. ``(3,)``, ``(1 … 4,)``, ``(1 … 4, 3)``."""
        lead = f"1 … {self.shape[0]}" if self.upto else str(self.shape[0])
        return "(" + ", ".join([lead] + [str(n) for n in self.shape[1:]]) + ("," if len(self.shape) == 1 else "") + ")"


@dataclass(frozen=True)
class EffectSpec:
    """What derive printed about one effect (see the module docstring).

    Parameters
    ----------
    name : str
        Effect name.
    code : int
        Code in the effect table (user effects from USER_CODE_BASE on).
    kind : {"force", "model"}
        A force/torque contribution, or a change of the body's model (joint, wheels).
    summary : str
        One line on what it does.
    params : tuple of ParamSpec
        Declared parameters in row order.
    n_params : int
        Floats they take in a row.
    outputs : tuple of str
        What it contributes (``"F_w"``, ``"tau_w"``).
    state_inputs : tuple of str
        What it reads (``"p_w"``, ``"q"``, ``"v_w"``, ``"omega_b"``, ``"m"``, ``"I_b"``).
    flags : int
        FLAG_* bits.
    kernel : str or None
        Name of its generated kernel.
    source : str, optional
        ``"built-in"`` or the directory of the user set it was loaded from.
    user_set : object, optional
        The loaded user set (lavendersim.extending.UserSet), None for a built-in.
    decay_rate : callable or None, optional
        For a pure linear decay (derive/effect_decay.py), its printed rate ``f(p (n, n_params), m (n,), I_b (n, 3))
        -> (n,)``, 1/s; None otherwise.
    """

    name: str
    code: int
    kind: str
    summary: str
    params: tuple
    n_params: int
    outputs: tuple
    state_inputs: tuple
    flags: int
    kernel: str | None
    source: str = "built-in"
    user_set: user_sets.UserSet | None = field(default=None, repr=False, compare=False)
    decay_rate: Callable[..., np.ndarray] | None = field(default=None, repr=False, compare=False)

    @property
    def is_decay(self) -> bool:
        """A pure linear decay (derive/effect_decay.py): its load only takes momentum out, and an explicit step of
        it is stable while ``decay_rate(p, m, I_b) * dt`` stays below the integrator's REAL_AXIS_STABILITY."""
        return self.decay_rate is not None

    @property
    def velocity_dependent(self) -> bool:
        """Reads v_w or omega_b (the splitting integrator then kicks by the explicit midpoint rule)."""
        return bool(self.flags & (FLAG_USES_V | FLAG_USES_OMEGA))

    @property
    def uses_v_w(self) -> bool:
        """Reads v_w (a body on a spherical joint then computes its kinematic COM velocity)."""
        return bool(self.flags & FLAG_USES_V)

    @property
    def rhs_flags(self) -> int:
        """The flags both backends pick a plain body's right-hand side by: the effect's own, for a built-in effect and
        a user effect declaring its torque in the body frame (FLAG_TORQUE_B: its set exports the body-frame form);
        a user effect of a world torque adds it in the world frame (FLAG_TORQUE_W: a set derived before these flags
        existed says so through its outputs)."""
        if self.user_set is None or self.flags & FLAG_TORQUE_B:
            return self.flags
        return self.flags | (FLAG_TORQUE_W if "tau_w" in self.outputs else 0)

    @classmethod
    def from_meta(cls, entry: dict, code: int | None = None, source: str = "built-in", user_set=None) -> "EffectSpec":
        """Build a spec from one entry of a generated ``effects_meta.EFFECTS`` list.

        Parameters
        ----------
        entry : dict
            The printed metadata of one effect.
        code : int, optional
            Overrides ``entry["code"]``.
        source, user_set
            As in the class. ``decay_rate``: the printed function named by ``entry["decay_rate"]``, from the user
            set's metadata module, or the built-in one's.

        Returns
        -------
        EffectSpec
        """
        params = tuple(ParamSpec(p["name"], tuple(p["shape"]), p["unit"], p["doc"], p["rule"], p["default"], p["offset"],
                                 bool(p.get("upto", False)), p.get("frame", _frame_of(p)))
                       for p in entry["params"])
        return cls(entry["name"], entry["code"] if code is None else code, entry["kind"], entry["summary"], params,
                   entry["n_params"], tuple(entry["outputs"]), tuple(entry["state_inputs"]), entry["flags"],
                   entry["kernel"], source, user_set, _decay_function(entry, user_set))


def _decay_function(entry: dict, user_set):
    """The printed decay-rate function of a meta entry, or None (not a decay, or a set derived before it existed)."""
    name = entry.get("decay_rate")
    if not name:
        return None
    module = _META if user_set is None else user_set.meta
    return getattr(module, name)


def _frame_of(p: dict) -> str | None:
    """The frame of a parameter printed before derive printed frames (a user set derived by an older
    version): the name's suffix, as derive.effect.Param.frame reads it."""
    shape = tuple(p["shape"])
    return {"_b": "body", "_w": "world"}.get(p["name"][-2:]) if shape and shape[-1] == 3 else None


class ImmutableEffectError(V.LavenderInputError, AttributeError):
    """Assignment to an attribute of a validated Effect (a LavenderInputError and an AttributeError).

    Parameters
    ----------
    field : str
        ``effect.<attribute>``.
    rule : str
        Why it is refused.
    detail : str, optional
    """


def _rebuild_effect(class_name: str, name: str, body, values: dict, source: str | None = None):
    """Unpickle an Effect: a declared one by its registered name (validated again). A user effect not registered
    in this process (a worker, a fresh interpreter) is registered first from its set's folder ``source`` (verified
    against its manifest by lavendersim.user_sets.open_set), else found by name in the user directory."""
    if name not in EFFECTS:
        if source is not None and source != "built-in":
            register_set(user_sets.open_set(source))
        else:
            _discover(name)
    if name in EFFECTS:
        return EFFECTS[name](body=body, **values)
    raise V.LavenderInputError("effect", f"{name!r} is not a registered effect in this process (load its user set "
                               "first)")


def _rebuild_plain(cls, body, values: dict):
    return cls(body=body, **values)


class Effect:
    """An effect declared on a scene: ``body`` (a name, or None for every body) and validated ``values``.

    Declared effects are subclasses built from their EffectSpec (``spec``); a hand-written subclass
    without a declaration can be constructed but a Sim refuses it (see the module docstring).

    Parameters
    ----------
    body : str or None, optional
        The body it acts on; None for every body (force effects only).
    **params
        The declared parameters by name (see the subclass's docstring for shapes and units).

    Raises
    ------
    LavenderInputError
        On a missing, unknown or invalid parameter (named ``effect.param``).
    """

    spec: EffectSpec | None = None
    body: str | None                 # set once by __init__ (an Effect is immutable)
    values: Mapping[str, Any]        # the validated parameters by name, read-only
    name = ""
    code = 0
    per_body = False  # True: changes the body's model (joint, wheels); body= required
    fields: tuple[str, ...] = ()
    defaults: dict = {}

    def __init__(self, body: str | None = None, **params):
        params = {**self.defaults, **params}
        if self.per_body and body is None:
            raise V.LavenderInputError(f"{self.name}.body", "is required (the name of the body it acts on)")
        if body is not None and (not isinstance(body, str) or not body):
            rule = "must be a body name" + ("" if self.per_body else " or None (every body)")
            raise V.LavenderInputError(f"{self.name}.body", rule, f", got {body!r}")
        unknown = sorted(set(params) - set(self.fields))
        if unknown:
            raise V.LavenderInputError(f"{self.name}.{unknown[0]}", f"unknown parameter; known: {', '.join(self.fields)}")
        missing = [f for f in self.fields if f not in params]
        if missing:
            raise V.LavenderInputError(f"{self.name}.{missing[0]}", "is required")
        values = {f: self._check(f, params[f]) for f in self.fields}
        for v in values.values():  # validated once: read-only, so a later edit cannot bypass the checks
            if isinstance(v, np.ndarray):
                v.flags.writeable = False
        object.__setattr__(self, "body", body)
        object.__setattr__(self, "values", MappingProxyType(values))

    def __setattr__(self, field: str, value) -> None:
        """An Effect is immutable once validated: a parameter changed by assignment would be silently ignored
        by a Sim already built (and half-applied in a scene), so every assignment raises, naming the field."""
        raise ImmutableEffectError(f"{self.name or type(self).__name__}.{field}",
                                   "an effect is immutable once validated: change a force effect's parameters "
                                   "between steps with Sim.set_effect_params(effect, ...), or add a new effect "
                                   "to the scene")

    def __delattr__(self, field: str) -> None:
        raise ImmutableEffectError(f"{self.name or type(self).__name__}.{field}", "an effect is immutable once validated")

    def __getattr__(self, field: str):
        """A parameter by name, read-only (``e.torque_w``; the same array as ``e.values["torque_w"]``)."""
        values = self.__dict__.get("values")
        if values is not None and field in values:
            return values[field]
        raise AttributeError(f"{type(self).__name__!r} object has no attribute {field!r}")

    def __reduce__(self):
        if self.spec is None:   # a hand-written subclass: rebuilt from its class (importable by reference)
            return (_rebuild_plain, (type(self), self.body, dict(self.values)))
        return (_rebuild_effect, (type(self).__name__, self.name, self.body, dict(self.values), self.spec.source))

    def __copy__(self):
        return self

    def __deepcopy__(self, memo):
        return self

    def _check(self, f, v):
        """Validate parameter f by its declared shape and rule (a plain finite 3-vector without a spec)."""
        field_name = f"{self.name}.{f}"
        p = None if self.spec is None else next(p for p in self.spec.params if p.name == f)
        if p is None:
            return V.vector(field_name, v)
        if not p.shape:
            return V.scalar(field_name, v, positive=p.rule == "positive", nonnegative=p.rule == "nonnegative")
        out = V.array(field_name, v, ((None,) if p.upto else p.shape[:1]) + tuple(p.shape[1:]))
        if p.upto and not 1 <= out.shape[0] <= p.shape[0]:
            raise V.LavenderInputError(field_name, f"takes 1 to {p.shape[0]} entries (shape {p.text()})",
                                       f", got {out.shape[0]}")
        bad = np.flatnonzero(~(out > 0) if p.rule == "positive" else ~(out >= 0) if p.rule == "nonnegative"
                             else np.zeros(out.size, bool))
        if bad.size:
            op = ">" if p.rule == "positive" else ">="
            raise V.LavenderInputError(field_name, f"each entry must be {op} 0", f", got {out.tolist()}")
        return out

    def params_flat(self) -> np.ndarray:
        """The parameters in row order (the declared offsets; a matrix parameter row-major)."""
        return np.concatenate([np.ravel(np.asarray(self.values[f], dtype=np.float64)) for f in self.fields]) \
            if self.fields else np.zeros(0)

    def row(self, body_index: int, width: int = ROW) -> np.ndarray:
        """This effect's row of the effect table: [code, body index (-1: every body), parameters …].

        Parameters
        ----------
        body_index : int
            Index of its body in the scene, -1 for every body.
        width : int, optional
            Row width (at least ROW).

        Returns
        -------
        ndarray, shape (max(width, needed),)
        """
        flat = self.params_flat()
        r = np.zeros(max(width, ROW_PARAMS + flat.size))
        r[ROW_CODE], r[ROW_BODY] = self.code, body_index
        r[ROW_PARAMS:ROW_PARAMS + flat.size] = flat
        return r

    def describe(self) -> str:
        """A one-line description: ``name(param=value, ...)``."""
        vals = ", ".join(f"{f}={' '.join(np.array2string(np.atleast_1d(self.values[f]), precision=4).split())}"
                         for f in self.fields)
        return f"{self.name}({vals})"

    def __repr__(self):
        return f"{type(self).__name__}(body={self.body!r}, {self.describe()})"


class _WheelsCheck:
    """Hand-written check of reaction_wheels against its body (a relation the declaration cannot state)."""

    name: str                        # an Effect's (the class this mixes into)
    values: Mapping[str, Any]

    def check_body(self, body) -> None:
        """One J per axis, unit axes; the body with its wheels free keeps a positive definite inertia
        (I_b − A_b J A_bᵀ; on the body axes: J_i < I_b[i]); cutoff is 0 or 1."""
        if self.values["cutoff"] not in (0.0, 1.0):
            raise V.LavenderInputError(f"{self.name}.cutoff", "must be 0 (torque–speed line) or 1 (hard cut-off at speed_limit)",
                                       f", got {self.values['cutoff']!r}")
        I_b, J = body.I_b, self.values["J"]
        A_b = V.wheel_axes(f"{self.name}.axes_b", self.values["axes_b"].T)
        if J.size != A_b.shape[1]:
            raise V.LavenderInputError(f"{self.name}.J", f"needs one inertia per wheel axis (axes_b has {A_b.shape[1]} rows)",
                                       f", got {J.size}")
        principal = getattr(body, "principal", True)
        if self.on_body_axes and principal:
            bad = np.flatnonzero(J >= I_b)
            if bad.size:
                i = int(bad[0])
                raise V.LavenderInputError(f"{self.name}.J", f"J[{i}] must be below the body's principal moment "
                                           f"I_b[{i}] = {I_b[i]:g} kg·m² (the body's inertia includes its wheels)",
                                           f", got {J[i]:g}")
            return
        A_pad, J_pad = np.zeros((3, LY.WHEELS_MAX)), np.zeros(LY.WHEELS_MAX)   # the printed kernel's slots, unused ones 0
        A_pad[:, :J.size], J_pad[:J.size] = A_b, J
        free = getattr(K, f"wheels{LY.WHEELS_MAX}_free_inertia")(np.diag(I_b) if principal else body.inertia_b, A_pad, J_pad)
        low = float(np.linalg.eigvalsh(free).min())
        if not low > 1e-12 * float(I_b.max()):
            raise V.LavenderInputError(f"{self.name}.J", "the body with its wheels free, I_b − A_b J A_bᵀ, must stay "
                                       "positive definite (the body's inertia includes its wheels)",
                                       f", got smallest eigenvalue {low:.6g} kg·m² with J = {J.tolist()}")

    @property
    def on_body_axes(self) -> bool:
        """Three wheels on body x, y, z in that order (the default layout, A_b = I; the one wheel model steps every layout)."""
        return bool(np.array_equal(self.values["axes_b"], np.eye(3)))

    @property
    def A_b(self) -> np.ndarray:
        """The wheel axes as the columns of a (3, N) matrix, body frame."""
        return self.values["axes_b"].T.copy()


class _JointCheck:
    """Hand-written check of spherical_joint against its body: the pivot's model must be finite."""

    name: str                        # an Effect's (the class this mixes into)
    values: Mapping[str, Any]

    def check_body(self, body) -> None:
        """The inertia about the pivot (parallel axis, m |r_b|²) and the pivot kinematics at the body's
        initial state must be finite: an anchor_w too far from the COM is rejected here, naming anchor_w."""
        from .generated.layout import STATE_OMEGA_B, STATE_P_W, STATE_Q
        from .kernels import K

        anchor = self.values["anchor_w"]
        x = body.x0
        with np.errstate(all="ignore"):
            r_b = K.quat_to_matrix(x[STATE_Q]).T @ (x[STATE_P_W] - anchor)
            I_p = K.parallel_axis(body.inertia_b, body.mass, -r_b)
            p_w, v_w = K.pivot_kinematics(x[STATE_Q], x[STATE_OMEGA_B], anchor, r_b)
        if not all(np.all(np.isfinite(a)) for a in (r_b, I_p, p_w, v_w)):
            raise V.LavenderInputError(f"{self.name}.anchor_w", f"too far from the COM of body {body.name!r}: the "
                                       f"inertia about the pivot (m |r_b|², m = {body.mass:g} kg) or the pivot "
                                       "kinematics overflow a float64", f", got {V._nums(anchor)}")


_HAND_CHECKS = {"reaction_wheels": _WheelsCheck, "spherical_joint": _JointCheck}

REGISTRY: dict[str, EffectSpec] = {}   # name -> spec of every known effect (built-in and loaded user ones)
BY_CODE: dict[int, EffectSpec] = {}    # code -> spec (user codes stay valid after a set is reloaded)
EFFECTS: dict[str, type[Effect]] = {}          # name -> its Effect class


def _class_name(name: str) -> str:
    return "".join(w.capitalize() for w in name.split("_"))


def _effect_doc(spec: EffectSpec) -> str:
    """A numpydoc docstring for an effect class, from its declaration."""
    body = ("str\n    The body it acts on (required: at most one per body)." if spec.kind == "model"
            else "str or None, optional\n    The body it acts on; None for every body.")
    lines = [f"{spec.summary}.", "", f"Declared in {spec.source} (``{spec.name}``).", "",
             "Parameters", "----------", f"body : {body}"]
    for p in spec.params:
        kind = "float" if not p.shape else f"array_like, shape {p.text()}"
        opt = ", optional" if p.default is not None else ""
        dflt = f" Default {p.default}." if p.default is not None else ""
        lines += [f"{p.name} : {kind}{opt}", f"    {p.doc[:1].upper()}{p.doc[1:]}, {p.unit or 'dimensionless'} ({p.rule}).{dflt}"]
    return "\n".join(lines) + "\n"


def _effect_class(spec: EffectSpec) -> type[Effect]:
    attrs = {"spec": spec, "name": spec.name, "code": spec.code, "per_body": spec.kind == "model",
             "fields": tuple(p.name for p in spec.params),
             "defaults": {p.name: p.default for p in spec.params if p.default is not None},
             "__doc__": _effect_doc(spec),
             "__module__": __name__}
    bases = (_HAND_CHECKS[spec.name], Effect) if spec.name in _HAND_CHECKS else (Effect,)
    return cast("type[Effect]", type(_class_name(spec.name), bases, attrs))


def register(spec: EffectSpec) -> type[Effect]:
    """Add a declared effect to the registry (the built-ins at import; user sets when loaded).

    Parameters
    ----------
    spec : EffectSpec
        The declaration.

    Returns
    -------
    type
        The Effect subclass built for it.

    Raises
    ------
    LavenderInputError
        If its name or code clashes with a registered effect from another source.
    """
    old = REGISTRY.get(spec.name)
    if old is not None and old.source != spec.source:
        raise V.LavenderInputError("effect", f"{spec.name!r} from {spec.source} clashes with the effect of the same "
                                   f"name from {old.source}; rename one of them")
    if spec.code in BY_CODE and BY_CODE[spec.code].name != spec.name:
        raise V.LavenderInputError("effect", f"code {spec.code} of {spec.name!r} is taken by {BY_CODE[spec.code].name!r}")
    REGISTRY[spec.name] = spec
    BY_CODE[spec.code] = spec
    EFFECTS[spec.name] = cls = _effect_class(spec)
    return cls


for _entry in _META.EFFECTS:
    _cls = register(EffectSpec.from_meta(_entry))
    globals()[_cls.__name__] = _cls  # AppliedTorque, ForceAtPoint, Gravity, … SphericalJoint, ReactionWheels
del _entry, _cls

if TYPE_CHECKING:   # the classes registered above by name, for type checkers (lavendersim.Gravity, ...)
    class AppliedTorque(Effect): ...
    class ForceAtPoint(Effect): ...
    class Gravity(Effect): ...
    class LinearDamping(Effect): ...
    class AngularDamping(Effect): ...
    class SphericalJoint(_JointCheck, Effect): ...
    class ReactionWheels(_WheelsCheck, Effect): ...


def register_set(s) -> None:
    """Register the effects of an opened user set (lavendersim.user_sets.UserSet): each gets a code from
    USER_CODE_BASE (a set registered again keeps its codes). Every clash is found before anything is registered.

    Parameters
    ----------
    s : lavendersim.user_sets.UserSet

    Raises
    ------
    lavendersim.validate.LavenderInputError
        An effect named as a built-in one, or (UserSetError) one another registered set declares.
    """
    if all(n in REGISTRY and REGISTRY[n].user_set is s for n in s.effect_names):
        return
    for entry in s.meta.EFFECTS:
        prev = REGISTRY.get(entry["name"])
        if prev is not None and prev.source == "built-in":
            raise V.LavenderInputError("user effects", f"{entry['name']!r} in {s.declaration} is the name of a "
                                       "built-in effect; rename it")
        if prev is not None and prev.user_set is not None and prev.user_set.directory != s.directory:
            o = prev.user_set
            raise user_sets.UserSetError("user set", f"effect {entry['name']!r} is declared by {s.declaration} (set "
                                         f"{s.directory}) and by {o.declaration} (set {o.directory}, loaded first)",
                                         "; an effect name belongs to one set: rename it in one of the files")
    for entry in s.meta.EFFECTS:
        prev = REGISTRY.get(entry["name"])
        code = prev.code if prev is not None and prev.user_set is not None else None   # the same set, loaded before
        if code is None:
            code = max([c for c in BY_CODE if c >= USER_CODE_BASE], default=USER_CODE_BASE - 1) + 1
        register(EffectSpec.from_meta(entry, code=code, source=str(s.directory), user_set=s))


def _discover(name: str) -> None:
    """Register the set in the user directory that declares effect `name`, if there is one."""
    d = user_sets.find(name, "effects")
    if d is not None:
        register_set(user_sets.open_set(d))


def make(name: str, body: str | None = None, **params) -> Effect:
    """Build an effect by name (a built-in, a loaded user effect, or one found in the user directory —
    see lavendersim.extending); unknown names raise naming the known ones.

    Parameters
    ----------
    name : str
        Effect name.
    body : str or None, optional
        The body it acts on (None: every body).
    **params
        Its parameters by name.

    Returns
    -------
    Effect
    """
    if isinstance(name, str) and name not in EFFECTS and re.match(r"^[a-z][a-z0-9_]*$", name):
        _discover(name)
    return EFFECTS[V.choice("effect", name, EFFECTS)](body=body, **params)


def check_declared(effect: Effect) -> EffectSpec:
    """The spec of a declared effect.

    Parameters
    ----------
    effect : Effect

    Returns
    -------
    EffectSpec

    Raises
    ------
    LavenderInputError
        Naming an effect that no derive declaration printed.
    """
    spec = REGISTRY.get(effect.name)
    if spec is None or spec.code != effect.code or BY_CODE.get(effect.code) is not spec or effect.spec is None:
        raise V.LavenderInputError(
            f"effect {effect.name or type(effect).__name__!r}",
            f"is not a declared effect (class {type(effect).__name__}, code {effect.code!r}): the backends evaluate only "
            "effects declared in SymPy and printed by `lavendersim derive` — declare it in one file and run "
            "`lavendersim derive --user FILE` (docs/extending.md)")
    return spec


def spec_for_code(code: int) -> EffectSpec:
    """The spec of a declared force effect by its code.

    Parameters
    ----------
    code : int

    Returns
    -------
    EffectSpec

    Raises
    ------
    LavenderInputError
        If no declared force effect has that code.
    """
    spec = BY_CODE.get(int(code))
    if spec is None or spec.kind != "force":
        known = ", ".join(f"{c} {s.name}" for c, s in sorted(BY_CODE.items()) if s.kind == "force")
        raise V.LavenderInputError("effects", f"code {code!r} is not a declared force effect (known: {known})")
    return spec


def net_load(effects, body) -> tuple[np.ndarray, np.ndarray]:
    """Sum of the force effects `effects` on `body` at its initial state: (F_w, tau_w), world frame,
    evaluated with the generated NumPy kernels (overflow gives inf/nan, no warning).

    Parameters
    ----------
    effects : iterable of Effect
        Force effects.
    body : Body

    Returns
    -------
    F_w, tau_w : ndarray, shape (3,)
        N and N·m, world frame, about the COM.
    """
    from .generated.layout import STATE_V_W

    x = body.x0[None]
    F, tau = np.zeros(3), np.zeros(3)   # a report (load_overflow's norms), not a stepped sum: no effect reads +0
    with np.errstate(all="ignore"):
        for e in effects:
            f, t = numpy_apply(e.code)(e.params_flat()[None], x, x[:, STATE_V_W], np.array([body.mass]), body.I_b[None])
            if f is not None:
                F = F + np.asarray(f, dtype=np.float64).reshape(3)
            if t is not None:
                tau = tau + np.asarray(t, dtype=np.float64).reshape(3)
    return F, tau


# The largest net force, torque or acceleration (SI units) a scene may declare: far beyond any physics,
# and far enough below the float64 limit (1.8e308) that the integrators' stage sums and products with
# dt cannot overflow from the loads themselves.
MAX_LOAD = 1e300


def load_overflow(effects, body) -> str | None:
    """Why the force effects `effects` on `body` are too large at its initial state (net force or
    torque, or the accelerations |F|/m, |tau|/min(I_b), not finite or above MAX_LOAD), or None.

    Parameters
    ----------
    effects : iterable of Effect
    body : Body

    Returns
    -------
    str or None
    """
    F, tau = net_load(effects, body)
    with np.errstate(all="ignore"):
        checks = (("net force", V.safe_norm(F) if np.all(np.isfinite(F)) else np.inf, "N"),
                  ("net torque", V.safe_norm(tau) if np.all(np.isfinite(tau)) else np.inf, "N·m"),
                  ("linear acceleration |F|/m", V.safe_norm(F) / body.mass if np.all(np.isfinite(F)) else np.inf, "m/s²"),
                  ("angular acceleration |tau|/min(I_b)", V.safe_norm(tau) / float(np.min(body.I_b))
                   if np.all(np.isfinite(tau)) else np.inf, "rad/s²"))
    for what, value, unit in checks:
        if not value <= MAX_LOAD:
            got = "overflows a float64" if not np.isfinite(value) else f"= {value:.3g} {unit}"
            return f"the {what} on body {body.name!r} at its initial state {got}; the bound is {MAX_LOAD:g} {unit}"
    return None


def largest_param(effect: Effect) -> str:
    """The field name (effect.param) of the effect's parameter with the largest magnitude.

    Parameters
    ----------
    effect : Effect

    Returns
    -------
    str
    """
    if not effect.fields:
        return effect.name
    mags = [float(np.max(np.abs(np.atleast_1d(effect.values[f])), initial=0.0)) for f in effect.fields]
    return f"{effect.name}.{effect.fields[int(np.argmax(mags))]}"


def numpy_apply(code: int):
    """The NumPy function of effect `code`: apply(p, x, v_w, m, I_b) -> (F_w or None, tau_w or None).

    Parameters
    ----------
    code : int

    Returns
    -------
    callable
        Batched over a leading axis: p (n, n_params), x (n, 13), v_w (n, 3), m (n,), I_b (n, 3).
    """
    spec = spec_for_code(code)
    if spec.user_set is None:
        from .generated.kernels_numpy import EFFECT_APPLY
        return EFFECT_APPLY[spec.name]
    return spec.user_set.numpy.EFFECT_APPLY[spec.name]


def velocity_dependent(codes) -> bool:
    """Whether any of these effect codes reads v_w or omega_b.

    Parameters
    ----------
    codes : iterable of int

    Returns
    -------
    bool
    """
    return any(spec_for_code(int(c)).velocity_dependent for c in codes)


def load_user(path) -> list[str]:
    """Load the user effects derived from a declaration file or found in a derived directory (see
    lavendersim.extending.load); returns their names. Effects in the user directory are also found on
    first use by name, so calling this is needed only for a set kept elsewhere.

    Parameters
    ----------
    path : str or os.PathLike
        A declaration file or a directory ``lavendersim derive --user`` wrote.

    Returns
    -------
    list of str
    """
    s = user_sets.open_set(user_sets.directory_of(path))
    register_set(s)
    return s.effect_names


def _casadi_kernel(spec: EffectSpec):
    from ._install import require

    require("casadi", "control", "the CasADi expression of an effect")
    assert spec.kernel is not None, spec.name   # a force effect (_force_spec) always has its kernel
    if spec.user_set is None:
        from .generated import kernels_casadi as KC
        return getattr(KC, spec.kernel)
    return getattr(spec.user_set.casadi, spec.kernel)


def casadi_expr(name: str, **inputs):
    """The CasADi expression of effect `name` (built-in or user): (F_w, tau_w), each a 3×1 casadi column
    (zeros for an output the effect does not have), world frame, about the COM.

    Parameters
    ----------
    name : str
        The effect's name.
    **inputs
        The state values it reads (any of p_w, q, v_w, omega_b, m, I_b, as in ``EFFECTS[name].spec.state_inputs``)
        and its parameters by name: numbers, numpy arrays or casadi SX/MX/DM. Missing ones raise.

    Returns
    -------
    F_w, tau_w : casadi column, 3×1
    """
    import casadi

    spec = _force_spec(name)
    want = list(spec.state_inputs) + [p.name for p in spec.params]
    missing = [w for w in want if w not in inputs]
    extra = sorted(set(inputs) - set(want))
    if missing or extra:
        raise V.LavenderInputError(f"casadi_expr({name})", f"takes exactly {', '.join(want)}",
                                   f"; missing {missing}" * bool(missing) + f"; unknown {extra}" * bool(extra))
    args = [casadi.DM(np.asarray(inputs[w], dtype=np.float64)) if isinstance(inputs[w], (int, float, list, tuple, np.ndarray))
            else inputs[w] for w in want]
    out = _casadi_kernel(spec)(*args)
    out = out if isinstance(out, tuple) else (out,)
    got = dict(zip(spec.outputs, out))
    zero = casadi.DM.zeros(3, 1)
    return got.get("F_w", zero), got.get("tau_w", zero)


def casadi_function(name: str):
    """A casadi.Function of effect `name`: inputs the state values it reads and its parameters (named as
    in the declaration), outputs F_w and tau_w (world frame, N and N·m).

    Parameters
    ----------
    name : str
        A force effect's name.

    Returns
    -------
    casadi.Function
    """
    import casadi

    spec = _force_spec(name)
    sizes = {"p_w": 3, "q": 4, "v_w": 3, "omega_b": 3, "m": 1, "I_b": 3}
    syms = {s: casadi.SX.sym(s, sizes[s]) for s in spec.state_inputs}
    syms.update({p.name: casadi.SX.sym(p.name, p.size) for p in spec.params})
    F, tau = casadi_expr(name, **syms)
    return casadi.Function(f"effect_{name}", list(syms.values()), [F, tau], list(syms), ["F_w", "tau_w"])


def _force_spec(name: str) -> EffectSpec:
    if isinstance(name, str) and name not in REGISTRY:
        _discover(name)
    if isinstance(name, str) and name in REGISTRY and REGISTRY[name].kind != "force":
        raise V.LavenderInputError("effect", f"{name!r} is a model effect: it has no force or torque expression")
    return REGISTRY[V.choice("effect", name, [n for n, s in REGISTRY.items() if s.kind == "force"])]


# ---------------------------------------------------------------------------------------------
# Listing: what effects there are and what they take
# ---------------------------------------------------------------------------------------------


def _spec_named(name: str) -> EffectSpec:
    """The spec of a registered effect (a user one in the user directory is loaded on first use, as in make)."""
    if isinstance(name, str) and name not in REGISTRY and re.match(r"^[a-z][a-z0-9_]*$", name):
        _discover(name)
    return REGISTRY[V.choice("effect", name, REGISTRY)]


def _decay_text(spec: EffectSpec) -> str | None:
    """The first sentence of a decay effect's printed rate function (what the rate is, its unit)."""
    if spec.decay_rate is None:
        return None
    doc = " ".join((getattr(spec.decay_rate, "__doc__", None) or "").split())
    head = doc.split(": ", 1)[-1].split(" (p:")[0].split(". ")[0].rstrip(".")
    return head or "a linear decay"


def list_effects(name: str | None = None) -> list[dict]:
    """The registered effects (built-in and the loaded user sets') and their parameters, as plain values.

    Parameters
    ----------
    name : str, optional
        Only this effect (a user effect in the user directory is loaded on first use, as by ``make``).

    Returns
    -------
    list of dict
        One dict per effect, in registration order: ``name``, ``kind`` ("force" or "model"), ``summary``,
        ``source`` ("built-in" or the user set's directory), ``code``, ``reads`` (state it reads, e.g.
        ``["q", "omega_b"]``), ``outputs`` (``"F_w"``, ``"tau_w"``), ``decay`` (bool), ``decay_rate``
        (what the rate of a pure linear decay is, 1/s, else None), ``per_body`` (bool) and ``params``: a list
        of dicts ``name``, ``shape`` (list; with ``upto`` the first length is a maximum), ``shape_text``
        (e.g. ``"(1 … 4, 3)"``), ``unit`` (SI, "" for dimensionless), ``rule`` ("finite", "positive",
        "nonnegative"), ``default`` (None: required), ``required``, ``frame`` ("body", "world" or None),
        ``doc``. JSON-ready.

    Raises
    ------
    LavenderInputError
        ``name`` is not a registered effect (the message lists the known ones).
    """
    specs = [_spec_named(name)] if name is not None else list(REGISTRY.values())
    out = []
    for s in specs:
        params = [{"name": p.name, "shape": list(p.shape), "shape_text": p.text() if p.shape else "()",
                   "upto": p.upto, "unit": p.unit, "rule": p.rule,
                   "default": np.asarray(p.default, float).tolist() if p.default is not None else None,
                   "required": p.default is None, "frame": p.frame, "doc": p.doc} for p in s.params]
        out.append({"name": s.name, "kind": s.kind, "summary": s.summary, "source": s.source, "code": s.code,
                    "reads": list(s.state_inputs), "outputs": list(s.outputs), "decay": s.is_decay,
                    "decay_rate": _decay_text(s), "per_body": s.kind == "model", "params": params})
    return out


def _describe_one(e: dict) -> list[str]:
    where = "built-in" if e["source"] == "built-in" else f"user set {e['source']}"
    reads = ", ".join(e["reads"]) or "nothing of the state"
    body = "body= required, one per body" if e["per_body"] else "body= one body or None (every body)"
    lines = [f"{e['name']} ({e['kind']}, {where}): {e['summary']}.",
             f"  reads {reads}; {body}" + (f"; adds {', '.join(e['outputs'])}" if e["outputs"] else "")]
    if e["decay"]:
        lines.append(f"  a pure linear decay, rate (1/s): {e['decay_rate']} (an explicit step is stable while "
                     "rate·dt stays below the integrator's REAL_AXIS_STABILITY)")
    for p in e["params"]:
        dflt = "required" if p["required"] else f"default {p['default']}"
        frame = f", {p['frame']} frame" if p["frame"] else ""
        lines.append(f"  {p['name']:<13} {p['shape_text']:<11} {p['unit'] or 'dimensionless':<13} {p['rule']:<11} "
                     f"{dflt}{frame} — {p['doc']}")
    return lines


def describe(name: str | None = None) -> str:
    """The registered effects (built-in and the loaded user sets') and their parameters, as text.

    Each effect: its name, kind, where it is declared, summary, what state it reads, whether it is a pure
    linear decay (and its rate); each parameter: shape, SI unit, validation rule, default (or "required"),
    frame and meaning. ``lavendersim effects [NAME] [--json]`` prints the same (with the user directory's
    sets loaded).

    Parameters
    ----------
    name : str, optional
        Only this effect (a user effect in the user directory is loaded on first use).

    Returns
    -------
    str
        Several lines per effect.

    Raises
    ------
    LavenderInputError
        ``name`` is not a registered effect.

    See Also
    --------
    list_effects : the same as plain values.
    """
    return "\n".join(line for e in list_effects(name) for line in _describe_one(e)) + "\n"
