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

   Layout: bodies are stepped in struct-of-arrays tiles (T[k][b] = state number k of body b), grouped by what
   their right-hand side needs (LV_FIXED_*): torque-free, constant torque, constant force and torque (every
   effect reads no state: its sums are evaluated once per call), any effects (summed at every stage by the
   generated dispatch). The tile holds each body's Euler coefficients c_b (generated euler_coefficients, once
   per call; k_x = (I_y - I_z)/I_x, r_x = 1/I_x) and the stages call the generated coefficient kernels
   (rigid_body_rhs_free_c / _torque_c / _c: bitwise the I_b kernels, the same printed arithmetic), so a
   torque-free step divides by nothing but the normalization's 1/sqrt (as csrc/batch_simd.h in float64).
   The loop over the bodies of a tile, with the kernels inlined (flatten), is what the compiler vectorizes for
   the first three kinds (one body per lane; 16 float lanes in AVX-512, one copy per instruction set: LV_ISA_COPIES,
   picked by lv_isa_get() as the float64 tiles are); the "any effects" tiles take the same loop with the effect
   dispatch (scalar). */

#if defined(__GNUC__) || defined(__clang__)
#define LV_FIXED_FLATTEN __attribute__((flatten))
#else
#define LV_FIXED_FLATTEN
#endif

#define LV_FIXED_TILE 64  /* bodies per tile */
#define LV_FIXED_CHUNK 64 /* steps between finiteness checks */

/* One effect acting on one body: its parameters (row after [code, body]) and its code. */
typedef struct {
    const LV_REAL *p;
    int code;
} LV_FN(ref);

/* What the right-hand side of a tile's bodies needs: LV_FIXED_FREE no effect acts on them (the free kernel);
   LV_FIXED_TORQUE / LV_FIXED_FORCE every effect on them reads no state (LV_EFFECT_USES_STATE clear: applied
   torque, gravity), without / with a force: their sums are evaluated once per call into the tile (the same
   inputs give the same bits at every stage) and the torque / full kernel takes them; LV_FIXED_ANY the
   effects summed in table order at every stage (the generated dispatch, scalar), then the full kernel. */
enum { LV_FIXED_FREE = 0, LV_FIXED_TORQUE = 1, LV_FIXED_FORCE = 2, LV_FIXED_ANY = 3, LV_FIXED_KINDS = 4 };

/* A tile of nt bodies (its arrays' rows are LV_FIXED_TILE numbers; LV_FN(simulate) places a tile on a 64-byte
   boundary: LV_FN(line_up)): T[k][b] state, C[k][b] Euler coefficients c_b (generated euler_coefficients, once per
   call), M[b] mass, I[k][b] principal moments (LV_FIXED_ANY: the effects' input), P[k][b] constant force
   (0..2) and torque (3..5) sums (LV_FIXED_TORQUE / LV_FIXED_FORCE); refs[b] / nref[b] body b's effects; K[k][b]
   the scaled-increment constants (LV_RK4_SCALE dt) k_b of LV_FIXED_FREE RK4 (LV_FN(free_rk4_h), per tile call). */
typedef struct {
    LV_REAL T[LV_STATE_SIZE][LV_FIXED_TILE];
    LV_REAL C[LV_EULER_SIZE][LV_FIXED_TILE];
    LV_REAL K[LV_EULER_K_LEN][LV_FIXED_TILE];
    LV_REAL M[LV_FIXED_TILE];
    LV_REAL I[3][LV_FIXED_TILE];
    LV_REAL P[6][LV_FIXED_TILE];
    const LV_FN(ref) *refs[LV_FIXED_TILE];
    long nref[LV_FIXED_TILE];
    long nt;
} LV_FN(tile);

