"""The live viewer from Python: payload validation, the scene state it draws, and that publishing
never waits for browsers (none, a stalled one, a slow one, one that disconnects mid-run).

Browser-side checks (a real headless Chromium) are in test_viewer_browser.py. Payload validation
runs everywhere; a live Viewer needs the viewer extra (viser): `@pytest.mark.needs("viewer")`
(tests/conftest.py: skipped without it, failed without it under CI=true).
"""
from __future__ import annotations

import base64
import os
import re
import socket
import subprocess
import sys
import threading
import time

import numpy as np
import pytest

from conftest import run_main

import lavendersim as lv
from lavendersim import viewer as VW
from lavendersim.validate import LavenderInputError

DEADLINE = 60.0   # s, for events waited on: only ever reached when the behaviour is broken


def _sim(omega=(1.0, 2.0, 3.0)):
    sc = lv.Scene()
    sc.add_body(lv.Body.box("cube", 1.0, (0.3, 0.2, 0.1), p_w=(0.1, -0.2, 0.3), omega_b=omega))
    sc.add_body(lv.Body.sphere("ball", 2.0, 0.1, p_w=(1.0, 0.0, 0.0)))
    sc.add_body(lv.Body.cylinder("can", 1.0, 0.05, 0.3, p_w=(0.0, 1.0, 0.0), omega_b=(0.0, 1.0, 0.0)))
    sc.add_body(lv.Body("blob", 1.0, (0.1, 0.2, 0.25), p_w=(0.0, 0.0, 1.0)))
    return lv.Sim(sc, dt=1e-3)


GOOD = {
    "axes": [{"body": "cube", "scale": 0.34}],
    "vectors": [
        {"label": "angular velocity", "origin": [0.1, -0.2, 0.3], "vector": [1.0, 2.0, 3.0], "scale": 0.12,
         "color": [0.51, 0.87, 0.76, 0.95]},
        {"label": "torque", "origin": [0.0, 0.0, 0.0], "vector": [0.0, 0.0, -0.1], "scale": 3.0,
         "color": [1.0, 0.0, 0.0, 1.0]},
    ],
}


@pytest.fixture(scope="module")
def viewer():
    v = VW.Viewer(port=0, max_rate_hz=200.0)
    yield v
    v.close()


def _publish(viewer, sim, overlays):
    n = viewer.publish_frame(sim, overlays)
    assert viewer.wait_applied(n, DEADLINE), viewer.stats()
    assert viewer.last_error is None, viewer.last_error
    return viewer.scene_state()


# ---- payload validation -----------------------------------------------------------------------

def _bad(**vec):
    v = {"label": "v", "origin": [0, 0, 0], "vector": [1, 0, 0], "scale": 1.0, "color": [1, 0, 0, 1]}
    v.update(vec)
    return {"vectors": [GOOD["vectors"][0], {k: x for k, x in v.items() if x is not ...}]}


BAD = [
    ("not a dict", [1, 2], "overlays"),
    ("unknown top key", {"arrows": []}, "overlays"),
    ("axes not a list", {"axes": {"body": "cube"}}, "overlays.axes"),
    ("axes item not a dict", {"axes": ["cube"]}, "overlays.axes[0]"),
    ("unknown body", {"axes": [{"body": "cub", "scale": 1}]}, "overlays.axes[0].body"),
    ("body missing", {"axes": [{"scale": 1}]}, "overlays.axes[0].body"),
    ("body not str", {"axes": [{"body": 3}]}, "overlays.axes[0].body"),
    ("duplicate axes", {"axes": [{"body": "cube"}, {"body": "cube"}]}, "overlays.axes[1].body"),
    ("axes scale zero", {"axes": [{"body": "cube", "scale": 0}]}, "overlays.axes[0].scale"),
    ("axes unknown key", {"axes": [{"body": "cube", "size": 1}]}, "overlays.axes[0]"),
    ("vectors not a list", {"vectors": "x"}, "overlays.vectors"),
    ("unknown vector key", _bad(colour=[1, 0, 0, 1]), "overlays.vectors[1]"),
    ("origin missing", _bad(origin=...), "overlays.vectors[1].origin"),
    ("vector missing", _bad(vector=...), "overlays.vectors[1].vector"),
    ("origin length", _bad(origin=[0, 0]), "overlays.vectors[1].origin"),
    ("vector nan", _bad(vector=[0, float("nan"), 0]), "overlays.vectors[1].vector"),
    ("vector inf", _bad(vector=[0, 0, float("inf")]), "overlays.vectors[1].vector"),
    ("vector bool", _bad(vector=[True, 0, 0]), "overlays.vectors[1].vector"),
    ("vector str", _bad(vector="1,0,0"), "overlays.vectors[1].vector"),
    ("scale negative", _bad(scale=-1.0), "overlays.vectors[1].scale"),
    ("scale nan", _bad(scale=float("nan")), "overlays.vectors[1].scale"),
    ("scale str", _bad(scale="2"), "overlays.vectors[1].scale"),
    ("color above 1", _bad(color=[1, 0, 0, 1.5]), "overlays.vectors[1].color"),
    ("color below 0", _bad(color=[-0.1, 0, 0, 1]), "overlays.vectors[1].color"),
    ("color rgb only", _bad(color=[1, 0, 0]), "overlays.vectors[1].color"),
    ("color 0-255", _bad(color=[255, 0, 0, 255]), "overlays.vectors[1].color"),
    ("color nan", _bad(color=[1, 0, float("nan"), 1]), "overlays.vectors[1].color"),
    ("label not str", _bad(label=5), "overlays.vectors[1].label"),
    ("too many vectors", {"vectors": [GOOD["vectors"][0]] * (VW.MAX_VECTORS + 1)}, "overlays.vectors"),
]


