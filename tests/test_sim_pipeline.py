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
        called: set[str] = set()
        with monkeypatch.context() as m:
            for k in named | stage_kernels | {"rigid_body_rhs_c", "rigid_body_rhs_free_c"}:
                f = getattr(K, k)
                m.setattr(K, k, lambda *a, _f=f, _k=k, **kw: (called.add(_k), _f(*a, **kw))[1])
            sim.run(2)
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
    code = inspect.getsource(PL) + inspect.getsource(Sim._plain_line)
    assert not {n for n in names if re.search(rf"\b{n}\b", code)}


def test_float32_lines_say_they_are_not_itemized():
    sim = lv.Sim(scene(), dt=1e-3, backend="numpy", dtype="float32")
    assert all(line.endswith("(its kernels are not itemized)") for line in sim.pipeline[1:])
    assert "a torque-free body" in sim.pipeline[1] and "FORCE body" in sim.pipeline[2]


@pytest.mark.parametrize("integrator", ["implicit_gyro", "rk4_expmap"])
def test_structured_steps_say_they_are_not_itemized(integrator):
    """The implicit solve and the exp-map update run kernels of their own (their family, derive/tableaux.py): the
    line says so and names no right-hand side; an explicit tableau of the same Sim is itemized."""
    sim = lv.Sim(scene(), dt=1e-3, backend="numpy", integrator=integrator)
    assert all(line.endswith("(its kernels are not itemized)") for line in sim.pipeline[1:])
    assert not PL.kernel_names(sim.pipeline[1:])
    assert not PL.itemized(integrator) and PL.itemized("rk4") and PL.itemized("a_user_tableau")
