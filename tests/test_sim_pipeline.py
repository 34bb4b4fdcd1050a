"""Sim.pipeline names the printed kernels each plain body's step really runs on the Sim's backend and integrator
(issue 30: "simulate only the effects a scene calls for ... visible"): torque-free bodies the scaled increments,
constant-effect bodies (gravity, an applied torque) their (q, omega_b) stages and the constant flow, decoupled bodies
(damping) the rotation's stages and the affine flow, the right-hand-side integrators their class's right-hand side.
The names are checked against the kernels generated/kernels.h declares, and on NumPy against the kernels a run
really calls."""
from __future__ import annotations

import re
from pathlib import Path

import numpy as np
import pytest

import lavendersim as lv
from lavendersim import pipeline as PL
from lavendersim.backends import numpy_scalar
from lavendersim.kernels import K

BACKENDS = ["numpy", "c"]
KERNELS_H = Path(__file__).resolve().parents[1] / "generated" / "kernels.h"

# the scene: each body with the effects of one path
EFFECTS = {
    "plain": [],
    "grav": [("gravity", {})],
    "torque": [("applied_torque", {"torque_w": [0.0, 0.01, -0.02]})],
    "damp": [("linear_damping", {"c": 0.1})],
    "gdamp": [("gravity", {}), ("linear_damping", {"c": 0.1})],
    "spin_damp": [("angular_damping", {"c": 0.01})],
    "coupled": [("force_at_point", {"r_b": [0.1, 0.0, 0.0], "F_w": [0.0, 0.2, 0.0]}), ("angular_damping", {"c": 0.01})],
}
# what each runs under rk4 (float64): its stage kernel, its translation, kernels it must not name
RK4 = {
    "plain": ("rigid_body_increments_free_c", "translation_drift"),
    "grav": ("rigid_body_increments_free_c", "translation_flow_constant"),
    "torque": ("rigid_body_increments_torque_h", "translation_drift"),
    "damp": ("rigid_body_increments_free_c", "translation_flow"),
    "gdamp": ("rigid_body_increments_free_c", "translation_flow"),
    "spin_damp": ("rigid_body_increments_rot_b_c", "translation_flow"),
    "coupled": ("rigid_body_increments_c", None),
}


def scene(copies: int = 1) -> lv.Scene:
    s = lv.Scene()
    rng = np.random.default_rng(3)
    for name, effs in EFFECTS.items():
        for j in range(copies):
            b = f"{name}{j}" if copies > 1 else name
            s.add_body(lv.Body.box(b, 1.5, (0.3, 0.5, 0.7), omega_b=rng.standard_normal(3), v_w=rng.standard_normal(3)))
            for e, p in effs:
                s.add_effect(e, body=b, **p)
    return s


def parts(line: str) -> dict[str, list[str]]:
    """A body line's kernels by part: "name: terms -> what: a, b; what: c" -> {what: [a, b], ...}."""
    out = {}
    for part in line.split(" -> ", 1)[1].split("; "):
        what, names = part.split(": ", 1)
        out[what] = names.split(", ")
    return out


def declared() -> set[str]:
    """The kernels generated/kernels.h declares (lv_<name>(...))."""
    return set(re.findall(r"\blv_(\w+)\(", KERNELS_H.read_text()))


@pytest.mark.parametrize("backend", BACKENDS)
def test_rk4_lines_name_each_paths_kernels(backend):
    sim = lv.Sim(scene(), dt=1e-3, backend=backend)
    lines = dict(line.split(": ", 1) for line in sim.pipeline[1:])
    assert list(lines) == list(EFFECTS)
    for name, (stage, translation) in RK4.items():
        p = parts(f"{name}: {lines[name]}")
        stages = p.get("stages (q, omega_b)", p.get("stages (13 numbers)"))
        assert stages == [stage], (name, lines[name])
        assert ("stages (13 numbers)" in p) == (name == "coupled"), (name, lines[name])
        if translation is not None:
            assert p["translation"] == [translation], (name, lines[name])
        assert "rigid_body_rhs" not in lines[name], (name, lines[name])   # no right-hand side runs under rk4
    assert "constant_acceleration_steps" in lines["grav"] and "translation_flow_scale" in lines["damp"]
    assert "rigid_body_increment_scale_free" in lines["plain"]
    # the per-call constants of a gravity body: C takes them from S (lv_const_scale), NumPy from the free kernel
    grav_scale = parts("grav: " + lines["grav"])["constants"][0]
    assert grav_scale == ("rigid_body_increment_scale" if backend == "c" else "rigid_body_increment_scale_free")