@pytest.mark.parametrize("what,overlays,field", BAD, ids=[b[0] for b in BAD])
def test_bad_payload_names_field(what, overlays, field):
    with pytest.raises(LavenderInputError) as e:
        VW.validate_overlays(overlays, ["cube", "ball"])
    assert e.value.field == field, str(e.value)
    assert str(e.value).startswith(field + ":")


def test_unknown_key_suggests_spelling():
    with pytest.raises(LavenderInputError, match="did you mean 'color'"):
        VW.validate_overlays(_bad(colour=[1, 0, 0, 1]), ["cube"])


def test_defaults_and_no_mutation():
    payload = {"axes": [{"body": "cube"}], "vectors": [{"origin": (0, 0, 0), "vector": np.array([1, 2, 3])}]}
    ov = VW.validate_overlays(payload, ["cube"])
    assert ov["axes"] == [{"body": "cube", "scale": VW.DEFAULT_AXES_SCALE}]
    (v,) = ov["vectors"]
    assert v["label"] == "" and v["scale"] == 1.0 and list(v["color"]) == list(VW.DEFAULT_COLOR)
    assert payload["vectors"][0]["origin"] == (0, 0, 0)
    assert VW.validate_overlays(None, ["cube"]) == {"axes": [], "vectors": []}


@pytest.mark.needs("viewer")
def test_bad_payload_draws_nothing(viewer):
    sim = _sim()
    before = _publish(viewer, sim, GOOD)
    published = viewer.stats()["published"]
    sim.run(10)
    with pytest.raises(LavenderInputError, match=r"overlays\.vectors\[1\]\.color"):
        viewer.publish_frame(sim, _bad(color=[1, 0, 0, 2]))
    assert viewer.stats()["published"] == published           # not stored: nothing to apply
    assert viewer.wait_applied(published, DEADLINE)
    assert viewer.scene_state() == before
    with pytest.raises(LavenderInputError, match="sim"):
        viewer.publish_frame(object(), GOOD)


def test_viewer_options_validated():
    with pytest.raises(LavenderInputError, match="port"):
        VW.Viewer(port=70000)
    with pytest.raises(LavenderInputError, match="port"):
        VW.Viewer(port="8080")
    with pytest.raises(LavenderInputError, match="max_rate_hz"):
        VW.Viewer(port=0, max_rate_hz=0)


# ---- what the scene holds ---------------------------------------------------------------------

def test_quaternion_convention():
    assert list(VW.xyzw_to_wxyz([0.1, 0.2, 0.3, 0.9])) == [0.9, 0.1, 0.2, 0.3]


