"""The viewer in a real browser: Debian's chromium, headless, driven by Playwright.

Never `playwright install`: the browser is /usr/bin/chromium from Debian (`.ci/run` installs it).
WebGL: headless chromium with --disable-gpu renders WebGL through SwiftShader (ANGLE on Vulkan,
"SwiftShader Device (Subzero)"); with Debian's chromium 156 that works with the flags below
alone. ``--enable-unsafe-swiftshader`` is added so that a chromium that no longer falls back to
SwiftShader by itself still gets WebGL.

Checks: the page connects; a published pure-red vector shows up as red pixels (pixels classified
by dominant colour) and disappears when unpublished; a changed vector moves the red pixels;
several tabs watch at once and every one keeps receiving the updates (waited for, never counted
per time window); the side panel's controls render and a click or a typed value there reaches
Python.

Needs Debian's chromium and the playwright package (`@pytest.mark.needs("chromium")`, see
tests/conftest.py): skipped without them, failed without them under CI=true.

Also a measurement script (numbers for the notes and README):

    python tests/test_viewer_browser.py --measure       # publish cost with 0/1/3 tabs, stalled client, browser fps
    python tests/test_viewer_browser.py --screenshot docs/viewer.png
"""
from __future__ import annotations

import io
import os
import sys
import tempfile
import threading
import time
from contextlib import contextmanager

import numpy as np
import pytest

CHROMIUM = "/usr/bin/chromium"
CHROMIUM_ARGS = ["--headless", "--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run",
                 "--disable-background-networking", "--disable-component-update", "--disable-sync",
                 "--enable-unsafe-swiftshader",
                 # several tabs watch at once: keep background tabs rendering (headless chromium
                 # otherwise throttles requestAnimationFrame in every tab but the focused one)
                 "--disable-background-timer-throttling", "--disable-renderer-backgrounding",
                 "--disable-backgrounding-occluded-windows"]
VIEWPORT = {"width": 960, "height": 640}
RED = [1.0, 0.0, 0.0, 1.0]
# s, for events waited on (a page connecting, pixels changing). Generous: on a loaded 2-core machine
# SwiftShader draws slowly and a third tab's first frame (after which viser counts it as a client)
# took 65 s while two tabs were rendering.
DEADLINE = 180.0

pytestmark = pytest.mark.needs("chromium", "viewer")


@contextmanager
def browser():
    """A persistent chromium context with a fresh profile in a temporary directory."""
    from playwright.sync_api import sync_playwright

    with sync_playwright() as p, tempfile.TemporaryDirectory(prefix="lavendersim-chromium-") as profile:
        ctx = p.chromium.launch_persistent_context(profile, executable_path=CHROMIUM, args=CHROMIUM_ARGS,
                                                   headless=True, viewport=VIEWPORT)
        ctx.set_default_timeout(DEADLINE * 1000)   # screenshots, waits (ms); playwright's 30 s is tight under load
        try:
            yield ctx
        finally:
            ctx.close()


def open_tab(ctx, viewer, timeout=DEADLINE):
    """Open the viewer in a new tab and wait until the page shows the connection and a frame."""
    before = set(viewer.server.get_clients())
    page = ctx.new_page()
    page._ws_times = count_ws(page)
    page.goto(viewer.url)
    end = time.monotonic() + timeout
    while not set(viewer.server.get_clients()) - before:          # viser counts a client once its websocket says hello
        if time.monotonic() > end:
            raise AssertionError(f"the page at {viewer.url} did not connect within {timeout} s")
        page.wait_for_timeout(50)     # (lets playwright deliver the page's events meanwhile)
    page.get_by_text("frame ").first.wait_for(timeout=timeout * 1000)   # the viewer's status line
    return page


def pixels(page) -> np.ndarray:
    """Screenshot as an (H, W, 3) float array in [0, 1]."""
    from matplotlib.image import imread

    return imread(io.BytesIO(page.screenshot()), format="png")[..., :3]


