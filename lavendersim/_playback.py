"""Playback for the browser viewer: its GUI controls and the Player that drives it.

:class:`Controls` holds what a learner reaches for in the page's side panel and the state behind
it: pause/resume, a speed slider (simulated seconds per wall-clock second), a checkbox for the body
axes and one per vector label, and, while a recorded Trajectory is replayed, a time slider. Every
control works the same from Python (``viewer.controls.pause()``), from a GUI handle
(``viewer.controls.handles["speed"].value = 2.0``, which runs the same callback as a browser) and
from the browser.

:class:`Player` drives a viewer at ``rate_hz`` frames per wall-clock second from a source: a live
Sim (advanced ``speed / rate_hz`` simulated seconds per frame) or a recorded Trajectory (the time
slider follows it, and dragging the slider seeks). Paused, the player waits on a condition (woken
by resume or stop, and at most every WAIT_SLICE_S seconds so Ctrl-C is seen): no frame is
published, the Sim does not advance and nothing spins. A player in its own thread is stopped with a
deadline (:meth:`Player.stop`), and it records why it stopped (``stop_reason``).

Used through :meth:`lavendersim.viewer.Viewer.play`, :meth:`~lavendersim.viewer.Viewer.replay` and
``lavendersim view``; see :mod:`lavendersim.viewer`.
"""
from __future__ import annotations

import math
import sys
import threading
import time
from collections.abc import Callable, Mapping, Sequence
from typing import TYPE_CHECKING, Any, Self

import numpy as np

from . import validate as V
from ._shapes import extent, shape_of
from .bodies import BodyState
from .generated import layout as LY

if TYPE_CHECKING:  # annotations only
    from .sim import Sim, Trajectory

SPEED_MIN, SPEED_MAX, SPEED_STEP = 0.05, 4.0, 0.05   # the speed slider: simulated s per wall-clock s
SPEED_MARKS = ((0.05, "0.05×"), (1.0, "1×"), (2.0, "2×"), (4.0, "4×"))
WAIT_SLICE_S = 0.5       # a paused player wakes at least this often (to see Ctrl-C / a stop), no more
JOIN_TIMEOUT_S = 10.0    # stopping a player thread waits this long for it
MAX_RATE_HZ = 1000.0     # frames per wall-clock second, at most
MAX_TOGGLES = 64         # vector checkboxes, at most (labels that change every frame would add one each)


def flag(field: str, value: object) -> bool:
    """``value`` when it is a bool; else LavenderInputError naming ``field``."""
    if not isinstance(value, bool):
        raise V.LavenderInputError(field, "expected a bool", f", got {V._describe(value)}")
    return value


def vector_key(k: int, label: str) -> str:
    """The toggle that shows or hides vector ``k``: its label, or ``"vector k+1"`` without one."""
    return label or f"vector {k + 1}"


