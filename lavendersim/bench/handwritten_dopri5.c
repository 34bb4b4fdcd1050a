/* The hand-written DOPRI5 peer of `lavendersim bench`: one torque-free rigid body stepped with
   Dormand-Prince 5(4), written directly in C99 (not part of the extension; the bench compiles it at run
   time with the extension's flags and calls it through ctypes). The bench divides its time by its
   right-hand-side evaluations and compares that with LavenderSim's dopri5 (time / sim.rhs_evals).

   Same algorithm as LavenderSim's dopri5 (lavendersim/sim.py docstring), dense output: dt is the output
   interval; the substeps run on unclipped past the output times and the state at the call's last output
   time is read off the Dormand-Prince continuous extension of the last accepted substep (Hairer's contd5);
   FSAL within a call (each call starts with one fresh evaluation); Hairer's RMS error norm over the 13 state
   numbers with sc = atol + rtol max(|y|, |y_new|); controller safety 0.9, factor in [0.2, 5], no growth
   right after a rejection, the factor 0.9 e^(-1/5) by two Newton steps from a bit-pattern seed (no pow per
   substep); Hairer's starting step when h <= 0; q normalized after every accepted substep and at the output.
   What a hand loop for this body can skip, it skips: only q and omega_b (7 numbers) go through the stages
   (v' = 0, so p moves by h v and the p and v errors are 0), the tableau is unrolled (no zero entries),
   nothing is carried for wheels, and the continuous extension is formed once per call (the stages of the
   last accepted substep are kept by swapping two stage sets, not copied).

   state x (13) = p_w[3], q[4] (x, y, z, w), v_w[3], omega_b[3]; I_b principal moments.
   Returns -1 after n_steps output steps (x, *h updated; *nfev += evaluations), or the 0-based output
   step at which the step size fell below dt*1e-12, passed 1e6 substeps, or the state went non-finite. */
#include <math.h>
#include <stdint.h>
#include <string.h>

#define A21 (1.0 / 5.0)
#define A31 (3.0 / 40.0)
#define A32 (9.0 / 40.0)
#define A41 (44.0 / 45.0)
#define A42 (-56.0 / 15.0)
#define A43 (32.0 / 9.0)
#define A51 (19372.0 / 6561.0)
#define A52 (-25360.0 / 2187.0)
#define A53 (64448.0 / 6561.0)
#define A54 (-212.0 / 729.0)
#define A61 (9017.0 / 3168.0)
#define A62 (-355.0 / 33.0)
#define A63 (46732.0 / 5247.0)
#define A64 (49.0 / 176.0)
#define A65 (-5103.0 / 18656.0)
#define B1 (35.0 / 384.0)
#define B3 (500.0 / 1113.0)
#define B4 (125.0 / 192.0)
#define B5 (-2187.0 / 6784.0)
#define B6 (11.0 / 84.0)
#define E1 (71.0 / 57600.0)
#define E3 (-71.0 / 16695.0)
#define E4 (71.0 / 1920.0)
#define E5 (-17253.0 / 339200.0)
#define E6 (22.0 / 525.0)
#define E7 (-1.0 / 40.0)

/* 0.9 e^(-1/5), the controller's factor, without pow: two Newton steps on r^-5 = e from a bit-pattern seed (within
   2.6e-5 of the power over [1e-6, 1e6]; outside, the factor is clamped anyway: 5 below, 0.2 above or for NaN) */
static inline double factor(double e)
{
    if (e >= 1e-6 && e <= 1e6) {
        uint64_t bits;
        double r, r2;
        memcpy(&bits, &e, sizeof bits);
        bits = 5528348686582378659ULL - bits / 5;
        memcpy(&r, &bits, sizeof r);
        r2 = r * r;
        r = r * (6.0 - e * (r2 * r2 * r)) * 0.2;
        r2 = r * r;
        r = r * (6.0 - e * (r2 * r2 * r)) * 0.2;
        return 0.9 * r;
    }
    return e < 1e-6 ? 5.0 : 0.2;
}

/* z = (qx, qy, qz, qw, w0, w1, w2) -> z' (q' = q (x) (w, 0) / 2, Euler's equations division-free) */
static inline void rhs7(const double *z, const double *c, double *d)
{
    const double t0 = 0.5 * z[4], t1 = 0.5 * z[5], t2 = 0.5 * z[6];
    d[0] = t0 * z[3] - t1 * z[2] + t2 * z[1];
    d[1] = t0 * z[2] + t1 * z[3] - t2 * z[0];
    d[2] = -t0 * z[1] + t1 * z[0] + t2 * z[3];
    d[3] = -t0 * z[0] - t1 * z[1] - t2 * z[2];
    d[4] = c[0] * z[5] * z[6];
    d[5] = c[1] * z[4] * z[6];
    d[6] = c[2] * z[4] * z[5];
}