@pytest.mark.parametrize("integrator", ["rk4", "euler", "semi_implicit_euler", "dopri5", "splitting"])
@pytest.mark.parametrize("backend", BACKENDS)
def test_every_named_kernel_is_printed(backend, integrator):
    """Each name a line gives (a composition's flows aside) is a kernel generated/kernels.h declares."""
    have = declared()
    sim = lv.Sim(scene(), dt=1e-3, integrator=integrator, backend=backend)
    for line in sim.pipeline[1:]:
        for what, names in parts(line).items():
            if what == "flows":
                continue
            assert set(names) <= have, (line, set(names) - have)
    if integrator in ("euler", "semi_implicit_euler", "dopri5"):
        lines = dict(line.split(": ", 1) for line in sim.pipeline[1:])
        assert "rigid_body_rhs_force_c" in lines["grav"] and "increments" not in " ".join(lines.values())
        free = "rigid_body_rhs_free" if backend == "c" and integrator != "dopri5" else "rigid_body_rhs_free_c"
        assert parts("plain: " + lines["plain"])["right-hand side"] == [free]
        torque = "rigid_body_rhs_torque_c" if backend == "c" else "rigid_body_rhs_c"
        assert parts("torque: " + lines["torque"])["right-hand side"] == [torque]
    if integrator == "splitting":
        lines = dict(line.split(": ", 1) for line in sim.pipeline[1:])
        assert lines["plain"].endswith("flows: drift, strang") and "kick" in lines["grav"]


def test_the_numpy_backend_calls_what_the_pipeline_names(monkeypatch):
    """Per body group (more bodies than the scalar path takes, one path each), the NumPy kernels one rk4 step calls:
    every kernel its line names, and no stage kernel another path names."""
    n = numpy_scalar.SCALAR_MAX_BODIES + 1
    stage_kernels = {stage for stage, _ in RK4.values()}
    for name, effs in EFFECTS.items():
        s = lv.Scene()
        for j in range(n):
            s.add_body(lv.Body.box(f"b{j}", 1.5, (0.3, 0.5, 0.7), omega_b=(0.1 * j, 0.2, -0.3), v_w=(1.0, 0.0, 0.5)))
        for e, p in effs:
            s.add_effect(e, **p)   # scene-wide: every body of the group
        sim = lv.Sim(s, dt=1e-3, backend="numpy")
        named = {k for ks in parts(sim.pipeline[1]).values() for k in ks}
        assert all(line.split(" -> ")[1] == sim.pipeline[1].split(" -> ")[1] for line in sim.pipeline[1:])
        called = _kernels_called(monkeypatch, K, named | stage_kernels | {"rigid_body_rhs_c", "rigid_body_rhs_free_c"}, sim)
        assert named <= called, (name, named - called)
        assert not (called & stage_kernels) - named, (name, called)


@pytest.mark.parametrize("backend", BACKENDS)
def test_a_large_scene_names_the_same_kernels_as_a_small_one(backend):
    """The SIMD tiles (groups of LV_TILE_MIN bodies and more) run the same printed kernels as the scalar blocks: the
    lines of a body do not depend on how many share its path."""
    small = lv.Sim(scene(), dt=1e-3, backend=backend).pipeline[1:]
    big = lv.Sim(scene(copies=20), dt=1e-3, backend=backend).pipeline[1:]
    tails = {line.split(": ", 1)[0]: line.split(" -> ", 1)[1] for line in small}
    for line in big:
        name = line.split(": ", 1)[0]
        assert line.split(" -> ", 1)[1] == tails[name.rstrip("0123456789")]


def test_kernel_names_reads_a_pipeline():
    sim = lv.Sim(scene(), dt=1e-3, backend="numpy")
    names = PL.kernel_names(sim.pipeline)
    assert {"rigid_body_increments_free_c", "rigid_body_increments_torque_h", "translation_flow_constant",
            "translation_flow", "rigid_body_increments_rot_b_c", "rigid_body_increments_c"} <= names
    assert names <= declared()


