/* LavenderSim fixed-step loop (euler, semi_implicit_euler, rk4) on plain bodies, templated on the real type.

   Included by a translation unit after it defines
     LV_REAL             the real type (float),
     LV_K(name)          the generated kernel `name` in that precision (lvf_##name: generated/kernels_f32.c),
     LV_EFFECT_APPLY     the generated effect dispatch in that precision (lvf_effect_apply),
     LV_FN(name)         the name of a function of this instance (name##_f32),
   and included generated/layout.h, generated/tableaux.h and step.h (integrator and status codes). It defines
   LV_FN(simulate), the contract of lv_simulate (step.h) restricted to plain bodies (no joint, no wheels),
   the fixed-step integrators and built-in effects.

   Control flow only: every equation is a generated kernel of the chosen precision, every integrator
   constant comes from tableaux.h (converted to LV_REAL once, so no subexpression is promoted to double).
   The arithmetic of a body's step is exactly that of the NumPy backend on arrays of the same dtype
   (lavendersim/backends/numpy_backend.py: the same kernels, RK4 combination and normalization in the same
   order), which tests/test_float32.py checks bitwise.

   Layout: bodies are stepped in struct-of-arrays tiles (T[k][b] = state number k of body b) so that the
   loop over the bodies of a tile, with the kernels inlined (flatten), is what the compiler vectorizes for
   torque-free bodies (one body per lane; 16 float lanes in AVX-512); bodies with effects take the same loop
   with the effect dispatch (scalar). */

#if defined(__GNUC__) || defined(__clang__)
#define LV_FIXED_FLATTEN __attribute__((flatten))
#else
#define LV_FIXED_FLATTEN
#endif
/* One copy of the torque-free tile per instruction set, chosen by the loader (GCC ifunc, x86-64 Linux). */
#if defined(__GNUC__) && !defined(__clang__) && defined(__x86_64__) && defined(__linux__) && !defined(LV_NO_CLONES)
#define LV_FIXED_CLONES __attribute__((target_clones("avx512f", "avx2", "default")))
#else
#define LV_FIXED_CLONES
#endif

#define LV_FIXED_TILE 64  /* bodies per tile */
#define LV_FIXED_CHUNK 64 /* steps between finiteness checks */

/* One effect acting on one body: its parameters (row after [code, body]) and its code. */
typedef struct {
    const LV_REAL *p;
    int code;
} LV_FN(ref);

/* d/dt of one plain body: the free kernel, or its effects summed in table order and the full kernel. */
static inline void LV_FN(rhs)(const LV_REAL *x, const LV_REAL *I, LV_REAL m, const LV_FN(ref) *refs, long n,
                              int forced, LV_REAL *xd)
{
    LV_REAL F[3] = {0, 0, 0}, tau[3] = {0, 0, 0};
    long k;
    if (!forced) {
        LV_K(rigid_body_rhs_free)(x, I, xd);
        return;
    }
    for (k = 0; k < n; k++) (void)LV_EFFECT_APPLY(refs[k].code, refs[k].p, x, x + LV_STATE_V_W, m, I, F, tau);
    LV_K(rigid_body_rhs)(x, m, I, F, tau, xd);
}

