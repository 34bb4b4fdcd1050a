"""Faults, round two (issue 28), the Sim's families: no lost update under its lock, fixed settings and
read-only arrays (nothing reaches the stepper unvalidated), errors and Sims that cross process boundaries,
and forks that never hang."""
from __future__ import annotations

import copy
import multiprocessing
import os
import pickle
import threading
import time

import numpy as np
import pytest

import lavendersim as lv
from lavendersim.errors import DivergenceError
from lavendersim.generated import layout as LY
from lavendersim.sim import ImmutableSimError

BACKENDS = ["numpy", "c"]
I_SAT = np.array([[0.2, 0.004, -0.002], [0.004, 0.25, 0.003], [-0.002, 0.003, 0.08]])


def _scene(wheels: bool = True):
    sc = lv.Scene()
    sc.add_body(lv.Body("sat", 12.0, I_SAT, omega_b=[0.3, -0.2, 0.5]))
    sc.add_body(lv.Body.box("cube", 1.0, (0.2, 0.2, 0.2), omega_b=[0.1, 0.2, -0.3]))
    if wheels:
        sc.add_effect("reaction_wheels", body="cube", J=[1e-4] * 3, torque_limit=0.1, speed_limit=100.0)
    sc.add_effect("applied_torque", body="sat", torque_w=[0.0, 0.0, 1e-3])
    return sc


# ---- settings and arrays --------------------------------------------------------------------------

@pytest.mark.parametrize("field, value", [("dt", 0.01), ("integrator", "euler"), ("normalize", False),
                                          ("backend", "numpy"), ("names", ["a"]), ("params", np.zeros((2, 4))),
                                          ("dtype", "float32"), ("max_growth", None)])
def test_settings_are_fixed_once_built(field, value):
    sim = lv.Sim(_scene(), dt=1e-3)
    before = getattr(sim, field)
    with pytest.raises(ImmutableSimError) as ei:
        setattr(sim, field, value)
    assert ei.value.field == f"sim.{field}" and isinstance(ei.value, AttributeError)
    after = getattr(sim, field)
    assert after is before or np.array_equal(after, before)


@pytest.mark.parametrize("backend", BACKENDS)
def test_the_stepped_arrays_are_read_only(backend):
    sim = lv.Sim(_scene(), dt=1e-3, backend=backend)
    for arr in (sim.params, sim.effects, sim.x, sim.q, sim.Omega):
        with pytest.raises(ValueError, match="read-only"):
            arr[0] = 1.0
    sim.run(10)
    ref = lv.Sim(_scene(), dt=1e-3, backend=backend)
    ref.run(10)
    np.testing.assert_array_equal(sim.x, ref.x)


@pytest.mark.parametrize("value, field", [(2**63 - 1, "steps"), (-1, "steps"), (1.5, "steps"), (2**63, "rhs_evals")])
def test_counters_take_only_valid_values(value, field):
    sim = lv.Sim(_scene(), dt=1e-3)
    sim.run(5)
    with pytest.raises(lv.LavenderInputError) as ei:
        setattr(sim, field, value)
    assert ei.value.field == field
    assert sim.steps == 5 and sim.t == pytest.approx(5e-3)


# ---- the lock ------------------------------------------------------------------------------------

@pytest.mark.parametrize("backend", BACKENDS)
def test_set_state_from_another_thread_is_never_a_lost_update(backend):
    """A set_state racing a run() ends as one of the two serial orders, to the bit: the run's rows are never
    half overwritten by a stale copy read before the run."""
    n = 20_000 if backend == "c" else 300
    q_new = np.array([0.0, 0.0, np.sin(0.3), np.cos(0.3)])

    def serial(first_set: bool):
        sim = lv.Sim(_scene(False), dt=1e-4, backend=backend)
        if first_set:
            sim.set_state("sat", q=q_new)
        sim.run(n)
        if not first_set:
            sim.set_state("sat", q=q_new)
        return sim.x.copy()

    refs = [serial(False), serial(True)]
    for delay in (0.0, 0.002, 0.01):
        sim = lv.Sim(_scene(False), dt=1e-4, backend=backend)
        errors = []

        def runner():
            try:
                sim.run(n)
            except BaseException as exc:   # recorded: the test fails naming it
                errors.append(exc)

        t = threading.Thread(target=runner)
        t.start()
        time.sleep(delay)
        sim.set_state("sat", q=q_new)   # the tumbling body: a stale row differs in omega_b too
        t.join(timeout=120)
        assert not t.is_alive() and not errors, errors
        assert any(np.array_equal(sim.x, r) for r in refs), f"delay {delay}: neither serial order"


