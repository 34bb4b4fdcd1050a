"""Input validation shared by every public entry point of LavenderSim.

Every check raises :class:`LavenderInputError` (a ``ValueError``) naming the
offending field; none uses ``assert`` (which ``python -O`` strips). Inputs are
never mutated, and array results are fresh C-contiguous float64 copies.

Conventions (README.md, "Conventions"): SI units; quaternions are ``(x, y, z, w)``, scalar
last; inertia is in kg*m^2, given in the body frame.
"""

from __future__ import annotations

import difflib
import functools
import inspect
import numbers
import os
from collections.abc import Callable, Iterable, Sequence
from pathlib import Path
from typing import Any, ParamSpec, SupportsFloat, TypeVar

import numpy as np
from numpy.typing import ArrayLike

from .errors import PicklableError

__all__ = [
    "LavenderInputError",
    "ValidityBoundError",
    "vector",
    "array",
    "scalar",
    "positive",
    "dt",
    "quaternion",
    "inertia",
    "principal_axes",
    "choice",
    "integer",
    "keywords",
    "safe_norm",
    "writable_dir",
    "writable_file",
]

# Relative tolerances, scaled by max|I| (inertia) or by the largest moment.
SYMMETRY_RTOL = 1e-12
DIAGONAL_RTOL = 1e-12
TRIANGLE_RTOL = 1e-12
# A quaternion whose norm is below this cannot be normalized meaningfully.
QUATERNION_MIN_NORM = 1e-300

_DIAGONAL_RULE = (
    "must be principal moments (a diagonal tensor) here: lavendersim.Body takes a full tensor "
    "(lavendersim.validate.principal_axes gives the moments and axes)"
)


class LavenderInputError(PicklableError, ValueError):
    """Invalid input to a LavenderSim entry point.

    The message is ``f"{field}: {rule}{detail}"``; the three are kept as attributes.

    Parameters
    ----------
    field : str
        The name of the rejected parameter (e.g. ``"mass"``, ``"overlays.vectors[1].color"``).
    rule : str
        The rule that was broken (``"must be finite and > 0"``).
    detail : str, optional
        A summary of the offending value (``", got -1"``).

    Examples
    --------
    >>> import lavendersim as lv
    >>> try:
    ...     lv.Body.box("b", mass=-1.0, size=(1, 1, 1))
    ... except lv.LavenderInputError as e:
    ...     print(e.field)
    mass
    """

    _init_fields: tuple[str, ...] = ("field", "rule", "detail")   # pickles with them (lavendersim.errors.PicklableError)

    def __init__(self, field: str, rule: str, detail: str = "") -> None:
        self.field = field
        self.rule = rule
        self.detail = detail
        super().__init__(f"{field}: {rule}{detail}")


class ValidityBoundError(LavenderInputError):
    """A value valid on its own that puts a simulation beyond its integrator's validity or stability bound
    (``Sim(..., on_bound="raise")``): the message names the bound and how to stay inside it. The labs
    record it, like a DivergenceError, as a failed figure of their failure modes.

    Parameters
    ----------
    field : str
        The setting that crosses the bound (an effect's name, ``omega_b``, ...).
    rule : str
        The bound and its value.
    detail : str, optional
        What to do about it.
    """


# --------------------------------------------------------------------------
# formatting helpers
# --------------------------------------------------------------------------


def _num(x) -> str:
    """Compact, exact-enough text for one real number: 1, 0.1, nan, -inf."""
    x = float(x)
    if np.isfinite(x) and x.is_integer() and abs(x) < 1e16:
        return str(int(x))
    return repr(x)


def _nums(a) -> str:
    return "[" + ", ".join(_num(x) for x in np.ravel(a)) + "]"


def _shape_text(shape) -> str:
    parts = ["N" if s is None else str(s) for s in shape]
    if len(parts) == 1:
        return f"({parts[0]},)"
    return "(" + ", ".join(parts) + ")"


def _describe(value) -> str:
    """Short description of a rejected object: its type and a clipped repr."""
    try:
        text = repr(value)
    except Exception:  # a broken __repr__ must not hide the real error
        text = "<unrepresentable>"
    if len(text) > 60:
        text = text[:57] + "..."
    return f"{type(value).__name__} {text}"


def _index_text(idx: tuple) -> str:
    return str(idx[0]) if len(idx) == 1 else "(" + ", ".join(map(str, idx)) + ")"


