"""LQR design with python-control's solvers, guarded: weights are real finite matrices, and a pair with a
growing mode no input reaches is refused naming the mode (DesignError) before and after solving. Also the
controllable-subspace tools the checks and the linearization use. lavendersim.control re-exports all of it."""
from __future__ import annotations

import math
from typing import Any

import numpy as np
from numpy.typing import ArrayLike

from . import validate as V
from ._install import require


def controllable_basis(A: np.ndarray, B: np.ndarray, tol: float = 1e-9, discrete: bool = False) -> np.ndarray:
    """Orthonormal basis (n, rank) of the controllable subspace span[B, AB, A²B, …].

    Krylov with re-orthogonalization; A and B scaled to unit norm, singular values below tol dropped.
    For a discrete pair the Krylov space of A − I is used (the same space, better conditioned when
    A ≈ I).

    Parameters
    ----------
    A : array_like (n, n)
        State matrix (continuous, or discrete with ``discrete=True``).
    B : array_like (n, m)
        Input matrix.
    tol : float, default 1e-9
        Rank tolerance on the singular values of the (unit-norm scaled) Krylov blocks; for B,
        relative to its largest singular value.
    discrete : bool, default False
        Whether (A, B) is a discrete-time pair (use A − I).

    Returns
    -------
    ndarray (n, rank)
        Orthonormal columns spanning the controllable subspace; (n, 0) if B is empty.
    """
    A, B = np.asarray(A, float), np.asarray(B, float)
    n = A.shape[0]
    if discrete:
        A = A - np.eye(n)
    if B.size == 0:
        return np.zeros((n, 0))
    An = A / max(float(np.linalg.norm(A, 2)), 1e-300)
    Bn = B / max(float(np.linalg.norm(B, 2)), 1e-300)
    U, s, _ = np.linalg.svd(Bn, full_matrices=False)
    new = U[:, s > tol * max(s.max(), 1e-300)]
    basis = new
    for _ in range(n):
        W = An @ new
        for _ in range(2):
            W = W - basis @ (basis.T @ W)
        if W.size == 0:
            break
        U, s, _ = np.linalg.svd(W, full_matrices=False)
        keep = s > tol
        if not keep.any():
            break
        new = U[:, keep]
        basis = np.hstack([basis, new])
        if basis.shape[1] >= n:
            break
    return basis


def uncontrollable(basis: np.ndarray, n: int) -> np.ndarray:
    """Orthonormal complement (n, n − rank) of an orthonormal basis (n, rank) of the controllable subspace.

    Parameters
    ----------
    basis : ndarray (n, rank)
        Orthonormal basis of the controllable subspace (from :func:`controllable_basis`).
    n : int
        State dimension.

    Returns
    -------
    ndarray (n, n − rank)
        Orthonormal basis of the uncontrollable directions; (n, 0) when rank >= n.
    """
    if basis.shape[1] >= n:
        return np.zeros((n, 0))
    P = np.eye(n) - basis @ basis.T
    Uf, _, _ = np.linalg.svd(P)
    return Uf[:, : n - basis.shape[1]]


# ----------------------------------------------------------------------------------------------
# LQR
# ----------------------------------------------------------------------------------------------


WEIGHT_MAX = 1e150   # |entries| of Q and R: the Riccati solution and the gain scale with them (sqrt(Q/R), sqrt(Q R))


