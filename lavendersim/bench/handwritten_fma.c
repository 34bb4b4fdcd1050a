/* The best torque-free RK4 batch loops we can write by hand: the peers the bench's "floor" lines compare
   against (lv_fma_rk4_free_soa, the classic stage form below, and lv_fma_rk4_free_soa_scaled, the scaled-increment
   form further down, faster on Zen 4: the bench takes the fastest variant). Unlike handwritten_rk4.c it is NOT constrained to the generated kernels' arithmetic: it does
   the fewest floating-point operations we know for one RK4 step of a torque-free rigid body, with fused
   multiply-adds, so its results differ from LavenderSim's in the last bits (the bench checks they agree
   to 1e-12). Compiled by the bench with -O3 -march=native -ffp-contract=fast (never -ffast-math).

   Per body-step only q (4) and omega_b (3) go through the four stages:
     G(q, w) = q (x) (w, 0)          (so q' = G / 2: the 1/2 is folded into the stage coefficients)
     f(w)_x = k_x w_y w_z, k_x = (I_y - I_z) / I_x (cyclic; once per call, not per step)
   the stage states q + (dt/4) G, w + (dt/2) f (the last stage: dt/2, dt), the RK4 sums accumulated into
   the new state with one FMA per number and stage, p += dt v (v' = 0, so RK4 is exact there), and q
   normalized. About 207 flops per body-step (an FMA counts 2) before the normalization.

   The normalization, like LavenderSim's FMA tiles (derive/quaternion.py quat_renormalize_near_unit): no sqrt and
   no division, q (1 - e/2 + 3e^2/8) with e = |q|^2 - 1, exact to rounding while |e| <= 2^-18 (after a step from a
   unit q e is ~1e-16); a lane beyond that keeps its raw q and the tile's pass after the step divides it by |q|
   (the divider costs ~1 ns per body-step on Zen 4, more than these 5 FMAs). 17 flops, where one sqrt and one
   division count 13 (the bench's FMA_FLOPS keeps the lower count, so its floor does not rise with this loop).

   lv_fma_rk4_free_soa: n bodies stored as structure of arrays, X[k*n + b] = number k of body b (13 rows
   of n; state order p_w[3], q[4] (x, y, z, w), v_w[3], omega_b[3]), I[k*n + b] = I_k of body b.
   Tiles of TILE bodies are copied into local rows (no aliasing), stepped n_steps times, copied back. */
#include <math.h>

#define TILE 128
#if defined(__GNUC__) || defined(__clang__)
#define ALIGN_TILE __attribute__((aligned(64))) /* rows on a cache line (as handwritten_rk4.c's tiles) */
#else
#define ALIGN_TILE
#endif
#define EPS_MAX 0x1p-18 /* |e| up to which the series normalizes to rounding */

/* G = q (x) (w, 0), q = (x, y, z, w) */
#define QDOT(g, qx, qy, qz, qw, w0, w1, w2)                                                          \
    const double g##x = fma(w0, qw, fma(w2, qy, -(w1 * qz)));                                        \
    const double g##y = fma(w0, qz, fma(w1, qw, -(w2 * qx)));                                        \
    const double g##z = fma(w1, qx, fma(w2, qw, -(w0 * qy)));                                        \
    const double g##w = -fma(w0, qx, fma(w1, qy, w2 * qz))
#define WDOT(f, w0, w1, w2)                                                                          \
    const double f##0 = c0 * (w1 * w2), f##1 = c1 * (w0 * w2), f##2 = c2 * (w0 * w1)

