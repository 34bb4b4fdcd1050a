/* LavenderSim stepping loop (see step.h). Every equation comes from generated/kernels.c.

   The generated kernels are compiled as part of this translation unit (setup.py does not compile
   kernels.c separately), so the optimizer sees their bodies and inlines them into the step loops:
   an out-of-line call per right-hand side (and, under -fPIC, through the PLT) cost ~20% of a
   torque-free RK4 step. Inlining does not change the arithmetic (no -ffast-math, no contraction). */
#include <math.h>
#include <stdlib.h>
#include <string.h>

#include "kernels.c"
#include "step.h"

/* ---- the effect index -------------------------------------------------------------------------

   One effect acting on one body: its parameters and, for a user effect, its compiled function
   (NULL: a built-in effect, dispatched by code through the generated lv_effect_apply). */
typedef struct {
    const double *p;
    lv_effect_fn user;
    int code;
} lv_effect_ref;

/* The effects of every body, indexed once per lv_simulate call (CSR): body b's effects are
   refs[start[b] .. start[b+1]-1] in table order (the every-body ones included), and flags[b] is the OR
   of their LV_EFFECT_USES_* flags. Building it is O(nb + entries); a body's right-hand side then costs
   its own effects only. */
typedef struct {
    long *start;
    lv_effect_ref *refs;
    int *flags;
} lv_effect_index;

/* Number of parameters of effect `code` (built-in, or a user code with an entry in `user`), its flags
   and, for a user effect, its function; -1 if no declared effect has this code. */
static int effect_info(int code, const lv_user_effects *user, int *flags, lv_effect_fn *fn)
{
    const int n = lv_effect_n_params(code);
    *fn = NULL;
    *flags = 0;
    if (n >= 0) {
        *flags = lv_effect_flags(code);
        return n;
    }
    if (user != NULL && code >= LV_EFFECT_USER_BASE && code - LV_EFFECT_USER_BASE < user->n) {
        const lv_user_effect *u = &user->entries[code - LV_EFFECT_USER_BASE];
        if (u->fn != NULL && u->n_params >= 0) {
            *fn = u->fn;
            *flags = u->flags;
            return u->n_params;
        }
    }
    return -1;
}

static void index_free(lv_effect_index *ix)
{
    free(ix->start);
    free(ix->refs);
    free(ix->flags);
    ix->start = NULL;
    ix->refs = NULL;
    ix->flags = NULL;
}

/* Build the index of the effect table (ne rows of row_size doubles). Returns LV_OK; LV_UNKNOWN_EFFECT
   with *bad_row = the first row whose code no declared effect has (or whose parameters do not fit the
   row); LV_BAD_ARGUMENT for a body index outside [-1, nb); LV_NO_MEMORY. Nothing to free unless LV_OK. */
static int index_build(lv_effect_index *ix, const double *effects, long ne, long row_size, long nb,
                       const lv_user_effects *user, long *bad_row)
{
    long e, b, n_every = 0, *fill;
    lv_effect_fn fn;
    int flags;
    ix->start = (long *)calloc((size_t)nb + 1, sizeof(long));
    ix->flags = (int *)calloc((size_t)nb + 1, sizeof(int));
    ix->refs = NULL;
    if (ix->start == NULL || ix->flags == NULL) { index_free(ix); return LV_NO_MEMORY; }
    for (e = 0; e < ne; e++) {
        const double *row = effects + e * row_size;
        const int code = (int)row[LV_EFFECT_ROW_CODE];
        const long target = (long)row[LV_EFFECT_ROW_BODY];
        const int np = (double)code == row[LV_EFFECT_ROW_CODE] ? effect_info(code, user, &flags, &fn) : -1;
        if (np < 0 || np > row_size - LV_EFFECT_ROW_PARAMS) { *bad_row = e; index_free(ix); return LV_UNKNOWN_EFFECT; }
        if (target < -1 || target >= nb) { *bad_row = e; index_free(ix); return LV_BAD_ARGUMENT; }
        if (target == -1) n_every++; else ix->start[target + 1]++;
    }
    for (b = 0; b < nb; b++) ix->start[b + 1] += ix->start[b] + n_every;
    ix->refs = (lv_effect_ref *)malloc(((size_t)ix->start[nb] + 1) * sizeof(lv_effect_ref));
    fill = (long *)malloc(((size_t)nb + 1) * sizeof(long));
    if (ix->refs == NULL || fill == NULL) { free(fill); index_free(ix); return LV_NO_MEMORY; }
    memcpy(fill, ix->start, (size_t)nb * sizeof(long));
    for (e = 0; e < ne; e++) {
        const double *row = effects + e * row_size;
        const long target = (long)row[LV_EFFECT_ROW_BODY];
        lv_effect_ref ref;
        ref.code = (int)row[LV_EFFECT_ROW_CODE];
        ref.p = row + LV_EFFECT_ROW_PARAMS;
        (void)effect_info(ref.code, user, &flags, &fn);
        ref.user = fn;
        if (target == -1) {
            for (b = 0; b < nb; b++) { ix->refs[fill[b]++] = ref; ix->flags[b] |= flags; }
        } else {
            ix->refs[fill[target]++] = ref;
            ix->flags[target] |= flags;
        }
    }
    free(fill);
    return LV_OK;
}

/* Force at the COM and torque about it (world), summed over one body's effects in table order. v_w is
   the COM velocity the effects see (the state's, or a joint's kinematic one). The codes were checked
   when the index was built, so lv_effect_apply always finds them. */
static inline void effect_sums(const double *x, const double *v_w, double m, const double *I_b,
                               const lv_effect_ref *refs, long n, double *F, double *tau)
{
    long k;
    for (k = 0; k < n; k++) {
        if (refs[k].user != NULL)
            refs[k].user(refs[k].p, x, v_w, m, I_b, F, tau);
        else
            (void)lv_effect_apply(refs[k].code, refs[k].p, x, v_w, m, I_b, F, tau);
    }
}

/* d/dt of one plain body's state: the free kernel when no effect applies, else the effects' force and
   torque summed in table order and passed to the full right-hand side. */
static void body_rhs(const double *x, const double *prm, const lv_effect_ref *refs, long n_refs, double *xdot)
{
    const double m = prm[0];
    const double *I_b = prm + 1;
    double F[3] = {0.0, 0.0, 0.0}, tau[3] = {0.0, 0.0, 0.0};
    if (n_refs == 0) {
        lv_rigid_body_rhs_free(x, I_b, xdot);
        return;
    }
    effect_sums(x, x + 7, m, I_b, refs, n_refs, F, tau);
    lv_rigid_body_rhs(x, m, I_b, F, tau, xdot);
}

static int all_finite(const double *x)
{
    int i;
    for (i = 0; i < LV_STATE_SIZE; i++)
        if (!isfinite(x[i])) return 0;
    return 1;
}

/* Bodies stepped in lockstep: one body's step is a chain of dependent divisions and square roots
   (latency-bound), so interleaving a few independent bodies lets the CPU overlap them. Each body's
   arithmetic is exactly the single-body sequence, so results do not depend on the blocking. */
