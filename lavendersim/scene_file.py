"""A Scene as a TOML file (and as the plain dict that TOML reads into): save, load, check.

The format (``scene_format = 1``), every length in m, mass in kg, inertia in kg·m², angles as unit
quaternions (x, y, z, w), frames by suffix (``_w`` world, ``_b`` the user's body frame)::

    scene_format = 1                      # optional on load; written by save

    [[body]]                              # one table per body ([body] for a single one)
    name = "sat"
    mass = 12.0
    inertia = [[0.2, 0.004, -0.002],      # about the COM, body frame: (3, 3) symmetric positive
               [0.004, 0.25, 0.003],      # definite, or (3,) principal moments; without it, the
               [-0.002, 0.003, 0.08]]     # uniform solid of `shape` (box, cylinder or sphere)
    # com_offset = [0.01, 0.0, 0.02]      # optional: `inertia` is about a CAD reference point and the
    #                                     # COM sits here from it (body frame); moved to the COM on load
    q = [0.0, 0.0, 0.0, 1.0]              # optional initial state: p_w, q, v_w, omega_b (or omega_w)
    shape = { kind = "box", dims = [0.1, 0.2, 0.3] }   # optional, drawn by the viewer

    [body.wheels]                         # optional: the body's reaction_wheels
    axes_b = [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]]   # (N, 3) rows, body frame
    J = 3e-5                              # kg·m², one for all or (N,)
    torque_limit = 0.002                  # N·m (stall torque)
    speed_limit = 600.0                   # rad/s (no-load speed)
    c_w = 0.0                             # N·m·s/rad bearing friction (default 0)
    motor = "line"                        # "line": torque–speed line (default); "cutoff": full torque up to speed_limit

    [body.joint]                          # optional: a world-anchored spherical_joint
    anchor_w = [0.0, 0.0, 0.0]            # the body point at anchor_w at the start stays there

    [[effects]]                           # force effects, each by its declared name and parameters
    name = "gravity"                      # (lavendersim.effects.EFFECTS: each class's docstring lists them)
    body = "sat"                          # optional: every body when absent
    g_w = [0.0, 0.0, -9.81]

Each wheel axis row is scaled to unit length when it is not unit already (to 1e-12), so a file may
write ``[1, 1, 1]``. A spacecraft file (lavendersim.spacecraft) is this format plus its controller,
sensors and maneuver tables.

Every key is checked: an unknown key, a wrong type or shape, a non-positive mass or limit raises
:class:`lavendersim.validate.LavenderInputError` naming the key path (``body.wheels.axes_b[2]``,
``effects[0].g_w``) and the rule; nothing is built from a file that fails.
"""
from __future__ import annotations

import difflib
import math
import os
import re
import tomllib
from contextlib import contextmanager
from pathlib import Path
from typing import Any

import numpy as np

from . import validate as V
from .bodies import Body
from .generated import layout as LY
from .scene import Scene

__all__ = ["scene_to_dict", "scene_from_dict", "save", "load", "dumps", "read_toml", "body_from_dict", "wheels_params"]

SCENE_FORMAT = 1
MOTORS = {"line": 0.0, "cutoff": 1.0}          # motor name -> the reaction_wheels cutoff parameter
AXIS_UNIT_TOL = 1e-12                           # an axis row this close to unit length is kept as written
TOP_KEYS = ("scene_format", "body", "effects")
BODY_KEYS = ("name", "mass", "inertia", "com_offset", "p_w", "q", "v_w", "omega_b", "omega_w", "shape", "wheels", "joint")
WHEEL_KEYS = ("axes_b", "J", "torque_limit", "speed_limit", "c_w", "motor")
JOINT_KEYS = ("anchor_w",)
SHAPE_KEYS = ("kind", "dims")
NESTED = {"reaction_wheels": "wheels", "spherical_joint": "joint"}   # model effects live in their body's table
# a spacecraft file's other top-level keys (lavendersim.spacecraft reads them; load() skips them)
SPACECRAFT_TABLES = ("name", "controller", "sensors", "actuator", "maneuver", "simulator", "monte_carlo")