/* The first 64-byte boundary (one cache line) at or after p. malloc aligns to 16 bytes only: a tile whose rows sat
   16 or 48 bytes off a line made every 16-lane load and store of a row straddle two lines (float32 RK4, AVX-512, one
   process, the tile moved to each offset, N = 1e3: 2.84-2.87 ns per body-step at 16 and 48 against 2.70 at 0 and 32;
   the same as batch_simd.h's LV_ALIGN_TILE for the float64 tiles on the stack). Layout only: the same operations. */
static void *LV_FN(line_up)(void *p)
{
    return (void *)(((uintptr_t)p + 63) & ~(uintptr_t)63);
}

/* d/dt of body b of tile t at state x (kind: LV_FIXED_*). The printed right-hand sides are the coefficient
   forms (*_c, bitwise the I_b kernels): no division but the full kernel's 1/m. */
static inline void LV_FN(rhs)(const LV_FN(tile) *LV_RESTRICT t, long b, int kind, const LV_REAL *x, LV_REAL *xd)
{
    LV_REAL cf[LV_EULER_SIZE], F[3] = {(LV_REAL)LV_SUM_START, (LV_REAL)LV_SUM_START, (LV_REAL)LV_SUM_START},
        tau[3] = {(LV_REAL)LV_SUM_START, (LV_REAL)LV_SUM_START, (LV_REAL)LV_SUM_START};
    long k;
    for (k = 0; k < LV_EULER_SIZE; k++) cf[k] = t->C[k][b];
    if (kind == LV_FIXED_FREE) {
        LV_K(rigid_body_rhs_free_c)(x, cf, xd);
        return;
    }
    if (kind == LV_FIXED_ANY) {
        const LV_REAL I[3] = {t->I[0][b], t->I[1][b], t->I[2][b]};
        for (k = 0; k < t->nref[b]; k++)
            (void)LV_EFFECT_APPLY(t->refs[b][k].code, t->refs[b][k].p, x, x + LV_STATE_V_W, t->M[b], I, F, tau);
    } else {
        for (k = 0; k < 3; k++) {
            F[k] = t->P[k][b];
            tau[k] = t->P[3 + k][b];
        }
    }
    if (kind == LV_FIXED_TORQUE) LV_K(rigid_body_rhs_torque_c)(x, cf, tau, xd);
    else LV_K(rigid_body_rhs_c)(x, t->M[b], cf, F, tau, xd);
}

/* The torque-free RK4 step of body b of tile t, x -> x (q not normalized), in the scaled-increment form (derive/
   tableaux.py scaled_program; tableaux.h LV_RK4_SCALED_STEP), csrc/step.c's lv_free_rk4_h in this precision (and
   numpy_backend._free_rk4_h on a float32 plan): q and omega_b through the stages on the printed increments (constants
   t->K and hq of the printed rigid_body_increment_scale_free, LV_FN(tile_steps)), p_w by the printed
   translation_drift with v_w, v_w kept. */
#define LV_FIXED_H_ROWS (LV_STATE_Q_LEN + LV_STATE_OMEGA_B_LEN) /* y = (q, omega_b) */
static inline void LV_FN(free_rk4_h)(const LV_FN(tile) *LV_RESTRICT t, long b, LV_REAL *x, LV_REAL hq, LV_REAL dt)
{
    LV_REAL y[LV_FIXED_H_ROWS], H[LV_FIXED_H_ROWS], acc[LV_FIXED_H_ROWS], tmp[LV_FIXED_H_ROWS], Ck[LV_EULER_K_LEN];
    int i;
    for (i = 0; i < LV_EULER_K_LEN; i++) Ck[i] = t->K[i][b];
    for (i = 0; i < LV_STATE_Q_LEN; i++) y[i] = x[LV_STATE_Q + i];
    for (i = 0; i < LV_STATE_OMEGA_B_LEN; i++) y[LV_STATE_Q_LEN + i] = x[LV_STATE_OMEGA_B + i];
#define LV_FIXED_H_RHS(in, out) LV_K(rigid_body_increments_free_c)(in, in + LV_STATE_Q_LEN, Ck, hq, out, out + LV_STATE_Q_LEN)
#define LV_FIXED_H_FOR(stmt) for (i = 0; i < LV_FIXED_H_ROWS; i++) stmt
#define LV_FIXED_H_AT(v) v[i]
    LV_RK4_SCALED_STEP(LV_REAL, LV_FIXED_H_RHS, LV_FIXED_H_FOR, LV_FIXED_H_AT, y, y, H, acc, tmp);
#undef LV_FIXED_H_RHS
#undef LV_FIXED_H_FOR
#undef LV_FIXED_H_AT
    LV_K(translation_drift)(x + LV_STATE_P_W, x + LV_STATE_V_W, dt, x + LV_STATE_P_W);
    for (i = 0; i < LV_STATE_Q_LEN; i++) x[LV_STATE_Q + i] = y[i];
    for (i = 0; i < LV_STATE_OMEGA_B_LEN; i++) x[LV_STATE_OMEGA_B + i] = y[LV_STATE_Q_LEN + i];
}

