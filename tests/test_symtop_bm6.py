"""symtop_bm6: symtop4's symmetric-top split (exact sphere and axis flows) composed by Blanes & Moan's
optimized order-6 splitting S10 instead of Suzuki's order-4 composition.

Order against the exact torque-free motion (lavendersim.oracle.torque_free) and, with loads, against
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

EPS = np.finfo(float).eps
NAME = "symtop_bm6"
I_DIAG = (1.0, 2.0, 3.0)
W1, W2 = (1.0, 0.5, 0.2), (0.1, 2.0, 0.1)          # the accuracy lab's diag_w1, diag_w2
BOX = tuple(K.inertia_box(1.0, 0.8, 0.2, 0.2))    # I_y = I_z: a symmetric top


def _backends():
    return ["c", "numpy"] if B.c_unavailable() is None else ["numpy"]


def _sim(dt, backend="c", bodies=None, effects=(), integrator=NAME, **kw):
    scene = lv.Scene()
    for name, I_b, k in bodies or [("b", I_DIAG, {"omega_b": W1})]:
        scene.add_body(lv.Body(name, 1.0, I_b, **k))
    for name, params in effects:
        scene.add_effect(name, **params)
    return lv.Sim(scene, dt=dt, integrator=integrator, backend=backend, **kw)


def _att_errors(I_b, w0, exps, backend, integrator=NAME, T_end=10.0):
    ref = R.torque_free(I_b, w0, [0, 0, 0, 1], T_end)
    out = []
    for k in exps:
        dt = 2.0 ** -k
        s = _sim(dt, backend, [("b", I_b, {"omega_b": w0})], integrator=integrator)
        s.run(int(round(T_end / dt)))
        out.append(float(R.attitude_error(s.x[0, 3:7], ref.q[-1])))
    return np.asarray(out)


# the printed program (generated/tableaux.py COMPOSITIONS): torque-free P(p_0 h) Q(q_0 h) ... P(p_s h), P = the
# top_b_nz axis flow, Q = the top_a one, then one sphere flow; with effects symtop4's kicked stages
_GAMMA, _, _FREE = T.COMPOSITIONS[NAME]
STAGES = len(_GAMMA)
P_FRAC = [x for f, x in _FREE if f == "top_b_nz"]
Q_FRAC = [x for f, x in _FREE if f == "top_a"]


def test_listed_plain_only_counted_and_bounded():
    assert NAME in B.INTEGRATORS and NAME in B.PLAIN_ONLY
    assert B.INTEGRATORS[NAME] == STAGES == len(T.COMPOSITIONS["symtop4"][0])
    assert len(P_FRAC) == len(Q_FRAC) + 1 == 11
    assert P_FRAC == P_FRAC[::-1] and Q_FRAC == Q_FRAC[::-1]
    assert abs(sum(P_FRAC) - 1.0) <= 8 * EPS and abs(sum(Q_FRAC) - 1.0) <= 8 * EPS
    assert NAME in T.WDT_MAX and NAME in T.WDT_RATIO_EXPONENT
    damped = _sim(0.01, _backends()[0], effects=[("angular_damping", {"c": 0.1})])
    damped.run(3)
    assert damped.rhs_evals == 3 * 4 * STAGES   # symtop4's kicked stages


@pytest.mark.parametrize("w0", [W1, W2])
def test_sixth_order_on_the_exact_torque_free_motion(w0):
    """diag(1, 2, 3), T = 10 s, dt = 2^-2 -> 2^-3 (finer steps reach the reference's rounding): the attitude
    error falls 2^6 = 64x (measured w1 2.2e-11 -> 3.5e-13, w2 4.2e-9 -> 6.6e-11: 62, 63); order 4 would
    give 16."""
    for backend in _backends():
        e = _att_errors(I_DIAG, w0, (2, 3), backend)
        r = e[:-1] / e[1:]
        assert np.all((r > 45.0) & (r < 90.0)), (backend, e, r)


def test_far_more_accurate_than_symtop4_at_the_labs_coarsest_dt():
    """dt = 2^-4 (the accuracy lab's coarsest step), diag_w2: symtop4 3.1e-7 rad; symtop_bm6 at the
    reference's rounding (measured 1.6e-12)."""
    backend = _backends()[0]
    e6 = _att_errors(I_DIAG, W2, [4], backend)[0]
    e4 = _att_errors(I_DIAG, W2, [4], backend, integrator="symtop4")[0]
    assert e6 < 1e-11 and e4 > 1e4 * e6, (e6, e4)


@pytest.mark.parametrize("w0", [W1, W2])
def test_exact_for_a_symmetric_top(w0):
    """The box (I_y = I_z) leaves c_b = 0: the P flows are identities, at rounding from dt = 2^-3 on."""
    for backend in _backends():
        assert max(_att_errors(BOX, w0, [3], backend)) < 1e-11


def _loaded(integrator, dt, backend="c", **kw):
    effects = [("applied_torque", {"torque_w": [0.3, -0.1, 0.2]}), ("gravity", {"g_w": [0, 0, -9.81]})]
    return _sim(dt, backend, [("b", (1.0, 2.0, 2.5), {"omega_b": W1, "v_w": (0.1, 0.0, 0.0)})], effects,
                integrator=integrator, **kw)


def test_fourth_order_with_attitude_dependent_loads():
    """With effects the step is symtop4's kicked composition around this rotation: order 4 (documented)."""
    backend = _backends()[0]
    T_end = 4.0
    ref = _loaded("dopri5", 0.5, backend, rtol=1e-13, atol=1e-13)
    ref.run(8)
    e = []
    for k in range(3, 7):
        dt = 2.0 ** -k
        s = _loaded(NAME, dt, backend)
        s.run(int(round(T_end / dt)))
        e.append(max(float(R.attitude_error(s.x[0, 3:7], ref.x[0, 3:7])),
                     float(np.linalg.norm(s.x[0, 10:13] - ref.x[0, 10:13])),
                     float(np.linalg.norm(s.x[0, 0:3] - ref.x[0, 0:3]))))
    e = np.asarray(e)
    r = e[:-1] / e[1:]
    assert np.all((r > 14.0) & (r < 18.5)), (e, r)


@pytest.mark.parametrize("effects", ["none", "loads", "damped"])
def test_c_and_numpy_bitwise_equal_on_random_bodies(effects):
    """Random bodies whose moments come in every order, so that the (P, Q) axes differ between bodies, and
    a symmetric top."""
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
        s = _sim(0.02, backend, bodies, eff)
        s.run(150)
        xs.append(s.x.copy())
    assert np.array_equal(xs[0], xs[1]), np.max(np.abs(xs[0] - xs[1]))


@pytest.mark.parametrize("backend", ["c", "numpy"])
def test_conserves_world_L_and_unit_q_over_a_long_run(backend):
    """Torque-free, normalization off, dt = 0.01: world L and |L_b| drift by rounding only (22 exact
    rotations per step); |q| − 1 by rounding only without any normalization."""
    if backend == "c" and B.c_unavailable() is not None:
        pytest.skip(f"C backend unavailable: {B.c_unavailable()}")
    n, every = (10_000, 100) if backend == "c" else (1_000, 10)
    bodies = [("diag", I_DIAG, {"omega_b": W1}), ("box", BOX, {"omega_b": W2}),
              ("fast", (0.5, 0.9, 1.2), {"omega_b": (5.0, -3.0, 8.0)})]
    s = _sim(0.01, backend, bodies, normalize=False)
    I = s.params[:, 1:4]

    def L(x):
        return np.array([K.quat_rotate(x[i, 3:7], I[i] * x[i, 10:13]) for i in range(len(bodies))])

    L0 = L(s.x)
    tr = s.record(n, every)
    drift = max(float(np.max(np.linalg.norm(L(x) - L0, axis=1) / np.linalg.norm(L0, axis=1))) for x in tr.x)
    Lb = np.linalg.norm(I * tr.x[:, :, 10:13], axis=2)
    drift_b = float(np.max(np.abs(Lb / Lb[0] - 1.0)))
    flows = n * (2 * len(Q_FRAC) + 2)
    assert drift <= 2 * EPS * flows, drift
    assert drift_b <= 2 * EPS * flows, drift_b
    # rounding of the quaternion products: measured 3.0e-12 after 10^4 C steps of 22 rotations (0.06 ε per
    # rotation, growing about linearly); allowed ε/4 per rotation
    assert float(np.max(np.abs(np.linalg.norm(tr.x[:, :, 3:7], axis=2) - 1.0))) <= EPS * flows / 4


def test_plain_bodies_only():
    scene = lv.Scene()
    scene.add_body(lv.Body("w", 1.0, (1.0, 1.0, 1.0)))
    scene.add_effect("reaction_wheels", body="w", J=[0.01, 0.01, 0.01], torque_limit=0.1, speed_limit=100.0)
    with pytest.raises(lv.LavenderInputError, match="plain rigid bodies only"):
        lv.Sim(scene, dt=0.01, integrator=NAME)


@pytest.mark.parametrize("backend", ["c", "numpy"])
def test_validity_bound_raises_and_warns(backend):
    """|ω| dt (I_max/I_min)^(1/2) = 2.4 > 1: refused with the bound named and the state kept; opted in with
    on_bound='warn' it runs (finite: exact rotations) and warns."""
    if backend == "c" and B.c_unavailable() is not None:
        pytest.skip(f"C backend unavailable: {B.c_unavailable()}")
    bodies = [("b", (1.0, 2.0, 2.5), {"omega_b": (0.0, 0.0, 15.0)})]
    s = _sim(0.1, backend, bodies)
    x0 = s.x.copy()
    with pytest.raises(lv.DivergenceError, match=r"symtop_bm6's validity bound"):
        s.run(5)
    assert np.array_equal(s.x, x0) and s.steps == 0
    w = _sim(0.1, backend, bodies, on_bound="warn")
    with pytest.warns(ValidityBoundWarning, match=NAME):
        w.run(5)
    assert np.all(np.isfinite(w.x))