def test_no_kernel_is_named_in_lavendersim():
    """The names come from derive's printed table (effects_meta.PIPELINE_KERNELS), never from a list typed in
    lavendersim/: the pipeline module and the Sim's line maker name none."""
    import inspect

    from lavendersim.generated import effects_meta
    from lavendersim.sim import Sim

    names = {n for table in effects_meta.PIPELINE_KERNELS.values() for ps in table.values() for _, ns in ps for n in ns}
    code = inspect.getsource(PL) + inspect.getsource(Sim._plain_line) + inspect.getsource(Sim._body_line)
    assert not {n for n in names if re.search(rf"\b{n}\b", code)}


# ---- float32, the implicit and the Lie-group steps: itemized from derive's rows too ------------------------------
STEP_CASES = [("float64", "implicit_gyro"), ("float64", "rk4_expmap"), ("float64", "euler"),
              ("float64", "semi_implicit_euler"), ("float32", "rk4"), ("float32", "euler"), ("float32", "semi_implicit_euler")]
STEP_C = Path(__file__).resolve().parents[1] / "lavendersim" / "csrc"



def _kernels_called(monkeypatch, module, names, sim) -> set[str]:
    """Which of module's kernels `names` two steps of sim call (each wrapped to record its name, then restored)."""
    called: set[str] = set()
    with monkeypatch.context() as m:
        for k in names:
            f = getattr(module, k)
            m.setattr(module, k, lambda *a, _f=f, _k=k, **kw: (called.add(_k), _f(*a, **kw))[1])
        sim.run(2)
    return called

def _c_function(text: str, head: str) -> str:
    """The body of the C function whose definition starts with `head` (up to the next line that is a lone '}')."""
    a = text.index(head)
    return text[a:text.index("\n}\n", a)]


def test_every_row_names_printed_kernels():
    """Every kernel of every row (each backend, dtype, path) is printed: kernels.h for float64, the float32 printing
    (lvf_<name>, generated/kernels_f32.c) for the float32 rows."""
    from lavendersim.generated import effects_meta

    have = declared()
    f32 = set(re.findall(r"\blvf_(\w+)\(", (KERNELS_H.parent / "kernels_f32.c").read_text()))
    for backend, table in effects_meta.PIPELINE_KERNELS.items():
        for key, row in table.items():
            names = {n for _, ns in row for n in ns}
            assert names <= (f32 if key.startswith("float32:") else have), (backend, key, names - have)


@pytest.mark.parametrize("dtype, integrator", STEP_CASES)
@pytest.mark.parametrize("backend", BACKENDS)
def test_float32_and_structured_steps_are_itemized(backend, dtype, integrator):
    """No line says "not itemized": each names its row's kernels; the float32 tiles' kinds part constant loads
    (summed once per call on C) from state-reading ones, the implicit step names its loads only with effects."""
    sim = lv.Sim(scene(), dt=1e-3, backend=backend, integrator=integrator, dtype=dtype)
    lines = dict(line.split(": ", 1) for line in sim.pipeline[1:])
    assert not any("not itemized" in v for v in lines.values())
    have = declared()
    for name, line in lines.items():
        assert {k for ks in parts(f"{name}: {line}").values() for k in ks} <= have, line
    if integrator == "implicit_gyro":
        assert "world_to_body" not in lines["plain"] and "world_to_body" in lines["grav"]
        assert all("implicit_gyro_newton, quat_exp_step" in v for v in lines.values())
    if integrator == "rk4_expmap":
        assert all(v.endswith("exponential coordinates: quat_exp_step, rkmk_dexpinv") for v in lines.values())
        euler = dict(ln.split(": ", 1) for ln in lv.Sim(scene(), dt=1e-3, backend=backend,
                                                       integrator="euler").pipeline[1:])
        assert all(lines[n].split(" -> ")[1].startswith(euler[n].split(" -> ")[1]) for n in lines)   # the same rhs
    if dtype == "float32":
        once = "right-hand side (loads summed once per call)" if backend == "c" else "right-hand side"
        positions = ({"positions (with the new rates)": ["translation_drift", "quat_derivative_body"]}
                     if integrator == "semi_implicit_euler" else {})
        assert parts("torque: " + lines["torque"]) == {
            once: ["rigid_body_rhs_torque_c" if backend == "c" else "rigid_body_rhs_c"]} | positions
        assert parts("grav: " + lines["grav"]) == {once: ["rigid_body_rhs_c"]} | positions
        assert parts("damp: " + lines["damp"]) == {"right-hand side": ["rigid_body_rhs_c"]} | positions
        free = parts("plain: " + lines["plain"])
        assert free == ({"stages (q, omega_b)": ["rigid_body_increments_free_c"], "translation": ["translation_drift"],
                         "constants": ["rigid_body_increment_scale_free"]} if integrator == "rk4"
                        else {"right-hand side": ["rigid_body_rhs_free_c"]} if integrator == "euler"
                        else {"right-hand side": ["rigid_body_rhs_free_c"],
                              "positions (with the new rates)": ["translation_drift", "quat_derivative_body"]})


