"""Stiff effects have a declared bound and bodies with effects a growth check (issue 28).

derive recognises pure linear decays (derive/effect_decay.py) and prints their rate; derive/tableaux.py
prints each integrator's stability limit for a decay (REAL_AXIS_STABILITY). These tests check that the
printed limit is the real threshold on both backends, that a Sim refuses (or warns about) a decay beyond it
when built and on every change, and that a body with effects that blows up anyway is a DivergenceError.
"""
import pickle
import warnings

import numpy as np
import pytest
import sympy as sp

import lavendersim as lv
from conftest import NUMPY_SLOW
from lavendersim import backends
from lavendersim.errors import DivergenceError, ValidityBoundWarning
from lavendersim.generated import tableaux as TABLEAUX

from lavendersim.derive import effect_decay
from lavendersim.derive import effects as derive_effects
from lavendersim.derive.effect import STATE, effect, param

FIXED = [n for n in backends.INTEGRATORS if n not in backends.ADAPTIVE]
BACKENDS = ["c", "numpy"]


def _damped(c: float, kind: str = "linear_damping", v_w=(1.0, 0.0, 0.0), omega_b=(0.0, 0.0, 0.0)) -> lv.Scene:
    s = lv.Scene()
    s.add_body(lv.Body("b", 2.0, (0.5, 1.0, 1.5), v_w=v_w, omega_b=omega_b))
    if c is not None:
        s.add_effect(kind, body="b", c=c)
    return s


# ---- derive: which effects are decays --------------------------------------------------------------------
def test_derive_finds_the_built_in_decays_and_their_rates():
    rates = {d.name: effect_decay.decay_rate(d) for d in derive_effects.declarations()}
    assert str(rates["linear_damping"]) == "c/m"
    assert str(rates["angular_damping"]) == "Max(c/I_b_0, c/I_b_1, c/I_b_2)"
    for name in ("applied_torque", "force_at_point", "gravity", "spherical_joint", "reaction_wheels"):
        assert rates[name] is None, name


def test_derive_decides_user_effects_by_their_structure():
    c = param("c", unit="N·m·s/rad", doc="drag", rule="nonnegative")
    k = param("k", unit="N·s/m", doc="drag", rule="nonnegative")
    spin = effect("spin_drag", "x", params=[c], torque_w=-c.symbol * STATE.omega_w)
    assert effect_decay.decay_rate(spin) == sp.Max(*(c.symbol / I for I in STATE.I_b))
    # a body-frame anisotropic drag -D omega_b is a decay (rate max(d_i / I_i)) ...
    d = param("d", 3, "N·m·s/rad", "drag per body axis", "nonnegative")
    body_drag = effect("body_drag", "x", params=[d], torque_w=STATE.R_WB * sp.Matrix([-d.symbol[i] * STATE.omega_b[i] for i in range(3)]))
    assert effect_decay.decay_rate(body_drag) == sp.Max(*(d.symbol[i] / STATE.I_b[i] for i in range(3)))
    # ... a world-frame anisotropic one is not (its body-frame Jacobian turns with q), nor quadratic drag,
    # nor a drag with a constant part (it supplies momentum at rest), nor anti-damping
    world_drag = effect("world_drag", "x", params=[c], torque_w=-c.symbol * sp.diag(1, 2, 3) * STATE.omega_w)
    v = STATE.v_w
    quad = effect("quad", "x", params=[k], force_w=-k.symbol * sp.sqrt(v.dot(v)) * v)
    offset = effect("offset", "x", params=[k], force_w=-k.symbol * (v - sp.Matrix([1, 0, 0])))
    anti = effect("anti", "x", params=[k], force_w=k.symbol * v)
    for e in (world_drag, quad, offset, anti):
        assert effect_decay.decay_rate(e) is None, e.name


def test_every_integrator_has_a_decay_limit():
    assert set(TABLEAUX.REAL_AXIS_STABILITY) == set(backends.INTEGRATORS)
    assert TABLEAUX.REAL_AXIS_STABILITY["euler"] == 2.0
    assert TABLEAUX.REAL_AXIS_STABILITY["splitting"] == pytest.approx(4.0, abs=1e-12)