def red_mask(img: np.ndarray) -> np.ndarray:
    """Pixels whose dominant colour is red (shaded red too: r clearly above g and b)."""
    r, g, b = img[..., 0], img[..., 1], img[..., 2]
    return (r > 0.45) & (r > 2.2 * g) & (r > 2.2 * b)


def _scene():
    import lavendersim as lv

    sc = lv.Scene()
    sc.add_body(lv.Body.box("cube", 1.0, (0.3, 0.3, 0.3), omega_b=(0.2, 0.5, 1.0)))
    return lv.Sim(sc, dt=1e-3)


def _red(vector, scale=1.0):
    return {"vectors": [{"label": "red probe", "origin": [0.0, 0.0, 0.0], "vector": list(vector), "scale": scale,
                         "color": RED}]}


def _settled(page, timeout=DEADLINE):
    """A screenshot once the picture has stopped changing (two in a row identical)."""
    end = time.monotonic() + timeout
    last = pixels(page)
    while True:
        time.sleep(0.2)
        img = pixels(page)
        if np.array_equal(img, last):
            return img
        assert time.monotonic() < end, f"the page kept changing for {timeout} s"
        last = img


def _wait_for(page, predicate, timeout=DEADLINE):
    """Screenshots until predicate(img) holds; returns the last image (and whether it held)."""
    end = time.monotonic() + timeout
    while True:
        img = pixels(page)
        if predicate(img) or time.monotonic() > end:
            return img, predicate(img)
        time.sleep(0.2)


@pytest.fixture(scope="module")
def live():
    from lavendersim.viewer import Viewer

    v = Viewer(port=0, max_rate_hz=60.0)
    sim = _scene()
    v.wait_applied(v.publish_frame(sim, None), DEADLINE)   # the scene exists (and sets the camera) before tabs open
    with browser() as ctx:
        yield v, sim, ctx
    v.close()


def test_page_connects_and_arrows_appear(live):
    v, sim, ctx = live
    page = open_tab(ctx, v)
    assert v.clients() >= 1
    renderer = page.evaluate("""() => { const g = document.createElement('canvas').getContext('webgl2');
        if (!g) return null; const e = g.getExtension('WEBGL_debug_renderer_info');
        return e ? g.getParameter(e.UNMASKED_RENDERER_WEBGL) : 'webgl2'; }""")
    assert renderer, "no WebGL in headless chromium (see the module docstring)"
    base = _settled(page)
    n_base = int(red_mask(base).sum())          # the corner axes gizmo has a little red
    v.wait_applied(v.publish_frame(sim, _red([0.6, 0.0, 0.0])), DEADLINE)
    img, ok = _wait_for(page, lambda im: red_mask(im).sum() > n_base + 400)
    n_x = int(red_mask(img).sum())
    assert ok, f"red arrow not drawn: {n_x} red pixels, {n_base} before"

    # a changed vector changes the picture: the red pixels move
    def centroid(im):
        m = red_mask(im) & ~red_mask(base)
        ys, xs = np.nonzero(m)
        return np.array([xs.mean(), ys.mean()]) if len(xs) else np.array([np.nan, np.nan])

    c_x = centroid(img)
    v.wait_applied(v.publish_frame(sim, _red([0.0, 0.6, 0.0])), DEADLINE)
    img2, ok = _wait_for(page, lambda im: np.linalg.norm(centroid(im) - c_x) > 40)
    assert ok, f"red pixels did not move: {centroid(img2)} vs {c_x}"
    assert np.abs(img2 - img).max() > 0.5

    # unpublished: the red goes away again
    v.wait_applied(v.publish_frame(sim, None), DEADLINE)
    img3, ok = _wait_for(page, lambda im: red_mask(im).sum() < n_base + 100)
    assert ok, f"red arrow still drawn: {int(red_mask(img3).sum())} red pixels"
    page.close()


