"""The effect contract: one declaration per effect, printed for every backend; unknown effects are errors;
effects are indexed per body (a body depends on, and pays for, its own effects only)."""
from __future__ import annotations

import re
from pathlib import Path

import numpy as np
import pytest
import sympy as sp

import lavendersim as lv
from lavendersim import effects as E
from lavendersim.backends import c_backend, get, rhs_per_step
from lavendersim.errors import DivergenceError
from lavendersim.generated import effects_meta
from lavendersim.generated import kernels_numpy as K
from lavendersim.validate import LavenderInputError

from conftest import require

ROOT = Path(__file__).resolve().parent.parent
GEN = ROOT / "generated"
BACKENDS = ("c", "numpy")


class BodyTorque(lv.effects.Effect):
    """What a user might try without a declaration: a subclass with a new code."""
    name, code, fields = "body_torque", 42, ("tau_b",)


def one_body():
    s = lv.Scene()
    s.add_body(lv.Body.box("b", 1.0, (0.3, 0.2, 0.1)))
    return s


# ---------------------------------------------------------------- unknown effects are errors

@pytest.mark.parametrize("backend", BACKENDS)
def test_an_undeclared_effect_subclass_is_refused_by_sim(backend):
    s = one_body()
    s.add_effect(BodyTorque(body="b", tau_b=[0, 0, 1]))
    with pytest.raises(LavenderInputError, match=r"body_torque.*not a declared effect.*code 42.*derive --user") as e:
        lv.Sim(s, backend=backend)
    assert "body_torque" in e.value.field


@pytest.mark.parametrize("backend", BACKENDS)
def test_a_declared_name_with_another_code_is_refused(backend):
    class Fake(lv.effects.AppliedTorque):
        code = 77
    s = one_body()
    s.add_effect(Fake(body="b", torque_w=[0, 0, 1]))
    with pytest.raises(LavenderInputError, match="not a declared effect"):
        lv.Sim(s, backend=backend)


def test_both_backends_refuse_an_unknown_code_in_the_table():
    state = lv.Body.box("b", 1.0, (0.3, 0.2, 0.1), omega_b=(1, 2, 3)).x0[None].copy()
    params = np.array([[1.0, 0.1, 0.2, 0.25]])
    table = np.array([[42.0, -1, 0, 0, 1, 0, 0, 0]])
    before = state.copy()
    with pytest.raises(LavenderInputError, match="code 42 is not a declared force effect"):
        get("numpy").advance(state, params, table, "rk4", True, 1e-3, 5)
    with pytest.raises(ValueError, match=r"code 42\.0 is not a declared effect"):
        c_backend.CBackend().advance(state, params, table, "rk4", True, 1e-3, 5)
    for code in (E.USER_CODE_BASE + 500, 6, 0, 1.5):  # an unloaded user code, a model effect's code, none, not integral
        table[0, 0] = code
        with pytest.raises(ValueError):
            c_backend.CBackend().advance(state, params, table, "euler", True, 1e-3, 5)
    np.testing.assert_array_equal(state, before)


def test_the_generated_numpy_dispatch_refuses_unknown_codes():
    with pytest.raises(ValueError, match="not a built-in effect"):
        K.effect_apply(42, np.zeros((1, 6)), np.zeros((1, 13)), np.zeros((1, 3)), np.ones(1), np.ones((1, 3)))


# ---------------------------------------------------------------- one declaration, every printing

def test_codes_and_layout_come_from_the_declarations():
    from lavendersim.derive import all_effects

    decls = all_effects()
    meta = {e["name"]: e for e in effects_meta.EFFECTS}
    assert [d.name for d in decls] == list(meta)
    h = (GEN / "kernels.h").read_text()
    for code, d in enumerate(decls, start=1):
        assert meta[d.name]["code"] == code and E.EFFECTS[d.name].code == code
        if d.kind == "force":
            assert re.search(rf"#define LV_EFFECT_{d.name.upper()} {code}\b", h)
            assert K.EFFECT_APPLY_BY_CODE[code] is K.EFFECT_APPLY[d.name]
            assert meta[d.name]["flags"] == d.flags
        assert [p["offset"] for p in meta[d.name]["params"]] == list(d.offsets().values())
    # flags are read from the expressions: damping reads v or omega, gravity reads neither
    assert E.REGISTRY["linear_damping"].uses_v_w and E.REGISTRY["angular_damping"].velocity_dependent
    assert not E.REGISTRY["gravity"].velocity_dependent and E.REGISTRY["gravity"].state_inputs == ("m",)
    assert c_backend._c.EFFECT_ABI == effects_meta.ABI_VERSION and c_backend._c.EFFECT_USER_BASE == E.USER_CODE_BASE