# ---- the printed limit is the real threshold, on both backends -------------------------------------------
@pytest.mark.parametrize("backend", NUMPY_SLOW)   # NumPy: up to 16 s per integrator when loaded; slow set
@pytest.mark.parametrize("integrator", FIXED)
def test_the_printed_limit_is_where_a_linear_decay_turns_unstable(integrator, backend):
    limit = TABLEAUX.REAL_AXIS_STABILITY[integrator]
    dt = 0.01
    speeds = {}
    for f in (0.97, 1.03):
        c = f * limit * 2.0 / dt               # rate c/m, m = 2
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", ValidityBoundWarning)
            sim = lv.Sim(_damped(c), dt=dt, integrator=integrator, backend=backend, on_bound="warn", max_growth=None)
        sim.run(300)
        speeds[f] = float(np.linalg.norm(sim.state("b").v_w))
    assert speeds[0.97] < 1.0, (integrator, speeds)
    assert speeds[1.03] > 1.0, (integrator, speeds)


# ---- the bound is checked when built and on every change ---------------------------------------------------
@pytest.mark.parametrize("kind,c", [("linear_damping", 3.0 * 2.0 / 0.1), ("angular_damping", 3.0 * 0.5 / 0.1)])
def test_a_decay_beyond_the_limit_is_refused_naming_the_effect(kind, c):
    with pytest.raises(lv.LavenderInputError) as e:
        lv.Sim(_damped(c, kind), dt=0.1, integrator="euler")
    assert e.value.field == kind and "stability limit 2" in str(e.value) and "rate*dt = 3" in str(e.value)
    with pytest.warns(ValidityBoundWarning, match="stability limit"):
        lv.Sim(_damped(c, kind), dt=0.1, integrator="euler", on_bound="warn")
    lv.Sim(_damped(c, kind), dt=0.1, integrator="dopri5")      # adaptive: it controls its own error


def test_decays_on_one_body_add_up():
    s = _damped(1.2 * 2.0 / 0.1)                                # 1.2 alone: inside euler's 2
    lv.Sim(s, dt=0.1, integrator="euler")
    s.add_effect("linear_damping", c=1.2 * 2.0 / 0.1)           # scene-wide: 2.4 on b
    with pytest.raises(lv.LavenderInputError, match="rate\\*dt = 2.4"):
        lv.Sim(s, dt=0.1, integrator="euler")


@pytest.mark.parametrize("backend", BACKENDS)
def test_set_effect_params_beyond_the_limit_changes_nothing(backend):
    s = _damped(1.0)
    sim = lv.Sim(s, dt=0.1, integrator="euler", backend=backend)
    twin = lv.Sim(_damped(1.0), dt=0.1, integrator="euler", backend=backend)
    drag = s.effects[0]
    with pytest.raises(lv.LavenderInputError, match="stability limit"):
        sim.set_effect_params(drag, c=100.0)
    assert np.array_equal(sim.effects, twin.effects)
    sim.run(50)
    twin.run(50)
    assert np.array_equal(sim.x, twin.x)
    s2 = _damped(1.0)
    warned = lv.Sim(s2, dt=0.1, integrator="euler", backend=backend, on_bound="warn")
    with pytest.warns(ValidityBoundWarning, match="set_effect_params"):
        warned.set_effect_params(s2.effects[0], c=100.0)


# ---- bodies with effects have a growth check: no finite blow-up is silent ----------------------------------
@pytest.mark.parametrize("backend", BACKENDS)
@pytest.mark.parametrize("integrator,f", [("euler", 3.0 / 2.0), ("rk4", 3.5 / 2.785293563405282)])
def test_a_stiff_linear_damping_let_through_is_a_divergence(integrator, f, backend):
    # the audit's cases: c*dt/m = 3 under euler, 3.5 under rk4; |v| reached 1e18 before any error
    dt = 0.01
    with pytest.warns(ValidityBoundWarning):
        sim = lv.Sim(_damped(f * TABLEAUX.REAL_AXIS_STABILITY[integrator] * 2.0 / dt), dt=dt, integrator=integrator,
                     backend=backend, on_bound="warn")
    before = sim.x.copy()
    with pytest.raises(DivergenceError) as e:
        sim.run(2000)
    assert e.value.step < 10 and "max_growth" in str(e.value)
    assert np.array_equal(sim.x, before) and sim.steps == 0


@pytest.mark.parametrize("backend", BACKENDS)
def test_a_stiff_angular_damping_let_through_is_a_divergence(backend):
    # the audit: c*dt/I = 3 grew omega 0.01 -> 41 rad/s before any bound fired
    dt = 0.01
    with pytest.warns(ValidityBoundWarning):
        sim = lv.Sim(_damped(3.0 * 0.5 / dt, "angular_damping", v_w=(0, 0, 0), omega_b=(0.01, 0.0, 0.0)), dt=dt,
                     integrator="euler", backend=backend, on_bound="warn")
    with pytest.raises(DivergenceError) as e:
        sim.run(2000)
    assert e.value.step < 10


