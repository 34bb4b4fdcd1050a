/* LavenderSim C stepping loop: advances many independent rigid bodies by many steps.
   Plain C99, no Python; uses only the generated kernels and effect dispatch (generated/kernels.h). */
#ifndef LAVENDERSIM_STEP_H
#define LAVENDERSIM_STEP_H

/* The state row (LV_STATE_*: p_w[3], q[4] (x,y,z,w), v_w[3], omega_b[3]), the params row (LV_PARAM_*: m,
   I_x, I_y, I_z), the per-body model row (LV_MODEL_*) and the extended state [x, Omega] (LV_XS_*) are
   declared in derive/layout.py and printed as named offsets in generated/layout.h. */
#include <stdint.h>

#include "layout.h"
#include "kernels.h"
#include "tableaux.h"

/* Wheel slots (rates, motor commands, applied torques) per model body: the XS layout's Omega length,
   WHEELS_MAX of derive/layout.py. Every wheeled body (LV_KIND_WHEELS) is stepped by the one N-wheel model
   (LV_WHEELS_BODY_RHS, LV_WHEELS_MOTOR: the printed wheels<WHEELS_MAX> kernels) on its row's axes A_b, the
   unused slots padded (zero axis, J = 1, at rest: derive/wheel_layout.py proves they change nothing); the
   default layout, three wheels on the body axes, is A_b = [I | 0]. */
#define LV_NW LV_XS_OMEGA_LEN
typedef char lv_nw_is_wheels_max[LV_NW == LV_WHEELS_MAX && LV_MODEL_A_B_LEN % LV_NW == 0 ? 1 : -1];

/* Whether a model row's kind is one the step loop knows: a bit set of JOINT and WHEELS. */
static inline int lv_kind_valid(double kind)
{
    const int k = (int)kind;
    return kind >= 0.0 && kind <= (double)(LV_KIND_JOINT | LV_KIND_WHEELS) && kind == (double)k;
}

/* The effect table, its row layout (LV_EFFECT_ROW_*), the built-in codes and their dispatch
   (lv_effect_apply) are generated from the effect declarations (generated/kernels.h). User effects are
   compiled apart and reach the stepping loop through this table: entry i serves code
   LV_EFFECT_USER_BASE + i (fn NULL: no such code). */
/* A user effect's fused tile (derive/effect_fuse_user.py, in the user's library): n_steps RK4 steps of the m lanes of a
   tile whose bodies' one effect is that effect, its function inlined into the plain tile's lane loop: T the states
   (LV_STATE_SIZE rows), J the Euler coefficients (LV_EULER_SIZE rows), p the effect's parameters (a row each), m_row
   the masses, I_b the principal moments (3 rows); bitwise the effect tile's stage passes. */
typedef void (*lv_user_fused_fn)(double (*T)[LV_EFFECT_TILE], const double (*J)[LV_EFFECT_TILE],
                                 const double (*p)[LV_EFFECT_TILE], const double *m_row,
                                 const double (*I_b)[LV_EFFECT_TILE], long m, double dt, long n_steps);

typedef struct {
    lv_effect_fn fn;  /* adds the effect's force and torque (the lv_effect_fn convention) */
    int n_params;     /* parameters it reads from its row */
    int flags;        /* LV_EFFECT_USES_*, LV_EFFECT_FORCE, LV_EFFECT_TORQUE_W / _B */
    lv_effect_tile_fn tile[3]; /* its tile form per instruction set LV_ISA_BASE .. LV_ISA_AVX512 (NULL: none) */
    lv_effect_fn fn_b; /* LV_EFFECT_TORQUE_B: its body-frame form (the torque added in the body frame, as
                          lv_effect_apply_b adds a built-in's), else NULL */
    lv_effect_tile_fn tile_b[3]; /* the body-frame form's tile forms (NULL: none) */
    lv_user_fused_fn fused[2][3]; /* its fused tiles (q raw / normalized x LV_ISA_BASE .. LV_ISA_AVX512; NULL: none) */
} lv_user_effect;