@pytest.mark.needs("viewer")
def test_scene_holds_published_poses(viewer):
    sim = _sim()
    sim.run(700)
    st = _publish(viewer, sim, GOOD)
    h = viewer.handles()
    for name in sim.names:
        s = sim.state(name)
        wxyz = [s.q[3], s.q[0], s.q[1], s.q[2]]
        assert np.allclose(st["bodies"][name]["position"], s.p_w)
        assert np.allclose(st["bodies"][name]["wxyz"], wxyz)
        assert np.allclose(h["bodies"][name].position, s.p_w)
        assert np.allclose(h["bodies"][name].wxyz, wxyz)
    assert st["bodies"]["cube"]["shape"] == ("box", (0.3, 0.2, 0.1))
    assert st["bodies"]["ball"]["shape"] == ("sphere", (0.1,))
    assert st["bodies"]["can"]["shape"] == ("cylinder", (0.05, 0.3))
    kind, dims = st["bodies"]["blob"]["shape"]   # no shape: the inertia-equivalent box
    w, hh, d = dims
    assert kind == "box" and np.allclose([(hh**2 + d**2) / 12, (w**2 + d**2) / 12, (w**2 + hh**2) / 12], [0.1, 0.2, 0.25])
    assert st["t"] == pytest.approx(0.7)
    # a later frame moves them
    sim.run(300)
    st2 = _publish(viewer, sim, GOOD)
    assert np.allclose(st2["bodies"]["cube"]["wxyz"], VW.xyzw_to_wxyz(sim.state("cube").q))
    assert not np.allclose(st2["bodies"]["cube"]["wxyz"], st["bodies"]["cube"]["wxyz"])


@pytest.mark.needs("viewer")
def test_axes_follow_their_body(viewer):
    sim = _sim()
    st = _publish(viewer, sim, GOOD)
    h = viewer.handles()
    assert st["axes"] == {"cube": 0.34}
    ax = h["axes"]["cube"]
    assert ax.visible and ax.axes_length == pytest.approx(0.34)
    assert ax.name.startswith(h["bodies"]["cube"].name + "/")   # a child: it moves with the body node
    assert np.allclose(ax.position, 0) and np.allclose(ax.wxyz, [1, 0, 0, 0])
    assert not h["axes"]["ball"].visible
    st = _publish(viewer, sim, {"axes": [{"body": "ball", "scale": 0.2}]})
    assert st["axes"] == {"ball": 0.2}
    assert not h["axes"]["cube"].visible and h["axes"]["ball"].visible


