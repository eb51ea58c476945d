/*
 * Stopper: an integrator that ends the simulation itself at t = stop_at.
 *
 *   x = x(start) + integral of u dt   (u held constant over each step: canInterpolateInputs="false")
 *
 * A step that reaches stop_at (ends at or after it, within 1e-9 * max(1, |stop_at|)) integrates up
 * to stop_at only and returns fmi2Discard; then fmi2GetBooleanStatus(fmi2Terminated) is fmi2True,
 * fmi2GetRealStatus(fmi2LastSuccessfulTime) is stop_at, and a further fmi2DoStep is refused. A step
 * from a time already at or past stop_at does nothing and returns fmi2Discard the same way.
 */
#define MODEL_GUID "{74fea24e-0f65-4bc9-b3e6-5d042796eb1b}"
#define N_VARIABLES 3
#define N_REALS 3
#define N_INTEGERS 0
#define N_BOOLEANS 0
#define N_STRINGS 0
#define MODEL_CAN_INTERPOLATE_INPUTS 0
#define MODEL_NEEDS_RESOURCES 0

typedef struct {
    int unused;
} ModelExtra;

#include "../common.h"

enum { R_U, R_X, R_STOP_AT };

static const Variable VARIABLES[N_VARIABLES] = {
    {"u", T_REAL, C_INPUT, V_CONTINUOUS, I_EXACT, R_U},
    {"x", T_REAL, C_OUTPUT, V_CONTINUOUS, I_EXACT, R_X},
    {"stop_at", T_REAL, C_PARAMETER, V_FIXED, I_EXACT, R_STOP_AT},
};

static void model_start(ModelState *m) {
    m->r[R_U] = 1.0;
    m->r[R_X] = 0.0;
    m->r[R_STOP_AT] = 0.42;
}

static fmi2Status model_exit_initialization(Instance *c) {
    (void)c;
    return fmi2OK;
}

static void model_calculate(Instance *c) { (void)c; }

static fmi2Status model_do_step(Instance *c, double t, double h) {
    ModelState *m = &c->m;
    const double stop_at = m->r[R_STOP_AT], tol = 1e-9 * fmax(1.0, fabs(stop_at));
    if (t + h < stop_at - tol) {
        m->r[R_X] += m->r[R_U] * h;
        return fmi2OK;
    }
    if (t < stop_at) {
        m->r[R_X] += m->r[R_U] * (stop_at - t);
        m->time = stop_at;
    } else {
        m->time = t;
    }
    m->terminated = 1;
    log_event(c, "the simulation ends at t = %.17g (stop_at = %.17g)", m->time, stop_at);
    return fmi2Discard;
}
