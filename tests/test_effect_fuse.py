"""The fused effect tiles' table (derive/effect_fuse.py, printed into kernels.h as LV_EFFECT_FUSED*): which effect
sequences batch_simd.h steps on a fused tile, and for which right-hand-side kinds, derived from the effect
declarations (the C stepping of those tiles is checked bitwise in tests/test_simd.py)."""
from __future__ import annotations

from pathlib import Path

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