class Controls:
    """The viewer's GUI controls and their state (see the module docstring).

    Parameters
    ----------
    gui : viser GuiApi
        ``server.gui`` of the viewer's viser server.
    on_change : callable
        Called without arguments after a change that alters the picture (a toggle, pause): the
        viewer redraws its latest frame.

    Attributes
    ----------
    handles : dict
        The viser GUI handles: ``"axes"`` (checkbox), ``"vectors"`` ({key: checkbox}), and while a
        player runs ``"pause"`` (button), ``"speed"`` (slider), and while replaying ``"time"`` (slider).
    untoggled : set of str
        Vector labels seen after MAX_TOGGLES checkboxes existed (always drawn).
    paused_wakeups : int
        How often a paused player woke up (bounded by elapsed / WAIT_SLICE_S plus the pause,
        resume and stop calls: it never spins).
    """

    def __init__(self, gui: Any, on_change: Callable[[], Any]) -> None:
        self._gui = gui
        self._on_change = on_change
        self._cv = threading.Condition()
        self._paused = False
        self._speed = 1.0
        self._show_axes = True
        self._vectors: dict[str, bool] = {}
        self._echo = threading.local()      # set while this thread moves the time slider itself
        self._on_seek: Callable[[float], Any] | None = None
        self._playback_folder = None
        self.paused_wakeups = 0
        self.untoggled: set[str] = set()     # vector labels beyond MAX_TOGGLES (drawn, no checkbox)
        self._show_folder = gui.add_folder("Show", order=20.0)
        with self._show_folder:
            axes = gui.add_checkbox("body axes", True, hint="the x (red), y (green), z (blue) axes of each body")
        axes.on_update(lambda event: self.set_show_axes(bool(event.target.value)))
        self.handles: dict[str, Any] = {"axes": axes, "vectors": {}}

    # ---- state ----------------------------------------------------------------------------
    @property
    def paused(self) -> bool:
        """Whether playback is paused."""
        return self._paused

    @property
    def speed(self) -> float:
        """Simulated seconds per wall-clock second."""
        return self._speed

    @property
    def show_axes(self) -> bool:
        """Whether body axes are drawn (the payload's ``axes``)."""
        return self._show_axes

    def vector_shown(self, key: str) -> bool:
        """Whether vectors with toggle `key` (:func:`vector_key`) are drawn.

        Parameters
        ----------
        key : str
            A vector's label (or ``"vector N"``).

        Returns
        -------
        bool
            True unless its checkbox is off.
        """
        return self._vectors.get(key, True)

    def vector_keys(self) -> list[str]:
        """The vector toggles, in the order they first appeared.

        Returns
        -------
        list of str
        """
        return list(self._vectors)

    # ---- changes (from Python, a GUI handle, or the browser) -------------------------------
    def pause(self) -> None:
        """Pause: the player publishes no frame and its Sim does not advance until :meth:`resume`."""
        self.set_paused(True)

    def resume(self) -> None:
        """Resume playback."""
        self.set_paused(False)

    def toggle_pause(self) -> None:
        """Pause if playing, resume if paused (the Pause/Resume button)."""
        with self._cv:
            paused = not self._paused
        self.set_paused(paused)

    def set_paused(self, paused: bool) -> None:
        """Pause (True) or resume (False).

        Parameters
        ----------
        paused : bool
        """
        flag("paused", paused)
        with self._cv:
            if paused == self._paused:
                return
            self._paused = paused
            self._cv.notify_all()
        button = self.handles.get("pause")
        if button is not None:
            button.label = "Resume" if paused else "Pause"
        self._on_change()

    def set_speed(self, speed: float) -> None:
        """Set the playback speed.

        Parameters
        ----------
        speed : float
            Simulated seconds per wall-clock second, in [SPEED_MIN, SPEED_MAX].

        Raises
        ------
        LavenderInputError
            Outside that range or not a real number.
        """
        speed = V.positive("speed", speed)
        if not SPEED_MIN - 1e-12 <= speed <= SPEED_MAX + 1e-12:
            raise V.LavenderInputError("speed", f"must be within [{SPEED_MIN:g}, {SPEED_MAX:g}] (simulated s per "
                                       "wall-clock s)", f", got {speed!r}")
        with self._cv:
            self._speed = speed
        slider = self.handles.get("speed")
        if slider is not None and slider.value != speed:
            slider.value = speed

    def set_show_axes(self, show: bool) -> None:
        """Draw (True) or hide (False) every body's axes.

        Parameters
        ----------
        show : bool
        """
        flag("show", show)
        with self._cv:
            if show == self._show_axes:
                return
            self._show_axes = show
        self.handles["axes"].value = show
        self._on_change()

    def set_vector_shown(self, key: str, show: bool) -> None:
        """Draw (True) or hide (False) the vectors with toggle `key`.

        Parameters
        ----------
        key : str
            A vector's label (or ``"vector N"``); a key not drawn yet is remembered for when it is.
        show : bool
        """
        if not isinstance(key, str):
            raise V.LavenderInputError("key", "expected a vector label (str)", f", got {V._describe(key)}")
        flag("show", show)
        with self._cv:
            if self._vectors.get(key, True) == show and key in self._vectors:
                return
            self._vectors[key] = show
        box = self.handles["vectors"].get(key)
        if box is not None:
            box.value = show
        self._on_change()

    # ---- for the viewer and the player -----------------------------------------------------
    def ensure_vector_toggles(self, keys: Sequence[str]) -> None:
        """Add a checkbox for each key that has none yet (the viewer's apply thread calls this).

        Parameters
        ----------
        keys : sequence of str
        """
        for key in keys:
            if key in self.handles["vectors"]:
                continue
            if len(self.handles["vectors"]) >= MAX_TOGGLES:    # no checkbox: always drawn
                self.untoggled.add(key)
                continue
            with self._cv:
                shown = self._vectors.setdefault(key, True)
            with self._show_folder:
                box = self._gui.add_checkbox(key, shown, hint=f"draw the arrow {key!r}")
            box.on_update(lambda event, key=key: self.set_vector_shown(key, bool(event.target.value)))
            self.handles["vectors"][key] = box

    def wait_while_paused(self, stop: threading.Event) -> None:
        """Block while paused and `stop` is not set (woken by resume and :meth:`wake`; at most every
        WAIT_SLICE_S seconds otherwise).

        Parameters
        ----------
        stop : threading.Event
        """
        with self._cv:
            while self._paused and not stop.is_set():
                self._cv.wait(WAIT_SLICE_S)
                self.paused_wakeups += 1

    def wake(self) -> None:
        """Wake every waiter of :meth:`wait_while_paused` (a player being stopped)."""
        with self._cv:
            self._cv.notify_all()

    def add_playback(self, times: np.ndarray | None, on_seek: Callable[[float], Any] | None) -> None:
        """Show the Playback folder: the Pause/Resume button, the speed slider and, for a replay
        (`times` given), a time slider calling ``on_seek(t)`` when moved by anything but
        :meth:`show_time`. Replaces a previous Playback folder.

        Parameters
        ----------
        times : ndarray, shape (T,), or None
            The replayed samples' times, s.
        on_seek : callable or None
            Called with the time (s) chosen on the slider.
        """
        self.remove_playback()
        gui = self._gui
        folder = gui.add_folder("Playback", order=10.0)
        with folder:
            button = gui.add_button("Resume" if self._paused else "Pause", hint="pause or resume the motion")
            speed = gui.add_slider("speed ×", SPEED_MIN, SPEED_MAX, SPEED_STEP, self._speed, marks=SPEED_MARKS,
                                   hint="simulated seconds per wall-clock second")
            handles = {"pause": button, "speed": speed}
            if times is not None:
                t0, t1 = float(times[0]), float(times[-1])
                step = float(np.min(np.diff(times))) if len(times) > 1 else 1.0
                handles["time"] = gui.add_slider("time (s)", t0, t1, step, t0, hint="drag to any recorded instant")
        button.on_click(lambda _event: self.toggle_pause())
        # a number typed into the slider's box may lie outside it: clamped, never an error in viser's thread
        speed.on_update(lambda event: self.set_speed(min(max(float(event.target.value), SPEED_MIN), SPEED_MAX)))
        if "time" in handles:
            self._on_seek = on_seek
            handles["time"].on_update(self._time_moved)
        self.handles.update(handles)
        self._playback_folder = folder

    def remove_playback(self) -> None:
        """Remove the Playback folder, if shown."""
        if self._playback_folder is not None:
            self._playback_folder.remove()
            self._playback_folder = None
        for name in ("pause", "speed", "time"):
            self.handles.pop(name, None)
        self._on_seek = None

    def show_time(self, t: float) -> None:
        """Move the time slider to `t` without seeking (the player following its replay).

        Parameters
        ----------
        t : float
            Seconds.
        """
        slider = self.handles.get("time")
        if slider is None:
            return
        self._echo.active = True
        try:
            slider.value = float(t)
        finally:
            self._echo.active = False

    def _time_moved(self, event: Any) -> None:
        if getattr(self._echo, "active", False) or self._on_seek is None:
            return
        self._on_seek(float(event.target.value))