# ---------------------------------------------------------------------------------------------
# checking helpers (shared with lavendersim.spacecraft)
# ---------------------------------------------------------------------------------------------


@contextmanager
def at(path: str, strip: str = ""):
    """Re-raise a LavenderInputError from inside with its field under ``path``.

    Parameters
    ----------
    path : str
        Key path of the value being checked (``"body"``, ``"effects[1]"``).
    strip : str, optional
        A prefix of the inner field to drop first (``"reaction_wheels."``).
    """
    try:
        yield
    except V.LavenderInputError as exc:
        field = exc.field[len(strip):] if strip and exc.field.startswith(strip) else exc.field
        joined = path if not field else (f"{path}{field}" if field.startswith("[") else f"{path}.{field}")
        raise V.LavenderInputError(joined, exc.rule, exc.detail) from None


def table(path: str, value: Any, known: tuple[str, ...], required: tuple[str, ...] = ()) -> dict:
    """A TOML table with only the ``known`` keys and every ``required`` one.

    Parameters
    ----------
    path : str
        Its key path (errors name ``path.key``).
    value : object
        What the file holds there.
    known, required : tuple of str
        Allowed and required keys.

    Returns
    -------
    dict
        ``value`` itself.

    Raises
    ------
    LavenderInputError
        Not a table, an unknown key (with the closest known one), or a missing required key.
    """
    if not isinstance(value, dict):
        raise V.LavenderInputError(path, "must be a table", f", got {V._describe(value)}")
    for key in value:
        if key not in known:
            close = difflib.get_close_matches(str(key), known, n=1)
            hint = f" (did you mean {close[0]!r}?)" if close else ""
            raise V.LavenderInputError(_join(path, key), "unknown key", f"; known: {', '.join(known)}{hint}")
    for key in required:
        if key not in value:
            raise V.LavenderInputError(_join(path, key), "is required")
    return value


def _join(path: str, key: str) -> str:
    return str(key) if not path else f"{path}.{key}"


def text(path: str, value: Any) -> str:
    """A non-empty string."""
    if not isinstance(value, str) or not value:
        raise V.LavenderInputError(path, "must be a non-empty string", f", got {V._describe(value)}")
    return value


def rows(path: str, value: Any, width: int, *, min_rows: int = 1, max_rows: int | None = None) -> np.ndarray:
    """An (N, width) array given as a list of rows, each row checked by itself (errors name ``path[i]``)."""
    if not isinstance(value, list):
        raise V.LavenderInputError(path, f"must be a list of rows of {width} numbers", f", got {V._describe(value)}")
    if not min_rows <= len(value) <= (len(value) if max_rows is None else max_rows):
        most = "" if max_rows is None else f" and at most {max_rows}"
        raise V.LavenderInputError(path, f"needs at least {min_rows}{most} rows", f", got {len(value)}")
    return np.array([V.vector(f"{path}[{i}]", r, width) for i, r in enumerate(value)]).reshape(len(value), width)


def unit_rows(path: str, A: np.ndarray) -> np.ndarray:
    """Each row scaled to unit length (a row unit to AXIS_UNIT_TOL is kept as written); a zero row refused."""
    out = A.copy()
    for i, r in enumerate(A):
        n = float(np.linalg.norm(r))
        if not n > 1e-12:
            raise V.LavenderInputError(f"{path}[{i}]", "a wheel axis must be a non-zero vector", f", got {V._nums(r)}")
        if abs(n - 1.0) > AXIS_UNIT_TOL:
            out[i] = r / n
    return out


# ---------------------------------------------------------------------------------------------
# dict -> Scene
# ---------------------------------------------------------------------------------------------


