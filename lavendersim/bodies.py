"""Rigid bodies: mass, inertia, shape, and an initial state.

Body frame at the centre of mass, in the user's axes: the inertia may be any symmetric positive definite
tensor there. Its principal axes are a constant rotation R_bp of the body (identity when the tensor is
diagonal); the Sim steps the principal frame and converts at every public boundary. Units: kg, m, kg·m², m/s, rad/s.
Orientation q = R_WB as (x, y, z, w). The state vector layout is declared in derive/layout.py and
printed as lavendersim.generated.layout: x = [p_w(3), q(4), v_w(3), omega_b(3)].
"""
from __future__ import annotations

from typing import Any

import numpy as np
from numpy.typing import ArrayLike

from . import validate as V
from .generated.layout import STATE_OMEGA_B as W, STATE_P_W as P, STATE_Q as Q, STATE_SIZE, STATE_V_W as VEL  # noqa: F401
from .kernels import K


# shape kind -> (number of dimensions, their names) of Body(shape=(kind, dims)); all in m, > 0
SHAPES = {"box": (3, "side lengths (w, h, d) along body x, y, z"), "cylinder": (2, "(radius, height), along body z"),
          "sphere": (1, "(radius,)")}
_FIELDS = ("name", "mass", "I_b", "shape", "x0", "R_bp", "_tensor")


class ImmutableBodyError(V.LavenderInputError, AttributeError):
    """Assignment to an attribute of a validated Body (a LavenderInputError and an AttributeError).

    Parameters
    ----------
    field : str
        ``body.<attribute>``.
    rule : str
        Why it is refused.
    detail : str, optional
    """


def _shape(value) -> tuple[str, tuple[float, ...]] | None:
    """Validate shape=(kind, dims): kind in SHAPES, dims positive finite lengths of the kind's count."""
    if value is None:
        return None
    if isinstance(value, (str, bytes)) or not isinstance(value, (tuple, list)) or len(value) != 2:
        raise V.LavenderInputError("shape", "expected None or (kind, dims), kind one of " + ", ".join(SHAPES),
                                   f", got {V._describe(value)}")
    kind = V.choice("shape[0]", value[0], SHAPES)
    n, what = SHAPES[kind]
    dims = V.vector("shape[1]", value[1], n) if n > 1 or not isinstance(value[1], (int, float)) \
        else V.vector("shape[1]", (value[1],), 1)
    for i, d in enumerate(dims):
        if not d > 0:
            raise V.LavenderInputError(f"shape[1][{i}]", f"{kind} dimensions {what} must be > 0 m", f", got {float(d)!r}")
    return kind, tuple(float(d) for d in dims)