@pytest.mark.parametrize("dtype, integrator", STEP_CASES)
def test_the_numpy_backend_calls_what_float32_and_structured_lines_name(monkeypatch, dtype, integrator):
    """Per body group (one path each, more bodies than the scalar path takes), the kernels one step calls in the
    Sim's precision: every kernel its line names, and no kernel of any other row that its line does not name."""
    from lavendersim.generated import effects_meta
    from lavendersim.generated import kernels_numpy_f32

    mod = K if dtype == "float64" else kernels_numpy_f32
    rows = effects_meta.PIPELINE_KERNELS["numpy"]
    every = {n for key, row in rows.items() for _, ns in row for n in ns if key.startswith("float32:") == (mod is not K)}
    n = numpy_scalar.SCALAR_MAX_BODIES + 1
    for name, effs in EFFECTS.items():
        s = lv.Scene()
        for j in range(n):
            s.add_body(lv.Body.box(f"b{j}", 1.5, (0.3, 0.5, 0.7), omega_b=(0.1 * j, 0.2, -0.3), v_w=(1.0, 0.0, 0.5)))
        for e, p in effs:
            s.add_effect(e, **p)
        sim = lv.Sim(s, dt=1e-3, backend="numpy", integrator=integrator, dtype=dtype)
        named = {k for ks in parts(sim.pipeline[1]).values() for k in ks}
        assert len(sim.pipeline.groups()) == 1
        called = _kernels_called(monkeypatch, mod, every, sim)
        assert named <= called, (name, named - called)
        assert not (called & every) - named, (name, (called & every) - named)


def test_the_c_float32_tiles_call_what_the_rows_name():
    """csrc/fixed_loop.h (the float32 loop): its tile kinds are the rule pipeline.float32_path follows, each kind's
    right-hand side is the kernel its row names, and the torque-free RK4 runs the float64 FREE row's kernels."""
    from lavendersim.generated import effects_meta

    rows = effects_meta.PIPELINE_KERNELS["c"]
    text = (STEP_C / "fixed_loop.h").read_text()
    assert re.search(r"start\[b \+ 1\] == start\[b\] \? LV_FIXED_FREE\s*: \(f & LV_EFFECT_USES_STATE\) \? LV_FIXED_ANY"
                     r"\s*: \(f & LV_EFFECT_FORCE\) \? LV_FIXED_FORCE : LV_FIXED_TORQUE;", text)
    rhs = _c_function(text, "static inline void LV_FN(rhs)")
    called = {"FREE": re.search(r"kind == LV_FIXED_FREE\) \{\s*LV_K\((\w+)\)", rhs)[1],
              "CONST_TORQUE": re.search(r"if \(kind == LV_FIXED_TORQUE\) LV_K\((\w+)\)", rhs)[1]}
    called["CONST_FORCE"] = called["ANY"] = re.search(r"else LV_K\((\w+)\)", rhs)[1]
    assert set(re.findall(r"LV_K\((\w+)\)", rhs)) == set(called.values())
    for path, kernel in called.items():
        assert [n for _, ns in rows[f"float32:rhs:{path}"] for n in ns] == [kernel], path
    free = _c_function(text, "static inline void LV_FN(free_rk4_h)") + _c_function(text, "static inline void LV_FN(tile_steps)")
    named = {n for _, ns in rows["float32:rk4:FREE"] for n in ns}
    assert named == set(re.findall(r"LV_K\((\w+)\)", free)) - {"quat_normalize", "quat_derivative_body",
                                                                 "translation_drift"} | {"translation_drift"}
    assert "LV_FN(free_rk4_h)(t, b, x, hq, dt)" in _c_function(text, "static inline void LV_FN(body_step)")


