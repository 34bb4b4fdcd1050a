/* LavenderSim float32 stepping loop (step_f32.c, the fixed_loop.h template in single precision). */
#ifndef LAVENDERSIM_STEP_F32_H
#define LAVENDERSIM_STEP_F32_H

/* lv_simulate (step.h) in float32 for plain bodies: state nb x LV_STATE_SIZE floats (in place), params
   nb x LV_PARAM_SIZE, effects ne rows of row_size floats [code, body (-1: every body), parameters...] with
   built-in codes only (body indices exact in float: nb < 2^24). integrator: a code with LV_INTEGRATOR_FLOAT32
   (generated/tableaux.h; each takes a fixed-step path, LV_INTEGRATOR_FIXED_PATH; else LV_BAD_ARGUMENT). Returns LV_OK, LV_DIVERGED
   (*fail_step, *fail_body: the earliest failing step, then the lowest body; that body holds its last finite
   state, the others are unspecified), LV_UNKNOWN_EFFECT (*fail_step = the row; nothing changed),
   LV_BAD_ARGUMENT or LV_NO_MEMORY (nothing changed). */
int lv_simulate_f32(float *state, const float *params, long nb, const float *effects, long ne, long row_size,
                    int integrator, int normalize, float dt, long n_steps, long *fail_step, long *fail_body);

#endif