/* One step of one body, x -> x (q normalized when asked). */
static inline void LV_FN(body_step)(LV_REAL *x, const LV_REAL *I, LV_REAL m, const LV_FN(ref) *refs, long n,
                                    int forced, int integrator, int normalize, LV_REAL dt)
{
    const LV_REAL h2 = (LV_REAL)LV_RK4_C1 * dt, h3 = (LV_REAL)LV_RK4_C2 * dt, h4 = (LV_REAL)LV_RK4_C3 * dt;
    const LV_REAL h6 = dt / (LV_REAL)LV_RK4_B_DEN;
    const LV_REAL b0 = (LV_REAL)LV_RK4_B0, b1 = (LV_REAL)LV_RK4_B1, b2 = (LV_REAL)LV_RK4_B2, b3 = (LV_REAL)LV_RK4_B3;
    LV_REAL k1[LV_STATE_SIZE], k2[LV_STATE_SIZE], k3[LV_STATE_SIZE], k4[LV_STATE_SIZE], tmp[LV_STATE_SIZE];
    int i;
    LV_FN(rhs)(x, I, m, refs, n, forced, k1);
    if (integrator == LV_INTEGRATOR_EULER) {
        for (i = 0; i < LV_STATE_SIZE; i++) x[i] = x[i] + dt * k1[i];
    } else if (integrator == LV_INTEGRATOR_SEMI_IMPLICIT_EULER) {
        for (i = 0; i < 3; i++) { /* v', omega' first */
            x[LV_STATE_V_W + i] = x[LV_STATE_V_W + i] + dt * k1[LV_STATE_V_W + i];
            x[LV_STATE_OMEGA_B + i] = x[LV_STATE_OMEGA_B + i] + dt * k1[LV_STATE_OMEGA_B + i];
        }
        LV_K(translation_drift)(x + LV_STATE_P_W, x + LV_STATE_V_W, dt, x + LV_STATE_P_W); /* p + dt v' */
        LV_K(quat_derivative_body)(x + LV_STATE_Q, x + LV_STATE_OMEGA_B, tmp);             /* q rate at omega' */
        for (i = 0; i < 4; i++) x[LV_STATE_Q + i] = x[LV_STATE_Q + i] + dt * tmp[i];
    } else { /* LV_INTEGRATOR_RK4 */
        for (i = 0; i < LV_STATE_SIZE; i++) tmp[i] = x[i] + h2 * k1[i];
        LV_FN(rhs)(tmp, I, m, refs, n, forced, k2);
        for (i = 0; i < LV_STATE_SIZE; i++) tmp[i] = x[i] + h3 * k2[i];
        LV_FN(rhs)(tmp, I, m, refs, n, forced, k3);
        for (i = 0; i < LV_STATE_SIZE; i++) tmp[i] = x[i] + h4 * k3[i];
        LV_FN(rhs)(tmp, I, m, refs, n, forced, k4);
        for (i = 0; i < LV_STATE_SIZE; i++) x[i] = x[i] + h6 * (b0 * k1[i] + b1 * k2[i] + b2 * k3[i] + b3 * k4[i]);
    }
    if (normalize) LV_K(quat_normalize)(x + LV_STATE_Q, x + LV_STATE_Q);
}

/* A tile of nt bodies: T[k][b] state, J[0..2][b] principal moments, J[3][b] mass; refs[b] / nref[b] body b's
   effects (forced tiles only). */
typedef struct {
    LV_REAL T[LV_STATE_SIZE][LV_FIXED_TILE];
    LV_REAL J[4][LV_FIXED_TILE];
    const LV_FN(ref) *refs[LV_FIXED_TILE];
    long nref[LV_FIXED_TILE];
    long nt;
} LV_FN(tile);

static inline void LV_FN(tile_steps)(LV_FN(tile) *LV_RESTRICT t, int forced, int integrator, int normalize,
                                     LV_REAL dt, long n_steps)
{
    long s, b;
    int i;
    for (s = 0; s < n_steps; s++) {
        for (b = 0; b < t->nt; b++) {
            LV_REAL x[LV_STATE_SIZE], I[3];
            for (i = 0; i < LV_STATE_SIZE; i++) x[i] = t->T[i][b];
            for (i = 0; i < 3; i++) I[i] = t->J[i][b];
            LV_FN(body_step)(x, I, t->J[3][b], forced ? t->refs[b] : NULL, forced ? t->nref[b] : 0, forced,
                             integrator, normalize, dt);
            for (i = 0; i < LV_STATE_SIZE; i++) t->T[i][b] = x[i];
        }
    }
}

typedef void (*LV_FN(tile_fn))(LV_FN(tile) *LV_RESTRICT t, LV_REAL dt, long n_steps);

/* The torque-free tiles, one specialized (constant integrator and normalize flag) copy each, and the tile of
   bodies with effects (generic). */
#define LV_FIXED_FREE_TILE(NAME, INTEGRATOR, NORMALIZE)                                                   \
    LV_FIXED_CLONES LV_FIXED_FLATTEN static void LV_FN(NAME)(LV_FN(tile) *LV_RESTRICT t, LV_REAL dt, long n_steps) \
    {                                                                                                   \
        LV_FN(tile_steps)(t, 0, INTEGRATOR, NORMALIZE, dt, n_steps);                                    \
    }
