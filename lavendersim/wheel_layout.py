"""Reaction wheels on arbitrary spin axes (a wheel layout): checks, the null space, the 4-wheel pyramid.

A layout is a body-frame axis matrix ``A_b`` (3×N, unit columns; ``reaction_wheels(axes_b=A_bᵀ)``), the
wheels' axial inertias ``J`` (N, kg·m²) and one motor model. The equations — body + N wheel rates,
wheel momentum ``h_w = J (A_bᵀ ω_b + Ω)`` — are derived once in derive/wheel_layout.py and printed
(C, NumPy, CasADi); any Scene declares them with ``reaction_wheels`` and lavendersim.control designs
and flies its controller (one control stack for every layout). With more wheels than axes the null
space of ``A_b`` (``A_b n = 0``, :func:`null_space`) lets the controller move the wheel speeds without
any torque on the body (``control.design(..., null_bias=...)``). :func:`pyramid_cube` is the usual
redundant set of four wheels on a pyramid, on a free cube.
"""
from __future__ import annotations

import math
import numbers

import numpy as np
from numpy.typing import ArrayLike

from . import validate as V
from .kernels import K as KN

MOTORS = ("line", "cutoff")
UNIT_TOL = V.WHEEL_UNIT_TOL


def printed_counts() -> tuple[int, ...]:
    """The wheel counts N with printed kernels (``wheels<N>_body_rhs`` in the generated NumPy module)."""
    from .generated import kernels_numpy as KG

    return tuple(sorted(int(k[6:-9]) for k in dir(KG) if k.startswith("wheels") and k.endswith("_body_rhs")))


axes = V.wheel_axes   # the check of a wheel axis matrix lives with the other validation (effects use it too)


def null_space(A_b: ArrayLike) -> np.ndarray:
    """Orthonormal basis (N, N − rank) of the wheel torques that put no torque on the body: ``A_b n = 0``.

    Parameters
    ----------
    A_b : array_like (3, N)
        Wheel spin axes as unit columns, body frame (checked as :func:`axes`).

    Returns
    -------
    ndarray (N, N − rank)
        Orthonormal columns; (N, 0) when the axes are independent.

    Raises
    ------
    lavendersim.validate.LavenderInputError
        ``A_b`` is not a (3, N) matrix of unit columns.
    """
    A = axes("A_b", A_b)
    _, s, vt = np.linalg.svd(A)
    r = int(np.sum(s > 1e-9 * max(1.0, s.max())))
    return vt[r:].T.copy()


def pyramid_axes(elevation_deg: float | None = None) -> np.ndarray:
    """Four wheel axes on a pyramid about body z: azimuths 0°, 90°, 180°, 270°, each raised by
    ``elevation_deg`` from the x–y plane (default atan(1/√2) ≈ 35.26°: equal authority on all
    three axes, ``A_b A_bᵀ = 4/3·1``).

    Parameters
    ----------
    elevation_deg : float, optional
        Elevation of each axis above the body x–y plane, degrees (default atan(1/√2)).

    Returns
    -------
    ndarray (3, 4)
        Unit columns, body frame.
    """
    e = math.atan(1.0 / math.sqrt(2.0)) if elevation_deg is None else math.radians(V.scalar("elevation_deg", elevation_deg))
    cols = []
    for k in range(4):
        a = np.asarray(KN.axis_angle_to_quat([0.0, 0.0, 1.0], k * math.pi / 2), dtype=float)
        cols.append(np.asarray(KN.quat_rotate(a, [math.cos(e), 0.0, math.sin(e)]), dtype=float))
    return np.stack(cols, axis=1)


def pyramid_cube(*, J: ArrayLike = 5.7e-4, mass: float = 1.0, size: float = 0.15, torque_limit: float = 0.2,
                 speed_limit: float = 400.0, damping: float = 0.0, wheel_damping: float = 0.0, motor: str = "line",
                 elevation_deg: float | None = None, name: str = "cube"):
    """The four-wheel pyramid cube as a Scene: a free uniform cube (a small spacecraft, no external torque)
    carrying ``reaction_wheels`` on :func:`pyramid_axes` (stepped by the printed N-wheel kernels).

    Parameters
    ----------
    J : float or array_like (4,), default 5.7e-4
        Wheel axial inertias, kg·m², > 0.
    mass, size : float
        kg (wheels included and locked), m; > 0 (defaults 1 kg, 0.15 m: the chapter's cube).
    torque_limit, speed_limit : float
        Motor stall torque, N·m, and no-load speed, rad/s (defaults 0.2, 400); > 0.
    damping : float, default 0
        Angular damping on the cube, N·m·s/rad, >= 0 (0: none declared).
    wheel_damping : float, default 0
        Wheel bearing damping ``c_w``, N·m·s/rad, >= 0.
    motor : {"line", "cutoff"}, default "line"
        The torque–speed line, or the hard cut-off at ``speed_limit``.
    elevation_deg : float, optional
        The axes' elevation (:func:`pyramid_axes`).
    name : str, default "cube"
        The body's name.

    Returns
    -------
    lavendersim.Scene

    Raises
    ------
    lavendersim.validate.LavenderInputError
        A parameter out of range, naming it.
    """
    from .bodies import Body
    from .scene import Scene

    motor = V.choice("motor", motor, MOTORS)
    J = np.full(4, V.scalar("J", J)) if isinstance(J, numbers.Real) else V.vector("J", J, 4)
    damping = V.scalar("damping", damping, nonnegative=True)
    scene = Scene()
    scene.add_body(Body.box(name, V.positive("mass", mass), (V.positive("size", size),) * 3))
    scene.add_effect("reaction_wheels", body=name, J=J, axes_b=pyramid_axes(elevation_deg).T, torque_limit=torque_limit,
                     speed_limit=speed_limit, c_w=wheel_damping, cutoff=1.0 if motor == "cutoff" else 0.0)
    if damping > 0:
        scene.add_effect("angular_damping", body=name, c=damping)
    return scene


LAYOUTS = {"pyramid4": pyramid_cube}
