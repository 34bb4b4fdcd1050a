"""docs/extending.md section 6 followed literally: a user's explicit Runge–Kutta tableau (Kutta's third-order method).

The declaration file, the command and the usage script are the guide's own code blocks (```python my_methods.py,
```bash my_methods, ```python use_kutta3.py), run in a temporary folder with LAVENDERSIM_USER_DIR set to it. The
Sim's runs on both backends, with effects, are compared with an independent Kutta3 written here (plain Python
floats, to 1e-13); bad declarations are refused with their one-line messages, an order the tableau does not have
among them; the derived bounds reproduce the built-ins' rules.
"""
from __future__ import annotations

import json
import math
import os
import pickle
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import sympy as sp

import lavendersim as lv
from lavendersim import backends as B
from lavendersim import extending
from lavendersim.derive.tableaux import _real_axis_limit, _stability_polynomial
from lavendersim.derive.user import DeclarationError, imaginary_axis_bound
from lavendersim.generated import layout as LY
from lavendersim.generated import tableaux as TB
from lavendersim.validate import LavenderInputError

from guide_steps import followed, guide_block, run_lavendersim  # noqa: E402

pytestmark = pytest.mark.needs("cc")  # the guide's command compiles the set's C (its tableau's doubles)

TOL = 1e-13


@pytest.fixture(scope="module")
def guide(tmp_path_factory):
    """The section's first two steps: write my_methods.py, run the documented command."""
    with followed(tmp_path_factory.mktemp("tableau_guide"), "my_methods.py", "bash my_methods") as g:
        yield g
        for name in [n for n, t in B.USER_TABLEAUX.items() if t.source.startswith(str(g["user"]))]:
            del B.USER_TABLEAUX[name]


def guide_scene() -> lv.Scene:
    """The scene of use_kutta3.py (the script itself runs in test_the_guides_script_runs)."""
    scene = lv.Scene()
    scene.add_body(lv.Body.box("brick", 2.0, (0.3, 0.2, 0.1), omega_b=(0.3, 1.0, 0.2), v_w=(1.0, 0.0, 2.0)))
    scene.add_effect("gravity", g_w=(0.0, 0.0, -9.81))
    scene.add_effect("angular_damping", body="brick", c=0.01)
    return scene


# ---------------------------------------------------------------- an independent Kutta3 (plain Python floats)

def f(state, m, I, g_w, c):
    """d/dt of [p_w, q, v_w, omega_b] under gravity g_w and angular_damping's torque tau_B = -c omega_B.

    The body's only torque is declared in the body frame, so it is taken so (nothing rotated); its world form
    R^T(-c R omega_B) equals it on the unit sphere only, and the stage states' q are not unit."""
    q, v, w = state[3:7], state[7:10], state[10:13]
    tau_b = [-c * w[i] for i in range(3)]
    x, y, z, s = q
    q_dot = [0.5 * (s * w[0] + y * w[2] - z * w[1]), 0.5 * (s * w[1] + z * w[0] - x * w[2]),
             0.5 * (s * w[2] + x * w[1] - y * w[0]), -0.5 * (x * w[0] + y * w[1] + z * w[2])]
    Iw = [I[i] * w[i] for i in range(3)]
    gyro = [w[1] * Iw[2] - w[2] * Iw[1], w[2] * Iw[0] - w[0] * Iw[2], w[0] * Iw[1] - w[1] * Iw[0]]
    return list(v) + q_dot + list(g_w) + [(tau_b[i] - gyro[i]) / I[i] for i in range(3)]


def kutta3(state, dt, n, *args):
    """Kutta (1901): k1 = f(x), k2 = f(x + h k1/2), k3 = f(x + h(-k1 + 2 k2)), x + h(k1 + 4 k2 + k3)/6; q normalized."""
    x = list(state)
    for _ in range(n):
        k1 = f(x, *args)
        k2 = f([a + dt * k / 2 for a, k in zip(x, k1)], *args)
        k3 = f([a + dt * (2 * l - k) for a, k, l in zip(x, k1, k2)], *args)
        x = [a + dt * (k + 4 * l + r) / 6 for a, k, l, r in zip(x, k1, k2, k3)]
        norm = math.sqrt(sum(v * v for v in x[3:7]))
        x[3:7] = [v / norm for v in x[3:7]]
    return np.array(x)