void lv_fma_rk4_free_soa(double *X, const double *I, long n, double dt, long n_steps)
{
    ALIGN_TILE double T[13][TILE];
    ALIGN_TILE double J[3][TILE];
    const double hq2 = 0.25 * dt, hq4 = 0.5 * dt;         /* q stages: (dt/2)/2, dt/2 */
    const double hw2 = 0.5 * dt, hw4 = dt;                /* omega stages */
    const double aq1 = dt / 12.0, aq2 = dt / 6.0;         /* q sum: (dt/6)(1, 2, 2, 1) / 2 */
    const double aw1 = dt / 6.0, aw2 = dt / 3.0;          /* omega sum: (dt/6)(1, 2, 2, 1) */
    long s, b, b0, m;
    int k;
    for (b0 = 0; b0 < n; b0 += m) {
        m = n - b0 < TILE ? n - b0 : TILE;
        for (k = 0; k < 13; k++)
            for (b = 0; b < m; b++) T[k][b] = X[k * n + b0 + b];
        for (b = 0; b < m; b++) {
            const double I0 = I[b0 + b], I1 = I[n + b0 + b], I2 = I[2 * n + b0 + b];
            J[0][b] = (I1 - I2) / I0;
            J[1][b] = (I2 - I0) / I1;
            J[2][b] = (I0 - I1) / I2;
        }
        for (s = 0; s < n_steps; s++) {
            long far = 0;
            for (b = 0; b < m; b++) {
                const double c0 = J[0][b], c1 = J[1][b], c2 = J[2][b];
                const double qx = T[3][b], qy = T[4][b], qz = T[5][b], qw = T[6][b];
                const double w0 = T[10][b], w1 = T[11][b], w2 = T[12][b];
                double nx, ny, nz, nw, n0, n1, n2, r, e;
                int near;
                QDOT(g1, qx, qy, qz, qw, w0, w1, w2);
                WDOT(f1, w0, w1, w2);
                const double ax = fma(hq2, g1x, qx), ay = fma(hq2, g1y, qy), az = fma(hq2, g1z, qz), aw = fma(hq2, g1w, qw);
                const double a0 = fma(hw2, f10, w0), a1 = fma(hw2, f11, w1), a2 = fma(hw2, f12, w2);
                nx = fma(aq1, g1x, qx); ny = fma(aq1, g1y, qy); nz = fma(aq1, g1z, qz); nw = fma(aq1, g1w, qw);
                n0 = fma(aw1, f10, w0); n1 = fma(aw1, f11, w1); n2 = fma(aw1, f12, w2);
                QDOT(g2, ax, ay, az, aw, a0, a1, a2);
                WDOT(f2, a0, a1, a2);
                const double bx = fma(hq2, g2x, qx), by = fma(hq2, g2y, qy), bz = fma(hq2, g2z, qz), bw = fma(hq2, g2w, qw);
                const double b0_ = fma(hw2, f20, w0), b1 = fma(hw2, f21, w1), b2 = fma(hw2, f22, w2);
                nx = fma(aq2, g2x, nx); ny = fma(aq2, g2y, ny); nz = fma(aq2, g2z, nz); nw = fma(aq2, g2w, nw);
                n0 = fma(aw2, f20, n0); n1 = fma(aw2, f21, n1); n2 = fma(aw2, f22, n2);
                QDOT(g3, bx, by, bz, bw, b0_, b1, b2);
                WDOT(f3, b0_, b1, b2);
                const double ex = fma(hq4, g3x, qx), ey = fma(hq4, g3y, qy), ez = fma(hq4, g3z, qz), ew = fma(hq4, g3w, qw);
                const double e0 = fma(hw4, f30, w0), e1 = fma(hw4, f31, w1), e2 = fma(hw4, f32, w2);
                nx = fma(aq2, g3x, nx); ny = fma(aq2, g3y, ny); nz = fma(aq2, g3z, nz); nw = fma(aq2, g3w, nw);
                n0 = fma(aw2, f30, n0); n1 = fma(aw2, f31, n1); n2 = fma(aw2, f32, n2);
                QDOT(g4, ex, ey, ez, ew, e0, e1, e2);
                WDOT(f4, e0, e1, e2);
                nx = fma(aq1, g4x, nx); ny = fma(aq1, g4y, ny); nz = fma(aq1, g4z, nz); nw = fma(aq1, g4w, nw);
                T[10][b] = fma(aw1, f40, n0); T[11][b] = fma(aw1, f41, n1); T[12][b] = fma(aw1, f42, n2);
                e = fma(nx, nx, fma(ny, ny, fma(nz, nz, fma(nw, nw, -1.0))));
                r = fma(e, fma(0.375, e, -0.5), 1.0);
                near = fabs(e) <= EPS_MAX;
                far |= !near;
                T[3][b] = near ? nx * r : nx; T[4][b] = near ? ny * r : ny;
                T[5][b] = near ? nz * r : nz; T[6][b] = near ? nw * r : nw;
                T[0][b] = fma(dt, T[7][b], T[0][b]);
                T[1][b] = fma(dt, T[8][b], T[1][b]);
                T[2][b] = fma(dt, T[9][b], T[2][b]);
            }
            if (far)
                for (b = 0; b < m; b++) {
                    const double q2 = T[3][b] * T[3][b] + T[4][b] * T[4][b] + T[5][b] * T[5][b] + T[6][b] * T[6][b];
                    if (fabs(q2 - 1.0) <= EPS_MAX) continue;
                    const double rn = 1.0 / sqrt(q2);
                    for (k = 3; k < 7; k++) T[k][b] *= rn;
                }
        }
        for (k = 0; k < 13; k++)
            for (b = 0; b < m; b++) X[k * n + b0 + b] = T[k][b];
    }
}