#define LV_BLOCK 8

/* Advance bodies ids[0 .. n-1] (n <= LV_BLOCK, ascending) by n_steps. Their rows are read at the start
   and written only on success. Returns -1 on success, else the 0-based failing step; then *fail_j is the
   first (lowest-index) body of the block that went non-finite at that step and last[] holds the block's
   last finite states. */
static inline long advance_block(double *state, const double *params, const long *ids, int n,
                          const lv_effect_index *ix, int integrator, int normalize,
                          double dt, long n_steps, int *fail_j, double last[][LV_STATE_SIZE])
{
    double x[LV_BLOCK][LV_STATE_SIZE], xn[LV_BLOCK][LV_STATE_SIZE], k1[LV_BLOCK][LV_STATE_SIZE],
        k2[LV_BLOCK][LV_STATE_SIZE], k3[LV_BLOCK][LV_STATE_SIZE], k4[LV_BLOCK][LV_STATE_SIZE],
        tmp[LV_BLOCK][LV_STATE_SIZE];
    const double *prm[LV_BLOCK];
    const lv_effect_ref *refs[LV_BLOCK];
    long n_refs[LV_BLOCK];
    const double h2 = 0.5 * dt, h6 = dt / 6.0;
    long s;
    int i, j;
    for (j = 0; j < n; j++) {
        const long b = ids[j];
        prm[j] = params + b * LV_PARAM_SIZE;
        refs[j] = ix->refs + ix->start[b];
        n_refs[j] = ix->start[b + 1] - ix->start[b];
        memcpy(x[j], state + b * LV_STATE_SIZE, sizeof x[j]);
    }
#define RHS(in, out) for (j = 0; j < n; j++) body_rhs(in[j], prm[j], refs[j], n_refs[j], out[j])
    for (s = 0; s < n_steps; s++) {
        switch (integrator) {
        case LV_INTEGRATOR_EULER:
            RHS(x, k1);
            for (j = 0; j < n; j++)
                for (i = 0; i < LV_STATE_SIZE; i++) xn[j][i] = x[j][i] + dt * k1[j][i];
            break;
        case LV_INTEGRATOR_SEMI_IMPLICIT_EULER:
            RHS(x, k1);
            for (j = 0; j < n; j++) {
                for (i = 7; i < 13; i++) xn[j][i] = x[j][i] + dt * k1[j][i];      /* v', omega' */
                for (i = 0; i < 3; i++) xn[j][i] = x[j][i] + dt * xn[j][7 + i];   /* p' = p + dt v' */
                lv_quat_derivative_body(x[j] + 3, xn[j] + 10, tmp[j]);          /* q rate at omega' */
                for (i = 0; i < 4; i++) xn[j][3 + i] = x[j][3 + i] + dt * tmp[j][i];
            }
            break;
        default: /* LV_INTEGRATOR_RK4; stage quaternions left unnormalized */
            RHS(x, k1);
            for (j = 0; j < n; j++)
                for (i = 0; i < LV_STATE_SIZE; i++) tmp[j][i] = x[j][i] + h2 * k1[j][i];
            RHS(tmp, k2);
            for (j = 0; j < n; j++)
                for (i = 0; i < LV_STATE_SIZE; i++) tmp[j][i] = x[j][i] + h2 * k2[j][i];
            RHS(tmp, k3);
            for (j = 0; j < n; j++)
                for (i = 0; i < LV_STATE_SIZE; i++) tmp[j][i] = x[j][i] + dt * k3[j][i];
            RHS(tmp, k4);
            for (j = 0; j < n; j++)
                for (i = 0; i < LV_STATE_SIZE; i++)
                    xn[j][i] = x[j][i] + h6 * (k1[j][i] + 2.0 * k2[j][i] + 2.0 * k3[j][i] + k4[j][i]);
            break;
        }
        if (normalize)
            for (j = 0; j < n; j++) lv_quat_normalize(xn[j] + 3, xn[j] + 3);
        for (j = 0; j < n; j++) {
            if (!all_finite(xn[j])) {
                *fail_j = j;
                memcpy(last, x, (size_t)n * sizeof x[0]);
                return s;
            }
        }
        memcpy(x, xn, (size_t)n * sizeof x[0]);
    }
#undef RHS
    for (j = 0; j < n; j++) memcpy(state + ids[j] * LV_STATE_SIZE, x[j], sizeof x[j]);
    return -1;
}

/* Right-hand sides on the lockstep RK4 path (`forced`): LV_RHS_FREE the free kernel; else each body's
   effects summed in table order, then LV_RHS_FULL the full kernel (as body_rhs), or LV_RHS_TORQUE the
   torque-only one for bodies whose effects add no force (bitwise the full kernel with F = 0). */
enum { LV_RHS_FREE = 0, LV_RHS_TORQUE = 1, LV_RHS_FULL = 2 };
#define LV_RK4_RHS(in, out)                                                                             \
    do {                                                                                                \
        if (forced == LV_RHS_FREE) {                                                                    \
            for (j = 0; j < n; j++) lv_rigid_body_rhs_free(in[j], I[j], out[j]);                        \
        } else {                                                                                        \
            for (j = 0; j < n; j++) {                                                                   \
                F[j][0] = F[j][1] = F[j][2] = tau[j][0] = tau[j][1] = tau[j][2] = 0.0;                  \
                effect_sums(in[j], in[j] + 7, m[j], I[j], refs[j], n_refs[j], F[j], tau[j]);            \
            }                                                                                           \
            if (forced == LV_RHS_TORQUE)                                                                \
                for (j = 0; j < n; j++) lv_rigid_body_rhs_torque(in[j], I[j], tau[j], out[j]);          \
            else                                                                                        \
                for (j = 0; j < n; j++) lv_rigid_body_rhs(in[j], m[j], I[j], F[j], tau[j], out[j]);     \
        }                                                                                               \
    } while (0)

/* One RK4 step of bodies 0 .. n-1: x -> xn (LV_RK4_RHS, the RK4 combination, q normalized with the
   generated kernel when asked). */
#define LV_FREE_RK4_STEP()                                                                              \
    do {                                                                                                \
        LV_RK4_RHS(x, k1);                                                                              \
        for (j = 0; j < n; j++)                                                                         \
            for (i = 0; i < LV_STATE_SIZE; i++) tmp[j][i] = x[j][i] + h2 * k1[j][i];                    \
        LV_RK4_RHS(tmp, k2);                                                                            \
        for (j = 0; j < n; j++)                                                                         \
            for (i = 0; i < LV_STATE_SIZE; i++) tmp[j][i] = x[j][i] + h2 * k2[j][i];                    \
        LV_RK4_RHS(tmp, k3);                                                                            \
        for (j = 0; j < n; j++)                                                                         \
            for (i = 0; i < LV_STATE_SIZE; i++) tmp[j][i] = x[j][i] + dt * k3[j][i];                    \
        LV_RK4_RHS(tmp, k4);                                                                            \
        for (j = 0; j < n; j++)                                                                         \
            for (i = 0; i < LV_STATE_SIZE; i++)                                                         \
                xn[j][i] = x[j][i] + h6 * (k1[j][i] + 2.0 * k2[j][i] + 2.0 * k3[j][i] + k4[j][i]);      \
        if (normalize)                                                                                  \
            for (j = 0; j < n; j++) lv_quat_normalize(xn[j] + 3, xn[j] + 3);                            \
    } while (0)

