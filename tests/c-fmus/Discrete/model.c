/*
 * Discrete: Integer, Boolean, Enumeration and String variables, changed only by fmi2DoStep.
 *
 *   every fmi2DoStep: if enable then counter += increment   (the inputs as set before the step)
 *   odd       = counter is odd
 *   phase     = Low (1) if counter < 3, Mid (2) if counter < 7, else High (3)
 *   label     = prefix + "=" + counter              e.g. "counter=7"
 *   time_seen = the FMU's time (the end of the last step)
 *
 * Each doStep adds once, whatever its size: a master that cuts a step in two (at an input change
 * between grid points, say) counts twice.
 */
#define MODEL_GUID "{33517f82-bb1a-4f37-aca7-d1d71f3be1d1}"
#define N_VARIABLES 8
#define N_REALS 1
#define N_INTEGERS 3
#define N_BOOLEANS 2
#define N_STRINGS 2
#define MODEL_CAN_INTERPOLATE_INPUTS 0
#define MODEL_NEEDS_RESOURCES 0

typedef struct {
    int unused;
} ModelExtra;

#include "../common.h"

enum { R_TIME_SEEN };
enum { I_INCREMENT, I_COUNTER, I_PHASE };
enum { B_ENABLE, B_ODD };
enum { S_LABEL, S_PREFIX };

static const Variable VARIABLES[N_VARIABLES] = {
    {"increment", T_INTEGER, C_INPUT, V_DISCRETE, I_EXACT, I_INCREMENT},
    {"enable", T_BOOLEAN, C_INPUT, V_DISCRETE, I_EXACT, B_ENABLE},
    {"counter", T_INTEGER, C_OUTPUT, V_DISCRETE, I_EXACT, I_COUNTER},
    {"odd", T_BOOLEAN, C_OUTPUT, V_DISCRETE, I_CALCULATED, B_ODD},
    {"phase", T_ENUMERATION, C_OUTPUT, V_DISCRETE, I_CALCULATED, I_PHASE},
    {"label", T_STRING, C_OUTPUT, V_DISCRETE, I_CALCULATED, S_LABEL},
    {"prefix", T_STRING, C_PARAMETER, V_FIXED, I_EXACT, S_PREFIX},
    {"time_seen", T_REAL, C_OUTPUT, V_CONTINUOUS, I_CALCULATED, R_TIME_SEEN},
};

enum { PHASE_LOW = 1, PHASE_MID = 2, PHASE_HIGH = 3 };

static void model_start(ModelState *m) {
    m->i[I_INCREMENT] = 1;
    m->b[B_ENABLE] = fmi2True;
    m->i[I_COUNTER] = 0;
    strcpy(m->s[S_PREFIX], "counter");
}

static fmi2Status model_exit_initialization(Instance *c) {
    (void)c;
    return fmi2OK;
}

static void model_calculate(Instance *c) {
    ModelState *m = &c->m;
    fmi2Integer counter = m->i[I_COUNTER];
    int n;
    m->b[B_ODD] = counter % 2 != 0 ? fmi2True : fmi2False;
    m->i[I_PHASE] = counter < 3 ? PHASE_LOW : counter < 7 ? PHASE_MID : PHASE_HIGH;
    n = snprintf(m->s[S_LABEL], STRING_CAPACITY, "%s=%d", m->s[S_PREFIX], (int)counter);
    if (n < 0) m->s[S_LABEL][0] = '\0'; /* (a longer label is cut to the buffer) */
    m->r[R_TIME_SEEN] = m->time;
}

static fmi2Status model_do_step(Instance *c, double t, double h) {
    ModelState *m = &c->m;
    (void)h;
    if (m->b[B_ENABLE]) {
        /* wraps around instead of overflowing */
        m->i[I_COUNTER] = (fmi2Integer)(int32_t)((uint32_t)m->i[I_COUNTER] + (uint32_t)m->i[I_INCREMENT]);
        log_event(c, "t = %.17g: counter += %d -> %d", t, (int)m->i[I_INCREMENT], (int)m->i[I_COUNTER]);
    }
    return fmi2OK;
}