# --------------------------------------------------------------------------
# sources
# --------------------------------------------------------------------------


class Snapshot:
    """One recorded sample, shaped like a Sim for :meth:`Viewer.publish_frame` and for a replay's
    overlays callable.

    Parameters
    ----------
    names : list of str
        Body names.
    t : float
        Sample time, s.
    x : ndarray, shape (nb, 13)
        Body states ``[p_w, q (x, y, z, w), v_w, omega_b]`` (SI units).
    Omega : ndarray, shape (nb, k)
        Wheel rates relative to each body, rad/s (a Sim's WHEELS_MAX slots, or three per body).
    bodies : mapping
        Body name -> :class:`~lavendersim.Body` (their shapes are drawn).
    wheel_counts : ndarray of int, shape (nb,), optional
        Wheels per body: ``state(name).Omega`` then has that many rates (three zeros without wheels).
    """

    def __init__(self, names: list[str], t: float, x: np.ndarray, Omega: np.ndarray, bodies: Mapping[str, Any],
                 wheel_counts: np.ndarray | None = None) -> None:
        self.names, self.t, self.x, self.Omega, self.bodies = names, t, x, Omega, bodies
        self.wheel_counts = wheel_counts

    def state(self, name: str) -> BodyState:
        """The state of body `name` at this sample.

        Parameters
        ----------
        name : str
            A body name.

        Returns
        -------
        BodyState
        """
        if name not in self.names:
            raise V.LavenderInputError("body", f"unknown body {name!r}; bodies: {', '.join(self.names)}")
        i = self.names.index(name)
        if self.wheel_counts is None:
            return BodyState(self.x[i], self.Omega[i])
        return BodyState.of_slots(self.x[i], self.Omega[i], int(self.wheel_counts[i]))