def _inertia(path: str, b: dict, mass: float) -> np.ndarray:
    value = b.get("inertia")
    if value is None:
        raise V.LavenderInputError(f"{path}.inertia", "is required (without a shape): (3, 3) tensor or (3,) principal "
                                   "moments, kg·m²")
    if isinstance(value, list) and value and isinstance(value[0], list):
        I = rows(f"{path}.inertia", value, 3, min_rows=3, max_rows=3)
    else:
        I = V.vector(f"{path}.inertia", value)
    if "com_offset" in b:   # CAD mass properties: moved to the COM (bodies.inertia_about_com, the derived kernel)
        from .bodies import inertia_about_com

        c = V.vector(f"{path}.com_offset", b["com_offset"])
        try:
            return inertia_about_com(np.diag(I) if I.ndim == 1 else I, mass, c)
        except V.LavenderInputError as exc:
            key = {"I_o": "inertia", "com": "com_offset", "mass": "mass"}.get(exc.field.split("[")[0], exc.field)
            raise V.LavenderInputError(f"{path}.{key}", exc.rule, exc.detail) from None
    return I


def _shape(path: str, value: Any):
    s = table(path, value, SHAPE_KEYS, required=SHAPE_KEYS)
    dims = s["dims"] if isinstance(s["dims"], list) else [s["dims"]]
    return (s["kind"], dims)


def body_from_dict(path: str, b: Any) -> Body:
    """A Body from its table (the wheels and joint are effects, read by :func:`scene_from_dict`).

    Parameters
    ----------
    path : str
        Its key path (``"body"`` or ``"body[2]"``).
    b : dict
        The table.

    Returns
    -------
    Body
    """
    table(path, b, BODY_KEYS, required=("name", "mass"))
    name = text(f"{path}.name", b["name"])
    mass = V.positive(f"{path}.mass", b["mass"])
    state = {k: b[k] for k in ("p_w", "q", "v_w", "omega_b", "omega_w") if k in b}
    shape = _shape(f"{path}.shape", b["shape"]) if "shape" in b else None
    if "inertia" not in b and shape is not None:   # the uniform solid of that shape
        if "com_offset" in b:
            raise V.LavenderInputError(f"{path}.com_offset", "needs the inertia it moves (inertia = ...)")
        kind = V.choice(f"{path}.shape.kind", shape[0], ("box", "cylinder", "sphere"))
        dims = shape[1]
        try:
            if kind == "box":
                return Body.box(name, mass, dims, **state)
            dims = V.vector("size", dims, 2 if kind == "cylinder" else 1)
            if kind == "cylinder":
                return Body.cylinder(name, mass, dims[0], dims[1], **state)
            return Body.sphere(name, mass, dims[0], **state)
        except V.LavenderInputError as exc:
            raise V.LavenderInputError(f"{path}.{_shape_field(exc.field)}", exc.rule, exc.detail) from None
    I = _inertia(path, b, mass)
    if shape is not None:
        state["shape"] = shape
    try:
        return Body(name, mass, I, **state)
    except V.LavenderInputError as exc:
        raise V.LavenderInputError(f"{path}.{_shape_field(exc.field)}", exc.rule, exc.detail) from None


def _shape_field(f: str) -> str:
    """Body's names for the shape's parts (shape[0], shape[1][i], size[i], radius, height) as the file's keys."""
    if f.startswith("shape[0]"):
        return "shape.kind"
    if f.startswith("shape[1]"):
        return "shape.dims" + f[len("shape[1]"):]
    if f.startswith("size"):
        return "shape.dims" + f[len("size"):]
    return "shape.dims" if f in ("radius", "height") else f