/* The user-effect table's columns: [function address, n_params, flags], then optionally the tile forms' addresses
   (base, avx2, avx512; 0: none), then optionally the body-frame form's address and its tile forms' (0: none), then
   optionally the fused tiles' (q raw: base, avx2, avx512; q normalized: the same; 0: none). lv_user_table_row reads
   row r of a table of `cols` (3, 6, 10 or 16) int64 columns. A row flagged LV_EFFECT_TORQUE_B without a body-frame
   form is read as a world-torque effect (LV_EFFECT_TORQUE_W, no fused tile): never a torque lost. */
static inline void lv_user_table_row(const long long *r, int cols, lv_user_effect *u)
{
    int k;
    u->fn = (lv_effect_fn)(uintptr_t)r[0];
    u->n_params = (int)r[1];
    u->flags = (int)r[2];
    for (k = 0; k < 3; k++) u->tile[k] = cols >= 6 ? (lv_effect_tile_fn)(uintptr_t)r[3 + k] : NULL;
    u->fn_b = cols >= 10 ? (lv_effect_fn)(uintptr_t)r[6] : NULL;
    for (k = 0; k < 3; k++) u->tile_b[k] = cols >= 10 ? (lv_effect_tile_fn)(uintptr_t)r[7 + k] : NULL;
    for (k = 0; k < 6; k++) u->fused[k / 3][k % 3] = cols >= 16 ? (lv_user_fused_fn)(uintptr_t)r[10 + k] : NULL;
    if ((u->flags & LV_EFFECT_TORQUE_B) && u->fn_b == NULL) {
        u->flags = (u->flags & ~LV_EFFECT_TORQUE_B) | LV_EFFECT_TORQUE_W;
        for (k = 0; k < 6; k++) u->fused[k / 3][k % 3] = NULL;
    }
}

typedef struct {
    const lv_user_effect *entries;
    long n;
} lv_user_effects;

/* The model row (LV_MODEL_SIZE), per body: kind, I_p[9] (about the pivot, body frame, row-major), r_b[3]
   (pivot -> COM, body frame), anchor_w[3], J[LV_NW], torque_limit, speed_limit, c_w, cutoff, A_b[3 x LV_NW]
   (offsets LV_MODEL_*). kind is a bit set of LV_KIND_JOINT and LV_KIND_WHEELS (lv_kind_valid);
   a body of kind 0 is a plain rigid body (its row is ignored). */

/* Per-body model data for bodies with a joint and/or wheels (all arrays nb rows).
   Omega (nb x LV_NW) is advanced in place; command (nb x LV_NW) is held over the call (zero-order hold);
   applied (nb x LV_NW) receives the saturated torques of the last step. */
typedef struct lv_model_cache lv_model_cache;
typedef struct {
    const double *rows;     /* nb x LV_MODEL_SIZE */
    double *Omega;          /* nb x LV_NW, wheel rates relative to the body, rad/s */
    const double *command;  /* nb x LV_NW, motor torque commands, N m */
    double *applied;        /* nb x LV_NW, saturated torques used in the last step, N m */
    lv_model_cache *cache;  /* NULL, or the caller's per-body decisions kept from call to call (lv_model_cache) */
} lv_models;

/* What lv_simulate decides per call from the model rows and the effect table alone, kept by a caller that steps the
   same arrays call after call (the Stepper, csrc/fast_step.c) instead of redone per call:
   * per model body (the fixed-step loops): the kind it is stepped with, its wheel coefficients, its momentum-bound
     factors (the Stepper's growth screen reads them while `valid`). Used while the rows
     are those it was made from: compared bytewise per call (one memcmp), or, for a cache made `marked`, while the
     owner has not reported a write to the rows (lv_model_cache_rows_written: the owner is the rows' only writer and
     reports every write). Otherwise made again from the rows: the same numbers either way.
   * the effect index (each body's effects, CSR) of the last call, and the fixed-step loops' order of the bodies
     made from it and the rows' kinds (made again with the rows' entries): used while the table is at the same address with
     the same size and every row's code and body are those it was built from (ne pairs compared per call: the index
     reads nothing else of a row, and its parameters are read through it at their current values), with the same user
     table; otherwise built again (and checked again) as in any call.
   Made with lv_model_cache_new. */
