/* A minimal hand-written reference for `lavendersim bench`: the torque-free rigid body stepped with
   classic RK4, written directly in plain C99 without the generated kernels, the effect table or the
   Python glue. It is NOT part of the extension (lavendersim/csrc is); the bench compiles it at run
   time with the system compiler into a temporary shared library and calls it through ctypes.

   Same work per step as LavenderSim's torque-free scene:
     state x (13) = p_w[3], q[4] (x, y, z, w; scalar last; R_WB), v_w[3], omega_b[3]
     p' = v,  v' = 0
     q' = 1/2 q (x) (omega_b, 0)          (body-form kinematics)
     I w' = (I w) x w                      (Euler's equations, principal axes)
   four right-hand-side evaluations (stage quaternions unnormalized), the RK4 combination of all 13
   numbers, then q normalized. With check != 0 every number of the new state is also tested for
   finiteness after each step, as LavenderSim's stepping loop does.

   Returns -1 after n_steps steps (x updated in place), or the 0-based step at which the state went
   non-finite (x then holds the last finite state). */
#include <math.h>

static void rhs_free(const double *x, const double *I, double *d)
{
    const double qx = x[3], qy = x[4], qz = x[5], qw = x[6];
    const double wx = x[10], wy = x[11], wz = x[12];
    d[0] = x[7];
    d[1] = x[8];
    d[2] = x[9];
    d[3] = 0.5 * (qw * wx + qy * wz - qz * wy);
    d[4] = 0.5 * (qw * wy + qz * wx - qx * wz);
    d[5] = 0.5 * (qw * wz + qx * wy - qy * wx);
    d[6] = -0.5 * (qx * wx + qy * wy + qz * wz);
    d[7] = 0.0;
    d[8] = 0.0;
    d[9] = 0.0;
    d[10] = (I[1] - I[2]) * wy * wz / I[0];
    d[11] = (I[2] - I[0]) * wz * wx / I[1];
    d[12] = (I[0] - I[1]) * wx * wy / I[2];
}

long lv_ref_rk4_free(double *x, const double *I, double dt, long n_steps, int check)
{
    double y[13], k1[13], k2[13], k3[13], k4[13], t[13], yn[13];
    const double h2 = 0.5 * dt, h6 = dt / 6.0;
    long s;
    int i;
    for (i = 0; i < 13; i++) y[i] = x[i];
    for (s = 0; s < n_steps; s++) {
        rhs_free(y, I, k1);
        for (i = 0; i < 13; i++) t[i] = y[i] + h2 * k1[i];
        rhs_free(t, I, k2);
        for (i = 0; i < 13; i++) t[i] = y[i] + h2 * k2[i];
        rhs_free(t, I, k3);
        for (i = 0; i < 13; i++) t[i] = y[i] + dt * k3[i];
        rhs_free(t, I, k4);
        for (i = 0; i < 13; i++) yn[i] = y[i] + h6 * (k1[i] + 2.0 * k2[i] + 2.0 * k3[i] + k4[i]);
        {
            const double r = 1.0 / sqrt(yn[3] * yn[3] + yn[4] * yn[4] + yn[5] * yn[5] + yn[6] * yn[6]);
            yn[3] *= r; yn[4] *= r; yn[5] *= r; yn[6] *= r;
        }
        if (check) {
            for (i = 0; i < 13; i++)
                if (!isfinite(yn[i])) {
                    for (i = 0; i < 13; i++) x[i] = y[i];
                    return s;
                }
        }
        for (i = 0; i < 13; i++) y[i] = yn[i];
    }
    for (i = 0; i < 13; i++) x[i] = y[i];
    return -1;
}
