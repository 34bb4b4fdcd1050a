"""Input validation shared by every public entry point of LavenderSim.

Every check raises :class:`LavenderInputError` (a ``ValueError``) naming the
offending field; none uses ``assert`` (which ``python -O`` strips). Inputs are
never mutated, and array results are fresh C-contiguous float64 copies.

Conventions (README.md, "Conventions"): SI units; quaternions are ``(x, y, z, w)``, scalar
last; inertia is in kg*m^2, given in the body frame.
"""

from __future__ import annotations

import difflib
import numbers
from collections.abc import Iterable, Sequence
from typing import SupportsFloat

import numpy as np
from numpy.typing import ArrayLike

__all__ = [
    "LavenderInputError",
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
]

# Relative tolerances, scaled by max|I| (inertia) or by the largest moment.
SYMMETRY_RTOL = 1e-12
DIAGONAL_RTOL = 1e-12
TRIANGLE_RTOL = 1e-12
# A quaternion whose norm is below this cannot be normalized meaningfully.
QUATERNION_MIN_NORM = 1e-300

_DIAGONAL_RULE = (
    "must be diagonal in the body frame: rotate the body to principal axes "
    "(lavendersim.validate.principal_axes gives them)"
)


class LavenderInputError(ValueError):
    """Invalid input to a LavenderSim entry point.

    Attributes: ``field`` (the parameter's name) and ``rule`` (the rule that
    was broken). The message is ``f"{field}: {rule}"`` followed by a summary of
    the offending value.
    """

    def __init__(self, field: str, rule: str, detail: str = "") -> None:
        self.field = field
        self.rule = rule
        self.detail = detail
        super().__init__(f"{field}: {rule}{detail}")

    def __reduce__(self):  # keep picklable (multiprocessing, etc.)
        return (type(self), (self.field, self.rule, self.detail))


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
                out[idx] = np.inf if item > 0 else -np.inf
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
    """
    shape = tuple(shape)
    arr = _real_array(field, value)
    ok = arr.ndim == len(shape) and all(s is None or s == d for s, d in zip(shape, arr.shape))
    if not ok:
        raise LavenderInputError(field, f"expected shape {_shape_text(shape)}", f", got {arr.shape}")
    _check_finite(field, arr)
    return arr


def vector(field: str, value: ArrayLike, n: int = 3) -> np.ndarray:
    """Validate a finite real vector of shape ``(n,)``; return a float64 copy."""
    return array(field, value, (n,))


# --------------------------------------------------------------------------
# scalars
# --------------------------------------------------------------------------


def scalar(field: str, value: SupportsFloat, *, positive: bool = False, nonnegative: bool = False) -> float:
    """Validate a finite real number (bools rejected); return it as a float.

    ``positive=True`` requires > 0; ``nonnegative=True`` requires >= 0.
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
            x = np.inf if value > 0 else -np.inf
    else:
        raise LavenderInputError(field, "expected a real number", f", got {_describe(value)}")
    if not np.isfinite(x) or (positive and not x > 0) or (nonnegative and not x >= 0):
        raise LavenderInputError(field, rule, f", got {x!r}")
    return x


def positive(field: str, value: SupportsFloat) -> float:
    """Shorthand for ``scalar(field, value, positive=True)`` (e.g. mass in kg)."""
    return scalar(field, value, positive=True)


def dt(field: str, value: SupportsFloat) -> float:
    """Validate a time step in seconds: finite and > 0."""
    return scalar(field, value, positive=True)


def integer(field: str, value: int | np.integer, *, minimum: int | None = None) -> int:
    """Validate a Python or NumPy integer (not bool, not float), optionally >= minimum."""
    if isinstance(value, (bool, np.bool_)) or not isinstance(value, (int, np.integer)):
        raise LavenderInputError(field, "expected an integer", f", got {_describe(value)}")
    n = int(value)
    if minimum is not None and n < minimum:
        raise LavenderInputError(field, f"must be an integer >= {minimum}", f", got {n}")
    return n


def choice(field: str, value: str, allowed: Iterable[str]) -> str:
    """Validate that ``value`` is one of the ``allowed`` names; return it."""
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
    """
    q = array(field, value, (4,))
    scale = float(np.max(np.abs(q)))
    # scaled norm: no overflow for huge entries, no underflow for tiny ones
    norm = scale * float(np.sqrt(np.sum((q / scale) ** 2))) if scale > 0 else 0.0
    if not norm >= QUATERNION_MIN_NORM:
        raise LavenderInputError(field, f"zero quaternion (norm {norm:g}) cannot be normalized")
    return (q / scale) / (norm / scale)


def _check_moments(field: str, m: np.ndarray) -> None:
    """Principal moments: all > 0, each <= sum of the other two (rel. tol.)."""
    if not np.all(m > 0):
        raise LavenderInputError(field, "principal moments must be > 0", f" (got {_nums(m)})")
    tol = TRIANGLE_RTOL * float(np.max(m))
    for k in range(3):
        i, j = [a for a in range(3) if a != k]
        if m[k] - (m[i] + m[j]) > tol:
            raise LavenderInputError(
                field,
                f"principal moments violate the triangle inequality I{i + 1} + I{j + 1} >= I{k + 1}",
                f" (got {_nums(m)})",
            )


def _checked_tensor(field: str, t: np.ndarray) -> tuple[np.ndarray, np.ndarray, float]:
    """Finite (already checked), symmetric and positive definite.

    Returns the symmetrized tensor, its eigenvalues (ascending) and max|I|.
    """
    scale = float(np.max(np.abs(t)))
    asym = float(np.max(np.abs(t - t.T)))
    if asym > SYMMETRY_RTOL * scale:
        raise LavenderInputError(
            field, "inertia tensor must be symmetric", f" (max |I - I^T| = {asym:g}, max |I| = {scale:g})"
        )
    sym = 0.5 * (t + t.T)
    eig = np.linalg.eigvalsh(sym)
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
    """
    t = array(field, I, (3, 3))
    sym, _, _ = _checked_tensor(field, t)
    moments, vecs = np.linalg.eigh(sym)
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
