"""The fused effect tiles' table (derive/effect_fuse.py, printed into kernels.h as LV_EFFECT_FUSED*): which effect
sequences batch_simd.h steps on a fused tile, and for which right-hand-side kinds, derived from the effect
declarations (the C stepping of those tiles is checked bitwise in tests/test_simd.py)."""
from __future__ import annotations

from pathlib import Path

import pytest

from lavendersim.derive import effect as E
from lavendersim.derive import effect_fuse, effects
from lavendersim.derive.effect import STATE, effect, param

ROOT = Path(__file__).resolve().parent.parent


def _builtins() -> list[tuple[int, E.EffectDecl]]:
    return [(i + 1, d) for i, d in enumerate(d for d in effects.declarations() if d.kind == "force")]


def _named(pats) -> dict[tuple[str, ...], tuple[str, ...]]:
    names = {c: d.name for c, d in _builtins()}
    return {tuple(names[c] for c in codes): kinds for _, codes, kinds in pats}


def test_the_builtin_patterns_are_the_state_reading_effects_with_their_kinds():
    got = _named(effect_fuse.patterns(_builtins()))
    # gravity and applied_torque read no state: summed once per call, never in a pattern
    assert not {n for seq in got for n in seq} & {"gravity", "applied_torque"}
    assert got[("linear_damping", "angular_damping")] == ("FULL", "BODY_F")   # + applied_torque: FULL
    assert got[("angular_damping", "linear_damping")] == ("FULL", "BODY_F")
    assert got[("linear_damping",)] == ("FULL", "FORCE")
    assert got[("angular_damping",)] == ("TORQUE", "FULL", "BODY", "BODY_F")
    assert got[("force_at_point",)] == ("FULL",)
    assert len(got) == 3 + 3 * 2                     # three effects: 3 singles, 6 ordered distinct pairs
    assert all(len(seq) <= effect_fuse.FUSED_MAX for seq in got)
    ids = [p for p, _, _ in effect_fuse.patterns(_builtins())]
    assert ids == list(range(1, len(ids) + 1))


def test_the_kinds_follow_the_flags():
    assert effect_fuse.tile_kind(E.FLAG_TORQUE_B) == "BODY"
    assert effect_fuse.tile_kind(E.FLAG_TORQUE_B | E.FLAG_FORCE) == "BODY_F"
    assert effect_fuse.tile_kind(E.FLAG_TORQUE_B | E.FLAG_TORQUE_W) == "TORQUE"
    assert effect_fuse.tile_kind(E.FLAG_TORQUE_W | E.FLAG_FORCE | E.FLAG_USES_STATE) == "FULL"
    assert effect_fuse.tile_kind(E.FLAG_FORCE | E.FLAG_USES_V) == "FORCE"


def test_a_new_state_reading_builtin_joins_the_patterns_and_a_constant_one_widens_the_kinds():
    """The table is the declarations': a further state-reading effect gets its own patterns, and a constant effect
    adding a force makes the force-free patterns reachable in the force kinds too."""
    c = param("c", (), "N·s/m", "drag coefficient", rule="nonnegative")
    spin = effect("spin_drag_w", "world spin drag", [c], torque_w=-c.symbol * STATE.omega_w)
    F_w = param("F_w", 3, "N", "force, world frame")
    lift = effect("lift", "a constant force", [F_w], force_w=F_w.symbol)
    assert _kinds([(1, spin)]) == {("spin_drag_w",): ("TORQUE",)}
    assert _kinds([(1, spin), (2, lift)]) == {("spin_drag_w",): ("TORQUE", "FULL")}
    assert _kinds([(1, effects.declarations()[4]), (2, lift)]) == {("angular_damping",): ("BODY", "BODY_F")}


def _kinds(decls) -> dict[tuple[str, ...], tuple[str, ...]]:
    names = {c: d.name for c, d in decls}
    return {tuple(names[c] for c in codes): kinds for _, codes, kinds in effect_fuse.patterns(decls)}


def test_kernels_h_carries_the_table_and_batch_simd_names_no_effect():
    h = (ROOT / "generated" / "kernels.h").read_text()
    assert "#define LV_EFFECT_FUSED(X, ...) X(__VA_ARGS__, 1, 2, LV_EFFECT_FORCE_AT_POINT, LV_EFFECT_LINEAR_DAMPING)" in h
    assert "#define LV_EFFECT_FUSED_BODY(X, ...) X(__VA_ARGS__, 9, 1, LV_EFFECT_ANGULAR_DAMPING, 0)\n" in h
    assert f"#define LV_EFFECT_FUSED_COUNT {len(effect_fuse.patterns(_builtins()))}" in h
    simd = (ROOT / "lavendersim" / "csrc" / "batch_simd.h").read_text()
    for _, d in _builtins():
        assert f"LV_EFFECT_{d.name.upper()}" not in simd, d.name