@pytest.mark.needs("viewer")
def test_vectors_in_world_coordinates(viewer):
    sim = _sim()
    st = _publish(viewer, sim, GOOD)
    v0, v1 = st["vectors"]
    assert v0["label"] == "angular velocity"
    assert np.allclose(v0["start"], [0.1, -0.2, 0.3])
    assert np.allclose(v0["end"], np.array([0.1, -0.2, 0.3]) + 0.12 * np.array([1.0, 2.0, 3.0]))
    assert v0["rgb"] == (130, 222, 194) and v0["opacity"] == pytest.approx(0.95)
    assert np.allclose(v1["end"], [0, 0, -0.3]) and v1["rgb"] == (255, 0, 0) and v1["opacity"] == 1.0
    h = viewer.handles()["vectors"]
    # the arrow node sits at the origin and its +z axis points along the vector, length |scale v|
    for hv, v in zip(h, GOOD["vectors"]):
        d = v["scale"] * np.asarray(v["vector"], float)
        w, x, y, z = hv["node"].wxyz
        R = np.array([[1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
                      [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
                      [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)]])
        assert np.allclose(hv["node"].position, v["origin"])
        assert np.allclose(R[:, 2] * np.linalg.norm(d), d, atol=1e-9)
        assert hv["shaft"].scale[2] + hv["head"].scale[2] == pytest.approx(np.linalg.norm(d))
        assert hv["node"].visible and hv["label"].text == v["label"]
    assert h[0]["shaft"].opacity == pytest.approx(0.95) and h[0]["head"].opacity == pytest.approx(0.95)
    assert h[1]["shaft"].opacity is None          # alpha 1: opaque
    assert tuple(h[1]["shaft"].color) == (255, 0, 0)
    # fewer vectors next frame: the extra arrow is hidden; a zero vector draws nothing
    st = _publish(viewer, sim, {"vectors": [{"origin": [0, 0, 0], "vector": [0, 0, 0]}]})
    assert len(st["vectors"]) == 1
    assert not h[0]["node"].visible and not h[1]["node"].visible


@pytest.mark.needs("viewer")
def test_anti_parallel_vector(viewer):
    sim = _sim()
    _publish(viewer, sim, {"vectors": [{"origin": [0, 0, 0], "vector": [0, 0, -2]}]})
    hv = viewer.handles()["vectors"][0]
    w, x, y, z = hv["node"].wxyz
    assert 1 - 2 * (x * x + y * y) == pytest.approx(-1.0)   # R[2, 2]: +z maps to -z


@pytest.mark.needs("viewer")
def test_chapter_payload_with_a_wheel_like_sim(viewer):
    """The chapter's exact call shape: tolist() vectors from a running sim."""
    sim = _sim()
    sim.run(100)
    s = sim.state("cube")
    st = _publish(viewer, sim, {
        "axes": [{"body": "cube", "scale": 0.34}],
        "vectors": [
            {"label": "angular velocity", "origin": s.p_w.tolist(), "vector": s.omega_w.tolist(), "scale": 0.12,
             "color": [0.51, 0.87, 0.76, 0.95]},
            {"label": "torque", "origin": s.p_w.tolist(), "vector": [0.0, 0.0, 0.02], "scale": 3.0,
             "color": [0.95, 0.66, 0.77, 0.95]},
        ]})
    assert np.allclose(st["vectors"][0]["end"], s.p_w + 0.12 * s.omega_w)


# ---- never stalls -----------------------------------------------------------------------------
#
# Behaviour, never durations or counts per time window: every publish_frame call returns, the
# frames coalesce (latest wins) at a bounded rate, and with a stalled, a slow and a disconnecting
# client a healthy client still receives the LATEST frame. Waits are for events, with generous
# deadlines (a loaded 2-core machine may take seconds where an idle one takes milliseconds).

def _camera_message() -> bytes:
    """What a browser sends first; viser counts a client as connected once it arrives."""
    import msgspec

    return msgspec.msgpack.encode({
        "type": "ViewerCameraMessage", "wxyz": [1.0, 0.0, 0.0, 0.0], "position": [1.0, -1.0, 1.0], "fov": 1.0,
        "near": 0.01, "far": 100.0, "image_height": 480, "image_width": 640, "look_at": [0.0, 0.0, 0.0],
        "up_direction": [0.0, 0.0, 1.0]})


def _masked_frame(payload: bytes) -> bytes:
    """One client-to-server websocket binary frame (RFC 6455: clients mask)."""
    mask = os.urandom(4)
    n = len(payload)
    head = bytes([0x82]) + (bytes([0x80 | n]) if n < 126 else bytes([0x80 | 126]) + n.to_bytes(2, "big"))
    return head + mask + bytes(b ^ mask[i % 4] for i, b in enumerate(payload))


def _stalled_client(port):
    """A websocket client that completes the handshake, says hello, and then never reads a byte."""
    import viser

    s = socket.socket()
    s.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 4096)
    s.settimeout(DEADLINE)
    s.connect(("127.0.0.1", port))
    key = base64.b64encode(os.urandom(16)).decode()
    s.sendall((f"GET / HTTP/1.1\r\nHost: 127.0.0.1:{port}\r\nUpgrade: websocket\r\nConnection: Upgrade\r\n"
               f"Sec-WebSocket-Key: {key}\r\nSec-WebSocket-Version: 13\r\n"
               f"Sec-WebSocket-Protocol: viser-v{viser.__version__}\r\n\r\n").encode())
    head = b""
    while b"\r\n\r\n" not in head:
        chunk = s.recv(1)
        assert chunk, f"server closed the connection during the handshake: {head!r}"
        head += chunk
    assert b" 101 " in head.split(b"\r\n")[0], head
    s.sendall(_masked_frame(_camera_message()))
    return s


def _queued(sock: socket.socket, ioctl: int) -> int:
    import fcntl
    import struct

    return struct.unpack("i", fcntl.ioctl(sock.fileno(), ioctl, struct.pack("i", 0)))[0]


def _backlog(client: socket.socket) -> tuple[int, int]:
    """(bytes the server has queued for `client` but could not deliver, bytes delivered to `client`'s
    socket and not read). Both > 0: the connection is backed up end to end — the client's receive
    window is closed and the server's kernel send queue holds data (Linux: TIOCOUTQ / FIONREAD on
    the server's end of the connection, found among this process's sockets; the server is ours).
    The first is -1 once the server has dropped the connection (websockets' keepalive closes a
    client that answers no ping for ~40 s)."""
    import termios

    want = client.getsockname()
    server_q = None
    for fd in os.listdir("/proc/self/fd"):
        try:
            if not os.readlink(f"/proc/self/fd/{fd}").startswith("socket:"):
                continue
            s = socket.socket(fileno=os.dup(int(fd)))
        except OSError:       # closed meanwhile, or not an inet socket: not the one we look for
            continue
        with s:
            if s.family != socket.AF_INET or s.type != socket.SOCK_STREAM:
                continue
            try:
                peer = s.getpeername()
            except OSError:   # a listening socket has no peer
                continue
            if peer == want:
                server_q = _queued(s, termios.TIOCOUTQ)
                break
    return (-1 if server_q is None else server_q), _queued(client, termios.FIONREAD)


