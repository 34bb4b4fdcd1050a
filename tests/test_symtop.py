"""The symmetric-top splittings: the free rigid body split around a symmetric top, H = |L|²/(2 I_r) + ½ c_a L_a² +
½ c_b L_b² (exact sphere and axis flows), composed as splitting4 composes splitting (symtop4: Suzuki, order 4) or by
Blanes & Moan's optimized order-6 splitting S10 (symtop_bm6).

Orders against the exact torque-free motion (lavendersim.oracle.torque_free) and, with loads, against
dopri5 at rtol = atol = 1e-13; world L and |q| to rounding; C and NumPy bitwise equal; the validity bound.
"""
from __future__ import annotations

import numpy as np
import pytest

import lavendersim as lv
from lavendersim import backends as B
from lavendersim import oracle as R
from lavendersim.backends import numpy_backend as NB
from lavendersim.errors import ValidityBoundWarning
from lavendersim.generated import tableaux as T
from lavendersim.kernels import K

from loaded_body import loaded_errors

EPS = np.finfo(float).eps
NAMES = ("symtop4", "symtop_bm6")
I_DIAG = (1.0, 2.0, 3.0)
W1, W2 = (1.0, 0.5, 0.2), (0.1, 2.0, 0.1)          # the accuracy lab's diag_w1, diag_w2
BOX = tuple(K.inertia_box(1.0, 0.8, 0.2, 0.2))    # I_y = I_z: a symmetric top


def _backends():
    return ["c", "numpy"] if B.c_unavailable() is None else ["numpy"]


def _sim(dt, backend="c", bodies=None, effects=(), integrator="symtop4", **kw):
    scene = lv.Scene()
    for name, I_b, k in bodies or [("b", I_DIAG, {"omega_b": W1})]:
        scene.add_body(lv.Body(name, 1.0, I_b, **k))
    for name, params in effects:
        scene.add_effect(name, **params)
    return lv.Sim(scene, dt=dt, integrator=integrator, backend=backend, **kw)


def _att_errors(I_b, w0, exps, backend, integrator="symtop4", T_end=10.0):
    ref = R.torque_free(I_b, w0, [0, 0, 0, 1], T_end)
    out = []
    for k in exps:
        dt = 2.0 ** -k
        s = _sim(dt, backend, [("b", I_b, {"omega_b": w0})], integrator=integrator)
        s.run(int(round(T_end / dt)))
        out.append(float(R.attitude_error(s.x[0, 3:7], ref.q[-1])))
    return np.asarray(out)


def _fractions(name, flow):
    """The fractions of h of one flow in name's torque-free program (generated/tableaux.py COMPOSITIONS)."""
    return [x for f, x in T.COMPOSITIONS[name][2] if f == flow]


STAGES = len(T.COMPOSITIONS["symtop4"][0])      # symtop4's kicked stages (symtop_bm6's with effects too)


# ---------------------------------------------------------------- symtop4
# torque-free A(a_0 h) B(b_0 h) A(a_1 h) ... A(a_s h) with A = the top_a axis flow then the sphere flow, B = the top_b
# flow; Suzuki's stages

def test_symtop4_listed_plain_only_counted_and_bounded():
    A_FRAC, B_FRAC = _fractions("symtop4", "top_a"), _fractions("symtop4", "top_b")
    assert "symtop4" in B.INTEGRATORS and "symtop4" in B.PLAIN_ONLY
    assert B.INTEGRATORS["symtop4"] == STAGES == len(B_FRAC) == 5
    assert len(A_FRAC) == STAGES + 1
    assert abs(sum(A_FRAC) - 1.0) <= 4 * EPS and abs(sum(B_FRAC) - 1.0) <= 4 * EPS
    assert A_FRAC == A_FRAC[::-1]
    assert "symtop4" in T.WDT_MAX and "symtop4" in T.WDT_RATIO_EXPONENT
    damped = _sim(0.01, _backends()[0], effects=[("angular_damping", {"c": 0.1})])
    damped.run(3)
    assert damped.rhs_evals == 3 * 4 * STAGES   # two midpoint half kicks per Strang stage


