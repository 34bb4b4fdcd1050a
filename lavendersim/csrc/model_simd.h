/* LavenderSim batched RK4 for model bodies (a spherical joint and reaction wheels on any axes, kind
   LV_KIND_JOINT | LV_KIND_WHEELS) on struct-of-arrays tiles, one body per lane, vectorized by the
   compiler with one copy per instruction set chosen at run time (as csrc/batch_simd.h does for plain
   bodies). Included once by step.c, after batch_simd.h.

   A group: RK4 bodies of that kind whose effect lists are the same effects (same codes, same parameter
   rows, in the same order: e.g. the scene-wide ones, body -1) and all built in. advance_model's step is
   cut into lane loops over the tile's arrays, one per piece of model_rhs_of: the wheel motor, per stage
   the joint's kinematic velocity (when an effect reads v), one loop per effect (its code known outside
   the loop, so the generated dispatch inlines to that effect alone), the generated wheel-body
   right-hand side (the one N-wheel model, LV_WHEELS_BODY_RHS, on each lane's axes) with the RK4 sums, then the combination, lv_quat_normalize and lv_pivot_kinematics.
   Every lane does the scalar path's IEEE operations in its order (the effect sums start at 0 and add
   in table order; the RK4 weighted sum B0 k1 + B1 k2 + B2 k3 + B3 k4 is accumulated left to right as C
   evaluates it; -ffp-contract=off), so results are bitwise advance_model's (tests/test_model_simd.py).

   Speed when the tiles landed (48a0cca, 2026-11-23; wheel cubes under scene-wide gravity and angular damping, RK4,
   one thread, CPU time, min of 7 interleaved rounds against isa(0), load ~0.5-1, Sim.run; the AVX-512 figure is ~45
   ns at N = 1024 since the tiles were aligned, 5de4d66): N = 1024: scalar 289 ns/body-step, AVX-512 98
   (2.95x), AVX2 139 (2.1x), SSE2 239 (1.2x); N = 10^4: 299, 108 (2.8x), 153 (1.95x), 252 (1.2x). The lane
   copies must be unrolled for that (LV_MT_UNROLL): without it the loops over the model row stay
   loops, the lane loops around them are not vectorized, and the tiles were 0.65x the scalar path. */
#ifndef LAVENDERSIM_MODEL_SIMD_H
#define LAVENDERSIM_MODEL_SIMD_H

/* Bodies per model tile: ~125 rows of LV_MTILE doubles (~32 KB) stay in L1 over a chunk of steps. */
#define LV_MTILE 32
#define LV_MKIND (LV_KIND_JOINT | LV_KIND_WHEELS)

/* Every row is LV_MTILE doubles (256 bytes) and the first starts on a 64-byte boundary (LV_ALIGN_TILE, batch_simd.h: a
   tile on the stack is otherwise 16-byte aligned, and at 16 or 48 bytes off a line every AVX-512 load or store of a
   row straddles two cache lines). Layout only: the same operations on the same numbers. */
typedef struct {
    LV_ALIGN_TILE double Y[LV_XS_SIZE][LV_MTILE];  /* [x, Omega] at the start of the step */
    double T[LV_XS_SIZE][LV_MTILE];  /* a stage's input */
    double A[LV_XS_SIZE][LV_MTILE];  /* the RK4 weighted sum of the stage derivatives so far */
    double V[3][LV_MTILE];           /* the joint's kinematic COM velocity at the stage input */
    double F[3][LV_MTILE], TAU[3][LV_MTILE]; /* the effect sums at the stage input */
    double U[LV_NW][LV_MTILE];           /* this step's applied wheel torques */
    double R[LV_MODEL_SIZE][LV_MTILE]; /* the model rows */
    double KW[LV_WCOEF_SIZE][LV_MTILE]; /* the wheel coefficients (model_coefficients: per call, or kept) */
    double P[LV_PARAM_SIZE][LV_MTILE]; /* the params rows (m, I_b) */
    double C[LV_NW][LV_MTILE];           /* the commands */
} lv_mtile;

typedef void (*lv_mtile_fn)(lv_mtile *LV_RESTRICT t, const lv_effect_ref *refs, long n_refs, int needs_v,
                            int normalize, long m, double dt, long n_steps);

/* A lane's rows in and out, and every loop over a lane's [x, Omega] (LV_XS_SIZE numbers, 17), are unrolled (GCC's
   complete peeling stops at 16 iterations; a loop left inside a lane loop keeps the compiler from vectorizing it
   over the lanes: the model row has LV_MODEL_SIZE numbers; with XS at 17 the RK4 sums alone cost 3x). */