def _viser_messages(data: bytes) -> bytes:
    """The msgpack body of one viser websocket message. viser's wire format (viser/infra/_infra.py,
    `_message_producer`): [8 bytes msgpack size][8 bytes compressed size][zstd(msgpack)][binary
    buffers], sizes little-endian."""
    import zstandard

    size, compressed = int.from_bytes(data[0:8], "little"), int.from_bytes(data[8:16], "little")
    assert 16 + compressed <= len(data), f"not viser's wire format: sizes {size}, {compressed}, {len(data)} bytes"
    body = zstandard.ZstdDecompressor().decompress(data[16:16 + compressed], max_output_size=size)
    assert len(body) == size, (len(body), size)
    return body


class _Reader:
    """A websocket client that reads every message on a helper thread (sleeping `delay` s after
    each). It records how much it received, the highest viewer frame number it saw (the status
    line "**frame N**" inside the decompressed message), and why it stopped (`error`: None when
    stopped by `close()`)."""

    FRAME = re.compile(rb"\*\*frame (\d+)\*\*")

    def __init__(self, port, delay=0.0):
        from websockets.sync.client import connect
        import viser

        self.delay = delay
        self.messages = 0
        self.bytes = 0
        self.frame = 0
        self.error: BaseException | None = None
        self._cv = threading.Condition()
        self._closing = threading.Event()
        self.ws = connect(f"ws://127.0.0.1:{port}", subprotocols=[f"viser-v{viser.__version__}"], max_size=None,
                          open_timeout=DEADLINE)
        self.ws.send(_camera_message())
        self.thread = threading.Thread(target=self._loop, daemon=True)
        self.thread.start()

    def _loop(self):
        from websockets.exceptions import ConnectionClosed

        try:
            while True:
                try:
                    msg = self.ws.recv(timeout=1.0)
                except TimeoutError:   # nothing yet: keep waiting (the publisher may be slow)
                    continue
                assert isinstance(msg, bytes), f"viser sends binary messages, got {type(msg).__name__}"
                frames = [int(n) for n in self.FRAME.findall(_viser_messages(msg))]
                with self._cv:
                    self.messages += 1
                    self.bytes += len(msg)
                    self.frame = max([self.frame] + frames)
                    self._cv.notify_all()
                if self.delay:
                    time.sleep(self.delay)
        except ConnectionClosed as exc:
            if not self._closing.is_set():
                self.error = exc           # closed by the server, not by us
        except BaseException as exc:       # recorded, asserted on by the test
            self.error = exc
        finally:
            with self._cv:
                self._cv.notify_all()

    def wait(self, predicate, timeout=DEADLINE) -> bool:
        """Wait until predicate(self) holds (True) or the reader stopped / the deadline passed."""
        end = time.monotonic() + timeout
        with self._cv:
            while not predicate(self):
                left = end - time.monotonic()
                if left <= 0 or not self.thread.is_alive():
                    return predicate(self)
                self._cv.wait(min(left, 1.0))
        return True

    def close(self):
        self._closing.set()
        self.ws.close()
        self.thread.join(DEADLINE)
        assert not self.thread.is_alive(), "reader thread did not stop after close()"

    def __repr__(self):
        return (f"<reader: {self.messages} messages, {self.bytes} bytes, frame {self.frame}, "
                f"alive={self.thread.is_alive()}, error={self.error!r}>")


def _until(predicate, timeout=DEADLINE) -> bool:
    """Poll predicate() until it holds (True) or the deadline passes (False)."""
    end = time.monotonic() + timeout
    while not predicate():
        if time.monotonic() > end:
            return predicate()
        time.sleep(0.02)
    return True


def _wait_clients(viewer, n, timeout=DEADLINE):
    end = time.monotonic() + timeout
    while viewer.clients() != n and time.monotonic() < end:
        time.sleep(0.02)
    assert viewer.clients() == n, (viewer.clients(), n)


class _Publisher:
    """Publishes frames on a helper thread until stopped; records every call's number, the call in
    progress, and why it stopped. A blocked publish_frame shows as a thread that does not finish."""

    def __init__(self, viewer, sim, overlays, each=None):
        self.viewer, self.sim, self.overlays, self.each = viewer, sim, overlays, each
        self.returned = 0
        self.last_number = 0
        self.error: BaseException | None = None
        self._stop = threading.Event()
        self.thread = threading.Thread(target=self._loop, daemon=True)
        self.thread.start()

    def _loop(self):
        try:
            while not self._stop.is_set():
                self.sim.step()
                ov = self.overlays(self.sim) if callable(self.overlays) else self.overlays
                self.last_number = self.viewer.publish_frame(self.sim, ov)
                self.returned += 1
                if self.each:
                    self.each(self)
                time.sleep(0.001)
        except BaseException as exc:   # recorded, asserted on by the test
            self.error = exc

    def stop(self):
        """Stop; assert the thread finished (every call returned) and raised nothing."""
        self._stop.set()
        self.thread.join(DEADLINE)
        assert not self.thread.is_alive(), \
            f"publish_frame did not return within {DEADLINE} s ({self.returned} calls returned before)"
        assert self.error is None, repr(self.error)


