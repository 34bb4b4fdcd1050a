"""The simulator: invariants, declared effects only, integrators, divergence, on every backend."""
import numpy as np
import pytest

import lavendersim as lv
from lavendersim.generated import kernels_numpy as K
from lavendersim.generated import layout as LY

BACKENDS = ["numpy", "c"]


def tumbling(I=(1.0, 2.0, 3.0), omega_b=(1.0, 0.5, 0.2), **kw):
    s = lv.Scene()
    s.add_body(lv.Body("b", 1.0, I, omega_b=omega_b, **kw))
    return s


@pytest.mark.parametrize("backend", BACKENDS)
def test_torque_free_rk4_conserves_energy_and_world_momentum(backend):
    sim = lv.Sim(tumbling(), dt=1e-3, integrator="rk4", backend=backend)
    L0, E0 = sim.angular_momentum_w("b"), sim.kinetic_energy()
    sim.run(10_000)  # 10 s
    assert np.linalg.norm(sim.angular_momentum_w("b") - L0) <= 1e-10 * np.linalg.norm(L0)
    assert abs(sim.kinetic_energy() - E0) <= 1e-10 * E0
    assert sim.t == pytest.approx(10.0, abs=1e-12)


# 1e5 NumPy steps take tens of seconds: slow (the C run of the same 1e5 steps stays in the quick set)
@pytest.mark.parametrize("backend", [pytest.param(b, marks=pytest.mark.slow) if b == "numpy" else b for b in BACKENDS])
def test_quaternion_norm_stays_unit_over_1e5_steps(backend):
    sim = lv.Sim(tumbling(omega_b=(3.0, -2.0, 5.0)), dt=1e-3, backend=backend)
    traj = sim.record(100_000, every=1000)
    norms = np.linalg.norm(traj.body("b").q, axis=-1)
    assert np.max(np.abs(norms - 1)) <= 1e-12


@pytest.mark.parametrize("backend", BACKENDS)
def test_without_normalization_the_norm_drifts_with_euler(backend):
    sim = lv.Sim(tumbling(omega_b=(3.0, -2.0, 5.0)), dt=1e-2, integrator="euler", backend=backend, normalize=False)
    sim.run(100)
    assert np.linalg.norm(sim.state("b").q) > 1.01
    assert "q not normalized" in sim.pipeline[0]


@pytest.mark.parametrize("backend", BACKENDS)
def test_explicit_euler_gains_energy_where_rk4_does_not(backend):
    E = {}
    for integ in ("euler", "rk4"):
        sim = lv.Sim(tumbling(), dt=1e-2, integrator=integ, backend=backend)
        E0 = sim.kinetic_energy()
        sim.run(1000)
        E[integ] = sim.kinetic_energy() / E0 - 1
    assert E["euler"] > 1e-3
    assert abs(E["rk4"]) < 1e-7


@pytest.mark.parametrize("backend", BACKENDS)
def test_isotropic_body_has_exactly_no_gyroscopic_term(backend):
    s = lv.Scene()
    s.add_body(lv.Body.sphere("ball", 2.0, 0.3, omega_b=(1.3, -0.7, 2.9)))
    sim = lv.Sim(s, dt=1e-2, backend=backend)
    sim.run(500)
    assert np.array_equal(sim.state("ball").omega_b, [1.3, -0.7, 2.9])


ZERO_EFFECTS = [
    ("applied_torque", {"torque_w": [0, 0, 0]}),
    ("force_at_point", {"r_b": [0.3, 0.1, 0], "F_w": [0, 0, 0]}),
    ("gravity", {"g_w": [0, 0, 0]}),
    ("linear_damping", {"c": 0.0}),
    ("angular_damping", {"c": 0.0}),
]


@pytest.mark.parametrize("backend", BACKENDS)
@pytest.mark.parametrize("name,params", ZERO_EFFECTS)
def test_an_effect_at_zero_strength_gives_the_same_numbers(backend, name, params):
    base = lv.Sim(tumbling(v_w=(0.5, 0, 0)), dt=1e-3, backend=backend)
    s = tumbling(v_w=(0.5, 0, 0))
    s.add_effect(name, body="b", **params)
    zero = lv.Sim(s, dt=1e-3, backend=backend)
    base.run(500)
    zero.run(500)
    np.testing.assert_allclose(zero.x, base.x, rtol=0, atol=1e-15)
    assert "rigid_body_increments_free_c" in base.pipeline[1] and name in zero.pipeline[1]