/* lv_fma_rk4_free_soa_scaled: the same step in the scaled-increment form (LavenderSim's, derive/tableaux.py
   scaled_program), written by hand for the FMA units: per stage the increments H = (dt/2) (q', omega_b') at their own
   cost (hq = dt/4 and C_k = (dt/2) k_k per body and call), the stage inputs q + H, q + H, q + (H + H) and the end
   q + (H1 + 2 H2 + 2 H3 + H4) / 3 as a running sum of adds. Zen 4 runs multiplies and FMAs on two pipes and adds on
   two others: this form puts ~104 of its ~160 vector operations per 8 bodies on the FMA pipes (21 per stage's
   increments, 7 for the end's 1/3, 10 for the normalization, 3 for p; GCC 12's AVX-512 loop: 58 vmulpd, 48 FMAs,
   54 adds) and the rest on the adders, where the classic loop above puts ~127 on the FMA pipes (its stage sums are
   FMAs): 3.9-4.2 against 4.7-4.8 ns per body-step (lavendersim bench --only simd, N = 1e3, 1e4, load 4-6). Explicit fma() where a product feeds a sum, plain
   adds elsewhere: compiled with -ffp-contract=off (the flags' last word), so no add becomes an FMA (GCC folds H + H
   into 2 H and would fuse it into the sum: FMA-pipe work again). Same normalization and far-lane pass. */
#define HINC(p, qx, qy, qz, qw, w0, w1, w2)                                                          \
    const double p##t0 = hq * (w0), p##t1 = hq * (w2), p##t2 = hq * (w1);                            \
    const double p##x = fma(qw, p##t0, fma(qy, p##t1, -((qz) * p##t2)));                             \
    const double p##y = fma(qz, p##t0, fma(qw, p##t2, -((qx) * p##t1)));                             \
    const double p##z = fma(qx, p##t2, fma(qw, p##t1, -((qy) * p##t0)));                             \
    const double p##w = -fma(qx, p##t0, fma(qy, p##t2, (qz) * p##t1));                               \
    const double p##0 = c0 * ((w1) * (w2)), p##1 = c1 * ((w0) * (w2)), p##2 = c2 * ((w0) * (w1))

