"""Live browser viewer: a viser page that shows a Sim's bodies plus Python-chosen axes and vectors.

Example::

    viewer = Viewer(port=8080)                 # serves http://127.0.0.1:8080 (host/port configurable)
    viewer.publish_frame(sim, overlays={
        "axes": [{"body": "cube", "scale": 0.34}],
        "vectors": [{"label": "angular velocity", "origin": p.tolist(), "vector": w.tolist(),
                     "scale": 0.12, "color": [0.51, 0.87, 0.76, 0.95]}],
    })

Bodies are drawn from the scene at their authoritative transforms (position p_w, orientation q);
a box with its side lengths, a cylinder (along body z) with its radius and height, a sphere with
its radius, and a body without a shape as its inertia-equivalent box. An axes triad (x red,
y green, z blue; length = scale in m) follows its body. A vector is drawn in world coordinates as
an arrow from ``origin`` to ``origin + scale * vector`` in colour ``[r, g, b, a]`` (each in
[0, 1]; a is the opacity) with its label at the tip.

Overlay payload (keys outside these are errors)::

  axes:    list of {"body": name (required), "scale": m > 0 (default 0.3)}; one entry per body.
  vectors: list (at most MAX_VECTORS) of {"label": str (default ""), "origin": 3 reals (required),
           "vector": 3 reals (required), "scale": real > 0 (default 1), "color": 4 reals in [0, 1]
           (default DEFAULT_COLOR)}.

Every coordinate drawn (origin, origin + scale * vector, the arrow's length, body positions) must lie
within FLOAT32_MAX (3.4e38; the browser draws in float32): a vector of 1e308 — or one whose length
overflows — is rejected. The whole payload is validated before anything is stored: a bad one raises
:class:`~lavendersim.validate.LavenderInputError` naming the field (``overlays.vectors[1].color``)
and the previously published frame stays on screen, untouched.

Publishing never waits for a browser. ``publish_frame`` validates, copies the poses (a few
microseconds) and stores the frame as the *latest*; a background thread applies the latest frame
to the viser scene at most ``max_rate_hz`` times per second (older unapplied frames are dropped —
coalesced, latest wins — and counted in ``stats()``). viser itself keeps one buffered message per
scene-node property, so a stalled or slow browser holds at most one pending state per node, and
every connected tab (any number) receives the same shared scene.

A frame that cannot be drawn is never reported as drawn: ``wait_applied`` raises :class:`ViewerError`
for it, and the next ``publish_frame`` raises it once (naming the frame and the cause); ``stats()``
counts failures. Body names map injectively to scene nodes (percent-encoded), so any set of distinct
names draws.

Binding: ``host`` must be an IP address or a host name (checked, and resolved within
RESOLVE_TIMEOUT_S) that is an address of this machine (a test bind, so 192.0.2.1 fails at once);
the server must be up within BIND_TIMEOUT_S. Otherwise LavenderInputError names ``host``.

Controls (the page's side panel; :class:`Controls`, ``viewer.controls``): a "body axes" checkbox and
one checkbox per vector label hide or show them (applied to the latest frame at once, and to every
frame after); while a :class:`Player` runs (:meth:`Viewer.play` for a live Sim, :meth:`Viewer.replay`
for a recorded :class:`~lavendersim.sim.Trajectory`, ``lavendersim view``), a Pause/Resume button, a
speed slider (simulated seconds per wall-clock second: a live Sim advances ``speed / rate_hz`` s per
frame) and, for a replay, a time slider to scrub. Each works the same from Python, from its GUI
handle and from the browser. Example::

    traj = sim.record(3000, every=20)          # 3 s at 1 ms steps, every 20th state
    viewer = Viewer(port=0)
    viewer.replay(traj, sim)                   # plays in a background thread; returns at once
    viewer                                     # in a notebook: the page inline, and a link
    viewer.controls.pause(); viewer.player.seek(1.5)
    viewer.close()                             # stops the player and the server (threads joined)

Conventions: our quaternions are (x, y, z, w); viser's are (w, x, y, z) — converted here, once.
World frame z up. Units m.
"""
from __future__ import annotations

import atexit
import copy
import dataclasses
import difflib
import html
import ipaddress
import math
import re
import socket
import sys
import threading
import time
import urllib.parse
import weakref
from collections.abc import Callable, Iterable, Mapping, Sequence
from typing import TYPE_CHECKING, Any, Self, TextIO

import numpy as np
from numpy.typing import ArrayLike

from . import _playback as PB
from . import validate as V
from ._install import require
from ._playback import Controls, Player, Snapshot
from ._shapes import extent as _extent
from ._shapes import shape_of as _shape_of
from .generated import layout as LY
from .kernels import K as KN

if TYPE_CHECKING:  # annotations only: the Sim loads lazily
    from .sim import Sim, Trajectory

__all__ = ["Viewer", "ViewerError", "Controls", "Player", "Snapshot", "validate_overlays", "xyzw_to_wxyz", "DEFAULT_COLOR",
           "MAX_VECTORS", "SCENES", "register_scene", "run_scene"]

DEFAULT_HOST = "127.0.0.1"
DEFAULT_PORT = 8080
DEFAULT_RATE_HZ = 30.0
DEFAULT_AXES_SCALE = 0.3
DEFAULT_COLOR = (0.95, 0.75, 0.2, 1.0)
MAX_VECTORS = 64
MAX_LABEL = 200
MIN_RATE_HZ = 0.1           # run_scene, play, replay: frames per second, at least
DEFAULT_REPLAY_S = 10.0     # run_scene(replay=True) without a duration records this many simulated seconds
MAX_REPLAY_SAMPLES = 100_000  # run_scene(replay=True): duration * rate_hz, at most (memory, recording time)
INLINE_HEIGHT = 480         # px: the notebook's inline frame
FLOAT32_MAX = 3.4e38        # the browser draws in float32: coordinates beyond this would become Infinity
RESOLVE_TIMEOUT_S = 10.0    # host name resolution
BIND_TIMEOUT_S = 30.0       # the viser server up and listening
BODY_COLORS = [(186, 160, 220), (150, 190, 230), (230, 200, 150), (170, 215, 170), (225, 170, 180)]

_AXES_KEYS = {"body", "scale"}
_VECTOR_KEYS = {"label", "origin", "vector", "scale", "color"}
_TOP_KEYS = {"axes", "vectors"}


# --------------------------------------------------------------------------
# payload validation (pure; no viser needed)
# --------------------------------------------------------------------------


def _keys(field: str, item, allowed: set[str], required: Iterable[str] = ()) -> None:
    if not isinstance(item, Mapping):
        raise V.LavenderInputError(field, "expected a dict", f", got {V._describe(item)}")
    for k in item:
        if k not in allowed:
            close = difflib.get_close_matches(str(k), sorted(allowed), n=1) if isinstance(k, str) else []
            hint = f" (did you mean {close[0]!r}?)" if close else ""
            raise V.LavenderInputError(f"{field}", f"unknown key {k!r}{hint}", f"; allowed: {', '.join(sorted(allowed))}")
    for k in sorted(required):
        if k not in item:
            raise V.LavenderInputError(f"{field}.{k}", "is required")


