"""`lavendersim bench` — speed, as ratios measured in one run.

    lavendersim bench [--quick] [--json] [--out FILE] [--rounds R] [--no-mujoco] [--only SECTION,...]
    python -m lavendersim.bench ...

Everything is measured in one process on one (shared, noisy) machine, so the figures that matter
are ratios against references measured in the same run. Every timing is CPU time of this process
(time.process_time: a loaded machine slows a case less than the wall clock says; only the
two-thread cases, whose point is the wall clock, are timed by it and say so). Repetitions are
interleaved (round-robin over all cases of a section, R rounds), and each figure is the minimum
over the rounds (the median is kept too); ratios are of minima, of peers measured in the same run.
The effect-cost, dopri5 and SIMD-batch sections time many short calls of about equal length instead
(timing.py: ~3 ms each, interleaved call by call, 20 per case per round; a disturbance on a shared host
then spoils few samples and hits ours and the peer alike), minimum over all calls.

Sections (one body: a solid box 2 kg, 0.8 x 0.4 x 0.2 m, asymmetric, omega_b0 = (1, 0.5, 0.2) rad/s,
v0 = (0.1, 0, 0) m/s, dt = 1e-3 s, RK4, q normalized each step):
* single body — LavenderSim C (`Sim.run(n)`: one C call, n >= 1e6 steps), the hand-written C99
  reference (handwritten_rk4.c: the same arithmetic as the generated kernels, everything inlined,
  compiled now with the system `cc -O3` and the extension's math flags, called through ctypes with
  n >= 1e6 steps; its trajectory must be bitwise the Sim's), NumPy (`Sim.run(n)`, fewer steps), one Python `sim.step()` call (c and numpy),
  and MuJoCo (when installed) on the same free body: `mj_step` in a Python loop and
  `mujoco.rollout` (steps inside C), integrators RK4, Euler and implicitfast;
* batched — N bodies in one C call (`Sim.run`), N = 1 … 1e5, ns per body-step; NumPy batched too;
* SIMD batch — the C batch loop itself (one backend call, no Sim checks between chunks) at every
  instruction set this CPU has (LV_ISA_*: scalar, sse2, avx2, avx512f; the extension picks the best at
  run time) against the hand-written struct-of-arrays loop (handwritten_rk4.c, compiled once per
  instruction set with -mavx2 / -mavx512f), N = 1 000 and 10 000 (quick: 1 000), ns per body-step;
* effects — the step cost of cumulative effect sets on one body in C: torque-free, + applied
  torque, + damping (linear + angular), + gravity, + spherical joint, + reaction wheels;
* per-body effects — N bodies each with its own applied_torque against N plain bodies, in C, at
  N = 1, 100, 10 000 (quick: 1, 100): ns per body-step and their ratio. The effects are indexed per
  body, so the ratio must stay flat in N (target <= 1.5);
* ReactionWheelCube-v0 (lavendersim/bench/envs.py; needs gymnasium, else skipped) — env.step() as
  gymnasium.make returns it and unwrapped, its physics alone (sim.run(substeps)), and the vector env at
  N = 1024 per env-step (one and two threads) with its physics alone, interleaved; env / physics is the
  Python overhead;
* scene build (lavendersim/bench/scenes.py) — a 1e4-body scene built with one add_bodies and its Sim,
  against the same built with add_body one by one; sim.state(name) at N = 1e4 against N = 10 (O(1));
* full inertia (lavendersim/bench/full_inertia.py) — bodies given the 6U CubeSat's full tensor against the same
  bodies given its principal moments, with gravity, damping and a force at r_b, at N = 1 and 1e3: Sim.run
  ns per body-step and the state readout (target <= 1.5x);
* effect cost (lavendersim/bench/effect_cost.py) — gravity, applied torque, damping, gravity + damping
  and the guide's user effect against plain bodies at N = 1e3, 1e4, 1e5;
* dopri5 (lavendersim/bench/dopri5.py) — ns per right-hand-side evaluation against a hand C DOPRI5;
* NumPy peers (lavendersim/bench/numpy_section.py) — the NumPy backend against hand NumPy (numpy_peers.py,
  N = 1e3, 1e5) and a pure-Python loop (N = 1);
* the best hand loop — beside the bitwise SoA peer, handwritten_fma.c: the fewest flops we know for a
  torque-free RK4 step (only q and omega_b through the stages, FMA, -O3 -march=native; the classic stage form and
  the scaled-increment form, each its own variants), and the flop
  floor of this CPU (FMA_FLOPS per body-step / the peak FMA rate a C loop measures now);
* small scenes — N = 4 and 8 bodies per body-step against the largest N (batched section);
* agreement — the hand-written kernel against the Sim (same trajectory to ~1e-12), and MuJoCo's
  trajectory against ours and against the exact torque-free motion over 1 s.

The project's speed targets are printed as PASS/MISS lines; a miss never changes the exit status.
A section that crashes is recorded (its error in ``errors``), the others still run and print, and
:func:`failed_sections` is not empty: ``lavendersim bench`` then exits 1 with one line naming them.
`--quick` is a short version (small step counts, N up to 1e3) for tests: they check that it runs
and that its output and JSON are well formed, never the timings.
"""
from __future__ import annotations

import ctypes
import datetime as _dt
import os
import platform
import shutil
import statistics
import subprocess
import tempfile
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

from .. import validate as V
from .._install import extra_command
from ..generated import layout as LY
from . import dopri5 as _dopri5
from . import effect_cost as _effect_cost
from . import envs as _envs
from . import full_inertia as _inertia
from . import numpy_section as _numpy_section
from . import scenes as _scenes
from . import timing as _timing

SCHEMA = "lavendersim-bench/1"
HERE = Path(__file__).resolve().parent
KERNEL_SOURCE = HERE / "handwritten_rk4.c"
CFLAGS = ["-O3", "-std=c99", "-fno-math-errno", "-ffp-contract=off", "-fPIC", "-shared"]  # the extension's (setup.py)
# the unconstrained peer: contraction into FMA allowed, this CPU's instruction set (never -ffast-math); GCC's pre-RA
# scheduler (-fschedule-insns) as the extension's AVX-512 tiles have it (batch_simd.h LV_TILE_H_SCHED_avx512): ~3 % here
FMA_SOURCE = HERE / "handwritten_fma.c"
# (name, flags, function): the classic loop (stage sums as FMAs: contraction on) and the scaled-increment loop (its
# products explicit fma(), its sums adds: contraction off, so GCC's fold of H + H into 2 H does not fuse them back)
FMA_VARIANTS = (("native", ["-march=native", "-ffp-contract=fast", "-fschedule-insns"], "lv_fma_rk4_free_soa"),
                ("native_512", ["-march=native", "-ffp-contract=fast", "-mprefer-vector-width=512", "-fschedule-insns"],
                 "lv_fma_rk4_free_soa"),
                ("scaled", ["-march=native", "-ffp-contract=off", "-fschedule-insns"], "lv_fma_rk4_free_soa_scaled"),
                ("scaled_512", ["-march=native", "-ffp-contract=off", "-mprefer-vector-width=512", "-fschedule-insns"],
                 "lv_fma_rk4_free_soa_scaled"))
# The fewest flops per body-step of any torque-free RK4 loop we know (an FMA counts 2; sqrt and division 1 each):
# the scaled-increment form the default tiles print (csrc/step.c lv_free_rk4_h, session 23): per stage the
# increments (dt/2) k of q and omega_b at k's own cost (21 multiplies, 8 adds: the dt/2 sits in the per-call
# constants, 3 multiplies per body and call, not counted), the stage inputs and the end by 9 adds and 1 multiply per
# number of (q, omega_b), q normalized (8 multiplies, 3 adds, one sqrt, one division), p += dt v (3 + 3):
# 4 * 29 + 7 * 10 + 13 + 6 = 205 (102 multiplies, 101 adds). The hand FMA peer's classic loop (lv_fma_rk4_free_soa)
# does 221 with a sqrt and a division (224 with its series), its scaled loop (lv_fma_rk4_free_soa_scaled) 208 (the
# series normalization 16 where q / |q| counts 13); the floor keeps the lowest count, so it does not rise with the
# loop that beats it.
FMA_FLOPS = 205
# the hand-written SoA peer, compiled once per instruction set (LV_ISA_* level -> name, extra flags)
# (avx512f: -fschedule-insns, as the extension's AVX-512 tile has it; it spills with 16 registers, so not avx2/sse2)
SOA_ISAS: tuple[tuple[int, str, list[str]], ...] = ((1, "sse2", []), (2, "avx2", ["-mavx2"]), (3, "avx512f", ["-mavx512f", "-fschedule-insns"]))

# The body every section uses.
MASS = 2.0
SIZE = (0.8, 0.4, 0.2)
OMEGA_B0 = (1.0, 0.5, 0.2)
V_W0 = (0.1, 0.0, 0.0)
Q0 = tuple((np.array([0.1, 0.2, 0.3, 0.9]) / np.linalg.norm([0.1, 0.2, 0.3, 0.9])).tolist())
DT = 1e-3
MAX_ROUNDS = 1000  # --rounds: interleaved rounds per section, 1..MAX_ROUNDS