/* LV_FLATTEN: inline every call in the function (its kernels included), so each call with constant block
   size, kind and normalize flag compiles to its own straight-line loop (GCC and clang; elsewhere a
   plain function). */
#if defined(__GNUC__) || defined(__clang__)
#define LV_FLATTEN __attribute__((flatten))
#else
#define LV_FLATTEN
#endif

/* Steps between finiteness checks on the torque-free path (see advance_free_rk4). */
#define LV_FREE_CHUNK 64

/* RK4 fast path on plain bodies, `forced` (LV_RHS_*) of them all: torque-free (no effect acts on them;
   the common free-flight scene), or with effects, each body summed over its own (from the index ix).
   The same arithmetic as advance_block (the same right-hand side, RK4 combination, q normalized with
   the generated kernel), so results are bitwise identical; without the integrator switch the loop is a
   straight chain the compiler can schedule (and, for a block, overlap). Inlined into
   advance_rk4_group with constant n, forced (and, free, normalize). Same contract as advance_block.

   Finiteness is checked once per chunk of LV_FREE_CHUNK steps instead of after every step (the 13 tests
   per body-step cost ~10% of a step). This is exact because on this path a non-finite number never
   becomes finite again: every new number is old + (something) (inf + finite = inf; inf + -inf, NaN + any
   = NaN), and normalization maps a q with an inf or NaN component to one with a NaN (1/sqrt(inf) = 0 and
   inf * 0 = NaN; NaN propagates) — whatever the right-hand side, effects included. So if any state in
   the chunk went non-finite its end state is
   non-finite too; then the chunk is re-run from its start with a check after every step, which
   recomputes the same bits (deterministic arithmetic) and finds the first failing step and body. */
static inline long advance_free_rk4(double *state, const double *params, const long *ids, int n,
                                    const lv_effect_index *ix, int forced, int normalize,
                                    double dt, long n_steps, int *fail_j, double last[][LV_STATE_SIZE])
{
    double x[LV_BLOCK][LV_STATE_SIZE], xn[LV_BLOCK][LV_STATE_SIZE], k1[LV_BLOCK][LV_STATE_SIZE],
        k2[LV_BLOCK][LV_STATE_SIZE], k3[LV_BLOCK][LV_STATE_SIZE], k4[LV_BLOCK][LV_STATE_SIZE],
        tmp[LV_BLOCK][LV_STATE_SIZE], I[LV_BLOCK][3], snap[LV_BLOCK][LV_STATE_SIZE];
    double F[LV_BLOCK][3], tau[LV_BLOCK][3], m[LV_BLOCK];
    const lv_effect_ref *refs[LV_BLOCK];
    long n_refs[LV_BLOCK];
    const double h2 = 0.5 * dt, h6 = dt / 6.0;
    long s, c, cm;
    int i, j, ok;
    for (j = 0; j < n; j++) {
        memcpy(x[j], state + ids[j] * LV_STATE_SIZE, sizeof x[j]);
        memcpy(I[j], params + ids[j] * LV_PARAM_SIZE + 1, sizeof I[j]);
        m[j] = params[ids[j] * LV_PARAM_SIZE];
        refs[j] = ix->refs + ix->start[ids[j]];
        n_refs[j] = ix->start[ids[j] + 1] - ix->start[ids[j]];
    }
    for (c = 0; c < n_steps; c += cm) {
        cm = n_steps - c < LV_FREE_CHUNK ? n_steps - c : LV_FREE_CHUNK;
        memcpy(snap, x, (size_t)n * sizeof x[0]);
        for (s = 0; s < cm; s++) {
            LV_FREE_RK4_STEP();
            memcpy(x, xn, (size_t)n * sizeof x[0]);
        }
        ok = 1;
        for (j = 0; j < n; j++) ok &= all_finite(x[j]);
        if (ok) continue;
        /* some body went non-finite in this chunk: redo it step by step from its start */
        memcpy(x, snap, (size_t)n * sizeof x[0]);
        for (s = 0; s < cm; s++) {
            LV_FREE_RK4_STEP();
            for (j = 0; j < n; j++) {
                if (!all_finite(xn[j])) {
                    *fail_j = j;
                    memcpy(last, x, (size_t)n * sizeof x[0]);
                    return c + s;
                }
            }
            memcpy(x, xn, (size_t)n * sizeof x[0]);
        }
        /* not reached: the non-finite end state of the chunk must fail on the re-run */
    }
    for (j = 0; j < n; j++) memcpy(state + ids[j] * LV_STATE_SIZE, x[j], sizeof x[j]);
    return -1;
}
#undef LV_FREE_RK4_STEP
#undef LV_RK4_RHS

/* ---- bodies with a spherical joint and/or reaction wheels ------------------------------------ */

/* extended state: x[13] then Omega[3] */
#define LV_XS 16

/* d/dt of [x, Omega] for a body of nonzero kind; u = this step's applied wheel torques.
   r = its model row. A jointed body's p, v derivatives are zero (set from the joint after the step);
   its effects that read v_w see the kinematic COM velocity (computed only when needs_v). */
static void model_rhs(const double *y, const double *u, double m, const double *I_b, const double *r, int kind,
                      int needs_v, const lv_effect_ref *refs, long n_refs, double *yd)
{
    double F[3] = {0.0, 0.0, 0.0}, tau[3] = {0.0, 0.0, 0.0}, pk[3], vk[3];
    const double *v = y + 7;
    int i;
    if (needs_v) {
        lv_pivot_kinematics(y + 3, y + 10, r + 13, r + 10, pk, vk);
        v = vk;
    }
    effect_sums(y, v, m, I_b, refs, n_refs, F, tau);
    if (kind & LV_KIND_WHEELS) {
        lv_wheel_body_rhs(y + 3, y + 10, y + 13, r + 1, r + 16, r + 10, F, tau, u, r[21], yd + 3, yd + 10, yd + 13);
    } else {
        lv_pivot_body_rhs(y + 3, y + 10, r + 1, r + 10, F, tau, yd + 3, yd + 10);
        yd[13] = yd[14] = yd[15] = 0.0;
    }
    if (kind & LV_KIND_JOINT) {
        for (i = 0; i < 3; i++) yd[i] = yd[7 + i] = 0.0;
    } else {
        for (i = 0; i < 3; i++) { yd[i] = y[7 + i]; yd[7 + i] = F[i] / m; }
    }
}