def test_no_effect_code_or_dispatch_is_kept_by_hand():
    src = {p: p.read_text() for p in [ROOT / "lavendersim/csrc/step.c", ROOT / "lavendersim/csrc/step.h",
                                      ROOT / "lavendersim/csrc/module.c", ROOT / "lavendersim/backends/numpy_backend.py",
                                      ROOT / "lavendersim/backends/__init__.py", ROOT / "lavendersim/backends/c_backend.py",
                                      ROOT / "lavendersim/effects.py"]}
    for path, text in src.items():
        for d in effects_meta.EFFECTS:
            assert f"LV_EFFECT_{d['name'].upper()}" not in text, path
        assert not re.search(r"code\s*==\s*\d|case [1-5]:|isin\(codes|EFFECT_CODES", text), path
    step_c = src[ROOT / "lavendersim/csrc/step.c"]
    assert "switch ((int)row" not in step_c and "switch (code)" not in step_c  # dispatch: generated lv_effect_apply
    assert "elif code" not in src[ROOT / "lavendersim/backends/numpy_backend.py"]


def test_the_equations_are_printed_from_the_expressions(derivation):
    from lavendersim.derive.codegen import Printed, latex_of

    md = (GEN / "EQUATIONS.md").read_text()
    assert derivation.files["EQUATIONS.md"] == md
    kernels = {k.name: k for k in derivation.kernels}
    for name in ("effect_gravity", "effect_force_at_point", "rigid_body_rhs", "wheels4_body_rhs", "quat_to_euler_xyz"):
        assert f"$${latex_of(Printed(kernels[name]))}$$" in md, name
    grav = md.split("### `effect_gravity`")[1].split("###")[0]
    assert r"F_{com,w} = \left[\begin{matrix}g_{w,0} m\\g_{w,1} m\\g_{w,2} m\end{matrix}\right]" in grav
    assert "| `g_w` | [3] | m/s² | finite | `(0.0, 0.0, -9.81)` | 0 |" in grav


# ---------------------------------------------------------------- the printer

def test_half_integer_powers_print_without_pow_and_their_base_once():
    from lavendersim.derive.codegen import CPrinter, NpPrinter, Printed
    from lavendersim.derive.kernel import Arg, Kernel, scalar, vec

    x = sp.Symbol("x", positive=True)
    assert CPrinter().doprint(x ** sp.Rational(5, 2)) == "(x*x*sqrt(x))"
    assert CPrinter().doprint(x ** sp.Rational(-3, 2)) == "(1.0/(x*sqrt(x)))"
    assert NpPrinter().doprint(x ** sp.Rational(3, 2)) == "(x*numpy.sqrt(x))"
    r, mu = vec("r", 3), scalar("mu")
    d2 = r.dot(r)
    k = Kernel("half_power_check", "test", "", [Arg("r", r, "r"), Arg("mu", mu, "mu")],
               [Arg("out", sp.Matrix([mu * r[0] * d2 ** sp.Rational(-5, 2)]), "out")])
    from lavendersim.derive.codegen import print_c

    _, c = print_c([Printed(k)])
    body = c.split("void lv_half_power_check")[1].split("}")[0]
    assert "pow(" not in body and body.count("r_0*r_0") == 1 and body.count("sqrt(") == 1, body


# ---------------------------------------------------------------- per-body index

def mixed_scene(bodies=range(21)):
    """Free bodies, torque-only bodies, bodies with forces, every-body effects, effects in table order."""
    s = lv.Scene()
    names = [f"b{i}" for i in bodies]
    for i in bodies:
        s.add_body(lv.Body.box(f"b{i}", 1.0 + 0.1 * i, (0.3, 0.2, 0.1 + 0.01 * i), q=(0.1 * i, 0.2, 0.3, 0.9),
                               omega_b=(1.0, 0.5 - 0.1 * i, 0.2), v_w=(0.1 * i, 0, 0)))
    table = [("angular_damping", None, dict(c=1e-3))]
    for i in bodies:
        if i % 4 == 1:
            table.append(("applied_torque", f"b{i}", dict(torque_w=[0.01 * i, -0.02, 0.03])))
        elif i % 4 == 2:
            table.append(("gravity", f"b{i}", {}))
            table.append(("force_at_point", f"b{i}", dict(r_b=[0.1, 0, 0], F_w=[0, 0.5, 0.1 * i])))
        elif i % 4 == 3 and i % 3 == 0:
            table.append(("linear_damping", f"b{i}", dict(c=0.05)))
    table.append(("applied_torque", None, dict(torque_w=[1e-3, 0, 0])))
    for name, body, params in table:
        if body is None or body in names:
            s.add_effect(name, body=body, **params)
    return s