def _list(field: str, value) -> list:
    if isinstance(value, (str, bytes, Mapping)) or not isinstance(value, Sequence):
        raise V.LavenderInputError(field, "expected a list", f", got {V._describe(value)}")
    return list(value)


def _vec(field: str, value, n: int = 3) -> np.ndarray:
    """V.vector with a fast path for the common case: a list/tuple of n finite Python floats/ints."""
    if type(value) in (list, tuple) and len(value) == n and all(type(x) in (float, int) for x in value):
        if all(math.isfinite(x) for x in value):
            return np.array(value, dtype=float)
    return V.vector(field, value, n)


def _pos(field: str, value) -> float:
    if type(value) in (float, int) and math.isfinite(value) and value > 0:
        return float(value)
    return V.positive(field, value)


def _check_drawable(f: str, item: dict) -> None:
    """origin, origin + scale * vector and the arrow's length within ±FLOAT32_MAX (no overflow)."""
    o = item["origin"]
    if np.max(np.abs(o)) > FLOAT32_MAX:
        raise V.LavenderInputError(f"{f}.origin", f"each coordinate must be within ±{FLOAT32_MAX:g} m (drawn in float32)",
                                   f", got {V._nums(o)}")
    with np.errstate(over="ignore", invalid="ignore"):
        d = item["scale"] * item["vector"]
        end = o + d
        length = V.safe_norm(d) if np.all(np.isfinite(d)) else math.inf
    if not (length <= FLOAT32_MAX and np.all(np.abs(end) <= FLOAT32_MAX)):
        raise V.LavenderInputError(f"{f}.vector", f"the drawn arrow (origin + scale * vector) and its length must be "
                                   f"within ±{FLOAT32_MAX:g} m (drawn in float32)",
                                   f", got vector {V._nums(item['vector'])} with scale {item['scale']:g}")


def node_name(body: str) -> str:
    """The scene node of a body: /bodies/ + its name percent-encoded (injective: "x/y" and "x_y" differ)."""
    return "/bodies/" + urllib.parse.quote(body, safe="")


class ViewerError(RuntimeError):
    """A published frame could not be drawn in the viser scene (the cause is chained)."""


_HOSTNAME = re.compile(r"^(?=.{1,253}$)([A-Za-z0-9]([A-Za-z0-9-]{0,61}[A-Za-z0-9])?)(\.[A-Za-z0-9]([A-Za-z0-9-]{0,61}[A-Za-z0-9])?)*\.?$")


# the only spellings of "every interface" accepted (with a warning on stderr): any other host that binds the
# wildcard address ("0", "", "0.0", "0x0", "000.0.0.0", "::0", "::ffff:0.0.0.0", a name resolving to 0.0.0.0)
# is refused, so nobody exposes the page to the network by a typo or without saying so
EVERY_INTERFACE = ("0.0.0.0", "::")


def _is_wildcard(addr: str) -> bool:
    """Whether a numeric address (as getaddrinfo gives it) is INADDR_ANY / in6addr_any (or mapped to it)."""
    try:
        ip = ipaddress.ip_address(addr.split("%", 1)[0])
    except ValueError:
        return False
    mapped = getattr(ip, "ipv4_mapped", None)
    return ip.is_unspecified or (mapped is not None and mapped.is_unspecified)


def binds_every_interface(host: str) -> bool:
    """Whether ``host`` (as accepted by :func:`check_host`) is one of EVERY_INTERFACE.

    Parameters
    ----------
    host : str

    Returns
    -------
    bool
    """
    return host in EVERY_INTERFACE


def check_host(host: object) -> str:
    """Validate an interface to bind: an IP address or a host name that resolves (within
    RESOLVE_TIMEOUT_S) to an address of this machine; LavenderInputError naming ``host`` otherwise.
    A host that would bind every interface is refused unless spelled exactly ``0.0.0.0`` or ``::``
    (EVERY_INTERFACE; :class:`Viewer` then prints a warning on stderr).

    Parameters
    ----------
    host : str

    Returns
    -------
    str
        ``host``.

    Raises
    ------
    lavendersim.validate.LavenderInputError
        Naming ``host``.
    """
    if not isinstance(host, str) or not host:
        raise V.LavenderInputError("host", "expected an interface address (str; 0.0.0.0 for every interface)",
                                   f", got {V._describe(host)}")
    try:
        addrs = [str(ipaddress.ip_address(host))]
    except ValueError:
        if not _HOSTNAME.match(host):
            raise V.LavenderInputError("host", "is neither an IP address nor a valid host name", f", got {host!r}") from None
        addrs = _resolve(host)
    if host not in EVERY_INTERFACE and any(_is_wildcard(a) for a in addrs):
        raise V.LavenderInputError("host", "would listen on every interface of this machine (it means "
                                   f"{', '.join(dict.fromkeys(addrs))}); spell it 0.0.0.0 (or :: for IPv6) if that is "
                                   "what you want, or give one interface such as 127.0.0.1", f", got {host!r}")
    errors = []
    for a in addrs:
        fam = socket.AF_INET6 if ":" in a else socket.AF_INET
        try:
            with socket.socket(fam, socket.SOCK_STREAM) as sock:
                sock.bind((a, 0))  # port 0: tests the address only (a taken port is viser's to skip)
            return host
        except OSError as exc:
            errors.append(f"{a}: {exc.strerror or exc}")
    raise V.LavenderInputError("host", "is not an address of this machine (cannot bind it)",
                               f", got {host!r} ({'; '.join(errors)})")


def _within(seconds: float, name: str, fn: Callable[[], Any]) -> dict[str, Any]:
    """Call fn() in a daemon thread named `name`, waiting at most `seconds` (a stuck call never hangs us):
    {"ok": its result}, {"err": what it raised} (re-raised by the caller, in its thread), or {} if still running."""
    box: dict[str, Any] = {}

    def work():
        try:
            box["ok"] = fn()
        except BaseException as exc:
            box["err"] = exc

    t = threading.Thread(target=work, name=name, daemon=True)
    t.start()
    t.join(seconds)
    return dict(box) if not t.is_alive() else {}


def _resolve(host: str) -> list[str]:
    """getaddrinfo in a daemon thread, bounded by RESOLVE_TIMEOUT_S (a stuck resolver never hangs us)."""
    box = _within(RESOLVE_TIMEOUT_S, "lavendersim-resolve", lambda: socket.getaddrinfo(host, None, type=socket.SOCK_STREAM))
    if not box:
        raise V.LavenderInputError("host", f"could not be resolved within {RESOLVE_TIMEOUT_S:g} s", f", got {host!r}")
    if isinstance(box.get("err"), OSError):
        raise V.LavenderInputError("host", "could not be resolved", f", got {host!r} ({box['err']})")
    if "err" in box:
        raise box["err"]
    return list(dict.fromkeys(info[4][0] for info in box["ok"]))