def test_the_c_structured_steps_call_what_the_rows_name():
    """csrc/step.c: gyro_step (with gyro_newton and plain_loads) and rk4_expmap_step (with expmap_stage) call the
    kernels their rows name beside the right-hand side (body_rhs: the rhs rows)."""
    from lavendersim.generated import effects_meta
    from lavendersim.generated import tableaux

    rows = effects_meta.PIPELINE_KERNELS["c"]
    text = (STEP_C / "step.c").read_text()

    def calls(*heads: str) -> set[str]:
        return {k for h in heads for k in re.findall(r"\blv_(\w+)\(", _c_function(text, h))}

    def semi_implicit(src: str, pattern: str) -> set[str]:   # the partitioned Euler branch, up to the normalization
        a = src.index("/* LV_PATH_SEMI_IMPLICIT */")
        return set(re.findall(pattern, src[a:src.index("normalize", a)]))

    semi = "semi_implicit_euler"   # (the one integrator of fixed path semi_implicit)
    positions = {n for what, ns in rows[f"{semi}:FREE"] if what.startswith("positions") for n in ns}
    assert semi_implicit(text, r"\blv_(\w+)\(") == positions
    assert semi_implicit((STEP_C / "fixed_loop.h").read_text(), r"LV_K\((\w+)\)") == positions
    assert rows[f"float32:{semi}:ANY"][-1] == rows[f"{semi}:FULL"][-1]
    implicit = calls("static int gyro_step(", "static int gyro_newton(", "static void plain_loads(")
    lie = calls("static void rk4_expmap_step(", "static void expmap_stage(")
    assert "body_rhs(xs," in _c_function(text, "static void expmap_stage(")
    for integrator, family in tableaux.INTEGRATOR_FAMILY.items():
        if family == "implicit":
            assert {n for _, ns in rows[f"{integrator}:FULL"] for n in ns} == implicit
            assert {n for _, ns in rows[f"{integrator}:FREE"] for n in ns} == implicit - {"world_to_body"}
            assert "if (c->has) plain_loads(" in _c_function(text, "static int gyro_step(")
        if family == "lie_group_rk":
            for path in ("FREE", "FULL", "BODY"):
                assert rows[f"{integrator}:{path}"] == rows[f"rhs:{path}"] + (("exponential coordinates",
                                                                                tuple(sorted(lie))),)


# ---- the scene's paths: one line per distinct path, readable at any N ----------------------------------------------
def test_grouped_view_one_line_per_path_with_index_ranges():
    """Bodies that run the same kernels share one line: their indices as ranges and their count; each member's own
    line runs the same kernels and has the same effects (names) as its group's path."""
    n = 40
    names = [f"b{i}" for i in range(n)]
    s = lv.Scene()
    s.add_bodies(names, np.full(n, 1.5), np.tile([0.1, 0.2, 0.3], (n, 1)))
    s.add_effects("applied_torque", names[5:10] + names[30:32], torque_w=np.tile([0.0, 0.01, 0.0], (7, 1)))
    s.add_effect("linear_damping", body="b20", c=0.1)
    s.add_effect("gravity", body="b20")
    for backend in BACKENDS:
        p = lv.Sim(s, dt=1e-3, backend=backend).pipeline
        groups = p.groups()
        assert [(g.n_bodies, g.ranges.tolist()) for g in groups] == [
            (32, [[0, 5], [10, 20], [21, 30], [32, 40]]), (7, [[5, 10], [30, 32]]), (1, [[20, 21]])]
        assert sum(g.n_bodies for g in groups) == n
        for g in groups:
            for i in g.indices():
                line = p.body(int(i))
                assert line.split(" -> ", 1)[1] == g.path.split(" -> ", 1)[1], (line, g.path)
                assert sorted(t.split("(")[0] for t in line.split(": ", 1)[1].split(" -> ")[0].split(" + ")) == \
                    sorted(g.path.split(" -> ")[0].split(" + ")) or g.path.startswith("torque- and force-free")
        text = str(p).splitlines()
        assert text[0] == p[0] and len(text) == 1 + len(groups) + 1
        assert text[1].startswith("bodies 0\u20134, 10\u201319, 21\u201329, 32\u201339 (32): torque- and force-free")
        assert text[2].startswith("bodies 5\u20139, 30\u201331 (7): applied_torque -> ")
        assert text[3].startswith("body 20: gravity + linear_damping -> ")   # (by effect code, not added order)
        assert "torque_w=" not in str(p) and "torque_w=" in p.body("b5")   # values: per body only