def _find_bool(value, path=()):
    """Index path of the first bool inside nested lists/tuples, else None."""
    if isinstance(value, (bool, np.bool_)):
        return path
    if isinstance(value, (list, tuple)):
        for i, item in enumerate(value):
            found = _find_bool(item, path + (i,))
            if found is not None:
                return found
    return None


# --------------------------------------------------------------------------
# arrays
# --------------------------------------------------------------------------


def _real_array(field: str, value) -> np.ndarray:
    """Convert to a fresh float64 array, rejecting non-real or bool content."""
    if isinstance(value, (str, bytes)) or value is None:
        raise LavenderInputError(field, "expected real numbers", f", got {_describe(value)}")
    if not isinstance(value, np.ndarray):
        where = _find_bool(value)
        if where is not None:
            detail = " (got a bool)" if where == () else f" (got a bool at index {_index_text(where)})"
            raise LavenderInputError(field, "expected real numbers, not bools", detail)
    try:
        arr = np.asarray(value)
    except (ValueError, TypeError) as exc:  # ragged nesting and the like
        raise LavenderInputError(
            field, "expected a rectangular array of real numbers", f", got {_describe(value)} ({exc})"
        ) from None
    kind = arr.dtype.kind
    if kind == "b":
        raise LavenderInputError(field, "expected real numbers, not bools", f", got dtype {arr.dtype}")
    if kind == "c":
        raise LavenderInputError(field, "expected real numbers, not complex", f", got dtype {arr.dtype}")
    if kind in "iuf":
        return np.array(arr, dtype=np.float64, order="C", copy=True)
    if kind == "O":
        out = np.empty(arr.shape, dtype=np.float64)
        for idx, item in np.ndenumerate(arr):
            if isinstance(item, (bool, np.bool_)) or not isinstance(item, numbers.Real):
                where = "" if idx == () else f" at index {_index_text(idx)}"
                raise LavenderInputError(
                    field, "expected real numbers", f", got {_describe(item)}{where}"
                )
            try:
                out[idx] = float(item)
            except OverflowError:
                out[idx] = -np.inf if item < 0 else np.inf
        return out
    raise LavenderInputError(field, "expected real numbers", f", got {_describe(value)} (dtype {arr.dtype})")


def _check_finite(field: str, arr: np.ndarray, rule: str = "must be finite") -> None:
    bad = ~np.isfinite(arr)
    if bad.any():
        idx = tuple(int(i) for i in np.argwhere(bad)[0])
        where = "" if idx == () else f" at index {_index_text(idx)}"
        raise LavenderInputError(field, rule, f", got {_num(arr[idx])}{where}")


def array(field: str, value: ArrayLike, shape: Sequence[int | None]) -> np.ndarray:
    """Validate a finite real array of the given shape; return a float64 copy.

    ``shape`` entries may be ``None`` for "any length" in that position, e.g.
    ``(None, 3)`` for a stack of 3-vectors.

    Parameters
    ----------
    field : str
        The name an error message gives the value (e.g. ``"omega_b"``, ``"scene.bodies"``).
    value : array_like
        The input.
    shape : sequence of int or None
        Expected shape.

    Returns
    -------
    ndarray
        float64 copy.

    Raises
    ------
    LavenderInputError
        Naming `field` and the broken rule.
    """
    shape = tuple(shape)
    arr = _real_array(field, value)
    ok = arr.ndim == len(shape) and all(s is None or s == d for s, d in zip(shape, arr.shape))
    if not ok:
        raise LavenderInputError(field, f"expected shape {_shape_text(shape)}", f", got {arr.shape}")
    _check_finite(field, arr)
    return arr


def vector(field: str, value: ArrayLike, n: int = 3) -> np.ndarray:
    """Validate a finite real vector of shape ``(n,)``; return a float64 copy.

    Parameters
    ----------
    field : str
        The name an error message gives the value (e.g. ``"omega_b"``, ``"scene.bodies"``).
    value : array_like
        The input.
    n : int, optional
        Expected length (3).

    Returns
    -------
    ndarray, shape (n,)

    Raises
    ------
    LavenderInputError
        Naming `field` and the broken rule.
    """
    return array(field, value, (n,))


# --------------------------------------------------------------------------
# scalars
# --------------------------------------------------------------------------