@pytest.mark.needs("viewer")
def test_publish_coalesces_latest_wins_at_a_bounded_rate_with_no_client():
    t_open = time.monotonic()
    with VW.Viewer(port=0, max_rate_hz=30.0) as v:
        sim = _sim()
        n = 0
        end = time.monotonic() + DEADLINE
        # publishing (microseconds per call) outpaces a 30 Hz apply rate: frames must coalesce
        while v.stats()["dropped"] < 20 and time.monotonic() < end:
            sim.step()
            n = v.publish_frame(sim, GOOD)
        st = v.stats()
        elapsed = time.monotonic() - t_open
        assert st["dropped"] >= 20, st
        assert st["published"] == n
        # every frame is dropped (replaced while waiting), applied, or in flight: at most one
        # waiting and one being applied when stats() is read
        assert 0 <= st["published"] - st["applied"] - st["dropped"] <= 2, st
        # the apply thread waits 1/max_rate_hz between frames: a load-proof upper bound on the
        # count since the viewer opened (load only lengthens `elapsed`)
        assert st["applied"] <= 1 + elapsed * 30.0, (st, elapsed)
        # latest wins: the last published frame is the one in the scene
        sim.step()
        last = v.publish_frame(sim, GOOD)
        assert v.wait_applied(last, DEADLINE), v.stats()
        state = v.scene_state()
        assert state["frame"] == last and state["t"] == pytest.approx(sim.t)
        assert np.allclose(state["bodies"]["cube"]["wxyz"], VW.xyzw_to_wxyz(sim.state("cube").q))
        assert v.last_error is None, v.last_error


def _many(sim):
    """Big frames (64 labelled vectors whose arrows all move every frame), so that the viewer sends
    a few kB per frame and a stalled client's socket fills."""
    t = sim.t
    return {"axes": [{"body": "cube"}], "vectors": [
        {"label": f"v{i}", "origin": [0.0, 0.0, 0.0],
         "vector": [float(np.cos(i + 10 * t)), float(np.sin(i + 10 * t)), 0.1 * i], "color": [0.0, 0.0, 1.0, 0.5]}
        for i in range(VW.MAX_VECTORS)]}


@pytest.mark.needs("viewer")
def test_stalled_slow_and_disconnecting_clients_do_not_stall_publishing():
    with VW.Viewer(port=0, max_rate_hz=60.0) as v:
        sim = _sim()
        assert v.wait_applied(v.publish_frame(sim, _many(sim)), DEADLINE), v.stats()   # the scene exists
        stalled = _stalled_client(v.port)
        healthy = _Reader(v.port)
        slow = _Reader(v.port, delay=0.3)
        leaver = _Reader(v.port)
        readers = {"healthy": healthy, "slow": slow, "leaver": leaver}
        try:
            _wait_clients(v, 4)
            pub = _Publisher(v, sim, _many)
            try:
                # 1. the stalled connection backs up end to end while publishing goes on
                end = time.monotonic() + DEADLINE
                while min(_backlog(stalled)) <= 0 and time.monotonic() < end and pub.thread.is_alive():
                    time.sleep(0.05)
                backlog = _backlog(stalled)
                assert min(backlog) > 0, (backlog, v.stats(), pub.returned, readers)
                # 2. a client disconnects mid-run
                leaver.close()
                assert leaver.error is None, leaver
                # 3. publishing and applying go on: more frames reach the scene and the healthy
                # client after the stall and the disconnect
                applied = v.stats()["applied"]
                mark = pub.last_number
                assert _until(lambda: v.stats()["applied"] >= applied + 5), (v.stats(), applied)
                assert v.wait_applied(mark + 10, DEADLINE), (v.stats(), mark)
                assert healthy.wait(lambda r: r.frame >= mark + 10), (healthy, mark)
            finally:
                pub.stop()                  # every publish_frame call returned; nothing raised
            # 4. the LATEST frame reaches the healthy client (the stalled client is still connected
            # unless this took long enough for the server's keepalive to drop it; either is fine)
            sim.step()
            latest = v.publish_frame(sim, _many(sim))
            assert v.wait_applied(latest, DEADLINE), v.stats()
            assert healthy.wait(lambda r: r.frame >= latest), (healthy, latest)
            assert healthy.frame == latest
            assert v.scene_state()["frame"] == latest
            assert v.last_error is None, v.last_error
            # the slow client is still connected and reading; every reader's thread ran until closed
            assert slow.thread.is_alive() and slow.error is None and slow.messages > 0, slow
            assert healthy.thread.is_alive() and healthy.error is None, healthy
        finally:
            stalled.close()
            for r in readers.values():
                if r.thread.is_alive():
                    r.close()
        for name, r in readers.items():
            assert r.error is None, (name, r)