def _weight(name: str, value, n: int, definite: bool) -> np.ndarray:
    """A weight matrix (n, n) from a scalar, a diagonal (n,) or a matrix (n, n) of real numbers, checked
    finite, its nonzero entries within [1/WEIGHT_MAX, WEIGHT_MAX] in magnitude, symmetric and positive
    semidefinite (Q) or positive definite (R).

    Complex, bool, string and object entries are refused (numpy would cast "1" or True to 1.0 and drop an
    imaginary part), naming ``name`` and the rule; nothing is rounded into a weight."""
    what = f"must be a real number, a diagonal of {n} real numbers or a {n}×{n} real matrix"
    try:
        arr = V._real_array(name, value)
    except V.LavenderInputError as exc:
        raise V.LavenderInputError(name, what, f" ({exc.rule}{exc.detail})") from None
    if arr.ndim == 0:
        arr = np.full(n, float(arr))
    if arr.ndim == 1:
        if arr.shape != (n,):
            raise V.LavenderInputError(name, f"a diagonal must have {n} entries", f", got {arr.shape[0]}")
        arr = np.diag(arr)
    if arr.shape != (n, n):
        raise V.LavenderInputError(name, f"must be {n}×{n} (or a diagonal of {n})", f", got shape {arr.shape}")
    if not np.all(np.isfinite(arr)):
        raise V.LavenderInputError(name, "must be finite (no NaN or inf)")
    mag = np.abs(arr)
    big = float(mag.max(initial=0.0))
    small = float(mag[mag > 0].min(initial=np.inf))
    if big > WEIGHT_MAX or small < 1 / WEIGHT_MAX:
        raise V.LavenderInputError(name, f"nonzero entries must be between {1 / WEIGHT_MAX:g} and {WEIGHT_MAX:g} in "
                                   "magnitude (rescale Q and R together)", f", got {big if big > WEIGHT_MAX else small:.3g}")
    if not np.allclose(arr, arr.T, rtol=1e-12, atol=1e-12 * max(1.0, big)):
        raise V.LavenderInputError(name, "must be symmetric")
    sym = arr / 2 + arr.T / 2
    ev = np.linalg.eigvalsh(sym)
    tol = 1e-12 * max(1.0, np.abs(ev).max())
    if definite and ev.min() <= tol:
        raise V.LavenderInputError(name, "must be positive definite", f", smallest eigenvalue {ev.min():.3g}")
    if not definite and ev.min() < -tol:
        raise V.LavenderInputError(name, "must be positive semidefinite", f", smallest eigenvalue {ev.min():.3g}")
    return sym


class DesignError(V.LavenderInputError):
    """The LQR design cannot stabilize the model: a mode no input reaches grows on its own (python-control
    refuses such a pair), or the solved gain leaves the closed loop unstable.

    A :class:`lavendersim.validate.LavenderInputError` (``field``, ``rule``, ``detail``) with the mode.

    Parameters
    ----------
    field, rule, detail : str
        As LavenderInputError (``field``: ``"sys"`` for lqr/dlqr, ``"scene"`` for design).
    eigenvalue : complex
        The mode's eigenvalue (continuous: 1/s; discrete: per sample).
    states : tuple of str
        The states the mode lives in (largest components of its PBH left eigenvector first).
    discrete : bool
        Whether the eigenvalue is discrete-time.
    """

    _init_fields = ("field", "rule", "detail", "eigenvalue", "states", "discrete")   # pickles with them

    def __init__(self, field: str, rule: str, detail: str = "", eigenvalue: complex = 0j, states: tuple = (),
                 discrete: bool = False) -> None:
        super().__init__(field, rule, detail)
        self.eigenvalue, self.states, self.discrete = complex(eigenvalue), tuple(states), bool(discrete)


STABILITY_RTOL = 1e-6   # a mode is unstable when it grows faster than this fraction of the model's fastest rate


def _growth(lam: np.ndarray, discrete: bool) -> np.ndarray:
    """Growth of eigenvalues past the stability boundary: |z| − 1 (discrete) or Re s (continuous)."""
    return np.abs(lam) - 1.0 if discrete else np.real(lam)


def _stability_tol(A: np.ndarray, block: np.ndarray, discrete: bool) -> float:
    """Growth below which a mode counts as marginal: STABILITY_RTOL times the fastest rate of the model
    (spectral radius of A, or of A − I discrete: unit-free), plus the rounding split of a double
    integrator's eigenvalues (10 sqrt(eps ‖A‖ ‖block‖): free positions and unactuated axes sit there)."""
    n = A.shape[0]
    fast = float(np.max(np.abs(np.linalg.eigvals(A - np.eye(n) if discrete else A)), initial=0.0))
    eps = np.finfo(float).eps
    return STABILITY_RTOL * fast + 10.0 * math.sqrt(eps * np.linalg.norm(A, 2) * max(float(np.linalg.norm(block, 2)), eps))


def _mode_states(w: np.ndarray, labels: list[str]) -> tuple[str, ...]:
    """The states a mode lives in: components of its left eigenvector at least a tenth of the largest, largest first."""
    a = np.abs(w)
    order = np.argsort(-a, kind="stable")
    return tuple(labels[i] for i in order if a[i] >= 0.1 * a.max())