class _LiveSource:
    """A Sim advanced by ``advance(sim, seconds)`` (default ``Sim.run_for``), up to `duration`."""

    def __init__(self, sim: Sim, overlays: Callable | None, advance: Callable | None, duration: float | None):
        self.sim, self.overlays, self.duration = sim, overlays, duration
        self._advance = advance or (lambda s, d: s.run_for(d))
        self._owed = 0.0     # simulated seconds asked for and not yet advanced (fractions of a step)

    @property
    def finished(self) -> bool:
        """At the duration: less than half a step left (a duration between steps rounds to one)."""
        return self.duration is not None and self.duration - self.sim.t <= 0.5 * self.sim.dt * (1 + 1e-9)

    def advance(self, seconds: float) -> int:
        """Advance by `seconds` of simulated time, in whole steps; returns the steps taken."""
        sim = self.sim
        self._owed += seconds
        left = None if self.duration is None else self.duration - sim.t
        if left is not None and self._owed >= left:       # the last frame: to the step nearest the duration
            self._owed = left
            n = round(left / sim.dt)
        else:
            n = math.floor(self._owed / sim.dt + 1e-9)
        if n < 1:
            return 0
        t0 = sim.t
        self._advance(sim, n * sim.dt)
        self._owed -= sim.t - t0          # what was advanced (an advance may round to its own quantum)
        return int(round((sim.t - t0) / sim.dt))

    def frame(self) -> tuple[Any, Any]:
        return self.sim, (self.overlays(self.sim) if self.overlays else None)