@pytest.mark.parametrize("I_b", [(1.0, 2.0, 3.0), (3.0, 1.0, 2.0), (2.0, 3.0, 1.0), (1.5, 1.0, 1.2), (5.0, 5.0, 1.0)])
def test_reference_axis_is_the_intermediate_moment(I_b):
    """The derived score |c_a c_b| is smallest about the intermediate principal axis; A takes the larger
    leftover coefficient."""
    I = np.array([I_b])
    a, b, I_r, c_a, c_b = NB.symtop_axes(I)
    assert I_r[0] == sorted(I_b)[1]
    assert {int(a[0]), int(b[0])} | {int(np.flatnonzero(I[0] == I_r[0])[0])} == {0, 1, 2}
    assert abs(c_a[0]) >= abs(c_b[0])
    assert c_a[0] == 1 / I_b[a[0]] - 1 / I_r[0] and c_b[0] == 1 / I_b[b[0]] - 1 / I_r[0]


def test_symtop4_fourth_order_on_the_exact_torque_free_motion():
    """diag(1, 2, 3), ω0 = [1, 0.5, 0.2], T = 10 s, dt = 2^-4 … 2^-7: the attitude error falls 16× per
    halving (measured 2.9e-9, 1.8e-10, 1.1e-11, 7.4e-13 rad)."""
    for backend in _backends():
        e = _att_errors(I_DIAG, W1, range(4, 8), backend)
        r = np.asarray(e[:-1]) / np.asarray(e[1:])
        assert np.all((r > 14.0) & (r < 18.5)), (backend, e, r)
        assert e[-1] < 1e-11


def test_symtop4_more_accurate_than_splitting4_at_equal_dt():
    """Same case, dt = 2^-5: symtop4's leftover B part is small (c_b = 1/3 - 1/2 about the intermediate
    axis) where splitting4 splits all three axes: measured 1.8e-10 vs 6.2e-10 rad (3.4x), with 17 exact
    rotations per step against 21."""
    backend = _backends()[0]
    e_s = _att_errors(I_DIAG, W1, [5], backend)[0]
    e_4 = _att_errors(I_DIAG, W1, [5], backend, integrator="splitting4")[0]
    assert e_s * 2.5 < e_4, (e_s, e_4)


def test_symtop4_fourth_order_with_attitude_dependent_loads():
    """A world-fixed torque and gravity (loads of q and p only): each stage's kicks keep it symmetric: order 4."""
    e = loaded_errors("symtop4", None, range(3, 7), _backends()[0])
    r = e[:-1] / e[1:]
    assert np.all((r > 14.0) & (r < 18.5)), (e, r)


def test_symtop4_third_order_with_damping():
    """Documented limit (as splitting4): the midpoint kick of a velocity-dependent effect is not symmetric."""
    e = loaded_errors("symtop4", 1.5, range(3, 7), _backends()[0])
    r = e[:-1] / e[1:]
    assert np.all((r > 7.0) & (r < 9.5)), (e, r)


# ---------------------------------------------------------------- symtop_bm6
# torque-free P(p_0 h) Q(q_0 h) ... P(p_s h), P = the top_b_nz axis flow, Q = the top_a one, then one sphere flow;
# with effects symtop4's kicked stages

def test_symtop_bm6_listed_plain_only_counted_and_bounded():
    NAME, P_FRAC, Q_FRAC = "symtop_bm6", _fractions("symtop_bm6", "top_b_nz"), _fractions("symtop_bm6", "top_a")
    assert NAME in B.INTEGRATORS and NAME in B.PLAIN_ONLY
    assert B.INTEGRATORS[NAME] == len(T.COMPOSITIONS[NAME][0]) == STAGES
    assert len(P_FRAC) == len(Q_FRAC) + 1 == 11
    assert P_FRAC == P_FRAC[::-1] and Q_FRAC == Q_FRAC[::-1]
    assert abs(sum(P_FRAC) - 1.0) <= 8 * EPS and abs(sum(Q_FRAC) - 1.0) <= 8 * EPS
    assert NAME in T.WDT_MAX and NAME in T.WDT_RATIO_EXPONENT
    damped = _sim(0.01, _backends()[0], effects=[("angular_damping", {"c": 0.1})], integrator=NAME)
    damped.run(3)
    assert damped.rhs_evals == 3 * 4 * STAGES   # symtop4's kicked stages