@pytest.mark.needs("viewer")
def test_closed_viewer_refuses_frames():
    v = VW.Viewer(port=0)
    v.close()
    with pytest.raises(RuntimeError, match="closed"):
        v.publish_frame(_sim(), None)
    v.close()  # idempotent


# ---- the command line -------------------------------------------------------------------------

@pytest.mark.needs("viewer")
def test_view_command_runs_tumble():
    r = subprocess.run([sys.executable, "-m", "lavendersim.cli", "view", "tumble", "--duration", "0.5", "--port", "0"],
                       capture_output=True, text=True, timeout=300)
    assert r.returncode == 0, r.stderr
    assert "http://127.0.0.1:" in r.stdout and "t = 0.500 s" in r.stdout


def test_view_command_rejects_unknown_scene():
    r = subprocess.run([sys.executable, "-m", "lavendersim.cli", "view", "tumbel", "--duration", "0.1"],
                       capture_output=True, text=True, timeout=300)
    assert r.returncode == 2 and "tumble" in r.stderr


def test_tumble_scene_conserves_momentum_vector():
    sim, overlays, advance = VW.SCENES["tumble"]()
    L0 = np.array(overlays(sim)["vectors"][1]["vector"])
    w0 = np.array(overlays(sim)["vectors"][0]["vector"])
    advance(sim, 2.0)
    ov = overlays(sim)
    VW.validate_overlays(ov, sim.names)
    assert np.allclose(ov["vectors"][1]["vector"], L0, rtol=1e-9)
    assert not np.allclose(ov["vectors"][0]["vector"], w0, atol=1e-2)   # it tumbles


@pytest.mark.needs("viewer")
def test_lab_view_option_streams_lab03(tmp_path):
    r = subprocess.run([sys.executable, "-m", "lavendersim.cli", "lab", "03", "--out", str(tmp_path),
                        "--view", "--view-port", "0", "--view-duration", "0.3"],
                       capture_output=True, text=True, timeout=300)
    assert r.returncode == 0, r.stderr
    assert "lavendersim view lab03: open http://127.0.0.1:" in r.stdout and "t = 0.300 s" in r.stdout


def test_lab_view_option_refused_for_a_lab_without_view():
    # argparse's refusal through cli.main in this process (the --view option of a real process: the test above)
    r = run_main("lab", "force", "--view")
    # labs without a live view have no --view option: argparse refuses it (one line, exit 2)
    assert r.returncode == 2 and "unrecognized arguments: --view" in r.stderr, (r.returncode, r.stderr)


def test_the_viewer_imports_no_lab_and_the_labs_register_their_scenes():
    # library code does not import labs: the viewer alone leaves lavendersim.labs unimported, and lab 03's
    # scene reaches run_scene's registry through labs.register_views (what the CLI calls)
    code = ("import sys, lavendersim.viewer as VW; bare = sorted(VW.SCENES); "
            "print(any(m.startswith('lavendersim.labs') for m in sys.modules), bare); "
            "from lavendersim.labs import register_views, LAB_VIEWS; register_views(); register_views(); "
            "print(sorted(VW.SCENES), all(v in VW.SCENES for v in LAB_VIEWS.values()))")
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=300)
    assert r.returncode == 0, r.stderr
    assert r.stdout.split("\n")[:2] == ["False ['tumble', 'wheel']", "['lab03', 'tumble', 'wheel'] True"], r.stdout


def test_register_scene_refuses_bad_names_and_builders():
    with pytest.raises(LavenderInputError, match="name"):
        VW.register_scene("", lambda: None)
    with pytest.raises(LavenderInputError, match="builder"):
        VW.register_scene("mine", 3)
    with pytest.raises(LavenderInputError, match="scene 'tumble' is taken"):
        VW.register_scene("tumble", lambda: None)
    assert "mine" not in VW.SCENES