def wheels_params(path: str, w: Any) -> dict:
    """The reaction_wheels parameters of a ``[body.wheels]`` table.

    Parameters
    ----------
    path : str
        Its key path.
    w : dict
        The table: axes_b (N, 3) (default the body x, y, z axes), J (one or N), torque_limit,
        speed_limit, c_w (default 0), motor ("line" or "cutoff", default "line").

    Returns
    -------
    dict
        Keyword arguments of ``scene.add_effect("reaction_wheels", ...)``.
    """
    table(path, w, WHEEL_KEYS, required=("J", "torque_limit", "speed_limit"))
    A = unit_rows(f"{path}.axes_b", rows(f"{path}.axes_b", w["axes_b"], 3, max_rows=4)) if "axes_b" in w else np.eye(3)
    n = A.shape[0]
    Jv = w["J"]
    J = np.full(n, V.positive(f"{path}.J", Jv)) if not isinstance(Jv, list) else V.vector(f"{path}.J", Jv, n)
    for i, j in enumerate(J):
        if not j > 0:
            raise V.LavenderInputError(f"{path}.J[{i}]", "must be > 0 kg·m²", f", got {j!r}")
    return {"axes_b": A, "J": J, "torque_limit": V.positive(f"{path}.torque_limit", w["torque_limit"]),
            "speed_limit": V.positive(f"{path}.speed_limit", w["speed_limit"]),
            "c_w": V.scalar(f"{path}.c_w", w.get("c_w", 0.0), nonnegative=True),
            "cutoff": MOTORS[V.choice(f"{path}.motor", w.get("motor", "line"), MOTORS)]}


def _effect(scene: Scene, path: str, e: Any) -> None:
    from .effects import make

    if not isinstance(e, dict):
        raise V.LavenderInputError(path, "must be a table", f", got {V._describe(e)}")
    if "name" not in e:
        raise V.LavenderInputError(f"{path}.name", "is required (the effect's name, e.g. \"gravity\")")
    name = text(f"{path}.name", e["name"])
    if name in NESTED:
        raise V.LavenderInputError(f"{path}.name", f"{name} belongs to its body: write it as [body.{NESTED[name]}]")
    params = {k: v for k, v in e.items() if k not in ("name", "body")}
    body = None if e.get("body") is None else text(f"{path}.body", e["body"])
    try:
        effect = make(name, body=body, **params)   # a built-in or a user effect (found by name)
    except V.LavenderInputError as exc:
        if exc.field == "effect":                  # an unknown name
            raise V.LavenderInputError(f"{path}.name", exc.rule, exc.detail) from None
        raise V.LavenderInputError(path + exc.field[len(name):] if exc.field.startswith(name + ".") else
                                   f"{path}.{exc.field}", exc.rule, exc.detail) from None
    with at(path, strip=f"{name}."):
        scene.add_effect(effect)


def scene_from_dict(d: dict, *, extra: tuple[str, ...] = ()) -> Scene:
    """Build a Scene from the dict a scene file reads into (see the module docstring).

    Parameters
    ----------
    d : dict
        ``tomllib.load`` of a scene file, or :func:`scene_to_dict`'s output.
    extra : tuple of str, optional
        Further top-level keys to allow (and ignore here): a spacecraft file's controller, sensors, ….

    Returns
    -------
    Scene
        A new scene; nothing is built when a key fails.

    Raises
    ------
    LavenderInputError
        Naming the key path and the rule.
    """
    table("", d, TOP_KEYS + tuple(extra), required=("body",))
    if "scene_format" in d:
        fmt = V.integer("scene_format", d["scene_format"], minimum=1)
        if fmt != SCENE_FORMAT:
            raise V.LavenderInputError("scene_format", f"this lavendersim reads scene_format {SCENE_FORMAT}", f", got {fmt}")
    bodies = d["body"]
    if isinstance(bodies, dict):
        items = [("body", bodies)]
    elif isinstance(bodies, list) and bodies:
        items = [(f"body[{i}]", b) for i, b in enumerate(bodies)]
    else:
        raise V.LavenderInputError("body", "must be a table ([body]) or a non-empty array of tables ([[body]])",
                                   f", got {V._describe(bodies)}")
    scene = Scene()
    for path, b in items:
        body = body_from_dict(path, b)
        with at(path, strip="body."):
            scene.add_body(body)
    for path, b in items:
        name = b["name"]
        if "wheels" in b:
            kw = wheels_params(f"{path}.wheels", b["wheels"])
            with at(f"{path}.wheels", strip="reaction_wheels."):
                scene.add_effect("reaction_wheels", body=name, **kw)
        if "joint" in b:
            j = table(f"{path}.joint", b["joint"], JOINT_KEYS, required=JOINT_KEYS)
            anchor = V.vector(f"{path}.joint.anchor_w", j["anchor_w"])
            with at(f"{path}.joint", strip="spherical_joint."):
                scene.add_effect("spherical_joint", body=name, anchor_w=anchor)
    effects = d.get("effects", [])
    if not isinstance(effects, list):
        raise V.LavenderInputError("effects", "must be an array of tables ([[effects]])", f", got {V._describe(effects)}")
    for i, e in enumerate(effects):
        _effect(scene, f"effects[{i}]", e)
    return scene