LV_FIXED_FREE_TILE(free_euler_n, LV_INTEGRATOR_EULER, 1)
LV_FIXED_FREE_TILE(free_euler_r, LV_INTEGRATOR_EULER, 0)
LV_FIXED_FREE_TILE(free_semi_n, LV_INTEGRATOR_SEMI_IMPLICIT_EULER, 1)
LV_FIXED_FREE_TILE(free_semi_r, LV_INTEGRATOR_SEMI_IMPLICIT_EULER, 0)
LV_FIXED_FREE_TILE(free_rk4_n, LV_INTEGRATOR_RK4, 1)
LV_FIXED_FREE_TILE(free_rk4_r, LV_INTEGRATOR_RK4, 0)
#undef LV_FIXED_FREE_TILE

LV_FIXED_FLATTEN static void LV_FN(forced_tile)(LV_FN(tile) *LV_RESTRICT t, int integrator, int normalize, LV_REAL dt,
                                                long n_steps)
{
    LV_FN(tile_steps)(t, 1, integrator, normalize, dt, n_steps);
}

static int LV_FN(tile_finite)(const LV_FN(tile) *t, long b)
{
    int k;
    for (k = 0; k < LV_STATE_SIZE; k++)
        if (!isfinite(t->T[k][b])) return 0;
    return 1;
}

/* n_steps of a tile, checked per chunk of LV_FIXED_CHUNK steps; a chunk whose end state is non-finite is
   re-run step by step from its start (the same bits: a non-finite number never becomes finite again on these
   paths, new = old + something and normalization keeps a NaN) to find its first failing step. Returns -1, or
   that step with *fail_b the lowest failing body of the tile and last[] its last finite state. */
static long LV_FN(tile_run)(LV_FN(tile) *t, LV_FN(tile) *snap, LV_FN(tile_fn) fn, int integrator, int normalize,
                            LV_REAL dt, long n_steps, long *fail_b, LV_REAL *last)
{
    long c, cm, r, b;
    int ok, k;
#define LV_FIXED_RUN(N) (fn != NULL ? fn(t, dt, (N)) : LV_FN(forced_tile)(t, integrator, normalize, dt, (N)))
    for (c = 0; c < n_steps; c += cm) {
        cm = n_steps - c < LV_FIXED_CHUNK ? n_steps - c : LV_FIXED_CHUNK;
        memcpy(snap, t, sizeof *t);
        LV_FIXED_RUN(cm);
        ok = 1;
        for (b = 0; b < t->nt; b++) ok &= LV_FN(tile_finite)(t, b);
        if (ok) continue;
        memcpy(t, snap, sizeof *t); /* some body went non-finite in this chunk: redo it step by step */
        for (r = 0; r < cm; r++) {
            memcpy(snap, t, sizeof *t);
            LV_FIXED_RUN(1);
            for (b = 0; b < t->nt; b++) {
                if (LV_FN(tile_finite)(t, b)) continue;
                *fail_b = b;
                for (k = 0; k < LV_STATE_SIZE; k++) last[k] = snap->T[k][b];
                return c + r;
            }
        }
        /* not reached: the non-finite end state of the chunk fails on the re-run */
    }
#undef LV_FIXED_RUN
    return -1;
}

/* The contract of lv_simulate (step.h) for plain bodies, integrator euler / semi_implicit_euler / rk4 and
   built-in effect codes (the caller checked them: any other code returns LV_UNKNOWN_EFFECT). */