/* Zero-order-hold saturation: clip to +-torque_limit; no drive beyond speed_limit. */
static void saturate(const double *cmd, const double *Omega, double tl, double sl, double *u)
{
    int i;
    for (i = 0; i < 3; i++) {
        double c = cmd[i];
        c = c < -tl ? -tl : (c > tl ? tl : c);
        if (fabs(Omega[i]) >= sl && c * Omega[i] > 0.0) c = 0.0;
        u[i] = c;
    }
}

/* Advance body b (nonzero kind) by n_steps. Its rows are written only on success; returns -1, or the
   0-based failing step with last[] = its last finite [x, Omega]. */
static long advance_model(double *state, const double *params, long b, const lv_models *md,
                          const lv_effect_index *ix, int integrator, int normalize,
                          double dt, long n_steps, double *last)
{
    const double *r = md->rows + b * LV_MODEL_SIZE;
    const int kind = (int)r[0];
    const double m = params[b * LV_PARAM_SIZE];
    const double *cmd = md->command + 3 * b;
    double y[LV_XS], yn[LV_XS], k1[LV_XS], k2[LV_XS], k3[LV_XS], k4[LV_XS], tmp[LV_XS];
    double u[3] = {0.0, 0.0, 0.0}, applied[3];
    const double h2 = 0.5 * dt, h6 = dt / 6.0;
    const double *I_b = params + b * LV_PARAM_SIZE + 1;
    const lv_effect_ref *refs = ix->refs + ix->start[b];
    const long n_refs = ix->start[b + 1] - ix->start[b];
    const int needs_v = (kind & LV_KIND_JOINT) && (ix->flags[b] & LV_EFFECT_USES_V);
    long s;
    int i;
    memcpy(y, state + b * LV_STATE_SIZE, LV_STATE_SIZE * sizeof(double));
    memcpy(y + LV_STATE_SIZE, md->Omega + 3 * b, 3 * sizeof(double));
    memcpy(applied, md->applied + 3 * b, sizeof applied);
#define MRHS(in, out) model_rhs(in, u, m, I_b, r, kind, needs_v, refs, n_refs, out)
    for (s = 0; s < n_steps; s++) {
        if (kind & LV_KIND_WHEELS) saturate(cmd, y + 13, r[19], r[20], u);
        switch (integrator) {
        case LV_INTEGRATOR_EULER:
            MRHS(y, k1);
            for (i = 0; i < LV_XS; i++) yn[i] = y[i] + dt * k1[i];
            break;
        case LV_INTEGRATOR_SEMI_IMPLICIT_EULER:
            MRHS(y, k1);
            for (i = 7; i < LV_XS; i++) yn[i] = y[i] + dt * k1[i];    /* v', omega', Omega' */
            for (i = 0; i < 3; i++) yn[i] = y[i] + dt * yn[7 + i];    /* p' = p + dt v' */
            lv_quat_derivative_body(y + 3, yn + 10, tmp);              /* q rate at omega' */
            for (i = 0; i < 4; i++) yn[3 + i] = y[3 + i] + dt * tmp[i];
            break;
        default: /* LV_INTEGRATOR_RK4 */
            MRHS(y, k1);
            for (i = 0; i < LV_XS; i++) tmp[i] = y[i] + h2 * k1[i];
            MRHS(tmp, k2);
            for (i = 0; i < LV_XS; i++) tmp[i] = y[i] + h2 * k2[i];
            MRHS(tmp, k3);
            for (i = 0; i < LV_XS; i++) tmp[i] = y[i] + dt * k3[i];
            MRHS(tmp, k4);
            for (i = 0; i < LV_XS; i++) yn[i] = y[i] + h6 * (k1[i] + 2.0 * k2[i] + 2.0 * k3[i] + k4[i]);
            break;
        }
        if (normalize) lv_quat_normalize(yn + 3, yn + 3);
        if (kind & LV_KIND_JOINT) lv_pivot_kinematics(yn + 3, yn + 10, r + 13, r + 10, yn, yn + 7);
        for (i = 0; i < LV_XS; i++) {
            if (!isfinite(yn[i])) {
                memcpy(last, y, sizeof y);
                return s;
            }
        }
        memcpy(y, yn, sizeof y);
        memcpy(applied, u, sizeof u);
    }
#undef MRHS
    memcpy(state + b * LV_STATE_SIZE, y, LV_STATE_SIZE * sizeof(double));
    memcpy(md->Omega + 3 * b, y + LV_STATE_SIZE, 3 * sizeof(double));
    memcpy(md->applied + 3 * b, applied, sizeof applied);
    return -1;
}

/* ---- per-body integrators: dopri5 (any kind), splitting and implicit_gyro (plain bodies) ------- */

/* One body's right-hand side on the extended state [x, Omega] (16): plain bodies get Omega' = 0. */
typedef struct {
    long b;
    int kind, has, needs_v, flags;
    double m;
    const double *prm, *r;
    const lv_effect_ref *refs;
    long n_refs;
    double u[3];
} body_ctx;

static void ctx_rhs(const body_ctx *c, const double *y, double *yd)
{
    if (c->kind == 0) {
        body_rhs(y, c->prm, c->refs, c->n_refs, yd);
        yd[13] = yd[14] = yd[15] = 0.0;
    } else {
        model_rhs(y, c->u, c->m, c->prm + 1, c->r, c->kind, c->needs_v, c->refs, c->n_refs, yd);
    }
}

static void ctx_init(body_ctx *c, const double *params, long b, const lv_models *md, const lv_effect_index *ix)
{
    c->b = b;
    c->prm = params + b * LV_PARAM_SIZE;
    c->m = c->prm[0];
    c->refs = ix->refs + ix->start[b];
    c->n_refs = ix->start[b + 1] - ix->start[b];
    c->flags = ix->flags[b];
    c->kind = md != NULL ? (int)md->rows[b * LV_MODEL_SIZE] : 0;
    c->r = md != NULL ? md->rows + b * LV_MODEL_SIZE : NULL;
    c->has = c->n_refs > 0;
    c->needs_v = (c->kind & LV_KIND_JOINT) && (c->flags & LV_EFFECT_USES_V);
    c->u[0] = c->u[1] = c->u[2] = 0.0;
}

/* Dormand-Prince 5(4) tableau (Hairer, Norsett & Wanner, Solving ODEs I, table 5.2). The nodes c_i
   are not needed: the right-hand side does not depend on time. */
static const double DP_A[7][6] = {
    {0, 0, 0, 0, 0, 0},
    {1.0 / 5, 0, 0, 0, 0, 0},
    {3.0 / 40, 9.0 / 40, 0, 0, 0, 0},
    {44.0 / 45, -56.0 / 15, 32.0 / 9, 0, 0, 0},
    {19372.0 / 6561, -25360.0 / 2187, 64448.0 / 6561, -212.0 / 729, 0, 0},
    {9017.0 / 3168, -355.0 / 33, 46732.0 / 5247, 49.0 / 176, -5103.0 / 18656, 0},
    {35.0 / 384, 0, 500.0 / 1113, 125.0 / 192, -2187.0 / 6784, 11.0 / 84}};
