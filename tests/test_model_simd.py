"""The batched RK4 path of jointed wheel bodies (the reaction-wheel cube: a spherical joint and three wheels) in C
(lavendersim/csrc/model_simd.h): RK4 model bodies whose effects are the same built-in ones go on struct-of-arrays
tiles of 32, one body per lane, one copy per instruction set. Every instruction set must give bitwise the scalar
path's states, wheel rates and applied torques (advance_model in csrc/step.c: same operations in the same order),
for counts that are no multiple of the tile or of any lane count, with or without scene-wide effects, q
normalized or not, on one or two threads, beside model and plain bodies that are not in the group; and a body
that diverges inside a tile must be reported as the scalar path reports it.
(_lavender_c is built by `pip install`; the suite needs the C backend.)"""
from __future__ import annotations

import numpy as np
import pytest

import lavendersim as lv
from lavendersim import _lavender_c as C
from lavendersim.backends import Models, c_backend
from lavendersim.errors import DivergenceError
from lavendersim.generated import layout as LY

WHEELS = dict(J=[1.0e-4, 1.2e-4, 0.9e-4], torque_limit=0.2, speed_limit=300.0, c_w=1e-5)


@pytest.fixture
def levels():
    """Every ISA level this CPU runs, scalar (0: the SIMD paths off) first; the best ISA and one thread after."""
    best = C.isa(-1)[2]
    yield list(range(best + 1))
    C.isa(-1)
    C.threads(1)


def _cube(sc: lv.Scene, name: str, rng: np.random.Generator, joint: bool = True, wheels: bool = True,
          cutoff: float = 0.0) -> None:
    s = 0.1 + 0.1 * rng.random()
    q = rng.standard_normal(4)
    sc.add_body(lv.Body.box(name, mass=0.5 + rng.random(), size=(s, s, s), p_w=tuple(0.1 * rng.standard_normal(3)),
                            q=tuple(q / np.linalg.norm(q)), omega_b=tuple(2.0 * rng.standard_normal(3)),
                            v_w=tuple(0.5 * rng.standard_normal(3) * (not joint))))
    if joint:
        sc.add_effect("spherical_joint", body=name, anchor_w=list(0.05 * rng.standard_normal(3)))
    if wheels:
        sc.add_effect("reaction_wheels", body=name, cutoff=cutoff, **WHEELS)


def _scene(n: int, seed: int, effects: str = "none", others: bool = False) -> lv.Scene:
    """n wheel cubes (the group; half of them with the cut-off motor), with scene-wide effects: none, gravity and
    angular damping (the vector env's), or every built-in one (linear damping reads the joint's kinematic v);
    others: bodies outside the group between them (a cube with an effect of its own, a joint-only body, a free
    wheeled body, plain boxes with and without an effect)."""
    rng = np.random.default_rng(seed)
    sc = lv.Scene()
    for i in range(n):
        _cube(sc, f"c{i}", rng, cutoff=float(i % 2))
        if others and i % 9 == 4:
            k = i // 9
            _cube(sc, f"own{k}", rng)
            sc.add_effect("applied_torque", body=f"own{k}", torque_w=list(1e-3 * rng.standard_normal(3)))
            _cube(sc, f"joint{k}", rng, wheels=False)
            _cube(sc, f"free{k}", rng, joint=False)
            sc.add_body(lv.Body.box(f"box{k}", 1.0, (0.1, 0.2, 0.3), omega_b=tuple(rng.standard_normal(3))))
            sc.add_body(lv.Body.box(f"pushed{k}", 1.0, (0.3, 0.2, 0.1), omega_b=tuple(rng.standard_normal(3))))
            sc.add_effect("applied_torque", body=f"pushed{k}", torque_w=[1e-3, 0.0, -1e-3])
    if effects in ("gravity", "all"):
        sc.add_effect("gravity", g_w=[0.0, 0.0, -9.81])
    if effects == "gravity":
        sc.add_effect("angular_damping", c=1e-3)
    elif effects == "all":
        sc.add_effect("linear_damping", c=0.2)
        sc.add_effect("angular_damping", c=2e-3)
        sc.add_effect("applied_torque", torque_w=[1e-3, -2e-3, 5e-4])
        sc.add_effect("force_at_point", r_b=[0.01, 0.02, -0.01], F_w=[0.1, 0.0, -0.2])
    return sc


def _sim(sc: lv.Scene, seed: int, normalize: bool = True) -> lv.Sim:
    """A Sim of the scene with random wheel rates and commands (commands beyond the torque limit included)."""
    sim = lv.Sim(sc, dt=1e-3, integrator="rk4", backend="c", normalize=normalize)
    rng = np.random.default_rng(seed + 1000)
    wheeled = [i for i, name in enumerate(sim.names) if "reaction_wheels" in sc.model_effects(name)]
    for i in wheeled:
        sim.set_state(sim.names[i], Omega=list(100.0 * rng.standard_normal(3)))
    u = np.zeros((len(sim.names), 3))
    u[wheeled] = 0.3 * rng.standard_normal((len(wheeled), 3))
    sim.set_wheel_commands(u)
    return sim


def _run(sc: lv.Scene, level: int, seed: int, normalize: bool = True, steps=(70, 50)) -> tuple[np.ndarray, ...]:
    """x, Omega and the applied torques after runs of `steps` (70: one chunk of 64 steps and a partial one)."""
    assert C.isa(level)[0] == level
    sim = _sim(sc, seed, normalize)
    for n in steps:
        sim.run(n)
    return np.array(sim.x, copy=True), np.array(sim.Omega, copy=True), np.array(sim.wheel_torques_applied, copy=True)


