"""The NumPy backend's explicit Runge–Kutta step forms only the state rows its right-hand side reads, and steps rows
whose printed rate is identically 0 as constants (generated/kernels_scalar.py READS and ZEROS; numpy_backend
_StateRows): bit for bit the step over every row, signed zeros included, whichever runs it uses."""
import numpy as np
import pytest

import lavendersim as lv
from lavendersim import backends as B
from lavendersim.backends import Tableau
from lavendersim.backends import numpy_backend as NB
from lavendersim.backends import numpy_scalar as SC
from lavendersim.generated import kernels_scalar as KS
from lavendersim.generated import layout as LY

KUTTA3 = Tableau("test_rows_kutta3", [0, 0.5, 1], [[0, 0, 0], [0.5, 0, 0], [-1.0, 2.0, 0]], [1 / 6, 2 / 3, 1 / 6], 3,
                 "tests")


@pytest.fixture
def kutta3():
    before = dict(B.USER_TABLEAUX)
    B.USER_TABLEAUX[KUTTA3.name] = KUTTA3
    yield
    B.USER_TABLEAUX.clear()
    B.USER_TABLEAUX.update(before)


def scene(n, effects):
    rng = np.random.default_rng(4)
    s = lv.Scene()
    q = rng.normal(size=(n, 4))
    v = rng.normal(size=(n, 3))
    v[::3] = -0.0                      # signed zeros: a zero-rate row must come out as the full sum does (+0.0)
    p = rng.normal(size=(n, 3))
    p[1::3] = -0.0
    s.add_bodies([f"b{i}" for i in range(n)], rng.uniform(0.5, 2, n), np.sort(rng.uniform(1.0, 1.9, (n, 3)), axis=1),
                 q=q / np.linalg.norm(q, axis=1, keepdims=True), omega_b=rng.uniform(-3, 3, (n, 3)), v_w=v, p_w=p)
    if effects in ("uniform", "mixed"):
        s.add_effect("gravity", g_w=(0.0, 0.0, -9.81))
        s.add_effect("angular_damping", c=0.1)
    if effects == "mixed":
        s.add_effect("linear_damping", body="b1", c=0.2)
        s.add_effect("force_at_point", body="b2", F_w=(0.5, 0.1, -0.2), r_b=(0.1, 0.2, -0.1))
    return s


def advance(s, integrator, monkeypatch, rows, split, fresh=False):
    monkeypatch.setattr(SC, "SCALAR_MAX_BODIES", 0)             # the vectorized path
    if fresh:     # a right-hand side that returns new arrays, not its rates in the stepper's buffers: copied in
        rhs = NB._Plan.rhs
        monkeypatch.setattr(NB._Plan, "rhs", lambda self, x, u=None, out=None: rhs(self, x, u))
    monkeypatch.setattr(NB, "ROWS_SPLIT_BODIES", 0 if split else 10**9)
    if not rows:
        monkeypatch.setattr(NB._StateRows, "of", staticmethod(lambda plan, effects: None))
    sim = lv.Sim(s, dt=0.01, integrator="rk4", backend="numpy")
    x = sim.x.copy()
    NB.NumpyBackend().advance(x, sim.params, sim.effects, integrator, True, 0.01, 30)
    monkeypatch.undo()
    return x


@pytest.mark.parametrize("integrator", ["rk4", "euler", KUTTA3.name])
@pytest.mark.parametrize("effects", ["none", "uniform", "mixed"])
def test_rows_step_is_the_full_step_bitwise(kutta3, monkeypatch, integrator, effects):
    full = advance(scene(40, effects), integrator, monkeypatch, rows=False, split=False)
    for split, fresh in ((False, False), (True, False), (False, True), (True, True)):
        x = advance(scene(40, effects), integrator, monkeypatch, rows=True, split=split, fresh=fresh)
        assert x.tobytes() == full.tobytes(), (integrator, effects, split, fresh)
    start = lv.Sim(scene(40, effects), dt=0.01, backend="numpy").x
    assert np.signbit(start[::3, LY.STATE_V_W]).all()          # the signed zeros are there to be stepped
    if effects == "none" and integrator == "rk4":              # rk4's torque-free form keeps v_w (v_w' = 0): -0.0
        assert np.signbit(full[::3, LY.STATE_V_W]).all()
    elif effects == "none":                                    # x + 0.0: the full sum's +0.0, the rows step's too
        assert not np.signbit(full[::3, LY.STATE_V_W]).any()


def test_the_printed_tables_name_the_free_kernels_rows():
    q, w, v, p = (set(range(s.start, s.stop)) for s in (LY.STATE_Q, LY.STATE_OMEGA_B, LY.STATE_V_W, LY.STATE_P_W))
    assert set(KS.READS["rigid_body_rhs_free_c"]["x"]) == q | w | v     # p_dot = v; nothing reads p
    assert set(KS.ZEROS["rigid_body_rhs_free_c"]["x_dot"]) == v        # torque- and force-free: v constant
    assert KS.ZEROS["rigid_body_rhs_c"]["x_dot"] == ()
    plan = NB._Plan(np.array([[1.0, 1.0, 1.5, 1.8]]), np.zeros((0, 8)))
    assert plan.rows.stage == ((3, 7), (10, 13)) and plan.rows.zero == ((7, 10),) and plan.rows.end == ((0, 7), (10, 13))
