"""What the viewer draws for a body: its declared shape, or the box with its mass and moments, and its size.
Used by the viewer and by playback's default overlays (neither imports the other for it)."""
from __future__ import annotations

import numpy as np

from .kernels import K


def shape_of(body) -> tuple:
    """(kind, dims) to draw: the body's shape, or the box with its mass and moments, along the body axes
    (for a full inertia tensor: the box of its diagonal in the body frame, an approximation drawn in the
    user's axes)."""
    shape = getattr(body, "shape", None)
    if shape and shape[0] in ("box", "cylinder", "sphere"):
        return shape[0], tuple(float(x) for x in shape[1])
    I = body.I_b if getattr(body, "principal", True) else np.diag(body.inertia_b)
    return "box", tuple(float(a) for a in K.box_of_inertia(float(body.mass), I))   # the printed kernel (derive/measures.py)


def extent(kind: str, dims: tuple) -> float:
    """The largest size, m, of a drawn shape (kind, dims) as shape_of gives it: box edges, sphere radius (the
    diameter), cylinder (radius, length)."""
    return max(dims) if kind == "box" else (2 * max(dims) if kind == "sphere" else max(2 * dims[0], dims[1]))