def scalar(field: str, value: object, *, positive: bool = False, nonnegative: bool = False) -> float:
    """Validate a finite real number (bools rejected); return it as a float.

    ``positive=True`` requires > 0; ``nonnegative=True`` requires >= 0.

    Parameters
    ----------
    field : str
        The name an error message gives the value (e.g. ``"omega_b"``, ``"scene.bodies"``).
    value : float
        The input (anything: what is not a finite real number is refused).
    positive, nonnegative : bool, optional
        Extra rules.

    Returns
    -------
    float

    Raises
    ------
    LavenderInputError
        Naming `field` and the broken rule.
    """
    if positive:
        rule = "must be finite and > 0"
    elif nonnegative:
        rule = "must be finite and >= 0"
    else:
        rule = "must be finite"
    if isinstance(value, (bool, np.bool_)):
        raise LavenderInputError(field, "expected a real number, not a bool", f", got {value!r}")
    if isinstance(value, np.ndarray):
        if value.ndim != 0:
            raise LavenderInputError(field, "expected a real number", f", got an array of shape {value.shape}")
        if value.dtype.kind not in "iuf":
            raise LavenderInputError(field, "expected a real number", f", got an array of dtype {value.dtype}")
        x = float(value)
    elif isinstance(value, numbers.Real):
        try:
            x = float(value)
        except OverflowError:
            x = -np.inf if value < 0 else np.inf
    else:
        raise LavenderInputError(field, "expected a real number", f", got {_describe(value)}")
    if not np.isfinite(x) or (positive and not x > 0) or (nonnegative and not x >= 0):
        raise LavenderInputError(field, rule, f", got {x!r}")
    return x


def positive(field: str, value: SupportsFloat) -> float:
    """Shorthand for ``scalar(field, value, positive=True)`` (e.g. mass in kg).

    Parameters
    ----------
    field : str
        The name an error message gives the value (e.g. ``"omega_b"``, ``"scene.bodies"``).
    value : float
        The input.

    Returns
    -------
    float

    Raises
    ------
    LavenderInputError
        Naming `field` and the broken rule.
    """
    return scalar(field, value, positive=True)


def dt(field: str, value: SupportsFloat) -> float:
    """Validate a time step in seconds: finite and > 0.

    Parameters
    ----------
    field : str
        The name an error message gives the value (e.g. ``"omega_b"``, ``"scene.bodies"``).
    value : float
        The step, s.

    Returns
    -------
    float

    Raises
    ------
    LavenderInputError
        Naming `field` and the broken rule.
    """
    return scalar(field, value, positive=True)


def integer(field: str, value: int | np.integer, *, minimum: int | None = None) -> int:
    """Validate a Python or NumPy integer (not bool, not float), optionally >= minimum.

    Parameters
    ----------
    field : str
        The name an error message gives the value (e.g. ``"omega_b"``, ``"scene.bodies"``).
    value : int
        The input.
    minimum : int or None, optional
        Smallest allowed value.

    Returns
    -------
    int

    Raises
    ------
    LavenderInputError
        Naming `field` and the broken rule.
    """
    if isinstance(value, (bool, np.bool_)) or not isinstance(value, (int, np.integer)):
        raise LavenderInputError(field, "expected an integer", f", got {_describe(value)}")
    n = int(value)
    if minimum is not None and n < minimum:
        raise LavenderInputError(field, f"must be an integer >= {minimum}", f", got {n}")
    return n


def choice(field: str, value: str, allowed: Iterable[str]) -> str:
    """Validate that ``value`` is one of the ``allowed`` names; return it.

    Parameters
    ----------
    field : str
        The name an error message gives the value (e.g. ``"omega_b"``, ``"scene.bodies"``).
    value : str
        The input.
    allowed : iterable of str
        The accepted names (listed in the error).

    Returns
    -------
    str

    Raises
    ------
    LavenderInputError
        Naming `field` and the broken rule.
    """
    known = sorted(allowed)
    known_text = ", ".join(known)
    if not isinstance(value, str):
        raise LavenderInputError(
            field, "expected a name (str)", f", got {_describe(value)}; known: {known_text}"
        )
    if value not in known:
        close = difflib.get_close_matches(value, known, n=1)
        hint = f" (did you mean {close[0]!r}?)" if close else ""
        raise LavenderInputError(field, f"unknown name {value!r}", f"; known: {known_text}{hint}")
    return str(value)