def test_pipeline_lists_only_declared_effects_per_body():
    s = lv.Scene()
    s.add_body(lv.Body.box("a", 1, (1, 1, 1)))
    s.add_body(lv.Body.box("b", 1, (1, 2, 3)))
    s.add_effect("angular_damping", body="b", c=0.1)
    p = lv.Sim(s, backend="numpy").pipeline
    assert p[1].startswith("a: torque- and force-free (no effect terms) -> stages (q, omega_b): "
                           "rigid_body_increments_free_c")
    assert "angular_damping" in p[2] and "gravity" not in " ".join(p)
    # the kernels it runs: a decoupled body-frame torque (its rotation staged alone, its translation's flow)
    assert "-> stages (q, omega_b): rigid_body_increments_rot_b_c; translation: translation_flow;" in p[2]


@pytest.mark.parametrize("backend", BACKENDS)
def test_pipeline_names_the_right_hand_side_each_body_runs(backend):
    """A force alone, world torques, body-frame torques with a force: the class both backends pick (rhs_classes) and
    the right-hand side it runs under euler."""
    s = lv.Scene()
    for n in "abc":
        s.add_body(lv.Body.box(n, 1, (1, 2, 3)))
    s.add_effect("gravity", body="a")
    s.add_effect("applied_torque", body="b", torque_w=[0.0, 0.0, 1.0])
    s.add_effect("linear_damping", body="c", c=0.1)
    s.add_effect("angular_damping", body="c", c=0.1)
    p = lv.Sim(s, integrator="euler", backend=backend).pipeline
    assert p[1].endswith("-> right-hand side: linear_acceleration, rigid_body_rhs_force_c")
    assert p[2].endswith("-> right-hand side: " + ("rigid_body_rhs_torque_c" if backend == "c" else "rigid_body_rhs_c"))
    assert p[3].endswith("-> right-hand side: linear_acceleration, rigid_body_rhs_body_c")


@pytest.mark.parametrize("backend", BACKENDS)
def test_effects_match_their_physics(backend):
    """Each effect's acceleration at the first instant, checked against its formula."""
    s = lv.Scene()
    q = K.axis_angle_to_quat(np.array([1.0, 2.0, 2.0]) / 3, 0.7)
    s.add_body(lv.Body.box("b", 2.0, (0.4, 0.3, 0.2), q=q, v_w=(1, -2, 0.5), omega_b=(0.3, 0.2, -0.1)))
    s.add_effect("gravity", g_w=(0, 0, -9.81))
    s.add_effect("linear_damping", c=0.5)
    s.add_effect("force_at_point", body="b", r_b=(0.2, 0, 0), F_w=(0, 3, 0))
    s.add_effect("applied_torque", body="b", torque_w=(0.1, 0, 0))
    s.add_effect("angular_damping", c=0.05)
    # One explicit Euler step of dt = 1 s returns x0 + f(x0): the derivative itself, up to rounding.
    # |omega|*dt = 0.37 is beyond euler's validity bound (0.1): a derivative probe, not a simulation
    sim = lv.Sim(s, dt=1.0, integrator="euler", backend=backend, normalize=False, on_bound="warn")
    x0 = sim.x[0].copy()
    sim.step()
    a = sim.x[0] - x0
    m, I_b = 2.0, sim.params[0, 1:4]
    F = m * np.array([0, 0, -9.81]) - 0.5 * np.array([1, -2, 0.5]) + np.array([0, 3, 0])
    np.testing.assert_allclose(a[7:10], F / m, rtol=1e-12)
    R = K.quat_to_matrix(q)
    w_b = np.array([0.3, 0.2, -0.1])
    tau_w = np.cross(R @ [0.2, 0, 0], [0, 3, 0]) + [0.1, 0, 0] - 0.05 * (R @ w_b)
    wdot = np.linalg.solve(np.diag(I_b), R.T @ tau_w - np.cross(w_b, I_b * w_b))
    np.testing.assert_allclose(a[10:13], wdot, rtol=1e-10)


