"""The viewer's controls without a browser: pause/resume, the speed slider, the axes and vector
toggles, replay of a recorded Trajectory with its time slider, the notebook's inline frame, and
how the player's thread waits and stops.

Each control is driven through its viser GUI handle (``handle.value = ...`` runs the same callback
a browser's click or drag runs) or the Python API, and the assertions are on state: frames and
steps advanced, scene nodes shown or hidden, samples shown. Never on durations: events are waited
for with generous deadlines. The browser renders the controls in test_viewer_browser.py.
"""
from __future__ import annotations

import os
import signal
import subprocess
import sys
import threading
import time

import numpy as np
import pytest

import lavendersim as lv
from lavendersim import _playback as PB
from lavendersim import viewer as VW
from lavendersim.validate import LavenderInputError

from conftest import interruptible

pytestmark = pytest.mark.needs("viewer")

DEADLINE = 60.0   # s, for events waited on: only ever reached when the behaviour is broken
PAYLOAD = {"axes": [{"body": "box", "scale": 0.3}], "vectors": [
    {"label": "angular velocity", "origin": [0.0, 0.0, 0.0], "vector": [0.0, 1.0, 0.0], "scale": 0.1},
    {"label": "torque", "origin": [0.0, 0.0, 0.0], "vector": [0.0, 0.0, 1.0], "scale": 0.1, "color": [1, 0, 0, 1]}]}


def _sim(dt=1e-3):
    sc = lv.Scene()
    sc.add_body(lv.Body.box("box", 1.0, (0.4, 0.25, 0.1), omega_b=(0.05, 4.0, 0.05)))
    return lv.Sim(sc, dt=dt)


@pytest.fixture
def viewer():
    v = VW.Viewer(port=0, max_rate_hz=200.0)
    yield v
    v.close()


def _until(predicate, timeout=DEADLINE) -> bool:
    end = time.monotonic() + timeout
    while not predicate():
        if time.monotonic() > end:
            return predicate()
        time.sleep(0.02)
    return True


def _drawn(viewer):
    """Wait until the latest frame published (a control's redraw included) is in the scene."""
    assert viewer.wait_applied(viewer.stats()["published"], DEADLINE), viewer.stats()
    assert viewer.last_error is None, viewer.last_error
    return viewer.scene_state()


# ---- pause and speed (a live Sim, driven frame by frame) ---------------------------------------

def test_pause_button_stops_frames_and_the_sim(viewer):
    sim = _sim()
    player = viewer.play(sim, lambda s: PAYLOAD, rate_hz=50.0, start=False)
    h = viewer.controls.handles
    assert h["pause"].label == "Pause" and not viewer.controls.paused
    assert player.tick() == 20                       # 1/50 s at dt = 1 ms: 20 steps per frame
    h["pause"].value = True                          # a click (the browser's click runs the same callback)
    assert viewer.controls.paused and h["pause"].label == "Resume"
    t, frames, published = sim.t, player.frames, viewer.stats()["published"]
    advanced = [player.tick() for _ in range(10)]
    assert advanced == [0] * 10
    assert sim.t == t and player.frames == frames
    # pausing redraws once (the status line says "paused"); paused ticks publish nothing
    assert viewer.stats()["published"] == published
    assert _drawn(viewer)["t"] == pytest.approx(t)
    h["pause"].value = True                          # a second click resumes
    assert not viewer.controls.paused and h["pause"].label == "Pause"
    assert player.tick() == 20 and sim.t == pytest.approx(t + 0.02)