/* One step of body b of tile t, x -> x (q normalized when asked); hq: LV_FN(free_rk4_h)'s. */
static inline void LV_FN(body_step)(const LV_FN(tile) *LV_RESTRICT t, long b, LV_REAL *x, int kind, int integrator,
                                    int normalize, LV_REAL dt, LV_REAL hq)
{
    LV_REAL k1[LV_STATE_SIZE], acc[LV_STATE_SIZE], tmp[LV_STATE_SIZE];
    int i;
#define LV_FIXED_RHS(in, out) LV_FN(rhs)(t, b, kind, in, out)
#define LV_FIXED_FOR(stmt) for (i = 0; i < LV_STATE_SIZE; i++) stmt
#define LV_FIXED_AT(v) v[i]
    if (integrator == LV_PATH_RK4 && kind == LV_FIXED_FREE) {
        LV_FN(free_rk4_h)(t, b, x, hq, dt);
    } else if (integrator == LV_PATH_RK4) {
        LV_RK4_STEP(LV_REAL, LV_FIXED_RHS, LV_FIXED_FOR, LV_FIXED_AT, dt, x, x, k1, acc, tmp);
    } else if (integrator == LV_PATH_EULER) {
        LV_EULER_STEP(LV_REAL, LV_FIXED_RHS, LV_FIXED_FOR, LV_FIXED_AT, dt, x, x, k1, acc, tmp);
    } else { /* LV_PATH_SEMI_IMPLICIT */
        LV_FIXED_RHS(x, k1);
        for (i = 0; i < 3; i++) { /* v', omega' first */
            x[LV_STATE_V_W + i] = x[LV_STATE_V_W + i] + dt * k1[LV_STATE_V_W + i];
            x[LV_STATE_OMEGA_B + i] = x[LV_STATE_OMEGA_B + i] + dt * k1[LV_STATE_OMEGA_B + i];
        }
        LV_K(translation_drift)(x + LV_STATE_P_W, x + LV_STATE_V_W, dt, x + LV_STATE_P_W); /* p + dt v' */
        LV_K(quat_derivative_body)(x + LV_STATE_Q, x + LV_STATE_OMEGA_B, tmp);             /* q rate at omega' */
        for (i = 0; i < 4; i++) x[LV_STATE_Q + i] = x[LV_STATE_Q + i] + dt * tmp[i];
    }
#undef LV_FIXED_RHS
#undef LV_FIXED_FOR
#undef LV_FIXED_AT
    if (normalize) LV_K(quat_normalize)(x + LV_STATE_Q, x + LV_STATE_Q);
}