# ---------------------------------------------------------------------------------------------
# Scene -> dict
# ---------------------------------------------------------------------------------------------


def _list(a) -> Any:
    return np.asarray(a, dtype=float).tolist()


def _body_dict(b: Body) -> dict:
    out: dict[str, Any] = {"name": b.name, "mass": float(b.mass),
                           "inertia": _list(b.I_b) if b.principal else _list(b.inertia_b)}
    st = {"p_w": b.x0[LY.STATE_P_W], "q": b.x0[LY.STATE_Q], "v_w": b.x0[LY.STATE_V_W], "omega_b": b.x0[LY.STATE_OMEGA_B]}
    default = {"p_w": np.zeros(3), "q": np.array([0.0, 0.0, 0.0, 1.0]), "v_w": np.zeros(3), "omega_b": np.zeros(3)}
    for k, v in st.items():
        if not np.array_equal(v, default[k]):
            out[k] = _list(v)
    if b.shape is not None:
        out["shape"] = {"kind": b.shape[0], "dims": list(b.shape[1])}
    return out


def scene_to_dict(scene: Scene) -> dict:
    """The scene as the dict a scene file holds (:func:`scene_from_dict` rebuilds it).

    Bodies keep their inertia about the COM in their body frame ((3,) when principal, else (3, 3)),
    their initial state (keys left out where it is the default) and shape; reaction_wheels and
    spherical_joint go in their body's table (``wheels``, ``joint``), force effects in ``effects``.

    Parameters
    ----------
    scene : Scene

    Returns
    -------
    dict
        Plain Python values (str, float, lists, dicts): ``tomllib`` and :func:`dumps` agree on it.
    """
    bodies = {name: _body_dict(b) for name, b in scene.bodies.items()}
    effects = []
    for e in scene.effects:
        if e.name == "reaction_wheels":
            v = e.values
            bodies[e.body]["wheels"] = {"axes_b": _list(v["axes_b"]), "J": _list(v["J"]),
                                        "torque_limit": float(v["torque_limit"]), "speed_limit": float(v["speed_limit"]),
                                        "c_w": float(v["c_w"]),
                                        "motor": next(k for k, c in MOTORS.items() if c == float(v["cutoff"]))}
        elif e.name == "spherical_joint":
            bodies[e.body]["joint"] = {"anchor_w": _list(e.values["anchor_w"])}
        else:
            entry: dict[str, Any] = {"name": e.name}
            if e.body is not None:
                entry["body"] = e.body
            entry.update({k: (_list(v) if np.ndim(v) else float(v)) for k, v in e.values.items()})
            effects.append(entry)
    ordered = [{k: b[k] for k in BODY_KEYS if k in b} for b in bodies.values()]   # one key order, whatever the effects'
    out: dict[str, Any] = {"scene_format": SCENE_FORMAT, "body": ordered}
    if effects:
        out["effects"] = effects
    return out


# ---------------------------------------------------------------------------------------------
# TOML text: a small writer for the types a scene file holds (tomllib only reads)
# ---------------------------------------------------------------------------------------------

_BARE = re.compile(r"^[A-Za-z0-9_-]+$")