def test_speed_slider_changes_sim_steps_per_frame(viewer):
    sim = _sim()
    player = viewer.play(sim, rate_hz=50.0, start=False)
    slider = viewer.controls.handles["speed"]
    steps = {}
    for speed in (1.0, 2.0, 0.25, 4.0):
        slider.value = speed                          # a drag
        assert viewer.controls.speed == speed
        steps[speed] = [player.tick() for _ in range(10)]
    assert steps == {1.0: [20] * 10, 2.0: [40] * 10, 0.25: [5] * 10, 4.0: [80] * 10}
    # a speed that is not a whole number of steps per frame keeps the fractions: 1/60 s * 0.1 at
    # 1 ms steps is 1.67 steps per frame, so 60 frames take 100 steps (not 60 or 120)
    player = viewer.play(_sim(), rate_hz=60.0, start=False, speed=0.1)
    assert sum(player.tick() for _ in range(60)) == 100
    # set from Python: the slider follows
    viewer.controls.set_speed(3.0)
    assert viewer.controls.handles["speed"].value == 3.0
    with pytest.raises(LavenderInputError, match="speed"):
        viewer.controls.set_speed(PB.SPEED_MAX * 2)
    assert viewer.controls.speed == 3.0


def test_play_options_are_validated_and_nothing_starts(viewer):
    sim = _sim()
    for kwargs, field in [({"rate_hz": 0.0}, "rate_hz"), ({"rate_hz": 1e6}, "rate_hz"), ({"speed": 100.0}, "speed"),
                          ({"duration": -1.0}, "duration"), ({"paused": "yes"}, "paused"), ({"overlays": 3}, "overlays"),
                          ({"advance": "fast"}, "advance")]:
        with pytest.raises(LavenderInputError) as e:
            viewer.play(sim, **kwargs)
        assert e.value.field == field, (kwargs, str(e.value))
    assert viewer.player is None and "pause" not in viewer.controls.handles
    with pytest.raises(LavenderInputError, match="sim"):
        viewer.play(object())


# ---- toggles --------------------------------------------------------------------------------

def test_vector_and_axes_toggles_hide_their_nodes(viewer):
    sim = _sim()
    viewer.publish_frame(sim, PAYLOAD)
    st = _drawn(viewer)
    boxes = viewer.controls.handles["vectors"]
    assert list(boxes) == ["angular velocity", "torque"] and all(b.value for b in boxes.values())
    arrows = viewer.handles()["vectors"]
    assert arrows[0]["node"].visible and arrows[1]["node"].visible and st["hidden"] == []

    boxes["torque"].value = False                     # unticked: the latest frame is redrawn at once
    st = _drawn(viewer)
    assert st["hidden"] == ["torque"] and [v["label"] for v in st["vectors"]] == ["angular velocity"]
    assert not arrows[1]["node"].visible and arrows[0]["node"].visible
    sim.run(10)                                       # and every later frame keeps it hidden
    viewer.publish_frame(sim, PAYLOAD)
    st = _drawn(viewer)
    assert st["hidden"] == ["torque"] and not arrows[1]["node"].visible

    axes = viewer.handles()["axes"]["box"]
    assert axes.visible and st["axes"] == {"box": 0.3}
    viewer.controls.handles["axes"].value = False
    st = _drawn(viewer)
    assert st["axes"] == {} and not axes.visible

    viewer.controls.set_vector_shown("torque", True)  # from Python: the checkbox follows
    viewer.controls.set_show_axes(True)
    st = _drawn(viewer)
    assert boxes["torque"].value and viewer.controls.handles["axes"].value
    assert st["hidden"] == [] and arrows[1]["node"].visible and axes.visible and st["axes"] == {"box": 0.3}


def test_labels_that_change_every_frame_add_at_most_max_toggles(viewer):
    sim = _sim()
    for i in range(PB.MAX_TOGGLES + 6):
        viewer.publish_frame(sim, {"vectors": [{"label": f"|L| = {i}", "origin": [0, 0, 0], "vector": [1, 0, 0]}]})
        _drawn(viewer)
    assert len(viewer.controls.handles["vectors"]) == PB.MAX_TOGGLES
    assert viewer.controls.untoggled == {f"|L| = {i}" for i in range(PB.MAX_TOGGLES, PB.MAX_TOGGLES + 6)}
    assert viewer.handles()["vectors"][0]["node"].visible          # drawn all the same


