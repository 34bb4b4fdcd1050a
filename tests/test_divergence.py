"""Issue 11 (diverge): finite blow-ups, validity bounds, implicit_gyro's Newton, record/run_for restore,
Ctrl-C in C runs, one Sim from two threads, step-count bounds and set_state checks."""
import os
import signal
import subprocess
import sys
import threading
import time
import warnings

import numpy as np
import pytest

import lavendersim as lv
from lavendersim import sim as S
from lavendersim.errors import ValidityBoundWarning
from lavendersim.generated import tableaux as TB
from lavendersim.validate import LavenderInputError

from conftest import NUMPY_SLOW, interruptible  # noqa: F401  (NUMPY_SLOW: the suite's conftest import pattern)

BACKENDS = ["numpy", "c"]


def spinner(omega_b=(0.5, 0.5, 50.0), I_b=(1.0, 2.0, 3.0), **kw):
    s = lv.Scene()
    s.add_body(lv.Body("b", 1.0, I_b, omega_b=omega_b, **kw))
    return s


def frozen(sim):
    return (sim.x.copy(), sim.steps, sim.t, sim.rhs_evals)


def assert_unchanged(sim, before):
    x, steps, t, rhs = before
    assert np.array_equal(sim.x, x) and sim.steps == steps and sim.t == t and sim.rhs_evals == rhs


# ------------------------------------------------------------------ finite blow-ups become DivergenceError

@pytest.mark.parametrize("backend", BACKENDS)
@pytest.mark.parametrize("integrator", ["euler", "semi_implicit_euler"])
def test_finite_blow_up_is_caught_before_infinity(backend, integrator):
    # 50 rad/s at dt = 0.1 reached |omega| = 2.6e58 in 10 steps silently before issue 11
    sim = lv.Sim(spinner(), dt=0.1, integrator=integrator, backend=backend)
    before = frozen(sim)
    with pytest.raises(lv.DivergenceError) as e:
        sim.run(10)
    assert e.value.step == 0 and e.value.body == 0 and e.value.body_name == "b"
    assert "validity bound" in e.value.cause and integrator in e.value.cause
    assert_unchanged(sim, before)
    # opted in to run beyond the bound, the growth check still stops it, long before |omega| is huge
    sim = lv.Sim(spinner(), dt=0.1, integrator=integrator, backend=backend, on_bound="warn")
    before = frozen(sim)
    with pytest.warns(ValidityBoundWarning), pytest.raises(lv.DivergenceError) as e:
        sim.run(10)
    assert "kinetic energy grew" in e.value.cause and "max_growth = 2" in e.value.cause
    assert 0 < e.value.step < 10
    assert_unchanged(sim, before)


@pytest.mark.parametrize("backend", BACKENDS)
def test_growth_step_is_the_first_failing_one_across_chunks(backend, monkeypatch):
    """The located step does not depend on how the run is chunked: the same as stepping one by one."""
    def failing_step(chunk):
        monkeypatch.setattr(S, "CHUNK_WORK", chunk)
        monkeypatch.setattr(S, "CHUNK_MIN_STEPS", 1)     # C too: chunks of CHUNK_WORK alone
        monkeypatch.setattr(S, "CHUNK_MIN_STEPS_C", 1)   # (C: its longer chunks too)
        sim = lv.Sim(spinner(omega_b=(0.3, 0.3, 2.0)), dt=0.04, integrator="euler", backend=backend,
                     on_bound="warn", max_growth=1.5)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", ValidityBoundWarning)
            with pytest.raises(lv.DivergenceError) as e:
                sim.run(5000)
        assert "kinetic energy grew" in e.value.cause
        return e.value.step
    by_step = failing_step(1)             # a check after every step
    assert by_step > 20
    assert failing_step(2**18) == by_step == failing_step(37)


@pytest.mark.parametrize("backend", BACKENDS)
def test_splitting_major_axis_beyond_its_bound_raises(backend):
    # |omega| = 1e4, dt = 1e-3: before issue 11 the spin ended about the minor axis with energy x2.9, silently
    sim = lv.Sim(spinner(omega_b=(1.0, 1.0, 1e4)), dt=1e-3, integrator="splitting", backend=backend)
    with pytest.raises(lv.DivergenceError, match=r"I_max/I_min.*splitting's validity bound"):
        sim.run(100)
    assert sim.steps == 0