def _loaded_scene() -> lv.Scene:
    s = lv.Scene()
    s.add_body(lv.Body("fall", 2.0, (0.5, 1.0, 1.5), omega_b=(0.3, 0.1, 0.0)))
    s.add_body(lv.Body("spin_up", 1.0, (0.2, 0.3, 0.4)))                      # from rest: |L(0)| = 0
    s.add_body(lv.Body("lever", 1.0, (0.2, 0.3, 0.4)))                        # force along r at the start: tau(0) = 0
    s.add_body(lv.Body("quiet", 1.0, (0.2, 0.3, 0.4), omega_b=(0.0, 0.5, 0.0)))
    s.add_effect("gravity", body="fall")
    s.add_effect("linear_damping", body="fall", c=0.5)
    s.add_effect("angular_damping", body="fall", c=0.05)
    s.add_effect("applied_torque", body="spin_up", torque_w=(0.0, 0.0, 0.2))
    s.add_effect("force_at_point", body="lever", r_b=(1.0, 0.0, 0.0), F_w=(1.0, 0.0, 0.0))
    s.add_effect("applied_torque", body="quiet", torque_w=(0.0, 0.0, 0.0))   # zero strength: |L| conserved
    s.add_effect("force_at_point", body="lever", r_b=(0.0, 0.1, 0.0), F_w=(0.0, 0.0, 1e-3))
    return s


@pytest.mark.parametrize("backend", NUMPY_SLOW)   # NumPy: 47 s on a loaded machine (C: <1 s); slow set
def test_real_loads_never_trip_the_growth_check(backend):
    sim = lv.Sim(_loaded_scene(), dt=1e-3, integrator="rk4", backend=backend)
    for _ in range(20):                       # many calls, the C fast path and the Python path both
        sim.run(500)
    for _ in range(300):
        sim.step()
    st = sim.state("spin_up")
    assert st.omega_w[2] * 0.4 == pytest.approx(0.2 * sim.t, rel=1e-9)   # L = tau t: the budget is exact here
    assert np.all(np.isfinite(sim.x))


def test_the_budget_survives_pickling_bit_for_bit():
    sim = lv.Sim(_loaded_scene(), dt=1e-3, integrator="rk4")
    sim.run(700)
    twin = pickle.loads(pickle.dumps(sim))
    sim.run(900)
    twin.run(900)
    assert np.array_equal(sim.x, twin.x)


# ---- wheeled bodies: their budget in the C screen (issue 29: no Python check per call) -----------------------
def _wheeled(n: int = 3, effect: str | None = "applied_torque", **params) -> lv.Scene:
    s = lv.Scene()
    for i in range(n):
        s.add_body(lv.Body.box(f"w{i}", 1.0, (0.1, 0.2, 0.3), v_w=(0.5, 0.0, 0.0), omega_b=(0.3, 0.2, 0.1)))
        s.add_effect("reaction_wheels", body=f"w{i}", J=[1e-4] * 3, torque_limit=0.1, speed_limit=100.0)
        if effect is not None:
            s.add_effect(effect, body=f"w{i}", **(params or {"torque_w": (0.0, 0.0, 1e-3)}))
    return s


@pytest.mark.parametrize("loaded", [True, False])
def test_calm_wheeled_bodies_pass_the_c_screen_and_never_reach_the_python_check(loaded):
    """The growth check of a wheeled body (loaded: its budget, |L| of body and wheels and m|v|; free: its total |L|)
    is held by the C screen like a plain body's, so run(1) and step() of a calm scene never evaluate it in Python
    (at HEAD before this, LoadBudget.violation ran after every call: 16x the call's cost at 100 bodies)."""
    sim = lv.Sim(_wheeled(effect="applied_torque" if loaded else None), dt=1e-3, integrator="rk4", backend="c")
    for i in range(3):
        sim.set_wheel_command(f"w{i}", (0.01, -0.02, 0.005))
    assert sim._fast is not None, "step() runs inside C for a wheeled scene under the growth check"
    assert (sim._budget is not None) == loaded
    calls = []
    if loaded:
        real = sim._budget.violation
        sim._budget.violation = lambda *a: calls.append(a) or real(*a)
    else:
        real_inv = sim._invariants
        sim._invariants = lambda *a, **k: calls.append(a) or real_inv(*a, **k)
    for _ in range(40):
        sim.run(1)
        sim.step()
    sim.run(500)
    assert calls == [] and sim.steps == 580
    assert (sim._g_fast[:, 0] == -np.inf).all() and (sim._g_fast[:, 2] < np.inf).all()   # evaluated, finite limits


