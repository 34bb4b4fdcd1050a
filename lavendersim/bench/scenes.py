"""The scene-building section of `lavendersim bench`: what a large scene costs before its first step.

Measured interleaved in the same rounds (min over rounds, as every section), at N = SCENE_N bodies:

* ``build`` — ``Scene()``, one batched ``Scene.add_bodies`` of N boxes (names, masses, I_b, q, omega_b as
  arrays) and ``Sim(scene, dt, "rk4", backend="c")``: the scene a user builds, ready to step;
* ``build_one_by_one`` — the same scene through N ``Scene.add_body`` calls (the peer a user would write
  without the batched call);
* ``state_big`` / ``state_small`` — ``sim.state(name)`` of the last body of the N-body Sim and of a
  STATE_SMALL_N-body one: their ratio is ~1 when a lookup is O(1), ~N / STATE_SMALL_N when it scans;
* ``build_wheeled`` — WHEELED_N bodies, each with its own reaction_wheels and applied_torque (two
  ``Scene.add_effects`` calls), and their Sim (issue 30: <= 2 s);

and, in a fresh process each (full runs only), PLAIN_BIG_N plain bodies: ``add_bodies`` + ``Sim`` CPU time and
the peak resident set during the build above the resident set before it, per body (_rss_reset_peak; issue 30:
<= 3 s, <= 400 B per body), and ns per body-step of ``run`` at PLAIN_BIG_N against SCALE_SMALL_N (min of interleaved
rounds in that process; issue 30: within 1.2x).
"""
from __future__ import annotations

import json
import subprocess
import sys

import numpy as np

SCENE_N = 10_000
STATE_SMALL_N = 10
WHEELED_N = 100_000
PLAIN_BIG_N = 1_000_000
PLAIN_BIG_ROUNDS = 5   # rounds of the PLAIN_BIG_N process at least (one chunk per big call, ~1.2 s): its min spans ~6 s
SCALE_SMALL_N = 10_000
TARGETS = {"wheeled_build_s": 2.0,       # WHEELED_N bodies with own wheels + applied_torque, Scene + Sim, s, at most
           "plain_big_build_s": 3.0,     # PLAIN_BIG_N plain bodies, add_bodies + Sim, s, at most
           "plain_big_rss_B": 400.0,     # ... peak RSS per body above the process's before the build, at most
           "plain_big_step_ratio": 1.2}  # ns per body-step at PLAIN_BIG_N / at SCALE_SMALL_N, at most


def _arrays(n: int) -> dict:
    """The N bodies' arrays: unit-box-like inertias, random unit q and spins (seeded)."""
    rng = np.random.default_rng(n)
    q = rng.standard_normal((n, 4))
    return {"names": [f"b{i}" for i in range(n)], "masses": np.full(n, 2.0),
            "I_b": np.tile([0.0333, 0.1133, 0.1333], (n, 1)), "q": q / np.linalg.norm(q, axis=1, keepdims=True),
            "omega_b": rng.standard_normal((n, 3))}


def _build(a: dict, batched: bool):
    from ..bodies import Body
    from ..scene import Scene
    from ..sim import Sim

    scene = Scene()
    if batched:
        scene.add_bodies(a["names"], a["masses"], a["I_b"], q=a["q"], omega_b=a["omega_b"])
    else:
        for i, name in enumerate(a["names"]):
            scene.add_body(Body(name, float(a["masses"][i]), a["I_b"][i], q=a["q"][i], omega_b=a["omega_b"][i]))
    return Sim(scene, dt=1e-3, integrator="rk4", backend="c")


def _build_wheeled(a: dict):
    """a's bodies, each with its own reaction_wheels (shared values) and applied_torque (one row each), and their Sim."""
    from ..scene import Scene
    from ..sim import Sim

    scene = Scene()
    scene.add_bodies(a["names"], a["masses"], a["I_b"], q=a["q"], omega_b=a["omega_b"])
    scene.add_effects("reaction_wheels", a["names"], J=[1e-4] * 3, torque_limit=0.1, speed_limit=100.0)
    scene.add_effects("applied_torque", a["names"], torque_w=a["torque_w"])
    return Sim(scene, dt=1e-3, integrator="rk4", backend="c")


_BIG = """
import json, resource, sys, time
from lavendersim.bench import scenes
n, small, rounds = (int(v) for v in sys.argv[1:4])
a, b = scenes._arrays(n), scenes._arrays(small)
scenes._build(b, True)                                   # imports and first-call costs outside the measurement
base, basis = scenes._rss_reset_peak()
t0 = time.process_time()
big = scenes._build(a, True)
build = time.process_time() - t0
peak = scenes._rss_peak(basis)
sm = scenes._build(b, True)
steps = max(1, big._chunk)
per = {"big": [], "small": []}
faults = {"big": [], "small": []}
for _ in range(rounds):
    for key, sim, k in (("big", big, steps), ("small", sm, max(steps, 2**21 // small))):
        r0, t0 = resource.getrusage(resource.RUSAGE_SELF), time.process_time()
        sim.run(k)
        t1, r1 = time.process_time(), resource.getrusage(resource.RUSAGE_SELF)
        per[key].append((t1 - t0) / (k * len(sim.names)) * 1e9)
        faults[key].append([r1.ru_minflt - r0.ru_minflt, (r1.ru_stime - r0.ru_stime) / (k * len(sim.names)) * 1e9])
print(json.dumps({"n_bodies": n, "build_s": build, "rss_per_body_B": (peak - base) * 1024 / n, "rss_basis": basis,
                  "ns_big": min(per["big"]), "ns_small": min(per["small"]), "small_n": small, "steps": steps,
                  "rounds": per, "faults_sys_ns": faults}))
"""