def unstable_uncontrollable_modes(A: ArrayLike, B: ArrayLike, *, discrete: bool = False, basis: np.ndarray | None = None,
                                  labels: list[str] | None = None) -> list[tuple[complex, tuple[str, ...]]]:
    """The PBH stabilizability test: the modes no input reaches that grow on their own.

    With T an orthonormal basis of the controllable subspace (:func:`controllable_basis`) and U its
    complement, the uncontrollable dynamics are ``Uᵀ A U`` (the subspace is A-invariant); a left eigenvector
    y of it gives ``w = U y`` with ``wᵀ A = λ wᵀ`` and ``wᵀ B = 0`` (rank [A − λI, B] < n): the coordinate
    ``w·x`` evolves as ``e^{λt}`` (or ``λ^k``) whatever the input. A mode is unstable when its growth
    (``Re λ``, or ``|λ| − 1`` discrete) exceeds ``STABILITY_RTOL`` (1e-6) times the model's fastest rate plus
    the rounding split of a double integrator: the marginal modes of internal torques (conserved momenta,
    a free body's position, an unactuated axis's attitude) pass.

    Parameters
    ----------
    A : array_like (n, n)
        State matrix (continuous, or discrete with ``discrete=True``).
    B : array_like (n, m)
        Input matrix.
    discrete : bool, default False
    basis : ndarray (n, rank), optional
        The controllable subspace (default :func:`controllable_basis`).
    labels : list of str, optional
        State names (default ``x[0]``, ``x[1]``, ...).

    Returns
    -------
    list of (complex, tuple of str)
        Each unstable uncontrollable mode (one of a complex pair): its eigenvalue and the states it
        lives in (largest components of w first); empty when (A, B) is stabilizable.
    """
    from scipy.linalg import eig

    A, B = np.asarray(A, float), np.asarray(B, float)
    n = A.shape[0]
    T = controllable_basis(A, B, discrete=discrete) if basis is None else basis
    U = uncontrollable(T, n)
    if U.shape[1] == 0:
        return []
    labels = [f"x[{i}]" for i in range(n)] if labels is None else list(labels)
    Auu = U.T @ A @ U
    lam, W = eig(Auu, left=True, right=False)
    tol = _stability_tol(A, Auu, discrete)
    g = _growth(lam, discrete)
    out = []
    for i in np.argsort(-g, kind="stable"):
        z = complex(lam[i])
        if g[i] > tol and (z.imag >= 0 or _is_real(z)):     # one of a complex pair; every real root
            out.append((complex(z.real) if _is_real(z) else z, _mode_states(U @ W[:, i], labels)))
    return out


def _refuse_unstable(A: np.ndarray, B: np.ndarray, T: np.ndarray, discrete: bool, labels: list[str] | None,
                     field: str, period: float | None) -> None:
    """Raise DesignError naming the fastest unstable uncontrollable mode of (A, B), if any."""
    modes = unstable_uncontrollable_modes(A, B, discrete=discrete, basis=T, labels=labels)
    if not modes:
        return
    lam, states = modes[0]
    rate = ""
    if discrete and period is not None:
        rate = f" (a continuous rate of {math.log(abs(lam)) / period:+.4g}/s at the period {period:g} s)"
    more = f"; {len(modes) - 1} more unstable uncontrollable mode(s)" if len(modes) > 1 else ""
    raise DesignError(field, "has an unstable mode no input reaches (not stabilizable: no gain can hold it)",
                      f": eigenvalue {_eig_text(lam)}{rate} in {', '.join(states)}{more}", lam, states, discrete)


def _is_real(lam: complex) -> bool:
    """An eigenvalue whose imaginary part is rounding (a real double root splits into a ±1e-16j pair)."""
    return abs(lam.imag) <= 1e-12 * max(1.0, abs(lam))


def _eig_text(lam: complex) -> str:
    return f"{lam.real:+.6g}" if _is_real(lam) else f"{lam.real:+.6g}{lam.imag:+.6g}j"


def _check_closed_loop(A: np.ndarray, B: np.ndarray, K: np.ndarray, T: np.ndarray, discrete: bool,
                       labels: list[str] | None, field: str) -> None:
    """Raise DesignError if the solved gain leaves a controllable closed-loop mode unstable (a solver failure)."""
    if T.shape[1] == 0:
        return
    Acl = T.T @ (A - B @ K) @ T
    lam, W = np.linalg.eig(Acl)
    g = _growth(lam, discrete)
    i = int(np.argmax(g))
    if g[i] > _stability_tol(A, Acl, discrete):
        w = T @ W[:, i]
        states = _mode_states(w, [f"x[{j}]" for j in range(A.shape[0])] if labels is None else list(labels))
        raise DesignError(field, "the solved LQR gain leaves the closed loop unstable (check Q against the plant)",
                          f": closed-loop eigenvalue {_eig_text(complex(lam[i]))} in {', '.join(states)}",
                          complex(lam[i]), states, discrete)


