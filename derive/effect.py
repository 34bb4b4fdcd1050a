"""Effect declarations: one per effect, the unit from which every printing of it is made.

An effect contributes a force at the centre of mass and/or a torque about it, both in the world
frame, written in SymPy over

* the body's state and model, the symbols of :data:`STATE` — ``p_w`` (3, m, world), ``q`` (4,
  orientation R_WB as (x, y, z, w)), ``v_w`` (3, m/s, world; for a body on a spherical joint the
  kinematic COM velocity), ``omega_b`` (3, rad/s, body frame), ``m`` (kg), ``I_b`` (3, principal
  moments about the COM, kg·m²) — plus the helpers ``STATE.R_WB`` and ``STATE.omega_w``;
* the effect's own named parameters (:func:`param`): a shape (scalar or a vector), a unit, a
  description, a validation rule (``"finite"``, ``"nonnegative"`` or ``"positive"``, applied to
  every entry) and an optional default.

``lavendersim derive`` prints, from a declaration: the C kernel ``lv_effect_<name>``, its entry in
the generated C dispatch ``lv_effect_apply``, the NumPy kernel and dispatch, the CasADi
expression, the Python metadata (code, parameter layout, rules, and whether the effect reads v or
ω — from the free symbols of its expressions) and its EQUATIONS.md entry. Model effects (a joint,
wheels) declare only their parameters: their equations are kernels of their own.

A user declares effects the same way in one file outside the package (see docs/extending.md)::

    from lavendersim.derive.effect import STATE, effect, param
    c = param("c", unit="N·m·s/rad", doc="drag coefficient", rule="nonnegative")
    EFFECTS = [effect("spin_drag", "Viscous spin drag", params=[c], torque_w=-c.symbol * STATE.omega_w)]
"""
from __future__ import annotations

import keyword
import re
import dataclasses
from dataclasses import dataclass, field

import sympy as sp

from .kernel import Arg, Kernel, mat, scalar, vec
from .layout import PARAM as LAYOUT_PARAM
from .layout import STATE as LAYOUT_STATE
from .quaternion import Rotation

RULES = ("finite", "nonnegative", "positive")
KINDS = ("force", "model")
# Effect table row: [code, body (index, or -1 for every body), parameters...]; a row holds at least
# ROW_MIN_PARAMS parameters (wider when a declared effect needs more).
ROW_CODE, ROW_BODY, ROW_PARAMS = 0, 1, 2
ROW_MIN_PARAMS = 6
# Codes of effects loaded from user declarations start here (assigned in load order at run time).
USER_CODE_BASE = 1000
# Bits of an effect's flags (C and Python): which state values its force or torque reads.
FLAG_USES_V = 1       # reads v_w (a jointed body then needs its kinematic COM velocity)
FLAG_USES_OMEGA = 2   # reads omega_b
FLAG_FORCE = 4        # adds a force (a body whose effects add none may use the torque-only right-hand side)
FLAG_USES_STATE = 8   # reads a state value p_w, q, v_w or omega_b (without it the force and torque are constant
                      # over a step, the mass and inertia being constants: the SIMD batch evaluates them once per
                      # call, csrc/batch_simd.h)
FLAG_TORQUE_W = 16    # declares a torque in the world frame (torque_w)
FLAG_TORQUE_B = 32    # declares its torque in the body frame only (torque_b, no torque_w): a plain body whose torques
                      # are all body-frame adds them as such (the body dispatch, *_b) and its right-hand side rotates
                      # nothing (rigid_body_rhs_body_c); elsewhere the effect adds R_WB tau_b as a world torque
FLAG_COUPLED = 64     # couples translation and rotation: its force reads p_w, q or omega_b, or is not F0 - k v_w (F0, k
                      # constant, k one scalar rate), or its torque reads p_w or v_w (affine_force). A plain body none of
                      # whose effects carries it steps its translation by the printed affine flow of RK4 and stages
                      # only (q, omega_b) (derive/rigid_body.py translation_flow*)
# Version of the calling convention of printed effect functions (checked when a user library loads).
ABI_VERSION = 1
# Lanes per row of the C SIMD tiles (csrc/batch_simd.h): the row stride of the tile form of an effect, which
# user libraries export as lvu_effect_tile<TILE_LANES>_<name>_<isa> (an older library without it: no tiles).
TILE_LANES = 64
_NAME = re.compile(r"^[a-z][a-z0-9_]*$")
_PARAM_NAME = re.compile(r"^[A-Za-z][A-Za-z0-9_]*$")


