/* Hand-written fixed-step RK4 of n Yu Y5 leader-follower Van der Pol networks: the limit that
 * benchmarks/bench_scale.py measures cpgsim against (compiled there with gcc -O2, called with ctypes).
 *
 * Per network (Yu 2019, Y5), state s = [x1, y1, x2, y2, x3, y3]:
 *   dx_i = y_i ;  dy_i = -eps*(b*x_i^2 - 1)*y_i - omega_i^2*x_i + u_i
 *   u1 = 0;  drive = -4*x1*y1
 *   u2 = k12*(drive - y2) + k32*(y3 - y2);  u3 = k13*(drive - y3) + k23*(y2 - y3)
 * Parameters per network, 9 doubles: eps, b, omega1, omega2, omega3, k12, k13, k23, k32.
 *
 * Every state is stored at every step: out is (steps + 1) x (6 n), row-major, row 0 = x0, allocated
 * by the caller (so first-touch page faults are paid here, as in cpgsim's own result buffers).
 * The arithmetic is written in the order cpgsim's compiled graph uses (b*(x*x), (omega*omega)*x,
 * x + (h/2)*k, x + (h/6)*(((k1 + 2 k2) + 2 k3) + k4)), so the two agree to rounding or exactly.
 */

#include <string.h>

#define NP 9 /* parameters per network */
#define NS 6 /* states per network */

static inline void y5_rhs(const double *p, const double *s, double *d)
{
    const double eps = p[0], b = p[1];
    const double x1 = s[0], y1 = s[1], x2 = s[2], y2 = s[3], x3 = s[4], y3 = s[5];
    const double drive = -4.0 * x1 * y1;
    const double u2 = p[5] * (drive - y2) + p[8] * (y3 - y2);
    const double u3 = p[6] * (drive - y3) + p[7] * (y2 - y3);
    d[0] = y1;
    d[1] = -eps * (b * (x1 * x1) - 1.0) * y1 - (p[2] * p[2]) * x1;
    d[2] = y2;
    d[3] = -eps * (b * (x2 * x2) - 1.0) * y2 - (p[3] * p[3]) * x2 + u2;
    d[4] = y3;
    d[5] = -eps * (b * (x3 * x3) - 1.0) * y3 - (p[4] * p[4]) * x3 + u3;
}

/* Integrate n networks for steps steps of h; returns 0. */
int y5_rk4(long n, const double *params, const double *x0, double h, long steps, double *out)
{
    const long width = NS * n;
    const double h2 = h / 2, h6 = h / 6;
    memcpy(out, x0, sizeof(double) * (size_t)width);
    for (long k = 0; k < steps; ++k) {
        const double *prev = out + k * width;
        double *next = out + (k + 1) * width;
        for (long net = 0; net < n; ++net) {
            const double *p = params + NP * net;
            const double *s = prev + NS * net;
            double k1[NS], k2[NS], k3[NS], k4[NS], t[NS];
            y5_rhs(p, s, k1);
            for (int i = 0; i < NS; ++i) t[i] = s[i] + h2 * k1[i];
            y5_rhs(p, t, k2);
            for (int i = 0; i < NS; ++i) t[i] = s[i] + h2 * k2[i];
            y5_rhs(p, t, k3);
            for (int i = 0; i < NS; ++i) t[i] = s[i] + h * k3[i];
            y5_rhs(p, t, k4);
            double *o = next + NS * net;
            for (int i = 0; i < NS; ++i) o[i] = s[i] + h6 * (((k1[i] + 2.0 * k2[i]) + 2.0 * k3[i]) + k4[i]);
        }
    }
    return 0;
}