def validate_overlays(overlays: Mapping[str, Any] | None, body_names: Iterable[str]) -> dict[str, list[dict[str, Any]]]:
    """Check an overlay payload against the bodies of a scene; return a normalized copy.

    Result: ``{"axes": [{"body": str, "scale": float}], "vectors": [{"label": str, "origin":
    ndarray(3), "vector": ndarray(3), "scale": float, "color": ndarray(4)}]}``. Raises
    LavenderInputError naming the first bad field; the input is never mutated.

    Parameters
    ----------
    overlays : mapping or None
        ``{"axes": [{"body", "scale"}], "vectors": [{"label", "origin", "vector", "scale", "color"}]}``;
        origin and vector world frame (m and any unit; drawn ``scale * vector`` long), color RGBA in [0, 1].
    body_names : iterable of str
        The scene's bodies (an axes entry must name one).

    Returns
    -------
    dict

    Raises
    ------
    LavenderInputError
        Naming the first bad field (``overlays.vectors[1].color``).
    """
    names = list(body_names)
    if overlays is None:
        return {"axes": [], "vectors": []}
    _keys("overlays", overlays, _TOP_KEYS)
    axes, seen = [], set()
    for i, a in enumerate(_list("overlays.axes", overlays.get("axes", []))):
        f = f"overlays.axes[{i}]"
        _keys(f, a, _AXES_KEYS, {"body"})
        body = a["body"]
        if not isinstance(body, str):
            raise V.LavenderInputError(f"{f}.body", "expected a body name (str)", f", got {V._describe(body)}")
        if body not in names:
            raise V.LavenderInputError(f"{f}.body", f"unknown body {body!r}", f"; bodies: {', '.join(names)}")
        if body in seen:
            raise V.LavenderInputError(f"{f}.body", f"axes for body {body!r} given twice")
        seen.add(body)
        axes.append({"body": body, "scale": _pos(f"{f}.scale", a.get("scale", DEFAULT_AXES_SCALE))})
    vectors = []
    raw = _list("overlays.vectors", overlays.get("vectors", []))
    if len(raw) > MAX_VECTORS:
        raise V.LavenderInputError("overlays.vectors", f"at most {MAX_VECTORS} vectors", f", got {len(raw)}")
    for i, v in enumerate(raw):
        f = f"overlays.vectors[{i}]"
        _keys(f, v, _VECTOR_KEYS, {"origin", "vector"})
        label = v.get("label", "")
        if not isinstance(label, str):
            raise V.LavenderInputError(f"{f}.label", "expected a str", f", got {V._describe(label)}")
        if len(label) > MAX_LABEL:
            raise V.LavenderInputError(f"{f}.label", f"at most {MAX_LABEL} characters", f", got {len(label)}")
        color = _vec(f"{f}.color", v.get("color", DEFAULT_COLOR), 4)
        if not all(0.0 <= c <= 1.0 for c in color):
            bad = np.flatnonzero((color < 0) | (color > 1))
            raise V.LavenderInputError(f"{f}.color", "each of r, g, b, a must be in [0, 1]",
                                       f", got {V._nums(color)} (index {int(bad[0])})")
        item = {
            "label": label,
            "origin": _vec(f"{f}.origin", v["origin"]),
            "vector": _vec(f"{f}.vector", v["vector"]),
            "scale": _pos(f"{f}.scale", v.get("scale", 1.0)),
            "color": color,
        }
        _check_drawable(f, item)
        vectors.append(item)
    return {"axes": axes, "vectors": vectors}


# --------------------------------------------------------------------------
# geometry helpers
# --------------------------------------------------------------------------


def xyzw_to_wxyz(q: ArrayLike) -> np.ndarray:
    """Our (x, y, z, w) quaternion as viser's (w, x, y, z).

    Parameters
    ----------
    q : array_like, shape (..., 4)
        Quaternions (x, y, z, w).

    Returns
    -------
    ndarray, shape (..., 4)
        (w, x, y, z).
    """
    q = np.asarray(q, dtype=float)
    return np.array([q[3], q[0], q[1], q[2]])


def _z_to(d: np.ndarray) -> np.ndarray:
    """wxyz quaternion of the shortest rotation taking +z onto the unit vector d."""
    return xyzw_to_wxyz(KN.quat_from_two_vectors([0.0, 0.0, 1.0], d))


def _cylinder_mesh(radius: float, z0: float, z1: float, n: int = 24):
    """Closed cylinder along z from z0 to z1."""
    a = np.linspace(0, 2 * np.pi, n, endpoint=False)
    ring = np.stack([radius * np.cos(a), radius * np.sin(a)], 1)
    verts = np.concatenate([np.c_[ring, np.full(n, z0)], np.c_[ring, np.full(n, z1)], [[0, 0, z0], [0, 0, z1]]])
    faces = []
    for i in range(n):
        j = (i + 1) % n
        faces += [[i, j, n + j], [i, n + j, n + i], [2 * n, j, i], [2 * n + 1, n + i, n + j]]
    return verts.astype(np.float32), np.array(faces, dtype=np.uint32)


def _cone_mesh(radius: float, n: int = 24):
    """Cone with its base (radius) at z = 0 and its tip at z = 1."""
    a = np.linspace(0, 2 * np.pi, n, endpoint=False)
    verts = np.concatenate([np.c_[radius * np.cos(a), radius * np.sin(a), np.zeros(n)], [[0, 0, 1], [0, 0, 0]]])
    faces = []
    for i in range(n):
        j = (i + 1) % n
        faces += [[i, j, n], [n + 1, j, i]]
    return verts.astype(np.float32), np.array(faces, dtype=np.uint32)


# --------------------------------------------------------------------------
# the viewer
# --------------------------------------------------------------------------


# a published frame's pose row: the body's p_w then q (x, y, z, w), taken from the state by name
POSE_P = slice(0, LY.STATE_P_W.stop - LY.STATE_P_W.start)
POSE_Q = slice(POSE_P.stop, POSE_P.stop + LY.STATE_Q.stop - LY.STATE_Q.start)


@dataclasses.dataclass(slots=True)
class _Frame:
    t: float
    names: tuple[str, ...]
    shapes: tuple
    pose: np.ndarray                     # (nb, 7): POSE_P, POSE_Q
    overlays: dict[str, list[dict[str, Any]]]
    published_at: float
    number: int = 0


