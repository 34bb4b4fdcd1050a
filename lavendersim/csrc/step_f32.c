/* LavenderSim float32 stepping (Sim(..., dtype="float32") on the C backend): the templated fixed-step loop
   (fixed_loop.h) instantiated in single precision on the generated float kernels (generated/kernels_f32.c,
   compiled into this translation unit so they inline). Control flow only; see fixed_loop.h. */
#include <math.h>
#include <stdint.h>
#include <stdlib.h>
#include <string.h>

#include "kernels_f32.c"
#include "step.h"
#include "step_f32.h"
#include "tableaux.h"

#if defined(_MSC_VER)
#define LV_RESTRICT __restrict
#else
#define LV_RESTRICT restrict
#endif

#define LV_REAL float
#define LV_K(name) lvf_##name
#define LV_EFFECT_APPLY lvf_effect_apply
#define LV_FN(name) name##_f32
#include "fixed_loop.h"

int lv_simulate_f32(float *state, const float *params, long nb, const float *effects, long ne, long row_size,
                    int integrator, int normalize, float dt, long n_steps, long *fail_step, long *fail_body)
{
    return simulate_f32(state, params, nb, effects, ne, row_size, integrator, normalize, dt, n_steps, lv_isa_get(),
                        fail_step, fail_body);
}
