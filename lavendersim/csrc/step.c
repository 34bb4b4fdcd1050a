/* LavenderSim stepping loop (see step.h). Every equation comes from generated/kernels.c.

   The generated kernels are compiled as part of this translation unit (setup.py does not compile
   kernels.c separately), so the optimizer sees their bodies and inlines them into the step loops:
   an out-of-line call per right-hand side (and, under -fPIC, through the PLT) cost ~20% of a
   torque-free RK4 step. Inlining does not change the arithmetic (no -ffast-math, no contraction). */
#include <math.h>
#include <stdint.h>
#include <stdlib.h>
#include <string.h>

#include "kernels.c"
#include "step.h"
#include "tableaux.h"

/* LV_FLATTEN: inline every call in the function (its kernels included), so each call with constant block
   size, kind and normalize flag compiles to its own straight-line loop (GCC and clang; elsewhere a
   plain function). */
#if defined(__GNUC__) || defined(__clang__)
#define LV_FLATTEN __attribute__((flatten))
#else
#define LV_FLATTEN
#endif
#if defined(_MSC_VER)
#define LV_RESTRICT __restrict
#else
#define LV_RESTRICT restrict
#endif

/* Threads for the SIMD tiles of one call (POSIX threads; elsewhere one). */
#if !defined(_WIN32) && (defined(__unix__) || defined(__APPLE__))
#include <pthread.h>
#define LV_HAVE_THREADS 1
#else
#define LV_HAVE_THREADS 0
#endif

/* Steps between finiteness checks on the torque-free path (see advance_free_rk4). */
#define LV_FREE_CHUNK 64

/* ---- the effect index -------------------------------------------------------------------------

   One effect acting on one body: its parameters and, for a user effect, its compiled function
   (NULL: a built-in effect, dispatched by code through the generated lv_effect_apply). */
typedef struct {
    const double *p;
    lv_effect_fn user;
    lv_effect_fn user_b; /* a user effect's body-frame form (LV_EFFECT_TORQUE_B), else NULL */
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
    const lv_user_effects *user; /* the user effects' table (NULL: none) */
} lv_effect_index;

/* Number of parameters of effect `code` (built-in, or a user code with an entry in `user`), its flags
   and, for a user effect, its function and its body-frame form (fn_b may be NULL: not wanted); -1 if no declared
   effect has this code. */
static int effect_info(int code, const lv_user_effects *user, int *flags, lv_effect_fn *fn, lv_effect_fn *fn_b)
{
    const int n = lv_effect_n_params(code);
    *fn = NULL;
    if (fn_b != NULL) *fn_b = NULL;
    *flags = 0;
    if (n >= 0) {
        *flags = lv_effect_flags(code);
        return n;
    }
    if (user != NULL && code >= LV_EFFECT_USER_BASE && code - LV_EFFECT_USER_BASE < user->n) {
        const lv_user_effect *u = &user->entries[code - LV_EFFECT_USER_BASE];
        if (u->fn != NULL && u->n_params >= 0) {
            *fn = u->fn;
            if (fn_b != NULL) *fn_b = u->fn_b;
            *flags = u->flags;
            return u->n_params;
        }
    }
    return -1;
}

