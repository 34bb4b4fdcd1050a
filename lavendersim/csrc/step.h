/* LavenderSim C stepping loop: advances many independent rigid bodies by many steps.
   Plain C99, no Python; uses only the generated kernels (generated/kernels.h). */
#ifndef LAVENDERSIM_STEP_H
#define LAVENDERSIM_STEP_H

/* state row (13): p_w[3], q[4] (x,y,z,w), v_w[3], omega_b[3] */
#define LV_STATE_SIZE 13
/* params row (4): m, I_x, I_y, I_z */
#define LV_PARAM_SIZE 4
/* effect row (8): kind, body (index, or -1 for every body), p0..p5 */
#define LV_EFFECT_SIZE 8

enum {
    LV_EFFECT_APPLIED_TORQUE = 1,  /* p0..2 = tau_w */
    LV_EFFECT_FORCE_AT_POINT = 2,  /* p0..2 = r_b (body frame), p3..5 = F_w */
    LV_EFFECT_GRAVITY = 3,         /* p0..2 = g_w */
    LV_EFFECT_LINEAR_DAMPING = 4,  /* p0 = c */
    LV_EFFECT_ANGULAR_DAMPING = 5  /* p0 = c */
};

enum {
    LV_INTEGRATOR_EULER = 0,
    LV_INTEGRATOR_SEMI_IMPLICIT_EULER = 1,
    LV_INTEGRATOR_RK4 = 2
};

enum {
    LV_OK = 0,
    LV_DIVERGED = 1,    /* a state became non-finite; see fail_step / fail_body */
    LV_BAD_ARGUMENT = -1
};

/* Advance nb bodies (state: nb x 13, in place) by n_steps steps of size dt.
   Bodies are independent: the outer loop runs over bodies, the inner over steps.
   After every step all 13 numbers of the body are checked; on a non-finite value the function
   returns LV_DIVERGED with *fail_step (0-based) and *fail_body set. Then bodies < fail_body have been
   advanced fully, body fail_body holds its last finite state (before step fail_step), and bodies
   > fail_body are untouched. Effect kinds/bodies must be valid (the caller validates);
   an unknown integrator returns LV_BAD_ARGUMENT. */
int lv_simulate(double *state, const double *params, long nb,
                const double *effects, long ne,
                int integrator, int normalize, double dt, long n_steps,
                long *fail_step, long *fail_body);

#endif