static inline void LV_FN(tile_steps)(LV_FN(tile) *LV_RESTRICT t, int kind, int integrator, int normalize, LV_REAL dt,
                                     long n_steps)
{
    const LV_REAL sdt = (LV_REAL)LV_RK4_SCALE * dt;
    LV_REAL hq = (LV_REAL)0;
    long s, b;
    int i;
    if (kind == LV_FIXED_FREE && integrator == LV_PATH_RK4) /* LV_FN(free_rk4_h)'s constants, as lv_free_rk4_scale: */
        for (b = 0; b < t->nt; b++) { /* the printed rigid_body_increment_scale_free (hq: the same for every body) */
            LV_REAL cb[LV_EULER_SIZE], Cb[LV_EULER_K_LEN], hb;
            for (i = 0; i < LV_EULER_SIZE; i++) cb[i] = t->C[i][b];
            LV_K(rigid_body_increment_scale_free)(cb, sdt, Cb, &hb);
            for (i = 0; i < LV_EULER_K_LEN; i++) t->K[i][b] = Cb[i];
            hq = hb;
        }
    for (s = 0; s < n_steps; s++) {
        for (b = 0; b < t->nt; b++) {
            LV_REAL x[LV_STATE_SIZE];
            for (i = 0; i < LV_STATE_SIZE; i++) x[i] = t->T[i][b];
            LV_FN(body_step)(t, b, x, kind, integrator, normalize, dt, hq);
            for (i = 0; i < LV_STATE_SIZE; i++) t->T[i][b] = x[i];
        }
    }
}

typedef void (*LV_FN(tile_fn))(LV_FN(tile) *LV_RESTRICT t, LV_REAL dt, long n_steps);

/* One specialized (constant kind, integrator and normalize flag) copy of the tile loop each, per instruction set
   (LV_ISA_COPIES): the loop over the bodies of a tile vectorizes for LV_FIXED_FREE / _TORQUE / _FORCE (one body
   per lane); LV_FIXED_ANY (the effect dispatch) stays scalar (the base copy only). */
#define LV_FIXED_TILE_FN(NAME, KIND, INTEGRATOR, NORMALIZE, SUFFIX, ATTR)                                     \
    ATTR LV_FIXED_FLATTEN static void LV_PASTE(LV_FN(NAME), _##SUFFIX)(LV_FN(tile) *LV_RESTRICT t, LV_REAL dt, \
                                                                       long n_steps)                          \
    {                                                                                                         \
        LV_FN(tile_steps)(t, KIND, INTEGRATOR, NORMALIZE, dt, n_steps);                                       \
    }