def test_the_c_screen_reads_a_wheeled_bodys_total_momentum_and_translation():
    """The screen's |L| of a wheeled body is of body and wheels (the printed wheel momentum: wheels spinning on a body
    at rest carry all of it) and its energy is the translational one (m|v| <= Pmax, whatever the body's spin): it
    passes at a limit just above the value the Python check computes and refuses just below it."""
    from lavendersim.generated import layout as LY

    sim = lv.Sim(_wheeled(), dt=1e-3, integrator="rk4", backend="c")
    x, W, rows = sim._x.copy(), sim._models.Omega.copy(), sim._models.rows
    x[0, LY.STATE_OMEGA_B] = 0.0
    W[0] = (50.0, -20.0, 10.0, 0.0)
    L, P = sim._budget._momenta(x, W)
    assert L[0] > 0 and P[0] == 0.5
    screen = sim._screen
    G = np.full((3, 3), np.inf)
    G[0] = (-np.inf, np.inf, L[0] ** 2 * (1 + 1e-9))
    assert screen(x, sim.params, sim._wdt_scale, np.inf, G, rows, W)
    G[0, 2] = L[0] ** 2 * (1 - 1e-9)
    assert not screen(x, sim.params, sim._wdt_scale, np.inf, G, rows, W)
    x[0, LY.STATE_OMEGA_B] = (5.0, 0.0, 0.0)   # a spin: rotational energy does not count against Pmax
    G[0] = (-np.inf, P[0] ** 2 / 2 * (1 + 1e-9), np.inf)   # m = 1: Pmax^2 / 2m
    assert screen(x, sim.params, sim._wdt_scale, np.inf, G, rows, W)
    G[0, 1] = P[0] ** 2 / 2 * (1 - 1e-9)
    assert not screen(x, sim.params, sim._wdt_scale, np.inf, G, rows, W)
    G[0] = np.inf     # without the model rows the row would be screened as a plain body's
    assert screen(x, sim.params, sim._wdt_scale, np.inf, G)


@pytest.mark.parametrize("backend", BACKENDS)
@pytest.mark.parametrize("kind,what", [("linear_damping", "|p| = "), ("angular_damping", "|L| = ")])
def test_a_wheeled_body_beyond_its_budget_is_a_divergence(kind, what, backend):
    """A stiff decay let through (on_bound='warn') on wheeled bodies: euler amplifies v (or omega) x2 per step; the
    budget refuses it within a few steps, through the C screen as through NumPy, and the state is left as it was."""
    dt, c = 0.01, (3.0 if kind == "linear_damping" else 3.0 * (0.1 ** 2 + 0.2 ** 2) / 12) / 0.01   # rate*dt = 3
    with pytest.warns(ValidityBoundWarning):
        sim = lv.Sim(_wheeled(1, kind, c=c), dt=dt, integrator="euler", backend=backend, on_bound="warn")
    before = sim.x.copy()
    with pytest.raises(DivergenceError) as e:
        sim.run(2000)
    assert e.value.step < 12 and what in e.value.cause and "loads can supply" in e.value.cause
    assert np.array_equal(sim.x, before) and sim.steps == 0
    with pytest.raises(DivergenceError) as e2:     # step() (inside C where the screen passes) finds the same step
        for _ in range(20):
            sim.step()
    assert (e2.value.step, e2.value.cause) == (e.value.step, e.value.cause) and sim.steps == e.value.step