/* error weights: b5 - b4 */
static const double DP_E[7] = {71.0 / 57600, 0.0, -71.0 / 16695, 71.0 / 1920, -17253.0 / 339200, 22.0 / 525, -1.0 / 40};

#define DP_SAFETY 0.9
#define DP_FACMIN 0.2
#define DP_FACMAX 5.0
#define DP_HMIN_REL 1e-12
#define DP_MAX_SUBSTEPS 1000000L

/* RMS of e / (atol + rtol max(|y|, |yn|)) over the first n numbers (Hairer's norm). */
static double dp_norm(const double *e, const double *y, const double *yn, int n, double rtol, double atol)
{
    double s = 0.0;
    int i;
    for (i = 0; i < n; i++) {
        const double a = fabs(y[i]), bb = fabs(yn[i]);
        const double sc = atol + rtol * (a > bb ? a : bb);
        if (e[i] != 0.0) { /* an exact zero counts 0, even with atol = 0 */
            const double z = e[i] / sc;
            s += z * z;
        }
    }
    return sqrt(s / n);
}

/* Hairer's starting step (Solving ODEs I, II.4): from f0 = f(y) and one more evaluation. */
static double dp_initial_h(const body_ctx *c, const double *y, const double *f0, int n, double rtol, double atol,
                           double dt, double *nfev)
{
    double y1[LV_XS], f1[LV_XS], d[LV_XS], d0, d1, d2, h0, h1, mx;
    int i;
    for (i = 0; i < n; i++) d[i] = 0.0;
    d0 = dp_norm(y, y, y, n, rtol, atol);
    d1 = dp_norm(f0, y, y, n, rtol, atol);
    h0 = (d0 < 1e-5 || d1 < 1e-5) ? 1e-6 : 0.01 * d0 / d1;
    if (h0 > dt) h0 = dt;
    for (i = 0; i < LV_XS; i++) y1[i] = y[i] + h0 * f0[i];
    ctx_rhs(c, y1, f1);
    *nfev += 1;
    for (i = 0; i < n; i++) d[i] = (f1[i] - f0[i]) / h0;
    d2 = dp_norm(d, y, y, n, rtol, atol);
    mx = d1 > d2 ? d1 : d2;
    h1 = mx <= 1e-15 ? (h0 * 1e-3 > 1e-6 ? h0 * 1e-3 : 1e-6) : pow(0.01 / mx, 0.2);
    h0 = 100.0 * h0 < h1 ? 100.0 * h0 : h1;
    return isfinite(h0) && h0 > 0.0 ? h0 : dt;
}

/* After an accepted substep: normalize q, put a jointed body back on its joint. */
static void ctx_finish(const body_ctx *c, double *y, int normalize)
{
    if (normalize) lv_quat_normalize(y + 3, y + 3);
    if (c->kind & LV_KIND_JOINT) lv_pivot_kinematics(y + 3, y + 10, c->r + 13, c->r + 10, y, y + 7);
}

/* Advance body b by n_steps output steps of dt with dopri5. Returns -1 on success (rows written), else
   the failing step with *why = LV_DIVERGED or LV_TOLERANCE and last[] = its last accepted state. */
static long advance_dopri5(double *state, const double *params, long b, const lv_models *md, const lv_effect_index *ix,
                           int normalize, double dt, long n_steps, const lv_adaptive *ad, int *why, double *last)
{
    body_ctx c;
    double y[LV_XS], yn[LV_XS], k[7][LV_XS], tmp[LV_XS], err[LV_XS], applied[3];
    double h, nfev = 0.0;
    const double rtol = ad->rtol, atol = ad->atol, hmin = DP_HMIN_REL * dt;
    const double *cmd = NULL;
    int have_k1 = 0, n, i, s2, j;
    long s;
    ctx_init(&c, params, b, md, ix);
    n = c.kind & LV_KIND_WHEELS ? LV_XS : LV_STATE_SIZE;
    memcpy(y, state + b * LV_STATE_SIZE, LV_STATE_SIZE * sizeof(double));
    y[13] = y[14] = y[15] = 0.0;
    if (c.kind) {
        memcpy(y + LV_STATE_SIZE, md->Omega + 3 * b, 3 * sizeof(double));
        memcpy(applied, md->applied + 3 * b, sizeof applied);
        cmd = md->command + 3 * b;
    }
    h = ad->h[b];
    for (s = 0; s < n_steps; s++) {
        double t = 0.0;
        long sub = 0;
        int rejected = 0;
        if (c.kind & LV_KIND_WHEELS) {
            saturate(cmd, y + 13, c.r[19], c.r[20], c.u);
            have_k1 = 0; /* the held torque may change at each output step */
        }
        if (!have_k1) {
            ctx_rhs(&c, y, k[0]);
            nfev += 1;
            have_k1 = 1;
        }
        if (!(h > 0.0) || !isfinite(h)) h = dp_initial_h(&c, y, k[0], n, rtol, atol, dt, &nfev);
        while (t < dt) {
            const double rem = dt - t;
            const int clipped = h >= rem;
            const double hs = clipped ? rem : h;
            double e;
            for (s2 = 1; s2 < 7; s2++) {
                for (i = 0; i < LV_XS; i++) {
                    double acc = 0.0;
                    for (j = 0; j < s2; j++) acc += DP_A[s2][j] * k[j][i];
                    tmp[i] = y[i] + hs * acc;
                }
                ctx_rhs(&c, tmp, k[s2]);
            }
            nfev += 6;
            for (i = 0; i < LV_XS; i++) yn[i] = tmp[i]; /* stage 7 is evaluated at the 5th-order solution */
            for (i = 0; i < LV_XS; i++) {
                double acc = 0.0;
                for (j = 0; j < 7; j++) acc += DP_E[j] * k[j][i];
                err[i] = hs * acc;
            }
            e = dp_norm(err, y, yn, n, rtol, atol);
            if (e <= 1.0) {
                double fac = e == 0.0 ? DP_FACMAX : DP_SAFETY * pow(e, -0.2);
                if (fac > DP_FACMAX) fac = DP_FACMAX;
                if (fac < DP_FACMIN) fac = DP_FACMIN;
                if (rejected && fac > 1.0) fac = 1.0;
                t = clipped ? dt : t + hs;
                /* a step shortened to land on the output time does not shrink the proposal */
                if (!(clipped && fac >= 1.0 && h > hs * fac)) h = hs * fac;
                ctx_finish(&c, yn, normalize);
                for (i = 0; i < LV_XS; i++) {
                    if (!isfinite(yn[i])) {
                        *why = LV_DIVERGED;
                        memcpy(last, y, sizeof y);
                        ad->nfev[b] += nfev;
                        return s;
                    }
                }
                memcpy(y, yn, sizeof y);
                memcpy(k[0], k[6], sizeof k[0]); /* FSAL: f at the new (un-normalized) point */
                rejected = 0;
            } else {
                double fac = isfinite(e) ? DP_SAFETY * pow(e, -0.2) : DP_FACMIN;
                if (fac < DP_FACMIN) fac = DP_FACMIN;
                if (fac > 1.0) fac = 1.0;
                h = hs * fac;
                rejected = 1;
            }
            if (h < hmin || ++sub > DP_MAX_SUBSTEPS) {
                *why = LV_TOLERANCE;
                memcpy(last, y, sizeof y);
                ad->h[b] = h;
                ad->nfev[b] += nfev;
                return s;
            }
        }
        if (c.kind) memcpy(applied, c.u, sizeof applied);
    }
    memcpy(state + b * LV_STATE_SIZE, y, LV_STATE_SIZE * sizeof(double));
    if (c.kind) {
        memcpy(md->Omega + 3 * b, y + LV_STATE_SIZE, 3 * sizeof(double));
        memcpy(md->applied + 3 * b, applied, sizeof applied);
    }
    ad->h[b] = h;
    ad->nfev[b] += nfev;
    return -1;
}

