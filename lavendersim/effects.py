"""Scene effects: what a scene declares is all the simulator evaluates.

Each effect acts on one named body or, with body=None, on every body. Codes and parameter rows
are the contract with the backends: a row is [code, body index (-1: all), p0 … p5].
Frames and units: torque_w N·m (world), r_b m (body frame offset from the COM), F_w N (world),
g_w m/s² (world), linear damping c N·s/m, angular damping c N·m·s/rad.
"""
from __future__ import annotations

import numpy as np

from . import validate as V

ROW = 8


class Effect:
    name = ""
    code = 0
    fields: tuple[str, ...] = ()
    defaults: dict = {}

    def __init__(self, body: str | None = None, **params):
        params = {**self.defaults, **params}
        if body is not None and (not isinstance(body, str) or not body):
            raise V.LavenderInputError(f"{self.name}.body", "must be a body name or None (every body)", f", got {body!r}")
        unknown = sorted(set(params) - set(self.fields))
        if unknown:
            raise V.LavenderInputError(f"{self.name}.{unknown[0]}", f"unknown parameter; known: {', '.join(self.fields)}")
        missing = [f for f in self.fields if f not in params]
        if missing:
            raise V.LavenderInputError(f"{self.name}.{missing[0]}", "is required")
        self.body = body
        self.values = {f: self._check(f, params[f]) for f in self.fields}

    def _check(self, f, v):
        return V.vector(f"{self.name}.{f}", v)

    def row(self, body_index: int) -> np.ndarray:
        r = np.zeros(ROW)
        r[0], r[1] = self.code, body_index
        flat = np.concatenate([np.atleast_1d(self.values[f]) for f in self.fields])
        r[2:2 + flat.size] = flat
        return r

    def describe(self) -> str:
        vals = ", ".join(f"{f}={np.array2string(np.atleast_1d(self.values[f]), precision=4)}" for f in self.fields)
        return f"{self.name}({vals})"

    def __repr__(self):
        return f"{type(self).__name__}(body={self.body!r}, {self.describe()})"


class AppliedTorque(Effect):
    name, code, fields = "applied_torque", 1, ("torque_w",)


class ForceAtPoint(Effect):
    name, code, fields = "force_at_point", 2, ("r_b", "F_w")


class Gravity(Effect):
    name, code, fields = "gravity", 3, ("g_w",)
    defaults = {"g_w": (0.0, 0.0, -9.81)}


class _Damping(Effect):
    fields = ("c",)

    def _check(self, f, v):
        return V.scalar(f"{self.name}.{f}", v, nonnegative=True)


class LinearDamping(_Damping):
    name, code = "linear_damping", 4


class AngularDamping(_Damping):
    name, code = "angular_damping", 5


EFFECTS = {cls.name: cls for cls in (AppliedTorque, ForceAtPoint, Gravity, LinearDamping, AngularDamping)}


def make(name: str, body: str | None = None, **params) -> Effect:
    """Build an effect by name; unknown names raise naming the known ones."""
    return EFFECTS[V.choice("effect", name, EFFECTS)](body=body, **params)