def test_opacity_is_honoured(live):
    v, sim, ctx = live
    page = open_tab(ctx, v)
    v.wait_applied(v.publish_frame(sim, _red([0.0, 0.0, 0.5])), DEADLINE)
    opaque, ok = _wait_for(page, lambda im: red_mask(im).sum() > 300)
    assert ok
    faint = dict(_red([0.0, 0.0, 0.5]))
    faint["vectors"][0]["color"] = [1.0, 0.0, 0.0, 0.25]
    v.wait_applied(v.publish_frame(sim, faint), DEADLINE)
    # a quarter-opaque red over the white background is pink: it is no longer "red" by our rule
    img, ok = _wait_for(page, lambda im: red_mask(im).sum() < 0.3 * red_mask(opaque).sum())
    assert ok, (int(red_mask(img).sum()), int(red_mask(opaque).sum()))
    pink = (img[..., 0] > 0.85) & (img[..., 1] > 0.55) & (img[..., 1] < 0.9) & (np.abs(img[..., 1] - img[..., 2]) < 0.1)
    assert pink.sum() > 100
    page.close()


def test_several_tabs_watch_and_frames_keep_arriving(live):
    v, sim, ctx = live
    pages = [open_tab(ctx, v) for _ in range(3)]
    end = time.monotonic() + DEADLINE
    while v.clients() < 3 and time.monotonic() < end:
        time.sleep(0.05)
    assert v.clients() >= 3
    marks = [len(p._ws_times) for p in pages]
    errors: list = []
    stop = threading.Event()
    th = threading.Thread(target=_publisher, args=(v, sim, stop, 120.0, errors), daemon=True)
    th.start()
    try:
        # every tab (the background ones too) keeps receiving the scene updates: wait until each has
        # received 20 more websocket messages than before publishing started
        end = time.monotonic() + DEADLINE
        while (got := [len(p._ws_times) - m for p, m in zip(pages, marks)]) and min(got) < 20:
            assert th.is_alive(), f"publisher stopped: {errors!r}"
            assert time.monotonic() < end, f"websocket messages received per tab within {DEADLINE} s: {got}"
            pages[0].wait_for_timeout(100)   # playwright's sync API delivers page events only while it runs
    finally:
        stop.set()
        th.join(DEADLINE)
    assert not th.is_alive(), "publisher did not stop"
    assert not errors, errors
    for p in pages:
        p.close()


def test_controls_render_and_reach_python(live):
    """The side panel shows the controls (Pause/Resume, the speed and time sliders, the body-axes
    checkbox, one checkbox per vector), and what the page does reaches Python: Resume starts the
    replay, typing a speed sets it, unticking a vector hides its arrow; a pause from Python shows
    in the page, and a time typed there seeks."""
    import lavendersim as lv
    from lavendersim.viewer import Viewer

    sc = lv.Scene()
    sc.add_body(lv.Body.box("box", 1.0, (0.4, 0.25, 0.1), omega_b=(0.05, 4.0, 0.05)))
    sim = lv.Sim(sc, dt=1e-3)
    traj = sim.record(1000, every=20)
    ctx = live[2]        # the module's browser (one playwright per thread); a viewer of its own
    with Viewer(port=0) as v:
        player = v.replay(traj, sim, paused=True, loop=True)
        page = open_tab(ctx, v)
        for text in ("Playback", "speed ×", "time (s)", "Show", "body axes"):
            page.get_by_text(text, exact=True).first.wait_for()
        ctl = v.controls
        assert page.get_by_role("checkbox", name="body axes").is_checked()
        omega = page.get_by_role("checkbox", name="angular velocity ω")
        assert omega.is_checked()

        page.get_by_role("button", name="Resume").click()
        assert _until(lambda: not ctl.paused and player.frames > 0), (ctl.paused, player.frames)
        page.get_by_role("button", name="Pause").wait_for()

        speed, when = page.get_by_role("textbox").all()   # the number boxes beside the speed and time sliders
        speed.fill("2")
        speed.press("Enter")
        assert _until(lambda: ctl.speed == 2.0), ctl.speed

        omega.click()
        assert _until(lambda: not ctl.vector_shown("angular velocity ω")
                      and v.scene_state()["hidden"] == ["angular velocity ω"]), v.scene_state()["hidden"]
        assert not v.handles()["vectors"][0]["node"].visible and not omega.is_checked()

        ctl.pause()                              # from Python: the page's button says Resume again
        page.get_by_role("button", name="Resume").wait_for()
        when.fill("0.5")                         # paused, a time typed in the page: that sample is drawn
        when.press("Enter")
        assert _until(lambda: player.t == 0.5 and v.scene_state()["t"] == 0.5), (player.t, v.scene_state()["t"])
        page.close()