@pytest.mark.parametrize("integrator", ["euler", "semi_implicit_euler", "rk4", "splitting", "implicit_gyro"])
def test_each_body_depends_on_its_own_effects_only_and_backends_agree_bitwise(integrator):
    full = {}
    for backend in BACKENDS:
        sim = lv.Sim(mixed_scene(), dt=1e-3, integrator=integrator, backend=backend)
        sim.run(150)  # more than one finiteness chunk of the lockstep path
        full[backend] = sim.x.copy()
    assert np.array_equal(full["c"], full["numpy"])
    for i in (0, 1, 2, 3, 9, 20):  # the same body alone, with the effects that act on it
        alone = lv.Sim(mixed_scene([i]), dt=1e-3, integrator=integrator, backend="c")
        alone.run(150)
        assert np.array_equal(alone.x[0], full["c"][i]), i


def test_gathering_keeps_the_divergence_order():
    # body 0 has an effect (generic group), body 1 is free (torque-free group, visited first): both
    # overflow at the same step; the lower body is reported, as NumPy does
    s = lv.Scene()
    for i in range(2):
        s.add_body(lv.Body.box(f"b{i}", 1.0, (0.3, 0.2, 0.1), omega_b=(3e153, 2e153, 1e153)))
    s.add_effect("applied_torque", body="b0", torque_w=[0, 0, 1e-9])
    errs = {}
    for backend in BACKENDS:
        sim = lv.Sim(s, dt=1e-3, integrator="rk4", backend=backend)
        x0 = sim.x.copy()
        with pytest.raises(DivergenceError) as e:
            sim.run(500)
        errs[backend] = (e.value.step, e.value.body)
        assert np.array_equal(sim.x, x0)
    assert errs["c"] == errs["numpy"] and errs["c"][1] == 0


def test_splitting_counts_midpoint_kicks_from_the_declarations():
    table = lambda *effs: np.array([E.make(n, **p).row(-1) for n, p in effs])  # noqa: E731
    assert rhs_per_step("splitting", table(("gravity", {})), 1) == 2
    assert rhs_per_step("splitting", table(("gravity", {}), ("angular_damping", {"c": 0.1})), 1) == 4
    assert rhs_per_step("rk4", table(("angular_damping", {"c": 0.1})), 1) == 4


def test_rows_grow_for_an_effect_with_many_parameters(tmp_path):
    from lavendersim import extending

    require("cc")
    decl = tmp_path / "wide_effects.py"
    decl.write_text(
        "from lavendersim.derive.effect import STATE, effect, param\n"
        "a = param('a', 3, 'N·m', 'first torque')\n"
        "b = param('b', 3, 'N·m', 'second torque')\n"
        "k = param('k', (), '', 'scale', rule='positive')\n"
        "EFFECTS = [effect('wide_torque', 'k (a + b), world', params=[a, b, k], torque_w=k.symbol * (a.symbol + b.symbol))]\n")
    extending.derive(decl, out=tmp_path / "sets")
    out = {}
    for backend in BACKENDS:
        s = one_body()
        s.add_effect("wide_torque", body="b", a=[0, 0, 1], b=[0, 1, 0], k=2.0)
        sim = lv.Sim(s, dt=1e-3, backend=backend)
        assert sim.effects.shape == (1, 2 + 7)
        sim.run(10)
        out[backend] = sim.x.copy()
    ref = one_body()
    ref.add_effect("applied_torque", body="b", torque_w=[0, 2, 2])
    r = lv.Sim(ref, dt=1e-3, backend="numpy")
    r.run(10)
    assert np.array_equal(out["c"], out["numpy"]) and np.allclose(out["c"], r.x, rtol=1e-14, atol=1e-15)
