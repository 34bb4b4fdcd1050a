/* LavenderSim batched RK4 on struct-of-arrays tiles, vectorized by the compiler, with one copy per
   instruction set chosen at run time: torque-free bodies; bodies whose effects all read no state
   (LV_EFFECT_USES_STATE clear: applied_torque, gravity), whose force and torque sums are evaluated once
   per call with the generated effect dispatch (effect_sums) and passed to the generated
   lv_rigid_body_rhs_torque / lv_rigid_body_rhs in every stage, as the scalar path does; and bodies whose
   effects read the state, all with the same effects (the effect tiles, LV_TILE_RK4_FX: stage passes, each
   effect a lane loop of its generated form, a user effect its printed tile form; a pattern of built-in effects
   (kernels.h's LV_EFFECT_FUSED) takes a fused tile instead: the plain tile's lane loop with those codes compiled in).

   Speed (lavendersim bench, "SIMD batch"): x86's divider is not pipelined like the adders (AVX-512
   vdivpd: one per ~16 cycles for 8 lanes). The printed right-hand sides divide by nothing: the tile
   holds each body's Euler coefficients c_b (k_x = (I_y - I_z)/I_x, r_x = 1/I_x; the generated
   lv_euler_coefficients, 6 divisions per body once per call) instead of I_b, and the stages call the
   generated *_c kernels (bitwise the I_b kernels, the same printed arithmetic). What is left per step
   is the normalization's sqrt and division (the bench's "divider floor" loop, ~2 ns/body-step at
   AVX-512 against ~9-10 ns for the hand SoA peer: the adds and multiplies, not the divider, now bound
   a step). Included once by
   step.c, after the generated kernels (static functions; not a separate translation unit, so the
   kernels inline into every copy).

   Every equation is the generated one: a tile step calls the generated right-hand side and lv_quat_normalize
   on one body's numbers (local arrays the compiler turns into registers) and the RK4 constants come
   from tableaux.h, exactly as advance_free_rk4 does; the loop over the bodies of a tile is what the
   compiler vectorizes, one body per lane. A lane computes the same IEEE operations (+, -, *, /, sqrt
   are correctly rounded in vector and scalar form alike) in the same order as the scalar path, and
   nothing contracts a*b+c into an FMA (setup.py compiles with -ffp-contract=off; never -ffast-math), so
   every instruction set gives bitwise the scalar path's results (tests/test_simd.py proves it).

   A wheel built on one x86-64 machine runs on another: the AVX-512 and AVX2 copies carry their own
   target attribute and are called only when __builtin_cpu_supports says the CPU (and OS) has them;
   the baseline copy uses the build's flags (SSE2 on plain x86-64). Elsewhere only the baseline copy
   exists. */
#ifndef LAVENDERSIM_BATCH_SIMD_H
#define LAVENDERSIM_BATCH_SIMD_H

/* Bodies per tile: 13 + 13 (snapshot) + 6 (c_b) + 7 (P) rows of LV_TILE doubles stay in L1 over a chunk of steps
   (kernels.h's LV_EFFECT_TILE: the row stride of the effects' tile forms, lv_effect_tile_fn). */
#define LV_TILE LV_EFFECT_TILE
/* Groups of plain RK4 bodies smaller than this take the scalar block path (advance_free_rk4); a smaller tile is
   padded to LV_TILE_PAD(m) lanes (copies of its last body, never written back), so that the vector loop covers it
   (the compiler's scalar remainder loop costs ~6x a lane): N = 2 .. 8 bodies ran on the scalar blocks at 35-57 ns
   per body-step against 6.3 on the tiles. */
#define LV_TILE_MIN 2
#define LV_TILE_PAD(m) ((m) <= 4 ? 4 : ((m) + 7) / 8 * 8 < LV_TILE ? ((m) + 7) / 8 * 8 : LV_TILE)
/* The tiles' rows start on a 64-byte boundary (one cache line): an AVX-512 load or store of 8 lanes then never
   straddles two lines. On the stack a tile is otherwise only 16-byte aligned, so its alignment mod 64 followed the
   caller's stack depth: the bitwise torque-free tile ran 5.21-5.25 ns per body-step with rows 64- or 32-byte aligned
   and 5.71-5.73 at 16 bytes off (a standalone copy of the tile, AVX-512, Zen 4; the run-to-run swing 5.5 <-> 6.1 the
   bench showed). Layout only: the same operations on the same numbers. */
#if defined(__GNUC__) || defined(__clang__)
#define LV_ALIGN_TILE __attribute__((aligned(64)))
#elif defined(_MSC_VER)
#define LV_ALIGN_TILE __declspec(align(64))
#else
#define LV_ALIGN_TILE
#endif
/* Groups of model bodies smaller than this stay off the model tiles (model_simd.h). */
#define LV_SOA_MIN 16

/* Rows of a tile's per-body numbers P[k][b]: the mass, then the force and the torque (world) summed over the
   body's effects in table order when they all read no state (LV_EFFECT_USES_STATE clear), as effect_sums adds
   them at every stage (the same inputs give the same bits, so summing them once per call changes nothing), then
   the principal moments (the effects' I_b input). */
enum { LV_TP_M = 0, LV_TP_F = 1, LV_TP_TAU = 4, LV_TP_I = 7, LV_TP_ROWS = 10 };

/* Effects that read the state, on the tiles (effect tiles): every body of a tile has the same effects in the same
   order (codes[0 .. n_eff-1]; their parameters may differ per body), whose parameters are the rows
   EP[off[e] .. off[e] + n_params - 1] of the tile (lane b: body b's row of effect e); a user effect is called
   through its tile form utile[e] (lv_effect_tile_fn, printed by derive into the user's library). */
#define LV_TE_EFFECTS 8   /* at most this many effects per body */
#define LV_TE_PARAMS 32   /* at most this many parameters over a body's effects */
#define LV_TE_LANES 32    /* bodies per stage pass: ~60 rows of LV_TE_LANES doubles stay in L1 */
typedef struct {
    int n_eff;
    int codes[LV_TE_EFFECTS];
    int off[LV_TE_EFFECTS];
    lv_effect_tile_fn utile[LV_TE_EFFECTS];
    int fused; /* the fused tile of the effects' pattern (its LV_EFFECT_FUSED id, tile_fx_pattern), 0 none */
    lv_user_fused_fn ufused[2]; /* one user effect alone: its fused tile, q raw / normalized (NULL: none) */
    int first; /* the first effect of the pattern: effects 0 .. first-1 read no state (summed in P's F, TAU rows) */
    LV_ALIGN_TILE double EP[LV_TE_PARAMS + LV_EFFECT_ROW_MIN_PARAMS][LV_TILE]; /* + room for a lane's full-width load */
} lv_tile_fx;

typedef void (*lv_tile_fn)(double (*LV_RESTRICT T)[LV_TILE], const double (*LV_RESTRICT J)[LV_TILE],
                           const double (*LV_RESTRICT P)[LV_TILE], const lv_tile_fx *LV_RESTRICT fx, long m,
                           double dt, long n_steps);

#if defined(__GNUC__) || defined(__clang__)
#define LV_NOINLINE __attribute__((noinline))
#else
#define LV_NOINLINE
#endif

/* n_steps RK4 steps of the m bodies of a tile: T[k][b] = state number k of body b, J[k][b] = its Euler
   coefficient c_b[k] (LV_EULER_*).
   NORMALIZE: q normalized after each step (the generated kernel), as on the scalar path. LOAD, RHS (LV_TILE_RK4,
   the fused effect tiles): the lane's loads and its right-hand side. */
#define LV_TILE_FOR(stmt) for (i = 0; i < LV_STATE_SIZE; i++) stmt
#define LV_TILE_AT(v) v[i]
/* The lanes' constants of the scaled increments (rigid_body_increment_scale of J's Euler coefficients, P's mass and
   LV_RK4_SCALE dt), once per call: SC[k][b]. */
#define LV_TILE_SCALES(SC)                                                                              \
    for (b = 0; b < m; b++) {                                                                           \
        double cb[LV_EULER_SIZE], sb[LV_INC_SCALE_SIZE];                                                \
        for (i = 0; i < LV_EULER_SIZE; i++) cb[i] = J[i][b];                                            \
        lv_rigid_body_increment_scale(cb, P[LV_TP_M][b], LV_RK4_SCALE * dt, sb);                        \
        for (i = 0; i < LV_INC_SCALE_SIZE; i++) SC[i][b] = sb[i];                                       \
    }
/* The tiles of bodies with effects step the built-in RK4 in its scaled-increment form (tableaux.h
   LV_RK4_SCALED_STEP on the 13 numbers, RHS(in, out) the lane's increments on its constants sc), bitwise the scalar
   blocks' advance_free_rk4. */