@pytest.mark.parametrize("backend", BACKENDS)
def test_semi_implicit_euler_updates_velocity_before_position(backend):
    s = lv.Scene()
    s.add_body(lv.Body.sphere("s", 1.0, 0.1))
    s.add_effect("gravity", g_w=(0, 0, -10.0))
    sim = lv.Sim(s, dt=0.1, integrator="semi_implicit_euler", backend=backend)
    sim.step()
    np.testing.assert_allclose(sim.state("s").v_w, [0, 0, -1.0], rtol=1e-15)
    np.testing.assert_allclose(sim.state("s").p_w, [0, 0, -0.1], rtol=1e-15)


@pytest.mark.parametrize("backend", BACKENDS)
def test_divergence_names_step_body_and_cause_and_restores_state(backend):
    s = lv.Scene()
    s.add_body(lv.Body.sphere("calm", 1.0, 0.1))
    s.add_body(lv.Body("wild", 1.0, (1, 2, 3), omega_b=(300.0, 400.0, 10.0)))
    sim = lv.Sim(s, dt=0.5, integrator="euler", backend=backend, normalize=False)
    before = sim.x.copy()
    with pytest.raises(lv.DivergenceError) as e:
        sim.run(1000)
    assert e.value.body == 1 and e.value.body_name == "wild"
    assert "wild" in str(e.value) and "step" in str(e.value) and "dt" in str(e.value)
    assert np.array_equal(sim.x, before)
    assert sim.steps == 0


@pytest.mark.parametrize("backend", BACKENDS)
def test_omega_world_and_body_agree(backend):
    q = K.axis_angle_to_quat(np.array([0.0, 1.0, 0.0]), np.pi / 2)
    s = lv.Scene()
    s.add_body(lv.Body.box("rod", 1.0, (0.8, 0.2, 0.2), q=q, omega_w=(0, 0, 1.0)))
    sim = lv.Sim(s, backend=backend)
    np.testing.assert_allclose(sim.state("rod").omega_b, [-1.0, 0, 0], atol=1e-15)
    np.testing.assert_allclose(sim.state("rod").omega_w, [0, 0, 1.0], atol=1e-15)


# ------------------------------------------------------------------ sim.step() inside C (issue 12)

def _scenes():
    from lavendersim import control as lc

    plain = tumbling()
    forced = tumbling(omega_b=(0.3, 2.0, 0.1))
    forced.add_effect("gravity", g_w=(0.0, 0.0, -9.81))
    forced.add_effect("angular_damping", body="b", c=0.05)
    cube = lc.chapter_cube("corner", damping=1e-3, omega_b=(0.2, -0.1, 0.3))
    free_sat, torqued_sat = lv.Scene(), lv.Scene()   # wheels, no joint: the growth check of body and wheels in C
    for sc in (free_sat, torqued_sat):
        sc.add_body(lv.Body.box("cube", 1.0, (0.1, 0.2, 0.3), v_w=(0.1, 0.0, 0.0), omega_b=(0.3, 0.2, 0.1)))
        sc.add_effect("reaction_wheels", body="cube", J=[1e-4] * 3, torque_limit=0.1, speed_limit=100.0)
    torqued_sat.add_effect("applied_torque", body="cube", torque_w=(0.0, 0.0, 1e-3))
    return {"plain": (plain, "rk4"), "forced": (forced, "rk4"), "plain_euler": (plain, "euler"),
            "splitting": (plain, "splitting"), "implicit_gyro": (forced, "implicit_gyro"), "cube": (cube, "rk4"),
            "dopri5": (forced, "dopri5"), "dopri5_cube": (cube, "dopri5"), "free_sat": (free_sat, "rk4"),
            "torqued_sat": (torqued_sat, "rk4")}


def _sim(scene, integrator):
    if "cube" in scene.bodies:   # the chapter cube: a wheeled body on a joint
        sim = lv.Sim(scene, dt=1e-3, integrator=integrator, backend="c")
        sim.set_state("cube", Omega=(5.0, -3.0, 1.0))
        sim.set_wheel_command("cube", (0.01, -0.02, 0.005))
        return sim
    return lv.Sim(scene, dt=1e-3, integrator=integrator, backend="c")


