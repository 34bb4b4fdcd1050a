/* The hand-written peers of `lavendersim bench`: the torque-free rigid body stepped with classic RK4,
   written directly in plain C99 without the generated kernels, the effect table or the Python glue --
   the best loops we can write by hand for the same arithmetic. They are NOT part of the extension
   (lavendersim/csrc is); the bench compiles this file at run time with the system compiler and the
   extension's flags (-O3, no -ffast-math, no contraction) and calls it through ctypes.

   Same work per step as LavenderSim's torque-free scene:
     state x (13) = p_w[3], q[4] (x, y, z, w; scalar last; R_WB), v_w[3], omega_b[3]
     p' = v,  v' = 0
     q' = 1/2 q (x) (omega_b, 0)          (body-form kinematics)
     I w' = (I w) x w                      (Euler's equations, principal axes), written division-free
     w_x' = k_x w_y w_z, k_x = (I_y - I_z)/I_x (cyclic), the coefficients computed once per call
   RK4 in its scaled-increment form, as LavenderSim's torque-free paths (csrc/step.c lv_free_rk4_h): four
   evaluations of the increments (dt/2) k of q and omega_b only (stage quaternions unnormalized), stage inputs
   and the end by adds and one multiply by 1/3, then q normalized; p by one Euler step with v, v kept. Each
   expression is written in the same order of operations as the generated kernels and tableaux.h
   (euler_coefficients, rigid_body_increments_free_c, LV_RK4_SCALED_UPDATE, quat_normalize, translation_drift),
   so a peer that is right gives bitwise LavenderSim's trajectory; the bench checks that (max |dx| = 0).

   lv_ref_rk4_free: one body, everything inlined into one loop (the scalar peer). With check != 0
   every number of the new state is tested for finiteness after each step, as LavenderSim's stepping
   loop does. Returns -1 after n_steps steps (x updated in place), or the 0-based step at which the
   state went non-finite (x then holds the last finite state).

   lv_ref_rk4_free_soa: n bodies stored as structure of arrays, X[k*n + b] = number k of body b (13
   arrays of n), I[k*n + b] = I_k of body b (turned into the coefficient rows k_x, k_y, k_z once per
   tile); every step is one loop over bodies that the compiler
   vectorizes (the batch peer). Compiled once per instruction set the bench measures (see
   lavendersim.bench: -mavx512f, -mavx2, SSE2 baseline). No finiteness checks. */
#include <math.h>

#define NX 13
#define TILE 128 /* bodies per tile of the SoA peer */
/* The SoA tiles' rows start on a cache line: an AVX-512 load of 8 lanes never straddles two (on the stack a tile is
   otherwise 16-byte aligned, and a row 16 bytes off a 32-byte boundary cost ~9% in the extension's own tile). */
#if defined(__GNUC__) || defined(__clang__)
#define ALIGN_TILE __attribute__((aligned(64)))
#else
#define ALIGN_TILE
#endif

/* The increments H = (dt/2) k of q and omega_b at a stage input (q, w): the stage scale dt/2 sits in the constants
   C = (dt/2) k_b (cyclic) and hq = (dt/2) * 1/2 (q' = 1/2 q (x) (w, 0)), taken once per call. */
static inline void incr(const double *q, const double *w, const double *C, double hq, double *H)
{
    const double t0 = hq * w[0], t1 = hq * w[2], t2 = hq * w[1];
    H[0] = q[1] * t1 - q[2] * t2 + q[3] * t0;
    H[1] = -q[0] * t1 + q[2] * t0 + q[3] * t2;
    H[2] = q[0] * t2 - q[1] * t0 + q[3] * t1;
    H[3] = -q[0] * t0 - q[1] * t2 - q[2] * t1;
    H[4] = C[0] * w[1] * w[2];
    H[5] = C[1] * w[0] * w[2];
    H[6] = C[2] * w[0] * w[1];
}

/* One RK4 step of one body x (13 numbers, in place): the stages on y = (q, w) only, with the increments H_i =
   (dt/2) k_i: inputs y + H1, y + H2, y + (H3 + H3), the end y + (H1 + (H2 + H2) + (H3 + H3) + H4) / 3 (the sum
   left to right, one multiply by 1/3); q normalized; p += dt v (v' = 0: RK4 is one Euler step there); v kept. */
static inline void step_free(double *x, const double *C, double hq, double dt)
{
    double y[7], Y[7], H[7], a[7], r;
    int i;
    for (i = 0; i < 4; i++) y[i] = x[3 + i];
    for (i = 0; i < 3; i++) y[4 + i] = x[10 + i];
    incr(y, y + 4, C, hq, H);
    for (i = 0; i < 7; i++) { a[i] = H[i]; Y[i] = y[i] + H[i]; }
    incr(Y, Y + 4, C, hq, H);
    for (i = 0; i < 7; i++) { a[i] = a[i] + (H[i] + H[i]); Y[i] = y[i] + H[i]; }
    incr(Y, Y + 4, C, hq, H);
    for (i = 0; i < 7; i++) { const double d = H[i] + H[i]; a[i] = a[i] + d; Y[i] = y[i] + d; }
    incr(Y, Y + 4, C, hq, H);
    for (i = 0; i < 7; i++) Y[i] = y[i] + (a[i] + H[i]) * 0.3333333333333333;
    r = 1.0 / sqrt(Y[0] * Y[0] + Y[1] * Y[1] + Y[2] * Y[2] + Y[3] * Y[3]);
    for (i = 0; i < 4; i++) x[3 + i] = Y[i] * r;
    for (i = 0; i < 3; i++) x[10 + i] = Y[4 + i];
    for (i = 0; i < 3; i++) x[i] = dt * x[7 + i] + x[i];
}