class Body:
    """A rigid body with its inertia about the COM (any symmetric positive definite tensor in the body
    frame) and its initial state.

    Give at most one of omega_b (body frame) and omega_w (world frame); the other follows from q.
    A Body is immutable once validated: assigning an attribute raises :class:`ImmutableBodyError`
    (a LavenderInputError naming the field) and its arrays are read-only — build a new Body instead.

    Parameters
    ----------
    name : str
        Non-empty name, unique within a Scene.
    mass : float
        kg, finite and > 0.
    inertia : array_like
        Principal moments (3,) or a symmetric positive definite (3, 3) tensor about the COM, body
        frame, kg·m² (principal moments > 0 with the triangle inequality). A full tensor (from CAD, say;
        see :func:`inertia_about_com` for one given about another point) keeps every public quantity in
        this body frame: q, omega_b, effect parameters such as r_b and axes_b, states and records.

    p_w, q, v_w, omega_b, omega_w : array_like
        Initial COM position (m, world), orientation R_WB (x, y, z, w; normalized), COM velocity
        (m/s, world), angular velocity (rad/s, body or world frame).
    shape : tuple, optional
        ``(kind, dims)`` drawn by the viewer: ``("box", (w, h, d))``, ``("cylinder", (r, h))`` or
        ``("sphere", (r,))``, lengths in m, > 0. None: drawn as the inertia-equivalent box.

    Notes
    -----
    ``I_b`` (3,) holds the principal moments, kg·m² (for a diagonal tensor: its diagonal, in order);
    ``R_bp`` (3, 3) the principal axes as columns in the body frame (identity for a diagonal tensor; a
    proper rotation); ``inertia_b`` (3, 3) the tensor in the body frame as given.
    """

    __slots__ = _FIELDS
    name: str
    mass: float
    I_b: np.ndarray                                   # (3,) kg·m², read-only
    shape: tuple[str, tuple[float, ...]] | None
    x0: np.ndarray                                    # (13,) the initial state, read-only
    R_bp: np.ndarray                                  # (3, 3), read-only
    _tensor: np.ndarray | None                        # (3, 3) as given, None for a principal body

    @V.keywords
    def __init__(self, name: str, mass: float, inertia: ArrayLike, *, p_w: ArrayLike = (0, 0, 0),
                 q: ArrayLike = (0, 0, 0, 1), v_w: ArrayLike = (0, 0, 0), omega_b: ArrayLike | None = None,
                 omega_w: ArrayLike | None = None, shape: tuple[str, tuple[float, ...]] | None = None) -> None:
        if not isinstance(name, str) or not name:
            raise V.LavenderInputError("name", "must be a non-empty string", f", got {V._describe(name)}")
        mass = V.positive("mass", mass)
        I_b, R_bp = V.inertia_frame("inertia", inertia)
        tensor = None
        if not np.array_equal(R_bp, np.eye(3)):   # one rotation everywhere: the matrix of its unit quaternion
            R_bp = K.quat_to_matrix(K.quat_normalize(K.matrix_to_quat(R_bp)))
            t = np.asarray(inertia, dtype=np.float64)
            tensor = 0.5 * t + 0.5 * t.T           # as given (symmetrized): saved and shown as the user wrote it
            tensor.flags.writeable = False
        x = np.empty(STATE_SIZE)
        x[P] = V.vector("p_w", p_w)
        x[Q] = V.quaternion("q", q)
        x[VEL] = V.vector("v_w", v_w)
        if omega_b is not None and omega_w is not None:
            raise V.LavenderInputError("omega_w", "give omega_b or omega_w, not both")
        if omega_w is not None:
            with np.errstate(over="ignore", invalid="ignore"):
                x[W] = K.world_to_body(x[Q], V.vector("omega_w", omega_w))
            if not np.all(np.isfinite(x[W])):
                raise V.LavenderInputError("omega_w", "its body-frame value overflows a float64",
                                           f", got {V._nums(np.asarray(omega_w, dtype=float))}")
        else:
            x[W] = V.vector("omega_b", (0, 0, 0) if omega_b is None else omega_b)
        shape = _shape(shape)
        I_b.flags.writeable = False
        x.flags.writeable = False
        R_bp = np.ascontiguousarray(R_bp, dtype=np.float64)
        R_bp.flags.writeable = False
        for f, v in zip(_FIELDS, (name, mass, I_b, shape, x, R_bp, tensor)):
            object.__setattr__(self, f, v)

    def __setattr__(self, field: str, value: Any) -> None:
        raise ImmutableBodyError(f"body.{field}", "a Body is immutable once validated: build a new Body "
                                 "(its arrays are read-only too)")

    def __delattr__(self, field: str) -> None:
        raise ImmutableBodyError(f"body.{field}", "a Body is immutable once validated: build a new Body")

    def __copy__(self) -> Body:
        return self

    def __deepcopy__(self, memo) -> Body:
        return self

    def __reduce__(self):
        return (_rebuild, tuple(getattr(self, f) for f in _FIELDS))

    @staticmethod
    def _no_shape(state: dict) -> None:
        if "shape" in state:
            raise V.LavenderInputError("shape", "is set by Body.box / cylinder / sphere; use Body(...) to give one")

    @classmethod
    @V.keywords
    def box(cls, name: str, mass: float, size: ArrayLike, **state: Any) -> Body:
        """Solid box with full side lengths size = (w, h, d) along body x, y, z (m).

        ``I_b = m/12 (h² + d², w² + d², w² + h²)`` (printed from derive/inertia.py).

        Parameters
        ----------
        name : str
            Non-empty name, unique within a Scene.
        mass : float
            kg, > 0.
        size : array_like, shape (3,)
            Full side lengths (w, h, d) along body x, y, z, m, > 0.
        **state
            Initial state keywords of :class:`Body` (``p_w``, ``q``, ``v_w``, ``omega_b`` or ``omega_w``).

        Returns
        -------
        Body

        Raises
        ------
        LavenderInputError
            On a non-positive mass or dimension, or a bad state keyword (named in the message).

        Examples
        --------
        >>> import lavendersim as lv
        >>> lv.Body.box("cube", mass=1.0, size=(0.1, 0.1, 0.1)).I_b
        array([0.00166667, 0.00166667, 0.00166667])
        """
        cls._no_shape(state)
        w, h, d = (V.positive(f"size[{i}]", s) for i, s in enumerate(V.vector("size", size)))
        return cls(name, mass, K.inertia_box(V.positive("mass", mass), w, h, d), shape=("box", (w, h, d)), **state)

    @classmethod
    @V.keywords
    def cylinder(cls, name: str, mass: float, radius: float, height: float, **state: Any) -> Body:
        """Solid cylinder with its axis along body z.

        Parameters
        ----------
        name : str
            Non-empty name, unique within a Scene.
        mass : float
            kg, > 0.
        radius, height : float
            m, > 0.
        **state
            Initial state keywords of :class:`Body` (``p_w``, ``q``, ``v_w``, ``omega_b`` or ``omega_w``).

        Returns
        -------
        Body

        Raises
        ------
        LavenderInputError
            On a non-positive mass or dimension, or a bad state keyword (named in the message).
        """
        cls._no_shape(state)
        r, h = V.positive("radius", radius), V.positive("height", height)
        return cls(name, mass, K.inertia_cylinder(V.positive("mass", mass), r, h), shape=("cylinder", (r, h)), **state)

    @classmethod
    @V.keywords
    def sphere(cls, name: str, mass: float, radius: float, **state: Any) -> Body:
        """Solid sphere of the given radius.

        Parameters
        ----------
        name : str
            Non-empty name, unique within a Scene.
        mass : float
            kg, > 0.
        radius : float
            m, > 0.
        **state
            Initial state keywords of :class:`Body` (``p_w``, ``q``, ``v_w``, ``omega_b`` or ``omega_w``).

        Returns
        -------
        Body

        Raises
        ------
        LavenderInputError
            On a non-positive mass or dimension, or a bad state keyword (named in the message).
        """
        cls._no_shape(state)
        r = V.positive("radius", radius)
        return cls(name, mass, K.inertia_sphere(V.positive("mass", mass), r), shape=("sphere", (r,)), **state)

    @property
    def principal(self) -> bool:
        """Whether the body frame is principal (R_bp is the identity)."""
        return bool(np.array_equal(self.R_bp, np.eye(3)))

    @property
    def inertia_b(self) -> np.ndarray:
        """The inertia tensor about the COM, body frame, kg·m², (3, 3): as given (symmetrized), equal to
        ``R_bp diag(I_b) R_bpᵀ`` to rounding; ``diag(I_b)`` for a principal body."""
        return np.diag(self.I_b) if self._tensor is None else self._tensor.copy()

    @property
    def params(self) -> np.ndarray:
        """[m, I_x, I_y, I_z], the per-body parameter row the backends take."""
        return np.concatenate(([self.mass], self.I_b))

    def __repr__(self) -> str:
        if self.principal:
            return f"Body({self.name!r}, mass={self.mass:g}, I_b={np.array2string(self.I_b, precision=6)})"
        I = " ".join(np.array2string(self.inertia_b, precision=6, separator=", ").split())
        return f"Body({self.name!r}, mass={self.mass:g}, inertia_b={I})"


