"""Fused tiles of user effects: the RK4 tile stepper with one user effect inlined, printed into the user's library.

A tile of plain bodies whose only effect is one user effect that reads the state steps, without a fused tile, in
stage passes (csrc/batch_simd.h LV_TILE_RK4_FX): per stage, a lane loop of the effect's tile form (a call into the
user's library), then a lane loop of the right-hand side. The fused tile is the plain tile's lane loop instead
(batch_simd.h LV_TILE_RK4: each lane's whole RK4 step in registers) with the effect's accumulating function
inlined: it needs the engine's printed kernels (the right-hand sides, lv_quat_normalize), its layout and its RK4
step (tableaux.h's LV_RK4_SCALED_STEP: the built-in RK4's scaled-increment form, each stage the kind's increments
kernels.h LV_RHS_INC_<kind> on the lane's rigid_body_increment_scale constants), so the user's library is compiled with the engine's generated sources on its
include path (lavendersim.user_sets: ``-DLVU_ENGINE=<their hash>``), and exports that hash (``lvu_engine_hash``):
the engine uses a fused tile only when it was compiled against the very sources it runs (else the stage passes).

Every lane does the stage passes' IEEE operations in their order: the effect sums start at LV_SUM_START (-0.0, IEEE's
additive identity, so gcc folds the first add) and the effect adds into them (its body-frame form for a body-frame
torque alone, FLAG_TORQUE_B), then the tile kind's increments (derive.effect_fuse.tile_kind and RHS_OF_KIND:
kernels.h's LV_RHS_INC_<kind>, as the stage passes call it); results are bitwise the stage passes'
(tests/test_extending.py checks it at every instruction set).

The copies keep GCC's default instruction scheduling, unlike the engine's AVX-512 tiles (batch_simd.h
LV_TILE_H_SCHED_avx512, the pre-register-allocation scheduler): measured on the guide's gravity_gradient (session 24,
GCC 12, Zen 4), that scheduler makes this tile slower. Its lane loop was 669 instructions per 8 bodies then (286
vmulpd, 223 vaddpd + 56 vsubpd, 9 vdivpd, 5 vsqrtpd; the plain torque-free tile's: 102 vmulpd, 101 adds; 512 in
session 26: 228 vmulpd, 141 vaddpd + 68 vsubpd, 4 vdivpd, 4 vsqrtpd, 42 stack references); the scheduler kept the
same arithmetic and raised the stack references from 75 to 95. ``lavendersim bench --only effect_cost``:
14.0-14.2 against 13.6-13.7 ns per body-step at N = 1e3 (3 alternating runs, load 5-6); the tile alone, called
through a pointer on 64 bodies: 12.9 against 12.3-12.5. "sched-pressure" with it, a 256-bit copy and a lane
loop unrolled by 2 were no faster either.
"""
from __future__ import annotations

from . import effect as E
from .effect_fuse import RHS_OF_KIND, tile_kind

NORMALIZE = (("raw", 0), ("norm", 1))   # q left / normalized after each step (the engine's LV_DEFINE_TILES order)


def fusable(decl: E.EffectDecl) -> bool:
    """Whether a user effect gets fused tiles: a force effect that reads the state (one that reads none is summed
    once per call by the engine, on the constant tiles)."""
    return decl.kind == "force" and bool(decl.flags & E.FLAG_USES_STATE)


def fused_name(decl: E.EffectDecl, normalize: str, isa: str) -> str:
    """The exported name of an effect's fused tile (normalize: "raw" or "norm"; isa: one of TILE_ISAS)."""
    return f"lvu_fused_tile{E.TILE_LANES}_{decl.name}_{normalize}_{isa}"


