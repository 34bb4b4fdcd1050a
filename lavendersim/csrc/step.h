/* LavenderSim C stepping loop: advances many independent rigid bodies by many steps.
   Plain C99, no Python; uses only the generated kernels (generated/kernels.h). */
#ifndef LAVENDERSIM_STEP_H
#define LAVENDERSIM_STEP_H

/* The state row (LV_STATE_*: p_w[3], q[4] (x,y,z,w), v_w[3], omega_b[3]), the params row (LV_PARAM_*: m,
   I_x, I_y, I_z), the per-body model row (LV_MODEL_*) and the extended state [x, Omega] (LV_XS_*) are
   declared in derive/layout.py and printed as named offsets in generated/layout.h. */
#include "layout.h"

/* effect row (8): kind, body (index, or -1 for every body), p0..p5 */
#define LV_EFFECT_SIZE 8

enum {
    LV_EFFECT_APPLIED_TORQUE = 1,  /* p0..2 = tau_w */
    LV_EFFECT_FORCE_AT_POINT = 2,  /* p0..2 = r_b (body frame), p3..5 = F_w */
    LV_EFFECT_GRAVITY = 3,         /* p0..2 = g_w */
    LV_EFFECT_LINEAR_DAMPING = 4,  /* p0 = c */
    LV_EFFECT_ANGULAR_DAMPING = 5  /* p0 = c */
};

/* The model row (LV_MODEL_SIZE), per body: kind, I_p[9] (about the pivot, body frame, row-major), r_b[3]
   (pivot -> COM, body frame), anchor_w[3], J[3], torque_limit, speed_limit, c_w (offsets LV_MODEL_*).
   kind is a bit set of LV_KIND_JOINT and LV_KIND_WHEELS; a body of kind 0 is a plain rigid body (its row
   is ignored). */

/* Per-body model data for bodies with a joint and/or wheels (all arrays nb rows).
   Omega (nb x 3) is advanced in place; command (nb x 3) is held over the call (zero-order hold);
   applied (nb x 3) receives the saturated torques of the last step. */
typedef struct {
    const double *rows;     /* nb x LV_MODEL_SIZE */
    double *Omega;          /* nb x 3, wheel rates relative to the body, rad/s */
    const double *command;  /* nb x 3, motor torque commands, N m */
    double *applied;        /* nb x 3, saturated torques used in the last step, N m */
} lv_models;

enum {
    LV_INTEGRATOR_EULER = 0,
    LV_INTEGRATOR_SEMI_IMPLICIT_EULER = 1,
    LV_INTEGRATOR_RK4 = 2,
    LV_INTEGRATOR_DOPRI5 = 3,        /* adaptive Dormand-Prince 5(4), FSAL; needs an lv_adaptive */
    LV_INTEGRATOR_SPLITTING = 4,     /* Strang splitting, exact axis sub-flows; plain bodies only */
    LV_INTEGRATOR_IMPLICIT_GYRO = 5  /* implicit gyroscopic term (Newton), exp-map q; plain bodies only */
};
#define LV_INTEGRATOR_LAST LV_INTEGRATOR_IMPLICIT_GYRO

/* Adaptive stepping (dopri5): every body is stepped with its own step sizes; each of the n_steps
   steps advances it by exactly dt with as many accepted substeps as its error estimate needs.
   h (nb) carries each body's step-size proposal between calls (<= 0: choose an initial one);
   nfev (nb) is incremented by the right-hand-side evaluations spent on each body. */
typedef struct {
    double rtol, atol;
    double *h;
    double *nfev;
} lv_adaptive;

enum {
    LV_OK = 0,
    LV_DIVERGED = 1,    /* a state became non-finite; see fail_step / fail_body */
    LV_TOLERANCE = 2,   /* dopri5: the step size fell below dt*1e-12 (or over 10^6 substeps in one step)
                           without meeting rtol/atol; same state contract as LV_DIVERGED, and h[fail_body]
                           holds the step size that was too small */
    LV_BAD_ARGUMENT = -1
};

/* Advance nb bodies (state: nb x 13, in place) by n_steps steps of size dt.
   Bodies are independent: the outer loop runs over bodies (blocks of them), the inner over steps.
   models may be NULL (every body plain). A body of nonzero kind steps [x, Omega] (16 numbers) with
   wheel_body_rhs (wheels) or pivot_body_rhs (joint only); its wheel torques are saturated at the
   start of each step; a jointed body's p_w, v_w are set from pivot_kinematics after each step.
   After every step all numbers of the body (13, or 16 with its wheel rates) are checked; on a
   non-finite value the function returns LV_DIVERGED with *fail_step (0-based) and *fail_body set:
   the earliest failing step over all bodies, then the lowest body index failing at that step (the
   NumPy backend's order). Then body fail_body holds its last finite state and wheel rates (before
   step fail_step; its applied row untouched) and, for LV_TOLERANCE, h[fail_body] as above; every
   other body's rows (state, Omega, applied, h, nfev) are unspecified (advanced by some number of
   steps): the caller restores them from its snapshot. Effect kinds/bodies and model kinds must be valid (the caller
   validates); an unknown integrator, dopri5 without `adaptive`, or splitting / implicit_gyro with a body
   of nonzero kind returns LV_BAD_ARGUMENT (nothing changed). `adaptive` is read only by dopri5. */
int lv_simulate(double *state, const double *params, long nb,
                const double *effects, long ne, const lv_models *models,
                int integrator, int normalize, double dt, long n_steps,
                const lv_adaptive *adaptive, long *fail_step, long *fail_body);

#endif