typedef struct lv_index_keep lv_index_keep;
struct lv_model_cache {
    long nb;
    int valid;      /* the entries below were made from the rows (as they are now) */
    int marked;     /* the owner reports every write to the rows (no compare; rows is NULL) */
    double *rows;   /* nb x LV_MODEL_SIZE: the rows they were made from (not marked) */
    int *kind;      /* nb: the kind the step loops step body b with (its row's kind, with LV_ON_AXES for wheels on the
                       default layout) */
    double *kw;     /* nb x LV_WCOEF_SIZE: the wheel coefficients of the wheeled bodies (others unset) */
    double *bound;  /* nb x LV_WHEELS_BOUND_SIZE: the wheeled bodies' momentum-bound factors
                       (LV_WHEELS_MOMENTUM_BOUND_FACTORS, for the growth screen; others unset) */
    lv_index_keep *index;   /* the last call's effect index and what it was built from, or NULL */
};

/* A cache for nb bodies (empty: lv_simulate fills it on first use), or NULL (out of memory); freed by
   lv_model_cache_free (NULL is fine). marked: the caller reports every write to the rows after the first call with
   lv_model_cache_rows_written (then no compare per call). */
lv_model_cache *lv_model_cache_new(long nb, int marked);
void lv_model_cache_free(lv_model_cache *c);
/* The rows of a marked cache were written: its per-body entries are made again at the next call. */
void lv_model_cache_rows_written(lv_model_cache *c);

/* The integrators (LV_INTEGRATOR_*, LV_INTEGRATOR_PLAIN_ONLY(i): plain bodies only, one by one in
   advance_structured), the fixed-step paths (LV_PATH_*: the code of the integrator that takes each; an explicit RK
   without one steps on the tableau stepper with its printed tableau, LV_TABLEAU_STEPPED) and the status codes (LV_OK,
   LV_DIVERGED, ...) are printed from derive/tableaux.py's registry into generated/tableaux.h: csrc/ names no
   integrator. */

/* Adaptive stepping (dopri5): every body is stepped with its own step sizes; each of the n_steps
   steps advances it by exactly dt with as many accepted substeps as its error estimate needs.
   h (nb) carries each body's step-size proposal between calls (<= 0: choose an initial one);
   nfev (nb) is incremented by the right-hand-side evaluations spent on each body. dense (nb x LV_DENSE_SIZE, or NULL:
   every call starts afresh) carries each wheel-less body's dense output between calls (layout.h DENSE). */
typedef struct {
    double rtol, atol;
    double *h;
    double *nfev;
    double *dense;
} lv_adaptive;


/* The RK4 and Euler updates are printed from their tableaux (derive/tableaux.py EXPLICIT_RK) into generated/tableaux.h:
   LV_RK4_UPDATE / LV_RK4_STEP and LV_EULER_UPDATE / LV_EULER_STEP, and the built-in rk4's scaled-increment form
   (derive/tableaux.py scaled_program) as LV_RK4_SCALE / LV_RK4_SCALED_UPDATE / LV_RK4_SCALED_STEP. Every path of
   csrc/ that steps rk4 or euler updates through them: plain bodies, torque-free or with effects, in the scaled form
   (the scalar blocks, the SIMD tiles, float32's torque-free tiles); the model bodies and tiles, float32 bodies with
   effects, the opt-in contract="fma" tiles and rk4_expmap through LV_RK4_STEP / LV_RK4_UPDATE. */

/* ---- one copy of a function per instruction set ---------------------------------------------------------
   LV_ISA_COPIES(DEF) expands DEF(SUFFIX, ATTR) once per instruction set: base (the build's flags), and on x86
   with GCC or clang avx2 and avx512 (their target attribute); LV_ISA_PICK(isa, NAME) is the copy NAME_SUFFIX of
   LV_ISA_* isa (one this CPU supports: lv_isa_get; NAME may be a macro call). The one dispatch of the SIMD paths
   (float64 and float32). */
#if (defined(__GNUC__) || defined(__clang__)) && (defined(__x86_64__) || defined(__i386__))
#define LV_HAVE_ISA_CLONES 1
#define LV_ISA_COPIES(DEF) DEF(base, ) DEF(avx2, __attribute__((target("avx2")))) \
    DEF(avx512, __attribute__((target("avx512f"))))
#define LV_ISA_PICK(isa, NAME)                                                                         \
    ((isa) == LV_ISA_AVX512 ? LV_PASTE(NAME, _avx512) : (isa) == LV_ISA_AVX2 ? LV_PASTE(NAME, _avx2) : LV_PASTE(NAME, _base))