def test_unlabelled_vectors_get_numbered_toggles(viewer):
    sim = _sim()
    viewer.publish_frame(sim, {"vectors": [{"origin": [0, 0, 0], "vector": [1, 0, 0]},
                                           {"origin": [0, 0, 0], "vector": [0, 1, 0]}]})
    _drawn(viewer)
    assert viewer.controls.vector_keys() == ["vector 1", "vector 2"]
    viewer.controls.handles["vectors"]["vector 2"].value = False
    assert _drawn(viewer)["hidden"] == ["vector 2"]


# ---- replay ---------------------------------------------------------------------------------

def _recorded():
    sim = _sim()
    traj = sim.record(1000, every=20)                 # 51 samples, 20 ms apart, t = 0 .. 1 s
    return sim, traj


def test_replay_follows_the_time_slider_and_the_speed(viewer):
    sim, traj = _recorded()
    player = viewer.replay(traj, sim, rate_hz=25.0, start=False)
    slider = viewer.controls.handles["time"]
    assert (slider.min, slider.max, slider.step) == pytest.approx((0.0, 1.0, 0.02))
    player.publish()
    st = _drawn(viewer)
    assert st["t"] == 0.0
    assert np.allclose(st["bodies"]["box"]["wxyz"], VW.xyzw_to_wxyz(traj.x[0, 0, 3:7]))
    # 1/25 s per frame at speed 1: two samples per frame; the slider follows the play head
    assert [player.tick() for _ in range(3)] == [2, 2, 2]
    assert player.t == pytest.approx(0.12) and slider.value == pytest.approx(0.12)
    viewer.controls.handles["speed"].value = 0.5
    assert [player.tick() for _ in range(2)] == [1, 1] and player.t == pytest.approx(0.16)
    # drag the slider (paused or not): that sample is drawn, with its own pose and default overlays
    viewer.controls.pause()
    slider.value = 0.7
    st = _drawn(viewer)
    i = 35
    assert player.t == pytest.approx(0.7) and st["t"] == pytest.approx(0.7)
    assert np.allclose(st["bodies"]["box"]["wxyz"], VW.xyzw_to_wxyz(traj.x[i, 0, 3:7]))
    w = traj.body("box").omega_w[i]
    (arrow,) = st["vectors"]
    assert arrow["label"] == "angular velocity ω"
    d = np.subtract(arrow["end"], arrow["start"])
    assert np.allclose(d / np.linalg.norm(d), w / np.linalg.norm(w))
    assert player.tick() == 0                          # paused: the play head stays
    assert player.t == pytest.approx(0.7)


def test_replay_pauses_at_the_end_and_loops_when_asked(viewer):
    sim, traj = _recorded()
    player = viewer.replay(traj, sim, rate_hz=10.0, speed=4.0, start=False)   # 0.4 s (20 samples) per frame
    moved = [player.tick() for _ in range(3)]
    assert moved == [20, 20, 10] and player.t == pytest.approx(1.0)
    assert viewer.controls.paused                      # played through: it waits at the end
    viewer.controls.resume()
    player.tick()
    assert player.t == 0.0                             # resumed at the end: from the start
    looping = viewer.replay(traj, sim, rate_hz=10.0, speed=4.0, loop=True, start=False)
    assert viewer.player is looping and not viewer.controls.paused
    [looping.tick() for _ in range(3)]
    assert looping.t == pytest.approx(0.2) and not viewer.controls.paused      # 1.2 s wraps to 0.2 s


def test_replay_with_payloads_or_a_callable(viewer):
    sim, traj = _recorded()
    payloads = [{"vectors": [{"label": f"sample {i}", "origin": [0, 0, 0], "vector": [1, 0, 0]}]}
                for i in range(len(traj.t))]
    player = viewer.replay(traj, sim.bodies, payloads, start=False)
    player.seek(0.5)
    assert _drawn(viewer)["vectors"][0]["label"] == "sample 25"

    def overlays(snap):
        s = snap.state("box")
        return {"vectors": [{"label": "p", "origin": s.p_w.tolist(), "vector": s.omega_w.tolist()}]}

    player = viewer.replay(traj, sim.bodies, overlays, start=False)
    player.seek(0.3)
    st = _drawn(viewer)
    assert np.allclose(np.subtract(st["vectors"][0]["end"], st["vectors"][0]["start"]), traj.body("box").omega_w[15])