class _ReplaySource:
    """A recorded Trajectory played back by time: ``advance(seconds)`` moves the play head, the
    sample shown is the last one at or before it."""

    finished = False

    def __init__(self, trajectory: Trajectory, bodies: Mapping[str, Any], overlays: Any, loop: bool):
        self.traj, self.bodies, self.loop = trajectory, bodies, loop
        self.t = np.asarray(trajectory.t, dtype=float)
        self.head = float(self.t[0])
        self.index = 0
        self.at_end = len(self.t) == 1
        self._lock = threading.Lock()
        if overlays is None:
            overlays = _default_overlays(trajectory, bodies)
        self.overlays = overlays

    def _index(self, head: float) -> int:
        return int(np.clip(np.searchsorted(self.t, head + 1e-12, side="right") - 1, 0, len(self.t) - 1))

    def advance(self, seconds: float) -> int:
        with self._lock:
            if self.at_end and seconds > 0:          # played through (and resumed): from the start
                self.head, self.at_end = float(self.t[0]), False
                old, self.index = self.index, 0
                return abs(old - self.index)
            head = self.head + seconds
            if head >= self.t[-1]:
                if self.loop and len(self.t) > 1:
                    head = float(self.t[0]) + (head - self.t[-1]) % (self.t[-1] - self.t[0])
                else:
                    head, self.at_end = float(self.t[-1]), True
            self.head = head
            old, self.index = self.index, self._index(head)
            return self.index - old if self.index >= old else self.index + len(self.t) - 1 - old

    def seek(self, t: float) -> None:
        with self._lock:
            self.head = float(np.clip(t, self.t[0], self.t[-1]))
            self.index = self._index(self.head)
            self.at_end = self.head >= self.t[-1] and not self.loop and len(self.t) > 1

    def frame(self) -> tuple[Any, Any]:
        with self._lock:
            i = self.index
        snap = self.snapshot(i)
        ov = self.overlays
        payload = ov(snap) if callable(ov) else ov[i]
        return snap, payload

    def snapshot(self, i: int) -> Snapshot:
        tr = self.traj
        return Snapshot(list(tr.names), float(self.t[i]), np.asarray(tr.x[i]), np.asarray(tr.Omega[i]), self.bodies,
                        getattr(tr, "wheel_counts", None))


_DEFAULT_COLORS = ([0.51, 0.87, 0.76, 0.95], [0.95, 0.66, 0.77, 0.95], [0.55, 0.65, 0.95, 0.95],
                   [0.95, 0.8, 0.4, 0.95])


def _default_overlays(trajectory: Trajectory, bodies: Mapping[str, Any]) -> Callable[[Snapshot], dict]:
    """Each body's axes and its angular velocity (world), the arrows scaled so that the fastest
    spin recorded draws about as long as the largest body."""
    ext = max(extent(*shape_of(bodies[n])) for n in trajectory.names)
    x = np.asarray(trajectory.x)
    w_max = float(np.max(np.linalg.norm(x[..., LY.STATE_OMEGA_B], axis=-1))) if x.size else 0.0
    scale = 0.8 * ext / w_max if w_max > 0 else 1.0

    def overlays(snap: Snapshot) -> dict:
        vecs = []
        for k, name in enumerate(snap.names):
            s = snap.state(name)
            vecs.append({"label": f"{name}: ω" if len(snap.names) > 1 else "angular velocity ω", "origin": s.p_w.tolist(),
                         "vector": s.omega_w.tolist(), "scale": scale, "color": _DEFAULT_COLORS[k % len(_DEFAULT_COLORS)]})
        return {"axes": [{"body": n, "scale": 0.9 * ext} for n in snap.names], "vectors": vecs[:64]}

    return overlays


