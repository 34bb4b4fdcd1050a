"""Issue 29, the C engine's families (csrc/step.c): one explicit Runge-Kutta stage loop for a user's tableau and
dopri5, one composition engine walking the printed programs (generated/tableaux.h LV_COMPOSITIONS, declared in
derive/tableaux.py compositions()), one effect-row check (float32 included), and the validity measure printed once
(derive/measures.py validity_scale / validity_wdt) for the Sim and the C screen alike."""
from __future__ import annotations

import re
from pathlib import Path

import numpy as np
import pytest
import sympy as sp

import lavendersim as lv
from lavendersim import backends as B
from lavendersim import validate as V
from lavendersim.generated import layout as LY
from lavendersim.generated import tableaux as T
from lavendersim.kernels import K

CSRC = Path(lv.__file__).parent / "csrc"
COMPOSITIONS = [n for n, f in T.INTEGRATOR_FAMILY.items() if f == "composition"]
needs_c = pytest.mark.skipif(B.c_unavailable() is not None, reason="the C backend is not built")


def _csrc_text() -> str:
    return "\n".join(p.read_text() for p in sorted(CSRC.glob("*.[ch]")))


def test_csrc_names_no_integrator():
    """Integrator names and codes appear in derive/ and generated/ only (issue 29): the compositions, the Lie-group
    RK and the implicit step are dispatched by family (LV_INTEGRATOR_IS_*), the compositions walk their printed
    programs, the adaptive RK is LV_INTEGRATOR_ADAPTIVE(i), and the fixed-step paths are selected by the printed
    LV_PATH_* (tableaux.h: the code of the integrator whose tableau each path steps). csrc/ names none of them."""
    text = _csrc_text()
    for name in T.INTEGRATOR_CODES:
        assert f"LV_INTEGRATOR_{name.upper()}" not in text, name
    for name in ("splitting_step", "splitting4_step", "symtop_step", "symtop_bm6_rotation", "advance_dopri5",
                 "advance_tableau"):
        assert re.search(rf"\b{name}\s*\(", text) is None, name


def test_fixed_paths_are_chosen_by_tableau_identity(monkeypatch):
    """Each fixed-step path of csrc/ is taken by the integrator whose tableau is the path's (derive/tableaux.py
    fixed_path), printed as LV_PATH_* = that integrator's code; a new built-in explicit RK (Heun's method, added to
    the registry here) takes none and is printed for C's tableau stepper (LV_TABLEAU_STEPPED): derive-only."""
    from lavendersim.derive import tableaux as DT
    R = sp.Rational
    taken = {p: [i.name for i in DT.INTEGRATORS if DT.fixed_path(i) == p] for p in DT.FIXED_PATHS}
    assert taken == {"euler": ["euler"], "semi_implicit": ["semi_implicit_euler"], "rk4": ["rk4"]}
    h = (Path(T.__file__).parent / "tableaux.h").read_text()   # beside generated/tableaux.py, whatever the install
    assert "LV_PATH_RK4 = LV_INTEGRATOR_RK4" in h and "#define LV_TABLEAU_STEPPED(X)\n" in h
    heun = DT.Integrator("heun", len(DT.INTEGRATORS), "explicit_rk", 2, 2, False, False, "Heun's method")
    monkeypatch.setattr(DT, "INTEGRATORS", DT.INTEGRATORS + (heun,))
    monkeypatch.setitem(DT.EXPLICIT_RK, "heun", ((R(0), R(1)), (1, 1), 2))
    monkeypatch.setitem(DT.WDT_MAX, "heun", R(1))
    monkeypatch.setitem(DT.WDT_RATIO_EXPONENT, "heun", R(0))
    assert DT.fixed_path(heun) is None
    h = DT.print_c()
    assert "static const double LV_HEUN_A[4] = {0.0, 0.0, 1.0, 0.0};" in h
    assert "static const double LV_HEUN_B_NUM[2] = {1.0, 1.0};" in h
    assert "#define LV_TABLEAU_STEPPED(X) X(LV_INTEGRATOR_HEUN, 2, LV_HEUN_A, LV_HEUN_B_NUM, 2.0)" in h
    assert "(i) == LV_PATH_RK4)" in h and "LV_PATH_HEUN" not in h