# ---------------------------------------------------------------- the guide

def test_the_command_derives_the_tableau_once_for_c_and_python(guide):
    s = extending.load(guide["set"])
    assert s.tableau_names == ["kutta3"] and s.manifest["tableaux"] == ["kutta3"]
    (t,) = s.tableaux
    assert t["order"] == 3 and t["exact"]["b"] == ("1/6", "2/3", "1/6")
    assert t["A"] == ((0.0, 0.0, 0.0), (0.5, 0.0, 0.0), (-1.0, 2.0, 0.0)) and t["b"] == (1 / 6, 2 / 3, 1 / 6)
    c_text = (guide["set"] / "kernels.c").read_text()
    assert "lvu_tableau_kutta3[15] = {0.0, 0.5, 1.0, 0.0, 0.0, 0.0, 0.5, 0.0, 0.0, -1.0, 2.0, 0.0, " \
           f"{1 / 6!r}, {2 / 3!r}, {1 / 6!r}}};" in c_text
    s.library()   # loading checks the library's lvu_tableau_kutta3 against effects_meta's doubles
    tab = extending.tableau("kutta3")
    assert B.tableau_of("kutta3") is tab and tab.order == 3 and tab.stages == 3
    np.testing.assert_array_equal(tab.c, [0.0, 0.5, 1.0])
    assert "### kutta3" in (guide["set"] / "EQUATIONS.md").read_text()


def test_the_guides_script_runs(guide):
    (guide["work"] / "use_kutta3.py").write_text(guide_block("python use_kutta3.py"), encoding="utf-8")
    r = subprocess.run([sys.executable, "use_kutta3.py"], cwd=guide["work"], env=guide["env"], capture_output=True,
                       text=True)
    assert r.returncode == 0, r.stdout + r.stderr
    lines = r.stdout.splitlines()
    assert lines[0].startswith("c [") and lines[1].startswith("numpy [") and lines[2].startswith("kutta3: 3 RHS")
    assert lines[0][2:] == lines[1][6:]      # the same numbers, as printed


@pytest.mark.parametrize("backend", ["c", "numpy"])
def test_kutta3_against_an_independent_implementation(guide, backend):
    sim = lv.Sim(guide_scene(), dt=0.01, integrator="kutta3", backend=backend)
    x0 = sim.x.copy()[0]
    m, I = float(sim.params[0, LY.PARAM_M]), [float(v) for v in sim.params[0, LY.PARAM_I_B]]
    sim.run(200)
    ref = kutta3(x0, 0.01, 200, m, I, (0.0, 0.0, -9.81), 0.01)
    assert np.max(np.abs(sim.x[0] - ref) / np.maximum(1.0, np.abs(ref))) <= TOL
    assert np.max(np.abs(sim.x[0] - x0)) > 1.0                 # it moved: the comparison can fail
    rk4 = lv.Sim(guide_scene(), dt=0.01, integrator="rk4", backend=backend)
    rk4.run(200)
    assert np.max(np.abs(sim.x[0] - rk4.x[0])) > 1e-9          # and it is not rk4 under another name
    assert sim.pipeline[0].startswith("kutta3: 3 RHS evaluations per step")


def test_the_backends_agree(guide):
    runs = []
    for backend in ("c", "numpy"):
        sim = lv.Sim(guide_scene(), dt=0.01, integrator="kutta3", backend=backend)
        sim.run(300)
        runs.append(sim.x.copy())
    assert np.max(np.abs(runs[0] - runs[1]) / np.maximum(1.0, np.abs(runs[1]))) <= 1e-14


def test_a_sim_with_the_tableau_pickles(guide):
    sim = lv.Sim(guide_scene(), dt=0.01, integrator="kutta3", backend="numpy")
    sim.run(10)
    again = pickle.loads(pickle.dumps(sim))
    assert again.integrator == "kutta3"
    again.run(5)
    sim.run(5)
    np.testing.assert_array_equal(again.x, sim.x)