@pytest.mark.parametrize("integrator", ["euler", "semi_implicit_euler"])
def test_saturated_wheels_blow_up_is_caught(integrator):
    # c_w = 0: euler let |Omega| reach 7.2e17 rad/s silently
    s = lv.Scene()
    s.add_body(lv.Body("sat", 1.0, (0.1, 0.12, 0.15), omega_b=(0.5, -0.3, 0.8)))
    s.add_effect("reaction_wheels", body="sat", J=(1e-3, 1e-3, 1e-3), torque_limit=0.05, speed_limit=50.0, c_w=0.0,
                 cutoff=1.0)  # the hard cut-off (issue 13: the default is the torque–speed line)
    sim = lv.Sim(s, dt=0.05, integrator=integrator, backend="c", on_bound="warn")
    sim.set_wheel_command("sat", (0.05, -0.05, 0.05))
    before = sim.x.copy(), sim.wheel_rates("sat")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", ValidityBoundWarning)
        with pytest.raises(lv.DivergenceError) as e:
            sim.run(20000)
    assert "|L| grew" in e.value.cause     # total momentum of a body no external effect acts on
    assert e.value.step < 3600              # |omega|*dt 0.55 there; non-finite only at step 3649
    assert np.array_equal(sim.x, before[0]) and np.array_equal(sim.wheel_rates("sat"), before[1])


def test_every_integrator_but_the_adaptive_declares_a_bound():
    from lavendersim.backends import ADAPTIVE, INTEGRATORS
    for name in INTEGRATORS:
        if name in ADAPTIVE:
            assert S.validity_bound(name) is None
        else:
            assert name in TB.WDT_MAX, f"{name} declares no validity bound in derive/tableaux.py"
    assert TB.WDT_MAX["rk4"] == pytest.approx(2 * np.sqrt(2), rel=1e-15)


@pytest.mark.parametrize("backend", BACKENDS)
def test_on_bound_warn_lets_the_user_run_beyond(backend):
    sim = lv.Sim(spinner(omega_b=(0.0, 0.0, 40.0)), dt=0.1, integrator="rk4", backend=backend, on_bound="warn")
    with pytest.warns(ValidityBoundWarning, match=r"rk4's validity bound 2\.828"):
        try:
            sim.run(3)
        except lv.DivergenceError as e:   # rk4 at |omega|dt = 4 may still blow up: then by growth, not bound
            assert "validity bound" not in e.cause
    with pytest.raises(LavenderInputError, match="on_bound"):
        lv.Sim(spinner(), on_bound="ignore")
    with pytest.raises(LavenderInputError, match="max_growth"):
        lv.Sim(spinner(), max_growth=1.0)


def test_fast_path_results_are_unchanged_by_the_checks():
    """Torque-free RK4 on C: chunked with checks == one uninterrupted backend call, bit for bit."""
    from lavendersim.backends.c_backend import CBackend
    sim = lv.Sim(spinner(omega_b=(1.0, 0.5, 0.2)), dt=1e-3, integrator="rk4", backend="c")
    x = sim.x.copy()
    CBackend().advance(x, sim.params, sim.effects, "rk4", True, 1e-3, 300_000)
    sim.run(300_000)
    assert np.array_equal(sim.x, x)


# ------------------------------------------------------------------ implicit_gyro's Newton

@pytest.mark.parametrize("backend", BACKENDS)
def test_implicit_gyro_newton_non_convergence_raises(backend):
    # the atlas's cell: energy x4.4 from a non-root before issue 11
    sim = lv.Sim(spinner(I_b=(3.16e-6, 0.9999984, 1.0), omega_b=(1e-3, 0.999999, 1e-3)), dt=10 ** (1 / 3),
                 integrator="implicit_gyro", backend=backend, on_bound="warn", max_growth=None)
    E0 = sim.kinetic_energy()
    before = frozen(sim)
    with pytest.raises(lv.DivergenceError) as e:
        sim.run(200)
    assert "Newton did not converge" in e.value.cause and e.value.step == 10
    assert_unchanged(sim, before)
    sim.run(e.value.step)  # every step before it solved its equation: the energy never grew
    assert sim.kinetic_energy() <= E0 * (1 + 1e-12)


# ------------------------------------------------------------------ record / run_for restore

@pytest.mark.parametrize("backend", BACKENDS)
def test_record_restores_the_state_on_divergence(backend):
    s = lv.Scene()
    s.add_body(lv.Body("wild", 1.0, (1, 2, 3), omega_b=(0.3, 0.4, 0.1)))
    sim = lv.Sim(s, dt=0.1, integrator="euler", backend=backend, max_growth=1.1)
    sim.run(10)
    before = frozen(sim)
    with pytest.raises(lv.DivergenceError) as e:
        sim.record(1000, every=10)
    assert e.value.step > 50 and "kinetic energy grew" in e.value.cause
    assert_unchanged(sim, before)
    with pytest.raises(lv.DivergenceError):
        sim.run_for(50.0)
    assert_unchanged(sim, before)


