"""Attitude error coordinates about a reference orientation: the chart the linearization and the controllers
use (dtheta = 2 vec(q_ref* ⊗ q), with the sign of the scalar part), its inverse, and helpers to rotate a
reference. Quaternions (x, y, z, w); the chart and its inverse are the printed kernels quat_error_chart and
quat_error_chart_inverse (derive/quaternion.py, derive/measures.py), as _linearize's CasADi twin."""
from __future__ import annotations

import math

import numpy as np
from numpy.typing import ArrayLike

from . import validate as V
from .kernels import K as KN


def attitude_error(q: ArrayLike, q_ref: ArrayLike) -> np.ndarray:
    """Attitude error dtheta = 2 vec(q_ref* ⊗ q), sign chosen so the scalar part is >= 0 (rad, body frame).

    Parameters
    ----------
    q : array_like (4,) or (..., 4)
        Orientation(s), body to world, quaternion (x, y, z, w), unit length.
    q_ref : array_like (4,) or (..., 4)
        Reference orientation(s), quaternion (x, y, z, w), unit length; broadcasts against ``q``.

    Returns
    -------
    ndarray (3,) or (..., 3)
        dtheta, rad, in the reference's body frame (the inverse of :func:`perturbed` for
        |dtheta| < 2).
    """
    return KN.quat_error_chart(q, q_ref)


def error_angle_deg(q: ArrayLike, q_ref: ArrayLike) -> np.ndarray:
    """Rotation angle between q and q_ref, degrees in [0, 180].

    Parameters
    ----------
    q : array_like (4,) or (..., 4)
        Orientation(s), body to world, quaternion (x, y, z, w), unit length.
    q_ref : array_like (4,) or (..., 4)
        Reference orientation(s), quaternion (x, y, z, w), unit length; broadcasts against ``q``.

    Returns
    -------
    float or ndarray (...,)
        The angle of the rotation q_ref* ⊗ q, deg (q and −q give the same angle).
    """
    return np.degrees(KN.quat_error_angle(np.asarray(q, float), np.asarray(q_ref, float)))


def perturbed(q_ref: ArrayLike, dtheta: ArrayLike) -> np.ndarray:
    """Orientation at attitude error dtheta: q = q_ref ⊗ [dtheta/2, sqrt(1 - |dtheta/2|²)].

    The inverse of :func:`attitude_error`.

    Parameters
    ----------
    q_ref : array_like (4,)
        Reference orientation, body to world, quaternion (x, y, z, w), unit length.
    dtheta : array_like (3,)
        Attitude error, rad, body frame; |dtheta| < 2.

    Returns
    -------
    ndarray (4,)
        q, quaternion (x, y, z, w).

    Raises
    ------
    lavendersim.validate.LavenderInputError
        If |dtheta| >= 2.
    """
    h = np.asarray(dtheta, float) / 2
    n2 = float(h @ h)
    if n2 >= 1:
        raise V.LavenderInputError("dtheta", "must satisfy |dtheta| < 2", f", got |dtheta| = {2 * math.sqrt(n2):.4g}")
    return KN.quat_error_chart_inverse(q_ref, dtheta)


def rotated(q_ref: ArrayLike, axis: ArrayLike, angle_deg: float) -> np.ndarray:
    """q_ref ⊗ rotation by angle_deg about a body-frame axis (normalized).

    Parameters
    ----------
    q_ref : array_like (4,)
        Reference orientation, body to world, quaternion (x, y, z, w), unit length.
    axis : array_like (3,)
        Rotation axis, body frame of ``q_ref``; any non-zero length (normalized here).
    angle_deg : float
        Rotation angle, deg (right-handed about ``axis``).

    Returns
    -------
    ndarray (4,)
        The rotated orientation, quaternion (x, y, z, w).

    Raises
    ------
    lavendersim.validate.LavenderInputError
        If ``axis`` is not a finite 3-vector or is zero, or ``angle_deg`` is not a finite number
        (reported as ``theta0_deg``).
    """
    axis = V.vector("axis", axis)
    n = np.linalg.norm(axis)
    if n == 0:
        raise V.LavenderInputError("axis", "must be a non-zero vector")
    qa = np.asarray(KN.axis_angle_to_quat(axis / n, math.radians(V.scalar("theta0_deg", angle_deg))), dtype=float)
    return np.asarray(KN.quat_mul(np.asarray(q_ref, float), qa), dtype=float)