def test_replay_rejects_bad_input_and_starts_nothing(viewer):
    sim, traj = _recorded()
    other = lv.Scene()
    other.add_body(lv.Body.sphere("ball", 1.0, 0.1))
    bad_t = lv.sim.Trajectory(traj.names, traj.t[::-1].copy(), traj.x)
    nan_x = traj.x.copy()
    nan_x[3, 0, 0] = np.nan
    cases = [
        ((object(), sim), {}, "trajectory"),
        ((bad_t, sim), {}, "trajectory.t"),
        ((lv.sim.Trajectory(traj.names, traj.t, nan_x), sim), {}, "trajectory.x"),
        ((lv.sim.Trajectory(traj.names, traj.t, traj.x[:, :, :7]), sim), {}, "trajectory.x"),
        ((traj, other), {}, "bodies"),
        ((traj, 5), {}, "bodies"),
        ((traj, sim, [None] * 3), {}, "overlays"),
        ((traj, sim, {"axes": []}), {}, "overlays"),
        ((traj, sim, lambda snap: {"vectors": [{"origin": [0, 0, 0]}]}), {}, "overlays.vectors[0].vector"),
        ((traj, sim), {"rate_hz": -1.0}, "rate_hz"),
        ((traj, sim), {"speed": 0.0}, "speed"),
        ((traj, sim), {"loop": 1}, "loop"),
    ]
    for args, kwargs, field in cases:
        with pytest.raises(LavenderInputError) as e:
            viewer.replay(*args, **kwargs)
        assert e.value.field == field, (field, str(e.value))
    assert viewer.player is None and "time" not in viewer.controls.handles


# ---- the player's thread: waits without spinning, stops with a deadline, says why ----------

def test_paused_player_thread_publishes_nothing_and_does_not_spin():
    with VW.Viewer(port=0) as v:
        sim = _sim()
        player = v.play(sim, lambda s: PAYLOAD, rate_hz=60.0)
        assert _until(lambda: player.frames >= 5), (player.frames, player.stop_reason)
        v.controls.pause()
        assert _until(lambda: player.state == "paused"), player.state
        t, frames, published, wakeups = sim.t, player.frames, v.stats()["published"], v.controls.paused_wakeups
        t0 = time.monotonic()
        time.sleep(1.5)                # nothing may happen meanwhile (load only makes it longer)
        elapsed = time.monotonic() - t0
        assert (sim.t, player.frames, v.stats()["published"]) == (t, frames, published)
        # a paused player sleeps on a condition: at most one wake-up per WAIT_SLICE_S (+1 in flight)
        woke = v.controls.paused_wakeups - wakeups
        assert woke <= 2 + elapsed / PB.WAIT_SLICE_S, (woke, elapsed)
        v.controls.resume()
        assert _until(lambda: player.frames >= frames + 5 and sim.t > t), (player.frames, sim.t)
        thread = player.thread
    # close() stopped the player and the apply thread, joined both, and each says why it stopped
    assert not thread.is_alive()
    assert v.threads() == {"apply": {"alive": False, "stop_reason": "closed"},
                           "player": {"alive": False, "stop_reason": "stopped", "state": "stopped"}}


def test_player_thread_stops_paused_at_once_and_finishes_at_its_duration():
    with VW.Viewer(port=0) as v:
        player = v.play(_sim(), rate_hz=60.0, paused=True)
        assert _until(lambda: player.state == "paused")
        assert player.stop(DEADLINE) and player.stop_reason == "stopped" and player.frames == 0
        sim = _sim()
        player = v.play(sim, rate_hz=60.0, duration=0.25, speed=4.0)
        player.thread.join(DEADLINE)
        assert not player.thread.is_alive() and player.stop_reason == "finished", player.stop_reason
        assert sim.t == pytest.approx(0.25)
        assert _drawn(v)["t"] == pytest.approx(0.25)            # the last frame is the final state