def test_grouped_view_stays_short_and_caps_the_ranges():
    """Alternating paths: two lines whatever N, each with at most max_ranges ranges and how many more."""
    n = 3000
    names = [f"b{i}" for i in range(n)]
    s = lv.Scene()
    s.add_bodies(names, np.full(n, 1.5), np.tile([0.1, 0.2, 0.3], (n, 1)))
    odd = names[1::2]
    s.add_effects("applied_torque", odd, torque_w=np.tile([0.0, 0.01, 0.0], (len(odd), 1)))
    p = lv.Sim(s, dt=1e-3, backend="numpy").pipeline
    text = p.summary(max_ranges=3).splitlines()
    assert len(text) == 4 and len(p) == n + 1
    assert text[1] == ("bodies 0, 2, 4, \u2026 (+1497 more ranges) (1500): " + p.groups()[0].path)
    assert p.groups()[1].indices().tolist() == list(range(1, n, 2))


def test_pipeline_is_a_sequence_of_the_per_body_lines():
    sim = lv.Sim(scene(), dt=1e-3, backend="numpy")
    p = sim.pipeline
    lines = list(p)
    assert len(p) == len(lines) == 1 + len(EFFECTS) and p == lines and p == sim.pipeline
    assert p[-1] == lines[-1] == p.body(len(EFFECTS) - 1) == p.body("coupled") and p[1:3] == lines[1:3]
    assert p[0].startswith("rk4: 4 RHS evaluations per step")
    with pytest.raises(IndexError):
        p[len(p)]
    with pytest.raises(IndexError):
        p.body(len(EFFECTS))
    with pytest.raises(lv.LavenderInputError, match="body"):
        p.body("nobody")
    assert repr(p) == str(p) and str(p).splitlines()[-1].startswith("(one body's line")


def test_paths_of_wheels_joints_and_principal_frames_are_their_own():
    """A body's model (wheel count, layout), joint and full inertia tensor part its path from a plain body's."""
    s = lv.Scene()
    for j in range(3):
        s.add_body(lv.Body.box(f"w{j}", 1.5, (0.3, 0.5, 0.7)))
    s.add_effect("reaction_wheels", body="w0", J=(5e-4, 5e-4, 5e-4), torque_limit=0.2, speed_limit=400.0)
    s.add_effect("reaction_wheels", body="w1", J=(5e-4, 5e-4, 5e-4), torque_limit=0.2, speed_limit=400.0)
    s.add_body(lv.Body("tensor", 1.0, [[0.2, 0.01, 0.0], [0.01, 0.3, 0.0], [0.0, 0.0, 0.4]]))
    s.add_body(lv.Body.box("pend", 1.0, (0.1, 0.1, 0.5)))
    s.add_effect("spherical_joint", body="pend", anchor_w=[0.0, 0.0, 1.0])
    p = lv.Sim(s, dt=1e-3, backend="numpy").pipeline
    got = [(g.n_bodies, g.ranges[:, 0].tolist()) for g in p.groups()]
    assert got == [(2, [0]), (1, [2]), (1, [3]), (1, [4])], got
    assert "wheels" in p.groups()[0].path and "full inertia tensor" in p.groups()[2].path
    assert "pivot_body_rhs" in p.groups()[3].path and "r_b=" not in p.groups()[3].path and "r_b=" in p.body("pend")