class LQRResult(tuple):
    """(K, S, E) as python-control's lqr/dlqr return them (unpacks as a 3-tuple), plus how the design
    was made: ``rank`` of the controllable subspace, ``controllable``, and ``uncontrollable`` — an
    orthonormal basis (n, n − rank) of the directions no input can change (their closed-loop
    eigenvalues stay at 0, continuous, or 1, discrete: conserved momenta, not errors to regulate)."""

    K: np.ndarray
    S: np.ndarray
    E: np.ndarray
    rank: int
    uncontrollable: np.ndarray

    def __new__(cls, K: np.ndarray, S: np.ndarray, E: np.ndarray, rank: int, unc: np.ndarray) -> "LQRResult":
        obj = super().__new__(cls, (K, S, E))
        obj.K, obj.S, obj.E, obj.rank, obj.uncontrollable = K, S, E, rank, unc
        return obj

    @property
    def controllable(self) -> bool:
        """Whether the design covered the whole state (rank == n)."""
        return self.uncontrollable.shape[1] == 0


def _pair(sys_or_A: Any, args: tuple, fn: str, discrete: bool) -> tuple[np.ndarray, np.ndarray, np.ndarray, tuple]:
    """(A, B, basis, rest of args) from a StateSpace, an (A, B) pair, or A, B positional (python-control style)."""
    ct = require("control", "control", "LQR design (python-control)")
    basis = None
    if isinstance(sys_or_A, ct.StateSpace):
        if discrete != sys_or_A.isdtime(strict=True):
            raise V.LavenderInputError("sys", f"{fn} needs a {'discrete' if discrete else 'continuous'} StateSpace"
                                       + (" (sample it: lin.sample(dt) or ct.c2d(sys, dt))" if discrete else " (use dlqr)"),
                                       f", got dt = {sys_or_A.dt}")
        A, B = sys_or_A.A, sys_or_A.B
        basis = getattr(sys_or_A, "basis", None)
    elif isinstance(sys_or_A, tuple) and len(sys_or_A) == 2:
        A, B = sys_or_A
    elif len(args) >= 3:
        A, B, args = sys_or_A, args[0], args[1:]
    else:
        raise V.LavenderInputError("sys", f"{fn} takes a control.StateSpace, an (A, B) pair, or A, B, Q, R",
                                   f", got {type(sys_or_A).__name__}")
    try:
        A, B = np.asarray(A, dtype=float), np.asarray(B, dtype=float)
    except (TypeError, ValueError):
        raise V.LavenderInputError("A", "A and B must be numeric matrices") from None
    if B.ndim == 1:
        B = B[:, None]
    n = A.shape[0] if A.ndim == 2 else -1
    if A.ndim != 2 or A.shape != (n, n) or B.ndim != 2 or B.shape[0] != n:
        raise V.LavenderInputError("A", "A must be n×n and B n×m", f", got {A.shape} and {B.shape}")
    if not (np.all(np.isfinite(A)) and np.all(np.isfinite(B))):
        raise V.LavenderInputError("A", "A and B must be finite")
    if len(args) != 2:
        raise V.LavenderInputError("Q", f"{fn} needs Q and R", f", got {len(args)} weight argument(s)")
    if basis is None:
        basis = controllable_basis(A, B, discrete=discrete)
    return A, B, basis, args


