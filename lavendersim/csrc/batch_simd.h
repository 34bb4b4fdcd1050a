/* LavenderSim batched RK4 on struct-of-arrays tiles, vectorized by the compiler, with one copy per
   instruction set chosen at run time: torque-free bodies, and bodies whose effects all read no state
   (LV_EFFECT_USES_STATE clear: applied_torque, gravity), whose force and torque sums are evaluated once
   per call with the generated effect dispatch (effect_sums) and passed to the generated
   lv_rigid_body_rhs_torque / lv_rigid_body_rhs in every stage, as the scalar path does.

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

/* Bodies per tile: 13 + 13 (snapshot) + 6 (c_b) + 7 (P) rows of LV_TILE doubles stay in L1 over a chunk of steps. */
#define LV_TILE 64
/* Groups of torque-free RK4 bodies smaller than this take the scalar block path (advance_free_rk4). */
#define LV_SOA_MIN 16

/* Rows of a tile's constant effect sums P[k][b] (bodies whose effects all read no state, see
   LV_EFFECT_USES_STATE): the mass, then the force and the torque (world) summed over the body's effects
   in table order, as effect_sums adds them at every stage (the same inputs give the same bits, so
   summing them once per call changes nothing). */
enum { LV_TP_M = 0, LV_TP_F = 1, LV_TP_TAU = 4, LV_TP_ROWS = 7 };

typedef void (*lv_tile_fn)(double (*LV_RESTRICT T)[LV_TILE], const double (*LV_RESTRICT J)[LV_TILE],
                           const double (*LV_RESTRICT P)[LV_TILE], long m, double dt, long n_steps);

/* One lane's right-hand side, per kind (LV_RHS_*): in, out, cf (the Euler coefficients c_b of body b); P as above. */
#define LV_TILE_RHS_FREE(in, out) lv_rigid_body_rhs_free_c(in, cf, out)
#define LV_TILE_RHS_TORQUE(in, out) lv_rigid_body_rhs_torque_c(in, cf, tau, out)
#define LV_TILE_RHS_FULL(in, out) lv_rigid_body_rhs_c(in, mass, cf, F, tau, out)
#define LV_TILE_LOAD_FREE (void)P
#define LV_TILE_LOAD_TORQUE                                                                             \
    const double tau[3] = {P[LV_TP_TAU][b], P[LV_TP_TAU + 1][b], P[LV_TP_TAU + 2][b]}
#define LV_TILE_LOAD_FULL                                                                               \
    const double tau[3] = {P[LV_TP_TAU][b], P[LV_TP_TAU + 1][b], P[LV_TP_TAU + 2][b]};                 \
    const double F[3] = {P[LV_TP_F][b], P[LV_TP_F + 1][b], P[LV_TP_F + 2][b]};                         \
    const double mass = P[LV_TP_M][b]

/* n_steps RK4 steps of the m bodies of a tile: T[k][b] = state number k of body b, J[k][b] = its Euler
   coefficient c_b[k] (LV_EULER_*).
   NORMALIZE: q normalized after each step (the generated kernel), as on the scalar path. LOAD, RHS:
   the lane's constant effect sums and its right-hand side (LV_TILE_LOAD_*, LV_TILE_RHS_*). */
#define LV_TILE_FOR(stmt) for (i = 0; i < LV_STATE_SIZE; i++) stmt
#define LV_TILE_AT(v) v[i]
#define LV_TILE_RK4(NORMALIZE, LOAD, RHS)                                                               \
    {                                                                                                   \
        long s, b;                                                                                      \
        int i;                                                                                          \
        for (s = 0; s < n_steps; s++) {                                                                 \
            for (b = 0; b < m; b++) {                                                                   \
                double x[LV_STATE_SIZE], k[LV_STATE_SIZE], acc[LV_STATE_SIZE], tmp[LV_STATE_SIZE],      \
                    xn[LV_STATE_SIZE], cf[LV_EULER_SIZE];                                               \
                LOAD;                                                                                   \
                for (i = 0; i < LV_STATE_SIZE; i++) x[i] = T[i][b];                                     \
                for (i = 0; i < LV_EULER_SIZE; i++) cf[i] = J[i][b];                                    \
                LV_RK4_STEP(double, RHS, LV_TILE_FOR, LV_TILE_AT, dt, x, xn, k, acc, tmp);              \
                if (NORMALIZE) lv_quat_normalize(xn + LV_STATE_Q, xn + LV_STATE_Q);                    \
                for (i = 0; i < LV_STATE_SIZE; i++) T[i][b] = xn[i];                                    \
            }                                                                                           \
        }                                                                                               \
    }