class _State:
    """Symbols of the body state and model that an effect may use (see the module docstring)."""

    FIELDS = tuple(f.name for f in LAYOUT_STATE.fields) + tuple(f.name for f in LAYOUT_PARAM.fields)
    DOCS = {"p_w": ("COM position, world frame, m", "real"),
            "q": ("orientation (x, y, z, w), R_WB, unit", "unit_quaternion"),
            "v_w": ("COM velocity, world frame, m/s", "real"),
            "omega_b": ("angular velocity, body frame, rad/s", "real"),
            "m": ("mass, kg", "positive"),
            "I_b": ("principal moments of inertia about the COM, body frame, kg·m²", "positive")}

    def __init__(self):
        if self.FIELDS != ("p_w", "q", "v_w", "omega_b", "m", "I_b"):
            raise RuntimeError("derive: the effect symbols follow derive/layout.py's STATE and PARAM fields")
        self.p_w, self.q, self.v_w, self.omega_b = vec("p_w", 3), vec("q", 4), vec("v_w", 3), vec("omega_b", 3)
        self.m = scalar("m", positive=True)
        self.I_b = vec("I_b", 3)
        self.R_WB = Rotation(self.q)                  # times a 3-vector: the sandwich (quaternion.Rotation)
        self.omega_w = self.R_WB * self.omega_b

    def value(self, name: str):
        return getattr(self, name)

    def symbols(self, name: str) -> list[sp.Symbol]:
        v = self.value(name)
        return list(v) if isinstance(v, sp.MatrixBase) else [v]


STATE = _State()


@dataclass
class Param:
    """A named effect parameter: shape () or (n,) (or (n, k), model effects), unit, description, rule,
    optional default; upto: the leading length n is a maximum (a value has 1 … n entries or rows: model
    effects only, e.g. one per reaction wheel)."""

    name: str
    shape: tuple[int, ...] = ()
    unit: str = ""
    doc: str = ""
    rule: str = "finite"
    default: object = None
    upto: bool = False

    def __post_init__(self):
        if isinstance(self.shape, int):
            self.shape = (self.shape,)
        self.shape = tuple(int(s) for s in self.shape)
        if not _PARAM_NAME.match(self.name):
            raise ValueError(f"param {self.name!r}: a name is letters, digits and _, starting with a letter")
        if keyword.iskeyword(self.name) or self.name in _State.FIELDS or self.name in _RESERVED:
            raise ValueError(f"param {self.name!r}: the name is reserved (state symbols: {', '.join(_State.FIELDS)})")
        if len(self.shape) > 2 or any(n < 1 for n in self.shape):
            raise ValueError(f"param {self.name!r}: shape must be (), (n,) or (n, k), got {self.shape}")
        if self.upto and not self.shape:
            raise ValueError(f"param {self.name!r}: upto needs a vector or matrix shape")
        if self.rule not in RULES:
            raise ValueError(f"param {self.name!r}: rule must be one of {', '.join(RULES)}, got {self.rule!r}")
        if self.default is not None:
            self.default = self._default(self.default)
        n = self.shape
        self.symbol = scalar(self.name) if not n else vec(self.name, n[0]) if len(n) == 1 else mat(self.name, *n)

    def _default(self, value):
        """The default as floats (nested tuples for a matrix), checked against the shape."""
        if not self.shape:
            return float(value)
        rows = tuple(tuple(float(v) for v in r) for r in value) if len(self.shape) == 2 else tuple(float(v) for v in value)
        ok = (1 <= len(rows) <= self.shape[0]) if self.upto else len(rows) == self.shape[0]
        if not ok or (len(self.shape) == 2 and any(len(r) != self.shape[1] for r in rows)):
            raise ValueError(f"param {self.name!r}: default must have shape {self.shape}" + (" (up to)" if self.upto else ""))
        return rows

    @property
    def size(self) -> int:
        out = 1
        for n in self.shape:
            out *= n
        return out

    @property
    def domain(self) -> str:
        return "real" if self.rule == "finite" else "positive"

    @property
    def frame(self) -> str | None:
        """The frame a vector (or each row of a matrix) is written in, from the name's suffix (the house's
        naming rule): "body" for ``*_b``, "world" for ``*_w``, None for scalars and frame-free values. The
        runtime rotates "body" values of a body given a full inertia tensor into its principal frame."""
        if not self.shape or self.shape[-1] != 3:
            return None
        return {"_b": "body", "_w": "world"}.get(self.name[-2:])