#define LV_FIXED_TILE_KIND(K, KIND, SUFFIX, ATTR)                                            \
    LV_FIXED_TILE_FN(K##_euler_n, KIND, LV_PATH_EULER, 1, SUFFIX, ATTR)                      \
    LV_FIXED_TILE_FN(K##_euler_r, KIND, LV_PATH_EULER, 0, SUFFIX, ATTR)                      \
    LV_FIXED_TILE_FN(K##_semi_n, KIND, LV_PATH_SEMI_IMPLICIT, 1, SUFFIX, ATTR)               \
    LV_FIXED_TILE_FN(K##_semi_r, KIND, LV_PATH_SEMI_IMPLICIT, 0, SUFFIX, ATTR)               \
    LV_FIXED_TILE_FN(K##_rk4_n, KIND, LV_PATH_RK4, 1, SUFFIX, ATTR)                          \
    LV_FIXED_TILE_FN(K##_rk4_r, KIND, LV_PATH_RK4, 0, SUFFIX, ATTR)
#define LV_FIXED_TILES(SUFFIX, ATTR)                                                         \
    LV_FIXED_TILE_KIND(free, LV_FIXED_FREE, SUFFIX, ATTR LV_TILE_H_SCHED_##SUFFIX)           \
    LV_FIXED_TILE_KIND(torque, LV_FIXED_TORQUE, SUFFIX, ATTR)                                \
    LV_FIXED_TILE_KIND(force, LV_FIXED_FORCE, SUFFIX, ATTR)
LV_ISA_COPIES(LV_FIXED_TILES)
LV_FIXED_TILE_KIND(any, LV_FIXED_ANY, base, )
#undef LV_FIXED_TILES
#undef LV_FIXED_TILE_KIND
#undef LV_FIXED_TILE_FN

#define LV_FIXED_ISA(NAME) LV_ISA_PICK(isa, NAME)
#define LV_FIXED_BASE(NAME) LV_PASTE(NAME, _base)
#define LV_FIXED_PICK(K, PICK)                                                                                   \
    (integrator == LV_PATH_EULER ? (normalize ? PICK(LV_FN(K##_euler_n)) : PICK(LV_FN(K##_euler_r)))       \
     : integrator == LV_PATH_SEMI_IMPLICIT ? (normalize ? PICK(LV_FN(K##_semi_n)) : PICK(LV_FN(K##_semi_r))) \
                                                       : (normalize ? PICK(LV_FN(K##_rk4_n)) : PICK(LV_FN(K##_rk4_r))))
/* The tile loop of kind (LV_FIXED_*), integrator and normalize flag, in instruction set isa (LV_ISA_*). */
static LV_FN(tile_fn) LV_FN(tile_pick)(int kind, int integrator, int normalize, int isa)
{
    (void)isa;
    return kind == LV_FIXED_FREE ? LV_FIXED_PICK(free, LV_FIXED_ISA)
         : kind == LV_FIXED_TORQUE ? LV_FIXED_PICK(torque, LV_FIXED_ISA)
         : kind == LV_FIXED_FORCE ? LV_FIXED_PICK(force, LV_FIXED_ISA) : LV_FIXED_PICK(any, LV_FIXED_BASE);
}
#undef LV_FIXED_PICK
#undef LV_FIXED_ISA
#undef LV_FIXED_BASE

static int LV_FN(tile_finite)(const LV_FN(tile) *t, long b)
{
    int k;
    for (k = 0; k < LV_STATE_SIZE; k++)
        if (!isfinite(t->T[k][b])) return 0;
    return 1;
}

/* Whether every body of tile t is finite: one pass over the rows (a lane loop that vectorizes, against 13 strided
   reads and branches per body). */
static int LV_FN(tile_all_finite)(const LV_FN(tile) *t)
{
    long b;
    int k, bad = 0;
    for (k = 0; k < LV_STATE_SIZE; k++)
        for (b = 0; b < t->nt; b++) bad |= !isfinite(t->T[k][b]);
    return !bad;
}

/* n_steps of a tile, checked per chunk of LV_FIXED_CHUNK steps; a chunk whose end state is non-finite is
   re-run step by step from its start (the same bits: a non-finite number never becomes finite again on these
   paths, new = old + something and normalization keeps a NaN) to find its first failing step. Returns -1, or
   that step with *fail_b the lowest failing body of the tile and last[] its last finite state. */
static long LV_FN(tile_run)(LV_FN(tile) *t, LV_FN(tile) *snap, LV_FN(tile_fn) fn, LV_REAL dt, long n_steps,
                            long *fail_b, LV_REAL *last)
{
    long c, cm, r, b;
    int k;
    for (c = 0; c < n_steps; c += cm) {
        cm = n_steps - c < LV_FIXED_CHUNK ? n_steps - c : LV_FIXED_CHUNK;
        memcpy(snap->T, t->T, sizeof t->T);
        fn(t, dt, cm);
        if (LV_FN(tile_all_finite)(t)) continue;
        memcpy(t->T, snap->T, sizeof t->T); /* some body went non-finite in this chunk: redo it step by step */
        for (r = 0; r < cm; r++) {
            memcpy(snap->T, t->T, sizeof t->T);
            fn(t, dt, 1);
            for (b = 0; b < t->nt; b++) {
                if (LV_FN(tile_finite)(t, b)) continue;
                *fail_b = b;
                for (k = 0; k < LV_STATE_SIZE; k++) last[k] = snap->T[k][b];
                return c + r;
            }
        }
        /* not reached: the non-finite end state of the chunk fails on the re-run */
    }
    return -1;
}

/* Tile t's bodies ids[0 .. t->nt-1] (of kind `kind`, LV_FIXED_*) from the arrays: states, masses, moments, effects,
   for LV_FIXED_TORQUE / LV_FIXED_FORCE their constant effect sums (in table order), and their Euler coefficients (the
   generated euler_coefficients, once per call) in a lane loop of their own, where the divisions vectorize. */
static void LV_FN(tile_fill)(LV_FN(tile) *LV_RESTRICT t, const long *ids, int kind, const LV_REAL *state,
                             const LV_REAL *params, const LV_FN(ref) *refs, const long *start)
{
    long b, e;
    int i;
    for (b = 0; b < t->nt; b++) {
        const LV_REAL *x = state + ids[b] * LV_STATE_SIZE, *prm = params + ids[b] * LV_PARAM_SIZE;
        LV_REAL F[3] = {(LV_REAL)LV_SUM_START, (LV_REAL)LV_SUM_START, (LV_REAL)LV_SUM_START},
            tau[3] = {(LV_REAL)LV_SUM_START, (LV_REAL)LV_SUM_START, (LV_REAL)LV_SUM_START};
        for (i = 0; i < LV_STATE_SIZE; i++) t->T[i][b] = x[i];
        for (i = 0; i < 3; i++) t->I[i][b] = prm[LV_PARAM_I_B + i];
        t->M[b] = prm[LV_PARAM_M];
        t->refs[b] = refs + start[ids[b]];
        t->nref[b] = start[ids[b] + 1] - start[ids[b]];
        if (kind == LV_FIXED_TORQUE || kind == LV_FIXED_FORCE) /* the constant sums, in table order */
            for (e = start[ids[b]]; e < start[ids[b] + 1]; e++)
                (void)LV_EFFECT_APPLY(refs[e].code, refs[e].p, x, x + LV_STATE_V_W, prm[LV_PARAM_M], prm + LV_PARAM_I_B,
                                      F, tau);
        for (i = 0; i < 3; i++) {
            t->P[i][b] = F[i];
            t->P[3 + i][b] = tau[i];
        }
    }
    for (b = 0; b < t->nt; b++) {
        const LV_REAL I[3] = {t->I[0][b], t->I[1][b], t->I[2][b]};
        LV_REAL cf[LV_EULER_SIZE];
        LV_K(euler_coefficients)(I, cf);
        for (i = 0; i < LV_EULER_SIZE; i++) t->C[i][b] = cf[i];
    }
}

/* The contract of lv_simulate (step.h) for plain bodies, an integrator with a fixed-step path (tableaux.h
   LV_INTEGRATOR_FIXED_PATH) and built-in effect codes (the caller checked them: any other code returns
   LV_UNKNOWN_EFFECT). */
static int LV_FN(simulate)(LV_REAL *state, const LV_REAL *params, long nb, const LV_REAL *effects, long ne,
                           long row_size, int integrator, int normalize, LV_REAL dt, long n_steps, int isa,
                           long *fail_step, long *fail_body)
{
    long *start = NULL, *order = NULL, *fill = NULL, e, b, j, k, n_every = 0, limit = n_steps, best = -1, s, fb;
    long first[LV_FIXED_KINDS + 1] = {0}, next[LV_FIXED_KINDS + 1];
    int *flags = NULL, every_flags = 0;
    LV_FN(ref) *refs = NULL;
    LV_FN(tile) *t = NULL, *snap = NULL;
    void *tiles = NULL; /* t and snap, each placed on a cache line (LV_FN(line_up)) */
    LV_REAL last[LV_STATE_SIZE];
    int status = LV_OK, kind;
    if (!LV_INTEGRATOR_FIXED_PATH(integrator)) return LV_BAD_ARGUMENT;
    if (ne > 0 && row_size < LV_EFFECT_ROW_PARAMS) return LV_BAD_ARGUMENT;
    start = (long *)calloc((size_t)nb + 1, sizeof(long));
    order = (long *)malloc(((size_t)nb + 1) * sizeof(long));
    fill = (long *)malloc(((size_t)nb + 1) * sizeof(long));
    flags = (int *)calloc((size_t)nb + 1, sizeof(int));
    tiles = malloc(2 * (sizeof *t + 64));
    if (start == NULL || order == NULL || fill == NULL || flags == NULL || tiles == NULL) { status = LV_NO_MEMORY; goto done; }
    t = (LV_FN(tile) *)LV_FN(line_up)(tiles);
    snap = (LV_FN(tile) *)LV_FN(line_up)(t + 1);
    /* the effect index (CSR, table order per body), as step.c's */
    for (e = 0; e < ne; e++) {
        const LV_REAL *row = effects + e * row_size;
        double head[LV_EFFECT_ROW_PARAMS]; /* code and body, exact in double: the one row check (step.c) */
        int np, code;
        long body;
        for (k = 0; k < LV_EFFECT_ROW_PARAMS; k++) head[k] = (double)row[k];
        status = lv_effect_row_check(head, row_size, nb, NULL, &np);
        if (status == LV_UNKNOWN_EFFECT) *fail_step = e;
        if (status != LV_OK) goto done;
        code = (int)row[LV_EFFECT_ROW_CODE];
        body = (long)row[LV_EFFECT_ROW_BODY];
        if (body == -1) { n_every++; every_flags |= lv_effect_flags(code); }
        else { start[body + 1]++; flags[body] |= lv_effect_flags(code); }
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
    /* bodies grouped by kind (LV_FIXED_*; in that order), tiles of ascending bodies within a kind, each
       advanced only as far as the earliest failure so far can still be beaten */
    for (b = 0; b < nb; b++) {
        const int f = flags[b] | (start[b + 1] > start[b] ? every_flags : 0);
        flags[b] = start[b + 1] == start[b] ? LV_FIXED_FREE
                 : (f & LV_EFFECT_USES_STATE) ? LV_FIXED_ANY
                 : (f & LV_EFFECT_FORCE) ? LV_FIXED_FORCE : LV_FIXED_TORQUE;
    }
    /* one counting pass: order = the bodies of kind 0, then kind 1, ..., each ascending (first[kind] where
       its run starts) */
    for (b = 0; b < nb; b++) first[flags[b] + 1]++;
    for (kind = 0; kind < LV_FIXED_KINDS; kind++) first[kind + 1] += first[kind];
    memcpy(next, first, sizeof first);
    for (b = 0; b < nb; b++) order[next[flags[b]]++] = b;
    for (kind = 0; kind < LV_FIXED_KINDS; kind++) {
        const LV_FN(tile_fn) fn = LV_FN(tile_pick)(kind, integrator, normalize, isa);
        const long *ids = order + first[kind];
        j = first[kind + 1] - first[kind];
        for (k = 0; k < j; k += t->nt) {
            long lim;
            t->nt = j - k < LV_FIXED_TILE ? j - k : LV_FIXED_TILE;
            LV_FN(tile_fill)(t, ids + k, kind, state, params, refs, start);
            lim = (best >= 0 && ids[k] < best && limit < n_steps) ? limit + 1 : limit;
            s = lim > 0 ? LV_FN(tile_run)(t, snap, fn, dt, lim, &fb, last) : -2;
            if (s == -2) continue;
            if (s < 0) {
                for (b = 0; b < t->nt; b++)
                    for (e = 0; e < LV_STATE_SIZE; e++) state[ids[k + b] * LV_STATE_SIZE + e] = t->T[e][b];
                continue;
            }
            if (s < limit || (s == limit && ids[k + fb] < best)) {
                limit = s;
                best = ids[k + fb];
                memcpy(state + best * LV_STATE_SIZE, last, sizeof last);
                status = LV_DIVERGED;
            }
        }
    }
done:
    free(start);
    free(order);
    free(fill);
    free(flags);
    free(refs);
    free(tiles);
    if (status == LV_DIVERGED) {
        *fail_step = limit;
        *fail_body = best;
    }
    return status;
}