def _until(predicate, timeout=DEADLINE) -> bool:
    end = time.monotonic() + timeout
    while not predicate():
        if time.monotonic() > end:
            return predicate()
        time.sleep(0.05)
    return True


# ---- shared by the tests and the measurement script -------------------------------------------

def _publisher(v, sim, stop, hz=120.0, errors=None):
    """Tumble the cube in real time and publish `hz` frames/s with axes and an ω arrow. Why it
    stopped, if not by `stop`, is appended to `errors` (and raised)."""
    t0, n = time.monotonic(), 0
    try:
        while not stop.is_set():
            sim.step()
            n += 1
            s = sim.state("cube")
            v.publish_frame(sim, {"axes": [{"body": "cube", "scale": 0.3}], "vectors": [
                {"label": "ω", "origin": s.p_w.tolist(), "vector": s.omega_w.tolist(), "scale": 0.3,
                 "color": [0.51, 0.87, 0.76, 0.95]}]})
            lag = t0 + n / hz - time.monotonic()
            if lag > 0:
                time.sleep(lag)
    except BaseException as exc:
        if errors is not None:
            errors.append(exc)
        raise


_START = """() => {
    const frameNo = () => { const r = document.evaluate("//strong[starts-with(., 'frame ')]", document, null,
        XPathResult.FIRST_ORDERED_NODE_TYPE, null).singleNodeValue; return r ? r.textContent : null; };
    const m = window.__lavender = {raf: 0, updates: 0, last: frameNo(), t0: performance.now(), on: true};
    // per animation frame: count it, and count it as a viewer update if the status line changed
    const tick = () => { if (!m.on) return; m.raf++; const f = frameNo();
        if (f !== m.last) { m.updates++; m.last = f; } requestAnimationFrame(tick); };
    requestAnimationFrame(tick);
}"""
_STOP = """() => { const m = window.__lavender; m.on = false;
    const s = (performance.now() - m.t0) / 1000; return {raf_per_s: m.raf / s, updates_per_s: m.updates / s}; }"""


def count_ws(page) -> list:
    """Record the arrival time of every websocket message the page receives (works in background
    tabs too, which headless chromium does not render)."""
    times: list = []
    page.on("websocket", lambda ws: ws.on("framereceived", lambda _: times.append(time.monotonic())))
    return times


def measure_pages(pages, seconds: float) -> list[dict]:
    """In each page at once: animation frames/s and distinct viewer frames shown per second (only
    the foreground tab renders in headless chromium), plus websocket messages/s received."""
    for p in pages:
        p.evaluate(_START)
    t0 = time.monotonic()
    marks = [len(getattr(p, "_ws_times", [])) for p in pages]
    time.sleep(seconds)
    out = []
    for p, m0 in zip(pages, marks):
        r = p.evaluate(_STOP)
        ts = getattr(p, "_ws_times", [])
        r["ws_messages_per_s"] = sum(1 for t in ts[m0:] if t >= t0) / (time.monotonic() - t0)
        out.append(r)
    return out


def _cost(v, sim, seconds=2.0, hz=1000.0):
    """publish_frame cost (µs) while publishing the chapter's payload at ~hz for `seconds`."""
    ts = []
    t0 = time.monotonic()
    while time.monotonic() - t0 < seconds:
        sim.step()
        s = sim.state("cube")
        ov = {"axes": [{"body": "cube", "scale": 0.34}], "vectors": [
            {"label": "angular velocity", "origin": s.p_w.tolist(), "vector": s.omega_w.tolist(), "scale": 0.12,
             "color": [0.51, 0.87, 0.76, 0.95]},
            {"label": "torque", "origin": s.p_w.tolist(), "vector": [0.0, 0.0, 0.05], "scale": 3.0,
             "color": [0.95, 0.66, 0.77, 0.95]}]}
        t = time.perf_counter()
        v.publish_frame(sim, ov)
        ts.append(time.perf_counter() - t)
        lag = t0 + len(ts) / hz - time.monotonic()
        if lag > 0:
            time.sleep(lag)
    us = np.array(ts) * 1e6
    return {"calls": len(us), "median_us": float(np.median(us)), "p99_us": float(np.percentile(us, 99)),
            "max_us": float(us.max())}