def test_a_user_declared_decay_gets_the_bound(tmp_path):
    """A user's spin drag (docs/extending.md's way) is recognised by derive and bounded like the built-ins."""
    import os
    import subprocess
    import sys

    from lavendersim import extending

    decl = tmp_path / "bounded_drag.py"
    decl.write_text(
        "from lavendersim.derive.effect import STATE, effect, param\n"
        "c = param('c', unit='N·m·s/rad', doc='drag', rule='nonnegative')\n"
        "EFFECTS = [effect('bounded_spin_drag', 'Viscous spin drag', params=[c], torque_w=-c.symbol * STATE.omega_w)]\n",
        encoding="utf-8")
    env = {**os.environ, extending.ENV: str(tmp_path / "user")}
    r = subprocess.run([sys.executable, "-m", "lavendersim", "derive", "--user", str(decl)], cwd=tmp_path, env=env,
                       capture_output=True, text=True)
    assert r.returncode == 0, r.stdout + r.stderr
    script = (
        "import lavendersim as lv\n"
        "from lavendersim import extending\n"
        f"extending.load({str(decl)!r})\n"
        "s = lv.Scene()\n"
        "s.add_body(lv.Body('b', 2.0, (0.5, 1.0, 1.5), omega_b=(0.1, 0, 0)))\n"
        "s.add_effect('bounded_spin_drag', body='b', c=0.5 * 1.9 / 0.1)\n"
        "lv.Sim(s, dt=0.1, integrator='euler')\n"
        "s.add_effect('bounded_spin_drag', body='b', c=0.5 * 0.2 / 0.1)\n"
        "try:\n"
        "    lv.Sim(s, dt=0.1, integrator='euler')\n"
        "except lv.LavenderInputError as e:\n"
        "    print('refused', e.field)\n")
    script += ("import pickle\n"
               "s2 = lv.Scene()\n"
               "s2.add_body(lv.Body('b', 2.0, (0.5, 1.0, 1.5), omega_b=(0.1, 0, 0)))\n"
               "s2.add_effect('bounded_spin_drag', body='b', c=0.01)\n"
               "sim = lv.Sim(s2, dt=0.1, integrator='rk4')\n"
               "sim.run(5)\n"
               "open('sim.pkl', 'wb').write(pickle.dumps(sim))\n"
               "sim.run(5)\n"
               "print(repr(sim.x.tobytes()))\n")
    r = subprocess.run([sys.executable, "-c", script], cwd=tmp_path, env=env, capture_output=True, text=True)
    assert r.returncode == 0, r.stderr
    refused, after = r.stdout.strip().splitlines()
    assert refused == "refused bounded_spin_drag"
    # a fresh process that never loaded the set unpickles the Sim (the effect's set is found and verified)
    fresh = ("import pickle\n"
             "sim = pickle.loads(open('sim.pkl', 'rb').read())\n"
             "sim.run(5)\n"
             "print(repr(sim.x.tobytes()))\n")
    r = subprocess.run([sys.executable, "-c", fresh], cwd=tmp_path, env=env, capture_output=True, text=True)
    assert r.returncode == 0, r.stderr
    assert r.stdout.strip() == after


def test_the_budget_keeps_the_rates_of_loads_that_read_no_state():
    """LoadBudget._rates evaluates the supplying loads once when none reads the state (gravity: m g), the same
    numbers as a fresh evaluation at any state; a load that reads the state (force_at_point rotates r_b by q) is
    evaluated at every call. violation's momenta from the columns it gathers once equal those read from the rows."""
    from lavendersim.generated import layout as LY

    s = lv.Scene()
    for i in range(5):
        s.add_body(lv.Body(f"b{i}", 1.0 + i, (0.5, 1.0, 1.5), v_w=(1.0, -i, 0.5), omega_b=(0.2 * i, 0.1, -0.3)))
    s.add_effect("gravity")
    s.add_effect("linear_damping", c=0.3)
    sim = lv.Sim(s, dt=1e-3, integrator="rk4", backend="numpy")
    b = sim._budget
    assert b is not None and b._const_rates
    x1 = sim._x.copy()
    x2 = x1 * 1.7
    first = b._rates(x1)
    assert b._rates(x2) is first
    for kept, fresh in zip(first, b._rates_of(x2)):
        assert np.array_equal(kept, fresh)
    assert not first[0].any() and np.array_equal(first[1], [np.linalg.norm(np.array([0, 0, -9.81]) * (1.0 + i)) for i in range(5)])
    v, w = np.ascontiguousarray(x2[:, LY.STATE_V_W]), np.ascontiguousarray(x2[:, LY.STATE_OMEGA_B])
    for a, c in zip(b._momenta(x2, sim._models.Omega), b._momenta(x2, sim._models.Omega, v, w)):
        assert np.array_equal(a, c) and (a > 0).all()

    s.add_effect("force_at_point", body="b1", r_b=(1.0, 0.0, 0.0), F_w=(0.0, 0.0, 2.0))
    sim = lv.Sim(s, dt=1e-3, integrator="rk4", backend="numpy")
    b = sim._budget
    assert b is not None and not b._const_rates
    x = sim._x.copy()
    r1 = b._rates(x)
    x[1, LY.STATE_Q] = (0.0, np.sqrt(0.5), 0.0, np.sqrt(0.5))   # r_b turned along F: no torque
    r2 = b._rates(x)
    assert r2 is not r1 and r1[0][1] == pytest.approx(2.0) and r2[0][1] == pytest.approx(0.0, abs=1e-12)