def test_the_kinds_are_the_numpy_backends_rhs_classes():
    """derive's tile_kind is the one statement of the right-hand-side class rule: printed as a table into
    effects_meta (lavendersim.effects.rhs_classes, the NumPy backend, which has no separate world-torque-only class:
    TORQUE runs the FULL kernel, bitwise in C too) and kernels.h (csrc/step.c's rhs_class). Every combination of the
    three rhs flags gives tile_kind's class through the printed tables."""
    import numpy as np

    from lavendersim import effects as RT
    from lavendersim.generated import effects_meta

    assert (E.FLAG_FORCE, E.FLAG_TORQUE_W, E.FLAG_TORQUE_B) == (RT.FLAG_FORCE, RT.FLAG_TORQUE_W, RT.FLAG_TORQUE_B)
    assert effects_meta.RHS_BITS == effect_fuse.RHS_BITS
    assert effects_meta.RHS_KINDS_BY_FLAGS == effect_fuse.kinds_by_flags()
    python = {"BODY": RT.RHS_BODY, "BODY_F": RT.RHS_BODY_F, "FORCE": RT.RHS_FORCE, "FULL": RT.RHS_FULL,
              "TORQUE": RT.RHS_FULL}
    every = []
    for force in (0, E.FLAG_FORCE):
        for tw in (0, E.FLAG_TORQUE_W):
            for tb in (0, E.FLAG_TORQUE_B):
                for other in (0, E.FLAG_USES_STATE | E.FLAG_USES_V | E.FLAG_USES_OMEGA):   # flags the rule ignores
                    flags = force | tw | tb | other
                    kind = effect_fuse.tile_kind(flags)
                    every.append((flags, python[kind]))
                    assert python[kind] == int(RT.rhs_classes(np.array([flags]))[0]), (flags, kind)
                    assert (kind in ("TORQUE", "FULL")) == bool(tw), flags   # a world torque always rotates
                    if flags & ~other:   # (effects with none of the three flags run the force kernel on zero sums)
                        assert kind.endswith(("_F", "FULL", "FORCE")) == bool(force), flags
    flags_all, want = np.array([f for f, _ in every]).reshape(4, 4), np.array([c for _, c in every]).reshape(4, 4)
    assert np.array_equal(RT.rhs_classes(flags_all), want)   # elementwise, in the flags' shape


def test_kernels_h_prints_the_rhs_class_table_and_step_c_reads_it():
    """The C table: LV_RHS_KINDS_BY_FLAGS indexed by LV_RHS_FLAGS_INDEX, evaluated here as C would for every
    combination of the flags, gives tile_kind; step.c's rhs_class and effects.py's rhs_classes hold no copy of the
    rule (they name none of the flags)."""
    import re

    h = (ROOT / "generated" / "kernels.h").read_text()
    table = re.search(r"#define LV_RHS_KINDS_BY_FLAGS\(K\) \{(.*)\}\n", h).group(1)
    kinds = tuple(re.fullmatch(r"K\((\w+)\)", k.strip()).group(1) for k in table.split(","))
    index = re.search(r"#define LV_RHS_FLAGS_INDEX\(flags\) (.*)\n", h).group(1)
    bits = {"LV_EFFECT_FORCE": E.FLAG_FORCE, "LV_EFFECT_TORQUE_W": E.FLAG_TORQUE_W, "LV_EFFECT_TORQUE_B": E.FLAG_TORQUE_B}
    terms = re.findall(r"\(\(\(\(flags\) & (LV_EFFECT_\w+)\) != 0\) << (\d)\)", index)
    assert len(terms) == 3 and index.count("|") == 2, index
    for flags in range(64):
        i = sum(int(flags & bits[name] != 0) << int(j) for name, j in terms)
        assert kinds[i] == effect_fuse.tile_kind(flags), (flags, i)
    step = (ROOT / "lavendersim" / "csrc" / "step.c").read_text()
    body = step[step.index("static inline int rhs_class("):]
    body = body[:body.index("\n}\n")]
    assert "LV_RHS_BY_FLAGS[LV_RHS_FLAGS_INDEX(flags)]" in body and "LV_EFFECT_" not in body
    assert "LV_RHS_KINDS_BY_FLAGS(LV_RHS_OF_KIND)" in step
    eff = (ROOT / "lavendersim" / "effects.py").read_text()
    rule = eff[eff.index("def rhs_classes("):]
    rule = rule[:rule.index("\n\n\n")]
    assert "FLAG_" not in rule and "RHS_BITS" in rule