def measure() -> None:
    import test_viewer as TV

    from lavendersim.viewer import Viewer

    sim = _scene()
    rows = []
    with Viewer(port=0, max_rate_hz=60.0) as v:
        v.wait_applied(v.publish_frame(sim, None), DEADLINE)
        rows.append(("0 clients", _cost(v, sim), v.stats()))
        with browser() as ctx:
            pages = [open_tab(ctx, v)]
            rows.append(("1 chromium tab", _cost(v, sim), v.stats()))
            pages += [open_tab(ctx, v), open_tab(ctx, v)]
            rows.append(("3 chromium tabs", _cost(v, sim), v.stats()))
            stalled = TV._stalled_client(v.port)
            time.sleep(0.5)
            rows.append(("3 tabs + 1 stalled client", _cost(v, sim), v.stats()))
            for p in pages:
                p.close()
            time.sleep(0.5)
            rows.append(("1 stalled client only", _cost(v, sim), v.stats()))
            stalled.close()
            page = open_tab(ctx, v)
            stop = threading.Event()
            th = threading.Thread(target=_publisher, args=(v, sim, stop), daemon=True)
            th.start()
            time.sleep(0.5)
            (fps1,) = measure_pages([page], 5.0)
            more = [open_tab(ctx, v), open_tab(ctx, v)]
            time.sleep(0.5)
            fps3 = measure_pages([page] + more, 5.0)
            stop.set()
            th.join()
    print("publish_frame cost (chapter payload: axes + 2 vectors, ~1 kHz for 2 s; viewer max 60 Hz):")
    for name, c, st in rows:
        print(f"  {name:<26} median {c['median_us']:7.1f} µs   p99 {c['p99_us']:8.1f} µs   max {c['max_us']:8.1f} µs"
              f"   ({c['calls']} calls; totals: {st['applied']} sent, {st['dropped']} coalesced)")
    print("browser (headless chromium, SwiftShader), publisher 120 frames/s, viewer max 60 Hz:")
    for name, f in [("1 tab", fps1)] + [(f"3 tabs, tab {i + 1}", f) for i, f in enumerate(fps3)]:
        print(f"  {name:<14} {f['updates_per_s']:5.1f} viewer frames/s shown, {f['raf_per_s']:5.1f} animation frames/s,"
              f" {f['ws_messages_per_s']:5.1f} websocket messages/s received")
    print("  (headless chromium renders only the foreground tab; background tabs still receive every update)")


def screenshot(path: str) -> None:
    """The README picture: the tumble scene (axes, ω and L arrows) as the test browser shows it,
    paused at t = 1.3 s with the side panel's controls."""
    from lavendersim import viewer as VW

    sim, overlays, advance = VW.SCENES["tumble"]()
    advance(sim, 1.3)
    with VW.Viewer(port=0) as v, browser() as ctx:
        v.play(sim, overlays, advance, paused=True)       # publishes the frame, then waits (paused)
        assert _until(lambda: v.scene_state()["frame"] >= 1), v.stats()
        page = open_tab(ctx, v)
        page.set_viewport_size({"width": 1440, "height": 640})   # the side panel clear of the labels
        time.sleep(3.0)
        for close in page.get_by_role("button", name="Close").all():   # software-WebGL notice, if shown
            if close.is_visible():
                close.click(timeout=10_000)
        time.sleep(1.0)
        page.screenshot(path=path)
    print(f"wrote {path}")


if __name__ == "__main__":
    sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
    if sys.argv[1:2] == ["--measure"]:
        measure()
    elif sys.argv[1:2] == ["--screenshot"] and len(sys.argv) == 3:
        screenshot(sys.argv[2])
    else:
        print(__doc__)
        sys.exit(2)
