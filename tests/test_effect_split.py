"""Decoupled bodies (issue 30): a plain body none of whose effects couples translation and rotation (derive/effect.py
FLAG_COUPLED clear: damping, gravity + damping) steps its rotation alone through RK4's stages and its translation by
RK4's exact affine flow (derive/rigid_body.py affine_flow, translation_flow*). Checked here: derive's decision and
polynomials, C = NumPy bitwise on every path (scalar blocks, stage-pass and fused tiles, vectorized and float NumPy),
zero strength = no effect, and agreement with RK4 on all 13 numbers to rounding."""
import numpy as np
import pytest
import sympy as sp

import lavendersim as lv
from lavendersim.derive import effects as DE
from lavendersim.derive import rigid_body as RB
from lavendersim.derive import tableaux as TB
from lavendersim.derive.effect import FLAG_COUPLED, STATE, effect, param
from lavendersim import backends as B

LIN, ANG, GRAV = ("linear_damping", {"c": 0.3}), ("angular_damping", {"c": 0.2}), ("gravity", {})
SETS = {"damping": [LIN, ANG], "gravity + damping": [GRAV, LIN, ANG], "linear alone": [LIN], "angular alone": [ANG],
        "gravity + linear": [GRAV, LIN],
        "unfused (gravity between)": [LIN, GRAV, ANG],      # no fused pattern: the stage-pass tiles
        "twice linear + angular": [LIN, ("linear_damping", {"c": 0.1}), ANG]}


def test_rk4_affine_flow_is_its_stability_polynomials():
    z = sp.Symbol("z")
    R, P, Q, S = RB.affine_flow(*TB.EXPLICIT_RK["rk4"])
    assert sp.expand(R - (1 - z + z**2 / 2 - z**3 / 6 + z**4 / 24)) == 0
    assert sp.expand(R - TB.explicit_rk_polynomial("rk4").subs(sp.Symbol("z"), -z)) == 0   # y' = -λy: R(-λh)
    assert sp.expand(P - (1 - z / 2 + z**2 / 6 - z**3 / 24)) == 0 and sp.expand(Q - P) == 0
    assert sp.expand(S - (sp.Rational(1, 2) - z / 6 + z**2 / 24)) == 0
    assert [e.subs(z, 0) for e in (R, P, Q, S)] == [1, 1, 1, sp.Rational(1, 2)]   # the constant-acceleration flow


def test_numpy_classes_step_decoupled_as_their_kinds_do_in_c():
    """The NumPy backends' split table (effects.RHS_SPLIT, printed by derive per NumPy class: RHS_SPLIT_BY_CLASS) says,
    for every kind C dispatches on (kernels.h LV_RHS_SPLIT_<kind>, effects_meta RHS_SPLIT), what C does; the kinds a
    class merges (TORQUE into FULL) agree, and every class is some kind's."""
    from lavendersim import effects as E
    from lavendersim.derive import effect_fuse as EF
    from lavendersim.generated import effects_meta as M
    assert set(M.RHS_CLASS_OF_KIND) == set(M.RHS_SPLIT) == set(EF.TILE_KINDS)
    for kind, split in M.RHS_SPLIT.items():
        assert E.RHS_SPLIT[M.RHS_CLASS_OF_KIND[kind]] == split, kind
    assert sorted(set(M.RHS_CLASS_OF_KIND.values())) == list(range(len(M.RHS_CLASSES))) == list(range(len(E.RHS_SPLIT)))
    assert (E.RHS_FULL, E.RHS_FORCE, E.RHS_BODY, E.RHS_BODY_F) == tuple(M.RHS_CLASS_OF_KIND[k] for k in
                                                                       ("FULL", "FORCE", "BODY", "BODY_F"))
    saved = dict(EF.SPLIT_OF_KIND)
    try:
        EF.SPLIT_OF_KIND["TORQUE"] = 2       # TORQUE and FULL share a NumPy class: they must step alike
        with pytest.raises(RuntimeError, match="FULL"):
            EF.split_by_class()
    finally:
        EF.SPLIT_OF_KIND.clear()
        EF.SPLIT_OF_KIND.update(saved)