def _printed_rhs(h: str) -> tuple[dict[str, str], dict[str, str], str]:
    """kernels.h's LV_RHS_CALL_<kind> bodies, LV_RHS_BODY_FRAME_<kind> values and LV_RHS_KINDS list."""
    import re

    calls = dict(re.findall(r"#define LV_RHS_CALL_(\w+)\(x, mass, cf, f, t, out\) (.*)\n", h))
    frames = dict(re.findall(r"#define LV_RHS_BODY_FRAME_(\w+) (\d)\n", h))
    kinds = re.search(r"#define LV_RHS_KINDS\(X\) (.*)\n", h).group(1)
    return calls, frames, kinds


def test_each_kinds_right_hand_side_is_printed_once_and_the_backends_read_it():
    """derive's RHS_OF_KIND is the one statement of what a kind runs after its sums: kernels.h prints it per kind
    (LV_RHS_CALL_<kind>, LV_RHS_BODY_FRAME_<kind>), effects_meta its pipeline names; step.c's plain_rhs,
    batch_simd.h's effect tiles and fused tiles, the user's fused tiles and Sim.pipeline name no kernel of it."""
    from lavendersim.derive import effect_fuse_user
    from lavendersim.generated import effects_meta

    calls, frames, kinds = _printed_rhs((ROOT / "generated" / "kernels.h").read_text())
    assert kinds == " ".join(f"X({k})" for k in effect_fuse.TILE_KINDS)
    assert set(calls) == set(frames) == set(effect_fuse.TILE_KINDS) == set(effect_fuse.RHS_OF_KIND)
    kernels = ({f"lv_{r.kernel}(" for r in effect_fuse.RHS_OF_KIND.values()} | {"lv_linear_acceleration("}
               | {f"lv_{r.inc[0]}(" for r in effect_fuse.RHS_OF_KIND.values()})
    h = (ROOT / "generated" / "kernels.h").read_text()
    for kind, r in effect_fuse.RHS_OF_KIND.items():
        assert calls[kind] == effect_fuse.rhs_call_c(kind) and frames[kind] == str(int(r.body_frame)), kind
        # the built-in RK4's scaled increments of the kind: printed once, beside its right-hand side
        inc = f"#define LV_RHS_INC_{kind}({', '.join(effect_fuse.RHS_INC_PARAMS)}) {effect_fuse.rhs_inc_c(kind)}\n"
        assert h.count(inc) == 1 and f"lv_{r.inc[0]}(" in inc, kind
        assert f"lv_{r.kernel}(" in calls[kind] and ("lv_linear_acceleration(mass, f, f)" in calls[kind]) == r.accel
        assert effects_meta.RHS_KERNELS[kind] == r.pipeline
    assert {k for k, r in effect_fuse.RHS_OF_KIND.items() if r.body_frame} == {"BODY", "BODY_F"}
    assert effect_fuse.RHS_OF_KIND["BODY"].args[2] == "zero" and not effect_fuse.RHS_OF_KIND["BODY"].accel
    simd = (ROOT / "lavendersim" / "csrc" / "batch_simd.h").read_text()
    tiles = simd[simd.index("#define LV_TE_CASE(CODE)"):simd.index("#define LV_TF_DEFINE(")]
    assert "LV_RHS_INC_##KIND" in tiles and "LV_RHS_BODY_FRAME_##KIND" in tiles
    assert not [k for k in kernels if k in tiles], "batch_simd.h's effect tiles name a right-hand side"
    step = (ROOT / "lavendersim" / "csrc" / "step.c").read_text()
    # plain_rhs and plain_inc: one function body (LV_PLAIN_BY_CLASS) over the printed kinds, each calling its
    # kind's printed right-hand side (LV_RHS_CALL_<kind>) or increments (LV_RHS_INC_<kind>), naming no kernel
    plain = step[step.index("#define LV_PLAIN_OF("):step.index("#undef LV_PLAIN_OF")]
    assert "CALL##KIND(" in plain and "LV_RHS_KINDS(CASE)" in plain
    assert "LV_PLAIN_BY_CLASS(plain_rhs, LV_PLAIN_RHS_CASE, LV_RHS_CALL_," in plain
    assert "LV_PLAIN_BY_CLASS(plain_inc, LV_PLAIN_INC_CASE, LV_RHS_INC_," in plain
    assert not [k for k in kernels if k in plain] and "LV_RHS_BODY" not in plain.replace("LV_RHS_BODY_FRAME_##", "")
    # the constant kinds' tiles step each lane by step.c's lv_const_rk4_h on the printed per-kind flags
    const = simd[simd.index("#define LV_TILE_RK4_C("):simd.index("/* The torque-free tile:")]
    assert not [k for k in kernels if k in const] and "lv_const_rk4_h(" in const
    assert "LV_CONST_TORQUE_##KIND" in const and "LV_CONST_FORCE_##KIND" in const
    for kind, (torque, force) in effect_fuse.CONSTANT_KINDS.items():
        assert h.count(f"#define LV_CONST_TORQUE_{kind} {int(torque)}\n") == 1, kind
        assert h.count(f"#define LV_CONST_FORCE_{kind} {int(force)}\n") == 1, kind
    assert effects_meta.RHS_CONSTANT == effect_fuse.CONSTANT_KINDS
    c = param("c", (), "N·m·s", "drag")
    decls = [effect("w_drag", "world drag", [c], torque_w=-c.symbol * STATE.omega_w),           # TORQUE
             effect("b_drag", "body drag", [c], torque_b=-c.symbol * STATE.omega_b),            # BODY
             effect("v_drag", "linear drag", [c], force_w=-c.symbol * STATE.v_w),               # FORCE
             effect("vb_drag", "both", [c], force_w=-c.symbol * STATE.v_w, torque_b=-c.symbol * STATE.omega_b),
             effect("vw_drag", "both", [c], force_w=-c.symbol * STATE.v_w, torque_w=-c.symbol * STATE.omega_w)]
    fused = "\n".join(effect_fuse_user.c_fused_tiles(decls, lambda d, body: f"acc_{d.name}{'_b' * body}"))
    for d in decls:
        kind = effect_fuse.tile_kind(d.flags)
        assert f"acc_{d.name}{'_b' * effect_fuse.RHS_OF_KIND[kind].body_frame}(pl," in fused
        assert f"LV_RHS_INC_{kind}(in, mass, sc, f, t, out)" in fused, d.name
    assert sorted(effect_fuse.tile_kind(d.flags) for d in decls) == sorted(effect_fuse.TILE_KINDS)
    assert not [k for k in kernels if k in fused]
    sim = (ROOT / "lavendersim" / "sim.py").read_text()
    assert "rigid_body_rhs_force" not in sim and "rigid_body_rhs_body" not in sim