def test_one_effect_row_check_in_c():
    """Every C path validates effect rows with lv_effect_row_check (step.c): no other file looks a row's code up in
    the effects' parameter counts (model_simd.h and batch_simd.h ask a code's parameter count to pick its tiles, on
    rows already checked: not a check). The C fast path (fast_step.c) checks no row itself: lv_simulate's index_build
    does, before anything is written (test_sim_faults: a bad row goes to the Python path, which names it)."""
    users = {p.name for p in CSRC.glob("*.[ch]") if "lv_effect_n_params(" in p.read_text()}
    assert users <= {"step.c", "model_simd.h", "batch_simd.h"}
    for name in ("fixed_loop.h", "module_f32.c", "module.c", "step.c"):
        assert "lv_effect_row_check(" in (CSRC / name).read_text(), name
    fast = (CSRC / "fast_step.c").read_text()
    assert "lv_simulate(" in fast and "lv_effect_row_check(" not in fast


def test_printed_programs_carry_the_declared_numbers():
    """The printed programs (C and NumPy walk the same COMPOSITIONS) carry the correctly rounded doubles of the
    exact fractions derive/tableaux.py declares (split4_sequence, symtop4_sequence, bm6_sequence), every stage list
    is the integrator's gamma, and only composition integrators have one."""
    from lavendersim.derive import tableaux as DT

    def dbl(v):
        return [float(sp.N(x, 50)) for x in v]

    assert sorted(T.COMPOSITIONS) == sorted(COMPOSITIONS)
    gamma, kicked, free = T.COMPOSITIONS["splitting4"]
    assert list(gamma) == dbl(DT.SPLIT4_GAMMA)
    seq = DT.split4_sequence()
    assert [(int("xyz".index(f[-1])), x) for f, x in free if f.startswith("axis_")] == list(zip(
        [a for a, _ in seq], dbl(f for _, f in seq)))
    gamma, kicked, free = T.COMPOSITIONS["symtop4"]
    fa, fb = DT.symtop4_sequence()
    assert list(gamma) == dbl(DT.SYMTOP4_GAMMA)
    assert [x for f, x in free if f == "top_a"] == [x for f, x in free if f == "sphere"] == dbl(fa)
    assert [x for f, x in free if f == "top_b"] == dbl(fb)
    assert [x for f, x in kicked if f in ("top_a", "sphere")] == [0.5] * 4     # the Strang step A(h/2) B(h) A(h/2)
    gamma, kicked, free = T.COMPOSITIONS["symtop_bm6"]
    fp, fq = DT.bm6_sequence()
    assert [x for f, x in free if f == "top_b_nz"] == dbl(fp)
    assert [x for f, x in free if f == "top_a"] == dbl(fq)
    for name in COMPOSITIONS:
        gamma, kicked, free = T.COMPOSITIONS[name]
        assert kicked[0] == kicked[-1] == ("kick", T.SPLIT_KICK) and free[0] == ("drift", 1.0)
        assert B.INTEGRATORS[name] == len(gamma)


def _scene(n_free=6, kicked=True, seed=3):
    rng = np.random.default_rng(seed)
    scene = lv.Scene()
    inertias = [(1.0, 2.0, 2.5), (2.0, 2.0, 3.0), (3.0, 1.5, 2.0), (1.0, 1.0, 1.0), (0.6, 3.0, 3.0), (4.0, 4.0, 1.0)]
    for i in range(n_free):
        scene.add_body(lv.Body(f"f{i}", 1.0 + i, inertias[i % len(inertias)], omega_b=rng.normal(size=3),
                               v_w=rng.normal(size=3)))
    if kicked:
        for i in range(3):
            scene.add_body(lv.Body(f"k{i}", 2.0, inertias[i], omega_b=rng.normal(size=3), v_w=rng.normal(size=3)))
        scene.add_effect("gravity", g_w=(0.0, 0.0, -9.81), body="k0")
        scene.add_effect("angular_damping", c=0.3, body="k1")
        scene.add_effect("gravity", g_w=(0.0, -1.0, 0.0), body="k2")
    return scene


@needs_c
@pytest.mark.parametrize("name", COMPOSITIONS)
def test_composition_engine_c_equals_numpy_bitwise(name):
    """Torque-free bodies (the free program; a symmetric top, c_b = 0, among them) and bodies under loads (the
    kicked stages; damped and undamped) step to the same doubles on both backends."""
    out = {}
    for backend in ("c", "numpy"):
        sim = lv.Sim(_scene(), dt=0.01, integrator=name, backend=backend)
        sim.run(40)
        out[backend] = sim.x.copy()
    assert np.all(np.isfinite(out["c"]))
    np.testing.assert_array_equal(out["c"], out["numpy"])


@needs_c
def test_dopri5_and_a_user_tableau_share_the_stage_loop():
    """dopri5 (the printed LV_DP_A through the explicit-RK stage loop) equals the NumPy backend bitwise, counts
    included, on free, damped and loaded bodies."""
    out = {}
    for backend in ("c", "numpy"):
        sim = lv.Sim(_scene(4), dt=0.05, integrator="dopri5", rtol=1e-9, atol=1e-11, backend=backend)
        sim.run(10)
        out[backend] = (sim.x.copy(), sim.rhs_evals)
    np.testing.assert_array_equal(out["c"][0], out["numpy"][0])
    assert out["c"][1] == out["numpy"][1]