# ---- processes -----------------------------------------------------------------------------------

def test_every_error_pickles_with_its_fields():
    e = DivergenceError(12, 1, "|L| grew x3", "cube", 0.5)
    f = pickle.loads(pickle.dumps(e))
    assert (f.step, f.body, f.cause, f.body_name, f.t, str(f)) == (12, 1, "|L| grew x3", "cube", 0.5, str(e))
    g = pickle.loads(pickle.dumps(ImmutableSimError("sim.dt", "is fixed")))
    assert (g.field, g.rule) == ("sim.dt", "is fixed") and isinstance(g, AttributeError)


@pytest.mark.parametrize("integrator", ["rk4", "dopri5", "implicit_gyro"])
@pytest.mark.parametrize("backend", BACKENDS)
def test_a_sim_pickles_and_deep_copies_bit_for_bit(integrator, backend):
    wheels = integrator != "implicit_gyro"   # implicit_gyro steps plain bodies only
    sim = lv.Sim(_scene(wheels), dt=1e-3, integrator=integrator, backend=backend)
    if wheels:
        sim.set_wheel_command("cube", [0.01, -0.02, 0.0])
    sim.run(60)
    for clone in (pickle.loads(pickle.dumps(sim)), copy.deepcopy(sim)):
        assert clone is not sim and clone.steps == sim.steps and clone.rhs_evals == sim.rhs_evals
        np.testing.assert_array_equal(clone.record(40, every=10).x, copy.deepcopy(sim).record(40, every=10).x)
    if wheels:
        np.testing.assert_array_equal(pickle.loads(pickle.dumps(sim)).wheel_command("cube"), sim.wheel_command("cube"))


def _diverge(k: int) -> float:
    """A pool task: task 1 diverges (|omega|*dt far beyond euler's validity bound)."""
    sc = lv.Scene()
    sc.add_body(lv.Body("b", 1.0, (1.0, 2.0, 3.0), omega_b=[0.1, 0.2, 300.0 if k == 1 else 0.3]))
    sim = lv.Sim(sc, dt=0.01, integrator="euler")
    sim.run(10)
    return float(sim.t)


def test_a_pool_whose_task_diverges_reports_the_divergence():
    ctx = multiprocessing.get_context("spawn")
    with ctx.Pool(2) as pool:
        res = pool.map_async(_diverge, [0, 1, 2])
        with pytest.raises(DivergenceError) as ei:
            res.get(timeout=120)
    assert ei.value.body_name == "b" and ei.value.step == 0


# ---- fork ----------------------------------------------------------------------------------------

@pytest.mark.skipif(not hasattr(os, "fork"), reason="no os.fork on this platform")
def test_a_fork_while_another_thread_holds_the_lock_does_not_hang():
    sim = lv.Sim(_scene(False), dt=1e-3, backend="numpy")
    held, release = threading.Event(), threading.Event()
    errors = []

    def holder():
        try:
            with sim._lock:          # what a long run does: hold the Sim's lock
                held.set()
                release.wait(60)
        except BaseException as exc:   # recorded: the test fails naming it
            errors.append(exc)

    t = threading.Thread(target=holder)
    t.start()
    assert held.wait(60)
    pid = os.fork()
    if pid == 0:                     # the child: the holder thread does not exist here
        try:
            sim.run(5)
            os._exit(0 if sim.steps == 5 else 3)
        except BaseException:
            os._exit(4)
    release.set()
    t.join(60)
    deadline = time.monotonic() + 120
    while True:
        done, status = os.waitpid(pid, os.WNOHANG)
        if done:
            break
        if time.monotonic() > deadline:
            os.kill(pid, 9)
            os.waitpid(pid, 0)
            pytest.fail("the forked child hung on the Sim's lock")
        time.sleep(0.05)
    assert os.WIFEXITED(status) and os.WEXITSTATUS(status) == 0, status
    assert not errors, errors


def test_an_omega_w_whose_body_frame_value_overflows_is_refused_by_body():
    with pytest.raises(lv.LavenderInputError) as ei:
        lv.Body("b", 1.0, (1.0, 2.0, 3.0), q=[0.7, 0.2, 0.1, 0.9], omega_w=[1.7e308, -1.7e308, 1.7e308])
    assert ei.value.field == "omega_w"