@pytest.mark.parametrize("w0", [W1, W2])
def test_symtop_bm6_sixth_order_on_the_exact_torque_free_motion(w0):
    """diag(1, 2, 3), T = 10 s, dt = 2^-2 -> 2^-3 (finer steps reach the reference's rounding): the attitude
    error falls 2^6 = 64x (measured w1 2.2e-11 -> 3.5e-13, w2 4.2e-9 -> 6.6e-11: 62, 63); order 4 would
    give 16."""
    for backend in _backends():
        e = _att_errors(I_DIAG, w0, (2, 3), backend, "symtop_bm6")
        r = e[:-1] / e[1:]
        assert np.all((r > 45.0) & (r < 90.0)), (backend, e, r)


def test_symtop_bm6_far_more_accurate_than_symtop4_at_the_labs_coarsest_dt():
    """dt = 2^-4 (the accuracy lab's coarsest step), diag_w2: symtop4 3.1e-7 rad; symtop_bm6 at the
    reference's rounding (measured 1.6e-12)."""
    backend = _backends()[0]
    e6 = _att_errors(I_DIAG, W2, [4], backend, "symtop_bm6")[0]
    e4 = _att_errors(I_DIAG, W2, [4], backend, integrator="symtop4")[0]
    assert e6 < 1e-11 and e4 > 1e4 * e6, (e6, e4)


def test_symtop_bm6_fourth_order_with_attitude_dependent_loads():
    """With effects the step is symtop4's kicked composition around this rotation: order 4 (documented)."""
    e = loaded_errors("symtop_bm6", None, range(3, 7), _backends()[0])
    r = e[:-1] / e[1:]
    assert np.all((r > 14.0) & (r < 18.5)), (e, r)


# ---------------------------------------------------------------- both

@pytest.mark.parametrize("w0", [W1, W2])
@pytest.mark.parametrize("name", NAMES)
def test_exact_for_a_symmetric_top(name, w0):
    """The box (I_y = I_z) leaves c_b = 0: the top_a axis flow and the sphere flow alone are the exact flow (the top_b
    flows turn by 0), at rounding from dt = 2^-3 on."""
    for backend in _backends():
        assert max(_att_errors(BOX, w0, [3], backend, name)) < 1e-11


@pytest.mark.parametrize("name", NAMES)
@pytest.mark.parametrize("effects", ["none", "loads", "damped"])
def test_c_and_numpy_bitwise_equal_on_random_bodies(effects, name):
    """Random bodies whose moments come in every order, so that the (A, B) axes (symtop_bm6: Q, P) differ between
    bodies, and a symmetric top."""
    if B.c_unavailable() is not None:
        pytest.skip(f"C backend unavailable: {B.c_unavailable()}")
    rng = np.random.default_rng(12)
    bodies = []
    for i in range(8):
        I_b = rng.permutation(np.sort(rng.uniform(1.0, 1.9, 3)))
        q = rng.normal(size=4)
        bodies.append((f"b{i}", tuple(I_b), {"q": q / np.linalg.norm(q), "omega_b": rng.normal(size=3) * 3,
                                           "v_w": rng.normal(size=3), "p_w": rng.normal(size=3)}))
    bodies.append(("top", (1.5, 1.2, 1.2), {"omega_b": W2}))    # c_b = 0: the P flows are skipped (turns by 0)
    axes = NB.symtop_axes(np.array([b[1] for b in bodies]))
    assert len(set(zip(axes[0].tolist(), axes[1].tolist()))) >= 3 and axes[4][-1] == 0.0
    eff = []
    if effects != "none":
        eff = [("gravity", {"g_w": [0, 0, -9.81]}), ("applied_torque", {"torque_w": [0.3, -0.1, 0.2]}),
               ("force_at_point", {"body": "b2", "r_b": [0.1, 0.2, 0.3], "F_w": [1.0, 0.0, -2.0]})]
    if effects == "damped":
        eff += [("angular_damping", {"c": 0.3}), ("linear_damping", {"c": 0.2})]
    xs = []
    for backend in ("c", "numpy"):
        s = _sim(0.02, backend, bodies, eff, name)
        s.run(150)
        xs.append(s.x.copy())
    assert np.array_equal(xs[0], xs[1]), np.max(np.abs(xs[0] - xs[1]))


