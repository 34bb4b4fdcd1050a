"""Kernel descriptions: a named set of SymPy output expressions over named, shaped inputs.

Every equation LavenderSim uses is written once as a `Kernel`; `derive.codegen` prints it as C99,
NumPy (vectorized over a leading batch axis) and CasADi. Inputs and outputs carry their shape and a
description that states frame and unit. Vectors are flattened row-major; quaternions are
(x, y, z, w), scalar last.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import sympy as sp


def vec(name: str, n: int) -> sp.Matrix:
    """Column of n real symbols name_0 … name_{n-1}."""
    return sp.Matrix([sp.Symbol(f"{name}_{i}", real=True) for i in range(n)])


def mat(name: str, rows: int, cols: int) -> sp.Matrix:
    """rows×cols matrix of real symbols name_{r}{c}, flattened row-major in generated code."""
    return sp.Matrix(rows, cols, lambda r, c: sp.Symbol(f"{name}_{r}{c}", real=True))


def scalar(name: str, positive: bool = False) -> sp.Symbol:
    return sp.Symbol(name, real=True, positive=positive or None)


def _shape(value) -> tuple[int, ...]:
    if isinstance(value, sp.MatrixBase):
        return (value.rows,) if value.cols == 1 else (value.rows, value.cols)
    return ()


def _flat(value) -> list:
    if isinstance(value, sp.MatrixBase):
        return [value[r, c] for r in range(value.rows) for c in range(value.cols)]
    return [value]


# Domains tell tests (and readers) which inputs are meaningful: random sampling draws from them.
# inertia_sym: a symmetric 3×3 inertia, diagonally dominant and larger than any "positive" draw
# (so that I − J stays positive definite for wheel inertias J).
DOMAINS = ("real", "positive", "unit_quaternion", "unit_vector", "spd_diag", "small", "inertia_sym")


@dataclass
class Arg:
    name: str
    value: object  # sp.Symbol or sp.Matrix of symbols (inputs) / expressions (outputs)
    doc: str
    domain: str = "real"

    def __post_init__(self):
        if self.domain not in DOMAINS:
            raise ValueError(f"domain: unknown {self.domain!r}")

    @property
    def shape(self) -> tuple[int, ...]:
        return _shape(self.value)

    @property
    def size(self) -> int:
        n = 1
        for s in self.shape:
            n *= s
        return n

    @property
    def flat(self) -> list:
        return _flat(self.value)


@dataclass
class Kernel:
    """A kernel: summary, an optional human caption (`latex`, shown beside the equation; EQUATIONS.md
    prints the equation itself from the outputs with sympy.latex), inputs, outputs, group, notes.

    where: named subexpressions [(symbol, expression)], evaluated in order before the outputs, which
    may use their symbols (an expression may use earlier ones). The printers compute each once, as
    written, and keep it as one rounded number: SymPy would otherwise flatten a product such as
    c·ω_y·ω_z with c = (I_y − I_z)/I_x into ω_y ω_z (I_y − I_z)/I_x, a division per call, where the
    grouped form lets a caller hoist c out of its loop (see derive/rigid_body.py). `output_exprs` has
    them substituted (the mathematics); `printed_exprs` keeps them (what the code computes)."""

    name: str
    summary: str
    latex: str
    inputs: list[Arg]
    outputs: list[Arg]
    group: str = ""
    notes: list[str] = field(default_factory=list)
    where: list[tuple[sp.Symbol, sp.Expr]] = field(default_factory=list)

    def __post_init__(self):
        names = {s for s in self.input_symbols}
        for s, _ in self.where:
            if not isinstance(s, sp.Symbol) or s in names:
                raise ValueError(f"kernel {self.name}: where-symbol {s!r} is not a fresh symbol")
            names.add(s)

    @property
    def input_symbols(self) -> list[sp.Symbol]:
        return [s for a in self.inputs for s in a.flat]

    @property
    def printed_exprs(self) -> list[sp.Expr]:
        """The outputs as the code computes them: where-symbols kept as names."""
        return [sp.sympify(e) for a in self.outputs for e in a.flat]

    @property
    def output_exprs(self) -> list[sp.Expr]:
        """The outputs over the inputs only (where-symbols substituted, last first)."""
        exprs = self.printed_exprs
        for s, e in reversed(self.where):
            exprs = [x.xreplace({s: e}) for x in exprs]
        return exprs