def check_trajectory(trajectory: Any, bodies: Any, overlays: Any) -> tuple[Mapping[str, Any], Any]:
    """Validate a replay's inputs; return (bodies mapping, overlays). LavenderInputError naming
    ``trajectory``, ``bodies`` or ``overlays`` otherwise (nothing is started)."""
    names, t, x = (getattr(trajectory, a, None) for a in ("names", "t", "x"))
    if names is None or t is None or x is None:
        raise V.LavenderInputError("trajectory", "expected a lavendersim Trajectory (Sim.record)",
                                   f", got {type(trajectory).__name__}")
    names = list(names)
    t = np.asarray(t)
    x = np.asarray(x)
    if t.ndim != 1 or len(t) < 1 or not np.issubdtype(t.dtype, np.number) or not np.all(np.isfinite(t)):
        raise V.LavenderInputError("trajectory.t", "must be a non-empty 1-D array of finite times",
                                   f", got shape {t.shape}")
    if len(t) > 1 and not np.all(np.diff(t) > 0):
        raise V.LavenderInputError("trajectory.t", "must increase strictly")
    if x.ndim != 3 or x.shape[:2] != (len(t), len(names)) or x.shape[2] < LY.STATE_SIZE:
        raise V.LavenderInputError("trajectory.x", f"must have shape ({len(t)}, {len(names)}, {LY.STATE_SIZE})",
                                   f", got {x.shape}")
    if not np.all(np.isfinite(x[..., :LY.STATE_SIZE])):
        raise V.LavenderInputError("trajectory.x", "must be finite (a diverged run?)")
    found = getattr(bodies, "bodies", bodies)
    if not isinstance(found, Mapping):
        raise V.LavenderInputError("bodies", "expected a Sim, a Scene or a mapping name -> Body",
                                   f", got {type(bodies).__name__}")
    absent = [n for n in names if n not in found]
    if absent:
        raise V.LavenderInputError("bodies", f"has no body {absent[0]!r} of the trajectory",
                                   f"; it has: {', '.join(map(str, found)) or 'none'}")
    if overlays is not None and not callable(overlays):
        if isinstance(overlays, (str, bytes, Mapping)) or not isinstance(overlays, Sequence):
            raise V.LavenderInputError("overlays", "expected None, a callable(Snapshot) or one payload per sample",
                                       f", got {type(overlays).__name__}")
        if len(overlays) != len(t):
            raise V.LavenderInputError("overlays", f"one payload per sample: {len(t)} expected", f", got {len(overlays)}")
    return found, overlays


# --------------------------------------------------------------------------
# the player
# --------------------------------------------------------------------------