static int LV_FN(simulate)(LV_REAL *state, const LV_REAL *params, long nb, const LV_REAL *effects, long ne,
                           long row_size, int integrator, int normalize, LV_REAL dt, long n_steps,
                           long *fail_step, long *fail_body)
{
    long *start = NULL, *order = NULL, *fill = NULL, e, b, j, k, n_every = 0, limit = n_steps, best = -1, s, fb;
    LV_FN(ref) *refs = NULL;
    LV_FN(tile) *t = NULL, *snap = NULL;
    LV_REAL last[LV_STATE_SIZE];
    int status = LV_OK, pass;
    if (integrator != LV_INTEGRATOR_EULER && integrator != LV_INTEGRATOR_SEMI_IMPLICIT_EULER
        && integrator != LV_INTEGRATOR_RK4)
        return LV_BAD_ARGUMENT;
    if (ne > 0 && row_size < LV_EFFECT_ROW_PARAMS) return LV_BAD_ARGUMENT;
    start = (long *)calloc((size_t)nb + 1, sizeof(long));
    order = (long *)malloc(((size_t)nb + 1) * sizeof(long));
    fill = (long *)malloc(((size_t)nb + 1) * sizeof(long));
    t = (LV_FN(tile) *)malloc(sizeof *t);
    snap = (LV_FN(tile) *)malloc(sizeof *snap);
    if (start == NULL || order == NULL || fill == NULL || t == NULL || snap == NULL) { status = LV_NO_MEMORY; goto done; }
    /* the effect index (CSR, table order per body), as step.c's */
    for (e = 0; e < ne; e++) {
        const LV_REAL *row = effects + e * row_size;
        const int code = (int)row[LV_EFFECT_ROW_CODE];
        const long body = (long)row[LV_EFFECT_ROW_BODY];
        const int np = (LV_REAL)code == row[LV_EFFECT_ROW_CODE] ? lv_effect_n_params(code) : -1;
        if (np < 0 || np > row_size - LV_EFFECT_ROW_PARAMS) { *fail_step = e; status = LV_UNKNOWN_EFFECT; goto done; }
        if (body < -1 || body >= nb || (LV_REAL)body != row[LV_EFFECT_ROW_BODY]) { status = LV_BAD_ARGUMENT; goto done; }
        if (body == -1) n_every++; else start[body + 1]++;
    }
    for (b = 0; b < nb; b++) start[b + 1] += start[b] + n_every;
    refs = (LV_FN(ref) *)malloc(((size_t)start[nb] + 1) * sizeof(LV_FN(ref)));
    if (refs == NULL) { status = LV_NO_MEMORY; goto done; }
    memcpy(fill, start, (size_t)nb * sizeof(long));
    for (e = 0; e < ne; e++) {
        const LV_REAL *row = effects + e * row_size;
        const long body = (long)row[LV_EFFECT_ROW_BODY];
        LV_FN(ref) r;
        r.p = row + LV_EFFECT_ROW_PARAMS;
        r.code = (int)row[LV_EFFECT_ROW_CODE];
        if (body == -1) for (b = 0; b < nb; b++) refs[fill[b]++] = r;
        else refs[fill[body]++] = r;
    }
    /* torque-free bodies first (pass 0), then those with effects (pass 1); tiles of ascending bodies, each
       advanced only as far as the earliest failure so far can still be beaten */
    for (pass = 0; pass < 2; pass++) {
        LV_FN(tile_fn) fn = NULL;
        if (pass == 0)
            fn = integrator == LV_INTEGRATOR_EULER ? (normalize ? LV_FN(free_euler_n) : LV_FN(free_euler_r))
               : integrator == LV_INTEGRATOR_SEMI_IMPLICIT_EULER ? (normalize ? LV_FN(free_semi_n) : LV_FN(free_semi_r))
               : (normalize ? LV_FN(free_rk4_n) : LV_FN(free_rk4_r));
        for (j = 0, b = 0; b < nb; b++)
            if ((start[b + 1] > start[b]) == pass) order[j++] = b;
        for (k = 0; k < j; k += t->nt) {
            long lim;
            t->nt = j - k < LV_FIXED_TILE ? j - k : LV_FIXED_TILE;
            for (b = 0; b < t->nt; b++) {
                const long id = order[k + b];
                int i;
                for (i = 0; i < LV_STATE_SIZE; i++) t->T[i][b] = state[id * LV_STATE_SIZE + i];
                for (i = 0; i < 3; i++) t->J[i][b] = params[id * LV_PARAM_SIZE + LV_PARAM_I_B + i];
                t->J[3][b] = params[id * LV_PARAM_SIZE + LV_PARAM_M];
                t->refs[b] = refs + start[id];
                t->nref[b] = start[id + 1] - start[id];
            }
            lim = (best >= 0 && order[k] < best && limit < n_steps) ? limit + 1 : limit;
            s = lim > 0 ? LV_FN(tile_run)(t, snap, fn, integrator, normalize, dt, lim, &fb, last) : -2;
            if (s == -2) continue;
            if (s < 0) {
                for (b = 0; b < t->nt; b++)
                    for (e = 0; e < LV_STATE_SIZE; e++) state[order[k + b] * LV_STATE_SIZE + e] = t->T[e][b];
                continue;
            }
            if (s < limit || (s == limit && order[k + fb] < best)) {
                limit = s;
                best = order[k + fb];
                memcpy(state + best * LV_STATE_SIZE, last, sizeof last);
                status = LV_DIVERGED;
            }
        }
    }
done:
    free(start);
    free(order);
    free(fill);
    free(refs);
    free(t);
    free(snap);
    if (status == LV_DIVERGED) {
        *fail_step = limit;
        *fail_body = best;
    }
    return status;
}