def _start_server(viser, host: str, port: int, label: str, verbose: bool):
    """ViserServer(...) bounded by BIND_TIMEOUT_S: viser retries 1000 ports and then waits forever."""
    box = _within(BIND_TIMEOUT_S, "lavendersim-viewer-bind",
                  lambda: viser.ViserServer(host=host, port=port, label=label, verbose=verbose))
    if not box:
        raise V.LavenderInputError("host", f"could not bind {host}:{port} (or any of the next ports) within "
                                   f"{BIND_TIMEOUT_S:g} s", "")
    if "err" in box:
        raise box["err"]
    return box["ok"]


class Viewer:
    """A live viser page at http://HOST:PORT; see the module docstring.

    host: interface to bind (default 127.0.0.1: this machine only). port: TCP port (0 = any free
    one; if the port is taken viser uses the next free one — ``viewer.port`` is the bound one).
    max_rate_hz: most scene updates per second sent to browsers (frames in between coalesce).
    arrow_radius: shaft radius of vector arrows in m (default: 2.5% of the largest body).

    Parameters
    ----------
    host : str, optional
        Interface to bind.
    port : int, optional
        TCP port.
    max_rate_hz : float, optional
        Most scene updates per second.
    label : str, optional
        Page title.
    arrow_radius : float or None, optional
        Shaft radius of vector arrows, m.
    verbose : bool, optional
        Let viser print its banner.

    Raises
    ------
    MissingExtraError
        Without the ``viewer`` extra (viser).
    LavenderInputError
        On a bad host, port or rate.
    """

    @V.keywords
    def __init__(self, host: str = DEFAULT_HOST, port: int = DEFAULT_PORT, *, max_rate_hz: float = DEFAULT_RATE_HZ,
                 label: str = "LavenderSim", arrow_radius: float | None = None, verbose: bool = False) -> None:
        port = V.integer("port", port, minimum=0)
        if port > 65535:
            raise V.LavenderInputError("port", "must be in 0..65535", f", got {port}")
        self.max_rate_hz = V.positive("max_rate_hz", max_rate_hz)
        self._arrow_radius = None if arrow_radius is None else V.positive("arrow_radius", arrow_radius)
        if not isinstance(label, str):
            raise V.LavenderInputError("label", "expected a str", f", got {V._describe(label)}")
        viser = require("viser", "viewer", "the browser viewer")
        check_host(host)
        self.server = _start_server(viser, host, port, label, verbose)
        self.host, self.port = host, int(self.server.get_port())
        if binds_every_interface(host):
            print(f"lavendersim viewer: warning: listening on every interface ({host}, port {self.port}): anyone who "
                  "can reach this machine can open the page; --host 127.0.0.1 keeps it on this machine",
                  file=sys.stderr, flush=True)
        self.server.gui.configure_theme(show_share_button=False, show_logo=False)
        self._status = self.server.gui.add_markdown("waiting for the first frame")
        self._lock = threading.Lock()
        self._last: _Frame | None = None   # the latest frame published (redrawn when a control changes)
        self.player: Player | None = None
        self.stop_reason: str | None = None   # why the apply thread stopped
        self._wake = threading.Event()
        self._stop = threading.Event()
        self._applied_cv = threading.Condition()
        self._pending: _Frame | None = None
        self._published = 0
        self._applied = 0
        self._applied_number = 0
        self._dropped = 0
        self._failed = 0
        self._done_number = 0          # the latest frame the apply thread finished (drawn or failed)
        self._done_failed: BaseException | None = None   # its error, if it failed
        self._unreported: tuple[int, BaseException] | None = None  # a failure publish_frame has not raised yet
        self.last_error: BaseException | None = None
        # scene bookkeeping (touched only by the apply thread, read under _state_lock)
        self._state_lock = threading.Lock()
        self._signature: tuple | None = None   # (names, shapes) of the scene built
        self._bodies: dict = {}     # name -> {"node", "shape", "axes"}
        self._vectors: list = []    # [{"node", "shaft", "head", "label"}]
        self._cache: dict = {}      # (handle id, prop) -> last value assigned
        self._state: dict = {"frame": 0, "t": None, "bodies": {}, "axes": {}, "vectors": [], "hidden": []}
        self.controls = Controls(self.server.gui, self._republish)
        self._thread = threading.Thread(target=self._run, name="lavendersim-viewer", daemon=True)
        self._thread.start()
        # a viewer left open (a notebook, a script) is closed at interpreter exit before viser stops
        # its server (atexit runs last-registered first), so a player never writes to a stopped one
        ref = weakref.ref(self)

        def at_exit() -> None:
            if (v := ref()) is not None:
                v.close()
        self._at_exit = at_exit
        atexit.register(self._at_exit)

    # ---- public ---------------------------------------------------------------------------
    @property
    def url(self) -> str:
        """The page's address, ``http://HOST:PORT/``."""
        host = {"0.0.0.0": "127.0.0.1", "::": "::1"}.get(self.host, self.host)
        if ":" in host:   # an IPv6 literal
            host = f"[{host}]"
        return f"http://{host}:{self.port}/"

    def publish_frame(self, sim: Sim, overlays: Mapping[str, Any] | None = None) -> int:
        """Validate ``overlays`` against ``sim``'s bodies, snapshot the poses, store as the latest
        frame and return its number. Never waits for a browser or for the scene update.

        Parameters
        ----------
        sim : Sim
            Its bodies are drawn at their current poses.
        overlays : mapping, optional
            Axes and vectors (see :func:`validate_overlays`).

        Returns
        -------
        int
            The frame's number (for :meth:`wait_applied`).

        Raises
        ------
        LavenderInputError
            On a bad payload (nothing is drawn).
        ViewerError
            If the previous frame could not be drawn.
        """
        names, x, bodies = self._sim_parts(sim)
        ov = validate_overlays(overlays, names)
        pose = np.concatenate([x[:, LY.STATE_P_W], x[:, LY.STATE_Q]], axis=1).astype(float)  # POSE_P, POSE_Q
        if not np.all(np.isfinite(pose)):
            raise V.LavenderInputError("sim", "state is not finite (diverged?); nothing published")
        if np.max(np.abs(pose[:, POSE_P])) > FLOAT32_MAX:
            raise V.LavenderInputError("sim", f"a body position is beyond ±{FLOAT32_MAX:g} m (drawn in float32); "
                                       "nothing published")
        f = _Frame(float(getattr(sim, "t", 0.0)), tuple(names), tuple(_shape_of(bodies[n]) for n in names), pose, ov,
                   time.perf_counter())
        with self._lock:
            if self._stop.is_set():
                raise RuntimeError("viewer is closed")
            failed, self._unreported = self._unreported, None
            if failed is not None:
                raise ViewerError(f"frame {failed[0]} could not be drawn: {failed[1]!r}; this frame was not "
                                  "published (the next call publishes)") from failed[1]
            self._published += 1
            f.number = self._published
            if self._pending is not None:
                self._dropped += 1
            self._pending = self._last = f
        self._wake.set()
        return f.number

    def _republish(self) -> int:
        """Draw the latest frame again (a control changed what is shown); returns the number to
        wait for (a new one, or the frame still pending)."""
        with self._lock:
            if self._stop.is_set() or self._last is None:
                return self._published
            if self._pending is None:
                self._published += 1
                self._pending = self._last = dataclasses.replace(self._last, number=self._published)
            number = self._pending.number
        self._wake.set()
        return number

    def wait_applied(self, number: int, timeout: float = 5.0) -> bool:
        """Block until frame ``number`` (or a later one) is in the viser scene; False on timeout.
        Raises :class:`ViewerError` when the apply thread failed to draw it (the latest frame it
        processed is ``number`` or later and failed). For tests and scripts; the simulation loop
        never needs it.

        Parameters
        ----------
        number : int
            A frame number from :meth:`publish_frame`.
        timeout : float, optional
            Seconds to wait.

        Returns
        -------
        bool
            True once applied, False on timeout.
        """
        number = V.integer("number", number, minimum=0)
        timeout = V.scalar("timeout", timeout, nonnegative=True)
        deadline = time.monotonic() + timeout
        with self._applied_cv:
            while self._done_number < number:
                left = deadline - time.monotonic()
                if left <= 0 or self._stop.is_set():
                    return False
                self._applied_cv.wait(left)
            failed, done = self._done_failed, self._done_number
        if failed is not None:
            with self._lock:
                if self._unreported is not None and self._unreported[0] == done:
                    self._unreported = None  # reported here
            raise ViewerError(f"frame {done} could not be drawn: {failed!r}") from failed
        return True

    def scene_state(self) -> dict[str, Any]:
        """What the viser scene shows now (deep copy): frame number, t, per-body position and
        wxyz, axes per body, the drawn vectors (label, start, end, rgb, opacity), and the vector
        toggles switched off in this frame (``"hidden"``)."""
        with self._state_lock:
            return copy.deepcopy(self._state)

    def handles(self) -> dict[str, Any]:
        """The viser scene handles: {"bodies": {name: node}, "axes": {name: frame handle},
        "vectors": [{"node", "shaft", "head", "label"}]} (read them, don't assign)."""
        with self._state_lock:
            return {"bodies": {n: b["node"] for n, b in self._bodies.items()},
                    "axes": {n: b["axes"] for n, b in self._bodies.items()},
                    "vectors": [dict(v) for v in self._vectors]}

    def clients(self) -> int:
        """Number of connected browser tabs."""
        return len(self.server.get_clients())

    def stats(self) -> dict[str, Any]:
        """Counters: frames published, applied, dropped (coalesced), failed; clients; the last error."""
        with self._lock:
            return {"published": self._published, "applied": self._applied, "dropped": self._dropped, "failed": self._failed,
                    "clients": self.clients(), "last_error": repr(self.last_error) if self.last_error else None}

    def threads(self) -> dict[str, dict[str, Any]]:
        """The viewer's threads and why each stopped: ``{"apply": {...}, "player": {...}}`` (the
        player only when one was started), each ``{"alive": bool, "stop_reason": str or None}``.

        Returns
        -------
        dict
        """
        out = {"apply": {"alive": self._thread.is_alive(), "stop_reason": self.stop_reason}}
        p = self.player
        if p is not None and p.thread is not None:
            out["player"] = {"alive": p.thread.is_alive(), "stop_reason": p.stop_reason, "state": p.state}
        return out

    def close(self) -> None:
        """Stop the player, the apply thread and the server (idempotent). Each thread is joined
        with a deadline of JOIN_TIMEOUT_S (lavendersim._playback); one still running then says so in :meth:`threads`."""
        if self._stop.is_set():
            return
        atexit.unregister(self._at_exit)
        if self.player is not None:
            self.player.stop(PB.JOIN_TIMEOUT_S)
        self._stop.set()
        self._wake.set()
        with self._applied_cv:
            self._applied_cv.notify_all()
        self._thread.join(PB.JOIN_TIMEOUT_S)
        if self._thread.is_alive():
            self.stop_reason = f"still running {PB.JOIN_TIMEOUT_S:g} s after close() (a stuck scene update?)"
        self.server.stop()

    # ---- playback ---------------------------------------------------------------------------
    @V.keywords
    def play(self, sim: Sim, overlays: Callable[[Sim], Mapping[str, Any] | None] | None = None,
             advance: Callable[[Sim, float], None] | None = None, *, rate_hz: float = 60.0,
             duration: float | None = None, speed: float | None = None, paused: bool = False,
             start: bool = True) -> Player:
        """Drive a live Sim in a background thread: ``rate_hz`` frames per wall-clock second, each
        advancing ``speed / rate_hz`` simulated seconds, with the Pause/Resume button and the speed
        slider in the page. Replaces a running player. Returns at once (the player runs until
        `duration`, :meth:`Player.stop` or :meth:`close`).

        Parameters
        ----------
        sim : Sim
            Advanced by the player's thread (leave it alone meanwhile).
        overlays : callable, optional
            ``overlays(sim)`` -> payload (see :func:`validate_overlays`) for each frame.
        advance : callable, optional
            ``advance(sim, seconds)`` (default ``sim.run_for``), e.g. a controller's loop.
        rate_hz : float, optional
            Frames per wall-clock second.
        duration : float or None, optional
            Stop at this simulated time, s (None: run until stopped).
        speed : float or None, optional
            Initial speed (None: keep the slider's).
        paused : bool, optional
            Start paused.
        start : bool, optional
            False: do not start the thread (drive it with :meth:`Player.tick` / :meth:`Player.run`).

        Returns
        -------
        Player

        Raises
        ------
        LavenderInputError
            On a bad argument (nothing started).
        """
        self._sim_parts(sim)
        for field, fn in (("overlays", overlays), ("advance", advance)):
            if fn is not None and not callable(fn):
                raise V.LavenderInputError(field, "expected a callable or None", f", got {V._describe(fn)}")
        if duration is not None:
            duration = V.scalar("duration", duration, nonnegative=True)
        return self._start(PB._LiveSource(sim, overlays, advance, duration), rate_hz, speed, paused, start, None)

    @V.keywords
    def replay(self, trajectory: Trajectory, bodies: Any, overlays: Any = None, *, rate_hz: float = 30.0,
               speed: float | None = None, loop: bool = False, paused: bool = False, start: bool = True) -> Player:
        """Play a recorded Trajectory back in a background thread, with a time slider (drag it to any
        sample, paused or not), the Pause/Resume button and the speed slider. Played through, it
        pauses at the end (resume: from the start) unless `loop`. Returns at once.

        Parameters
        ----------
        trajectory : Trajectory
            From :meth:`Sim.record`: names, t (T,), x (T, nb, 13).
        bodies : Sim, Scene or mapping
            The bodies (name -> Body) whose shapes are drawn; every trajectory body must be there.
        overlays : None, callable or sequence, optional
            None: each body's axes and its angular velocity ω (world) as an arrow; a callable
            ``overlays(snapshot)`` -> payload, given a :class:`Snapshot` of the sample; or one payload
            per sample (length T).
        rate_hz : float, optional
            Frames per wall-clock second.
        speed : float or None, optional
            Initial speed, simulated s per wall-clock s (None: keep the slider's).
        loop : bool, optional
            Start over at the end instead of pausing there.
        paused : bool, optional
            Start paused (at the first sample).
        start : bool, optional
            False: do not start the thread (drive it with :meth:`Player.tick` / :meth:`Player.run`).

        Returns
        -------
        Player

        Raises
        ------
        LavenderInputError
            Naming ``trajectory``, ``bodies``, ``overlays`` or an option when it is bad (nothing started).
        """
        found, overlays = PB.check_trajectory(trajectory, bodies, overlays)
        source = PB._ReplaySource(trajectory, found, overlays, PB.flag("loop", loop))
        snap, payload = source.frame()          # the first sample draws: a bad payload stops here
        validate_overlays(payload, snap.names)
        return self._start(source, rate_hz, speed, paused, start, source.t)

    def _start(self, source, rate_hz, speed, paused, start, times) -> Player:
        rate_hz = V.positive("rate_hz", rate_hz)
        if not MIN_RATE_HZ <= rate_hz <= PB.MAX_RATE_HZ:
            raise V.LavenderInputError("rate_hz", f"must be within [{MIN_RATE_HZ:g}, {PB.MAX_RATE_HZ:g}] frames per second",
                                       f", got {rate_hz!r}")
        PB.flag("paused", paused)
        PB.flag("start", start)
        if speed is not None:
            speed = V.positive("speed", speed)
            if not PB.SPEED_MIN <= speed <= PB.SPEED_MAX:
                raise V.LavenderInputError("speed", f"must be within [{PB.SPEED_MIN:g}, {PB.SPEED_MAX:g}]", f", got {speed!r}")
        if self._stop.is_set():
            raise RuntimeError("viewer is closed")
        if self.player is not None:
            self.player.stop(PB.JOIN_TIMEOUT_S)
        player = Player(self, source, rate_hz)
        if speed is not None:
            self.controls.set_speed(speed)
        self.controls.set_paused(paused)
        self.controls.add_playback(times, player.seek if times is not None else None)
        self.player = player
        if start:
            player.start()
        return player

    # ---- in a notebook ------------------------------------------------------------------------
    def _inline_html(self, height: int) -> str:
        url = html.escape(self.url, quote=True)
        return (f'<iframe src="{url}" width="100%" height="{height}" style="border: 1px solid #ddd" '
                f'title="LavenderSim viewer"></iframe>'
                f'<p>LavenderSim viewer: <a href="{url}" target="_blank">{url}</a> (opens it in a tab)</p>')

    def _repr_html_(self) -> str:
        """A notebook shows the page inline (an iframe) and a link to it."""
        return self._inline_html(INLINE_HEIGHT)

    def show(self, height: int = INLINE_HEIGHT) -> None:
        """Show the page inline in a notebook (an iframe of :attr:`url` and a link); outside a
        notebook, print the link. The iframe works from a Jupyter whose browser runs on this
        machine (the viewer binds 127.0.0.1 by default); from a remote Jupyter, forward the port.

        Parameters
        ----------
        height : int, optional
            Height of the inline frame, px (>= 100).
        """
        height = V.integer("height", height, minimum=100)
        try:
            from IPython import get_ipython
            from IPython.display import HTML, display
            shell = get_ipython()
        except ImportError:
            shell = None
        if shell is not None:
            display(HTML(self._inline_html(height)))
        else:
            print(f"LavenderSim viewer: {self.url}")

    def __enter__(self) -> Self:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    # ---- internals ------------------------------------------------------------------------
    @staticmethod
    def _sim_parts(sim):
        names = getattr(sim, "names", None)
        x = getattr(sim, "x", None)
        bodies = getattr(sim, "bodies", None)
        if names is None or x is None or bodies is None:
            raise V.LavenderInputError("sim", "expected a lavendersim.Sim (names, bodies, x)", f", got {type(sim).__name__}")
        x = np.asarray(x)
        if x.ndim != 2 or x.shape[0] != len(names) or x.shape[1] < max(LY.STATE_P_W.stop, LY.STATE_Q.stop):
            raise V.LavenderInputError("sim", f"state must have shape ({len(names)}, {LY.STATE_SIZE})", f", got {x.shape}")
        return list(names), x, bodies

    def _run(self) -> None:
        try:
            self._serve()
            self.stop_reason = "closed"
        except BaseException as exc:   # recorded for threads(); the thread ends
            self.stop_reason = f"error: {exc!r}"
            raise

    def _serve(self) -> None:
        period = 1.0 / self.max_rate_hz
        next_at = 0.0
        while not self._stop.is_set():
            self._wake.wait(timeout=0.5)
            if self._stop.is_set():
                break
            delay = next_at - time.monotonic()
            if delay > 0 and self._stop.wait(delay):
                break
            with self._lock:
                f, self._pending = self._pending, None
                self._wake.clear()
            if f is None:
                continue
            next_at = time.monotonic() + period
            error = None
            try:
                self._apply(f)
            except Exception as exc:  # keep serving; publish_frame / wait_applied report it
                if repr(exc) != repr(self.last_error):
                    print(f"lavendersim viewer: could not draw frame {f.number}: {exc!r}", file=sys.stderr)
                self.last_error = error = exc
                self._signature = None  # rebuild the scene on the next frame
            with self._lock:
                if error is None:
                    self._applied += 1
                else:
                    self._failed += 1
                    self._unreported = (f.number, error)
            with self._applied_cv:
                self._done_number = f.number
                self._done_failed = error
                if error is None:
                    self._applied_number = f.number
                self._applied_cv.notify_all()

    def _set(self, handle, prop: str, value) -> None:
        """Assign a handle property only when it changed (keeps the websocket traffic small)."""
        key = (id(handle), prop)
        v = tuple(np.round(np.asarray(value, dtype=float).ravel(), 7)) if not isinstance(value, (str, bool, type(None))) else value
        if self._cache.get(key, object()) != v:
            setattr(handle, prop, value)
            self._cache[key] = v

    def _build(self, f: _Frame) -> None:
        sc = self.server.scene
        for b in self._bodies.values():
            b["node"].remove()
        self._bodies, self._cache = {}, {}
        ext = max(_extent(k, d) for k, d in f.shapes)
        self._ref = ext
        for i, (name, (kind, dims)) in enumerate(zip(f.names, f.shapes)):
            node = sc.add_frame(node_name(name), show_axes=False)
            color = BODY_COLORS[i % len(BODY_COLORS)]
            if kind == "box":
                sc.add_box(f"{node_name(name)}/shape", color=color, dimensions=dims)
            elif kind == "sphere":
                sc.add_icosphere(f"{node_name(name)}/shape", radius=dims[0], color=color, subdivisions=3)
            else:
                v, fc = _cylinder_mesh(dims[0], -dims[1] / 2, dims[1] / 2, 32)
                sc.add_mesh_simple(f"{node_name(name)}/shape", v, fc, color=color, flat_shading=False)
            axes = sc.add_frame(f"{node_name(name)}/axes", axes_length=DEFAULT_AXES_SCALE, axes_radius=0.012, visible=False)
            self._bodies[name] = {"node": node, "shape": (kind, dims), "axes": axes}
        centre = f.pose[:, POSE_P].mean(axis=0)
        span = max(ext, float(np.ptp(f.pose[:, POSE_P], axis=0).max()) if len(f.names) > 1 else ext)
        self.server.initial_camera.look_at = tuple(centre)
        self.server.initial_camera.position = tuple(centre + span * np.array([1.3, -1.8, 1.0]))
        self._signature = (f.names, f.shapes)

    def _vector_handles(self, k: int) -> dict:
        while len(self._vectors) <= k:
            sc, i = self.server.scene, len(self._vectors)
            r = self._arrow_radius or max(0.004, 0.025 * self._ref)
            node = sc.add_frame(f"/vectors/{i}", show_axes=False)
            sv, sf = _cylinder_mesh(r, 0.0, 1.0, 20)
            hv, hf = _cone_mesh(2.4 * r, 20)
            self._vectors.append({
                "node": node,
                "shaft": sc.add_mesh_simple(f"/vectors/{i}/shaft", sv, sf, cast_shadow=False, receive_shadow=False),
                "head": sc.add_mesh_simple(f"/vectors/{i}/head", hv, hf, cast_shadow=False, receive_shadow=False),
                "label": sc.add_label(f"/vectors/{i}/label", "", anchor="center-left"),
                "radius": r,
            })
        return self._vectors[k]

    def _apply(self, f: _Frame) -> None:
        state: dict[str, Any] = {"frame": f.number, "t": f.t, "bodies": {}, "axes": {}, "vectors": [], "hidden": []}
        ctl = self.controls
        keys = [PB.vector_key(k, v["label"]) for k, v in enumerate(f.overlays["vectors"])]
        ctl.ensure_vector_toggles(keys)
        with self.server.atomic():
            if (f.names, f.shapes) != self._signature:
                self._build(f)
            for i, name in enumerate(f.names):
                b = self._bodies[name]
                pos, wxyz = f.pose[i, POSE_P], xyzw_to_wxyz(f.pose[i, POSE_Q])
                b["node"].position = pos
                b["node"].wxyz = wxyz
                state["bodies"][name] = {"position": pos.tolist(), "wxyz": wxyz.tolist(), "shape": b["shape"]}
            axes = {a["body"]: a["scale"] for a in f.overlays["axes"]} if ctl.show_axes else {}
            for name, b in self._bodies.items():
                on = name in axes
                if on:
                    self._set(b["axes"], "axes_length", axes[name])
                    self._set(b["axes"], "axes_radius", 0.04 * axes[name])
                    self._set(b["axes"], "origin_radius", 0.06 * axes[name])
                    state["axes"][name] = axes[name]
                self._set(b["axes"], "visible", on)
            for k, v in enumerate(f.overlays["vectors"]):
                h = self._vector_handles(k)
                if not ctl.vector_shown(keys[k]):
                    self._set(h["node"], "visible", False)
                    state["hidden"].append(keys[k])
                    continue
                d = v["scale"] * v["vector"]
                length = V.safe_norm(d)
                rgb = tuple(int(round(255 * c)) for c in v["color"][:3])
                alpha = float(v["color"][3])
                state["vectors"].append({"label": v["label"], "start": v["origin"].tolist(),
                                         "end": (v["origin"] + d).tolist(), "rgb": rgb, "opacity": alpha})
                if length < 1e-9:
                    self._set(h["node"], "visible", False)
                    continue
                head = min(6.0 * h["radius"], 0.5 * length)
                h["node"].position = v["origin"]
                h["node"].wxyz = _z_to(d / length)
                self._set(h["shaft"], "scale", (1.0, 1.0, length - head))
                self._set(h["head"], "position", (0.0, 0.0, length - head))
                self._set(h["head"], "scale", (1.0, 1.0, head))
                for part in ("shaft", "head"):
                    self._set(h[part], "color", rgb)
                    self._set(h[part], "opacity", None if alpha >= 1.0 else alpha)
                self._set(h["label"], "text", v["label"])
                self._set(h["label"], "position", (0.0, 0.0, length + 4.0 * h["radius"]))
                self._set(h["node"], "visible", True)
            for h in self._vectors[len(f.overlays["vectors"]):]:
                self._set(h["node"], "visible", False)
            self._status.content = f"**frame {f.number}** · t = {f.t:.3f} s" + (" · paused" if ctl.paused else "")
        with self._state_lock:
            self._state = state