def test_what_sim_refuses_with_it(guide):
    with pytest.raises(LavenderInputError, match=r"dtype: float32 steps .* not 'kutta3'"):
        lv.Sim(guide_scene(), dt=0.01, integrator="kutta3", backend="numpy", dtype="float32")
    with pytest.raises(LavenderInputError, match=r"rtol: applies to the adaptive integrators .* 'kutta3' uses the fixed"):
        lv.Sim(guide_scene(), dt=0.01, integrator="kutta3", backend="numpy", rtol=1e-8)
    with pytest.raises(LavenderInputError, match=r"integrator: unknown name 'kutta4'.*kutta3"):
        lv.Sim(guide_scene(), dt=0.01, integrator="kutta4", backend="numpy")


def test_its_validity_bounds_are_the_sims(guide):
    from lavendersim.sim import validity_bound

    assert validity_bound("kutta3") == (pytest.approx(math.sqrt(3), rel=1e-14), 0.0)
    tab = extending.tableau("kutta3")
    assert tab.real_axis == pytest.approx(2.5127453266183286, rel=1e-14)   # 1 - x + x²/2 - x³/6 = -1
    scene = lv.Scene()
    scene.add_body(lv.Body("fast", 1.0, (1.0, 1.0, 1.0), omega_b=(0.0, 0.0, 200.0)))   # |omega| dt = 2 > sqrt(3)
    sim = lv.Sim(scene, dt=0.01, integrator="kutta3", backend="numpy")
    with pytest.raises(lv.DivergenceError, match=r"kutta3's validity bound 1\.73"):
        sim.run(1)
    lv.Sim(scene, dt=0.01, integrator="rk4", backend="numpy").run(1)   # within rk4's 2 sqrt(2)


def test_the_bound_rules_reproduce_the_builtins():
    R = sp.Rational
    rk4 = _stability_polynomial([[], [R(1, 2)], [0, R(1, 2)], [0, 0, 1]], [R(1, 6), R(1, 3), R(1, 3), R(1, 6)])
    euler = 1 + sp.Symbol("z")
    assert imaginary_axis_bound(rk4) == pytest.approx(float(TB.WDT_MAX["rk4"]), rel=1e-14)
    assert imaginary_axis_bound(euler) == pytest.approx(float(TB.WDT_MAX["euler"]), rel=1e-14)
    assert _real_axis_limit(rk4) == pytest.approx(TB.REAL_AXIS_STABILITY["rk4"], rel=1e-14)


# ---------------------------------------------------------------- bad declarations

KUTTA3 = 'A=[[], ["1/2"], [-1, 2]], b=["1/6", "2/3", "1/6"], order=3'
BAD = [
    ('tableau("kutta3", A=[[], ["1/2"], [-1, 2]], b=["1/6", "2/3", "1/6"], order=4)',
     "tableau 'kutta3' declares order 4, but an order-4 condition fails: Σ b_i (c·A(c))_i = 1/6, must be 1/8 "
     "(it has order 3)"),
    ('tableau("k", A=[[0, 0, 0], ["1/2", "1/2", 0], [-1, 2, 0]], b=["1/6", "2/3", "1/6"], order=3)',
     "tableau 'k': A must be strictly lower triangular (an explicit method), but A[1][1] = 1/2 (j >= i)"),
    ('tableau("k", A=[[], ["1/2"]], b=["1/6", "2/3", "1/6"], order=3)',
     "tableau 'k': A must be a list of 3 rows (one per stage, as b has 3 weights), got 2"),
    ('tableau("k", A=[[], ["1/2"], [-1]], b=["1/6", "2/3", "1/6"], order=3)',
     "tableau 'k': A[2] must list its 2 entries left of the diagonal (or all 3), got 1"),
    ('tableau("k", c=[0, "0.4", 1], ' + KUTTA3 + ')',
     "tableau 'k': c[1] = 2/5, but the sum of A[1] is 1/2 (c_i = Σ_j A_ij)"),
    ('tableau("k", A=[[], ["1/2"], [-1, 2]], b=["1/6", "2/3", float("nan")], order=3)',
     "tableau 'k': b[2] must be finite, got nan"),
    ('tableau("k", A=[[], ["1/2"], [-1, "two"]], b=["1/6", "2/3", "1/6"], order=3)',
     "tableau 'k': A[2][1] = 'two' is not a rational like '1/6' or '0.25'"),
    ('tableau("k", ' + KUTTA3.replace("order=3", "order=0") + ')', "tableau 'k': order must be an integer 1 … 8, got 0"),
    ('tableau("rk4", ' + KUTTA3 + ')', "tableau 'rk4' is the name of a built-in integrator; rename it"),
    ('tableau("Kutta", ' + KUTTA3 + ')',
     "tableau name must be lowercase letters, digits and _, starting with a letter, got 'Kutta'"),
]