#define LV_TILE_RK4(NORMALIZE, LOAD, RHS)                                                               \
    {                                                                                                   \
        LV_ALIGN_TILE double SC[LV_INC_SCALE_SIZE][LV_TILE];                                            \
        long s, b;                                                                                      \
        int i;                                                                                          \
        (void)fx;                                                                                       \
        LV_TILE_SCALES(SC)                                                                              \
        for (s = 0; s < n_steps; s++) {                                                                 \
            for (b = 0; b < m; b++) {                                                                   \
                double x[LV_STATE_SIZE], k[LV_STATE_SIZE], acc[LV_STATE_SIZE], tmp[LV_STATE_SIZE],      \
                    xn[LV_STATE_SIZE], sc[LV_INC_SCALE_SIZE];                                           \
                LOAD;                                                                                   \
                for (i = 0; i < LV_STATE_SIZE; i++) x[i] = T[i][b];                                     \
                for (i = 0; i < LV_INC_SCALE_SIZE; i++) sc[i] = SC[i][b];                               \
                LV_RK4_SCALED_STEP(double, RHS, LV_TILE_FOR, LV_TILE_AT, x, xn, k, acc, tmp);           \
                if (NORMALIZE) lv_quat_normalize(xn + LV_STATE_Q, xn + LV_STATE_Q);                    \
                for (i = 0; i < LV_STATE_SIZE; i++) T[i][b] = xn[i];                                    \
            }                                                                                           \
        }                                                                                               \
    }

/* The tiles of bodies whose effects all read no state (a constant kind KIND: TORQUE, FULL, FORCE): each lane one
   body's lv_const_rk4_h (step.c: (q, omega_b) staged alone, the translation by the constant force's exact flow or
   drift; bitwise the scalar blocks'), its LV_CONST_SIZE constants (lv_const_scale of J's Euler coefficients and P's
   mass and effect sums) taken once per call. A lane's constants are loaded in two loops of at most 16 numbers: GCC
   peels a loop of up to 16 iterations whole, and a loop left inside the lane loop keeps it from vectorizing (one
   loop of LV_CONST_SIZE = 18: the tile ran scalar, ~6x slower). */