/* Exact flow for time h of H_a = L_a^2 / (2 I_a): body momentum L turns about body axis a by -h L_a/I_a
   and the attitude turns about it by +h L_a/I_a (q <- q (x) [sin(th/2) e_a, cos(th/2)]). */
static void axis_flow(const double *I, double *q, double *L, int a, double h)
{
    const double th = h * L[a] / I[a];
    const int j = (a + 1) % 3, k = (a + 2) % 3;
    const double sh = sin(0.5 * th), ch = cos(0.5 * th);
    const double c = 1.0 - 2.0 * sh * sh, s = 2.0 * sh * ch;
    const double Lj = L[j], Lk = L[k];
    double hq[4] = {0.0, 0.0, 0.0, 0.0};
    L[j] = c * Lj + s * Lk;
    L[k] = -s * Lj + c * Lk;
    hq[a] = sh;
    hq[3] = ch;
    lv_quat_mul(q, hq, q);
}

/* Force at the COM (world) and torque (body frame) of the effects on a plain body. */
static void plain_loads(const body_ctx *c, const double *x, double *F, double *tau_b)
{
    double tau_w[3] = {0.0, 0.0, 0.0};
    F[0] = F[1] = F[2] = 0.0;
    effect_sums(x, x + 7, c->m, c->prm + 1, c->refs, c->n_refs, F, tau_w);
    lv_world_to_body(x + 3, tau_w, tau_b);
}

/* Half kick of the splitting: v and omega (q, p fixed) under the effects for time h. One evaluation
   when the loads do not depend on v or omega (then exact); the explicit midpoint rule (two) with an
   effect that reads them (linear or angular damping, ...), which keeps the composition symmetric to
   second order. */
static void kick(const body_ctx *c, double *x, double h, int damped)
{
    const double *I = c->prm + 1;
    double F[3], tb[3], xm[LV_STATE_SIZE];
    int i;
    plain_loads(c, x, F, tb);
    if (damped) {
        memcpy(xm, x, sizeof xm);
        for (i = 0; i < 3; i++) {
            xm[7 + i] += 0.5 * h * F[i] / c->m;
            xm[10 + i] += 0.5 * h * tb[i] / I[i];
        }
        plain_loads(c, xm, F, tb);
    }
    for (i = 0; i < 3; i++) {
        x[7 + i] += h * F[i] / c->m;
        x[10 + i] += h * tb[i] / I[i];
    }
}

/* One splitting step: kick(h/2), drift p by h v, free rotation by Strang 1(h/2) 2(h/2) 3(h) 2(h/2) 1(h/2),
   kick(h/2). Second order, symmetric; torque-free it conserves L_w and |L_b| exactly (to rounding). */
static void splitting_step(const body_ctx *c, double *x, double h, int damped)
{
    const double *I = c->prm + 1;
    double L[3];
    int i;
    if (c->has) kick(c, x, 0.5 * h, damped);
    for (i = 0; i < 3; i++) {
        x[i] += h * x[7 + i];
        L[i] = I[i] * x[10 + i];
    }
    axis_flow(I, x + 3, L, 0, 0.5 * h);
    axis_flow(I, x + 3, L, 1, 0.5 * h);
    axis_flow(I, x + 3, L, 2, h);
    axis_flow(I, x + 3, L, 1, 0.5 * h);
    axis_flow(I, x + 3, L, 0, 0.5 * h);
    for (i = 0; i < 3; i++) x[10 + i] = L[i] / I[i];
    if (c->has) kick(c, x, 0.5 * h, damped);
}

/* Solve I (w1 - w) + h w1 x (I w1) = h tau_b for w1 by Newton's method (to rounding, at most 30
   iterations), starting from w1 = w. Solved exactly, the torque-free step never gains energy:
   E - E1 = (w - w1)^T I (w - w1) / 2 >= 0. */
static void gyro_newton(const double *I, const double *w, const double *tau_b, double h, double *w1)
{
    int it, r, col;
    w1[0] = w[0]; w1[1] = w[1]; w1[2] = w[2];
    for (it = 0; it < 30; it++) {
        const double L[3] = {I[0] * w1[0], I[1] * w1[1], I[2] * w1[2]};
        double g[3], J[3][3], d[3], det, A[3][3], nd, nw;
        g[0] = I[0] * (w1[0] - w[0]) + h * (w1[1] * L[2] - w1[2] * L[1]) - h * tau_b[0];
        g[1] = I[1] * (w1[1] - w[1]) + h * (w1[2] * L[0] - w1[0] * L[2]) - h * tau_b[1];
        g[2] = I[2] * (w1[2] - w[2]) + h * (w1[0] * L[1] - w1[1] * L[0]) - h * tau_b[2];
        /* J = I + h (skew(w1) I - skew(I w1)) */
        J[0][0] = I[0];                       J[0][1] = h * (-w1[2] * I[1] + L[2]); J[0][2] = h * (w1[1] * I[2] - L[1]);
        J[1][0] = h * (w1[2] * I[0] - L[2]);  J[1][1] = I[1];                       J[1][2] = h * (-w1[0] * I[2] + L[0]);
        J[2][0] = h * (-w1[1] * I[0] + L[1]); J[2][1] = h * (w1[0] * I[1] - L[0]);  J[2][2] = I[2];
        A[0][0] = J[1][1] * J[2][2] - J[1][2] * J[2][1];
        A[0][1] = J[0][2] * J[2][1] - J[0][1] * J[2][2];
        A[0][2] = J[0][1] * J[1][2] - J[0][2] * J[1][1];
        A[1][0] = J[1][2] * J[2][0] - J[1][0] * J[2][2];
        A[1][1] = J[0][0] * J[2][2] - J[0][2] * J[2][0];
        A[1][2] = J[0][2] * J[1][0] - J[0][0] * J[1][2];
        A[2][0] = J[1][0] * J[2][1] - J[1][1] * J[2][0];
        A[2][1] = J[0][1] * J[2][0] - J[0][0] * J[2][1];
        A[2][2] = J[0][0] * J[1][1] - J[0][1] * J[1][0];
        det = J[0][0] * A[0][0] + J[0][1] * A[1][0] + J[0][2] * A[2][0];
        nd = nw = 0.0;
        for (r = 0; r < 3; r++) {
            d[r] = 0.0;
            for (col = 0; col < 3; col++) d[r] += A[r][col] * g[col];
            d[r] /= det;
        }
        for (r = 0; r < 3; r++) {
            w1[r] -= d[r];
            nd += d[r] * d[r];
            nw += w1[r] * w1[r];
        }
        if (!(nd > 1e-32 * nw)) break; /* |dw| <= 1e-16 |w1| (or non-finite: caught by the caller) */
    }
}

