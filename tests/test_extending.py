"""docs/extending.md followed literally in a temporary folder.

The declaration file and the usage script are the guide's own code blocks (```python my_effects.py,
```python use_effects.py) and the command is its ```bash block, run with LAVENDERSIM_USER_DIR set to
the temporary folder. The user effects are then checked against independent NumPy formulas written
here (to 1e-12), through C (the compiled functions, and stepping) and NumPy, with every integrator,
and through CasADi when it is installed.
"""
from __future__ import annotations

import ctypes
import re
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

import lavendersim as lv
from lavendersim import effects as E
from lavendersim.generated import layout as LY
from lavendersim import extending
from lavendersim.validate import LavenderInputError

from conftest import have, require
from guide_steps import followed, guide_block, run_lavendersim

pytestmark = pytest.mark.needs("cc")  # the guide's command compiles the C of the set

INTEGRATORS = ("euler", "semi_implicit_euler", "rk4", "dopri5", "splitting", "implicit_gyro", "splitting4", "rk4_expmap",
               "symtop4")
RTOL = 1e-12


@pytest.fixture(scope="module")
def guide(tmp_path_factory):
    """The guide's steps 1 and 2: write my_effects.py, run the documented command."""
    with followed(tmp_path_factory.mktemp("guide"), "my_effects.py", "bash") as g:
        # nothing on stderr when all is well (a derive-time RuntimeWarning was printed once)
        assert g["run"].stderr == ""
        yield g


# ---------------------------------------------------------------- independent formulas (NumPy, written here)