def inertia_about_com(I_o: ArrayLike, mass: float, com: ArrayLike) -> np.ndarray:
    """Move CAD mass properties to the centre of mass: the inertia about the COM from the inertia about a
    reference point O (the parallel-axis theorem read backwards, printed from derive/inertia.py).

    ``I_C = I_O − m (|c|² 1 − c cᵀ)``, c the COM relative to O.

    Parameters
    ----------
    I_o : array_like, shape (3, 3)
        Inertia about the reference point O, body frame, kg·m² (symmetric; as CAD reports it, with
        the products of inertia carrying their sign convention ``I_xy = −∫ x y dm``).
    mass : float
        kg, finite and > 0.
    com : array_like, shape (3,)
        The COM relative to O, body frame, m.

    Returns
    -------
    ndarray, shape (3, 3)
        Inertia about the COM, body frame, kg·m²: what :class:`Body` takes. It is validated as Body
        validates it (symmetric, positive definite, triangle inequality of its principal moments).

    Raises
    ------
    LavenderInputError
        Naming ``I_o``, ``mass`` or ``com``; ``I_o`` when the result is not a physical inertia (the COM
        offset is inconsistent with I_o).

    Examples
    --------
    >>> import numpy as np, lavendersim as lv
    >>> I_o = np.diag([0.02, 0.02, 0.01]) + 2.0 * (0.01 * np.eye(3) - np.outer([0, 0, 0.1], [0, 0, 0.1]))
    >>> np.round(lv.inertia_about_com(I_o, 2.0, [0, 0, 0.1]), 12).diagonal()
    array([0.02, 0.02, 0.01])
    """
    I_o = V.array("I_o", I_o, (3, 3))
    m = V.positive("mass", mass)
    c = V.vector("com", com)
    with np.errstate(over="ignore", invalid="ignore"):
        I_c = K.inertia_about_com(I_o, m, c)
    V.inertia_frame("I_o", I_c)   # the COM inertia must be a physical one
    return I_c