def _design(sys_or_A: Any, args: tuple, discrete: bool, *, labels: list[str] | None = None, field: str = "sys",
            period: float | None = None) -> LQRResult:
    ct = require("control", "control", "LQR design (python-control)")
    fn = "dlqr" if discrete else "lqr"
    A, B, T, (Q, R) = _pair(sys_or_A, args, fn, discrete)
    n, m = B.shape
    Q = _weight("Q", Q, n, definite=False)
    R = _weight("R", R, m, definite=True)
    if labels is None and isinstance(sys_or_A, ct.StateSpace):
        labels = list(sys_or_A.state_labels)
    _refuse_unstable(A, B, T, discrete, labels, field, period if period is not None else (
        float(sys_or_A.dt) if discrete and isinstance(sys_or_A, ct.StateSpace) and sys_or_A.dt is not True else None))
    solve = ct.dlqr if discrete else ct.lqr
    if T.shape[1] == n:
        K, S, _ = solve(A, B, Q, R)
    else:
        if T.shape[1] == 0:
            raise V.LavenderInputError("B", "no input reaches any state (the controllable subspace is empty)")
        Qc = T.T @ Q @ T
        Kc, Sc, _ = solve(T.T @ A @ T, T.T @ B, (Qc + Qc.T) / 2, R)
        K, S = np.asarray(Kc) @ T.T, T @ np.asarray(Sc) @ T.T
    K, S = np.asarray(K), np.asarray(S)
    _check_closed_loop(A, B, K, T, discrete, labels, field)
    E = np.linalg.eigvals(A - B @ K)
    E = E[np.argsort(np.abs(E) if discrete else E.real)]
    return LQRResult(K, S, E, T.shape[1], uncontrollable(T, n))


def lqr(sys: Any, *args: Any) -> LQRResult:
    """Continuous LQR, python-control conventions: ``lqr(sys, Q, R)`` with a ``control.StateSpace``
    (a :class:`~lavendersim.control.Linearization` or any continuous one), ``lqr((A, B), Q, R)`` or ``lqr(A, B, Q, R)``.

    When (A, B) is not controllable (internal wheel torques conserve momentum) the design is made on
    the controllable subspace (orthonormal Krylov basis T): ``Kc, Sc = control.lqr(TᵀAT, TᵀB, TᵀQT,
    R)``, ``K = Kc Tᵀ``, ``S = T Sc Tᵀ``; otherwise it is exactly ``control.lqr(A, B, Q, R)``.

    Parameters
    ----------
    sys : control.StateSpace, (A, B) or A
        The model (n states, m inputs).
    *args
        Q (n×n, a diagonal (n,) or a scalar; symmetric PSD) and R (m×m, (m,) or scalar; PD), after
        B when A and B are given separately.

    Returns
    -------
    LQRResult
        Unpacks as (K (m, n), S (n, n), E (n,) closed-loop eigenvalues of A − B K, sorted by real
        part); ``.rank`` and ``.uncontrollable`` report the directions the design cannot move.

    Raises
    ------
    DesignError
        A mode no input reaches grows on its own (:func:`unstable_uncontrollable_modes`: python-control
        refuses such a pair), naming its eigenvalue and states; or the solved gain leaves the closed loop
        unstable. Marginal uncontrollable modes (conserved momenta at 0) are designed around.
    lavendersim.validate.LavenderInputError
        As :func:`dlqr`.
    """
    return _design(sys, args, discrete=False)


def dlqr(sys: Any, *args: Any) -> LQRResult:
    """Discrete LQR (python-control's dlqr), with the same forms and subspace design as :func:`lqr`.

    ``dlqr(lin.sample(Ts), Q, R)``, ``dlqr((Ad, Bd), Q, R)`` or ``dlqr(Ad, Bd, Q, R)``. The gain is
    for u[k] = u0 − K x[k] held over the period (zero-order hold). E are the eigenvalues of Ad − Bd K,
    sorted by modulus (conserved directions at 1).

    Parameters
    ----------
    sys : control.StateSpace, (Ad, Bd) or Ad
        The discrete-time model (n states, m inputs), e.g. ``lin.sample(Ts)``; a StateSpace must be
        discrete (dt > 0).
    *args
        Q (n×n, a diagonal (n,) or a scalar; symmetric PSD) and R (m×m, (m,) or scalar; PD), after
        Bd when Ad and Bd are given separately.

    Returns
    -------
    LQRResult
        Unpacks as (K (m, n), S (n, n), E (n,) closed-loop eigenvalues of Ad − Bd K, sorted by
        modulus); ``.rank`` and ``.uncontrollable`` report the directions the design cannot move.

    Raises
    ------
    lavendersim._install.MissingExtraError
        If python-control (the ``control`` extra) is not installed.
    lavendersim.validate.LavenderInputError
        If the system is continuous or not a recognized form, A, B are not finite n×n, n×m matrices,
        Q and R are missing or not valid weights (real finite numbers; Q symmetric PSD, R symmetric PD), or
        no input reaches any state.
    DesignError
        A mode no input reaches grows on its own (|z| > 1), naming its eigenvalue and states, or the solved
        gain leaves the closed loop unstable. Marginal uncontrollable modes (conserved momenta at 1) pass.
    """
    return _design(sys, args, discrete=True)