def _key(k: str) -> str:
    return k if _BARE.match(k) else _string(k)


def _string(s: str) -> str:
    out = ['"']
    for ch in s:
        if ch in '"\\':
            out.append("\\" + ch)
        elif ch == "\n":
            out.append("\\n")
        elif ch == "\t":
            out.append("\\t")
        elif ord(ch) < 0x20 or ord(ch) == 0x7F:
            out.append(f"\\u{ord(ch):04x}")
        else:
            out.append(ch)
    return "".join(out) + '"'


def _value(v: Any) -> str:
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, (int, np.integer)):
        return str(int(v))
    if isinstance(v, (float, np.floating)):
        x = float(v)
        if math.isnan(x):
            return "nan"
        if math.isinf(x):
            return "inf" if x > 0 else "-inf"
        return repr(x)
    if isinstance(v, str):
        return _string(v)
    if isinstance(v, (list, tuple, np.ndarray)):
        return "[" + ", ".join(_value(x) for x in v) + "]"
    if isinstance(v, dict):
        return "{ " + ", ".join(f"{_key(k)} = {_value(x)}" for k, x in v.items()) + " }"
    raise TypeError(f"cannot write {type(v).__name__} as TOML")


def _is_table_array(v: Any) -> bool:
    return isinstance(v, list) and bool(v) and all(isinstance(x, dict) for x in v)


def _emit(lines: list[str], d: dict, prefix: str) -> None:
    for k, v in d.items():
        if not isinstance(v, dict) and not _is_table_array(v):
            lines.append(f"{_key(k)} = {_value(v)}")
    for k, v in d.items():
        path = f"{prefix}.{_key(k)}" if prefix else _key(k)
        if isinstance(v, dict):
            lines += ["", f"[{path}]"]
            _emit(lines, v, path)
        elif _is_table_array(v):
            for item in v:
                lines += ["", f"[[{path}]]"]
                _emit(lines, item, path)


def dumps(d: dict) -> str:
    """TOML text of a dict of str, int, float, bool, lists and tables (what scene files hold).

    Parameters
    ----------
    d : dict

    Returns
    -------
    str
        ``tomllib.loads(dumps(d)) == d`` for such a dict (floats written with ``repr``: exact).
    """
    lines: list[str] = []
    _emit(lines, d, "")
    return "\n".join(lines).lstrip("\n") + "\n"


def read_toml(path: str | os.PathLike[str], field: str = "file") -> dict:
    """Read a TOML file; a missing file or bad TOML raises LavenderInputError naming ``field``.

    Parameters
    ----------
    path : str or os.PathLike
    field : str, optional
        What the error names.

    Returns
    -------
    dict
    """
    p = Path(path)
    try:
        with p.open("rb") as f:
            return tomllib.load(f)
    except tomllib.TOMLDecodeError as exc:
        raise V.LavenderInputError(field, "is not valid TOML", f" ({p}: {exc})") from None
    except OSError as exc:
        raise V.LavenderInputError(field, "cannot be read", f" ({p}: {exc.strerror or exc})") from None


def save(scene: Scene, path: str | os.PathLike[str]) -> Path:
    """Write the scene as a TOML scene file.

    Parameters
    ----------
    scene : Scene
    path : str or os.PathLike
        The file (its folder must exist and be writable).

    Returns
    -------
    Path
    """
    p = V.writable_file("path", path)
    p.write_text(dumps(scene_to_dict(scene)), encoding="utf-8")
    return p


def load(path: str | os.PathLike[str]) -> Scene:
    """Read a TOML scene file, or the scene part of a spacecraft file (its SPACECRAFT_TABLES are skipped here;
    lavendersim.spacecraft.load reads them).

    Parameters
    ----------
    path : str or os.PathLike

    Returns
    -------
    Scene

    Raises
    ------
    LavenderInputError
        A missing file, bad TOML, or a bad key (its path named).
    """
    return scene_from_dict(read_toml(path, field=str(path)), extra=SPACECRAFT_TABLES)