def _rebuild(name, mass, I_b, shape, x0, R_bp=None, tensor=None) -> Body:
    """Unpickle a Body without re-running validation twice (its fields were validated)."""
    b = object.__new__(Body)
    R_bp = np.eye(3) if R_bp is None else R_bp
    tensor = None if tensor is None else np.array(tensor)
    for f, v in zip(_FIELDS, (name, mass, np.array(I_b), shape, np.array(x0), np.array(R_bp), tensor)):
        if isinstance(v, np.ndarray):
            v.flags.writeable = False
        object.__setattr__(b, f, v)
    return b


class BodyState:
    """A view of one body's state (or trajectory: leading time axis) with derived quantities.

    Parameters
    ----------
    x : ndarray, shape (..., 13)
        ``[p_w(3), q(4), v_w(3), omega_b(3)]`` (layout printed in lavendersim.generated.layout);
        a leading axis (samples of a Trajectory) is kept by every property.
    Omega : ndarray, shape (..., N), optional
        Rates of the body's N reaction wheels relative to it (rad/s); three zeros for a body without
        reaction wheels.
    """

    def __init__(self, x: np.ndarray, Omega: np.ndarray | None = None) -> None:
        self.x = x
        self.Omega = np.zeros(x.shape[:-1] + (3,)) if Omega is None else Omega

    @classmethod
    def of_slots(cls, x: np.ndarray, Omega_slots: np.ndarray, n_wheels: int) -> "BodyState":
        """A state from a Sim's wheel slots (WHEELS_MAX, last axis): the body's N wheel rates, or three zeros
        without wheels (as a body without wheels always showed).

        Parameters
        ----------
        x : ndarray, shape (..., 13)
            The body state(s).
        Omega_slots : ndarray, shape (..., WHEELS_MAX)
            The body's wheel slots, rad/s.
        n_wheels : int
            Its wheels (0 without).

        Returns
        -------
        BodyState
        """
        return cls(x, Omega_slots[..., :n_wheels] if n_wheels else np.zeros(x.shape[:-1] + (3,)))

    @property
    def p_w(self) -> np.ndarray:
        """COM position, world, m"""
        return self.x[..., P]

    @property
    def q(self) -> np.ndarray:
        """orientation R_WB (x, y, z, w)"""
        return self.x[..., Q]

    @property
    def v_w(self) -> np.ndarray:
        """COM velocity, world, m/s"""
        return self.x[..., VEL]

    @property
    def omega_b(self) -> np.ndarray:
        """angular velocity, body frame, rad/s"""
        return self.x[..., W]

    @property
    def omega_w(self) -> np.ndarray:
        """Angular velocity, world frame, rad/s."""
        return K.quat_rotate(self.q, self.omega_b)

    @property
    def R_wb(self) -> np.ndarray:
        """Rotation matrix, shape (..., 3, 3), mapping body to world coordinates."""
        return K.quat_to_matrix(self.q)
