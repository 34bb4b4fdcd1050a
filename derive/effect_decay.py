"""Which effects are pure linear decays, and at what rate: the stiffness a Sim checks against its integrator.

An effect is a *decay* when its accelerations — ``F_w / m`` on the COM velocity (world frame) and
``I⁻¹ (R_WBᵀ tau_w + tau_b)`` on ``omega_b`` (body frame) — are ``-D (v_w, omega_b)`` with ``D`` diagonal,
non-negative, constant in the state (every ``p_w``, ``q``, ``v_w``, ``omega_b``) and zero at rest. Such a load only
takes momentum out (``F·p = -m Σ d_i v_i² ≤ 0``; ``tau·L = -ω·D I ω ≤ 0`` with ``D`` and ``I`` diagonal), and
an explicit step of it is stable while ``max(D)·dt`` stays below its integrator's limit on the negative real
axis (tableaux.real_axis_stability: ``c dt / m ≤ 2`` under euler, for instance).

:func:`decay_rate` decides it for one declaration and returns ``max(D)`` as a SymPy expression in the
effect's parameters, ``m`` and ``I_b`` (None when the effect is not a decay: its load then counts in the
growth check's budget of what the loads can supply, see lavendersim/sim.py). The structure is read
symbolically (the Jacobian of the accelerations, its diagonal at ``q`` = identity); that it holds in every
state is checked at derive time on random states, orientations and parameter values within their rules
(a rational function of the state that vanishes at 8 random points is taken as zero, as with every
derive-time proof by evaluation here).
"""
from __future__ import annotations

import numpy as np
import sympy as sp

from .effect import STATE, EffectDecl

SAMPLES = 8            # random (state, orientation, parameter) points each property is checked at
REL_TOL = 1e-9         # relative agreement of the sampled Jacobians


def _accelerations(d: EffectDecl) -> sp.Matrix:
    """(F_w / m, I⁻¹ (R_WBᵀ tau_w + tau_b)): 6 rows, in the effect's parameters and the state."""
    zero = sp.zeros(3, 1)
    F = d.force_w if d.force_w is not None else zero
    tau_b = STATE.R_WB.T * (d.torque_w if d.torque_w is not None else zero)
    if d.torque_b is not None:           # a body-frame torque (FLAG_TORQUE_B) as declared, not rotated there and back
        tau_b = tau_b + d.torque_b
    return sp.Matrix([F[i] / STATE.m for i in range(3)] + [tau_b[i] / STATE.I_b[i] for i in range(3)])


def _samples(d: EffectDecl, rng: np.random.Generator) -> list[dict]:
    """Random points: unit q, state values, positive m and I_b, parameters within their rules."""
    out = []
    for _ in range(SAMPLES):
        q = rng.normal(size=4)
        q /= np.linalg.norm(q)
        point = dict(zip(STATE.q, q))
        for f in ("p_w", "v_w", "omega_b"):
            point.update(zip(STATE.symbols(f), rng.normal(size=3)))
        point[STATE.m] = rng.uniform(0.5, 3.0)
        point.update(zip(STATE.I_b, rng.uniform(0.5, 3.0, size=3)))
        for p in d.params:
            syms = list(p.symbol) if isinstance(p.symbol, sp.MatrixBase) else [p.symbol]
            vals = rng.uniform(0.1, 2.0, size=len(syms)) if p.rule != "finite" else rng.normal(size=len(syms))
            point.update(zip(syms, vals))
        out.append(point)
    return out


def decay_rate(d: EffectDecl) -> sp.Expr | None:
    """``max(D)`` of a decay effect (module docstring), in its parameters, ``m`` and ``I_b``; None otherwise.

    Parameters
    ----------
    d : EffectDecl
        A force effect declaration (model effects: None; wheel damping has its own bound).

    Returns
    -------
    sympy.Expr or None
        The decay rate, 1/s.
    """
    if d.kind != "force":
        return None
    hit = _MEMO.get(id(d))
    if hit is None or hit[0] is not d:
        hit = _MEMO[id(d)] = (d, _decay_rate(d))     # the declaration is held: its id is not reused
    return hit[1]


_MEMO: dict[int, tuple] = {}


def _decay_rate(d: EffectDecl) -> sp.Expr | None:
    try:
        return _structure(d)
    except (NameError, TypeError, ValueError, ZeroDivisionError, OverflowError, AttributeError):
        # a function the numeric check cannot evaluate (e.g. erf, or sign's DiracDelta derivative): no bound is
        # declared for it; its loads count in the growth budget like any other
        return None


def _structure(d: EffectDecl) -> sp.Expr | None:
    y = _accelerations(d)
    x = list(STATE.v_w) + list(STATE.omega_b)
    J = y.jacobian(x).replace(sp.DiracDelta, lambda *a: sp.Integer(0))    # d sign(u)/du = 0 where it is defined
    fy = sp.lambdify([list(y.free_symbols | J.free_symbols)], [y, J], modules="numpy")
    syms = list(y.free_symbols | J.free_symbols)
    rng = np.random.default_rng(20261126)
    for point in _samples(d, rng):
        at_rest = {**point, **{s: 0.0 for s in x}}
        with np.errstate(all="ignore"):      # e.g. |v| v at rest: 0/0 is not a decay (the NaN fails below)
            y0, _ = fy([at_rest.get(s, 0.0) for s in syms])
            _, Jn = fy([point.get(s, 0.0) for s in syms])
        Jn = np.asarray(Jn, dtype=float)
        scale = max(1.0, float(np.abs(Jn).max()))
        if not np.abs(np.asarray(y0, dtype=float)).max() <= REL_TOL * scale:
            return None                      # a load at rest: it can supply momentum
        if not (np.abs(Jn - np.diag(np.diag(Jn))).max() <= REL_TOL * scale and np.diag(Jn).max() <= REL_TOL * scale):
            return None                      # coupled or anti-damping: not a pure decay
    # constant in the state: the Jacobian at q = identity, symbolic in the parameters, m, I_b
    ident = {STATE.q[0]: 0, STATE.q[1]: 0, STATE.q[2]: 0, STATE.q[3]: 1}
    diag = [sp.simplify(-J[i, i].subs(ident)) for i in range(6)]
    state = set(STATE.p_w) | set(STATE.q) | set(x)
    if any(e.free_symbols & state for e in diag):
        return None
    f = sp.lambdify([syms], sp.Matrix(diag), modules="numpy")
    for point in _samples(d, rng):
        with np.errstate(all="ignore"):
            _, Jn = fy([point.get(s, 0.0) for s in syms])
        want = -np.diag(np.asarray(Jn, dtype=float))
        got = np.asarray(f([point.get(s, 0.0) for s in syms]), dtype=float).ravel()
        if not np.abs(got - want).max() <= REL_TOL * max(1.0, float(np.abs(want).max())):
            return None                      # depends on the orientation or the state: no constant rate
    terms = [e for e in diag if e != 0]
    if not terms:
        return None
    return terms[0] if len(terms) == 1 else sp.Max(*terms)