TARGETS = {
    "c_single_rk4_ns": 100.0,          # ns per step, at most
    "mujoco_rk4_speedup": 90.0,        # MuJoCo RK4 ns / LavenderSim C ns, at least
    "batched_ns_per_body_step": 40.0,  # at most, every N >= 1e3
    "torque_free_vs_handwritten": 1.1,  # LavenderSim C / hand-written (inlined, same arithmetic), at most
    "simd_batch_vs_hand_soa": 1.3,     # C batch loop / hand-written SoA loop, best ISA of each, N >= 1e3, at most
    "simd_batch_ns_avx512": 8.0,       # C batch loop ns per body-step on AVX-512, N >= 1e3, at most
    "threads2_speedup": 1.8,           # C batch loop, 1 thread / 2 threads, N >= 1e4, at least
    "per_body_effect_ratio": 1.5,      # one applied_torque per body / plain body, ns per body-step, at most
    "python_step_c_ns": 1000.0,        # one Python sim.step() on the C backend, at most (issue 12)
    "float32_batch_speedup": 1.8,      # float64 / float32 ns per body-step, Sim.run in C, N >= 1e3, at least ("about 2x")
    "env_step_us": 10.0,               # ReactionWheelCube-v0 env.step() as gymnasium.make returns it, µs, at most
    "vector_env_us": 2.0,              # its vector env, µs per env-step at N = 1024, at most
    "scene_build_s": 0.2,              # Scene + add_bodies(1e4) + Sim(...), seconds, at most (issue 12)
    "state_lookup_ratio": 2.0,         # sim.state(name) at N = 1e4 / at N = 10, at most (O(1): ~1; a scan: ~1000)
    "full_inertia_ratio": 1.5,         # a full-tensor body / the same body by principal moments, ns per body-step (issue 26)
    "small_scene_ratio": 2.0,          # ns per body-step at N = 4 and 8 / at the largest N, at most (issue 30)
    "dopri5_per_rhs_vs_hand": 1.2,     # dopri5 ns per RHS evaluation / the hand C DOPRI5's, at most (issue 30)
    "dopri5_dense_vs_coarse": 1.3,     # dopri5 CPU at an output interval of 0.01 s / at one output step, at most (issue 30)
    "simd_batch_vs_flop_floor": 1.3,   # C batch loop / the flop floor (FMA_FLOPS / peak FMA rate), at most (issue 30)
    "numpy_vs_hand_numpy": 1.5,        # NumPy backend / hand NumPy RK4 (numpy_peers.py), N >= 1e3, at most (issue 30)
    "numpy_single_vs_python": 1.0,     # NumPy backend / a pure-Python RK4 loop, one body, at most (issue 30)
}
SMALL_SIZES = (4, 8)
PER_BODY_SIZES_FULL = (1, 100, 10_000)
PER_BODY_SIZES_QUICK = (1, 100)
PER_BODY_TORQUE = (1e-3, 2e-3, -1e-3)
BATCH_SIZES_FULL = (1, 4, 8, 10, 100, 1_000, 10_000, 100_000)
BATCH_SIZES_QUICK = (1, 4, 8, 10, 100, 1_000)
SIMD_SIZES_FULL = (1_000, 10_000)
SIMD_SIZES_QUICK = (1_000,)
THREADS_MIN_N = 1_000  # the SIMD batch sizes that also time two threads
SIMD_MIN_STEPS = 400   # steps per timed call at least: a batch call's setup (~30 ns per body: AoS <-> tiles) < 1.5 %
MUJOCO_INTEGRATORS = ("RK4", "Euler", "implicitfast")

EFFECT_SETS: tuple[tuple[str, list[tuple[str, dict[str, Any]]]], ...] = (
    ("torque-free", []),
    ("+ applied torque", [("applied_torque", {"torque_w": [1e-3, 2e-3, -1e-3]})]),
    ("+ damping", [("linear_damping", {"c": 0.05}), ("angular_damping", {"c": 2e-3})]),
    ("+ gravity", [("gravity", {})]),
    ("+ spherical joint", [("spherical_joint", {"anchor_w": [0.0, 0.0, 0.3]})]),
    ("+ reaction wheels", [("reaction_wheels", {"J": [1e-3, 1e-3, 1e-3], "torque_limit": 0.01,
                                                "speed_limit": 300.0, "c_w": 1e-5})]),
)
WHEEL_COMMAND = (1e-3, -5e-4, 2e-4)


_PROGRESS: list[Callable[[str], None] | None] = [None]   # the current run's progress callable (msg -> None), or None: silent


def _progress(msg: str) -> None:
    if _PROGRESS[0] is not None:
        _PROGRESS[0](msg)


# --------------------------------------------------------------------------- machine stamp

def _run(cmd: list[str], cwd=None) -> str | None:
    try:
        r = subprocess.run(cmd, capture_output=True, text=True, timeout=20, cwd=cwd)
    except (OSError, subprocess.SubprocessError):
        return None
    return r.stdout.strip() if r.returncode == 0 else None


def compiler() -> str | None:
    """The C compiler the bench uses: $CC, else cc, else gcc (None if none is found)."""
    for c in (os.environ.get("CC"), "cc", "gcc"):
        if c and shutil.which(c.split()[0]):
            return c
    return None


def source_commit() -> tuple[str | None, bool | None]:
    """The git commit this package runs from and whether tracked files differ from it.

    ``(None, None)`` when the package is not run from a git checkout (an installed wheel or
    sdist): then :func:`machine_stamp` records the installed version only."""
    repo = HERE.parent.parent
    commit = _run(["git", "rev-parse", "HEAD"], cwd=repo) if (repo / ".git").exists() else None
    if not commit:
        return None, None
    st = _run(["git", "status", "--porcelain", "--untracked-files=no"], cwd=repo)
    return commit, (bool(st) if st is not None else None)


def _cpu_flags() -> list[str]:
    """The SIMD flags of /proc/cpuinfo the bench cares about (empty where it cannot be read)."""
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.lower().startswith("flags"):
                have = set(line.split(":", 1)[1].split())
                return [f for f in ("sse2", "avx", "avx2", "fma", "avx512f") if f in have]
    except OSError:
        pass
    return []


def machine_stamp() -> dict:
    """Where and on what a measurement ran: CPU, cores, load, Python/NumPy/MuJoCo/LavenderSim
    versions, the C compiler, the git commit (None outside a checkout) and the UTC date."""
    cpu = None
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.lower().startswith("model name"):
                cpu = line.split(":", 1)[1].strip()
                break
    except OSError:
        pass
    cc = compiler()
    cc_version = (_run(cc.split() + ["--version"]) or "").splitlines()[0] if cc else None
    commit, dirty = source_commit()
    try:
        affinity = len(os.sched_getaffinity(0))
    except AttributeError:
        affinity = None
    try:
        load = [round(x, 2) for x in os.getloadavg()]
    except OSError:
        load = None
    try:
        import mujoco
        mj = mujoco.__version__
    except Exception:  # noqa: BLE001 - optional extra; any import failure means "not available"
        mj = None
    import lavendersim
    return {
        "cpu": cpu or platform.processor() or platform.machine(),
        "cores": os.cpu_count(), "cores_usable": affinity, "loadavg": load,
        "platform": platform.platform(),
        "python": f"{platform.python_implementation()} {platform.python_version()}",
        "numpy": np.__version__, "mujoco": mj, "lavendersim": lavendersim.__version__,
        "compiler": cc, "compiler_version": cc_version,
        "isa": (extension_isa() or {}).get("best"), "cpu_flags": _cpu_flags(),
        "git_commit": commit, "git_dirty": dirty,
        "date": _dt.datetime.now(_dt.timezone.utc).isoformat(timespec="seconds"),
    }


# --------------------------------------------------------------------------- timing

def _stats(seconds: list[float], units: int) -> dict:
    ns = [s / units * 1e9 for s in seconds]
    return {"ns_min": min(ns), "ns_median": statistics.median(ns), "units_per_call": units,
            "rounds": len(ns), "ns_samples": ns}


def interleaved_calls(cases: dict, rounds: int, label: str = "") -> dict:
    """timing.interleaved_calls (short calls of equal length, interleaved call by call) with the bench's progress."""
    return _timing.interleaved_calls(cases, rounds, label, _progress)


def interleaved(cases: dict, rounds: int, label: str = "") -> dict:
    """cases: name -> (fn, units) or (fn, units, "wall"). Warm each once, then `rounds` rounds, each
    timing every case once in turn (round-robin, so a noisy stretch hits all cases alike). A case is
    timed in CPU time of the process (time.process_time), or by the wall clock when marked "wall" (a
    case running on several threads, whose CPU time would hide the speed-up). Returns name -> _stats
    (with "clock": "cpu" or "wall")."""
    for fn, *_ in cases.values():
        fn()
    times: dict[str, list[float]] = {k: [] for k in cases}
    clocks = {k: time.perf_counter if c[2:] == ("wall",) else time.process_time for k, c in cases.items()}
    for r in range(rounds):
        if label:
            _progress(f"{label}: round {r + 1}/{rounds}")
        for k, (fn, *_) in cases.items():
            clock = clocks[k]
            t0 = clock()
            fn()
            times[k].append(clock() - t0)
    return {k: {**_stats(times[k], cases[k][1]), "clock": "wall" if clocks[k] is time.perf_counter else "cpu"}
            for k in cases}


# --------------------------------------------------------------------------- scenes

def body(name: str = "body"):
    from ..bodies import Body
    return Body.box(name, MASS, SIZE, q=Q0, omega_b=OMEGA_B0, v_w=V_W0)


def inertia() -> np.ndarray:
    return np.asarray(body().I_b, dtype=float)


def initial_state() -> np.ndarray:
    return np.asarray(body().x0, dtype=float).copy()


def single_sim(backend: str = "c", integrator: str = "rk4", effects=(), dt: float = DT):
    from ..scene import Scene
    from ..sim import Sim
    scene = Scene()
    scene.add_body(body())
    for name, params in effects:
        scene.add_effect(name, body="body", **params)
    sim = Sim(scene, dt=dt, integrator=integrator, backend=backend)
    if any(name == "reaction_wheels" for name, _ in effects):
        sim.set_wheel_command("body", WHEEL_COMMAND)
    return sim


def batch_sim(n: int, backend: str, torque: bool = False, dtype: str = "float64"):
    """n copies of the body with slightly different spins (independent trajectories); with torque,
    each body has its own applied_torque (n effects, one per body); dtype: the Sim's precision."""
    from ..bodies import Body
    from ..scene import Scene
    from ..sim import Sim
    scene = Scene()
    rng = np.random.default_rng(n)
    for i in range(n):
        w = np.asarray(OMEGA_B0) * (1.0 + 0.1 * rng.standard_normal(3))
        scene.add_body(Body.box(f"b{i}", MASS, SIZE, q=Q0, omega_b=w, v_w=V_W0))
        if torque:
            scene.add_effect("applied_torque", body=f"b{i}", torque_w=PER_BODY_TORQUE)
    return Sim(scene, dt=DT, integrator="rk4", backend=backend, dtype=dtype)


# --------------------------------------------------------------------------- hand-written reference

class NoCompiler(RuntimeError):
    """No C compiler: the hand-written peers are not measured (not a crash of the bench)."""


def compile_c(source: Path, extra: list[str], cc: str | None = None) -> tuple[ctypes.CDLL, str]:
    """Compile source with the extension's flags (CFLAGS) + extra into a temporary shared library and load it.

    Returns the library (it stays mapped after its file is removed) and the command. Raises NoCompiler without
    a compiler, RuntimeError with the compiler's message when it fails."""
    cc = cc or compiler()
    if cc is None:
        raise NoCompiler("no C compiler found (set CC, or install cc/gcc)")
    d = tempfile.mkdtemp(prefix="lavendersim-bench-")
    try:
        lib = Path(d) / (source.stem + ".so")
        cmd = cc.split() + CFLAGS + list(extra) + [str(source), "-o", str(lib), "-lm"]
        r = subprocess.run(cmd, capture_output=True, text=True)
        if r.returncode != 0:
            raise RuntimeError(f"compiling {source.name} failed ({' '.join(cmd)}): {r.stderr.strip()[-400:]}")
        return ctypes.CDLL(str(lib)), " ".join(cmd)
    finally:
        shutil.rmtree(d, ignore_errors=True)