# --------------------------------------------------------------------------
# orientation and inertia
# --------------------------------------------------------------------------


def quaternion(field: str, value: ArrayLike) -> np.ndarray:
    """Validate an orientation quaternion ``(x, y, z, w)``, scalar last.

    Rejects wrong shape, non-finite entries and zero (norm < 1e-300). A nonzero
    quaternion that is not of unit length is normalized; the unit quaternion is
    returned (``q`` and ``-q`` are kept as given).

    Parameters
    ----------
    field : str
        The name an error message gives the value (e.g. ``"omega_b"``, ``"scene.bodies"``).
    value : array_like, shape (4,)
        The quaternion (x, y, z, w).

    Returns
    -------
    ndarray, shape (4,)
        Unit quaternion.

    Raises
    ------
    LavenderInputError
        Naming `field` and the broken rule.
    """
    from .kernels import K   # (on first use: importing validate loads no generated module)

    # the printed scaled normalization (derive/measures.py): no overflow for huge entries, no underflow for tiny
    # ones; the true norm is only compared, never divided by (it may overflow to inf for 1e308 entries)
    with np.errstate(over="ignore"):
        q_unit, norm = K.quat_normalize_scaled(array(field, value, (4,)))
    if not norm >= QUATERNION_MIN_NORM:
        raise LavenderInputError(field, f"zero quaternion (norm {float(norm):g}) cannot be normalized")
    return q_unit


def _check_moments(field: str, m: np.ndarray) -> None:
    """Principal moments: all > 0, each <= sum of the other two (rel. tol.)."""
    if not np.all(m > 0):
        raise LavenderInputError(field, "principal moments must be > 0", f" (got {_nums(m)})")
    u = m / float(np.max(m))  # relative to the largest: no overflow of I_i + I_j near 1e308
    for k in range(3):
        i, j = [a for a in range(3) if a != k]
        if u[k] - (u[i] + u[j]) > TRIANGLE_RTOL:
            raise LavenderInputError(
                field,
                f"principal moments violate the triangle inequality I{i + 1} + I{j + 1} >= I{k + 1}",
                f" (got {_nums(m)})",
            )


def _eigh(field: str, sym: np.ndarray, scale: float, vectors: bool = False):
    """eigvalsh / eigh of a finite symmetric tensor without overflow: tensors with max|I| outside
    [1e-100, 1e100] are solved scaled to max|I| = 1 (others exactly as numpy computes them).
    A result that is not finite (eigenvalues beyond the float64 range) is rejected naming `field`."""
    moderate = scale == 0 or 1e-100 <= scale <= 1e100
    try:
        a = sym if moderate else sym / scale
        eig, vecs = np.linalg.eigh(a) if vectors else (np.linalg.eigvalsh(a), None)
    except np.linalg.LinAlgError as exc:  # not expected for a finite symmetric input; never leak it
        raise LavenderInputError(field, "inertia tensor: eigenvalues could not be computed", f" ({exc})") from None
    if not moderate:
        with np.errstate(over="ignore"):
            eig = eig * scale
    if not np.all(np.isfinite(eig)):
        raise LavenderInputError(field, f"inertia tensor entries too large (max |I| = {scale:g}): its "
                                 "eigenvalues overflow a float64")
    return (eig, vecs) if vectors else eig


def _checked_tensor(field: str, t: np.ndarray) -> tuple[np.ndarray, np.ndarray, float]:
    """Finite (already checked), symmetric and positive definite.

    Returns the symmetrized tensor, its eigenvalues (ascending) and max|I|. No intermediate
    overflows for entries near the float64 limit (halves are summed; differences are scaled).
    """
    scale = float(np.max(np.abs(t)))
    u = t / scale if scale > 0 else t
    asym = float(np.max(np.abs(u - u.T))) * scale
    if asym > SYMMETRY_RTOL * scale:
        raise LavenderInputError(
            field, "inertia tensor must be symmetric", f" (max |I - I^T| = {asym:g}, max |I| = {scale:g})"
        )
    sym = 0.5 * t + 0.5 * t.T  # == 0.5 * (t + t.T) bitwise, without overflow
    eig = _eigh(field, sym, scale)
    if not np.all(eig > 0):
        raise LavenderInputError(
            field, "inertia tensor must be positive definite", f" (eigenvalues {_nums(eig)})"
        )
    return sym, eig, scale