def test_path_keys_part_every_code_set_beyond_64_codes():
    """More distinct effect codes than an int64 has bits: the keys are renumbered, still one per code set (and a
    row for every body, body -1, counts for each)."""
    rng = np.random.default_rng(5)
    n, codes = 500, 90
    rows = [(c, b) for b in range(n) for c in rng.choice(codes, size=rng.integers(0, 4), replace=False)]
    extra = rng.integers(0, 3, n)
    for every in ([], [(7, -1)]):
        table = np.zeros((len(rows) + len(every), 4))
        table[:, 0], table[:, 1] = [r[0] for r in rows + every], [r[1] for r in rows + every]
        keys = PL.path_keys(table, extra)
        sets = [(frozenset(c for c, b in rows + every if b in (i, -1)), int(extra[i])) for i in range(n)]
        same = keys[:, None] == keys[None, :]
        assert (same == np.array([[a == b for b in sets] for a in sets])).all()
        assert len(set(sets)) > 300


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_every_member_of_a_group_has_its_groups_path(seed):
    """A random scene (per-body effects, scene-wide and batched ones, wheels, joints, full inertia tensors, mixed
    paths on both backends): the group each body falls in (pipeline.path_keys, from the effect table and the model
    rows) says exactly what the body's own line says without values (from the Sim's effect objects)."""
    rng = np.random.default_rng(seed)
    s = lv.Scene()
    n = 60
    for i in range(n):
        if rng.random() < 0.1:
            s.add_body(lv.Body(f"b{i}", 1.0, [[0.2, 0.01, 0.0], [0.01, 0.3, 0.0], [0.0, 0.0, 0.4]]))
        else:
            s.add_body(lv.Body.box(f"b{i}", 1.5, (0.3, 0.5, 0.7), omega_b=rng.standard_normal(3)))
    if seed != 1:
        s.add_effect("gravity")
    per_body = [("applied_torque", {"torque_w": [0.0, 0.01, -0.02]}), ("linear_damping", {"c": 0.1}),
                ("angular_damping", {"c": 0.01}), ("force_at_point", {"r_b": [0.1, 0.0, 0.0], "F_w": [0.0, 0.2, 0.0]})]
    for i in range(n):
        for e, p in per_body:
            if rng.random() < 0.25:
                s.add_effect(e, body=f"b{i}", **p)
        if rng.random() < 0.08:
            s.add_effect("reaction_wheels", body=f"b{i}", J=(5e-4, 5e-4, 5e-4), torque_limit=0.2, speed_limit=400.0)
        elif rng.random() < 0.05:
            s.add_effect("spherical_joint", body=f"b{i}", anchor_w=(0.0, 0.0, 1.0))
    picked = [f"b{i}" for i in range(n) if rng.random() < 0.3]
    s.add_effects("applied_torque", picked, torque_w=np.tile([0.0, 0.0, 0.01], (len(picked), 1)))
    for backend in BACKENDS:
        sim = lv.Sim(s, dt=1e-3, backend=backend)
        groups = sim.pipeline.groups()
        assert sum(g.n_bodies for g in groups) == n and len(groups) > 5
        seen = np.zeros(n, int)
        for g in groups:
            seen[g.indices()] += 1
            for i in g.indices():
                assert sim._body_line(int(i), False) == g.path, (backend, int(i))
        assert (seen == 1).all()


# ---- bodies with a joint or wheels: their rows against the dispatch -------------------------------------------------
def test_the_model_rows_are_what_numpy_runs(monkeypatch):
    """NumPy: the wheel model and motor it binds (numpy_backend._WHEELS_RHS / _WHEELS_MOTOR) are the kernels the wheel
    rows name; a step of a wheeled, a jointed and a jointed body whose effects read v_w calls the rows' other kernels
    (pivot_body_rhs, translation_rhs, pivot_kinematics) and no model kernel its line does not name."""
    from lavendersim.backends import numpy_backend
    from lavendersim.generated import effects_meta

    rows = effects_meta.PIPELINE_KERNELS["numpy"]
    for integrator in ("rk4", "euler", "dopri5", "tableau"):
        wheel, motor = rows[f"{integrator}:model_rotation:WHEELS_ON_AXES"][:2]
        assert rows[f"{integrator}:model_rotation:WHEELS"][:2] == (wheel, motor)
        assert numpy_backend._WHEELS_RHS is getattr(K, wheel[1][0]) and numpy_backend._WHEELS_MOTOR is getattr(K, motor[1][0])
    models = {"pivot_body_rhs", "translation_rhs", "pivot_kinematics"}
    cases = {"wheeled": ([("reaction_wheels", {"J": (5e-4, 5e-4, 5e-4), "torque_limit": 0.2, "speed_limit": 400.0})],
                         {"translation_rhs"}),
             "jointed": ([("spherical_joint", {"anchor_w": (0.0, 0.0, 1.0)}), ("gravity", {})],
                         {"pivot_body_rhs", "pivot_kinematics", "translation_rhs"}),   # (the group's, zeroed)
             "jointed_v": ([("spherical_joint", {"anchor_w": (0.0, 0.0, 1.0)}), ("linear_damping", {"c": 0.1})],
                           {"pivot_body_rhs", "pivot_kinematics", "translation_rhs"})}
    for name, (effs, expect) in cases.items():
        s = lv.Scene()
        s.add_body(lv.Body.box("b", 1.5, (0.3, 0.5, 0.7), omega_b=(0.1, 0.2, -0.3)))
        for e, p in effs:
            s.add_effect(e, body="b", **p)
        sim = lv.Sim(s, dt=1e-3, backend="numpy")
        named = {k for ks in parts(sim.pipeline[1]).values() for k in ks}
        assert named & models == expect, (name, named)
        called = _kernels_called(monkeypatch, K, models, sim)
        assert called == expect, (name, called)
    assert "effects that read it" in lv.Sim(s, dt=1e-3, backend="numpy").pipeline[1]   # jointed_v: v_w formed too


