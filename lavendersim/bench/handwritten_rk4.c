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
   four right-hand-side evaluations (stage quaternions unnormalized), the RK4 combination of all 13
   numbers, then q normalized. Each expression is written in the same order of operations as the
   generated kernels (generated/kernels.c: euler_coefficients, rigid_body_rhs_free_c, quat_normalize;
   rigid_body_rhs_free prints the same arithmetic), so a peer that is
   right gives bitwise LavenderSim's trajectory; the bench checks that (max |dx| = 0).

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

static inline void rhs_free(const double *x, const double *c, double *d)
{
    const double t0 = 0.5 * x[10], t1 = 0.5 * x[11], t2 = 0.5 * x[12];
    d[0] = x[7];
    d[1] = x[8];
    d[2] = x[9];
    d[3] = t0 * x[6] - t1 * x[5] + t2 * x[4];
    d[4] = t0 * x[5] + t1 * x[6] - t2 * x[3];
    d[5] = -t0 * x[4] + t1 * x[3] + t2 * x[6];
    d[6] = -t0 * x[3] - t1 * x[4] - t2 * x[5];
    d[7] = 0.0;
    d[8] = 0.0;
    d[9] = 0.0;
    d[10] = c[0] * x[11] * x[12];
    d[11] = c[1] * x[10] * x[12];
    d[12] = c[2] * x[10] * x[11];
}