class HandwrittenKernel:
    """handwritten_rk4.c compiled now into a temporary shared library, called through ctypes."""

    def __init__(self, cc: str | None = None):
        self.cc = cc or compiler()
        if self.cc is None:
            raise NoCompiler("no C compiler found (set CC, or install cc/gcc)")
        self.flags = list(CFLAGS)
        self._lib, self.command = compile_c(KERNEL_SOURCE, [], self.cc)
        f = self._lib.lv_ref_rk4_free
        f.argtypes = [ctypes.POINTER(ctypes.c_double), ctypes.POINTER(ctypes.c_double),
                      ctypes.c_double, ctypes.c_long, ctypes.c_int]
        f.restype = ctypes.c_long
        self._f = f
        self.soa: dict[str, Callable[..., Any]] = {}  # ISA name -> lv_ref_rk4_free_soa of a copy compiled for it
        self.floor: dict[str, Callable[..., Any]] = {}  # ISA name -> lv_ref_divider_floor_soa of that copy (the divider's limit)
        self.soa_commands: dict[str, str] = {}
        self.soa_errors: dict[str, str] = {}
        # variant name -> its function of handwritten_fma.c compiled with FMA_VARIANTS' flags
        self.fma: dict[str, Callable[..., Any]] = {}
        self.peak_fma: Callable[..., float] | None = None   # lv_peak_fma of the first variant
        self.fma_commands: dict[str, str] = {}
        self.fma_errors: dict[str, str] = {}

    def compile_fma(self, variants=FMA_VARIANTS) -> None:
        """Compile the unconstrained FMA peer once per (name, flags, function) (a failing one is recorded, not raised)."""
        for name, extra, symbol in variants:
            try:
                so, cmd = compile_c(FMA_SOURCE, list(extra), self.cc)   # the last -ffp-contract wins
            except RuntimeError as exc:
                self.fma_errors[name] = str(exc)
                continue
            f = getattr(so, symbol)
            f.argtypes = [ctypes.POINTER(ctypes.c_double), ctypes.POINTER(ctypes.c_double), ctypes.c_long,
                          ctypes.c_double, ctypes.c_long]
            f.restype = None
            self.fma[name] = f
            self.fma_commands[name] = cmd
            if self.peak_fma is None:
                p = so.lv_peak_fma
                p.argtypes = [ctypes.c_long, ctypes.c_double, ctypes.c_double]
                p.restype = ctypes.c_double
                self.peak_fma = p

    def advance_fma(self, name: str, X: np.ndarray, I: np.ndarray, dt: float, n_steps: int) -> None:
        """As advance_soa, with the FMA peer compiled as variant name (results differ in the last bits)."""
        _check_soa(X, I)
        dp = ctypes.POINTER(ctypes.c_double)
        self.fma[name](X.ctypes.data_as(dp), I.ctypes.data_as(dp), X.shape[1], float(dt), int(n_steps))

    def compile_soa(self, isas) -> None:
        """Compile the SoA peer once per (name, flags) in isas (a failing one is recorded, not raised)."""
        for name, extra in isas:
            try:
                so, cmd = compile_c(KERNEL_SOURCE, extra, self.cc)
            except RuntimeError as exc:
                self.soa_errors[name] = str(exc)
                continue
            for table, f in ((self.soa, so.lv_ref_rk4_free_soa), (self.floor, so.lv_ref_divider_floor_soa)):
                f.argtypes = [ctypes.POINTER(ctypes.c_double), ctypes.POINTER(ctypes.c_double), ctypes.c_long,
                              ctypes.c_double, ctypes.c_long]
                f.restype = None
                table[name] = f
            self.soa_commands[name] = cmd

    def advance_soa(self, isa: str, X: np.ndarray, I: np.ndarray, dt: float, n_steps: int, floor: bool = False) -> None:
        """Advance the bodies of X (13, n) float64 (struct of arrays) in place with the SoA peer of isa;
        I (3, n) their principal moments. floor: run the divider's floor loop instead (X then holds
        meaningless numbers)."""
        n = X.shape[1]
        _check_soa(X, I)
        dp = ctypes.POINTER(ctypes.c_double)
        (self.floor if floor else self.soa)[isa](X.ctypes.data_as(dp), I.ctypes.data_as(dp), n, float(dt), int(n_steps))

    def advance(self, x: np.ndarray, I_b: np.ndarray, dt: float, n_steps: int, check: bool = False) -> int:
        """Advance x (13,) float64 in place; returns -1, or the step at which it went non-finite."""
        if x.dtype != np.float64 or x.shape != (13,) or not x.flags.c_contiguous:
            raise TypeError("x must be a C-contiguous float64 array of shape (13,)")
        I_b = np.ascontiguousarray(I_b, dtype=np.float64)
        dp = ctypes.POINTER(ctypes.c_double)
        return int(self._f(x.ctypes.data_as(dp), I_b.ctypes.data_as(dp), float(dt), int(n_steps), 1 if check else 0))


def _check_soa(X: np.ndarray, I: np.ndarray) -> None:
    n = X.shape[1]
    if X.dtype != np.float64 or X.shape[0] != 13 or not X.flags.c_contiguous or I.shape != (3, n) \
            or I.dtype != np.float64 or not I.flags.c_contiguous:
        raise TypeError("X must be C-contiguous float64 (13, n) and I float64 (3, n)")


def fma_agreement(kernel: HandwrittenKernel, n: int = 257, n_steps: int = 1_000) -> dict:
    """Each FMA variant against the Sim (C, RK4) over n_steps from batch_sim(n)'s bodies: largest difference."""
    state0, _, X0, I = _batch_arrays(n)
    sim = batch_sim(n, "c")
    sim.run(n_steps)
    ref = np.asarray(sim.x, dtype=float).reshape(n, LY.STATE_SIZE)
    out: dict[str, float] = {"bodies": n, "steps": n_steps}
    for name in kernel.fma:
        X = X0.copy()
        kernel.advance_fma(name, X, I, DT, n_steps)
        out[f"max_abs_diff_{name}"] = float(np.max(np.abs(X.T - ref)))
    return out