void lv_fma_rk4_free_soa_scaled(double *X, const double *I, long n, double dt, long n_steps)
{
    ALIGN_TILE double T[13][TILE];
    ALIGN_TILE double J[3][TILE];
    const double hq = 0.25 * dt, sdt = 0.5 * dt, third = 1.0 / 3.0;
    long s, b, b0, m;
    int k;
    for (b0 = 0; b0 < n; b0 += m) {
        m = n - b0 < TILE ? n - b0 : TILE;
        for (k = 0; k < 13; k++)
            for (b = 0; b < m; b++) T[k][b] = X[k * n + b0 + b];
        for (b = 0; b < m; b++) {
            const double I0 = I[b0 + b], I1 = I[n + b0 + b], I2 = I[2 * n + b0 + b];
            J[0][b] = sdt * ((I1 - I2) / I0);
            J[1][b] = sdt * ((I2 - I0) / I1);
            J[2][b] = sdt * ((I0 - I1) / I2);
        }
        for (s = 0; s < n_steps; s++) {
            long far = 0;
            for (b = 0; b < m; b++) {
                const double c0 = J[0][b], c1 = J[1][b], c2 = J[2][b];
                const double qx = T[3][b], qy = T[4][b], qz = T[5][b], qw = T[6][b];
                const double w0 = T[10][b], w1 = T[11][b], w2 = T[12][b];
                double nx, ny, nz, nw, r, e;
                int near;
                HINC(h1, qx, qy, qz, qw, w0, w1, w2);
                const double ax = qx + h1x, ay = qy + h1y, az = qz + h1z, aw = qw + h1w;
                const double a0 = w0 + h10, a1 = w1 + h11, a2 = w2 + h12;
                HINC(h2, ax, ay, az, aw, a0, a1, a2);
                const double sx = h1x + (h2x + h2x), sy = h1y + (h2y + h2y), sz = h1z + (h2z + h2z), sw = h1w + (h2w + h2w);
                const double s0 = h10 + (h20 + h20), s1 = h11 + (h21 + h21), s2 = h12 + (h22 + h22);
                const double bx = qx + h2x, by = qy + h2y, bz = qz + h2z, bw = qw + h2w;
                const double b0_ = w0 + h20, b1 = w1 + h21, b2 = w2 + h22;
                HINC(h3, bx, by, bz, bw, b0_, b1, b2);
                const double dx = h3x + h3x, dy = h3y + h3y, dz = h3z + h3z, dw = h3w + h3w;
                const double d0 = h30 + h30, d1 = h31 + h31, d2 = h32 + h32;
                const double ux = sx + dx, uy = sy + dy, uz = sz + dz, uw = sw + dw;
                const double u0 = s0 + d0, u1 = s1 + d1, u2 = s2 + d2;
                const double ex = qx + dx, ey = qy + dy, ez = qz + dz, ew = qw + dw;
                const double e0 = w0 + d0, e1 = w1 + d1, e2 = w2 + d2;
                HINC(h4, ex, ey, ez, ew, e0, e1, e2);
                nx = fma(ux + h4x, third, qx); ny = fma(uy + h4y, third, qy);
                nz = fma(uz + h4z, third, qz); nw = fma(uw + h4w, third, qw);
                T[10][b] = fma(u0 + h40, third, w0); T[11][b] = fma(u1 + h41, third, w1);
                T[12][b] = fma(u2 + h42, third, w2);
                e = fma(nx, nx, fma(ny, ny, fma(nz, nz, fma(nw, nw, -1.0))));
                r = fma(e, fma(0.375, e, -0.5), 1.0);
                near = fabs(e) <= EPS_MAX;
                far |= !near;
                T[3][b] = near ? nx * r : nx; T[4][b] = near ? ny * r : ny;
                T[5][b] = near ? nz * r : nz; T[6][b] = near ? nw * r : nw;
                T[0][b] = fma(dt, T[7][b], T[0][b]);
                T[1][b] = fma(dt, T[8][b], T[1][b]);
                T[2][b] = fma(dt, T[9][b], T[2][b]);
            }
            if (far)
                for (b = 0; b < m; b++) {
                    const double q2 = T[3][b] * T[3][b] + T[4][b] * T[4][b] + T[5][b] * T[5][b] + T[6][b] * T[6][b];
                    if (fabs(q2 - 1.0) <= EPS_MAX) continue;
                    const double rn = 1.0 / sqrt(q2);
                    for (k = 3; k < 7; k++) T[k][b] *= rn;
                }
        }
        for (k = 0; k < 13; k++)
            for (b = 0; b < m; b++) X[k * n + b0 + b] = T[k][b];
    }
}

/* The peak FMA rate this loop gets from the CPU: 64 independent accumulators (enough chains to cover the
   FMA latency of every pipe at any vector width), n_iter rounds of acc = acc * a + b each; 128 flops per
   round. Returns their sum, so nothing is optimized away. The bench divides FMA_FLOPS by this rate: the
   floor of a torque-free RK4 body-step on this machine. */
double lv_peak_fma(long n_iter, double a, double b)
{
    double acc[64], s = 0.0;
    long it;
    int i;
    for (i = 0; i < 64; i++) acc[i] = (double)i;
    for (it = 0; it < n_iter; it++)
        for (i = 0; i < 64; i++) acc[i] = fma(acc[i], a, b);
    for (i = 0; i < 64; i++) s += acc[i];
    return s;
}