#define LV_DEFINE_TILE(NAME, ATTR, NORMALIZE, KIND)                                                     \
    ATTR LV_FLATTEN static void NAME(double (*LV_RESTRICT T)[LV_TILE], const double (*LV_RESTRICT J)[LV_TILE], \
                                     const double (*LV_RESTRICT P)[LV_TILE], long m, double dt, long n_steps) \
    LV_TILE_RK4(NORMALIZE, LV_TILE_LOAD_##KIND, LV_TILE_RHS_##KIND)

/* One instruction set's tile steppers: q normalized / not, times torque-free / constant torque /
   constant force and torque. */
#define LV_DEFINE_TILES(SUFFIX, ATTR)                                                                   \
    LV_DEFINE_TILE(tile_rk4_norm_free_##SUFFIX, ATTR, 1, FREE)                                          \
    LV_DEFINE_TILE(tile_rk4_raw_free_##SUFFIX, ATTR, 0, FREE)                                           \
    LV_DEFINE_TILE(tile_rk4_norm_torque_##SUFFIX, ATTR, 1, TORQUE)                                      \
    LV_DEFINE_TILE(tile_rk4_raw_torque_##SUFFIX, ATTR, 0, TORQUE)                                       \
    LV_DEFINE_TILE(tile_rk4_norm_full_##SUFFIX, ATTR, 1, FULL)                                          \
    LV_DEFINE_TILE(tile_rk4_raw_full_##SUFFIX, ATTR, 0, FULL)

LV_ISA_COPIES(LV_DEFINE_TILES)

/* The tile stepper of instruction set isa (LV_ISA_*; one this CPU supports, see lv_isa_best) for
   right-hand side kind (LV_RHS_*; with effects: constant ones, see LV_TP_*). */
static lv_tile_fn tile_rk4_fn(int isa, int normalize, int kind)
{
    (void)isa;
    return kind == LV_RHS_FREE     ? (normalize ? LV_ISA_PICK(isa, tile_rk4_norm_free) : LV_ISA_PICK(isa, tile_rk4_raw_free))
         : kind == LV_RHS_TORQUE ? (normalize ? LV_ISA_PICK(isa, tile_rk4_norm_torque) : LV_ISA_PICK(isa, tile_rk4_raw_torque))
                                 : (normalize ? LV_ISA_PICK(isa, tile_rk4_norm_full) : LV_ISA_PICK(isa, tile_rk4_raw_full));
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
    double T[LV_STATE_SIZE][LV_TILE], S[LV_STATE_SIZE][LV_TILE], J[LV_EULER_SIZE][LV_TILE], P[LV_TP_ROWS][LV_TILE];
    const double (*Pc)[LV_TILE] = (const double (*)[LV_TILE])P;
    long c, cm, s, j;
    int k, ok;
    for (j = 0; j < m; j++) {
        const double *x = state + ids[j] * LV_STATE_SIZE, *prm = params + ids[j] * LV_PARAM_SIZE;
        double F[3] = {0.0, 0.0, 0.0}, tau[3] = {0.0, 0.0, 0.0}, cf[LV_EULER_SIZE];
        for (k = 0; k < LV_STATE_SIZE; k++) T[k][j] = x[k];
        lv_euler_coefficients(prm + LV_PARAM_I_B, cf);
        for (k = 0; k < LV_EULER_SIZE; k++) J[k][j] = cf[k];
        if (ix == NULL) continue;
        effect_sums(x, x + LV_STATE_V_W, prm[LV_PARAM_M], prm + LV_PARAM_I_B, ix->refs + ix->start[ids[j]],
                    ix->start[ids[j] + 1] - ix->start[ids[j]], F, tau);
        P[LV_TP_M][j] = prm[LV_PARAM_M];
        for (k = 0; k < 3; k++) {
            P[LV_TP_F + k][j] = F[k];
            P[LV_TP_TAU + k][j] = tau[k];
        }
    }
    for (c = 0; c < n_steps; c += cm) {
        cm = n_steps - c < LV_FREE_CHUNK ? n_steps - c : LV_FREE_CHUNK;
        memcpy(S, T, sizeof T);
        fn(T, (const double (*)[LV_TILE])J, Pc, m, dt, cm);
        ok = 1;
        for (j = 0; j < m; j++) ok &= tile_finite((const double (*)[LV_TILE])T, j);
        if (ok) continue;
        memcpy(T, S, sizeof T); /* some body went non-finite in this chunk: redo it step by step */
        for (s = 0; s < cm; s++) {
            memcpy(S, T, sizeof T);
            fn(T, (const double (*)[LV_TILE])J, Pc, m, dt, 1);
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