# exact rotations per step of the torque-free program, and the |q| - 1 allowed after n steps of them: symtop4
# measured 6.1e-13 after 10^4 C steps of 17 (0.28 ε per step, a random walk of 17 products), allowed ε per step;
# symtop_bm6 3.0e-12 after 10^4 C steps of 22 (0.06 ε per rotation, growing about linearly), allowed ε/4 per rotation
ROTATIONS = {"symtop4": 3 * STAGES + 2, "symtop_bm6": 2 * len(_fractions("symtop_bm6", "top_a")) + 2}
Q_DRIFT = {"symtop4": lambda n: EPS * n, "symtop_bm6": lambda n: EPS * n * ROTATIONS["symtop_bm6"] / 4}


@pytest.mark.parametrize("name", NAMES)
@pytest.mark.parametrize("backend", ["c", "numpy"])
def test_conserves_world_L_and_unit_q_over_a_long_run(backend, name):
    """Torque-free, normalization off, dt = 0.01: world L and |L_b| drift by rounding only (ROTATIONS exact
    rotations per step); |q| − 1 by rounding only without any normalization."""
    if backend == "c" and B.c_unavailable() is not None:
        pytest.skip(f"C backend unavailable: {B.c_unavailable()}")
    n, every = (10_000, 100) if backend == "c" else (1_000, 10)
    bodies = [("diag", I_DIAG, {"omega_b": W1}), ("box", BOX, {"omega_b": W2}),
              ("fast", (0.5, 0.9, 1.2), {"omega_b": (5.0, -3.0, 8.0)})]
    s = _sim(0.01, backend, bodies, integrator=name, normalize=False)
    I = s.params[:, 1:4]

    def L(x):
        return np.array([K.quat_rotate(x[i, 3:7], I[i] * x[i, 10:13]) for i in range(len(bodies))])

    L0 = L(s.x)
    tr = s.record(n, every)
    drift = max(float(np.max(np.linalg.norm(L(x) - L0, axis=1) / np.linalg.norm(L0, axis=1))) for x in tr.x)
    Lb = np.linalg.norm(I * tr.x[:, :, 10:13], axis=2)
    drift_b = float(np.max(np.abs(Lb / Lb[0] - 1.0)))
    flows = n * ROTATIONS[name]
    assert drift <= 2 * EPS * flows, drift
    assert drift_b <= 2 * EPS * flows, drift_b
    assert float(np.max(np.abs(np.linalg.norm(tr.x[:, :, 3:7], axis=2) - 1.0))) <= Q_DRIFT[name](n)


@pytest.mark.parametrize("name", NAMES)
def test_plain_bodies_only(name):
    scene = lv.Scene()
    scene.add_body(lv.Body("w", 1.0, (1.0, 1.0, 1.0)))
    scene.add_effect("reaction_wheels", body="w", J=[0.01, 0.01, 0.01], torque_limit=0.1, speed_limit=100.0)
    with pytest.raises(lv.LavenderInputError, match="plain rigid bodies only"):
        lv.Sim(scene, dt=0.01, integrator=name)


@pytest.mark.parametrize("name", NAMES)
@pytest.mark.parametrize("backend", ["c", "numpy"])
def test_validity_bound_raises_and_warns(backend, name):
    """|ω| dt (I_max/I_min)^(1/2) = 2.4 > 1: refused with the bound named and the state kept; opted in with
    on_bound='warn' it runs (finite: exact rotations) and warns."""
    if backend == "c" and B.c_unavailable() is not None:
        pytest.skip(f"C backend unavailable: {B.c_unavailable()}")
    bodies = [("b", (1.0, 2.0, 2.5), {"omega_b": (0.0, 0.0, 15.0)})]
    s = _sim(0.1, backend, bodies, integrator=name)
    x0 = s.x.copy()
    with pytest.raises(lv.DivergenceError, match=rf"{name}'s validity bound"):
        s.run(5)
    assert np.array_equal(s.x, x0) and s.steps == 0
    w = _sim(0.1, backend, bodies, integrator=name, on_bound="warn")
    with pytest.warns(ValidityBoundWarning, match=name):
        w.run(5)
    assert np.all(np.isfinite(w.x))