/* One implicit_gyro step: loads at the start (explicit), w1 from gyro_newton, q <- q (x) exp(h w1 / 2)
   (unit by construction), then v += h F/m, p += h v (semi-implicit). */
static void gyro_step(const body_ctx *c, double *x, double h)
{
    const double *I = c->prm + 1;
    double F[3] = {0.0, 0.0, 0.0}, tb[3] = {0.0, 0.0, 0.0}, w1[3], e[4], nrm, a, sa;
    int i;
    if (c->has) plain_loads(c, x, F, tb);
    gyro_newton(I, x + 10, tb, h, w1);
    nrm = sqrt(w1[0] * w1[0] + w1[1] * w1[1] + w1[2] * w1[2]);
    a = 0.5 * h * nrm;
    sa = a > 1e-8 ? sin(a) / nrm : 0.5 * h * (1.0 - a * a / 6.0); /* sin(a)/|w1| */
    e[0] = sa * w1[0]; e[1] = sa * w1[1]; e[2] = sa * w1[2]; e[3] = cos(a);
    lv_quat_mul(x + 3, e, x + 3);
    for (i = 0; i < 3; i++) {
        x[10 + i] = w1[i];
        x[7 + i] += h * F[i] / c->m;
        x[i] += h * x[7 + i];
    }
}

/* Advance plain body b by n_steps of splitting or implicit_gyro; contract as advance_block with n = 1. */
static long advance_structured(double *state, const double *params, long b, const lv_effect_index *ix,
                               int integrator, int normalize, double dt, long n_steps, double *last)
{
    body_ctx c;
    double x[LV_STATE_SIZE], xn[LV_STATE_SIZE];
    int damped, i;
    long s;
    ctx_init(&c, params, b, NULL, ix);
    damped = (c.flags & (LV_EFFECT_USES_V | LV_EFFECT_USES_OMEGA)) != 0;
    memcpy(x, state + b * LV_STATE_SIZE, sizeof x);
    for (s = 0; s < n_steps; s++) {
        memcpy(xn, x, sizeof x);
        if (integrator == LV_INTEGRATOR_SPLITTING)
            splitting_step(&c, xn, dt, damped);
        else
            gyro_step(&c, xn, dt);
        if (normalize) lv_quat_normalize(xn + 3, xn + 3);
        for (i = 0; i < LV_STATE_SIZE; i++) {
            if (!isfinite(xn[i])) {
                memcpy(last, x, sizeof x);
                return s;
            }
        }
        memcpy(x, xn, sizeof x);
    }
    memcpy(state + b * LV_STATE_SIZE, x, sizeof x);
    return -1;
}

/* Divergence is reported at the earliest failing step over all bodies, then the lowest body index (as
   the NumPy backend, which steps every body in lockstep). Bodies are visited in groups, each advanced
   only as far as the failure kept so far (limit, best) can still be beaten: up to `limit` steps, one
   more when the group holds a body below `best` (it would win a tie at step `limit`). */
static int earlier(long s, long b, long limit, long best)
{
    return s < limit || (s == limit && b < best);
}

static long run_limit(long lowest, long limit, long best, long n_steps)
{
    return (best >= 0 && lowest < best && limit < n_steps) ? limit + 1 : limit;
}

/* RK4 on up to LV_BLOCK plain bodies of ids with effects, in lockstep, all of one right-hand side kind
   (LV_RHS_TORQUE or LV_RHS_FULL). Every call below has constant arguments and is inlined with its
   kernels and the effect dispatch (flatten), so each block size and kind compiles to its own loop. */
LV_FLATTEN static long advance_forced_rk4(double *state, const double *params, const long *ids, int n,
                                          const lv_effect_index *ix, int kind, int normalize, double dt, long n_steps,
                                          int *fail_j, double last[][LV_STATE_SIZE])
{
    if (kind == LV_RHS_TORQUE)
        return n == LV_BLOCK ? advance_free_rk4(state, params, ids, LV_BLOCK, ix, LV_RHS_TORQUE, normalize, dt, n_steps, fail_j, last)
                             : advance_free_rk4(state, params, ids, n, ix, LV_RHS_TORQUE, normalize, dt, n_steps, fail_j, last);
    return n == LV_BLOCK ? advance_free_rk4(state, params, ids, LV_BLOCK, ix, LV_RHS_FULL, normalize, dt, n_steps, fail_j, last)
                         : advance_free_rk4(state, params, ids, n, ix, LV_RHS_FULL, normalize, dt, n_steps, fail_j, last);
}

/* RK4 on up to LV_BLOCK plain bodies of ids in lockstep, all of one right-hand side kind (LV_RHS_*). The
   torque-free calls have constant block sizes and normalize flags, so the compiler specializes them. */
static long advance_rk4_group(double *state, const double *params, const long *ids, int n, const lv_effect_index *ix,
                              int kind, int normalize, double dt, long n_steps, int *fail_j,
                              double last[][LV_STATE_SIZE])
{
    if (kind != LV_RHS_FREE)
        return advance_forced_rk4(state, params, ids, n, ix, kind, normalize, dt, n_steps, fail_j, last);
    if (n == LV_BLOCK)
        return normalize ? advance_free_rk4(state, params, ids, LV_BLOCK, ix, LV_RHS_FREE, 1, dt, n_steps, fail_j, last)
                         : advance_free_rk4(state, params, ids, LV_BLOCK, ix, LV_RHS_FREE, 0, dt, n_steps, fail_j, last);
    if (n == 1)
        return normalize ? advance_free_rk4(state, params, ids, 1, ix, LV_RHS_FREE, 1, dt, n_steps, fail_j, last)
                         : advance_free_rk4(state, params, ids, 1, ix, LV_RHS_FREE, 0, dt, n_steps, fail_j, last);
    return advance_free_rk4(state, params, ids, n, ix, LV_RHS_FREE, normalize, dt, n_steps, fail_j, last);
}

/* Up to LV_BLOCK plain bodies of ids (ascending) in lockstep, all of one right-hand side kind (LV_RHS_*):
   RK4 on the fast path, the other integrators on the generic block (constant block sizes let the
   compiler specialize it). */
