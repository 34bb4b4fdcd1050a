"""Particle systems: total mass, centre of mass, linear and angular momentum.

Each function validates its inputs (``LavenderInputError`` naming the field) and sums the
generated per-particle kernels (``particle_moments``, ``particle_angular_momentum``,
``parallel_axis``) over the particles; nothing here retypes an equation.

Shapes: ``m`` (N,) masses in kg, all > 0; ``r_w`` (N, 3) world positions in m; ``v_w`` (N, 3)
world velocities in m/s. Results are world-frame float64 arrays::

    m = sum_i m_i                                  total_mass
    r_COM = (1/m) sum_i m_i r_i                    center_of_mass
    p = sum_i m_i v_i = m v_COM                    linear_momentum
    L = sum_i (r_i - r_COM) x m_i (v_i - v_COM)    angular_momentum_com
    I = sum_i m_i (|s_i|^2 1 - s_i s_i^T), s_i = r_i - r_COM     inertia_com
"""
from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike

from . import validate as V
from .kernels import K

__all__ = ["total_mass", "center_of_mass", "linear_momentum", "com_velocity", "angular_momentum_com", "inertia_com"]


def _masses(m) -> np.ndarray:
    arr = V.array("m", m, (None,))
    if arr.size == 0:
        raise V.LavenderInputError("m", "a particle system needs at least one particle")
    bad = np.nonzero(~(arr > 0))[0]
    if bad.size:
        raise V.LavenderInputError("m", "every mass must be > 0 (kg)", f", got {arr[bad[0]]!r} at index {bad[0]}")
    return arr


def _vectors(field: str, value, n: int) -> np.ndarray:
    arr = V.array(field, value, (None, 3))
    if arr.shape[0] != n:
        raise V.LavenderInputError(field, f"expected one 3-vector per mass: shape ({n}, 3)", f", got {arr.shape}")
    return arr


def total_mass(m: ArrayLike) -> float:
    """Sum of the particle masses, kg.

    Parameters
    ----------
    m : array_like, shape (n,)
        Masses, kg, > 0.

    Returns
    -------
    float

    Raises
    ------
    LavenderInputError
        On a non-positive mass or mismatched shapes.
    """
    return float(np.sum(_masses(m)))


def center_of_mass(m: ArrayLike, r_w: ArrayLike) -> np.ndarray:
    """Centre of mass, world, m: (sum_i m_i r_i) / (sum_i m_i).

    Parameters
    ----------
    m : array_like, shape (n,)
        Masses, kg, > 0.
    r_w : array_like, shape (n, 3)
        Positions, world frame, m.

    Returns
    -------
    ndarray, shape (3,)

    Raises
    ------
    LavenderInputError
        On a non-positive mass or mismatched shapes.
    """
    m = _masses(m)
    r = _vectors("r_w", r_w, m.size)
    m_r, _ = K.particle_moments(m, r, np.zeros_like(r))
    return m_r.sum(axis=0) / m.sum()


def linear_momentum(m: ArrayLike, v_w: ArrayLike) -> np.ndarray:
    """Total linear momentum, world, kg·m/s: sum_i m_i v_i.

    Parameters
    ----------
    m : array_like, shape (n,)
        Masses, kg, > 0.
    v_w : array_like, shape (n, 3)
        Velocities, world frame, m/s.

    Returns
    -------
    ndarray, shape (3,)

    Raises
    ------
    LavenderInputError
        On a non-positive mass or mismatched shapes.
    """
    m = _masses(m)
    v = _vectors("v_w", v_w, m.size)
    _, p = K.particle_moments(m, np.zeros_like(v), v)
    return p.sum(axis=0)


def com_velocity(m: ArrayLike, v_w: ArrayLike) -> np.ndarray:
    """Velocity of the centre of mass, world, m/s: p / m.

    Parameters
    ----------
    m : array_like, shape (n,)
        Masses, kg, > 0.
    v_w : array_like, shape (n, 3)
        Velocities, world frame, m/s.

    Returns
    -------
    ndarray, shape (3,)

    Raises
    ------
    LavenderInputError
        On a non-positive mass or mismatched shapes.
    """
    m = _masses(m)
    return linear_momentum(m, v_w) / m.sum()


def angular_momentum_com(m: ArrayLike, r_w: ArrayLike, v_w: ArrayLike) -> np.ndarray:
    """Angular momentum about the centre of mass, world, kg·m²/s.

    Parameters
    ----------
    m : array_like, shape (n,)
        Masses, kg, > 0.
    r_w : array_like, shape (n, 3)
        Positions, world frame, m.
    v_w : array_like, shape (n, 3)
        Velocities, world frame, m/s.

    Returns
    -------
    ndarray, shape (3,)

    Raises
    ------
    LavenderInputError
        On a non-positive mass or mismatched shapes.
    """
    m = _masses(m)
    r = _vectors("r_w", r_w, m.size)
    v = _vectors("v_w", v_w, m.size)
    m_r, p = K.particle_moments(m, r, v)
    r_com = m_r.sum(axis=0) / m.sum()
    v_com = p.sum(axis=0) / m.sum()
    return K.particle_angular_momentum(m, r, v, r_com, v_com).sum(axis=0)


def inertia_com(m: ArrayLike, r_w: ArrayLike) -> np.ndarray:
    """Inertia tensor about the centre of mass, world axes, kg·m² (3, 3).

    Each point mass is a zero tensor moved to its offset by the parallel-axis kernel.

    Parameters
    ----------
    m : array_like, shape (n,)
        Masses, kg, > 0.
    r_w : array_like, shape (n, 3)
        Positions, world frame, m.

    Returns
    -------
    ndarray, shape (3, 3)

    Raises
    ------
    LavenderInputError
        On a non-positive mass or mismatched shapes.
    """
    m = _masses(m)
    r = _vectors("r_w", r_w, m.size)
    s = r - center_of_mass(m, r)
    return K.parallel_axis(np.zeros((m.size, 3, 3)), m, s).sum(axis=0)