#else
#define LV_HAVE_ISA_CLONES 0
#define LV_ISA_COPIES(DEF) DEF(base, )
#define LV_ISA_PICK(isa, NAME) LV_PASTE(NAME, _base)
#endif
#define LV_PASTE_(a, b) a##b
#define LV_PASTE(a, b) LV_PASTE_(a, b) /* a and b expanded first */
/* The torque-free tiles' instruction order (batch_simd.h, fixed_loop.h; LV_TILE_H_SCHED_<isa>, added to the copy's
   target attribute): GCC's pre-register-allocation scheduler (-fschedule-insns, off by default on x86) for the AVX-512 copy only. It interleaves
   the lane loop's independent chains (q's and omega_b's stages, the normalization) before the registers are given out:
   the same instructions (102 vmulpd, 101 vaddpd/vsubpd, one vsqrtpd and vdivpd per 8 bodies, no contraction: the
   file's -ffp-contract=off holds), so the same bits, with 6 stack references per iteration instead of 13. Standalone
   copy of the tile (64 bodies, min of 7, same binary, load ~3): 4.29 ns per body-step against 4.70 (~9 %). With 16
   registers (AVX2, the baseline SSE2 copy) it spills more and is slower (7.5 against 6.4 ns), so those keep the
   default. The opt-in FMA tiles' AVX-512 copies (tile_rk4_*_free_fma_avx512) take it too (~3 %, still contracted).
   The float32 torque-free tiles' AVX-512 copies (fixed_loop.h) take it too: 2.58-2.62 against 2.38-2.41 ns per
   body-step at N = 1e3, 2.94-3.08 against 2.78-2.83 at 1e4 (Sim.run, load ~5, /work/notes/s24/lead/f32_probe.py).
   Control flow only: no arithmetic is written here. */
#if defined(__GNUC__) && !defined(__clang__)
#define LV_TILE_H_SCHED_avx512 __attribute__((optimize("schedule-insns")))
#else
#define LV_TILE_H_SCHED_avx512
#endif
#define LV_TILE_H_SCHED_avx2
#define LV_TILE_H_SCHED_base

/* The instruction sets of the batched RK4 paths (plain bodies: csrc/batch_simd.h; jointed wheel bodies:
   csrc/model_simd.h): LV_ISA_SCALAR turns them off (every body on the scalar block or per-body path), LV_ISA_BASE is the build's baseline (SSE2 on x86-64), AVX2 and
   AVX-512F copies exist on x86 builds with GCC or clang. All give bitwise the same results. */
enum { LV_ISA_SCALAR = 0, LV_ISA_BASE = 1, LV_ISA_AVX2 = 2, LV_ISA_AVX512 = 3 };
/* The best instruction set this CPU (and OS) supports, detected once. */
int lv_isa_best(void);
/* The one lv_simulate uses (default: lv_isa_best()). lv_isa_set(isa) selects one, capped at lv_isa_best()
   (a negative isa: the best again), and returns the one now in use. Not for use while another thread is
   in lv_simulate (a test and benchmark switch). */
int lv_isa_get(void);
int lv_isa_set(int isa);
/* Threads that share the SIMD tiles and the bodies with a joint or wheels (euler, semi-implicit Euler, rk4) of
   one lv_simulate call (default 1; 1 .. LV_MAX_THREADS; always 1 where the build has no POSIX threads). Results
   are bitwise those of one thread. lv_threads_set returns the
   number now in use; like lv_isa_set, not for use while another thread is in lv_simulate. */
#define LV_MAX_THREADS 64
int lv_threads_get(void);
int lv_threads_set(int threads);
/* The arithmetic of the torque-free RK4 SIMD tiles in the calling thread's lv_simulate calls (csrc/batch_simd.h):
   LV_CONTRACT_OFF (the default) bitwise the scalar path and NumPy; LV_CONTRACT_FMA a copy of those tiles compiled
   with a*b+c contracted into fused multiply-adds (AVX2/AVX-512 with FMA, GCC builds: lv_contract_available), whose
   results differ from the bitwise ones in the last bits. Every other path stays bitwise in either mode.
   lv_contract_set returns the previous mode; it is per thread (lavendersim._lavender_c.simulate sets it around one
   call). */
