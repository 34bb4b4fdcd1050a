/* LavenderSim stepping loop (see step.h). Every equation comes from generated/kernels.c. */
#include <math.h>
#include <string.h>

#include "kernels.h"
#include "step.h"

/* Force at the COM and torque about it (world), summed over the effects acting on body b in table
   order. v_w is the COM velocity the linear damping sees (the state's, or a joint's kinematic one). */
static inline void effect_sums(const double *x, const double *v_w, double m, const double *effects, long ne,
                               long b, double *F, double *tau)
{
    double c[3];
    long e;
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
            lv_linear_damping(p[0], v_w, c);
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
}

/* d/dt of one plain body's state: the free kernel when no effect applies, else the effects' force and
   torque summed in table order and passed to the full right-hand side. */
static void body_rhs(const double *x, const double *prm, const double *effects, long ne, long b,
                     int has_effects, double *xdot)
{
    const double m = prm[0];
    const double *I_b = prm + 1;
    double F[3] = {0.0, 0.0, 0.0}, tau[3] = {0.0, 0.0, 0.0};
    if (!has_effects) {
        lv_rigid_body_rhs_free(x, I_b, xdot);
        return;
    }
    effect_sums(x, x + 7, m, effects, ne, b, F, tau);
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

/* ---- bodies with a spherical joint and/or reaction wheels ------------------------------------ */

/* extended state: x[13] then Omega[3] */
#define LV_XS 16

/* d/dt of [x, Omega] for a body of nonzero kind; u = this step's applied wheel torques.
   r = its model row. A jointed body's p, v derivatives are zero (set from the joint after the step);
   its linear damping sees the kinematic COM velocity (computed only when needs_v). */
static void model_rhs(const double *y, const double *u, double m, const double *r, int kind, int needs_v,
                      const double *effects, long ne, long b, double *yd)
{
    double F[3] = {0.0, 0.0, 0.0}, tau[3] = {0.0, 0.0, 0.0}, pk[3], vk[3];
    const double *v = y + 7;
    int i;
    if (needs_v) {
        lv_pivot_kinematics(y + 3, y + 10, r + 13, r + 10, pk, vk);
        v = vk;
    }
    effect_sums(y, v, m, effects, ne, b, F, tau);
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
                          const double *effects, long ne, int integrator, int normalize,
                          double dt, long n_steps, double *last)
{
    const double *r = md->rows + b * LV_MODEL_SIZE;
    const int kind = (int)r[0];
    const double m = params[b * LV_PARAM_SIZE];
    const double *cmd = md->command + 3 * b;
    double y[LV_XS], yn[LV_XS], k1[LV_XS], k2[LV_XS], k3[LV_XS], k4[LV_XS], tmp[LV_XS];
    double u[3] = {0.0, 0.0, 0.0}, applied[3];
    const double h2 = 0.5 * dt, h6 = dt / 6.0;
    int needs_v = 0;
    long s, e;
    int i;
    if (kind & LV_KIND_JOINT)
        for (e = 0; e < ne; e++) {
            const double *row = effects + e * LV_EFFECT_SIZE;
            if ((int)row[0] == LV_EFFECT_LINEAR_DAMPING && ((long)row[1] == -1 || (long)row[1] == b)) needs_v = 1;
        }
    memcpy(y, state + b * LV_STATE_SIZE, LV_STATE_SIZE * sizeof(double));
    memcpy(y + LV_STATE_SIZE, md->Omega + 3 * b, 3 * sizeof(double));
    memcpy(applied, md->applied + 3 * b, sizeof applied);
#define MRHS(in, out) model_rhs(in, u, m, r, kind, needs_v, effects, ne, b, out)
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

int lv_simulate(double *state, const double *params, long nb,
                const double *effects, long ne, const lv_models *models,
                int integrator, int normalize, double dt, long n_steps,
                long *fail_step, long *fail_body)
{
    double last[LV_BLOCK][LV_STATE_SIZE];
    long b0, b, s;
    int j, n;
    if (integrator != LV_INTEGRATOR_EULER && integrator != LV_INTEGRATOR_SEMI_IMPLICIT_EULER
        && integrator != LV_INTEGRATOR_RK4)
        return LV_BAD_ARGUMENT;
    for (b0 = 0; b0 < nb; b0 += n) {
        if (models != NULL && (int)models->rows[b0 * LV_MODEL_SIZE] != 0) {
            double lastm[LV_XS];
            n = 1;
            s = advance_model(state, params, b0, models, effects, ne, integrator, normalize, dt, n_steps, lastm);
            if (s < 0) continue;
            memcpy(state + b0 * LV_STATE_SIZE, lastm, LV_STATE_SIZE * sizeof(double));
            memcpy(models->Omega + 3 * b0, lastm + LV_STATE_SIZE, 3 * sizeof(double));
            *fail_step = s;
            *fail_body = b0;
            return LV_DIVERGED;
        }
        /* a run of up to LV_BLOCK consecutive plain bodies */
        n = (int)(nb - b0 < LV_BLOCK ? nb - b0 : LV_BLOCK);
        if (models != NULL)
            for (j = 1; j < n; j++)
                if ((int)models->rows[(b0 + j) * LV_MODEL_SIZE] != 0) { n = j; break; }
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