# Output names of effect kernels, and names the printed dispatch code uses.
OUT_FORCE, OUT_TORQUE, OUT_TORQUE_B = "F_com_w", "tau_com_w", "tau_com_b"
_RESERVED = {"x", "p", "F", "tau", OUT_FORCE, OUT_TORQUE, OUT_TORQUE_B, "code", "body", "numpy", "casadi", "batch"}


def param(name: str, shape=(), unit: str = "", doc: str = "", rule: str = "finite", default=None, upto: bool = False) -> Param:
    """Declare an effect parameter; its SymPy value is ``.symbol`` (a symbol or a column of them).

    Parameters
    ----------
    name : str
        Parameter name, as the user passes it to ``scene.add_effect(..., name=value)``.
    shape : int or tuple
        ``()`` for a scalar, ``3`` or ``(3,)`` for a vector.
    unit, doc : str
        Unit and meaning (frame included), shown in EQUATIONS.md and error messages.
    rule : {"finite", "nonnegative", "positive"}
        Validation of every entry when an effect is added to a scene.
    default : float or sequence, optional
        Value used when the parameter is not given.
    upto : bool, optional
        Model effects only: the leading length of ``shape`` is a maximum (a value has 1 … n entries or
        rows, e.g. one per reaction wheel).
    """
    return Param(name, shape, unit, doc, rule, default, upto)