# --------------------------------------------------------------------------
# live scenes for `lavendersim view NAME`
# --------------------------------------------------------------------------


def _tumble_scene():
    """A torque-free box (0.4 x 0.25 x 0.1 m, 1 kg) tumbling near its intermediate axis: body axes,
    angular velocity (world) and the conserved world angular momentum."""
    from .bodies import Body
    from .scene import Scene
    from .sim import Sim

    scene = Scene()
    scene.add_body(Body.box("box", 1.0, (0.4, 0.25, 0.1), omega_b=(0.05, 4.0, 0.05)))
    sim = Sim(scene, dt=1e-3)

    def overlays(sim):
        s = sim.state("box")
        L = sim.angular_momentum_w("box")
        return {"axes": [{"body": "box", "scale": 0.4}],
                "vectors": [
                    {"label": "angular velocity ω", "origin": s.p_w.tolist(), "vector": s.omega_w.tolist(),
                     "scale": 0.15, "color": [0.51, 0.87, 0.76, 0.95]},
                    {"label": "angular momentum L (conserved)", "origin": s.p_w.tolist(), "vector": L.tolist(),
                     "scale": 20.0, "color": [0.95, 0.66, 0.77, 0.95]}]}

    return sim, overlays, lambda sim, dt: sim.run_for(dt)


