"""The Gymnasium section of `lavendersim bench`: ReactionWheelCube-v0 per env step against its own physics.

Measured interleaved in the same rounds (min over rounds, as every section):

* ``env_wrapped`` — ``env.step(a)`` of the env as ``gymnasium.make`` returns it (TimeLimit, OrderEnforcing,
  PassiveEnvChecker around it; ``max_episode_steps`` raised so no episode ends inside the timing);
* ``env_unwrapped`` — ``env.unwrapped.step(a)`` of a second env;
* ``physics`` — ``sim.run(substeps)`` of a third env's Sim (the env's physics per step alone: 10 substeps of
  the wheel + joint cube, RK4, one C call);
* ``vector`` — ``gymnasium.make_vec(..., num_envs=N, vectorization_mode="vector_entry_point").step(A)`` at
  N = VECTOR_N, per env-step (the call's time / N), and ``vector_physics``: its Sim's ``run(substeps)`` alone;
* ``vector_2_threads`` / ``vector_physics_2_threads`` — the same with ``c_backend.threads(2)`` (the cubes of one
  C call shared over two threads; the setting is restored after each call).

Actions alternate between +a and -a (a fixed, saturating-free torque), so the cubes stay near rest and no
episode terminates. The ratios env / physics are the Python overhead. Skipped (``available: False`` with the
reason) without gymnasium (the ``gym`` extra).
"""
from __future__ import annotations

import os
from collections.abc import Callable
from typing import Any

import numpy as np

VECTOR_N = 1024
ACTION = (0.05, -0.03, 0.02)     # fractions of the motor torque limit


def settings(quick: bool) -> dict:
    """Calls per round: single-env steps and vector-env steps (each of VECTOR_N env-steps)."""
    return {"env_steps": 200, "vector_steps": 2} if quick else {"env_steps": 5_000, "vector_steps": 20}