def inertia(field: str, value: ArrayLike) -> np.ndarray:
    """Validate body-frame inertia (kg*m^2); return principal moments, shape (3,).

    Accepts 3 principal moments or a 3x3 tensor. A tensor must be finite,
    symmetric, positive definite and diagonal (off-diagonals <= 1e-12 max|I|).
    Moments must be > 0 and satisfy the triangle inequality (each <= sum of the
    other two, relative tolerance 1e-12); equality (a flat plate) is valid.

    Parameters
    ----------
    field : str
        The name an error message gives the value (e.g. ``"omega_b"``, ``"scene.bodies"``).
    value : array_like, shape (3,) or (3, 3)
        Principal moments or a diagonal tensor about the COM, body frame, kg·m².

    Returns
    -------
    ndarray, shape (3,)
        Principal moments, kg·m².

    Raises
    ------
    LavenderInputError
        Naming `field` and the broken rule.
    """
    arr = _real_array(field, value)
    if arr.shape == (3,):
        _check_finite(field, arr)
        _check_moments(field, arr)
        return arr
    if arr.shape != (3, 3):
        raise LavenderInputError(
            field, "expected shape (3,) principal moments or (3, 3) tensor", f", got {arr.shape}"
        )
    _check_finite(field, arr)
    sym, eig, scale = _checked_tensor(field, arr)
    off = float(np.max(np.abs(sym - np.diag(np.diag(sym)))))
    if off > DIAGONAL_RTOL * scale:
        _check_moments(field, eig)  # a physically impossible tensor says so first
        raise LavenderInputError(field, _DIAGONAL_RULE, f" (max off-diagonal {off:g})")
    moments = np.array(np.diag(sym), dtype=np.float64, copy=True)
    _check_moments(field, moments)
    return moments


def principal_axes(I: ArrayLike, *, field: str = "inertia") -> tuple[np.ndarray, np.ndarray]:
    """Principal moments and axes of a symmetric positive definite 3x3 inertia.

    Returns ``(moments, R)``: moments (kg*m^2) sorted ascending, and ``R`` a
    proper rotation (det +1) whose columns are the principal axes, so that
    ``I == R @ diag(moments) @ R.T``. Validates like :func:`inertia` except
    that ``I`` need not be diagonal.

    Parameters
    ----------
    I : array_like, shape (3, 3)
        Inertia tensor about the COM in some body frame, kg·m².
    field : str, optional
        The name an error gives it.

    Returns
    -------
    moments : ndarray, shape (3,)
    R : ndarray, shape (3, 3)

    Raises
    ------
    LavenderInputError
        Naming `field` and the broken rule.
    """
    t = array(field, I, (3, 3))
    sym, _, scale = _checked_tensor(field, t)
    moments, vecs = _eigh(field, sym, scale, vectors=True)
    _check_moments(field, moments)
    # deterministic signs: largest component of the first two axes positive, and the third axis
    # signed so that det R = +1 (a proper rotation; eigh's columns are orthonormal)
    cols = []
    for c in range(2):
        v = vecs[:, c]
        if v[int(np.argmax(np.abs(v)))] < 0:
            v = -v
        cols.append(v)
    cols.append(vecs[:, 2])
    R = np.column_stack(cols)
    if np.linalg.det(R) < 0:
        R[:, 2] = -R[:, 2]
    R = np.ascontiguousarray(R, dtype=np.float64)
    return np.array(moments, dtype=np.float64, copy=True), R