def handwritten_agreement(kernel: HandwrittenKernel, n_steps: int = 10_000, every: int = 1_000,
                          backend: str = "c") -> dict:
    """The hand-written kernel and the Sim (torque-free scene, RK4) from the same state: the largest
    difference of any state number at every `every` steps over n_steps."""
    sim = single_sim(backend)
    traj = sim.record(n_steps, every=every)
    x = initial_state()
    I_b = inertia()
    worst, worst_rel = 0.0, 0.0
    for k in range(1, n_steps // every + 1):
        kernel.advance(x, I_b, DT, every)
        d = np.abs(traj.x[k, 0] - x)
        worst = max(worst, float(d.max()))
        worst_rel = max(worst_rel, float((d / np.maximum(np.abs(x), 1.0)).max()))
    return {"backend": backend, "steps": n_steps, "sampled_every": every, "max_abs_diff": worst,
            "max_rel_diff": worst_rel, "bitwise": worst == 0.0}


# --------------------------------------------------------------------------- MuJoCo

def mujoco_model_xml(integrator: str, dt: float = DT) -> str:
    """The same free body in MJCF: inertial frame = body frame = principal axes, no geoms, no gravity,
    contacts disabled."""
    I = inertia()
    return (f'<mujoco model="lavendersim-bench"><option timestep="{float(dt)!r}" integrator="{integrator}" '
            f'gravity="0 0 0"><flag contact="disable"/></option><worldbody><body name="body"><freejoint/>'
            f'<inertial pos="0 0 0" mass="{float(MASS)!r}" diaginertia="{float(I[0])!r} {float(I[1])!r} {float(I[2])!r}"/>'
            f'</body></worldbody></mujoco>')


def mujoco_available() -> tuple[bool, str]:
    try:
        import mujoco  # noqa: F401
    except Exception as exc:  # noqa: BLE001
        return False, f"mujoco is not installed or does not import ({type(exc).__name__}: {exc}); " \
                      f"install it with `{extra_command('bench')}`"
    return True, ""


class MujocoBody:
    """One MuJoCo free body set to our initial state. MuJoCo's free joint: qpos = [p_w (3), q (w, x,
    y, z)], qvel = [v_w (3, world), omega (3, body frame)] (MuJoCo docs, overview "Floating objects")."""

    def __init__(self, integrator: str):
        import mujoco
        self.mj = mujoco
        self.m = mujoco.MjModel.from_xml_string(mujoco_model_xml(integrator))
        self.d = mujoco.MjData(self.m)
        self.reset()
        try:
            from mujoco import rollout
            self.rollout = rollout
        except Exception:  # noqa: BLE001 - older mujoco without rollout
            self.rollout = None
        spec = mujoco.mjtState.mjSTATE_FULLPHYSICS
        self.spec = spec
        self.nstate = mujoco.mj_stateSize(self.m, spec)
        self.s0 = np.empty(self.nstate)
        mujoco.mj_getState(self.m, self.d, self.s0, spec)

    def reset(self) -> None:
        x = initial_state()
        q = x[LY.STATE_Q]
        self.mj.mj_resetData(self.m, self.d)
        self.d.qpos[0:3] = x[LY.STATE_P_W]
        self.d.qpos[3:7] = [q[3], q[0], q[1], q[2]]  # (x, y, z, w) -> (w, x, y, z)
        self.d.qvel[0:3] = x[LY.STATE_V_W]
        self.d.qvel[3:6] = x[LY.STATE_OMEGA_B]

    def step_loop(self, n: int) -> None:
        step, m, d = self.mj.mj_step, self.m, self.d
        for _ in range(n):
            step(m, d)

    def rollout_states(self, n: int, out: np.ndarray | None = None) -> np.ndarray:
        """n steps inside C from the initial state; returns (n, nstate) = [time, qpos (7), qvel (6)]."""
        if out is None:
            out = np.empty((1, n, self.nstate))
        self.rollout.rollout(self.m, self.d, self.s0[None], nstep=n, state=out)
        return out[0]


def mujoco_agreement(n_steps: int = 1000) -> dict:
    """MuJoCo (each integrator) against LavenderSim's C RK4 and against the exact torque-free motion
    (lavendersim.oracle.torque_free) over n_steps steps from the same state."""
    from lavendersim import oracle as ref
    t = DT * np.arange(1, n_steps + 1)
    exact = ref.torque_free(inertia(), OMEGA_B0, Q0, t)
    ours = single_sim("c").record(n_steps).x[1:, 0]
    x0 = initial_state()
    P, Q, V, W = LY.STATE_P_W, LY.STATE_Q, LY.STATE_V_W, LY.STATE_OMEGA_B
    p_exact = x0[P] + t[:, None] * x0[V]

    def errors(q, w, p, v, q_ref, w_ref, p_ref, v_ref):
        return {"attitude_rad_max": float(np.max(ref.attitude_error(q, q_ref))),
                "omega_b_max": float(np.max(np.abs(w - w_ref))),
                "p_w_max": float(np.max(np.abs(p - p_ref))), "v_w_max": float(np.max(np.abs(v - v_ref)))}

    out = {"steps": n_steps, "seconds": n_steps * DT,
           "lavendersim_rk4_vs_exact": errors(ours[:, Q], ours[:, W], ours[:, P], ours[:, V],
                                              exact.q, exact.omega_b, p_exact, np.broadcast_to(x0[V], (n_steps, 3)))}
    for integ in MUJOCO_INTEGRATORS:
        mb = MujocoBody(integ)
        if mb.rollout is not None:
            s = mb.rollout_states(n_steps)
            qpos, qvel = s[:, 1:8], s[:, 8:14]
        else:
            qpos, qvel = np.empty((n_steps, 7)), np.empty((n_steps, 6))
            for k in range(n_steps):
                mb.mj.mj_step(mb.m, mb.d)
                qpos[k], qvel[k] = mb.d.qpos, mb.d.qvel
        q = np.concatenate([qpos[:, 4:7], qpos[:, 3:4]], axis=1)  # (w, x, y, z) -> (x, y, z, w)
        w, p, v = qvel[:, 3:6], qpos[:, 0:3], qvel[:, 0:3]
        out[f"mujoco_{integ}_vs_lavendersim_rk4"] = errors(q, w, p, v, ours[:, Q], ours[:, W],
                                                            ours[:, P], ours[:, V])
        out[f"mujoco_{integ}_vs_exact"] = errors(q, w, p, v, exact.q, exact.omega_b, p_exact,
                                                 np.broadcast_to(x0[V], (n_steps, 3)))
    return out


# --------------------------------------------------------------------------- SIMD batch

def extension_isa() -> dict | None:
    """The C extension's instruction sets: {"levels": [(level, name), ...] this CPU can run (scalar
    first), "best": name} — None without the extension."""
    try:
        from ..backends.c_backend import _c as C
    except Exception:  # noqa: BLE001 - no C backend: the section is not run
        return None
    cur, _, best, best_name = C.isa()
    levels = []
    try:
        for lvl in range(best + 1):
            levels.append((lvl, C.isa(lvl)[1]))
    finally:
        C.isa(-1 if cur == best else cur)
    return {"levels": levels, "best": best_name, "best_level": best}


def _batch_arrays(n: int):
    """n bodies as batch_sim(n) builds them: state (n, 13) AoS, params (n, 4), and the same as SoA."""
    state = np.ascontiguousarray(np.asarray(batch_sim(n, "c").x, dtype=float).reshape(n, LY.STATE_SIZE))
    params = np.tile(np.concatenate([[MASS], inertia()]), (n, 1))
    return state, params, np.ascontiguousarray(state.T), np.ascontiguousarray(params[:, 1:].T)


def _at_isa(C, level: int, be, state: np.ndarray, params: np.ndarray, empty: np.ndarray, steps: int,
            contract: str = "off") -> None:
    """Select the C extension's instruction-set level (-1: its best), then one batch RK4 advance of `steps`
    (contract "fma": the opt-in FMA copy of the tiles, Sim(..., contract="fma"))."""
    C.isa(level)
    be.advance(state, params, empty, "rk4", True, DT, steps, contract=contract)


def _simd_kernel(ctx):
    """The hand-written peers for the simd section: the handwritten section's, or (that section not run) the SoA and
    FMA peers compiled now, without its agreement checks; None without a compiler."""
    if ctx.get("kernel") is None:
        try:
            kernel = HandwrittenKernel()
        except NoCompiler:
            return None
        isa = extension_isa()
        if isa is not None:
            kernel.compile_soa([(nm, extra) for lvl, nm, extra in SOA_ISAS if lvl <= isa["best_level"]])
        kernel.compile_fma()
        ctx["kernel"] = kernel
    return ctx["kernel"]


def simd_batch(kernel, sizes, body_steps: int, rounds: int) -> dict:
    """The C batch loop (one CBackend.advance call, torque-free RK4, q normalized) at every instruction
    set the CPU has, against the hand-written SoA loop compiled for each; ns per body-step. Every case is timed in
    timing.py's short calls interleaved call by call (~3 ms, at least SIMD_MIN_STEPS steps), the same for ours and the
    peers; the two-thread pair by the wall clock in long calls (body_steps per call), interleaved round by round.
    Also checks that every level and every hand copy give bitwise the same states after 50 steps."""
    from ..backends.c_backend import ROW, CBackend, contract_available
    from ..backends.c_backend import _c as C
    info = extension_isa()
    fma_ours = contract_available()
    assert info is not None   # (the import of the extension above succeeded)
    be = CBackend()
    empty = np.zeros((0, ROW))
    out = {"isa_levels": [nm for _, nm in info["levels"]], "best_isa": info["best"], "sizes": []}
    hand = {} if kernel is None else kernel.soa
    try:
        for n in sizes:
            _progress(f"SIMD batch: N = {n}")
            state0, params, X0, I = _batch_arrays(n)
            outs: dict[str, np.ndarray] = {}
            for lvl, nm in info["levels"]:
                C.isa(lvl)
                st = state0.copy()
                be.advance(st, params, empty, "rk4", True, DT, 50)
                outs[f"lavendersim_{nm}"] = st
            for nm in hand:
                X = X0.copy()
                kernel.advance_soa(nm, X, I, DT, 50)
                outs[f"hand_soa_{nm}"] = np.ascontiguousarray(X.T)
            ref = outs[f"lavendersim_{info['levels'][0][1]}"]
            bitwise = all(np.array_equal(ref, v) for v in outs.values())
            fma_diff = None
            if fma_ours:   # the opt-in FMA tiles after the same 50 steps: how far from the bitwise states
                st = state0.copy()
                _at_isa(C, -1, be, st, params, empty, 50, contract="fma")
                fma_diff = float(np.max(np.abs(st - ref)))
            cases: dict[str, tuple[Any, ...]] = {}   # fn(k): k steps (peak_fma: k iterations), timing.py's short calls
            for lvl, nm in info["levels"]:
                st = state0.copy()
                cases[f"lavendersim_{nm}"] = (lambda k, lvl=lvl, st=st: _at_isa(C, lvl, be, st, params, empty, k), n)
            if fma_ours:
                st = state0.copy()
                cases["lavendersim_fma"] = (lambda k, st=st: _at_isa(C, -1, be, st, params, empty, k, contract="fma"), n)
            for nm in hand:
                X = X0.copy()
                cases[f"hand_soa_{nm}"] = (lambda k, nm=nm, X=X: kernel.advance_soa(nm, X, I, DT, k), n)
            fma = {} if kernel is None else kernel.fma
            for nm in fma:
                X = X0.copy()
                cases[f"hand_fma_{nm}"] = (lambda k, nm=nm, X=X: kernel.advance_fma(nm, X, I, DT, k), n)
            if kernel is not None and kernel.peak_fma is not None:   # ns per flop at the peak FMA rate
                peak = kernel.peak_fma
                cases["peak_fma"] = (lambda k, peak=peak: peak(k, 0.999999, 1e-7), 128)
            floor_isa = list(hand)[-1] if hand else None   # the widest hand copy
            if floor_isa is not None:
                X = X0.copy()
                cases["divider_floor"] = (lambda k, X=X: kernel.advance_soa(floor_isa, X, I, DT, k, floor=True), n)
            t = _timing.interleaved_calls(cases, rounds, f"SIMD batch N = {n}", _progress, min_count=SIMD_MIN_STEPS)
            steps = t[f"lavendersim_{info['best']}"]["count_per_call"]
            if n >= THREADS_MIN_N:   # one thread against two by the wall clock (CPU time would hide the speed-up),
                wsteps = max(2, body_steps // n)   # in long calls: a short one would time the threads' start
                st1, st2 = state0.copy(), state0.copy()
                t.update(interleaved({
                    "lavendersim_1_thread_wall": (lambda st=st1: _at_isa(C, -1, be, st, params, empty, wsteps),
                                                  wsteps * n, "wall"),
                    "lavendersim_2_threads": (lambda st=st2: _two_threads(C, be, st, params, empty, wsteps),
                                              wsteps * n, "wall")}, rounds, f"SIMD batch N = {n}, threads"))
            row = {"n_bodies": n, "steps": steps, "bitwise_identical": bitwise, "divider_floor_isa": floor_isa, **t}
            if fma_diff is not None:
                row["fma_max_abs_diff_50_steps"] = fma_diff
            ours = t[f"lavendersim_{info['best']}"]["ns_min"]
            if fma:
                best_fma = min(fma, key=lambda nm: t[f"hand_fma_{nm}"]["ns_min"])
                row["best_fma"] = best_fma
                row["ratio_to_hand_fma"] = ours / t[f"hand_fma_{best_fma}"]["ns_min"]
                if "peak_fma" in t:
                    row["peak_gflops"] = 1.0 / t["peak_fma"]["ns_min"]
                    row["flop_floor_ns"] = FMA_FLOPS * t["peak_fma"]["ns_min"]
                    row["ratio_to_flop_floor"] = ours / row["flop_floor_ns"]
                    if "lavendersim_fma" in t:
                        row["fma_ratio_to_flop_floor"] = t["lavendersim_fma"]["ns_min"] / row["flop_floor_ns"]
                    row["hand_fma_over_flop_floor"] = t[f"hand_fma_{best_fma}"]["ns_min"] / row["flop_floor_ns"]
            if "lavendersim_2_threads" in t:
                row["threads_speedup"] = t["lavendersim_1_thread_wall"]["ns_min"] / t["lavendersim_2_threads"]["ns_min"]
                row["threads_cores_got"] = _cores_got(lambda st=st2: _two_threads(C, be, st, params, empty, wsteps))
                row["threads_loadavg"] = list(os.getloadavg())
            if hand:
                best_hand = min(hand, key=lambda nm: t[f"hand_soa_{nm}"]["ns_min"])
                row["best_hand_isa"] = best_hand
                row["ratio_to_hand_soa"] = ours / t[f"hand_soa_{best_hand}"]["ns_min"]
            out["sizes"].append(row)
    finally:
        C.isa(-1)
        C.threads(1)
    return out


def _cores_got(fn, calls: int = 3) -> float:
    """How many cores the process had while fn ran: its CPU time (every thread) over the wall clock, over a few
    calls. Two threads that got ~2 and no speed-up point at the code; ~1 means the second core was busy (another
    process: a wall-clock speed-up on a shared machine depends on it)."""
    c0, w0 = time.process_time(), time.perf_counter()
    for _ in range(calls):
        fn()
    return (time.process_time() - c0) / max(time.perf_counter() - w0, 1e-9)


def _two_threads(C, be, st, params, empty, steps) -> None:
    """One C batch call at the best ISA with its tiles shared by two threads."""
    C.isa(-1)
    C.threads(2)
    try:
        be.advance(st, params, empty, "rk4", True, DT, steps)
    finally:
        C.threads(1)


# --------------------------------------------------------------------------- the run

def settings(quick: bool) -> dict:
    if quick:
        return {"rounds": 2, "c_steps": 20_000, "simd_sizes": SIMD_SIZES_QUICK, "numpy_steps": 200, "py_step_calls": 500,
                "batch_sizes": BATCH_SIZES_QUICK, "per_body_sizes": PER_BODY_SIZES_QUICK,
                "c_body_steps": 40_000, "numpy_body_steps": 4_000,
                "effect_steps": 20_000, "mj_step_steps": 300, "mj_rollout_steps": 1_000,
                "agreement_steps": 2_000, "mujoco_agreement_steps": 200}
    return {"rounds": 5, "c_steps": 2_000_000, "simd_sizes": SIMD_SIZES_FULL, "numpy_steps": 10_000, "py_step_calls": 20_000,
            "batch_sizes": BATCH_SIZES_FULL, "per_body_sizes": PER_BODY_SIZES_FULL,
            "c_body_steps": 4_000_000, "numpy_body_steps": 400_000,
            "effect_steps": 1_000_000, "mj_step_steps": 20_000, "mj_rollout_steps": 50_000,
            "agreement_steps": 10_000, "mujoco_agreement_steps": 1_000}


SECTIONS = ("handwritten", "single", "batched", "effects", "per_body", "float32", "simd", "effect_cost", "dopri5",
            "numpy_peers", "env", "scenes", "inertia", "mujoco_agreement")


def _sec_handwritten(ctx) -> None:
    cfg, res = ctx["cfg"], ctx["res"]
    hw = res["handwritten"] = {"available": False, "source": str(KERNEL_SOURCE)}
    try:
        kernel = HandwrittenKernel()
    except NoCompiler as exc:   # not a crash: the peers are not measured
        hw["error"] = str(exc)
        return
    ctx["kernel"] = kernel
    hw.update(available=True, compile_command=kernel.command)
    isa = extension_isa()
    if isa is not None:
        kernel.compile_soa([(nm, extra) for lvl, nm, extra in SOA_ISAS if lvl <= isa["best_level"]])
        hw.update(soa_compile_commands=kernel.soa_commands, soa_compile_errors=kernel.soa_errors)
    kernel.compile_fma()
    hw.update(fma_compile_commands=kernel.fma_commands, fma_compile_errors=kernel.fma_errors)
    _progress("hand-written kernels compiled; checking them against the Sim")
    hw["agreement"] = handwritten_agreement(kernel, cfg["agreement_steps"], max(1, cfg["agreement_steps"] // 10))
    if kernel.fma:
        hw["fma_agreement"] = fma_agreement(kernel)


def _single_cases(ctx) -> dict:
    cfg, kernel = ctx["cfg"], ctx.get("kernel")
    n_c, n_np, n_py = cfg["c_steps"], cfg["numpy_steps"], cfg["py_step_calls"]
    sim_c, sim_np = single_sim("c"), single_sim("numpy")
    sim_pc, sim_pn = single_sim("c"), single_sim("numpy")
    cases = {
        "c_rk4": (lambda: sim_c.run(n_c), n_c),
        "numpy_rk4": (lambda: sim_np.run(n_np), n_np),
        "python_step_c": (lambda: [sim_pc.step() for _ in range(n_py)], n_py),
        "python_step_numpy": (lambda: [sim_pn.step() for _ in range(max(1, n_py // 10))], max(1, n_py // 10)),
    }
    if sim_c.backend.name == "c":   # the general C entry for one step (no checks, no snapshot) beside sim.step()
        from ..backends import c_backend as _cb
        xr, pr, er = sim_c.x.copy(), sim_c.params, sim_c.effects
        cases["c_call_1step"] = (lambda: [_cb._c.simulate(xr, pr, er, 2, 1, DT, 1) for _ in range(n_py)], n_py)
    if kernel is not None:
        xh, xhc, I_b = initial_state(), initial_state(), inertia()
        cases["handwritten_c"] = (lambda: kernel.advance(xh, I_b, DT, n_c), n_c)
        cases["handwritten_c_checked"] = (lambda: kernel.advance(xhc, I_b, DT, n_c, check=True), n_c)
    return cases


def _mujoco_cases(ctx, cases: dict) -> None:
    cfg, mj = ctx["cfg"], ctx["mj"]
    n_py = cfg["py_step_calls"]
    try:
        bodies = {}
        for integ in MUJOCO_INTEGRATORS:
            mb = bodies[integ] = MujocoBody(integ)
            n_s = cfg["mj_step_steps"]
            cases[f"mujoco_{integ}_mj_step"] = (lambda mb=mb, n_s=n_s: mb.step_loop(n_s), n_s)
            if mb.rollout is not None:
                n_r = cfg["mj_rollout_steps"]
                buf = np.empty((1, n_r, mb.nstate))
                cases[f"mujoco_{integ}_rollout"] = (lambda mb=mb, n_r=n_r, buf=buf: mb.rollout_states(n_r, buf), n_r)
        # mj_step on a model with no bodies: what one call from Python costs beyond the physics (binding overhead)
        mjm = bodies["RK4"].mj
        m0 = mjm.MjModel.from_xml_string("<mujoco/>")
        d0 = mjm.MjData(m0)
        cases["mujoco_empty_mj_step"] = (lambda st=mjm.mj_step, m0=m0, d0=d0, n=n_py: [st(m0, d0) for _ in range(n)],
                                         n_py)
        mj.update(version=mjm.__version__, rollout=bodies["RK4"].rollout is not None)
    except Exception as exc:  # noqa: BLE001 - an optional peer that does not work here: reported, not a crash
        mj.clear()
        mj.update(available=False, reason=f"mujoco imported but failed: {type(exc).__name__}: {exc}")
        for k in [k for k in cases if k.startswith("mujoco_")]:
            del cases[k]


def _sec_single(ctx) -> None:
    cases = _single_cases(ctx)
    if ctx["mj"]["available"]:
        _mujoco_cases(ctx, cases)
    _progress(f"single body: {len(cases)} cases interleaved, {ctx['R']} rounds")
    ctx["res"]["single_body"] = interleaved(cases, ctx["R"], "single body")


def _sec_batched(ctx) -> None:
    cfg, R = ctx["cfg"], ctx["R"]
    batched = ctx["res"]["batched"] = []
    for n in cfg["batch_sizes"]:
        _progress(f"batched: N = {n}: building scenes")
        sc, sn = batch_sim(n, "c"), batch_sim(n, "numpy")
        steps_c = max(2, cfg["c_body_steps"] // n)
        steps_n = max(2, min(2_000, cfg["numpy_body_steps"] // n))
        t = interleaved({"c": (lambda sc=sc, s=steps_c: sc.run(s), steps_c * n),
                         "numpy": (lambda sn=sn, s=steps_n: sn.run(s), steps_n * n)}, R, f"batched N = {n}")
        batched.append({"n_bodies": n, "c_steps": steps_c, "numpy_steps": steps_n, "c": t["c"], "numpy": t["numpy"]})
        del sc, sn


def _sec_effects(ctx) -> None:
    eff_cases: dict[str, tuple[Any, ...]] = {}
    acc: list[tuple[str, dict[str, Any]]] = []
    n_e = ctx["cfg"]["effect_steps"]
    for name, effs in EFFECT_SETS:
        acc = acc + effs
        s = single_sim("c", effects=list(acc))
        eff_cases[name] = (lambda s=s: s.run(n_e), n_e)
    _progress(f"effects: {len(eff_cases)} sets interleaved, {ctx['R']} rounds")
    et = interleaved(eff_cases, ctx["R"], "effects")
    base = et["torque-free"]["ns_min"]
    acc = []
    out = ctx["res"]["effects"] = []
    for name, effs in EFFECT_SETS:
        acc = acc + effs
        out.append({"name": name, "effects": [e for e, _ in acc], **et[name], "ratio_to_torque_free": et[name]["ns_min"] / base})


def _sec_dopri5(ctx) -> None:
    try:
        ctx["res"]["dopri5"] = _dopri5.dopri5_section(ctx["quick"], ctx["R"], interleaved_calls, compile_c, single_sim,
                                                      initial_state(), inertia())
    except NoCompiler as exc:
        ctx["res"]["dopri5"] = {"unavailable": str(exc)}
    ctx["res"]["dopri5"]["dense"] = _dopri5.dense_section(ctx["quick"], ctx["R"], interleaved_calls, single_sim)


def _sec_mujoco_agreement(ctx) -> None:
    mj = ctx["mj"]
    if mj["available"]:
        _progress("MuJoCo trajectory agreement")
        mj["agreement"] = mujoco_agreement(ctx["cfg"]["mujoco_agreement_steps"])


RUNNERS = {
    "handwritten": _sec_handwritten,
    "single": _sec_single,
    "batched": _sec_batched,
    "effects": _sec_effects,
    "per_body": lambda ctx: ctx["res"].__setitem__("per_body_effects", per_body_effects(
        ctx["cfg"]["per_body_sizes"], ctx["cfg"]["c_body_steps"], ctx["R"])),
    "float32": lambda ctx: ctx["res"].__setitem__("float32_batch", float32_batch(
        ctx["cfg"]["simd_sizes"], ctx["cfg"]["c_body_steps"], ctx["R"])),
    "simd": lambda ctx: extension_isa() is not None and ctx["res"].__setitem__("simd_batch", simd_batch(
        _simd_kernel(ctx), ctx["cfg"]["simd_sizes"], ctx["cfg"]["c_body_steps"], ctx["R"])),
    "effect_cost": lambda ctx: ctx["res"].__setitem__("effect_cost", _effect_cost.effect_cost_section(
        ctx["quick"], ctx["R"], interleaved_calls, _progress)),
    "dopri5": _sec_dopri5,
    "numpy_peers": lambda ctx: ctx["res"].__setitem__("numpy_peers", _numpy_section.numpy_section(
        ctx["quick"], ctx["R"], interleaved, batch_sim, inertia(), ctx["cfg"]["numpy_body_steps"], _progress)),
    "env": lambda ctx: ctx["res"].__setitem__("env", _envs.env_section(ctx["quick"], ctx["R"], interleaved)),
    "scenes": lambda ctx: ctx["res"].__setitem__("scenes", _scenes.scene_section(ctx["quick"], ctx["R"], interleaved)),
    "inertia": lambda ctx: ctx["res"].__setitem__("inertia", _inertia.inertia_section(ctx["quick"], ctx["R"],
                                                                                      interleaved)),
    "mujoco_agreement": _sec_mujoco_agreement,
}


def failed_sections(res: dict) -> list[dict]:
    """The sections of a run that crashed: [{"section", "error"}] (empty when every section ran)."""
    return list(res.get("errors", []))


def run(quick: bool = False, rounds: int | None = None, use_mujoco: bool = True, only=None, progress=None) -> dict:
    """Run the bench (see the module docstring) and return every figure as a JSON-ready dict.

    Parameters
    ----------
    quick : bool, optional
        The short version (small step counts, N up to 1e3).
    rounds : int, optional
        Interleaved rounds per section (default 5; 2 with quick), 1 ... MAX_ROUNDS.
    use_mujoco : bool, optional
        Measure MuJoCo when it is installed.
    only : iterable of str, optional
        Run only these sections (names in SECTIONS); default all.
    progress : callable, optional
        Called with a short message before each phase and round (default: silent).

    Returns
    -------
    dict
        Schema SCHEMA; ``errors`` lists the sections that crashed (section, error), ``standing`` the
        PASS/MISS/N/A lines, ``ratios`` the ratios.
    """
    cfg = settings(quick)
    if rounds is not None:
        cfg["rounds"] = V.integer("rounds", rounds, minimum=1)
        if cfg["rounds"] > MAX_ROUNDS:
            raise V.LavenderInputError("rounds", f"must be at most {MAX_ROUNDS}", f", got {rounds}")
    only = list(SECTIONS) if only is None else list(only)
    bad = [s for s in only if s not in SECTIONS]
    if bad:
        raise V.LavenderInputError("only", f"must name sections of {', '.join(SECTIONS)}", f", got {', '.join(bad)}")
    res: dict = {"schema": SCHEMA, "quick": quick, "machine": machine_stamp(),
                 "config": {"body": {"shape": "box", "mass": MASS, "size": list(SIZE), "I_b": inertia().tolist(),
                                     "q0": list(Q0), "omega_b0": list(OMEGA_B0), "v_w0": list(V_W0)},
                            "dt": DT, "integrator": "rk4", "normalize": True, "statistic": "min over rounds",
                            "clock": "CPU time of the process (time.process_time); two-thread cases: wall clock",
                            "short_calls": {"sections": ["effect_cost", "dopri5", "simd"], "call_s": _timing.CALL_S,
                                            "calls_per_round": _timing.CALLS_PER_ROUND,
                                            "min_calls_per_round": _timing.MIN_CALLS_PER_ROUND,
                                            "simd_min_steps": SIMD_MIN_STEPS},
                            "sections": only, **{k: (list(v) if isinstance(v, tuple) else v) for k, v in cfg.items()}},
                 "targets": TARGETS, "errors": [], "handwritten": {"available": False}}
    mj_ok, mj_why = mujoco_available() if use_mujoco else (False, "skipped (--no-mujoco)")
    ctx: dict[str, Any] = {"cfg": cfg, "R": cfg["rounds"], "quick": quick, "res": res,
           "mj": {"available": True} if mj_ok else {"available": False, "reason": mj_why}}
    _PROGRESS[0] = progress
    try:
        for name in SECTIONS:
            if name not in only:
                continue
            try:
                RUNNERS[name](ctx)
            except Exception as exc:  # noqa: BLE001 - recorded; the other sections still run; the CLI exits 1
                res["errors"].append({"section": name, "error": f"{type(exc).__name__}: {' '.join(str(exc).split())}"})
    finally:
        _PROGRESS[0] = None
    try:
        res["machine"]["loadavg_end"] = [round(x, 2) for x in os.getloadavg()]
    except OSError:
        res["machine"]["loadavg_end"] = None
    res["mujoco"] = ctx["mj"]
    res["ratios"] = ratios(res)
    res["standing"] = standing(res)
    return res


def float32_batch(sizes, body_steps: int, rounds: int) -> list[dict]:
    """For each N: the batch of batch_sim(N) stepped by Sim.run on the C backend in float64 and in float32
    (Sim(dtype="float32"): csrc/step_f32.c), interleaved in the same rounds; ns per body-step, the speed-up
    (float64 / float32) and the largest |x32 - x64| after the timed runs' first call (the same steps)."""
    out = []
    for n in sizes:
        _progress(f"float32 batch: N = {n}: building scenes")
        s64, s32 = batch_sim(n, "c"), batch_sim(n, "c", dtype="float32")
        steps = max(2, body_steps // n)
        s64.run(steps)
        s32.run(steps)
        diff = float(np.max(np.abs(s32.x.astype(np.float64) - s64.x)))
        t = interleaved({"float64": (lambda s=s64, k=steps: s.run(k), steps * n),
                         "float32": (lambda s=s32, k=steps: s.run(k), steps * n)}, rounds, f"float32 batch N = {n}")
        out.append({"n_bodies": n, "steps": steps, "float64": t["float64"], "float32": t["float32"],
                    "speedup": t["float64"]["ns_min"] / t["float32"]["ns_min"], "max_abs_diff_after_steps": diff})
        del s64, s32
    return out


def per_body_effects(sizes, body_steps: int, rounds: int) -> list[dict]:
    """For each N: N plain bodies and N bodies each with its own applied_torque, in C, interleaved in the
    same rounds; ns per body-step and the ratio (effected / plain)."""
    out = []
    for n in sizes:
        _progress(f"per-body effects: N = {n}: building scenes")
        plain, torque = batch_sim(n, "c"), batch_sim(n, "c", torque=True)
        steps = max(2, body_steps // n)
        t = interleaved({"plain": (lambda s=plain: s.run(steps), steps * n),
                         "applied_torque": (lambda s=torque: s.run(steps), steps * n)}, rounds, f"per-body effects N = {n}")
        out.append({"n_bodies": n, "steps": steps, "plain": t["plain"], "applied_torque": t["applied_torque"],
                    "ratio": t["applied_torque"]["ns_min"] / t["plain"]["ns_min"]})
        del plain, torque
    return out


def _ns(res, key):
    v = (res.get("single_body") or {}).get(key)
    return None if v is None else v["ns_min"]


def _div(a, b):
    return None if a is None or b is None or not b else a / b


def ratios(res: dict) -> dict:
    """Every ratio of the run by name (a section that did not run has none)."""
    c = _ns(res, "c_rk4")
    r: dict[str, Any] = {}
    for k in ("handwritten_c", "handwritten_c_checked"):
        r[f"c_rk4_over_{k}"] = _div(c, _ns(res, k))
    for k in ("numpy_rk4", "python_step_c", "python_step_numpy"):
        r[f"{k}_over_c_rk4"] = _div(_ns(res, k), c)
    for integ in MUJOCO_INTEGRATORS:
        for how in ("mj_step", "rollout"):
            r[f"mujoco_{integ}_{how}_over_c_rk4"] = _div(_ns(res, f"mujoco_{integ}_{how}"), c)
    for b in res.get("batched", []):
        n = b["n_bodies"]
        r[f"batched_{n}_c_ns_per_body_step_over_single"] = _div(b["c"]["ns_min"], c)
        r[f"batched_{n}_numpy_over_c"] = b["numpy"]["ns_min"] / b["c"]["ns_min"]
    small = _small_scenes(res)
    for n, v in (small or {}).get("ratios", {}).items():
        r[f"small_scene_{n}_over_N_{(small or {})['large_n']}"] = v
    for e in res.get("effects", []):
        r[f"effects[{e['name']}]_over_torque_free"] = e["ratio_to_torque_free"]
    for p in res.get("per_body_effects", []):
        r[f"per_body_applied_torque_{p['n_bodies']}_over_plain"] = p["ratio"]
    for row in (res.get("simd_batch") or {}).get("sizes", []):
        for key in ("ratio_to_hand_soa", "ratio_to_hand_fma", "ratio_to_flop_floor", "hand_fma_over_flop_floor",
                    "fma_ratio_to_flop_floor"):
            if key in row:
                r[f"simd_batch_{row['n_bodies']}_{key}"] = row[key]
    for n, row in (res.get("effect_cost") or {}).get("sizes", {}).items():
        for nm, v in row["ratios"].items():
            if nm != "plain":
                r[f"effect_cost[{nm}]_{n}_over_plain"] = v
    for n, v in (res.get("numpy_peers") or {}).get("sizes", {}).items():
        r[f"numpy_{n}_over_{v['peer']}"] = v["ratio"]
    d = res.get("dopri5") or {}
    if "ratio_per_rhs" in d:
        r["dopri5_per_rhs_over_hand"] = d["ratio_per_rhs"]
    if "ratio" in (d.get("dense") or {}):
        r["dopri5_dense_over_coarse"] = d["dense"]["ratio"]
    return {k: v for k, v in r.items() if v is not None}


def _small_scenes(res: dict) -> dict | None:
    """ns per body-step at N = SMALL_SIZES over the largest N of the batched section (None without them)."""
    rows = {b["n_bodies"]: b["c"]["ns_min"] for b in res.get("batched", [])}
    if not rows or not all(n in rows for n in SMALL_SIZES):
        return None
    big = max(rows)
    return {"large_n": big, "ratios": {n: rows[n] / rows[big] for n in SMALL_SIZES}}


def _line(name, value, limit, kind, unit, basis):
    if value is None:
        return {"name": name, "status": "N/A", "value": None, "limit": limit, "unit": unit, "basis": basis}
    ok = value <= limit if kind == "max" else value >= limit
    return {"name": name, "status": "PASS" if ok else "MISS", "value": value, "limit": limit,
            "kind": kind, "unit": unit, "basis": basis}


def _standing_single(res: dict) -> list[dict]:
    c = _ns(res, "c_rk4")
    out = [_line("C single-body RK4", c, TARGETS["c_single_rk4_ns"], "max", "ns/step",
                 "Sim.run(n), one C call, min over rounds")]
    out.append(_line("faster than MuJoCo RK4 (mj_step loop)", _div(_ns(res, "mujoco_RK4_mj_step"), c),
                     TARGETS["mujoco_rk4_speedup"], "min", "x", "MuJoCo mj_step in a Python loop / LavenderSim C"))
    out.append(_line("faster than MuJoCo RK4 (rollout, in C)", _div(_ns(res, "mujoco_RK4_rollout"), c),
                     TARGETS["mujoco_rk4_speedup"], "min", "x", "mujoco.rollout / LavenderSim C"))
    big = [b for b in res.get("batched", []) if b["n_bodies"] >= 1000]
    worst = max((b["c"]["ns_min"] for b in big), default=None)
    out.append(_line("batched ns per body-step (worst of N >= 1e3)", worst, TARGETS["batched_ns_per_body_step"],
                     "max", "ns/body-step", ("N = " + ", ".join(f"{b['n_bodies']:g}" for b in big)) if big
                     else "batched section not run"))
    small = _small_scenes(res)
    out.append(_line(f"small scenes N = {', '.join(map(str, SMALL_SIZES))} / the largest N, per body-step (worst)",
                     None if small is None else max(small["ratios"].values()), TARGETS["small_scene_ratio"], "max", "x",
                     "batched section not run" if small is None else
                     "Sim.run in C, torque-free; " + ", ".join(f"N = {n}: {v:.2f}" for n, v in small["ratios"].items())
                     + f" x N = {small['large_n']:g}"))
    out.append(_line("RK4 torque-free single body \u2264 1.1\u00d7 hand C", _div(c, _ns(res, "handwritten_c")),
                     TARGETS["torque_free_vs_handwritten"], "max", "x",
                     "LavenderSim C / handwritten_rk4.c (inlined, same arithmetic, -O3; no checks)"))
    return out


def _standing_simd(res: dict) -> list[dict]:
    sb = res.get("simd_batch") or {"sizes": []}
    rows = [r for r in sb["sizes"] if r["n_bodies"] >= 1000]
    worst = max((r["ratio_to_hand_soa"] for r in rows if "ratio_to_hand_soa" in r), default=None)
    out = [_line("SIMD batch loop / hand-written SoA loop (worst of N >= 1e3)", worst,
                 TARGETS["simd_batch_vs_hand_soa"], "max", "x",
                 (f"one C call, LavenderSim at {sb.get('best_isa')} / the fastest bitwise hand copy; "
                  "N = " + ", ".join(f"{r['n_bodies']:g}" for r in rows)) if rows else "simd section not run")]
    fl = [r for r in rows if "ratio_to_flop_floor" in r]
    out.append(_line("SIMD batch loop / the flop floor (worst of N >= 1e3)",
                     max((r["ratio_to_flop_floor"] for r in fl), default=None), TARGETS["simd_batch_vs_flop_floor"],
                     "max", "x", "simd section not run, or no compiler for the FMA peer" if not fl else
                     f"floor = {FMA_FLOPS} flops / the peak FMA rate measured now "
                     + ", ".join(f"({r['peak_gflops']:.1f} Gflop/s: {r['flop_floor_ns']:.2f} ns)" for r in fl)
                     + "; the best hand loop (handwritten_fma.c, FMA, -march=native) is at "
                     + ", ".join(f"{r['hand_fma_over_flop_floor']:.2f}x" for r in fl) + " of it"))
    ff = [r for r in fl if "fma_ratio_to_flop_floor" in r]
    out.append(_line("SIMD batch loop, contract='fma' (opt-in, not bitwise) / the flop floor (worst of N >= 1e3)",
                     max((r["fma_ratio_to_flop_floor"] for r in ff), default=None), TARGETS["simd_batch_vs_flop_floor"],
                     "max", "x", "no FMA copy of the tiles here (contract_available() False), or no floor measured"
                     if not ff else "Sim(..., contract='fma'): only q and omega through the stages, a*b+c fused, q "
                     "renormalized by the printed series (no sqrt, no division); max "
                     "|state - bitwise| after 50 steps " + ", ".join(f"{r['fma_max_abs_diff_50_steps']:.1e}" for r in ff)))
    ns512 = max((r["lavendersim_avx512f"]["ns_min"] for r in rows if "lavendersim_avx512f" in r), default=None)
    floor = max((r["divider_floor"]["ns_min"] for r in rows
                 if r.get("divider_floor_isa") == "avx512f" and "divider_floor" in r), default=None)
    out.append(_line("SIMD batch ns per body-step on AVX-512 (worst of N >= 1e3)", ns512,
                     TARGETS["simd_batch_ns_avx512"], "max", "ns/body-step",
                     ("one C call at avx512f" if ns512 is not None else "this CPU or build has no AVX-512 path")
                     + ("" if floor is None else f"; the divider alone (the normalization's 1 div + 1 sqrt per body-step, "
                        f"required for bitwise results) takes {floor:.2f}")))
    for p in res.get("per_body_effects", []):
        out.append(_line(f"one applied_torque per body / plain body, N = {p['n_bodies']:g}", p["ratio"],
                         TARGETS["per_body_effect_ratio"], "max", "x", "ns per body-step, same run"))
    big = [r for r in sb["sizes"] if r["n_bodies"] >= 10_000 and "threads_speedup" in r]
    out.append(_line("two threads / one, SIMD batch loop (worst of N >= 1e4)",
                     min((r["threads_speedup"] for r in big), default=None), TARGETS["threads2_speedup"], "min", "x",
                     "one C call at the best ISA, tiles split over 2 threads, wall clock (CPU time hides a speed-up); "
                     + (f"{os.cpu_count()} cores, load {(res['machine'].get('loadavg') or ['?'])[0]}" + _cores_note(big)
                        if big else "not measured (N >= 1e4 is not in this run)")))
    f32 = [r for r in res.get("float32_batch", []) if r["n_bodies"] >= 1000]
    out.append(_line("float32 / float64 batch throughput (worst of N >= 1e3)", min((r["speedup"] for r in f32), default=None),
                     TARGETS["float32_batch_speedup"], "min", "x",
                     ("Sim.run on the C backend, float64 ns / float32 ns per body-step, same rounds; N = "
                      + ", ".join(f"{r['n_bodies']:g}" for r in f32)) if f32 else "float32 section not run"))
    return out


def _standing_step(res: dict) -> list[dict]:
    py, bare, mj0 = _ns(res, "python_step_c"), _ns(res, "c_call_1step"), _ns(res, "mujoco_empty_mj_step")
    basis = "min over rounds" + ("" if bare is None else f"; _c.simulate for one step {bare / 1e3:.3f} µs: the general entry, "
                                                  "which parses and checks its arguments and indexes the effects per call; sim.step() "
                                                  "calls a C stepper prepared once")
    if mj0 is not None:
        basis += f"; mujoco.mj_step on an empty model (its Python-call overhead) {mj0 / 1e3:.3f} µs"
    return [_line("one Python sim.step(), c backend", py, TARGETS["python_step_c_ns"], "max", "ns/call", basis)]


def standing(res: dict) -> list[dict]:
    """The PASS/MISS/N/A line of every target (N/A: its section did not run, or crashed)."""
    out = _standing_single(res) + _standing_simd(res) + _standing_step(res)
    out += _effect_cost.standing_lines(res, _line, TARGETS)
    out += _dopri5.standing_lines(res, _line, TARGETS)
    out += _numpy_section.standing_lines(res, _line, TARGETS)
    for mod in (_envs, _scenes, _inertia):   # each says N/A when its section did not run
        out += mod.standing_lines(res, _line, TARGETS)
    return out


# --------------------------------------------------------------------------- report

def _f(ns: float) -> str:
    if ns >= 1e6:
        return f"{ns / 1e6:9.2f} ms"
    if ns >= 1e3:
        return f"{ns / 1e3:9.2f} µs"
    return f"{ns:9.1f} ns"


def report(res: dict) -> str:
    m = res["machine"]
    L = [f"lavendersim bench{' --quick' if res['quick'] else ''} — speed as ratios measured in one run",
         f"machine : {m['cpu']}; {m['cores']} cores ({m['cores_usable']} usable); load {m['loadavg']} at the start, "
         f"{m.get('loadavg_end')} at the end",
         f"software: {m['python']}, numpy {m['numpy']}, mujoco {m['mujoco'] or 'not installed'}, "
         f"lavendersim {m['lavendersim']}; compiler {m['compiler_version'] or 'none'}",
         f"isa     : extension's batch path {m.get('isa') or 'n/a'}; cpu flags {' '.join(m.get('cpu_flags') or []) or 'n/a'}",
         f"commit  : {m['git_commit'] or 'unknown'}{' (dirty)' if m['git_dirty'] else ''}; {m['date']}",
         f"body    : box {MASS} kg {SIZE} m, I_b = {np.array2string(inertia(), precision=5)}, "
         f"omega_b0 = {OMEGA_B0}, dt = {DT} s, RK4, q normalized; CPU time, min of {res['config']['rounds']} "
         "interleaved rounds"]
    for part in (_report_single, _report_batched, _report_simd, _report_mujoco):
        L += part(res)
    L += _envs.report_lines(res, _f)
    L += _scenes.report_lines(res, _f)
    L += _inertia.report_lines(res, _f)
    L += _effect_cost.report_lines(res, _f)
    L += _dopri5.report_lines(res, _f)
    L += _numpy_section.report_lines(res, _f)
    L.append("")
    L.append("targets")
    for t in res["standing"]:
        if t["value"] is None:
            L.append(f"  N/A   {t['name']}: not measured ({t['basis']})")
            continue
        op = "<=" if t["kind"] == "max" else ">="
        L.append(f"  {t['status']:<5} {t['name']}: {t['value']:.3g} {t['unit']} (target {op} {t['limit']:g}; {t['basis']})")
    for e in failed_sections(res):
        L.append(f"  CRASH section {e['section']}: {e['error']}")
    return "\n".join(L)


def targets_markdown(res: dict) -> str:
    """Every target of one run as a Markdown table (the tables of docs/performance.md are this, pasted), headed by
    the run's machine stamp: ``lavendersim bench --markdown`` prints it, ``--from RUN.json`` re-prints a saved run's.

    Parameters
    ----------
    res : dict
        One run's results (:func:`run`, or the JSON ``--out`` wrote).

    Returns
    -------
    str
        The stamp lines and a table: target, measured, limit, status, basis.
    """
    m = res["machine"]
    L = [f"One run of `lavendersim bench{' --quick' if res['quick'] else ''}` (commit {(m['git_commit'] or 'unknown')[:12]}"
         f"{', dirty' if m['git_dirty'] else ''}; {m['date']}; {m['cpu']}, {m['cores']} cores; batch path "
         f"{m.get('isa') or 'n/a'}; load {m['loadavg']} at the start, {m.get('loadavg_end')} at the end; CPU time, "
         f"min of {res['config']['rounds']} interleaved rounds).", "",
         "| target | measured | limit | status | basis |", "|---|---|---|---|---|"]
    def cell(text) -> str:   # a | inside a cell would end it
        return str(text).replace("|", "\\|")

    for t in res["standing"]:
        if t["value"] is None:
            L.append(f"| {cell(t['name'])} | — | {t['limit']:g} | N/A | {cell(t['basis'])} |")
            continue
        op = "≤" if t["kind"] == "max" else "≥"
        L.append(f"| {cell(t['name'])} | {t['value']:.3g} {t['unit']} | {op} {t['limit']:g} | {t['status']} | "
                 f"{cell(t['basis'])} |")
    for e in failed_sections(res):
        L.append(f"| section {e['section']} | crashed | — | CRASH | {cell(' '.join(str(e['error']).split()))} |")
    return "\n".join(L)


def _report_single(res: dict) -> list[str]:
    s, hw = res.get("single_body"), res["handwritten"]
    if s is None:
        return []
    c = s["c_rk4"]["ns_min"]
    L = [""]
    L.append("single body                                         per step     median   x C")
    rows = [("c_rk4", f"LavenderSim C, Sim.run({s['c_rk4']['units_per_call']:.0e} steps)"),
            ("handwritten_c", "hand-written C99 RK4 (ctypes, 1 call)"),
            ("handwritten_c_checked", "hand-written + finite check each step"),
            ("numpy_rk4", f"LavenderSim NumPy, Sim.run({s['numpy_rk4']['units_per_call']})"),
            ("python_step_c", "one Python sim.step() call, c backend"),
            ("c_call_1step", "_c.simulate for one step (general entry)"),
            ("mujoco_empty_mj_step", "MuJoCo mj_step, empty model (call overhead)"),
            ("python_step_numpy", "one Python sim.step() call, numpy backend")]
    for integ in MUJOCO_INTEGRATORS:
        rows += [(f"mujoco_{integ}_mj_step", f"MuJoCo {integ}: mj_step in a Python loop"),
                 (f"mujoco_{integ}_rollout", f"MuJoCo {integ}: rollout (steps in C)")]
    for key, label in rows:
        if key in s:
            L.append(f"  {label:<48}{_f(s[key]['ns_min'])} {_f(s[key]['ns_median'])} {s[key]['ns_min'] / c:7.2f}")
    if not hw["available"]:
        L.append(f"  hand-written reference unavailable: {hw.get('error')}")
    elif "agreement" in hw:
        a = hw["agreement"]
        L.append(f"  hand-written vs Sim ({a['steps']} steps): max |Δx| = {a['max_abs_diff']:.2e}"
                 f"{' (bitwise identical)' if a.get('bitwise') else ''}")
    if "fma_agreement" in hw:
        a = hw["fma_agreement"]
        L.append(f"  hand FMA SoA loop vs Sim ({a['bodies']} bodies, {a['steps']} steps): max |Δx| = "
                 + ", ".join(f"{v:.2e} ({k[len('max_abs_diff_'):]})" for k, v in a.items() if k.startswith("max_abs")))
    mj = res["mujoco"]
    if not mj["available"]:
        L.append(f"  MuJoCo: not measured — {mj.get('reason')}")
    return L


def _report_batched(res: dict) -> list[str]:
    L = []
    if res.get("batched"):
        L += ["", "batched: N bodies in one C call                 C ns/body-step  NumPy ns/body-step  NumPy/C"]
    for b in res.get("batched", []):
        L.append(f"  N = {b['n_bodies']:<8g} ({b['c_steps']:>8} steps C, {b['numpy_steps']:>5} NumPy) "
                 f"{b['c']['ns_min']:10.1f}  {b['numpy']['ns_min']:14.1f}  {b['numpy']['ns_min'] / b['c']['ns_min']:10.1f}")
    if res.get("effects"):
        L += ["", "effect sets on one body, C (cumulative)           ns/step   x torque-free"]
    for e in res.get("effects", []):
        L.append(f"  {e['name']:<46}{e['ns_min']:8.1f}   {e['ratio_to_torque_free']:6.2f}")
    if res.get("per_body_effects"):
        L.append("")
        L.append("per-body effects, C: one applied_torque per body      plain ns/body-step  torque ns/body-step  ratio")
        for p in res["per_body_effects"]:
            L.append(f"  N = {p['n_bodies']:<8g} ({p['steps']:>8} steps)                    {p['plain']['ns_min']:10.1f}"
                     f"  {p['applied_torque']['ns_min']:19.1f}  {p['ratio']:5.2f}")
    if res.get("float32_batch"):
        L.append("")
        L.append("float32 batch, C (Sim(dtype='float32')), torque-free RK4   float64 ns/body-step  float32  speed-up  max|x32-x64|")
        for r in res["float32_batch"]:
            L.append(f"  N = {r['n_bodies']:<8g} ({r['steps']:>8} steps)                     {r['float64']['ns_min']:10.2f}"
                     f"  {r['float32']['ns_min']:9.2f}  {r['speedup']:7.2f}x  {r['max_abs_diff_after_steps']:.2e}")
    return L


def _report_simd(res: dict) -> list[str]:
    L = []
    sb = res.get("simd_batch")
    if sb and sb["sizes"]:
        L.append("")
        names = sb["isa_levels"]
        hands = [k[len("hand_soa_"):] for k in sb["sizes"][0] if k.startswith("hand_soa_")]
        L.append(f"SIMD batch, ns/body-step: the C batch loop (one call) per instruction set (best here: "
                 f"{sb['best_isa']}) and the hand-written SoA loop")
        fmas = [k[len("hand_fma_"):] for k, v in sb["sizes"][0].items() if k.startswith("hand_fma_") and isinstance(v, dict)]
        L.append("  N          " + "".join(f"{'ours ' + nm:>14}" for nm in names)
                 + "".join(f"{'hand ' + nm:>14}" for nm in hands) + "".join(f"{'fma ' + nm:>16}" for nm in fmas)
                 + "   ours/hand  ours/fma  ours/floor  bitwise  ours fma (opt-in)  fma/floor")
        for r in sb["sizes"]:
            L.append(f"  {r['n_bodies']:<9g}" + "".join(f"{r['lavendersim_' + nm]['ns_min']:14.2f}" for nm in names)
                     + "".join(f"{r['hand_soa_' + nm]['ns_min']:14.2f}" for nm in hands)
                     + "".join(f"{r['hand_fma_' + nm]['ns_min']:16.2f}" for nm in fmas)
                     + "".join(f"{r[k]:{w}.2f}" if k in r else f"{'—':>{w}}" for k, w in
                               (("ratio_to_hand_soa", 12), ("ratio_to_hand_fma", 10), ("ratio_to_flop_floor", 12)))
                     + f"  {'yes' if r['bitwise_identical'] else 'NO':>7}"
                     + (f"{r['lavendersim_fma']['ns_min']:19.2f}" if "lavendersim_fma" in r else f"{'—':>19}")
                     + (f"{r['fma_ratio_to_flop_floor']:11.2f}" if "fma_ratio_to_flop_floor" in r else f"{'—':>11}"))
        for r in sb["sizes"]:
            if "flop_floor_ns" in r:
                L.append(f"  N = {r['n_bodies']:g}: flop floor {r['flop_floor_ns']:.2f} ns/body-step ({FMA_FLOPS} flops at "
                         f"{r['peak_gflops']:.1f} Gflop/s, the FMA rate a C loop reaches now); the FMA hand loop is at "
                         f"{r['hand_fma_over_flop_floor']:.2f}x of it")
        for r in sb["sizes"]:
            if "divider_floor" in r:
                L.append(f"  N = {r['n_bodies']:g}: divider floor at {r['divider_floor_isa']} {r['divider_floor']['ns_min']:.2f} "
                         "ns/body-step (only the normalization's division + sqrt a bitwise step needs; no loop below it)")
        for r in sb["sizes"]:
            if "threads_speedup" in r:
                L.append(f"  N = {r['n_bodies']:g}: two threads {r['lavendersim_2_threads']['ns_min']:.2f} ns/body-step, "
                         f"speed-up {r['threads_speedup']:.2f}x over one (both by the wall clock)"
                         + (f"; the process got {r['threads_cores_got']:.2f} cores then" if "threads_cores_got" in r
                            else ""))
    return L


def _cores_note(rows: list[dict]) -> str:
    """The two-thread line's note: the cores the process got during those calls (CPU / wall) and the load then."""
    got = [r for r in rows if "threads_cores_got" in r]
    if not got:
        return ""
    return ("; the two threads got " + ", ".join(f"{r['threads_cores_got']:.2f}" for r in got)
            + " cores (CPU time / wall; ~1: the second core was busy), load then "
            + ", ".join(f"{r['threads_loadavg'][0]:.2f}" for r in got))


def _report_mujoco(res: dict) -> list[str]:
    L, mj = [], res["mujoco"]
    if mj["available"] and "agreement" in mj:
        a = mj["agreement"]
        L.append("")
        L.append(f"trajectory agreement over {a['seconds']:g} s ({a['steps']} steps), max over the run: "
                 "attitude rad, |Δω_b| rad/s, |Δp| m, |Δv| m/s")

        def row(label, e):
            return (f"  {label:<40}{e['attitude_rad_max']:10.2e} {e['omega_b_max']:10.2e} "
                    f"{e['p_w_max']:10.2e} {e['v_w_max']:10.2e}")
        L.append(row("LavenderSim RK4 vs exact", a["lavendersim_rk4_vs_exact"]))
        for integ in MUJOCO_INTEGRATORS:
            L.append(row(f"MuJoCo {integ} vs LavenderSim RK4", a[f"mujoco_{integ}_vs_lavendersim_rk4"]))
            L.append(row(f"MuJoCo {integ} vs exact", a[f"mujoco_{integ}_vs_exact"]))
    return L