def _assert_same(got, want, msg):
    for g, w, what in zip(got, want, ("x", "Omega", "applied")):
        np.testing.assert_array_equal(g, w, err_msg=f"{what}: {msg}")


@pytest.mark.parametrize("n", [7, 16, 45, 100])     # fewer than LV_SOA_MIN (scalar), one partial tile, 2, 4 tiles
@pytest.mark.parametrize("effects", ["none", "gravity", "all"])
@pytest.mark.parametrize("normalize", [True, False])
def test_every_isa_is_the_scalar_path_bitwise(levels, n, effects, normalize):
    sc = _scene(n, seed=n, effects=effects)
    want = _run(sc, 0, seed=n, normalize=normalize)
    assert all(np.isfinite(w).all() for w in want)
    for level in levels[1:]:
        _assert_same(_run(sc, level, seed=n, normalize=normalize), want, C.isa(level)[1])


@pytest.mark.parametrize("effects", ["none", "all"])
def test_group_beside_other_bodies_is_the_scalar_path_bitwise(levels, effects):
    """Cubes with an effect of their own, joint-only, free wheeled and plain bodies between the group's cubes:
    every body ends as on the scalar path."""
    sc = _scene(100, seed=21, effects=effects, others=True)
    want = _run(sc, 0, seed=21)
    for level in levels[1:]:
        _assert_same(_run(sc, level, seed=21), want, C.isa(level)[1])


@pytest.mark.parametrize("n", [45, 100])
def test_two_threads_are_the_scalar_path_bitwise(levels, n):
    sc = _scene(n, seed=n + 3, effects="gravity", others=True)
    want = _run(sc, 0, seed=n)
    for threads in (1, 2):
        assert C.threads(threads) in (1, threads)      # 1 where the build has no POSIX threads
        for level in levels[1:]:
            _assert_same(_run(sc, level, seed=n), want, f"{C.isa(level)[1]}, {threads} threads")


def test_the_commands_and_effects_act_on_the_group(levels):
    """The tiles do apply the motor and the scene-wide effects: other commands or no effects end elsewhere."""
    a = _run(_scene(45, seed=5, effects="all"), levels[-1], seed=5)
    b = _run(_scene(45, seed=5, effects="none"), levels[-1], seed=5)
    c = _run(_scene(45, seed=5, effects="all"), levels[-1], seed=6)
    assert np.abs(a[0] - b[0]).max(axis=1).min() > 0 and np.abs(a[1] - c[1]).max(axis=1).min() > 0


def _raw(sim: lv.Sim) -> tuple:
    m = sim._models
    return (np.array(sim.x, copy=True), np.array(sim.params, copy=True), np.array(sim.effects, copy=True),
            Models(m.rows.copy(), m.Omega.copy(), m.command.copy(), m.applied.copy()))


@pytest.mark.parametrize("bad", [[29], [40, 5], [31, 32], [99, 0]])   # in a tile; two tiles; tile edges
@pytest.mark.parametrize("threads", [1, 2])
def test_divergence_in_a_model_tile_is_reported_as_on_the_scalar_path(levels, bad, threads):
    """Cubes spun up among 100 until RK4 overflows (after a step or two; the later listed sooner): every level
    reports the same step and body (the earliest step, then the lowest body), and that body's last finite state
    and wheel rates (after a step: the tile's arithmetic, not the initial state)."""
    sim = _sim(_scene(100, seed=8, effects="gravity"), seed=8)
    x0, params, effects, models0 = _raw(sim)
    for k, b in enumerate(bad):
        x0[b, LY.STATE_OMEGA_B] = [5000.0 * (1 + k), 5000.0, -5000.0]
    C.threads(threads)
    reports = []
    for level in levels:
        C.isa(level)
        x, models = x0.copy(), Models(models0.rows, models0.Omega.copy(), models0.command, models0.applied.copy())
        with pytest.raises(DivergenceError) as err:
            c_backend.CBackend().advance(x, params, effects, "rk4", True, 1e-3, 50, models, restore=False)
        b = err.value.body
        reports.append((err.value.step, b, x[b].copy(), models.Omega[b].copy()))
    assert reports[0][0] >= 1 and reports[0][1] in bad, reports[0][:2]
    assert np.isfinite(reports[0][2]).all() and np.isfinite(reports[0][3]).all()
    for level, r in zip(levels[1:], reports[1:]):
        assert r[:2] == reports[0][:2], C.isa(level)[1]
        np.testing.assert_array_equal(r[2], reports[0][2])
        np.testing.assert_array_equal(r[3], reports[0][3])


def test_divergence_in_a_sim_leaves_the_others_as_on_the_scalar_path(levels):
    """Sim names the same step and body on every level and leaves every body as before the call; the other
    bodies then run on as on the scalar path."""
    sc = _scene(45, seed=12, effects="gravity", others=True)
    results = []
    for level in levels:
        C.isa(level)
        sim = _sim(sc, seed=12)
        sim.run(10)
        i = sim.names.index("c30")
        sim._x[i, LY.STATE_OMEGA_B] = [1e150, 1e150, -1e150]
        before = np.array(sim.x, copy=True)
        with pytest.raises(DivergenceError) as err:
            sim.run(40)
        np.testing.assert_array_equal(sim.x, before)
        sim._x[i, LY.STATE_OMEGA_B] = 0.0
        sim.run(40)
        results.append((err.value.step, err.value.body, np.array(sim.x, copy=True), np.array(sim.Omega, copy=True)))
    assert results[0][1] == sim.names.index("c30")
    for level, r in zip(levels[1:], results[1:]):
        assert r[:2] == results[0][:2], C.isa(level)[1]
        np.testing.assert_array_equal(r[2], results[0][2])
        np.testing.assert_array_equal(r[3], results[0][3])