#if defined(__GNUC__) && !defined(__clang__)
#define LV_MT_UNROLL _Pragma("GCC unroll 64")
#else
#define LV_MT_UNROLL
#endif
#define LV_MT_LOAD(dst, SRC, n)                                                                         \
    LV_MT_UNROLL for (i = 0; i < (n); i++) dst[i] = t->SRC[i][b]
#define LV_MT_STORE(SRC, src, n)                                                                        \
    LV_MT_UNROLL for (i = 0; i < (n); i++) t->SRC[i][b] = src[i]

/* One effect's lane loop: code CODE (a constant), parameters p (the same row for every lane). */
#define LV_MT_EFFECT1(CODE, VLOAD)                                                                            \
    for (b = 0; b < m; b++) {                                                                           \
        double x[LV_STATE_SIZE], v[3], F[3], tau[3], prm[LV_PARAM_SIZE];                                \
        LV_MT_LOAD(x, T, LV_STATE_SIZE);                                                                \
        LV_MT_LOAD(prm, P, LV_PARAM_SIZE);                                                              \
        LV_MT_LOAD(F, F, 3);                                                                            \
        LV_MT_LOAD(tau, TAU, 3);                                                                        \
        VLOAD;                                                                                          \
        (void)lv_effect_apply(CODE, p, x, v, prm[LV_PARAM_M], prm + LV_PARAM_I_B, F, tau);              \
        LV_MT_STORE(F, F, 3);                                                                           \
        LV_MT_STORE(TAU, tau, 3);                                                                       \
    }

#define LV_MT_VK LV_MT_LOAD(v, V, 3)
#define LV_MT_VX for (i = 0; i < 3; i++) v[i] = x[LV_STATE_V_W + i]
#define LV_MT_EFFECT(CODE)                                                                              \
    if (needs_v) { LV_MT_EFFECT1(CODE, LV_MT_VK) }                                                      \
    else { LV_MT_EFFECT1(CODE, LV_MT_VX) }

/* RK4 stage STAGE (0..3) on the stage input t->T: its derivative k, then the weighted sum and the next
   stage's input (h: LV_RK4_C1..3 dt), or, after the last stage, the step's end in t->Y. */
#define LV_MT_STAGE_RHS(COMBINE)                                                                        \
    for (b = 0; b < m; b++) {                                                                           \
        double y[LV_XS_SIZE], k[LV_XS_SIZE], r[LV_MODEL_SIZE], kw[LV_WCOEF_SIZE], F[3], tau[3], u[LV_NW]; \
        LV_MT_LOAD(y, T, LV_XS_SIZE);                                                                   \
        LV_MT_LOAD(r, R, LV_MODEL_SIZE);                                                                \
        LV_MT_LOAD(kw, KW, LV_WCOEF_SIZE);                                                              \
        LV_MT_LOAD(F, F, 3);                                                                            \
        LV_MT_LOAD(tau, TAU, 3);                                                                        \
        LV_MT_LOAD(u, U, LV_NW);                                                                        \
        lv_wheels_rhs(on_axes, y, r, kw, F, tau, u, k);                                                          \
        for (i = 0; i < 3; i++) k[LV_STATE_P_W + i] = k[LV_STATE_V_W + i] = 0.0;                        \
        COMBINE                                                                                         \
    }

/* Stages 1-3 (LV_RK4_UPDATE): the weighted sum t->A and the next stage's input t->T; the last stage: the step's end. */
#define LV_MT_NEXT(STAGE)                                                                               \
    LV_MT_UNROLL for (i = 0; i < LV_XS_SIZE; i++)                                                       \
        (void)LV_RK4_UPDATE(double, STAGE, dt, t->Y[i][b], k[i], t->A[i][b], t->T[i][b]);
#define LV_MT_LAST(NORMALIZE)                                                                           \
    {                                                                                                   \
        double yn[LV_XS_SIZE];                                                                          \
        LV_MT_UNROLL for (i = 0; i < LV_XS_SIZE; i++)                                                   \
            (void)LV_RK4_UPDATE(double, 4, dt, t->Y[i][b], k[i], t->A[i][b], yn[i]);                    \
        if (NORMALIZE) lv_quat_normalize(yn + LV_STATE_Q, yn + LV_STATE_Q);                             \
        lv_pivot_kinematics(yn + LV_STATE_Q, yn + LV_STATE_OMEGA_B, r + LV_MODEL_ANCHOR_W,             \
                            r + LV_MODEL_R_B, yn + LV_STATE_P_W, yn + LV_STATE_V_W);                    \
        LV_MT_STORE(Y, yn, LV_XS_SIZE);                                                                 \
    }

