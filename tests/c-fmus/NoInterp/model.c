/*
 * NoInterp: a gain with direct feedthrough and an integrator, for an FMU that cannot interpolate
 * its inputs (canInterpolateInputs is not declared, so it is false).
 *
 *   y        = 3 u                      (direct feedthrough: y follows u set after a step)
 *   integral = integral of u dt         (u held constant over each step)
 *
 * fmi2SetRealInputDerivatives is exported but refuses: it logs "fmi2SetRealInputDerivatives called
 * although canInterpolateInputs is false" and returns fmi2Error.
 */
#define MODEL_GUID "{94ba658f-114c-4bd4-b39c-8042c15f99e7}"
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

enum { R_U, R_Y, R_INTEGRAL };

static const Variable VARIABLES[N_VARIABLES] = {
    {"u", T_REAL, C_INPUT, V_CONTINUOUS, I_EXACT, R_U},
    {"y", T_REAL, C_OUTPUT, V_CONTINUOUS, I_CALCULATED, R_Y},
    {"integral", T_REAL, C_OUTPUT, V_CONTINUOUS, I_EXACT, R_INTEGRAL},
};

static void model_start(ModelState *m) {
    m->r[R_U] = 0.0;
    m->r[R_INTEGRAL] = 0.0;
}

static fmi2Status model_exit_initialization(Instance *c) {
    (void)c;
    return fmi2OK;
}

static void model_calculate(Instance *c) { c->m.r[R_Y] = 3.0 * c->m.r[R_U]; }

static fmi2Status model_do_step(Instance *c, double t, double h) {
    (void)t;
    c->m.r[R_INTEGRAL] += c->m.r[R_U] * h;
    return fmi2OK;
}