def declare(folder: Path, body: str, name: str = "bad_methods") -> Path:
    path = folder / f"{name}.py"
    path.write_text(f"from lavendersim.derive.user import tableau\n\nTABLEAUX = [\n    {body},\n]\n", encoding="utf-8")
    return path


@pytest.mark.parametrize("body,message", BAD, ids=[m.split(": ", 1)[-1][:24] for _, m in BAD])
def test_a_bad_declaration_is_refused_naming_the_field_and_the_rule(tmp_path, body, message):
    path = declare(tmp_path, body)
    with pytest.raises(DeclarationError) as e:
        extending.derive(path, out=tmp_path / "sets", compile=False)
    assert str(e.value) == f"{path} line 4: {message}"
    assert not (tmp_path / "sets" / "bad_methods").exists()


def test_a_claimed_order_the_tableau_does_not_have_is_refused(tmp_path):
    """Heun's method (order 2) claimed as order 3, exactly and with float coefficients; the same at order 2 passes."""
    exact = declare(tmp_path, 'tableau("heun", A=[[], [1]], b=["1/2", "1/2"], order=3)', "heun_exact")
    with pytest.raises(DeclarationError, match=r"tableau 'heun' declares order 3, but an order-3 condition fails: "
                                               r"Σ b_i \(c\^2\)_i = 1/2, must be 1/3 \(it has order 2\)"):
        extending.derive(exact, out=tmp_path / "sets", compile=False)
    floats = declare(tmp_path, 'tableau("heun", A=[[], [1.0]], b=[0.5, 0.5], order=3)', "heun_floats")
    with pytest.raises(DeclarationError, match=r"order-3 condition fails: Σ b_i \(c\^2\)_i = 0\.5, must be 1/3"):
        extending.derive(floats, out=tmp_path / "sets", compile=False)
    ok = declare(tmp_path, 'tableau("heun", A=[[], [1.0]], b=[0.5, 0.5], order=2)', "heun_ok")
    s = extending.derive(ok, out=tmp_path / "sets", compile=False)
    try:
        assert s.tableau_names == ["heun"] and B.tableau_of("heun").order == 2
        assert B.tableau_of("heun").wdt_max == pytest.approx(0.2 ** 0.5, rel=1e-12)   # |R(iy)|² = 1 + y⁴/4 = 1.01
    finally:
        del B.USER_TABLEAUX["heun"]


def test_the_command_refuses_in_one_line(tmp_path):
    path = declare(tmp_path, 'tableau("k", A=[[], ["1/2"], [-1, 2]], b=["1/6", "2/3", "1/6"], order=4)')
    r = run_lavendersim(["derive", "--user", str(path), "--out", str(tmp_path / "sets")], tmp_path, dict(os.environ))
    assert r.returncode == 2 and r.stdout == ""
    assert len(r.stderr.strip().splitlines()) == 1 and "declares order 4, but an order-4 condition fails" in r.stderr