@pytest.mark.parametrize("duration", [0.0105, 0.0004, 0.0])
def test_a_duration_between_steps_finishes_at_the_nearest_step(viewer, duration):
    sim = _sim()
    player = viewer.play(sim, rate_hz=60.0, duration=duration, start=False)
    assert player.run() == "finished"
    assert abs(sim.t - duration) <= 0.5 * sim.dt + 1e-15, sim.t


def test_a_typed_speed_outside_the_slider_is_clamped(viewer):
    viewer.play(_sim(), start=False)
    viewer.controls.handles["speed"].value = 50.0        # typed into the box beside the slider
    assert viewer.controls.speed == PB.SPEED_MAX
    viewer.controls.handles["speed"].value = 0.0
    assert viewer.controls.speed == PB.SPEED_MIN


def test_player_thread_records_an_error():
    def overlays(sim):
        if sim.t > 0.05:
            return {"vectors": [{"origin": [0, 0, 0], "vector": [float("nan"), 0, 0]}]}
        return None

    with VW.Viewer(port=0) as v:
        player = v.play(_sim(), overlays, rate_hz=60.0)
        player.thread.join(DEADLINE)
        assert not player.thread.is_alive()
        assert isinstance(player.error, LavenderInputError) and player.stop_reason.startswith("error: ")
        assert "overlays.vectors[0].vector" in player.stop_reason


def test_a_new_player_replaces_the_running_one():
    with VW.Viewer(port=0) as v:
        sim, traj = _recorded()
        first = v.replay(traj, sim, loop=True)
        assert _until(lambda: first.frames >= 2)
        second = v.play(_sim(), rate_hz=30.0)
        assert not first.thread.is_alive() and first.stop_reason == "stopped"
        assert v.player is second and "time" not in v.controls.handles and "pause" in v.controls.handles


# ---- the notebook -----------------------------------------------------------------------------

def test_notebook_shows_an_inline_frame_and_a_link(viewer, capsys):
    html = viewer._repr_html_()
    assert f'<iframe src="{viewer.url}"' in html and f'<a href="{viewer.url}"' in html
    viewer.show()                      # outside a notebook: the link, printed
    assert capsys.readouterr().out.strip() == f"LavenderSim viewer: {viewer.url}"
    with pytest.raises(LavenderInputError, match="height"):
        viewer.show(height=10)


# ---- the command line -------------------------------------------------------------------------

def test_run_scene_replay_limits_the_recording():
    with pytest.raises(LavenderInputError, match="duration"):
        VW.run_scene("tumble", duration=1e6, replay=True)


def test_view_replay_command_records_replays_and_stops_on_ctrl_c():
    proc = subprocess.Popen([sys.executable, "-m", "lavendersim.cli", "view", "tumble", "--replay", "--duration", "0.5",
                             "--port", "0"], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                            preexec_fn=interruptible)
    lines: list[str] = []
    why: list[BaseException] = []

    def read():
        try:
            for line in proc.stdout:
                lines.append(line)
        except BaseException as exc:   # recorded: asserted below
            why.append(exc)

    reader = threading.Thread(target=read, daemon=True)
    reader.start()
    try:
        assert _until(lambda: any("replaying" in ln for ln in lines) or proc.poll() is not None, 300), lines
        assert proc.poll() is None, (lines, proc.stderr.read())
        os.kill(proc.pid, signal.SIGINT)
        rc = proc.wait(DEADLINE)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait(DEADLINE)
    reader.join(DEADLINE)
    assert not reader.is_alive() and not why, why
    err = proc.stderr.read()
    assert rc == 0, (rc, err)
    out = "".join(lines)
    assert "recording 0.5 s" in out and "replaying 31 samples (t = 0 to 0.500 s)" in out, out
    assert "lavendersim view tumble: t = " in out and "Traceback" not in err, (out, err)
