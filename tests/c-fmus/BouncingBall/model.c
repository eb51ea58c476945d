/*
 * BouncingBall: a ball falling under gravity and bouncing on the ground h = 0.
 *
 *   dh/dt = v, dv/dt = -g; at h = 0 with v < 0: v := -e v, bounces += 1;
 *   energy (a local) = g h + v^2 / 2;
 *   an impact that leaves the ball slower than V_REST = 0.1 m/s puts it to rest (h = v = 0 for good).
 *
 * fmi2DoStep advances in sub-steps of at most SUBSTEP (the communication step split evenly), each
 * integrated exactly (constant acceleration); an impact inside a sub-step is located by bisection on
 * h(t) = h + v t - g t^2 / 2, the restitution applied there and the rest of the sub-step continued
 * from the ground. Any communication step size is accepted.
 */
#define MODEL_GUID "{2ad5abc6-3519-4706-a5cd-144b29652500}"
#define N_VARIABLES 6
#define N_REALS 5
#define N_INTEGERS 1
#define N_BOOLEANS 0
#define N_STRINGS 0
#define MODEL_CAN_INTERPOLATE_INPUTS 0
#define MODEL_NEEDS_RESOURCES 0

typedef struct {
    int resting;
} ModelExtra;

#include "../common.h"

enum { R_H, R_V, R_G, R_E, R_ENERGY };
enum { I_BOUNCES };

static const Variable VARIABLES[N_VARIABLES] = {
    {"h", T_REAL, C_OUTPUT, V_CONTINUOUS, I_EXACT, R_H},
    {"v", T_REAL, C_OUTPUT, V_CONTINUOUS, I_EXACT, R_V},
    {"g", T_REAL, C_PARAMETER, V_FIXED, I_EXACT, R_G},
    {"e", T_REAL, C_PARAMETER, V_FIXED, I_EXACT, R_E},
    {"bounces", T_INTEGER, C_OUTPUT, V_DISCRETE, I_CALCULATED, I_BOUNCES},
    {"energy", T_REAL, C_LOCAL, V_CONTINUOUS, I_CALCULATED, R_ENERGY},
};

#define SUBSTEP 1e-3
#define V_REST 0.1

static void model_start(ModelState *m) {
    m->r[R_H] = 1.0;
    m->r[R_V] = 0.0;
    m->r[R_G] = 9.81;
    m->r[R_E] = 0.7;
    m->i[I_BOUNCES] = 0;
    m->x.resting = 0;
}

static fmi2Status model_exit_initialization(Instance *c) {
    const double *r = c->m.r;
    if (!(r[R_G] > 0)) {
        log_status(c, fmi2Error, "g = %g: gravity must be positive", r[R_G]);
        return fmi2Error;
    }
    if (!(r[R_E] >= 0 && r[R_E] <= 1)) {
        log_status(c, fmi2Error, "e = %g: the coefficient of restitution must be in [0, 1]", r[R_E]);
        return fmi2Error;
    }
    if (r[R_H] < 0) {
        log_status(c, fmi2Error, "h = %g: the ball starts below the ground", r[R_H]);
        return fmi2Error;
    }
    return fmi2OK;
}

/* The local `energy`: mechanical energy per unit mass, g h + v^2 / 2 (falls at each impact). */
static void model_calculate(Instance *c) {
    double *r = c->m.r;
    r[R_ENERGY] = r[R_G] * r[R_H] + 0.5 * r[R_V] * r[R_V];
}

static double height_after(double h, double v, double g, double tau) { return h + v * tau - 0.5 * g * tau * tau; }

static fmi2Status model_do_step(Instance *c, double t, double step) {
    ModelState *m = &c->m;
    const double g = m->r[R_G], e = m->r[R_E];
    double h = m->r[R_H], v = m->r[R_V];
    long n = (long)ceil(step / SUBSTEP - 1e-9);
    double dt;
    if (n < 1) n = 1;
    dt = step / (double)n;
    for (long k = 0; k < n && !m->x.resting; k++) {
        double left = dt; /* of this sub-step */
        while (left > 0 && !m->x.resting) {
            double tau, v_impact;
            if (h <= 0 && v <= 0) {
                tau = 0; /* on the ground, moving down: the impact is now */
            } else if (height_after(h, v, g, left) >= 0) {
                h = height_after(h, v, g, left);
                v -= g * left;
                break;
            } else {
                /* h(0) >= 0 > h(left), h concave: bisect for the last crossing */
                double lo = 0, hi = left;
                for (int it = 0; it < 200; it++) {
                    double mid = 0.5 * (lo + hi);
                    if (mid <= lo || mid >= hi) break;
                    if (height_after(h, v, g, mid) > 0)
                        lo = mid;
                    else
                        hi = mid;
                }
                tau = hi;
            }
            v_impact = v - g * tau;
            left -= tau;
            h = 0;
            if (v_impact < 0) {
                m->i[I_BOUNCES]++;
                log_event(c, "impact %d at t = %.17g with v = %.17g", (int)m->i[I_BOUNCES],
                          t + (double)k * dt + (dt - left), v_impact);
            }
            v = v_impact < 0 ? -e * v_impact : v_impact;
            if (v < V_REST) {
                v = 0;
                m->x.resting = 1;
                log_event(c, "the ball comes to rest at t = %.17g", t + (double)k * dt + (dt - left));
            }
        }
    }
    m->r[R_H] = h;
    m->r[R_V] = v;
    return fmi2OK;
}