/* Hairer's RMS norm over the 13 numbers; e, y, yn hold the 7 of q and omega (p and v contribute 0 error). */
static double norm7(const double *e, const double *y, const double *yn, double rtol, double atol)
{
    double s = 0.0;
    int i;
    for (i = 0; i < 7; i++) {
        const double a = fabs(y[i]), b = fabs(yn[i]);
        const double z = e[i] / (atol + rtol * (a > b ? a : b));
        s += z * z;
    }
    return sqrt(s / 13.0);
}

/* Hairer's starting step from f0 = f(y) over all 13 numbers (II.4), one more evaluation. */
static double initial_h(const double *x, const double *z, const double *f0, const double *c, double rtol,
                        double atol, double dt, double *nfev)
{
    double s0 = 0.0, s1 = 0.0, s2 = 0.0, d0, d1, d2, h0, h1, mx, z1[7], f1[7];
    int i;
    for (i = 0; i < 13; i++) {
        const double sc = atol + rtol * fabs(x[i]);
        const double fi = i < 3 ? x[7 + i] : (i >= 3 && i < 7) ? f0[i - 3] : i >= 10 ? f0[i - 6] : 0.0;
        s0 += (x[i] / sc) * (x[i] / sc);
        s1 += (fi / sc) * (fi / sc);
    }
    d0 = sqrt(s0 / 13.0);
    d1 = sqrt(s1 / 13.0);
    h0 = (d0 < 1e-5 || d1 < 1e-5) ? 1e-6 : 0.01 * d0 / d1;
    if (h0 > dt) h0 = dt;
    for (i = 0; i < 7; i++) z1[i] = z[i] + h0 * f0[i];
    rhs7(z1, c, f1);
    *nfev += 1;
    for (i = 0; i < 7; i++) {
        const double sc = atol + rtol * fabs(z[i]), di = (f1[i] - f0[i]) / h0;
        s2 += (di / sc) * (di / sc);
    }
    d2 = sqrt(s2 / 13.0);
    mx = d1 > d2 ? d1 : d2;
    h1 = mx <= 1e-15 ? (h0 * 1e-3 > 1e-6 ? h0 * 1e-3 : 1e-6) : pow(0.01 / mx, 0.2);
    h0 = 100.0 * h0 < h1 ? 100.0 * h0 : h1;
    return isfinite(h0) && h0 > 0.0 ? h0 : dt;
}

#define D1 (-12715105075.0 / 11282082432.0)
#define D3 (87487479700.0 / 32700410799.0)
#define D4 (-10690763975.0 / 1880347072.0)
#define D5 (701980252875.0 / 199316789632.0)
#define D6 (-1453857185.0 / 822651844.0)
#define D7 (69997945.0 / 29380423.0)

static void store(double *x, const double *z, const double *p)
{
    int i;
    for (i = 0; i < 3; i++) x[i] = p[i];
    for (i = 0; i < 4; i++) x[3 + i] = z[i];
    for (i = 0; i < 3; i++) x[10 + i] = z[i + 4];
}