#define LV_TILE_RK4_C(NORMALIZE, KIND)                                                                  \
    {                                                                                                   \
        LV_ALIGN_TILE double KC[LV_CONST_SIZE][LV_TILE];                                                \
        long s, b;                                                                                      \
        int i;                                                                                          \
        (void)fx;                                                                                       \
        for (b = 0; b < m; b++) {                                                                       \
            double cb[LV_EULER_SIZE], kb[LV_CONST_SIZE], F[3], tau[3];                                  \
            for (i = 0; i < LV_EULER_SIZE; i++) cb[i] = J[i][b];                                        \
            for (i = 0; i < 3; i++) {                                                                   \
                F[i] = P[LV_TP_F + i][b];                                                               \
                tau[i] = P[LV_TP_TAU + i][b];                                                           \
            }                                                                                           \
            lv_const_scale(cb, P[LV_TP_M][b], F, tau, dt, LV_CONST_FORCE_##KIND, kb);                   \
            for (i = 0; i < LV_CONST_SIZE; i++) KC[i][b] = kb[i];                                       \
        }                                                                                               \
        for (s = 0; s < n_steps; s++) {                                                                 \
            for (b = 0; b < m; b++) {                                                                   \
                double x[LV_STATE_SIZE], xn[LV_STATE_SIZE], kb[LV_CONST_SIZE];                          \
                for (i = 0; i < LV_STATE_SIZE; i++) x[i] = T[i][b];                                     \
                for (i = 0; i < LV_INC_SCALE_SIZE; i++) kb[i] = KC[i][b]; /* two loops of <= 16: each */  \
                for (i = LV_INC_SCALE_SIZE; i < LV_CONST_SIZE; i++) kb[i] = KC[i][b]; /* peeled whole */ \
                lv_const_rk4_h(x, xn, kb, dt, LV_CONST_TORQUE_##KIND, LV_CONST_FORCE_##KIND, NORMALIZE); \
                for (i = 0; i < LV_STATE_SIZE; i++) T[i][b] = xn[i];                                    \
            }                                                                                           \
        }                                                                                               \
    }

/* The torque-free tile: each lane one body's lv_free_rk4_h (step.c: the scaled-increment RK4 step, bitwise the
   scalar blocks'), its constants C (rows of LV_EULER_K_LEN) taken once per call. */
#define LV_TILE_RK4_H(NORMALIZE)                                                                        \
    {                                                                                                   \
        LV_ALIGN_TILE double C[LV_EULER_K_LEN][LV_TILE];                                                \
        double hq = 0.0;                                                                                \
        long s, b;                                                                                      \
        int i;                                                                                          \
        (void)fx;                                                                                       \
        (void)P;                                                                                        \
        for (b = 0; b < m; b++) {                                                                       \
            double cb[LV_EULER_SIZE], Cb[LV_EULER_K_LEN];                                               \
            for (i = 0; i < LV_EULER_SIZE; i++) cb[i] = J[i][b];                                        \
            hq = lv_free_rk4_scale(cb, dt, Cb);                                                         \
            for (i = 0; i < LV_EULER_K_LEN; i++) C[i][b] = Cb[i];                                       \
        }                                                                                               \
        for (s = 0; s < n_steps; s++) {                                                                 \
            for (b = 0; b < m; b++) {                                                                   \
                double x[LV_STATE_SIZE], xn[LV_STATE_SIZE], Cb[LV_EULER_K_LEN];                         \
                for (i = 0; i < LV_STATE_SIZE; i++) x[i] = T[i][b];                                     \
                for (i = 0; i < LV_EULER_K_LEN; i++) Cb[i] = C[i][b];                                   \
                lv_free_rk4_h(x, xn, Cb, hq, dt, NORMALIZE);                                            \
                for (i = 0; i < LV_STATE_SIZE; i++) T[i][b] = xn[i];                                    \
            }                                                                                           \
        }                                                                                               \
    }

/* The effect tiles' RK4 step, cut into lane loops (stage passes) as model_simd.h does: per stage, the effect sums at
   the stage input (F, TAU start at 0; one lane loop per effect, its code known outside the loop, so the
   generated dispatch lv_effect_apply inlines to that effect alone; effects add in table order), then the right-hand
   side's scaled increments (kernels.h LV_RHS_INC_<kind> on the lane's constants SC, LV_TILE_SCALES) and the
   scaled-increment RK4 combination (LV_RK4_SCALED_UPDATE, tableaux.h): every lane does the scalar path's IEEE
   operations in its order (advance_free_rk4 with effect_sums), so results are bitwise its. X: a stage's input, A:
   the running sum of the increments. */
#define LV_TE_CASE(CODE) LV_TE_CASE_WITH(CODE, lv_effect_apply)
#define LV_TE_CASE_B(CODE) LV_TE_CASE_WITH(CODE, lv_effect_apply_b)
#define LV_TE_CASE_WITH(CODE, APPLY)                                                                    \
    case CODE:                                                                                          \
        for (b = b0; b < b1; b++) {                                                                     \
            double x[LV_STATE_SIZE], p[LV_EFFECT_ROW_MIN_PARAMS], f[3], t[3], I[3];                     \
            for (i = 0; i < LV_STATE_SIZE; i++) x[i] = in[i][b];                                        \
            for (i = 0; i < LV_EFFECT_ROW_MIN_PARAMS; i++) p[i] = ep[i][b];                             \
            for (i = 0; i < 3; i++) {                                                                   \
                f[i] = F[i][b];                                                                         \
                t[i] = TAU[i][b];                                                                       \
                I[i] = P[LV_TP_I + i][b];                                                               \
            }                                                                                           \
            (void)APPLY(CODE, p, x, x + LV_STATE_V_W, P[LV_TP_M][b], I, f, t);                          \
            for (i = 0; i < 3; i++) {                                                                   \
                F[i][b] = f[i];                                                                         \
                TAU[i][b] = t[i];                                                                       \
            }                                                                                           \
        }                                                                                               \
        break;
/* The effect sums at the stage input IN (T, the step's start, or X), one lane loop per effect, added into F and TAU
   (zero: LV_TILE_RK4_FX zeroes them once per pass, LV_TE_STAGE again as it reads them, in its own lane loop, where
   the stores vectorize; zeroing here, a loop of its own per row, compiled to 6 memset calls per stage); CASE the case of a
   built-in effect (LV_TE_CASE: the generated dispatch lv_effect_apply; LV_TE_CASE_B: lv_effect_apply_b, for
   LV_RHS_BODY*: body-frame torques). */
#define LV_TE_SUMS(IN, CASE)                                                                            \
    for (e = 0; e < fx->n_eff; e++) {                                                                   \
        const double (*ep)[LV_TILE] = fx->EP + fx->off[e], (*in)[LV_TILE] = (const double (*)[LV_TILE])IN; \
        switch (fx->codes[e]) {                                                                         \
        LV_EFFECT_BUILTINS(CASE)                                                                        \
        default: fx->utile[e](b0, b1, in, ep, P[LV_TP_M], P + LV_TP_I, F, TAU); break;                   \
        }                                                                                               \
    }
/* A lane's right-hand side of kind KIND after its sums f, t (derive's rule, kernels.h's LV_RHS_INC_<kind>: its scaled increments), and the
   case of a built-in effect in its sums: the body dispatch when the kind's torques are body-frame forms
   (LV_RHS_BODY_FRAME_<kind>). */
#define LV_TE_RHS(KIND) LV_RHS_INC_##KIND(x, P[LV_TP_M][b], sc, f, t, k)
#define LV_TE_APPLY(KIND) LV_TE_APPLY_FRAME(LV_RHS_BODY_FRAME_##KIND)
#define LV_TE_APPLY_FRAME(BODY_FRAME) LV_TE_APPLY_FRAME_(BODY_FRAME)
#define LV_TE_APPLY_FRAME_(BODY_FRAME) LV_TE_APPLY_FRAME_##BODY_FRAME
#define LV_TE_APPLY_FRAME_0 LV_TE_CASE
#define LV_TE_APPLY_FRAME_1 LV_TE_CASE_B
/* Stage STAGE's right-hand side at its input IN and the RK4 combination: the next stage's input X and the weighted
   sum A, or (stage 4) the step's end in T. */
#define LV_TE_STAGE(STAGE, IN, RHS, NORMALIZE)                                                          \
    for (b = b0; b < b1; b++) {                                                                         \
        double x[LV_STATE_SIZE], k[LV_STATE_SIZE], sc[LV_INC_SCALE_SIZE], f[3], t[3];                   \
        for (i = 0; i < LV_STATE_SIZE; i++) x[i] = IN[i][b];                                            \
        for (i = 0; i < LV_INC_SCALE_SIZE; i++) sc[i] = SC[i][b];                                       \
        for (i = 0; i < 3; i++) {                                                                       \
            f[i] = F[i][b];                                                                             \
            t[i] = TAU[i][b];                                                                           \
            F[i][b] = TAU[i][b] = LV_SUM_START; /* the next stage's sums start (kernels.h) */           \
        }                                                                                               \
        RHS;                                                                                            \
        if (STAGE < 4) {                                                                                \
            for (i = 0; i < LV_STATE_SIZE; i++) (void)LV_RK4_SCALED_UPDATE(double, STAGE, T[i][b], k[i], A[i][b], X[i][b]); \
        } else {                                                                                        \
            double xn[LV_STATE_SIZE];                                                                   \
            for (i = 0; i < LV_STATE_SIZE; i++) (void)LV_RK4_SCALED_UPDATE(double, 4, T[i][b], k[i], A[i][b], xn[i]); \
            if (NORMALIZE) lv_quat_normalize(xn + LV_STATE_Q, xn + LV_STATE_Q);                        \
            for (i = 0; i < LV_STATE_SIZE; i++) T[i][b] = xn[i];                                        \
        }                                                                                               \
    }
#define LV_TILE_RK4_FX(NORMALIZE, KIND)                                                                 \
    {                                                                                                   \
        LV_ALIGN_TILE double X[LV_STATE_SIZE][LV_TILE];                                                 \
        LV_ALIGN_TILE double A[LV_STATE_SIZE][LV_TILE];                                                 \
        LV_ALIGN_TILE double F[3][LV_TILE];                                                             \
        LV_ALIGN_TILE double TAU[3][LV_TILE];                                                           \
        LV_ALIGN_TILE double SC[LV_INC_SCALE_SIZE][LV_TILE];                                            \
        long s, b, b0, b1;                                                                              \
        int i, e, st;                                                                                   \
        LV_TILE_SCALES(SC)                                                                              \
        for (b0 = 0; b0 < m; b0 = b1) {                                                                 \
            b1 = m - b0 < LV_TE_LANES ? m : b0 + LV_TE_LANES;                                           \
            for (i = 0; i < 3; i++)                                                                     \
                for (b = b0; b < b1; b++) F[i][b] = TAU[i][b] = LV_SUM_START;                           \
            for (s = 0; s < n_steps; s++) {                                                             \
                LV_TE_SUMS(T, LV_TE_APPLY(KIND))                                                        \
                LV_TE_STAGE(1, T, LV_TE_RHS(KIND), NORMALIZE)                                           \
                for (st = 2; st <= 4; st++) {                                                           \
                    LV_TE_SUMS(X, LV_TE_APPLY(KIND))                                                    \
                    if (st == 2) { LV_TE_STAGE(2, X, LV_TE_RHS(KIND), NORMALIZE) }                      \
                    else if (st == 3) { LV_TE_STAGE(3, X, LV_TE_RHS(KIND), NORMALIZE) }                 \
                    else { LV_TE_STAGE(4, X, LV_TE_RHS(KIND), NORMALIZE) }                              \
                }                                                                                       \
            }                                                                                           \
        }                                                                                               \
    }

/* The effect tiles' decoupled step (a body of class + LV_RHS_SPLIT, csrc/step.c rhs_kind: all effects built-in, none
   coupling, not all constant) when its effects fuse into no pattern: each lane one body's LV_SPLIT_RK4_H (step.c, as
   the scalar blocks), its torque sums through the body dispatch over the tile's codes in table order (LV_TE_SPLIT_SUMS)
   and its flow constants from their affine forces (lv_effect_affine, table order from LV_SUM_START, as
   lv_split_flow_scale). */
#define LV_TE_SPLIT_SUMS(xs, F, t)                                                                      \
    for (e = 0; e < fx->n_eff; e++)                                                                     \
        (void)lv_effect_apply_b(fx->codes[e], pe[e], xs, (xs) + LV_STATE_V_W, mass, I, F, t)
#define LV_TE_SPLIT_RHS_B(in, out) LV_SPLIT_H_ROT_B(in, out, LV_TE_SPLIT_SUMS)
#define LV_TE_SPLIT_LANE                                                                                \
    const double mass = P[LV_TP_M][b], I[3] = {P[LV_TP_I][b], P[LV_TP_I + 1][b], P[LV_TP_I + 2][b]};    \
    double pe[LV_TE_EFFECTS][LV_EFFECT_ROW_MIN_PARAMS];                                                 \
    for (e = 0; e < fx->n_eff; e++)                                                                     \
        for (i = 0; i < LV_EFFECT_ROW_MIN_PARAMS; i++) pe[e][i] = fx->EP[fx->off[e] + i][b];           \
    (void)pe
#define LV_TILE_RK4_FX_SPLIT(NORMALIZE, RHS)                                                            \
    {                                                                                                   \
        LV_ALIGN_TILE double SC[LV_INC_SCALE_SIZE][LV_TILE];                                            \
        LV_ALIGN_TILE double TF[LV_FLOW_SIZE][LV_TILE];                                                 \
        long s, b;                                                                                      \
        int i, e;                                                                                       \
        LV_TILE_SCALES(SC)                                                                              \
        for (b = 0; b < m; b++) {                                                                       \
            LV_TE_SPLIT_LANE;                                                                           \
            double f0[3] = LV_SUM_START3, kk = LV_SUM_START, tf[LV_FLOW_SIZE];                          \
            (void)I;                                                                                    \
            for (e = 0; e < fx->n_eff; e++) (void)lv_effect_affine(fx->codes[e], pe[e], mass, f0, &kk); \
            lv_translation_flow_scale(kk, f0, mass, dt, tf);                                            \
            for (i = 0; i < LV_FLOW_SIZE; i++) TF[i][b] = tf[i];                                        \
        }                                                                                               \
        for (s = 0; s < n_steps; s++) {                                                                 \
            for (b = 0; b < m; b++) {                                                                   \
                double x[LV_STATE_SIZE], xn[LV_STATE_SIZE], sc[LV_INC_SCALE_SIZE], tf[LV_FLOW_SIZE];    \
                LV_TE_SPLIT_LANE;                                                                       \
                (void)mass;                                                                             \
                (void)I;                                                                                \
                for (i = 0; i < LV_STATE_SIZE; i++) x[i] = T[i][b];                                     \
                for (i = 0; i < LV_INC_SCALE_SIZE; i++) sc[i] = SC[i][b];                               \
                for (i = 0; i < LV_FLOW_SIZE; i++) tf[i] = TF[i][b];                                    \
                LV_SPLIT_RK4_H(RHS, x, xn, sc, tf, NORMALIZE);                                          \
                for (i = 0; i < LV_STATE_SIZE; i++) T[i][b] = xn[i];                                    \
            }                                                                                           \
        }                                                                                               \
    }
#define LV_TE_SPLIT_TORQUE(NORMALIZE) /* world torques: not split (LV_RHS_SPLIT_TORQUE 0) */
#define LV_TE_SPLIT_FULL(NORMALIZE)
#define LV_TE_SPLIT_FORCE(NORMALIZE) LV_TILE_RK4_FX_SPLIT(NORMALIZE, LV_SPLIT_H_RHS_1)
#define LV_TE_SPLIT_BODY(NORMALIZE) LV_TILE_RK4_FX_SPLIT(NORMALIZE, LV_TE_SPLIT_RHS_B)
#define LV_TE_SPLIT_BODY_F(NORMALIZE) LV_TILE_RK4_FX_SPLIT(NORMALIZE, LV_TE_SPLIT_RHS_B)
/* Whether the effect tile fx steps decoupled (its kind allows it: LV_RHS_SPLIT_<kind> != 0): every effect built-in and
   none coupling (rhs_kind's rule; the tile's bodies are not all constant). */
static int tile_fx_decoupled(const lv_tile_fx *fx)
{
    int e;
    for (e = 0; e < fx->n_eff; e++)
        if (fx->codes[e] >= LV_EFFECT_USER_BASE || (lv_effect_flags(fx->codes[e]) & LV_EFFECT_COUPLED)) return 0;
    return fx->n_eff > 0;
}

/* The fused effect tiles: a pattern of built-in effects reading the state (kernels.h's LV_EFFECT_FUSED, printed by
   derive/effect_fuse.py; tile_fx_pattern finds it), each code known to the compiler, so that the generated dispatch
   inlines to that effect alone inside the plain tile's lane loop (LV_TILE_RK4: each lane's whole step in registers,
   no stage passes). The effects before the pattern read no state: their sums start F and TAU (P's rows, summed per
   call in table order as effect_sums adds them: the same bits), then each stage adds the pattern's effects in table
   order and takes the kind's right-hand side, as LV_TE_SUMS and LV_TE_RHS do, so results are bitwise the effect
   tiles' (and the scalar path's). Each kind's effect tile stepper NAME has one fused tile NAME_tf<id> per pattern of
   LV_EFFECT_FUSED_<kind>. */
#if LV_EFFECT_FUSED_MAX != 2
#error "batch_simd.h's fused tiles load two parameter rows (p0, p1): LV_EFFECT_FUSED_MAX changed"
#endif
#define LV_TF_LOAD                                                                                      \
    const double mass = P[LV_TP_M][b], I[3] = {P[LV_TP_I][b], P[LV_TP_I + 1][b], P[LV_TP_I + 2][b]};    \
    const double F0[3] = {P[LV_TP_F][b], P[LV_TP_F + 1][b], P[LV_TP_F + 2][b]};                         \
    const double T0[3] = {P[LV_TP_TAU][b], P[LV_TP_TAU + 1][b], P[LV_TP_TAU + 2][b]};                   \
    double p0[LV_EFFECT_ROW_MIN_PARAMS], p1[LV_EFFECT_ROW_MIN_PARAMS];                                  \
    for (i = 0; i < LV_EFFECT_ROW_MIN_PARAMS; i++) {                                                    \
        p0[i] = E0[i][b];                                                                               \
        p1[i] = E1[i][b];                                                                               \
    }
/* A stage's effect sums of the pattern (codes C0, C1; C1 0: none) at the lane's input in, through APPLY. */
#define LV_TF_SUMS(APPLY, C0, C1, in)                                                                   \
    double f[3] = {F0[0], F0[1], F0[2]}, t[3] = {T0[0], T0[1], T0[2]};                                  \
    (void)APPLY(C0, p0, in, in + LV_STATE_V_W, mass, I, f, t);                                          \
    if (C1 != 0) (void)APPLY(C1, p1, in, in + LV_STATE_V_W, mass, I, f, t)
/* A stage's right-hand side of kind KIND at in (LV_TILE_RK4's RHS(in, out)): the pattern's sums through the kind's
   dispatch (LV_RHS_BODY_FRAME_<kind>), then its increments (kernels.h's LV_RHS_INC_<kind>), as LV_TE_SUMS and
   LV_TE_RHS do. */
#define LV_TF_RHS(KIND, in, out) do { LV_TF_SUMS(LV_TF_APPLY(LV_RHS_BODY_FRAME_##KIND), lv_c0, lv_c1, in);      \
    LV_RHS_INC_##KIND(in, mass, sc, f, t, out); } while (0)
#define LV_TF_APPLY(BODY_FRAME) LV_TF_APPLY_(BODY_FRAME)
#define LV_TF_APPLY_(BODY_FRAME) LV_TF_APPLY_##BODY_FRAME
#define LV_TF_APPLY_0 lv_effect_apply
#define LV_TF_APPLY_1 lv_effect_apply_b
#define LV_TF_RHS_TORQUE(in, out) LV_TF_RHS(TORQUE, in, out)
#define LV_TF_RHS_FULL(in, out) LV_TF_RHS(FULL, in, out)
#define LV_TF_RHS_FORCE(in, out) LV_TF_RHS(FORCE, in, out)
#define LV_TF_RHS_BODY(in, out) LV_TF_RHS(BODY, in, out)
#define LV_TF_RHS_BODY_F(in, out) LV_TF_RHS(BODY_F, in, out)
/* The decoupled step of a fused tile (a pattern of LV_EFFECT_FUSED_SPLIT_<id> in a kind of LV_RHS_SPLIT_<kind> != 0:
   no effect couples translation and rotation, derive/effect.py FLAG_COUPLED): per lane and call, the affine force's
   sums F0 (P's constant rows, then the pattern's lv_effect_affine in table order) and k, and translation_flow_scale's
   constants TF; per step, the rotation alone (q, omega_b: 7 numbers) through the scaled-increment stages
   (LV_RK4_SCALED_STEP) with the pattern's torque sums at each stage input (the lane's 13 numbers xs, q and omega_b
   replaced), then translation_flow on (p_w, v_w). */
#define LV_SPLIT_ROWS (LV_STATE_Q_LEN + LV_STATE_OMEGA_B_LEN) /* y = (q, omega_b) */
#define LV_SPLIT_FOR(stmt) for (i = 0; i < LV_SPLIT_ROWS; i++) stmt
#define LV_SPLIT_ROT_1(in, out) lv_rigid_body_increments_free_c(in, in + LV_STATE_Q_LEN, sc + LV_INC_SCALE_C,  \
    sc[LV_INC_SCALE_HQ], out, out + LV_STATE_Q_LEN)
#define LV_SPLIT_ROT_2(in, out) lv_rigid_body_increments_rot_b_c(in, in + LV_STATE_Q_LEN, sc, t, out,           \
    out + LV_STATE_Q_LEN)