def _nearest_proper_frame(vecs: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The column order and signs of orthonormal eigenvectors closest to the identity: the permutation
    maximizing |trace|, each column signed to a positive diagonal, then det +1 by flipping the column
    with the smallest diagonal. Returns (order (3,), R (3, 3))."""
    import itertools

    best = max(itertools.permutations(range(3)), key=lambda p: sum(abs(vecs[i, p[i]]) for i in range(3)))
    R = vecs[:, list(best)].copy()
    for c in range(3):
        if R[c, c] < 0:
            R[:, c] = -R[:, c]
    if np.linalg.det(R) < 0:
        k = int(np.argmin(np.abs(np.diag(R))))
        R[:, k] = -R[:, k]
    return np.array(best), R


def inertia_frame(field: str, value: ArrayLike) -> tuple[np.ndarray, np.ndarray]:
    """Validate a body-frame inertia about the COM; return its principal moments and axes.

    Accepts 3 principal moments, a diagonal (3, 3) tensor, or any symmetric positive definite (3, 3)
    tensor whose principal moments satisfy the triangle inequality. For moments or a diagonal tensor
    (off-diagonals <= 1e-12 max|I|) the body frame is principal: ``R_bp`` is the identity and the
    moments keep their order. Otherwise the principal axes are ordered and signed to lie closest to
    the body axes (``R_bp`` near the identity, det +1).

    Parameters
    ----------
    field : str
        The name an error message gives the value.
    value : array_like, shape (3,) or (3, 3)
        Principal moments or a tensor about the COM, body frame, kg·m².

    Returns
    -------
    I_p : ndarray, shape (3,)
        Principal moments, kg·m².
    R_bp : ndarray, shape (3, 3)
        Proper rotation whose columns are the principal axes in the body frame:
        ``I_b = R_bp @ diag(I_p) @ R_bp.T``.

    Raises
    ------
    LavenderInputError
        Naming `field` and the broken rule (shape, finite, symmetric, positive definite, triangle).
    """
    arr = _real_array(field, value)
    if arr.shape == (3, 3):
        _check_finite(field, arr)
        sym, eig, scale = _checked_tensor(field, arr)
        off = float(np.max(np.abs(sym - np.diag(np.diag(sym)))))
        if off > DIAGONAL_RTOL * scale:
            _check_moments(field, eig)
            moments, vecs = _eigh(field, sym, scale, vectors=True)
            order, R = _nearest_proper_frame(vecs)
            return np.array(moments[order], dtype=np.float64), np.ascontiguousarray(R, dtype=np.float64)
    return inertia(field, value), np.eye(3)


# --------------------------------------------------------------------------
# magnitudes and keyword arguments
# --------------------------------------------------------------------------


def safe_norm(a: ArrayLike) -> float:
    """Euclidean norm without intermediate overflow or underflow (scaled by max|a|).

    Returns inf only when the norm itself exceeds the largest float64.

    Parameters
    ----------
    a : array_like
        Any shape (flattened).

    Returns
    -------
    float
    """
    a = np.asarray(a, dtype=np.float64).ravel()
    scale = float(np.max(np.abs(a), initial=0.0))
    if not scale > 0 or not np.isfinite(scale):
        return scale
    with np.errstate(over="ignore"):
        return float(scale * np.sqrt(np.sum((a / scale) ** 2)))


_P = ParamSpec("_P")
_R = TypeVar("_R")


def keywords(fn: Callable[_P, _R]) -> Callable[_P, _R]:
    """Decorator: a call with an unknown keyword, a missing argument or too many positional
    arguments raises :class:`LavenderInputError` naming it (and the accepted names), not a
    ``TypeError``. Functions that take ``**kwargs`` check those themselves.

    Parameters
    ----------
    fn : callable
        The function or method to wrap.

    Returns
    -------
    callable
        With ``fn``'s signature, for type checkers too (``ParamSpec``).
    """
    sig = inspect.signature(fn)
    params = sig.parameters
    takes_var_kw = any(p.kind is p.VAR_KEYWORD for p in params.values())
    named = [n for n, p in params.items() if p.kind in (p.POSITIONAL_OR_KEYWORD, p.KEYWORD_ONLY) and n not in ("self", "cls")]
    where = fn.__qualname__.replace(".__init__", "")

    @functools.wraps(fn)
    def wrapper(*args: _P.args, **kwargs: _P.kwargs) -> _R:
        try:
            sig.bind(*args, **kwargs)
        except TypeError as exc:
            if not takes_var_kw:
                unknown = sorted(k for k in kwargs if k not in params or params[k].kind is params[k].POSITIONAL_ONLY)
                if unknown:
                    close = difflib.get_close_matches(unknown[0], named, n=1)
                    hint = f" (did you mean {close[0]!r}?)" if close else ""
                    raise LavenderInputError(unknown[0], f"unknown keyword argument of {where}{hint}",
                                             f"; known: {', '.join(named)}") from None
            missing = [n for n, p in params.items() if p.default is p.empty
                       and p.kind not in (p.VAR_POSITIONAL, p.VAR_KEYWORD) and n not in kwargs]
            text = str(exc)
            field = next((n for n in missing if repr(n) in text), where)
            raise LavenderInputError(field, f"{where}: {text}") from None
        return fn(*args, **kwargs)

    wrapper.__signature__ = sig  # type: ignore[attr-defined]
    return wrapper


def writable_dir(field: str, path: str | os.PathLike[str]) -> Path:
    """Create directory `path` (and parents) if needed and check that a file can be written in it;
    LavenderInputError naming `field` otherwise (a path through a file, no permission, read-only).

    Parameters
    ----------
    field : str
        The name an error message gives the value (e.g. ``"omega_b"``, ``"scene.bodies"``).
    path : str or os.PathLike
        The directory.

    Returns
    -------
    pathlib.Path

    Raises
    ------
    LavenderInputError
        Naming `field` and the broken rule.
    """
    import tempfile

    if not isinstance(path, (str, os.PathLike)) or not str(path):
        raise LavenderInputError(field, "expected a directory path", f", got {_describe(path)}")
    d = Path(path)
    for parent in (d, *d.parents):
        if parent.exists() and not parent.is_dir():
            raise LavenderInputError(field, f"cannot write to {d}", f" ({parent} is a file, not a directory)")
    try:
        d.mkdir(parents=True, exist_ok=True)
        fd, probe = tempfile.mkstemp(dir=d, prefix=".write-test-")
        os.close(fd)
        os.unlink(probe)
    except OSError as exc:
        raise LavenderInputError(field, f"cannot write to {d}", f" ({exc.strerror or exc})") from None
    return d


def writable_file(field: str, path: str | os.PathLike[str]) -> Path:
    """Check that file `path` can be written (its directory is created if needed, as the writer would);
    LavenderInputError naming `field` otherwise (a directory, a path through a file, no permission).

    Parameters
    ----------
    field : str
        The name an error message gives the value (e.g. ``"omega_b"``, ``"scene.bodies"``).
    path : str or os.PathLike
        The file.

    Returns
    -------
    pathlib.Path

    Raises
    ------
    LavenderInputError
        Naming `field` and the broken rule.
    """
    if not isinstance(path, (str, os.PathLike)) or not str(path):
        raise LavenderInputError(field, "expected a file path", f", got {_describe(path)}")
    p = Path(path)
    if p.is_dir():
        raise LavenderInputError(field, f"cannot write to {p}", " (it is a directory)")
    writable_dir(field, p.parent if str(p.parent) else ".")
    if p.exists() and not os.access(p, os.W_OK):
        raise LavenderInputError(field, f"cannot write to {p}", " (permission denied)")
    return p


WHEEL_UNIT_TOL = 1e-9   # |‖a_i‖ − 1| allowed for a wheel axis


def wheel_axes(field_name: str, A_b: ArrayLike, *, span: bool = False) -> np.ndarray:
    """Check a wheel axis matrix: (3, N) with N ≥ 1, finite, unit columns; ``span``: rank 3 (every
    body axis reachable — needed for attitude control).

    Parameters
    ----------
    field_name : str
        The name used in the error message.
    A_b : array_like (3, N)
        Wheel spin axes as columns, body frame (a single (3,) axis is one wheel).
    span : bool, default False
        Also require the columns to span 3-D space.

    Returns
    -------
    ndarray (3, N)

    Raises
    ------
    lavendersim.validate.LavenderInputError
        Naming ``field_name`` and the rule broken.
    """
    A = array(field_name, A_b, (3, None)) if np.ndim(A_b) != 1 else vector(field_name, A_b)[:, None]
    if A.shape[1] < 1:
        raise LavenderInputError(field_name, "needs at least one wheel axis (shape (3, N), N ≥ 1)")
    norms = np.linalg.norm(A, axis=0)
    bad = np.flatnonzero(np.abs(norms - 1.0) > WHEEL_UNIT_TOL)
    if bad.size:
        raise LavenderInputError(field_name, "each wheel axis (column) must be a unit vector",
                                   f", column {int(bad[0])} has norm {norms[bad[0]]:.6g}")
    if span and np.linalg.matrix_rank(A, tol=1e-9) < 3:
        raise LavenderInputError(field_name, "the wheel axes must span 3-D space (rank 3) for attitude control",
                                   f", rank {np.linalg.matrix_rank(A, tol=1e-9)} with {A.shape[1]} wheel(s)")
    return A