@pytest.mark.parametrize("edit, message", [("code", r"effects\[0\] code 999\.0 is not a declared effect"),
                                           ("body", r"effects\[0\] body must be -1 \(every body\) or an index in \[0, 2\)"),
                                           ("kind", r"model_rows\[1\] kind must be 0 \(plain\)")])
def test_a_table_changed_behind_the_c_fast_paths_back_goes_to_the_python_path(edit, message):
    """The C fast path (Stepper) does not re-check the effect table and model kinds itself: lv_simulate refuses a
    bad effect code, effect body or model kind before it writes anything, the step falls back to the Python path,
    and that names the row and the rule; nothing is stepped. A valid edit (set_effect_params) keeps the fast path;
    an invalid one is refused there by name and changes nothing."""
    sim = lv.Sim(_scene(), dt=1e-3, backend="c")
    assert sim._fast is not None and sim._fast_n >= 1
    push = next(e for e in sim._forces if e.name == "applied_torque")
    with pytest.raises(lv.LavenderInputError, match="torque_w"):
        sim.set_effect_params(push, torque_w=[0.0, np.nan, 0.0])
    sim.set_effect_params(push, torque_w=[0.0, 0.0, 2e-3])
    sim.run(1)
    sim.step()
    assert sim._fast.is_checked() and sim._fast.steps == 2   # both calls inside C
    x0, steps = sim.x.copy(), sim.steps
    arr, at, bad = {"code": (sim._effects, (0, 0), 999.0), "body": (sim._effects, (0, 1), 7.0),
                    "kind": (sim._models.rows, (1, LY.MODEL_KIND), 5.0)}[edit]   # effects row 0: the torque on "sat"
    arr[at] = bad
    for call in (sim.step, lambda: sim.run(1), lambda: sim.run(50)):
        with pytest.raises(ValueError, match=message):
            call()
        np.testing.assert_array_equal(sim.x, x0)
        assert sim.steps == steps


def _steps_inside_c_as_a_fresh_advance(sim, integrator):
    """sim.step() then sim.run(4), all inside C (the Stepper, 4 steps before), step its state, wheel rates and applied
    torques bitwise as CBackend.advance does 5 steps from copies (a call that decides everything afresh). Returns that
    call's state and models."""
    from lavendersim.backends import Models, c_backend
    m = sim._models
    ref = Models(m.rows.copy(), m.Omega.copy(), m.command.copy(), m.applied.copy())
    x = sim._x.copy()                                            # (the stepped rows: principal frames)
    c_backend.CBackend().advance(x, sim._params.copy(), sim._effects.copy(), integrator, sim.normalize, sim.dt, 5, ref)
    sim.step()
    sim.run(4)
    assert sim._fast.steps == 9                                   # all of them inside C
    np.testing.assert_array_equal(sim._x, x)
    np.testing.assert_array_equal(m.Omega, ref.Omega)
    np.testing.assert_array_equal(m.applied, ref.applied)
    return x, ref


@pytest.mark.parametrize("n_joint", [1, 20])   # 20: the jointed wheel bodies step on a model tile (csrc/model_simd.h)
def test_the_c_fast_path_steps_a_rewritten_model_row_as_a_fresh_call_does(n_joint):
    """The Stepper keeps its model rows' per-body decisions (the step kind, the wheel coefficients: csrc/step.h
    lv_model_cache) from call to call instead of making them per call. A row rewritten between calls
    (reinit_body moves a jointed body's pivot offset r_b, so its I_p and wheel coefficients change) is stepped inside C
    exactly as the backend's advance steps it, which decides everything afresh: bitwise."""
    sc = lv.Scene()
    for i in range(n_joint):
        sc.add_body(lv.Body.box(f"c{i}", 1.0, (0.15, 0.15, 0.15), p_w=(0.075, 0.0, 0.0), omega_b=(0.3, -0.2, 0.01 * i)))
        sc.add_effect("spherical_joint", body=f"c{i}", anchor_w=[0.0, 0.0, 0.0])
        sc.add_effect("reaction_wheels", body=f"c{i}", J=[2e-4, 3e-4, 2.5e-4], torque_limit=0.2, speed_limit=400.0)
    sc.add_body(lv.Body("w", 12.0, I_SAT, omega_b=[0.3, -0.2, 0.5]))   # wheels off the body axes: the general print
    sc.add_effect("reaction_wheels", body="w", J=[1e-4] * 3, axes_b=[[0.0, 0.6, 0.8], [1.0, 0.0, 0.0], [0.0, 0.8, -0.6]],
                  torque_limit=0.1, speed_limit=100.0)
    sc.add_effect("gravity")
    sim = lv.Sim(sc, dt=1e-3, integrator="rk4", backend="c")
    sim.set_wheel_command("c0", [0.01, -0.02, 0.005])
    sim.set_wheel_command("w", [0.003, 0.0, -0.002])
    sim.run(3)
    sim.step()
    assert sim._fast is not None and sim._fast.steps == 4        # inside C: the decisions kept since the first call
    rows = sim.model.rows.copy()
    sim.reinit_body(0, np.array([0.0, 0.06, 0.05]), np.array([0.0, np.sin(0.2), 0.0, np.cos(0.2)]),
                    np.array([0.2, 0.1, -0.3]), np.array([5.0, -3.0, 1.0]))
    assert not np.array_equal(sim.model.rows[0, LY.MODEL_I_P], rows[0, LY.MODEL_I_P])   # a new row for body 0
    sim.set_wheel_command("c0", [-0.01, 0.0, 0.02])
    sim.check_written()
    _steps_inside_c_as_a_fresh_advance(sim, "rk4")