#define LV_SPLIT_ROT(SPLIT, in, out) LV_SPLIT_ROT_(SPLIT, in, out)
#define LV_SPLIT_ROT_(SPLIT, in, out) LV_SPLIT_ROT_##SPLIT(in, out)
#define LV_TF_ROT(KIND, in, out) do {                                                                   \
        for (i = 0; i < LV_STATE_Q_LEN; i++) xs[LV_STATE_Q + i] = in[i];                                 \
        for (i = 0; i < LV_STATE_OMEGA_B_LEN; i++) xs[LV_STATE_OMEGA_B + i] = in[LV_STATE_Q_LEN + i];    \
        {                                                                                               \
            LV_TF_SUMS(LV_TF_APPLY(LV_RHS_BODY_FRAME_##KIND), lv_c0, lv_c1, xs);                        \
            (void)f;                                                                                    \
            (void)t;                                                                                    \
            LV_SPLIT_ROT(LV_RHS_SPLIT_##KIND, in, out);                                                 \
        }                                                                                               \
    } while (0)
#define LV_TF_ROT_FORCE(in, out) LV_TF_ROT(FORCE, in, out)
#define LV_TF_ROT_BODY(in, out) LV_TF_ROT(BODY, in, out)
#define LV_TF_ROT_BODY_F(in, out) LV_TF_ROT(BODY_F, in, out)
#define LV_TF_SPLIT_TORQUE(NORMALIZE) /* world torques: not split (LV_RHS_SPLIT_TORQUE 0) */
#define LV_TF_SPLIT_FULL(NORMALIZE)
#define LV_TF_SPLIT_FORCE(NORMALIZE) LV_TILE_RK4_SPLIT(NORMALIZE, FORCE)
#define LV_TF_SPLIT_BODY(NORMALIZE) LV_TILE_RK4_SPLIT(NORMALIZE, BODY)
#define LV_TF_SPLIT_BODY_F(NORMALIZE) LV_TILE_RK4_SPLIT(NORMALIZE, BODY_F)
#define LV_TILE_RK4_SPLIT(NORMALIZE, KIND)                                                              \
    {                                                                                                   \
        LV_ALIGN_TILE double SC[LV_INC_SCALE_SIZE][LV_TILE];                                            \
        LV_ALIGN_TILE double TF[LV_FLOW_SIZE][LV_TILE];                                                 \
        long s, b;                                                                                      \
        int i;                                                                                          \
        LV_TILE_SCALES(SC)                                                                              \
        for (b = 0; b < m; b++) {                                                                       \
            LV_TF_LOAD                                                                                  \
            double f0[3] = {F0[0], F0[1], F0[2]}, kk = LV_SUM_START, tf[LV_FLOW_SIZE];                  \
            (void)T0;                                                                                   \
            (void)I;                                                                                    \
            (void)lv_effect_affine(lv_c0, p0, mass, f0, &kk);                                           \
            if (lv_c1 != 0) (void)lv_effect_affine(lv_c1, p1, mass, f0, &kk);                           \
            lv_translation_flow_scale(kk, f0, mass, dt, tf);                                            \
            for (i = 0; i < LV_FLOW_SIZE; i++) TF[i][b] = tf[i];                                        \
        }                                                                                               \
        for (s = 0; s < n_steps; s++) {                                                                 \
            for (b = 0; b < m; b++) {                                                                   \
                double xs[LV_STATE_SIZE], y[LV_SPLIT_ROWS], H[LV_SPLIT_ROWS], acc[LV_SPLIT_ROWS],       \
                    tmp[LV_SPLIT_ROWS], sc[LV_INC_SCALE_SIZE], tf[LV_FLOW_SIZE], pn[3], vn[3];          \
                LV_TF_LOAD                                                                              \
                for (i = 0; i < LV_STATE_SIZE; i++) xs[i] = T[i][b];                                    \
                for (i = 0; i < LV_INC_SCALE_SIZE; i++) sc[i] = SC[i][b];                               \
                for (i = 0; i < LV_FLOW_SIZE; i++) tf[i] = TF[i][b];                                    \
                lv_translation_flow(xs + LV_STATE_P_W, xs + LV_STATE_V_W, tf, pn, vn);                  \
                for (i = 0; i < LV_STATE_Q_LEN; i++) y[i] = xs[LV_STATE_Q + i];                         \
                for (i = 0; i < LV_STATE_OMEGA_B_LEN; i++) y[LV_STATE_Q_LEN + i] = xs[LV_STATE_OMEGA_B + i]; \
                LV_RK4_SCALED_STEP(double, LV_TF_ROT_##KIND, LV_SPLIT_FOR, LV_TILE_AT, y, y, H, acc, tmp);  \
                if (NORMALIZE) lv_quat_normalize(y, y);                                                 \
                for (i = 0; i < 3; i++) {                                                               \
                    T[LV_STATE_P_W + i][b] = pn[i];                                                     \
                    T[LV_STATE_V_W + i][b] = vn[i];                                                     \
                }                                                                                       \
                for (i = 0; i < LV_STATE_Q_LEN; i++) T[LV_STATE_Q + i][b] = y[i];                       \
                for (i = 0; i < LV_STATE_OMEGA_B_LEN; i++) T[LV_STATE_OMEGA_B + i][b] = y[LV_STATE_Q_LEN + i]; \
            }                                                                                           \
        }                                                                                               \
    }
/* The fused tile NAME_tf<ID> of the effect tile stepper NAME (kind KIND) for the pattern (ID, N, C0, C1): decoupled
   (LV_TILE_RK4_SPLIT) when the pattern and the kind allow it, else the 13-number stages. */
#define LV_TF_DEFINE(NAME, ATTR, NORMALIZE, KIND, ID, N, C0, C1)                                        \
    ATTR LV_FLATTEN LV_NOINLINE static void NAME##_tf##ID(double (*LV_RESTRICT T)[LV_TILE],             \
        const double (*LV_RESTRICT J)[LV_TILE], const double (*LV_RESTRICT P)[LV_TILE],                 \
        const lv_tile_fx *LV_RESTRICT fx, long m, double dt, long n_steps)                              \
    {                                                                                                   \
        const double (*E0)[LV_TILE] = fx->EP + fx->off[fx->first];                                      \
        const double (*E1)[LV_TILE] = fx->EP + fx->off[fx->first + (fx->n_eff > fx->first + 1)];        \
        enum { lv_c0 = C0, lv_c1 = C1 };                                                                \
        if (LV_EFFECT_FUSED_SPLIT_##ID && LV_RHS_SPLIT_##KIND != 0) {                                   \
            LV_TF_SPLIT_##KIND(NORMALIZE)                                                               \
        } else                                                                                          \
            LV_TILE_RK4(NORMALIZE, LV_TF_LOAD, LV_TF_RHS_##KIND)                                        \
    }
/* The call of the effect tile stepper NAME to its fused tile of pattern ID (a case of its switch on fx->fused). */
#define LV_TF_GO(NAME, ID, N, C0, C1) case ID: NAME##_tf##ID(T, J, P, fx, m, dt, n_steps); return;

#define LV_DEFINE_TILE(NAME, ATTR, NORMALIZE, KIND)                                                     \
    ATTR LV_FLATTEN static void NAME(double (*LV_RESTRICT T)[LV_TILE], const double (*LV_RESTRICT J)[LV_TILE], \
                                     const double (*LV_RESTRICT P)[LV_TILE], const lv_tile_fx *LV_RESTRICT fx, \
                                     long m, double dt, long n_steps)                                   \
    LV_TILE_RK4_C(NORMALIZE, KIND)
/* The torque-free tiles' instruction order: LV_TILE_H_SCHED_<isa> (step.h). */
#define LV_DEFINE_TILE_H(NAME, ATTR, NORMALIZE)                                                         \
    ATTR LV_FLATTEN static void NAME(double (*LV_RESTRICT T)[LV_TILE], const double (*LV_RESTRICT J)[LV_TILE], \
                                     const double (*LV_RESTRICT P)[LV_TILE], const lv_tile_fx *LV_RESTRICT fx, \
                                     long m, double dt, long n_steps)                                   \
    LV_TILE_RK4_H(NORMALIZE)
#define LV_DEFINE_TILE_FX(NAME, ATTR, NORMALIZE, KIND)                                                  \
    LV_EFFECT_FUSED_##KIND(LV_TF_DEFINE, NAME, ATTR, NORMALIZE, KIND)                                   \
    ATTR LV_FLATTEN static void NAME(double (*LV_RESTRICT T)[LV_TILE], const double (*LV_RESTRICT J)[LV_TILE], \
                                     const double (*LV_RESTRICT P)[LV_TILE], const lv_tile_fx *LV_RESTRICT fx, \
                                     long m, double dt, long n_steps)                                   \
    {                                                                                                   \
        if (fx->ufused[NORMALIZE] != NULL) { /* one user effect: its fused tile, in the user's library */    \
            fx->ufused[NORMALIZE](T, J, fx->EP, P[LV_TP_M], P + LV_TP_I, m, dt, n_steps);                \
            return;                                                                                     \
        }                                                                                               \
        switch (fx->fused) {                                                                            \
        LV_EFFECT_FUSED_##KIND(LV_TF_GO, NAME)                                                          \
        default: break;                                                                                 \
        }                                                                                               \
        if (LV_RHS_SPLIT_##KIND != 0 && tile_fx_decoupled(fx)) {                                        \
            LV_TE_SPLIT_##KIND(NORMALIZE)                                                               \
            return;                                                                                     \
        }                                                                                               \
        LV_TILE_RK4_FX(NORMALIZE, KIND)                                                                 \
    }

/* One instruction set's tile steppers: q normalized / not, times torque-free / constant torque /
   constant force and torque / effects reading the state, without / with a force. The tiles of bodies with effects
   (their fused tiles too) take the torque-free tiles' scheduling (LV_TILE_H_SCHED_<isa>): the same instructions, so
   the same bits; effect_cost at N = 1e3-1e5 (main 3b285c5 alternating, load 1.0): damping 7.4-8.2 against 7.7-8.6
   ns per body-step, gravity 5.9-6.7 against 6.0-7.0, applied torque 8.3-9.0 against 8.4-9.3. */
#define LV_DEFINE_TILES(SUFFIX, ATTR)                                                                   \
    LV_DEFINE_TILE_H(tile_rk4_norm_free_##SUFFIX, ATTR LV_TILE_H_SCHED_##SUFFIX, 1)                 \
    LV_DEFINE_TILE_H(tile_rk4_raw_free_##SUFFIX, ATTR LV_TILE_H_SCHED_##SUFFIX, 0)                  \
    LV_DEFINE_TILE(tile_rk4_norm_torque_##SUFFIX, ATTR LV_TILE_H_SCHED_##SUFFIX, 1, TORQUE)         \
    LV_DEFINE_TILE(tile_rk4_raw_torque_##SUFFIX, ATTR LV_TILE_H_SCHED_##SUFFIX, 0, TORQUE)          \
    LV_DEFINE_TILE(tile_rk4_norm_full_##SUFFIX, ATTR LV_TILE_H_SCHED_##SUFFIX, 1, FULL)             \
    LV_DEFINE_TILE(tile_rk4_raw_full_##SUFFIX, ATTR LV_TILE_H_SCHED_##SUFFIX, 0, FULL)              \
    LV_DEFINE_TILE_FX(tile_rk4_norm_fx_torque_##SUFFIX, ATTR LV_TILE_H_SCHED_##SUFFIX, 1, TORQUE)   \
    LV_DEFINE_TILE_FX(tile_rk4_raw_fx_torque_##SUFFIX, ATTR LV_TILE_H_SCHED_##SUFFIX, 0, TORQUE)    \
    LV_DEFINE_TILE_FX(tile_rk4_norm_fx_full_##SUFFIX, ATTR LV_TILE_H_SCHED_##SUFFIX, 1, FULL)       \
    LV_DEFINE_TILE_FX(tile_rk4_raw_fx_full_##SUFFIX, ATTR LV_TILE_H_SCHED_##SUFFIX, 0, FULL)        \
    LV_DEFINE_TILE(tile_rk4_norm_force_##SUFFIX, ATTR LV_TILE_H_SCHED_##SUFFIX, 1, FORCE)           \
    LV_DEFINE_TILE(tile_rk4_raw_force_##SUFFIX, ATTR LV_TILE_H_SCHED_##SUFFIX, 0, FORCE)            \
    LV_DEFINE_TILE_FX(tile_rk4_norm_fx_force_##SUFFIX, ATTR LV_TILE_H_SCHED_##SUFFIX, 1, FORCE)     \
    LV_DEFINE_TILE_FX(tile_rk4_raw_fx_force_##SUFFIX, ATTR LV_TILE_H_SCHED_##SUFFIX, 0, FORCE)      \
    LV_DEFINE_TILE_FX(tile_rk4_norm_fx_body_##SUFFIX, ATTR LV_TILE_H_SCHED_##SUFFIX, 1, BODY)       \
    LV_DEFINE_TILE_FX(tile_rk4_raw_fx_body_##SUFFIX, ATTR LV_TILE_H_SCHED_##SUFFIX, 0, BODY)        \
    LV_DEFINE_TILE_FX(tile_rk4_norm_fx_body_f_##SUFFIX, ATTR LV_TILE_H_SCHED_##SUFFIX, 1, BODY_F)   \
    LV_DEFINE_TILE_FX(tile_rk4_raw_fx_body_f_##SUFFIX, ATTR LV_TILE_H_SCHED_##SUFFIX, 0, BODY_F)

LV_ISA_COPIES(LV_DEFINE_TILES)

/* The opt-in FMA copies (lv_contract_set(LV_CONTRACT_FMA), Sim(..., contract="fma")), torque-free bodies: only q and
   omega_b go through the stages, in the default tiles' scaled-increment form (the printed
   rigid_body_increments_free_c on the constants of lv_free_rk4_scale, once per call) with the printed
   LV_RK4_SCALED_UPDATE_FUSED; p_w drifts by v_w (the printed translation_drift: v_w' = 0, RK4 is one Euler step there)
   and v_w stays as it is. Compiled with -ffp-contract=fast for CPUs with FMA, so the compiler fuses a*b+c into one
   rounding: not bitwise the scalar path nor NumPy (README and docs/performance.md give the measured difference).
   Why this shape (Zen 4: multiplies and FMAs share two pipes, adds have two more): the increments' products fuse
   into their sums, the stage sums stay adds (FUSED: a multiple 2 as two adds, since GCC folds H + H into 2 H and
   fuses that into the sum); omega_b's increments (one product each) still fuse into each of their sums. The AVX-512
   lane loop: 48 vmulpd, 68 FMAs, 43 vaddpd per 8 bodies. Measured (lavendersim bench --only simd, AVX-512, N = 1e3 /
   1e4, load 4-6, alternating with main): 4.30-4.40 ns per body-step against 4.50-4.57 for the old stage form
   (LV_RK4_UPDATE, its stage sums FMAs: 42 vmulpd + 85 FMAs); the scaled form with LV_RK4_SCALED_UPDATE read the same
   as the old (51 + 74: GCC's 2 H), uncontracted 4.45 (104 vmulpd, 104 adds). q is renormalized without the divider
   by the printed quat_renormalize_near_unit (tile_q_normalize_far below: its range and the exact fallback). */
/* The FMA tiles' normalization, q p(eps) (the printed quat_renormalize_near_unit: no sqrt, no division), holds
   while |eps| = ||q|^2 - 1| <= LV_QUAT_RENORM_EPS_MAX; a lane beyond it (a state written far from unit, a wild step,
   NaN) keeps its raw q in the step's lane loop and is flagged, and then this pass gives it q / |q| (the printed
   quat_normalize) before the next step reads it: never a norm the series got wrong. Off the vector loop. */
LV_NOINLINE static void tile_q_normalize_far(double (*LV_RESTRICT T)[LV_TILE], long m)
{
    long b;
    int i;
    for (b = 0; b < m; b++) {
        double q[LV_STATE_Q_LEN], qn[LV_STATE_Q_LEN], eps;
        for (i = 0; i < LV_STATE_Q_LEN; i++) q[i] = T[LV_STATE_Q + i][b];
        lv_quat_renormalize_near_unit(q, qn, &eps);
        if (fabs(eps) <= LV_QUAT_RENORM_EPS_MAX) continue; /* this lane took the series */
        lv_quat_normalize(q, q);
        for (i = 0; i < LV_STATE_Q_LEN; i++) T[LV_STATE_Q + i][b] = q[i];
    }
}
/* Stage STAGE of the scaled-increment RK4 step (as lv_free_rk4_h, with tableaux.h's LV_RK4_SCALED_UPDATE_FUSED: the
   same program, its multiples 2 as two adds): the printed increments H = (s dt) (dq/dt, domega_b/dt) at (IN_Q, IN_W) on
   the lane's constants (Cb, hq), then the running sums (aq, aw) and the next stage's input or (stage 4) the step's end
   in (OUT_Q, OUT_W). */
#define LV_TILE_STAGED(STAGE, IN_Q, IN_W, OUT_Q, OUT_W)                                                 \
    lv_rigid_body_increments_free_c(IN_Q, IN_W, Cb, hq, Hq, Hw);                                        \
    for (i = 0; i < LV_STATE_Q_LEN; i++) (void)LV_RK4_SCALED_UPDATE_FUSED(double, STAGE, q0[i], Hq[i], aq[i], OUT_Q[i]); \
    for (i = 0; i < LV_STATE_OMEGA_B_LEN; i++) (void)LV_RK4_SCALED_UPDATE_FUSED(double, STAGE, w0[i], Hw[i], aw[i], OUT_W[i])
#define LV_DEFINE_TILE_STAGED(NAME, ATTR, NORMALIZE)                                                    \
    ATTR LV_FLATTEN static void NAME(double (*LV_RESTRICT T)[LV_TILE], const double (*LV_RESTRICT J)[LV_TILE], \
                                     const double (*LV_RESTRICT P)[LV_TILE], const lv_tile_fx *LV_RESTRICT fx, \
                                     long m, double dt, long n_steps)                                   \
    {                                                                                                   \
        LV_ALIGN_TILE double C[LV_EULER_K_LEN][LV_TILE];                                                \
        double hq = 0.0;                                                                                \
        long s, b;                                                                                      \
        int i;                                                                                          \
        (void)fx;                                                                                       \
        (void)P;                                                                                        \
        for (b = 0; b < m; b++) { /* the lanes' constants, once per call (lv_free_rk4_scale) */         \
            double cb[LV_EULER_SIZE], Cb[LV_EULER_K_LEN];                                               \
            for (i = 0; i < LV_EULER_SIZE; i++) cb[i] = J[i][b];                                        \
            hq = lv_free_rk4_scale(cb, dt, Cb);                                                         \
            for (i = 0; i < LV_EULER_K_LEN; i++) C[i][b] = Cb[i];                                       \
        }                                                                                               \
        for (s = 0; s < n_steps; s++) {                                                                 \
            long far = 0; /* a lane whose |q|^2 - 1 is beyond QUAT_RENORM_EPS_MAX this step */          \
            for (b = 0; b < m; b++) {                                                                   \
                double q0[LV_STATE_Q_LEN], w0[LV_STATE_OMEGA_B_LEN], Cb[LV_EULER_K_LEN], Hq[LV_STATE_Q_LEN], \
                    Hw[LV_STATE_OMEGA_B_LEN], aq[LV_STATE_Q_LEN], aw[LV_STATE_OMEGA_B_LEN], tq[LV_STATE_Q_LEN], \
                    tw[LV_STATE_OMEGA_B_LEN];                                                           \
                for (i = 0; i < LV_STATE_Q_LEN; i++) q0[i] = T[LV_STATE_Q + i][b];                      \
                for (i = 0; i < LV_STATE_OMEGA_B_LEN; i++) w0[i] = T[LV_STATE_OMEGA_B + i][b];          \
                for (i = 0; i < LV_EULER_K_LEN; i++) Cb[i] = C[i][b];                                   \
                LV_TILE_STAGED(1, q0, w0, tq, tw);                                                      \
                LV_TILE_STAGED(2, tq, tw, tq, tw);                                                      \
                LV_TILE_STAGED(3, tq, tw, tq, tw);                                                      \
                LV_TILE_STAGED(4, tq, tw, tq, tw);                                                      \
                if (NORMALIZE) { /* q's direction kept; in range its norm 1 to rounding, else q left for the tile's pass */ \
                    double qn[LV_STATE_Q_LEN], eps;                                                     \
                    lv_quat_renormalize_near_unit(tq, qn, &eps);                                        \
                    const int near = fabs(eps) <= LV_QUAT_RENORM_EPS_MAX; /* false for NaN */           \
                    far |= !near;                                                                       \
                    for (i = 0; i < LV_STATE_Q_LEN; i++) T[LV_STATE_Q + i][b] = near ? qn[i] : tq[i];   \
                } else {                                                                                \
                    for (i = 0; i < LV_STATE_Q_LEN; i++) T[LV_STATE_Q + i][b] = tq[i];                  \
                }                                                                                       \
                for (i = 0; i < LV_STATE_OMEGA_B_LEN; i++) T[LV_STATE_OMEGA_B + i][b] = tw[i];          \
                { /* p_w drifts by v_w (the printed translation_drift; v_w' = 0: RK4 is one Euler step there) */ \
                    double p[LV_STATE_P_W_LEN], v[LV_STATE_V_W_LEN];                                    \
                    for (i = 0; i < LV_STATE_P_W_LEN; i++) p[i] = T[LV_STATE_P_W + i][b];               \
                    for (i = 0; i < LV_STATE_V_W_LEN; i++) v[i] = T[LV_STATE_V_W + i][b];               \
                    lv_translation_drift(p, v, dt, p);                                                  \
                    for (i = 0; i < LV_STATE_P_W_LEN; i++) T[LV_STATE_P_W + i][b] = p[i];               \
                }                                                                                       \
            }                                                                                           \
            if (far) tile_q_normalize_far(T, m);                                                        \
        }                                                                                               \
    }
#if LV_HAVE_ISA_CLONES && defined(__GNUC__) && !defined(__clang__)
#define LV_HAVE_FMA_TILES 1
#pragma GCC push_options
#pragma GCC optimize("fp-contract=fast")
LV_DEFINE_TILE_STAGED(tile_rk4_norm_free_fma_avx2, __attribute__((target("avx2,fma"))), 1)
LV_DEFINE_TILE_STAGED(tile_rk4_raw_free_fma_avx2, __attribute__((target("avx2,fma"))), 0)
LV_DEFINE_TILE_STAGED(tile_rk4_norm_free_fma_avx512, __attribute__((target("avx512f,fma"))) LV_TILE_H_SCHED_avx512, 1)
LV_DEFINE_TILE_STAGED(tile_rk4_raw_free_fma_avx512, __attribute__((target("avx512f,fma"))) LV_TILE_H_SCHED_avx512, 0)
#pragma GCC pop_options
#else
#define LV_HAVE_FMA_TILES 0
#endif
#if defined(__GNUC__) || defined(__clang__)
static __thread int lv_contract_mode = LV_CONTRACT_OFF;
#else
static int lv_contract_mode = LV_CONTRACT_OFF;
#endif

int lv_contract_available(void)
{
#if LV_HAVE_FMA_TILES
    return lv_isa_best() >= LV_ISA_AVX2 && __builtin_cpu_supports("fma");
#else
    return 0;
#endif
}

int lv_contract_set(int mode)
{
    const int old = lv_contract_mode;
    lv_contract_mode = mode == LV_CONTRACT_FMA ? LV_CONTRACT_FMA : LV_CONTRACT_OFF;
    return old;
}

/* The FMA copy of the torque-free tile stepper at isa, or NULL (bitwise mode, no FMA copy or CPU support, or an
   instruction set below AVX2). */
static lv_tile_fn tile_rk4_free_fma(int isa, int normalize)
{
#if LV_HAVE_FMA_TILES
    if (lv_contract_mode != LV_CONTRACT_FMA || isa < LV_ISA_AVX2 || !lv_contract_available()) return NULL;
    if (isa == LV_ISA_AVX512) return normalize ? tile_rk4_norm_free_fma_avx512 : tile_rk4_raw_free_fma_avx512;
    return normalize ? tile_rk4_norm_free_fma_avx2 : tile_rk4_raw_free_fma_avx2;
#else
    (void)isa;
    (void)normalize;
    return NULL;
#endif
}

/* The tile stepper of instruction set isa (LV_ISA_*; one this CPU supports, see lv_isa_best) for the bodies of
   rhs_kind class cls (step.c: LV_RHS_FREE; LV_RHS_TORQUE / LV_RHS_FULL with effects that read the state, the
   effect tiles; + LV_RHS_CONSTANT with constant ones, see LV_TP_*), a group of count bodies. */
static lv_tile_fn tile_rk4_fn(int isa, int normalize, int cls, long count)
{
    if (count <= 4 && isa == LV_ISA_AVX512) isa = LV_ISA_AVX2; /* a tile of 4 lanes: AVX2's width */
    switch (cls) {
    case LV_RHS_FREE:
        if (tile_rk4_free_fma(isa, normalize) != NULL) return tile_rk4_free_fma(isa, normalize);
        return normalize ? LV_ISA_PICK(isa, tile_rk4_norm_free) : LV_ISA_PICK(isa, tile_rk4_raw_free);
    case LV_RHS_TORQUE: return normalize ? LV_ISA_PICK(isa, tile_rk4_norm_fx_torque) : LV_ISA_PICK(isa, tile_rk4_raw_fx_torque);
    case LV_RHS_FULL: return normalize ? LV_ISA_PICK(isa, tile_rk4_norm_fx_full) : LV_ISA_PICK(isa, tile_rk4_raw_fx_full);
    case LV_RHS_TORQUE + LV_RHS_CONSTANT:
        return normalize ? LV_ISA_PICK(isa, tile_rk4_norm_torque) : LV_ISA_PICK(isa, tile_rk4_raw_torque);
    case LV_RHS_FORCE: return normalize ? LV_ISA_PICK(isa, tile_rk4_norm_fx_force) : LV_ISA_PICK(isa, tile_rk4_raw_fx_force);
    case LV_RHS_FORCE + LV_RHS_CONSTANT:
        return normalize ? LV_ISA_PICK(isa, tile_rk4_norm_force) : LV_ISA_PICK(isa, tile_rk4_raw_force);
    case LV_RHS_BODY: return normalize ? LV_ISA_PICK(isa, tile_rk4_norm_fx_body) : LV_ISA_PICK(isa, tile_rk4_raw_fx_body);
    case LV_RHS_BODY_F:
        return normalize ? LV_ISA_PICK(isa, tile_rk4_norm_fx_body_f) : LV_ISA_PICK(isa, tile_rk4_raw_fx_body_f);
    case LV_RHS_FORCE + LV_RHS_SPLIT: case LV_RHS_BODY + LV_RHS_SPLIT: case LV_RHS_BODY_F + LV_RHS_SPLIT:
        return tile_rk4_fn(isa, normalize, cls - LV_RHS_SPLIT, count); /* their kind's effect tiles decide it */
    default: return normalize ? LV_ISA_PICK(isa, tile_rk4_norm_full) : LV_ISA_PICK(isa, tile_rk4_raw_full);
    }
}

/* Whether every effect on plain body b reads no state (a built-in effect without LV_EFFECT_USES_STATE):
   its force and torque sums are then constant and the body may take the SIMD tiles with effects. */
static int effects_constant(const lv_effect_index *ix, long b)
{
    long k;
    if (ix->flags[b] & LV_EFFECT_USES_STATE) return 0;
    for (k = ix->start[b]; k < ix->start[b + 1]; k++)
        if (ix->refs[k].user != NULL) return 0;
    return 1;
}

/* Effect `code`'s parameter count and, for a user effect, its tile form at instruction set isa (NULL: none, and
   then the effect stays off the tiles); body: the group's torques are all body-frame (LV_RHS_BODY*), so a user
   effect with a body-frame form (LV_EFFECT_TORQUE_B) is called through that form's tile form, as effect_sums_b
   calls its body-frame form. */
static int tile_effect_info(const lv_effect_index *ix, int code, int isa, int body, lv_effect_tile_fn *tile)
{
    const lv_user_effect *u;
    *tile = NULL;
    if (code < LV_EFFECT_USER_BASE) return lv_effect_n_params(code);
    if (ix->user == NULL || code - LV_EFFECT_USER_BASE >= ix->user->n || isa < LV_ISA_BASE || isa > LV_ISA_AVX512)
        return -1;
    u = &ix->user->entries[code - LV_EFFECT_USER_BASE];
    *tile = body && u->fn_b != NULL ? u->tile_b[isa - LV_ISA_BASE] : u->tile[isa - LV_ISA_BASE];
    return *tile != NULL ? u->n_params : -1;
}

/* Whether plain body b's torques are all body-frame (its right-hand side class LV_RHS_BODY*). */
static int tile_body_frame(const lv_effect_index *ix, long b)
{
    return rhs_class(ix->start[b + 1] - ix->start[b], ix->flags[b]) >= LV_RHS_BODY;
}

/* Whether the bodies list[0 .. count-1] may take the effect tiles at instruction set isa: each has the same
   effects in the same order (the codes; parameters may differ), built in or user effects with a tile form, at
   most LV_TE_EFFECTS of them with at most LV_TE_PARAMS parameters. */
static int effects_tileable(const lv_effect_index *ix, const long *list, long count, int isa)
{
    const long n = count > 0 ? ix->start[list[0] + 1] - ix->start[list[0]] : 0;
    const lv_effect_ref *r0 = count > 0 ? ix->refs + ix->start[list[0]] : NULL;
    lv_effect_tile_fn tile;
    long j, k, n_par = 0;
    if (n < 1 || n > LV_TE_EFFECTS) return 0;
    for (k = 0; k < n; k++) {
        const int np = tile_effect_info(ix, r0[k].code, isa, tile_body_frame(ix, list[0]), &tile);
        if (np < 0) return 0;
        n_par += np;
    }
    if (n_par > LV_TE_PARAMS) return 0;
    for (j = 1; j < count; j++) {
        const lv_effect_ref *r = ix->refs + ix->start[list[j]];
        if (ix->start[list[j] + 1] - ix->start[list[j]] != n) return 0;
        for (k = 0; k < n; k++)
            if (r[k].code != r0[k].code) return 0;
    }
    return 1;
}

/* The fused tile of the effect tile fx (its id in LV_EFFECT_FUSED, see LV_TF_DEFINE): after a run of built-in effects
   that read no state (fx->first of them), the pattern left; 0 for any other set (the effect tile's stage passes). */
#define LV_TF_ROW(UNUSED, ID, N, C0, C1) {ID, N, {C0, C1}},
static void tile_fx_pattern(lv_tile_fx *fx)
{
    static const struct { int fused, n, c[LV_EFFECT_FUSED_MAX]; } pats[LV_EFFECT_FUSED_COUNT] = {LV_EFFECT_FUSED(LV_TF_ROW, ~)};
    const int *c = fx->codes;
    int f = 0, k, e;
    while (f < fx->n_eff && c[f] < LV_EFFECT_USER_BASE && !(lv_effect_flags(c[f]) & LV_EFFECT_USES_STATE)) f++;
    fx->fused = 0;
    fx->first = 0;
    for (k = 0; k < LV_EFFECT_FUSED_COUNT; k++) {
        if (fx->n_eff - f != pats[k].n) continue;
        for (e = 0; e < pats[k].n && c[f + e] == pats[k].c[e]; e++) {}
        if (e == pats[k].n) {
            fx->fused = pats[k].fused;
            fx->first = f;
        }
    }
}

/* The effect tiles' codes and per-lane parameters (lv_tile_fx) of the m bodies ids, from the index ix (bodies
   effects_tileable accepts). */
static void tile_fx_fill(lv_tile_fx *fx, const lv_effect_index *ix, const long *ids, long m)
{
    const lv_effect_ref *r0 = ix->refs + ix->start[ids[0]];
    long j;
    int e, k, o = 0;
    fx->n_eff = (int)(ix->start[ids[0] + 1] - ix->start[ids[0]]);
    if (fx->n_eff > LV_TE_EFFECTS) fx->n_eff = 0; /* (not an effect tile: unused) */
    for (e = 0; e < fx->n_eff; e++) {
        const int np = tile_effect_info(ix, r0[e].code, lv_isa_get(), tile_body_frame(ix, ids[0]), &fx->utile[e]);
        fx->codes[e] = r0[e].code;
        fx->off[e] = o;
        for (j = 0; j < m; j++) {
            const double *p = ix->refs[ix->start[ids[j]] + e].p;
            for (k = 0; k < np && o + k < LV_TE_PARAMS; k++) fx->EP[o + k][j] = p[k];
        }
        o += np;
    }
    tile_fx_pattern(fx);
    fx->ufused[0] = fx->ufused[1] = NULL;
    if (fx->n_eff == 1 && fx->codes[0] >= LV_EFFECT_USER_BASE) { /* (tile_effect_info found its entry) */
        const lv_user_effect *u = &ix->user->entries[fx->codes[0] - LV_EFFECT_USER_BASE];
        const int isa = lv_isa_get();
        if (isa >= LV_ISA_BASE && isa <= LV_ISA_AVX512) {
            fx->ufused[0] = u->fused[0][isa - LV_ISA_BASE];
            fx->ufused[1] = u->fused[1][isa - LV_ISA_BASE];
        }
    }
}

static int tile_finite(const double (*T)[LV_TILE], long j)
{
    int k;
    for (k = 0; k < LV_STATE_SIZE; k++)
        if (!isfinite(T[k][j])) return 0;
    return 1;
}

/* RK4 on the m <= LV_TILE plain bodies ids (ascending) through tile stepper fn: torque-free (ix NULL),
   or each with its constant effect sums (from ix, see effects_constant), evaluated here once. Same
   contract as advance_free_rk4, except that on failure the lowest failing body's last finite state is
   written to last[0] (and *fail_j is its index in ids). Finiteness is checked per chunk of
   LV_FREE_CHUNK steps, with the step-by-step re-run of a failing chunk (see advance_free_rk4): a lane
   computes the same bits whether its tile is stepped one step or a chunk at a time. */
static long advance_free_soa(double *state, const double *params, const long *ids, long m, lv_tile_fn fn,
                             const lv_effect_index *ix, double dt, long n_steps, int *fail_j,
                             double last[][LV_STATE_SIZE])
{
    LV_ALIGN_TILE double T[LV_STATE_SIZE][LV_TILE];
    LV_ALIGN_TILE double S[LV_STATE_SIZE][LV_TILE];
    LV_ALIGN_TILE double J[LV_EULER_SIZE][LV_TILE];
    LV_ALIGN_TILE double P[LV_TP_ROWS][LV_TILE];
    const double (*Pc)[LV_TILE] = (const double (*)[LV_TILE])P;
    const long mp = LV_TILE_PAD(m);
    const int sums = ix != NULL && effects_constant(ix, ids[0]); /* the group's effects are constant (else: effect tile) */
    lv_tile_fx fx;
    long c, cm, s, j;
    int k, ok;
    fx.n_eff = fx.fused = fx.first = 0;
    fx.ufused[0] = fx.ufused[1] = NULL;
    if (ix != NULL && !sums) {
        memset(fx.EP, 0, sizeof fx.EP); /* the rows past an effect's parameters are loaded, never used */
        tile_fx_fill(&fx, ix, ids, m);
    }
    for (j = 0; j < m; j++) {
        const double *x = state + ids[j] * LV_STATE_SIZE, *prm = params + ids[j] * LV_PARAM_SIZE;
        double F[3] = LV_SUM_START3, tau[3] = LV_SUM_START3, cf[LV_EULER_SIZE];
        for (k = 0; k < LV_STATE_SIZE; k++) T[k][j] = x[k];
        lv_euler_coefficients(prm + LV_PARAM_I_B, cf);
        for (k = 0; k < LV_EULER_SIZE; k++) J[k][j] = cf[k];
        if (ix == NULL) continue;
        P[LV_TP_M][j] = prm[LV_PARAM_M];
        for (k = 0; k < 3; k++) P[LV_TP_I + k][j] = prm[LV_PARAM_I_B + k];
        if (!sums) { /* an effect tile: the sums of the effects before its fused pattern here, the rest per stage */
            const long nr = ix->start[ids[j] + 1] - ix->start[ids[j]];
            if (rhs_class(nr, ix->flags[ids[j]]) >= LV_RHS_BODY)
                effect_sums_b(x, x + LV_STATE_V_W, prm[LV_PARAM_M], prm + LV_PARAM_I_B, ix->refs + ix->start[ids[j]],
                              fx.first, F, tau);
            else
                effect_sums(x, x + LV_STATE_V_W, prm[LV_PARAM_M], prm + LV_PARAM_I_B, ix->refs + ix->start[ids[j]],
                            fx.first, F, tau);
        } else {
            effect_sums(x, x + LV_STATE_V_W, prm[LV_PARAM_M], prm + LV_PARAM_I_B, ix->refs + ix->start[ids[j]],
                        ix->start[ids[j] + 1] - ix->start[ids[j]], F, tau);
        }
        for (k = 0; k < 3; k++) {
            P[LV_TP_F + k][j] = F[k];
            P[LV_TP_TAU + k][j] = tau[k];
        }
    }
    for (j = m; j < mp; j++) { /* padding lanes: copies of the last body (stepped, never checked nor written back) */
        for (k = 0; k < LV_STATE_SIZE; k++) T[k][j] = T[k][m - 1];
        for (k = 0; k < LV_EULER_SIZE; k++) J[k][j] = J[k][m - 1];
        for (k = 0; k < LV_TP_ROWS && ix != NULL; k++) P[k][j] = P[k][m - 1];
        for (k = 0; k < LV_TE_PARAMS && fx.n_eff > 0; k++) fx.EP[k][j] = fx.EP[k][m - 1];
    }
    for (c = 0; c < n_steps; c += cm) {
        cm = n_steps - c < LV_FREE_CHUNK ? n_steps - c : LV_FREE_CHUNK;
        memcpy(S, T, sizeof T);
        fn(T, (const double (*)[LV_TILE])J, Pc, &fx, mp, dt, cm);
        ok = 1;
        for (j = 0; j < m; j++) ok &= tile_finite((const double (*)[LV_TILE])T, j);
        if (ok) continue;
        memcpy(T, S, sizeof T); /* some body went non-finite in this chunk: redo it step by step */
        for (s = 0; s < cm; s++) {
            memcpy(S, T, sizeof T);
            fn(T, (const double (*)[LV_TILE])J, Pc, &fx, mp, dt, 1);
            for (j = 0; j < m; j++) {
                if (!tile_finite((const double (*)[LV_TILE])T, j)) {
                    *fail_j = (int)j;
                    for (k = 0; k < LV_STATE_SIZE; k++) last[0][k] = S[k][j];
                    return c + s;
                }
            }
        }
        /* not reached: the non-finite end state of the chunk must fail on the re-run */
    }
    for (j = 0; j < m; j++)
        for (k = 0; k < LV_STATE_SIZE; k++) state[ids[j] * LV_STATE_SIZE + k] = T[k][j];
    return -1;
}

#endif