def test_derive_decides_which_effects_couple():
    flags = {d.name: d.flags for d in DE.declarations() if d.kind == "force"}
    for name in ("gravity", "linear_damping", "angular_damping", "applied_torque", "force_at_point"):
        assert not flags[name] & FLAG_COUPLED, name
    c = param("c", (), "", "", "nonnegative")
    coupled = [effect("quad", "", [c], force_w=-c.symbol * STATE.v_w.norm() * STATE.v_w),      # not affine in v
               effect("aniso", "", [c], force_w=sp.Matrix([-c.symbol * STATE.v_w[0], 0, 0])),  # no scalar rate
               effect("lift", "", [c], force_w=c.symbol * STATE.omega_w),                      # force reads omega
               effect("fin", "", [c], torque_w=c.symbol * STATE.v_w)]                          # torque reads v
    for d in coupled:
        assert d.flags & FLAG_COUPLED and d.affine_force is None, d.name
    F0, k = [d for d in DE.declarations() if d.name == "gravity"][0].affine_force
    assert k == 0 and [str(e) for e in F0] == ["g_w_0*m", "g_w_1*m", "g_w_2*m"]


def _scene(n, effects, seed=3):
    rng = np.random.default_rng(seed)
    s = lv.Scene()
    for i in range(n):
        q = rng.normal(size=4)
        s.add_body(lv.Body(f"b{i}", rng.uniform(0.5, 2.0), tuple(rng.uniform(0.8, 1.2, 3)), p_w=tuple(rng.normal(size=3)),
                           q=tuple(q / np.linalg.norm(q)), v_w=tuple(rng.normal(size=3)),
                           omega_b=tuple(2 * rng.normal(size=3))))
    for name, kw in effects:
        s.add_effect(name, **kw)
    return s


def _run(n, effects, backend, integrator="rk4", steps=60, dt=1e-2, normalize=True):
    sim = lv.Sim(_scene(n, effects), dt=dt, integrator=integrator, backend=backend, normalize=normalize)
    sim.run(steps)
    return sim.x.copy()


@pytest.mark.parametrize("n", [1, 5, 70])   # C: scalar blocks, tiles (padded), two tiles; NumPy: floats, vectorized
@pytest.mark.parametrize("label", list(SETS))
def test_c_and_numpy_step_decoupled_bodies_bitwise(label, n):
    for normalize in (True, False):
        c = _run(n, SETS[label], "c", normalize=normalize)
        assert np.array_equal(c, _run(n, SETS[label], "numpy", normalize=normalize)), (label, n, normalize)


@pytest.mark.parametrize("backend", ["c", "numpy"])
@pytest.mark.parametrize("n", [1, 70])
def test_zero_strength_damping_gives_the_bits_of_no_effect(backend, n):
    zero = [("linear_damping", {"c": 0.0}), ("angular_damping", {"c": 0.0})]
    assert np.array_equal(_run(n, zero, backend), _run(n, [], backend))


def test_zero_damping_after_gravity_is_the_constant_acceleration_flow():
    """k = 0: R = 1, dt Q = dt, dv = dt a, dp = (dt dt 1/2) a exactly (the form of gravity's constant flow)."""
    from lavendersim.kernels import K
    F0, m, dt = np.array([[0.3, -1.7, -9.81 * 1.3]]), np.array([1.3]), 0.013
    T = K.translation_flow_scale(np.zeros(1), F0, m, dt)
    a = F0 / m[:, None]
    assert T[0, 0] == 1.0 and T[0, 1] == dt
    assert np.array_equal(T[0, 2:5], dt * a[0]) and np.array_equal(T[0, 5:8], (dt * dt * 0.5) * a[0])


@pytest.mark.parametrize("backend", ["c", "numpy"])
def test_decoupled_step_is_rk4_on_all_13_numbers_to_rounding(backend):
    """The 13-number stages of a user-declared RK4 tableau against the decoupled form: the same method, other
    roundings (so the bits differ)."""
    rk4 = B.Tableau("test_split_rk4", [0, 0.5, 0.5, 1], [[0, 0, 0, 0], [0.5, 0, 0, 0], [0, 0.5, 0, 0], [0, 0, 1, 0]],
                    [1 / 6, 1 / 3, 1 / 3, 1 / 6], 4, "tests")
    B.USER_TABLEAUX[rk4.name] = rk4
    try:
        for label in ("damping", "gravity + damping", "unfused (gravity between)"):
            ref = _run(9, SETS[label], backend, integrator=rk4.name, steps=200)
            x = _run(9, SETS[label], backend, steps=200)
            np.testing.assert_allclose(x, ref, rtol=0, atol=1e-12)
            assert not np.array_equal(x, ref), label
    finally:
        del B.USER_TABLEAUX[rk4.name]
