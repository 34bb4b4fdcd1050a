/* LavenderSim stepping loop (see step.h). Every equation comes from generated/kernels.c. */
#include <math.h>
#include <string.h>

#include "kernels.h"
#include "step.h"

/* d/dt of one body's state: the free kernel when no effect applies, else the effects' force and
   torque summed in table order and passed to the full right-hand side. */
static void body_rhs(const double *x, const double *prm, const double *effects, long ne, long b,
                     int has_effects, double *xdot)
{
    const double m = prm[0];
    const double *I_b = prm + 1;
    double F[3] = {0.0, 0.0, 0.0}, tau[3] = {0.0, 0.0, 0.0}, c[3];
    long e;
    if (!has_effects) {
        lv_rigid_body_rhs_free(x, I_b, xdot);
        return;
    }
    for (e = 0; e < ne; e++) {
        const double *row = effects + e * LV_EFFECT_SIZE;
        const long target = (long)row[1];
        const double *p = row + 2;
        if (target != -1 && target != b) continue;
        switch ((int)row[0]) {
        case LV_EFFECT_APPLIED_TORQUE:
            tau[0] += p[0]; tau[1] += p[1]; tau[2] += p[2];
            break;
        case LV_EFFECT_FORCE_AT_POINT:
            F[0] += p[3]; F[1] += p[4]; F[2] += p[5];
            lv_force_at_point(x + 3, p, p + 3, c);
            tau[0] += c[0]; tau[1] += c[1]; tau[2] += c[2];
            break;
        case LV_EFFECT_GRAVITY:
            lv_gravity_force(m, p, c);
            F[0] += c[0]; F[1] += c[1]; F[2] += c[2];
            break;
        case LV_EFFECT_LINEAR_DAMPING:
            lv_linear_damping(p[0], x + 7, c);
            F[0] += c[0]; F[1] += c[1]; F[2] += c[2];
            break;
        case LV_EFFECT_ANGULAR_DAMPING:
            lv_angular_damping(x + 3, p[0], x + 10, c);
            tau[0] += c[0]; tau[1] += c[1]; tau[2] += c[2];
            break;
        default:
            break; /* validated by the caller */
        }
    }
    lv_rigid_body_rhs(x, m, I_b, F, tau, xdot);
}

static int all_finite(const double *x)
{
    int i;
    for (i = 0; i < LV_STATE_SIZE; i++)
        if (!isfinite(x[i])) return 0;
    return 1;
}

int lv_simulate(double *state, const double *params, long nb,
                const double *effects, long ne,
                int integrator, int normalize, double dt, long n_steps,
                long *fail_step, long *fail_body)
{
    long b, s, e;
    int i;
    if (integrator != LV_INTEGRATOR_EULER && integrator != LV_INTEGRATOR_SEMI_IMPLICIT_EULER
        && integrator != LV_INTEGRATOR_RK4)
        return LV_BAD_ARGUMENT;
    for (b = 0; b < nb; b++) {
        double x[LV_STATE_SIZE], xn[LV_STATE_SIZE], k1[LV_STATE_SIZE], k2[LV_STATE_SIZE],
            k3[LV_STATE_SIZE], k4[LV_STATE_SIZE], tmp[LV_STATE_SIZE];
        const double *prm = params + b * LV_PARAM_SIZE;
        double *row = state + b * LV_STATE_SIZE;
        int has_effects = 0;
        for (e = 0; e < ne; e++) {
            const long target = (long)effects[e * LV_EFFECT_SIZE + 1];
            if (target == -1 || target == b) { has_effects = 1; break; }
        }
        memcpy(x, row, sizeof x);
        for (s = 0; s < n_steps; s++) {
            switch (integrator) {
            case LV_INTEGRATOR_EULER:
                body_rhs(x, prm, effects, ne, b, has_effects, k1);
                for (i = 0; i < LV_STATE_SIZE; i++) xn[i] = x[i] + dt * k1[i];
                break;
            case LV_INTEGRATOR_SEMI_IMPLICIT_EULER:
                body_rhs(x, prm, effects, ne, b, has_effects, k1);
                for (i = 7; i < 13; i++) xn[i] = x[i] + dt * k1[i];          /* v', omega' */
                for (i = 0; i < 3; i++) xn[i] = x[i] + dt * xn[7 + i];       /* p' = p + dt v' */
                lv_quat_derivative_body(x + 3, xn + 10, tmp);                /* q rate at omega' */
                for (i = 0; i < 4; i++) xn[3 + i] = x[3 + i] + dt * tmp[i];
                break;
            default: { /* LV_INTEGRATOR_RK4; stage quaternions left unnormalized */
                const double h2 = 0.5 * dt;
                body_rhs(x, prm, effects, ne, b, has_effects, k1);
                for (i = 0; i < LV_STATE_SIZE; i++) tmp[i] = x[i] + h2 * k1[i];
                body_rhs(tmp, prm, effects, ne, b, has_effects, k2);
                for (i = 0; i < LV_STATE_SIZE; i++) tmp[i] = x[i] + h2 * k2[i];
                body_rhs(tmp, prm, effects, ne, b, has_effects, k3);
                for (i = 0; i < LV_STATE_SIZE; i++) tmp[i] = x[i] + dt * k3[i];
                body_rhs(tmp, prm, effects, ne, b, has_effects, k4);
                for (i = 0; i < LV_STATE_SIZE; i++)
                    xn[i] = x[i] + (dt / 6.0) * (k1[i] + 2.0 * k2[i] + 2.0 * k3[i] + k4[i]);
                break;
            }
            }
            if (normalize) lv_quat_normalize(xn + 3, xn + 3);
            if (!all_finite(xn)) {
                memcpy(row, x, sizeof x);
                *fail_step = s;
                *fail_body = b;
                return LV_DIVERGED;
            }
            memcpy(x, xn, sizeof x);
        }
        memcpy(row, x, sizeof x);
    }
    return LV_OK;
}