def _wheel_scene():
    """The reaction-wheel cube balancing on its corner (lavendersim.control's Cubli-like model,
    15 cm, 1 kg) from a 3° tilt under LQR wheel control: cube axes, angular velocity and the
    motor torque acting on the cube (−u), as in the chapter's example payload."""
    from .sim import Sim
    from . import control as C

    scene = C.chapter_cube("corner")
    ctrl = C.design(scene, period=2e-3, q_ref=C.cube_upright_q("corner"), weights={"attitude_deg": 0.5})
    sim = Sim(C.chapter_cube("corner", q=C.rotated(ctrl.q_ref, (1.0, -1.0, 0.0), 3.0)), dt=1e-3)

    def advance(sim, dt):
        for _ in range(max(1, int(round(dt / ctrl.Ts)))):
            st = sim.state(C.BODY)
            sim.set_wheel_command(C.BODY, ctrl.command(st.q, st.omega_b, sim.wheel_rates(C.BODY)))
            sim.run(int(round(ctrl.Ts / sim.dt)))

    def overlays(sim):
        s = sim.state(C.BODY)
        tau_cube_w = -np.asarray(KN.quat_rotate(s.q, sim.wheel_command_applied(C.BODY)))
        return {"axes": [{"body": C.BODY, "scale": 0.34}],
                "vectors": [
                    {"label": "angular velocity", "origin": s.p_w.tolist(), "vector": s.omega_w.tolist(),
                     "scale": 0.12, "color": [0.51, 0.87, 0.76, 0.95]},
                    {"label": "torque", "origin": s.p_w.tolist(), "vector": tau_cube_w.tolist(),
                     "scale": 3.0, "color": [0.95, 0.66, 0.77, 0.95]}]}

    return sim, overlays, advance