def _python_path_only(sim):
    """The same Sim with its C fast path switched off (step and run take the Python path)."""
    sim.__dict__.pop("step", None)
    sim._fast = None
    return sim


@pytest.mark.parametrize("case", list(_scenes()))
def test_step_inside_c_equals_the_python_path_bitwise(case):
    scene, integrator = _scenes()[case]
    fast, slow, fast_run = _sim(scene, integrator), _python_path_only(_sim(scene, integrator)), _sim(scene, integrator)
    assert fast._fast is not None, "the C fast path should serve this scene"
    for _ in range(300):
        fast.step()
    slow.run(300)                       # the Python path (chunked checks)
    for _ in range(30):
        fast_run.run(10)                # run(n) inside C
    assert np.array_equal(fast_run.x, slow.x) and fast_run.steps == 300
    assert np.array_equal(fast.x, slow.x)
    assert np.array_equal(fast._models.Omega, slow._models.Omega)
    assert (fast.steps, fast.t, fast.rhs_evals) == (slow.steps, slow.t, slow.rhs_evals) == (300, slow.t, slow.rhs_evals)
    assert fast.t == 300 * fast.dt
    # a state written between steps is checked again, then stepped as the Python path does
    name = fast.names[0]
    for s in (fast, slow):
        s.set_state(name, omega_b=(0.4, -0.2, 0.1))
    for _ in range(5):
        fast.step()
        slow.run(1)
    assert np.array_equal(fast.x, slow.x)


def test_step_in_a_loop_raises_at_the_first_bad_step_and_restores_it():
    sim = lv.Sim(tumbling(omega_b=(0.5, 0.5, 50.0)), dt=0.1, integrator="euler", backend="c", on_bound="raise",
                 max_growth=None)
    with pytest.raises(lv.DivergenceError) as e:   # beyond euler's bound already: the pre-step check
        sim.step()
    assert sim.steps == 0 and "validity bound" in str(e.value)
    sim = lv.Sim(tumbling(omega_b=(0.2, 0.3, 8.0)), dt=1e-2, integrator="euler", backend="c", max_growth=2.0)
    before = None
    for k in range(100_000):
        before = (sim.x.copy(), sim.steps, sim.rhs_evals)
        try:
            sim.step()
        except lv.DivergenceError as exc:
            assert exc.step == k == before[1]
            assert "grew" in exc.cause or "validity bound" in exc.cause
            break
    else:
        pytest.fail("euler never diverged")
    assert np.array_equal(sim.x, before[0]) and (sim.steps, sim.rhs_evals) == before[1:]
    with pytest.raises(lv.DivergenceError):        # and again: nothing was half-applied
        sim.step()
    assert np.array_equal(sim.x, before[0])


def test_set_state_moves_the_growth_reference_and_its_no_work_region():
    """After set_state lowers a free body's energy, growth is measured from the new energy: the same
    step fails as in a Sim built at that state (the no-work region |omega| <= w_safe follows E0)."""
    def run(sim):
        with pytest.raises(lv.DivergenceError) as e:
            sim.run(20_000)
        return e.value.step, e.value.cause.split(" (")[0]

    for backend in BACKENDS:
        a = lv.Sim(tumbling(omega_b=(0.2, 0.3, 9.0)), dt=1e-2, integrator="euler", backend=backend, max_growth=1.5)
        a.set_state("b", omega_b=(0.1, 0.2, 3.0))
        b = lv.Sim(tumbling(omega_b=(0.1, 0.2, 3.0)), dt=1e-2, integrator="euler", backend=backend, max_growth=1.5)
        assert run(a) == run(b)