@dataclass
class EffectDecl:
    """One effect: its force (world, at the COM) and torque about the COM in SymPy, declared in the world frame
    (torque_w) or in the body frame (torque_b), built-in or user-declared."""

    name: str
    summary: str
    params: list[Param]
    force_w: sp.Matrix | None = None
    torque_w: sp.Matrix | None = None
    kind: str = "force"
    caption: str = ""
    notes: list[str] = field(default_factory=list)
    torque_b: sp.Matrix | None = None

    def __post_init__(self):
        if not _NAME.match(self.name) or keyword.iskeyword(self.name):
            raise ValueError(f"effect {self.name!r}: a name is lowercase letters, digits and _, starting with a letter")
        if self.kind not in KINDS:
            raise ValueError(f"effect {self.name}: kind must be one of {', '.join(KINDS)}")
        names = [p.name for p in self.params]
        if len(set(names)) != len(names):
            raise ValueError(f"effect {self.name}: duplicate parameter names {names}")
        for label in ("force_w", "torque_w", "torque_b"):
            v = getattr(self, label)
            if v is None:
                continue
            v = sp.Matrix(v)
            if v.shape != (3, 1):
                raise ValueError(f"effect {self.name}: {label} must be a 3-vector (column), got shape {v.shape}")
            setattr(self, label, v)
        if self.kind == "force":
            if self.force_w is None and self.torque_w is None and self.torque_b is None:
                raise ValueError(f"effect {self.name}: declare force_w and/or torque_w (or torque_b)")
            allowed = {s for f in _State.FIELDS for s in STATE.symbols(f)} | {s for p in self.params for s in _flat(p.symbol)}
            unknown = self.free_symbols - allowed
            if unknown:
                raise ValueError(f"effect {self.name}: uses undeclared symbols {sorted(map(str, unknown))}; "
                                 f"declare them with param() or use STATE's ({', '.join(_State.FIELDS)})")
            odd = [p.name for p in self.params if p.upto or len(p.shape) > 1]
            if odd:
                raise ValueError(f"effect {self.name}: a force effect's parameters have a fixed shape () or (n,) "
                                 f"(its row layout is printed), not {odd[0]!r}")
        elif self.force_w is not None or self.torque_w is not None or self.torque_b is not None:
            raise ValueError(f"effect {self.name}: a model effect declares parameters only")

    @property
    def torque_world(self) -> sp.Matrix | None:
        """The torque in the world frame: torque_w, plus R_WB torque_b when a body-frame torque is declared."""
        if self.torque_b is None:
            return self.torque_w
        rotated = STATE.R_WB * self.torque_b
        return rotated if self.torque_w is None else self.torque_w + rotated

    @property
    def outputs(self) -> list[tuple[str, sp.Matrix]]:
        """(kernel output name, expression) of the world-frame outputs (every backend's effect contract), the
        force first."""
        return [(n, v) for n, v in ((OUT_FORCE, self.force_w), (OUT_TORQUE, self.torque_world)) if v is not None]

    @property
    def body_outputs(self) -> list[tuple[str, sp.Matrix]] | None:
        """The outputs of the body-frame form (FLAG_TORQUE_B: the force, world, then the torque, body frame), or
        None when the effect has no such form."""
        if self.torque_b is None or self.torque_w is not None:
            return None
        return [(n, v) for n, v in ((OUT_FORCE, self.force_w), (OUT_TORQUE_B, self.torque_b)) if v is not None]

    @property
    def free_symbols(self) -> set:
        out = set()
        for _, v in self.outputs:
            out |= v.free_symbols
        return out

    @property
    def state_inputs(self) -> list[str]:
        """The state fields the expressions read, in STATE order."""
        free = self.free_symbols
        return [f for f in _State.FIELDS if free & set(STATE.symbols(f))]

    @property
    def flags(self) -> int:
        used = self.state_inputs
        varying = any(f.name in used for f in LAYOUT_STATE.fields)   # m and I_b (params) are constants
        return ((FLAG_USES_V if "v_w" in used else 0) | (FLAG_USES_OMEGA if "omega_b" in used else 0)
                | (FLAG_FORCE if self.force_w is not None else 0) | (FLAG_USES_STATE if varying else 0)
                | (FLAG_TORQUE_W if self.torque_w is not None else 0)
                | (FLAG_TORQUE_B if self.body_outputs is not None else 0)
                | (FLAG_COUPLED if self.affine_force is None else 0))

    @property
    def affine_force(self) -> tuple[sp.Matrix, sp.Expr] | None:
        """(F0, k) when the effect leaves translation and rotation decoupled: its force is F0 − k v_W with F0 (3,
        world, N) and the scalar rate k (kg/s) free of the state (p_w, q, v_w, omega_b; m, I_b and the parameters
        allowed), its torques read neither p_w nor v_w; None otherwise (FLAG_COUPLED). Decided from the declared
        expressions: the force's derivatives in p_w, q and omega_b vanish, its Jacobian in v_w is −k times the
        identity, and F0 + (−k) v_W expands to the force."""
        if self.kind != "force":
            return None
        other = set(STATE.p_w) | set(STATE.q) | set(STATE.omega_b)
        for t in (self.torque_w, self.torque_b):
            if t is not None and t.free_symbols & (set(STATE.p_w) | set(STATE.v_w)):
                return None
        if self.force_w is None:
            return sp.zeros(3, 1), sp.Integer(0)
        F = self.force_w
        if F.free_symbols & other:
            return None
        J = F.jacobian(STATE.v_w).applyfunc(sp.expand)
        k = -J[0, 0]
        state = set(STATE.v_w) | other
        if (k.free_symbols & state) or (J + k * sp.eye(3)).applyfunc(sp.expand) != sp.zeros(3, 3):
            return None
        F0 = F.subs({s: 0 for s in STATE.v_w})
        if (F0 - k * STATE.v_w - F).applyfunc(sp.expand) != sp.zeros(3, 1):
            return None
        return F0, k

    def affine_kernel(self, group: str = "Scene effects") -> Kernel | None:
        """effect_<name>_affine: the decoupled force's (F0, k) of affine_force (F = F0 − k v_W) from the mass and
        the parameters, for an effect with a force and no FLAG_COUPLED; None otherwise."""
        af = self.affine_force
        if af is None or self.force_w is None:
            return None
        ins = [Arg("m", STATE.m, *_State.DOCS["m"])]
        ins += [Arg(p.name, p.symbol, f"{p.doc}, {p.unit}" if p.unit else p.doc, p.domain) for p in self.params]
        outs = [Arg("F0_w", af[0], "the force at v_W = 0, world frame, N"),
                Arg("k", af[1], "the rate of the force in v_W (F = F0 − k v_W), kg/s")]
        return Kernel(self.kernel_name + "_affine", self.summary + " (its affine form in v_W)", self.caption, ins, outs,
                      group, ["F_W = F0_W − k v_W: a plain body whose effects all have this form (no FLAG_COUPLED) steps "
                              "its translation by translation_flow on the summed F0 and k."])

    @property
    def n_params(self) -> int:
        return sum(p.size for p in self.params)

    def offsets(self) -> dict[str, int]:
        """Offset of each parameter within the row's parameter block."""
        out, o = {}, 0
        for p in self.params:
            out[p.name] = o
            o += p.size
        return out

    @property
    def kernel_name(self) -> str:
        return f"effect_{self.name}"

    def kernel(self, group: str = "Scene effects") -> Kernel:
        """The effect as a kernel: inputs = the state fields it reads, then its parameters."""
        if self.kind != "force":
            raise ValueError(f"effect {self.name}: a model effect has no kernel")
        ins = [Arg(f, STATE.value(f), *_State.DOCS[f]) for f in self.state_inputs]
        ins += [Arg(p.name, p.symbol, f"{p.doc}, {p.unit}" if p.unit else p.doc, p.domain) for p in self.params]
        outs = [Arg(n, v, "force at the COM, world frame, N" if n == OUT_FORCE else "torque about the COM, world frame, N·m")
                for n, v in self._printed(False)]
        outs, where = constant_factors(outs, {s.name for a in ins for s in a.flat})
        return Kernel(self.kernel_name, self.summary, self.caption, ins, outs, group, list(self.notes), where)

    def _printed(self, body: bool) -> list[tuple[str, sp.Matrix]]:
        """The outputs (body: the body-frame form's) as the kernels print them: printed_form of the declared ones,
        computed once per declaration."""
        memo = self.__dict__.setdefault("_printed_memo", {})
        if body not in memo:
            outputs = self.body_outputs if body else self.outputs
            assert outputs is not None
            memo[body] = list(zip([n for n, _ in outputs], printed_form([v for _, v in outputs])))
        return memo[body]

    def body_kernel(self, group: str = "Scene effects") -> Kernel | None:
        """The body-frame form (FLAG_TORQUE_B) as kernel effect_<name>_b: the force (world) and the torque as
        declared, in the body frame; None without one."""
        outputs = self.body_outputs
        if self.kind != "force" or outputs is None:
            return None
        free = set().union(*(v.free_symbols for _, v in outputs))
        ins = [Arg(f, STATE.value(f), *_State.DOCS[f]) for f in _State.FIELDS if free & set(STATE.symbols(f))]
        ins += [Arg(p.name, p.symbol, f"{p.doc}, {p.unit}" if p.unit else p.doc, p.domain) for p in self.params]
        outs = [Arg(n, v, "force at the COM, world frame, N" if n == OUT_FORCE else "torque about the COM, body frame, N·m")
                for n, v in self._printed(True)]
        outs, where = constant_factors(outs, {s.name for a in ins for s in a.flat})
        return Kernel(self.kernel_name + "_b", self.summary + " (its body-frame form)", self.caption, ins, outs, group,
                      ["The torque as declared, in the body frame: plain bodies whose torques are all body-frame add "
                       "it so and rotate nothing; effect_" + self.name + " gives it in the world frame."], where)


