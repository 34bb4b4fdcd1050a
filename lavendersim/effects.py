"""Scene effects: what a scene declares is all the simulator evaluates.

Each force effect acts on one named body or, with body=None, on every body. Codes and parameter
rows are the contract with the backends: a row is [code, body index (-1: all), p0 … p5].
Frames and units: torque_w N·m (world), r_b m (body frame offset from the COM), F_w N (world),
g_w m/s² (world), linear damping c N·s/m, angular damping c N·m·s/rad.

Two effects change a body's model instead of adding a force (`per_body = True`; body= required,
at most one of each per body): `spherical_joint` (anchor_w, m, world) pins the body point that
coincides with anchor_w at the start to that world point; `reaction_wheels` (J kg·m² about body
x, y, z; torque_limit N·m; speed_limit rad/s on |Omega_i|; c_w N·m·s/rad bearing damping) adds
three wheels on the body axes. The Sim turns them into per-body model rows (see
lavendersim.backends.MODEL_LAYOUT); they never appear in the force-effect table.
"""
from __future__ import annotations

import numpy as np

from . import validate as V

ROW = 8


class Effect:
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


class SphericalJoint(Effect):
    """World-anchored ball joint: the body point at anchor_w (m, world) when the Sim starts stays there."""
    name, code, fields, per_body = "spherical_joint", 6, ("anchor_w",), True


class ReactionWheels(Effect):
    """Three reaction wheels on the body x, y, z axes; the body's mass and inertia include them (locked).

    J (3,) spin inertias, kg·m², each > 0 and below the body's principal moment about that axis;
    torque_limit N·m (> 0) clips each motor command; speed_limit rad/s (> 0): a wheel with
    |Omega_i| >= speed_limit is not driven further (u_i·Omega_i > 0 → u_i = 0); c_w N·m·s/rad (>= 0)."""
    name, code, fields, per_body = "reaction_wheels", 7, ("J", "torque_limit", "speed_limit", "c_w"), True
    defaults = {"c_w": 0.0}

    def _check(self, f, v):
        field = f"{self.name}.{f}"
        if f == "J":
            J = V.vector(field, v)
            if not np.all(J > 0):
                raise V.LavenderInputError(field, "each wheel inertia must be > 0", f", got {J.tolist()}")
            return J
        if f == "c_w":
            return V.scalar(field, v, nonnegative=True)
        return V.scalar(field, v, positive=True)

    def check_body(self, I_b: np.ndarray) -> None:
        """J_i < I_b[i]: the body with its wheels free must keep a positive inertia about each axis."""
        J = self.values["J"]
        bad = np.flatnonzero(J >= I_b)
        if bad.size:
            i = int(bad[0])
            raise V.LavenderInputError(f"{self.name}.J", f"J[{i}] must be below the body's principal moment "
                                       f"I_b[{i}] = {I_b[i]:g} kg·m² (the body's inertia includes its wheels)",
                                       f", got {J[i]:g}")


EFFECTS = {cls.name: cls for cls in (AppliedTorque, ForceAtPoint, Gravity, LinearDamping, AngularDamping,
                                     SphericalJoint, ReactionWheels)}


def make(name: str, body: str | None = None, **params) -> Effect:
    """Build an effect by name; unknown names raise naming the known ones."""
    return EFFECTS[V.choice("effect", name, EFFECTS)](body=body, **params)