/* The effect sums at the stage input t->T (kinematic velocity first when an effect reads v). */
#define LV_MT_EFFECTS                                                                                   \
    if (needs_v) {                                                                                      \
        for (b = 0; b < m; b++) {                                                                       \
            double y[LV_STATE_SIZE], r[LV_MODEL_SIZE], pk[3], vk[3];                                    \
            LV_MT_LOAD(y, T, LV_STATE_SIZE);                                                            \
            LV_MT_LOAD(r, R, LV_MODEL_SIZE);                                                            \
            lv_pivot_kinematics(y + LV_STATE_Q, y + LV_STATE_OMEGA_B, r + LV_MODEL_ANCHOR_W,           \
                                r + LV_MODEL_R_B, pk, vk);                                              \
            LV_MT_STORE(V, vk, 3);                                                                      \
        }                                                                                               \
    }                                                                                                   \
    for (i = 0; i < 3; i++)                                                                             \
        for (b = 0; b < m; b++) t->F[i][b] = t->TAU[i][b] = LV_SUM_START;                               \
    for (e = 0; e < n_refs; e++) {                                                                      \
        const double *p = refs[e].p;                                                                    \
        switch (refs[e].code) { LV_EFFECT_BUILTINS(LV_MT_CASE) default: break; }                        \
    }
/* One case per built-in effect (derive prints the list, LV_EFFECT_BUILTINS), so each lane loop inlines one. */
#define LV_MT_CASE(CODE)                                                                                \
    case CODE: LV_MT_EFFECT(CODE) break;

/* Whether the lane loops above dispatch `code`: every built-in effect does (a user effect stays scalar). */
static int mtile_code_known(int code) { return lv_effect_n_params(code) >= 0; }

/* n_steps RK4 steps of the m bodies of tile t (kind LV_MKIND, effects refs[0 .. n_refs-1], the same for
   every lane): advance_model's step for each lane; AXES: the lanes' wheels are on the default layout (LV_ON_AXES). */
#define LV_DEFINE_MTILE1(NAME, ATTR, AXES)                                                              \
    ATTR LV_FLATTEN static void NAME(lv_mtile *LV_RESTRICT t, const lv_effect_ref *refs,                \
                                     long n_refs, int needs_v, int normalize, long m,                   \
                                     double dt, long n_steps)                                           \
    {                                                                                                   \
        const int on_axes = AXES;                                                                       \
        long s, b, e;                                                                                   \
        int i;                                                                                          \
        for (s = 0; s < n_steps; s++) {                                                                 \
            for (b = 0; b < m; b++) {                                                                   \
                double cmd[LV_NW], Om[LV_NW], r[LV_MODEL_SIZE], u[LV_NW];                               \
                LV_MT_LOAD(cmd, C, LV_NW);                                                              \
                LV_MT_UNROLL for (i = 0; i < LV_NW; i++) Om[i] = t->Y[LV_XS_OMEGA + i][b];              \
                LV_MT_LOAD(r, R, LV_MODEL_SIZE);                                                        \
                lv_wheels_motor(r, cmd, Om, u);                                                         \
                LV_MT_STORE(U, u, LV_NW);                                                               \
                LV_MT_UNROLL for (i = 0; i < LV_XS_SIZE; i++) t->T[i][b] = t->Y[i][b];                  \
            }                                                                                           \
            LV_MT_EFFECTS                                                                               \
            LV_MT_STAGE_RHS(LV_MT_NEXT(1))                                                              \
            LV_MT_EFFECTS                                                                               \
            LV_MT_STAGE_RHS(LV_MT_NEXT(2))                                                              \
            LV_MT_EFFECTS                                                                               \
            LV_MT_STAGE_RHS(LV_MT_NEXT(3))                                                              \
            LV_MT_EFFECTS                                                                               \
            if (normalize) { LV_MT_STAGE_RHS(LV_MT_LAST(1)) }                                           \
            else { LV_MT_STAGE_RHS(LV_MT_LAST(0)) }                                                     \
        }                                                                                               \
    }