def _flat(v) -> list:
    return list(v) if isinstance(v, sp.MatrixBase) else [v]


_VARYING = ("p_w", "q", "v_w", "omega_b")     # the state an integrator's stages change (m, I_b, parameters do not)


def constant_factors(outs: list, taken: set) -> tuple[list, list]:
    """outs (Arg list of a kernel) with, in each entry that reads the varying state (p_w, q, v_w, omega_b), the
    product of its factors that do not (numbers, parameters, m, I_b: 3 μ (I_z − I_y); two or more, not a number
    and one factor) named: a
    Kernel.where symbol kc<i>, computed once per call as one rounded number. A caller that inlines the kernel
    in every stage of a step (the fused RK4 tiles) then computes it once per body, not once per stage.

    Parameters
    ----------
    outs : list of Arg
        The kernel's outputs, 3×1 or scalar.
    taken : set of str
        Names already used by the kernel (its inputs): a where-symbol's name avoids them.

    Returns
    -------
    (list of Arg, list of (Symbol, Expr))
        The outputs with the products named, and the where list (empty when no entry has such a product).
    """
    varying = {x for f in _VARYING for x in STATE.symbols(f)}
    names: dict = {}
    where: list = []

    def name(product):
        if product not in names:
            i, base = len(names), "kc"
            while f"{base}{i}" in taken:
                base += "_"
            names[product] = sp.Symbol(f"{base}{i}", real=True)
            where.append((names[product], product))
        return names[product]

    def group(e):
        e = sp.sympify(e)
        if not e.is_Mul or not (e.free_symbols & varying):
            return e
        fixed = [a for a in e.args if not (a.free_symbols & varying) and a != -1]
        if len(fixed) < 2 or (len(fixed) == 2 and any(a.is_Number for a in fixed)):   # (k·μ·x prints as (k·μ)·x)
            return e
        return sp.Mul(*[a for a in e.args if a not in fixed], name(sp.Mul(*fixed)))

    new = []
    for a in outs:
        v = a.value.applyfunc(group) if isinstance(a.value, sp.MatrixBase) else group(a.value)
        new.append(dataclasses.replace(a, value=v))
    return new, where