def test_lab03_scene_payload_is_valid():
    from lavendersim.labs import lab_module

    sim, overlays, advance = lab_module("03").view_scene()
    advance(sim, 0.5)
    ov = VW.validate_overlays(overlays(sim), sim.names)
    assert [a["body"] for a in ov["axes"]] == ["principal", "mixed"] and len(ov["vectors"]) == 4


@pytest.mark.needs("control")
def test_wheel_scene_balances_the_cube_and_draws_the_chapter_payload():
    from lavendersim import control as C

    sim, overlays, advance = VW.SCENES["wheel"]()
    ov0 = VW.validate_overlays(overlays(sim), sim.names)
    assert [v["label"] for v in ov0["vectors"]] == ["angular velocity", "torque"]
    q_up = C.cube_upright_q("corner")
    tilt0 = C.error_angle_deg(sim.state("cube").q, q_up)
    advance(sim, 1.0)
    ov = VW.validate_overlays(overlays(sim), sim.names)
    tilt = C.error_angle_deg(sim.state("cube").q, q_up)
    assert abs(tilt0 - 3.0) < 1e-9 and tilt < 0.1               # the controller brought it upright
    # the torque arrow is the motor torque on the cube: minus the applied wheel torque, in world
    u = sim.wheel_command_applied("cube")
    np.testing.assert_allclose(ov["vectors"][1]["vector"], -(sim.state("cube").R_wb @ u), atol=1e-15)
    from lavendersim.labs import LAB_VIEWS

    assert LAB_VIEWS["04"] == "wheel"


# ---- which interface the page listens on (issue 28) -------------------------------------------------------

# every spelling that binds INADDR_ANY / in6addr_any other than the two accepted ones
WILDCARDS = ["0", "0.0", "0.0.0", "0x0", "000.000.000.000", "::0", "0:0:0:0:0:0:0:0", "0::0", "::ffff:0.0.0.0"]


@pytest.mark.parametrize("host", WILDCARDS)
def test_a_host_that_binds_every_interface_is_refused_unless_spelled_0_0_0_0(host):
    with pytest.raises(LavenderInputError) as exc:
        VW.check_host(host)
    assert exc.value.field == "host" and "every interface" in str(exc.value) and "0.0.0.0" in str(exc.value)


def test_an_empty_host_is_refused():
    with pytest.raises(LavenderInputError, match="host"):
        VW.check_host("")


def test_the_two_spellings_of_every_interface_are_accepted():
    assert VW.check_host("0.0.0.0") == "0.0.0.0"
    assert VW.check_host("127.0.0.1") == "127.0.0.1" and not VW.binds_every_interface("127.0.0.1")
    assert VW.binds_every_interface("0.0.0.0") and VW.binds_every_interface("::")
    try:   # a machine without IPv6 cannot bind :: at all
        with socket.socket(socket.AF_INET6, socket.SOCK_STREAM) as s:
            s.bind(("::", 0))
    except OSError:
        return
    assert VW.check_host("::") == "::"


@pytest.mark.needs("viewer")
def test_a_viewer_on_every_interface_says_so_on_stderr_and_listens_there(capsys):
    with VW.Viewer(host="0.0.0.0", port=0) as v:
        err = capsys.readouterr().err
        assert v.url == f"http://127.0.0.1:{v.port}/"
        if sys.platform.startswith("linux"):   # all of 127/8 is this machine: only a wildcard bind answers 127.0.0.2
            socket.create_connection(("127.0.0.2", v.port), timeout=DEADLINE).close()
    lines = [ln for ln in err.splitlines() if "every interface" in ln]
    assert len(lines) == 1 and "0.0.0.0" in lines[0] and "warning" in lines[0]


@pytest.mark.needs("viewer")
def test_a_viewer_on_one_interface_prints_no_warning(capsys):
    with VW.Viewer(host="127.0.0.1", port=0) as v:
        assert v.url == f"http://127.0.0.1:{v.port}/"
        if sys.platform.startswith("linux"):   # the control: bound to one address, 127.0.0.2 is refused
            with pytest.raises(OSError):
                socket.create_connection(("127.0.0.2", v.port), timeout=DEADLINE).close()
    assert "every interface" not in capsys.readouterr().err


@pytest.mark.parametrize("host", ["0", "::0"])
def test_view_command_refuses_a_wildcard_host_in_one_line(host):
    r = subprocess.run([sys.executable, "-m", "lavendersim.cli", "view", "tumble", "--host", host, "--duration", "0.1",
                        "--port", "0"], capture_output=True, text=True, timeout=300)
    assert r.returncode == 2 and "Traceback" not in r.stderr
    assert len(r.stderr.strip().splitlines()) == 1 and "--host" not in r.stdout and "every interface" in r.stderr