def test_the_model_rows_are_what_c_runs():
    """C (csrc/step.c): model_rhs_of takes the on-axes print under LV_ON_AXES, the general one for other wheels,
    pivot_body_rhs for a joint alone, translation_rhs off the joint and pivot_kinematics for the effects' v_w; the
    fixed-step paths step with lv_step_kind (LV_ON_AXES added), the stage loop (dopri5, a user's tableau) with the
    row's kind: the rows the pipeline reads say the same, each macro resolved through generated/layout.h."""
    from lavendersim.generated import effects_meta
    from lavendersim.generated import tableaux

    rows = effects_meta.PIPELINE_KERNELS["c"]
    text = (STEP_C / "step.c").read_text()
    macros = dict(re.findall(r"#define (LV_WHEELS_\w+) lv_(\w+)", (KERNELS_H.parent / "layout.h").read_text()))
    rhs = _c_function(text, "static inline void model_rhs_of(")
    wheels = _c_function(text, "static inline void lv_wheels_rhs(")
    on_axes = macros[re.search(r"if \(on_axes\)\s*(LV_WHEELS_\w+)\(", wheels)[1]]
    general = macros[re.search(r"else\s*(LV_WHEELS_\w+)\(", wheels)[1]]
    assert re.search(r"if \(kind & LV_ON_AXES\) \{\s*lv_wheels_rhs\(1,", rhs) and "lv_wheels_rhs_call(" in rhs
    assert "lv_wheels_rhs(0," in _c_function(text, "static void lv_wheels_rhs_call(")
    assert {"pivot_body_rhs", "translation_rhs", "pivot_kinematics"} <= set(re.findall(r"\blv_(\w+)\(", rhs))
    assert "const int kind = model_step_kind(md, b);" in _c_function(text, "static long advance_model_body(")
    assert "c->kind = md != NULL ? (int)md->rows[b * LV_MODEL_SIZE + LV_MODEL_KIND] : 0;" in text   # ctx_init
    motor = macros[re.search(r"(LV_WHEELS_MOTOR)\(", _c_function(text, "static inline void lv_wheels_motor("))[1]]
    coefficients = macros["LV_WHEELS_COEFFICIENTS"]
    fixed = [i for i in ("euler", "semi_implicit_euler", "rk4") if i in tableaux.INTEGRATOR_CODES]
    for integrator in fixed + ["dopri5", "tableau"]:
        want = on_axes if integrator in fixed else general
        assert rows[f"{integrator}:model_rotation:WHEELS_ON_AXES"] == (
            ("rotation and wheels", (want,)), ("wheel motors (per step, zero-order hold)", (motor,)),
            ("constants", (coefficients,))), integrator
        assert rows[f"{integrator}:model_rotation:WHEELS"][0] == ("rotation and wheels", (general,))
        assert rows[f"{integrator}:model_rotation:PIVOT"] == (("rotation about the pivot", ("pivot_body_rhs",)),)
    assert [n for _, ns in rows["model_translation:FREE"] for n in ns] == ["translation_rhs"]
    assert [n for _, ns in rows["model_translation:JOINT_V"] for n in ns] == ["pivot_kinematics"]