def _ops_after_cse(exprs: list) -> int:
    """The operations a kernel of these expressions prints: count_ops over CSE's temporaries and results."""
    temps, reduced = sp.cse(exprs, symbols=sp.numbered_symbols("t"), order="canonical")
    return int(sum(sp.count_ops(e) for _, e in temps) + sum(sp.count_ops(e) for e in reduced))


def _same_function(a: sp.Expr, b: sp.Expr) -> bool:
    """Whether a and b are the same rational function of their symbols and radicals (proved: a − b over one
    denominator, expanded, is 0; False when SymPy cannot show it)."""
    try:
        return sp.expand(sp.together(a - b)) == 0
    except (TypeError, ValueError, NotImplementedError, RecursionError):
        return False


def printed_form(values: list[sp.Matrix]) -> list[sp.Matrix]:
    """The form an effect's kernels print its outputs in: each entry with the factors common to the terms of its
    sums pulled out (sp.factor_terms, e.g. r_y (I_z r_z) − r_z (I_y r_y) → r_y r_z (I_z − I_y), whose I_z − I_y
    reads per-body constants only), kept when the kernel's operation count after CSE is lower and each entry is
    proved the same function (_same_function); else the declared form. Every backend prints this one form (C
    and NumPy stay bitwise equal); it differs from the declared arithmetic at rounding level only.

    Parameters
    ----------
    values : list of sympy.Matrix
        The outputs (3×1 each: force and/or torque) of one kernel.

    Returns
    -------
    list of sympy.Matrix
        The outputs to print, entry for entry the same functions.
    """
    flat = [e for v in values for e in v]
    factored = [sp.factor_terms(e) for e in flat]
    if factored == flat or _ops_after_cse(factored) >= _ops_after_cse(flat):
        return values
    if not all(_same_function(a, b) for a, b in zip(flat, factored)):
        return values
    out, i = [], 0
    for v in values:
        out.append(sp.Matrix(v.rows, v.cols, factored[i:i + len(v)]))
        i += len(v)
    return out


def effect(name: str, summary: str, params=(), force_w=None, torque_w=None, caption: str = "",
           notes=(), torque_b=None) -> EffectDecl:
    """Declare a force effect (see the module docstring).

    Parameters
    ----------
    name : str
        The name users pass to ``scene.add_effect``; lowercase, digits and underscores.
    summary : str
        One line, shown in EQUATIONS.md and ``sim.pipeline``'s documentation.
    params : sequence of Param
        The effect's parameters, in row order.
    force_w, torque_w : sympy.Matrix (3×1), optional
        Force at the COM and torque about it, world frame (N, N·m). At least one (or torque_b).
    caption : str, optional
        A human LaTeX caption shown beside the printed equation.
    notes : sequence of str
        Extra lines for EQUATIONS.md.
    torque_b : sympy.Matrix (3×1), optional
        The torque about the COM in the body frame (N·m), instead of torque_w (built-in and user effects). Its world
        form R_WB torque_b is printed too; a plain body whose torques are all body-frame adds torque_b as it is and
        rotates nothing (FLAG_TORQUE_B).
    """
    return EffectDecl(name, summary, list(params), force_w, torque_w, "force", caption, list(notes), torque_b)


def model_effect(name: str, summary: str, params=(), notes=()) -> EffectDecl:
    """Declare a per-body model effect (parameters only; its equations are kernels of their own)."""
    return EffectDecl(name, summary, list(params), None, None, "model", "", list(notes))