# ------------------------------------------------------------------ step-count bounds, set_state checks

@pytest.mark.parametrize("backend", BACKENDS)
def test_huge_step_counts_are_rejected(backend):
    sim = lv.Sim(spinner(omega_b=(0.1, 0.2, 0.3)), backend=backend)
    for call in (lambda: sim.run(2**63), lambda: sim.record(2**63), lambda: sim.run(2**53 + 1)):
        with pytest.raises(LavenderInputError, match="n_steps.*2\\*\\*53"):
            call()
    with pytest.raises(LavenderInputError, match="duration"):
        sim.run_for(1e300)
    assert sim.steps == 0


@pytest.mark.parametrize("backend", BACKENDS)
def test_set_state_rejects_omega_beyond_the_bound_at_the_call(backend):
    sim = lv.Sim(spinner(omega_b=(0.1, 0.2, 0.3)), backend=backend)
    x = sim.x.copy()
    with pytest.raises(LavenderInputError, match="omega_b"):
        sim.set_state("b", omega_b=(1e200, 0, 0))
    with pytest.raises(LavenderInputError, match=r"omega_b.*validity bound"):
        sim.set_state("b", omega_b=(0, 0, 5000.0))   # |omega| dt = 5 > 2.83
    assert np.array_equal(sim.x, x)
    sim.set_state("b", omega_b=(0, 0, 2000.0))        # 2.0: fine
    warn = lv.Sim(spinner(omega_b=(0.1, 0.2, 0.3)), backend=backend, on_bound="warn")
    with pytest.warns(ValidityBoundWarning):
        warn.set_state("b", omega_b=(0, 0, 5000.0))
    with pytest.raises(LavenderInputError, match="omega_b"):
        warn.set_state("b", omega_b=(1e200, 0, 0))  # not representable: rejected whatever on_bound says


# ------------------------------------------------------------------ one Sim from two threads

def test_two_threads_on_one_sim_never_lose_a_step():
    n = 200_000
    one = lv.Sim(spinner(omega_b=(1.0, 0.5, 0.2)), dt=1e-3, backend="c")
    one.run(2 * n)
    sim = lv.Sim(spinner(omega_b=(1.0, 0.5, 0.2)), dt=1e-3, backend="c")
    why = {}

    def worker(k):
        try:
            sim.run(n)
            why[k] = "done"
        except BaseException as exc:  # recorded, asserted below
            why[k] = repr(exc)
    threads = [threading.Thread(target=worker, args=(k,)) for k in range(2)]
    for t in threads:
        t.start()
    for t in threads:
        t.join(timeout=300)
    assert why == {0: "done", 1: "done"}
    assert sim.steps == 2 * n
    assert np.array_equal(sim.x, one.x)


def test_two_sims_in_two_threads_run_in_parallel():
    """The C loop releases the GIL: while one thread is inside a long C run, another thread's Python
    code keeps running (a counter advances during the run). Behaviour, not timing."""
    a = lv.Sim(spinner(omega_b=(1.0, 0.5, 0.2)), dt=1e-3, backend="c")
    b = lv.Sim(spinner(omega_b=(1.0, 0.5, 0.2)), dt=1e-3, backend="c")
    ticks, stop, why = [0], threading.Event(), {}

    def ticker():
        while not stop.is_set():
            ticks[0] += 1
            b.step()          # the other Sim steps meanwhile: its lock is its own
            time.sleep(0)     # let the GIL go: else the run's Python between its C chunks waits for it a whole
            #                   switch interval (1 s) per chunk while this loop re-takes it (12 s instead of 0.2 s)
        why["ticker"] = "stopped"
    t = threading.Thread(target=ticker)
    t.start()
    deadline = time.monotonic() + 60
    while ticks[0] == 0 and time.monotonic() < deadline:
        time.sleep(0.01)
    start = ticks[0]
    sys.setswitchinterval(1.0)   # without GIL release the ticker would barely run during the C call
    try:
        a.run(3_000_000)
    finally:
        sys.setswitchinterval(0.005)
        stop.set()
        t.join(timeout=60)
    assert why == {"ticker": "stopped"}
    assert ticks[0] - start > 10 and b.steps >= ticks[0] - 1


# ------------------------------------------------------------------ Ctrl-C in a long C run

CHILD = """
import sys, numpy as np, lavendersim as lv
s = lv.Scene()
s.add_body(lv.Body("b", 1.0, (1.0, 2.0, 3.0), omega_b=(1.0, 0.5, 0.2)))
sim = lv.Sim(s, dt=1e-3, integrator="rk4", backend="c")
x0 = sim.x.copy()
print("started", flush=True)
try:
    sim.run(2 * 10**9)
except KeyboardInterrupt:
    print("interrupted", sim.steps, bool(np.array_equal(sim.x, x0)), flush=True)
    raise
"""


