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

/* Bodies stepped in lockstep: one body's step is a chain of dependent divisions and square roots
   (latency-bound), so interleaving a few independent bodies lets the CPU overlap them. Each body's
   arithmetic is exactly the single-body sequence, so results do not depend on the blocking. */
#define LV_BLOCK 4

/* Advance bodies b0 .. b0+n-1 (n <= LV_BLOCK) by n_steps. Their rows are read at the start and written
   only on success. Returns -1 on success, else the 0-based failing step; then *fail_j is the first
   (lowest-index) body of the block that went non-finite at that step and last[] holds the block's
   last finite states. */
static long advance_block(double *state, const double *params, long b0, int n,
                          const double *effects, long ne, int integrator, int normalize,
                          double dt, long n_steps, int *fail_j, double last[][LV_STATE_SIZE])
{
    double x[LV_BLOCK][LV_STATE_SIZE], xn[LV_BLOCK][LV_STATE_SIZE], k1[LV_BLOCK][LV_STATE_SIZE],
        k2[LV_BLOCK][LV_STATE_SIZE], k3[LV_BLOCK][LV_STATE_SIZE], k4[LV_BLOCK][LV_STATE_SIZE],
        tmp[LV_BLOCK][LV_STATE_SIZE];
    const double *prm[LV_BLOCK];
    int has[LV_BLOCK];
    const double h2 = 0.5 * dt, h6 = dt / 6.0;
    long s, e;
    int i, j;
    for (j = 0; j < n; j++) {
        const long b = b0 + j;
        prm[j] = params + b * LV_PARAM_SIZE;
        has[j] = 0;
        for (e = 0; e < ne; e++) {
            const long target = (long)effects[e * LV_EFFECT_SIZE + 1];
            if (target == -1 || target == b) { has[j] = 1; break; }
        }
        memcpy(x[j], state + b * LV_STATE_SIZE, sizeof x[j]);
    }
#define RHS(in, out) for (j = 0; j < n; j++) body_rhs(in[j], prm[j], effects, ne, b0 + j, has[j], out[j])
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
    for (j = 0; j < n; j++) memcpy(state + (b0 + j) * LV_STATE_SIZE, x[j], sizeof x[j]);
    return -1;
}

int lv_simulate(double *state, const double *params, long nb,
                const double *effects, long ne,
                int integrator, int normalize, double dt, long n_steps,
                long *fail_step, long *fail_body)
{
    double last[LV_BLOCK][LV_STATE_SIZE];
    long b0, b, s;
    int j;
    if (integrator != LV_INTEGRATOR_EULER && integrator != LV_INTEGRATOR_SEMI_IMPLICIT_EULER
        && integrator != LV_INTEGRATOR_RK4)
        return LV_BAD_ARGUMENT;
    for (b0 = 0; b0 < nb; b0 += LV_BLOCK) {
        const int n = (int)(nb - b0 < LV_BLOCK ? nb - b0 : LV_BLOCK);
        /* constant block sizes let the compiler specialize (clone) advance_block */
        if (n == LV_BLOCK)
            s = advance_block(state, params, b0, LV_BLOCK, effects, ne, integrator, normalize, dt, n_steps, &j, last);
        else if (n == 1)
            s = advance_block(state, params, b0, 1, effects, ne, integrator, normalize, dt, n_steps, &j, last);
        else
            s = advance_block(state, params, b0, n, effects, ne, integrator, normalize, dt, n_steps, &j, last);
        if (s < 0) continue;
        /* A body of this block diverged; rows are untouched. Redo the block body by body so that
           earlier bodies end fully advanced and the failing one holds its last finite state. */
        for (b = b0; b < b0 + n; b++) {
            s = advance_block(state, params, b, 1, effects, ne, integrator, normalize, dt, n_steps, &j, last);
            if (s >= 0) {
                memcpy(state + b * LV_STATE_SIZE, last[0], sizeof last[0]);
                *fail_step = s;
                *fail_body = b;
                return LV_DIVERGED;
            }
        }
        /* unreachable for a deterministic build; report the block's first failure if it happens */
        *fail_step = -1;
        *fail_body = b0;
        return LV_DIVERGED;
    }
    return LV_OK;
}