enum { LV_CONTRACT_OFF = 0, LV_CONTRACT_FMA = 1 };
int lv_contract_set(int mode);
int lv_contract_available(void);
/* A short name of LV_ISA_* isa ("scalar", "sse2" (x86-64) or "baseline", "avx2", "avx512f"). */
const char *lv_isa_name(int isa);

/* Advance nb bodies (state: nb x 13, in place) by n_steps steps of size dt.
   effects: ne rows of row_size doubles, [code, body (-1: every body), parameters...]; built-in codes
   and codes of `user` (may be NULL). The effects are indexed per body once per call (O(nb + ne)), so a
   body's step costs its own effects only.
   Bodies are independent: the outer loop runs over bodies (blocks of them), the inner over steps.
   models may be NULL (every body plain). A body of nonzero kind steps [x, Omega] (LV_XS_SIZE numbers) with
   LV_WHEELS_BODY_RHS (wheels) or pivot_body_rhs (joint only); its wheel torques are saturated at the
   start of each step; a jointed body's p_w, v_w are set from pivot_kinematics after each step.
   After every step all numbers of the body (13, or LV_XS_SIZE with its wheel rates) are checked; on a
   non-finite value the function returns LV_DIVERGED with *fail_step (0-based) and *fail_body set:
   the earliest failing step over all bodies, then the lowest body index failing at that step (the
   NumPy backend's order). Then body fail_body holds its last finite state and wheel rates (before
   step fail_step; its applied row untouched) and, for LV_TOLERANCE, h[fail_body] as above; every
   other body's rows (state, Omega, applied, h, nfev) are unspecified (advanced by some number of
   steps): the caller restores them from its snapshot. A model kind lv_kind_valid refuses, an
   unknown integrator, dopri5 without `adaptive`, a plain-only integrator (LV_INTEGRATOR_PLAIN_ONLY) with a body of nonzero kind, or
   an effect body outside [-1, nb) returns LV_BAD_ARGUMENT, an effect code no declared effect has (built
   in or in `user`) LV_UNKNOWN_EFFECT with *fail_step = its row (nothing changed, never a silent no-op).
   `adaptive` is read only by dopri5. */
/* The one check of an effect row (index_build in step.c, simulate()'s argument check in module.c): LV_OK with *np =
   its parameter count; LV_UNKNOWN_EFFECT for a code no declared effect has (built in, or in `user`, which may be NULL) or whose parameters do not fit a row of row_size (*np says which: < 0 or the
   count); LV_BAD_ARGUMENT for a body other than -1 (every body) or an integer index in [0, nb). */
int lv_effect_row_check(const double *row, long row_size, long nb, const lv_user_effects *user, int *np);

/* A user-declared explicit Runge-Kutta method (lavendersim.backends.Tableau), stepped by lv_simulate when given in
   place of a built-in integrator: s stages (1 .. LV_TABLEAU_MAX_STAGES), a (s x s, row-major, strictly lower),
   the weights b_num (s) over b_den. With h = dt and k_0 = f(x): stage i evaluates k_i = f(x + h * sum_j a[i][j] k_j)
   (the first nonzero term, then the later nonzero ones added in increasing j; x itself for an all-zero row), and
   the step ends at x + (h / b_den) * sum_i b_num[i] k_i (the same order, zero weights skipped): the NumPy
   backend's operation order (lavendersim.backends.rk_weights gives b_num, b_den). */
#define LV_TABLEAU_MAX_STAGES 16
typedef struct {
    int s;
    const double *a;
    const double *b_num;
    double b_den;
} lv_tableau;

/* tableau: NULL, or a user's explicit Runge-Kutta method (then `integrator` is ignored): every body (any kind) is
   stepped one by one as rk4 steps it (effects, joint, wheels with their torques held over the step, q normalized
   when asked, the same divergence contract).
   cache: with models NULL, NULL or where a caller that steps the same arrays call after call keeps the effect index
   and the order of the bodies (lv_model_cache's index; lv_model_cache_new(0, 1): no model entries are made); with
   models, ignored (models->cache is used). */
int lv_simulate(double *state, const double *params, long nb,
                const double *effects, long ne, long row_size, const lv_user_effects *user,
                const lv_models *models, lv_model_cache *cache, int integrator, int normalize, double dt, long n_steps,
                const lv_adaptive *adaptive, const lv_tableau *tableau, long *fail_step, long *fail_body);

#endif