def test_ctrl_c_stops_a_long_c_run():
    env = dict(os.environ, PYTHONSAFEPATH="1")
    p = subprocess.Popen([sys.executable, "-c", CHILD], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                         env=env, cwd="/", preexec_fn=interruptible)
    try:
        line = ""
        deadline = time.monotonic() + 120
        while "started" not in line and time.monotonic() < deadline:
            line = p.stdout.readline()
            if not line and p.poll() is not None:
                break
        assert "started" in line, p.stderr.read()
        time.sleep(0.5)
        p.send_signal(signal.SIGINT)
        out, err = p.communicate(timeout=300)  # generous: a shared box at load 12 ran past 60 s
    finally:
        if p.poll() is None:
            p.kill()
            p.wait()
    assert p.returncode != -signal.SIGKILL
    assert "KeyboardInterrupt" in err
    assert "interrupted 0 True" in out      # consistent: the Sim is as before the call


@pytest.mark.parametrize("backend", BACKENDS)
def test_splitting_extreme_inertia_ratio_is_refused(backend):
    # I = (1e-9, 1, 1): splitting was 0.38 rad off after 10 s (rk4: 3e-10), silently; the bound's
    # (I_max/I_min)**(1/2) factor refuses it, rk4 runs it
    with pytest.raises(lv.DivergenceError, match=r"I_max/I_min\)\*\*0\.5 = 162 is beyond splitting's validity bound"):
        lv.Sim(spinner(I_b=(1e-9, 1.0, 1.0), omega_b=(5.0, 1.0, 0.5)), integrator="splitting", backend=backend).run(10)
    lv.Sim(spinner(I_b=(1e-9, 1.0, 1.0), omega_b=(5.0, 1.0, 0.5)), integrator="rk4", backend=backend).run(10)


def test_divergence_cause_measures_the_bound_as_the_sim():
    """backends.divergence_cause names a failure's cause with the Sim's validity measure (the printed
    validity_wdt, |omega| dt (I_max/I_min)**p): a 1:100 body at |omega| dt = 0.5 under splitting is 5 times beyond
    its bound (it used to compare the bare 0.5 with 1 and guess "grew without bound"); rk4 has no ratio term."""
    from lavendersim import backends as B

    I_b, omega_b, dt = (1.0, 100.0, 100.0), (10.0, 0.0, 0.0), 0.05
    x = np.zeros(13)
    x[6], x[10:13] = 1.0, omega_b
    why = B.divergence_cause(x, dt, "splitting", I_b)
    assert why.startswith("|omega|*dt*(I_max/I_min)**0.5 = 5 is beyond splitting's validity bound 1"), why
    with pytest.raises(lv.DivergenceError, match=r"\(I_max/I_min\)\*\*0\.5 = 5 is beyond splitting's validity"):
        lv.Sim(spinner(I_b=I_b, omega_b=omega_b), integrator="splitting", dt=dt).run(1)
    assert B.divergence_cause(x, dt, "rk4", I_b).startswith("state grew without bound (|omega| = 10 rad/s")


def test_wheels_spinning_in_the_null_space_are_not_a_divergence():
    """Four pyramid wheels at 50 rad/s in the layout's null space on a body at rest: the total |L| is rounding
    (~1e-17), so a commanded slew must not be called a divergence by the growth check (its reference |L| is
    floored at L_FLOOR times the parts' momentum); with the floor at 0 the same run is refused at step 9."""
    import lavendersim.sim as S
    from lavendersim import wheel_layout as WL

    def run():
        A = WL.pyramid_axes()
        sc = lv.Scene()
        sc.add_body(lv.Body.box("c", 1.0, (0.15, 0.15, 0.15)))
        sc.add_effect("reaction_wheels", body="c", axes_b=A.T, J=[5.7e-4] * 4, torque_limit=0.2, speed_limit=400.0)
        sim = lv.Sim(sc, dt=1e-3)
        n = np.ravel(WL.null_space(A))
        sim.set_state("c", Omega=50 * n / np.max(np.abs(n)))
        sim.set_wheel_command("c", [0.01, -0.02, 0.005, 0.0])
        sim.run(3000)
        return sim

    sim = run()
    Lb, Lw = sim.wheel_momentum_w("c")
    assert np.linalg.norm(sim.state("c").omega_b) > 1.0             # it did slew
    assert np.linalg.norm(Lb + Lw) <= 1e-12 * np.linalg.norm(Lb)     # and kept the total
    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(S, "L_FLOOR", 0.0)
        with pytest.raises(lv.DivergenceError, match=r"\|L\| grew"):
            run()