long lv_ref_rk4_free(double *x, const double *I_b, double dt, long n_steps, int check)
{
    double y[NX], k1[NX], k2[NX], k3[NX], k4[NX], t[NX], yn[NX];
    const double c[3] = {(I_b[1] - I_b[2]) / I_b[0], (-I_b[0] + I_b[2]) / I_b[1], (I_b[0] - I_b[1]) / I_b[2]};
    const double h2 = 0.5 * dt, h6 = dt / 6.0;
    long s;
    int i;
    for (i = 0; i < NX; i++) y[i] = x[i];
    for (s = 0; s < n_steps; s++) {
        rhs_free(y, c, k1);
        for (i = 0; i < NX; i++) t[i] = y[i] + h2 * k1[i];
        rhs_free(t, c, k2);
        for (i = 0; i < NX; i++) t[i] = y[i] + h2 * k2[i];
        rhs_free(t, c, k3);
        for (i = 0; i < NX; i++) t[i] = y[i] + dt * k3[i];
        rhs_free(t, c, k4);
        for (i = 0; i < NX; i++) yn[i] = y[i] + h6 * (1.0 * k1[i] + 2.0 * k2[i] + 2.0 * k3[i] + 1.0 * k4[i]);
        {
            const double r = 1.0 / sqrt(yn[3] * yn[3] + yn[4] * yn[4] + yn[5] * yn[5] + yn[6] * yn[6]);
            yn[3] *= r; yn[4] *= r; yn[5] *= r; yn[6] *= r;
        }
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

/* The right-hand side on named scalars: stage input a##0..12 -> derivative d##3..6, d##10..12 (the
   others are a##7..9 and 0). */
#define RHS_S(a, d)                                                                                  \
    const double d##u0 = 0.5 * a##10, d##u1 = 0.5 * a##11, d##u2 = 0.5 * a##12;                      \
    const double d##3 = d##u0 * a##6 - d##u1 * a##5 + d##u2 * a##4;                                  \
    const double d##4 = d##u0 * a##5 + d##u1 * a##6 - d##u2 * a##3;                                  \
    const double d##5 = -d##u0 * a##4 + d##u1 * a##3 + d##u2 * a##6;                                 \
    const double d##6 = -d##u0 * a##3 - d##u1 * a##4 - d##u2 * a##5;                                 \
    const double d##10 = c0 * a##11 * a##12;                                                         \
    const double d##11 = c1 * a##10 * a##12;                                                         \
    const double d##12 = c2 * a##10 * a##11
/* stage state: a##k = y##k + h * d##k (d##0..2 = y##7..9 of the previous stage, d##7..9 = 0). */
#define STAGE(a, h, d, v0, v1, v2)                                                                   \
    const double a##0 = y0 + h * v0, a##1 = y1 + h * v1, a##2 = y2 + h * v2;                         \
    const double a##3 = y3 + h * d##3, a##4 = y4 + h * d##4, a##5 = y5 + h * d##5, a##6 = y6 + h * d##6; \
    const double a##7 = y7 + h * 0.0, a##8 = y8 + h * 0.0, a##9 = y9 + h * 0.0;                      \
    const double a##10 = y10 + h * d##10, a##11 = y11 + h * d##11, a##12 = y12 + h * d##12
#define COMB(k, v1, v2, v3, v4) y##k + h6 * (1.0 * (v1) + 2.0 * (v2) + 2.0 * (v3) + 1.0 * (v4))

void lv_ref_rk4_free_soa(double *X, const double *I, long n, double dt, long n_steps)
{
    /* a tile of bodies is copied into local rows (no aliasing for the compiler to fear) and stays in
       L1 over all the steps */
    ALIGN_TILE double T[NX][TILE];
    ALIGN_TILE double J[3][TILE];
    const double h2 = 0.5 * dt, h6 = dt / 6.0;
    long s, b, b0, m;
    int k;
    for (b0 = 0; b0 < n; b0 += m) {
        m = n - b0 < TILE ? n - b0 : TILE;
        for (k = 0; k < NX; k++)
            for (b = 0; b < m; b++) T[k][b] = X[k * n + b0 + b];
        for (b = 0; b < m; b++) { /* the Euler coefficients, once per tile */
            const double I0 = I[b0 + b], I1 = I[n + b0 + b], I2 = I[2 * n + b0 + b];
            J[0][b] = (I1 - I2) / I0;
            J[1][b] = (-I0 + I2) / I1;
            J[2][b] = (I0 - I1) / I2;
        }
        for (s = 0; s < n_steps; s++) {
            for (b = 0; b < m; b++) {
                const double c0 = J[0][b], c1 = J[1][b], c2 = J[2][b];
                const double y0 = T[0][b], y1 = T[1][b], y2 = T[2][b], y3 = T[3][b], y4 = T[4][b], y5 = T[5][b],
                    y6 = T[6][b], y7 = T[7][b], y8 = T[8][b], y9 = T[9][b], y10 = T[10][b], y11 = T[11][b],
                    y12 = T[12][b];
                double n3, n4, n5, n6, q;
                RHS_S(y, k1);
                STAGE(a, h2, k1, y7, y8, y9);
                RHS_S(a, k2);
                STAGE(e, h2, k2, a7, a8, a9);
                RHS_S(e, k3);
                STAGE(g, dt, k3, e7, e8, e9);
                RHS_S(g, k4);
                T[0][b] = COMB(0, y7, a7, e7, g7);
                T[1][b] = COMB(1, y8, a8, e8, g8);
                T[2][b] = COMB(2, y9, a9, e9, g9);
                n3 = COMB(3, k13, k23, k33, k43);
                n4 = COMB(4, k14, k24, k34, k44);
                n5 = COMB(5, k15, k25, k35, k45);
                n6 = COMB(6, k16, k26, k36, k46);
                T[7][b] = COMB(7, 0.0, 0.0, 0.0, 0.0);
                T[8][b] = COMB(8, 0.0, 0.0, 0.0, 0.0);
                T[9][b] = COMB(9, 0.0, 0.0, 0.0, 0.0);
                T[10][b] = COMB(10, k110, k210, k310, k410);
                T[11][b] = COMB(11, k111, k211, k311, k411);
                T[12][b] = COMB(12, k112, k212, k312, k412);
                q = 1.0 / sqrt(n3 * n3 + n4 * n4 + n5 * n5 + n6 * n6);
                T[3][b] = n3 * q; T[4][b] = n4 * q; T[5][b] = n5 * q; T[6][b] = n6 * q;
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