def test_two_threads_stepping_one_sim_never_lose_a_step():
    import threading

    n = 20_000
    ref = lv.Sim(tumbling(), dt=1e-3, backend="c")
    ref.run(3 * n)
    sim = lv.Sim(tumbling(), dt=1e-3, backend="c")
    why = {}

    def stepper(k):
        try:
            for _ in range(n):
                sim.step()
            why[k] = "done"
        except BaseException as exc:  # recorded, asserted below
            why[k] = repr(exc)

    def runner():
        try:
            for _ in range(n // 100):
                sim.run(100)
            why["run"] = "done"
        except BaseException as exc:
            why["run"] = repr(exc)
    threads = [threading.Thread(target=stepper, args=(k,)) for k in range(2)] + [threading.Thread(target=runner)]
    for t in threads:
        t.start()
    for t in threads:
        t.join(timeout=300)
    assert why == {0: "done", 1: "done", "run": "done"}
    assert sim.steps == 3 * n
    assert np.array_equal(sim.x, ref.x)


# ------------------------------------------------------------------ zero-copy views, O(1) lookup (issue 12)

@pytest.mark.parametrize("backend", BACKENDS)
def test_state_views_are_zero_copy_read_only_and_current(backend):
    s = lv.Scene()
    for k in range(3):
        s.add_body(lv.Body(f"b{k}", 1.0 + k, (1.0, 2.0, 3.0), p_w=(k, 0, 0), omega_b=(0.1 * k, 0.2, 0.3)))
    sim = lv.Sim(s, dt=1e-3, backend=backend)
    views = {"x": sim.x, "p_w": sim.p_w, "q": sim.q, "v_w": sim.v_w, "omega_b": sim.omega_b, "Omega": sim.Omega}
    assert [v.shape for v in views.values()] == [(3, 13), (3, 3), (3, 4), (3, 3), (3, 3), (3, LY.WHEELS_MAX)]
    for name, v in views.items():
        assert not v.flags.writeable, name
        with pytest.raises(ValueError):
            v[0, 0] = 1.0
        with pytest.raises(ValueError):          # and the flag cannot be turned back on (set_state is the writer)
            v.flags.writeable = True
    for _ in range(10):
        sim.step()
    sim.run(10)
    for k, name in enumerate(sim.names):                       # the same memory, advanced in place
        st = sim.state(name)
        assert np.array_equal(views["x"][k], st.x) and np.array_equal(views["q"][k], st.q)
        assert np.array_equal(views["omega_b"][k], st.omega_b) and np.array_equal(views["p_w"][k], st.p_w)
        assert np.array_equal(views["v_w"][k], st.v_w)
    sim.set_state("b1", omega_b=(0.0, 0.0, 1.0))                # set_state is the writer; the views see it
    assert np.array_equal(views["omega_b"][1], [0.0, 0.0, 1.0])
    with pytest.raises(lv.LavenderInputError, match="unknown body 'nope'"):
        sim.state("nope")
    with pytest.raises(lv.LavenderInputError, match="unknown body"):
        sim.state(["unhashable"])


# ------------------------------------------------------------------ batched add_bodies (issue 12)

def _batch(n=6, seed=0):
    rng = np.random.default_rng(seed)
    return dict(names=[f"b{i}" for i in range(n)], masses=rng.uniform(0.5, 2.0, n), I_b=rng.uniform(1.0, 1.5, (n, 3)),
                p_w=rng.normal(size=(n, 3)), q=rng.normal(size=(n, 4)), v_w=rng.normal(size=(n, 3)),
                omega_w=rng.normal(size=(n, 3)))


@pytest.mark.parametrize("backend", BACKENDS)
def test_add_bodies_equals_add_body_one_by_one(backend):
    kw = _batch()
    one = lv.Scene()
    for i, name in enumerate(kw["names"]):
        one.add_body(lv.Body(name, kw["masses"][i], kw["I_b"][i], p_w=kw["p_w"][i], q=kw["q"][i], v_w=kw["v_w"][i],
                             omega_w=kw["omega_w"][i]))
    many = lv.Scene()
    out = many.add_bodies(**kw)
    assert [b.name for b in out] == kw["names"] == list(many.bodies)
    for a, b in zip(one.bodies.values(), many.bodies.values()):
        assert a.mass == b.mass and np.array_equal(a.I_b, b.I_b)
        np.testing.assert_allclose(b.x0, a.x0, rtol=0, atol=1e-15)       # q normalized, omega_w rotated alike
        assert not b.x0.flags.writeable and not b.I_b.flags.writeable
    sa, sb = lv.Sim(one, backend=backend), lv.Sim(many, backend=backend)
    sa.run(50)
    sb.run(50)
    np.testing.assert_allclose(sb.x, sa.x, rtol=0, atol=1e-12)
    defaults = lv.Scene()
    defaults.add_bodies(["u", "v"], [1.0, 2.0], [[1.0, 1.0, 1.0], [1.0, 2.0, 2.5]])
    assert np.array_equal(defaults.bodies["v"].x0, lv.Body("v", 2.0, (1.0, 2.0, 2.5)).x0)


@pytest.mark.parametrize("field, value, match", [
    ("masses", lambda m: np.r_[m[:3], -1.0, m[4:]], r"masses\[3\]: must be finite and > 0"),
    ("masses", lambda m: np.r_[m[:2], np.nan, m[3:]], r"masses: must be finite.*index 2"),
    ("I_b", lambda I: np.r_[I[:4], [[1.0, 1.0, 5.0]], I[5:]], r"I_b\[4\]: principal moments violate the triangle"),
    ("I_b", lambda I: np.r_[I[:1], [[1.0, 0.0, 1.0]], I[2:]], r"I_b\[1\]: principal moments must be > 0"),
    ("q", lambda q: np.r_[q[:5], [[0.0, 0.0, 0.0, 0.0]]], r"q\[5\]: zero quaternion"),
    ("p_w", lambda p: p[:5], r"p_w: expected shape \(6, 3\)"),
    ("names", lambda n: n[:2] + ["b0"] + n[3:], r"names\[2\]: duplicate name 'b0' \(also names\[0\]\)"),
    ("names", lambda n: n[:1] + [""] + n[2:], r"names\[1\]: must be a non-empty string"),
])
def test_add_bodies_names_the_bad_row_and_adds_nothing(field, value, match):
    kw = _batch()
    kw[field] = value(kw[field])
    s = lv.Scene()
    s.add_body(lv.Body("first", 1.0, (1.0, 1.0, 1.0)))
    with pytest.raises(lv.LavenderInputError, match=match):
        s.add_bodies(**kw)
    assert list(s.bodies) == ["first"]
    with pytest.raises(lv.LavenderInputError, match="names\\[0\\]: duplicate name 'first'"):
        s.add_bodies(["first"], [1.0], [[1.0, 1.0, 1.0]])
    with pytest.raises(lv.LavenderInputError, match="omega_w: give omega_b or omega_w, not both"):
        s.add_bodies(["x"], [1.0], [[1.0, 1.0, 1.0]], omega_b=[[0, 0, 1]], omega_w=[[0, 0, 1]])
    with pytest.raises(lv.LavenderInputError, match="omega_x"):
        s.add_bodies(["x"], [1.0], [[1.0, 1.0, 1.0]], omega_x=[[0, 0, 1]])
    assert list(s.bodies) == ["first"]


@pytest.mark.parametrize("integrator", ["rk4", "dopri5"])
def test_a_failing_later_chunk_is_located_by_replay_bitwise(integrator, monkeypatch):
    """_advance keeps one snapshot per call and reaches a failing chunk's start by replaying the chunks
    before it: the error names the same step as one long chunk does, and the Sim is restored exactly."""
    from lavendersim import sim as S

    def run(chunk_work):
        monkeypatch.setattr(S, "CHUNK_WORK", chunk_work)
        monkeypatch.setattr(S, "CHUNK_MIN_STEPS", 1)     # chunks of CHUNK_WORK alone (16: one step each)
        monkeypatch.setattr(S, "CHUNK_MIN_STEPS_C", 1)   # (C: its longer chunks too)
        sim = lv.Sim(tumbling(omega_b=(0.2, 0.3, 8.0)), dt=1e-2, integrator="euler" if integrator == "rk4" else integrator,
                     backend="c", max_growth=2.0, **({"rtol": 1e-3} if integrator == "dopri5" else {}))
        sim.run(3)
        x0, steps0 = sim.x.copy(), sim.steps
        try:
            sim.run(5000)
        except lv.DivergenceError as e:
            assert np.array_equal(sim.x, x0) and sim.steps == steps0
            return e.step, e.cause
        return None

    one, many = run(2**40), run(16)
    if integrator == "rk4":
        assert one is not None and one == many
    else:   # dopri5 at rtol 1e-3 may well stay bounded; when it fails, both name the same step
        assert one == many or one is None or many is None


def test_c_screen_serves_an_elongated_spinning_body_and_agrees_with_the_numpy_check():
    """A body with I_max/I_min > max_growth spinning off its minor axis is beyond the no-work rate w_safe from the start;
    the C screen then evaluates E and |L| (generated kernels) instead of sending every step to the Python path, and it
    passes exactly when the NumPy growth check finds nothing (states inside and beyond the limits)."""
    scene = lv.Scene()
    scene.add_body(lv.Body.box("b", 2.0, (0.8, 0.4, 0.2), omega_b=(1.0, 0.5, 0.2)))
    sim = lv.Sim(scene, dt=1e-3, integrator="rk4", backend="c")
    w = float(np.linalg.norm(sim.x[0, LY.STATE_OMEGA_B]))
    assert w > sim._g_fast[0, 0], "the body starts beyond its no-work rate (the case the screen must compute)"
    sim.run(1)                          # the Python path: checks the state and hands it to the fast path
    assert sim._fast.advance(1), "the C fast path served the step (screen passed on the exact invariants)"
    x = sim.x.copy()
    for scale, expect in ((1.0, True), (1.2, True), (1.6, False), (3.0, False)):   # E, |L| grow as scale^2, scale
        y = x.copy()
        y[0, LY.STATE_OMEGA_B] *= scale
        c = bool(sim._screen(y, sim.params, sim._wdt_scale, np.inf, sim._g_fast))
        E, L = sim._invariants(y, sim._models.Omega)
        numpy_ok = bool(E[0] <= sim.max_growth * sim._E0[0] and L[0] <= sim.max_growth * sim._L0[0])
        assert c == numpy_ok == expect, (scale, c, numpy_ok)
    y = x.copy()
    y[0, LY.STATE_OMEGA_B.start + 1] = np.nan
    assert not sim._screen(y, sim.params, sim._wdt_scale, np.inf, sim._g_fast)


def test_chunks_of_large_scenes_on_c_are_long_and_change_nothing(monkeypatch):
    """On the C and NumPy backends a fixed-step run of a large scene is chunked in at least CHUNK_MIN_STEPS steps
    (within CHUNK_WORK_MAX, NumPy CHUNK_WORK_MAX_NUMPY evaluations); dopri5 keeps CHUNK_WORK's chunks. The result
    is bitwise that of short chunks."""
    from lavendersim import sim as S

    assert S.chunk_steps(4, False) == S.chunk_steps(4, True) == S.CHUNK_WORK // 4
    assert S.chunk_steps(4 * 10**5, False) == S.CHUNK_WORK // (4 * 10**5) == 2
    assert S.chunk_steps(4 * 10**5, True) == S.CHUNK_MIN_STEPS == 64
    assert S.chunk_steps(4 * 10**6, True) == S.CHUNK_WORK_MAX // (4 * 10**6) == 8
    assert S.chunk_steps(10**9, True) == 1
    n = 20_000

    def sim(**kw):
        rng = np.random.default_rng(2)          # the same scene every time
        sc = lv.Scene()
        sc.add_bodies([f"b{i}" for i in range(n)], np.ones(n), 1 + rng.random((n, 3)),
                      omega_b=2.0 * rng.standard_normal((n, 3)))
        return lv.Sim(sc, dt=1e-3, **kw)

    long_c = sim(integrator="rk4", backend="c")
    assert long_c._chunk == S.CHUNK_MIN_STEPS_C == 256     # C: its longer chunks
    long_np = sim(integrator="rk4", backend="numpy")
    assert long_np._chunk == 64 and S.CHUNK_WORK_MAX_NUMPY // (4 * n) >= 64
    assert sim(integrator="dopri5", backend="c", rtol=1e-6)._chunk == S.CHUNK_WORK // (12 * n)
    monkeypatch.setattr(S, "CHUNK_MIN_STEPS", 1)
    monkeypatch.setattr(S, "CHUNK_MIN_STEPS_C", 1)
    short_c = sim(integrator="rk4", backend="c")
    assert short_c._chunk == S.CHUNK_WORK // (4 * n) == 13
    short_np = sim(integrator="rk4", backend="numpy")
    assert short_np._chunk == 13
    long_c.run(150)
    short_c.run(150)
    assert np.array_equal(long_c.x, short_c.x) and long_c.steps == short_c.steps == 150
    long_np.run(70)
    short_np.run(70)
    assert np.array_equal(long_np.x, short_np.x) and long_np.steps == short_np.steps == 70