def test_validity_scale_is_the_declared_formula():
    """validity_scale = dt (I_max/I_min)^p, validity_wdt = (|omega|, |omega| scale): the numbers the Sim used to
    type by hand, bitwise."""
    rng = np.random.default_rng(7)
    I = rng.uniform(0.1, 10.0, (50, 3))
    om = rng.normal(size=(50, 3)) * 5
    for p in (0.0, 0.5):
        want = 0.01 * ((I.max(axis=1) / I.min(axis=1)) ** p if p else np.ones(50))
        np.testing.assert_array_equal(K.validity_scale(I, 0.01, p), want)
    scale = K.validity_scale(I, 0.01, 0.5)
    w, v = K.validity_wdt(om, scale)
    np.testing.assert_array_equal(w, np.sqrt(np.add.reduce(om * om, axis=1)))
    np.testing.assert_array_equal(v, w * scale)


@needs_c
def test_c_screen_decides_on_the_printed_measure():
    """checks_pass (csrc/fast_step.c) passes a bound equal to the largest printed measure and refuses the next double
    below it: C and the Sim decide on the same double."""
    from lavendersim.backends import c_backend
    rng = np.random.default_rng(11)
    nb = 40
    x = np.zeros((nb, LY.STATE_SIZE))
    x[:, LY.STATE_Q] = [0.0, 0.0, 0.0, 1.0]
    x[:, LY.STATE_OMEGA_B] = rng.normal(size=(nb, 3)) * 3
    params = np.zeros((nb, LY.PARAM_SIZE))
    params[:, LY.PARAM_M] = 1.0
    params[:, LY.PARAM_I_B] = rng.uniform(0.5, 50.0, (nb, 3))
    scale = K.validity_scale(params[:, LY.PARAM_I_B], 0.003, 0.5)
    growth = np.full((nb, 3), np.inf)
    top = float(K.validity_wdt(x[:, LY.STATE_OMEGA_B], scale)[1].max())
    assert c_backend._c.checks_pass(x, params, scale, top, growth)
    assert not c_backend._c.checks_pass(x, params, scale, float(np.nextafter(top, 0.0)), growth)


def test_set_state_checks_the_bound_with_that_bodys_inertia_ratio():
    """Sim.set_state on body 1 measures |omega| dt (I_max/I_min)^p with body 1's ratio (it took body 0's before):
    splitting (p = 1/2), a sphere first, a 1:100 body second, |omega| dt = 0.5 (within 1 for the sphere, 5 for it)."""
    scene = lv.Scene()
    scene.add_body(lv.Body("sphere", 1.0, (1.0, 1.0, 1.0)))
    scene.add_body(lv.Body("rod", 1.0, (0.01, 1.0, 1.0)))
    sim = lv.Sim(scene, dt=0.01, integrator="splitting", backend="numpy")
    sim.set_state("sphere", omega_b=(50.0, 0.0, 0.0))                 # 0.5 <= 1: accepted
    with pytest.raises(V.ValidityBoundError, match="validity bound"):
        sim.set_state("rod", omega_b=(50.0, 0.0, 0.0))                # 0.5 * 10 = 5 > 1


@needs_c
def test_float32_effect_rows_take_the_one_check():
    """simulate_f32 refuses an unknown code and a bad body through lv_effect_row_check, naming the row."""
    from lavendersim.backends import c_backend
    state = np.zeros((2, LY.STATE_SIZE), np.float32)
    state[:, LY.STATE_Q] = [0.0, 0.0, 0.0, 1.0]
    params = np.ones((2, LY.PARAM_SIZE), np.float32)
    ok = np.array([[5.0, -1.0, 0.4, 0, 0, 0, 0, 0]], np.float32)      # angular_damping (code 5) on every body
    assert c_backend._c.simulate_f32(state.copy(), params, ok, 0, 0, 0.01, 2)[0] == 0
    bad_code = ok.copy()
    bad_code[0, 0] = 9999.0
    with pytest.raises(ValueError, match=r"effects\[0\] code 9999"):
        c_backend._c.simulate_f32(state.copy(), params, bad_code, 0, 0, 0.01, 2)
    for body in (2.0, 0.5, -2.0):
        bad_body = ok.copy()
        bad_body[0, 1] = body
        with pytest.raises(ValueError, match=r"effects\[0\] body"):
            c_backend._c.simulate_f32(state.copy(), params, bad_body, 0, 0, 0.01, 2)