def env_section(quick: bool, rounds: int, interleaved) -> dict:
    """Time the env, the unwrapped env, the physics and the vector env (see the module docstring).

    Parameters
    ----------
    quick : bool
        Short run (settings(True)).
    rounds : int
        Interleaved rounds.
    interleaved : callable
        lavendersim.bench.interleaved (cases name -> (fn, units), rounds, label) -> name -> stats.

    Returns
    -------
    dict
        ``available``; when True the per-case stats (ns per env step), ``ratios`` and the setup; else ``reason``.
    """
    try:
        import gymnasium
    except ImportError:
        return {"available": False, "reason": "gymnasium is not installed (pip install -e '.[gym]')"}
    from ..envs.reaction_wheel_cube import ReactionWheelCubeEnv
    from ..envs.vector import ReactionWheelCubeVectorEnv
    cfg = settings(quick)
    n_env, n_vec = cfg["env_steps"], cfg["vector_steps"]
    env_id = "lavendersim:ReactionWheelCube-v0"
    wrapped = gymnasium.make(env_id, max_episode_steps=10**9)
    bare = gymnasium.make(env_id).unwrapped
    phys = gymnasium.make(env_id).unwrapped
    assert isinstance(phys, ReactionWheelCubeEnv), type(phys)
    for e in (wrapped, bare, phys):
        e.reset(seed=0)
    acts = [np.array(ACTION, np.float32), -np.array(ACTION, np.float32)]
    sim = phys.sim
    assert sim is not None   # (built by reset)
    sim.set_wheel_command("cube", np.array(ACTION) * phys.torque_limit)
    k = phys.substeps

    def loop(step, n):
        a0, a1 = acts
        for _ in range(n // 2):
            step(a0)
            step(a1)

    vec = gymnasium.make_vec(env_id, num_envs=VECTOR_N, vectorization_mode="vector_entry_point")
    vec.reset(seed=0)
    A = [np.tile(a, (VECTOR_N, 1)) for a in acts]
    vec_env = vec.unwrapped
    assert isinstance(vec_env, ReactionWheelCubeVectorEnv), type(vec_env)
    vsim = vec_env.sim
    vsim.set_wheel_commands(np.tile(np.array(ACTION) * phys.torque_limit, (VECTOR_N, 1)))
    have_c = vsim.backend.name == "c"

    def vec_loop(n):
        for i in range(n):
            vec.step(A[i & 1])

    def vphys_loop(n):
        for _ in range(n):
            vsim.run(k)

    def two_threads(fn):
        from ..backends import c_backend

        def run():
            before = c_backend.threads()
            c_backend.threads(2)
            try:
                fn()
            finally:
                c_backend.threads(before)
        return run

    n_env -= n_env % 2
    cases: dict[str, tuple[Any, ...]] = {
        "env_wrapped": (lambda: loop(wrapped.step, n_env), n_env),
        "env_unwrapped": (lambda: loop(bare.step, n_env), n_env),
        "physics": (lambda: _repeat(sim.run, k, n_env), n_env),
        "vector": (lambda: vec_loop(n_vec), n_vec * VECTOR_N),
        "vector_physics": (lambda: vphys_loop(n_vec), n_vec * VECTOR_N),
    }
    if have_c:   # one thread against two by the wall clock (CPU time would hide the speed-up)
        cases["vector_wall"] = (lambda: vec_loop(n_vec), n_vec * VECTOR_N, "wall")
        cases["vector_physics_wall"] = (lambda: vphys_loop(n_vec), n_vec * VECTOR_N, "wall")
        cases["vector_2_threads"] = (two_threads(lambda: vec_loop(n_vec)), n_vec * VECTOR_N, "wall")
        cases["vector_physics_2_threads"] = (two_threads(lambda: vphys_loop(n_vec)), n_vec * VECTOR_N, "wall")
    t = interleaved(cases, rounds, "ReactionWheelCube-v0")
    wrapped.close()
    vec.close()
    ns = {name: s["ns_min"] for name, s in t.items()}
    ratios = {"env_wrapped_over_physics": ns["env_wrapped"] / ns["physics"],
              "env_unwrapped_over_physics": ns["env_unwrapped"] / ns["physics"],
              "vector_over_vector_physics": ns["vector"] / ns["vector_physics"]}
    if have_c:
        ratios["vector_1_thread_over_2_threads"] = ns["vector_wall"] / ns["vector_2_threads"]
        ratios["vector_physics_1_thread_over_2_threads"] = ns["vector_physics_wall"] / ns["vector_physics_2_threads"]
    return {"available": True, "backend": vsim.backend.name, "substeps": k, "dt": sim.dt, "vector_n": VECTOR_N,
            "loadavg": [round(x, 2) for x in os.getloadavg()] if hasattr(os, "getloadavg") else None,
            "gymnasium": gymnasium.__version__, "wrappers": str(wrapped), **cfg, "cases": t, "ratios": ratios}


def _repeat(fn: Callable[[int], None], arg: int, n: int) -> None:
    """n calls fn(arg)."""
    for _ in range(n):
        fn(arg)


def best_vector_ns(sec: dict) -> tuple[float, str]:
    """The vector env's ns per env-step for the target: one thread, CPU time (two threads are timed by the wall
    clock, which a loaded machine inflates: their speed-up is reported beside it, not mixed into it)."""
    return sec["cases"]["vector"]["ns_min"], "threads(1), CPU time"


def standing_lines(res: dict, line, targets: dict) -> list[dict]:
    """The section's PASS/MISS lines (N/A without gymnasium), built with lavendersim.bench._line."""
    sec = res.get("env") or {"available": False, "reason": "not run"}
    loadavg = (sec.get("loadavg") or ["?"])[0]
    if not sec["available"]:
        why = sec.get("reason", "not run")
        return [line("env.step() ReactionWheelCube-v0, as gymnasium.make returns it", None, targets["env_step_us"],
                     "max", "µs/step", why),
                line(f"vector env per env-step, N = {VECTOR_N}", None, targets["vector_env_us"], "max",
                     "µs/env-step", why)]
    c, r = sec["cases"], sec["ratios"]
    v, how = best_vector_ns(sec)
    return [line("env.step() ReactionWheelCube-v0, as gymnasium.make returns it", c["env_wrapped"]["ns_min"] / 1e3,
                 targets["env_step_us"], "max", "µs/step",
                 f"unwrapped {c['env_unwrapped']['ns_min'] / 1e3:.2f} µs, physics alone (sim.run({sec['substeps']})) "
                 f"{c['physics']['ns_min'] / 1e3:.2f} µs; env / physics {r['env_wrapped_over_physics']:.2f}x; "
                 f"{sec['backend']} backend, load {loadavg}"),
            line(f"vector env per env-step, N = {VECTOR_N}", v / 1e3, targets["vector_env_us"], "max", "µs/env-step",
                 f"{how}; physics alone {c['vector_physics']['ns_min'] / 1e3:.2f} µs"
                 + (f" (2 threads {c['vector_physics_2_threads']['ns_min'] / 1e3:.2f} µs)"
                    if "vector_physics_2_threads" in c else "")
                 + f"; vec / physics {r['vector_over_vector_physics']:.2f}x; load {loadavg}")]


def report_lines(res: dict, fmt) -> list[str]:
    """The section of the text report (fmt: lavendersim.bench._f, ns -> text)."""
    sec = res.get("env")
    if sec is None:
        return []
    if not sec["available"]:
        return ["", f"ReactionWheelCube-v0: not measured — {sec['reason']}"]
    c = sec["cases"]
    L = ["", f"ReactionWheelCube-v0 ({sec['substeps']} substeps of {sec['dt'] * 1e3:g} ms, RK4, {sec['backend']} backend; "
         f"gymnasium {sec['gymnasium']})            per env-step     median  x physics"]
    rows = [("env_wrapped", "physics", "env.step(), as gymnasium.make returns it"),
            ("env_unwrapped", "physics", "env.unwrapped.step()"),
            ("physics", "physics", f"physics alone: sim.run({sec['substeps']})"),
            ("vector", "vector_physics", f"vector env N = {sec['vector_n']}: step()"),
            ("vector_physics", "vector_physics", f"vector env N = {sec['vector_n']}: sim.run({sec['substeps']})"),
            ("vector_2_threads", "vector_physics_2_threads", "vector env step(), threads(2)"),
            ("vector_physics_2_threads", "vector_physics_2_threads", "vector env sim.run, threads(2)")]
    for key, base, label in rows:
        if key in c:
            L.append(f"  {label:<56}{fmt(c[key]['ns_min'])} {fmt(c[key]['ns_median'])} "
                     f"{c[key]['ns_min'] / c[base]['ns_min']:8.2f}")
    r = sec["ratios"]
    if "vector_1_thread_over_2_threads" in r:
        L.append(f"  two threads / one (wall clock, load {(sec.get('loadavg') or ['?'])[0]}): vector step "
                 f"{r['vector_1_thread_over_2_threads']:.2f}x, physics {r['vector_physics_1_thread_over_2_threads']:.2f}x")
    return L