def _status_kib(key: str) -> int | None:
    """A field of /proc/self/status in KiB (Linux), or None where there is none."""
    try:
        with open("/proc/self/status") as f:
            for line in f:
                if line.startswith(key + ":"):
                    return int(line.split()[1])
    except OSError:
        pass
    return None


_HWM = "VmHWM after the build minus VmRSS before it (the peak reset through /proc/self/clear_refs)"
_MAXRSS = "ru_maxrss after minus before the build (no resettable peak here)"


def _rss_reset_peak() -> tuple[int, str]:
    """The process's resident set now, KiB, with its peak reset to it (Linux: /proc/self/clear_refs "5"), and the
    basis of the measure (_HWM); where the peak cannot be reset, the high-water mark ru_maxrss (_MAXRSS).

    ru_maxrss alone is no measure of a build in a child process on Linux: the parent's peak is carried into the
    child's ru_maxrss across fork and exec, so a child of a full bench process read 0 B per body (run at 79836a8)."""
    rss = _status_kib("VmRSS")
    if rss is not None and _status_kib("VmHWM") is not None:
        try:
            with open("/proc/self/clear_refs", "w") as f:
                f.write("5")
            return rss, _HWM
        except OSError:
            pass
    import resource
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss, _MAXRSS


def _rss_peak(basis: str) -> int:
    """The process's peak resident set, KiB, since _rss_reset_peak returned `basis`."""
    hwm = _status_kib("VmHWM") if basis == _HWM else None
    if hwm is not None:
        return hwm
    import resource
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss


def plain_big(n: int = PLAIN_BIG_N, small: int = SCALE_SMALL_N, rounds: int = PLAIN_BIG_ROUNDS) -> dict:
    """PLAIN_BIG_N plain bodies built and stepped in a fresh process (module docstring): ``build_s``,
    ``rss_per_body_B``, ``ns_big`` / ``ns_small`` (ns per body-step at n and at `small`, min over `rounds` interleaved
    rounds of one ``run`` call each) and their ``step_ratio``; ``rounds`` (every round's ns per body-step, big and
    small) and ``faults_sys_ns`` (each round's minor page faults and system CPU ns per body-step: a round that reads
    slow says whether the kernel's page handling was in it)."""
    out = subprocess.run([sys.executable, "-c", _BIG, str(n), str(small), str(rounds)], capture_output=True,
                         text=True, timeout=1200, check=True)
    d = json.loads(out.stdout.strip().splitlines()[-1])
    d["step_ratio"] = d["ns_big"] / d["ns_small"]
    return d


def scene_section(quick: bool, rounds: int, interleaved) -> dict:
    """Time building an N-body scene (batched and one by one) and ``sim.state(name)`` (module docstring).

    Parameters
    ----------
    quick : bool
        Short run: N = SCENE_N / 10.
    rounds : int
        Interleaved rounds.
    interleaved : callable
        lavendersim.bench.interleaved (cases name -> (fn, units), rounds, label) -> name -> stats.

    Returns
    -------
    dict
        ``n_bodies``, the per-case stats (``ns_min`` per build or per lookup) and ``state_ratio``
        (state_big / state_small).
    """
    n = SCENE_N // 10 if quick else SCENE_N
    big, small = _arrays(n), _arrays(STATE_SMALL_N)
    nw = WHEELED_N // 10 if quick else WHEELED_N
    wheeled = _arrays(nw)
    wheeled["torque_w"] = np.random.default_rng(1).normal(size=(nw, 3)) * 1e-3
    sim_big, sim_small = _build(big, True), _build(small, True)
    last_big, last_small = big["names"][-1], small["names"][-1]
    cases = {"build": (lambda: _build(big, True), 1),
             "build_one_by_one": (lambda: _build(big, False), 1),
             "state_big": (lambda: [sim_big.state(last_big) for _ in range(100)], 100),
             "state_small": (lambda: [sim_small.state(last_small) for _ in range(100)], 100),
             "build_wheeled": (lambda: _build_wheeled(wheeled), 1)}
    t = interleaved(cases, rounds, f"scene build N = {n}")
    return {"n_bodies": n, "n_wheeled": nw, "cases": t,
            "state_ratio": t["state_big"]["ns_min"] / t["state_small"]["ns_min"],
            "one_by_one_over_batched": t["build_one_by_one"]["ns_min"] / t["build"]["ns_min"],
            "plain_big": None if quick else plain_big(rounds=max(rounds, PLAIN_BIG_ROUNDS))}