# name -> builder () -> (sim, overlays, advance): the built-in scenes; register_scene adds more (the labs add
# theirs from the CLI layer: library code does not import labs)
SCENES = {"tumble": _tumble_scene, "wheel": _wheel_scene}


def register_scene(name: str, builder: Callable[[], tuple]) -> None:
    """Make a scene available to :func:`run_scene` (and ``lavendersim view NAME``) under `name`.

    Parameters
    ----------
    name : str
        A new, non-empty scene name (registering the same builder again under its name is a no-op).
    builder : callable
        ``builder() -> (sim, overlays, advance)`` as the built-in scenes: a Sim, ``overlays(sim) -> dict``
        (see :func:`validate_overlays`) and ``advance(sim, dt)``.

    Raises
    ------
    LavenderInputError
        `name` empty, not a string, or taken by another builder; `builder` not callable.
    """
    if not isinstance(name, str) or not name:
        raise V.LavenderInputError("name", "must be a non-empty string", f", got {name!r}")
    if not callable(builder):
        raise V.LavenderInputError("builder", "must be callable: builder() -> (sim, overlays, advance)",
                                   f", got {type(builder).__name__}")
    if SCENES.get(name, builder) is not builder:
        raise V.LavenderInputError("name", f"scene {name!r} is taken (scenes: {', '.join(SCENES)})")
    SCENES[name] = builder


