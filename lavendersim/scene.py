"""A scene: bodies plus the effects it declares, and nothing else."""
from __future__ import annotations

from types import MappingProxyType

import numpy as np

from . import validate as V
from .bodies import Body
from .effects import Effect, check_declared, largest_param, load_overflow, make, row_width


def _declared(effect: Effect) -> bool:
    try:
        check_declared(effect)
    except V.LavenderInputError:
        return False
    return True


class Scene:
    """Bodies (by name, in the order added) and the effects declared on them.

    Every add is validated before anything is stored: a rejected call leaves the scene as it was.
    Force effects whose parameters would overflow — alone or summed with the other effects on a body,
    as force, torque or acceleration at the body's initial state — are rejected when added."""

    @V.keywords
    def __init__(self):
        self._bodies: dict[str, Body] = {}
        self.effects: list[Effect] = []

    @property
    def bodies(self) -> MappingProxyType:
        """The bodies by name, in the order added: a read-only view (add with add_body, which validates)."""
        return MappingProxyType(self._bodies)

    @V.keywords
    def add_body(self, body: Body) -> Body:
        """Add a (validated, immutable) Body; its name must be new in this scene."""
        if not isinstance(body, Body):
            raise V.LavenderInputError("body", "must be a lavendersim.Body", f", got {type(body).__name__}")
        if body.name in self.bodies:
            raise V.LavenderInputError("body.name", f"duplicate name {body.name!r}")
        every = [e for e in self.effects if not e.per_body and e.body is None and _declared(e)]
        why = load_overflow(every, body) if every else None
        if why:
            raise V.LavenderInputError("body", f"{why} with the scene's effects on every body "
                                       f"({', '.join(e.name for e in every)})")
        self._bodies[body.name] = body
        return body

    def add_effect(self, effect: Effect | str, body: str | None = None, **params) -> Effect:
        """Declare an effect: an Effect instance, or its name plus parameters."""
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
            if any(e.name == effect.name and e.body == effect.body for e in self.effects):
                raise V.LavenderInputError(f"{effect.name}.body", f"body {effect.body!r} already has a {effect.name}; "
                                           "at most one per body")
            if hasattr(effect, "check_body"):
                effect.check_body(self.bodies[effect.body])
        elif _declared(effect):  # an undeclared effect is refused by Sim (naming how to declare it)
            targets = list(self.bodies.values()) if effect.body is None else [self.bodies[effect.body]]
            for b in targets:
                mine = [e for e in self.effects if not e.per_body and e.body in (None, b.name) and _declared(e)]
                why = load_overflow([effect], b) or load_overflow(mine + [effect], b)
                if why:
                    raise V.LavenderInputError(largest_param(effect), f"too large: {why}"
                                               + (f" (with {', '.join(e.name for e in mine)})" if mine else ""))
        self.effects.append(effect)
        return effect

    def index(self, name: str) -> int:
        if name not in self.bodies:
            raise V.LavenderInputError("body", f"unknown body {name!r}; bodies: {', '.join(self.bodies) or 'none'}")
        return list(self.bodies).index(name)

    def model_effects(self, name: str) -> dict:
        """The per-body (model) effects declared on body `name`: {"spherical_joint": e, "reaction_wheels": e}."""
        return {e.name: e for e in self.effects if e.per_body and e.body == name}

    def arrays(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(state (nb, 13), params (nb, 4) = [m, I_x, I_y, I_z], effects (ne, width)) for the backends.
        The effect table holds only force effects, one row each ([code, body, parameters …], see
        lavendersim.effects; width = the widest, at least effects.ROW); joints and wheels are
        per-body model rows that the Sim builds (they need the initial state)."""
        if not self.bodies:
            raise V.LavenderInputError("scene.bodies", "a scene needs at least one body")
        bodies = list(self.bodies.values())
        state = np.ascontiguousarray(np.stack([b.x0 for b in bodies]))
        params = np.ascontiguousarray(np.stack([b.params for b in bodies]))
        forces = [e for e in self.effects if not e.per_body]
        width = row_width(forces)
        rows = [e.row(-1 if e.body is None else self.index(e.body), width) for e in forces]
        effects = np.ascontiguousarray(np.array(rows, dtype=np.float64).reshape(len(rows), width))
        return state, params, effects