def test_a_tableau_name_another_set_declares_is_refused_naming_both(guide, tmp_path):
    other = declare(tmp_path, 'tableau("kutta3", ' + KUTTA3 + ')', "other_methods")
    with pytest.raises(extending.UserSetError) as e:
        extending.derive(other, out=guide["user"] / "sets", compile=False)
    assert "tableau 'kutta3'" in str(e.value) and str(other) in str(e.value) and "my_methods.py" in str(e.value)


def test_deriving_again_replaces_the_sets_tableaux(tmp_path):
    two = 'tableau("mid2", A=[[], ["1/2"]], b=[0, 1], order=2),\n    tableau("heun2", A=[[], [1]], b=["1/2", "1/2"], order=2)'
    path = declare(tmp_path, two, "pair")
    extending.derive(path, out=tmp_path / "sets", compile=False)
    try:
        assert {"mid2", "heun2"} <= set(B.USER_TABLEAUX)
        declare(tmp_path, 'tableau("mid2", A=[[], ["1/2"]], b=[0, 1], order=2, summary="again")', "pair")
        extending.derive(path, out=tmp_path / "sets", compile=False)
        assert "heun2" not in B.USER_TABLEAUX and "mid2" in B.USER_TABLEAUX   # the set's tableaux, as derived now
    finally:
        for n in ("mid2", "heun2"):
            B.USER_TABLEAUX.pop(n, None)


BESIDE = '''"""An effect and a tableau in one declaration file."""
from lavendersim.derive.effect import STATE, effect, param
from lavendersim.derive.user import tableau

k = param("k", unit="N·m·s", doc="drag on the spin", rule="nonnegative")
EFFECTS = [effect("tabtest_spin_drag", "A torque -k omega_w", params=[k], torque_w=-k.symbol * STATE.omega_w)]
TABLEAUX = [tableau("tabtest_ralston3", A=[[], ["1/2"], [0, "3/4"]], b=["2/9", "1/3", "4/9"], order=3,
                    summary="Ralston's third-order method")]
'''


@pytest.fixture(scope="module")
def beside(tmp_path_factory):
    """BESIDE derived (outside the user directory) once for the module; its tableau unregistered after."""
    work = tmp_path_factory.mktemp("beside")
    (work / "beside.py").write_text(BESIDE, encoding="utf-8")
    yield extending.derive(work / "beside.py", out=work / "sets")
    B.USER_TABLEAUX.pop("tabtest_ralston3", None)


@pytest.mark.parametrize("backend", ["numpy", "c"])
def test_a_tableau_beside_a_user_effect_in_one_file(beside, backend):
    """The set's tableau steps the set's effect: the same run as with the built-in angular_damping (the same law).

    A zero applied torque beside it keeps both in the world frame (the built-in then adds its world form R_WB tau_B):
    alone, the built-in would take tau_B = -c omega_B in the body frame, exact where the world form on the
    unnormalized stage quaternions is not (the two runs then differ by ~8e-9 here)."""
    assert beside.effect_names == ["tabtest_spin_drag"] and beside.tableau_names == ["tabtest_ralston3"]
    B.USER_TABLEAUX.pop("tabtest_ralston3", None)   # found again through the opened set (outside the user directory)
    runs = []
    for name, kw in (("tabtest_spin_drag", {"k": 0.05}), ("angular_damping", {"c": 0.05})):
        scene = lv.Scene()
        scene.add_body(lv.Body("b", 1.5, (0.2, 0.3, 0.4), omega_b=(1.0, -2.0, 0.5)))
        scene.add_effect(name, body="b", **kw)
        scene.add_effect("applied_torque", body="b", torque_w=(0.0, 0.0, 0.0))
        sim = lv.Sim(scene, dt=0.01, integrator="tabtest_ralston3", backend=backend)
        sim.run(100)
        runs.append(sim.x.copy())
    assert B.tableau_of("tabtest_ralston3").source == str(beside.directory)
    np.testing.assert_allclose(runs[0], runs[1], rtol=1e-14, atol=1e-15)
    assert np.max(np.abs(runs[0][0, LY.STATE_OMEGA_B] - (1.0, -2.0, 0.5))) > 0.05   # the drag acted