@V.keywords
def run_scene(name: str, *, duration: float | None = None, host: str = DEFAULT_HOST, port: int = DEFAULT_PORT,
              rate_hz: float = 60.0, viewer: Viewer | None = None, out: TextIO = sys.stdout,
              replay: bool = False) -> dict[str, Any]:
    """Run scene ``name`` in real time, publishing ``rate_hz`` frames per second, for ``duration``
    seconds of simulated time (None: until interrupted), with the page's Pause/Resume button and
    speed slider. With ``replay``: record ``duration`` simulated seconds (default DEFAULT_REPLAY_S)
    first, then replay them with a time slider until interrupted. Returns the viewer's stats.

    Parameters
    ----------
    name : str
        A scene of SCENES (``"tumble"``, ``"wheel"``, ...).
    duration : float or None, optional
        Simulated seconds (None: until Ctrl-C; with `replay`: DEFAULT_REPLAY_S recorded).
    host, port : optional
        Where to serve (when `viewer` is None).
    rate_hz : float, optional
        Frames per second (live: per simulated second at speed 1; a replay samples at this rate).
    viewer : Viewer, optional
        An existing viewer (its player is stopped on return, the viewer is left open).
    out : text stream, optional
        Where the URL line is printed.
    replay : bool, optional
        Record first, then replay with a time slider.

    Returns
    -------
    dict
        :meth:`Viewer.stats`.
    """
    V.choice("scene", name, SCENES)
    if duration is not None:
        duration = V.scalar("duration", duration, nonnegative=True)
    rate_hz = V.positive("rate_hz", rate_hz)
    PB.flag("replay", replay)
    sim, overlays, advance = SCENES[name]()
    if not MIN_RATE_HZ <= rate_hz <= 1.0 / sim.dt:  # a frame must advance at least one step, at most 1/MIN_RATE_HZ s
        raise V.LavenderInputError("rate_hz", f"must be within [{MIN_RATE_HZ:g}, {1.0 / sim.dt:g}] frames per simulated "
                                   f"second (scene {name!r} steps dt = {sim.dt:g} s)", f", got {rate_hz!r}")
    record_s = DEFAULT_REPLAY_S if duration is None else duration   # (replay only)
    if replay and record_s * rate_hz > MAX_REPLAY_SAMPLES:
        raise V.LavenderInputError("duration", f"with replay, duration * rate_hz must be at most {MAX_REPLAY_SAMPLES} "
                                   "samples", f", got {record_s:g} s at {rate_hz:g} Hz")
    own = viewer is None
    viewer = viewer or Viewer(host, port)
    print(f"lavendersim view {name}: open {viewer.url}  (Ctrl-C to stop)", file=out, flush=True)
    player = None
    try:
        if replay:
            print(f"lavendersim view {name}: recording {record_s:g} s ...", file=out, flush=True)
            traj, payloads = _record_scene(sim, overlays, advance, record_s, rate_hz)
            player = viewer.replay(traj, sim, payloads, rate_hz=rate_hz, start=False)
            print(f"lavendersim view {name}: replaying {len(traj.t)} samples (t = 0 to {traj.t[-1]:.3f} s); "
                  "Pause, speed and time are in the page's side panel", file=out, flush=True)
        else:
            player = viewer.play(sim, overlays, advance, rate_hz=rate_hz, duration=duration, start=False)
        player.run()
    except KeyboardInterrupt:    # while recording
        pass
    finally:
        stats = viewer.stats()
        if own:
            viewer.close()
        elif player is not None:
            player.stop()
    print(f"lavendersim view {name}: t = {(player.t if player else sim.t):.3f} s, {stats['published']} frames published, "
          f"{stats['applied']} sent, {stats['dropped']} coalesced", file=out)
    return stats


def _record_scene(sim, overlays, advance, seconds: float, rate_hz: float):
    """A scene's states and payloads every 1/rate_hz simulated seconds up to `seconds`, as a
    Trajectory (wheel rates not recorded: zeros) and the list of payloads."""
    from .sim import Trajectory

    ts, xs, payloads = [sim.t], [np.array(sim.x, copy=True)], [overlays(sim)]
    while sim.t < seconds - 0.5 * sim.dt:
        advance(sim, max(sim.dt, min(1.0 / rate_hz, seconds - sim.t)))
        ts.append(sim.t)
        xs.append(np.array(sim.x, copy=True))
        payloads.append(overlays(sim))
    return Trajectory(list(sim.names), np.array(ts), np.stack(xs)), payloads