#define LV_DEFINE_MTILE(SUFFIX, ATTR)                                                                   \
    LV_DEFINE_MTILE1(mtile_rk4_##SUFFIX, ATTR, 0)                                                       \
    LV_DEFINE_MTILE1(mtile_rk4_axes_##SUFFIX, ATTR, 1)

LV_ISA_COPIES(LV_DEFINE_MTILE)

static lv_mtile_fn mtile_rk4_fn(int isa, int on_axes)
{
    (void)isa;
    return on_axes ? LV_ISA_PICK(isa, mtile_rk4_axes) : LV_ISA_PICK(isa, mtile_rk4);
}

/* Whether model body b may join the group of body b0 (b0 itself: whether it may lead one): kind LV_MKIND,
   wheels on the default layout or not as b0's (lv_step_kind), effects all built in with codes the tile
   dispatches, and the same effects as b0's (same rows, same order). */
static int mtile_member(const lv_models *md, const lv_effect_index *ix, long b, long b0)
{
    long k, n = ix->start[b + 1] - ix->start[b];
    int kind;
    /* the row's kind first: the step kind (a layout comparison, unless kept) only for a model tile's kind */
    if ((int)md->rows[b * LV_MODEL_SIZE + LV_MODEL_KIND] != LV_MKIND) return 0;
    kind = model_step_kind(md, b);
    if (b != b0 && kind != model_step_kind(md, b0)) return 0;
    if (n != ix->start[b0 + 1] - ix->start[b0]) return 0;
    if ((ix->flags[b] & LV_EFFECT_USES_V) != (ix->flags[b0] & LV_EFFECT_USES_V)) return 0;
    for (k = 0; k < n; k++) {
        const lv_effect_ref *x = ix->refs + ix->start[b] + k, *y = ix->refs + ix->start[b0] + k;
        if (x->user != NULL || !mtile_code_known(x->code) || x->code != y->code || x->p != y->p) return 0;
    }
    return 1;
}

static int mtile_finite(const lv_mtile *t, long j)
{
    int k;
    for (k = 0; k < LV_XS_SIZE; k++)
        if (!isfinite(t->Y[k][j])) return 0;
    return 1;
}

/* RK4 on the m <= LV_MTILE model bodies ids (ascending, one group: see mtile_member) through fn. Same
   contract as advance_model for each: rows written only on success (state, Omega, applied); on failure
   returns the earliest failing step, *fail_j the lowest failing body there (its index in ids) and
   last[] its last finite [x, Omega]. Finiteness is checked per chunk of LV_FREE_CHUNK steps, a failing
   chunk re-run step by step (a lane computes the same bits either way). */
static long advance_model_soa(double *state, const double *params, const lv_models *md, const lv_effect_index *ix,
                              const long *ids, long m, lv_mtile_fn fn, int normalize, double dt, long n_steps,
                              int *fail_j, double *last)
{
    lv_mtile t;
    LV_ALIGN_TILE double S[LV_XS_SIZE][LV_MTILE];
    const long b0 = ids[0];
    const lv_effect_ref *refs = ix->refs + ix->start[b0];
    const long n_refs = ix->start[b0 + 1] - ix->start[b0];
    const int needs_v = (ix->flags[b0] & LV_EFFECT_USES_V) != 0;
    long c, cm, s, j;
    int k, ok;
    for (j = 0; j < m; j++) {
        const long b = ids[j];
        double kw[LV_WCOEF_SIZE];
        for (k = 0; k < LV_STATE_SIZE; k++) t.Y[k][j] = state[b * LV_STATE_SIZE + k];
        for (k = 0; k < LV_NW; k++) {
            t.Y[LV_XS_OMEGA + k][j] = md->Omega[LV_NW * b + k];
            t.C[k][j] = md->command[LV_NW * b + k];
        }
        for (k = 0; k < LV_MODEL_SIZE; k++) t.R[k][j] = md->rows[b * LV_MODEL_SIZE + k];
        model_coefficients(md, b, kw);
        for (k = 0; k < LV_WCOEF_SIZE; k++) t.KW[k][j] = kw[k];
        for (k = 0; k < LV_PARAM_SIZE; k++) t.P[k][j] = params[b * LV_PARAM_SIZE + k];
    }
    for (c = 0; c < n_steps; c += cm) {
        cm = n_steps - c < LV_FREE_CHUNK ? n_steps - c : LV_FREE_CHUNK;
        memcpy(S, t.Y, sizeof S);
        fn(&t, refs, n_refs, needs_v, normalize, m, dt, cm);
        ok = 1;
        for (j = 0; j < m; j++) ok &= mtile_finite(&t, j);
        if (ok) continue;
        memcpy(t.Y, S, sizeof S); /* some body went non-finite in this chunk: redo it step by step */
        for (s = 0; s < cm; s++) {
            memcpy(S, t.Y, sizeof S);
            fn(&t, refs, n_refs, needs_v, normalize, m, dt, 1);
            for (j = 0; j < m; j++) {
                if (!mtile_finite(&t, j)) {
                    *fail_j = (int)j;
                    for (k = 0; k < LV_XS_SIZE; k++) last[k] = S[k][j];
                    return c + s;
                }
            }
        }
    }
    for (j = 0; j < m; j++) {
        const long b = ids[j];
        for (k = 0; k < LV_STATE_SIZE; k++) state[b * LV_STATE_SIZE + k] = t.Y[k][j];
        for (k = 0; k < LV_NW; k++) {
            md->Omega[LV_NW * b + k] = t.Y[LV_XS_OMEGA + k][j];
            md->applied[LV_NW * b + k] = t.U[k][j];
        }
    }
    return -1;
}

/* One share of a group's tiles over threads (advance_models_threads with unit LV_MTILE; as soa_share_run for plain
   bodies): its bodies share one model_step_kind (mtile_member). */
static void mtile_share_run(void *arg)
{
    model_share *const sh = (model_share *)arg;
    const lv_mtile_fn fn = mtile_rk4_fn(sh->isa, (model_step_kind(sh->md, sh->list[0]) & LV_ON_AXES) != 0);
    double last[LV_XS_SIZE];
    long k, s, lim, n;
    int j;
    for (k = 0; k < sh->count; k += n) {
        n = sh->count - k < LV_MTILE ? sh->count - k : LV_MTILE;
        lim = run_limit(sh->list[k], sh->head.limit, sh->head.best, sh->n_steps);
        if (lim <= 0) continue;
        s = advance_model_soa(sh->state, sh->params, sh->md, sh->ix, sh->list + k, n, fn, sh->normalize, sh->dt, lim,
                              &j, last);
        if (s < 0 || !earlier(s, sh->list[k + j], sh->head.limit, sh->head.best)) continue;
        memcpy(sh->state + sh->list[k + j] * LV_STATE_SIZE, last, LV_STATE_SIZE * sizeof(double));
        memcpy(sh->md->Omega + LV_NW * sh->list[k + j], last + LV_XS_OMEGA, LV_NW * sizeof(double));
        sh->head.limit = s;
        sh->head.best = sh->list[k + j];
        sh->head.status = LV_DIVERGED;
    }
}



/* The model bodies list[0 .. count-1] (ascending): RK4 (isa not LV_ISA_SCALAR) takes the group of the first
   body that may lead one (mtile_member) to the model tiles when it has LV_SOA_MIN bodies or more; every
   other body, and everything otherwise, goes to advance_models_threads. list is reordered (the group
   first, then the rest, each ascending). Returns LV_DIVERGED (with *limit, *best updated) or LV_OK. */
static int advance_models_grouped(double *state, const double *params, const lv_models *md,
                                  const lv_effect_index *ix, long *list, long count, int integrator, int isa,
                                  int normalize, double dt, long n_steps, int threads, long *limit, long *best)
{
    long k, b0 = -1, n_g = 0, n_r = 0, *rest;
    int status = LV_OK;
    if (integrator == LV_PATH_RK4 && isa != LV_ISA_SCALAR) {
        for (k = 0; k < count && b0 < 0; k++)
            if (mtile_member(md, ix, list[k], list[k])) b0 = list[k];
        if (b0 >= 0)
            for (k = 0; k < count; k++) n_g += mtile_member(md, ix, list[k], b0);
    }
    rest = n_g >= LV_SOA_MIN ? (long *)malloc((size_t)count * sizeof(long)) : NULL;
    if (rest == NULL)
        return advance_models_threads(state, params, md, ix, list, count, 1, model_share_run, integrator, 0,
                                      normalize, dt, n_steps, threads, limit, best);
    for (k = 0, n_g = 0; k < count; k++) {
        if (mtile_member(md, ix, list[k], b0)) list[n_g++] = list[k];
        else rest[n_r++] = list[k];
    }
    memcpy(list + n_g, rest, (size_t)n_r * sizeof(long));
    free(rest);
    if (advance_models_threads(state, params, md, ix, list, n_g, LV_MTILE, mtile_share_run, integrator, isa, normalize,
                               dt, n_steps, threads, limit, best) == LV_DIVERGED)
        status = LV_DIVERGED;
    if (n_r > 0 && advance_models_threads(state, params, md, ix, list + n_g, n_r, 1, model_share_run, integrator, 0,
                                          normalize, dt, n_steps, threads, limit, best) == LV_DIVERGED)
        status = LV_DIVERGED;
    return status;
}

#endif