long lv_ref_dopri5_free(double *x, const double *I_b, double dt, long n_steps, double rtol, double atol,
                        double *h_io, double *nfev_out)
{
    const double c[3] = {(I_b[1] - I_b[2]) / I_b[0], (I_b[2] - I_b[0]) / I_b[1], (I_b[0] - I_b[1]) / I_b[2]};
    double z[7], zn[7], K[2][7][7], t[7], err[7], p[3], z0[7], y1[7], p0[3], p1[3], nfev = 0.0, h = *h_io;
    double ahead = 0.0, hl = 0.0;
    const double hmin = 1e-12 * dt;
    long s;
    int i, cur = 0;
    for (i = 0; i < 4; i++) z[i] = x[3 + i];
    for (i = 0; i < 3; i++) z[4 + i] = x[10 + i], p[i] = x[i];
    rhs7(z, c, K[0][0]);
    nfev += 1;
    if (!(h > 0.0) || !isfinite(h)) h = initial_h(x, z, K[0][0], c, rtol, atol, dt, &nfev);
    for (s = 0; s < n_steps; s++) {
        long sub = 0;
        int rejected = 0;
        ahead -= dt;
        while (ahead < 0.0) {
            double (*k)[7] = K[cur];
            const double hs = h;
            double e, fac;
            for (i = 0; i < 7; i++) t[i] = z[i] + hs * (A21 * k[0][i]);
            rhs7(t, c, k[1]);
            for (i = 0; i < 7; i++) t[i] = z[i] + hs * (A31 * k[0][i] + A32 * k[1][i]);
            rhs7(t, c, k[2]);
            for (i = 0; i < 7; i++) t[i] = z[i] + hs * (A41 * k[0][i] + A42 * k[1][i] + A43 * k[2][i]);
            rhs7(t, c, k[3]);
            for (i = 0; i < 7; i++)
                t[i] = z[i] + hs * (A51 * k[0][i] + A52 * k[1][i] + A53 * k[2][i] + A54 * k[3][i]);
            rhs7(t, c, k[4]);
            for (i = 0; i < 7; i++)
                t[i] = z[i] + hs * (A61 * k[0][i] + A62 * k[1][i] + A63 * k[2][i] + A64 * k[3][i] + A65 * k[4][i]);
            rhs7(t, c, k[5]);
            for (i = 0; i < 7; i++)
                zn[i] = z[i] + hs * (B1 * k[0][i] + B3 * k[2][i] + B4 * k[3][i] + B5 * k[4][i] + B6 * k[5][i]);
            rhs7(zn, c, k[6]);
            nfev += 6;
            for (i = 0; i < 7; i++)
                err[i] = hs * (E1 * k[0][i] + E3 * k[2][i] + E4 * k[3][i] + E5 * k[4][i] + E6 * k[5][i] + E7 * k[6][i]);
            e = norm7(err, z, zn, rtol, atol);
            fac = factor(e);
            if (e <= 1.0) {
                double r;
                if (fac > 5.0) fac = 5.0;
                if (fac < 0.2) fac = 0.2;
                if (rejected && fac > 1.0) fac = 1.0;
                h = hs * fac;
                for (i = 0; i < 7; i++) z0[i] = z[i], y1[i] = zn[i];   /* the substep, for the continuous extension */
                for (i = 0; i < 3; i++) p0[i] = p[i], p1[i] = p[i] + hs * x[7 + i];
                r = 1.0 / sqrt(zn[0] * zn[0] + zn[1] * zn[1] + zn[2] * zn[2] + zn[3] * zn[3]);
                for (i = 0; i < 4; i++) zn[i] *= r;
                for (i = 0; i < 7; i++) {
                    if (!isfinite(zn[i])) {
                        *h_io = h;
                        *nfev_out += nfev;
                        return s;
                    }
                }
                for (i = 0; i < 3; i++) p[i] = p1[i];
                for (i = 0; i < 7; i++) {
                    z[i] = zn[i];
                    K[1 - cur][0][i] = k[6][i]; /* FSAL: f at the new (un-normalized) point */
                }
                cur = 1 - cur;   /* K[1 - cur]: the stages of the last accepted substep */
                ahead += hs;
                hl = hs;
                rejected = 0;
            } else {
                if (fac < 0.2) fac = 0.2;
                if (fac > 1.0) fac = 1.0;
                h = hs * fac;
                rejected = 1;
            }
            if (h < hmin || ++sub > 1000000L) {
                *h_io = h;
                *nfev_out += nfev;
                return s;
            }
        }
    }
    if (n_steps > 0 && ahead != 0.0) {   /* the output: Hairer's contd5 on the last accepted substep */
        double (*k)[7] = K[1 - cur], out[7], po[3], r;
        const double th = (hl - ahead) / hl, th1 = 1.0 - th;
        for (i = 0; i < 7; i++) {
            const double d1 = y1[i] - z0[i], d2 = hl * k[0][i] - d1, d3 = d1 - hl * k[6][i] - d2;
            const double d4 = hl * (D1 * k[0][i] + D3 * k[2][i] + D4 * k[3][i] + D5 * k[4][i] + D6 * k[5][i] + D7 * k[6][i]);
            out[i] = z0[i] + th * (d1 + th1 * (d2 + th * (d3 + th1 * d4)));
        }
        for (i = 0; i < 3; i++) po[i] = p0[i] + th * (p1[i] - p0[i]);
        r = 1.0 / sqrt(out[0] * out[0] + out[1] * out[1] + out[2] * out[2] + out[3] * out[3]);
        for (i = 0; i < 4; i++) out[i] *= r;
        store(x, out, po);
    } else {
        store(x, z, p);
    }
    *h_io = h;
    *nfev_out += nfev;
    return -1;
}