@pytest.mark.parametrize("integrator", ["rk4", "euler", "dopri5"])
def test_both_backends_run_and_name_each_kinds_right_hand_side(integrator):
    """A body of each kind, few (the scalar path's plain_rhs) and many (the effect tiles with rk4): C and NumPy
    bitwise, and Sim.pipeline names what each body's kind runs on each (derive's table): under euler and dopri5 the
    kind's right-hand side (RHS_OF_KIND; NumPy runs TORQUE on FULL's), under rk4 its increments or its path's."""
    import numpy as np

    import lavendersim as lv

    sets = {"TORQUE": [("applied_torque", {"torque_w": [1e-2, 0.0, -2e-2]}), ("angular_damping", {"c": 1e-2})],
            "FULL": [("gravity", {}), ("applied_torque", {"torque_w": [0.0, 1e-2, 0.0]}), ("linear_damping", {"c": 0.1})],
            "FORCE": [("linear_damping", {"c": 0.1})],
            "BODY": [("angular_damping", {"c": 1e-2})],
            "BODY_F": [("linear_damping", {"c": 0.1}), ("angular_damping", {"c": 1e-2})]}
    rng = np.random.default_rng(7)
    for per_kind in (1, 20):
        s = lv.Scene()
        for kind, effs in sets.items():
            for j in range(per_kind):
                name = f"{kind}{j}"
                s.add_body(lv.Body.box(name, 1.5, (0.3, 0.5, 0.7), omega_b=rng.standard_normal(3),
                                       v_w=rng.standard_normal(3)))
                for e, p in effs:
                    s.add_effect(e, body=name, **p)
        runs = {}
        for backend in ("c", "numpy"):
            sim = lv.Sim(s, dt=1e-2, integrator=integrator, backend=backend)
            for kind in sets:
                line = next(ln for ln in sim.pipeline if ln.startswith(f"{kind}0:"))
                r = effect_fuse.RHS_OF_KIND["FULL" if kind == "TORQUE" and backend == "numpy" else kind]
                if integrator == "rk4":   # world torques: the 13-number stages; the others decoupled
                    want = ("stages (13 numbers): " + r.inc[0] if kind in ("TORQUE", "FULL")
                            else "stages (q, omega_b): ")
                    assert want in line, (backend, line)
                else:
                    assert line.endswith("-> right-hand side: " + ("linear_acceleration, " if r.accel else "")
                                         + r.kernel), (backend, line)
            sim.run(50)
            runs[backend] = np.array([sim.state(f"{k}{j}").x for k in sets for j in range(per_kind)])
        np.testing.assert_array_equal(runs["c"], runs["numpy"])