class Player:
    """Publishes a source's frames to a viewer at `rate_hz` frames per wall-clock second, honouring
    the viewer's controls (pause, speed; see the module docstring). Made by
    :meth:`Viewer.play` / :meth:`Viewer.replay`.

    Parameters
    ----------
    viewer : Viewer
        Where frames are published; its :attr:`~Viewer.controls` steer playback.
    source : object
        A live Sim or a recorded Trajectory source (internal).
    rate_hz : float
        Frames per wall-clock second.

    Attributes
    ----------
    frames : int
        Frames published by :meth:`tick` (paused ticks publish none).
    steps : int
        Sim steps advanced (live) or samples moved (replay).
    stop_reason : str or None
        Why the player stopped: ``"finished"`` (the duration was reached), ``"stopped"``
        (:meth:`stop`), ``"interrupted (Ctrl-C)"``, ``"viewer closed"`` or ``"error: ..."``;
        None while it runs (or before it started).
    error : BaseException or None
        The exception that stopped it, if any.
    """

    def __init__(self, viewer: Any, source: Any, rate_hz: float) -> None:   # viewer: a lavendersim.viewer.Viewer
        self.viewer, self.source, self.rate_hz = viewer, source, rate_hz
        self.controls = viewer.controls
        self.frames = 0
        self.steps = 0
        self.stop_reason: str | None = None
        self.error: BaseException | None = None
        self.state = "new"              # "playing", "paused", "stopped"
        self._stop = threading.Event()
        self.thread: threading.Thread | None = None

    @property
    def replaying(self) -> bool:
        """Whether this player replays a recorded Trajectory (else it drives a live Sim)."""
        return isinstance(self.source, _ReplaySource)

    @property
    def t(self) -> float:
        """Simulated time shown (live: the Sim's time; replay: the current sample's time), s."""
        if self.replaying:
            return float(self.source.t[self.source.index])
        return float(self.source.sim.t)

    def publish(self) -> int:
        """Publish the source's current frame (also while paused: after a seek).

        Returns
        -------
        int
            The frame number.
        """
        sim, payload = self.source.frame()
        n = self.viewer.publish_frame(sim, payload)
        if self.replaying:
            self.controls.show_time(self.t)
        return n

    def seek(self, t: float) -> int:
        """Replay only: show the last sample at or before `t` (the time slider calls this).

        Parameters
        ----------
        t : float
            Seconds (clipped to the recording).

        Returns
        -------
        int
            The frame number published.
        """
        if not self.replaying:
            raise V.LavenderInputError("t", "seek needs a replay (Viewer.replay); a live Sim cannot go back")
        self.source.seek(V.scalar("t", t))
        return self.publish()

    def tick(self) -> int:
        """One frame: unless paused, advance the source by ``speed / rate_hz`` simulated seconds and
        publish. Returns the steps (live) or samples (replay) advanced; 0 when paused.

        Returns
        -------
        int
        """
        if self.controls.paused:
            return 0
        n = self.source.advance(self.controls.speed / self.rate_hz)
        self.publish()
        self.frames += 1
        self.steps += n
        if self.replaying and self.source.at_end and not self.source.loop:
            self.controls.pause()                    # played through: wait at the end (scrub, or resume)
        return n

    def run(self) -> str:
        """Play in this thread until finished, stopped or interrupted (Ctrl-C); returns the stop
        reason. An exception from the source (a diverged Sim, a bad payload) is recorded and raised.

        Returns
        -------
        str
        """
        try:
            self._loop()
            self.stop_reason = "stopped" if self._stop.is_set() else "finished"
        except KeyboardInterrupt:
            self.stop_reason = "interrupted (Ctrl-C)"
        except RuntimeError as exc:
            if "viewer is closed" not in str(exc):
                self._failed(exc)
                raise
            self.stop_reason = "viewer closed"
        except BaseException as exc:
            self._failed(exc)
            raise
        finally:
            self.state = "stopped"
        return self.stop_reason

    def start(self) -> Self:
        """Play in a daemon thread (returns at once).

        Returns
        -------
        Player
            self.
        """
        if self.thread is not None:
            raise RuntimeError("this player was started already")

        def work():
            try:
                self.run()
            except BaseException as exc:    # recorded by run(); say it once, the thread ends
                print(f"lavendersim viewer: playback stopped: {exc!r}", file=sys.stderr)

        self.thread = threading.Thread(target=work, name="lavendersim-player", daemon=True)
        self.thread.start()
        return self

    def stop(self, timeout: float = JOIN_TIMEOUT_S) -> bool:
        """Stop playing and wait up to `timeout` s for the thread. Returns whether it stopped (a
        thread still running then is reported in ``stop_reason``).

        Parameters
        ----------
        timeout : float, optional
            Seconds to wait.

        Returns
        -------
        bool
        """
        self._stop.set()
        self.controls.wake()
        if self.thread is None or self.thread is threading.current_thread():
            return True
        self.thread.join(timeout)
        if self.thread.is_alive():
            self.stop_reason = f"still running {timeout:g} s after stop() (a long advance?)"
            return False
        return True

    def _failed(self, exc: BaseException) -> None:
        self.error = exc
        self.stop_reason = f"error: {exc!r}"

    def _loop(self) -> None:
        period = 1.0 / self.rate_hz
        self.publish()                                 # the first frame, before any motion
        next_at = time.monotonic()
        while not self._stop.is_set():
            if self.controls.paused:
                self.state = "paused"
                self.controls.wait_while_paused(self._stop)
                next_at = time.monotonic()
                continue
            self.state = "playing"
            self.tick()
            if self.source.finished:
                return
            next_at += period
            delay = next_at - time.monotonic()
            if delay > 0:
                self._stop.wait(delay)
            elif delay < -period:                      # behind (a slow advance): no burst to catch up
                next_at = time.monotonic()