def standing_lines(res: dict, line, targets: dict) -> list[dict]:
    """The section's PASS/MISS lines, built with lavendersim.bench._line."""
    sec = res.get("scenes")
    if sec is None:
        return [line(f"scene of {SCENE_N:g} bodies built (add_bodies + Sim)", None, targets["scene_build_s"], "max", "s",
                     "not run")] + _issue30_lines(None, line)
    c, n = sec["cases"], sec["n_bodies"]
    build_s = c["build"]["ns_min"] / 1e9
    return [line(f"scene of {n:g} bodies built (add_bodies + Sim)", build_s, targets["scene_build_s"], "max", "s",
                 f"one by one (add_body x {n:g} + Sim) {c['build_one_by_one']['ns_min'] / 1e9:.3f} s, "
                 f"{sec['one_by_one_over_batched']:.1f}x"
                 + ("" if n == SCENE_N else f"; --quick: N = {n:g}, not the target's {SCENE_N:g}")),
            line(f"sim.state(name) at N = {n:g} / at N = {STATE_SMALL_N}", sec["state_ratio"], targets["state_lookup_ratio"],
                 "max", "x", f"{c['state_big']['ns_min'] / 1e3:.2f} µs against {c['state_small']['ns_min'] / 1e3:.2f} µs "
                 "per call (O(1): no scan of the bodies)")] + _issue30_lines(sec, line)


def _n(n: int) -> str:
    """1e6 for 1_000_000 (a power of ten >= 1000), else the number."""
    e = len(str(n)) - 1
    return f"1e{e}" if n == 10 ** e and e >= 3 else str(n)


def _issue30_lines(sec: dict | None, line) -> list[dict]:
    """The wheeled build and the PLAIN_BIG_N lines (issue 30); N/A where not measured."""
    wheeled = None if sec is None or "build_wheeled" not in sec["cases"] else sec["cases"]["build_wheeled"]["ns_min"] / 1e9
    nw = WHEELED_N if sec is None else sec.get("n_wheeled", WHEELED_N)
    big = None if sec is None else sec.get("plain_big")
    why = "not run" if sec is None else "full runs only (a fresh process)" if big is None else ""
    g = (lambda k: None) if big is None else big.get
    return [line(f"{_n(nw)} bodies each with own reaction_wheels + applied_torque built (add_effects + Sim)", wheeled,
                 TARGETS["wheeled_build_s"], "max", "s", "not run" if wheeled is None else "two Scene.add_effects calls"
                 + ("" if nw == WHEELED_N else f"; --quick: N = {_n(nw)}, not the target's {_n(WHEELED_N)}")),
            line(f"{_n(PLAIN_BIG_N)} plain bodies built (add_bodies + Sim)", g("build_s"), TARGETS["plain_big_build_s"],
                 "max", "s", why or "CPU time in a fresh process"),
            line(f"{_n(PLAIN_BIG_N)} plain bodies: peak RSS per body", g("rss_per_body_B"), TARGETS["plain_big_rss_B"],
                 "max", "B", why or g("rss_basis") or "above the process's peak before the build"),
            line(f"{_n(PLAIN_BIG_N)} plain bodies: ns per body-step / at N = {_n(SCALE_SMALL_N)}", g("step_ratio"),
                 TARGETS["plain_big_step_ratio"], "max", "x",
                 why or f"{g('ns_big'):.2f} against {g('ns_small'):.2f} ns per body-step (rk4, C)")]


def report_lines(res: dict, fmt) -> list[str]:
    """The section of the text report (fmt: lavendersim.bench._f, ns -> text)."""
    sec = res.get("scenes")
    if sec is None:
        return []
    c, n = sec["cases"], sec["n_bodies"]
    rows = [("build", f"Scene + add_bodies({n:g}) + Sim"), ("build_one_by_one", f"Scene + add_body x {n:g} + Sim"),
            ("state_big", f"sim.state(name), N = {n:g}"), ("state_small", f"sim.state(name), N = {STATE_SMALL_N}"),
            ("build_wheeled", f"Scene + add_bodies + 2 add_effects({sec.get('n_wheeled', WHEELED_N):g}) + Sim")]
    L = ["", "scene build (C backend, RK4)                                  per call     median"]
    for key, label in rows:
        if key in c:
            L.append(f"  {label:<56}{fmt(c[key]['ns_min'])} {fmt(c[key]['ns_median'])}")
    big = sec.get("plain_big")
    if big:
        L.append(f"  {_n(PLAIN_BIG_N)} plain bodies: build {big['build_s']:.2f} s CPU, peak RSS {big['rss_per_body_B']:.0f} B "
                 f"per body, {big['ns_big']:.2f} ns per body-step (N = {_n(big['small_n'])}: {big['ns_small']:.2f})")
    return L