long lv_ref_rk4_free(double *x, const double *I_b, double dt, long n_steps, int check)
{
    double y[NX], yn[NX];
    const double c[3] = {(I_b[1] - I_b[2]) / I_b[0], (-I_b[0] + I_b[2]) / I_b[1], (I_b[0] - I_b[1]) / I_b[2]};
    const double h = 0.5 * dt, hq = h * 0.5, C[3] = {h * c[0], h * c[1], h * c[2]};
    long s;
    int i;
    for (i = 0; i < NX; i++) y[i] = x[i];
    for (s = 0; s < n_steps; s++) {
        for (i = 0; i < NX; i++) yn[i] = y[i];
        step_free(yn, C, hq, dt);
        if (check) {
            for (i = 0; i < NX; i++)
                if (!isfinite(yn[i])) {
                    for (i = 0; i < NX; i++) x[i] = y[i];
                    return s;
                }
        }
        for (i = 0; i < NX; i++) y[i] = yn[i];
    }
    for (i = 0; i < NX; i++) x[i] = y[i];
    return -1;
}

void lv_ref_rk4_free_soa(double *X, const double *I, long n, double dt, long n_steps)
{
    /* a tile of bodies is copied into local rows (no aliasing for the compiler to fear) and stays in
       L1 over all the steps */
    ALIGN_TILE double T[NX][TILE];
    ALIGN_TILE double J[3][TILE];
    const double h = 0.5 * dt, hq = h * 0.5;
    long s, b, b0, m;
    int k;
    for (b0 = 0; b0 < n; b0 += m) {
        m = n - b0 < TILE ? n - b0 : TILE;
        for (k = 0; k < NX; k++)
            for (b = 0; b < m; b++) T[k][b] = X[k * n + b0 + b];
        for (b = 0; b < m; b++) { /* the Euler coefficients times dt/2, once per tile */
            const double I0 = I[b0 + b], I1 = I[n + b0 + b], I2 = I[2 * n + b0 + b];
            J[0][b] = h * ((I1 - I2) / I0);
            J[1][b] = h * ((-I0 + I2) / I1);
            J[2][b] = h * ((I0 - I1) / I2);
        }
        for (s = 0; s < n_steps; s++) {
            for (b = 0; b < m; b++) {
                double x[NX];
                const double C[3] = {J[0][b], J[1][b], J[2][b]};
                for (k = 0; k < NX; k++) x[k] = T[k][b];
                step_free(x, C, hq, dt);
                for (k = 0; k < NX; k++) T[k][b] = x[k];
            }
        }
        for (k = 0; k < NX; k++)
            for (b = 0; b < m; b++) X[k * n + b0 + b] = T[k][b];
    }
}

/* The divider's floor for the batch (not a peer, a limit): per body-step only the correctly rounded
   operations the torque-free RK4 step cannot do without while giving the same bits -- the sqrt and the
   division of the normalization (the Euler coefficients' divisions are once per call, not per step) --
   on the same SoA tiles, vectorized like lv_ref_rk4_free_soa. Each step's sqrt depends on the previous
   step's quotient, so nothing is hoisted out of the loop. On x86 the divider (divpd/sqrtpd) is one
   unit, not pipelined like the adders and multipliers, so this loop bounds the throughput of any
   bitwise-identical batch loop from below. I is unused (same signature as the peer). X is updated
   (its values are meaningless). */
void lv_ref_divider_floor_soa(double *X, const double *I, long n, double dt, long n_steps)
{
    ALIGN_TILE double T[NX][TILE];
    long s, b, b0, m;
    int k;
    (void)I;
    for (b0 = 0; b0 < n; b0 += m) {
        m = n - b0 < TILE ? n - b0 : TILE;
        for (k = 0; k < NX; k++)
            for (b = 0; b < m; b++) T[k][b] = X[k * n + b0 + b];
        for (s = 0; s < n_steps; s++) {
            for (b = 0; b < m; b++) {
                const double w0 = T[3][b] + dt * T[10][b], w1 = T[4][b], w2 = T[5][b], w3 = T[6][b];
                const double q = 1.0 / sqrt(w0 * w0 + w1 * w1 + w2 * w2 + w3 * w3);
                T[3][b] = w0 * q;
                T[4][b] = w1 * q;
                T[5][b] = w2 * q;
                T[6][b] = w3 * q;
            }
        }
        for (k = 0; k < NX; k++)
            for (b = 0; b < m; b++) X[k * n + b0 + b] = T[k][b];
    }
}