@pytest.mark.parametrize("integrator", ["rk4", "euler"])
def test_the_c_fast_path_keeps_its_effect_index_and_reads_new_parameters_through_it(integrator):
    """The Stepper keeps the effect index (each body's effects) of its last call while every row's code and body are
    unchanged (csrc/step.h lv_model_cache). set_effect_params rewrites a row's parameters in place: the next calls
    inside C step the new loads exactly as the backend's advance does with an index built afresh (bitwise), on wheeled
    bodies and a plain one, with a scene-wide effect beside the per-body ones."""
    from lavendersim.backends import Models, c_backend
    sc = lv.Scene()
    pushes = []
    for i in range(6):
        sc.add_body(lv.Body(f"b{i}", 1.0 + 0.1 * i, [0.1, 0.2, 0.3], omega_b=[0.3, -0.2, 0.1 * i]))
        if i:
            sc.add_effect("reaction_wheels", f"b{i}", J=[1e-4] * 3, torque_limit=0.1, speed_limit=100.0)
        pushes.append(sc.add_effect("applied_torque", f"b{i}", torque_w=[1e-3 * i, 0.0, -1e-3]))
    sc.add_effect("gravity")
    sim = lv.Sim(sc, dt=1e-3, integrator=integrator, backend="c")
    sim.set_wheel_command("b1", [0.01, -0.02, 0.005])
    sim.run(3)
    sim.step()
    assert sim._fast is not None and sim._fast.steps == 4          # inside C: the index kept since the first call
    table = sim._effects.copy()
    start = (sim._x.copy(), sim._models.Omega.copy(), sim._models.applied.copy())
    sim.set_effect_params(pushes[0], torque_w=[0.0, 2e-2, 0.0])     # a plain body's load
    sim.set_effect_params(pushes[3], torque_w=[-3e-2, 0.0, 1e-2])   # a wheeled body's
    x, ref = _steps_inside_c_as_a_fresh_advance(sim, integrator)
    stale = Models(ref.rows, start[1].copy(), ref.command, start[2].copy())   # the loads as they were: other states
    c_backend.CBackend().advance(start[0], sim._params.copy(), table, integrator, sim.normalize, sim.dt, 5, stale)
    assert not np.array_equal(start[0], x)


def test_run_takes_a_plain_int_straight_to_c_and_still_refuses_what_it_refused():
    """run(n) with a plain int in (0, the fast chunk] goes to the Stepper without V.integer (the value is valid as it
    is); every other argument is validated as before: NumPy integers step the same, bool, floats, negatives and
    n > MAX_STEPS are refused naming n_steps, with nothing stepped."""
    a, b = lv.Sim(_scene(), dt=1e-3, backend="c"), lv.Sim(_scene(), dt=1e-3, backend="c")
    assert a._fast is not None and a._fast_n >= 3
    a.run(3)
    b.run(np.int64(3))
    np.testing.assert_array_equal(a.x, b.x)
    assert a.steps == b.steps == 3 and a._fast.steps == 3
    for bad in (True, 1.0, -1, 2 ** 60, "1"):
        with pytest.raises(lv.LavenderInputError) as e:
            a.run(bad)
        assert e.value.field == "n_steps"
    a.run(0)
    assert a.steps == 3
    np.testing.assert_array_equal(a.x, b.x)