static long advance_group(double *state, const double *params, const long *ids, int n, const lv_effect_index *ix,
                          int kind, int integrator, int normalize, double dt, long n_steps, int *fail_j,
                          double last[][LV_STATE_SIZE])
{
    if (integrator == LV_INTEGRATOR_RK4)
        return advance_rk4_group(state, params, ids, n, ix, kind, normalize, dt, n_steps, fail_j, last);
    if (n == LV_BLOCK)
        return advance_block(state, params, ids, LV_BLOCK, ix, integrator, normalize, dt, n_steps, fail_j, last);
    if (n == 1)
        return advance_block(state, params, ids, 1, ix, integrator, normalize, dt, n_steps, fail_j, last);
    return advance_block(state, params, ids, n, ix, integrator, normalize, dt, n_steps, fail_j, last);
}

/* The right-hand side kind of plain body b (LV_RHS_*). */
static int rhs_kind(const lv_effect_index *ix, long b)
{
    if (ix->start[b + 1] == ix->start[b]) return LV_RHS_FREE;
    return (ix->flags[b] & LV_EFFECT_FORCE) ? LV_RHS_FULL : LV_RHS_TORQUE;
}

/* euler, semi-implicit Euler, rk4 over every body. Bodies with a joint or wheels are stepped one by one;
   plain bodies in lockstep blocks gathered by their work (rhs_kind): those no effect acts on together
   (RK4: the torque-free fast path), those with effects by kind, so a plain body never leaves its path
   because of a neighbour. ids: scratch for nb indices. Returns the status; *limit, *best as in
   lv_simulate. */
static int advance_fixed(double *state, const double *params, long nb, const lv_effect_index *ix,
                         const lv_models *models, int integrator, int normalize, double dt, long n_steps,
                         long *ids, long *limit, long *best)
{
    double last[LV_BLOCK][LV_STATE_SIZE], lastm[LV_XS];
    long b, k, s, lim, count[3] = {0, 0, 0}, first[3];
    int j, n, kind, status = LV_OK;
    for (b = 0; b < nb; b++) {
        if (models != NULL && (int)models->rows[b * LV_MODEL_SIZE] != 0) {
            lim = run_limit(b, *limit, *best, n_steps);
            if (lim <= 0) continue;
            s = advance_model(state, params, b, models, ix, integrator, normalize, dt, lim, lastm);
            if (s < 0 || !earlier(s, b, *limit, *best)) continue;
            memcpy(state + b * LV_STATE_SIZE, lastm, LV_STATE_SIZE * sizeof(double));
            memcpy(models->Omega + 3 * b, lastm + LV_STATE_SIZE, 3 * sizeof(double));
            *limit = s;
            *best = b;
            status = LV_DIVERGED;
        } else {
            count[rhs_kind(ix, b)]++;
        }
    }
    first[0] = 0; /* ids: the plain bodies grouped by kind, ascending within each */
    first[1] = count[0];
    first[2] = count[0] + count[1];
    for (b = 0; b < nb; b++)
        if (models == NULL || (int)models->rows[b * LV_MODEL_SIZE] == 0) ids[first[rhs_kind(ix, b)]++] = b;
    for (kind = 0; kind < 3; kind++) {
        const long *list = ids + first[kind] - count[kind];
        for (k = 0; k < count[kind]; k += n) {
            n = (int)(count[kind] - k < LV_BLOCK ? count[kind] - k : LV_BLOCK);
            lim = run_limit(list[k], *limit, *best, n_steps);
            if (lim <= 0) continue;
            s = advance_group(state, params, list + k, n, ix, kind, integrator, normalize, dt, lim, &j, last);
            /* the block stops at its first failing step, j its lowest failing body there (lockstep) */
            if (s < 0 || !earlier(s, list[k + j], *limit, *best)) continue;
            memcpy(state + list[k + j] * LV_STATE_SIZE, last[j], sizeof last[j]);
            *limit = s;
            *best = list[k + j];
            status = LV_DIVERGED;
        }
    }
    return status;
}

int lv_simulate(double *state, const double *params, long nb,
                const double *effects, long ne, long row_size, const lv_user_effects *user,
                const lv_models *models, int integrator, int normalize, double dt, long n_steps,
                const lv_adaptive *adaptive, long *fail_step, long *fail_body)
{
    lv_effect_index ix;
    double last[LV_BLOCK][LV_STATE_SIZE];
    long b, s, limit = n_steps, best_body = -1, *ids = NULL;
    int status = LV_OK;
    if (integrator < LV_INTEGRATOR_EULER || integrator > LV_INTEGRATOR_LAST) return LV_BAD_ARGUMENT;
    if (ne > 0 && row_size < LV_EFFECT_ROW_PARAMS) return LV_BAD_ARGUMENT;
    if (integrator == LV_INTEGRATOR_DOPRI5 && (adaptive == NULL || !(adaptive->rtol > 0.0) || !(adaptive->atol >= 0.0)))
        return LV_BAD_ARGUMENT;
    if ((integrator == LV_INTEGRATOR_SPLITTING || integrator == LV_INTEGRATOR_IMPLICIT_GYRO) && models != NULL)
        for (b = 0; b < nb; b++)
            if ((int)models->rows[b * LV_MODEL_SIZE] != 0) return LV_BAD_ARGUMENT;
    status = index_build(&ix, effects, ne, row_size, nb, user, fail_step);
    if (status != LV_OK) return status;
    if (integrator == LV_INTEGRATOR_DOPRI5) {
        for (b = 0; b < nb && limit > 0; b++) {
            double lastx[LV_XS];
            int why = LV_DIVERGED;
            s = advance_dopri5(state, params, b, models, &ix, normalize, dt, limit, adaptive, &why, lastx);
            if (s < 0) continue;
            memcpy(state + b * LV_STATE_SIZE, lastx, LV_STATE_SIZE * sizeof(double));
            if (models != NULL && (int)models->rows[b * LV_MODEL_SIZE] != 0)
                memcpy(models->Omega + 3 * b, lastx + LV_STATE_SIZE, 3 * sizeof(double));
            limit = s;
            best_body = b;
            status = why;
        }
    } else if (integrator == LV_INTEGRATOR_SPLITTING || integrator == LV_INTEGRATOR_IMPLICIT_GYRO) {
        for (b = 0; b < nb && limit > 0; b++) {
            s = advance_structured(state, params, b, &ix, integrator, normalize, dt, limit, last[0]);
            if (s < 0) continue;
            memcpy(state + b * LV_STATE_SIZE, last[0], sizeof last[0]);
            limit = s;
            best_body = b;
            status = LV_DIVERGED;
        }
    } else {
        ids = (long *)malloc(((size_t)nb + 1) * sizeof(long));
        status = ids == NULL ? LV_NO_MEMORY
                             : advance_fixed(state, params, nb, &ix, models, integrator, normalize, dt, n_steps, ids,
                                             &limit, &best_body);
        free(ids);
    }
    index_free(&ix);
    if (status != LV_OK && status != LV_NO_MEMORY) {
        *fail_step = limit;
        *fail_body = best_body;
    }
    return status;
}