def c_fused_tiles(effects: list[E.EffectDecl], user_function) -> list[str]:
    """kernels.c's fused tiles of the fusable effects (compiled only with LVU_ENGINE defined, see the module
    docstring); user_function(decl, body) names an effect's exported accumulating function."""
    fused = [d for d in effects if fusable(d)]
    if not fused:
        return []
    n = E.TILE_LANES
    c = ["/* ---- Fused tiles (derive/effect_fuse_user.py): RK4 on a tile of bodies whose one effect is this one ---- */",
         "#if defined(LVU_ENGINE)", "#include <layout.h>", "#include <tableaux.h>", "#include <kernels.c>",
         f"#if LV_EFFECT_TILE != {n}", "#error \"the engine's tile width is not the one this set was derived for\"",
         "#endif", "LV_EXPORT const char lvu_engine_hash[] = LVU_ENGINE;",
         "#define LVU_FOR(stmt) for (i = 0; i < LV_STATE_SIZE; i++) stmt", "#define LVU_AT(v) v[i]", ""]
    args = (f"double (*restrict T)[{n}], const double (*restrict J)[{n}], const double (*restrict p)[{n}], "
            f"const double *restrict m_row, const double (*restrict I_row)[{n}], long m, double dt, long n_steps")
    for d in fused:
        kind = tile_kind(d.flags)
        body = RHS_OF_KIND[kind].body_frame
        np_ = max(d.n_params, 1)
        rhs = f"LVU_RHS_{d.name.upper()}"
        c += [f"/* {d.name}: tile kind {kind}; the lane's effect sums start at LV_SUM_START, as the stage passes' do */",
              f"#define {rhs}(in, out) do {{ double f[3] = LV_SUM_START3, t[3] = LV_SUM_START3; "
              f"{user_function(d, body)}(pl, in, in + LV_STATE_V_W, mass, I, f, t); "
              f"LV_RHS_INC_{kind}(in, mass, sc, f, t, out); }} while (0)"]
        macro = f"LVU_FUSED_{d.name.upper()}"
        lines = [f"#define {macro}(SUFFIX, ATTR, NORM, NORMALIZE)",
                 f"LV_EXPORT ATTR LVU_FLATTEN void lvu_fused_tile{n}_{d.name}_##NORM##_##SUFFIX({args})",
                 "{", "    long s, b;", "    int i;", f"    double SC[LV_INC_SCALE_SIZE][{n}];",
                 "    for (b = 0; b < m; b++) {   /* the lanes' increment constants, once per call */",
                 "        double cb[LV_EULER_SIZE], sb[LV_INC_SCALE_SIZE];",
                 "        for (i = 0; i < LV_EULER_SIZE; i++) cb[i] = J[i][b];",
                 "        lv_rigid_body_increment_scale(cb, m_row[b], LV_RK4_SCALE * dt, sb);",
                 "        for (i = 0; i < LV_INC_SCALE_SIZE; i++) SC[i][b] = sb[i];", "    }",
                 "    for (s = 0; s < n_steps; s++) {",
                 "        for (b = 0; b < m; b++) {",
                 "            double x[LV_STATE_SIZE], k[LV_STATE_SIZE], acc[LV_STATE_SIZE], tmp[LV_STATE_SIZE], "
                 f"xn[LV_STATE_SIZE], sc[LV_INC_SCALE_SIZE], pl[{np_}], I[3];",
                 "            const double mass = m_row[b];",
                 "            (void)mass;",
                 f"            for (i = 0; i < {d.n_params}; i++) pl[i] = p[i][b];" if d.n_params else "            pl[0] = 0.0;",
                 "            for (i = 0; i < 3; i++) I[i] = I_row[i][b];",
                 "            for (i = 0; i < LV_STATE_SIZE; i++) x[i] = T[i][b];",
                 "            for (i = 0; i < LV_INC_SCALE_SIZE; i++) sc[i] = SC[i][b];",
                 f"            LV_RK4_SCALED_STEP(double, {rhs}, LVU_FOR, LVU_AT, x, xn, k, acc, tmp);",
                 "            if (NORMALIZE) lv_quat_normalize(xn + LV_STATE_Q, xn + LV_STATE_Q);",
                 "            for (i = 0; i < LV_STATE_SIZE; i++) T[i][b] = xn[i];", "        }", "    }", "}"]
        c += [ln + " \\" for ln in lines[:-1]] + [lines[-1]]
        c += [f"#define {macro}_BOTH(SUFFIX, ATTR) {macro}(SUFFIX, ATTR, raw, 0) {macro}(SUFFIX, ATTR, norm, 1)",
              f"LVU_TILE_COPIES({macro}_BOTH)", ""]
    return c + ["#endif /* LVU_ENGINE */", ""]
