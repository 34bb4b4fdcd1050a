"""What the viewer draws for a body: its declared shape, or the box with its mass and moments, and its size.
Used by the viewer and by playback's default overlays (neither imports the other for it)."""
from __future__ import annotations

import math

import numpy as np


def shape_of(body) -> tuple:
    """(kind, dims) to draw: the body's shape, or the box with its mass and moments, along the body axes
    (for a full inertia tensor: the box of its diagonal in the body frame, an approximation drawn in the
    user's axes)."""
    shape = getattr(body, "shape", None)
    if shape and shape[0] in ("box", "cylinder", "sphere"):
        return shape[0], tuple(float(x) for x in shape[1])
    m = float(body.mass)
    I = np.asarray(body.I_b if getattr(body, "principal", True) else np.diag(body.inertia_b), dtype=float)
    sq = [max(6.0 * (I[(k + 1) % 3] + I[(k + 2) % 3] - I[k]) / m, 1e-6) for k in range(3)]
    return "box", tuple(math.sqrt(s) for s in sq)


def extent(kind: str, dims: tuple) -> float:
    """The largest size, m, of a drawn shape (kind, dims) as shape_of gives it: box edges, sphere radius (the
    diameter), cylinder (radius, length)."""
    return max(dims) if kind == "box" else (2 * max(dims) if kind == "sphere" else max(2 * dims[0], dims[1]))