int lv_effect_row_check(const double *row, long row_size, long nb, const lv_user_effects *user, int *np)
{
    const double code = row[LV_EFFECT_ROW_CODE], body = row[LV_EFFECT_ROW_BODY];
    int flags;
    lv_effect_fn fn;
    *np = -1;
    /* whole numbers by a truncating conversion (in range first: the conversion is defined there), not floor(): a
       library call per row and call on the baseline build, twice per row */
    if (fabs(code) < 1e9 && code == (double)(long)code) *np = effect_info((int)code, user, &flags, &fn, NULL);
    if (*np < 0 || *np > row_size - LV_EFFECT_ROW_PARAMS) return LV_UNKNOWN_EFFECT;
    if (!(body == -1 || (body >= 0 && body < (double)nb && body == (double)(long)body))) return LV_BAD_ARGUMENT;
    return LV_OK;
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
    ix->user = user;
    if (ix->start == NULL || ix->flags == NULL) { index_free(ix); return LV_NO_MEMORY; }
    for (e = 0; e < ne; e++) {
        const double *row = effects + e * row_size;
        int np;
        const int status = lv_effect_row_check(row, row_size, nb, user, &np);
        const long target = (long)row[LV_EFFECT_ROW_BODY];
        if (status != LV_OK) { *bad_row = e; index_free(ix); return status; }
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
        (void)effect_info(ref.code, user, &flags, &fn, &ref.user_b);
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

/* effect_sums for refs that are all built-in effects (no user function): the generated dispatch only, so a
   flattened caller inlines every effect. */
static inline void builtin_effect_sums(const double *x, const double *v_w, double m, const double *I_b,
                                       const lv_effect_ref *refs, long n, double *F, double *tau)
{
    long k;
    for (k = 0; k < n; k++) (void)lv_effect_apply(refs[k].code, refs[k].p, x, v_w, m, I_b, F, tau);
}

/* effect_sums for a plain body whose torques are all declared in the body frame (LV_RHS_BODY*): the generated
   body dispatch, which adds those torques to tau in the body frame, and a user effect's body-frame form (user_b;
   a user effect without one adds no torque there). */
static inline void effect_sums_b(const double *x, const double *v_w, double m, const double *I_b,
                                 const lv_effect_ref *refs, long n, double *F, double *tau)
{
    long k;
    for (k = 0; k < n; k++) {
        if (refs[k].user_b != NULL)
            refs[k].user_b(refs[k].p, x, v_w, m, I_b, F, tau);
        else if (refs[k].user != NULL)
            refs[k].user(refs[k].p, x, v_w, m, I_b, F, tau);
        else
            (void)lv_effect_apply_b(refs[k].code, refs[k].p, x, v_w, m, I_b, F, tau);
    }
}

/* Right-hand side classes of plain bodies (rhs_class, from the OR of their effects' flags): LV_RHS_FREE none;
   LV_RHS_TORQUE world torques only; LV_RHS_FULL a force and world torques; LV_RHS_FORCE a force and no torque
   (rigid_body_rhs_force_c on a_w = F/m: nothing rotated); LV_RHS_BODY / LV_RHS_BODY_F torques all declared in
   the body frame (LV_EFFECT_TORQUE_B, the body dispatch), without / with a force (rigid_body_rhs_body_c; without
   a force a_w = 0, bitwise the +0/m the NumPy backend divides). Which class a body with effects has is derive's
   rule (derive/effect_fuse.py tile_kind), printed into kernels.h as a table over the flags (LV_RHS_KINDS_BY_FLAGS,
   LV_RHS_FLAGS_INDEX). LV_RHS_CONSTANT is added to LV_RHS_TORQUE, LV_RHS_FULL and LV_RHS_FORCE when every effect
   of the body reads no state (see rhs_kind). */
enum { LV_RHS_FREE = 0, LV_RHS_TORQUE = 1, LV_RHS_FULL = 2, LV_RHS_FORCE = 5, LV_RHS_BODY = 8, LV_RHS_BODY_F = 9 };
#define LV_RHS_CONSTANT 2
/* LV_RHS_SPLIT is added to the class of a plain body that steps decoupled (rhs_kind, effects_decoupled): a kind of
   kernels.h's LV_RHS_SPLIT_<kind> != 0 (FORCE, BODY, BODY_F), effects not all constant, all built-in, none coupling
   translation and rotation (LV_EFFECT_COUPLED clear: derive/effect.py affine_force). Its rotation is staged alone
   (lv_split_rk4_h), its translation takes the printed affine flow. */
#define LV_RHS_SPLIT 16
#define LV_RHS_CLASSES (LV_RHS_SPLIT + 10)
#define LV_RHS_SPLIT_OF(kind) [LV_RHS_##kind] = LV_RHS_SPLIT_##kind,
static const unsigned char LV_SPLIT_BY_CLASS[LV_RHS_SPLIT] = {LV_RHS_KINDS(LV_RHS_SPLIT_OF)};
#undef LV_RHS_SPLIT_OF
#define rhs_constant(cls) ((cls) == LV_RHS_TORQUE + LV_RHS_CONSTANT || (cls) == LV_RHS_FULL + LV_RHS_CONSTANT || \
                           (cls) == LV_RHS_FORCE + LV_RHS_CONSTANT)
#define LV_RHS_OF_KIND(kind) LV_RHS_##kind
static const unsigned char LV_RHS_BY_FLAGS[] = LV_RHS_KINDS_BY_FLAGS(LV_RHS_OF_KIND);
static inline int rhs_class(long n_refs, int flags)
{
    return n_refs == 0 ? LV_RHS_FREE : LV_RHS_BY_FLAGS[LV_RHS_FLAGS_INDEX(flags)];
}

/* One plain body with effects (refs) of class cls (rhs_class, no LV_RHS_CONSTANT): the effects' sums in table order
   (their body-frame forms where the class says so), then CALL<kind>(x, m, K, F, tau, out) of its class, both derive's
   rule (kernels.h's LV_RHS_BODY_FRAME_<kind>; LV_RHS_CALL_<kind> / LV_RHS_INC_<kind>), as the tiles take them; the
   general kind FULL for any other class (none has effects: rhs_class gives one of the kinds). LV_PLAIN_BY_CLASS
   writes the function NAME(cls, x, m, I_b, K, refs, n_refs, out) of one CALL, CASE its switch's case. */
#define LV_PLAIN_OF(KIND, CALL, K)                                                                      \
    if (LV_RHS_BODY_FRAME_##KIND)                                                                       \
        effect_sums_b(x, x + LV_STATE_V_W, m, I_b, refs, n_refs, F, tau);                               \
    else                                                                                                \
        effect_sums(x, x + LV_STATE_V_W, m, I_b, refs, n_refs, F, tau);                                 \
    CALL##KIND(x, m, K, F, tau, out);                                                                   \
    return;
#define LV_PLAIN_BY_CLASS(NAME, CASE, CALL, K)                                                          \
    static inline void NAME(int cls, const double *x, double m, const double *I_b, const double *K,     \
                            const lv_effect_ref *refs, long n_refs, double *out)                        \
    {                                                                                                   \
        double F[3] = LV_SUM_START3, tau[3] = LV_SUM_START3;                                            \
        switch (cls) {                                                                                  \
        LV_RHS_KINDS(CASE)                                                                              \
        default: break;                                                                                 \
        }                                                                                               \
        LV_PLAIN_OF(FULL, CALL, K)                                                                      \
    }
/* plain_rhs: d/dt x (out) on the body's Euler coefficients cf (LV_RHS_CALL_<kind>). */
#define LV_PLAIN_RHS_CASE(KIND) case LV_RHS_##KIND: { LV_PLAIN_OF(KIND, LV_RHS_CALL_, cf) }
LV_PLAIN_BY_CLASS(plain_rhs, LV_PLAIN_RHS_CASE, LV_RHS_CALL_, cf)
/* plain_inc: the scaled increments H = (s dt) d/dt x (out; the built-in RK4's scaled-increment form) on the body's
   constants sc (rigid_body_increment_scale; LV_RHS_INC_<kind>). */
#define LV_PLAIN_INC_CASE(KIND) case LV_RHS_##KIND: { LV_PLAIN_OF(KIND, LV_RHS_INC_, sc) }
LV_PLAIN_BY_CLASS(plain_inc, LV_PLAIN_INC_CASE, LV_RHS_INC_, sc)
#undef LV_PLAIN_INC_CASE
#undef LV_PLAIN_RHS_CASE
#undef LV_PLAIN_BY_CLASS
#undef LV_PLAIN_OF

/* d/dt of one plain body's state: the free kernel when no effect applies, else plain_rhs by its class. */
static void body_rhs(const double *x, const double *prm, const lv_effect_ref *refs, long n_refs, int flags,
                     double *xdot)
{
    const double *I_b = prm + LV_PARAM_I_B;
    double cf[LV_EULER_SIZE];
    if (n_refs == 0) {
        lv_rigid_body_rhs_free(x, I_b, xdot);
        return;
    }
    lv_euler_coefficients(I_b, cf);
    plain_rhs(rhs_class(n_refs, flags), x, prm[LV_PARAM_M], I_b, cf, refs, n_refs, xdot);
}

static int all_finite(const double *x)
{
    int i;
    for (i = 0; i < LV_STATE_SIZE; i++)
        if (!isfinite(x[i])) return 0;
    return 1;
}

/* Every number i of bodies j = 0 .. n-1 of a lockstep block (the FOR and AT of LV_RK4_STEP, tableaux.h). */
#define LV_BLOCK_FOR(stmt) for (j = 0; j < n; j++) for (i = 0; i < LV_STATE_SIZE; i++) stmt
#define LV_BLOCK_AT(v) v[j][i]

/* Bodies stepped in lockstep: one body's step is a chain of dependent divisions and square roots
   (latency-bound), so interleaving a few independent bodies lets the CPU overlap them. Each body's
   arithmetic is exactly the single-body sequence, so results do not depend on the blocking. */
#define LV_BLOCK 8

/* Advance bodies ids[0 .. n-1] (n <= LV_BLOCK, ascending) by n_steps of euler or semi-implicit Euler (RK4 takes
   advance_free_rk4). Their rows are read at the start
   and written only on success. Returns -1 on success, else the 0-based failing step; then *fail_j is the
   first (lowest-index) body of the block that went non-finite at that step and last[] holds the block's
   last finite states. */
static inline long advance_block(double *state, const double *params, const long *ids, int n,
                          const lv_effect_index *ix, int integrator, int normalize,
                          double dt, long n_steps, int *fail_j, double last[][LV_STATE_SIZE])
{
    double x[LV_BLOCK][LV_STATE_SIZE], xn[LV_BLOCK][LV_STATE_SIZE], k1[LV_BLOCK][LV_STATE_SIZE],
        tmp[LV_BLOCK][LV_STATE_SIZE];
    const double *prm[LV_BLOCK];
    const lv_effect_ref *refs[LV_BLOCK];
    long n_refs[LV_BLOCK];
    int flags[LV_BLOCK];
    long s;
    int i, j;
    for (j = 0; j < n; j++) {
        const long b = ids[j];
        prm[j] = params + b * LV_PARAM_SIZE;
        refs[j] = ix->refs + ix->start[b];
        n_refs[j] = ix->start[b + 1] - ix->start[b];
        flags[j] = ix->flags[b];
        memcpy(x[j], state + b * LV_STATE_SIZE, sizeof x[j]);
    }
#define RHS(in, out) for (j = 0; j < n; j++) body_rhs(in[j], prm[j], refs[j], n_refs[j], flags[j], out[j])
    for (s = 0; s < n_steps; s++) {
        if (integrator == LV_PATH_EULER) {
            LV_EULER_STEP(double, RHS, LV_BLOCK_FOR, LV_BLOCK_AT, dt, x, xn, k1, k1, tmp);
        } else { /* LV_PATH_SEMI_IMPLICIT */
            RHS(x, k1);
            for (j = 0; j < n; j++) {
                for (i = 0; i < 3; i++) {                                         /* v', omega' */
                    xn[j][LV_STATE_V_W + i] = x[j][LV_STATE_V_W + i] + dt * k1[j][LV_STATE_V_W + i];
                    xn[j][LV_STATE_OMEGA_B + i] = x[j][LV_STATE_OMEGA_B + i] + dt * k1[j][LV_STATE_OMEGA_B + i];
                }
                lv_translation_drift(x[j] + LV_STATE_P_W, xn[j] + LV_STATE_V_W, dt, xn[j] + LV_STATE_P_W); /* p + dt v' */
                lv_quat_derivative_body(x[j] + LV_STATE_Q, xn[j] + LV_STATE_OMEGA_B, tmp[j]);          /* q rate at omega' */
                for (i = 0; i < 4; i++) xn[j][LV_STATE_Q + i] = x[j][LV_STATE_Q + i] + dt * tmp[j][i];
            }
        }
        if (normalize)
            for (j = 0; j < n; j++) lv_quat_normalize(xn[j] + LV_STATE_Q, xn[j] + LV_STATE_Q);
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

/* One torque-free RK4 step of one body, x -> xn (13 numbers each, not overlapping), in the scaled-increment form
   (tableaux.h LV_RK4_SCALED_STEP, derive/tableaux.py scaled_program): only q and omega_b go through the stages, as
   increments H_i = LV_RK4_SCALE dt k_i that the printed rigid_body_increments_free_c computes at k_i's own cost (the
   scale is in its constants C and hq, the printed rigid_body_increment_scale_free per body and call,
   lv_free_rk4_scale), so a stage's input and the step's end are adds and one multiply (~17% fewer multiplies than
   LV_RK4_STEP on 13 numbers); q normalized with the generated kernel when asked; p_w moves by the printed
   translation_drift with v_w (v_w' = 0 and the weights sum to 1: RK4 is one Euler step there), v_w is kept.
   Every torque-free RK4 body of the default paths takes it (the scalar blocks, the SIMD tiles per lane); the
   NumPy backend does the same operations (numpy_backend._free_rk4_h), so C = NumPy bitwise. */
#define LV_H_ROWS (LV_STATE_Q_LEN + LV_STATE_OMEGA_B_LEN) /* y = (q, omega_b) */
#define LV_H_FOR(stmt) for (i_h_ = 0; i_h_ < LV_H_ROWS; i_h_++) stmt
#define LV_H_AT(v) v[i_h_]
/* y = (q, omega_b) of x after one step of the scaled-increment stages with the increments RHS(in, out) (on y's rows),
   q normalized when asked: the one staging of every body that steps its rotation alone (lv_rot_free_h,
   lv_rot_torque_h, the decoupled LV_SPLIT_RK4_H); lv_h_store writes y back. */
#define LV_H_STAGES(x, y, RHS, normalize)                                                              \
    do {                                                                                                \
        double H_h_[LV_H_ROWS], acc_h_[LV_H_ROWS], tmp_h_[LV_H_ROWS];                                   \
        int i_h_;                                                                                       \
        for (i_h_ = 0; i_h_ < LV_STATE_Q_LEN; i_h_++) (y)[i_h_] = (x)[LV_STATE_Q + i_h_];               \
        for (i_h_ = 0; i_h_ < LV_STATE_OMEGA_B_LEN; i_h_++)                                             \
            (y)[LV_STATE_Q_LEN + i_h_] = (x)[LV_STATE_OMEGA_B + i_h_];                                  \
        LV_RK4_SCALED_STEP(double, RHS, LV_H_FOR, LV_H_AT, y, y, H_h_, acc_h_, tmp_h_);                 \
        if (normalize) lv_quat_normalize(y, y);                                                         \
    } while (0)
/* (q, omega_b) of a torque-free body (rigid_body_increments_free_c on C, hq) into y. */
static inline void lv_rot_free_h(const double *x, double *y, const double *C, double hq, int normalize)
{
#define LV_H_RHS(in, out) lv_rigid_body_increments_free_c(in, in + LV_STATE_Q_LEN, C, hq, out, out + LV_STATE_Q_LEN)
    LV_H_STAGES(x, y, LV_H_RHS, normalize);
#undef LV_H_RHS
}
/* (q, omega_b) of a body under a constant world torque (rigid_body_increments_torque_h on S and the torque's
   constants T_w of rigid_body_torque_constants) into y. */
static inline void lv_rot_torque_h(const double *x, double *y, const double *S, const double *T_w, int normalize)
{
#define LV_H_RHS(in, out) lv_rigid_body_increments_torque_h(in, in + LV_STATE_Q_LEN, S, T_w, out, out + LV_STATE_Q_LEN)
    LV_H_STAGES(x, y, LV_H_RHS, normalize);
#undef LV_H_RHS
}
/* xn's q and omega_b from y. */
static inline void lv_h_store(const double *y, double *xn)
{
    int i;
    for (i = 0; i < LV_STATE_Q_LEN; i++) xn[LV_STATE_Q + i] = y[i];
    for (i = 0; i < LV_STATE_OMEGA_B_LEN; i++) xn[LV_STATE_OMEGA_B + i] = y[LV_STATE_Q_LEN + i];
}

/* One decoupled RK4 step of one body (class + LV_RHS_SPLIT), x -> xn: the rotation (q, omega_b) alone through the
   scaled-increment stages (LV_H_STAGES, as lv_free_rk4_h), RHS its increments: LV_SPLIT_H_RHS_1 torque-free
   (LV_RHS_SPLIT_<kind> 1), LV_SPLIT_H_ROT_B(in, out, SUMS) (2) the body-frame torque sums SUMS(xs, F, tau) at each
   stage input (xs: the body's 13 numbers with q and
   omega_b replaced; the torques read neither p_w nor v_w) and rigid_body_increments_rot_b_c, on the body's constants
   sc (rigid_body_increment_scale); then p_w, v_w by the printed translation_flow on the constants tf
   (translation_flow_scale, lv_split_flow_scale). The tiles (batch_simd.h LV_TILE_RK4_SPLIT) do the same per lane. */
#define LV_SPLIT_RK4_H(RHS, x, xn, sc, tf, normalize)                                                  \
    do {                                                                                                \
        double xs_[LV_STATE_SIZE], y_[LV_H_ROWS];                                                       \
        int i_;                                                                                         \
        for (i_ = 0; i_ < LV_STATE_SIZE; i_++) xs_[i_] = (x)[i_];                                        \
        (void)xs_; /* (read by the torque sums of LV_SPLIT_H_ROT_B only) */                             \
        LV_H_STAGES(x, y_, RHS, normalize);                                                             \
        lv_translation_flow((x) + LV_STATE_P_W, (x) + LV_STATE_V_W, tf, (xn) + LV_STATE_P_W, (xn) + LV_STATE_V_W); \
        lv_h_store(y_, xn);                                                                             \
    } while (0)
#define LV_SPLIT_H_RHS_1(in, out) lv_rigid_body_increments_free_c(in, in + LV_STATE_Q_LEN, sc + LV_INC_SCALE_C,  \
    sc[LV_INC_SCALE_HQ], out, out + LV_STATE_Q_LEN)
#define LV_SPLIT_H_ROT_B(in, out, SUMS)                                                                    \
    do {                                                                                                \
        double F_[3] = LV_SUM_START3, t_[3] = LV_SUM_START3;                                            \
        for (i_ = 0; i_ < LV_STATE_Q_LEN; i_++) xs_[LV_STATE_Q + i_] = in[i_];                           \
        for (i_ = 0; i_ < LV_STATE_OMEGA_B_LEN; i_++) xs_[LV_STATE_OMEGA_B + i_] = in[LV_STATE_Q_LEN + i_]; \
        SUMS(xs_, F_, t_);                                                                              \
        lv_rigid_body_increments_rot_b_c(in, in + LV_STATE_Q_LEN, sc, t_, out, out + LV_STATE_Q_LEN);   \
    } while (0)

/* The translation flow's constants tf (translation_flow_scale) of a body with the effects refs (all built-in,
   decoupled): their affine forces' F0 and k (lv_effect_affine) summed in table order from LV_SUM_START. */
static inline void lv_split_flow_scale(const lv_effect_ref *refs, long n, double m, double dt, double *tf)
{
    double F0[3] = LV_SUM_START3, k = LV_SUM_START;
    long j;
    for (j = 0; j < n; j++) (void)lv_effect_affine(refs[j].code, refs[j].p, m, F0, &k);
    lv_translation_flow_scale(k, F0, m, dt, tf);
}

static inline void lv_free_rk4_h(const double *x, double *xn, const double *C, double hq, double dt, int normalize)
{
    double y[LV_H_ROWS];
    int i;
    lv_rot_free_h(x, y, C, hq, normalize);
    lv_translation_drift(x + LV_STATE_P_W, x + LV_STATE_V_W, dt, xn + LV_STATE_P_W);
    lv_h_store(y, xn);
    for (i = 0; i < LV_STATE_V_W_LEN; i++) xn[LV_STATE_V_W + i] = x[LV_STATE_V_W + i];
}

/* lv_free_rk4_h's constants of a call (the printed rigid_body_increment_scale_free): C = (LV_RK4_SCALE dt) k_b from a
   body's Euler coefficients c_b, and hq. */
static inline double lv_free_rk4_scale(const double *c_b, double dt, double *C)
{
    double hq;
    lv_rigid_body_increment_scale_free(c_b, LV_RK4_SCALE * dt, C, &hq);
    return hq;
}

/* One RK4 step of a body whose effects all read no state (a constant kind, kernels.h LV_CONST_*: TORQUE, FULL,
   FORCE), x -> xn, in lv_free_rk4_h's form: only q and omega_b go through the stages, with the constant world torque
   (torque: rigid_body_increments_torque_h) or as a torque-free body (the same lv_rot_free_h, on S's C and hq:
   bitwise the torque-free constants); p_w and v_w by the constant force's exact flow (force: the printed
   translation_flow_constant, RK4 being exact on p' = v, v' = F/m) or translation_drift with v_w kept. K: the body's
   LV_CONST_SIZE constants of the call (lv_const_scale). The SIMD tiles take it per lane (LV_TILE_RK4_C), the NumPy
   backend does the same operations (numpy_backend._const_rk4_h), so C = NumPy bitwise. */
static inline void lv_const_rk4_h(const double *x, double *xn, const double *K, double dt, int torque, int force,
                                  int normalize)
{
    double y[LV_H_ROWS];
    int i;
    if (torque)
        lv_rot_torque_h(x, y, K, K + LV_CONST_TAU, normalize);
    else
        lv_rot_free_h(x, y, K + LV_INC_SCALE_C, K[LV_INC_SCALE_HQ], normalize);
    if (force) {
        lv_translation_flow_constant(x + LV_STATE_P_W, x + LV_STATE_V_W, dt, K + LV_CONST_DV, K + LV_CONST_DP,
                                     xn + LV_STATE_P_W, xn + LV_STATE_V_W);
    } else {
        lv_translation_drift(x + LV_STATE_P_W, x + LV_STATE_V_W, dt, xn + LV_STATE_P_W);
        for (i = 0; i < LV_STATE_V_W_LEN; i++) xn[LV_STATE_V_W + i] = x[LV_STATE_V_W + i];
    }
    lv_h_store(y, xn);
}

/* lv_const_rk4_h's constants K of a call for a body with Euler coefficients c_b, mass m and its constant effect sums
   F (force) and tau (world torque): the printed rigid_body_increment_scale, rigid_body_torque_constants (tau, 2 tau:
   the stages' rotation takes the doubled torque), and with force the printed constant_acceleration_steps (else
   zero). */
static inline void lv_const_scale(const double *c_b, double m, const double *F, const double *tau, double dt,
                                  int force, double *K)
{
    int i;
    lv_rigid_body_increment_scale(c_b, m, LV_RK4_SCALE * dt, K);
    lv_rigid_body_torque_constants(tau, K + LV_CONST_TAU);
    for (i = 0; i < 3; i++) K[LV_CONST_DV + i] = K[LV_CONST_DP + i] = 0.0;
    if (force) lv_constant_acceleration_steps(m, F, dt, K + LV_CONST_DV, K + LV_CONST_DP);
}
/* A constant kind's flags (LV_CONST_TORQUE_<kind>, LV_CONST_FORCE_<kind>) of class cls (LV_RHS_TORQUE, _FULL, _FORCE). */
#define LV_CONST_OF(FLAG, cls) ((cls) == LV_RHS_TORQUE ? LV_CONST_##FLAG##_TORQUE                      \
                                : (cls) == LV_RHS_FULL ? LV_CONST_##FLAG##_FULL : LV_CONST_##FLAG##_FORCE)

/* Increments on the lockstep RK4 path (`forced`, rhs_class, effects reading the state: a constant kind takes
   lv_const_rk4_h), the built-in RK4's scaled-increment form (tableaux.h LV_RK4_SCALED_STEP on the 13 numbers;
   LV_RHS_FREE takes lv_free_rk4_h instead): each body's effects summed in table order (plain_inc), the torque-only
   kernel for LV_RHS_TORQUE. Each on the body's constants S[j] (rigid_body_increment_scale, once per call: s dt folded
   into the Euler coefficients, 1/I, q's rate scale and 1/m). */
#define LV_RK4_INC(in, out)                                                                             \
    do {                                                                                                \
        if (forced == LV_RHS_TORQUE) {                                                                  \
            for (j = 0; j < n; j++) {                                                                   \
                F[j][0] = F[j][1] = F[j][2] = tau[j][0] = tau[j][1] = tau[j][2] = LV_SUM_START;         \
                effect_sums(in[j], in[j] + LV_STATE_V_W, m[j], I[j], refs[j], n_refs[j], F[j], tau[j]);  \
            }                                                                                           \
            for (j = 0; j < n; j++) LV_RHS_INC_TORQUE(in[j], m[j], S[j], F[j], tau[j], out[j]);\
        } else {                                                                                        \
            for (j = 0; j < n; j++) plain_inc(forced, in[j], m[j], I[j], S[j], refs[j], n_refs[j], out[j]); \
        }                                                                                               \
    } while (0)

/* One RK4 step of bodies 0 .. n-1: x -> xn (torque-free: lv_free_rk4_h; else LV_RK4_INC through
   LV_RK4_SCALED_STEP), q normalized with the generated kernel when asked. */
#define LV_FREE_RK4_STEP()                                                                              \
    do {                                                                                                \
        if (forced == LV_RHS_FREE) { /* torque-free: the scaled-increment form (lv_free_rk4_h) */       \
            for (j = 0; j < n; j++) lv_free_rk4_h(x[j], xn[j], Ch[j], hq, dt, normalize);               \
            break;                                                                                      \
        }                                                                                               \
        if (forced & LV_RHS_SPLIT) { /* decoupled: the rotation staged alone, the translation's flow */  \
            for (j = 0; j < n; j++) {                                                                   \
                const double *sc = S[j];                                                                \
                if (LV_SPLIT_BY_CLASS[forced - LV_RHS_SPLIT] == 1)                                      \
                    LV_SPLIT_RK4_H(LV_SPLIT_H_RHS_1, x[j], xn[j], sc, TF[j], normalize);                \
                else                                                                                    \
                    LV_SPLIT_RK4_H(LV_SPLIT_H_RHS_J, x[j], xn[j], sc, TF[j], normalize);                \
            }                                                                                           \
            break;                                                                                      \
        }                                                                                               \
        if (constant) { /* effects reading no state: (q, omega_b) staged alone (lv_const_rk4_h) */     \
            for (j = 0; j < n; j++)                                                                     \
                lv_const_rk4_h(x[j], xn[j], Kc[j], dt, LV_CONST_OF(TORQUE, forced), LV_CONST_OF(FORCE, forced), \
                               normalize);                                                              \
            break;                                                                                      \
        }                                                                                               \
        LV_RK4_SCALED_STEP(double, LV_RK4_INC, LV_BLOCK_FOR, LV_BLOCK_AT, x, xn, k, acc, tmp);          \
        if (normalize)                                                                                  \
            for (j = 0; j < n; j++) lv_quat_normalize(xn[j] + LV_STATE_Q, xn[j] + LV_STATE_Q);          \
    } while (0)


/* A decoupled body's torque sums at a stage (LV_SPLIT_RK4_H's SUMS): its effects' body-frame forms (BODY kinds). */
#define LV_SPLIT_SUMS_J(xs, F, t) effect_sums_b(xs, (xs) + LV_STATE_V_W, m[j], I[j], refs[j], n_refs[j], F, t)
#define LV_SPLIT_H_RHS_J(in, out) LV_SPLIT_H_ROT_B(in, out, LV_SPLIT_SUMS_J)

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
                                    const lv_effect_index *ix, int forced, int constant, int normalize,
                                    double dt, long n_steps, int *fail_j, double last[][LV_STATE_SIZE])
{
    double x[LV_BLOCK][LV_STATE_SIZE], xn[LV_BLOCK][LV_STATE_SIZE], k[LV_BLOCK][LV_STATE_SIZE],
        acc[LV_BLOCK][LV_STATE_SIZE], tmp[LV_BLOCK][LV_STATE_SIZE], I[LV_BLOCK][3], cf[LV_BLOCK][LV_EULER_SIZE],
        snap[LV_BLOCK][LV_STATE_SIZE];
    double F[LV_BLOCK][3], tau[LV_BLOCK][3], m[LV_BLOCK], Ch[LV_BLOCK][LV_EULER_K_LEN], hq = 0.0,
        S[LV_BLOCK][LV_INC_SCALE_SIZE], TF[LV_BLOCK][LV_FLOW_SIZE], Kc[LV_BLOCK][LV_CONST_SIZE];
    const lv_effect_ref *refs[LV_BLOCK];
    long n_refs[LV_BLOCK];
    long s, c, cm;
    int i, j, ok;
    for (j = 0; j < n; j++) {
        memcpy(x[j], state + ids[j] * LV_STATE_SIZE, sizeof x[j]);
        memcpy(I[j], params + ids[j] * LV_PARAM_SIZE + LV_PARAM_I_B, sizeof I[j]);
        lv_euler_coefficients(I[j], cf[j]);
        if (forced == LV_RHS_FREE) hq = lv_free_rk4_scale(cf[j], dt, Ch[j]);
        m[j] = params[ids[j] * LV_PARAM_SIZE + LV_PARAM_M];
        refs[j] = ix->refs + ix->start[ids[j]];
        n_refs[j] = ix->start[ids[j] + 1] - ix->start[ids[j]];
        F[j][0] = F[j][1] = F[j][2] = tau[j][0] = tau[j][1] = tau[j][2] = LV_SUM_START;
        if (constant && forced != LV_RHS_FREE) {
            effect_sums(x[j], x[j] + LV_STATE_V_W, m[j], I[j], refs[j], n_refs[j], F[j], tau[j]);
            lv_const_scale(cf[j], m[j], F[j], tau[j], dt, LV_CONST_OF(FORCE, forced), Kc[j]);
        } else if (forced != LV_RHS_FREE) {
            lv_rigid_body_increment_scale(cf[j], m[j], LV_RK4_SCALE * dt, S[j]);
        }
        if (forced & LV_RHS_SPLIT) lv_split_flow_scale(refs[j], n_refs[j], m[j], dt, TF[j]);
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
#undef LV_BLOCK_FOR
#undef LV_BLOCK_AT
#undef LV_RK4_INC

#include "batch_simd.h"

/* ---- instruction set selection ---------------------------------------------------------------- */

static int lv_isa_detect(void)
{
#if LV_HAVE_ISA_CLONES
    __builtin_cpu_init();
    if (__builtin_cpu_supports("avx512f")) return LV_ISA_AVX512;
    if (__builtin_cpu_supports("avx2")) return LV_ISA_AVX2;
#endif
    return LV_ISA_BASE;
}

static int lv_isa_best_cached = -1; /* benign race: every thread computes the same value */
static int lv_isa_current = -1;     /* -1: the best */

int lv_isa_best(void)
{
    if (lv_isa_best_cached < 0) lv_isa_best_cached = lv_isa_detect();
    return lv_isa_best_cached;
}

int lv_isa_get(void)
{
    return lv_isa_current < 0 ? lv_isa_best() : lv_isa_current;
}

int lv_isa_set(int isa)
{
    lv_isa_current = isa < 0 ? -1 : (isa < lv_isa_best() ? isa : lv_isa_best());
    return lv_isa_get();
}

const char *lv_isa_name(int isa)
{
    switch (isa) {
    case LV_ISA_SCALAR: return "scalar";
#if defined(__x86_64__) || defined(_M_X64)
    case LV_ISA_BASE: return "sse2";
#else
    case LV_ISA_BASE: return "baseline";
#endif
    case LV_ISA_AVX2: return "avx2";
    case LV_ISA_AVX512: return "avx512f";
    default: return "unknown";
    }
}

/* ---- bodies with a spherical joint and/or reaction wheels ------------------------------------ */

/* Loops over a body's [x, Omega] (LV_XS_SIZE numbers, past GCC's 16-iteration complete peeling) unrolled. */
#if defined(__GNUC__) && !defined(__clang__)
#define LV_XS_UNROLL _Pragma("GCC unroll 32")
#else
#define LV_XS_UNROLL
#endif


/* The inertia-only coefficients kw (LV_WCOEF_SIZE) of a wheeled body's model row r: once per body and call. */
static inline void lv_wheels_coefficients(const double *r, double *kw)
{
    LV_WHEELS_COEFFICIENTS(r + LV_MODEL_I_P, r + LV_MODEL_A_B, r + LV_MODEL_J, kw);
}

/* A bit the step loops add to a wheeled body's kind (beside the row's LV_KIND_* bits): its row is the default
   layout, A_b = [I | 0] as derive prints it (LV_WHEELS_ON_AXES_A_B), so its stages take the one wheel model's
   on-axes print (LV_WHEELS_ON_AXES_RHS_C: the same equations with A_b substituted). */
#define LV_ON_AXES 0x100

/* The kind a step loop steps body row r with: its row's kind, plus LV_ON_AXES for wheels on the default layout. */
static int lv_step_kind(const double *r)
{
    static const double axes[LV_MODEL_A_B_LEN] = LV_WHEELS_ON_AXES_A_B;
    const int kind = (int)r[LV_MODEL_KIND];
    int i;
    if (!(kind & LV_KIND_WHEELS)) return kind;
    for (i = 0; i < LV_MODEL_A_B_LEN; i++)
        if (r[LV_MODEL_A_B + i] != axes[i]) return kind;
    return kind | LV_ON_AXES;
}

lv_model_cache *lv_model_cache_new(long nb, int marked)
{
    lv_model_cache *c = (lv_model_cache *)calloc(1, sizeof(lv_model_cache));
    if (c == NULL) return NULL;
    c->nb = nb;
    c->marked = marked != 0;
    c->rows = marked ? NULL : (double *)calloc((size_t)nb * LV_MODEL_SIZE + 1, sizeof(double));
    c->kind = (int *)calloc((size_t)nb + 1, sizeof(int));
    c->kw = (double *)calloc((size_t)nb * LV_WCOEF_SIZE + 1, sizeof(double));
    c->bound = (double *)calloc((size_t)nb * LV_WHEELS_BOUND_SIZE + 1, sizeof(double));
    if ((c->rows == NULL && !marked) || c->kind == NULL || c->kw == NULL || c->bound == NULL) {
        lv_model_cache_free(c);
        return NULL;
    }
    return c;
}

/* The effect index of a call, kept in a lv_model_cache with what it was built from (lv_model_cache, step.h). */
struct lv_index_keep {
    lv_effect_index ix;
    const double *effects;
    long ne, row_size, nb, user_n;
    const lv_user_effects *user;
    double *keys;   /* ne x 2: each row's code and body when the index was built */
    lv_user_effect *user_copy;   /* user_n: the user table's entries when it was built (the refs hold their fns) */
    long *ids;      /* NULL, or advance_fixed's order of the bodies from this index and the model rows as they are
                       (ids_build; dropped when model_cache_sync makes the rows' entries again) */
    long count[LV_RHS_CLASSES], n_models;   /* with ids: ids_build's counts */
};

static void index_keep_free(lv_index_keep *k)
{
    if (k == NULL) return;
    index_free(&k->ix);
    free(k->keys);
    free(k->user_copy);
    free(k->ids);
    free(k);
}

void lv_model_cache_free(lv_model_cache *c)
{
    if (c == NULL) return;
    free(c->rows);
    free(c->kind);
    free(c->kw);
    free(c->bound);
    index_keep_free(c->index);
    free(c);
}

void lv_model_cache_rows_written(lv_model_cache *c)
{
    if (c != NULL) c->valid = 0;
}

/* 1 when index k was built from this table: same address, size, bodies and user table (at the same address, with the
   same entries: a caller may rebuild it per call, module.c simulate), and every row's code and body
   equal to those it was built from (then index_build would build and check the same index: it reads nothing else of
   a row; a NaN compares unequal, so it is built and refused again). */
static int index_kept(const lv_index_keep *k, const double *effects, long ne, long row_size, long nb,
                      const lv_user_effects *user)
{
    long e;
    if (k == NULL || k->effects != effects || k->ne != ne || k->row_size != row_size || k->nb != nb || k->user != user
        || (user != NULL && (k->user_n != user->n || k->user_copy == NULL
                             || memcmp(k->user_copy, user->entries, (size_t)user->n * sizeof *user->entries) != 0)))
        return 0;
    for (e = 0; e < ne; e++) {
        const double *row = effects + e * row_size;
        if (row[LV_EFFECT_ROW_CODE] != k->keys[2 * e] || row[LV_EFFECT_ROW_BODY] != k->keys[2 * e + 1]) return 0;
    }
    return 1;
}

/* index_build, or the index c keeps when it was built from this table (index_kept); a freshly built index replaces
   the kept one (when memory allows). *owned: 1 when the caller frees *ix (index_free), 0 when c keeps it. */
static int index_for_call(lv_effect_index *ix, int *owned, lv_model_cache *c, const double *effects, long ne,
                          long row_size, long nb, const lv_user_effects *user, long *bad_row)
{
    lv_index_keep *k;
    long e;
    int status;
    *owned = 1;
    if (c != NULL && index_kept(c->index, effects, ne, row_size, nb, user)) {
        *ix = c->index->ix;
        *owned = 0;
        return LV_OK;
    }
    status = index_build(ix, effects, ne, row_size, nb, user, bad_row);
    if (status != LV_OK || c == NULL) return status;
    index_keep_free(c->index);
    c->index = NULL;
    k = (lv_index_keep *)calloc(1, sizeof(lv_index_keep));
    if (k == NULL) return LV_OK;
    k->keys = (double *)malloc(((size_t)ne * 2 + 1) * sizeof(double));
    if (k->keys == NULL) { free(k); return LV_OK; }
    for (e = 0; e < ne; e++) {
        k->keys[2 * e] = effects[e * row_size + LV_EFFECT_ROW_CODE];
        k->keys[2 * e + 1] = effects[e * row_size + LV_EFFECT_ROW_BODY];
    }
    if (user != NULL && user->n > 0) {   /* (else not kept: index_kept refuses a user table without its copy) */
        k->user_copy = (lv_user_effect *)malloc((size_t)user->n * sizeof *user->entries);
        if (k->user_copy != NULL) memcpy(k->user_copy, user->entries, (size_t)user->n * sizeof *user->entries);
    }
    k->ix = *ix;
    k->effects = effects, k->ne = ne, k->row_size = row_size, k->nb = nb, k->user = user;
    k->user_n = user != NULL ? user->n : 0;
    c->index = k;
    *owned = 0;
    return LV_OK;
}

/* md's cache (if any) made valid for its nb rows: kept when the rows are those it was made from (compared bytewise,
   or for a marked cache not reported written since), else made again from the rows. Called by lv_simulate after it
   checked the rows' kinds, before any stepping thread starts. */
static void model_cache_sync(const lv_models *md, long nb)
{
    lv_model_cache *c = md == NULL ? NULL : md->cache;
    const size_t n = (size_t)nb * LV_MODEL_SIZE * sizeof(double);
    long b;
    if (c == NULL) return;
    if (c->valid && c->nb == nb && (c->marked || memcmp(c->rows, md->rows, n) == 0)) return;
    if (c->index != NULL) {   /* the kept order of the bodies read the rows' kinds: made again */
        free(c->index->ids);
        c->index->ids = NULL;
    }
    if (c->nb != nb) {
        c->valid = 0;
        return;
    }
    for (b = 0; b < nb; b++) {
        const double *r = md->rows + b * LV_MODEL_SIZE;
        c->kind[b] = lv_step_kind(r);
        if (c->kind[b] & LV_KIND_WHEELS) {
            lv_wheels_coefficients(r, c->kw + b * LV_WCOEF_SIZE);
            LV_WHEELS_MOMENTUM_BOUND_FACTORS(r + LV_MODEL_I_P, r + LV_MODEL_A_B, r + LV_MODEL_J,
                                             c->bound + b * LV_WHEELS_BOUND_SIZE);
        }
    }
    if (!c->marked) memcpy(c->rows, md->rows, n);
    c->valid = 1;
}

/* lv_step_kind of body b's row, from md's cache when it holds one (model_cache_sync). */
static inline int model_step_kind(const lv_models *md, long b)
{
    const lv_model_cache *c = md->cache;
    return c != NULL && c->valid ? c->kind[b] : lv_step_kind(md->rows + b * LV_MODEL_SIZE);
}

/* lv_wheels_coefficients of body b's row into kw, from md's cache when it holds them (model_cache_sync). */
static inline void model_coefficients(const lv_models *md, long b, double *kw)
{
    const lv_model_cache *c = md->cache;
    if (c != NULL && c->valid) memcpy(kw, c->kw + b * LV_WCOEF_SIZE, LV_WCOEF_SIZE * sizeof(double));
    else lv_wheels_coefficients(md->rows + b * LV_MODEL_SIZE, kw);
}

/* The rotational part of d/dt [x, Omega] (q, omega_b, Omega) of a body with wheels, F and tau its effect
   sums (world), u its applied motor torques, kw its coefficients (lv_wheels_coefficients): the one wheel model
   on the row's axes (padded slots stay at rest), its on-axes print when on_axes (equal up to the sign of a zero). */
static inline void lv_wheels_rhs(int on_axes, const double *y, const double *r, const double *kw, const double *F,
                                 const double *tau, const double *u, double *yd)
{
    if (on_axes)
        LV_WHEELS_ON_AXES_RHS_C(y + LV_STATE_Q, y + LV_STATE_OMEGA_B, y + LV_XS_OMEGA, r + LV_MODEL_I_P, r + LV_MODEL_J,
                                kw, r + LV_MODEL_R_B, F, tau, u, r[LV_MODEL_C_W], yd + LV_STATE_Q,
                                yd + LV_STATE_OMEGA_B, yd + LV_XS_OMEGA);
    else
        LV_WHEELS_BODY_RHS_C(y + LV_STATE_Q, y + LV_STATE_OMEGA_B, y + LV_XS_OMEGA, r + LV_MODEL_I_P, r + LV_MODEL_A_B,
                             r + LV_MODEL_J, kw, r + LV_MODEL_R_B, F, tau, u, r[LV_MODEL_C_W], yd + LV_STATE_Q,
                             yd + LV_STATE_OMEGA_B, yd + LV_XS_OMEGA);
}

/* lv_wheels_rhs as a call, for the one-body-at-a-time loops (advance_model, dopri5): flattened into advance_model's
   RK4 loop the kernel costs more (one jointed wheel cube under the bench's five effects, both builds in one
   process, min of 12: 415 ns per step inlined, 365 called; the model tiles, vectorized over lanes, inline it). */
#if defined(__GNUC__) || defined(__clang__)
__attribute__((noinline))
#endif
static void lv_wheels_rhs_call(const double *y, const double *r, const double *kw, const double *F, const double *tau,
                               const double *u, double *yd)
{
    lv_wheels_rhs(0, y, r, kw, F, tau, u, yd);
}

/* The torques the motors of a body with wheels apply this step (the printed motor line, per wheel). */
static inline void lv_wheels_motor(const double *r, const double *cmd, const double *Omega, double *u)
{
    LV_WHEELS_MOTOR(cmd, Omega, r[LV_MODEL_TORQUE_LIMIT], r[LV_MODEL_SPEED_LIMIT], r[LV_MODEL_CUTOFF], u);
}

/* The wheels of a model row in use: the columns of A_b with a nonzero axis (padded slots have none). */
static int lv_wheel_count(const double *r)
{
    const int rows = LV_MODEL_A_B_LEN / LV_NW;
    int i, k, n = 0;
    for (i = 0; i < LV_NW; i++) {
        int used = 0;
        for (k = 0; k < rows; k++) used |= r[LV_MODEL_A_B + k * LV_NW + i] != 0.0;
        n += used;
    }
    return n;
}

/* d/dt of [x, Omega] for a body of nonzero kind; u = this step's applied wheel torques.
   r = its model row, kw its wheel coefficients (read only with wheels). A jointed body's p, v derivatives are zero (set from the joint after the step);
   its effects that read v_w see the kinematic COM velocity (computed only when needs_v). */
static inline void model_rhs_of(const double *y, const double *u, double m, const double *I_b, const double *r,
                                const double *kw, int kind, int needs_v, int builtin, const lv_effect_ref *refs,
                                long n_refs, double *yd)
{
    double F[3] = LV_SUM_START3, tau[3] = LV_SUM_START3, pk[3], vk[3];
    const double *v = y + LV_STATE_V_W;
    int i;
    if (needs_v) {
        lv_pivot_kinematics(y + LV_STATE_Q, y + LV_STATE_OMEGA_B, r + LV_MODEL_ANCHOR_W, r + LV_MODEL_R_B, pk, vk);
        v = vk;
    }
    if (builtin) builtin_effect_sums(y, v, m, I_b, refs, n_refs, F, tau);
    else effect_sums(y, v, m, I_b, refs, n_refs, F, tau);
    if (kind & LV_ON_AXES) {
        lv_wheels_rhs(1, y, r, kw, F, tau, u, yd); /* inlined: fewer numbers than the general print */
    } else if (kind & LV_KIND_WHEELS) {
        lv_wheels_rhs_call(y, r, kw, F, tau, u, yd);
    } else {
        lv_pivot_body_rhs(y + LV_STATE_Q, y + LV_STATE_OMEGA_B, r + LV_MODEL_I_P, r + LV_MODEL_R_B, F, tau,
                          yd + LV_STATE_Q, yd + LV_STATE_OMEGA_B);
        for (i = 0; i < LV_NW; i++) yd[LV_XS_OMEGA + i] = 0.0;
    }
    if (kind & LV_KIND_JOINT) {
        for (i = 0; i < 3; i++) yd[LV_STATE_P_W + i] = yd[LV_STATE_V_W + i] = 0.0;
    } else {
        lv_translation_rhs(m, y + LV_STATE_V_W, F, yd + LV_STATE_P_W, yd + LV_STATE_V_W);
    }
}

static void model_rhs(const double *y, const double *u, double m, const double *I_b, const double *r,
                      const double *kw, int kind, int needs_v, const lv_effect_ref *refs, long n_refs, double *yd)
{
    model_rhs_of(y, u, m, I_b, r, kw, kind, needs_v, 0, refs, n_refs, yd);
}

/* Advance body b (nonzero kind) by n_steps. Its rows are written only on success; returns -1, or the
   0-based failing step with last[] = its last finite [x, Omega]. kind is the body's (its model row's);
   builtin: none of its effects is a user effect (then the effect sums inline). advance_model_body calls it
   with constant kind, builtin, integrator and normalize, so each combination compiles to its own loop. */
static inline long advance_model(double *state, const double *params, long b, const lv_models *md,
                                 const lv_effect_index *ix, int kind, int builtin, int integrator, int normalize,
                                 double dt, long n_steps, double *last)
{
    const double *r = md->rows + b * LV_MODEL_SIZE;
    const double m = params[b * LV_PARAM_SIZE + LV_PARAM_M];
    const double *cmd = md->command + LV_NW * b;
    double y[LV_XS_SIZE], yn[LV_XS_SIZE], k1[LV_XS_SIZE], acc[LV_XS_SIZE], tmp[LV_XS_SIZE];
    double u[LV_NW] = {0.0}, applied[LV_NW], kw[LV_WCOEF_SIZE] = {0.0};
    const double *I_b = params + b * LV_PARAM_SIZE + LV_PARAM_I_B;
    const lv_effect_ref *refs = ix->refs + ix->start[b];
    const long n_refs = ix->start[b + 1] - ix->start[b];
    const int needs_v = (kind & LV_KIND_JOINT) && (ix->flags[b] & LV_EFFECT_USES_V);
    long s;
    int i;
    memcpy(y, state + b * LV_STATE_SIZE, LV_STATE_SIZE * sizeof(double));
    memcpy(y + LV_XS_OMEGA, md->Omega + LV_NW * b, LV_NW * sizeof(double));
    memcpy(applied, md->applied + LV_NW * b, sizeof applied);
    if (kind & LV_KIND_WHEELS) model_coefficients(md, b, kw);
#define MRHS(in, out) model_rhs_of(in, u, m, I_b, r, kw, kind, needs_v, builtin, refs, n_refs, out)
#define XS_FOR(stmt) LV_XS_UNROLL for (i = 0; i < LV_XS_SIZE; i++) stmt
#define XS_AT(v) v[i]
    for (s = 0; s < n_steps; s++) {
        if (kind & LV_KIND_WHEELS) lv_wheels_motor(r, cmd, y + LV_XS_OMEGA, u);
        switch (integrator) {
        case LV_PATH_EULER:
            LV_EULER_STEP(double, MRHS, XS_FOR, XS_AT, dt, y, yn, k1, acc, tmp);
            break;
        case LV_PATH_SEMI_IMPLICIT:
            MRHS(y, k1);
            for (i = 0; i < 3; i++) {                                    /* v', omega' */
                yn[LV_STATE_V_W + i] = y[LV_STATE_V_W + i] + dt * k1[LV_STATE_V_W + i];
                yn[LV_STATE_OMEGA_B + i] = y[LV_STATE_OMEGA_B + i] + dt * k1[LV_STATE_OMEGA_B + i];
            }
            for (i = 0; i < LV_NW; i++) yn[LV_XS_OMEGA + i] = y[LV_XS_OMEGA + i] + dt * k1[LV_XS_OMEGA + i]; /* Omega' */
            lv_translation_drift(y + LV_STATE_P_W, yn + LV_STATE_V_W, dt, yn + LV_STATE_P_W); /* p + dt v' */
            lv_quat_derivative_body(y + LV_STATE_Q, yn + LV_STATE_OMEGA_B, tmp);                /* q rate at omega' */
            for (i = 0; i < 4; i++) yn[LV_STATE_Q + i] = y[LV_STATE_Q + i] + dt * tmp[i];
            break;
        default: /* LV_PATH_RK4 */
            LV_RK4_STEP(double, MRHS, XS_FOR, XS_AT, dt, y, yn, k1, acc, tmp);
            break;
        }
        if (normalize) lv_quat_normalize(yn + LV_STATE_Q, yn + LV_STATE_Q);
        if (kind & LV_KIND_JOINT)
            lv_pivot_kinematics(yn + LV_STATE_Q, yn + LV_STATE_OMEGA_B, r + LV_MODEL_ANCHOR_W, r + LV_MODEL_R_B,
                                yn + LV_STATE_P_W, yn + LV_STATE_V_W);
        LV_XS_UNROLL for (i = 0; i < LV_XS_SIZE; i++) {
            if (!isfinite(yn[i])) {
                memcpy(last, y, sizeof y);
                return s;
            }
        }
        memcpy(y, yn, sizeof y);
        memcpy(applied, u, sizeof u);
    }
#undef MRHS
#undef XS_FOR
#undef XS_AT
    memcpy(state + b * LV_STATE_SIZE, y, LV_STATE_SIZE * sizeof(double));
    memcpy(md->Omega + LV_NW * b, y + LV_XS_OMEGA, LV_NW * sizeof(double));
    memcpy(md->applied + LV_NW * b, applied, sizeof applied);
    return -1;
}

/* advance_model for body b with its kind, builtin flag, integrator and normalize as constants: RK4 with
   built-in effects only (the env's cube, the common case) gets a loop per kind with the kernels and the
   effect dispatch inlined (flatten); anything else the generic loop. Same arithmetic in the same order
   either way (inlining changes no operation), so the results are bitwise the same. */
#define LV_MODEL_RK4(k) (normalize ? advance_model(state, params, b, md, ix, (k), 1, LV_PATH_RK4, 1, dt, n_steps, last) \
                                   : advance_model(state, params, b, md, ix, (k), 1, LV_PATH_RK4, 0, dt, n_steps, last))
LV_FLATTEN static long advance_model_rk4(double *state, const double *params, long b, const lv_models *md,
                                         const lv_effect_index *ix, int kind, int normalize, double dt, long n_steps,
                                         double *last)
{
    switch (kind) {
    case LV_KIND_JOINT | LV_KIND_WHEELS | LV_ON_AXES: return LV_MODEL_RK4(LV_KIND_JOINT | LV_KIND_WHEELS | LV_ON_AXES);
    case LV_KIND_WHEELS | LV_ON_AXES: return LV_MODEL_RK4(LV_KIND_WHEELS | LV_ON_AXES);
    case LV_KIND_JOINT | LV_KIND_WHEELS: return LV_MODEL_RK4(LV_KIND_JOINT | LV_KIND_WHEELS);
    case LV_KIND_WHEELS: return LV_MODEL_RK4(LV_KIND_WHEELS);
    default: return LV_MODEL_RK4(LV_KIND_JOINT);
    }
}
#undef LV_MODEL_RK4

static long advance_model_body(double *state, const double *params, long b, const lv_models *md,
                               const lv_effect_index *ix, int integrator, int normalize, double dt, long n_steps,
                               double *last)
{
    const int kind = model_step_kind(md, b);
    long k;
    int builtin = 1;
    for (k = ix->start[b]; k < ix->start[b + 1]; k++)
        if (ix->refs[k].user != NULL) builtin = 0;
    if (integrator == LV_PATH_RK4 && builtin)
        return advance_model_rk4(state, params, b, md, ix, kind, normalize, dt, n_steps, last);
    return advance_model(state, params, b, md, ix, kind, 0, integrator, normalize, dt, n_steps, last);
}

/* ---- per-body integrators: dopri5 (any kind), splitting and implicit_gyro (plain bodies) ------- */

/* One body's right-hand side on the extended state [x, Omega] (LV_XS_SIZE): plain bodies get Omega' = 0. */
typedef struct {
    long b;
    int kind, has, needs_v, flags;
    double m;
    const double *prm, *r;
    const lv_effect_ref *refs;
    long n_refs;
    double u[LV_NW];
    double kw[LV_WCOEF_SIZE];  /* wheel coefficients (with wheels) */
} body_ctx;

static void ctx_rhs(const body_ctx *c, const double *y, double *yd)
{
    if (c->kind == 0) {
        int i;
        body_rhs(y, c->prm, c->refs, c->n_refs, c->flags, yd);
        for (i = 0; i < LV_NW; i++) yd[LV_XS_OMEGA + i] = 0.0;
    } else {
        model_rhs(y, c->u, c->m, c->prm + LV_PARAM_I_B, c->r, c->kw, c->kind, c->needs_v, c->refs, c->n_refs, yd);
    }
}

static void ctx_init(body_ctx *c, const double *params, long b, const lv_models *md, const lv_effect_index *ix)
{
    int i;
    c->b = b;
    c->prm = params + b * LV_PARAM_SIZE;
    c->m = c->prm[LV_PARAM_M];
    c->refs = ix->refs + ix->start[b];
    c->n_refs = ix->start[b + 1] - ix->start[b];
    c->flags = ix->flags[b];
    c->kind = md != NULL ? (int)md->rows[b * LV_MODEL_SIZE + LV_MODEL_KIND] : 0;
    c->r = md != NULL ? md->rows + b * LV_MODEL_SIZE : NULL;
    c->has = c->n_refs > 0;
    c->needs_v = (c->kind & LV_KIND_JOINT) && (c->flags & LV_EFFECT_USES_V);
    for (i = 0; i < LV_NW; i++) c->u[i] = 0.0;
    for (i = 0; i < LV_WCOEF_SIZE; i++) c->kw[i] = 0.0;
    if (c->kind & LV_KIND_WHEELS) lv_wheels_coefficients(c->r, c->kw);
}

/* ---- the explicit Runge-Kutta family, one stage loop: a user's tableau (lv_tableau) and dopri5 -------------
   Dormand-Prince 5(4) is the printed tableau LV_DP_A (generated/tableaux.h; its last row is the 5th-order solution,
   FSAL) with the error weights LV_DP_E and a step-size controller on top. The nodes c_i are not needed: the
   right-hand side does not depend on time. */

/* out = y + h * sum_j w[j] k[j] over j < n (lv_tableau's order: the first nonzero w[j] k[j], then the later nonzero
   ones added in increasing j); y when every w[j] is zero. One row of an explicit Runge-Kutta tableau. */
static void rk_row(double *out, const double *y, double h, const double *w, double k[][LV_XS_SIZE], int n)
{
    int i, j, j0 = 0;
    while (j0 < n && w[j0] == 0.0) j0++;
    if (j0 == n) {
        memcpy(out, y, LV_XS_SIZE * sizeof(double));
        return;
    }
    for (i = 0; i < LV_XS_SIZE; i++) {
        double acc = w[j0] * k[j0][i];
        for (j = j0 + 1; j < n; j++)
            if (w[j] != 0.0) acc = acc + w[j] * k[j][i];
        out[i] = y[i] + h * acc;
    }
}

/* The stages first .. s-1 of the tableau a (row i at a + i * lda) at y with step h: k[i] = f(y + h sum_j a[i][j] k[j])
   (rk_row); out holds the last stage's input. */
static void rk_stages(const body_ctx *c, const double *y, double h, const double *a, int lda, int first, int s,
                      double k[][LV_XS_SIZE], double *out)
{
    int i;
    for (i = first; i < s; i++) {
        rk_row(out, y, h, a + i * lda, k, i);
        ctx_rhs(c, out, k[i]);
    }
}

/* Accept the step's end yn: normalize q, put a jointed body back on its joint, then y = yn when every number is
   finite. 0 (y untouched) when one is not. */
static int rk_accept(const body_ctx *c, double *y, double *yn, int normalize)
{
    int i;
    if (normalize) lv_quat_normalize(yn + LV_STATE_Q, yn + LV_STATE_Q);
    if (c->kind & LV_KIND_JOINT)
        lv_pivot_kinematics(yn + LV_STATE_Q, yn + LV_STATE_OMEGA_B, c->r + LV_MODEL_ANCHOR_W, c->r + LV_MODEL_R_B,
                            yn + LV_STATE_P_W, yn + LV_STATE_V_W);
    for (i = 0; i < LV_XS_SIZE; i++)
        if (!isfinite(yn[i])) return 0;
    memcpy(y, yn, LV_XS_SIZE * sizeof(double));
    return 1;
}

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

/* dopri5's controller state of one body: the step-size proposal h, the norm's count n (the state and the rates of the
   wheels in use; the padded slots stay 0), the evaluations spent. */
typedef struct {
    double h, nfev, rtol, atol;
    int n;
} dp_control;

/* Hairer's starting step (Solving ODEs I, II.4): from f0 = f(y) and one more evaluation. */
static double dp_initial_h(const body_ctx *c, const double *y, const double *f0, dp_control *d, double dt)
{
    double y1[LV_XS_SIZE], f1[LV_XS_SIZE], dd[LV_XS_SIZE], d0, d1, d2, h0, h1, mx;
    int i;
    for (i = 0; i < d->n; i++) dd[i] = 0.0;
    d0 = dp_norm(y, y, y, d->n, d->rtol, d->atol);
    d1 = dp_norm(f0, y, y, d->n, d->rtol, d->atol);
    h0 = (d0 < LV_DP_INIT_SMALL || d1 < LV_DP_INIT_SMALL) ? LV_DP_INIT_TINY_H : LV_DP_INIT_FRAC * d0 / d1;
    if (h0 > dt) h0 = dt;
    for (i = 0; i < LV_XS_SIZE; i++) y1[i] = y[i] + h0 * f0[i];
    ctx_rhs(c, y1, f1);
    d->nfev += 1;
    for (i = 0; i < d->n; i++) dd[i] = (f1[i] - f0[i]) / h0;
    d2 = dp_norm(dd, y, y, d->n, d->rtol, d->atol);
    mx = d1 > d2 ? d1 : d2;
    h1 = mx <= LV_DP_INIT_FLAT ? (h0 * LV_DP_INIT_SHRINK > LV_DP_INIT_TINY_H ? h0 * LV_DP_INIT_SHRINK : LV_DP_INIT_TINY_H)
                               : pow(LV_DP_INIT_FRAC / mx, LV_DP_INIT_EXPONENT);
    h0 = LV_DP_INIT_GROW * h0 < h1 ? LV_DP_INIT_GROW * h0 : h1;
    return isfinite(h0) && h0 > 0.0 ? h0 : dt;
}

/* The controller's factor SAFETY e^(-1/5) without pow (derive/tableaux.py DP_ROOT5_*): Newton steps on r^-5 = e from
   a bit-pattern seed within [LO, HI]; FACMAX below (e = 0 included), FACMIN above or for NaN (before clamping). */
static inline double dp_factor(double e)
{
    if (e >= LV_DP_ROOT5_LO && e <= LV_DP_ROOT5_HI) {
        uint64_t bits;
        double r;
        int it;
        memcpy(&bits, &e, sizeof bits);
        bits = LV_DP_ROOT5_SEED - bits / LV_DP_ROOT5_DIV;
        memcpy(&r, &bits, sizeof r);
        for (it = 0; it < LV_DP_ROOT5_NEWTON; it++) {
            const double r2 = r * r;
            r = r * (LV_DP_ROOT5_A - e * (r2 * r2 * r)) * LV_DP_ROOT5_B;
        }
        return LV_DP_SAFETY * r;
    }
    return e < LV_DP_ROOT5_LO ? LV_DP_FACMAX : LV_DP_FACMIN;
}

/* The numbers of a body that go through dopri5's stages (DP_*): a plain body without effects only q and omega_b (its
   v is constant, so p moves by h v and their error estimates are exactly zero), a plain body with effects its state,
   any other body [x, Omega]. */
enum { DP_FREE = 0, DP_PLAIN = 1, DP_MODEL = 2 };
static const int DP_IDX[LV_XS_SIZE] = {0, 1, 2, 3, 4, 5, 6, 7, 8, 9, 10, 11, 12, 13, 14, 15, 16};
static const int DP_IDX_FREE[7] = {LV_STATE_Q, LV_STATE_Q + 1, LV_STATE_Q + 2, LV_STATE_Q + 3,
                                   LV_STATE_OMEGA_B, LV_STATE_OMEGA_B + 1, LV_STATE_OMEGA_B + 2};
#define DP_IDX_OF(v) ((v) == DP_FREE ? DP_IDX_FREE : DP_IDX)
#define DP_N_OF(v) ((v) == DP_FREE ? 7 : (v) == DP_PLAIN ? LV_STATE_SIZE : LV_XS_SIZE)

/* out[i] = y[i] + h sum_{j < s, w[j] != 0} w[j] k[j][i] (left to right; y NULL: without y[i]) for the variant's
   numbers i: with w a row of the printed tableau and everything unrolled, the zero entries cost nothing. */
static inline void dp_combine(int v, double *out, const double *y, double h, const double *w, double k[][LV_XS_SIZE],
                              int s)
{
    int ii, j;
    LV_XS_UNROLL for (ii = 0; ii < DP_N_OF(v); ii++) {
        const int i = DP_IDX_OF(v)[ii];
        double acc = 0.0;
        int first = 1;
        LV_XS_UNROLL for (j = 0; j < s; j++) {
            if (w[j] == 0.0) continue;
            acc = first ? w[j] * k[j][i] : acc + w[j] * k[j][i];
            first = 0;
        }
        out[i] = y != NULL ? y[i] + h * acc : h * acc;
    }
}

/* The variant's right-hand side; cf a plain body's Euler coefficients (lv_euler_coefficients). */
static inline void dp_rhs(int v, const body_ctx *c, const double *cf, const double *y, double *yd)
{
    if (v == DP_FREE) {
        lv_rigid_body_rhs_free_c(y, cf, yd);
    } else if (v == DP_PLAIN) {
        plain_rhs(rhs_class(c->n_refs, c->flags), y, c->m, c->prm + LV_PARAM_I_B, cf, c->refs, c->n_refs, yd);
    } else {
        ctx_rhs(c, y, yd);
    }
}

/* rk_accept for the variant: a body without a model has no joint, and its numbers past its state stay 0. */
static inline int dp_accept(int v, const body_ctx *c, double *y, double *yn, int normalize)
{
    int i;
    if (v == DP_MODEL) return rk_accept(c, y, yn, normalize);
    if (normalize) lv_quat_normalize(yn + LV_STATE_Q, yn + LV_STATE_Q);
    for (i = 0; i < LV_STATE_SIZE; i++)
        if (!isfinite(yn[i])) return 0;
    memcpy(y, yn, LV_STATE_SIZE * sizeof(double));
    return 1;
}

/* One substep attempt of hs from y (k[0] = f(y)): the six stages (k[6] = f(yn), FSAL), yn = the 5th-order solution
   (a free body's p by hs v), and the error norm. */
static inline double dp_attempt(int v, const body_ctx *c, const double *cf, const double *y, double hs,
                                double k[][LV_XS_SIZE], double *yn, const dp_control *d)
{
    double err[LV_XS_SIZE], s = 0.0;
    int st, ii;
    LV_XS_UNROLL for (st = 1; st < 7; st++) {
        dp_combine(v, yn, y, hs, LV_DP_A[st], k, st);
        dp_rhs(v, c, cf, yn, k[st]);
    }
    if (v == DP_FREE)
        for (ii = 0; ii < 3; ii++) yn[LV_STATE_P_W + ii] = y[LV_STATE_P_W + ii] + hs * y[LV_STATE_V_W + ii];
    dp_combine(v, err, NULL, hs, LV_DP_E, k, 7);
    LV_XS_UNROLL for (ii = 0; ii < DP_N_OF(v); ii++) {   /* dp_norm over the variant's numbers */
        const int i = DP_IDX_OF(v)[ii];
        const double a = fabs(y[i]), bb = fabs(yn[i]);
        if (err[i] != 0.0) {
            const double z = err[i] / (d->atol + d->rtol * (a > bb ? a : bb));
            s += z * z;
        }
    }
    return sqrt(s / d->n);
}

/* dopri5 with dense output: the integrator keeps its own state z, `ahead` seconds past the output state, and steps on
   unclipped; an output time inside its last accepted substep (of length hl) is read off the continuous extension
   (Y0..Y4, derive/tableaux.py DP_DENSE), so an output interval forces no substep. Carried between calls in the body's
   DENSE row (lv_adaptive.dense). A body with wheels lands on every output time instead (its held torque changes
   there: the substep that would pass it is clipped to end on it, z is the output and nothing is carried). The extension Y is formed only when an output is
   read (have_Y 0: from the last accepted substep's z0, raw end y1 and stages, which stay in the stage set that is not
   current: the caller's k and Kb take turns, cur naming the current one, so nothing is copied but z0, y1 and f). */
typedef struct {
    double z[LV_XS_SIZE], Y[5][LV_XS_SIZE], ahead, hl, a0, m;   /* a0, m: DENSE lead0, passed (dp_skip) */
    double Kb[7][LV_XS_SIZE], z0[LV_XS_SIZE], y1[LV_XS_SIZE];
    int cur, have_Y;
} dp_dense;

/* The numbers an output interpolates: a body without a model its state, else [x, Omega]. */
#define DP_NOUT_OF(v) ((v) == DP_MODEL ? LV_XS_SIZE : LV_STATE_SIZE)

/* The dense-output coefficients of the accepted substep y0 -> y1 (raw, before normalizing) of length h: Y0 = y0,
   Y1 = y1 - y0, Y2 = h k1 - Y1, Y3 = Y1 - h k7 - Y2, Y4 = h sum_i DP_DENSE[i] k_i; a free body's p is linear (Y0, Y1)
   and its v constant (Y0). */
static inline void dp_dense_coeffs(int v, const double *y0, const double *y1, double h, double k[][LV_XS_SIZE],
                                   dp_dense *o)
{
    double y4[LV_XS_SIZE];
    int ii;
    dp_combine(v, y4, NULL, h, LV_DP_DENSE, k, 7);
    LV_XS_UNROLL for (ii = 0; ii < DP_N_OF(v); ii++) {
        const int i = DP_IDX_OF(v)[ii];
        const double d1 = y1[i] - y0[i], d2 = h * k[0][i] - d1;
        o->Y[0][i] = y0[i];
        o->Y[1][i] = d1;
        o->Y[2][i] = d2;
        o->Y[3][i] = d1 - h * k[6][i] - d2;
        o->Y[4][i] = y4[i];
    }
    if (v == DP_FREE)
        for (ii = 0; ii < 3; ii++) {
            const int p = LV_STATE_P_W + ii, w = LV_STATE_V_W + ii;
            o->Y[0][p] = y0[p], o->Y[1][p] = y1[p] - y0[p], o->Y[2][p] = o->Y[3][p] = o->Y[4][p] = 0.0;
            o->Y[0][w] = y0[w], o->Y[1][w] = y1[w] - y0[w], o->Y[2][w] = o->Y[3][w] = o->Y[4][w] = 0.0;
        }
}

/* The output steps the integrator's lead covers, in O(1) whatever their number: the lead after m output steps since
   a0 (the lead at the last accepted substep or the call's start) is a0 - m dt, one rounding (not m subtractions;
   NumPy's _dopri5 forms the same double). From m (a0 - m dt >= 0) to the smallest m' > m with a0 - m' dt < 0, at
   most last - *s further steps (*s advanced alike; m' = that cap when the lead still covers it). a0 - m dt does not
   increase with m, so a guess from a0 / dt (rdt = 1 / dt) corrected by one-step moves finds that m'. Returns
   a0 - m' dt. */
static inline double dp_skip(double a0, double dt, double rdt, long *m, long *s, long last)
{
    const long lo = *m + 1, top = *m + (last - *s);
    const double g = a0 * rdt + 1.0;   /* a0 >= 0 here: (long) g is floor(a0 / dt) + 1, give or take one */
    long j = !(g > (double)lo) ? lo : g >= (double)top ? top : (long)g;
    while (j > lo && a0 - (double)(j - 1) * dt < 0.0) j--;
    while (j < top && a0 - (double)j * dt >= 0.0) j++;
    *s += j - *m;
    *m = j;
    return a0 - (double)j * dt;
}

/* Output steps *s_io .. of dt with dense output, up to the call's last (n_steps - 1) or, with land, this one only:
   each lowers the lead z->ahead by dt (dp_skip); one that leaves it >= 0 costs nothing else, else substeps
   (unclipped; with land the one that would pass the output time clipped to end on it, the proposal not shrunk by
   that; rejections and the substep count per output step) until z is past the output time. At the last output step (no state between is seen; every
   step of a landing body) y = the continuous extension there, q normalized, a jointed body put on its joint (z itself
   when it lands on it: already so). *s_io = the output step reached. LV_OK; else LV_DIVERGED or LV_TOLERANCE (at
   output step *s_io) with y untouched. z, ahead and the step in locals: nothing aliases the stage stores. */
static inline int dp_dense_run(int v, const body_ctx *c, const double *cf, double *y, double k[][LV_XS_SIZE],
                               dp_control *d, dp_dense *z, double dt, int normalize, long *s_io, long n_steps, int land)
{
    double yn[LV_XS_SIZE], yo[LV_XS_SIZE], zz[LV_XS_SIZE], a0 = z->ahead, ahead, h = d->h;
    const double rdt = 1.0 / dt;
    long s = *s_io, m = 0;
    int ii, st = LV_OK;
    if (z->m > 0.0 && z->a0 - z->m * dt == a0)   /* the count since the last substep goes on (same dt) */
        a0 = z->a0, m = (long)z->m;
    ahead = a0 - (double)++m * dt;
    memcpy(zz, z->z, sizeof zz);
    memcpy(yn, zz, sizeof yn);
    if (ahead >= 0.0 && s < n_steps - 1)   /* output steps inside the last substep cost this only */
        ahead = dp_skip(a0, dt, rdt, &m, &s, n_steps - 1);
    for (;;) {
        long sub = 0;
        int rejected = 0;
        while (ahead < 0.0) {
            double (*kc)[LV_XS_SIZE] = z->cur ? z->Kb : k, (*kn)[LV_XS_SIZE] = z->cur ? k : z->Kb;
            const int clipped = land && h >= -ahead;
            const double hs = clipped ? -ahead : h;
            const double e = dp_attempt(v, c, cf, zz, hs, kc, yn, d);
            double fac = dp_factor(e);
            d->nfev += 6;
            if (e <= 1.0) {
                if (fac > LV_DP_FACMAX) fac = LV_DP_FACMAX;
                if (fac < LV_DP_FACMIN) fac = LV_DP_FACMIN;
                if (rejected && fac > 1.0) fac = 1.0;
                if (!(clipped && fac >= 1.0 && h > hs * fac)) h = hs * fac;
                memcpy(z->z0, zz, DP_NOUT_OF(v) * sizeof(double));
                memcpy(z->y1, yn, DP_NOUT_OF(v) * sizeof(double));
                if (!dp_accept(v, c, zz, yn, normalize)) {
                    st = LV_DIVERGED;
                    break;
                }
                LV_XS_UNROLL for (ii = 0; ii < DP_N_OF(v); ii++)   /* FSAL: f at the new (un-normalized) point */
                    kn[0][DP_IDX_OF(v)[ii]] = kc[6][DP_IDX_OF(v)[ii]];
                z->cur ^= 1;
                z->have_Y = 0;
                a0 = ahead = clipped ? 0.0 : ahead + hs;
                m = 0;
                z->hl = hs;
                rejected = 0;
            } else {
                if (fac < LV_DP_FACMIN) fac = LV_DP_FACMIN;
                if (fac > 1.0) fac = 1.0;
                h = hs * fac;
                rejected = 1;
            }
            if (h < LV_DP_HMIN_REL * dt || ++sub > LV_DP_MAX_SUBSTEPS) {
                st = LV_TOLERANCE;
                break;
            }
        }
        if (st != LV_OK || land || s == n_steps - 1) break;
        ahead = dp_skip(a0, dt, rdt, &m, &s, n_steps - 1);   /* the next output step, and those inside the last substep */
    }
    memcpy(z->z, zz, sizeof zz);
    z->ahead = ahead;
    z->a0 = a0;
    z->m = (double)m;
    d->h = h;
    *s_io = s;
    if (st != LV_OK) return st;
    if (ahead == 0.0) {
        memcpy(y, zz, DP_NOUT_OF(v) * sizeof(double));
        return LV_OK;
    }
    if (!z->have_Y) {
        dp_dense_coeffs(v, z->z0, z->y1, z->hl, z->cur ? k : z->Kb, z);
        z->have_Y = 1;
    }
    memcpy(yo, y, sizeof yo);
    {
        const double th = (z->hl - ahead) / z->hl, th1 = 1.0 - th;
        LV_XS_UNROLL for (ii = 0; ii < DP_NOUT_OF(v); ii++)
            yo[ii] = z->Y[0][ii] + th * (z->Y[1][ii] + th1 * (z->Y[2][ii] + th * (z->Y[3][ii] + th1 * z->Y[4][ii])));
    }
    if (!dp_accept(v, c, y, yo, normalize)) return LV_DIVERGED;
    return LV_OK;
}

/* The body's dense-output row -> z, k[0] (FSAL) when it continues y (row given and valid, y the state the last call
   wrote): 1; else z = y: 0 (k[0] = f(y) is then the caller's). */
static int dp_dense_load(const double *row, const double *y, double k[][LV_XS_SIZE], dp_dense *z)
{
    if (row != NULL && row[LV_DENSE_VALID] == 1.0 && memcmp(row + LV_DENSE_X_OUT, y, LV_STATE_SIZE * sizeof(double)) == 0) {
        memcpy(z->z, row + LV_DENSE_Z, sizeof z->z);
        memcpy(k[0], row + LV_DENSE_F, sizeof k[0]);
        memcpy(z->Y, row + LV_DENSE_COEF, sizeof z->Y);
        z->ahead = row[LV_DENSE_AHEAD];
        z->hl = row[LV_DENSE_H_LAST];
        z->a0 = row[LV_DENSE_LEAD0];
        z->m = row[LV_DENSE_PASSED];
        z->cur = 0;
        z->have_Y = 1;
        return 1;
    }
    memset(z, 0, sizeof *z);
    memcpy(z->z, y, sizeof z->z);
    return 0;
}

static void dp_dense_store(double *row, const double *y, double k[][LV_XS_SIZE], const dp_dense *z)
{
    row[LV_DENSE_VALID] = 1.0;
    row[LV_DENSE_AHEAD] = z->ahead;
    row[LV_DENSE_H_LAST] = z->hl;
    row[LV_DENSE_LEAD0] = z->a0;
    row[LV_DENSE_PASSED] = z->m;
    memcpy(row + LV_DENSE_Z, z->z, sizeof z->z);
    memcpy(row + LV_DENSE_F, z->cur ? z->Kb[0] : k[0], sizeof k[0]);
    memcpy(row + LV_DENSE_X_OUT, y, LV_STATE_SIZE * sizeof(double));
    memcpy(row + LV_DENSE_COEF, z->Y, sizeof z->Y);
}

/* dp_dense_run per variant, each its own loop with the right-hand side inlined. */
LV_FLATTEN static int dp_dense_run_free(const body_ctx *c, const double *cf, double *y, double k[][LV_XS_SIZE],
                                        dp_control *d, dp_dense *z, double dt, int normalize, long *s, long n)
{
    return dp_dense_run(DP_FREE, c, cf, y, k, d, z, dt, normalize, s, n, 0);
}

LV_FLATTEN static int dp_dense_run_plain(const body_ctx *c, const double *cf, double *y, double k[][LV_XS_SIZE],
                                         dp_control *d, dp_dense *z, double dt, int normalize, long *s, long n)
{
    return dp_dense_run(DP_PLAIN, c, cf, y, k, d, z, dt, normalize, s, n, 0);
}

static int dp_dense_run_model(const body_ctx *c, const double *cf, double *y, double k[][LV_XS_SIZE], dp_control *d,
                              dp_dense *z, double dt, int normalize, long *s, long n, int land)
{
    return dp_dense_run(DP_MODEL, c, cf, y, k, d, z, dt, normalize, s, n, land);
}

/* Advance body b (any kind) by n_steps steps of dt of an explicit Runge-Kutta method: the user's tableau tab, or
   (ad != NULL) dopri5 with its per-body step sizes (lv_adaptive). Wheel torques from the motor line at the start of
   each step, held over it; q normalized when asked; a jointed body put back on its joint. Rows written only on
   success; returns -1, or the 0-based failing step with *why = LV_DIVERGED or LV_TOLERANCE and last[] = its last
   finite [x, Omega]. */
static long advance_rk(double *state, const double *params, long b, const lv_models *md, const lv_effect_index *ix,
                       const lv_tableau *tab, const lv_adaptive *ad, int normalize, double dt, long n_steps, int *why,
                       double *last)
{
    body_ctx c;
    dp_control d = {0.0, 0.0, 0.0, 0.0, 0};
    double y[LV_XS_SIZE], yn[LV_XS_SIZE], k[LV_TABLEAU_MAX_STAGES][LV_XS_SIZE], applied[LV_NW], cf[6];
    const double *cmd = NULL;
    dp_dense z;
    double *row = NULL;
    long s;
    int i, st = LV_OK, land = 0, fresh = 1;
    ctx_init(&c, params, b, md, ix);
    lv_euler_coefficients(c.prm + LV_PARAM_I_B, cf);
    memcpy(y, state + b * LV_STATE_SIZE, LV_STATE_SIZE * sizeof(double));
    for (i = 0; i < LV_NW; i++) y[LV_XS_OMEGA + i] = 0.0;
    if (c.kind) {
        memcpy(y + LV_XS_OMEGA, md->Omega + LV_NW * b, LV_NW * sizeof(double));
        memcpy(applied, md->applied + LV_NW * b, sizeof applied);
        cmd = md->command + LV_NW * b;
    }
    if (ad != NULL) {
        d.h = ad->h[b], d.nfev = 0.0, d.rtol = ad->rtol, d.atol = ad->atol;
        d.n = c.kind & LV_KIND_WHEELS ? LV_XS_OMEGA + lv_wheel_count(c.r) : LV_STATE_SIZE;
        land = (c.kind & LV_KIND_WHEELS) != 0;   /* the held torque changes at each output time: land there */
        row = ad->dense != NULL && !land ? ad->dense + b * LV_DENSE_SIZE : NULL;
        fresh = !dp_dense_load(row, y, k, &z);
    }
    if (ad != NULL) {
        for (s = 0; s < n_steps && st == LV_OK; s++) {   /* a body without wheels: one dp_dense_run for all */
            if (land) lv_wheels_motor(c.r, cmd, y + LV_XS_OMEGA, c.u);
            if (fresh || land) {   /* f at z (the FSAL stage) under this step's loads */
                ctx_rhs(&c, z.z, z.cur ? z.Kb[0] : k[0]);
                d.nfev += 1;
                fresh = 0;
            }
            if (s == 0 && (!(d.h > 0.0) || !isfinite(d.h)))   /* a starting step where there is no proposal */
                d.h = dp_initial_h(&c, z.z, z.cur ? z.Kb[0] : k[0], &d, dt);
            st = c.kind ? dp_dense_run_model(&c, cf, y, k, &d, &z, dt, normalize, &s, n_steps, land)
                 : c.n_refs ? dp_dense_run_plain(&c, cf, y, k, &d, &z, dt, normalize, &s, n_steps)
                 : dp_dense_run_free(&c, cf, y, k, &d, &z, dt, normalize, &s, n_steps);
            if (st == LV_OK && c.kind) memcpy(applied, c.u, sizeof applied);
        }
    } else {
        for (s = 0; s < n_steps && st == LV_OK; s++) {
            if (c.kind & LV_KIND_WHEELS) lv_wheels_motor(c.r, cmd, y + LV_XS_OMEGA, c.u);
            rk_stages(&c, y, dt, tab->a, tab->s, 0, tab->s, k, yn);
            rk_row(yn, y, dt / tab->b_den, tab->b_num, k, tab->s);
            st = rk_accept(&c, y, yn, normalize) ? LV_OK : LV_DIVERGED;
            if (st == LV_OK && c.kind) memcpy(applied, c.u, sizeof applied);
        }
    }
    if (ad != NULL) {
        if (st != LV_DIVERGED) ad->h[b] = d.h;
        ad->nfev[b] += d.nfev;
        if (row != NULL && st == LV_OK && n_steps > 0) dp_dense_store(row, y, k, &z);
    }
    if (st != LV_OK) {
        *why = st;
        memcpy(last, y, sizeof y);
        return s - 1;
    }
    memcpy(state + b * LV_STATE_SIZE, y, LV_STATE_SIZE * sizeof(double));
    if (c.kind) {
        memcpy(md->Omega + LV_NW * b, y + LV_XS_OMEGA, LV_NW * sizeof(double));
        memcpy(md->applied + LV_NW * b, applied, sizeof applied);
    }
    return -1;
}

/* Force at the COM (world) and torque (body frame) of the effects on a plain body. */
static void plain_loads(const body_ctx *c, const double *x, double *F, double *tau_b)
{
    double tau_w[3] = LV_SUM_START3;
    F[0] = F[1] = F[2] = LV_SUM_START;
    effect_sums(x, x + LV_STATE_V_W, c->m, c->prm + LV_PARAM_I_B, c->refs, c->n_refs, F, tau_w);
    lv_world_to_body(x + LV_STATE_Q, tau_w, tau_b);
}

/* Kick of the splitting: v and omega (q, p fixed) under the effects for time h (splitting_kick). One
   evaluation when the loads do not depend on v or omega (then exact); the explicit midpoint rule (two)
   with an effect that reads them (linear or angular damping, ...), which keeps the composition symmetric
   to second order. */
static void kick(const body_ctx *c, double *x, double h, int damped)
{
    const double *I = c->prm + LV_PARAM_I_B;
    double F[3], tb[3], xm[LV_STATE_SIZE];
    plain_loads(c, x, F, tb);
    if (damped) {
        memcpy(xm, x, sizeof xm);
        lv_splitting_kick(c->m, I, x + LV_STATE_V_W, x + LV_STATE_OMEGA_B, F, tb, LV_SPLIT_MIDPOINT * h,
                          xm + LV_STATE_V_W, xm + LV_STATE_OMEGA_B);
        plain_loads(c, xm, F, tb);
    }
    lv_splitting_kick(c->m, I, x + LV_STATE_V_W, x + LV_STATE_OMEGA_B, F, tb, h, x + LV_STATE_V_W, x + LV_STATE_OMEGA_B);
}

/* Solve I (w1 - w) + h w1 x (I w1) = h tau_b for w1 by Newton's method (implicit_gyro_newton: the derived
   residual, its SymPy Jacobian and the adjugate solve) to rounding, at most LV_GYRO_MAX_ITER iterations,
   starting from w1 = w. Solved exactly, the torque-free step never gains energy:
   E - E1 = (w - w1)^T I (w - w1) / 2 >= 0. Returns 1 when it converged: the last update met the stopping
   rule, or (an ill-conditioned solve stalls at rounding) is at most sqrt(LV_GYRO_ACCEPT_SQ) |w1|; 0 when
   the iteration wandered (no root near: the step is reported as a divergence, never returned). */
static int gyro_newton(const double *I, const double *w, const double *tau_b, double h, double *w1)
{
    double d[3], dd = 0.0, ww = 0.0;
    int it;
    w1[0] = w[0]; w1[1] = w[1]; w1[2] = w[2];
    for (it = 0; it < LV_GYRO_MAX_ITER; it++) {
        lv_implicit_gyro_newton(I, w, tau_b, h, w1, w1, d);
        dd = d[0] * d[0] + d[1] * d[1] + d[2] * d[2];
        ww = w1[0] * w1[0] + w1[1] * w1[1] + w1[2] * w1[2];
        /* |d| <= 1e-16 |w1| (or non-finite: caught by the caller) */
        if (!(dd > LV_GYRO_TOL_SQ * ww))
            return 1;
    }
    return !(dd > LV_GYRO_ACCEPT_SQ * ww);
}

/* One implicit_gyro step: loads at the start (explicit), w1 from gyro_newton, q <- q (x) exp(h w1 / 2)
   (quat_exp_step; unit by construction), then v += h F/m, p += h v (semi_implicit_translation).
   Returns 0 when the Newton solve did not converge (x then holds an unspecified state). */
static int gyro_step(const body_ctx *c, double *x, double h)
{
    double F[3] = LV_SUM_START3, tb[3] = LV_SUM_START3, w1[3];
    int ok;
    if (c->has) plain_loads(c, x, F, tb);
    ok = gyro_newton(c->prm + LV_PARAM_I_B, x + LV_STATE_OMEGA_B, tb, h, w1);
    lv_quat_exp_step(x + LV_STATE_Q, w1, h, x + LV_STATE_Q);
    memcpy(x + LV_STATE_OMEGA_B, w1, sizeof w1);
    lv_semi_implicit_translation(c->m, x + LV_STATE_P_W, x + LV_STATE_V_W, F, h, x + LV_STATE_P_W, x + LV_STATE_V_W);
    return ok;
}

/* symtop4's split of inertia I (symtop_score, symtop_leftover): the reference axis r (the smallest score, the first on
   ties: the intermediate principal axis), the A axis (the larger leftover coefficient |c_a| of the other two, the first
   on ties) and the B axis, I_r, c_a, c_b. */
typedef struct {
    int a, b;
    double I_r, c_a, c_b;
} symtop_split;

static void symtop_axes(const double *I, symtop_split *t)
{
    double score[3], c[3];
    int r = 0, i, j, k;
    lv_symtop_score(I, score);
    for (i = 1; i < 3; i++)
        if (score[i] < score[r]) r = i;
    t->I_r = I[r];
    lv_symtop_leftover(I, I[r], c);
    j = (r + 1) % 3;
    k = (r + 2) % 3;
    if (fabs(c[k]) > fabs(c[j])) { i = j; j = k; k = i; }
    t->a = j; t->b = k; t->c_a = c[j]; t->c_b = c[k];
}

/* The exact flow for time tau of 1/2 cf L_ax^2 on (q, L) (symtop_axis_flow_{x,y,z}), in place. */
static void symtop_axis(int ax, double cf, double *q, double *L, double tau)
{
    if (ax == 0)
        lv_symtop_axis_flow_x(q, L, cf, tau, q, L);
    else if (ax == 1)
        lv_symtop_axis_flow_y(q, L, cf, tau, q, L);
    else
        lv_symtop_axis_flow_z(q, L, cf, tau, q, L);
}

/* Flow f of a composition for time frac_f g on x (L: its body momentum while the program carries it): kick (the loads
   on v and omega), drift (p += tau v), momentum / rate (omega to L_b = I omega and back), strang (splitting_rotation),
   axis_x/y/z (principal-axis flows on L_b), top_a / top_b / top_b_nz (the symmetric-top split t's axis flows;
   top_b_nz skipped when c_b = 0) and sphere. */
static inline void composition_flow(const body_ctx *c, const symtop_split *t, const lv_flow *f, double *x, double *L,
                                    double g, int damped)
{
    const double *I = c->prm + LV_PARAM_I_B;
    double *q = x + LV_STATE_Q, *w = x + LV_STATE_OMEGA_B;
    const double tau = f->frac * g;
    switch (f->flow) {
    case LV_FLOW_KICK: kick(c, x, tau, damped); break;
    case LV_FLOW_DRIFT: lv_translation_drift(x + LV_STATE_P_W, x + LV_STATE_V_W, tau, x + LV_STATE_P_W); break;
    case LV_FLOW_MOMENTUM: lv_body_momentum(I, w, L); break;
    case LV_FLOW_RATE: lv_body_rate(I, L, w); break;
    case LV_FLOW_STRANG: lv_splitting_rotation(I, q, w, tau, q, w); break;
    case LV_FLOW_AXIS_X: lv_axis_flow_x(I, q, L, tau, q, L); break;
    case LV_FLOW_AXIS_Y: lv_axis_flow_y(I, q, L, tau, q, L); break;
    case LV_FLOW_AXIS_Z: lv_axis_flow_z(I, q, L, tau, q, L); break;
    case LV_FLOW_TOP_A: symtop_axis(t->a, t->c_a, q, L, tau); break;
    case LV_FLOW_TOP_B_NZ: if (t->c_b == 0.0) break; /* fall through */
    case LV_FLOW_TOP_B: symtop_axis(t->b, t->c_b, q, L, tau); break;
    case LV_FLOW_SPHERE: lv_sphere_flow(q, L, t->I_r, tau, q); break;
    }
}

/* One step of a composition m (generated/tableaux.h LV_COMPOSITIONS, derive/tableaux.py compositions()): a body with
   effects takes the stages gamma_i in turn, each m->kicked over g = gamma_i h; a body without effects m->free once
   over g = h (composition_flow). The NumPy backend's _composition, operation for operation. */
static inline void composition_step(const body_ctx *c, const symtop_split *t, const lv_composition *m, double *x,
                                    double h, int damped)
{
    double L[3] = {0.0, 0.0, 0.0};
    int i, k;
    if (!c->has) {
        LV_XS_UNROLL for (k = 0; k < m->n_free; k++) composition_flow(c, t, &m->free[k], x, L, h, damped);
        return;
    }
    for (i = 0; i < m->n_stages; i++) {
        const double g = m->gamma[i] * h;
        LV_XS_UNROLL for (k = 0; k < m->n_kicked; k++) composition_flow(c, t, &m->kicked[k], x, L, g, damped);
    }
}

/* composition_step with each registered integrator's program a constant (LV_INTEGRATORS: the printed registry; an
   integrator of another family has the empty program), so that the compiler lays the flows out in line. */
typedef void (*composition_fn)(const body_ctx *c, const symtop_split *t, double *x, double h, int damped);
#define LV_DEFINE_COMPOSITION(NAME, CODE)                                                                      \
    LV_FLATTEN static void composition_##NAME(const body_ctx *c, const symtop_split *t, double *x, double h,    \
                                              int damped)                                                       \
    {                                                                                                           \
        composition_step(c, t, &LV_COMPOSITIONS[CODE], x, h, damped);                                           \
    }
LV_INTEGRATORS(LV_DEFINE_COMPOSITION)
#define LV_COMPOSITION_ENTRY(NAME, CODE) [CODE] = composition_##NAME,
static const composition_fn LV_COMPOSITION_FNS[LV_INTEGRATOR_LAST + 1] = {LV_INTEGRATORS(LV_COMPOSITION_ENTRY)};

/* rk4_expmap's stage derivative k at ys (p, u, v, omega): the right-hand side at q0 (x) exp(u/2) (x itself at the
   first stage, u = 0), u' = rkmk_dexpinv(u, omega), the fourth slot held at 0. */
static void expmap_stage(const body_ctx *c, const double *x, const double *q0, const double *ys, int first, double *k)
{
    double xs[LV_STATE_SIZE];
    memcpy(xs, first ? x : ys, sizeof xs);
    if (!first) lv_quat_exp_step(q0, ys + LV_STATE_Q, 1.0, xs + LV_STATE_Q);
    body_rhs(xs, c->prm, c->refs, c->n_refs, c->flags, k);
    lv_rkmk_dexpinv(ys + LV_STATE_Q, ys + LV_STATE_OMEGA_B, k + LV_STATE_Q);
    k[LV_STATE_Q + 3] = 0.0;
}

/* One rk4_expmap step (RKMK4): the RK4 tableau on (p, u, v, omega) with u (the body rotation vector since
   the step's start, u0 = 0) kept in q's first three slots and the fourth held at 0. Stage s evaluates the
   right-hand side at the attitude q0 (x) exp(u/2) (quat_exp_step with h = 1) and u' = rkmk_dexpinv(u, omega);
   the step ends with q = q0 (x) exp(u1/2), unit to rounding. The same operations in the same order as the
   NumPy backend's _rk4_expmap (bitwise equal results). */
static void rk4_expmap_step(const body_ctx *c, double *x, double h)
{
    double y[LV_STATE_SIZE], ys[LV_STATE_SIZE], k[LV_STATE_SIZE], acc[LV_STATE_SIZE], q0[4];
    int i;
    memcpy(q0, x + LV_STATE_Q, sizeof q0);
    memcpy(y, x, sizeof y);
    for (i = 0; i < 4; i++) y[LV_STATE_Q + i] = 0.0;
#define EXPMAP_RHS(in, out) expmap_stage(c, x, q0, in, (const double *)(in) == (const double *)y, out)
#define EXPMAP_FOR(stmt) for (i = 0; i < LV_STATE_SIZE; i++) stmt
#define EXPMAP_AT(v) v[i]
    LV_RK4_STEP(double, EXPMAP_RHS, EXPMAP_FOR, EXPMAP_AT, h, y, y, k, acc, ys);
#undef EXPMAP_RHS
#undef EXPMAP_FOR
#undef EXPMAP_AT
    memcpy(x, y, sizeof y);
    lv_quat_exp_step(q0, y + LV_STATE_Q, 1.0, x + LV_STATE_Q);
}

/* Advance plain body b by n_steps of a plain-only integrator, by its family (LV_INTEGRATOR_IS_*): a composition
   (composition_step on its printed program), RK4 in exponential coordinates (rk4_expmap_step) or the implicit
   gyroscopic step (gyro_step); contract as advance_block with n = 1, and *why = LV_DIVERGED (non-finite) or
   LV_NO_ROOT (implicit_gyro's Newton solve did not converge). */
static long advance_structured(double *state, const double *params, long b, const lv_effect_index *ix,
                               int integrator, int normalize, double dt, long n_steps, double *last, int *why)
{
    body_ctx c;
    symtop_split t;
    double x[LV_STATE_SIZE], xn[LV_STATE_SIZE];
    int damped, i;
    long s;
    ctx_init(&c, params, b, NULL, ix);
    damped = (c.flags & (LV_EFFECT_USES_V | LV_EFFECT_USES_OMEGA)) != 0;
    symtop_axes(c.prm + LV_PARAM_I_B, &t);
    memcpy(x, state + b * LV_STATE_SIZE, sizeof x);
    for (s = 0; s < n_steps; s++) {
        memcpy(xn, x, sizeof x);
        if (LV_INTEGRATOR_IS_COMPOSITION(integrator))
            LV_COMPOSITION_FNS[integrator](&c, &t, xn, dt, damped);
        else if (LV_INTEGRATOR_IS_LIE_GROUP_RK(integrator))
            rk4_expmap_step(&c, xn, dt);
        else if (!gyro_step(&c, xn, dt)) {
            *why = LV_NO_ROOT;
            memcpy(last, x, sizeof x);
            return s;
        }
        if (normalize) lv_quat_normalize(xn + LV_STATE_Q, xn + LV_STATE_Q);
        for (i = 0; i < LV_STATE_SIZE; i++) {
            if (!isfinite(xn[i])) {
                *why = LV_DIVERGED;
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

/* What every share of a call's bodies over threads reports, the first member of each *_share struct: its
   earliest failure so far (limit, best: started from the call's) and LV_DIVERGED once it has one. */
typedef struct {
    long limit, best;
    int status;
} lv_share_head;

typedef void (*lv_share_fn)(void *share);

#if LV_HAVE_THREADS
typedef struct {
    lv_share_fn run;
    void *share;
} lv_share_job;

static void *share_job_thread(void *arg)
{
    const lv_share_job *job = (const lv_share_job *)arg;
    job->run(job->share);
    return NULL;
}
#endif

/* Runs the n_sh shares (an array of structs of `size` bytes, each starting with an lv_share_head) with run:
   the calling thread runs the first, a thread each of the others (one that cannot be started has its share
   run here). Shares touch disjoint bodies, so merging their failures in order with `earlier` gives the
   earliest step, then the lowest body, over all of them. Returns LV_DIVERGED (with *limit, *best updated) or
   LV_OK. */
static int run_shares(void *shares, size_t size, int n_sh, lv_share_fn run, long *limit, long *best)
{
    char *base = (char *)shares;
    int t, status = LV_OK;
#if LV_HAVE_THREADS
    pthread_t tid[LV_MAX_THREADS];
    int started[LV_MAX_THREADS];
    lv_share_job job[LV_MAX_THREADS];
    for (t = 1; t < n_sh; t++) {
        job[t].run = run;
        job[t].share = base + (size_t)t * size;
        started[t] = pthread_create(&tid[t], NULL, share_job_thread, &job[t]) == 0;
    }
    run(base);
    for (t = 1; t < n_sh; t++) {
        if (started[t]) pthread_join(tid[t], NULL);
        else run(base + (size_t)t * size);
    }
#else
    for (t = 0; t < n_sh; t++) run(base + (size_t)t * size);
#endif
    for (t = 0; t < n_sh; t++) {
        const lv_share_head *h = (const lv_share_head *)(base + (size_t)t * size);
        if (h->status != LV_DIVERGED || !earlier(h->limit, h->best, *limit, *best)) continue;
        *limit = h->limit;
        *best = h->best;
        status = LV_DIVERGED;
    }
    return status;
}

/* RK4 on up to LV_BLOCK plain bodies of ids with effects, in lockstep, all of one right-hand side kind
   (LV_RHS_TORQUE or LV_RHS_FULL), one copy per instruction set (LV_ISA_COPIES; the same IEEE operations in each).
   Every call below has constant arguments and is inlined with its kernels and the effect dispatch (flatten), so
   each block size and kind compiles to its own loop. */
typedef long (*lv_forced_fn)(double *state, const double *params, const long *ids, int n, const lv_effect_index *ix,
                             int kind, int normalize, double dt, long n_steps, int *fail_j, double last[][LV_STATE_SIZE]);
#define LV_DEFINE_FORCED(SUFFIX, ATTR)                                                                  \
    ATTR LV_FLATTEN static long advance_forced_rk4_##SUFFIX(double *state, const double *params, const long *ids, \
        int n, const lv_effect_index *ix, int kind, int normalize, double dt, long n_steps, int *fail_j, \
        double last[][LV_STATE_SIZE])                                                                   \
    {                                                                                                   \
        switch (kind) {                                                                                 \
        case LV_RHS_TORQUE: return LV_FORCED(LV_RHS_TORQUE, 0);                                         \
        case LV_RHS_TORQUE + LV_RHS_CONSTANT: return LV_FORCED(LV_RHS_TORQUE, 1);                       \
        case LV_RHS_FULL + LV_RHS_CONSTANT: return LV_FORCED(LV_RHS_FULL, 1);                           \
        case LV_RHS_FORCE: return LV_FORCED(LV_RHS_FORCE, 0);                                           \
        case LV_RHS_FORCE + LV_RHS_CONSTANT: return LV_FORCED(LV_RHS_FORCE, 1);                         \
        case LV_RHS_BODY: return LV_FORCED(LV_RHS_BODY, 0);                                             \
        case LV_RHS_BODY_F: return LV_FORCED(LV_RHS_BODY_F, 0);                                         \
        case LV_RHS_FORCE + LV_RHS_SPLIT: return LV_FORCED(LV_RHS_FORCE + LV_RHS_SPLIT, 0);             \
        case LV_RHS_BODY + LV_RHS_SPLIT: return LV_FORCED(LV_RHS_BODY + LV_RHS_SPLIT, 0);               \
        case LV_RHS_BODY_F + LV_RHS_SPLIT: return LV_FORCED(LV_RHS_BODY_F + LV_RHS_SPLIT, 0);           \
        default: return LV_FORCED(LV_RHS_FULL, 0);                                                      \
        }                                                                                               \
    }
#define LV_FORCED(KIND, CONST)                                                                          \
    (n == LV_BLOCK ? advance_free_rk4(state, params, ids, LV_BLOCK, ix, KIND, CONST, normalize, dt, n_steps, fail_j, last) \
     : n == 1      ? advance_free_rk4(state, params, ids, 1, ix, KIND, CONST, normalize, dt, n_steps, fail_j, last)        \
                   : advance_free_rk4(state, params, ids, n, ix, KIND, CONST, normalize, dt, n_steps, fail_j, last))
LV_ISA_COPIES(LV_DEFINE_FORCED)
#undef LV_FORCED
#undef LV_DEFINE_FORCED

/* RK4 on up to LV_BLOCK plain bodies of ids in lockstep, all of one right-hand side kind (LV_RHS_*). The
   torque-free calls have constant block sizes and normalize flags, so the compiler specializes them, and
   flatten inlines the generated right-hand side into each loop (GCC 12 at -O3 kept 24 out-of-line calls of
   lv_rigid_body_rhs_free in these loops without it: ~2x a torque-free step). */
LV_FLATTEN static long advance_rk4_group(double *state, const double *params, const long *ids, int n, const lv_effect_index *ix,
                              int kind, int normalize, double dt, long n_steps, int isa, int *fail_j,
                              double last[][LV_STATE_SIZE])
{
    if (kind != LV_RHS_FREE) {
        const lv_forced_fn fn = LV_ISA_PICK(isa, advance_forced_rk4);
        return fn(state, params, ids, n, ix, kind, normalize, dt, n_steps, fail_j, last);
    }
    if (n == LV_BLOCK)
        return normalize ? advance_free_rk4(state, params, ids, LV_BLOCK, ix, LV_RHS_FREE, 0, 1, dt, n_steps, fail_j, last)
                         : advance_free_rk4(state, params, ids, LV_BLOCK, ix, LV_RHS_FREE, 0, 0, dt, n_steps, fail_j, last);
    if (n == 1)
        return normalize ? advance_free_rk4(state, params, ids, 1, ix, LV_RHS_FREE, 0, 1, dt, n_steps, fail_j, last)
                         : advance_free_rk4(state, params, ids, 1, ix, LV_RHS_FREE, 0, 0, dt, n_steps, fail_j, last);
    return advance_free_rk4(state, params, ids, n, ix, LV_RHS_FREE, 0, normalize, dt, n_steps, fail_j, last);
}

/* Up to LV_BLOCK plain bodies of ids (ascending) in lockstep, all of one right-hand side kind (LV_RHS_*):
   RK4 on the fast path, the other integrators on the generic block (constant block sizes let the
   compiler specialize it; flatten inlines the kernels and the effect dispatch into each). */
LV_FLATTEN static long advance_group(double *state, const double *params, const long *ids, int n, const lv_effect_index *ix,
                          int kind, int integrator, int normalize, double dt, long n_steps, int isa, int *fail_j,
                          double last[][LV_STATE_SIZE])
{
    if (integrator == LV_PATH_RK4)
        return advance_rk4_group(state, params, ids, n, ix, kind, normalize, dt, n_steps, isa, fail_j, last);
    if (n == LV_BLOCK)
        return advance_block(state, params, ids, LV_BLOCK, ix, integrator, normalize, dt, n_steps, fail_j, last);
    if (n == 1)
        return advance_block(state, params, ids, 1, ix, integrator, normalize, dt, n_steps, fail_j, last);
    return advance_block(state, params, ids, n, ix, integrator, normalize, dt, n_steps, fail_j, last);
}

/* The right-hand side kind of plain body b (LV_RHS_*), plus LV_RHS_CONSTANT when it has effects and
   they are all constant (effects_constant: such a group takes the SIMD tiles with effects, or the
   scalar blocks with its sums taken once per call). */
/* Whether plain body b's effects are all built-in and none couples translation and rotation (LV_EFFECT_COUPLED). */
static int effects_decoupled(const lv_effect_index *ix, long b)
{
    long k;
    if (ix->flags[b] & LV_EFFECT_COUPLED) return 0;
    for (k = ix->start[b]; k < ix->start[b + 1]; k++)
        if (ix->refs[k].user != NULL) return 0;
    return 1;
}

static int rhs_kind(const lv_effect_index *ix, long b)
{
    const int cls = rhs_class(ix->start[b + 1] - ix->start[b], ix->flags[b]);
    if (cls != LV_RHS_FREE && cls < LV_RHS_BODY && effects_constant(ix, b)) return cls + LV_RHS_CONSTANT;
    return LV_SPLIT_BY_CLASS[cls] != 0 && effects_decoupled(ix, b) ? cls + LV_RHS_SPLIT : cls;
}

/* ---- the SoA tiles of one call, over threads ---------------------------------------------------

   One share of the torque-free tiles: bodies list[0 .. count-1] (ascending), stepped tile by tile, each
   only as far as the share's own failure so far (limit, best; started from the call's) can still be
   beaten. Shares touch disjoint bodies, so they run on threads with no shared writes; merging their
   failures in order with `earlier` gives the earliest step, then the lowest body, over all of them: the
   same report and the same failing body's state as one share (the other bodies' rows are unspecified
   on failure anyway, lv_simulate's contract), and bitwise the same states on success. */
typedef struct {
    lv_share_head head; /* first: run_shares reads it */
    double *state;
    const double *params;
    const long *list;
    long count, n_steps;
    lv_tile_fn tile;
    const lv_effect_index *ix; /* NULL: torque-free tiles; else the constant effects' index */
    double dt;
} soa_share;

static void soa_share_run(void *arg)
{
    soa_share *const sh = (soa_share *)arg;
    double last[1][LV_STATE_SIZE];
    long k, s, lim;
    int n, j;
    for (k = 0; k < sh->count; k += n) {
        n = (int)(sh->count - k < LV_TILE ? sh->count - k : LV_TILE);
        lim = run_limit(sh->list[k], sh->head.limit, sh->head.best, sh->n_steps);
        if (lim <= 0) continue;
        s = advance_free_soa(sh->state, sh->params, sh->list + k, n, sh->tile, sh->ix, sh->dt, lim, &j, last);
        /* the tile stops at its first failing step, j its lowest failing body there (lockstep) */
        if (s < 0 || !earlier(s, sh->list[k + j], sh->head.limit, sh->head.best)) continue;
        memcpy(sh->state + sh->list[k + j] * LV_STATE_SIZE, last[0], sizeof last[0]);
        sh->head.limit = s;
        sh->head.best = sh->list[k + j];
        sh->head.status = LV_DIVERGED;
    }
}


/* The plain bodies list[0 .. count-1] on SIMD tiles (torque-free: ix NULL; else all with constant
   effects, see advance_free_soa), split into `threads` shares of whole tiles (the calling thread runs the
   first; a thread that cannot be started has its share run here). Returns LV_DIVERGED (with *limit,
   *best updated as in advance_fixed) or LV_OK. */
static int advance_soa_threads(double *state, const double *params, const long *list, long count, lv_tile_fn tile,
                               const lv_effect_index *ix, double dt, long n_steps, int threads, long *limit,
                               long *best)
{
    soa_share sh[LV_MAX_THREADS];
    const long tiles = (count + LV_TILE - 1) / LV_TILE;
    long t0 = 0;
    int t, n_sh;
    n_sh = threads < 1 ? 1 : (threads > LV_MAX_THREADS ? LV_MAX_THREADS : threads);
    if (n_sh > tiles) n_sh = (int)tiles;
    for (t = 0; t < n_sh; t++) { /* share t: tiles [t0, t1) */
        const long t1 = tiles * (t + 1) / n_sh;
        const long b0 = t0 * LV_TILE, b1 = t1 * LV_TILE < count ? t1 * LV_TILE : count;
        sh[t].state = state;
        sh[t].params = params;
        sh[t].list = list + b0;
        sh[t].count = b1 - b0;
        sh[t].n_steps = n_steps;
        sh[t].head.limit = *limit;
        sh[t].head.best = *best;
        sh[t].tile = tile;
        sh[t].ix = ix;
        sh[t].dt = dt;
        sh[t].head.status = LV_OK;
        t0 = t1;
    }
    return run_shares(sh, sizeof sh[0], n_sh, soa_share_run, limit, best);
}

/* ---- bodies with a joint or wheels, over threads ----------------------------------------------

   One share of the model bodies: list[0 .. count-1] (ascending), each advanced by advance_model_body only as
   far as the share's own failure so far (limit, best; started from the call's) can still be beaten, as
   soa_share_run does for tiles. Shares touch disjoint bodies (their state, Omega and applied rows), so they
   run on threads with no shared writes, and merging their failures with `earlier` gives the report of one
   thread; each body's arithmetic does not depend on the split, so the states are bitwise those of one
   thread. */
typedef struct {
    lv_share_head head; /* first: run_shares reads it */
    double *state;
    const double *params;
    const lv_models *md;
    const lv_effect_index *ix;
    const long *list;
    long count, n_steps;
    int integrator, isa, normalize; /* isa: the model tiles' instruction set (mtile_share_run) */
    double dt;
} model_share;

static void model_share_run(void *arg)
{
    model_share *const sh = (model_share *)arg;
    double lastm[LV_XS_SIZE];
    long k, s, lim, b;
    for (k = 0; k < sh->count; k++) {
        b = sh->list[k];
        lim = run_limit(b, sh->head.limit, sh->head.best, sh->n_steps);
        if (lim <= 0) continue;
        s = advance_model_body(sh->state, sh->params, b, sh->md, sh->ix, sh->integrator, sh->normalize, sh->dt, lim,
                               lastm);
        if (s < 0 || !earlier(s, b, sh->head.limit, sh->head.best)) continue;
        memcpy(sh->state + b * LV_STATE_SIZE, lastm, LV_STATE_SIZE * sizeof(double));
        memcpy(sh->md->Omega + LV_NW * b, lastm + LV_XS_OMEGA, LV_NW * sizeof(double));
        sh->head.limit = s;
        sh->head.best = b;
        sh->head.status = LV_DIVERGED;
    }
}


/* Below this many body-steps per thread a call's model bodies stay on the calling thread (starting a thread
   costs about as much as ~100 body-steps). */
#define LV_MODEL_THREAD_WORK 512

/* The model bodies list[0 .. count-1] (ascending), split into up to `threads` shares of consecutive bodies, whole
   units of `unit` bodies each (1, or a model tile: LV_MTILE), no more shares than the work pays for; run steps a
   share (model_share_run, or mtile_share_run on tiles of isa). The calling thread runs the first share; a thread
   that cannot be started has its share run here. Returns LV_DIVERGED (with *limit, *best updated as in
   advance_fixed) or LV_OK. */
static int advance_models_threads(double *state, const double *params, const lv_models *md, const lv_effect_index *ix,
                                  const long *list, long count, long unit, lv_share_fn run, int integrator, int isa,
                                  int normalize, double dt, long n_steps, int threads, long *limit, long *best)
{
    model_share sh[LV_MAX_THREADS];
    const long units = (count + unit - 1) / unit;
    long u0 = 0, most;
    int t, n_sh;
    n_sh = threads < 1 ? 1 : (threads > LV_MAX_THREADS ? LV_MAX_THREADS : threads);
    most = count * n_steps / LV_MODEL_THREAD_WORK; /* shares the work pays for */
    if (most < n_sh) n_sh = most < 1 ? 1 : (int)most;
    if (n_sh > units) n_sh = units < 1 ? 1 : (int)units;
    for (t = 0; t < n_sh; t++) { /* share t: units [u0, u1) */
        const long u1 = units * (t + 1) / n_sh;
        const long b0 = u0 * unit, b1 = u1 * unit < count ? u1 * unit : count;
        sh[t].state = state;
        sh[t].params = params;
        sh[t].md = md;
        sh[t].ix = ix;
        sh[t].list = list + b0;
        sh[t].count = b1 - b0;
        sh[t].n_steps = n_steps;
        sh[t].head.limit = *limit;
        sh[t].head.best = *best;
        sh[t].integrator = integrator;
        sh[t].isa = isa;
        sh[t].normalize = normalize;
        sh[t].dt = dt;
        sh[t].head.status = LV_OK;
        u0 = u1;
    }
    return run_shares(sh, sizeof sh[0], n_sh, run, limit, best);
}

static int lv_threads_current = 1;

int lv_threads_get(void)
{
    return lv_threads_current;
}

int lv_threads_set(int threads)
{
#if LV_HAVE_THREADS
    lv_threads_current = threads < 1 ? 1 : (threads > LV_MAX_THREADS ? LV_MAX_THREADS : threads);
#else
    (void)threads;
    lv_threads_current = 1;
#endif
    return lv_threads_current;
}

#include "model_simd.h"

/* advance_fixed's order of the nb bodies into ids (nb): the model bodies (ascending) first, then the plain ones grouped
   by class (rhs_kind), ascending within each; count[cls] the plain bodies of class cls, *n_models the model bodies. It
   reads the index and the rows' kinds only, so a caller's cache keeps it with the index (ids_for_call). */
static void ids_build(const lv_effect_index *ix, const lv_models *models, long nb, long *ids, long *count,
                      long *n_models)
{
    long b, k, first[LV_RHS_CLASSES];
    int cls;
    *n_models = 0;
    for (cls = 0; cls < LV_RHS_CLASSES; cls++) count[cls] = 0;
    for (b = 0; b < nb; b++) {
        if (models != NULL && (int)models->rows[b * LV_MODEL_SIZE + LV_MODEL_KIND] != 0) ++*n_models;
        else count[rhs_kind(ix, b)]++;
    }
    first[0] = *n_models;
    for (cls = 1; cls < LV_RHS_CLASSES; cls++) first[cls] = first[cls - 1] + count[cls - 1];
    for (b = 0, k = 0; b < nb; b++) {
        if (models != NULL && (int)models->rows[b * LV_MODEL_SIZE + LV_MODEL_KIND] != 0) ids[k++] = b;
        else ids[first[rhs_kind(ix, b)]++] = b;
    }
}

/* The order of the bodies for a call (ids_build) into count, *n_models: the one cache keeps with the call's index
   (kept: the index is c's, index_for_call) when it has one, else built, and kept there when the index is; *owned 1
   when the caller frees the returned ids. A kept order holds a copy of its model bodies' part after its nb + 1
   entries, put back at each call (advance_models_grouped reorders that part in place). NULL: out of memory. */
static long *ids_for_call(lv_model_cache *c, int kept, const lv_effect_index *ix, const lv_models *models, long nb,
                          long *count, long *n_models, int *owned)
{
    lv_index_keep *const k = kept && c != NULL ? c->index : NULL;
    long *ids;
    *owned = 0;
    if (k != NULL && k->ids != NULL) {
        memcpy(count, k->count, sizeof k->count);
        *n_models = k->n_models;
        memcpy(k->ids, k->ids + nb + 1, (size_t)k->n_models * sizeof(long));
        return k->ids;
    }
    ids = (long *)malloc(((size_t)nb + 1) * sizeof(long));
    if (ids == NULL) return NULL;
    ids_build(ix, models, nb, ids, count, n_models);
    if (k != NULL && *n_models > 0) {   /* room for the model part's copy (else not kept: built again next call) */
        long *grown = (long *)realloc(ids, ((size_t)nb + 1 + (size_t)*n_models) * sizeof(long));
        if (grown == NULL) {
            *owned = 1;
            return ids;
        }
        ids = grown;
        memcpy(ids + nb + 1, ids, (size_t)*n_models * sizeof(long));
    }
    if (k == NULL) {
        *owned = 1;
        return ids;
    }
    k->ids = ids;
    memcpy(k->count, count, sizeof k->count);
    k->n_models = *n_models;
    return ids;
}

/* euler, semi-implicit Euler, rk4 over every body. Bodies with a joint or wheels are stepped one by one
   (shared over `threads`, see advance_models_threads), except, under RK4 with SIMD on, one group of jointed
   wheel bodies with the same built-in effects, on model tiles (advance_models_grouped, csrc/model_simd.h); plain bodies in lockstep blocks gathered by their work (rhs_kind): those no effect acts on together
   (RK4: the torque-free fast path), those with effects by kind, so a plain body never leaves its path
   because of a neighbour. ids, count, n_models: the order of the bodies (ids_build; advance_models_grouped reorders
   the model bodies' part). Returns the status; *limit, *best as in lv_simulate. */
static int advance_fixed(double *state, const double *params, const lv_effect_index *ix,
                         const lv_models *models, int integrator, int normalize, double dt, long n_steps,
                         int isa, int threads, long *ids, const long *count, long n_models, long *limit,
                         long *best)
{
    double last[LV_BLOCK][LV_STATE_SIZE];
    long k, s, lim, first[LV_RHS_CLASSES];
    int j, n, cls, status = LV_OK;
    first[0] = n_models + count[0];   /* (each class's list ends at first[cls]) */
    for (cls = 1; cls < LV_RHS_CLASSES; cls++) first[cls] = first[cls - 1] + count[cls];
    if (n_models > 0 && advance_models_grouped(state, params, models, ix, ids, n_models, integrator, isa, normalize,
                                               dt, n_steps, threads, limit, best) == LV_DIVERGED)
        status = LV_DIVERGED;
    for (cls = 0; cls < LV_RHS_CLASSES; cls++) {
        const long *list = ids + first[cls] - count[cls];
        /* RK4 groups of LV_TILE_MIN bodies or more on SIMD tiles (csrc/batch_simd.h), split over threads
           when asked: torque-free ones, those with constant effects (their sums are then evaluated
           once per call, not at every stage), and those whose effects read the state when they all have the
           same built-in effects (effects_tileable: the effect tiles); smaller such groups get the same on the scalar blocks (one
           body with one applied torque: 1.57-1.69x a plain body there, 1.74x on a 1-body tile; bench
           per-body effects, loaded machine) */
        if ((cls == LV_RHS_FREE || rhs_constant(cls) || effects_tileable(ix, list, count[cls], isa))
            && count[cls] >= LV_TILE_MIN && integrator == LV_PATH_RK4 && isa != LV_ISA_SCALAR) {
            if (advance_soa_threads(state, params, list, count[cls], tile_rk4_fn(isa, normalize, cls, count[cls]),
                                    cls == LV_RHS_FREE ? NULL : ix, dt, n_steps, threads, limit, best) == LV_DIVERGED)
                status = LV_DIVERGED;
            continue;
        }
        for (k = 0; k < count[cls]; k += n) {
            n = (int)(count[cls] - k < LV_BLOCK ? count[cls] - k : LV_BLOCK);
            lim = run_limit(list[k], *limit, *best, n_steps);
            if (lim <= 0) continue;
            s = advance_group(state, params, list + k, n, ix, cls, integrator, normalize, dt, lim, isa, &j, last);
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

/* The printed tableau of a built-in explicit RK that takes no fixed-step path (tableaux.h LV_TABLEAU_STEPPED), else
   NULL: such an integrator steps on the tableau stepper, as a user's tableau does. */
static const lv_tableau *builtin_tableau(int integrator)
{
#define LV_STEPPED_TABLEAU(CODE, S, A, B_NUM, B_DEN)                   \
    if (integrator == (CODE)) {                                        \
        static const lv_tableau tab = {(S), (A), (B_NUM), (B_DEN)};    \
        return &tab;                                                   \
    }
    LV_TABLEAU_STEPPED(LV_STEPPED_TABLEAU)
#undef LV_STEPPED_TABLEAU
    (void)integrator;
    return NULL;
}

int lv_simulate(double *state, const double *params, long nb,
                const double *effects, long ne, long row_size, const lv_user_effects *user,
                const lv_models *models, lv_model_cache *cache, int integrator, int normalize, double dt,
                long n_steps, const lv_adaptive *adaptive, const lv_tableau *tableau, long *fail_step, long *fail_body)
{
    lv_effect_index ix;
    double last[LV_BLOCK][LV_STATE_SIZE];
    long b, s, limit = n_steps, best_body = -1, *ids = NULL;
    int status = LV_OK, ix_owned = 1, ids_owned = 0;
    if (models != NULL) cache = models->cache;
    if (tableau != NULL && (tableau->s < 1 || tableau->s > LV_TABLEAU_MAX_STAGES || !(tableau->b_den > 0.0)))
        return LV_BAD_ARGUMENT;
    if (tableau == NULL && (integrator < 0 || integrator > LV_INTEGRATOR_LAST)) return LV_BAD_ARGUMENT;
    if (tableau == NULL) tableau = builtin_tableau(integrator);
    if (ne > 0 && row_size < LV_EFFECT_ROW_PARAMS) return LV_BAD_ARGUMENT;
    if (tableau == NULL && LV_INTEGRATOR_ADAPTIVE(integrator) && (adaptive == NULL || !(adaptive->rtol > 0.0) || !(adaptive->atol >= 0.0)))
        return LV_BAD_ARGUMENT;
    if (models != NULL)   /* a kind the step loop knows; the PLAIN_ONLY integrators step plain bodies only */
        for (b = 0; b < nb; b++) {
            const double kind = models->rows[b * LV_MODEL_SIZE + LV_MODEL_KIND];
            if (!lv_kind_valid(kind) || (kind != 0 && tableau == NULL && LV_INTEGRATOR_PLAIN_ONLY(integrator)))
                return LV_BAD_ARGUMENT;
        }
    status = index_for_call(&ix, &ix_owned, cache, effects, ne, row_size, nb, user, fail_step);
    if (status != LV_OK) return status;
    if (tableau != NULL || LV_INTEGRATOR_ADAPTIVE(integrator)) {
        for (b = 0; b < nb && limit > 0; b++) {
            double lastx[LV_XS_SIZE];
            int why = LV_DIVERGED;
            s = advance_rk(state, params, b, models, &ix, tableau, tableau != NULL ? NULL : adaptive, normalize, dt, limit,
                           &why, lastx);
            if (s < 0) continue;
            memcpy(state + b * LV_STATE_SIZE, lastx, LV_STATE_SIZE * sizeof(double));
            if (models != NULL && (int)models->rows[b * LV_MODEL_SIZE + LV_MODEL_KIND] != 0)
                memcpy(models->Omega + LV_NW * b, lastx + LV_XS_OMEGA, LV_NW * sizeof(double));
            limit = s;
            best_body = b;
            status = why;
        }
    } else if (LV_INTEGRATOR_PLAIN_ONLY(integrator)) {
        for (b = 0; b < nb && limit > 0; b++) {
            int why = LV_DIVERGED;
            s = advance_structured(state, params, b, &ix, integrator, normalize, dt, limit, last[0], &why);
            if (s < 0) continue;
            memcpy(state + b * LV_STATE_SIZE, last[0], sizeof last[0]);
            limit = s;
            best_body = b;
            status = why;
        }
    } else {
        long count[LV_RHS_CLASSES], n_models;
        model_cache_sync(models, nb);
        ids = ids_for_call(cache, !ix_owned, &ix, models, nb, count, &n_models, &ids_owned);
        status = ids == NULL ? LV_NO_MEMORY
                             : advance_fixed(state, params, &ix, models, integrator, normalize, dt, n_steps,
                                             lv_isa_get(), lv_threads_get(), ids, count, n_models, &limit, &best_body);
        if (ids_owned) free(ids);
    }
    if (ix_owned) index_free(&ix);
    if (status != LV_OK && status != LV_NO_MEMORY) {
        *fail_step = limit;
        *fail_body = best_body;
    }
    return status;
}