def test_the_accuracy_lab_measures_it_with_its_declared_order(guide):
    """lab accuracy's integrators=[...] (the CLI's --integrators): kutta3's slope is checked against its declared 3;
    the same coefficients registered claiming order 4 (bypassing derive) fail that check."""
    from lavendersim.labs import accuracy

    k3 = extending.tableau("kutta3")
    B.USER_TABLEAUX["tabtest_k3_claims4"] = B.Tableau("tabtest_k3_claims4", k3.c, k3.A, k3.b, 4, "tests",
                                                      real_axis=k3.real_axis, wdt_max=k3.wdt_max)
    try:
        r = accuracy.compute("auto", quick=True, mujoco=False, workers=1, integrators=["kutta3", "tabtest_k3_claims4"])
    finally:
        del B.USER_TABLEAUX["tabtest_k3_claims4"]
    checks = {c.name: c for c in r.checks}
    orders = [c for n, c in checks.items() if n.startswith("order_kutta3_")]
    assert len(orders) == 2 and all(c.passed and abs(c.value - 3.0) < 0.1 for c in orders)
    assert all(c.passed for n, c in checks.items() if n.startswith("backends_agree_kutta3_"))
    wrong = [c for n, c in checks.items() if n.startswith("order_tabtest_k3_claims4_")]
    assert len(wrong) == 2 and not any(c.passed for c in wrong)
    with pytest.raises(LavenderInputError, match="kutta4"):
        accuracy.compute("auto", quick=True, mujoco=False, workers=1, integrators=["kutta4"])


# slow set: the whole quick accuracy lab again in a subprocess (28 s when loaded); in-process the lab measures
# the tableau (test_the_accuracy_lab_measures_it_with_its_declared_order) and the option reaches compute
# (test_cli_conventions.py::test_lab_accuracy_integrators_reach_compute)
@pytest.mark.slow
def test_lab_accuracy_takes_it_on_the_command_line(guide, tmp_path):
    """`lavendersim lab accuracy --integrators kutta3` (the guide's sentence), quick, as a user runs it."""
    r = run_lavendersim(["lab", "accuracy", "--quick", "--no-mujoco", "--workers", "1", "--integrators", "kutta3",
                         "--json", "--out", str(tmp_path)], guide["work"], guide["env"])
    assert r.returncode == 0, r.stderr
    d = json.loads(r.stdout)
    assert d["integrators"] == "kutta3" and d["passed"] is True
    assert d["check_order_kutta3_box_w1"] is True and abs(d["order_kutta3_c_box_w1"] - 3.0) < 0.1
    bad = run_lavendersim(["lab", "accuracy", "--quick", "--integrators", "kutta4", "--out", str(tmp_path)],
                          guide["work"], guide["env"])
    assert bad.returncode == 2 and len(bad.stderr.strip().splitlines()) == 1 and "kutta4" in bad.stderr


def test_loading_a_second_set_with_the_same_tableau_name_is_refused(guide, tmp_path):
    """Derived elsewhere (--out: no other set there to compare with), the clash is found when the set loads, before
    anything of it is registered (its effect neither)."""
    from lavendersim import effects as E

    extending.tableau("kutta3")
    other = tmp_path / "elsewhere_methods.py"
    other.write_text(BESIDE.replace("tabtest_spin_drag", "tabtest_elsewhere_drag").replace(
        'tableau("tabtest_ralston3", A=[[], ["1/2"], [0, "3/4"]], b=["2/9", "1/3", "4/9"]', 'tableau("kutta3", '
        + KUTTA3.replace(", order=3", "")), encoding="utf-8")
    with pytest.raises(extending.UserSetError, match=r"tableau 'kutta3' is declared by .*elsewhere_methods\.py .* and by "
                                                     r"the set .*my_methods, loaded first"):
        extending.derive(other, out=tmp_path / "sets", compile=False)
    assert B.tableau_of("kutta3").source == str(guide["set"].resolve())   # the first stays
    assert "tabtest_elsewhere_drag" not in E.REGISTRY                      # nothing of the refused set
