/* LavenderSim batched torque-free RK4 on struct-of-arrays tiles, vectorized by the compiler, with one
   copy per instruction set chosen at run time. Included once by step.c, after the generated kernels
   (static functions; not a separate translation unit, so the kernels inline into every copy).

   Every equation is the generated one: a tile step calls lv_rigid_body_rhs_free and lv_quat_normalize
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

/* Bodies per tile: 13 + 13 (snapshot) + 3 rows of LV_TILE doubles stay in L1 over a chunk of steps. */
#define LV_TILE 64
/* Groups of torque-free RK4 bodies smaller than this take the scalar block path (advance_free_rk4). */
#define LV_SOA_MIN 16

typedef void (*lv_tile_fn)(double (*LV_RESTRICT T)[LV_TILE], const double (*LV_RESTRICT J)[LV_TILE], long m,
                           double dt, long n_steps);

/* n_steps RK4 steps of the m bodies of a tile: T[k][b] = state number k of body b, J[k][b] = its I_k.
   NORMALIZE: q normalized after each step (the generated kernel), as on the scalar path. */
#define LV_TILE_RK4(NORMALIZE)                                                                          \
    {                                                                                                   \
        const double h2 = LV_RK4_C1 * dt, h3 = LV_RK4_C2 * dt, h4 = LV_RK4_C3 * dt, h6 = dt / LV_RK4_B_DEN; \
        long s, b;                                                                                      \
        int i;                                                                                          \
        for (s = 0; s < n_steps; s++) {                                                                 \
            for (b = 0; b < m; b++) {                                                                   \
                double x[LV_STATE_SIZE], k1[LV_STATE_SIZE], k2[LV_STATE_SIZE], k3[LV_STATE_SIZE],       \
                    k4[LV_STATE_SIZE], tmp[LV_STATE_SIZE], xn[LV_STATE_SIZE], I[3];                     \
                for (i = 0; i < LV_STATE_SIZE; i++) x[i] = T[i][b];                                     \
                for (i = 0; i < 3; i++) I[i] = J[i][b];                                                 \
                lv_rigid_body_rhs_free(x, I, k1);                                                       \
                for (i = 0; i < LV_STATE_SIZE; i++) tmp[i] = x[i] + h2 * k1[i];                         \
                lv_rigid_body_rhs_free(tmp, I, k2);                                                     \
                for (i = 0; i < LV_STATE_SIZE; i++) tmp[i] = x[i] + h3 * k2[i];                         \
                lv_rigid_body_rhs_free(tmp, I, k3);                                                     \
                for (i = 0; i < LV_STATE_SIZE; i++) tmp[i] = x[i] + h4 * k3[i];                         \
                lv_rigid_body_rhs_free(tmp, I, k4);                                                     \
                for (i = 0; i < LV_STATE_SIZE; i++)                                                     \
                    xn[i] = x[i] + h6 * (LV_RK4_B0 * k1[i] + LV_RK4_B1 * k2[i] + LV_RK4_B2 * k3[i]      \
                                         + LV_RK4_B3 * k4[i]);                                          \
                if (NORMALIZE) lv_quat_normalize(xn + LV_STATE_Q, xn + LV_STATE_Q);                    \
                for (i = 0; i < LV_STATE_SIZE; i++) T[i][b] = xn[i];                                    \
            }                                                                                           \
        }                                                                                               \
    }

/* One instruction set's pair of tile steppers (q normalized / not). */
#define LV_DEFINE_TILES(SUFFIX, ATTR)                                                                   \
    ATTR LV_FLATTEN static void tile_rk4_norm_##SUFFIX(double (*LV_RESTRICT T)[LV_TILE],                \
                                                       const double (*LV_RESTRICT J)[LV_TILE], long m,  \
                                                       double dt, long n_steps)                         \
    LV_TILE_RK4(1)                                                                                      \
    ATTR LV_FLATTEN static void tile_rk4_raw_##SUFFIX(double (*LV_RESTRICT T)[LV_TILE],                 \
                                                      const double (*LV_RESTRICT J)[LV_TILE], long m,   \
                                                      double dt, long n_steps)                          \
    LV_TILE_RK4(0)

LV_DEFINE_TILES(base, )
#if LV_HAVE_ISA_CLONES
LV_DEFINE_TILES(avx2, __attribute__((target("avx2"))))
LV_DEFINE_TILES(avx512, __attribute__((target("avx512f"))))
#endif

/* The tile stepper of instruction set isa (LV_ISA_*; one this CPU supports, see lv_isa_best). */
static lv_tile_fn tile_rk4_fn(int isa, int normalize)
{
#if LV_HAVE_ISA_CLONES
    if (isa == LV_ISA_AVX512) return normalize ? tile_rk4_norm_avx512 : tile_rk4_raw_avx512;
    if (isa == LV_ISA_AVX2) return normalize ? tile_rk4_norm_avx2 : tile_rk4_raw_avx2;
#endif
    (void)isa;
    return normalize ? tile_rk4_norm_base : tile_rk4_raw_base;
}

static int tile_finite(const double (*T)[LV_TILE], long j)
{
    int k;
    for (k = 0; k < LV_STATE_SIZE; k++)
        if (!isfinite(T[k][j])) return 0;
    return 1;
}

/* RK4 on the m <= LV_TILE torque-free plain bodies ids (ascending) through tile stepper fn. Same
   contract as advance_free_rk4, except that on failure the lowest failing body's last finite state is
   written to last[0] (and *fail_j is its index in ids). Finiteness is checked per chunk of
   LV_FREE_CHUNK steps, with the step-by-step re-run of a failing chunk (see advance_free_rk4): a lane
   computes the same bits whether its tile is stepped one step or a chunk at a time. */
static long advance_free_soa(double *state, const double *params, const long *ids, long m, lv_tile_fn fn,
                             double dt, long n_steps, int *fail_j, double last[][LV_STATE_SIZE])
{
    double T[LV_STATE_SIZE][LV_TILE], S[LV_STATE_SIZE][LV_TILE], J[3][LV_TILE];
    long c, cm, s, j;
    int k, ok;
    for (j = 0; j < m; j++) {
        for (k = 0; k < LV_STATE_SIZE; k++) T[k][j] = state[ids[j] * LV_STATE_SIZE + k];
        for (k = 0; k < 3; k++) J[k][j] = params[ids[j] * LV_PARAM_SIZE + LV_PARAM_I_B + k];
    }
    for (c = 0; c < n_steps; c += cm) {
        cm = n_steps - c < LV_FREE_CHUNK ? n_steps - c : LV_FREE_CHUNK;
        memcpy(S, T, sizeof T);
        fn(T, (const double (*)[LV_TILE])J, m, dt, cm);
        ok = 1;
        for (j = 0; j < m; j++) ok &= tile_finite((const double (*)[LV_TILE])T, j);
        if (ok) continue;
        memcpy(T, S, sizeof T); /* some body went non-finite in this chunk: redo it step by step */
        for (s = 0; s < cm; s++) {
            memcpy(S, T, sizeof T);
            fn(T, (const double (*)[LV_TILE])J, m, dt, 1);
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
