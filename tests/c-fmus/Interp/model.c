/*
 * Interp: NoInterp's gain and integrator for an FMU that interpolates its input
 * (canInterpolateInputs="true"): fmi2SetRealInputDerivatives (order 1) makes the input
 *
 *   u(t) = u_k + du (t - t_k)           inside the next step [t_k, t_k + h]
 *
 *   y        = 3 u                      (direct feedthrough)
 *   integral += u_k h + du h^2 / 2      (exact for a linear u)
 *
 * At the end of the step the input holds its end value u_k + du h and the derivative is back to 0
 * (the shear FMU's convention): a master that sends no derivative gets a held input.
 */
#define MODEL_GUID "{9235a385-3880-4d74-ba0d-8cef677075b4}"
#define N_VARIABLES 3
#define N_REALS 3
#define N_INTEGERS 0
#define N_BOOLEANS 0
#define N_STRINGS 0
#define MODEL_CAN_INTERPOLATE_INPUTS 1
#define MODEL_NEEDS_RESOURCES 0

typedef struct {
    double du; /* derivative of u for the next step */
} ModelExtra;

#include "../common.h"

enum { R_U, R_Y, R_INTEGRAL };

static const Variable VARIABLES[N_VARIABLES] = {
    {"u", T_REAL, C_INPUT, V_CONTINUOUS, I_EXACT, R_U},
    {"y", T_REAL, C_OUTPUT, V_CONTINUOUS, I_CALCULATED, R_Y},
    {"integral", T_REAL, C_OUTPUT, V_CONTINUOUS, I_EXACT, R_INTEGRAL},
};

static void model_start(ModelState *m) {
    m->r[R_U] = 0.0;
    m->r[R_INTEGRAL] = 0.0;
    m->x.du = 0.0;
}

static fmi2Status model_exit_initialization(Instance *c) {
    (void)c;
    return fmi2OK;
}

static void model_calculate(Instance *c) { c->m.r[R_Y] = 3.0 * c->m.r[R_U]; }

static fmi2Status model_set_input_derivative(Instance *c, const Variable *v, double derivative) {
    (void)v; /* u is the only continuous Real input */
    c->m.x.du = derivative;
    return fmi2OK;
}

static fmi2Status model_do_step(Instance *c, double t, double h) {
    ModelState *m = &c->m;
    (void)t;
    m->r[R_INTEGRAL] += m->r[R_U] * h + 0.5 * m->x.du * h * h;
    m->r[R_U] += m->x.du * h;
    m->x.du = 0.0;
    return fmi2OK;
}