def rot(q):
    x, y, z, w = q / np.linalg.norm(q)
    return np.array([[1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
                     [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
                     [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)]])


def gravity_gradient_w(p_w, q, I_b, mu, center_w):
    R = rot(q)
    r_b = R.T @ (np.asarray(p_w) - np.asarray(center_w))
    r = np.linalg.norm(r_b)
    n = r_b / r
    return R @ (3 * mu / r**3 * np.cross(n, I_b * n))


def quadratic_drag_w(v_w, rho, cd_area):
    v = np.asarray(v_w)
    return -0.5 * rho * cd_area * np.linalg.norm(v) * v


MU, CENTER = 2.0, np.array([0.1, 0.2, -0.3])
RHO, CDA = 1.2, 0.05


def hand_rk4(x, I_b, dt, n, a_w=lambda v_w: np.zeros(3)):
    """Classic RK4 of one rigid body under the guide's gravity gradient (MU, CENTER) and the COM acceleration
    a_w(v_w), q normalized after each step (as the Sim): an independent NumPy oracle."""
    def f(y):
        q = y[3:7]
        w = y[10:13]
        tau_b = rot(q).T @ gravity_gradient_w(y[0:3], q, I_b, MU, CENTER)
        qw = np.array([q[3] * w[0] + q[1] * w[2] - q[2] * w[1], q[3] * w[1] + q[2] * w[0] - q[0] * w[2],
                       q[3] * w[2] + q[0] * w[1] - q[1] * w[0], -q[0] * w[0] - q[1] * w[1] - q[2] * w[2]]) / 2
        wd = (tau_b - np.cross(w, I_b * w)) / I_b
        return np.concatenate([y[7:10], qw, a_w(y[7:10]), wd])
    for _ in range(n):
        k1 = f(x)
        k2 = f(x + dt / 2 * k1)
        k3 = f(x + dt / 2 * k2)
        k4 = f(x + dt * k3)
        x = x + dt / 6 * (k1 + 2 * k2 + 2 * k3 + k4)
        x[3:7] /= np.linalg.norm(x[3:7])
    return x


def reference_rk4(x, m, I_b, dt, n):
    """RK4 of the rigid body under both user effects (gravity gradient, quadratic drag)."""
    return hand_rk4(x, I_b, dt, n, lambda v_w: quadratic_drag_w(v_w, RHO, CDA) / m)


def make_scene(extra_free: bool = False):
    s = lv.Scene()
    s.add_body(lv.Body.box("sat", 3.0, (0.6, 0.3, 0.2), p_w=(2.0, 0.5, -0.3), q=(0.1, 0.2, 0.3, 0.9),
                           v_w=(3.0, -1.0, 2.0), omega_b=(0.3, -0.2, 0.5)))
    if extra_free:
        s.add_body(lv.Body.sphere("ball", 1.0, 0.1, omega_b=(1, 2, 3)))
    s.add_effect("gravity_gradient", body="sat", mu=MU, center_w=CENTER)
    s.add_effect("quadratic_drag", body="sat", rho=RHO, cd_area=CDA)
    return s


def close(a, b, rtol=RTOL):
    a, b = np.asarray(a, float), np.asarray(b, float)
    return np.max(np.abs(a - b)) <= rtol * max(1.0, float(np.max(np.abs(b))))


# ---------------------------------------------------------------- step 2: the command

def test_command_prints_the_set_and_compiles_it(guide):
    d = guide["set"]
    for name in ("kernels.c", "kernels.h", "kernels_numpy.py", "kernels_casadi.py", "effects_meta.py", "EQUATIONS.md"):
        assert (d / name).is_file(), name
    libs = list((d / "build").glob("libmy_effects-*.so"))
    assert len(libs) == 1
    out = guide["run"].stdout
    assert "gravity_gradient" in out and "quadratic_drag" in out and "inertia_cone" in out
    md = (d / "EQUATIONS.md").read_text()
    assert "### `effect_gravity_gradient`" in md and "| `mu` | scalar | m³/s² | positive |" in md
    c = (d / "kernels.c").read_text()
    assert "pow(" not in c and "sqrt(" in c  # |r|^-5 printed as 1/(r2*r2*sqrt(r2))


def test_running_the_command_again_compiles_nothing(guide):
    lib = next((guide["set"] / "build").glob("libmy_effects-*.so"))
    before = lib.stat().st_mtime_ns
    r = run_lavendersim(guide["cmd"][1:], guide["work"], guide["env"])
    assert r.returncode == 0, r.stderr
    assert "cached" in r.stdout
    assert lib.stat().st_mtime_ns == before and len(list(lib.parent.glob("*.so"))) == 1


# ---------------------------------------------------------------- step 3: the guide's script, then numbers

def test_the_guides_script_runs(guide):
    (guide["work"] / "use_effects.py").write_text(guide_block("python use_effects.py"), encoding="utf-8")
    r = subprocess.run([sys.executable, "use_effects.py"], cwd=guide["work"], env=guide["env"], capture_output=True, text=True)
    assert r.returncode == 0, r.stderr
    lines = r.stdout.splitlines()
    c = np.array(re.findall(r"[-+0-9.e]+", lines[0][2:]), float)
    n = np.array(re.findall(r"[-+0-9.e]+", lines[1][6:]), float)
    assert lines[0].startswith("c ") and lines[1].startswith("numpy ") and close(c, n, 1e-6)
    assert any("gravity_gradient(mu=" in line and "quadratic_drag(rho=" in line for line in lines)


def test_found_by_name_in_the_user_directory(guide):
    s = make_scene()
    assert {type(e).__name__ for e in s.effects} == {"GravityGradient", "QuadraticDrag"}
    spec = E.EFFECTS["gravity_gradient"].spec
    assert spec.code >= E.USER_CODE_BASE and spec.state_inputs == ("p_w", "q", "I_b") and not spec.velocity_dependent
    assert E.EFFECTS["quadratic_drag"].spec.velocity_dependent and E.EFFECTS["quadratic_drag"].spec.uses_v_w
    assert np.array_equal(s.effects[0].values["center_w"], CENTER)
    s.add_effect("gravity_gradient", body="sat", mu=1.0)  # the declared default
    assert np.array_equal(s.effects[-1].values["center_w"], [0, 0, 0])


@pytest.mark.parametrize("params,field", [(dict(mu=-1.0), "gravity_gradient.mu"), (dict(mu=1.0, center_w=[0, 0]),
                                          "gravity_gradient.center_w"), (dict(), "gravity_gradient.mu"),
                                          (dict(mu=1.0, radius=2), "gravity_gradient.radius")])
def test_parameters_are_validated_by_their_declared_rules(guide, params, field):
    s = make_scene()
    with pytest.raises(LavenderInputError) as e:
        s.add_effect("gravity_gradient", body="sat", **params)
    assert e.value.field == field


def random_states(n, seed=1):
    rng = np.random.default_rng(seed)
    q = rng.normal(size=(n, 4))
    q /= np.linalg.norm(q, axis=1, keepdims=True)
    x = np.concatenate([rng.uniform(-3, 3, (n, 3)), q, rng.uniform(-5, 5, (n, 3)), rng.uniform(-2, 2, (n, 3))], axis=1)
    I_b = rng.uniform(0.2, 3.0, (n, 3))
    return x, I_b


def test_numpy_and_c_functions_match_the_independent_formulas(guide):
    s = extending.load("my_effects.py" if False else guide["set"])
    x, I_b = random_states(50)
    m = np.full(50, 2.5)
    p_gg = np.tile(np.concatenate([[MU], CENTER]), (50, 1))
    p_dr = np.tile([RHO, CDA], (50, 1))
    F, tau = s.numpy.EFFECT_APPLY["gravity_gradient"](p_gg, x, x[:, 7:10], m, I_b)
    assert F is None
    F2, tau2 = s.numpy.EFFECT_APPLY["quadratic_drag"](p_dr, x, x[:, 7:10], m, I_b)
    assert tau2 is None
    lib = s.library()
    dp = ctypes.POINTER(ctypes.c_double)
    for i in range(50):
        want_t = gravity_gradient_w(x[i, 0:3], x[i, 3:7], I_b[i], MU, CENTER)
        want_f = quadratic_drag_w(x[i, 7:10], RHO, CDA)
        assert close(tau[i], want_t) and close(F2[i], want_f)
        for name, p, want, out in (("gravity_gradient", p_gg[i], want_t, 1), ("quadratic_drag", p_dr[i], want_f, 0)):
            acc = [np.full(3, 0.25), np.full(3, -0.5)]  # the C function adds into F and tau
            args = [np.ascontiguousarray(a, dtype=np.float64) for a in (p, x[i], x[i, 7:10])]
            getattr(lib, f"lvu_effect_{name}")(*(a.ctypes.data_as(dp) for a in args), ctypes.c_double(m[i]),
                                                np.ascontiguousarray(I_b[i]).ctypes.data_as(dp),
                                                acc[0].ctypes.data_as(dp), acc[1].ctypes.data_as(dp))
            assert close(acc[out] - (0.25 if out == 0 else -0.5), want)
            assert np.array_equal(acc[1 - out], np.full(3, -0.5 if out == 0 else 0.25))


@pytest.mark.parametrize("backend", ["c", "numpy"])
def test_stepping_matches_an_independent_rk4(guide, backend):
    sim = lv.Sim(make_scene(), dt=1e-3, integrator="rk4", backend=backend)
    x0 = sim.x[0].copy()
    sim.run(200)
    want = reference_rk4(x0, sim.params[0, 0], sim.params[0, 1:4], 1e-3, 200)
    for sl in (slice(0, 3), slice(3, 7), slice(7, 10), slice(10, 13)):
        assert close(sim.x[0, sl], want[sl]), (backend, sl, sim.x[0, sl] - want[sl])
    assert np.max(np.abs(sim.x[0, 10:13] - x0[10:13])) > 1e-2  # the torque acted


@pytest.mark.parametrize("integrator", INTEGRATORS)
def test_every_integrator_on_both_backends(guide, integrator):
    out = {}
    for backend in ("c", "numpy"):
        sim = lv.Sim(make_scene(extra_free=True), dt=1e-3, integrator=integrator, backend=backend)
        sim.run(300)
        out[backend] = sim.x.copy()
        assert any("gravity_gradient(mu=" in line and "quadratic_drag(" in line for line in sim.pipeline)
        if integrator == "rk4":   # user effects never split or stay constant: the 13-number stages of their kind
            assert sim.pipeline[1].endswith("-> stages (13 numbers): rigid_body_increments_body_c; "
                                            "constants: rigid_body_increment_scale"), sim.pipeline[1]
        if integrator == "splitting":  # quadratic_drag reads v: explicit-midpoint kicks, 2 evaluations each
            assert sim.rhs_evals == 300 * 4
    if integrator == "dopri5":  # per-body step sizes in C, one shared step in NumPy: agree to the tolerance
        assert close(out["c"], out["numpy"], 1e-10)
    else:  # the same printed expressions in the same order: bitwise
        assert np.array_equal(out["c"], out["numpy"])
    free = lv.Scene()
    free.add_body(lv.Body.box("sat", 3.0, (0.6, 0.3, 0.2), p_w=(2.0, 0.5, -0.3), q=(0.1, 0.2, 0.3, 0.9),
                              v_w=(3.0, -1.0, 2.0), omega_b=(0.3, -0.2, 0.5)))
    ref = lv.Sim(free, dt=1e-3, integrator=integrator, backend="numpy")
    ref.run(300)
    assert np.max(np.abs(out["c"][0, 10:13] - ref.x[0, 10:13])) > 1e-3  # the effects acted
    assert np.max(np.abs(out["c"][0, 7:10] - ref.x[0, 7:10])) > 1e-3


@pytest.mark.parametrize("backend", ["c", "numpy"])
def test_on_a_jointed_wheeled_body_drag_sees_the_kinematic_velocity(guide, backend):
    s = lv.Scene()
    s.add_body(lv.Body.box("cube", 1.0, (0.15, 0.15, 0.15), p_w=(0, 0, 0.2), omega_b=(2.0, -1.0, 3.0)))
    s.add_effect("spherical_joint", body="cube", anchor_w=(0, 0, 0))
    s.add_effect("reaction_wheels", body="cube", J=[1e-4] * 3, torque_limit=0.1, speed_limit=300.0)
    s.add_effect("quadratic_drag", body="cube", rho=RHO, cd_area=0.5)
    sims = {i: lv.Sim(s, dt=1e-3, integrator=i, backend=backend) for i in ("rk4", "dopri5")}
    for sim in sims.values():
        sim.run(200)
    no_drag = lv.Scene()
    no_drag.add_body(s.bodies["cube"])         # scene.bodies is a read-only view: add_body is the way in
    no_drag.effects = s.effects[:2]
    ref = lv.Sim(no_drag, dt=1e-3, integrator="rk4", backend=backend)
    ref.run(200)
    w, w0 = np.linalg.norm(sims["rk4"].x[0, 10:13]), np.linalg.norm(ref.x[0, 10:13])
    assert w < w0 - 1e-4  # drag on the COM (moving about the pivot) slows the spin
    assert close(sims["dopri5"].x[0], sims["rk4"].x[0], 1e-6)


def test_c_and_numpy_agree_bitwise_with_built_in_effects_around(guide):
    xs = []
    for backend in ("c", "numpy"):
        s = make_scene(extra_free=True)
        s.add_effect("angular_damping", c=0.01)                 # every body, after the user effects
        s.add_effect("gravity", body="ball")
        s.add_effect("gravity_gradient", body="ball", mu=0.5, center_w=(5, 0, 0))  # a user effect on a second body
        sim = lv.Sim(s, dt=1e-3, integrator="rk4", backend=backend)
        sim.run(100)
        xs.append(sim.x.copy())
    assert np.array_equal(xs[0], xs[1])


@pytest.mark.parametrize("n", [3, 37])
def test_user_effects_on_the_simd_tiles_are_the_scalar_path_and_numpy_bitwise(guide, n):
    """Many bodies under the guide's effects (and a built-in one) take the C effect tiles, the user effects through
    their printed tile forms (one per instruction set): every instruction set gives the scalar path's and NumPy's
    bits."""
    import platform

    from lavendersim import _lavender_c as C
    from lavendersim.backends.c_backend import user_effect_table
    rng = np.random.default_rng(n)
    s = lv.Scene()
    for i in range(n):
        s.add_body(lv.Body.box(f"b{i}", 1.0 + rng.random(), tuple(0.1 + rng.random(3)), p_w=tuple(rng.standard_normal(3)),
                               q=tuple(rng.standard_normal(4)), v_w=tuple(rng.standard_normal(3)),
                               omega_b=tuple(rng.standard_normal(3))))
    s.add_effect("gravity_gradient", mu=MU, center_w=CENTER)
    s.add_effect("angular_damping", c=0.02)
    s.add_effect("quadratic_drag", rho=RHO, cd_area=CDA)
    ref = lv.Sim(s, dt=1e-3, integrator="rk4", backend="numpy")
    ref.run(60)
    from lavendersim import effects as E
    rows = np.asarray(s.arrays()[2])
    table = user_effect_table(rows)
    assert table.shape[1] == 16
    # the table is indexed by user code; codes this scene does not use (other sets registered in this process by
    # other tests) are zero rows, so only the scene's own user effects are checked
    codes = np.unique(rows[:, E.ROW_CODE]).astype(np.int64)
    used = codes[codes >= E.USER_CODE_BASE] - E.USER_CODE_BASE
    assert len(used) == 2
    gg = E.REGISTRY["gravity_gradient"].code - E.USER_CODE_BASE
    drag = E.REGISTRY["quadratic_drag"].code - E.USER_CODE_BASE
    assert (table[gg, 6:7] != 0).all() and (table[drag, 6:10] == 0).all()   # the body-frame form of torque_b only
    if platform.machine() in ("x86_64", "AMD64"):   # tile forms and fused tiles (q raw / normalized), at every ISA
        assert (table[used, 3:6] != 0).all() and (table[gg, 7:10] != 0).all() and (table[used, 10:] != 0).all()
    try:
        for level in range(C.isa(-1)[2] + 1):
            C.isa(level)
            sim = lv.Sim(s, dt=1e-3, integrator="rk4", backend="c")
            sim.run(60)
            assert np.array_equal(sim.x, ref.x), C.isa()[1]
    finally:
        C.isa(-1)


def test_the_body_frame_torque_has_both_forms_and_c_is_numpy_bitwise(guide):
    """gravity_gradient declares torque_b: its set exports the world form (R_WB tau_b, lvu_effect_gravity_gradient)
    and the body-frame form (tau_b, lvu_effect_gravity_gradient_b, NumPy EFFECT_APPLY_B); each equals the formula
    written here, and C gives NumPy's bits for both."""
    s = extending.load(guide["set"])
    assert E.REGISTRY["gravity_gradient"].rhs_flags & E.FLAG_TORQUE_B
    assert not E.REGISTRY["gravity_gradient"].rhs_flags & E.FLAG_TORQUE_W
    assert set(s.numpy.EFFECT_APPLY_B) == {"gravity_gradient"}     # quadratic_drag has no torque: no body form
    x, I_b = random_states(40)
    m = np.full(40, 2.5)
    p_gg = np.tile(np.concatenate([[MU], CENTER]), (40, 1))
    F_w, tau_w = s.numpy.EFFECT_APPLY["gravity_gradient"](p_gg, x, x[:, 7:10], m, I_b)
    F_b, tau_b = s.numpy.EFFECT_APPLY_B["gravity_gradient"](p_gg, x, x[:, 7:10], m, I_b)
    assert F_w is None and F_b is None
    lib = s.library()
    dp = ctypes.POINTER(ctypes.c_double)
    for i in range(40):
        R = rot(x[i, 3:7])
        want_w = gravity_gradient_w(x[i, 0:3], x[i, 3:7], I_b[i], MU, CENTER)
        assert close(tau_w[i], want_w) and close(tau_b[i], R.T @ want_w)
        for fn, want in (("lvu_effect_gravity_gradient", tau_w[i]), ("lvu_effect_gravity_gradient_b", tau_b[i])):
            F, tau = np.zeros(3), np.zeros(3)
            args = [np.ascontiguousarray(a, dtype=np.float64) for a in (p_gg[i], x[i], x[i, 7:10], I_b[i])]
            getattr(lib, fn)(args[0].ctypes.data_as(dp), args[1].ctypes.data_as(dp), args[2].ctypes.data_as(dp),
                             ctypes.c_double(m[i]), args[3].ctypes.data_as(dp), F.ctypes.data_as(dp),
                             tau.ctypes.data_as(dp))
            assert tau.tobytes() == (0.0 + want).tobytes() and not F.any(), fn


@pytest.mark.parametrize("n", [1, 5, 40])
def test_a_body_torque_user_effect_runs_on_the_body_or_world_right_hand_side_bitwise(guide, n):
    """gravity_gradient alone (the body-torque right-hand side: its body-frame form, nothing rotated) and with a world
    torque beside it (applied_torque: its world form, rotated back): C, at every instruction set (the effect tiles
    from 2 bodies, the user tile forms of both frames), gives NumPy's bits, and both follow an independent RK4."""
    from lavendersim import _lavender_c as C
    rng = np.random.default_rng(n)
    scenes = {}
    for label, extra in (("body", []), ("world", [("applied_torque", {"torque_w": [1e-3, -2e-3, 5e-4]})])):
        s = lv.Scene()
        for i in range(n):
            s.add_body(lv.Body.box(f"b{i}", 1.0 + rng.random(), tuple(0.1 + rng.random(3)),
                                   p_w=tuple(3.0 * rng.standard_normal(3)), q=tuple(rng.standard_normal(4)),
                                   v_w=tuple(rng.standard_normal(3)), omega_b=tuple(rng.standard_normal(3))))
        s.add_effect("gravity_gradient", mu=MU, center_w=CENTER)
        for name, p in extra:
            s.add_effect(name, **p)
        scenes[label] = s
    for label, s in scenes.items():
        ref = lv.Sim(s, dt=1e-3, integrator="rk4", backend="numpy")
        x0 = ref.x.copy()
        ref.run(80)
        if label == "body":   # the independent RK4 (torque in the world frame, rotated back into the body)
            for b in range(n):
                want = reference_rk4_gg(x0[b], ref.params[b, 0], ref.params[b, 1:4], 1e-3, 80)
                assert close(ref.x[b], want), (b, ref.x[b] - want)
        try:
            for level in range(C.isa(-1)[2] + 1):
                C.isa(level)
                sim = lv.Sim(s, dt=1e-3, integrator="rk4", backend="c")
                sim.run(80)
                assert np.array_equal(sim.x, ref.x), (label, C.isa()[1])
        finally:
            C.isa(-1)


@pytest.mark.parametrize("n", [5, 67])
@pytest.mark.parametrize("normalize", [True, False])
@pytest.mark.parametrize("effect", ["gravity_gradient", "quadratic_drag"])
def test_a_user_effects_fused_tile_is_its_stage_passes_bitwise(guide, monkeypatch, n, normalize, effect):
    """A tile of bodies whose one effect is a user effect steps on that effect's fused tile (printed into the user's
    library by derive/effect_fuse_user.py, the engine's RK4 tile with the effect inlined; gravity_gradient: the body
    torque's tile kind, quadratic_drag: a force's): at every instruction set it gives the bits of the effect tile's
    stage passes (the same table without its fused tiles), of the scalar path and of NumPy, each body its own
    parameters. Signed zeros too: every third body starts with v_w = (-0, +0, v_z); a body-frame torque alone (no
    force: its increments' H_v is -0, the additive identity) leaves v_w bitwise as it was, -0 included."""
    import platform

    from lavendersim import _lavender_c as C
    from lavendersim.backends import c_backend
    rng = np.random.default_rng(n)
    s = lv.Scene()
    for i in range(n):
        v_w = (-0.0, 0.0, rng.standard_normal()) if i % 3 == 0 else tuple(rng.standard_normal(3))
        s.add_body(lv.Body.box(f"b{i}", 1.0 + rng.random(), tuple(0.1 + rng.random(3)),
                               p_w=tuple(3.0 * rng.standard_normal(3)), q=tuple(rng.standard_normal(4)),
                               v_w=v_w, omega_b=tuple(rng.standard_normal(3))))
        if effect == "gravity_gradient":
            s.add_effect(effect, body=f"b{i}", mu=MU * (0.5 + rng.random()), center_w=tuple(0.1 * rng.random(3)))
        else:
            s.add_effect(effect, body=f"b{i}", rho=RHO * (0.5 + rng.random()), cd_area=CDA)
    table = c_backend.user_effect_table(np.asarray(s.arrays()[2]))
    code = E.REGISTRY[effect].code - E.USER_CODE_BASE
    if platform.machine() in ("x86_64", "AMD64"):
        assert (table[code, 10:] != 0).all()    # its fused tiles, q raw / normalized, at every instruction set
    ref = lv.Sim(s, dt=1e-3, integrator="rk4", backend="numpy", normalize=normalize)
    v0 = ref.x[:, LY.STATE_V_W].copy()
    ref.run(90)
    if effect == "gravity_gradient":
        assert np.array_equal(ref.x[:, LY.STATE_V_W], v0) and np.signbit(ref.x[::3, LY.STATE_V_W][:, 0]).all()
    full = c_backend.user_effect_table

    def without_fused(effects):
        out = full(effects)
        if out is not None:
            out = out.copy()
            out[:, 10:] = 0
        return out

    try:
        for level in range(C.isa(-1)[2] + 1):
            C.isa(level)
            for table_of in (full, without_fused):
                monkeypatch.setattr(c_backend, "user_effect_table", table_of)
                sim = lv.Sim(s, dt=1e-3, integrator="rk4", backend="c", normalize=normalize)
                sim.run(90)
                assert np.array_equal(sim.x, ref.x), (C.isa()[1], table_of.__name__)
                assert np.array_equal(np.signbit(sim.x), np.signbit(ref.x)), (C.isa()[1], table_of.__name__)
    finally:
        C.isa(-1)


def reference_rk4_gg(x, m, I_b, dt, n):
    """RK4 of one rigid body under gravity_gradient alone (MU, CENTER), q normalized after each step."""
    return hand_rk4(x, I_b, dt, n)


def test_a_body_form_named_as_another_effect_is_refused(tmp_path):
    """An effect declaring torque_b exports lvu_effect_<name>_b: an effect named <name>_b in the same file would
    collide with it, and derive refuses the file naming the name."""
    from lavendersim.derive.user import DeclarationError, load_declarations
    decl = tmp_path / "clash.py"
    decl.write_text("from lavendersim.derive.effect import STATE, effect\n"
                    "EFFECTS = [effect('spin', 'a', torque_b=-STATE.omega_b),\n"
                    "           effect('spin_b', 'b', torque_w=-STATE.omega_w)]\n", encoding="utf-8")
    with pytest.raises(DeclarationError, match=r"duplicate names \['effect_spin_b'\]"):
        load_declarations(decl)


# ---------------------------------------------------------------- step 4: CasADi

def test_the_guides_casadi_example_runs(guide):
    require("control")
    (guide["work"] / "casadi_example.py").write_text(guide_block("python casadi_example.py"), encoding="utf-8")
    r = subprocess.run([sys.executable, "casadi_example.py"], cwd=guide["work"], env=guide["env"],
                       capture_output=True, text=True)
    assert r.returncode == 0, r.stderr
    assert "['p_w', 'q', 'I_b', 'mu', 'center_w'] ['F_w', 'tau_w']" in r.stdout


def test_casadi_expression_matches_the_independent_formula(guide):
    require("control")
    import casadi

    x, I_b = random_states(5, seed=7)
    for i in range(5):
        F, tau = E.casadi_expr("gravity_gradient", p_w=x[i, 0:3], q=x[i, 3:7], I_b=I_b[i], mu=MU, center_w=CENTER)
        assert close(np.asarray(tau).ravel(), gravity_gradient_w(x[i, 0:3], x[i, 3:7], I_b[i], MU, CENTER))
        assert np.array_equal(np.asarray(F).ravel(), np.zeros(3))
    f = E.casadi_function("quadratic_drag")
    assert f.name_in() == ["v_w", "rho", "cd_area"] and f.name_out() == ["F_w", "tau_w"]
    F, _ = f(x[0, 7:10], RHO, CDA)
    assert close(np.asarray(F).ravel(), quadratic_drag_w(x[0, 7:10], RHO, CDA))
    v = casadi.SX.sym("v", 3)  # and it differentiates: dF/dv at v = 0 is 0
    F, _ = E.casadi_expr("quadratic_drag", v_w=v, rho=RHO, cd_area=CDA)
    J = casadi.Function("J", [v], [casadi.jacobian(F, v)])
    assert np.allclose(np.asarray(J([3.0, 0.0, 0.0])), -0.5 * RHO * CDA * np.diag([6.0, 3.0, 3.0]))


# ---------------------------------------------------------------- step 5: the plain kernel

def test_the_guides_cone_example_runs(guide):
    (guide["work"] / "cone_example.py").write_text(guide_block("python cone_example.py"), encoding="utf-8")
    r = subprocess.run([sys.executable, "cone_example.py"], cwd=guide["work"], env=guide["env"],
                       capture_output=True, text=True)
    assert r.returncode == 0, r.stderr
    assert r.stdout.startswith("Body('cone', mass=2, I_b=[")


def test_plain_kernel_of_the_guide(guide):
    my = extending.load(guide["work"] / "my_effects.py")
    m, R, h = 2.0, 0.1, 0.3
    I = my.numpy.inertia_cone(m, R, h)
    want = [3 / 80 * m * (h * h + 4 * R * R)] * 2 + [3 / 10 * m * R * R]
    assert close(I, want)
    lv.Body("cone", m, I)
    if have("control"):
        assert close(np.asarray(my.casadi.inertia_cone(m, R, h)).ravel(), want)
    out = np.zeros(3)   # the compiled library exports the plain kernel too (issue 31)
    my.library().lvu_my_effects_inertia_cone(ctypes.c_double(m), ctypes.c_double(R), ctypes.c_double(h),
                                              out.ctypes.data_as(ctypes.POINTER(ctypes.c_double)))
    assert close(out, want)


# ---------------------------------------------------------------- what can go wrong

def test_an_edited_declaration_is_not_simulated_stale(guide, tmp_path):
    decl = tmp_path / "drift.py"
    decl.write_text(guide_block("python my_effects.py").replace("gravity_gradient", "gg_drift")
                    .replace("quadratic_drag", "qd_drift").replace("inertia_cone", "inertia_cone_drift"))
    out = tmp_path / "sets"
    extending.derive(decl, out=out)
    decl.write_text(decl.read_text() + "\n# edited\n")
    with pytest.raises(LavenderInputError, match="derive --user"):
        extending.load(out / "drift", reload=True)


def test_a_compiler_error_is_raised_with_its_full_output(guide, tmp_path, monkeypatch):
    """The API raises UserBuildError holding the command and the compiler's whole output (the CLI's one line,
    the log file and the last good set kept: tests/test_user_sets.py)."""
    cc = tmp_path / "failcc"
    cc.write_text("#!/bin/sh\necho 'kernels.c:3:1: error: this is not C' >&2\necho 'second line of output' >&2\nexit 1\n")
    cc.chmod(0o755)
    decl = tmp_path / "broken_c.py"
    decl.write_text(guide_block("python my_effects.py").replace("gravity_gradient", "gg_broken")
                    .replace("quadratic_drag", "qd_broken"))
    monkeypatch.setenv("CC", str(cc))
    with pytest.raises(extending.UserBuildError) as e:
        extending.derive(decl, out=tmp_path / "sets")
    msg = str(e.value)
    assert "error: this is not C" in msg and "second line of output" in msg and "-std=c99" in msg
    assert "\n" not in e.value.summary and "error: this is not C" in e.value.summary
    assert Path(e.value.log).read_text().count("second line of output") == 1
    assert not (tmp_path / "sets" / "broken_c").exists()     # nothing swapped in


def test_cli_lists_the_guides_effects(guide):
    """The guide's set, derived into a fresh user directory by the documented command (the module fixture):
    `lavendersim effects` lists its effects and parameters beside the built-ins, naming the set (issue 31; was
    test_effects_listing's, which derived the same set again into a user directory of its own)."""
    import json

    cli = [sys.executable, "-m", "lavendersim.cli"]
    r = subprocess.run([*cli, "effects", "--json"], env=guide["env"], capture_output=True, text=True, timeout=300)
    assert r.returncode == 0 and r.stderr == "", r.stderr
    listed = {e["name"]: e for e in json.loads(r.stdout)}
    # every built-in (this process may hold user sets other tests loaded from elsewhere: not the child's)
    assert {n for n, spec in E.REGISTRY.items() if spec.source == "built-in"} < set(listed)
    gg = listed["gravity_gradient"]
    assert gg["source"] != "built-in" and "my_effects" in gg["source"]
    assert {p["name"] for p in gg["params"]} >= {"mu", "center_w"} and gg["reads"] == ["p_w", "q", "I_b"]
    text = subprocess.run([*cli, "effects", "quadratic_drag"], env=guide["env"], capture_output=True, text=True,
                          timeout=300)
    assert text.returncode == 0 and text.stdout.startswith("quadratic_drag (force, user set ")


def test_a_user_effect_cannot_shadow_a_built_in(guide, tmp_path):
    decl = tmp_path / "shadow.py"
    decl.write_text("from lavendersim.derive.effect import STATE, effect, param\n"
                    "c = param('c', rule='nonnegative')\n"
                    "EFFECTS = [effect('gravity', 'not the real one', params=[c], force_w=-c.symbol * STATE.v_w)]\n")
    with pytest.raises(LavenderInputError, match="built-in"):
        extending.derive(decl, out=tmp_path / "sets", compile=False)


@pytest.mark.needs("control")
def test_linearize_a_scene_with_user_effects(guide):
    """Issue 13: lavendersim.control.linearize composes the user effects' CasADi printing; checked
    against finite differences of one Euler step of the Sim (tolerances: tests/test_linearize.py)."""
    from lavendersim import control as lc

    s = make_scene()
    lin = lc.linearize(s, inputs=["quadratic_drag.cd_area", "gravity_gradient.mu"])
    assert lin.ninputs == 2 and lin.nstates == 12
    for backend in ("c", "numpy"):
        A, B = lc.finite_difference(lin, s, backend=backend)
        res = lc.linearization_residual(lin, A, B)
        assert res["A_rel"] <= 1e-5 and res["B_rel"] <= 1e-7, res
